"""The public API raises only optkin's errors for bad input, or returns success=False.

One test per reproduction of ``../shared/repro`` (api_raw_exceptions.py,
jacobians_hang_degenerate.py, distribute_wrong_success.py) and of the other findings of the
reliability issue on the mechanism, solver, analysis and statics functions: raw Python
exceptions (ZeroDivisionError, OverflowError, TypeError, RecursionError, LinAlgError, plain
ValueError), a LAPACK hang on NaN, a statics answer 1e288 times too small reported as
optimal, and statics numbers that depended on what the process solved before.
"""

from __future__ import annotations

import doctest
import importlib
import json
import pickle
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import optkin
from optkin import Mechanism, MechanismError, StaticsError, statics
from optkin import mechanisms as M

BASE = [[0, 0], [1, 0], [0.5, 0.9]]
PLAT = [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]


def row(d):
    return [{"a": 0, "mu": 1, "sigma": 0, "theta": "t1", "d": d}]


def run_python(code: str, timeout: float = 120.0) -> str:
    """Run ``code`` in a fresh interpreter (a hang there cannot hang the suite); its stdout."""
    p = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True,
                       text=True, timeout=timeout)
    assert p.returncode == 0, p.stderr[-3000:]
    return p.stdout


def last_json(out: str):
    """The last line of ``out`` that is JSON (solvers may print banners before it)."""
    return json.loads([line for line in out.splitlines() if line.startswith(("{", "["))][-1])


# ----------------------------------------------------------------------------- expressions
# api_raw_exceptions.py: ZeroDivisionError, OverflowError, TypeError, RecursionError; the
# issue's B2 adds MemoryError ("-" * 100000 + "1") and a bignum 9**9**9.


@pytest.mark.parametrize("text, match", [
    ("1/0", r"row 1 \(frame j=1\), column d: '1/0' divides by zero"),
    ("9**9**9", r"column d: '9\*\*9\*\*9' overflows"),
    ("(-1)**0.5", r"column d: .*negative number to a fractional power \(a complex number\)"),
    ("0**-1", r"column d: .*divides by zero"),
    ("1" + "+1" * 1000, r"column d: the expression is 2001 characters long; at most 1000"),
    ("-" * 100000 + "1", r"column d: the expression is 100001 characters long"),
    ("+".join(["1"] * 300), r"column d: the expression is nested more than 100 levels deep"),
    ("1e999", r"column d: the number 1e999 in '1e999' is too large"),
    ("1" + "0" * 400, r"column d: the number 1000000.* is too large"),
    ("1e100*1e100*1e100*1e100", r"column d: .*overflows|is too large|beyond"),
    ("True", r"column d: 'True' is not allowed"),
    ("2j", r"column d: '2j' is not allowed"),
])
def test_khalil_expression_errors_are_mechanism_errors_with_a_path(text, match):
    with pytest.raises(MechanismError, match=match) as e:
        Mechanism.from_khalil(row(text))
    assert e.value.path == ("rows", 0, "d")


def test_expressions_within_the_limits_still_evaluate():
    m = Mechanism.from_khalil(row("+".join(["0.01"] * 99)), params={"a": 2.0})
    assert m.table.frames[0].d == pytest.approx(0.99)
    m = Mechanism.from_khalil(row("-a**2/4 + pi/pi"), params={"a": 2.0})
    assert m.table.frames[0].d == pytest.approx(0.0)


# ----------------------------------------------------------------------------- huge integers


