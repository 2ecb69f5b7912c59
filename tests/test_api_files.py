"""Controller files through the API and the CLI (issue 7): an import replaces each slot it
names whole, a dry run writes nothing, bad files are refused naming the line and the field
with the stored tables unchanged (a JSON backup's hash before and after), and the export
patches the imported file."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from api_helpers import C, finish_job, make_client, ok
from server.cli.main import main

DATA = Path(__file__).parent / "data"
KUKA = (DATA / "kuka_cell7_config.dat").read_bytes().decode()
ABB = (DATA / "abb_cell7.mod").read_text()


def backup_hash(client) -> str:
    """The hash of the tables' JSON backup without its time stamps of reading."""
    return hashlib.sha256(client.get(f"{C}/export", params={"format": "json"}).content).hexdigest()


def imp(client, fmt: str, text: str, dry_run: bool = False):  # noqa: ANN201
    return client.post(f"{C}/import", json={"format": fmt, "text": text, "dry_run": dry_run})


def test_import_then_export_is_byte_identical_and_an_edit_touches_only_its_slot(client):
    res = ok(imp(client, "kuka", KUKA))
    assert res["entries"] == 9 and res["skipped"] == []
    assert client.get(f"{C}/export", params={"format": "kuka"}).text == KUKA
    ok(client.put(f"{C}/tools/2", json={"pose": {"x": 148.32, "y": -2.105, "z": 357.125,
                                                 "a": 0, "b": 67.5, "c": 0}}, headers={"If-Match": "*"}))
    out = client.get(f"{C}/export", params={"format": "kuka"}).text
    changed = [a for a, b in zip(KUKA.splitlines(), out.splitlines()) if a != b]
    assert changed == ["TOOL_DATA[2]={X 148.320,Y -2.10500,Z 356.870,A 0.0,B 67.5000,C 0.0}"]
    assert len(out.splitlines()) == len(KUKA.splitlines())
    other = f"/controllers/{ok(client.post('/controllers', json={'name': 'cell-7'}))['id']}"
    ok(client.post(f"{other}/import", json={"format": "abb", "text": ABB}))
    assert client.get(f"{other}/export", params={"format": "abb"}).text == ABB


def line_of(text: str, start: str) -> int:
    """The 1-based line that starts with ``start``."""
    return next(i for i, s in enumerate(text.splitlines(), 1) if s.lstrip().startswith(start))


def test_kinds_loads_and_units_reach_the_tables(client):
    ok(imp(client, "kuka", KUKA))
    panel = ok(client.get(f"{C}/tools/3"))
    assert panel["kind"] == "workpiece" and panel["name"] == "Door panel LH"
    assert panel["load"]["inertia_axes_deg"] == [89.777, -0.721, 0.991]  # CM A, B, C
    assert ok(client.get(f"{C}/tools/1"))["kind"] == "tool"  # TOOL_TYPE #BASE
    assert ok(client.get(f"{C}/bases/2"))["kind"] == "fixed_tool"  # BASE_TYPE #TCP
    turntable = ok(client.get(f"{C}/bases/3"))
    assert (turntable["kind"], turntable["mech_unit"]) == ("coordinated_base", "DKP_400_1")
    ok(imp(client, "abb", ABB))
    nozzle = ok(client.get(f"{C}/bases/1"))
    assert nozzle["kind"] == "fixed_tool" and nozzle["load"]["mass_kg"] == 4.5
    assert ok(client.get(f"{C}/bases/3"))["mech_unit"] == "STN1"
    assert "4.5,[0,12,135]" in client.get(f"{C}/export", params={"format": "abb"}).text


def test_an_import_replaces_each_named_slot_whole(client):
    ok(client.put(f"{C}/tools/4", json={"name": "spindle", "load": {"mass_kg": 9.0}}, headers={"If-Match": "*"}))
    ok(client.put(f"{C}/tools/9", json={"name": "left over", "pose": {"z": 50}}, headers={"If-Match": "*"}))
    ok(imp(client, "kuka", KUKA))
    assert ok(client.get(f"{C}/tools/4"))["load"] is None  # LOAD_DATA[4] M -1: not set
    assert ok(client.get(f"{C}/tools/9"))["name"] == ""  # the file lists slot 9 as unused
    assert ok(client.get(f"{C}/tools/2"))["load"]["mass_kg"] == 6.8
    # the ABB module names tool 2 (tTorch) with a load and tool 4 (tSpare) without one
    ok(client.put(f"{C}/tools/4", json={"load": {"mass_kg": 9.0}}, headers={"If-Match": "*"}))
    ok(imp(client, "abb", ABB))
    assert ok(client.get(f"{C}/tools/4"))["load"] is None
    hist = ok(client.get(f"{C}/tools/4/history"))
    assert hist[-1]["reason"] == "import" and hist[-1]["after"]["mass_kg"] is None


