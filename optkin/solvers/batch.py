"""Many direct-model solves at once: ``forward_batch``.

Two layouts of the work, both on compiled CasADi code when a C compiler is present
(:mod:`optkin.model.compiled`; interpreted Functions otherwise):

* ``path=True`` (default): the rows of ``QA`` are consecutive points of a path. The first
  is solved by :func:`optkin.forward` from ``guess``; then chunks of ``chunk`` points are
  tracked in one compiled call each (``Function.mapaccum``): at every point the Euler
  predictor x - W_p^-1 W_a dq_a (the velocity model [7.51]) and ``iters`` Newton
  corrections (7.9), the last solution of a chunk seeding the next chunk. A point whose
  residual stays above ``tol`` is re-solved by :func:`optkin.forward` (damped Newton, then
  IPOPT) from the previous solution, and tracking resumes from it. The assembly mode is
  the one of the first point, followed continuously as long as no parallel singularity is
  met. The tracker itself takes no care of singularities: near one, the iteration may
  cross into another assembly mode or be carried through a fold. So every solved row is
  then checked against the previous one by a second compiled Function mapped over the
  rows (:func:`optkin.model.fused.guard_function`, one Householder QR of W_p per row): the
  sign of det W_p, a conditioning indicator, and the distance of the solution from the
  Euler predictions made at both ends of the step. A sign change, or a solution farther
  from both predictions than ``jump`` times the predicted moves, marks the row in
  ``BatchResult.crossed``. The result then gets status ``"singular"`` (the vocabulary of
  :func:`optkin.track`, which stops there; this batch goes on, the rows after a crossing
  following the mode it led to), as it does when the first row that does not close
  follows a near-singular row, or one where det W_p extrapolated (its square, linear in
  the distance to a fold) reaches 0: the assembly mode ends at a fold. The checks cost
  about 0.3-0.5 us per row for a 3-RPR and 1.4 us for a Stewart-Gough platform
  (``guard=False`` skips them). The first call compiles the libraries of the model's
  topology (about 0.5-1.5 s, then cached on disk; the geometry is an input, so another
  geometry of the topology compiles nothing); above :data:`COMPILE_MAX` unknowns (legs in
  chain form) only libraries already cached are used, the rest runs interpreted.
* ``path=False``: the rows are independent; all start from ``guess`` (one guess, or one
  row of unknowns per solve) and the compiled damped Newton step, mapped over ``chunk``
  columns with threads (``Function.map(chunk, "thread", threads)``), iterates until each
  converges; the rest falls back to :func:`optkin.forward`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_matrix, as_vector, check_option
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..limits import MAX_ITERATIONS, MAX_THREADS, MAX_UNROLL, Deadline, check_sizes, show
from ..mechanism import Mechanism
from ..model import Model, fused, get_model
from ..model import compiled as cc
from ..model.compiled import FastFn
from ..results import (
    INFEASIBLE,
    OPTIMAL,
    SINGULAR,
    TIME_LIMIT,
    KinResult,
    SolverStats,
    jsonable,
)
from .common import check_mechanism, check_qa, make_result, merge_options, parse_guess, timer
from .forward import forward

__all__ = ["forward_batch", "BatchResult", "BATCH_DEFAULTS"]

#: Options of :func:`forward_batch` and their defaults.
BATCH_DEFAULTS: dict[str, Any] = {
    "path": True,  # rows are consecutive points of a path (warm-started tracking)
    "tol": 1e-10,  # max |Phi| for success
    "chunk": 128,  # points per compiled call (one compiled library per chunk size)
    "iters": 2,  # path: Newton corrections after the Euler predictor
    "max_iter": 40,  # independent rows: damped Newton iterations
    "threads": 1,  # independent rows: threads sharing each chunk (1: batch runs parallelize
    # by worker process; 2 measured 1.2x faster than 1 on 2048 rows of a 6-6 platform here)
    "fallback": True,  # re-solve failed points with optkin.forward (Newton, then IPOPT)
    "guard": True,  # det W_p sign, conditioning and jump checks of every row (see crossed)
    "jump": 2.0,  # path: mark a row farther from both Euler predictions than jump x moves
    "near": 1e-3,  # conditioning indicator below which a row is near_singular
}

#: Rows per call of the mapped guard Function (one compiled library per topology).
GUARD_CHUNK = 256
#: Most unknowns for which forward_batch compiles its libraries on first use: the tracker of
#: a 3-UPU in chain form (19 unknowns, 49 000 instructions) takes a minute of C compiling
#: and runs interpreted at 1 ms a point; above, libraries already in the disk cache are
#: used (``Model.compile(tracker=(chunk, iters), guard=GUARD_CHUNK)`` builds them).
COMPILE_MAX = 12
#: Largest ``chunk`` (points per compiled call; one compiled library per value).
MAX_CHUNK = 1 << 16
# Measured memory (peak resident growth, VmHWM, of a fresh process): per row of QA, its
# solution, residual, guard buffers and checks, and the lists of its to_dict, about
# 300 + 100 (nx + na) bytes (750 bytes for a five-bar, both layouts); per column of a
# compiled call, its buffers and the work of the mapped Function, 100 (nx + na) bytes
# (314 bytes measured for a five-bar at chunk = 65536). limits.SAFETY is applied on top.
_COST_ROW = (300.0, 100.0)
_COST_CHUNK = 100.0
# The tracker takes the geometry as an input and repeats it for every point of a chunk
# (its values, sparsity and the interpreted graph's work): 120-170 bytes per column and
# entry of the geometry vector measured (14 KB a column for a five-bar, interpreted).
_COST_GEOMETRY = 180.0


def _row_cost(model: Model) -> float:
    a, b = _COST_ROW
    return a + b * (model.nx + model.na)
#: Scaled distance below which the jump test never fires (round-off, repeated rows); it
#: grows as 1 / conditioning below 1e-3, where x is ill-determined along the null direction.
JUMP_FLOOR = 1e-7


@dataclass
class BatchResult:
    """The outcome of :func:`forward_batch`: one row per solve.

    Attributes
    ----------
    x : ndarray (n, nx)
        The unknowns (``x_names``) of every solve.
    qa : ndarray (n, na)
        The active joint values, as given.
    closed : ndarray of bool (n,)
        Whether max ``|Phi|`` <= tol at each row.
    success : bool
        Whether every row closed (``closed.all()``; ``all_success`` is the same).
    residual : ndarray (n,)
        max ``|Phi|`` at each row.
    nit : ndarray of int (n,)
        Newton iterations (corrections) spent on each row.
    status, message : str
        ``"singular"`` when a row is marked in ``crossed``, else ``"optimal"`` when every
        row closed, else ``"infeasible"``; ``"time_limit"`` when the time budget stopped
        the batch; a sentence naming the first such row.
    stats : SolverStats
        ``extra`` holds ``compiled`` (bool), ``fallback`` (rows re-solved by ``forward``),
        ``chunks`` (compiled calls), ``chunk`` and ``guard_time`` (s).
    det_sign : ndarray of int8 (n,)
        Sign of det W_p at each closed row (0 at rows that did not close, or without the
        guard; always +1 when W_p has more rows than columns).
    conditioning : ndarray (n,)
        A cheap conditioning indicator of W_p at each closed row, in [0, 1]: the Hadamard
        ratio ``|det(W_p S)|`` / prod_i ``|row_i(W_p S)|`` with the columns scaled by the
        mechanism's size (S = diag(x_scale)); 1 for orthogonal rows, 0 at a parallel
        singularity; NaN at rows that did not close. It bounds the smallest singular value
        s of the row-normalised matrix: s^n <= conditioning <= s n^((n-1)/2).
    crossed : ndarray of bool (n,)
        ``path=True``: row i is marked when, between the previous closed row and row i,
        det W_p changes sign (a parallel singularity was crossed), or the solution is
        farther from both Euler predictions x_prev - W_p^-1 W_a dq_a (W_p, W_a taken at
        one end of the step, then at the other) than ``jump`` times the predicted move (it
        jumped to another solution; one end alone is fooled where the tangent changes
        fast, e.g. near a serial singularity). Rows from the first marked one on may belong
        to another assembly mode than row 0: ``np.cumsum(crossed) == 0`` selects the rows
        known to follow it.
    near_singular : ndarray of bool (n,)
        Closed rows with ``conditioning`` below the option ``near``.
    """

    x: np.ndarray
    qa: np.ndarray
    closed: np.ndarray
    residual: np.ndarray
    nit: np.ndarray
    status: str
    message: str
    stats: SolverStats = field(default_factory=SolverStats)
    x_names: tuple[str, ...] = ()
    model: Model | None = field(default=None, repr=False)
    det_sign: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    conditioning: np.ndarray = field(default_factory=lambda: np.zeros(0))
    crossed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    near_singular: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    def __len__(self) -> int:
        return int(self.x.shape[0])

    def __repr__(self) -> str:
        n = len(self)
        ok = int(np.sum(self.closed))
        worst = float(np.max(self.residual)) if n else 0.0
        marked = int(np.sum(self.crossed))
        cross = f", {marked} crossed" if marked else ""
        return (f"BatchResult({ok}/{n} closed{cross}, status={self.status!r}, "
                f"max residual={worst:.2e}, solver={self.stats.solver!r})")

    @property
    def success(self) -> bool:
        """Whether every row closed (rows that did not are False in :attr:`closed`)."""
        return bool(np.all(self.closed))

    @property
    def all_success(self) -> bool:
        """The same as :attr:`success`."""
        return self.success

    def result(self, i: int, tol: float = 1e-10) -> KinResult:
        """Row ``i`` as a full :class:`KinResult` (joints, pose, cond(W_p))."""
        st = SolverStats(self.stats.solver, 0.0, 0.0, int(self.nit[i]), self.stats.raw_status)
        return make_result(self.model, self.qa[i], self.x[i], tol, int(self.nit[i]), st)

    def q(self) -> np.ndarray:
        """All joint values (n, nq), in ``mech.joint_names`` order."""
        ev = self.model.fast("result")
        out = np.empty((len(self), len(self.model.mech.joint_names)))
        for i in range(len(self)):
            out[i] = ev(self.qa[i], self.model.canonical_x(self.x[i]))[3]
        return out

    def poses(self) -> np.ndarray:
        """End-effector poses (n, 4, 4)."""
        ev = self.model.fast("result")
        out = np.empty((len(self), 4, 4))
        for i in range(len(self)):
            out[i] = ev(self.qa[i], self.x[i])[2].reshape(4, 4).T
        return out

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`: NaN and inf entries, e.g. of
        rows that diverged, become None); ``closed`` per row, ``success`` for all."""
        return jsonable({
            "success": self.success, "status": self.status, "message": self.message,
            "x": self.x.tolist(), "qa": self.qa.tolist(), "closed": self.closed.tolist(),
            "residual": self.residual.tolist(), "nit": self.nit.tolist(),
            "stats": self.stats.to_dict(),
            "x_names": list(self.x_names), "det_sign": self.det_sign.tolist(),
            "conditioning": [None if not np.isfinite(c) else float(c)
                             for c in self.conditioning],
            "crossed": self.crossed.tolist(), "near_singular": self.near_singular.tolist(),
        })


