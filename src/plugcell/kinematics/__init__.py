"""plugcell.kinematics — pure-numpy robot kinematics (SI units, vectorised).

Transforms and DH/Hayati links (:mod:`.transforms`), orientation conventions
(:mod:`.rotations`), the pose-error convention (:mod:`.pose_error`), immutable
robot descriptions (:mod:`.description`) and parameter sets (:mod:`.parameters`),
parallelogram loop closure (:mod:`.closure`), forward kinematics through loops
(:mod:`.forward`), the manipulator Jacobian (:mod:`.jacobian`) and nominal
inverse kinematics (:mod:`.inverse`); joint-origin chains (URDF style) converted
exactly to DH/Hayati rows (:mod:`.joint_chain`).  No I/O, no framework imports; files are
read by :mod:`plugcell.io.robots`.  See docs/kinematics.md.
"""

from plugcell.kinematics.closure import ClosureResult, fourbar_closure, nominal_closure
from plugcell.kinematics.description import (
    Box,
    CoupledLimit,
    FourBarLoop,
    JointCoupling,
    Link,
    PointMass,
    RobotDescription,
)
from plugcell.kinematics.errors import (
    DescriptionError,
    JointLimitError,
    KinematicsError,
    LoopClosureError,
    UnreachableError,
)
from plugcell.kinematics.forward import FKResult, branch_cut_transform, forward
from plugcell.kinematics.inverse import IKResult, inverse
from plugcell.kinematics.jacobian import (
    jacobian_from_fk,
    kinematic_jacobian_from_fk,
    manipulator_jacobian,
)
from plugcell.kinematics.joint_chain import ChainJoint, JointChain, description_from_chain
from plugcell.kinematics.parameters import FIELDS, GeometricParameters
from plugcell.kinematics.pose_error import pose_error, pose_error_exact, rotation_error
from plugcell.kinematics.rotations import (
    CONVENTIONS,
    angles_to_matrix,
    matrix_to_angles,
    matrix_to_pose,
    matrix_to_prj,
    matrix_to_rpy,
    matrix_to_xyz,
    matrix_to_zyz,
    pose_to_matrix,
    prj_to_matrix,
    rpy_to_matrix,
    xyz_to_matrix,
    zyz_to_matrix,
)
from plugcell.kinematics.transforms import (
    cross,
    dh_hayati,
    identity,
    invert,
    rot_x,
    rot_y,
    rot_z,
    skew,
    so3_exp,
    so3_log,
    translation,
    vee,
)

__all__ = [
    "CONVENTIONS",
    "FIELDS",
    "Box",
    "ChainJoint",
    "ClosureResult",
    "CoupledLimit",
    "DescriptionError",
    "FKResult",
    "FourBarLoop",
    "GeometricParameters",
    "IKResult",
    "JointChain",
    "JointCoupling",
    "JointLimitError",
    "KinematicsError",
    "Link",
    "LoopClosureError",
    "PointMass",
    "RobotDescription",
    "UnreachableError",
    "angles_to_matrix",
    "branch_cut_transform",
    "cross",
    "description_from_chain",
    "dh_hayati",
    "forward",
    "fourbar_closure",
    "identity",
    "inverse",
    "invert",
    "jacobian_from_fk",
    "kinematic_jacobian_from_fk",
    "manipulator_jacobian",
    "matrix_to_angles",
    "matrix_to_pose",
    "matrix_to_prj",
    "matrix_to_rpy",
    "matrix_to_xyz",
    "matrix_to_zyz",
    "nominal_closure",
    "pose_error",
    "pose_error_exact",
    "pose_to_matrix",
    "prj_to_matrix",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_error",
    "rpy_to_matrix",
    "skew",
    "so3_exp",
    "so3_log",
    "translation",
    "vee",
    "xyz_to_matrix",
    "zyz_to_matrix",
]
