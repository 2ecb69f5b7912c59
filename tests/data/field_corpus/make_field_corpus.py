"""Writes tests/data/field_corpus: controller files with traits real ones have and
tests/data/controller-files lacks. Run ``python3 tests/data/field_corpus/make_field_corpus.py``;
the files are committed, this is how they were made. Each file's traits and the public file
it was checked against (read through a code index; nothing is copied, the values are ours):

kuka_kss5_6digit_cp1252_crlf.dat -- the layout of a real KR C2 / KSS 5 $config.dat
  (GitHub EdgarMontielG/Cell-3_R10, KRC/R1/System/$config.dat): reals printed with six
  significant digits ("380.790", "-90.0000", "M -1.00000"), other declarations around the
  tables (E6AXIS XHOME with E1..E6, STRUC / ENUM IPO_M_T definitions, SIGNAL ... TO ...,
  'B0001' bit strings, DEF_GROUP[n]=... ; comment, DECL LOAD LOAD_A1_DATA, REF_PT[16]),
  MACHINE_DEF / MACHINE_TOOL_DAT / MACHINE_FRAME_DAT with PARENT[] "WORLD", ;FOLD/;ENDFOLD;
  a used tool and a base left #NONE with a frame (a KR C4 $config.dat, GitHub
  HugoDanielson/ChinaMilling KRC/R1/System/$config.dat: TOOL_TYPE[3]=#NONE on a named tool with
  a frame and a load, BASE_TYPE[11]=#NONE on a frame with a blank name, nine-digit reals);
  a comment line with trailing spaces ("; CP - MOVEMENTS" and 49 spaces in that file);
  plus CR LF and Windows-1252 comments and names with umlauts (KSS writes on Windows).
kuka_hand_edited_utf8_bom.dat -- a $config.dat edited in a text editor: UTF-8 with a byte
  order mark, LF, lower-case keywords (KRL is case-insensitive), DECL left out ("FRAME
  TOOL_DATA[16]", as KSS itself writes "FRAME REF_TOOL=..." in the file above), spaces
  around "=" and ",", tabs, 1.0E+02 / 1.5e-3 / -0.0, a ";" inside a name, a trailing comment
  after an assignment, and a last line (ENDDAT) without a line end.
abb_rw6_task_pers_cp1252_crlf.mod -- RobotWare 6 program module: %%% header, TASK PERS and
  LOCAL PERS / LOCAL CONST (GitHub kangoananya/gkr_timber RW6-13 backup A088_DataTask_Rob.mod;
  a public BE_User1.mod with "TASK PERS tooldata tWeldGun" and 6-digit quaternions
  [0.897126,0.00570523,0.441553,-0.0127845]); spaces around ":=" and after "," and a tool of
  mass 0 (public M_Motion.mod / CM_Cylinder.mod: "LOCAL PERS tooldata tool := [TRUE,[[0,0,0],
  [1.91069E-15,-1,-4.37114E-08,-4.37114E-08]],..."); robtargets with 9E+09 external axes;
  an array of tooldata ({2}); a RECORD; lower-case true/false; a declaration over several
  lines with "!" comments inside the aggregate; a wobjdata with both uframe and oframe turned;
  CR LF and Windows-1252 comments ("Prüfspitze", "fotocélula").
abb_sysmodule_utf8_bom_lf.sys -- a system module written by a UTF-8 editor: BOM, LF,
  MODULE name(SYSMODULE,NOSTEPIN), lower-case "pers", "!" inside a string, CONST tooldata,
  and a last line (ENDMODULE) without a line end.
ur_commented_bom_no_final_eol.script, fanuc_listing_commented_no_final_eol.txt -- pendant's own
  UR script and FANUC listing (tests/data/ur_cell7.script, fanuc_cell7.txt) as a person keeps
  them: opened in a Windows editor that saved a UTF-8 BOM (UR) or CR LF (FANUC), a comment
  line of their own added near the top, a hand-spaced line, and no line end after the last
  line (Notepad does not add one).
fanuc_sysframe_one_group_lf.va -- SYSFRAME.VA of a one-group controller (ARRAY[1,n], as in the
  public FANUC post-processors that write it: "$MNUFRAME  Storage: SHADOW  Access: RW  :
  ARRAY[1,9] OF POSITION"), LF, Config F U T, and a last line without a line end.
"""

