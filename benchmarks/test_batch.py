"""forward_batch: 10 000 poses along a path (3-RPR and Stewart-Gough), and independent rows.

Targets: <= 10 us per solve, >= 20x faster than scipy.optimize.fsolve warm-started along
the same path (timed in-run on the first 500 points).
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from conftest import fsolve_forward, record, reference

import optkin
from optkin.mechanism.tasks import task_to_pose

N = 10_000


def _path(name: str, n: int):
    """Poses along a smooth closed-ish path around the reference pose, and their q_a
    (closed-form inverse model, leg by leg)."""
    ref = reference(name)
    mech = ref.mech
    home = np.asarray(mech.home, dtype=float)
    s = np.linspace(0.0, 1.0, n)
    QA = np.empty((n, mech.dof))
    T0 = task_to_pose(mech, home)
    r0 = optkin.inverse(mech, T0)[0]
    post = r0.posture
    for i, si in enumerate(s):
        t = home.copy()
        if name == "rpr3":
            t += [0.04 * np.sin(2 * np.pi * si), 0.03 * si, 0.15 * np.sin(np.pi * si)]
        else:
            t += [0.1 * np.sin(2 * np.pi * si), 0.05 * si, 0.1 * si,
                  0.15 * np.sin(2 * np.pi * si), 0.1 * si, 0.2 * np.cos(2 * np.pi * si) - 0.2]
        sols = optkin.inverse(mech, task_to_pose(mech, t))
        pick = [r for r in sols if r.posture == post]
        QA[i] = pick[0].qa
    return ref, QA


@pytest.fixture(scope="module", params=["rpr3", "stewart_gough"])
def path(request):
    return _path(request.param, N)


def test_forward_batch_path(benchmark, path):
    ref, QA = path
    mech = ref.mech
    optkin.forward_batch(mech, QA[:200], guess=ref.sol)  # compile / load the tracker
    b = benchmark.pedantic(lambda: optkin.forward_batch(mech, QA, guess=ref.sol),
                           rounds=5, warmup_rounds=1)
    per = benchmark.stats.stats.median / N
    fs = fsolve_forward(mech)
    m = 500
    t0 = time.perf_counter()
    x = ref.sol.x.copy()
    nfev = 0
    X = np.empty((m, x.size))
    for i in range(m):
        x, ok, nf = fs(QA[i], x)
        X[i] = x
        nfev += nf
    base = (time.perf_counter() - t0) / m
    record(benchmark, base * N, "scipy.optimize.fsolve along the path (500 points, scaled)",
           mechanism=ref.name, status=b.status, nit=int(b.nit.sum()), n=N,
           per_solve_us=per * 1e6, fsolve_per_solve_us=base * 1e6,
           fallback=b.stats.extra["fallback"], compiled=b.stats.extra["compiled"],
           max_residual=float(b.residual.max()),
           agrees_with_fsolve=bool(np.max(np.abs(X[:, :3] - b.x[:m, :3])) < 1e-7),
           target_us=10, meets_target=bool(per <= 10e-6 and base / per >= 20))
    assert b.all_success


def test_forward_batch_independent(benchmark, path):
    """Rows solved independently from one guess (mapped damped Newton, 2000 rows)."""
    ref, QA = path
    mech = ref.mech
    A = QA[::5][:2000]
    optkin.forward_batch(mech, A[:10], guess=ref.sol, path=False)
    b = benchmark.pedantic(lambda: optkin.forward_batch(mech, A, guess=ref.sol, path=False),
                           rounds=3, warmup_rounds=1)
    per = benchmark.stats.stats.median / len(A)
    t2 = time.perf_counter()
    optkin.forward_batch(mech, A, guess=ref.sol, path=False, threads=2, chunk=1024)
    per2 = (time.perf_counter() - t2) / len(A)
    fs = fsolve_forward(mech)
    t0 = time.perf_counter()
    for i in range(200):
        fs(A[i], ref.sol.x)
    base = (time.perf_counter() - t0) / 200
    record(benchmark, base * len(A), "scipy.optimize.fsolve per row from the same guess",
           mechanism=ref.name, status=b.status, nit=int(b.nit.sum()), n=len(A),
           per_solve_us=per * 1e6, per_solve_threads2_chunk1024_us=per2 * 1e6,
           fsolve_per_solve_us=base * 1e6, fallback=b.stats.extra["fallback"])
    assert b.all_success
