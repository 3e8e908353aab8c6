"""Parameter homotopy from monodromy start systems (optkin.solvers.homotopy).

Evidence: the 3-RPR's real modes against the elimination written in
tests/test_assembly_modes.py (a sextic in tan(phi/2)), and its generic root count 6 (the
degree of that polynomial); Dietmaier's 6-6 platform (40 real postures, the published
number; 40 = the generic root count of a 6-6 platform, Raghavan 1993); the five-bar against
circle intersections; every path accounted for.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from test_assembly_modes import (
    DIET_A,
    DIET_B,
    DIET_L,
    _matches,
    circle_intersections,
    five_bar_reference,
    rpr_reference,
)

import optkin
from optkin.model import get_model
from optkin.solvers import homotopy as H


def _rot2(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def test_3rpr_random_instances_match_the_elimination():
    """The issue's 200 random instances (base in [-10, 10]^2, platform in [-4, 4]^2, legs
    from a random pose), skipping the rare ones whose sextic has a near-double root."""
    rng = np.random.default_rng(21)
    done = 0
    for trial in range(205):
        a, b = rng.uniform(-10, 10, (3, 2)), rng.uniform(-4, 4, (3, 2))
        x = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        s = np.linalg.norm(x[:2] + (_rot2(x[2]) @ b.T).T - a, axis=1)
        ref, ambiguous = rpr_reference(a, b, s)
        if ambiguous:
            continue
        modes = optkin.assembly_modes(optkin.mechanisms.rpr3(a, b), s, method="homotopy")
        assert modes.stats.method == "homotopy" and modes.stats.root_count == 6
        assert modes.complete and modes.stats.failed == 0, modes.info["message"]
        assert modes.stats.paths == modes.stats.finite + modes.stats.at_infinity
        assert _matches([r.x for r in modes], ref), (trial, len(modes), len(ref))
        done += 1
    assert done >= 195


def test_special_3rpr_geometries_start_from_the_wider_family():
    """A 3-RPR with the first base and platform points at the origin and the second on
    the x axis (the textbook frames: zeros no shipped start system has) starts from the
    shipped generic 3-RPR's start system, and its modes are the sextic's real roots."""
    rng = np.random.default_rng(8)
    done = 0
    for trial in range(40):
        a = np.array([[0, 0], [rng.uniform(5, 10), 0], rng.uniform(-10, 10, 2)])
        b = np.array([[0, 0], [rng.uniform(1, 4), 0], rng.uniform(-4, 4, 2)])
        x = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        s = np.linalg.norm(x[:2] + (_rot2(x[2]) @ b.T).T - a, axis=1)
        ref, ambiguous = rpr_reference(a, b, s)
        if ambiguous:
            continue
        m = optkin.mechanisms.rpr3(a, b)
        assert H.structural(get_model(m))  # special: its own pattern
        modes = optkin.assembly_modes(m, s)
        assert modes.stats.method == "homotopy" and modes.info["start_pattern"] == "wider"
        assert modes.complete and _matches([r.x for r in modes], ref), (trial, len(ref))
        done += 1
    assert done >= 36


def test_failing_wider_start_builds_the_patterns_own(monkeypatch, tmp_path):
    """When the paths from the wider family's start system fail, the pattern's own start
    system is built by monodromy and the paths tracked from it."""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    a, b = np.array([[0, 0], [8, 0], [3, 7.0]]), np.array([[0, 0], [2, 0], [1, 1.5]])
    m = optkin.mechanisms.rpr3(a, b)
    model = get_model(m)
    real = H.covering_start(model)
    broken = H.StartSystem(real.theta, real.solutions + 0.3, real.loops, real.time,
                           real.stopped, real.trace)  # not solutions: every path fails
    monkeypatch.setattr(H, "covering_start", lambda model: broken)
    s = np.linalg.norm(np.array([3.0, 2.0]) + (_rot2(0.4) @ b.T).T - a, axis=1)
    modes = optkin.assembly_modes(m, s, method="homotopy", seed=3)
    ref, _ = rpr_reference(a, b, s)
    assert modes.info["start_pattern"] == "own" and modes.complete
    assert _matches([r.x for r in modes], ref)


def test_3rrr_random_instances_match_the_elimination():
    """A 3-RRR at fixed actuated angles is a 3-RPR whose base points are the elbows
    C_i = A_i + l_i (cos q_i, sin q_i) and whose legs are the distal lengths: its modes
    are that sextic's real roots. (Randomising the unit entries of the legs' joint axes
    had left the rigid family: monodromy found 2-3 of the 6 start solutions.)"""
    rng = np.random.default_rng(5)
    done = 0
    for trial in range(40):
        a, b = rng.uniform(-10, 10, (3, 2)), rng.uniform(-3, 3, (3, 2))
        x = np.array([*rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)])
        P = x[:2] + (_rot2(x[2]) @ b.T).T
        d = np.linalg.norm(P - a, axis=1)
        prox = d * rng.uniform(0.4, 0.6, 3)  # proximal and distal links that reach P
        dist = d * rng.uniform(0.6, 0.9, 3)
        m = optkin.mechanisms.rrr3(a, b, prox, dist)
        inv = optkin.inverse(m, x)
        if not len(inv):
            continue
        q = inv[0].qa
        C = a + prox[:, None] * np.c_[np.cos(q), np.sin(q)]
        ref, ambiguous = rpr_reference(C, b, dist)
        if ambiguous:
            continue
        modes = optkin.assembly_modes(m, q, method="homotopy")
        assert modes.stats.root_count == 6 and modes.complete, modes.info["message"]
        assert _matches([r.x for r in modes], ref), (trial, len(modes), len(ref))
        done += 1
    assert done >= 30


def test_compiled_tracker_follows_the_python_loop():
    """The compiled tracker (CHUNK steps per call, mapped over the paths) and the Python
    loop of track() are two writings of one method: same steps, same endpoints."""
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    model = get_model(m)
    sys = H._system(model)
    tr = H._tracker(model)
    if tr is None:
        pytest.skip("no C compiler: only the Python loop exists here")
    S = H.load_or_build_start(model, seed=0)
    target = np.concatenate([[0.6, 0.7, 0.65], np.asarray(model.p)[sys.p_used],
                             np.zeros(sys.n)]).astype(complex)
    g = np.exp(0.7j)
    slow = H.track(sys, S.solutions, S.theta, target, g, h0=tr.h0, hmax=tr.hmax)
    fast = H.track(sys, S.solutions, S.theta, target, g, tracker=tr)
    assert list(slow.status) == list(fast.status) and slow.steps == fast.steps
    np.testing.assert_allclose(fast.x, slow.x, atol=1e-12)


def test_hermite_tracker_ends_where_the_rk4_loop_does():
    """Above 4 unknowns the compiled tracker predicts by Hermite extrapolation; the numpy
    loop of track() by RK4: along one gamma path both must end at the same 40 points."""
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    model = get_model(m)
    sys = H._system(model)
    tr = H._tracker(model)
    if tr is None:
        pytest.skip("no C compiler: only the Python loop exists here")
    assert tr.predictor == "hermite"
    S = H.covering_start(model)  # the generic platform's (shipped): no monodromy here
    target = np.concatenate([DIET_L, np.asarray(model.p)[sys.p_used],
                             np.zeros(sys.n)]).astype(complex)
    g = np.exp(0.7j)
    fast = H.track(sys, S.solutions, S.theta, target, g, tracker=tr)
    slow = H.track(sys, S.solutions, S.theta, target, g)
    assert list(fast.status) == list(slow.status) == ["finite"] * 40
    a, b = H._canonical(model, fast.x), H._canonical(model, slow.x)
    assert np.max(np.abs(a - b)) < 1e-8  # path by path: no path jumped in either


def test_step_controller_ends_where_the_fixed_factor_does():
    """The Hermite tracker's step aimed at a first Newton update of STEP_TARGET and the
    fixed-factor rule (target=None): on three random 6-6 platforms, along one gamma path,
    both end every one of the 40 paths at the same point (no path jumped in either)."""
    for m, L in _random_stewart_platforms(3, seed=12):
        model = get_model(m)
        sys = H._system(model)
        tr = H._tracker(model)
        if tr is None:
            pytest.skip("no C compiler: only the Python loop exists here")
        fixed = H._Tracker(sys, target=None)
        if fixed._pending is not None:
            fixed._pending.wait()
            fixed._poll()
        S = H.covering_start(model)
        target = np.concatenate([L, np.asarray(model.p)[sys.p_used],
                                 np.zeros(sys.n)]).astype(complex)
        g = np.exp(0.05j)
        a = H.track(sys, S.solutions, S.theta, target, g, tracker=tr)
        b = H.track(sys, S.solutions, S.theta, target, g, tracker=fixed)
        assert list(a.status) == list(b.status) == ["finite"] * 40
        d = np.abs(H._canonical(model, a.x) - H._canonical(model, b.x))
        assert np.max(d) < 1e-8


def test_time_limit_is_validated():
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    for bad in (float("nan"), -1.0, 0.0):
        with pytest.raises(optkin.MechanismError, match="time_limit"):
            H.homotopy_modes(m, [0.6, 0.7, 0.65], time_limit=bad)


def test_dietmaier_all_40_by_homotopy():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    modes = optkin.assembly_modes(m, DIET_L, method="homotopy", certify=True)
    assert len(modes) == 40 and modes.stats.root_count == 40
    assert modes.complete and modes.stats.failed == 0 and modes.stats.finite == 40
    assert modes.info["certified"] == 40
    ref = optkin.assembly_modes(m, DIET_L)
    for r in modes:  # the same poses as the multistart's
        assert min(np.max(np.abs(r.pose - q.pose)) for q in ref) < 1e-8


def test_five_bar_against_circle_intersections():
    rng = np.random.default_rng(3)
    seen = 0
    for _ in range(8):
        L = rng.uniform(0.5, 2.0, 5)
        th = rng.uniform(-np.pi, np.pi, 2)
        ref, _, _ = five_bar_reference(L, *th)
        if ref is None:
            continue
        modes = optkin.assembly_modes(optkin.mechanisms.five_bar(*L), th, method="homotopy")
        assert modes.complete, modes.info["message"]
        got = [r.x for r in modes]
        assert len(got) == len(ref)
        for p in ref:
            assert min(np.max(np.abs(g - p)) for g in got) < 1e-8
        seen += 1
    assert seen >= 5


def test_start_system_solutions_solve_their_system():
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    model = get_model(m)
    S = H.start_system(model, seed=4)
    assert S.root_count == 6
    sys = H._system(model)
    n = S.solutions.shape[0]
    Hv, J, _ = sys.eval(S.solutions, np.repeat(S.theta[None], n, 0),
                        np.zeros((n, sys.nth), complex))
    assert np.max(np.abs(Hv)) < 1e-8
    assert np.min(np.abs(np.linalg.det(J))) > 1e-8  # nonsingular: isolated


def test_method_is_validated():
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    with pytest.raises(optkin.MechanismError, match="method must be"):
        optkin.assembly_modes(m, [0.6, 0.7, 0.65], method="bertini")


def test_start_systems_are_stored_and_verified(tmp_path, monkeypatch):
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    model = get_model(m)
    S = H.load_or_build_start(model, seed=9)
    path = H._start_path(model, 9)
    assert path.exists() and S.root_count == 6
    again = H.load_or_build_start(model, seed=9)  # loaded: the same numbers
    np.testing.assert_array_equal(again.solutions, S.solutions)
    np.testing.assert_array_equal(again.theta, S.theta)
    # a stored "start system" whose solutions do not solve it is not trusted
    np.savez(path, theta=S.theta, solutions=S.solutions + 0.1, loops=1, time=0.0)
    rebuilt = H.load_or_build_start(model, seed=9)
    assert rebuilt.root_count == 6 and H._verified(model, rebuilt.theta, rebuilt.solutions)
    assert not H._verified(model, S.theta, S.solutions + 0.1)
    path.write_bytes(b"not an npz file")
    assert H.load_or_build_start(model, seed=9).root_count == 6



def _random_stewart_platforms(count: int, seed: int):
    """``count`` random 6-6 platforms, nearly planar joints, legs from a random pose."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    for _ in range(count):
        ab, ap = np.sort(rng.uniform(0, 2 * np.pi, 6)), np.sort(rng.uniform(0, 2 * np.pi, 6))
        A = np.c_[np.cos(ab), np.sin(ab), rng.uniform(-0.1, 0.1, 6)]
        B = 0.5 * np.c_[np.cos(ap), np.sin(ap), rng.uniform(-0.1, 0.1, 6)]
        p = np.r_[rng.uniform(-0.1, 0.1, 2), rng.uniform(0.8, 1.2)]
        R = Rotation.from_rotvec(rng.uniform(-0.15, 0.15, 3)).as_matrix()
        yield optkin.mechanisms.stewart_gough(A, B), np.linalg.norm(p + B @ R.T - A, axis=1)


