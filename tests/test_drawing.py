"""Drawings of legs written as chains: a 3-UPU from its leg type, legs from their screws.

Independent evidence: the base points and the platform points (in the platform frame) are
the numbers the mechanisms are built from; where the platform is comes from the solved
pose; an elbow lies at its link length from the base (written here, not read from optkin).
"""

from __future__ import annotations

import numpy as np
import pytest

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
    fig = draw(m, rs, str(png))
    assert png.stat().st_size > 5000
    # spatial panels: 3-D axes, labelled, equal ranges in x, y and z (a cube), the ranges
    # holding every joint of both configurations
    assert len(fig.axes) == 2 and all(a.name == "3d" for a in fig.axes)
    pts = np.vstack([np.vstack(chain_points(m, r)) for r in rs])
    for a in fig.axes:
        assert (a.get_xlabel(), a.get_ylabel(), a.get_zlabel()) == ("x", "y", "z")
        lims = np.array([a.get_xlim(), a.get_ylim(), a.get_zlim()])
        assert np.allclose(np.diff(lims, axis=1), np.diff(lims, axis=1)[0])
        assert np.all(lims[:, 0] <= pts.min(axis=0)) and np.all(lims[:, 1] >= pts.max(axis=0))


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


def _rpr3_modes():
    m = optkin.mechanisms.rpr3([[0, 0], [10, 0], [5, 8.66]], [[-2, -1.15], [2, -1.15],
                                                            [0, 2.31]])
    return m, list(optkin.assembly_modes(m, [7.0, 6.5, 6.0]))


def test_draw_returns_a_figure_and_writes_only_when_asked(tmp_path):
    """No path: a Figure and no file; a path: the file at the asked resolution, and no
    pyplot figure left open (a batch of pictures must not accumulate them)."""
    import matplotlib.pyplot as plt
    from PIL import Image

    m, modes = _rpr3_modes()
    assert len(modes) >= 2
    before = set(plt.get_fignums())
    png = tmp_path / "modes.png"
    fig = draw(m, modes[:2], png, dpi=150)
    assert set(plt.get_fignums()) == before  # kept out of pyplot
    w, h = Image.open(png).size
    fw, fh = fig.get_size_inches()
    assert (w, h) == (round(fw * 150), round(fh * 150))
    assert list(tmp_path.iterdir()) == [png]
    fig2 = draw(m, modes[0])  # interactive: a pyplot figure, nothing written
    assert fig2.number in plt.get_fignums() and list(tmp_path.iterdir()) == [png]
    plt.close(fig2)
    # a panel: labelled equal axes, a legend naming legs, platform and fixed joints, the
    # platform polygon closed and its three vertices the platform points of the pose
    a = fig.axes[0]
    assert (a.get_xlabel(), a.get_ylabel()) == ("x", "y") and a.get_aspect() == 1.0
    labels = fig.legends[0].get_texts()
    assert [t.get_text() for t in labels] == ["leg chains", "platform", "base", "fixed joints"]
    plat = chain_points(m, modes[0])[3]
    assert np.allclose(plat[0], plat[-1]) and len(plat) == 4


