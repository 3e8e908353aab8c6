"""Result objects: every solve returns data, never raises on non-convergence.

The vocabulary follows scipy's ``OptimizeResult`` (``x``, ``success``, ``status``,
``message``, ``nit``) plus the kinematic fields, like cvxpy's ``SolverStats`` for the
solver side.

Every public result of optkin (:class:`KinResult`, :class:`SolutionSet`, the analyses'
and the statics' results, :class:`optkin.design.DesignResult`, ...) has

* ``success`` (bool): the call found what it was asked for; an answer "no" can be one
  (:func:`optkin.statics.feasible` answering that a wrench set is not feasible), while a
  solve without a solution is not (a pose out of reach: ``success=False``, status
  ``"infeasible"``);
* ``status``: one word of :data:`STATUS`, the constants below, in the manner of cvxpy's
  ``cvxpy/settings.py``; the groups (:data:`SOLUTION_PRESENT`, :data:`INF_OR_UNB`,
  :data:`LIMIT_REACHED`, :data:`FAILURE`, :data:`ANSWERED`) say what a status means for
  the caller;
* ``message`` (str): one or two sentences, never empty;
* ``to_dict()``: JSON data (:func:`jsonable`: NaN and inf become None), which
  ``json.dumps(..., allow_nan=False)`` accepts.

A solver's own word (IPOPT's ``return_status``, cvxpy's ``problem.status``) goes to
``stats.raw_status`` (:class:`SolverStats`) where the result keeps solver statistics.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = [
    "KinResult", "SolutionSet", "SolverStats", "EnumerationStats", "TrackStats", "STATUS",
    "OPTIMAL", "INACCURATE", "INFEASIBLE", "UNBOUNDED", "SINGULAR", "ITERATION_LIMIT",
    "TIME_LIMIT", "MEMORY_LIMIT", "ERROR", "SOLUTION_PRESENT", "INF_OR_UNB", "LIMIT_REACHED",
    "FAILURE", "ANSWERED", "RESULT_ATTRIBUTES", "ipopt_status", "jsonable",
]

# --------------------------------------------------------------------------- statuses
#: The answer was computed, to the tolerance asked for.
OPTIMAL = "optimal"
#: An answer was computed, short of the tolerance (a solver's "acceptable" level) or
#: incomplete in a way the message states (some curves short of the residual, ...).
INACCURATE = "inaccurate"
#: The problem has no solution, or none was found: a pose out of reach, active joint
#: values no configuration closes, an infeasible LP, two modes no path joins.
INFEASIBLE = "infeasible"
#: An LP of the statics is unbounded (a wrench carried without actuator force).
UNBOUNDED = "unbounded"
#: At (or through) a singularity: values valid where the message says so (statics at a
#: parallel singularity), or a path stopped where det W_p changes sign.
SINGULAR = "singular"
#: Stopped at an iteration cap (IPOPT's ``max_iter``, a Newton budget, steps of a path).
ITERATION_LIMIT = "iteration_limit"
#: Stopped at a time limit: a ``time_limit`` option, or the time budget of
#: :mod:`optkin.limits` (``OPTKIN_TIME_BUDGET``); what was found so far is returned.
TIME_LIMIT = "time_limit"
#: Stopped at the memory budget of :mod:`optkin.limits` (``OPTKIN_MEMORY_BUDGET``) while
#: tracing; what was found so far is returned.
MEMORY_LIMIT = "memory_limit"
#: A numerical or solver failure (non-finite values, a solver error, an undefined model).
ERROR = "error"

#: Every status a public result may carry.
STATUS = (OPTIMAL, INACCURATE, INFEASIBLE, UNBOUNDED, SINGULAR, ITERATION_LIMIT, TIME_LIMIT,
          MEMORY_LIMIT, ERROR)

#: An answer is present (cvxpy's ``SOLUTION_PRESENT``).
SOLUTION_PRESENT = (OPTIMAL, INACCURATE)
#: No solution: infeasible or unbounded (cvxpy's ``INF_OR_UNB``).
INF_OR_UNB = (INFEASIBLE, UNBOUNDED)
#: Stopped by a budget before the end: the result is partial and ``success`` is False.
LIMIT_REACHED = (ITERATION_LIMIT, TIME_LIMIT, MEMORY_LIMIT)
#: A failure: ``success`` is False.
FAILURE = (ERROR,)
#: The statuses a successful result may carry: an answer, possibly "no solution" or "at
#: a singularity" (e.g. ``feasible(...)`` answers ``feasible=False`` with success).
#: ``success=True`` never comes with a status of :data:`LIMIT_REACHED` or
#: :data:`FAILURE`, and ``status == OPTIMAL`` always comes with ``success=True``.
ANSWERED = SOLUTION_PRESENT + INF_OR_UNB + (SINGULAR,)

#: What every public result type has: ``success``, ``status``, ``message`` and ``to_dict``.
RESULT_ATTRIBUTES = ("success", "status", "message", "to_dict")

_IPOPT_STATUS_MAP = {
    "Solve_Succeeded": "optimal",
    "Solved_To_Acceptable_Level": "inaccurate",
    "Infeasible_Problem_Detected": "infeasible",
    "Restoration_Failed": "infeasible",
    "Local_Infeasibility": "infeasible",
    "Maximum_Iterations_Exceeded": "iteration_limit",
    "Maximum_CpuTime_Exceeded": "time_limit",
    "Maximum_WallTime_Exceeded": "time_limit",
    "Search_Direction_Becomes_Too_Small": "inaccurate",
    "Diverging_Iterates": "error",
    "Error_In_Step_Computation": "error",
    "Not_Enough_Degrees_Of_Freedom": "error",
    "Invalid_Number_Detected": "error",
    "Invalid_Option": "error",
    "Internal_Error": "error",
}


def ipopt_status(raw: str) -> str:
    """Map an IPOPT ``return_status`` string to one of :data:`STATUS`."""
    return _IPOPT_STATUS_MAP.get(raw, "error")


def jsonable(v: Any, *, keep_nonfinite: bool = False) -> Any:
    """``v`` as JSON data: the one converter of optkin's ``to_dict`` methods and files.

    Numpy arrays and scalars become lists and Python numbers, mappings dicts with string
    keys, tuples, lists and sets lists, objects with a ``to_dict`` method (results) and
    dataclasses their dicts, paths strings; anything else its ``repr``. NaN and +-inf
    become None (JSON has no such numbers), unless ``keep_nonfinite`` (a description
    that must round-trip, e.g. unbounded joint limits).

    Parameters
    ----------
    v : any
        The value to convert.
    keep_nonfinite : bool, optional
        Keep NaN and +-inf floats as they are (default False: None).

    Returns
    -------
    JSON data: dict, list, str, int, float, bool or None.

    Examples
    --------
    >>> jsonable({"q": np.array([1.0, np.nan]), 2: (np.int64(3), float("inf"))})
    {'q': [1.0, None], '2': [3, None]}
    """
    if v is None or isinstance(v, (str, bool)):
        return v
    if isinstance(v, float):  # before int: also numpy's float64, a float subclass
        return float(v) if keep_nonfinite or math.isfinite(v) else None
    if isinstance(v, int):
        return int(v)
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist(), keep_nonfinite=keep_nonfinite)
    if isinstance(v, np.generic):
        return jsonable(v.item(), keep_nonfinite=keep_nonfinite)
    if hasattr(v, "to_dict") and callable(v.to_dict) and not isinstance(v, type):
        return jsonable(v.to_dict(), keep_nonfinite=keep_nonfinite)
    if isinstance(v, Mapping):
        return {str(k): jsonable(x, keep_nonfinite=keep_nonfinite) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x, keep_nonfinite=keep_nonfinite) for x in v]
    if isinstance(v, (set, frozenset)):
        items = [jsonable(x, keep_nonfinite=keep_nonfinite) for x in v]
        try:
            return sorted(items)
        except TypeError:
            return items
    if dataclasses.is_dataclass(v) and not isinstance(v, type):  # its fields, not a deep copy
        return {f.name: jsonable(getattr(v, f.name), keep_nonfinite=keep_nonfinite)
                for f in dataclasses.fields(v)}
    if isinstance(v, os.PathLike):
        return os.fspath(v)
    return repr(v)




def _short_array(a: np.ndarray) -> str:
    """One line: at most 8 entries shown (first and last 3 of longer arrays)."""
    return np.array2string(np.asarray(a), precision=4, max_line_width=10**6, threshold=8,
                           edgeitems=3, separator=", ")


@dataclass
class SolverStats:
    """Which solver ran, how long it took and what it said.

    Attributes
    ----------
    solver : str
        The solver's name (``"ipopt"``, ``"newton"``, ``"CLARABEL"``, ...).
    setup_time, solve_time : float
        Seconds spent building and solving.
    nit : int
        Iterations.
    raw_status : str
        The solver's own word for the outcome (IPOPT's ``return_status``, cvxpy's
        ``problem.status``); the result's ``status`` is its translation into
        :data:`STATUS`.
    extra : dict
        Anything else the producer records.
    """

    solver: str = ""
    setup_time: float = 0.0
    solve_time: float = 0.0
    nit: int = 0
    raw_status: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`jsonable`)."""
        return jsonable(
            {
                "solver": self.solver,
                "setup_time": self.setup_time,
                "solve_time": self.solve_time,
                "nit": self.nit,
                "raw_status": self.raw_status,
                "extra": self.extra,
            }
        )


