"""Singular curves by continuation, checked against closed forms and brute-force grids.

Independent evidence: the five-bar's A and B of Chablat & Wenger (1998, eqs. 7b-7c) and
its inverse kinematics written out by hand; the four-bar loop equation of Modern Robotics
7.3 (Lynch & Park 2017, L1 = L2 = 4, L3 = L4 = 2); the 3-RPR's A written out by hand, with finite
differences for the cusp condition. Grids are computed here, in numpy, never by optkin.
"""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin.analysis.continuation import singular_curves

L0, L1, L2, L3, L4 = 9.0, 8.0, 5.0, 5.0, 8.0
BASE_B = np.array([L0, 0.0])


def wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def cross(u, w):
    return u[..., 0] * w[..., 1] - u[..., 1] * w[..., 0]


def u2(t):
    return np.stack([np.cos(t), np.sin(t)], -1)


def seg_dist(P, Q, periodic=False):
    """Distance from every point P (k, 2) to the polyline Q (n, 2)."""
    A, B = Q[:-1], Q[1:]
    d = B - A
    if periodic:
        d = wrap(d)
    out = np.empty(len(P))
    for s in range(0, len(P), 500):
        W = P[s:s + 500, None, :] - A[None]
        if periodic:
            W = wrap(W)
        L2_ = np.maximum(np.einsum("ij,ij->i", d, d), 1e-300)
        t = np.clip(np.einsum("kij,ij->ki", W, d) / L2_, 0, 1)
        E = W - t[..., None] * d[None]
        out[s:s + 500] = np.sqrt(np.min(np.einsum("kij,kij->ki", E, E), axis=1))
    return out


def dist_to_curves(P, curves, periodic=False):
    """Distance to the traced curves (closed ones closed)."""
    polys = [np.vstack([c.points, c.points[:1]]) if c.closed else c.points for c in curves]
    return np.min([seg_dist(P, Q, periodic) for Q in polys if len(Q) > 1], axis=0)


@pytest.fixture(scope="module")
def five_bar():
    return optkin.mechanisms.five_bar(L0, L1, L2, L3, L4)


def fb_ik(P, s1, s2):
    """Hand-written inverse kinematics of the five-bar, posture signs s1, s2."""
    r1 = np.hypot(P[..., 0], P[..., 1])
    dB = P - BASE_B
    r2 = np.hypot(dB[..., 0], dB[..., 1])
    c1 = (r1**2 + L1**2 - L2**2) / (2 * r1 * L1)
    c2 = (r2**2 + L4**2 - L3**2) / (2 * r2 * L4)
    ok = (np.abs(c1) <= 1) & (np.abs(c2) <= 1)
    t1 = np.arctan2(P[..., 1], P[..., 0]) + s1 * np.arccos(np.clip(c1, -1, 1))
    t2 = np.arctan2(dB[..., 1], dB[..., 0]) + s2 * np.arccos(np.clip(c2, -1, 1))
    return t1, t2, ok


def fb_AB(t1, t2, P):
    """det A (Chablat & Wenger 1998 eq. 7b) and the B_jj (eq. 7c) up to positive factors."""
    C = L1 * u2(t1)
    D = BASE_B + L4 * u2(t2)
    detA = cross(P - C, P - D)
    b1 = cross(C, P - C)            # L1 L2 sin(theta3 - theta1)
    b2 = cross(D - BASE_B, P - D)   # L3 L4 sin(theta4 - theta2)
    return detA, b1, b2


def test_five_bar_parallel_points_satisfy_closed_form(five_bar):
    for plane in ("joint", "workspace"):
        r = singular_curves(five_bar, plane=plane, kind="parallel")
        assert r.success, r.message
        assert r.max_residual < 1e-9
        V = np.vstack([c.v for c in r.curves])
        t1, t2, P = V[:, 0], V[:, 1], V[:, 2:4]
        C, D = L1 * u2(t1), BASE_B + L4 * u2(t2)
        # the closure, by hand
        assert np.max(np.abs(np.linalg.norm(P - C, axis=1) - L2)) < 1e-9
        assert np.max(np.abs(np.linalg.norm(P - D, axis=1) - L3)) < 1e-9
        # C, D and P aligned (Chablat & Wenger 1998, section 3.2)
        assert np.max(np.abs(cross(P - C, P - D))) < 1e-8
        # all curves close (angles periodic, workspace bounded)
        assert all(c.closed for c in r.curves)


