"""Singularity loci by pseudo-arclength continuation.

A singular locus of a 2-DoF mechanism (or of a 2-D section of a 3-DoF one) is a curve in the
configuration manifold {Phi(q_a, x) = 0}: the zero set of one more scalar function c on it,
det W_p (parallel singularities; det A of Chablat & Wenger 1998), one B_jj (serial
singularities of leg j), or q_a,j - limit (a joint-limit boundary). With the variables
v = (q_a, x), the fixed ones of a section removed (z), the curve is the solution set of

    G(z) = [Phi(z); c(z)] = 0,        G : R^n -> R^(n-1),

traced here by a pseudo-arclength predictor-corrector: the tangent is the null vector of
dG/dz (oriented by continuity), the corrector is Newton's method on [G; t.(z - z_pred)] = 0,
the step adapts to the Newton effort and the turning of the tangent, and a curve stops when
it closes (angles are periodic), leaves the user's box in the plane, or fails to continue.
Simple branch points are detected by a sign change of det [dG/dz; t^T] between two steps,
located by bisection, and every branch through them is followed (the second branch starts
from the branch point along the null direction of dG/dz orthogonal to the first branch).
Seeds come from sign changes of c on a coarse grid of a closed-form chart of the manifold
(the platform coordinates with each leg's closed-form inverse, Özgören; planar platforms
whose legs are distance constraints, :mod:`optkin.model.charts`), refined by Newton; the
grid only seeds: every point returned is a corrected point of the curve. Mechanisms
without such a chart (Khalil tables) are seeded by multi-start Newton on the model.

For a 1-DoF mechanism (the four-bar) the curve is the configuration space itself
(``kind="closure"``, G = Phi) and its bifurcation points are the C-space singularities of
Modern Robotics 7.3 (Lynch & Park 2017).
"""

from __future__ import annotations

import math
import numbers
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .._checks import MAX_ABS, as_float, as_matrix, as_vector, check_mechanism, check_number
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..limits import SAFETY, Deadline, check_size, largest_size, memory_budget, show
from ..mechanism import Mechanism
from ..model import get_model
from ..model.charts import PlanarChart, planar_chart, translational_chart
from ..model.compiled import FastFn, map_shared
from ..results import INACCURATE, MEMORY_LIMIT, OPTIMAL, TIME_LIMIT, jsonable

__all__ = ["Curve", "SingularCurves", "singular_curves", "SINGULAR_CURVES_DEFAULTS",
           "augmented_system"]

TWO_PI = 2.0 * np.pi
#: Largest continuation step, in scaled units (lengths / mechanism size, radians).
DEFAULT_STEP = 0.08

#: Options of :func:`singular_curves`.
SINGULAR_CURVES_DEFAULTS: dict[str, Any] = {
    "bounds": None,  # box [[lo, hi], [lo, hi]] in the plane the curves stop on; None: the
    # reach of the legs, [-pi, pi] for angles (periodic when their range is 2 pi)
    "grid": None,  # seeding grid per chart axis (None: 32); it only seeds the continuation
    "limits": None,  # actuated joint limits {name: (lo, hi)}, traced by kind="limit"
    "step": None,  # largest continuation step, scaled units (None: DEFAULT_STEP = 0.08)
    "tol": 1e-11,  # corrector tolerance on max |G|
    "max_steps": None,  # continuation steps each way along one curve (None: 20000, lowered
    # to what the memory budget allows)
    "cusps": None,  # detect cusps of the parallel curves (None: when the plane is the joint
    # space of a section)
}


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % TWO_PI - np.pi


# ---------------------------------------------------------------------------------------
# the augmented system: Functions built once per (topology, condition, fixed variables)
# ---------------------------------------------------------------------------------------


class _Functions:
    """G(z; fixed, lim, p) = [Phi; c] and dG/dz of one topology as CasADi Functions, the
    geometry p their last input (shared by every geometry of the topology)."""

    def __init__(self, model: Any, cond: str, fixed_idx: tuple[int, ...]) -> None:
        mech = model.mech
        na, nx = model.na, model.nx
        if model.m != nx:
            raise MechanismError(
                f"{mech.name}: singular curves need as many closure rows as unknowns x "
                f"(got {model.m} rows for {nx} unknowns); redundantly actuated or spatial "
                "quaternion platforms are not supported"
            )
        nv = na + nx
        free_idx = tuple(i for i in range(nv) if i not in fixed_idx)
        qa, x, p, phi = model.symbols
        v = ca.vertcat(qa, x)
        Wp = ca.jacobian(phi, x)
        Wa = ca.jacobian(phi, qa)
        lim = ca.SX.sym("lim")
        if cond == "parallel":
            c = ca.det(Wp)
        elif cond.startswith("serial:"):
            j = int(cond.split(":")[1])
            c = Wa[j, j]
        elif cond.startswith("limit:"):
            j = int(cond.split(":")[1])
            c = qa[j] - lim
        elif cond == "closure":
            c = None
        else:
            raise MechanismError(f"unknown singularity kind {cond!r}")
        rows = phi if c is None else ca.vertcat(phi, c)
        self.n_rows = int(rows.shape[0])
        if self.n_rows != len(free_idx) - 1:
            raise MechanismError(
                f"{mech.name}: {len(free_idx)} free variables and {self.n_rows} equations "
                f"do not make a curve; fix {len(free_idx) - 1 - self.n_rows} more "
                "variable(s) with fixed={name: value} (a 2-D section)"
            )
        z = ca.SX.sym("z", len(free_idx))
        pf = ca.SX.sym("fixed", len(fixed_idx))
        parts = []
        iz = ip = 0
        for i in range(nv):
            if i in fixed_idx:
                parts.append(pf[ip])
                ip += 1
            else:
                parts.append(z[iz])
                iz += 1
        vv = ca.vertcat(*parts)
        F = ca.Function("F", [v, lim, p], [rows])
        G = F(vv, lim, p)
        J = ca.jacobian(G, z)
        self.G = ca.Function("G", [z, pf, lim, p], [G])
        # one packed input and output: fewer conversions per call in the tracer's loop
        w = ca.vertcat(z, pf, lim)
        self.nz = len(free_idx)
        self.GJw = ca.Function("GJw", [w, p], [ca.densify(ca.vertcat(G, ca.vec(J)))])
        # labels of a full point v: det W_p and diag W_a (the working mode, where B is
        # diagonal: fully parallel mechanisms)
        if model.fully_parallel:
            bdiag = ca.vertcat(*[Wa[j, j] for j in range(na)])
        else:
            bdiag = ca.SX.zeros(na, 1)
        self.aux = ca.Function("aux", [v, p], [ca.det(Wp), bdiag])
        self.cfun = None if c is None else ca.Function("c", [v, lim, p], [c])
        self._maps: dict[int, Any] = {}
        self._corrector: ca.Function | None = None
        self._tag = f"curves:{model.topology.key}:{cond}:{','.join(map(str, fixed_idx))}"
        self._late: dict[str, Any] = {}

    def late(self, name: str, make: Any) -> Any:
        """``make()`` compiled in the background (:class:`~optkin.model.compiled.LateCompiled`),
        once per topology, condition and fixed variables: the tracer's corrector and
        G/J evaluation, called once or more per traced point (interpreted, 13 us a call
        on a 3-RPR's section; a 3-RRR's 3-D aspects made 234 278 corrector calls)."""
        lc = self._late.get(name)
        if lc is None:
            from ..model.compiled import LateCompiled

            lc = self._late[name] = LateCompiled(f"{self._tag}:{name}", make())
        return lc

    def corrector(self) -> ca.Function:
        """The first :data:`CORRECTOR_STEPS` Newton steps of the tracer's corrector (its
        :meth:`_Tracer.correct`) in one Function, the graph built on first use: from the
        prediction ``u`` (scaled), Newton on [G; t.(u - a)] = 0; each step taken only while
        the point has not converged (max ``|G|`` < tol and ``|t.(u - a)|`` < 1e-10) and while the
        steps stay finite and within ``cap``. Outputs: the point, ``done`` (converged; the
        step count ``k`` at which it did and J there), ``failed`` (a step not finite or
        longer than cap). Neither: the caller goes on from the point in Python."""
        if self._corrector is None:
            nz, m = self.nz, self.n_rows
            nw = int(self.GJw.size1_in(0))
            u0, a, t, scl = (ca.SX.sym(n, nz) for n in ("u", "a", "t", "scl"))
            rest = ca.SX.sym("rest", nw - nz)
            tol, cap = ca.SX.sym("tol"), ca.SX.sym("cap")
            p = ca.SX.sym("p", self.GJw.size1_in(1))

            def gj(u):
                out = self.GJw(ca.vertcat(u * scl, rest), p)
                return out[:m], ca.reshape(out[m:], m, nz) * ca.repmat(scl.T, m, 1)

            u, done, fail = u0, ca.SX(0), ca.SX(0)
            kk, Jd = ca.SX(0), ca.SX.zeros(m, nz)
            for k in range(CORRECTOR_STEPS):
                g, J = gj(u)
                fm = ca.dot(t, u - a)
                conv = ca.logic_and(ca.mmax(ca.fabs(g)) < tol, ca.fabs(fm) < 1e-10)
                act = ca.logic_and(ca.logic_not(done), ca.logic_not(fail))
                new = ca.logic_and(act, conv)
                kk = ca.if_else(new, k, kk)
                Jd = ca.if_else(new, J, Jd)
                done = ca.logic_or(done, new)
                du = -ca.solve(ca.vertcat(J, t.T), ca.vertcat(g, fm))
                go = ca.logic_and(act, ca.logic_not(conv))
                ok = ca.norm_2(du) <= cap  # false for inf and NaN too
                fail = ca.logic_or(fail, ca.logic_and(go, ca.logic_not(ok)))
                u = ca.if_else(ca.logic_and(go, ok), u + du, u)
            # the tangent continuing t at the converged point: [J; t] x = e_n, normalised
            e = ca.DM.zeros(nz, 1)
            e[-1] = 1.0
            x = ca.solve(ca.vertcat(Jd, t.T), e)
            self._corrector = ca.Function(
                "corrector", [u0, a, t, rest, scl, tol, cap, p],
                [u, done, fail, kk, Jd, x / ca.norm_2(x)],
                ["u", "a", "t", "rest", "scl", "tol", "cap", "p"],
                ["u_out", "done", "failed", "k", "J", "tangent"])
        return self._corrector

    def mapped(self, key: int, build: Any) -> Any:
        f = self._maps.get(key)
        if f is None:
            f = build()
            if len(self._maps) < 64:
                self._maps[key] = f
        return f