from pathlib import Path

HERE = Path(__file__).parent
Z6 = "{X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0}"
NOLOAD6 = "{M -1.00000,CM {X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0},J {X 0.0,Y 0.0,Z 0.0}}"


def kss5() -> list[str]:
    tools = {1: ("{X 0.0,Y 0.0,Z 380.790,A -90.0000,B -90.0000,C -90.0000}", "Schweißzange Öl",
                 "{M 21.0000,CM {X 27.0000,Y 0.0,Z 124.000,A 0.0,B 0.0,C 0.0},J {X 1.05000,Y 1.05000,Z 0.550000}}",
                 "#BASE"),
             2: ("{X 420.390,Y 195.500,Z 259.650,A 0.0,B 0.0,C 0.0}", "Greifer groß",
                 "{M 12.9297,CM {X 38.8040,Y -94.4510,Z 136.873,A 89.7770,B -0.721000,C 0.991000},J {X 0.525000,Y 0.557200,Z 0.765800}}",
                 "#BASE"),
             3: ("{X -186.740,Y 93.0000,Z 420.740,A -180.000,B 0.0,C 0.0}", "Teil Tür", NOLOAD6, "#TCP"),
             4: ("{X 409.434326,Y 3.01155138,Z 166.257782,A -90.0000,B 0.0,C 90.0000}", "Fräser alt",
                 "{M 42.0494804,CM {X -14.1015730,Y 6.26803398,Z 117.189,A -90.0347900,B -0.200267,C 0.849656},J {X 5.25000,Y 5.25000,Z 5.25000}}",
                 "#NONE")}
    bases = {1: ("{X 1333.94,Y -175.000,Z -215.137,A -90.0000,B 0.0,C 0.0}", "Vorrichtung 10A", "#BASE"),
             2: ("{X 21.8400,Y 1866.09,Z 658.470,A 90.0000,B 0.0,C 180.000}", "Klebedüse", "#TCP"),
             11: ("{X 1197.28235,Y 883.007,Z 776.392395,A -90.8298,B 0.254145205,C -0.0897579566}", " ",
                  "#NONE")}
    out = ["&ACCESS  RV", r"&PARAM DISKPATH = KRC:\R1\System", "&REL 1", "DEFDAT  $CONFIG",
           ";FOLD BASISTECH GLOBALS", ";==================================",
           "; VORGABEWERTE FÜR BEWEGUNGEN – nicht ändern", ";==================================",
           "INT DEF_OV_PRO=100", "INT DEF_VEL_PTP=100 ; PTP-Geschwindigkeit [%]",
           "; CP - BEWEGUNGEN" + " " * 49,
           "ENUM IPO_M_T NONE,TCP,BASE",
           "STRUC FDAT INT TOOL_NO,BASE_NO,IPO_MODE IPO_FRAME,CHAR POINT2[24],BOOL TQ_STATE",
           "STRUC MACHINE_TOOL_T INT MACH_DEF_INDEX,CHAR PARENT[24],CHAR GEOMETRY[255]",
           "STRUC MACHINE_FRAME_T INT MACH_DEF_INDEX,CHAR PARENT[24],CHAR GEOMETRY[255]",
           "SIGNAL CHANNEL_1 $ANOUT[1]", "SIGNAL EXTUSERID $IN[1026]  TO $IN[1026]",
           'DECL FDAT FDEFAULT={TOOL_NO 1,BASE_NO 0,IPO_FRAME #BASE,POINT2[] " ",TQ_STATE FALSE}',
           "INT COMPL_GROUP='B0001'", "INT DEF_GROUP[3]", "DEF_GROUP[1]='B1111' ; KOMPLETT",
           "DEF_GROUP[2]='B0001' ; NUR ROBOTER", "DEF_GROUP[3]='B0011' ; ROBOTER UND FAHRACHSE",
           "E6AXIS XHOME={A1 0.0,A2 -90.0000,A3 90.0000,A4 0.0,A5 0.0,A6 0.0,E1 0.0,E2 0.0,E3 0.0,E4 0.0,E5 0.0,E6 0.0}",
           "DECL FRAME REF_PT[2]", f"REF_PT[1]={Z6}", f"REF_PT[2]={Z6}",
           f"FRAME REF_TOOL={Z6}", "", "; TOOL AND BASE DATA", ";----------------------------------",
           "BOOL TOOL_CORR_ON=FALSE", f"FRAME TOOL_CORR={Z6}", "", "INT MAX_TOOL=16",
           "DECL FRAME TOOL_DATA[16]"]
    out += [f"TOOL_DATA[{n}]={tools.get(n, (Z6,))[0]}" for n in range(1, 17)]
    out += ["", "DECL CHAR TOOL_NAME[16,24]"]
    out += [f'TOOL_NAME[{n},]="{tools[n][1] if n in tools else " "}"' for n in range(1, 17)]
    out += ["", "DECL LOAD LOAD_DATA[16]"]
    out += [f"LOAD_DATA[{n}]={tools[n][2] if n in tools else NOLOAD6}" for n in range(1, 17)]
    out += ["", "DECL IPO_M_T TOOL_TYPE[16]"]
    out += [f"TOOL_TYPE[{n}]={tools[n][3] if n in tools else '#NONE'}" for n in range(1, 17)]
    out += ["", f"DECL LOAD LOAD_A1_DATA={NOLOAD6}",
            "DECL LOAD LOAD_A3_DATA={M 30.0000,CM {X -400.000,Y 0.0,Z -1315.00,A 0.0,B 0.0,C 0.0},J {X 10.0000,Y 10.0000,Z 10.0000}}",
            "", "INT MAX_BASE=32", "DECL FRAME BASE_DATA[32]"]
    out += [f"BASE_DATA[{n}]={bases.get(n, (Z6,))[0]}" for n in range(1, 33)]
    out += ["", "DECL CHAR BASE_NAME[32,24]"]
    out += [f'BASE_NAME[{n},]="{bases[n][1] if n in bases else " "}"' for n in range(1, 33)]
    out += ["", "DECL IPO_M_T BASE_TYPE[32]"]
    out += [f"BASE_TYPE[{n}]={bases[n][2] if n in bases else '#NONE'}" for n in range(1, 33)]
    out += ["", ";******************************************", "; VARIABLES FOR CELL DEFINITION",
            "INT MAX_MACHINES=3", "DECL MACHINE_DEF_T MACHINE_DEF[3]",
            'MACHINE_DEF[1]={NAME[] "KR 210 R2700 extra",COOP_KRC_INDEX 1,PARENT[] "WORLD",ROOT {X 0.0,Y 0.0,Z 0.0,A 0.0,B 0.0,C 0.0},MECH_TYPE #ROBOT,GEOMETRY[] "ObjectId = 12345"}']
    out += [f'MACHINE_DEF[{n}]={{NAME[] " ",COOP_KRC_INDEX 0,PARENT[] " ",ROOT {Z6},MECH_TYPE #NONE,GEOMETRY[] " "}}'
            for n in (2, 3)]
    out += ["", "DECL MACHINE_TOOL_T MACHINE_TOOL_DAT[16]"]
    out += [f'MACHINE_TOOL_DAT[{n}]={{MACH_DEF_INDEX {1 if n in tools else 0},PARENT[] '
            f'"{"KR 210 R2700 extra" if n in tools else " "}",GEOMETRY[] " "}}' for n in range(1, 17)]
    out += ["", "DECL MACHINE_FRAME_T MACHINE_FRAME_DAT[32]"]
    out += [f'MACHINE_FRAME_DAT[{n}]={{MACH_DEF_INDEX 0,PARENT[] "{"WORLD" if n in bases else " "}",GEOMETRY[] " "}}'
            for n in range(1, 33)]
    out += ["REAL EXTAX_TOL[2]", "EXTAX_TOL[1]=10.0000", "EXTAX_TOL[2]=10.0000",
            ";ENDFOLD (BASISTECH GLOBALS)", ";FOLD USER GLOBALS", "; Benutzer: Müller, Öl-Station",
            "BOOL TEILDA=FALSE", ";ENDFOLD (USER GLOBALS)", "ENDDAT", ""]
    return out


