"""Velocity and acceleration models (optkin.jacobians) against independent references.

References: central finite differences of the solved forward map (optkin.forward with a warm
guess), second-order differences for the acceleration term [7.52], the closed forms of
Examples 7.7 (SR400) and 7.8 (AKR-3000) of Khalil & Dombre 2002, leg formulas of Chablat-Wenger's A and
B written here, and Modern Robotics' Stewart-Gough statics checked against leg lengths
differentiated along a screw motion.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

import optkin
from optkin import mechanisms as M
from optkin.mechanism.geometry import rpy_to_matrix, wrap_angle

RNG = np.random.default_rng(2024)
H = 1e-5  # finite-difference step

RPR_BASE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]])
RPR_PLAT = np.array([[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
_ab = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([10, -10] * 3)
_ap = np.deg2rad([30, 90, 150, 210, 270, 330]) + np.deg2rad([-15, 15] * 3)
SG_BASE = np.c_[np.cos(_ab), np.sin(_ab), np.zeros(6)]
SG_PLAT = 0.5 * np.c_[np.cos(_ap), np.sin(_ap), np.zeros(6)]


def _platform_configs(m, poses):
    out = []
    for pose in poses:
        sols = optkin.inverse(m, pose)
        if len(sols):
            out.append(sols[RNG.integers(len(sols))])
    return out


def _regular(m, draw, attempts: int = 50):
    """A configuration at actuated values ``draw()`` whose W_p is well conditioned (smallest
    singular value above 1e-2 of the largest): near a singular one (the SR400's
    parallelogram nearly flat, at theta5 ~ 0) the passive joints are known only to
    cond(W_p) times the closure's rounding, 1e-11 there, which second differences at
    h = 5e-4 turn into 1e-4 (seen: 9 of 60 random rates failed the 1e-5 tolerance)."""
    for _ in range(attempts):
        r = optkin.forward(m, draw(), tol=1e-13)
        if r.success:
            s = np.linalg.svd(optkin.jacobians(m, r).W_p, compute_uv=False)
            if s[-1] > 1e-2 * s[0]:
                return r
    raise AssertionError(f"{m.name}: no well-conditioned configuration in {attempts} draws")


def _akr_configuration(m, rng):
    """A closed AKR-3000 configuration from the numpy tree: the cylinder lengths are the
    distances between the ends they join (frames 3 -> 13 and 4 -> 14)."""
    table = m.table
    q = {n: 0.0 for n in m.joint_names}
    q.update(theta1=rng.uniform(-1, 1), theta2=rng.uniform(0.6, 1.6),
             theta7=rng.uniform(-1.6, -0.6), theta8=rng.uniform(-1, 1),
             theta9=rng.uniform(-1, 1), theta10=rng.uniform(-1, 1))
    O = {j: table.transform_0(j, q)[:3, 3] for j in (3, 4, 13, 14)}
    q["r5"] = float(np.linalg.norm(O[13] - O[3]))
    q["r6"] = float(np.linalg.norm(O[14] - O[4]))
    qa = [q[n] for n in m.active_names]
    r = optkin.forward(m, qa, guess=np.array([q[n] for n in m.joint_names]), tol=1e-13)
    assert r.success, r.message
    return r


def _cases():
    """(mechanism, list of closed configurations) for every library mechanism."""
    cases = []
    m = M.rpr3(RPR_BASE, RPR_PLAT)
    cases.append(("rpr3", m, _platform_configs(
        m, [[0.5 + RNG.uniform(-.1, .1), 0.4 + RNG.uniform(-.1, .1), RNG.uniform(-.3, .3)]
            for _ in range(3)])))
    m = M.rpr4([[0, 0], [1, 0], [1, 1], [0, 1]], [[-.1, -.1], [.1, -.1], [.1, .1], [-.1, .1]]) \
        if hasattr(M, "rpr4") else None
    if m is not None:
        cases.append(("rpr4", m, _platform_configs(m, [[0.5, 0.45, 0.1], [0.45, 0.55, -0.2]])))
    m = M.rrr3(RPR_BASE, RPR_PLAT, 0.45, 0.45)
    cases.append(("rrr3", m, _platform_configs(
        m, [[0.5 + RNG.uniform(-.05, .05), 0.4 + RNG.uniform(-.05, .05), RNG.uniform(-.2, .2)]
            for _ in range(3)])))
    m = M.five_bar(1.0, 1.0, 1.0, 1.0, 1.0)
    cases.append(("five_bar", m, _platform_configs(
        m, [[RNG.uniform(0.3, 0.7), RNG.uniform(0.8, 1.3)] for _ in range(3)])))
    m = M.stewart_gough(SG_BASE, SG_PLAT)
    cases.append(("stewart_gough", m, _platform_configs(
        m, [np.r_[RNG.uniform(-.1, .1, 2), RNG.uniform(.8, 1.2), RNG.uniform(-.2, .2, 3)]
            for _ in range(3)])))
    m = M.delta(0.2, 0.05, 0.3, 0.8)
    cases.append(("delta", m, _platform_configs(
        m, [np.r_[RNG.uniform(-.1, .1, 2), RNG.uniform(-.85, -.6)] for _ in range(3)])))
    m = M.four_bar(1.0, 2.0, 2.0, 2.5)
    cases.append(("four_bar", m, [optkin.forward(m, [t], tol=1e-13) for t in (0.3, 1.0, 2.5)]))
    m = M.sr400()
    cases.append(("sr400", m, [_regular(m, lambda: RNG.uniform(-0.5, 0.5, 6))
                               for _ in range(3)]))
    m = M.akr3000()
    cases.append(("akr3000", m, [_akr_configuration(m, RNG) for _ in range(3)]))
    return cases


CASES = _cases()


def _active_rates(mech, jac):
    """Random active rates; for a redundantly actuated platform, compatible ones
    (qdot_a = -B^-1 A t for a random twist t)."""
    if getattr(mech, "redundant", False):
        t = RNG.normal(size=jac.A.shape[1])
        return np.linalg.solve(jac.B, -jac.A @ t)
    return RNG.normal(size=jac.qa.size)


def _rot_vee(Rp, Rm, R, h):
    """omega from (R(+h) - R(-h)) / 2h = [omega] R."""
    S = (Rp - Rm) / (2 * h) @ R.T
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def _redundant_check(mech, r, jac):
    """Redundant actuation: move the platform along x(t) = x + t xd and get compatible leg
    lengths from the inverse model (closed form), then difference those."""
    xd = RNG.normal(size=jac.x.size)
    h = 1e-4

    def qa_at(t):
        x = r.x + t * xd
        pose = [x[0], x[1], x[2]]
        return optkin.inverse(mech, pose).closest_to(r.q).qa

    qp, q0, qm = qa_at(h), r.qa, qa_at(-h)
    qp2, qm2 = qa_at(2 * h), qa_at(-2 * h)
    qad = (8 * (qp - qm) - (qp2 - qm2)) / (12 * h)
    qadd = (-qp2 + 16 * qp - 30 * q0 + 16 * qm - qm2) / (12 * h**2)
    assert _rel(jac.x_rates(qad), xd) < 1e-6
    # x'' = 0 along the straight line: [7.52] must give zero passive acceleration
    assert np.max(np.abs(jac.passive_accelerations(qad, qadd))) < 1e-5


@pytest.mark.parametrize("name,mech,configs", CASES, ids=[c[0] for c in CASES])
def test_rates_match_finite_differences_of_the_forward_map(name, mech, configs):
    assert configs, f"{name}: no configuration"
    for r in configs:
        assert r.success
        jac = optkin.jacobians(mech, r)
        assert jac.success, jac.message
        if getattr(mech, "redundant", False):
            _redundant_check(mech, r, jac)
            continue
        qad = RNG.normal(size=r.qa.size)
        rp = optkin.forward(mech, r.qa + H * qad, guess=r, tol=1e-13)
        rm = optkin.forward(mech, r.qa - H * qad, guess=r, tol=1e-13)
        assert rp.success and rm.success
        # passive (model unknowns) and all joint rates
        fd_x = (rp.x - rm.x) / (2 * H)
        assert _rel(jac.x_rates(qad), fd_x) < 1e-6, name
        fd_q = wrap_angle(rp.q - rm.q) / (2 * H)
        fd_q[~np.array(mech.revolute)] = ((rp.q - rm.q) / (2 * H))[~np.array(mech.revolute)]
        assert _rel(jac.joint_rates(qad), fd_q) < 1e-6, name
        # end-effector twist (v, omega) in base coordinates
        v = (rp.pose[:3, 3] - rm.pose[:3, 3]) / (2 * H)
        w = _rot_vee(rp.pose[:3, :3], rm.pose[:3, :3], r.pose[:3, :3], H)
        tw = np.r_[v, w]
        rows = {"vx": 0, "vy": 1, "vz": 2, "wx": 3, "wy": 4, "wz": 5}
        fd_t = tw[[rows[n] for n in jac.twist_names]]
        assert _rel(jac.twist(qad), fd_t) < 1e-6, name
        # MR spatial twist: v_s = v - omega x p
        fd_s = np.r_[w, v - np.cross(w, r.pose[:3, 3])]
        assert _rel(jac.J_s @ qad, fd_s) < 1e-6, name
        if mech.kind == "legs":
            # Chablat-Wenger: A t + B qdot_a = 0 with the differenced twist
            assert np.max(np.abs(jac.A @ fd_t + jac.B @ qad)) < 1e-6 * max(
                1.0, float(np.abs(jac.B @ qad).max()))
            assert np.allclose(jac.B, np.diag(np.diag(jac.B)))  # B is diagonal
        # [7.51] for Khalil mechanisms: W gives the tree's passive joints
        if mech.kind == "khalil":
            ip = [mech.joint_names.index(n) for n in mech.passive_names]
            assert _rel(jac.passive_rates(qad), fd_q[ip]) < 1e-6
            ic = [mech.joint_names.index(n) for n in mech.cut_names]
            # bottom block row of [7.49]: W_c qdot_c = -(W_ac qdot_a + W_pc qdot_p)
            lhs = jac.W_c @ fd_q[ic]
            rhs = -(jac.W_ac @ qad + jac.W_pc @ fd_q[ip])
            assert np.allclose(lhs, rhs, atol=1e-6)
            assert np.allclose(jac.W_a @ qad + jac.W_p @ fd_q[ip], 0, atol=1e-6)


def _second_difference(mech, r, qad, h):
    """x'' along qa(t) = qa + t qad by a Richardson-extrapolated second difference."""
    # the centre to the same tolerance as the sides: r (solved at the default 1e-10) may be
    # 1e-11 off, which the division by h^2 makes 1e-4 (seen on the SR400 in one cold run)
    r0 = optkin.forward(mech, r.qa, guess=r, tol=1e-14)
    assert r0.success

    def d2(h):
        rp = optkin.forward(mech, r.qa + h * qad, guess=r0, tol=1e-14)
        rm = optkin.forward(mech, r.qa - h * qad, guess=r0, tol=1e-14)
        assert rp.success and rm.success
        return (rp.x - 2 * r0.x + rm.x) / h**2, rp, rm

    D1, rp, rm = d2(h)
    D2, rp2, rm2 = d2(h / 2)
    return (4 * D2 - D1) / 3, (rp, rm, rp2, rm2)


@pytest.mark.parametrize("name,mech,configs", CASES, ids=[c[0] for c in CASES])
def test_acceleration_term_matches_second_differences(name, mech, configs):
    r = configs[0]
    jac = optkin.jacobians(mech, r)
    if getattr(mech, "redundant", False):
        _redundant_check(mech, r, jac)
        return
    qad = RNG.normal(size=r.qa.size)
    h = 5e-4
    # qa(t) = qa + t qad (zero active acceleration): x'' = -W_p^-1 (Jdot qdot) by [7.52]
    fd_xdd, (rp, rm, rp2, rm2) = _second_difference(mech, r, qad, h)
    xdd = jac.passive_accelerations(qad, np.zeros_like(qad))
    assert _rel(xdd, fd_xdd) < 1e-5, name
    if mech.kind == "khalil":
        # (Psi, Phi) = dJ/dt qdot: difference the constraint matrix along the motion
        def dJ(a, b, step):
            return (optkin.jacobians(mech, a).J - optkin.jacobians(mech, b).J) / (2 * step)

        qd = jac.joint_rates(qad)
        order = np.r_[[mech.joint_names.index(n) for n in mech.active_names],
                      [mech.joint_names.index(n) for n in mech.passive_names],
                      [mech.joint_names.index(n) for n in mech.cut_names]]
        fd = (4 * dJ(rp2, rm2, h / 2) - dJ(rp, rm, h)) / 3 @ qd[order]
        psi, phi = jac.accel_term(qad)
        assert _rel(np.r_[psi, phi], fd) < 1e-5, name
        # and [7.52] itself: J qddot + (Psi, Phi) = 0 for the differenced accelerations
        qdd = np.zeros(len(mech.joint_names))
        act = np.array(mech.actuated)
        qdd[~act] = fd_xdd
        assert np.allclose(jac.J @ qdd[order] + np.r_[psi, phi], 0, atol=1e-4)


def test_sr400_example_7_7():
    """Example 7.7: theta3' = -theta2' + theta7', theta8' = theta2' - theta7',
    theta9' = -theta2' + theta7', whatever the configuration; checked at well-conditioned
    ones (near the parallelogram's flat posture the rates computed are off by far more
    than eps cond(W_p): 1.6e-8 at cond 3e3 in one of 300 draws, 58 eps cond(H_p)..5800
    eps cond(H_p) in the worst four, so a draw there failed the bound below)."""
    m = M.sr400()
    for _ in range(3):
        r = _regular(m, lambda: RNG.uniform(-0.5, 0.5, 6))
        jac = optkin.jacobians(m, r)
        qad = RNG.normal(size=6)
        t = dict(zip(m.active_names, qad))
        qd = dict(zip(m.joint_names, jac.joint_rates(qad)))
        # the passive rates solve W_p qp' = -W_a qa': a backward-stable solve is exact to
        # about eps cond(W_p) |qa'| (cond reaches ~1e3 at some draws), never looser than 1e-12
        tol = max(1e-12, 64 * np.finfo(float).eps * np.linalg.cond(jac.W_p)
                  * (1 + np.abs(qad).max()))
        assert abs(qd["theta3"] - (-t["theta2"] + t["theta7"])) < tol
        assert abs(qd["theta8"] - (t["theta2"] - t["theta7"])) < tol
        assert abs(qd["theta9"] - (-t["theta2"] + t["theta7"])) < tol
        assert m.passive_names == ("theta3", "theta8")
        ia = m.active_names.index
        W_ref = np.zeros((2, 6))
        W_ref[0, ia("theta2")], W_ref[0, ia("theta7")] = -1, 1
        W_ref[1, ia("theta2")], W_ref[1, ia("theta7")] = 1, -1
        np.testing.assert_allclose(jac.W, W_ref, atol=tol)
        assert jac.W_p.shape == (2, 2) and jac.W_c.shape == (1, 1)


def _in_rowspace(Hm, e):
    c = np.linalg.lstsq(Hm.T, e, rcond=None)[0]
    return float(np.linalg.norm(Hm.T @ c - e) / np.linalg.norm(e))


def test_akr3000_example_7_8_both_projections():
    """The six non-trivial equations of Example 7.8, in the root frame (i) and in the
    terminal frames (ii), span the same space as the model's constraint rows.

    Two printed coefficients are corrected here, each by the structure of its companion
    equation: in (i) loop 1, the theta2 coefficient of the first row is
    d7 S2 + d13 S(alpha) (the d13 lever turns with theta2 and theta7 alike, as the
    theta7 term d13 S(alpha) and the second row -(d7 C2 + d13 C(alpha)) show; the seed
    prints d7 S2 - d13 S(alpha)); in (ii) loop 2 the d14 theta2' term belongs to the second
    row with a minus sign, as d13 in loop 1 (ii) (the seed prints +d14 theta2' in the first).
    """
    m = M.akr3000()
    P = m.params
    d7, d13, d14, g13, g14 = (P[k] for k in ("d7", "d13", "d14", "g13", "g14"))
    C, S = np.cos, np.sin
    idx = {n: i for i, n in enumerate(m.joint_names)}

    def row(**c):
        e = np.zeros(len(m.joint_names))
        for k, v in c.items():
            e[idx[k]] = v
        return e

    for _ in range(3):
        r = _akr_configuration(m, RNG)
        jac = optkin.jacobians(m, r)
        q = dict(zip(m.joint_names, r.q))
        t2, t3, t4, t7, t11, t12, r5, r6 = (q[k] for k in (
            "theta2", "theta3", "theta4", "theta7", "theta11", "theta12", "r5", "r6"))
        al = g13 + t2 + t7
        E_i = [
            row(theta3=-r5 * C(t3), r5=-S(t3), theta2=d7 * S(t2) + d13 * S(al),
                theta7=d13 * S(al)),
            row(theta3=-r5 * S(t3), r5=C(t3), theta2=-(d7 * C(t2) + d13 * C(al)),
                theta7=-d13 * C(al)),
            row(theta3=-1, theta11=-1, theta2=1, theta7=1),
            row(theta4=-r6 * C(t4), r6=-S(t4), theta2=d14 * S(g14 + t2)),
            row(theta4=-r6 * S(t4), r6=C(t4), theta2=-d14 * C(g14 + t2)),
            row(theta4=-1, theta12=-1, theta2=1),
        ]
        E_ii = [
            row(theta3=-r5 * C(t11), r5=S(t11), theta2=-d7 * S(g13 + t7)),
            row(theta3=r5 * S(t11), r5=C(t11), theta2=-(d13 + d7 * C(g13 + t7)),
                theta7=-d13),
            row(theta3=-1, theta11=-1, theta2=1, theta7=1),
            row(theta4=-r6 * C(t12), r6=S(t12)),
            row(theta4=r6 * S(t12), r6=C(t12), theta2=-d14),
            row(theta4=-1, theta12=-1, theta2=1),
        ]
        for E in (E_i, E_ii):
            E = np.array(E)
            assert np.linalg.matrix_rank(E) == 6
            for e in E:
                assert _in_rowspace(jac.H, e) < 1e-12
            # and conversely: the model's rows are combinations of the book's
            for h in jac.H:
                assert _in_rowspace(E, h) < 1e-12
        # the [7.49] blocks have the dimensions of Example 7.8
        assert jac.W_a.shape == (4, 6) and jac.W_p.shape == (4, 4)
        assert jac.W_ac.shape == (2, 6) and jac.W_pc.shape == (2, 4) and jac.W_c.shape == (2, 2)
        assert jac.qp_names == ("theta2", "theta3", "theta4", "theta7")
        assert jac.qc_names == ("theta11", "theta12")


def test_rpr3_A_and_B_by_hand():
    """3-RPR: f_i = |p + R b_i - a_i| - rho_i, so with n_i the unit leg vector,
    A_i = [n_i^T, n_i . (E R b_i)] (E = rotation by 90 deg) and B = -I."""
    m = M.rpr3(RPR_BASE, RPR_PLAT)
    for r in CASES[0][2]:
        jac = optkin.jacobians(m, r)
        x, y, phi = r.x
        R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
        E = np.array([[0.0, -1.0], [1.0, 0.0]])
        A = []
        for a, b in zip(RPR_BASE, RPR_PLAT):
            d = np.array([x, y]) + R @ b - a
            n = d / np.linalg.norm(d)
            A.append([n[0], n[1], n @ (E @ R @ b)])
        np.testing.assert_allclose(jac.A, A, atol=1e-12)
        np.testing.assert_allclose(jac.B, -np.eye(3), atol=1e-12)


def test_five_bar_A_and_B_by_hand():
    """Five-bar: f_i = |P - C_i(theta_i)| - l_i; A_i = (P - C_i)^T / l_i,
    B_ii = -(P - C_i) . C_i'(theta_i) / l_i with C_i' = L (-sin, cos)."""
    L0, L1, L2, L3, L4 = 1.0, 0.8, 1.1, 1.0, 0.9
    m = M.five_bar(L0, L1, L2, L3, L4)
    for P in ([0.4, 1.1], [0.7, 0.9], [0.2, 1.3]):
        for s in optkin.inverse(m, P):
            jac = optkin.jacobians(m, s)
            t1, t2 = s.qa
            Pv = np.asarray(P)
            C1 = L1 * np.array([np.cos(t1), np.sin(t1)])
            C2 = np.array([L0, 0]) + L4 * np.array([np.cos(t2), np.sin(t2)])
            A = np.array([(Pv - C1) / L2, (Pv - C2) / L3])
            B = np.diag([-(Pv - C1) @ (L1 * np.array([-np.sin(t1), np.cos(t1)])) / L2,
                         -(Pv - C2) @ (L4 * np.array([-np.sin(t2), np.cos(t2)])) / L3])
            np.testing.assert_allclose(jac.A, A, atol=1e-12)
            np.testing.assert_allclose(jac.B, B, atol=1e-12)
            # working mode = signs of diag(B) (Chablat & Wenger 1998) as reported by inverse
            assert tuple(int(v) for v in np.sign(np.diag(jac.B))) == s.working_mode


def test_stewart_gough_statics_matches_leg_rates_along_a_screw():
    """MR 7.2.1: qdot_a = J_s^-1 V_s with rows (-n_i x q_i, n_i). Leg lengths differentiated
    along the screw motion T(t) = exp([V_s] t) T0 (computed here) must agree, and so must
    the inverse of the AD twist Jacobian J_s."""
    m = M.stewart_gough(SG_BASE, SG_PLAT)
    for r in CASES[4][2]:
        jac = optkin.jacobians(m, r)
        G = jac.G_statics
        np.testing.assert_allclose(G @ jac.J_s, np.eye(6), atol=1e-9)
        Vs = RNG.normal(size=6)
        w, v = Vs[:3], Vs[3:]
        X = np.zeros((4, 4))
        X[:3, :3] = [[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]]
        X[:3, 3] = v

        def legs(t, r=r, X=X):
            T = expm(X * t) @ r.pose
            return np.linalg.norm(T[:3, 3] + SG_PLAT @ T[:3, :3].T - SG_BASE, axis=1)

        fd = (legs(H) - legs(-H)) / (2 * H)
        np.testing.assert_allclose(G @ Vs, fd, rtol=1e-7, atol=1e-8)
        # A t + B qdot = 0 with t = (v, omega) of the platform origin
        qad = G @ Vs
        t = np.r_[v + np.cross(w, r.pose[:3, 3]), w]
        assert np.allclose(jac.A @ t + jac.B @ qad, 0, atol=1e-9)


def test_rpy_pose_helper_consistency():
    # guard for the test's own fixtures: the Stewart-Gough poses close with RPY angles
    m = M.stewart_gough(SG_BASE, SG_PLAT)
    pose = [0.02, -0.01, 1.0, 0.1, -0.05, 0.2]
    s = optkin.inverse(m, pose)[0]
    np.testing.assert_allclose(s.pose[:3, :3], rpy_to_matrix(*pose[3:]), atol=1e-12)


def test_jacobians_input_errors_and_non_closed_configuration():
    m = M.four_bar(1.0, 2.0, 2.0, 2.5)
    with pytest.raises(optkin.MechanismError, match=r"q: expected all 4 joint values"):
        optkin.jacobians(m, [0.1, 0.2])
    jac = optkin.jacobians(m, [0.1, 0.2, 0.3, 0.4])
    assert not jac.success and "does not close" in jac.message


def test_functions_are_built_once_per_mechanism():
    from optkin.analysis._functions import analysis_functions

    m = M.four_bar(1.0, 2.0, 2.0, 2.5)
    f1 = analysis_functions(m)
    optkin.jacobians(m, optkin.forward(m, [0.5]))
    assert analysis_functions(M.four_bar(1.0, 2.0, 2.0, 2.5)) is f1


@pytest.mark.parametrize("name", ["optkin.analysis.velocity", "optkin.analysis.mobility",
                                  "optkin.analysis.singularity", "optkin.analysis.maps"])
def test_docstring_examples_of_the_analyses(name):
    import doctest
    import importlib

    failures, tried = doctest.testmod(importlib.import_module(name),
                                      optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


def test_accel_term_from_all_joint_rates_equals_from_active_rates():
    m = M.akr3000()
    r = CASES[-1][2][0]
    jac = optkin.jacobians(m, r)
    qad = RNG.normal(size=6)
    a1 = np.r_[jac.accel_term(qad)]
    a2 = np.r_[jac.accel_term(qdot=jac.joint_rates(qad))]
    np.testing.assert_allclose(a1, a2, atol=1e-12)
