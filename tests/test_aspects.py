"""Working modes, generalized aspects and workspaces (Chablat & Wenger 1998).

Independent evidence: a fine grid over the workspace per working mode with the five-bar's
inverse kinematics, A and B written out by hand (Chablat & Wenger 1998, eqs. 7b-7c), its connected
components counted with scipy.ndimage; the workspace area against the closed form of the
intersection of two annuli (circle-lens areas); joint limits against a grid count.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import optkin
from optkin.analysis.aspects import aspects, leg_working_modes, workspace

L0, L1, L2, L3, L4 = 9.0, 8.0, 5.0, 5.0, 8.0
BB = np.array([L0, 0.0])


def cross(u, w):
    return u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]


def u2(t):
    return np.stack([np.cos(t), np.sin(t)], -1)


def ik(P, s1, s2):
    r1 = np.hypot(P[..., 0], P[..., 1])
    dB = P - BB
    r2 = np.hypot(dB[..., 0], dB[..., 1])
    c1 = (r1**2 + L1**2 - L2**2) / (2 * r1 * L1)
    c2 = (r2**2 + L4**2 - L3**2) / (2 * r2 * L4)
    ok = (np.abs(c1) <= 1) & (np.abs(c2) <= 1)
    t1 = np.arctan2(P[..., 1], P[..., 0]) + s1 * np.arccos(np.clip(c1, -1, 1))
    t2 = np.arctan2(dB[..., 1], dB[..., 0]) + s2 * np.arccos(np.clip(c2, -1, 1))
    return t1, t2, ok


def hand_labels(P, s1, s2):
    """det A and the signs of optkin's B_jj = d(|P - C| - L2)/d theta1 (= -L1 sin(theta3 -
    theta1) of eq. 7c up to a positive factor), by hand."""
    t1, t2, ok = ik(P, s1, s2)
    C, D = L1 * u2(t1), BB + L4 * u2(t2)
    det = cross(P - C, P - D)
    m1 = -np.sign(cross(C, P - C))
    m2 = -np.sign(cross(D - BB, P - D))
    return det, m1, m2, ok, t1, t2


def lens(r1, r2, d):
    """Area of the intersection of two disks (closed form)."""
    if d >= r1 + r2:
        return 0.0
    if d <= abs(r1 - r2):
        return np.pi * min(r1, r2) ** 2
    a1 = r1**2 * np.arccos((d * d + r1 * r1 - r2 * r2) / (2 * d * r1))
    a2 = r2**2 * np.arccos((d * d + r2 * r2 - r1 * r1) / (2 * d * r2))
    return a1 + a2 - 0.5 * np.sqrt((-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2))


@pytest.fixture(scope="module")
def five_bar():
    return optkin.mechanisms.five_bar(L0, L1, L2, L3, L4)


@pytest.fixture(scope="module")
def asp(five_bar):
    return aspects(five_bar)


@pytest.fixture(scope="module")
def grid_labels():
    n = 700
    xs = np.linspace(-4.5, 13.5, n)
    ys = np.linspace(-13.0, 13.0, n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.stack([X, Y], -1)
    cell = (xs[1] - xs[0]) * (ys[1] - ys[0])
    out = {}
    for s1 in (1, -1):
        for s2 in (1, -1):
            det, m1, m2, ok, _, _ = hand_labels(P, s1, s2)
            mode = (int(m1[ok][0]), int(m2[ok][0]))
            assert np.all(m1[ok] == mode[0]) and np.all(m2[ok] == mode[1])
            comps = []
            for sgn in (1, -1):
                lab, nl = ndimage.label(ok & (np.sign(det) == sgn))
                sizes = ndimage.sum_labels(np.ones_like(lab), lab, index=np.arange(1, nl + 1))
                for k, sz in enumerate(sizes, start=1):
                    if sz > 30:
                        comps.append((sgn, sz * cell, lab == k))
            out[mode] = comps
    return xs, ys, out


def test_four_working_modes(five_bar, asp):
    modes = leg_working_modes(five_bar)
    assert len(modes) == 4 and len(set(modes)) == 4  # Chablat & Wenger 1998, section 3.4
    assert asp.working_modes == modes
    assert set(asp.counts) == set(modes)


def test_aspects_against_grid_components(asp, grid_labels):
    """Per working mode: as many aspects as connected components of the grid labelled by
    the sign of det A, with matching signs and areas, and the representative point inside."""
    xs, ys, comps = grid_labels
    h = max(xs[1] - xs[0], ys[1] - ys[0])
    assert asp.success, asp.message
    for mode, cs in comps.items():
        mine = asp.of_mode(mode)
        assert len(mine) == len(cs), (mode, [a.area for a in mine], [c[1] for c in cs])
        for a in mine:
            i = int(round((a.x[0] - xs[0]) / (xs[1] - xs[0])))
            j = int(round((a.x[1] - ys[0]) / (ys[1] - ys[0])))
            hits = [c for c in cs if c[2][i, j]]
            assert len(hits) == 1, mode
            sgn, area, _ = hits[0]
            assert sgn == a.det_sign
            # grid area error ~ perimeter * step
            per = sum(np.sum(np.linalg.norm(np.diff(np.vstack([R, R[:1]]), axis=0), axis=1))
                      for R in [a.face.outer] + a.face.holes)
            assert abs(area - a.area) < 0.6 * per * h + 1e-3 * a.area, (mode, area, a.area)
    # the representative configurations are what they claim, by hand
    for a in asp.aspects:
        t1, t2 = a.qa
        P = a.x
        C, D = L1 * u2(t1), BB + L4 * u2(t2)
        assert abs(np.linalg.norm(P - C) - L2) < 1e-9 and abs(np.linalg.norm(P - D) - L3) < 1e-9
        assert -np.sign(cross(C, P - C)) == a.working_mode[0]
        assert -np.sign(cross(D - BB, P - D)) == a.working_mode[1]
        assert np.sign(cross(P - C, P - D)) == a.det_sign


def test_aspect_counts_five_bar(asp):
    """The counts this test suite establishes for the paper's robot (L0 = 9, L1 = 8,
    L2 = L3 = 5, L4 = 8): two aspects in each working mode where both legs have the same
    posture sign, three where they differ (the grid test above confirms them)."""
    c = asp.counts
    assert sorted(c.values()) == [2, 2, 3, 3]
    assert c[(1, 1)] == c[(-1, -1)] == 2 and c[(1, -1)] == c[(-1, 1)] == 3
    # the union of the aspects of a working mode fills its workspace (det A = 0 is thin)
    for m in asp.working_modes:
        assert abs(sum(a.area for a in asp.of_mode(m)) - asp.workspace_area[m]) < 1e-6
    # serial aspects: joint-space masks exist and have positive area
    assert all(a.qa_area > 0 for a in asp.aspects)


def test_workspace_area_closed_form(five_bar):
    """W = annulus(A; 3, 13) intersected with annulus(B; 3, 13): inclusion-exclusion of
    disk lenses (closed form)."""
    ro, ri = L1 + L2, abs(L1 - L2)
    exact = lens(ro, ro, L0) - lens(ri, ro, L0) - lens(ro, ri, L0) + lens(ri, ri, L0)
    ws = workspace(five_bar)
    assert ws.success, ws.message
    assert abs(ws.area - exact) < 5e-4 * exact, (ws.area, exact)
    for m in ws.working_modes:  # every working mode reaches the whole workspace here
        assert abs(ws.areas[m] - exact) < 5e-4 * exact
        assert len(ws.regions[m]) == 1 and len(ws.regions[m][0].holes) == 2


def test_workspace_with_joint_limits(five_bar):
    """Joint limits theta1 in [0, 2], theta2 in [1, 3]: areas per working mode against a
    grid count with the hand-written inverse kinematics."""
    lim = {"L1.theta1": (0.0, 2.0), "L2.theta1": (1.0, 3.0)}
    ws = workspace(five_bar, limits=lim)
    assert ws.success, ws.message
    n = 900
    xs = np.linspace(-4.5, 13.5, n)
    ys = np.linspace(-13.0, 13.0, n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.stack([X, Y], -1)
    cell = (xs[1] - xs[0]) * (ys[1] - ys[0])
    union = np.zeros(X.shape, dtype=bool)
    for s1 in (1, -1):
        for s2 in (1, -1):
            _, m1, m2, ok, t1, t2 = hand_labels(P, s1, s2)
            t1 = (t1 + np.pi) % (2 * np.pi) - np.pi
            t2 = (t2 + np.pi) % (2 * np.pi) - np.pi
            inside = ok & (t1 >= 0) & (t1 <= 2) & (t2 >= 1) & (t2 <= 3)
            union |= inside
            if not inside.any():
                continue
            mode = (int(m1[inside][0]), int(m2[inside][0]))
            area = inside.sum() * cell
            assert abs(ws.areas[mode] - area) < 0.02 * area + 0.5, (mode, ws.areas[mode], area)
    assert abs(ws.area - union.sum() * cell) < 0.02 * ws.area + 0.5


def test_pictures(tmp_path, asp, five_bar):
    import matplotlib.pyplot as plt

    before = set(plt.get_fignums())
    p = tmp_path / "aspects.png"
    fig = asp.plot(str(p))
    assert p.stat().st_size > 10000
    assert set(plt.get_fignums()) == before  # a figure for a file stays out of pyplot
    # every workspace panel names its aspects (with det A's sign and the area) and the
    # parallel singularity in a legend; the joint-space axes are named for people
    for j, mode in enumerate(asp.working_modes):
        texts = [t.get_text() for t in fig.axes[j].get_legend().get_texts()]
        for k, a in enumerate(asp.of_mode(mode)):
            assert texts[k].startswith(f"aspect {k + 1} (det A {'+' if a.det_sign > 0 else '-'})")
            assert f"area {a.area:.3g}" in texts[k]
        assert "parallel singularity" in texts
    assert fig.axes[len(asp.working_modes)].get_xlabel() == r"$\theta_{1}$ of leg 1 (rad)"
    # the joint-space masks rasterized: the vector file stays small (77 MB before)
    svg = tmp_path / "aspects.svg"
    asp.plot(str(svg))
    assert svg.stat().st_size < 3e6
    d = asp.to_dict()
    assert d["n_working_modes"] == 4 and d["count"] == len(asp.aspects)


def test_errors(five_bar):
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0, 1]], [[0, 0], [0.2, 0], [0, 0.2]])
    with pytest.raises(optkin.MechanismError, match="phi"):  # a section is at fixed phi
        aspects(m, fixed={"x": 0.1})
    with pytest.raises(optkin.MechanismError, match="actuated joint"):
        workspace(five_bar, limits={"x": (0, 1)})


def test_rpr3_section_aspects_against_grid():
    """A 3-RPR at constant orientation phi = 0.5 with leg strokes [10, 30]: one working mode
    (B = -I), aspects = components of the stroke-limited workspace split by det A = 0,
    against a grid with the leg lengths and det A written by hand; workspace area likewise."""
    base = np.array([[0.0, 0.0], [15.91, 0.0], [0.0, 10.0]])
    d1, d2, d3 = 17.04, 16.54, 20.84
    al = np.arccos((d1**2 + d3**2 - d2**2) / (2 * d1 * d3))
    plat = np.array([[0.0, 0.0], [d1, 0.0], [d3 * np.cos(al), d3 * np.sin(al)]])
    m = optkin.mechanisms.rpr3(base, plat)
    lim = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
    a = aspects(m, fixed={"phi": 0.5}, limits=lim)
    ws = workspace(m, fixed={"phi": 0.5}, limits=lim)
    assert a.success and ws.success
    assert a.working_modes == [(-1, -1, -1)]
    b = a.curves.bounds
    n = 700
    xs, ys = np.linspace(*b[0], n), np.linspace(*b[1], n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    c, s = np.cos(0.5), np.sin(0.5)
    ok = np.ones(X.shape, dtype=bool)
    rows = []
    for A, bb in zip(base, plat):
        Rb = np.array([c * bb[0] - s * bb[1], s * bb[0] + c * bb[1]])
        dx, dy = X + Rb[0] - A[0], Y + Rb[1] - A[1]
        rho = np.hypot(dx, dy)
        ok &= (rho >= 10) & (rho <= 30)
        rows.append(np.stack([dx, dy, Rb[0] * dy - Rb[1] * dx], -1))
    det = np.linalg.det(np.stack(rows, -2))
    cell = (xs[1] - xs[0]) * (ys[1] - ys[0])
    assert abs(ws.area - ok.sum() * cell) < 0.01 * ws.area
    comps = []
    for sgn in (1, -1):
        lab, k = ndimage.label(ok & (np.sign(det) == sgn))
        sizes = ndimage.sum_labels(np.ones_like(lab), lab, np.arange(1, k + 1))
        comps += [(sgn, sz * cell, lab == q) for q, sz in enumerate(sizes, start=1) if sz > 30]
    assert len(a.aspects) == len(comps)
    for asp_ in a.aspects:
        i = int(round((asp_.x[0] - xs[0]) / (xs[1] - xs[0])))
        j = int(round((asp_.x[1] - ys[0]) / (ys[1] - ys[0])))
        hit = [cp for cp in comps if cp[2][i, j]]
        assert len(hit) == 1 and hit[0][0] == asp_.det_sign
        assert abs(hit[0][1] - asp_.area) < 0.02 * asp_.area


def _grid_aspect_counts(L0_, L1_, L2_, L3_, L4_, bounds, n=500):
    """Aspects per working mode by grid components (hand-written IK and det A)."""
    xs, ys = np.linspace(*bounds[0], n), np.linspace(*bounds[1], n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    r1, r2 = np.hypot(X, Y), np.hypot(X - L0_, Y)
    c1 = (r1**2 + L1_**2 - L2_**2) / (2 * r1 * L1_)
    c2 = (r2**2 + L4_**2 - L3_**2) / (2 * r2 * L4_)
    ok = (np.abs(c1) <= 1) & (np.abs(c2) <= 1)
    out = {}
    for s1 in (1, -1):
        for s2 in (1, -1):
            t1 = np.arctan2(Y, X) + s1 * np.arccos(np.clip(c1, -1, 1))
            t2 = np.arctan2(Y, X - L0_) + s2 * np.arccos(np.clip(c2, -1, 1))
            Cx, Cy = L1_ * np.cos(t1), L1_ * np.sin(t1)
            Dx, Dy = L0_ + L4_ * np.cos(t2), L4_ * np.sin(t2)
            det = (X - Cx) * (Y - Dy) - (Y - Cy) * (X - Dx)
            m1 = -np.sign(Cx * (Y - Cy) - Cy * (X - Cx))
            m2 = -np.sign((Dx - L0_) * (Y - Dy) - Dy * (X - Dx))
            k = 0
            for sg in (1, -1):
                lab, nl = ndimage.label(ok & (np.sign(det) == sg))
                sz = ndimage.sum_labels(np.ones_like(lab), lab, np.arange(1, nl + 1))
                k += int(np.sum(sz > 30))
            out[(int(m1[ok][0]), int(m2[ok][0]))] = k
    return out


@pytest.mark.parametrize("dims", [(9, 8, 5, 4, 7), (10, 6, 7, 5, 6), (4, 5, 5, 5, 5)])
def test_other_five_bars_against_grid(dims):
    a = aspects(optkin.mechanisms.five_bar(*dims))
    assert a.success, a.message
    assert a.counts == _grid_aspect_counts(*dims, a.curves.bounds)


def test_docstring_examples():
    import doctest
    import importlib

    mod = importlib.import_module("optkin.analysis.aspects")
    failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


def test_rrr3_section_aspects_against_grid():
    """A 3-RRR at constant orientation phi = 0.2 (8 working modes): aspects per working mode
    against grid components, with each leg's inverse kinematics and the rows of A
    (P_i - C_i, cross(R b_i, P_i - C_i)) written by hand. Every grid component larger than
    60 cells lies in exactly one aspect of its working mode with the same sign of det A,
    and every aspect larger than 60 cells holds exactly one of them (smaller aspects, a few
    tens of cells here, are what a grid resolves only by chance)."""
    import itertools

    base = np.array([[0, 0], [10, 0], [5, 8.0]])
    plat = np.array([[-1, -0.6], [1, -0.6], [0, 1.0]])
    l1 = l2 = 5.0
    phi = 0.2
    a = aspects(optkin.mechanisms.rrr3(base, plat, l1, l2), fixed={"phi": phi})
    assert a.success and len(a.working_modes) == 8
    b = a.curves.bounds
    n = 600
    xs, ys = np.linspace(*b[0], n), np.linspace(*b[1], n)
    cell = (xs[1] - xs[0]) * (ys[1] - ys[0])
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    c, s = np.cos(phi), np.sin(phi)
    legs = []
    for A, bb in zip(base, plat):
        Px, Py = X + c * bb[0] - s * bb[1], Y + s * bb[0] + c * bb[1]
        dx, dy = Px - A[0], Py - A[1]
        L = np.hypot(dx, dy)
        cc = (L * L + l1 * l1 - l2 * l2) / (2 * L * l1)
        al, be = np.arctan2(dy, dx), np.arccos(np.clip(cc, -1, 1))
        legs.append([(al + sg * be, np.abs(cc) <= 1, Px, Py, A, bb) for sg in (1, -1)])
    for combo in itertools.product(*legs):
        ok = np.logical_and.reduce([cb[1] for cb in combo])
        rows, signs = [], []
        for th, _, Px, Py, A, bb in combo:
            Cx, Cy = A[0] + l1 * np.cos(th), A[1] + l1 * np.sin(th)
            ex, ey = Px - Cx, Py - Cy
            Rb = np.array([c * bb[0] - s * bb[1], s * bb[0] + c * bb[1]])
            rows.append(np.stack([ex, ey, Rb[0] * ey - Rb[1] * ex], -1))
            signs.append(-np.sign((Cx - A[0]) * ey - (Cy - A[1]) * ex))
        det = np.linalg.det(np.stack(rows, -2))
        mode = tuple(int(sg[ok][0]) for sg in signs)
        mine = a.of_mode(mode)
        big_mine = [x for x in mine if x.area > 60 * cell]
        hits = {id(x): 0 for x in big_mine}
        n_big = 0
        for sg in (1, -1):
            lab, nl = ndimage.label(ok & (np.sign(det) == sg))
            for k in range(1, nl + 1):
                comp = lab == k
                if comp.sum() <= 60:
                    continue
                n_big += 1
                depth = ndimage.distance_transform_edt(comp)
                i, j = np.unravel_index(np.argmax(depth), comp.shape)
                p = np.array([[xs[i], ys[j]]])
                owners = [x for x in mine if x.face.contains(p)[0]]
                assert len(owners) == 1 and owners[0].det_sign == sg, (mode, p)
                if id(owners[0]) in hits:
                    hits[id(owners[0])] += 1
        assert n_big == len(big_mine), mode
        assert all(v == 1 for v in hits.values()), mode
