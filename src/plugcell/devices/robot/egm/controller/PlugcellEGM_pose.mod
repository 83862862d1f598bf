MODULE PlugcellEGM
    ! Written by `plugcell egm files`: EGM pose targets from plugcell at {{sensor_ip}}:{{port}}
    ! (UDP unit device "{{device}}"), sample rate {{sample_ms}} ms, CommTimeout {{timeout_s}} s.
    ! On the PC: plugcell egm run --robot-ip CONTROLLER_IP --port {{port}} --mode pose
    ! plugcell sends the TCP pose where EGM started (in egm_wobj, with egm_tool) moved by its
    ! offset, held to its limits: {{limits}}.
    VAR egmident egm_id;
    VAR egmstate egm_state;
    ! convergence condition (mm, degrees)
    CONST egm_minmax egm_cond := [-0.1, 0.1];
    ! the correction and sensor frames: the work object's own
    CONST pose egm_frame := [[0, 0, 0], [1, 0, 0, 0]];
    PERS tooldata egm_tool := [TRUE, [[0, 0, 0], [1, 0, 0, 0]], [0.001, [0, 0, 0.001], [1, 0, 0, 0], 0, 0, 0]];
    PERS wobjdata egm_wobj := [FALSE, TRUE, "", [[0, 0, 0], [1, 0, 0, 0]], [[0, 0, 0], [1, 0, 0, 0]]];

    PROC main()
        EGMGetId egm_id;
        egm_state := EGMGetState(egm_id);
        IF egm_state <= EGM_STATE_CONNECTED THEN
            EGMSetupUC ROB_1, egm_id, "default", "{{device}}" \Pose \CommTimeout:={{timeout_s}};
        ENDIF
        EGMActPose egm_id \Tool:=egm_tool \WObj:=egm_wobj, egm_frame, EGM_FRAME_WOBJ, egm_frame,
            EGM_FRAME_WOBJ \x:=egm_cond \y:=egm_cond \z:=egm_cond \rx:=egm_cond \ry:=egm_cond
            \rz:=egm_cond \SampleRate:={{sample_ms}} \MaxSpeedDeviation:={{max_speed_deg}};
        EGMRunPose egm_id, EGM_STOP_HOLD \x \y \z \Rx \Ry \Rz \CondTime:={{cond_time}}
            \RampInTime:=0.05;
        EGMReset egm_id;
    ERROR
        IF ERRNO = ERR_UDPUC_COMM THEN
            TPWrite "plugcell EGM: no message from the PC within CommTimeout";
            EGMReset egm_id;
            RETURN;
        ENDIF
    ENDPROC
ENDMODULE
