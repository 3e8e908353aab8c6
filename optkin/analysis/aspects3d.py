"""Generalized aspects of 3-DoF planar platforms in (x, y, phi), from exact sections.

A generalized aspect (Chablat and Wenger 1998) of a 3-DoF planar platform is a
connected component, in one working mode, of the configurations with det A != 0 within the
actuators' strokes: a region of (x, y, phi). At a fixed orientation phi its section is a
union of faces of the planar arrangement of the singular and limit curves, which
:func:`optkin.aspects` computes exactly (curves traced by continuation, faces as polygons
with their areas). Here the sections at ``slices`` orientations around the circle are
linked: a face of one section and a face of the next belong to one aspect when they have
the same working mode and sign of det A and either overlap or are joined by a segment in
phi from a point inside one of them that stays free (strokes kept, det A of that sign at
24 orientations across the gap; the legs' closed-form inverses and det W_p of the model,
vectorised). Where a face that is not tiny (area above ``tiny`` times the section's
largest) finds no partner across a gap, the gap is bisected, down to ``min_gap``: an
aspect born, dying, splitting or merging there is then located between two close
sections, and faces on either side link across it (a face near the sections' sliver
threshold, which one section keeps and the next drops, is no such event). The volume of
an aspect is the integral over phi of its section's area: each face's area corrected for
the arcs between its traced vertices (:func:`optkin.analysis.planar.arc_area`), the
integral the trapezoid rule less its curvature term (:func:`_integrate`); its bounding
box and a representative configuration come from its faces.

The refinement also halves gaps where the phi integral's estimated error is large
(``vol_tol``, :func:`_interval_errors`): the areas have kinked, steep stretches away from
any event (near phi = -0.1, 0 and 0.9-1.04 on the 3-RPR below, where the two signs' areas
trade tens of units within 0.02 rad), across which the even sections alone converge
slowly.

Measured on the cuspidal 3-RPR of Zein, Wenger and Chablat with strokes [10, 30]
(tests/test_aspects3d.py), 2026-12-06, the volumes of its 2 aspects (length^2 rad):

==============  ========  ==========  ==========  ======
refinement      sections  det A > 0   det A < 0   time
==============  ========  ==========  ==========  ======
events only     83        2097.028    2069.383    2.3 s
576 even        585       2097.221    2068.605    16.8 s
vol_tol 1e-3    123       2097.213    2068.590    3.8 s
vol_tol 1e-4    237       2097.253    2068.599    7.4 s
vol_tol 1e-5    656       2097.227    2068.597    21 s
vol_tol 3e-6    1209      2097.229    2068.598    40 s
==============  ========  ==========  ==========  ======

(36 even sections in each but the second; the events only: ``vol_tol=inf``.) Voxel grids
of the sign of det A find the same two components and approach these volumes as they are
refined: 2097.7 and 2069.5 at 240^3 (3 s), 2096.6 and 2068.2 at 320^3, 2097.4 and 2068.7
at 400^3, 2097.3 and 2068.7 at 480^3 (27 s). The default (1e-3) is within 1e-5 of the
finest refinement, the 480^3 grid within 5e-5 (benchmarks/test_aspects3d.py times both).
The section areas themselves agree wherever the orientations coincide (to 2e-12). Both
curves of its sections come in closed form: the strokes' limit curves are the legs'
circles, the parallel curve a conic (:func:`optkin.analysis.continuation._conic_arcs`;
3.0-3.3 s of CPU against 4.3-4.5 s traced, in one run). A section costs about 30 ms (the
faces of the arrangement, their interior points and labels, the links between sections).
An aspect whose whole
extent in phi is shorter than ``min_gap`` may be missed, and a neck thinner than it in
phi may join or split aspects.

Legs with several postures get their aspects per working mode the same way, at the
sections' finer default step (see ``step``): tested on the 3-RRR (the 3-PRR takes the
same path, not compared with a grid yet). Measured on a 3-RRR (equilateral
base of side 10 and platform of circumradius 2, links 5 and 4; tests/test_aspects3d.py):
16 aspects, two per working mode, volumes 154.87 (2), 148.51 (6), 107.67 (6) and 101.31
(2) from 217 sections, 98 s here (154.77, 148.50, 107.71 and 101.44 from 143 sections in
54 s with ``vol_tol=inf``), against a 200^3 voxel grid's 16 components, 154.80,
148.44-148.45, 107.63-107.64 and 101.31 (101.24 at 160^3). A design whose legs
fold completely (links of equal length: the inner serial circle shrinks to the base
joint, where the leg's inverse is singular) is not handled reliably: with links 5 and 5
the curves of 86 of 198 sections stopped early near phi = +-1.4 and the aspects fell apart
into hundreds of pieces; the result then says so (status ``"inaccurate"``, the first such
orientation named), as it does for any section whose curves stopped early (none on the
3-RPR and the 3-RRR above).
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
from .planar import Face, face_arc_area, point_in_face

__all__ = ["Aspect3D", "Aspects3D", "aspects3d", "ASPECTS3D_DEFAULTS"]

#: Options of :func:`aspects3d` and their defaults.
ASPECTS3D_DEFAULTS: dict[str, Any] = {
    "limits": None,  # actuator strokes, dict name -> (lo, hi) (None: unlimited)
    "bounds": None,  # box [[lo, hi], [lo, hi]] in (x, y) (None: the reach of the legs)
    "slices": 36,  # sections spread evenly over [-pi, pi) before refinement (>= 4)
    "min_gap": 1e-3,  # smallest gap in phi the refinement bisects down to (rad, > 0)
    "modes": True,  # count the assembly modes each aspect holds at its representative q_a
    "tiny": 1e-5,  # a face under this fraction of its section's largest area may appear
    # or vanish between two sections without refinement
    "step": None,  # largest continuation step of the sections' curves (scaled units, > 0;
    # None: 0.25 when every actuator is its leg's length, else the sections' default 0.08)
    "time_limit": 300.0,  # seconds (capped by the time budget); past it no gap is refined
    "vol_tol": 1e-3,  # gaps are also halved where the phi integral's estimated error
    # exceeds this fraction of the total volume (shared by width; inf: events only, > 0)
}


@dataclass
class Aspect3D:
    """One generalized aspect in (x, y, phi).

    Attributes
    ----------
    working_mode : tuple of int
    det_sign : int
        Sign of det A (= det W_p) in it.
    volume : float
        Integral over phi of the section areas (length^2 rad).
    bbox : ndarray (3, 2)
        [[x_lo, x_hi], [y_lo, y_hi], [phi_lo, phi_hi]]: phi spans [-pi, pi] when the aspect
        goes all the way round, and phi_lo > phi_hi when it passes through +-pi.
    v : ndarray
        A representative configuration (q_a then x) inside its largest section.
    sections : list of (phi, Face)
        Its faces in the sections.
    modes_at : list of (qa, int)
        Actuated values (those of ``v``) and how many assembly modes there lie in this
        aspect: more than one marks a cuspidal design.
    """

    working_mode: tuple[int, ...]
    det_sign: int
    volume: float
    bbox: np.ndarray
    v: np.ndarray
    sections: list[tuple[float, Face]] = field(repr=False, default_factory=list)
    modes_at: list[tuple[np.ndarray, int]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"working_mode": list(self.working_mode), "det_sign": self.det_sign,
                "volume": self.volume, "bbox": self.bbox.tolist(), "v": self.v.tolist(),
                "n_sections": len(self.sections),
                "modes_at": [{"qa": q.tolist(), "modes": n} for q, n in self.modes_at]}


@dataclass
class Aspects3D:
    """The 3-D generalized aspects of a 3-DoF planar platform (see :func:`aspects3d`).

    Attributes
    ----------
    aspects : list of Aspect3D
        Every aspect, with its volume and sections.
    phis : ndarray
        The orientations of the sections.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``; a section's status when
        one failed; ``"time_limit"`` when refinement stopped at the time limit;
        ``"inaccurate"`` (the aspects still given) when some section's curves stopped
        early, so that faces may be missing or merged there.
    """

    mechanism: str
    aspects: list[Aspect3D]
    phis: np.ndarray
    success: bool
    status: str
    message: str
    time: float = 0.0
    names: tuple[str, str, str] = ("x", "y", "phi")

    def __len__(self) -> int:
        return len(self.aspects)

    def __iter__(self):
        return iter(self.aspects)

    def __repr__(self) -> str:
        return (f"Aspects3D({self.mechanism!r}, {len(self.aspects)} aspect(s) from "
                f"{len(self.phis)} sections, status={self.status!r})")

    @property
    def cuspidal(self) -> bool:
        """Some aspect holds more than one assembly mode at one q_a."""
        return any(n > 1 for a in self.aspects for _, n in a.modes_at)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({"mechanism": self.mechanism, "success": self.success,
                         "status": self.status, "message": self.message,
                         "count": len(self.aspects), "n_sections": len(self.phis),
                         "cuspidal": self.cuspidal,
                         "aspects": [a.to_dict() for a in self.aspects], "time": self.time})

    def plot(self, path: str | None = None, every: int = 3, title: str | None = None, *,
             ax: Any = None) -> Any:
        """The aspects as stacks of section outlines in (x, y, phi), one colour each.

        With several working modes (legs with two postures: a 3-RRR's 8) and no ``ax``,
        one panel per working mode: their aspects overlap in (x, y, phi), so drawn
        together they would hide one another. Returns the matplotlib Figure; ``ax`` (a 3-D
        Axes) draws every aspect into yours, ``path`` writes the picture.
        """
        from .aspects import _axes, _check_path, _mode_str, _save

        _check_path(path)
        if ax is not None and getattr(ax, "name", "") != "3d":
            raise MechanismError("ax: expected a 3-D Axes (fig.add_subplot(projection='3d'))")
        modes = list(dict.fromkeys(tuple(a.working_mode) for a in self.aspects))
        head = title or f"{self.mechanism}: {len(self.aspects)} generalized aspects"
        if ax is None and len(modes) > 1:
            from ..plot import _figure

            cols = min(4, len(modes))
            rows = -(-len(modes) // cols)
            fig = _figure(path, (4.2 * cols, 4.0 * rows))
            number = {id(a): k + 1 for k, a in enumerate(self.aspects)}
            for m, mode in enumerate(modes):
                sub = fig.add_subplot(rows, cols, m + 1, projection="3d")
                mine = [a for a in self.aspects if tuple(a.working_mode) == mode]
                self._draw(sub, mine, every, [number[id(a)] for a in mine])
                sub.set_title(f"working mode {_mode_str(mode)}", fontsize=10)
            fig.suptitle(head)
            fig.tight_layout()
        else:
            fig, ax, _ = _axes(ax, (7.5, 6.5), three_d=True, path=path)
            self._draw(ax, self.aspects, every, range(1, len(self.aspects) + 1))
            ax.set_title(head)
        if path is not None:
            _save(fig, path)
        return fig

    def _draw(self, ax: Any, aspects: list[Aspect3D], every: int, numbers: Any) -> None:
        small = len(aspects) <= 4
        for k, (a, num) in enumerate(zip(aspects, numbers)):
            color = f"C{k % 10}"
            label = (f"aspect {num}: det {'+' if a.det_sign > 0 else '-'}, "
                     f"volume {a.volume:.4g}")
            for i, (phi, f) in enumerate(a.sections[::max(1, every)]):
                R = np.vstack([f.outer, f.outer[:1]])
                ax.plot(R[:, 0], R[:, 1], np.full(len(R), phi), color=color,
                        lw=0.6 if small else 0.8, label=label if i == 0 else None)
        ax.set_xlabel(self.names[0])
        ax.set_ylabel(self.names[1])
        ax.set_zlabel(self.names[2] + " (rad)")
        ax.legend(loc="upper left", fontsize=7 if small else 8)


def _overlap(f: Face, g: Face) -> bool:
    """Do two faces (of neighbouring sections) overlap? Vertices of one inside the other,
    either way, or their interior points."""
    if (f.outer[:, 0].max() < g.outer[:, 0].min() or g.outer[:, 0].max() < f.outer[:, 0].min()
            or f.outer[:, 1].max() < g.outer[:, 1].min()
            or g.outer[:, 1].max() < f.outer[:, 1].min()):
        return False
    for a, b in ((f, g), (g, f)):
        P = a.outer if a.point is None else np.vstack([a.outer, a.point[None]])
        if np.any(point_in_face(b, P)):
            return True
    return False


class _FreeTest:
    """Is a configuration (x, y, phi) free in a working mode: every stroke within its
    limits, the legs' postures those of the mode (the signs of diag B) and det A of a given
    sign? The legs' closed-form inverses (the model's planar chart, every posture
    combination) and det A, diag B of the augmented system the sections label their faces
    with, vectorised."""

    def __init__(self, mech, model, limits) -> None:
        from ..model.charts import planar_chart
        from .continuation import augmented_system

        self.model = model
        self.chart = planar_chart(model)
        # the sections' system (at a fixed orientation): det A and diag B at full points
        turn = [model.na + i for i, a in enumerate(model.x_angle) if a]
        self.sys = augmented_system(mech, "parallel", tuple(turn))
        names = list(mech.active_names)
        self.lim = [(names.index(k), float(v[0]), float(v[1]))
                    for k, v in dict(limits or {}).items()]

    def aux(self, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """det A (N,) and diag B (N, na) at the rows of V: the system's Function mapped over
        power-of-two blocks through call buffers, the maps built once (by DM calls: 0.3 ms
        a call, a tenth of a 3-RPR's 3-D aspects)."""
        from ..model.compiled import LateCompiled, map_shared

        N, nv = V.shape
        n = 1 << max(0, (N - 1).bit_length())
        # compiled in the background, once per topology (the interpreted Function answers
        # meanwhile): a 3-RRR's (740 operations) took 2.2 us a point interpreted, and its
        # 3-D aspects spent 93 of 155 s here
        fn = self.sys.fn
        late = getattr(fn, "_late_aux", None)
        if late is None:
            late = fn._late_aux = LateCompiled(f"aux:{self.model.topology.key}", fn.aux)
        fm = late.mapped(n, lambda f, k: map_shared(f, f"aux_{k}", k, [1]))
        A = np.empty((n, nv))
        A[:N], A[N:] = V, V[:1]  # padding: a real point, no NaN
        d, b = fm(A.ravel(), self.model.p)
        return d[:N].copy(), b.reshape(n, self.model.na)[:N].copy()

    def vertical(self, P: np.ndarray, a: float, b: float, sign: int, mode: tuple[int, ...],
                 n: int = 24) -> np.ndarray:
        """For each point P (k, 2): free in working mode ``mode`` with det sign ``sign`` at
        n + 1 orientations from a to b."""
        k = len(P)
        ph = np.linspace(a, b, n + 1)
        X = np.zeros((k * len(ph), 3))
        X[:, 0] = np.repeat(P[:, 0], len(ph))
        X[:, 1] = np.repeat(P[:, 1], len(ph))
        X[:, 2] = ((np.tile(ph, k) + np.pi) % (2 * np.pi)) - np.pi
        free = np.zeros(len(X), bool)
        want = np.asarray(mode, dtype=int)
        for V, ok in self.chart.full_points(X):  # one posture combination at a time
            qa = V[:, :self.model.na]
            for j, lo, hi in self.lim:
                ok &= (qa[:, j] >= lo) & (qa[:, j] <= hi)
            idx = np.flatnonzero(ok)
            if not len(idx):
                continue
            d, B = self.aux(V[idx])
            good = (np.sign(d) == sign) & np.all(np.sign(B).astype(int) == want, axis=1)
            free[idx[good]] = True
        return free.reshape(k, len(ph)).all(axis=1)

    def label(self, V: np.ndarray) -> tuple[tuple[int, ...], int]:
        """The working mode and the sign of det A of a configuration V = (q_a, x)."""
        d, B = self.aux(np.asarray(V, dtype=float)[None])
        return tuple(int(v) for v in np.sign(B[0])), int(np.sign(d[0]))


@dataclass
class _Section:
    """What :func:`aspects3d` keeps of a section: its outcome and its faces
    (working mode, det sign, face, representative configuration)."""

    success: bool
    status: str
    message: str
    faces: list[tuple[tuple[int, ...], int, Face, np.ndarray]]
    #: some of its curves stopped early (stalled, max_steps, jumped to another curve)
    early: bool = False


class _Find:
    def __init__(self) -> None:
        self.up: dict[Any, Any] = {}

    def root(self, a):
        self.up.setdefault(a, a)
        while self.up[a] != a:
            self.up[a] = self.up[self.up[a]]
            a = self.up[a]
        return a

    def join(self, a, b) -> None:
        self.up[self.root(a)] = self.root(b)


def aspects3d(mech: Mechanism, **options: Any) -> Aspects3D:
    """The generalized aspects of a 3-DoF planar platform in (x, y, phi), linked from
    exact sections at ``slices`` orientations (see the module docstring).

    Parameters
    ----------
    mech : Mechanism
        A 3-DoF planar platform with distance legs (what :func:`optkin.aspects` takes with
        ``fixed={"phi": value}``).
    **options
        The options below, by keyword, over :data:`ASPECTS3D_DEFAULTS` (an unknown name
        raises :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    limits : dict name -> (lo, hi), optional
        Actuator strokes.
    bounds : [[lo, hi], [lo, hi]], optional
        A box in (x, y) (default: the reach of the legs).
    slices : int
        Sections spread evenly over [-pi, pi) before refinement.
    min_gap : float
        Smallest gap in phi the refinement bisects down to (rad).
    modes : bool
        Count the assembly modes each aspect holds at its representative q_a.
    tiny : float
        A face below this fraction of its section's largest area may be born or die
        between two sections without refinement.
    step : float, optional
        Largest continuation step of the sections' curves (scaled units; the step still
        adapts to their turning). By default 0.25 when every actuator is its leg's length
        (3-RPR: the volumes then agree with a 240^3 grid to 4e-4, in half the time of
        0.08), else the sections' own default 0.08 (legs with a driven revolute or slider
        add their serial singularity curves: a 3-RRR's inner circle, of radius
        ``|l1 - l2|``, which 0.25 does not resolve: its aspects fell apart into 64 pieces).
    vol_tol : float
        Gaps are also halved, down to ``min_gap``, where the estimated error of the
        integral over phi (:func:`_interval_errors`, summed over the aspects) exceeds this
        fraction of the aspects' total volume times the gap's share of the circle: the
        areas have kinked, steep stretches away from any birth, death, split or merge,
        where the even sections alone converge slowly. On the cuspidal 3-RPR the default
        1e-3 gives volumes within 1e-5 of the converged ones (123 sections, 3.8 s, against
        83 sections, 2.3 s and 4e-4 with ``inf``, which refines at the events only).
    time_limit : float
        Seconds (capped by the time budget); past it no gap is refined any more and the
        result says so (``success=False``, status ``"time_limit"``).

    Returns
    -------
    Aspects3D
    """
    from .._checks import check_mechanism, check_option
    from ..limits import Deadline, time_budget
    from ..solvers.common import merge_options

    who = "aspects3d"
    opts = merge_options(ASPECTS3D_DEFAULTS, options, who)

    def num(name: str, **kw: Any) -> Any:
        return check_option(opts, name, who, ASPECTS3D_DEFAULTS, **kw)

    limits, bounds, modes = opts["limits"], opts["bounds"], opts["modes"]
    min_gap = num("min_gap", lo=0.0, lo_open=True)
    tiny = num("tiny", lo=0.0)
    step = None if opts["step"] is None else num("step", lo=0.0, lo_open=True)
    vol_tol = num("vol_tol", lo=0.0, lo_open=True, finite=False)
    deadline = Deadline(min(num("time_limit", lo=0.0, lo_open=True), time_budget()))
    from .aspects import aspects

    t0 = time.perf_counter()
    slices = num("slices", integer=True, lo=4)
    check_mechanism(mech, "aspects3d")
    model = get_model(mech)
    turn = [n for n, a in zip(model.x_names, model.x_angle) if a]
    if model.na != 3 or len(turn) != 1 or model.nx != 3:
        raise MechanismError(f"aspects3d: {mech.name} is not a 3-DoF planar platform "
                             "(three actuators; unknowns x, y and one orientation)")
    from ..model.charts import planar_chart

    chart = planar_chart(model)
    if chart is None:
        raise MechanismError(f"aspects3d: {mech.name}'s legs are not distance constraints "
                             "with one actuator each (3-RPR, 3-RRR, 3-PRR): no planar chart")
    if step is None:
        # legs whose actuator is their length (3-RPR) have no serial singularity: the
        # sections' curves are the parallel ones and the strokes' circles, which 0.25
        # resolves (volumes within 4e-4 of a 240^3 grid, half the time of 0.08). Legs with
        # a driven revolute or slider (3-RRR, 3-PRR) add their serial singularity curves,
        # a 3-RRR's inner circle as small as |l1 - l2|: at 0.25 that (radius 1 in a mechanism of
        # size 10) was under-resolved, sections dropped faces of area 12 and the aspects
        # fell apart into 64 pieces; at 0.08 the voxel grid's 16
        step = 0.25 if bool(np.all(chart.length_actuated)) else None
    angle = turn[0]
    cache: dict[float, Any] = {}
    from .aspects import min_face_area
    from .continuation import DEFAULT_STEP

    floor = min_face_area(3.0 * float(step or DEFAULT_STEP) * model.length)

    def section(phi: float) -> _Section:
        if phi not in cache:  # only the faces are kept (a 3-RRR section's curves: ~20 MB)
            r = aspects(mech, fixed={angle: phi}, limits=limits, bounds=bounds, step=step)
            cache[phi] = _Section(r.success, r.status, r.message,
                                  [(a.working_mode, a.det_sign, a.face, a.v) for a in r.aspects],
                                  r.curves is not None and r.curves.stopped_early)
        return cache[phi]

    def faces(phi):
        return section(phi).faces

    def sliver(phi: float, i: int) -> bool:
        """Face i of the section at phi is about the sections' sliver size (or a tiny
        fraction of its largest face): one section may keep it and the next drop it."""
        big = max(f[2].area for f in faces(phi))
        return faces(phi)[i][2].area <= max(tiny * big, 2 * floor)

    free = _FreeTest(mech, model, limits)
    rng = np.random.default_rng(0)
    samples: dict[tuple[float, int], np.ndarray] = {}

    def inner(p: float, i: int) -> np.ndarray:
        """Points inside face i of the section at p (its interior point and up to 12
        drawn in its bounding box)."""
        key = (p, i)
        if key not in samples:
            f = faces(p)[i][2]
            lo, hi = f.outer.min(axis=0), f.outer.max(axis=0)
            P = lo + (hi - lo) * rng.uniform(size=(64, 2))
            P = P[point_in_face(f, P)][:12]
            if f.point is not None:
                P = np.vstack([f.point[None], P])
            samples[key] = P
        return samples[key]

    def links(a: float, b: float) -> tuple[list[tuple[int, int]], set[int], set[int]]:
        """Pairs (i, j) of faces of the sections at a and b joined by an overlap or by a
        segment in phi from an inner point that stays free (det sign and strokes kept,
        checked at 24 orientations of the gap); and the unmatched faces of each."""
        wa, wb = _wrap(a), _wrap(b)
        fa, fb = faces(wa), faces(wb)
        pairs = set()
        for i, (ma, da, f, _) in enumerate(fa):
            for j, (mb, db, g, _) in enumerate(fb):
                if ma == mb and da == db and _overlap(f, g):
                    pairs.add((i, j))
        for src, dst, p0, p1, flip in ((fa, fb, a, b, False), (fb, fa, b, a, True)):
            for i, (m0, d0, _, _) in enumerate(src):
                P = inner(_wrap(p0), i)
                if not len(P):
                    continue
                ok = free.vertical(P, p0, p1, d0, m0)
                if not ok.any():
                    continue
                for j, (m1, d1, g, _) in enumerate(dst):
                    if m1 == m0 and d1 == d0 and point_in_face(g, P[ok]).any():
                        pairs.add((j, i) if flip else (i, j))
        la = {i for i, _ in pairs}
        lb = {j for _, j in pairs}
        return sorted(pairs), set(range(len(fa))) - la, set(range(len(fb))) - lb

    phis = list(np.linspace(-np.pi, np.pi, int(slices), endpoint=False))
    # refine: bisect a gap across which a face of some size finds no partner (a birth or
    # death of a small face needs no refinement: it is one), down to min_gap
    work = [(phis[k], phis[k + 1] if k + 1 < len(phis) else phis[0] + 2 * np.pi)
            for k in range(len(phis))]
    done_gaps: list[tuple[float, float, list[tuple[int, int]]]] = []
    late = False
    arc: dict[tuple[float, int], float] = {}

    def grouped() -> list[list[tuple[float, int]]]:
        """The faces of every aspect so far, (phi, index) each: faces of neighbouring
        sections joined by the links of their gap."""
        find = _Find()
        for p in cache:
            for i in range(len(faces(p))):
                find.root((p, i))
        for a, b, pairs in done_gaps:
            for i, j in pairs:
                find.join((_wrap(a), i), (_wrap(b), j))
        groups: dict[Any, list] = {}
        for p in sorted(cache):
            for i in range(len(faces(p))):
                groups.setdefault(find.root((p, i)), []).append((p, i))
        return list(groups.values())

    def areas(members: list[tuple[float, int]], order: list[float]) -> np.ndarray:
        """An aspect's section areas at the orientations ``order`` (0 where it has none)."""
        area = dict.fromkeys(order, 0.0)
        for p, i in members:
            if (p, i) not in arc:
                arc[(p, i)] = face_arc_area(faces(p)[i][2])
            area[p] += arc[(p, i)]
        return np.array([area[p] for p in order])

    while True:
        while work:
            a, b = work.pop()
            if deadline.expired():  # out of time: the sections not yet traced stay untraced
                late = True
                if all(_wrap(q) in cache for q in (a, b)):
                    done_gaps.append((a, b, links(a, b)[0]))
                continue
            pairs, ua, ub = links(a, b)
            wa, wb = _wrap(a), _wrap(b)
            # a face near the sections' sliver threshold may be kept in one section and
            # dropped in the next: its lack of a partner is no event to locate
            large = any(not sliver(wa, i) for i in ua) or any(not sliver(wb, j) for j in ub)
            if not large or b - a <= min_gap:
                done_gaps.append((a, b, pairs))
                continue
            mid = 0.5 * (a + b)
            work += [(a, mid), (mid, b)]
        if not np.isfinite(vol_tol) or late or deadline.expired() or any(
                not section(p).success for p in cache):
            break
        # refine for the volumes: halve each gap whose share of the integral's estimated
        # error (:func:`_interval_errors`, summed over the aspects) exceeds its share
        # of vol_tol times the aspects' total volume
        order = sorted(cache)
        est = np.zeros(len(order))
        total = 0.0
        for members in grouped():
            if len(members) == 1 and sliver(*members[0]):
                continue
            e, v = _interval_errors(np.array(order), areas(members, order))
            est += e
            total += abs(v)
        h = np.diff(np.r_[order, order[0] + 2 * np.pi])
        coarse = {order[k] for k in np.flatnonzero(
            (est > vol_tol * total * h / (2 * np.pi)) & (h > 2 * min_gap))}
        if not coarse:
            break
        keep = []
        for a, b, pairs in done_gaps:
            if _wrap(a) in coarse:
                mid = 0.5 * (a + b)
                work += [(a, mid), (mid, b)]
            else:
                keep.append((a, b, pairs))
        done_gaps = keep
    bad = [section(p) for p in cache if not section(p).success]
    if bad:
        return Aspects3D(mech.name, [], np.array(sorted(cache)), False, bad[0].status,
                         f"a section failed: {bad[0].message}", time.perf_counter() - t0,
                         (model.x_names[0], model.x_names[1], angle))
    groups = grouped()
    order = sorted(cache)
    spacing = 2 * np.pi / int(slices)
    out: list[Aspect3D] = []
    slivers = 0
    for members in groups:
        if len(members) == 1:
            # a face of about the sections' sliver size (which one section keeps and the
            # next drops, so the refinement does not locate it) seen in one section only:
            # below the resolution, not an aspect (a 3-RRR's: areas 0.013-0.016 for a
            # floor of 0.013, 16 of them beside the grid's 16 aspects)
            if sliver(*members[0]):
                slivers += 1
                continue
        secs = [(p, faces(p)[i]) for p, i in members]
        vol = _integrate(np.array(order), areas(members, order))
        pts = np.vstack([f.outer for _, (_, _, f, _) in secs])
        ph = np.unique([p for p, _ in secs])
        # its extent in phi: the circle minus the largest gap between its sections (a
        # gap no wider than the sections' own spacing is no gap)
        gaps = np.diff(np.r_[ph, ph[0] + 2 * np.pi])
        g = int(np.argmax(gaps))
        if gaps[g] <= 1.01 * spacing:
            span = [-np.pi, np.pi]
        else:  # from the end of the largest gap round to its start (lo > hi: through pi)
            span = [ph[(g + 1) % len(ph)], ph[g]]
        bbox = np.array([[pts[:, 0].min(), pts[:, 0].max()], [pts[:, 1].min(), pts[:, 1].max()],
                         span])
        _, (wm, d, _, v) = max(secs, key=lambda s: s[1][2].area)
        out.append(Aspect3D(tuple(wm), int(d), vol, bbox, v.copy(),
                            [(p, f) for p, (_, _, f, _) in secs]))
    out.sort(key=lambda a: -a.volume)
    if modes:
        _count_modes(mech, free, out, order)
    n = len(out)
    # a section whose curves stopped early may lack faces or merge two (their areas still
    # add up): aspects then split or join wrongly. None did on the 3-RPR and 3-RRR of the
    # tests; a 3-RRR whose links are equal (legs folding onto their base joints) had such
    # sections near phi = +-1.4 and fell apart into 897 pieces
    early = [p for p in order if cache[p].early]
    msg = (f"{n} aspect(s) of {mech.name} in (x, y, {angle}) from {len(order)} sections "
           f"({int(slices)} even, {len(order) - int(slices)} added where the sections' faces "
           f"change or the integral over {angle} needed them); volumes {[round(a.volume, 6) for a in out]}"
           + (f"; {slivers} face(s) of the sections' sliver size seen in one section only "
              "(below the resolution) not counted" if slivers else "")
           + (f"; the curves of {len(early)} section(s) stopped early (stalled, max_steps or "
              f"jumped to another curve; the first at {angle} = {early[0]:.6g}): faces may be "
              "missing or merged there, so aspects may be split or joined wrongly; a smaller "
              "step may help" if early else "")
           + ("; refinement stopped at the time limit: counts may be wrong" if late else ""))
    status = TIME_LIMIT if late else INACCURATE if early else OPTIMAL
    return Aspects3D(mech.name, out, np.array(order), status == OPTIMAL, status, msg,
                     time.perf_counter() - t0, (model.x_names[0], model.x_names[1], angle))


def _wrap(q: float) -> float:
    """An angle in [-pi, pi) (the key of its section)."""
    return ((q + np.pi) % (2 * np.pi)) - np.pi


def _integrate(phi: np.ndarray, A: np.ndarray) -> float:
    """The integral over the circle of a function sampled at the sorted angles ``phi``
    (an aspect's section areas, 0 where it has none): the trapezoid rule less, on each
    interval, h^3 / 12 times the second derivative (the mean of the second divided
    differences at its two ends, where the function is present at the three points each
    needs). Areas are smooth between the sections the refinement put around births,
    deaths, splits and merges; there the intervals are short and the correction small."""
    h, F, D = _second_differences(phi, A)
    trap = float(np.sum(0.5 * h * (F[1:-1] + F[2:])))
    mid = 0.5 * (D[:-1] + D[1:])  # on the interval from phi[k] to phi[k + 1]
    corr = np.where(np.isfinite(mid), h ** 3 / 12.0 * mid, 0.0)
    return trap - float(np.sum(corr))


def _second_differences(phi: np.ndarray, A: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For samples ``A`` at the sorted angles ``phi`` round the circle: the width of each
    interval from ``phi[k]`` to the next (n), the samples padded periodically at both ends
    (n + 2: ``F[k + 1]`` is ``A[k]``), and the second divided difference at each sample,
    repeated at the end (n + 1: ``D[k]`` at ``phi[k]``), NaN where the function is not
    present (> 0) at all three points it needs."""
    n = len(phi)
    P = np.r_[phi[-1] - 2 * np.pi, phi, phi[0] + 2 * np.pi]
    F = np.r_[A[-1], A, A[0]]
    h = np.diff(P)  # h[k]: from P[k] to P[k + 1]
    d2 = 2 * ((F[2:] - F[1:-1]) / h[1:] - (F[1:-1] - F[:-2]) / h[:-1]) / (h[1:] + h[:-1])
    d2[(F[:-2] <= 0) | (F[1:-1] <= 0) | (F[2:] <= 0)] = np.nan
    return h[1:n + 1], F, np.r_[d2, d2[0]]


def _interval_errors(phi: np.ndarray, A: np.ndarray) -> tuple[np.ndarray, float]:
    """An estimate of the error of :func:`_integrate` on each interval (from ``phi[k]`` to
    the next, round the circle), and the integral. Where both ends have the second
    divided difference the correction uses, their mean stands for f'' on the interval:
    the error is then about h^3 / 24 times their difference (a kink in the area between
    them makes it large); where only one has it the interval is integrated by the plain
    trapezoid, whose error is about h^3 / 12 times that one; where neither has (a face born
    or dying: the events' own refinement) it is not estimated."""
    hk, _, D = _second_differences(phi, A)
    lo, hi = D[:-1], D[1:]
    both = np.isfinite(lo) & np.isfinite(hi)
    one = np.where(np.isfinite(lo), lo, np.where(np.isfinite(hi), hi, 0.0))
    err = np.where(both, hk ** 3 / 24 * np.abs(np.nan_to_num(lo - hi)),
                   hk ** 3 / 12 * np.abs(one))
    return err, _integrate(phi, A)


def _count_modes(mech, free: _FreeTest, out, order) -> None:
    """At each aspect's representative q_a, how many assembly modes lie in it (each mode of
    the aspect's working mode and det sign placed by the face containing it in the nearest
    section of its orientation)."""
    from ..solvers.enumerate import assembly_modes

    order = np.array(order)
    na = free.model.na
    for a in out:
        qa = a.v[:na]
        sols = assembly_modes(mech, qa)
        n = 0
        for s in sols:
            if free.label(np.r_[qa, s.x]) != (tuple(a.working_mode), a.det_sign):
                continue
            phi = float(_wrap(s.x[2]))
            p = order[int(np.argmin(np.abs(np.angle(np.exp(1j * (order - phi))))))]
            inside = [f for q, f in a.sections if q == p]
            if any(bool(point_in_face(f, s.x[None, :2])[0]) for f in inside):
                n += 1
        a.modes_at.append((qa.copy(), n))
