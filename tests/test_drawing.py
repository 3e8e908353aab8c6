"""Drawings of legs written as chains: a 3-UPU from its leg type, legs from their screws.

Independent evidence: the base points and the platform points (in the platform frame) are
the numbers the mechanisms are built from; where the platform is comes from the solved
pose; an elbow lies at its link length from the base (written here, not read from optkin).
"""

from __future__ import annotations

import numpy as np

import optkin
from optkin.mechanism.legs import prismatic_screw, revolute_screw
from optkin.plot import chain_points, draw


def _frame(R, p):
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def _check_legs(mech, r, bases, plat_pts, tol=1e-9):
    """Every leg's polyline starts at its base and ends at its platform point (at the
    solved pose); the platform polygon joins those points."""
    lines = chain_points(mech, r)
    T = np.asarray(r.pose)
    ends = [T[:3, :3] @ np.pad(b, (0, 3 - len(b))) + T[:3, 3] for b in plat_pts]
    for k, (A, P) in enumerate(zip(bases, ends)):
        line = lines[k]
        assert line.shape[1] == 3 and len(line) >= 2
        assert np.allclose(line[0], np.pad(A, (0, 3 - len(A))), atol=tol), (k, line[0], A)
        assert np.allclose(line[-1], P, atol=tol), (k, line[-1], P)
    poly = lines[len(bases)]
    assert np.allclose(poly[:-1], ends, atol=tol) and np.allclose(poly[0], poly[-1])
    return lines


def test_draw_3upu_from_leg_types(tmp_path):
    """Tsai's 3-UPU (UPU legs by type on a spatial platform): two configurations drawn."""
    R_, r_ = 1.0, 0.4
    legs, bases, plats = [], [], []
    for k in range(3):
        a = 2 * np.pi * k / 3
        e = np.array([np.cos(a), np.sin(a), 0.0])
        t = np.array([-np.sin(a), np.cos(a), 0.0])
        bases.append(R_ * e)
        plats.append(r_ * e)
        legs.append({"type": "UPU", "base": (R_ * e).tolist(), "platform": (r_ * e).tolist(),
                     "axis": t.tolist(), "arm": np.cross([0, 0, 1.0], t).tolist()})
    m = optkin.Mechanism.from_legs(legs, "spatial", name="3-UPU")
    rs = []
    for pose in ([0.1, -0.05, 0.8, 0, 0, 0], [-0.2, 0.1, 0.6, 0, 0, 0]):
        s = optkin.inverse(m, pose)
        assert len(s) > 0
        r = s[0]
        assert r.success
        lines = _check_legs(m, r, bases, plats)
        for k in range(3):  # the leg is straight: its prismatic length is |P - A|
            assert abs(np.linalg.norm(lines[k][-1] - lines[k][0])
                       - abs(r.q[5 * k + 2])) < 1e-9
        rs.append(r)
    png = tmp_path / "upu3.png"
    assert draw(m, rs, str(png)) == str(png)
    assert png.stat().st_size > 5000


def test_draw_legs_from_screws(tmp_path):
    """A 3-RRR and a 3-RPR written with Leg.from_screws: polylines from the base through
    the elbow (at its link length) to the platform point."""
    base = np.array([[0, 0], [10, 0], [5, 8.0]])
    plat = np.array([[-1, -0.6], [1, -0.6], [0, 1.0]])
    l1 = l2 = 5.0
    legs = []
    for A, b in zip(base, plat):
        C, E = A + [l1, 0], A + [l1 + l2, 0]
        S = [revolute_screw([0, 0, 1], A), revolute_screw([0, 0, 1], C),
             revolute_screw([0, 0, 1], E)]
        legs.append(optkin.Leg.from_screws(S, _frame(np.eye(3), [*(E - b), 0]), actuated=0,
                                           joints="RRR"))
    m = optkin.Mechanism.from_legs(legs, "planar", name="3-RRR (screws)")
    s = optkin.inverse(m, [5.0, 3.5, 0.2])
    assert len(s) > 0
    for r in list(s)[:3]:
        lines = _check_legs(m, r, base, plat)
        for k in range(3):
            assert len(lines[k]) == 3
            assert abs(np.linalg.norm(lines[k][1] - lines[k][0]) - l1) < 1e-9
            assert abs(np.linalg.norm(lines[k][2] - lines[k][1]) - l2) < 1e-9
    png = tmp_path / "rrr3.png"
    draw(m, list(s)[:4], str(png))
    assert png.stat().st_size > 5000

    base2 = np.array([[0, 0], [1, 0], [0.5, 0.9]])
    plat2 = np.array([[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    legs2 = [optkin.Leg.from_screws(
        [revolute_screw([0, 0, 1], A), prismatic_screw([1, 0]), revolute_screw([0, 0, 1], A)],
        _frame(np.eye(3), [*(A - b), 0]), actuated=1, joints="RPR")
        for A, b in zip(base2, plat2)]
    m2 = optkin.Mechanism.from_legs(legs2, "planar", name="3-RPR (screws)")
    s2 = optkin.inverse(m2, [0.5, 0.4, 0.1])
    assert len(s2) > 0
    r2 = next(r for r in s2 if np.all(r.q[1::3] > 0))
    _check_legs(m2, r2, base2, plat2)
    png2 = tmp_path / "rpr3.png"
    draw(m2, r2, str(png2))
    assert png2.stat().st_size > 5000
