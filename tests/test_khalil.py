"""Khalil-Kleinfinger descriptions: transforms [7.3]/[7.4], SR400 and AKR-3000 closures."""

from __future__ import annotations

import ast
import pathlib

import numpy as np
import pytest

import optkin
from optkin.mechanism import khalil_inverse, khalil_transform
from optkin.mechanism.geometry import rot_x, rot_z, wrap_angle

RNG = np.random.default_rng(20261122)


def _trans(axis: int, v: float) -> np.ndarray:
    T = np.eye(4)
    T[axis, 3] = v
    return T


def _rot(R: np.ndarray) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    return T


def test_transform_is_the_product_of_elementary_motions():
    # [7.2]: Rot(z,gamma) Trans(z,b) Rot(x,alpha) Trans(x,d) Rot(z,theta) Trans(z,r)
    for _ in range(20):
        g, b, a, d, t, r = RNG.uniform(-2, 2, 6)
        ref = (_rot(rot_z(g)) @ _trans(2, b) @ _rot(rot_x(a)) @ _trans(0, d)
               @ _rot(rot_z(t)) @ _trans(2, r))
        np.testing.assert_allclose(khalil_transform(g, b, a, d, t, r), ref, atol=1e-13)


def test_inverse_transform_7_4():
    for gamma in (0.0, 0.7):
        for _ in range(10):
            b, a, d, t, r = RNG.uniform(-2, 2, 5)
            T = khalil_transform(gamma, b, a, d, t, r)
            np.testing.assert_allclose(khalil_inverse(gamma, b, a, d, t, r), np.linalg.inv(T),
                                       atol=1e-12)