def test_dry_run_shows_before_after_kind_changes_and_skips_and_writes_nothing(client):
    ok(imp(client, "kuka", KUKA))
    before = backup_hash(client)
    res = ok(imp(client, "abb", ABB, dry_run=True))
    assert backup_hash(client) == before
    assert res["dry_run"] is True
    slots = {(s["table"], s["number"]): s for s in res["slots"]}
    s3 = slots[("tool", 3)]  # KUKA: held door panel; ABB: tPen, a tool
    assert s3["kind_change"] == "workpiece -> tool" and s3["changed"]
    assert (s3["before"]["name"], s3["after"]["name"]) == ("Door panel LH", "tPen")
    assert s3["line"] == 16
    assert [(k["line"], k["field"]) for k in res["skipped"]] == [(37, "tSet"), (39, "tCopy"),
                                                               (40, "tTemp")]
    assert client.get(f"{C}/export", params={"format": "abb"}).status_code == 200


BAD = {  # what is wrong: (format, text, line, field)
    "X 2.0E+07": ("kuka", KUKA.replace("Z 180.000,A 0.0", "Z 2.0E+07,A 0.0"),
                  line_of(KUKA, "TOOL_DATA[1]="), "TOOL_DATA[1].Z"),
    "B 9E+99": ("kuka", KUKA.replace("B 67.5000,C 0.0}", "B 9E+99,C 0.0}"),
                line_of(KUKA, "TOOL_DATA[2]="), "TOOL_DATA[2].B"),
    "cut before TOOL_DATA[5]": ("kuka", KUKA[:KUKA.index("TOOL_DATA[5]=")],
                                line_of(KUKA, "TOOL_DATA[4]="), "ENDDAT"),
    "cut before BASE_NAME": ("kuka", KUKA[:KUKA.index("DECL CHAR BASE_NAME")],
                             line_of(KUKA, "DECL CHAR BASE_NAME") - 1, "ENDDAT"),
    "no ENDMODULE": ("abb", ABB[:ABB.index("ENDMODULE")], line_of(ABB, "ENDMODULE") - 1,
                     "ENDMODULE"),
    "trans 2E7": ("abb", ABB.replace("[[0,0,152.5]", "[[0,0,2E7]"),
                  line_of(ABB, "TASK PERS tooldata tGripper"), "tGripper.tframe.trans[3]"),
    "ufmec of 40": ("abb", ABB.replace('"STN1"', '"' + "S" * 40 + '"'),
                    line_of(ABB, "PERS wobjdata wTurntable"), "wTurntable.mech_unit"),
    "name of 1e6": ("abb", ABB.replace("  TASK PERS tooldata tGripper",
                                       '  ! pendant: tool 1 "' + "g" * 10**6 + '"\n'
                                       "  TASK PERS tooldata tGripper"),
                    line_of(ABB, "TASK PERS tooldata tGripper"), "tGripper.name"),
}


@pytest.mark.parametrize("fmt, text, line, field", BAD.values(), ids=BAD.keys())
def test_bad_files_are_refused_naming_line_and_field_and_nothing_changes(client, fmt, text,
                                                                         line, field):
    ok(imp(client, "kuka", KUKA))
    before = backup_hash(client)
    r = imp(client, fmt, text)
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["body", "file", f"line {line}", field]
    assert backup_hash(client) == before


def test_one_set_of_bounds_on_every_path(client):
    r = client.put(f"{C}/tools/1", json={"name": "x" * 65}, headers={"If-Match": "*"})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][-1] == "name"
    r = client.put(f"{C}/tools/1", json={"name": "two\u2028lines"}, headers={"If-Match": "*"})
    assert r.status_code == 422 and "U+2028" in r.text
    r = client.put(f"{C}/tools/1", json={"pose": {"z": 2e7}}, headers={"If-Match": "*"})
    assert r.status_code == 422
    # the backup path refuses what the API refuses
    ok(client.put(f"{C}/tools/1", json={"name": "x" * 64, "pose": {"z": 1e6}}, headers={"If-Match": "*"}))
    doc = client.get(f"{C}/export", params={"format": "json"}).json()
    assert ok(client.post(f"{C}/import", json={"format": "json",
                                                "text": __import__("json").dumps(doc)}))
    doc["entries"][0]["name"] = "y" * 65
    r = client.post(f"{C}/import", json={"format": "json", "text": __import__("json").dumps(doc)})
    assert r.status_code == 422 and "name" in r.json()["detail"][0]["loc"]


