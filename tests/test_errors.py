"""Bad input raises a MechanismError (a ValueError) naming the item and the fix."""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin import Mechanism, MechanismError
from optkin import mechanisms as M

ROW = dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="t1", r=0)


def rows(*changes):
    out = [dict(ROW), dict(ROW, a=1, theta="t2", d=1.0)]
    for j, key, value in changes:
        out[j][key] = value
    return out


def test_error_is_a_value_error():
    assert issubclass(MechanismError, ValueError)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: M.rpr3([[0, 0], [1, 0]], [[0, 0], [1, 0], [0, 1]]), r"base: expected an array of shape \(3, 2\)"),
        (lambda: M.rpr3([[0, 0], [1, 0], [0, 1]], [[0, 0, 0]] * 3), r"platform: expected an array of shape \(3, 2\)"),
        (lambda: M.stewart_gough(np.zeros((6, 2)), np.zeros((6, 3))), r"base: expected an array of shape \(6, 3\)"),
        (lambda: M.rrr3(np.eye(3)[:, :2], np.eye(3)[:, :2], -1.0, 1.0), r"proximal: lengths must be positive"),
        (lambda: M.rrr3(np.eye(3)[:, :2], np.eye(3)[:, :2], 1.0, [1.0, 2.0]), r"distal: expected a positive number or 3"),
        (lambda: M.five_bar(float("nan"), 1, 1, 1, 1), r"L0: expected a positive length"),
        (lambda: M.five_bar(1, 1, 0, 1, 1), r"L2: expected a positive length"),
        (lambda: M.four_bar(1, -2, 1, 1), r"L2: expected a positive length"),
        (lambda: M.delta(upper=0), r"upper: expected a positive length"),
        (lambda: M.rpr3([[0, 0], [1, 0], [0, float("inf")]], np.zeros((3, 2))), r"base: expected finite"),
    ],
)
def test_library_argument_errors(call, match):
    with pytest.raises(MechanismError, match=match):
        call()


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(rows=rows((1, "a", 2))), r"row 2 \(frame j=2\): a\(j\)=2 must satisfy 0 <= a\(j\) < j"),
        (dict(rows=rows((1, "a", 5))), r"row 2 .*a\(j\)=5 must satisfy"),
        (dict(rows=rows((1, "sigma", 5))), r"row 2 .*sigma=5 is not a joint type.*0 \(revolute\)"),
        (dict(rows=rows((0, "mu", 3))), r"row 1 .*mu=3"),
        (dict(rows=rows((1, "d", "dd"))), r"row 2 .*column d: unknown parameter 'dd'"),
        (dict(rows=rows((1, "d", "import os"))), r"row 2 .*cannot read"),
        (dict(rows=rows((1, "d", float("nan")))), r"row 2 .*column d"),
        (dict(rows=rows((1, "colour", 1))), r"row 2 .*unknown column"),
        (dict(rows=rows((1, "theta", "t1"))), r"joint name 't1' is used twice"),
        (dict(rows=[]), r"rows: the table is empty"),
        (dict(rows=rows(), loops=-1), r"loops: expected a non-negative integer"),
        (dict(rows=rows(), loops=1), r"loops: 1 loop\(s\) need"),
        (dict(rows=rows(), end_effector=7), r"end_effector: 7 is not a tree frame"),
        (dict(rows=rows((0, "mu", 0), (1, "mu", 0))), r"no joint is actuated"),
        (dict(rows=rows(), task=("x", "q")), r"task: \['x', 'q'\] must name distinct components"),
    ],
)
def test_khalil_table_errors(kwargs, match):
    with pytest.raises(MechanismError, match=match):
        Mechanism.from_khalil(**kwargs)


def _four_bar_rows():
    return [
        dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="theta", r=0),
        dict(a=1, mu=0, sigma=0, gamma=0, b=0, alpha=0, d=1.0, theta="t2", r=0),
        dict(a=0, mu=0, sigma=0, gamma=0, b=0, alpha=0, d=2.5, theta="phi", r=0),
        dict(a=2, mu=0, sigma=0, gamma=0, b=0, alpha=0, d=2.0, theta="t4", r=0),
        dict(a=3, mu=0, sigma=2, gamma=0, b=0, alpha=0, d=2.0, theta=0, r=0),
    ]


def test_limit_errors():
    with pytest.raises(MechanismError, match=r"limits.t9: unknown joint"):
        Mechanism.from_khalil(rows(), limits={"t9": (0, 1)})
    with pytest.raises(MechanismError, match=r"limits.t1: need lower < upper"):
        Mechanism.from_khalil(rows(), limits={"t1": (1, 0)})
    with pytest.raises(MechanismError, match=r"limits.t1: expected \(lower, upper\)"):
        Mechanism.from_khalil(rows(), limits={"t1": 3})


def test_cut_frame_without_partner():
    r = _four_bar_rows()
    r[4]["sigma"] = 0
    r[4]["theta"] = "t5"
    with pytest.raises(MechanismError, match=r"cut frame 4 has no partner frame: frame k\+B=5"):
        Mechanism.from_khalil(r, loops=1)


