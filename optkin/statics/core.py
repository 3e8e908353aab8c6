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

from .. import numeric
from .._checks import MAX_ABS, as_int, as_matrix, as_vector, check_option, show
from .._dryrun import checkpoint, computing
from ..errors import NumericError, StaticsError
from ..limits import Deadline
from ..mechanism import Mechanism
from ..model import get_model
from ..model import statics as ms
from ..model.home import home_task
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


#: Most directions, wrench vertices or box components an analysis takes.
MAX_DIRECTIONS = 4096
MAX_BOX_COMPONENTS = 12
#: Most points per axis of the grid of :func:`wrench_feasible_workspace`.
MAX_GRID = 1000
#: Relative tolerance of the check of every solver answer against its constraints.
CHECK_RTOL = 1e-6


# --------------------------------------------------------------------------------------
# inputs


def _options(options: Mapping[str, Any], where: str) -> dict[str, Any]:
    """The statics options merged over :data:`STATICS_DEFAULTS` and range-checked."""
    opts = merge_options(STATICS_DEFAULTS, options, where)

    def bad(name: str, want: str) -> StaticsError:
        return StaticsError(f"{where}: option {name} must be {want} (default "
                            f"{STATICS_DEFAULTS[name]!r}), got {show(opts[name])}",
                            path=("options", name))

    def number(name: str, **bounds: Any) -> Any:
        return check_option(opts, name, where, STATICS_DEFAULTS, error=StaticsError, **bounds)

    opts["sing_tol"] = number("sing_tol", lo=0.0, hi=1.0, hi_open=True)
    opts["cap"] = number("cap", lo=0.0, lo_open=True)
    opts["dir_tol"] = number("dir_tol", lo=0.0)
    opts["chunk"] = number("chunk", integer=True, lo=1, hi=4096)
    if not isinstance(opts["reuse"], (bool, int, np.bool_)) or opts["reuse"] not in (True, False):
        raise bad("reuse", "True or False")
    solver = opts["solver"]
    if solver is not None:
        import cvxpy as cp

        if not isinstance(solver, str) or solver.upper() not in cp.installed_solvers():
            raise bad("solver", f"None or an installed cvxpy solver {cp.installed_solvers()}")
        opts["solver"] = solver.upper()
    return opts


def _pow2(*arrays: np.ndarray) -> float:
    """The power of two at or above the largest magnitude in ``arrays`` (1 for all zero)."""
    m = max((float(np.max(np.abs(a))) for a in arrays if np.size(a)), default=0.0)
    return float(2.0 ** np.ceil(np.log2(m))) if m > 0 else 1.0


def limits_of(limits: Any, sm: StaticModel, required: bool = True
              ) -> tuple[np.ndarray, np.ndarray] | None:
    """(lo, hi) from a scalar, one bound per actuator (``|tau_i|`` <= b_i) or pairs (lo_i, hi_i)."""
    na, names = sm.na, list(sm.actuator_names)
    if limits is None:
        if required:
            raise StaticsError(
                f"limits: required; give one bound per actuator {names} (|tau_i| <= b_i) or "
                "pairs [lo_i, hi_i]", path=("limits",)
            )
        return None
    try:
        a = np.asarray(limits, dtype=float)
    except (TypeError, ValueError, OverflowError, RecursionError):
        raise StaticsError(f"limits: expected numbers, got {show(limits)}",
                           path=("limits",)) from None
    if a.ndim == 0:
        a = np.full(na, float(a))
    if a.shape == (na,):
        if np.any(a < 0):
            bad = [names[i] for i in np.flatnonzero(a < 0)]
            raise StaticsError(
                f"limits: bounds |tau_i| <= b_i must be >= 0, negative for {bad}; give pairs "
                "[lo, hi] for one-sided limits", path=("limits",)
            )
        lo, hi = -a, a.copy()
    elif a.shape == (na, 2):
        lo, hi = a[:, 0].copy(), a[:, 1].copy()
        if np.any(lo > 0) or np.any(hi < 0):
            bad = [names[i] for i in np.flatnonzero((lo > 0) | (hi < 0))]
            raise StaticsError(
                f"limits: each pair [lo, hi] must contain 0 (lo <= 0 <= hi); not so for {bad}",
                path=("limits",)
            )
    else:
        raise StaticsError(
            f"limits: expected a number, {na} bounds or {na} pairs [lo, hi] for the actuators "
            f"{names}, got shape {a.shape}", path=("limits",)
        )
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise StaticsError("limits: must be finite; use a large number for 'unlimited'",
                           path=("limits",))
    if max(np.abs(lo).max(initial=0.0), np.abs(hi).max(initial=0.0)) > MAX_ABS:
        raise StaticsError(f"limits: magnitudes above {MAX_ABS:g}; give limits of sensible size",
                           path=("limits",))
    return lo + 0.0, hi + 0.0


