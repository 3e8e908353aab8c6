"""Capability over many poses: the parametrised (DPP) cvxpy problem re-solved vs rebuilt.

Three ways over the same poses: ``capability`` with the cached parametrised problem
(re-solved per pose), the same problem rebuilt per pose (``reuse=False``, the baseline),
and ``capability_many`` (64 poses per parametrised LP).

Run as a script (prints the ratio) or under pytest (``-m slow``, pytest-benchmark's
``extra_info`` records the times, the ratio and the statuses)::

    python benchmarks/bench_statics.py --poses 1000
    python -m pytest benchmarks/bench_statics.py -m slow
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pytest

import optkin
from optkin import statics

BASE3 = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
PLAT3 = np.array([[-0.5, -0.3], [0.5, -0.3], [0.0, 0.4]])


def configurations(n: int, seed: int = 0):
    """n closed configurations of the MR 3-RPR (closed-form inverse), fixed seed."""
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    rng = np.random.default_rng(seed)
    P = np.column_stack([rng.uniform(1.3, 2.3, n), rng.uniform(0.9, 1.7, n),
                         rng.uniform(-0.4, 0.4, n)])
    return m, [optkin.inverse(m, p)[0] for p in P]


def run(n: int = 1000, seed: int = 0, directions=None) -> dict:
    """Time capability over n poses with reuse=True (built once) and reuse=False."""
    m, sols = configurations(n, seed)
    out: dict = {"poses": n}
    maxes = {}
    for reuse in (True, False):
        statics.capability(m, sols[0], 1.0, directions, reuse=reuse)  # warm the cache
        t0 = time.perf_counter()
        res = [statics.capability(m, s, 1.0, directions, reuse=reuse) for s in sols]
        dt = time.perf_counter() - t0
        key = "parametrised" if reuse else "rebuilt"
        out[f"{key}_s"] = dt
        out[f"{key}_ms_per_pose"] = 1e3 * dt / n
        out[f"{key}_statuses"] = sorted({r.status for r in res})
        maxes[key] = np.array([r.max for r in res])
    statics.capability_many(m, sols[:64], 1.0, directions)  # build the batched LP
    t0 = time.perf_counter()
    res = statics.capability_many(m, sols, 1.0, directions, chunk=64)
    dt = time.perf_counter() - t0
    out["batched_s"] = dt
    out["batched_ms_per_pose"] = 1e3 * dt / n
    out["batched_statuses"] = sorted({r.status for r in res})
    maxes["batched"] = np.array([r.max for r in res])
    out["ratio_rebuilt_over_parametrised"] = out["rebuilt_s"] / out["parametrised_s"]
    out["ratio_rebuilt_over_batched"] = out["rebuilt_s"] / out["batched_s"]
    out["max_abs_difference_batched"] = float(
        np.max(np.abs(maxes["parametrised"] - maxes["batched"])))
    out["max_abs_difference"] = float(np.max(np.abs(maxes["parametrised"] - maxes["rebuilt"])))
    return out


@pytest.mark.slow
def test_capability_parametrised_vs_rebuilt(benchmark):
    info = benchmark.pedantic(run, kwargs={"n": 1000}, rounds=1, iterations=1)
    benchmark.extra_info.update(info)
    assert info["parametrised_statuses"] == ["optimal"]
    assert info["max_abs_difference"] < 1e-7
    assert info["ratio_rebuilt_over_parametrised"] > 1.0
    assert info["max_abs_difference_batched"] < 1e-7


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args()
    for k, v in run(a.poses, a.seed).items():
        print(f"{k}: {v}")
