"""How each joint type moves: one class per entry of
:data:`optkin.mechanism.joints.JOINT_TYPES`, its motion written once.

A joint's motion is the product of the exponentials of its elementary screws (Lynch &
Park, *Modern Robotics* (4.14)): :func:`screw_exp` is the one formula of a rotation
(Rodrigues) and of a translation, written with CasADi operations, which work alike on
symbols (SX, MX) and numbers (DM): numbers come from evaluating the same expression,
never from a numpy twin.

Besides its motion, a joint class gives the closed forms of the reduced leg models
(Paden-Kahan subproblems, written once here): :meth:`Joint.solve_distance` (values that
place a point at a distance: the actuated joint of a distance leg), :meth:`Joint.align`
(the variables that turn a direction into another: a leg's pivot) and
:meth:`Joint.orient` (the variables of a relative rotation: a leg's end joint), for joints
whose axes are orthonormal at home.

Adding a joint type: one line in :data:`optkin.mechanism.joints.JOINT_TYPES` (what it is)
and one class here (how it moves), registered in :data:`JOINTS`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, ClassVar

import casadi as ca

from ..mechanism.joints import JOINT_TYPES

__all__ = ["Joint", "Revolute", "Prismatic", "Cylindrical", "Universal", "Spherical",
           "JOINTS", "screw_exp", "chain_transform"]


def _ca():
    return ca


def _skew(w):
    ca = _ca()
    return ca.vertcat(ca.horzcat(0, -w[2], w[1]), ca.horzcat(w[2], 0, -w[0]),
                      ca.horzcat(-w[1], w[0], 0))


#: One SX Function per screw kind, ``exp([S] theta)`` of symbols: a call with SX (or DM)
#: arguments expands it in CasADi's C++ (one Python call where the formula below is some
#: eighty: a 6-6 platform's legs took 40 ms of SX operations in Python, 54 screws)
_EXP: dict[str, Any] = {}


def _exp_function(kind: str):
    f = _EXP.get(kind)
    if f is None:
        S, theta = ca.SX.sym("S", 6), ca.SX.sym("theta")
        f = _EXP[kind] = ca.Function(f"screw_exp_{kind}", [S, theta],
                                     [_screw_exp(S, theta, kind)])
    return f


def screw_exp(S, theta, kind: str):
    """``exp([S] theta)`` as a 4x4 CasADi expression (a number for DM inputs).

    ``kind`` is ``"R"`` (revolute: ``S[:3]`` a unit axis, Rodrigues' formula) or ``"P"``
    (prismatic: ``S[3:]`` a unit direction). Modern Robotics Prop. 3.25.

    >>> import casadi as ca, numpy as np
    >>> T = np.array(screw_exp(ca.DM([0, 0, 1, 0, -1, 0]), np.pi / 2, "R"))  # axis z at (1, 0)
    >>> np.round(T @ [1, 1, 0, 1], 12).tolist()   # (1, 1) turns a quarter about (1, 0)
    [0.0, 0.0, 0.0, 1.0]
    """
    if isinstance(S, ca.MX) or isinstance(theta, ca.MX):
        return _screw_exp(S, theta, kind)
    return _exp_function(kind)(S, theta)


def _screw_exp(S, theta, kind: str):
    """The formula of :func:`screw_exp`."""
    ca = _ca()
    w, v = S[0:3], S[3:6]
    eye = ca.DM.eye(3)  # DM + SX is SX, DM + MX is MX, DM + DM is DM
    if kind == "P":
        R = eye
        p = v * theta
    elif kind == "R":
        W = _skew(w)
        W2 = ca.mtimes(W, W)
        c, s = ca.cos(theta), ca.sin(theta)
        R = eye + s * W + (1 - c) * W2
        p = ca.mtimes(theta * eye + (1 - c) * W + (theta - s) * W2, v)
    else:
        raise ValueError(f"screw kind {kind!r}: expected 'R' or 'P'")
    return ca.vertcat(ca.horzcat(R, p), ca.horzcat(ca.DM([[0, 0, 0, 1]])))


def chain_transform(screws: Sequence[Any], kinds: str, q: Sequence[Any], home: Any = None):
    """``exp([S_1] q_1) ... exp([S_n] q_n) home``: the product of exponentials (MR (4.14)).

    ``screws`` are the 6-vectors in the fixed frame at home, ``kinds`` one letter per screw
    (``"R"``/``"P"``), ``home`` the 4x4 pose reached at q = 0 (identity when None).
    """
    ca = _ca()
    T = None
    for S, k, qi in zip(screws, kinds, q):
        E = screw_exp(S, qi, k)
        T = E if T is None else ca.mtimes(T, E)
    if home is not None:
        T = home if T is None else ca.mtimes(T, home)
    if T is None:
        T = ca.DM.eye(4)
    return T


def _pk1(w, u, v):
    """Paden-Kahan subproblem 1: the angle of the rotation about unit axis ``w`` that turns
    the direction ``u`` towards ``v`` (their components normal to ``w``)."""
    ca = _ca()
    up = u - w * ca.dot(w, u)
    vp = v - w * ca.dot(w, v)
    return ca.atan2(ca.dot(w, ca.cross(up, vp)), ca.dot(up, vp))


def _clip1(v):
    ca = _ca()
    return ca.fmin(ca.fmax(v, -1.0), 1.0)


class Joint:
    """A joint type: its elementary screws and its variables.

    Class attributes
    ----------------
    letter : str
        The letter used in leg strings such as ``"UPS"``.
    kinds : str
        One letter per elementary screw, ``"R"`` (rotation) or ``"P"`` (translation).
    suffixes : tuple of str
        Names of the joint's variables (appended to the joint's name; ``("",)`` for a
        one-variable joint).
    """

    letter: ClassVar[str] = ""
    kinds: ClassVar[str] = ""
    suffixes: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls, **kw: Any) -> None:
        super().__init_subclass__(**kw)
        t = JOINT_TYPES[cls.letter]  # the data entry this class moves
        cls.kinds, cls.suffixes = t.kinds, t.suffixes

    @classmethod
    def n(cls) -> int:
        """Number of variables (= elementary screws)."""
        return len(cls.kinds)

    @classmethod
    def angles(cls) -> tuple[bool, ...]:
        """Which variables are angles."""
        return tuple(k == "R" for k in cls.kinds)

    @classmethod
    def motion(cls, screws: Sequence[Any], q: Sequence[Any]):
        """The joint's 4x4 motion ``prod exp([S_i] q_i)`` (screws in the fixed frame)."""
        return chain_transform(screws, cls.kinds, q)

    @classmethod
    def solve_distance(cls, S: Any, c0: Any, P: Any, L: Any) -> list[tuple[Any, Any]]:
        """Values of this one-variable joint (screw ``S``) that move the point ``c0`` to
        distance ``L`` from ``P``: a list of (value, valid) (CasADi expressions), the
        branches in a fixed order; ``valid`` is 1 where the branch exists."""
        raise NotImplementedError(f"a {cls.__name__} joint cannot place a point at a distance")

    @classmethod
    def align(cls, axes: Sequence[Any], d_home: Any, d: Any) -> list:
        """Variables that turn the unit direction ``d_home`` into ``d`` (axes as they are
        now, orthonormal; see the subclasses). Not every joint can."""
        raise NotImplementedError(f"a {cls.__name__} joint cannot align a direction")

    @classmethod
    def orient(cls, axes: Sequence[Any], R: Any) -> list:
        """Variables of the relative rotation ``R`` (3x3, in the fixed frame) about the
        joint's ``axes`` (as they are now, orthonormal)."""
        raise NotImplementedError(f"a {cls.__name__} joint cannot take a rotation")


