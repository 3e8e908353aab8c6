"""Parallel platforms described by their legs (numpy only).

A leg joins a fixed base point to a platform point (given in the platform frame) through a
joint sequence. Supported sequences and the joint that may be actuated:

============  =========  =============================================  ==========
type          platform   joints (names)                                 actuated
============  =========  =============================================  ==========
``RPR``       planar     theta (base R), rho (P), psi (platform R)       rho
``RRR``       planar     theta1 (base R), theta2 (elbow), theta3         theta1
``UPS/SPS``   spatial    ua, ub (base U), rho (P), sa, sb, sc (S)        rho
``RUS/RSS``   spatial    theta (base R), ua, ub (elbow, forearm dir.)   theta
============  =========  =============================================  ==========

Each leg gives one closure equation between the platform pose and its actuated joint
(seed 003, "Inverse Kinematics": the inverse model is stated leg by leg); the passive joints
follow in closed form from the pose, and :func:`leg_inverse` lists every posture (branch)
of a leg.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import MechanismError
from .geometry import euler_xyz, rot2, rot_x, rot_y, rot_z, wrap_angle

__all__ = ["Leg", "LEG_TYPES", "PLATFORMS", "leg_inverse", "leg_forward", "leg_joints"]

#: type -> (dimension, joint names, actuated index, number of link lengths)
LEG_TYPES: dict[str, tuple[int, tuple[str, ...], int, int]] = {
    "RPR": (2, ("theta", "rho", "psi"), 1, 0),
    "RRR": (2, ("theta1", "theta2", "theta3"), 0, 2),
    "UPS": (3, ("ua", "ub", "rho", "sa", "sb", "sc"), 2, 0),
    "SPS": (3, ("ua", "ub", "rho", "sa", "sb", "sc"), 2, 0),
    "RUS": (3, ("theta", "ua", "ub"), 0, 2),
    "RSS": (3, ("theta", "ua", "ub"), 0, 2),
}

#: platform kind -> (space dimension, degrees of freedom, task coordinates)
PLATFORMS: dict[str, tuple[int, int, tuple[str, ...]]] = {
    "planar": (2, 3, ("x", "y", "phi")),
    "planar_point": (2, 2, ("x", "y")),
    "spatial": (3, 6, ("x", "y", "z", "roll", "pitch", "yaw")),
    "spatial_translational": (3, 3, ("x", "y", "z")),
}


def _vec(v: Any, n: int, where: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        raise MechanismError(f"{where}: expected {n} numbers, got {v!r}") from None
    if a.shape != (n,):
        got = a.size if a.ndim <= 1 else f"an array of shape {a.shape}"
        raise MechanismError(f"{where}: expected {n} numbers, got {got}")
    if not np.all(np.isfinite(a)):
        raise MechanismError(f"{where}: expected finite numbers, got {a.tolist()}")
    return a


@dataclass(frozen=True)
class Leg:
    """One leg of a parallel platform.

    Parameters
    ----------
    type : str
        One of :data:`LEG_TYPES`.
    base : array (2,) or (3,)
        The base joint centre in the base frame.
    platform : array (2,) or (3,)
        The platform joint centre in the platform frame.
    lengths : tuple
        Link lengths: ``(proximal, distal)`` for RRR and RUS/RSS, empty otherwise.
    axis, arm : array (3,), RUS/RSS only
        The base revolute axis and the arm direction at theta = 0 (orthogonal unit vectors);
        the arm turns towards ``axis x arm`` as theta grows.
    """

    type: str
    base: np.ndarray
    platform: np.ndarray
    lengths: tuple[float, ...] = ()
    axis: np.ndarray | None = None
    arm: np.ndarray | None = None
    actuated: int = field(default=-1)

    @property
    def dim(self) -> int:
        return LEG_TYPES[self.type][0]

    @property
    def joint_names(self) -> tuple[str, ...]:
        return LEG_TYPES[self.type][1]

    @property
    def actuated_index(self) -> int:
        return LEG_TYPES[self.type][2]

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "type": self.type,
            "base": np.asarray(self.base, dtype=float).tolist(),
            "platform": np.asarray(self.platform, dtype=float).tolist(),
        }
        if self.lengths:
            d["lengths"] = list(self.lengths)
        if self.axis is not None:
            d["axis"] = np.asarray(self.axis, dtype=float).tolist()
            d["arm"] = np.asarray(self.arm, dtype=float).tolist()
        return d

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any] | Leg, i: int) -> Leg:
        """Build and validate leg ``i`` (0-based) from a mapping."""
        if isinstance(spec, Leg):  # re-validated: a Leg built directly skipped the checks
            fields: dict[str, Any] = {"type": spec.type, "base": spec.base,
                                      "platform": spec.platform}
            if spec.lengths:
                fields["lengths"] = spec.lengths
            for key in ("axis", "arm"):
                if getattr(spec, key) is not None:
                    fields[key] = getattr(spec, key)
            if spec.actuated != -1:
                fields["actuated"] = spec.actuated
            spec = fields
        where = f"legs[{i}]"
        if not isinstance(spec, Mapping):
            raise MechanismError(f"{where}: expected a mapping with type, base, platform")
        allowed = {"type", "base", "platform", "lengths", "axis", "arm", "actuated"}
        unknown = sorted(set(spec) - allowed)
        if unknown:
            raise MechanismError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
        t = str(spec.get("type", "")).upper()
        if t not in LEG_TYPES:
            raise MechanismError(
                f"{where}.type: unknown leg type {spec.get('type')!r}; supported: "
                f"{sorted(LEG_TYPES)}"
            )
        dim, names, act, nlen = LEG_TYPES[t]
        for key in ("base", "platform"):
            if key not in spec:
                raise MechanismError(f"{where}.{key}: missing; give the joint centre ({dim} numbers)")
        base = _vec(spec["base"], dim, f"{where}.base")
        plat = _vec(spec["platform"], dim, f"{where}.platform")
        if "actuated" in spec and spec["actuated"] is not None:
            a = spec["actuated"]
            if isinstance(a, str):
                a = names.index(a) if a in names else -2
            if a != act:
                raise MechanismError(
                    f"{where}.actuated: {spec['actuated']!r} is not supported for {t} legs; "
                    f"the actuated joint is {names[act]!r} (index {act})"
                )
        lengths: tuple[float, ...] = ()
        if nlen:
            if "lengths" not in spec:
                raise MechanismError(f"{where}.lengths: {t} legs need {nlen} link lengths")
            L = _vec(spec["lengths"], nlen, f"{where}.lengths")
            if np.any(L <= 0):
                raise MechanismError(
                    f"{where}.lengths: link lengths must be positive, got {L.tolist()}"
                )
            lengths = tuple(float(v) for v in L)
        elif spec.get("lengths") not in (None, [], ()):
            raise MechanismError(f"{where}.lengths: {t} legs have no fixed link lengths")
        axis = arm = None
        if t in ("RUS", "RSS"):
            if "axis" not in spec or "arm" not in spec:
                raise MechanismError(
                    f"{where}: {t} legs need 'axis' (base revolute axis) and 'arm' (arm "
                    "direction at theta=0), two orthogonal unit vectors"
                )
            axis = _vec(spec["axis"], 3, f"{where}.axis")
            arm = _vec(spec["arm"], 3, f"{where}.arm")
            if abs(np.linalg.norm(axis) - 1) > 1e-9 or abs(np.linalg.norm(arm) - 1) > 1e-9:
                raise MechanismError(f"{where}: axis and arm must be unit vectors")
            if abs(axis @ arm) > 1e-9:
                raise MechanismError(f"{where}: axis and arm must be orthogonal")
        for key in ("axis", "arm"):
            if t not in ("RUS", "RSS") and key in spec:
                raise MechanismError(f"{where}.{key}: only RUS/RSS legs take {key!r}")
        for arr in (base, plat):
            arr.setflags(write=False)
        return cls(t, base, plat, lengths, axis, arm, act)


# --------------------------------------------------------------------------------------
# numpy leg kinematics (used for inverse, guesses, drawing, and as the reference in tests)


def _platform_point(leg: Leg, R: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p + R @ leg.platform


def leg_inverse(leg: Leg, R: np.ndarray, p: np.ndarray, tol: float = 1e-12) -> list[tuple[np.ndarray, int]]:
    """Every posture of ``leg`` for the platform pose (R, p).

    Returns a list of ``(joint values, branch)``; ``branch`` is +1/-1 for legs with two
    postures (the sign of the leg's diagonal entry of B, seed 004) and +1 otherwise.
    An empty list means the pose is out of the leg's reach.
    """
    P = _platform_point(leg, R, p)
    A = leg.base
    t = leg.type
    if t == "RPR":
        d = P - A
        rho = float(np.hypot(*d))
        th = float(np.arctan2(d[1], d[0]))
        phi = float(np.arctan2(R[1, 0], R[0, 0]))
        return [(np.array([th, rho, wrap_angle(phi - th)]), 1)]
    if t == "RRR":
        l1, l2 = leg.lengths
        phi = float(np.arctan2(R[1, 0], R[0, 0]))
        d = P - A
        L = float(np.hypot(*d))
        if L < tol:
            return []
        c = (L * L + l1 * l1 - l2 * l2) / (2 * L * l1)
        if abs(c) > 1 + 1e-12:
            return []
        beta = float(np.arccos(np.clip(c, -1, 1)))
        out = []
        for s in (1, -1):
            th1 = float(np.arctan2(d[1], d[0])) + s * beta
            C = A + l1 * np.array([np.cos(th1), np.sin(th1)])
            e = P - C
            th12 = float(np.arctan2(e[1], e[0]))
            q = np.array([wrap_angle(th1), wrap_angle(th12 - th1), wrap_angle(phi - th12)])
            # B_ii = d/dtheta1 (|P - C| - l2) = -(P - C) . l1 n(theta1) / l2
            n = np.array([-np.sin(th1), np.cos(th1)])
            b = -(e @ n) * l1 / l2
            out.append((q, 1 if b > 0 else -1))
        if beta < 1e-12:
            out = out[:1]
        return out
    if t in ("UPS", "SPS"):
        d = P - A
        rho = float(np.linalg.norm(d))
        if rho < tol:
            return []
        u = d / rho
        ub = float(np.arcsin(np.clip(u[0], -1, 1)))
        ua = float(np.arctan2(-u[1], u[2]))
        RS = (rot_x(ua) @ rot_y(ub)).T @ R
        sa, sb, sc = euler_xyz(RS)
        return [(np.array([ua, ub, rho, sa, sb, sc]), 1)]
    if t in ("RUS", "RSS"):
        la, lb = leg.lengths
        u0, ax = leg.arm, leg.axis
        w = np.cross(ax, u0)  # type: ignore[arg-type]
        d = P - A
        k = (d @ d + la * la - lb * lb) / (2 * la)
        a, b = float(d @ u0), float(d @ w)
        r = float(np.hypot(a, b))
        if r < tol or abs(k) > r * (1 + 1e-12):
            return []
        base_ang = float(np.arctan2(b, a))
        delta = float(np.arccos(np.clip(k / r, -1, 1)))
        out = []
        for s in (1, -1):
            th = base_ang + s * delta
            armv = np.cos(th) * u0 + np.sin(th) * w
            C = A + la * armv
            v = (P - C) / lb
            F = np.column_stack([armv, ax, np.cross(armv, ax)])
            vl = F.T @ v
            ub = float(np.arcsin(np.clip(vl[0], -1, 1)))
            ua = float(np.arctan2(-vl[1], vl[2]))
            darm = -np.sin(th) * u0 + np.cos(th) * w
            bii = -((P - C) @ darm) * la / lb
            out.append((np.array([wrap_angle(th), ua, ub]), 1 if bii > 0 else -1))
        if delta < 1e-12:
            out = out[:1]
        return out
    raise MechanismError(f"unknown leg type {t!r}")  # pragma: no cover


def leg_forward(leg: Leg, q: np.ndarray, planar_point: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The platform pose (R, p) reached by the serial chain of ``leg`` at joint values q."""
    t = leg.type
    if t == "RPR":
        th, rho, psi = q
        P = leg.base + rho * np.array([np.cos(th), np.sin(th)])
        phi = 0.0 if planar_point else th + psi
        R = rot2(phi)
        return R, P - R @ leg.platform
    if t == "RRR":
        l1, l2 = leg.lengths
        t1, t2, t3 = q
        C = leg.base + l1 * np.array([np.cos(t1), np.sin(t1)])
        P = C + l2 * np.array([np.cos(t1 + t2), np.sin(t1 + t2)])
        phi = 0.0 if planar_point else t1 + t2 + t3
        R = rot2(phi)
        return R, P - R @ leg.platform
    if t in ("UPS", "SPS"):
        ua, ub, rho, sa, sb, sc = q
        Rl = rot_x(ua) @ rot_y(ub)
        P = leg.base + rho * Rl[:, 2]
        R = Rl @ rot_x(sa) @ rot_y(sb) @ rot_z(sc)
        return R, P - R @ leg.platform
    if t in ("RUS", "RSS"):
        la, lb = leg.lengths
        th, ua, ub = q
        u0, ax = leg.arm, leg.axis
        w = np.cross(ax, u0)  # type: ignore[arg-type]
        armv = np.cos(th) * u0 + np.sin(th) * w
        C = leg.base + la * armv
        F = np.column_stack([armv, ax, np.cross(armv, ax)])
        v = F @ (rot_x(ua) @ rot_y(ub))[:, 2]
        P = C + lb * v
        return np.eye(3), P - leg.platform
    raise MechanismError(f"unknown leg type {t!r}")  # pragma: no cover


def validate_legs(legs: Sequence[Any], platform: str, redundant: bool = False) -> tuple[Leg, ...]:
    """Validate the legs of a platform: one actuated leg per degree of freedom, or (with
    ``redundant=True``) more actuated legs than degrees of freedom (redundant actuation)."""
    if platform not in PLATFORMS:
        raise MechanismError(
            f"platform: unknown platform kind {platform!r}; use one of {sorted(PLATFORMS)}"
        )
    if isinstance(legs, (str, bytes)) or not isinstance(legs, Sequence) or not legs:
        raise MechanismError("legs: expected a non-empty list of legs")
    dim, dof, _ = PLATFORMS[platform]
    out = tuple(Leg.from_spec(s, i) for i, s in enumerate(legs))
    for i, leg in enumerate(out):
        if leg.dim != dim:
            raise MechanismError(
                f"legs[{i}].type: a {leg.type} leg is {'planar' if leg.dim == 2 else 'spatial'} "
                f"but the platform is {platform!r}"
            )
    if redundant:
        if len(out) <= dof:
            raise MechanismError(
                f"legs: a redundantly actuated {platform!r} platform needs more than {dof} "
                f"actuated legs, got {len(out)}; drop redundant=True for {dof} legs"
            )
    elif len(out) != dof:
        hint = "; pass redundant=True for redundant actuation" if len(out) > dof else ""
        raise MechanismError(
            f"legs: a {platform!r} platform has {dof} degrees of freedom and needs {dof} "
            f"actuated legs, got {len(out)}{hint}"
        )
    return out


def leg_joints(leg: Leg, R: np.ndarray, p: np.ndarray, a: float) -> np.ndarray:
    """Joint values of ``leg`` at platform pose (R, p) with its actuated joint at ``a``."""
    P = _platform_point(leg, R, p)
    A = leg.base
    t = leg.type
    if t == "RPR":
        d = P - A
        th = float(np.arctan2(d[1], d[0]))
        phi = float(np.arctan2(R[1, 0], R[0, 0]))
        return np.array([th, a, wrap_angle(phi - th)])
    if t == "RRR":
        l1 = leg.lengths[0]
        phi = float(np.arctan2(R[1, 0], R[0, 0]))
        C = A + l1 * np.array([np.cos(a), np.sin(a)])
        e = P - C
        th12 = float(np.arctan2(e[1], e[0]))
        return np.array([a, wrap_angle(th12 - a), wrap_angle(phi - th12)])
    if t in ("UPS", "SPS"):
        d = P - A
        n = float(np.linalg.norm(d))
        u = d / n if n > 0 else np.array([0.0, 0.0, 1.0])
        ub = float(np.arcsin(np.clip(u[0], -1, 1)))
        ua = float(np.arctan2(-u[1], u[2]))
        RS = (rot_x(ua) @ rot_y(ub)).T @ R
        return np.concatenate([[ua, ub, a], euler_xyz(RS)])
    la = leg.lengths[0]
    u0, ax = leg.arm, leg.axis
    w = np.cross(ax, u0)  # type: ignore[arg-type]
    armv = np.cos(a) * u0 + np.sin(a) * w
    C = A + la * armv
    v = P - C
    n = float(np.linalg.norm(v))
    v = v / n if n > 0 else armv
    F = np.column_stack([armv, ax, np.cross(armv, ax)])
    vl = F.T @ v
    return np.array([a, float(np.arctan2(-vl[1], vl[2])), float(np.arcsin(np.clip(vl[0], -1, 1)))])
