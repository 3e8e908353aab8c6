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


def _components(free: np.ndarray, cell: float) -> list[float]:
    """Volumes of the connected components of ``free`` (n, n, m) with the last axis
    periodic, largest first."""
    from scipy import ndimage

    lab, nl = ndimage.label(free)
    parent = list(range(nl + 1))

    def root(a):
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
    return sorted((c * cell for r, c in enumerate(counts) if r > 0 and c > 0), reverse=True)


def voxel_aspects(n: int, lo: float = -32.0, hi: float = 32.0):
    """Volumes of the components of {strokes in [10, 30], det A of one sign} on an n^3
    grid over [lo, hi]^2 x [-pi, pi), per sign, largest first."""
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
    return {sg: _components(ok & (sign == sg), cell) for sg in (1, -1)}


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


@pytest.mark.slow
def test_3rpr_volumes_against_a_fine_voxel_grid():
    """The default refinement of the phi integral (``vol_tol``) against a 480^3 grid:
    the volumes within 1e-4 of its components' (the grids approach them as they are
    refined: 3.1e-4, 1.0e-4 and 4.3e-5 off at 320^3, 400^3 and 480^3 for the larger
    aspect). With the events' refinement alone (``vol_tol=inf``) the smaller aspect is
    3.5e-4 off."""
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    grid = voxel_aspects(480)
    res = aspects3d(m, limits=LIMITS, modes=False)
    assert res.success and len(res) == 2, res.message
    for a in res:
        ref = grid[a.det_sign][0]
        assert abs(a.volume - ref) < 1e-4 * ref, (a.det_sign, a.volume, ref)
    coarse = aspects3d(m, limits=LIMITS, modes=False, vol_tol=np.inf)
    assert max(abs(a.volume - grid[a.det_sign][0]) / a.volume for a in coarse) > 3e-4


#: A 3-RRR with equilateral base (side 10) and platform (circumradius 2), proximal links 5
#: and distal 4: each leg's platform point within the annulus 1 <= |P - A| <= 9.
RRR_BASE = [[0.0, 0.0], [10.0, 0.0], [5.0, 5.0 * np.sqrt(3.0)]]
RRR_PLAT = [[2 * np.cos(a), 2 * np.sin(a)] for a in (7 * np.pi / 6, -np.pi / 6, np.pi / 2)]


def rrr_voxels(n: int, l1: float = 5.0, l2: float = 4.0):
    """{(elbows, sign of det A): component volumes} on an n^3 grid over a box holding the
    workspace x [-pi, pi). Each leg by hand: the elbow C = A + l1 (cos t, sin t) from the
    law of cosines (two, one on each side of A -> P), the leg's posture the side, i.e. the
    sign of (C - A) x (P - C) (the sign of B_ii up to a convention); det A from the rows
    (d, (R b) x d), d = P - C (the derivative of |P - C|^2 / 2 in x, y, phi)."""
    xs = np.linspace(-3.0, 13.0, n)
    ys = np.linspace(-5.0, 12.0, n)
    ph = np.linspace(-np.pi, np.pi, n, endpoint=False)
    cell = (xs[1] - xs[0]) * (ys[1] - ys[0]) * (ph[1] - ph[0])
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    modes = [(a, b, c) for a in (1, -1) for b in (1, -1) for c in (1, -1)]
    reach = np.zeros((n, n, n), bool)
    sign = {w: np.zeros((n, n, n), np.int8) for w in modes}
    for k, p in enumerate(ph):
        c, s = np.cos(p), np.sin(p)
        ok = np.ones_like(X, bool)
        legs = []
        for A, b in zip(RRR_BASE, RRR_PLAT):
            Rb = (c * b[0] - s * b[1], s * b[0] + c * b[1])
            Px, Py = X + Rb[0], Y + Rb[1]
            dx, dy = Px - A[0], Py - A[1]
            r = np.hypot(dx, dy)
            ok &= (r > abs(l1 - l2)) & (r < l1 + l2)
            g = np.arccos(np.clip((l1 ** 2 + r ** 2 - l2 ** 2) / (2 * l1 * np.maximum(r, 1e-12)),
                                  -1, 1))
            two = []
            for e in (1, -1):
                t = np.arctan2(dy, dx) + e * g
                ux, uy = l1 * np.cos(t), l1 * np.sin(t)
                d0, d1 = Px - A[0] - ux, Py - A[1] - uy
                two.append((np.sign(ux * d1 - uy * d0),
                            np.stack([d0, d1, Rb[0] * d1 - Rb[1] * d0], -1)))
            legs.append(two)
        reach[:, :, k] = ok
        for w in modes:
            rows = [np.where((legs[i][0][0] == w[i])[..., None], legs[i][0][1], legs[i][1][1])
                    for i in range(3)]
            sign[w][:, :, k] = np.sign(np.linalg.det(np.stack(rows, -2)))
    return {(w, sg): _components(reach & (sign[w] == sg), cell)
            for w in modes for sg in (1, -1)}


