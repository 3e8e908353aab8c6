"""Force capability, wrench feasibility and force distribution (cvxpy, re-solved with DPP).

All analyses take the static model (2) of :mod:`optkin.statics.model`:
F = A^T lambda, tau = -B^T lambda, P^T lambda = 0, with F the wrench the end effector
applies to the environment (the load it resists is -F) and tau the actuator forces.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import StaticsError
from ..mechanism import Mechanism
from ..results import SolverStats
from ..solvers.common import merge_options
from . import problems as pb
from .model import SING_TOL, StaticModel, static_model
from .results import (
    CapabilityResult,
    DistributionResult,
    FeasibilityResult,
    PolytopeResult,
    WorkspaceResult,
)

__all__ = [
    "capability", "capability_many", "capability_polygon", "polytope", "feasible",
    "wrench_feasible_workspace", "distribute", "box", "limits_of", "STATICS_DEFAULTS",
]

#: Options shared by the statics analyses and their defaults.
STATICS_DEFAULTS: dict[str, Any] = {
    "sing_tol": SING_TOL,  # relative singular-value tolerance of the singularity tests
    "solver": None,  # None: HiGHS for LPs, Clarabel for the 2-norm QP
    "reuse": True,  # False rebuilds the cvxpy problem (benchmark baseline)
    "cap": 1e6,  # capability above cap * (limit scale) counts as unbounded
    "dir_tol": 1e-7,  # |U^T d| above this: direction d not resisted (parallel singularity)
    "chunk": 64,  # poses per LP in capability_many / wrench_feasible_workspace
}


# --------------------------------------------------------------------------------------
# inputs


def limits_of(limits: Any, sm: StaticModel, required: bool = True
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) from a scalar, one bound per actuator (|tau_i| <= b_i) or pairs (lo_i, hi_i)."""
    na, names = sm.na, list(sm.actuator_names)
    if limits is None:
        if required:
            raise StaticsError(
                f"limits: required; give one bound per actuator {names} (|tau_i| <= b_i) or "
                "pairs [lo_i, hi_i]"
            )
        return None
    try:
        a = np.asarray(limits, dtype=float)
    except (TypeError, ValueError):
        raise StaticsError(f"limits: expected numbers, got {limits!r}") from None
    if a.ndim == 0:
        a = np.full(na, float(a))
    if a.shape == (na,):
        if np.any(a < 0):
            bad = [names[i] for i in np.flatnonzero(a < 0)]
            raise StaticsError(
                f"limits: bounds |tau_i| <= b_i must be >= 0, negative for {bad}; give pairs "
                "[lo, hi] for one-sided limits"
            )
        lo, hi = -a, a.copy()
    elif a.shape == (na, 2):
        lo, hi = a[:, 0].copy(), a[:, 1].copy()
        if np.any(lo > 0) or np.any(hi < 0):
            bad = [names[i] for i in np.flatnonzero((lo > 0) | (hi < 0))]
            raise StaticsError(
                f"limits: each pair [lo, hi] must contain 0 (lo <= 0 <= hi); not so for {bad}"
            )
    else:
        raise StaticsError(
            f"limits: expected a number, {na} bounds or {na} pairs [lo, hi] for the actuators "
            f"{names}, got shape {a.shape}"
        )
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise StaticsError("limits: must be finite; use a large number for 'unlimited'")
    return lo + 0.0, hi + 0.0


def _directions(directions: Any, sm: StaticModel) -> np.ndarray:
    m, names = sm.m, list(sm.wrench_names)
    if directions is None:
        return np.vstack([np.eye(m), -np.eye(m)])
    if isinstance(directions, str):
        if directions not in names and not (directions[:1] == "-" and directions[1:] in names):
            raise StaticsError(f"directions: unknown component {directions!r}; use one of {names}")
        directions = [directions]
    if isinstance(directions, (list, tuple)) and directions and all(
            isinstance(d, str) for d in directions):
        rows = []
        for d in directions:
            sgn = -1.0 if d.startswith("-") else 1.0
            key = d.lstrip("-+")
            if key not in names:
                raise StaticsError(f"directions: unknown component {d!r}; use one of {names}")
            e = np.zeros(m)
            e[names.index(key)] = sgn
            rows.append(e)
        return np.array(rows)
    try:
        D = np.atleast_2d(np.asarray(directions, dtype=float))
    except (TypeError, ValueError):
        raise StaticsError(f"directions: expected an array (k, {m}), got {directions!r}") from None
    if D.ndim != 2 or D.shape[1] != m or D.shape[0] == 0:
        raise StaticsError(
            f"directions: expected an array (k, {m}) of wrench directions {names}, got shape "
            f"{np.shape(directions)}"
        )
    n = np.linalg.norm(D, axis=1)
    if not np.all(np.isfinite(D)) or np.any(n == 0):
        raise StaticsError("directions: every direction must be finite and non-zero")
    return D / n[:, None]