def hand_edited() -> list[str]:
    z = "{x 0.0,y 0.0,z 0.0,a 0.0,b 0.0,c 0.0}"
    nl = "{m -1,cm {x 0,y 0,z 0,a 0,b 0,c 0},j {x 0,y 0,z 0}}"
    out = ["&ACCESS RVP", "&REL 7", "defdat  $config", "; von Hand bearbeitet – Prüfstand",
           ";FOLD TOOL AND BASE DATA", "int max_tool=4", "frame tool_data[4]",
           "tool_data[1] = { x 1.0E+02 , y -0.0 , z 1.5e-3 , a 0.0 , b 90.0 , c -0.0 }",
           "\ttool_data[2]={X 12.5,Y 0.0,Z 2.5E+2,A 0.0,B 0.0,C 0.0}   ; kalibriert 2024-03-12",
           f"tool_data[3]={z}", f"tool_data[4]={z}", "",
           "char tool_name[4,24]", 'tool_name[1,]="Stift; lang"', 'tool_name[2,] = "Düse"',
           'tool_name[3,]=" "', 'tool_name[4,]=" "', "", "load load_data[4]",
           "load_data[1]={m 0.5,cm {x 0,y 0,z 40,a 0,b 0,c 0},j {x 1.0E-03,y 1.0E-03,z 5.0E-04}}",
           f"load_data[2]={nl}", f"load_data[3]={nl}", f"load_data[4]={nl}", "",
           "ipo_m_t tool_type[4]", "tool_type[1]=#base", "tool_type[2] = #tcp",
           "tool_type[3]=#none", "tool_type[4]=#none", "", "int max_base=2",
           "frame base_data[2]", "base_data[1]={x 1.0E+03,y -2.5E+02,z 0.0,a -0.0,b 0.0,c 0.0}",
           f"base_data[2]={z}", "char base_name[2,24]", 'base_name[1,]="Tisch"',
           'base_name[2,]=" "', "ipo_m_t base_type[2]", "base_type[1]=#base",
           "base_type[2]=#none", ";ENDFOLD", "enddat"]
    return out


