"""The Calibrate menus: each method's steps, the inputs it needs and its solver
(``methods``: tool, base, fixed tool, workpiece, light barrier; ``external``: the
External kinematics menus)."""

from server.menus.external import EXTERNAL_METHODS
from server.menus.methods import CALIBRATE_METHODS, MethodSpec

#: every menu by name: the Calibrate menus, then the External kinematics menus
METHODS: dict[str, MethodSpec] = {**CALIBRATE_METHODS, **{m.name: m for m in EXTERNAL_METHODS}}