def _directions(directions: Any, sm: StaticModel) -> np.ndarray:
    m, names = sm.m, list(sm.wrench_names)
    if directions is None:
        return np.vstack([np.eye(m), -np.eye(m)])
    if isinstance(directions, str):
        if directions not in names and not (directions[:1] == "-" and directions[1:] in names):
            raise StaticsError(f"directions: unknown component {show(directions)}; use one of "
                               f"{names}", path=("directions",))
        directions = [directions]
    if isinstance(directions, (list, tuple)) and directions and all(
            isinstance(d, str) for d in directions):
        if len(directions) > MAX_DIRECTIONS:
            raise StaticsError(f"directions: at most {MAX_DIRECTIONS}", path=("directions",))
        rows = []
        for i, d in enumerate(directions):
            sgn = -1.0 if d.startswith("-") else 1.0
            key = d.lstrip("-+")
            if key not in names:
                raise StaticsError(f"directions: unknown component {show(d)}; use one of {names}",
                                   path=("directions", i))
            e = np.zeros(m)
            e[names.index(key)] = sgn
            rows.append(e)
        return np.array(rows)
    try:
        D = np.atleast_2d(as_matrix(_rows(directions), "directions",
                                    error=StaticsError, path=("directions",)))
    except StaticsError:
        raise StaticsError(
            f"directions: expected an array (k, {m}) of finite wrench directions {names} of "
            f"magnitude at most {MAX_ABS:g}, got {show(directions)}", path=("directions",)
        ) from None
    if D.shape[1] != m or D.shape[0] == 0 or D.shape[0] > MAX_DIRECTIONS:
        raise StaticsError(
            f"directions: expected an array (k, {m}) of wrench directions {names} with 1 <= k "
            f"<= {MAX_DIRECTIONS}, got shape {np.shape(directions)}", path=("directions",)
        )
    D = D / _pow2(D)  # exact: no overflow in the norms below
    n = np.linalg.norm(D, axis=1)
    if np.any(n == 0):
        raise StaticsError("directions: every direction must be finite and non-zero",
                           path=("directions",))
    return D / n[:, None]


def _float_array(v: Any) -> Any:
    """``v`` as a float array when numpy can read it, else ``v`` (the converter says why)."""
    try:
        return np.asarray(v, dtype=float)
    except (TypeError, ValueError, OverflowError, RecursionError):
        return v


def _rows(v: Any) -> Any:
    """``v`` as a 2-D float array (one row for a vector) when numpy can read it, else ``v``."""
    a = _float_array(v)
    return np.atleast_2d(a) if isinstance(a, np.ndarray) else a


def box(lower: Any, upper: Any) -> np.ndarray:
    """The 2^m vertices (rows) of the wrench box lower <= F <= upper.

    Parameters
    ----------
    lower, upper : array (m,)
        Finite bounds of each wrench component, ``lower <= upper`` (at most 12 components).

    Returns
    -------
    ndarray (2^m, m)
        The corners, in binary order (last component fastest).

    Examples
    --------
    >>> box([-1, 0], [1, 2]).tolist()
    [[-1.0, 0.0], [-1.0, 2.0], [1.0, 0.0], [1.0, 2.0]]
    """
    try:
        lo = as_vector(_ravel(lower), "lower", error=StaticsError, path=("lower",))
        hi = as_vector(_ravel(upper), "upper", error=StaticsError, path=("upper",))
    except StaticsError as e:
        raise StaticsError(
            f"wrench box: lower and upper must be finite (magnitude at most {MAX_ABS:g}), of "
            f"equal length, lower <= upper; {e}", path=e.path) from None
    if lo.shape != hi.shape or np.any(lo > hi) or lo.size > MAX_BOX_COMPONENTS:
        raise StaticsError(
            f"wrench box: lower and upper must be finite, of equal length (at most "
            f"{MAX_BOX_COMPONENTS}), lower <= upper; got {show(lo.tolist())} and "
            f"{show(hi.tolist())}", path=("upper",)
        )
    return np.array(list(itertools.product(*zip(lo, hi))), dtype=float)


