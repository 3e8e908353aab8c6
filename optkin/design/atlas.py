"""Performance atlases: measures over a grid of designs, as contour maps.

``atlas(family, variables, measures, n=...)`` evaluates each measure at every design of a
grid over two free design variables (the others fixed or given by equalities, as in
:class:`~optkin.design.Family`): measures over fixed nodes (GCI, least conditioning,
dimensions) as one mapped call of the compiled evaluation for every design and node; the
others design by design. Designs outside the bounds of an eliminated variable (the
trapezoid of Liu, Wang and Pritschow's normalised design space r1 + r2 + r3 = 3) are NaN.
"""

from __future__ import annotations

import textwrap
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._checks import as_int, show
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..results import OPTIMAL, jsonable
from .family import Family
from .problem import Measure

__all__ = ["Atlas", "atlas"]


@dataclass
class Atlas:
    """Measures over a grid of designs.

    Attributes
    ----------
    names : tuple of str
        The two free variables spanning the grid.
    axes : tuple of ndarray
        Their grid values.
    values : dict name -> ndarray (n1, n0)
        Each measure on the grid (rows: the second variable), NaN outside the design space.
    dims : dict name -> ndarray (n1, n0)
        Every dimension on the grid.
    success, status, message :
        As every result (:mod:`optkin.results`); the message counts the designs inside
        the design space (the others are NaN in ``values``).
    """

    names: tuple[str, str]
    axes: tuple[np.ndarray, np.ndarray]
    values: dict[str, np.ndarray]
    dims: dict[str, np.ndarray] = field(default_factory=dict)
    time: float = 0.0
    success: bool = True
    status: str = OPTIMAL
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`: NaN outside the design space
        becomes None)."""
        return jsonable({"names": self.names, "axes": self.axes, "values": self.values,
                         "time": self.time, "success": self.success,
                         "status": self.status, "message": self.message})

    def best(self, measure: str, maximize: bool = True) -> dict[str, float]:
        """The grid design with the largest (or smallest) value of ``measure``."""
        v = self.values[measure]
        k = np.nanargmax(v) if maximize else np.nanargmin(v)
        i, j = np.unravel_index(k, v.shape)
        out = {n: float(d[i, j]) for n, d in self.dims.items()}
        out[measure] = float(v[i, j])
        return out

    def plot(self, path: str | None = None, measures: Sequence[str] | None = None,
             levels: int = 12, *, fig: Any = None) -> Any:
        """Contour maps of the measures over the design grid, labelled, one panel each.

        Returns the matplotlib Figure; ``fig`` draws into an empty Figure of yours,
        ``path`` writes it (at :data:`optkin.plot.DPI`).
        """
        from ..analysis.aspects import _check_path, _fig, _save

        _check_path(path)

        names = list(measures or self.values)
        for m in names:
            if m not in self.values:
                raise MechanismError(f"plot: {show(m)} is not a measure of this atlas; known: "
                                     f"{', '.join(self.values)}")
        n = len(names)
        fig, axs = _fig(1, n, 4.8, 4.2, path, fig)
        X, Y = np.meshgrid(*self.axes)
        for ax, m in zip(axs[0], names):
            V = self.values[m]
            if np.isfinite(V).any():
                cs = ax.contourf(X, Y, V, levels=levels, cmap="viridis")
                cl = ax.contour(X, Y, V, levels=cs.levels, colors="k", linewidths=0.4)
                ax.clabel(cl, fmt="%.3g", fontsize=7)
                fig.colorbar(cs, ax=ax, label=m if len(m) <= 24 else "value")
                k = np.unravel_index(np.nanargmax(V), V.shape)
                ax.plot(X[k], Y[k], marker="*", ms=12, color="w", mec="k",
                        label=f"largest: {V[k]:.4g}")
                ax.legend(loc="best", fontsize=8)
            ax.set_xlabel(self.names[0])
            ax.set_ylabel(self.names[1])
            ax.set_title(textwrap.fill(m, 44), fontsize=10)
            ax.set_aspect("equal", adjustable="box")
        return _save(fig, path)


def atlas(family: Callable[..., Any] | Family, variables: Mapping[str, Any] | None = None,
          measures: Mapping[str, Measure] | Sequence[Measure] = (), *, n: int | Sequence[int]
          = 50, fixed: Mapping[str, Any] | None = None,
          equal: Sequence[tuple[Mapping[str, float], float]] = (), jobs: int = 1,
          client: Any = None) -> Atlas:
    """Evaluate measures over an n x n grid of two free design variables.

    Parameters
    ----------
    family, variables, fixed, equal :
        As for :func:`optkin.design.optimize` (exactly two free variables).
    measures : mapping name -> Measure, or sequence of Measure
    n : int or (n0, n1)
        Grid points per variable (between the bounds, ends excluded by half a cell).
    jobs : int
        Worker processes (the grid in chunks; the family and measures sent with
        cloudpickle, so lambdas work). 1: in this process.
    client : dask.distributed.Client, optional
        Send the chunks to a Dask cluster instead (as ``optkin run --scheduler`` does).

    Returns
    -------
    Atlas

    Examples
    --------
    >>> import optkin
    >>> from optkin import design
    >>> five = lambda a, b: optkin.mechanisms.five_bar(1.0, a, b, b, a)
    >>> at = design.atlas(five, {"a": (0.6, 1.4), "b": (0.6, 1.4)},
    ...                   {"GCI": design.GCI(design.Disc((0.5, 1.0), 0.2), (1, -1))}, n=8)
    >>> at.values["GCI"].shape
    (8, 8)
    """
    import time

    from .optimize import _family

    t0 = time.perf_counter()
    fam = _family(family, variables, fixed, equal)
    if len(fam.free) != 2:
        raise MechanismError(f"atlas: the grid spans exactly two free variables; this family "
                             f"has {list(fam.free)} (fix or tie the others)")
    if not isinstance(measures, Mapping):
        measures = {repr(m): m for m in measures}
    if not measures:
        raise MechanismError("measures: give at least one measure")
    for k, m in measures.items():
        if not isinstance(m, Measure):
            raise MechanismError(f"measures[{k!r}]: expected an optkin.design measure, got "
                                 f"{show(m)}")
    nn = (n, n) if np.isscalar(n) else tuple(n)
    if len(nn) != 2:
        raise MechanismError(f"n: expected an int or a pair, got {show(n)}")
    n0, n1 = (as_int(v, "n", lo=2, hi=2000) for v in nn)
    checkpoint()
    ax0 = fam.lower[0] + (np.arange(n0) + 0.5) / n0 * (fam.upper[0] - fam.lower[0])
    ax1 = fam.lower[1] + (np.arange(n1) + 0.5) / n1 * (fam.upper[1] - fam.lower[1])
    X, Y = np.meshgrid(ax0, ax1)
    Z = np.stack([X.ravel(), Y.ravel()], -1)
    inside = fam.bound_violation(Z) <= 0
    jobs = as_int(jobs, "jobs", lo=1, hi=1024)
    values = {k: np.full(len(Z), np.nan) for k in measures}
    Zin = Z[inside]
    if len(Zin) and (jobs > 1 or client is not None):
        payload = _dumps((fam.build, {k: (a, b) for k, a, b in zip(
            fam.names, fam.all_lower, fam.all_upper)}, fam.fixed,
            [({fam.names[i]: float(coef[i]) for i in np.flatnonzero(coef)}, val)
             for _, coef, val in fam._eq], dict(measures)))
        parts = np.array_split(Zin, max(1, 4 * (jobs if client is None else 8)))
        parts = [p_ for p_ in parts if len(p_)]
        if client is not None:
            futs = client.map(_chunk, [payload] * len(parts), parts, pure=False)
            results = client.gather(futs)
        else:
            import concurrent.futures as cf
            import multiprocessing as mp

            with cf.ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as ex:
                results = list(ex.map(_chunk, [payload] * len(parts), parts))
        got = {k: np.concatenate([r[k] for r in results]) for k in measures}
        for k in measures:
            values[k][inside] = got[k]
    elif len(Zin):
        for k, m in measures.items():
            values[k][inside] = m.values(fam, Zin)
    values = {k: v.reshape(X.shape) for k, v in values.items()}
    full = fam.full(Z)
    dims = {name: full[:, i].reshape(X.shape) for i, name in enumerate(fam.names)}
    return Atlas(names=(fam.free[0], fam.free[1]), axes=(ax0, ax1), values=values, dims=dims,
                 time=time.perf_counter() - t0,
                 message=f"{len(measures)} measure(s) over {n0} x {n1} designs, "
                         f"{int(inside.sum())} inside the design space")


def _dumps(obj: Any) -> bytes:
    try:
        import cloudpickle

        return cloudpickle.dumps(obj)
    except ImportError:  # plain pickle: module-level functions only
        import pickle

        return pickle.dumps(obj)


def _chunk(payload: bytes, Z: np.ndarray) -> dict[str, np.ndarray]:
    """A worker's part of an atlas: the family rebuilt, every measure at the designs Z."""
    import pickle

    build, variables, fixed, equal, measures = pickle.loads(payload)
    fam = Family(build, variables, fixed, equal)
    return {k: m.values(fam, Z) for k, m in measures.items()}