@pytest.mark.parametrize("call, match", [
    (lambda: optkin.forward(M.four_bar(1, 2, 2, 2.5), [10**400]), r"^qa: .*too large"),
    (lambda: M.five_bar(10**400, 1, 1, 1, 1), r"^L0: expected a positive length"),
    (lambda: M.five_bar(1e300, 1e300, 1e300, 1e300, 1e300), r"^L0: expected a positive length"),
    (lambda: M.rpr3([[10**400, 0], [1, 0], [0.5, 0.9]], PLAT), r"^base: "),
    (lambda: M.sr400(d2=10**400), r"^d2: the integer"),
    (lambda: Mechanism.from_khalil(row(0.5), params={"p": 10**400}), r"^params\.p: the integer"),
    (lambda: Mechanism.from_khalil(row(10**400)), r"^row 1 \(frame j=1\), column d: the integer"),
    (lambda: Mechanism.from_khalil(row(0.5), home=[10**400]), r"^home: expected 1 finite"),
    (lambda: Mechanism.from_khalil(row(0.5), limits={"t1": (0, 10**400)}), r"^limits\.t1: "),
    (lambda: Mechanism.from_khalil([dict(row(0.5)[0], mu=10**400)]), r"mu must be an integer"),
    (lambda: Mechanism.from_legs([{"type": "RPR", "base": [10**400, 0], "platform": [0, 0]}] * 3),
     r"^legs\[0\]\.base: "),
    (lambda: optkin.forward(M.four_bar(1, 2, 2, 2.5), [1.0], tol=10**400),
     r"^forward: option tol must be a number >= 0"),
    (lambda: optkin.forward(M.four_bar(1, 2, 2, 2.5), [1.0], max_iter=10**400),
     r"^forward: option max_iter must be"),
    (lambda: optkin.inverse(M.five_bar(1, 1, 1, 1, 1), [0.5, 1.2], starts=10**400),
     r"^inverse: option starts must be"),
    (lambda: optkin.inverse(M.five_bar(1, 1, 1, 1, 1), [10**400, 1.2]), r"^pose: expected"),
    (lambda: optkin.dof(M.four_bar(4, 4, 2, 2), samples=10**400),
     r"^dof: option samples must be"),
    (lambda: optkin.dof(M.four_bar(4, 4, 2, 2), seed=10**400),
     r"^dof: option seed must be a number >= 0 .*too large"),
], ids=["forward_qa", "five_bar", "five_bar_1e300", "rpr3_base", "sr400", "params", "column",
        "home", "limits", "mu", "legs", "option_tol", "option_max_iter", "inverse_starts",
        "inverse_pose", "dof_samples", "dof_seed"])
def test_huge_integers_anywhere_are_mechanism_errors(call, match):
    with pytest.raises(MechanismError, match=match):
        call()


@pytest.mark.parametrize("kw", [{"tol": "x"}, {"method": 3}, {"max_iter": "8"},
                                {"polish": [1]}, {"tol": complex(1, 1)}])
def test_string_and_odd_options_are_mechanism_errors(kw):
    with pytest.raises(MechanismError, match=r"^forward: option \w+ must be"):
        optkin.forward(M.four_bar(1, 2, 2, 2.5), [1.0], **kw)


def test_statics_inputs_beyond_the_float_range_are_statics_errors():
    m = M.rpr3(BASE, PLAT)
    r = optkin.forward(m, [0.5] * 3)
    with pytest.raises(StaticsError, match=r"^limits: "):
        statics.capability(m, r, 10**400)
    with pytest.raises(StaticsError, match=r"^limits: magnitudes above 1e\+150"):
        statics.capability(m, r, 1e300)
    with pytest.raises(StaticsError, match=r"^wrench: expected 3 finite components"):
        statics.distribute(m, r, [10**400, 0, 0])
    with pytest.raises(StaticsError, match=r"^wrench_set: expected a wrench"):
        statics.feasible(m, r, [1e300, 0, 0], 1.0)
    with pytest.raises(StaticsError, match=r"^directions: expected an array"):
        statics.capability(m, r, 1.0, [[1, "x", 0]])
    with pytest.raises(StaticsError, match=r"^norm: expected 2 or 'inf'"):
        statics.distribute(m, r, [1, 0, 0], norm=np.array([2, 2]))
    with pytest.raises(StaticsError, match=r"^wrench box: .*at most 12"):
        statics.box([0] * 40, [1] * 40)
    with pytest.raises(StaticsError, match=r"option solver must be None or an installed"):
        statics.distribute(m, r, [1, 0, 0], solver="nonsense")


# ----------------------------------------------------------------------------- B1: the hang


def test_degenerate_rpr3_is_rejected_at_construction_without_hanging():
    """jacobians_hang_degenerate.py: all points coincident used to pass construction, then
    jacobians spun forever in LAPACK. Now construction names the points; the whole script
    runs in a subprocess with a time limit so that a regression cannot hang the suite."""
    out = run_python("""
        import json, numpy as np, optkin
        from optkin import mechanisms as M
        try:
            m = M.rpr3(base=[[0, 0]] * 3, platform=[[0, 0]] * 3)
            r = optkin.jacobians(m, np.zeros(9))
            print(json.dumps({"built": True, "success": bool(r.success)}))
        except optkin.MechanismError as e:
            print(json.dumps({"built": False, "error": str(e), "path": list(e.path)}))
    """, timeout=60)
    res = last_json(out)
    if res["built"]:
        assert res["success"] is False
    else:
        assert res["error"].startswith("platform: rows 0, 1, 2: all platform points coincide")
        assert "move them apart" in res["error"] and res["path"] == ["platform"]


