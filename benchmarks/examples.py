"""Write the example files of docs/api.md ("pendant calibrate"): flange poses taught in the
demo cell (KUKA KR 6 R900 sixx, cell seed 1), each touch-up off the mark like a person's
(0.05 mm per axis, seeded).

    python benchmarks/examples.py        # writes docs/examples/touches.csv and plate.csv
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator import approach, cell_for, home_joints
from server.methods import METHODS
from solvers.dh import forward_kinematics
from solvers.frames import Pose
from solvers.robots import ROBOTS

OUT = Path(__file__).resolve().parent.parent / "docs" / "examples"
AIM_MM = 0.05


def flange_rows(targets: list[tuple[str, float, float, float]], seed: int) -> list[str]:
    robot = ROBOTS["kuka_kr6_r900_sixx"]
    cell = cell_for(robot, 1)
    rng = np.random.default_rng(seed)
    q, rows = np.array(home_joints(robot)), ["x,y,z,a,b,c"]
    for target, tilt, around, spin in targets:
        q = approach(robot, cell, q, target, tilt, around, spin, miss_mm=rng.normal(0, AIM_MM, 3))
        rows.append(",".join(f"{v:.4f}" for v in Pose.from_matrix(forward_kinematics(robot, q)).as_array()))
    return rows


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    tool = [(s.target, s.tilt_deg, s.around_deg, s.spin_deg) for s in METHODS["tool.xyz_4point"].steps]
    tool.append(("reference_tip", 25.0, 45.0, -90.0))  # a fifth orientation: the bad-point test runs
    base = [(s.target, s.tilt_deg, s.around_deg, s.spin_deg) for s in METHODS["base.3point"].steps]
    for name, targets, seed in (("touches.csv", tool, 1), ("plate.csv", base, 2)):
        (OUT / name).write_text("\n".join(flange_rows(targets, seed)) + "\n", encoding="utf-8")
        print(f"wrote {OUT / name}")


if __name__ == "__main__":
    main()
