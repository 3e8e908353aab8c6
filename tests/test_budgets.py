"""Memory and time budgets of the analyses (issue 11, B9, B12, B15).

For every size option: under a small budget (``OPTKIN_MEMORY_BUDGET``), a value far too
large is refused before anything is allocated, with a message naming the option and the
largest allowed value; that largest value runs, in a fresh process, with a peak memory
growth (``VmHWM`` after a warm-up, /proc/self/clear_refs) within the budget; the next
value is refused. Then the repro's ``grid = 1000000`` workspace, the time budget, the
assembly_modes that finds no mode (B12) and the raw exceptions of B15.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import optkin
from optkin import MechanismError
from optkin import mechanisms as M

MiB = 1 << 20

FIVE_BAR = "m = M.five_bar(9, 8, 5, 5, 8)"
FIVE_BAR_SMALL = "m = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)"
# the elbows of this five-bar coincide at these actuated values: the platform point may be
# anywhere on a circle, so every start becomes a solution of its own (the worst case)
CONTINUUM = (FIVE_BAR_SMALL + "; y = np.sqrt(1.25); qa = [np.arctan2(y, 1), np.arctan2(y, -1)]")
RPR3 = ("m = M.rpr3(base=[[0, 0], [1, 0], [0.5, 0.9]], "
        "platform=[[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]); qa = [0.6, 0.5, 0.55]")
PATH = ("P = lambda n: np.column_stack([np.linspace(1.2, 1.4, n), np.full(n, 1.9)])")
FB = "m = M.five_bar(1.0, 1.0, 1.0, 1.0, 1.0); Q = lambda n: np.c_[np.linspace(1.2, 1.5, n), np.linspace(1.9, 1.6, n)]"
TRACKED = (FIVE_BAR_SMALL + "; " + PATH + "; R = list(optkin.track(m, P(8), [0.9, 2.3]))"
           " * 4; import tempfile, os; D = tempfile.mkdtemp(); from optkin.plot import draw")


def _largest(message: str, option: str) -> int:
    m = re.search(rf"the largest allowed {re.escape(option)} is (\d+)", message)
    assert m, message
    return int(m.group(1))


def _refused(call, option: str) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(MechanismError, match=rf"option {re.escape(option)} = .* the largest "
                           rf"allowed {re.escape(option)} is \d+") as e:
            call()
    return str(e.value)


def _peak_growth(setup: str, warm: str, call: str, budget: int, tmp_path: Path,
                 **env_extra: str) -> float:
    """Peak resident memory growth (bytes) of ``call`` in a fresh process under ``budget``,
    after ``warm`` (the same functions with small sizes: models and caches are built)."""
    script = textwrap.dedent(f"""
        import json, sys, warnings
        warnings.filterwarnings("ignore")
        import numpy as np, optkin
        from optkin import mechanisms as M

        def status(key):
            for line in open("/proc/self/status"):
                if line.startswith(key):
                    return int(line.split()[1]) * 1024

        {setup}
        {warm}
        import gc
        gc.collect()
        open("/proc/self/clear_refs", "w").write("5")
        before = status("VmRSS")
        {call}
        print(json.dumps({{"growth": status("VmHWM") - before}}))
    """)
    env = dict(os.environ, OPTKIN_MEMORY_BUDGET=str(budget), **env_extra)
    p = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True,
                       timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    return float(json.loads(p.stdout.strip().splitlines()[-1])["growth"])


def _can_reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


needs_vmhwm = pytest.mark.skipif(not _can_reset_peak(),
                                 reason="needs Linux /proc/self/clear_refs to measure peaks")


# (id, budget, setup, warm-up, call with the size as {n}, option name, next value)
CASES = [
    ("assembly_modes-width", 16 * MiB, RPR3,
     "optkin.assembly_modes(m, qa, width=64, starts=64, rescue=0)",
     "r = optkin.assembly_modes(m, qa, width={n}, starts=64, rescue=0, bound=None)",
     "width", lambda n: 2 * n),
    ("assembly_modes-starts", 16 * MiB, CONTINUUM,
     "optkin.assembly_modes(m, qa, starts=64)",
     "r = optkin.assembly_modes(m, qa, starts={n}, bound=None, time_limit=60); r.to_dict()",
     "starts", lambda n: n + 1),
    ("assembly_modes-rescue", 16 * MiB, RPR3,
     "optkin.assembly_modes(m, qa, starts=64)",
     "r = optkin.assembly_modes(m, qa, starts=64, rescue={n}, bound=None)",
     "rescue", lambda n: n + 1),
    ("track-path", 16 * MiB, FIVE_BAR_SMALL + "; " + PATH,
     "optkin.track(m, P(10), [0.9, 2.3])",
     "r = optkin.track(m, P({n}), [0.9, 2.3]); assert r.info['success']; r.to_dict()",
     "len(qa_path)", lambda n: n + 1),
    ("forward_batch-rows", 16 * MiB, FB,
     "optkin.forward_batch(m, Q(300))",
     "b = optkin.forward_batch(m, Q({n})); assert b.all_success; b.to_dict()",
     "len(QA)", lambda n: n + 1),
    ("forward_batch-chunk", 16 * MiB, FB,
     "optkin.forward_batch(m, Q(300))",
     "b = optkin.forward_batch(m, Q(300), chunk={n}); assert b.all_success",
     "chunk", lambda n: n + 1),
    ("singular_curves-grid", 64 * MiB, FIVE_BAR, "optkin.singular_curves(m)",
     "r = optkin.singular_curves(m, grid={n}); assert r.success; r.to_dict()",
     "grid", lambda n: n + 1),
    # the smallest step: every curve runs max_steps each way, until the traced points fill
    # the budget (status memory_limit)
    ("singular_curves-max_steps", 16 * MiB, FIVE_BAR, "optkin.singular_curves(m)",
     "r = optkin.singular_curves(m, max_steps={n}, step=1e-6); r.to_dict()",
     "max_steps", lambda n: n + 1),
    ("aspects-grid", 64 * MiB, FIVE_BAR, "optkin.aspects(m, qa_grid=2)",
     "r = optkin.aspects(m, grid={n}, qa_grid=2); assert r.success; r.to_dict()",
     "grid", lambda n: n + 1),
    ("aspects-qa_grid", 64 * MiB, FIVE_BAR, "optkin.aspects(m)",
     "r = optkin.aspects(m, qa_grid={n}); assert r.success; r.to_dict()",
     "qa_grid", lambda n: n + 1),
    ("workspace-grid", 64 * MiB, FIVE_BAR, "optkin.workspace(m, qa_grid=2)",
     "r = optkin.workspace(m, grid={n}, qa_grid=2); assert r.success; r.to_dict()",
     "grid", lambda n: n + 1),
    ("draw-panels", 32 * MiB, TRACKED, "draw(m, R[:2], os.path.join(D, 'a.png'))",
     "draw(m, R[:{n}], os.path.join(D, 'b.png'))",
     "len(results)", lambda n: n + 1),
]
#: Far too large for any budget of these tests.
HUGE = {"width": 1 << 40, "starts": 10**9, "rescue": 10**9, "len(qa_path)": 10**6,
        "len(QA)": 10**6, "chunk": 10**6, "grid": 10**6, "max_steps": 10**9, "qa_grid": 10**5,
        "len(results)": 32}


def _run(setup: str, call: str, n: int) -> None:
    g = {"optkin": optkin, "M": M, "np": np}
    exec(setup, g)
    exec(call.format(n=n), g)


@needs_vmhwm
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_largest_accepted_size_runs_within_the_budget_and_the_next_is_refused(
        case, monkeypatch, tmp_path):
    name, budget, setup, warm, call, option, nxt = case
    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", str(budget))
    # far too large: refused before allocation, naming the option and the largest value
    t0 = time.perf_counter()
    msg = _refused(lambda: _run(setup, call, HUGE[option]), option)
    assert time.perf_counter() - t0 < 30
    n = _largest(msg, option)
    assert n >= 2
    # the next value is refused, with the same largest value
    assert _largest(_refused(lambda: _run(setup, call, nxt(n)), option), option) == n
    # the largest runs within the budget (peak growth of a fresh process)
    # (a new chunk size would compile a library of its own: interpreted here)
    extra = {"OPTKIN_COMPILE": "off"} if option == "chunk" else {}
    growth = _peak_growth(setup, warm, call.format(n=n), budget, tmp_path, **extra)
    assert growth <= budget, f"{name}: {option} = {n} grew {growth / MiB:.1f} MiB"


def test_plot_singularity_map_grid_is_bounded(monkeypatch, tmp_path):
    """len(u) * len(v) grid points against the budget (the sampling costs milliseconds a
    point, so the largest grid is kept small by a budget just above the figure's own)."""
    from optkin.analysis import maps
    from optkin.limits import SAFETY

    budget = int(maps._COST_FIGURE + SAFETY * maps._COST_MAP_POINT * 400) + 1
    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", str(budget))
    m = M.five_bar(1, 1, 1, 1, 1)
    path = str(tmp_path / "m.png")
    with pytest.raises(MechanismError, match=r"singularity_map: option len\(u\) \* len\(v\) = "
                       r"1000000 .* the largest allowed len\(u\) \* len\(v\) is (\d+)") as e:
        optkin.plot_singularity_map(m, np.linspace(-0.5, 1.5, 1000), np.linspace(0.2, 1.8, 1000),
                                    path)
    n = _largest(str(e.value), "len(u) * len(v)")
    assert n == 400
    with pytest.raises(MechanismError, match=r"the largest allowed len\(u\) \* len\(v\) is 400"):
        optkin.plot_singularity_map(m, np.linspace(-0.5, 1.5, 2), np.linspace(0.2, 1.8, 201), path)
    if _can_reset_peak():
        growth = _peak_growth(
            "m = M.five_bar(1, 1, 1, 1, 1)",
            f"optkin.plot_singularity_map(m, [0.0, 1.0], [0.5, 1.0], {str(tmp_path / 'w.png')!r})",
            f"sm = optkin.plot_singularity_map(m, np.linspace(-0.5, 1.5, 20), "
            f"np.linspace(0.2, 1.8, 20), {path!r}); assert sm.success",
            budget, tmp_path)
        assert growth <= budget


def test_repro_workspace_grid_million_is_refused_at_once():
    """B9: grid = 1000000 (repro grid_unbounded.toml) ran past 100 s; now a MechanismError
    naming grid and its largest allowed value, before any seeding."""
    m = M.five_bar(9.0, 8.0, 5.0, 5.0, 8.0)
    optkin.workspace(m, qa_grid=2)  # the model and its Functions
    t0 = time.perf_counter()
    with pytest.raises(MechanismError, match=r"^workspace: option grid = 1000000 needs about "
                       r".* above the memory budget .* the largest allowed grid is \d+$"):
        optkin.workspace(m, grid=1000000)
    assert time.perf_counter() - t0 < 1.0
    for call, option in [(lambda: optkin.aspects(m, grid=10**4), "grid"),
                         (lambda: optkin.singular_curves(m, grid=5000), "grid"),
                         (lambda: optkin.assembly_modes(m, [1.0, 2.0], width=2**26), "width")]:
        t0 = time.perf_counter()
        _refused(call, option)
        assert time.perf_counter() - t0 < 1.0


def test_budget_from_the_environment(monkeypatch):
    from optkin import limits

    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", "64MiB")
    assert limits.memory_budget() == 64 * MiB
    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", "2G")
    assert limits.memory_budget() == 2 * 10**9
    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", "lots")
    with pytest.raises(MechanismError, match="OPTKIN_MEMORY_BUDGET: expected a number of bytes"):
        limits.memory_budget()
    monkeypatch.delenv("OPTKIN_MEMORY_BUDGET")
    monkeypatch.setattr(limits, "MEMORY_BUDGET", 32 * MiB)
    assert limits.memory_budget() == 32 * MiB
    with pytest.raises(MechanismError, match=r"largest allowed grid is \d+"):
        optkin.singular_curves(M.five_bar(9, 8, 5, 5, 8), grid=1000)


def test_limits_doctest(monkeypatch):
    import doctest

    from optkin import limits

    monkeypatch.delenv("OPTKIN_MEMORY_BUDGET", raising=False)
    failures, tried = doctest.testmod(limits, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


# ------------------------------------------------------------------------------ time


def test_assembly_modes_time_limit_is_within_the_time_budget(monkeypatch):
    m = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    monkeypatch.setenv("OPTKIN_TIME_BUDGET", "5")
    for tl in (float("inf"), 6.0, 1e9):
        with pytest.raises(MechanismError, match=r"assembly_modes: option time_limit = .* exceeds "
                           r"the time budget of 5 s \(OPTKIN_TIME_BUDGET\)"):
            optkin.assembly_modes(m, [1.2, 1.9], time_limit=tl)


def test_the_time_budget_stops_long_calls(monkeypatch):
    """Calls without a time limit of their own stop at the time budget with success False."""
    monkeypatch.setenv("OPTKIN_TIME_BUDGET", "0.3")
    m = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    P = np.column_stack([np.linspace(1.2, 1.4, 5000), np.full(5000, 1.9)])
    t0 = time.perf_counter()
    r = optkin.track(m, P, [0.9, 2.3])
    assert time.perf_counter() - t0 < 3
    assert r.info["status"] == "time_limit" and r.to_dict()["success"] is False
    assert "time budget of 0.3 s" in r.info["message"]
    fb = M.five_bar(1.0, 1.0, 1.0, 1.0, 1.0)
    optkin.forward_batch(fb, np.c_[np.linspace(1.2, 1.5, 20), np.linspace(1.9, 1.6, 20)])
    Q = np.tile([np.pi, 0.0], (20000, 1))  # |C D| = 3 > 2: every row falls back to forward
    t0 = time.perf_counter()
    b = optkin.forward_batch(fb, Q)
    assert time.perf_counter() - t0 < 5
    assert b.status == "time_limit" and "time budget" in b.message
    assert b.stats.extra["stopped_at"] < 20000
    five = M.five_bar(9, 8, 5, 5, 8)
    optkin.singular_curves(five)
    t0 = time.perf_counter()
    r = optkin.singular_curves(five, step=1e-6, max_steps=10**5)
    assert time.perf_counter() - t0 < 5
    assert not r.success and r.status == "time_limit"
    a = optkin.aspects(five, step=1e-6)
    assert not a.success and a.status == "time_limit" and len(a) == 0
    t0 = time.perf_counter()
    sm = optkin.analysis.singularity_map(fb, np.linspace(-0.5, 1.5, 100),
                                         np.linspace(0.2, 1.8, 100))
    assert time.perf_counter() - t0 < 5
    assert not sm.success and sm.status == "time_limit"


def test_traced_points_stop_at_the_memory_budget(monkeypatch):
    monkeypatch.setenv("OPTKIN_MEMORY_BUDGET", "8MiB")
    r = optkin.singular_curves(M.five_bar(9, 8, 5, 5, 8), step=1e-4)
    assert not r.success and r.status == "memory_limit"
    assert "the most the memory budget allows" in r.message


# ------------------------------------------------------------------------------ B12, B15


def test_assembly_modes_without_a_mode_is_not_a_success():
    """B12 (repro assembly_modes_none_ok.toml): 0 modes must not look successful."""
    r = optkin.assembly_modes(M.five_bar(9.0, 8.0, 5.0, 5.0, 8.0), [3.14159, 0.0])
    d = r.to_dict()
    assert len(r) == 0 and d["success"] is False and d["status"] == "infeasible"
    assert d["message"].startswith("no closed configuration exists for these actuated values")
    # the same when the starts ran and none converged (a non-Grashof four-bar out of reach)
    r = optkin.assembly_modes(M.four_bar(2, 1, 1, 1.5), [3.0])
    d = r.to_dict()
    assert len(r) == 0 and d["success"] is False and d["status"] == "infeasible"
    assert "no closed configuration exists for these actuated values" in d["message"]
    assert r.info["starts"] > 0
    # found modes: success at the top level too
    d = optkin.assembly_modes(M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5), [1.2, 1.9]).to_dict()
    assert d["success"] is True and d["status"] == "optimal" and d["count"] == 2


def test_raw_exceptions_of_b15_are_mechanism_errors():
    """B15 cases of repro api_raw_exceptions.py in these modules."""
    with pytest.raises(MechanismError):
        optkin.workspace(M.five_bar(*[1e300] * 5))
    with pytest.raises(MechanismError, match=r"assembly_modes: option bound must be 'auto', "
                       r"None or an integer >= 0"):
        optkin.assembly_modes(M.four_bar(1, 2, 2, 2.5), [1.0], bound="x")


def test_huge_mechanisms_and_arguments_name_the_culprit():
    big = optkin.Mechanism.from_legs(
        [{"type": "RRR", "base": [0, 0], "platform": [0, 0], "lengths": [1e149, 1e149]},
         {"type": "RRR", "base": [1e149, 0], "platform": [0, 0], "lengths": [1e149, 1e149]}],
        "planar_point")
    try:
        r = optkin.workspace(big)
    except MechanismError:
        pass
    else:
        assert isinstance(r.success, bool)
    m = M.five_bar(9, 8, 5, 5, 8)
    for kw, match in [({"grid": 10**400}, "grid"), ({"max_steps": 2**70}, "max_steps"),
                      ({"bounds": [[0, 1e300], [0, 1]]}, "bounds"),
                      ({"fixed": {"x": 10**400}}, "fixed"), ({"plane": ("x", 10**5000)}, "plane"),
                      ({"kind": 5}, "kind"), ({"limits": "wide"}, "limits")]:
        with pytest.raises(MechanismError, match=match):
            optkin.singular_curves(m, **kw)
    for kw, match in [({"width": 10**5000}, "width"), ({"starts": float("nan")}, "starts"),
                      ({"seed": 10**400}, "seed"), ({"max_iter": 10**400}, "max_iter"),
                      ({"jit": "sometimes"}, "jit"), ({"threads": 10**6}, "threads")]:
        with pytest.raises(MechanismError, match=match):
            optkin.assembly_modes(m, [1.0, 2.0], **kw)
    with pytest.raises(MechanismError, match="qa"):
        optkin.assembly_modes(m, [10**400, 1.0])
    with pytest.raises(MechanismError, match="qa_path"):
        optkin.track(m, [[1.0, 10**400]])
    with pytest.raises(MechanismError, match="QA"):
        optkin.forward_batch(m, [[1.0, 10**400]])
    with pytest.raises(MechanismError, match="iters"):
        optkin.forward_batch(m, [[1.0, 2.0]], iters=10**6)


def test_validation_stops_at_the_checkpoint_after_the_size_checks():
    """Problem-file validation runs the same checks: a size beyond the budget is refused,
    valid arguments reach the checkpoint without doing the work."""
    from optkin._dryrun import Checked, validating

    five = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    cw = M.five_bar(9, 8, 5, 5, 8)
    P = np.column_stack([np.linspace(1.2, 1.4, 5), np.full(5, 1.9)])
    with validating():
        with pytest.raises(MechanismError, match=r"option grid = 1000000 .* largest allowed grid"):
            optkin.workspace(cw, grid=10**6)
        with pytest.raises(MechanismError, match=r"^guess: expected the unknowns x"):
            optkin.track(five, P, [1, 2, 3, 4, 5])
        for call in (lambda: optkin.assembly_modes(five, [1.2, 1.9]),
                     lambda: optkin.track(five, P, [0.9, 2.3]),
                     lambda: optkin.forward_batch(five, P),
                     lambda: optkin.working_modes(five),
                     lambda: optkin.singular_curves(cw),
                     lambda: optkin.aspects(cw),
                     lambda: optkin.workspace(cw)):
            with pytest.raises(Checked):
                call()


def test_the_largest_accepted_inverse_and_statics_grids_stop_at_the_time_budget(monkeypatch):
    """inverse with the largest accepted number of starts (a Khalil multi-start took 27 min)
    and a wrench-feasibility grid of the largest accepted size (10^6 poses) stop at the time
    budget with success False, their result saying so."""
    from optkin import statics
    from optkin.solvers.inverse import MAX_STARTS
    from optkin.statics.core import MAX_GRID

    sr = M.sr400()
    q = optkin.forward(sr, [0.3, -0.4, 0.2, 0.5, 0.4, 0.6], guess=[np.pi / 2 + 1, -1, np.pi + 1])
    monkeypatch.setenv("OPTKIN_TIME_BUDGET", "1")
    t0 = time.perf_counter()
    r = optkin.inverse(sr, q.pose, starts=MAX_STARTS)
    assert time.perf_counter() - t0 < 15
    assert r.info["success"] is False and r.info["status"] == "time_limit"
    assert "time budget of 1 s" in r.info["message"]
    m = M.rpr3(base=[[0, 0], [4, 0], [0, 3]], platform=[[-0.5, -0.3], [0.5, -0.3], [0, 0.4]])
    t0 = time.perf_counter()
    w = statics.wrench_feasible_workspace(m, [0.0, -1.0, 0.0], 10.0, grid=MAX_GRID,
                                          fixed=[0.0, 0.0, 0.2])
    assert time.perf_counter() - t0 < 15
    assert not w.success and w.status == "time_limit"
    assert "not computed" in w.message and w.point_status.count("not computed") > 0
