"""Every shell snippet in README.md and docs/ runs as written (issue 14).

A snippet is a fenced block tagged ``bash``, ``sh``, ``shell`` or ``console``. The snippets of
one document run in order, in one ``bash`` with ``set -euo pipefail`` (a later snippet may use
a variable an earlier one set, as a reader's shell would), in a scratch folder that links to
the repository (``docs/`` is a copy, so a snippet may write there). When a document talks to
``http://127.0.0.1:8000``, the real service runs on a fresh SQLite file at a free port and
the test writes that port in place of 8000; ``PENDANT_DB_URL`` points the CLI at the same
file (the reader's default database), and ``TOKEN`` holds its first Administrator's token (the
login link's token a reader has after the first start); no other ``PENDANT_*`` variable is
set, so a snippet whose CLI command needs ``PENDANT_TOKEN`` sets it where the reader sees it. A snippet passes when bash exits 0 and nothing printed a traceback or a refused
request (``"detail"``).

**Illustrative snippets.** A snippet that cannot run as written (the set-up itself, one that
rewrites a committed file) starts with the visible line ``# illustrative: <why>`` and is only
checked for that reason. A command block left untagged is an error: tag it ``bash``.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
SHELL = {"bash", "sh", "shell", "console"}
MARK = "# illustrative:"
FENCE = re.compile(r"^```([^\n`]*)\n(.*?)^```[ \t]*$", re.S | re.M)
COMMAND = re.compile(r"^(pendant|curl|python3?|pip|bash|uvicorn|docker|alembic|[A-Z_]+=\S)\b")
SERVICE = "127.0.0.1:8000"


@dataclass(frozen=True)
class Snippet:
    path: Path
    line: int
    lang: str
    text: str

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line}"

    @property
    def illustrative(self) -> bool:
        return self.text.lstrip().startswith(MARK)


def blocks(path: Path) -> list[Snippet]:
    text = path.read_text(encoding="utf-8")
    return [Snippet(path, text.count("\n", 0, m.start()) + 1, m.group(1).strip().split(" ")[0], m.group(2))
            for m in FENCE.finditer(text)]


def shell_snippets(path: Path) -> list[Snippet]:
    return [b for b in blocks(path) if b.lang in SHELL]


RUNNABLE = [p for p in DOCUMENTS if any(not s.illustrative for s in shell_snippets(p))]


def test_command_blocks_are_tagged_as_shell():
    untagged = [b.where for p in DOCUMENTS for b in blocks(p)
                if not b.lang and COMMAND.match(b.text.lstrip())]
    assert not untagged, f"tag these command blocks ```bash so the snippet test runs them: {untagged}"


def test_illustrative_snippets_say_why():
    marked = [s for p in DOCUMENTS for s in shell_snippets(p) if s.illustrative]
    for s in marked:
        reason = s.text.lstrip()[len(MARK):].splitlines()[0].strip()
        assert len(reason) >= 10, f"{s.where}: say why the snippet is illustrative"
    # the marker is rare: most snippets run
    total = sum(len(shell_snippets(p)) for p in DOCUMENTS)
    assert len(marked) <= total // 3, [s.where for s in marked]


def scratch_folder(tmp: Path) -> Path:
    """A folder that looks like the repository: links to it, with a copy of docs/."""
    work = tmp / "repo"
    work.mkdir()
    for entry in ROOT.iterdir():
        if entry.name in {"docs", ".git"} or entry.name.startswith("."):
            continue
        (work / entry.name).symlink_to(entry)
    shutil.copytree(ROOT / "docs", work / "docs")
    return work


@pytest.mark.parametrize("document", RUNNABLE, ids=[str(p.relative_to(ROOT)) for p in RUNNABLE])
def test_the_shell_snippets_of_a_document_run(document: Path, tmp_path: Path):
    from browser_helpers import serve

    snippets = [s for s in shell_snippets(document) if not s.illustrative]
    work = scratch_folder(tmp_path)
    db_url = f"sqlite:///{tmp_path / 'pendant.db'}"
    from api_helpers import ADMIN_TOKEN

    # the reader's shell holds the first start's token as TOKEN (docs/api.md, Authentication),
    # and nothing else: a snippet whose CLI command reads PENDANT_TOKEN sets it visibly (it
    # once did not, and passed here because this test set it for the reader)
    env = {k: v for k, v in os.environ.items() if not k.startswith("PENDANT_")}
    env.update({"PYTHONPATH": str(ROOT), "PENDANT_DB_URL": db_url, "TOKEN": ADMIN_TOKEN})
    if shutil.which("pendant") is None:  # the console script of `pip install -e .`
        bin_dir = tmp_path / "bin"
        bin_dir.mkdir()
        (bin_dir / "pendant").write_text('#!/bin/sh\nexec python3 -m server.cli "$@"\n')
        (bin_dir / "pendant").chmod(0o755)
        env["PATH"] = f"{bin_dir}{os.pathsep}{env['PATH']}"
    script = "\n".join(f"# --- {s.where}\n{s.text}" for s in snippets)
    needs_service = SERVICE in script
    with serve(db_url) if needs_service else _no_service() as url:
        if needs_service:
            script = script.replace(SERVICE, url.removeprefix("http://"))
        run = subprocess.run(["bash", "-c", "set -euo pipefail\n" + script], cwd=work, env=env,
                             capture_output=True, text=True, timeout=600)
    out = run.stdout + run.stderr
    print(out[-4000:])  # pytest -s shows what the snippets printed
    where = ", ".join(s.where for s in snippets)
    assert run.returncode == 0, f"{where}: exit {run.returncode}\n{out[-3000:]}"
    assert "Traceback" not in out, f"{where}:\n{out[-3000:]}"
    assert '"detail"' not in run.stdout, f"{where}: a request was refused:\n{run.stdout[-3000:]}"


class _no_service:
    def __enter__(self) -> str:
        return ""

    def __exit__(self, *exc: object) -> None:
        return None
