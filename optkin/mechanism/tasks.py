"""Task coordinates (the pose vector a user types) and 4x4 poses."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import MAX_ABS, as_matrix, as_vector, show
from ..errors import MechanismError
from .geometry import homogeneous, matrix_to_rpy, rot2, rot_x, rot_y, rot_z, rpy_to_matrix

__all__ = ["task_to_pose", "pose_to_task", "as_pose", "task_space", "task_values"]


def task_to_pose(mech: Any, t: Any) -> np.ndarray:
    """The 4x4 pose of task coordinates ``t`` (see ``mech.task``).

    planar: (x, y, phi); planar_point: (x, y); spatial: (x, y, z, roll, pitch, yaw) with
    R = Rz(yaw) Ry(pitch) Rx(roll); spatial_translational: (x, y, z). Khalil mechanisms:
    the components named in ``mech.task`` (positions; rotation angles about base axes).
    """
    try:
        flat = np.asarray(t, dtype=float).ravel()
    except (TypeError, ValueError, OverflowError, RecursionError):
        flat = t  # not numbers: as_vector says so
    try:
        t = as_vector(flat, "pose", len(mech.task), path=("pose",))
    except MechanismError:
        raise MechanismError(
            f"pose: expected a 4x4 matrix or {len(mech.task)} finite task coordinates "
            f"{list(mech.task)} of magnitude at most {MAX_ABS:g}, got {show(t)}", path=("pose",)
        ) from None
    if mech.kind == "legs":
        plat = mech.platform
        if plat == "planar":
            return homogeneous(rot2(t[2]), t[:2])
        if plat == "planar_point":
            return homogeneous(np.eye(2), t[:2])
        if plat == "spatial":
            return homogeneous(rpy_to_matrix(t[3], t[4], t[5]), t[:3])
        return homogeneous(np.eye(3), t[:3])
    vals = dict(zip(mech.task, t))
    p = np.array([vals.get("x", 0.0), vals.get("y", 0.0), vals.get("z", 0.0)])
    R = rot_z(vals.get("rz", 0.0)) @ rot_y(vals.get("ry", 0.0)) @ rot_x(vals.get("rx", 0.0))
    return homogeneous(R, p)


def pose_to_task(mech: Any, T: np.ndarray) -> np.ndarray:
    """Task coordinates of a 4x4 pose (inverse of :func:`task_to_pose`)."""
    return task_values(task_space(mech), tuple(mech.task), T)


def task_space(mech: Any) -> str:
    """The kind of task coordinates of ``mech``: its platform's ("planar",
    "planar_point", "spatial", "spatial_translational") or "khalil"."""
    return str(mech.platform) if mech.kind == "legs" else "khalil"


def task_values(space: str, names: tuple[str, ...], T: np.ndarray) -> np.ndarray:
    """The task coordinates ``names`` of a 4x4 pose in a task space of kind ``space``
    (:func:`task_space`)."""
    T = np.asarray(T, dtype=float)
    if space == "planar":
        return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])
    if space == "planar_point":
        return T[:2, 3].copy()
    if space == "spatial":
        return np.concatenate([T[:3, 3], matrix_to_rpy(T[:3, :3])])
    if space != "khalil":
        return T[:3, 3].copy()
    rpy = matrix_to_rpy(T[:3, :3])
    comp = {"x": T[0, 3], "y": T[1, 3], "z": T[2, 3], "rx": rpy[0], "ry": rpy[1], "rz": rpy[2]}
    return np.array([comp[c] for c in names])


def as_pose(mech: Any, pose: Any) -> np.ndarray:
    """A 4x4 pose from either a 4x4 matrix or task coordinates."""
    try:
        shape = np.shape(pose)
    except (TypeError, ValueError, RecursionError):
        shape = None
    if shape == (4, 4):
        try:
            a = as_matrix(pose, "pose", (4, 4), path=("pose",))
        except MechanismError:
            raise MechanismError(f"pose: the 4x4 matrix has non-finite entries or entries "
                                 f"beyond {MAX_ABS:g}", path=("pose",)) from None
        R = a[:3, :3]
        with np.errstate(over="ignore", invalid="ignore"):
            orth = np.abs(R.T @ R - np.eye(3)).max()
        if not orth <= 1e-6 or abs(float(np.linalg.det(R)) - 1) > 1e-6:
            raise MechanismError("pose: the rotation block of the 4x4 matrix is not a rotation",
                                 path=("pose",))
        if np.abs(a[3] - [0, 0, 0, 1]).max() > 1e-9:
            raise MechanismError("pose: the last row of the 4x4 matrix must be (0, 0, 0, 1)",
                                 path=("pose",))
        return a
    return task_to_pose(mech, pose)
