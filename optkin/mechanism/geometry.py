"""Rotations and poses: scipy.spatial.transform.Rotation behind optkin's conventions
(quaternions (w, x, y, z), roll-pitch-yaw as R = Rz(yaw) Ry(pitch) Rx(roll))."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

__all__ = [
    "rot_x", "rot_y", "rot_z", "rot2", "rpy_to_matrix", "matrix_to_rpy", "quat_to_matrix",
    "matrix_to_quat", "homogeneous", "euler_xyz", "wrap_angle",
]


def wrap_angle(a):
    """Wrap angles to (-pi, pi]."""
    a = np.asarray(a, dtype=float)
    w = np.mod(a + np.pi, 2 * np.pi) - np.pi
    w = np.where(w <= -np.pi, w + 2 * np.pi, w)
    return w if w.ndim else float(w)


def _Rotation() -> Any:
    """scipy's Rotation (imported on first use: ``import optkin`` stays lean)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def rot_x(a: float) -> np.ndarray:
    """The rotation by ``a`` about x."""
    return _Rotation().from_euler("x", float(a)).as_matrix()


def rot_y(a: float) -> np.ndarray:
    """The rotation by ``a`` about y."""
    return _Rotation().from_euler("y", float(a)).as_matrix()


def rot_z(a: float) -> np.ndarray:
    """The rotation by ``a`` about z."""
    return _Rotation().from_euler("z", float(a)).as_matrix()


def rot2(a: float) -> np.ndarray:
    """The planar rotation by ``a``."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): scipy's ``Rotation.from_euler("ZYX", [yaw, pitch,
    roll])`` (intrinsic z-y'-x'')."""
    return _Rotation().from_euler("ZYX", [float(yaw), float(pitch), float(roll)]).as_matrix()


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`: (roll, pitch, yaw), pitch in [-pi/2, pi/2] (at
    pitch = +-pi/2, where only yaw -+ roll is defined, roll = 0)."""
    with warnings.catch_warnings():  # the gimbal-lock note: roll = 0 there, as documented
        warnings.simplefilter("ignore", UserWarning)
        yaw, pitch, roll = _Rotation().from_matrix(np.asarray(R, dtype=float)).as_euler("ZYX")
    return np.array([roll, pitch, yaw])


def euler_xyz(R: np.ndarray) -> np.ndarray:
    """Angles (a, b, c) with R = Rx(a) Ry(b) Rz(c) (scipy's intrinsic "XYZ")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return _Rotation().from_matrix(np.asarray(R, dtype=float)).as_euler("XYZ")


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation of a quaternion (w, x, y, z); normalised first."""
    w, x, y, z = np.asarray(q, dtype=float)
    return _Rotation().from_quat([x, y, z, w]).as_matrix()


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) with w >= 0 of a rotation matrix."""
    x, y, z, w = _Rotation().from_matrix(np.asarray(R, dtype=float)).as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def homogeneous(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    R = np.asarray(R, dtype=float)
    p = np.asarray(p, dtype=float)
    if R.shape == (2, 2):
        T[:2, :2] = R
        T[:2, 3] = p[:2]
    else:
        T[:3, :3] = R
        T[:3, 3] = p
    return T
