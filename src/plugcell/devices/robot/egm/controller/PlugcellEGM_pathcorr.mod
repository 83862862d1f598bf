MODULE PlugcellEGM
    ! Written by `plugcell egm files`: EGM path corrections from plugcell at
    ! {{sensor_ip}}:{{port}} (UDP unit device "{{device}}"), sample rate {{sample_ms}} ms,
    ! CommTimeout {{timeout_s}} s.  The robot drives, the PC corrects (issue 37, mode (b)):
    ! the robot runs its own path (EGMMoveL) and plugcell's corrections (y, z in path
    ! coordinates, mm) are added, held to its limits: {{limits}}.
    ! On the PC: plugcell serve robot --egm {{sensor_ip}}:{{port}} --egm-robot CONTROLLER_IP
    !   --param egm_mode=pathcorr, then: plugcell call ROBOT CORRECT (docs/abb-egm.md)
    ! (or, to try the stream: plugcell egm run --robot-ip CONTROLLER_IP --port {{port}}
    !   --mode pathcorr).
    ! Teach p_start and p_end (and egm_tool, egm_wobj) for your cell first.  The
    ! ExtConfigName "{{ext_config}}" is a Motion > External Motion Interface Data entry
    ! (MOC_plugcell.cfg: load it with the parameters).
    VAR egmident egm_id;
    VAR egmstate egm_state;
    ! the sensor frame in the tool frame: the path coordinates' origin
    CONST pose egm_sensor_frame := [[0, 0, 0], [1, 0, 0, 0]];
    PERS tooldata egm_tool := [TRUE, [[0, 0, 0], [1, 0, 0, 0]], [0.001, [0, 0, 0.001], [1, 0, 0, 0], 0, 0, 0]];
    PERS wobjdata egm_wobj := [FALSE, TRUE, "", [[0, 0, 0], [1, 0, 0, 0]], [[0, 0, 0], [1, 0, 0, 0]]];
    CONST robtarget p_start := [[600, -200, 800], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];
    CONST robtarget p_end := [[600, 200, 800], [0, 0, 1, 0], [0, 0, 0, 0], [9E9, 9E9, 9E9, 9E9, 9E9, 9E9]];

    PROC main()
        EGMGetId egm_id;
        egm_state := EGMGetState(egm_id);
        IF egm_state <= EGM_STATE_CONNECTED THEN
            EGMSetupUC ROB_1, egm_id, "{{ext_config}}", "{{device}}" \PathCorr \APTR \CommTimeout:={{timeout_s}};
        ENDIF
        EGMActMove egm_id, egm_sensor_frame \SampleRate:={{sample_ms}};
        ! the start of your path, without correction
        MoveL p_start, v100, fine, egm_tool \WObj:=egm_wobj;
        ! ---- your path: EGMMoveL moves, each corrected by the PC -----------------
        EGMMoveL egm_id, p_end, v100, z10, egm_tool \WObj:=egm_wobj;
        EGMMoveL egm_id, p_start, v100, fine, egm_tool \WObj:=egm_wobj;
        ! ---- end of your path ------------------------------------------------------
        EGMReset egm_id;
    ERROR
        IF ERRNO = ERR_UDPUC_COMM THEN
            TPWrite "plugcell EGM: no message from the PC within CommTimeout";
            EGMReset egm_id;
            RETURN;
        ENDIF
    ENDPROC
ENDMODULE
