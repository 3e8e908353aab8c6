"""Platform kinds: how a moving platform's pose is written, one class each.

A platform kind fixes the unknown coordinates x of the platform (the model's unknowns
besides the legs' passive joints), its task coordinates (what a user types as a pose), the
twist components it has, and which rows of a leg's closure constrain it:

=========================  =======================  ==========================  ========
kind                       x                        task coordinates            dof
=========================  =======================  ==========================  ========
``planar``                 x, y, phi                x, y, phi                   3
``planar_point``           x, y                     x, y                        2
``spatial``                x, y, z, qw, qx, qy, qz  x, y, z, roll, pitch, yaw   6
``spatial_translational``  x, y, z                  x, y, z                     3
=========================  =======================  ==========================  ========

Spatial rotations are unit quaternions (w, x, y, z) in x (one more closure row keeps their
norm at 1) and roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll) in task coordinates.
The platform frame as a CasADi function of x is the model's
(:func:`optkin.model.structure.platform_frame`); the numeric conversions between poses, x
and task coordinates are here.

Adding a platform kind: subclass :class:`Platform` and register it in :data:`PLATFORMS`.
"""

from __future__ import annotations

import math
from typing import ClassVar

import numpy as np

from .geometry import homogeneous, matrix_to_quat, matrix_to_rpy, rot2, rpy_to_matrix

__all__ = ["Platform", "Planar", "PlanarPoint", "Spatial", "SpatialTranslational",
           "PLATFORMS", "TWIST_NAMES", "WRENCH_NAMES"]

#: Components of a twist: linear velocity of the end-effector point, then angular velocity.
TWIST_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")
#: Components of a wrench: force, then moment about the end-effector point.
WRENCH_NAMES = ("fx", "fy", "fz", "mx", "my", "mz")


class Platform:
    """A kind of moving platform (class attributes, no instances).

    Attributes
    ----------
    name : str
        The kind's name (``Mechanism.from_legs(..., platform=name)``).
    space_dim : int
        2 (planar) or 3 (spatial).
    dof : int
        Degrees of freedom of the platform.
    coords : tuple of str
        Names of the platform coordinates x.
    angles : tuple of bool
        Which coordinates are angles (wrapped to (-pi, pi]).
    lengths : tuple of bool
        Which coordinates are lengths (scaled by the mechanism's size).
    task : tuple of str
        Names of the task coordinates.
    twist_rows : tuple of int
        Which of :data:`TWIST_NAMES` the platform's twist has.
    point_rows, frame_rows : tuple of int
        Which of (px, py, pz) a leg ending at a point, and which of (px, py, pz, rx, ry,
        rz) a leg ending at the platform frame constrain.
    rotates : bool
        Whether the platform turns (a leg that ends at the platform frame constrains its
        orientation).
    shared_point : bool
        The legs meet in one point (a point platform: no platform body, the legs' last
        joints form one multiple joint).
    """

    name: ClassVar[str] = ""
    space_dim: ClassVar[int] = 3
    dof: ClassVar[int] = 0
    coords: ClassVar[tuple[str, ...]] = ()
    angles: ClassVar[tuple[bool, ...]] = ()
    lengths: ClassVar[tuple[bool, ...]] = ()
    task: ClassVar[tuple[str, ...]] = ()
    twist_rows: ClassVar[tuple[int, ...]] = ()
    point_rows: ClassVar[tuple[int, ...]] = (0, 1, 2)
    frame_rows: ClassVar[tuple[int, ...]] = (0, 1, 2, 3, 4, 5)
    rotates: ClassVar[bool] = True
    shared_point: ClassVar[bool] = False
    norm_row: ClassVar[bool] = False

    @classmethod
    def nx(cls) -> int:
        return len(cls.coords)

    @classmethod
    def x_from_pose(cls, T: np.ndarray) -> np.ndarray:
        """The coordinates x of a 4x4 pose."""
        raise NotImplementedError

    @classmethod
    def task_to_pose(cls, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    @classmethod
    def pose_to_task(cls, T: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    @classmethod
    def canonical(cls, x: np.ndarray) -> np.ndarray:
        """x with angles wrapped to (-pi, pi] (and quaternions normalised, w >= 0)."""
        x = np.array(x, dtype=float)
        for i, a in enumerate(cls.angles):
            if a and math.isfinite(x[i]):
                v = math.remainder(x[i], 2 * math.pi)
                x[i] = math.pi if v <= -math.pi else v
        return x

    @classmethod
    def xdot_of_twist(cls, x: np.ndarray) -> np.ndarray:
        """E with x_dot = E t for the platform twist t (rows ``twist_rows``)."""
        return np.eye(cls.nx())


class Planar(Platform):
    name = "planar"
    space_dim = 2
    dof = 3
    coords = ("x", "y", "phi")
    angles = (False, False, True)
    lengths = (True, True, False)
    task = ("x", "y", "phi")
    twist_rows = (0, 1, 5)
    point_rows = (0, 1)
    frame_rows = (0, 1, 5)


    @classmethod
    def x_from_pose(cls, T):
        T = np.asarray(T, dtype=float)
        return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])

    @classmethod
    def task_to_pose(cls, t):
        return homogeneous(rot2(t[2]), t[:2])

    @classmethod
    def pose_to_task(cls, T):
        return cls.x_from_pose(T)