@dataclass(frozen=True)
class EnumerationStats:
    """The account of a search for every solution (``SolutionSet.stats``).

    Attributes
    ----------
    method : str
        ``"multistart"``: Newton from low-discrepancy starts (:func:`optkin.assembly_modes`);
        ``"homotopy"``: parameter homotopy paths (``method="homotopy"``).
    paths : int
        Starts (or homotopy paths) run to the end.
    finite : int
        Those that reached a solution.
    at_infinity : int
        Those that diverged (non-finite, or beyond 1000 mechanism sizes).
    singular : int
        Solutions found that are singular (cond(W_p) > 1e8) or lie on a continuum.
    failed : int
        The rest: stalled, or out of iterations.
    root_count : int or None
        The known bound on the number of solutions (None: unknown).
    complete : bool
        True only when every solution is accounted for: for ``"multistart"``, when the
        number of isolated solutions found equals the known bound and no continuum was met;
        for ``"homotopy"``, when every path ended (none failed or jumped) and the start
        system is not known to be short.
    """

    method: str
    paths: int
    finite: int
    at_infinity: int
    singular: int
    failed: int
    root_count: int | None
    complete: bool

    def to_dict(self) -> dict[str, Any]:
        return {"method": self.method, "paths": int(self.paths), "finite": int(self.finite),
                "at_infinity": int(self.at_infinity), "singular": int(self.singular),
                "failed": int(self.failed), "root_count": self.root_count,
                "complete": bool(self.complete)}


