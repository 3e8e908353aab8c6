"""Measures as objects of a design problem: objectives, constraints, atlas columns.

A :class:`Measure` is evaluated over many designs of a :class:`~optkin.design.Family` at
once (``values(family, Z)``); comparing it with a number makes a :class:`Constraint`
(``GCI(...) >= 0.5``, ``Dimension("l1") <= 2``), and :class:`Maximize` / :class:`Minimize`
make an objective, in cvxpy's manner. Smooth measures over fixed nodes (:class:`GCI`,
:class:`MinConditioning`, :class:`Dimension`) also give a CasADi expression of the free
design variables for IPOPT (``symbolic``); the others (:class:`LargestInscribed`,
:class:`AspectArea`) are evaluated design by design and optimized by the global strategy.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .._checks import as_float, show
from ..errors import MechanismError
from ._evaluator import Evaluator
from .measures import Box, Disc, _box_arg, _mode_arg, _probe, aspect_integral, largest_inscribed

__all__ = ["Measure", "Constraint", "Maximize", "Minimize", "GCI", "MinConditioning", "JointRange",
           "LargestInscribed", "AspectArea", "Dimension"]


class Measure:
    """A scalar measure of a design (see the module docstring)."""

    name = "measure"
    smooth = False

    def values(self, family: Any, Z: np.ndarray) -> np.ndarray:  # pragma: no cover
        raise NotImplementedError

    def search_values(self, family: Any, Z: np.ndarray) -> np.ndarray:
        """Values for the global search (cheaper estimates where a measure has them)."""
        return self.values(family, Z)

    def symbolic(self, family: Any, z: ca.MX, nodes: Any = None) -> ca.MX:
        raise MechanismError(f"{self.name} is not smooth in the dimensions; optimize it with "
                             "method='global'")

    def __ge__(self, other: Any) -> Constraint:
        return Constraint(self, ">=", as_float(other, f"{self.name} >= bound"))

    def __le__(self, other: Any) -> Constraint:
        return Constraint(self, "<=", as_float(other, f"{self.name} <= bound"))

    def __repr__(self) -> str:
        return self.name


@dataclass
class Constraint:
    """``measure >= bound`` or ``measure <= bound``."""

    measure: Measure
    sense: str
    bound: float

    def violation(self, v: np.ndarray) -> np.ndarray:
        """How far values ``v`` are from satisfying it (0 where they do; NaN counts as
        violated by 1)."""
        d = self.bound - v if self.sense == ">=" else v - self.bound
        return np.where(np.isfinite(d), np.maximum(d, 0.0), 1.0)

    def __repr__(self) -> str:
        return f"{self.measure!r} {self.sense} {self.bound:g}"


@dataclass
class Maximize:
    measure: Measure
    sign: float = field(default=-1.0, init=False)   # minimised: sign * value


@dataclass
class Minimize:
    measure: Measure
    sign: float = field(default=1.0, init=False)


# --------------------------------------------------------------------------- helpers
def _evaluator(family: Any) -> Evaluator:
    return family.model0.cached("design_evaluator", lambda: Evaluator(family.model0))


def _batch(family: Any, Z: np.ndarray, T: np.ndarray, mode: tuple[int, ...],
           length: float) -> dict[str, np.ndarray]:
    """Evaluate every design (rows of Z) at every task point (rows of T): arrays (nZ, nT)."""
    ev = _evaluator(family)
    Z = np.atleast_2d(np.asarray(Z, dtype=float))
    p0, M, D = family.geometry(Z)
    nZ, nT = len(Z), len(T)
    if T.ndim == 3:   # one node set per design
        nT = T.shape[1]
        TT = T.reshape(-1, T.shape[2])
    else:
        TT = np.tile(T, (nZ, 1))
    o = ev.evaluate(TT, mode, p0, M, np.repeat(D, nT, axis=0), length)
    return {k: v.reshape((nZ, nT) + v.shape[1:]) for k, v in o.items()}


def _sym_points(family: Any, T: np.ndarray, mode: tuple[int, ...], length: float,
                z: ca.MX) -> tuple[ca.MX, ca.MX, ca.MX]:
    """(1/kappa (1, N), det A (1, N), reach margins (na, N)) at the task points T as CasADi
    expressions of the free design variables z (an affine family)."""
    if not family.affine:
        raise MechanismError("the IPOPT path needs a family whose geometry is affine in its "
                             "dimensions; use method='global'")
    ev = _evaluator(family)
    N = len(T)
    f = ev._point.map(f"design_sym_{N}", "serial", N, [1, 2, 3], [])
    p = ca.DM(family.p0) + ca.mtimes(ca.DM(family.M), z)
    qa, ok, det, ik, jinv, reach = f(ca.DM(T.T), p, ca.DM(list(mode)), length)
    return ik, det, reach


class _RegionMeasure(Measure):
    def __init__(self, region: Any, mode: Any, fixed: Mapping[str, float] | None,
                 length: float, order: int) -> None:
        if not (isinstance(region, (Disc, Box)) or callable(region)):
            raise MechanismError(f"{type(self).__name__}: region must be a Disc or a Box (or a "
                                 "function of the dimensions returning one), got "
                                 f"{type(region).__name__}")
        self.region, self.mode, self.fixed = region, mode, dict(fixed or {})
        self.length, self.order = float(length), int(order)
        # a region that moves with the design is not smooth for IPOPT's fixed nodes
        self.smooth = isinstance(region, (Disc, Box))

    def region_of(self, family: Any, z: Any) -> Disc | Box:
        if isinstance(self.region, (Disc, Box)):
            return self.region
        r = self.region(family.dims(z))
        if not isinstance(r, (Disc, Box)):
            raise MechanismError(f"{type(self).__name__}: the region function returned "
                                 f"{type(r).__name__}, not a Disc or a Box")
        return r

    def _plane(self, family: Any, mode: tuple[int, ...]) -> Any:
        return _probe(None, mode, self.fixed, family=family, z=family.z0)

    def _setup(self, family: Any, Z: Any = None
               ) -> tuple[tuple[int, ...], np.ndarray, np.ndarray]:
        """(mode, task nodes (nT, nt) or (nZ, nT, nt) for a moving region, weights)."""
        mode = _mode_arg(family.model0, self.mode)
        pr = self._plane(family, mode)
        if isinstance(self.region, (Disc, Box)) or Z is None:
            P, W = self.region_of(family, family.z0).nodes(self.order)
            return mode, pr.task(P), W
        Ts, W = [], None
        for z in np.atleast_2d(Z):
            P, W = self.region_of(family, z).nodes(self.order)
            Ts.append(pr.task(P))
        return mode, np.stack(Ts), W

    boundary = 96

    def points(self, family: Any, dense: int = 1, z: Any = None
               ) -> tuple[tuple[int, ...], np.ndarray]:
        mode = _mode_arg(family.model0, self.mode)
        reg = self.region_of(family, family.z0 if z is None else z)
        P, _ = reg.nodes(self.order * dense)
        B = reg.boundary(self.boundary * dense)
        c = np.mean(B, axis=0, keepdims=True) if isinstance(reg, Box) else \
            np.array([reg.centre])
        return mode, self._plane(family, mode).task(np.vstack([c, P, B]))

    def _at_points(self, family: Any, Z: np.ndarray, dense: int) -> dict[str, np.ndarray]:
        """The evaluation (arrays (nZ, nT)) at the region's centre, nodes and boundary
        (:meth:`points`), for every design of Z."""
        Z = np.atleast_2d(Z)
        if isinstance(self.region, (Disc, Box)):
            mode, T = self.points(family, dense)
        else:
            Ts = [self.points(family, dense, z) for z in Z]
            mode, T = Ts[0][0], np.stack([t for _, t in Ts])
        return _batch(family, Z, T, mode, self.length)


class GCI(_RegionMeasure):
    """The global conditioning index over a prescribed disc or box (area-weighted mean of
    1/kappa, Gauss quadrature; unreachable nodes count 0): see
    :func:`optkin.design.gci`."""

    name = "GCI"

    def __init__(self, region: Disc | Box, mode: Any = None,
                 fixed: Mapping[str, float] | None = None, length: float = 1.0,
                 order: int = 12) -> None:
        super().__init__(region, mode, fixed, length, order)

    def values(self, family: Any, Z: np.ndarray) -> np.ndarray:
        mode, T, W = self._setup(family, Z)
        o = _batch(family, Z, T, mode, self.length)
        ik = np.nan_to_num(o["inv_kappa"])
        return ik @ W / W.sum()

    def symbolic(self, family: Any, z: ca.MX, nodes: Any = None) -> ca.MX:
        mode, T, W = self._setup(family)
        ik, _, _ = _sym_points(family, T, mode, self.length, z)
        return ca.mtimes(ik, ca.DM(W)) / float(W.sum())


class MinConditioning(_RegionMeasure):
    """The least 1/kappa over a disc or box (its Gauss nodes and ``boundary`` points on its
    edge; unreachable points and a change of the sign of det A count 0). As a constraint
    (``MinConditioning(...) >= gamma``) the IPOPT path imposes it at sample nodes and
    refines them by an exchange step (verify on a denser set, add the violated points)."""

    name = "min 1/kappa"

    def __init__(self, region: Disc | Box, mode: Any = None,
                 fixed: Mapping[str, float] | None = None, length: float = 1.0,
                 order: int = 12, boundary: int = 96) -> None:
        super().__init__(region, mode, fixed, length, order)
        self.boundary = int(boundary)

    def values(self, family: Any, Z: np.ndarray, dense: int = 1) -> np.ndarray:
        o = self._at_points(family, Z, dense)
        ik = np.nan_to_num(o["inv_kappa"])
        s = np.sign(o["raw_det"][:, :1])
        same = np.sign(o["raw_det"]) == s
        ik = np.where(same & o["valid"], ik, 0.0)
        return ik.min(axis=1)


class JointRange(_RegionMeasure):
    """The actuator travel needed to cover a disc or box in a working mode: the largest,
    over the actuated joints, of max - min of the joint's value over the region's nodes
    and boundary (angles unwrapped about their value at the region's centre; a node out of
    reach makes it infinite). ``joint`` names one actuated joint instead."""

    name = "joint range"

    def __init__(self, region: Any, mode: Any = None,
                 fixed: Mapping[str, float] | None = None, order: int = 12,
                 boundary: int = 96, joint: str | None = None) -> None:
        super().__init__(region, mode, fixed, 1.0, order)
        self.boundary, self.joint = int(boundary), joint
        if joint is not None:
            self.name = f"range of {joint}"

    def values(self, family: Any, Z: np.ndarray, dense: int = 1) -> np.ndarray:
        o = self._at_points(family, Z, dense)
        qa = o["qa"]                                       # (nZ, nT, na)
        mech = family.model0.mech
        ang = np.array([bool(mech.revolute[i]) for i in mech.active_index])
        rel = qa - qa[:, :1]
        rel[..., ang] = (rel[..., ang] + np.pi) % (2 * np.pi) - np.pi
        span = rel.max(axis=1) - rel.min(axis=1)           # (nZ, na)
        span = np.where(o["valid"].all(axis=1)[:, None], span, np.inf)
        if self.joint is not None:
            names = list(mech.active_names)
            if self.joint not in names:
                raise MechanismError(f"JointRange: {show(self.joint)} is not an actuated joint; "
                                     f"known: {', '.join(names)}")
            return span[:, names.index(self.joint)]
        return span.max(axis=1)


class LargestInscribed(Measure):
    """The largest singularity-free disc (radius) or square (half side) of one working mode
    and aspect, with conditioning floor and limits.

    :func:`optkin.design.largest_inscribed` per design (not smooth in the dimensions)."""

    name = "largest inscribed"

    def __init__(self, mode: Any = None, shape: str = "disc", centre: Any = None,
                 line: Any = None, fixed: Mapping[str, float] | None = None,
                 limits: Mapping[str, Any] | None = None, gamma: float = 0.0,
                 length: float = 1.0, bounds: Any = None, rays: int = 64,
                 steps: int = 48, aspect: Any = (1.0, 1.0)) -> None:
        self.kw = dict(mode=mode, shape=shape, centre=centre, line=line, fixed=fixed,
                       limits=limits, gamma=gamma, length=length, bounds=bounds, rays=rays,
                       steps=steps, aspect=aspect)
        self.name = f"largest inscribed {shape}"

    def result(self, family: Any, z: Any, **over: Any) -> Any:
        kw = dict(self.kw)
        kw.update(over)
        line = kw.pop("line")
        if callable(line):
            line = line(family.dims(z))
        centre = kw.pop("centre")
        if callable(centre):
            centre = centre(family.dims(z))
        return largest_inscribed(None, line=line, centre=centre, family=family, z=z, **kw)

    def values(self, family: Any, Z: np.ndarray, exact: bool = True) -> np.ndarray:
        Z = np.atleast_2d(Z)
        return np.array([self.result(family, z, exact=exact).size for z in Z])

    def search_values(self, family: Any, Z: np.ndarray) -> np.ndarray:
        """Quick estimates for the global search (:func:`largest_inscribed`'s
        ``exact=False``)."""
        return self.values(family, Z, exact=False)


class AspectArea(Measure):
    """The area of the aspect containing ``seed`` (a point, or a function of the design's
    dimensions returning one) within ``bounds``: :func:`optkin.design.area`."""

    name = "aspect area"

    def __init__(self, seed: Any, mode: Any = None, fixed: Mapping[str, float] | None = None,
                 limits: Mapping[str, Any] | None = None, gamma: float = 0.0,
                 length: float = 1.0, bounds: Any = None, tol: float = 1e-6) -> None:
        self.seed, self.mode, self.fixed, self.limits = seed, mode, fixed, limits
        self.gamma, self.length, self.bounds, self.tol = gamma, length, bounds, tol

    def values(self, family: Any, Z: np.ndarray) -> np.ndarray:
        out = []
        for z in np.atleast_2d(Z):
            pr = _probe(None, self.mode, self.fixed, self.limits, self.gamma, self.length,
                        family, z)
            seed = self.seed(family.dims(z)) if callable(self.seed) else self.seed
            b = self.bounds(family.dims(z)) if callable(self.bounds) else self.bounds
            A, _, _, _ = aspect_integral(pr, np.asarray(seed, dtype=float),
                                         None if b is None else _box_arg(b), tol=self.tol)
            out.append(A)
        return np.array(out)


class Dimension(Measure):
    """A design variable's value (after the equalities), or a linear combination
    ``Dimension({"l1": 1, "l2": 1})``."""

    smooth = True

    def __init__(self, which: str | Mapping[str, float]) -> None:
        self.coef = {which: 1.0} if isinstance(which, str) else dict(which)
        self.name = " + ".join(f"{c:g} {k}" for k, c in self.coef.items())

    def _vec(self, family: Any) -> np.ndarray:
        c = np.zeros(len(family.names))
        for k, v in self.coef.items():
            if k not in family.names and k not in family.fixed:
                raise MechanismError(f"Dimension: {show(k)} is not a design variable; known: "
                                     f"{', '.join(family.names)}")
            if k in family.names:
                c[family.names.index(k)] = v
        return c

    def _const(self, family: Any) -> float:
        return float(sum(v * float(family.fixed[k]) for k, v in self.coef.items()
                         if k in family.fixed))

    def values(self, family: Any, Z: np.ndarray) -> np.ndarray:
        return family.full(np.atleast_2d(Z)) @ self._vec(family) + self._const(family)

    def symbolic(self, family: Any, z: ca.MX, nodes: Any = None) -> ca.MX:
        A, b = family.full_affine()
        c = self._vec(family)
        return ca.mtimes(ca.DM(c @ A).T, z) + float(c @ b) + self._const(family)