def test_actuated_cut_joint():
    r = _four_bar_rows()
    r[3]["mu"] = 1
    with pytest.raises(MechanismError, match=r"cut joint 4 is actuated"):
        Mechanism.from_khalil(r, loops=1, dof=2)


def test_partner_on_same_link():
    r = _four_bar_rows()
    r[4]["a"] = 2
    with pytest.raises(MechanismError, match=r"partner frame 5 sits on link 2"):
        Mechanism.from_khalil(r, loops=1)


def test_loop_that_can_never_close():
    r = _four_bar_rows()
    r[4]["b"] = 0.3  # the partner frame is lifted out of the loop plane
    m = Mechanism.from_khalil(r, loops=1)
    with pytest.raises(MechanismError, match=r"loop:4.pz: this closure row is the constant"):
        optkin.get_model(m)


def test_leg_errors():
    leg = {"type": "RPR", "base": [0, 0], "platform": [0, 0]}
    with pytest.raises(MechanismError, match=r"legs\[1\].type: unknown leg type 'RXR'"):
        Mechanism.from_legs([leg, dict(leg, type="RXR"), leg])
    with pytest.raises(MechanismError, match=r"legs\[2\].base: expected 2 numbers, got 3"):
        Mechanism.from_legs([leg, leg, dict(leg, base=[0, 0, 0])])
    with pytest.raises(MechanismError, match=r"needs 3 actuated legs, got 2"):
        Mechanism.from_legs([leg, leg])
    with pytest.raises(MechanismError, match=r"legs\[0\].lengths: RRR legs need 2 link lengths"):
        Mechanism.from_legs([dict(leg, type="RRR")] * 3)
    with pytest.raises(MechanismError, match=r"legs\[0\].actuated: 0 is not supported for RPR"):
        Mechanism.from_legs([dict(leg, actuated=0)] * 3)
    with pytest.raises(MechanismError, match=r"platform: unknown platform kind 'wobbly'"):
        Mechanism.from_legs([leg] * 3, platform="wobbly")
    with pytest.raises(MechanismError, match=r"legs\[0\].type: a UPS leg is spatial"):
        Mechanism.from_legs([dict(type="UPS", base=[0, 0, 0], platform=[0, 0, 0])] * 3)


def test_solver_input_errors():
    m = M.rpr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    with pytest.raises(MechanismError, match=r"qa: expected 3 values for the active joints"):
        optkin.forward(m, [0.5, 0.5])
    with pytest.raises(MechanismError, match=r"qa\[1\] \(L2.rho\): a leg length must be positive"):
        optkin.forward(m, [0.5, -0.5, 0.5])
    with pytest.raises(MechanismError, match=r"qa: non-finite value for \['L3.rho'\]"):
        optkin.forward(m, [0.5, 0.5, float("nan")])
    with pytest.raises(MechanismError, match=r"guess: expected the unknowns x"):
        optkin.forward(m, [0.5, 0.5, 0.5], guess=[1.0, 2.0])
    with pytest.raises(MechanismError, match=r"pose: expected a 4x4 matrix or 3 finite task"):
        optkin.inverse(m, [0.1, 0.2])
    with pytest.raises(MechanismError, match=r"not a rotation"):
        optkin.inverse(m, np.full((4, 4), 0.5))


def test_unknown_option_raises():
    m = M.five_bar(1, 1, 1, 1, 1)
    with pytest.raises(MechanismError, match=r"unknown option 'tolerance'"):
        optkin.forward(m, [1.8, 1.3], tolerance=1e-3)


def test_mechanism_is_immutable_and_picklable():
    import pickle

    m = M.sr400()
    with pytest.raises(AttributeError):
        m.name = "other"
    m2 = pickle.loads(pickle.dumps(m))
    assert m2.key == m.key and m2.joint_names == m.joint_names


@pytest.mark.parametrize("values, max_abs, bad_at", [
    ([1.0, 2.0], None, None), ([1.0, float("nan")], None, 1), ([float("inf"), 1.0], None, 0),
    ([1.0, -1e200], None, 1), ([1e200, 1.0], float("inf"), None),
    ([1.0, float("-inf")], float("inf"), 1), ([float("nan")], float("inf"), 0),
])
def test_as_vector_refuses_non_finite_and_too_large_entries(values, max_abs, bad_at):
    """as_vector's check, against the rule written out: NaN and +-inf are refused always,
    finite entries beyond max_abs (default MAX_ABS) only when max_abs is finite; the
    message names the first offending entry."""
    from optkin._checks import MAX_ABS, as_vector

    kw = {} if max_abs is None else {"max_abs": max_abs}
    limit = MAX_ABS if max_abs is None else max_abs
    want = next((i for i, v in enumerate(values)
                 if not np.isfinite(v) or abs(v) > limit), None)
    assert want == bad_at
    if bad_at is None:
        assert as_vector(values, "qa", **kw).tolist() == values
    else:
        with pytest.raises(optkin.MechanismError, match=f"at entry {bad_at}"):
            as_vector(values, "qa", **kw)
