"""What the enumeration of assembly modes needs from a model, written once per structure.

:func:`optkin.assembly_modes` (:mod:`optkin.solvers.enumerate`) draws starting points and
compares solutions through this module and never looks at the kind of description:

* :func:`layout`: which unknowns identify an assembly mode (the platform coordinates of a
  leg mechanism, whose legs' passive joints are postures of the legs, not other modes;
  every unknown of a Khalil table), which are angles, which form a unit quaternion (a
  quaternion and its negative are one rotation), and how each unknown is drawn: angles
  uniformly, quaternions uniformly on SO(3) (Shoemake), the platform's origin in its reach
  box, Khalil lengths in a box of the mechanism's size, the variables of legs in chain
  form from the sampled pose (:func:`seed_legs`);
* :func:`reach_box`: where the platform's origin can be for given actuated values. Every
  leg confines it to a ball: a distance leg |P - C(q_a)| = r puts P in the ball of radius
  r about C; a chain is followed from its end to the base, each joint mapping the ball of
  its end point to a ball that holds every image (an actuated joint moves it by its known
  value, a passive revolute spins it about the axis: centre to the axis, radius grown by
  the centre's distance from it; a passive prismatic joint leaves it unbounded). The
  origin is then within |b| more of the ball of its platform point b when the platform
  turns. The boxes of the balls intersect in the reach box; an empty intersection proves
  that no assembly mode exists;
* :func:`least_squares_positions`: for a turning spatial platform whose legs are all
  distance legs, the position that best satisfies the differences of the squared leg
  equations (linear in the position: Modern Robotics 7.1.2) for a sampled orientation;
* :func:`known_bound`: an upper bound on the number of real assembly modes from the
  structure of the closure (distance legs with fixed centres and radii once q_a is known);
* :func:`canonical_columns` and :func:`scaled_distances`: solutions compared in scaled
  units, angles modulo 2 pi, quaternion signs ignored.

Here (in the model layer) the kind of description may be read; the solvers only call
these functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..mechanism.geometry import wrap_angle
from . import compiled as cc
from .joints import chain_transform, screw_exp
from .structure import platform_frame

__all__ = ["Layout", "layout", "known_bound", "reach_box", "least_squares_positions",
           "platform_rotations", "seed_legs", "canonical_columns", "scaled_distances",
           "shoemake", "least_squares_available", "solve_rows"]


@dataclass(frozen=True)
class Layout:
    """How the unknowns x of a topology are drawn and compared (indices into x).

    Attributes
    ----------
    compare : ndarray of int
        The unknowns that identify an assembly mode.
    angle : ndarray of bool (nx,)
        Angles (compared modulo 2 pi, drawn in [-pi, pi)).
    quat : ndarray of int
        The four entries (w, x, y, z) of a unit quaternion, or none.
    pos : ndarray of int
        The platform origin's coordinates (drawn in the reach box).
    turn : ndarray of int
        Platform angles (drawn uniformly).
    box : ndarray of int
        Unknowns drawn uniformly in a box (Khalil tables: every unknown).
    legs : ndarray of int
        Variables of legs in chain form (drawn from the pose by :func:`seed_legs`).
    rotates : bool
        The platform turns (its orientation is drawn).
    space_dim : int
    """

    compare: np.ndarray
    angle: np.ndarray
    quat: np.ndarray
    pos: np.ndarray
    turn: np.ndarray
    box: np.ndarray
    legs: np.ndarray
    rotates: bool
    space_dim: int


def _ints(v: Any) -> np.ndarray:
    a = np.asarray(v, dtype=int).reshape(-1)
    a.setflags(write=False)
    return a


def layout(model) -> Layout:
    """The :class:`Layout` of ``model``'s topology (built once per topology)."""

    def build() -> Layout:
        nx = model.nx
        angle = np.array(model.x_angle, dtype=bool)
        angle.setflags(write=False)
        plat = model.platform
        if plat is None:  # a Khalil table: every unknown in a box, every unknown compared
            every = _ints(range(nx))
            return Layout(every, angle, _ints([]), _ints([]), _ints([]), every, _ints([]),
                          False, 3)
        npl = model.n_platform
        lengths = np.asarray(plat.lengths, dtype=bool)
        angles = np.asarray(plat.angles, dtype=bool)
        pos = np.flatnonzero(lengths)
        turn = np.flatnonzero(angles)
        quat = np.flatnonzero(~lengths & ~angles) if plat.norm_row else np.zeros(0, int)
        return Layout(_ints(range(npl)), angle, _ints(quat), _ints(pos), _ints(turn),
                      _ints([]), _ints(range(npl, nx)), bool(plat.rotates),
                      int(plat.space_dim))

    return model.cached("enumeration:layout", build)