@pytest.mark.parametrize("legs, match", [
    ([{"type": "RPR", "base": [0, 0], "platform": p} for p in PLAT],
     r"^legs: legs\[0\]\.base, legs\[1\]\.base, legs\[2\]\.base: all base points coincide"),
    ([{"type": "RRR", "base": b, "platform": [0.1, 0.1], "lengths": [1, 1]} for b in BASE],
     r"^legs: .*all platform points coincide at \(0\.1, 0\.1\)"),
    ([{"type": "RPR", "base": BASE[0], "platform": PLAT[0]}] * 2
     + [{"type": "RPR", "base": BASE[2], "platform": PLAT[2]}],
     r"^legs: legs\[0\], legs\[1\]: legs 1 and 2 have the same base point"),
])
def test_degenerate_platforms_are_rejected_naming_the_points(legs, match):
    with pytest.raises(MechanismError, match=match) as e:
        Mechanism.from_legs(legs, "planar")
    assert e.value.path[0] == "legs"


def test_degenerate_spatial_platforms_are_rejected():
    a = np.linspace(0, 2 * np.pi, 7)[:-1]
    base = np.c_[np.cos(a), np.sin(a), 0 * a]
    with pytest.raises(MechanismError, match=r"^platform: .*all platform points lie on one line"):
        M.stewart_gough(base, np.c_[a, 2 * a, 0 * a])
    with pytest.raises(MechanismError, match=r"^base: .*all base points lie on one line"):
        M.stewart_gough(np.c_[a, 0 * a, 0 * a], 0.5 * base)
    M.stewart_gough(base, 0.5 * base)  # a regular design is accepted


ZERO_LEG = dict(base=[[0, 0], [-1, 0], [-2, 0.5]], platform=[[0, 0], [0.5, 0], [0, 0.5]])
ZERO_LEG_Q = [0, 0, 0, 0, 1.5, 0, 0, 2, 0]  # leg 1 of length 0: its direction is undefined


def test_a_leg_of_zero_length_gives_success_false_without_reaching_lapack():
    """The NaN of an undefined leg direction used to reach LAPACK (a hang on some builds,
    LinAlgError in classify here); run in a subprocess with a time limit."""
    out = run_python(f"""
        import json, optkin
        from optkin import mechanisms as M
        m = M.rpr3(**{ZERO_LEG!r})
        jac = optkin.jacobians(m, {ZERO_LEG_Q!r})
        rep = optkin.classify(m, {ZERO_LEG_Q!r})
        print(json.dumps({{"jac": [jac.success, jac.status, jac.message],
                          "rep": [rep.success, sorted(rep.types), rep.message, repr(rep)]}}))
    """, timeout=90)
    res = last_json(out)
    assert res["jac"][:2] == [False, "singular"]
    assert "leg 1 (RPR) has zero length" in res["jac"][2]
    assert res["rep"][0] is False and res["rep"][1] == []
    assert "undefined" in res["rep"][3]


def test_statics_at_a_leg_of_zero_length_is_success_false():
    m = M.rpr3(**ZERO_LEG)
    sm = statics.static_model(m, ZERO_LEG_Q)
    assert sm.singularity == "undefined"
    d = statics.distribute(m, ZERO_LEG_Q, [0, 1, 0])
    c = statics.capability(m, ZERO_LEG_Q, 1.0)
    f = statics.feasible(m, ZERO_LEG_Q, [0, 1, 0], 1.0)
    p = statics.polytope(m, ZERO_LEG_Q, 1.0)
    for r in (d, c, f, p):
        assert r.success is False and "undefined" in r.message


def test_jacobians_at_1e308_is_success_false_not_linalgerror():
    """api_raw_exceptions.py: q = 1e308 raised LinAlgError (SVD did not converge)."""
    m = M.rpr3(BASE, PLAT)
    jac = optkin.jacobians(m, [1e308] * 9)
    assert jac.success is False and not jac.info["defined"]
    assert "overflows" in jac.message
    rep = optkin.classify(m, [1e308] * 9)
    assert rep.success is False


