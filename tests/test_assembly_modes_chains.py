"""Assembly modes of legs written as chains (Leg.from_screws, UPU, RPS, PRS, PSP, PUS, PRR)
and the bounds read from the structure.

Evidence written here, independent of optkin's model:

* the library 3-RPR and Stewart-Gough platforms (distance legs, reduced form) solve the
  same problems: a leg written as a chain of screws with ``Leg.from_screws`` must give
  the same platform poses (the assembly modes; the legs' joint values are postures);
* Tsai's 3-UPU: every returned configuration is checked by the product of exponentials of
  each leg (Modern Robotics (4.14), Rodrigues' formula in numpy) against the platform pose,
  and the translational solutions against the intersection of the three spheres
  |p + b_i - a_i| = rho_i (trilateration in numpy);
* the other chain legs: a configuration closed by ``forward`` is one of the modes.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_assembly_modes import _random_rpr

import optkin
from optkin import Leg, Mechanism
from optkin.mechanism.geometry import rpy_to_matrix
from optkin.mechanism.legs import prismatic_screw, revolute_screw
from optkin.solvers.enumerate import known_bound

# ---------------------------------------------------------------------------------------------
# legs from screws
# ---------------------------------------------------------------------------------------------


def rpr3_screws(a, b) -> Mechanism:
    """3-RPR: base revolute at a_i, prismatic along the leg, revolute at the platform point;
    at home (every joint zero) the leg has length 0 along x and b_i sits on a_i."""
    legs = []
    for ai, bi in zip(a, b):
        a3, b3 = np.r_[ai, 0.0], np.r_[bi, 0.0]
        S = [revolute_screw([0, 0, 1], a3), prismatic_screw([1, 0, 0]),
             revolute_screw([0, 0, 1], a3)]
        home = np.eye(4)
        home[:3, 3] = a3 - b3
        legs.append(Leg.from_screws(S, home, actuated=1, joints="RPR"))
    return Mechanism.from_legs(legs, "planar", name="3-RPR (screws)")


def ups6_screws(a, b) -> Mechanism:
    """6-UPS: universal joint at a_i (axes x, y), prismatic along z, spherical (x, y, z) at
    the platform point, which is at a_i at home (length 0)."""
    X, Y, Z = np.eye(3)
    legs = []
    for ai, bi in zip(a, b):
        S = [revolute_screw(X, ai), revolute_screw(Y, ai), prismatic_screw(Z),
             revolute_screw(X, ai), revolute_screw(Y, ai), revolute_screw(Z, ai)]
        home = np.eye(4)
        home[:3, 3] = np.asarray(ai) - np.asarray(bi)
        legs.append(Leg.from_screws(S, home, actuated=2, joints="UPS"))
    return Mechanism.from_legs(legs, "spatial", name="6-UPS (screws)")


def _pose_gap(T1, T2) -> float:
    return float(np.max(np.abs(np.asarray(T1) - np.asarray(T2))))


def _same_poses(A, B, tol):
    """One-to-one match of the poses of two solution sets; the largest distance."""
    assert len(A) == len(B), (len(A), len(B))
    worst, used = 0.0, set()
    for ra in A:
        d = [(_pose_gap(ra.pose, rb.pose), j) for j, rb in enumerate(B) if j not in used]
        dmin, j = min(d)
        used.add(j)
        worst = max(worst, dmin)
    assert worst < tol, worst
    return worst


def test_rpr3_from_screws_has_the_modes_of_the_library_rpr3():
    rng = np.random.default_rng(11)
    for trial in range(3):
        a, b, s = _random_rpr(rng)
        lib = optkin.assembly_modes(optkin.mechanisms.rpr3(a, b), s, seed=trial)
        chain = optkin.assembly_modes(rpr3_screws(a, b), s, seed=trial)
        assert lib.info["bound"] == 6 and chain.info["bound"] is None
        _same_poses(lib, chain, 1e-9)
        for r in chain:
            assert r.success and r.residual < 1e-9


def _random_stewart(rng):
    a = rng.uniform(-1, 1, (6, 3))
    b = rng.uniform(-0.6, 0.6, (6, 3))
    R0 = rpy_to_matrix(*rng.uniform(-0.4, 0.4, 3))
    p0 = np.array([*rng.uniform(-0.2, 0.2, 2), 0.9])
    s = np.linalg.norm(p0 + b @ R0.T - a, axis=1)
    T0 = np.eye(4)
    T0[:3, :3], T0[:3, 3] = R0, p0
    return a, b, s, T0


def test_stewart_gough_from_screws_has_the_modes_of_the_library_platform():
    rng = np.random.default_rng(7)
    for trial in range(2):
        a, b, s, T0 = _random_stewart(rng)
        lib = optkin.assembly_modes(optkin.mechanisms.stewart_gough(a, b), s, seed=trial)
        chain = optkin.assembly_modes(ups6_screws(a, b), s, seed=trial)
        assert min(_pose_gap(r.pose, T0) for r in lib) < 1e-9  # the generating pose
        _same_poses(lib, chain, 1e-9)
        for r in chain:
            assert r.success and r.residual < 1e-9


def test_general_closure_and_distance_form_give_the_same_modes():
    """The reduced one-row form of distance legs and their joint-level chains (reduced=False)
    enumerate the same platform poses."""
    rng = np.random.default_rng(2)
    a, b, s = _random_rpr(rng)
    legs = [{"type": "RPR", "base": ai.tolist(), "platform": bi.tolist()} for ai, bi in zip(a, b)]
    red = optkin.assembly_modes(Mechanism.from_legs(legs, "planar"), s)
    full = optkin.assembly_modes(Mechanism.from_legs(legs, "planar", reduced=False), s)
    assert red.info["bound"] == 6 and full.info["bound"] is None
    _same_poses(red, full, 1e-9)


# ---------------------------------------------------------------------------------------------
# Tsai's 3-UPU
# ---------------------------------------------------------------------------------------------

_ANG = (92.0, 207.0, 338.0)
_RB, _RP = (1.0, 1.1, 0.93), (0.45, 0.41, 0.5)


def _circle(r, deg):
    t = np.deg2rad(deg)
    return np.array([r * np.cos(t), r * np.sin(t), 0.0])


def _tangent(deg):
    t = np.deg2rad(deg)
    return np.array([-np.sin(t), np.cos(t), 0.0])


def upu3_geometry():
    """Base and platform points, first (base-fixed) axes tangent to the base circle and
    second axes radial inwards (so that the legs leave upwards), Tsai's arrangement."""
    A = np.array([_circle(r, t) for r, t in zip(_RB, _ANG)])
    B = np.array([_circle(r, t) for r, t in zip(_RP, _ANG)])
    axis = np.array([_tangent(t) for t in _ANG])
    arm = -np.array([_circle(1.0, t) for t in _ANG])
    return A, B, axis, arm