# --------------------------------------------------------------------------------------
# the bound


def known_bound(model) -> int | None:
    """An upper bound on the number of real assembly modes, read from the structure.

    When every leg is a distance constraint |P_i - C_i(q_a)| = r_i(q_a) with one actuator
    and one closure row (the model's distance form, fully parallel, one leg per platform
    freedom), fixing q_a fixes every centre and radius, and the count is the one of the
    classical problem: a platform that does not turn has its point on dof spheres (circles)
    at once, at most 2 points; a planar platform that turns on three such legs has at most
    6 modes (the sextic of Modern Robotics 7.1.1); a spatial one on six at most 40 (Raghavan
    and Roth). None for every other structure (chains, Khalil tables, redundant actuation).
    """
    plat = model.platform
    if plat is None or model.distance_form() is None or not model.fully_parallel:
        return None
    if model.na != plat.dof or model.mech.redundant:
        return None
    if not plat.rotates:
        return 2
    if plat.space_dim == 2 and plat.dof == 3:
        return 6
    if plat.space_dim == 3 and plat.dof == 6:
        return 40
    return None


# --------------------------------------------------------------------------------------
# where the platform can be


def _leg_offsets(mech) -> list[int]:
    off, out = 0, []
    for leg in mech.legs:
        out.append(off)
        off += len(leg.geometry())
    return out


def _chain_ball(leg, qa_leg: np.ndarray) -> tuple[np.ndarray, float]:
    """A ball holding the end of the chain (its end point, or the platform origin for a
    chain that ends at the platform frame) for every value of its passive variables."""
    c = np.asarray(leg.home, dtype=float)[:3, 3].copy()
    r = 0.0
    act = {a: float(v) for a, v in zip(leg.actuated, qa_leg)}
    kinds = leg.kinds
    for j in range(len(kinds) - 1, -1, -1):
        S = np.asarray(leg.screws[j], dtype=float)
        if j in act:
            T = np.array(screw_exp(ca.DM(S), act[j], kinds[j]))
            c = T[:3, :3] @ c + T[:3, 3]
        elif kinds[j] == "P":
            return c, np.inf
        else:
            w = S[:3]
            q0 = np.cross(w, S[3:])  # the axis' point nearest the origin
            foot = q0 + w * float(w @ (c - q0))
            r += float(np.linalg.norm(c - foot))
            c = foot
    return c, r


def _distance_fn(model) -> ca.Function:
    """(q_a, p) -> (C 3 x n, r 1 x n) of the legs in the distance form (zeros elsewhere)."""

    def build() -> ca.Function:
        st = model.structure
        cs, rs = [], []
        for d in st.distance:
            if d is None:
                cs.append(ca.SX.zeros(3, 1))
                rs.append(ca.SX(0))
            else:
                cs.append(d[0])
                rs.append(d[2])
        return ca.Function("reach_distance", [st.qa, st.p],
                           [ca.horzcat(*cs), ca.horzcat(*rs)])

    return model.cached("enumeration:distance", build)


