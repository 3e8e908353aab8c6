"""forward_batch along paths: det W_p signs, the conditioning indicator, and the rows where a
path leaves its assembly mode (a parallel singularity crossed, a fold, a jump); and the
upper bound p_new_upper that assembly_modes reports beside its Good-Turing estimate.

Evidence written here or in test_assembly_modes.py, independent of optkin's model:

* 3-RPR: the rows (u_i, (R b_i) x u_i) of W_p (Modern Robotics) in numpy, and the
  elimination of Modern Robotics 7.1.1 (``rpr_reference``): the place where two modes
  merge is where its count of real solutions drops by 2 (bisection); a reference
  continuation of a mode along a path follows the elimination's solutions on a fine grid
  and ends where the mode vanishes or another solution comes close.
* five-bar: circle intersections; the assembly mode is the side of the line CD where P is,
  and det W_p = cross(P - C, P - D) / (L2 L3), zero when C, D, P are aligned.
* completeness: Dietmaier's 6-6 platform (40 real modes, a published number) has rare
  modes; a brute-force run of 20 000 starts measures the share of the starts that reach
  each mode, hence the share held by the modes a short run missed; the Poisson limit is
  computed with scipy.stats.chi2.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.stats import chi2
from test_assembly_modes import (
    DIET_A,
    DIET_B,
    DIET_L,
    SIX_A,
    SIX_B,
    SIX_S,
    _det_rpr,
    _legs_rpr,
    _rot2,
    five_bar_reference,
    rpr_reference,
)

import optkin

FIVE = (2.0, 1.5, 1.2, 1.2, 1.5)


def _wrap_dist(u, v) -> float:
    d = np.asarray(u, float) - np.asarray(v, float)
    d[2] = np.arctan2(np.sin(d[2]), np.cos(d[2]))
    return float(np.max(np.abs(d)))


def _rpr_rows(a, b, x) -> np.ndarray:
    R = _rot2(x[2])
    rows = []
    for i in range(3):
        P = x[:2] + R @ b[i]
        u = (P - a[i]) / np.linalg.norm(P - a[i])
        rb = R @ b[i]
        rows.append([u[0], u[1], rb[0] * u[1] - rb[1] * u[0]])
    return np.array(rows)


def _side(P, C, D) -> float:
    """Which side of the line CD the point P is on: the five-bar's assembly mode."""
    u, v = D - C, P - C
    return float(np.sign(u[0] * v[1] - u[1] * v[0]))


def _fb_CD(L, t1, t2):
    C = L[1] * np.array([np.cos(t1), np.sin(t1)])
    D = np.array([L[0], 0.0]) + L[4] * np.array([np.cos(t2), np.sin(t2)])
    return C, D


# ---------------------------------------------------------------------------------------------
# det W_p and the conditioning indicator
# ---------------------------------------------------------------------------------------------


def test_det_sign_and_conditioning_of_the_six_rpr3_modes():
    """The six modes of a 3-RPR (both aspects) as independent rows: det W_p signs equal the
    closed-form ones, the conditioning equals the Hadamard ratio of the closed-form rows."""
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    ref, amb = rpr_reference(SIX_A, SIX_B, SIX_S)
    assert len(ref) == 6 and not amb
    X = np.array(ref)
    b = optkin.forward_batch(m, np.tile(SIX_S, (6, 1)), guess=X, path=False)
    assert b.all_success and not b.crossed.any()
    for x_ref, x, sgn, h in zip(X, b.x, b.det_sign, b.conditioning):
        assert _wrap_dist(x, x_ref) < 1e-8
        assert sgn == np.sign(_det_rpr(SIX_A, SIX_B, x_ref))
        W = _rpr_rows(SIX_A, SIX_B, x_ref) * optkin.get_model(m).x_scale  # columns scaled
        had = abs(np.linalg.det(W)) / np.prod(np.linalg.norm(W, axis=1))
        assert h == pytest.approx(had, rel=1e-8)
    assert set(b.det_sign.tolist()) == {-1, 1}  # both aspects are represented


def test_five_bar_det_sign_is_the_side_of_CD():
    m = optkin.mechanisms.five_bar(*FIVE)
    t = np.linspace(0.0, 1.0, 40)
    QA = np.column_stack([1.2 + 0.5 * t, 1.9 - 0.3 * t])
    for P0 in five_bar_reference(FIVE, *QA[0])[0]:
        b = optkin.forward_batch(m, QA, guess=P0)
        assert b.status == "optimal" and not b.crossed.any()
        for qa, P, sgn in zip(QA, b.x, b.det_sign):
            C, D = _fb_CD(FIVE, *qa)
            assert min(np.max(np.abs(P - r)) for r in five_bar_reference(FIVE, *qa)[0]) < 1e-9
            assert sgn == _side(P, C, D) == _side(P0, *_fb_CD(FIVE, *QA[0]))


