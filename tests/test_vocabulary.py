"""One vocabulary across optkin's public results (issue 15, part 3).

Every public function is driven once on a small mechanism (the 3-RPR of the README, the
five-bar of Chablat and Wenger, a four-bar), failures included, and every result it
returns must have ``success`` (bool), ``status`` (one word of ``optkin.results.STATUS``),
a non-empty ``message`` and ``to_dict()`` that strict ``json.dumps`` accepts. The result
classes are enumerated from ``optkin.__all__``, ``optkin.statics.__all__`` and
``optkin.design.__all__``: a new public class must either be covered here or be listed
among the classes that are not results, and a new public function must be driven here.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import json
import pathlib
import re
import warnings
from typing import Any

import numpy as np
import pytest

import optkin
from optkin import design, results, statics
from optkin import mechanisms as M
from optkin.errors import OptkinError

ROOT = pathlib.Path(optkin.__file__).parent
MODULES = (optkin, statics, design)

#: Public classes that are not results, and why.
NOT_RESULTS = {
    "Leg": "a description", "Mechanism": "a description",
    "OptkinError": "an error", "MechanismError": "an error", "ProblemFileError": "an error",
    "SolverError": "an error", "StaticsError": "an error",
    "SolverStats": "the solver statistics inside results (stats.raw_status)",
    "StaticModel": "the static model at a configuration, an input of the statics analyses",
    "Family": "a design family", "ForceCapability": "a design measure",
    "LegStroke": "a design measure", "Aspect": "a design region", "Box": "a design region",
    "Disc": "a design region", "GCI": "a design measure", "AspectArea": "a design measure",
    "Constraint": "a design constraint", "Dimension": "a design measure",
    "JointRange": "a design measure", "LargestInscribed": "a design measure",
    "Maximize": "a design objective", "Minimize": "a design objective",
    "Measure": "a design measure", "MinConditioning": "a design measure",
}

#: What the public functions that return no result return.
NOT_RESULT_RETURNS = {
    "get_model": "optkin.model.Model", "box": "numpy array", "limits_of": "tuple of arrays",
    "wrench_names": "tuple of str", "static_model": "StaticModel",
    "conditioning": "numpy array", "singular_values": "numpy array",
    "plot_capability": "matplotlib Figure", "plot_workspace": "matplotlib Figure",
}


def _public(kind: str) -> dict[str, Any]:
    """Public classes (kind "class") or functions (kind "function") by qualified name."""
    out = {}
    for mod in MODULES:
        for name in mod.__all__:
            obj = getattr(mod, name)
            if inspect.ismodule(obj):
                continue
            if (kind == "class") == inspect.isclass(obj) and (inspect.isclass(obj) or callable(obj)):
                out[f"{mod.__name__}.{name}"] = obj
    return out


CLASSES = _public("class")
FUNCTIONS = _public("function")
RESULT_CLASSES = {k: c for k, c in CLASSES.items() if k.rsplit(".", 1)[1] not in NOT_RESULTS}


# ------------------------------------------------------------------------------ the walk
@dataclasses.dataclass
class Walk:
    results: list[tuple[str, Any]]    # (call, result)
    called: set[str]                  # qualified names of the public functions driven
    other: dict[str, Any]             # non-result returns by function name


@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> Walk:
    out: list[tuple[str, Any]] = []
    called: set[str] = set()
    other: dict[str, Any] = {}

    def call(qualname: str, label: str, *args: Any, **kw: Any) -> Any:
        mod, _, name = qualname.rpartition(".")
        fn = {"optkin": optkin, "optkin.statics": statics, "optkin.design": design}[mod]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = getattr(fn, name)(*args, **kw)
        called.add(qualname)
        items = res if isinstance(res, list) else [res]
        if name in NOT_RESULT_RETURNS:
            other[name] = res
        else:
            out.extend((f"{name}({label})", r) for r in items)
        return res

    rpr = M.rpr3(base=[[0, 0], [1, 0], [0.5, 0.9]],
                 platform=[[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    five = M.five_bar(9, 8, 5, 5, 8)
    four = M.four_bar(4, 4, 2, 2)
    small = M.five_bar(1.6, 1.2, 1.0, 1.0, 1.2)
    ok = "optkin"

    # kinematics
    post = call(f"{ok}.inverse", "3-RPR", rpr, [0.45, 0.35, 0.1])
    call(f"{ok}.inverse", "out of reach", five, [0.0, 100.0])
    r = call(f"{ok}.forward", "3-RPR", rpr, post[0].qa, guess=[0.4, 0.3, 0.0])
    call(f"{ok}.forward", "legs that cannot close", rpr, [5.0, 5.0, 0.01])
    call(f"{ok}.assembly_modes", "3-RPR", rpr, r.qa)
    call(f"{ok}.assembly_modes", "five-bar, no mode", five, [np.pi, 0.0], method="multistart",
         time_limit=2)
    path = np.linspace(r.qa, r.qa * 1.02, 5)
    call(f"{ok}.track", "3-RPR", rpr, path, guess=r)
    call(f"{ok}.forward_batch", "3-RPR", rpr, path, guess=r)
    call(f"{ok}.forward_batch", "rows out of reach", rpr, np.array([r.qa, [5.0, 5.0, 0.01]]),
         guess=r)
    call(f"{ok}.certify", "3-RPR", rpr, r)
    call(f"{ok}.working_modes", "five-bar", five, pose=[0.0, 9.0])
    call(f"{ok}.working_modes", "five-bar, pose out of reach", five, pose=[0.0, 100.0])
    call(f"{ok}.get_model", "four-bar", four)
    # velocity, mobility, singularities
    call(f"{ok}.jacobians", "3-RPR", rpr, r)
    call(f"{ok}.jacobians", "not closed", rpr, np.r_[r.q[:-1], r.q[-1] + 0.1])
    call(f"{ok}.classify", "3-RPR", rpr, r)
    call(f"{ok}.dof", "four-bar", four)
    call(f"{ok}.singular_curves", "five-bar", five)
    call(f"{ok}.aspects", "five-bar", five)
    call(f"{ok}.workspace", "five-bar", five)
    call(f"{ok}.plot_singularity_map", "five-bar", five, np.linspace(-2, 2, 2),
         np.linspace(6, 10, 2), str(tmp_path_factory.mktemp("map") / "map.png"))
    call(f"{ok}.singularity_map", "five-bar", five, np.linspace(-2, 2, 2), np.linspace(6, 10, 2))
    call(f"{ok}.aspects3d", "3-RPR", rpr, slices=4, time_limit=2)
    call(f"{ok}.singular_surfaces", "3-RPR", rpr, slices=4, time_limit=2)
    call(f"{ok}.cusp_curves", "3-RPR", rpr, slices=2, time_limit=2)
    call(f"{ok}.is_cuspidal", "3-RPR, stopped", rpr, sections=[1.0], angles=1, time_limit=1)
    call(f"{ok}.mode_change_path", "3-RPR, other aspect", rpr, r.qa, 0, 1, time_limit=2)
    cusp = M.rpr3([[0, 0], [15.91, 0], [0, 10]], [[0, 0], [17.04, 0], [13.2364, 16.0967]])
    call(f"{ok}.mode_change_path", "cuspidal 3-RPR", cusp, [14.98, 13.85, 6.77], 1, 2)
    # statics
    st = "optkin.statics"
    wset = {"lower": [0, 0, -0.1], "upper": [0, 0, 0.1]}
    cap = call(f"{st}.capability", "3-RPR", rpr, r, 1.0)
    call(f"{st}.capability_many", "3-RPR", rpr, [r, r], 1.0, chunk=2)
    call(f"{st}.capability_polygon", "3-RPR", rpr, r, 1.0, n=8)
    call(f"{st}.polytope", "3-RPR", rpr, r, 1.0)
    call(f"{st}.feasible", "3-RPR", rpr, r, wset, 1.0)
    call(f"{st}.feasible", "3-RPR, a set too large", rpr, r,
         {"lower": [0, 0, -100], "upper": [0, 0, 100]}, 1.0)
    call(f"{st}.distribute", "3-RPR", rpr, r, [0, -1, 0], 10.0)
    call(f"{st}.distribute", "3-RPR, beyond the limits", rpr, r, [0, -1000, 0], 1.0)
    ws = call(f"{st}.wrench_feasible_workspace", "3-RPR", rpr, wset, 1.0, grid=3)
    call(f"{st}.plot_capability", "3-RPR", cap)
    call(f"{st}.plot_workspace", "3-RPR", ws)
    sm = call(f"{st}.static_model", "3-RPR", rpr, r)
    call(f"{st}.limits_of", "3-RPR", 1.0, sm)
    call(f"{st}.box", "", [0, 0, -1], [0, 0, 1])
    call(f"{st}.wrench_names", "3-RPR", rpr)
    # design
    dz = "optkin.design"
    outward = (1, -1)  # the working mode with both elbows outward
    call(f"{dz}.gci", "five-bar", small, design.Disc((0.8, 1.3), 0.3), mode=(1, 1), order=4)
    call(f"{dz}.area", "five-bar", small, design.Disc((0.8, 1.3), 0.3), mode=(1, 1), order=4)
    call(f"{dz}.largest_inscribed", "five-bar", small, mode=(1, 1), centre=(0.8, 1.3), rays=32,
         steps=16)
    call(f"{dz}.conditioning", "five-bar", small, [[0.8, 1.3]], mode=(1, 1))
    call(f"{dz}.singular_values", "five-bar", small, [[0.8, 1.3]], mode=(1, 1))

    def fam(a: float, b: float) -> Any:
        return M.five_bar(1.0, a, b, b, a)

    call(f"{dz}.atlas", "five-bar family", fam, {"a": (0.6, 1.4), "b": (0.6, 1.8)},
         {"GCI": design.GCI(design.Disc((0.5, 1.2), 0.2), outward)}, n=3)
    call(f"{dz}.optimize", "five-bar family", fam, {"a": (0.5, 1.8), "b": (0.5, 1.8)},
         design.Maximize(design.GCI(design.Disc((0.5, 1.4), 0.3), outward)), maxiter=1, popsize=4,
         method="global", time_limit=5)
    return Walk(out, called, other)


def check_result(res: Any, where: str) -> None:
    """The contract of every public result."""
    assert type(res.success) is bool, where
    assert res.status in results.STATUS, (where, res.status)
    assert isinstance(res.message, str) and res.message.strip(), where
    if res.success:
        assert res.status in results.ANSWERED, (where, res.status)
    if res.status in results.LIMIT_REACHED + results.FAILURE:
        assert not res.success, where
    if res.status == results.OPTIMAL:
        assert res.success, (where, res.message)
    d = res.to_dict()
    text = json.dumps(d, allow_nan=False)  # no NaN, no inf, nothing but JSON data
    assert json.loads(text) == d, where
    assert d["success"] is res.success and d["status"] == res.status, where
    assert d["message"] == res.message, where


# ------------------------------------------------------------------------------ the tests
def test_the_status_vocabulary_and_its_groups():
    S = results
    assert S.STATUS == (S.OPTIMAL, S.INACCURATE, S.INFEASIBLE, S.UNBOUNDED, S.SINGULAR,
                        S.ITERATION_LIMIT, S.TIME_LIMIT, S.MEMORY_LIMIT, S.ERROR)
    assert len(set(S.STATUS)) == len(S.STATUS)
    groups = (S.SOLUTION_PRESENT, S.INF_OR_UNB, S.LIMIT_REACHED, S.FAILURE)
    assert sorted(s for g in groups for s in g) == sorted(set(S.STATUS) - {S.SINGULAR})
    assert set(S.ANSWERED) == set(S.SOLUTION_PRESENT + S.INF_OR_UNB + (S.SINGULAR,))
    # solvers' words are translated into the vocabulary (and kept as stats.raw_status)
    from optkin.statics.problems import STATUS_MAP

    assert set(S._IPOPT_STATUS_MAP.values()) <= set(S.STATUS)
    assert S.ipopt_status("Maximum_CpuTime_Exceeded") == S.TIME_LIMIT
    assert S.ipopt_status("something new") == S.ERROR
    assert set(STATUS_MAP.values()) <= set(S.STATUS)


def test_every_public_class_is_a_result_or_said_not_to_be():
    names = {k.rsplit(".", 1)[1] for k in CLASSES}
    assert not set(NOT_RESULTS) - names, "listed but no longer public"
    for qualname, cls in RESULT_CLASSES.items():
        fields = {f.name for f in dataclasses.fields(cls)} if dataclasses.is_dataclass(cls) \
            else set()
        for attr in results.RESULT_ATTRIBUTES:
            assert attr in fields or hasattr(cls, attr), f"{qualname} has no {attr}"
        assert callable(cls.to_dict), qualname


def test_every_result_of_every_public_function_keeps_the_contract(walk):
    assert walk.results
    for where, res in walk.results:
        check_result(res, where)


def test_every_solution_set_carries_typed_statistics(walk):
    """``SolutionSet.stats`` is a typed record (a frozen dataclass of plain fields) from
    every producer, and its ``to_dict`` is what ``SolutionSet.to_dict`` reports."""
    sets = [(w, r) for w, r in walk.results if isinstance(r, optkin.SolutionSet)]
    assert {w.split("(")[0] for w, _ in sets} >= {"assembly_modes", "inverse", "track"}
    for where, s in sets:
        assert type(s.stats) in (results.EnumerationStats, results.TrackStats), where
        assert dataclasses.is_dataclass(s.stats) and s.stats.__dataclass_params__.frozen
        d = s.to_dict()
        assert d["stats"] == json.loads(json.dumps(s.stats.to_dict())), where
        assert d["complete"] is s.complete is bool(s.stats.complete), where


def test_every_public_function_is_driven_and_every_result_class_met(walk):
    assert set(FUNCTIONS) - walk.called == set(), "public functions not driven here"
    met = {type(r) for _, r in walk.results}
    missing = [k for k, c in RESULT_CLASSES.items() if c not in met]
    assert not missing, f"result classes no call returned: {missing}"
    # every function that returns no result is listed with what it returns
    assert set(walk.other) == set(NOT_RESULT_RETURNS)
    for name in walk.other:
        assert getattr(walk.other[name], "status", None) is None, name


def test_failures_are_results_in_the_vocabulary(walk):
    got = dict(walk.results)
    r = got["forward(legs that cannot close)"]
    assert not r.success and r.status == "infeasible" and r.stats.raw_status
    inv = got["inverse(out of reach)"]
    assert len(inv) == 0 and not inv.success and inv.status == "infeasible"
    assert "cannot reach" in inv.message
    am = got["assembly_modes(five-bar, no mode)"]
    assert not am.success and am.status in ("infeasible", "time_limit")
    b = got["forward_batch(rows out of reach)"]
    assert not b.success and b.closed.tolist() == [True, False] and b.status == "infeasible"
    d = got["distribute(3-RPR, beyond the limits)"]
    assert not d.success and d.status == "infeasible" and d.stats.raw_status == "infeasible"
    f = got["feasible(3-RPR, a set too large)"]  # a "no" is an answer
    assert f.success and not f.feasible and f.status == "optimal"
    c = got["is_cuspidal(3-RPR, stopped)"]
    assert not c.success and c.cuspidal is None and c.status in ("time_limit", "infeasible")
    mc = got["mode_change_path(3-RPR, other aspect)"]
    assert not mc.success and mc.status == "infeasible"
    wm = got["working_modes(five-bar, pose out of reach)"]
    assert wm.success and wm.existing == {} and "0 reach the pose" in wm.message
    assert got["jacobians(not closed)"].status == "infeasible"


def test_seed_is_accepted_by_keyword_everywhere():
    """``seed`` is a keyword argument or an option (``*_DEFAULTS``) of every public function
    that has one, and the two kinds agree on the keyword."""
    from optkin.analysis.mobility import DOF_DEFAULTS
    from optkin.solvers.enumerate import ASSEMBLY_DEFAULTS
    from optkin.solvers.inverse import INVERSE_DEFAULTS

    with_seed = [k for k, f in FUNCTIONS.items() if "seed" in inspect.signature(f).parameters]
    assert {"optkin.design.optimize"} <= set(with_seed)
    for k in with_seed:
        p = inspect.signature(FUNCTIONS[k]).parameters["seed"]
        assert p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY), k
    assert "seed" in INVERSE_DEFAULTS and "seed" in ASSEMBLY_DEFAULTS and "seed" in DOF_DEFAULTS
    m = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    a = optkin.assembly_modes(m, [1.2, 1.9], seed=3, method="multistart")
    b = optkin.assembly_modes(m, [1.2, 1.9], seed=4, method="multistart")
    assert (a.seed, b.seed) == (3, 4) and len(a) == len(b)
    with pytest.raises(TypeError):
        optkin.assembly_modes(m, [1.2, 1.9], 3)  # an option, never positional
    assert optkin.inverse(M.sr400(), np.eye(4) + np.c_[np.zeros((4, 3)), [0.5, 0, 0.5, 0]],
                          seed=3, starts=8).seed == 3


#: Public functions of the top-level namespace that take a mechanism and no tuning options,
#: with why: their keyword arguments say what is asked, not how to compute it
NO_OPTIONS = {
    "get_model": "the mechanism only",
    "working_modes": "the pose only",
    "certify": "the results to certify only",
    "singularity_map": "the grid and the section (axes, fixed, working_mode, guess)",
    "plot_singularity_map": "a picture: the map's arguments and the drawing's (ax, path, ...)",
}


def test_one_option_convention():
    """Every solver and analysis of the top-level namespace is ``f(mech, <what is asked>,
    **options)``: its tuning knobs are options over a documented ``*_DEFAULTS`` (on the
    options page), none of them positional, and an unknown name is an error naming it
    before any work."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("_options_page",
                                                  ROOT.parent / "docs" / "_options_page.py")
    page = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(page)
    configured = {f.strip().removeprefix("optkin.") for *_, fns in page.TABLES
                  for f in fns.split(",")}
    m = M.five_bar(2.0, 1.5, 2.0, 2.0, 1.5)
    for name in optkin.__all__:
        f = getattr(optkin, name)
        if not inspect.isfunction(f) or name in NO_OPTIONS:
            continue
        params = list(inspect.signature(f).parameters.values())
        assert params[0].name == "mech", name
        assert params[-1].kind is params[-1].VAR_KEYWORD, f"{name} takes no **options"
        assert name in configured, f"{name}'s options are not on the options page"
        # every option is a keyword: a call with one more positional argument than the
        # configuration takes is a TypeError
        n_pos = sum(p.kind is p.POSITIONAL_OR_KEYWORD for p in params)
        with pytest.raises(TypeError):
            f(*([m] + [None] * n_pos))
        with pytest.raises(optkin.MechanismError, match=rf"{name}: unknown option 'bogus'"):
            required = [None] * sum(p.default is p.empty and p.kind is p.POSITIONAL_OR_KEYWORD
                                    for p in params[1:])
            f(m, *required, bogus=1)
    for name in NO_OPTIONS:
        assert not any(p.kind is p.VAR_KEYWORD
                       for p in inspect.signature(getattr(optkin, name)).parameters.values()
                       ) or name == "plot_singularity_map", name