def test_five_bar_parallel_vs_workspace_grid(five_bar):
    """Sign changes of det A on a fine grid per working mode lie on the traced curves,
    and every traced point has a grid sign change nearby."""
    r = singular_curves(five_bar, plane="workspace", kind="parallel")
    n = 500
    xs = np.linspace(-4.5, 13.5, n)
    ys = np.linspace(-13.0, 13.0, n)
    h = max(xs[1] - xs[0], ys[1] - ys[0])
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    P = np.stack([X, Y], -1)
    V = np.vstack([c.v for c in r.curves])
    Pt = V[:, 2:4]
    dA_t, b1_t, b2_t = fb_AB(V[:, 0], V[:, 1], Pt)
    for s1 in (1, -1):
        for s2 in (1, -1):
            t1, t2, ok = fb_ik(P, s1, s2)
            d, b1, b2 = fb_AB(t1, t2, P)
            mode = (np.sign(b1[ok][0]), np.sign(b2[ok][0]))
            d = np.where(ok, d, np.nan)
            cr = []
            for a, b, pa, pb in ((d[:-1], d[1:], P[:-1], P[1:]), (d[:, :-1], d[:, 1:], P[:, :-1], P[:, 1:])):
                hit = np.isfinite(a) & np.isfinite(b) & (a * b < 0)
                s = (a[hit] / (a[hit] - b[hit]))[:, None]
                cr.append(pa[hit] + s * (pb[hit] - pa[hit]))
            cr = np.vstack(cr)
            assert len(cr) > 100
            sel = (np.sign(b1_t) == mode[0]) & (np.sign(b2_t) == mode[1])
            dist = dist_to_curves(cr, r.curves)
            assert dist.max() < 1.5 * h, (s1, s2, dist.max(), h)
            # vice versa: traced points of this working mode, away from the boundary of W
            Q = Pt[sel]
            tq1, tq2, okq = fb_ik(Q, s1, s2)
            inner = np.ones(len(Q), dtype=bool)
            for dx, dy in ((2 * h, 0), (-2 * h, 0), (0, 2 * h), (0, -2 * h)):
                inner &= fb_ik(Q + [dx, dy], s1, s2)[2]
            dq = np.min(np.linalg.norm(Q[inner][:, None, :] - cr[None], axis=2), axis=1)
            assert inner.sum() > 20
            assert dq.max() < 2 * h, (s1, s2, dq.max())


def test_five_bar_joint_space_vs_grid(five_bar):
    """In the joint space the parallel locus is |C - D| = L2 + L3 (P between C and D) or
    C = D (the coupler circle, projected to two points) - Chablat & Wenger 1998, section 3.2."""
    r = singular_curves(five_bar, plane="joint", kind="parallel")
    V = np.vstack([c.v for c in r.curves])
    C, D = L1 * u2(V[:, 0]), BASE_B + L4 * u2(V[:, 1])
    g = np.linalg.norm(C - D, axis=1)
    assert np.all((np.abs(g - (L2 + L3)) < 1e-8) | (g < 1e-8))
    # the two degenerate configurations C = D are found (intersections of the circles)
    deg = V[g < 1e-8]
    assert len(deg) > 10
    yC = np.sqrt(L1**2 - (L0 / 2) ** 2)
    Cs = L1 * u2(deg[:, 0])
    assert np.allclose(np.abs(Cs[:, 1]), yC, atol=1e-8)
    assert {np.sign(c) for c in Cs[:, 1]} == {1.0, -1.0}
    # brute force on the torus: sign changes of |C - D| - (L2 + L3)
    n = 400
    th = np.linspace(-np.pi, np.pi, n, endpoint=False)
    T1, T2 = np.meshgrid(th, th, indexing="ij")
    G = np.linalg.norm(L1 * u2(T1) - BASE_B - L4 * u2(T2), axis=-1) - (L2 + L3)
    Q = np.stack([T1, T2], -1)
    cr = []
    for a, b, pa, pb in ((G, np.roll(G, -1, 0), Q, np.roll(Q, -1, 0)),
                         (G, np.roll(G, -1, 1), Q, np.roll(Q, -1, 1))):
        hit = a * b < 0
        s = (a[hit] / (a[hit] - b[hit]))[:, None]
        cr.append(pa[hit] + s * wrap(pb[hit] - pa[hit]))
    cr = np.vstack(cr)
    h = 2 * np.pi / n
    dist = dist_to_curves(cr, [c for c in r.curves if np.ptp(c.points[:, 0]) > 1e-6],
                          periodic=True)
    assert dist.max() < 1.5 * h
    main = V[np.abs(g - (L2 + L3)) < 1e-8][:, :2]
    back = np.min(np.linalg.norm(wrap(main[:, None, :] - cr[None]), axis=2), axis=1)
    assert back.max() < 2 * h


