"""Fuzz of the public mechanism, solver, analysis and statics functions (hypothesis).

Whatever the arguments (huge ints, NaN, inf, 1e308, strings, nested or ragged lists, wrong
shapes, random expressions, unknown options), a call either raises one of optkin's errors
(:class:`MechanismError`, :class:`StaticsError`) or returns a result whose ``success`` is a
bool, and it returns within a time bound (hypothesis ``deadline`` per example, plus a
process-wide watchdog that ends the run with a traceback instead of hanging it should a
native call never return). The default run stays short; the ``slow`` variants run many
more examples (``pytest -m slow tests/test_fuzz_api.py``).
"""

from __future__ import annotations

import faulthandler
import time
import warnings
from datetime import timedelta

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import optkin
from optkin import Mechanism, MechanismError, StaticsError, statics
from optkin import mechanisms as M
from optkin.mechanism import COLUMNS, LEG_TYPES, PLATFORMS

ALLOWED = (MechanismError, StaticsError)
#: Longest a single call may take (s); the hypothesis deadline is per example.
CALL_BUDGET = 20.0
FAST = settings(max_examples=150, deadline=timedelta(seconds=10), derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                       HealthCheck.filter_too_much])
SLOW = settings(FAST, max_examples=2000, derandomize=False)


@pytest.fixture(autouse=True, scope="module")
def watchdog():
    """A native call that never returns (LAPACK on NaN) ends the run with a traceback."""
    faulthandler.dump_traceback_later(1800, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


def check(call):
    """Run ``call``: only optkin's errors, or a result with a bool ``success``, in time."""
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            out = call()
        except ALLOWED as e:
            assert isinstance(e.path, tuple)
            out = None
    assert time.perf_counter() - t0 < CALL_BUDGET
    if out is None or isinstance(out, Mechanism):
        return out
    if isinstance(out, optkin.SolutionSet):
        assert type(out.info.get("success", False)) is bool
        for r in out:
            assert type(r.success) is bool
    elif isinstance(out, list):
        for r in out:
            assert type(r.success) is bool
    else:
        assert type(out.success) is bool, type(out)
    return out


# ----------------------------------------------------------------------------- strategies
HUGE = [10**400, -(10**400), 2**64, 1e308, -1e308, 1e151, 1e150, -1e149, 5e-324, float("nan"),
        float("inf"), -float("inf")]
#: an int beyond 4300 digits (str() of it raises ValueError); built when drawn, since
#: hypothesis cannot repr it inside a strategy
beyond_str = st.just(5000).map(lambda k: 10**k)

scalar = st.one_of(
    st.floats(-5, 5),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(10**400), max_value=10**400),
    st.integers(-3, 3),
    st.sampled_from(HUGE),
    beyond_str,
    st.text(max_size=6),
    st.none(),
    st.booleans(),
    st.complex_numbers(max_magnitude=10),
)

nested = st.recursive(scalar, lambda c: st.one_of(
    st.lists(c, max_size=4), st.tuples(c, c),
    st.dictionaries(st.text(max_size=3), c, max_size=2)), max_leaves=8)


def vectors(n: int, lo: float = -2.0, hi: float = 2.0):
    """Mostly well-formed vectors of n numbers (so the solvers run), and everything else."""
    good = st.lists(st.floats(lo, hi), min_size=n, max_size=n)
    return st.one_of(
        good, good, good.map(np.array),
        st.lists(scalar, min_size=n, max_size=n),
        st.lists(st.floats(lo, hi), min_size=0, max_size=n + 2),
        st.lists(st.sampled_from(HUGE), min_size=n, max_size=n),
        nested,
    )


def matrices(r: int, c: int, lo: float = -2.0, hi: float = 2.0):
    good = st.lists(st.lists(st.floats(lo, hi), min_size=c, max_size=c), min_size=r, max_size=r)
    return st.one_of(good, good, st.lists(st.lists(scalar, min_size=c, max_size=c),
                                          min_size=r, max_size=r),
                     st.lists(st.lists(st.floats(lo, hi), max_size=c + 1), max_size=r + 1),
                     nested)


_atom = st.one_of(st.integers(-9, 9).map(str), st.floats(-1e3, 1e3).map(repr),
                  st.sampled_from(["pi", "p", "q", "x", "1e999", "0", "9", "10" * 30]))
