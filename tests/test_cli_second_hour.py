"""The CLI in a new user's second hour (issue 27): ``pendant slot`` exits 2 with one readable
line (a bad --pose, a 401, a 404), finds the service from --url / --service or
$PENDANT_SERVICE; a missing file is said as the other mistakes are; ``... | head`` prints no
"Broken pipe"; ``--help`` states every default; a CLI import is audited as its user."""

from __future__ import annotations

import argparse
import getpass
import os
import subprocess
import sys
from pathlib import Path


from server.cli.main import build_parser, main

ROOT = Path(__file__).resolve().parent.parent
DATA = Path(__file__).parent / "data"


def one_line(capsys, argv: list[str]) -> str:  # noqa: ANN001
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in captured.err, captured.err
    return lines[0]


def test_slot_bad_pose_exits_2_before_any_request(capsys):
    line = one_line(capsys, ["slot", "tool", "3", "--url", "http://127.0.0.1:9", "--pose", "1,2,3"])
    assert line == "pendant: --pose: needs x,y,z,a,b,c (6 numbers), got '1,2,3'"


def test_slot_refusals_are_one_readable_line_and_the_url_comes_from_the_environment(
        db_url, capsys, monkeypatch):  # noqa: ANN001
    from api_helpers import ADMIN_TOKEN
    from browser_helpers import serve

    with serve(db_url) as url:
        monkeypatch.setenv("PENDANT_SERVICE", url)  # no --url: the variable names the service
        monkeypatch.delenv("PENDANT_TOKEN", raising=False)
        line = one_line(capsys, ["slot", "tool", "3"])
        assert line.startswith("pendant: 401: ") and "PENDANT_TOKEN" in line and "{" not in line, line
        monkeypatch.setenv("PENDANT_TOKEN", ADMIN_TOKEN)
        line = one_line(capsys, ["slot", "tool", "99"])
        assert line.startswith("pendant: 404: ") and "{" not in line and "99" in line, line
        assert main(["slot", "tool", "3"]) == 0
        assert capsys.readouterr().out.startswith("tool 3 ")
        assert main(["slot", "tool", "3", "--service", url, "--name", "pointer"]) == 0
        assert "'pointer'" in capsys.readouterr().out


def test_a_missing_file_is_said_as_the_other_mistakes(capsys, db_url):  # noqa: ANN001
    line = one_line(capsys, ["import", "no-such.dat", "--controller", "cell-1", "--db", db_url])
    assert line == "pendant: no-such.dat: No such file or directory"


def test_a_closed_pipe_prints_no_broken_pipe():
    """``pendant analyze REC | head``: the reader leaves; pendant says nothing about it."""
    read, write = os.pipe()
    os.close(read)  # the reader has gone before the first line
    try:
        r = subprocess.run([sys.executable, "-m", "server.cli", "analyze",
                            str(ROOT / "web" / "example-recording.json")], stdout=write,
                           stderr=subprocess.PIPE, text=True, cwd=ROOT, timeout=120, check=False,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
    finally:
        os.close(write)
    assert "Broken pipe" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip() == "" and r.returncode == 141, (r.returncode, r.stderr)


def test_help_states_every_default():
    def walk(p: argparse.ArgumentParser, path: str):  # noqa: ANN202
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, child in a.choices.items():
                    yield from walk(child, f"{path} {name}")
            elif a.option_strings and a.help != argparse.SUPPRESS and not (
                    a.default is None or a.default is False or a.default in (argparse.SUPPRESS, "", [])):
                yield path, a, p

    missing = []
    for path, action, parser in walk(build_parser(), "pendant"):
        text = parser.format_help()
        formatter = parser._get_formatter()
        shown = formatter._expand_help(action) if action.help else ""
        d = action.default
        value = str(int(d)) if isinstance(d, float) and d.is_integer() else str(d)
        if "default" not in shown or (value not in shown and "$" not in shown):
            missing.append(f"{path} {action.option_strings[0]} (default {action.default!r})")
        assert text  # the help renders
    assert not missing, "--help does not state these defaults: " + ", ".join(missing)


def test_a_cli_import_is_audited_as_its_user(db_url, capsys):  # noqa: ANN001
    from sqlalchemy import create_engine, text

    assert main(["import", str(DATA / "kuka_cell7_config.dat"), "--controller", "cell-1",
                 "--db", db_url]) == 0
    capsys.readouterr()
    with create_engine(db_url).connect() as c:
        rows = c.execute(text("select user_name, source from audit_record "
                              "where action = 'frame.import'")).all()
    assert rows and set(rows) == {(f"cli:{getpass.getuser()}", "cli")}, rows
