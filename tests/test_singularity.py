"""Degrees of freedom and singularity classification on configurations built by geometry.

Every expected verdict is derived here from the geometry of the configuration (collinear
joints, concurrent or parallel leg lines, coincident joints), never from the code's output:
Modern Robotics 7.3 (four-bar bifurcations, five-bar Figs. 7.7-7.9), MR 7.1 / Chablat & Wenger 1998
(3-RPR parallel singularities), Khalil & Dombre 2002 [7.57]-[7.59] and the Bennett linkage.
"""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin import mechanisms as M

RNG = np.random.default_rng(11)


def _cross(a, b):
    return float(a[0] * b[1] - a[1] * b[0])


def _collinear(*pts, tol=1e-9):
    p0 = np.asarray(pts[0])
    for i in range(1, len(pts)):
        for j in range(i + 1, len(pts)):
            if abs(_cross(np.asarray(pts[i]) - p0, np.asarray(pts[j]) - p0)) > tol:
                return False
    return True


# ------------------------------------------------------------------ five-bar (MR 7.3)
def _five_bar_q(L, t1, t2, P):
    """All joints of the five-bar legs (base, elbow, distal-to-point) for actuated angles
    t1, t2 and end point P (built from the geometry, not by a solver)."""
    L0, L1, L2, L3, L4 = L
    C = L1 * np.array([np.cos(t1), np.sin(t1)])
    D = np.array([L0, 0.0]) + L4 * np.array([np.cos(t2), np.sin(t2)])
    assert abs(np.linalg.norm(P - C) - L2) < 1e-12 and abs(np.linalg.norm(P - D) - L3) < 1e-12
    a1 = np.arctan2(*(P - C)[::-1])
    a2 = np.arctan2(*(P - D)[::-1])
    return np.array([t1, a1 - t1, -a1, t2, a2 - t2, -a2]), C, D


def _five_bar_cases():
    cases = []
    # Fig. 7.9: leg 2 stretched (B, D, P collinear): end-effector / serial singularity
    L = (1.0, 1.5, 1.5, 1.0, 1.0)
    P = np.array([1.0, 2.0])
    d = np.linalg.norm(P)
    beta = np.arccos((d**2 + L[1] ** 2 - L[2] ** 2) / (2 * d * L[1]))
    t1 = np.arctan2(P[1], P[0]) + beta
    cases.append(("fig7.9", L, t1, np.pi / 2, P))
    # Fig. 7.8 left: distal links aligned (C, P, D collinear, P between): non-degenerate
    L = (2.0, 1.0, 1.0, 1.0, 1.0)
    cases.append(("fig7.8-left", L, np.pi / 2, np.pi / 2, np.array([1.0, 1.0])))
    # Fig. 7.8 right: C = D with equal distal links: degenerate (the inner links turn)
    L = (1.0, 1.0, 0.8, 0.8, 1.0)
    C = np.array([0.5, np.sqrt(3) / 2])
    cases.append(("fig7.8-right", L, np.pi / 3, 2 * np.pi / 3,
                  C + 0.8 * np.array([np.cos(1.0), np.sin(1.0)])))
    # Fig. 7.7: every joint on one line (stretched, and folded)
    cases.append(("fig7.7-stretched", (4.0, 1.0, 1.0, 1.0, 1.0), 0.0, np.pi, np.array([2.0, 0.0])))
    cases.append(("fig7.7-folded", (1.0, 2.0, 1.0, 1.0, 1.0), 0.0, 0.0, np.array([1.0, 0.0])))
    # regular configurations
    L = (1.0, 1.0, 1.0, 1.0, 1.0)
    for P in ([0.5, 1.0], [0.3, 1.2], [0.7, 0.8]):
        P = np.array(P)
        d = np.linalg.norm(P)
        t1 = np.arctan2(P[1], P[0]) + np.arccos(d / 2)
        e = P - np.array([1.0, 0.0])
        t2 = np.arctan2(e[1], e[0]) - np.arccos(np.linalg.norm(e) / 2)
        cases.append((f"regular{P.tolist()}", L, t1, t2, P))
    return cases


