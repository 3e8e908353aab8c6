"""Singularity surfaces of 3-DoF platforms as triangulated meshes.

The parallel singularities (det W_p = det A = 0) of a 3-DoF planar platform form a surface
in the task space (x, y, phi) and, mapped through the closure, in the joint space; those of
a translational spatial platform (the Delta) or of a platform that translates in an
operation mode (Tsai's 3-UPU, through the mode's chart of
:mod:`optkin.analysis.fixed_orientation`) a surface in (x, y, z). It is
traced here section by section: the curves of :func:`optkin.singular_curves` at
``slices`` values of the third coordinate (phi for ``space="task"``, z for a translational
platform, the first actuated joint for ``space="joint"``), every point a corrected point
of the augmented system
[Phi; det W_p] (residual about 1e-11), then consecutive sections' curves are stitched
into triangle strips: each curve is paired with the nearest curve of the next section
(mean distance of its points, below ``link`` times the mechanism's size), closed curves
are turned to start at matching points and to run the same way, and the strip takes at
each step the shorter diagonal. A curve with no partner (where the section's topology
changes between two slices) leaves an open edge, counted in ``open_curves``. Points
outside the actuator strokes ``limits`` are left out.

So the vertices are exact (on the surface to the corrector's tolerance) and the
triangles interpolate between sections; the topology-changing sections are not yet
located exactly (see the issue tracker).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model
from ..results import INACCURATE, OPTIMAL, TIME_LIMIT, jsonable

__all__ = ["SingularSurface", "singular_surfaces", "SINGULAR_SURFACES_DEFAULTS"]

#: Options of :func:`singular_surfaces` and their defaults.
SINGULAR_SURFACES_DEFAULTS: dict[str, Any] = {
    "limits": None,  # actuator strokes, dict name -> (lo, hi): vertices outside are left out
    "bounds": None,  # box [[lo, hi], [lo, hi]] of the sections' plane (None: singular_curves')
    "slices": 72,  # sections (>= 2)
    "step": 0.25,  # largest continuation step in each section (scaled units, > 0)
    "link": 0.6,  # largest mean distance between stitched curves, in mechanism sizes (> 0)
    "range": None,  # (lo, hi) of the sectioning coordinate (None: its whole range)
    "time_limit": 300.0,  # seconds (capped by the time budget); later sections left out
}


@dataclass
class SingularSurface:
    """A triangulated singularity surface (see :func:`singular_surfaces`).

    Attributes
    ----------
    vertices : ndarray (V, 3)
        Points of the surface in the space's three coordinates ``names``.
    v : ndarray (V, na + nx)
        The full configuration (q_a then x) at each vertex.
    triangles : ndarray (T, 3) of int
        Vertex indices.
    residual : ndarray (V,)
        max ``|[Phi; det W_p]|`` at each vertex (from the continuation's corrector).
    sections : ndarray
        The values of the third coordinate the curves were traced at.
    open_curves : int
        Curves left unstitched on one side (topology changes between sections).
    planes : list of float
        Values of the third coordinate whose whole section is singular (det A vanishes
        identically there, e.g. phi = 0 for a 3-RPR whose platform is a scaled copy of its
        base); each is meshed as a planar patch over the section's points within the
        strokes (a grid of the plane: every point of it is on the surface).
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``; ``"inaccurate"`` when a
        section failed or no triangle was made; ``"time_limit"`` when sections were left
        out at the time limit.
    """

    mechanism: str
    space: str
    names: tuple[str, str, str]
    vertices: np.ndarray
    v: np.ndarray
    triangles: np.ndarray
    residual: np.ndarray
    sections: np.ndarray
    open_curves: int
    success: bool
    status: str
    message: str
    time: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    planes: list[float] = field(default_factory=list)

    def __repr__(self) -> str:
        return (f"SingularSurface({self.mechanism!r}, {self.space}, {len(self.vertices)} "
                f"vertices, {len(self.triangles)} triangles, status={self.status!r})")

    @property
    def max_residual(self) -> float:
        return float(self.residual.max(initial=0.0))

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({
            "mechanism": self.mechanism, "space": self.space, "names": list(self.names),
            "success": self.success, "status": self.status, "message": self.message,
            "n_vertices": int(len(self.vertices)), "n_triangles": int(len(self.triangles)),
            "max_residual": self.max_residual, "open_curves": self.open_curves,
            "n_sections": int(len(self.sections)), "time": self.time,
            "planes": [float(v) for v in self.planes]})

    def plot(self, path: str | None = None, ax: Any = None, title: str | None = None,
             color: Any = None) -> Any:
        """The surface (matplotlib ``plot_trisurf``), coloured by the third coordinate."""
        from .aspects import _axes, _check_path, _save

        _check_path(path)
        fig, ax, own = _axes(ax, (7.5, 6.5), three_d=True, path=path)
        V, T = self.vertices, self.triangles
        if len(T):
            kw = {"color": color} if color is not None else {"cmap": "viridis"}
            ax.plot_trisurf(V[:, 0], V[:, 1], V[:, 2], triangles=T, linewidth=0.1,
                            edgecolor="0.3", alpha=0.85, **kw)
        ax.set_xlabel(self.names[0])
        ax.set_ylabel(self.names[1])
        ax.set_zlabel(self.names[2])
        ax.set_title(title or f"{self.mechanism}: parallel singularity surface "
                     f"({self.space} space)")
        if own and path is not None:
            _save(fig, path)
        return fig


def _strip(A: np.ndarray, B: np.ndarray, ia: np.ndarray, ib: np.ndarray,
           longest: float = np.inf) -> list[tuple]:
    """Triangles between polylines A and B (point arrays, same orientation), choosing the
    shorter diagonal at every step; ia, ib their vertex indices. A triangle with an edge
    across the strip longer than ``longest`` is left out: where one curve runs on past the
    other (a piece ending at a branch point or a stroke), the strip would otherwise fan
    from its last point across the section."""
    tri = []
    i = j = 0
    na, nb = len(A), len(B)
    far = longest * longest
    while i < na - 1 or j < nb - 1:
        if i == na - 1 or (j < nb - 1 and np.sum((A[i] - B[j + 1]) ** 2)
                           <= np.sum((A[i + 1] - B[j]) ** 2)):
            t, d = (ia[i], ib[j], ib[j + 1]), max(np.sum((A[i] - B[j]) ** 2),
                                                  np.sum((A[i] - B[j + 1]) ** 2))
            j += 1
        else:
            t, d = (ia[i], ib[j], ia[i + 1]), max(np.sum((A[i] - B[j]) ** 2),
                                                  np.sum((A[i + 1] - B[j]) ** 2))
            i += 1
        if d <= far:
            tri.append(t)
    return tri


def singular_surfaces(mech: Mechanism, space: str = "task",
                      **options: Any) -> SingularSurface:
    """The parallel singularity surface of a 3-DoF planar or translational platform as a
    triangle mesh (see the module docstring).

    Parameters
    ----------
    mech : Mechanism
        A 3-DoF planar platform with distance legs, a translational spatial platform
        whose legs are distance legs with closed-form inverses (the Delta), or a spatial
        platform with three actuators that translates in an operation mode with the
        identity orientation (Tsai's 3-UPU: sections of that mode's chart, see
        :mod:`optkin.analysis.fixed_orientation`; ``bounds`` default to +-2 mechanism
        sizes, ``range`` to z in (0.1, 2) sizes; the mode is entered by
        :func:`optkin.inverse` at the first section's centre).
    space : "task" or "joint"
        (x, y, phi), sections at fixed phi over [-pi, pi) (a translational platform:
        (x, y, z), sections at fixed z over the legs' reach); or the actuated joints,
        sections at fixed first actuated joint over its stroke (``limits``) or its range
        (planar platforms).
    **options
        The options below, by keyword, over :data:`SINGULAR_SURFACES_DEFAULTS` (an unknown
        name raises :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    limits : dict name -> (lo, hi), optional
        Actuator strokes: vertices outside them are left out.
    bounds : [[lo, hi], [lo, hi]], optional
        The box of the sections' plane.
    slices : int
        Sections.
    step : float
        Largest continuation step in each section (scaled units).
    link : float
        Largest mean distance between stitched curves, in mechanism sizes.
    range : (lo, hi), optional
        The sections' span of the third coordinate (default: phi's turn, z's reach, the
        first actuator's stroke).
    time_limit : float
        Seconds (capped by the time budget); the sections not reached are left out and
        the result says so (status ``"time_limit"``).

    Returns
    -------
    SingularSurface
    """
    from .._checks import check_mechanism, check_option
    from ..limits import Deadline, time_budget
    from ..model.charts import translational_chart
    from ..solvers.common import merge_options
    from .aspects import _first_range, _limit_map
    from .continuation import _names_of, singular_curves

    t0 = time.perf_counter()
    who = "singular_surfaces"
    opts = merge_options(SINGULAR_SURFACES_DEFAULTS, options, who)

    def num(name: str, **kw: Any) -> Any:
        return check_option(opts, name, who, SINGULAR_SURFACES_DEFAULTS, **kw)

    limits, bounds = opts["limits"], opts["bounds"]
    deadline = Deadline(min(num("time_limit", lo=0.0, lo_open=True), time_budget()))
    step = num("step", lo=0.0, lo_open=True)
    link = num("link", lo=0.0, lo_open=True)
    if space not in ("task", "joint"):
        raise MechanismError(f"{who}: space must be 'task' or 'joint', got "
                             f"{space!r}")
    slices = num("slices", integer=True, lo=2)
    check_mechanism(mech, who)
    span = opts["range"]
    if span is not None:
        span = _span(span, who)
    model = get_model(mech)
    turn = [n for n, a in zip(model.x_names, model.x_angle) if a]
    tchart = None if turn else translational_chart(model)
    spatial = tchart is not None
    # a spatial platform with passive joints among its unknowns (Tsai's 3-UPU): sections of
    # its translational mode through the chart p -> configuration
    kept = (not spatial and model.na == 3 and model.platform is not None
            and model.platform.space_dim == 3 and model.nx > 3)
    if (spatial or kept) and space != "task":
        raise MechanismError(f"singular_surfaces: {mech.name} translates in space: its "
                             "surface is traced in the task space (x, y, z); use "
                             "space='task'")
    if kept:
        return _kept_orientation(mech, model, opts["limits"], bounds, int(slices),
                                 float(step), float(link), deadline, t0, span)
    if model.na != 3 or model.nx != 3 or (len(turn) != 1 and not spatial):
        raise MechanismError(f"singular_surfaces: {mech.name} is not a 3-DoF planar "
                             "platform (three actuators; unknowns x, y and one orientation) "
                             "nor a translational one with distance legs (unknowns x, y, z)")
    names_all = _names_of(mech)
    lim = _limit_map(mech, names_all, limits)
    na = model.na
    if space == "task" and spatial:
        third = model.x_names[2]
        lo, hi = span if span is not None else tchart.reach_box()[2]
        values = np.linspace(lo, hi, int(slices) + 2)[1:-1]
        plane, cols = "workspace", [na, na + 1, na + 2]
        names = (model.x_names[0], model.x_names[1], third)
    elif space == "task":
        third = turn[0]
        values = (np.linspace(-np.pi, np.pi, int(slices), endpoint=False) if span is None
                  else np.linspace(span[0], span[1], int(slices)))
        plane, cols = "workspace", [na, na + 1, na + 2]
        names = (model.x_names[0], model.x_names[1], third)
    else:
        third = names_all[0]
        lo, hi = span if span is not None else _first_range(who, model, names_all, lim)
        values = np.linspace(lo, hi, int(slices) + 2)[1:-1]
        # the section plane (the other two actuated joints), then the sectioning joint
        plane, cols = "joint", [1, 2, 0]
        names = (names_all[1], names_all[2], names_all[0])
    secs: list[list[tuple[np.ndarray, np.ndarray, bool, np.ndarray]]] = []
    failed = []
    late = False
    planes: list[float] = []
    patches: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
    for val in values:
        if deadline.expired():
            late = True
            secs.append([])
            continue
        if space == "task" and not spatial:
            patch = _whole_section(mech, model, float(val), bounds, lim)
            if patch is not None:
                planes.append(float(val))
                patches.append(patch)
                secs.append([])
                continue
        c = singular_curves(mech, plane=plane, kind="parallel", fixed={third: float(val)},
                            bounds=bounds, step=step, cusps=False)
        if not c.success:
            failed.append((float(val), c.message))
        secs.append(_pieces(c.curves, lim, cols))
    return _mesh(mech, model, space, names, values, secs, failed, late, planes, patches,
                 link, t0)


def _kept_orientation(mech: Mechanism, model: Any, limits: Any, bounds: Any, slices: int,
                      step: float, link: float, deadline: Any, t0: float,
                      span: tuple[float, float] | None) -> SingularSurface:
    """singular_surfaces of a spatial platform that translates in an operation mode (its
    orientation kept at the identity; the sections of
    :mod:`optkin.analysis.fixed_orientation`); the options already checked."""
    from .aspects import _limit_map
    from .continuation import _bounds_arg, _names_of
    from .fixed_orientation import fixed_orientation, section_curves

    who = "singular_surfaces"
    L = float(model.length)
    lim = _limit_map(mech, _names_of(mech), limits)
    box = (np.array([[-2 * L, 2 * L], [-2 * L, 2 * L]]) if bounds is None
           else _bounds_arg(bounds, "workspace"))
    lo, hi = span if span is not None else (0.1 * L, 2 * L)
    values = np.linspace(lo, hi, slices + 2)[1:-1]
    na = model.na
    names = tuple(model.x_names[:3])
    # the mode's chart, entered at the first section's centre with the identity orientation
    from ..solvers.inverse import inverse

    T = np.eye(4)
    T[:2, 3] = box.mean(axis=1)
    T[2, 3] = values[0]
    sols = inverse(mech, T)
    if not len(sols):
        raise MechanismError(
            f"{who}: {mech.name} has no configuration with its platform at "
            f"{T[:3, 3].tolist()} and the identity orientation (inverse: {sols.message}); "
            "give bounds and range around a reachable position")
    v = np.r_[sols[0].qa, sols[0].x]
    ch = fixed_orientation(mech, model, v)
    secs: list[list[tuple]] = []
    failed: list[tuple[float, str]] = []
    late = False
    for val in values:
        if deadline.expired():
            late = True
            secs.append([])
            continue
        curves, v_next = section_curves(ch, float(val), v, box, hmax=step)
        if v_next is None:
            failed.append((float(val), f"the mode's chart did not reach the section at "
                                       f"{names[2]} = {val:.6g}"))
            secs.append([])
            continue
        v = v_next
        secs.append(_pieces(curves, lim, [na, na + 1, na + 2]))
    return _mesh(mech, model, "task", names, values, secs, failed, late, [], [], link, t0)


def _pieces(curves: Any, lim: dict, cols: list[int]) -> list[tuple]:
    """The runs of traced curves (each with ``v``, ``closed``, ``residual`` and
    ``working_mode``) within the strokes ``lim`` and in one working mode, as (points in the
    surface's coordinates, configurations, closed, residual, working mode)."""
    pieces = []
    for cv in curves:
        keep = np.ones(len(cv.v), dtype=bool)
        for j, (a, b) in lim.items():
            keep &= (cv.v[:, j] >= a) & (cv.v[:, j] <= b)
        wm = None if cv.working_mode is None else np.asarray(cv.working_mode, dtype=int)
        # the runs within the strokes and in one working mode (a curve through a serial
        # singularity, as a Delta's do, passes from one sheet of the surface to another)
        change = np.zeros(len(cv.v), dtype=bool)
        if wm is not None and len(wm) > 1:
            change[1:] = np.any(wm[1:] != wm[:-1], axis=1)
        if keep.all() and not change.any():
            pieces.append((cv.v[:, cols], cv.v, cv.closed, cv.residual,
                           None if wm is None else tuple(wm[0].tolist())))
            continue
        start = 0
        for k in range(1, len(cv.v) + 1):
            if k < len(cv.v) and keep[k] and keep[k - 1] and not change[k]:
                continue
            if keep[start] and k - start >= 2:
                pieces.append((cv.v[start:k][:, cols], cv.v[start:k], False,
                               cv.residual[start:k],
                               None if wm is None else tuple(wm[start].tolist())))
            start = k
    return pieces


def _mesh(mech: Mechanism, model: Any, space: str, names: tuple, values: np.ndarray,
          secs: list, failed: list, late: bool, planes: list, patches: list, link: float,
          t0: float) -> SingularSurface:
    """The sections' pieces stitched into one mesh (see the module docstring)."""
    na = model.na
    L = float(model.length)
    # vertices
    verts, full, res, index = [], [], [], []
    n = 0
    for pieces in secs:
        idx = []
        for P, V, _, r, _ in pieces:
            verts.append(P)
            full.append(V)
            res.append(r)
            idx.append(np.arange(n, n + len(P)))
            n += len(P)
        index.append(idx)
    tri: list[tuple] = []
    open_curves = 0
    # consecutive sections (not the last back to the first in phi: that strip would
    # cross the picture from pi to -pi)
    for ka, kb in [(k, k + 1) for k in range(len(secs) - 1)]:
        used = set()
        for ia, (A, _, ca_, _, ma) in enumerate(secs[ka]):
            best, bj = np.inf, None
            for jb, (B, _, cb_, _, mb) in enumerate(secs[kb]):  # (one sheet: same mode)
                if jb in used or ca_ != cb_ or (ma is not None and mb is not None
                                                and ma != mb):
                    continue
                d = np.sqrt(((A[:, None, :2] - B[None, :, :2]) ** 2).sum(-1)).min(axis=1)
                dm = float(np.mean(d)) / L
                if dm < best:
                    best, bj = dm, jb
            if bj is None or best > link:
                open_curves += 1
                continue
            used.add(bj)
            B = secs[kb][bj][0]
            Ia, Ib = index[ka][ia], index[kb][bj]
            a2, b2 = A[:, :2] / L, B[:, :2] / L
            if ca_:  # closed: start B at the point nearest A's start, run the same way
                s0 = int(np.argmin(((b2 - a2[0]) ** 2).sum(1)))
                order = np.roll(np.arange(len(B)), -s0)
                fwd = b2[order[min(1, len(order) - 1)]] - b2[order[0]]
                if np.dot(a2[min(1, len(a2) - 1)] - a2[0], fwd) < 0:
                    order = np.r_[order[0], order[1:][::-1]]
                Ib = Ib[order]
                b2 = b2[order]
                a2 = np.vstack([a2, a2[:1]])
                b2 = np.vstack([b2, b2[:1]])
                Ia = np.r_[Ia, Ia[:1]]
                Ib = np.r_[Ib, Ib[:1]]
            elif np.sum((a2[0] - b2[0]) ** 2) > np.sum((a2[0] - b2[-1]) ** 2):
                b2, Ib = b2[::-1], Ib[::-1]
            tri += _strip(a2, b2, Ia, Ib, longest=link)
        open_curves += len(secs[kb]) - len(used)
    for P, Vfull, r, Tp in patches:        # planar patches of wholly singular sections
        verts.append(P)
        full.append(Vfull)
        res.append(r)
        tri += [tuple(t_) for t_ in (Tp + n)]
        n += len(P)
    V = np.vstack(verts) if verts else np.zeros((0, 3))
    Vf = np.vstack(full) if full else np.zeros((0, na + model.nx))
    R = np.concatenate(res) if res else np.zeros(0)
    T = np.array(tri, dtype=int).reshape(-1, 3)
    ok = not failed and not late and len(T) > 0
    msg = (f"{len(V)} vertices, {len(T)} triangles from {len(values)} sections in the "
           f"{space} space; max residual {R.max(initial=0.0):.1e}; {open_curves} curve(s) "
           "left open where the sections' topology changes"
           + (f"; {len(failed)} section(s) incomplete: {failed[0][1]}" if failed else "")
           + ("; stopped at the time limit: later sections left out" if late else "")
           + (f"; wholly singular section(s) at {', '.join(f'{v:.6g}' for v in planes)} "
              "meshed as planar patches" if planes else ""))
    status = OPTIMAL if ok else TIME_LIMIT if late else INACCURATE
    return SingularSurface(mech.name, space, names, V, Vf, T, R, np.asarray(values),
                           open_curves, ok, status, msg,
                           time.perf_counter() - t0, planes=planes)




def _span(v: Any, who: str) -> tuple[float, float]:
    """The option ``range`` as (lo, hi), lo < hi, both finite."""
    try:
        lo, hi = (float(t) for t in v)
    except (TypeError, ValueError):
        raise MechanismError(f"{who}: option range: expected (lo, hi), two numbers, got "
                             f"{v!r}") from None
    if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
        raise MechanismError(f"{who}: option range: expected finite lo < hi, got "
                             f"({lo:g}, {hi:g})")
    return lo, hi


def _whole_section(mech: Mechanism, model: Any, val: float, bounds: Any, lim: dict,
                   n: int = 41) -> tuple | None:
    """If det A vanishes on the whole section at orientation ``val`` in some working mode
    (|det A| below 1e-10 of its scale at 48 random points of the section where every leg
    reaches), its planar patch: (vertices (V, 3), configurations, |det A|, triangles) over
    an n x n grid of the section's box, cells whose corners all reach within the strokes;
    else None."""
    from ..design._evaluator import evaluator
    from ..model.charts import planar_chart

    try:
        ev = evaluator(mech)
    except MechanismError:
        return None
    chart = planar_chart(model)
    box = np.asarray(bounds, dtype=float) if bounds is not None else (
        chart.reach_box() if chart is not None else None)
    if box is None:
        return None
    L = float(model.length)
    ang = [i for i in range(3) if model.x_angle[i]][0]
    tr = [i for i in range(3) if not model.x_angle[i]]
    rng = np.random.default_rng(0)

    def task(P: np.ndarray) -> np.ndarray:
        T = np.zeros((len(P), 3))
        T[:, tr[0]], T[:, tr[1]], T[:, ang] = P[:, 0], P[:, 1], val
        return T

    Ps = box[:, 0] + rng.random((400, 2)) * (box[:, 1] - box[:, 0])
    for mode in model.working_modes():
        o = ev.evaluate(task(Ps), mode, model.p)
        ok = o["valid"]
        if ok.sum() < 48:
            continue
        # det A scales as (size)^(number of length rows): compare with the legs' lengths
        if np.max(np.abs(o["det"][ok][:48])) > 1e-10 * L ** 3:
            continue
        g0 = np.linspace(box[0, 0], box[0, 1], n)
        g1 = np.linspace(box[1, 0], box[1, 1], n)
        G0, G1 = np.meshgrid(g0, g1, indexing="ij")
        P = np.stack([G0.ravel(), G1.ravel()], -1)
        oo = ev.evaluate(task(P), mode, model.p)
        inside = oo["valid"].copy()
        for j, (a, b) in lim.items():
            if j < model.na:
                inside &= (oo["qa"][:, j] >= a) & (oo["qa"][:, j] <= b)
        idx = np.full(len(P), -1)
        idx[inside] = np.arange(inside.sum())
        I = idx.reshape(n, n)
        tris = []
        for i in range(n - 1):
            for k in range(n - 1):
                a_, b_, c_, d_ = I[i, k], I[i + 1, k], I[i + 1, k + 1], I[i, k + 1]
                if min(a_, b_, c_, d_) >= 0:
                    tris += [(a_, b_, c_), (a_, c_, d_)]
        if not tris:
            return None
        T3 = task(P[inside])
        names = list(model.x_names)
        V = np.stack([T3[:, names.index(model.x_names[tr[0]])],
                      T3[:, names.index(model.x_names[tr[1]])], T3[:, ang]], -1)
        full = np.hstack([oo["qa"][inside], T3])
        return V, full, np.abs(oo["det"][inside]), np.array(tris, dtype=int)
    return None
