"""Assembly-mode changes without a singularity: loops around cusps of the joint space.

A parallel mechanism is *cuspidal* when it can pass from one assembly mode to another
without meeting a parallel singularity (det A keeps its sign; Innocenti and Parenti-Castelli
1992, McAree and Daniel 1999, Özgören). Near a cusp point of the singular locus in the
joint space the direct kinematics has the normal form x^3 + a x + b = 0: inside the cusp's
wedge three local solutions, outside one. A loop that starts inside the wedge, leaves it
across one fold (where the two *other* solutions merge) and comes back across the other
fold carries the outer solution on one side to the outer solution on the other side; both
are nonsingular all along, with the same sign of det A (Zein, Wenger and Chablat 2006).

:func:`mode_change_path` builds such loops in the joint-space section through ``qa``
(the first actuated joint fixed for a 3-DoF mechanism, none for a 2-DoF one): the cusps
come from :func:`~optkin.analysis.continuation.singular_curves` (continuation, every cusp
a corrected point), every candidate loop goes from ``qa`` to a point on a small circle
about a cusp, once around the cusp either way, and back; each is followed by
:func:`optkin.track`, which stops where det W_p changes sign or the tracked mode folds.
A breadth-first search over the assembly modes at ``qa``, with the loops that were
followed to the end as edges, gives the shortest chain of loops from ``start`` to
``target``. :func:`is_cuspidal` looks for one such change near the cusps of a few
sections and returns it as evidence.

What it does not prove: a search that finds no path (no cusp in the section, loops that
all fold) does not show that none exists; the message says which sections and cusps were
tried.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import check_mechanism, check_number, check_option
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model
from ..results import INACCURATE, INFEASIBLE, OPTIMAL, TIME_LIMIT, jsonable

__all__ = ["ModeChangePath", "mode_change_path", "Cuspidality", "is_cuspidal", "CuspCurves",
           "cusp_curves", "MODE_CHANGE_DEFAULTS", "IS_CUSPIDAL_DEFAULTS", "CUSP_CURVES_DEFAULTS"]

#: Options of :func:`mode_change_path` and their defaults.
MODE_CHANGE_DEFAULTS: dict[str, Any] = {
    "radius": None,  # of the loops about each cusp (None: 2 % of the section's extent)
    "angles": 12,  # entry points tried on each circle, both orientations from each (>= 1)
    "depth": 4,  # largest number of loops chained (>= 1)
    "bounds": None,  # the section's box [[lo, hi], [lo, hi]] (None: singular_curves' box)
    "points": 240,  # points per circle, the segments a quarter of it (>= 1)
    "curves": None,  # the section's SingularCurves with cusps, when already traced
    "time_limit": 120.0,  # seconds for the search (capped by the time budget)
}

#: Options of :func:`is_cuspidal` and their defaults.
IS_CUSPIDAL_DEFAULTS: dict[str, Any] = {
    "radius": None,  # of the circles about each cusp (None: 2 % of the section's extent)
    "bounds": None,  # the sections' box [[lo, hi], [lo, hi]] (None: singular_curves' box)
    "angles": 8,  # points on each circle where the assembly modes are followed (>= 1)
    "time_limit": 120.0,  # seconds for the search (capped by the time budget)
}

#: Options of :func:`cusp_curves` and their defaults.
CUSP_CURVES_DEFAULTS: dict[str, Any] = {
    "limits": None,  # actuator strokes, dict name -> (lo, hi): cusps outside are left out
    "bounds": None,  # the sections' box [[lo, hi], [lo, hi]] (None: singular_curves' box)
    "slices": 40,  # sections over the first actuated joint's stroke or range (>= 1)
    "slope": 4.0,  # largest move in the other actuated joints per unit of the first (> 0)
    "time_limit": 300.0,  # seconds (capped by the time budget); later sections left out
}


@dataclass
class ModeChangePath:
    """A joint-space path along which one assembly mode turns into another
    (see :func:`mode_change_path`).

    Attributes
    ----------
    success, status, message :
        ``status`` is ``"optimal"`` when a path was found, ``"infeasible"`` when the modes
        lie in different aspects (det A of opposite signs) or no loop joined them,
        ``"time_limit"`` when the time limit stopped the search first.
    qa_path : ndarray (N, na)
        The actuated values along the path (starts and ends at ``qa``).
    x : ndarray (N, nx)
        The tracked configuration at every point of ``qa_path``.
    det : ndarray (N,)
        det W_p (columns scaled by the mechanism size) along it: one sign throughout.
    min_conditioning : float
        The smallest 1 / cond(W_p) along the path.
    start, target : ndarray
        The two assembly modes (x) at ``qa``.
    cusps : ndarray (k, na)
        The cusps the path loops around, in order.
    modes : list of int
        The assembly modes at ``qa`` visited (indices into ``assembly_modes``), start first.
    det_signs : tuple of int
        Sign of det W_p at the start and at the target.
    """

    success: bool
    status: str
    message: str
    qa: np.ndarray
    start: np.ndarray
    target: np.ndarray
    qa_path: np.ndarray
    x: np.ndarray
    det: np.ndarray
    min_conditioning: float
    cusps: np.ndarray
    modes: list[int]
    det_signs: tuple[int, int]
    section: dict[str, float] = field(default_factory=dict)
    loops_tried: int = 0
    time: float = 0.0
    curves: Any = None
    mechanism: Any = field(default=None, repr=False)
    results: list = field(default_factory=list, repr=False)

    def __repr__(self) -> str:
        return (f"ModeChangePath(success={self.success}, {len(self.qa_path)} points, "
                f"{len(self.cusps)} loop(s), status={self.status!r})")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({
            "success": self.success, "status": self.status, "message": self.message,
            "qa": self.qa, "start": self.start, "target": self.target,
            "qa_path": self.qa_path, "x": self.x, "det": self.det,
            "min_conditioning": self.min_conditioning, "cusps": self.cusps,
            "modes": list(self.modes), "det_signs": list(self.det_signs),
            "section": dict(self.section), "loops_tried": self.loops_tried,
            "time": self.time})

    def plot(self, path: str | None = None, ax: Any = None, title: str | None = None) -> Any:
        """The path in the joint-space section over its singular curves and cusps."""
        from .aspects import _axes, _check_path, _save

        _check_path(path)
        if not len(self.qa_path):
            raise MechanismError("plot: this ModeChangePath has no path (success=False)")
        fig, ax, own = _axes(ax, (6, 6), path=path)
        if self.curves is not None:
            self.curves.plot(ax=ax)
        k = [i for i in range(self.qa_path.shape[1]) if self.section.get(i) is None]
        P = self.qa_path[:, k[-2:]]
        ax.plot(P[:, 0], P[:, 1], color="tab:green", lw=1.6, label="mode-change path")
        ax.plot(*P[0], "o", color="black", ms=6, label="qa (start and end)")
        C = self.cusps[:, k[-2:]] if len(self.cusps) else np.zeros((0, 2))
        if len(self.cusps):
            ax.plot(C[:, 0], C[:, 1], "*", color="tab:purple", ms=12, label="cusp looped")
        ax.legend(loc="upper left", fontsize=8)
        span = np.ptp(P, axis=0).max()
        x0, x1 = ax.get_xlim()
        if self.curves is not None and 0 < span < 0.2 * (x1 - x0):  # a zoom on the loop
            ins = ax.inset_axes([0.58, 0.04, 0.4, 0.4])
            for line in self.curves.polylines("parallel"):
                ins.plot(line[:, 0], line[:, 1], color="tab:red", lw=1)
            ins.plot(P[:, 0], P[:, 1], color="tab:green", lw=1.4)
            ins.plot(*P[0], "o", color="black", ms=5)
            if len(self.cusps):
                ins.plot(C[:, 0], C[:, 1], "*", color="tab:purple", ms=10)
            c, h = P.mean(axis=0), 0.8 * span
            ins.set_xlim(c[0] - h, c[0] + h)
            ins.set_ylim(c[1] - h, c[1] + h)
            ins.set_xticks([])
            ins.set_yticks([])
            ax.indicate_inset_zoom(ins, edgecolor="0.4")
        ax.set_title(title or (f"mode change {self.modes[0]} -> {self.modes[-1]}"
                               if self.modes else "no mode change found"))
        ax.set_xlabel(self.curves.plane[0] if self.curves is not None else "")
        ax.set_ylabel(self.curves.plane[1] if self.curves is not None else "")
        if own and path is not None:
            _save(fig, path)
        return fig

    def animate(self, path: str | None = None, frames: int = 60, fps: int = 15) -> Any:
        """The mechanism moving along the path (left) beside the path in the joint-space
        section (right): a matplotlib ``FuncAnimation`` (in a notebook,
        ``IPython.display.HTML(anim.to_jshtml())``), saved as a GIF when ``path`` is given.
        """
        import matplotlib.pyplot as plt
        from matplotlib.animation import FuncAnimation, PillowWriter

        from ..plot import _drawing

        if not self.success or not self.results:
            raise MechanismError("animate: this ModeChangePath has no path (success=False)")
        fps = check_number(fps, "animate: fps", lo=0.0, lo_open=True)
        frames = check_number(frames, "animate: frames", integer=True, lo=2)
        frames = max(2, min(int(frames), len(self.results)))
        idx = np.unique(np.linspace(0, len(self.results) - 1, frames).round().astype(int))
        draws = [_drawing(self.mechanism, self.results[k]) for k in idx]
        if draws[0].dim != 2:
            raise MechanismError("animate: drawn for planar mechanisms only")
        pts = np.vstack([np.vstack(d.lines) for d in draws])
        lo, hi = pts.min(axis=0)[:2], pts.max(axis=0)[:2]
        pad = 0.05 * float(np.max(hi - lo))
        fig, (axm, axq) = plt.subplots(1, 2, figsize=(11, 5))
        axm.set_xlim(lo[0] - pad, hi[0] + pad)
        axm.set_ylim(lo[1] - pad, hi[1] + pad)
        axm.set_aspect("equal", adjustable="box")
        axm.grid(alpha=0.3)
        axm.set_xlabel("x")
        axm.set_ylabel("y")
        base = draws[0].base
        if len(base):
            axm.scatter(base[:, 0], base[:, 1], marker="^", c="k", s=40, zorder=3,
                        label="base joints")
        n_legs = len(draws[0].legs)
        lines = [axm.plot([], [], "o-", lw=2, ms=4, color="C0" if j < n_legs else "C1",
                          label=("leg chains" if j == 0 else "platform" if j == n_legs else None))[0]
                 for j in range(len(draws[0].lines))]
        axm.legend(loc="upper right", fontsize=8)
        self.plot(ax=axq)
        k_free = [i for i in range(self.qa_path.shape[1]) if self.section.get(i) is None][-2:]
        dot, = axq.plot([], [], "o", color="tab:red", ms=8)
        title = axm.set_title("")

        def update(f):
            d = draws[f]
            for ln, P in zip(lines, d.lines):
                ln.set_data(P[:, 0], P[:, 1])
            q = self.qa_path[idx[f], k_free]
            dot.set_data([q[0]], [q[1]])
            title.set_text(f"det W_p = {self.det[idx[f]]:+.3g}")
            return [*lines, dot, title]

        anim = FuncAnimation(fig, update, frames=len(draws), interval=1000 / fps, blit=False)
        if path is not None:
            anim.save(path, writer=PillowWriter(fps=fps))
        return anim


def _loop(qa: np.ndarray, c: np.ndarray, free: list[int], rad: float, a0: float,
          orient: int, n_seg: int, n_circ: int) -> np.ndarray:
    """qa -> a point at angle a0 on the circle of radius rad about c (in the free
    coordinates) -> once around -> back to qa."""
    u = np.array([np.cos(a0), np.sin(a0)])
    q_in = qa.copy()
    q_in[free] = c[free] + rad * u
    seg = np.linspace(qa, q_in, n_seg)
    ang = a0 + orient * np.linspace(0.0, 2 * np.pi, n_circ)
    circ = np.repeat(q_in[None], n_circ, axis=0)
    circ[:, free] = c[free] + rad * np.c_[np.cos(ang), np.sin(ang)]
    return np.vstack([seg, circ[1:], seg[::-1][1:]])


def _det_sign(mech: Mechanism, kr) -> int:
    from .velocity import jacobians

    return int(np.sign(np.linalg.det(jacobians(mech, kr).W_p)))


def _which(modes, x: np.ndarray, scale: np.ndarray) -> int | None:
    d = [float(np.max(np.abs(x - m.x) / scale)) for m in modes]
    j = int(np.argmin(d))
    return j if d[j] < 1e-6 else None


def _resolve(modes, v: Any, what: str, scale) -> int:
    if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
        if not 0 <= int(v) < len(modes):
            raise MechanismError(f"mode_change_path: {what} = {int(v)} is not an assembly "
                                 f"mode index; qa has {len(modes)} modes (0 to "
                                 f"{len(modes) - 1})")
        return int(v)
    x = np.asarray(getattr(v, "x", v), dtype=float).ravel()
    j = None if x.shape != modes[0].x.shape else _which(modes, x, scale)
    if j is None:
        raise MechanismError(f"mode_change_path: {what} is not one of the {len(modes)} "
                             "assembly modes at qa; pass an index into "
                             "optkin.assembly_modes(mech, qa) or one of its results")
    return j


def _pieces_result(mech, qa, modes, i0, i1, signs, section, fixed, pieces, C, chain,
                   tried, curves, t0) -> ModeChangePath:
    """The ModeChangePath of the loops ``pieces`` [(cusp index, qa path, track result)]."""
    path = np.vstack([p[1] if n == 0 else p[1][1:] for n, p in enumerate(pieces)])
    X = np.vstack([np.array([r.x for r in p[2]])[(0 if n == 0 else 1):]
                   for n, p in enumerate(pieces)])
    det = np.concatenate([np.asarray(p[2].info["det"])[(0 if n == 0 else 1):]
                          for n, p in enumerate(pieces)])
    cond = np.concatenate([np.asarray(p[2].info["cond"]) for p in pieces])
    return ModeChangePath(
        True, OPTIMAL,
        f"mode {i0} -> mode {i1} by {len(pieces)} loop(s) about the cusp(s) at "
        f"{[np.round(C[p[0]], 4).tolist() for p in pieces]} (section "
        f"{fixed or 'the joint space'}); det W_p keeps its sign "
        f"({'+' if signs[0] > 0 else '-'}) along {len(path)} points",
        qa, modes[i0].x.copy(), modes[i1].x.copy(), path, X, det,
        float(1.0 / np.max(cond)), np.array([C[p[0]] for p in pieces], dtype=float), chain,
        signs, section, tried, time.perf_counter() - t0, curves, mech,
        [r for n, p in enumerate(pieces) for r in list(p[2])[(0 if n == 0 else 1):]])


def _failed(model, qa, modes, i0, i1, signs, section, msg, tried, curves, t0,
            status: str = INFEASIBLE):
    na = model.na
    return ModeChangePath(False, status, msg, qa, modes[i0].x.copy(),
                          modes[i1].x.copy(), np.zeros((0, na)), np.zeros((0, model.nx)),
                          np.zeros(0), float("nan"), np.zeros((0, na)), [], signs, section,
                          tried, time.perf_counter() - t0, curves)


def _section(mech, model, qa, bounds, curves=None):
    """The joint-space section through qa, its singular curves and cusps (na columns)."""
    from .continuation import _names_of, singular_curves

    fixed = {_names_of(mech)[0]: float(qa[0])} if model.na == 3 else {}
    if curves is None:
        curves = singular_curves(mech, plane="joint", fixed=fixed or None, bounds=bounds,
                                 cusps=True)
    C = np.asarray(curves.cusps, dtype=float).reshape(-1, len(curves.names))[:, :model.na]
    section = {0: float(qa[0])} if model.na == 3 else {}
    free = [k for k in range(model.na) if k not in section]
    return fixed, section, free, curves, C


def _default_radius(curves) -> float:
    """2 % of the section's extent: the loops' default radius about a cusp."""
    b = np.asarray(curves.bounds, dtype=float)
    return 0.02 * float(np.max(b[:, 1] - b[:, 0]))


def _follow(mech, P, mode):
    """optkin.track along P from ``mode``; None unless followed to the end."""
    from ..solvers.enumerate import track

    try:
        tr = track(mech, P, mode)
    except MechanismError:  # the loop leaves the joints' domain (a negative length)
        return None
    return tr if tr.info.get("status") == "optimal" and len(tr) == len(P) else None


def _check_qa_arg(model, qa, who):
    na = model.na
    if na not in (2, 3):
        raise MechanismError(f"{who}: needs 2 or 3 actuated joints, {model.mech.name} has {na}")
    qa = np.asarray(qa, dtype=float).ravel()
    if qa.shape != (na,) or not np.all(np.isfinite(qa)):
        raise MechanismError(f"{who}: qa must be {na} finite numbers, got "
                             f"{np.asarray(qa).tolist()}")
    return qa


def mode_change_path(mech: Mechanism, qa: Any, start: Any, target: Any,
                     **options: Any) -> ModeChangePath:
    """A joint-space loop from ``qa`` back to ``qa`` that takes assembly mode ``start`` to
    ``target`` without meeting a parallel singularity (see the module docstring).

    Parameters
    ----------
    mech : Mechanism
        A 2- or 3-DoF mechanism whose singular curves :func:`optkin.singular_curves`
        traces in the joint space (planar platforms with distance legs, five-bars).
    qa : array (na,)
        Actuated values where both modes are taken; the loops lie in the section through
        it (the first actuated joint fixed at ``qa[0]`` for 3 actuated joints).
    start, target : int, KinResult or array
        Assembly modes at ``qa``: indices into ``optkin.assembly_modes(mech, qa)`` (sorted
        as it returns them) or its results / their x.
    **options
        The options below, by keyword, over :data:`MODE_CHANGE_DEFAULTS` (an unknown name
        raises :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    radius : float, optional
        Radius of the loops about each cusp (default: 2 % of the section's extent).
    angles : int
        Entry points tried on each circle (both orientations are tried from each).
    depth : int
        Largest number of loops chained.
    bounds : [[lo, hi], [lo, hi]], optional
        The section's box (default: that of :func:`optkin.singular_curves`).
    points : int
        Points per circle (the segments get a quarter of it).
    curves : SingularCurves, optional
        The section's singular curves, when already traced (with cusps).
    time_limit : float
        Seconds for the search (capped by the time budget); out of time it reports what it
        tried, ``success=False``.

    Returns
    -------
    ModeChangePath
        ``success=False`` with status ``"infeasible"`` when det W_p has opposite signs at
        the two modes (they lie in different aspects: no such path exists) or when no
        chain of loops joined them (the message lists what was tried).
    """
    from ..limits import Deadline, time_budget
    from ..solvers.common import merge_options
    from ..solvers.enumerate import assembly_modes

    t0 = time.perf_counter()
    who = "mode_change_path"
    opts = merge_options(MODE_CHANGE_DEFAULTS, options, who)

    def num(name: str, **kw: Any) -> Any:
        return check_option(opts, name, who, MODE_CHANGE_DEFAULTS, **kw)

    bounds, curves = opts["bounds"], opts["curves"]
    deadline = Deadline(min(num("time_limit", lo=0.0, lo_open=True), time_budget()))
    radius = num("radius", lo=0.0, lo_open=True, optional=True)
    check_mechanism(mech, who)
    model = get_model(mech)
    qa = _check_qa_arg(model, qa, who)
    angles = num("angles", integer=True, lo=1)
    depth = num("depth", integer=True, lo=1)
    points = num("points", integer=True, lo=1)
    modes = assembly_modes(mech, qa)
    if len(modes) < 2:
        raise MechanismError(f"{who}: qa has {len(modes)} assembly mode(s); a mode change "
                             "needs two")
    scale = np.asarray(model.x_scale, dtype=float)
    i0 = _resolve(modes, start, "start", scale)
    i1 = _resolve(modes, target, "target", scale)
    if i0 == i1:
        raise MechanismError(f"{who}: start and target are the same assembly mode ({i0})")
    signs = (_det_sign(mech, modes[i0]), _det_sign(mech, modes[i1]))
    section = {0: float(qa[0])} if model.na == 3 else {}
    if signs[0] != signs[1]:
        return _failed(model, qa, modes, i0, i1, signs, section,
                       f"modes {i0} and {i1} lie in different aspects: det W_p is "
                       f"{'positive' if signs[0] > 0 else 'negative'} at {i0} and "
                       f"{'positive' if signs[1] > 0 else 'negative'} at {i1}, so every "
                       "path between them meets a parallel singularity", 0, None, t0)
    fixed, section, free, curves, C = _section(mech, model, qa, bounds, curves)
    if not len(C):
        return _failed(model, qa, modes, i0, i1, signs, section,
                       f"no cusp in the joint-space section {fixed or '(the joint space)'}: "
                       "no loop to try; this does not prove that no path exists", 0,
                       curves, t0)
    rad = radius if radius is not None else _default_radius(curves)
    n_circ = max(16, points)
    n_seg = max(8, n_circ // 4)
    order = np.argsort(np.linalg.norm(C[:, free] - qa[free], axis=1))  # nearest cusp first
    prev: dict[int, Any] = {i0: None}
    tried = 0
    queue = deque([(i0, 0)])
    while queue and i1 not in prev and not deadline.expired():
        i, d = queue.popleft()
        if d >= depth:
            continue
        for ci in order:
            if deadline.expired():
                break
            for a0 in np.linspace(0, 2 * np.pi, angles, endpoint=False):
                for orient in (1, -1):
                    if deadline.expired():
                        break
                    P = _loop(qa, C[ci], free, rad, a0, orient, n_seg, n_circ)
                    tried += 1
                    tr = _follow(mech, P, modes[i])
                    j = None if tr is None else _which(modes, tr[-1].x, scale)
                    if j is not None and j not in prev:
                        prev[j] = (i, ci, P, tr)
                        queue.append((j, d + 1))
                    if i1 in prev:
                        break
                if i1 in prev:
                    break
            if i1 in prev:
                break
    if i1 not in prev:
        return _failed(model, qa, modes, i0, i1, signs, section,
                       f"no chain of at most {depth} loops about the {len(C)} cusp(s) of "
                       f"the section took mode {i0} to mode {i1} ({tried} loops followed; "
                       f"modes reached: {sorted(prev)}); a larger radius or more angles "
                       "may find one" + ("; stopped at the time limit" if deadline.expired()
                                         else ""), tried, curves, t0,
                       TIME_LIMIT if deadline.expired() else INFEASIBLE)
    chain, pieces, k = [i1], [], i1
    while prev[k] is not None:
        i, ci, P, tr = prev[k]
        pieces.append((ci, P, tr))
        chain.append(i)
        k = i
    chain.reverse()
    pieces.reverse()
    return _pieces_result(mech, qa, modes, i0, i1, signs, section, fixed, pieces, C,
                          chain, tried, curves, t0)


@dataclass
class Cuspidality:
    """The answer of :func:`is_cuspidal` with its evidence.

    Attributes
    ----------
    cuspidal : bool or None
        True with the path that proves it (``evidence``); None when no assembly-mode change
        was found (not a proof of the contrary).
    success, status, message :
        As every result (:mod:`optkin.results`): ``success`` True and status
        ``"optimal"`` when a mode change was found; else ``success`` False with status
        ``"infeasible"`` (no change found by the loops tried) or ``"time_limit"`` (the
        search stopped at the time limit); the message says what was tried.
    evidence : ModeChangePath or None
        The mode-changing path.
    sections : list of float
        The section values of the first actuated joint searched.
    cusps : int
        Cusps met in those sections.
    """

    cuspidal: bool | None
    message: str
    evidence: ModeChangePath | None
    sections: list[float]
    cusps: int
    time: float = 0.0
    status: str = ""

    def __post_init__(self) -> None:
        if not self.status:
            self.status = OPTIMAL if self.cuspidal else INFEASIBLE

    @property
    def success(self) -> bool:
        """Whether the search answered: a mode change was found (``cuspidal`` True)."""
        return self.cuspidal is not None

    def __bool__(self) -> bool:
        return bool(self.cuspidal)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({"cuspidal": self.cuspidal, "success": self.success,
                         "status": self.status, "message": self.message,
                         "sections": self.sections, "cusps": self.cusps, "time": self.time,
                         "evidence": self.evidence})


def is_cuspidal(mech: Mechanism, sections: Any = None, **options: Any) -> Cuspidality:
    """Look for an assembly-mode change without a singularity near the cusps of joint-space
    sections; ``cuspidal=True`` comes with the path that proves it (``evidence``).

    For each section value of the first actuated joint (3-DoF; ``sections``, default five
    values between 0.6 and 1.6 times the mechanism's size) and each cusp there, every
    assembly mode at ``angles`` points on a circle of ``radius`` about the cusp is followed
    once around that circle either way; one that comes back as another mode, det W_p of
    one sign all along, is the evidence. ``cuspidal`` is None when none did: not a proof
    of the contrary (the message says what was tried). ``time_limit`` (s, capped by the
    time budget) stops the search; the message says so.

    Parameters
    ----------
    mech : Mechanism
        A 2- or 3-DoF mechanism whose singular curves :func:`optkin.singular_curves`
        traces in the joint space.
    sections : sequence of float, optional
        Values of the first actuated joint (3 actuated joints; ignored for 2) whose
        sections are searched (default: five values between 0.6 and 1.6 times the
        mechanism's size).
    **options
        The options below, by keyword, over :data:`IS_CUSPIDAL_DEFAULTS` (an unknown name
        raises :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    radius : float, optional
        Radius of the circles about each cusp (default: 2 % of the section's extent).
    bounds : [[lo, hi], [lo, hi]], optional
        The sections' box (default: that of :func:`optkin.singular_curves`).
    angles : int
        Points on each circle where the assembly modes are taken and followed.
    time_limit : float
        Seconds for the search (capped by the time budget).

    Returns
    -------
    Cuspidality
    """
    from ..limits import Deadline, time_budget
    from ..solvers.common import merge_options
    from ..solvers.enumerate import assembly_modes
    from .continuation import _names_of, singular_curves

    t0 = time.perf_counter()
    who = "is_cuspidal"
    opts = merge_options(IS_CUSPIDAL_DEFAULTS, options, who)

    def num(name: str, **kw: Any) -> Any:
        return check_option(opts, name, who, IS_CUSPIDAL_DEFAULTS, **kw)

    bounds = opts["bounds"]
    deadline = Deadline(min(num("time_limit", lo=0.0, lo_open=True), time_budget()))
    check_mechanism(mech, who)
    model = get_model(mech)
    na = model.na
    _check_qa_arg(model, np.zeros(na), who)
    angles = num("angles", integer=True, lo=1)
    radius = num("radius", lo=0.0, lo_open=True, optional=True)
    if na == 3:
        name = _names_of(mech)[0]
        if sections is None:
            sections = np.linspace(0.6, 1.6, 5) * float(model.length)
        values = [check_number(v, f"{who}: sections")
                  for v in np.atleast_1d(np.asarray(sections, dtype=float))]
    else:
        name, values = None, [float("nan")]
    scale = np.asarray(model.x_scale, dtype=float)
    n_cusps = tried = 0
    for s in values:
        if deadline.expired():
            break
        fixed = {name: s} if name is not None else None
        curves = singular_curves(mech, plane="joint", fixed=fixed, bounds=bounds, cusps=True)
        C = np.asarray(curves.cusps, dtype=float).reshape(-1, len(curves.names))[:, :na]
        n_cusps += len(C)
        rad = radius if radius is not None else _default_radius(curves)
        free = [k for k in range(na) if not (na == 3 and k == 0)]
        section = {0: s} if na == 3 else {}
        for ci, c in enumerate(C):
            if deadline.expired():
                break
            for a0 in np.linspace(0, 2 * np.pi, angles, endpoint=False):
                if deadline.expired():
                    break
                q = c.copy()
                q[free] = c[free] + rad * np.array([np.cos(a0), np.sin(a0)])
                try:
                    modes = assembly_modes(mech, q)
                except MechanismError:  # outside the joints' domain
                    continue
                if len(modes) < 2:
                    continue
                sg = [_det_sign(mech, m) for m in modes]
                loops = [_loop(q, c, free, rad, a0, orient, 1, 240) for orient in (1, -1)]
                for i in range(len(modes)):
                    for P in loops:
                        if deadline.expired():
                            break
                        tried += 1
                        tr = _follow(mech, P, modes[i])
                        j = None if tr is None else _which(modes, tr[-1].x, scale)
                        if j is None or j == i or sg[j] != sg[i]:
                            continue
                        r = _pieces_result(mech, q, modes, i, j, (sg[i], sg[j]),
                                           section, fixed or {}, [(ci, P, tr)], C, [i, j],
                                           tried, curves, t0)
                        return Cuspidality(True, f"cuspidal: {r.message}, at qa = "
                                           f"{np.round(q, 6).tolist()}", r, values, n_cusps,
                                           time.perf_counter() - t0)
    late = "; stopped at the time limit" if deadline.expired() else ""
    return Cuspidality(None, f"no assembly-mode change found by {tried} loops about "
                       f"{n_cusps} cusp(s) in {len(values)} section(s){late}; not a proof "
                       "that the mechanism is noncuspidal", None, values, n_cusps,
                       time.perf_counter() - t0, TIME_LIMIT if late else INFEASIBLE)


@dataclass
class CuspCurves:
    """Cusp curves of a 3-DoF mechanism in its joint space (see :func:`cusp_curves`).

    Attributes
    ----------
    curves : list of ndarray (k, na)
        Each curve's points (actuated values), in order along the first actuated joint.
    v : list of ndarray (k, na + nx)
        The full configuration at each point (q_a then x): a cusp of the section through it.
    points : ndarray (n, na)
        Every cusp found, linked or not.
    sections : ndarray
        The values of the first actuated joint the sections were taken at.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``; ``"inaccurate"`` when a
        section's curves are; ``"time_limit"`` when later sections were left out.
    """

    mechanism: str
    names: tuple[str, ...]
    curves: list[np.ndarray]
    v: list[np.ndarray]
    points: np.ndarray
    sections: np.ndarray
    success: bool
    status: str
    message: str
    time: float = 0.0

    def __len__(self) -> int:
        return len(self.curves)

    def __repr__(self) -> str:
        return (f"CuspCurves({self.mechanism!r}, {len(self.curves)} curve(s), "
                f"{len(self.points)} cusp point(s), status={self.status!r})")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({"mechanism": self.mechanism, "names": list(self.names),
                         "success": self.success, "status": self.status,
                         "message": self.message, "curves": list(self.curves),
                         "sections": self.sections, "time": self.time})

    def plot(self, path: str | None = None, ax: Any = None, title: str | None = None) -> Any:
        """The cusp curves in the joint space (3-D axes; ``ax`` may be a 3-D Axes)."""
        from .aspects import _axes, _check_path, _save

        _check_path(path)
        fig, ax, own = _axes(ax, (7, 6), three_d=True, path=path)
        for k, c in enumerate(self.curves):
            ax.plot(c[:, 1], c[:, 2], c[:, 0], "-", color="tab:purple", lw=2,
                    label="cusp curves" if k == 0 else None)
        if len(self.points):
            ax.scatter(self.points[:, 1], self.points[:, 2], self.points[:, 0], s=6,
                       color="black", label="cusps of the sections")
        ax.set_xlabel(self.names[1])
        ax.set_ylabel(self.names[2])
        ax.set_zlabel(self.names[0])
        ax.legend(loc="upper left", fontsize=8)
        ax.set_title(title or f"{self.mechanism}: cusp curves in the joint space")
        if own and path is not None:
            _save(fig, path)
        return fig


def cusp_curves(mech: Mechanism, **options: Any) -> CuspCurves:
    """The cusp curves of a 3-DoF mechanism in its joint space: the cusps of the sections
    at ``slices`` values of the first actuated joint (over its stroke in ``limits``, else
    its range), each a corrected cusp of a traced singular curve, linked from section to
    section (the nearest cusp of the next section in the other actuated joints, within
    ``slope`` times the section step; one partner each).

    The links interpolate between sections; where cusps are born or die in pairs (a
    swallowtail) between two sections a curve ends. ``time_limit`` (s, capped by the time
    budget): the sections not reached are left out and the result says so.

    Parameters
    ----------
    mech : Mechanism
        A mechanism with 3 actuated joints whose singular curves
        :func:`optkin.singular_curves` traces in the joint space.
    **options
        The options below, by keyword, over :data:`CUSP_CURVES_DEFAULTS` (an unknown name
        raises :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    limits : dict name -> (lo, hi), optional
        Actuator strokes: the sections span the first actuated joint's stroke (else its
        range), and cusps outside the strokes are left out.
    bounds : [[lo, hi], [lo, hi]], optional
        The sections' box (default: that of :func:`optkin.singular_curves`).
    slices : int
        Sections.
    slope : float
        Largest move in the other actuated joints per unit of the first between linked
        cusps.
    time_limit : float
        Seconds (capped by the time budget).

    Returns
    -------
    CuspCurves
    """
    from ..limits import Deadline, time_budget
    from ..solvers.common import merge_options
    from .aspects import _first_range, _limit_map
    from .continuation import _names_of, singular_curves

    t0 = time.perf_counter()
    who = "cusp_curves"
    opts = merge_options(CUSP_CURVES_DEFAULTS, options, who)

    def num(name: str, **kw: Any) -> Any:
        return check_option(opts, name, who, CUSP_CURVES_DEFAULTS, **kw)

    limits, bounds = opts["limits"], opts["bounds"]
    deadline = Deadline(min(num("time_limit", lo=0.0, lo_open=True), time_budget()))
    slope = num("slope", lo=0.0, lo_open=True)
    check_mechanism(mech, who)
    model = get_model(mech)
    if model.na != 3:
        raise MechanismError(f"{who}: needs 3 actuated joints, {mech.name} has {model.na}")
    slices = num("slices", integer=True, lo=1)
    names = _names_of(mech)
    lim = _limit_map(mech, names, limits)
    lo, hi = _first_range(who, model, names, lim)
    values = np.linspace(lo, hi, slices + 2)[1:-1]
    gap = float(values[1] - values[0]) if len(values) > 1 else 1.0
    per: list[np.ndarray] = []
    failed = []
    late = False
    for val in values:
        if deadline.expired():
            late = True
            per.append(np.zeros((0, model.na + model.nx)))
            continue
        c = singular_curves(mech, plane="joint", fixed={names[0]: float(val)}, bounds=bounds,
                            cusps=True)
        if not c.success:
            failed.append(c.message)
        V = np.asarray(c.cusps, dtype=float).reshape(-1, len(c.names))
        for j, (a, b) in lim.items():
            V = V[(V[:, j] >= a) & (V[:, j] <= b)]
        per.append(V)
    # link section to section
    chains: list[list[np.ndarray]] = []
    open_ends: list[tuple[int, int]] = []  # (chain, index into the previous section)
    for k, V in enumerate(per):
        new_open = []
        taken = set()
        for ci, pi in open_ends:
            prev = per[k - 1][pi]
            if not len(V):
                continue
            # distance in the other actuated joints, against the section step: a cusp
            # curve may move at most ``slope`` in them per unit of the sectioning joint
            d = np.linalg.norm((V - prev)[:, 1:model.na], axis=1) / gap
            for j in np.argsort(d):
                if d[j] > slope:
                    break
                if j not in taken:
                    taken.add(j)
                    chains[ci].append(V[j])
                    new_open.append((ci, int(j)))
                    break
        for j in range(len(V)):
            if j not in taken:
                chains.append([V[j]])
                new_open.append((len(chains) - 1, j))
        open_ends = new_open
    vs = [np.array(c) for c in chains if len(c) >= 2]
    pts = np.vstack(per)[:, :model.na] if any(len(v) for v in per) else np.zeros((0, 3))
    ok = not failed and not late
    msg = (f"{len(vs)} cusp curve(s) through {len(pts)} cusps of {len(values)} sections "
           f"({names[0]} from {values[0]:.4g} to {values[-1]:.4g})"
           + (f"; {len(failed)} section(s) incomplete: {failed[0]}" if failed else "")
           + ("; stopped at the time limit: later sections left out" if late else ""))
    status = OPTIMAL if ok else TIME_LIMIT if late else INACCURATE
    return CuspCurves(mech.name, tuple(names[:model.na]), [v[:, :model.na] for v in vs], vs,
                      pts, values, ok, status, msg, time.perf_counter() - t0)