@pytest.mark.parametrize("case", _five_bar_cases(), ids=lambda c: c[0])
def test_five_bar_singularities_of_modern_robotics(case):
    name, L, t1, t2, P = case
    m = M.five_bar(*L)
    q, C, D = _five_bar_q(L, t1, t2, P)
    A, B = np.zeros(2), np.array([L[0], 0.0])
    rep = optkin.classify(m, q)
    assert rep.success
    # expected verdicts from the geometry
    leg1 = _collinear(A, C, P)  # A-C-P aligned: B_11 = 0
    leg2 = _collinear(B, D, P)
    distal = _collinear(C, P, D)  # the two distal links on one line: A singular
    every = _collinear(A, C, P, D, B)
    coincident = np.linalg.norm(C - D) < 1e-12 and L[2] == L[3]
    assert ("serial" in rep.types) == (leg1 or leg2), name
    assert rep.legs_at_psik == tuple(i + 1 for i, f in enumerate((leg1, leg2)) if f)
    assert ("parallel" in rep.types) == distal, name
    assert ("actuator" in rep.types) == distal, name  # H_p singular <=> A singular here
    assert ("configuration_space" in rep.types) == every, name
    if distal and not every:
        assert ("actuator_degenerate" in rep.types) == coincident, name
    if (leg1 or leg2) and not distal:
        # MR Fig. 7.9: the effective 2R chain is aligned - end-effector singularity
        assert "end_effector" in rep.types
    if not (leg1 or leg2 or distal):
        assert rep.types == set()
        assert min(rep.margins[t] for t in ("serial", "parallel", "configuration_space",
                                            "actuator", "end_effector")) > 1e-3
    # aliases of the slides
    assert rep.aliases["PSFK"] == rep.aliases["MSFK"] == ("parallel" in rep.types)
    assert rep.aliases["PSIK"] == rep.aliases["MSIK"] == ("serial" in rep.types)


def test_margins_shrink_towards_the_singularity_and_rtol_decides():
    """Fig. 7.8 left moved off the singularity (symmetric, t1 = pi/2 - delta): the parallel
    margin is proportional to the sine of the angle between the two distal links (computed
    here), and the verdict flips with the tolerance."""
    L = (2.0, 1.0, 1.0, 1.0, 1.0)
    m = M.five_bar(*L)
    ratio = []
    for delta in (1e-2, 1e-3, 1e-4, 1e-5):
        t1 = np.pi / 2 - delta
        C = np.array([np.cos(t1), np.sin(t1)])
        P = np.array([1.0, C[1] + np.sqrt(1 - (1 - C[0]) ** 2)])  # on the axis x = 1
        q, C, D = _five_bar_q(L, t1, np.pi - t1, P)
        sin_angle = abs(_cross(P - C, D - P)) / (np.linalg.norm(P - C) * np.linalg.norm(D - P))
        rep = optkin.classify(m, q)
        ratio.append(rep.margins["parallel"] / sin_angle)
        assert "parallel" not in rep.types
        assert "parallel" in optkin.classify(m, q, rtol=10 * rep.margins["parallel"]).types
    assert np.ptp(ratio) < 0.05 * np.mean(ratio)  # margin ~ c sin(angle), c -> const


# ------------------------------------------------------------------ 3-RPR (MR 7.1)
ANG = np.deg2rad([90.0, 210.0, 330.0])
BASE = np.c_[np.cos(ANG), np.sin(ANG)]


def _leg_lines_meet(base, plat, pose, tol=1e-9):
    """True when the three leg lines are concurrent or parallel: the determinant of their
    homogeneous coordinates l_i = (a_i, 1) x (P_i, 1) vanishes."""
    x, y, phi = pose
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    lines = []
    for a, b in zip(base, plat):
        P = np.array([x, y]) + R @ b
        ln = np.cross(np.r_[a, 1.0], np.r_[P, 1.0])
        lines.append(ln / np.linalg.norm(ln))
    return abs(np.linalg.det(np.array(lines))) < tol