def test_export_without_an_imported_file_is_a_whole_file_that_reads_back(client):
    ok(client.put(f"{C}/tools/1", json={"name": "pointer", "pose": {"z": 180}}, headers={"If-Match": "*"}))
    ok(client.put(f"{C}/bases/2", json={"name": "turntable", "kind": "coordinated_base",
                                        "mech_unit": "STN1", "pose": {"z": 400}}, headers={"If-Match": "*"}))
    for fmt in ("kuka", "abb", "fanuc", "ur"):
        text = client.get(f"{C}/export", params={"format": fmt}).text
        other = f"/controllers/{ok(client.post('/controllers', json={'name': f'c-{fmt}'}))['id']}"
        ok(client.post(f"{other}/import", json={"format": fmt, "text": text}))
        b2 = ok(client.get(f"{other}/bases/2"))
        assert (b2["kind"], b2["mech_unit"], b2["pose"]["z"]) == ("coordinated_base", "STN1", 400)
        assert client.get(f"{other}/export", params={"format": fmt}).text == text


def test_cli_import_dry_run_then_import(db_url, tmp_path, capsys):
    with make_client(db_url):  # migrations and the demo controller cell-1
        pass
    f = tmp_path / "$config.dat"
    f.write_bytes(KUKA.encode())
    assert main(["import", str(f), "--controller", "cell-1", "--dry-run", "--db", db_url]) == 0
    out = capsys.readouterr().out
    assert "tool  3: '(unused)' -> 'Door panel LH' (workpiece)" in out and "nothing written" in out
    with make_client(db_url) as client:
        assert ok(client.get(f"{C}/tools/3"))["name"] == ""
    assert main(["import", str(f), "--controller", "cell-1", "--db", db_url]) == 0
    assert "9 slot(s) changed" in capsys.readouterr().out
    with make_client(db_url) as client:
        assert ok(client.get(f"{C}/tools/3"))["name"] == "Door panel LH"
        assert client.get(f"{C}/export", params={"format": "kuka"}).text == KUKA
    bad = tmp_path / "cut.mod"
    bad.write_text(ABB[:ABB.index("ENDMODULE")])
    assert main(["import", str(bad), "--controller", "cell-1", "--db", db_url]) == 2
    assert f"line {line_of(ABB, 'ENDMODULE') - 1}.ENDMODULE" in capsys.readouterr().err


def test_a_slot_the_tables_do_not_have_is_refused_naming_its_line(client):
    before = backup_hash(client)
    text = ABB.replace("  PERS tooldata tTorch",
                       '  ! pendant: tool 17 "torch"\n  PERS tooldata tTorch')
    r = imp(client, "abb", text)
    assert r.status_code == 422
    assert r.json()["detail"][0]["loc"] == ["body", "text",
                                            f"line {line_of(text, 'PERS tooldata tTorch')}",
                                            "tool 17"]
    assert "1..16" in r.json()["detail"][0]["msg"]
    assert backup_hash(client) == before


def test_the_json_backup_keeps_the_imported_file(client):
    ok(imp(client, "kuka", KUKA))
    ok(client.put(f"{C}/bases/8", json={"name": "Pallet 3"}, headers={"If-Match": "*"}))
    backup = client.get(f"{C}/export", params={"format": "json"}).text
    other = f"/controllers/{ok(client.post('/controllers', json={'name': 'restored'}))['id']}"
    job = finish_job(client, client.post(f"{other}/import", json={"format": "json", "text": backup}))
    assert job["state"] == "done", job  # a restore is a job
    out = client.get(f"{other}/export", params={"format": "kuka"}).text
    assert [a for a, b in zip(KUKA.splitlines(), out.splitlines()) if a != b] == \
        ['BASE_NAME[8,]="Pallet 2"']
    doc = json.loads(backup)
    doc["files"][0]["text"] = KUKA[:KUKA.index("ENDDAT")]
    r = client.post(f"{other}/import",
                    json={"format": "json", "text": json.dumps(doc)})
    assert r.status_code == 422 and r.json()["detail"][0]["loc"][:4] == ["body", "text", "files", 0]
    assert "ENDDAT" in r.json()["detail"][0]["msg"]


