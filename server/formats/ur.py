"""Universal Robots: a URScript snippet with TCPs, payloads and features.

UR writes a pose as ``p[x, y, z, rx, ry, rz]``: metres and a rotation vector (axis times
angle, radians). Each tool becomes ``global tool_<n> = p[...]`` (T_flange_tcp) and a
function ``use_tool_<n>()`` calling ``set_tcp`` and ``set_payload(mass, [cx, cy, cz])``
(kg, metres); a base becomes a feature ``global base_<n> = p[...]`` (T_world_base, in the
robot base frame). A fixed tool is ``global fixed_tool_<n>`` (its TCP in the robot base)
and a robot-held workpiece ``global workpiece_<n>`` (relative to the tool flange; in base
it is ``pose_trans(get_actual_tool_flange_pose(), workpiece_<n>)``).
"""

from __future__ import annotations

from typing import Iterable

from solvers.frames import ur_from_matrix

from server.formats.model import FormatError, FrameEntry, LoadData, one_line

__all__ = ["export_ur"]

_TITLE = {"tool": "Tools (TCP in the tool flange)",
          "workpiece": "Workpieces held by the robot (pose in the tool flange)",
          "base": "Features (bases, pose in the robot base)",
          "fixed_tool": "Fixed tools (TCP in the robot base)",
          "coordinated_base": "Features on a mechanical unit (pose in the unit's flange)"}


def _num(v: float, decimals: int) -> str:
    s = f"{round(float(v), decimals) + 0.0:.{decimals}f}".rstrip("0")
    return s + "0" if s.endswith(".") else s


def _p(entry: FrameEntry) -> str:
    v = ur_from_matrix(entry.pose.as_matrix())
    return "p[" + ", ".join([_num(x, 9) for x in v[:3]] + [_num(x, 12) for x in v[3:]]) + "]"


def _payload(load: LoadData) -> str:
    cog = ", ".join(_num(x / 1000.0, 9) for x in load.com_mm)
    return f"set_payload({_num(load.mass_kg, 6)}, [{cog}])"


def _comment(name: str) -> str:
    return one_line(name).replace('"', "'")


def export_ur(entries: Iterable[FrameEntry]) -> str:
    """URScript: ``global`` poses for every entry and a ``use_tool_<n>()`` per tool.

    Poses go through ``ur_from_matrix`` (metres, rotation vector of length <= pi); numbers
    carry 9 decimals in metres (1 nm) and 12 in radians. Inertia is not part of
    ``set_payload`` and is given in a comment.

    Raises
    ------
    FormatError
        ``("entries", i, "number")`` when two entries of one kind share a number.

    Examples
    --------
    >>> from solvers.frames import Pose
    >>> from server.formats.model import LoadData
    >>> text = export_ur([FrameEntry(1, "pointer", "tool", Pose(0, 0, 180, 0, 0, 0),
    ...                              LoadData(2.5, (0, 0, 80)))])
    >>> print(text, end="")  # doctest: +ELLIPSIS
    # pendant: Universal Robots TCP and feature data (docs/formats.md)
    ...
    # tool 1 "pointer"
    global tool_1 = p[0.0, 0.0, 0.18, 0.0, 0.0, 0.0]
    def use_tool_1():
      set_tcp(tool_1)
      set_payload(2.5, [0.0, 0.0, 0.08])
    end
    """
    entries = list(entries)
    seen: dict[tuple[str, int], int] = {}
    for i, e in enumerate(entries):  # named per kind: tool_1 and workpiece_1 may coexist
        if (e.kind, e.number) in seen:
            raise FormatError(("entries", i, "number"),
                              f"{e.kind} {e.number} is also entries[{seen[(e.kind, e.number)]}]")
        seen[(e.kind, e.number)] = i
    lines = ["# pendant: Universal Robots TCP and feature data (docs/formats.md)",
             "# p[x, y, z, rx, ry, rz]: metres, rotation vector in radians"]
    for kind in ("tool", "workpiece", "base", "fixed_tool", "coordinated_base"):
        chosen = sorted((e for e in entries if e.kind == kind), key=lambda e: e.number)
        if not chosen:
            continue
        lines += ["", f"# {_TITLE[kind]}"]
        for e in chosen:
            var = f"{kind}_{e.number}"
            lines += [f'# {kind} {e.number} "{_comment(e.name)}"', f"global {var} = {_p(e)}"]
            if kind == "tool":
                lines += [f"def use_{var}():", f"  set_tcp({var})"]
                if e.load is None:
                    lines.append("  # load not known: set the payload before running")
                else:
                    lines.append(f"  {_payload(e.load)}")
                lines.append("end")
            elif kind == "workpiece" and e.load is not None:
                lines.append(f"# payload while holding it: {_payload(e.load)}")
            if e.load is not None and any(e.load.inertia_kgm2):
                ix, iy, iz = (f"{x:.6g}" for x in e.load.inertia_kgm2)
                axes = ", ".join(f"{a:g}" for a in e.load.inertia_axes_deg)
                lines.append(f"# principal inertia {ix}, {iy}, {iz} kg m^2 "
                             f"(axes at KUKA A, B, C = {axes} deg)")
    return "\n".join(lines) + "\n"