def abb_rw6() -> list[str]:
    return [
        "%%%", "  VERSION:1", "  LANGUAGE:ENGLISH", "%%%", "", "MODULE A042_Data",
        "    !***********************************************************",
        "    ! Werkzeuge der Zelle 4 – Prüfspitze und Greifer",
        "    ! Nota: di8 es la fotocélula",
        "    !***********************************************************",
        "    RECORD Blocks", "        robtarget pos;  ! pose of the block", "        num colorId;",
        "    ENDRECORD",
        "    TASK PERS tooldata tWeldGun:=[TRUE,[[109.186,-2.80676,376.482],"
        "[0.897126,0.00570523,0.441553,-0.0127845]],[5.3,[31.7,-4.1,38.8],[1,0,0,0],0.034,0.069,0.044]];",
        "    LOCAL PERS tooldata tFlip := [TRUE,[[0,0,0],[1.91069E-15,-1,-4.37114E-08,-4.37114E-08]],"
        "[0,[0,0,0],[1,0,0,0],0,0,0]];",
        "    PERS tooldata tProbe:=[ true,",
        "        ! TCP of the Prüfspitze, measured 2024-03-12",
        "        [ [ 0.5, -0.25, 120.75 ],",
        "          [ 1, 0, 0, 0 ] ],   ! no turn",
        "        [ 0.3, [ 0, 0, 40 ], [ 1, 0, 0, 0 ], 0, 0, 0 ] ];",
        "    PERS tooldata tSpare{2}:=[[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]],"
        "[TRUE,[[0,0,200],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]];",
        "    LOCAL PERS wobjdata U_kal:=[false,true,\"\",[[1000,-250,12.5],[0.707107,0.707107,0,0]],"
        "[[50,20,0],[0.965926,0,0,0.258819]]];",
        "    TASK PERS wobjdata wTable:=[FALSE, TRUE, \"\",[[450, 0, 0],[1, 0, 0, 0]],[[0,0,0],[1,0,0,0]]];",
        "    LOCAL CONST robtarget pSafePos:=[[980.84,-25.17,1127.55],[0.183045,0.080843,0.979713,"
        "-0.0110132],[0,-1,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];",
        "    TASK PERS jointtarget jtHome:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];",
        "    PERS Blocks localizedBlocks{6};", "",
        "    PROC main()", "        TPWrite \"Prüfung läuft!\";",
        "        MoveL pSafePos,v100,fine,tWeldGun\\WObj:=wTable;", "    ENDPROC", "ENDMODULE", ""]


