"""Parallel singularity surfaces of a 3-DoF planar platform (optkin.analysis.surfaces).

Evidence, written here: at a parallel singularity of a 3-RPR the three leg lines are
concurrent or parallel, i.e. the determinant of their homogeneous line coordinates
(A_i x P_i, with A_i the base and P_i the platform point as (x, y, 1)) vanishes; the
vertices' leg lengths are the distances |P_i - A_i| and lie within the strokes.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_continuation import BASE3, PLAT3

import optkin
from optkin.analysis.surfaces import singular_surfaces
from optkin.model import get_model

LIMITS = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}


def _legs(x, y, phi):
    c, s = np.cos(phi), np.sin(phi)
    P = np.stack([x[:, None] + c[:, None] * PLAT3[None, :, 0] - s[:, None] * PLAT3[None, :, 1],
                  y[:, None] + s[:, None] * PLAT3[None, :, 0] + c[:, None] * PLAT3[None, :, 1]],
                 -1)
    return P  # (N, 3, 2) platform points


def _concurrency(x, y, phi):
    """det of the three leg lines' homogeneous coordinates, each normalised to unit
    (a, b): zero when the lines meet in one point or are parallel."""
    P = _legs(x, y, phi)
    A = np.broadcast_to(BASE3, P.shape)
    h = lambda Q: np.concatenate([Q, np.ones(Q.shape[:-1] + (1,))], -1)  # noqa: E731
    lines = np.cross(h(A), h(P))
    lines /= np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)
    return np.linalg.det(lines)


@pytest.fixture(scope="module")
def rpr():
    return optkin.mechanisms.rpr3(BASE3, PLAT3)


@pytest.mark.parametrize("space", ["task", "joint"])
def test_vertices_make_the_legs_concurrent(rpr, space):
    s = singular_surfaces(rpr, space=space, limits=LIMITS, slices=24)
    assert s.success, s.message
    assert s.planes == []     # no section of this design is wholly singular
    assert len(s.triangles) > 100 and s.max_residual < 1e-9
    x, y, phi = s.v[:, 3], s.v[:, 4], s.v[:, 5]
    d = _concurrency(x, y, phi)
    assert np.max(np.abs(d)) < 1e-6, np.max(np.abs(d))
    rho = np.linalg.norm(_legs(x, y, phi) - BASE3[None], axis=-1)
    np.testing.assert_allclose(rho, s.v[:, :3], atol=1e-8)
    assert rho.min() >= 10 - 1e-9 and rho.max() <= 30 + 1e-9
    # the test discriminates: ordinary configurations are far from concurrent
    rng = np.random.default_rng(0)
    far = _concurrency(rng.uniform(-5, 5, 50), rng.uniform(-5, 5, 50),
                       rng.uniform(-np.pi, np.pi, 50))
    assert np.median(np.abs(far)) > 1e-2
    # the mesh indexes its vertices, and the third coordinate is the section's
    assert s.triangles.max() < len(s.vertices)
    assert set(np.round(s.vertices[:, 2], 12)) <= set(np.round(s.sections, 12))


def test_arguments(rpr):
    with pytest.raises(optkin.MechanismError, match="space must be 'task' or 'joint'"):
        singular_surfaces(rpr, space="both")
    with pytest.raises(optkin.MechanismError, match="not a 3-DoF planar platform"):
        singular_surfaces(optkin.mechanisms.five_bar(9, 8, 5, 5, 8))


def test_similar_triangles_make_whole_sections_singular():
    """A 3-RPR whose platform is its base scaled by s = 0.5: at phi = 0 the platform point
    P_i = t + s A_i, so every leg line A_i + lambda (P_i - A_i) passes through the
    homothety centre H = t / (1 - s) (lambda = 1 / (1 - s)) whatever t: the whole section
    is singular, and so is phi = pi (the scale -s). Those sections are reported as planes
    and meshed; every vertex, patches and traced curves alike, makes the leg lines
    concurrent or parallel (the determinant of their line coordinates, written here)."""
    base = np.array([[0.0, 0.0], [10.0, 0.0], [3.0, 8.0]])
    s_ = 0.5
    m = optkin.mechanisms.rpr3(base, s_ * base)
    lim = {f"L{i}.rho": (2.0, 15.0) for i in (1, 2, 3)}
    surf = singular_surfaces(m, space="task", limits=lim, slices=24)
    assert surf.success, surf.message
    assert 0.0 in surf.planes and -np.pi in surf.planes and len(surf.planes) == 2
    x, y, phi = surf.v[:, 3], surf.v[:, 4], surf.v[:, 5]
    c, s = np.cos(phi), np.sin(phi)
    P = np.stack([x[:, None] + s_ * (c[:, None] * base[None, :, 0] - s[:, None] * base[None, :, 1]),
                  y[:, None] + s_ * (s[:, None] * base[None, :, 0] + c[:, None] * base[None, :, 1])],
                 -1)
    h = lambda Q: np.concatenate([Q, np.ones(Q.shape[:-1] + (1,))], -1)  # noqa: E731
    lines = np.cross(h(np.broadcast_to(base, P.shape)), h(P))
    lines /= np.linalg.norm(lines[..., :2], axis=-1, keepdims=True)
    assert np.max(np.abs(np.linalg.det(lines))) < 1e-6
    # the phi = 0 patch: every leg through H = t / (1 - s)
    at0 = np.abs(phi) < 1e-12
    H = np.stack([x[at0], y[at0]], -1) / (1 - s_)
    dist = np.abs(np.einsum("nkj,nj->nk", lines[at0][..., :2], H) + lines[at0][..., 2])
    assert at0.sum() > 100 and dist.max() < 1e-9
    # it covers the section within the strokes (a grid of the plane, cells inside only)
    tri = surf.triangles[np.all(at0[surf.triangles], axis=1)]
    V = surf.vertices
    e1, e2 = V[tri[:, 1], :2] - V[tri[:, 0], :2], V[tri[:, 2], :2] - V[tri[:, 0], :2]
    patch = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    g = 0.02
    X, Y = np.meshgrid(np.arange(-20, 30, g), np.arange(-20, 30, g))
    Q = np.stack([X.ravel(), Y.ravel()], -1)
    rho = np.linalg.norm(Q[:, None] + s_ * base[None] - base[None], axis=-1)
    region = np.all((rho >= 2) & (rho <= 15), axis=1).sum() * g * g
    assert 0.85 * region <= patch <= region * 1.001


# ---------------------------------------------------------------------------------------
# a translational spatial platform: the Delta, in (x, y, z)
# ---------------------------------------------------------------------------------------
RB, RP, LA, LB = 0.2, 0.05, 0.3, 0.8  # base and platform radii, arm and forearm lengths
_U = np.stack([np.cos(2 * np.pi * np.arange(3) / 3), np.sin(2 * np.pi * np.arange(3) / 3),
               np.zeros(3)], 1)  # the legs' radial directions
_EZ = np.array([0.0, 0.0, 1.0])


def _forearms(theta, p):
    """Forearm vectors P_i - E_i (N, 3, 3) of the Delta written here: elbow E_i = RB u_i +
    LA (cos theta_i u_i - sin theta_i e_z) (the arm turns about the tangent to the base
    circle, down for theta > 0), platform joint P_i = p + RP u_i."""
    c, s = np.cos(theta)[..., None], np.sin(theta)[..., None]
    E = RB * _U + LA * (c * _U - s * _EZ)
    return p[:, None, :] + RP * _U - E


def _coplanarity(F):
    """det of the three forearm directions: zero exactly when the forearms are parallel
    to one plane (the Delta's parallel singularity: the platform gains a translation)."""
    return np.linalg.det(F) / np.prod(np.linalg.norm(F, axis=-1), axis=-1)


def _leg_inverse(p):
    """Both closed-form postures of each leg (N, 3, 2) at platform positions p (N, 3):
    |w - LA cos(t) u + LA sin(t) e_z| = LB with w = p + (RP - RB) u is
    A cos t + B sin t = C; NaN where the leg does not reach."""
    w = p[:, None, :] + (RP - RB) * _U
    A = -2 * LA * np.einsum("nij,ij->ni", w, _U)
    B = 2 * LA * w[..., 2]
    C = LB ** 2 - np.sum(w * w, -1) - LA ** 2
    with np.errstate(invalid="ignore"):
        half = np.arccos(C / np.hypot(A, B))
    mid = np.arctan2(B, A)
    return np.stack([mid + half, mid - half], -1)


@pytest.fixture(scope="module")
def delta_surface():
    return singular_surfaces(optkin.mechanisms.delta(RB, RP, LA, LB), slices=12)


def test_delta_vertices_make_the_forearms_coplanar(delta_surface):
    s = delta_surface
    assert s.success and s.names == ("x", "y", "z") and len(s.triangles) > 1000
    theta, p = s.v[:, :3], s.v[:, 3:6]
    F = _forearms(theta, p)
    np.testing.assert_allclose(np.linalg.norm(F, axis=-1), LB, atol=1e-9)  # closed
    assert np.max(np.abs(_coplanarity(F))) < 1e-8
    assert np.max(s.residual) < 1e-9
    np.testing.assert_array_equal(s.vertices, p)
    # a triangle joins points of one sheet: each leg in the same posture at its three
    # vertices (the sign of F_i . dE_i/dtheta_i, B's diagonal; a leg near its serial
    # singularity, where the sign is moot, is not compared)
    dE = LA * (-np.sin(theta)[..., None] * _U - np.cos(theta)[..., None] * _EZ)
    b = np.einsum("nij,nij->ni", F, dE) / (LA * LB)
    bt = b[s.triangles]  # (T, 3 vertices, 3 legs)
    clear = np.abs(bt) > 1e-2
    mixed = np.any(clear & (bt > 0), axis=1) & np.any(clear & (bt < 0), axis=1)
    assert not mixed.any(), int(mixed.sum())
    dz = np.ptp(p[s.triangles, 2], axis=1)
    assert np.all(dz <= np.max(np.diff(s.sections)) + 1e-12)  # within one gap
    # nothing traced off the surface, and every section holds some of it
    assert set(np.round(p[:, 2], 12)) <= set(np.round(s.sections, 12))
    assert np.all(np.isin(np.round(s.sections[2:-2], 12), np.round(p[:, 2], 12)))


def _sign_changes(z0, on):
    """(edges, misses): the grid edges of the section at z0 along which the coplanarity
    determinant changes sign in one posture combination (it vanishes between their ends),
    and how many of them lie farther from the points ``on`` (M, 2) than the grid spacing
    plus the continuation's step."""
    g = np.linspace(-1.1, 1.1, 90)
    h = g[1] - g[0]
    X, Y = np.meshgrid(g, g, indexing="ij")
    p = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z0)], 1)
    T = _leg_inverse(p)
    edges = misses = 0
    for combo in np.ndindex(2, 2, 2):
        th = np.stack([T[:, i, combo[i]] for i in range(3)], 1)
        with np.errstate(invalid="ignore"):
            D = _coplanarity(_forearms(th, p)).reshape(X.shape)
        for di, dj in ((1, 0), (0, 1)):
            a, b = D[:D.shape[0] - di, :D.shape[1] - dj], D[di:, dj:]
            for i, j in np.argwhere(np.isfinite(a) & np.isfinite(b) & (a * b < 0)):
                mid = np.array([g[i] + di * h / 2, g[j] + dj * h / 2])
                edges += 1
                misses += int(np.min(np.hypot(*(on - mid).T)) > h + 0.25 * LB)
    return edges, misses


