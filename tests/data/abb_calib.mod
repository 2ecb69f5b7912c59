%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE CalibData
  !***********************************************************
  ! Cell 4, IRB 6700 - tool and work object data
  ! Re-taught 2026-11-02 after the torch crash; see log book p. 41
  !***********************************************************

  ! Robot-held tools
  PERS tooldata tGripper:=[TRUE,[[0,0,152.5],[1,0,0,0]],[3.2,[0,0,65],[1,0,0,0],0.012,0.012,0.006]];
  PERS tooldata tTorch:=[TRUE,[[148.32,-2.105,356.87],[0.83147,0,0.55557,0]],
    [6.8,[42.5,0,118.3],[0.980785,0,0.19509,0],0.045,0.052,0.018]];  ! 22 deg neck
  TASK PERS tooldata tSpindle:=[TRUE,[[107.147,6.2E-5,313.237],[0.92388,0,0.382683,0]],[0.001,[0,0,0.001],[1,0,0,0],0,0,0]];
  const tooldata tPen := [ TRUE,
                           [ [ 0, 0, 1.2E+2 ], [ 1, 0, 0, 0 ] ],   ! felt pen, 120 mm
                           [ 0.5, [ 0, 0, 40 ], [ 1, 0, 0, 0 ], 0, 0, 0 ] ];

  ! Stationary tool: glue nozzle on the pedestal (tframe in world)
  PERS tooldata tGlueNozzle:=[FALSE,[[1250.4,-320.75,880],[0,0.707107,0.707107,0]],[2.5,[0,0,120],[1,0,0,0],0,0,0]];

  ! The robot holds the panel and brings it to the nozzle
  PERS wobjdata wPanel:=[TRUE,TRUE,"",[[0,0,380.79],[0.5,-0.5,0.5,-0.5]],[[0,0,0],[1,0,0,0]]];
  PERS loaddata wPanel_load:=[129.297,[38.804,-94.451,136.873],[1,0,0,0],5.25,5.572,7.658];
  PERS loaddata loadBox:=[12,[0,0,150],[1,0,0,0],0,0,0];

  ! Work objects
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[1333.94,-175,-215.137],[0.707107,0,0,-0.707107]],[[0,0,0],[1,0,0,0]]];
  PERS wobjdata wFixtureA:=[FALSE,TRUE,"",[[885.94,-145.63,-215.137],[0.707107,0,0,-0.707107]],
                            [[10,20,0],[0.996195,0,0,0.0871557]]];   ! oframe: part offset

  CONST robtarget pHome:=[[500,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
  VAR num nCount:=0;
  VAR tooldata tTemp;

  PROC main()
    ! MoveL pHome, v100, fine, tGripper\WObj:=wTable;
    MoveL pHome, v100, fine, tGripper\WObj:=wTable;
    nCount:=nCount+1;
  ENDPROC
ENDMODULE
