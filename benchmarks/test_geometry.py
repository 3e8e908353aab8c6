"""Geometry as a parameter: a new geometry of a known topology compiles nothing.

In a fresh process with an empty compiled-code cache, 20 random geometries of one
topology (a 6-6 Stewart-Gough platform, a 3-RRR, a Khalil four-bar): the compiled
libraries are built for the first geometry only, and the first ``assembly_modes`` on each
later geometry costs about what a second call on it costs. The in-run baseline of each
figure is that second call: ``extra_info["first_over_second"]`` is the median ratio.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from optkin.model import compiled as cc

_SCRIPT = textwrap.dedent("""
    import json, time, pathlib, os
    import numpy as np
    import optkin
    from optkin import mechanisms as M

    rng = np.random.default_rng(5)
    cache = pathlib.Path(os.environ["OPTKIN_CACHE"])

    def stewart():
        ab = np.sort(rng.uniform(0, 2 * np.pi, 6)); ap = np.sort(rng.uniform(0, 2 * np.pi, 6))
        m = M.stewart_gough(np.c_[np.cos(ab), np.sin(ab), np.zeros(6)],
                            0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)])
        s = optkin.inverse(m, [0.02, -0.01, 0.9, 0.05, -0.03, 0.1])
        return m, s[0].qa

    def rrr3():
        while True:
            base = rng.uniform(0, 1, (3, 2)); plat = rng.uniform(-0.15, 0.15, (3, 2))
            m = M.rrr3(base, plat, 0.6, 0.6)
            s = optkin.inverse(m, [*base.mean(0), 0.1])
            if len(s):
                return m, s[0].qa

    def four_bar():
        L = rng.uniform(1.0, 3.0, 4); L[0] = rng.uniform(0.3, 0.8)  # a short crank
        return M.four_bar(*L), np.array([rng.uniform(0, 2 * np.pi)])

    make = {"stewart_gough": stewart, "rrr3": rrr3, "four_bar": four_bar}[NAME]
    libs, rows = [], []
    for i in range(20):
        m, qa = make()
        t0 = time.perf_counter(); a = optkin.assembly_modes(m, qa)
        t1 = time.perf_counter(); b = optkin.assembly_modes(m, qa)
        t2 = time.perf_counter()
        rows.append((t1 - t0, t2 - t1, len(a), len(b)))
        libs.append(len(list(cache.glob("*.so"))))
    print(json.dumps({"rows": rows, "libs": libs}))
""")


@pytest.mark.skipif(cc.find_compiler() is None, reason="no C compiler")
@pytest.mark.parametrize("name", ["stewart_gough", "rrr3", "four_bar"])
def test_new_geometry_compiles_nothing(benchmark, name, tmp_path):
    env = dict(os.environ, OPTKIN_CACHE=str(tmp_path / "cache"), OPTKIN_COMPILE="auto")
    script = "NAME = " + repr(name) + "\n" + _SCRIPT

    def run():
        out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                             env=env, timeout=600, cwd=Path(__file__).parent)
        assert out.returncode == 0, out.stderr[-2000:]
        return json.loads(out.stdout.strip().splitlines()[-1])

    data = benchmark.pedantic(run, rounds=1, iterations=1)
    rows = data["rows"]
    later = sorted(r[0] / r[1] for r in rows[1:])
    second = sorted(r[1] for r in rows[1:])
    benchmark.extra_info.update(
        mechanism=name,
        first_over_second=later[len(later) // 2],
        worst_first_over_second=later[-1],
        second_call_s=second[len(second) // 2],
        first_geometry_s=rows[0][0],
        libraries_after_first=data["libs"][0],
        libraries_at_end=data["libs"][-1],
        same_modes=all(r[2] == r[3] for r in rows),
    )