@pytest.mark.parametrize("plat_scale,pose", [
    (0.3, [0.0, 0.0, 0.0]),  # MR Fig. 7.3a-like: platform joints on the base radii
    (1.0, [0.0, 1.5, 0.0]),  # platform a translated copy of the base: legs parallel
    (1.0, [0.7, -0.4, 0.0]),
    (0.3, [0.0, 0.0, 0.5]),  # rotated: regular
    (0.3, [0.1, 0.05, 0.0]),
    (0.3, [0.05, -0.1, 0.2]),
])
def test_rpr3_parallel_singularity_from_leg_lines(plat_scale, pose):
    plat = plat_scale * BASE
    m = M.rpr3(BASE, plat)
    s = optkin.inverse(m, pose)[0]
    rep = optkin.classify(m, s)
    expected = _leg_lines_meet(BASE, plat, pose)
    assert ("parallel" in rep.types) == expected
    assert ("PSFK" in rep) == expected
    assert "serial" not in rep.types  # prismatic legs: B = -I never loses rank
    assert rep.margins["serial"] > 0.5
    if plat_scale == 1.0 and expected:
        # parallel legs of equal length on congruent triangles: a parallelogram linkage,
        # the platform translates on a circle with the actuators locked (degenerate)
        assert "actuator_degenerate" in rep.types


# ------------------------------------------------------------------ four-bar (MR 7.3)
def test_four_bar_configuration_space_singular_only_at_bifurcations():
    """L1 = L2 = 4, L3 = L4 = 2 (MR Fig. 7.5): sample its C-space densely with (7.22)-(7.25)
    and expect a configuration-space singularity exactly where all four joints are
    collinear (the bifurcation points)."""
    L1, L2, L3, L4 = 4.0, 4.0, 2.0, 2.0
    m = M.four_bar(L1, L2, L3, L4)
    n_sing = n = 0
    for th in np.arange(0, 2 * np.pi, np.pi / 60):
        al = 2 * L3 * L4 - 2 * L1 * L3 * np.cos(th)
        be = -2 * L1 * L3 * np.sin(th)
        ga = L2**2 - L4**2 - L3**2 - L1**2 + 2 * L1 * L4 * np.cos(th)
        c = ga / np.hypot(al, be)
        if abs(c) > 1 + 1e-12:
            continue
        for sgn in (1, -1):
            ph = np.arctan2(be, al) + sgn * np.arccos(np.clip(c, -1, 1))
            Bp = L1 * np.array([np.cos(th), np.sin(th)])
            E = np.array([L4, 0.0]) + L3 * np.array([np.cos(ph), np.sin(ph)])
            assert abs(np.linalg.norm(E - Bp) - L2) < 1e-9
            t2 = np.arctan2(*(E - Bp)[::-1]) - th
            q = np.array([th, t2, ph, ph - th - t2])
            rep = optkin.classify(m, q)
            assert rep.success
            expected = _collinear(np.zeros(2), Bp, E, np.array([L4, 0.0]), tol=1e-8)
            assert ("configuration_space" in rep.types) == expected, (th, ph)
            n += 1
            n_sing += expected
    assert n_sing >= 2 and n > 200


# ------------------------------------------------------------------ degrees of freedom
RPR_BASE = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]]
RPR_PLAT = [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]
_ab = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([10, -10] * 3)
_ap = np.deg2rad([30, 90, 150, 210, 270, 330]) + np.deg2rad([-15, 15] * 3)


