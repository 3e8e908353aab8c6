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
    """Polylines (arrays (k, 3)) of the mechanism's links at the configuration of ``r``."""
    from .solvers.common import check_mechanism, check_result_of

    check_mechanism(mech, "chain_points")
    if not isinstance(r, KinResult):
        raise MechanismError(f"r: expected a KinResult (from optkin.forward, inverse, "
                             f"assembly_modes, track), got {type(r).__name__}")
    check_result_of(mech, r, "r")
    checkpoint()  # validation stops here: every argument is checked
    lines: list[np.ndarray] = []
    if mech.kind == "khalil":
        qmap = dict(zip(mech.joint_names, r.q))
        table = mech.table
        origin = {0: np.zeros(3)}
        for f in table.frames:
            origin[f.j] = table.transform_0(f.j, qmap)[:3, 3]
        for f in table.frames:
            lines.append(np.array([origin[f.a], origin[f.j]]))
        return lines
    T = r.pose
    R, p = T[:3, :3], T[:3, 3]
    plat = []
    k = 0
    for leg in mech.legs:
        n = len(leg.joint_names)
        q = r.q[k:k + n]
        k += n
        A = np.pad(leg.base, (0, 3 - leg.base.size))
        P = p + R @ np.pad(leg.platform, (0, 3 - leg.platform.size))
        pts = [A]
        if leg.type == "RRR":
            l1 = leg.lengths[0]
            pts.append(A + l1 * np.array([np.cos(q[0]), np.sin(q[0]), 0.0]))
        elif leg.type in ("RUS", "RSS"):
            la = leg.lengths[0]
            w = np.cross(leg.axis, leg.arm)
            pts.append(A + la * (np.cos(q[0]) * leg.arm + np.sin(q[0]) * w))
        pts.append(P)
        lines.append(np.array(pts))
        plat.append(P)
    if len(plat) > 2:
        lines.append(np.array(plat + [plat[0]]))
    return lines


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
    spatial = not (mech.planar or (mech.kind == "khalil" and _is_planar_khalil(mech, rs)))
    fig = plt.figure(figsize=(3.6 * cols, 3.4 * rows))
    lims = _common_limits(mech, rs)
    for i in range(n):
        if spatial:
            ax = fig.add_subplot(rows, cols, i + 1, projection="3d")
        else:
            ax = fig.add_subplot(rows, cols, i + 1)
        if i >= len(rs):
            ax.set_title("no solution")
            continue
        r = rs[i]
        for j, line in enumerate(chain_points(mech, r)):
            style: dict[str, Any] = {"lw": 2, "marker": "o", "ms": 4}
            color = "C0" if mech.kind == "legs" and j < len(mech.legs) else "C1"
            if spatial:
                ax.plot(line[:, 0], line[:, 1], line[:, 2], color=color, **style)
            else:
                ax.plot(line[:, 0], line[:, 1], color=color, **style)
        if mech.kind == "legs":  # fixed joints: black triangles
            base = np.array([np.pad(leg.base, (0, 3 - leg.base.size)) for leg in mech.legs])
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


def _is_planar_khalil(mech: Mechanism, rs: Sequence[KinResult]) -> bool:
    if not rs:
        return False
    pts = np.vstack(chain_points(mech, rs[0]))
    return bool(np.ptp(pts[:, 2]) < 1e-9)


def _common_limits(mech: Mechanism, rs: Sequence[KinResult]) -> list[tuple[float, float]]:
    """Shared x/y limits for every panel, so configurations compare at a glance."""
    pts = [np.vstack(chain_points(mech, r)) for r in rs]
    if not pts:
        return [(-1.0, 1.0), (-1.0, 1.0)]
    P = np.vstack(pts)
    lo, hi = P.min(axis=0), P.max(axis=0)
    c, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1e-9) * 1.1
    return [(c[0] - half, c[0] + half), (c[1] - half, c[1] + half)]
