"""Fuzz of the analyses (hypothesis): assembly_modes, track, forward_batch, working_modes,
singular_curves, aspects, workspace and plot_singularity_map.

Whatever the arguments and options (huge ints, 10**5000, NaN, inf, 1e308, strings, None,
negative and huge sizes, wrong shapes, unknown options), a call either raises
:class:`MechanismError` or returns a result whose ``success`` is a bool, within a time
bound (hypothesis ``deadline`` per example). The calls run under a small memory budget
(``OPTKIN_MEMORY_BUDGET``) and time budget (``OPTKIN_TIME_BUDGET``), so that the largest
accepted sizes stay quick, and without compiling C code (``OPTKIN_COMPILE=off``: every
``chunk`` would compile a library of its own). The default run is short; the ``slow``
variants run many more examples (``pytest -m slow tests/test_fuzz_analyses.py``).
"""

from __future__ import annotations

import faulthandler
import math
import os
import tempfile
import time
import warnings
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import optkin
from optkin import MechanismError, limits
from optkin import mechanisms as M
from optkin.analysis.aspects import ASPECTS_DEFAULTS
from optkin.analysis.continuation import SINGULAR_CURVES_DEFAULTS
from optkin.solvers.batch import BATCH_DEFAULTS
from optkin.solvers.enumerate import ASSEMBLY_DEFAULTS, TRACK_DEFAULTS

#: Budgets of the fuzzed calls (the largest accepted sizes must stay quick).
ENV = {"OPTKIN_MEMORY_BUDGET": "96MiB", "OPTKIN_TIME_BUDGET": "2", "OPTKIN_COMPILE": "off"}
#: Longest a single call may take (s): the time budget, plus what it does not cover (one
#: native call, building a model, drawing a picture).
CALL_BUDGET = 12.0
FAST = settings(max_examples=30, deadline=timedelta(seconds=15), derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])
SLOW = settings(FAST, max_examples=300, derandomize=False)


@pytest.fixture(autouse=True)
def budgets(monkeypatch):
    for k, v in ENV.items():
        monkeypatch.setenv(k, v)


