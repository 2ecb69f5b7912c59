"""Tool menu: the 16 tool slots (robot-held tools and robot-held workpieces)."""

from server.api.routers.tables import table_router

router = table_router("tool", "tools", "Tool")