def _ravel(v: Any) -> Any:
    a = _float_array(v)
    return a.ravel() if isinstance(a, np.ndarray) else a


def _wrench_set(ws: Any, sm: StaticModel) -> np.ndarray:
    m, names = sm.m, list(sm.wrench_names)
    if isinstance(ws, Mapping):
        keys = {str(k).lower() for k in ws}
        lo_k = "lower" if "lower" in keys else "min"
        hi_k = "upper" if "upper" in keys else "max"
        if lo_k not in keys or hi_k not in keys:
            raise StaticsError(
                "wrench_set: a box is a mapping with 'lower' and 'upper' (one value per "
                f"component {names})", path=("wrench_set",)
            )
        low = {str(k).lower(): v for k, v in ws.items()}
        V = box(low[lo_k], low[hi_k])
    else:
        try:
            V = as_matrix(_rows(ws), "wrench_set", error=StaticsError,
                          path=("wrench_set",))
        except StaticsError:
            V = np.full((0, 0), np.nan)
    if V.ndim != 2 or V.shape[1] != m or V.shape[0] > MAX_DIRECTIONS or not np.all(
            np.isfinite(V)) or V.size == 0:
        raise StaticsError(
            f"wrench_set: expected a wrench ({m},), vertices ({'{'}nv{'}'}, {m}) or a box "
            f"{{'lower': ..., 'upper': ...}} with components {names}, finite, of magnitude at "
            f"most {MAX_ABS:g}; got {show(ws)}", path=("wrench_set",)
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
        ``|tau_i|`` <= limits_i, or pairs (lo_i, hi_i) with lo_i <= 0 <= hi_i.
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
    opts = _options(options, "capability")
    with computing():  # the static model is an input of the checks below
        sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    D = _directions(directions, sm)
    checkpoint()  # validation stops here: every argument is checked
    return _capability(sm, lo, hi, D, opts)


def _cap_of(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, opts: dict[str, Any]) -> float:
    """The capability above which a direction counts as unbounded (serial singularity)."""
    lim = float(max(np.max(hi), np.max(-lo), 1e-300))
    normA = numeric.norm2(sm.A, "A") if sm.A.size else 1.0
    svB = numeric.singular_values(sm.B, "B") if sm.B.size else np.ones(1)
    sB = svB[svB > float(opts["sing_tol"]) * max(svB[0], 1e-300)]
    ref = lim * max(1.0, normA) / max(min(1.0, float(sB.min()) if sB.size else 1.0), 1e-12)
    return float(opts["cap"]) * ref


def _capability(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, D: np.ndarray,
                opts: dict[str, Any]) -> CapabilityResult:
    """One capability LP, solved on data scaled to the limits (a power of two: exact) and
    checked against its constraints before it is believed."""
    k = D.shape[0]
    if sm.singularity == "undefined":
        return _capability_result(sm, lo, hi, D, np.full(k, np.nan), np.full((k, sm.na), np.nan),
                                  np.nan, "error", sm.extra["why"], SolverStats(
                                      "none", 0.0, 0.0, 0, "not solved"), opts)
    cap = _cap_of(sm, lo, hi, opts)
    sc = _pow2(lo, hi)
    prob = pb.capability_problem(*_shape(sm), k, reuse=bool(opts["reuse"]))
    vals = _params(sm, lo / sc, hi / sc)
    vals.update({"D": D.T.copy(), "cap": cap / sc})
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    if out["s"] is None or out["L"] is None:
        s, tau = np.full(k, np.nan), np.full((k, sm.na), np.nan)
    else:
        status, raw = _checked(status, raw, _violation(sm, out["L"], D.T * out["s"][None, :],
                                                       lo / sc, hi / sc))
        s, tau = out["s"] * sc, out["tau"].T * sc
    return _capability_result(sm, lo, hi, D, s, tau, cap, status, raw, stats, opts)


def _violation(sm: StaticModel, L: np.ndarray, target: np.ndarray, lo: np.ndarray,
               hi: np.ndarray, shrink: Any = 1.0) -> float:
    """The largest relative violation of the static model by the multipliers ``L`` (columns):
    A^T L = target, P^T L = 0 and shrink * lo <= -B^T L <= shrink * hi. Data scaled to ~1."""
    L = np.reshape(L, (sm.A.shape[0], -1))
    target = np.reshape(target, (sm.m, -1))
    if not (np.isfinite(L).all() and np.isfinite(target).all()):
        return float("inf")
    eq = np.abs(sm.A.T @ L - target).max(initial=0.0)
    if sm.P.shape[1]:
        eq = max(eq, np.abs(sm.P.T @ L).max(initial=0.0))
    eq /= 1.0 + float(np.abs(target).max(initial=0.0))
    tau = -sm.B.T @ L
    sh = np.reshape(np.asarray(shrink, dtype=float), (1, -1))
    with np.errstate(invalid="ignore"):
        hs, ls = hi[:, None] * sh, lo[:, None] * sh
        over = np.maximum(np.where(np.isfinite(hs), tau - hs, 0.0),
                          np.where(np.isfinite(ls), ls - tau, 0.0))
    bounds = np.abs(np.concatenate([lo, hi]))
    lim = max(float(bounds[np.isfinite(bounds)].max(initial=0.0)), 1.0)
    return float(max(eq, over.max(initial=0.0) / (lim * max(1.0, float(np.abs(sh).max())))))


def _checked(status: str, raw: str, violation: float) -> tuple[str, str]:
    """A solver's claim of success stands only when its answer satisfies the constraints."""
    if status in ("optimal", "inaccurate") and not violation <= CHECK_RTOL:
        return "error", (f"{raw}, but the answer violates the constraints by {violation:.2e} "
                         "(relative): not trusted")
    return status, raw


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
    if sm.singularity == "undefined":
        message, out_status = str(raw), "error"
    elif not ok:
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
    opts = _options(options, "capability_many")
    if isinstance(qs, (str, bytes)):
        raise StaticsError("qs: expected a sequence of configurations", path=("qs",))
    try:
        qs = list(qs)
    except TypeError:
        raise StaticsError("qs: expected a sequence of configurations", path=("qs",)) from None
    if not qs:
        return []
    chunk = as_int(chunk, "chunk", lo=1, hi=4096, error=StaticsError, path=("chunk",))
    sms = [static_model(mech, q, float(opts["sing_tol"])) for q in qs]
    lo, hi = limits_of(limits, sms[0])  # type: ignore[misc]
    D = _directions(directions, sms[0])
    bad = [i for i, sm in enumerate(sms) if sm.singularity == "undefined"]
    if bad:  # those poses alone (a failed result each), the others batched
        alone = {i: _capability(sms[i], lo, hi, D, opts) for i in bad}
        good = [q for i, q in enumerate(qs) if i not in alone]
        rest = iter(capability_many(mech, good, limits, directions, chunk, **options)
                    if good else [])
        return [alone[i] if i in alone else next(rest) for i in range(len(qs))]
    k, na = D.shape[0], sms[0].na
    n = min(int(chunk), len(sms))
    sc = _pow2(lo, hi)
    prob = pb.capability_batch_problem(*_shape(sms[0]), k, n, reuse=bool(opts["reuse"]))
    out: list[CapabilityResult] = []
    for c0 in range(0, len(sms), n):
        block = sms[c0:c0 + n]
        pad = block + [block[-1]] * (n - len(block))
        caps = [_cap_of(sm, lo, hi, opts) for sm in pad]
        vals: dict[str, Any] = {"lo": lo / sc, "hi": hi / sc, "D": D.T.copy(),
                                "cap": np.repeat(caps, k) / sc}
        for i, sm in enumerate(pad):
            vals[f"At{i}"] = sm.A.T.copy()
            vals[f"Bt{i}"] = sm.B.T.copy()
            if sm.P.shape[1]:
                vals[f"Pt{i}"] = sm.P.T.copy()
        status, raw, stats, res = pb.solve(prob, vals, opts["solver"])
        stats.extra["poses_in_lp"] = n
        for i, sm in enumerate(block):
            st, rw = status, raw
            if res["s"] is not None and res["L"] is not None:
                s = res["s"][i * k:(i + 1) * k]
                st, rw = _checked(status, raw, _violation(
                    sm, res["L"][:, i * k:(i + 1) * k], D.T * s[None, :], lo / sc, hi / sc))
                s = s * sc
                tau = res["tau"][:, i * k:(i + 1) * k].T * sc
            else:
                s, tau = np.full(k, np.nan), np.full((k, na), np.nan)
            out.append(_capability_result(sm, lo, hi, D, s, tau, caps[i], st, rw, stats,
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
    opts = _options(options, "capability_polygon")
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 3 <= n <= MAX_DIRECTIONS:
        raise StaticsError(f"n: expected an integer number of directions >= 3 and <= "
                           f"{MAX_DIRECTIONS}, got {show(n)}", path=("n",))
    with computing():  # the static model is an input of the checks below
        sm = static_model(mech, q, float(opts["sing_tol"]))
    names = list(sm.wrench_names)
    if isinstance(plane, (str, bytes)) or not isinstance(plane, Sequence) or not all(
            isinstance(c, str) for c in plane):
        raise StaticsError(f"plane: expected two different components of {names}, got "
                           f"{show(plane)}", path=("plane",))
    for c in plane:
        if c not in names:
            raise StaticsError(f"plane: unknown component {c!r}; use two of {names}",
                               path=("plane",))
    if len(plane) != 2 or plane[0] == plane[1]:
        raise StaticsError(f"plane: expected two different components of {names}, got {plane}",
                           path=("plane",))
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
    opts = _options(options, "polytope")
    with computing():  # the static model is an input of the checks below
        sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    return _polytope(sm, lo, hi, opts)


def _polytope(sm: StaticModel, lo: np.ndarray, hi: np.ndarray, opts: dict[str, Any]
              ) -> PolytopeResult:
    from scipy.spatial import ConvexHull, QhullError

    m = sm.m
    empty = dict(vertices=np.zeros((0, m)), equations=np.zeros((0, m + 1)), dimension=0,
                 volume=0.0, wrench_names=sm.wrench_names)
    if sm.singularity == "undefined":
        return PolytopeResult(success=False, status="error", message=sm.extra["why"], **empty)
    if sm.G is None:
        return PolytopeResult(success=False, status="singular",
                              message=f"{_sing_message(sm)}: the polytope is unbounded", **empty)
    if sm.na > 16:
        raise StaticsError(f"polytope: {sm.na} actuators give 2^{sm.na} corners; at most 16")
    corners = np.array(list(itertools.product(*zip(lo, hi))))
    W = corners @ sm.G.T
    try:
        Ur, sv, _ = numeric.svd(sm.G, "G", full_matrices=False)
    except NumericError as e:
        return PolytopeResult(success=False, status="error", message=str(e), **empty)
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
            if not np.isfinite(Y).all():
                raise ValueError("the corners' images are not finite")
            s_y = _pow2(Y)  # Qhull on data of magnitude ~1 (exact scaling)
            hull = ConvexHull(Y / s_y)
            idx, eq_r = hull.vertices, hull.equations.copy()
            eq_r[:, -1] *= s_y
            with np.errstate(over="ignore"):
                vol = float(hull.volume * np.float64(s_y) ** Y.shape[1])
    except (QhullError, ValueError) as e:
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
    Q = numeric.svd(np.eye(m) - U @ U.T, "complement")[0]
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
    opts = _options(options, "feasible")
    with computing():  # the static model is an input of the checks below
        sm = static_model(mech, q, float(opts["sing_tol"]))
    lo, hi = limits_of(limits, sm)  # type: ignore[misc]
    V = _wrench_set(wrench_set, sm)
    checkpoint()  # validation stops here: every argument is checked
    return _feasible(sm, lo, hi, V, opts)


def _feasible(sm: StaticModel, lo, hi, V, opts) -> FeasibilityResult:
    nv = V.shape[0]
    if sm.singularity == "undefined":
        return FeasibilityResult(feasible=False, margin=np.nan, vertices=V,
                                 tau=np.full((nv, sm.na), np.nan), worst_vertex=-1, success=False,
                                 status="error", message=sm.extra["why"],
                                 singularity=sm.singularity, wrench_names=sm.wrench_names)
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
    sc = _pow2(lo, hi, V)  # the margin is scale-free: solve on data of magnitude ~1
    prob = pb.margin_problem(*_shape(sm), nv, reuse=bool(opts["reuse"]))
    vals = _params(sm, lo / sc, hi / sc)
    vals["W"] = V.T / sc
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    if status in ("optimal", "inaccurate"):
        if out["mu"] is None or out["L"] is None:
            status, raw = "error", f"{raw} without a solution"
        else:
            status, raw = _checked(status, raw, _violation(sm, out["L"], V.T / sc, lo / sc,
                                                           hi / sc, 1 - float(out["mu"])))
    if status in ("optimal", "inaccurate"):
        mu = float(out["mu"])
        tau = out["tau"].T * sc
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
    sc = _pow2(lo, hi, V)
    vals: dict[str, Any] = {"lo": lo / sc, "hi": hi / sc, "W": V.T / sc}
    for i, sm in enumerate(pad):
        vals[f"At{i}"] = sm.A.T.copy()
        vals[f"Bt{i}"] = sm.B.T.copy()
        if sm.P.shape[1]:
            vals[f"Pt{i}"] = sm.P.T.copy()
    status, _, _, out = pb.solve(prob, vals, opts["solver"])
    if status in ("optimal", "inaccurate") and out["mu"] is not None and out["L"] is not None:
        nv = V.shape[0]
        mus = [float(v) for v in out["mu"][: len(sms)]]
        ok = [_violation(sm, out["L"][:, i * nv:(i + 1) * nv], V.T / sc, lo / sc, hi / sc,
                         1 - mus[i]) <= CHECK_RTOL for i, sm in enumerate(sms)]
        return mus, ["ok" if good else "fallback" for good in ok]
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
    opts = _options(options, "wrench_feasible_workspace")
    td = mech.task_dim
    tnames = tuple(mech.task)
    grid_shape = None
    if poses is None and td < 2:
        raise StaticsError(
            f"grid: {mech.name} has {td} task coordinate(s) {list(tnames)}, a grid needs two; "
            f"give poses, an array (N, {td}) of task coordinates", path=("grid",))
    if isinstance(posture, bool) or not isinstance(posture, (int, np.integer)) or posture < 0:
        raise StaticsError(f"posture: expected a non-negative integer index, got {show(posture)}",
                           path=("posture",))
    if working_mode is not None:
        try:
            wm_ok = np.asarray(working_mode, dtype=object).ravel()
        except (TypeError, ValueError):
            wm_ok = np.zeros(0, dtype=object)
        if wm_ok.size != mech.n_actuated or any(
                isinstance(v, (bool, np.bool_)) or v not in (1, -1) for v in wm_ok):
            raise StaticsError(
                f"working_mode: expected {mech.n_actuated} signs (+1 or -1), one per actuator "
                f"{list(mech.active_names)}, got {show(working_mode)}", path=("working_mode",))
    if poses is None:
        gl = list(grid) if isinstance(grid, (list, tuple, np.ndarray)) else [grid]
        if len(gl) not in (1, 2):
            raise StaticsError(f"grid: expected an integer or two integers, got {show(grid)}",
                               path=("grid",))
        g = [as_int(v, "grid", lo=2, hi=MAX_GRID, error=StaticsError, path=("grid",))
             for v in gl] * (3 - len(gl))
        if bounds is None:
            bounds = ms.base_box(get_model(mech))
            if bounds is None:
                raise StaticsError("bounds: required for a Khalil mechanism ([[lo, hi], [lo, hi]])",
                                   path=("bounds",))
        try:
            b = as_matrix(_float_array(bounds), "bounds", (2, 2), error=StaticsError)
        except StaticsError:
            b = np.full((2, 2), np.nan)
        if not np.all(np.isfinite(b)) or np.any(b[:, 0] >= b[:, 1]):
            raise StaticsError(f"bounds: expected [[lo, hi], [lo, hi]] with lo < hi, finite, got "
                               f"{show(bounds)}", path=("bounds",))
        if fixed is None:
            fixed = home_task(get_model(mech))
            if fixed is None:
                fixed = np.zeros(td)
        try:
            f = as_vector(_ravel(fixed), "fixed", td, error=StaticsError)
        except StaticsError:
            raise StaticsError(f"fixed: expected {td} finite task coordinates {list(tnames)}",
                               path=("fixed",)) from None
        xs = np.linspace(b[0, 0], b[0, 1], int(g[0]))
        ys = np.linspace(b[1, 0], b[1, 1], int(g[1]))
        X, Y = np.meshgrid(xs, ys, indexing="xy")
        P = np.tile(f, (X.size, 1))
        P[:, 0], P[:, 1] = X.ravel(), Y.ravel()
        grid_shape = X.shape
    else:
        try:
            P = as_matrix(_rows(poses), "poses", (None, td),
                          error=StaticsError)
        except (StaticsError, ValueError):
            P = np.zeros((0, 0))
        if P.shape[0] == 0 or P.shape[1] != td or P.shape[0] > MAX_GRID ** 2:
            raise StaticsError(
                f"poses: expected an array (N, {td}) of finite task coordinates {list(tnames)} "
                f"(1 <= N <= {MAX_GRID ** 2}), got {show(poses)}", path=("poses",))
    N = P.shape[0]
    margin = np.full(N, np.nan)
    feas = np.zeros(N, dtype=bool)
    pstat: list[str] = ["not computed"] * N
    t0 = time.perf_counter()
    deadline = Deadline()  # the time budget of one call (optkin.limits)
    n = max(1, min(int(opts.get("chunk", 64)), N))
    nsolve = 0
    lo = hi = V = None
    # poses in chunks: the static models of one chunk at a time (memory stays bounded)
    for c0 in range(0, N, n):
        if deadline.expired():
            break
        sms: dict[int, StaticModel] = {}
        for i in range(c0, min(N, c0 + n)):
            pstat[i] = "unreachable"
            sols = inverse(mech, P[i])
            sol = None
            if working_mode is not None:
                wm = tuple(int(v) for v in working_mode)
                sol = next((s for s in sols if s.working_mode == wm), None)
            elif len(sols) > posture:
                sol = sols[posture]
            if sol is not None and sol.success:
                sms[i] = static_model(mech, sol, float(opts["sing_tol"]))
        if not sms:
            continue
        if V is None:
            first = next(iter(sms.values()))
            lo, hi = limits_of(limits, first)  # type: ignore[misc]
            V = _wrench_set(wrench_set, first)
        todo = []
        for i, sm in sms.items():
            if sm.singularity == "undefined":
                margin[i], pstat[i] = np.nan, "error"
                continue
            U = sm.unresisted
            if U.shape[1] and any(np.linalg.norm(U.T @ v) > float(opts["dir_tol"]) * max(
                    1.0, np.linalg.norm(v)) for v in V):
                margin[i], pstat[i] = -np.inf, "singular"
            else:
                todo.append(i)
        if not todo:
            continue
        mus, st = _margins_batch([sms[i] for i in todo], lo, hi, V, n, opts)
        nsolve += 1
        for i, mu, sti in zip(todo, mus, st):
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
    nleft = sum(1 for s in pstat if s == "not computed")
    nerr = sum(1 for s in pstat if s not in ("feasible", "infeasible", "unreachable", "singular",
                                             "not computed"))
    nreach -= nleft
    msg = (f"{int(feas.sum())} of {nreach} reachable poses feasible ({N} poses, "
           f"{N - nreach - nleft} unreachable)")
    if nerr:
        msg += f"; the LP failed at {nerr} poses"
    status = "optimal" if nerr == 0 else "error"
    if nleft:
        status = "time_limit"
        msg = deadline.message("wrench_feasible_workspace") + f" ({nleft} poses not computed); {msg}"
    res = WorkspaceResult(
        poses=P, margin=margin, feasible=feas, point_status=pstat, grid_shape=grid_shape,
        axes=tnames[:2], success=nerr == 0 and not nleft, status=status,
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
    if isinstance(norm, str):
        if norm in ("2", "l2", "two"):
            return "2"
        if norm in ("inf", "max", "linf"):
            return "inf"
    elif isinstance(norm, (int, float, np.integer, np.floating)) and not isinstance(
            norm, (bool, np.bool_)):
        f = float(norm) if abs(norm) < 1e300 else float("nan")  # no OverflowError for 10**400
        if f == 2.0:
            return "2"
        if f == float("inf") or norm == float("inf"):
            return "inf"
    raise StaticsError(f"norm: expected 2 or 'inf', got {show(norm)}", path=("norm",))


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
    opts = _options(options, "distribute")
    with computing():  # the static model is an input of the checks below
        sm = static_model(mech, q, float(opts["sing_tol"]))
    nm = _norm_name(norm)
    try:
        F = as_vector(_ravel(wrench), "wrench", sm.m, error=StaticsError, path=("wrench",))
    except StaticsError:
        raise StaticsError(
            f"wrench: expected {sm.m} finite components {list(sm.wrench_names)} of magnitude "
            f"at most {MAX_ABS:g}, got {show(wrench)}", path=("wrench",)
        ) from None
    lh = limits_of(limits, sm, required=False)
    if sm.singularity == "undefined":
        nan = np.full(sm.na, np.nan)
        return DistributionResult(tau=nan, multipliers=np.full(sm.A.shape[0], np.nan), wrench=F,
                                  norm=nm, value=np.nan, residual=np.nan, utilisation=None,
                                  success=False, status="error", message=sm.extra["why"],
                                  singularity=sm.singularity, actuator_names=sm.actuator_names,
                                  stats=SolverStats("none", 0.0, 0.0, 0, "not solved"))
    try:
        w = np.ones(sm.na) if weights is None else as_vector(
            _ravel(weights), "weights", sm.na, error=StaticsError)
    except StaticsError:
        w = np.zeros(0)
    if w.shape != (sm.na,) or np.any(w <= 0) or np.any(w < 1 / MAX_ABS):
        raise StaticsError(f"weights: expected {sm.na} positive numbers (in [{1 / MAX_ABS:g}, "
                           f"{MAX_ABS:g}]), got {show(weights)}", path=("weights",))
    checkpoint()  # validation stops here: every argument is checked
    lo, hi = lh if lh is not None else (np.zeros(sm.na), np.zeros(sm.na))
    # solve on data of magnitude ~1: lambda, tau and the limits scale with the wrench and the
    # weighted limits by a power of two (exact), the answer is scaled back and checked
    sc = _pow2(F, lo * w, hi * w)
    prob = pb.distribution_problem(*_shape(sm), nm, lh is not None, reuse=bool(opts["reuse"]))
    vals = {"At": sm.A.T.copy(), "Bt": (sm.B * w[None, :]).T.copy(), "lo": lo * w / sc,
            "hi": hi * w / sc, "F": F / sc}
    if sm.P.shape[1]:
        vals["Pt"] = sm.P.T.copy()
    status, raw, stats, out = pb.solve(prob, vals, opts["solver"])
    if status in ("optimal", "inaccurate") and out["lambda"] is not None:
        status, raw = _checked(status, raw, _violation(
            sm, out["lambda"], F / sc, lo / sc if lh is not None else np.full(sm.na, -np.inf),
            hi / sc if lh is not None else np.full(sm.na, np.inf)))
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
        msg += f"; wrench {show(F.tolist())}"
        return DistributionResult(tau=nan, multipliers=np.full(sm.A.shape[0], np.nan),
                                  wrench=F, norm=nm, value=np.nan, residual=np.nan,
                                  utilisation=None, success=False, status=status, message=msg,
                                  singularity=sm.singularity, actuator_names=sm.actuator_names,
                                  stats=stats)
    lam = out["lambda"] * sc
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