def bennett(a=1.0, alpha=np.pi / 3, beta=np.pi / 4, b=None):
    """A Bennett linkage as a Khalil table: 4R loop with link lengths a, b, a, b and twists
    alpha, beta, alpha, beta, a / sin(alpha) = b / sin(beta); cut at joint 4, the partner
    frame 5 on the ground (its pose is the inverse of the fourth link's)."""
    b = a * np.sin(beta) / np.sin(alpha) if b is None else b
    rows = [dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="t1", r=0),
            dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=alpha, d=a, theta="t2", r=0),
            dict(a=2, mu=0, sigma=0, gamma=0, b=0, alpha=beta, d=b, theta="t3", r=0),
            dict(a=3, mu=0, sigma=0, gamma=0, b=0, alpha=alpha, d=a, theta="t4", r=0),
            dict(a=0, mu=0, sigma=2, gamma=0, b=0, alpha=-beta, d=-b, theta=0, r=0)]
    return optkin.Mechanism.from_khalil(rows, loops=1, name="Bennett")


# (mechanism, Grubler count by hand, mobility): the hand counts use Özgören's formula
# m = lambda n_mb - sum (lambda - f) j with lambda = 3 (planar) or 6 (spatial).
DOF_CASES = [
    ("rpr3", lambda: M.rpr3(RPR_BASE, RPR_PLAT), 3 * 7 - 2 * 9, 3),
    ("rrr3", lambda: M.rrr3(RPR_BASE, RPR_PLAT, 0.45, 0.45), 3 * 7 - 2 * 9, 3),
    ("five_bar", lambda: M.five_bar(1, 1, 1, 1, 1), 3 * 4 - 2 * 5, 2),
    ("four_bar", lambda: M.four_bar(4, 4, 2, 2), 3 * 3 - 2 * 4, 1),
    ("stewart_gough", lambda: M.stewart_gough(
        np.c_[np.cos(_ab), np.sin(_ab), np.zeros(6)],
        0.5 * np.c_[np.cos(_ap), np.sin(_ap), np.zeros(6)]),
     6 * 13 - 5 * 6 - 4 * 6 - 3 * 6, 6),
    # Delta: 3 arms + 6 rods + platform, 3 R + 12 S: 9, of which 6 idle rod spins
    ("delta", lambda: M.delta(), 6 * 10 - 5 * 3 - 3 * 12, 3),
    # [7.57]: L - sum c_j with planar loops (c_j = 3)
    ("sr400", lambda: M.sr400(), 9 - 3, 6),
    ("akr3000", lambda: M.akr3000(), 12 - 3 - 3, 6),
    # Bennett: spatial loop, 4 joints: 6 * 3 - 5 * 4 = -2, yet it moves with 1
    ("bennett", bennett, 6 * 3 - 5 * 4, 1),
]
if hasattr(M, "rpr4"):
    DOF_CASES.append(("rpr4", lambda: M.rpr4([[0, 0], [1, 0], [1, 1], [0, 1]],
                                              [[-.1, -.1], [.1, -.1], [.1, .1], [-.1, .1]]),
                      3 * 9 - 2 * 12, 3))


@pytest.mark.parametrize("name,factory,grubler,mobility", DOF_CASES, ids=[c[0] for c in DOF_CASES])
def test_dof_of_library_mechanisms_and_bennett(name, factory, grubler, mobility):
    m = factory()
    r = optkin.dof(m, samples=3)
    assert r.success and r.samples == 3
    assert r.grubler == grubler
    assert r.mobility == mobility
    if name == "bennett":
        assert not r.agree and "overconstrained" in r.message
        assert r.constraints == 3 and r.loop_lambda == (6,)
    elif name == "delta":
        assert r.idle == 6 and r.agree
    else:
        assert r.agree, r.message
    if name in ("four_bar", "five_bar", "sr400", "akr3000"):
        assert all(lam == 3 for lam in r.loop_lambda)


