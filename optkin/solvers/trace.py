"""The trace test: is a start system's solution set complete?

Monodromy grows a solution set but cannot say when it has everything. The trace test can
(Sommese, Verschelde and Wampler 2002; Leykin, Rodriguez and Sottile, "Trace test",
Arnold Math. J. 4, 2018). This is the construction HomotopyContinuation.jl's
``verify_solution_completeness`` uses, written for optkin's systems:

For the start system's solutions S of H(x; theta_0) = 0, take a random direction v in the
offset c of the parameters (theta = (q_a, p, c), H = F(x; q_a, p) - c: along c the curve
below is algebraic; along a geometry angle, entering by its cosine, it is not, and the
witnesses never end) and a random linear form a on the algebraic coordinates y(x) of the unknowns
(cos and sin of each periodic angle, the other unknowns as they are), and the system in
(x, lam) with the parameter t::

    G(x, lam; t) = [ H(x; theta_0 + lam v) ;  (a . y(x) - 1) lam + t ].

At t = 0 its solutions are S x {lam = 0} and the *witnesses* W: the points of the curve
C = {(x, lam): H(x; theta_0 + lam v) = 0} on the hyperplane a . y = 1. For t != 0 both
sets move together on C, cut by the hypersurface (a . y - 1) lam = -t; the sum of the
coordinates (y, lam) over all of S and W is then an affine function of t when, and in
general only when, S and W are complete. W is found by monodromy (its own loops over
theta_0, v and a at t = 0, started from points of C made by construction), then
all of S and W are tracked to t = g/2 and t = g for a random complex g, and the three
sums T(0), T(g/2), T(g) are tested for collinearity: the residual is
max |T(g/2) - (T(0) + T(g)) / 2| over the coordinates, relative to how far the points
moved from t = 0 to g/2 (the sum over points of max |y(g/2) - y(0)|): a missing point
departs from the line by its own curvature, which a residual relative to the size of the
sums hides when some witnesses lie far out (HomotopyContinuation.jl's sigma_3 / sigma_1
of [[T(0), T(g/2), T(g)], [1, 1, 1]] passed a 3-RPR set missing one solution at 2e-7).

The curve and the slice are options of :func:`trace_test`. The curve may move the
actuated values instead of c (``direction="qa"``, prismatic actuators only), and the
hyperplane may read only the unknowns that are not periodic angles (``slice="pose"``):
the test is then one of the curve's projection on the pose, whose witnesses are far
fewer (Tsai's 3-UPU: 2 560 along the leg lengths, against 23 304 along c with every
invariant coordinate, 100 minutes, after which not all of them could be tracked). In
every case the traces sum exactly the coordinates the hyperplane reads, and lam: the sum
of any other coordinate is affine in t only if that coordinate has no pole where
(a . y - 1) lam stays finite, which nothing ensures (the 3-RPS along its leg lengths: a
leg angle's cos is (leg vector . axis) / leg length, and the length passes 0 on the
curve; summed, the complete set failed at 0.087, and passes at 5e-15 without it).

A start system whose solutions are complete passes; one missing a solution fails (tests
drop one). A spatial platform's unit quaternion q and -q are one rotation, and the start
system keeps one of them: the test sums both. An angle the system is not periodic in
enters y(x) as it is (then the test is a heuristic: the system is not algebraic in it).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ..model import enumeration as _enum
from . import homotopy as _hom
from .homotopy import _new_mask

__all__ = ["TraceResult", "trace_test"]

log = logging.getLogger("optkin.trace")

#: The ways :func:`trace_test` may slice and move its curve (module docstring).
SLICES = ("invariant", "pose")
DIRECTIONS = ("c", "qa")

#: The trace test passes when its residual (module docstring) is at most this.
TRACE_TOL = 1e-6


@dataclass
class TraceResult:
    """The outcome of :func:`trace_test`.

    Attributes
    ----------
    passed : bool
        The traces are collinear (``residual <= tol``): the solution set is complete.
    residual : float
        The departure of the traces from a line, relative to the points' motion (module
        docstring); NaN when a path failed.
    tol : float
    solutions : int
        The solutions tested (a spatial platform's counted with both quaternion signs).
    witnesses : int
        The points of the auxiliary curve on the hyperplane, found by monodromy.
    loops : int
        The monodromy loops that found them.
    time : float
        Seconds.
    message : str
    """

    passed: bool
    residual: float
    tol: float
    solutions: int
    witnesses: int
    loops: int
    time: float
    message: str


class _TraceSystem(_hom._Base):
    """G(x, lam; t, theta, v, a) of the module docstring, complex and compiled."""

    def __init__(self, model) -> None:
        base = _hom._system(model)
        n, nth = base.n, base.nth
        x = ca.SX.sym("x", n)
        lam = ca.SX.sym("lam")
        t = ca.SX.sym("t")
        th = ca.SX.sym("th", nth)
        v = ca.SX.sym("v", nth)
        self.base = base
        self.per = np.asarray(base.periodic, dtype=bool)
        y = self.coords_sym(x)
        self.k = int(y.shape[0])
        a = ca.SX.sym("a", self.k)
        G = ca.vertcat(base.h_real(x, th + lam * v), (ca.dot(a, y) - 1) * lam + t)
        self.y_fun = ca.Function("y", [x], [y])
        scale = np.concatenate([base.scale, [1.0]])
        self._setup(ca.vertcat(x, lam), ca.vertcat(t, th, v, a), G,
                    f"trace:{base.key}", scale)
        #: the unknowns the system is 2 pi periodic in (lam is not)
        self.periodic = np.concatenate([self.per, [False]])

    def coords_sym(self, x):
        out = []
        for i in range(x.shape[0]):
            out += [ca.cos(x[i]), ca.sin(x[i])] if self.per[i] else [x[i]]
        return ca.vertcat(*out)

    def coords(self, X: np.ndarray) -> np.ndarray:
        """The algebraic coordinates y(x) of the rows of X (complex)."""
        cols = []
        for i in range(X.shape[1]):
            cols += [np.cos(X[:, i]), np.sin(X[:, i])] if self.per[i] else [X[:, i]]
        return np.stack(cols, axis=1)


def _trace_system(model) -> _TraceSystem:
    return model.topology.cached("homotopy:trace", lambda: _TraceSystem(model))


def _trace_tracker(model, tsys: _TraceSystem):
    def build():
        if not tsys.compiled:
            return None
        tr = _hom._Tracker(tsys, sx=False)  # MX: compiled in seconds, not a minute
        return tr if tr.compiled else None

    return model.topology.cached("homotopy:trace_tracker", build)


def _expand(model, S: np.ndarray) -> np.ndarray:
    """S with a spatial platform's quaternions in both signs (the whole fibre)."""
    q = np.asarray(_enum.layout(model).quat, dtype=int)
    if q.size != 4 or not len(S):
        return S
    T = S.copy()
    T[:, q] = -T[:, q]
    return np.vstack([S, T])


def _canon_w(tsys: _TraceSystem, Y: np.ndarray) -> np.ndarray:
    Y = Y.copy()
    ang = np.flatnonzero(tsys.per)
    if ang.size:
        Y[:, ang] = (np.mod(Y[:, ang].real + np.pi, 2 * np.pi) - np.pi) + 1j * Y[:, ang].imag
    return Y


def _new_rows(S: np.ndarray, Y: np.ndarray, sc: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Rows of Y not within tol of a row of S or an earlier row of Y
    (:func:`optkin.solvers.homotopy._new_mask`)."""
    return Y[_new_mask(S, Y, sc, tol)]


def trace_test(model, start: Any, seed: int = 0, stale: int = 5, max_loops: int = 200,
               tol: float = TRACE_TOL, deadline: Any = None, direction: str = "c",
               slice: str = "invariant") -> TraceResult:
    """Test whether ``start`` (a :class:`~optkin.solvers.homotopy.StartSystem` of
    ``model``'s topology) holds every solution of its system (module docstring).

    ``stale`` monodromy loops in a row without a new witness end a round; the trace is
    then computed, and a round that fails the test is followed by another (up to
    ``max_loops`` loops), since the witnesses may be the incomplete set.

    ``direction``: the parameters the test's curve moves, the offset c (``"c"``, any
    system) or the actuated values (``"qa"``: prismatic actuators only, which the system
    is polynomial in). ``slice``: the coordinates the hyperplane reads, every algebraic
    coordinate the symmetry group leaves unchanged (``"invariant"``) or only those of the
    unknowns that are not periodic angles (``"pose"``: a spatial platform's pose; the
    test is then one of the curve's projection on them). The traces sum exactly the
    coordinates the hyperplane reads, and lam. On Tsai's 3-UPU, ``direction="qa",
    slice="pose"`` needs 2 560 witnesses where the defaults needed 23 304 and 100
    minutes and then could not track them all."""
    if direction not in DIRECTIONS:
        raise ValueError(f"trace_test: direction must be one of {DIRECTIONS}, got "
                         f"{direction!r}")
    if slice not in SLICES:
        raise ValueError(f"trace_test: slice must be one of {SLICES}, got {slice!r}")
    if direction == "qa":
        mech = model.mech
        rev = [mech.active_names[k] for k, i in enumerate(mech.active_index)
               if mech.revolute[i]]
        if rev:
            raise ValueError(f"trace_test: direction='qa' needs prismatic actuators (the "
                             f"system polynomial in them); {mech.name}'s {rev} are "
                             "revolute: use direction='c'")
    t0 = time.perf_counter()
    base = _hom._system(model)
    tsys = _trace_system(model)
    tr_b = _hom._tracker(model)
    tr = _trace_tracker(model, tsys)
    rng = np.random.default_rng([int(seed), 17])
    n, k = base.n, tsys.k
    # with a symmetry group (homotopy.symmetry) one point per orbit is tracked and its
    # endpoints mapped to the others; the hyperplane then reads only the coordinates the
    # group leaves unchanged, so that the witnesses too come in whole orbits
    sym, reps = start.representatives(model)
    S_all = np.asarray(start.solutions, dtype=complex)
    S = _expand(model, S_all[reps])  # tracked (both signs of a quaternion)
    n_sol = sym.order * len(S)
    one = np.ones((sym.order, 1))
    tsym = _hom.Symmetry(np.hstack([sym.sign, one]), np.hstack([sym.shift, 0 * one]))
    xr = np.random.default_rng(3).normal(size=(1, n)) + 0j
    inv = np.all(np.abs(tsys.coords(sym.apply(xr)) - tsys.coords(xr)) <= 1e-12, axis=0)
    if slice == "pose":
        inv &= np.concatenate([[False, False] if p else [True] for p in tsys.per])
    if not inv.any():
        raise ValueError(f"trace_test: slice={slice!r} leaves no coordinate of "
                         f"{model.mech.name}'s unknowns to slice by: use 'invariant'")
    th0 = np.asarray(start.theta, dtype=complex)
    size = float(np.max(base.scale))
    ysc = max(1.0, size)

    def fail(msg: str, W: int = 0, loops: int = 0) -> TraceResult:
        return TraceResult(False, float("nan"), tol, n_sol, W, loops,
                           time.perf_counter() - t0, msg)

    # points of the curve by construction: some solutions tracked to theta_0 + v, and a
    # linear form a through them (a . y = 1)
    def along_c(d: np.ndarray) -> np.ndarray:
        out = np.zeros_like(d)
        if direction == "qa":  # the curve of the actuated values
            out[:base.na] = d[:base.na]
        else:
            out[-n:] = d[-n:]
        return out

    th_q = th0 + along_c(_hom._random_theta(base, model, rng) - th0)
    P = _hom.track(base, S[:min(k, len(S))], th0, th_q, np.exp(2j * np.pi * rng.uniform()),
                   tracker=tr_b, deadline=deadline)
    Xq = P.x[P.status == "finite"]
    if not len(Xq):
        return fail("no path from the start system reached the auxiliary parameters")
    Yq = tsys.coords(Xq)[:, inv]
    # Solutions can lie in a proper affine subspace of the y space: the 3-RPS's at joint
    # level satisfy three affine relations (its platform's origin is an affine combination
    # of the leg ends, each linear in cos and sin of its angle), and a hyperplane through
    # as many of them as span that subspace contains every solution there: not a generic
    # slice, and the witness loops diverged on the way back to it (trace residual 8e-2 on a
    # complete set). Through one point fewer than span it, the slice is generic among those
    # through its points (the same set then passes at 1e-15).
    Z = np.hstack([Yq, np.ones((len(Yq), 1))])
    sv = np.linalg.svd(Z, compute_uv=False)
    r = int(np.sum(sv > 1e-9 * sv[0]))
    if r < len(Yq):
        Xq, Yq = Xq[:max(1, r - 1)], Yq[:max(1, r - 1)]
    a0 = np.zeros(k, complex)
    a0[inv] = np.linalg.lstsq(Yq, np.ones(len(Yq), complex), rcond=None)[0]
    TH0 = np.concatenate([[0.0], th0, along_c(th_q - th0), a0])
    W = np.zeros((0, n + 1), complex)  # every witness, whole orbits
    Wr = np.zeros((0, n + 1), complex)  # one of each orbit (tracked)

    def add_witnesses(Y: np.ndarray) -> int:
        """The new points of Y with their orbits (one by one: a point whose orbit an
        earlier one brought adds nothing); how many orbits were new."""
        nonlocal W, Wr
        Y = _new_rows(W, _canon_w(tsys, Y), tsys.scale)
        if not len(Y):
            return 0
        G = tsym.order
        O = _canon_w(tsys, tsym.apply(Y)).reshape(G, len(Y), -1).transpose(1, 0, 2)
        O = O.reshape(G * len(Y), -1)  # each point's orbit in turn
        keep = _new_mask(W, O, tsys.scale)
        new = keep.reshape(len(Y), G).any(axis=1)
        W, Wr = np.vstack([W, O[keep]]), np.vstack([Wr, Y[new]])
        return int(new.sum())

    add_witnesses(np.hstack([Xq, np.ones((len(Xq), 1))]))

    def random_params() -> np.ndarray:
        th = _hom._random_theta(base, model, rng)
        v = along_c(_hom._random_theta(base, model, rng) - th)
        a = inv * (rng.normal(size=k) + 1j * rng.normal(size=k)) / (ysc * np.sqrt(k))
        return np.concatenate([[0.0], th, v, a])

    def coords_lam(Y: np.ndarray) -> np.ndarray:
        """The coordinates the traces sum: those the hyperplane reads, and lam. Only
        those: the sum of a coordinate that can grow without bound where (a . y - 1) lam
        stays finite is not affine in t even over a complete set. Tsai's 3-UPU with the
        pose hyperplane: the sums of the angle coordinates its leg flips leave unchanged
        departed from the line by up to 0.118 where the pose's and lam's did by 1.5e-10
        (the same complete set; the other angle coordinates cancel over each orbit)."""
        return np.hstack([tsys.coords(Y[:, :n])[:, inv], Y[:, n:n + 1]])

    def sums(Y: np.ndarray) -> np.ndarray:
        return coords_lam(Y).sum(axis=0)

    loops = 0
    residual = float("nan")
    while loops < max_loops:
        quiet = 0
        while quiet < stale and loops < max_loops:  # a monodromy round for the witnesses
            if deadline is not None and deadline.expired():
                return fail("stopped at the time limit", len(W), loops)
            loops += 1
            p1, p2 = random_params(), random_params()
            Y = Wr
            for a, b in ((TH0, p1), (p1, p2), (p2, TH0)):
                Q = _hom.track(tsys, Y, a, b, np.exp(2j * np.pi * rng.uniform()),
                               tracker=tr, deadline=deadline)
                Y = Q.x[Q.status == "finite"]
                if not len(Y):
                    break
            if len(Y):  # on the witness component only: lam != 0 (a path may jump
                # onto the other, lam = 0, where the start system's solutions lie)
                Y = Y[np.abs(Y[:, n]) > 1e-6 * (1 + np.abs(Y[:, n]).max())]
            if len(Y) and add_witnesses(Y):
                quiet = 0
            else:
                quiet += 1
            log.debug("trace test: loop %d, %d witnesses", loops, len(W))
        # the trace at t = 0, g/2, g: linear when complete, T(g/2) = (T(0) + T(g)) / 2
        Y0r = np.vstack([np.hstack([S, np.zeros((len(S), 1))]), Wr])
        Y0 = tsym.apply(Y0r)
        g = np.exp(2j * np.pi * rng.uniform())
        ends = []
        for tt in (0.5 * g, g):
            TH1 = TH0.copy()
            TH1[0] = tt
            ok = False
            for _ in range(_hom.TRIES):
                Q = _hom.track_orbits(tsys, tsym, Y0r, TH0, TH1,
                                      np.exp(2j * np.pi * rng.uniform()), tracker=tr,
                                      deadline=deadline)
                # every path finite, and no two ending at one point (path jumping: the
                # 3-UPU's 24 648 paths once ended on 24 636 points, all "finite")
                ok = bool(np.all(Q.status == "finite")) and bool(
                    _new_mask(np.zeros((0, n + 1), complex), _canon_w(tsys, Q.x),
                              tsys.scale).all())
                if ok:
                    break
            if not ok:
                log.debug("trace test: the paths to t = %s failed or jumped", tt)
                break
            ends.append(Q.x)
        if len(ends) == 2:
            T0, T1, T2 = sums(Y0), sums(ends[0]), sums(ends[1])
            # the departure from linearity against how far the points moved: a missing
            # solution departs by its own curvature, whatever the size of the sums
            moved = np.sum(np.max(np.abs(coords_lam(ends[0]) - coords_lam(Y0)), axis=1))
            residual = float(np.max(np.abs(T1 - 0.5 * (T0 + T2))) / max(moved, 1e-300))
            log.debug("trace test: residual %.3g with %d witnesses", residual, len(W))
            if residual <= tol:
                return TraceResult(
                    True, residual, tol, n_sol, len(W), loops, time.perf_counter() - t0,
                    f"trace test passed: {n_sol} solutions complete (trace residual "
                    f"{residual:.1e}, {len(W)} witnesses, {loops} loops)")
    return TraceResult(False, residual, tol, n_sol, len(W), loops, time.perf_counter() - t0,
                       f"trace test failed: residual {residual:.1e} > {tol:g} after "
                       f"{loops} loops ({len(W)} witnesses): the solution set (or the "
                       "witness set) is incomplete")
