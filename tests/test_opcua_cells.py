"""A plant's worth of cells on the OPC UA face: a cell is a copy of a template cell (not
asyncua's ``instantiate``, which browses the nodeset's types for every node, about a second a
cell with the face's event loop blocked), the copy is the cell ``instantiate`` makes, and a
poll reads in full only the controllers that changed. benchmarks/opcua_cells.py has the
figures for 300 cells."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator

import pytest
from api_helpers import C, edit_slot, make_client, ok, open_session
from asyncua import ua
from opcua_helpers import start_face

from server.opcua import space, state


@pytest.fixture(scope="module")
def cell(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    with make_client(fresh_db()) as rest:
        face = start_face(rest.app.state.sessionmaker, tmp_path_factory.mktemp("opcua-cells"))
        yield {"rest": rest, "face": face}
        face.stop()


def dump(aspace, root: ua.NodeId) -> dict[str, tuple]:
    """``root``'s subtree as comparable values: each node's attributes (a value without its
    timestamps) and references."""
    out: dict[str, tuple] = {}
    todo = [root]
    while todo:
        nid = todo.pop()
        nd = aspace[nid]
        attrs = {}
        for attr, av in nd.attributes.items():
            dv = av.value
            attrs[attr.name] = (repr(dv.Value), repr(dv.StatusCode)) if dv is not None else None
        refs = sorted(repr((r.ReferenceTypeId, r.IsForward, r.NodeId, r.BrowseName,
                            r.DisplayName, r.NodeClass, r.TypeDefinition)) for r in nd.references)
        out[nid.to_string()] = (attrs, refs)
        todo += [r.NodeId for r in nd.references if r.IsForward and r.NodeId not in [root]
                 and isinstance(r.NodeId.Identifier, str)
                 and r.NodeId.Identifier.startswith(f"{root.Identifier}.")]
    return out


def test_a_copied_cell_is_the_cell_instantiate_builds(cell: dict) -> None:
    """The served cell (a copy of the template) against the same controller built the slow
    way: the same NodeIds, names, references and values, node for node."""
    from server.opcua.service import METHODS

    face = cell["face"]
    srv = face.server

    async def compare() -> tuple[dict, dict, int]:
        cid = min(srv.cells)
        nodes, st = srv.cells[cid], srv.states[cid]
        aspace = srv.server.iserver.aspace
        roots = (nodes.system.nodeid, nodes.pendant.nodeid)
        copied = {k: v for r in roots for k, v in dump(aspace, r).items()}
        for r in roots:
            space.remove_ids(srv.server, r)
        built, _identity = await space._build_cell(srv.server, srv.ns_ids, st)
        for name, inputs, outputs in METHODS:
            await space.add_method_node(srv.server, built.pendant, name, srv.ns_ids[2],
                                        inputs, outputs)
        srv._link_methods(cid, built)
        slow = {k: v for r in roots for k, v in dump(aspace, r).items()}
        return copied, slow, len(copied)

    copied, slow, n = face.run(compare())
    assert n > 1000  # the MotionDeviceSystem and the 48 slots' frames
    assert sorted(copied) == sorted(slow)
    differ = [k for k in copied if copied[k] != slow[k]]
    assert not differ, [(k, copied[k], slow[k]) for k in differ[:3]]


def test_adding_a_cell_browses_nothing_and_leaves_the_loop_free(cell: dict) -> None:
    """A new controller (the shape of one served already) is added without one Browse,
    TranslateBrowsePath or AddNodes call (asyncua's instantiate: thousands a cell), and the
    face's loop answers between (a tick every 10 ms never waits a second: it waited 1.3 s
    and more for each cell)."""
    face, rest = cell["face"], cell["rest"]
    srv = face.server
    calls = {"browse": 0, "translate": 0, "add_nodes": 0}
    view, mgt = srv.server.iserver.view_service, srv.server.iserver.node_mgt_service
    gaps: list[float] = []
    stop = asyncio.Event()

    def counted(obj, method: str, key: str):
        orig = getattr(obj, method)

        def wrapper(*a, **kw):
            calls[key] += 1
            return orig(*a, **kw)
        setattr(obj, method, wrapper)

    async def probe() -> None:
        last = time.perf_counter()
        while not stop.is_set():
            await asyncio.sleep(0.01)
            now = time.perf_counter()
            gaps.append(now - last - 0.01)
            last = now

    async def watch() -> asyncio.Task:
        counted(view, "browse", "browse")
        counted(view, "translate_browsepaths_to_nodeids", "translate")
        counted(mgt, "add_nodes", "add_nodes")
        return asyncio.create_task(probe())

    task = face.run(watch())
    try:
        made = ok(rest.post("/controllers", json={"name": "cell-new"}))
        deadline = time.monotonic() + 60
        while made["id"] not in srv.cells and time.monotonic() < deadline:
            time.sleep(0.05)
        assert made["id"] in srv.cells
    finally:
        async def unwatch() -> None:
            for name in ("browse", "translate_browsepaths_to_nodeids"):
                view.__dict__.pop(name, None)
            mgt.__dict__.pop("add_nodes", None)
            stop.set()
            await task
        face.run(unwatch())
    assert calls == {"browse": 0, "translate": 0, "add_nodes": 0}
    assert max(gaps) < 1.0, f"the loop was blocked {max(gaps):.2f} s"


def test_a_poll_reads_only_the_controllers_that_changed(cell: dict,
                                                        monkeypatch: pytest.MonkeyPatch) -> None:
    rest = cell["rest"]
    make_session = rest.app.state.sessionmaker
    ok(rest.post("/controllers", json={"name": "cell-quiet"}))
    read: list[str] = []
    full = state.controller_state
    me = threading.get_ident()

    def counting(db, c, slots=None):  # the face's own poll runs on its thread: not this reader's
        if threading.get_ident() == me:
            read.append(c.name)
        return full(db, c, slots)
    monkeypatch.setattr(state, "controller_state", counting)

    reader = state.CellReader()
    first = reader.read(make_session)
    assert sorted(read) == sorted(st.name for st in first.values()) and len(first) >= 2
    read.clear()
    again = reader.read(make_session)
    assert read == [] and all(again[cid] is first[cid] for cid in first)

    cid = min(first)
    name = first[cid].name
    quiet = next(c for c, st in first.items() if st.name == "cell-quiet")
    changes = [  # a slot, a jog, a session, an audit record naming the controller
        lambda: ok(edit_slot(rest, f"{C}/tools/5", {"name": "probe"})),
        lambda: ok(rest.post(f"{C}/robot/jog", json={"mode": "joint", "axis": "A2",
                                                      "increment": 1.0})),
        lambda: open_session(rest, "tool.xyz_4point", 6),
    ]
    for change, slots_changed in zip(changes, (True, False, False)):
        before = reader.states[cid]
        change()
        read.clear()
        after = reader.read(make_session)
        assert read == [name], read
        assert after[cid] != before
        assert after[quiet] is first[quiet]
        # a jog or a session keeps the cell's slots: they are not read again
        assert (after[cid].slots is before.slots) is not slots_changed
    assert after[cid].slot("tool", 5).name == "probe"
    assert after[cid].sessions
