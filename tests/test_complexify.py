"""Complex evaluation of SX Functions (optkin.model.complexify).

Evidence: an expression written twice, once with CasADi symbols and once with numpy's
complex arithmetic, agrees at random complex points; a model's complexified closure
gives, by the complex step f(x + i h e_k) with h = 1e-30, its real Jacobian column by
column (CasADi's symbolic W_p), to round-off; and it is holomorphic at complex points
(the derivative along i e_k is i times the derivative along e_k, by finite differences).
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from test_certify import _mechanisms

import optkin
from optkin.model import compiled as cc
from optkin.model import get_model
from optkin.model.complexify import complexify


def _eval(fc, *parts):
    return [np.array(v, dtype=float).ravel() for v in fc(*parts)]


def test_expression_agrees_with_numpy_complex():
    x = ca.SX.sym("x", 3)
    p = ca.SX.sym("p")
    e = ca.vertcat(
        ca.sin(x[0]) * x[1] + ca.sqrt(x[0] ** 2 + x[1] ** 2 + p) / (x[2] - 3),
        ca.exp(x[0] / 2) * ca.cos(x[1]) - x[2] ** 3 + 1 / x[0] - 2 * ca.tanh(x[2]),
        ca.log(x[1] + 2) * ca.cosh(x[0]) - ca.sinh(x[2]) * ca.tan(x[0] / 3) + x[0] ** -2,
    )
    f = ca.Function("f", [x, p], [e], ["x", "p"], ["e"])
    fc = complexify(f, ["x"])
    assert fc.n_in() == 3 and fc.name_in() == ["x_re", "x_im", "p"]
    rng = np.random.default_rng(0)
    for _ in range(50):
        z = rng.normal(0, 0.7, 3) + 1j * rng.normal(0, 0.7, 3)
        pv = rng.uniform(0.5, 2)
        ref = np.array([
            np.sin(z[0]) * z[1] + np.sqrt(z[0] ** 2 + z[1] ** 2 + pv) / (z[2] - 3),
            np.exp(z[0] / 2) * np.cos(z[1]) - z[2] ** 3 + 1 / z[0] - 2 * np.tanh(z[2]),
            np.log(z[1] + 2) * np.cosh(z[0]) - np.sinh(z[2]) * np.tan(z[0] / 3) + z[0] ** -2,
        ])
        re, im = _eval(fc, z.real, z.imag, pv)
        np.testing.assert_allclose(re + 1j * im, ref, rtol=1e-12, atol=1e-12)


def test_real_points_give_real_values():
    x = ca.SX.sym("x", 2)
    f = ca.Function("f", [x], [ca.vertcat(x[0] * ca.sin(x[1]), ca.exp(x[0]) - x[1] ** 2)])
    re, im = _eval(complexify(f), [0.3, -1.2], [0.0, 0.0])
    np.testing.assert_array_equal(im, 0.0)
    np.testing.assert_allclose(re, np.array(f([0.3, -1.2], )).ravel(), rtol=1e-15)


def test_non_holomorphic_operations_are_refused():
    x = ca.SX.sym("x")
    with pytest.raises(ValueError, match="fabs has no holomorphic extension"):
        complexify(ca.Function("f", [x], [ca.fabs(x)]))
    with pytest.raises(TypeError, match="SX Function"):
        complexify(ca.Function("g", [ca.MX.sym("y")], [ca.MX(1)]))


def _mechs():
    """test_certify's mechanisms (distance legs, a Khalil four-bar, a Delta) and the SR400
    (a Khalil table with two loops)."""
    return {**_mechanisms(), "sr400": optkin.mechanisms.sr400()}


@pytest.mark.parametrize("name", list(_mechs()))
def test_model_closure_complex_step_and_holomorphy(name):
    model = get_model(_mechs()[name])
    topo = model.topology
    fc = complexify(topo.phi, ["x"])  # inputs: qa, x_re, x_im, p
    rng = np.random.default_rng(2)
    qa = rng.uniform(0.5, 1.5, model.na)
    x = model.default_x(qa) + rng.normal(0, 0.1, model.nx)
    _, Wp, _ = (np.array(v, dtype=float) for v in topo.jac(qa, x, model.p))
    h = 1e-30
    for k in range(model.nx):  # complex step: Im f(x + i h e_k) / h = df/dx_k exactly
        e = np.zeros(model.nx)
        e[k] = h
        re, im = _eval(fc, qa, x, e, model.p)
        np.testing.assert_allclose(im / h, Wp[:, k], rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(re, np.array(topo.phi(qa, x, model.p)).ravel(),
                                   rtol=1e-13, atol=1e-13)
    # holomorphy at a complex point: d/d(i t) = i d/dt along each unknown
    y_im = rng.normal(0, 0.05, model.nx)
    d = 1e-6
    for k in range(model.nx):
        e = np.zeros(model.nx)
        e[k] = d
        r0, i0 = _eval(fc, qa, x - e, y_im, model.p)
        r1, i1 = _eval(fc, qa, x + e, y_im, model.p)
        r2, i2 = _eval(fc, qa, x, y_im - e, model.p)
        r3, i3 = _eval(fc, qa, x, y_im + e, model.p)
        along_real = ((r1 - r0) + 1j * (i1 - i0)) / (2 * d)
        along_imag = ((r3 - r2) + 1j * (i3 - i2)) / (2 * d)
        np.testing.assert_allclose(along_imag, 1j * along_real, rtol=1e-6, atol=1e-6)


@pytest.mark.skipif(cc.find_compiler() is None,
                    reason="no C compiler here: the compiled path falls back to the interpreter")
def test_complexified_closure_compiles_and_maps(tmp_path, monkeypatch):
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    model = get_model(_mechs()["rpr3"])
    fc = complexify(model.topology.phi, ["x"])
    lib = cc.library("complex:rpr3", [fc])
    assert lib is not None
    compiled = lib[fc.name()]
    assert compiled.is_a("External")
    fm = compiled.map(8)
    rng = np.random.default_rng(4)
    X = rng.normal(0, 0.5, (model.nx, 8))
    Y = rng.normal(0, 0.5, (model.nx, 8))
    qa = np.full((model.na, 8), 0.8)
    P = np.repeat(np.asarray(model.p)[:, None], 8, axis=1)
    re, im = (np.array(v) for v in fm(qa, X, Y, P))
    for j in range(8):
        r1, i1 = _eval(fc, qa[:, j], X[:, j], Y[:, j], P[:, j])
        np.testing.assert_allclose(re[:, j], r1, rtol=1e-14)
        np.testing.assert_allclose(im[:, j], i1, rtol=1e-14)