def test_bennett_motion_matches_its_closed_form():
    """Bennett (1903): along the motion theta3 = -theta1, theta4 = -theta2 (this table's
    sign convention) and tan(theta1/2) tan(theta2/2) = sin((beta+alpha)/2) /
    sin((beta-alpha)/2). The velocity model W (an overconstrained, non-square W_p) must give
    the derivative of theta2(theta1) from that closed form."""
    al, be = np.pi / 3, np.pi / 4
    m = bennett(alpha=al, beta=be)
    K = np.sin((be + al) / 2) / np.sin((be - al) / 2)
    for t1 in (0.4, 1.0, 1.7):
        r = optkin.forward(m, [t1], guess=[t1, -2.9, -t1, 2.9])
        assert r.success
        t = dict(zip(m.joint_names, r.q))
        assert abs(np.tan(t1 / 2) * np.tan(t["t2"] / 2) - K) < 1e-9
        assert abs(np.sin(t["t3"] + t1)) < 1e-9 and abs(np.sin(t["t4"] + t["t2"])) < 1e-9
        jac = optkin.jacobians(m, r)
        # d/dt1 of t2 = 2 atan(K / tan(t1 / 2))
        u = K / np.tan(t1 / 2)
        dt2 = 2 / (1 + u**2) * (-K / np.sin(t1 / 2) ** 2 / 2)
        rates = jac.joint_rates([1.0])
        assert abs(rates[1] - dt2) < 1e-9
        assert abs(rates[2] + 1) < 1e-9 and abs(rates[3] + dt2) < 1e-9
        assert optkin.classify(m, r).types == set()


def test_generic_4r_loop_is_rigid():
    m = bennett(b=1.0)  # breaks a / sin(alpha) = b / sin(beta)
    r = optkin.dof(m, samples=3)
    assert r.grubler == -2
    assert (not r.success) or r.mobility == 0


# ------------------------------------------------------------------ pictures and options
def test_singularity_map_png_matches_leg_line_geometry(tmp_path):
    """3-RPR whose platform is a homothetic copy of the base: at phi = 0 every leg line
    passes through the homothety centre, so the slice phi = 0 is singular for every (x, y),
    and elsewhere the leg lines are not concurrent (determinant computed here). The map's
    parallel measure must vanish exactly on the same grid cells."""
    m = M.rpr3(BASE, 0.3 * BASE)
    xs = np.linspace(-0.2, 0.2, 5)
    phis = np.linspace(-0.4, 0.4, 9)  # contains 0
    sm = optkin.plot_singularity_map(m, xs, phis, str(tmp_path / "rpr3.png"),
                                     measure="parallel", axes=("x", "phi"), fixed={"y": 0.05})
    assert (tmp_path / "rpr3.png").stat().st_size > 1000
    Z = sm.values["parallel"]
    assert np.all(np.isfinite(Z))
    truth = np.array([[_leg_lines_meet(BASE, 0.3 * BASE, (x, 0.05, ph)) for x in xs]
                      for ph in phis])
    assert truth[4].all() and truth.sum() == xs.size
    np.testing.assert_array_equal(Z < 1e-8, truth)


def test_classify_options_and_report():
    m = M.five_bar(1, 1, 1, 1, 1)
    s = optkin.inverse(m, [0.5, 1.0])[0]
    with pytest.raises(optkin.MechanismError, match=r"classify: unknown option 'tolerance'; "
                       r"known options: \['rtol', 'second_order_tol'\]"):
        optkin.classify(m, s, tolerance=1e-3)
    with pytest.raises(optkin.MechanismError, match=r"unknown option 'rtl' \(did you mean "
                       r"'rtol'\?\)"):
        optkin.classify(m, s, rtl=1e-3)
    rep = optkin.classify(m, s)
    d = rep.to_dict()
    assert d["types"] == [] and set(d["margins"]) >= {"serial", "parallel", "end_effector"}
    assert not rep.singular and repr(rep) == "SingularityReport(regular)"


