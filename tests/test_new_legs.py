"""The leg types beyond distance legs, and the library mechanisms built from them, checked
against leg equations written out here (closed forms independent of optkin's chains)."""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin import mechanisms as M

RNG = np.random.default_rng(20261130)


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    cr, sr, cp, sp = np.cos(r), np.sin(r), np.cos(p), np.sin(p)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    return _rz(y) @ Ry @ Rx


def _circle(radius: float, n: int = 3) -> np.ndarray:
    a = 2 * np.pi * np.arange(n) / n
    return radius * np.c_[np.cos(a), np.sin(a), np.zeros(n)]


# --------------------------------------------------------------------------------------
# Tsai's 3-UPU


def _three_spheres(c: np.ndarray, rho: np.ndarray) -> list[np.ndarray]:
    """The points at distance rho_i from the centres c_i (the centres in one horizontal
    plane): eliminate |p|^2 from the differences, then the height from the first sphere."""
    A = 2 * (c[1:] - c[0])[:, :2]
    b = (rho[0] ** 2 - rho[1:] ** 2) + (np.sum(c[1:] ** 2, axis=1) - np.sum(c[0] ** 2))
    xy = np.linalg.solve(A, b)
    h2 = rho[0] ** 2 - np.sum((xy - c[0, :2]) ** 2)
    if h2 < 0:
        return []
    h = np.sqrt(h2)
    return [np.array([xy[0], xy[1], c[0, 2] + h]), np.array([xy[0], xy[1], c[0, 2] - h])]


def test_upu3_translates_along_200_random_inputs():
    """Forward from the default (home) configuration keeps the orientation at the identity
    to 1e-10, and the position is the upper three-sphere intersection."""
    R, r = 1.0, 0.5
    m = M.upu3(R, r)
    centres = _circle(R - r)
    worst = 0.0
    for _ in range(200):
        p = np.array([RNG.uniform(-0.2, 0.2), RNG.uniform(-0.2, 0.2), RNG.uniform(0.8, 1.3)])
        rho = np.linalg.norm(p - centres, axis=1)
        res = optkin.forward(m, rho)
        assert res.success, res.message
        worst = max(worst, float(np.abs(res.pose[:3, :3] - np.eye(3)).max()))
        up = _three_spheres(centres, rho)[0]
        assert np.allclose(res.pose[:3, 3], up, atol=1e-9)
    assert worst < 1e-10


def test_upu3_assembly_modes_contain_the_two_translations():
    """The translational solutions of assembly_modes are exactly the two three-sphere
    intersections; every other solution (the 3-UPU's other operation modes) closes. The
    default is the homotopy from the shipped start system (verified complete by the trace
    test): every pose comes in the 8 joint configurations of its legs' flips."""
    m = M.upu3(1.0, 0.5)
    centres = _circle(0.5)
    p = np.array([0.05, -0.08, 1.0])
    rho = np.linalg.norm(p - centres, axis=1)
    modes = optkin.assembly_modes(m, rho)
    assert modes.stats.method == "homotopy" and modes.complete, modes.info["message"]
    translational = [s for s in modes if np.abs(s.pose[:3, :3] - np.eye(3)).max() < 1e-8]
    want = _three_spheres(centres, rho)
    poses: list[np.ndarray] = []
    for s in translational:
        if not any(np.allclose(s.pose[:3, 3], q, atol=1e-9) for q in poses):
            poses.append(s.pose[:3, 3])
    got = sorted(poses, key=lambda v: -v[2])
    assert len(got) == 2
    for g, w in zip(got, want):
        assert np.allclose(g, w, atol=1e-9)
        assert sum(np.allclose(s.pose[:3, 3], g, atol=1e-9) for s in translational) == 8
    model = optkin.get_model(m)
    for s in modes:
        assert np.max(np.abs(model.residual(s.qa, s.x))) < 1e-9


def test_upu3_and_translational_ups_mobility():
    m = M.upu3(1.0, 0.5)
    assert optkin.dof(m).mobility == 3
    legs = [{"type": "UPS", "base": b.tolist(), "platform": (0.4 * b).tolist()}
            for b in _circle(1.0)]
    t = optkin.Mechanism.from_legs(legs, "spatial_translational")
    assert optkin.dof(t).mobility == 3  # was 12: the S joints turned freely


# --------------------------------------------------------------------------------------
# 3-PRR, 3-RPS, Hexa, 6-PUS, 3-PSP: inverse against leg equations, forward round trips


