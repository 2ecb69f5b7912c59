"""The OPC UA face's address space as a client relies on it (issue 20): NodeIds in pendant's
namespace that survive a restart and are never handed to another robot, names that cannot
collide with the face's own nodes, the Robotics enumerations as the nodeset defines them, and
CommitFrame's argument checks with the standard status codes."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator

import pytest
from api_helpers import ADMIN_TOKEN, C, make_client, ok
from asyncua import Client, Node, ua
from opcua_helpers import namespaces, secure_client, start_face


@pytest.fixture(scope="module")
def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:

    folder = tmp_path_factory.mktemp("opcua-nodes")
    with make_client(fresh_db()) as rest:
        face = start_face(rest.app.state.sessionmaker, folder)
        yield {"rest": rest, "face": face}
        face.stop()


def on_client(cell: dict, body):
    async def run():
        client = await secure_client(cell["face"].endpoint, cell["face"].client, "admin",
                                     ADMIN_TOKEN)
        async with client:
            return await body(client, await namespaces(client))
    return asyncio.run(run())


def poll(cell: dict, body, settled, timeout_s: float = 20.0):
    import time

    deadline = time.monotonic() + timeout_s
    while True:
        try:
            out = on_client(cell, body)
        except ua.UaStatusCodeError as err:
            out = err
        except (ConnectionError, OSError, asyncio.TimeoutError) as err:
            out = err  # the face busy adding a controller (a loaded machine): ask again
        if settled(out) or time.monotonic() > deadline:
            return out
        time.sleep(0.2)


async def system(client: Client, ns: dict, name: str) -> Node:
    return await client.nodes.objects.get_child([f"{ns['di']}:DeviceSet", f"{ns['pendant']}:{name}"])


async def a1(client: Client, ns: dict, name: str) -> Node:
    devices = await (await system(client, ns, name)).get_child([f"{ns['rob']}:MotionDevices"])
    (arm,) = await devices.get_children()
    return await arm.get_child([f"{ns['rob']}:Axes", f"{ns['rob']}:A1",
                                f"{ns['di']}:ParameterSet", f"{ns['rob']}:ActualPosition"])


async def below(node: Node) -> list[Node]:
    """``node`` and every Object and Variable under it (hierarchical references)."""
    found = [node]
    for child in await node.get_children(refs=ua.ObjectIds.HierarchicalReferences):
        if await child.read_node_class() in (ua.NodeClass.Object, ua.NodeClass.Variable,
                                             ua.NodeClass.Method):
            found += await below(child)
    return found


def test_every_instance_node_is_in_the_pendant_namespace_under_a_stable_key(cell: dict) -> None:
    async def body(client: Client, ns: dict) -> list[ua.NodeId]:
        pendant = await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant",
                                                        f"{ns['pendant']}:cell-1"])
        nodes = await below(await system(client, ns, "cell-1")) + await below(pendant)
        return [n.nodeid for n in nodes], ns["pendant"]

    ids, pendant_ns = on_client(cell, body)
    assert len(ids) > 300
    outside = [i for i in ids if i.NamespaceIndex != pendant_ns or i.NodeIdType != ua.NodeIdType.String]
    assert outside == []
    assert all(i.Identifier.startswith(("cell-1@", "Pendant.cell-1@")) for i in ids)
    assert len(set(ids)) == len(ids)


def test_node_ids_survive_a_restart_and_are_never_another_robots(cell: dict) -> None:
    made = ok(cell["rest"].post("/controllers", json={"name": "cell-9", "robot": "abb_irb120"}))

    async def a1_id(client: Client, ns: dict) -> tuple[ua.NodeId, float]:
        node = await a1(client, ns, "cell-9")
        return node.nodeid, await node.read_value()

    first, value = poll(cell, a1_id, lambda out: not isinstance(out, Exception))
    cell["face"].restart()

    async def read(client: Client, ns: dict, node_id: ua.NodeId = first) -> float:
        return await client.get_node(node_id).read_value()

    assert on_client(cell, read) == pytest.approx(value)  # the same id after a restart
    assert cell["rest"].delete(f"/controllers/{made['id']}").status_code == 204
    ok(cell["rest"].post("/controllers", json={"name": "cell-9", "robot": "kuka_kr6_r900_sixx"}))
    second, _ = poll(cell, a1_id, lambda out: not isinstance(out, Exception) and out[0] != first)
    assert second != first
    cell["face"].restart()
    with pytest.raises(ua.UaStatusCodeError) as err:
        on_client(cell, read)  # the deleted robot's id reads nothing, not the new robot's joint
    assert err.value.code == ua.StatusCodes.BadNodeIdUnknown


def test_a_controller_named_pendant_collides_with_nothing(cell: dict) -> None:
    ok(cell["rest"].post("/controllers", json={"name": "Pendant", "robot": "abb_irb120"}))

    async def both(client: Client, ns: dict) -> tuple[float, float]:
        return (await (await a1(client, ns, "Pendant")).read_value(),
                await (await a1(client, ns, "cell-1")).read_value())

    out = poll(cell, both, lambda o: not isinstance(o, Exception))
    assert not isinstance(out, Exception), out
    before = out[1]
    ok(cell["rest"].post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A1",
                                                  "increment": 1.5}))
    moved = poll(cell, both, lambda o: not isinstance(o, Exception) and o[1] != before)
    assert moved[1] == pytest.approx(before + 1.5)  # the poll goes on for every controller


def test_a_bounded_rotary_axis_is_motion_profile_rotary(cell: dict) -> None:
    async def body(client: Client, ns: dict) -> int:
        devices = await (await system(client, ns, "cell-1")).get_child([f"{ns['rob']}:MotionDevices"])
        (arm,) = await devices.get_children()
        return await (await arm.get_child([f"{ns['rob']}:Axes", f"{ns['rob']}:A1",
                                           f"{ns['rob']}:MotionProfile"])).read_value()

    assert on_client(cell, body) == 1  # AxisMotionProfileEnumeration ROTARY (2: ROTARY_ENDLESS)


@pytest.mark.parametrize("args, status, bad", [
    (["tool", 6, "123456", "x", ua.Variant(1, ua.VariantType.UInt64)],
     ua.StatusCodes.BadInvalidArgument, [2]),
    (["tool", 6, ua.Variant([True] * 6, ua.VariantType.Boolean), "x",
      ua.Variant(1, ua.VariantType.UInt64)], ua.StatusCodes.BadInvalidArgument, [2]),
    (["tool", 6, [0.0] * 6, "x", 1.0], ua.StatusCodes.BadInvalidArgument, [4]),
    (["tool", 6, [0.0] * 6], ua.StatusCodes.BadArgumentsMissing, []),
    (["tool", 6, [0.0] * 6, "x", ua.Variant(1, ua.VariantType.UInt64), "extra"],
     ua.StatusCodes.BadTooManyArguments, []),
])
def test_commit_frame_checks_its_arguments(cell: dict, args: list, status: int, bad: list) -> None:
    before = ok(cell["rest"].get(f"{C}/tools/6"))

    async def body(client: Client, ns: dict) -> ua.CallMethodResult:
        obj = await client.nodes.objects.get_child([f"{ns['pendant']}:Pendant",
                                                    f"{ns['pendant']}:cell-1"])
        method = await obj.get_child(f"{ns['pendant']}:CommitFrame")
        values = [a if isinstance(a, ua.Variant) else ua.Variant(a) for a in args]
        (res,) = await client.uaclient.call([ua.CallMethodRequest(
            ObjectId=obj.nodeid, MethodId=method.nodeid, InputArguments=values)])
        return res

    res = on_client(cell, body)
    assert res.StatusCode.value == status
    mismatched = [i for i, r in enumerate(res.InputArgumentResults)
                  if r.value == ua.StatusCodes.BadTypeMismatch]
    assert mismatched == bad
    assert ok(cell["rest"].get(f"{C}/tools/6")) == before


def test_no_variable_is_a_good_null(cell: dict) -> None:
    """Identification, SpeedOverride, SafetyState, TaskControl, FlangeLoad's structures: filled
    from the emulated cell; what it does not know (a motor's serial, its temperature) reads
    BadNotReadable, never Null with status Good."""
    async def body(client: Client, ns: dict) -> tuple[list[str], list[str], dict]:
        good_nulls, unreadable = [], []
        for node in await below(await system(client, ns, "cell-1")):
            if await node.read_node_class() != ua.NodeClass.Variable:
                continue
            dv = await node.read_data_value(raise_on_bad_status=False)
            path = (await node.read_browse_name()).Name
            if dv.StatusCode.is_good() and (dv.Value is None or dv.Value.Value is None):
                good_nulls.append(f"{node.nodeid.Identifier}")
            elif not dv.StatusCode.is_good():
                assert dv.StatusCode.value == ua.StatusCodes.BadNotReadable, path
                unreadable.append(path)
        devices = await (await system(client, ns, "cell-1")).get_child([f"{ns['rob']}:MotionDevices"])
        (arm,) = await devices.get_children()
        known = {k: await (await arm.get_child([f"{ns['di']}:{k}"])).read_value()
                 for k in ("Model", "ProductCode")}
        load = await arm.get_child([f"{ns['rob']}:FlangeLoad"])
        known["com"] = await (await load.get_child([f"{ns['rob']}:CenterOfMass"])).read_value()
        known["inertia"] = await (await load.get_child([f"{ns['rob']}:Inertia"])).read_value()
        return good_nulls, unreadable, known

    good_nulls, unreadable, known = on_client(cell, body)
    assert good_nulls == []
    assert set(unreadable) == {"MotorTemperature", "ProductCode", "SerialNumber"}
    assert known["Model"].Text == "KUKA KR 6 R900 sixx"
    assert known["ProductCode"] == "kuka_kr6_r900_sixx"
    assert isinstance(known["com"], ua.ThreeDFrame) and isinstance(known["inertia"], ua.ThreeDVector)


def test_frames_carry_units_rotation_order_and_source_timestamps(cell: dict) -> None:
    async def body(client: Client, ns: dict) -> dict:
        frame = await client.nodes.objects.get_child([
            f"{ns['pendant']}:Pendant", f"{ns['pendant']}:cell-1", f"{ns['pendant']}:Tools",
            f"{ns['pendant']}:Tool1", f"{ns['pendant']}:Frame"])
        coords = await frame.get_child(["0:CartesianCoordinates"])
        orient = await frame.get_child(["0:Orientation"])
        x = await coords.get_child(["0:X"])
        return {"length": await (await coords.get_child(["0:LengthUnit"])).read_value(),
                "angle": await (await orient.get_child(["0:AngleUnit"])).read_value(),
                "order": (await orient.read_description()).Text,
                "x_time": (await x.read_data_value()).SourceTimestamp,
                "namespaces": await client.get_namespace_array()}

    got = on_client(cell, body)
    assert (got["length"].DisplayName.Text, got["length"].UnitId) == ("mm", 5066068)  # MMT
    assert (got["angle"].DisplayName.Text, got["angle"].UnitId) == ("°", 17476)  # DD
    assert "A about X" in got["order"] and "Rz(C) Ry(B) Rx(A)" in got["order"]
    assert got["x_time"] is not None
    assert "urn:pendant:opcua" in got["namespaces"]