@dataclass(frozen=True)
class TrackStats:
    """The account of a tracked path (``SolutionSet.stats`` of :func:`optkin.track`).

    Attributes
    ----------
    points : int
        Path points asked for (rows of ``qa_path``).
    reached : int
        Points followed in the starting assembly mode (the solutions of the set).
    stopped_at : int or None
        Index of the first path point not reached (None: every point was).
    s_stop : float or None
        Where on the segment ending at ``stopped_at`` the tracking stopped, as a fraction
        of the segment (0 at its start, 1 at its end); None when nothing stopped it.
    max_cond : float or None
        Largest scaled condition number of W_p at the points reached.
    halvings : int
        Sub-steps halved by the step control along the whole path.
    time : float
        Wall time of the call, seconds.
    """

    points: int
    reached: int
    stopped_at: int | None
    s_stop: float | None
    max_cond: float | None
    halvings: int
    time: float

    @property
    def complete(self) -> bool:
        """True when every point of the path was reached."""
        return self.stopped_at is None and self.reached == self.points

    def to_dict(self) -> dict[str, Any]:
        return {"points": int(self.points), "reached": int(self.reached),
                "stopped_at": None if self.stopped_at is None else int(self.stopped_at),
                "s_stop": None if self.s_stop is None else float(self.s_stop),
                "max_cond": None if self.max_cond is None else float(self.max_cond),
                "halvings": int(self.halvings), "time": float(self.time),
                "complete": self.complete}