_ops = st.sampled_from(["+", "-", "*", "/", "**"])
expressions = st.one_of(
    st.recursive(_atom, lambda c: st.one_of(
        st.tuples(c, _ops, c).map(lambda t: f"{t[0]}{t[1]}{t[2]}"),
        st.tuples(c, _ops, c).map(lambda t: f"({t[0]}{t[1]}{t[2]})"),
        c.map(lambda s: "-" + s)), max_leaves=40),
    st.text(alphabet="0123456789+-*/().epix_ ", max_size=60),
    st.sampled_from(["1" + "+1" * 1000, "-" * 5000 + "1", "9**9**9", "2**-9999", "(-1)**0.5",
                     "__import__('os')", "lambda: 0", "[1]", "1 if 1 else 0", "p.real", "p[0]",
                     "(" * 300 + "1" + ")" * 300, "1/(p-p)", "p**p**p**p", "\x00"]),
)


@st.composite
def khalil_rows(draw):
    n = draw(st.integers(1, 6))
    rows = []
    for j in range(1, n + 1):
        if draw(st.booleans()):  # plausible row
            sigma = draw(st.sampled_from([0, 1, 2]))
            r = {"a": draw(st.integers(0, j - 1)), "mu": draw(st.integers(0, 1)) if sigma < 2
                 else 0, "sigma": sigma}
            for c in ("gamma", "b", "alpha", "d", "theta", "r"):
                if draw(st.booleans()):
                    r[c] = draw(st.one_of(st.floats(-2, 2), expressions, scalar))
            if sigma < 2 and draw(st.booleans()):
                r["theta" if sigma == 0 else "r"] = f"q{j}"
        else:
            keys = st.sampled_from(COLUMNS + ("j", "bogus", 3))
            r = draw(st.one_of(
                st.dictionaries(keys, st.one_of(st.integers(0, 3), scalar, expressions),
                                max_size=9),
                st.lists(st.one_of(st.integers(0, 2), scalar), max_size=10), scalar))
        rows.append(r)
    return draw(st.one_of(st.just(rows), st.just(rows), nested))


PARAMS = st.dictionaries(st.sampled_from(["p", "q", "x", "1a", "", "pi"]),
                         st.one_of(st.floats(-3, 3), scalar), max_size=3)


# ----------------------------------------------------------------------------- constructors


def _from_khalil(data):
    rows = data.draw(khalil_rows())
    kw = {}
    for key, strat in (("loops", st.one_of(st.integers(0, 2), scalar)),
                       ("params", st.one_of(PARAMS, scalar)),
                       ("end_effector", st.one_of(st.integers(0, 6), scalar)),
                       ("task", st.one_of(st.lists(st.sampled_from(
                           ["x", "y", "z", "rx", "ry", "rz", "w"]), max_size=7), scalar)),
                       ("home", st.one_of(vectors(3), st.dictionaries(
                           st.sampled_from(["q1", "q2", "theta1"]), scalar, max_size=2))),
                       ("dof", st.one_of(st.integers(0, 4), scalar)),
                       ("limits", st.one_of(st.dictionaries(
                           st.sampled_from(["q1", "q2", "r1"]), st.one_of(
                               st.tuples(scalar, scalar), scalar), max_size=2), scalar))):
        if data.draw(st.booleans()):
            kw[key] = data.draw(strat)
    m = check(lambda: Mechanism.from_khalil(rows, **kw))
    if m is not None and data.draw(st.booleans()) and len(m.joint_names) <= 6:
        qa = data.draw(vectors(m.n_actuated))
        check(lambda: optkin.forward(m, qa))


@st.composite
def legs(draw):
    platform = draw(st.one_of(st.sampled_from(sorted(PLATFORMS)), scalar))
    dim = PLATFORMS[platform].space_dim if isinstance(platform, str) and platform in PLATFORMS \
        else 2
    n = draw(st.integers(0, 7))
    out = []
    for _ in range(n):
        if draw(st.integers(0, 5)) == 0:  # a chain given by its screws (Leg.from_screws)
            k = draw(st.integers(1, 6))
            leg = {"screws": draw(st.one_of(matrices(k, 6, -1.0, 1.0), st.sampled_from(
                       [[[0, 0, 1, 0, -1, 0], [0, 0, 0, 1, 0, 0], [0, 0, 1, 0, -1, 0]]]))),
                   "home": draw(st.one_of(st.just(np.eye(4).tolist()), matrices(4, 4))),
                   "actuated": draw(st.one_of(st.integers(-1, 6), st.lists(
                       st.integers(0, 6), max_size=3), scalar))}
            if draw(st.booleans()):
                leg["joints"] = draw(st.one_of(st.sampled_from(["RPR", "UPU", "C", "S"]),
                                               scalar))
            out.append(leg)
            continue
        leg = {"type": draw(st.one_of(st.sampled_from(sorted(LEG_TYPES)), scalar)),
               "base": draw(vectors(dim)), "platform": draw(vectors(dim, -0.5, 0.5))}
        lt = LEG_TYPES.get(leg["type"]) if isinstance(leg["type"], str) else None
        if lt is not None and draw(st.booleans()):  # the keys its type takes, as many numbers
            for key, count in lt.keys.items():
                leg[key] = draw(vectors(count, 0.1, 2.0))
        if draw(st.booleans()):
            leg["lengths"] = draw(vectors(2, 0.1, 2.0))
        if draw(st.booleans()):
            leg["axis"], leg["arm"] = draw(st.sampled_from(
                [([0, 0, 1], [1, 0, 0]), ([0, 0, 1], [0, 0, 1]), ("z", "x")]))
        if draw(st.booleans()):
            leg["actuated"] = draw(st.one_of(st.integers(-1, 6), scalar))
        if draw(st.booleans()):
            leg[draw(st.sampled_from(["bogus", 7]))] = 1
        out.append(leg)
    return platform, draw(st.one_of(st.just(out), st.just(out), nested))


