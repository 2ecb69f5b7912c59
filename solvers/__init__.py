"""Pure calibration math: frames, kinematics and every Calibrate-menu solver.

Nothing here touches the web, a database or the file system.
"""
