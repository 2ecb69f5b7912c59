%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE A042_Data
    !***********************************************************
    ! Werkzeuge der Zelle 4 – Prüfspitze und Greifer
    ! Nota: di8 es la fotocélula
    !***********************************************************
    RECORD Blocks
        robtarget pos;  ! pose of the block
        num colorId;
    ENDRECORD
    TASK PERS tooldata tWeldGun:=[TRUE,[[109.186,-2.80676,376.482],[0.897126,0.00570523,0.441553,-0.0127845]],[5.3,[31.7,-4.1,38.8],[1,0,0,0],0.034,0.069,0.044]];
    LOCAL PERS tooldata tFlip := [TRUE,[[0,0,0],[1.91069E-15,-1,-4.37114E-08,-4.37114E-08]],[0,[0,0,0],[1,0,0,0],0,0,0]];
    PERS tooldata tProbe:=[ true,
        ! TCP of the Prüfspitze, measured 2024-03-12
        [ [ 0.5, -0.25, 120.75 ],
          [ 1, 0, 0, 0 ] ],   ! no turn
        [ 0.3, [ 0, 0, 40 ], [ 1, 0, 0, 0 ], 0, 0, 0 ] ];
    PERS tooldata tSpare{2}:=[[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]],[TRUE,[[0,0,200],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]]];
    LOCAL PERS wobjdata U_kal:=[false,true,"",[[1000,-250,12.5],[0.707107,0.707107,0,0]],[[50,20,0],[0.965926,0,0,0.258819]]];
    TASK PERS wobjdata wTable:=[FALSE, TRUE, "",[[450, 0, 0],[1, 0, 0, 0]],[[0,0,0],[1,0,0,0]]];
    LOCAL CONST robtarget pSafePos:=[[980.84,-25.17,1127.55],[0.183045,0.080843,0.979713,-0.0110132],[0,-1,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    TASK PERS jointtarget jtHome:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    PERS Blocks localizedBlocks{6};

    PROC main()
        TPWrite "Prüfung läuft!";
        MoveL pSafePos,v100,fine,tWeldGun\WObj:=wTable;
    ENDPROC
ENDMODULE
