"""Shared pieces of the solvers: options, input checks, Newton iterations, results."""

from __future__ import annotations

import difflib
import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from .._checks import MAX_ABS, as_matrix, as_vector, check_mechanism, check_option
from .._checks import show as _show
from ..errors import MechanismError, NumericError
from ..model import Model
from ..numeric import singular_values
from ..results import KinResult, SolverStats

__all__ = ["merge_options", "count_option", "check_qa", "check_mechanism", "check_result_of",
           "newton", "make_result", "parse_guess"]


def merge_options(defaults: Mapping[str, Any], given: Mapping[str, Any], where: str) -> dict[str, Any]:
    """Merge keyword options over defaults.

    An unknown name is an error (a :class:`MechanismError` naming it, the closest known
    name when one is close, and every known option), in Python as in problem files: a
    misspelt tolerance must not silently leave the default in force.

    An option whose default is a number (tolerances, counts, limits, seeds) must be given
    a real number >= 0 of magnitude at most ``MAX_ABS`` (inf allowed, e.g. to disable a
    limit), else a :class:`MechanismError` names the option and its default
    (:func:`optkin._checks.check_option`); the value is returned as a float (an int for an
    integral int). Each function checks its own ranges with ``check_option``.

    This is the one options validator of optkin: every public function that takes
    ``**options`` merges them here over its module's ``*_DEFAULTS`` mapping.
    """
    out = dict(defaults)
    for k, v in given.items():
        if k not in defaults:
            close = suggest(str(k), [str(d) for d in defaults])
            hint = f" (did you mean {close!r}?)" if close else ""
            raise MechanismError(
                f"{where}: unknown option {_show(k)}{hint}; known options: {sorted(defaults)}",
                path=("options", str(k)))
        d = defaults[k]
        if isinstance(d, (int, float)) and not isinstance(d, bool):
            f = check_option({k: v}, k, where, defaults, lo=0.0, finite=False)
            v = int(v) if isinstance(d, int) and isinstance(v, (int, np.integer)) else f
        out[k] = v
    return out


def suggest(name: str, known: list[str]) -> str | None:
    """The known name ``name`` most likely misspells: one it starts with or that starts with
    it (``tolerance`` -> ``tol``), else the closest by difflib, else None."""
    pre = [k for k in known if k and (name.startswith(k) or k.startswith(name))]
    if pre:
        return max(pre, key=len)
    close = difflib.get_close_matches(name, known, n=1)
    return close[0] if close else None


def count_option(opts: Mapping[str, Any], name: str, where: str, lo: int, hi: int,
                 defaults: Mapping[str, Any]) -> int:
    """``opts[name]`` as an integer in [lo, hi], else a MechanismError naming the option
    (:func:`optkin._checks.check_option`)."""
    return int(check_option(opts, name, where, defaults, integer=True, lo=lo, hi=hi))


def check_result_of(mech: Any, r: KinResult, where: str) -> None:
    """Raise a MechanismError naming ``where`` when ``r`` was solved on another mechanism.

    Results carry the joint names of their mechanism; one with other names (or, without
    names, with a q of another length) cannot describe a configuration of ``mech``.
    """
    names = tuple(r.joint_names or ())
    mine = tuple(mech.joint_names)
    if (names and names != mine) or (not names and np.size(r.q) != len(mine)):
        got = list(names) if names else f"{np.size(r.q)} joint values"
        raise MechanismError(
            f"{where}: the KinResult belongs to another mechanism (joints {got}), not "
            f"{mech.name!r} (joints {list(mine)}); solve on this mechanism first")


def check_qa(model: Model, qa: Any) -> np.ndarray:
    """The active joint values as a finite float vector (one per active joint), else a
    MechanismError naming the joint; leg lengths must be positive."""
    mech = model.mech
    na = mech.n_actuated
    try:
        shape = np.shape(qa)
    except (ValueError, TypeError, RecursionError):
        shape = None
    if shape is not None and len(shape) == 1 and shape[0] != na:
        raise MechanismError(
            f"qa: expected {na} values for the active joints {list(mech.active_names)}, "
            f"got shape {shape}", path=("qa",))
    a = as_vector(qa, "qa", na, names=mech.active_names, path=("qa",))
    pos = model.qa_positive
    if pos.any() and np.min(a[pos]) <= 0:
        i = int(np.flatnonzero(pos)[np.argmin(a[pos])])
        raise MechanismError(
            f"qa[{i}] ({mech.active_names[i]}): a leg length must be positive, got {a[i]:g}",
            path=("qa", i))
    return a


