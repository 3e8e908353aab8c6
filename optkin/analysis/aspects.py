"""Working modes, generalized aspects and workspaces of planar parallel mechanisms.

Chablat and Wenger 1998: a working mode Mf_i is a set of configurations where the
signs of the diagonal entries B_jj of the inverse-kinematics matrix stay constant and
nonzero (Definition 4); the generalized aspects A_ij are the maximal connected subsets of a
working mode free of parallel singularities, det A != 0 (Definition 5); their projections
are the parallel aspects WA_ij in the workspace (Definition 6) and the serial aspects QA_ij
in the joint space (Definition 7).

For planar distance legs (one closed-form branch of the leg's inverse per sign of its
B_jj), one working mode maps homeomorphically onto its workspace region (each leg's
posture is the closed-form branch of the mode), so the aspects
of Mf_i are the faces, inside W_i, of the planar arrangement of the curves that bound them in
the workspace plane: the serial curves B_jj = 0 and joint-limit curves of this working mode
(the boundary of W_i) and the parallel curves det A = 0 of this working mode, all traced by
continuation (:mod:`optkin.analysis.continuation`). Connectivity thus follows the traced
curves (:mod:`optkin.analysis.planar`): a thin or small aspect is a face like any other.
The joint-space projection QA_ij is a mask on a grid of q_a (closed-form direct kinematics
of two-leg point platforms), with its area; the workspace projection WA_ij is a polygon
with holes and its exact (polygon) area. The closed forms (leg inverses, circles, circle
intersections) are the model's chart (:mod:`optkin.model.charts`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_float, check_mechanism, check_number
from ..errors import MechanismError
from ..limits import SAFETY, check_size, show
from ..mechanism import Mechanism
from ..model import get_model
from ..model.charts import PlanarChart, planar_chart
from ..results import INACCURATE, LIMIT_REACHED, OPTIMAL, jsonable
from .continuation import (
    DEFAULT_STEP,
    MIN_POINTS,
    SingularCurves,
    _cell_cost,
    _check_mech_size,
    _mapping_arg,
    _pair_arg,
    _point_cost,
    _singular_curves,
    _split_wrapped,
    augmented_system,
)
from .planar import Face, faces

__all__ = ["Aspect", "Aspects", "Workspace", "aspects", "workspace", "ASPECTS_DEFAULTS",
           "leg_working_modes"]

#: Options of :func:`aspects` and :func:`workspace` (the same for both).
ASPECTS_DEFAULTS: dict[str, Any] = {
    "limits": None,  # actuated joint limits {name: (lo, hi)} (the passive joints are unlimited)
    "bounds": None,  # box [[lo, hi], [lo, hi]] in the workspace plane; None: the reach of
    # the legs
    "grid": None,  # seeding grid of the continuation per chart axis (None: 32); it only seeds
    "qa_grid": 200,  # resolution of the joint-space masks (two-leg point platforms), >= 2
    "step": None,  # largest continuation step, scaled units (None: 0.08)
}


def leg_working_modes(mech: Mechanism) -> list[tuple[int, ...]]:
    """All sign patterns of diag(B) of a fully parallel mechanism (Chablat & Wenger 1998, Def. 4), in
    the model's order (:meth:`optkin.model.core.Model.working_modes`).

    A leg whose actuated joint moves the centre of its distance constraint has two
    postures (B_jj of either sign); one whose actuated joint is the distance has
    B_jj = -1 always.
    """
    modes = get_model(mech).working_modes()
    if not modes:
        raise MechanismError(f"{mech.name}: working modes are defined for fully parallel "
                             "mechanisms (legs that are distance constraints, one actuator "
                             "each)")
    return modes


@dataclass
class Aspect:
    """One generalized aspect A_ij (Chablat & Wenger 1998, Definition 5).

    Attributes
    ----------
    working_mode : tuple of int
        Signs of the B_jj in it.
    det_sign : int
        Sign of det A (= det W_p) in it.
    face : Face
        Its workspace projection WA_ij (outer ring and holes) in the plane.
    area : float
        The area of WA_ij (polygon area).
    v : ndarray
        A representative configuration (q_a then x), well inside.
    qa_mask : ndarray of bool or None
        Its joint-space projection QA_ij on the grid ``Aspects.qa_grid``.
    qa_area : float or None
        The area of QA_ij (cells times cell area).
    """

    working_mode: tuple[int, ...]
    det_sign: int
    face: Face
    area: float
    v: np.ndarray
    qa: np.ndarray
    x: np.ndarray
    qa_mask: np.ndarray | None = None
    qa_area: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"working_mode": list(self.working_mode), "det_sign": self.det_sign,
                "area": self.area, "qa_area": self.qa_area, "qa": self.qa.tolist(),
                "x": self.x.tolist(), "n_holes": len(self.face.holes)}


@dataclass
class Aspects:
    """The generalized aspects of every working mode (see :func:`aspects`).

    Attributes
    ----------
    aspects : list of Aspect
        Every aspect (working mode, sign of det A, face, area, representative point).
    curves : SingularCurves
        The curves that bound them.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``; ``"inaccurate"`` when the
        curves are, or an aspect has no sign of det A; ``"time_limit"`` /
        ``"memory_limit"`` when the curves stopped at a budget (no aspects then).
    """

    mechanism: str
    working_modes: list[tuple[int, ...]]
    aspects: list[Aspect]
    curves: SingularCurves
    plane: tuple[str, str]
    qa_names: tuple[str, ...]
    qa_grid: tuple[np.ndarray, np.ndarray] | None
    success: bool
    status: str
    message: str
    time: float = 0.0
    workspace_area: dict[tuple[int, ...], float] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.aspects)

    def __iter__(self):
        return iter(self.aspects)

    def __repr__(self) -> str:
        counts = ", ".join(f"{m}: {n}" for m, n in self.counts.items())
        return (f"Aspects({self.mechanism!r}, {len(self.aspects)} aspect(s) in "
                f"{len(self.working_modes)} working mode(s) {{{counts}}}, status={self.status!r})")

    def of_mode(self, mode: tuple[int, ...]) -> list[Aspect]:
        return [a for a in self.aspects if a.working_mode == tuple(mode)]

    @property
    def counts(self) -> dict[tuple[int, ...], int]:
        return {m: len(self.of_mode(m)) for m in self.working_modes}

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({
            "mechanism": self.mechanism, "success": self.success, "status": self.status,
            "message": self.message, "count": len(self.aspects),
            "n_working_modes": len(self.working_modes),
            "working_modes": [list(m) for m in self.working_modes],
            "counts": [self.counts[m] for m in self.working_modes],
            "aspects": [a.to_dict() for a in self.aspects], "time": self.time,
            "workspace_area": [self.workspace_area.get(m) for m in self.working_modes],
        })

    def plot(self, path: str | None = None, title: str | None = None, *, fig: Any = None
             ) -> Any:
        """One column per working mode: its aspects in the workspace and the joint space.

        Returns the matplotlib Figure; ``fig`` draws into an empty Figure of yours (a
        notebook's), ``path`` writes it (PNG, SVG, PDF, ... by the suffix; masks rasterized).
        """
        _check_path(path)
        return _plot_aspects(self, path, title, fig)


@dataclass
class Workspace:
    """The reachable workspace in a plane, per working mode and in total.

    Attributes
    ----------
    regions, areas : dict
        Per working mode: its faces and their total area; ``total`` and ``area`` for the
        union.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``, ``"inaccurate"`` (the
        serial curves are), ``"time_limit"`` / ``"memory_limit"`` (no regions then).
    """

    mechanism: str
    plane: tuple[str, str]
    working_modes: list[tuple[int, ...]]
    regions: dict[tuple[int, ...], list[Face]]
    areas: dict[tuple[int, ...], float]
    total: list[Face]
    area: float
    curves: SingularCurves
    success: bool
    status: str
    message: str
    time: float = 0.0
    qa_masks: dict[tuple[int, ...], np.ndarray] | None = None
    qa_grid: tuple[np.ndarray, np.ndarray] | None = None
    qa_names: tuple[str, ...] = ()

    def __repr__(self) -> str:
        return (f"Workspace({self.mechanism!r}, plane={self.plane}, area={self.area:.4g}, "
                f"{len(self.working_modes)} working mode(s), status={self.status!r})")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({"mechanism": self.mechanism, "success": self.success,
                         "status": self.status, "message": self.message, "area": self.area,
                         "working_modes": [list(m) for m in self.working_modes],
                         "areas": [self.areas[m] for m in self.working_modes],
                         "n_regions": [len(self.regions[m]) for m in self.working_modes],
                         "time": self.time})

    def plot(self, path: str | None = None, title: str | None = None, *, fig: Any = None
             ) -> Any:
        """The reachable regions of each working mode and their union.

        Returns the matplotlib Figure; ``fig`` draws into an empty Figure of yours,
        ``path`` writes it.
        """
        _check_path(path)
        return _plot_workspace(self, path, title, fig)


# ---------------------------------------------------------------------------------------


def _runs(curves: SingularCurves, mode: tuple[int, ...], kinds: tuple[str, ...]) -> list[tuple[np.ndarray, bool]]:
    """The pieces of the traced curves that lie in working mode ``mode`` (plane points).

    A piece ends where some B_kk changes sign; its end is interpolated to B_kk = 0 and
    later snapped onto the serial curve it meets.
    """
    out = []
    m = np.array(mode)
    for c in curves.curves:
        if not c.kind.startswith(kinds):
            continue
        cmp = np.ones(len(m), dtype=bool)
        if c.kind.startswith("serial:"):
            cmp[int(c.kind.split(":")[1])] = False
        S = np.sign(c.B)
        inm = np.all(S[:, cmp] == m[cmp], axis=1)
        if inm.all():
            out.append((c.points, c.closed))
            continue
        if not inm.any():
            continue
        n = len(inm)
        idx = np.arange(n)
        if c.closed:  # rotate so that the curve starts out of the mode
            k0 = int(np.flatnonzero(~inm)[0])
            idx = np.roll(idx, -k0)
        flags = inm[idx]
        P = c.points[idx]
        Bv = c.B[idx]
        k = 0
        while k < n:
            if not flags[k]:
                k += 1
                continue
            j = k
            while j + 1 < n and flags[j + 1]:
                j += 1
            pts = [P[k:j + 1]]
            if k > 0:
                pts.insert(0, _cross(P[k - 1], P[k], Bv[k - 1], Bv[k], m, cmp)[None])
            if j + 1 < n:
                pts.append(_cross(P[j], P[j + 1], Bv[j], Bv[j + 1], m, cmp)[None])
            elif c.closed:
                pts.append(_cross(P[j], P[0], Bv[j], Bv[0], m, cmp)[None])
            run = np.vstack(pts)
            if len(run) >= 2:
                out.append((run, False))
            k = j + 1
    return out


def _cross(pa, pb, ba, bb, m, cmp) -> np.ndarray:
    """Linear interpolation where the first B_kk leaves its sign between two points."""
    s = 1.0
    for kk in np.flatnonzero(cmp):
        if np.sign(ba[kk]) != np.sign(bb[kk]) and ba[kk] != bb[kk]:
            s = min(s, ba[kk] / (ba[kk] - bb[kk]))
    s = float(np.clip(s, 0, 1))
    return pa + s * (pb - pa)


def _box(bounds: np.ndarray) -> np.ndarray:
    (x0, x1), (y0, y1) = bounds
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], dtype=float)


def _label(chart: PlanarChart, pidx, fixed: dict[int, float], P: np.ndarray, mode,
           limits: dict[int, tuple[float, float]]) -> tuple[np.ndarray | None, float]:
    """The configuration of working mode ``mode`` over plane point P, and det A there."""
    model = chart.model
    mech = model.mech
    na, nx = model.na, model.nx
    x = np.zeros(nx)
    for i, v in fixed.items():
        if i >= na:
            x[i - na] = v
    for k, i in enumerate(pidx):
        x[i - na] = P[k]
    sys = augmented_system(mech, "parallel", tuple(sorted(fixed)))
    for V, ok in chart.full_points(x[None, :]):
        if not ok[0]:
            continue
        v = V[0]
        if any(not (lo <= v[i] <= hi) for i, (lo, hi) in limits.items()):
            continue
        d, B = sys.aux_many(v[:, None])
        if tuple(np.sign(B[:, 0]).astype(int)) == tuple(mode):
            return v, float(d[0])
    return None, 0.0


def _check_path(path: Any) -> None:
    if path is not None and not (isinstance(path, (str, os.PathLike)) or hasattr(path, "write")):
        raise MechanismError(f"path: expected a file name (str or os.PathLike) for the PNG, "
                             f"got {type(path).__name__}")


def _check_plane(mech: Mechanism, fixed: Mapping[str, float] | None):
    check_mechanism(mech)
    model = get_model(mech)
    chart = planar_chart(model)
    if chart is None:
        raise MechanismError(
            f"{mech.name}: aspects and workspaces are computed for planar platforms whose "
            "legs are distance constraints with one actuator each (2-DoF point platforms, "
            "or 3-DoF platforms at a fixed orientation)")
    _check_mech_size(model)
    fixed = _mapping_arg(fixed, "fixed")
    turn = [model.x_names[j] for j in chart.orientation]
    dof = model.platform.dof
    if turn and set(fixed) != set(turn):
        sec = ", ".join(f"{n!r}: value" for n in turn)
        raise MechanismError(
            f"{mech.name}: a {dof}-DoF platform needs a section at fixed orientation: "
            f"fixed={{{sec}}}")
    if not turn and fixed:
        raise MechanismError(f"{mech.name}: a {dof}-DoF point platform takes no fixed "
                             "coordinates")
    names = tuple(mech.active_names) + tuple(model.x_names)
    fixed = {k: as_float(v, f"fixed[{show(k)}]") for k, v in fixed.items()}
    return fixed, names, chart


def _limit_map(mech, names, limits):
    out = {}
    for k, pair in _mapping_arg(limits, "limits").items():
        if not isinstance(k, str) or k not in names[: get_model(mech).na]:
            raise MechanismError(f"limits: {show(k)} is not an actuated joint of "
                                 f"{mech.name}; known: {', '.join(mech.active_names)}")
        out[names.index(k)] = _pair_arg(pair, f"limits[{k!r}]")
    return out


def _first_range(who: str, model, names, lim) -> tuple[float, float]:
    """The range of the first actuated joint: its limits, else its chart's natural range
    (an angle's turn, a length's span)."""
    if 0 in lim:
        return lim[0]
    from ..model.charts import planar_chart

    chart = planar_chart(model)
    if chart is None:
        raise MechanismError(f"{who}: give limits for {names[0]} (its range is not known)")
    return chart.actuator_range(0)


def min_face_area(snap: float) -> float:
    """Faces smaller than this are dropped as slivers (see :func:`_region_faces`): a
    chord of a traced curve (at most ``snap / 3`` long, turning at most 0.25 rad) leaves a
    sliver of at most about 0.02 of its length squared against the boundary it touches."""
    return 0.02 * (snap / 3.0) ** 2


def _region_faces(chart, curves, mode, bounds, snap, pidx, fixed_map, lim_map, with_parallel):
    kinds = ("serial", "limit", "parallel") if with_parallel else ("serial", "limit")
    lines = _runs(curves, mode, kinds)
    lines.append((_box(bounds), True))
    out = []
    # slivers between a chord of a curve and the boundary it touches (a parallel curve meets
    # the workspace boundary tangentially, at a fold) are below the resolution of the
    # polylines: faces smaller than a fraction of a step squared are dropped
    min_area = min_face_area(snap)
    for f in faces(lines, snap=snap):
        if f.area < min_area or f.point is None:  # (the point is computed when read)
            continue
        v, d = _label(chart, pidx, fixed_map, f.point, mode, lim_map)
        if v is None:
            continue
        out.append((f, v, d))
    return out


def aspects(
    mech: Mechanism,
    fixed: Mapping[str, float] | None = None,
    **options: Any,
) -> Aspects:
    """The generalized aspects of every working mode (Chablat and Wenger 1998).

    Parameters
    ----------
    mech : Mechanism
        A planar platform whose legs are distance constraints with one actuator each
        (:func:`optkin.model.charts.planar_chart`): a 2-DoF point platform (the five-bar), or
        a 3-DoF platform in a section at fixed orientation (``fixed={"phi": value}``; the
        aspects are then those of the section). A 3-DoF platform without ``fixed`` gets
        its aspects in (x, y, phi): :func:`optkin.analysis.aspects3d.aspects3d`.
    fixed : dict, optional
        The section of a 3-DoF platform, ``{"phi": value}``.
    **options
        The options below, by keyword, over :data:`ASPECTS_DEFAULTS` (an unknown name is a
        :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    limits : dict name -> (lo, hi), optional
        Actuated joint limits (the passive joints are unlimited).
    bounds : [[lo, hi], [lo, hi]], optional
        A box in the workspace plane (default: the reach of the legs).
    grid : int, optional
        Seeding grid of the continuation (default 32; it only seeds).
    qa_grid : int
        Resolution of the joint-space masks QA_ij (two-leg point platforms; default 200).
    step : float, optional
        Continuation step (scaled units; default 0.08).

    Returns
    -------
    Aspects
        ``aspects`` (each with working_mode, det_sign, face = WA polygon, area, v, qa_mask,
        qa_area), ``counts`` per working mode, the traced ``curves``, success/status/message.

    Memory and time
    ---------------
    Checked against the budget of :mod:`optkin.limits` before anything is allocated:
    ``qa_grid``^2 mask cells of about 400 bytes plus one byte per mask (223 bytes measured
    for a five-bar), then the seeding chart of :func:`singular_curves` (``grid``^2 points),
    then every traced point at about 2.1 KB plus 60 nv bytes (the curves and the planar
    arrangements of the regions; 2.1 KB measured for a five-bar). When the curves stop
    at a budget (status ``"memory_limit"`` or ``"time_limit"``) no aspects are returned
    and ``success`` is False.

    Examples
    --------
    >>> import optkin
    >>> a = optkin.aspects(optkin.mechanisms.five_bar(9, 8, 5, 5, 8))
    >>> a.working_modes
    [(1, 1), (1, -1), (-1, 1), (-1, -1)]
    >>> [a.counts[w] for w in a.working_modes]
    [2, 3, 3, 2]
    """
    t0 = time.perf_counter()
    from ..solvers.common import merge_options

    o = merge_options(ASPECTS_DEFAULTS, options, "aspects")
    limits, bounds, grid, qa_grid, step = (o["limits"], o["bounds"], o["grid"],
                                           o["qa_grid"], o["step"])
    if fixed is None and isinstance(mech, Mechanism):
        model = get_model(mech)
        chart = planar_chart(model)
        if chart is not None and chart.orientation and model.na == 3:
            from .aspects3d import aspects3d  # a turning 3-DoF platform, no section

            kw = {} if step is None else {"step": step}  # grid, qa_grid: planar only
            return aspects3d(mech, limits=limits, bounds=bounds, **kw)  # type: ignore
    fixed, names, chart = _check_plane(mech, fixed)
    qa_grid = check_number(qa_grid, "aspects: option qa_grid", integer=True, lo=2)
    lim_map = _limit_map(mech, names, limits)
    model = get_model(mech)
    qa_cost = _qa_grid_cost(chart, "aspects", qa_grid)
    kinds = ["parallel", "serial"] + (["limit"] if lim_map else [])
    curves = _singular_curves(mech, "workspace", kinds, fixed, bounds, grid, limits, step,
                              1e-11, None, False, None, "aspects", _region_cost(model),
                              qa_cost)
    modes = leg_working_modes(mech)
    if curves.status in _STOPPED:  # incomplete curves bound no regions
        return Aspects(mechanism=mech.name, working_modes=modes, aspects=[], curves=curves,
                       plane=curves.plane, qa_names=tuple(mech.active_names), qa_grid=None,
                       success=False, status=curves.status,
                       message=f"no aspects: {curves.message}",
                       time=time.perf_counter() - t0, workspace_area={})
    pidx = curves.info["plane_index"]
    fixed_map = {names.index(k): float(v) for k, v in fixed.items()}
    snap = 3.0 * float(step or DEFAULT_STEP) * model.length
    out: list[Aspect] = []
    wareas = {}
    for mode in modes:
        reg = _region_faces(chart, curves, mode, curves.bounds, snap, pidx, fixed_map, lim_map,
                            True)
        for f, v, d in reg:
            out.append(Aspect(working_mode=mode, det_sign=int(np.sign(d)), face=f, area=f.area,
                              v=v, qa=v[:model.na].copy(), x=v[model.na:].copy()))
        wareas[mode] = float(sum(f.area for f, _, _ in reg))
    qgrid = None
    if chart.two_leg_point and out:
        qgrid = _qa_masks(chart, out, qa_grid, lim_map)
    ok = curves.success and all(a.det_sign != 0 for a in out)
    counts = {m: sum(a.working_mode == m for a in out) for m in modes}
    msg = (f"{len(modes)} working mode(s), aspects per mode "
           f"{[counts[m] for m in modes]}; curves: {curves.message}")
    status = OPTIMAL if ok else _failed_status(curves)
    return Aspects(mechanism=mech.name, working_modes=modes, aspects=out, curves=curves,
                   plane=curves.plane, qa_names=tuple(mech.active_names), qa_grid=qgrid,
                   success=bool(ok), status=status, message=msg,
                   time=time.perf_counter() - t0, workspace_area=wareas)


def _qa_masks(chart: PlanarChart, out: list[Aspect], n: int, lim_map
              ) -> tuple[np.ndarray, np.ndarray]:
    """Each aspect's joint-space projection QA_ij on an n x n grid of q_a (closed-form
    direct kinematics of a two-leg point platform)."""
    mech = chart.model.mech
    r0, r1 = chart.actuator_range(0), chart.actuator_range(1)
    g0 = np.linspace(*r0, n, endpoint=False) + 0.5 * (r0[1] - r0[0]) / n
    g1 = np.linspace(*r1, n, endpoint=False) + 0.5 * (r1[1] - r1[0]) / n
    G0, G1 = np.meshgrid(g0, g1, indexing="ij")
    Q = np.stack([G0.ravel(), G1.ravel()], 1)
    cell = (r0[1] - r0[0]) * (r1[1] - r1[0]) / n**2
    sys = augmented_system(mech, "parallel", ())
    for a in out:
        a.qa_mask = np.zeros(n * n, dtype=bool)
    inlim = np.ones(len(Q), dtype=bool)
    for i, (lo, hi) in lim_map.items():
        inlim &= (Q[:, i] >= lo) & (Q[:, i] <= hi)
    for P, ok in chart.point_fk(Q):
        ok = ok & inlim
        idx = np.flatnonzero(ok)
        if len(idx) == 0:
            continue
        V = np.hstack([Q[idx], P[idx]])
        _, B = sys.aux_many(V.T)
        S = np.sign(B.T).astype(int)
        for a in out:
            sel = np.all(S == np.array(a.working_mode), axis=1)
            if not sel.any():
                continue
            ins = a.face.contains(P[idx[sel]])
            a.qa_mask[idx[sel][ins]] = True
    for a in out:
        a.qa_mask = a.qa_mask.reshape(n, n)
        a.qa_area = float(a.qa_mask.sum() * cell)
    return g0, g1


def union_area(groups: list[list[Face]], eps: float, snap: float) -> tuple[float, list[Face]]:
    """Area and faces of the union of regions (lists of faces).

    The rings of every face (outer counter-clockwise, holes clockwise) are arranged
    together; a copy of a boundary already given by an earlier region (the same arc with
    the region on the same side, within ``eps``) is dropped first, and the pieces left are
    snapped together (``snap``). The faces of the arrangement inside some region make up
    the union.
    """
    allf = [f for g in groups for f in g]
    lines: list[tuple[np.ndarray, bool]] = []
    for gi, g in enumerate(groups):
        earlier = [f for gj in range(gi) for f in groups[gj]]
        for f in g:
            for R in [f.outer] + list(f.holes):
                Rn = np.roll(R, -1, axis=0)
                d = Rn - R
                ln = np.maximum(np.linalg.norm(d, axis=1), 1e-300)
                nr = np.stack([d[:, 1], -d[:, 0]], 1) / ln[:, None]
                mid = 0.5 * (R + Rn)
                keep = np.ones(len(R), dtype=bool)
                for h in earlier:
                    dup = h.contains(mid - eps * nr) & ~h.contains(mid + 3 * eps * nr)
                    if dup.any():
                        keep &= ~(dup & (_ring_dist(mid, h) < eps))
                if keep.all():
                    lines.append((R, True))
                    continue
                if not keep.any():
                    continue
                k0 = int(np.flatnonzero(~keep)[0])
                order = np.roll(np.arange(len(R)), -k0)
                kk = keep[order]
                cuts = np.flatnonzero(np.diff(kk.astype(int)) != 0) + 1
                for part, pk in zip(np.split(order, cuts), np.split(kk, cuts)):
                    if pk[0]:
                        pts = np.vstack([R[part], Rn[part[-1:]]])
                        lines.append((pts, False))
    out = []
    for f in faces(lines, snap=snap):
        if f.point is not None and any(h.contains(f.point[None])[0] for h in allf):
            out.append(f)
    return float(sum(f.area for f in out)), out


def _ring_dist(P: np.ndarray, f: Face) -> np.ndarray:
    from .planar import _seg_dist

    rings = [f.outer] + list(f.holes)
    A = np.vstack(rings)
    B = np.vstack([np.roll(r, -1, axis=0) for r in rings])
    return _seg_dist(P, A, B)


def workspace(
    mech: Mechanism,
    fixed: Mapping[str, float] | None = None,
    **options: Any,
) -> Workspace:
    """The reachable workspace in the plane, per working mode and in total.

    Its boundary is made of serial singular curves (B_jj = 0) and joint-limit curves,
    traced by continuation; the regions are the faces of their arrangement that the
    working mode reaches, with polygon areas (Chablat & Wenger 1998, Figs. 9-12).

    Parameters
    ----------
    mech : Mechanism
        As for :func:`aspects`.
    fixed : dict, optional
        As for :func:`aspects`.
    **options
        The options below, by keyword, over :data:`ASPECTS_DEFAULTS` (an unknown name is a
        :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    limits, bounds, grid, qa_grid, step
        As for :func:`aspects` (``qa_grid``: the joint-space images of the working modes,
        two-leg point platforms).

    Returns
    -------
    Workspace
        ``regions`` and ``areas`` per working mode, ``total`` (faces) and ``area`` of the
        union, success/status/message.

    Memory and time: as for :func:`aspects` (``qa_grid``, ``grid`` and the traced points are
    checked against the budget of :mod:`optkin.limits`; a budget that stops the curves
    leaves no regions and ``success`` False).

    Examples
    --------
    Two annuli 3 <= r <= 13 about A and B, ``|AB|`` = 9 (exactly 245.1414):

    >>> import optkin
    >>> round(optkin.workspace(optkin.mechanisms.five_bar(9, 8, 5, 5, 8)).area, 1)
    245.1
    """
    t0 = time.perf_counter()
    from ..solvers.common import merge_options

    o = merge_options(ASPECTS_DEFAULTS, options, "workspace")
    limits, bounds, grid, qa_grid, step = (o["limits"], o["bounds"], o["grid"],
                                           o["qa_grid"], o["step"])
    fixed, names, chart = _check_plane(mech, fixed)
    qa_grid = check_number(qa_grid, "workspace: option qa_grid", integer=True, lo=2)
    lim_map = _limit_map(mech, names, limits)
    model = get_model(mech)
    qa_cost = _qa_grid_cost(chart, "workspace", qa_grid)
    kinds = ["serial"] + (["limit"] if lim_map else [])
    has_serial = any(len(s_) == 2 for s_ in model.working_mode_signs)
    if not has_serial and not lim_map:
        kinds = ["parallel"]  # only the box bounds the region; parallel curves unused
    curves = _singular_curves(mech, "workspace", kinds, fixed, bounds, grid, limits, step,
                              1e-11, None, False, None, "workspace", _region_cost(model),
                              qa_cost)
    modes = leg_working_modes(mech)
    if curves.status in _STOPPED:  # incomplete curves bound no regions
        return Workspace(mechanism=mech.name, plane=curves.plane, working_modes=modes,
                         regions={m: [] for m in modes}, areas={m: 0.0 for m in modes},
                         total=[], area=0.0, curves=curves, success=False,
                         status=curves.status, message=f"no workspace: {curves.message}",
                         time=time.perf_counter() - t0, qa_names=tuple(mech.active_names))
    pidx = curves.info["plane_index"]
    fixed_map = {names.index(k): float(v) for k, v in fixed.items()}
    snap = 3.0 * float(step or DEFAULT_STEP) * model.length
    regions, areas = {}, {}
    for mode in modes:
        reg = _region_faces(chart, curves, mode, curves.bounds, snap, pidx, fixed_map, lim_map,
                            False)
        regions[mode] = [f for f, _, _ in reg]
        areas[mode] = float(sum(f.area for f in regions[mode]))
    area, total = union_area([regions[m] for m in modes], 0.01 * model.length, snap)
    qmasks, qgrid = None, None
    if chart.two_leg_point:
        qmasks, qgrid = _mode_qa_masks(chart, regions, qa_grid, lim_map)
    ok = (curves.success or not has_serial) and curves.status not in _STOPPED
    return Workspace(mechanism=mech.name, plane=curves.plane, working_modes=modes,
                     regions=regions, areas=areas, total=total, area=area, curves=curves,
                     success=bool(ok), status=OPTIMAL if ok else _failed_status(curves),
                     message=f"workspace area {area:.6g}; per mode "
                             f"{[round(areas[m], 6) for m in modes]}",
                     time=time.perf_counter() - t0, qa_masks=qmasks, qa_grid=qgrid,
                     qa_names=tuple(mech.active_names))


def _mode_qa_masks(chart: PlanarChart, regions, n, lim_map):
    """The joint-space image of each working mode's region (closed-form direct kinematics
    of a two-leg point platform), on an n x n grid of q_a."""
    mech = chart.model.mech
    r0, r1 = chart.actuator_range(0), chart.actuator_range(1)
    g0 = np.linspace(*r0, n, endpoint=False) + 0.5 * (r0[1] - r0[0]) / n
    g1 = np.linspace(*r1, n, endpoint=False) + 0.5 * (r1[1] - r1[0]) / n
    G0, G1 = np.meshgrid(g0, g1, indexing="ij")
    Q = np.stack([G0.ravel(), G1.ravel()], 1)
    inlim = np.ones(len(Q), dtype=bool)
    for i, (lo, hi) in lim_map.items():
        inlim &= (Q[:, i] >= lo) & (Q[:, i] <= hi)
    sys = augmented_system(mech, "parallel", ())
    masks = {m: np.zeros(len(Q), dtype=bool) for m in regions}
    for P, ok in chart.point_fk(Q):
        idx = np.flatnonzero(ok & inlim)
        if len(idx) == 0:
            continue
        _, B = sys.aux_many(np.hstack([Q[idx], P[idx]]).T)
        S = np.sign(B.T).astype(int)
        for m, faces_m in regions.items():
            sel = np.all(S == np.array(m), axis=1)
            for f in faces_m:
                ins = f.contains(P[idx[sel]])
                masks[m][idx[sel][ins]] = True
    return {m: v.reshape(n, n) for m, v in masks.items()}, (g0, g1)


# ---------------------------------------------------------------------------------------
# budgets
# ---------------------------------------------------------------------------------------

#: Statuses of curves stopped by a budget (time or memory): the regions are incomplete.
_STOPPED = LIMIT_REACHED
# Measured memory (peak resident growth, VmHWM, of a fresh process). Per traced point of
# the curves, beyond what singular_curves keeps: the polylines cut per working mode and
# the planar arrangement of each (segments, split lists, vertices, half-edges, faces):
# _REGION_POINT bytes. Per cell of the joint-space masks (qa_grid^2 cells): the grid,
# the closed-form direct kinematics of both assembly modes, the B labels, and a mask per
# aspect or working mode: a + b * (number of masks) bytes.
_REGION_POINT = 1500.0
_COST_QA_CELL = (400.0, 1.0)
#: Masks counted per working mode for the joint-space images (aspects per mode).
_MASKS_PER_MODE = 8


def _region_cost(model: Any) -> float:
    """Bytes per traced point for aspects and workspace (curves and arrangements)."""
    return _point_cost(model) + _REGION_POINT


def _qa_grid_cost(chart: PlanarChart, where: str, n: int) -> float:
    """Check ``qa_grid`` against the memory budget, with room for a seeding chart of the
    default size and MIN_POINTS traced points (``grid`` is checked next, with the masks
    reserved); the bytes it reserves (with SAFETY)."""
    if not chart.two_leg_point:
        return 0.0  # no joint-space masks for this mechanism
    model = chart.model
    rest = SAFETY * (_cell_cost(model) * 32.0**2 + _region_cost(model) * MIN_POINTS)
    a, b = _COST_QA_CELL
    per = a + b * _MASKS_PER_MODE * len(model.working_modes())
    check_size(where, "qa_grid", n, per, power=2, lo=2, fixed=rest,
               unit="one cell of the joint-space masks")
    return SAFETY * per * n * n


def _failed_status(curves: SingularCurves) -> str:
    return curves.status if curves.status in _STOPPED else INACCURATE


# ---------------------------------------------------------------------------------------
# pictures (matplotlib)
# ---------------------------------------------------------------------------------------


def _fig(nr, nc, w=4.0, h=4.0, path=None, fig=None):
    """A grid of nr x nc Axes: in ``fig`` when given (it must be empty), else in a new
    Figure of (w nc, h nr) inches with constrained layout."""
    if fig is not None:
        if not hasattr(fig, "subplots") or fig.axes:
            raise MechanismError("fig: expected an empty matplotlib Figure (e.g. "
                                 "plt.figure(layout='constrained')) to draw the panels into")
        return fig, fig.subplots(nr, nc, squeeze=False)
    from ..plot import _figure

    fig = _figure(path, (w * nc, h * nr), "constrained")
    return fig, fig.subplots(nr, nc, squeeze=False)


def _axes(ax, figsize, three_d: bool = False, path=None):
    """(figure, axes, whether they are new): ``ax`` itself when given, else a new figure
    of ``figsize`` with one (3-D) axes (kept out of pyplot when it goes to ``path``)."""
    if ax is not None:
        return ax.figure, ax, False
    from ..plot import _figure

    fig = _figure(path, figsize)
    return fig, fig.add_subplot(projection="3d" if three_d else None), True


def _mode_str(mode: tuple[int, ...]) -> str:
    """A working mode as the signs of its legs' B_kk, e.g. (+, -)."""
    return "(" + ", ".join("+" if m > 0 else "-" for m in mode) + ")"


def _joint_label(name: str) -> str:
    """A joint's axis label for people: ``L1.theta1`` -> "$\\theta_{1}$ of leg 1 (rad)" (Greek
    names as symbols); lengths (rho, d, r) without a unit (the mechanism's own); other
    names as they are."""
    import re

    m = re.fullmatch(r"L(\d+)\.([A-Za-z]+)(\d*)", name)
    if m is None:
        return name
    leg, kind, k = m.groups()
    unit = " (rad)" if kind in ("theta", "th", "q", "phi", "alpha") else ""
    greek = {"theta": "theta", "th": "theta", "phi": "phi", "alpha": "alpha", "rho": "rho"}
    sym = f"$\\{greek[kind]}" if kind in greek else f"${kind}"
    sym += f"_{{{k}}}$" if k else "$"
    return f"{sym} of leg {leg}{unit}"


def _face_patch(f: Face, **kw):
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path

    verts, codes = [], []
    for R in [f.outer] + list(f.holes):
        verts += list(R) + [R[0]]
        codes += [Path.MOVETO] + [Path.LINETO] * (len(R) - 1) + [Path.CLOSEPOLY]
    return PathPatch(Path(np.array(verts), codes), **kw)


def _save(fig, path):
    """Write ``fig`` to ``path`` (when given) at :data:`optkin.plot.DPI`; returns it."""
    if path is not None:
        from ..plot import DPI

        fig.savefig(path, dpi=DPI, bbox_inches="tight")
        import matplotlib.pyplot as plt

        plt.close(fig)  # (a no-op for the figures _figure keeps out of pyplot)
    return fig


_COLORS = {"parallel": "tab:red", "serial": "tab:blue", "limit": "tab:green",
           "closure": "black"}


def _plot_curves(res: SingularCurves, path=None, ax=None, title=None):
    if ax is None:
        fig, axs = _fig(1, 1, 6, 6, path)
        ax = axs[0, 0]
    else:
        fig = ax.figure
    for c in res.curves:
        col = _COLORS.get(c.kind.split(":")[0], "k")
        for P in _split_wrapped(np.vstack([c.points, c.points[:1]]) if c.closed else c.points,
                                res.periodic):
            ax.plot(P[:, 0], P[:, 1], color=col, lw=1.0)
    if len(res.branch_points):
        B = res.plane_points(res.branch_points)
        ax.plot(B[:, 0], B[:, 1], "ko", ms=4, label="branch points")
    act = res.info.get("actuator_singularities")
    if act is not None and len(act):
        B = res.plane_points(act)
        ax.plot(B[:, 0], B[:, 1], "gs", ms=5, mfc="none", label="det W_p = 0")
    if len(res.cusps):
        B = res.plane_points(res.cusps)
        ax.plot(B[:, 0], B[:, 1], "m^", ms=6, label="cusps")
    ax.set_xlabel(res.plane[0])
    ax.set_ylabel(res.plane[1])
    kinds = sorted({c.kind.split(":")[0] for c in res.curves})
    for k in kinds:
        ax.plot([], [], color=_COLORS.get(k, "k"), label=k)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(title or f"{res.mechanism}: singular curves ({', '.join(kinds)})", fontsize=10)
    ax.set_xlim(*res.bounds[0])
    ax.set_ylim(*res.bounds[1])
    if not any(res.periodic):
        ax.set_aspect("equal")
    return _save(fig, path)


def _plot_aspects(res: Aspects, path=None, title=None, fig=None):
    import matplotlib.pyplot as plt

    modes = res.working_modes
    rows = 2 if res.qa_grid is not None else 1
    fig, axs = _fig(rows, len(modes), 3.6, 4.2 if rows == 1 else 4.0, path, fig)
    cmap = plt.get_cmap("tab10")
    for j, mode in enumerate(modes):
        ax = axs[0, j]
        for k, a in enumerate(res.of_mode(mode)):
            ax.add_patch(_face_patch(a.face, facecolor=cmap(k % 10), alpha=0.55,
                                     edgecolor="k", lw=0.6,
                                     label=f"aspect {k + 1} (det A {'+' if a.det_sign > 0 else '-'}"
                                           f"): area {a.area:.3g}"))
            ax.plot(*a.x[:2], "k.", ms=3)
        first = True
        for c in res.curves.curves:
            if c.kind.startswith("parallel"):
                sel = np.all(np.sign(c.B) == np.array(mode), axis=1)
                P = np.where(sel[:, None], c.points, np.nan)
                ax.plot(P[:, 0], P[:, 1], color="tab:red", lw=0.8,
                        label="parallel singularity" if first and sel.any() else None)
                first = first and not sel.any()
        if res.of_mode(mode):  # below the panel: it would hide part of a region
            ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16),
                      frameon=False)
        ax.set_xlim(*res.curves.bounds[0])
        ax.set_ylim(*res.curves.bounds[1])
        ax.set_aspect("equal")
        ax.set_title(f"working mode {_mode_str(mode)}: {len(res.of_mode(mode))} aspect(s)",
                     fontsize=10)
        ax.set_xlabel(res.plane[0])
        ax.set_ylabel(res.plane[1])
        if rows == 2:
            ax2 = axs[1, j]
            g0, g1 = res.qa_grid
            for k, a in enumerate(res.of_mode(mode)):
                M = np.ma.masked_where(~a.qa_mask.T, np.full(a.qa_mask.T.shape, k % 10))
                ax2.pcolormesh(g0, g1, M, cmap=cmap, vmin=0, vmax=9.99, alpha=0.6,
                               shading="nearest", rasterized=True)
            ax2.set_xlabel(_joint_label(res.qa_names[0]))
            ax2.set_ylabel(_joint_label(res.qa_names[1]))
            ax2.set_title("serial aspects QA (joint space)", fontsize=10)
    fig.suptitle(title or f"{res.mechanism}: generalized aspects per working mode", fontsize=12)
    return _save(fig, path)


