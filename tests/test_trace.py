"""The trace test (optkin.solvers.trace) and the start systems shipped with the package.

Evidence: a start system known complete by a closed form (the 3-RPR's six solutions, the
structure's bound; the four-bar's two circle intersections) passes; the same set with one
solution dropped fails. Every shipped start system loads without a rebuild, and passes the
trace test here, in the test, not only when it was made."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import optkin
from optkin.model import get_model
from optkin.solvers import homotopy as H
from optkin.solvers.shipped import CATALOGUE, TRACE_OPTIONS, UNVERIFIED
from optkin.solvers.trace import trace_test


def _rpr3():
    return optkin.mechanisms.rpr3([[0.3, 0.2], [7.1, -0.5], [2.9, 6.2]],
                                  [[-0.8, -0.4], [1.1, -0.7], [0.3, 1.2]])


def test_trace_passes_on_a_complete_set_and_fails_without_one_solution():
    model = get_model(_rpr3())
    S = H.start_system(model, seed=5)
    assert S.stopped == "bound" and S.root_count == 6  # the sextic's six
    ok = trace_test(model, S, seed=1)
    assert ok.passed and ok.residual < 1e-9, ok.message
    for drop in (0, 3):
        short = dataclasses.replace(S, solutions=np.delete(S.solutions, drop, axis=0))
        bad = trace_test(model, short, seed=1, max_loops=20)
        assert not bad.passed, bad.message
        assert not np.isfinite(bad.residual) or bad.residual > 1e-4


def test_trace_passes_on_the_3rps_whose_solutions_satisfy_affine_relations():
    """The 3-RPS at joint level: its 16 solutions satisfy three affine relations in the
    test's coordinates (the platform's origin is an affine combination of the three leg
    ends, each linear in cos and sin of its angle; checked here: [y, 1] has rank 11). A
    slice fitted through all 13 first solutions contained every one of them, and the test
    failed on this complete set (residual 8e-2); through fewer it passes to round-off."""
    from optkin.solvers.trace import _trace_system

    model = get_model(optkin.mechanisms.rps3())
    S = H.start_system(model, seed=0, stale=10, max_loops=80, verify=False)
    assert S.stopped == "stale" and S.root_count == 16
    Y = _trace_system(model).coords(S.solutions)
    assert np.linalg.matrix_rank(np.c_[Y, np.ones(16)], tol=1e-9 * np.abs(Y).max()) == 11
    ok = trace_test(model, S, seed=1)
    assert ok.passed and ok.residual < 1e-9, ok.message


def test_pose_slice_along_the_leg_lengths_sums_only_what_it_slices():
    """The 3-RPS's 16 solutions (complete: the default test passes on them, above), the
    curve moved along the leg lengths and sliced by the platform's pose. A revolute angle
    of a leg has cos = (leg vector . axis) / leg length, which blows up where the length
    moving along the curve passes 0 while the pose, and so the slice's function, stays
    finite: summed with the rest, the complete set failed (residual 0.087); the traces
    sum the pose and lam only, and pass. One solution dropped still fails."""
    model = get_model(optkin.mechanisms.rps3())
    S = H.shipped_start(model)
    assert S.root_count == 16
    ok = trace_test(model, S, seed=2, direction="qa", slice="pose")
    assert ok.passed and ok.residual < 1e-9, ok.message
    short = dataclasses.replace(S, solutions=S.solutions[1:])
    bad = trace_test(model, short, seed=2, max_loops=20, direction="qa", slice="pose")
    assert not bad.passed and bad.residual > 1e-4, bad.message


def test_trace_options_are_checked():
    model = get_model(_rpr3())
    S = H.start_system(model, seed=5)
    with pytest.raises(ValueError, match="direction must be one of"):
        trace_test(model, S, direction="x")
    with pytest.raises(ValueError, match="slice must be one of"):
        trace_test(model, S, slice="all")
    fb = get_model(optkin.mechanisms.five_bar(1.3, 0.8, 1.1, 0.9, 0.7))
    with pytest.raises(ValueError, match=r"prismatic actuators.*revolute: use direction='c'"):
        trace_test(fb, H.shipped_start(fb), direction="qa")


@pytest.mark.slow
def test_trace_fails_on_the_3rps_without_one_solution():
    """(80 s here.)"""
    model = get_model(optkin.mechanisms.rps3())
    S = H.start_system(model, seed=0, stale=10, max_loops=80, verify=False)
    short = dataclasses.replace(S, solutions=S.solutions[1:])
    bad = trace_test(model, short, seed=1, max_loops=30)
    assert not bad.passed and (not np.isfinite(bad.residual) or bad.residual > 1e-4)


def test_four_bar_start_system_is_complete_by_the_trace_test():
    """A Khalil table has no known bound: monodromy stops when the trace test passes, and
    the count is the closed form's (two circle intersections)."""
    model = get_model(optkin.mechanisms.four_bar(1.0, 0.45, 1.15, 0.85))
    S = H.start_system(model, seed=3)
    assert S.stopped == "trace" and S.root_count == 2 and S.trace <= 1e-6
    bad = trace_test(model, dataclasses.replace(S, solutions=S.solutions[:1]), max_loops=20)
    assert not bad.passed


