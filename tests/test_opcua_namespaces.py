"""Server/Namespaces (OPC 10000-5 §6.3.13-14): a NamespaceMetadataType object for pendant's
namespace beside DI's and Robotics', read by an Operator (the least role) over asyncua, and
its Static* properties true of the address space the face serves."""

from __future__ import annotations

import asyncio
import datetime as dt
import re
from collections.abc import Iterator

import pytest
from api_helpers import make_client, ok
from asyncua import ua
from opcua_helpers import namespaces, secure_client, start_face

from server import __version__
from server.opcua.space import DI_URI, PENDANT_URI, ROBOTICS_URI

PROPERTIES = ("NamespaceUri", "NamespaceVersion", "NamespacePublicationDate", "IsNamespaceSubset",
              "StaticNodeIdTypes", "StaticNumericNodeIdRange", "StaticStringNodeIdPattern")


@pytest.fixture(scope="module")
def face(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    """The face (with the demo controller, cell-1) and an Operator's login."""
    with make_client(fresh_db("opcua-ns")) as rest:
        ok(rest.post("/users", json={"name": "op", "role": "Operator"}))
        token = ok(rest.post("/users/op/tokens", json={}))["token"]
        running = start_face(rest.app.state.sessionmaker, tmp_path_factory.mktemp("face-ns"))
        yield {"face": running, "operator": token}
        running.stop()


def read_namespaces(face: dict) -> tuple[dict[str, int], dict[str, dict[str, object]]]:
    """The namespace indexes, and each Server/Namespaces object's properties by its
    NamespaceUri, read by the Operator."""
    async def run() -> tuple[dict, dict]:
        client = await secure_client(face["face"].endpoint, face["face"].client, "op",
                                     face["operator"])
        async with client:
            found: dict[str, dict[str, object]] = {}
            folder = client.get_node(ua.ObjectIds.Server_Namespaces)
            for meta in await folder.get_children(refs=ua.ObjectIds.HasComponent):
                props = {}
                for name in PROPERTIES:
                    dv = await (await meta.get_child(f"0:{name}")).read_data_value()
                    assert dv.StatusCode.is_good(), (name, dv.StatusCode)
                    props[name] = dv.Value
                props["BrowseName"] = await meta.read_browse_name()
                props["TypeDefinition"] = await meta.read_type_definition()
                found[props["NamespaceUri"].Value] = props
            return await namespaces(client), found
    return asyncio.run(run())


def test_server_namespaces_lists_pendant_beside_di_and_robotics(face: dict) -> None:
    ns, found = read_namespaces(face)
    assert {DI_URI, ROBOTICS_URI, PENDANT_URI} <= set(found)
    mine = found[PENDANT_URI]
    assert mine["TypeDefinition"] == ua.NodeId(ua.ObjectIds.NamespaceMetadataType)
    assert mine["BrowseName"] == ua.QualifiedName(PENDANT_URI, ns["pendant"])
    for name in PROPERTIES:  # Mandatory (Table 21/22), none a Good Null
        assert mine[name].Value is not None, name
    assert mine["NamespaceVersion"].Value == __version__ != ""
    assert mine["IsNamespaceSubset"].Value is False
    assert isinstance(mine["NamespacePublicationDate"].Value, dt.datetime)
    assert mine["StaticNodeIdTypes"].VariantType == ua.VariantType.Int32
    assert [ua.IdType(t) for t in mine["StaticNodeIdTypes"].Value] == [ua.IdType.Numeric]
    # the nodesets' own metadata stays as they ship it
    assert found[DI_URI]["NamespaceVersion"].Value == "1.04.0"
    assert found[DI_URI]["BrowseName"] == ua.QualifiedName(DI_URI, ns["di"])
    assert found[ROBOTICS_URI]["BrowseName"] == ua.QualifiedName(ROBOTICS_URI, ns["rob"])
    assert found[ROBOTICS_URI]["NamespaceVersion"].Value == "1.01"


def test_the_static_node_claims_hold_for_every_node_in_pendant_s_namespace(face: dict) -> None:
    """StaticNodeIdTypes [Numeric]: every Numeric node is a type node (PendantEventType and its
    properties), identical in every server; a String node is static only if the pattern
    says so (the metadata object), never a controller's node."""
    _, found = read_namespaces(face)
    pattern = re.compile(found[PENDANT_URI]["StaticStringNodeIdPattern"].Value)
    srv = face["face"].server.server

    async def nodes() -> dict[str, list]:
        idx = await srv.get_namespace_index(PENDANT_URI)
        out: dict[str, list] = {"numeric": [], "static": [], "live": []}
        for nid in list(srv.iserver.aspace.keys()):
            nd = srv.iserver.aspace[nid]
            if nid.NamespaceIndex != idx:
                continue
            name = nd.attributes[ua.AttributeIds.BrowseName].value.Value.Value.Name
            if isinstance(nid.Identifier, int):
                out["numeric"].append(name)
            else:
                out["static" if pattern.search(nid.Identifier) else "live"].append(nid.Identifier)
        return out

    seen = face["face"].run(nodes())
    assert sorted(seen["numeric"]) == sorted(["PendantEventType", "Kind", "Controller", "Payload",
                                              "EventRecordId"])
    assert sorted(seen["static"]) == sorted(["NamespaceMetadata"] + [
        f"NamespaceMetadata.{p}" for p in PROPERTIES])
    assert any("cell-1@" in i and i.endswith("ActualPosition") for i in seen["live"])