# ------------------------------------------------------------------ spatial platforms
def test_stewart_gough_fichter_singularity_from_pluecker_lines():
    """Fichter (1986): a 6-6 platform with semi-regular hexagons, centred, is singular when
    rotated by +-90 deg about the vertical from its central orientation. Independently of the
    model, the six leg lines (Pluecker coordinates (n_i, q_i x n_i), computed here) are then
    linearly dependent; the parallel verdict must follow that determinant."""
    a, b = np.deg2rad(10), np.deg2rad(15)
    angb = np.array([k * 2 * np.pi / 3 + s * a for k in range(3) for s in (-1, 1)])
    angp = np.roll(np.array([k * 2 * np.pi / 3 + np.pi / 3 + s * b
                             for k in range(3) for s in (-1, 1)]), 1)
    base = np.c_[np.cos(angb), np.sin(angb), np.zeros(6)]
    plat = 0.5 * np.c_[np.cos(angp), np.sin(angp), np.zeros(6)]
    m = M.stewart_gough(base, plat)
    for yaw in np.deg2rad([0.0, 45.0, 89.0, 90.0, -90.0, 120.0]):
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
        p = np.array([0.0, 0.0, 1.0])
        P = p + plat @ R.T
        n = (P - base) / np.linalg.norm(P - base, axis=1)[:, None]
        pl = np.c_[n, np.cross(base, n)]
        expected = abs(np.linalg.det(pl)) < 1e-9
        rep = optkin.classify(m, optkin.inverse(m, [0, 0, 1.0, 0, 0, yaw])[0])
        assert ("parallel" in rep.types) == expected, np.rad2deg(yaw)
        assert expected == bool(np.isclose(abs(yaw), np.pi / 2))
        assert "serial" not in rep.types


def test_delta_stretched_arm_is_a_serial_singularity():
    """Delta (base radius 0.2, platform 0.05, arm 0.3, forearm 0.8): put leg 1's forearm in
    line with its arm (theta = 100 deg) - the elbow is straight, |P - A| = arm + forearm, and
    B_11 = 0. The other two legs are not straight (checked here)."""
    Rb, rp, la, lb = 0.2, 0.05, 0.3, 0.8
    m = M.delta(Rb, rp, la, lb)
    th = np.deg2rad(100.0)
    u0, z = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    A0 = Rb * u0
    P0 = A0 + (la + lb) * (np.cos(th) * u0 - np.sin(th) * z)
    p = P0 - rp * u0
    straight = []
    for k in range(3):
        ak = 2 * np.pi * k / 3
        u = np.array([np.cos(ak), np.sin(ak), 0.0])
        straight.append(abs(np.linalg.norm(p + rp * u - Rb * u) - (la + lb)) < 1e-12)
    assert straight == [True, False, False]
    sols = optkin.inverse(m, p)
    assert len(sols) == 4  # legs 2 and 3 have two postures each, leg 1 one (double root)
    for s in sols:
        rep = optkin.classify(m, s)
        assert "serial" in rep.types and rep.legs_at_psik == (1,)
        assert "PSIK" in rep and "MSIK" in rep


def test_open_chain_2r_arm_jacobian_and_stretched_singularity():
    """A serial 2R arm (no loop) as a Khalil table: J_a's task rows are the textbook
    [[-l1 s1 - l2 s12, -l2 s12], [l1 c1 + l2 c12, l2 c12]]; the arm is singular exactly
    when its links are aligned (t2 = 0 or pi)."""
    l1, l2 = 1.0, 0.8
    rows = [dict(a=0, mu=1, sigma=0, theta="t1"), dict(a=1, mu=1, sigma=0, d=l1, theta="t2"),
            dict(a=2, mu=0, sigma=2, d=l2)]
    m = optkin.Mechanism.from_khalil(rows, end_effector=3, task=("x", "y"))
    assert optkin.dof(m).mobility == 2
    for t1, t2 in ((0.3, 0.5), (-1.0, 2.0), (0.7, 0.0), (0.2, np.pi)):
        q = np.array([t1, t2])
        jac = optkin.jacobians(m, q)
        s1, c1, s12, c12 = np.sin(t1), np.cos(t1), np.sin(t1 + t2), np.cos(t1 + t2)
        ref = [[-l1 * s1 - l2 * s12, -l2 * s12], [l1 * c1 + l2 * c12, l2 * c12]]
        np.testing.assert_allclose(jac.J_task, ref, atol=1e-12)
        aligned = abs(np.sin(t2)) < 1e-12
        rep = optkin.classify(m, q)
        assert ("serial" in rep.types) == aligned
        assert ("end_effector" in rep.types) == aligned
        assert "parallel" not in rep.types