@pytest.mark.slow
def test_3rrr_aspects_against_a_voxel_grid():
    """Legs with two postures: every working mode's aspects in (x, y, phi) against the
    grid's components, mode by mode. The grid's labels may differ from optkin's by a sign
    convention (the legs' postures, det A): one relabelling must match all 16."""
    m = optkin.mechanisms.rrr3(RRR_BASE, RRR_PLAT, 5.0, 4.0)
    res = optkin.aspects(m)  # no section: the 3-D aspects
    assert res.success, res.message
    grid = rrr_voxels(200)  # 16 components at 120^3, 160^3 and 200^3
    total = sum(sum(v) for v in grid.values())
    big = {k: [v for v in vols if v > 1e-3 * total] for k, vols in grid.items()}
    assert sum(len(v) for v in big.values()) == len(res) == 16
    mine: dict = {}
    for a in res:
        mine.setdefault((tuple(a.working_mode), a.det_sign), []).append(a.volume)
    matched = 0
    for fw in (1, -1):
        for fs in (1, -1):
            ref = {(tuple(fw * np.array(w)), fs * sg): v for (w, sg), v in big.items()}
            if set(ref) == set(mine) and all(
                    len(ref[k]) == len(mine[k]) and all(
                        abs(x - y) < 3e-3 * y for x, y in zip(sorted(mine[k]), sorted(ref[k])))
                    for k in ref):
                matched += 1
    assert matched >= 1, (mine, big)
    # every working mode: one aspect of each sign of det A, volumes summing to the mode's
    # reachable volume (the same for every mode)
    per_mode = {}
    for a in res:
        per_mode.setdefault(tuple(a.working_mode), []).append(a)
    assert len(per_mode) == 8
    sums = [sum(a.volume for a in v) for v in per_mode.values()]
    assert all(sorted(a.det_sign for a in v) == [-1, 1] for v in per_mode.values())
    assert np.ptp(sums) < 1e-3 * np.mean(sums)


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


def test_the_phi_integrals_error_estimate_points_at_kinks():
    """:func:`_interval_errors` (which drives ``vol_tol``'s refinement) on closed forms: a
    smooth periodic area (integral 6 pi) has small estimates everywhere; 3 + |sin(phi -
    0.05)| (integral 6 pi + 4) has its largest on the two intervals holding its kinks
    (and their neighbours), and their sum bounds the integral's actual error."""
    from optkin.analysis.aspects3d import _interval_errors

    phi = np.linspace(-np.pi, np.pi, 36, endpoint=False)
    e, v = _interval_errors(phi, 3 + np.cos(phi) + 0.5 * np.sin(2 * phi))
    assert abs(v - 6 * np.pi) < 1e-9
    ek, vk = _interval_errors(phi, 3 + np.abs(np.sin(phi - 0.05)))
    kinks = [int(np.searchsorted(phi, q) - 1) for q in (0.05, 0.05 - np.pi)]
    assert phi[kinks[0]] < 0.05 < phi[kinks[0] + 1] and kinks[1] == 0
    assert set(kinks) <= set(np.argsort(-ek)[:4].tolist())
    assert e.max() < ek[kinks].min() / 5
    assert 1e-4 < abs(vk - (6 * np.pi + 4)) <= ek.sum()


def test_plot_gives_each_working_mode_its_panel(tmp_path):
    """Aspects of several working modes overlap in (x, y, phi): one panel per mode, each
    with its own aspects in its legend; one mode (or an Axes given): one panel."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from optkin.analysis.aspects3d import Aspect3D, Aspects3D
    from optkin.analysis.planar import Face

    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])

    def asp(mode, sign, dx):
        f = Face(sq + dx, area=1.0, point=np.array([0.5 + dx, 0.5]))
        return Aspect3D(mode, sign, 1.0, np.zeros((3, 2)), np.zeros(6),
                        [(-0.1, f), (0.1, f)])

    many = Aspects3D("m", [asp((1, 1, 1), 1, 0), asp((1, 1, 1), -1, 2),
                           asp((1, -1, 1), 1, 4)], np.array([-0.1, 0.1]), True, "optimal", "")
    fig = many.plot(str(tmp_path / "a.png"))
    assert (tmp_path / "a.png").stat().st_size > 0
    titles = [ax.get_title() for ax in fig.axes]
    assert titles == ["working mode (+, +, +)", "working mode (+, -, +)"]
    legends = [[t.get_text() for t in ax.get_legend().get_texts()] for ax in fig.axes]
    assert [len(x) for x in legends] == [2, 1] and legends[1][0].startswith("aspect 3:")
    one = Aspects3D("m", many.aspects[:2], many.phis, True, "optimal", "")
    assert len(one.plot().axes) == 1
    ax = plt.figure().add_subplot(projection="3d")
    assert many.plot(ax=ax) is ax.figure and len(ax.get_legend().get_texts()) == 3
    plt.close("all")


def test_a_section_whose_curves_stopped_early_makes_the_result_inaccurate(monkeypatch):
    """Such a section may lack faces or merge two, so the aspects may be split or joined
    wrongly: the result says so (status "inaccurate", the orientation named), aspects kept.
    The 3-RPR's sections at phi = 0 made to report a stalled curve."""
    import dataclasses
    import sys

    mod = sys.modules["optkin.analysis.aspects"]  # (optkin.analysis.aspects: the function)
    real = mod.aspects
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    kw = dict(limits=LIMITS, slices=4, min_gap=10.0, modes=False)  # 4 sections, no refinement
    clean = aspects3d(m, **kw)
    assert clean.success and clean.status == "optimal" and "stopped early" not in clean.message

    def stalled_at_zero(*args, **kwargs):
        r = real(*args, **kwargs)
        if kwargs["fixed"]["phi"] == 0.0:
            c = r.curves.curves[0]
            r.curves.curves[0] = dataclasses.replace(c, ends=(c.ends[0], "stalled"))
        return r

    monkeypatch.setattr(mod, "aspects", stalled_at_zero)
    res = aspects3d(m, **kw)
    assert not res.success and res.status == "inaccurate"
    assert "the curves of 1 section(s) stopped early" in res.message and "phi = 0" in res.message
    assert len(res) == len(clean)
