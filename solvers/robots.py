"""The robot library: published DH tables with joint limits and the source of each number.

Units mm and degrees; ``q`` is the joint value the controller shows. Each table was checked
against the vendor's or ROS-Industrial's URDF where named; ``tests/test_robots.py`` checks
forward kinematics against published poses.
"""

from __future__ import annotations

from solvers.dh import DHJoint, RobotModel
from solvers.frames import Pose


def _arm(a, alpha, d, offset, direction, limits) -> tuple[DHJoint, ...]:
    return tuple(DHJoint(a_mm=float(a_), alpha_deg=float(al), d_mm=float(d_), offset_deg=float(o),
                         direction=int(s), q_min_deg=float(lo), q_max_deg=float(hi))
                 for a_, al, d_, o, s, (lo, hi) in zip(a, alpha, d, offset, direction, limits))


KUKA_KR6_R900_SIXX = RobotModel(
    name="KUKA KR 6 R900 sixx",
    dh_convention="standard",
    # theta = [-A1, A2, A3 - 90, -A4, A5, -A6 + 180]: KUKA counts A1, A4, A6 against the DH sense.
    joints=_arm(a=[25, 455, 35, 0, 0, 0], alpha=[-90, 0, -90, 90, -90, 0],
                d=[400, 0, 0, 420, 0, 80], offset=[0, 0, -90, 0, 0, 180],
                direction=[-1, 1, 1, -1, 1, -1],
                limits=[(-170, 170), (-190, 45), (-120, 156), (-185, 185), (-120, 120), (-350, 350)]),
    source="DH: ros-industrial kuka_experimental kr6r900sixx_macro.xacro (checked at 20 random "
           "configurations); limits: KUKA KR AGILUS sixx data sheet (KR 6 R900 sixx).",
    payload_kg=6.0, reach_mm=901.0,
)

ABB_IRB_120 = RobotModel(
    name="ABB IRB 120",
    dh_convention="standard",
    joints=_arm(a=[0, 270, 70, 0, 0, 0], alpha=[-90, 0, -90, 90, -90, 0],
                d=[290, 0, 0, 302, 0, 72], offset=[0, -90, 0, 0, 0, 180],
                direction=[1] * 6,
                limits=[(-165, 165), (-110, 110), (-110, 70), (-160, 160), (-120, 120), (-400, 400)]),
    source="DH: ros-industrial abb irb120_3_58_macro.xacro (checked at 20 random configurations); "
           "limits: ABB IRB 120 product specification 3HAC035960-001.",
    payload_kg=3.0, reach_mm=580.0,
)

UR5E = RobotModel(
    name="Universal Robots UR5e",
    dh_convention="standard",
    joints=_arm(a=[0, -425, -392.2, 0, 0, 0], alpha=[90, 0, 0, 90, -90, 0],
                d=[162.5, 0, 0, 133.3, 99.7, 99.6], offset=[0] * 6, direction=[1] * 6,
                limits=[(-360, 360)] * 6),
    source="Universal Robots, 'DH parameters for calculations of kinematics and dynamics' "
           "(published table; every real UR carries its own calibrated deltas).",
    payload_kg=5.0, reach_mm=850.0,
)

UR10 = RobotModel(
    name="Universal Robots UR10 (CB3)",
    dh_convention="standard",
    joints=_arm(a=[0, -612, -572.3, 0, 0, 0], alpha=[90, 0, 0, 90, -90, 0],
                d=[127.3, 0, 0, 163.941, 115.7, 92.2], offset=[0] * 6, direction=[1] * 6,
                limits=[(-360, 360)] * 6),
    source="Universal Robots, 'DH parameters for calculations of kinematics and dynamics' (CB3 UR10).",
    payload_kg=10.0, reach_mm=1300.0,
)

TM5_900 = RobotModel(
    name="Techman TM5-900",
    dh_convention="modified",
    joints=_arm(a=[0, 0, 429, 411.5, 0, 0], alpha=[0, -90, 0, 0, 90, 90],
                d=[145.2, 0, 0, -122.3, 106, 113.15], offset=[0, -90, 0, 90, 0, 0],
                direction=[1] * 6,
                limits=[(-270, 270), (-180, 180), (-155, 155), (-180, 180), (-180, 180), (-270, 270)]),
    source="DH: TechmanRobotInc tmr_ros1 macro.tm5-900-nominal.urdf.xacro (checked at 20 random "
           "configurations); limits: Techman TM5-900 hardware manual. The robot of the laser paper.",
    payload_kg=4.0, reach_mm=900.0,
)

FANUC_LR_MATE_200ID = RobotModel(
    name="FANUC LR Mate 200iD",
    dh_convention="standard",
    # theta = [J1, J2 - 90, -(J3 + J2), -J4, -J5, -J6]: FANUC measures J3 from the horizontal.
    joints=_arm(a=[50, 330, 35, 0, 0, 0], alpha=[-90, 0, -90, 90, -90, 0],
                d=[330, 0, 0, 335, 0, 80], offset=[0, -90, 0, 0, 0, 0],
                direction=[1, 1, -1, -1, -1, -1],
                limits=[(-170, 170), (-100, 145), (-140.43, 280), (-190, 190), (-125, 125), (-360, 360)]),
    coupling=((1, 0, 0, 0, 0, 0), (0, 1, 0, 0, 0, 0), (0, 1, 1, 0, 0, 0),
              (0, 0, 0, 1, 0, 0), (0, 0, 0, 0, 1, 0), (0, 0, 0, 0, 0, 1)),
    base_pose=Pose(z=-330.0),  # FANUC's World frame sits 330 mm above DH frame 0
    source="DH: ros-industrial fanuc lrmate200id_macro.xacro (checked at 20 random configurations); "
           "limits: same URDF (J3 -140.43..280 deg, the data sheet's 420 deg range); J2/J3 coupling "
           "from the FANUC controller convention (ROS driver J23_factor = 1).",
    payload_kg=7.0, reach_mm=717.0,
)

ROBOTS: dict[str, RobotModel] = {
    "kuka_kr6_r900_sixx": KUKA_KR6_R900_SIXX,
    "abb_irb120": ABB_IRB_120,
    "ur5e": UR5E,
    "ur10": UR10,
    "tm5_900": TM5_900,
    "fanuc_lrmate200id": FANUC_LR_MATE_200ID,
}
"""Library key -> model. The five calibration-core arms plus the UR10 of the real data set."""