def _plot_workspace(res: Workspace, path=None, title=None, fig=None):
    import matplotlib.pyplot as plt

    modes = res.working_modes
    rows = 2 if res.qa_masks is not None else 1
    fig, axs = _fig(rows, len(modes) + 1, 3.6, 3.6, path, fig)
    cmap = plt.get_cmap("tab10")
    for j, mode in enumerate(modes):
        ax = axs[0, j]
        for f in res.regions[mode]:
            ax.add_patch(_face_patch(f, facecolor=cmap(j % 10), alpha=0.5, edgecolor="k", lw=0.6))
        ax.set_title(f"working mode {_mode_str(mode)}: area {res.areas[mode]:.4g}",
                     fontsize=10)
        if rows == 2:
            ax2 = axs[1, j]
            g0, g1 = res.qa_grid
            M = np.ma.masked_where(~res.qa_masks[mode].T, np.full(res.qa_masks[mode].T.shape, j))
            ax2.pcolormesh(g0, g1, M, cmap=cmap, vmin=0, vmax=9.99, alpha=0.6, shading="nearest",
                           rasterized=True)
            ax2.set_xlabel(_joint_label(res.qa_names[0]))
            ax2.set_ylabel(_joint_label(res.qa_names[1]))
            ax2.set_title(f"working mode {_mode_str(mode)} in the joint space", fontsize=10)
    if rows == 2:
        axs[1, -1].axis("off")
    ax = axs[0, -1]
    for f in res.total:
        ax.add_patch(_face_patch(f, facecolor="0.6", alpha=0.6, edgecolor="k", lw=0.6))
    ax.set_title(f"workspace: area {res.area:.4g}", fontsize=10)
    for ax in axs[0]:
        ax.set_xlim(*res.curves.bounds[0])
        ax.set_ylim(*res.curves.bounds[1])
        ax.set_aspect("equal")
        ax.set_xlabel(res.plane[0])
        ax.set_ylabel(res.plane[1])
    fig.suptitle(title or f"{res.mechanism}: workspace per working mode", fontsize=12)
    return _save(fig, path)