def test_five_bar_serial_curves(five_bar):
    """B_jj = 0: A, C, P aligned (|AP| = L1 +- L2) or B, D, P aligned (Chablat & Wenger 1998, 3.3)."""
    r = singular_curves(five_bar, plane="workspace", kind="serial")
    assert r.success and r.max_residual < 1e-9
    for c in r.curves:
        P = c.v[:, 2:4]
        if c.kind == "serial:0":
            d = np.linalg.norm(P, axis=1)
            radii = (L1 + L2, abs(L1 - L2))
        else:
            d = np.linalg.norm(P - BASE_B, axis=1)
            radii = (L3 + L4, abs(L3 - L4))
        assert np.all(np.min([np.abs(d - rr) for rr in radii], axis=0) < 1e-9)
    # every circle (outer and inner, both legs) is present
    for k, base in ((0, np.zeros(2)), (1, BASE_B)):
        ds = np.concatenate([np.linalg.norm(c.v[:, 2:4] - base, axis=1)
                             for c in r.curves if c.kind == f"serial:{k}"])
        assert np.any(np.abs(ds - 13) < 1e-9) and np.any(np.abs(ds - 3) < 1e-9)


def test_four_bar_cspace_through_bifurcations():
    """MR 7.3, Fig. 7.5: L1 = L2 = 4, L3 = L4 = 2; the C-space curve in (theta, phi) with
    its bifurcation points, every branch followed."""
    Lc, Lk, Lr, Lg = 4.0, 4.0, 2.0, 2.0
    m = optkin.mechanisms.four_bar(Lc, Lk, Lr, Lg)
    r = singular_curves(m, plane=("theta", "phi"))
    assert r.success, r.message
    assert r.max_residual < 1e-9

    def f(t, p):  # |C - B|^2 - L2^2, B = crank tip, C = rocker tip
        B = Lc * u2(t)
        C = np.array([Lg, 0.0]) + Lr * u2(p)
        return np.sum((C - B) ** 2, axis=-1) - Lk**2

    P = np.vstack([c.points for c in r.curves])
    assert np.max(np.abs(f(P[:, 0], P[:, 1]))) < 1e-8
    # bifurcation points: the gradient of f vanishes (closed form, by central differences)
    assert len(r.branch_points) >= 2
    i0, i1 = r.info["plane_index"]
    for b in r.branch_points:
        t, p = b[i0], b[i1]
        e = 1e-6
        gt = (f(t + e, p) - f(t - e, p)) / (2 * e)
        gp = (f(t, p + e) - f(t, p - e)) / (2 * e)
        assert abs(f(t, p)) < 1e-8 and np.hypot(gt, gp) < 1e-5
    # brute force: every sign change of f on a grid is near a traced curve, and back
    n = 300
    th = np.linspace(-np.pi, np.pi, n, endpoint=False)
    T, Ph = np.meshgrid(th, th, indexing="ij")
    F = f(T, Ph)
    Q = np.stack([T, Ph], -1)
    cr = []
    for a, b, pa, pb in ((F, np.roll(F, -1, 0), Q, np.roll(Q, -1, 0)),
                         (F, np.roll(F, -1, 1), Q, np.roll(Q, -1, 1))):
        hit = a * b < 0
        s = (a[hit] / (a[hit] - b[hit]))[:, None]
        cr.append(pa[hit] + s * wrap(pb[hit] - pa[hit]))
    cr = np.vstack(cr)
    h = 2 * np.pi / n
    dist = dist_to_curves(cr, r.curves, periodic=True)
    assert dist.max() < 1.5 * h
    # the branch phi = pi (rocker folded onto the ground link) has no sign change of f
    # (f >= 0 near it); check the others come back to the grid
    away = np.abs(wrap(P[:, 1] - np.pi)) > 3 * h
    back = np.min(np.linalg.norm(wrap(P[away][:, None, :] - cr[None]), axis=2), axis=1)
    assert back.max() < 2 * h


# ----------------------------------------------------------------------------- 3-RPR

D1, D2, D3 = 17.04, 16.54, 20.84
BASE3 = np.array([[0.0, 0.0], [15.91, 0.0], [0.0, 10.0]])
_al = np.arccos((D1**2 + D3**2 - D2**2) / (2 * D1 * D3))
PLAT3 = np.array([[0.0, 0.0], [D1, 0.0], [D3 * np.cos(_al), D3 * np.sin(_al)]])
RHO1 = 14.98


@pytest.fixture(scope="module")
def rpr():
    return optkin.mechanisms.rpr3(BASE3, PLAT3)


def rpr_det(x, y, phi):
    """det A of the 3-RPR by hand: rows (P_i - A_i, cross(R b_i, P_i - A_i))."""
    c, s = np.cos(phi), np.sin(phi)
    rows = []
    for A, b in zip(BASE3, PLAT3):
        Rb = np.stack([c * b[0] - s * b[1], s * b[0] + c * b[1]], -1)
        d = np.stack([x, y], -1) + Rb - A
        rows.append(np.stack([d[..., 0], d[..., 1], cross(Rb, d)], -1))
    M = np.stack(rows, -2)
    return np.linalg.det(M)