def test_draw_into_the_callers_axes(tmp_path):
    """ax=: every configuration overlaid in the given Axes, one legend entry each; the
    wrong kind of Axes is refused with a message naming the fix."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m, modes = _rpr3_modes()
    fig, ax = plt.subplots()
    try:
        out = draw(m, modes, ax=ax, title="assembly modes")
        assert out is fig and ax.get_title() == "assembly modes"
        texts = [t.get_text() for t in ax.get_legend().get_texts()]
        assert texts == [f"#{i + 1}" for i in range(len(modes))]
        assert list(tmp_path.iterdir()) == []
    finally:
        plt.close(fig)
    fig3 = plt.figure()
    try:
        ax3 = fig3.add_subplot(projection="3d")
        try:
            draw(m, modes[0], ax=ax3)
        except optkin.MechanismError as e:
            assert "projection='3d'" in str(e) and "planar" in str(e)
        else:
            raise AssertionError("3-D Axes accepted for a planar mechanism")
    finally:
        plt.close(fig3)


def _crossings(poly2d):
    """Pairs of non-adjacent edges of a closed polygon (k+1, 2) that cross (written here:
    the signs of the orientation determinants)."""
    def orient(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    E = [(poly2d[i], poly2d[i + 1]) for i in range(len(poly2d) - 1)]
    out = 0
    for i in range(len(E)):
        for j in range(i + 2, len(E)):
            if i == 0 and j == len(E) - 1:
                continue  # adjacent through the closing vertex
            (p, q), (r, s) = E[i], E[j]
            if orient(p, q, r) * orient(p, q, s) < 0 and orient(r, s, p) * orient(r, s, q) < 0:
                out += 1
    return out


def test_stewart_platform_polygon_is_simple():
    """A 6-6 platform whose legs are numbered out of angular order: in leg order its
    hexagon crosses itself; drawn, the platform's polygon (in the platform's plane) does
    not, and it still visits every platform point once."""
    ang_b = np.deg2rad([0, 180, 60, 240, 120, 300])  # leg order jumps across the circle
    ang_p = ang_b + np.deg2rad(20)
    A = np.c_[np.cos(ang_b), np.sin(ang_b), np.zeros(6)]
    B = 0.5 * np.c_[np.cos(ang_p), np.sin(ang_p), np.zeros(6)]
    m = optkin.mechanisms.stewart_gough(A, B)
    p = np.array([0.05, -0.02, 1.0])
    L = np.linalg.norm(p + B - A, axis=1)
    r = optkin.forward(m, L, guess=np.r_[p, 1.0, 0, 0, 0])
    assert r.success
    leg_order = np.vstack([B, B[:1]])[:, :2]
    assert _crossings(leg_order) > 0  # the trap is real
    poly = chain_points(m, r)[6]
    R, t = np.asarray(r.pose)[:3, :3], np.asarray(r.pose)[:3, 3]
    local = (poly - t) @ R  # back into the platform frame (its plane z = 0)
    assert np.allclose(local[:, 2], 0, atol=1e-9)
    assert _crossings(local[:, :2]) == 0
    assert np.allclose(local[0], local[-1])
    got = {tuple(np.round(v, 9)) for v in local[:-1, :2]}
    assert got == {tuple(np.round(v, 9)) for v in B[:, :2]}


def test_animate_a_tracked_motion(tmp_path):
    """A 3-RPR tracked along a path of leg lengths: a GIF of the asked number of frames at
    the asked size, whose frames differ (the mechanism moves); the platform origin's trail
    ends at the last pose; a wrong suffix is refused naming the fix, and nothing is
    written without a path."""
    from PIL import Image, ImageChops

    from optkin.plot import animate

    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.5, 0.9]],
                               [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    r = optkin.forward(m, optkin.inverse(m, [0.45, 0.35, 0.1])[0].qa, guess=[0.4, 0.3, 0.0])
    motion = optkin.track(m, np.linspace(r.qa, r.qa * [1.2, 0.9, 1.1], 40), guess=r)
    assert all(s.success for s in motion)
    gif = tmp_path / "motion.gif"
    anim = animate(m, motion, gif, frames=8, dpi=50)
    im = Image.open(gif)
    assert im.n_frames == 8 and im.size == (round(5.4 * 50), round(5.0 * 50))
    first = im.convert("RGB")
    im.seek(7)
    assert ImageChops.difference(first, im.convert("RGB")).getbbox() is not None
    trail = [ln for ln in anim._fig.axes[0].lines if ln.get_label() == "platform origin"][0]
    x, y = trail.get_data()
    assert np.allclose([x[-1], y[-1]], np.asarray(motion[-1].pose)[:2, 3])
    with pytest.raises(optkin.MechanismError, match=r"\.gif or \.mp4"):
        animate(m, motion, tmp_path / "motion.png")
    import matplotlib.pyplot as plt

    shown = animate(m, motion, frames=3)  # for a notebook: nothing written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["motion.gif"]
    shown._draw_was_started = True  # (not shown here: no warning at its deletion)
    plt.close(shown._fig)


def test_animate_a_spatial_batch(tmp_path):
    """A 6-6 platform lifted along z by forward_batch: a 3-D animation of its rows."""
    from PIL import Image

    from optkin.plot import animate

    ang = np.deg2rad([0, 60, 120, 180, 240, 300])
    A = np.c_[np.cos(ang - 0.2), np.sin(ang - 0.2), np.zeros(6)]
    B = 0.5 * np.c_[np.cos(ang + 0.3), np.sin(ang + 0.3), np.zeros(6)]
    m = optkin.mechanisms.stewart_gough(A, B)
    Z = np.linspace(0.9, 1.2, 6)
    QA = np.array([np.linalg.norm([0, 0, z] + B - A, axis=1) for z in Z])
    batch = optkin.forward_batch(m, QA, guess=np.r_[0, 0, 0.9, 1.0, 0, 0, 0])
    assert np.all(batch.closed) and batch.success
    gif = tmp_path / "lift.gif"
    anim = animate(m, batch, gif, dpi=40)
    assert Image.open(gif).n_frames == 6 and anim._fig.axes[0].name == "3d"
