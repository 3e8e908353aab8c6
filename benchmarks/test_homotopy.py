"""assembly_modes(method="homotopy") beside in-run baselines: the multistart and,
for the 3-RPR, the univariate polynomial of the elimination (numpy.roots, the floor).

Start systems are built (or loaded from the cache) before timing; the time of building
one is ``extra_info["start_system_s"]`` (measured in a fresh cache directory).
"""

from __future__ import annotations

import time

import numpy as np
from conftest import median_time, record
from test_assembly_modes import (
    DIET_A,
    DIET_B,
    DIET_L,
    SIX_A,
    SIX_B,
    SIX_S,
    polynomial_floor,
)

import optkin
from optkin.model import get_model
from optkin.solvers import homotopy as H


def _compiled(mech) -> None:
    """Wait for the topology's tracker and system libraries (built in the background on
    first use, the interpreted Functions running meanwhile) and, for larger systems, the
    tracker's SIMD lanes library: the figures are the compiled code's (the system switches
    at its next evaluation)."""
    tr = H._tracker(get_model(mech))
    if tr is not None and tr._pending is not None:
        tr._pending.wait()
        tr._poll()
    if tr is not None and tr.sys._pending is not None:
        tr.sys._pending.wait()
    if tr is not None:  # larger systems: the SIMD lanes' library too (started just now)
        tr._lanes_fn()
        if tr._lanes is not None and not isinstance(tr._lanes, dict):
            tr._lanes.wait()


def _start_time(mech) -> float:
    t0 = time.perf_counter()
    H.start_system(get_model(mech), seed=123)  # not cached: a fresh build
    return time.perf_counter() - t0


def test_homotopy_rpr3_six(benchmark):
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    optkin.assembly_modes(m, SIX_S, method="homotopy")
    _compiled(m)
    res = benchmark(lambda: optkin.assembly_modes(m, SIX_S, method="homotopy"))
    t_poly = median_time(lambda: polynomial_floor(SIX_A, SIX_B, SIX_S), min_time=0.2)
    t_multi = median_time(lambda: optkin.assembly_modes(m, SIX_S, method="multistart"),
                          min_time=0.5)
    record(benchmark, t_poly, "univariate polynomial (numpy.roots), the floor",
           mechanism="rpr3-six", count=len(res), complete=res.complete,
           paths=res.stats.paths, multistart_s=t_multi, start_system_s=_start_time(m))
    assert len(res) == 6 and res.complete


def test_homotopy_stewart_dietmaier(benchmark):
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    optkin.assembly_modes(m, DIET_L, method="homotopy")
    _compiled(m)
    res = benchmark.pedantic(lambda: optkin.assembly_modes(m, DIET_L, method="homotopy"),
                             rounds=5, iterations=1)
    t_multi = median_time(lambda: optkin.assembly_modes(m, DIET_L, method="multistart"),
                          min_time=1.0)
    rng = np.random.default_rng(0)  # a generic instance: legs from a random pose
    perturbed = DIET_L * (1 + 0.02 * rng.uniform(-1, 1, 6))
    t_multi_generic = median_time(
        lambda: optkin.assembly_modes(m, perturbed, method="multistart"), min_time=1.0)
    t_hom_generic = median_time(lambda: optkin.assembly_modes(m, perturbed, method="homotopy"),
                                min_time=1.0)
    record(benchmark, t_multi, "multistart, Dietmaier's legs",
           mechanism="stewart-dietmaier", count=len(res), complete=res.complete,
           paths=res.stats.paths, generic_multistart_s=t_multi_generic,
           generic_homotopy_s=t_hom_generic, start_system_s=_start_time(m))
    assert len(res) == 40 and res.complete


