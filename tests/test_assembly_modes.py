"""Every assembly mode, tracking and working modes, against independent references.

References written here, independent of optkin's model and solvers:

* 3-RPR: Modern Robotics 7.1.1 elimination. Differences of the squared leg equations
  |p + R(phi) b_i - a_i|^2 = s_i^2 are linear in p; Cramer's rule and t = tan(phi/2) turn the
  remaining equation into a univariate polynomial, solved with ``numpy.roots``.
* five-bar and four-bar: circle intersections in closed form.
* Stewart-Gough: the leg equations of Modern Robotics 7.1.2 evaluated from the returned pose;
  Dietmaier's platform (40 real solutions, a published number); the mirror symmetry of a
  planar-base/planar-platform design; a brute-force count by a vectorised numpy Newton in
  rotation-vector coordinates from many random starts (slow).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.polynomial import polynomial as Pn
from scipy.optimize import brentq

import optkin
from optkin import MechanismError
from optkin.mechanism.geometry import rpy_to_matrix

# ---------------------------------------------------------------------------------------------
# reference: 3-RPR by elimination (Modern Robotics 7.1.1)
# ---------------------------------------------------------------------------------------------


def _rot2(phi: float) -> np.ndarray:
    c, s = np.cos(phi), np.sin(phi)
    return np.array([[c, -s], [s, c]])


def _p_of_phi(a, b, s, phi):
    d = (_rot2(phi) @ b.T).T - a
    e = np.sum(d * d, 1) - s**2
    A = 2 * (d[1:] - d[:1])
    return np.linalg.solve(A, -(e[1:] - e[:1])), d, e


def _polish_phi(a, b, s, phi):
    """Newton on g(phi) = eq. 1 at p(phi), then the full residual check."""
    def g(ph):
        p, d, e = _p_of_phi(a, b, s, ph)
        return p @ p + 2 * p @ d[0] + e[0]

    try:
        for _ in range(40):
            h = 1e-7
            dg = (g(phi + h) - g(phi - h)) / (2 * h)
            if dg == 0:
                break
            step = g(phi) / dg
            phi -= step
            if abs(step) < 1e-15:
                break
        p, _, _ = _p_of_phi(a, b, s, phi)
    except np.linalg.LinAlgError:
        return None
    res = np.linalg.norm(p + (_rot2(phi) @ b.T).T - a, axis=1) - s
    if not np.all(np.isfinite(res)) or np.max(np.abs(res)) > 1e-8 * max(1.0, s.max()):
        return None
    return np.array([p[0], p[1], np.arctan2(np.sin(phi), np.cos(phi))])


def rpr_polynomial(a, b, s):
    """The univariate polynomial in t = tan(phi/2) of the elimination (coefficients, lowest
    degree first)."""
    return _elimination(a, b, s)[0]


def rpr_reference(a, b, s, imag_tol=1e-6):
    """All real (x, y, phi) of the 3-RPR with base a (3, 2), platform b (3, 2), legs s.

    Returns (solutions, ambiguous): ``ambiguous`` is True when a root of the polynomial is
    nearly real (|imag| between imag_tol and 1e-3): a near-double root the floating-point
    count cannot settle.
    """
    a, b, s = (np.asarray(v, dtype=float) for v in (a, b, s))
    G = _elimination(a, b, s)[0]
    roots = np.roots(G[::-1])
    out: list[np.ndarray] = []
    ambiguous = False
    for t in roots:
        im = abs(t.imag) / max(1.0, abs(t))
        if im > imag_tol:
            ambiguous |= im < 1e-3
            continue
        sol = _polish_phi(a, b, s, 2 * np.arctan(t.real))
        if sol is not None and not any(_close(sol, o) for o in out):
            out.append(sol)
    sol = _polish_phi(a, b, s, np.pi)  # t = infinity
    if sol is not None and not any(_close(sol, o) for o in out):
        out.append(sol)
    return out, ambiguous


def _elimination(a, b, s):
    a, b, s = (np.asarray(v, dtype=float) for v in (a, b, s))
    C, S, W = np.array([1.0, 0.0, -1.0]), np.array([0.0, 2.0]), np.array([1.0, 0.0, 1.0])
    add, sub, mul = Pn.polyadd, Pn.polysub, Pn.polymul

    def sc(k, p):
        return Pn.polymul([k], p)

    def rot(v):  # W R(phi) v: homogeneous of degree 1 in (C, S, W)
        return sub(sc(v[0], C), sc(v[1], S)), add(sc(v[0], S), sc(v[1], C))

    e, dW = [], []
    for i in range(3):
        Rb = rot(b[i])
        k = a[i] @ a[i] + b[i] @ b[i] - s[i] ** 2  # |d|^2 = |a|^2 + |b|^2 - 2 a.Rb
        e.append(sub(sc(k, W), add(sc(2 * a[i][0], Rb[0]), sc(2 * a[i][1], Rb[1]))))
        dW.append((sub(Rb[0], sc(a[i][0], W)), sub(Rb[1], sc(a[i][1], W))))
    M = [[sc(2, sub(dW[i][j], dW[0][j])) for j in range(2)] for i in (1, 2)]
    r = [sub(e[0], e[i]) for i in (1, 2)]
    D = sub(mul(M[0][0], M[1][1]), mul(M[0][1], M[1][0]))
    Nx = sub(mul(r[0], M[1][1]), mul(M[0][1], r[1]))
    Ny = sub(mul(M[0][0], r[1]), mul(r[0], M[1][0]))
    # equation 1 times D^2 W:  W |N|^2 + 2 D N.(W d_1) + D^2 e_1 = 0
    G = add(mul(W, add(mul(Nx, Nx), mul(Ny, Ny))),
            add(sc(2, mul(D, add(mul(Nx, dW[0][0]), mul(Ny, dW[0][1])))), mul(mul(D, D), e[0])))
    return np.trim_zeros(G, "b"), (D, Nx, Ny)


def _close(u, v, tol=1e-7):
    d = np.asarray(u, float) - np.asarray(v, float)
    d[-1] = np.arctan2(np.sin(d[-1]), np.cos(d[-1]))
    return np.max(np.abs(d)) < tol


def _matches(found: list[np.ndarray], ref: list[np.ndarray], tol: float = 1e-6) -> bool:
    """Same number and a one-to-one match within tol (last coordinate an angle)."""
    if len(found) != len(ref):
        return False
    used = set()
    for r in ref:
        k = next((i for i, f in enumerate(found) if i not in used and _close(f, r, tol)), None)
        if k is None:
            return False
        used.add(k)
    return True


def _random_rpr(rng):
    a = rng.uniform(-1, 1, (3, 2))
    b = rng.uniform(-1, 1, (3, 2))
    x = np.array([*rng.uniform(-0.5, 0.5, 2), rng.uniform(-np.pi, np.pi)])
    s = np.linalg.norm(x[:2] + (_rot2(x[2]) @ b.T).T - a, axis=1)
    return a, b, s


#: A 3-RPR with 6 real assembly modes, found by a brute-force search over random
#: geometries (rng seed 1, trial 21) with :func:`rpr_reference`; rounded to 6 digits.
SIX_A = np.array([[0.894012, 0.297702], [0.169933, -0.869403], [-0.895647, -0.577203]])
SIX_B = np.array([[-0.724354, 0.9675], [-0.994506, -0.268313], [-0.883155, 0.280021]])
SIX_S = np.array([1.478218, 1.02988, 1.397834])


def test_reference_is_exact_on_a_constructed_pose():
    rng = np.random.default_rng(3)
    a, b, s = _random_rpr(rng)
    x = np.array([0.2, -0.1, 0.7])
    s = np.linalg.norm(x[:2] + (_rot2(x[2]) @ b.T).T - a, axis=1)
    ref, _ = rpr_reference(a, b, s)
    assert any(_close(r, x, 1e-9) for r in ref)


def test_rpr3_six_real_modes_all_found_in_20_seeds():
    ref, amb = rpr_reference(SIX_A, SIX_B, SIX_S)
    assert len(ref) == 6 and not amb
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    for seed in range(20):
        modes = optkin.assembly_modes(m, SIX_S, seed=seed, method="multistart")
        assert _matches([r.x for r in modes], ref), (seed, len(modes))
        assert modes.info["complete"] and modes.info["stop_reason"] == "bound"
        for r in modes:
            assert r.success and r.residual < 1e-10 and np.isfinite(r.cond)


def _rpr_random_cases(n, seed):
    rng = np.random.default_rng(seed)
    skipped = mism = 0
    counts = {}
    for trial in range(n):
        a, b, s = _random_rpr(rng)
        ref, amb = rpr_reference(a, b, s)
        m = optkin.mechanisms.rpr3(a, b)
        modes = optkin.assembly_modes(m, s, seed=trial)
        ok = _matches([r.x for r in modes], ref)
        if not ok:
            near = [r for r in modes if r.cond > 1e6]
            if amb or near:
                skipped += 1
                continue
            mism += 1
        counts[len(ref)] = counts.get(len(ref), 0) + 1
    return counts, skipped, mism


def test_rpr3_200_random_geometries_match_the_elimination():
    counts, skipped, mism = _rpr_random_cases(200, 5)
    assert mism == 0 and skipped <= 10, (counts, skipped)
    assert set(counts) >= {2, 4, 6}


# ---------------------------------------------------------------------------------------------
# five-bar and four-bar: circle intersections
# ---------------------------------------------------------------------------------------------


def circle_intersections(c1, r1, c2, r2, margin=1e-7):
    """Intersection points of two circles; None when (nearly) tangent."""
    c1, c2 = np.asarray(c1, float), np.asarray(c2, float)
    d = np.linalg.norm(c2 - c1)
    if d < 1e-12:
        return None
    if abs(d - (r1 + r2)) < margin or abs(d - abs(r1 - r2)) < margin:
        return None
    if d > r1 + r2 or d < abs(r1 - r2):
        return []
    u = (c2 - c1) / d
    along = (d * d + r1 * r1 - r2 * r2) / (2 * d)
    h = np.sqrt(max(r1 * r1 - along * along, 0.0))
    n = np.array([-u[1], u[0]])
    m = c1 + along * u
    return [m + h * n, m - h * n]


def five_bar_reference(L, th1, th2):
    L0, L1, L2, L3, L4 = L
    C1 = L1 * np.array([np.cos(th1), np.sin(th1)])
    C2 = np.array([L0, 0.0]) + L4 * np.array([np.cos(th2), np.sin(th2)])
    return circle_intersections(C1, L2, C2, L3), C1, C2


def _five_bar_cases(n, seed):
    rng = np.random.default_rng(seed)
    seen = {0: 0, 2: 0}
    for trial in range(n):
        L = rng.uniform(0.5, 2.0, 5)
        th = rng.uniform(-np.pi, np.pi, 2)
        ref, _, _ = five_bar_reference(L, *th)
        if ref is None:
            continue
        m = optkin.mechanisms.five_bar(*L)
        modes = optkin.assembly_modes(m, th, seed=trial)
        got = [r.x for r in modes]
        assert len(got) == len(ref), (trial, len(got), len(ref))
        for p in ref:
            assert min(np.max(np.abs(g - p)) for g in got) < 1e-8
        seen[len(ref)] += 1
        if ref:
            assert modes.info["complete"]
    return seen


def test_five_bar_200_random_against_circle_intersection():
    seen = _five_bar_cases(200, 12)
    assert seen[0] > 10 and seen[2] > 40


def _four_bar_cases(n, seed):
    """Khalil table (passive and cut joints unknown): the rocker angle phi."""
    rng = np.random.default_rng(seed)
    n2 = 0
    for trial in range(n):
        L1, L2, L3, L4 = rng.uniform(0.5, 2.5, 4)
        th = rng.uniform(-np.pi, np.pi)
        B = L1 * np.array([np.cos(th), np.sin(th)])
        D = np.array([L4, 0.0])
        ref = circle_intersections(B, L2, D, L3)
        if ref is None:
            continue
        m = optkin.mechanisms.four_bar(L1, L2, L3, L4)
        modes = optkin.assembly_modes(m, [th], seed=trial)
        assert len(modes) == len(ref), (trial, len(modes), len(ref))
        iphi = m.joint_names.index("phi")
        phis = [r.q[iphi] for r in modes]
        for C in ref:
            want = np.arctan2(C[1] - D[1], C[0] - D[0])
            assert min(abs(np.angle(np.exp(1j * (p - want)))) for p in phis) < 1e-8
        n2 += len(ref) == 2
    return n2


@pytest.mark.slow
def test_four_bar_200_random_against_circle_intersection():
    assert _four_bar_cases(200, 3) > 50


def test_docstring_examples():
    import doctest

    from optkin.solvers import enumerate as en

    failures, tried = doctest.testmod(en, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


# ---------------------------------------------------------------------------------------------
# Stewart-Gough
# ---------------------------------------------------------------------------------------------

#: Dietmaier (1998), "The Stewart-Gough platform of general geometry can have 40 real
#: postures" (Advances in Robot Kinematics): base a_i, platform b_i, leg lengths; the numbers
#: as reproduced in the Drake repository's Stewart-platform global-IK example.
DIET_A = np.array([[0, 0, 0], [1.107915, 0, 0], [0.549094, 0.756063, 0],
                   [0.735077, -0.223935, 0.525991], [0.514188, -0.526063, -0.368418],
                   [0.590473, 0.094733, -0.205018]])
DIET_B = np.array([[0, 0, 0], [0.542805, 0, 0], [0.956919, -0.528915, 0],
                   [0.665885, -0.353482, 1.402538], [0.478359, 1.158742, 0.107672],
                   [-0.137087, -0.235121, 0.353913]])
DIET_L = np.array([1, 0.645275, 1.086284, 1.503439, 1.281933, 0.771071])


def leg_residuals(T, a, b, s):
    """Modern Robotics 7.1.2: |p + R b_i - a_i| - s_i from a 4x4 pose."""
    R, p = T[:3, :3], T[:3, 3]
    return np.linalg.norm(p + b @ R.T - a, axis=1) - s


def _pose_distance(T1, T2, scale):
    return max(np.max(np.abs(T1[:3, 3] - T2[:3, 3])) / scale, np.max(np.abs(T1[:3, :3] - T2[:3, :3])))


def _check_distinct_and_closed(modes, a, b, s):
    poses = [r.pose for r in modes]
    for T in poses:
        assert np.max(np.abs(leg_residuals(T, a, b, s))) < 1e-9
        R = T[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3), atol=1e-12) and np.linalg.det(R) > 0
    for i in range(len(poses)):
        for j in range(i):
            assert _pose_distance(poses[i], poses[j], 1.0) > 1e-6


def test_dietmaier_40_real_solutions_in_20_seeds():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    for seed in range(20):
        modes = optkin.assembly_modes(m, DIET_L, seed=seed, method="multistart")
        assert len(modes) == 40, (seed, len(modes), modes.info)
        assert modes.info["complete"]
    _check_distinct_and_closed(modes, DIET_A, DIET_B, DIET_L)
    info = modes.info
    assert sum(info["hits"]) == info["converged"] <= info["starts"]
    assert all(r.stats.extra["hits"] == h for r, h in zip(modes, info["hits"]))


def test_dietmaier_40_real_by_the_path_account_in_20_seeds():
    """The default on Dietmaier's platform (planar base and platform: zeros no shipped
    start system has) is the homotopy from the generic platform's start system: 40 real
    in every seed, complete because every one of the 40 paths ends finite and
    nonsingular (not because a count reached a bound)."""
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    for seed in range(20):
        modes = optkin.assembly_modes(m, DIET_L, seed=seed)
        st = modes.stats
        assert st.method == "homotopy" and len(modes) == 40, (seed, modes.info["message"])
        assert (st.paths, st.finite, st.singular, st.failed, st.at_infinity) == (40, 40, 0, 0, 0)
        assert modes.complete and modes.dimension == 0
    _check_distinct_and_closed(modes, DIET_A, DIET_B, DIET_L)


def _planar_platform():
    ang = np.deg2rad([0, 50, 120, 170, 240, 290])
    a = np.column_stack([1.0 * np.cos(ang), 1.0 * np.sin(ang), np.zeros(6)])
    ang2 = np.deg2rad([20, 95, 140, 215, 260, 335])
    b = np.column_stack([0.5 * np.cos(ang2), 0.55 * np.sin(ang2), np.zeros(6)])
    return a, b


def test_planar_stewart_mirror_pairs():
    """Planar base and platform: every solution's mirror through the base plane is one."""
    a, b = _planar_platform()
    R0 = rpy_to_matrix(0.2, -0.15, 0.4)
    p0 = np.array([0.1, -0.05, 0.8])
    s = np.linalg.norm(p0 + b @ R0.T - a, axis=1)
    m = optkin.mechanisms.stewart_gough(a, b)
    modes = optkin.assembly_modes(m, s, seed=3)
    _check_distinct_and_closed(modes, a, b, s)
    assert len(modes) % 2 == 0 and len(modes) >= 2
    M = np.diag([1.0, 1.0, -1.0])
    poses = [r.pose for r in modes]

    def found(R, p):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, p
        return any(_pose_distance(T, P, 1.0) < 1e-6 for P in poses)

    assert found(R0, p0) and found(M @ R0 @ M, M @ p0)
    for T in poses:
        assert found(M @ T[:3, :3] @ M, M @ T[:3, 3])