def abb_sys() -> list[str]:
    return ["MODULE user_tools(SYSMODULE,NOSTEPIN)", "  ! Werkzeugdaten – gepflegt in VS Code (UTF-8)",
            "  pers tooldata tNozzle:=[TRUE,[[1.5,-2.25,210.125],[0.9961947,0,0.0871557,0]],"
            "[1.2,[0,0,80],[1,0,0,0],0,0,0]];",
            "  CONST string sNote:=\"Düse! nicht anfassen\";",
            "  CONST tooldata tRef:=[TRUE,[[0,0,150],[1,0,0,0]],[0.5,[0,0,30],[1,0,0,0],0,0,0]];",
            "  pers wobjdata wJig:=[FALSE,TRUE,\"\",[[500,-500,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];",
            "ENDMODULE"]


def sysframe() -> list[str]:
    def frame(g: int, n: int, xyz, wpr, cfg="N D B") -> list[str]:
        return [f"    [{g},{n}] = ", f"  Group: {g}   Config: {cfg}, 0, 0, 0",
                "  X: {:>9.3f}   Y: {:>9.3f}   Z: {:>9.3f}".format(*xyz),
                "  W: {:>9.3f}   P: {:>9.3f}   R: {:>9.3f}".format(*wpr)]
    out = ["[*SYSTEM*]$MNUFRAME  Storage: SHADOW  Access: RW  : ARRAY[1,9] OF POSITION"]
    out += frame(1, 1, (1200.0, -350.25, 0.0), (0.0, 0.0, 90.0))
    for n in range(2, 10):
        out += frame(1, n, (0, 0, 0), (0, 0, 0)) if n != 4 else [f"    [1,{n}] = Uninitialized"]
    out += ["[*SYSTEM*]$MNUFRAMENUM  Storage: CMOS  Access: RW  : ARRAY[1] OF BYTE", "    [1] = 1",
            "[*SYSTEM*]$MNUTOOL  Storage: SHADOW  Access: RW  : ARRAY[1,10] OF POSITION"]
    out += frame(1, 1, (0.0, 0.0, 185.5), (0.0, 0.0, 0.0), "F U T")
    out += frame(1, 2, (12.125, -3.5, 240.0), (180.0, -30.0, 0.0), "F U T")
    for n in range(3, 11):
        out += frame(1, n, (0, 0, 0), (0, 0, 0))
    out += ["[*SYSTEM*]$MNUTOOLNUM  Storage: CMOS  Access: RW  : ARRAY[1] OF BYTE", "    [1] = 1"]
    return out


def write(name: str, lines: list[str], eol: str, encoding: str, bom: bool = False) -> None:
    text = eol.join(lines)
    (HERE / name).write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode(encoding))


def main() -> None:
    write("kuka_kss5_6digit_cp1252_crlf.dat", kss5(), "\r\n", "cp1252")
    write("kuka_hand_edited_utf8_bom.dat", hand_edited(), "\n", "utf-8", bom=True)
    write("abb_rw6_task_pers_cp1252_crlf.mod", abb_rw6(), "\r\n", "cp1252")
    write("abb_sysmodule_utf8_bom_lf.sys", abb_sys(), "\n", "utf-8", bom=True)
    write("fanuc_sysframe_one_group_lf.va", sysframe(), "\n", "ascii")
    data = HERE.parent
    ur = (data / "ur_cell7.script").read_text().rstrip("\n").split("\n")
    ur.insert(3, "# Zelle 7: kalibriert von J. Müller, 2024-03-12 (nicht löschen)")
    ur = [s.replace("set_payload(6.8, [0.0425, 0.0, 0.1183])", "set_payload(6.8,  [0.0425, 0.0, 0.1183])  # Brenner")
          .replace("global tool_6 = p[", "global tool_6 =  p[").replace(
              "3.14159265359, 0.0, 0.0]", "3.14159265359, 0.0, 0.0]  # alte Messspitze") for s in ur]
    write("ur_commented_bom_no_final_eol.script", ur, "\n", "utf-8", bom=True)
    fanuc = (data / "fanuc_cell7.txt").read_text().rstrip("\n").split("\n")
    fanuc.insert(3, "! Zelle 7: kalibriert von J. Mueller, 2024-03-12")
    write("fanuc_listing_commented_no_final_eol.txt", fanuc, "\r\n", "ascii")


if __name__ == "__main__":
    main()
