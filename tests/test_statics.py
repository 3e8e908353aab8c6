"""Statics: capability, feasibility, distribution against independent computations.

Independent references written here: the planar leg wrench F = sum tau_i (u_i, r_i x u_i)
by hand (unit leg vectors and moment arms), Modern Robotics 7.2.1's Stewart-Gough
J_s^-T, closed forms on a symmetric 3-RPR, virtual work by finite differences of the
leg-length formula s_i = |p + R b_i - a_i| (MR eq. 7.2), and scipy.optimize.linprog on
the same LPs written in actuator-force space with the hand-derived map.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

import optkin
from optkin import statics
from optkin.errors import MechanismError, StaticsError

RNG = np.random.default_rng(7)

# Modern Robotics 7.1.1-style 3-RPR (also problems/rpr3.toml)
BASE3 = np.array([[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]])
PLAT3 = np.array([[-0.5, -0.3], [0.5, -0.3], [0.0, 0.4]])
# redundantly actuated 4-RPR (problems/rpr4.toml)
BASE4 = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0]])
PLAT4 = np.array([[-0.5, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.5, 0.3]])
# symmetric 3-RPR: base radius R, platform radius r, joints at 0, 120, 240 degrees
R_SYM, r_SYM = 1.0, 0.2
ANG = 2 * np.pi * np.arange(3) / 3
BASE_SYM = R_SYM * np.column_stack([np.cos(ANG), np.sin(ANG)])
PLAT_SYM = r_SYM * np.column_stack([np.cos(ANG), np.sin(ANG)])


def rot(phi):
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def hand_G(base, plat, pose):
    """3 x n map tau -> (fx, fy, mz): column i = (u_i, (R b_i) x u_i), u_i from a_i to P_i."""
    x, y, phi = pose
    cols = []
    for a, b in zip(base, plat):
        r = rot(phi) @ b
        P = np.array([x, y]) + r
        u = (P - a) / np.linalg.norm(P - a)
        cols.append([u[0], u[1], r[0] * u[1] - r[1] * u[0]])
    return np.array(cols).T


def leg_lengths(base, plat, pose):
    x, y, phi = pose
    return np.array([np.linalg.norm(np.array([x, y]) + rot(phi) @ b - a)
                     for a, b in zip(base, plat)])


def lp_capability(G, d, lo, hi):
    """max s  s.t.  G tau = s d, lo <= tau <= hi   (scipy linprog, tau-space)."""
    n = G.shape[1]
    c = np.zeros(n + 1)
    c[-1] = -1.0
    A_eq = np.hstack([G, -d[:, None]])
    bounds = [(lo[i], hi[i]) for i in range(n)] + [(0, None)]
    res = linprog(c, A_eq=A_eq, b_eq=np.zeros(G.shape[0]), bounds=bounds, method="highs")
    assert res.status == 0, res.message
    return -res.fun


def lp_min_utilisation(G, w, lim):
    """min t  s.t.  G tau = w, |tau_i| <= t lim_i   (linprog)."""
    n = G.shape[1]
    c = np.zeros(n + 1)
    c[-1] = 1.0
    A_ub = np.vstack([np.hstack([np.eye(n), -lim[:, None]]),
                      np.hstack([-np.eye(n), -lim[:, None]])])
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(2 * n), A_eq=np.hstack([G, np.zeros((3, 1))]),
                  b_eq=w, bounds=[(None, None)] * n + [(0, None)], method="highs")
    assert res.status == 0, res.message
    return res.fun


def sol_at(m, pose, k=0):
    sols = optkin.inverse(m, pose)
    assert len(sols) > k, sols.info
    return sols[k]


# ----------------------------------------------------------------------------- static map


def test_mr_exercise_72c_style_wrench_from_joint_forces():
    """MR Exercise 7.2(c) style: tau = (1, 0, -1) on a 3-RPR whose legs 1, 2 share a base
    joint and legs 2, 3 share a platform joint; the wrench (m_bz, f_bx, f_by) in {b}."""
    base = np.array([[0.0, 0.0], [0.0, 0.0], [3.0, 0.0]])
    plat = np.array([[-0.5, 0.0], [0.5, 0.0], [0.5, 0.0]])
    m = optkin.mechanisms.rpr3(base, plat)
    pose = (1.2, 1.5, 0.35)
    s = sol_at(m, pose)
    tau = np.array([1.0, 0.0, -1.0])
    # by hand: leg i pushes the platform joint B_i along u_i = (B_i - A_i)/|B_i - A_i| with
    # force tau_i; the moment about the {b} origin is (R b_i) x (tau_i u_i)
    Rm = rot(pose[2])
    f = np.zeros(2)
    mz = 0.0
    for a, b, t in zip(base, plat, tau):
        ri = Rm @ b
        Bi = np.array(pose[:2]) + ri
        u = (Bi - a) / np.hypot(*(Bi - a))
        f += t * u
        mz += t * (ri[0] * u[1] - ri[1] * u[0])
    f_b = Rm.T @ f
    expected = np.array([mz, f_b[0], f_b[1]])
    F = statics.static_model(m, s).wrench(tau)  # (fx, fy, mz), base frame
    got = np.array([F[2], *(Rm.T @ F[:2])])
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_virtual_work_finite_differences_rpr3():
    """tau . ds = F . dt for small platform motions (leg lengths by MR eq. 7.2)."""
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    for _ in range(5):
        pose = np.array([RNG.uniform(1.3, 2.1), RNG.uniform(0.9, 1.6), RNG.uniform(-0.4, 0.4)])
        sm = statics.static_model(m, sol_at(m, pose))
        tau = RNG.normal(size=3)
        F = sm.wrench(tau)
        for _k in range(3):
            dt = RNG.normal(size=3)
            h = 1e-6
            ds = (leg_lengths(BASE3, PLAT3, pose + h * dt)
                  - leg_lengths(BASE3, PLAT3, pose - h * dt)) / (2 * h)
            assert abs(tau @ ds - F @ dt) < 1e-7 * (1 + abs(F @ dt))
        # and G equals the hand-written map
        np.testing.assert_allclose(sm.G, hand_G(BASE3, PLAT3, pose), atol=1e-12)


def test_stewart_gough_matches_mr_721():
    """F_s = sum [q_i x n_i; n_i] tau_i (MR 7.2.1), moments moved to the platform origin."""
    ang = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([-10, 10] * 3)
    base = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(6)])
    pang = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([25, -25] * 3)
    plat = 0.5 * np.column_stack([np.cos(pang), np.sin(pang), np.zeros(6)])
    m = optkin.mechanisms.stewart_gough(base, plat)
    pose = [0.05, -0.03, 0.9, 0.1, -0.05, 0.2]
    s = sol_at(m, pose)
    T = s.pose
    R, p = T[:3, :3], T[:3, 3]
    tau = RNG.normal(size=6)
    f = np.zeros(3)
    m_s = np.zeros(3)
    for qi, bi, t in zip(base, plat, tau):
        n = p + R @ bi - qi
        n /= np.linalg.norm(n)
        f += n * t
        m_s += np.cross(qi, n) * t  # -n x q = q x n
    m_p = m_s - np.cross(p, f)
    F = statics.static_model(m, s).wrench(tau)
    np.testing.assert_allclose(F, np.concatenate([f, m_p]), atol=1e-10)
    # spatial capability vs linprog on the hand-written 6 x 6 map (moments about p)
    G = np.zeros((6, 6))
    for i, (qi, bi) in enumerate(zip(base, plat)):
        n = p + R @ bi - qi
        n /= np.linalg.norm(n)
        G[:3, i] = n
        G[3:, i] = np.cross(qi, n) - np.cross(p, n)
    lim = RNG.uniform(50, 150, 6)
    D = RNG.normal(size=(6, 6))
    D /= np.linalg.norm(D, axis=1)[:, None]
    cap = statics.capability(m, s, lim, D)
    assert cap.status == "optimal"
    np.testing.assert_allclose(cap.max, [lp_capability(G, d, -lim, lim) for d in D], rtol=1e-8)


def test_khalil_four_bar_virtual_work():
    """Four-bar (MR 7.3, Khalil table): crank torque tau vs rocker moment M: tau = (dphi/dtheta) M."""
    m = optkin.mechanisms.four_bar(1.0, 2.0, 2.0, 2.5)
    r = optkin.forward(m, [1.0])
    iphi = m.joint_names.index("phi")
    h = 1e-6
    p1 = optkin.forward(m, [1.0 + h], guess=r).q[iphi]
    p0 = optkin.forward(m, [1.0 - h], guess=r).q[iphi]
    ratio = (p1 - p0) / (2 * h)
    sm = statics.static_model(m, r)
    assert sm.wrench_names == ("mz",)
    np.testing.assert_allclose(sm.wrench([1.0]), [1.0 / ratio], rtol=1e-7)
    cap = statics.capability(m, r, 2.0, ["mz", "-mz"])
    np.testing.assert_allclose(cap.max, [2.0 / abs(ratio)] * 2, rtol=1e-7)


# ----------------------------------------------------------------------------- capability


def test_capability_symmetric_rpr3_closed_form():
    """Symmetric 3-RPR at (0, 0, phi): every leg has the moment arm h = r R sin(phi) / L,
    so M_max = 3 t h; a pure force along psi needs tau_i = (2/3) s cos(psi - arg u_1 - theta_i)."""
    m = optkin.mechanisms.rpr3(BASE_SYM, PLAT_SYM)
    t = 1.7
    for phi in (0.25, 0.6, -0.9):
        s = sol_at(m, [0.0, 0.0, phi])
        L = np.sqrt(R_SYM**2 + r_SYM**2 - 2 * R_SYM * r_SYM * np.cos(phi))
        h = r_SYM * R_SYM * np.sin(phi) / L
        psi = np.linspace(0, 2 * np.pi, 13)[:-1]
        D = np.column_stack([np.cos(psi), np.sin(psi), np.zeros_like(psi)])
        D = np.vstack([D, [0, 0, 1], [0, 0, -1]])
        cap = statics.capability(m, s, t, D)
        assert cap.success and cap.status == "optimal"
        u1 = (r_SYM * np.array([np.cos(phi), np.sin(phi)]) - np.array([R_SYM, 0.0])) / L
        aw = np.arctan2(u1[1], u1[0])
        closed = [t / ((2 / 3) * np.max(np.abs(np.cos(p - aw - ANG)))) for p in psi]
        closed += [3 * t * abs(h)] * 2
        np.testing.assert_allclose(cap.max, closed, atol=1e-6)


@pytest.mark.parametrize("which", ["rpr3", "rpr4"])
def test_capability_matches_linprog(which):
    base, plat = (BASE3, PLAT3) if which == "rpr3" else (BASE4, PLAT4)
    m = getattr(optkin.mechanisms, which)(base, plat)
    n = len(base)
    for trial in range(4):
        pose = np.array([RNG.uniform(1.4, 2.4), RNG.uniform(1.0, 1.8), RNG.uniform(-0.4, 0.4)])
        s = sol_at(m, pose)
        D = RNG.normal(size=(8, 3))
        D /= np.linalg.norm(D, axis=1)[:, None]
        if trial % 2:  # asymmetric limits (lo, hi), lo <= 0 <= hi
            lo, hi = -RNG.uniform(0.2, 2.0, n), RNG.uniform(0.2, 2.0, n)
            limits = np.column_stack([lo, hi])
        else:
            hi = RNG.uniform(0.5, 2.0, n)
            lo, limits = -hi, hi
        cap = statics.capability(m, s, limits, D)
        assert cap.success, cap.message
        G = hand_G(base, plat, pose)
        ref = [lp_capability(G, d, lo, hi) for d in D]
        np.testing.assert_allclose(cap.max, ref, atol=1e-6, rtol=1e-9)
        # the reported actuator forces produce the boundary wrench within the limits
        np.testing.assert_allclose(cap.tau @ G.T, cap.points, atol=1e-7)
        assert np.all(cap.tau <= hi + 1e-8) and np.all(cap.tau >= lo - 1e-8)


def test_polytope_support_equals_capability():
    """Zonotope of the actuator box (corners + ConvexHull) vs the ray LPs."""
    m = optkin.mechanisms.rpr4(BASE4, PLAT4)
    s = sol_at(m, [2.2, 1.3, 0.2])
    lim = np.array([1.0, 2.0, 1.5, 0.7])
    poly = statics.polytope(m, s, lim)
    assert poly.success and poly.dimension == 3
    D = RNG.normal(size=(10, 3))
    D /= np.linalg.norm(D, axis=1)[:, None]
    cap = statics.capability(m, s, lim, D)
    np.testing.assert_allclose(cap.max, [poly.support(d) for d in D], rtol=1e-7)


def test_parallel_singularity_unresisted_moment():
    """Symmetric 3-RPR at phi = 0: the legs meet at the platform origin (MR 7.3: the
    platform turns about it with locked legs): zero moment capability, clear status."""
    m = optkin.mechanisms.rpr3(BASE_SYM, PLAT_SYM)
    s = sol_at(m, [0.0, 0.0, 0.0])
    cap = statics.capability(m, s, 1.0, ["fx", "fy", "mz", "-mz"])
    assert cap.success
    assert cap.status == "singular" and cap.singularity == "parallel"
    assert "parallel singularity" in cap.message
    assert cap.direction_status[2:] == ["unresisted", "unresisted"]
    assert cap.max[2] == 0.0 and cap.max[3] == 0.0
    np.testing.assert_allclose(np.abs(cap.unresisted[:, 0]), [0, 0, 1], atol=1e-12)
    # the in-plane forces are still resisted, as linprog on the hand map says
    G = hand_G(BASE_SYM, PLAT_SYM, (0, 0, 0))
    ref = [lp_capability(G, d, -np.ones(3), np.ones(3)) for d in np.eye(3)[:2]]
    np.testing.assert_allclose(cap.max[:2], ref, atol=1e-6)
    # a moment cannot be held, and no distribution produces it
    fz = statics.feasible(m, s, [0.0, 0.0, 0.01], 1.0)
    assert not fz.feasible and fz.status == "singular"
    d = statics.distribute(m, s, [0.0, 0.0, 0.01])
    assert not d.success and d.status == "infeasible" and "parallel singularity" in d.message
    # a redundant 4-RPR with similar squares is singular at phi = 0 for the same reason
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    m4 = optkin.mechanisms.rpr4(sq, 0.2 * (sq - 0.5))
    cap4 = statics.capability(m4, sol_at(m4, [0.45, 0.55, 0.0]), 1.0, ["mz"])
    assert cap4.status == "singular" and cap4.max[0] == 0.0


def test_serial_singularity_unbounded_along_stretched_leg():
    """Five-bar with leg 1 fully stretched (|P - A| = L1 + L2): the force along the leg
    passes through the actuated base joint and needs no torque."""
    m = optkin.mechanisms.five_bar(1.0, 1.0, 1.0, 1.0, 1.0)
    P = np.array([0.6, np.sqrt(4 - 0.36)])
    s = sol_at(m, P)
    d = P / np.linalg.norm(P)
    perp = np.array([-d[1], d[0]])
    cap = statics.capability(m, s, 1.0, [d, perp])
    assert cap.status == "singular" and "serial" in cap.singularity
    assert cap.direction_status[0] == "unbounded" and np.isinf(cap.max[0])
    assert np.isfinite(cap.max[1]) and cap.max[1] > 0
    assert not statics.polytope(m, s, 1.0).success


# ----------------------------------------------------------------------------- feasibility


def test_feasible_margin_matches_linprog():
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    pose = [1.7, 1.3, 0.1]
    s = sol_at(m, pose)
    lim = np.array([2.0, 1.0, 1.5])
    G = hand_G(BASE3, PLAT3, pose)
    for scale in (0.3, 1.0, 3.0):
        box = {"lower": [-0.2 * scale, -0.5 * scale, -0.05 * scale],
               "upper": [0.4 * scale, 0.1 * scale, 0.05 * scale]}
        r = statics.feasible(m, s, box, lim)
        V = statics.box(box["lower"], box["upper"])
        worst = max(lp_min_utilisation(G, v, lim) for v in V)
        assert r.success and r.feasible == (worst <= 1 + 1e-9)
        np.testing.assert_allclose(r.margin, 1 - worst, atol=1e-6)
        # brute force: random wrenches inside the box, tau = G^-1 w, within the limits iff
        # the margin says so (convexity)
        W = RNG.uniform(box["lower"], box["upper"], size=(200, 3))
        inside = np.all(np.abs(np.linalg.solve(G, W.T)) <= lim[:, None] + 1e-12, axis=0)
        if r.feasible:
            assert inside.all()


def test_symmetric_moment_feasibility_closed_form():
    """Pure moment box |mz| <= M on the symmetric 3-RPR: margin = 1 - M / (3 t h)."""
    m = optkin.mechanisms.rpr3(BASE_SYM, PLAT_SYM)
    phi, t, M = 0.5, 2.0, 0.3
    s = sol_at(m, [0.0, 0.0, phi])
    L = np.sqrt(R_SYM**2 + r_SYM**2 - 2 * R_SYM * r_SYM * np.cos(phi))
    h = r_SYM * R_SYM * np.sin(phi) / L
    r = statics.feasible(m, s, {"lower": [0, 0, -M], "upper": [0, 0, M]}, t)
    np.testing.assert_allclose(r.margin, 1 - M / (3 * t * h), atol=1e-6)


def test_wrench_feasible_workspace_and_pictures(tmp_path):
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    lim = np.array([2.0, 2.0, 2.0])
    wset = {"lower": [-0.5, -1.0, -0.1], "upper": [0.5, 0.0, 0.1]}
    png = tmp_path / "ws.png"
    ws = statics.wrench_feasible_workspace(m, wset, lim, grid=6, bounds=[[0.8, 3.0], [0.5, 2.5]],
                                           fixed=[0, 0, 0.1], path=str(png))
    assert ws.success and ws.grid_shape == (6, 6) and png.stat().st_size > 1000
    assert set(ws.point_status) <= {"feasible", "infeasible", "unreachable", "singular"}
    V = statics.box(wset["lower"], wset["upper"])
    for i in RNG.choice(36, 5, replace=False):
        pose = ws.poses[i]
        G = hand_G(BASE3, PLAT3, pose)
        worst = max(lp_min_utilisation(G, v, lim) for v in V)
        np.testing.assert_allclose(ws.margin[i], 1 - worst, atol=1e-6)
    png2 = tmp_path / "cap.png"
    cap = statics.capability_polygon(m, sol_at(m, [1.7, 1.3, 0.1]), lim, n=36, path=str(png2))
    assert cap.success and png2.stat().st_size > 1000 and cap.max.shape == (36,)


# ----------------------------------------------------------------------------- distribution


def test_distribute_rpr4_min_norm_closed_form_and_inf_norm_linprog():
    m = optkin.mechanisms.rpr4(BASE4, PLAT4)
    assert m.redundant and m.n_actuated == 4 and m.dof == 3
    for _ in range(3):
        pose = np.array([RNG.uniform(1.5, 2.5), RNG.uniform(1.0, 1.8), RNG.uniform(-0.3, 0.3)])
        s = sol_at(m, pose)
        G = hand_G(BASE4, PLAT4, pose)
        F = RNG.normal(size=3)
        d2 = statics.distribute(m, s, F, norm=2)
        assert d2.success and d2.residual < 1e-8
        np.testing.assert_allclose(d2.tau, np.linalg.pinv(G) @ F, atol=1e-6)
        dinf = statics.distribute(m, s, F, norm="inf")
        ref = lp_min_utilisation(G, F, np.ones(4))
        np.testing.assert_allclose(dinf.value, ref, atol=1e-7)
        np.testing.assert_allclose(G @ dinf.tau, F, atol=1e-8)


def test_distribute_rpr4_with_active_limits_null_space_closed_form():
    """tau = tau0 + alpha n with G n = 0 (one-dimensional null space): the limited 2-norm
    minimiser is the unconstrained alpha clipped to the interval the bounds allow."""
    m = optkin.mechanisms.rpr4(BASE4, PLAT4)
    pose = [2.0, 1.5, 0.15]
    s = sol_at(m, pose)
    G = hand_G(BASE4, PLAT4, pose)
    n = np.linalg.svd(G)[2][-1]
    F = np.array([1.0, 0.4, 0.2])
    tau0 = np.linalg.pinv(G) @ F
    # make one bound active: raise the lower bound of the actuator with the largest |n_i|
    i = int(np.argmax(np.abs(n)))
    lo = -5.0 * np.ones(4)
    hi = 5.0 * np.ones(4)
    if n[i] > 0:
        lo[i] = tau0[i] + 0.05 * abs(n[i])
    else:
        hi[i] = tau0[i] - 0.05 * abs(n[i])
    # feasible alpha interval from lo <= tau0 + alpha n <= hi
    a_lo, a_hi = -np.inf, np.inf
    for k in range(4):
        if abs(n[k]) > 1e-14:
            b1, b2 = (lo[k] - tau0[k]) / n[k], (hi[k] - tau0[k]) / n[k]
            a_lo, a_hi = max(a_lo, min(b1, b2)), min(a_hi, max(b1, b2))
    alpha = np.clip(0.0, a_lo, a_hi)  # tau0 is the unconstrained minimiser (alpha = 0)
    assert alpha != 0.0
    d = statics.distribute(m, s, F, limits=np.column_stack([lo, hi]), norm=2)
    assert d.success, d.message
    np.testing.assert_allclose(d.tau, tau0 + alpha * n, atol=1e-6)


def test_distribute_nonredundant_is_unique_and_infeasible_beyond_limits():
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    pose = [1.6, 1.2, 0.3]
    s = sol_at(m, pose)
    G = hand_G(BASE3, PLAT3, pose)
    F = np.array([0.3, -0.2, 0.1])
    exact = np.linalg.solve(G, F)
    for norm in (2, "inf"):
        d = statics.distribute(m, s, F, norm=norm)
        np.testing.assert_allclose(d.tau, exact, atol=1e-6)
    small = 0.5 * np.max(np.abs(exact))
    d = statics.distribute(m, s, F, limits=small)
    assert not d.success and d.status == "infeasible" and "limits" in d.message


def test_sign_convention_push_only_legs():
    """Push-only legs (tau >= 0): the platform can push along +u only. F is the wrench the
    platform APPLIES; with all legs pushing equally it points along sum u_i."""
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    pose = [1.7, 1.3, 0.1]
    s = sol_at(m, pose)
    G = hand_G(BASE3, PLAT3, pose)
    F = G @ np.array([1.0, 1.0, 1.0])
    lim = np.array([[0.0, 2.0]] * 3)
    assert statics.feasible(m, s, F, lim).feasible
    assert not statics.feasible(m, s, -F, lim).feasible
    d = statics.capability(m, s, lim, [F, -F])
    np.testing.assert_allclose(d.max, [lp_capability(G, v / np.linalg.norm(v), lim[:, 0],
                                                     lim[:, 1]) for v in (F, -F)], atol=1e-6)
    assert d.max[1] == pytest.approx(0.0, abs=1e-9)


# ----------------------------------------------------------------------------- DPP, errors


def test_problem_is_parametrised_and_reused():
    from optkin.statics import problems as pb

    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    D = np.eye(3)
    r1 = statics.capability(m, sol_at(m, [1.6, 1.2, 0.3]), 1.0, D)
    r2 = statics.capability(m, sol_at(m, [1.8, 1.1, 0.0]), 1.0, D)
    p = pb.capability_problem(3, 3, 3, 0, 3)
    assert p.problem.is_dpp() and p.nsolves >= 2
    assert r2.stats.extra["reused"] and r2.stats.setup_time == 0.0
    assert not np.allclose(r1.max, r2.max)


def test_input_errors():
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    s = sol_at(m, [1.6, 1.2, 0.3])
    with pytest.raises(StaticsError, match=r"limits: expected a number, 3 bounds or 3 pairs"):
        statics.capability(m, s, [1.0, 2.0])
    with pytest.raises(StaticsError, match=r"must be >= 0, negative for \['L2.rho'\]"):
        statics.capability(m, s, [1.0, -2.0, 1.0])
    with pytest.raises(StaticsError, match=r"must contain 0"):
        statics.capability(m, s, [[0.1, 1.0]] * 3)
    with pytest.raises(StaticsError, match=r"limits: required"):
        statics.capability(m, s, None)
    with pytest.raises(StaticsError, match=r"directions: unknown component 'fz'"):
        statics.capability(m, s, 1.0, ["fz"])
    with pytest.raises(StaticsError, match=r"non-zero"):
        statics.capability(m, s, 1.0, [[0.0, 0.0, 0.0]])
    with pytest.raises(StaticsError, match=r"wrench: expected 3 finite components"):
        statics.distribute(m, s, [1.0, 2.0])
    with pytest.raises(StaticsError, match=r"norm: expected 2 or 'inf'"):
        statics.distribute(m, s, [1.0, 2.0, 0.0], norm=1)
    with pytest.raises(StaticsError, match=r"wrench_set: expected a wrench"):
        statics.feasible(m, s, [[1.0, 2.0]], 1.0)
    with pytest.raises(MechanismError, match=r"q: expected 9 finite joint values"):
        statics.capability(m, [0.0, 1.0], 1.0)


# ----------------------------------------------------------------------------- redundancy


def test_redundant_mechanism_forward_inverse_and_validation():
    m = optkin.mechanisms.rpr4(BASE4, PLAT4)
    pose = [2.1, 1.4, -0.25]
    s = sol_at(m, pose)
    np.testing.assert_allclose(s.qa, leg_lengths(BASE4, PLAT4, pose), atol=1e-12)
    f = optkin.forward(m, s.qa, guess=[2.0, 1.5, -0.2])
    assert f.success, f.message
    np.testing.assert_allclose(f.x, pose, atol=1e-9)
    fi = optkin.forward(m, s.qa, guess=[2.0, 1.5, -0.2], method="ipopt")
    assert fi.success and np.allclose(fi.x, pose, atol=1e-9)
    bad = optkin.forward(m, s.qa + [0, 0, 0, 0.2], guess=[2.0, 1.5, -0.2])
    assert not bad.success and bad.status != "optimal"
    legs = [{"type": "RPR", "base": a, "platform": b} for a, b in zip(BASE4, PLAT4)]
    with pytest.raises(MechanismError, match=r"pass redundant=True"):
        optkin.Mechanism.from_legs(legs, "planar")
    with pytest.raises(MechanismError, match=r"needs more than 3 actuated legs, got 3"):
        optkin.Mechanism.from_legs(legs[:3], "planar", redundant=True)
    # the non-redundant mechanisms keep their content keys
    import pickle

    assert pickle.loads(pickle.dumps(m)).key == m.key
    assert optkin.mechanisms.rpr3(BASE3, PLAT3).redundant is False


# ----------------------------------------------------------------------------- problem files


def _statics_doc(**task):
    return {
        "schema_version": 1,
        "mechanism": {"type": "library", "name": "rpr3",
                      "args": {"base": BASE3.tolist(), "platform": PLAT3.tolist()}},
        "task": [{"kind": "statics", **task}],
    }


def test_problem_file_statics_task_validation():
    from optkin.errors import ProblemFileError
    from optkin.problems.schema import validate_document

    ok = validate_document(_statics_doc(pose=[1.6, 1.2, 0.3], limits=[1.0, 2.0, 1.0],
                                        directions=["fx", "-mz", [1.0, 1.0, 0.0]]), "s.toml")
    assert ok.task[0].analysis == "capability"
    with pytest.raises(ProblemFileError, match=r"s.toml: task\[0\].limits: required"):
        validate_document(_statics_doc(pose=[1.6, 1.2, 0.3]), "s.toml")
    with pytest.raises(ProblemFileError, match=r"s.toml: task\[0\].q: give exactly one of q, qa"):
        validate_document(_statics_doc(limits=1.0), "s.toml")
    with pytest.raises(ProblemFileError, match=r"task\[0\].wrench: required for analysis = 'distribute'"):
        validate_document(_statics_doc(analysis="distribute", qa=[1.0, 2.0, 2.0]), "s.toml")
    with pytest.raises(ProblemFileError, match=r"task\[0\].wrench_upper: a wrench box needs"):
        validate_document(_statics_doc(analysis="feasible", pose=[1.6, 1.2, 0.3], limits=1.0,
                                       wrench_lower=[0.0, 0.0, 0.0]), "s.toml")
    with pytest.raises(ProblemFileError, match=r"task\[0\].directions\[1\]: expected a component name"):
        validate_document(_statics_doc(pose=[1.6, 1.2, 0.3], limits=1.0,
                                       directions=["fx", "torque"]), "s.toml")


# ----------------------------------------------------------------------------- more checks


def test_delta_virtual_work_by_forward_finite_differences():
    """Delta (translational, RUS legs): tau . dqa = F . dp with dp from the direct model."""
    m = optkin.mechanisms.delta()
    s = sol_at(m, [0.03, -0.02, -0.75])
    sm = statics.static_model(m, s)
    assert sm.wrench_names == ("fx", "fy", "fz") and sm.singularity == "none"
    tau = np.array([0.7, -0.2, 0.4])
    F = sm.wrench(tau)
    h = 1e-6
    for _ in range(3):
        dqa = RNG.normal(size=3)
        p1 = optkin.forward(m, s.qa + h * dqa, guess=s).pose[:3, 3]
        p0 = optkin.forward(m, s.qa - h * dqa, guess=s).pose[:3, 3]
        dp = (p1 - p0) / (2 * h)
        assert abs(tau @ dqa - F @ dp) < 1e-6 * (1 + abs(tau @ dqa))


def test_static_model_consistent_with_optkin_jacobians():
    """Cross-check with the velocity model of optkin.analysis (another implementation)."""
    ang = np.deg2rad([0, 60, 120, 180, 240, 300])
    base = np.column_stack([np.cos(ang + 0.2), np.sin(ang + 0.2), np.zeros(6)])
    plat = 0.4 * np.column_stack([np.cos(ang - 0.5), np.sin(ang - 0.5), np.zeros(6)])
    m = optkin.mechanisms.stewart_gough(base, plat)
    s = sol_at(m, [0.02, 0.01, 0.8, 0.05, 0.1, -0.1])
    jac = optkin.jacobians(m, s)
    sm = statics.static_model(m, s)
    np.testing.assert_allclose(sm.A, jac.A, atol=1e-12)
    np.testing.assert_allclose(sm.B, jac.B, atol=1e-12)
    m6 = optkin.mechanisms.sr400()
    r6 = optkin.forward(m6, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    np.testing.assert_allclose(statics.static_model(m6, r6).J, optkin.jacobians(m6, r6).J_task,
                               atol=1e-10)


@pytest.mark.parametrize("which", ["rpr3", "stewart_gough", "delta"])
def test_chain_form_gives_the_reduced_form_static_map(which):
    """Legs in their chain form (reduced=False) take the augmented static model (task rows
    over the joint-level closure); it gives the map of the reduced A/B form."""
    if which == "rpr3":
        ref, pose = optkin.mechanisms.rpr3(BASE3, PLAT3), [1.6, 1.2, 0.3]
    elif which == "stewart_gough":
        ang = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([-10, 10] * 3)
        base = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(6)])
        pang = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([25, -25] * 3)
        plat = 0.5 * np.column_stack([np.cos(pang), np.sin(pang), np.zeros(6)])
        ref, pose = optkin.mechanisms.stewart_gough(base, plat), [0.05, -0.03, 0.9, 0.1, -0.05, 0.2]
    else:
        ref, pose = optkin.mechanisms.delta(), [0.05, 0.02, -0.7]
    spec = ref.to_dict()
    chain = optkin.Mechanism.from_legs(spec["legs"], spec["platform"], reduced=False)
    a = sol_at(ref, pose)
    b = min(optkin.inverse(chain, pose),
            key=lambda s: np.abs(np.angle(np.exp(1j * (s.qa - a.qa)))).max())
    sa, sb = statics.static_model(ref, a), statics.static_model(chain, b)
    assert sb.P.shape[1] > 0 and sa.P.shape[1] == 0
    assert sa.singularity == sb.singularity == "none"
    np.testing.assert_allclose(sb.G, sa.G, atol=1e-9)
    np.testing.assert_allclose(sb.J, sa.J, atol=1e-9)


@pytest.mark.parametrize("name", ["optkin.statics.core", "optkin.statics.model"])
def test_statics_docstring_examples(name):
    import doctest
    import importlib

    failures, tried = doctest.testmod(importlib.import_module(name),
                                      optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


def test_rrr3_virtual_work_with_hand_written_inverse():
    """3-RRR (actuated base revolutes): tau . dtheta = F . dx, the crank angles of each
    working mode by the law of cosines written here."""
    base = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]])
    plat = np.array([[-0.1, -0.05], [0.1, -0.05], [0.0, 0.1]])
    l1 = l2 = 0.5
    m = optkin.mechanisms.rrr3(base, plat, l1, l2)

    def cranks(pose, signs):
        x, y, phi = pose
        out = []
        for a, b, sg in zip(base, plat, signs):
            d = np.array([x, y]) + rot(phi) @ b - a
            L = np.hypot(*d)
            out.append(np.arctan2(d[1], d[0]) + sg * np.arccos((L * L + l1 * l1 - l2 * l2)
                                                               / (2 * L * l1)))
        return np.array(out)

    pose = np.array([0.5, 0.35, 0.1])
    for s in optkin.inverse(m, pose)[:4]:
        signs = [1 if p == 0 else -1 for p in s.posture]  # posture 0: +beta (leg_inverse)
        np.testing.assert_allclose(np.cos(cranks(pose, signs) - s.qa), 1.0, atol=1e-12)
        sm = statics.static_model(m, s)
        tau = RNG.normal(size=3)
        F = sm.wrench(tau)
        for _ in range(2):
            dx = RNG.normal(size=3)
            h = 1e-6
            dth = (cranks(pose + h * dx, signs) - cranks(pose - h * dx, signs)) / (2 * h)
            assert abs(tau @ dth - F @ dx) < 1e-6 * (1 + abs(F @ dx))


def test_capability_many_matches_pose_by_pose():
    """The batched LP (chunks of poses, last chunk padded) gives the per-pose results,
    singular poses included."""
    m = optkin.mechanisms.rpr3(BASE_SYM, PLAT_SYM)
    poses = [[0.0, 0.0, 0.4], [0.05, -0.02, 0.2], [0.0, 0.0, 0.0], [0.1, 0.1, -0.3],
             [-0.05, 0.0, 0.7]]
    sols = [sol_at(m, p) for p in poses]
    many = statics.capability_many(m, sols, [1.0, 2.0, 1.5], ["fx", "fy", "mz"], chunk=2)
    assert len(many) == 5
    for s, r in zip(sols, many):
        one = statics.capability(m, s, [1.0, 2.0, 1.5], ["fx", "fy", "mz"])
        assert r.status == one.status and r.direction_status == one.direction_status
        np.testing.assert_allclose(r.max, one.max, atol=1e-9)
    assert many[2].status == "singular" and many[2].max[2] == 0.0


def test_workspace_marks_singular_poses():
    """Homothetic 3-RPR at phi = 0: the legs always meet (at the centre of homothety), so
    no wrench with a moment about that point is resisted; margins equal feasible()."""
    m = optkin.mechanisms.rpr3(BASE_SYM, PLAT_SYM)
    b = [[-0.2, 0.2], [-0.2, 0.2]]
    ws = statics.wrench_feasible_workspace(m, {"lower": [0, 0, -0.01], "upper": [0, 0, 0.01]},
                                           1.0, grid=3, bounds=b, fixed=[0, 0, 0])
    assert ws.point_status == ["singular"] * 9 and np.all(ws.margin == -np.inf)
    forces = {"lower": [-0.3, -0.3, 0.0], "upper": [0.3, 0.3, 0.0]}
    ws = statics.wrench_feasible_workspace(m, forces, 1.0, grid=3, bounds=b, fixed=[0, 0, 0])
    # only at the centre do the legs meet at the platform origin, where a pure force has no
    # moment about the meeting point; elsewhere it has one and is not resisted
    assert ws.point_status == ["singular"] * 4 + ["feasible"] + ["singular"] * 4
    for pose, mu in zip(ws.poses, ws.margin):
        one = statics.feasible(m, sol_at(m, pose), forces, 1.0)
        np.testing.assert_allclose(mu, one.margin, atol=1e-7)


def test_no_solver_banner_in_library_use():
    """HiGHS prints a copyright banner on stdout at its first instance in a process; a
    statics call from Python prints nothing (a notebook cell shows only what it asked)."""
    import subprocess
    import sys

    code = ("import optkin\n"
            "from optkin import statics\n"
            "m = optkin.mechanisms.rpr3([[0, 0], [4, 0], [0, 3]], [[-0.5, -0.3], [0.5, -0.3],"
            " [0, 0.4]])\n"
            "r = optkin.inverse(m, [1.6, 1.2, 0.3])[0]\n"
            "cap = statics.capability(m, r, 1.0, ['fx', '-fx'])\n"
            "assert cap.success and cap.stats.solver == 'HIGHS'\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout == "" and "HiGHS" not in p.stderr, p.stdout + p.stderr
