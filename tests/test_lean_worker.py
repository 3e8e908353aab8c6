"""A worker running the common analyses imports no scipy.special, scipy.spatial or
matplotlib (about 0.3-0.4 s each per process), and the small geometric routines written in
their place agree with those libraries (imported here, in the test)."""

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


def test_poisson_upper_rejects_negative_counts():
    with pytest.raises(ValueError, match="k must be >= 0"):
        poisson_upper(-1)


def test_common_analyses_import_no_heavy_scipy_or_matplotlib():
    code = textwrap.dedent("""
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