# ---------------------------------------------------------------------------------------------
# paths inside one aspect: nothing flagged
# ---------------------------------------------------------------------------------------------


def test_rpr3_circle_inside_one_aspect_is_not_flagged():
    ang = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    a = np.column_stack([np.cos(ang + 0.1), np.sin(ang + 0.1)])
    bb = 0.35 * np.column_stack([np.cos(ang + 0.9), np.sin(ang + 0.9)])
    th = np.linspace(0, 2 * np.pi, 1000)
    poses = np.column_stack([0.1 * np.cos(th), 0.1 * np.sin(th), 0.3 * np.sin(th)])
    assert all(_det_rpr(a, bb, x) > 0 for x in poses)  # the reference stays in one aspect
    Q = np.array([_legs_rpr(a, bb, x) for x in poses])
    b = optkin.forward_batch(optkin.mechanisms.rpr3(a, bb), Q, guess=poses[0])
    assert b.status == "optimal", b.message
    assert not b.crossed.any() and not b.near_singular.any()
    assert np.all(b.det_sign == 1)
    assert np.max(np.abs(b.x - poses)) < 1e-8
    assert "crossed" not in repr(b)


# ---------------------------------------------------------------------------------------------
# paths that leave their assembly mode
# ---------------------------------------------------------------------------------------------


def _rpr_merge():
    """Leg 1 of the six-mode 3-RPR at which two modes merge (the elimination's count drops
    by 2), and the two merging modes a little before it (as in test_assembly_modes)."""
    a, b, s0 = SIX_A, SIX_B, SIX_S

    def count(r1):
        return len(rpr_reference(a, b, [r1, s0[1], s0[2]])[0])

    grid = np.linspace(s0[0], 0.3 * s0[0], 120)
    n = [count(r) for r in grid]
    k = next(i for i in range(1, len(grid)) if n[i] == n[i - 1] - 2)
    hi, lo = grid[k - 1], grid[k]
    for _ in range(40):
        mid = 0.5 * (hi + lo)
        hi, lo = (mid, lo) if count(mid) == n[k - 1] else (hi, mid)
    r_star = 0.5 * (hi + lo)
    near = rpr_reference(a, b, [r_star + 1e-6, s0[1], s0[2]])[0]
    i, j = min(((i, j) for i in range(len(near)) for j in range(i)),
               key=lambda ij: _wrap_dist(near[ij[0]], near[ij[1]]))
    mid = 0.5 * (near[i] + near[j])
    r0 = r_star + 0.02
    before = rpr_reference(a, b, [r0, s0[1], s0[2]])[0]
    pair = sorted(before, key=lambda x: _wrap_dist(x, mid))[:2]
    return r_star, r0, pair


@pytest.mark.parametrize("n", [81, 200])
def test_rpr3_mode_ending_where_two_modes_merge_is_flagged_at_that_row(n):
    r_star, r0, pair = _rpr_merge()
    assert np.sign(_det_rpr(SIX_A, SIX_B, pair[0])) != np.sign(_det_rpr(SIX_A, SIX_B, pair[1]))
    r = np.linspace(r0, r_star - 0.02, n)
    QA = np.column_stack([r, np.full(n, SIX_S[1]), np.full(n, SIX_S[2])])
    k_star = int(np.argmax(r < r_star))  # the first row past the merge
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    for start in pair:
        b = optkin.forward_batch(m, QA, guess=start)
        sign0 = np.sign(_det_rpr(SIX_A, SIX_B, start))
        # up to the merge: closed rows, in the start's aspect (closed-form det), unflagged
        assert b.closed[:k_star].all() and not b.crossed[:k_star].any()
        assert all(np.sign(_det_rpr(SIX_A, SIX_B, x)) == sign0 for x in b.x[:k_star])
        np.testing.assert_allclose(np.array([_legs_rpr(SIX_A, SIX_B, x) for x in b.x[:k_star]]),
                                   QA[:k_star], atol=1e-9)
        # the first event is at the merge: the row does not close, or is marked crossed
        event = min(np.flatnonzero(~b.closed | b.crossed))
        assert event == k_star
        assert b.status == "singular", b.message
        assert f"rows {k_star - 1} and {k_star}" in b.message
        # a row marked crossed holds another mode: far from the last row of the tracked one
        for i in np.flatnonzero(b.crossed):
            assert b.closed[i] and _wrap_dist(b.x[i], b.x[k_star - 1]) > 1e-3
        # without the guard the same rows are computed, but nothing is said
        nb = optkin.forward_batch(m, QA, guess=start, guard=False)
        np.testing.assert_array_equal(nb.x[b.closed], b.x[b.closed])
        assert nb.status != "singular" and not nb.crossed.any()