def _check_against_multistart(platforms):
    for m, L in platforms:
        hom = optkin.assembly_modes(m, L, method="homotopy")
        ref = optkin.assembly_modes(m, L)
        assert hom.complete and hom.stats.root_count == 40, hom.info["message"]
        assert hom.stats.failed == 0 and hom.stats.finite + hom.stats.at_infinity == 40
        assert len(hom) == len(ref)
        for r in hom:
            assert min(np.max(np.abs(r.pose - q.pose)) for q in ref) < 1e-8


def test_random_stewart_platforms_match_the_multistart():
    """12 random 6-6 platforms: every path accounted for, the real modes equal to the
    multistart's."""
    _check_against_multistart(_random_stewart_platforms(12, 11))


@pytest.mark.slow
def test_hundred_random_stewart_platforms_match_the_multistart():
    """The issue's 100 generic instances (measured here: 100 of 100)."""
    _check_against_multistart(_random_stewart_platforms(100, 12))


def test_khalil_four_bar_against_circle_intersections():
    """A Khalil table: its zero offsets and twists stay fixed in the start system (a
    planar loop stays planar), which then has the 2 solutions of the four-bar."""
    rng = np.random.default_rng(8)
    both = 0
    for _ in range(40):
        L1, L2, L3, L4 = rng.uniform(0.5, 2.5, 4)
        th = rng.uniform(-np.pi, np.pi)
        B, D = L1 * np.array([np.cos(th), np.sin(th)]), np.array([L4, 0.0])
        ref = circle_intersections(B, L2, D, L3) or []
        m = optkin.mechanisms.four_bar(L1, L2, L3, L4)
        modes = optkin.assembly_modes(m, [th], method="homotopy")
        assert modes.complete and modes.stats.root_count == 2, modes.info["message"]
        assert len(modes) == len(ref)
        iphi = m.joint_names.index("phi")
        for C in ref:
            want = np.arctan2(C[1] - D[1], C[0] - D[0])
            assert min(abs(np.angle(np.exp(1j * (r.q[iphi] - want)))) for r in modes) < 1e-8
        both += len(ref) == 2
    assert both >= 10


