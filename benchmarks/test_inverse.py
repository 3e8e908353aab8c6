"""inverse: every posture for a pose."""

from __future__ import annotations

import numpy as np
from conftest import median_time, record
from scipy.optimize import fsolve

import optkin
from optkin.mechanism.legs import leg_inverse
from optkin.model import khalil as kh


def test_inverse(benchmark, ref):
    """Baseline: legs, the numpy closed form leg by leg (leg_inverse) for every leg;
    Khalil tables, scipy.optimize.fsolve on [Phi; task error] from 64 random starts."""
    mech = ref.mech
    T = ref.sol.pose
    model = optkin.get_model(mech)
    model.compile()
    sols = benchmark(lambda: optkin.inverse(mech, T))
    if mech.kind == "legs":
        R, p = T[:3, :3], T[:3, 3]
        if mech.planar:
            R, p = R[:2, :2], p[:2]
        base = median_time(lambda: [leg_inverse(leg, R, p) for leg in mech.legs])
        name = "numpy leg_inverse of every leg"
    else:
        import casadi as ca

        nq = len(mech.joint_names)
        q = ca.SX.sym("q", nq)
        Tq = kh.frames_0(mech, q)
        rows, names = kh.closure_rows(mech, Tq)
        phi = rows[[names.index(n) for n in model.row_names]]
        Te = Tq[mech.end_effector]
        comps = {"x": Te[0, 3] - T[0, 3], "y": Te[1, 3] - T[1, 3], "z": Te[2, 3] - T[2, 3]}
        g = kh.gibbs(ca.mtimes(Te[:3, :3], T[:3, :3].T))
        comps.update({"rx": g[0], "ry": g[1], "rz": g[2]})
        G = ca.Function("G", [q], [ca.vertcat(phi, *[comps[c] for c in mech.task])])
        rng = np.random.default_rng(0)
        starts = rng.uniform(-np.pi, np.pi, (64, nq))

        def run():
            out = []
            for s in starts:
                z, _, ier, _ = fsolve(lambda z: np.array(G(z)).ravel(), s, full_output=True)
                if ier == 1:
                    out.append(z)
            return out

        base = median_time(run, min_time=0.1, max_rounds=3)
        name = "scipy fsolve from 64 random starts"
    record(benchmark, base, name, mechanism=ref.name, status="optimal" if len(sols) else
           "infeasible", nit=int(sum(r.nit for r in sols)), postures=len(sols))
    assert len(sols) >= 1
    d = min(np.max(np.abs(np.asarray(r.qa) - ref.qa)) for r in sols)
    benchmark.extra_info["reference_found"] = bool(d < 1e-6)