def test_delta_surface_misses_no_sign_change_of_the_condition(delta_surface):
    """Brute force, written here: on a grid of each of three sections, every grid edge along
    which the coplanarity determinant changes sign in one posture combination lies within
    reach of the section's traced vertices; with half of each section's curves left out,
    the same count finds the gap (the check can fail)."""
    s = delta_surface
    for z0 in s.sections[[3, 5, 8]]:
        on = s.vertices[np.isclose(s.vertices[:, 2], z0, atol=1e-12), :2]
        edges, misses = _sign_changes(z0, on)
        assert edges > 50 and misses == 0, (z0, edges, misses)
    z0 = s.sections[5]
    on = s.vertices[np.isclose(s.vertices[:, 2], z0, atol=1e-12), :2]
    assert _sign_changes(z0, on[on[:, 0] < 0])[1] > 10  # the half x > 0 left out


def test_delta_arguments():
    d = optkin.mechanisms.delta(RB, RP, LA, LB)
    with pytest.raises(optkin.MechanismError, match="use space='task'"):
        singular_surfaces(d, space="joint")
    with pytest.raises(optkin.MechanismError, match="option range"):
        singular_surfaces(d, range=(0.2, -0.2))
    with pytest.raises(optkin.MechanismError, match="one fixed platform coordinate"):
        optkin.singular_curves(d, plane="workspace", kind="serial", fixed={"z": -0.6})
    s = singular_surfaces(d, slices=3, range=(-0.7, -0.5))
    np.testing.assert_allclose(s.sections, [-0.65, -0.6, -0.55])


