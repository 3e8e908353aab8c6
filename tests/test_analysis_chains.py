"""The analyses on legs in chain form (issue 12): a 3-UPU, a 3-RPS and a 3-PSP built with
``from_legs``, legs written with ``Leg.from_screws``, mixed leg types, and UPS legs on a
translational platform.

References: central finite differences of the solved forward map (optkin.forward with a
warm guess), as tests/test_velocity.py does for the library mechanisms; the designed
mobility of each mechanism (3 for the three spatial 3-DoF platforms, counted by hand with
Grubler's formula in the comments); the general closure against the distance form.
"""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin import Leg, Mechanism
from optkin import mechanisms as M
from optkin.mechanism.geometry import wrap_angle
from optkin.mechanism.legs import prismatic_screw, revolute_screw

RNG = np.random.default_rng(12)
H = 1e-5  # finite-difference step


def _circle(r, deg):
    a = np.deg2rad(deg)
    return r * np.array([np.cos(a), np.sin(a), 0.0])


def _tangent(deg):
    a = np.deg2rad(deg)
    return np.array([-np.sin(a), np.cos(a), 0.0])


# generic geometries: neither the angles nor the radii are regular
ANG_B = (92.0, 207.0, 338.0)
ANG_P = (95.0, 201.0, 343.0)
R_B = (1.0, 1.1, 0.93)
R_P = (0.45, 0.41, 0.5)


def upu3():
    """Tsai's 3-UPU: the base universal joints' first axes tangent to the base circle, the
    second radial (inwards) so that the legs leave upwards; the platform joints' axes are
    parallel to them (the builder's arrangement): the platform only translates."""
    legs = [{"type": "UPU", "base": _circle(rb, ab).tolist(), "platform": _circle(rp, ap).tolist(),
             "axis": _tangent(ab).tolist(), "arm": (-_circle(1.0, ab)).tolist()}
            for rb, rp, ab, ap in zip(R_B, R_P, ANG_B, ANG_P)]
    return Mechanism.from_legs(legs, "spatial", name="3-UPU")


def rps3():
    """3-RPS: passive base revolutes tangent to the base circle, actuated prismatic legs,
    spherical joints on the platform."""
    legs = [{"type": "RPS", "base": _circle(rb, ab).tolist(), "platform": _circle(rp, ap).tolist(),
             "axis": _tangent(ab).tolist()}
            for rb, rp, ab, ap in zip(R_B, R_P, ANG_B, ANG_P)]
    return Mechanism.from_legs(legs, "spatial", name="3-RPS")


def psp3():
    """3-PSP (Modern Robotics Exercise 7.5): actuated vertical sliders on the base, a
    spherical joint on each, and a slider along the platform's radius."""
    legs = [{"type": "PSP", "base": _circle(rb, ab).tolist(), "platform": _circle(rp, ap).tolist(),
             "direction": [0.0, 0.0, 1.0], "axis": _circle(1.0, ap).tolist()}
            for rb, rp, ab, ap in zip(R_B, R_P, ANG_B, ANG_P)]
    return Mechanism.from_legs(legs, "spatial", name="3-PSP")


def rpr3_from_screws(base, plat):
    """A 3-RPR written with Leg.from_screws: each chain ends at the platform frame."""
    legs = []
    for a, b in zip(base, plat):
        a3 = np.r_[a, 0.0]
        S = [revolute_screw([0, 0, 1], a3), prismatic_screw([1, 0, 0]),
             revolute_screw([0, 0, 1], a3)]
        home = np.eye(4)
        home[:3, 3] = a3 - np.r_[b, 0.0]  # platform point b at the base point at home
        legs.append(Leg.from_screws(S, home, actuated=1, joints="RPR"))
    return Mechanism.from_legs(legs, "planar", name="3-RPR (screws)")