def box(lower: Any, upper: Any) -> np.ndarray:
    """The 2^m vertices (rows) of the wrench box lower <= F <= upper.

    Parameters
    ----------
    lower, upper : array (m,)
        Finite bounds of each wrench component, ``lower <= upper``.

    Returns
    -------
    ndarray (2^m, m)
        The corners, in binary order (last component fastest).

    Examples
    --------
    >>> box([-1, 0], [1, 2]).tolist()
    [[-1.0, 0.0], [-1.0, 2.0], [1.0, 0.0], [1.0, 2.0]]
    """
    lo = np.asarray(lower, dtype=float).ravel()
    hi = np.asarray(upper, dtype=float).ravel()
    if lo.shape != hi.shape or np.any(lo > hi) or not np.all(np.isfinite(lo + hi)):
        raise StaticsError(
            f"wrench box: lower and upper must be finite, of equal length, lower <= upper; "
            f"got {lo.tolist()} and {hi.tolist()}"
        )
    return np.array(list(itertools.product(*zip(lo, hi))), dtype=float)


def _wrench_set(ws: Any, sm: StaticModel) -> np.ndarray:
    m, names = sm.m, list(sm.wrench_names)
    if isinstance(ws, Mapping):
        keys = {k.lower() for k in ws}
        lo_k = "lower" if "lower" in keys else "min"
        hi_k = "upper" if "upper" in keys else "max"
        if lo_k not in keys or hi_k not in keys:
            raise StaticsError(
                "wrench_set: a box is a mapping with 'lower' and 'upper' (one value per "
                f"component {names})"
            )
        low = {k.lower(): v for k, v in ws.items()}
        V = box(low[lo_k], low[hi_k])
    else:
        try:
            V = np.atleast_2d(np.asarray(ws, dtype=float))
        except (TypeError, ValueError):
            raise StaticsError(f"wrench_set: expected numbers, got {ws!r}") from None
    if V.ndim != 2 or V.shape[1] != m or not np.all(np.isfinite(V)):
        raise StaticsError(
            f"wrench_set: expected a wrench ({m},), vertices ({'{'}nv{'}'}, {m}) or a box "
            f"{{'lower': ..., 'upper': ...}} with components {names}; got shape {V.shape}"
        )
    return V


def _params(sm: StaticModel, lo: np.ndarray, hi: np.ndarray) -> dict[str, np.ndarray]:
    v = {"At": sm.A.T.copy(), "Bt": sm.B.T.copy(), "lo": lo, "hi": hi}
    if sm.P.shape[1]:
        v["Pt"] = sm.P.T.copy()
    return v


def _shape(sm: StaticModel) -> tuple[int, int, int, int]:
    return sm.A.shape[0], sm.m, sm.na, sm.P.shape[1]


def _sing_message(sm: StaticModel) -> str:
    parts = []
    if sm.unresisted.shape[1]:
        tw = ", ".join(np.array2string(t, precision=4, suppress_small=True)
                       for t in sm.unresisted.T)
        parts.append(
            f"parallel singularity: with the actuators locked the platform can still move "
            f"along the twist(s) {tw} ({'/'.join(sm.wrench_names)} order); no actuator force "
            "resists a wrench doing work on that motion"
        )
    if sm.free_wrenches.shape[1]:
        fw = ", ".join(np.array2string(w, precision=4, suppress_small=True)
                       for w in sm.free_wrenches.T)
        parts.append(
            f"serial singularity: the wrench(es) {fw} are carried by the structure with no "
            "actuator force (unbounded capability along them)"
        )
    return "; ".join(parts)


# --------------------------------------------------------------------------------------
# capability


def capability(
    mech: Mechanism, q: Any, limits: Any, directions: Any = None, **options: Any
) -> CapabilityResult:
    """The largest wrench the end effector can apply (or resist) along each direction.

    For each unit direction d: max s  s.t.  s d = A^T lambda, P^T lambda = 0,
    lo <= -B^T lambda <= hi (the static model (2)). All k directions are one LP (their
    columns are independent), built once per shape with ``cp.Parameter`` s and re-solved
    with HiGHS for every pose.

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        The configuration (``KinResult.q``, all joints) or the KinResult.
    limits : float, array (na,) or array (na, 2)
        |tau_i| <= limits_i, or pairs (lo_i, hi_i) with lo_i <= 0 <= hi_i.
    directions : array (k, m), list of component names, or None
        Wrench directions in the task space (normalised here): planar (fx, fy, mz), spatial
        (fx, fy, fz, mx, my, mz), base frame, moments about the end-effector point. Names
        such as ``["fx", "-mz"]`` pick unit components. Default: +- each component.
    **options
        See :data:`STATICS_DEFAULTS`.

    Returns
    -------
    CapabilityResult
        ``.max`` (k,); at a parallel singularity ``status="singular"`` and the directions
        that do work on the free twist have ``max = 0`` and status ``"unresisted"``.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> c, s = np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)
    >>> base = np.array([[1, 0], [c, s], [c, -s]])
    >>> m = optkin.mechanisms.rpr3(base, 0.2 * base)
    >>> r = capability(m, optkin.inverse(m, [0, 0, 0.4])[0], 1.0, ["mz"])
    >>> r.status, round(float(r.max[0]), 6)   # 3 tau_max r R sin(phi) / L
    ('optimal', 0.285115)
    """
    opts = merge_options(STATICS_DEFAULTS, options, "capability")
    sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    D = _directions(directions, sm)
    return _capability(sm, lo, hi, D, opts)


