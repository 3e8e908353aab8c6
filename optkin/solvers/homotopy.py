"""Every assembly mode by parameter homotopy, from start systems found by monodromy.

The method of Sommese and Wampler (2005), ch. 7 and 18 (parameter homotopies, the gamma
trick) and Duff et al. (2019, monodromy), for the closure of any square model:

* the system. The closure rows ``sqrt(u) - v`` of distance legs become ``u - v^2`` (the
  same real solutions, no branch cut); with the actuated values q_a, the geometry p and an
  offset c as parameters theta = (q_a, p, c), H(x; theta) = F(x; q_a, p) - c. Its value, its
  Jacobian in x and its derivative along a direction of theta are one CasADi Function,
  made complex by :func:`optkin.model.complexify.complexify` and mapped over the paths.
* start systems by monodromy. At random complex parameters theta_0 (geometry entries
  equal to 0, +-pi/2 or +-pi kept, and the axes of passive revolutes: :func:`structural`;
  legs' screws kept rigid and the quaternion's norm row without offset:
  :func:`_keep_rigid`; c_0 = F(x_0; q_a0, p_0)
  for a random complex x_0, which is then a solution by construction), the solutions are
  grown by loops theta_0 -> theta_1 -> theta_2 -> theta_0 through random complex
  parameters: each loop permutes the solutions, and new endpoints are new solutions. The
  loops stop at the structure's known count when it has one (distance legs: 6, 40, 2),
  else when, after ``stale`` loops in a row that found nothing, the trace test
  (:mod:`optkin.solvers.trace`) shows the set complete, or at ``max_loops``. Solutions
  are identified modulo 2 pi in the real part of each angle and up to the sign of a
  quaternion.
* the parameter homotopy. From theta_0 to the target (q_a, p, 0) along
  theta_0 + s(t) (theta_1 - theta_0), s(t) = gamma t / (1 + (gamma - 1) t) with a random
  gamma on the unit circle, near 1 on the first try (:data:`GAMMA_SPREAD`; theta_0 is
  random complex, which keeps the path away from the discriminant with probability one),
  every path is tracked by a predictor (RK4, or Hermite extrapolation above ``SMALL``
  unknowns) and a Newton corrector with adaptive steps
  (linear solves equilibrated: columns by the size of the point, rows to unit norm);
  a path that grows beyond 1e8 (scaled) near the target (t >= 0.99) goes to infinity;
  one that does so earlier, or whose step falls below 1e-12, fails, and then every path is
  tracked again along another gamma (up to :data:`TRIES` in all; on nearly planar 6-6
  platforms a path can swing out to |x| ~ 1e6, where Newton stalls at 1e-7 relative:
  projective coordinates would cure it, not done yet). Endpoints with negligible imaginary
  parts are polished by the real model's Newton step and returned as
  :class:`~optkin.results.KinResult`.

The tracking is compiled: up to ``CHUNK`` predictor-corrector steps of a path, then three
Newton steps at the target on the paths that have arrived, are one CasADi Function
(:class:`_Tracker`, built once per topology: a fold over one step that skips stopped
paths, mapped over the paths still running, their statuses read between calls; the scale
of the unknowns an input, so that results never depend on the geometry seen first).
It is compiled in the background, the interpreted Function answering meanwhile with the
same numbers (a call it fails is made again compiled). Systems of more than :data:`SMALL` unknowns
predict by a cubic Hermite extrapolation through the last two points and their tangents
(one linear solve a step instead of RK4's four), solved by a complex elimination written
out (:func:`_clu`), the tangent from the second Newton update's factorisation and a third
update only where the second has not reached the tolerance. Without a C compiler the RK4 steps run as
a numpy loop over the paths (:func:`track`).

The account: every path ends finite, at infinity, singular or failed; ``complete`` only when
none failed, no two finite nonsingular endpoints coincide (path jumping) and the start
system is known complete (its bound reached, or the trace test passed). A path goes to
infinity when its largest algebraic coordinate (an unknown, or the cos and sin of a
periodic angle, whose size is exp |Im|) passes ``big`` near the target, or when it stops in
the endgame zone (t >= :data:`ENDGAME`) large and growing like (1 - t)^-v, v estimated
from the tangent there (:func:`_diverging`: the valuation an endgame estimates; Tsai's
3-UPU at its own geometry has 96 such paths of 672, whose step size collapsed at |x| ~
1e3). Not yet here: an endgame for singular endpoints (a path that stalls near a finite
singular point is reported failed); see the issue tracker.

Symmetries (:func:`symmetry`): where maps of the angles leave the system unchanged for
every parameter of the family (flipping both universal joints of a U-P-U leg: 8 joint
configurations of one pose on Tsai's 3-UPU), monodromy keeps whole orbits, and monodromy,
the trace test and the parameter homotopy track one path per orbit, mapping its endpoint
to the others (:func:`track_orbits`): the 3-UPU's 672 paths as 84. Start systems of
the library's topologies ship with the package (:data:`SHIPPED`); others are stored in the
compiled-code cache directory (``.npz``, no pickles); both are re-verified on loading
(each stored solution must solve its system, nonsingular and distinct).
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import math
import os
import time
import weakref
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from ..errors import MechanismError
from ..model import enumeration as _enum
from ..results import (
    INFEASIBLE,
    OPTIMAL,
    TIME_LIMIT,
    EnumerationStats,
    KinResult,
    SolutionSet,
    SolverStats,
)

__all__ = ["StartSystem", "start_system", "load_or_build_start", "homotopy_modes"]


# ---------------------------------------------------------------------------------------
# the system H(x; theta) = F(x; q_a, p) - c, complex and mapped
# ---------------------------------------------------------------------------------------

def _squared(e: ca.SX) -> ca.SX:
    """A closure row ``sqrt(u) - v`` as ``u - v^2``; other rows unchanged."""
    if e.is_op(ca.OP_SUB) and e.n_dep() == 2 and e.dep(0).is_op(ca.OP_SQRT):
        return e.dep(0).dep(0) - e.dep(1) ** 2
    return e


class _Base:
    """A square system H(x; theta) made complex and compiled: its value, x-Jacobian and
    derivative along a direction of theta, evaluated over rows by :meth:`eval` (the
    interface the trackers use)."""

    def _setup(self, x: ca.SX, th: ca.SX, H: ca.SX, tag: str, scale: np.ndarray) -> None:
        from ..model import compiled as cc
        from ..model.complexify import complexify

        self.n, self.nth = int(x.shape[0]), int(th.shape[0])
        dth = ca.SX.sym("dth", self.nth)
        Jx = ca.densify(ca.jacobian(H, x))
        Ht = ca.jtimes(H, th, dth)
        f = ca.Function("homotopy", [x, th, dth], [ca.densify(H), Jx, ca.densify(Ht)],
                        ["x", "th", "dth"], ["H", "Jx", "Ht"])
        # complexified op by op in Python (a 6-6 platform's 0.06 s): kept in the cache
        from ..model import complexify as cx

        self.f_sx = cc.memo_function(
            "homotopy_cx", [cc.fingerprint(f), _source_digest(cx.__file__)], lambda: complexify(f))
        self.key = tag
        # compiled in the background (a 6-6 platform's library takes gcc about a second,
        # a 3-RPR's 0.3 s): meanwhile the interpreted Function answers, with the same
        # numbers (no linear solve inside, nothing it could raise on that the compiled
        # code would not), so that a topology's first call does not wait for the compiler
        self._fn = cc.LateCompiled(f"homotopy:{tag}", self.f_sx)
        #: whether a compiler is (or will be) behind the system (False: none available)
        self.compiled = self._fn.compiled
        self.scale = np.asarray(scale, dtype=float)

    @property
    def _pending(self) -> Any:
        """The system's library being built (None once it has landed or failed)."""
        return self._fn.pending

    def eval(self, X: np.ndarray, TH: np.ndarray, DTH: np.ndarray):
        """H (N, n), Jx (N, n, n), Ht (N, n) at the N rows of X, TH, DTH (complex)."""
        N0 = X.shape[0]
        N = max(8, 1 << (N0 - 1).bit_length())  # a few widths: padded with the first row
        if N != N0:
            pad = N - N0
            X = np.concatenate([X, np.repeat(X[:1], pad, 0)])
            TH = np.concatenate([TH, np.repeat(TH[:1], pad, 0)])
            DTH = np.concatenate([DTH, np.repeat(DTH[:1], pad, 0)])
        # through preallocated buffers: no numpy -> DM conversions
        fm = self._fn.mapped(N, lambda f, N: f.map(N))
        # an (N, k) C-ordered array is the column-major (k, N) input
        Hr, Hi, Jr, Ji, Tr, Ti = fm(X.real.ravel(), X.imag.ravel(), TH.real.ravel(),
                                    TH.imag.ravel(), DTH.real.ravel(), DTH.imag.ravel())
        n = self.n
        with np.errstate(invalid="ignore", over="ignore"):  # a path gone to inf: inf/nan
            H = (Hr + 1j * Hi).reshape(N, n)[:N0]
            J = (Jr + 1j * Ji).reshape(N, n, n).transpose(0, 2, 1)[:N0]
            Ht = (Tr + 1j * Ti).reshape(N, n)[:N0]
        return H, J, Ht


class _System(_Base):
    def __init__(self, model) -> None:
        topo = model.topology
        st = topo.st
        if topo.m != topo.nx:
            raise MechanismError(
                f"homotopy: the closure has {topo.m} equations for {topo.nx} unknowns; the "
                "homotopy needs a square system (use method='multistart')")
        rows = [_squared(topo.phi_sym[i]) for i in range(topo.m)]
        F = ca.vertcat(*rows)
        self.na = topo.na
        # only the geometry entries the closure reads are parameters (a 6-6 platform's
        # geometry vector has 349 entries, its leg equations read 36)
        # (the free symbols of F matched by identity: one traversal of the graph, 0.3 ms,
        # where a depends_on per entry took 34 ms on a 6-6 platform)
        #: (m, n) which unknowns each row reads (the legs' private angles: :func:`symmetry`)
        self.reads = np.array(ca.jacobian(F, st.x).sparsity(), dtype=bool)
        reads = {s.element_hash() for s in ca.symvar(F)}
        entries = ca.vertsplit(st.p)
        used = np.array([i for i, e in enumerate(entries) if e.element_hash() in reads], int)
        self.p_used = used
        self.np_ = int(used.size)
        c = ca.SX.sym("c", topo.m)
        th = ca.vertcat(st.qa, *[entries[int(i)] for i in used], c)
        #: the real system H(x, theta), for systems built on this one (the trace test's)
        self.h_real = ca.Function("h", [st.x, th], [F - c])
        self._setup(st.x, th, F - c, topo.key, model.x_scale)
        # the angles the system is 2 pi periodic in (a Khalil table's loop-angle row, a
        # sum of angles, is not): only those are identified modulo 2 pi. Tested at the
        # model's own geometry: random geometry need not be a rigid leg's (w . v != 0 keeps
        # theta itself in a screw's exponential), and the homotopy's is kept rigid
        # (:func:`_keep_rigid`)
        rng = np.random.default_rng(0)
        x = rng.normal(size=self.n) + 1j * rng.normal(size=self.n)
        th = rng.normal(size=self.nth) + 1j * rng.normal(size=self.nth)
        th[self.na:self.na + self.np_] = np.asarray(model.p, dtype=float)[used]
        zero = np.zeros((1, self.nth), complex)
        h0 = self.eval(x[None], th[None], zero)[0][0]
        self.periodic = np.zeros(self.n, bool)
        for i in np.flatnonzero(np.asarray(model.x_angle, dtype=bool)):
            y = x.copy()
            y[i] += 2 * np.pi
            h1 = self.eval(y[None], th[None], zero)[0][0]
            self.periodic[i] = bool(np.max(np.abs(h1 - h0)) <= 1e-9 * (1 + np.max(np.abs(h0))))


def _system(model) -> _System:
    return model.topology.cached("homotopy:system", lambda: _System(model))


