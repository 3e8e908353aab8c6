"""Distance-to-singularity and manipulability maps over a 2-D slice, drawn as PNG.

:func:`singularity_map` samples a grid: for platforms (models whose poses are task
coordinates) over two task coordinates (the others fixed), solving the inverse model leg
by leg in one working mode; for Khalil mechanisms over two active joints (the others
fixed), solving the direct model with warm starts along the grid. At each point it
evaluates, from :func:`optkin.jacobians` (dimensionless matrices, as in
:func:`optkin.classify`):

* ``parallel``: the parallel margin of :func:`optkin.classify` (sigma_min of A, or of W_p
  for Khalil mechanisms, relative to the constraint Jacobian) - zero at a parallel
  (PSFK/MSFK) singularity;
* ``serial``: the serial margin of :func:`optkin.classify` (smallest leg margin
  |B_ii| / |[A_i, B_i]|, or the J1 margin of Khalil mechanisms) - zero at a serial one;
* ``distance``: min(parallel, serial);
* ``manipulability``: Yoshikawa's sqrt(det(J J^T)) of the scaled task Jacobian J_a.

:func:`plot_singularity_map` draws the grid (matplotlib) and writes a PNG.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_float, as_matrix, as_vector
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..limits import Deadline, check_size, show
from ..mechanism import Mechanism
from ..model import get_model
from ..model.analysis import task_rows
from ..results import OPTIMAL, TIME_LIMIT, KinResult, jsonable
from .velocity import jacobians

__all__ = ["SingularityMap", "singularity_map", "plot_singularity_map", "MEASURES"]

MEASURES = ("distance", "parallel", "serial", "manipulability")

#: What each measure is, for the colour bar (classify's relative margins)
_MEASURE_LABELS = {
    "distance": "margin to the nearest singularity (min of parallel, serial)",
    "parallel": r"parallel margin ($\sigma_{min}(A)$ / $\|[A\ B]\|$, scaled)",
    "serial": r"serial margin (least leg's $|B_i|$ / $|[A_i\ B_i]|$)",
    "manipulability": "manipulability (product of singular values)",
}


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
        The file :meth:`plot` or :func:`plot_singularity_map` last wrote.
    figure : matplotlib Figure or None
        The picture :func:`plot_singularity_map` drew (not part of :meth:`to_dict`).
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"`` when every grid point was
        sampled (unreachable points are part of the answer: NaN), ``"time_limit"`` when
        the time budget stopped the sampling; the message counts the reachable points.
    """

    mech_name: str
    axes: tuple[str, str]
    u: np.ndarray
    v: np.ndarray
    values: dict[str, np.ndarray]
    fixed: dict[str, float] = field(default_factory=dict)
    path: str | None = None
    success: bool = True
    status: str = OPTIMAL
    message: str = ""
    figure: Any = field(default=None, repr=False, compare=False)

    def __repr__(self) -> str:
        reach = int(np.isfinite(self.values["distance"]).sum()) if "distance" in self.values else 0
        return (f"SingularityMap({self.mech_name!r}, axes={self.axes}, grid {self.v.size} x "
                f"{self.u.size}, {reach} reachable point(s), path={self.path!r})")

    @property
    def reachable(self) -> np.ndarray:
        """Where a configuration was found (the measures are finite)."""
        return np.isfinite(self.values["distance"])

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`: NaN of unreachable points
        becomes None)."""
        return jsonable({"mechanism": self.mech_name, "success": self.success,
                         "status": self.status, "message": self.message,
                         "axes": list(self.axes), "u": self.u, "v": self.v,
                         "fixed": self.fixed, "values": self.values, "path": self.path,
                         "reachable": int(np.sum(self.reachable))})

    def plot(self, measure: str = "distance", log: bool = True, *, ax: Any = None,
             path: Any = None, title: str | None = None) -> Any:
        """Draw ``measure`` over the grid; returns the matplotlib Figure.

        Singular curves appear as dark valleys (log10 of the measure); unreachable points
        are left blank. ``ax`` draws into your Axes (a colour bar is added beside it),
        ``path`` writes the picture (PNG, SVG, PDF, ... by the suffix, at
        :data:`optkin.plot.DPI`).
        """
        _check_picture(measure, log, path)
        if measure not in self.values:
            raise MechanismError(f"measure: {measure!r} was not sampled in this map; "
                                 f"sampled: {sorted(self.values)}")
        from ..plot import DPI, _figure

        if ax is None:
            fig = _figure(path, (6, 5), "constrained")  # out of pyplot when written
            ax = fig.add_subplot()
        else:
            fig = ax.figure
        _draw_map(fig, ax, self, self.values[measure], measure, bool(log), self.mech_name,
                  title)
        if path is not None:
            try:
                fig.savefig(path, dpi=DPI)
            except OSError as e:
                raise MechanismError(f"path: cannot write the picture {os.fspath(path)!r}: "
                                     f"{e.strerror or e}") from None
            if isinstance(path, (str, os.PathLike)):
                self.path = os.fspath(path)
        return fig


def _measures(jac: Any) -> dict[str, float]:
    """The map's measures at one configuration: classify's margins and the manipulability."""
    from .singularity import classify_jacobians

    mech = jac.mech
    model = get_model(mech)
    L = model.length
    act = np.array(mech.actuated)
    qa_scale = np.where(np.array(mech.revolute)[act], 1.0, L)
    rep = classify_jacobians(mech, jac)  # (classify(mech, jac.q) would evaluate them again)
    par, ser = rep.margins["parallel"], rep.margins["serial"]
    rows = task_rows(model)
    J = jac.J_task
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
        With ``success``/``status``/``message``: when the time budget of
        :mod:`optkin.limits` runs out, the points not sampled stay NaN, ``success`` is False
        and ``status`` is ``"time_limit"``.

    The grid costs about 300 bytes per point (measures and picture: 215 measured), checked
    against the memory budget of :mod:`optkin.limits` before sampling
    (``len(u) * len(v)``).
    """
    from ..solvers import forward, inverse
    from ..solvers.common import check_mechanism

    deadline = Deadline()
    check_mechanism(mech, "singularity_map")
    u, v = _axis_values("u", u), _axis_values("v", v)
    check_size("singularity_map", "len(u) * len(v)", u.size * v.size, _COST_MAP_POINT, lo=4,
               fixed=_COST_FIGURE, unit="one grid point: its measures and its cell of the "
               "picture")
    fixed = _fixed_arg(fixed)
    ax_given = _axes_arg(axes)
    guess = _guess_arg(guess)
    stopped: str | None = None
    vals = {k: np.full((v.size, u.size), np.nan) for k in MEASURES}
    model = get_model(mech)
    if model.platform is not None:  # poses are task coordinates: the inverse model
        names = list(mech.task)
        ax = ax_given if ax_given is not None else (names[0], names[1])
        for a in ax:
            if a not in names:
                raise MechanismError(f"axes: {show(a)} is not a task coordinate of {mech.name} "
                                     f"({names})")
        base = np.array(mech.home if mech.home is not None else np.zeros(len(names)), float)
        for k, val in fixed.items():
            if k not in names:
                raise MechanismError(f"fixed: {show(k)} is not a task coordinate ({names})")
            base[names.index(k)] = val
        mode = _mode_arg(working_mode, model.na)
        checkpoint()  # validation stops here: every argument is checked
        for i, vv in enumerate(v):
            if stopped:
                break
            for j, uu in enumerate(u):
                if deadline.expired():
                    stopped = deadline.message("singularity_map") + (
                        f": sampled {i * u.size + j} of {u.size * v.size} points")
                    break
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
        ax = ax_given if ax_given is not None else (names[0], names[1] if len(names) > 1 else
                                                    names[0])
        for a in ax:
            if a not in names:
                raise MechanismError(f"axes: {show(a)} is not an active joint of {mech.name} "
                                     f"({names})")
        base = np.zeros(len(names))
        for k, val in fixed.items():
            if k not in names:
                raise MechanismError(f"fixed: {show(k)} is not an active joint ({names})")
            base[names.index(k)] = val
        checkpoint()  # validation stops here: every argument is checked
        prev_row = guess
        for i, vv in enumerate(v):
            if stopped:
                break
            prev = prev_row
            for j, uu in enumerate(u):
                if deadline.expired():
                    stopped = deadline.message("singularity_map") + (
                        f": sampled {i * u.size + j} of {u.size * v.size} points")
                    break
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
    sm = SingularityMap(mech.name, (str(ax[0]), str(ax[1])), u, v, vals, fixed_out)
    if stopped:
        sm.success, sm.status, sm.message = False, TIME_LIMIT, stopped
    else:
        sm.message = f"{int(np.isfinite(vals['distance']).sum())} of {u.size * v.size} points reachable"
    return sm


def plot_singularity_map(
    mech: Mechanism,
    u: Sequence[float],
    v: Sequence[float],
    path: Any = None,
    measure: str = "distance",
    log: bool = True,
    *,
    ax: Any = None,
    **kwargs: Any,
) -> SingularityMap:
    """Sample :func:`singularity_map` and draw ``measure`` (:meth:`SingularityMap.plot`).

    Singular curves appear as dark valleys (log10 of the measure); unreachable points are
    left blank. Extra keyword arguments go to :func:`singularity_map`.

    Parameters
    ----------
    mech : Mechanism
    u, v : sequence of float
        Grid values of the two sampled coordinates (at least two finite values each).
    path : str, os.PathLike or file object, optional
        Write the picture there (PNG, SVG, PDF, ... by the suffix); the Figure then stays
        out of pyplot.
    measure : str
        One of ``"distance"``, ``"parallel"``, ``"serial"``, ``"manipulability"``.
    log : bool
        Draw log10 of the measure.
    ax : matplotlib Axes, optional
        Draw into this Axes.
    **kwargs
        ``axes``, ``fixed``, ``working_mode``, ``guess`` of :func:`singularity_map`.

    Returns
    -------
    SingularityMap
        The sampled measures, with the picture in ``figure`` (and ``path`` set when
        written).

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
    _check_picture(measure, log, path)  # before the sampling, which takes a while
    unknown = sorted(set(kwargs) - set(_KWARGS))
    if unknown:
        raise MechanismError(f"plot_singularity_map: unknown argument(s) {unknown}; known: "
                             f"{list(_KWARGS)} (of singularity_map)")
    sm = singularity_map(mech, u, v, **kwargs)
    sm.figure = sm.plot(measure, log, ax=ax, path=path, title=None)
    return sm


def _check_picture(measure: Any, log: Any, path: Any) -> None:
    """The drawing arguments of :meth:`SingularityMap.plot` and
    :func:`plot_singularity_map`, else a MechanismError naming the one that is wrong."""
    if not isinstance(measure, str) or measure not in MEASURES:
        raise MechanismError(f"measure: {show(measure)} is not one of {list(MEASURES)}")
    if not isinstance(log, (bool, np.bool_)):
        raise MechanismError(f"log: expected True or False, got {show(log)}")
    if path is not None and not (isinstance(path, (str, os.PathLike)) and os.fspath(path)
                                 or hasattr(path, "write")):
        raise MechanismError(f"path: expected a file name (str or os.PathLike) or a file "
                             f"object for the picture, got {type(path).__name__}")


def _draw_map(fig: Any, axp: Any, sm: SingularityMap, Z: np.ndarray, measure: str,
              log: bool, name: str, title: str | None = None) -> None:
    with np.errstate(divide="ignore", invalid="ignore"):
        data = np.log10(np.maximum(Z, 1e-16)) if log else Z
    finite = data[np.isfinite(data)]
    # the colour scale from the 1st percentile up: one grid point that happens to fall on
    # a singularity (log10 of 1e-16) would otherwise wash every valley out
    lo = float(np.percentile(finite, 1)) if finite.size else None
    mesh = axp.pcolormesh(sm.u, sm.v, np.ma.masked_invalid(data), shading="auto",
                          cmap="viridis", vmin=lo, rasterized=True)  # (small vector files)
    extend = "min" if finite.size and finite.min() < lo else "neither"
    cb = fig.colorbar(mesh, ax=axp, extend=extend)
    cb.set_label(("log10 " if log else "") + _MEASURE_LABELS[measure], fontsize=8)
    axp.set_xlabel(sm.axes[0])
    axp.set_ylabel(sm.axes[1])
    fx = ", ".join(f"{k}={v:.3g}" for k, v in sm.fixed.items())
    axp.set_title(title or f"{name}: {measure}" + (f" ({fx})" if fx else ""))


def _axis_values(name: str, a: Any) -> np.ndarray:
    """The grid values of one axis: at least two finite numbers, else a MechanismError."""
    try:
        out = as_vector(a, name)
    except MechanismError:
        out = np.full(0, np.nan)
    if out.ndim != 1 or out.size < 2:
        raise MechanismError(
            f"{name}: expected a 1-D sequence of at least 2 finite grid values (e.g. "
            f"np.linspace(lo, hi, 21)), got {show(a)}")
    return out


# Measured memory per grid point (peak resident growth, VmHWM, of a fresh process): the
# four measures, and the picture of plot_singularity_map (pcolormesh cells, contour,
# the PNG raster: 215 bytes measured at 1000 x 1000); limits.SAFETY is applied on top.
_COST_MAP_POINT = 300.0
#: ... and of the figure itself (its raster and artists, 16 MB measured), with SAFETY.
_COST_FIGURE = 24e6
_KWARGS = ("axes", "fixed", "working_mode", "guess")


def _fixed_arg(fixed: Any) -> dict[str, float]:
    if fixed is None:
        return {}
    if not isinstance(fixed, Mapping):
        raise MechanismError(f"fixed: expected a dict name -> value, got {type(fixed).__name__}")
    out = {}
    for k, val in fixed.items():
        if not isinstance(k, str):
            raise MechanismError(f"fixed: expected coordinate names as keys, got {show(k)}")
        out[k] = as_float(val, f"fixed[{show(k)}]")
    return out


def _axes_arg(axes: Any) -> tuple[str, str] | None:
    if axes is None:
        return None
    if (isinstance(axes, str) or not isinstance(axes, Sequence) or len(axes) != 2
            or not all(isinstance(a, str) for a in axes)):
        raise MechanismError(f"axes: expected two coordinate names, got {show(axes)}")
    return (axes[0], axes[1])


def _mode_arg(mode: Any, n: int) -> tuple[int, ...] | None:
    if mode is None:
        return None
    try:
        m = as_vector(mode, "working_mode", n)
    except MechanismError:
        m = np.zeros(0)
    if m.size != n or not np.all(np.isin(m, (-1.0, 1.0))):
        raise MechanismError(f"working_mode: expected {n} signs (+1 or -1), one per actuated "
                             f"leg, got {show(mode)}")
    return tuple(int(x) for x in m)


def _guess_arg(guess: Any) -> Any:
    if guess is None or isinstance(guess, KinResult):
        return guess
    try:
        return as_matrix(guess, "guess")
    except MechanismError:
        return as_vector(guess, "guess")