class _System:
    """The augmented system of one mechanism (its topology's :class:`_Functions` with the
    geometry filled in), for the plane variables v = (q_a, x) with ``fixed_idx`` fixed."""

    def __init__(self, model: Any, cond: str, fixed_idx: tuple[int, ...]) -> None:
        mech = model.mech
        self.mech, self.model, self.cond = mech, model, cond
        self.fn = model.cached(("singular_curves", cond, fixed_idx),
                               lambda: _Functions(model, cond, fixed_idx))
        na, nx = model.na, model.nx
        self.na, self.nx, self.nv = na, nx, na + nx
        self.names = tuple(mech.active_names) + tuple(model.x_names)
        act_rev = [bool(mech.revolute[i]) for i in mech.active_index]
        self.periodic = np.array(act_rev + list(model.x_angle), dtype=bool)
        self.scale = np.where(self.periodic, 1.0, model.length)
        self.fixed_idx = fixed_idx
        self.free_idx = tuple(i for i in range(self.nv) if i not in fixed_idx)
        self.n_rows = self.fn.n_rows
        self.nz = self.fn.nz
        self.geo = model.p
        # call buffers (~1 us per evaluation instead of ~60 us through the Python wrapper),
        # made on first use: systems made only for det A and diag B need neither
        self._fast_fn: FastFn | None = None
        self._corr_fn: FastFn | None = None
        self._lock = threading.Lock()

    def G(self, z: np.ndarray, pfix: np.ndarray, lim: float) -> np.ndarray:
        return np.array(self.fn.G(z, pfix, lim, self.geo))

    def G_many(self, U: np.ndarray, pfix: np.ndarray, lim: float) -> np.ndarray:
        """G at the rows of U (N, nz): (n_rows, N)."""
        return _in_blocks(self.fn, self.fn.G, -(10**9), U.T, [1, 2, 3],
                          (pfix, lim, self.geo))[0]

    @property
    def _fast(self) -> FastFn:
        lc = self.fn.late("GJw", lambda: self.fn.GJw)
        lc.poll()
        if self._fast_fn is None or self._fast_fn.f is not lc.f:
            self._fast_fn = FastFn(lc.f, fixed=(self.geo,))
        return self._fast_fn

    @property
    def _corr(self) -> FastFn:
        lc = self.fn.late("corrector", self.fn.corrector)
        lc.poll()
        if self._corr_fn is None or self._corr_fn.f is not lc.f:
            self._corr_fn = FastFn(lc.f, fixed=(self.geo,))
        return self._corr_fn

    def gjw(self, w: np.ndarray) -> np.ndarray:
        """[G; vec(dG/dz)] at w = [z; fixed; lim] (through the buffer; thread-safe)."""
        with self._lock:
            (out,) = self._fast(w)
            return out.copy()

    def correct(self, up, a, t, rest, scl, tol, cap):
        """The corrector's first steps (:meth:`_Functions.corrector`): (u, done, failed,
        k, J, tangent), copies (thread-safe)."""
        with self._lock:
            fn = self._corr  # once: a second look may meet the compiled code just landed
            r = fn(up, a, t, rest, scl, tol, cap)
            ok = fn.ok()
            u, done, failed, k = r[0].copy(), bool(r[1][0]), bool(r[2][0]), int(r[3][0])
            # J (m, nz), dense: stored by columns
            J = r[4].reshape(self.nz, self.n_rows).T.copy() if done else None
            tn = r[5].copy() if done else None
        if not ok or not np.all(np.isfinite(u)):
            return u, False, True, 0, None, None
        return u, done, failed, k, J, tn

    def aux_one(self, v: np.ndarray) -> tuple[float, np.ndarray]:
        d, b = self.fn.aux(v, self.geo)
        return float(np.array(d).ravel()[0]), np.array(b).ravel()

    def c_many(self, V: np.ndarray, lim: float) -> np.ndarray:
        """c at the columns of V (nv, N)."""
        return _in_blocks(self.fn, self.fn.cfun, 0, V, [1, 2], (lim, self.geo))[0].ravel()

    def aux_many(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = V.shape[1]
        d, b = _in_blocks(self.fn, self.fn.aux, -(10**6), V, [1], (self.geo,))
        return d.ravel(), b.reshape(self.na, n)


#: Newton steps of the tracer's corrector taken in one call of a Function
#: (:meth:`_Functions.corrector`); a point not converged by then goes on in Python.
CORRECTOR_STEPS = 4

#: Columns per evaluation of a mapped Function of the augmented system: larger sets are
#: evaluated in blocks (CasADi's evaluation of a map holds about 2.5 KB per column).
BLOCK = 2048


def _in_blocks(fns: Any, f: ca.Function, tag: int, V: np.ndarray, shared: list[int],
               rest: tuple) -> list[np.ndarray]:
    """``f`` at the columns of ``V`` (its first input), the other inputs ``rest`` shared by
    every column, in blocks of at most :data:`BLOCK` columns (power-of-two maps built once
    per topology); outputs stacked by column."""
    N = V.shape[1]
    n = 1
    while n < min(N, BLOCK):
        n *= 2
    fm = fns.mapped(tag - n, lambda: map_shared(f, f"{f.name()}_{n}", n, shared))
    outs: list[list[np.ndarray]] = [[] for _ in range(f.n_out())]
    for s in range(0, N, n):
        blk = V[:, s:s + n]
        k = blk.shape[1]
        if k < n:
            blk = np.hstack([blk, np.repeat(blk[:, -1:] if k else np.zeros((V.shape[0], 1)),
                                            n - k, axis=1)])
        res = fm(blk, *rest)
        res = res if isinstance(res, (list, tuple)) else [res]
        for j, r in enumerate(res):
            outs[j].append(np.array(r)[:, :k])
    return [np.hstack(o) if o else np.zeros((f.size1_out(j), 0)) for j, o in enumerate(outs)]


def augmented_system(mech: Mechanism, cond: str = "parallel",
                     fixed: Sequence[int] = ()) -> _System:
    """The augmented system of ``mech`` (see the module docstring); its Functions are built
    once per topology, condition and fixed variables."""
    return _System(get_model(mech), cond, tuple(sorted(fixed)))


# ---------------------------------------------------------------------------------------
# results
# ---------------------------------------------------------------------------------------


@dataclass
class Curve:
    """One traced curve.

    Attributes
    ----------
    kind : str
        ``"parallel"`` (det W_p = 0), ``"serial:j"`` (B_jj = 0, leg j from 0),
        ``"limit:j"`` (q_a,j at a limit) or ``"closure"`` (the C-space of a 1-DoF chain).
    v : ndarray (N, nv)
        The ordered points, all variables (q_a then x), in the order of ``names``.
    points : ndarray (N, 2)
        The points in the plane.
    residual : ndarray (N,)
        max ``|G|`` at every point (the closure rows and the singularity condition).
    closed : bool
        The curve closes on itself (angles modulo 2 pi).
    ends : tuple of str
        How each end stopped: ``"closed"``, ``"boundary"``, ``"branch"``, ``"stalled"``,
        ``"max_steps"``, or ``"jumped"`` (the run came round a loop that does not pass
        through its start: the corrector had jumped to another, closed, curve).
    working_mode : ndarray (N, na) of int, or None
        Signs of the B_jj at every point (leg mechanisms).
    """

    kind: str
    v: np.ndarray
    points: np.ndarray
    residual: np.ndarray
    closed: bool
    ends: tuple[str, str]
    working_mode: np.ndarray | None = None
    det_Wp: np.ndarray | None = None
    B: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.v)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "n_points": len(self.v), "closed": self.closed,
                "ends": list(self.ends), "max_residual": float(np.max(self.residual)),
                "points": self.points.tolist()}


#: How a curve ends when it stopped early (:attr:`SingularCurves.stopped_early`).
_EARLY = ("max_steps", "stalled", "jumped")


@dataclass
class SingularCurves:
    """The singular loci of a mechanism in a plane (see :func:`singular_curves`).

    Attributes
    ----------
    curves : list of Curve
        Each traced curve (kind, full points, plane points, residuals).
    branch_points, cusps : ndarray
        Full points (q_a then x) where curves cross, and cusps of the parallel curves.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"`` (also when no curve lies in
        the box: ``count`` 0, the message says so), ``"inaccurate"`` when some curve's
        residual exceeds 1e-9, ``"time_limit"`` / ``"memory_limit"`` when tracing stopped
        at a budget (``success`` False, the curves incomplete).
    """

    mechanism: str
    names: tuple[str, ...]
    plane: tuple[str, str]
    fixed: dict[str, float]
    curves: list[Curve]
    branch_points: np.ndarray
    cusps: np.ndarray
    success: bool
    status: str
    message: str
    bounds: np.ndarray
    periodic: tuple[bool, bool]
    n_seeds: int = 0
    time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        return (f"SingularCurves({self.mechanism!r}, plane={self.plane}, {self.count} curve(s), "
                f"{len(self.branch_points)} branch point(s), {len(self.cusps)} cusp(s), "
                f"status={self.status!r})")

    @property
    def count(self) -> int:
        return len(self.curves)

    @property
    def max_residual(self) -> float:
        return float(max((np.max(c.residual) for c in self.curves), default=0.0))

    @property
    def stopped_early(self) -> bool:
        """Some curve stopped before closing or leaving the box (stalled, max_steps or
        jumped to another curve): a region it should bound may be missing or merged."""
        return any(e in _EARLY for c in self.curves for e in c.ends)

    def __len__(self) -> int:
        return len(self.curves)

    def __iter__(self):
        return iter(self.curves)

    def of_kind(self, prefix: str) -> list[Curve]:
        return [c for c in self.curves if c.kind.startswith(prefix)]

    def polylines(self, kind: str | None = None) -> list[np.ndarray]:
        """Plane polylines, split where a periodic coordinate wraps (for drawing)."""
        out = []
        for c in self.curves:
            if kind is not None and not c.kind.startswith(kind):
                continue
            P = np.vstack([c.points, c.points[:1]]) if c.closed else c.points
            out += _split_wrapped(P, self.periodic)
        return out

    def plane_points(self, V: np.ndarray) -> np.ndarray:
        """Plane coordinates of full points V (n, nv), periodic ones wrapped to [-pi, pi)."""
        P = np.asarray(V, dtype=float).reshape(-1, len(self.names))[:, list(self.info["plane_index"])]
        for k in range(2):
            if self.periodic[k]:
                P[:, k] = _wrap(P[:, k])
        return P

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        kinds: dict[str, int] = {}
        for c in self.curves:
            k = c.kind.split(":")[0]
            kinds[k] = kinds.get(k, 0) + 1
        return jsonable({
            "mechanism": self.mechanism, "plane": list(self.plane), "fixed": self.fixed,
            "success": self.success, "status": self.status, "message": self.message,
            "count": self.count, "counts": kinds, "n_points": int(sum(len(c) for c in self.curves)),
            "max_residual": self.max_residual,
            "n_branch_points": int(len(self.branch_points)),
            "branch_points": self.branch_points.tolist(),
            "branch_points_plane": self.plane_points(self.branch_points).tolist(),
            "n_cusps": int(len(self.cusps)), "cusps": self.cusps.tolist(),
            "cusps_plane": self.plane_points(self.cusps).tolist(),
            "actuator_singularities_plane": self.plane_points(
                self.info.get("actuator_singularities", np.zeros((0, len(self.names))))).tolist(),
            "time": self.time, "n_seeds": self.n_seeds,
            "curves": [c.to_dict() for c in self.curves],
        })

    def plot(self, path: str | None = None, ax: Any = None, title: str | None = None) -> Any:
        """Draw the curves in the plane (PNG when ``path`` is given)."""
        from .aspects import _check_path, _plot_curves

        _check_path(path)
        return _plot_curves(self, path, ax, title)


