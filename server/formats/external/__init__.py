"""External kinematics in controller files (issue 13): turntables, two-axis positioners and a
linear unit carrying the robot, with the bases on them.

- :mod:`.model`: :class:`ExternalKinematic` (the chain ``root @ F_1 @ J(q_1) [@ F_2 @ J(q_2)]
  @ flange``), the constructors from the solvers' results (:func:`turntable`,
  :func:`positioner_2axis`, :func:`linear_unit`) and :func:`flange_matrix`;
- :mod:`.kuka`: :func:`kuka_external_kinematics` / :func:`read_kuka_external`
  (``$machine.dat``, ``$config.dat``);
- :mod:`.abb`: :func:`abb_mechanical_units` / :func:`read_abb_external` (``MOC.cfg``, RAPID).

See docs/formats.md, "External kinematics", for the layouts and their public sources.
"""

from server.formats.external.abb import (AbbExternalText, abb_mechanical_units, abb_unit_name,
                                         read_abb_external)
from server.formats.external.kuka import (KukaExternalText, kuka_external_kinematics,
                                          kuka_machine_name, read_kuka_external)
from server.formats.external.model import (AXIS_COUNT, KINDS, MAX_KINEMATICS, ExternalKinematic,
                                           ExternalKind, ExternalSetup, flange_matrix,
                                           linear_unit, positioner_2axis, turntable)

#: the files each controller keeps these in (for a download)
FILE_NAMES: dict[str, tuple[str, str]] = {
    "kuka": ("$machine.dat", "$config.dat"), "abb": ("MOC.cfg", "ExtUnits.mod"),
}

__all__ = [
    "AXIS_COUNT", "AbbExternalText", "ExternalKind", "ExternalKinematic", "ExternalSetup",
    "FILE_NAMES", "KINDS", "KukaExternalText", "MAX_KINEMATICS", "abb_mechanical_units",
    "abb_unit_name", "flange_matrix", "kuka_external_kinematics", "kuka_machine_name",
    "linear_unit", "positioner_2axis", "read_abb_external", "read_kuka_external", "turntable",
]
