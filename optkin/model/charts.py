"""Closed-form charts of planar distance-leg mechanisms.

A planar mechanism whose legs are all distance constraints ``|P_i - C_i(q_a,i)| = r_i``
(Özgören: one equation per leg; :meth:`optkin.model.core.Model.distance_form`), one
actuator per leg, has a closed-form chart of its configuration manifold: the platform
coordinates x, with each leg's actuated value from its closed-form inverse (the model's
:class:`~optkin.model.inverse.ClosedPart`, one or two branches per leg). Its loci are
circles and lines: a leg's platform point with its actuator fixed lies on the circle
``|P - C(q_a)| = r``; a leg's serial singularities (B_jj = 0) are the points ``P = C +- r n``
with ``n`` normal to the centre's velocity dC/dq_a. The continuation
(:mod:`optkin.analysis.continuation`) seeds from this chart, and aspects and workspaces
(:mod:`optkin.analysis.aspects`) label and project with it.

:func:`planar_chart` returns the chart of a model, or None when the model has none.
:func:`translational_chart` returns the same chart for a spatial platform that only
translates (the Delta: x, y, z), whose legs are distance constraints too (spheres instead
of circles); only its leg inverses, posture combinations and reach box are used (the
sections of :func:`optkin.singular_surfaces` at fixed z), not the planar loci. Its
Functions are built once per topology (:meth:`Model.cached`); the numbers are the model's
geometry.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from . import compiled as cc

__all__ = ["PlanarChart", "planar_chart", "translational_chart"]

#: Points per evaluation of a chart Function (memory stays bounded for large grids).
CHUNK = 2048


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _chunked(model: Any, key: str, X: np.ndarray) -> list[np.ndarray]:
    """Outputs of the chart Function ``key`` (x, p) at the rows of X, as (N, rows) arrays:
    mapped over at most CHUNK points at a time (memory stays bounded), the maps built once
    per topology for chunks of 2^k points."""
    N = X.shape[0]
    # compiled in the background once per topology, the interpreted Function answering
    # meanwhile (a 3-RRR's leg inverses: 11 of the 81 s of its 3-D aspects interpreted)
    late = model.cached(("planar_chart", key), lambda: cc.LateCompiled(
        f"chart:{model.topology.key}:{key}", _dense(_build(model, key))))
    late.poll()
    f = late.f
    n = 1
    while n < min(N, CHUNK):
        n *= 2
    # through preallocated buffers (a numpy call of a Function costs 0.1-0.4 ms); one
    # FastFn per topology, size and build (the geometry an input), its calls serialised
    # (its buffers are shared)
    fm, lock = model.cached(("planar_chart", key, n, f.is_a("External")), lambda: (
        cc.FastFn(cc.map_shared(f, f"{f.name()}_{n}", n, [1])), threading.Lock()))
    p = np.asarray(model.p, dtype=float)
    rows = [f.size1_out(j) for j in range(f.n_out())]
    outs: list[list[np.ndarray]] = [[] for _ in range(f.n_out())]
    for s in range(0, N, n):
        blk = X[s:s + n]
        k = blk.shape[0]
        if k < n:
            blk = np.vstack([blk, np.repeat(blk[-1:], n - k, axis=0)])
        with lock:
            res = fm(np.ascontiguousarray(blk).ravel(), p)
            for j, r in enumerate(res):  # column-major (rows, n): row i of the block
                outs[j].append(r.reshape(n, rows[j])[:k].copy())
    return [np.vstack(o) if o else np.zeros((0, f.size1_out(j)))
            for j, o in enumerate(outs)]


@dataclass(frozen=True)
class PlanarChart:
    """The closed-form chart of a planar distance-leg mechanism (see the module docstring).

    Attributes
    ----------
    model : Model
    n_legs : int
        Legs (= actuated joints, leg k drives q_a,k).
    branches : tuple of int
        Closed-form branches of each leg's inverse (its postures).
    qa_angle : ndarray (na,) of bool
        Which actuated joints are angles (periodic).
    length_actuated : ndarray (na,) of bool
        The actuated joint is the leg's distance (B_jj = -1: no serial singularity).
    translation : tuple of int
        The platform coordinates that translate it (x, y).
    orientation : tuple of int
        The platform coordinates that turn it (empty for a point platform).
    """

    model: Any
    n_legs: int
    branches: tuple[int, ...]
    qa_angle: np.ndarray
    length_actuated: np.ndarray
    translation: tuple[int, ...]
    orientation: tuple[int, ...]

    # ------------------------------------------------------------------ leg inverses
    def leg_qa(self, X: np.ndarray) -> list[list[tuple[np.ndarray, np.ndarray]]]:
        """Per leg, per branch: (q_a values (N,), valid (N,)) with the platform at the
        coordinates X (N, n_platform); angles wrapped to [-pi, pi)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        QA, V = _chunked(self.model, "leg_qa", X)
        out, k = [], 0
        for leg, b in enumerate(self.branches):
            per = []
            for _ in range(b):
                q = QA[:, k]
                if self.qa_angle[leg]:
                    q = _wrap(q)
                per.append((q, (V[:, k] > 0.5) & np.isfinite(q)))
                k += 1
            out.append(per)
        return out

    def full_points(self, X: np.ndarray, fixed_leg: int | None = None,
                    fixed_val: np.ndarray | None = None
                    ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Full points V = (q_a, x) (N, na + nx) and their validity for every posture
        combination of the legs, one combination at a time (leg ``fixed_leg``, if given,
        keeps the actuated values ``fixed_val``)."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        per_leg = self.leg_qa(X)
        if fixed_leg is not None:
            per_leg[fixed_leg] = [(np.broadcast_to(np.asarray(fixed_val, dtype=float),
                                                   (len(X),)),
                                   np.ones(len(X), dtype=bool))]
        for combo in itertools.product(*per_leg):
            Q = np.stack([c[0] for c in combo], 1)
            ok = np.logical_and.reduce([c[1] for c in combo])
            yield np.hstack([Q, X]), ok

    @property
    def n_combos(self) -> int:
        """Posture combinations of the legs."""
        return int(np.prod(self.branches))

    # ------------------------------------------------------------------ the platform
    def platform_points(self, X: np.ndarray) -> np.ndarray:
        """Every leg's platform point (N, n_legs, 2) for platform coordinates X."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        (P,) = _chunked(self.model, "points", X)
        return P.reshape(len(X), self.n_legs, 3)[:, :, :2]

    def place(self, leg: int, P: np.ndarray, X: np.ndarray) -> np.ndarray:
        """X with its translation set so that leg ``leg``'s platform point is at P (N, 2),
        the orientation coordinates of X kept."""
        X = np.array(np.atleast_2d(X), dtype=float)
        t = list(self.translation)
        X[:, t] = 0.0
        P0 = self.platform_points(X)[:, leg]
        X[:, t] = np.asarray(P, dtype=float) - P0
        return X

    # ------------------------------------------------------------------ loci of a leg
    def centres_radii(self, QA: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """C (N, n_legs, 2) and r (N, n_legs) for rows of actuated values QA (N, na)."""
        QA = np.atleast_2d(np.asarray(QA, dtype=float))
        C, r = _chunked(self.model, "centres", QA)
        return C.reshape(len(QA), self.n_legs, 3)[:, :, :2], r

    def circle(self, leg: int, value: float, th: np.ndarray) -> np.ndarray:
        """Points (m, 2) of leg ``leg``'s platform point with its actuator at ``value``:
        the circle |P - C| = r, at the angles ``th``."""
        qa = np.zeros((1, self.model.na))
        qa[0, leg] = value
        C, r = self.centres_radii(qa)
        return C[0, leg] + r[0, leg] * np.stack([np.cos(th), np.sin(th)], 1)

    def serial_loci(self, leg: int, values: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Leg ``leg``'s serial singularities (B_jj = 0) with its actuator at ``values``
        (m,): P = C + r n and P = C - r n, n normal to dC/dq_a, each as (points (k, 2), the
        matching actuator values (k,)); none when the actuator is the distance itself."""
        if self.length_actuated[leg]:
            return []
        values = np.asarray(values, dtype=float)
        QA = np.zeros((len(values), self.model.na))
        QA[:, leg] = values
        C, r, dC = _chunked(self.model, "centre_rates", QA)
        C = C.reshape(len(QA), self.n_legs, 3)[:, leg, :2]
        dC = dC.reshape(len(QA), self.n_legs, 3)[:, leg, :2]
        rr = r[:, leg]
        nd = np.linalg.norm(dC, axis=1)
        ok = nd > 0
        n = np.stack([dC[ok, 1], -dC[ok, 0]], 1) / nd[ok, None]
        C, rr = C[ok], rr[ok]
        return [(C + rr[:, None] * n, values[ok]), (C - rr[:, None] * n, values[ok])]

    def actuator_range(self, j: int) -> tuple[float, float]:
        """A range of actuator ``j`` for grids: an angle's turn, else 0 to twice the
        mechanism's size for a leg length, +- that for a slider moving the centre."""
        L = float(self.model.length)
        if self.qa_angle[j]:
            return (-np.pi, np.pi)
        if self.length_actuated[j]:
            return (0.0, 2.0 * L)
        return (-2.0 * L, 2.0 * L)

    def reach_box(self) -> np.ndarray:
        """A box [[lo, hi], ...] of the platform's translation coordinates (x, y; x, y, z
        for a translational spatial platform) that every closed configuration lies in
        (each leg's platform point within reach of its base: a disc or a ball, plus the
        platform point's distance from the platform origin)."""
        d = len(self.translation)
        cs, rs = _reach_discs(self.model, d)
        lo = np.max(cs - rs[:, None], axis=0)
        hi = np.min(cs + rs[:, None], axis=0)
        return np.stack([lo, hi], 1)

    # ------------------------------------------------------------------ point platforms
    @property
    def two_leg_point(self) -> bool:
        """A point platform on two legs (the five-bar): its direct kinematics is a circle
        intersection (:meth:`point_fk`)."""
        return self.n_legs == 2 and not self.orientation

    def point_fk(self, QA: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Closed-form direct kinematics of a two-leg point platform at actuated values QA
        (N, 2): the platform coordinates (N, 2) and validity of both assembly modes (the
        intersections of the legs' circles about C_i - b_i)."""
        QA = np.atleast_2d(np.asarray(QA, dtype=float))
        C, r = self.centres_radii(QA)
        b = self.platform_points(np.zeros((1, self.model.nx)))[0]  # origin at 0: P_i = b_i
        c0, c1 = C[:, 0] - b[0], C[:, 1] - b[1]
        r0, r1 = r[:, 0], r[:, 1]
        dv = c1 - c0
        dd = np.hypot(dv[:, 0], dv[:, 1])
        with np.errstate(divide="ignore", invalid="ignore"):
            a = (r0**2 - r1**2 + dd**2) / (2 * dd)
            h2 = r0**2 - a**2
            ok = (h2 >= 0) & (dd > 1e-12)
            h = np.sqrt(np.where(ok, h2, 0))
            e = dv / dd[:, None]
        m = c0 + a[:, None] * e
        nrm = np.stack([-e[:, 1], e[:, 0]], 1)
        return [(m + h[:, None] * nrm, ok), (m - h[:, None] * nrm, ok)]


def translational_chart(model: Any) -> PlanarChart | None:
    """The closed-form chart of a spatial platform that only translates (x, y, z), or
    None: legs that are all distance legs with one actuator each and closed-form inverses,
    three closure rows, the three translations the only unknowns (the Delta). Its planar
    loci (circles, serial loci, placing a leg's point) do not apply."""
    return _distance_chart(model, 3)


def planar_chart(model: Any) -> PlanarChart | None:
    """The closed-form chart of ``model``, or None: it needs a planar platform whose legs
    are all distance legs in the reduced form with one actuator each (fully parallel), as
    many closure rows as unknowns, and the platform coordinates as the only unknowns."""
    return _distance_chart(model, 2)


def _distance_chart(model: Any, space_dim: int) -> PlanarChart | None:
    """The chart of a platform moving in ``space_dim`` dimensions whose legs are all
    distance legs with closed-form inverses, one actuator each, the platform coordinates
    the only unknowns, as many closure rows: two translations (and any angles) in the
    plane, three translations and no angle in space; else None."""
    plat = model.platform
    if plat is None or plat.space_dim != space_dim or not model.fully_parallel:
        return None
    form = model.distance_form()
    if form is None or model.nx != model.n_platform or model.m != model.nx:
        return None
    npl = model.n_platform
    ang = tuple(i for i in range(npl) if model.x_angle[i])
    trans = tuple(i for i in range(npl) if not model.x_angle[i])
    if len(trans) != space_dim or (space_dim == 3 and ang):
        return None
    from .inverse import ClosedPart

    parts = model.inverse_parts()
    if not all(isinstance(pt, ClosedPart) for pt in parts):
        return None
    mech = model.mech
    return PlanarChart(model=model, n_legs=len(parts),
                       branches=tuple(int(pt.branches) for pt in parts),
                       qa_angle=np.array([bool(mech.revolute[i]) for i in mech.active_index],
                                         dtype=bool),
                       length_actuated=np.array(form.length_actuated),
                       translation=trans, orientation=ang)


# --------------------------------------------------------------------------------------
# per-topology Functions


def _dense(f: ca.Function) -> ca.Function:
    """``f`` with dense outputs (read straight from the buffers of a FastFn)."""
    ins = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
    return ca.Function(f.name(), ins, [ca.densify(o) for o in f.call(ins)])


def _build(model: Any, key: str) -> ca.Function:
    st = model.structure
    qa, x, p = st.qa, st.x, st.p
    if key == "leg_qa":
        from .inverse import ClosedPart

        xp = ca.SX.sym("xp", model.n_platform)
        QA, V = [], []
        for part in model.inverse_parts():
            assert isinstance(part, ClosedPart)
            qa_b, _, v_b = part.fn(xp, p)
            QA.append(qa_b)
            V.append(v_b)
        return ca.Function("chart_leg_qa", [xp, p], [ca.vertcat(*QA), ca.vertcat(*V)])
    if key == "points":
        P = ca.vertcat(*[d[1] for d in st.distance])
        return ca.Function("chart_points", [x, p], [P])
    if key == "centres":
        C = ca.vertcat(*[d[0] for d in st.distance])
        r = ca.vertcat(*[d[2] for d in st.distance])
        return ca.Function("chart_centres", [qa, p], [C, r])
    if key == "centre_rates":
        Cs = [d[0] for d in st.distance]
        C = ca.vertcat(*Cs)
        r = ca.vertcat(*[d[2] for d in st.distance])
        dC = ca.vertcat(*[ca.jacobian(c, qa[i]) for i, c in enumerate(Cs)])
        return ca.Function("chart_centre_rates", [qa, p], [C, r, dC])
    raise KeyError(key)


def _reach_discs(model: Any, dims: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Per leg, a disc (centre (2,), radius) holding every position of the platform
    origin's translation, from the leg's distance form: the centre C moves on a circle
    about the driving revolute's axis (radius |C - axis| + r), along a slider (within twice
    the mechanism's size), or stays (the leg length up to twice the size); the radius
    grows by the platform point's distance from the platform origin. ``dims=3``: balls
    (centre (3,)) for a spatial platform."""
    L = float(model.length)
    cs, rs = [], []
    for leg in model.mech.legs:
        d = leg.distance
        c0 = np.asarray(d.centre, dtype=float)
        b = float(np.linalg.norm(np.asarray(leg.platform_point, dtype=float)[:dims]))
        if d.length is None:  # the actuated joint is the distance
            centre, reach = c0, 2.0 * L
        elif leg.kinds[0] == "R" and d.driver > 0:
            S = np.asarray(leg.screws[0], dtype=float)
            w, v = S[:3], S[3:]
            a = np.cross(w, v)  # the axis' point nearest the origin
            centre = a + w * float(w @ (c0 - a))
            reach = float(np.linalg.norm(c0 - centre)) + float(d.length)
        else:  # a slider moves the centre
            centre, reach = c0, 2.0 * L + float(d.length)
        cs.append(centre[:dims])
        rs.append(reach + b)
    return np.array(cs), np.array(rs)
