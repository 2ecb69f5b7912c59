"""Writes the corpus of controller files (issue 23): our own files with the traits of real
ones. Run from anywhere: ``python3 tests/data/controller-files/make_corpus.py``; the files
are committed, this is how they were made.

- kuka_krc4_crlf_cp1252.dat: CRLF, Windows-1252 ("Greifer Öl"), 8- and 9-digit reals
  (Y 3.01155138, B 0.238999218), TOOL_TYPE[2]=#BASE with a zero frame and a blank name,
  M -1 loads, BASE_NAME[10,]="KukaReburn" on a #NONE zero slot, a #BASE base with a zero
  frame and a blank name;
- kuka_krc2_config.dat: KRC2 style (folds, E-notation reals, free spacing, no MACHINE_FRAME_DAT);
- kuka_all_unused.dat: a new robot's file: every slot #NONE, zero, M -1;
- kuka_mixed_endings.dat: CRLF with some LF lines;
- abb_program_cp1252_crlf.mod: CRLF, Windows-1252 (TPWrite "Cartón detectado."), a routine
  parameter (PERS tooldata Tool), a routine-local VAR tooldata, a quaternion
  [0.99998,0.00625,0,0], a work object defined by its oframe, a tool of mass -1;
- abb_mixed_endings.mod: LF with some CRLF lines, tagged declarations;
- abb_backup_36_tools.sys: a RobotWare-style system module with 36 tooldata;
- fanuc_crlf.txt, ur_crlf.script: pendant's own FANUC listing and UR script
  (tests/data/fanuc_cell7.txt, ur_cell7.script) with CR LF line ends;
- fanuc_sysframe_crlf.va: a controller's SYSFRAME.VA (the shape of an R-30iB V9 backup): CR LF,
  other variables around the tables ($MNUFRAMENUM, $MNUTOOLNUM, $MNUJOGFRAME), two motion
  groups (group 2 a positioner with frames of its own), Uninitialized entries, all-zero
  frames, "-0.000", a wide value (-1234.567) and a hand-edited line with other spacing.
"""

from pathlib import Path

HERE = Path(__file__).parent
ZERO = "{X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}"
NOLOAD = "{M -1.0,CM {X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0},J {X 0.0,Y 0.0,Z 0.0}}"


def kuka(tools: dict, bases: dict, header: list[str], krc2: bool = False) -> list[str]:
    lines = list(header)
    lines += ["INT MAX_TOOL=16", "DECL FRAME TOOL_DATA[16]"]
    lines += [f"TOOL_DATA[{n}]={tools.get(n, (ZERO,))[0]}" for n in range(1, 17)]
    lines += ["", "DECL CHAR TOOL_NAME[16,24]"]
    lines += [f'TOOL_NAME[{n}, ]="{tools[n][1] if n in tools else " "}"' if krc2 else
              f'TOOL_NAME[{n},]="{tools[n][1] if n in tools else " "}"' for n in range(1, 17)]
    lines += ["", "DECL LOAD LOAD_DATA[16]"]
    lines += [f"LOAD_DATA[{n}]={tools[n][2] if n in tools else NOLOAD}" for n in range(1, 17)]
    lines += ["", "DECL IPO_M_T TOOL_TYPE[16]"]
    lines += [f"TOOL_TYPE[{n}]={tools[n][3] if n in tools else '#NONE'}" for n in range(1, 17)]
    lines += ["", "INT MAX_BASE=32", "DECL FRAME BASE_DATA[32]"]
    lines += [f"BASE_DATA[{n}]={bases.get(n, (ZERO,))[0]}" for n in range(1, 33)]
    lines += ["", "DECL CHAR BASE_NAME[32,24]"]
    lines += [f'BASE_NAME[{n},]="{bases[n][1] if n in bases else " "}"' for n in range(1, 33)]
    lines += ["", "DECL IPO_M_T BASE_TYPE[32]"]
    lines += [f"BASE_TYPE[{n}]={bases[n][2] if n in bases else '#NONE'}" for n in range(1, 33)]
    return lines


HEAD4 = ["&ACCESS RVP", "&REL 12", "&PARAM EDITMASK = *",
         r"&PARAM TEMPLATE = C:\KRC\Roboter\Template\vorgabe", r"&PARAM DISKPATH = KRC:\R1\System",
         "DEFDAT  $CONFIG", ";FOLD BASISTECH GLOBALS", "INT DEF_OV_PRO=100",
         "DECL FDAT FDEFAULT={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,POINT2[] \" \",TQ_STATE FALSE}",
         ";ENDFOLD (BASISTECH GLOBALS)", ";FOLD TOOL AND BASE DATA",
         "; Werkzeuge und Basen (Zelle 4, Öl-Station)", "BOOL TOOL_CORR_ON=FALSE"]
TAIL = [";ENDFOLD (TOOL AND BASE DATA)", ";FOLD USER GLOBALS", "INT COUNTER_OEL=0",
        ";ENDFOLD (USER GLOBALS)", "ENDDAT", ""]