def _cap_of(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, opts: dict[str, Any]) -> float:
    """The capability above which a direction counts as unbounded (serial singularity)."""
    lim = float(max(np.max(hi), np.max(-lo), 1e-300))
    normA = float(np.linalg.norm(sm.A, 2)) if sm.A.size else 1.0
    svB = np.linalg.svd(sm.B, compute_uv=False) if sm.B.size else np.ones(1)
    sB = svB[svB > float(opts["sing_tol"]) * max(svB[0], 1e-300)]
    ref = lim * max(1.0, normA) / max(min(1.0, float(sB.min()) if sB.size else 1.0), 1e-12)
    return float(opts["cap"]) * ref


def _capability(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, D: np.ndarray,
                opts: dict[str, Any]) -> CapabilityResult:
    k = D.shape[0]
    cap = _cap_of(sm, lo, hi, opts)
    prob = pb.capability_problem(*_shape(sm), k, reuse=bool(opts["reuse"]))
    vals = _params(sm, lo, hi)
    vals.update({"D": D.T.copy(), "cap": cap})
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    s = out["s"] if out["s"] is not None else np.full(k, np.nan)
    tau = out["tau"].T if out["tau"] is not None else np.full((k, sm.na), np.nan)
    return _capability_result(sm, lo, hi, D, s, tau, cap, status, raw, stats, opts)


def _capability_result(sm, lo, hi, D, s, tau, cap, status, raw, stats, opts) -> CapabilityResult:
    k = D.shape[0]
    tau = np.array(tau, dtype=float)
    dstat = ["optimal"] * k
    smax = np.clip(np.asarray(s, dtype=float), 0.0, None)
    U, Fw = sm.unresisted, sm.free_wrenches
    tol = float(opts["dir_tol"])
    for j in range(k):
        d = D[j]
        if Fw.shape[1] and np.linalg.norm(d - Fw @ (Fw.T @ d)) < tol:
            dstat[j], smax[j] = "unbounded", np.inf
            tau[j] = np.nan
        elif U.shape[1] and np.linalg.norm(U.T @ d) > tol:
            dstat[j], smax[j] = "unresisted", 0.0
            tau[j] = 0.0
        elif status in ("optimal", "inaccurate") and s[j] >= cap * (1 - 1e-6):
            dstat[j], smax[j] = "unbounded", np.inf
            tau[j] = np.nan
    ok = status in ("optimal", "inaccurate")
    points = np.where(np.isfinite(smax)[:, None], smax[:, None] * D, np.nan)
    if not ok:
        message = f"the capability LP failed ({raw}); check the limits and the configuration"
        out_status = status
    elif sm.singularity != "none":
        nz = sum(1 for x in dstat if x == "unresisted")
        nu = sum(1 for x in dstat if x == "unbounded")
        message = (f"{_sing_message(sm)}: capability 0 in {nz} and unbounded in {nu} of "
                   f"{k} directions")
        out_status = "singular"
    else:
        out_status = status
        message = f"capability along {k} directions (LP {raw}, cond {sm.cond:.3g})"
        if sm.cond > 1e6:
            message += "; near a parallel singularity: small capability along the near-free twist"
        nu = sum(1 for x in dstat if x == "unbounded")
        if nu:
            message += f"; unbounded in {nu} direction(s) (near a serial singularity)"
    return CapabilityResult(
        directions=D, max=smax, points=points, tau=tau,
        direction_status=dstat, success=ok, status=out_status, message=message,
        singularity=sm.singularity, unresisted=sm.unresisted, wrench_names=sm.wrench_names,
        limits=np.column_stack([lo, hi]), cond=sm.cond, stats=stats,
    )


def capability_many(
    mech: Mechanism, qs: Sequence[Any], limits: Any, directions: Any = None,
    chunk: int = 64, **options: Any,
) -> list[CapabilityResult]:
    """:func:`capability` at many configurations, ``chunk`` poses per LP.

    One parametrised problem holds ``chunk`` independent copies of the capability LP (one
    parameter block A^T, B^T per pose), built once and re-solved chunk after chunk: the
    per-solve overhead of cvxpy is paid once per chunk instead of once per pose. The
    results are those of :func:`capability` pose by pose (the LPs are independent).

    Parameters
    ----------
    qs : sequence of arrays or KinResults
        The configurations.
    chunk : int
        Poses per LP (the last chunk is padded by repeating its last pose).

    Returns
    -------
    list of CapabilityResult
        One per configuration, in the order of ``qs`` (empty for no configuration).
    """
    opts = merge_options(STATICS_DEFAULTS, options, "capability_many")
    qs = list(qs)
    if not qs:
        return []
    if int(chunk) < 1:
        raise StaticsError(f"chunk: expected a positive integer, got {chunk!r}")
    sms = [static_model(mech, q, float(opts["sing_tol"])) for q in qs]
    lo, hi = limits_of(limits, sms[0])  # type: ignore[misc]
    D = _directions(directions, sms[0])
    k, na = D.shape[0], sms[0].na
    n = min(int(chunk), len(sms))
    prob = pb.capability_batch_problem(*_shape(sms[0]), k, n, reuse=bool(opts["reuse"]))
    out: list[CapabilityResult] = []
    for c0 in range(0, len(sms), n):
        block = sms[c0:c0 + n]
        pad = block + [block[-1]] * (n - len(block))
        caps = [_cap_of(sm, lo, hi, opts) for sm in pad]
        vals: dict[str, Any] = {"lo": lo, "hi": hi, "D": D.T.copy(),
                                "cap": np.repeat(caps, k)}
        for i, sm in enumerate(pad):
            vals[f"At{i}"] = sm.A.T.copy()
            vals[f"Bt{i}"] = sm.B.T.copy()
            if sm.P.shape[1]:
                vals[f"Pt{i}"] = sm.P.T.copy()
        status, raw, stats, res = pb.solve(prob, vals, opts["solver"])
        stats.extra["poses_in_lp"] = n
        for i, sm in enumerate(block):
            if res["s"] is not None:
                s = res["s"][i * k:(i + 1) * k]
                tau = res["tau"][:, i * k:(i + 1) * k].T
            else:
                s, tau = np.full(k, np.nan), np.full((k, na), np.nan)
            out.append(_capability_result(sm, lo, hi, D, s, tau, caps[i], status, raw, stats,
                                          opts))
    return out