def upu3() -> Mechanism:
    A, B, axis, arm = upu3_geometry()
    legs = [{"type": "UPU", "base": A[i].tolist(), "platform": B[i].tolist(),
             "axis": axis[i].tolist(), "arm": arm[i].tolist()} for i in range(3)]
    return Mechanism.from_legs(legs, "spatial", name="3-UPU")


def _exp(w, q, theta):
    """exp([S] theta) of a rotation about the unit axis w through q (Rodrigues), 4x4."""
    K = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    R = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, q - R @ q
    return T


def _slide(v, s):
    T = np.eye(4)
    T[:3, 3] = s * np.asarray(v)
    return T


def upu_leg_frame(A, b, a1, a2, q):
    """The platform frame reached through one UPU leg: Rot(a1, ua) Rot(a2, ub) at A, slide
    rho along a1 x a2, then Rot(a2, va) Rot(a1, vb) about the axes through A at home, and
    the home pose (identity rotation, b at A)."""
    ua, ub, rho, va, vb = q
    M = np.eye(4)
    M[:3, 3] = A - b
    return (_exp(a1, A, ua) @ _exp(a2, A, ub) @ _slide(np.cross(a1, a2), rho)
            @ _exp(a2, A, va) @ _exp(a1, A, vb) @ M)


