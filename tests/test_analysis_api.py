"""Analysis through the service (POST /recordings, /recordings/{id}/analyze, GET /analysis/{id})
and the command line (pendant simulate / pendant analyze)."""

from __future__ import annotations

import json

import pytest
from api_helpers import analyze, make_client, ok

from server.cli.analysis import parse_effects
from server.cli.main import main
from solvers.errors import CalibrationError
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording

REPORT_KEYS = {"format", "kind", "n_samples", "verdict", "baseline", "locate", "findings", "final"}


def compliant_ur10() -> dict:
    imp = Imperfections(noise_mm=0.02, compliance_deg_per_Nm=(0, 5e-4, 0, 0, 0, 0))
    return simulate_recording("tracker", "ur10", imp, 40, seed=5, payload=(5.0, [0, 0, 50]))


def test_store_analyze_and_read_back(client) -> None:  # noqa: F811
    rec = ok(client.post("/recordings", json=compliant_ur10()))
    assert rec["kind"] == "tracker" and rec["n_samples"] == 40
    rep = analyze(client, rec["id"])
    assert REPORT_KEYS <= set(rep) and rep["format"] == "analysis-report/1"
    assert rep["verdict"] == "explained"
    f = rep["findings"][0]
    assert (f["effect"], f["joint"]) == ("joint_compliance", 2)
    assert f["parameters"]["compliance_deg_per_Nm"] == pytest.approx(5e-4, rel=0.3)
    assert set(rep["baseline"]) >= {"rms_mm", "heldout_rms_mm", "parameters"}
    assert set(rep["locate"]) >= {"summary", "worst_samples"}
    assert set(rep["final"]) >= {"rms_mm", "heldout_rms_mm"}
    for block in ("baseline", "final"):  # per-sample |r_k|, sample order (the page plots them)
        r = rep[block]["residuals_mm"]
        assert len(r) == rep["n_samples"] and min(r) >= 0.0
        rms = (sum(v * v for v in r) / len(r)) ** 0.5
        assert rms == pytest.approx(rep[block]["rms_mm"], rel=1e-3, abs=1e-5)
    assert set(f) >= {"effect", "joint", "explanation", "parameters", "rms_mm", "heldout_rms_mm", "evidence"}
    again = ok(client.get(f"/analysis/{rep['id']}"))
    assert again["findings"] == rep["findings"]
    assert ok(client.get(f"/recordings/{rec['id']}"))["format"] == "robot-recording/1"


def test_recording_and_analysis_survive_a_restart(db_url) -> None:  # noqa: F811
    doc = compliant_ur10()
    with make_client(db_url) as first:
        rid = ok(first.post("/recordings", json=doc))["id"]
        rep = analyze(first, rid)
        first.app.state.engine.dispose()
    with make_client(db_url) as second:  # a new process on the same SQLite file
        assert ok(second.get(f"/recordings/{rid}")) == doc
        assert ok(second.get(f"/analysis/{rep['id']}")) == rep
        again = analyze(second, rid)  # ids go on, not start over
        assert again["id"] != rep["id"] and again["findings"] == rep["findings"]
        second.app.state.engine.dispose()


def test_bad_recording_is_422_naming_the_field(client) -> None:  # noqa: F811
    doc = compliant_ur10()
    doc["samples"][3]["joints_deg"] = doc["samples"][3]["joints_deg"][:5]
    r = client.post("/recordings", json=doc)
    assert r.status_code == 422
    loc = r.json()["detail"][0]["loc"]
    assert loc[:4] == ["body", "samples", 3, "joints_deg"], loc


def test_unknown_ids_are_404(client) -> None:  # noqa: F811
    assert client.post("/recordings/99/analyze").status_code == 404
    r = client.get("/analysis/7")
    assert r.status_code == 404 and r.json()["detail"][0]["loc"] == ["path", "analysis_id"]


def test_too_few_samples_is_422_and_four_are_analysed(client) -> None:  # noqa: F811
    doc = simulate_recording("touch", "ur10", Imperfections(noise_mm=0.02), 4, seed=1)
    rid = ok(client.post("/recordings", json=doc))["id"]
    assert analyze(client, rid)["n_samples"] == 4
    doc["samples"] = doc["samples"][:3]
    r = client.post("/recordings", json=doc)
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "samples"]


def test_cli_simulate_then_analyze(tmp_path, capsys) -> None:
    out = tmp_path / "rec.json"
    assert main(["simulate", "tracker", "--robot", "tm5_900", "--effect", "offset:2=0.02",
                 "--n", "40", "--seed", "3", "-o", str(out)]) == 0
    assert json.loads(out.read_text())["format"] == "robot-recording/1"
    capsys.readouterr()
    assert main(["analyze", str(out), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert (rep["findings"][0]["effect"], rep["findings"][0]["joint"]) == ("joint_offset", 2)
    assert rep["findings"][0]["parameters"]["offset_deg"] == pytest.approx(0.02, rel=0.3)
    assert main(["analyze", str(out)]) == 0
    text = capsys.readouterr().out
    assert "Verdict: explained" in text and "joint_offset J2" in text


def test_cli_bad_effect_names_the_option(tmp_path, capsys) -> None:
    assert main(["simulate", "tracker", "--robot", "ur10", "--effect", "wobble:2=1",
                 "-o", str(tmp_path / "x.json")]) == 2
    assert "--effect" in capsys.readouterr().err
    with pytest.raises(CalibrationError):
        parse_effects(["compliance=0.1"], 6, 0.0)
    imp = parse_effects(["a:3=0.1", "cyclic:2=0.01@3", "latency=2", "backlash:1=0.01"], 6, 0.01)
    assert imp.dh_delta == {("a_mm", 3): 0.1} and imp.cyclic_error == {2: (0.01, 3.0)}
    assert imp.trigger_latency_ms == 2 and imp.backlash_deg[0] == 0.01


def test_cli_reads_warmup_and_gear_effects() -> None:
    imp = parse_effects(["drift=0.2", "tau=1800", "gear:2=0.01@3@40", "gear:2=0.005@7"], 6, 0.01)
    assert imp.thermal_drift_mm == 0.2 and imp.thermal_tau_s == 1800.0
    assert imp.gear_transmission_error == ((2, 0.01, 3.0, 40.0), (2, 0.005, 7.0, 0.0))
    with pytest.raises(CalibrationError):
        parse_effects(["gear=0.01@3"], 6, 0.0)       # a gear error needs its joint