def test_khalil_five_bar_against_circle_intersections():
    """The five-bar written as a Khalil table (one loop cut at P; passive t2, t4, t3; the
    rows of test_continuation): its start system is built here by monodromy and verified
    by the trace test (no structural bound for a table), then every call accounts for its
    2 paths; the point P = C + L2 u(t1 + t2) of each real mode is one of the intersections
    of the circles (C, L2) and (D, L3), C = L1 u(t1), D = (L0, 0) + L4 u(t5), computed
    here, and the modes are the multistart's."""
    from test_assembly_modes import circle_intersections

    def table(L0, L1, L2, L3, L4):
        rows = [dict(a=0, mu=1, sigma=0, d=0, theta="t1"),
                dict(a=1, mu=0, sigma=0, d=L1, theta="t2"),
                dict(a=0, mu=1, sigma=0, d=L0, theta="t5"),
                dict(a=3, mu=0, sigma=0, d=L4, theta="t4"),
                dict(a=2, mu=0, sigma=0, d=L2, theta="t3"),
                dict(a=4, mu=0, sigma=2, d=L3, theta=0)]
        return optkin.Mechanism.from_khalil(rows, loops=1, name="five-bar (Khalil)")

    def u(a):
        return np.array([np.cos(a), np.sin(a)])

    rng = np.random.default_rng(4)
    both = 0
    for _ in range(12):
        L = rng.uniform(0.5, 2.0, 5)
        th = rng.uniform(-np.pi, np.pi, 2)
        m = table(*L)
        modes = optkin.assembly_modes(m, th, method="homotopy", time_limit=300)
        assert modes.complete and modes.stats.root_count == 2, modes.info["message"]
        assert modes.info["monodromy_stopped"] == "trace"
        C, D = L[1] * u(th[0]), np.array([L[0], 0.0]) + L[4] * u(th[1])
        ref = circle_intersections(C, L[2], D, L[3]) or []
        assert len(modes) == len(ref)
        i2 = m.joint_names.index("t2")
        got = [C + L[2] * u(th[0] + r.q[i2]) for r in modes]
        for p in ref:
            assert min(np.max(np.abs(g - p)) for g in got) < 1e-9
        ms = optkin.assembly_modes(m, th, method="multistart", seed=0)
        assert len(ms) == len(modes)
        for r in ms:
            assert min(np.max(np.abs(np.angle(np.exp(1j * (r.q - h.q))))) for h in modes) < 1e-8
        both += len(ref) == 2
    assert both >= 4


