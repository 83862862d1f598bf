MODULE PlugcellEGM
    ! Written by `plugcell egm files`: EGM path corrections from plugcell at
    ! {{sensor_ip}}:{{port}} (UDP unit device "{{device}}"), sample rate {{sample_ms}} ms.
    ! On the PC: plugcell egm run --robot-ip CONTROLLER_IP --port {{port}} --mode pathcorr
    ! The robot runs its own path (EGMMoveL); plugcell's corrections (y, z in path
    ! coordinates, mm) are added, held to its limits: {{limits}}.
    ! Teach p_start and p_end (and egm_tool, egm_wobj) for your cell first.
    VAR egmident egm_id;
    CONST pose egm_sensor_frame := [[0, 0, 0], [1, 0, 0, 0]];
    PERS tooldata egm_tool := [TRUE, [[0, 0, 0], [1, 0, 0, 0]], [0.001, [0, 0, 0.001], [1, 0, 0, 0], 0, 0, 0]];
    PERS wobjdata egm_wobj := [FALSE, TRUE, "", [[0, 0, 0], [1, 0, 0, 0]], [[0, 0, 0], [1, 0, 0, 0]]];
    CONST robtarget p_start := [[600, -200, 800], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];
    CONST robtarget p_end := [[600, 200, 800], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];

    PROC main()
        EGMGetId egm_id;
        EGMSetupUC ROB_1, egm_id, "pathCorr", "{{device}}" \PathCorr \APTR;
        EGMActMove egm_id, egm_sensor_frame.trans \SampleRate:={{sample_ms}};
        MoveL p_start, v100, fine, egm_tool \WObj:=egm_wobj;
        EGMMoveL egm_id, p_end, v100, z10, egm_tool \WObj:=egm_wobj;
        EGMMoveL egm_id, p_start, v100, fine, egm_tool \WObj:=egm_wobj;
        EGMReset egm_id;
    ENDPROC
ENDMODULE
