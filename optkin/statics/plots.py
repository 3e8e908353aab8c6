"""Pictures of the statics analyses (PNG files; the figures stay out of pyplot)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._checks import show
from ..errors import StaticsError
from .results import CapabilityResult, WorkspaceResult

__all__ = ["plot_capability", "plot_workspace"]


def _subplots(figsize: tuple[float, float], path: object, ax: object):
    """(figure, axes, new): the caller's Axes, else a new figure: out of pyplot when it
    goes to a file (no backend switched under the caller, nothing left open), a pyplot
    figure otherwise (``plt.show()``, notebooks)."""
    if ax is not None:
        if not hasattr(ax, "plot") or not hasattr(ax, "figure"):
            raise StaticsError(f"ax: expected a matplotlib Axes, got {type(ax).__name__}")
        return ax.figure, ax, False
    from ..plot import _figure

    fig = _figure(path, figsize)
    return fig, fig.add_subplot(), True


def _dpi() -> int:
    from ..plot import DPI

    return DPI


def _check(res: object, cls: type, path: object, made_by: str) -> None:
    if not isinstance(res, cls):
        raise StaticsError(f"res: expected a {cls.__name__} (from {made_by}), got "
                           f"{type(res).__name__}")
    if path is not None and not (isinstance(path, (str, os.PathLike)) or hasattr(path, "write")):
        raise StaticsError(f"path: expected a file name (str or os.PathLike) for the PNG, a "
                           f"file object or None, got {type(path).__name__}")


def plot_capability(
    res: CapabilityResult,
    path: str | os.PathLike[str] | None = None,
    plane: Sequence[str] = ("fx", "fy"),
    title: str | None = None,
    exact: np.ndarray | None = None,
    *,
    ax: Any = None,
) -> Any:
    """Draw the capability polygon of ``res`` in the plane of two wrench components;
    returns the matplotlib Figure, written to ``path`` (a file name or file object) when
    given, drawn into ``ax`` when given.

    Directions whose other components are non-zero are skipped; unresisted directions are
    drawn at the origin in red, unbounded ones as arrows. ``exact`` (k, 2): the exact
    section of the capability polytope, drawn dashed.
    """
    _check(res, CapabilityResult, path, "capability / capability_polygon")
    names = list(res.wrench_names)
    if (isinstance(plane, (str, bytes)) or not isinstance(plane, Sequence) or len(plane) != 2
            or not all(isinstance(c, str) and c in names for c in plane)
            or plane[0] == plane[1]):
        raise StaticsError(f"plane: expected two different components of {names}, got "
                           f"{show(plane)}", path=("plane",))
    i, j = names.index(plane[0]), names.index(plane[1])
    other = [k for k in range(len(names)) if k not in (i, j)]
    D = res.directions
    inplane = np.all(np.abs(D[:, other]) < 1e-12, axis=1) if other else np.ones(len(D), bool)
    ang = np.arctan2(D[:, j], D[:, i])
    order = [k for k in np.argsort(ang) if inplane[k]]
    fig, ax, new = _subplots((5.2, 5.0), path, ax)
    fin = [k for k in order if np.isfinite(res.max[k])]
    if fin:
        pts = np.array([[res.points[k, i], res.points[k, j]] for k in fin])
        closed = np.vstack([pts, pts[:1]])
        ax.fill(closed[:, 0], closed[:, 1], alpha=0.25, color="C0")
        ax.plot(closed[:, 0], closed[:, 1], "-", color="C0", lw=1.5,
                label=f"capability LP ({len(fin)} directions)")
    if exact is not None and len(exact) >= 3:
        ex = np.vstack([exact, exact[:1]])
        ax.plot(ex[:, 0], ex[:, 1], "--", color="k", lw=1.0, label="polytope section")
    unres = [k for k in order if res.direction_status[k] == "unresisted"]
    if unres:
        ax.plot(0, 0, "o", color="C3", label=f"{len(unres)} unresisted directions")
    unb = [k for k in order if res.direction_status[k] == "unbounded"]
    for k in unb:
        ax.annotate("", xy=(D[k, i], D[k, j]), xytext=(0, 0),
                    arrowprops={"arrowstyle": "->", "color": "C2"})
    ax.plot(0, 0, "k+")
    ax.set_xlabel(plane[0])
    ax.set_ylabel(plane[1])
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or f"capability polygon ({res.status}, cond {res.cond:.3g})", fontsize=10)
    if new:
        fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=_dpi())
    return fig


def plot_workspace(
    res: WorkspaceResult, path: str | os.PathLike[str] | None = None,
    title: str | None = None, *, ax: Any = None,
) -> Any:
    """Map of the wrench-feasibility margin over the grid (or scatter of the poses); returns
    the matplotlib Figure, written to ``path`` when given, drawn into ``ax`` when given.

    Green: feasible (margin >= 0); the 0 contour bounds the wrench-feasible workspace;
    grey: unreachable; black crosses: singular (the set is not resisted).
    """
    _check(res, WorkspaceResult, path, "wrench_feasible_workspace")
    fig, ax, new = _subplots((6.0, 5.0), path, ax)
    P, M = res.poses, res.margin.copy()
    M[np.isneginf(M)] = np.nan
    lim = np.nanmax(np.abs(M)) if np.any(np.isfinite(M)) else 1.0
    lim = min(lim, 1.0) if lim > 0 else 1.0
    if res.grid_shape is not None:
        X = P[:, 0].reshape(res.grid_shape)
        Y = P[:, 1].reshape(res.grid_shape)
        Z = M.reshape(res.grid_shape)
        pc = ax.pcolormesh(X, Y, np.ma.masked_invalid(Z), cmap="RdYlGn", vmin=-lim, vmax=lim,
                           shading="nearest")
        if np.any(np.isfinite(Z)) and np.nanmin(Z) < 0 < np.nanmax(Z):
            ax.contour(X, Y, np.nan_to_num(Z, nan=-lim), levels=[0.0], colors="k",
                       linewidths=1.2)
            ax.plot([], [], "k-", lw=1.2, label="margin 0: boundary of the feasible set")
    else:
        pc = ax.scatter(P[:, 0], P[:, 1], c=M, cmap="RdYlGn", vmin=-lim, vmax=lim, s=18)
    st = np.array(res.point_status)
    un = st == "unreachable"
    if un.any():
        ax.plot(P[un, 0], P[un, 1], ".", color="0.6", ms=3, label="unreachable")
    sg = st == "singular"
    if sg.any():
        ax.plot(P[sg, 0], P[sg, 1], "kx", ms=4, label="not resisted (singular)")
    fig.colorbar(pc, ax=ax, label="margin (fraction of actuator limit left)")
    ax.set_xlabel(res.axes[0])
    ax.set_ylabel(res.axes[1])
    ax.set_aspect("equal", adjustable="box")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.12), fontsize=8, frameon=False,
                  ncols=3)
    ax.set_title(title or f"wrench-feasible workspace: {res.fraction:.0%} of reachable poses",
                 fontsize=10)
    if new:
        fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=_dpi())
    return fig
