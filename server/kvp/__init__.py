"""The KVP face: KUKAVARPROXY's protocol over the KUKA-kind controllers' frames (docs/kvp.md)."""
