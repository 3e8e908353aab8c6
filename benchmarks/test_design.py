"""Design optimization and atlases (optkin.design) beside the same computation without the
compiled, parametrised evaluation: each design built as a mechanism and evaluated node by
node through the public API (optkin.inverse, optkin.jacobians), timed on a few designs and
scaled to the whole grid or to the optimization's design count (``baseline_median_s`` is
that extrapolation)."""

from __future__ import annotations

import time

import numpy as np
from conftest import record

import optkin
from optkin import design

DISC = design.Disc((0.5, 1.3), 0.3)
MODE = (1, -1)
VARS = {"a": (0.5, 1.8), "b": (0.5, 1.8)}


def five(a, b):
    return optkin.mechanisms.five_bar(1.0, a, b, b, a)


def per_design_gci(a: float, b: float) -> float:
    """The GCI of one design without the design evaluator: a new mechanism, and at every
    Gauss node the inverse (the working mode's posture) and the Jacobians A, B."""
    m = five(a, b)
    P, W = DISC.nodes(12)
    vals = np.zeros(len(P))
    for i, p in enumerate(P):
        for s in optkin.inverse(m, p):
            if tuple(s.working_mode) == MODE:
                j = optkin.jacobians(m, s)
                sv = np.linalg.svd(np.linalg.solve(j.A, j.B), compute_uv=False)
                vals[i] = sv[-1] / sv[0]
    return float(vals @ W / W.sum())


def _per_design_seconds(n: int = 3) -> float:
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for a, b in rng.uniform(0.6, 1.7, (n, 2)):
        per_design_gci(a, b)
    return (time.perf_counter() - t0) / n


def test_atlas_100x100_five_bar_gci(benchmark):
    meas = {"GCI": design.GCI(DISC, MODE)}
    design.atlas(five, VARS, meas, n=4)          # compiled code ready (once per machine)
    res = benchmark.pedantic(lambda: design.atlas(five, VARS, meas, n=100), rounds=1,
                             iterations=1)
    per = _per_design_seconds()
    a, b = res.dims["a"][7, 3], res.dims["b"][7, 3]
    assert abs(per_design_gci(a, b) - res.values["GCI"][7, 3]) < 1e-9
    record(benchmark, per * 100 * 100, "per design: mechanism + inverse + jacobians at 576 "
           "nodes (3 designs timed, x 10 000)", designs=10000, nodes=576,
           per_design_baseline_s=per)


def test_optimize_five_bar_gci(benchmark):
    objective = design.Maximize(design.GCI(DISC, MODE))
    cons = [design.Dimension({"a": 1, "b": 1}) <= 2.6, design.MinConditioning(DISC, MODE) >= 0.3]
    design.optimize(five, VARS, objective, cons, maxiter=2)   # compiled code ready
    res = benchmark.pedantic(lambda: design.optimize(five, VARS, objective, cons, maxiter=30),
                             rounds=1, iterations=1)
    per = _per_design_seconds()
    record(benchmark, per * res.evaluations, "per design: mechanism + inverse + jacobians "
           "at 576 nodes (3 designs timed, x the designs the optimization evaluated)",
           evaluations=res.evaluations, value=res.value, status=res.status,
           per_design_baseline_s=per)
    assert res.success


def test_optimize_le_kang_doan_square(benchmark):
    def lkd(rho):
        return optkin.mechanisms.five_bar(np.sqrt(2) * (rho - 1), 1.0, rho, rho, 1.0)

    meas = design.LargestInscribed(MODE, shape="square", gamma=0.5,
                                   line=lambda d: ((np.sqrt(2) / 2 * (d["rho"] - 1), 0),
                                                   (0, 1), (0, 1 + d["rho"])))
    res = benchmark.pedantic(lambda: design.optimize(lkd, {"rho": (1.2, 3.0)},
                                                     design.Maximize(meas), maxiter=4,
                                                     popsize=5), rounds=1, iterations=1)
    record(benchmark, None, "", evaluations=res.evaluations, side=2 * res.value,
           rho=res.dimensions["rho"], status=res.status)
    assert res.success