def test_unknown_options_name_the_allowed_ones():
    m = M.four_bar(1.0, 2.0, 2.0, 2.5)
    with pytest.raises(optkin.MechanismError,
                       match=r"^forward: unknown option 'tolerance' \(did you mean 'tol'\?\); "
                             r"known options: \['max_iter', 'method', 'polish', 'tol'\]"):
        optkin.forward(m, [1.0], tolerance=1e-9)
    with pytest.raises(optkin.MechanismError, match=r"^inverse: unknown option 'budget'; known"):
        optkin.inverse(m, [1.0, 1.0, 0.0], budget=9)


def test_numbers_and_mechanisms_are_checked_in_one_place():
    """One "expected an optkin Mechanism" and one number validator (optkin._checks)."""
    from optkin._checks import check_number, check_option

    text = {p: p.read_text() for p in ROOT.rglob("*.py")}
    said = [p.relative_to(ROOT) for p, t in text.items() if "expected an optkin Mechanism" in t]
    assert [str(p) for p in said] == ["_checks.py"]
    defs = re.compile(r"^def (_?jsonable|_j|to_jsonable|_json|_positive_option|_option_number|"
                      r"_positive_int|check_number|check_option|check_mechanism)\(", re.M)
    found = sorted((str(p.relative_to(ROOT)), m.group(1)) for p, t in text.items()
                   for m in defs.finditer(t) if p.name != "cli.py")  # cli: argparse types
    assert found == [("_checks.py", "check_mechanism"), ("_checks.py", "check_number"),
                     ("_checks.py", "check_option"), ("results.py", "jsonable")]
    with pytest.raises(optkin.MechanismError, match=r"^grid: expected an integer >= 2, got 1$"):
        check_number(1, "grid", integer=True, lo=2)
    with pytest.raises(optkin.MechanismError,
                       match=r"^f: option tol must be a finite number > 0 \(default 1e-10\), "
                             r"got inf$") as e:
        check_option({"tol": float("inf")}, "tol", "f", {"tol": 1e-10}, lo=0.0, lo_open=True)
    assert e.value.path == ("options", "tol")
    for name in ("forward", "inverse", "assembly_modes", "track", "jacobians", "classify",
                 "dof", "certify", "working_modes", "singular_curves", "aspects"):
        fn = getattr(optkin, name)
        nargs = sum(1 for p in inspect.signature(fn).parameters.values()
                    if p.default is p.empty and p.kind is p.POSITIONAL_OR_KEYWORD)
        with pytest.raises(optkin.MechanismError, match="expected an optkin Mechanism"):
            fn("five_bar", *[[1.0, 2.0]] * (nargs - 1))


