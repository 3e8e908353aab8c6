"""The option convention of aspects, workspace, singular_curves, dof and jacobians:
``f(mech, <configuration>, **options)`` with the options merged over a documented
``*_DEFAULTS`` by :func:`optkin.solvers.common.merge_options` (an unknown name is a
MechanismError naming the function and the option; a former tuning parameter given by
position is a TypeError; by keyword it still works)."""

from __future__ import annotations

import importlib
import inspect

import numpy as np
import pytest

import optkin
from optkin import MechanismError
from optkin import mechanisms as M
from optkin.analysis import continuation, mobility, velocity
from optkin.analysis.aspects import ASPECTS_DEFAULTS
from optkin.analysis.continuation import SINGULAR_CURVES_DEFAULTS
from optkin.analysis.mobility import DOF_DEFAULTS
from optkin.analysis.velocity import JACOBIANS_DEFAULTS

aspects_module = importlib.import_module("optkin.analysis.aspects")  # (the package's
# attribute ``aspects`` is the function)

FIVE = M.five_bar(9, 8, 5, 5, 8)
FOUR = M.four_bar(4, 4, 2, 2)


@pytest.fixture(scope="module")
def closed():
    r = optkin.forward(FIVE, [1.0, 2.0])
    assert r.success
    return r


#: function name -> (function, its defaults, the module exporting them, the arguments
#: before the options, the former tuning parameters in their old positional order)
CASES = {
    "aspects": (optkin.aspects, ASPECTS_DEFAULTS, aspects_module, (FIVE, None),
                ("limits", "bounds", "grid", "qa_grid", "step")),
    "workspace": (optkin.workspace, ASPECTS_DEFAULTS, aspects_module, (FIVE, None),
                  ("limits", "bounds", "grid", "step", "qa_grid")),
    "singular_curves": (optkin.singular_curves, SINGULAR_CURVES_DEFAULTS, continuation,
                        (FIVE, "joint", "parallel", None),
                        ("bounds", "grid", "limits", "step", "tol", "max_steps", "cusps")),
    "dof": (optkin.dof, DOF_DEFAULTS, mobility, (FOUR,), ("samples", "seed", "rtol")),
    "jacobians": (optkin.jacobians, JACOBIANS_DEFAULTS, velocity, (FIVE, None), ("tol",)),
}


def _args(name, closed):
    args = CASES[name][3]
    return tuple(closed if (name == "jacobians" and a is None) else a for a in args)


@pytest.mark.parametrize("name", sorted(CASES))
def test_signature_and_exported_defaults(name):
    fn, defaults, module, args, former = CASES[name]
    params = list(inspect.signature(fn).parameters.values())
    assert params[-1].kind is inspect.Parameter.VAR_KEYWORD and params[-1].name == "options"
    assert len(params) == len(args) + 1  # the configuration arguments, then **options
    assert set(defaults) == set(former)
    dict_name = next(k for k in module.__all__ if k.endswith("_DEFAULTS"))
    assert getattr(module, dict_name) is defaults
    assert f":data:`{dict_name}`" in fn.__doc__ and "Other Parameters" in fn.__doc__


@pytest.mark.parametrize("name", sorted(CASES))
def test_an_unknown_option_names_the_function_and_the_option(name, closed):
    fn = CASES[name][0]
    with pytest.raises(MechanismError, match=rf"^{name}: unknown option 'no_such_knob'; known "
                                             r"options: \[") as e:
        fn(*_args(name, closed), no_such_knob=1)
    assert e.value.path == ("options", "no_such_knob")
    with pytest.raises(MechanismError, match=rf"^{name}: unknown option 'tolerance' "
                                             r"\(did you mean 'tol'\?\)"
                       if "tol" in CASES[name][1] else rf"^{name}: unknown option"):
        fn(*_args(name, closed), tolerance=1e-9)


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_former_tuning_parameter_by_position_is_a_type_error(name, closed):
    fn, defaults, _, _, former = CASES[name]
    with pytest.raises(TypeError):
        fn(*_args(name, closed), defaults[former[0]])


def test_dof_options_by_keyword():
    assert optkin.dof(FOUR).samples == DOF_DEFAULTS["samples"] == 5
    r = optkin.dof(FOUR, samples=2, seed=3, rtol=1e-6)
    assert r.samples == 2 and r.mobility == 1 and r.agree
    a, b = optkin.dof(FOUR, samples=1, seed=7), optkin.dof(FOUR, samples=1, seed=7)
    assert a.residual == b.residual  # the seed makes a run reproducible
    assert optkin.dof(FOUR, samples=np.int64(2)).samples == 2
    with pytest.raises(MechanismError, match=r"^dof: option samples must be an integer >= 1 "
                                             r"and <= 1000 \(default 5\), got 0") as e:
        optkin.dof(FOUR, samples=0)
    assert e.value.path == ("options", "samples")
    with pytest.raises(MechanismError, match=r"^dof: option seed must be"):
        optkin.dof(FOUR, seed=-1)


def test_jacobians_tol_by_keyword(closed):
    q = np.asarray(closed.q, dtype=float) + 1e-4  # off the closure by about 1e-4
    assert optkin.jacobians(FIVE, closed).success
    assert not optkin.jacobians(FIVE, q).success  # the default tol 1e-8
    assert optkin.jacobians(FIVE, q, tol=1.0).success
    with pytest.raises(MechanismError, match=r"^jacobians: option tol must be a number > 0 "
                                             r"\(default 1e-08\), got 0"):
        optkin.jacobians(FIVE, closed, tol=0)


def test_singular_curves_options_by_keyword():
    r = optkin.singular_curves(FIVE, bounds=[[0.0, 3.0], [0.0, 3.0]], grid=8, step=0.2)
    assert r.success and np.allclose(r.bounds, [[0.0, 3.0], [0.0, 3.0]])
    with pytest.raises(MechanismError, match=r"^singular_curves: option tol must be"):
        optkin.singular_curves(FIVE, tol=-1.0)
    with pytest.raises(MechanismError, match=r"^singular_curves: option step: expected a number between"):
        optkin.singular_curves(FIVE, step=5.0)  # the function's own range check


def test_aspects_and_workspace_options_by_keyword():
    a = optkin.aspects(FIVE, qa_grid=16)
    assert a.success and a.qa_grid[0].shape == (16,)
    assert [a.counts[w] for w in a.working_modes] == [2, 3, 3, 2]
    w = optkin.workspace(FIVE, qa_grid=16)
    assert w.success and w.qa_grid[0].shape == (16,) and round(w.area, 1) == 245.1
    with pytest.raises(MechanismError, match=r"^workspace: option qa_grid: expected an integer >= 2, got 1"):
        optkin.workspace(FIVE, qa_grid=1)
    with pytest.raises(MechanismError, match=r"^aspects: option qa_grid must be"):
        optkin.aspects(FIVE, qa_grid="fine")


def test_problem_files_accept_the_same_options():
    """The task kinds accept exactly the options they did before (the defaults' keys less
    the ones the task sets from its own fields)."""
    from optkin.problems.tasks import OPTIONS

    assert OPTIONS["jacobians"].allowed() == ["tol"]
    assert OPTIONS["dof"].allowed() == ["rtol", "samples", "seed"]
    assert OPTIONS["singular_curves"].allowed() == ["cusps", "max_steps", "step", "tol"]
    assert OPTIONS["aspects"].allowed() == OPTIONS["workspace"].allowed() == ["qa_grid", "step"]