def test_four_bar_actuator_singularities_depend_on_the_actuated_joint():
    """MR 7.3: configuration-space singularities do not depend on which joint is actuated,
    actuator singularities do. Same C-space sample as above, crank or rocker actuated:
    crank actuated -> H_p singular iff coupler and rocker are aligned (B, E, D collinear);
    rocker actuated -> iff crank and coupler are aligned (A, B, E collinear). With the
    rocker locked on the branch E = A the crank and coupler still turn together (|B - A| =
    L1 = L2): a degenerate actuator singularity."""
    L1, L2, L3, L4 = 4.0, 4.0, 2.0, 2.0
    crank = M.four_bar(L1, L2, L3, L4)
    spec = crank.to_dict()
    rows = [dict(r) for r in spec["rows"]]
    rows[0]["mu"], rows[2]["mu"] = 0, 1  # actuate the rocker (frame 3, phi) instead
    rocker = optkin.Mechanism.from_khalil(rows, loops=1, params=spec["params"], end_effector=1,
                                          task=("rz",), name="four-bar (rocker actuated)")
    A, D = np.zeros(2), np.array([L4, 0.0])
    seen = {"crank": 0, "rocker": 0, "degenerate": 0}
    for th in np.arange(0, 2 * np.pi, np.pi / 30):
        al = 2 * L3 * L4 - 2 * L1 * L3 * np.cos(th)
        be = -2 * L1 * L3 * np.sin(th)
        ga = L2**2 - L4**2 - L3**2 - L1**2 + 2 * L1 * L4 * np.cos(th)
        c = np.clip(ga / np.hypot(al, be), -1, 1)
        for sgn in (1, -1):
            ph = np.arctan2(be, al) + sgn * np.arccos(c)
            B = L1 * np.array([np.cos(th), np.sin(th)])
            E = D + L3 * np.array([np.cos(ph), np.sin(ph)])
            t2 = np.arctan2(*(E - B)[::-1]) - th
            q = np.array([th, t2, ph, ph - th - t2])
            rc, rr = optkin.classify(crank, q), optkin.classify(rocker, q)
            every = _collinear(A, B, E, D, tol=1e-8)
            assert ("configuration_space" in rc.types) == every
            assert ("configuration_space" in rr.types) == every
            exp_c = _collinear(B, E, D, tol=1e-8)
            exp_r = _collinear(A, B, E, tol=1e-8)
            assert ("actuator" in rc.types) == exp_c, (th, ph)
            assert ("actuator" in rr.types) == exp_r, (th, ph)
            if exp_r and not every:
                assert "actuator_degenerate" in rr.types
                seen["degenerate"] += 1
            seen["crank"] += exp_c
            seen["rocker"] += exp_r
    assert seen["crank"] >= 2 and seen["degenerate"] > 20


