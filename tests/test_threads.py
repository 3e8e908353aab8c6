"""``threads``: the columns of a mapped Newton step shared among threads.

A split is right when it changes nothing but the wall time: the same modes as one thread
(assembly_modes, whose one-thread answer the homotopy and elimination tests check), the
same rows as one thread (forward_batch), including shares of unequal size, and the
closure of every row checked here with numpy (|p + R b_i - a_i| = rho_i).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

import optkin
from optkin.solvers import batch
from optkin.solvers import enumerate as enum

M = optkin.mechanisms


def _platform(seed: int):
    rng = np.random.default_rng(seed)
    b = np.c_[rng.uniform(-1, 1, (6, 2)), np.zeros(6)]
    p = np.c_[rng.uniform(-0.5, 0.5, (6, 2)), np.zeros(6)]
    return M.stewart_gough(b, p), b, p, rng


def _legs(b, p, pose: np.ndarray) -> np.ndarray:
    """Leg lengths at a pose (x, y, z, qw, qx, qy, qz), by numpy."""
    Rm = Rotation.from_quat(np.r_[pose[4:7], pose[3]]).as_matrix()
    return np.linalg.norm(pose[:3] + p @ Rm.T - b, axis=1)


def test_assembly_modes_with_two_threads_finds_the_same_modes():
    m, b, p, rng = _platform(3)
    Rm = Rotation.from_euler("ZYX", rng.uniform(-0.3, 0.3, 3)).as_matrix()
    qa = np.linalg.norm(np.array([0.1, -0.1, 0.8]) + p @ Rm.T - b, axis=1)
    one = optkin.assembly_modes(m, qa, method="multistart", seed=1)
    two = optkin.assembly_modes(m, qa, method="multistart", seed=1, threads=2)
    three = optkin.assembly_modes(m, qa, method="multistart", seed=1, threads=3, width=64)
    assert len(one) >= 2
    assert two.info["starts"] == one.info["starts"]  # the same pool, split: the same run
    for s in (two, three):
        assert len(s) == len(one)
        np.testing.assert_allclose(np.array([r.x for r in s]), np.array([r.x for r in one]),
                                   atol=1e-8)
    for r in two:  # every mode closes the legs
        np.testing.assert_allclose(_legs(b, p, r.x), qa, atol=1e-9)


def test_threaded_step_shares_cover_every_column():
    m, *_ = _platform(4)
    model = optkin.get_model(m)
    step, *_ = enum._mapped_step(model, 10, 0.3, 2, False, 3)
    assert isinstance(step, enum._ThreadedStep)
    assert [q.width for q in step.parts] == [4, 3, 3]
    ref, *_ = enum._mapped_step(model, 10, 0.3, 2, False, 1)
    X = model.default_x(np.ones(6))[:, None] + 0.01 * np.arange(10)[None, :]
    qa = np.full(6, 1.0)
    (x1, r1), (x2, r2) = ref(qa, X), step(qa, X)
    np.testing.assert_array_equal(x1, x2)
    np.testing.assert_array_equal(r1, r2)


def test_forward_batch_with_threads_returns_the_same_rows():
    m, b, p, rng = _platform(5)
    QA = []
    for _ in range(37):  # an odd chunk: shares 19 and 18, then 13, 12 and 12
        Rm = Rotation.from_euler("ZYX", rng.uniform(-0.2, 0.2, 3))
        t = np.array([*rng.uniform(-0.1, 0.1, 2), 0.8])
        QA.append(np.linalg.norm(t + p @ Rm.as_matrix().T - b, axis=1))
    QA = np.array(QA)
    guess = optkin.forward(m, QA[0])
    one = optkin.forward_batch(m, QA, guess=guess, path=False, chunk=37)
    for threads in (2, 3):
        many = optkin.forward_batch(m, QA, guess=guess, path=False, chunk=37, threads=threads)
        assert many.success and many.closed.all()
        np.testing.assert_array_equal(many.x, one.x)
    for x, qa in zip(one.x, QA):
        np.testing.assert_allclose(_legs(b, p, x), qa, atol=1e-9)
    assert isinstance(batch._step_map(optkin.get_model(m), 37, 2), batch._ThreadedEval)


def test_homotopy_paths_shared_among_threads_end_where_one_thread_ends():
    """The homotopy's paths in shares (2, 3 and 5 threads: 20, 14/13/13 and 8 paths) end
    at the points one thread gives, every path accounted for, and the real modes close
    the legs (checked with numpy)."""
    from optkin.solvers.homotopy import PATHS_PER_THREAD, _shares

    m, b, p, rng = _platform(5)
    Rm = Rotation.from_euler("ZYX", rng.uniform(-0.3, 0.3, 3)).as_matrix()
    qa = np.linalg.norm(np.array([0.05, 0.1, 0.9]) + p @ Rm.T - b, axis=1)
    runs = {t: optkin.assembly_modes(m, qa, method="homotopy", threads=t)
            for t in (1, 2, 3, 5)}
    one = runs[1]
    assert one.complete and one.stats.paths == 40 and len(one) >= 2
    for t, r in runs.items():
        assert r.complete and r.stats == one.stats, t
        assert len(r) == len(one), t
        for x, y in zip(r, one):
            assert np.max(np.abs(x.x - y.x)) < 1e-12, t
            assert np.max(np.abs(_legs(b, p, x.x) - qa)) < 1e-9
    for n, t in ((40, 2), (40, 3), (40, 5), (40, 8), (15, 2), (7, 4), (1, 1)):
        s = _shares(n, t)
        assert sum(s) == n and max(s) - min(s) <= 1
        assert len(s) == 1 or min(s) >= PATHS_PER_THREAD


def test_auto_threads_is_one_where_omp_says_one(monkeypatch):
    from optkin.limits import auto_threads

    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    assert auto_threads() == 1
    monkeypatch.delenv("OMP_NUM_THREADS")
    import os
    assert auto_threads() == len(os.sched_getaffinity(0))