def test_an_unverified_start_system_is_never_complete():
    m = optkin.mechanisms.four_bar(1.0, 0.45, 1.15, 0.85)
    model = get_model(m)
    S = dataclasses.replace(H.start_system(model, seed=3), stopped="stale")
    modes = H.homotopy_modes(m, [1.5], start=S)
    assert len(modes) == 2 and not modes.complete
    assert "not verified complete" in modes.info["message"]


@pytest.mark.parametrize("name,make", [pytest.param(n, mk, id=n, marks=[pytest.mark.slow]
                                                    if slow else [])
                                       for n, mk, slow in CATALOGUE])
def test_shipped_start_systems_load_and_pass_the_trace_test(name, make, monkeypatch, tmp_path):
    model = get_model(make())
    path = H.shipped_path(model)
    assert path.is_file(), f"{name}: no shipped start system (python -m optkin.solvers.shipped)"
    assert path.stat().st_size < 250_000  # the 3-UPU's 672 solutions: 205 kB
    S = H._read_start(model, path.read_bytes())
    assert S is not None, name
    # shipped unverified, and said so (every call then reports complete=False)
    assert S.verified == (name not in UNVERIFIED), (name, S.stopped)

    # used as shipped: no monodromy in a process with an empty cache
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))

    def refuse(*a, **k):
        raise AssertionError("the shipped start system was not used")

    monkeypatch.setattr(H, "start_system", refuse)
    loaded = H.load_or_build_start(model)
    assert np.array_equal(loaded.theta, S.theta)
    if name in UNVERIFIED:
        return
    T = trace_test(model, S, seed=2, **TRACE_OPTIONS.get(name, {}))
    assert T.passed, f"{name}: {T.message}"


@pytest.mark.parametrize("dense", [None, 0], ids=["default", "windows-only"])
def test_new_witnesses_are_those_a_pairwise_comparison_finds(dense, monkeypatch):
    """The witnesses' identification (trace._new_rows: windows on a random projection, or
    every pair at once for few rows) against the plain comparison of every row with every
    earlier one, written here, on random sets with copies planted 3e-9 (the same point)
    and 2e-6 (another) relative apart, near and far out, and on chains of rows 0.8
    tolerances apart; once as it runs and once with the windows for every size."""
    from optkin.solvers.trace import _new_rows

    if dense is not None:
        monkeypatch.setattr(H, "_DENSE_PAIRS", dense)

    def pairwise(S, Y, sc, tol=1e-6):
        out = []
        for y in Y:
            P = np.vstack([S] + out) if len(S) or out else np.zeros((0, Y.shape[1]))
            size = 1.0 + np.max(np.abs(y) / sc)
            if not len(P) or np.min(np.max(np.abs(P - y) / sc, axis=1)) > tol * size:
                out.append(y[None])
        return np.vstack(out) if out else np.zeros((0, Y.shape[1]), complex)

    rng = np.random.default_rng(0)
    for _ in range(30):
        m = int(rng.integers(2, 21))
        sc = rng.uniform(0.5, 3.0, m)
        base = ((rng.normal(size=(int(rng.integers(1, 60)), m)) + 1j * rng.normal(size=(1, m)))
                * np.exp(rng.uniform(0, 6)))
        S = base[:int(rng.integers(0, len(base)))]
        Y = base[rng.integers(0, len(base), int(rng.integers(1, 80)))]
        Y = Y * (1 + rng.choice([0.0, 3e-9, 2e-6], size=(len(Y), 1)))
        Y = np.vstack([Y, rng.normal(size=(5, m)) + 0j])[rng.permutation(len(Y) + 5)]
        got, ref = _new_rows(S, Y, sc), pairwise(S, Y, sc)
        assert got.shape == ref.shape and np.array_equal(got, ref)
    # chains: rows 0.8 tolerances apart along a line, in random order (a row near one
    # that is itself dropped must be compared with the rows kept)
    for _ in range(100):
        y0 = rng.normal(size=3) + 0j
        d = rng.normal(size=3)
        d /= np.max(np.abs(d))
        step = 0.8e-6 * (1 + np.max(np.abs(y0)))
        Y = np.array([y0 + k * step * d for k in range(6)])[rng.permutation(6)]
        got, ref = _new_rows(np.zeros((0, 3), complex), Y, np.ones(3)), pairwise(
            np.zeros((0, 3), complex), Y, np.ones(3))
        assert got.shape == ref.shape and np.array_equal(got, ref)


def test_paths_that_end_on_one_point_give_no_trace(monkeypatch):
    """A trace from endpoints two of which coincide (path jumping, every path 'finite')
    is not computed: the paths are tracked again, and with every try jumping the test
    does not pass. The 3-RPR's complete set, its tracked endpoints' last row made a copy
    of the first."""
    model = get_model(_rpr3())
    S = H.start_system(model, seed=5)
    real = H.track_orbits
    calls = []

    def jumping(*a, **k):
        P = real(*a, **k)
        X = P.x.copy()
        X[-1] = X[0]
        calls.append(1)
        return H._Paths(X, P.status, P.cond, P.t, P.steps)

    monkeypatch.setattr(H, "track_orbits", jumping)
    T = trace_test(model, S, seed=1, max_loops=6)
    assert not T.passed and not np.isfinite(T.residual), T
    assert len(calls) >= H.TRIES
