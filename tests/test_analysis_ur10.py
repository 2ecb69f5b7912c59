"""Real data: a UR10 measured by a laser tracker (tests/data/ur10-laser-tracker, MIT licence).

The nominal model with a fitted tracker frame and probe leaves ~0.78 mm RMS; a blind
recalibration of every identifiable DH parameter (15) predicts held-out poses to ~0.40 mm,
and with a two-joint gravity compliance 0.344 mm (issue 11's reference). The analysis must
name what the model leaves out and predict held-out poses to 0.34 mm (all 632 poses) and
0.30 mm (the first 200) under issue 11's random 5-fold split, and beat the blind fit under
the blocked split too (issue 25: the default for samples ordered in time).
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import pytest

from server.formats.recording import parse_recording
from solvers.analysis import analyze, render_text
from solvers.analysis.blind import blind_dh

DATA = Path(__file__).parent / "data" / "ur10-laser-tracker" / "recording-series-d.json"


@pytest.fixture(scope="module")
def rec():
    return parse_recording(json.loads(DATA.read_text(encoding="utf-8")))


@pytest.fixture(scope="module")
def report(rec):
    # no numpy RuntimeWarning may leak to the terminal (issue 11: an overflow in the second
    # orthogonalisation pass of a rank-deficient model, seen on this very recording)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        return analyze(rec, split="random")


def test_licence_travels_with_the_data() -> None:
    assert (DATA.parent / "LICENSE.md").is_file() and (DATA.parent / "README.md").is_file()


def test_rigid_baseline_leaves_about_078_mm(report) -> None:
    assert report["n_samples"] == 632
    assert report["baseline"]["rms_mm"] == pytest.approx(0.78, abs=0.03)
    assert report["baseline"]["heldout_rms_mm"] >= report["baseline"]["rms_mm"]
    # the series turns the probe too little about axes across it to place it along its own
    # axis (relative singular value ~1e-4: a standard deviation of tens of mm): named as
    # not identifiable and not reported, the others are
    bad = report["identifiability"]["not_identifiable"]
    assert bad and "tcp_z_mm" in bad[0]["parameters"]
    assert "tcp_z_mm" not in report["baseline"]["parameters"]
    assert report["baseline"]["parameters"]["tcp_x_mm"] == pytest.approx(0.0, abs=2.0)


def test_blind_dh_recalibration_is_the_yardstick(rec) -> None:
    blind = blind_dh(rec, split="random")
    # only identifiable parameters count: not the J1 offset, d1 or the J6 row the instrument
    # frame and the TCP absorb (issue 25: 31 were counted)
    assert len(blind["dh_parameters"]) == 15
    assert not {"joint_offset_j1", "link_length_j1_d", "joint_offset_j6", "link_length_j6_d",
                "link_length_j6_a", "link_twist_j6_alpha"} & set(blind["dh_parameters"])
    assert blind["n_parameters"] == 15 + 8
    assert blind["heldout_rms_mm"] == pytest.approx(0.40, abs=0.02)


@pytest.fixture(scope="module")
def blocked(rec):
    return analyze(rec)


def test_blocked_split_beats_the_blind_fit_under_the_same_split(rec, blocked) -> None:
    rep = blocked
    assert rep["split"]["method"] == "blocked"
    blind = blind_dh(rec)
    assert blind["split"] == "blocked"
    assert rep["final"]["heldout_rms_mm"] <= blind["heldout_rms_mm"]
    assert all(c["passed"] for c in rep["checks"])


def test_analysis_names_the_physics_and_beats_the_blind_fit(rec, report) -> None:
    blind = blind_dh(rec, split="random")
    findings = {(f["effect"], f["joint"]) for f in report["findings"]}
    # what this UR10's nominal table leaves out: the upper-arm and forearm lengths, the
    # non-parallel shoulder/elbow axes, and joints 2 and 3 yielding under gravity
    assert ("link_length", 2) in findings and ("link_length", 3) in findings
    assert ("joint_compliance", 2) in findings
    assert report["final"]["heldout_rms_mm"] <= 0.34
    assert report["final"]["heldout_rms_mm"] < blind["heldout_rms_mm"]
    # the periodic structure on joint 2 is a gear's transmission error, named per harmonic
    gears = [f for f in report["findings"] if f["effect"] == "gear_transmission_error"]
    assert any(f["joint"] == 2 for f in gears)
    assert all(f["parameters"]["amplitude_deg"] <= 0.05 for f in gears)
    comp = next(f for f in report["findings"] if f["effect"] == "joint_compliance" and f["joint"] == 2)
    assert 1e-4 < comp["parameters"]["compliance_deg_per_Nm"] < 2e-3
    assert "gravity torque on joint 2" in comp["explanation"]


def test_first_200_poses_reach_030_mm_held_out() -> None:
    doc = json.loads(DATA.read_text(encoding="utf-8"))
    doc["samples"] = doc["samples"][:200]
    rep = analyze(parse_recording(doc), split="random")
    assert rep["final"]["heldout_rms_mm"] <= 0.30
    assert {f["effect"] for f in rep["findings"]} >= {"link_length", "gear_transmission_error"}


def test_stand_ins_are_kept_and_named(report) -> None:
    """No finding is withdrawn for standing in (issue 11): each stand-in is in the findings."""
    keys = {(f["effect"], f["joint"]) for f in report["findings"]}
    for s in report["stand_ins"]:
        assert (s["effect"], s["joint"]) in keys and s["stands_in_for"]
    assert "withheld" not in report


def test_human_report_reads(report) -> None:
    text = render_text(report)
    assert "Rigid model: RMS 0.77" in text and "joint_compliance J2" in text
    assert "Not identifiable" in text


def test_the_model_carries_over_to_the_second_half_better_than_blind_dh() -> None:
    """Issue 25's transfer: fitted on the first half of the series in time and predicting
    the second (the instrument frame and the probe refitted, the robot held), the saved model
    predicts better than a blind DH recalibration of the same half (0.653 against 0.617 mm
    while the selection's blocked held-out test solved for the probe, which the first four
    time blocks do not determine)."""
    from solvers.analysis.model import model_document, predict

    doc = json.loads(DATA.read_text(encoding="utf-8"))
    half = len(doc["samples"]) // 2
    first = parse_recording({**doc, "samples": doc["samples"][:half]})
    second = parse_recording({**doc, "samples": doc["samples"][half:]})
    rep = analyze(first)
    assert rep["split"]["method"] == "blocked"
    mine = predict(rep["model"], second, refit_setup=True)["rms_mm"]
    b = blind_dh(first)
    theirs = predict(model_document(b["prepared"], b["fit"]), second, refit_setup=True)["rms_mm"]
    rigid = predict({**rep["model"], "effects": []}, second, refit_setup=True)["rms_mm"]
    assert mine <= theirs < rigid, (mine, theirs, rigid)


SMALL = {"link_length_j5_d", "link_twist_j2_alpha", "joint_compliance_j3"}


def _effects(rep):
    """The effects of a report's saved model."""
    from solvers.analysis.model import Effect

    return [Effect(e["effect"], e.get("joint"), e.get("dh_parameter"), e.get("periods_per_turn"),
                   e.get("tau_s")) for e in rep["model"]["effects"]]