def rpr_chart(psi, phi):
    """Platform pose with leg 1 at length RHO1 and angle psi; leg lengths 2 and 3."""
    c, s = np.cos(phi), np.sin(phi)
    b = PLAT3[0]
    x = BASE3[0, 0] + RHO1 * np.cos(psi) - (c * b[0] - s * b[1])
    y = BASE3[0, 1] + RHO1 * np.sin(psi) - (s * b[0] + c * b[1])
    rh = []
    for A, bb in zip(BASE3[1:], PLAT3[1:]):
        px = x + c * bb[0] - s * bb[1] - A[0]
        py = y + s * bb[0] + c * bb[1] - A[1]
        rh.append(np.hypot(px, py))
    return x, y, rh


def cusp_ratio(psi, phi, e=1e-6):
    """|J tau| / (|J| |tau|): tau the tangent of det A = 0 in the (psi, phi) chart, J the
    Jacobian of (rho2, rho3); zero at a cusp of the joint-space curve. Finite differences."""
    def D(a, b):
        x, y, _ = rpr_chart(a, b)
        return rpr_det(x, y, b)

    def R(a, b):
        return np.array(rpr_chart(a, b)[2])

    g = np.array([(D(psi + e, phi) - D(psi - e, phi)) / (2 * e),
                  (D(psi, phi + e) - D(psi, phi - e)) / (2 * e)])
    tau = np.array([-g[1], g[0]])
    J = np.stack([(R(psi + e, phi) - R(psi - e, phi)) / (2 * e),
                  (R(psi, phi + e) - R(psi, phi - e)) / (2 * e)], 1)
    return np.linalg.norm(J @ tau) / (np.linalg.norm(J) * np.linalg.norm(tau))


