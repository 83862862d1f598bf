"""plugcell.metrology — metrology geometry (pure math, SI units).

Best-fit line/plane/circle, frames from features, BASE/PROBE estimation by the
procedures of thesis Appendix D, rigid registration, accuracy statistics of
eqs. 8.1–8.2, straightness (8.3.1), ISO 9283 pose accuracy/repeatability, and the alignment
of sensor clocks (delay between two records of a motion, clock maps).

Inputs are numpy arrays in metres and radians; nothing here does I/O or imports
the framework. Degenerate input raises :class:`MetrologyError` (a ``ValueError``).
See ``docs/metrology.md``.
"""

from plugcell.lazy import exports

#: Module → the public names it defines (imported on first use: :mod:`plugcell.lazy`).
_NAMES = {
    "_validate": ("MetrologyError",),
    "accuracy": (
        "AccuracyStats", "ComponentStats", "ErrorStats", "Iso9283Result", "NormStats",
        "StraightnessResult", "accuracy_statistics", "iso9283_pose_accuracy", "pose_errors",
        "straightness", "wrap_angle",
    ),
    "fitting": ("CircleFit", "LineFit", "PlaneFit", "fit_circle", "fit_line", "fit_plane"),
    "frames": (
        "SMR_RADIUS_HALF_INCH", "BaseEstimate", "BaseParameters", "ProbeEstimate", "RigidFit",
        "base_from_features", "base_matrix_from_parameters", "base_parameters_from_matrix",
        "fit_rigid_transform", "frame_from_axes", "invert_transform", "probe_from_flange_features",
    ),
    "timing": ("ClockMap", "DelayEstimate", "estimate_delay", "fit_clock_map"),
}
__getattr__, __dir__, __all__ = exports(__name__, _NAMES)
