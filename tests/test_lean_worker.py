"""A worker running the common analyses imports no scipy.special, scipy.spatial or
matplotlib (about 0.3-0.4 s each per process), and the small geometric routines written in
their place (point in polygon, close pairs, the rotation conversions of spatial poses)
agree with those libraries (imported here, in the test)."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest
from matplotlib.path import Path
from scipy.spatial import cKDTree

from optkin.analysis.planar import close_pairs, points_in_ring
from optkin.solvers.enumerate import poisson_upper


def test_points_in_ring_agrees_with_matplotlib():
    rng = np.random.default_rng(7)
    for t in range(40):
        m = int(rng.integers(3, 80))
        if t % 2:  # star-shaped simple ring
            ang = np.sort(rng.uniform(0, 2 * np.pi, m))
            R = rng.uniform(0.3, 1, m)[:, None] * np.c_[np.cos(ang), np.sin(ang)]
        else:  # self-intersecting ring
            R = rng.uniform(-1, 1, (m, 2))
        if t % 4 == 1:  # first vertex repeated at the end
            R = np.vstack([R, R[:1]])
        P = rng.uniform(-1.2, 1.2, (4000, 2))
        expect = Path(R).contains_points(P)
        got = points_in_ring(R, P)
        assert np.array_equal(got, expect), (t, int((got != expect).sum()))
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    assert points_in_ring(sq, [0.5, 0.5])[0] and not points_in_ring(sq, [1.5, 0.5])[0]


def test_points_in_ring_on_grids_and_long_rings_agrees_with_matplotlib():
    """Points sharing the y of vertices and horizontal edges (a quarter grid on a ring
    with vertices on it; some points lie on the ring, where the rule may go either way,
    so the reference is the n x m crossing count, written here), and a ring long enough that the (edge, point) pairs are
    processed in several runs (more than ``_CHUNK``), and no points at all."""
    from optkin.analysis import planar

    rng = np.random.default_rng(11)
    X, Y = np.meshgrid(np.arange(-5, 6) / 4, np.arange(-5, 6) / 4)
    G = np.c_[X.ravel(), Y.ravel()] + [0.01, 0.0]  # off the vertical edges, on the rows
    R = np.round(rng.uniform(-1, 1, (30, 2)) * 4) / 4
    A, B = R[None], np.roll(R, -1, axis=0)[None]
    px, py = G[:, :1], G[:, 1:]
    with np.errstate(divide="ignore", invalid="ignore"):
        x = A[..., 0] + (py - A[..., 1]) * (B[..., 0] - A[..., 0]) / (B[..., 1] - A[..., 1])
    cross = ((A[..., 1] > py) != (B[..., 1] > py)) & (px < x)
    expect = cross.sum(axis=1) % 2 == 1
    assert 10 < expect.sum() < len(G) - 10
    assert np.array_equal(points_in_ring(R, G), expect)
    th = np.linspace(0, 2 * np.pi, 3000, endpoint=False)
    R = np.c_[np.cos(th) * (1 + 0.3 * np.cos(7 * th)), np.sin(th)]
    P = rng.uniform([-1.4, -0.99], [1.4, 0.99], (100_000, 2))
    assert len(P) * 2 > 1.5 * planar._CHUNK  # each point's line meets the ring twice or more
    got = points_in_ring(R, P)
    assert np.array_equal(got, Path(R).contains_points(P))
    assert 0.3 < got.mean() < 0.6
    assert points_in_ring(R, np.zeros((0, 2))).shape == (0,)


@pytest.mark.parametrize("tol", [1e-9, 5e-3])
def test_close_pairs_agrees_with_a_kd_tree(tol):
    rng = np.random.default_rng(3)
    X = rng.uniform(0, 1, (3000, 2)) * (1e6 * tol)
    X = np.r_[X, X[:500] + rng.normal(0, 0.6 * tol, (500, 2)), X[:50] + [tol * 0.999, 0]]
    cell = np.round(X / tol)
    _, first = np.unique(cell, axis=0, return_index=True)
    X, cell = X[first], cell[first]
    got = {tuple(p) for p in close_pairs(X, cell, tol)}
    expect = {tuple(sorted(p)) for p in cKDTree(X).query_pairs(tol)}
    assert len(expect) > 50
    assert got == expect


def test_matrix_to_rpy_agrees_with_scipy():
    """The closed form of matrix_to_rpy against scipy's Rotation (intrinsic ZYX), random
    rotations and gimbal lock (pitch +-pi/2, where both set roll = 0) included."""
    import warnings

    from scipy.spatial.transform import Rotation

    from optkin.mechanism.geometry import matrix_to_rpy

    def scipy_rpy(R):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            yaw, pitch, roll = Rotation.from_matrix(R).as_euler("ZYX")
        return np.array([roll, pitch, yaw])

    def gap(a, b):  # angles equal modulo 2 pi (+pi and -pi are one angle)
        return float(np.abs((a - b + np.pi) % (2 * np.pi) - np.pi).max())

    rng = np.random.default_rng(5)
    mats = list(Rotation.random(500, random_state=5).as_matrix())
    for pitch in (np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-9, -np.pi / 2 + 1e-9):
        for yaw, roll in rng.uniform(-np.pi, np.pi, (50, 2)):
            mats.append(Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix())
    mats += [np.eye(3), np.diag([-1.0, -1.0, 1.0]), np.diag([1.0, -1.0, -1.0])]
    locked = 0
    for R in mats:
        got, want = matrix_to_rpy(R), scipy_rpy(R)
        assert gap(got, want) < 1e-9, (R, got, want)
        lock = abs(abs(want[1]) - np.pi / 2) < 1e-7
        locked += lock
        # and the angles rebuild the matrix, R = Rz(yaw) Ry(pitch) Rx(roll) (within the
        # lock band, where roll is set to 0, to the band's width)
        back = Rotation.from_euler("ZYX", got[::-1]).as_matrix()
        assert np.abs(back - R).max() < (1e-6 if lock else 1e-12)
    assert locked >= 200  # the gimbal-lock branch was taken


def test_rotation_closed_forms_agree_with_scipy():
    """rpy_to_matrix, rot_x/y/z and the quaternion conversions against scipy's Rotation:
    random rotations, half turns (w = 0, each of Shepperd's four branches) and the identity."""
    from scipy.spatial.transform import Rotation

    from optkin.mechanism import geometry as g

    rng = np.random.default_rng(11)
    for roll, pitch, yaw in rng.uniform(-4, 4, (300, 3)):
        want = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()
        assert np.abs(g.rpy_to_matrix(roll, pitch, yaw) - want).max() < 1e-14
        for f, ax in ((g.rot_x, "x"), (g.rot_y, "y"), (g.rot_z, "z")):
            assert np.abs(f(roll) - Rotation.from_euler(ax, roll).as_matrix()).max() < 1e-14
    rots = list(Rotation.random(500, random_state=11))
    rots += [Rotation.from_rotvec(np.pi * np.asarray(a, float) / np.linalg.norm(a))
             for a in ([1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [0, 1, 1], [1, -2, 3])]
    rots += [Rotation.identity()]
    for r in rots:
        x, y, z, w = r.as_quat()
        q_scipy = np.array([w, x, y, z])
        R = r.as_matrix()
        q = g.matrix_to_quat(R)
        assert q[0] >= 0 and abs(np.linalg.norm(q) - 1) < 1e-14
        # a rotation's two quaternions: the one with w >= 0 (either, at w = 0)
        assert min(np.abs(q - q_scipy).max(), np.abs(q + q_scipy).max()) < 1e-12
        assert np.abs(g.quat_to_matrix(3.0 * q_scipy) - R).max() < 1e-14  # normalised
    with pytest.raises(ValueError, match="non-zero finite quaternion"):
        g.quat_to_matrix([0.0, 0.0, 0.0, 0.0])


def test_poisson_upper_rejects_negative_counts():
    with pytest.raises(ValueError, match="k must be >= 0"):
        poisson_upper(-1)


def test_common_analyses_import_no_heavy_scipy_or_matplotlib():
    code = textwrap.dedent("""
        import math
        import sys
        from optkin.problems import runner
        probs = {
            "rpr": '[mechanism]\\ntype = "library"\\nname = "rpr3"\\n'
                   '[mechanism.args]\\nbase = [[0, 0], [1, 0], [0, 1]]\\n'
                   'platform = [[0, 0], [0.3, 0], [0, 0.3]]\\n'
                   '[[task]]\\nkind = "assembly_modes"\\nqa = [0.424264069, 0.5, 0.5]\\n',
            "fb": '[mechanism]\\ntype = "library"\\nname = "five_bar"\\n'
                  'args = { L0 = 8.0, L1 = 7.0, L2 = 5.0, L3 = 5.0, L4 = 7.0 }\\n'
                  '[[task]]\\nkind = "aspects"\\n',
        }
        # a spatial platform (its poses are reported in roll-pitch-yaw angles): hexagons
        # turned by 30 degrees, every leg sqrt(1.25 - cos 30 deg + 1) long at z = 1
        ang = [k * 1.0471975511965976 for k in range(6)]
        base = [[math.cos(t), math.sin(t), 0.0] for t in ang]
        plat = [[0.5 * math.cos(t + 0.5235987755982988),
                 0.5 * math.sin(t + 0.5235987755982988), 0.0] for t in ang]
        leg = math.sqrt(2.25 - math.cos(0.5235987755982988))
        probs["sg"] = ('[mechanism]\\ntype = "library"\\nname = "stewart_gough"\\n'
                       f'[mechanism.args]\\nbase = {base}\\nplatform = {plat}\\n'
                       f'[[task]]\\nkind = "forward"\\nqa = {[leg] * 6}\\n'
                       'guess = [0.0, 0.0, 0.9, 0.0, 0.0, 0.0]\\n')
        for name, body in probs.items():
            text = f'schema_version = 1\\nname = "{name}"\\n' + body
            out = runner.run_job(name + ".toml", text.encode(), name + ".toml",
                                 pictures=False)
            task = out["result"]["tasks"][0]
            assert task["output"]["success"], task
        heavy = [m for m in ("scipy.special", "scipy.spatial", "scipy.stats",
                             "matplotlib", "cvxpy") if m in sys.modules]
        print(",".join(heavy) or "none")
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == "none"


def test_subpackages_are_attributes_of_a_fresh_import():
    """``import optkin`` then ``optkin.solvers``, ``optkin.mechanism`` and the other
    subpackages as attributes (as scipy's), loaded on first use: a bare import still loads
    no CasADi."""
    code = ("import sys, optkin\n"
            "assert 'casadi' not in sys.modules\n"
            "from optkin.mechanism.geometry import rpy_to_matrix\n"
            "assert optkin.mechanism.geometry.rpy_to_matrix is rpy_to_matrix\n"
            "for n in ('analysis', 'design', 'mechanism', 'model', 'problems', 'solvers'):\n"
            "    assert getattr(optkin, n).__name__ == 'optkin.' + n\n"
            "assert callable(optkin.solvers.forward)\n"
            "print('ok')\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
