"""inverse: every posture for a pose."""

from __future__ import annotations

import numpy as np
from conftest import median_time, record
from scipy.optimize import least_squares

import optkin


def leg_closed_form(leg, R: np.ndarray, p: np.ndarray) -> list[float]:
    """The actuated joint values of one leg at the pose (R, p), by the textbook closed
    forms written here with numpy: a prismatic leg (RPR, UPS) is the distance from its base
    to its platform point; a revolute one (RRR planar, RUS) puts its elbow on the circle
    of its first link at the second link's length from the platform point (two values)."""
    a = np.asarray(leg.base, dtype=float)
    c = R @ np.asarray(leg.platform, dtype=float) + p
    d = c - a
    if leg.type in ("RPR", "UPS"):
        return [float(np.linalg.norm(d))]
    l1, l2 = leg.lengths
    if leg.type == "RRR":  # planar: angle of the first link from the x axis
        A, B = d[0], d[1]
    else:  # RUS: the arm turns about its axis, from its direction at zero
        u = np.asarray(leg.arm, dtype=float)
        w = np.cross(np.asarray(leg.axis, dtype=float), u)
        A, B = d @ u, d @ w
    C = (d @ d + l1 * l1 - l2 * l2) / (2 * l1)
    r = np.hypot(A, B)
    if abs(C) > r:
        return []
    base, half = np.arctan2(B, A), np.arccos(C / r)
    return [float(base + half), float(base - half)]


def test_inverse(benchmark, ref):
    """Baseline: legs, the numpy closed form leg by leg (:func:`leg_closed_form`);
    Khalil tables, scipy.optimize.least_squares on [Phi; task error] from 64 random starts."""
    mech = ref.mech
    T = ref.sol.pose
    model = optkin.get_model(mech)
    model.compile()
    sols = benchmark(lambda: optkin.inverse(mech, T))
    if mech.kind == "legs":
        R, p = T[:3, :3], T[:3, 3]
        if mech.planar:
            R, p = R[:2, :2], p[:2]
        base = median_time(lambda: [leg_closed_form(leg, R, p) for leg in mech.legs])
        name = "numpy closed form of every leg"
        # (and the baseline is right: the reference's actuated values are among its own)
        for leg, qa in zip(mech.legs, ref.qa):
            got = leg_closed_form(leg, R, p)
            assert min(abs(np.angle(np.exp(1j * (g - qa)))) for g in got) < 1e-6, \
                (ref.name, leg.type, got, qa)
    else:  # a Khalil table: [closure; task error] in (qa, x) from random starts
        from scipy.spatial.transform import Rotation

        nqa = len(ref.qa)
        nz = nqa + len(model.default_x(ref.qa))
        axes = {"x": 0, "y": 1, "z": 2}

        def G(z):
            qa, x = z[:nqa], z[nqa:]
            Te = np.asarray(model.pose(qa, x), dtype=float)
            rot = Rotation.from_matrix(Te[:3, :3] @ T[:3, :3].T).as_rotvec()
            err = [Te[axes[c], 3] - T[axes[c], 3] if c in axes else rot[axes[c[1]]]
                   for c in mech.task]
            return np.r_[np.asarray(model.residual(qa, x), dtype=float).ravel(), err]

        rng = np.random.default_rng(0)
        starts = rng.uniform(-np.pi, np.pi, (64, nz))

        def run():
            out = []
            for s in starts:
                r = least_squares(G, s, xtol=1e-10, ftol=1e-10, max_nfev=200)
                if r.success and np.max(np.abs(r.fun)) < 1e-8:
                    out.append(r.x)
            return out

        base = median_time(run, min_time=0.1, max_rounds=3)
        benchmark.extra_info["baseline_solutions"] = len(run())  # (not distinct ones)
        name = "scipy least_squares from 64 random starts"
    record(benchmark, base, name, mechanism=ref.name, status="optimal" if len(sols) else
           "infeasible", nit=int(sum(r.nit for r in sols)), postures=len(sols))
    assert len(sols) >= 1
    d = min(np.max(np.abs(np.asarray(r.qa) - ref.qa)) for r in sols)
    benchmark.extra_info["reference_found"] = bool(d < 1e-6)