def _library(data):
    name = data.draw(st.sampled_from(["rpr3", "rpr4", "rrr3", "stewart_gough", "five_bar",
                                      "four_bar", "delta", "sr400", "akr3000"]))
    pos = st.one_of(st.floats(0.05, 3.0), scalar)
    if name in ("rpr3", "rrr3"):
        args = [data.draw(matrices(3, 2)), data.draw(matrices(3, 2, -0.3, 0.3))]
        if name == "rrr3":
            args += [data.draw(st.one_of(pos, vectors(3, 0.1, 1.0))) for _ in range(2)]
        call = getattr(M, name)
    elif name == "rpr4":
        args, call = [data.draw(matrices(4, 2)), data.draw(matrices(4, 2, -0.3, 0.3))], M.rpr4
    elif name == "stewart_gough":
        args = [data.draw(matrices(6, 3)), data.draw(matrices(6, 3, -0.5, 0.5))]
        call = M.stewart_gough
    elif name == "five_bar":
        args, call = [data.draw(pos) for _ in range(5)], M.five_bar
    elif name == "four_bar":
        args, call = [data.draw(pos) for _ in range(4)], M.four_bar
    else:
        call = getattr(M, name)
        keys = {"delta": ["base_radius", "platform_radius", "upper", "lower"],
                "sr400": ["d2", "d3", "d4", "d8", "rl4"],
                "akr3000": ["d3", "d4", "d7", "r8", "d13", "gamma13"]}[name]
        kw = {k: data.draw(pos) for k in keys if data.draw(st.booleans())}
        return check(lambda: call(**kw))
    kw = {"home": data.draw(vectors(3))} if name in ("rpr3", "rrr3") and data.draw(
        st.booleans()) else {}
    return check(lambda: call(*args, **kw))


# ----------------------------------------------------------------------------- solvers


BASE = [[0, 0], [1, 0], [0.5, 0.9]]
PLAT = [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]
MECHS = {
    "rpr3": M.rpr3(BASE, PLAT),
    "five_bar": M.five_bar(1.0, 1.0, 1.0, 1.0, 1.0),
    "four_bar": M.four_bar(1.0, 2.0, 2.0, 2.5),
    "sr400": M.sr400(),
    "delta": M.delta(),
}
CLOSED = {
    "rpr3": optkin.forward(MECHS["rpr3"], [0.5, 0.5, 0.5]),
    "five_bar": optkin.inverse(MECHS["five_bar"], [0.5, 1.2])[0],
    "four_bar": optkin.forward(MECHS["four_bar"], [1.0]),
    "sr400": optkin.forward(MECHS["sr400"], [0.3, -0.4, 0.2, 0.5, 0.4, 0.6],
                            guess=[np.pi / 2 + 1, -1, np.pi + 1]),
    "delta": optkin.forward(MECHS["delta"], [0.3, 0.3, 0.3]),
}
assert all(r.success for r in CLOSED.values())
OPTION_NAMES = ["tol", "max_iter", "polish", "method", "starts", "iters", "seed", "rtol",
                "second_order_tol", "sing_tol", "cap", "dir_tol", "chunk", "solver", "reuse",
                "bogus"]
options = st.dictionaries(st.sampled_from(OPTION_NAMES), st.one_of(
    st.floats(0, 1e-6), st.integers(0, 40), scalar, st.sampled_from(
        ["auto", "ipopt", "newton", "HIGHS", "CLARABEL", "x"])), max_size=3)


