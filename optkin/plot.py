"""Pictures of mechanisms in their configurations (PNG files through matplotlib's Agg)."""

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

#: Measured memory per panel of :func:`draw` (peak resident growth, VmHWM, of a fresh
#: process: its Axes, lines and share of the PNG raster, about 1.1 MB planar and 1.3 MB
#: spatial); limits.SAFETY is applied on top.
_COST_PANEL = 2.0e6

__all__ = ["draw", "chain_points"]


def _mpl():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


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
    path: str | os.PathLike[str],
    title: str | None = None,
) -> str:
    """Draw ``mech`` in one or several configurations (one panel each) to a PNG file.

    Returns the path written. Memory: about 2 MB per panel (one panel per configuration),
    checked against the memory budget of :mod:`optkin.limits` before drawing.
    """
    from .solvers.common import check_mechanism, check_result_of

    check_mechanism(mech, "draw")
    if not isinstance(path, (str, os.PathLike)) or not os.fspath(path):
        raise MechanismError(f"path: expected a file name (str or os.PathLike) for the PNG, "
                             f"got {type(path).__name__}")
    if isinstance(results, KinResult):
        rs = [results]
    elif isinstance(results, (str, bytes)) or not hasattr(results, "__iter__"):
        rs = [results]  # refused below
    else:
        if hasattr(results, "__len__"):  # before making a list of it
            check_size("draw", "len(results)", len(results), _COST_PANEL, lo=0,
                       unit="one panel of the picture")
        rs = list(results)
    check_size("draw", "len(results)", len(rs), _COST_PANEL, lo=0,
               unit="one panel of the picture")
    if title is not None and not isinstance(title, str):
        raise MechanismError(f"title: expected a string, got {type(title).__name__}")
    if not all(isinstance(r, KinResult) for r in rs):
        raise MechanismError(
            "results: expected a KinResult or a sequence of them (from optkin.forward, "
            f"inverse, assembly_modes, track), got {type(results).__name__}")
    for r in rs:
        check_result_of(mech, r, "results")
    checkpoint()  # validation stops here: every argument is checked
    plt = _mpl()
    rs = [r for r in rs if np.all(np.isfinite(r.q))]
    n = max(1, len(rs))
    cols = min(4, n)
    rows = (n + cols - 1) // cols
    drawings = [_drawing(mech, r) for r in rs]
    if drawings:
        spatial = drawings[0].dim == 3
    else:
        from .model import get_model

        plat = get_model(mech).platform
        spatial = plat is not None and plat.space_dim == 3
    fig = plt.figure(figsize=(3.6 * cols, 3.4 * rows))
    lims = _common_limits(drawings)
    for i in range(n):
        if spatial:
            ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
        else:
            ax = fig.add_subplot(rows, cols, i + 1)
        if i >= len(rs):
            ax.set_title("no solution")
            continue
        r = rs[i]
        d = drawings[i]
        for j, line in enumerate(d.lines):
            style: dict[str, Any] = {"lw": 2, "marker": "o", "ms": 4}
            color = "C0" if j < len(d.legs) else "C1"  # legs, then platform and links
            if spatial:
                ax.plot(line[:, 0], line[:, 1], line[:, 2], color=color, **style)
            else:
                ax.plot(line[:, 0], line[:, 1], color=color, **style)
        if len(d.base):  # fixed joints: black triangles
            base = d.base
            if spatial:
                ax.scatter(base[:, 0], base[:, 1], base[:, 2], marker="^", c="k", s=30)
            else:
                ax.scatter(base[:, 0], base[:, 1], marker="^", c="k", s=40, zorder=3)
        if not spatial:
            ax.set_xlim(*lims[0])
            ax.set_ylim(*lims[1])
            ax.set_aspect("equal", adjustable="box")
            ax.grid(alpha=0.3)
        label = f"#{i + 1}"
        if r.working_mode is not None:
            label += " wm " + "".join("+" if s > 0 else "-" for s in r.working_mode)
        if not r.success:
            label += " (failed)"
        ax.set_title(label, fontsize=9)
    fig.suptitle(title or f"{mech.name}: {len(rs)} configuration(s)")
    fig.tight_layout()
    path = os.fspath(path)
    try:
        fig.savefig(path, dpi=100)
    except OSError as e:
        raise MechanismError(f"path: cannot write the PNG {path!r}: {e.strerror or e}") from None
    finally:
        plt.close(fig)
    return path


def _common_limits(drawings: Sequence[Any]) -> list[tuple[float, float]]:
    """Shared x/y limits for every panel, so configurations compare at a glance."""
    pts = [np.vstack(d.lines) for d in drawings if d.lines]
    if not pts:
        return [(-1.0, 1.0), (-1.0, 1.0)]
    P = np.vstack(pts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    c, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-9) * 1.1
    return [(c[0] - half, c[0] + half), (c[1] - half, c[1] + half)]
