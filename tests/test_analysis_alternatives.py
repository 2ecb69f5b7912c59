"""A candidate almost as good as the one named is listed under ``evidence.alternatives``.

The margin is the extra sum of squares: another candidate within ``ALTERNATIVE_LR`` (4)
residual variances of the named one's is an alternative (docs/analysis.md, step 5). The
alternatives were gathered only among the candidates that passed the step's Holm test on
their own, so one just short of it was left out: in a touch recording of a UR10 whose a2 is
0.08 mm long (30 samples, 0.02 mm noise; ``benchmarks/analysis_sweep.py`` section 1's case),
a1 is named (its projected regressor and a2's have |cos| 0.95 on these poses: a2's
signature is 91 % a1's) and a2 explains 3.3 sigma^2 less (p 9e-5 alone, where the step's
Holm test over 56 candidates at 1e-3 asks for about 2e-5), and was not listed: the report
gave no hint of the true effect. The test fails on the old gathering.
"""

from __future__ import annotations

from server.formats.recording import parse_recording
from solvers.analysis import analyze
from solvers.physics import Imperfections
from solvers.simulate import simulate_recording

PAYLOAD = (3.0, [0.0, 0.0, 60.0])


def touch_report(robot: str, seed: int, **effects) -> dict:
    doc = simulate_recording("touch", robot, Imperfections(noise_mm=0.02, **effects), 30,
                             seed=seed, payload=PAYLOAD)
    return analyze(parse_recording(doc))


def test_a_candidate_short_of_holm_alone_is_listed_as_an_alternative() -> None:
    rep = touch_report("ur10", 709, dh_delta={("a_mm", 2): 0.08})
    first = rep["findings"][0]
    assert (first["effect"], first["joint"], first["parameters"]["dh_parameter"]) == \
        ("link_length", 1, "a")
    ev = first["evidence"]
    assert "link_length_j2_a" in ev.get("alternatives", [])
    # not the same regressor (|cos| 0.95): an alternative, not indistinguishable
    assert "link_length_j2_a" not in ev.get("indistinguishable_from", [])


def test_an_alternative_passing_holm_stays_listed() -> None:
    """UR5e, joint 3's zero 0.01 deg off: d5 named (alpha5 the same regressor), the offset
    0.6 sigma^2 behind it among the alternatives (listed before the change too)."""
    rep = touch_report("ur5e", 801, joint_offset_deg=(0.0, 0.0, 0.01, 0.0, 0.0, 0.0))
    ev = rep["findings"][0]["evidence"]
    assert ev["indistinguishable_from"] == ["link_twist_j5_alpha"]
    assert "joint_offset_j3" in ev["alternatives"]


def test_the_same_effect_on_another_joint_is_listed_as_an_alternative() -> None:
    """``Candidate.family`` is the candidate's key (effect and joint; all warm-up time
    constants of thermal drift are one family), so the alternatives' rule ``family !=``
    excludes only the named candidate's own group, not backlash of another joint. A beam
    recording of a UR10 whose joint 3 has 0.01 deg backlash (72 triggers, 0.02 mm noise):
    joints 3 and 4 move the beam's signed distance alike on these poses (|cos| 0.998 outside
    the rigid model), joint 4 is named and joint 3, 0.3 sigma^2 behind, is listed.
    (``benchmarks/analysis_sweep.py`` section 2's seed 704 names joint 4 with no alternative:
    there |cos| is 0.982 and joint 3 is 7.1 sigma^2 behind, beyond the 4 sigma^2 margin; a
    noise draw, 0.4 % likely for the linearised true model on those poses.)"""
    doc = simulate_recording("beam", "ur10", Imperfections(
        noise_mm=0.02, backlash_deg=(0.0, 0.0, 0.01, 0.0, 0.0, 0.0)), 72, seed=710,
        payload=PAYLOAD)
    first = analyze(parse_recording(doc))["findings"][0]
    assert (first["effect"], first["joint"]) == ("backlash", 4)
    assert "backlash_j3" in first["evidence"].get("alternatives", [])
