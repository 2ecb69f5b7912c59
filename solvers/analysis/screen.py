"""Step 1, candidates: which effects of the library this recording can show at all.

A candidate effect enters the residual through its regressor ``X`` (``effects.py``). It is
screened out when

- *invisible*: even a large but possible value of its parameter (``PLAUSIBLE``, the upper
  limit of what the effect can be, which the selection also uses) would change the samples by
  less than ``VISIBLE_MM`` RMS;
- *not identifiable*: ``X`` lies (almost) inside span(B), the baseline's Jacobian, so the
  rigid fit absorbs it (relative residual of the worst column direction below
  ``IDENT_TOL``). This is the column-rank test of the identification Jacobian used to find a
  robot's identifiable ("base") parameters: Khalil & Dombre, *Modeling, Identification and
  Control of Robots* (2002), ch. 11; Hollerbach & Wampler, "The calibration index and
  taxonomy for robot kinematic calibration methods", IJRR 15(6):573-591, 1996.

Every screened-out candidate is listed with what data would reveal it (``text.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from solvers.analysis.baseline import Baseline
from solvers.analysis.effects import Candidate
from solvers.analysis.selection import residual_ratio
from solvers.analysis.text import not_identifiable_reason

IDENT_TOL = 3e-3        # relative residual of a regressor outside the model's span
VISIBLE_MM = 1e-3
# a large but possible value of each effect's parameter, used twice: an effect that would
# change the samples by less than VISIBLE_MM RMS even at this value is invisible in the
# recording (here), and a fitted value beyond it is physically impossible, so the candidate
# is not named (``forward.plausible``, ``forward.backward``). The second use makes each value
# an upper limit of what the effect can be in a working cell, not a typical size: a value
# the robot can really show must lie inside it, or its effect is never named and other
# candidates stand in for it. trigger_latency: the time from the beam's interruption to the
# controller latching the joints, a sensor's response (up to ~20 ms) plus the input's path
# (a controller polling its inputs once per interpolation cycle, 4-12 ms; through a PLC
# and a fieldbus, scan and bus cycles of tens of ms): 100 ms. It was 20 ms, which
# docs/emulator.md's light-barrier example sets: fitted at 20.0000068 ms (linearised) it was
# "impossible", nothing was named; at 25-80 ms simulated beam recordings named backlash of
# two or three joints instead, verdict ``explained``.
PLAUSIBLE = {"joint_offset": 1.0, "link_length": 2.0, "link_twist": 1.0,
             "joint_compliance": 5e-3, "backlash": 0.5, "thermal_drift": 1.0,
             "gear_transmission_error": 0.05, "trigger_latency": 100.0, "tool_deflection": 0.01}


@dataclass
class Screened:
    """The candidates the selection may test, and those it cannot (report entries)."""

    candidates: list[Candidate] = field(default_factory=list)
    not_identifiable: list[dict] = field(default_factory=list)


def _entry(c: Candidate, ratio: float, reason: str) -> dict:
    return {"effect": c.effect, "joint": c.joint,
            **({"dh_parameter": c.dh_parameter} if c.dh_parameter else {}),
            **({"periods_per_turn": c.periods} if c.periods else {}),
            "relative_residual": round(ratio, 6), "reason": reason}


def screen(rec, base: Baseline, QB: np.ndarray, candidates: list[Candidate]) -> Screened:
    """Split ``candidates`` into testable and not identifiable (invisible or absorbed)."""
    out = Screened()
    N = rec.n_samples
    for c in candidates:
        if not np.any(c.columns):
            continue
        ratio = residual_ratio(QB, c.columns)
        size = float(np.sqrt(np.sum((c.columns * PLAUSIBLE[c.effect] * base.row_scale[:, None]) ** 2)
                             / N))
        if size < VISIBLE_MM:
            out.not_identifiable.append(_entry(
                c, ratio, f"invisible in this recording: even {c.param} = "
                          f"{PLAUSIBLE[c.effect]:g} would change the samples by only "
                          f"{size:.2g} mm RMS"))
        elif ratio < IDENT_TOL:
            out.not_identifiable.append(_entry(c, ratio, not_identifiable_reason(rec, c, base)))
        else:
            out.candidates.append(c)
    return out
