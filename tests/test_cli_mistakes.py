"""The ``pendant`` command meets a person's mistakes: each is one line on stderr that says
what is wrong and what to type, and a non-zero exit; never a traceback (issue 14)."""

from __future__ import annotations

import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from server import __version__
from server.cli.main import main
from server.menus import METHODS

ROOT = Path(__file__).resolve().parent.parent


def one_line_error(capsys, argv: list[str]) -> str:  # noqa: ANN001
    """Run ``pendant argv``; assert exit 2 and exactly one stderr line; return that line."""
    assert main(argv) == 2
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err and captured.out == ""
    return lines[0]


@pytest.mark.parametrize(("url", "says"), [
    ("sqllite:///pendant.db", "unknown database 'sqllite' in 'sqllite:///pendant.db'; did you mean sqlite?"),
    ("pendant.db", "'pendant.db' is not a database URL; for a SQLite file write sqlite:///"),
    ("/var/tmp/pendant.db", "is not a database URL; for a SQLite file write sqlite:////var/tmp/pendant.db"),
    ("sqlite:////no/such/folder/pendant.db", "the folder /no/such/folder of 'sqlite:////no/such/folder/pendant.db' "
                                             "does not exist; create it (mkdir -p /no/such/folder)"),
    ("postgresql+psycopg2://robot@localhost/pendant", "needs the Python driver 'psycopg2', which is not "
                                                      "installed: pip install psycopg2-binary"),
])
def test_a_db_url_typo_is_one_line_naming_the_fix(capsys, url, says):
    for argv in (["export", "cell-1", "--db", url], ["serve", "--port", "0", "--db", url]):
        line = one_line_error(capsys, argv)
        assert line.startswith("pendant: --db: ") and says in line, line


def test_a_bad_pendant_db_url_variable_is_named(capsys, monkeypatch):
    monkeypatch.setenv("PENDANT_DB_URL", "sqllite:///x.db")
    assert one_line_error(capsys, ["export", "cell-1"]).startswith("pendant: PENDANT_DB_URL: unknown database")


def test_a_database_that_refuses_the_connection_is_one_line(capsys):
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    line = one_line_error(capsys, ["export", "cell-1", "--db", f"postgresql+psycopg://robot@127.0.0.1:{port}/p"])
    assert line.startswith(f"pendant: --db: cannot open 'postgresql+psycopg://robot@127.0.0.1:{port}/p': ")


def test_a_port_in_use_suggests_another_port(capsys, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        line = one_line_error(capsys, ["serve", "--port", str(port), "--db", f"sqlite:///{tmp_path / 'p.db'}"])
    assert line == (f"pendant: --port: port {port} on 127.0.0.1 is in use (another pendant serve?); "
                    f"choose another: pendant serve --port {port + 1}")


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"pendant {__version__}"
    assert __version__[0].isdigit()


def test_help_is_plain_text_with_defaults_and_the_methods_once(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")  # argparse wraps to the terminal: one line per option
    def help_of(*argv: str) -> str:
        with pytest.raises(SystemExit):
            main([*argv, "--help"])
        return capsys.readouterr().out

    top = help_of()
    assert "``" not in top and ":func:" not in top
    for command in ("serve", "calibrate", "export", "analyze", "simulate"):
        assert command in top
    serve = help_of("serve")
    assert "(default: 127.0.0.1)" in serve and "(default: 8000)" in serve and "--db URL" in serve
    export = help_of("export")
    assert "(default: kuka)" in export and "$config.dat" in export
    calibrate = help_of("calibrate")
    for name, m in METHODS.items():
        # once, in the methods list (a whole name: ext.root_point is in ext.root_point_numeric)
        assert len(re.findall(rf"(?<![\w.]){re.escape(name)}(?![\w.])", calibrate)) == 1, name
        assert f"{name}  " in calibrate and m.title in calibrate
    assert "usage: pendant calibrate [-h]" in calibrate and "METHOD FILE" in calibrate


def test_an_unknown_method_is_one_line(capsys, tmp_path):
    f = tmp_path / "p.json"
    f.write_text(json.dumps({"points": []}))
    line = one_line_error(capsys, ["calibrate", "tool.xyz_4pt", str(f)])
    assert line.startswith("pendant: method: unknown method 'tool.xyz_4pt'; one of tool.xyz_4point")


def test_two_ctrl_c_during_an_analysis_stop_with_one_line(tmp_path):
    """``pendant serve`` analysing the real UR10 recording (a job in its worker); Ctrl-C twice:
    one line, exit 130, no CancelledError trace; the recording stored before stays in the
    database (the job is taken up again at the next start)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    db = tmp_path / "p.db"
    from api_helpers import ADMIN_TOKEN

    auth = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PENDANT_ADMIN_TOKEN": ADMIN_TOKEN}
    proc = subprocess.Popen([sys.executable, "-m", "server.cli", "serve", "--port", str(port), "--db", f"sqlite:///{db}"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env, cwd=ROOT,
                            start_new_session=True)  # its own process group, as in a terminal
    url = f"http://127.0.0.1:{port}"
    try:
        for _ in range(300):
            try:
                urllib.request.urlopen(urllib.request.Request(url + "/controllers", headers=auth),
                                       timeout=1)
                break
            except OSError:
                time.sleep(0.05)
        doc = (ROOT / "tests/data/ur10-laser-tracker/recording-series-d.json").read_bytes()
        rid = json.load(urllib.request.urlopen(urllib.request.Request(
            url + "/recordings", data=doc, headers={"Content-Type": "application/json", **auth})))["id"]
        analysis = subprocess.Popen([sys.executable, "-c", "import sys, urllib.request; urllib.request.urlopen("
                                     f"urllib.request.Request('{url}/recordings/{rid}/analyze', method='POST', "
                                     f"headers={auth!r}))"],
                                    stderr=subprocess.DEVNULL)
        time.sleep(0.5)  # the analysis of 632 poses takes over a second
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole foreground group:
        time.sleep(0.2)                     # the service and its job workers
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        analysis.wait(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "CancelledError" not in err, err
    said = [line for line in err.strip().splitlines() if line.startswith("pendant:")
            and not line.startswith(("pendant: database:", "pendant: serving"))]  # the start
    assert len(said) == 1 and said[0] in ("pendant: interrupted", said[0]) and (
        said[0] == "pendant: interrupted" or "in progress abandoned" in said[0]), err
    with __import__("sqlite3").connect(db) as con:
        assert con.execute("select count(*) from stored_document").fetchone()[0] >= 1