def _as_rows(model: Model, QA: Any) -> np.ndarray:
    na = model.na
    try:
        A = as_matrix(QA, "QA")
    except MechanismError:
        a = as_vector(QA, "QA")  # not numbers, not finite: its own message
        if a.size != na:
            raise MechanismError(
                f"QA: expected an (n, {na}) array, one row of active joint values "
                f"{list(model.mech.active_names)} per solve; got shape {a.shape}") from None
        A = a[None, :]
    if na not in A.shape:
        raise MechanismError(
            f"QA: expected an (n, {na}) array, one row of active joint values "
            f"{list(model.mech.active_names)} per solve; got shape {A.shape}"
        )
    if A.shape[1] != na:  # (na, n): columns
        A = A.T
    pos = np.flatnonzero(model.qa_positive)
    if pos.size and A.size and np.min(A[:, pos]) <= 0:
        names = ", ".join(model.mech.active_names[i] for i in pos)
        raise MechanismError(f"QA: leg lengths (columns {names}) must be positive")
    return np.ascontiguousarray(A)


def _bool_opt(opts: dict[str, Any], key: str) -> bool:
    v = opts[key]
    if isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1)):
        return bool(v)
    raise MechanismError(f"forward_batch: option {key} must be True or False, got "
                         f"{show(v)}")