def three_spheres(c, r):
    """The (two) points at distances r_i from the centres c_i (trilateration)."""
    ex = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
    i = ex @ (c[2] - c[0])
    ey = c[2] - c[0] - i * ex
    ey /= np.linalg.norm(ey)
    ez = np.cross(ex, ey)
    d = np.linalg.norm(c[1] - c[0])
    j = ey @ (c[2] - c[0])
    x = (r[0] ** 2 - r[1] ** 2 + d * d) / (2 * d)
    y = (r[0] ** 2 - r[2] ** 2 + i * i + j * j) / (2 * j) - i * x / j
    z2 = r[0] ** 2 - x * x - y * y
    z = np.sqrt(max(z2, 0.0))
    base = c[0] + x * ex + y * ey
    return [base + z * ez, base - z * ez]


def test_tsai_3upu_modes_close_every_loop_and_its_translations_are_the_sphere_points():
    A, B, axis, arm = upu3_geometry()
    m = upu3()
    p0 = np.array([0.04, -0.03, 0.7])
    rho = np.linalg.norm(p0 + B - A, axis=1)  # a translated platform: legs along p + b - a
    modes = optkin.assembly_modes(m, rho, seed=0)
    assert len(modes) >= 2 and modes.info["bound"] is None
    trans = []
    for r in modes:
        assert r.success and r.residual < 1e-9
        T = r.pose
        for k in range(3):  # every loop closes: each leg reaches the platform frame
            Tk = upu_leg_frame(A[k], B[k], axis[k], arm[k], r.q[5 * k: 5 * k + 5])
            assert _pose_gap(Tk, T) < 1e-9, (k, _pose_gap(Tk, T))
            assert abs(r.q[5 * k + 2] - rho[k]) < 1e-12
        if np.max(np.abs(T[:3, :3] - np.eye(3))) < 1e-9:
            trans.append(T[:3, 3])
    ref = three_spheres(A - B, rho)
    assert len(trans) == 2
    for p in ref:
        assert min(np.max(np.abs(t - p)) for t in trans) < 1e-9
    assert min(np.max(np.abs(t - p0)) for t in trans) < 1e-9


# ---------------------------------------------------------------------------------------------
# other chain legs, mixed legs
# ---------------------------------------------------------------------------------------------


def _three(kind, **extra):
    return [{"type": kind, "base": _circle(rb, t).tolist(), "platform": _circle(rp, t + d).tolist(),
             **{k: (v(t) if callable(v) else v) for k, v in extra.items()}}
            for rb, rp, t, d in zip(_RB, _RP, _ANG, (3.0, -6.0, 5.0))]


def rps3():
    return Mechanism.from_legs(_three("RPS", axis=lambda t: _tangent(t).tolist()), "spatial")


def prs3():
    return Mechanism.from_legs(_three("PRS", direction=[0.0, 0.0, 1.0],
                                      axis=lambda t: _tangent(t).tolist(), lengths=[0.8]),
                               "spatial")


def psp3():
    return Mechanism.from_legs(_three("PSP", direction=[0.0, 0.0, 1.0],
                                      axis=lambda t: _circle(1.0, t).tolist()), "spatial")


def pus6():
    ab, ap = (10, 110, 130, 230, 250, 350), (50, 70, 170, 190, 290, 310)
    legs = [{"type": "PUS", "base": _circle(1.0, a).tolist(), "platform": _circle(0.4, b).tolist(),
             "direction": [0.0, 0.0, 1.0], "lengths": [0.9]} for a, b in zip(ab, ap)]
    return Mechanism.from_legs(legs, "spatial")


def prr3():
    legs = [{"type": "PRR", "base": _circle(rb, t)[:2].tolist(),
             "platform": _circle(rp, t + 4.0)[:2].tolist(),
             "direction": _tangent(t)[:2].tolist(), "lengths": [0.7]}
            for rb, rp, t in zip(_RB, _RP, _ANG)]
    return Mechanism.from_legs(legs, "planar")


