%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE Cell7Data
  !***********************************************************
  ! Cell 7, IRB 6700 with IRBP A-250 positioner (STN1)
  ! Tool and work object data. Re-taught 2026-11-02.
  !***********************************************************

  ! Robot-held tools
  TASK PERS tooldata tGripper:=[TRUE,[[0,0,152.5],[1,0,0,0]],[3.2,[0,0,65],[1,0,0,0],0.012,0.012,0.006]];
  PERS tooldata tTorch:=[TRUE,[[148.32,-2.105,356.87],[0.831469612302545,0,0.555570233019602,0]],
    [6.8,[42.5,0,118.3],[0.98078528040323,0,0.195090322016128,0],0.045,0.052,0.018]];  ! 22.5 deg neck
  const tooldata tPen := [ TRUE,
                           [ [ 0, 0, 1.2E+2 ], [ 1, 0, 0, 0 ] ],   ! felt pen, 120 mm
                           [ 5.0E-1, [ 0, 0, 40 ], [ 1, 0, 0, 0 ], 0, 0, 0 ] ];
  PERS tooldata tSpare:=[TRUE,[[107.147,6.2E-5,313.237],[0.923879532511287,0,0.38268343236509,0]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];

  ! Stationary tool: glue nozzle on the pedestal. Its tload is what the robot
  ! carries while it works at the nozzle (gripper and door panel).
  PERS tooldata tGlueNozzle:=[FALSE,[[1250.4,-320.75,880],[0,0.707106781186548,0.707106781186548,0]],[4.5,[0,12,135],[1,0,0,0],0.02,0.03,0.01]];

  ! The robot holds the door panel and brings it to the nozzle
  PERS wobjdata wDoorPanel:=[TRUE,TRUE,"",[[12.5,-410.25,95],[0,0.707106781186548,-0.707106781186548,0]],[[0,0,0],[1,0,0,0]]];
  PERS loaddata wDoorPanel_load:=[18.75,[0,-80,40],[1,0,0,0],0.45,0.62,0.21];

  ! Work objects
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[1333.94,-175,-215.137],[0.707106781186548,0,0,-0.707106781186548]],
                         [[10,20,0],[0.996194698091746,0,0,0.0871557427476582]]];   ! oframe: part offset
  ! Fixture on the turntable: moved by STN1, uframe in the turntable's frame
  PERS wobjdata wTurntable:=[FALSE,FALSE,"STN1",[[0,0,412.5],[0.991444861373811,0,0,0.130526192220052]],
                             [[150,0,25],[1,0,0,0]]];

  ! What pendant cannot use: listed, not refused
  PERS tooldata tSet{2}:=[[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]],
                          [TRUE,[[0,0,200],[1,0,0,0]],[1,[0,0,50],[1,0,0,0],0,0,0]]];
  PERS tooldata tCopy:=tGripper;
  VAR tooldata tTemp;

  CONST robtarget pHome:=[[500,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR num nCount:=0;

  PROC main()
    MoveL pHome, v100, fine, tGripper\WObj:=wTable;
    nCount:=nCount+1;
  ENDPROC
ENDMODULE
