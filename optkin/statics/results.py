"""Result objects of the statics analyses (data, never exceptions for solver outcomes)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..results import SolverStats, jsonable

__all__ = ["CapabilityResult", "PolytopeResult", "FeasibilityResult", "WorkspaceResult",
           "DistributionResult"]


class _Result:
    """What the statics results share: ``to_dict`` (every field, as JSON data by
    :func:`optkin.results.jsonable`) and a one-line ``repr``. Each has ``success``,
    ``status`` (:data:`optkin.results.STATUS`; the solver's own word is
    ``stats.raw_status``) and ``message``, as every result of optkin."""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict of every field (NaN and inf become None)."""
        return {k: jsonable(getattr(self, k)) for k in self.__dataclass_fields__}  # type: ignore[attr-defined]

    def __repr__(self) -> str:
        return f"{type(self).__name__}(success={self.success}, status={self.status!r})"  # type: ignore[attr-defined]


@dataclass(repr=False)
class CapabilityResult(_Result):
    """The largest wrench along each direction the end effector can apply.

    Attributes
    ----------
    directions : array (k, m)
        Unit wrench directions (rows), components :attr:`wrench_names`.
    max : array (k,)
        The largest magnitude s with s * direction achievable; 0 where the direction is not
        resisted (parallel singularity), inf where it is carried without actuator force.
    points : array (k, m)
        ``max[:, None] * directions`` (finite rows only; inf rows are nan).
    tau : array (k, na)
        Actuator forces achieving each point.
    direction_status : list of str
        Per direction: ``"optimal"``, ``"unresisted"`` or ``"unbounded"``.
    success, status, message
        ``status`` is ``"optimal"``, ``"singular"`` (values valid, see ``singularity``),
        or a solver status (``"inaccurate"``, ``"infeasible"``, ``"error"``).
    singularity : str
        Of the static model: ``"none"``, ``"parallel"``, ``"serial"``, ``"parallel+serial"``.
    unresisted : array (m, j)
        Twists the platform follows with locked actuators (see the static model).
    """

    directions: np.ndarray
    max: np.ndarray
    points: np.ndarray
    tau: np.ndarray
    direction_status: list[str]
    success: bool
    status: str
    message: str
    singularity: str
    unresisted: np.ndarray
    wrench_names: tuple[str, ...]
    limits: np.ndarray
    cond: float
    stats: SolverStats = field(default_factory=SolverStats)


@dataclass(repr=False)
class PolytopeResult(_Result):
    """The capability polytope {G tau : lo <= tau <= hi} (a zonotope), as vertices and facets.

    ``equations`` rows (a, b) describe the polytope as a . F + b <= 0 (scipy's
    ``ConvexHull.equations``, mapped back to the full wrench space when the polytope is
    flat, in which case ``dimension < m`` and the flat directions appear as pairs of
    opposite inequalities).
    """

    vertices: np.ndarray
    equations: np.ndarray
    dimension: int
    volume: float
    success: bool
    status: str
    message: str
    wrench_names: tuple[str, ...]

    def support(self, d: Any) -> float:
        """The largest s >= 0 with s * d inside the polytope (ray shooting on the facets)."""
        d = np.asarray(d, dtype=float)
        a, b = self.equations[:, :-1], self.equations[:, -1]
        ad = a @ d
        with np.errstate(divide="ignore"):
            lim = np.where(ad > 1e-14, -b / np.where(ad > 1e-14, ad, 1.0), np.inf)
        if np.any((np.abs(ad) <= 1e-14) & (b > 1e-12)):
            return 0.0
        return float(max(0.0, lim.min())) if lim.size else float("inf")

    def section(self, plane: tuple[str, str] = ("fx", "fy")) -> np.ndarray:
        """Vertices (k, 2), counter-clockwise, of the section of the polytope by the plane of
        two components (the others zero); empty when the section is degenerate."""
        from scipy.spatial import HalfspaceIntersection, QhullError

        names = list(self.wrench_names)
        idx = [names.index(c) for c in plane]
        if self.equations.shape[0] == 0:
            return np.zeros((0, 2))
        H = np.column_stack([self.equations[:, idx], self.equations[:, -1]])
        if np.any(H[:, -1] >= -1e-12):  # the origin is not strictly inside
            return np.zeros((0, 2))
        try:
            V = HalfspaceIntersection(H, np.zeros(2)).intersections
        except QhullError:
            return np.zeros((0, 2))
        c = V.mean(axis=0)
        V = V[np.argsort(np.arctan2(V[:, 1] - c[1], V[:, 0] - c[0]))]
        keep = np.r_[True, np.linalg.norm(np.diff(V, axis=0), axis=1) > 1e-12]
        return V[keep]


@dataclass(repr=False)
class FeasibilityResult(_Result):
    """Whether every wrench of a set (given by its vertices) is achievable within the limits.

    ``margin`` = 1 - (smallest achievable worst utilisation max_i tau_i / limit_i over the
    vertices): the fraction of the actuator limits left at the worst vertex; the set is
    feasible iff margin >= 0 (-inf when a vertex cannot be resisted at all).
    """

    feasible: bool
    margin: float
    vertices: np.ndarray
    tau: np.ndarray
    worst_vertex: int
    success: bool
    status: str
    message: str
    singularity: str
    wrench_names: tuple[str, ...]
    stats: SolverStats = field(default_factory=SolverStats)


@dataclass(repr=False)
class WorkspaceResult(_Result):
    """Wrench-feasibility margin over a set of poses (a grid or a list).

    ``point_status`` per pose: ``"feasible"``, ``"infeasible"``, ``"unreachable"`` (no
    inverse solution), ``"singular"`` (the set is not resisted: parallel singularity) or a
    solver status. ``margin`` is nan where unreachable.
    """

    poses: np.ndarray
    margin: np.ndarray
    feasible: np.ndarray
    point_status: list[str]
    grid_shape: tuple[int, ...] | None
    axes: tuple[str, ...]
    success: bool
    status: str
    message: str
    task_names: tuple[str, ...]
    stats: SolverStats = field(default_factory=SolverStats)

    @property
    def fraction(self) -> float:
        """Fraction of the reachable poses where the wrench set is feasible."""
        reach = np.isfinite(self.margin) | (self.margin == -np.inf)
        return float(self.feasible[reach].mean()) if reach.any() else 0.0


@dataclass(repr=False)
class DistributionResult(_Result):
    """Actuator forces producing a wrench, with the smallest 2-norm or largest entry.

    ``tau`` the actuator forces (nan when infeasible), ``multipliers`` the constraint
    forces lambda (leg forces), ``wrench`` the requested F, ``residual`` max ``|G tau - F|``
    recomputed from the static model, ``utilisation`` tau_i / limit_i (signed side).
    """

    tau: np.ndarray
    multipliers: np.ndarray
    wrench: np.ndarray
    norm: str
    value: float
    residual: float
    utilisation: np.ndarray | None
    success: bool
    status: str
    message: str
    singularity: str
    actuator_names: tuple[str, ...]
    stats: SolverStats = field(default_factory=SolverStats)