# ---------------------------------------------------------------------------------------
# Tsai's 3-UPU: its constraint singularities, derived here
# ---------------------------------------------------------------------------------------
#
# Leg i (base joint at R u_i, platform joint at r u_i, u_i at 0, 120, 240 degrees, the
# platform at p with its orientation kept) has universal joints whose first axis is the
# tangent t_i = e_z x u_i and whose second axis w_i is t_i's normal in the plane
# (-u_i, e_z), turned by the first joint angle theta: w_i = -cos(theta) u_i +
# sin(theta) e_z; the platform's joint repeats both axes (Tsai's condition). The leg's
# twists are rotations about t_i and w_i (through two points each) and the translation
# along the leg; the one wrench reciprocal to them all is the couple n_i = t_i x w_i =
# cos(theta) e_z + sin(theta) u_i. The leg s_i = p - d u_i (d = R - r) is normal to w_i:
# tan(theta) = (u_i . p - d) / p_z, so n_i ~ a_i u_i + p_z e_z with a_i = u_i . p - d.
# The platform can turn (a constraint singularity) where the three couples are coplanar:
#   det[n_1; n_2; n_3] = p_z sin(120 deg) (a_1 a_2 + a_2 a_3 + a_3 a_1)
# and, with sum u_i = 0 and sum (u_i . p)^2 = 3/2 (x^2 + y^2),
#   a_1 a_2 + a_2 a_3 + a_3 a_1 = ((sum a_i)^2 - sum a_i^2) / 2 = 3 d^2 - 3/4 (x^2 + y^2):
# above the base plane, the vertical cylinder x^2 + y^2 = (2 d)^2, whatever z; the
# platform then turns about the normal of the couples' plane.

def _upu3_config(m, R, r, p, guess=None):
    u = np.c_[np.cos(2 * np.pi * np.arange(3) / 3), np.sin(2 * np.pi * np.arange(3) / 3),
              np.zeros(3)]
    rho = np.linalg.norm(p - (R - r) * u, axis=1)
    res = optkin.forward(m, rho, guess=[*p, 0, 0, 0] if guess is None else guess, tol=1e-14)
    assert res.success
    np.testing.assert_allclose(res.pose[:3, 3], p, atol=1e-10)
    np.testing.assert_allclose(res.pose[:3, :3], np.eye(3), atol=1e-10)  # translational
    return res, u


@pytest.mark.parametrize("R,r", [(1.0, 0.5), (1.2, 0.3)])
def test_3upu_constraint_singularity_is_the_cylinder_of_radius_twice_R_minus_r(R, r):
    m = M.upu3(R, r)
    d = R - r
    for ang, z in zip(RNG.uniform(0, 2 * np.pi, 3), RNG.uniform(0.4, 1.2, 3)):
        e = np.array([np.cos(ang), np.sin(ang), 0.0])
        # on the cylinder: a parallel singularity whose null motion turns the platform
        # about the normal of the three couples
        p = 2 * d * e + [0, 0, z]
        res, u = _upu3_config(m, R, r, p)
        rep = optkin.classify(m, res)
        assert "parallel" in rep.types and "internal" in rep.types, rep.types
        jac = optkin.jacobians(m, res)
        names = list(jac.x_names)
        v = np.linalg.svd(jac.W_p)[2][-1]
        omega = v[[names.index(k) for k in ("qx", "qy", "qz")]]  # 2 qdot at the identity
        assert np.linalg.norm(omega) > 0.1 * np.linalg.norm(v)  # it turns the platform
        n = (u @ p - d)[:, None] * u + [0, 0, z]
        assert abs(np.linalg.det(n)) < 1e-12
        np.testing.assert_allclose(n @ omega / np.linalg.norm(omega), 0, atol=1e-9)
        # off it, inside and outside: regular, and det W_p changes sign across it along
        # the radius (the legs' joints near those on the cylinder on both sides)
        dets = []
        for f in (0.9, 1.1):
            q, _ = _upu3_config(m, R, r, 2 * d * f * e + [0, 0, z])
            assert np.abs(q.x[7:] - res.x[7:]).max() < 0.3  # the same branch of each leg
            assert optkin.classify(m, q).types == set(), (f, optkin.classify(m, q).types)
            dets.append(np.linalg.det(optkin.jacobians(m, q).W_p))
        assert dets[0] * dets[1] < 0
