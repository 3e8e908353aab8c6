"""The :class:`Mechanism`: an immutable description, either a Khalil table or legs."""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._checks import as_float, as_int, as_vector
from .._checks import show as _show
from ..errors import MechanismError
from ..results import jsonable
from .khalil import KhalilTable
from .legs import Leg, validate_legs
from .platforms import PLATFORMS

__all__ = ["Mechanism", "TASK_COMPONENTS"]

#: Pose components an inverse problem may prescribe for a Khalil mechanism.
TASK_COMPONENTS = ("x", "y", "z", "rx", "ry", "rz")


class Mechanism:
    """A closed-chain or parallel mechanism (plain data, validated on construction).

    Build one with :meth:`from_khalil`, :meth:`from_legs` or a factory of
    :mod:`optkin.mechanisms`. Its compiled CasADi model lives beside it (see
    :func:`optkin.model.get_model`), keyed by :attr:`key`.

    Attributes
    ----------
    joint_names : tuple of str
        Every joint variable, in the order of ``KinResult.q``.
    actuated : tuple of bool
        Whether each joint is actuated.
    dof : int
        The number of degrees of freedom the mechanism is meant to have (= active joints,
        unless the mechanism is redundantly actuated).
    redundant : bool
        True for a redundantly actuated platform: more actuated joints (``n_actuated``) than
        degrees of freedom; the closure then has more rows than unknowns.
    """

    __slots__ = (
        "name", "kind", "joint_names", "actuated", "revolute", "dof", "planar", "table",
        "end_effector", "task", "legs", "platform", "home", "params", "redundant", "limits", "_spec",
        "reduced", "_key", "_topology", "_geometry",
        "__weakref__",
    )

    def __setattr__(self, name: str, value: Any) -> None:
        if getattr(self, "_key", None) is not None:
            raise AttributeError("a Mechanism is immutable; build a new one")
        object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ builders
    @classmethod
    def from_khalil(
        cls,
        rows: Sequence[Any],
        loops: int = 0,
        params: Mapping[str, float] | None = None,
        end_effector: int | None = None,
        name: str = "khalil",
        task: Sequence[str] | None = None,
        home: Mapping[str, float] | Sequence[float] | None = None,
        dof: int | None = None,
        limits: Mapping[str, Sequence[float | None]] | None = None,
    ) -> Mechanism:
        """A mechanism from its Khalil table (Khalil & Dombre 2002, Tables 7.1 and 7.2).

        Parameters
        ----------
        rows : sequence of mappings
            One row per frame j = 1..n+2B with keys a, mu, sigma, gamma, b, alpha, d, theta, r.
        loops : int
            B, the number of loops; the last 2B rows are the cut joints then their partner
            frames k+B (sigma = 2).
        params : mapping
            Values of named parameters used in the rows (``{"d3": 0.6}``).
        end_effector : int
            The frame whose pose is the end-effector pose (default: the last tree frame n).
        task : sequence of str
            The pose components an inverse problem prescribes, from ``x y z rx ry rz``
            (default all six when dof >= 6, else the first dof of ``rz x y z rx ry``).
        home : mapping or sequence
            Default guess for the passive joints (by name, or all joints in order).
        dof : int
            The intended number of degrees of freedom (default: number of actuated joints).
        limits : mapping
            Joint limits by name, ``{"r5": (0.0, None)}`` (None: unbounded). Postures outside
            them are left out of :func:`optkin.inverse`; :func:`optkin.forward` reports them.

        Examples
        --------
        >>> rows = [dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="t1", r=0)]
        >>> Mechanism.from_khalil(rows).joint_names
        ('t1',)
        """
        table = KhalilTable(rows, loops=loops, params=params)
        joints = table.joints
        m = object.__new__(cls)
        m.kind = "khalil"
        m.name = _name(name)
        m.table = table
        m.joint_names = tuple(f.name for f in joints)  # type: ignore[misc]
        m.actuated = tuple(bool(f.mu) for f in joints)
        m.revolute = tuple(f.sigma == 0 for f in joints)
        nact = sum(m.actuated)
        if nact == 0:
            raise MechanismError("rows: no joint is actuated; set mu=1 on the active joints",
                                 path=("rows",))
        m.dof = as_int(dof, "dof", path=("dof",)) if dof is not None else nact
        if m.dof != nact:
            raise MechanismError(
                f"dof: the mechanism is meant to have {m.dof} degrees of freedom but "
                f"{nact} joints are actuated (mu=1); actuate exactly one joint per degree of "
                "freedom", path=("dof",)
            )
        ee = table.n if end_effector is None else end_effector
        if isinstance(ee, bool) or not isinstance(ee, (int, np.integer)) or not 1 <= ee <= table.n:
            raise MechanismError(
                f"end_effector: {_show(end_effector)} is not a tree frame; give a frame number in "
                f"1..{table.n}", path=("end_effector",)
            )
        m.end_effector = int(ee)
        if task is None:
            order = ("x", "y", "z", "rx", "ry", "rz") if m.dof >= 6 else ("rz", "x", "y", "z", "rx", "ry")
            task = order[: min(6, m.dof)]
        if isinstance(task, str) or not isinstance(task, (Sequence, np.ndarray)) or len(task) > 6:
            raise MechanismError(f"task: expected a list of components among "
                                 f"{list(TASK_COMPONENTS)}, got {_show(task)}", path=("task",))
        task = tuple(t if isinstance(t, str) else _show(t) for t in task)
        bad = [t for t in task if t not in TASK_COMPONENTS]
        if bad or len(set(task)) != len(task):
            raise MechanismError(
                f"task: {list(task)} must name distinct components among {list(TASK_COMPONENTS)}",
                path=("task",)
            )
        m.task = task
        m.planar = False
        m.redundant = False
        m.reduced = True
        m.legs = ()
        m.platform = None
        m.params = dict(table.params)
        m.home = m._home_vector(home)
        m.limits = m._check_limits(limits)
        m._spec = {
            "kind": "khalil",
            "name": m.name,
            "rows": table.rows_source,
            "loops": table.loops,
            "params": table.params,
            "end_effector": m.end_effector,
            "task": list(task),
            "home": None if m.home is None else m.home.tolist(),
            "dof": m.dof,
            "limits": {k: [None if not np.isfinite(v) else v for v in lim]
                       for k, lim in m.limits.items()},
        }
        m._finish()
        return m

    @classmethod
    def from_legs(
        cls,
        legs: Sequence[Mapping[str, Any] | Leg],
        platform: str = "planar",
        name: str = "legs",
        home: Sequence[float] | None = None,
        params: Mapping[str, Any] | None = None,
        redundant: bool = False,
        reduced: bool = True,
    ) -> Mechanism:
        """A parallel platform from its legs (see :mod:`optkin.mechanism.legs`).

        Parameters
        ----------
        legs : sequence of mappings or Leg
            ``{"type": "RPR", "base": [x, y], "platform": [x, y]}`` (a type of
            :data:`optkin.mechanism.legs.LEG_TYPES` with its keys, e.g. ``lengths`` for
            RRR/RUS legs and ``axis``/``arm`` for RUS legs), a chain
            ``{"screws": ..., "home": ..., "actuated": ...}``, or :class:`Leg` objects
            (:meth:`Leg.from_screws`). Types may be mixed on one platform.
        platform : str
            ``planar`` (x, y, phi), ``planar_point`` (x, y), ``spatial``
            (x, y, z, roll, pitch, yaw) or ``spatial_translational`` (x, y, z).
        home : sequence
            A pose (task coordinates) used as the default guess of :func:`optkin.forward`.
        redundant : bool
            Allow more actuated legs than degrees of freedom (redundant actuation). The
            direct model then solves the overdetermined closure in the least-squares sense
            (Gauss-Newton), and the leg lengths must be consistent for it to close.
        reduced : bool
            Distance legs (RPR, RRR, UPS, RUS, ...) as one row ``|P - C(q_a)|`` = l each
            (default); False: every leg in its chain form (the joint-level closure), which
            gives the same configurations.
        """
        if not isinstance(redundant, (bool, np.bool_, int, np.integer)) or redundant not in (0, 1):
            raise MechanismError(f"redundant: expected True or False, got {_show(redundant)}",
                                 path=("redundant",))
        if params is not None and not isinstance(params, Mapping):
            raise MechanismError(f"params: expected a mapping, got {_show(params)}",
                                 path=("params",))
        if not isinstance(reduced, (bool, np.bool_)):
            raise MechanismError(f"reduced: expected True or False, got {_show(reduced)}",
                                 path=("reduced",))
        legs_t = validate_legs(legs, platform, redundant=bool(redundant))
        if platform == "spatial_translational" and all(
                leg.type in ("RUS", "RSS") for leg in legs_t):
            # a Delta: each forearm is a parallelogram of two S-S rods (Grubler's count;
            # the model keeps the equivalent R-U-S chain), whose spins are idle
            for leg in legs_t:
                object.__setattr__(leg, "inventory", ((1, 3, 3, 3, 3), 3, 2))
        m = object.__new__(cls)
        m.kind = "legs"
        m.name = _name(name)
        m.legs = legs_t
        m.platform = platform
        plat = PLATFORMS[platform]
        dim, coords = plat.space_dim, plat.task
        names, act, rev = [], [], []
        for i, leg in enumerate(legs_t):
            kinds = leg.kinds
            for k, jn in enumerate(leg.joint_names):
                names.append(f"L{i + 1}.{jn}")
                act.append(k in leg.actuated)
                rev.append(kinds[k] == "R")
        if len(set(names)) != len(names):
            raise MechanismError("legs: two joint variables have one name; name the legs' "
                                 "joints differently", path=("legs",))
        m.joint_names = tuple(names)
        m.actuated = tuple(act)
        m.revolute = tuple(rev)
        n_act = int(sum(act))
        m.dof = plat.dof if (bool(redundant) or all(
            leg.distance is not None for leg in legs_t)) else n_act
        m.reduced = bool(reduced)
        m.planar = dim == 2
        m.redundant = bool(redundant)
        m.limits = {}
        m.table = None
        m.end_effector = None
        m.task = coords
        m.params = dict(params or {})
        if home is None:
            m.home = None
        else:
            try:
                m.home = as_vector(home, "home", len(coords), path=("home",))
            except MechanismError:
                raise MechanismError(
                    f"home: expected {len(coords)} finite task coordinates {list(coords)}, got "
                    f"{_show(home)}", path=("home",)
                ) from None
            m.home.setflags(write=False)
        m._spec = {
            "kind": "legs",
            "name": m.name,
            "platform": platform,
            "legs": [leg.to_dict() for leg in legs_t],
            "home": None if m.home is None else m.home.tolist(),
        }
        if m.redundant:  # only then, so that existing keys do not change
            m._spec["redundant"] = True
        if not m.reduced:
            m._spec["reduced"] = False
        m._finish()
        return m

    # ------------------------------------------------------------------ helpers
    def _home_vector(self, home: Any) -> np.ndarray | None:
        if home is None:
            return None
        n = len(self.joint_names)
        if isinstance(home, Mapping):
            unknown = sorted(set(home) - set(self.joint_names), key=str)
            if unknown:
                raise MechanismError(f"home: unknown joint(s) {unknown}; joints: {self.joint_names}",
                                     path=("home", str(unknown[0])))
            vals: Any = [home.get(k, 0.0) for k in self.joint_names]
        else:
            vals = home
        try:
            return as_vector(vals, "home", n, path=("home",))
        except MechanismError:
            raise MechanismError(
                f"home: expected {n} finite joint values {list(self.joint_names)} (a sequence "
                f"or a {{name: value}} table), got {_show(home)}", path=("home",)) from None

    def _check_limits(self, limits: Any) -> dict[str, tuple[float, float]]:
        if not limits:
            return {}
        if not isinstance(limits, Mapping):
            raise MechanismError("limits: expected a mapping joint name -> (lower, upper)",
                                 path=("limits",))
        out: dict[str, tuple[float, float]] = {}
        for name, lim in limits.items():
            if name not in self.joint_names:
                raise MechanismError(
                    f"limits.{name}: unknown joint; joints are {list(self.joint_names)}",
                    path=("limits", str(name))
                )
            where = f"limits.{name}"
            try:
                if isinstance(lim, (str, bytes)) or len(lim) != 2:
                    raise TypeError
                lo, hi = (sign * np.inf if v is None else
                          as_float(v, where, finite=False, path=("limits", name))
                          for sign, v in zip((-1, 1), lim))
            except (TypeError, MechanismError):
                raise MechanismError(
                    f"{where}: expected (lower, upper) numbers or None, got {_show(lim)}",
                    path=("limits", name)
                ) from None
            if not lo < hi:
                raise MechanismError(f"{where}: need lower < upper, got ({lo}, {hi})",
                                     path=("limits", name))
            out[name] = (lo, hi)
        return out

    def within_limits(self, q: Any, tol: float = 1e-9) -> bool:
        """Whether the joint values ``q`` (in ``joint_names`` order) respect :attr:`limits`."""
        limits = getattr(self, "limits", None) or {}
        for i, n in enumerate(self.joint_names):
            if n in limits:
                lo, hi = limits[n]
                if not (lo - tol <= q[i] <= hi + tol):
                    return False
        return True

    def _finish(self) -> None:
        if getattr(self, "home", None) is not None:
            self.home.setflags(write=False)
        if self.kind == "khalil":
            frames = self.table.frames
            topo: tuple = ("khalil", tuple((f.a, f.mu, f.sigma, f.name) for f in frames),
                           self.table.loops, self.end_effector)
            geo = np.array([[f.gamma, f.b, f.alpha, f.d, f.theta, f.r] for f in frames],
                           dtype=float).ravel()
        else:
            topo = ("legs", self.platform, tuple(leg.topology for leg in self.legs),
                    self.redundant, self.reduced)
            geo = np.concatenate([leg.geometry() for leg in self.legs])
        geo.setflags(write=False)
        object.__setattr__(self, "_topology", topo)
        object.__setattr__(self, "_geometry", geo)
        blob = json.dumps(jsonable(self._spec, keep_nonfinite=True), sort_keys=True,
                          default=repr).encode()
        object.__setattr__(self, "_key", hashlib.sha256(blob).hexdigest()[:16])

    # ------------------------------------------------------------------ views
    @property
    def key(self) -> str:
        """A content hash of the whole description (topology and numbers)."""
        return self._key

    @property
    def topology(self) -> tuple:
        """What the compiled code depends on (hashable): joint types, leg structure,
        actuated joints, the Khalil table's structure; not the numbers. Mechanisms of one
        topology share their compiled model and differ only in :attr:`geometry`."""
        return self._topology

    @property
    def geometry(self) -> np.ndarray:
        """The numbers of the description as one read-only vector (names:
        :attr:`geometry_names`): Khalil (gamma, b, alpha, d, theta, r) per frame; legs
        their screws, home poses, platform points and distance forms."""
        return self._geometry

    @property
    def geometry_names(self) -> tuple[str, ...]:
        if self.kind == "khalil":
            return tuple(f"rows[{f.j - 1}].{c}" for f in self.table.frames
                         for c in ("gamma", "b", "alpha", "d", "theta", "r"))
        return tuple(f"legs[{i}].{n}" for i, leg in enumerate(self.legs)
                     for n in leg.geometry_names())

    @property
    def passive_revolute_screws(self) -> tuple[tuple[int, ...], ...]:
        """Where the screws (w, v) of revolute joints whose angle is an unknown of the
        closure sit in :attr:`geometry` (six indices each; none for a Khalil table, whose
        rows are rigid by construction). A rigid screw has w . w = 1 and w . v = 0; the
        homotopy keeps its random start geometry so."""
        if self.kind == "khalil":
            return ()
        out, at = [], 0
        for leg in self.legs:
            S = np.asarray(leg.screws, dtype=float)
            unknown = len(S) - leg.n_reported  # (reported variables are no unknowns)
            out += [tuple(range(at + 6 * k, at + 6 * k + 6)) for k in range(unknown)
                    if k not in leg.actuated and np.any(S[k, :3])]
            at += len(leg.geometry_names())
        return tuple(out)

    @property
    def active_names(self) -> tuple[str, ...]:
        return tuple(n for n, a in zip(self.joint_names, self.actuated) if a)

    @property
    def n_actuated(self) -> int:
        """The number of actuated joints (= dof unless :attr:`redundant`)."""
        return int(sum(self.actuated))

    @property
    def active_index(self) -> np.ndarray:
        return np.flatnonzero(self.actuated)

    @property
    def cut_names(self) -> tuple[str, ...]:
        """Cut joint variables q_c ([7.7]); empty for leg-described platforms."""
        if self.kind != "khalil":
            return ()
        cut = set(self.table.cut_frames)
        return tuple(f.name for f in self.table.joints if f.j in cut)  # type: ignore[misc]

    @property
    def passive_names(self) -> tuple[str, ...]:
        """Passive joints of the tree, q_p ([7.7])."""
        cut = set(self.cut_names)
        return tuple(n for n, a in zip(self.joint_names, self.actuated) if not a and n not in cut)

    @property
    def task_dim(self) -> int:
        return len(self.task)

    @property
    def n_loops(self) -> int:
        return self.table.loops if self.kind == "khalil" else len(self.legs) - 1

    def to_dict(self) -> dict[str, Any]:
        """The description as JSON-ready data (echoed in problem results; unbounded joint
        limits stay +-inf so that it round-trips)."""
        return jsonable(self._spec, keep_nonfinite=True)

    def __repr__(self) -> str:
        return (
            f"Mechanism({self.name!r}, {self.kind}, dof={self.dof}, "
            f"joints={len(self.joint_names)}, active={list(self.active_names)})"
        )

    def __reduce__(self):
        spec = self._spec
        if spec["kind"] == "khalil":
            return (
                _rebuild_khalil,
                (spec["rows"], spec["loops"], spec["params"], spec["end_effector"], spec["name"],
                 spec["task"], None if self.home is None else self.home.tolist(), self.dof,
                 spec.get("limits")),
            )
        return (_rebuild_legs, (spec["legs"], spec["platform"], spec["name"], spec["home"],
                                spec.get("redundant", False), spec.get("reduced", True)))



def _name(name: Any) -> str:
    """A mechanism name: a string of sensible length."""
    if not isinstance(name, str) or len(name) > 200:
        raise MechanismError(f"name: expected a short string, got {_show(name)}", path=("name",))
    return name


def _rebuild_khalil(rows, loops, params, ee, name, task, home, dof, limits=None):
    return Mechanism.from_khalil(rows, loops, params, ee, name, task, home, dof, limits)


def _rebuild_legs(legs, platform, name, home, redundant=False, reduced=True):
    return Mechanism.from_legs(legs, platform, name, home, redundant=redundant, reduced=reduced)