def _solve_scaled(J: np.ndarray, b: np.ndarray, X: np.ndarray, sc: np.ndarray) -> np.ndarray:
    """J[k]^-1 b[k], with the columns scaled by max(1, |x|/scale) and the rows to unit
    norm: the same step, far better conditioned where a path swings far out (measured on
    a nearly planar 6-6 platform at |x| ~ 5e4: cond 2e15 unscaled, 2e9 scaled). Systems
    of at most :data:`SMALL` unknowns are solved unscaled (the scaling costs a 3-RPR
    40 % of its time, and its paths have not needed it)."""
    if X.shape[1] <= SMALL:
        return _enum.solve_rows(J, b)
    D = np.maximum(1.0, np.abs(X) / sc)
    Jc = J * D[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        r = 1.0 / np.sqrt(np.sum(np.abs(Jc) ** 2, axis=2))
        return _enum.solve_rows(Jc * r[:, :, None], b * r) * D


# ---------------------------------------------------------------------------------------
# compiled tracking: K steps of the predictor-corrector in one compiled Function
# ---------------------------------------------------------------------------------------

#: Steps per call of the compiled tracker (the paths' statuses are read between calls).
CHUNK = 32

#: Where each path's state sits in the compiled tracker's state vector (after 2n values).
_T, _H, _ST, _CNT = 0, 1, 2, 3
_CODES = np.array(["running", "finite", "at_infinity", "failed"], dtype=object)


def _cmul(a, b):
    return a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]


def _cdiv(a, b):
    den = b[0] * b[0] + b[1] * b[1]
    return (a[0] * b[0] + a[1] * b[1]) / den, (a[1] * b[0] - a[0] * b[1]) / den


def _adjugate(Jr, Ji):
    """(adj J, det J) of a complex J of order 1-3 (real and imaginary parts apart): the
    cofactors and the determinant written out, as nested lists of (re, im) pairs."""
    n = Jr.shape[0]
    A = [[(Jr[i, j], Ji[i, j]) for j in range(n)] for i in range(n)]

    def det2(a, b_, c, d):
        return _cadd(_cmul(a, d), _cneg(_cmul(b_, c)))

    if n == 1:
        return [[(1.0, 0.0)]], A[0][0]
    if n == 2:
        adj = [[A[1][1], _cneg(A[0][1])], [_cneg(A[1][0]), A[0][0]]]
        return adj, det2(A[0][0], A[0][1], A[1][0], A[1][1])

    def cof(i, j):
        r = [k for k in range(3) if k != i]
        c = [k for k in range(3) if k != j]
        m = det2(A[r[0]][c[0]], A[r[0]][c[1]], A[r[1]][c[0]], A[r[1]][c[1]])
        return m if (i + j) % 2 == 0 else _cneg(m)

    C = [[cof(i, j) for j in range(3)] for i in range(3)]
    adj = [[C[j][i] for j in range(3)] for i in range(3)]
    return adj, _cadd(*[_cmul(A[0][j], C[0][j]) for j in range(3)])


def _cadd(*terms):
    return (sum(t[0] for t in terms), sum(t[1] for t in terms))


def _cneg(a):
    return (-a[0], -a[1])


def _adjugate_solve(Jr, Ji, br, bi):
    """J^-1 b for a complex J of order 1-3 by the adjugate: one complex division by det J."""
    n = Jr.shape[0]
    adj, det = _adjugate(Jr, Ji)
    b = [(br[i], bi[i]) for i in range(n)]
    den = det[0] * det[0] + det[1] * det[1]
    inv = (det[0] / den, -det[1] / den)
    out = [_cmul(inv, _cadd(*[_cmul(adj[i][j], b[j]) for j in range(n)])) for i in range(n)]
    return ca.vertcat(*[o[0] for o in out]), ca.vertcat(*[o[1] for o in out])


def _adjugate_cond(Jr, Ji):
    """The Frobenius condition number ||J||_F ||J^-1||_F of a complex J of order 1-3 (at
    most n times the 2-norm one; inf where det J = 0)."""
    adj, det = _adjugate(Jr, Ji)
    fa = sum(a[0] ** 2 + a[1] ** 2 for row in adj for a in row)
    fj = ca.sum1(ca.sum2(Jr ** 2 + Ji ** 2))
    return ca.sqrt(fj * fa / (det[0] ** 2 + det[1] ** 2))


@functools.lru_cache(maxsize=16)
def _clu(n: int, k: int) -> ca.Function:
    """X = J^-1 B for a complex n x n J and n x k B (real and imaginary parts apart), as one
    SX Function written out: columns scaled by D (the size of the point over its scale),
    rows to unit norm (as :func:`_solve_scaled`), then Gaussian elimination with partial
    pivoting (the row of largest modulus brought up by compare-and-swap) and back
    substitution. A 6-6 platform's 7 x 7 solve: 3 160 operations, 3.1 us compiled, where
    CasADi's QR of the real 14 x 14 form took 5.2 us; with a second column (the tangent
    beside the Newton update: one factorisation) 3.3 us."""
    Jr, Ji = ca.SX.sym("Jr", n, n), ca.SX.sym("Ji", n, n)
    Br, Bi = ca.SX.sym("Br", n, k), ca.SX.sym("Bi", n, k)
    D = ca.SX.sym("D", n)
    A = [[(Jr[i, j] * D[j], Ji[i, j] * D[j]) for j in range(n)] for i in range(n)]
    B = [[(Br[i, c], Bi[i, c]) for c in range(k)] for i in range(n)]
    for i in range(n):
        r = 1 / ca.sqrt(sum(a[0] ** 2 + a[1] ** 2 for a in A[i]))
        A[i] = [(a[0] * r, a[1] * r) for a in A[i]]
        B[i] = [(b[0] * r, b[1] * r) for b in B[i]]
    for c in range(n):
        for i in range(c + 1, n):  # bring the largest |A[i][c]| to row c
            # (a swap as u + s (v - u), v - s (v - u) with s in {0, 1}: 4 operations per
            # entry where two if_else take 6; an inf entry gives NaN, which the tracker's
            # finiteness checks reject as they would the inf)
            swap = (A[i][c][0] ** 2 + A[i][c][1] ** 2) > (A[c][c][0] ** 2 + A[c][c][1] ** 2)
            for row in (A, B):
                for j in range(c if row is A else 0, len(row[c])):
                    u, v = row[c][j], row[i][j]
                    sd = (swap * (v[0] - u[0]), swap * (v[1] - u[1]))
                    row[c][j] = (u[0] + sd[0], u[1] + sd[1])
                    row[i][j] = (v[0] - sd[0], v[1] - sd[1])
        p = A[c][c]
        den = p[0] ** 2 + p[1] ** 2
        inv = (p[0] / den, -p[1] / den)
        for i in range(c + 1, n):
            f = _cmul(A[i][c], inv)
            A[i] = A[i][:c + 1] + [_cadd(A[i][j], _cneg(_cmul(f, A[c][j])))
                                   for j in range(c + 1, n)]
            B[i] = [_cadd(B[i][j], _cneg(_cmul(f, B[c][j]))) for j in range(k)]
        A[c] = A[c][:c] + [(1.0, 0.0)] + [_cmul(a, inv) for a in A[c][c + 1:]]
        B[c] = [_cmul(b, inv) for b in B[c]]
    X: list[list[Any]] = [[None] * k for _ in range(n)]
    for i in reversed(range(n)):
        for c in range(k):
            X[i][c] = _cadd(B[i][c], *[_cneg(_cmul(A[i][j], X[j][c])) for j in range(i + 1, n)])
    Xr = ca.vertcat(*[ca.horzcat(*[X[i][c][0] * D[i] for c in range(k)]) for i in range(n)])
    Xi = ca.vertcat(*[ca.horzcat(*[X[i][c][1] * D[i] for c in range(k)]) for i in range(n)])
    return ca.Function(f"homotopy_clu_{n}_{k}", [Jr, Ji, Br, Bi, D], [Xr, Xi],
                       {"cse": True})


def _finite(v):
    return ca.sum1(ca.fabs(v)) < 1e300  # NaN and inf both fail


