"""Every assembly mode: multi-start enumeration with a measured completeness; path tracking.

:func:`assembly_modes` solves the direct geometric model Phi(q_a, x) = 0 ([7.9] of Khalil & Dombre 2002)
from many starting points at once. The starts are low-discrepancy (Sobol) points
over the unknowns, drawn as the model says what each unknown is
(:mod:`optkin.model.enumeration`): joint angles over [-pi, pi) for Khalil mechanisms; for
platforms SO(2) angles or uniform unit quaternions (Shoemake's map of Sobol points) and
positions in the box where every leg can still close (each leg confines the platform to a
ball: a distance leg ``|P - C(q_a)|`` = r puts its platform point in the ball of radius r about
C, a chain of joints is followed from its end to its base, every passive revolute growing
the ball by the distance of its centre from the axis); the variables of legs written as
chains (``Leg.from_screws``, UPU, RPS, PSP, ...) are drawn from the sampled pose, each leg
brought to reach it by a few Gauss-Newton steps on its own variables. For spatial
platforms on six distance legs the position is not sampled: differences of the squared
leg equations are linear in the position (the elimination of Modern Robotics 7.1.1 and
7.1.2), so each sampled orientation gets its least-squares position (measured: it
converges in fewer iterations; for planar platforms box starts reach rare modes far more
often, so they keep them). The Sobol points are randomised by a shift drawn from ``seed``
(Cranley-Patterson rotation).

An assembly mode is a solution of the closure up to what identifies it: for a platform its
pose (the legs' passive joints of a chain are postures of the legs: two postures of a leg
reaching one pose are one mode), for a Khalil table all its unknowns.

The starts run through Khalil's iteration (Newton with the step clamped to a threshold S,
[7.55]) compiled into one CasADi Function mapped over a pool of columns (C code through
:mod:`optkin.model.compiled`, cached on disk per topology, for 6+ unknowns: the geometry is
an input, so a new geometry of a known topology compiles nothing). Above
:data:`FUSED_MAX` unknowns (legs in chain form) the closure and its Jacobian are mapped
and compiled, and the linear solves are done by numpy. Converged columns are
deduplicated as they arrive (angles modulo 2 pi, quaternion sign, a tolerance relative to
the mechanism size) and replaced by fresh starts. Exclusion rather than deflation: a start
that enters the quadratic-convergence region of a known solution (``|Phi|`` < 1e-5 L, within
1e-3 scaled) is counted as its hit and replaced, which saves iterations without biasing the
hit counts (deflating known solutions would change the basins and with them the meaning of
the Good-Turing estimate).

The solution set reports how many starts ran, how many converged, how often each solution was
hit, the Good-Turing estimate of the probability that a further start would find a new
solution (p_new = N1 / n, the share of the n starts whose solution was seen exactly once,
N1 of them) and a conservative upper bound on it, p_new_upper = u(N1) / n with u(k) the
one-sided 99 % upper confidence limit of a Poisson mean from k events, chi2.ppf(0.99,
2 k + 2) / 2 (u(0) = -ln 0.01 = 4.6, u(1) = 6.6, u(2) = 8.4). With no singletons the
estimate is 0 however few starts ran; the bound is then the "rule of three" at 99 %,
4.6 / n, exact for one unseen mode: a mode whose basin takes a share p >= 4.6 / n of the
starts is missed by all n starts with probability (1 - p)^n <= e^-4.6 = 1 %. The level is
99 % rather than 95 % because the stopping rule checks the bound after every batch (optional
stopping): measured on Dietmaier's platform (40 seeds, ``min_starts=32``), stopping when
the bound is at most 0.01, the modes missed at the stop held a larger share of the starts
than the bound in 2 of 40 runs at 99 % (9 of 40 with a 95 % bound); stopping when the
estimate is at most 0.01, they held more than the estimate in 33 of 40 runs.

Enumeration stops when the estimate is at most ``target`` and the bound at most
``target_upper`` (1e-3 and 1e-2 by default: the bound adds a condition only where it is
cheap, when no start was a singleton, e.g. 460 instead of 256 starts for a small system
below its known bound or without one; ``target_upper=1`` drops it), after at least
``min_starts`` (256 starts for small systems and 2048 for 6+ unknowns, set so that modes
hit by 0.3 % of the starts, as the rarest of Dietmaier's platform are, are found), when the
number of
solutions reaches a known upper bound read from the structure of the closure (distance legs
with centres and radii fixed by q_a: 6 for a planar platform on three, 40 for a spatial one
on six, 2 for a point or a translating platform, e.g. a five-bar or a Delta: the set is then
provably complete; :func:`known_bound`), or at the start budget or time limit. Below such an even bound an odd
count means a mode is still missing (non-real solutions come in conjugate pairs; only a
double root at a singularity breaks this), so the target may stop the run only after four
times ``min_starts``. IPOPT ([7.9] as an NLP) only rescues starts that stalled.

:func:`track` follows one assembly mode along a path of actuated values (predictor-corrector
continuation with step halving) and stops with status ``"singular"`` where det W_p changes
sign or W_p becomes ill-conditioned, instead of jumping to another mode.

:func:`working_modes` lists the sign patterns of the diagonal B = W_a of a fully parallel
mechanism (Chablat and Wenger 1998, Definition 4) and, at a pose, which exist.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from .._checks import MAX_ABS, as_matrix, as_vector, check_number, check_option
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..limits import (
    MAX_ITERATIONS,
    MAX_THREADS,
    SAFETY,
    Deadline,
    auto_threads,
    check_size,
    check_sizes,
    floor_pow2,
    show,
    time_budget,
)
from ..mechanism import Mechanism
from ..model import Model, get_model
from ..model import enumeration as _enum
from ..model.compiled import FastFn
from ..results import (
    INFEASIBLE,
    LIMIT_REACHED,
    OPTIMAL,
    TIME_LIMIT,
    EnumerationStats,
    KinResult,
    SolutionSet,
    SolverStats,
    TrackStats,
    jsonable,
)
from .common import (
    check_mechanism,
    check_qa,
    make_result,
    merge_options,
    newton,
    parse_guess,
    timer,
)
from .sobol import sobol_points

__all__ = [
    "assembly_modes",
    "track",
    "working_modes",
    "WorkingModes",
    "ASSEMBLY_DEFAULTS",
    "TRACK_DEFAULTS",
    "known_bound",
]

#: Options of :func:`assembly_modes` and their defaults.
ASSEMBLY_DEFAULTS: dict[str, Any] = {
    "seed": 0,  # of the Sobol scrambling and the homotopy's gamma (a run is reproducible)
    "tol": 1e-10,  # max |Phi| for a converged start
    "starts": 20000,  # start budget
    "min_starts": "auto",  # starts before the target may stop a run: auto 256, 2048 (6+ unknowns)
    "target": 1e-3,  # stop when the Good-Turing probability of a new solution is <= target
    "target_upper": 1e-2,  # ... and its 99 % upper bound p_new_upper too (1: no condition)
    "time_limit": 10.0,  # seconds (compilation excluded)
    "bound": "auto",  # known upper bound on the number of real solutions (None: unknown)
    "width": "auto",  # columns of the mapped Newton step (the pool of starts run at once)
    "max_iter": 40,  # Newton iterations per start
    "step_max": "auto",  # threshold S of [7.55], scaled units (lengths / size); auto 0.3 or 1
    "dedup_tol": 1e-6,  # scaled distance under which two solutions are the same
    "rescue": 8,  # IPOPT rescues of stalled starts
    "certify": False,  # prove each mode by Krawczyk's test (optkin.solvers.certify)
    "continua": True,  # look for solutions that are not isolated (optkin.solvers.continua)
    "method": "auto",  # "homotopy": parameter homotopy (optkin.solvers.homotopy);
    # "multistart"; "auto": the homotopy where the package ships the topology's start system
    # and no multistart option is given, kept when it finds a mode, its account is complete
    # and no singular endpoint is near the real space (else the multistart: it also reports
    # continua, and why no mode exists)
    "jit": "auto",  # compile the step to C: True (wait for the compiler), False, "cached" (if
    # in the disk cache), "auto" ("cached" under 6 unknowns, else compiled in the background
    # while the first calls use the interpreted step)
    "threads": "auto",  # threads sharing the work. The homotopy's paths: "auto" is
    # optkin.limits.auto_threads() (the usable CPUs, 1 in batch workers when several run),
    # at least 8 paths a thread (a 6-6 platform's 40 paths 1.65x faster on 2 threads here).
    # The multistart's pool columns (6+ unknowns): "auto" is 1 (2 measured 0.99-1.14x the
    # speed of 1 on a 6-6 platform, the Newton step being a quarter of the time)
}

#: Options of :func:`track` and their defaults.
TRACK_DEFAULTS: dict[str, Any] = {
    "tol": 1e-10,  # max |Phi| at every accepted point
    "max_iter": 8,  # corrector Newton iterations per sub-step
    "min_step": 2.0**-14,  # smallest sub-step, as a fraction of one path segment
    "cond_max": 1e8,  # scaled cond(W_p) at which the path is declared singular
    "cond_near": 1e3,  # where the halving runs out: cond above which the stop is "singular"
    "max_correction": 0.25,  # largest corrector move (scaled units) before a step is halved
    "contraction": 0.5,  # largest corrector move relative to the predicted move
}


def known_bound(mech: Mechanism) -> int | None:
    """An upper bound on the number of real assembly modes, when the structure has one.

    Read from the model's closure (:func:`optkin.model.enumeration.known_bound`): when
    every leg is a distance constraint between a platform point and a point fixed by q_a
    (one actuator and one row per leg, one leg per platform freedom), a planar platform
    that turns has at most 6 modes (the sextic of Modern Robotics 7.1.1), a spatial one at
    most 40 (Raghavan and Roth), a platform that does not turn (a five-bar's point, a
    Delta) at most 2. None otherwise (Khalil tables, chains, redundant actuation).

    >>> import optkin
    >>> known_bound(optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5))
    2
    """
    return _enum.known_bound(get_model(mech))


# ---------------------------------------------------------------------------------------------
# starting points
# ---------------------------------------------------------------------------------------------

#: Re-exported: uniform unit quaternions from points of the unit cube.
shoemake = _enum.shoemake

_SOBOL: dict[int, np.ndarray] = {}
#: Sobol points per dimension kept in the process-wide cache (beyond: generated per run).
_SOBOL_CACHED = 1 << 16


class _ShiftedSobol:
    """Sobol points with a random Cranley-Patterson shift: (u + shift(seed)) mod 1.

    The unscrambled points of each dimension are generated once and cached, so a run costs
    one small random draw instead of building a scrambled engine (which costs more than a
    small enumeration); the shift makes runs with different seeds independent randomised
    quasi-Monte Carlo samples.
    """

    def __init__(self, dim: int, seed: int) -> None:
        self.dim = dim
        self.shift = np.random.default_rng(seed).random(dim)
        self.pos = 0

    def random(self, n: int) -> np.ndarray:
        if self.dim == 0:
            return np.zeros((n, 0))
        need = self.pos + n
        if need <= _SOBOL_CACHED:
            base = _SOBOL.get(self.dim)
            if base is None or base.shape[0] < need:
                m = max(1024, 1 << int(np.ceil(np.log2(need))))
                base = sobol_points(self.dim, m)
                _SOBOL[self.dim] = base
            U = base[self.pos:need] + self.shift
        else:  # past the cached points: the same sequence, generated for this run
            U = sobol_points(self.dim, n, start=self.pos) + self.shift
        self.pos = need
        return U - np.floor(U)


def _sobol(dim: int, seed: int) -> _ShiftedSobol:
    return _ShiftedSobol(dim, seed)


class _Starts:
    """Low-discrepancy starting points x (columns) for one mechanism and q_a.

    What each unknown is comes from the model (:func:`optkin.model.enumeration.layout`):
    Khalil unknowns in a box (angles over [-pi, pi), lengths over twice the mechanism's
    size); platform angles uniform, quaternions by Shoemake's map, the origin in the reach
    box or, for a turning spatial platform on distance legs, at its least-squares position;
    the variables of legs in chain form drawn from the sampled pose
    (:func:`optkin.model.enumeration.seed_legs`).
    """

    def __init__(self, model: Model, qa: np.ndarray, seed: int, block: int,
                 jit: bool | str = False) -> None:
        self.model = model
        self.qa = np.asarray(qa, dtype=float)
        self.block = block
        self.jit = jit
        self.empty_reason: str | None = None
        self.buf = np.zeros((model.nx, 0))
        self.lay = lay = _enum.layout(model)
        self.rng = np.random.default_rng([int(seed), 1])
        self.ls = False
        if lay.box.size:
            L = 2.0 * model.length
            ang = lay.angle[lay.box]
            self.lo = np.where(ang, -np.pi, -L)
            self.hi = np.where(ang, np.pi, L)
            self.dim = int(lay.box.size)
        else:
            lo, hi, why = _enum.reach_box(model, self.qa)
            self.empty_reason = why
            self.plo, self.phi = lo, hi
            # the least-squares position speeds up spatial platforms, while planar ones reach
            # rare modes far more often from box starts (measured: 3-RPR modes hit by 0.1 % of
            # least-squares starts get 3 % or more of box starts)
            self.ls = _enum.least_squares_available(model)
            self.nrot = int(lay.turn.size + (3 if lay.quat.size else 0))
            self.dim = self.nrot + (0 if self.ls else int(lay.pos.size))
        self.sob = _sobol(self.dim, seed)

    def _make(self, U: np.ndarray) -> np.ndarray:
        model, lay = self.model, self.lay
        n = U.shape[0]
        X = np.zeros((n, model.nx))
        if lay.box.size:
            X[:, lay.box] = self.lo + U * (self.hi - self.lo)
            return X.T
        col = 0
        for i in lay.turn:
            X[:, i] = -np.pi + 2 * np.pi * U[:, col]
            col += 1
        if lay.quat.size:
            X[:, lay.quat] = shoemake(U[:, col:col + 3])
            col += 3
        if self.ls:
            R = _enum.platform_rotations(model, X[:, : model.n_platform])
            P = _enum.least_squares_positions(model, self.qa, R)
            X[:, lay.pos] = np.clip(P[:, : lay.pos.size], self.plo, self.phi)
        else:
            X[:, lay.pos] = self.plo + U[:, col:] * (self.phi - self.plo)
        if lay.legs.size:
            _enum.seed_legs(model, X, self.qa, self.rng,
                            jit=True if self.jit == "background" else self.jit)
        return X.T

    def take(self, n: int) -> np.ndarray:
        while self.buf.shape[1] < n:
            self.buf = np.hstack([self.buf, self._make(self.sob.random(self.block))])
        out, self.buf = self.buf[:, :n], self.buf[:, n:]
        return out


# ---------------------------------------------------------------------------------------------
# the compiled, mapped step
# ---------------------------------------------------------------------------------------------

#: Largest number of unknowns for which the whole clamped Newton step (the linear solve
#: included) is one CasADi expression; above it the solve is done by numpy (LAPACK) on
#: the mapped Jacobians: the symbolic solve of a 37-unknown closure (a 6-UPS platform in
#: chain form) is 10^5 instructions and 40 s of C compiling, its Jacobian alone 4 s.
FUSED_MAX = 12


def _clamped_step(model: Model, step_max: float, k: int = 1) -> ca.Function:
    """k iterations x -> x + dx min(1, S / |dx / scale|), dx the Newton (Gauss-Newton when
    there are more rows than unknowns) step: Khalil's clamped iteration [7.55]. Returns the
    new x and max |Phi| there. Inputs (q_a, x, p): the geometry is an input."""
    qa, x, p, phi = model.symbols
    Wp = ca.jacobian(phi, x)
    if model.m == model.nx:
        dx = -ca.solve(Wp, phi)
    else:
        dx = -ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, phi))
    nrm = ca.norm_2(dx / model.topology.x_scale_sym)
    one = ca.Function("one", [qa, x, p], [x + dx * ca.fmin(1, step_max / (nrm + 1e-300))])
    xs = x
    for _ in range(k):
        xs = one(qa, xs, p)
    fphi = ca.Function("phi", [qa, x, p], [ca.mmax(ca.fabs(phi)) if model.m else ca.SX(0)])
    return ca.Function("clamped_newton", [qa, x, p], [xs, fphi(qa, xs, p)],
                       ["qa", "x", "p"], ["x_next", "res"])


def _no_compiler_warning() -> None:
    warnings.warn("assembly_modes: no compiled step (no C compiler, or compiling is "
                  "off: OPTKIN_COMPILE); using the CasADi virtual machine (slower)",
                  stacklevel=4)


#: Widest mapped step kept per topology (a map holds 40 bytes per column and entry of the
#: geometry vector: wider ones are built for the call).
_CACHED_WIDTH = 1024


def _mapped(model: Model, f: ca.Function, width: int, part: int = 0) -> tuple[ca.Function, bool]:
    """``f`` (q_a, x, p) mapped serially over ``width`` columns, q_a and p single columns
    (CasADi's threaded map repeats them for every column: measured 12 % slower with 2
    threads than with 1 on a 6-6 platform here; threads split the columns instead,
    :class:`_ThreadedStep`, each share through a map of its own: ``part``)."""
    return f.map(f"{f.name()}_{int(width)}_{int(part)}", "serial", int(width), [0, 2],
                 []), True


class _ThreadedStep:
    """A step over ``width`` columns as ``len(parts)`` steps over a share of the columns
    each, evaluated at once: the first share in the calling thread, the others in a pool
    of threads kept with the step (CasADi's evaluation releases the GIL); the geometry
    held once per share."""

    def __init__(self, parts: list[Any]) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.parts = parts
        self.cuts = np.cumsum([0] + [p.width for p in parts])
        self.pool = ThreadPoolExecutor(len(parts) - 1, thread_name_prefix="optkin-step")

    def __call__(self, qa: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = self.cuts
        futs = [self.pool.submit(p, qa, X[:, c[i]:c[i + 1]])
                for i, p in enumerate(self.parts) if i]
        out = [self.parts[0](qa, X[:, :c[1]])] + [f.result() for f in futs]
        return (np.concatenate([o[0] for o in out], axis=1),
                np.concatenate([o[1] for o in out]))


class _FusedStep:
    """The clamped step (:func:`_clamped_step`) mapped over the pool's columns."""

    def __init__(self, fm: ca.Function, single: bool, model: Model, width: int) -> None:
        p = model.p if single else np.tile(model.p[:, None], (1, width))
        self.ev = FastFn(fm, fixed=(p,))
        self.single, self.width, self.nx = single, width, model.nx

    def __call__(self, qa: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q = qa if self.single else np.tile(np.asarray(qa, float)[:, None], (1, self.width))
        xn, r = self.ev(q, X)
        return xn.reshape((self.width, self.nx)).T.copy(), r.copy()


class _SplitStep:
    """The clamped step with the closure and its Jacobian mapped in CasADi and the linear
    solves in numpy (large systems, see :data:`FUSED_MAX`); returns the new columns and
    max |Phi| at the given ones (a converged column moves by one more Newton step)."""

    def __init__(self, fm: ca.Function, single: bool, model: Model, width: int,
                 step_max: float) -> None:
        p = model.p if single else np.tile(model.p[:, None], (1, width))
        self.ev = FastFn(fm, fixed=(p,))
        self.single, self.width = single, width
        self.scale = model.x_scale
        self.square = model.m == model.nx
        self.S = step_max
        self.F = np.empty((width, model.m))
        self.J = np.empty((width, model.m, model.nx))

    def __call__(self, qa: np.ndarray, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Xr = np.ascontiguousarray(X.T)
        qa = np.asarray(qa, dtype=float)
        q = qa if self.single else np.ascontiguousarray(np.tile(qa, (self.width, 1)))
        self.ev.into([q, Xr], [self.F, self.J])
        F, J = self.F, self.J
        r = np.max(np.abs(F), axis=1) if F.shape[1] else np.zeros(F.shape[0])
        if self.square:
            dx = -_enum.solve_rows(J, F)
        else:
            dx = -_enum.solve_rows(np.einsum("kmi,kmj->kij", J, J),
                                   np.einsum("kmi,km->ki", J, F))
        nrm = np.linalg.norm(dx / self.scale, axis=1)
        dx *= np.minimum(1.0, self.S / (nrm + 1e-300))[:, None]
        return (Xr + dx).T, r


def _step_function(model: Model, split: bool, step_max: float, k: int,
                   jit: bool | str) -> tuple[ca.Function, bool]:
    """The step Function of the topology (compiled as ``jit`` says) and whether compiled.

    The interpreted Function and, once built or loaded, the compiled one are kept per
    topology; a library missing from the disk cache (``jit="cached"``) is looked for again
    by a later call, a build that failed is not tried again.
    """
    from ..model import compiled as cc

    def build() -> dict[str, Any]:
        if split:
            qa, x, p, phi = model.symbols
            Wt = ca.densify(ca.jacobian(phi, x)).T
            f = ca.Function("closure_jacobian", [qa, x, p], [phi, Wt])
            tag = f"enum:{model.topology.key}:jacobian"
        else:
            f = _clamped_step(model, step_max, k)
            tag = f"enum:{model.topology.key}:{k}:{step_max!r}"
        return {"f": f, "tag": tag, "lib": None, "failed": False}

    entry = model.cached(("enumeration:step", split, float(step_max), int(k)), build)
    if jit == "background" and entry["lib"] is None and not entry["failed"]:
        # compiled when cached; else the compiler runs in the background while this call
        # (and any until it is done) uses the interpreted step: the 0.6 s of a Stewart
        # platform's build overlap the first solve instead of preceding it
        pending = entry.get("pending")
        if pending is None:
            pending = cc.start_library(entry["tag"], [entry["f"]])
            if pending is None:
                entry["failed"] = True
                _no_compiler_warning()
            elif isinstance(pending, dict):
                entry["lib"] = pending[entry["f"].name()]
            else:
                entry["pending"] = pending
        else:
            done = pending.poll()
            if done is not None:
                entry.pop("pending", None)
                if done is False:
                    entry["failed"] = True
                else:
                    entry["lib"] = done[entry["f"].name()]
    elif jit and entry["lib"] is None and not entry["failed"]:
        lib = cc.library(entry["tag"], [entry["f"]], build=jit is True)
        if lib is not None:
            entry["lib"] = lib[entry["f"].name()]
        elif jit is True:
            entry["failed"] = True
            _no_compiler_warning()
    if jit and entry["lib"] is not None:
        return entry["lib"], True
    return entry["f"], False


def _mapped_step(model: Model, width: int, step_max: float, k: int, jit: bool | str,
                 threads: int):
    """The clamped step mapped over ``width`` columns; (step, setup s, compiled, unroll).

    Built once per topology (the geometry is an input). ``jit=True`` compiles it to C
    (through :func:`optkin.model.compiled.library`, so the shared library is cached on
    disk and later processes load it in milliseconds); ``"cached"`` uses a compiled step
    only when it is already in the disk cache.
    """
    t0 = time.perf_counter()
    split = model.nx > FUSED_MAX
    f, compiled = _step_function(model, split, step_max, k, jit)

    def one(w: int, part: int = 0) -> Any:
        if w <= _CACHED_WIDTH:
            fm, single = model.cached(("enumeration:map", split, float(step_max), int(k),
                                       compiled, int(w), part),
                                      lambda: _mapped(model, f, w, part))
        else:  # a wide map: not kept
            fm, single = _mapped(model, f, w, part)
        if split:
            return _SplitStep(fm, single, model, w, step_max)
        return _FusedStep(fm, single, model, w)

    threads = max(1, min(int(threads), width))
    if threads > 1:  # the columns in shares as equal as can be
        shares = [width // threads + (i < width % threads) for i in range(threads)]
        step: Any = _ThreadedStep([one(w, i) for i, w in enumerate(shares)])
    else:
        step = one(width)
    return step, time.perf_counter() - t0, compiled, (1 if split else k)


# ---------------------------------------------------------------------------------------------
# distances between configurations
# ---------------------------------------------------------------------------------------------


def _scaled_dist(model: Model, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """max-norm scaled distances between the assembly modes of the columns of X (nx, n) and
    Y (nx, k), (n, k): angles modulo 2 pi, a quaternion and its negative the same rotation
    (:func:`optkin.model.enumeration.scaled_distances`)."""
    return _enum.scaled_distances(model, X, Y)


def _canon(model: Model, X: np.ndarray) -> np.ndarray:
    return _enum.canonical_columns(model, X)

# ---------------------------------------------------------------------------------------------
# inputs, memory
# ---------------------------------------------------------------------------------------------

_NO_MODE = "no closed configuration exists for these actuated values: "
#: Stalled starts kept per IPOPT rescue (the best residuals; the others are dropped).
_STALLED_PER_RESCUE = 4
#: Entries (columns x solutions x unknowns) of one block of distances.
_DIST_BLOCK = 1 << 18
#: Largest pool of columns (one mapped call; clustering the new solutions of one call
#: costs width^2 in the worst case).
MAX_WIDTH = 1 << 16

# Measured memory (peak resident growth, /proc/self/status VmHWM, of a fresh process) of
# assembly_modes: per column of the pool (the mapped step's inputs and outputs and their
# copies, the starts generated for it, the masks, one block of distances), per start (on
# a continuum of configurations every start becomes a solution of its own: its column,
# hit count, sort key and KinResult), per stalled start kept for the rescues. Each figure
# is a + b * nx bytes (nx unknowns); limits.SAFETY is applied on top.
_COST_COLUMN = (200.0, 160.0)
_COST_START = (6000.0, 400.0)
_COST_STALLED = (200.0, 8.0)
# A column of the mapped step also holds the geometry (an input of the topology's Function:
# CasADi's map repeats it for every column, its values and sparsity): 40 bytes per entry
# of p measured (4.8 KB a column for a 3-RPR, 14 KB for a Stewart-Gough platform); and,
# above FUSED_MAX unknowns, the Jacobians of the numpy solves, 48 bytes per entry of W_p
# (25 KB a column for a 3-UPU in chain form).
_COST_GEOMETRY = 40.0
_COST_JACOBIAN = 48.0


def _assembly_costs(model: Model) -> tuple[float, float, float]:
    nx = model.nx
    col, start, stalled = (a + b * nx for a, b in (_COST_COLUMN, _COST_START, _COST_STALLED))
    col += _COST_GEOMETRY * model.p.size
    if nx > FUSED_MAX:
        col += _COST_JACOBIAN * nx * model.m
    return col, start, stalled


def _check_size_of(model: Model, where: str) -> None:
    """A mechanism of a size beyond MAX_ABS overflows every square (1e300 ** 2)."""
    L = float(model.length)
    if not (np.isfinite(L) and L <= MAX_ABS):
        raise MechanismError(
            f"{where}: the mechanism's size {L:g} is too large (above {MAX_ABS:g}): squares "
            "of its lengths overflow; give lengths of sensible size (change the unit)")


def _qa_arg(model: Model, qa: Any, where: str = "qa") -> np.ndarray:
    """Active joint values: finite numbers (any input), then the usual shape and leg checks."""
    return check_qa(model, as_vector(qa, where, names=list(model.mech.active_names)))


def _guess_arg(guess: Any, where: str = "guess") -> Any:
    """A guess as numbers (any input): None and KinResults pass, 2-D arrays stay 2-D."""
    if guess is None or isinstance(guess, KinResult):
        return guess
    try:
        return as_matrix(guess, where)
    except MechanismError:
        return as_vector(guess, where)


def _defaults_of(where: str) -> dict[str, Any]:
    return TRACK_DEFAULTS if where == "track" else ASSEMBLY_DEFAULTS


def _opt_float(opts: dict[str, Any], key: str, where: str, *, lo: float = 0.0,
               hi: float | None = None, positive: bool = False) -> float:
    """The option ``key`` of ``where`` as a finite float in [lo, hi] (> lo when
    ``positive``): :func:`optkin._checks.check_option`."""
    return check_option(opts, key, where, _defaults_of(where), lo=lo, hi=hi, lo_open=positive)


def _opt_int(opts: dict[str, Any], key: str, where: str, *, lo: int = 0,
             hi: int | None = MAX_ITERATIONS) -> int:
    """The option ``key`` of ``where`` as an integer in [lo, hi]."""
    return check_option(opts, key, where, _defaults_of(where), integer=True, lo=lo, hi=hi)


def _opt_auto(opts: dict[str, Any], key: str, where: str, conv) -> Any:
    v = opts[key]
    if isinstance(v, str):
        if v == "auto":
            return v
        raise MechanismError(f"{where}: option {key} must be 'auto' or a number, got {show(v)}")
    return conv(v)


#: Options only the multistart reads: giving one selects it under ``method="auto"``.
_MULTISTART_ONLY = ("starts", "min_starts", "target", "target_upper", "bound", "width",
                    "max_iter", "step_max", "dedup_tol", "rescue", "jit", "continua")


def _homotopy_ready(model: Model, given: dict[str, Any]) -> bool:
    """``method="auto"`` takes the homotopy: the package ships this topology's start
    system, verified complete, for the geometry's pattern of structural entries or a wider
    family's (a deterministic choice: never the state of a cache), and no option of the
    multistart was given."""
    if any(k in given for k in _MULTISTART_ONLY) or model.m != model.nx:
        return False
    from .homotopy import covering_start, shipped_start

    try:  # the pattern's own, or a wider family's (homotopy_modes starts from it); one
        # shipped unverified (Tsai's 3-UPU) can never give a complete answer: not tried
        S = shipped_start(model)
        if S is None:
            S = covering_start(model)
        return S is not None and S.verified
    except MechanismError:
        return False


#: Checked options of assembly_modes by their values (:func:`_assembly_options`).
_CHECKED_OPTIONS: dict[Any, dict[str, Any]] = {}


def _assembly_options(opts: dict[str, Any], model: Model, given_time: bool = True
                      ) -> dict[str, Any]:
    """Every option of assembly_modes converted and checked (MechanismError naming it); the
    default time limit is lowered to the time budget, a given one may not exceed it.
    Options of hashable values are checked once per set of values (keyed with their types:
    ``certify=1`` is refused where ``True`` passes) and time budget: 20-70 us of a 3-RPR's
    1 ms call."""
    tb = time_budget()
    try:
        key: Any = (bool(given_time), tb, tuple((k, type(v), v) for k, v in opts.items()))
        hash(key)
    except TypeError:  # an array, a list: checked every time
        key = None
    got = _CHECKED_OPTIONS.get(key) if key is not None else None
    if got is not None:
        return dict(got)
    o = _check_assembly_options(opts, given_time, tb)
    if key is not None and len(_CHECKED_OPTIONS) < 256:
        _CHECKED_OPTIONS[key] = dict(o)
    return o


def _check_assembly_options(opts: dict[str, Any], given_time: bool, tb: float
                            ) -> dict[str, Any]:
    w = "assembly_modes"
    o: dict[str, Any] = {}
    o["tol"] = _opt_float(opts, "tol", w, positive=True)
    o["starts"] = _opt_int(opts, "starts", w, lo=1, hi=None)
    o["min_starts"] = _opt_auto(opts, "min_starts", w,
                                lambda v: _opt_int({"min_starts": v}, "min_starts", w, hi=None))
    o["target"] = _opt_float(opts, "target", w)
    o["target_upper"] = _opt_float(opts, "target_upper", w)
    tl = check_option(opts, "time_limit", w, ASSEMBLY_DEFAULTS, lo=0.0, finite=False)
    if not given_time:
        tl = min(tl, tb)
    if tl > tb:
        raise MechanismError(
            f"{w}: option time_limit = {tl:g} s exceeds the time budget of {tb:g} s "
            "(OPTKIN_TIME_BUDGET); give at most that, or raise the budget")
    o["time_limit"] = tl
    b = opts["bound"]
    if b is None or (isinstance(b, str) and b == "auto"):
        o["bound"] = b
    elif isinstance(b, str):
        raise MechanismError(f"{w}: option bound must be 'auto', None or an integer >= 0 "
                             f"(the known largest number of assembly modes), got {show(b)}")
    else:
        o["bound"] = _opt_int(opts, "bound", w, hi=None)
    wd = opts["width"]
    if isinstance(wd, str) and wd == "auto":
        o["width"] = wd
    else:
        if isinstance(wd, str):
            raise MechanismError(f"{w}: option width must be a power of 2 or 'auto', got "
                                 f"{show(wd)}")
        wd = _opt_int(opts, "width", w, lo=1, hi=None)
        if wd & (wd - 1):
            raise MechanismError(f"{w}: option width must be a power of 2 or 'auto', got "
                                 f"{show(wd)}")
        o["width"] = wd
    o["max_iter"] = _opt_int(opts, "max_iter", w, lo=1)
    o["step_max"] = _opt_auto(opts, "step_max", w, lambda v: _opt_float(
        {"step_max": v}, "step_max", w, positive=True))
    o["dedup_tol"] = _opt_float(opts, "dedup_tol", w)
    o["rescue"] = _opt_int(opts, "rescue", w, lo=0, hi=None)
    if not isinstance(opts["certify"], (bool, np.bool_)):
        raise MechanismError(f"{w}: option certify must be True or False, got "
                             f"{show(opts['certify'])}")
    o["certify"] = bool(opts["certify"])
    if not isinstance(opts["continua"], (bool, np.bool_)):
        raise MechanismError(f"{w}: option continua must be True or False, got "
                             f"{show(opts['continua'])}")
    o["continua"] = bool(opts["continua"])
    if opts["method"] not in ("auto", "multistart", "homotopy"):
        raise MechanismError(f"{w}: option method must be 'auto', 'multistart' or "
                             f"'homotopy', got {show(opts['method'])}")
    o["method"] = opts["method"]
    j = opts["jit"]
    if isinstance(j, (bool, np.bool_)):
        o["jit"] = bool(j)
    elif isinstance(j, str) and j in ("auto", "cached"):
        o["jit"] = j
    else:
        raise MechanismError(f"{w}: option jit must be True, False, 'auto' or 'cached', got "
                             f"{show(j)}")
    o["threads"] = _opt_auto(opts, "threads", w,
                             lambda v: _opt_int(opts, "threads", w, lo=1, hi=MAX_THREADS))
    return o


class _Columns:
    """A growable (nx, n) array of columns (amortised appends)."""

    def __init__(self, nx: int) -> None:
        self.buf = np.zeros((nx, 16))
        self.n = 0

    def append(self, x: np.ndarray) -> None:
        if self.n == self.buf.shape[1]:
            self.buf = np.hstack([self.buf, np.zeros_like(self.buf)])
        self.buf[:, self.n] = x
        self.n += 1

    def view(self) -> np.ndarray:
        return self.buf[:, :self.n]


class _Stalled:
    """The ``keep`` stalled starts of smallest residual (what the rescues may use)."""

    def __init__(self, keep: int) -> None:
        self.keep = keep
        self.r: list[float] = []
        self.x: list[np.ndarray] = []

    def add(self, r: float, x: np.ndarray) -> None:
        if self.keep <= 0:
            return
        self.r.append(r)
        self.x.append(x.copy())
        if len(self.r) >= 2 * self.keep:
            order = np.argsort(self.r, kind="stable")[: self.keep]
            self.r = [self.r[i] for i in order]
            self.x = [self.x[i] for i in order]

    def best(self) -> tuple[np.ndarray, np.ndarray]:
        """(residuals, columns), best first."""
        if not self.r:
            return np.zeros(0), np.zeros((0, 0))
        order = np.argsort(self.r, kind="stable")[: self.keep]
        return np.array(self.r)[order], np.array(self.x)[order].T


def _nearest(model: Model, X: np.ndarray, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each column of X, the index of the nearest column of Y and the scaled distance
    (inf without columns); in blocks of Y, so that memory stays bounded."""
    n, k = X.shape[1], Y.shape[1]
    arg = np.zeros(n, dtype=int)
    best = np.full(n, np.inf)
    if n == 0 or k == 0:
        return arg, best
    step = max(1, _DIST_BLOCK // max(1, n * model.nx))
    rows = np.arange(n)
    for a in range(0, k, step):
        D = _scaled_dist(model, X, Y[:, a:a + step])
        j = np.argmin(D, axis=1)
        d = D[rows, j]
        better = d < best
        best[better] = d[better]
        arg[better] = j[better] + a
    return arg, best


def _nn_update(model: Model, Y: np.ndarray, s0: int, nn: np.ndarray) -> np.ndarray:
    """Nearest-neighbour distances of the columns of Y after columns s0: were added (nn
    holds those of the first s0); in blocks."""
    s1 = Y.shape[1]
    nn = np.concatenate([nn[:s0], np.full(s1 - s0, np.inf)])
    step = max(1, _DIST_BLOCK // max(1, s1 * model.nx))
    for a in range(s0, s1, step):
        b = min(s1, a + step)
        D = _scaled_dist(model, Y[:, a:b], Y)
        D[np.arange(b - a), np.arange(a, b)] = np.inf
        nn[a:b] = np.minimum(nn[a:b], D.min(axis=1))
        nn = np.minimum(nn, D.min(axis=0))
    return nn


# ---------------------------------------------------------------------------------------------
# assembly_modes
# ---------------------------------------------------------------------------------------------


#: One-sided confidence level of ``p_new_upper`` (see the module docstring for why 99 %).
P_NEW_CONFIDENCE = 0.99
def poisson_upper(k: int) -> float:
    """One-sided 99 % upper confidence limit of a Poisson mean from ``k`` observed events:
    the mean m at which P(X <= k) = sum_{j<=k} e^-m m^j / j! falls to 1 %, which is
    chi2.ppf(0.99, 2 k + 2) / 2 = scipy.special.gammaincinv(k + 1, 0.99); -ln 0.01 = 4.6 for
    k = 0.

    Solved here by safeguarded Newton steps on the Poisson sum (dP/dm = -e^-m m^k / k!)
    rather than by ``scipy.special``, whose import costs a worker process about 0.3 s.
    """
    k = int(k)
    if k < 0:
        raise ValueError(f"poisson_upper: k must be >= 0, got {k}")
    alpha = 1.0 - P_NEW_CONFIDENCE
    j = np.arange(k + 1)
    log_fact = np.r_[0.0, np.cumsum(np.log(np.arange(1, k + 1)))]

    def cdf_pmf(m: float) -> tuple[float, float]:
        terms = np.exp(-m + j * np.log(m) - log_fact)
        return float(math.fsum(terms)), float(terms[-1])

    lo, hi = max(float(k), 1e-300), k + 10.0 * math.sqrt(k + 1.0) + 10.0
    m = 0.5 * (lo + hi)
    for _ in range(200):
        c, p = cdf_pmf(m)
        if c > alpha:
            lo = m
        else:
            hi = m
        nxt = m + (c - alpha) / p if p > 0 else 0.5 * (lo + hi)
        if not lo < nxt < hi:
            nxt = 0.5 * (lo + hi)
        if abs(nxt - m) <= 1e-15 * m or hi - lo <= 1e-15 * hi:
            return nxt
        m = nxt
    return m


def draws(converged: int, starts: int) -> int:
    """The draws the Good-Turing figures count: the converged starts (a start that does
    not converge draws no mode); with none converged, the starts (then p_new_upper is the
    rule of three over them: no solution is found by a further start with probability
    >= 1 - 4.6 / n)."""
    return converged if converged else starts


def _good_turing(hits: Sequence[int], draws: int) -> dict[str, Any]:
    """Good-Turing figures over ``draws`` converged starts (each a draw of a mode)."""
    starts = draws
    h = np.asarray(hits, dtype=int)
    f1 = int(np.sum(h == 1))
    f2 = int(np.sum(h == 2))
    s_obs = int(h.size)
    chao1 = s_obs + (f1 * f1 / (2.0 * f2) if f2 > 0 else f1 * (f1 - 1) / 2.0)
    return {
        "singletons": f1,
        "doubletons": f2,
        "p_new": f1 / starts if starts else 1.0,
        "p_new_upper": min(1.0, poisson_upper(f1) / starts) if starts else 1.0,
        "estimated_total": float(chao1),
    }


def assembly_modes(mech: Mechanism, qa: Any, **options: Any) -> SolutionSet:
    """Every real assembly mode: all distinct solutions x of Phi(q_a, x) = 0.

    Low-discrepancy starts are solved together by Khalil's clamped Newton iteration ([7.55])
    in one compiled, mapped CasADi Function, deduplicated as they converge (angles modulo
    2 pi, quaternion sign, a tolerance relative to the mechanism size); IPOPT only rescues
    stalled starts. See the module docstring for the start distributions and the stopping
    rules.

    Parameters
    ----------
    mech : Mechanism
        Any mechanism the model describes (Khalil tables included: their passive and cut
        joints are the unknowns).
    qa : array (n_actuated,)
        Active joint values.
    **options
        See :data:`ASSEMBLY_DEFAULTS`: ``seed`` (of the Sobol scrambling and the
        homotopy's random gamma: a run is reproducible from it), ``starts`` (budget), ``target`` and
        ``target_upper`` (stop when the Good-Turing estimate ``p_new`` of the probability
        of a new solution is at most ``target`` and its upper bound ``p_new_upper`` at most
        ``target_upper``), ``time_limit`` (s), ``bound`` (known maximum count, ``"auto"``
        uses :func:`known_bound`), ``tol``, ...

    Memory and time
    ---------------
    Checked against the budget of :mod:`optkin.limits` before anything is allocated
    (:class:`MechanismError` naming the option and its largest allowed value):
    ``width`` costs about 200 + 160 nx + 40 np bytes per column (nx unknowns, np entries
    of the geometry vector, which the mapped step takes as an input; 48 nx m more above
    :data:`FUSED_MAX` unknowns; measured 4.8 KB for a 3-RPR, 14 KB for a Stewart-Gough
    platform) and is at most :data:`MAX_WIDTH`;
    without a known ``bound`` (Khalil mechanisms, ``bound=None``), ``starts`` costs about
    6000 + 400 nx bytes per start, since on a continuum of configurations every start
    becomes a solution of its own (its column, KinResult and JSON: 1.7 KB + 4.7 KB
    measured for a five-bar); with a bound the search stops there, so at most
    bound + width solutions are kept whatever ``starts``; ``rescue`` keeps 4 stalled
    starts per rescue,
    200 + 8 nx bytes each. ``time_limit`` (also for the IPOPT rescues) may not exceed the
    time budget; ``max_iter`` is at most :data:`optkin.limits.MAX_ITERATIONS`, ``threads``
    at most :data:`optkin.limits.MAX_THREADS`.

    Returns
    -------
    SolutionSet
        ``kind="assembly modes"``, sorted by the unknowns x. Each :class:`KinResult` carries
        its residual, the condition number of W_p (``cond``) and in ``stats.extra["hits"]``
        how many starts converged to it. ``info`` holds the account: ``starts`` (starts run
        to the end), ``converged`` (n), ``hits`` (per solution), ``singletons`` (N1),
        ``p_new`` (the Good-Turing estimate N1 / n of the probability that the next
        converged start lands on a new solution: over converged starts, since those that do
        not converge draw no mode), ``p_new_upper`` (a conservative bound on it: u(N1) / n,
        u(k) the one-sided 99 % upper confidence limit of a Poisson mean from k events,
        chi2.ppf(0.99, 2k+2)/2; 4.6 / n, the rule of three at 99 %, when N1 = 0: a mode
        drawn by a share p >= 4.6 / n of the converging starts is missed by all n with
        probability <= 1 %),
        ``estimated_total`` (Chao1), ``bound`` and ``complete`` (True when the count reached
        the known bound), ``stop_reason``, ``time`` and ``setup_time`` (compilation);
        ``success``, ``status`` and ``message`` (also at the top level of ``to_dict()``):
        no mode found is ``success=False``, status ``"infeasible"`` (``"time_limit"``
        when the time limit stopped the search), and the message says that no closed
        configuration exists for these actuated values.

    Examples
    --------
    >>> import optkin
    >>> m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    >>> modes = optkin.assembly_modes(m, [1.2, 1.9])
    >>> len(modes), modes.info["complete"]
    (2, True)
    """
    opts = merge_options(ASSEMBLY_DEFAULTS, options, "assembly_modes")
    check_mechanism(mech, "assembly_modes")
    seed = check_number(opts["seed"], "assembly_modes: seed", integer=True, lo=0,
                        hi=2**63 - 1, default=0, path=("options", "seed"))
    model = get_model(mech)
    _check_size_of(model, "assembly_modes")
    qa = _qa_arg(model, qa)
    o = _assembly_options(opts, model, "time_limit" in options)
    method = o["method"]
    tried = None
    if method == "auto":
        method = "homotopy" if _homotopy_ready(model, options) else "multistart"
    if method == "homotopy":
        checkpoint()
        from .homotopy import homotopy_modes

        modes = homotopy_modes(mech, qa, seed=int(seed), tol=o["tol"],
                               time_limit=o["time_limit"],
                               threads=(auto_threads() if o["threads"] == "auto"
                                        else o["threads"]), _checked=True)
        if o["method"] == "auto" and not (len(modes) and modes.complete
                                          and modes.info["singular_near_real"] == 0
                                          and modes.info["status"] not in LIMIT_REACHED):
            tried = modes.info["message"]  # the multistart accounts for it (and continua)
        else:
            if o["certify"] and len(modes):
                from .certify import stamp

                modes.info["certified"] = stamp(model, qa, modes)
            return modes
    t_start = timer()
    tol = o["tol"]
    nx = model.nx
    bound = known_bound(mech) if o["bound"] == "auto" else o["bound"]
    small = nx < 6
    split = nx > FUSED_MAX  # closure and Jacobian in CasADi, the solves in numpy
    width = o["width"]
    if width == "auto":
        width = 64 if small else 256
    jit = o["jit"]
    if jit == "auto":
        jit = "cached" if small else "background"
    threads = 1 if small or o["threads"] == "auto" else min(o["threads"], width)
    unroll = 3 if small else 2  # Newton iterations per call: fewer Python round trips
    budget = o["starts"]
    min_starts = (256 if small else 2048) if o["min_starts"] == "auto" else o["min_starts"]
    target = o["target"]
    target_upper = o["target_upper"]
    time_limit = o["time_limit"]
    max_iter = o["max_iter"]
    dedup = o["dedup_tol"]
    n_rescue = o["rescue"]
    # memory, before anything is allocated: the pool of columns, then every start (each
    # may become a solution of its own, as on a continuum of configurations), then the
    # stalled starts kept for the rescues
    per_col, per_start, per_stalled = _assembly_costs(model)
    sizes = [("width", width, per_col, {"hi": MAX_WIDTH, "fit": floor_pow2,
                                        "unit": "one column of the pool"}),
             ("rescue", n_rescue, per_stalled * _STALLED_PER_RESCUE,
              {"lo": 0, "unit": f"{_STALLED_PER_RESCUE} stalled starts kept per rescue"})]
    kept = 0.0
    if bound is None:
        sizes.append(("starts", budget, per_start,
                      {"unit": "one start, which may become a solution"}))
    else:  # the search stops at the bound: at most bound + width solutions are kept
        kept = SAFETY * per_start * min(budget, bound + width)
    check_sizes("assembly_modes", *sizes, fixed=kept)
    checkpoint()  # validation stops here: every argument is checked

    starts = _Starts(model, qa, int(seed), width, jit)
    info: dict[str, Any] = {"bound": bound, "width": width}
    if tried is not None:  # method="auto": why the homotopy's answer was not kept
        info["homotopy"] = tried
    if starts.empty_reason is not None:
        info.update({"success": False, "status": "infeasible",
                     "message": _NO_MODE + starts.empty_reason, "starts": 0,
                     "converged": 0, "hits": [], "p_new": 0.0, "p_new_upper": 0.0,
                     "singletons": 0,
                     "doubletons": 0, "estimated_total": 0.0, "complete": True,
                     "stop_reason": "infeasible", "time": timer() - t_start,
                     "setup_time": 0.0, "rescued": 0, "jit": False, "dimension": 0})
        return SolutionSet([], "assembly modes", info, seed=int(seed), dimension=0,
                           stats=EnumerationStats("multistart", 0, 0, 0, 0, 0, bound, True))

    step_max = o["step_max"]
    if step_max == "auto":
        step_max = 1.0 if small or split else 0.3
    step, setup, compiled, unroll = _mapped_step(model, width, float(step_max), unroll, jit,
                                                 threads)
    if split:  # legs in chain form: about twice the iterations of the reduced closures
        max_iter *= 2
    t0 = timer()
    issued = min(width, budget)
    X = starts.take(width)
    live = np.zeros(width, dtype=bool)
    live[:issued] = True
    it = np.zeros(width, dtype=int)
    sols = _Columns(nx)
    hits: list[int] = []
    first_nit: list[int] = []
    done = converged = 0
    n_once = 0
    total_iter = 0
    excluded = 0
    diverged = 0
    excl_res = 1e-5 * max(1.0, model.length)
    excl_dist = 1e-3
    nn = np.zeros(0)  # distance of each solution to its nearest other solution
    # a start still far from closing after half its iterations is given up (it would most
    # likely wander until max_iter): Newton converges in a few steps once |Phi| is small
    stall_iter, stall_res = max_iter // 2, 1e-3 * max(1.0, model.length)
    stalled = _Stalled(_STALLED_PER_RESCUE * n_rescue)
    big = 1e3 * model.x_scale[:, None]
    stop = None
    while True:
        Xn, r = step(qa, X)
        total_iter += unroll * int(live.sum())
        it += unroll
        finite = np.all(np.isfinite(Xn), axis=0)
        conv = live & (r <= tol) & finite
        # exclusion: a start already inside the quadratic-convergence region of a known
        # solution is counted as a hit of it without iterating to round-off
        near = live & ~conv & finite & (r <= excl_res)
        if near.any() and sols.n:
            jn = np.flatnonzero(near)
            kn, dn = _nearest(model, _canon(model, Xn[:, jn]), sols.view())
            radius = np.minimum(excl_dist, 0.25 * nn)  # per solution: 1e-3, or a quarter
            inside = dn < radius[kn]  # of the distance to its nearest neighbour
            for k in kn[inside]:
                hits[k] += 1
                n_once -= hits[k] == 2
            excluded_now = np.zeros(width, dtype=bool)
            excluded_now[jn[inside]] = True
            converged += int(inside.sum())
            excluded += int(inside.sum())
        else:
            excluded_now = None
        away = ~finite | np.any(np.abs(Xn) > big, axis=0)
        bad = live & ~conv & (away | (it >= max_iter) | ((it >= stall_iter) & (r > stall_res)))
        diverged += int(np.count_nonzero(bad & away))
        if conv.any():
            idx = np.flatnonzero(conv)
            C = _canon(model, Xn[:, idx])
            if sols.n:
                kmin, dmin = _nearest(model, C, sols.view())
                known = dmin < dedup
                for k in kmin[known]:
                    hits[k] += 1
                    n_once -= hits[k] == 2
            else:
                known = np.zeros(idx.size, dtype=bool)
            unk = np.flatnonzero(~known)
            if unk.size:  # new solutions, clustered among themselves
                Cu = C[:, unk]
                rep = np.full(unk.size, -1)
                s_before = sols.n
                for j in range(unk.size):
                    if rep[j] >= 0:
                        continue
                    rest = np.flatnonzero(rep < 0)
                    same = rest[_scaled_dist(model, Cu[:, rest], Cu[:, j:j + 1])[:, 0] < dedup]
                    rep[same] = j
                    sols.append(Cu[:, j])
                    cnt = int(same.size)
                    hits.append(cnt)
                    n_once += cnt == 1
                    first_nit.append(int(it[idx[unk[j]]]))
                nn = _nn_update(model, sols.view(), s_before, nn)
            converged += idx.size
        if bad.any():
            for col in np.flatnonzero(bad):
                if np.isfinite(r[col]) and finite[col]:
                    stalled.add(float(r[col]), Xn[:, col])
        fin = conv | bad
        if excluded_now is not None:
            fin |= excluded_now
        done += int(fin.sum())
        X = Xn
        # stopping rules
        if bound is not None and len(hits) >= bound:
            stop = "bound"
        elif (done >= (min_starts if bound is None or (len(hits) - bound) % 2 == 0
                       else 4 * min_starts)
              and n_once <= target * draws(converged, done)
              and poisson_upper(n_once) <= target_upper * draws(converged, done)):
            # with a known bound (an even number of complex solutions), an odd count means a
            # mode is still missing (non-real solutions come in conjugate pairs), unless a
            # degenerate case has a double root: run four times longer before stopping.
            # The bound u(N1) / n is a table look-up
            stop = "target"
        elif timer() - t0 > time_limit:
            stop = "time_limit"
        if stop:
            break
        # refill finished columns with fresh starts
        free = np.flatnonzero(fin | ~live)
        n_new = min(free.size, budget - issued)
        if n_new > 0:
            cols = free[:n_new]
            X[:, cols] = starts.take(n_new)
            it[cols] = 0
            live[cols] = True
            issued += n_new
        if free.size > n_new:
            live[free[n_new:]] = False
            X[:, ~live] = 1.0  # parked columns: harmless finite values
        if not live.any():
            stop = "budget"
            break
    t_newton = timer() - t0

    # IPOPT rescues of stalled starts (best residuals first, away from known solutions),
    # within the time limit too
    rescued = 0
    stalled_r, cand = stalled.best()
    if stop != "bound" and n_rescue > 0 and cand.shape[1]:
        cand = cand[:, stalled_r < 0.1 * max(1.0, model.length)]
        tried = 0
        solver = model.nlp() if cand.shape[1] else None
        for j in range(cand.shape[1]):
            if tried >= n_rescue or (bound is not None and len(hits) >= bound):
                break
            if timer() - t0 > time_limit:
                stop = "time_limit"
                break
            x0 = cand[:, j]
            if sols.n and _nearest(model, _canon(model, x0[:, None]), sols.view())[1][0] < 1e-3:
                continue
            tried += 1
            sol = solver(x0=x0, p=np.concatenate([qa, x0, model.p]), lbg=0, ubg=0)
            x1, res1, _, ok = newton(model, qa, np.array(sol["x"]).ravel(), tol, 8)
            if not ok:
                continue
            c1 = _canon(model, x1[:, None])
            kk, d = _nearest(model, c1, sols.view())
            if sols.n and d[0] < dedup:
                hits[int(kk[0])] += 1
            else:
                sols.append(c1[:, 0])
                hits.append(1)
                first_nit.append(max_iter)
                rescued += 1
            converged += 1
    sols = sols.view()

    # results, sorted by x
    order = sorted(range(len(hits)), key=lambda k: tuple(np.round(sols[:, k] / model.x_scale, 9)))
    elapsed = timer() - t_start
    out: list[KinResult] = []
    for k in order:
        # polished to round-off: a residual at tol leaves the pose off by cond(W_p) tol
        x, _, nit, ok = newton(model, qa, sols[:, k], tol, 5)
        stats = SolverStats("newton-multistart", setup, t_newton, first_nit[k], "converged",
                            {"hits": hits[k], "jit": compiled})
        kr = make_result(model, qa, x, tol, first_nit[k], stats)
        if not kr.success:  # the polish failed (never expected: converged columns are at tol)
            kr = make_result(model, qa, sols[:, k], tol, first_nit[k], stats)
        out.append(kr)
    hits_sorted = [hits[k] for k in order]
    comps: list = []
    if o["continua"] and (not out or any(not kr.cond <= _SINGULAR_COND for kr in out)):
        out, hits_sorted, comps = _continua(model, qa, out, hits_sorted, starts, tol, dedup)
    dimension = max((c.dimension for c in comps), default=0)
    if o["certify"] and out:
        from .certify import stamp

        info["certified"] = stamp(model, qa, out)
    gt = _good_turing(hits_sorted, draws(converged, done))
    # more isolated modes than the bound: some are not what the bound counts (points of a
    # continuum that looked isolated, or duplicates); never called complete
    complete = bound is not None and len(out) == bound and not comps
    msg = (f"{len(out)} assembly modes from {done} starts ({converged} converged); "
           + (f"complete: the known bound {bound} is reached" if complete else
              f"Good-Turing probability that a further start finds a new one: {gt['p_new']:.2g}"
              f" (99 % upper bound {gt['p_new_upper']:.2g})")
           + f"; stopped by {stop}")
    if bound is not None and len(out) > bound:
        msg += (f"; more than the known bound {bound}: not all are isolated solutions of a "
                "generic mechanism")
    success = bool(out) and all(s.success for s in out)
    if comps:
        n_s = sum(len(c.samples) for c in comps)
        msg = ((f"{len(out)} isolated assembly modes" if out else "no isolated assembly mode")
               + f" and {len(comps)} continuum component(s) of dimension "
               + ", ".join(str(c.dimension) for c in comps)
               + f" ({n_s} sample configurations in components): the solutions are not "
               "isolated (a self-motion or an architecture singularity); " + msg)
        success = all(s.success for s in out)
        status = "singular"
    elif not out:
        status = TIME_LIMIT if stop == "time_limit" else INFEASIBLE
        tried = f"none of {done} starts closed the loops (stopped by {stop})"
        msg = (_NO_MODE + tried if stop != "time_limit" else
               "no closed configuration found for these actuated values within the time "
               f"limit: {tried}")
    elif out:
        status = "optimal" if success else "inaccurate"
    info.update({
        "success": success,
        "status": status,
        "message": msg,
        "starts": done,
        "issued": issued,
        "converged": converged,
        "hits": hits_sorted,
        **gt,
        "complete": complete,
        "stop_reason": stop,
        "time": elapsed,
        "newton_time": t_newton,
        "setup_time": setup,
        "iterations": total_iter,
        "rescued": rescued,
        "excluded": excluded,
        "jit": compiled,
        "dimension": dimension,
    })
    n_sing = sum(1 for kr in out if not kr.cond <= _SINGULAR_COND)
    n_sing += sum(len(c.samples) for c in comps)
    account = EnumerationStats("multistart", done, converged, diverged, n_sing,
                               max(0, done - converged - diverged), bound, complete)
    return SolutionSet(out, "assembly modes", info, seed=int(seed), dimension=dimension,
                       components=comps, stats=account)


#: Condition number of W_p above which a solution is examined for a continuum through it.
_SINGULAR_COND = 1e8
#: Starts projected by Gauss-Newton when Newton found nothing (a continuum stalls Newton).
_CONTINUA_PROBES = 16
#: Samples kept per dimension of continuum (each pair may be joined by projections).
_CONTINUA_SAMPLES = 12


def _continua(model: Model, qa: np.ndarray, out: list[KinResult], hits: list[int],
              starts: _Starts, tol: float, dedup: float):
    """Split the solutions into isolated ones and samples of continua (by
    :func:`optkin.solvers.continua.local_dimension`); with no solution at all, project a
    few more starts by Gauss-Newton of least norm, which reaches a continuum where Newton
    stalls. Returns (isolated, their hits, components)."""
    from .continua import Component, group, local_dimension, project

    keep, keep_hits, pts = [], [], []
    for kr, h in zip(out, hits):
        d = local_dimension(model, qa, kr.x, tol) if not kr.cond <= _SINGULAR_COND else 0
        if d:
            pts.append((kr.x, d))
        else:
            keep.append(kr)
            keep_hits.append(h)
    if not out:
        X = starts.take(_CONTINUA_PROBES)
        for j in range(X.shape[1]):
            y, _, ok = project(model, qa, X[:, j], tol)
            if not ok:
                continue
            y = model.canonical_x(y)
            d = local_dimension(model, qa, y, tol)
            if d:
                pts.append((y, d))
                continue
            if keep and np.min(_scaled_dist(model, np.array([k.x for k in keep]).T,
                                            y[:, None])) < dedup:
                continue
            stats = SolverStats("gauss-newton", 0.0, 0.0, 0, "converged", {"hits": 1})
            keep.append(make_result(model, qa, y, tol, 0, stats))
            keep_hits.append(1)
    comps = []
    for d in sorted({d for _, d in pts}):
        xs = [x for x, dd in pts if dd == d][:_CONTINUA_SAMPLES]
        for idx in group(model, qa, xs, tol):
            samples = []
            for i in idx:
                stats = SolverStats("continuum", 0.0, 0.0, 0, "converged", {"dimension": d})
                kr = make_result(model, qa, xs[i], tol, 0, stats, status="singular",
                                 message=f"on a continuum of solutions of dimension {d}")
                samples.append(kr)
            comps.append(Component(d, samples))
    return keep, keep_hits, comps


# ---------------------------------------------------------------------------------------------
# track
# ---------------------------------------------------------------------------------------------


def _scaled_wp(model: Model, qa: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    phi, Wp, Wa = model.jac(qa, x)
    Wp = np.array(Wp) * model.x_scale[None, :]
    return np.array(phi).ravel(), Wp, np.array(Wa)


def _det_cond(Wp: np.ndarray) -> tuple[float, float]:
    if Wp.shape[0] != Wp.shape[1]:
        s = np.linalg.svd(Wp, compute_uv=False)
        return float(s[-1]), float(s[0] / s[-1]) if s[-1] > 0 else float("inf")
    det = float(np.linalg.det(Wp))
    try:
        cond = float(np.linalg.cond(Wp))
    except np.linalg.LinAlgError:
        cond = float("inf")
    return det, cond


def _jac_np(model: Model, qa: np.ndarray, x: np.ndarray):
    """(Phi, W_p, W_a) as numpy arrays, through the model's buffered (compiled when
    available) evaluator."""
    ev = model.fast("W")
    out = ev(np.asarray(qa, dtype=float), np.asarray(x, dtype=float))
    return out[0].copy(), ev.dense(1), ev.dense(2)


def _corrector(model: Model, qa: np.ndarray, x: np.ndarray, tol: float, max_iter: int,
               max_move: float):
    """Plain Newton from x. Returns (x, ok, iterations, W_p, W_a at x); fails when it does
    not converge in ``max_iter`` iterations or moves more than ``max_move`` (scaled)."""
    x0 = x.copy()
    s = model.x_scale
    for k in range(max_iter + 1):
        phi, Wp, Wa = _jac_np(model, qa, x)
        if np.max(np.abs(phi)) <= tol:
            return x, True, k, Wp, Wa
        if k == max_iter:
            break
        try:
            if Wp.shape[0] == Wp.shape[1]:
                dx = -np.linalg.solve(Wp, phi)
            else:
                dx = -np.linalg.lstsq(Wp, phi, rcond=None)[0]
        except np.linalg.LinAlgError:
            break
        x = x + dx
        if not np.all(np.isfinite(x)) or np.max(np.abs(x - x0) / s) > max_move:
            break
    return x, False, max_iter, None, None


#: Smallest ``min_step`` of :func:`track` (a fraction of one segment: below it the
#: sub-steps no longer move s in floating point within any sensible time).
MIN_STEP = 1e-12
# Measured memory of track per path point (its KinResult, det and cond, its row of the
# path): a + b * (number of joints) bytes; limits.SAFETY on top.
_COST_POINT = (6000.0, 150.0)


def _track_cost(model: Model) -> float:
    a, b = _COST_POINT
    return a + b * (len(model.mech.joint_names) + model.nx)


def _path_arg(model: Model, path: Any, where: str) -> np.ndarray:
    """Rows of active joint values (N, na) from any input, else a MechanismError."""
    na = model.na
    try:
        P = as_matrix(path, where)
    except MechanismError:
        P = as_vector(path, where)  # not numbers, not finite, 3-D: its own message
        P = P[:, None] if na == 1 else P
    if P.ndim != 2 or P.shape[1] != na or P.shape[0] < 1:
        raise MechanismError(
            f"{where}: expected an array of shape (N, {na}) (one row of "
            f"{list(model.mech.active_names)} per path point), got shape {P.shape}")
    return P


def _tangent(Wp: np.ndarray, Wa: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """dx = -W_p^-1 W_a dq_a ([7.49]); least squares when W_p is not square."""
    try:
        if Wp.shape[0] == Wp.shape[1]:
            return -np.linalg.solve(Wp, Wa @ dq)
        return -np.linalg.lstsq(Wp, Wa @ dq, rcond=None)[0]
    except np.linalg.LinAlgError:
        return np.zeros(Wp.shape[1])


def track(mech: Mechanism, qa_path: Any, guess: Any = None, **options: Any) -> SolutionSet:
    """Follow one assembly mode along a path of actuated values.

    Predictor-corrector continuation: the tangent dx = -W_p^-1 W_a dq_a ([7.49]) predicts,
    a few plain Newton iterations correct. A sub-step is halved (down to ``min_step`` of a
    segment) when the corrector fails, when it has to move the prediction by more than
    ``contraction`` times the predicted move (the solution is not the smooth continuation:
    near a singularity two modes come close), or when det W_p changes sign. The path stops
    with status ``"singular"`` where det W_p changes sign (a parallel singularity is crossed:
    continuing would change the assembly mode), where cond(W_p) (columns scaled by the
    mechanism size) exceeds ``cond_max``, or where the halving runs out next to a
    near-singular configuration (the mode ends at a fold); with ``"iteration_limit"`` where
    the corrector fails away from any singularity (e.g. the legs cannot close).

    Parameters
    ----------
    mech : Mechanism
    qa_path : array (N, n_actuated)
        The actuated values along the path.
    guess : optional
        Selects the assembly mode at ``qa_path[0]``: a :class:`KinResult` (e.g. one of
        :func:`assembly_modes`), x, all joints, or (platforms) a pose; None: the home.
    **options
        See :data:`TRACK_DEFAULTS`. ``min_step`` is at least :data:`MIN_STEP`, ``max_iter``
        at most :data:`optkin.limits.MAX_ITERATIONS`.

    Notes
    -----
    Memory and time: each path point costs about 6000 + 150 (nq + nx) bytes (its
    KinResult and JSON; 6.2 KB measured for a five-bar), checked against the memory budget
    of :mod:`optkin.limits` before tracking (``len(qa_path)``). When the time budget runs
    out, the path stops there with status ``"time_limit"``.

    Returns
    -------
    SolutionSet
        ``kind="path"``: one :class:`KinResult` per path point reached; ``stats`` the typed
        account (:class:`optkin.results.TrackStats`: points, reached, stopped_at, s_stop,
        max_cond, halvings, time). ``info``: ``status``
        (``"optimal"`` when the whole path was followed), ``success``, ``stopped_at`` (index of
        the first point not reached, None when complete), ``s_stop`` (fraction of the segment
        into it where the path stopped, or where det W_p crosses zero, interpolated),
        ``qa_stop``, ``message``, ``det`` and ``cond`` (of the scaled W_p at each point
        reached), ``max_cond``, ``near_singular`` (indices of points reached with cond above
        ``cond_near``: the path passed close to a singularity there, where the tracked mode
        stays on its side, det W_p keeping its sign, while a nearby mode may cross),
        ``halvings``.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    >>> path = np.column_stack([np.linspace(1.2, 1.4, 11), np.full(11, 1.9)])
    >>> r = optkin.track(m, path, [0.9, 2.3])
    >>> r.info["status"], len(r)
    ('optimal', 11)
    """
    deadline = Deadline()
    opts = merge_options(TRACK_DEFAULTS, options, "track")
    check_mechanism(mech, "track")
    model = get_model(mech)
    P = _path_arg(model, qa_path, "qa_path")
    check_size("track", "len(qa_path)", P.shape[0], _track_cost(model),
               unit="one path point and its KinResult")
    for k in range(P.shape[0]):
        check_qa(model, P[k])
    guess = _guess_arg(guess)
    w = "track"
    tol = _opt_float(opts, "tol", w, positive=True)
    max_iter = _opt_int(opts, "max_iter", w, lo=1)
    min_step = _opt_float(opts, "min_step", w, lo=MIN_STEP, hi=1.0)
    cond_max = _opt_float(opts, "cond_max", w)
    cond_near = _opt_float(opts, "cond_near", w)
    max_move = _opt_float(opts, "max_correction", w, positive=True)
    contraction = _opt_float(opts, "contraction", w)
    x0 = parse_guess(model, P[0], guess)
    checkpoint()  # validation stops here: every argument is checked
    scale = model.x_scale
    t0 = timer()
    x, r, nit, ok = newton(model, P[0], x0, tol, 50)
    pts: list[KinResult] = []
    dets: list[float] = []
    conds: list[float] = []
    halvings = 0

    def record(qa_k: np.ndarray, x_k: np.ndarray, nit_k: int) -> None:
        stats = SolverStats("continuation", 0.0, timer() - t0, nit_k, "converged")
        pts.append(make_result(model, qa_k, x_k, tol, nit_k, stats))

    status, msg, stopped, s_stop, qa_stop = "optimal", "", None, None, None
    Wp = Wa = None
    if not ok:
        status = "iteration_limit" if np.isfinite(r) else "error"
        msg = (f"no closed configuration near the guess at qa_path[0] (max |Phi| = {r:.2e}); "
               "give another guess, e.g. a result of assembly_modes")
        stopped, s_stop, qa_stop = 0, 0.0, P[0]
    else:
        _, Wp, Wa = _jac_np(model, P[0], x)
        det, cond = _det_cond(Wp * scale)
        dets.append(det)
        conds.append(cond)
        record(P[0], x, nit)
        if cond > cond_max:
            status, stopped, s_stop, qa_stop = "singular", 1, 0.0, P[0]
            msg = f"the start qa_path[0] is singular (cond W_p = {cond:.2e} > {cond_max:.1e})"
    det_scale = abs(dets[0]) if dets else 1.0
    k = 1
    h = 1.0
    slope: float | None = None
    while status == "optimal" and k < P.shape[0]:
        qa_prev, qa_next = P[k - 1], P[k]
        dqa = qa_next - qa_prev
        s = 0.0
        x_seg, Wp_seg, Wa_seg, det_prev, nit_seg = x, Wp, Wa, dets[-1], 0
        seg_len = float(np.linalg.norm(dqa)) or 1.0
        h = 1.0
        while s < 1.0:
            if deadline.expired():
                stopped, s_stop, qa_stop = k, s, qa_prev + s * dqa
                status, msg = TIME_LIMIT, deadline.message("track") + (
                    f": stopped at s = {s:.4f} of the segment from qa_path[{k - 1}] to "
                    f"qa_path[{k}]")
                break
            h = min(h, 1.0 - s)
            # det W_p extrapolated along the path (secant slope of the last accepted steps):
            # a predicted sign change within the step means a singularity ahead, approached
            # by halving so that a crossing of two modes there is not passed unnoticed
            ahead = slope is not None and np.sign(det_prev + slope * h * seg_len) != np.sign(det_prev)
            if ahead and h > min_step:
                h *= 0.5
                halvings += 1
                continue
            dx_pred = _tangent(Wp_seg, Wa_seg, h * dqa)
            x_pred = x_seg + dx_pred
            x_try, ok, nk, Wp_t, Wa_t = _corrector(model, qa_prev + (s + h) * dqa, x_pred, tol,
                                                    max_iter, max_move)
            nit_seg += nk
            crossed = smooth = False
            if ok:
                det_t, cond_t = _det_cond(Wp_t * scale)
                crossed = Wp_t.shape[0] == Wp_t.shape[1] and np.sign(det_t) != np.sign(det_prev)
                pred = float(np.max(np.abs(dx_pred) / scale))
                corr = float(np.max(np.abs(x_try - x_pred) / scale))
                smooth = corr <= contraction * pred + 1e-7
            if ok and smooth and not crossed and not ahead and cond_t <= cond_max:
                s += h
                slope = (det_t - det_prev) / (h * seg_len)
                x_seg, Wp_seg, Wa_seg, det_prev = x_try, Wp_t, Wa_t, det_t
                det_scale = max(det_scale, abs(det_t))
                h = min(1.0, 2.0 * h)
                continue
            if h > min_step:
                h *= 0.5
                halvings += 1
                continue
            # cannot go on: classify
            stopped = k
            if ok and crossed:
                frac = abs(det_prev) / (abs(det_prev) + abs(det_t))
                s_stop = s + frac * h
                status = "singular"
                msg = (f"det W_p changes sign between qa_path[{k - 1}] and qa_path[{k}] "
                       f"(at s = {s_stop:.4f} of the segment): a parallel singularity; "
                       "continuing would change the assembly mode")
            elif ahead:
                s_stop = min(1.0, s + abs(det_prev / slope) / seg_len)
                status = "singular"
                msg = (f"det W_p = {det_prev:.2e} is about to change sign between "
                       f"qa_path[{k - 1}] and qa_path[{k}] (at s = {s_stop:.4f} of the segment, "
                       "extrapolated): a parallel singularity where two assembly modes meet")
            elif ok and cond_t > cond_max:
                s_stop = s + h
                status = "singular"
                msg = (f"cond W_p = {cond_t:.2e} exceeds cond_max = {cond_max:.1e} between "
                       f"qa_path[{k - 1}] and qa_path[{k}] (s = {s_stop:.4f})")
            else:
                s_stop = s
                det_l, cond_l = _det_cond(Wp_seg * scale)
                near = cond_l > cond_near or abs(det_l) < 1e-2 * det_scale
                status = "singular" if near else "iteration_limit"
                msg = (f"no smooth continuation past s = {s:.4f} of the segment from "
                       f"qa_path[{k - 1}] to qa_path[{k}] (cond W_p there {cond_l:.2e}): "
                       + ("the assembly mode meets a parallel singularity (two modes merge)"
                          if near else "no nearby closed configuration (the legs may not close)"))
            qa_stop = qa_prev + s_stop * dqa
            break
        if status != "optimal":
            break
        x, Wp, Wa = x_seg, Wp_seg, Wa_seg
        dets.append(det_prev)
        conds.append(cond_t)
        record(qa_next, x, nit_seg)
        k += 1
    if status == "optimal":
        msg = f"followed all {P.shape[0]} path points in one assembly mode"
    info = {
        "success": status == "optimal",
        "status": status,
        "message": msg,
        "stopped_at": stopped,
        "s_stop": s_stop,
        "qa_stop": None if qa_stop is None else np.asarray(qa_stop).tolist(),
        "points": int(P.shape[0]),
        "reached": len(pts),
        "det": dets,
        "cond": conds,
        "max_cond": max(conds) if conds else None,
        "near_singular": [i for i, c in enumerate(conds) if c > cond_near],
        "halvings": halvings,
        "time": timer() - t0,
    }
    stats = TrackStats(points=int(P.shape[0]), reached=len(pts), stopped_at=stopped,
                       s_stop=s_stop, max_cond=info["max_cond"], halvings=halvings,
                       time=info["time"])
    return SolutionSet(pts, "path", info, stats=stats)


# ---------------------------------------------------------------------------------------------
# working modes
# ---------------------------------------------------------------------------------------------

@dataclass
class WorkingModes:
    """The working modes of a fully parallel mechanism (Chablat and Wenger, Definition 4).

    Attributes
    ----------
    modes : list of tuple
        Every sign pattern of (B_11, ..., B_nn) the legs allow, in the model's order
        (:meth:`optkin.model.Model.working_modes`: +1 before -1, the first leg slowest): 2
        signs for a leg whose actuated joint moves the centre of its distance constraint
        (RRR, RUS, RSS, PRR: elbow up or down), 1 for a leg whose actuated joint is the
        distance (B_jj = -1 for f_j = ``|P_j - A_j|`` - rho_j).
    legs : list of str
        The leg types (or joint strings of chains).
    pose : ndarray or None
        The pose at which existence was checked.
    existing : dict or None
        At ``pose``: sign pattern -> the :class:`KinResult` of that posture (from
        :func:`optkin.inverse`); patterns absent here do not reach the pose.
    success, status, message :
        As every result (:mod:`optkin.results`). The sign patterns follow from the legs,
        so the answer is always there (``success`` True, status ``"optimal"``), also at a
        pose no posture reaches (``existing`` empty: the message says so); at a pose,
        status ``"time_limit"`` (``success`` False) when the inverse model was cut short.
    """

    modes: list[tuple[int, ...]]
    legs: list[str]
    pose: np.ndarray | None = None
    existing: dict[tuple[int, ...], KinResult] | None = field(default=None)
    success: bool = True
    status: str = OPTIMAL
    message: str = ""

    def __len__(self) -> int:
        return len(self.modes)

    def __iter__(self) -> Iterator[tuple[int, ...]]:
        return iter(self.modes)

    def summary(self) -> str:
        s = f"{len(self.modes)} working modes"
        if self.existing is not None:
            s += f", {len(self.existing)} reach the pose"
        return s

    def __repr__(self) -> str:
        return f"WorkingModes({self.summary()})"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        out: dict[str, Any] = dict(success=bool(self.success), status=self.status,
                                   message=self.message or self.summary(),
                                   count=len(self.modes), modes=[list(m) for m in self.modes],
                                   legs=list(self.legs), summary=self.summary())
        if self.existing is not None:
            out["pose"] = self.pose
            out["existing"] = [list(m) for m in self.existing]
            out["postures"] = list(self.existing.values())
            out["count_at_pose"] = len(self.existing)
        return jsonable(out)


def working_modes(mech: Mechanism, pose: Any = None) -> WorkingModes:
    """The working modes (sign patterns of diag B, Chablat & Wenger 1998) of a fully parallel mechanism.

    Parameters
    ----------
    mech : Mechanism
        A leg-described platform (one actuated joint per leg, so B = W_a is diagonal).
    pose : optional
        A 4x4 pose or task coordinates; then :func:`optkin.inverse` finds the postures there
        and ``existing`` maps each sign pattern reached to its posture.

    Returns
    -------
    WorkingModes

    Examples
    --------
    >>> import optkin
    >>> m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    >>> wm = optkin.working_modes(m, pose=[1.0, 1.8])
    >>> len(wm), len(wm.existing)
    (4, 4)
    """
    check_mechanism(mech, "working_modes")
    model = get_model(mech)
    if model.working_mode_signs is None:
        raise MechanismError(
            f"{mech.name}: working modes are defined for fully parallel mechanisms (one "
            "actuated joint per independent leg, each leg a distance constraint whose "
            "closure row B = W_a is diagonal, Chablat & Wenger 1998); describe it with "
            "Mechanism.from_legs and distance legs"
        )
    if pose is None:
        checkpoint()  # validation stops here: every argument is checked
    modes = [tuple(int(v) for v in m) for m in model.working_modes()]
    wm = WorkingModes(modes, list(model.leg_labels))
    wm.message = f"{len(modes)} working modes of the legs {list(model.leg_labels)}"
    if pose is not None:
        from .inverse import inverse

        pose = _guess_arg(pose, "pose")
        if isinstance(pose, KinResult):
            raise MechanismError("pose: expected a 4x4 pose or task coordinates, got a "
                                 "KinResult (use its .pose)")
        sols = inverse(mech, pose)
        wm.pose = np.asarray(pose, dtype=float)
        wm.existing = {}
        for s in sols:
            if s.working_mode is not None and s.working_mode not in wm.existing:
                wm.existing[tuple(s.working_mode)] = s
        wm.message = (f"{len(modes)} working modes; {len(wm.existing)} reach the pose"
                      + ("" if wm.existing else f" ({sols.message})"))
        if sols.status in LIMIT_REACHED:  # the postures at the pose are not all known
            wm.success, wm.status = False, sols.status
    return wm