def _roundtrip(m, sols, guess_noise=1e-3):
    for s in sols:
        g = s.pose.copy()
        g[:3, 3] += guess_noise
        back = optkin.forward(m, s.qa, guess=g)
        assert back.success, back.message
        assert np.allclose(back.pose, s.pose, atol=1e-8)


def test_prr3_inverse_against_the_slider_quadratics():
    base = np.array([[0, 0], [2, 0], [1, 2.0]])
    dirs = np.array([[1, 0], [0, 1], [-1, 0.0]])
    plat = np.array([[-0.2, -0.1], [0.2, -0.1], [0.0, 0.2]])
    L = 1.5
    m = M.prr3(base, dirs, plat, L)
    for _ in range(5):
        x, y, phi = RNG.uniform(0.8, 1.2), RNG.uniform(0.8, 1.2), RNG.uniform(-0.3, 0.3)
        sols = optkin.inverse(m, [x, y, phi])
        c, s_ = np.cos(phi), np.sin(phi)
        P = np.array([x, y]) + plat @ np.array([[c, -s_], [s_, c]]).T
        roots = []
        for i in range(3):  # |P - B - s d| = L
            w = P[i] - base[i]
            vw = dirs[i] @ w
            disc = vw * vw - w @ w + L * L
            roots.append({vw + np.sqrt(disc), vw - np.sqrt(disc)})
        assert len(sols) == 8
        for sol in sols:
            for i in range(3):
                assert min(abs(sol.qa[i] - v) for v in roots[i]) < 1e-10
        _roundtrip(m, sols[:3])


def test_rps3_inverse_forward_and_mobility():
    """A 3-RPS pose: each platform point lies in its leg's vertical plane and at distance
    rho from the base point; a pose from forward kinematics satisfies both, and inverse
    gives back those lengths."""
    R, r = 1.0, 0.5
    m = M.rps3(R, r)
    a = 2 * np.pi * np.arange(3) / 3
    tang = np.c_[-np.sin(a), np.cos(a), np.zeros(3)]
    B, P0 = _circle(R), _circle(r)
    for _ in range(5):
        rho = RNG.uniform(0.9, 1.2, 3)
        res = optkin.forward(m, rho, guess=[0, 0, 1.0, 0, 0, 0])
        assert res.success
        P = res.pose[:3, 3] + P0 @ res.pose[:3, :3].T
        assert np.allclose(np.einsum("ij,ij->i", P - B, tang), 0, atol=1e-10)  # in the plane
        assert np.allclose(np.linalg.norm(P - B, axis=1), rho, atol=1e-10)
        sols = optkin.inverse(m, res.pose)
        assert len(sols) >= 1 and any(np.allclose(s.qa, rho, atol=1e-9) for s in sols)
    assert optkin.dof(m).mobility == 3


def _rus_angles(A, axis, arm, la, lb, P):
    """Paden-Kahan 3 for an arm of length la turning about axis through A: both angles."""
    w = np.cross(axis, arm)
    d = P - A
    k = (d @ d + la * la - lb * lb) / (2 * la)
    a_, b_ = d @ arm, d @ w
    base = np.arctan2(b_, a_)
    delta = np.arccos(np.clip(k / np.hypot(a_, b_), -1, 1))
    return {(base + delta + np.pi) % (2 * np.pi) - np.pi, (base - delta + np.pi) % (2 * np.pi) - np.pi}


def test_hexa_inverse_against_the_arm_equation():
    m = M.hexa()
    for _ in range(3):
        pose = [RNG.uniform(-0.05, 0.05), RNG.uniform(-0.05, 0.05), RNG.uniform(-0.65, -0.55),
                RNG.uniform(-0.1, 0.1), RNG.uniform(-0.1, 0.1), RNG.uniform(-0.2, 0.2)]
        sols = optkin.inverse(m, pose)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _rpy(*pose[3:]), pose[:3]
        assert len(sols) == 64
        for i, leg in enumerate(m.legs):
            P = T[:3, 3] + T[:3, :3] @ np.asarray(leg.platform)
            want = _rus_angles(np.asarray(leg.base), np.asarray(leg.axis), np.asarray(leg.arm),
                               *leg.lengths, P)
            for sol in sols:
                v = (sol.qa[i] + np.pi) % (2 * np.pi) - np.pi
                assert min(abs(v - w) for w in want) < 1e-9
        _roundtrip(m, sols[:4])
    assert len(optkin.working_modes(m)) == 64
    assert optkin.dof(m).mobility == 6