def test_numeric_wrappers_refuse_nan():
    from optkin import numeric
    from optkin.errors import NumericError

    bad = np.array([[np.nan, 0.0], [0.0, 1.0]])
    for call in (lambda: numeric.svd(bad, "W"), lambda: numeric.lstsq(bad, np.ones(2), "W"),
                 lambda: numeric.solve(bad, np.ones(2), "W"), lambda: numeric.rank(bad, "W"),
                 lambda: numeric.cond(bad, "W"), lambda: numeric.pinv(bad, "W"),
                 lambda: numeric.inv(bad, "W"), lambda: numeric.norm2(bad, "W")):
        with pytest.raises(NumericError, match=r"^W: the matrix has non-finite entries"):
            call()
    assert issubclass(NumericError, MechanismError)
    big = np.array([[1e308, 1e308], [1e308, -1e308]])  # finite, but squares overflow
    assert np.allclose(numeric.singular_values(big, "big"), [np.sqrt(2) * 1e308] * 2)
    assert numeric.inv(np.zeros((2, 2)), "z") is None


# ----------------------------------------------------------------------------- B10: statics


def _rpr_wrench(m, r, tau):
    """F = sum_i tau_i [u_i; (R b_i) x u_i]: the 3-RPR's static balance written out here
    (u_i the unit vector from the base joint to the platform joint), not by optkin."""
    T = r.pose
    R, p = T[:2, :2], T[:2, 3]
    F = np.zeros(3)
    for t, leg in zip(tau, m.legs):
        rb = R @ np.asarray(leg.platform)
        u = p + rb - np.asarray(leg.base)
        u = u / np.linalg.norm(u)
        F += t * np.array([u[0], u[1], rb[0] * u[1] - rb[1] * u[0]])
    return F


def test_distribute_1e308_is_an_error_and_huge_wrenches_are_solved_to_scale():
    """distribute_wrong_success.py: a 1e308 wrench gave success=True, 'optimal', forces
    1e288 times too small. Beyond 1e150 it is now an error; within, the answer balances."""
    m = M.rpr3(BASE, PLAT)
    r = optkin.forward(m, [0.5] * 3)
    with pytest.raises(StaticsError, match=r"^wrench: .*magnitude at most 1e\+150"):
        statics.distribute(m, r, [1e308] * 3)
    for scale in (1e140, 1.0, 1e-140):
        w = np.array([1.0, -0.5, 0.2]) * scale
        for norm in (2, "inf"):
            d = statics.distribute(m, r, w, norm=norm)
            if d.success:
                rel = np.abs(_rpr_wrench(m, r, d.tau) - w).max() / np.abs(w).max()
                assert rel < 1e-8, (scale, norm, rel)
                assert d.residual <= 1e-8 * np.abs(w).max()
            else:
                assert d.status in ("error", "infeasible", "inaccurate")
    d = statics.distribute(m, r, [1e140] * 3, limits=1e139)  # beyond the limits: infeasible
    assert not d.success and d.status == "infeasible"


def test_capability_and_feasibility_scale_with_the_limits():
    m = M.rpr3(BASE, PLAT)
    r = optkin.forward(m, [0.5] * 3)
    one = statics.capability(m, r, 1.0)
    big = statics.capability(m, r, 1e140)
    assert big.success and np.allclose(big.max / one.max, 1e140, rtol=1e-9)
    f1 = statics.feasible(m, r, [0.1, -0.2, 0.01], 1.0)
    fb = statics.feasible(m, r, [1e139, -2e139, 1e138], 1e140)
    assert fb.success and fb.margin == pytest.approx(f1.margin, rel=1e-9)


def test_a_solver_answer_that_violates_its_constraints_is_not_success():
    """The check behind every statics success: an answer off the constraints is refused."""
    from optkin.statics import core

    m = M.rpr3(BASE, PLAT)
    sm = statics.static_model(m, optkin.forward(m, [0.5] * 3))
    lo, hi = -np.ones(3), np.ones(3)
    lam = np.array([0.3, -0.2, 0.1])
    F = sm.A.T @ lam
    assert core._violation(sm, lam, F, lo, hi) < 1e-12
    assert core._violation(sm, lam * (1 + 1e-20) + 1e-3, F, lo, hi) > 1e-6
    assert core._checked("optimal", "ok", 1e-3)[0] == "error"
    assert core._checked("optimal", "ok", 1e-9)[0] == "optimal"


