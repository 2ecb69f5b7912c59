MODULE CalibData
  ! Tool and work object data
  ! pendant: tool 1 "Nozzle"
  PERS tooldata Nozzle:=[TRUE,[[1.5,-2.25,210.125],[0.9961947,0,0.0871557,0]],[1.2,[0,0,80],[1,0,0,0],0,0,0]];
  ! pendant: tool 2 "Probe"
  PERS tooldata Probe:=[TRUE,[[0,0,150],[1,0,0,0]],[0.5,[0,0,30],[1,0,0,0],0,0,0]];
  ! pendant: base 1 "Pallet"
  PERS wobjdata Pallet:=[FALSE,TRUE,"",[[1000,250,-12.5],[0.999048222,0,0,0.0436193874]],[[0,0,0],[1,0,0,0]]];
  ! pendant: base 4 "Jig"
  PERS wobjdata Jig:=[FALSE,TRUE,"",[[500,-500,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];
ENDMODULE