RPR_BASE = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]])
RPR_PLAT = np.array([[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])

# leg lengths of the library 3-RPR at the pose (0.45, 0.35, -0.2) (rho_i = |p + R b_i - a_i|)
_R = np.array([[np.cos(-0.2), -np.sin(-0.2)], [np.sin(-0.2), np.cos(-0.2)]])
RPR_QA = np.linalg.norm(np.array([0.45, 0.35]) + RPR_PLAT @ _R.T - RPR_BASE, axis=1)

# (name, factory, actuated values of a first configuration, guess pose (task coordinates))
CHAIN_CASES = [
    ("3-UPU", upu3, [0.8, 0.85, 0.75], [0.0, 0.0, 0.6, 0, 0, 0]),
    ("3-RPS", rps3, [0.8, 0.85, 0.75], [0.0, 0.0, 0.6, 0, 0, 0]),
    ("3-PSP", psp3, [0.3, 0.35, 0.25], [0.0, 0.0, 0.3, 0, 0, 0]),
    ("3-RPR-screws", lambda: rpr3_from_screws(RPR_BASE, RPR_PLAT), RPR_QA.tolist(),
     [0.45, 0.35, -0.2]),
]


def _rot_vee(Rp, Rm, R, h):
    """omega from (R(+h) - R(-h)) / 2h = [omega] R."""
    S = (Rp - Rm) / (2 * h) @ R.T
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def _rel(a, b):
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def _configs(m, qa, guess):
    """A closed configuration from the guess pose, and a second one nearby (the actuated
    values moved along a fixed direction, the first configuration as the guess)."""
    r0 = optkin.forward(m, qa, guess=guess, tol=1e-13)
    assert r0.success, r0.message
    r1 = optkin.forward(m, r0.qa + 0.01 * np.array([1.0, -2.5, 1.5]), guess=r0, tol=1e-13)
    assert r1.success, r1.message
    return [r0, r1]


@pytest.mark.parametrize("name,factory,qa,guess", CHAIN_CASES, ids=[c[0] for c in CHAIN_CASES])
def test_chain_legs_rates_match_finite_differences_of_the_forward_map(name, factory, qa, guess):
    m = factory()
    for r in _configs(m, qa, guess):
        jac = optkin.jacobians(m, r)
        assert jac.success, jac.message
        assert jac.W_p.shape == (len(r.x), len(r.x)) and jac.W_c.shape == (0, 0)
        qad = RNG.normal(size=r.qa.size)
        rp = optkin.forward(m, r.qa + H * qad, guess=r, tol=1e-13)
        rm = optkin.forward(m, r.qa - H * qad, guess=r, tol=1e-13)
        assert rp.success and rm.success
        # the model's unknowns (platform coordinates and the legs' passive joints)
        assert _rel(jac.x_rates(qad), (rp.x - rm.x) / (2 * H)) < 1e-6, name
        # every joint rate, through the joint-level closure H (MR (7.13))
        rev = np.array(m.revolute)
        fd_q = np.where(rev, wrap_angle(rp.q - rm.q), rp.q - rm.q) / (2 * H)
        assert _rel(jac.joint_rates(qad), fd_q) < 1e-6, name
        # end-effector twist (v, omega) in base coordinates, and MR's spatial twist
        v = (rp.pose[:3, 3] - rm.pose[:3, 3]) / (2 * H)
        w = _rot_vee(rp.pose[:3, :3], rm.pose[:3, :3], r.pose[:3, :3], H)
        tw = np.r_[v, w]
        rows = {"vx": 0, "vy": 1, "vz": 2, "wx": 3, "wy": 4, "wz": 5}
        assert _rel(jac.twist(qad), tw[[rows[n] for n in jac.twist_names]]) < 1e-6, name
        assert _rel(jac.J_s @ qad, np.r_[w, v - np.cross(w, r.pose[:3, 3])]) < 1e-6, name


@pytest.mark.parametrize("name,factory,qa,guess", CHAIN_CASES[:3], ids=[c[0] for c in CHAIN_CASES[:3]])
def test_chain_legs_acceleration_matches_second_differences(name, factory, qa, guess):
    m = factory()
    r = _configs(m, qa, guess)[1]
    jac = optkin.jacobians(m, r)
    qad = RNG.normal(size=3)
    h = 5e-4

    def d2(h):
        rp = optkin.forward(m, r.qa + h * qad, guess=r, tol=1e-14)
        rm = optkin.forward(m, r.qa - h * qad, guess=r, tol=1e-14)
        assert rp.success and rm.success
        return (rp.x - 2 * r.x + rm.x) / h**2

    fd = (4 * d2(h / 2) - d2(h)) / 3
    assert _rel(jac.passive_accelerations(qad, np.zeros(3)), fd) < 1e-5, name


def test_tsai_3upu_translates_and_its_twist_has_no_rotation():
    m = upu3()
    r = _configs(m, [0.8, 0.85, 0.75], [0.0, 0.0, 0.6, 0, 0, 0])[1]
    np.testing.assert_allclose(r.pose[:3, :3], np.eye(3), atol=1e-10)
    jac = optkin.jacobians(m, r)
    assert np.abs(jac.J_a[3:]).max() < 1e-9  # omega = 0 for every actuated rate
    assert np.linalg.matrix_rank(jac.J_a[:3]) == 3


# Grubler (Özgören): m = lambda n_mb - sum (lambda - f_k) = sum f - lambda loops, lambda = 6
#   3-UPU: 3 x (2 + 1 + 2) freedoms, 7 bodies, 9 joints (2 loops): 15 - 12 = 3
#   3-RPS: 3 x (1 + 1 + 3) = 15 - 12 = 3;  3-PSP: 3 x (1 + 3 + 1) = 15 - 12 = 3
#   3-RPR (planar, lambda = 3): 3 x 3 = 9 - 6 = 3
@pytest.mark.parametrize("name,factory", [(c[0], c[1]) for c in CHAIN_CASES],
                         ids=[c[0] for c in CHAIN_CASES])
def test_chain_legs_dof_is_the_designed_mobility(name, factory):
    m = factory()
    r = optkin.dof(m, samples=3)
    assert r.success and r.samples == 3
    assert r.grubler == 3 and r.mobility == 3 and r.agree, r.message
    assert r.n_links == 7 and r.n_joints == 9 and r.n_loops == 2


def test_3upu_dof_at_a_generic_translational_configuration():
    """dof's rank test at the configuration itself: the constraint Jacobian over every joint
    and the platform coordinates has nullity 3 there (the three leg lengths)."""
    m = upu3()
    r = _configs(m, [0.83, 0.79, 0.88], [0.0, 0.0, 0.6, 0, 0, 0])[1]
    jac = optkin.jacobians(m, r)
    from optkin.analysis.mobility import _scaled

    s = np.linalg.svd(_scaled(m, jac.H), compute_uv=False)
    assert jac.H.shape[1] - int(np.sum(s > 1e-8 * s[0])) == 3
    assert optkin.classify(m, r).types == set()


def test_ups_legs_on_a_translational_platform_have_three_degrees_of_freedom():
    """The joint-level closure joins each leg's reported spherical joint to the platform
    frame, whose orientation a translational platform keeps: mobility 3 (it was 12)."""
    legs = [{"type": "UPS", "base": _circle(rb, ab).tolist(),
             "platform": _circle(rp, ap).tolist()}
            for rb, rp, ab, ap in zip(R_B, R_P, ANG_B, ANG_P)]
    m = Mechanism.from_legs(legs, "spatial_translational", home=[0.0, 0.0, 0.8])
    r = optkin.dof(m, samples=3)
    assert r.success and r.mobility == 3
    s = optkin.inverse(m, [0.05, 0.02, 0.8])
    jac = optkin.jacobians(m, s[0])
    assert jac.success and jac.A.shape == (3, 3) and jac.G_statics is None
    np.testing.assert_allclose(jac.B, -np.eye(3), atol=1e-12)


def test_screw_legs_and_the_library_3rpr_have_the_same_velocity_model():
    """The 3-RPR from screws (general closure, chain form) and rpr3 (distance form) at one
    configuration: the same twist per actuated rate and the same parallel singularity
    verdicts."""
    a = rpr3_from_screws(RPR_BASE, RPR_PLAT)
    b = M.rpr3(RPR_BASE, RPR_PLAT)
    for pose in ([0.45, 0.35, -0.2], [0.55, 0.45, 0.0]):
        sb = optkin.inverse(b, pose)[0]
        ra = optkin.forward(a, sb.qa, guess=pose, tol=1e-13)
        assert ra.success
        np.testing.assert_allclose(ra.pose, sb.pose, atol=1e-9)
        ja, jb = optkin.jacobians(a, ra), optkin.jacobians(b, sb)
        assert ja.A is None and jb.A is not None  # A, B: the distance form's
        np.testing.assert_allclose(ja.J_a, jb.J_a, atol=1e-9)
        np.testing.assert_allclose(ja.H_p.shape[0], ja.H.shape[0])
        ca_, cb = optkin.classify(a, ra), optkin.classify(b, sb)
        assert ca_.types == cb.types == set()


def test_mixed_leg_types_on_one_platform():
    """Ozgoren's mixed 3-PRR + 3-RPR idea, one PRR leg and two RPR legs: distance legs all,
    so Chablat and Wenger's A and B apply; B is diagonal."""
    legs = [{"type": "PRR", "base": RPR_BASE[0].tolist(), "platform": RPR_PLAT[0].tolist(),
             "direction": [1.0, 0.0], "lengths": [0.6]},
            {"type": "RPR", "base": RPR_BASE[1].tolist(), "platform": RPR_PLAT[1].tolist()},
            {"type": "RPR", "base": RPR_BASE[2].tolist(), "platform": RPR_PLAT[2].tolist()}]
    m = Mechanism.from_legs(legs, "planar")
    r = optkin.dof(m, samples=3)
    assert r.grubler == 3 and r.mobility == 3 and r.agree
    s = optkin.inverse(m, [0.5, 0.4, 0.1])[0]
    jac = optkin.jacobians(m, s)
    assert jac.success and np.allclose(jac.B, np.diag(np.diag(jac.B)))
    qad = RNG.normal(size=3)
    rp = optkin.forward(m, s.qa + H * qad, guess=s, tol=1e-13)
    rm = optkin.forward(m, s.qa - H * qad, guess=s, tol=1e-13)
    assert _rel(jac.x_rates(qad), (rp.x - rm.x) / (2 * H)) < 1e-6


def test_analysis_functions_are_shared_by_the_geometries_of_a_topology():
    from optkin.analysis._functions import analysis_functions

    a = M.rpr3(RPR_BASE, RPR_PLAT)
    b = M.rpr3(RPR_BASE + 0.1, RPR_PLAT * 0.9)
    assert a.key != b.key
    assert analysis_functions(a) is analysis_functions(b)
    # and each geometry keeps its own numbers: the same rates as finite differences
    for m in (a, b):
        s = optkin.inverse(m, [0.45, 0.35, -0.2])[0]
        jac = optkin.jacobians(m, s)
        qad = RNG.normal(size=3)
        rp = optkin.forward(m, s.qa + H * qad, guess=s, tol=1e-13)
        rm = optkin.forward(m, s.qa - H * qad, guess=s, tol=1e-13)
        assert _rel(jac.x_rates(qad), (rp.x - rm.x) / (2 * H)) < 1e-6


ANG = np.deg2rad([90.0, 210.0, 330.0])
BASE = np.c_[np.cos(ANG), np.sin(ANG)]


def _leg_lines_meet(base, plat, pose, tol=1e-9):
    """The three leg lines are concurrent or parallel: the determinant of their homogeneous
    coordinates l_i = (a_i, 1) x (P_i, 1) vanishes (as in tests/test_singularity.py)."""
    x, y, phi = pose
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    lines = []
    for a, b in zip(base, plat):
        ln = np.cross(np.r_[a, 1.0], np.r_[np.array([x, y]) + R @ b, 1.0])
        lines.append(ln / np.linalg.norm(ln))
    return abs(np.linalg.det(np.array(lines))) < tol


@pytest.mark.parametrize("plat_scale,pose", [
    (0.3, [0.0, 0.0, 0.0]),  # platform joints on the base radii: concurrent leg lines
    (1.0, [0.0, 1.5, 0.0]),  # a translated copy of the base: parallel legs
    (0.3, [0.0, 0.0, 0.5]),
    (0.3, [0.05, -0.1, 0.2]),
])
def test_screw_legs_parallel_singularity_from_leg_lines(plat_scale, pose):
    """The 3-RPR from screws has no A and B (its unknowns include the legs' joints): its
    parallel verdict comes from W_p and the end-effector motion, and must follow the leg
    lines as the library 3-RPR's does."""
    plat = plat_scale * BASE
    a, b = rpr3_from_screws(BASE, plat), M.rpr3(BASE, plat)
    sb = optkin.inverse(b, pose)[0]
    ra = optkin.forward(a, sb.qa, guess=pose, tol=1e-13)
    assert ra.success
    expected = _leg_lines_meet(BASE, plat, pose)
    rep = optkin.classify(a, ra)
    assert ("parallel" in rep.types) == expected
    assert rep.types == optkin.classify(b, sb).types