def test_rpr_joint_section_and_cusps(rpr):
    r = singular_curves(rpr, plane="joint", fixed={"L1.rho": RHO1}, bounds=[[0, 40], [0, 40]])
    assert r.success, r.message
    assert r.max_residual < 1e-9
    V = np.vstack([c.v for c in r.curves])
    assert np.allclose(V[:, 0], RHO1)
    dets = rpr_det(V[:, 3], V[:, 4], V[:, 5])  # det of rows with lengths^3 units
    assert np.max(np.abs(dets)) < 1e-9 * 40**3
    assert len(r.cusps) >= 2
    for v in r.cusps:
        x, y, phi = v[3:]
        b = PLAT3[0]
        c, s = np.cos(phi), np.sin(phi)
        P1 = np.array([x + c * b[0] - s * b[1], y + s * b[0] + c * b[1]])
        psi = np.arctan2(*(P1 - BASE3[0])[::-1])
        _, _, rh = rpr_chart(psi, phi)
        assert np.allclose(rh, v[1:3], atol=1e-8)
        assert cusp_ratio(psi, phi) < 1e-4
    # ordinary points of the curve are not cusps (the test discriminates)
    sample = V[:: max(1, len(V) // 50)]
    ratios = []
    for v in sample:
        if np.min(np.linalg.norm(r.cusps[:, 1:3] - v[1:3], axis=1)) < 2.0:
            continue
        b = PLAT3[0]
        c, s = np.cos(v[5]), np.sin(v[5])
        P1 = np.array([v[3] + c * b[0] - s * b[1], v[4] + s * b[0] + c * b[1]])
        ratios.append(cusp_ratio(np.arctan2(P1[1], P1[0]), v[5]))
    assert np.median(ratios) > 1e-2


def test_rpr_cusp_count_vs_brute_force(rpr):
    """Cusps counted independently: the contour det A = 0 on a fine (psi, phi) grid
    (contourpy, ordered polylines), mapped to (rho2, rho3); a cusp is where the mapped
    polyline reverses direction (consecutive steps with a negative dot product)."""
    import contourpy

    r = singular_curves(rpr, plane="joint", fixed={"L1.rho": RHO1}, bounds=[[0, 40], [0, 40]])
    n = 900
    ps = np.linspace(-np.pi, np.pi, n)
    PS, PH = np.meshgrid(ps, ps, indexing="ij")
    x, y, _ = rpr_chart(PS, PH)
    Dg = rpr_det(x, y, PH)
    gen = contourpy.contour_generator(PS, PH, Dg)
    rev = []
    for line in gen.lines(0.0):
        rr = np.array(rpr_chart(line[:, 0], line[:, 1])[2]).T
        st = np.diff(rr, axis=0)
        keep = np.linalg.norm(st, axis=1) > 1e-12
        st, pts = st[keep], rr[1:][keep]
        dots = np.einsum("ij,ij->i", st[:-1], st[1:])
        for k in np.flatnonzero(dots < 0):
            p = pts[k]
            if 0.5 < p[0] < 39.5 and 0.5 < p[1] < 39.5:
                rev.append(p)
    clusters: list[np.ndarray] = []
    for p in rev:
        if all(np.linalg.norm(c - p) > 1.0 for c in clusters):
            clusters.append(p)
    found = [c for c in r.cusps[:, 1:3] if 0.5 < c[0] < 39.5 and 0.5 < c[1] < 39.5]
    assert len(clusters) == len(found), (clusters, found)
    for c in clusters:
        assert np.min(np.linalg.norm(np.array(found) - c, axis=1)) < 0.5


def test_rpr_workspace_section_conic(rpr):
    """At constant orientation the 3-RPR's parallel singularity locus is a conic; every
    traced point satisfies det A = 0 written by hand."""
    r = singular_curves(rpr, plane="workspace", fixed={"phi": 0.5})
    assert r.success and r.max_residual < 1e-9
    V = np.vstack([c.v for c in r.curves])
    assert np.allclose(V[:, 5], 0.5)
    assert np.max(np.abs(rpr_det(V[:, 3], V[:, 4], V[:, 5]))) < 1e-6
    # brute force: sign changes of det A on a grid lie on the traced curves
    b = r.bounds
    n = 300
    xs, ys = np.linspace(*b[0], n), np.linspace(*b[1], n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    Dg = rpr_det(X, Y, np.full_like(X, 0.5))
    Q = np.stack([X, Y], -1)
    cr = []
    for a, bb, pa, pb in ((Dg[:-1], Dg[1:], Q[:-1], Q[1:]), (Dg[:, :-1], Dg[:, 1:], Q[:, :-1], Q[:, 1:])):
        hit = a * bb < 0
        s = (a[hit] / (a[hit] - bb[hit]))[:, None]
        cr.append(pa[hit] + s * (pb[hit] - pa[hit]))
    cr = np.vstack(cr)
    h = max(xs[1] - xs[0], ys[1] - ys[0])
    assert dist_to_curves(cr, r.curves).max() < 1.5 * h


def test_pictures(tmp_path, five_bar):
    r = singular_curves(five_bar, plane="joint", kind="all")
    p = tmp_path / "joint.png"
    r.plot(str(p))
    assert p.stat().st_size > 5000
    d = r.to_dict()
    assert d["count"] == len(r.curves) and d["max_residual"] < 1e-9


def test_errors(five_bar):
    with pytest.raises(optkin.MechanismError, match="unknown coordinate"):
        singular_curves(five_bar, plane=("nope", "x"))
    with pytest.raises(optkin.MechanismError, match="kind"):
        singular_curves(five_bar, kind="weird")
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    with pytest.raises(optkin.MechanismError, match="fix"):
        singular_curves(m, plane="workspace")


def test_four_bar_turning_points():
    """A double rocker (crank 3, coupler 1, rocker 2, ground 3; Grashof with the coupler
    shortest): the input angle turns back where det W_p = 0, i.e. where coupler and
    rocker are aligned, |B - D| = L3 +- L2 (B the crank tip, D the rocker pivot)."""
    m = optkin.mechanisms.four_bar(3.0, 1.0, 2.0, 3.0)
    r = singular_curves(m, plane=("theta", "phi"))
    assert r.success and r.max_residual < 1e-9
    act = r.info["actuator_singularities"]
    assert len(act) == 4
    i0, _ = r.info["plane_index"]
    B = 3.0 * u2(act[:, i0])
    dist = np.linalg.norm(B - np.array([3.0, 0.0]), axis=1)
    assert np.all(np.min(np.abs(dist[:, None] - np.array([1.0, 3.0])), axis=1) < 1e-8)
    # and a crank-rocker (crank shortest) has none
    r2 = singular_curves(optkin.mechanisms.four_bar(1.0, 3.0, 2.0, 3.0), plane=("theta", "phi"))
    assert len(r2.info["actuator_singularities"]) == 0


def test_five_bar_as_khalil_table():
    """The same five-bar written as a Khalil table (one loop cut at P, passive t2, t4, t3):
    its internal singularities det W_p = 0, traced in (t1, t5), satisfy |C - D| = L2 + L3 by
    hand (the coupler circle C = D projects to points and is not a curve of this plane)."""
    rows = [dict(a=0, mu=1, sigma=0, d=0, theta="t1"), dict(a=1, mu=0, sigma=0, d=L1, theta="t2"),
            dict(a=0, mu=1, sigma=0, d=L0, theta="t5"), dict(a=3, mu=0, sigma=0, d=L4, theta="t4"),
            dict(a=2, mu=0, sigma=0, d=L2, theta="t3"), dict(a=4, mu=0, sigma=2, d=L3, theta=0)]
    m = optkin.Mechanism.from_khalil(rows, loops=1, name="five-bar (Khalil)")
    r = singular_curves(m, plane="joint")
    assert r.success and r.max_residual < 1e-9
    V = np.vstack([c.v for c in r.curves])
    C, D = L1 * u2(V[:, 0]), BASE_B + L4 * u2(V[:, 1])
    assert np.max(np.abs(np.linalg.norm(C - D, axis=1) - (L2 + L3))) < 1e-8
    # it covers the closed curve |C - D| = 10 of the torus: grid crossings are near it
    n = 200
    th = np.linspace(-np.pi, np.pi, n, endpoint=False)
    T1, T2 = np.meshgrid(th, th, indexing="ij")
    G = np.linalg.norm(L1 * u2(T1) - BASE_B - L4 * u2(T2), axis=-1) - (L2 + L3)
    Q = np.stack([T1, T2], -1)
    hit = G * np.roll(G, -1, 0) < 0
    s = (G[hit] / (G[hit] - np.roll(G, -1, 0)[hit]))[:, None]
    cr = Q[hit] + s * wrap(np.roll(Q, -1, 0)[hit] - Q[hit])
    assert dist_to_curves(cr, r.curves, periodic=True).max() < 2 * np.pi / n * 1.5


def test_docstring_examples():
    import doctest
    import importlib

    mod = importlib.import_module("optkin.analysis.continuation")
    failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


def test_coarse_step_does_not_go_round_a_loop_it_jumped_to():
    """A 3-RRR section at phi = pi/2 traced with step 0.25: the corrector jumps from one
    parallel curve to a closed one and, before the loop check, went round it until
    max_steps (14780 points, one curve 290 times over; the faces of that arrangement then
    took hours). Now the run stops after one round: the coarse curves are the fine ones
    (every coarse point within 2 % of the size of the section of the fine polylines),
    with fewer points, and the sections' faces have the fine sections' areas."""
    A = np.array([[0, 0], [10, 0], [5, 8.66]])
    b = np.array([[-2, -1.15], [2, -1.15], [0, 2.31]])
    m = optkin.mechanisms.rrr3(A, b, 5.0, 5.0)
    sec = {"phi": np.pi / 2}
    coarse = singular_curves(m, "workspace", ["parallel"], fixed=sec, step=0.25)
    fine = singular_curves(m, "workspace", ["parallel"], fixed=sec, step=0.04)
    assert coarse.success and fine.success
    pc = np.vstack([c.points for c in coarse.curves])
    assert len(pc) < sum(len(c.points) for c in fine.curves)

    def dist(P, Z):  # from points P to the polyline Z, by brute force over its segments
        a, d = Z[:-1], np.diff(Z, axis=0)
        s = np.clip(np.einsum("pkj,kj->pk", P[:, None] - a, d) / np.einsum("kj,kj->k", d, d),
                    0, 1)
        return np.min(np.linalg.norm(P[:, None] - (a + s[..., None] * d), axis=2), axis=1)

    near = np.min([dist(pc, c.points) for c in fine.curves if len(c.points) > 1], axis=0)
    assert near.max() < 0.02 * np.ptp(np.vstack([c.points for c in fine.curves]), axis=0).max()
    a_c = sorted(a.area for a in optkin.aspects(m, fixed=sec, step=0.25).aspects)
    a_f = sorted(a.area for a in optkin.aspects(m, fixed=sec).aspects)
    assert len(a_c) == len(a_f) and np.allclose(a_c, a_f, rtol=0.05, atol=0.05)


def test_one_call_corrector_takes_the_python_newton_steps(rpr):
    """The corrector's first steps in one Function against Newton on [G; t.(u - a)] = 0
    written here with numpy (the tracer's own G and J): from predictions off a traced
    curve of the 3-RPR, the same point after the same number of steps, to rounding."""
    from optkin.analysis import continuation as C

    res = singular_curves(rpr, "workspace", ["parallel"], fixed={"phi": 0.3})
    sys = C.augmented_system(rpr, "parallel", (5,))
    tr = C._Tracer(sys, np.array([0.3]), 0.0, (3, 4), res.bounds, 0.25, 1e-11, 100)
    rng = np.random.default_rng(0)
    Z = np.vstack([c.points for c in res.curves])
    compared = 0
    for P in Z[rng.choice(len(Z), 20, replace=False)]:
        V = next(v[0] for v, ok in tr_points(rpr, P, 0.3) if ok[0])
        u0 = np.r_[V[:3], V[3:5]] / tr.scl
        _, J = tr.GJ(u0)
        t = np.linalg.svd(J)[2][-1]
        up = u0 + 0.1 * t + 0.02 * rng.normal(size=5)
        u, k = tr.correct(up, t)
        ref, kr = up.copy(), None  # numpy Newton, with the tracer's cap on a step's length
        cap = 4 * 0.25  # (4 hmax, scaled units: a longer step is refused, the step halved)
        for it in range(10):
            g, Jr = tr.GJ(ref)
            F = np.r_[g, t @ (ref - up)]
            if np.abs(g).max() < 1e-11 and abs(F[-1]) < 1e-10:
                kr = it
                break
            du = np.linalg.solve(np.vstack([Jr, t]), -F)
            if np.linalg.norm(du) > cap:
                kr = "refused"
                break
            ref = ref + du
        if kr == "refused":
            assert u is None
            continue
        if kr is None:
            continue
        assert u is not None and k == kr
        assert np.allclose(u, ref, rtol=0, atol=1e-9)
        compared += 1
    assert compared >= 15


def tr_points(mech, P, phi):
    """Full points (rho, x, y, phi) over the platform position P at orientation phi."""
    from optkin.model import get_model
    from optkin.model.charts import planar_chart

    return planar_chart(get_model(mech)).full_points(np.array([[P[0], P[1], phi]]))


def test_faces_of_overlapping_copies_of_a_curve():
    """Sixty copies of one closed curve (a circle of radius 2 sampled at 40 shifted points,
    noise 1e-5) in a box: every chord crosses two of every other copy, an arrangement that
    took hours for a traced curve gone round 290 times. The copies are dropped first: the
    faces are those of one copy: the 40-gon (its shoelace area) and the box less it."""
    from optkin.analysis.planar import faces, ring_area

    rng = np.random.default_rng(0)
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    copies = [(2 * np.c_[np.cos(t + s), np.sin(t + s)] + rng.normal(0, 1e-5, (40, 2)), True)
              for s in rng.uniform(0, 2 * np.pi / 40, 60)]
    box = (np.array([[-3, -3], [3, -3], [3, 3], [-3, 3]], float), True)
    out = sorted(f.area for f in faces(copies + [box], snap=1.0))
    disc = ring_area(copies[0][0])
    assert len(out) == 2
    assert np.allclose(out, sorted([disc, 36 - disc]), atol=1e-3)


@pytest.mark.parametrize("phi", [0.3, -2.0])
def test_rpr3_limit_curves_in_closed_form(rpr, monkeypatch, phi):
    """A 3-RPR's stroke-limit curves at a fixed orientation come from the legs' circles
    (continuation.CLOSED_FORM_LIMITS): every vertex has its leg at the limit, written here
    as |p + R b_i - a_i| = rho, and lies in the box; the curves cover the part of each
    circle inside the box, found here by sampling 20000 angles; and the curves traced by
    continuation (the flag off) lie on them, within the sagitta of the closed form's chords."""
    from optkin.analysis import continuation as cont

    lims = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
    c, s = np.cos(phi), np.sin(phi)
    R = np.array([[c, -s], [s, c]])

    def curves(flag):
        monkeypatch.setattr(cont, "CLOSED_FORM_LIMITS", flag)
        sc = optkin.singular_curves(rpr, plane="workspace", kind="limit",
                                    fixed={"phi": phi}, limits=lims, step=0.25)
        assert sc.success, sc.message
        return sc

    closed_form, traced = curves(True), curves(False)
    lo, hi = closed_form.bounds[:, 0], closed_form.bounds[:, 1]
    for i in range(3):
        for rho in (10.0, 30.0):
            mine = [cv for cv in closed_form.curves if cv.kind == f"limit:{i}"
                    and abs(cv.v[0, i] - rho) < 1e-9]
            assert mine, (i, rho)
            P = np.vstack([cv.points for cv in mine])
            assert np.all(P >= lo - 1e-9) and np.all(P <= hi + 1e-9)
            lengths = np.linalg.norm(P + PLAT3[i] @ R.T - BASE3[i], axis=1)
            assert np.max(np.abs(lengths - rho)) < 1e-9
            # coverage: the angles of the circle inside the box, against the curves' arcs
            centre = BASE3[i] - R @ PLAT3[i]
            th = np.linspace(-np.pi, np.pi, 20000, endpoint=False)
            Q = centre + rho * np.c_[np.cos(th), np.sin(th)]
            inside = np.all((Q >= lo) & (Q <= hi), axis=1)
            covered = 0.0
            for cv in mine:
                a = np.unwrap(np.arctan2(*(cv.points - centre).T[::-1]))
                covered += abs(a[-1] - a[0]) + (np.abs(a[1] - a[0]) if cv.closed else 0.0)
            assert abs(covered - inside.mean() * 2 * np.pi) < 2e-3 * 2 * np.pi, (i, rho)
            # the traced curve's points lie on the closed form's polyline (chords of the
            # circle: within their sagitta)
            T = np.vstack([cv.points for cv in traced.curves if cv.kind == f"limit:{i}"
                           and abs(cv.v[0, i] - rho) < 1e-9])
            seg = max(float(np.max(np.linalg.norm(np.diff(cv.points, axis=0), axis=1)))
                      for cv in mine)
            d = np.min(np.linalg.norm(T[:, None] - P[None], axis=2), axis=1)
            assert np.max(d) < seg, (np.max(d), seg)
            assert np.max(np.abs(np.linalg.norm(T - centre, axis=1) - rho)) < 1e-9


@pytest.mark.parametrize("phi", [0.3, -2.0, 2.9])
def test_rpr3_parallel_curves_in_closed_form(rpr, monkeypatch, phi):
    """A 3-RPR's parallel singularity curve at a fixed orientation is a conic
    (continuation.CLOSED_FORM_CONICS, sampled exactly): at every vertex the three leg
    lines are concurrent or parallel (the determinant of their line coordinates (d, P x d),
    written here, relative to the rows' sizes, below 1e-9); every sign change of det A
    (rpr_det) between neighbours of a 300 x 300 grid of the box lies within a cell and a
    chord of a vertex (the conic's part in the box covered); and the curves traced by
    continuation (the flag off) lie on the closed form's chords."""
    from optkin.analysis import continuation as cont

    c, s = np.cos(phi), np.sin(phi)
    R = np.array([[c, -s], [s, c]])

    def curves(flag):
        monkeypatch.setattr(cont, "CLOSED_FORM_CONICS", flag)
        sc = optkin.singular_curves(rpr, plane="workspace", kind="parallel",
                                    fixed={"phi": phi}, step=0.25)
        assert sc.success, sc.message
        return [cv for cv in sc.curves if cv.kind == "parallel"], sc.bounds

    mine, (bx, by) = curves(True)
    traced, _ = curves(False)
    assert mine
    P = np.vstack([cv.points for cv in mine])
    assert np.all(P >= [bx[0] - 1e-9, by[0] - 1e-9]) and np.all(P <= [bx[1] + 1e-9, by[1] + 1e-9])
    Pi = P[:, None, :] + PLAT3 @ R.T  # the legs' platform points
    d = Pi - BASE3
    lines = np.concatenate([d, (Pi[..., 0] * d[..., 1] - Pi[..., 1] * d[..., 0])[..., None]], 2)
    rel = np.abs(np.linalg.det(lines)) / np.prod(np.linalg.norm(lines, axis=2), axis=1)
    assert np.max(rel) < 1e-9, np.max(rel)
    # coverage: the sign changes of det A on a grid, each near a vertex
    n = 300
    xs, ys = np.linspace(*bx, n), np.linspace(*by, n)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    D = np.sign(rpr_det(X, Y, phi))
    mids = np.vstack([np.c_[(X[1:] + X[:-1]).ravel() / 2, Y[1:].ravel()][(D[1:] != D[:-1]).ravel()],
                      np.c_[X[:, 1:].ravel(), (Y[:, 1:] + Y[:, :-1]).ravel() / 2][
                          (D[:, 1:] != D[:, :-1]).ravel()]])
    assert len(mids) > 50
    seg = max(float(np.max(np.linalg.norm(np.diff(cv.points, axis=0), axis=1))) for cv in mine)
    cell = max(xs[1] - xs[0], ys[1] - ys[0])
    dist = np.min(np.linalg.norm(mids[:, None] - P[None], axis=2), axis=1)
    assert np.max(dist) < seg + cell, (np.max(dist), seg, cell)
    # the traced curves on the closed form's chords
    T = np.vstack([cv.points for cv in traced])
    dt = np.min(np.linalg.norm(T[:, None] - P[None], axis=2), axis=1)
    assert np.max(dt) < seg, (np.max(dt), seg)


@pytest.mark.parametrize("k", [4, 11, 40])
def test_compiled_code_landing_mid_trace_changes_nothing(monkeypatch, k):
    """The tracer's corrector and G/J are interpreted until their compiled library lands,
    at whatever moment a background build finishes. Here each one is swapped, at its k-th
    look, for a copy of itself (the same numbers, a new Function, as when the compiled code
    lands): the curves and aspects must be those of a run without the swap, bit for bit.
    Before the fix, a swap between the corrector's call and its success check read the
    status of a buffer never called, failed a good step, and moved a five-bar's aspect
    areas in the fifth digit (seen as runs of one batch disagreeing)."""
    import casadi as ca

    from optkin.model import compiled as cc

    monkeypatch.setenv("OPTKIN_COMPILE", "off")  # the interpreted code throughout
    mech = optkin.mechanisms.five_bar(6.421981, 7.887324, 5.854309, 5.854309, 7.887324)

    def run():
        a = optkin.aspects(mech)
        assert a.success
        return ([x.area for x in a.aspects],
                [c.points.copy() for c in a.curves.curves])

    ref_areas, ref_pts = run()
    seen: dict[int, int] = {}
    swaps = []

    def poll(self):
        n = seen[id(self)] = seen.get(id(self), 0) + 1
        if n == k:
            self.f = ca.Function.deserialize(self.f.serialize())
            self._maps = {}
            swaps.append(self.tag)

    monkeypatch.setattr(cc.LateCompiled, "poll", poll)
    areas, pts = run()
    assert swaps  # the swap happened during the trace
    assert areas == ref_areas
    assert len(pts) == len(ref_pts)
    assert all(np.array_equal(p, q) for p, q in zip(pts, ref_pts))