def test_khalil_sr400_against_the_multistart():
    m = optkin.mechanisms.sr400()
    rng = np.random.default_rng(1)
    for _ in range(4):
        qa = rng.uniform(-1, 1, 6)
        # the first call in an empty cache tracks interpreted while the tracker compiles
        # (about 13 s of CPU together): on a loaded machine the default 10 s is too short
        hom = optkin.assembly_modes(m, qa, method="homotopy", time_limit=60)
        ref = optkin.assembly_modes(m, qa)
        assert hom.complete, hom.info["message"]
        assert len(hom) == len(ref) >= 1
        for r in hom:
            assert min(np.max(np.abs(np.angle(np.exp(1j * (r.x - q.x))))) for q in ref) < 1e-8


def _tsai_3upu(angles=(92.0, 207.0, 338.0), rb=1.0, rp=0.45) -> optkin.Mechanism:
    """Tsai's 3-UPU with legs at other angles than the library's (its own start system)."""
    t = np.deg2rad(angles)
    u = np.c_[np.cos(t), np.sin(t), np.zeros(3)]
    legs = [{"type": "UPU", "base": (rb * u[i]).tolist(), "platform": (rp * u[i]).tolist(),
             "axis": [-u[i, 1], u[i, 0], 0.0], "arm": (-u[i]).tolist()} for i in range(3)]
    return optkin.Mechanism.from_legs(legs, "spatial", name="3-UPU")


