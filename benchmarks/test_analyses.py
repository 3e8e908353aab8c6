"""Analyses built by other issues, benchmarked when present (skipped otherwise):
assembly_modes, jacobians, classify, statics.capability, singular_curves, aspects.

Each beside an in-run baseline: finite differences of an fsolve direct model (jacobians,
classify), naive random multi-start IPOPT (assembly_modes), scipy.optimize.linprog
(capability), a brute-force numpy grid of det A (singular curves and aspects of the
five-bar of Chablat & Wenger 1998).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import fsolve_forward, median_time, numpy_residual, record, reference

import optkin


def api(name: str):
    """An optkin function if some issue has built it, else skip."""
    f = getattr(optkin, name, None)
    if f is None:
        import optkin.analysis as an

        f = getattr(an, name, None)
    if f is None:
        pytest.skip(f"optkin.{name} is not there yet")
    return f


def _fd_W(mech, qa, x, h=1e-6):
    fs = fsolve_forward(mech)
    cols = []
    for j in range(len(qa)):
        e = np.zeros(len(qa))
        e[j] = h
        cols.append((fs(qa + e, x)[0] - fs(qa - e, x)[0]) / (2 * h))
    return np.array(cols).T


def test_jacobians(benchmark, ref):
    jac = api("jacobians")
    J = benchmark(lambda: jac(ref.mech, ref.sol.q))
    base = median_time(lambda: _fd_W(ref.mech, ref.qa, ref.sol.x), min_time=0.1, max_rounds=20)
    ok = getattr(J, "success", True)
    agree = None
    if ref.mech.kind == "legs" and ref.mech.platform != "spatial" and hasattr(J, "W"):
        agree = bool(np.allclose(np.asarray(J.W), _fd_W(ref.mech, ref.qa, ref.sol.x),
                                 atol=1e-5))
    record(benchmark, base, "central differences of an fsolve direct model",
           mechanism=ref.name, status=getattr(J, "status", "optimal" if ok else "error"),
           nit=0, agrees_with_fd=agree)


def test_classify(benchmark, ref):
    cls = api("classify")
    rep = benchmark(lambda: cls(ref.mech, ref.sol.q))
    res = numpy_residual(ref.mech)

    def baseline():
        x, qa, h = ref.sol.x, ref.qa, 1e-6
        Wp = np.array([(res(qa, x + h * e) - res(qa, x - h * e)) / (2 * h)
                       for e in np.eye(len(x))]).T
        Wa = np.array([(res(qa + h * e, x) - res(qa - h * e, x)) / (2 * h)
                       for e in np.eye(len(qa))]).T
        return np.linalg.svd(Wp, compute_uv=False), np.linalg.svd(Wa, compute_uv=False)

    base = median_time(baseline)
    record(benchmark, base, "finite-difference W_p, W_a and their singular values (numpy)",
           mechanism=ref.name, status="optimal", nit=0,
           types=sorted(getattr(rep, "types", []) or []))


def _naive_multistart(mech, qa, n, seed=0):
    """Random starts, one IPOPT solve each (solver built once), distinct solutions."""
    model = optkin.get_model(mech)
    S = model.nlp()
    rng = np.random.default_rng(seed)
    sols = []
    for _ in range(n):
        if mech.kind == "legs" and mech.platform == "spatial":
            qq = rng.normal(size=4)
            x0 = np.r_[rng.uniform(-1, 1, 2), rng.uniform(0, 2), qq / np.linalg.norm(qq)]
        else:
            x0 = model.default_x(qa) + rng.uniform(-1, 1, model.nx) * model.x_scale
        r = S(x0=x0, p=np.r_[qa, x0, model.p], lbg=0, ubg=0)  # (q_a, guess, geometry)
        if S.stats()["success"]:
            x = model.canonical_x(np.array(r["x"]).ravel())
            if all(np.max(np.abs(x - y)) > 1e-6 for y in sols):
                sols.append(x)
    return sols


@pytest.mark.parametrize("name", ["rpr3", "five_bar", "stewart_gough"])
def test_assembly_modes(benchmark, name):
    am = api("assembly_modes")
    ref = reference(name)
    out = benchmark.pedantic(lambda: am(ref.mech, ref.qa), rounds=3, warmup_rounds=1)
    n_starts = 300 if name == "stewart_gough" else 100
    import time

    t0 = time.perf_counter()
    naive = _naive_multistart(ref.mech, ref.qa, n_starts)
    base = time.perf_counter() - t0
    record(benchmark, base, f"naive random multi-start IPOPT ({n_starts} starts)",
           mechanism=name, status="optimal" if len(out) else "infeasible",
           nit=int(sum(getattr(r, "nit", 0) for r in out)), modes=len(out),
           naive_modes=len(naive), info={k: v for k, v in getattr(out, "info", {}).items()
                                         if isinstance(v, (int, float, str, bool))})


@pytest.mark.parametrize("name", ["rpr3", "stewart_gough"])
def test_statics_capability(benchmark, name):
    statics = getattr(optkin, "statics", None)
    if statics is None or not hasattr(statics, "capability"):
        pytest.skip("optkin.statics.capability is not there yet")
    jac = api("jacobians")
    from scipy.optimize import linprog

    ref = reference(name)
    ntask = 3 if ref.mech.planar else 6
    rng = np.random.default_rng(1)
    D = rng.normal(size=(32, ntask))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    lim = np.ones(ref.mech.dof)
    cap = benchmark(lambda: statics.capability(ref.mech, ref.sol.q, lim, directions=D))
    J = jac(ref.mech, ref.sol.q)

    def baseline():
        A, B = np.asarray(J.A), np.asarray(J.B)
        G = np.linalg.solve(B, A).T  # the wrench of actuator forces (up to sign)
        out = []
        for d in D:
            c = np.r_[-1.0, np.zeros(len(lim))]
            Aeq = np.c_[d, -G]
            r = linprog(c, A_eq=Aeq, b_eq=np.zeros(ntask),
                        bounds=[(0, None)] + [(-b, b) for b in lim], method="highs")
            out.append(-r.fun if r.status == 0 else np.nan)
        return np.array(out)

    base = median_time(baseline, min_time=0.1, max_rounds=5)
    record(benchmark, base, "scipy linprog per direction", mechanism=name,
           status=getattr(cap, "status", "optimal"), nit=0, directions=len(D))


SEED004 = (9.0, 8.0, 5.0, 5.0, 8.0)


def _five_bar_grid(n: int = 1000):
    """Brute force: det A of the five-bar over an n x n workspace grid, per working mode,
    from the closed-form inverse model (numpy); counts the cells where its sign changes."""
    L0, L1, L2, L3, L4 = SEED004
    xs = np.linspace(-8, 17, n)
    ys = np.linspace(-13, 13, n)
    X, Y = np.meshgrid(xs, ys)
    cells = 0
    for s1 in (-1, 1):
        for s2 in (-1, 1):
            r1 = np.hypot(X, Y)
            c1 = np.clip((L1**2 + r1**2 - L2**2) / (2 * L1 * r1 + 1e-300), -1, 1)
            t1 = np.arctan2(Y, X) + s1 * np.arccos(c1)
            r2 = np.hypot(X - L0, Y)
            c2 = np.clip((L4**2 + r2**2 - L3**2) / (2 * L4 * r2 + 1e-300), -1, 1)
            t2 = np.arctan2(Y, X - L0) + s2 * np.arccos(c2)
            Cx, Cy = L1 * np.cos(t1), L1 * np.sin(t1)
            Dx, Dy = L0 + L4 * np.cos(t2), L4 * np.sin(t2)
            det = (X - Cx) * (Y - Dy) - (Y - Cy) * (X - Dx)
            ok = (np.abs(c1) < 1) & (np.abs(c2) < 1)
            sg = np.where(ok, np.sign(det), 0)
            cells += int(np.sum((sg[1:, :] * sg[:-1, :]) < 0) + np.sum((sg[:, 1:] * sg[:, :-1]) < 0))
    return cells


def test_singular_curves_five_bar(benchmark):
    sc = api("singular_curves")
    mech = optkin.mechanisms.five_bar(*SEED004)
    out = benchmark.pedantic(lambda: sc(mech), rounds=3, warmup_rounds=1)
    base = median_time(_five_bar_grid, min_time=0.1, max_rounds=3)
    curves = getattr(out, "curves", out)
    record(benchmark, base, "numpy grid 1000x1000 x 4 working modes, det A sign changes",
           mechanism="five_bar Chablat & Wenger 1998", status=getattr(out, "status", "optimal"), nit=0,
           curves=len(curves) if hasattr(curves, "__len__") else None, target_s=0.5)


def test_aspects_five_bar(benchmark):
    asp = api("aspects")
    mech = optkin.mechanisms.five_bar(*SEED004)
    out = benchmark.pedantic(lambda: asp(mech), rounds=2, warmup_rounds=1)
    base = median_time(_five_bar_grid, min_time=0.1, max_rounds=3)
    items = getattr(out, "aspects", out)
    record(benchmark, base, "numpy grid 1000x1000 x 4 working modes, det A sign changes",
           mechanism="five_bar Chablat & Wenger 1998", status=getattr(out, "status", "optimal"), nit=0,
           aspects=len(items) if hasattr(items, "__len__") else None, target_s=2.0)
