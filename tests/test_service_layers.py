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
