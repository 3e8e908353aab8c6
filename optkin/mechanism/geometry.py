"""Rotations and poses in optkin's conventions: quaternions (w, x, y, z), roll-pitch-yaw as
R = Rz(yaw) Ry(pitch) Rx(roll), the conventions of scipy's ``Rotation`` (its
``from_euler("ZYX", [yaw, pitch, roll])`` and scalar-last quaternions reordered).

The conversions that every spatial problem meets (its guess and its poses are in
roll-pitch-yaw angles, its unknowns hold a quaternion) are written here in closed form and
checked against ``Rotation`` in the tests (``tests/test_lean_worker.py``): ``import
scipy.spatial`` loads its kd-trees, Qhull and scipy.sparse, about 0.3 s in every worker
process of a batch run. The others call ``Rotation``, imported on first use.
"""

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


#: |cos pitch| below which :func:`matrix_to_rpy` treats the pitch as +-pi/2 (gimbal lock):
#: scipy's test, a pitch within 1e-7 of +-pi/2
_LOCK = float(np.sin(1e-7))


def _Rotation() -> Any:
    """scipy's Rotation (imported on first use: ``import optkin`` stays lean)."""
    from scipy.spatial.transform import Rotation

    return Rotation


def rot_x(a: float) -> np.ndarray:
    """The rotation by ``a`` about x."""
    c, s = np.cos(float(a)), np.sin(float(a))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    """The rotation by ``a`` about y."""
    c, s = np.cos(float(a)), np.sin(float(a))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    """The rotation by ``a`` about z."""
    c, s = np.cos(float(a)), np.sin(float(a))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot2(a: float) -> np.ndarray:
    """The planar rotation by ``a``."""
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def rpy_to_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): scipy's ``Rotation.from_euler("ZYX", [yaw, pitch,
    roll])`` (intrinsic z-y'-x'')."""
    return rot_z(yaw) @ rot_y(pitch) @ rot_x(roll)


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix`: (roll, pitch, yaw), pitch in [-pi/2, pi/2] (at
    pitch = +-pi/2, where only yaw -+ roll is defined, roll = 0).

    The angles of scipy's ``Rotation.from_matrix(R).as_euler("ZYX")`` (reversed), gimbal
    lock included, in closed form (checked against it in the tests): every spatial result
    is reported in these angles, and ``import scipy.spatial`` (its kd-trees, Qhull and
    scipy.sparse) costs each worker process of a batch run about 0.3 s.
    """
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"matrix_to_rpy: a 3x3 rotation matrix expected, got shape {R.shape}")
    # R = Rz(yaw) Ry(pitch) Rx(roll): first column (cy cp, sy cp, -sp), last row
    # (-sp, cp sr, cp cr)
    cp = float(np.hypot(R[0, 0], R[1, 0]))
    pitch = float(np.arctan2(-R[2, 0], cp))
    if cp > _LOCK:
        roll = float(np.arctan2(R[2, 1], R[2, 2]))
        yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    else:  # pitch = +-pi/2: R = Rz(yaw) Ry(pitch) with roll = 0, whose middle column is
        # (-sin yaw, cos yaw, 0)
        roll = 0.0
        yaw = float(np.arctan2(-R[0, 1], R[1, 1]))
    return np.array([roll, pitch, yaw])


def euler_xyz(R: np.ndarray) -> np.ndarray:
    """Angles (a, b, c) with R = Rx(a) Ry(b) Rz(c) (scipy's intrinsic "XYZ")."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return _Rotation().from_matrix(np.asarray(R, dtype=float)).as_euler("XYZ")


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation of a quaternion (w, x, y, z); normalised first."""
    q = np.asarray(q, dtype=float)
    n = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
    if not n > 0 or not np.isfinite(n):
        raise ValueError(f"quat_to_matrix: a non-zero finite quaternion (w, x, y, z) "
                         f"expected, got {q!r}")
    w, x, y, z = q / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) with w >= 0 of a rotation matrix.

    Shepperd's method (the largest of |w|, |x|, |y|, |z| found from the diagonal first,
    the others from the off-diagonal sums and differences), as scipy's ``from_matrix``;
    scipy first projects a matrix that is not quite orthogonal onto the rotations, this
    reads the rotation's own entries (the two agree to the matrix's error)."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ValueError(f"matrix_to_quat: a 3x3 rotation matrix expected, got shape {R.shape}")
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    k = int(np.argmax([R[0, 0], R[1, 1], R[2, 2], tr]))
    if k == 3:
        q = np.array([1 + tr, R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    else:
        i, j, m = k, (k + 1) % 3, (k + 2) % 3
        q = np.empty(4)
        q[1 + i] = 1 + 2 * R[i, i] - tr
        q[1 + j] = R[j, i] + R[i, j]
        q[1 + m] = R[m, i] + R[i, m]
        q[0] = R[m, j] - R[j, m]
    q /= np.linalg.norm(q)
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