def _rotvec_R(w):
    """Rodrigues, vectorised: w (n, 3) -> R (n, 3, 3)."""
    th = np.linalg.norm(w, axis=1)[:, None, None]
    K = np.zeros((w.shape[0], 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -w[:, 2], w[:, 1], -w[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = w[:, 2], -w[:, 1], w[:, 0]
    th = np.maximum(th, 1e-12)
    K = K / th
    return np.eye(3) + np.sin(th) * K + (1 - np.cos(th)) * (K @ K)


def brute_force_stewart(a, b, s, n=6000, iters=60, seed=0):
    """Independent count: damped Newton with finite-difference Jacobians on the squared leg
    equations in (p, rotation vector), vectorised over n random starts; distinct poses."""
    rng = np.random.default_rng(seed)
    z = np.hstack([rng.uniform(-1.5, 1.5, (n, 3)), rng.normal(size=(n, 3)) * np.pi / 2])

    def F(z):
        R = _rotvec_R(z[:, 3:])
        P = z[:, None, :3] + np.einsum("nij,kj->nki", R, b) - a[None]
        return np.sum(P * P, axis=2) - s[None] ** 2

    for _ in range(iters):
        f = F(z)
        J = np.empty((n, 6, 6))
        for k in range(6):
            dz = np.zeros(6)
            dz[k] = 1e-7
            J[:, :, k] = (F(z + dz) - F(z - dz)) / 2e-7
        try:
            step = np.linalg.solve(J, -f[..., None])[..., 0]
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(J[0], -f[0], rcond=None)[0][None].repeat(n, 0)
        step = np.nan_to_num(step)
        nrm = np.linalg.norm(step, axis=1, keepdims=True)
        z = z + step * np.minimum(1.0, 0.5 / np.maximum(nrm, 1e-300))
    ok = np.max(np.abs(F(z)), axis=1) < 1e-10
    R = _rotvec_R(z[ok, 3:])
    poses = []
    for Ri, pi in zip(R, z[ok, :3]):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = Ri, pi
        if not any(_pose_distance(T, P, 1.0) < 1e-6 for P in poses):
            poses.append(T)
    return poses


@pytest.mark.slow
def test_generic_stewart_against_brute_force():
    rng = np.random.default_rng(4)
    a = rng.uniform(-1, 1, (6, 3))
    b = rng.uniform(-0.6, 0.6, (6, 3))
    R0 = rpy_to_matrix(*rng.uniform(-0.5, 0.5, 3))
    p0 = np.array([0.1, 0.2, 0.9])
    s = np.linalg.norm(p0 + b @ R0.T - a, axis=1)
    ref = brute_force_stewart(a, b, s, n=8000, seed=1)
    m = optkin.mechanisms.stewart_gough(a, b)
    modes = optkin.assembly_modes(m, s, seed=0)
    _check_distinct_and_closed(modes, a, b, s)
    poses = [r.pose for r in modes]
    assert len(poses) == len(ref)
    for T in ref:
        assert min(_pose_distance(T, P, 1.0) for P in poses) < 1e-6


# ---------------------------------------------------------------------------------------------
# the account, options and errors
# ---------------------------------------------------------------------------------------------


def test_account_and_good_turing():
    m = optkin.mechanisms.rpr3(SIX_A, SIX_B)
    modes = optkin.assembly_modes(m, SIX_S * 1.02, seed=1, bound=None, min_starts=512)
    info = modes.info
    h = np.array(info["hits"])
    assert len(h) == len(modes) and sum(h) == info["converged"] <= info["starts"]
    assert info["singletons"] == int(np.sum(h == 1))
    # over the converged starts (those that converge draw a mode; the others draw nothing)
    assert info["p_new"] == pytest.approx(info["singletons"] / info["converged"])
    assert info["stop_reason"] in ("target", "budget") and info["starts"] >= 512
    assert "assembly modes from" in info["message"]
    assert modes.summary().startswith(f"{len(modes)} assembly modes")
    d = modes.to_dict()
    assert d["count"] == len(modes) and d["seed"] == 1


def test_odd_count_below_an_even_bound_runs_longer():
    """Non-real solutions pair up, so with the bound 40 an odd count is incomplete: the
    Good-Turing target may stop such a run only after 4 x min_starts."""
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    for seed in range(8):
        modes = optkin.assembly_modes(m, DIET_L, seed=seed, min_starts=64, target=0.05)
        assert modes.info["stop_reason"] in ("target", "bound")
        if modes.info["stop_reason"] == "target":
            assert modes.info["starts"] >= (256 if len(modes) % 2 else 64)


def test_budget_and_time_limit_stop():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    few = optkin.assembly_modes(m, DIET_L, starts=64, bound=None)
    assert few.info["stop_reason"] == "budget" and few.info["starts"] <= 64
    quick = optkin.assembly_modes(m, DIET_L, time_limit=0.0, bound=None)
    assert quick.info["stop_reason"] == "time_limit"


def test_ipopt_rescues_stalled_starts():
    """With tiny clamped steps and 3 iterations no start converges by Newton; IPOPT from the
    best stalled points finds both modes (checked against the circle intersection)."""
    L = (2.0, 1.5, 2.0, 2.0, 1.5)
    m = optkin.mechanisms.five_bar(*L)
    modes = optkin.assembly_modes(m, [1.2, 1.9], max_iter=3, step_max=0.05, starts=64,
                                  bound=None)
    ref, _, _ = five_bar_reference(L, 1.2, 1.9)
    assert modes.info["rescued"] == 2 and len(modes) == 2
    for p in ref:
        assert min(np.max(np.abs(r.x - p)) for r in modes) < 1e-9


def test_unreachable_lengths_give_an_empty_set():
    m = optkin.mechanisms.five_bar(4.0, 1.0, 1.0, 1.0, 1.0)
    modes = optkin.assembly_modes(m, [np.pi, 0.0])
    assert len(modes) == 0 and not modes.info["success"]
    assert "cannot" in modes.info["message"]


def test_option_errors():
    m = optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    with pytest.raises(ValueError, match="width must be a power of 2"):
        optkin.assembly_modes(m, [1.2, 1.9], width=30)
    with pytest.raises(MechanismError, match="unknown option 'budget'"):
        optkin.assembly_modes(m, [1.2, 1.9], budget=10)
    with pytest.raises(MechanismError, match=r"qa_path: expected an array of shape \(N, 2\)"):
        optkin.track(m, np.zeros((5, 3)))
    with pytest.raises(MechanismError, match="working modes are defined for fully parallel"):
        optkin.working_modes(optkin.mechanisms.four_bar(1.0, 2.0, 2.0, 2.5))


# ---------------------------------------------------------------------------------------------
# tracking
# ---------------------------------------------------------------------------------------------


def test_track_five_bar_against_closed_form():
    L = (2.0, 1.5, 2.0, 2.0, 1.5)
    m = optkin.mechanisms.five_bar(*L)
    path = np.column_stack([np.linspace(1.2, 1.8, 61), np.linspace(1.9, 1.5, 61)])
    start = optkin.assembly_modes(m, path[0])[0]
    res = optkin.track(m, path, start)
    assert res.info["status"] == "optimal" and len(res) == 61

    def side(P, C1, C2):  # which side of C1C2 the point is: the assembly mode
        u, v = C2 - C1, P - C1
        return np.sign(u[0] * v[1] - u[1] * v[0])

    ref0, C1, C2 = five_bar_reference(L, *path[0])
    mode = side(start.x, C1, C2)
    for r, qa in zip(res, path):
        ref, C1, C2 = five_bar_reference(L, *qa)
        want = next(P for P in ref if side(P, C1, C2) == mode)
        assert np.max(np.abs(r.x - want)) < 1e-9


def _legs_rpr(a, b, x):
    return np.linalg.norm(x[:2] + (_rot2(x[2]) @ b.T).T - a, axis=1)


def _det_rpr(a, b, x):
    """Modern Robotics: rows (u_i, (R b_i) x u_i) of the 3-RPR's static matrix."""
    R = _rot2(x[2])
    rows = []
    for i in range(3):
        P = x[:2] + R @ b[i]
        u = (P - a[i]) / np.linalg.norm(P - a[i])
        rb = R @ b[i]
        rows.append([u[0], u[1], rb[0] * u[1] - rb[1] * u[0]])
    return np.linalg.det(np.array(rows))


def test_track_rpr3_circle_of_1000_poses_stays_in_one_mode():
    ang = np.array([0.0, 2 * np.pi / 3, 4 * np.pi / 3])
    a = np.column_stack([np.cos(ang + 0.1), np.sin(ang + 0.1)])
    b = 0.35 * np.column_stack([np.cos(ang + 0.9), np.sin(ang + 0.9)])
    th = np.linspace(0, 2 * np.pi, 1000)
    poses = np.column_stack([0.1 * np.cos(th), 0.1 * np.sin(th), 0.3 * np.sin(th)])
    dets = np.array([_det_rpr(a, b, x) for x in poses])
    assert np.all(dets > 0)  # the reference path stays in one aspect
    Q = np.array([_legs_rpr(a, b, x) for x in poses])
    m = optkin.mechanisms.rpr3(a, b)
    res = optkin.track(m, Q, poses[0])
    assert res.info["status"] == "optimal" and len(res) == 1000
    X = np.array([r.x for r in res])
    assert np.max(np.abs(X - poses)) < 1e-8


def test_track_five_bar_stops_at_the_fold():
    """Distal links aligned (|C1 C2| = L2 + L3): the two modes merge; closed-form place."""
    L = (2.0, 1.5, 1.2, 1.2, 1.5)
    th2 = 1.9
    m = optkin.mechanisms.five_bar(*L)

    def gap(t1):
        _, C1, C2 = five_bar_reference(L, t1, th2)
        return np.linalg.norm(C1 - C2) - (L[2] + L[3])

    t_star = brentq(gap, -1.5, 1.2)
    path = np.column_stack([np.linspace(1.2, t_star - 0.3, 200), np.full(200, th2)])
    res = optkin.track(m, path, optkin.assembly_modes(m, path[0])[0])
    info = res.info
    assert info["status"] == "singular" and not info["success"]
    assert abs(info["qa_stop"][0] - t_star) < 1e-4
    k = info["stopped_at"]
    assert path[k - 1, 0] >= t_star >= path[k, 0]
    assert len(res) == k and res[-1].cond > 10


def test_track_rpr3_stops_where_two_modes_merge():
    """Leg 1 shortened across a value where two modes merge (the elimination's count drops
    by 2 there, located by bisection): tracking one of them stops there, "singular"."""
    a, b, s0 = SIX_A, SIX_B, SIX_S

    def count(r1):
        return len(rpr_reference(a, b, [r1, s0[1], s0[2]])[0])

    grid = np.linspace(s0[0], 0.3 * s0[0], 300)
    n = [count(r) for r in grid]
    k = next(i for i in range(1, len(grid)) if n[i] == n[i - 1] - 2)
    hi, lo = grid[k - 1], grid[k]
    for _ in range(40):
        mid = 0.5 * (hi + lo)
        hi, lo = (mid, lo) if count(mid) == n[k - 1] else (hi, mid)
    r_star = 0.5 * (hi + lo)
    near = rpr_reference(a, b, [r_star + 1e-6, s0[1], s0[2]])[0]
    i, j = min(((i, j) for i in range(len(near)) for j in range(i)),
               key=lambda ij: np.max(np.abs(near[ij[0]] - near[ij[1]])))
    pair_mid = 0.5 * (near[i] + near[j])
    r0 = r_star + 0.02
    start = min(rpr_reference(a, b, [r0, s0[1], s0[2]])[0],
                key=lambda x: np.max(np.abs(x - pair_mid)))
    path = np.column_stack([np.linspace(r0, r_star - 0.02, 81), np.full(81, s0[1]),
                            np.full(81, s0[2])])
    m = optkin.mechanisms.rpr3(a, b)
    res = optkin.track(m, path, start)
    info = res.info
    assert info["status"] == "singular", info["message"]
    assert abs(info["qa_stop"][0] - r_star) < 1e-4
    assert res[-1].qa[0] >= r_star


# ---------------------------------------------------------------------------------------------
# working modes
# ---------------------------------------------------------------------------------------------


def test_working_modes_counts_seed_004():
    assert len(optkin.working_modes(optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5))) == 4
    assert len(optkin.working_modes(optkin.mechanisms.delta())) == 8  # Example 1: 2^3
    assert len(optkin.working_modes(optkin.mechanisms.rpr3(SIX_A, SIX_B))) == 1


def test_working_modes_at_a_pose_match_the_elbow_signs():
    L0, L1, L2, L3, L4 = 2.0, 1.5, 2.0, 2.0, 1.5
    m = optkin.mechanisms.five_bar(L0, L1, L2, L3, L4)
    P = np.array([1.0, 1.8])
    wm = optkin.working_modes(m, pose=P)
    assert len(wm.existing) == 4
    bases = [np.zeros(2), np.array([L0, 0.0])]
    prox = [L1, L4]
    for mode, r in wm.existing.items():
        for j in range(2):
            th = r.qa[j]
            C = bases[j] + prox[j] * np.array([np.cos(th), np.sin(th)])
            # B_jj = d/dtheta_j |P - C(theta_j)| = -(P - C).(dC/dtheta) / |P - C|
            dC = prox[j] * np.array([-np.sin(th), np.cos(th)])
            assert mode[j] == np.sign(-(P - C) @ dC)
    d = wm.to_dict()
    assert d["count"] == 4 and d["count_at_pose"] == 4


def test_checked_options_are_reused_only_for_the_same_values_types_and_budget(monkeypatch):
    """assembly_modes checks a set of option values once (enumerate._assembly_options):
    a value equal but of another type (1 for True) is still refused, and a time limit the
    budget allowed is refused once the budget is lowered."""
    A = np.array([[0, 0], [10, 0], [4, 8]], float)
    B = np.array([[-1, -0.5], [1, -0.5], [0, 1]], float)
    m = optkin.mechanisms.rpr3(A, B)
    c, s = np.cos(0.2), np.sin(0.2)
    qa = np.linalg.norm(np.array([4.0, 3.0]) + B @ np.array([[c, -s], [s, c]]).T - A, axis=1)
    assert optkin.assembly_modes(m, qa, certify=True, time_limit=5.0).success
    with pytest.raises(optkin.MechanismError, match="certify must be True or False"):
        optkin.assembly_modes(m, qa, certify=1, time_limit=5.0)
    monkeypatch.setenv("OPTKIN_TIME_BUDGET", "2")
    with pytest.raises(optkin.MechanismError, match="exceeds the time budget"):
        optkin.assembly_modes(m, qa, certify=True, time_limit=5.0)
