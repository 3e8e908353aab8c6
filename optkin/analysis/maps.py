"""Distance-to-singularity and manipulability maps over a 2-D slice, drawn as PNG.

:func:`singularity_map` samples a grid: for leg-described platforms over two task
coordinates (the others fixed), solving the inverse model leg by leg in one working mode;
for Khalil mechanisms over two active joints (the others fixed), solving the direct model
with warm starts along the grid. At each point it evaluates, from :func:`optkin.jacobians`
(dimensionless matrices, as in :func:`optkin.classify`):

* ``parallel``: the parallel margin of :func:`optkin.classify` (sigma_min of A, or of W_p
  for Khalil mechanisms, relative to the constraint Jacobian) - zero at a parallel
  (PSFK/MSFK) singularity;
* ``serial``: the serial margin of :func:`optkin.classify` (smallest leg margin
  |B_ii| / |[A_i, B_i]|, or the J1 margin of Khalil mechanisms) - zero at a serial one;
* ``distance``: min(parallel, serial);
* ``manipulability``: Yoshikawa's sqrt(det(J J^T)) of the scaled task Jacobian J_a.

:func:`plot_singularity_map` draws the grid (matplotlib, Agg backend) and writes a PNG.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model
from .velocity import jacobians

__all__ = ["SingularityMap", "singularity_map", "plot_singularity_map", "MEASURES"]

MEASURES = ("distance", "parallel", "serial", "manipulability")
_TASK_TO_TWIST = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}


@dataclass
class SingularityMap:
    """Sampled measures over a 2-D slice.

    Attributes
    ----------
    axes : (str, str)
        Names of the two sampled coordinates.
    u, v : ndarray
        Grid values along each axis.
    values : dict
        Measure name -> array (len(v), len(u)); NaN where no configuration exists.
    path : str or None
        The PNG written by :func:`plot_singularity_map`.
    """

    mech_name: str
    axes: tuple[str, str]
    u: np.ndarray
    v: np.ndarray
    values: dict[str, np.ndarray]
    fixed: dict[str, float] = field(default_factory=dict)
    path: str | None = None

    def __repr__(self) -> str:
        reach = int(np.isfinite(self.values["distance"]).sum()) if "distance" in self.values else 0
        return (f"SingularityMap({self.mech_name!r}, axes={self.axes}, grid {self.v.size} x "
                f"{self.u.size}, {reach} reachable point(s), path={self.path!r})")

    @property
    def reachable(self) -> np.ndarray:
        return np.isfinite(self.values["distance"])


def _measures(jac: Any) -> dict[str, float]:
    """The map's measures at one configuration: classify's margins and the manipulability."""
    from .singularity import classify

    mech = jac.mech
    model = get_model(mech)
    L = model.length
    act = np.array(mech.actuated)
    qa_scale = np.where(np.array(mech.revolute)[act], 1.0, L)
    rep = classify(mech, jac.q)
    par, ser = rep.margins["parallel"], rep.margins["serial"]
    if mech.kind == "legs":
        idx = {"vx": 0, "vy": 1, "vz": 2, "wx": 3, "wy": 4, "wz": 5}
        rows = [idx[n] for n in jac.twist_names]
        J = jac.J_a
    else:
        rows = [_TASK_TO_TWIST[t] for t in mech.task]
        J = jac.J_a[rows]
    J = np.array([1.0 / L if i < 3 else 1.0 for i in rows])[:, None] * J * qa_scale[None, :]
    sv = np.linalg.svd(J, compute_uv=False)
    return {"parallel": float(par), "serial": float(ser), "distance": float(min(par, ser)),
            "manipulability": float(np.prod(sv))}


def singularity_map(
    mech: Mechanism,
    u: Sequence[float],
    v: Sequence[float],
    axes: Sequence[str] | None = None,
    fixed: dict[str, float] | None = None,
    working_mode: Sequence[int] | None = None,
    guess: Any = None,
) -> SingularityMap:
    """Sample the singularity measures over the grid ``u x v``.

    Parameters
    ----------
    mech : Mechanism
    u, v : sequence of float
        Values of the two sampled coordinates.
    axes : (str, str), optional
        Platforms: two task coordinates (default the first two of ``mech.task``); Khalil
        mechanisms: two active joint names (default the first two).
    fixed : dict, optional
        Values of the other task coordinates (platforms; default the mechanism's home or 0)
        or of the other active joints (Khalil; default 0).
    working_mode : sequence of int, optional
        Platforms: the signs of diag(B) to follow (default: the first posture found).
    guess : optional
        Khalil mechanisms: a starting configuration for the first grid point.

    Returns
    -------
    SingularityMap
    """
    from ..solvers import forward, inverse
    from ..solvers.common import check_mechanism

    check_mechanism(mech, "singularity_map")
    u, v = _axis_values("u", u), _axis_values("v", v)
    fixed = dict(fixed or {})
    vals = {k: np.full((v.size, u.size), np.nan) for k in MEASURES}
    if mech.kind == "legs":
        names = list(mech.task)
        ax = tuple(axes) if axes is not None else (names[0], names[1])
        for a in ax:
            if a not in names:
                raise MechanismError(f"axes: {a!r} is not a task coordinate of {mech.name} "
                                     f"({names})")
        base = np.array(mech.home if mech.home is not None else np.zeros(len(names)), float)
        for k, val in fixed.items():
            if k not in names:
                raise MechanismError(f"fixed: {k!r} is not a task coordinate ({names})")
            base[names.index(k)] = float(val)
        mode = None if working_mode is None else tuple(int(s) for s in working_mode)
        for i, vv in enumerate(v):
            for j, uu in enumerate(u):
                t = base.copy()
                t[names.index(ax[0])] = uu
                t[names.index(ax[1])] = vv
                sols = inverse(mech, t)
                pick = None
                for s in sols:
                    if mode is None or s.working_mode == mode:
                        pick = s
                        break
                if pick is None:
                    continue
                if mode is None:
                    mode = pick.working_mode
                for k, m in _measures(jacobians(mech, pick)).items():
                    vals[k][i, j] = m
        fixed_out = {n: float(base[names.index(n)]) for n in names if n not in ax}
    else:
        names = list(mech.active_names)
        ax = tuple(axes) if axes is not None else (names[0], names[1] if len(names) > 1 else
                                                    names[0])
        for a in ax:
            if a not in names:
                raise MechanismError(f"axes: {a!r} is not an active joint of {mech.name} "
                                     f"({names})")
        base = np.zeros(len(names))
        for k, val in fixed.items():
            if k not in names:
                raise MechanismError(f"fixed: {k!r} is not an active joint ({names})")
            base[names.index(k)] = float(val)
        prev_row = guess
        for i, vv in enumerate(v):
            prev = prev_row
            for j, uu in enumerate(u):
                qa = base.copy()
                qa[names.index(ax[0])] = uu
                qa[names.index(ax[1])] = vv
                r = forward(mech, qa, guess=prev)
                if not r.success:
                    continue
                if j == 0:
                    prev_row = r
                prev = r
                for k, m in _measures(jacobians(mech, r)).items():
                    vals[k][i, j] = m
        fixed_out = {n: float(base[names.index(n)]) for n in names if n not in ax}
    return SingularityMap(mech.name, (str(ax[0]), str(ax[1])), u, v, vals, fixed_out)


def plot_singularity_map(
    mech: Mechanism,
    u: Sequence[float],
    v: Sequence[float],
    path: str,
    measure: str = "distance",
    log: bool = True,
    **kwargs: Any,
) -> SingularityMap:
    """Sample :func:`singularity_map` and draw ``measure`` as a PNG at ``path``.

    Singular curves appear as dark valleys (log10 of the measure); unreachable points are
    left blank. Extra keyword arguments go to :func:`singularity_map`.

    Parameters
    ----------
    mech : Mechanism
    u, v : sequence of float
        Grid values of the two sampled coordinates (at least two finite values each).
    path : str
        The PNG to write.
    measure : str
        One of ``"distance"``, ``"parallel"``, ``"serial"``, ``"manipulability"``.
    log : bool
        Draw log10 of the measure.
    **kwargs
        ``axes``, ``fixed``, ``working_mode``, ``guess`` of :func:`singularity_map`.

    Returns
    -------
    SingularityMap
        The sampled measures, with ``path`` set.

    Examples
    --------
    >>> import numpy as np, optkin, tempfile, os
    >>> m = optkin.mechanisms.five_bar(1, 1, 1, 1, 1)
    >>> with tempfile.TemporaryDirectory() as d:
    ...     sm = optkin.plot_singularity_map(m, np.linspace(-0.5, 1.5, 9),
    ...                                      np.linspace(0.2, 1.8, 9), os.path.join(d, "m.png"))
    ...     os.path.getsize(sm.path) > 0
    True
    """
    if measure not in MEASURES:
        raise MechanismError(f"measure: {measure!r} is not one of {list(MEASURES)}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sm = singularity_map(mech, u, v, **kwargs)
    Z = sm.values[measure]
    fig, axp = plt.subplots(figsize=(6, 5))
    with np.errstate(divide="ignore", invalid="ignore"):
        data = np.log10(np.maximum(Z, 1e-16)) if log else Z
    mesh = axp.pcolormesh(sm.u, sm.v, np.ma.masked_invalid(data), shading="auto",
                          cmap="viridis")
    cb = fig.colorbar(mesh, ax=axp)
    cb.set_label(("log10 " if log else "") + measure)
    if np.isfinite(data).sum() > 4:
        try:
            lev = np.nanpercentile(data, 5)
            axp.contour(sm.u, sm.v, np.ma.masked_invalid(data), levels=[lev], colors="w",
                        linewidths=0.8)
        except (ValueError, TypeError):
            pass
    axp.set_xlabel(sm.axes[0])
    axp.set_ylabel(sm.axes[1])
    fx = ", ".join(f"{k}={v:.3g}" for k, v in sm.fixed.items())
    axp.set_title(f"{mech.name}: {measure}" + (f" ({fx})" if fx else ""))
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    sm.path = str(path)
    return sm


def _axis_values(name: str, a: Any) -> np.ndarray:
    """The grid values of one axis: at least two finite numbers, else a MechanismError."""
    try:
        out = np.asarray(a, dtype=float)
    except (TypeError, ValueError):
        out = np.full(0, np.nan)
    if out.ndim != 1 or out.size < 2 or not np.all(np.isfinite(out)):
        raise MechanismError(
            f"{name}: expected a 1-D sequence of at least 2 finite grid values (e.g. "
            f"np.linspace(lo, hi, 21)), got {a!r}")
    return out