class Revolute(Joint):
    """A rotation about one line (planar case: the axis is z)."""

    letter = "R"

    @classmethod
    def solve_distance(cls, S, c0, P, L):
        """Paden-Kahan subproblem 3: theta0 +- acos(k) with theta0 the angle from the
        point's radius to P's (about the axis), branches (+, -)."""
        ca = _ca()
        w = S[0:3]
        a = ca.cross(w, S[3:6])  # the axis' point nearest the origin
        u = c0 - a
        v = P - a
        u_par = w * ca.dot(w, u)
        u_perp, v_perp = u - u_par, v - w * ca.dot(w, v)
        nu, nv = ca.norm_2(u_perp), ca.norm_2(v_perp)
        th0 = _pk1(w, u_perp, v_perp)
        k = (ca.sumsqr(v - u_par) + nu * nu - L * L) / (2 * nu * nv + 1e-300)
        ok = ca.fabs(k) <= 1 + 1e-12
        delta = ca.acos(_clip1(k))
        return [(th0 + delta, ok), (th0 - delta, ok)]

    @classmethod
    def align(cls, axes, d_home, d):
        return [_pk1(axes[0], d_home, d)]

    @classmethod
    def orient(cls, axes, R):
        ca = _ca()
        w = axes[0]
        # a direction normal to w (the largest of w x e_k, so it never vanishes)
        cands = [ca.cross(w, ca.DM(e)) for e in ([1, 0, 0], [0, 1, 0], [0, 0, 1])]
        u = cands[0]
        for c in cands[1:]:
            u = ca.if_else(ca.sumsqr(c) > ca.sumsqr(u), c, u)
        return [_pk1(w, u, ca.mtimes(R, u))]