def _batch_options(opts: dict[str, Any]) -> dict[str, Any]:
    w = "forward_batch"
    o = {k: _bool_opt(opts, k) for k in ("path", "fallback", "guard")}

    def number(key: str, **bounds: Any) -> Any:
        return check_option(opts, key, w, BATCH_DEFAULTS, **bounds)

    o["tol"] = number("tol", lo=0.0, lo_open=True)
    o["chunk"] = max(1, number("chunk", integer=True, lo=0))
    o["iters"] = number("iters", integer=True, lo=0, hi=MAX_UNROLL)
    o["max_iter"] = number("max_iter", integer=True, lo=0, hi=MAX_ITERATIONS)
    o["threads"] = max(1, number("threads", integer=True, lo=0, hi=MAX_THREADS))
    o["jump"] = number("jump", lo=0.0)
    o["near"] = number("near", lo=0.0)
    return o


def _guess_arg(guess: Any) -> Any:
    if guess is None or isinstance(guess, KinResult):
        return guess
    try:
        return as_matrix(guess, "guess")
    except MechanismError:
        return as_vector(guess, "guess")


def forward_batch(mech: Mechanism, QA: Any, guess: Any = None, **options: Any) -> BatchResult:
    """Solve the direct geometric model for many active joint vectors at once.

    Parameters
    ----------
    mech : Mechanism
    QA : array (n, na)
        One row of active joint values per solve (``mech.active_names`` order). An
        (na, n) array (one column per solve, CasADi's layout) is accepted when n != na.
    guess : optional
        ``path=True``: the start of the first point, as for :func:`optkin.forward` (None, a
        KinResult, x, q, a pose...). ``path=False``: the same for every row, or an (n, nx)
        array of unknowns, one row per solve.
    **options
        See :data:`BATCH_DEFAULTS`. ``chunk`` is at most :data:`MAX_CHUNK`, ``iters`` (Newton
        steps unrolled into the compiled tracker) at most
        :data:`optkin.limits.MAX_UNROLL`, ``max_iter`` at most
        :data:`optkin.limits.MAX_ITERATIONS`, ``threads`` at most
        :data:`optkin.limits.MAX_THREADS`.

    Notes
    -----
    Memory and time: each row of ``QA`` costs about 300 + 100 (nx + na) bytes (solution,
    checks and JSON; 750 bytes measured for a five-bar) and each column of a compiled call
    (``chunk``) about 100 (nx + na) + 180 np bytes (np entries of the geometry vector, an
    input the tracker repeats for every point); both are checked against the memory budget of
    :mod:`optkin.limits` before solving. When the time budget runs out the rows not yet
    solved stay NaN, the status is ``"time_limit"`` and ``stats.extra["stopped_at"]``
    is the first of them.

    Returns
    -------
    BatchResult
        Rows of unknowns, residuals and ``closed`` flags; ``result(i)`` gives a KinResult.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = optkin.mechanisms.five_bar(1.0, 1.0, 1.0, 1.0, 1.0)
    >>> t = np.linspace(0, 0.3, 50)
    >>> QA = np.c_[1.2 + t, 1.9 - t]
    >>> b = optkin.forward_batch(m, QA)
    >>> b.all_success, b.x.shape
    (True, (50, 2))
    """
    deadline = Deadline()
    opts = merge_options(BATCH_DEFAULTS, options, "forward_batch")
    check_mechanism(mech, "forward_batch")
    o = _batch_options(opts)
    model = get_model(mech)
    A = _as_rows(model, QA)
    nx, na = model.nx, model.na
    chunk = o["chunk"]
    check_sizes(
        "forward_batch",
        ("chunk", chunk, _COST_CHUNK * (nx + na) + _COST_GEOMETRY * model.p.size,
         {"hi": MAX_CHUNK, "unit": "one column of a compiled call"}),
        ("len(QA)", A.shape[0], _row_cost(model),
         {"lo": 0, "unit": "one row: its solution, checks and JSON"}))
    guess = _guess_arg(guess)
    if not o["path"] and guess is not None and A.shape[0]:  # one guess for every row
        g = guess if isinstance(guess, KinResult) else np.asarray(guess)
        if not (isinstance(g, np.ndarray) and g.shape == (A.shape[0], model.nx)):
            parse_guess(model, check_qa(model, A[0]), guess)
    elif guess is not None and A.shape[0]:
        parse_guess(model, check_qa(model, A[0]), guess)
    checkpoint()  # validation stops here: every argument is checked
    tol = o["tol"]
    path = o["path"]
    guard = (path, o["jump"], o["near"]) if o["guard"] else None
    gchunk = GUARD_CHUNK if guard else None
    # the libraries (core, tracker, guard) are compiled in parallel; a large closure's
    # (legs in chain form) only loaded when cached: their C takes minutes to compile
    build = model.nx <= COMPILE_MAX
    if path:
        model.compile(build=build, tracker=(chunk, o["iters"]), guard=gchunk)
        return _track(model, A, guess, tol, chunk, o["iters"], o["fallback"], guard, deadline)
    model.compile(build=build, guard=gchunk)
    return _independent(model, A, guess, tol, chunk, o["max_iter"], o["threads"],
                        o["fallback"], guard, deadline)