def test_homotopy_rpr3_random_200(benchmark):
    """The issue's batch: 200 random 3-RPR (base in [-10, 10]^2, platform in [-4, 4]^2, legs
    from a random pose). Per instance, the homotopy's time beside numpy.roots on the
    sextic; the benchmark's own figure is the whole batch."""
    rng = np.random.default_rng(2026)
    inst = []
    for _ in range(200):
        a, b = rng.uniform(-10, 10, (3, 2)), rng.uniform(-4, 4, (3, 2))
        phi = rng.uniform(-np.pi, np.pi)
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        p = rng.uniform(-3, 3, 2)
        inst.append((optkin.mechanisms.rpr3(a, b), a, b,
                     np.linalg.norm(p + b @ R.T - a, axis=1)))
    optkin.assembly_modes(inst[0][0], inst[0][3], method="homotopy")  # start system, compile
    _compiled(inst[0][0])
    # in blocks of 20 instances, the homotopy's then the sextic's: within a block each
    # method in its own loop (interleaved call by call, the sextic's numpy calls between
    # two homotopy calls had evicted its code and data: 2.4 ms a first call instead of
    # 1.4), and the blocks alternating so that this machine's drift (20-40 % over a
    # minute) weighs on both alike (two whole loops, one after the other, gave ratios of
    # 1.7-2.3 in consecutive runs)
    hom, poly, complete = [], [], 0
    for k in range(0, len(inst), 20):
        for m, _, _, s in inst[k:k + 20]:  # the first call on each new geometry
            t0 = time.perf_counter()
            res = optkin.assembly_modes(m, s, method="homotopy")
            hom.append(time.perf_counter() - t0)
            complete += res.complete
        for _, a, b, s in inst[k:k + 20]:
            poly.append(median_time(lambda a=a, b=b, s=s: polynomial_floor(a, b, s),
                                    min_time=0.01))
    benchmark.pedantic(lambda: [optkin.assembly_modes(m, s, method="homotopy")
                                for m, _, _, s in inst], rounds=3, iterations=1)
    warm = []  # the same instances again: models built, nothing new
    for m, _, _, s in inst:
        t0 = time.perf_counter()
        optkin.assembly_modes(m, s, method="homotopy")
        warm.append(time.perf_counter() - t0)
    record(benchmark, float(np.sum(poly)), "numpy.roots on the sextic, per instance, summed",
           mechanism="rpr3-random-200", complete=complete,
           homotopy_median_s=float(np.median(hom)), homotopy_max_s=float(np.max(hom)),
           sextic_median_s=float(np.median(poly)),
           median_ratio=float(np.median(hom) / np.median(poly)),
           warm_median_s=float(np.median(warm)),
           first_call_over_warm=float(np.median(hom) / np.median(warm)))
    assert complete == 200


def test_homotopy_stewart_first_call(benchmark):
    """A new geometry of a known topology (no compilation, the start system loaded): the
    first call on each of 10 new 6-6 platforms beside a second call on the same one."""
    rng = np.random.default_rng(4)
    plat = []
    for _ in range(10):
        A = DIET_A + rng.uniform(-0.02, 0.02, DIET_A.shape)
        B = DIET_B + rng.uniform(-0.02, 0.02, DIET_B.shape)
        plat.append((optkin.mechanisms.stewart_gough(A, B), DIET_L))
    optkin.assembly_modes(optkin.mechanisms.stewart_gough(DIET_A + 0.01, DIET_B), DIET_L)
    _compiled(plat[0][0])
    first, warm = [], []
    for m, L in plat:
        t0 = time.perf_counter()
        res = optkin.assembly_modes(m, L)
        first.append(time.perf_counter() - t0)
        assert res.stats.method == "homotopy" and res.complete, res.info["message"]
        t0 = time.perf_counter()
        optkin.assembly_modes(m, L)
        warm.append(time.perf_counter() - t0)
    benchmark.pedantic(lambda: [optkin.assembly_modes(m, L) for m, L in plat], rounds=1,
                       iterations=1)
    record(benchmark, float(np.sum(warm)), "the same calls again (warm), summed",
           mechanism="stewart-new-geometry", first_median_s=float(np.median(first)),
           warm_median_s=float(np.median(warm)),
           first_call_over_warm=float(np.median(first) / np.median(warm)))