def _balls(model, qa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per leg, a ball (centre (n, 3), radius (n,)) holding the platform's origin."""
    mech = model.mech
    st = model.structure
    plat = model.platform
    C, rr = (np.array(v) for v in _distance_fn(model)(qa, model.p))
    centres, radii = [], []
    for k, (leg, sl) in enumerate(zip(mech.legs, st.legs)):
        b = np.asarray(leg.platform_point, dtype=float)
        if sl.reduced:
            c, r = C[:, k].copy(), float(rr[0, k])
        else:
            c, r = _chain_ball(leg, np.asarray(qa, dtype=float)[list(sl.qa)])
        if leg.end == "point" or sl.reduced:  # the ball of the platform point b
            if plat.rotates:
                r = r + float(np.linalg.norm(b))
            else:
                c = c - b
        centres.append(c)
        radii.append(r)
    return np.array(centres), np.array(radii, dtype=float)


def reach_box(model, qa: np.ndarray) -> tuple[np.ndarray, np.ndarray, str | None]:
    """(lo, hi, why) of the platform origin's coordinates (``layout(model).pos``) for the
    actuated values ``qa``; ``why`` says which axis has no common position when the legs'
    balls do not intersect (then no assembly mode exists), else None."""
    lay = layout(model)
    k = lay.pos.size
    qa = np.asarray(qa, dtype=float)
    c, r = _balls(model, qa)
    c = c[:, :k]
    fin = np.isfinite(r)
    L = float(model.length)
    if not fin.any():  # only chains with passive slides: a box of the mechanism's size
        span = 2.0 * L + (float(np.max(np.abs(qa))) if qa.size else 0.0)
        return c.min(0) - span, c.max(0) + span, None
    lo = np.max(c[fin] - r[fin, None], axis=0)
    hi = np.min(c[fin] + r[fin, None], axis=0)
    why = None
    if np.any(lo > hi + 1e-12 * L):
        i = int(np.argmax(lo - hi))
        why = ("the legs cannot all reach a common platform position (their reach boxes do "
               f"not overlap along axis {'xyz'[i]})")
    return lo, np.maximum(hi, lo), why


def platform_rotations(model, XP: np.ndarray) -> np.ndarray:
    """Rotation matrices (n, 3, 3) of the platform for rows of platform coordinates."""
    n = XP.shape[0]
    npl = model.n_platform

    def build() -> ca.Function:
        xs = ca.SX.sym("xp", npl)
        R, _ = platform_frame(model.structure.platform, xs)
        return ca.Function("platform_rotation", [xs], [ca.reshape(R, 9, 1)])

    f = model.cached("enumeration:rotation", build)
    out = np.array(f.map(n)(np.asarray(XP, dtype=float).T))  # (9, n), column-major R
    return out.T.reshape(n, 3, 3).transpose(0, 2, 1)


def least_squares_available(model) -> bool:
    """Whether :func:`least_squares_positions` applies: a platform that turns in space on
    at least four legs, every one a distance leg."""
    lay = layout(model)
    form = model.distance_form()
    return bool(form is not None and lay.rotates and lay.space_dim == 3
                and form.platform_points.shape[0] >= 4)


def least_squares_positions(model, qa: np.ndarray, R: np.ndarray) -> np.ndarray | None:
    """Positions (n, 3) that best satisfy the differences of the squared leg equations
    |p|^2 + 2 p.d_i + |d_i|^2 - r_i^2 = 0, d_i = R b_i - c_i (linear in p), for each
    rotation of R (n, 3, 3); None unless the platform turns in space on at least four
    distance legs (then the differences determine the position)."""
    if not least_squares_available(model):
        return None
    form = model.distance_form()
    b = form.platform_points
    C, r = form.centres_radii(np.asarray(qa, dtype=float)[None, :])
    c, r = C[0], r[0]
    d = np.einsum("nij,kj->nki", R, b) - c[None]
    e = np.sum(d * d, axis=2) - r[None] ** 2
    A = 2.0 * (d[:, 1:] - d[:, :1])
    rhs = -(e[:, 1:] - e[:, :1])
    AtA = np.einsum("nki,nkj->nij", A, A) + 1e-12 * np.eye(3)
    Atb = np.einsum("nki,nk->ni", A, rhs)
    return np.linalg.solve(AtA, Atb[..., None])[..., 0]


def shoemake(U: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z), uniform on SO(3), from points U (n, 3) of [0, 1)^3
    (Shoemake's subgroup algorithm); w >= 0.

    >>> q = shoemake(np.array([[0.3, 0.6, 0.1]]))
    >>> bool(abs(np.linalg.norm(q) - 1) < 1e-15 and q[0, 0] >= 0)
    True
    """
    u1, u2, u3 = U[:, 0], U[:, 1], U[:, 2]
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    q = np.stack([b * np.cos(2 * np.pi * u3), a * np.sin(2 * np.pi * u2),
                  a * np.cos(2 * np.pi * u2), b * np.sin(2 * np.pi * u3)], 1)
    return q * np.where(q[:, :1] < 0, -1.0, 1.0)


# --------------------------------------------------------------------------------------
# the variables of legs in chain form, from a sampled pose


@dataclass(frozen=True)
class _LegGroup:
    """Legs in chain form of one leg topology: one Function serves them all (their
    geometry is an input)."""

    fn: ca.Function                 # (z, x_platform, g) -> (residual, dense Jacobian^T)
    legs: tuple[int, ...]
    n: int                          # own variables (actuated and solved) per leg
    m: int                          # residual rows
    act: tuple[int, ...]            # which own variables are actuated
    solved: tuple[int, ...]         # which are solved in x
    angle: np.ndarray


def _leg_geometry_view(g, leg) -> tuple[list, Any, Any]:
    """Screws, home (4x4) and platform point of one leg from its geometry vector g
    (layout of ``Leg.geometry``)."""
    n = len(leg.screws)
    screws = [g[6 * k: 6 * k + 6] for k in range(n)]
    off = 6 * n
    cols = [g[off + 3 * c: off + 3 * c + 3] for c in range(4)]
    home = ca.vertcat(ca.horzcat(*cols), ca.DM([[0, 0, 0, 1]]))
    return screws, home, g[off + 12: off + 15]


def _seed_groups(model) -> list[_LegGroup]:
    """The seed Functions of the legs in chain form, grouped by leg topology."""

    def build() -> list[_LegGroup]:
        mech = model.mech
        st = model.structure
        npl = model.n_platform
        xp = ca.SX.sym("xp", npl)
        R, pv = platform_frame(st.platform, xp)
        groups: dict[tuple, list[int]] = {}
        for k, (leg, sl) in enumerate(zip(mech.legs, st.legs)):
            if not sl.reduced and sl.x:
                groups.setdefault(leg.topology, []).append(k)
        out = []
        for idx in groups.values():
            leg, sl = mech.legs[idx[0]], st.legs[idx[0]]
            n_all = len(leg.names)
            own = [v for v in range(n_all) if sl.q.start + v not in sl.reported]
            kinds = leg.kinds
            g = ca.SX.sym("g", len(leg.geometry()))
            z = ca.SX.sym("z", len(own))
            q = [ca.SX(0)] * n_all
            for i, v in enumerate(own):
                q[v] = z[i]
            screws, home, b = _leg_geometry_view(g, leg)
            T = chain_transform(screws, kinds, q, home)
            if leg.end == "point":
                res = T[:3, 3] - (pv + ca.mtimes(R, b))
            else:  # position and the whole rotation: smooth everywhere (no Gibbs pole)
                res = ca.vertcat(T[:3, 3] - pv, ca.reshape(T[:3, :3] - R, 9, 1))
            J = ca.densify(ca.jacobian(res, z))
            fn = ca.Function(f"seed_leg_{len(out)}", [z, xp, g], [res, J.T])
            act = tuple(own.index(a) for a in leg.actuated)
            solved = tuple(i for i, v in enumerate(own) if v not in leg.actuated)
            out.append(_LegGroup(fn, tuple(idx), len(own), int(res.shape[0]), act, solved,
                                 np.array([kinds[v] == "R" for v in own])))
        return out

    return model.cached("enumeration:seed_groups", build)


def _seed_fn(model, grp: _LegGroup, cols: int, jit: bool | str) -> ca.Function:
    """``grp.fn`` mapped over ``cols`` columns (compiled with ``jit``)."""

    def build() -> ca.Function:
        f = grp.fn
        if jit:
            lib = cc.library(f"enum:{model.topology.key}:{f.name()}", [f], build=jit is True)
            if lib is not None:
                f = lib[f.name()]
        return f.map(f"{f.name()}_{cols}", "serial", cols, [], [])

    return model.cached(("enumeration:seed_map", grp.fn.name(), int(cols), jit), build)


def seed_legs(model, X: np.ndarray, qa: np.ndarray, rng: np.random.Generator,
              iters: int = 10, rounds: int = 3, jit: bool | str = False) -> None:
    """Fill the variables of legs in chain form in the starts X (rows) from their platform
    coordinates: each leg's variables, its actuated ones free, by Gauss-Newton from random
    values towards the leg reaching the sampled pose (its end point at the platform point,
    or its end frame at the platform frame: positions and rotation matrices, which have
    no pole where Gibbs vectors do); ``iters`` iterations, then the legs that did not reach
    start again from other random values, ``rounds`` times in all. A start so drawn is a
    configuration of every leg with other actuated values; the closure then moves it to
    the given ones."""
    groups = _seed_groups(model)
    if not groups:
        return
    mech = model.mech
    st = model.structure
    N = X.shape[0]
    npl = model.n_platform
    offs = _leg_offsets(mech)
    XP = np.ascontiguousarray(X[:, :npl])
    L = float(model.length)
    for grp in groups:
        c = len(grp.legs)
        cols = N * c
        ev = cc.FastFn(_seed_fn(model, grp, cols, jit))
        size = len(mech.legs[grp.legs[0]].geometry())
        G = np.empty((cols, size))
        Z = np.where(grp.angle, rng.uniform(-np.pi, np.pi, (cols, grp.n)),
                     L * rng.uniform(-1.0, 1.0, (cols, grp.n)))
        QA = np.empty((cols, len(grp.act)))
        for j, k in enumerate(grp.legs):
            G[j * N:(j + 1) * N] = model.p[offs[k]: offs[k] + size]
            QA[j * N:(j + 1) * N] = np.asarray(qa, dtype=float)[list(st.legs[k].qa)]
        Z[:, list(grp.act)] = QA
        XPc = np.ascontiguousarray(np.tile(XP, (c, 1)))
        F = np.empty((cols, grp.m))
        J = np.empty((cols, grp.m, grp.n))  # J^T column-major: the Jacobian row by row
        scale = np.where(grp.angle, 1.0, L)
        eye = np.eye(grp.n)
        tol = 1e-6 * max(1.0, L)
        for rnd in range(rounds):
            for _ in range(iters):
                ev.into([Z, XPc, G], [F, J])
                H = np.einsum("kmi,kmj->kij", J, J) + 1e-9 * eye
                g = np.einsum("kmi,km->ki", J, F)
                dz = -solve_rows(H, g)
                nrm = np.linalg.norm(dz / scale, axis=1)
                dz *= np.minimum(1.0, 1.0 / (nrm + 1e-300))[:, None]
                ok = np.all(np.isfinite(dz), axis=1)
                Z[ok] += dz[ok]
            if rnd == rounds - 1:
                break
            ev.into([Z, XPc, G], [F, J])
            miss = ~(np.max(np.abs(F), axis=1) <= tol)  # legs that did not reach: again
            if not miss.any():
                break
            k = int(miss.sum())
            Z[miss] = np.where(grp.angle, rng.uniform(-np.pi, np.pi, (k, grp.n)),
                               L * rng.uniform(-1.0, 1.0, (k, grp.n)))
            Z[np.ix_(miss, list(grp.act))] = QA[miss]
        for j, k in enumerate(grp.legs):
            sl = st.legs[k]
            X[:, list(sl.x)] = Z[j * N:(j + 1) * N][:, list(grp.solved)]


def solve_rows(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Solutions of the systems A[k] x = b[k] (real or complex); NaN rows where A[k] is
    singular."""
    try:
        return np.linalg.solve(A, b[..., None])[..., 0]
    except np.linalg.LinAlgError:
        out = np.full(b.shape, np.nan, dtype=np.result_type(A, b, float))
        for k in range(A.shape[0]):
            try:
                out[k] = np.linalg.solve(A[k], b[k])
            except np.linalg.LinAlgError:
                pass
        return out


# --------------------------------------------------------------------------------------
# comparing solutions


def canonical_columns(model, X: np.ndarray) -> np.ndarray:
    """Columns of unknowns with angles wrapped to (-pi, pi] and quaternions normalised
    with w >= 0 (a copy)."""
    lay = layout(model)
    X = np.array(X, dtype=float)
    if lay.angle.any():
        X[lay.angle] = wrap_angle(X[lay.angle])
    if lay.quat.size:
        q = X[lay.quat] / np.linalg.norm(X[lay.quat], axis=0)
        X[lay.quat] = q * np.where(q[0] < 0, -1.0, 1.0)
    return X


def scaled_distances(model, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Max-norm scaled distances (n, k) between the assembly modes of the columns of X
    (nx, n) and Y (nx, k): the unknowns of ``layout(model).compare``, angles modulo 2 pi,
    a quaternion and its negative the same rotation."""
    if Y.shape[1] == 0 or X.shape[1] == 0:
        return np.full((X.shape[1], Y.shape[1]), np.inf)
    lay = layout(model)
    idx = lay.compare
    s = model.x_scale[idx][:, None, None]
    D = X[idx, :, None] - Y[idx, None, :]
    ang = lay.angle[idx]
    if ang.any():
        D[ang] = wrap_angle(D[ang])
    D = np.abs(D) / s
    if lay.quat.size:
        qi = np.searchsorted(idx, lay.quat)  # the quaternion's rows among the compared
        rest = np.setdiff1d(np.arange(idx.size), qi)
        D2 = np.abs(X[lay.quat, :, None] + Y[lay.quat, None, :]) / s[qi]
        d_rest = D[rest].max(axis=0) if rest.size else 0.0
        return np.maximum(d_rest, np.minimum(D[qi].max(axis=0), D2.max(axis=0)))
    return D.max(axis=0)