def test_one_json_converter():
    from optkin.problems import runner, tasks

    assert tasks.jsonable is results.jsonable
    v = {"a": np.array([1.0, np.nan, np.inf]), "b": (np.int64(2), {3}), 4: pathlib.Path("x")}
    want = {"a": [1.0, None, None], "b": [2, [3]], "4": "x"}
    assert results.jsonable(v) == runner.clean_json(v) == want
    assert results.jsonable(float("-inf"), keep_nonfinite=True) == float("-inf")
    r = optkin.forward(M.four_bar(1.0, 2.0, 2.0, 2.5), [1.0])
    assert results.jsonable(r) == r.to_dict()
    assert isinstance(OptkinError("x"), Exception)


def test_every_picture_draws_into_the_callers_figure_and_writes_only_when_asked(
        walk, tmp_path, monkeypatch):
    """Each result with a ``plot`` (and the statics plots) takes ``ax=`` (or ``fig=`` for
    pictures of several panels), returns that Figure and writes no file; given a path it
    writes one and leaves no figure in pyplot."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.figure import Figure

    monkeypatch.chdir(tmp_path)
    plots: dict[type, Any] = {}
    for _, res in walk.results:
        if hasattr(res, "plot") and (type(res) not in plots or res.success):
            plots[type(res)] = res.plot
    for name in ("plot_capability", "plot_workspace"):
        fn = getattr(statics, name)
        res = walk.other[name]
        # the statics plots take the result they draw: drawn again from it
        source = [r for _, r in walk.results if type(r).__name__ == (
            "CapabilityResult" if name == "plot_capability" else "WorkspaceResult")][0]
        assert res is not None
        plots[fn] = functools.partial(fn, source)
    with_plot = {c for c in RESULT_CLASSES.values() if hasattr(c, "plot")}
    assert with_plot <= set(plots), f"results with a plot not drawn here: {with_plot - set(plots)}"
    assert len(plots) >= 12
    for key, plot in plots.items():
        label = getattr(key, "__name__", str(key))
        open_before = set(plt.get_fignums())
        probe = plot()  # a new Figure, in pyplot (for notebooks and plt.show())
        assert isinstance(probe, Figure), label
        three_d = any(getattr(a, "name", "") == "3d" for a in probe.axes)
        plt.close(probe)
        params = inspect.signature(getattr(key, "plot", plot)).parameters
        mine = Figure(layout="constrained")
        if "ax" in params or callable(key) and not inspect.isclass(key):
            ax = mine.add_subplot(projection="3d" if three_d else None)
            got = plot(ax=ax)
            assert ax in got.axes, label
        else:
            assert "fig" in params, f"{label}.plot takes neither ax= nor fig="
            got = plot(fig=mine)
            assert mine.axes, label
        assert got is mine, label
        assert not list(tmp_path.iterdir()), f"{label} wrote a file without a path"
        out = tmp_path / f"{label}.png"
        written = plot(path=str(out))
        assert isinstance(written, Figure) and out.stat().st_size > 1000, label
        assert set(plt.get_fignums()) == open_before, f"{label} left a pyplot figure"
        out.unlink()