def test_time_limit_stops_a_monodromy_that_does_not_end(monkeypatch, tmp_path):
    """A 3-UPU whose start system does not ship: its monodromy takes over a minute (84
    orbits of 8 solutions); under a time budget of 2 s the call stops, says so, and
    stores nothing."""
    monkeypatch.setenv("OPTKIN_TIME_BUDGET", "2")
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    m = _tsai_3upu()
    modes = optkin.assembly_modes(m, [1.2, 1.2, 1.2], method="homotopy")
    assert not modes.complete and modes.info["status"] == "time_limit"
    assert modes.info["monodromy_stopped"] == "time"
    assert "time limit" in modes.info["message"]
    assert not list(tmp_path.glob("optkin_start_*.npz"))


def test_monodromy_of_the_3rps_at_joint_level_finds_its_16_solutions():
    """The 3-RPS's direct kinematics has 16 complex solutions (Innocenti and
    Parenti-Castelli 1990). At joint level (the platform pose and one revolute angle per
    leg) monodromy found thousands before the random start geometry was kept within rigid
    legs: a revolute screw with w . w != 1 or w . v != 0 is no rotation, and its
    exponential is not 2 pi periodic in the angle. Now it stops, after 10 loops in a row
    without a new one, at 16 distinct solutions (two seeds), each a solution of the start
    system with its angles identified modulo 2 pi only, and no path of its loops diverges
    (with the axes normalised at each end rather than fixed, a third did: mid-path they
    were no unit vectors)."""
    from optkin.model.core import get_model
    from optkin.solvers import homotopy as H

    M = get_model(optkin.mechanisms.rps3())
    assert H._system(M).periodic[7:].all() and not H._system(M).periodic[:7].any()
    ends = []
    track = H.track

    def counted(*a, **k):
        P = track(*a, **k)
        ends.extend(P.status)
        return P

    for seed in (0, 1):
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(H, "track", counted)
            S = H.start_system(M, seed=seed, stale=10, max_loops=80, verify=False)
        assert S.stopped == "stale" and len(S.solutions) == 16, (seed, S.stopped, len(S.solutions))
        sys_ = H._system(M)
        res = sys_.eval(S.solutions, np.repeat(S.theta[None], 16, 0),
                        np.zeros((16, sys_.nth)))[0]
        assert np.max(np.abs(res)) < 1e-8
        # distinct as rotations and angles: cos/sin of the angles, q up to its sign
        q = S.solutions[:, 3:7] * np.sign(S.solutions[:, 3:4].real)
        key = np.c_[S.solutions[:, :3], q, np.cos(S.solutions[:, 7:]), np.sin(S.solutions[:, 7:])]
        gap = min(np.max(np.abs(key[i] - key[j])) for i in range(16) for j in range(i))
        assert gap > 1e-4
    assert len(ends) > 100 and set(ends) == {"finite"}, sorted(set(ends))


def test_every_assembly_mode_of_a_3rps_complete(tmp_path, monkeypatch):
    """The 3-RPS (joint level): every path accounted for, complete, and each real mode a
    configuration of the legs checked here with numpy: the platform point at its leg's
    length from the base point, in the plane through it normal to the revolute's axis.
    The count equals the multistart's."""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    m = optkin.mechanisms.rps3(1.0, 0.5)
    for qa in ([1.03, 1.03, 1.03], [1.2, 0.9, 1.1]):
        modes = optkin.assembly_modes(m, qa, method="homotopy")
        assert modes.complete and modes.stats.paths == 16 and modes.stats.failed == 0, \
            modes.info["message"]
        assert len(modes) == len(optkin.assembly_modes(m, qa, method="multistart"))
        for r in modes:
            T = np.asarray(r.pose)
            for leg, q in zip(m.legs, qa):
                P = T[:3, :3] @ np.asarray(leg.platform, float) + T[:3, 3]
                a = np.asarray(leg.base, float)
                assert abs(np.linalg.norm(P - a) - q) < 1e-9
                assert abs(np.dot(P - a, np.asarray(leg.axis, float))) < 1e-9