def _reference_continuation(Q, x0, sub=15):
    """Follow x0 along the straight segments of Q through the elimination's solutions on a
    fine grid; None from the first row whose segment has the mode vanish or meet another
    solution (nearest not clearly nearer than the second nearest)."""
    out = [np.asarray(x0, float)]
    x = out[0]
    for i in range(1, len(Q)):
        for t in np.linspace(0, 1, sub + 1)[1:]:
            sols, amb = rpr_reference(SIX_A, SIX_B, Q[i - 1] + t * (Q[i] - Q[i - 1]))
            ds = sorted(_wrap_dist(s, x) for s in sols)
            if amb or not ds or (len(ds) > 1 and ds[0] > 0.3 * ds[1]):
                return out + [None] * (len(Q) - len(out))
            x = min(sols, key=lambda s: _wrap_dist(s, x))
        out.append(x)
    return out


@pytest.mark.parametrize("seed", [0, 2, 4, 7, 10, 13])
def test_coarse_rpr3_paths_flagged_where_the_reference_continuation_ends(seed):
    """Straight paths in leg space, 12 rows, from each of the six modes: the rows agree with
    the reference continuation up to where it ends, and the first row marked (crossed or not
    closed) is that row; every sign change of the closed-form det W_p is marked."""
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    modes, _ = rpr_reference(SIX_A, SIX_B, SIX_S)
    modes.sort(key=lambda x: tuple(np.round(x, 6)))
    rng = np.random.default_rng(seed)
    end = SIX_S * rng.uniform(0.8, 1.2, 3)
    Q = SIX_S + np.linspace(0, 1, 12)[:, None] * (end - SIX_S)
    start = modes[seed % 6]
    b = optkin.forward_batch(m, Q, guess=start)
    ref = _reference_continuation(Q, start)
    diverge = [k for k in range(len(Q))
               if ref[k] is None or not b.closed[k] or _wrap_dist(b.x[k], ref[k]) > 1e-6]
    events = np.flatnonzero(~b.closed | b.crossed)
    if not diverge:
        assert b.status == "optimal" and events.size == 0, b.message
    else:
        assert events.size and events[0] == diverge[0], (events, diverge, b.message)
        assert b.status == "singular", b.message
    closed = np.flatnonzero(b.closed)
    s = [np.sign(_det_rpr(SIX_A, SIX_B, b.x[k])) for k in closed]
    for j in range(1, len(closed)):
        if s[j] != s[j - 1]:
            assert b.crossed[closed[j]]


def test_five_bar_fold_where_C_D_P_align():
    """theta1 decreasing past the value where |CD| = L2 + L3 (C, P, D aligned, closed form):
    the rows before close in one mode, the first row past it does not, status "singular"."""
    L, th2 = FIVE, 1.9
    m = optkin.mechanisms.five_bar(*L)

    def gap(t1):
        C, D = _fb_CD(L, t1, th2)
        return np.linalg.norm(C - D) - (L[2] + L[3])

    t_star = brentq(gap, -1.5, 1.2)
    t = np.linspace(1.2, t_star - 0.3, 200)
    QA = np.column_stack([t, np.full(len(t), th2)])
    k_star = int(np.argmax(t < t_star))
    for P0 in five_bar_reference(L, *QA[0])[0]:
        b = optkin.forward_batch(m, QA, guess=P0)
        side0 = _side(P0, *_fb_CD(L, *QA[0]))
        assert b.closed[:k_star].all() and not b.closed[k_star:].any()
        assert all(_side(P, *_fb_CD(L, *qa)) == side0 for P, qa in zip(b.x[:k_star], QA))
        assert not b.crossed.any()
        assert b.status == "singular" and f"rows {k_star - 1} and {k_star}" in b.message
        assert "fold" in b.message
        # the conditioning falls towards the fold (det W_p ~ sqrt of the distance)
        assert int(np.nanargmin(b.conditioning)) == k_star - 1
        assert b.conditioning[k_star - 1] < 0.5 * b.conditioning[0]


def test_result_fields_and_dict():
    m = optkin.mechanisms.five_bar(*FIVE)
    QA = np.column_stack([np.linspace(1.2, 1.3, 5), np.full(5, 1.9)])
    b = optkin.forward_batch(m, QA)
    d = b.to_dict()
    assert d["det_sign"] == b.det_sign.tolist() and len(d["conditioning"]) == 5
    assert d["crossed"] == [False] * 5 and d["near_singular"] == [False] * 5
    assert "guard_time" in b.stats.extra
    off = optkin.forward_batch(m, QA, guard=False)
    assert np.all(off.det_sign == 0) and np.all(np.isnan(off.conditioning))


