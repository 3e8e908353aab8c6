"""The cvxpy problems of the statics analyses, built once per shape and re-solved (DPP).

Each problem takes the static model (2) of :mod:`optkin.statics.model` through
``cp.Parameter`` s (A^T, B^T, P^T, the limits, the directions or wrenches), so moving to
another pose only assigns parameter values: cvxpy canonicalises a DPP problem once and then
re-uses the reduction (its "parameterized programs"). Problems are cached by their shape
(rows, wrench dimension, actuators, passive unknowns, number of directions / vertices),
so two mechanisms of the same shape share them; a lock makes set-and-solve atomic, and every
solve starts cold (no warm start), so that its answer does not depend on the history of the
process.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cvxpy as cp
import numpy as np

from .._cache import KeyedCache
from ..results import SolverStats

__all__ = ["CvxProblem", "capability_problem", "capability_batch_problem", "margin_problem",
           "margin_batch_problem", "distribution_problem",
           "solve", "cvx_status", "clear_cache"]

_CACHE: KeyedCache[CvxProblem] = KeyedCache()

#: cvxpy status -> optkin status (results.STATUS vocabulary)
STATUS_MAP = {
    cp.OPTIMAL: "optimal",
    cp.OPTIMAL_INACCURATE: "inaccurate",
    cp.INFEASIBLE: "infeasible",
    cp.INFEASIBLE_INACCURATE: "infeasible",
    cp.UNBOUNDED: "unbounded",
    cp.UNBOUNDED_INACCURATE: "unbounded",
    cp.USER_LIMIT: "iteration_limit",
    cp.SOLVER_ERROR: "error",
}


def cvx_status(raw: str | None) -> str:
    return STATUS_MAP.get(raw, "error")


@dataclass
class CvxProblem:
    """A parametrised cvxpy problem with its parameters and variables by name."""

    problem: cp.Problem
    params: dict[str, cp.Parameter]
    variables: dict[str, Any]
    solver: str
    build_time: float
    lock: threading.Lock
    nsolves: int = 0


def _cached(key: tuple, build: Callable[[], CvxProblem], reuse: bool) -> CvxProblem:
    if not reuse:
        return build()
    return _CACHE.get(key, build)


def clear_cache() -> None:
    _CACHE.clear()


def _col(v: cp.Expression, n: int, k: int) -> cp.Expression:
    """A parameter vector (n,) repeated as k columns (n, k)."""
    return cp.reshape(v, (n, 1), order="F") @ np.ones((1, k))


def _common(r: int, m: int, na: int, np_: int) -> dict[str, cp.Parameter]:
    prm = {
        "At": cp.Parameter((m, r), name="A_T"),
        "Bt": cp.Parameter((na, r), name="B_T"),
        "hi": cp.Parameter(na, nonneg=True, name="tau_hi"),
        "lo": cp.Parameter(na, nonpos=True, name="tau_lo"),
    }
    if np_:
        prm["Pt"] = cp.Parameter((np_, r), name="P_T")
    return prm


def capability_problem(r: int, m: int, na: int, np_: int, k: int, reuse: bool = True
                       ) -> CvxProblem:
    """max sum_j s_j  s.t.  A^T L = D diag(s), P^T L = 0, lo <= -B^T L <= hi, 0 <= s <= cap.

    Column j of L holds the multipliers of direction j (column j of D); the columns are
    independent, so the sum is maximised by maximising each s_j: one LP for k directions.
    """

    def build() -> CvxProblem:
        t0 = time.perf_counter()
        prm = _common(r, m, na, np_)
        prm["D"] = cp.Parameter((m, k), name="directions")
        prm["cap"] = cp.Parameter(nonneg=True, name="cap")
        L = cp.Variable((r, k), name="lambda")
        s = cp.Variable(k, name="s")
        tau = -prm["Bt"] @ L
        cons = [
            prm["At"] @ L == prm["D"] @ cp.diag(s),
            tau <= _col(prm["hi"], na, k),
            tau >= _col(prm["lo"], na, k),
            s >= 0,
            s <= prm["cap"],
        ]
        if np_:
            cons.append(prm["Pt"] @ L == 0)
        prob = cp.Problem(cp.Maximize(cp.sum(s)), cons)
        return CvxProblem(prob, prm, {"L": L, "s": s, "tau": tau}, "HIGHS",
                          time.perf_counter() - t0, threading.Lock())

    return _cached(("capability", r, m, na, np_, k), build, reuse)


def capability_batch_problem(r: int, m: int, na: int, np_: int, k: int, n: int,
                             reuse: bool = True) -> CvxProblem:
    """n independent copies of :func:`capability_problem` (one per pose) in one LP.

    Parameters ``At{i}``, ``Bt{i}`` (``Pt{i}``) per pose, shared ``D``, ``lo``, ``hi`` and
    a ``cap`` per (pose, direction); columns i*k .. (i+1)*k-1 of L and s belong to pose i.
    """

    def build() -> CvxProblem:
        t0 = time.perf_counter()
        prm: dict[str, cp.Parameter] = {
            "hi": cp.Parameter(na, nonneg=True, name="tau_hi"),
            "lo": cp.Parameter(na, nonpos=True, name="tau_lo"),
            "D": cp.Parameter((m, k), name="directions"),
            "cap": cp.Parameter(n * k, nonneg=True, name="cap"),
        }
        L = cp.Variable((r, n * k), name="lambda")
        s = cp.Variable(n * k, name="s")
        taus = []
        cons = [s >= 0, s <= prm["cap"]]
        H, Lo = _col(prm["hi"], na, k), _col(prm["lo"], na, k)
        for i in range(n):
            At = prm[f"At{i}"] = cp.Parameter((m, r), name=f"A_T{i}")
            Bt = prm[f"Bt{i}"] = cp.Parameter((na, r), name=f"B_T{i}")
            Li, si = L[:, i * k:(i + 1) * k], s[i * k:(i + 1) * k]
            tau = -Bt @ Li
            taus.append(tau)
            cons += [At @ Li == prm["D"] @ cp.diag(si), tau <= H, tau >= Lo]
            if np_:
                Pt = prm[f"Pt{i}"] = cp.Parameter((np_, r), name=f"P_T{i}")
                cons.append(Pt @ Li == 0)
        prob = cp.Problem(cp.Maximize(cp.sum(s)), cons)
        return CvxProblem(prob, prm, {"L": L, "s": s, "tau": cp.hstack(taus)}, "HIGHS",
                          time.perf_counter() - t0, threading.Lock())

    return _cached(("capability_batch", r, m, na, np_, k, n), build, reuse)


def margin_problem(r: int, m: int, na: int, np_: int, nv: int, reuse: bool = True
                   ) -> CvxProblem:
    """max mu  s.t.  A^T L = W, P^T L = 0, (1 - mu) lo <= -B^T L <= (1 - mu) hi, mu <= 1.

    Column v of W is a wrench (a vertex of the required set); 1 - mu is the smallest
    achievable worst utilisation max_i tau_i / limit_i over all vertices.
    """

    def build() -> CvxProblem:
        t0 = time.perf_counter()
        prm = _common(r, m, na, np_)
        prm["W"] = cp.Parameter((m, nv), name="wrenches")
        L = cp.Variable((r, nv), name="lambda")
        mu = cp.Variable(name="mu")
        tau = -prm["Bt"] @ L
        cons = [
            prm["At"] @ L == prm["W"],
            tau <= cp.multiply(_col(prm["hi"], na, nv), 1 - mu),
            tau >= cp.multiply(_col(prm["lo"], na, nv), 1 - mu),
            mu <= 1,
        ]
        if np_:
            cons.append(prm["Pt"] @ L == 0)
        prob = cp.Problem(cp.Maximize(mu), cons)
        return CvxProblem(prob, prm, {"L": L, "mu": mu, "tau": tau}, "HIGHS",
                          time.perf_counter() - t0, threading.Lock())

    return _cached(("margin", r, m, na, np_, nv), build, reuse)


def margin_batch_problem(r: int, m: int, na: int, np_: int, nv: int, n: int,
                         reuse: bool = True) -> CvxProblem:
    """n independent copies of :func:`margin_problem` (one per pose, each its own mu_i,
    maximising the sum); parameters ``At{i}``, ``Bt{i}`` (``Pt{i}``), shared W, lo, hi."""

    def build() -> CvxProblem:
        t0 = time.perf_counter()
        prm: dict[str, cp.Parameter] = {
            "hi": cp.Parameter(na, nonneg=True, name="tau_hi"),
            "lo": cp.Parameter(na, nonpos=True, name="tau_lo"),
            "W": cp.Parameter((m, nv), name="wrenches"),
        }
        L = cp.Variable((r, n * nv), name="lambda")
        mu = cp.Variable(n, name="mu")
        H, Lo = _col(prm["hi"], na, nv), _col(prm["lo"], na, nv)
        cons = [mu <= 1]
        for i in range(n):
            At = prm[f"At{i}"] = cp.Parameter((m, r), name=f"A_T{i}")
            Bt = prm[f"Bt{i}"] = cp.Parameter((na, r), name=f"B_T{i}")
            Li = L[:, i * nv:(i + 1) * nv]
            tau = -Bt @ Li
            cons += [At @ Li == prm["W"], tau <= cp.multiply(H, 1 - mu[i]),
                     tau >= cp.multiply(Lo, 1 - mu[i])]
            if np_:
                Pt = prm[f"Pt{i}"] = cp.Parameter((np_, r), name=f"P_T{i}")
                cons.append(Pt @ Li == 0)
        prob = cp.Problem(cp.Maximize(cp.sum(mu)), cons)
        return CvxProblem(prob, prm, {"L": L, "mu": mu}, "HIGHS", time.perf_counter() - t0,
                          threading.Lock())

    return _cached(("margin_batch", r, m, na, np_, nv, n), build, reuse)


def distribution_problem(r: int, m: int, na: int, np_: int, norm: str, limited: bool,
                         reuse: bool = True) -> CvxProblem:
    """min ||tau_w||_2^2 or ||tau_w||_inf  s.t.  A^T l = F, P^T l = 0, tau_w = -B_w^T l,
    lo_w <= tau_w <= hi_w (when ``limited``); B_w = B diag(w) and the limits are weighted
    outside (tau = tau_w / w), which keeps the problem DPP."""

    def build() -> CvxProblem:
        t0 = time.perf_counter()
        prm = _common(r, m, na, np_)
        prm["F"] = cp.Parameter(m, name="wrench")
        lam = cp.Variable(r, name="lambda")
        tau = -prm["Bt"] @ lam
        cons = [prm["At"] @ lam == prm["F"]]
        if limited:
            cons += [tau <= prm["hi"], tau >= prm["lo"]]
        if np_:
            cons.append(prm["Pt"] @ lam == 0)
        if norm == "2":
            obj = cp.Minimize(cp.sum_squares(tau))
            solver = "CLARABEL"
        else:
            obj = cp.Minimize(cp.norm_inf(tau))
            solver = "HIGHS"
        prob = cp.Problem(obj, cons)
        return CvxProblem(prob, prm, {"lambda": lam, "tau": tau}, solver,
                          time.perf_counter() - t0, threading.Lock())

    return _cached(("distribution", r, m, na, np_, norm, limited), build, reuse)


_BANNER = {"done": False}
_BANNER_LOCK = threading.Lock()


def _quiet_highs() -> None:
    """Create the process's first HiGHS instance with stdout (file descriptor 1) sent to
    /dev/null: HiGHS prints its copyright banner there once per process, whatever its
    options (``output_flag=False`` does not stop it), into a notebook, a pipe or the
    runner's progress bar."""
    with _BANNER_LOCK:
        if _BANNER["done"]:
            return
        _BANNER["done"] = True
        try:
            import highspy
        except ImportError:
            return
        try:
            sys.stdout.flush()
            saved = os.dup(1)
        except (OSError, ValueError, AttributeError):
            return
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, 1)
            highspy.Highs()
        finally:
            os.dup2(saved, 1)
            os.close(saved)
            os.close(null)


