"""The 3-D analyses take their tuning knobs as options (optkin's convention):
``f(mech, <config>, **options)`` over a module-level ``*_DEFAULTS`` mapping, merged by
:func:`optkin.solvers.common.merge_options`.

Checked here without running any of the computations: an unknown option is refused by
name before any work (no model is built: ``get_model`` is replaced by a tripwire), and a
former tuning parameter given positionally is a TypeError.
"""

from __future__ import annotations

import time

import numpy as np
import pytest
from test_continuation import BASE3, PLAT3

import optkin
import optkin.solvers.common  # noqa: F401  (imported before the timed calls)
from optkin.analysis import aspects3d as aspects3d_mod
from optkin.analysis import cusps as cusps_mod
from optkin.analysis import surfaces as surfaces_mod

LIMITS = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
QA = np.array([14.98, 13.85146, 6.7713])  # tests/test_cusps.py

#: function name -> (module, its defaults dict, the config arguments after mech)
CASES = {
    "aspects3d": (aspects3d_mod, "ASPECTS3D_DEFAULTS", ()),
    "singular_surfaces": (surfaces_mod, "SINGULAR_SURFACES_DEFAULTS", ("task",)),
    "cusp_curves": (cusps_mod, "CUSP_CURVES_DEFAULTS", ()),
    "is_cuspidal": (cusps_mod, "IS_CUSPIDAL_DEFAULTS", ([14.98],)),
    "mode_change_path": (cusps_mod, "MODE_CHANGE_DEFAULTS", (QA, 1, 2)),
}

#: a misspelt option of each and the option it misspells
MISSPELT = {
    "aspects3d": ("slice", "slices"),
    "singular_surfaces": ("links", "link"),
    "cusp_curves": ("slop", "slope"),
    "is_cuspidal": ("angle", "angles"),
    "mode_change_path": ("dept", "depth"),
}

#: a valid value of the misspelt option (the call then goes on to build the model)
MEANT = {"aspects3d": 36, "singular_surfaces": 0.6, "cusp_curves": 4.0, "is_cuspidal": 8,
         "mode_change_path": 4}

#: a former tuning parameter given positionally (the first after the config arguments)
POSITIONAL = {
    "aspects3d": LIMITS,
    "singular_surfaces": LIMITS,
    "cusp_curves": LIMITS,
    "is_cuspidal": 0.5,  # radius
    "mode_change_path": 0.5,  # radius (keyword-only before too)
}


@pytest.fixture(scope="module")
def rpr():
    return optkin.mechanisms.rpr3(BASE3, PLAT3)


@pytest.fixture
def no_model(monkeypatch):
    """Building the model is the first heavy step of every one of them: trip on it."""
    def tripwire(*a, **k):
        raise AssertionError("get_model called: the options were not checked first")

    for mod, _, _ in CASES.values():
        monkeypatch.setattr(mod, "get_model", tripwire)


@pytest.mark.parametrize("name", sorted(CASES))
def test_an_unknown_option_is_refused_first(rpr, no_model, name):
    mod, _, args = CASES[name]
    bad, meant = MISSPELT[name]
    fn = getattr(optkin, name)
    assert fn is getattr(mod, name)
    t0 = time.perf_counter()
    with pytest.raises(optkin.MechanismError,
                       match=rf"^{name}: unknown option '{bad}' \(did you mean '{meant}'\?\)"
                             r"; known options: \[") as e:
        fn(rpr, *args, **{bad: 1})
    assert time.perf_counter() - t0 < 2.0  # a dict merge, not a computation
    assert e.value.path == ("options", bad)
    with pytest.raises(optkin.MechanismError, match=rf"^{name}: unknown option 'nonsense'"):
        fn(rpr, *args, nonsense=None)
    with pytest.raises(AssertionError, match="get_model called"):  # the tripwire is live
        fn(rpr, *args, **{meant: MEANT[name]})


@pytest.mark.parametrize("name", sorted(CASES))
def test_a_former_tuning_parameter_is_not_positional(rpr, no_model, name):
    _, _, args = CASES[name]
    with pytest.raises(TypeError):
        getattr(optkin, name)(rpr, *args, POSITIONAL[name])


@pytest.mark.parametrize("name", sorted(CASES))
def test_the_defaults_are_exported_and_the_signature_is_the_convention(name):
    import inspect

    mod, dname, args = CASES[name]
    defaults = getattr(mod, dname)
    assert dname in mod.__all__ and isinstance(defaults, dict) and defaults
    params = list(inspect.signature(getattr(mod, name)).parameters.values())
    assert params[-1].kind is inspect.Parameter.VAR_KEYWORD and params[-1].name == "options"
    assert len(params) == 2 + len(args)  # mech, the config arguments, **options
    assert not {p.name for p in params} & set(defaults)