def test_description_layer_imports_numpy_only():
    root = pathlib.Path(optkin.__file__).parent / "mechanism"
    for f in root.glob("*.py"):
        tree = ast.parse(f.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            assert not any(n.split(".")[0] in ("casadi", "cvxpy") for n in names), f.name


def test_sr400_split_and_loop_rows():
    m = optkin.mechanisms.sr400()
    # Example 7.6: q_a = (theta1, theta2, theta4, theta5, theta6, theta7), q_p = (theta3, theta8),
    # q_c = (theta9); the parallelogram is planar, so three independent rows.
    assert m.active_names == ("theta1", "theta2", "theta4", "theta5", "theta6", "theta7")
    assert m.passive_names == ("theta3", "theta8")
    assert m.cut_names == ("theta9",)
    assert len(optkin.get_model(m).row_names) == 3


@pytest.mark.parametrize("d", [(0.15, 0.6, 0.1, 0.25, 0.65), (0.3, 0.9, 0.05, 0.4, 0.8),
                               (0.0, 0.5, 0.2, 0.1, 0.5)])
def test_sr400_parallelogram_closed_form(d):
    m = optkin.mechanisms.sr400(*d)
    for _ in range(5):
        qa = RNG.uniform(-1.2, 1.2, 6)
        # keep the parallelogram away from its flat (singular) posture theta2 = theta7,
        # where it meets the anti-parallelogram branch
        qa[5] = qa[1] - RNG.choice([-1, 1]) * RNG.uniform(0.5, 2.6)
        t2, t7 = qa[1], qa[5]
        # guess near the parallelogram posture (not the answer: perturbed)
        guess = np.array([np.pi / 2 - t2 + t7, t2 - t7, np.pi - t2 + t7]) + RNG.normal(0, 0.05, 3)
        r = optkin.forward(m, qa, guess=guess)
        assert r.success, r.message
        q = dict(zip(m.joint_names, r.q))
        # [7.41]-[7.43]
        assert abs(wrap_angle(q["theta3"] - (np.pi / 2 - t2 + t7))) < 1e-9
        assert abs(wrap_angle(q["theta8"] - (t2 - t7))) < 1e-9
        assert abs(wrap_angle(q["theta9"] - (np.pi - t2 + t7))) < 1e-9


def _akr_configuration(m, rng):
    """A closed AKR-3000 configuration built from the numpy tree: each cylinder length is
    the distance between its end points (frames 3->13 and 4->14)."""
    table = m.table
    q = {n: 0.0 for n in m.joint_names}
    q.update(theta1=rng.uniform(-1, 1), theta2=rng.uniform(0.6, 1.6), theta7=rng.uniform(-1.6, -0.6),
             theta8=rng.uniform(-1, 1), theta9=rng.uniform(-1, 1), theta10=rng.uniform(-1, 1))
    O = {j: table.transform_0(j, q)[:3, 3] for j in (3, 4, 13, 14)}
    q["r5"] = float(np.linalg.norm(O[13] - O[3]))
    q["r6"] = float(np.linalg.norm(O[14] - O[4]))
    return q


def test_akr3000_loop_equations():
    m = optkin.mechanisms.akr3000()
    P = m.params
    d3, d4, d7, d13, d14, g14, g13 = (P[k] for k in ("d3", "d4", "d7", "d13", "d14", "g14", "g13"))
    assert m.active_names == ("theta1", "r5", "r6", "theta8", "theta9", "theta10")
    assert m.passive_names == ("theta2", "theta3", "theta4", "theta7")
    assert m.cut_names == ("theta11", "theta12")
    checked = 0
    for _ in range(8):
        ref = _akr_configuration(m, RNG)
        qa = [ref[n] for n in m.active_names]
        guess = np.array([ref[n] for n in m.joint_names])
        passive = ~np.array(m.actuated)
        guess[passive] += RNG.normal(0, 0.05, passive.sum())
        r = optkin.forward(m, qa, guess=guess)
        assert r.success, r.message
        q = dict(zip(m.joint_names, r.q))
        r5, r6 = q["r5"], q["r6"]
        t2p = q["theta2"] + g14  # [7.16]
        # [7.26]
        assert abs(d14**2 + d4**2 - 2 * d4 * d14 * np.cos(t2p) - r6**2) < 1e-9
        # [7.27] with F of [7.23]
        Fx, Fy = np.cos(t2p) * d14 - d4, np.sin(t2p) * d14
        assert abs(-np.sin(q["theta4"]) * r6 - Fx) < 1e-9
        assert abs(np.cos(q["theta4"]) * r6 - Fy) < 1e-9
        # [7.35]
        s11 = np.sin(q["theta11"])
        lhs = r5**2 + d13**2 - 2 * d13 * r5 * s11
        rhs = d7**2 + d3**2 - 2 * d3 * d7 * np.cos(q["theta2"])
        assert abs(lhs - rhs) < 1e-9
        # [7.36] with F of [7.33] (its second entry printed as -S(theta11) r5 in the seed is
        # -C(theta11) r5 when developed: Rot(z,-theta11) maps (0,-r5) to (-r5 S11, -r5 C11))
        t7p = q["theta7"] + g13  # [7.28]
        Fx, Fy = d13 - s11 * r5, -np.cos(q["theta11"]) * r5
        Gx, Gy = np.cos(q["theta2"]) * d3 - d7, -np.sin(q["theta2"]) * d3
        assert abs(np.cos(t7p) * Fx - np.sin(t7p) * Fy - Gx) < 1e-9
        assert abs(np.sin(t7p) * Fx + np.cos(t7p) * Fy - Gy) < 1e-9
        # orientation equations: [7.19] rot(z,theta4) rot(z,theta12) = rot(z,theta2') and [7.30]
        assert abs(wrap_angle(q["theta4"] + q["theta12"] - t2p)) < 1e-9
        assert abs(wrap_angle(q["theta2"] + t7p - q["theta3"] - q["theta11"])) < 1e-9
        checked += 1
    assert checked == 8


def test_four_bar_matches_modern_robotics_7_22():
    L1, L2, L3, L4 = 1.0, 2.0, 2.0, 2.5
    m = optkin.mechanisms.four_bar(L1, L2, L3, L4)
    tested = 0
    for theta in RNG.uniform(-np.pi, np.pi, 12):
        # (7.22)-(7.25): phi = atan2(beta, alpha) +- acos(gamma / sqrt(alpha^2 + beta^2))
        a = 2 * L3 * L4 - 2 * L1 * L3 * np.cos(theta)
        b = -2 * L1 * L3 * np.sin(theta)
        g = L2**2 - L4**2 - L3**2 - L1**2 + 2 * L1 * L4 * np.cos(theta)
        if g**2 >= 0.95 * (a**2 + b**2):
            continue
        for s in (1, -1):
            phi = np.arctan2(b, a) + s * np.arccos(g / np.hypot(a, b))
            B = L1 * np.array([np.cos(theta), np.sin(theta)])
            C = np.array([L4, 0.0]) + L3 * np.array([np.cos(phi), np.sin(phi)])
            th2 = np.arctan2(*(C - B)[::-1]) - theta
            guess = np.array([th2, phi, phi - theta - th2]) + 0.05
            r = optkin.forward(m, [theta], guess=guess)
            assert r.success, r.message
            assert abs(wrap_angle(dict(zip(m.joint_names, r.q))["phi"] - phi)) < 1e-9
            tested += 1
    assert tested >= 6
