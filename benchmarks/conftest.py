"""Shared pieces of the benchmark suite: the library mechanisms at reference configurations,
and the in-run baselines.

Every benchmark times optkin with pytest-benchmark and, beside it, an in-run baseline
(a numpy closed form, scipy.optimize.fsolve, or a naive casadi.nlpsol built per call),
timed with :func:`median_time`, so that ``extra_info["ratio"]`` (baseline / optkin) is
comparable across machines. ``extra_info`` also holds the status and the iterations.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np
import pytest

import optkin
from optkin import mechanisms as lib
from optkin.mechanism.tasks import task_to_pose


def stewart_gough() -> optkin.Mechanism:
    """A regular 6-6 platform (cond(W_p) about 2.5 at home)."""
    ab = np.deg2rad([-10, 10, 110, 130, 230, 250])
    ap = np.deg2rad([-50, 50, 70, 170, 190, 290])
    base = np.c_[np.cos(ab), np.sin(ab), np.zeros(6)]
    plat = 0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]
    return lib.stewart_gough(base, plat, home=[0.05, -0.03, 1.0, 0.1, -0.05, 0.2])


#: name -> factory of every library mechanism, with the geometry used in the benchmarks.
MECHANISMS: dict[str, Callable[[], optkin.Mechanism]] = {
    "rpr3": lambda: lib.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]],
                             home=[0.45, 0.35, 0.2]),
    "rrr3": lambda: lib.rrr3([[0, 0], [1, 0], [0.5, 0.9]], [[0, 0], [0.2, 0], [0.1, 0.17]],
                             0.6, 0.6, home=[0.42, 0.3, 0.1]),
    "five_bar": lambda: lib.five_bar(9.0, 8.0, 5.0, 5.0, 8.0),
    "four_bar": lambda: lib.four_bar(1.0, 2.0, 2.0, 2.5),
    "stewart_gough": stewart_gough,
    "delta": lambda: lib.delta(),
    "sr400": lambda: lib.sr400(),
    "akr3000": lambda: lib.akr3000(),
}


@dataclass
class Reference:
    """A mechanism at a closed reference configuration."""

    name: str
    mech: optkin.Mechanism
    qa: np.ndarray
    sol: optkin.KinResult


@cache
def reference(name: str) -> Reference:
    mech = MECHANISMS[name]()
    model = optkin.get_model(mech)
    if mech.kind == "legs":
        T = task_to_pose(mech, np.asarray(mech.home, dtype=float)) if mech.home is not None \
            else model.pose(np.ones(mech.dof), model.default_x(np.ones(mech.dof)))
        sols = optkin.inverse(mech, T)
        assert len(sols), f"{name}: reference pose out of reach"
        qa = np.asarray(sols[0].qa, dtype=float)
        sol = optkin.forward(mech, qa, guess=T)
    elif name == "four_bar":
        qa = np.array([1.0])
        sol = optkin.forward(mech, qa)
    elif name == "sr400":
        q = np.asarray(mech.home, dtype=float)
        qa = np.array([0.1, 0.3, 0.2, 0.1, 0.1, -0.3])  # away from the singular home
        sol = optkin.forward(mech, qa, guess=q)
    else:  # akr3000: an assembly from the IPOPT solver of the direct model
        qa = np.array([0.1, 0.6, 0.6, 0.2, 0.3, 0.4])
        sol = optkin.forward(mech, qa, method="ipopt")
    assert sol.success, f"{name}: reference configuration did not close: {sol.message}"
    return Reference(name, mech, qa, sol)


def median_time(fn: Callable[[], Any], min_time: float = 0.2, max_rounds: int = 200) -> float:
    """Median wall time of ``fn()`` in seconds over rounds filling about ``min_time``."""
    times = []
    t_end = time.perf_counter() + min_time
    while len(times) < 3 or (time.perf_counter() < t_end and len(times) < max_rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def record(benchmark, baseline_s: float | None, baseline: str, **info: Any) -> None:
    """Store status, iterations, the baseline's median time and the ratio."""
    stats = benchmark.stats.stats if benchmark.stats else None
    med = float(stats.median) if stats is not None else float("nan")
    benchmark.extra_info.update({k: (v.item() if isinstance(v, np.generic) else v)
                                 for k, v in info.items()})
    benchmark.extra_info["optkin_median_s"] = med
    benchmark.extra_info["load_average_1min"] = round(os.getloadavg()[0], 2)
    if baseline_s is not None:
        benchmark.extra_info["baseline"] = baseline
        benchmark.extra_info["baseline_median_s"] = baseline_s
        benchmark.extra_info["ratio"] = baseline_s / med if med > 0 else float("nan")