def solve(p: CvxProblem, values: dict[str, np.ndarray], solver: str | None = None,
          solver_options: dict[str, Any] | None = None
          ) -> tuple[str, str, SolverStats, dict[str, np.ndarray | None]]:
    """Assign parameter values and solve; returns (status, raw status, stats, variable values).

    Solver failures become the status ``"error"`` (never an exception).
    """
    name = solver or p.solver
    if str(name).upper() == "HIGHS" and not _BANNER["done"]:
        _quiet_highs()
    with p.lock:
        t0 = time.perf_counter()
        raw = None
        err = ""
        try:
            for k, v in values.items():
                if k in p.params:
                    p.params[k].value = v
            # no warm start: the answer must not depend on what this cached problem solved
            # before (another pose, another mechanism of the same shape)
            p.problem.solve(solver=name, warm_start=False, **(solver_options or {}))
            raw = p.problem.status
        except (cp.error.SolverError, ValueError, ArithmeticError) as e:
            err = f"{type(e).__name__}: {e}"
        dt = time.perf_counter() - t0
        out = {k: (None if v.value is None else np.array(v.value, dtype=float))
               for k, v in p.variables.items()}
        setup = p.build_time if p.nsolves == 0 else 0.0
        p.nsolves += 1
        nit = 0
        try:
            st = p.problem.solver_stats
            nit = int(st.num_iters or 0) if st is not None else 0
        except (AttributeError, TypeError, cp.error.SolverError):
            nit = 0
    status = cvx_status(raw) if raw is not None else "error"
    stats = SolverStats(name, setup, dt, nit, str(raw if raw is not None else err),
                        {"reused": p.nsolves > 1})
    return status, str(raw if raw is not None else err), stats, out
