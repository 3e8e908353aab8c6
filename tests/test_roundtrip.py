"""Inverse then forward for every library mechanism, against leg equations written here."""

from __future__ import annotations

import numpy as np

import optkin
from optkin import mechanisms as M
from optkin.mechanism.geometry import rpy_to_matrix, wrap_angle

RNG = np.random.default_rng(7)

RPR_BASE = [[0.0, 0.0], [1.0, 0.0], [0.5, 0.9]]
RPR_PLAT = [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]  # not similar to the base
ang_b = np.deg2rad([0, 60, 120, 180, 240, 300]) + np.deg2rad([10, -10] * 3)
ang_p = np.deg2rad([30, 90, 150, 210, 270, 330]) + np.deg2rad([-15, 15] * 3)
SG_BASE = np.c_[np.cos(ang_b), np.sin(ang_b), np.zeros(6)]
SG_PLAT = 0.5 * np.c_[np.cos(ang_p), np.sin(ang_p), np.zeros(6)]


def _pose_planar(x, y, phi):
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    return R, np.array([x, y])


def _rho_planar(base, plat, x, y, phi):
    # Modern Robotics 7.1.1: s_i^2 = (p_x + b_ix cos phi - b_iy sin phi - a_ix)^2 + (...)^2
    out = []
    for (ax, ay), (bx, by) in zip(base, plat):
        sx = x + bx * np.cos(phi) - by * np.sin(phi) - ax
        sy = y + bx * np.sin(phi) + by * np.cos(phi) - ay
        out.append(np.hypot(sx, sy))
    return np.array(out)


def _roundtrip(m, sols, n_expected=None):
    assert len(sols) > 0, sols.info
    if n_expected is not None:
        assert len(sols) == n_expected
    passive = ~np.array(m.actuated)
    for s in sols:
        assert s.success, s.message
        g = s.q[passive] + RNG.uniform(-0.05, 0.05, passive.sum())  # perturbed by 0.05 rad
        f = optkin.forward(m, s.qa, guess=g)
        assert f.success, f.message
        np.testing.assert_allclose(f.pose, s.pose, atol=1e-9)


def test_rpr3_inverse_leg_lengths_and_roundtrip():
    m = M.rpr3(RPR_BASE, RPR_PLAT)
    for _ in range(20):
        x, y, phi = RNG.uniform(0.3, 0.6), RNG.uniform(0.25, 0.45), RNG.uniform(-0.6, 0.6)
        sols = optkin.inverse(m, [x, y, phi])
        assert len(sols) == 1
        if sols[0].cond > 30:  # keep to nonsingular poses
            continue
        np.testing.assert_allclose(sols[0].qa, _rho_planar(RPR_BASE, RPR_PLAT, x, y, phi),
                                   atol=1e-12)
        _roundtrip(m, sols, 1)


def test_stewart_gough_inverse_leg_lengths_and_roundtrip():
    m = M.stewart_gough(SG_BASE, SG_PLAT)
    for _ in range(5):
        p = np.array([RNG.uniform(-0.1, 0.1), RNG.uniform(-0.1, 0.1), RNG.uniform(0.8, 1.2)])
        rpy = RNG.uniform(-0.2, 0.2, 3)
        sols = optkin.inverse(m, np.r_[p, rpy])
        R = rpy_to_matrix(*rpy)
        # Modern Robotics 7.1.2: s_i = p + R b_i - a_i, rho_i = |s_i|
        rho = np.linalg.norm(p + SG_PLAT @ R.T - SG_BASE, axis=1)
        np.testing.assert_allclose(sols[0].qa, rho, atol=1e-12)
        _roundtrip(m, sols, 1)


def test_five_bar_four_postures_and_closed_form():
    L = (1.0, 1.0, 1.0, 1.0, 1.0)
    m = M.five_bar(*L)
    for _ in range(5):
        P = np.array([RNG.uniform(0.3, 0.7), RNG.uniform(0.8, 1.3)])
        sols = optkin.inverse(m, P)
        assert len(sols) == 4
        assert len({s.working_mode for s in sols}) == 4
        for s in sols:
            t1, t2 = s.qa
            C = np.array([L[1] * np.cos(t1), L[1] * np.sin(t1)])
            D = np.array([L[0], 0.0]) + L[4] * np.array([np.cos(t2), np.sin(t2)])
            assert abs(np.linalg.norm(P - C) - L[2]) < 1e-12
            assert abs(np.linalg.norm(P - D) - L[3]) < 1e-12
        _roundtrip(m, sols, 4)


def test_rrr3_eight_postures_and_distal_lengths():
    m = M.rrr3(RPR_BASE, RPR_PLAT, 0.45, 0.45)
    x, y, phi = 0.5, 0.4, 0.2
    sols = optkin.inverse(m, [x, y, phi])
    assert len(sols) == 8
    R, p = _pose_planar(x, y, phi)
    for s in sols:
        for i in range(3):
            th = s.qa[i]
            C = np.array(RPR_BASE[i]) + 0.45 * np.array([np.cos(th), np.sin(th)])
            P = p + R @ np.array(RPR_PLAT[i])
            assert abs(np.linalg.norm(P - C) - 0.45) < 1e-12
    _roundtrip(m, sols, 8)


def test_delta_postures_and_forearm_lengths():
    m = M.delta(0.2, 0.05, 0.3, 0.8)
    for _ in range(4):
        p = np.array([RNG.uniform(-0.1, 0.1), RNG.uniform(-0.1, 0.1), RNG.uniform(-0.85, -0.6)])
        sols = optkin.inverse(m, p)
        assert len(sols) == 8
        for s in sols:
            for i in range(3):
                a = 2 * np.pi * i / 3
                u = np.array([np.cos(a), np.sin(a), 0.0])
                th = s.qa[i]
                # elbow: arm turns from radial (theta=0) downwards
                C = 0.2 * u + 0.3 * (np.cos(th) * u - np.sin(th) * np.array([0, 0, 1.0]))
                P = p + 0.05 * u
                assert abs(np.linalg.norm(P - C) - 0.8) < 1e-12
        _roundtrip(m, sols, 8)


