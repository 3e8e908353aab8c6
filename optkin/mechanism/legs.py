"""Legs of parallel platforms: serial chains in product-of-exponentials form (numpy data).

A leg is a serial chain of joints (:mod:`optkin.mechanism.joints`, moved by :mod:`optkin.model.joints`) from the base to the
moving platform, given as in Lynch & Park, *Modern Robotics* ch. 4: one screw per joint
variable, ``S = (omega, v)`` in the fixed frame at the home configuration (every variable
zero), and the pose ``home`` reached at the end of the chain there. The chain's end is
either

* the platform frame itself (``end="frame"``, what :meth:`Leg.from_screws` builds): the leg
  constrains the whole platform pose, ``T_leg(q) = T_platform``; or
* a point of the platform (``end="point"``) reached through a spherical joint (a planar
  revolute for planar platforms) that is not part of the chain: the leg constrains only
  where that point is, ``T_leg(q) e0 = T_platform b``. Its angles are *reported* in the
  joint values (computed from the orientation) when the leg type names them.

Many classical legs are a distance constraint: the actuated joint moves a centre C (or is
the distance itself) and a link of fixed length joins C to a platform point P, so
``|P - C(q_a)| = l`` (Özgören's leg-by-leg equations; the rows of A and B of Chablat and
Wenger). Such legs carry a :class:`Distance` description and the model uses this reduced
one-row form by default; it gives the same configurations as the chain's full closure.

Builders (:data:`LEG_TYPES`) keep the familiar types, each a thin constructor of a chain:

=====  =========  =======================================  =============  ========
type   platform   joint values                              actuated       form
=====  =========  =======================================  =============  ========
RPR    planar     theta, rho, psi                           rho            distance
RRR    planar     theta1, theta2, theta3                    theta1         distance
PRR    planar     s, theta, psi                             s              distance
UPS    spatial    ua, ub, rho, sa, sb, sc                   rho            distance
SPS    spatial    as UPS (the base spin about the leg is idle)  rho        distance
RUS    spatial    theta, ua, ub (the platform S unreported) theta          distance
RSS    spatial    as RUS (the elbow spin is idle)           theta          distance
PUS    spatial    s, ua, ub (the platform S unreported)     s              distance
RPS    spatial    theta, rho, sa, sb, sc                    rho            chain
PRS    spatial    s, theta, sa, sb, sc                      s              chain
UPU    spatial    ua, ub, rho, va, vb                       rho            chain
PSP    spatial    s, sa, sb, sc, t                          s              chain
=====  =========  =======================================  =============  ========

Adding a leg type: write its builder (a function returning a :class:`Leg`) and register it
with :func:`leg_type`. The problem-file schema reads this registry.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_vector
from .._checks import show as _show
from ..errors import MechanismError
from ..numeric import singular_values
from .joints import JOINT_TYPES, expand, n_vars
from .platforms import PLATFORMS

__all__ = ["Leg", "Distance", "LegType", "LEG_TYPES", "MAX_LEGS", "degenerate_points",
           "leg_type", "validate_legs", "revolute_screw", "prismatic_screw"]

#: Most legs a platform may have (redundant actuation included).
MAX_LEGS = 64
#: Most elementary joint variables in one leg.
MAX_LEG_VARIABLES = 24


def revolute_screw(axis: Any, point: Any) -> np.ndarray:
    """The screw (omega, -omega x q) of a rotation about the line through ``point`` along
    the unit ``axis`` (3 numbers each; 2-D points lie in the plane z = 0).

    >>> revolute_screw([0, 0, 1], [1, 0]).tolist()
    [0.0, 0.0, 1.0, 0.0, -1.0, 0.0]
    """
    w = _pad3(np.asarray(axis, dtype=float))
    q = _pad3(np.asarray(point, dtype=float))
    # q x w written out: numpy's cross of two 3-vectors costs 57 us, which a 6-6
    # platform's 60 screws paid in every problem a worker loads (3.4 ms)
    return np.array([w[0], w[1], w[2], q[1] * w[2] - q[2] * w[1],
                     q[2] * w[0] - q[0] * w[2], q[0] * w[1] - q[1] * w[0]])


def prismatic_screw(direction: Any) -> np.ndarray:
    """The screw (0, v) of a translation along the unit ``direction``."""
    return np.concatenate([np.zeros(3), _pad3(np.asarray(direction, dtype=float))])


def _pad3(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float).ravel()
    return np.concatenate([v, np.zeros(3 - v.size)]) if v.size < 3 else v


def _frozen(a: Any) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Distance:
    """A leg that is a distance constraint ``|P - C(q_a)| = l``.

    Attributes
    ----------
    driver : int
        How many leading variables move the centre C (the actuated joint, or 0 when the
        actuated joint is the distance itself).
    pivot : int
        Index (in ``Leg.joints``) of the joint at C that turns the link towards P.
    centre : ndarray (3,)
        C at home.
    direction : ndarray (3,)
        The unit direction of the link at home, from C towards P.
    length : float or None
        The link's length l; None when the actuated prismatic joint after the pivot is the
        distance (RPR, UPS).
    """

    driver: int
    pivot: int
    centre: np.ndarray
    direction: np.ndarray
    length: float | None


class Leg:
    """One leg: a serial chain from the base to the platform (see the module docstring).

    Build one by its type, ``Leg("UPS", base, platform)`` (keys of the type as keyword
    arguments: ``lengths``, ``axis``, ``arm``, ``direction``; checked when the mechanism is
    built, or by :meth:`from_spec`), or from its screws with :meth:`from_screws`. Legs are
    immutable.

    Attributes
    ----------
    type : str
        The leg's type (``"UPS"``) or, for chains built from screws, its joint string.
    joints : str
        The letters of the chain's joints, base to platform (:data:`~optkin.mechanism.joints.JOINT_TYPES`).
    screws : ndarray (n, 6)
        One screw per joint variable, fixed frame, home configuration.
    names : tuple of str
        The joint variables' names.
    actuated : tuple of int
        Indices of the actuated variables.
    home : ndarray (4, 4)
        The chain's end at home: the platform frame (frame end) or a frame whose origin
        is the end point e0 (point end).
    end : str
        ``"frame"`` or ``"point"``.
    platform_point : ndarray (3,)
        The end point in the platform frame (point end; zero for a frame end).
    end_joint : str
        The joint at the platform ("S", or "R" for planar legs) of a point end.
    reported : bool
        The last joint of ``joints`` is that end joint: its variables follow from the
        orientation (UPS's sa, sb, sc; RPR's psi) instead of constraining anything.
    distance : Distance or None
        The reduced distance form, when the leg is one.
    base, platform, lengths, axis, arm :
        The builder's geometry (attachment points in the base and platform frames, link
        lengths, axes), for reports and drawings; empty for chains built from screws.
    inventory : tuple
        (joint freedoms, moving links, idle freedoms) of the physical leg, for Grubler's
        count (a Delta's parallelogram is two S-S rods, not R + U + S).
    positive : tuple of int
        Variables that must stay positive (a leg's length between its joints).
    """

    __slots__ = ("type", "joints", "screws", "names", "actuated", "home", "end", "platform_point",
                 "dim", "end_joint", "reported", "distance", "base", "platform", "lengths", "axis",
                 "arm", "inventory", "positive", "spec")

    def __init__(self, type: str, base: Any = None, platform: Any = None, lengths: Any = (),
                 axis: Any = None, arm: Any = None, actuated: Any = None, **keys: Any) -> None:
        spec: dict[str, Any] = {"type": type, "base": _plain(base), "platform": _plain(platform)}
        for k, v in (("lengths", lengths), ("axis", axis), ("arm", arm), ("actuated", actuated),
                     *keys.items()):
            if not _empty(v):
                spec[k] = _plain(v)
        _init(self, type=type, joints="", screws=np.zeros((0, 6)), names=(), actuated=(),
              home=np.eye(4), end="", platform_point=np.zeros(3), dim=0, spec=spec)

    @classmethod
    def _chain(cls, **fields: Any) -> Leg:
        leg = object.__new__(cls)
        _init(leg, **fields)
        return leg

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a Leg is immutable; build a new one")

    def __repr__(self) -> str:
        return f"Leg({self.type!r}, joints={self.joints!r}, end={self.end!r})"

    # ------------------------------------------------------------------ structure
    @property
    def kinds(self) -> str:
        """One letter per variable: ``"R"`` rotation, ``"P"`` translation."""
        return expand(self.joints)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.names

    @property
    def actuated_index(self) -> int:
        """The (first) actuated variable."""
        return self.actuated[0]

    @property
    def n_reported(self) -> int:
        """How many trailing variables are the reported end joint's."""
        return n_vars(self.joints[-1]) if self.reported else 0

    @property
    def topology(self) -> tuple:
        """What the compiled code depends on (not the numbers)."""
        d = self.distance
        dist = None if d is None else (d.driver, d.pivot, d.length is None)
        return (self.type, self.joints, self.actuated, self.end, self.end_joint, self.reported,
                self.dim, dist)

    def geometry(self) -> np.ndarray:
        """The leg's numbers as one vector (layout: :meth:`geometry_names`)."""
        d = self.distance
        parts = [self.screws.ravel(), self.home[:3, :].T.ravel(), self.platform_point]
        if d is not None:
            parts += [d.centre, d.direction, [d.length if d.length is not None else 0.0]]
        return np.concatenate([np.asarray(p, dtype=float).ravel() for p in parts])

    def geometry_names(self) -> list[str]:
        names = [f"screws[{k}][{c}]" for k in range(len(self.screws)) for c in range(6)]
        names += [f"home[{r}][{c}]" for c in range(4) for r in range(3)]
        names += [f"platform_point[{c}]" for c in range(3)]
        if self.distance is not None:
            names += [f"distance.centre[{c}]" for c in range(3)]
            names += [f"distance.direction[{c}]" for c in range(3)] + ["distance.length"]
        return names

    def to_dict(self) -> dict[str, Any]:
        """The leg's description (the builder's arguments, or the screws)."""
        if self.spec:
            return {k: _plain(v) for k, v in self.spec.items() if v is not None}
        return {"screws": self.screws.tolist(), "home": self.home.tolist(),
                "actuated": list(self.actuated), "joints": self.joints}

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_screws(cls, screws: Any, home: Any, actuated: Any, joints: str | None = None,
                    name: str | None = None) -> Leg:
        """A leg from its screws: the general chain (Modern Robotics (4.14)).

        Parameters
        ----------
        screws : array (n, 6)
            Rows ``(omega, v)`` in the fixed frame at home: ``|omega| = 1`` for a rotation
            (``v = -omega x q``, q a point of the axis), ``omega = 0`` and ``|v| = 1`` for
            a translation.
        home : array (4, 4)
            The pose of the platform frame reached through this leg when every joint is
            zero.
        actuated : int or sequence of int
            Index (or indices) of the actuated variable(s).
        joints : str, optional
            Groups the screws into joints for names and reports, e.g. ``"UPU"`` (U = two
            rotations with intersecting axes, S = three, C = a rotation and a translation
            along one axis). Default: one R or P per screw.
        name : str, optional
            The leg's label (default: the joint string).

        Examples
        --------
        A 3-RPR leg from base point (1, 0) with the platform frame at (1, 0) at home:

        >>> from optkin.mechanism.legs import revolute_screw, prismatic_screw
        >>> S = [revolute_screw([0, 0, 1], [1, 0]), prismatic_screw([1, 0]),
        ...      revolute_screw([0, 0, 1], [1, 0])]
        >>> T = [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]
        >>> Leg.from_screws(S, T, actuated=1, joints="RPR").names
        ('R1', 'P2', 'R3')
        """
        S = _screws(screws, "screws")
        kinds = "".join("P" if np.linalg.norm(s[:3]) == 0 else "R" for s in S)
        if joints is None:
            joints = kinds
        if not isinstance(joints, str) or not joints:
            raise MechanismError(f"joints: expected a string of joint letters among "
                                 f"{sorted(JOINT_TYPES)}, got {_show(joints)}", path=("joints",))
        bad = [c for c in joints if c not in JOINT_TYPES]
        if bad:
            raise MechanismError(f"joints: unknown joint letter {bad[0]!r}; known: "
                                 f"{sorted(JOINT_TYPES)}", path=("joints",))
        if expand(joints) != kinds:
            raise MechanismError(
                f"joints: {joints!r} means screws of kinds {expand(joints)!r} (R rotation, P "
                f"translation), but the screws are {kinds!r}", path=("joints",))
        T = _pose4(home, "home")
        act = _actuated(actuated, len(S))
        names = []
        for k, c in enumerate(joints):
            for suf in JOINT_TYPES[c].suffixes:
                names.append(f"{c}{k + 1}{suf}")
        label = _label(name if name is not None else joints)
        planar = _is_planar(S, T)
        dim = 2 if planar else 3
        return cls._chain(type=label, joints=joints, screws=_frozen(S), names=tuple(names),
                   actuated=act, home=_frozen(T), end="frame", platform_point=_frozen(np.zeros(3)),
                   dim=dim, inventory=(tuple(n_vars(c) for c in joints), len(joints) - 1, 0))

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any] | Leg, i: int) -> Leg:
        """Build and validate leg ``i`` (0-based) from a mapping ``{"type": ..., ...}``
        (one of :data:`LEG_TYPES`) or ``{"screws": ..., "home": ..., "actuated": ...}``."""
        if isinstance(spec, Leg):
            if not spec.spec:  # a chain (from screws): already valid
                return spec
            spec = spec.spec  # a leg given by its type: built and checked here
        where = f"legs[{i}]"
        if not isinstance(spec, Mapping):
            raise MechanismError(f"{where}: expected a mapping with type, base, platform "
                                 "(or screws, home, actuated)", path=("legs", i))
        if "screws" in spec:
            allowed = {"screws", "home", "actuated", "joints", "name"}
            unknown = sorted(set(spec) - allowed, key=str)
            if unknown:
                raise MechanismError(f"{where}: unknown key(s) {unknown}; a chain takes "
                                     f"{sorted(allowed)}", path=("legs", i, str(unknown[0])))
            for key in ("home", "actuated"):
                if key not in spec:
                    raise MechanismError(f"{where}.{key}: missing", path=("legs", i, key))
            try:
                return cls.from_screws(spec["screws"], spec["home"], spec["actuated"],
                                       spec.get("joints"), spec.get("name"))
            except MechanismError as e:
                raise MechanismError(f"{where}.{e}", path=("legs", i, *e.path)) from None
        t = spec.get("type", "")
        t = t.upper() if isinstance(t, str) else ""
        lt = LEG_TYPES.get(t)
        if lt is None:
            raise MechanismError(
                f"{where}.type: unknown leg type {_show(spec.get('type'))}; supported: "
                f"{sorted(LEG_TYPES)}, or a chain given by its screws (Leg.from_screws)",
                path=("legs", i, "type"))
        allowed = {"type", "base", "platform", "actuated", *lt.keys}
        unknown = sorted(set(spec) - allowed, key=str)
        if unknown:
            raise MechanismError(f"{where}: unknown key(s) {unknown}; a {t} leg takes "
                                 f"{sorted(allowed)}", path=("legs", i, str(unknown[0])))
        args: dict[str, Any] = {}
        for key in ("base", "platform"):
            if key not in spec:
                raise MechanismError(f"{where}.{key}: missing; give the joint centre "
                                     f"({lt.dim} numbers)", path=("legs", i, key))
            args[key] = _vec(spec[key], lt.dim, f"{where}.{key}", ("legs", i, key))
        for key, n in lt.keys.items():
            v = spec.get(key)
            if key == "lengths" and n == 0:
                if not _empty(v):
                    raise MechanismError(f"{where}.lengths: {t} legs have no fixed link "
                                         "lengths", path=("legs", i, "lengths"))
                continue
            if v is None:
                if key in lt.optional:
                    continue
                what = (f"{n} link length{'s' if n != 1 else ''}" if key == "lengths"
                        else f"{key} ({lt.doc[key]})")
                raise MechanismError(f"{where}.{key}: {t} legs need {what}",
                                     path=("legs", i, key))
            args[key] = _vec(v, n, f"{where}.{key}", ("legs", i, key))
        if "actuated" in spec and spec["actuated"] is not None:
            a = spec["actuated"]
            names = lt.names
            if isinstance(a, str):
                a = names.index(a) if a in names else -2
            if isinstance(a, bool) or not isinstance(a, (int, np.integer)) or a != lt.actuated:
                raise MechanismError(
                    f"{where}.actuated: {_show(spec['actuated'])} is not supported for {t} "
                    f"legs; the actuated joint is {names[lt.actuated]!r} (index {lt.actuated})",
                    path=("legs", i, "actuated"))
        try:
            leg = lt.build(**args)
        except MechanismError as e:
            raise MechanismError(f"{where}.{e}", path=("legs", i, *e.path)) from None
        keep = {"type": t, **{k: (v.tolist() if isinstance(v, np.ndarray) else v)
                              for k, v in args.items()}}
        object.__setattr__(leg, "spec", keep)
        return leg