def mixed_prr_rpr():
    a, b, _ = _random_rpr(np.random.default_rng(4))
    legs = [{"type": "PRR", "base": a[0].tolist(), "platform": b[0].tolist(),
             "direction": [1.0, 0.0], "lengths": [0.9]},
            {"type": "RPR", "base": a[1].tolist(), "platform": b[1].tolist()},
            {"type": "RPR", "base": a[2].tolist(), "platform": b[2].tolist()}]
    return Mechanism.from_legs(legs, "planar")


@pytest.mark.parametrize("factory, qa, guess, bound", [
    (rps3, [0.8, 0.85, 0.75], [0.0, 0.0, 0.6, 0, 0, 0], None),
    (prs3, [0.3, 0.35, 0.25], [0.0, 0.0, 0.9, 0, 0, 0], None),
    (psp3, [0.3, 0.35, 0.25], [0.0, 0.0, 0.3, 0, 0, 0], None),
    (pus6, [0.2, 0.25, 0.2, 0.3, 0.25, 0.2], [0.0, 0.0, 1.0, 0, 0, 0], 40),
    (prr3, [0.1, -0.1, 0.05], [0.0, 0.0, 0.0], 6),
    (mixed_prr_rpr, [0.1, 0.9, 1.0], None, 6),
], ids=["3-RPS", "3-PRS", "3-PSP", "6-PUS", "3-PRR", "PRR+2RPR"])
def test_chain_legs_modes_hold_a_configuration_closed_by_forward(factory, qa, guess, bound):
    m = factory()
    r0 = optkin.forward(m, qa, guess=guess)
    if not r0.success:  # the mixed platform: find a closed configuration first
        r0 = optkin.assembly_modes(m, qa, seed=1)[0]
    modes = optkin.assembly_modes(m, r0.qa, seed=0)
    assert modes.info["bound"] == bound
    assert len(modes) >= 1 and all(r.success and r.residual < 1e-9 for r in modes)
    assert min(_pose_gap(r.pose, r0.pose) for r in modes) < 1e-9
    for i, r in enumerate(modes):  # distinct platform poses
        assert all(_pose_gap(r.pose, modes[j].pose) > 1e-7 for j in range(i))


# ---------------------------------------------------------------------------------------------
# bounds and working modes from the structure
# ---------------------------------------------------------------------------------------------


def test_known_bounds_come_from_the_structure():
    M = optkin.mechanisms
    a, b, _ = _random_rpr(np.random.default_rng(0))
    legs = [{"type": "RPR", "base": ai.tolist(), "platform": bi.tolist()} for ai, bi in zip(a, b)]
    assert known_bound(M.rpr3(a, b)) == 6
    assert known_bound(M.rrr3(a, b, 0.6, 0.6)) == 6
    assert known_bound(prr3()) == 6 and known_bound(mixed_prr_rpr()) == 6
    rng = np.random.default_rng(1)
    assert known_bound(M.stewart_gough(rng.uniform(-1, 1, (6, 3)), rng.uniform(-1, 1, (6, 3)))) == 40
    assert known_bound(pus6()) == 40
    assert known_bound(M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)) == 2
    assert known_bound(M.delta()) == 2
    # chains, redundant actuation and Khalil tables have no such bound
    assert known_bound(rpr3_screws(a, b)) is None
    assert known_bound(Mechanism.from_legs(legs, "planar", reduced=False)) is None
    assert known_bound(upu3()) is None and known_bound(rps3()) is None
    assert known_bound(M.rpr4(np.r_[a, [[0.5, 0.5]]], np.r_[b, [[0.1, 0.1]]])) is None
    assert known_bound(M.four_bar(1.0, 2.0, 2.0, 2.5)) is None


def test_working_modes_in_the_models_order():
    m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    wm = optkin.working_modes(m)
    assert wm.modes == optkin.get_model(m).working_modes()
    assert wm.modes[0] == (1, 1) and wm.modes[-1] == (-1, -1)
    with pytest.raises(optkin.MechanismError, match="fully parallel"):
        optkin.working_modes(upu3())