def _khalil_roundtrip(m, qa, guess):
    ref = optkin.forward(m, qa, guess=guess)
    assert ref.success, ref.message
    sols = optkin.inverse(m, ref.pose)
    assert sols.info["success"]
    # the configuration we started from is one of the postures
    d = [np.max(np.abs(wrap_angle(s.q - ref.q))) for s in sols]
    assert min(d) < 1e-7
    _roundtrip(m, sols)
    return sols


def test_four_bar_inverse_two_postures():
    m = M.four_bar(1.0, 2.0, 2.0, 2.5)
    sols = _khalil_roundtrip(m, [0.8], None)
    assert len(sols) == 2  # two crank angles for a rocker angle inside its range


def test_sr400_inverse_contains_start_and_roundtrips():
    m = M.sr400()
    qa = np.array([0.3, -0.4, 0.2, 0.5, 0.4, 0.6])
    sols = _khalil_roundtrip(m, qa, [np.pi / 2 + 1.0, -1.0, np.pi + 1.0])
    # spherical wrist x elbow x shoulder = 8 serial postures, each with the parallelogram
    # or anti-parallelogram loop branch
    assert len(sols) == 16


def test_akr3000_inverse_roundtrip():
    m = M.akr3000()
    ref = {"theta2": 1.0, "theta3": 0.9, "theta4": 1.1, "theta7": -1.0}
    table = m.table
    q = {n: 0.0 for n in m.joint_names}
    q.update(ref, theta1=0.2, theta8=0.3, theta9=0.4, theta10=0.5)
    O = {j: table.transform_0(j, q)[:3, 3] for j in (3, 4, 13, 14)}
    q["r5"] = float(np.linalg.norm(O[13] - O[3]))
    q["r6"] = float(np.linalg.norm(O[14] - O[4]))
    qa = [q[n] for n in m.active_names]
    sols = _khalil_roundtrip(m, qa, None)
    # the path theta1, theta2, theta7 + spherical wrist (frames 8-10 share an origin) has
    # 2 x 2 x 2 = 8 solutions; for each, each loop closes with the cylinder length +- |d|,
    # and only the positive lengths are postures (limits r5, r6 >= 0): 8 kept, 24 left out
    assert len(sols) == 8
    assert sols.info["outside_limits"] == 24
    i5, i6 = m.joint_names.index("r5"), m.joint_names.index("r6")
    assert all(s.q[i5] > 0 and s.q[i6] > 0 for s in sols)


def test_unreachable_leg_lengths_fail_cleanly():
    m = M.rpr3(RPR_BASE, RPR_PLAT)
    r = optkin.forward(m, [0.01, 0.01, 0.01])
    assert not r.success
    assert r.status in ("infeasible", "iteration_limit", "error")
    assert "reach" in r.message or "close" in r.message
    d = r.to_dict()
    assert d["success"] is False


def test_unreachable_pose_gives_empty_set():
    m = M.five_bar(1, 1, 1, 1, 1)
    sols = optkin.inverse(m, [0.5, 5.0])
    assert len(sols) == 0
    assert "cannot reach" in sols.info["message"]


def test_results_carry_their_task_coordinates_by_name():
    """KinResult.task: the six numbers a user gives a spatial platform (not the quaternion
    in x), with roll, pitch, yaw checked against scipy's Rotation (Rz(yaw) Ry(pitch)
    Rx(roll) is from_euler("ZYX", [yaw, pitch, roll])); a planar platform's (x, y, phi)
    from its legs' forward model; a Khalil table's named components."""
    from scipy.spatial.transform import Rotation

    sg = M.stewart_gough(SG_BASE, SG_PLAT)
    t = {"x": 0.05, "y": -0.03, "z": 1.0, "roll": 0.1, "pitch": -0.05, "yaw": 0.2}
    R = Rotation.from_euler("ZYX", [t["yaw"], t["pitch"], t["roll"]]).as_matrix()
    p = np.array([t["x"], t["y"], t["z"]])
    legs = np.linalg.norm(p + SG_PLAT @ R.T - SG_BASE, axis=1)  # the leg equations
    r = optkin.forward(sg, legs, guess=np.r_[p, 1.0, 0.0, 0.0, 0.0] + 0.01)
    assert r.success and len(r.x) == 7  # x holds a quaternion
    assert list(r.task) == ["x", "y", "z", "roll", "pitch", "yaw"]
    assert np.allclose([r.task[k] for k in t], list(t.values()), atol=1e-9)
    assert np.allclose(r.pose[:3, :3], R, atol=1e-9)
    assert r.to_dict()["task"] == r.task

    m = M.rpr3(RPR_BASE, RPR_PLAT)
    x, y, phi = 0.45, 0.35, 0.1
    rf = optkin.forward(m, _rho_planar(RPR_BASE, RPR_PLAT, x, y, phi), guess=[0.4, 0.3, 0.0])
    assert rf.success and list(rf.task) == ["x", "y", "phi"]
    assert np.allclose(list(rf.task.values()), [x, y, phi], atol=1e-9)

    sr = M.sr400()
    q = optkin.forward(sr, [0.3, -0.4, 0.2, 0.5, 0.4, 0.6], guess=[np.pi / 2 + 1, -1, np.pi + 1])
    assert tuple(q.task) == tuple(sr.task)
    assert np.allclose([q.task["x"], q.task["y"], q.task["z"]], q.pose[:3, 3])