def _pick(data):
    name = data.draw(st.sampled_from(sorted(MECHS)))
    m, r = MECHS[name], CLOSED[name]
    q = data.draw(st.one_of(st.just(r), st.just(r), st.just(r.q),
                            vectors(len(m.joint_names)), st.sampled_from(HUGE)))
    return m, r, q


def _forward_inverse(data):
    m, r, _ = _pick(data)
    qa = data.draw(st.one_of(st.just(r.qa), vectors(m.n_actuated, 0.05, 2.0),
                             vectors(m.n_actuated)))
    guess = data.draw(st.one_of(st.none(), st.just(r), vectors(len(m.joint_names)),
                                vectors(m.task_dim), scalar))
    opts = data.draw(options)
    check(lambda: optkin.forward(m, qa, guess, **opts))
    pose = data.draw(st.one_of(st.just(r.pose), vectors(m.task_dim), matrices(4, 4),
                               st.just(r.pose * 2), scalar))
    opts = data.draw(options)
    check(lambda: optkin.inverse(m, pose, **opts))


def _analyses(data):
    m, r, q = _pick(data)
    tol = data.draw(st.one_of(st.just(1e-8), scalar))
    jac = check(lambda: optkin.jacobians(m, q, tol=tol))
    if jac is not None and data.draw(st.booleans()):
        rates = data.draw(vectors(m.n_actuated))
        for method in ("joint_rates", "twist", "passive_rates", "x_rates"):
            check(lambda method=method: _result_of(getattr(jac, method)(rates)))
    check(lambda: optkin.classify(m, q, **data.draw(options)))
    if data.draw(st.booleans()):
        samples = data.draw(st.one_of(st.integers(1, 3), scalar))
        seed = data.draw(st.one_of(st.integers(0, 5), scalar))
        rtol = data.draw(st.one_of(st.just(1e-8), scalar))
        check(lambda: optkin.dof(m, samples=samples, seed=seed, rtol=rtol))


class _Done:
    success = True


def _result_of(values):
    """A method that returns an array: wrap it as a result for :func:`check`."""
    np.asarray(values, dtype=float)
    return _Done()


def _statics(data):
    m, r, q = _pick(data)
    na, nw = m.n_actuated, len(statics.wrench_names(m))
    limits = data.draw(st.one_of(st.floats(0.1, 10), vectors(na, 0.0, 5.0),
                                 matrices(na, 2, -3.0, 3.0), scalar, st.none()))
    opts = {k: v for k, v in data.draw(options).items() if k != "chunk"}
    directions = data.draw(st.one_of(st.none(), matrices(2, nw), st.lists(
        st.sampled_from(["fx", "fy", "mz", "-fx", "fz", "-my", 3]), max_size=3), scalar))
    check(lambda: statics.capability(m, q, limits, directions, **opts))
    ws = data.draw(st.one_of(vectors(nw, -1e3, 1e3), matrices(2, nw), st.fixed_dictionaries(
        {"lower": vectors(nw, -1, 0), "upper": vectors(nw, 0, 1)}), scalar))
    check(lambda: statics.feasible(m, q, ws, limits, **opts))
    wrench = data.draw(st.one_of(vectors(nw, -1e140, 1e140), vectors(nw), scalar))
    norm = data.draw(st.one_of(st.sampled_from([2, "inf", "max", 1, "l2"]), scalar))
    weights = data.draw(st.one_of(st.none(), vectors(na, 0.01, 3.0), scalar))
    check(lambda: statics.distribute(m, q, wrench, limits, norm, weights, **opts))


# ----------------------------------------------------------------------------- the tests
# default run: a few dozen examples each (about half a minute for the file); the slow
# variants draw many more.

CASES = {"from_khalil": _from_khalil, "library": _library, "forward_inverse": _forward_inverse,
         "analyses": _analyses, "statics": _statics}


def _from_legs(data):
    platform, lg = data.draw(legs())
    kw = {}
    if data.draw(st.booleans()):
        kw["home"] = data.draw(vectors(3))
    if data.draw(st.booleans()):
        kw["redundant"] = data.draw(st.one_of(st.booleans(), scalar))
    m = check(lambda: Mechanism.from_legs(lg, platform, **kw))
    if m is not None and data.draw(st.booleans()):
        qa = data.draw(vectors(m.n_actuated, 0.05, 2.0))
        check(lambda: optkin.forward(m, qa))


CASES["from_legs"] = _from_legs


@pytest.mark.parametrize("case", sorted(CASES))
@FAST
@given(data=st.data())
def test_fuzz_public_api(case, data):
    CASES[case](data)


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
@SLOW
@given(data=st.data())
def test_fuzz_public_api_slow(case, data):
    CASES[case](data)