@dataclass
class KinResult:
    """The outcome of one kinematic solve.

    Attributes
    ----------
    q : ndarray
        All joint values in ``mech.joint_names`` order (NaN where unknown).
    qa, qp, qc : ndarray
        Active joints, passive joints of the tree, cut joints ([7.7]). Leg-described
        platforms have no cut joints (``qc`` is empty); their passive leg joints are ``qp``.
    x : ndarray
        The unknowns the solver worked on (passive joints for Khalil mechanisms, platform
        coordinates for leg-described ones).
    pose : ndarray
        4x4 homogeneous transform of the end effector in the base frame.
    success, status, message :
        Whether the closure is satisfied to tolerance; one of :data:`STATUS` (the solver's
        own word is ``stats.raw_status``); a sentence.
    residual : float
        max ``|Phi|`` at the returned configuration.
    nit : int
        Iterations used.
    posture : tuple or None
        For inverse solutions: the branch index of each leg; ``working_mode`` the sign of
        each B_jj (Chablat & Wenger 1998) where that applies.
    certified : bool or None
        None unless certification was asked for (``assembly_modes(..., certify=True)``,
        :func:`optkin.certify`); then True when Krawczyk's test proved that a box around
        ``x`` holds exactly one real solution.
    task : dict
        The pose as the mechanism's task coordinates, by name (``mech.task``): x, y, phi
        for a planar platform; x, y, z, roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll),
        scipy's ``Rotation.from_euler("ZYX", [yaw, pitch, roll])``) for a spatial one, whose
        ``x`` holds a quaternion instead; the named components for a Khalil table.
    """

    q: np.ndarray
    qa: np.ndarray
    qp: np.ndarray
    qc: np.ndarray
    x: np.ndarray
    pose: np.ndarray
    success: bool
    status: str
    message: str
    residual: float
    nit: int = 0
    stats: SolverStats = field(default_factory=SolverStats)
    posture: tuple[int, ...] | None = None
    working_mode: tuple[int, ...] | None = None
    cond: float = float("nan")
    joint_names: tuple[str, ...] = ()
    certified: bool | None = None
    #: the names of the task coordinates and the kind of task space (see :attr:`task`)
    task_names: tuple[str, ...] = ()
    task_space: str = ""

    @property
    def task(self) -> dict[str, float]:
        """The pose as task coordinates by name (NaN where the pose is unknown)."""
        if not self.task_names:
            return {}
        if not np.all(np.isfinite(self.pose)):
            return {n: float("nan") for n in self.task_names}
        from .mechanism.tasks import task_values

        v = task_values(self.task_space, self.task_names, self.pose)
        return {n: float(x) for n, x in zip(self.task_names, v)}

    @property
    def solve_time(self) -> float:
        return self.stats.solve_time

    @property
    def maxcv(self) -> float:
        """Largest constraint violation (scipy's name for :attr:`residual`)."""
        return self.residual

    def __repr__(self) -> str:
        flag = "ok" if self.success else "FAILED"
        extra = f", working_mode={self.working_mode}" if self.working_mode is not None else ""
        return (
            f"KinResult({flag}, status={self.status!r}, residual={self.residual:.2e}, "
            f"nit={self.nit}{extra}, q={_short_array(self.q)})"
        )

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`jsonable`: NaN and inf become None)."""
        return jsonable(
            {
                "success": bool(self.success),
                "status": self.status,
                "message": self.message,
                "residual": float(self.residual),
                "nit": int(self.nit),
                "q": self.q,
                "qa": self.qa,
                "qp": self.qp,
                "qc": self.qc,
                "x": self.x,
                "pose": self.pose,
                "joint_names": list(self.joint_names),
                "task": self.task,
                "posture": self.posture,
                "working_mode": self.working_mode,
                "cond": self.cond,
                **({} if self.certified is None else {"certified": bool(self.certified)}),
                "stats": self.stats.to_dict(),
            }
        )


class SolutionSet(Sequence):
    """Several solutions of one problem (assembly modes, postures).

    List-like (``len``, iteration, indexing) with a one-line summary and filters, in the
    spirit of HomotopyContinuation.jl's ``Result``.

    Attributes
    ----------
    success, status, message :
        The outcome of the search, as in every result (``info["success"]``,
        ``info["status"]`` and ``info["message"]``, which the producers set): ``success``
        False when nothing was found (status ``"infeasible"``) or the search stopped at a
        limit (``"time_limit"``, ``"iteration_limit"``), or a path at a singularity
        (``"singular"``, :func:`optkin.track`).
    stats : EnumerationStats or TrackStats
        The typed account: :class:`EnumerationStats` for a search of every solution
        (:func:`optkin.assembly_modes`, :func:`optkin.inverse`), :class:`TrackStats` for a
        tracked path (:func:`optkin.track`).
    info : dict
        Everything else the producer reports, keyed as its docstring lists (the
        Good-Turing account of the multistart, the homotopy's trace test, the path's
        determinants, ...): detail for the curious, where ``stats`` is the contract.
    """

    def __init__(
        self,
        solutions: Sequence[KinResult],
        kind: str = "solutions",
        info: dict[str, Any] | None = None,
        seed: int | None = None,
        dimension: int | None = None,
        components: Sequence[Any] = (),
        stats: EnumerationStats | TrackStats | None = None,
    ) -> None:
        self._sols = list(solutions)
        self.kind = kind
        self.info: dict[str, Any] = dict(info or {})
        self.seed = seed
        #: 0 when every solution found is isolated, d >= 1 when some form a continuum of
        #: dimension d (see :attr:`components`); None where the producer does not examine it
        self.dimension = dimension
        #: Positive-dimensional sets of solutions (:class:`optkin.solvers.continua.Component`:
        #: ``dimension`` and sample configurations), apart from the isolated solutions
        self.components = list(components)
        #: The typed account (:class:`EnumerationStats` or :class:`TrackStats`)
        self.stats = stats

    @property
    def success(self) -> bool:
        """``info["success"]`` when the producer set it, else whether any solution exists."""
        v = self.info.get("success")
        return bool(v) if v is not None else bool(self._sols)

    @property
    def status(self) -> str:
        """``info["status"]`` when the producer set it, else ``"optimal"`` when successful
        and ``"infeasible"`` otherwise (one of :data:`STATUS`)."""
        v = self.info.get("status")
        if v is not None:
            return str(v)
        return OPTIMAL if self.success else INFEASIBLE

    @property
    def message(self) -> str:
        """``info["message"]`` when the producer set it, else the :meth:`summary`."""
        v = self.info.get("message")
        return str(v) if v else self.summary()

    @property
    def complete(self) -> bool:
        """True when every solution is accounted for (:attr:`stats`; else ``info``)."""
        if self.stats is not None:
            return bool(self.stats.complete)
        return bool(self.info.get("complete", False))

    def __len__(self) -> int:
        return len(self._sols)

    def __getitem__(self, i):  # type: ignore[override]
        if isinstance(i, slice):
            return SolutionSet(self._sols[i], self.kind, self.info, self.seed,
                               self.dimension, self.components, self.stats)
        return self._sols[i]

    def __iter__(self) -> Iterator[KinResult]:
        return iter(self._sols)

    def summary(self) -> str:
        near = sum(1 for s in self._sols if s.cond > 1e8)  # inf: singular (NaN: not known)
        text = f"{len(self._sols)} {self.kind}"
        conv, starts = self.info.get("converged"), self.info.get("starts")
        if isinstance(conv, int) and isinstance(starts, int) and starts > 0:
            text += f" ({conv} of {starts} starts converged)"
        text += f", {near} near-singular"
        if any(s.certified is not None for s in self._sols):
            text += f", {sum(1 for s in self._sols if s.certified)} certified"
        if self.components:
            text += (f"; and {len(self.components)} continuum component(s) of dimension "
                     + ", ".join(str(c.dimension) for c in self.components))
        return text

    def __repr__(self) -> str:
        return f"SolutionSet({self.summary()})"

    def nonsingular(self, max_cond: float = 1e8) -> SolutionSet:
        """The solutions whose condition number of W_p is at most ``max_cond`` (a singular
        one, ``cond = inf``, never is; one whose condition number was not computed, NaN, is
        kept)."""
        from ._checks import check_number

        max_cond = check_number(max_cond, "max_cond", lo=1.0, finite=False,
                                want="a number >= 1 (a condition number)")
        keep = [s for s in self._sols if not s.cond > max_cond]
        return SolutionSet(keep, self.kind, self.info, self.seed, self.dimension,
                           self.components, self.stats)

    def closest_to(self, q: Sequence[float]) -> KinResult:
        """The solution whose ``q`` is nearest to ``q`` (angles not wrapped)."""
        if not self._sols:
            raise IndexError("the solution set is empty")
        q = np.asarray(q, dtype=float)
        nq = len(self._sols[0].q)
        if q.shape != (nq,):
            from .errors import MechanismError

            raise MechanismError(
                f"q: expected {nq} joint values (as in KinResult.q), got shape {q.shape}")
        d = [float(np.linalg.norm(np.nan_to_num(s.q) - q)) for s in self._sols]
        return self._sols[int(np.argmin(d))]

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`jsonable`) with ``success``, ``status`` and
        ``message`` at the top level (``info`` repeats what the producer set)."""
        return jsonable(
            {
                "kind": self.kind,
                "count": len(self._sols),
                "seed": self.seed,
                "success": self.success,
                "status": self.status,
                "message": self.message,
                "info": self.info,
                "solutions": [s.to_dict() for s in self._sols],
                **({} if self.stats is None else {"stats": self.stats.to_dict(),
                                                  "complete": bool(self.stats.complete)}),
                **({} if self.dimension is None else {
                    "dimension": self.dimension,
                    "components": [c.to_dict() for c in self.components]}),
            }
        )