def capability_polygon(
    mech: Mechanism, q: Any, limits: Any, n: int = 72, plane: Sequence[str] = ("fx", "fy"),
    path: str | None = None, **options: Any,
) -> CapabilityResult:
    """Capability along ``n`` directions spread over the plane of two wrench components.

    The directions cover the plane of ``plane`` (default the forces fx, fy with zero
    moment): the boundary of the capability polygon, optionally drawn to the PNG ``path``
    (:func:`optkin.statics.plot_capability`).

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        A closed configuration (``KinResult.q`` or the result itself).
    limits : float, array or pairs
        Actuator limits, as for :func:`capability`.
    n : int
        Number of directions (at least 3), evenly spread over the circle.
    plane : (str, str)
        Two different wrench components (:func:`optkin.statics.wrench_names`).
    path : str, optional
        Where to draw the polygon (PNG).
    **options
        See :data:`STATICS_DEFAULTS`.

    Returns
    -------
    CapabilityResult
        The largest wrench along each direction (``max``), as :func:`capability`.
    """
    opts = merge_options(STATICS_DEFAULTS, options, "capability_polygon")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 3:
        raise StaticsError(f"n: expected an integer number of directions >= 3, got {n!r}")
    sm = static_model(mech, q, float(opts["sing_tol"]))
    names = list(sm.wrench_names)
    for c in plane:
        if c not in names:
            raise StaticsError(f"plane: unknown component {c!r}; use two of {names}")
    if len(plane) != 2 or plane[0] == plane[1]:
        raise StaticsError(f"plane: expected two different components of {names}, got {plane}")
    th = np.linspace(0.0, 2 * np.pi, int(n), endpoint=False)
    D = np.zeros((int(n), sm.m))
    D[:, names.index(plane[0])] = np.cos(th)
    D[:, names.index(plane[1])] = np.sin(th)
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    res = _capability(sm, lo, hi, D, opts)
    if path is not None:
        from .plots import plot_capability

        exact = None
        if sm.G is not None and sm.na <= 12 and res.success:
            exact = _polytope(sm, lo, hi, opts).section(tuple(plane))  # type: ignore[arg-type]
        plot_capability(res, path, plane=tuple(plane), exact=exact)
    return res


# --------------------------------------------------------------------------------------
# polytope


def polytope(mech: Mechanism, q: Any, limits: Any, **options: Any) -> PolytopeResult:
    """The whole capability polytope {G tau : lo <= tau <= hi} (a zonotope) at ``q``.

    Its vertices are among the images of the 2^na corners of the actuator box; scipy's
    ConvexHull gives the facets. Flat at a parallel singularity (``dimension < m``).
    Undefined at a serial singularity (``success=False``).

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        A closed configuration (``KinResult.q`` or the result itself).
    limits : float, array or pairs
        Actuator limits, as for :func:`capability`.
    **options
        See :data:`STATICS_DEFAULTS`.

    Returns
    -------
    PolytopeResult
    """
    opts = merge_options(STATICS_DEFAULTS, options, "polytope")
    sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    return _polytope(sm, lo, hi, opts)


