"""statics: capability and distribution per pose, the parametrised (DPP) cvxpy problem
re-solved vs the same problem rebuilt per call (in-run baseline, ``extra_info["ratio"]``).

The 1000-pose sweep of the issue is benchmarks/bench_statics.py (``-m slow``).
"""

from __future__ import annotations

import numpy as np
from conftest import median_time, record

import optkin
from optkin import statics

BASE4 = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]]
PLAT4 = [[-0.5, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.5, 0.3]]


def _rpr3():
    m = optkin.mechanisms.rpr3([[0, 0], [4, 0], [0, 3]], [[-0.5, -0.3], [0.5, -0.3], [0, 0.4]])
    return m, optkin.inverse(m, [1.6, 1.2, 0.3])[0]


def test_capability_72_directions(benchmark):
    """Capability polygon (72 directions, one LP) at one pose; baseline: rebuilt problem."""
    m, s = _rpr3()
    th = np.linspace(0, 2 * np.pi, 72, endpoint=False)
    D = np.column_stack([np.cos(th), np.sin(th), np.zeros(72)])
    r = benchmark(lambda: statics.capability(m, s, 1.0, D))
    base = median_time(lambda: statics.capability(m, s, 1.0, D, reuse=False), max_rounds=20)
    record(benchmark, base, "cvxpy problem rebuilt per call", mechanism="rpr3",
           status=r.status, nit=r.stats.nit, solver=r.stats.solver, directions=72)
    assert r.status == "optimal"


def test_distribute_rpr4(benchmark):
    """Minimum 2-norm forces of the redundant 4-RPR (Clarabel QP); baseline: rebuilt."""
    m = optkin.mechanisms.rpr4(BASE4, PLAT4)
    s = optkin.inverse(m, [2.1, 1.4, -0.25])[0]
    F = [0.0, -50.0, 5.0]
    r = benchmark(lambda: statics.distribute(m, s, F, limits=100.0))
    base = median_time(lambda: statics.distribute(m, s, F, limits=100.0, reuse=False),
                       max_rounds=20)
    record(benchmark, base, "cvxpy problem rebuilt per call", mechanism="rpr4",
           status=r.status, nit=r.stats.nit, solver=r.stats.solver)
    assert r.success