@functools.lru_cache(maxsize=4)
def _source_digest(path: str = __file__) -> str:
    """A digest of a module's source (default this one): a graph kept in the cache is one
    this code built."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


class _Tracker:
    """:func:`track`'s step, written once as a CasADi graph: ``CHUNK`` steps of every path
    in one compiled call, mapped over the paths (the same arithmetic as :func:`track`, whose
    Python loop remains for when no compiler is available)."""

    def __init__(self, sys: _System, h0: float = 0.05, hmax: float = 0.25,
                 hmin: float = 1e-12, big: float = 1e8, accept_tol: float | None = None,
                 grow: float = 1.25, sx: bool | None = None, newton: int = 3,
                 predictor: str | None = None, target: float | None | str = "auto") -> None:
        n, nth = sys.n, sys.nth
        # the predictor: RK4 (4 solves a step) for small systems, where it takes fewer
        # steps; above, a cubic Hermite extrapolation through the last two points and
        # their tangents (one solve a step): a 6-6 platform's 40 paths in 175 steps and
        # 85 ms instead of 316 and 105 ms
        if predictor is None:
            predictor = "rk4" if n <= SMALL else "hermite"
        if predictor not in ("rk4", "hermite"):
            raise ValueError(f"predictor must be 'rk4' or 'hermite', got {predictor!r}")
        if target == "auto":
            target = STEP_TARGET[predictor]
        # small systems as one SX graph (the linear solves unrolled), larger ones as MX
        # (QR factorisations by CasADi's linear solver, a call to the system each)
        if sx is None:  # inlined only when small: a Khalil four-bar's inlined chunk has
            # 369k instructions and takes gcc a minute (MX: calls, compiled in a second)
            sx = n <= SMALL and sys.f_sx.n_instructions() <= 2000
        sym = ca.SX if sx else ca.MX
        self.n, self.nth, self.h0, self.hmax = n, nth, h0, hmax
        self.sys = sys
        self.width = 2 * n + 4 + (6 * n + 2 if predictor == "hermite" else 0)
        self.predictor = predictor
        self.fused_cond = n <= 3 and sx
        # the second Newton update's factorisation also gives the Hermite tangent (at the
        # point before that update, close to the accepted one)
        fused = predictor == "hermite" and n > SMALL
        # SIMD lanes for systems of moderate size only (the C of a step grows as n^3 and
        # with the system's graph, and gcc's time with it; a 6-6 platform's: 7 unknowns,
        # 3.8k operations, 36k in the step and polish, compiled in 5-10 s)
        lanes_ok = (fused and LANES_ON and n <= LANES_MAX_N
                    and sys.f_sx.n_instructions() <= LANES_MAX_OPS)
        # a step is accepted when the last Newton update is this small (relative): 1e-6
        # for small systems; 1e-4 for the fused ones, whose quadratic convergence puts the
        # point itself within ~1e-8 by then (a 6-6 platform's 40 paths 1.3x faster; the
        # endpoints are polished at the target in any case)
        if accept_tol is None:
            accept_tol = 1e-4 if fused else 1e-6
        from ..model import compiled as cc

        # the periodic angles: the system is polynomial in their cos and sin, which pass
        # ``big`` where |Im| > log(big) (Tsai's 3-UPU: paths to infinity at |Im| ~ 1e3,
        # where cos overflowed long before |x| reached big)
        per = np.flatnonzero(_periodic(sys))

        def build() -> ca.Function:
            # the value and Jacobian (the corrector), the Jacobian and the parameter derivative
            # (the predictor): each without the work of the output it does not need
            ins = sys.f_sx.sx_in()
            out = sys.f_sx(*ins)
            f_hj = ca.Function("homotopy_hj", ins[:4], out[:4])
            f_jt = ca.Function("homotopy_jt", ins, out[2:])
            f_all = sys.f_sx
            s = sym.sym("state", self.width)
            # the parameters of a run: start theta, direction, gamma and the scale of the
            # unknowns (the target model's: an input, so that the compiled tracker is one per
            # topology whatever geometry was seen first)
            par = sym.sym("par", 4 * nth + 2 + n)
            th0 = (par[0:nth], par[nth:2 * nth])
            d = (par[2 * nth:3 * nth], par[3 * nth:4 * nth])
            g = (par[4 * nth], par[4 * nth + 1])
            sc = par[4 * nth + 2:]

            def theta(t):
                den = (1 + (g[0] - 1) * t, g[1] * t)
                sr, si = _cdiv((g[0] * t, g[1] * t), den)
                dsr, dsi = _cdiv(g, _cmul(den, den))
                TH = (th0[0] + sr * d[0] - si * d[1], th0[1] + sr * d[1] + si * d[0])
                DTH = (dsr * d[0] - dsi * d[1], dsr * d[1] + dsi * d[0])
                return TH, DTH

            def csolve(Jr, Ji, br, bi, x, scale=None):  # equilibrated as in _solve_scaled
                if n <= 3 and sx:  # the complex adjugate: a 6 x 6 real QR costs 5x more
                    return _adjugate_solve(Jr, Ji, br, bi)
                if n <= SMALL:
                    A = ca.blockcat([[Jr, -Ji], [Ji, Jr]])
                    # MX: QR named, so that the interpreted chunk (used while the compiler
                    # runs) solves as the compiled one does
                    u = (ca.solve(A, ca.vertcat(br, bi)) if sx else
                         ca.solve(A, ca.vertcat(br, bi), "qr"))
                    return u[:n], u[n:]
                # the complex elimination written out (:func:`_clu`), equilibrated
                scale = sc if scale is None else scale
                return _clu(n, br.shape[1])(Jr, Ji, br, bi, ca.fmax(1, absc(x) / scale))

            def rhs(x, t):
                TH, DTH = theta(t)
                Jr, Ji, Tr, Ti = f_jt(x[0], x[1], TH[0], TH[1], DTH[0], DTH[1])
                kr, ki = csolve(Jr, Ji, Tr, Ti, x)
                return -kr, -ki

            def absc(x):
                return ca.sqrt(x[0] ** 2 + x[1] ** 2)

            Xa = (s[0:n], s[n:2 * n])
            t, h, st, cnt = s[2 * n + _T], s[2 * n + _H], s[2 * n + _ST], s[2 * n + _CNT]
            run = st == 0
            ha = ca.fmin(h, 1 - t)
            hermite = predictor == "hermite"
            if hermite:  # extra state: previous point, its t, both tangents, "has previous"
                o = 2 * n + 4
                xp = (s[o:o + n], s[o + n:o + 2 * n])
                tp = s[o + 2 * n]
                dx = (s[o + 2 * n + 1:o + 3 * n + 1], s[o + 3 * n + 1:o + 4 * n + 1])
                dxp = (s[o + 4 * n + 1:o + 5 * n + 1], s[o + 5 * n + 1:o + 6 * n + 1])
                hasp = s[o + 6 * n + 1]
                D = t - tp
                u = 1 + ha / ca.if_else(hasp > 0, D, 1.0)
                h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
                h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
                herm = tuple(h00 * xp[i] + h10 * D * dxp[i] + h01 * Xa[i] + h11 * D * dx[i]
                             for i in (0, 1))
                Xp = tuple(ca.if_else(hasp > 0, herm[i], Xa[i] + ha * dx[i]) for i in (0, 1))
            else:
                k1 = rhs(Xa, t)
                k2 = rhs((Xa[0] + 0.5 * ha * k1[0], Xa[1] + 0.5 * ha * k1[1]), t + 0.5 * ha)
                k3 = rhs((Xa[0] + 0.5 * ha * k2[0], Xa[1] + 0.5 * ha * k2[1]), t + 0.5 * ha)
                k4 = rhs((Xa[0] + ha * k3[0], Xa[1] + ha * k3[1]), t + ha)
                Xp = tuple(Xa[i] + ha / 6 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i])
                           for i in (0, 1))
            tn = t + ha
            THn, DTHn = theta(tn)
            ok = _finite(ca.vertcat(*Xp))
            Xp = tuple(ca.if_else(ok, Xp[i], Xa[i]) for i in (0, 1))
            size = 1 + ca.mmax(absc(Xp) / sc)
            def newton_step(Xp, prev, ok, tangent, size, TH, scale):
                """One Newton update at parameters TH, kept only while the updates
                contract (with the Hermite tangent from the same factorisation when asked)."""
                kn = None
                if tangent:
                    Hr, Hi, Jr, Ji, Tr, Ti = f_all(Xp[0], Xp[1], TH[0], TH[1],
                                                   DTHn[0], DTHn[1])
                    ur, ui = csolve(Jr, Ji, ca.horzcat(Hr, Tr), ca.horzcat(Hi, Ti), Xp, scale)
                    up, kn = (ur[:, 0], ui[:, 0]), (-ur[:, 1], -ui[:, 1])
                else:
                    Hr, Hi, Jr, Ji = f_hj(Xp[0], Xp[1], TH[0], TH[1])
                    up = csolve(Jr, Ji, Hr, Hi, Xp, scale)
                fin = _finite(ca.vertcat(*up))
                nrm = ca.if_else(fin, ca.mmax(absc(up) / scale) / size, ca.inf)
                ok = ca.logic_and(ca.logic_and(ok, fin), ca.logic_or(
                    nrm <= ca.fmax(0.5 * prev, 1e-9), prev <= NOISE))
                Xp = tuple(Xp[i] - ca.if_else(ok, up[i], 0) for i in (0, 1))
                return Xp, nrm, ok, kn

            prev = ca.inf
            first = None
            kn = None
            # fused (larger systems): the tangent from the second update's factorisation,
            # and the updates after it only where that one has not yet reached accept_tol
            # (a branch in the compiled code: most steps need two updates, not three)
            tan_it = min(1, newton - 1) if fused else -1
            for it in range(newton):
                if fused and it > tan_it:
                    xs, pv, okk = sym.sym("x", 2 * n), sym.sym("prev"), sym.sym("ok")
                    ths, scs, szs = sym.sym("th", 2 * nth), sym.sym("sc", n), sym.sym("size")
                    Xq, nq, oq, _ = newton_step((xs[:n], xs[n:]), pv, okk, False, szs,
                                                (ths[:nth], ths[nth:]), scs)
                    extra = ca.Function("homotopy_newton", [xs, pv, okk, ths, scs, szs],
                                        [ca.vertcat(Xq[0], Xq[1], nq, oq)])
                    packed = ca.vertcat(Xp[0], Xp[1], prev, ok)
                    res = ca.if_else(ca.logic_and(ok, prev > accept_tol), extra(
                        ca.vertcat(Xp[0], Xp[1]), prev, ok, ca.vertcat(THn[0], THn[1]), sc,
                        size), packed, True)
                    Xp, prev, ok = (res[:n], res[n:2 * n]), res[2 * n], res[2 * n + 1]
                    continue
                Xp, nrm, ok, k = newton_step(Xp, prev, ok, it == tan_it, size, THn, sc)
                if k is not None:
                    kn = k
                if first is None:
                    first = nrm
                prev = nrm
            small = ca.mmax(absc((Xa[0] - Xp[0], Xa[1] - Xp[1])) / sc)
            accept = ca.logic_and(ca.logic_and(ok, prev <= accept_tol),
                                  small <= 0.5 + 0.5 * ca.mmax(absc(Xa)))
            acc = ca.logic_and(run, accept)
            X1 = tuple(ca.if_else(acc, Xp[i], Xa[i]) for i in (0, 1))
            t1 = ca.if_else(acc, tn, t)
            if target is None:  # by a fixed factor
                hgrow = ca.fmin(h * ca.if_else(first < 1e-7, 2.0, grow), hmax)
            else:  # the step that would have made the first update `target` (local error
                # ~ h^order), within a factor 2 either way
                order = 4 if hermite else 5
                q = target / ca.fmax(first, 1e-300)
                # (the fourth root as two square roots: the SIMD lanes' code computes
                # exactly this, where pow(q, 0.25) may differ in the last bit)
                ratio = ca.sqrt(ca.sqrt(q)) if order == 4 else q ** (1.0 / order)
                hgrow = ca.fmin(h * ca.fmin(ca.fmax(ratio, 0.5), 2.0), hmax)
            h1 = ca.if_else(run, ca.if_else(accept, hgrow, 0.5 * h), h)
            far = ca.mmax(absc(X1) / sc) > big
            if per.size:  # an angle whose cos and sin pass big: Im > log(big)
                far = ca.logic_or(far, ca.mmax(ca.fabs(X1[1][per.tolist()])) > math.log(big))
            code = ca.if_else(far, ca.if_else(t1 >= 0.99, 2, 3),
                              ca.if_else(ca.logic_and(ca.logic_not(accept), h1 < hmin), 3,
                                         ca.if_else(t1 >= 1.0, 1, 0)))
            st1 = ca.if_else(run, code, st)
            s1 = ca.vertcat(X1[0], X1[1], t1, h1, st1, cnt + run)
            if hermite:  # on acceptance: the tangent at the new point; the old one moves back
                if kn is None:
                    kn = rhs(Xp, tn)
                keep = lambda a, b: ca.if_else(acc, a, b)  # noqa: E731
                s1 = ca.vertcat(s1, keep(Xa[0], xp[0]), keep(Xa[1], xp[1]), keep(t, tp),
                                keep(kn[0], dx[0]), keep(kn[1], dx[1]),
                                keep(dx[0], dxp[0]), keep(dx[1], dxp[1]),
                                ca.if_else(acc, 1.0, hasp))
            # common subexpressions merged (the angles' cos and sin recur): a 3-RPR's step
            # runs twice as fast compiled
            opts = {"cse": True} if sx else {}
            step = ca.Function("homotopy_step", [s, par], [s1], opts)
            # the polish, in the same call: three Newton steps at the target (s(1) = 1) on the
            # paths that have arrived (again in later calls: a converged point stays), and the
            # condition number of Jx there (columns scaled), written out for the adjugate's
            # orders, else from one evaluation in numpy (:func:`_endpoint_cond`)
            X = Xa
            TH1 = (th0[0] + d[0], th0[1] + d[1])
            done = st == 1
            for _ in range(3):
                Hr, Hi, Jr, Ji = f_hj(X[0], X[1], TH1[0], TH1[1])
                up = csolve(Jr, Ji, Hr, Hi, X)
                use = ca.logic_and(done, _finite(ca.vertcat(*up)))
                X = tuple(X[i] - ca.if_else(use, up[i], 0) for i in (0, 1))
            S = ca.vertcat(X[0], X[1], s[2 * n:])
            if self.fused_cond:
                _, _, Jr, Ji = f_hj(X[0], X[1], TH1[0], TH1[1])
                D = ca.repmat(sc.T, n, 1)
                cond = ca.if_else(done, _adjugate_cond(Jr * D, Ji * D), ca.inf)
            else:
                cond = ca.inf
            polish = ca.Function("homotopy_polish", [s, par], [S, cond], opts)
            # CHUNK steps as a loop over the step (fold), then the polish: C code the size of
            # one step (inlined, a 3-RPR's chunk took gcc 4-5 s; a loop, under a second)
            ms, mp = ca.MX.sym("state", self.width), ca.MX.sym("par", par.shape[0])
            # a path that has stopped is not stepped again (a branch in the compiled code):
            # a call can hold many steps without paying them for the paths already done
            live = ca.Function("homotopy_live_step", [ms, mp], [ca.if_else(
                ms[2 * n + _ST] == 0, step(ms, mp), ms, True)])
            if lanes_ok:
                # the step and the polish as single SX graphs (their branches selects,
                # common subexpressions merged): the very operations the SIMD lanes'
                # library evaluates (:meth:`_start_lanes`), so that this chunk, interpreted
                # or compiled, and the lanes give the same numbers to the bit
                from ..model.lanes import single_sx

                live, polish = (single_sx(live, "homotopy_live_sx"),
                                single_sx(polish, "homotopy_polish_sx"))
            last = live.fold(CHUNK)(ms, ca.repmat(mp, 1, CHUNK))
            return ca.Function("homotopy_chunk", [ms, mp], polish(last, mp))

        # built op by op in Python (a 3-RPR's SX step 0.13 s, a 6-6 platform's 0.03 s):
        # kept serialized in the cache, read back in a few ms by the next process
        chunk = cc.memo_function("homotopy_chunk", [
            cc.fingerprint(sys.f_sx), repr((h0, hmax, hmin, big, accept_tol, grow, sx, newton,
                                         predictor, CHUNK, target, lanes_ok)), _source_digest()], build)

        # compiled in the background: until the library is ready (about a second), runs
        # use the interpreted chunk (a 3-RPR's call 11 ms instead of 1.4 ms, a 6-6
        # platform's 0.4 s instead of 0.1 s; the same numbers to the bit on 100 random
        # 3-RPR and 6 random 6-6 platforms), so that a worker's first problem of a
        # topology does not wait for the compiler. An interpreted call can fail where the
        # compiled code does not (CasADi's QR solver raises on an exactly singular matrix,
        # the compiled one gives inf or NaN, which the step's guards handle): such a call
        # waits for the library and is made again from the same state (:meth:`run`)
        # with SIMD lanes to come, CasADi's compiled chunk is not built (11 s of gcc for a
        # 6-6 platform) unless the lanes' build fails: the interpreted chunk (the same
        # operations, 0.18 s a call) answers until the lanes land (a cached library of it
        # is loaded all the same)
        from ..model import lanes as _lanes

        defer = lanes_ok and _lanes.cpu_key() is not None
        self._chunk = cc.LateCompiled(f"homotopy_track:{sys.key}:{predictor}", chunk,
                                      build=not defer)
        #: whether a compiler is (or will be) behind the chunk (False: none available)
        self.compiled = self._chunk.compiled
        # larger systems: the same chunk for eight paths at once (SIMD lanes,
        # :mod:`optkin.model.lanes`), built in the background from the first call (its C
        # written then: 0.4-1 s once per machine and topology); until it lands the chunk
        # above serves, and where it cannot be built that chunk is compiled instead
        self._lanes: Any = None
        self._lanes_fm: dict[int, Any] = {}
        self._lanes_todo = ((chunk, int(4 * nth + 2 + n)) if lanes_ok and self.compiled
                            else None)

    def _start_lanes(self, chunk: ca.Function, npar: int) -> Any:
        """The lanes library of ``chunk`` (:func:`optkin.model.compiled.start_library`:
        loaded, pending or None)."""
        from ..model import compiled as cc
        from ..model import lanes

        cpu = lanes.cpu_key()
        if cpu is None:
            return None
        W = self.width
        S = ca.MX.sym("state", lanes.LANES, W)
        ref = ca.Function("homotopy_lanes", [S, ca.MX.sym("par", npar)],
                          [S, ca.MX.zeros(lanes.LANES, 1)])
        tag = (f"homotopy_lanes:{self.sys.key}:{cc.fingerprint(chunk)[:16]}:"
               f"{lanes.source_digest()}:{cpu}:{CHUNK}:{' '.join(lanes.FLAGS)}")

        def source() -> str:  # (a ValueError: start_library releases the build lock)
            fns = {f.name(): f for f in chunk.find_functions()}
            if "homotopy_live_sx" not in fns or "homotopy_polish_sx" not in fns:
                raise ValueError("lanes: the chunk has no single-SX step and polish")
            return lanes.chunk_source("homotopy_lanes", fns["homotopy_live_sx"],
                                      fns["homotopy_polish_sx"], W, npar, CHUNK)

        try:
            return cc.start_library(tag, [ref], source=source, flags=lanes.FLAGS)
        except (OSError, RuntimeError, ValueError):
            return None

    def _lanes_fn(self) -> Any:
        """The lanes Function once its library has landed, else None (its build is started
        by the first call that finds nothing being compiled for the chunk; where it cannot
        be built, CasADi's compiled chunk is built instead)."""
        if self._lanes_todo is not None and self._pending is None:
            todo, self._lanes_todo = self._lanes_todo, None
            self._lanes = self._start_lanes(*todo)
        lib = self._lanes
        if lib is None or isinstance(lib, dict):
            if lib is None:
                self._chunk.start()  # no lanes: CasADi's compiled chunk after all
            return None if lib is None else lib["homotopy_lanes"]
        done = lib.poll()
        if done is None:
            return None
        self._lanes = done if done is not False else None
        return self._lanes_fn()

    def _call_lanes(self, f: Any, S: np.ndarray, act: np.ndarray, par: np.ndarray,
                    threads: int) -> None:
        """One lanes chunk of the paths ``act`` (rows of ``S`` updated in place), eight a
        call; the calls shared among ``threads`` threads, each with buffers of its own.
        The last block is filled with stopped copies of its first path (left as they are)."""
        from ..model.compiled import FastFn
        from ..model.lanes import LANES

        n = self.n
        blocks = [act[i:i + LANES] for i in range(0, act.size, LANES)]
        k = max(1, min(int(threads), len(blocks)))

        def run(part: int) -> None:
            fm = self._lanes_fm.get(part)
            if fm is None or fm.f is not f:
                fm = self._lanes_fm[part] = FastFn(f)
            for blk in blocks[part::k]:
                X = S[blk]
                if len(blk) < LANES:
                    pad = np.repeat(X[:1], LANES - len(blk), 0)
                    pad[:, 2 * n + _ST] = 3
                    X = np.vstack([X, pad])
                out, _ = fm(np.ascontiguousarray(X.T).ravel(), par)
                S[blk] = out.reshape(self.width, LANES).T[:len(blk)]

        if k == 1:
            run(0)
            return
        pool = self._threads(k - 1)
        futures = [pool.submit(run, part) for part in range(1, k)]
        run(0)
        for fu in futures:
            fu.result()

    @property
    def _pending(self) -> Any:
        """The chunk's library being built (None once it has landed or failed)."""
        return self._chunk.pending

    def _poll(self) -> None:
        """Switch to the compiled chunk once its background build has finished."""
        self._chunk.poll()

    def _map(self, N: int, part: int = 0):
        return self._chunk.mapped(N, lambda f, N: f.map(f"homotopy_chunk_{N}", "serial", N,
                                                        [1], []), part)

    def _call(self, S: np.ndarray, act: np.ndarray, par: np.ndarray, threads: int):
        """One compiled chunk of the paths ``act`` (rows of ``S`` updated in place); the
        paths in ``threads`` shares evaluated at once, each through call buffers of its
        own (the compiled code releases the GIL). Returns the fused condition numbers."""
        W = self.width
        lf = (self._lanes_fn() if self._lanes is not None or self._lanes_todo is not None
              else None)
        if lf is not None:
            self._call_lanes(lf, S, act, par, threads)
            return np.full(act.size, np.inf)
        # (threads only once the compiled chunk is in: the interpreted one may fail and
        # wait for it)
        shares = _shares(act.size, threads if self._pending is None else 1)
        if len(shares) == 1:
            fm = self._map(act.size)
            out, c = fm(S[act].ravel(), par)
            if self._pending is not None and not fm.ok():  # interpreted, and it failed:
                self._pending.wait()  # the compiled chunk, from the same state
                self._poll()
                if self._pending is None:
                    fm = self._map(act.size)
                    out, c = fm(S[act].ravel(), par)
            S[act] = out.reshape(act.size, W)
            return np.asarray(c).ravel().copy()
        cuts = np.cumsum([0] + shares)
        parts = [act[cuts[k]:cuts[k + 1]] for k in range(len(shares))]
        fms = [self._map(p.size, k) for k, p in enumerate(parts)]

        def run(k: int):
            out, c = fms[k](S[parts[k]].ravel(), par)
            return out.reshape(parts[k].size, W).copy(), np.asarray(c).ravel().copy()

        pool = self._threads(len(parts) - 1)
        futures = [pool.submit(run, k) for k in range(1, len(parts))]
        res = [run(0)] + [f.result() for f in futures]
        for p, (out, _) in zip(parts, res):
            S[p] = out
        return np.concatenate([c for _, c in res])

    def _threads(self, n: int):
        """A pool of ``n`` threads kept with the tracker."""
        from concurrent.futures import ThreadPoolExecutor

        pool, size = getattr(self, "_pool", (None, 0))
        if pool is None or size != n:
            if pool is not None:
                pool.shutdown(wait=False)
            pool = ThreadPoolExecutor(n, thread_name_prefix="optkin-homotopy")
            self._pool = (pool, n)
        return pool

    def run(self, X0: np.ndarray, th0: np.ndarray, th1: np.ndarray, gamma: complex,
            max_steps: int = 5000, deadline: Any = None, scale: np.ndarray | None = None,
            threads: int = 1):
        """(X, status, t, steps, cond) after tracking the rows of X0 from th0 to th1
        (``scale``: of the unknowns, default the system's; cond None unless computed in the
        compiled call; ``threads``: the paths shared among that many threads, each share
        at least :data:`PATHS_PER_THREAD` paths)."""
        N, n = X0.shape
        scale = self.sys.scale if scale is None else np.asarray(scale, dtype=float)
        W = self.width
        S = np.zeros((N, W))
        S[:, :n], S[:, n:2 * n] = X0.real, X0.imag
        S[:, 2 * n + _H] = self.h0
        d = th1 - th0
        if self.predictor == "hermite":  # the tangent at the start points
            TH = np.repeat(th0[None], N, 0)
            DTH = np.repeat((gamma * d)[None], N, 0)
            _, J, Ht = self.sys.eval(X0.astype(complex), TH, DTH)
            k = -_solve_scaled(J, Ht, X0, scale)
            o = 2 * n + 4
            S[:, o + 2 * n + 1:o + 3 * n + 1] = k.real
            S[:, o + 3 * n + 1:o + 4 * n + 1] = k.imag
        par = np.concatenate([th0.real, th0.imag, d.real, d.imag, [gamma.real, gamma.imag],
                              scale])
        act = np.arange(N)
        cond = np.full(N, np.inf)
        steps = 0
        while act.size and steps < max_steps and not (deadline is not None
                                                       and deadline.expired()):
            cond[act] = self._call(S, act, par, threads)
            steps += CHUNK
            act = act[S[act, 2 * n + _ST] == 0]
        X = S[:, :n] + 1j * S[:, n:2 * n]
        status = _CODES[S[:, 2 * n + _ST].astype(int)]
        status[status == "running"] = "failed"
        return (X, status, S[:, 2 * n + _T], int(S[:, 2 * n + _CNT].max(initial=0)),
                cond if self.fused_cond else None)


#: The size of the first Newton update (relative) an accepted step aims the next step at,
#: per predictor (None: grow by a fixed factor, ``grow``, or 2 after a tiny update). With
#: the Hermite predictor, whose local error goes as h^4: 30 random 6-6 platforms (the
#: benchmark's) in 51.9 steps a path instead of 58.2, 36.5-38.2 ms against 41.6-48.4 ms
#: on one thread, the same modes on all 30; for RK4 (the 3-RPR) it changed nothing.
STEP_TARGET: dict[str, float | None] = {"hermite": 5e-3, "rk4": None}

#: Whether larger systems are tracked by SIMD lanes once their library is built
#: (``OPTKIN_LANES=0`` turns it off: CasADi's compiled chunk only).
LANES_ON = os.environ.get("OPTKIN_LANES", "1").strip() not in ("0", "off", "no")

#: Largest systems given SIMD lanes: unknowns, and operations of the complex system.
LANES_MAX_N, LANES_MAX_OPS = 8, 6000

#: Fewest paths a thread is given (below, one call on all of them is faster than the
#: threads' hand-over).
PATHS_PER_THREAD = 8


def _shares(n: int, threads: int) -> list[int]:
    """``n`` paths in up to ``threads`` shares as equal as can be, each of at least
    :data:`PATHS_PER_THREAD` paths."""
    k = max(1, min(int(threads), n // PATHS_PER_THREAD))
    return [n // k + (i < n % k) for i in range(k)]


def _tracker(model) -> _Tracker | None:
    """The topology's compiled tracker, or None without a compiler."""
    def build():
        sys = _system(model)
        if not sys.compiled:
            return None
        tr = _Tracker(sys)
        return tr if tr.compiled else None

    return model.topology.cached("homotopy:tracker", build)


# ---------------------------------------------------------------------------------------
# path tracking
# ---------------------------------------------------------------------------------------

@dataclass
class _Paths:
    x: np.ndarray  # (N, n) endpoints
    status: np.ndarray  # (N,) "finite", "at_infinity", "failed"
    cond: np.ndarray  # (N,) condition number of Jx at the endpoint
    t: np.ndarray  # (N,) where each path stopped (1: at the target)
    steps: int  # loop iterations (steps of the slowest path)


#: Systems of at most this many unknowns: one SX graph per compiled step, solved
#: without equilibration.
SMALL = 4

#: Gamma paths tried before a call reports failed paths (each is a new random path).
TRIES = 6

#: The phase of gamma on each try, uniform in +-spread turns: near the straight segment
#: first (the start parameters are random complex, so the segment itself avoids the
#: discriminant with probability one), wider on each retry. A phase of a quarter turn or
#: more makes s(t) swing out to |s| ~ 1 / |1 + gamma| and the paths that much longer
#: (measured on 7 random 6-6 platforms: 40-60 steps a path at phase 0, 55-90 at 0.3 turns,
#: 100-135 at 0.45).
GAMMA_SPREAD = (0.05, 0.15, 0.3, 0.5)

#: A Newton update this small (relative to the point) has converged: the next ones need
#: not contract further.
NOISE = 1e-7


def track(sys: _System, X0: np.ndarray, th0: np.ndarray, th1: np.ndarray,
          gamma: complex, h0: float = 0.05, hmax: float = 0.25,
          hmin: float = 1e-12, big: float = 1e8, max_steps: int = 5000,
          accept_tol: float = 1e-6, grow: float = 1.25,
          tracker: _Tracker | None = None, deadline: Any = None,
          scale: np.ndarray | None = None, threads: int = 1) -> _Paths:
    """Track the solutions X0 (N, n) of H(.; th0) to H(.; th1) along the gamma path
    (by ``tracker``, compiled, when given: then the step parameters are its own, and
    ``threads`` share the paths). ``scale``: of the unknowns (the model's ``x_scale``;
    default the system's)."""
    N, n = X0.shape
    sc = sys.scale if scale is None else np.asarray(scale, dtype=float)
    if tracker is not None:
        X, status, t, steps, cond = tracker.run(X0, th0, th1, gamma, max_steps, deadline,
                                                sc, threads)
        if cond is None:  # polished already: the condition numbers in numpy
            cond = _endpoint_cond(sys, X, status, th1, sc)
        _diverging(sys, X, status, t, th0, th1, gamma, sc)
        return _Paths(X, status, cond, t, steps)
    d = th1 - th0
    per = np.flatnonzero(_periodic(sys))

    def theta(t):
        s = gamma * t / (1 + (gamma - 1) * t)
        ds = gamma / (1 + (gamma - 1) * t) ** 2
        return th0[None, :] + s[:, None] * d[None, :], ds[:, None] * d[None, :]

    def rhs(X, t):
        TH, DTH = theta(t)
        _, J, Ht = sys.eval(X, TH, DTH)
        return -_solve_scaled(J, Ht, X, sc)

    X = X0.astype(complex).copy()
    t = np.zeros(N)
    h = np.full(N, h0)
    status = np.array(["running"] * N, dtype=object)
    steps = 0
    while True:
        act = np.flatnonzero(status == "running")
        if act.size == 0 or steps >= max_steps or (deadline is not None and deadline.expired()):
            break
        steps += 1
        Xa, ta = X[act], t[act]
        ha = np.minimum(h[act], 1.0 - ta)
        # RK4 predictor
        k1 = rhs(Xa, ta)
        k2 = rhs(Xa + 0.5 * ha[:, None] * k1, ta + 0.5 * ha)
        k3 = rhs(Xa + 0.5 * ha[:, None] * k2, ta + 0.5 * ha)
        k4 = rhs(Xa + ha[:, None] * k3, ta + ha)
        Xp = Xa + (ha[:, None] / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        tn = ta + ha
        # Newton corrector: three iterations, contracting
        TH, DTH = theta(tn)
        ok = np.all(np.isfinite(Xp), axis=1)
        Xp = np.where(ok[:, None], Xp, Xa)  # a failed row is evaluated at its last point
        prev = np.full(act.size, np.inf)
        # updates relative to the size of the point (complex solutions may be far out)
        size = 1.0 + np.max(np.abs(Xp) / sc, axis=1)
        first_nrm = None
        for _ in range(3):
            H, J, _ = sys.eval(Xp, TH, DTH)
            dx = _solve_scaled(J, H, Xp, sc)
            nrm = np.max(np.abs(dx) / sc, axis=1) / size
            if first_nrm is None:
                first_nrm = np.where(np.isfinite(nrm), nrm, np.inf)
            # contracting, unless already converged to the working accuracy (where a path
            # swings far out the updates stall at noise of 1e-8 relative, not below)
            ok &= np.isfinite(nrm) & ((nrm <= np.maximum(0.5 * prev, 1e-9)) | (prev <= NOISE))
            Xp = Xp - np.where(ok[:, None], dx, 0)
            prev = np.where(np.isfinite(nrm), nrm, np.inf)
        small = np.max(np.abs(Xa - Xp) / sc, axis=1)
        accept = ok & (prev <= accept_tol) & (small <= 0.5 + 0.5 * np.abs(Xa).max(axis=1))
        idx = act[accept]
        X[idx], t[idx] = Xp[accept], tn[accept]
        # grow gently: by 2 only when the predictor was very good (the first Newton update
        # tiny), else by `grow` (doubling after every success rejected every other step)
        first = first_nrm[accept]
        h[idx] = np.minimum(h[idx] * np.where(first < 1e-7, 2.0, grow), hmax)
        rej = act[~accept]
        h[rej] *= 0.5
        # only near the target can a path go to infinity (before it, the parameters are
        # generic): a path that swings far out earlier has failed (another gamma)
        far = np.max(np.abs(X[act]) / sc, axis=1) > big
        if per.size:  # an angle whose cos and sin pass big (see _Tracker)
            far |= np.max(np.abs(X[act][:, per].imag), axis=1) > math.log(big)
        status[act[far & (t[act] >= 0.99)]] = "at_infinity"
        status[act[far & (t[act] < 0.99)]] = "failed"
        status[rej[h[rej] < hmin]] = "failed"
        status[act[(t[act] >= 1.0) & (status[act] == "running")]] = "finite"
    status[status == "running"] = "failed"
    _diverging(sys, X, status, t, th0, th1, gamma, sc)
    return _polish(sys, X, status, t, steps, th1, sc)


#: A path that stops in the endgame zone (t at least this) can be found to diverge.
ENDGAME = 0.99
#: ... when its largest algebraic coordinate is this large (scaled) and grows as
#: (1 - t)^-v with v at least :data:`VALUATION`.
FAR = 1e2
VALUATION = 0.1


def _periodic(sys) -> np.ndarray:
    """Which unknowns of a system the tracker sees as periodic angles (bool, (n,))."""
    return np.asarray(getattr(sys, "periodic", np.zeros(sys.n, bool)), bool)


def _diverging(sys, X, status, t, th0, th1, gamma, sc) -> None:
    """Paths that stopped short of the target in the endgame zone on their way to
    infinity, marked ``"at_infinity"`` in ``status`` (in place). Such a path's largest
    algebraic coordinate y (an unknown, or the cos and sin of a periodic angle: exp |Im|)
    grows like (1 - t)^-v near the target; the step size collapses long before |y|
    reaches the tracker's ``big`` (Tsai's 3-UPU: |x| ~ 1e3 at t = 0.9998). v is estimated
    from the tangent there, v = (1 - t) d log|y| / dt (the valuation of the path's
    Puiseux series, as an endgame estimates it from its samples): a path to a finite
    singular endpoint has v <= 0 in every coordinate that is large (the 3-UPU's diverging
    paths: v = 1 or 2/3, at |y| of 1.4e3 to 2e4)."""
    idx = np.flatnonzero((status == "failed") & (t >= ENDGAME) & (t < 1.0))
    if not idx.size:
        return
    per = _periodic(sys)
    x, tt = X[idx], t[idx]
    d = th1 - th0
    s = gamma * tt / (1 + (gamma - 1) * tt)
    ds = gamma / (1 + (gamma - 1) * tt) ** 2
    TH = th0[None, :] + s[:, None] * d[None, :]
    _, J, Ht = sys.eval(x, TH, ds[:, None] * d[None, :])
    with np.errstate(all="ignore"):
        xd = -np.linalg.solve(J, Ht[..., None])[..., 0]
        # log-size of each coordinate and its derivative in t
        big = np.where(per[None, :], np.abs(x.imag), np.log(np.abs(x) / sc[None, :]))
        dbig = np.where(per[None, :], np.sign(x.imag) * xd.imag, (xd / x).real)
    k = np.argmax(np.where(np.isfinite(big), big, -np.inf), axis=1)
    r = np.arange(idx.size)
    v = (1 - tt) * dbig[r, k]
    out = (big[r, k] >= math.log(FAR)) & np.isfinite(v) & (v >= VALUATION)
    status[idx[out]] = "at_infinity"


def _endpoint_cond(sys: _System, X, status, th1, sc) -> np.ndarray:
    """The condition numbers of Jx (columns scaled) at the finite endpoints (inf else)."""
    cond = np.full(X.shape[0], np.inf)
    fin = np.flatnonzero(status == "finite")
    if fin.size:
        TH = np.repeat(th1[None, :], fin.size, axis=0)
        _, J, _ = sys.eval(X[fin], TH, np.zeros_like(TH))
        with np.errstate(all="ignore"):
            cond[fin] = np.linalg.cond(J * sc[None, None, :])
    return cond


def _polish(sys: _System, X, status, t, steps, th1, sc) -> _Paths:
    """Newton at the target on the finite endpoints, and their condition numbers."""
    fin = np.flatnonzero(status == "finite")
    if fin.size:
        TH = np.repeat(th1[None, :], fin.size, axis=0)
        Xf = X[fin]
        for _ in range(3):  # polish at the target
            H, J, _ = sys.eval(Xf, TH, np.zeros_like(TH))
            dx = _solve_scaled(J, H, Xf, sc)
            good = np.all(np.isfinite(dx), axis=1)
            Xf = Xf - np.where(good[:, None], dx, 0)
        X[fin] = Xf
    return _Paths(X, status, _endpoint_cond(sys, X, status, th1, sc), t, steps)


# ---------------------------------------------------------------------------------------
# identification of solutions
# ---------------------------------------------------------------------------------------

def _canonical(model, X: np.ndarray) -> np.ndarray:
    X = X.copy()
    ang = np.flatnonzero(_system(model).periodic)
    if ang.size:
        X[:, ang] = (np.mod(X[:, ang].real + np.pi, 2 * np.pi) - np.pi) + 1j * X[:, ang].imag
    q = np.asarray(_enum.layout(model).quat, dtype=int)
    if q.size == 4:
        Q = X[:, q]
        k = np.argmax(np.abs(Q), axis=1)
        sign = np.where(Q[np.arange(len(Q)), k].real < 0, -1.0, 1.0)
        X[:, q] = Q * sign[:, None]
    return X


def _distinct(model, S: np.ndarray, Y: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Rows of Y (canonical) not within tol of a row of S or an earlier row of Y, in
    scaled units and relative to the row's size (:func:`_new_mask`): a solution far out is
    accurate only relatively. (With an absolute tolerance, monodromy on Tsai's 3-UPU from
    seed 2 kept adding copies of one orbit at |x| ~ 490 whose endpoints differed by
    1.5e-6, 3e-9 relative, from loop to loop: 1 256 "solutions" after 120 loops, of which
    672 distinct, the count seeds 0 and 1 stop at.)"""
    return Y[_new_mask(S, Y, np.asarray(model.x_scale, dtype=float), tol)]


#: Up to this many pairs (rows of Y times rows of S and Y) every pair is compared at once:
#: a call's few endpoints (a 3-RPR's 6: 0.2 ms a call through the windows, most of it
#: making the random direction, against tens of microseconds).
_DENSE_PAIRS = 4096


@functools.lru_cache(maxsize=64)
def _direction(m: int) -> tuple[np.ndarray, np.ndarray]:
    """The fixed random direction (real and imaginary parts) :func:`_new_mask` projects
    rows of ``m`` entries on."""
    rng = np.random.default_rng(1234)
    wr, wi = rng.normal(size=m), rng.normal(size=m)
    wr.flags.writeable = wi.flags.writeable = False
    return wr, wi


def _new_mask(S: np.ndarray, Y: np.ndarray, sc: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """Which rows of Y are not within tol of a row of S or an earlier row of Y, in scaled units and
    relative to the row's size (1 + its largest scaled entry: witnesses far out are
    accurate only relatively).

    Each row is compared only with the rows whose projection on a fixed random direction
    lies within the bound the tolerance puts on it (rows sorted by that projection), not
    with all of them: with ``N`` witnesses found and as many candidates, a loop of the
    trace test's witness monodromy on the 3-UPU spent a fifth of its time here at N = 11 000 (an N x N
    comparison), more as N grew."""
    m = Y.shape[1]
    if not len(Y):
        return np.zeros(0, dtype=bool)
    Zy = Y / sc
    rad = tol * (1.0 + np.max(np.abs(Zy), axis=1))
    if len(Y) * (len(S) + len(Y)) <= _DENSE_PAIRS:  # a call's few endpoints: all pairs
        keep = np.ones(len(Y), dtype=bool)
        if len(S):
            dS = np.max(np.abs(Zy[:, None, :] - (np.asarray(S) / sc)[None]), axis=2)
            keep = ~np.any(dS <= rad[:, None], axis=1)
        near = np.max(np.abs(Zy[:, None, :] - Zy[None]), axis=2) <= rad[:, None]
        for i in range(1, len(Y)):
            if keep[i] and np.any(near[i, :i] & keep[:i]):
                keep[i] = False
        return keep
    wr, wi = _direction(m)
    lip = float(np.sum(np.abs(wr)) + np.sum(np.abs(wi)))  # |key(y) - key(p)| <= lip d
    ky = Zy.real @ wr + Zy.imag @ wi
    keep = np.ones(len(Y), dtype=bool)
    if len(S):
        Zs = np.asarray(S) / sc
        ks = Zs.real @ wr + Zs.imag @ wi
        order = np.argsort(ks)
        ks, Zs = ks[order], Zs[order]
        lo = np.searchsorted(ks, ky - lip * rad, side="left")
        hi = np.searchsorted(ks, ky + lip * rad, side="right")
        for i in np.flatnonzero(hi > lo):
            if np.min(np.max(np.abs(Zs[lo[i]:hi[i]] - Zy[i]), axis=1)) <= rad[i]:
                keep[i] = False
    # among the rows of Y, in their order: each against the earlier ones kept (already
    # decided), found by the same windows in the rows sorted by projection
    idx = np.flatnonzero(keep)
    order = idx[np.argsort(ky[idx], kind="stable")]
    ks = ky[order]
    for i in idx:
        lo = np.searchsorted(ks, ky[i] - lip * rad[i], side="left")
        hi = np.searchsorted(ks, ky[i] + lip * rad[i], side="right")
        near = order[lo:hi]
        near = near[(near < i) & keep[near]]
        if len(near) and np.min(np.max(np.abs(Zy[near] - Zy[i]), axis=1)) <= rad[i]:
            keep[i] = False
    return keep


# ---------------------------------------------------------------------------------------
# symmetries: maps of the angles that leave the system unchanged
# ---------------------------------------------------------------------------------------

#: The maps of one angle tried: x -> s x + k pi, (s, k).
_ANGLE_MAPS = ((1.0, 0.0), (1.0, 1.0), (-1.0, 0.0), (-1.0, 1.0))
#: Legs with more private angles than this are not searched (4^k candidate maps).
MAX_BLOCK = 6
#: Groups larger than this are not used (their orbits would be tracked as they come).
MAX_GROUP = 4096


@dataclass(frozen=True)
class Symmetry:
    """A group of maps g(x) = sign * x + shift (shift a multiple of pi in some angles)
    under which the homotopy system is invariant, H(g(x); theta) = H(x; theta), for every
    x and every parameter of the homotopy's family (:func:`symmetry`). Row 0 is the
    identity. A universal joint's two angles (a, b) and (a + pi, pi - b) point its
    outgoing axis the same way, turned half a turn about it: flipping both universal
    joints of a U-P-U leg leaves the leg's ends where they were (Tsai's 3-UPU: 8 joint
    configurations for every pose). Monodromy, the trace test and the parameter homotopy
    then track one solution per orbit and map its endpoint to the others (the paths of
    g(x) are g of the paths of x)."""

    sign: np.ndarray  # (G, n)
    shift: np.ndarray  # (G, n)

    @classmethod
    def identity(cls, n: int) -> Symmetry:
        """The trivial group of ``n`` unknowns."""
        return cls(np.ones((1, n)), np.zeros((1, n)))

    @property
    def order(self) -> int:
        return int(self.sign.shape[0])

    def apply(self, X: np.ndarray) -> np.ndarray:
        """The images of the rows of X, (G N, n): all of X under each map in turn."""
        X = np.asarray(X)
        return (X[None, :, :] * self.sign[:, None, :] + self.shift[:, None, :]).reshape(
            -1, X.shape[1])


def symmetry(model) -> Symmetry:
    """The symmetry group of the topology's homotopy system (:class:`Symmetry`; only the
    identity when there is none), found once per topology: for each leg, the angles only
    that leg's closure rows read, every map x -> +-x + k pi of them (4^k candidates, k at
    most :data:`MAX_BLOCK`) kept when H is unchanged to 1e-10 at random complex points
    and random parameters of the family (rigid legs: :func:`_random_theta`, and a point of
    the straight segment between two of them, where the paths run); the group is the
    product of the legs' maps."""
    return model.topology.cached("homotopy:symmetry", lambda: _find_symmetry(model))


def _find_symmetry(model) -> Symmetry:
    import itertools

    sys = _system(model)
    n = sys.n
    ident = Symmetry.identity(n)
    if not np.any(sys.periodic):
        return ident
    rng = np.random.default_rng(5)
    tha, thb = _random_theta(sys, model, rng), _random_theta(sys, model, rng)
    ths = [tha, tha + (0.3 + 0.4j) * (thb - tha)]
    xs = [rng.normal(size=n) + 1j * rng.normal(size=n) for _ in range(2)]
    row_leg = np.asarray(model.topology.row_leg)
    legs_maps = []
    for leg in sorted(set(int(v) for v in row_leg if v >= 0)):
        cols = [j for j in np.flatnonzero(sys.periodic)
                if sys.reads[:, j].any() and set(row_leg[sys.reads[:, j]]) == {leg}]
        if not cols or len(cols) > MAX_BLOCK:
            continue
        cand = np.array(list(itertools.product(range(len(_ANGLE_MAPS)), repeat=len(cols)))[1:])
        sgn = np.ones((len(cand), n))
        sft = np.zeros((len(cand), n))
        for c, j in enumerate(cols):
            sgn[:, j] = [_ANGLE_MAPS[k][0] for k in cand[:, c]]
            sft[:, j] = [_ANGLE_MAPS[k][1] * np.pi for k in cand[:, c]]
        keep = np.ones(len(cand), bool)
        for th in ths:
            for x in xs:
                h0 = sys.eval(x[None], th[None], np.zeros((1, sys.nth), complex))[0][0]
                X = x[None, :] * sgn + sft
                TH = np.repeat(th[None], len(X), 0)
                Hg = sys.eval(X, TH, np.zeros_like(TH))[0]
                keep &= np.max(np.abs(Hg - h0), axis=1) <= 1e-10 * (1 + np.max(np.abs(h0)))
        if keep.any():
            legs_maps.append((np.vstack([np.ones((1, n)), sgn[keep]]),
                              np.vstack([np.zeros((1, n)), sft[keep]])))
    if not legs_maps or np.prod([len(m[0]) for m in legs_maps]) > MAX_GROUP:
        return ident
    sign, shift = ident.sign, ident.shift
    for s2, k2 in legs_maps:  # the product: the legs' maps act on disjoint angles
        sign = (sign[:, None, :] * s2[None, :, :]).reshape(-1, n)
        shift = (shift[:, None, :] + k2[None, :, :]).reshape(-1, n)
    return Symmetry(sign, shift)


def _orbits(model, S: np.ndarray, sym: Symmetry) -> np.ndarray | None:
    """Indices of one row of S per orbit of ``sym`` when S is a union of whole orbits of
    ``sym.order`` distinct points each (else None: then every row is tracked)."""
    if sym.order == 1:
        return np.arange(len(S))
    sc = np.asarray(model.x_scale, dtype=float)
    C = _canonical(model, S)
    left = np.ones(len(S), bool)
    reps = []
    for i in range(len(S)):
        if not left[i]:
            continue
        img = _canonical(model, sym.apply(C[i:i + 1]))
        hit = [int(np.argmin(d)) if np.min(d) < 1e-6 else -1
               for d in (np.max(np.abs(C - y) / sc, axis=1) for y in img)]
        if min(hit) < 0 or len(set(hit)) != sym.order or not left[hit].all():
            return None
        left[hit] = False
        reps.append(i)
    return np.asarray(reps, dtype=int)


def track_orbits(sys: _System, sym: Symmetry, reps: np.ndarray, *args: Any,
                 **kwargs: Any) -> _Paths:
    """:func:`track` of the rows ``reps`` only, their endpoints mapped by every element of
    ``sym`` (the paths of g(x) are g of the paths of x): (G N) paths, map-major."""
    P = track(sys, reps, *args, **kwargs)
    G = sym.order
    if G == 1:
        return P
    return _Paths(sym.apply(P.x), np.tile(P.status, G), np.tile(P.cond, G), np.tile(P.t, G),
                  P.steps)


# ---------------------------------------------------------------------------------------
# start systems by monodromy
# ---------------------------------------------------------------------------------------

@dataclass
class StartSystem:
    """Random complex parameters ``theta`` = (q_a, p, c) and all the solutions found there
    (``solutions``, one row each), with how they were found."""

    theta: np.ndarray
    solutions: np.ndarray
    loops: int
    time: float
    #: why monodromy stopped: "bound" (the structure's known count reached), "trace"
    #: (the trace test passed: complete), "stale" (``stale`` loops found nothing and the
    #: trace test was not run or failed), "max_loops" or "time" (the deadline; such a
    #: start system is never stored or called complete)
    stopped: str = "stale"
    #: the trace test's residual (NaN: not run; see :mod:`optkin.solvers.trace`)
    trace: float = float("nan")

    @property
    def verified(self) -> bool:
        """Known complete: the structure's bound reached or the trace test passed."""
        return self.stopped in ("bound", "trace")

    @property
    def root_count(self) -> int:
        return int(self.solutions.shape[0])

    def representatives(self, model) -> tuple[Symmetry, np.ndarray]:
        """The topology's symmetry group and the indices of one solution per orbit (every
        solution and the identity when the solutions are not whole free orbits), found
        once per start system."""
        got = self.__dict__.get("_reps")
        if got is None:
            sym = symmetry(model)
            idx = _orbits(model, self.solutions, sym)
            if idx is None:
                sym = Symmetry.identity(self.solutions.shape[1])
                idx = np.arange(self.root_count)
            got = self.__dict__["_reps"] = (sym, idx)
        return got


_PATTERNS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

#: The geometry values that make an entry structural (:func:`structural`).
_SPECIAL = np.array([0.0, np.pi / 2, -np.pi / 2, np.pi, -np.pi, 1.0, -1.0])


def structural(model) -> tuple[tuple[int, float], ...]:
    """The geometry entries (positions in the homotopy's parameters) taken to define the
    family rather than vary within it: those equal to 0, +-1, +-pi/2 or +-pi. In a Khalil
    table they are parallel or perpendicular axes and zero offsets (a planar loop stays
    planar only with them: randomised, the four-bar's start system was a spatial loop's,
    and 6 of its 8 paths failed); in joint chains, the unit entries of joint axes (a
    3-RRR's randomised z axes left the rigid family: its solutions lay at |x| ~ 1e5 and
    monodromy found 2-3 of the 6). They stay fixed, real, in the start system, which is
    built and stored per pattern; a geometry with another pattern gets its own, or starts
    from a shipped one of a wider family (:func:`covering_start`, :func:`homotopy_modes`)."""
    pat = _PATTERNS.get(model)
    if pat is None:
        pat = _PATTERNS[model] = _structural(model)
    return pat


def _structural(model) -> tuple[tuple[int, float], ...]:
    sys = _system(model)
    p = np.asarray(model.p, dtype=float)[sys.p_used]
    hit = np.abs(p[:, None] - _SPECIAL[None, :]) <= 1e-12
    rows = np.flatnonzero(hit.any(axis=1))
    vals = dict(zip(rows.tolist(), _SPECIAL[hit[rows].argmax(axis=1)].tolist()))
    for ix in _rigid_screws(model):  # the axes of passive revolutes (:func:`_keep_rigid`)
        for k in ix[:3]:
            vals.setdefault(int(k), float(p[k]))
    keys = sorted(vals)
    return tuple(zip((sys.na + np.array(keys, int)).tolist(), [vals[k] for k in keys]))


def _rigid_screws(model) -> tuple[tuple[int, ...], ...]:
    """The screws (w, v) of revolutes whose angle is an unknown of the closure, as
    positions among the homotopy's geometry parameters (of ``p_used``; once per
    topology)."""

    def build():
        at = {int(i): k for k, i in enumerate(_system(model).p_used)}
        rev = [tuple(at.get(i, -1) for i in ix)
               for ix in getattr(model.mech, "passive_revolute_screws", ())]
        return tuple(ix for ix in rev if min(ix) >= 0)

    return model.topology.cached("homotopy:rigid", build)


def _keep_rigid(model, pp: np.ndarray, fixed: set[int]) -> np.ndarray:
    """Random complex geometry ``pp`` moved back into the family of rigid legs: the axis w
    of a revolute whose angle is an unknown is structural (:func:`structural`), and its
    v = -w x (a point of the axis) is projected onto w . v = 0, changing only entries not
    in ``fixed``. A screw with w . w != 1 or w . v != 0 is no rotation, and its exponential
    is not 2 pi periodic in the angle (its translation keeps a term in theta itself): the
    start system of a 3-RPS at joint level had a lattice of solutions theta + 2 pi k / |w|,
    and monodromy found thousands of them. Both conditions are linear once w is fixed, so
    the straight parameter paths of the homotopy keep them too (a w normalised at each
    end would not: mid-path it is no unit vector, and paths diverged)."""
    for ix in _rigid_screws(model):
        w, v = pp[list(ix[:3])], pp[list(ix[3:])].copy()
        fv = [c for c in range(3) if ix[3 + c] not in fixed]
        g = sum(w[c] ** 2 for c in fv)
        if fv and abs(g) > 1e-12:
            v[fv] -= (w @ v) * w[fv] / g
        pp[list(ix[3:])] = v
    return pp


def _norm_row(model) -> int | None:
    """The row of the quaternion's norm, if any: its offset stays 0 (with |q|^2 != 1 the
    platform's rotation formula is no rotation, and the family is no longer rigid)."""
    names = list(model.row_names)
    return names.index("quaternion:norm") if "quaternion:norm" in names else None


def _random_theta(sys: _System, model, rng, c: np.ndarray | None = None) -> np.ndarray:
    p = np.asarray(model.p, dtype=float)[sys.p_used]
    size = float(model.length)
    qa = size * (rng.normal(size=sys.na) + 1j * rng.normal(size=sys.na))
    pp = p + (np.abs(p) + 0.1 * size) * (rng.normal(size=p.size) + 1j * rng.normal(size=p.size))
    pattern = structural(model)
    for k, v in pattern:
        pp[k - sys.na] = v
    pp = _keep_rigid(model, pp, {k - sys.na for k, _ in pattern})
    if c is None:
        c = size * (rng.normal(size=sys.n) + 1j * rng.normal(size=sys.n))
        r = _norm_row(model)
        if r is not None:
            c[r] = 0.0
    return np.concatenate([qa, pp, c])


def start_system(model, seed: int = 0, stale: int = 8, max_loops: int = 60,
                 deadline: Any = None, verify: bool = True,
                 trace_options: dict[str, Any] | None = None) -> StartSystem:
    """Monodromy: one solution by construction, grown by random loops (module docstring).

    Where the structure has a known bound on the number of solutions (distance legs:
    6, 40 or 2), reaching it stops at once (``stopped="bound"``). Otherwise a round ends
    after ``stale`` loops in a row without a new solution and, with ``verify``, the
    trace test (:func:`optkin.solvers.trace.trace_test`) decides: passed, the set is
    complete (``stopped="trace"``); failed, another round follows, up to ``max_loops``
    loops in all. ``deadline`` (an :class:`optkin.limits.Deadline`) stops it too.
    ``trace_options``: keywords of the trace test (its ``direction`` and ``slice``)."""
    bound = _enum.known_bound(model)
    t0 = time.perf_counter()
    sys = _system(model)
    tr = _tracker(model)
    rng = np.random.default_rng([int(seed), 7])
    sc = np.asarray(model.x_scale, dtype=float)
    x0 = sc * (rng.normal(size=sys.n) + 1j * rng.normal(size=sys.n))
    q = np.asarray(_enum.layout(model).quat, dtype=int)
    if q.size == 4:  # a unit quaternion (q . q = 1, complex): the norm row's offset is 0
        x0[q] /= np.sqrt(x0[q] @ x0[q])
    th = _random_theta(sys, model, rng, c=np.zeros(sys.n))
    H, _, _ = sys.eval(x0[None, :], th[None, :], np.zeros((1, sys.nth)))
    th[-sys.n:] = H[0]  # with c = 0, H(x0) = F(x0): c0 = F(x0) makes x0 a solution
    # with a symmetry group (:func:`symmetry`) S holds whole orbits and the loops track
    # one solution of each (R): a new endpoint brings its orbit
    sym = symmetry(model)
    R = _canonical(model, x0[None, :])
    S = _distinct(model, np.zeros((0, sys.n)), _canonical(model, sym.apply(R)))
    if len(S) != sym.order:  # x0 a fixed point of some map (probability zero)
        sym = Symmetry.identity(sys.n)
        S = R
    loops = 0
    out_of_time = False
    trace = None
    while True:
        quiet = 0
        while loops < max_loops and (bound is None or len(S) < bound) and (
                quiet < stale or (bound is not None and len(S) < bound)):
            if deadline is not None and deadline.expired():
                out_of_time = True
                break
            loops += 1
            th1, th2 = _random_theta(sys, model, rng), _random_theta(sys, model, rng)
            Y = R
            for a, b in ((th, th1), (th1, th2), (th2, th)):
                g = np.exp(2j * np.pi * rng.uniform())
                P = track(sys, Y, a, b, g, tracker=tr, deadline=deadline, scale=sc)
                Y = P.x[P.status == "finite"]
                if Y.size == 0:
                    break
            new = _distinct(model, S, _canonical(model, Y)) if Y.size else np.zeros((0, sys.n))
            grew = False
            for y in new:  # one orbit at a time: two new points may share one
                orbit = _distinct(model, S, _canonical(model, sym.apply(y[None])))
                if orbit.shape[0]:
                    S = np.vstack([S, orbit])
                    R = np.vstack([R, y[None]])
                    grew = True
            if grew:
                quiet = 0
            else:
                quiet += 1
        if (bound is not None or not verify or out_of_time or loops >= max_loops
                or (deadline is not None and deadline.expired())):
            break
        from .trace import trace_test

        trace = trace_test(model, StartSystem(th, S, loops, 0.0), seed=seed,
                           deadline=deadline, **(trace_options or {}))
        if trace.passed:
            break
    stopped = ("time" if out_of_time or (deadline is not None and deadline.expired()) else
               "bound" if bound is not None and len(S) >= bound else
               "trace" if trace is not None and trace.passed else
               "stale" if quiet >= stale else "max_loops")
    return StartSystem(th, S, loops, time.perf_counter() - t0, stopped,
                       float("nan") if trace is None else trace.residual)


# ---------------------------------------------------------------------------------------
# start systems on disk
# ---------------------------------------------------------------------------------------

#: Part of a stored start system's name: bump when the system's form changes.
START_VERSION = "5"

#: Where the start systems of the library's topologies ship, inside the package
#: (made by ``python -m optkin.solvers.shipped``; each re-verified on loading and,
#: in the tests, by the trace test).
SHIPPED = Path(__file__).resolve().parent.parent / "data" / "start"


def _start_key(model, seed: int, pattern: tuple | None = None) -> str:
    import hashlib

    pat = structural(model) if pattern is None else pattern
    key = f"{model.topology.key}|{START_VERSION}|{int(seed)}|{pat}"
    return hashlib.sha256(key.encode()).hexdigest()[:24]


def _start_path(model, seed: int):
    from ..model import compiled as cc

    d = cc.cache_dir()
    if d is None:
        return None
    return d / f"optkin_start_{_start_key(model, seed)}.npz"


def shipped_path(model, pattern: tuple | None = None) -> Path:
    """Where the package keeps (or would keep) this topology's start system for the
    pattern of ``model`` (or ``pattern``; ``()`` the generic one): built with seed 0, used
    for every seed (the seed then picks the gamma paths)."""
    return SHIPPED / f"start_{_start_key(model, 0, pattern)}.npz"


def shipped_start(model, pattern: tuple | None = None) -> StartSystem | None:
    """The shipped start system for the pattern of ``model`` (or ``pattern``), read and
    verified once per topology and pattern; None when the package has none."""
    pat = structural(model) if pattern is None else pattern

    def load():
        path = shipped_path(model, pat)
        if path.is_file() and path.stat().st_size < 1 << 26:
            S = _read_start(model, path.read_bytes(), pat)
            if S is not None:
                return S
        return False  # none (cached: the file is looked for once)

    S = model.topology.cached(("homotopy:shipped", pat), load)
    return S if S is not False else None


def covering_start(model) -> StartSystem | None:
    """A shipped start system of this topology from a wider family: its structural entries
    (read off its parameters: exactly 0, +-1, +-pi/2 or +-pi where the others are random
    complex numbers) a subset of this geometry's, the widest such; None when there is none.
    Its paths reach every isolated solution of this geometry too (parameter homotopy: the
    geometry lies in its family). Looked for once per topology and pattern."""
    pat = structural(model)
    sys = _system(model)

    def find():
        import io

        best, size = False, -1
        mine = dict(pat)
        for f in sorted(SHIPPED.glob("start_*.npz")):
            try:
                with np.load(io.BytesIO(f.read_bytes()), allow_pickle=False) as z:
                    theta = z["theta"]
                    shape = z["solutions"].shape
            except (OSError, ValueError, KeyError, TypeError):
                continue
            if theta.shape != (sys.nth,) or len(shape) != 2 or shape[1] != sys.n:
                continue
            g = theta[sys.na:sys.na + sys.np_]
            hit = (g.imag == 0) & np.isin(g.real, _SPECIAL)
            theirs = {sys.na + int(k): float(g[k].real) for k in np.flatnonzero(hit)}
            if len(theirs) <= size or any(mine.get(k) != v for k, v in theirs.items()):
                continue
            S = _read_start(model, f.read_bytes(), tuple(sorted(theirs.items())))
            if S is not None:
                best, size = S, len(theirs)
        return best

    S = model.topology.cached(("homotopy:covering", pat), find)
    return S if S is not False else None


def _verified(model, theta: np.ndarray, sols: np.ndarray, pattern: tuple | None = None
              ) -> bool:
    """The stored solutions solve their system, nonsingular and distinct (a damaged or
    foreign file is recomputed, never trusted)."""
    sys = _system(model)
    if theta.shape != (sys.nth,) or sols.ndim != 2 or sols.shape[1] != sys.n or not len(sols):
        return False
    pat = structural(model) if pattern is None else pattern
    if any(theta[k] != v for k, v in pat):  # another family's start system
        return False
    n = sols.shape[0]
    Hv, J, _ = sys.eval(sols, np.repeat(theta[None], n, 0), np.zeros((n, sys.nth), complex))
    if not np.all(np.isfinite(Hv)) or np.max(np.abs(Hv)) > 1e-8 * max(1.0, np.abs(theta).max()):
        return False
    with np.errstate(all="ignore"):
        if np.any(np.abs(np.linalg.det(J)) < 1e-12):
            return False
    return _distinct(model, np.zeros((0, sys.n)), _canonical(model, sols)).shape[0] == n


def _read_start(model, data: bytes, pattern: tuple | None = None) -> StartSystem | None:
    import io

    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            theta, sols = z["theta"], z["solutions"]
            loops, took = int(z["loops"]), float(z["time"])
            stopped, trace = str(z["stopped"]), float(z["trace"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if (stopped in ("bound", "trace", "stale", "max_loops")
            and _verified(model, theta, sols, pattern)):
        return StartSystem(theta, sols, loops, took, stopped, trace)
    return None


def save_start(S: StartSystem, path: Path) -> None:
    """Write ``S`` to ``path`` atomically (.npz, no pickles)."""
    import os
    import tempfile

    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".start-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez(f, theta=S.theta, solutions=S.solutions, loops=S.loops, time=S.time,
                     stopped=S.stopped, trace=S.trace)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def load_or_build_start(model, seed: int = 0, deadline: Any = None) -> StartSystem:
    """The topology's start system: shipped with the package, or for ``seed`` from the
    disk cache (beside the compiled code), when one verifies; else built by
    :func:`start_system` and stored in the cache."""
    from ..model.compiled import _read_private

    S = shipped_start(model)  # one per topology, whatever the seed
    if S is not None:
        return S
    path = _start_path(model, seed)
    if path is not None and path.exists():
        with contextlib.suppress(OSError, ValueError):
            S = _read_start(model, _read_private(path, 1 << 26))
            if S is not None:
                return S
    S = start_system(model, seed, deadline=deadline)
    if path is not None and S.stopped != "time":
        with contextlib.suppress(OSError):
            save_start(S, path)
    return S


# ---------------------------------------------------------------------------------------
# assembly modes by parameter homotopy
# ---------------------------------------------------------------------------------------

def _generic_first(model) -> bool:
    """The package ships no start system for this geometry's pattern, and one of a wider
    family (:func:`covering_start`). Decided by the package's files alone, never by what
    a cache holds, so that a result does not depend on what ran before."""
    pat = structural(model)
    if not pat or shipped_start(model) is not None:
        return False
    return covering_start(model) is not None


@functools.lru_cache(maxsize=256)
def _gamma_draws(seed: int) -> tuple[float, ...]:
    """The uniform draws in [-1, 1) behind the gamma of each try of :func:`homotopy_modes`
    for ``seed`` (made once: a new numpy Generator costs 25-40 us, a 3-RPR's whole call
    about 1 ms)."""
    rng = np.random.default_rng([int(seed), 11])
    return tuple(float(rng.uniform(-1, 1)) for _ in range(TRIES))


def homotopy_modes(mech, qa: Any, seed: int = 0, start: StartSystem | None = None,
                   tol: float = 1e-10, time_limit: float | None = None,
                   threads: int = 1, _checked: bool = False) -> SolutionSet:
    """Every real assembly mode of ``mech`` at ``qa`` by parameter homotopy (see the
    module docstring). ``start`` defaults to the topology's start system for ``seed``
    (built by monodromy on first use and kept for the process).

    ``time_limit`` (s) bounds the tracking; building a start system gets at least 60 s
    or the time budget (:func:`optkin.limits.time_budget`) when smaller. Out of time, the
    result says so (status ``"time_limit"``, ``complete`` False) and a start system
    cut short is neither stored nor reused. ``threads`` share the paths (at least
    :data:`PATHS_PER_THREAD` each: a 6-6 platform's 40 paths on 2 threads)."""
    from .._checks import check_number
    from ..limits import Deadline, time_budget
    from ..model import get_model
    from .common import check_mechanism, check_qa, make_result, newton

    check_mechanism(mech, "homotopy")
    model = get_model(mech)
    if not _checked:  # (assembly_modes has checked them)
        qa = check_qa(model, qa)
    t0 = time.perf_counter()
    sys = _system(model)
    tr = _tracker(model)
    budget = (time_budget() if time_limit is None else
              min(check_number(time_limit, "time_limit", lo=0.0, lo_open=True), time_budget()))
    def exact_start():  # this pattern's own: stored, or built by monodromy now
        key = ("homotopy:start", int(seed), structural(model))
        S = model.topology.cached(key, lambda: load_or_build_start(
            model, seed, Deadline(min(max(60.0, budget), time_budget()))))
        if S.stopped == "time":  # cut short: never reused
            model.topology.forget(key)
        return S

    # a geometry whose pattern of structural entries has no start system stored yet (a
    # 3-RPR with a base point at the origin, a planar 6-6 platform) starts from a shipped
    # one of a wider family (:func:`covering_start`): its paths reach every isolated
    # solution of the special geometry too; only when some fail is the pattern's own built
    generic = start is None and _generic_first(model)
    if generic:
        start = covering_start(model)
    elif start is None:
        start = exact_start()
    deadline = Deadline(budget)
    t_start = time.perf_counter()
    target = np.concatenate([qa, np.asarray(model.p, dtype=float)[sys.p_used],
                             np.zeros(sys.n)]).astype(complex)
    sc = np.asarray(model.x_scale, dtype=float)

    def tally(Q):  # (finite indices, canonical endpoints, singular, path jumps, bad)
        fin = np.flatnonzero(Q.status == "finite")
        Xf = _canonical(model, Q.x[fin])
        singular = Q.cond[fin] > 1e10
        ns = Xf[~singular]  # path jumping: two nonsingular endpoints at one point
        jumped = ns.shape[0] - _distinct(model, np.zeros((0, sys.n)), ns, 1e-8).shape[0]
        return fin, Xf, singular, jumped, int(np.sum(Q.status == "failed")) + jumped

    # every path along one gamma path (which start goes to which end depends on it); a
    # failed path (one that swings far out near parameters where a solution goes to
    # infinity) or two paths ending at one point (a jump) send all of them along another
    # gamma, up to ``TRIES`` times; the best account is kept
    def paths(start):
        draws = _gamma_draws(int(seed))
        P = acc = None
        tries = 0
        while tries < TRIES:
            tries += 1
            gamma = np.exp(2j * np.pi * GAMMA_SPREAD[min(tries, len(GAMMA_SPREAD)) - 1]
                           * draws[tries - 1])
            sym, reps = start.representatives(model)
            Q = track_orbits(sys, sym, start.solutions[reps], start.theta, target, gamma,
                             tracker=tr, deadline=deadline, scale=sc, threads=threads)
            a = tally(Q)
            if P is None or a[4] < acc[4]:
                P, acc = Q, a
            if acc[4] == 0 or deadline.expired():
                break
        return P, acc, tries

    P, acc, tries = paths(start)
    if generic and acc[4] and not deadline.expired():
        start, generic = exact_start(), False
        P, acc, tries = paths(start)
    late = deadline.expired() and bool(np.any(P.status == "failed"))  # paths cut short
    fin, Xf, singular, jumped, _ = acc
    real = np.max(np.abs(Xf.imag) / sc, axis=1) < 1e-6
    # singular endpoints that may be real (a double root on a singularity, a point of a
    # real continuum): imaginary parts small beside the point's size; far from real ones
    # (a 6-6 platform's complex solutions near infinity, |x| ~ 1e5 with cond 1e13) cannot
    # hide a real mode
    size = 1.0 + np.max(np.abs(Xf) / sc, axis=1)
    near_real = np.max(np.abs(Xf.imag) / sc, axis=1) <= 1e-3 * size
    out: list[KinResult] = []
    seen: list[np.ndarray] = []
    ang = np.asarray(model.x_angle, dtype=bool)
    for x in Xf[real & ~singular].real:
        # polished at the target already: the real part usually closes the real model to
        # round-off (its Newton steps only where it does not)
        x1 = model.canonical_x(x)
        if seen:  # the same mode? (angles compared modulo 2 pi: pi and -pi are one)
            dif = np.abs(np.asarray(seen) - x1)
            dif[:, ang] = np.abs(np.mod(dif[:, ang] + np.pi, 2 * np.pi) - np.pi)
            if np.min(np.max(dif / sc, axis=1)) < 1e-6:
                continue
        stats = SolverStats("parameter-homotopy", start.time, time.perf_counter() - t_start,
                            0, "converged", {"paths": start.root_count})
        r = make_result(model, qa, x1, tol, 0, stats)
        if not (r.success and r.residual <= 1e-3 * tol):
            x2, _, nit, ok = newton(model, qa, x, tol, 8)
            if not ok:
                continue
            x1 = model.canonical_x(x2)
            r = make_result(model, qa, x1, tol, nit, stats)
        seen.append(x1)
        out.append(r)
    out.sort(key=lambda r: tuple(np.round(r.x / sc, 9)))
    n_fail = int(np.sum(P.status == "failed"))
    n_inf = int(np.sum(P.status == "at_infinity"))
    (bound,) = model.topology.cached("homotopy:bound", lambda: (_enum.known_bound(model),))
    short = bound is not None and start.root_count < bound  # monodromy missed some
    cut = start.stopped == "time"
    # without a known bound, a start system is complete only by the trace test
    unverified = not short and not cut and not start.verified
    complete = (n_fail == 0 and jumped == 0 and not short and not cut and not late
                and not unverified)
    account = EnumerationStats("homotopy", start.root_count, int(fin.size), n_inf,
                               int(singular.sum()), n_fail, start.root_count, complete)
    msg = (f"{len(out)} real assembly modes from {start.root_count} paths: {fin.size} "
           f"finite ({int(singular.sum())} singular), {n_inf} at infinity, {n_fail} failed"
           + (f", {jumped} path jumps" if jumped else "")
           + ("; every path accounted for" if complete else "; not every path accounted for")
           + (f"; the start system has {start.root_count} of the {bound} solutions the "
              "structure has: some modes may be missing" if short else "")
           + ("; monodromy stopped at the time limit: the start system may be incomplete"
              if cut else "")
           + (f"; the start system's {start.root_count} solutions are not verified complete "
              f"(trace test residual {start.trace:.1e}): some modes may be missing"
              if unverified else "")
           + (f"; tracking stopped at the time limit of {budget:g} s" if late else ""))
    status = TIME_LIMIT if late or cut else OPTIMAL if out else INFEASIBLE
    info = {"success": bool(out) and not (late or cut), "status": status,
            "message": msg, "complete": complete, "root_count": start.root_count,
            "bound": bound,
            "monodromy_loops": start.loops, "start_time": start.time, "gamma_tries": tries,
            "monodromy_stopped": start.stopped, "trace": start.trace,
            "start_pattern": "wider" if generic else "own",
            "singular_near_real": int(np.sum(singular & near_real)),
            "time": time.perf_counter() - t0, "method": "homotopy"}
    # isolated solutions only when every path is accounted for and none ends singular (a
    # continuum's points end singular paths); else not known here
    dim = 0 if complete and not singular.any() else None
    info["dimension"] = dim
    return SolutionSet(out, "assembly modes", info, seed=int(seed), dimension=dim,
                       stats=account)
