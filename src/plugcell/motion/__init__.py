"""plugcell.motion — time-parametrised robot trajectories, checked before motion.

Joint (PTP, synchronised axes), linear and circular Cartesian moves (LIN, CIRC) with
speed, acceleration and jerk limits (a double-S time law, :mod:`.profile`), blends
between consecutive moves (:mod:`.timing`), Cartesian moves mapped to joints by the
robot's inverse kinematics on one branch (:mod:`.tracking`), sampled at any time or
interpolation cycle (:class:`Trajectory`).  :func:`plan` checks joint limits, joint
speeds, singularities and reachability before motion and names the move that fails
(:mod:`.errors`).  Pure math: SI units, no I/O.  See docs/motion.md.
"""

from plugcell.motion.errors import (
    JointRangeError,
    JointSpeedError,
    MoveError,
    SingularityError,
    TrajectoryError,
    UnreachablePoseError,
)
from plugcell.motion.limits import CartesianLimits, JointLimits
from plugcell.motion.moves import CIRC, LIN, PTP, Move
from plugcell.motion.planner import plan
from plugcell.motion.profile import DoubleS, ProfileSample, double_s
from plugcell.motion.trajectory import JointSample, Trajectory

__all__ = [
    "CIRC",
    "LIN",
    "PTP",
    "CartesianLimits",
    "DoubleS",
    "JointLimits",
    "JointRangeError",
    "JointSample",
    "JointSpeedError",
    "Move",
    "MoveError",
    "ProfileSample",
    "SingularityError",
    "Trajectory",
    "TrajectoryError",
    "UnreachablePoseError",
    "double_s",
    "plan",
]