def _split_wrapped(P: np.ndarray, periodic: tuple[bool, bool]) -> list[np.ndarray]:
    P = np.array(P, dtype=float)
    for k in range(2):
        if periodic[k]:
            P[:, k] = _wrap(P[:, k])
    if len(P) < 2:
        return [P]
    jump = np.zeros(len(P) - 1, dtype=bool)
    for k in range(2):
        if periodic[k]:
            jump |= np.abs(np.diff(P[:, k])) > np.pi
    cuts = np.flatnonzero(jump) + 1
    return [s for s in np.split(P, cuts) if len(s) > 1]


# ---------------------------------------------------------------------------------------
# the tracer
# ---------------------------------------------------------------------------------------


class _Tracer:
    def __init__(self, sys: _System, pvals: np.ndarray, lim: float, plane_idx: tuple[int, int],
                 bounds: np.ndarray, hmax: float, tol: float, max_steps: int,
                 budget: _Budget | None = None) -> None:
        self.sys = sys
        self.budget = budget if budget is not None else _Budget()
        self.pfix = pvals
        self.lim = lim
        self.rest = np.concatenate([pvals, [lim]])  # w = [z; fixed; lim]: its fixed part
        self._w: np.ndarray | None = None
        self.free = np.array(sys.free_idx)
        self.per = sys.periodic[self.free]
        self.scl = sys.scale[self.free]
        # plane coordinates as indices into z
        self.pz = [int(np.flatnonzero(self.free == i)[0]) for i in plane_idx]
        self.bounds = bounds
        self.box_periodic = [bool(self.per[k]) and bounds[j][1] - bounds[j][0] >= TWO_PI - 1e-9
                             for j, k in enumerate(self.pz)]
        self.hmax = hmax
        self.hmin = hmax * 1e-4
        self.tol = tol
        self.max_steps = max_steps
        self.curves_z: list[np.ndarray] = []
        self.curves_bb: list[tuple[np.ndarray, np.ndarray]] = []
        self.bps: list[np.ndarray] = []
        self.bp_dirs: list[np.ndarray] = []

    # scaled evaluation ------------------------------------------------------------
    def GJ(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        w = self._w
        if w is None:  # [z; fixed; lim]: the fixed part written once
            w = self._w = np.concatenate([u * self.scl, self.rest])
        else:
            np.multiply(u, self.scl, out=w[:u.shape[0]])
        out = self.sys.gjw(w)
        m = self.sys.n_rows
        g = out[:m]
        J = out[m:].reshape(self.sys.nz, m).T * self.scl
        return g, J

    def tangent(self, J: np.ndarray) -> np.ndarray:
        _, _, vt = np.linalg.svd(J)
        return vt[-1]

    def diff(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """a - b with periodic coordinates wrapped."""
        d = a - b
        d[self.per] = _wrap(d[self.per])
        return d

    def newton_free(self, u: np.ndarray, iters: int = 30) -> tuple[np.ndarray, bool]:
        """Min-norm Newton onto G = 0 (seeds)."""
        for _ in range(iters):
            g, J = self.GJ(u)
            if np.max(np.abs(g)) < self.tol:
                return u, True
            du = np.linalg.lstsq(J, -g, rcond=None)[0]
            n = np.linalg.norm(du)
            if n > 0.5:
                du *= 0.5 / n
            u = u + du
        g, _ = self.GJ(u)
        return u, bool(np.max(np.abs(g)) < self.tol)

    def correct(self, up: np.ndarray, t: np.ndarray, anchor: np.ndarray | None = None,
                iters: int = 10) -> tuple[np.ndarray | None, int]:
        """Newton on [G; t.(u - anchor)] = 0 from the prediction up: the first
        :data:`CORRECTOR_STEPS` steps in one call (:meth:`_Functions.corrector`), the rest
        here."""
        a = up if anchor is None else anchor
        m = self.sys.n_rows
        u, done, failed, k0, J, tn = self.sys.correct(up, a, t, self.rest, self.scl,
                                                      self.tol, 4 * self.hmax)
        self.last_tangent = None
        if failed:
            return None, CORRECTOR_STEPS
        if done:
            self.last_J = J
            if np.all(np.isfinite(tn)):  # else the caller solves for it (or uses the SVD)
                self.last_tangent = tn
            return u, k0
        M = np.empty((m + 1, u.shape[0]))
        F = np.empty(m + 1)
        for k in range(CORRECTOR_STEPS, iters):
            g, J = self.GJ(u)
            F[:m] = g
            F[m] = t @ (u - a)
            if np.abs(g).max() < self.tol and abs(F[m]) < 1e-10:
                self.last_J = J
                return u, k
            M[:m] = J
            M[m] = t
            try:
                du = np.linalg.solve(M, -F)
            except np.linalg.LinAlgError:
                return None, k
            u = u + du
            if math.sqrt(du @ du) > 4 * self.hmax:
                return None, k
        g, J = self.GJ(u)
        if np.max(np.abs(g)) < self.tol:
            self.last_J = J
            return u, iters
        return None, iters

    def in_box(self, u: np.ndarray) -> bool:
        for j, k in enumerate(self.pz):
            if self.box_periodic[j]:
                continue
            val = u[k] * self.scl[k]
            lo, hi = self.bounds[j]
            if self.per[k]:
                # angle boxes narrower than 2 pi: compare the wrapped value
                val = lo + (val - lo) % TWO_PI
            if val < lo or val > hi:
                return False
        return True

    def near_known(self, u: np.ndarray, thr: float) -> bool:
        npd = ~self.per
        for Z, (lo, hi) in zip(self.curves_z, self.curves_bb):
            if np.any(u[npd] < lo - thr) or np.any(u[npd] > hi + thr):
                continue
            if _dist_to_polyline(u, Z, self.per) < thr:
                return True
        return False

    def add_curve(self, Z: np.ndarray) -> None:
        npd = ~self.per
        self.curves_z.append(Z)
        self.curves_bb.append((Z[:, npd].min(axis=0), Z[:, npd].max(axis=0)))

    def aug_det(self, J: np.ndarray, t: np.ndarray) -> float:
        return float(np.linalg.det(np.vstack([J, t])))

    # one direction -------------------------------------------------------------
    def run(self, u0: np.ndarray, t0: np.ndarray, stop_at_bps: bool,
            start_bp: int | None = None) -> tuple[list[np.ndarray], str]:
        pts = [u0]
        u, t = u0, t0
        _, J = self.GJ(u)
        d_prev = self.aug_det(J, t)
        h = self.hmax * 0.25
        arc = 0.0
        budget = self.budget
        # the points and tangents so far, in arrays grown by doubling (the check for a
        # loop not through u0 reads them every few steps)
        P_all = np.empty((64, len(u0)))
        T_all = np.empty((64, len(u0)))
        P_all[0], T_all[0] = u0, t0
        for k_step in range(self.max_steps):
            if budget.exhausted():
                return pts, budget.reason
            up = u + h * t
            un, nit = self.correct(up, t)
            if un is None:
                h *= 0.5
                if h < self.hmin:
                    return pts, self._stall_kind(u)
                continue
            Jn = self.last_J
            tn = self.last_tangent  # from the corrector's call when it converged there
            if tn is None:
                try:  # the tangent continuing t: [Jn; t] x = e_n (no SVD)
                    M = np.vstack([Jn, t])
                    e = np.zeros(len(t))
                    e[-1] = 1.0
                    tn = np.linalg.solve(M, e)
                    tn /= np.linalg.norm(tn)
                except np.linalg.LinAlgError:
                    tn = self.tangent(Jn)
                    if tn @ t < 0:
                        tn = -tn
            step = np.linalg.norm(un - u)
            if tn @ t < np.cos(0.25) or step > 2 * h:
                h *= 0.5
                if h < self.hmin:
                    return pts, self._stall_kind(u)
                continue
            d_new = self.aug_det(Jn, tn)
            if d_prev * d_new < 0:
                self._branch_point(u, t, un, tn)
            d_prev = d_new
            if not self.in_box(un):
                ub = self._to_boundary(u, un)
                if ub is not None:
                    pts.append(ub)
                return pts, "boundary"
            pts.append(un)
            k_pt = len(pts) - 1
            if k_pt >= len(P_all):
                P_all = np.concatenate([P_all, np.empty_like(P_all)])
                T_all = np.concatenate([T_all, np.empty_like(T_all)])
            P_all[k_pt], T_all[k_pt] = un, tn
            budget.points += 1
            arc += step
            # closure
            if arc > 3 * h and np.linalg.norm(self.diff(un, u0)) < 1.2 * max(h, step):
                return pts, "closed"
            # a loop that does not pass through u0: the corrector has jumped to another
            # curve, a closed one, and would go round it until max_steps (a 3-RRR section
            # traced with step 0.25 went round one 290 times, and the faces of that
            # arrangement took hours); a point passed again in the same direction (not a
            # crossing of the curve with itself) ends the run
            if k_step % 4 == 3 and k_pt > 11:
                D = P_all[1:k_pt - 9] - un
                D[:, self.per] = _wrap(D[:, self.per])
                near = np.einsum("ij,ij->i", D, D) < (0.6 * max(h, step)) ** 2
                if near.any() and np.any(T_all[1:k_pt - 9][near] @ tn > np.cos(0.25)):
                    return pts, "jumped"
            if stop_at_bps and arc > 2 * h:
                for ib, b in enumerate(self.bps):
                    if ib == start_bp and arc < 4 * self.hmax:
                        continue
                    if np.linalg.norm(self.diff(un, b)) < 0.6 * max(h, step):
                        pts.append(b.copy())
                        return pts, "branch"
            u, t = un, tn
            if nit <= 3:
                h = min(h * 1.5, self.hmax)
            elif nit >= 6:
                h *= 0.7
        return pts, "max_steps"

    def _stall_kind(self, u: np.ndarray) -> str:
        """'boundary' when the curve stopped on the box (e.g. a leg length reaching 0,
        where |P - A| is not differentiable), else 'stalled'."""
        for j, k in enumerate(self.pz):
            if self.box_periodic[j]:
                continue
            lo, hi = self.bounds[j]
            val = u[k] * self.scl[k]
            if min(abs(val - lo), abs(val - hi)) < 1e-3 * (hi - lo):
                return "boundary"
        v = u * self.scl
        for k, i in enumerate(self.free):
            if i < self.sys.na and not self.sys.periodic[i] and abs(v[k]) < 1e-3 * self.sys.model.length:
                return "degenerate"  # a leg length reaches 0: the model row is not smooth
        return "stalled"

    def _to_boundary(self, u_in: np.ndarray, u_out: np.ndarray) -> np.ndarray | None:
        """The curve point on the box edge between an inside and an outside point."""
        for j, k in enumerate(self.pz):
            if self.box_periodic[j]:
                continue
            lo, hi = self.bounds[j]
            a, b = u_in[k] * self.scl[k], u_out[k] * self.scl[k]
            for edge in (lo, hi):
                if (a - edge) * (b - edge) <= 0 and a != b:
                    s = (edge - a) / (b - a)
                    ug = u_in + s * (u_out - u_in)
                    e = np.zeros_like(ug)
                    e[k] = 1.0
                    ub, _ = self.correct(ug, e, anchor=ug)
                    if ub is not None:
                        return ub
        return None

    def _branch_point(self, ua, ta, ub, tb) -> None:
        """Locate a branch point between ua and ub (bisection on the augmented det)."""
        _, Ja = self.GJ(ua)
        da = self.aug_det(Ja, ta)
        lo, hi = 0.0, 1.0
        d = ub - ua
        dn = d / np.linalg.norm(d)
        best = None
        for _ in range(40):
            s = 0.5 * (lo + hi)
            um, _ = self.correct(ua + s * d, dn)
            if um is None:
                break
            _, Jm = self.GJ(um)
            tm = self.tangent(Jm)
            if tm @ ta < 0:
                tm = -tm
            dm = self.aug_det(Jm, tm)
            best = um
            if dm * da > 0:
                lo = s
            else:
                hi = s
            if (hi - lo) * np.linalg.norm(d) < 1e-10:
                break
        if best is None:
            return
        for b in self.bps:
            if np.linalg.norm(self.diff(best, b)) < 1e-6:
                return
        self.bps.append(best)
        self.bp_dirs.append(dn)

    def branch_seeds(self, ib: int) -> list[tuple[np.ndarray, np.ndarray]]:
        """Start points on the other branch(es) through branch point ib."""
        b, t1 = self.bps[ib], self.bp_dirs[ib]
        _, J = self.GJ(b)
        _, _, vt = np.linalg.svd(J)
        N = vt[-2:]  # the 2-D null space at a simple branch point
        c = N @ t1
        tp = N.T @ np.array([-c[1], c[0]])
        tp /= np.linalg.norm(tp)
        out = []
        for h in (0.05 * self.hmax, 0.2 * self.hmax):
            for s in (1.0, -1.0):
                ug = b + s * h * tp
                u, _ = self.correct(ug, tp, anchor=ug)
                if u is not None and np.linalg.norm(self.diff(u, b)) > 0.3 * h:
                    out.append((u, s * tp))
            if out:
                break
        return out


def _dist_to_polyline(u: np.ndarray, Z: np.ndarray, per: np.ndarray) -> float:
    if len(Z) == 0:
        return np.inf
    D = Z - u
    D[:, per] = _wrap(D[:, per])
    if len(Z) == 1:
        return float(np.linalg.norm(D[0]))
    a = D[:-1]
    seg = np.diff(Z, axis=0)
    seg[:, per] = _wrap(seg[:, per])
    L2 = np.einsum("ij,ij->i", seg, seg)
    s = np.clip(-np.einsum("ij,ij->i", a, seg) / np.where(L2 > 0, L2, 1), 0, 1)
    e = a + s[:, None] * seg
    return float(np.sqrt(np.min(np.einsum("ij,ij->i", e, e))))


def _trace_all(tr: _Tracer, seeds: list[np.ndarray], dedup: float) -> list[tuple[np.ndarray, bool, tuple[str, str]]]:
    """Trace every seed not already on a curve, and every branch through every branch point."""
    out = []
    done_bps = 0
    queue: list[tuple[np.ndarray, np.ndarray | None, int | None]] = [(s, None, None) for s in seeds]
    while queue or done_bps < len(tr.bps):
        if tr.budget.exhausted():
            break
        if not queue:
            ib = done_bps
            done_bps += 1
            for u, tp in tr.branch_seeds(ib):
                if not tr.near_known(u, 0.2 * np.linalg.norm(tr.diff(u, tr.bps[ib]))):
                    queue.append((u, tp, ib))
            continue
        u0, tdir, ib = queue.pop(0)
        if ib is None:
            # a raw grid seed: skip it when it is already near a traced curve, else correct it
            if tr.near_known(u0, 2 * dedup):
                continue
            u0, ok = tr.newton_free(u0)
            if not ok or not tr.in_box(u0) or tr.near_known(u0, dedup):
                continue
        elif tr.near_known(u0, 1e-3 * tr.hmax):
            continue
        _, J = tr.GJ(u0)
        t0 = tr.tangent(J)
        if tdir is not None and t0 @ tdir < 0:
            t0 = -t0
        if ib is not None:
            # from a branch point: go outwards only, then back to the branch point
            fwd, end1 = tr.run(u0, t0, True, ib)
            bwd, end2 = [tr.bps[ib].copy()], "branch"
            if end1 == "closed":
                end2 = "closed"
            Z = np.array(bwd + fwd)
        else:
            fwd, end1 = tr.run(u0, t0, True)
            if end1 == "closed":
                Z, end2 = np.array(fwd), "closed"
            else:
                bwd, end2 = tr.run(u0, -t0, True)
                Z = np.array(bwd[::-1] + fwd[1:])
        closed = end1 == "closed"
        tr.add_curve(Z)
        out.append((Z, closed, (end2, end1)))
    return out


#: Limit curves of distance legs from their closed form (:func:`_limit_arcs`); False traces
#: them by continuation like every other curve (kept for the tests that compare the two).
CLOSED_FORM_LIMITS = True
#: Their points lie this fraction of the step apart (in the scaled variables).
LIMIT_SPACING = 0.5


def _distance_section(chart: PlanarChart, tr: _Tracer, fixed: dict[int, float],
                      pidx: tuple[int, ...]) -> np.ndarray | None:
    """The platform coordinates X0 (1, nx) of a section whose curves have closed forms:
    every leg a distance leg with one posture, the orientation fixed and the plane the
    platform's (x, y), not periodic; None otherwise."""
    na = tr.sys.na
    if (not bool(np.all(chart.length_actuated)) or chart.n_combos != 1
            or set(fixed) != {na + j for j in chart.orientation}
            or [pidx[0] - na, pidx[1] - na] not in (list(chart.translation),
                                                    list(chart.translation)[::-1])
            or any(tr.box_periodic)):
        return None
    X0 = np.zeros((1, tr.sys.nx))
    for i, v in fixed.items():
        X0[0, i - na] = v
    return X0


def _limit_arcs(chart: PlanarChart, tr: _Tracer, leg: int, lim: float,
                fixed: dict[int, float], pidx: tuple[int, ...]
                ) -> list[tuple[np.ndarray, bool, tuple[str, str]]] | None:
    """The curve q_a,leg = lim of a section at a fixed orientation in the platform's (x, y),
    in closed form, when every leg is a distance leg (a 3-RPR): leg ``leg``'s platform point
    on its circle |P - C| = lim, so the platform's origin on the circle of the same radius
    about C - P0 (P0: that point with the platform at the origin, in the section's
    orientation), the other legs' lengths from their closed-form inverses. The same curve
    as continuation traces, as ``_trace_all`` returns it: (points in the tracer's scaled
    free variables, closed, ends), cut exactly where it leaves the plane's box, with points
    every :data:`LIMIT_SPACING` step in the scaled variables (and at most 0.25 rad of
    turning between points, as the tracer). None where this does not apply (legs with
    postures, another section or plane): the caller traces it."""
    sys = tr.sys
    na = sys.na
    X0 = _distance_section(chart, tr, fixed, pidx) if CLOSED_FORM_LIMITS else None
    if X0 is None:
        return None
    free = np.array(sys.free_idx)
    qa = np.zeros((1, na))
    qa[0, leg] = lim
    C, r = chart.centres_radii(qa)
    r = float(r[0, leg])
    t = list(chart.translation)
    centre = C[0, leg] - chart.platform_points(X0)[0, leg]  # the origin's circle, in (x, y)
    if not (np.all(np.isfinite(centre)) and np.isfinite(r) and r > 0):
        return None
    # the plane's coordinates in the order of pidx
    k = [t.index(pidx[0] - na), t.index(pidx[1] - na)]
    c2 = centre[k]
    bounds = np.asarray(tr.bounds, dtype=float)

    def full(th: np.ndarray) -> tuple[np.ndarray, bool]:
        X = np.repeat(X0, len(th), axis=0)
        X[:, t] = centre + r * np.stack([np.cos(th), np.sin(th)], 1)
        V, ok = next(iter(chart.full_points(X, leg, np.full(len(th), lim))))
        return V, bool(np.all(ok) and np.all(np.isfinite(V)))

    # where the circle crosses the box's edges: c + r (cos, sin)[axis] = edge
    cuts = []
    for ax in (0, 1):
        for edge in bounds[ax]:
            w = (edge - c2[ax]) / r
            if abs(w) < 1.0:
                a = math.acos(w) if ax == 0 else math.asin(w)
                cuts += [a, -a] if ax == 0 else [a, math.pi - a]
    cuts = np.sort(np.mod(np.array(cuts), 2 * np.pi))

    def inside(th: float) -> bool:
        p = c2 + r * np.array([math.cos(th), math.sin(th)])
        return bool(np.all(p >= bounds[:, 0]) and np.all(p <= bounds[:, 1]))

    if len(cuts) == 0:
        runs = [(0.0, 2 * np.pi, True)] if inside(0.0) else []
    else:
        ends = np.r_[cuts, cuts[0] + 2 * np.pi]
        runs = [(a, b, False) for a, b in zip(ends[:-1], ends[1:])
                if b - a > 1e-12 and inside(0.5 * (a + b))]
    return _sampled_runs(tr, full, runs, free)


def _sampled_runs(tr: _Tracer, full: Any, runs: list[tuple[float, float, bool]],
                  free: np.ndarray, fine: int = 257
                  ) -> list[tuple[np.ndarray, np.ndarray, tuple[str, str]]] | None:
    """Curves given by a parametrisation ``full(s) -> (full points, all valid)`` over the
    ``runs`` (s from a to b, closed or cut by the box), as ``_trace_all`` returns them:
    each run sampled at ``fine`` values of s, then points every :data:`LIMIT_SPACING` step
    of its arc in the scaled variables (and more where it turns by more than 0.25 rad
    between points). None when a point is not valid (the caller traces the curve)."""
    out = []
    for a, b, closed in runs:
        tf = np.linspace(a, b, fine)
        V, ok = full(tf)
        if not ok:  # a leg without its closed form somewhere: trace the curves instead
            return None
        U = V[:, free] / tr.scl
        D = np.diff(U, axis=0)
        D[:, tr.per] = _wrap(D[:, tr.per])
        seg = np.linalg.norm(D, axis=1)
        arc = np.r_[0.0, np.cumsum(seg)]
        T = D / np.where(seg > 0, seg, 1.0)[:, None]
        turn = float(np.sum(np.arccos(np.clip(np.einsum("ij,ij->i", T[:-1], T[1:]), -1, 1))))
        n = max(int(np.ceil(arc[-1] / (LIMIT_SPACING * tr.hmax))), int(np.ceil(turn / 0.25)),
                3 if closed else 1)
        tk = np.interp(np.linspace(0.0, arc[-1], n + 1), arc, tf)
        if closed:
            tk = tk[:-1]
        V, ok = full(tk)
        if not ok:
            return None
        out.append((V[:, free] / tr.scl, closed,
                    ("closed", "closed") if closed else ("boundary", "boundary")))
    return out


#: The parallel curves of such sections from their closed form (:func:`_conic_arcs`).
CLOSED_FORM_CONICS = True


def _conic_arcs(chart: PlanarChart, tr: _Tracer, fixed: dict[int, float],
                pidx: tuple[int, ...]
                ) -> list[tuple[np.ndarray, bool, tuple[str, str]]] | None:
    """The parallel singularity curve of a section at a fixed orientation in the
    platform's (x, y), when every leg is a distance leg (a 3-RPR), in closed form: with
    d_i = P_i - C_i (platform point less base point) the rows of the Jacobian of
    |d_i|^2 / 2 in (x, y, phi) are (d_i, (P_i - p) x d_i), each linear in the platform's
    position p, and the cubic terms of their determinant cancel (the first two columns of
    its cubic part are p itself in every row): a conic in (x, y). Its six coefficients are
    fitted to that determinant at 16 points of the box (refused, and the curve traced,
    unless the fit is exact to 1e-9 of the determinant's size, the conic is not
    degenerate, and the points then solve the tracer's system to 1e-9). Its real points
    are P(s) = P0 - (grad Q(P0) . u) / (u' M u) u, u = (cos s, sin s), s in [0, pi): the
    second point where the line through a point P0 of the conic in direction u meets it
    (every conic, the hyperbola's branches split at its asymptotes' directions). Cut
    exactly at the box's edges and sampled as :func:`_limit_arcs` samples the legs'
    circles. Returned as ``_trace_all`` returns curves; [] when the conic has no point in
    the box; None where this does not apply."""
    sys = tr.sys
    na = sys.na
    X0 = (_distance_section(chart, tr, fixed, pidx)
          if CLOSED_FORM_CONICS and chart.n_legs == 3 else None)
    if X0 is None:
        return None
    free = np.array(sys.free_idx)
    t = list(chart.translation)
    k = [t.index(pidx[0] - na), t.index(pidx[1] - na)]  # plane order -> (x, y) order
    bounds = np.asarray(tr.bounds, dtype=float)  # in the plane's order
    C, _ = chart.centres_radii(np.zeros((1, na)))
    C = C[0]
    R = chart.platform_points(X0)[0]  # P_i - p (the platform at the origin)

    def det(W: np.ndarray) -> np.ndarray:  # W (N, 2) in (x, y)
        d = W[:, None, :] + R[None] - C[None]
        third = R[None, :, 0] * d[..., 1] - R[None, :, 1] * d[..., 0]
        return np.linalg.det(np.concatenate([d, third[..., None]], axis=2))

    def to_xy(Wp: np.ndarray) -> np.ndarray:  # plane order -> (x, y)
        W = np.empty_like(Wp)
        W[:, k] = Wp
        return W

    g = np.linspace(0.0, 1.0, 4)
    G1, G2 = np.meshgrid(bounds[0, 0] + g * (bounds[0, 1] - bounds[0, 0]),
                         bounds[1, 0] + g * (bounds[1, 1] - bounds[1, 0]))
    Wp = np.stack([G1.ravel(), G2.ravel()], 1)
    c0 = Wp.mean(axis=0)
    L = float(np.max(np.abs(Wp - c0))) or 1.0
    Z = (Wp - c0) / L  # the plane's coordinates, centred and scaled
    val = det(to_xy(Wp))
    basis = np.stack([Z[:, 0] ** 2, Z[:, 0] * Z[:, 1], Z[:, 1] ** 2, Z[:, 0], Z[:, 1],
                      np.ones(len(Z))], 1)
    coef = np.linalg.lstsq(basis, val, rcond=None)[0]
    size = float(np.max(np.abs(val))) or 1.0
    if not np.all(np.isfinite(coef)) or np.max(np.abs(basis @ coef - val)) > 1e-9 * size:
        return None
    a, b, c, dd, e, f = coef / size
    M = np.array([[a, b / 2], [b / 2, c]])
    Q3 = np.array([[a, b / 2, dd / 2], [b / 2, c, e / 2], [dd / 2, e / 2, f]])
    if abs(np.linalg.det(Q3)) < 1e-9 * max(1.0, float(np.max(np.abs(Q3)))) ** 3:
        return None  # a pair of lines (or worse): traced

    def Q(P: np.ndarray) -> np.ndarray:
        x, y = P[..., 0], P[..., 1]
        return a * x * x + b * x * y + c * y * y + dd * x + e * y + f

    def grad(P: np.ndarray) -> np.ndarray:
        return np.stack([2 * a * P[..., 0] + b * P[..., 1] + dd,
                         b * P[..., 0] + 2 * c * P[..., 1] + e], -1)

    # a real point P0 of the conic: on a principal axis through its centre, or (a
    # parabola) along its axis through the box's centre; none: no real point
    lam, vec = np.linalg.eigh(M)
    P0 = None
    if abs(np.linalg.det(M)) > 1e-12 * max(1.0, float(np.max(np.abs(M)))) ** 2:
        cen = np.linalg.solve(M, -0.5 * np.array([dd, e]))
        q0 = float(Q(cen))
        for li, vi in zip(lam, vec.T):
            if li != 0 and -q0 / li >= 0:
                P0 = cen + np.sqrt(-q0 / li) * vi
                break
    else:
        v0 = vec[:, int(np.argmin(np.abs(lam)))]
        gv = float(grad(np.zeros(2)) @ v0)
        if gv != 0:
            P0 = -float(Q(np.zeros(2))) / gv * v0
    if P0 is None:
        return []

    def point(s: np.ndarray) -> np.ndarray:
        u = np.stack([np.cos(s), np.sin(s)], 1)
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = -(u @ grad(P0)) / np.einsum("ij,jk,ik->i", u, M, u)
        return P0 + tau[:, None] * u

    def angle(P: np.ndarray) -> float:  # the s of a point of the conic
        w = P - P0
        if np.linalg.norm(w) < 1e-12 * (1 + np.linalg.norm(P0)):
            gr = grad(P0)  # P0 itself: the tangent's direction
            w = np.array([-gr[1], gr[0]])
        return float(np.mod(np.arctan2(w[1], w[0]), np.pi))

    # breaks in s: the box's edges (in the scaled coordinates) and the asymptotes
    zb = (bounds - c0[:, None]) / L
    brk = []
    for ax in (0, 1):
        for edge in zb[ax]:
            # Q on the line z[ax] = edge: a quadratic in the other coordinate
            o = 1 - ax
            if ax == 0:
                A2, B2, C2 = c, b * edge + e, a * edge * edge + dd * edge + f
            else:
                A2, B2, C2 = a, b * edge + dd, c * edge * edge + e * edge + f
            roots = np.roots([A2, B2, C2]) if abs(A2) > 1e-14 else (
                np.array([-C2 / B2]) if abs(B2) > 1e-14 else np.zeros(0))
            for r in roots:
                if abs(r.imag) <= 1e-12 * (1 + abs(r.real)):
                    P = np.zeros(2)
                    P[ax], P[o] = edge, r.real
                    brk.append(angle(P))
    if abs(c) > 1e-14:
        for r in np.roots([c, b, a]):
            if abs(r.imag) <= 1e-12 * (1 + abs(r.real)):
                brk.append(float(np.mod(np.arctan(r.real), np.pi)))
    else:
        brk.append(np.pi / 2)
        if abs(b) > 1e-14:
            brk.append(float(np.mod(np.arctan(-a / b), np.pi)))

    def inside(P: np.ndarray) -> bool:
        return bool(np.all(np.isfinite(P)) and np.all(P >= zb[:, 0] - 1e-12)
                    and np.all(P <= zb[:, 1] + 1e-12))

    brk = np.unique(np.array(brk))
    if len(brk) == 0:  # an ellipse that no edge meets: inside the box, or not at all
        runs = [(0.0, np.pi, True)] if inside(point(np.array([0.5]))[0]) else []
    else:
        ends = np.r_[brk, brk[0] + np.pi]
        runs = [(lo, hi, False) for lo, hi in zip(ends[:-1], ends[1:])
                if hi - lo > 1e-12 and inside(point(np.array([0.5 * (lo + hi)]))[0])]

    def full(s: np.ndarray) -> tuple[np.ndarray, bool]:
        X = np.repeat(X0, len(s), axis=0)
        X[:, t] = to_xy(c0 + L * point(s))
        V, ok = next(iter(chart.full_points(X)))
        return V, bool(np.all(ok) and np.all(np.isfinite(V)))

    out = _sampled_runs(tr, full, runs, free, fine=1025)
    if out:  # the tracer's own system at the points: else trace the curve
        for Zs, _, _ in out:
            if np.max(np.abs(sys.G_many(Zs * tr.scl, tr.pfix, tr.lim))) > 1e-9:
                return None
    return out


# ---------------------------------------------------------------------------------------
# seeds from closed-form charts of the configuration manifold
# ---------------------------------------------------------------------------------------


def _full_from_x(chart: PlanarChart, X: np.ndarray, fixed_leg: int | None = None,
                 fixed_val: np.ndarray | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Full points V (N, nv) and validity for every posture combination of the legs
    (generated one combination at a time: memory of one combination), each leg's actuated
    value from its closed-form inverse."""
    return chart.full_points(X, fixed_leg, fixed_val)


def _seeds_chart(sys: _System, chart: PlanarChart, cond: str, fixed: dict[int, float],
                 lim: float, n: int, bounds_full: dict[int, tuple[float, float]]
                 ) -> list[np.ndarray]:
    """Seed points (full v) for a curve kind of a mechanism with a closed-form chart."""
    na, nx = sys.na, sys.nx
    fixed_qa = [i for i in fixed if i < na]
    fixed_x = {i - na: v for i, v in fixed.items() if i >= na}
    free_x = [j for j in range(nx) if j not in fixed_x]

    def xbox(j):
        if na + j in bounds_full:
            return bounds_full[na + j]
        if j in chart.orientation:
            return (-np.pi, np.pi)
        return tuple(chart.reach_box()[chart.translation.index(j)])

    pin_leg = None
    pin_kind = None
    if cond.startswith("serial:") or cond.startswith("limit:"):
        pin_leg = int(cond.split(":")[1])
        pin_kind = cond.split(":")[0]
    if fixed_qa:
        if pin_leg is not None or len(fixed_qa) > 1:
            return []
        pin_leg, pin_kind = fixed_qa[0], "fixed"
    seeds: list[np.ndarray] = []
    if pin_leg is None:
        # 2-D chart over the free platform coordinates; sign changes of c
        if len(free_x) != 2:
            return []
        g = [np.linspace(*xbox(j), n) for j in free_x]
        G0, G1 = np.meshgrid(g[0], g[1], indexing="ij")
        X = np.zeros((G0.size, nx))
        for j, val in fixed_x.items():
            X[:, j] = val
        X[:, free_x[0]] = G0.ravel()
        X[:, free_x[1]] = G1.ravel()
        for V, ok in _full_from_x(chart, X):
            seeds += _sign_change_seeds(sys, V, ok, (n, n), lim)
        return seeds
    # a pinned leg: its platform point moves on a circle (fixed joint / limit) or on its
    # serial loci (the leg outstretched or folded)
    free_turn = [j for j in chart.orientation if j in free_x]
    if free_turn:
        # a turning platform with only the pinned leg's constraint: chart (psi, phi), psi
        # the angle of the leg's platform point on its circle
        if pin_kind != "fixed" or len(free_x) != 3 or len(free_turn) != 1:
            return []
        val = fixed[pin_leg]
        psi = np.linspace(-np.pi, np.pi, n, endpoint=False)
        ph = np.linspace(*xbox(free_turn[0]), n)
        PS, PH = np.meshgrid(psi, ph, indexing="ij")
        PS, PH = PS.ravel(), PH.ravel()
        P = chart.circle(pin_leg, val, PS)
        X = np.zeros((len(PS), nx))
        for j, v in fixed_x.items():
            X[:, j] = v
        X[:, free_turn[0]] = PH
        X = chart.place(pin_leg, P, X)
        for V, ok in _full_from_x(chart, X, pin_leg, np.full(len(X), val)):
            seeds += _sign_change_seeds(sys, V, ok, (n, n), lim, wrap_axis0=True)
        return seeds
    # 1-D chart: the pinned relation leaves one parameter; points lie on the curve
    m = 4 * n
    th = np.linspace(-np.pi, np.pi, m, endpoint=False)
    cands: list[tuple[np.ndarray, np.ndarray]] = []
    if pin_kind == "serial":
        if chart.qa_angle[pin_leg]:
            vals = th
        else:
            vals = np.linspace(*chart.actuator_range(pin_leg), m)
        cands += chart.serial_loci(pin_leg, vals)
    else:
        val = lim if pin_kind == "limit" else fixed[pin_leg]
        cands.append((chart.circle(pin_leg, val, th), np.full(m, val)))
    for P, qk in cands:
        X = np.zeros((len(P), nx))
        for j, v in fixed_x.items():
            X[:, j] = v
        X = chart.place(pin_leg, P, X)
        for V, ok in _full_from_x(chart, X, pin_leg, qk):
            seeds += [V[i] for i in np.flatnonzero(ok)[::8]]
    return seeds


def _sign_change_seeds(sys: _System, V: np.ndarray, ok: np.ndarray, shape: tuple[int, int],
                       lim: float, wrap_axis0: bool = False) -> list[np.ndarray]:
    c = np.full(len(V), np.nan)
    if ok.any():
        c[ok] = sys.c_many(V[ok].T, lim)
    C = c.reshape(shape)
    Vg = V.reshape(shape + (V.shape[1],))
    out = []
    per = sys.periodic
    for axis in (0, 1):
        if axis == 0:
            a, b = C[:-1], C[1:]
            va, vb = Vg[:-1], Vg[1:]
            if wrap_axis0:
                a, b = C, np.roll(C, -1, axis=0)
                va, vb = Vg, np.roll(Vg, -1, axis=0)
        else:
            a, b = C[:, :-1], C[:, 1:]
            va, vb = Vg[:, :-1], Vg[:, 1:]
        hit = np.isfinite(a) & np.isfinite(b) & (a * b < 0)
        for idx in zip(*np.nonzero(hit)):
            ca_, cb_ = a[idx], b[idx]
            s = ca_ / (ca_ - cb_)
            d = vb[idx] - va[idx]
            d[per] = _wrap(d[per])
            out.append(va[idx] + s * d)
    return out


def _seeds_newton(sys: _System, fixed: dict[int, float], n: int, rng: np.random.Generator,
                  budget: _Budget | None = None) -> list[np.ndarray]:
    """C-space seeds of a mechanism with one free actuated joint (and no closed-form
    chart): a grid over it, multi-start Newton (the model's damped step) on the unknowns x."""
    model = sys.model
    na = sys.na
    free_qa = [i for i in range(na) if i not in fixed]
    if len(free_qa) != 1 or any(i >= na for i in fixed):
        return []
    seeds = []
    step = model.fast("newton_step")
    starts = rng.uniform(-np.pi, np.pi, (6, model.nx)) * model.x_scale
    qa = np.zeros(na)
    for i, v in fixed.items():
        qa[i] = v
    for val in np.linspace(-np.pi, np.pi, n, endpoint=False):
        if budget is not None and budget.exhausted():
            break
        qa[free_qa[0]] = val
        for x0 in starts:
            x = x0.copy()
            for _ in range(40):
                xn, r = step(qa, x)
                x = xn.copy()
                if float(r[0]) < 1e-10:
                    break
            if np.max(np.abs(model.residual(qa, x))) < 1e-8:
                seeds.append(np.concatenate([qa, x]))
    return seeds


def _seeds_newton_parallel(mech: Mechanism, names, n_lines: int, n: int, hmax: float,
                           budget: _Budget | None = None) -> list[np.ndarray]:
    """Seeds of det W_p = 0 for a 2-DoF mechanism without a closed-form chart: along the 1-DoF sections q_a,0 = c (C-space
    curves traced by continuation), the points where det W_p changes sign."""
    seeds: list[np.ndarray] = []
    na = get_model(mech).na
    for c in np.linspace(-np.pi, np.pi, n_lines, endpoint=False):
        if budget is not None and budget.exhausted():
            break
        sub = _singular_curves(mech, (names[1], names[na]), "closure", {names[0]: float(c)},
                               None, 6, None, hmax, 1e-11, None, False, budget,
                               "singular_curves")
        seeds += list(sub.info["actuator_singularities"])
    return seeds


# ---------------------------------------------------------------------------------------
# public entry point
# ---------------------------------------------------------------------------------------


def _resolve_names(mech: Mechanism, sysnames: Sequence[str], items: Any, what: str) -> list[int]:
    out = []
    for it in items:
        if isinstance(it, numbers.Integral) and not isinstance(it, (bool, np.bool_)):
            i = int(it)
            if not 0 <= i < len(sysnames):
                raise MechanismError(
                    f"{what}: coordinate index {show(i)} is out of range (0 to "
                    f"{len(sysnames) - 1}: {', '.join(sysnames)})")
            out.append(i)
        elif isinstance(it, str) and it in sysnames:
            out.append(sysnames.index(it))
        else:
            raise MechanismError(
                f"{what}: unknown coordinate {show(it)} of {mech.name}; known: "
                f"{', '.join(sysnames)}"
            )
    return out


def _names_of(mech: Mechanism) -> tuple[str, ...]:
    return tuple(mech.active_names) + tuple(get_model(mech).x_names)


def plane_indices(mech: Mechanism, plane: Any, fixed_idx: Sequence[int]) -> tuple[int, int]:
    """Indices (into v = (q_a, x)) of the plane's two coordinates."""
    model = get_model(mech)
    names = _names_of(mech)
    na = model.na
    if isinstance(plane, str):
        if plane in ("joint", "joints", "qa", "joint_space"):
            cand = [i for i in range(na) if i not in fixed_idx]
        elif plane in ("workspace", "task", "x", "cartesian"):
            # the platform's position, not its orientation (angles), when it can
            cand = [na + j for j in range(model.nx) if na + j not in fixed_idx
                    and not (j < model.n_platform and model.x_angle[j])]
            if len(cand) < 2:
                cand = [na + j for j in range(model.nx) if na + j not in fixed_idx]
        else:
            raise MechanismError(
                f"plane: expected 'joint', 'workspace' or two coordinate names, got {show(plane)}")
        if model.platform is None and plane in ("joint", "joints", "qa", "joint_space") \
                and len(cand) < 2:  # a chain's joint space: its passive joints complete it
            cand = cand + [i for i in range(na, na + model.nx) if i not in fixed_idx]
        if len(cand) < 2:
            raise MechanismError(
                f"plane {show(plane)} of {mech.name} has {len(cand)} free coordinate(s); name two "
                f"coordinates, e.g. plane=({names[0]!r}, {names[-1]!r})")
        return cand[0], cand[1]
    if not isinstance(plane, (Sequence, np.ndarray)) or len(plane) != 2:
        raise MechanismError(f"plane: expected 'joint', 'workspace' or two coordinate names, "
                             f"got {show(plane)}")
    idx = _resolve_names(mech, names, list(plane), "plane")
    if len(idx) != 2 or idx[0] == idx[1]:
        raise MechanismError(f"plane: expected two coordinates, got {show(plane)}")
    return idx[0], idx[1]


def singular_curves(
    mech: Mechanism,
    plane: Any = "joint",
    kind: str | Sequence[str] = "parallel",
    fixed: Mapping[str, float] | None = None,
    **options: Any,
) -> SingularCurves:
    """Trace the singular loci of a mechanism in a plane by pseudo-arclength continuation.

    Parameters
    ----------
    mech : Mechanism
        A planar platform whose legs are distance constraints with one actuator each
        (2-DoF, or 3-DoF with one coordinate fixed), a translational spatial platform
        with such legs and closed-form leg inverses (the Delta: parallel curves in the
        workspace plane of a section at one fixed coordinate, e.g. ``fixed={"z": -0.6}``),
        a 1-DoF Khalil mechanism (``kind="closure"``: its C-space curve) or a 2-DoF one.
    plane : "joint", "workspace" or (name, name)
        The plane the curves are shown in: the actuated joints q_a, the platform
        coordinates, or any two coordinates of v = (q_a, x). The curves themselves live
        in the configuration manifold; the plane only projects them (and bounds them).
    kind : str or list of str
        ``"parallel"`` (det W_p = det A = 0), ``"serial"`` (every B_jj = 0), ``"limit"``
        (the joint-limit boundaries of ``limits``), ``"closure"`` (1-DoF C-space), or
        ``"all"`` (parallel + serial + limit).
    fixed : dict, optional
        Section values, e.g. ``{"phi": 0.3}`` or ``{"L1.rho": 17.0}`` for a 3-DoF mechanism.
    **options
        The options below, by keyword, over :data:`SINGULAR_CURVES_DEFAULTS` (an unknown
        name is a :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    bounds : [[lo, hi], [lo, hi]], optional
        A box in the plane; curves stop on it (angles are periodic when their range is
        2 pi, the default). Default: the reach of the legs, [-pi, pi] for angles.
    grid : int, optional
        Seeding grid size per chart axis (default 32); it only seeds the continuation.
    limits : dict name -> (lo, hi), optional
        Actuated joint limits (for ``kind="limit"``).
    step : float, optional
        Largest continuation step in scaled units (lengths / mechanism size, radians);
        default :data:`DEFAULT_STEP`.
    tol : float
        Corrector tolerance on max ``|G|`` (default 1e-11).
    max_steps : int, optional
        Largest number of continuation steps each way along one curve (default 20000,
        lowered to what the memory budget allows when not given).
    cusps : bool, optional
        Detect cusps of the parallel curves in the plane (default: when the plane is the
        joint space of a section).

    Returns
    -------
    SingularCurves
        ``curves`` (ordered points with residuals), ``branch_points`` (full v) and
        ``cusps`` (full v; ``plane_points`` gives their plane coordinates),
        ``success``/``status``/``message``.

    Memory and time
    ---------------
    Checked against the budget of :mod:`optkin.limits` before anything is allocated: the
    seeding chart holds ``grid``^2 points, about 40 + 110 nv bytes each (nv = na + nx;
    363 bytes measured for a five-bar, 634 for a 3-RPR section); every traced point costs
    about 600 + 60 nv bytes (570 measured), and a given ``max_steps`` must leave room for
    2 ``max_steps`` points. While tracing, the curves stop when the points would exceed
    the budget (status ``"memory_limit"``) or when the time budget runs out (status
    ``"time_limit"``); ``success`` is then False. No curve in the box is a successful
    answer (status ``"optimal"``, ``count`` 0) whose message says so. ``step`` lies between
    :data:`MIN_STEP` and :data:`MAX_STEP`.

    Examples
    --------
    The five-bar of Chablat and Wenger: in its joint space, C, P and D aligned with
    ``|CD|`` = L2 + L3 (one curve) or C = D (two curves that project to two points).

    >>> import optkin
    >>> m = optkin.mechanisms.five_bar(9, 8, 5, 5, 8)
    >>> r = optkin.singular_curves(m, plane="joint")
    >>> r.count, r.success, r.max_residual < 1e-9
    (3, True, True)
    """
    from ..solvers.common import merge_options

    o = merge_options(SINGULAR_CURVES_DEFAULTS, options, "singular_curves")
    return _singular_curves(mech, plane, kind, fixed, o["bounds"], o["grid"], o["limits"],
                            o["step"], o["tol"], o["max_steps"], o["cusps"], None,
                            "singular_curves")


def _singular_curves(mech, plane, kind, fixed, bounds, grid, limits, step, tol, max_steps,
                     cusps, budget: _Budget | None, where: str,
                     point_cost: float | None = None, reserved: float = 0.0) -> SingularCurves:
    """singular_curves with a shared budget (``None``: a new one for this call, sized by
    ``point_cost`` bytes per traced point, ``reserved`` bytes being spent elsewhere by the
    caller; ``max_steps=None``: the default, lowered to what the budget allows)."""
    t0 = time.perf_counter()
    deadline = Deadline()
    check_mechanism(mech, where)
    grid = check_number(grid, f"{where}: option grid", integer=True, lo=2, optional=True)
    step = check_number(step, f"{where}: option step", lo=0.0, lo_open=True, optional=True)
    if step is not None and not MIN_STEP <= step <= MAX_STEP:
        raise MechanismError(f"{where}: option step: expected a number between {MIN_STEP:g} "
                             f"and {MAX_STEP:g} (scaled units: lengths / mechanism size, "
                             f"radians), got {step:g}")
    tol = check_number(tol, f"{where}: option tol", lo=0.0, lo_open=True)
    user_steps = max_steps is not None
    if user_steps:
        max_steps = check_number(max_steps, f"{where}: option max_steps", integer=True, lo=1)
    if isinstance(cusps, (np.bool_, numbers.Integral)) and not isinstance(cusps, bool) \
            and cusps in (0, 1):
        cusps = bool(cusps)
    if cusps is not None and not isinstance(cusps, bool):
        raise MechanismError(f"cusps: expected True, False or None, got {show(cusps)}")
    model = get_model(mech)
    _check_mech_size(model)
    names = _names_of(mech)
    fixed = _mapping_arg(fixed, "fixed")
    fixed_idx_l = _resolve_names(mech, names, list(fixed), "fixed")
    fixed_map = {i: as_float(fixed[k], f"fixed[{show(k)}]") for i, k in zip(fixed_idx_l, fixed)}
    fixed_idx = tuple(sorted(fixed_map))
    pidx = plane_indices(mech, plane, fixed_idx)
    if any(i in fixed_idx for i in pidx):
        raise MechanismError("plane: a plane coordinate cannot also be fixed")
    if isinstance(kind, str):
        kinds: list[str] = [kind]
    elif isinstance(kind, Sequence) and all(isinstance(k, str) for k in kind):
        kinds = list(kind)
    else:
        raise MechanismError(f"kind: expected 'parallel', 'serial', 'limit', 'closure', 'all' "
                             f"or a list of them, got {show(kind)}")
    if "all" in kinds:
        kinds = ["parallel", "serial", "limit"]
    if model.na == 1 and kinds == ["parallel"]:  # a 1-DoF mechanism: its C-space curve
        kinds = ["closure"]
    na = model.na
    conds: list[tuple[str, float]] = []
    limits = _mapping_arg(limits, "limits")
    lim_idx = _resolve_names(mech, names, list(limits), "limits")
    for k in kinds:
        if k == "serial":
            signs = model.working_mode_signs
            if signs is None:
                raise MechanismError("kind='serial': serial curves (B_jj = 0) need a fully "
                                     "parallel mechanism (legs with one actuator each, B "
                                     "diagonal)")
            # a leg whose actuator is its length has B_jj = -1: no serial singularity (its
            # stroke ends are limits)
            conds += [(f"serial:{j}", 0.0) for j in range(na)
                      if j not in fixed_idx and len(signs[j]) == 2]
        elif k == "limit":
            for i, key in zip(lim_idx, limits):
                if i >= na:
                    raise MechanismError(f"limits: {show(key)} is not an actuated joint")
                lo, hi = _pair_arg(limits[key], f"limits[{show(key)}]")
                conds += [(f"limit:{i}", lo), (f"limit:{i}", hi)]
        elif k in ("parallel", "closure"):
            conds.append((k, 0.0))
        else:
            raise MechanismError(
                f"kind: expected 'parallel', 'serial', 'limit', 'closure' or 'all', got {show(k)}")
    chart = planar_chart(model)
    if chart is None and model.platform is not None:
        # a translational spatial platform (the Delta): its sections at a fixed
        # translation, seeded from the same closed-form leg inverses
        chart = translational_chart(model)
        if chart is None:
            raise MechanismError(
                f"{mech.name}: singular curves support planar platforms and translational "
                "spatial platforms (x, y, z) whose legs are distance constraints (one "
                "actuator each), and Khalil mechanisms, in this version")
        if kinds != ["parallel"] or len(fixed_map) != 1 or min(fixed_map) < na \
                or min(pidx) < na:
            raise MechanismError(
                f"{mech.name}: a translational spatial platform's singular curves are "
                "parallel singularities in a section at one fixed platform coordinate, e.g. "
                "plane='workspace', kind='parallel', fixed={'z': -0.7}")
    n = int(grid or 32)
    hmax = float(step or DEFAULT_STEP)
    # plane bounds
    periodic_v = [bool(mech.revolute[i]) for i in mech.active_index] + list(model.x_angle)
    per2 = (bool(periodic_v[pidx[0]]), bool(periodic_v[pidx[1]]))
    if bounds is None:
        bx = []
        rb = chart.reach_box() if chart is not None else None
        for j, i in enumerate(pidx):
            if per2[j]:
                bx.append((-np.pi, np.pi))
            elif rb is not None and i >= na and i - na in chart.translation:
                lo, hi = rb[chart.translation.index(i - na)]
                pad = 0.05 * (hi - lo)
                bx.append((lo - pad, hi + pad))
            else:
                bx.append((0.0, 3.0 * model.length))
        bounds_arr = np.array(bx, dtype=float)
    else:
        bounds_arr = _bounds_arg(bounds, plane)
    # memory, before anything is allocated: the seeding chart, then the traced points
    if budget is None:
        cell = _cell_cost(model)
        per_point = _point_cost(model) if point_cost is None else point_cost
        # the chart leaves room for MIN_POINTS traced points at least
        check_size(where, "grid", n, cell, power=2, lo=2,
                   fixed=reserved + SAFETY * per_point * MIN_POINTS,
                   unit=f"one seeding point of {_n_combos(chart)} posture combination(s), "
                   f"{MIN_POINTS} traced points being kept free")
        spent = reserved + SAFETY * cell * n * n
        if user_steps:
            check_size(where, "max_steps", max_steps, 2 * per_point, fixed=spent,
                       unit="two traced points (a curve runs max_steps each way)")
        else:
            max_steps = max(1, min(DEFAULT_MAX_STEPS, largest_size(2 * per_point, fixed=spent)))
        budget = _Budget(deadline, max(2, int((memory_budget() - spent)
                                                 / (SAFETY * per_point))))
    elif not user_steps:
        max_steps = DEFAULT_MAX_STEPS
    bounds_full = {pidx[0]: tuple(bounds_arr[0]), pidx[1]: tuple(bounds_arr[1])}
    rng = np.random.default_rng(0)
    curves: list[Curve] = []
    bps: list[np.ndarray] = []
    n_seeds = 0
    messages = []
    pvals = np.array([fixed_map[i] for i in fixed_idx])
    # the augmented systems check that each condition makes a curve in this section
    systems = [augmented_system(mech, cond, fixed_idx) for cond, _ in conds]
    if chart is None and any(c == "parallel" for c, _ in conds) and (
            model.na != 2 or fixed_map):
        raise MechanismError(
            f"{mech.name}: parallel curves of a mechanism without a closed-form chart (a "
            "Khalil table, legs in chain form) need 2 actuated joints and no section "
            "(fixed); 1-DoF mechanisms: kind='closure'")
    checkpoint()  # validation stops here: every argument is checked
    for (cond, lim), sys in zip(conds, systems):
        if budget.exhausted():
            break
        tr = _Tracer(sys, pvals, lim, pidx, bounds_arr, hmax, tol, max_steps, budget)
        traced = (_limit_arcs(chart, tr, int(cond.split(":")[1]), lim, fixed_map, pidx)
                  if chart is not None and cond.startswith("limit:") else
                  _conic_arcs(chart, tr, fixed_map, pidx)
                  if chart is not None and cond == "parallel" else None)
        if traced is None:
            if chart is not None:
                seeds_v = _seeds_chart(sys, chart, cond, fixed_map, lim, n, bounds_full)
            elif cond == "parallel":
                seeds_v = _seeds_newton_parallel(mech, names, max(8, n // 2), n, hmax, budget)
            else:
                seeds_v = _seeds_newton(sys, fixed_map, n, rng, budget)
            free = np.array(sys.free_idx)
            seeds_u = [v[free] / tr.scl for v in seeds_v]
            n_seeds += len(seeds_u)
            if not seeds_u:
                messages.append(f"{cond}: no seed found")
            traced = _trace_all(tr, seeds_u, dedup=0.3 * hmax)
        else:
            n_seeds += len(traced)
        for Z, closed, ends in traced:
            if len(Z) < 2:
                continue
            U = Z * tr.scl
            V = np.empty((len(U), sys.nv))
            V[:, list(sys.free_idx)] = U
            for i in fixed_idx:
                V[:, i] = fixed_map[i]
            gm = sys.G_many(U, pvals, lim)
            res = np.max(np.abs(gm), axis=0).ravel()
            detw, B = sys.aux_many(V.T)
            wm = np.sign(B.T).astype(int) if model.fully_parallel else None
            curves.append(Curve(cond, V, V[:, list(pidx)], res, closed, ends, wm, detw, B.T))
        for b in tr.bps:
            vb = np.empty(sys.nv)
            vb[list(sys.free_idx)] = b * tr.scl
            for i in fixed_idx:
                vb[i] = fixed_map[i]
            bps.append(vb)
    # cusps of the parallel curves in the plane
    do_cusps = cusps if cusps is not None else (bool(fixed_idx) and all(i < na for i in pidx))
    cusp_pts = np.zeros((0, model.na + model.nx))
    if do_cusps:
        found = []
        for c in curves:
            if c.kind.startswith("parallel"):
                sys = augmented_system(mech, "parallel", fixed_idx)
                tr = _Tracer(sys, pvals, 0.0, pidx, bounds_arr, hmax, tol, max_steps, budget)
                found += _cusps_on(tr, c, pidx, fixed_idx, fixed_map)
        if found:
            cusp_pts = np.array(found)
    # actuator (input) singularities along a 1-DoF C-space: det W_p changes sign
    act_pts = []
    for c in curves:
        if c.kind.startswith("closure") and c.det_Wp is not None:
            sys = augmented_system(mech, "closure", fixed_idx)
            tr = _Tracer(sys, pvals, 0.0, pidx, bounds_arr, hmax, tol, max_steps, budget)
            act_pts += _det_zeros_on(tr, c, fixed_idx, fixed_map)
    maxres = max((float(np.max(c.residual)) for c in curves), default=0.0)
    ok = maxres < 1e-9  # no curve found is an answer too: the message says so
    status = OPTIMAL if ok else INACCURATE
    msg = f"{len(curves)} curve(s), {len(bps)} branch point(s), max residual {maxres:.1e}"
    if not curves:
        msg = (f"no singular curve found in the box ({n_seeds} seed(s) met the conditions "
               f"{[c for c, _ in conds]}): {msg}")
    if messages:
        msg += "; " + "; ".join(messages)
    if budget.reason is not None:
        ok, status = False, budget.reason
        msg += "; " + budget.message(where)
    if any(e in _EARLY for c in curves for e in c.ends):
        msg += "; some curves stopped early (stalled, max_steps or jumped to another curve)"
    per_plane = tuple(bool(p and (b[1] - b[0]) >= TWO_PI - 1e-9) for p, b in zip(per2, bounds_arr))
    return SingularCurves(
        mechanism=mech.name, names=names, plane=(names[pidx[0]], names[pidx[1]]),
        fixed={names[i]: fixed_map[i] for i in fixed_idx}, curves=curves,
        branch_points=np.array(bps).reshape(-1, len(names)),
        cusps=cusp_pts, success=ok, status=status, message=msg, bounds=bounds_arr,
        periodic=per_plane, n_seeds=n_seeds, time=time.perf_counter() - t0,
        info={"plane_index": pidx, "conditions": [c for c, _ in conds],
              "actuator_singularities": np.array(act_pts).reshape(-1, len(names))},
    )


def _det_zeros_on(tr: _Tracer, c: Curve, fixed_idx, fixed_map) -> list[np.ndarray]:
    """Points of a traced curve where det W_p vanishes (bisection between sign changes)."""
    free = np.array(tr.sys.free_idx)
    U = c.v[:, free] / tr.scl
    d = c.det_Wp
    n = len(U)
    pairs = [(i, i + 1) for i in range(n - 1)] + ([(n - 1, 0)] if c.closed else [])
    out = []

    def full(u):
        v = np.empty(tr.sys.nv)
        v[free] = u * tr.scl
        for k in fixed_idx:
            v[k] = fixed_map[k]
        return v

    for i, j in pairs:
        if d[i] * d[j] >= 0:
            continue
        ua, step = U[i], tr.diff(U[j], U[i])
        dn = step / np.linalg.norm(step)
        lo, hi, best = 0.0, 1.0, None
        for _ in range(50):
            sm = 0.5 * (lo + hi)
            um, _ = tr.correct(ua + sm * step, dn)
            if um is None:
                break
            best = um
            dm = tr.sys.aux_one(full(um))[0]
            if dm * d[i] > 0:
                lo = sm
            else:
                hi = sm
            if (hi - lo) * np.linalg.norm(step) < 1e-12:
                break
        if best is not None:
            out.append(full(best))
    return out


def _cusps_on(tr: _Tracer, c: Curve, pidx, fixed_idx, fixed_map) -> list[np.ndarray]:
    """Cusps of the plane projection: the projected tangent reverses along the curve."""
    free = np.array(tr.sys.free_idx)
    U = c.v[:, free] / tr.scl
    pz = tr.pz
    T = []
    for u in U:
        _, J = tr.GJ(u)
        T.append(tr.tangent(J))
    T = np.array(T)
    for i in range(1, len(T)):  # orient by continuity
        if T[i] @ T[i - 1] < 0:
            T[i] = -T[i]
    P = T[:, pz]
    out = []
    for i in range(len(U) - 1):
        if P[i] @ P[i + 1] >= 0:
            continue
        ref = P[i].copy()
        ua, ub = U[i], U[i + 1]
        d = tr.diff(ub, ua)
        dn = d / np.linalg.norm(d)
        lo, hi = 0.0, 1.0
        best = None
        for _ in range(60):
            s = 0.5 * (lo + hi)
            um, _ = tr.correct(ua + s * d, dn)
            if um is None:
                break
            _, J = tr.GJ(um)
            t = tr.tangent(J)
            if t @ T[i] < 0:
                t = -t
            best = um
            if t[pz] @ ref > 0:
                lo = s
            else:
                hi = s
            if (hi - lo) * np.linalg.norm(d) < 1e-12:
                break
        if best is None:
            continue
        v = np.empty(tr.sys.nv)
        v[free] = best * tr.scl
        for k in fixed_idx:
            v[k] = fixed_map[k]
        if not any(np.linalg.norm(v - o) < 1e-6 for o in out):
            out.append(v)
    return out


# ---------------------------------------------------------------------------------------
# arguments and budgets
# ---------------------------------------------------------------------------------------

#: Default (and, when not given, budget-lowered) ``max_steps`` of :func:`singular_curves`.
DEFAULT_MAX_STEPS = 20000
#: Traced points the memory check of ``grid`` keeps room for (the curves of the bundled
#: problems take 300 to 3000).
MIN_POINTS = 4096
#: Range of the continuation ``step`` (scaled units): below, curves take millions of
#: points; above, a step jumps across the mechanism.
MIN_STEP, MAX_STEP = 1e-6, 1.0

# Measured memory (peak resident growth, /proc/self/status VmHWM, of a fresh process).
# Seeding chart: per grid cell (grid^2 of them) and posture combination of the legs, its
# platform coordinates, leg inverse kinematics, full points, the mapped evaluation of the
# condition and the sign-change search: a + b * nv bytes (nv = na + nx variables; e.g. 333
# bytes per cell for the aspects of a five-bar, 4 combinations, at grid 1600).
_COST_CELL = (40.0, 110.0)
# Per traced point: the tracer's list, the curve arrays (v, plane points, residual, det,
# B, working modes) and its JSON (to_dict): a + b * nv bytes.
_COST_POINT = (600.0, 60.0)


class _Budget:
    """What one call may still spend: a deadline and a number of traced points."""

    def __init__(self, deadline: Deadline | None = None, max_points: int | None = None) -> None:
        self.deadline = deadline if deadline is not None else Deadline()
        self.max_points = max_points
        self.points = 0
        self.reason: str | None = None

    def exhausted(self) -> bool:
        if self.reason is None:
            if self.max_points is not None and self.points >= self.max_points:
                self.reason = MEMORY_LIMIT
            elif self.deadline.expired():
                self.reason = TIME_LIMIT
        return self.reason is not None

    def message(self, where: str) -> str:
        if self.reason == MEMORY_LIMIT:
            return (f"{where}: stopped after {self.points} traced points, the most the memory "
                    "budget allows (OPTKIN_MEMORY_BUDGET); the curves are incomplete: give a "
                    "larger step or a smaller box")
        return self.deadline.message(where)


def _n_combos(chart: PlanarChart | None) -> int:
    """Posture combinations of the legs the seeding chart goes through."""
    return 1 if chart is None else chart.n_combos


def _cell_cost(model: Any) -> float:
    """Bytes per cell of the seeding chart (grid^2 cells), without the safety factor."""
    a, b = _COST_CELL
    return a + b * (model.na + model.nx)


def _point_cost(model: Any) -> float:
    a, b = _COST_POINT
    return a + b * (model.na + model.nx)


def _check_mech_size(model: Any) -> None:
    L = float(model.length)
    if not (np.isfinite(L) and L <= MAX_ABS):
        raise MechanismError(
            f"{model.mech.name}: the mechanism's size {L:g} is too large (above {MAX_ABS:g}): "
            "squares of its lengths overflow; give lengths of sensible size (change the unit)")


def _mapping_arg(v: Any, name: str) -> dict[Any, Any]:
    if v is None:
        return {}
    if not isinstance(v, Mapping):
        raise MechanismError(f"{name}: expected a dict name -> value, got {type(v).__name__}")
    return dict(v)


def _pair_arg(v: Any, name: str) -> tuple[float, float]:
    try:
        lo, hi = as_vector(v, name, 2)
    except MechanismError:
        lo = hi = float("nan")
    if not lo < hi:
        raise MechanismError(f"{name}: expected a pair (lo, hi) of finite numbers with "
                             f"lo < hi, got {show(v)}")
    return float(lo), float(hi)


def _bounds_arg(bounds: Any, plane: Any) -> np.ndarray:
    b = None
    try:
        b = as_matrix(bounds, "bounds", (2, 2))
    except MechanismError:
        try:
            b = as_vector(bounds, "bounds", 4).reshape(2, 2)
        except MechanismError:
            b = None
    if b is None or not np.all(b[:, 0] < b[:, 1]):
        raise MechanismError(
            f"bounds: expected [[lo, hi], [lo, hi]] with lo < hi (finite, magnitude at most "
            f"{MAX_ABS:g}) for the plane {show(plane)}, got {show(bounds)}")
    return b