def write(name: str, lines: list[str], ends, encoding: str) -> None:
    text = "".join(line + ends(i, line) for i, line in enumerate(lines[:-1])) + lines[-1]
    (HERE / name).write_bytes(text.encode(encoding))


def main() -> None:
    tools = {1: ("{X 148.320007,Y 3.01155138,Z 357.125,A 0.0,B 67.5,C 0.0}", "Greifer Öl",
                 "{M 6.80000019,CM {X 12.0,Y 0.0,Z 80.5,A 0.0,B 0.0,C 0.0},"
                 "J {X 0.0500000007,Y 0.0500000007,Z 0.0199999996}}", "#BASE"),
             2: (ZERO, " ", NOLOAD, "#BASE"),
             3: ("{X 12.5,Y -410.25,Z 95.0,A -90.0,B 0.0,C 180.0}", "Tür links", NOLOAD, "#TCP"),
             5: ("{X 1.07147003E+02,Y 6.19999992E-05,Z 313.237,A 0.0,B 45.0,C 0.0}", "Schweißbrenner",
                 "{M 4.5,CM {X 0.0,Y 0.0,Z 120.0,A 0.0,B 0.0,C 0.0},J {X 0.0,Y 0.0,Z 0.0}}",
                 "#BASE")}
    bases = {1: ("{X 1200.5,Y -350.25,Z 0.0,A 90.0,B 0.238999218,C 0.0}", "Tisch 1", "#BASE"),
             2: ("{X 640.0,Y 820.0,Z 455.5,A 0.0,B 0.0,C 0.0}", "Kleberdüse", "#TCP"),
             3: (ZERO, " ", "#BASE"),
             10: (ZERO, "KukaReburn", "#NONE")}
    lines = kuka(tools, bases, HEAD4) + TAIL
    write("kuka_krc4_crlf_cp1252.dat", lines, lambda i, s: "\r\n", "cp1252")
    write("kuka_mixed_endings.dat", lines,
          lambda i, s: "\n" if i % 7 == 3 or s.startswith("BASE_NAME") else "\r\n", "cp1252")

    head2 = ["&ACCESS RVP", "&REL 3", "&PARAM TEMPLATE = C:\\KRC\\Roboter\\Template\\vorgabe",
             "DEFDAT  $CONFIG", ";FOLD BASISTECH GLOBALS", ";ENDFOLD", ";FOLD TOOL AND BASE DATA"]
    tools2 = {1: ("{X 2.20500002E+02,Y -1.5,Z 1.85250000E+02,A 0.0,B 0.0,C 0.0}", "Pinsel",
                  "{M 2.0,CM {X 0.0,Y 0.0,Z 50.0,A 0.0,B 0.0,C 0.0},J {X 0.0,Y 0.0,Z 0.0}}",
                  "#BASE"),
              2: ("{X 10.0,Y 20.0,Z 30.0,A 0.5,B -0.25,C 0.125}", "Messspitze", NOLOAD, "#BASE")}
    bases2 = {1: ("{X 900.0,Y 0.0,Z 400.0,A 1.79999995,B 0.0,C 0.0}", "Vorrichtung", "#BASE")}
    write("kuka_krc2_config.dat", kuka(tools2, bases2, head2, krc2=True) + [";ENDFOLD", "ENDDAT", ""],
          lambda i, s: "\n", "cp1252")
    write("kuka_all_unused.dat", kuka({}, {}, head2) + [";ENDFOLD", "ENDDAT", ""],
          lambda i, s: "\r\n", "cp1252")

    abb = ["%%%", "  VERSION:1", "  LANGUAGE:ENGLISH", "%%%", "", "MODULE MainModule",
           "  ! Greifer und Werkstücke",
           "  PERS tooldata tGripper:=[TRUE,[[0,3.01155138,185.5],[0.99998,0.00625,0,0]],"
           "[2.5,[0,0,60],[1,0,0,0],0,0,0]];",
           "  PERS tooldata tSpare:=[TRUE,[[10,0,100],[1,0,0,0]],[-1,[0,0,0],[1,0,0,0],0,0,0]];",
           "  PERS tooldata tPen:=[TRUE,[[0.5,-0.25,120.75],[0.707106781,0,0.707106781,0]],"
           "[0.3,[0,0,40],[1,0,0,0],0,0,0]];",
           "  TASK PERS wobjdata wFixture:=[FALSE,TRUE,\"\",[[0,0,0],[1,0,0,0]],"
           "[[812.5,-240.125,305],[0.7071068,0,0,0.7071068]]];",
           "  PERS wobjdata wTable:=[FALSE,TRUE,\"\",[[1200,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];",
           "  CONST robtarget pHome:=[[600,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];",
           "", "  PROC main()",
           "    VAR tooldata tTemp:=[TRUE,[[0,0,50],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];",
           "    TPWrite \"Cartón detectado.\";", "    MoveWith tGripper;", "  ENDPROC", "",
           "  PROC MoveWith(PERS tooldata Tool)",
           "    MoveL pHome,v100,fine,Tool\\WObj:=wTable;", "  ENDPROC", "ENDMODULE", ""]
    write("abb_program_cp1252_crlf.mod", abb, lambda i, s: "\r\n", "cp1252")
    mixed = ["MODULE CalibData", "  ! Tool and work object data",
             '  ! pendant: tool 1 "Nozzle"',
             "  PERS tooldata Nozzle:=[TRUE,[[1.5,-2.25,210.125],[0.9961947,0,0.0871557,0]],"
             "[1.2,[0,0,80],[1,0,0,0],0,0,0]];",
             '  ! pendant: tool 2 "Probe"',
             "  PERS tooldata Probe:=[TRUE,[[0,0,150],[1,0,0,0]],[0.5,[0,0,30],[1,0,0,0],0,0,0]];",
             '  ! pendant: base 1 "Pallet"',
             "  PERS wobjdata Pallet:=[FALSE,TRUE,\"\",[[1000,250,-12.5],[0.999048222,0,0,0.0436193874]],"
             "[[0,0,0],[1,0,0,0]]];",
             '  ! pendant: base 4 "Jig"',
             "  PERS wobjdata Jig:=[FALSE,TRUE,\"\",[[500,-500,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];",
             "ENDMODULE", ""]
    write("abb_mixed_endings.mod", mixed, lambda i, s: "\r\n" if i % 2 else "\n", "utf-8")
    backup = ["MODULE user(SYSMODULE)", "  ! RobotWare 6 backup: 36 tools"]
    for n in range(1, 37):
        backup.append(f"  PERS tooldata tool_{n:02d}:=[TRUE,[[{n}.5,{-n}.25,{100 + n}],"
                      f"[1,0,0,0]],[{0.5 + n / 10:g},[0,0,{n}],[1,0,0,0],0,0,0]];")
    backup += ["  PERS wobjdata wobj_station:=[FALSE,TRUE,\"\",[[1500,0,300],[1,0,0,0]],"
               "[[0,0,0],[1,0,0,0]]];", "ENDMODULE", ""]
    write("abb_backup_36_tools.sys", backup, lambda i, s: "\r\n", "cp1252")
    write("fanuc_sysframe_crlf.va", sysframe(), lambda i, s: "\r\n", "ascii")
    data = HERE.parent
    for src, dst in (("fanuc_cell7.txt", "fanuc_crlf.txt"), ("ur_cell7.script", "ur_crlf.script")):
        lf = (data / src).read_bytes().replace(b"\r\n", b"\n")
        (HERE / dst).write_bytes(lf.replace(b"\n", b"\r\n"))


