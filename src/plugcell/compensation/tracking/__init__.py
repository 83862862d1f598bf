"""Dynamic path correction: a laser tracker in the loop while the robot moves (issue 38).

API (stable; the correction source and ``plugcell path run`` build on it)::

    from plugcell.compensation.tracking import (TrackingLoop, TrackingSettings,
                                                 TrackerMeasurement)
    loop = TrackingLoop(IdentifiedModel(result.model), TrackingSettings(lead_s=0.012),
                        payload_kg=36.0, tracking=True)
    loop.add([TrackerMeasurement(t_s, T_tool_F0, six_dof=True, status="ok"), ...])  # any thread
    out = loop.cycle(t, q_feedback, T_path)   # once per robot cycle
    out.offset          # (6,) [Δp (m); φ (rad)] in F0: aim at (p_p + Δp, exp(φ)·R_p)
    loop.windows        # [HoldWindow(start_s, end_s, reason)]: stretches on the model alone
    loop.stats          # TrackingStats: fresh cycles, samples used/bad/stale, ages

* :mod:`.estimator` — :class:`TrackerMeasurement`, :class:`JointHistory` (``q(t)``
  between cycles), :class:`ResidualFilter` (Kalman filter on the residual of the
  calibrated model at the sample's joints: the age compensation).
* :mod:`.limiter` — :class:`RateLimiter` (speed, acceleration, total; no overshoot).
* :mod:`.learning` — :class:`IterativeLearning`: learning a repeated path's offset, the
  P-type law below the modes, the model-inverting law above them; :mod:`.plant` — the
  plant it inverts, identified from the runs (:func:`identify_plant`, :class:`ModalPlant`).
* :mod:`.loop` — :class:`TrackingLoop`, :class:`TrackingSettings`: the law (lead +
  model-based feed-forward + tracker term), beam breaks, hold windows.

Pure math (numpy, SI units, no I/O).  The RSI correction source is
:mod:`plugcell.devices.robot.rsi.tracking`; the closed loop on the twin
:mod:`plugcell.sim.tracked_path`; results in docs/dynamic-correction.md.
"""

from plugcell.lazy import exports

#: Module → the public names it defines (imported on first use: :mod:`plugcell.lazy`).
_NAMES = {
    "estimator": ("JointHistory", "ResidualFilter", "TrackerMeasurement", "steady_state_gain"),
    "learning": (
        "DEFAULT_WEIGHTING", "InverseSettings", "InverseState", "IterativeLearning",
        "LearnedOffset", "LearningSettings", "contraction", "contraction_inverse", "inverse_gain",
        "path_error", "weighting_for",
    ),
    "limiter": ("RateLimiter",),
    "loop": ("CycleOutput", "HoldWindow", "TrackingLoop", "TrackingSettings", "TrackingStats"),
    "plant": ("ModalPlant", "excitation", "identify_plant"),
    "smoothing": ("SpectralGain", "TileGain", "WeightingSettings"),
}
__getattr__, __dir__, __all__ = exports(__name__, _NAMES)
