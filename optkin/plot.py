"""Pictures of mechanisms in their configurations: matplotlib Figures, written to a file
when given a path (without pyplot), drawn into the caller's Axes when given one."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from ._dryrun import checkpoint
from .errors import MechanismError
from .limits import check_size
from .mechanism import Mechanism
from .results import KinResult

#: Memory per panel of :func:`draw` at 100 dpi, and the raster's part, which grows with
#: the square of the resolution (peak resident growth, VmHWM, of a fresh process: 1.1-1.3 MB
#: a panel at 100 dpi, 4.7 MB at 200); limits.SAFETY is applied on top.
_COST_PANEL, _COST_RASTER = 1.0e6, 1.25e6


__all__ = ["draw", "animate", "chain_points", "DPI"]


def _panel_cost(dpi: float) -> float:
    return _COST_PANEL + _COST_RASTER * (float(dpi) / 100.0) ** 2


#: Resolution of the PNG files :func:`draw` writes (dots per inch).
DPI = 200


def _figure(path: Any, size: tuple[float, float], layout: str | None = None) -> Any:
    """A new Figure: kept out of pyplot when it goes to a file (nothing to close, no
    backend switched under the caller, e.g. a notebook's); a pyplot figure otherwise, so
    that ``plt.show()`` and notebooks display it. Every picture of optkin starts here."""
    if path is not None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=size, layout=layout)
        FigureCanvasAgg(fig)
        return fig
    import matplotlib.pyplot as plt

    return plt.figure(figsize=size, layout=layout)


def _line(ax: Any, P: np.ndarray, spatial: bool, **kw: Any) -> Any:
    """One polyline (k, 3) in 2-D or 3-D Axes."""
    if spatial:
        return ax.plot(P[:, 0], P[:, 1], P[:, 2], **kw)[0]
    return ax.plot(P[:, 0], P[:, 1], **kw)[0]


def _fixed_joints(ax: Any, B: np.ndarray, spatial: bool, label: str | None) -> None:
    """The fixed joints as black triangles."""
    if spatial:
        ax.scatter(B[:, 0], B[:, 1], B[:, 2], marker="^", c="k", s=36, label=label)
    else:
        ax.scatter(B[:, 0], B[:, 1], marker="^", c="k", s=36, zorder=3, label=label)


def chain_points(mech: Mechanism, r: KinResult) -> list[np.ndarray]:
    """Polylines (arrays (k, 3)) of the mechanism's links at the configuration of ``r``:
    each leg from its base along its joints to its platform point, then the platform
    polygon (more than two legs); a Khalil table's links from each frame's antecedent
    (:func:`optkin.model.drawing.drawing`)."""
    from .solvers.common import check_mechanism, check_result_of

    check_mechanism(mech, "chain_points")
    if not isinstance(r, KinResult):
        raise MechanismError(f"r: expected a KinResult (from optkin.forward, inverse, "
                             f"assembly_modes, track), got {type(r).__name__}")
    check_result_of(mech, r, "r")
    checkpoint()  # validation stops here: every argument is checked
    return _drawing(mech, r).lines


def _drawing(mech: Mechanism, r: KinResult) -> Any:
    from .model import get_model
    from .model.drawing import drawing

    model = get_model(mech)
    pose = r.pose if model.platform is not None and r.pose is not None else None
    return drawing(model, r.q, pose)


def draw(
    mech: Mechanism,
    results: KinResult | Sequence[KinResult],
    path: str | os.PathLike[str] | None = None,
    title: str | None = None,
    *,
    ax: Any = None,
    dpi: float = DPI,
) -> Any:
    """Draw ``mech`` in one or several configurations; returns the matplotlib Figure.

    Parameters
    ----------
    mech : Mechanism
    results : KinResult or sequence of KinResult
        The configurations (from :func:`optkin.forward`, ``inverse``, ``assembly_modes``,
        ``track``); non-finite ones are left out.
    path : str or PathLike, optional
        Write the figure to this file (PNG, or any format matplotlib knows from the
        suffix); nothing is written without it.
    title : str, optional
        The figure's title (default: the mechanism's name and the number of
        configurations).
    ax : matplotlib Axes, optional
        Draw every configuration into this Axes (3-D Axes for a spatial mechanism),
        overlaid in turn in the colours of the cycle; by default a new figure has one panel
        per configuration (at most four a row) on shared limits.
    dpi : float
        Resolution of the written file (default :data:`DPI`).

    Notes
    -----
    In each panel the legs are drawn from their fixed joints (black triangles) to the
    platform, whose polygon is closed and shaded (planar) or outlined (spatial); a Khalil
    table's links join each frame to its antecedent. Axes are equal in every direction and
    labelled x, y (and z) in the mechanism's length unit. Memory: about 5 MB a panel at
    200 dpi (1 MB plus the raster, which grows with dpi squared),
    checked against the memory budget of :mod:`optkin.limits` before drawing.
    """
    from .solvers.common import check_mechanism, check_result_of

    check_mechanism(mech, "draw")
    if path is not None and (not isinstance(path, (str, os.PathLike)) or not os.fspath(path)):
        raise MechanismError(f"path: expected a file name (str or os.PathLike) or None, "
                             f"got {type(path).__name__}")
    if isinstance(dpi, bool) or not isinstance(dpi, (int, float)) or not 10 <= dpi <= 2000:
        raise MechanismError(f"dpi: expected a number in [10, 2000], got {dpi!r}")
    cost = _panel_cost(dpi) if ax is None else _COST_PANEL
    if isinstance(results, KinResult):
        rs = [results]
    elif isinstance(results, (str, bytes)) or not hasattr(results, "__iter__"):
        rs = [results]  # refused below
    else:
        if hasattr(results, "__len__"):  # before making a list of it
            check_size("draw", "len(results)", len(results), cost, lo=0,
                       unit="one panel of the picture")
        rs = list(results)
    check_size("draw", "len(results)", len(rs), cost, lo=0,
               unit="one panel of the picture")
    if title is not None and not isinstance(title, str):
        raise MechanismError(f"title: expected a string, got {type(title).__name__}")
    if not all(isinstance(r, KinResult) for r in rs):
        raise MechanismError(
            "results: expected a KinResult or a sequence of them (from optkin.forward, "
            f"inverse, assembly_modes, track), got {type(results).__name__}")
    for r in rs:
        check_result_of(mech, r, "results")
    if ax is not None and not hasattr(ax, "plot"):
        raise MechanismError(f"ax: expected a matplotlib Axes, got {type(ax).__name__}")
    checkpoint()  # validation stops here: every argument is checked
    rs = [r for r in rs if np.all(np.isfinite(r.q))]
    drawings = [_drawing(mech, r) for r in rs]
    if drawings:
        spatial = drawings[0].dim == 3
    else:
        from .model import get_model

        plat = get_model(mech).platform
        spatial = plat is not None and plat.space_dim == 3
    if ax is not None and spatial != (getattr(ax, "name", "") == "3d"):
        raise MechanismError(
            "ax: a spatial mechanism needs 3-D Axes (projection='3d') and a planar one 2-D "
            f"Axes; got {'3-D' if getattr(ax, 'name', '') == '3d' else '2-D'} Axes for "
            f"{'a spatial' if spatial else 'a planar'} mechanism")
    lims = _common_limits(drawings, 3 if spatial else 2)
    if ax is not None:
        fig = ax.figure
        for i, (r, d) in enumerate(zip(rs, drawings)):
            _panel(ax, d, spatial, f"C{i % 10}" if len(rs) > 1 else None,
                   _label(i, r) if len(rs) > 1 else None, legend=i == 0)
        _frame_axes(ax, spatial, lims)
        if len(rs) > 1:
            ax.legend(fontsize=7, loc="best")
        if title is not None:
            ax.set_title(title)
    else:
        n = max(1, len(rs))
        cols = min(4, n)
        rows = (n + cols - 1) // cols
        fig = _figure(path, (3.8 * cols, 3.6 * rows + 0.4))
        for i in range(n):
            a = fig.add_subplot(rows, cols, i + 1, projection="3d" if spatial else None)
            if i >= len(rs):
                a.set_title("no solution")
                continue
            _panel(a, drawings[i], spatial, None, None, legend=i == 0)
            _frame_axes(a, spatial, lims)
            a.set_title(_label(i, rs[i]), fontsize=9)
        if drawings:
            handles, labels = fig.axes[0].get_legend_handles_labels()
            fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8,
                       frameon=False)
        fig.suptitle(title or f"{mech.name}: {len(rs)} configuration(s)")
        fig.tight_layout(rect=(0, 0.06 if drawings else 0, 1, 1))
    if path is not None:
        path = os.fspath(path)
        try:
            fig.savefig(path, dpi=dpi)
        except OSError as e:
            raise MechanismError(f"path: cannot write {path!r}: {e.strerror or e}") from None
    return fig


def animate(
    mech: Mechanism,
    motion: Any,
    path: str | os.PathLike[str] | None = None,
    *,
    frames: int | None = None,
    fps: float = 15,
    dpi: float = 100,
    title: str | None = None,
) -> Any:
    """The mechanism moving through ``motion``: a matplotlib ``FuncAnimation``, written to
    ``path`` when given (``.gif`` with pillow, ``.mp4`` with ffmpeg when installed).

    Parameters
    ----------
    mech : Mechanism
    motion : sequence of KinResult, or BatchResult
        The configurations in order: :func:`optkin.track`'s result, a list of
        :class:`~optkin.results.KinResult`, or :func:`optkin.forward_batch`'s result.
        Configurations that did not succeed are left out (the title counts them).
    path : str or PathLike, optional
        Where to write the animation; without it nothing is written (in a notebook,
        ``IPython.display.HTML(anim.to_jshtml())`` shows it).
    frames : int, optional
        At most this many frames, evenly spaced along the motion (default: every
        configuration, up to 200).
    fps : float
        Frames per second of the written file.
    dpi : float
        Resolution of the written file.
    title : str, optional
        Printed above the frame counter (default: the mechanism's name).

    The axes hold the whole motion (equal scales; 3-D for spatial mechanisms); the path of
    the platform's origin is drawn as it goes (for mechanisms with a platform).
    """
    from matplotlib.animation import FuncAnimation

    from .solvers.common import check_mechanism, check_result_of

    check_mechanism(mech, "animate")
    if path is not None:
        if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
            raise MechanismError(f"path: expected a file name (str or os.PathLike) or None, "
                                 f"got {type(path).__name__}")
        suffix = os.path.splitext(os.fspath(path))[1].lower()
        if suffix not in (".gif", ".mp4"):
            raise MechanismError(f"path: expected a .gif or .mp4 file name, got "
                                 f"{os.fspath(path)!r}; give the animation one of those suffixes")
    if hasattr(motion, "result") and hasattr(motion, "qa") and hasattr(motion, "closed"):
        ok = np.flatnonzero(np.asarray(motion.closed, dtype=bool))
        rs: list[Any] = [motion.result(int(i)) for i in ok]
        n_all = len(motion.closed)
    elif isinstance(motion, KinResult):
        rs, n_all = [motion], 1
    elif isinstance(motion, (str, bytes)) or not hasattr(motion, "__iter__"):
        raise MechanismError("motion: expected a sequence of KinResult (optkin.track) or a "
                             f"BatchResult (optkin.forward_batch), got {type(motion).__name__}")
    else:
        rs = list(motion)
        n_all = len(rs)
        if not all(isinstance(r, KinResult) for r in rs):
            raise MechanismError(
                "motion: expected a sequence of KinResult (optkin.track) or a BatchResult "
                "(optkin.forward_batch); found another object in the sequence")
        for r in rs:
            check_result_of(mech, r, "motion")
        rs = [r for r in rs if r.success and np.all(np.isfinite(r.q))]
    if frames is not None:
        if isinstance(frames, bool) or not isinstance(frames, (int, np.integer)) or frames < 1:
            raise MechanismError(f"frames: expected a positive integer, got {frames!r}")
    for name, v, lo, hi in (("fps", fps, 0.1, 240), ("dpi", dpi, 10, 2000)):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
            raise MechanismError(f"{name}: expected a number in [{lo}, {hi}], got {v!r}")
    if title is not None and not isinstance(title, str):
        raise MechanismError(f"title: expected a string, got {type(title).__name__}")
    if not rs:
        raise MechanismError("motion: no configuration succeeded; nothing to animate")
    k = min(len(rs), 200 if frames is None else int(frames))
    check_size("animate", "frames", k, _panel_cost(dpi), lo=1, unit="one frame")
    checkpoint()  # validation stops here: every argument is checked
    idx = np.unique(np.linspace(0, len(rs) - 1, k).round().astype(int))
    draws = [_drawing(mech, rs[i]) for i in idx]
    spatial = draws[0].dim == 3
    lims = _common_limits(draws, 3 if spatial else 2)
    fig = _figure(path, (5.4, 5.0))
    ax = fig.add_subplot(projection="3d" if spatial else None)
    _frame_axes(ax, spatial, lims)
    if len(draws[0].base):
        _fixed_joints(ax, draws[0].base, spatial, "fixed joints")

    def new_line(**kw):
        return _line(ax, np.zeros((0, 3)), spatial, **kw)

    d0 = draws[0]
    legs = [new_line(color="C0", lw=2, marker="o", ms=3.5, label="leg chains" if j == 0 else None)
            for j in range(len(d0.legs))]
    plat = new_line(color="C1", lw=2.2, label="platform") if d0.platform is not None else None
    links = [new_line(color="C2", lw=2, marker="o", ms=3.5, label="links" if j == 0 else None)
             for j in range(len(d0.links))]
    poses = [rs[i].pose for i in idx]
    has_trail = all(P is not None for P in poses) and d0.platform is not None
    trail = (new_line(color="0.5", lw=1, ls=":", label="platform origin")
             if has_trail else None)
    origins = np.array([np.asarray(P)[:3, 3] for P in poses]) if has_trail else None
    ax.legend(loc="upper right", fontsize=7)
    head = title or mech.name
    text = ax.set_title("")

    def put(line, P):
        line.set_data(P[:, 0], P[:, 1])
        if spatial:
            line.set_3d_properties(P[:, 2])

    def update(f):
        d = draws[f]
        for ln, P in zip(legs, d.legs):
            put(ln, P)
        if plat is not None and d.platform is not None:
            put(plat, d.platform)
        for ln, P in zip(links, d.links):
            put(ln, P)
        if trail is not None:
            put(trail, origins[:f + 1])
        text.set_text(f"{head}: {idx[f] + 1} / {len(rs)}"
                      + (f" ({n_all - len(rs)} left out)" if n_all > len(rs) else ""))
        return [*legs, *links, *([plat] if plat is not None else []),
                *([trail] if trail is not None else []), text]

    update(0)
    anim = FuncAnimation(fig, update, frames=len(draws), interval=1000.0 / fps, blit=False)
    if path is not None:
        from matplotlib import animation

        out = os.fspath(path)
        if out.lower().endswith(".mp4"):
            if not animation.writers.is_available("ffmpeg"):
                raise MechanismError(f"path: writing {out!r} needs ffmpeg, which is not "
                                     "installed; write a .gif instead (pillow)")
            writer: Any = animation.FFMpegWriter(fps=fps)
        else:
            writer = animation.PillowWriter(fps=fps)
        try:
            anim.save(out, writer=writer, dpi=dpi)
        except OSError as e:
            raise MechanismError(f"path: cannot write {out!r}: {e.strerror or e}") from None
    return anim


def _label(i: int, r: KinResult) -> str:
    label = f"#{i + 1}"
    if r.working_mode is not None:
        label += " wm " + "".join("+" if s > 0 else "-" for s in r.working_mode)
    if not r.success:
        label += " (failed)"
    return label


def _panel(ax: Any, d: Any, spatial: bool, color: str | None, label: str | None,
           legend: bool) -> None:
    """One configuration: legs, platform (closed; shaded in the plane), links, fixed
    joints; the legend's labels on the first configuration only."""
    def lab(text):
        return (label if label is not None and text == "leg chains" else
                text if legend and label is None else None)

    def line(P, **kw):
        return _line(ax, P, spatial, **kw)

    leg_c = color or "C0"
    for j, P in enumerate(d.legs):
        line(P, color=leg_c, lw=2, marker="o", ms=3.5, label=lab("leg chains") if j == 0 else None)
    if d.platform is not None:
        P = d.platform
        pc = color or "C1"
        line(P, color=pc, lw=2.2, label=lab("platform"))
        if not spatial:
            ax.fill(P[:, 0], P[:, 1], color=pc, alpha=0.18, lw=0)
    for j, P in enumerate(d.links):
        line(P, color=color or "C2", lw=2, marker="o", ms=3.5,
             label=lab("links") if j == 0 else None)
    if len(d.base) > 2 and d.platform is not None:  # the base polygon, dashed
        from .model.drawing import _polygon

        line(_polygon(np.asarray(d.base, dtype=float)), color="0.35", lw=1.2, ls="--",
             label=lab("base"))
    if len(d.base):
        _fixed_joints(ax, d.base, spatial, lab("fixed joints"))


def _frame_axes(ax: Any, spatial: bool, lims: list[tuple[float, float]]) -> None:
    """Equal scales in every direction, shared limits, labelled axes."""
    ax.set_xlim(*lims[0])
    ax.set_ylim(*lims[1])
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    if spatial:
        ax.set_zlim(*lims[2])
        ax.set_zlabel("z")
        ax.set_box_aspect((1, 1, 1))
    else:
        ax.set_aspect("equal", adjustable="box")
        ax.grid(alpha=0.3)


def _common_limits(drawings: Sequence[Any], dim: int = 2) -> list[tuple[float, float]]:
    """Shared limits for every panel (a cube: equal scales), so configurations compare at
    a glance."""
    pts = [np.vstack(d.lines) for d in drawings if d.lines]
    if not pts:
        return [(-1.0, 1.0)] * dim
    P = np.vstack(pts)[:, :dim]
    lo, hi = P.min(axis=0), P.max(axis=0)
    c, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-9) * 1.1
    return [(c[k] - half, c[k] + half) for k in range(dim)]