def _polytope(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, opts: dict[str, Any]
              ) -> PolytopeResult:
    from scipy.spatial import ConvexHull, QhullError

    m = sm.m
    empty = dict(vertices=np.zeros((0, m)), equations=np.zeros((0, m + 1)), dimension=0,
                 volume=0.0, wrench_names=sm.wrench_names)
    if sm.G is None:
        return PolytopeResult(success=False, status="singular",
                              message=f"{_sing_message(sm)}: the polytope is unbounded", **empty)
    if sm.na > 16:
        raise StaticsError(f"polytope: {sm.na} actuators give 2^{sm.na} corners; at most 16")
    corners = np.array(list(itertools.product(*zip(lo, hi))))
    W = corners @ sm.G.T
    Ur = np.linalg.svd(sm.G, full_matrices=False)[0]
    sv = np.linalg.svd(sm.G, compute_uv=False)
    rank = int(np.sum(sv > float(opts["sing_tol"]) * max(sv[0], 1e-300)))
    Ur = Ur[:, :rank]
    Y = W @ Ur
    if rank == 0:
        return PolytopeResult(success=True, status="singular", message="G = 0: a single point",
                              **{**empty, "vertices": np.zeros((1, m))})
    try:
        if rank == 1:
            y = Y[:, 0]
            idx = np.array([int(np.argmin(y)), int(np.argmax(y))])
            eq_r = np.array([[-1.0, y.min()], [1.0, -y.max()]])
            vol = float(y.max() - y.min())
        else:
            hull = ConvexHull(Y)
            idx, eq_r, vol = hull.vertices, hull.equations, float(hull.volume)
    except QhullError as e:
        return PolytopeResult(success=False, status="error", message=f"Qhull failed: {e}",
                              **empty)
    eqs = np.column_stack([eq_r[:, :-1] @ Ur.T, eq_r[:, -1]])
    if rank < m:
        N = _complement(Ur)
        flat = np.vstack([np.column_stack([N.T, np.zeros(N.shape[1])]),
                          np.column_stack([-N.T, np.zeros(N.shape[1])])])
        eqs = np.vstack([eqs, flat])
    status = "optimal" if rank == m else "singular"
    msg = (f"zonotope of {corners.shape[0]} actuator corners: {len(idx)} vertices, "
           f"{eq_r.shape[0]} facets, dimension {rank} of {m}")
    if rank < m:
        msg = f"{_sing_message(sm)}; flat polytope: " + msg
    return PolytopeResult(vertices=W[idx], equations=eqs, dimension=rank, volume=vol,
                          success=True, status=status, message=msg,
                          wrench_names=sm.wrench_names)


def _complement(U: np.ndarray) -> np.ndarray:
    m, r = U.shape
    Q = np.linalg.svd(np.eye(m) - U @ U.T)[0]
    return Q[:, : m - r]


# --------------------------------------------------------------------------------------
# feasibility


def feasible(mech: Mechanism, q: Any, wrench_set: Any, limits: Any, **options: Any
             ) -> FeasibilityResult:
    """Is every wrench of a set achievable within the actuator limits at ``q``?

    The set is convex (a box or a polytope given by its vertices), so it is feasible iff
    every vertex is. One LP over all vertices maximises the margin mu: every vertex is
    produced with actuator forces in the shrunken box (1 - mu) [lo, hi].

    Parameters
    ----------
    wrench_set : array (m,), array (nv, m) or mapping
        One wrench, the vertices of a polytope, or a box ``{"lower": [...], "upper": [...]}``.
        Wrenches are applied BY the end effector (a load resisted is its negative).
    limits : see :func:`capability`

    Returns
    -------
    FeasibilityResult
        ``feasible``, ``margin`` (>= 0 iff feasible), ``tau`` (nv, na) at each vertex.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> c, s = np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)
    >>> base = np.array([[1, 0], [c, s], [c, -s]])
    >>> m = optkin.mechanisms.rpr3(base, 0.2 * base)
    >>> r = feasible(m, optkin.inverse(m, [0, 0, 0.4])[0], {"lower": [0, 0, -0.1],
    ...              "upper": [0, 0, 0.1]}, 1.0)
    >>> r.feasible, round(r.margin, 6)    # 1 - 0.1 / 0.285115
    (True, 0.649264)
    """
    opts = merge_options(STATICS_DEFAULTS, options, "feasible")
    sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    V = _wrench_set(wrench_set, sm)
    return _feasible(sm, lo, hi, V, opts)


def _feasible(sm: StaticModel, lo, hi, V, opts) -> FeasibilityResult:
    nv = V.shape[0]
    U = sm.unresisted
    tol = float(opts["dir_tol"])
    if U.shape[1]:
        bad = [v for v in range(nv)
               if np.linalg.norm(U.T @ V[v]) > tol * max(1.0, np.linalg.norm(V[v]))]
        if bad:
            return FeasibilityResult(
                feasible=False, margin=-np.inf, vertices=V, tau=np.full((nv, sm.na), np.nan),
                worst_vertex=bad[0], success=True, status="singular",
                message=(f"{_sing_message(sm)}: {len(bad)} of {nv} wrench vertices (first: "
                         f"{V[bad[0]].tolist()}) are not resisted"),
                singularity=sm.singularity, wrench_names=sm.wrench_names,
            )
    prob = pb.margin_problem(*_shape(sm), nv, reuse=bool(opts["reuse"]))
    vals = _params(sm, lo, hi)
    vals["W"] = V.T.copy()
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    if status in ("optimal", "inaccurate"):
        mu = float(out["mu"])
        tau = out["tau"].T
        with np.errstate(divide="ignore", invalid="ignore"):
            util = np.where(tau >= 0, tau / hi, tau / lo)
        util = np.nan_to_num(util, nan=0.0, posinf=np.inf)
        worst = int(np.argmax(util.max(axis=1)))
        ok = mu >= -1e-9
        msg = (f"{'feasible' if ok else 'infeasible'}: margin {mu:.6g} (worst vertex {worst}: "
               f"{np.round(V[worst], 6).tolist()}, utilisation {1 - mu:.6g})")
        return FeasibilityResult(feasible=bool(ok), margin=mu, vertices=V, tau=tau,
                                 worst_vertex=worst, success=True,
                                 status="optimal" if status == "optimal" else status,
                                 message=msg, singularity=sm.singularity,
                                 wrench_names=sm.wrench_names, stats=stats)
    if status == "infeasible":
        msg = ("some wrench of the set is outside the range of the static map (no actuator "
               "forces produce it); near a singularity?")
        return FeasibilityResult(feasible=False, margin=-np.inf, vertices=V,
                                 tau=np.full((nv, sm.na), np.nan), worst_vertex=-1,
                                 success=True, status="infeasible", message=msg,
                                 singularity=sm.singularity, wrench_names=sm.wrench_names,
                                 stats=stats)
    return FeasibilityResult(feasible=False, margin=np.nan, vertices=V,
                             tau=np.full((nv, sm.na), np.nan), worst_vertex=-1, success=False,
                             status=status, message=f"the margin LP failed ({raw})",
                             singularity=sm.singularity, wrench_names=sm.wrench_names,
                             stats=stats)


