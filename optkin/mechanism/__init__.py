"""Plain mechanism descriptions (numpy only): Khalil tables, legs, the Mechanism class."""

from .core import TASK_COMPONENTS, Mechanism
from .geometry import homogeneous, matrix_to_quat, matrix_to_rpy, quat_to_matrix, rpy_to_matrix
from .joints import JOINT_TYPES, JointType
from .khalil import COLUMNS, KhalilFrame, KhalilTable, khalil_inverse, khalil_transform
from .legs import LEG_TYPES, Leg, leg_type
from .platforms import PLATFORMS, Platform

__all__ = [
    "COLUMNS", "JOINT_TYPES", "JointType", "KhalilFrame", "KhalilTable", "LEG_TYPES", "Leg",
    "Mechanism", "PLATFORMS", "Platform", "TASK_COMPONENTS", "homogeneous", "khalil_inverse",
    "khalil_transform", "leg_type", "matrix_to_quat", "matrix_to_rpy", "quat_to_matrix",
    "rpy_to_matrix",
]