_ORDER = """
import sys, json, numpy as np, optkin
big = optkin.mechanisms.rpr3([[0.3, 0.1], [40.0, -2.0], [17.0, 35.0]],
                             [[-4.0, -2.5], [5.0, -3.5], [1.0, 6.0]])
small = optkin.mechanisms.rpr3([[0.03, 0.01], [1.0, -0.05], [0.4, 0.9]],
                               [[-0.1, -0.06], [0.12, -0.09], [0.02, 0.15]])
if sys.argv[1] == "big-first":
    optkin.assembly_modes(big, [30.0, 25.0, 28.0], method="homotopy")
m = optkin.assembly_modes(small, [0.55, 0.62, 0.5], method="homotopy")
print(json.dumps([r.x.tolist() for r in m]))
"""


def test_results_do_not_depend_on_the_geometry_seen_first():
    """The compiled tracker is one per topology; the scale of the unknowns (the model's
    size) is an input of each run, not a constant of whichever geometry built it: a small
    3-RPR's modes are the same to the bit whether a forty times larger one ran first in the
    process (they differed at round-off, and results of parallel runs with them)."""
    import subprocess
    import sys

    out = [subprocess.run([sys.executable, "-c", _ORDER, order], capture_output=True,
                          text=True, timeout=300, check=True).stdout
           for order in ("big-first", "alone")]
    assert out[0] == out[1] and len(out[0]) > 10


_COLD = """
import sys, json, numpy as np, optkin
from optkin.model import get_model
from optkin.solvers import homotopy as H
from test_assembly_modes import DIET_A, DIET_B, DIET_L
rng = np.random.default_rng(3)
out, trackers, first = [], [], []
for k in range(4):
    if k < 2:
        a, b = rng.uniform(-10, 10, (3, 2)), rng.uniform(-4, 4, (3, 2))
        m, qa = optkin.mechanisms.rpr3(a, b), rng.uniform(6, 12, 3)
    else:
        A = DIET_A + rng.uniform(-0.03, 0.03, DIET_A.shape)
        m, qa = optkin.mechanisms.stewart_gough(A, DIET_B), DIET_L
    sy = H._system(get_model(m))  # just built: with an empty cache, its compile pending
    first.append(sy._pending is not None)
    r = optkin.assembly_modes(m, qa, method="homotopy")
    out.append([s.x.tolist() for s in r])
    trackers.append(H._tracker(get_model(m)))
print(json.dumps({"modes": out, "interpreted": [t._pending is not None for t in trackers],
                  "system_interpreted": first}))
for t in trackers:  # let the libraries be stored for the next process
    for p in (t._pending, t.sys._pending):
        if p is not None:
            p.wait()
"""


def test_interpreted_tracker_while_compiling_gives_the_compiled_numbers(tmp_path):
    """With an empty cache the trackers and the systems they track compile in the
    background and the interpreted ones answer meanwhile (a failed interpreted call is
    made again compiled); a second process, which loads the compiled libraries, gives the
    same modes to the bit."""
    import json
    import os
    import subprocess
    import sys

    env = dict(os.environ, OPTKIN_CACHE=str(tmp_path / "cache"),
               PYTHONPATH=os.pathsep.join([str(Path(__file__).parent),
                                           os.environ.get("PYTHONPATH", "")]))
    runs = [json.loads(subprocess.run([sys.executable, "-c", _COLD], env=env, text=True,
                                      capture_output=True, timeout=600, check=True).stdout)
            for _ in range(2)]
    assert any(runs[0]["interpreted"]) and not any(runs[1]["interpreted"])
    assert any(runs[0]["system_interpreted"]) and not any(runs[1]["system_interpreted"])
    assert runs[0]["modes"] == runs[1]["modes"] and sum(map(len, runs[0]["modes"])) > 8