# ---------------------------------------------------------------------------------------------
# assembly_modes: the upper bound on the probability of a new solution
# ---------------------------------------------------------------------------------------------


def test_p_new_upper_is_the_poisson_limit_and_the_rule_of_three():
    m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    for n in (40, 64, 200):
        modes = optkin.assembly_modes(m, [1.2, 1.9], bound=None, starts=n, min_starts=n,
                                      target=0.0)
        info = modes.info
        k, starts = info["singletons"], info["converged"]  # draws: the converged starts
        assert info["p_new_upper"] == pytest.approx(chi2.ppf(0.99, 2 * k + 2) / 2 / starts)
        assert info["p_new_upper"] > info["p_new"]
        if k == 0:  # both modes seen often: the estimate says 0, the bound -ln(0.01) / n
            assert info["p_new"] == 0.0
            assert info["p_new_upper"] == pytest.approx(-np.log(0.01) / starts)
    assert "99 % upper bound" in modes.info["message"]


def test_default_stop_needs_the_bound_below_target_upper():
    """A mechanism without a known bound (the four-bar as a Khalil table) stops by the
    target only once the bound is at most target_upper; target_upper=1 is the old rule."""
    m = optkin.mechanisms.four_bar(1.0, 2.0, 2.0, 2.5)
    new = optkin.assembly_modes(m, [1.0], method="multistart")
    old = optkin.assembly_modes(m, [1.0], target_upper=1.0)
    assert new.info["stop_reason"] == old.info["stop_reason"] == "target"
    assert new.info["p_new_upper"] <= 1e-2 < old.info["p_new_upper"]
    assert new.info["p_new"] <= 1e-3 and new.info["starts"] > old.info["starts"]
    assert len(new) == len(old) == 2


def _missing_share(modes, X, share) -> float:
    got = np.array([r.x for r in modes])
    return float(sum(p for x, p in zip(X, share)
                     if not len(got) or np.min(np.max(np.abs(got - x), axis=1)) > 1e-6))


def test_upper_bound_covers_the_rare_modes_of_dietmaiers_platform():
    """Brute force: 20 000 starts reach all 40 modes (the published count), the rarest by
    well under 1 % of the starts. Short runs (at least 32 starts) stopped by the bound at
    0.02 leave out at most the bounded share in all but a few of 20 seeds; stopped by the
    Good-Turing estimate at 0.02, the missed share exceeds the estimate in most of them."""
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    brute = optkin.assembly_modes(m, DIET_L, seed=1000, bound=None, starts=20000,
                                  min_starts=20000, target=0.0, time_limit=60)
    assert len(brute) == 40 and brute.info["starts"] == 20000
    X = np.array([r.x for r in brute])
    share = np.array(brute.info["hits"]) / brute.info["converged"]  # per converged draw
    assert share.min() < 0.006  # rare modes exist
    by_bound = by_estimate = 0
    complete_bound = complete_estimate = 0
    for seed in range(20):
        b = optkin.assembly_modes(m, DIET_L, seed=seed, min_starts=32, target=1.0,
                                  target_upper=0.02)
        e = optkin.assembly_modes(m, DIET_L, seed=seed, min_starts=32, target=0.02,
                                  target_upper=1.0)
        assert b.info["stop_reason"] in ("target", "bound")
        assert e.info["stop_reason"] in ("target", "bound")
        by_bound += _missing_share(b, X, share) <= b.info["p_new_upper"]
        by_estimate += _missing_share(e, X, share) <= e.info["p_new"]
        complete_bound += len(b) == 40
        complete_estimate += len(e) == 40
    assert by_bound >= 17, by_bound  # a 99 % bound, checked after every batch
    assert by_estimate <= 10, by_estimate  # the estimate alone is not conservative
    assert complete_bound > complete_estimate


def test_path_that_starts_out_of_reach_recovers_when_the_legs_can_close():
    base = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]])
    plat = np.array([[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    m = optkin.mechanisms.rpr3(base, plat)
    start = optkin.inverse(m, [0.45, 0.35, 0.1])[0]
    QA = np.vstack([[0.01, 0.01, 0.01]] * 3 + [start.qa + 0.001 * k for k in range(40)])
    b = optkin.forward_batch(m, QA)
    assert not b.closed[:3].any() and b.closed[3:].all()
    # leg lengths of every solved pose, written out (Modern Robotics 7.1.1), equal the inputs
    for qa, (x, y, phi) in zip(QA[3:], b.x[3:]):
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        rho = np.linalg.norm(np.array([x, y]) + plat @ R.T - base, axis=1)
        np.testing.assert_allclose(rho, qa, atol=1e-9)