def parse_guess(model: Model, qa: np.ndarray, guess: Any) -> np.ndarray:
    """The starting unknowns x from a guess: None, a KinResult, x, q, q_p or a pose."""
    mech = model.mech
    if guess is None:
        return model.default_x(qa)
    if isinstance(guess, KinResult):
        check_result_of(mech, guess, "guess")
        x = np.asarray(guess.x, dtype=float).copy()
        if x.shape != (model.nx,) or not np.all(np.isfinite(x)):
            raise MechanismError("guess: the KinResult has no finite configuration (a failed "
                                 "solve?); pass a successful result or joint values",
                                 path=("guess",))
        return x
    try:
        ndim = np.ndim(guess)
    except (ValueError, TypeError, RecursionError):
        ndim = 1
    try:
        g = (as_matrix(guess, "guess", path=("guess",)) if ndim == 2 else
             as_vector(guess, "guess", path=("guess",)))
    except MechanismError as e:
        if "non-finite" in str(e) or "too large" in str(e):
            raise MechanismError(f"guess: has non-finite entries or entries beyond {MAX_ABS:g}",
                                 path=("guess",)) from None
        raise MechanismError(f"guess: expected numbers, got {_show(guess)}",
                             path=("guess",)) from None
    nq = len(mech.joint_names)
    npas = nq - mech.n_actuated
    if g.shape == (4, 4):
        return model.x_from_pose(g, qa)
    if g.ndim == 1 and g.size == model.nx:
        return g.copy()
    if g.ndim == 1 and g.size == nq:
        return model.x_from_q(g)
    if g.ndim == 1 and g.size == npas:
        q = np.empty(nq)
        act = np.array(mech.actuated)
        q[act] = qa
        q[~act] = g
        return model.x_from_q(q)
    if g.ndim == 1 and g.size == mech.task_dim and model.platform is not None:
        return model.x_from_task(g, qa)
    raise MechanismError(
        f"guess: expected the unknowns x ({model.nx}: {list(model.x_names)}), all joints ({nq}), "
        f"the passive joints ({npas}), a 4x4 pose or a KinResult; got shape {g.shape}",
        path=("guess",)
    )


def newton(model: Model, qa: np.ndarray, x: np.ndarray, tol: float, max_iter: int):
    """Damped Newton iterations (7.9). Returns (x, residual, iterations, converged).

    Once the residual is below ``tol``, up to two more steps polish it to round-off. The
    step is evaluated through a buffered (and, when available, compiled) Function.
    """
    ev = model.fast("newton_step")
    qa = np.asarray(qa, dtype=float)
    best_x, best_r = x, np.inf
    extra = 0
    floor = 1e-14 * max(1.0, model.length)
    for it in range(max_iter):
        xn, rr = ev(qa, x)
        r = float(rr[0])
        if r < best_r:
            best_x, best_r = x, r
        if r <= tol:
            extra += 1
            if extra > 2 or r < floor:
                return best_x, best_r, it, True
        elif extra:
            return best_x, best_r, it, best_r <= tol
        if not (math.isfinite(r) and math.isfinite(float(xn.sum()))):
            return best_x, best_r, it, best_r <= tol
        x = xn.copy()
    if model.m:
        phi = model.fast("Phi")(qa, x)[0]
        r = float(np.max(np.abs(phi)))
    else:
        r = 0.0
    if r < best_r:
        best_x, best_r = x, r
    return best_x, best_r, max_iter, best_r <= tol


def make_result(
    model: Model,
    qa: np.ndarray,
    x: np.ndarray,
    tol: float,
    nit: int,
    stats: SolverStats,
    status: str | None = None,
    message: str | None = None,
    posture: tuple[int, ...] | None = None,
    working_mode: tuple[int, ...] | None = None,
) -> KinResult:
    mech = model.mech
    x = model.canonical_x(x)
    qa = np.array(qa, dtype=float)
    # one fused evaluation: Phi, W_p, the pose and all joints (optkin.model.fused)
    phi_b, wp_b, T_b, q_b = model.fast("result")(qa, x)
    res = float(np.max(np.abs(phi_b))) if phi_b.size else 0.0
    finite = bool(np.isfinite(x).all()) and math.isfinite(res)
    Wp = wp_b.reshape((model.nx, model.m)).T
    try:
        if finite and Wp.size and np.isfinite(Wp).all() and np.abs(Wp).max() < 1e150:
            sv = np.linalg.svd(Wp, compute_uv=False)  # (no scaling needed at this size)
        else:
            sv = singular_values(Wp, "W_p") if finite and Wp.size else None
        cond = float(sv[0] / sv[-1]) if sv is not None and sv[-1] > 0 else float("inf")
    except (NumericError, np.linalg.LinAlgError):  # W_p undefined here (a leg of zero length)
        cond = float("nan")
    success = bool(finite and res <= tol)
    if status is None:
        status = "optimal" if success else "infeasible"
    if message is None:
        if success:
            message = f"closure satisfied: max |Phi| = {res:.2e}"
        else:
            worst = (model.row_names[int(np.nanargmax(np.abs(phi_b)))]
                     if phi_b.size and finite else "?")
            message = (
                f"the loops do not close for these inputs: max |Phi| = {res:.2e} "
                f"(worst row {worst}); the active joint values may be out of reach"
            )
    if finite:
        q = q_b.copy()
        pose = T_b.reshape((4, 4)).T.copy()
    else:
        q = np.full(len(mech.joint_names), np.nan)
        pose = np.full((4, 4), np.nan)
    if success and mech.limits and not mech.within_limits(q):
        message += "; outside the joint limits: " + ", ".join(
            n for n, v in zip(mech.joint_names, q)
            if n in mech.limits and not mech.limits[n][0] <= v <= mech.limits[n][1])
    ip, ic = model.qp_index, model.qc_index
    stats.nit = nit
    return KinResult(
        q=q,
        qa=qa,
        qp=q[ip],
        qc=q[ic],
        x=x,
        pose=pose,
        success=success,
        status=status if success or status != "optimal" else "infeasible",
        message=message,
        residual=res,
        nit=nit,
        stats=stats,
        posture=posture,
        working_mode=working_mode,
        cond=cond,
        joint_names=tuple(mech.joint_names),
        task_names=model.task_names,
        task_space=model.task_space,
    )


def timer() -> float:
    return time.perf_counter()
