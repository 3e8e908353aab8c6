"""3-D generalized aspects (optkin.aspects3d) beside the in-run voxel grid of equal
accuracy: the 240^3 grid of tests/test_aspects3d.py, whose component volumes agree with
the sections' to about 4e-4 on the cuspidal 3-RPR with strokes [10, 30]."""

from __future__ import annotations

import pathlib
import sys

from conftest import median_time, record

_TESTS = pathlib.Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(_TESTS))
from test_continuation import BASE3, PLAT3  # noqa: E402


def _tests_module(name: str):
    """tests/<name>.py under another module name (this file has the same name)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(f"_tests_{name}", _TESTS / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


_T = _tests_module("test_aspects3d")
LIMITS, voxel_aspects = _T.LIMITS, _T.voxel_aspects

import optkin  # noqa: E402


def test_aspects3d_cuspidal_rpr(benchmark):
    m = optkin.mechanisms.rpr3(BASE3, PLAT3)
    res = benchmark.pedantic(lambda: optkin.aspects3d(m, limits=LIMITS), rounds=1,
                             iterations=1)
    t_grid = median_time(lambda: voxel_aspects(240), min_time=0.0, max_rounds=3)
    record(benchmark, t_grid, "240^3 voxel grid of the sign of det A, scipy.ndimage.label",
           mechanism="rpr3-cuspidal", count=len(res), sections=len(res.phis),
           volumes=[a.volume for a in res])
    assert len(res) == 2