def test_cli_dry_run_shows_values_before_and_after_and_slots_choose(db_url, tmp_path, capsys):
    """Issue 23: ``pendant import --dry-run`` lists per slot the values before -> after with
    every digit; ``--slots`` applies only those; a Windows-1252 file keeps its encoding."""
    with make_client(db_url) as client:
        ok(client.put(f"{C}/tools/1", json={"name": "pointer", "pose": {"z": 180}}, headers={"If-Match": "*"}))
    f = tmp_path / "$config.dat"
    raw = (DATA / "controller-files" / "kuka_krc4_crlf_cp1252.dat").read_bytes()
    f.write_bytes(raw)
    assert main(["import", str(f), "--controller", "cell-1", "--dry-run", "--db", db_url]) == 0
    out = capsys.readouterr().out
    assert "tool  1: 'pointer' -> 'Greifer Öl' (tool)" in out
    assert "    x        0.0 -> 148.320007" in out and "    y        0.0 -> 3.01155138" in out
    assert "    z        180.0 -> 357.125" in out and "    mass_kg  - -> 6.80000019" in out
    assert main(["import", str(f), "--controller", "cell-1", "--slots", "tool3,base1",
                 "--db", db_url]) == 0
    assert "2 slot(s) changed" in capsys.readouterr().out
    for bad in ("tool" + "1" * 5000, "tool\u0663", "gripper1"):  # a traceback (ValueError) before
        assert main(["import", str(f), "--controller", "cell-1", "--slots", bad,
                     "--db", db_url]) != 0
        assert "--slots: expected tool<n> or base<n>" in capsys.readouterr().err
    with make_client(db_url) as client:
        assert ok(client.get(f"{C}/tools/1"))["name"] == "pointer"
        assert ok(client.get(f"{C}/bases/1"))["pose"]["b"] == 0.238999218
    assert main(["import", str(f), "--controller", "cell-1", "--db", db_url]) == 0
    with make_client(db_url) as client:
        assert client.get(f"{C}/export", params={"format": "kuka"}).content == raw


def test_pendant_slot_changes_one_component_and_keeps_every_digit_of_the_others(
        fresh_db, tmp_path, monkeypatch):  # noqa: ANN001
    """Issue 23 (1): ``pendant slot tool 1 --x ...`` sends X alone; Y keeps 3.01155138."""
    import httpx

    from api_helpers import ADMIN_TOKEN
    from browser_helpers import serve

    monkeypatch.setenv("PENDANT_TOKEN", ADMIN_TOKEN)
    auth = {"Authorization": f"Bearer {ADMIN_TOKEN}"}
    with serve(fresh_db()) as url:
        r = httpx.put(f"{url}{C}/tools/1", headers={**auth, "If-Match": "*"},
                      json={"pose": {"x": 1, "y": 3.01155138, "z": 357.125, "b": 0.238999218}})
        assert r.status_code == 200, r.text
        assert main(["slot", "tool", "1", "--url", url, "--x", "2.5"]) == 0
        pose = httpx.get(f"{url}{C}/tools/1", headers=auth).json()["pose"]
        assert pose == {"x": 2.5, "y": 3.01155138, "z": 357.125, "a": 0.0, "b": 0.238999218, "c": 0.0}


def test_a_deeply_nested_value_is_refused_naming_its_line(client):
    """A module or $config.dat whose value nests 1500 brackets (or braces) made the readers,
    which recurse per level, pass Python's stack: POST .../import answered 500. Each is a 422
    naming the line and the reason, and nothing is written (formats.abb/kuka MAX_NESTING)."""
    before = client.get(f"{C}/tools/1").headers["etag"]
    abb = "MODULE M\n  PERS tooldata t1:=" + "[" * 1500 + ";\nENDMODULE\n"
    kuka = ("DEFDAT $CONFIG\nDECL FRAME TOOL_DATA[16]\nTOOL_DATA[1]=" + "{X " * 1500 +
            "\nENDDAT\n")
    for fmt, text, line in (("abb", abb, 2), ("kuka", kuka, 3)):
        r = client.post(f"{C}/import", json={"format": fmt, "text": text})
        assert r.status_code == 422, (fmt, r.status_code, r.text[:300])
        detail = r.json()["detail"][0]
        assert detail["loc"][:3] == ["body", "file", f"line {line}"], detail
        assert "nests" in detail["msg"] and "more than 16 deep" in detail["msg"], detail
    assert client.get(f"{C}/tools/1").headers["etag"] == before