@pytest.fixture(autouse=True, scope="module")
def watchdog():
    """A native call that never returns ends the run with a traceback instead of a hang."""
    faulthandler.dump_traceback_later(1800, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def check(call):
    """Only MechanismError, or a result with a bool ``success``, within CALL_BUDGET."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            out = call()
        except MechanismError:
            out = None
    assert time.perf_counter() - t0 < CALL_BUDGET
    if out is None:
        return None
    if isinstance(out, optkin.SolutionSet):
        d = out.to_dict()
        assert type(out.info.get("success")) is bool
        assert d.get("success") is out.info["success"]
        for r in out:
            assert type(r.success) is bool
    elif isinstance(out, optkin.WorkingModes):
        out.to_dict()
    elif isinstance(out, optkin.BatchResult):
        assert out.closed.dtype == bool and type(out.success) is bool
        assert out.status in optkin.results.STATUS
        out.to_dict()
    else:
        assert type(out.success) is bool, type(out)
        if hasattr(out, "to_dict"):
            out.to_dict()
    return out


# ----------------------------------------------------------------------------- strategies
HUGE = [10**400, -(10**400), 2**64, 2**63, 1e308, -1e308, 1e151, 1e150, 5e-324, 0, -1,
        float("nan"), float("inf"), -float("inf"), True, None, "x", "", "auto", b"1", 1j,
        [], {}, [1, 2], np.nan, np.int64(2**62)]
#: an int beyond 4300 digits (str() of it raises ValueError), built when drawn
beyond_str = st.just(5000).map(lambda k: 10**k)

scalar = st.one_of(st.floats(-5, 5), st.floats(allow_nan=True, allow_infinity=True),
                   st.integers(-10, 10), st.sampled_from(HUGE), beyond_str)
size = st.one_of(st.integers(-3, 70), st.integers(-(2**70), 2**70),
                 st.sampled_from([2**20, 2**26, 10**6, 10**9, 10**400, 2.0, 4.5, float("nan"),
                                  float("inf"), "8", None, -1]),
                 beyond_str)
junk = st.one_of(scalar, st.text(max_size=5), st.lists(scalar, max_size=4),
                 st.lists(st.lists(scalar, max_size=3), max_size=3),
                 st.builds(lambda n: np.full(n, np.nan), st.integers(0, 3)))


FIVE = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
CW = M.five_bar(9, 8, 5, 5, 8)
RPR3 = M.rpr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
FOUR = M.four_bar(1.0, 2.0, 2.0, 2.5)
MECHS = {"five": (FIVE, [1.2, 1.9]), "cw": (CW, [1.0, 2.0]), "rpr3": (RPR3, [0.6, 0.5, 0.55]),
         "four": (FOUR, [1.0])}
bad_mech = st.sampled_from(["five_bar", None, 3, FIVE.legs])
bad = st.one_of(junk, size, bad_mech)


@st.composite
def call_args(draw, args: dict, opts: dict, n_opts: int = 4, unknown: bool = True):
    """Valid arguments and a few valid options, then, one time in two, one of them (or an
    unknown option, for functions taking ``**options``; elsewhere Python's TypeError is the
    answer) replaced by junk or a size: most calls get far enough to do work."""
    out = {k: draw(v) for k, v in args.items()}
    keys = draw(st.lists(st.sampled_from(sorted(opts)), max_size=n_opts, unique=True)
                ) if opts else []
    o = {k: draw(opts[k]) for k in keys}
    target = draw(st.sampled_from([None, None, None] + sorted(args) + sorted(opts)
                                  + (["bogus"] if unknown else [])))
    if target in args:
        out[target] = draw(bad)
    elif target is not None:
        o[target] = draw(bad)
    return out, o


pos = st.floats(1e-12, 1e-6)
ASSEMBLY_OPTS = {
    "seed": st.integers(0, 5), "tol": pos, "starts": st.integers(1, 3000),
    "min_starts": st.one_of(st.just("auto"), st.integers(0, 500)),
    "target": st.floats(0, 1), "target_upper": st.floats(0, 1), "time_limit": st.floats(0, 1),
    "bound": st.one_of(st.none(), st.just("auto"), st.integers(0, 10)),
    "width": st.sampled_from([1, 2, 8, 64, 256, 4096, "auto"]),
    "max_iter": st.integers(1, 100), "step_max": st.one_of(st.just("auto"), st.floats(0.01, 2)),
    "dedup_tol": st.floats(0, 1e-3), "rescue": st.integers(0, 20),
    "jit": st.sampled_from([True, False, "auto", "cached"]), "threads": st.integers(1, 8),
    "certify": st.booleans(), "continua": st.booleans(), "method": st.just("multistart"),
}
TRACK_OPTS = {
    "tol": pos, "max_iter": st.integers(1, 20), "min_step": st.floats(1e-6, 0.5),
    "cond_max": st.floats(10, 1e12), "cond_near": st.floats(10, 1e6),
    "max_correction": st.floats(0.01, 1), "contraction": st.floats(0.1, 1),
}
BATCH_OPTS = {
    "path": st.booleans(), "tol": pos, "chunk": st.integers(1, 512), "iters": st.integers(0, 4),
    "max_iter": st.integers(0, 50), "threads": st.integers(1, 4), "fallback": st.booleans(),
    "guard": st.booleans(), "jump": st.floats(0.5, 5), "near": st.floats(0, 0.1),
}
assert set(ASSEMBLY_OPTS) == set(ASSEMBLY_DEFAULTS) and set(TRACK_OPTS) == set(TRACK_DEFAULTS)
assert set(BATCH_OPTS) == set(BATCH_DEFAULTS)


def near(values, spread=0.3):
    base = np.asarray(values, dtype=float)
    return st.lists(st.floats(-spread, spread), min_size=base.size, max_size=base.size).map(
        lambda d: (base.ravel() + np.array(d)).reshape(base.shape))


def path_of(qa, transpose=False):
    qa = np.asarray(qa, dtype=float)
    good = st.tuples(st.integers(1, 30), st.floats(-1, 1)).map(
        lambda t: qa + np.linspace(0, t[1], t[0])[:, None])
    return st.one_of(good, good.map(lambda P: P.T) if transpose else good,
                     st.just(np.zeros((0, qa.size))))


mech_key = st.sampled_from(sorted(MECHS))


# ----------------------------------------------------------------------------- the fuzz
@st.composite
def assembly_case(draw):
    mech, qa = MECHS[draw(mech_key)]
    args, opts = draw(call_args({"mech": st.just(mech), "qa": near(qa)},
                                ASSEMBLY_OPTS))
    # the defaults would run up to the time budget, and 20000 starts (each of which may
    # become a solution) need more than the fuzz's memory budget
    opts.setdefault("time_limit", 0.5)
    opts.setdefault("starts", 2000)
    return args, opts


def _assembly(case):
    args, opts = case
    check(lambda: optkin.assembly_modes(args["mech"], args["qa"], **opts))


@st.composite
def track_case(draw):
    mech, qa = MECHS[draw(mech_key)]
    return draw(call_args({"mech": st.just(mech), "path": path_of(qa),
                           "guess": st.just(None)}, TRACK_OPTS))


def _track(case):
    args, opts = case
    check(lambda: optkin.track(args["mech"], args["path"], args["guess"], **opts))


@st.composite
def batch_case(draw):
    mech, qa = MECHS[draw(mech_key)]
    return draw(call_args({"mech": st.just(mech), "QA": path_of(qa, transpose=True),
                           "guess": st.just(None)}, BATCH_OPTS))


def _batch(case):
    args, opts = case
    check(lambda: optkin.forward_batch(args["mech"], args["QA"], args["guess"], **opts))


@st.composite
def working_case(draw):
    mech = draw(st.sampled_from([FIVE, RPR3, FOUR]))
    pose = st.one_of(st.none(), near([1.0, 1.8]), near([0.45, 0.35, 0.1], 0.1))
    return draw(call_args({"mech": st.just(mech), "pose": pose}, {}))


def _working(case):
    args, _ = case
    check(lambda: optkin.working_modes(args["mech"], pose=args["pose"]))


#: per mechanism, what a sensible call looks like
VALID = {
    "cw": dict(plane=st.sampled_from(["joint", "workspace", ("x", "L2.theta1")]),
               kind=st.sampled_from(["parallel", "serial", "all", ["parallel", "serial"]]),
               fixed=st.none(), bounds=near([[-5.0, 15.0], [-5.0, 15.0]], 1.0),
               limits=st.just({"L1.theta1": (0.0, 2.0)})),
    "rpr3": dict(plane=st.just("workspace"), kind=st.just("parallel"),
                 fixed=st.floats(-3, 3).map(lambda p: {"phi": p}),
                 bounds=near([[-1.0, 2.0], [-1.0, 2.0]], 0.3),
                 limits=st.just({"L1.rho": (0.2, 1.0)})),
    "four": dict(plane=st.just(("theta", "phi")), kind=st.just("closure"), fixed=st.none(),
                 bounds=near([[-3.0, 3.0], [-3.0, 3.0]], 0.1),
                 limits=st.just({"theta": (0.0, 1.0)})),
}


def curve_args(name, region):
    v = VALID[name]
    args = {"mech": st.just(MECHS[name][0]), "fixed": v["fixed"]}
    opts = {"bounds": v["bounds"], "limits": v["limits"], "grid": st.integers(2, 80),
            "step": st.floats(0.02, 0.3)}
    if region:
        opts["qa_grid"] = st.integers(2, 80)
    else:
        args.update(plane=v["plane"], kind=v["kind"])
        opts.update(tol=st.floats(1e-12, 1e-8), max_steps=st.integers(1, 5000),
                    cusps=st.sampled_from([None, True, False]))
    assert set(opts) == set(ASPECTS_DEFAULTS if region else SINGULAR_CURVES_DEFAULTS)
    return call_args(args, opts)


@st.composite
def curves_case(draw):
    return draw(curve_args(draw(st.sampled_from(["cw", "rpr3", "four"])), region=False))


def _curves(case):
    args, opts = case
    kw = {k: v for k, v in args.items() if k != "mech"}
    check(lambda: optkin.singular_curves(args["mech"], **kw, **opts))


@st.composite
def region_case(draw):
    return draw(curve_args(draw(st.sampled_from(["cw", "cw", "rpr3"])), region=True))


def _aspects(case):
    args, opts = case
    check(lambda: optkin.aspects(args["mech"], fixed=args["fixed"], **opts))


def _workspace(case):
    args, opts = case
    check(lambda: optkin.workspace(args["mech"], fixed=args["fixed"], **opts))


PNG_DIR = tempfile.mkdtemp(prefix="optkin-fuzz-")


@st.composite
def map_case(draw):
    name = draw(st.sampled_from(["five", "rpr3", "four"]))
    grid = st.integers(2, 5).map(lambda n: np.linspace(0.2, 1.8, n))
    if name == "rpr3":
        grid = st.integers(2, 4).map(lambda n: np.linspace(-0.2, 0.2, n))
    axes = {"five": ("x", "y"), "rpr3": ("x", "phi"), "four": ("theta", "theta")}[name]
    return draw(call_args(
        {"mech": st.just(MECHS[name][0]), "u": grid, "v": grid,
         "path": st.sampled_from([os.path.join(PNG_DIR, "m.png"),
                                  os.path.join(PNG_DIR, "no", "such", "m.png")])},
        {"measure": st.sampled_from(["distance", "parallel", "serial", "manipulability"]),
         "log": st.booleans(), "axes": st.just(axes),
         "fixed": st.sampled_from([None, {"y": 0.05}]),
         "working_mode": st.sampled_from([None, (1, 1), (-1, -1, -1)]), "guess": st.none()}))


def _map(case):
    args, opts = case
    # a junk path (a short text) is a file name relative to the working directory: write
    # it in the fuzz's own directory, never in the checkout (it left x.png there)
    here = os.getcwd()
    os.chdir(PNG_DIR)
    try:
        check(lambda: optkin.plot_singularity_map(args["mech"], args["u"], args["v"],
                                                  args["path"], **opts))
    finally:
        os.chdir(here)


CASES = {"assembly_modes": (assembly_case(), _assembly), "track": (track_case(), _track),
         "forward_batch": (batch_case(), _batch), "working_modes": (working_case(), _working),
         "singular_curves": (curves_case(), _curves), "aspects": (region_case(), _aspects),
         "workspace": (region_case(), _workspace), "plot_singularity_map": (map_case(), _map)}


def _fuzz(name: str, s: settings):
    strategy, run = CASES[name]

    @s
    @given(strategy)
    def inner(case):
        run(case)

    inner()


@pytest.mark.parametrize("name", sorted(CASES))
def test_fuzz_analyses(name):
    _fuzz(name, FAST)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CASES))
def test_fuzz_analyses_slow(name):
    _fuzz(name, SLOW)


def test_fuzz_budgets_are_in_force():
    """The environment of the fuzz: sizes far too large are refused, not run."""
    with pytest.raises(MechanismError, match=r"largest allowed grid is \d+"):
        optkin.aspects(CW, grid=10**4)
    assert math.isclose(limits.time_budget(), 2.0)


def test_fuzz_findings():
    """Cases the slow fuzz found."""
    # no rows and a guess, independent rows: an IndexError on A[0]
    b = optkin.forward_batch(FIVE, np.zeros((0, 2)), 0.0, chunk=1, path=False)
    assert len(b) == 0 and b.all_success
