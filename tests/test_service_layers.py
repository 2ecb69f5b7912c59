"""The service layer knows nothing of its faces (docs/architecture.md): no module of
server/service imports a face (REST's routers, request path, app; OPC UA, RWS, KVP) or the web
framework, at the top or inside a function. The REST input models (server/api/schemas.py) are
the one exception: an operation may take one as its argument."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FACES = ("server.api", "server.opcua", "server.rws", "server.kvp", "server.cli", "fastapi",
         "starlette")
ALLOWED = ("server.api.schemas",)


def imported(path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in ``path``, function-local ones included."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            out += [(node.lineno, node.module)]
            out += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return out


def is_face(module: str) -> bool:
    def under(m: str, pkg: str) -> bool:
        return m == pkg or m.startswith(pkg + ".")
    return any(under(module, f) for f in FACES) and not any(under(module, a) for a in ALLOWED) \
        and module != "server.api"


def test_no_service_module_imports_a_face():
    files = sorted((ROOT / "server" / "service").glob("*.py"))
    assert len(files) >= 8, files  # the service's modules are where the test looks
    wrong = [f"{p.relative_to(ROOT)}:{line}: {m}" for p in files for line, m in imported(p)
             if is_face(m)]
    assert wrong == []


def test_the_check_finds_a_face_import():
    assert is_face("server.api.routers.common")
    assert is_face("server.api.deps")
    assert is_face("fastapi")
    assert not is_face("server.api.schemas")
    assert not is_face("server.service.robot")


WRITES = {"add", "add_all", "delete", "merge", "flush", "commit", "store_document", "enqueue",
          "write_session", "lock_controller", "record"}  # a session's writes, crud's, audit's


def writes_in(path: Path) -> list[tuple[int, str]]:
    """(line, call) of every call in ``path`` that writes rows itself: ``db.add(...)``,
    ``store_document(...)``, ``jobs.enqueue(...)``, ``audit.record(...)``..."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            router = isinstance(f, ast.Attribute) and ast.unparse(f.value) == "router"
            if name in WRITES and not router:  # @router.delete(...) declares a route
                out.append((node.lineno, ast.unparse(f)))
    return out


def test_no_route_writes_the_database_itself():
    """A REST route reads its body, calls one operation of server/service and presents the
    answer: the write (rows, audit, outbox, queued jobs) is the operation's."""
    files = sorted((ROOT / "server" / "api" / "routers").glob("*.py"))
    assert len(files) >= 10, files
    wrong = [f"{p.relative_to(ROOT)}:{line}: {call}" for p in files for line, call in writes_in(p)]
    assert wrong == []


def test_the_check_finds_a_route_that_writes(tmp_path: Path):
    route = tmp_path / "route.py"
    route.write_text("def create(db, body):\n    db.add(body)\n    audit.record(db, 'x')\n"
                     "    return store_document(db, 'recordings', body)\n", encoding="utf-8")
    assert [call for _, call in writes_in(route)] == ["db.add", "audit.record", "store_document"]
