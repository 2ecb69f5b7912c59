%%%
  VERSION:1
  LANGUAGE:ENGLISH
%%%

MODULE MainModule
  ! Greifer und Werkstücke
  PERS tooldata tGripper:=[TRUE,[[0,3.01155138,185.5],[0.99998,0.00625,0,0]],[2.5,[0,0,60],[1,0,0,0],0,0,0]];
  PERS tooldata tSpare:=[TRUE,[[10,0,100],[1,0,0,0]],[-1,[0,0,0],[1,0,0,0],0,0,0]];
  PERS tooldata tPen:=[TRUE,[[0.5,-0.25,120.75],[0.707106781,0,0.707106781,0]],[0.3,[0,0,40],[1,0,0,0],0,0,0]];
  TASK PERS wobjdata wFixture:=[FALSE,TRUE,"",[[0,0,0],[1,0,0,0]],[[812.5,-240.125,305],[0.7071068,0,0,0.7071068]]];
  PERS wobjdata wTable:=[FALSE,TRUE,"",[[1200,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
  CONST robtarget pHome:=[[600,0,800],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];

  PROC main()
    VAR tooldata tTemp:=[TRUE,[[0,0,50],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];
    TPWrite "Cartón detectado.";
    MoveWith tGripper;
  ENDPROC

  PROC MoveWith(PERS tooldata Tool)
    MoveL pHome,v100,fine,Tool\WObj:=wTable;
  ENDPROC
ENDMODULE
