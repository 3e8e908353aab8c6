"""forward: cold (from the default guess) and warm (from the previous solution)."""

from __future__ import annotations

import numpy as np
from conftest import fsolve_forward, median_time, naive_nlpsol_forward, record

import optkin


def test_forward_cold(benchmark, ref):
    """From the mechanism's default start (home); baseline: nlpsol built per call."""
    mech, qa = ref.mech, ref.qa
    model = optkin.get_model(mech)
    model.compile()
    r = benchmark(lambda: optkin.forward(mech, qa))
    x0 = model.default_x(qa)
    naive = naive_nlpsol_forward(mech)
    base = median_time(lambda: naive(qa, x0), min_time=0.2, max_rounds=10)
    fs = fsolve_forward(mech)
    t_fs = median_time(lambda: fs(qa, x0), min_time=0.1, max_rounds=50)
    record(benchmark, base, "nlpsol built + solved per call", mechanism=ref.name,
           status=r.status, nit=r.nit, solver=r.stats.solver, fsolve_s=t_fs,
           compiled=model.compiled)


def test_forward_warm(benchmark, ref):
    """Warm-started tracking step (q_a moved by 1e-4); baseline: scipy.optimize.fsolve on a
    numpy residual from the same guess. Target: <= 200 us per call."""
    mech = ref.mech
    model = optkin.get_model(mech)
    model.compile()
    qa = ref.qa + 1e-4
    r = benchmark(lambda: optkin.forward(mech, qa, guess=ref.sol))
    fs = fsolve_forward(mech)
    x, ok, nfev = fs(qa, ref.sol.x)
    base = median_time(lambda: fs(qa, ref.sol.x))
    med = benchmark.stats.stats.median
    record(benchmark, base, "scipy.optimize.fsolve (numpy residual)", mechanism=ref.name,
           status=r.status, nit=r.nit, solver=r.stats.solver, fsolve_ok=bool(ok),
           fsolve_nfev=int(nfev), fsolve_agrees=bool(np.max(np.abs(x - r.x)) < 1e-7),
           compiled=model.compiled, target_us=200, meets_target=bool(med <= 200e-6))
    assert r.success
