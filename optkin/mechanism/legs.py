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

from .._checks import as_vector
from .._checks import show as _show
from ..errors import MechanismError
from ..numeric import singular_values
from .geometry import euler_xyz, rot2, rot_x, rot_y, rot_z, wrap_angle

__all__ = ["Leg", "LEG_TYPES", "PLATFORMS", "MAX_LEGS", "degenerate_points", "leg_inverse",
           "leg_forward", "leg_joints"]

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


def _vec(v: Any, n: int, where: str, path: tuple = ()) -> np.ndarray:
    """``v`` as ``n`` finite numbers, else a MechanismError naming ``where`` (and ``path``)."""
    try:
        shape = np.shape(v)
    except (ValueError, TypeError, OverflowError, RecursionError):  # ragged nested lists
        shape = ()
    a = as_vector(v, where, path=path) if len(shape) <= 1 else None  # strings, huge, NaN
    if a is None or a.shape != (n,):
        got = a.size if a is not None else f"an array of shape {shape}"
        raise MechanismError(f"{where}: expected {n} numbers, got {got}", path=path)
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
            raise MechanismError(f"{where}: expected a mapping with type, base, platform",
                                 path=("legs", i))
        allowed = {"type", "base", "platform", "lengths", "axis", "arm", "actuated"}
        unknown = sorted(set(spec) - allowed, key=str)
        if unknown:
            raise MechanismError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}",
                                 path=("legs", i, str(unknown[0])))
        t = spec.get("type", "")
        t = t.upper() if isinstance(t, str) else ""
        if t not in LEG_TYPES:
            raise MechanismError(
                f"{where}.type: unknown leg type {_show(spec.get('type'))}; supported: "
                f"{sorted(LEG_TYPES)}", path=("legs", i, "type")
            )
        dim, names, act, nlen = LEG_TYPES[t]
        for key in ("base", "platform"):
            if key not in spec:
                raise MechanismError(f"{where}.{key}: missing; give the joint centre ({dim} numbers)",
                                     path=("legs", i, key))
        base = _vec(spec["base"], dim, f"{where}.base", ("legs", i, "base"))
        plat = _vec(spec["platform"], dim, f"{where}.platform", ("legs", i, "platform"))
        if "actuated" in spec and spec["actuated"] is not None:
            a = spec["actuated"]
            if isinstance(a, str):
                a = names.index(a) if a in names else -2
            if isinstance(a, bool) or not isinstance(a, (int, np.integer)) or a != act:
                raise MechanismError(
                    f"{where}.actuated: {_show(spec['actuated'])} is not supported for {t} legs; "
                    f"the actuated joint is {names[act]!r} (index {act})",
                    path=("legs", i, "actuated")
                )
        lengths: tuple[float, ...] = ()
        if nlen:
            if "lengths" not in spec:
                raise MechanismError(f"{where}.lengths: {t} legs need {nlen} link lengths",
                                     path=("legs", i, "lengths"))
            L = _vec(spec["lengths"], nlen, f"{where}.lengths", ("legs", i, "lengths"))
            if np.any(L <= 0):
                raise MechanismError(
                    f"{where}.lengths: link lengths must be positive, got {L.tolist()}",
                    path=("legs", i, "lengths", int(np.flatnonzero(L <= 0)[0]))
                )
            lengths = tuple(float(v) for v in L)
        elif not _empty(spec.get("lengths")):
            raise MechanismError(f"{where}.lengths: {t} legs have no fixed link lengths",
                                 path=("legs", i, "lengths"))
        axis = arm = None
        if t in ("RUS", "RSS"):
            if "axis" not in spec or "arm" not in spec:
                raise MechanismError(
                    f"{where}: {t} legs need 'axis' (base revolute axis) and 'arm' (arm "
                    "direction at theta=0), two orthogonal unit vectors",
                    path=("legs", i, "axis" if "axis" not in spec else "arm")
                )
            axis = _vec(spec["axis"], 3, f"{where}.axis", ("legs", i, "axis"))
            arm = _vec(spec["arm"], 3, f"{where}.arm", ("legs", i, "arm"))
            for key, vec in (("axis", axis), ("arm", arm)):
                if abs(np.linalg.norm(vec) - 1) > 1e-9:
                    raise MechanismError(f"{where}: axis and arm must be unit vectors",
                                         path=("legs", i, key))
            if abs(axis @ arm) > 1e-9:
                raise MechanismError(f"{where}: axis and arm must be orthogonal",
                                     path=("legs", i, "arm"))
        for key in ("axis", "arm"):
            if t not in ("RUS", "RSS") and key in spec:
                raise MechanismError(f"{where}.{key}: only RUS/RSS legs take {key!r}",
                                     path=("legs", i, key))
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


#: Most legs a platform may have (redundant actuation included).
MAX_LEGS = 64


