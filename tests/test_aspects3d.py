"""Generalized aspects of a 3-DoF planar platform in (x, y, phi)
(optkin.analysis.aspects3d).

Evidence: a voxel grid written here (the sign of det A by hand, rows (P_i - A_i,
(R b_i) x (P_i - A_i)) as in tests/test_continuation.py, the strokes from the leg
vectors), its connected components labelled by scipy.ndimage with phi periodic: the same
count of aspects, volumes within the grid's resolution. The cuspidal 3-RPR of Zein,
Wenger and Chablat with strokes [10, 30] (the issue's example: a 140^3 grid splits one
aspect in two through a thin neck; 200^3 and finer show two).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_continuation import BASE3, PLAT3

import optkin
from optkin.analysis.aspects3d import aspects3d

LIMITS = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}


def voxel_aspects(n: int, lo: float = -32.0, hi: float = 32.0):
    """Volumes of the components of {strokes in [10, 30], det A of one sign} on an n^3
    grid over [lo, hi]^2 x [-pi, pi), per sign, largest first."""
    from scipy import ndimage

    xs = np.linspace(lo, hi, n)
    ph = np.linspace(-np.pi, np.pi, n, endpoint=False)
    cell = (xs[1] - xs[0]) ** 2 * (ph[1] - ph[0])
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    ok = np.zeros((n, n, n), bool)
    sign = np.zeros((n, n, n), np.int8)
    for k, p in enumerate(ph):
        c, s = np.cos(p), np.sin(p)
        rows, good = [], np.ones_like(X, bool)
        for A, b in zip(BASE3, PLAT3):
            Rb = np.array([c * b[0] - s * b[1], s * b[0] + c * b[1]])
            dx, dy = X + Rb[0] - A[0], Y + Rb[1] - A[1]
            r = np.hypot(dx, dy)
            good &= (r >= 10) & (r <= 30)
            rows.append(np.stack([dx, dy, Rb[0] * dy - Rb[1] * dx], -1))
        ok[:, :, k] = good
        sign[:, :, k] = np.sign(np.linalg.det(np.stack(rows, -2)))
    out = {}
    for sg in (1, -1):
        lab, nl = ndimage.label(ok & (sign == sg))
        parent = list(range(nl + 1))

        def root(a, parent=parent):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        a, b = lab[:, :, 0], lab[:, :, -1]  # phi is periodic: the two ends touch
        both = (a > 0) & (b > 0)
        for u, v in set(zip(a[both].tolist(), b[both].tolist())):
            parent[root(u)] = root(v)
        roots = np.array([root(i) for i in range(nl + 1)])
        counts = np.bincount(roots[lab.ravel()], minlength=nl + 1)
        out[sg] = sorted((c * cell for r, c in enumerate(counts) if r > 0 and c > 0),
                         reverse=True)
    return out


@pytest.mark.slow
def test_cuspidal_3rpr_aspects_against_a_voxel_grid():
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    res = optkin.aspects(m, limits=LIMITS)  # no section: the 3-D aspects
    assert res.success, res.message
    grid = voxel_aspects(240)
    total = sum(sum(v) for v in grid.values())
    # components of the grid above 0.1 % of the free volume (below: cells cut off by the
    # grid in slivers along the curves, which shrink as the grid is refined)
    big = {sg: [v for v in vols if v > 1e-3 * total] for sg, vols in grid.items()}
    assert sum(len(v) for v in big.values()) == len(res) == 2
    for a in res:
        (ref,) = big[a.det_sign]
        assert abs(a.volume - ref) < 2e-3 * ref, (a.volume, ref)
        assert a.bbox.shape == (3, 2)
    # the design is cuspidal: an aspect holds more than one assembly mode
    assert res.cuspidal and max(n for a in res for _, n in a.modes_at) >= 2


def test_arguments_and_dispatch():
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    with pytest.raises(optkin.MechanismError, match="slices must be an integer >= 4"):
        aspects3d(m, slices=2)
    with pytest.raises(optkin.MechanismError, match="not a 3-DoF planar platform"):
        aspects3d(optkin.mechanisms.five_bar(9, 8, 5, 5, 8))
    with pytest.raises(optkin.MechanismError, match="time_limit"):
        aspects3d(m, time_limit=float("nan"))
    with pytest.raises(optkin.MechanismError, match="min_gap"):
        aspects3d(m, min_gap=0)
    # junk for fixed is refused as before, not taken for "no section" (a fuzz finding)
    with pytest.raises(optkin.MechanismError):
        optkin.aspects(optkin.mechanisms.five_bar(9, 8, 5, 5, 8), fixed=np.full(0, np.nan))
    # a workspace still needs its section (aspects without one are 3-D)
    with pytest.raises(optkin.MechanismError, match="phi"):
        optkin.workspace(m)
    # the five-bar (2-DoF) keeps its planar aspects
    assert isinstance(optkin.aspects(optkin.mechanisms.five_bar(9, 8, 5, 5, 8)),
                      optkin.Aspects)


def test_arc_corrected_areas_and_the_phi_integral():
    """The face areas and the integral over phi behind the volumes, against closed forms:
    an inscribed N-gon's arc-corrected area converges to pi r^2 as N^-4 (the polygon's as
    N^-2), a half disc's too (its two corners add nothing); the integral of a smooth
    periodic function sampled at uneven angles, and of one present on part of the circle
    only (an aspect born and dying), beats the trapezoid rule's accuracy."""
    from optkin.analysis.aspects3d import _integrate
    from optkin.analysis.planar import arc_area, ring_area

    for N in (24, 48, 96):
        t = np.linspace(0, 2 * np.pi, N, endpoint=False)
        R = 2.0 * np.c_[np.cos(t), np.sin(t)]
        assert abs(4 * np.pi - arc_area(R)) < 0.2 * (2 * np.pi / N) ** 4 * 4
        assert abs(4 * np.pi - ring_area(R)) > 0.5 * (2 * np.pi / N) ** 2 * 4 / 6
        assert np.isclose(arc_area(R[::-1]), -arc_area(R))  # a hole: clockwise
    t = np.linspace(0, np.pi, 49)
    assert abs(np.pi / 2 - arc_area(np.c_[np.cos(t), np.sin(t)])) < 1e-5
    rng = np.random.default_rng(1)
    phi = np.sort(rng.uniform(-np.pi, np.pi, 96))
    A = 5 + np.cos(phi) + 0.5 * np.sin(2 * phi)  # integral 10 pi
    P, F = np.r_[phi, phi[0] + 2 * np.pi], np.r_[A, A[0]]
    trap = np.sum(0.5 * np.diff(P) * (F[1:] + F[:-1]))
    assert abs(_integrate(phi, A) - 10 * np.pi) < 0.1 * abs(trap - 10 * np.pi)
    B = np.where(np.abs(phi) < 1, np.cos(phi * np.pi / 2) ** 2, 0.0)  # integral 1
    assert abs(_integrate(phi, B) - 1.0) < 1e-2
