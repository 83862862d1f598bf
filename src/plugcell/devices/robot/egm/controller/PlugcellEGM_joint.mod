MODULE PlugcellEGM
    ! Written by `plugcell egm files`: EGM joint targets from plugcell at {{sensor_ip}}:{{port}}
    ! (UDP unit device "{{device}}"), sample rate {{sample_ms}} ms, CommTimeout {{timeout_s}} s.
    ! On the PC: plugcell egm run --robot-ip CONTROLLER_IP --port {{port}} --mode joint
    ! plugcell sends the joints where EGM started plus its offset, held to its limits:
    ! {{limits}}.
    ! The robot holds (EGM_STOP_HOLD) when the PC stops, and EGM ends after CommTimeout.
    VAR egmident egm_id;
    VAR egmstate egm_state;
    ! convergence condition of each joint (degrees): EGMRunJoint runs until CondTime
    CONST egm_minmax egm_cond := [-0.1, 0.1];

    PROC main()
        EGMGetId egm_id;
        egm_state := EGMGetState(egm_id);
        IF egm_state <= EGM_STATE_CONNECTED THEN
            EGMSetupUC ROB_1, egm_id, "default", "{{device}}" \Joint \CommTimeout:={{timeout_s}};
        ENDIF
        EGMActJoint egm_id \J1:=egm_cond \J2:=egm_cond \J3:=egm_cond \J4:=egm_cond
            \J5:=egm_cond \J6:=egm_cond \SampleRate:={{sample_ms}} \MaxSpeedDeviation:={{max_speed_deg}};
        ! stream until the PC stops (CondTime: seconds the condition must hold before it ends)
        EGMRunJoint egm_id, EGM_STOP_HOLD \J1 \J2 \J3 \J4 \J5 \J6 \CondTime:={{cond_time}}
            \RampInTime:=0.05 \PosCorrGain:=1;
        EGMReset egm_id;
    ERROR
        IF ERRNO = ERR_UDPUC_COMM THEN
            TPWrite "plugcell EGM: no message from the PC within CommTimeout";
            EGMReset egm_id;
            RETURN;
        ENDIF
    ENDPROC
ENDMODULE