def test_pus6_inverse_against_the_slider_quadratics():
    m = M.pus6()
    for _ in range(3):
        pose = [RNG.uniform(-0.05, 0.05), RNG.uniform(-0.05, 0.05), RNG.uniform(0.55, 0.65),
                RNG.uniform(-0.1, 0.1), RNG.uniform(-0.1, 0.1), RNG.uniform(-0.2, 0.2)]
        T_R = _rpy(*pose[3:])
        sols = optkin.inverse(m, pose)
        assert len(sols) == 64
        for i, leg in enumerate(m.legs):
            P = np.asarray(pose[:3]) + T_R @ np.asarray(leg.platform)
            w = P - np.asarray(leg.base)
            d = np.asarray(leg.axis)
            vw = d @ w
            disc = vw * vw - w @ w + leg.lengths[0] ** 2
            roots = {vw + np.sqrt(disc), vw - np.sqrt(disc)}
            for sol in sols:
                assert min(abs(sol.qa[i] - v) for v in roots) < 1e-10
        _roundtrip(m, sols[:4])
    assert optkin.dof(m).mobility == 6


def test_psp3_inverse_and_mobility():
    """3-PSP (Modern Robotics Exercise 7.5): at a pose, each base slider height s_i puts
    the sphere centre (u_i, s_i) on the platform slider line through its platform point:
    written out, s_i follows from the line's direction."""
    m = M.psp3(1.0, 0.4)
    a = 2 * np.pi * np.arange(3) / 3
    u = np.c_[np.cos(a), np.sin(a), np.zeros(3)]
    for _ in range(3):
        rho = RNG.uniform(0.6, 0.8, 3)
        res = optkin.forward(m, rho, guess=[0, 0, 0.7, 0, 0, 0])
        assert res.success
        R, p = res.pose[:3, :3], res.pose[:3, 3]
        for i in range(3):
            Pi = p + R @ (0.4 * u[i])
            di = R @ u[i]  # the platform slider's direction
            # the centre C = (u_i, s_i) = P_i + t d_i: solve the x-y components for t
            t = np.linalg.lstsq(di[:2, None], u[i, :2] - Pi[:2], rcond=None)[0][0]
            assert np.allclose(Pi[:2] + t * di[:2], u[i, :2], atol=1e-9)
            assert abs(Pi[2] + t * di[2] - rho[i]) < 1e-9
        sols = optkin.inverse(m, res.pose)
        assert any(np.allclose(s.qa, rho, atol=1e-9) for s in sols)
    assert optkin.dof(m).mobility == 3


def _prr3():
    return M.prr3([[0, 0], [2, 0], [1, 2.0]], [[1, 0], [0, 1], [-1, 0.0]],
                  [[-0.2, -0.1], [0.2, -0.1], [0, 0.2]], 1.5)


#: (factory, a pose to solve by inverse, or actuated values to solve by forward)
CONFIGS = {
    "prr3": (_prr3, ("pose", [1.0, 1.0, 0.1])),
    "hexa": (M.hexa, ("pose", [0.01, -0.02, -0.6, 0.05, -0.03, 0.1])),
    "pus6": (M.pus6, ("pose", [0.02, 0.01, 0.6, 0.04, 0.02, -0.1])),
    "rps3": (M.rps3, ("qa", [1.0, 1.05, 1.1])),
    "psp3": (M.psp3, ("qa", [0.7, 0.72, 0.68])),
    "upu3": (M.upu3, ("qa", [1.1, 1.15, 1.2])),
}


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_jacobians_against_finite_differences(name):
    """x_dot = W q_a_dot [7.51] against central differences of forward."""
    factory, (how, value) = CONFIGS[name]
    m = factory()
    if how == "pose":
        sol = optkin.inverse(m, value)[0]
    else:
        sol = optkin.forward(m, value, guess=[0, 0, 0.9, 0, 0, 0])
    assert sol.success, sol.message
    jac = optkin.jacobians(m, sol)
    h = 1e-6
    for k in range(len(sol.qa)):
        dq = np.zeros(len(sol.qa))
        dq[k] = h
        xp = optkin.forward(m, sol.qa + dq, guess=sol).x
        xm = optkin.forward(m, sol.qa - dq, guess=sol).x
        assert np.allclose(jac.W_x[:, k], (xp - xm) / (2 * h), atol=1e-6), (name, k)
