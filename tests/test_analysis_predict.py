"""Issue 25: ``pendant analyze --save-model``, ``pendant predict`` and their HTTP faces
(../shared/spec/robot-model.md; docs/analysis.md, "The model and predict")."""

from __future__ import annotations

import json

import numpy as np
import pytest
from api_helpers import analyze, ok

from server.cli.main import main
from server.formats.recording import parse_recording
from solvers.analysis.model import predict
from solvers.errors import CalibrationError
from solvers.frames import Pose
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording

IMP = Imperfections(noise_mm=0.02, compliance_deg_per_Nm=(0, 5e-4, 0, 0, 0, 0),
                    dh_delta={("a_mm", 3): 0.4})


def session(seed: int, instrument: Pose, n: int = 80) -> dict:
    return simulate_recording("tracker", "ur10", IMP, n, seed=seed, payload=(5.0, [0, 0, 50]),
                              instrument_pose=instrument)


DAY1 = Pose(2500.0, 800.0, -400.0, 160.0, 3.0, -2.0)
DAY2 = Pose(-1800.0, 1500.0, 200.0, 20.0, -2.0, 1.0)


def test_save_model_then_predict_the_same_and_another_session(tmp_path, capsys) -> None:
    rec1, rec2 = tmp_path / "day1.json", tmp_path / "day2.json"
    rec1.write_text(json.dumps(session(1, DAY1)))
    rec2.write_text(json.dumps(session(2, DAY2)))
    model = tmp_path / "model.json"
    assert main(["analyze", str(rec1), "--json", "--save-model", str(model)]) == 0
    rep = json.loads(capsys.readouterr().out)
    m = json.loads(model.read_text())
    assert m["format"] == "robot-model/1" and "model" not in rep
    assert {(e["effect"], e["joint"]) for e in m["effects"]} == \
        {("joint_compliance", 2), ("link_length", 3)}

    # the same session: the model as fitted reproduces the report's in-sample figure
    assert main(["predict", str(model), str(rec1), "--json"]) == 0
    same = json.loads(capsys.readouterr().out)
    assert same["format"] == "prediction/1" and same["refit_setup"] is False
    assert same["n_samples"] == 80 and len(same["predicted"]) == 80
    assert same["rms_mm"] == pytest.approx(rep["final"]["rms_mm"], rel=1e-3)
    meas = np.array([s["measured_mm"] for s in json.loads(rec1.read_text())["samples"]])
    r = np.asarray(same["predicted"]) - meas
    assert same["rms_mm"] == pytest.approx(float(np.sqrt(np.mean(np.sum(r ** 2, 1)))), rel=1e-4)

    # another day, the instrument placed elsewhere: the setup must be refitted
    assert main(["predict", str(model), str(rec2), "--json"]) == 0
    stale = json.loads(capsys.readouterr().out)
    assert stale["rms_mm"] > 100.0
    assert main(["predict", str(model), str(rec2), "--refit-setup", "--json"]) == 0
    new = json.loads(capsys.readouterr().out)
    assert new["refit_setup"] is True and "setup" in new
    assert new["rms_mm"] < 0.06          # noise 0.02 mm per axis: 0.035 mm
    assert np.asarray(new["setup"]["t_instrument_base"]) == pytest.approx(
        DAY2.as_matrix()[:3, 3], abs=0.5)
    # the rigid model alone does not carry over as well
    rigid = dict(m, effects=[])
    assert predict(rigid, parse_recording(json.loads(rec2.read_text())), True)["rms_mm"] \
        > 3 * new["rms_mm"]


def test_predict_without_measurements() -> None:
    rec = parse_recording(session(1, DAY1, 40))
    from solvers.analysis import analyze as run
    model = run(rec)["model"]
    doc = session(3, DAY1, 10)
    for s in doc["samples"]:
        del s["measured_mm"]
    # a recording without measurements is predicted (no rms); --refit-setup needs them
    with pytest.raises(CalibrationError):
        parse_recording(doc)                     # the analysis needs them
    bare = parse_recording(doc, measurements_optional=True)
    out = predict(model, bare)
    assert len(out["predicted"]) == 10 and "rms_mm" not in out
    with pytest.raises(CalibrationError) as e:
        predict(model, bare, refit_setup=True)
    assert e.value.loc[-1] == "measured_mm"


def test_bad_model_names_the_field() -> None:
    rec = parse_recording(session(1, DAY1, 30))
    from solvers.analysis import analyze as run
    model = run(rec)["model"]
    bad = json.loads(json.dumps(model))
    bad["effects"].append({"effect": "joint_compliance", "joint": 9, "beta": [0.0]})
    with pytest.raises(CalibrationError) as e:
        predict(bad, rec)
    assert e.value.loc == ("effects", len(model["effects"]), "joint")
    bad = json.loads(json.dumps(model))
    bad["setup"]["tcp_mm"] = [0, 0]
    with pytest.raises(CalibrationError) as e:
        predict(bad, rec)
    assert e.value.loc == ("setup", "tcp_mm")
    with pytest.raises(CalibrationError) as e:
        predict({"format": "robot-model/9"}, rec)
    assert e.value.loc == ("format",)
    other = json.loads(json.dumps(model))
    other["robot"]["joints"][1]["a_mm"] += 10.0
    with pytest.raises(CalibrationError) as e:
        predict(other, rec)
    assert e.value.loc == ("robot", "joints", 1, "a_mm")


def test_http_model_download_and_predict(client) -> None:  # noqa: F811
    rid = ok(client.post("/recordings", json=session(1, DAY1, 60)))["id"]
    rep = analyze(client, rid)
    r = client.get(f"/analysis/{rep['id']}/model")
    assert r.status_code == 200, r.text
    assert "attachment" in r.headers["content-disposition"]
    model = r.json()
    assert model["format"] == "robot-model/1"
    body = {"model": model, "recording": session(2, DAY2, 40), "refit_setup": True}
    out = ok(client.post("/predict", json=body))
    assert out["format"] == "prediction/1" and out["rms_mm"] < 0.06
    bad = client.post("/predict", json={**body, "model": {**model, "setup": {}}})
    assert bad.status_code == 422
    assert bad.json()["detail"][0]["loc"][:2] in (["model", "setup"], ["body", "model"])
    assert client.get("/analysis/999/model").status_code == 404