def _checks(model: Model, A, X, ok, path: bool, jump: float, near: float):
    """det W_p signs, conditioning, and the rows where a path crosses a singularity.

    Returns (det_sign, conditioning, crossed, near_singular, prev, why, ratio, det) with
    ``prev[i]`` the closed row that row i is compared with, ``why[i]`` = 1 (det sign
    change) or 2 (jump), ``ratio[i]`` the smaller distance of the solution from the two
    Euler predictions relative to the predicted moves, ``det`` det W_p."""
    n, na, nx = A.shape[0], model.na, model.nx
    idx = np.arange(n)
    if path:  # compare each row with the last closed row before it
        last = np.maximum.accumulate(np.where(ok, idx, -1))
        prev = np.r_[-1, last[:-1]] if n else last
        prev = np.where(prev < 0, idx, prev)
        # and each closed row with the next closed row after it
        nxt_c = np.minimum.accumulate(np.where(ok, idx, n)[::-1])[::-1]
        nxt = np.r_[nxt_c[1:], n] if n else nxt_c
        nxt = np.where(nxt >= n, idx, nxt)
    else:
        prev = nxt = idx
    g = GUARD_CHUNK
    npad = -(-n // g) * g
    Xc = np.where(np.isfinite(X), X, 0.0)
    bufs = []
    for rows in (prev, idx, nxt):
        Qb, Xb = np.empty((npad, na)), np.empty((npad, nx))
        Qb[:n], Xb[:n] = A[rows], Xc[rows]
        Qb[n:], Xb[n:] = A[n - 1], Xc[n - 1]
        bufs += [Qb, Xb]
    det = np.empty(npad)
    h = np.empty(npad)
    cpb = np.empty((npad, 4))
    f, _ = _guard(model, g)
    ev = FastFn(f, fixed=(model.p,))
    for s in range(0, npad, g):
        ev.into([b[s:s + g] for b in bufs], [det[s:s + g], h[s:s + g], cpb[s:s + g]])
    det, h, cpb = det[:n], h[:n], cpb[:n]
    # per row: the prediction made at the previous closed row (its fwd step) and the one
    # made at this row (its back step)
    cp = np.column_stack([cpb[prev, 2], cpb[prev, 3], cpb[:, 0], cpb[:, 1]])
    sign = np.where(ok, np.sign(det), 0).astype(np.int8)
    cond = np.where(ok, h, np.nan)
    why = np.zeros(n, dtype=np.int8)
    floor = JUMP_FLOOR * np.maximum(1.0, 1e-3 / np.maximum(np.minimum(h, h[prev]), 1e-300))
    if path:
        has = ok & (prev != idx)
        flip = has & (sign != sign[prev])
        # a jump: the move disagrees with the Euler predictions of both ends (one end alone
        # is fooled where the tangent changes fast, e.g. near a serial singularity)
        jumped = has & (cp[:, 0] > jump * cp[:, 1] + floor) & (cp[:, 2] > jump * cp[:, 3] + floor)
        why[jumped] = 2
        why[flip] = 1
    crossed = why > 0
    near_s = ok & (h < near)
    with np.errstate(all="ignore"):
        ratio = np.minimum(cp[:, 0] / (cp[:, 1] + floor), cp[:, 2] / (cp[:, 3] + floor))
    return sign, cond, crossed, near_s, prev, why, ratio, det


def _finish(model: Model, A, X, R, nit, tol, solver, t0, extra, guard=None,
            stopped: tuple[int, str] | None = None) -> BatchResult:
    ok = np.isfinite(R) & (R <= tol)
    n = A.shape[0]
    nbad = int(n - ok.sum())
    status = OPTIMAL if nbad == 0 else INFEASIBLE
    if nbad == 0:
        msg = f"{n} solves closed: max |Phi| = {R.max() if n else 0.0:.2e}"
    else:
        first = int(np.flatnonzero(~ok)[0])
        msg = (f"{nbad} of {n} solves did not close (first at row {first}, max |Phi| = "
               f"{R[first]:.2e}); those active joint values may be out of reach")
    sign = np.zeros(n, dtype=np.int8)
    cond = np.full(n, np.nan)
    crossed = np.zeros(n, dtype=bool)
    near_s = np.zeros(n, dtype=bool)
    if guard is not None and n:
        tg = timer()
        sign, cond, crossed, near_s, prev, why, ratio, det = _checks(model, A, X, ok, *guard)
        extra["guard_time"] = timer() - tg
        # the first row that did not close, right after a near-singular row or where det W_p
        # extrapolated from the two rows before reaches 0: the mode ends at a fold (there
        # det W_p ~ sqrt(distance to the fold), so det^2 is extrapolated linearly)
        fold = None
        f = int(np.flatnonzero(~ok)[0]) if guard[0] and nbad else 0
        if f > 0:
            p = f - 1
            pp = int(prev[p])
            ahead = False
            if pp != p:
                gap = float(np.linalg.norm(A[p] - A[pp]))
                if gap > 0:
                    d2, d2p = det[p] ** 2, det[pp] ** 2
                    r = float(np.linalg.norm(A[f] - A[p])) / gap
                    ahead = bool(d2 + (d2 - d2p) * r <= 0)
            if near_s[p] or ahead:
                fold = f
        events: list[tuple[int, str]] = []
        if fold is not None and not crossed[:fold].any():
            events.append((fold, (
                f"the assembly mode ends at a parallel singularity between rows {fold - 1} "
                f"and {fold} of QA (conditioning {cond[fold - 1]:.1e} at row {fold - 1}, "
                "det W_p heading for 0): two modes merge there (a fold)")))
        if crossed.any():
            i = int(np.flatnonzero(crossed)[0])
            p = int(prev[i])
            if why[i] == 1:
                head = (f"det W_p changes sign between rows {p} and {i} of QA: a parallel "
                        "singularity is crossed there")
            else:
                head = (f"the solution at row {i} of QA is {ratio[i]:.3g} times farther from "
                        f"the Euler predictions than the predicted move from row {p}: it "
                        "jumped to another solution (near a singularity, or the path steps "
                        "are too coarse there)")
            k = int(crossed.sum())
            low = np.where(ok, cond, np.inf)
            j = int(np.argmin(low))
            events.append((i, (
                f"{head}; the rows from {i} on may belong to another assembly mode "
                f"({k} row{'s' if k > 1 else ''} marked in crossed; conditioning "
                f"{low[j]:.1e} at row {j})")))
        if events:
            msg = ". ".join(t for _, t in sorted(events)) + ". " + msg
            status = SINGULAR
    if stopped is not None:  # the time budget ran out: the rows from stopped[0] on
        msg = f"{stopped[1]} (rows from {stopped[0]} on were not solved). {msg}"
        status = TIME_LIMIT
        extra["stopped_at"] = stopped[0]
    stats = SolverStats(solver, 0.0, timer() - t0, int(nit.sum()), status, extra)
    return BatchResult(X, A, ok, R, nit, status, msg, stats, tuple(model.x_names), model,
                       sign, cond, crossed, near_s)


def _track(model: Model, A, guess, tol, chunk, iters, fallback, guard=None,
           deadline: Deadline | None = None) -> BatchResult:
    t0 = timer()
    n, na, nx = A.shape[0], model.na, model.nx
    X = np.full((n, nx), np.nan)
    R = np.full(n, np.inf)
    nit = np.zeros(n, dtype=int)
    if n == 0:
        return _finish(model, A, X, R, nit, tol, "track", t0, {})
    f, compiled = _tracker(model, chunk, iters)
    ev = FastFn(f, fixed=(model.p,))
    first = forward(model.mech, A[0], guess=guess, tol=tol)
    X[0], R[0], nit[0] = first.x, first.residual, first.nit
    xs, qs = np.array(first.x, dtype=float), A[0].copy()
    Qc = np.empty((chunk, na))
    Xc = np.empty((chunk, nx))
    Rc = np.empty(chunk)
    junk = np.empty((chunk, na))
    i, calls, nfall = 1, 0, 0
    anchored = bool(first.success)
    stopped = None
    while i < n:
        if deadline is not None and deadline.expired():
            stopped = (i, deadline.message("forward_batch"))
            break
        if not anchored:
            # no closed configuration to continue from yet (e.g. the path starts out of
            # reach): solve rows one by one from the caller's guess until one closes
            r = forward(model.mech, A[i], guess=guess, tol=tol)
            nfall += 1
            X[i], R[i], nit[i] = r.x, r.residual, r.nit
            if r.success:
                xs, qs = np.array(r.x, dtype=float), A[i].copy()
                anchored = True
            i += 1
            continue
        k = min(chunk, n - i)
        Qc[:k] = A[i:i + k]
        Qc[k:] = A[i + k - 1]
        ev.into([xs, qs, Qc], [Xc, junk, Rc])
        calls += 1
        good = np.isfinite(Rc[:k]) & (Rc[:k] <= tol)
        j = k if good.all() else int(np.argmin(good))
        X[i:i + j] = Xc[:j]
        R[i:i + j] = Rc[:j]
        nit[i:i + j] = iters
        if j > 0:
            xs, qs = Xc[j - 1].copy(), A[i + j - 1].copy()
        i += j
        if j < k:  # point i did not close: the full solver, from the last solution
            if fallback:
                r = forward(model.mech, A[i], guess=xs, tol=tol)
                nfall += 1
                X[i], R[i], nit[i] = r.x, r.residual, r.nit
                if r.success:
                    xs, qs = np.array(r.x, dtype=float), A[i].copy()
            else:
                X[i], R[i], nit[i] = Xc[j], Rc[j], iters
            i += 1
    extra = {"compiled": compiled, "fallback": nfall, "chunks": calls, "chunk": chunk,
             "iters": iters, "path": True}
    return _finish(model, A, X, R, nit, tol, "compiled-track" if compiled else "track", t0,
                   extra, guard, stopped)


def _interpreted() -> bool:
    """``OPTKIN_COMPILE=off``: no compiled code, not even libraries another call built."""
    return cc.compile_mode() == "off"


def _tracker(model: Model, chunk: int, iters: int):
    """The path tracker over ``chunk`` points (inputs x0, q_a0, QA, p) and whether it is
    compiled (:meth:`optkin.model.Model.tracker`; interpreted when compiling is off)."""
    if not _interpreted():
        return model.tracker(chunk, iters)
    return model.cached(("forward_batch:tracker", int(chunk), int(iters)), lambda: (
        fused.tracker_chunk(model.topology, int(chunk), int(iters)))), False


def _guard(model: Model, chunk: int):
    """The row checks mapped over ``chunk`` rows (geometry last) and whether compiled."""
    if not _interpreted():
        return model.guard(chunk)
    return model.cached(("forward_batch:guard", int(chunk)), lambda: (
        fused.guard_chunk(model.topology, int(chunk))[0])), False


def _step(model: Model):
    """The damped Newton step (q_a, x, p): compiled when available and compiling is on."""
    return model.step_sx if _interpreted() else model.step


class _ThreadedEval:
    """:meth:`FastFn.into` over rows split in shares, evaluated at once: the first share
    in the calling thread, the others in a pool kept with the evaluator (CasADi's
    evaluation releases the GIL)."""

    def __init__(self, evs: list[FastFn], shares: list[int]) -> None:
        from concurrent.futures import ThreadPoolExecutor

        self.evs = evs
        self.cuts = np.cumsum([0, *shares])
        self.pool = ThreadPoolExecutor(len(evs) - 1, thread_name_prefix="optkin-batch")

    def into(self, args: list[np.ndarray], res: list[np.ndarray]) -> None:
        c = self.cuts
        futs = [self.pool.submit(ev.into, [a[c[i]:c[i + 1]] for a in args],
                                 [r[c[i]:c[i + 1]] for r in res])
                for i, ev in enumerate(self.evs) if i]
        self.evs[0].into([a[:c[1]] for a in args], [r[:c[1]] for r in res])
        for f in futs:
            f.result()


def _step_map(model: Model, chunk: int, threads: int) -> FastFn | _ThreadedEval:
    """The model's damped Newton step (compiled when available) mapped over ``chunk``
    rows, the map built once per topology, as an evaluator with the geometry filled in
    (unmapped). More threads split the rows in shares, each through a map of its own
    evaluated in a thread (:class:`_ThreadedEval`; CasADi's threaded map repeats the
    geometry for every column: it ran slower with 2 threads than with 1 here)."""
    step = _step(model)

    def one(n: int, part: int) -> FastFn:
        key = ("forward_batch:step", n, part, step.is_a("External"))
        fm = model.cached(key, lambda: step.map(f"newton_step_{n}_{part}", "serial", n,
                                                [2], []))
        return FastFn(fm, fixed=(model.p,))

    threads = max(1, min(int(threads), int(chunk)))
    if threads == 1:
        return one(int(chunk), 0)
    shares = [chunk // threads + (i < chunk % threads) for i in range(threads)]
    return _ThreadedEval([one(int(w), i) for i, w in enumerate(shares)], shares)


def _independent(model: Model, A, guess, tol, chunk, max_iter, threads, fallback,
                 guard=None, deadline: Deadline | None = None) -> BatchResult:
    t0 = timer()
    n, nx = A.shape[0], model.nx
    if n == 0:
        return _finish(model, A, np.zeros((0, nx)), np.zeros(0), np.zeros(0, dtype=int), tol,
                       "newton", t0, {})
    g = None if guess is None or isinstance(guess, KinResult) else np.asarray(guess, dtype=float)
    if g is not None and g.ndim == 2 and g.shape == (n, nx):
        X0 = np.array(g, dtype=float)
    else:
        X0 = np.empty((n, nx))
        x_one = None if guess is None else parse_guess(model, check_qa(model, A[0]), guess)
        for i in range(n):
            X0[i] = model.default_x(A[i]) if x_one is None else x_one
    chunk = min(chunk, max(n, 1))
    ev = _step_map(model, chunk, threads)
    X = X0.copy()
    R = np.full(n, np.inf)
    nit = np.zeros(n, dtype=int)
    Qc = np.empty((chunk, model.na))
    Xc = np.empty((chunk, nx))
    Xn = np.empty((chunk, nx))
    Rc = np.empty(chunk)
    calls = 0
    stopped = None
    for s in range(0, n, chunk):
        if deadline is not None and deadline.expired():
            stopped = (s, deadline.message("forward_batch"))
            X[s:] = np.nan
            break
        k = min(chunk, n - s)
        Qc[:k] = A[s:s + k]
        Qc[k:] = A[s + k - 1]
        Xc[:k] = X[s:s + k]
        Xc[k:] = X[s + k - 1]
        done = np.zeros(chunk, dtype=bool)
        done[k:] = True
        for it in range(max_iter + 1):
            ev.into([Qc, Xc], [Xn, Rc])
            calls += 1
            conv = ~done & np.isfinite(Rc) & (Rc <= tol)
            R[s:s + k][conv[:k]] = Rc[:k][conv[:k]]
            nit[s:s + k][conv[:k]] = it
            # converged at Xc: keep the one further (polishing) step when it is finite
            pol = conv & np.isfinite(Xn).all(axis=1)
            Xc[pol] = Xn[pol]
            done |= conv
            if done.all() or it == max_iter:
                break
            upd = ~done & np.isfinite(Xn).all(axis=1)
            Xc[upd] = Xn[upd]
        ev.into([Qc, Xc], [Xn, Rc])  # the residuals at the returned (polished) rows
        calls += 1
        X[s:s + k] = Xc[:k]
        R[s:s + k] = Rc[:k]
        nit[s:s + k][~done[:k]] = max_iter
    nfall = 0
    if fallback:
        for i in np.flatnonzero(~(np.isfinite(R) & (R <= tol))):
            if stopped is not None and i >= stopped[0]:
                break
            if deadline is not None and deadline.expired():
                stopped = (int(i), deadline.message("forward_batch"))
                break
            r = forward(model.mech, A[i], guess=X0[i], tol=tol)
            nfall += 1
            X[i], R[i], nit[i] = r.x, r.residual, nit[i] + r.nit
    compiled = _step(model).is_a("External")
    extra = {"compiled": compiled, "fallback": nfall, "chunks": calls, "chunk": chunk,
             "threads": threads, "path": False}
    return _finish(model, A, X, R, nit, tol, "compiled-newton" if compiled else "newton", t0,
                   extra, guard, stopped)