def _margins_batch(sms: list[StaticModel], lo, hi, V, n: int, opts: dict[str, Any]
                   ) -> tuple[list[float], list[str]]:
    """Margins of the wrench set V at several poses: one LP of n independent blocks."""
    prob = pb.margin_batch_problem(*_shape(sms[0]), V.shape[0], n, reuse=bool(opts["reuse"]))
    pad = sms + [sms[-1]] * (n - len(sms))
    vals: dict[str, Any] = {"lo": lo, "hi": hi, "W": V.T.copy()}
    for i, sm in enumerate(pad):
        vals[f"At{i}"] = sm.A.T.copy()
        vals[f"Bt{i}"] = sm.B.T.copy()
        if sm.P.shape[1]:
            vals[f"Pt{i}"] = sm.P.T.copy()
    status, _, _, out = pb.solve(prob, vals, opts["solver"])
    if status in ("optimal", "inaccurate") and out["mu"] is not None:
        return [float(v) for v in out["mu"][: len(sms)]], ["ok"] * len(sms)
    return [np.nan] * len(sms), ["fallback"] * len(sms)


def wrench_feasible_workspace(
    mech: Mechanism,
    wrench_set: Any,
    limits: Any,
    poses: Any = None,
    *,
    grid: int | Sequence[int] = 21,
    bounds: Any = None,
    fixed: Any = None,
    posture: int = 0,
    working_mode: Sequence[int] | None = None,
    path: str | None = None,
    **options: Any,
) -> WorkspaceResult:
    """Wrench feasibility (and margin) of ``wrench_set`` over a grid or a list of poses.

    Each pose is solved by :func:`optkin.inverse` and one posture is kept (``posture``
    index, or the one with the given ``working_mode``); the margin LP of :func:`feasible`
    (built once) is re-solved at each pose.

    Parameters
    ----------
    poses : array (N, task_dim), optional
        Task coordinates (``mech.task``). When None, a grid over the first two task
        coordinates: ``grid`` points per axis, ``bounds`` [[lo, hi], [lo, hi]] (default: the
        box of the base joints), the other coordinates from ``fixed`` (default home or 0).
    path : str, optional
        Write a PNG map of the margin (:func:`optkin.statics.plot_workspace`).

    Returns
    -------
    WorkspaceResult
        The margin and feasibility at every pose; unreachable poses (no posture, or none
        with ``working_mode``) are data, not errors.
    """
    from ..solvers.common import check_mechanism
    from ..solvers.inverse import inverse

    check_mechanism(mech, "wrench_feasible_workspace")
    opts = merge_options(STATICS_DEFAULTS, options, "wrench_feasible_workspace")
    td = mech.task_dim
    tnames = tuple(mech.task)
    grid_shape = None
    if poses is None and td < 2:
        raise StaticsError(
            f"grid: {mech.name} has {td} task coordinate(s) {list(tnames)}, a grid needs two; "
            f"give poses, an array (N, {td}) of task coordinates")
    if isinstance(posture, bool) or not isinstance(posture, (int, np.integer)) or posture < 0:
        raise StaticsError(f"posture: expected a non-negative integer index, got {posture!r}")
    if working_mode is not None:
        wm_ok = np.asarray(working_mode, dtype=object).ravel()
        if wm_ok.size != mech.n_actuated or any(v not in (1, -1) for v in wm_ok):
            raise StaticsError(
                f"working_mode: expected {mech.n_actuated} signs (+1 or -1), one per actuator "
                f"{list(mech.active_names)}, got {working_mode!r}")
    if poses is None:
        g = _numbers("grid", grid, int, "an integer or two integers (points per axis)")
        if g.size not in (1, 2):
            raise StaticsError(f"grid: expected an integer or two integers, got {grid!r}")
        g = np.broadcast_to(g, (2,))
        if np.any(g < 2):
            raise StaticsError(f"grid: expected at least 2 points per axis, got {grid!r}")
        if bounds is None:
            if mech.kind != "legs":
                raise StaticsError("bounds: required for a Khalil mechanism ([[lo, hi], [lo, hi]])")
            pts = np.array([leg.base[:2] for leg in mech.legs])
            bounds = np.column_stack([pts.min(axis=0), pts.max(axis=0)])
        b = _numbers("bounds", bounds, float, "[[lo, hi], [lo, hi]] with lo < hi")
        if b.shape != (2, 2) or not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
            raise StaticsError(f"bounds: expected [[lo, hi], [lo, hi]] with lo < hi, got {bounds!r}")
        if fixed is None:
            fixed = mech.home if (mech.kind == "legs" and mech.home is not None) else np.zeros(td)
        f = _numbers("fixed", fixed, float, f"{td} task coordinates {list(tnames)}").ravel()
        if f.shape != (td,) or not np.all(np.isfinite(f)):
            raise StaticsError(f"fixed: expected {td} finite task coordinates {list(tnames)}")
        xs = np.linspace(b[0, 0], b[0, 1], int(g[0]))
        ys = np.linspace(b[1, 0], b[1, 1], int(g[1]))
        X, Y = np.meshgrid(xs, ys, indexing="xy")
        P = np.tile(f, (X.size, 1))
        P[:, 0], P[:, 1] = X.ravel(), Y.ravel()
        grid_shape = X.shape
    else:
        P = np.atleast_2d(_numbers("poses", poses, float, f"an array (N, {td}) of task coordinates"))
        if P.ndim != 2 or P.shape[1] != td or not np.all(np.isfinite(P)):
            raise StaticsError(
                f"poses: expected an array (N, {td}) of finite task coordinates {list(tnames)}")
    N = P.shape[0]
    margin = np.full(N, np.nan)
    feas = np.zeros(N, dtype=bool)
    pstat: list[str] = ["unreachable"] * N
    t0 = time.perf_counter()
    sms: dict[int, StaticModel] = {}
    for i in range(N):
        sols = inverse(mech, P[i])
        sol = None
        if working_mode is not None:
            wm = tuple(int(v) for v in working_mode)
            sol = next((s for s in sols if s.working_mode == wm), None)
        elif len(sols) > posture:
            sol = sols[posture]
        if sol is not None and sol.success:
            sms[i] = static_model(mech, sol, float(opts["sing_tol"]))
    nsolve = 0
    if sms:
        first = next(iter(sms.values()))
        lo, hi = limits_of(limits, first)  # type: ignore[misc]
        V = _wrench_set(wrench_set, first)
        todo = []
        for i, sm in sms.items():
            U = sm.unresisted
            if U.shape[1] and any(np.linalg.norm(U.T @ v) > float(opts["dir_tol"]) * max(
                    1.0, np.linalg.norm(v)) for v in V):
                margin[i], pstat[i] = -np.inf, "singular"
            else:
                todo.append(i)
        n = max(1, min(int(opts.get("chunk", 64)), len(todo))) if todo else 1
        for c0 in range(0, len(todo), n):
            idx = todo[c0:c0 + n]
            mus, st = _margins_batch([sms[i] for i in idx], lo, hi, V, n, opts)
            nsolve += 1
            for i, mu, sti in zip(idx, mus, st):
                if sti == "fallback":  # the batch failed: solve this pose alone
                    r = _feasible(sms[i], lo, hi, V, opts)
                    nsolve += 1
                    mu = r.margin
                    sti = "singular" if r.status == "singular" else (
                        r.status if not r.success else "ok")
                margin[i] = mu
                feas[i] = bool(mu >= -1e-9)
                pstat[i] = ("feasible" if feas[i] else "infeasible") if sti == "ok" else sti
    dt = time.perf_counter() - t0
    nreach = sum(1 for s in pstat if s != "unreachable")
    nerr = sum(1 for s in pstat if s not in ("feasible", "infeasible", "unreachable", "singular"))
    msg = (f"{int(feas.sum())} of {nreach} reachable poses feasible ({N} poses, "
           f"{N - nreach} unreachable)")
    if nerr:
        msg += f"; the LP failed at {nerr} poses"
    res = WorkspaceResult(
        poses=P, margin=margin, feasible=feas, point_status=pstat, grid_shape=grid_shape,
        axes=tnames[:2], success=nerr == 0, status="optimal" if nerr == 0 else "error",
        message=msg, task_names=tnames,
        stats=SolverStats("HIGHS", 0.0, dt, nsolve, "", {"poses": N, "lp_solves": nsolve}),
    )
    if path is not None:
        from .plots import plot_workspace

        plot_workspace(res, path)
    return res


