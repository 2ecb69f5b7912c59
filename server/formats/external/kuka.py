"""KUKA external kinematics: ``$machine.dat`` (``$EX_KIN``, ``$ETn_AX``, ``$ETn_NAME[]``,
``$ETn_TA1KR`` .. ``$ETn_TFLA3``, ``$ERSYSROOT``) and ``$config.dat`` (``MACHINE_DEF``, the bases
with their ``MACHINE_FRAME_DAT``); fragments or the controller's own files patched.

The chain and the model: :mod:`server.formats.external.model`; sources: docs/formats.md.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Iterable

import numpy as np

from server.formats import kuka as _kuka
from server.formats.external.model import (MAX_KINEMATICS, ExternalKinematic, ExternalSetup,
                                           _check_setup, _pose)
from server.formats.model import FormatError, FrameEntry, family_of, index_number, one_line
from solvers.errors import CalibrationError
from solvers.frames import Pose

__all__ = ["KukaExternalText", "kuka_external_kinematics", "read_kuka_external",
           "kuka_machine_name"]

KUKA_ET_NAME_CHARS = 20  # $ETn_NAME[] (width not verified; see docs/formats.md)


@dataclass(frozen=True)
class KukaExternalText:
    """The two KUKA fragments: for ``KRC:\\R1\\Mada\\$machine.dat`` and for
    ``KRC:\\R1\\System\\$config.dat`` (lines joined by ``"\\n"``)."""

    machine_dat: str
    config_dat: str


_FRAMES = ("TA1KR", "TA2A1", "TA3A2", "TFLA3")
_EASYS = "ABCDEF"


def kuka_machine_name(name: str) -> str:
    """A kinematic's name as KUKA files carry it (``$ETn_NAME[]``, ``MACHINE_DEF NAME[]``,
    ``MACHINE_FRAME_DAT PARENT[]``): one line, no ``"``, at most 20 characters, trimmed.

    Examples
    --------
    >>> kuka_machine_name('DKP "400"\\nBASE_DATA[1]={X 9}')
    'DKP  400  BASE_DATA['
    """
    return one_line(name).replace('"', " ").strip()[:KUKA_ET_NAME_CHARS].strip()


def _kname(k: ExternalKinematic) -> str:
    """The name KUKA files give kinematic ``k`` (``ETn`` when nothing of its name is left)."""
    return kuka_machine_name(k.name) or f"ET{k.number}"


def _machine_def_index(k: ExternalKinematic) -> int:
    """``MACHINE_DEF`` index of ETn: n + 1 (index 1 is the robot)."""
    return k.number + 1


def _ex_kin_type(k: ExternalKinematic) -> str:
    return "#ERSYS" if k.linear else f"#E{_EASYS[k.number - 1]}SYS"


def kuka_external_kinematics(kinematics: Iterable[ExternalKinematic],
                             bases: Iterable[FrameEntry] = (), *,
                             machine_template: str | None = None,
                             config_template: str | None = None) -> KukaExternalText:
    """The KUKA machine data of external kinematics and the ``$config.dat`` entries of the
    bases on them.

    ``$machine.dat``: ``DECL EX_KIN $EX_KIN={ET1 #EASYS,...}`` (``#EASYS`` .. ``#EFSYS`` a
    base kinematic ETn by its number, ``#ERSYS`` the linear unit carrying the robot),
    ``DECL ET_AX $ETn_AX={TR_A1 #E1,TR_A2 #NONE,TR_A3 #NONE}``, ``$ETn_NAME[]="..."``,
    ``FRAME $ETn_TA1KR``, ``$ETn_TA2A1``, ``$ETn_TA3A2`` (identity for unused axes) and
    ``$ETn_TFLA3``, and ``FRAME $ERSYSROOT`` (the linear unit's root). ``$config.dat``:
    ``MACHINE_DEF[n+1]={NAME[] "...",COOP_KRC_INDEX 1,PARENT[] " ",ROOT {...},MECH_TYPE
    #EASYS,GEOMETRY[] " "}`` (the root of base kinematic ETn) and, per base,
    ``BASE_DATA[n]`` (``T_flange_base``), ``BASE_NAME[n,]``, ``BASE_TYPE[n]=#BASE`` and
    ``MACHINE_FRAME_DAT[n]={MACH_DEF_INDEX n+1,PARENT[] "...",GEOMETRY[] " "}``.
    Reals have the shortest digits that read back as the same double (``krl_real``); names
    go through :func:`kuka_machine_name` (a name cannot add a line).

    Parameters
    ----------
    kinematics : iterable of ExternalKinematic
        Every external kinematic of the cell (ETn not listed is written ``#NONE``).
    bases : iterable of FrameEntry
        ``coordinated_base`` entries whose ``mech_unit`` is a listed (rotary) kinematic.
    machine_template, config_template : str, optional, keyword-only
        The whole ``$machine.dat`` / ``$config.dat`` imported before: the result is that file
        with only the values that changed rewritten (numbers whose value did not change keep
        their digits, with no change the file comes back byte for byte); variables it lacks
        are added before ``ENDDAT``. A ``MACHINE_DEF`` is found by its ``NAME[]``, else
        ``MACHINE_DEF[n+1]`` is used when free and declared; the bases go through
        :func:`~server.formats.kuka.export_kuka` with the template (their slots are replaced
        whole).

    Raises
    ------
    FormatError
        ``("kinematics", i, field)``: a number or axis used twice, two names written alike,
        two linear units; ``("bases", i, field)``: a base not a ``coordinated_base``, on no
        listed kinematic or on the linear unit, a slot given twice;
        ``("config_template", "line N", "MACHINE_DEF")``: no free entry for a new kinematic;
        a template's own read errors.

    Examples
    --------
    >>> from server.formats.external import turntable
    >>> t = kuka_external_kinematics([turntable(1, "TABLE", Pose(1500, 0, 300, 0, 0, 0))])
    >>> print("\\n".join(t.machine_dat.splitlines()[2:9]))
    DECL EX_KIN $EX_KIN={ET1 #EASYS,ET2 #NONE,ET3 #NONE,ET4 #NONE,ET5 #NONE,ET6 #NONE}
    ; ET1: turntable
    DECL ET_AX $ET1_AX={TR_A1 #E1,TR_A2 #NONE,TR_A3 #NONE}
    $ET1_NAME[]="TABLE"
    FRAME $ET1_TA1KR={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    FRAME $ET1_TA2A1={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    FRAME $ET1_TA3A2={X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}
    >>> print(t.config_dat.splitlines()[-1])
    MACHINE_DEF[2]={NAME[] "TABLE",COOP_KRC_INDEX 1,PARENT[] " ",ROOT {X 1500.0,Y 0.0,Z 300.0,A 0.0,B 0.0,C 0.0},MECH_TYPE #EASYS,GEOMETRY[] " "}
    """
    kins, base_list, by_name = _check_setup(kinematics, bases, _kname)
    machine = _machine_items(kins)
    config = _config_items(kins, {k.number: _machine_def_index(k) for k in kins})
    if machine_template is None:
        md = ["; External kinematics written by pendant (docs/formats.md): put these values",
              "; into the same declarations of KRC:\\R1\\Mada\\$machine.dat",
              *(line for _, line, _ in machine)]
        md_text = "\n".join(md) + "\n"
    else:
        md_text = _patch_krl(machine_template, machine, "machine_template")
    if config_template is None:
        cd = ["; Bases on external kinematics written by pendant (docs/formats.md): put these",
              "; values into the same entries of KRC:\\R1\\System\\$config.dat",
              *(line for _, line, _ in config)]
        for b in base_list:
            k = by_name[b.mech_unit]  # type: ignore[index]
            n = b.number
            cd += [f"BASE_DATA[{n}]={_kuka._frame(b.pose)}",
                   f"BASE_NAME[{n},]={_kuka._name(b.name)}", f"BASE_TYPE[{n}]=#BASE",
                   f"MACHINE_FRAME_DAT[{n}]="
                   f"{_kuka._machine_frame(_kname(k), _machine_def_index(k))}"]
        cd_text = "\n".join(cd) + "\n"
    else:
        cd_text = _patch_config(config_template, kins, base_list, by_name)
    return KukaExternalText(md_text, cd_text)


#: (variable, line to write, target: an aggregate's values by key path or a string's text)
_Item = tuple[str | None, str, object]


def _frame_target(p: Pose) -> dict[tuple[str, ...], object]:
    return {(k,): float(x) for k, x in zip(_kuka._FRAME_KEYS, p.as_array())}


def _machine_items(kins: list[ExternalKinematic]) -> list[_Item]:
    """The ``$machine.dat`` lines of ``kins`` with what each must hold (for patching)."""
    by_num = {k.number: k for k in kins}
    types = {f"ET{n}": _ex_kin_type(by_num[n]) if n in by_num else "#NONE"
             for n in range(1, MAX_KINEMATICS + 1)}
    ex_kin = ",".join(f"{et} {t}" for et, t in types.items())
    items: list[_Item] = [("EX_KIN", f"DECL EX_KIN $EX_KIN={{{ex_kin}}}",
                           {(et,): t for et, t in types.items()})]
    for k in kins:
        n = k.number
        axes = {f"TR_A{i}": f"#{a}" for i, a in enumerate([*k.axes, "NONE", "NONE"][:3], 1)}
        ax = ",".join(f"{tr} {a}" for tr, a in axes.items())
        frames = [*k.axis_frames, Pose(), Pose()][:3] + [k.flange]
        items += [(None, f"; ET{n}: {k.kind.replace('_', ' ')}", None),
                  (f"ET{n}_AX", f"DECL ET_AX $ET{n}_AX={{{ax}}}",
                   {(tr,): a for tr, a in axes.items()}),
                  (f"ET{n}_NAME[]", f'$ET{n}_NAME[]="{_kname(k)}"', _kname(k))]
        items += [(f"ET{n}_{sfx}", f"FRAME $ET{n}_{sfx}={_kuka._frame(p)}", _frame_target(p))
                  for sfx, p in zip(_FRAMES, frames)]
        if k.linear:
            items.append(("ERSYSROOT", f"FRAME $ERSYSROOT={_kuka._frame(k.root)}",
                          _frame_target(k.root)))
    return items


def _config_items(kins: list[ExternalKinematic], index: dict[int, int]) -> list[_Item]:
    """The ``MACHINE_DEF`` lines of the base kinematics (ETn at ``index[n]``)."""
    items: list[_Item] = []
    for k in kins:
        if k.linear:
            continue
        i, name, typ = index[k.number], _kname(k), _ex_kin_type(k)
        target = {("NAME[]",): name, ("MECH_TYPE",): typ,
                  **{("ROOT", *key): v for key, v in _frame_target(k.root).items()}}
        items.append((f"MACHINE_DEF[{i}]",
                      f'MACHINE_DEF[{i}]={{NAME[] "{name}",COOP_KRC_INDEX 1,PARENT[] " ",'
                      f'ROOT {_kuka._frame(k.root)},MECH_TYPE {typ},GEOMETRY[] " "}}', target))
    return items


def _patch_krl(template: str, items: list[_Item], what: str) -> str:
    """``template`` (a whole KRL data file) with each item's values patched into its line,
    and the lines of items it lacks added before ``ENDDAT``; other bytes kept."""
    found = _krl_values(template, what)
    lines = _kuka._LINES.findall(template)  # the lines _krl_values counts
    eol = "\r\n" if lines and lines[0].endswith("\r\n") else "\n"
    added = []
    for key, line, target in items:
        if key is None:
            continue
        if key not in found:
            added.append(line + eol)
            continue
        f = found[key]
        raw = lines[f.line - 1]
        a, b = f.span
        rhs = raw[a:b]
        if isinstance(target, dict):
            new = _kuka._patch_numbers(rhs, target, f.line, key)
        else:
            new = rhs if re.fullmatch(r'"\s*' + re.escape(str(target)) + r'\s*"', rhs) \
                else f'"{target}"'
        lines[f.line - 1] = raw[:a] + new + raw[b:]
    if added:
        at = next((i for i, raw in enumerate(lines)
                   if _kuka._ENDDAT.match(_kuka._strip_comment(raw))), len(lines))
        if at == len(lines) and lines and not lines[-1].endswith(("\n", "\r")):
            lines[-1] += eol
        lines[at:at] = added
    return "".join(lines)


def _patch_config(template: str, kins: list[ExternalKinematic], bases: list[FrameEntry],
                  by_name: dict[str, ExternalKinematic]) -> str:
    """A whole ``$config.dat`` with the kinematics' ``MACHINE_DEF`` entries (where the file
    names them, else at index n + 1) and the bases on them patched in (``export_kuka``)."""
    found = _krl_values(template, "config_template")
    defs = _machine_defs(found)
    decl = re.search(r"^[ \t]*DECL\s+\w+\s+MACHINE_DEF\s*\[\s*(\d+)\s*\]", template,
                     re.IGNORECASE | re.MULTILINE)
    decl_line = template.count("\n", 0, decl.start()) + 1 if decl else 0
    index: dict[int, int] = {}
    for k in kins:
        if k.linear:
            continue
        name = _kname(k).upper()
        if name in defs:
            index[k.number] = defs[name][1]
            continue
        i = _machine_def_index(k)
        key = f"MACHINE_DEF[{i}]"
        if key in found:
            other = _agg_at(found[key], "config_template", key).get("NAME[]")
            if isinstance(other, str) and other[1:-1].strip():
                raise FormatError(("config_template", f"line {found[key].line}", key),
                                  f"holds {other} and no MACHINE_DEF names {_kname(k)!r}: "
                                  "free the entry or name the kinematic like it")
        if decl and i > index_number(decl.group(1), decl_line, "MACHINE_DEF", "config_template"):
            raise FormatError(("config_template", f"line {decl_line}", "MACHINE_DEF"),
                              f"declared with {decl.group(1)} entries; ET{k.number} "
                              f"({_kname(k)!r}) needs MACHINE_DEF[{i}]: enlarge the array on "
                              "the controller or free an entry")
        index[k.number] = i
    text = _patch_krl(template, _config_items(kins, index), "config_template")
    written = {_kname(k).upper() for k in kins}
    slots = {b.number for b in bases}
    keep = [e for e in _kuka.read_kuka(text).entries
            if not (e.kind == "coordinated_base" and (e.mech_unit or "").upper() in written)
            and not (family_of(e.kind) == "stationary" and e.number in slots)]
    new = [replace(b, mech_unit=_kname(by_name[b.mech_unit])) for b in bases]  # type: ignore
    return _kuka.export_kuka(keep + new, template=text)


_KRL_LINE = re.compile(r"^\s*(?:DECL\s+)?(?:GLOBAL\s+)?(?:\w+\s+)?\$?(\w+)\s*(\[[^\]]*\])?\s*=\s*"
                       r"(.*?)\s*$", re.IGNORECASE)
#: the variables the readers use: one of them assigned twice is refused
_USED = re.compile(r"EX_KIN|ERSYSROOT|ET[1-6]_(AX|NAME\[\]|TA1KR|TA2A1|TA3A2|TFLA3)|"
                   r"(MACHINE_DEF|MACHINE_FRAME_DAT|BASE_DATA|BASE_TYPE)\[\d+\]|BASE_NAME\[\d+,\]")


@dataclass
class _Found:
    value: object
    line: int
    span: tuple[int, int] = (0, 0)  # of the right-hand side in its line


def _krl_values(text: str, what: str) -> dict[str, _Found]:
    """``{VARIABLE[index]: (right-hand side, line)}`` of every assignment or initialised
    declaration in a KRL data text (comments, headers, DEFDAT lines left out)."""
    if not isinstance(text, str):
        raise FormatError((what,), f"expected text, got {type(text).__name__}")
    out: dict[str, _Found] = {}
    for number, raw in enumerate(_kuka._LINES.findall(text), 1):  # CR LF, CR, LF only
        raw = raw.rstrip("\r\n")
        code = _kuka._strip_comment(raw)
        if not code.strip() or code.lstrip().startswith("&"):
            continue
        m = _KRL_LINE.match(code)
        if not m:
            continue
        key = (m.group(1) + re.sub(r"\s+", "", m.group(2) or "")).upper()
        if key in out and _USED.fullmatch(key):
            raise FormatError((what, f"line {number}", key),
                              f"assigned twice (first on line {out[key].line})")
        out.setdefault(key, _Found(m.group(3), number, m.span(3)))
    return out


def _frame_at(found: _Found, what: str, fld: str) -> Pose:
    try:
        agg = _kuka.parse_aggregate(str(found.value), found.line, fld)
        return Pose(*_kuka.aggregate_components(agg, _kuka._FRAME_KEYS, _kuka._UNITS, found.line, fld))
    except FormatError as err:
        raise FormatError((what, f"line {found.line}", str(err.loc[-1])), err.reason) from None


def _agg_at(found: _Found, what: str, fld: str) -> dict[str, object]:
    try:
        return _kuka.parse_aggregate(str(found.value), found.line, fld)
    except FormatError as err:
        raise FormatError((what, f"line {found.line}", str(err.loc[-1])), err.reason) from None


def _quoted(found: _Found, what: str, fld: str) -> str:
    m = re.fullmatch(r'"([^"]*)"', str(found.value))
    if not m:
        raise FormatError((what, f"line {found.line}", fld), 'expected a quoted name "..."')
    return m.group(1).strip()


def read_kuka_external(machine_dat: str, config_dat: str = "") -> ExternalSetup:
    """The external kinematics of a ``$machine.dat`` (whole or the fragment
    :func:`kuka_external_kinematics` writes) and the bases on them in a ``$config.dat``.

    Kinematic ETn exists when ``$EX_KIN`` gives it a type other than ``#NONE``: ``#ERSYS``
    is the linear unit carrying the robot (root ``$ERSYSROOT``), ``#EASYS`` .. ``#EFSYS`` a
    base kinematic (root ``MACHINE_DEF[k].ROOT`` of the entry whose ``NAME[]`` is
    ``$ETn_NAME[]``); its axes are the ``TR_A1..3`` of ``$ETn_AX`` up to the first ``#NONE``
    (one axis: turntable, two: positioner). The constant frames of unused axes
    (``$ETn_TA2A1``, ``$ETn_TA3A2``) are folded into the flange, as the chain
    ``TA1KR(E1) : TA2A1(E2) : TA3A2(E3) : TFLA3`` prescribes. Bases: every ``BASE_DATA[n]``
    whose ``MACHINE_FRAME_DAT[n]`` names one of these kinematics.

    Raises
    ------
    FormatError
        ``("machine_dat" | "config_dat", "line N", field)``: an unreadable frame or aggregate,
        a value beyond server/service/bounds.py, an assignment given twice; ``$EX_KIN`` missing or
        with an unknown type; a kinematic without its ``$ETn_AX``, ``$ETn_NAME``, frames,
        ``MACHINE_DEF`` or ``$ERSYSROOT``; a linear unit with more than one axis; three axes.

    Examples
    --------
    >>> from server.formats.external import turntable
    >>> k = turntable(1, "TABLE", Pose(1500, 0, 300, 0, 0, 0))
    >>> t = kuka_external_kinematics([k])
    >>> read_kuka_external(t.machine_dat, t.config_dat).kinematics == [k]
    True
    """
    mv = _krl_values(machine_dat, "machine_dat")
    cv = _krl_values(config_dat, "config_dat")
    if "EX_KIN" not in mv:
        raise FormatError(("machine_dat", "EX_KIN"), "no $EX_KIN: which external kinematics "
                          "exist is not said (DECL EX_KIN $EX_KIN={ET1 #EASYS,...})")
    ex_kin = _agg_at(mv["EX_KIN"], "machine_dat", "$EX_KIN")
    defs = _machine_defs(cv)
    kins = []
    for n in range(1, MAX_KINEMATICS + 1):
        typ = str(ex_kin.get(f"ET{n}", "#NONE")).upper()
        if typ == "#NONE":
            continue
        if not re.fullmatch(r"#E[A-F]SYS|#ERSYS", typ):
            raise FormatError(("machine_dat", f"line {mv['EX_KIN'].line}", f"$EX_KIN.ET{n}"),
                              f"expected #NONE, #EASYS..#EFSYS or #ERSYS, got {typ}")
        kins.append(_read_et(n, typ, mv, defs))
    return ExternalSetup(kins, _read_bases(cv, kins))


def _need(values: dict[str, _Found], key: str, what: str, why: str) -> _Found:
    if key not in values:
        raise FormatError((what, key), f"missing: {why}")
    return values[key]


def _read_et(n: int, typ: str, mv: dict[str, _Found], defs: dict[str, tuple[Pose, int]]
             ) -> ExternalKinematic:
    what = "machine_dat"
    ax_found = _need(mv, f"ET{n}_AX", what, f"$EX_KIN lists ET{n}; its axes $ET{n}_AX")
    ax = _agg_at(ax_found, what, f"$ET{n}_AX")
    axes: list[str] = []
    for i in (1, 2, 3):
        a = str(ax.get(f"TR_A{i}", "#NONE")).upper()
        if a == "#NONE":
            later = [j for j in range(i + 1, 4) if str(ax.get(f"TR_A{j}", "#NONE")).upper()
                     != "#NONE"]
            if later:
                raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX.TR_A{i}"),
                                  f"#NONE before TR_A{later[0]}: the axes are assigned from "
                                  "left to right without gaps")
            break
        if not re.fullmatch(r"#E[1-6]", a):
            raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX.TR_A{i}"),
                              f"expected #E1..#E6 or #NONE, got {a}")
        axes.append(a[1:])
    if len(axes) == 3:
        raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"),
                          "three-axis kinematics are not supported (turntable, two-axis "
                          "positioner, linear unit)")
    if not axes:
        raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"), "no axis assigned")
    name_found = _need(mv, f"ET{n}_NAME[]", what, f"the name of ET{n}, $ET{n}_NAME[]")
    name = _quoted(name_found, what, f"$ET{n}_NAME[]")
    frames = [_frame_at(_need(mv, f"ET{n}_{s}", what, f"the frame $ET{n}_{s}"), what,
                        f"$ET{n}_{s}") for s in _FRAMES]
    used, rest = frames[:len(axes)], frames[len(axes):]
    flange_T = np.eye(4)
    for p in rest:  # TA2A1 / TA3A2 of unused axes are constant links before TFLA3
        flange_T = flange_T @ p.as_matrix()
    flange = rest[-1] if len(rest) == 1 else _pose(flange_T)
    if typ == "#ERSYS":
        if len(axes) != 1:
            raise FormatError((what, f"line {ax_found.line}", f"$ET{n}_AX"),
                              "a linear unit (#ERSYS) has one axis")
        root = _frame_at(_need(mv, "ERSYSROOT", what, "the linear unit's root $ERSYSROOT"),
                         what, "$ERSYSROOT")
        kind = "linear_unit"
    else:
        if name.upper() not in defs:
            raise FormatError(("config_dat", "MACHINE_DEF"),
                              f'no MACHINE_DEF has NAME[] "{name}" ($ET{n}_NAME[] on line '
                              f"{name_found.line}): its root point is there")
        root = defs[name.upper()][0]
        kind = "turntable" if len(axes) == 1 else "positioner_2axis"
    try:
        return ExternalKinematic(n, name, kind, root, tuple(used), flange,  # type: ignore[arg-type]
                                 tuple(axes))
    except CalibrationError as err:
        raise FormatError((what, f"line {name_found.line}", f"ET{n}.{err.loc[0]}"),
                          err.reason) from None


def _machine_defs(cv: dict[str, _Found]) -> dict[str, tuple[Pose, int]]:
    """``NAME -> (ROOT, index)`` of every ``MACHINE_DEF[k]`` with a name."""
    out: dict[str, tuple[Pose, int]] = {}
    for key, found in cv.items():
        m = re.fullmatch(r"MACHINE_DEF\[(\d+)\]", key)
        if not m:
            continue
        fld = f"MACHINE_DEF[{m.group(1)}]"
        agg = _agg_at(found, "config_dat", fld)
        name = agg.get("NAME[]")
        if not isinstance(name, str):
            raise FormatError(("config_dat", f"line {found.line}", f"{fld}.NAME"),
                              'expected NAME[] "..."')
        if not name[1:-1].strip() or not isinstance(agg.get("ROOT"), dict):
            continue
        root = agg["ROOT"]
        try:
            pose = Pose(*_kuka.aggregate_components(root, _kuka._FRAME_KEYS,  # type: ignore[arg-type]
                                           _kuka._UNITS, found.line, f"{fld}.ROOT"))
        except FormatError as err:
            raise FormatError(("config_dat", f"line {found.line}", str(err.loc[-1])),
                              err.reason) from None
        out[name[1:-1].strip().upper()] = (pose, index_number(m.group(1), found.line, fld,
                                                              "config_dat"))
    return out


def _read_bases(cv: dict[str, _Found], kins: list[ExternalKinematic]) -> list[FrameEntry]:
    names = {k.name.upper(): k for k in kins if not k.linear}
    out = []
    for key, found in cv.items():
        m = re.fullmatch(r"MACHINE_FRAME_DAT\[(\d+)\]", key)
        if not m:
            continue
        n = index_number(m.group(1), found.line, key, "config_dat")
        try:
            unit = _kuka._parse_value("MACHINE_FRAME_DAT", str(found.value), found.line, key,
                                      None)
        except FormatError as err:
            raise FormatError(("config_dat", f"line {found.line}", str(err.loc[-1])),
                              err.reason) from None
        if unit is None or str(unit).upper() not in names:
            continue
        data = _need(cv, f"BASE_DATA[{n}]", "config_dat", f"{key} names {unit!r}; "
                     f"the base itself, BASE_DATA[{n}]")
        pose = _frame_at(data, "config_dat", f"BASE_DATA[{n}]")
        name = _quoted(cv[f"BASE_NAME[{n},]"], "config_dat", f"BASE_NAME[{n},]") \
            if f"BASE_NAME[{n},]" in cv else ""
        typ = str(cv[f"BASE_TYPE[{n}]"].value).upper() if f"BASE_TYPE[{n}]" in cv else "#BASE"
        if typ != "#BASE":
            raise FormatError(("config_dat", f"line {cv[f'BASE_TYPE[{n}]'].line}",
                               f"BASE_TYPE[{n}]"), f"{key} names a kinematic, so the base is "
                              f"used with IPO mode #BASE, got {typ}")
        try:
            out.append(FrameEntry(n, name, "coordinated_base", pose, None,
                                  names[str(unit).upper()].name))
        except CalibrationError as err:
            raise FormatError(("config_dat", f"line {data.line}", f"BASE[{n}].{err.loc[0]}"),
                              err.reason) from None
    return sorted(out, key=lambda b: b.number)
