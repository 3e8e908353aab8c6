"""Plain mechanism descriptions (numpy only): Khalil tables, legs, the Mechanism class."""

from .core import TASK_COMPONENTS, Mechanism
from .geometry import homogeneous, matrix_to_quat, matrix_to_rpy, quat_to_matrix, rpy_to_matrix
from .khalil import COLUMNS, KhalilFrame, KhalilTable, khalil_inverse, khalil_transform
from .legs import LEG_TYPES, PLATFORMS, Leg, leg_forward, leg_inverse

__all__ = [
    "COLUMNS", "KhalilFrame", "KhalilTable", "LEG_TYPES", "Leg", "Mechanism", "PLATFORMS",
    "TASK_COMPONENTS", "homogeneous", "khalil_inverse", "khalil_transform", "leg_forward",
    "leg_inverse", "matrix_to_quat", "matrix_to_rpy", "quat_to_matrix", "rpy_to_matrix",
]