class Prismatic(Joint):
    """A translation along one direction (planar case: the direction lies in x-y)."""

    letter = "P"

    @classmethod
    def solve_distance(cls, S, c0, P, L):
        """The roots of |P - c0 - s v| = L: s = v.w +- sqrt((v.w)^2 - |w|^2 + L^2), w =
        P - c0, branches (+, -)."""
        ca = _ca()
        v = S[3:6]
        w = P - c0
        vw = ca.dot(v, w)
        disc = vw * vw - ca.sumsqr(w) + L * L
        ok = disc >= -1e-12 * (L * L + 1e-300)
        r = ca.sqrt(ca.fmax(disc, 0))
        return [(vw + r, ok), (vw - r, ok)]


class Cylindrical(Joint):
    """A rotation about a line and a translation along it."""

    letter = "C"


class Universal(Joint):
    """Two rotations about intersecting, orthogonal axes (``a`` then ``b``)."""

    letter = "U"

    @classmethod
    def align(cls, axes, d_home, d):
        """With ``d_home = a x b`` (the link leaves the cross along their normal):
        ``Rot(a, ta) Rot(b, tb) d_home = d`` with ``tb`` in [-pi/2, pi/2]."""
        ca = _ca()
        a, b = axes[0], axes[1]
        c = ca.cross(a, b)
        ua, ub, uc = ca.dot(a, d), ca.dot(b, d), ca.dot(c, d)
        tb = ca.asin(_clip1(ua))
        ta = ca.atan2(-ub, uc)
        return [ta, tb]


class Spherical(Joint):
    """Three rotations about concurrent, orthogonal axes (``a``, ``b``, ``c`` in turn)."""

    letter = "S"

    @classmethod
    def align(cls, axes, d_home, d):
        """As a universal joint on the first two axes, the spin about the link zero."""
        return [*Universal.align(axes[:2], d_home, d), 0.0]

    @classmethod
    def orient(cls, axes, R):
        """``R = Rot(a, ta) Rot(b, tb) Rot(c, tc)`` with ``tb`` in [-pi/2, pi/2] (XYZ
        angles in the joint's frame [a, b, c])."""
        ca = _ca()
        F = ca.horzcat(axes[0], axes[1], axes[2])
        L = ca.mtimes(ca.mtimes(F.T, R), F)
        tb = ca.asin(_clip1(L[0, 2]))
        ta = ca.atan2(-L[1, 2], L[2, 2])
        tc = ca.atan2(-L[0, 1], L[0, 0])
        return [ta, tb, tc]


#: Joint letter -> class.
JOINTS: dict[str, type[Joint]] = {j.letter: j for j in (Revolute, Prismatic, Cylindrical,
                                                        Universal, Spherical)}
assert set(JOINTS) == set(JOINT_TYPES), "every joint type needs its class (and vice versa)"