# ---------------------------------------------------------------------------------------
# Tsai's 3-UPU: a translational mode of a platform with 19 unknowns, in (x, y, z)
# ---------------------------------------------------------------------------------------
# Each leg's constraint wrench is the couple n_i = t_i x w_i, normal to the two axes of its
# universal joints (t_i the base circle's tangent, w_i normal to t_i and to the leg
# s_i = p - d u_i, d = R - r): n_i ~ (u_i . p - d) u_i + p_z e_z. The platform turns (a
# constraint singularity) where n_1, n_2, n_3 are coplanar; det[n] = p_z sin(120 deg)
# (3 d^2 - 3/4 (x^2 + y^2)): above the base, the cylinder x^2 + y^2 = (2 d)^2.

def _couples(p, d):
    n = (np.einsum("nj,ij->ni", p, _U) - d)[..., None] * _U + p[:, None, 2:3] * _EZ
    return np.linalg.det(n) / np.prod(np.linalg.norm(n, axis=-1), axis=-1)


@pytest.fixture(scope="module")
def upu_surface():
    return singular_surfaces(optkin.mechanisms.upu3(1.0, 0.5), slices=6)


def test_3upu_vertices_make_the_constraint_couples_coplanar(upu_surface):
    s, d = upu_surface, 0.5
    assert s.success, s.message
    assert s.names == ("x", "y", "z") and len(s.triangles) > 100 and s.max_residual < 1e-9
    p = s.v[:, 3:6]
    np.testing.assert_array_equal(s.vertices, p)
    # in the translational mode, the legs closed: the identity orientation (quaternion
    # (1, 0, 0, 0)) and leg lengths |p - d u_i|
    np.testing.assert_allclose(s.v[:, 6:10], np.tile([1.0, 0, 0, 0], (len(p), 1)), atol=1e-9)
    rho = np.linalg.norm(p[:, None, :] - d * _U[None], axis=-1)
    np.testing.assert_allclose(s.v[:, :3], rho, atol=1e-9)
    assert np.max(np.abs(_couples(p, d))) < 1e-9
    assert np.max(np.abs(np.hypot(p[:, 0], p[:, 1]) - 2 * d)) < 1e-8
    # the model agrees: a parallel singularity at the vertices
    m = optkin.mechanisms.upu3(1.0, 0.5)
    for k in (0, len(p) // 2, len(p) - 1):
        q = get_model(m).to_q(s.v[k, :3], s.v[k, 3:])
        assert "parallel" in optkin.classify(m, q).types


def test_3upu_arguments():
    m = optkin.mechanisms.upu3(1.0, 0.5)
    with pytest.raises(optkin.MechanismError, match="use space='task'"):
        singular_surfaces(m, space="joint")
    s = singular_surfaces(m, slices=2, range=(0.6, 0.9), bounds=[[-1.5, 1.5], [-1.5, 1.5]])
    assert s.success and len(s.triangles) > 10
    np.testing.assert_allclose(s.sections, [0.7, 0.8])
    # a platform that turns as its legs move has no surface in (x, y, z)
    with pytest.raises(optkin.MechanismError, match="turn its platform"):
        singular_surfaces(optkin.mechanisms.rps3(), slices=2)


def test_3upu_surface_misses_no_sign_change_of_the_condition(upu_surface):
    """Brute force, written here: along 36 rays of each section, the couples' determinant
    changes sign once between radii 0.1 and 1.9, and the section's vertices pass within the
    continuation's step of that crossing; with a quarter of the vertices left out, some
    crossing is missed (the check can fail)."""
    s, d = upu_surface, 0.5
    ang = np.linspace(0, 2 * np.pi, 36, endpoint=False)
    r = np.linspace(0.105, 1.905, 181)  # (no node on the crossing itself)

    def misses(z0, on):
        out = 0
        for a in ang:
            e = np.array([np.cos(a), np.sin(a), 0.0])
            D = _couples(r[:, None] * e + [0, 0, z0], d)
            k = np.flatnonzero(D[:-1] * D[1:] < 0)
            assert len(k) == 1
            cross = 0.5 * (r[k[0]] + r[k[0] + 1]) * e[:2]
            out += int(np.min(np.hypot(*(on - cross).T)) > 0.25 + r[1] - r[0])
        return out

    for z0 in s.sections:
        on = s.vertices[np.isclose(s.vertices[:, 2], z0, atol=1e-12), :2]
        assert misses(z0, on) == 0, z0
    z0 = s.sections[2]
    on = s.vertices[np.isclose(s.vertices[:, 2], z0, atol=1e-12), :2]
    assert misses(z0, on[(on[:, 0] < 0) | (on[:, 1] < 0)]) > 3
