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


def _panel_cost(dpi: float) -> float:
    return _COST_PANEL + _COST_RASTER * (float(dpi) / 100.0) ** 2

__all__ = ["draw", "chain_points", "DPI"]


#: Resolution of the PNG files :func:`draw` writes (dots per inch).
DPI = 200


def _figure(path: Any, size: tuple[float, float]) -> Any:
    """A new Figure: kept out of pyplot when it goes to a file (nothing to close, no GUI
    backend chosen for the caller); a pyplot figure otherwise, so that ``plt.show()`` and
    notebooks display it."""
    if path is not None:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=size)
        FigureCanvasAgg(fig)
        return fig
    import matplotlib.pyplot as plt

    return plt.figure(figsize=size)


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
        return (label if label is not None and text == "legs" else
                text if legend and label is None else None)

    def line(P, **kw):
        if spatial:
            return ax.plot(P[:, 0], P[:, 1], P[:, 2], **kw)
        return ax.plot(P[:, 0], P[:, 1], **kw)

    leg_c = color or "C0"
    for j, P in enumerate(d.legs):
        line(P, color=leg_c, lw=2, marker="o", ms=3.5, label=lab("legs") if j == 0 else None)
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
        B = d.base
        kw = {"marker": "^", "c": "k", "s": 36, "label": lab("fixed joints")}
        if spatial:
            ax.scatter(B[:, 0], B[:, 1], B[:, 2], **kw)
        else:
            ax.scatter(B[:, 0], B[:, 1], zorder=3, **kw)


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