def sysframe() -> list[str]:
    """A controller's SYSFRAME.VA: tool 1 and 3, user frames 1 and 2 of group 1 set; a
    positioner (group 2) with a tool and a frame of its own."""
    def table(var: str, size: int, frames: dict) -> list[str]:
        out = [f"[*SYSTEM*]{var}  Storage: SHADOW  Access: RW  : ARRAY[2,{size}] OF POSITION"]
        for g in (1, 2):
            for n in range(1, size + 1):
                v = frames.get((g, n))
                if v == "uninit":
                    out.append(f"    [{g},{n}] = Uninitialized")
                    continue
                v = v or (0.0,) * 6
                out += [f"    [{g},{n}] = ", f"  Group: {g}   Config: N D B, 0, 0, 0"]
                if isinstance(v, str):  # a line as typed by hand
                    out += v.split("|")
                    continue
                out += [f"  X: {v[0]:9.3f}   Y: {v[1]:9.3f}   Z: {v[2]:9.3f}",
                        f"  W: {v[3]:9.3f}   P: {v[4]:9.3f}   R: {v[5]:9.3f}"]
        return out

    tools = {(1, 1): (1.25, -0.5, 185.0, 0.0, -90.0, 0.0),
             (1, 2): "uninit",
             (1, 3): "  X:    12.500 Y:   -1234.567   Z:   310.250|"
                     "  W:   -0.000   P:    45.000 R:  180.000",
             (2, 1): (0.0, 0.0, 50.0, 0.0, 0.0, 0.0)}
    frames = {(1, 1): (1500.0, -250.0, 300.0, 0.0, 0.0, 90.0),
              (1, 2): (800.125, 600.0, -12.5, 0.5, -0.25, 179.5),
              (1, 5): "uninit",
              (2, 1): (0.0, 0.0, 400.0, 0.0, 0.0, 0.0)}
    return (["[*SYSTEM*]$MNUFRAMENUM  Storage: CMOS  Access: RW  : ARRAY[2] OF BYTE",
             "    [1] = 2", "    [2] = 0"]
            + table("$MNUFRAME", 9, frames)
            + ["[*SYSTEM*]$MNUJOGFRAME  Storage: SHADOW  Access: RW  : ARRAY[2,5] OF POSITION",
               "    [1,1] = Uninitialized"]
            + table("$MNUTOOL", 10, tools)
            + ["[*SYSTEM*]$MNUTOOLNUM  Storage: CMOS  Access: RW  : ARRAY[2] OF BYTE",
               "    [1] = 1", "    [2] = 1", ""])


if __name__ == "__main__":
    main()