def test_blocked_check_judges_a_refused_effect_against_every_finding(blocked) -> None:
    """d5, alpha2 and joint 3's compliance were chosen on the linearisation and refused by
    the model's own check under the blocked split, each judged only against the findings
    before it (joint 3's compliance and alpha2 against a2 alone: their fold fits wandered,
    0.00006-0.00089 deg/Nm and 0.005-0.029 deg, and the held-out RMS rose 0.6886 -> 0.6905,
    0.6906 mm). Judged again against every finding kept, each lowers the held-out RMS of the
    model itself (0.435 -> 0.343 mm for the three), and the structure along joint 6's angle
    that a missing d5 left (p ~ 1e-76) is gone from the leading groups."""
    rep = blocked
    keys = {e.key for e in _effects(rep)}
    assert SMALL <= keys, keys
    assert not rep["not_confirmed"]
    assert rep["final"]["heldout_rms_mm"] <= 0.36
    d5 = next(f for f in rep["findings"] if f["effect"] == "link_length" and f["joint"] == 5)
    assert 0.1 < d5["parameters"]["delta_mm"] < 0.3    # the random split's 0.173 mm
    lead = [u["varies_with"] for u in rep["locate"]["unexplained"][:3]]
    assert "joint 6's angle" not in lead and all(u["p_value"] > 1e-70 for u in
                                                   rep["locate"]["unexplained"])
    # each kept finding lowered the held-out RMS where it was added
    for f in rep["findings"]:
        assert f["heldout_rms_mm"] < f["evidence"]["heldout_rms_before_mm"]


def test_the_small_effects_carry_over_in_time(blocked) -> None:
    """Fitted on the second half of the series in time with the blocked split's findings,
    d5, alpha2 and joint 3's compliance predict the first half better (setup refitted, the
    robot held): 0.369 mm without them, 0.332 with them. The first half cannot judge d5: its
    regressor lies inside the rigid fit's span there (relative norm 1e-3, the probe along
    its axis is not determined), and fitted there it runs to -18 mm."""
    from solvers.analysis.model import Prepared, fit, model_document, predict

    doc = json.loads(DATA.read_text(encoding="utf-8"))
    half = len(doc["samples"]) // 2
    first = parse_recording({**doc, "samples": doc["samples"][:half]})
    second = parse_recording({**doc, "samples": doc["samples"][half:]})
    effects = _effects(blocked)
    assert SMALL <= {e.key for e in effects}

    def carried(effs):
        prep = Prepared.make(second, effs)
        return predict(model_document(prep, fit(prep)), first, refit_setup=True)["rms_mm"]

    without = carried([e for e in effects if e.key not in SMALL])
    with_them = carried(effects)
    assert with_them < 0.95 * without, (with_them, without)