@pytest.fixture(params=list(MECHANISMS))
def ref(request) -> Reference:
    return reference(request.param)


def numpy_residual(mech: optkin.Mechanism) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """The closure residual written in numpy (leg mechanisms: one row per leg, Özgören),
    independent of the CasADi model; Khalil mechanisms: the model's SX Function called from
    Python, which is what a user of scipy would write."""
    if mech.kind != "legs":
        f = optkin.get_model(mech).phi
        return lambda qa, x: np.array(f(qa, x)).ravel()
    from optkin.mechanism.geometry import quat_to_matrix

    legs = mech.legs
    B = np.array([np.resize(np.r_[leg.base, 0, 0][:3], 3) for leg in legs])
    P = np.array([np.r_[leg.platform, 0, 0][:3] for leg in legs])
    plat = mech.platform

    def frame(x):
        if plat == "planar":
            c, s = np.cos(x[2]), np.sin(x[2])
            return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), np.array([x[0], x[1], 0.0])
        if plat == "planar_point":
            return np.eye(3), np.array([x[0], x[1], 0.0])
        if plat == "spatial":
            w, a, b, c = x[3:7]
            R = np.array([[1 - 2 * (b * b + c * c), 2 * (a * b - c * w), 2 * (a * c + b * w)],
                          [2 * (a * b + c * w), 1 - 2 * (a * a + c * c), 2 * (b * c - a * w)],
                          [2 * (a * c - b * w), 2 * (b * c + a * w), 1 - 2 * (a * a + b * b)]])
            return R, np.asarray(x[:3])
        return np.eye(3), np.asarray(x[:3])

    def res(qa, x):
        R, p = frame(x)
        Pw = p + P @ R.T
        out = np.empty(len(legs) + (plat == "spatial"))
        for i, leg in enumerate(legs):
            if leg.type in ("RPR", "UPS", "SPS"):
                out[i] = np.linalg.norm(Pw[i] - B[i]) - qa[i]
            elif leg.type == "RRR":
                l1, l2 = leg.lengths
                C = B[i] + l1 * np.array([np.cos(qa[i]), np.sin(qa[i]), 0.0])
                out[i] = np.linalg.norm(Pw[i] - C) - l2
            else:
                la, lb = leg.lengths
                w = np.cross(leg.axis, leg.arm)
                C = B[i] + la * (np.cos(qa[i]) * np.asarray(leg.arm) + np.sin(qa[i]) * w)
                out[i] = np.linalg.norm(Pw[i] - C) - lb
        if plat == "spatial":
            out[-1] = x[3:7] @ x[3:7] - 1
        return out

    _ = quat_to_matrix
    return res


def fsolve_forward(mech: optkin.Mechanism, res=None):
    """A scipy.optimize.fsolve direct model: x = fsolve(Phi(qa, .), x0)."""
    from scipy.optimize import fsolve

    res = res or numpy_residual(mech)

    def solve(qa, x0):
        x, info, ier, _ = fsolve(lambda x: res(qa, x), x0, full_output=True, xtol=1e-12)
        return x, ier == 1, info["nfev"]

    return solve


def naive_nlpsol_forward(mech: optkin.Mechanism):
    """A casadi.nlpsol (IPOPT) direct model built at every call (the naive way)."""
    import casadi as ca

    model = optkin.get_model(mech)

    def solve(qa, x0):
        qa_s, x_s, p_s, phi_s = model.symbols
        x = ca.SX.sym("x", x_s.numel())
        phi = ca.substitute(phi_s, ca.vertcat(qa_s, p_s),
                            ca.vertcat(ca.DM(qa), ca.DM(np.asarray(model.p, dtype=float))))
        phi = ca.substitute(phi, x_s, x)
        S = ca.nlpsol("naive", "ipopt", {"x": x, "f": ca.sumsqr(x - x0), "g": phi},
                      {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                       "error_on_fail": False, "ipopt.tol": 1e-10})
        sol = S(x0=x0, lbg=0, ubg=0)
        return np.array(sol["x"]).ravel(), S.stats()["success"], S.stats()["iter_count"]

    return solve