# --------------------------------------------------------------------------------------
# distribution


def _norm_name(norm: Any) -> str:
    if norm in (2, "2", 2.0, "l2", "two"):
        return "2"
    if norm in ("inf", "max", "linf") or (isinstance(norm, float) and np.isinf(norm)):
        return "inf"
    raise StaticsError(f"norm: expected 2 or 'inf', got {norm!r}")


def distribute(
    mech: Mechanism,
    q: Any,
    wrench: Any,
    limits: Any = None,
    norm: Any = 2,
    weights: Any = None,
    **options: Any,
) -> DistributionResult:
    """Actuator forces producing ``wrench`` (applied by the end effector), sharing the load.

    Solves  min ||diag(w) tau||  s.t.  F = A^T lambda, tau = -B^T lambda, P^T lambda = 0,
    lo <= tau <= hi, with the 2-norm (a QP, Clarabel) or the largest entry (``norm="inf"``,
    an LP, HiGHS). With redundant actuation (more actuators than dof) the solution is one
    of infinitely many; without, it is the unique tau = G^-1 F (limits permitting).

    Parameters
    ----------
    wrench : array (m,)
        The wrench F the end effector applies (the load it resists is -F).
    limits : optional, see :func:`capability`
    norm : 2 or "inf"
    weights : array (na,), optional
        Positive weights w_i (e.g. 1 / tau_max_i to share the load in proportion to the
        actuator sizes).

    Returns
    -------
    DistributionResult
        ``status="infeasible"`` (``success=False``) when the limits cannot produce F.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = optkin.mechanisms.rpr4([[0, 0], [1, 0], [1, 1], [0, 1]],
    ...                            [[-.1, -.1], [.1, -.1], [.1, .1], [-.1, .1]])
    >>> r = distribute(m, optkin.inverse(m, [0.5, 0.5, 0.3])[0], [0, 1.0, 0])
    >>> r.success, np.round(r.tau, 4).tolist()
    (True, [0.3269, 0.3784, -0.3269, -0.3784])
    """
    opts = merge_options(STATICS_DEFAULTS, options, "distribute")
    sm = static_model(mech, q, float(opts["sing_tol"]))
    nm = _norm_name(norm)
    try:
        F = np.asarray(wrench, dtype=float).ravel()
    except (TypeError, ValueError):
        raise StaticsError(f"wrench: expected {sm.m} numbers, got {wrench!r}") from None
    if F.shape != (sm.m,) or not np.all(np.isfinite(F)):
        raise StaticsError(
            f"wrench: expected {sm.m} finite components {list(sm.wrench_names)}, got "
            f"{np.asarray(wrench).tolist()}"
        )
    lh = limits_of(limits, sm, required=False)
    w = np.ones(sm.na) if weights is None else np.asarray(weights, dtype=float).ravel()
    if w.shape != (sm.na,) or np.any(~np.isfinite(w)) or np.any(w <= 0):
        raise StaticsError(f"weights: expected {sm.na} positive numbers, got {weights!r}")
    lo, hi = lh if lh is not None else (np.zeros(sm.na), np.zeros(sm.na))
    prob = pb.distribution_problem(*_shape(sm), nm, lh is not None, reuse=bool(opts["reuse"]))
    vals = {"At": sm.A.T.copy(), "Bt": (sm.B * w[None, :]).T.copy(), "lo": lo * w,
            "hi": hi * w, "F": F}
    if sm.P.shape[1]:
        vals["Pt"] = sm.P.T.copy()
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    nan = np.full(sm.na, np.nan)
    if status not in ("optimal", "inaccurate") or out["tau"] is None:
        if status == "infeasible":
            why = ("the actuator limits cannot produce this wrench" if lh is not None else
                   "no actuator forces produce this wrench")
            if sm.unresisted.shape[1] and np.linalg.norm(sm.unresisted.T @ F) > 1e-9 * max(
                    1.0, np.linalg.norm(F)):
                why = _sing_message(sm)
            msg = f"infeasible: {why}"
        else:
            msg = f"the distribution problem failed ({raw})"
        return DistributionResult(tau=nan, multipliers=np.full(sm.A.shape[0], np.nan),
                                  wrench=F, norm=nm, value=np.nan, residual=np.nan,
                                  utilisation=None, success=False, status=status, message=msg,
                                  singularity=sm.singularity, actuator_names=sm.actuator_names,
                                  stats=stats)
    lam = out["lambda"]
    tau = -sm.B.T @ lam
    resid = float(np.max(np.abs(sm.A.T @ lam - F))) if sm.m else 0.0
    value = float(np.linalg.norm(w * tau, 2 if nm == "2" else np.inf))
    util = None
    if lh is not None:
        with np.errstate(divide="ignore", invalid="ignore"):
            util = np.where(tau >= 0, tau / hi, tau / lo)
        util = np.nan_to_num(util, nan=0.0)
    msg = (f"{'minimum 2-norm' if nm == '2' else 'minimum largest'} actuator forces: "
           f"|w tau| = {value:.6g}, wrench residual {resid:.2e}")
    if sm.singularity != "none":
        msg += f" ({_sing_message(sm)})"
    return DistributionResult(tau=tau, multipliers=lam, wrench=F, norm=nm, value=value,
                              residual=resid, utilisation=util, success=True,
                              status=status if sm.singularity == "none" else "singular",
                              message=msg, singularity=sm.singularity,
                              actuator_names=sm.actuator_names, stats=stats)


def _numbers(name: str, v: Any, dtype: type, expected: str) -> np.ndarray:
    """``np.asarray(v, dtype)``, or a StaticsError naming ``name`` and what was expected."""
    try:
        return np.asarray(v, dtype=dtype)
    except (TypeError, ValueError):
        raise StaticsError(f"{name}: expected {expected}, got {v!r}") from None
