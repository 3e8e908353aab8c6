"""assembly_modes: all modes of a 3-RPR with 6 real modes and of Dietmaier's 6-6 platform
(40 real modes), beside in-run baselines.

Baselines: the univariate polynomial of the 3-RPR elimination solved with numpy (the floor
the issue names, ~0.5 ms), and naive random multi-start IPOPT (one ``casadi.nlpsol`` built
once, solved from uniformly random starts until every mode has been seen). The compiled
Newton step is built (or loaded from the disk cache) before timing; its build time is in
``extra_info["setup_s"]``.
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np
from conftest import median_time, record

import optkin


def _reference_module():
    """tests/test_assembly_modes.py (its references and the published cases), loaded under
    another name (this file has the same module name)."""
    path = Path(__file__).resolve().parents[1] / "tests" / "test_assembly_modes.py"
    spec = importlib.util.spec_from_file_location("assembly_modes_reference", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


_ref = _reference_module()
DIET_A, DIET_B, DIET_L = _ref.DIET_A, _ref.DIET_B, _ref.DIET_L
SIX_A, SIX_B, SIX_S = _ref.SIX_A, _ref.SIX_B, _ref.SIX_S
rpr_polynomial = _ref.rpr_polynomial


def polynomial_floor(a, b, s):
    """The elimination's univariate polynomial in tan(phi/2) solved with numpy.roots, each
    real root turned into (x, y, phi) by the 2x2 linear solve (no polishing)."""
    G = rpr_polynomial(a, b, s)
    t = np.roots(G[::-1])
    out = []
    for phi in 2 * np.arctan(t[np.abs(t.imag) < 1e-6].real):
        c, sn = np.cos(phi), np.sin(phi)
        d = (np.array([[c, -sn], [sn, c]]) @ b.T).T - a
        e = np.sum(d * d, 1) - s**2
        p = np.linalg.solve(2 * (d[1:] - d[:1]), -(e[1:] - e[:1]))
        out.append((p[0], p[1], phi))
    return out


def naive_multistart(mech, qa, want: int, max_starts: int, seed: int = 0):
    """Random starts (positions in a box, uniform rotations) solved one by one with IPOPT
    (min |x - x0|^2 s.t. Phi = 0), until ``want`` distinct solutions are seen.
    Returns (seconds, starts used, distinct solutions)."""
    model = optkin.get_model(mech)
    x = ca.SX.sym("x", model.nx)
    x0 = ca.SX.sym("x0", model.nx)
    qa_s, x_s, p_s, phi_s = model.symbols  # the geometry p is an input of the closure
    phi = ca.substitute(phi_s, ca.vertcat(qa_s, p_s), ca.vertcat(ca.DM(qa), ca.DM(model.p)))
    phi = ca.substitute(phi, x_s, x)
    S = ca.nlpsol("naive", "ipopt", {"x": x, "p": x0, "f": ca.sumsqr(x - x0), "g": phi},
                  {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes",
                   "error_on_fail": False, "ipopt.tol": 1e-10})
    rng = np.random.default_rng(seed)
    L = model.length
    sols: list[np.ndarray] = []
    t0 = time.perf_counter()
    n = 0
    while n < max_starts and len(sols) < want:
        n += 1
        if model.platform.norm_row:  # a quaternion in x: uniform rotations
            q = rng.normal(size=4)
            q /= np.linalg.norm(q)
            xs = np.r_[rng.uniform(-2 * L, 2 * L, 3), q]
        else:
            xs = np.r_[rng.uniform(-2 * L, 2 * L, 2), rng.uniform(-np.pi, np.pi)]
        r = S(x0=xs, p=xs, lbg=0, ubg=0)
        if not S.stats()["success"]:
            continue
        xr = model.canonical_x(np.array(r["x"]).ravel())
        if np.max(np.abs(model.residual(qa, xr))) > 1e-8:
            continue
        if not any(np.max(np.abs(xr - s)) < 1e-6 for s in sols):
            sols.append(xr)
    return time.perf_counter() - t0, n, len(sols)


def test_assembly_modes_rpr3_six(benchmark):
    """3-RPR with 6 real modes; target <= 2 ms; floor: the numpy polynomial (~0.5 ms)."""
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    t0 = time.perf_counter()
    optkin.assembly_modes(m, SIX_S, jit=True)  # compile (or load) the step
    setup = time.perf_counter() - t0
    seeds = iter(range(10**6))
    res = benchmark(lambda: optkin.assembly_modes(m, SIX_S, seed=next(seeds)))
    assert len(polynomial_floor(SIX_A, SIX_B, SIX_S)) == 6
    t_poly = median_time(lambda: polynomial_floor(SIX_A, SIX_B, SIX_S), min_time=0.2)
    complete = sum(len(optkin.assembly_modes(m, SIX_S, seed=s)) == 6 for s in range(20))
    t_naive, n_naive, k_naive = naive_multistart(m, SIX_S, 6, 2000)
    record(benchmark, t_poly, "univariate polynomial (numpy.roots), the floor",
           mechanism="rpr3-six", count=len(res), complete_in_20_seeds=complete,
           method=res.info.get("method"), starts=res.info.get("starts"),
           stop_reason=res.info.get("stop_reason"), paths=res.info.get("root_count"),
           compiled=res.info.get("jit"), setup_s=setup, naive_ipopt_s=t_naive,
           naive_ipopt_starts=n_naive, naive_ipopt_found=k_naive, target_s=2e-3,
           meets_target=bool(benchmark.stats.stats.median <= 2e-3))
    assert len(res) == 6


def test_assembly_modes_stewart_dietmaier(benchmark):
    """Dietmaier's 6-6 platform, 40 real modes; target <= 50 ms and >= 50x the naive
    random multi-start IPOPT."""
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    t0 = time.perf_counter()
    optkin.assembly_modes(m, DIET_L)
    setup = time.perf_counter() - t0
    seeds = iter(range(10**6))
    res = benchmark.pedantic(lambda: optkin.assembly_modes(m, DIET_L, seed=next(seeds)),
                             rounds=20, iterations=1)
    complete = sum(len(optkin.assembly_modes(m, DIET_L, seed=s)) == 40 for s in range(20))
    t_naive, n_naive, k_naive = naive_multistart(m, DIET_L, 40, 4000)
    record(benchmark, t_naive, "naive random multi-start IPOPT until all 40 are seen",
           mechanism="stewart-dietmaier", count=len(res), complete_in_20_seeds=complete,
           method=res.info.get("method"), starts=res.info.get("starts"),
           stop_reason=res.info.get("stop_reason"), paths=res.info.get("root_count"),
           compiled=res.info.get("jit"), setup_s=setup, naive_ipopt_starts=n_naive,
           naive_ipopt_found=k_naive, target_s=50e-3,
           meets_target=bool(benchmark.stats.stats.median <= 50e-3))
    assert len(res) == 40
