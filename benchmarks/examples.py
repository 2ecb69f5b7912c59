"""Write the example files of docs/api.md ("pendant calibrate"): flange poses taught in the
demo cell (KUKA KR 6 R900 sixx, cell seed 1), each touch-up off the mark like a person's
(0.05 mm per axis, seeded).

    python benchmarks/examples.py        # writes docs/examples/touches.csv, plate.csv, turntable.csv

turntable.csv: the mark on the demo turntable (its seeded hidden errors) touched with the true
pointer at five E1 values of the Root point menu, the E1 value in column ``e1``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from emulator import approach, cell_for, home_joints
from emulator import external as ext_emu
from server.menus import METHODS
from solvers.dh import forward_kinematics
from solvers.frames import Pose
from solvers.robots import ROBOTS

OUT = Path(__file__).resolve().parent.parent / "docs" / "examples"
AIM_MM = 0.05


def flange_rows(targets: list[tuple], seed: int) -> list[str]:
    """CSV rows of the flange poses at ``targets`` (target, tilt, around, spin[, E values])."""
    robot = ROBOTS["kuka_kr6_r900_sixx"]
    cell = cell_for(robot, 1)
    external = ext_emu.external_cell(robot.reach_mm, None, 1)
    rng = np.random.default_rng(seed)
    with_e = any(len(t) > 4 for t in targets)
    q, rows = np.array(home_joints(robot)), ["x,y,z,a,b,c" + (",e1" if with_e else "")]
    for target, tilt, around, spin, *ext in targets:
        goal = ext_emu.target(external, cell, target, ext[0]) if ext else target
        q = approach(robot, cell, q, goal, tilt, around, spin, miss_mm=rng.normal(0, AIM_MM, 3))
        row = [f"{v:.4f}" for v in Pose.from_matrix(forward_kinematics(robot, q)).as_array()]
        rows.append(",".join(row + ([f"{ext[0]['E1']:g}"] if ext else [])))
    return rows


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    tool = [(s.target, s.tilt_deg, s.around_deg, s.spin_deg) for s in METHODS["tool.xyz_4point"].steps]
    tool.append(("reference_tip", 25.0, 45.0, -90.0))  # a fifth orientation: the bad-point test runs
    base = [(s.target, s.tilt_deg, s.around_deg, s.spin_deg) for s in METHODS["base.3point"].steps]
    spec = METHODS["ext.root_point"]
    table = [(st.target, st.tilt_deg, st.around_deg, st.spin_deg, dict(st.external_axes or ()))
             for st in [*spec.steps, spec.extra_step(0), spec.extra_step(1)]]
    for name, targets, seed in (("touches.csv", tool, 1), ("plate.csv", base, 2),
                                ("turntable.csv", table, 3)):
        (OUT / name).write_text("\n".join(flange_rows(targets, seed)) + "\n", encoding="utf-8")
        print(f"wrote {OUT / name}")


if __name__ == "__main__":
    main()
