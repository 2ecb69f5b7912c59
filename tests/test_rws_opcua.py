"""A tooldata written through the RWS face (abb-robot-client) reads back through OPC UA's
ReadFrame: the faces share the service's slots, versions and database."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from api_helpers import make_client, ok
from browser_helpers import free_port
from opcua_helpers import start_face
from server.rws import digest, ops
from server.rws.app import RwsFace, create_rws_app
from server.rws.service import serve_asgi

rws = pytest.importorskip("abb_robot_client.rws")
pytest.importorskip("asyncua")

from test_opcua import poll  # noqa: E402  (its helpers, not its fixtures)
from test_opcua import pendant as pendant_object  # noqa: E402


@pytest.fixture(scope="module")
def face(fresh_db, tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:  # noqa: ANN001
    """REST, the OPC UA face (its PKI trusting one client certificate) and the RWS face on
    one database."""
    with make_client(fresh_db()) as rest:
        cid = ok(rest.post("/controllers", json={"name": "abb-1", "robot": "abb_irb120"}))["id"]
        ok(rest.post("/users", json={"name": "expert", "role": "Expert"}))
        maker = rest.app.state.sessionmaker
        with maker() as db:
            ops.set_rws_ha1(db, "expert", digest.ha1("expert", "expert-secret"))
            db.commit()
        opcua = start_face(maker, tmp_path_factory.mktemp("face"))
        port = free_port()
        running = serve_asgi(create_rws_app(RwsFace(maker)), "127.0.0.1", port, "rws-test")
        try:
            yield {"rest": rest, "server": opcua.server, "cert": opcua.client, "cid": cid,
                   "url": f"http://127.0.0.1:{port}"}
        finally:
            running.stop()
            opcua.stop()


def test_tooldata_set_through_rws_reads_back_through_opcua(face: dict) -> None:
    c = rws.RWS(face["url"], "expert", "expert-secret")
    c.set_rapid_variable("tool2", "[TRUE,[[10,-20,150.5],[1,0,0,0]],[1.5,[0,0,40],[1,0,0,0],0,0,0]]")
    version = int(face["rest"].get(f"/controllers/{face['cid']}/tools/2").headers["ETag"]
                  .strip('W/"'))

    async def body(client, ns):  # noqa: ANN001, ANN202
        obj = await pendant_object(client, ns, "abb-1")
        return await obj.call_method(f"{ns['pendant']}:ReadFrame", "tool", 2)

    out = poll(face, body, lambda o: not isinstance(o, Exception) and o[3] == version)
    name, kind, xyzabc, seen = out
    assert seen == version and kind == "tool"
    assert xyzabc == pytest.approx([10.0, -20.0, 150.5, 0.0, 0.0, 0.0], abs=1e-9)