class _Translating(Platform):
    """A platform that only translates: its coordinates are its origin's."""

    @classmethod
    def x_from_pose(cls, T):
        return np.asarray(T, dtype=float)[:cls.space_dim, 3].copy()

    @classmethod
    def task_to_pose(cls, t):
        return homogeneous(np.eye(cls.space_dim), t[:cls.space_dim])

    @classmethod
    def pose_to_task(cls, T):
        return cls.x_from_pose(T)


class PlanarPoint(_Translating):
    name = "planar_point"
    space_dim = 2
    dof = 2
    coords = ("x", "y")
    angles = (False, False)
    lengths = (True, True)
    task = ("x", "y")
    twist_rows = (0, 1)
    point_rows = (0, 1)
    frame_rows = (0, 1, 5)  # a leg's last joint keeps a fictitious orientation 0
    rotates = False
    shared_point = True


class Spatial(Platform):
    name = "spatial"
    space_dim = 3
    dof = 6
    coords = ("x", "y", "z", "qw", "qx", "qy", "qz")
    angles = (False,) * 7
    lengths = (True, True, True, False, False, False, False)
    task = ("x", "y", "z", "roll", "pitch", "yaw")
    twist_rows = (0, 1, 2, 3, 4, 5)
    norm_row = True


    @classmethod
    def x_from_pose(cls, T):
        T = np.asarray(T, dtype=float)
        return np.concatenate([T[:3, 3], matrix_to_quat(T[:3, :3])])

    @classmethod
    def task_to_pose(cls, t):
        return homogeneous(rpy_to_matrix(t[3], t[4], t[5]), t[:3])

    @classmethod
    def pose_to_task(cls, T):
        T = np.asarray(T, dtype=float)
        return np.concatenate([T[:3, 3], matrix_to_rpy(T[:3, :3])])

    @classmethod
    def canonical(cls, x):
        x = np.array(x, dtype=float)
        n = math.sqrt(float(x[3:7] @ x[3:7]))
        if n > 0 and math.isfinite(n):
            qq = x[3:7] / n
            x[3:7] = qq if qq[0] >= 0 else -qq
        return x

    @classmethod
    def xdot_of_twist(cls, x):
        """Position rates are v; quaternion rates 0.5 G omega (omega in base coordinates)."""
        w, a, b, c = np.asarray(x, dtype=float)[3:7]
        G = np.array([[-a, -b, -c], [w, c, -b], [-c, w, a], [b, -a, w]])
        E = np.zeros((7, 6))
        E[:3, :3] = np.eye(3)
        E[3:, 3:] = 0.5 * G
        return E


class SpatialTranslational(_Translating):
    name = "spatial_translational"
    space_dim = 3
    dof = 3
    coords = ("x", "y", "z")
    angles = (False, False, False)
    lengths = (True, True, True)
    task = ("x", "y", "z")
    twist_rows = (0, 1, 2)
    rotates = False


#: Platform kind name -> class.
PLATFORMS: dict[str, type[Platform]] = {
    p.name: p for p in (Planar, PlanarPoint, Spatial, SpatialTranslational)}