def validate_legs(legs: Sequence[Any], platform: str, redundant: bool = False) -> tuple[Leg, ...]:
    """Validate the legs of a platform: one actuated leg per degree of freedom, or (with
    ``redundant=True``) more actuated legs than degrees of freedom (redundant actuation).

    Platforms whose attachment points leave no regular configuration at all (see
    :func:`degenerate_points`) are rejected here, before any solver sees them.
    """
    if not isinstance(platform, str) or platform not in PLATFORMS:
        raise MechanismError(
            f"platform: unknown platform kind {_show(platform)}; use one of {sorted(PLATFORMS)}",
            path=("platform",)
        )
    if isinstance(legs, (str, bytes)) or not isinstance(legs, Sequence) or not legs:
        raise MechanismError("legs: expected a non-empty list of legs", path=("legs",))
    if len(legs) > MAX_LEGS:
        raise MechanismError(f"legs: {len(legs)} legs; at most {MAX_LEGS} are supported",
                             path=("legs",))
    dim, dof, _ = PLATFORMS[platform]
    out = tuple(Leg.from_spec(s, i) for i, s in enumerate(legs))
    for i, leg in enumerate(out):
        if leg.dim != dim:
            raise MechanismError(
                f"legs[{i}].type: a {leg.type} leg is {'planar' if leg.dim == 2 else 'spatial'} "
                f"but the platform is {platform!r}", path=("legs", i, "type")
            )
    if redundant:
        if len(out) <= dof:
            raise MechanismError(
                f"legs: a redundantly actuated {platform!r} platform needs more than {dof} "
                f"actuated legs, got {len(out)}; drop redundant=True for {dof} legs",
                path=("legs",)
            )
    elif len(out) != dof:
        hint = "; pass redundant=True for redundant actuation" if len(out) > dof else ""
        raise MechanismError(
            f"legs: a {platform!r} platform has {dof} degrees of freedom and needs {dof} "
            f"actuated legs, got {len(out)}{hint}", path=("legs",)
        )
    bad = degenerate_points(out, platform)
    if bad is not None:
        key, idx, text = bad
        legs_txt = ", ".join(f"legs[{i}]" + (f".{key}" if key else "") for i in idx)
        raise MechanismError(f"legs: {legs_txt}: {text}",
                             path=("legs", idx[-1]) if not key else ("legs",))
    return out


def _pts(v: np.ndarray) -> str:
    return "(" + ", ".join(f"{x:.6g}" for x in v) + ")"


def degenerate_points(legs: Sequence[Leg], platform: str
                      ) -> tuple[str, tuple[int, ...], str] | None:
    """Attachment points that make every configuration of the platform singular.

    The closure row of a leg is a line (a pure force) through its platform point, and for
    RPR/UPS/SPS legs through its base point too. When the points are placed so that these
    lines are dependent at every pose, no closed configuration has a regular W_p: the
    platform moves with the actuators locked everywhere (a permanent parallel singularity)
    and the solvers have nothing to converge to. Detected:

    * two RPR/UPS/SPS legs with the same base and the same platform point (one line twice);
    * planar platforms: all platform points coincide, or all base points of RPR legs do
      (the lines all pass through one point, about which the platform turns);
    * spatial platforms: all platform points on one line, or all base points of UPS/SPS
      legs on one line (every leg line meets it: the platform turns about it);
    * translational and point platforms with RPR/UPS/SPS legs: the points base - platform
      coincide (point platforms) or lie on one line (translational): the leg directions
      stay in one plane.

    Returns None, or ``(key, leg indices, explanation)`` with ``key`` "base" or "platform"
    (the points at fault), or "" for two legs that are the same.
    """
    n = len(legs)
    prism = [leg.type in ("RPR", "UPS", "SPS") for leg in legs]
    B = np.array([leg.base for leg in legs], dtype=float)
    P = np.array([leg.platform for leg in legs], dtype=float)
    # "coincide" relative to the size of the points compared (base and platform points may
    # differ in size by many orders of magnitude)
    def tol(*pts: np.ndarray) -> float:
        return 1e-12 * max(max(float(np.abs(p).max()) for p in pts), 1e-300)

    fix = "move them apart so that the legs' lines are independent"
    def flat(pts: np.ndarray, k: int) -> bool:  # the points span at most k dimensions
        c = pts - pts.mean(axis=0)
        s = singular_values(c, "attachment points")
        return bool(s.size <= k or s[k] <= tol(pts))

    every = tuple(range(n))
    if platform == "planar":
        if flat(P, 0):
            return ("platform", every, f"all platform points coincide at {_pts(P[0])}: the "
                    "platform turns about that point with the actuators locked, at every pose "
                    f"(no configuration is regular); {fix}")
        if all(prism) and flat(B, 0):
            return ("base", every, f"all base points coincide at {_pts(B[0])}: every leg line "
                    "passes through it, so the platform turns about it with the actuators "
                    f"locked, at every pose (no configuration is regular); {fix}")
    elif platform == "spatial":
        if flat(P, 1):
            return ("platform", every, "all platform points lie on one line: the platform "
                    "turns about that line with the actuators locked, at every pose (no "
                    f"configuration is regular); {fix}")
        if all(prism) and flat(B, 1):
            return ("base", every, "all base points lie on one line: every leg line meets it, "
                    "so the platform can turn with the actuators locked at every pose (no "
                    f"configuration is regular); {fix}")
    elif all(prism):  # translational and point platforms: directions from p to B - P
        k = 0 if platform == "planar_point" else 1
        if flat(B - P, k):
            return ("base", every, "the points base - platform of the legs "
                    + ("coincide" if k == 0 else "lie on one line")
                    + (": the legs stay parallel" if k == 0 else
                       ": the leg directions stay in one plane")
                    + " and the platform moves with the actuators locked at every pose (no "
                    f"configuration is regular); {fix}")
    for i in range(n):
        for j in range(i + 1, n):
            if prism[i] and prism[j] and np.abs(B[i] - B[j]).max() <= tol(B) and np.abs(
                    P[i] - P[j]).max() <= tol(P):
                return ("", (i, j), f"legs {i + 1} and {j + 1} have the same base point "
                        f"{_pts(B[i])} and the same platform point {_pts(P[i])}: one line of "
                        "force twice, so the platform moves with the actuators locked at every "
                        f"pose; {fix}")
    return None



def _empty(v: Any) -> bool:
    """None or an empty list / tuple / array (a leg type without fixed lengths)."""
    if v is None:
        return True
    try:
        return len(v) == 0
    except TypeError:
        return False


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
