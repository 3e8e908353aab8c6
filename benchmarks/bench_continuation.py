"""Singular loci by continuation and generalized aspects of the five-bar of Chablat & Wenger 1998, each
beside an in-run brute-force grid (2000 x 2000 per working mode, numpy, hand-written
inverse kinematics and det A; for the aspects, connected components by scipy.ndimage).

The grid only resolves the curves to its step (about 0.009 length units here); the traced
curves are exact to 1e-9 at every point.

    python benchmarks/bench_continuation.py
    python -m pytest benchmarks/bench_continuation.py -m slow
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
import pytest
from scipy import ndimage

import optkin

L0, L1, L2, L3, L4 = 9.0, 8.0, 5.0, 5.0, 8.0
BB = np.array([L0, 0.0])


def _grid_modes(n: int, label: bool):
    xs = np.linspace(-4.5, 13.5, n)
    ys = np.linspace(-13.0, 13.0, n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    r1 = np.hypot(X, Y)
    r2 = np.hypot(X - L0, Y)
    c1 = (r1**2 + L1**2 - L2**2) / (2 * r1 * L1)
    c2 = (r2**2 + L4**2 - L3**2) / (2 * r2 * L4)
    ok = (np.abs(c1) <= 1) & (np.abs(c2) <= 1)
    a1, b1 = np.arctan2(Y, X), np.arccos(np.clip(c1, -1, 1))
    a2, b2 = np.arctan2(Y, X - L0), np.arccos(np.clip(c2, -1, 1))
    out = []
    for s1 in (1, -1):
        for s2 in (1, -1):
            t1, t2 = a1 + s1 * b1, a2 + s2 * b2
            Cx, Cy = L1 * np.cos(t1), L1 * np.sin(t1)
            Dx, Dy = L0 + L4 * np.cos(t2), L4 * np.sin(t2)
            det = (X - Cx) * (Y - Dy) - (Y - Cy) * (X - Dx)
            sgn = np.where(ok, np.sign(det), 0)
            if label:
                n_comp = 0
                for s in (1, -1):
                    lab, k = ndimage.label(sgn == s)
                    sizes = ndimage.sum_labels(np.ones_like(lab), lab, np.arange(1, k + 1))
                    n_comp += int(np.sum(sizes > 30))
                out.append(n_comp)
            else:
                ch = np.count_nonzero(sgn[1:] * sgn[:-1] < 0) + np.count_nonzero(
                    sgn[:, 1:] * sgn[:, :-1] < 0)
                out.append(ch)
    return out


def run(n_grid: int = 2000, rounds: int = 3) -> dict:
    mech = optkin.mechanisms.five_bar(L0, L1, L2, L3, L4)
    out: dict = {"load_average_1min": round(os.getloadavg()[0], 2)}
    optkin.singular_curves(mech, kind="all")  # build and cache the CasADi functions
    optkin.aspects(mech)
    for key, fn in (
        ("locus_joint", lambda: optkin.singular_curves(mech, plane="joint", kind="all")),
        ("locus_workspace", lambda: optkin.singular_curves(mech, plane="workspace", kind="all")),
        ("parallel_joint", lambda: optkin.singular_curves(mech, plane="joint")),
        ("aspects", lambda: optkin.aspects(mech)),
        ("workspace", lambda: optkin.workspace(mech)),
    ):
        ts = []
        for _ in range(rounds):
            t0 = time.perf_counter()
            res = fn()
            ts.append(time.perf_counter() - t0)
        out[f"{key}_s"] = float(np.median(ts))
        out[f"{key}_status"] = res.status
    out["aspect_counts"] = [len(res) for res in [optkin.aspects(mech)]][0]
    t0 = time.perf_counter()
    ch = _grid_modes(n_grid, label=False)
    out["grid_locus_s"] = time.perf_counter() - t0
    out["grid_sign_changes"] = ch
    t0 = time.perf_counter()
    comps = _grid_modes(n_grid, label=True)
    out["grid_aspects_s"] = time.perf_counter() - t0
    out["grid_aspect_counts"] = comps
    out["ratio_locus"] = out["grid_locus_s"] / out["locus_workspace_s"]
    out["ratio_aspects"] = out["grid_aspects_s"] / out["aspects_s"]
    return out


@pytest.mark.slow
def test_five_bar_locus_and_aspects(benchmark):
    info = benchmark.pedantic(run, kwargs={"n_grid": 2000, "rounds": 3}, rounds=1, iterations=1)
    benchmark.extra_info.update(info)
    assert info["aspects_status"] == "optimal"  # (optkin.results.OPTIMAL)
    assert info["aspect_counts"] == 10  # Chablat and Wenger: 2 + 3 + 3 + 2
    assert info["grid_aspect_counts"] == [2, 3, 3, 2]


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("--grid", type=int, default=2000)
    ap.add_argument("--rounds", type=int, default=3)
    a = ap.parse_args()
    for k, v in run(a.grid, a.rounds).items():
        print(f"{k}: {v}")