def test_auto_keeps_the_homotopy_when_only_complex_endpoints_are_singular():
    """A random planar 6-6 platform (the scaling benchmark's recipe, its instance 6) whose
    homotopy ends four paths ill-conditioned at complex points near infinity (|x| ~ 1e5,
    far from real): ``method="auto"`` keeps the homotopy, and its real modes are those of
    the multistart (an independent method: random starts, Newton, IPOPT rescues)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(0)
    for i in range(7):  # the benchmark's stream: three kinds drawn in turn
        if i % 3 == 0:
            ab = np.sort(rng.uniform(0, 2 * np.pi, 6))
            ap = np.sort(rng.uniform(0, 2 * np.pi, 6))
            p = np.r_[rng.uniform(-0.1, 0.1, 2), rng.uniform(0.8, 1.2)]
            R = Rotation.from_euler("ZYX", rng.uniform(-0.15, 0.15, 3)[::-1]).as_matrix()
            base = np.c_[np.cos(ab), np.sin(ab), np.zeros(6)]
            plat = 0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]
            qa = np.linalg.norm(p + plat @ R.T - base, axis=1)
        elif i % 3 == 1:
            rng.uniform(-1, 1, (3, 2)), rng.uniform(-0.4, 0.4, (3, 2))
            rng.uniform(-0.3, 0.3, 2), rng.uniform(-1, 1)
        else:
            rng.uniform(6, 10), rng.uniform(6, 9), rng.uniform(4, 6)
    mech = optkin.mechanisms.stewart_gough(base, plat)
    hom = optkin.assembly_modes(mech, qa, method="homotopy")
    assert hom.stats.singular > 0 and hom.info["singular_near_real"] == 0
    auto = optkin.assembly_modes(mech, qa)
    assert auto.info["method"] == "homotopy" and auto.complete
    ms = optkin.assembly_modes(mech, qa, method="multistart", seed=3)
    assert len(auto) == len(ms) >= 2
    for r in ms:
        d = [np.max(np.abs(s.x - r.x)) for s in auto]
        assert min(d) < 1e-7


@pytest.mark.parametrize("n,k", [(5, 1), (7, 2)])
def test_complex_elimination_against_numpy(n, k):
    """The tracker's written-out complex solve (H._clu: equilibrated, partial pivoting)
    against numpy.linalg.solve: random complex systems, some whose leading block is zero
    (no solve without row exchanges) or whose rows differ in size by 1e6, and the column
    scale D applied as x = D u with (J D) u = b."""
    rng = np.random.default_rng(3)
    f = H._clu(n, k)
    for trial in range(12):
        J = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
        if trial % 3 == 1:
            J[:2, :2] = 0  # the first pivots must come from lower rows
        if trial % 3 == 2:
            J[0] *= 1e6
            J[-1] *= 1e-6
        B = rng.normal(size=(n, k)) + 1j * rng.normal(size=(n, k))
        D = rng.uniform(1, 5, n)
        Xr, Xi = f(J.real, J.imag, B.real, B.imag, D)
        X = np.array(Xr) + 1j * np.array(Xi)
        ref = np.linalg.solve(J, B)
        assert np.max(np.abs(X - ref)) <= 1e-9 * (1 + np.max(np.abs(ref))), trial


def _rodrigues(w, a):
    w = np.asarray(w, float) / np.linalg.norm(w)
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def test_the_3upu_symmetry_flips_both_universal_joints_of_a_leg():
    """A universal joint's angles (a, b) and (a + pi, pi - b) point its outgoing axis the
    same way, turned half a turn about it (Rodrigues' formula, here): flipping both joints
    of a U-P-U leg leaves its ends in place. homotopy.symmetry finds exactly these maps on
    Tsai's 3-UPU: the 7 non-empty sets of legs flipped, each leg's four angles mapped
    (ua + pi, pi - ub, pi - va, vb + pi); the real closure is unchanged by them at random
    configurations; mechanisms without such joints get the identity alone."""
    rng = np.random.default_rng(0)
    a1, a2 = np.array([0.0, 1.0, 0.0]), np.array([-1.0, 0.0, 0.0])
    d = np.cross(a1, a2)
    for a, b in rng.uniform(-np.pi, np.pi, (5, 2)):
        R = _rodrigues(a1, a) @ _rodrigues(a2, b)
        R2 = _rodrigues(a1, a + np.pi) @ _rodrigues(a2, np.pi - b)
        assert np.allclose(R2, R @ _rodrigues(d, np.pi), atol=1e-12)
    m = get_model(optkin.mechanisms.upu3())
    sym = H.symmetry(m)
    assert sym.order == 8
    assert np.all(sym.sign[0] == 1) and np.all(sym.shift[0] == 0)
    names = list(m.x_names)
    flipped = set()
    for sg, sh in zip(sym.sign[1:], sym.shift[1:]):
        moved = np.flatnonzero((sg != 1) | (sh != 0))
        legs = frozenset(names[i].split(".")[0] for i in moved)
        for leg in legs:
            ix = [names.index(f"{leg}.{v}") for v in ("ua", "ub", "va", "vb")]
            assert sg[ix].tolist() == [1, -1, -1, 1]
            assert np.allclose(np.cos(sh[ix]), -1.0)
        assert len(moved) == 4 * len(legs)
        flipped.add(legs)
    assert len(flipped) == 7
    qa = np.array([1.2, 1.1, 1.3])
    for _ in range(3):
        x = rng.normal(size=m.nx)
        x[3:7] /= np.linalg.norm(x[3:7])
        r0 = m.residual(qa, x)
        assert np.max(np.abs(r0)) > 1e-2  # not a solution: the identity holds everywhere
        for g in range(1, sym.order):
            assert np.allclose(m.residual(qa, x * sym.sign[g] + sym.shift[g]), r0, atol=1e-12)
    for mk in (optkin.mechanisms.rps3, lambda: optkin.mechanisms.rpr3(
            [[0, 0], [1, 0], [0, 1]], [[0, 0], [0.3, 0], [0, 0.3]])):
        assert H.symmetry(get_model(mk())).order == 1


def test_the_3upu_homotopy_accounts_for_every_path():
    """Tsai's 3-UPU at joint level (19 unknowns): the shipped start system's 672
    solutions (84 orbits of the legs' flips; verified by the trace test along the leg
    lengths, sliced by the pose), one path per orbit tracked. At the leg lengths of a translated platform
    every path is accounted for (finite or, at Tsai's special geometry, diverging: the
    endgame's valuation), none failed; every real solution closes each leg by the chain written in
    test_assembly_modes_chains (its own Rodrigues products), comes in 8 joint
    configurations of one pose, and the poses are the multistart's, with the two
    translations at the three-sphere intersection."""
    from test_assembly_modes_chains import three_spheres, upu_leg_frame

    m = optkin.mechanisms.upu3()
    a = 2 * np.pi * np.arange(3) / 3
    u = np.c_[np.cos(a), np.sin(a), np.zeros(3)]
    A, B, axis, arm = 1.0 * u, 0.5 * u, np.c_[-u[:, 1], u[:, 0], np.zeros(3)], -u
    p0 = np.array([0.05, -0.02, 0.8])
    rho = np.linalg.norm(p0 + B - A, axis=1)
    # (a first call in a fresh cache tracks with the interpreted tracker while its code
    # compiles: beside other tests, past assembly_modes' default 10 s)
    hom = optkin.assembly_modes(m, rho, method="homotopy", time_limit=300)
    st = hom.stats
    assert hom.info["root_count"] == 672 and st.failed == 0, hom.info["message"]
    assert st.finite + st.at_infinity == 672 and st.at_infinity > 0
    assert "every path accounted for" in hom.info["message"]
    assert hom.complete and "not verified" not in hom.info["message"]
    poses = []
    for r in hom:
        assert r.success and r.residual < 1e-9
        for k in range(3):
            Tk = upu_leg_frame(A[k], B[k], axis[k], arm[k], r.q[5 * k: 5 * k + 5])
            assert np.max(np.abs(Tk - r.pose)) < 1e-9
        poses.append(np.r_[r.pose[:3, 3], r.pose[:3, :3].ravel()])
    poses = np.array(poses)
    distinct = []
    for p in poses:
        if not any(np.max(np.abs(p - q)) < 1e-8 for q in distinct):
            distinct.append(p)
    counts = [sum(np.max(np.abs(p - q)) < 1e-8 for p in poses) for q in distinct]
    assert counts == [8] * len(distinct)
    ms = optkin.assembly_modes(m, rho, method="multistart", seed=0)
    ref = [np.r_[r.pose[:3, 3], r.pose[:3, :3].ravel()] for r in ms]
    assert len(ref) == len(distinct) >= 2
    for q in ref:
        assert min(np.max(np.abs(p - q)) for p in distinct) < 1e-8
    trans = [p[:3] for p in distinct if np.max(np.abs(p[3:] - np.eye(3).ravel())) < 1e-9]
    sph = three_spheres(A - B, rho)
    assert len(trans) == 2
    for s in sph:
        assert min(np.max(np.abs(t - s)) for t in trans) < 1e-9


def test_solutions_far_out_are_told_apart_relative_to_their_size():
    """Monodromy's identification of solutions (homotopy._distinct): a point far out
    computed twice agrees only relatively (Tsai's 3-UPU, seed 2: an orbit at |x| ~ 490
    whose endpoints differed by 1.5e-6 from loop to loop, 3e-9 relative, was added again
    and again: 1 256 "solutions" of which 672 distinct). Two copies of such a point within
    3e-9 relative are one solution; points 1e-4 apart relative stay two, near and far."""
    model = get_model(optkin.mechanisms.rpr3([[0, 0], [10, 0], [4, 8]],
                                             [[-1, -0.5], [1, -0.5], [0, 1]]))
    sc = np.asarray(model.x_scale, dtype=float)
    rng = np.random.default_rng(5)
    for size in (1.0, 490.0):
        y = size * sc * (rng.normal(size=3) + 1j * rng.normal(size=3))
        y[2] = 0.3 + 1j * y[2].imag / sc[2]  # the angle: its real part canonical
        twin = y + 3e-9 * np.max(np.abs(y)) * np.exp(1j * rng.uniform(0, 6.3, 3))
        far = y + 1e-4 * (1 + np.max(np.abs(y) / sc)) * sc * np.array([2.0, 0, 0])
        S = y[None]
        assert H._distinct(model, S, twin[None]).shape[0] == 0, size
        assert H._distinct(model, S, far[None]).shape[0] == 1, size
        assert H._distinct(model, np.zeros((0, 3)), np.vstack([y, twin, far])).shape[0] == 2