_DEFAULTS: dict[str, Any] = {"end_joint": "", "reported": False, "distance": None,
                             "lengths": (), "axis": None, "arm": None,
                             "inventory": ((), 0, 0), "positive": (), "spec": {}}


def _init(leg: Leg, **fields: Any) -> None:
    for k in Leg.__slots__:
        v = fields[k] if k in fields else _DEFAULTS.get(k)
        if k in ("base", "platform") and v is None:
            v = _frozen(np.zeros(0))
        object.__setattr__(leg, k, v)


def _plain(v: Any) -> Any:
    """A spec value as plain data (lists of numbers), for echoing and rebuilding."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.generic):
        return v.item()
    return v


# --------------------------------------------------------------------------------------
# input checks


def _empty(v: Any) -> bool:
    """None or an empty list / tuple / array (a leg type without fixed lengths)."""
    if v is None:
        return True
    try:
        return len(v) == 0
    except TypeError:
        return False


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


def _screws(v: Any, where: str) -> np.ndarray:
    try:
        S = np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise MechanismError(f"{where}: expected an (n, 6) array of screws, got {_show(v)}",
                             path=(where,)) from None
    if S.ndim != 2 or S.shape[1] != 6 or not 1 <= S.shape[0] <= MAX_LEG_VARIABLES:
        raise MechanismError(f"{where}: expected an (n, 6) array of screws (1 <= n <= "
                             f"{MAX_LEG_VARIABLES}), got shape {S.shape}", path=(where,))
    if not np.all(np.isfinite(S)) or np.abs(S).max() > 1e150:
        raise MechanismError(f"{where}: non-finite or huge entries", path=(where,))
    for k, s in enumerate(S):
        nw, nv = np.linalg.norm(s[:3]), np.linalg.norm(s[3:])
        if nw > 0 and abs(nw - 1) > 1e-9:
            raise MechanismError(f"{where}[{k}]: the rotation axis omega must be a unit vector "
                                 f"(|omega| = {nw:.6g}); for a translation give omega = 0",
                                 path=(where, k))
        if nw == 0 and abs(nv - 1) > 1e-9:
            raise MechanismError(f"{where}[{k}]: a translation needs a unit direction v "
                                 f"(|v| = {nv:.6g})", path=(where, k))
        if nw > 0 and abs(float(s[:3] @ s[3:])) > 1e-9 * max(1.0, nv):
            raise MechanismError(f"{where}[{k}]: omega . v must be 0 for a revolute joint "
                                 "(v = -omega x q); screws with a pitch are not joints here",
                                 path=(where, k))
    return S


def _pose4(v: Any, where: str) -> np.ndarray:
    try:
        T = np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError):
        T = np.zeros(0)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise MechanismError(f"{where}: expected a 4x4 homogeneous transform, got "
                             f"{_show(v)}", path=(where,))
    R = T[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > 1e-9 or np.linalg.det(R) < 0 or np.abs(
            T[3] - [0, 0, 0, 1]).max() > 1e-12:
        raise MechanismError(f"{where}: not a rigid transform (orthonormal rotation block, "
                             "det +1, last row 0 0 0 1)", path=(where,))
    return T


def _actuated(v: Any, n: int) -> tuple[int, ...]:
    vals = [v] if isinstance(v, (int, np.integer)) and not isinstance(v, bool) else v
    try:
        out = tuple(int(a) for a in vals if not isinstance(a, bool) and float(a) == int(a))
        ok = len(out) == len(vals) and len(out) >= 1 and len(set(out)) == len(out)
    except (TypeError, ValueError, OverflowError):
        ok, out = False, ()
    if not ok or any(not 0 <= a < n for a in out):
        raise MechanismError(f"actuated: expected the index (or indices) of actuated "
                             f"variables in 0..{n - 1}, got {_show(v)}", path=("actuated",))
    return tuple(sorted(out))


def _label(v: Any) -> str:
    if not isinstance(v, str) or not v or len(v) > 40:
        raise MechanismError(f"name: expected a short string, got {_show(v)}", path=("name",))
    return v


def _is_planar(S: np.ndarray, T: np.ndarray) -> bool:
    """Every rotation about z, every translation and the home frame in the plane z = 0."""
    rot_ok = all(np.allclose(s[:2], 0) and np.isclose(abs(s[2]), 1) and np.isclose(s[5], 0)
                 if np.linalg.norm(s[:3]) > 0 else np.isclose(s[5], 0) for s in S)
    return bool(rot_ok and np.isclose(T[2, 3], 0) and np.allclose(T[:3, 2], [0, 0, 1]))


# --------------------------------------------------------------------------------------
# the leg types


@dataclass(frozen=True)
class LegType:
    """A leg type: its builder and what it takes (the schema reads these)."""

    name: str
    dim: int
    names: tuple[str, ...]
    actuated: int
    keys: dict[str, int]  # extra keys -> number of values (lengths: how many)
    doc: dict[str, str]
    build: Callable[..., Leg]
    optional: tuple[str, ...] = ()
    summary: str = ""


#: Leg type name -> :class:`LegType`.
LEG_TYPES: dict[str, LegType] = {}


def leg_type(name: str, dim: int, names: Sequence[str], actuated: int,
             keys: Mapping[str, int] | None = None, doc: Mapping[str, str] | None = None,
             optional: Sequence[str] = (), summary: str = ""):
    """Register a builder ``f(base, platform, **keys) -> Leg`` as leg type ``name``."""

    def deco(fn: Callable[..., Leg]) -> Callable[..., Leg]:
        LEG_TYPES[name] = LegType(name, dim, tuple(names), actuated, dict(keys or {}),
                                  dict(doc or {}), fn, tuple(optional), summary)
        return fn

    return deco


_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])
_Y = np.array([0.0, 1.0, 0.0])


def _unit(v: np.ndarray, where: str) -> np.ndarray:
    n = float(np.linalg.norm(v))
    if n < 1e-12 or abs(n - 1) > 1e-9:
        raise MechanismError(f"{where}: expected a unit vector, got {_show(v.tolist())}",
                             path=(where,))
    return v / n


def _point_leg(type_: str, joints: str, screws: list, names: Sequence[str], actuated: int,
               e0: np.ndarray, b: np.ndarray, dim: int, reported: bool, distance: Distance | None,
               **geo: Any) -> Leg:
    home = np.eye(4)
    home[:3, 3] = e0
    end_joint = "R" if dim == 2 else "S"
    freedoms = tuple(n_vars(c) for c in joints)
    if not reported:
        freedoms += (n_vars(end_joint) if dim == 3 else 1,)
    return Leg._chain(type=type_, joints=joints, screws=_frozen(np.array(screws)), names=tuple(names),
               actuated=(actuated,), home=_frozen(home), end="point",
               platform_point=_frozen(_pad3(b)), dim=dim, end_joint=end_joint,
               reported=reported, distance=distance,
               inventory=(freedoms, len(freedoms) - 1, 0), **geo)


def _geo(base: np.ndarray, platform: np.ndarray, **kw: Any) -> dict[str, Any]:
    return {"base": _frozen(base), "platform": _frozen(platform), **kw}


@leg_type("RPR", 2, ("theta", "rho", "psi"), 1,
          summary="base revolute, actuated prismatic, platform revolute (planar)")
def _rpr(base: np.ndarray, platform: np.ndarray) -> Leg:
    A = _pad3(base)
    S = [revolute_screw(_Z, A), prismatic_screw(_X), revolute_screw(_Z, A)]
    d = Distance(0, 0, _frozen(A), _frozen(_X), None)
    return _point_leg("RPR", "RPR", S, ("theta", "rho", "psi"), 1, A, platform, 2, True, d,
                      **_geo(base, platform))


@leg_type("RRR", 2, ("theta1", "theta2", "theta3"), 0, {"lengths": 2},
          {"lengths": "proximal and distal link lengths"},
          summary="actuated base revolute, elbow revolute, platform revolute (planar)")
def _rrr(base: np.ndarray, platform: np.ndarray, lengths: np.ndarray) -> Leg:
    l1, l2 = _positive_lengths(lengths)
    A = _pad3(base)
    C = A + l1 * _X
    E = C + l2 * _X
    S = [revolute_screw(_Z, A), revolute_screw(_Z, C), revolute_screw(_Z, E)]
    d = Distance(1, 1, _frozen(C), _frozen(_X), l2)
    return _point_leg("RRR", "RRR", S, ("theta1", "theta2", "theta3"), 0, E, platform, 2, True,
                      d, **_geo(base, platform, lengths=(l1, l2)))


@leg_type("PRR", 2, ("s", "theta", "psi"), 0, {"direction": 2, "lengths": 1},
          {"direction": "the slider's unit direction", "lengths": "the distal link's length"},
          summary="actuated slider, revolute on it, platform revolute (planar)")
def _prr(base: np.ndarray, platform: np.ndarray, direction: np.ndarray,
         lengths: np.ndarray) -> Leg:
    (l2,) = _positive_lengths(lengths)
    u = _unit(_pad3(direction), "direction")
    A = _pad3(base)
    E = A + l2 * _X
    S = [prismatic_screw(u), revolute_screw(_Z, A), revolute_screw(_Z, E)]
    d = Distance(1, 1, _frozen(A), _frozen(_X), l2)
    return _point_leg("PRR", "PRR", S, ("s", "theta", "psi"), 0, E, platform, 2, True, d,
                      **_geo(base, platform, lengths=(l2,), axis=_frozen(u)))


def _ups(type_: str, base: np.ndarray, platform: np.ndarray) -> Leg:
    A = _pad3(base)
    S = [revolute_screw(_X, A), revolute_screw(_Y, A), prismatic_screw(_Z),
         revolute_screw(_X, A), revolute_screw(_Y, A), revolute_screw(_Z, A)]
    d = Distance(0, 0, _frozen(A), _frozen(_Z), None)
    return _point_leg(type_, "UPS", S, ("ua", "ub", "rho", "sa", "sb", "sc"), 2, A, platform, 3,
                      True, d, **_geo(base, platform))


@leg_type("UPS", 3, ("ua", "ub", "rho", "sa", "sb", "sc"), 2,
          summary="base universal, actuated prismatic, platform spherical")
def _ups_leg(base: np.ndarray, platform: np.ndarray) -> Leg:
    return _ups("UPS", base, platform)


@leg_type("SPS", 3, ("ua", "ub", "rho", "sa", "sb", "sc"), 2,
          summary="as UPS: the base spherical's spin about the leg is idle and left out")
def _sps_leg(base: np.ndarray, platform: np.ndarray) -> Leg:
    return _ups("SPS", base, platform)


def _rus(type_: str, base, platform, lengths, axis, arm) -> Leg:
    la, lb = _positive_lengths(lengths)
    ax = _unit(axis, "axis")
    ar = _unit(arm, "arm")
    if abs(ax @ ar) > 1e-9:
        raise MechanismError("arm: axis and arm must be orthogonal", path=("arm",))
    A = _pad3(base)
    C = A + la * ar
    d_home = np.cross(ar, ax)
    E = C + lb * d_home
    S = [revolute_screw(ax, A), revolute_screw(ar, C), revolute_screw(ax, C)]
    d = Distance(1, 1, _frozen(C), _frozen(d_home), lb)
    return _point_leg(type_, "RU", S, ("theta", "ua", "ub"), 0, E, platform, 3, False, d,
                      **_geo(base, platform, lengths=(la, lb), axis=_frozen(ax),
                             arm=_frozen(ar)))


_RUS_DOC = {"lengths": "arm (crank) and forearm (rod) lengths",
            "axis": "the base revolute's unit axis", "arm": "the arm's unit direction at "
            "theta = 0, orthogonal to axis (the arm turns towards axis x arm)"}


@leg_type("RUS", 3, ("theta", "ua", "ub"), 0, {"lengths": 2, "axis": 3, "arm": 3}, _RUS_DOC,
          summary="actuated base revolute (crank), universal, platform spherical")
def _rus_leg(base, platform, lengths, axis, arm) -> Leg:
    return _rus("RUS", base, platform, lengths, axis, arm)


@leg_type("RSS", 3, ("theta", "ua", "ub"), 0, {"lengths": 2, "axis": 3, "arm": 3}, _RUS_DOC,
          summary="as RUS: the elbow spherical's spin about the rod is idle and left out")
def _rss_leg(base, platform, lengths, axis, arm) -> Leg:
    return _rus("RSS", base, platform, lengths, axis, arm)


@leg_type("PUS", 3, ("s", "ua", "ub"), 0, {"direction": 3, "lengths": 1},
          {"direction": "the slider's unit direction", "lengths": "the rod's length"},
          summary="actuated slider, universal on it, rod, platform spherical")
def _pus_leg(base, platform, direction, lengths) -> Leg:
    (lb,) = _positive_lengths(lengths)
    u = _unit(direction, "direction")
    A = _pad3(base)
    E = A + lb * _Z  # the rod points up at home
    S = [prismatic_screw(u), revolute_screw(_X, A), revolute_screw(_Y, A)]
    d = Distance(1, 1, _frozen(A), _frozen(_Z), lb)
    return _point_leg("PUS", "PU", S, ("s", "ua", "ub"), 0, E, platform, 3, False, d,
                      **_geo(base, platform, lengths=(lb,), axis=_frozen(u)))


@leg_type("RPS", 3, ("theta", "rho", "sa", "sb", "sc"), 1, {"axis": 3},
          {"axis": "the base revolute's unit axis (the leg turns in the plane normal to it)"},
          summary="passive base revolute, actuated prismatic, platform spherical")
def _rps_leg(base, platform, axis) -> Leg:
    ax = _unit(axis, "axis")
    A = _pad3(base)
    v = np.cross(ax, _X) if abs(ax @ _Z) > 0.9 else _Z - ax * (ax @ _Z)
    v = v / np.linalg.norm(v)  # the leg's direction at home: normal to the axis
    f1 = np.cross(ax, v)       # the spherical's axes: (f1, ax, v), right-handed
    S = [revolute_screw(ax, A), prismatic_screw(v), revolute_screw(f1, A),
         revolute_screw(ax, A), revolute_screw(v, A)]
    leg = _point_leg("RPS", "RPS", S, ("theta", "rho", "sa", "sb", "sc"), 1, A, platform, 3,
                     True, None, **_geo(base, platform, axis=_frozen(ax)))
    object.__setattr__(leg, "positive", (1,))
    return leg


@leg_type("PRS", 3, ("s", "theta", "sa", "sb", "sc"), 0,
          {"direction": 3, "axis": 3, "lengths": 1},
          {"direction": "the slider's unit direction", "axis": "the revolute's unit axis",
           "lengths": "the link's length"},
          summary="actuated slider, revolute, link, platform spherical")
def _prs_leg(base, platform, direction, axis, lengths) -> Leg:
    (l,) = _positive_lengths(lengths)
    u = _unit(direction, "direction")
    ax = _unit(axis, "axis")
    A = _pad3(base)
    v = u - ax * (ax @ u)  # the link along the slider at home (normal to the axis)
    if np.linalg.norm(v) < 1e-9:
        raise MechanismError("axis: the revolute axis must not be along the slider",
                             path=("axis",))
    v = v / np.linalg.norm(v)
    f1 = np.cross(ax, v)  # (f1, ax, v) right-handed
    E = A + l * v
    S = [prismatic_screw(u), revolute_screw(ax, A), revolute_screw(f1, E),
         revolute_screw(ax, E), revolute_screw(v, E)]
    return _point_leg("PRS", "PRS", S, ("s", "theta", "sa", "sb", "sc"), 0, E, platform, 3, True,
                      None, **_geo(base, platform, lengths=(l,), axis=_frozen(ax),
                                   arm=_frozen(u)))


@leg_type("UPU", 3, ("ua", "ub", "rho", "va", "vb"), 2, {"axis": 3, "arm": 3},
          {"axis": "the first base axis of the universal joint (fixed to the base)",
           "arm": "its second axis at home (orthogonal to axis; the leg leaves along "
                  "axis x arm); the platform joint's axes are arm then axis (Tsai's "
                  "arrangement: the platform only translates)"},
          summary="base universal, actuated prismatic, platform universal")
def _upu_leg(base, platform, axis, arm) -> Leg:
    a1 = _unit(axis, "axis")
    a2 = _unit(arm, "arm")
    if abs(a1 @ a2) > 1e-9:
        raise MechanismError("arm: axis and arm must be orthogonal", path=("arm",))
    A = _pad3(base)
    b = _pad3(platform)
    v = np.cross(a1, a2)
    S = [revolute_screw(a1, A), revolute_screw(a2, A), prismatic_screw(v),
         revolute_screw(a2, A), revolute_screw(a1, A)]
    home = np.eye(4)
    home[:3, 3] = A - b  # the platform frame at home: its point b at A
    return Leg._chain(type="UPU", joints="UPU", screws=_frozen(np.array(S)),
               names=("ua", "ub", "rho", "va", "vb"), actuated=(2,), home=_frozen(home),
               end="frame", platform_point=_frozen(b), dim=3, inventory=((2, 1, 2), 2, 0),
               positive=(2,), **_geo(base, platform, axis=_frozen(a1), arm=_frozen(a2)))


@leg_type("PSP", 3, ("s", "sa", "sb", "sc", "t"), 0, {"direction": 3, "axis": 3},
          {"direction": "the base slider's unit direction (actuated)",
           "axis": "the platform slider's unit direction, in the platform frame"},
          summary="actuated base slider, spherical, slider on the platform")
def _psp_leg(base, platform, direction, axis) -> Leg:
    u = _unit(direction, "direction")
    w = _unit(axis, "axis")
    A = _pad3(base)
    b = _pad3(platform)
    S = [prismatic_screw(u), revolute_screw(_X, A), revolute_screw(_Y, A),
         revolute_screw(_Z, A), prismatic_screw(w)]
    home = np.eye(4)
    home[:3, 3] = A - b
    return Leg._chain(type="PSP", joints="PSP", screws=_frozen(np.array(S)),
               names=("s", "sa", "sb", "sc", "t"), actuated=(0,), home=_frozen(home),
               end="frame", platform_point=_frozen(b), dim=3, inventory=((1, 3, 1), 2, 0),
               **_geo(base, platform, axis=_frozen(w), arm=_frozen(u)))


def _positive_lengths(v: np.ndarray) -> tuple[float, ...]:
    if np.any(v <= 0):
        raise MechanismError(f"lengths: link lengths must be positive, got {v.tolist()}",
                             path=("lengths", int(np.flatnonzero(v <= 0)[0])))
    return tuple(float(x) for x in v)


# --------------------------------------------------------------------------------------
# a platform's legs


def validate_legs(legs: Sequence[Any], platform: str, redundant: bool = False) -> tuple[Leg, ...]:
    """Validate the legs of a platform: one actuated joint per degree of freedom, or (with
    ``redundant=True``) more actuated joints than degrees of freedom.

    Platforms whose attachment points leave no regular configuration at all (see
    :func:`degenerate_points`) are rejected here, before any solver sees them.
    """
    if not isinstance(platform, str) or platform not in PLATFORMS:
        raise MechanismError(
            f"platform: unknown platform kind {_show(platform)}; use one of {sorted(PLATFORMS)}",
            path=("platform",))
    if isinstance(legs, (str, bytes)) or not isinstance(legs, Sequence) or not legs:
        raise MechanismError("legs: expected a non-empty list of legs", path=("legs",))
    if len(legs) > MAX_LEGS:
        raise MechanismError(f"legs: {len(legs)} legs; at most {MAX_LEGS} are supported",
                             path=("legs",))
    plat = PLATFORMS[platform]
    out = tuple(Leg.from_spec(s, i) for i, s in enumerate(legs))
    for i, leg in enumerate(out):
        if leg.dim != plat.space_dim and not (leg.dim == 2 and plat.space_dim == 3
                                              and leg.end == "frame"):
            raise MechanismError(
                f"legs[{i}].type: a {leg.type} leg is {'planar' if leg.dim == 2 else 'spatial'} "
                f"but the platform is {platform!r}", path=("legs", i, "type"))
    n_act = sum(len(leg.actuated) for leg in out)
    dof = plat.dof
    if redundant:
        if n_act <= dof:
            raise MechanismError(
                f"legs: a redundantly actuated {platform!r} platform needs more than {dof} "
                f"actuated legs, got {n_act}; drop redundant=True for {dof} legs", path=("legs",))
    elif n_act != dof and all(leg.distance is not None for leg in out):
        # distance legs leave the platform all its freedoms: one actuator each (legs in
        # chain form constrain it; the model checks that their closure is square)
        hint = "; pass redundant=True for redundant actuation" if n_act > dof else ""
        raise MechanismError(
            f"legs: a {platform!r} platform has {dof} degrees of freedom and needs {dof} "
            f"actuated legs, got {n_act}{hint}", path=("legs",))
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

    The closure row of a distance leg is a line (a pure force) through its platform point,
    and for legs whose actuated prismatic joint is the distance (RPR/UPS/SPS) through its
    base point too. When the points are placed so that these lines are dependent at every
    pose, no closed configuration has a regular W_p: the platform moves with the actuators
    locked everywhere (a permanent parallel singularity) and the solvers have nothing to
    converge to. Detected (among distance legs):

    * two length-actuated legs with the same base and the same platform point;
    * planar platforms: all platform points coincide, or all base points of
      length-actuated legs do;
    * spatial platforms: all platform points on one line, or all base points of
      length-actuated legs on one line;
    * translational and point platforms with length-actuated legs: the points
      base - platform coincide (point platforms) or lie on one line (translational).

    Returns None, or ``(key, leg indices, explanation)`` with ``key`` "base" or "platform"
    (the points at fault), or "" for two legs that are the same.
    """
    dist = [leg for leg in legs if leg.distance is not None and leg.base.size]
    if len(dist) != len(legs) or not legs:
        return None  # general chains: their closure is checked when solved
    n = len(legs)
    prism = [leg.distance.length is None for leg in legs]  # type: ignore[union-attr]
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
