"""Result objects: every solve returns data, never raises on non-convergence.

The vocabulary follows scipy's ``OptimizeResult`` (``x``, ``success``, ``status``,
``message``, ``nit``) plus the kinematic fields, like cvxpy's ``SolverStats`` for the
solver side.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["KinResult", "SolutionSet", "SolverStats", "STATUS", "ipopt_status"]

#: The handful of statuses every result uses.
STATUS = ("optimal", "inaccurate", "infeasible", "iteration_limit", "singular", "error")

_IPOPT_STATUS_MAP = {
    "Solve_Succeeded": "optimal",
    "Solved_To_Acceptable_Level": "inaccurate",
    "Infeasible_Problem_Detected": "infeasible",
    "Restoration_Failed": "infeasible",
    "Local_Infeasibility": "infeasible",
    "Maximum_Iterations_Exceeded": "iteration_limit",
    "Maximum_CpuTime_Exceeded": "iteration_limit",
    "Maximum_WallTime_Exceeded": "iteration_limit",
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


def _jsonable(v: Any) -> Any:
    if isinstance(v, np.ndarray):
        return _jsonable(v.tolist())  # recurse: NaN and inf entries become None
    if isinstance(v, (np.floating, np.integer, np.bool_)):
        return _jsonable(v.item())
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def _short_array(a: np.ndarray) -> str:
    """One line: at most 8 entries shown (first and last 3 of longer arrays)."""
    return np.array2string(np.asarray(a), precision=4, max_line_width=10**6, threshold=8,
                           edgeitems=3, separator=", ")


@dataclass
class SolverStats:
    """Which solver ran, how long it took and what it said."""

    solver: str = ""
    setup_time: float = 0.0
    solve_time: float = 0.0
    nit: int = 0
    raw_status: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return _jsonable(
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
        Whether the closure is satisfied to tolerance; one of :data:`STATUS`; a sentence.
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
        """A JSON-ready dict (NaN and inf become None)."""
        return _jsonable(
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
    """

    def __init__(
        self,
        solutions: Sequence[KinResult],
        kind: str = "solutions",
        info: dict[str, Any] | None = None,
        seed: int | None = None,
        dimension: int | None = None,
        components: Sequence[Any] = (),
        stats: EnumerationStats | None = None,
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
        #: The account of the search (:class:`EnumerationStats`) where the producer keeps one
        self.stats = stats

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
        try:
            max_cond = float(max_cond)
        except (TypeError, ValueError):
            max_cond = float("nan")
        if not max_cond >= 1:  # NaN fails too
            from .errors import MechanismError

            raise MechanismError(f"max_cond: expected a number >= 1 (a condition number), got "
                                 f"{max_cond!r}")
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
        """A JSON-ready dict; ``success``, ``status`` and ``message`` of ``info`` (when the
        producer sets them, e.g. assembly_modes, track) are repeated at the top level."""
        head = {k: self.info[k] for k in ("success", "status", "message") if k in self.info}
        return _jsonable(
            {
                "kind": self.kind,
                "count": len(self._sols),
                "seed": self.seed,
                **head,
                "info": self.info,
                "solutions": [s.to_dict() for s in self._sols],
                **({} if self.stats is None else {"stats": self.stats.to_dict(),
                                                  "complete": bool(self.stats.complete)}),
                **({} if self.dimension is None else {
                    "dimension": self.dimension,
                    "components": [c.to_dict() for c in self.components]}),
            }
        )