HISTORY = """
    import json, warnings
    warnings.filterwarnings("ignore")
    import optkin
    from optkin import mechanisms as M, statics
    m = M.rpr3({BASE!r}, {PLAT!r})
    ra = optkin.forward(m, [0.5] * 3)
    rb = optkin.forward(m, [0.6, 0.55, 0.5])

    def A():
        return [statics.distribute(m, ra, [1.0, 2.0, 0.3]).tau.tobytes().hex(),
                statics.capability(m, ra, 1.0).max.tobytes().hex(),
                statics.distribute(m, ra, [1.0, 2.0, 0.3], limits=10, norm="inf").tau
                .tobytes().hex(),
                repr(statics.feasible(m, ra, [0.1, 0.1, 0.01], 1.0).margin)]

    def B():
        return [statics.distribute(m, rb, [-3.0, 0.5, 1.0]).tau.tobytes().hex(),
                statics.capability(m, rb, 2.0).max.tobytes().hex(),
                statics.distribute(m, rb, [-3.0, 0.5, 1.0], limits=10, norm="inf").tau
                .tobytes().hex(),
                repr(statics.feasible(m, rb, [0.3, 0.1, 0.01], 1.0).margin)]

    {body}
"""


def test_statics_numbers_do_not_depend_on_what_ran_before():
    """A, then B, then A again give bitwise the same A; B after A is bitwise B in a fresh
    process (the cached cvxpy problems used to warm-start from the previous solve)."""
    after = last_json(run_python(HISTORY.format(
        BASE=BASE, PLAT=PLAT, body="a1 = A(); b = B(); a2 = A(); print(json.dumps([a1, b, a2]))")))
    fresh = last_json(run_python(HISTORY.format(
        BASE=BASE, PLAT=PLAT, body="print(json.dumps(B()))")))
    a1, b, a2 = after
    assert a1 == a2
    assert b == fresh


# ----------------------------------------------------------------------------- paths


def test_mechanism_errors_carry_their_path_and_keep_it_through_pickling():
    cases = [
        (lambda: Mechanism.from_khalil(row(0.5) + [{"a": 1, "sigma": 0, "d": "1/0"}]),
         ("rows", 1, "d")),
        (lambda: Mechanism.from_khalil(row(0.5), params={"p": "x"}), ("params", "p")),
        (lambda: Mechanism.from_khalil([dict(row(0.5)[0], sigma=7)]), ("rows", 0, "sigma")),
        (lambda: Mechanism.from_khalil(row(0.5), home=[np.nan]), ("home",)),
        (lambda: Mechanism.from_khalil(row(0.5), end_effector=9), ("end_effector",)),
        (lambda: Mechanism.from_legs([{"type": "RPR", "base": [0, 0], "platform": [0, 0]},
                                      {"type": "RPR", "base": [0, "x"], "platform": [0, 0]},
                                      {"type": "RPR", "base": [1, 0], "platform": [0, 1]}]),
         ("legs", 1, "base")),
        (lambda: M.rpr3(BASE, [[0, 0], [1, 0]]), ("platform",)),
        (lambda: M.five_bar(1, 1, -1, 1, 1), ("L2",)),
        (lambda: optkin.forward(M.rpr3(BASE, PLAT), [0.5, -0.5, 0.5]), ("qa", 1)),
    ]
    for call, path in cases:
        with pytest.raises(MechanismError) as e:
            call()
        assert e.value.path == path, (str(e.value), e.value.path)
        again = pickle.loads(pickle.dumps(e.value))
        assert type(again) is type(e.value) and again.path == path and str(again) == str(e.value)
    assert MechanismError("x").path == ()


@pytest.mark.parametrize("name", ["optkin.numeric", "optkin.errors"])
def test_docstring_examples_of_the_new_modules(name):
    mod = importlib.import_module(name)
    failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert tried > 0 and failures == 0


def test_an_odd_option_name_is_named_in_the_error():
    """An option name Python accepts but no function has (``**{"10": 1}``) is optkin's
    error naming it, never a crash while building the message."""
    with pytest.raises(MechanismError, match=r"forward: unknown option '10'; known options"):
        optkin.forward(M.four_bar(1, 2, 2, 2.5), [1.0], **{"10": 1})
