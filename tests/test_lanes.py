"""SIMD lanes (optkin.model.lanes): an SX graph compiled to evaluate eight points at once.

Evidence: every operation the writer knows, evaluated at eight points per call, against
CasADi's own evaluation of the same Function point by point (NaN, infinities and ties
included, where fmin/fmax, comparisons and the logical operations have their corner
cases); and the homotopy tracker run through its lanes library against the same tracker
through CasADi's evaluation of the same chunk, on random 6-6 platforms: equal to the bit.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from test_homotopy import _random_stewart_platforms

import optkin
from optkin.model import compiled as cc
from optkin.model import get_model, lanes
from optkin.solvers import homotopy as H

needs_lanes = pytest.mark.skipif(cc.find_compiler() is None or lanes.cpu_key() is None,
                                 reason="no C compiler, or no CPU flags to key the "
                                        "library by (/proc/cpuinfo)")


def _every_op() -> ca.Function:
    x, y = ca.SX.sym("x", 3), ca.SX.sym("y", 3)
    p = ca.SX.sym("p", 2)
    a, b = x[0], y[0]
    outs = [a + b, a - b, a * b, a / b, -a, 2 * a, a ** 2, 1 / a, ca.sqrt(ca.fabs(a)),
            ca.fabs(b), a < b, a <= b, a == b, a != b, ca.logic_not(a),
            ca.logic_and(a, b), ca.logic_or(a, b), ca.if_else(a < b, x[1], y[1]),
            ca.fmin(a, b), ca.fmax(a, b), ca.fabs(a) ** 0.25, ca.constpow(x[2], 2),
            ca.sqrt(ca.fabs(y[2])) ** 0.5, a * p[0] + p[1], ca.if_else(a > 0, ca.inf, -ca.inf),
            x[1] * y[2] - x[2] * y[1]]
    return ca.Function("every_op", [x, y, p], [ca.vertcat(*outs)])


@needs_lanes
def test_every_operation_matches_casadi_at_every_lane():
    f = _every_op()
    g = lanes.lanes_function(f, shared=[2])
    assert g is not None and g.size_in(0) == (lanes.LANES, 3)
    rng = np.random.default_rng(3)
    special = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1.0, 1.0]
    for trial in range(20):
        X = rng.normal(size=(lanes.LANES, 3))
        Y = rng.normal(size=(lanes.LANES, 3))
        if trial % 2:  # corner cases: NaN, infinities, signed zeros, ties
            X[:, 0] = rng.choice(special, lanes.LANES)
            Y[:, 0] = rng.choice(special, lanes.LANES)
        P = rng.normal(size=2)
        got = np.array(g(X, Y, P))
        for k in range(lanes.LANES):
            want = np.array(f(X[k], Y[k], P)).ravel()
            np.testing.assert_allclose(got[k], want, rtol=1e-15, atol=0, equal_nan=True,
                                       err_msg=f"lane {k}: x={X[k]}, y={Y[k]}")


def test_an_unknown_operation_is_refused():
    x = ca.SX.sym("x")
    with pytest.raises(ValueError, match="ATAN2 not written"):
        lanes.kernel(ca.Function("f", [x], [ca.atan2(x, 1.0)]), "k")
    with pytest.raises(ValueError, match="power"):
        lanes.kernel(ca.Function("f", [x], [x ** 0.3]), "k")


@needs_lanes
def test_the_lanes_tracker_ends_every_path_where_the_chunk_does():
    """Three random 6-6 platforms, the same start system and gamma: the 40 endpoints of the
    lanes library (8 paths a call, the last call padded) against CasADi's evaluation of the
    same chunk (its interpreted Function, or its compiled one where the cache holds it): the
    same to the bit."""
    plats = list(_random_stewart_platforms(3, 21))
    m0 = plats[0][0]
    optkin.assembly_modes(m0, plats[0][1], method="homotopy")  # start system, chunk
    tr = H._tracker(get_model(m0))
    if tr._pending is not None:
        tr._pending.wait()
        tr._poll()
    tr._lanes_fn()  # starts the lanes library's build
    if tr._lanes is not None and not isinstance(tr._lanes, dict):
        tr._lanes.wait()
    assert tr._lanes_fn() is not None, "the lanes library did not build"
    rng = np.random.default_rng(0)
    for m, L in plats:
        model = get_model(m)
        S = H.covering_start(model) or H.load_or_build_start(model)
        sys = H._system(model)
        th1 = np.r_[L, np.asarray(model.p)[sys.p_used], np.zeros(sys.n)].astype(complex)
        gamma = np.exp(0.2j * rng.uniform(-1, 1))
        sc = np.asarray(model.x_scale, dtype=float)
        X1, st1, _, _, _ = tr.run(S.solutions, S.theta, th1, gamma, scale=sc, threads=2)
        saved = tr._lanes, tr._lanes_todo
        tr._lanes, tr._lanes_todo = None, None
        try:
            X0, st0, _, _, _ = tr.run(S.solutions, S.theta, th1, gamma, scale=sc, threads=1)
        finally:
            tr._lanes, tr._lanes_todo = saved
        assert list(st1) == list(st0) and (st0 == "finite").sum() == 40
        np.testing.assert_array_equal(X1, X0)  # to the bit: the same operations, no FMA
