"""Benchmark of ``pendant plan``: 30 planned poses against 30 random poses and 30 poses of an
ISO 9283 cube, by simulation (the table in docs/analysis.md).

    python benchmarks/plan.py [--repeats 10]

A UR10 with a 5 kg payload and hidden joint compliance (J2, J3), joint offsets (J2, J3) and
two link-length errors (a2, a3) is measured by a laser tracker (noise 0.02 mm per axis) at
30 poses of each design; the model of the planned effects (joint_compliance:2,3,
link_length:2,3, joint_offset) is fitted, as the analysis fits it, to those 30 samples, and
predicts 300 other poses of the same workspace (noise-free truth). Per design: the mean
held-out RMS (mm) and the parameters' standard deviations (from the fit's covariance),
averaged over the repeats (different noise; different random poses).

- planned: :func:`solvers.analysis.plan.plan_poses` (D-optimal over a pool of 1500).
- random: 30 poses drawn from the same pool (same limits, box, floor, conditioning).
- ISO 9283 cube: the largest cube centred in the box; the test plane through its diagonal
  corners C1-C2-C7-C8; P1 at the centre and P2..P5 on the plane's diagonals at 10 % of the
  diagonal from the corners (ISO 9283:1998, 6.2); each point with 6 tool orientations
  (straight down, tilted 25 deg about +-x and +-y of base, and turned 90 deg).

The last line is machine-read: ``plan_heldout_mm=<> random_heldout_mm=<> iso_heldout_mm=<>``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from server.formats.recording import parse_recording  # noqa: E402
from solvers.analysis.baseline import fit_baseline  # noqa: E402
from solvers.analysis.effects import build_library  # noqa: E402
from solvers.analysis.plan import (Workspace, parse_effects, plan_poses, reached,  # noqa: E402
                                   record_plan, solve_ik, tracker_pool)
from solvers.analysis.selection import fit_linear  # noqa: E402
from solvers.physics import Imperfections  # noqa: E402
from solvers.robots import ROBOTS  # noqa: E402

ROBOT = ROBOTS["ur10"]
PAYLOAD = (5.0, (0.0, 0.0, 50.0))
TOOL = np.eye(4)
EFFECTS = ["joint_compliance:2,joint_compliance:3,link_length:2,link_length:3,joint_offset"]
TRUTH = Imperfections(noise_mm=0.02, compliance_deg_per_Nm=(0, 5e-4, 6e-4, 0, 0, 0),
                      joint_offset_deg=(0, -0.01, 0.01, 0, 0, 0),
                      dh_delta={("a_mm", 2): -0.5, ("a_mm", 3): 0.3})
N_POSES = 30


def iso_cube(ws: Workspace, rng: np.random.Generator) -> np.ndarray:
    """30 joint configurations: ISO 9283 P1..P5, 6 tool orientations each."""
    centre = 0.5 * (ws.lo + ws.hi)
    side = 0.8 * float(np.min(ws.hi - ws.lo))
    h = side / 2
    c1, c7 = centre + [-h, -h, -h], centre + [h, h, h]
    c2, c8 = centre + [h, h, -h], centre + [-h, -h, h]
    pts = [centre] + [c + 0.1 * (centre - c) / np.linalg.norm(centre - c) * np.linalg.norm(c7 - c1)
                      for c in (c1, c2, c7, c8)]
    down = Rotation.from_euler("x", 180.0, degrees=True)
    tilts = [Rotation.identity(), Rotation.from_euler("x", 25, degrees=True),
             Rotation.from_euler("x", -25, degrees=True), Rotation.from_euler("y", 25, degrees=True),
             Rotation.from_euler("y", -25, degrees=True), Rotation.from_euler("z", 90, degrees=True)]
    seeds = tracker_pool(ROBOT, TOOL, Workspace(ws.lo - 100, ws.hi + 100, ws.floor_mm), 3000, rng)
    from solvers.dh import forward_kinematics
    seed_p = forward_kinematics(ROBOT, seeds, TOOL)[:, :3, 3]
    out = []
    for p in pts:
        for r in tilts:
            goal = np.eye(4)
            goal[:3, :3] = (r * down).as_matrix() if r is not tilts[-1] else (down * r).as_matrix()
            goal[:3, 3] = p
            near = seeds[np.argsort(np.linalg.norm(seed_p - p, axis=1))[:40]]
            goals = np.repeat(goal[None], len(near), axis=0)
            q = solve_ik(ROBOT, TOOL, goals, near)
            ok = np.flatnonzero(reached(ROBOT, TOOL, q, goals))
            if not len(ok):
                raise SystemExit(f"ISO cube point {np.round(p, 1)} not reachable")
            out.append(q[ok[0]])
    return np.array(out)


def evaluate(design: np.ndarray, validation: np.ndarray, keys: list[str], seed: int
             ) -> tuple[float, dict[str, float]]:
    """Held-out RMS (mm) on the validation poses and each parameter's std, fitting on design."""
    train = record_plan(ROBOT, design, TRUTH, seed=seed, payload=PAYLOAD)
    from dataclasses import replace
    val = record_plan(ROBOT, validation, replace(TRUTH, noise_mm=0.0), seed=seed, payload=PAYLOAD)
    doc = dict(train)
    t_end = train["samples"][-1]["t_s"]
    doc["samples"] = train["samples"] + [{**v, "t_s": v["t_s"] + t_end + 10.0} for v in val["samples"]]
    rec = parse_recording(doc)
    base = fit_baseline(rec)
    lib = {c.key: c for c in build_library(rec, base).candidates}
    M = np.hstack([base.B] + [lib[k].columns for k in keys])
    y = -base.g
    n_tr = 3 * len(design)
    beta, cov, _, _ = fit_linear(y[:n_tr], M[:n_tr])
    e = (y[n_tr:] - M[n_tr:] @ beta).reshape(-1, 3)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))[base.B.shape[1]:]
    return float(np.sqrt(np.mean(np.sum(e ** 2, axis=1)))), dict(zip(keys, std))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=10)
    args = ap.parse_args()
    ws = Workspace.default(ROBOT)
    rng = np.random.default_rng(11)
    plan = plan_poses(ROBOT, parse_effects(EFFECTS, 6), N_POSES, payload=PAYLOAD, seed=3)
    keys = plan["parameters"]
    pool = tracker_pool(ROBOT, TOOL, ws, 1500, np.random.default_rng(3))
    validation = tracker_pool(ROBOT, TOOL, ws, 300, np.random.default_rng(99))
    designs = {"planned (D-optimal)": lambda r: np.array(plan["joints_deg"]),
               "random": lambda r: pool[rng.choice(len(pool), N_POSES, replace=False)],
               "ISO 9283 cube": lambda r: cube}
    cube = iso_cube(ws, np.random.default_rng(5))
    shown = ["joint_compliance_j2", "joint_compliance_j3", "link_length_j2_a", "joint_offset_j3"]
    print(f"UR10, 5 kg payload, tracker noise 0.02 mm, {N_POSES} poses, {args.repeats} repeats; "
          f"fitted: {', '.join(keys)}")
    print(f"{'design':<22} {'held-out mm':>12} " + " ".join(f"{k:>20}" for k in shown))
    result = {}
    for name, make in designs.items():
        held, stds = [], []
        for r in range(args.repeats):
            h, s = evaluate(make(r), validation, keys, seed=100 + r)
            held.append(h)
            stds.append(s)
        mean_std = {k: float(np.mean([s[k] for s in stds])) for k in keys}
        result[name] = float(np.mean(held))
        print(f"{name:<22} {np.mean(held):>12.4f} "
              + " ".join(f"{mean_std[k]:>20.3g}" for k in shown))
    print(f"plan_heldout_mm={result['planned (D-optimal)']:.4f} "
          f"random_heldout_mm={result['random']:.4f} iso_heldout_mm={result['ISO 9283 cube']:.4f}")


if __name__ == "__main__":
    main()