def test_homotopy_stewart_random_30(benchmark):
    """30 random generic 6-6 platforms (the tests' generator: joints on circles, nearly
    planar, legs from a random pose), each warm: the homotopy with its default threads
    (``"auto"``: the usable CPUs, at least 8 paths a thread) and with one thread, beside
    the multistart (its default, one thread) on the same instances, and with one thread
    without the SIMD lanes library (CasADi's compiled chunk, built for this comparison:
    ``lanes_speedup_1thread``).
    The benchmark's own figure is the whole batch with the defaults."""
    from scipy.spatial.transform import Rotation

    from optkin.limits import auto_threads

    rng = np.random.default_rng(12)  # as tests/test_homotopy.py's _random_stewart_platforms
    inst = []
    for _ in range(30):
        ab, ap = np.sort(rng.uniform(0, 2 * np.pi, 6)), np.sort(rng.uniform(0, 2 * np.pi, 6))
        A = np.c_[np.cos(ab), np.sin(ab), rng.uniform(-0.1, 0.1, 6)]
        B = 0.5 * np.c_[np.cos(ap), np.sin(ap), rng.uniform(-0.1, 0.1, 6)]
        p = np.r_[rng.uniform(-0.1, 0.1, 2), rng.uniform(0.8, 1.2)]
        R = Rotation.from_rotvec(rng.uniform(-0.15, 0.15, 3)).as_matrix()
        inst.append((optkin.mechanisms.stewart_gough(A, B),
                     np.linalg.norm(p + B @ R.T - A, axis=1)))
    for m, L in inst[:2]:
        optkin.assembly_modes(m, L, method="homotopy")
    _compiled(inst[0][0])
    for m, L in inst:  # models built: the figures below are warm
        optkin.assembly_modes(m, L, method="homotopy")

    def each(**kw):
        ts = []
        for m, L in inst:
            t0 = time.perf_counter()
            r = optkin.assembly_modes(m, L, **kw)
            ts.append(time.perf_counter() - t0)
            assert r.stats.method == kw["method"]
            assert kw["method"] != "homotopy" or r.complete, r.info["message"]
        return np.array(ts)

    auto = each(method="homotopy")
    one = each(method="homotopy", threads=1)
    multi = each(method="multistart")
    tr = H._tracker(get_model(inst[0][0]))  # the same without the SIMD lanes library:
    tr._chunk.start()  # CasADi's compiled chunk (not built where the lanes are)
    if tr._chunk.pending is not None:
        tr._chunk.pending.wait()
        tr._chunk.poll()
    saved = tr._lanes, tr._lanes_todo
    tr._lanes, tr._lanes_todo = None, None
    try:
        chunk_one = each(method="homotopy", threads=1)
    finally:
        tr._lanes, tr._lanes_todo = saved
    benchmark.pedantic(lambda: [optkin.assembly_modes(m, L, method="homotopy")
                                for m, L in inst], rounds=3, iterations=1)
    record(benchmark, float(np.sum(multi)), "multistart, per instance, summed",
           mechanism="stewart-random-30", threads_auto=auto_threads(),
           homotopy_median_s=float(np.median(auto)), homotopy_max_s=float(np.max(auto)),
           homotopy_1thread_median_s=float(np.median(one)),
           multistart_median_s=float(np.median(multi)),
           median_ratio_multistart=float(np.median(multi) / np.median(auto)),
           median_ratio_multistart_1thread=float(np.median(multi) / np.median(one)),
           lanes=saved[0] is not None,
           chunk_1thread_median_s=float(np.median(chunk_one)),
           lanes_speedup_1thread=float(np.median(chunk_one) / np.median(one)))
