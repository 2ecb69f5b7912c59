"""Analysis: each effect of the library, simulated on several arms and both DH conventions,
is named with the right joint and value, and the model with it predicts held-out samples at
most 0.6x as far off as the rigid model does; concealed cases included (see ``CASES``).

Concealed, as the requirement words it:

- *by noise*: the effect's rigid-fit RMS (what the rigid fit leaves of the effect alone, the
  same poses without noise) is within 1.5x the noise floor (the rigid-fit RMS of the same
  recording with the noise alone). Those cases sit at 1.3..1.5x: the best any model can then
  do held out is about ``1 / sqrt(1 + 1.45^2) = 0.57`` of the baseline, so they need enough
  samples (60..250) for the final model's held-out RMS to come close to the noise.
- *absorbed*: the rigid fit takes more than half of the effect's squared size into its own
  parameters (the TCP, the instrument frame, the fixed point, the tool axis).
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np
import pytest

from server.formats.recording import parse_recording
from solvers.analysis import analyze
from solvers.analysis.baseline import _beam_constraint, _beam_inputs, fit_baseline, rms_mm
from solvers.analysis.selection import orth, project_out
from solvers.dh import forward_kinematics
from solvers.physics import Imperfections, true_tcp_poses
from solvers.robots import ROBOTS
from solvers.simulate import simulate_recording

NOISE_MM = 0.02
PAYLOAD = (3.0, [0.0, 0.0, 60.0])
CONCEALED_BAND = (1.3, 1.5)   # effect rigid-fit RMS / noise floor of a case concealed by noise
HELDOUT_RATIO = 0.6           # final held-out RMS / the rigid baseline's, every case


def per_joint(j: int, v: float) -> tuple[float, ...]:
    out = [0.0] * 6
    out[j - 1] = v
    return tuple(out)


# (kind, n, robot, effects, effect, joint, parameter, true value, concealed)
# concealed: "noise" (effect rigid-fit RMS within CONCEALED_BAND x the noise floor),
# "absorbed" (the rigid fit absorbs more than half of it), "both", or "" (in plain view)
CASES = [
    ("tracker", 60, "ur10", dict(compliance_deg_per_Nm=per_joint(2, 3e-4)), "joint_compliance", 2, "compliance_deg_per_Nm", 3e-4, "absorbed"),
    ("tracker", 60, "tm5_900", dict(compliance_deg_per_Nm=per_joint(3, 1e-3)), "joint_compliance", 3, "compliance_deg_per_Nm", 1e-3, ""),
    ("tracker", 60, "fanuc_lrmate200id", dict(compliance_deg_per_Nm=per_joint(2, 1e-3)), "joint_compliance", 2, "compliance_deg_per_Nm", 1e-3, ""),
    ("tracker", 60, "kuka_kr6_r900_sixx", dict(joint_offset_deg=per_joint(3, 0.01)), "joint_offset", 3, "offset_deg", 0.01, ""),
    ("tracker", 60, "tm5_900", dict(joint_offset_deg=per_joint(2, 0.01)), "joint_offset", 2, "offset_deg", 0.01, ""),
    ("tracker", 60, "tm5_900", dict(dh_delta={("a_mm", 3): 0.08}), "link_length", 3, "delta_mm", 0.08, ""),
    ("tracker", 60, "abb_irb120", dict(dh_delta={("a_mm", 2): 0.08}), "link_length", 2, "delta_mm", 0.08, "absorbed"),
    ("tracker", 60, "ur10", dict(backlash_deg=per_joint(1, 0.01)), "backlash", 1, "backlash_deg", 0.01, ""),
    ("tracker", 250, "tm5_900", dict(backlash_deg=per_joint(2, 0.011)), "backlash", 2, "backlash_deg", 0.011, "noise"),
    ("tracker", 250, "abb_irb120", dict(thermal_drift_mm=0.17), "thermal_drift", None, "drift_mm", 0.17, "both"),
    ("tracker", 250, "ur5e", dict(tool_deflection_mm_per_N=0.0037), "tool_deflection", None, "deflection_mm_per_N", 0.0037, "both"),
    ("touch", 60, "kuka_kr6_r900_sixx", dict(joint_offset_deg=per_joint(5, 0.031)), "joint_offset", 5, "offset_deg", 0.031, "both"),
    ("touch", 30, "tm5_900", dict(compliance_deg_per_Nm=per_joint(2, 3e-3)), "joint_compliance", 2, "compliance_deg_per_Nm", 3e-3, "absorbed"),
    ("touch", 30, "abb_irb120", dict(thermal_drift_mm=0.25), "thermal_drift", None, "drift_mm", 0.25, "absorbed"),
    ("beam", 72, "kuka_kr6_r900_sixx", dict(trigger_latency_ms=4.0), "trigger_latency", None, "latency_ms", 4.0, ""),
    ("beam", 216, "tm5_900", dict(trigger_latency_ms=3.1), "trigger_latency", None, "latency_ms", 3.1, "noise"),
    ("touch", 80, "tm5_900", dict(joint_offset_deg=per_joint(5, 0.027)), "joint_offset", 5, "offset_deg", 0.027, "both"),
    # link_twist on axes 2..4 (alpha2..alpha4 of each of the six arms at 0.05 deg, tracker, 60
    # samples, seed 217: all named with joint and value, also alpha1 of the standard-DH arms).
    # Not the base's axis (modified DH alpha1: the instrument frame absorbs it) nor axis 6
    # against the flange (standard DH alpha6: the TCP absorbs it), both ``not_identifiable``;
    # nor the axis carrying the TCP (standard alpha5, modified alpha6: axis 6 tilted against
    # axis 5): with the TCP on axis 6 that tilt moves it by a constant along axis 5, as d5 does,
    # and the finding is d5 with the twist under ``indistinguishable_from`` (priority order).
    ("tracker", 60, "tm5_900", dict(dh_delta={("alpha_deg", 3): 0.05}), "link_twist", 3, "delta_alpha_deg", 0.05, ""),
    ("tracker", 60, "kuka_kr6_r900_sixx", dict(dh_delta={("alpha_deg", 2): 0.05}), "link_twist", 2, "delta_alpha_deg", 0.05, "absorbed"),
    # one gear harmonic (more harmonics, with compliance, concealed: test_analysis_warmup_gear)
    ("tracker", 60, "kuka_kr6_r900_sixx", dict(gear_transmission_error=((3, 0.012, 4, 30.0),)), "gear_transmission_error", 3, "amplitude_deg", 0.012, ""),
    # a late trigger as a PLC-wired light barrier shows it (tens of ms): above the 20 ms that
    # screen.PLAUSIBLE held possible until docs/emulator.md's 20 ms example came out unnamed
    # (at 25-80 ms backlash of two or three joints was named instead, verdict explained)
    ("beam", 72, "abb_irb120", dict(trigger_latency_ms=50.0), "trigger_latency", None, "latency_ms", 50.0, ""),
]


def case_id(c) -> str:
    return f"{c[0]}-{c[2]}-{c[4]}" + (f"-J{c[5]}" if c[5] else "")


def effect_rows(rec, imp: Imperfections) -> np.ndarray:
    """The rigid model's residual rows (mm) that the effect alone causes at the recorded
    joints: the nominal model's constraint minus the true robot's (noise left out)."""
    T_nom = forward_kinematics(rec.robot, rec.joints_deg, rec.tool)
    T_true = true_tcp_poses(rec.robot, rec.joints_deg, rec.t_s, replace(imp, noise_mm=0.0),
                            rec.tool, rec.start_joints_deg, rec.payload_mass_kg,
                            rec.payload_com_mm, rec.tcp_velocity_mm_s)
    if rec.kind == "beam":
        b, v, w, edge, radius = _beam_inputs(rec)

        def g(T):
            return _beam_constraint(T[:, :3, 3], T[:, :3, 2], b, v, w, edge, radius)

        return g(T_nom) - g(T_true)
    return (T_nom[:, :3, 3] - T_true[:, :3, 3]).ravel()


def effect_figures(rec, imp: Imperfections) -> tuple[float, float]:
    """(the effect's rigid-fit RMS in mm, the share of its squared size the rigid fit absorbs).

    The rigid fit of the effect alone, linearised at the recording's rigid fit (the effects
    are far smaller than the scale on which the rigid model bends; checked against a
    noise-free recording by ``test_effect_rms_is_the_rigid_fit_of_the_effect_alone``).
    """
    base = fit_baseline(rec)
    e = effect_rows(rec, imp)
    if rec.kind == "tracker":
        e = (e.reshape(-1, 3) @ base.R_instrument_base.T).ravel()   # into the instrument frame
    ew = e if base.w is None else e * base.w
    left = project_out(orth(base.B), ew[:, None])[:, 0]
    absorbed = 1.0 - float(left @ left) / float(ew @ ew)
    return rms_mm(left * base.row_scale, base.m), absorbed


def floor_mm(kind: str, n: int, robot: str, seed: int) -> float:
    """The noise floor: the rigid-fit RMS of the same recording with the noise alone."""
    rec0 = parse_recording(simulate_recording(kind, robot, Imperfections(noise_mm=NOISE_MM), n,
                                              seed=seed, payload=PAYLOAD))
    base = fit_baseline(rec0)
    return rms_mm(base.g_mm, base.m)


@lru_cache(maxsize=None)
def run(i: int) -> dict:
    kind, n, robot, effects, *_ = CASES[i]
    seed = 200 + i
    imp = Imperfections(noise_mm=NOISE_MM, **effects)
    rec = parse_recording(simulate_recording(kind, robot, imp, n, seed=seed, payload=PAYLOAD))
    effect_rms, absorbed = effect_figures(rec, imp)
    floor = floor_mm(kind, n, robot, seed)
    return {"report": analyze(rec), "effect_ratio": effect_rms / floor, "absorbed": absorbed}


@pytest.mark.parametrize("i", range(len(CASES)), ids=[case_id(c) for c in CASES])
def test_effect_is_named_with_joint_value_and_better_prediction(i: int) -> None:
    kind, n, robot, effects, effect, joint, param, true, concealed = CASES[i]
    out = run(i)
    rep = out["report"]
    assert rep["format"] == "analysis-report/1" and rep["kind"] == kind
    if concealed in ("noise", "both"):
        lo, hi = CONCEALED_BAND
        assert lo <= out["effect_ratio"] <= hi, out["effect_ratio"]
    if concealed in ("absorbed", "both"):
        assert out["absorbed"] > 0.5, out["absorbed"]
    assert rep["findings"], rep["locate"]["summary"]
    first = rep["findings"][0]
    assert (first["effect"], first["joint"]) == (effect, joint), [
        (f["effect"], f["joint"]) for f in rep["findings"]]
    assert first["parameters"][param] == pytest.approx(true, rel=0.3)
    for _, _, periods, phase in effects.get("gear_transmission_error", ()):
        assert first["parameters"]["periods_per_turn"] == periods
        assert abs((first["parameters"]["phase_deg"] - phase + 180.0) % 360.0 - 180.0) < 30.0
    assert rep["verdict"] == "explained"
    ratio = rep["final"]["heldout_rms_mm"] / rep["baseline"]["heldout_rms_mm"]
    assert ratio <= HELDOUT_RATIO, (ratio, out["effect_ratio"])
    assert first["explanation"] and isinstance(first["evidence"]["p_value"], float)


def test_suite_has_concealed_cases() -> None:
    """At least three cases concealed by noise and three mostly absorbed, on tracker and
    touch/beam recordings and on both DH conventions."""
    by_noise = [c for c in CASES if c[8] in ("noise", "both")]
    absorbed = [c for c in CASES if c[8] in ("absorbed", "both")]
    for group in (by_noise, absorbed):
        assert len(group) >= 3, [case_id(c) for c in group]
        assert {c[0] == "tracker" for c in group} == {True, False}
        assert {ROBOTS[c[2]].dh_convention for c in group} == {"standard", "modified"}


def test_both_dh_conventions_in_suite() -> None:
    conventions = {ROBOTS[c[2]].dh_convention for c in CASES}
    assert conventions == {"standard", "modified"}


@pytest.mark.parametrize("kind, n, robot, effects", [
    ("tracker", 40, "ur10", dict(compliance_deg_per_Nm=per_joint(2, 3e-4))),
    ("touch", 20, "tm5_900", dict(joint_offset_deg=per_joint(5, 0.03))),
    ("beam", 40, "kuka_kr6_r900_sixx", dict(trigger_latency_ms=4.0, backlash_deg=per_joint(1, 0.01))),
])
def test_effect_rms_is_the_rigid_fit_of_the_effect_alone(kind, n, robot, effects) -> None:
    """``effect_figures`` (linearised, at the noisy recording's joints) equals the rigid fit of
    a noise-free recording; for a tracker the same seed gives the same poses without noise."""
    imp = Imperfections(**effects)
    clean = parse_recording(simulate_recording(kind, robot, imp, n, seed=5, payload=PAYLOAD))
    base = fit_baseline(clean)
    assert effect_figures(clean, imp)[0] == pytest.approx(rms_mm(base.g_mm, base.m), rel=1e-3)
    if kind == "tracker":
        noisy_imp = replace(imp, noise_mm=NOISE_MM)
        noisy = parse_recording(simulate_recording(kind, robot, noisy_imp, n, seed=5,
                                                   payload=PAYLOAD))
        np.testing.assert_array_equal(noisy.joints_deg, clean.joints_deg)
        assert effect_figures(noisy, noisy_imp)[0] == pytest.approx(
            rms_mm(base.g_mm, base.m), rel=1e-2)


# Issue 25's two cases of the private suite, reconstructed (the private parameters are not
# in this repository): a tool that bends under gravity is tool bending, not "joint 4
# compliance" (a payload with its centre off the tool axis loads joint 4 as well, a long tool
# bends more); a modified-DH arm with J2 compliance and a two-per-turn J3 gear error names
# both, J2's compliance not as a J2 gear error, J3's amplitude within 30 %.
BENDING = [
    ("ur10", (5.0, [80.0, 0.0, 60.0]), [0.0, 0.0, 250.0], 0.004, 0),
    ("kuka_kr6_r900_sixx", (3.0, [0.0, 50.0, 120.0]), [0.0, 0.0, 150.0], 0.004, 5),
    ("tm5_900", (8.0, [0.0, 0.0, 200.0]), [100.0, 0.0, 150.0], 0.005, 1),
]


@pytest.mark.parametrize("robot, payload, tool, deflection, seed", BENDING,
                         ids=[f"{c[0]}-seed{c[4]}" for c in BENDING])
def test_a_tool_bending_under_gravity_is_named_tool_bending(robot, payload, tool, deflection,
                                                            seed) -> None:
    imp = Imperfections(noise_mm=NOISE_MM, tool_deflection_mm_per_N=deflection)
    rep = analyze(parse_recording(simulate_recording("tracker", robot, imp, 60, seed=seed,
                                                     payload=payload, tool_mm=tool)))
    assert [(f["effect"], f["joint"]) for f in rep["findings"]] == [("tool_deflection", None)], [
        (f["effect"], f["joint"]) for f in rep["findings"]]
    p = rep["findings"][0]["parameters"]
    assert p["deflection_mm_per_N"] == pytest.approx(deflection, rel=0.3)
    assert rep["verdict"] == "explained"


MODIFIED_DH = [   # tm5_900 is the library's modified-DH arm
    (1e-3, "gear", 0.01, 0.0, 60, 3),
    (5e-4, "gear", 0.02, 45.0, 60, 0),
    (3e-4, "cyclic", 0.005, None, 250, 41),
    (3e-3, "cyclic", 0.02, None, 60, 11),
]


@pytest.mark.parametrize("compliance, form, amplitude, phase, n, seed", MODIFIED_DH,
                         ids=[f"{c[1]}-{c[2]}-c{c[0]:g}-n{c[4]}" for c in MODIFIED_DH])
def test_modified_dh_compliance_and_two_per_turn_gear_error(compliance, form, amplitude,
                                                            phase, n, seed) -> None:
    assert ROBOTS["tm5_900"].dh_convention == "modified"
    gear = dict(cyclic_error={3: (amplitude, 2)}) if form == "cyclic" else \
        dict(gear_transmission_error=((3, amplitude, 2, phase),))
    imp = Imperfections(noise_mm=NOISE_MM, compliance_deg_per_Nm=per_joint(2, compliance),
                        **gear)
    rep = analyze(parse_recording(simulate_recording("tracker", "tm5_900", imp, n, seed=seed,
                                                     payload=PAYLOAD)))
    named = {(f["effect"], f["joint"], f["parameters"].get("periods_per_turn")): f
             for f in rep["findings"]}
    assert set(named) == {("joint_compliance", 2, None), ("gear_transmission_error", 3, 2)}, \
        sorted(named)
    assert named[("joint_compliance", 2, None)]["parameters"]["compliance_deg_per_Nm"] == \
        pytest.approx(compliance, rel=0.3)
    assert named[("gear_transmission_error", 3, 2)]["parameters"]["amplitude_deg"] == \
        pytest.approx(amplitude, rel=0.3)
    assert rep["verdict"] == "explained"
