"""Regression tests of a user review: bad inputs, result objects, CLI edge cases.

Each test pins one defect found by calling the public API the way a new user would: bad
input raises a subclass of ValueError from :mod:`optkin.errors` naming the argument (never a
bare numpy / casadi exception), results print on one line and serialise to strict JSON.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

import optkin
from optkin import mechanisms as M
from optkin import statics
from optkin.cli import main
from optkin.errors import MechanismError, OptkinError, StaticsError

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"


@pytest.fixture(scope="module")
def rpr3():
    return M.rpr3(base=[[0, 0], [1, 0], [0.5, 0.9]],
                  platform=[[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])


@pytest.fixture(scope="module")
def closed(rpr3):
    """A closed 3-RPR configuration (inverse model, leg by leg)."""
    return optkin.inverse(rpr3, [0.45, 0.35, 0.1])[0]


@pytest.fixture(scope="module")
def unclosed(rpr3):
    """A forward solve that cannot close: leg 1 far longer than the others can follow."""
    r = optkin.forward(rpr3, [10.0, 0.1, 0.1])
    assert not r.success
    return r


def _one_line(obj, limit: int = 300) -> str:
    s = repr(obj)
    assert "\n" not in s and len(s) <= limit, s
    return s


# ---------------------------------------------------------------------------
# results serialise to strict JSON (NaN / inf -> None)
# ---------------------------------------------------------------------------


def test_kinresult_to_dict_turns_nan_entries_of_arrays_into_none():
    nan = float("nan")
    r = optkin.KinResult(
        q=np.array([nan, 1.0]), qa=np.array([1.0]), qp=np.array([nan]), qc=np.zeros(0),
        x=np.array([nan]), pose=np.full((4, 4), nan), success=False, status="error",
        message="diverged", residual=np.float64(nan), cond=np.float64(np.inf))
    d = r.to_dict()
    text = json.dumps(d, allow_nan=False)  # strict JSON: raises on NaN / Infinity
    assert d["q"] == [None, 1.0] and d["residual"] is None and d["cond"] is None
    assert json.loads(text)["pose"][0] == [None] * 4


def test_solution_set_to_dict_is_strict_json(rpr3, closed, unclosed):
    s = optkin.SolutionSet([closed, unclosed], kind="mixed", info={"p": np.float64(np.nan)})
    d = json.loads(json.dumps(s.to_dict(), allow_nan=False))
    assert d["count"] == 2 and d["info"]["p"] is None


# ---------------------------------------------------------------------------
# forward: options
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("opts, word", [
    ({"method": "newtn"}, "method"),
    ({"tol": "tight"}, "tol"),
    ({"tol": -1.0}, "tol"),
    ({"tol": float("nan")}, "tol"),
    ({"max_iter": -3}, "max_iter"),
    ({"polish": None}, "polish"),
])
def test_forward_rejects_bad_option_values_naming_the_option(rpr3, closed, opts, word):
    with pytest.raises(MechanismError, match=rf"forward: option {word} must be"):
        optkin.forward(rpr3, closed.qa, **opts)


def test_forward_accepts_good_option_values(rpr3, closed):
    r = optkin.forward(rpr3, closed.qa, guess=closed, tol=1e-9, max_iter=20, method="newton")
    assert r.success and r.residual <= 1e-9


# ---------------------------------------------------------------------------
# a mechanism of the wrong type
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("call", [
    lambda: optkin.dof("five_bar"),
    lambda: optkin.working_modes("five_bar"),
    lambda: optkin.aspects("five_bar"),
    lambda: optkin.workspace("five_bar"),
    lambda: optkin.plot_singularity_map("five_bar", [0, 1], [0, 1], "x.png"),
    lambda: statics.wrench_feasible_workspace("five_bar", [0, 0, 0], 1.0),
    lambda: statics.wrench_names("five_bar"),
], ids=["dof", "working_modes", "aspects", "workspace", "plot_singularity_map",
        "wrench_feasible_workspace", "wrench_names"])
def test_public_functions_reject_a_non_mechanism(call):
    with pytest.raises(MechanismError, match="expected an optkin Mechanism, got str"):
        call()


@pytest.mark.parametrize("kw, word", [
    ({"samples": 0}, "samples"),
    ({"samples": [1, 2]}, "samples"),
    ({"rtol": -1.0}, "rtol"),
])
def test_dof_rejects_bad_arguments(kw, word):
    with pytest.raises(MechanismError, match=rf"dof: option {word} must be"):
        optkin.dof(M.four_bar(4, 4, 2, 2), **kw)


# ---------------------------------------------------------------------------
# analyses: options, rates, grids
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("kw", [{"rtol": "small"}, {"rtol": 0.0},
                                {"second_order_tol": None}])
def test_classify_rejects_bad_option_values(rpr3, closed, kw):
    name = next(iter(kw))
    with pytest.raises(MechanismError, match=rf"classify: option {name} must be a (positive )?number"):
        optkin.classify(rpr3, closed, **kw)


def test_classify_report_of_an_unclosed_configuration_says_so(rpr3, unclosed):
    rep = optkin.classify(rpr3, unclosed)
    assert not rep.success
    assert "NOT CLOSED" in _one_line(rep)


@pytest.mark.parametrize("method, arg, name", [
    ("joint_rates", [1.0, 2.0], "qa_dot"),
    ("twist", [1.0, float("nan"), 0.0], "qa_dot"),
    ("accel_term", "fast", "qa_dot"),
])
def test_jacobian_rates_of_the_wrong_length_name_the_argument(rpr3, closed, method, arg, name):
    jac = optkin.jacobians(rpr3, closed)
    with pytest.raises(MechanismError, match=rf"{name}: expected 3 finite rates"):
        getattr(jac, method)(arg)


def test_jacobian_rates_still_match_finite_differences(rpr3, closed):
    """The checked joint_rates agree with a finite difference of two forward solves."""
    jac = optkin.jacobians(rpr3, closed)
    d = np.array([0.3, -0.2, 0.5])
    h = 1e-6
    qp = optkin.forward(rpr3, closed.qa + h * d, guess=closed).q
    qm = optkin.forward(rpr3, closed.qa - h * d, guess=closed).q
    assert np.allclose(jac.joint_rates(d), (qp - qm) / (2 * h), atol=1e-6)


@pytest.mark.parametrize("u, v", [([], [0, 1]), ([0.0, np.nan], [0, 1]), ([0, 1], "abc"),
                                  ([[0, 1], [2, 3]], [0, 1])])
def test_singularity_map_rejects_bad_grids(tmp_path, u, v):
    m = M.five_bar(1, 1, 1, 1, 1)
    with pytest.raises(MechanismError, match=r"^[uv]: expected a 1-D sequence"):
        optkin.plot_singularity_map(m, u, v, str(tmp_path / "m.png"))


def test_solution_set_closest_to_names_the_expected_length(closed):
    s = optkin.SolutionSet([closed])
    with pytest.raises(MechanismError, match=r"q: expected 9 joint values"):
        s.closest_to([1.0, 2.0])
    assert s.closest_to(closed.q) is closed


def test_draw_rejects_something_that_is_not_a_result(rpr3, tmp_path):
    with pytest.raises(MechanismError, match="results: expected a KinResult"):
        optkin.plot.draw(rpr3, "pose", str(tmp_path / "x.png"))


# ---------------------------------------------------------------------------
# statics
# ---------------------------------------------------------------------------


def test_statics_refuse_an_unclosed_configuration(rpr3, unclosed):
    for call in (lambda: statics.capability(rpr3, unclosed, limits=1.0),
                 lambda: statics.static_model(rpr3, unclosed),
                 lambda: statics.distribute(rpr3, unclosed, [0, -1, 0])):
        with pytest.raises(MechanismError, match="did not close the loops"):
            call()


@pytest.mark.parametrize("kw, word", [
    ({"fixed": {"zz": 1.0}}, "fixed"),
    ({"fixed": [0.5, 0.4, np.inf]}, "fixed"),
    ({"grid": "fine"}, "grid"),
    ({"grid": [3, 4, 5]}, "grid"),
    ({"bounds": "box"}, "bounds"),
    ({"bounds": [[0, np.nan], [0, 1]]}, "bounds"),
    ({"posture": -1}, "posture"),
    ({"working_mode": [1, 1]}, "working_mode"),
    ({"working_mode": [1, 1, 2]}, "working_mode"),
    ({"poses": "here"}, "poses"),
    ({"poses": [[np.nan, 0.0, 0.0]]}, "poses"),
])
def test_wrench_feasible_workspace_rejects_bad_arguments(rpr3, kw, word):
    kw = {"grid": 3, **kw}
    with pytest.raises(StaticsError, match=rf"^{word}: expected"):
        statics.wrench_feasible_workspace(rpr3, [0, -0.1, 0], 1.0, **kw)


def test_static_model_repr_is_one_line_and_wrench_checks_tau(rpr3, closed):
    sm = statics.static_model(rpr3, closed)
    assert "singularity='none'" in _one_line(sm)
    for tau in ("strong", [1.0, 2.0], [1.0, np.nan, 1.0]):
        with pytest.raises(StaticsError, match=r"tau: expected 3 finite actuator forces"):
            sm.wrench(tau)
    # F = G tau against virtual work: tau . qa_dot = F . t for t = J qa_dot (J = G^T)
    tau = np.array([0.3, -0.7, 0.2])
    qd = np.array([0.1, 0.4, -0.2])
    t = optkin.jacobians(rpr3, closed).J_a @ qd
    assert math.isclose(float(sm.wrench(tau) @ t), float(tau @ qd), rel_tol=1e-9, abs_tol=1e-12)


# ---------------------------------------------------------------------------
# printable results
# ---------------------------------------------------------------------------


def test_analysis_results_print_on_one_line():
    five = M.five_bar(9, 8, 5, 5, 8)
    curves = optkin.singular_curves(five)
    assert _one_line(curves).startswith("SingularCurves('five-bar'")
    asp = optkin.aspects(five)
    s = _one_line(asp)
    assert f"{len(asp)} aspect(s)" in s and "working mode(s)" in s
    ws = optkin.workspace(five)
    assert _one_line(ws).startswith("Workspace('five-bar'")
    for obj in (curves, asp, ws):
        json.dumps(obj.to_dict(), allow_nan=False)


def test_singularity_map_prints_on_one_line(tmp_path):
    m = M.five_bar(1, 1, 1, 1, 1)
    sm = optkin.plot_singularity_map(m, np.linspace(-0.5, 1.5, 4), np.linspace(0.2, 1.8, 3),
                                     str(tmp_path / "m.png"))
    assert "grid 3 x 4" in _one_line(sm)


# ---------------------------------------------------------------------------
# CLI: show uses the task's guess, and skips a task the library rejects
# ---------------------------------------------------------------------------


def _four_bar_modes(L1, L2, L3, L4, theta):
    """Rocker angles phi of both assembly modes: two circles intersected (MR 7.3)."""
    B = L1 * np.array([math.cos(theta), math.sin(theta)])
    D = np.array([L4, 0.0])
    d = float(np.linalg.norm(D - B))
    a = (L2**2 - L3**2 + d**2) / (2 * d)
    h = math.sqrt(L2**2 - a**2)
    u = (D - B) / d
    n = np.array([-u[1], u[0]])
    E = [B + a * u + h * n, B + a * u - h * n]
    return sorted(math.atan2(e[1], e[0] - L4) for e in E)


def test_show_draws_the_assembly_mode_the_guess_selects(tmp_path, monkeypatch):
    L = (1.0, 2.0, 2.0, 2.5)
    crossed, _open = _four_bar_modes(*L, 1.0)  # crossed mode: phi < 0 here
    toml = f"""schema_version = 1
name = "four_bar_crossed"
[mechanism]
type = "library"
name = "four_bar"
args = {{ L1 = {L[0]}, L2 = {L[1]}, L3 = {L[2]}, L4 = {L[3]} }}
[[task]]
kind = "forward"
qa = [1.0]
guess = {{ theta2 = -2.3, phi = -2.5, theta4 = -1.1 }}
"""
    f = tmp_path / "fb.toml"
    f.write_text(toml)
    drawn = []
    monkeypatch.setattr(optkin.plot, "draw", lambda mech, what, path, *a, **k: drawn.append(what))
    assert main(["show", str(f), "--out", str(tmp_path / "fb.png")]) == 0
    (res,) = drawn
    phi = dict(zip(res.joint_names, res.q))["phi"]
    assert math.isclose(phi, crossed, abs_tol=1e-8)


def test_show_skips_a_first_task_the_library_rejects(tmp_path, capsys):
    text = (PROBLEMS / "rpr3.toml").read_text()
    i = text.index("[[task]]")
    j = text.index("[[task]]", i + 1)
    inverse_task, forward_task = text[i:j], text[j:]
    start = forward_task.index("qa = [")
    end = forward_task.index("]", start)
    forward_task = forward_task[:start] + "qa = [-1.0, 2.0, 2.0" + forward_task[end:]
    f = tmp_path / "rpr3_bad_first.toml"
    f.write_text(text[:i] + forward_task + "\n" + inverse_task)
    png = tmp_path / "out.png"
    assert main(["show", str(f), "--out", str(png)]) == 0
    err = capsys.readouterr().err
    assert "task[0] (forward) skipped: qa[0] (L1.rho): a leg length must be positive" in err
    assert "Traceback" not in err
    assert png.read_bytes()[:4] == b"\x89PNG"


@pytest.mark.parametrize("setup", ["empty", "missing", "not_toml", "readme_only"])
@pytest.mark.parametrize("command", ["run", "validate", "show"])
def test_cli_odd_paths_exit_2_without_traceback(tmp_path, capsys, command, setup):
    p = tmp_path / setup
    if setup in ("empty", "readme_only"):
        p.mkdir()
        if setup == "readme_only":
            (p / "README.md").write_text("# notes\n")
    elif setup == "not_toml":
        p = tmp_path / "notes.txt"
        p.write_text("hello [[[\n")
    args = [command, str(p)] + (["--out", str(tmp_path / "res")] if command == "run" else [])
    assert main(args) == 2
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    assert out.err.strip()


def test_every_public_error_is_a_value_error():
    for cls in (MechanismError, StaticsError, optkin.ProblemFileError):
        assert issubclass(cls, ValueError) and issubclass(cls, OptkinError)


@pytest.mark.parametrize("n", [0, 2, "many", 7.5])
def test_capability_polygon_rejects_a_bad_number_of_directions(rpr3, closed, n):
    with pytest.raises(StaticsError, match=r"^n: expected an integer number of directions"):
        statics.capability_polygon(rpr3, closed, 1.0, n=n)


def test_capability_polygon_at_three_directions_matches_virtual_work(rpr3, closed):
    """|tau_i| <= 1 and tau = J_a^T F (virtual work): max s along d is 1 / |J_a^T d|_inf."""
    poly = statics.capability_polygon(rpr3, closed, 1.0, n=3)
    J = optkin.jacobians(rpr3, closed).J_a
    th = np.linspace(0, 2 * np.pi, 3, endpoint=False)
    D = np.column_stack([np.cos(th), np.sin(th), np.zeros(3)])
    expected = [1.0 / np.max(np.abs(J.T @ d)) for d in D]
    assert poly.success and np.allclose(poly.max, expected, rtol=1e-6)


# ---------------------------------------------------------------------------
# option values: numbers where numbers are expected
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("call, where, name", [
    (lambda m, s: optkin.assembly_modes(m, s.qa, tol="tight"), "assembly_modes", "tol"),
    (lambda m, s: optkin.assembly_modes(m, s.qa, time_limit=-1), "assembly_modes", "time_limit"),
    (lambda m, s: optkin.assembly_modes(m, s.qa, target="low"), "assembly_modes", "target"),
    (lambda m, s: optkin.track(m, [s.qa, s.qa * 1.01], guess=s, max_iter="8"), "track",
     "max_iter"),
    (lambda m, s: optkin.track(m, [s.qa, s.qa * 1.01], guess=s, cond_max=np.nan), "track",
     "cond_max"),
    (lambda m, s: optkin.inverse(m, [0.45, 0.35, 0.1], tol=-1e-9), "inverse", "tol"),
    (lambda m, s: statics.capability(m, s, 1.0, dir_tol="x"), "capability", "dir_tol"),
    (lambda m, s: statics.distribute(m, s, [0, -1, 0], sing_tol=-1), "distribute", "sing_tol"),
], ids=lambda v: v if isinstance(v, str) else "")
def test_numeric_options_reject_non_numbers_and_negatives(rpr3, closed, call, where, name):
    with pytest.raises(MechanismError, match=rf"^{where}: option {name} must be a number >= 0"):
        call(rpr3, closed)


def test_inverse_of_a_khalil_mechanism_needs_at_least_one_start():
    sr = M.sr400()
    q = optkin.forward(sr, [0.3, -0.4, 0.2, 0.5, 0.4, 0.6], guess=[np.pi / 2 + 1, -1, np.pi + 1])
    with pytest.raises(MechanismError, match=r"inverse: option starts must be an integer >= 1"):
        optkin.inverse(sr, q.pose, starts=0)
    with pytest.raises(MechanismError, match=r"inverse: option seed must be an integer"):
        optkin.inverse(sr, q.pose, seed=0.5)


def test_assembly_modes_seed_and_width_are_checked(rpr3, closed):
    with pytest.raises(MechanismError, match=r"assembly_modes: option seed must be a number >= 0"):
        optkin.assembly_modes(rpr3, closed.qa, seed=-1)
    with pytest.raises(MechanismError, match=r"assembly_modes: option width must be a power of 2"):
        optkin.assembly_modes(rpr3, closed.qa, width=3)


def test_jacobians_tol_is_checked(rpr3, closed):
    with pytest.raises(MechanismError, match=r"jacobians: option tol must be a number"):
        optkin.jacobians(rpr3, closed, tol="1e-8")
    with pytest.raises(MechanismError, match=r"jacobians: option tol must be a number > 0"):
        optkin.jacobians(rpr3, closed, tol=0.0)


@pytest.mark.parametrize("kw, match", [
    ({"grid": -1}, r"^singular_curves: option grid: expected an integer >= 2"),
    ({"grid": 2.5}, r"^singular_curves: option grid: expected an integer >= 2"),
    ({"step": 0.0}, r"^singular_curves: option step: expected a number > 0"),
    ({"tol": "small"}, r"^singular_curves: option tol must be a number"),  # merge_options
    ({"tol": 0.0}, r"^singular_curves: option tol: expected a number > 0"),
    ({"max_steps": 0}, r"^singular_curves: option max_steps: expected an integer >= 1"),
    ({"bounds": "a"}, r"^bounds: expected \[\[lo, hi\], \[lo, hi\]\]"),
    ({"bounds": [[1, 0], [0, 1]]}, r"^bounds: expected \[\[lo, hi\], \[lo, hi\]\]"),
])
def test_singular_curves_rejects_bad_arguments(kw, match):
    with pytest.raises(MechanismError, match=match):
        optkin.singular_curves(M.five_bar(9, 8, 5, 5, 8), **kw)


@pytest.mark.parametrize("fn", ["aspects", "workspace"])
@pytest.mark.parametrize("kw, match", [
    ({"qa_grid": 0}, r"^(aspects|workspace): option qa_grid: expected an integer >= 2"),
    ({"grid": 1}, r"^(aspects|workspace): option grid: expected an integer >= 2"),
    ({"bounds": [[0, 1]]}, r"^bounds: expected"),
    ({"limits": {"L1.theta1": (1.0, 0.0)}}, r"^limits\['L1.theta1'\]: expected a pair"),
    ({"limits": {"L1.theta1": "wide"}}, r"^limits\['L1.theta1'\]: expected a pair"),
])
def test_aspects_and_workspace_reject_bad_arguments(fn, kw, match):
    with pytest.raises(MechanismError, match=match):
        getattr(optkin, fn)(M.five_bar(9, 8, 5, 5, 8), **kw)


# ---------------------------------------------------------------------------
# CLI: output paths
# ---------------------------------------------------------------------------


def test_show_into_a_directory_or_without_suffix_reports_the_file_written(tmp_path, capsys):
    d = tmp_path / "pics"
    d.mkdir()
    assert main(["show", str(PROBLEMS / "four_bar.toml"), "--out", str(d)]) == 0
    assert (d / "four_bar.png").read_bytes()[:4] == b"\x89PNG"
    assert f"wrote {d / 'four_bar.png'}" in capsys.readouterr().out
    assert main(["show", str(PROBLEMS / "four_bar.toml"), "--out", str(tmp_path / "pic")]) == 0
    assert (tmp_path / "pic.png").exists()
    assert f"wrote {tmp_path / 'pic.png'}" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["show", "run"])
def test_unwritable_output_exits_2_without_traceback(tmp_path, capsys, command):
    blocker = tmp_path / "a_file"
    blocker.write_text("in the way\n")
    out = blocker / "sub" / ("x.png" if command == "show" else "results")
    args = [command, str(PROBLEMS / "four_bar.toml"), "--out", str(out)]
    if command == "run":
        args.append("--no-pictures")
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "optkin: cannot write the output" in err and "--out" in err
    assert "Traceback" not in err


def test_kinresult_repr_is_one_line_for_many_joints():
    a = np.linspace(0, 2 * np.pi, 7)[:-1]
    sg = M.stewart_gough(np.c_[np.cos(a), np.sin(a), 0 * a],
                         0.5 * np.c_[np.cos(a + 0.3), np.sin(a + 0.3), 0 * a])
    r = optkin.forward(sg, [1.2] * 6)
    assert len(r.q) > 8
    s = _one_line(r, limit=200)
    assert s.startswith("KinResult(ok") and "..." in s


def test_wrench_feasible_workspace_grid_needs_two_task_coordinates():
    fb = M.four_bar(1.0, 2.0, 2.0, 2.5)
    with pytest.raises(StaticsError, match=r"^grid: four-bar has 1 task coordinate\(s\) \['rz'\]"):
        statics.wrench_feasible_workspace(fb, [0.1], 1.0, grid=3, bounds=[[0, 1], [0, 1]])
    res = statics.wrench_feasible_workspace(fb, [0.1], 1.0, poses=[[1.7], [1.8]])
    assert res.margin.shape == (2,)


def test_a_leg_built_directly_is_validated_by_from_legs():
    Leg = optkin.Leg
    with pytest.raises(MechanismError, match=r"legs\[0\].type: unknown leg type 'XYZ'"):
        optkin.Mechanism.from_legs([Leg("XYZ", [0, 0], [0, 0])] * 3, "planar")
    with pytest.raises(MechanismError, match=r"legs\[0\].platform: expected 2 numbers, got 4"):
        optkin.Mechanism.from_legs([Leg("RPR", [0, 0], [0, 0, 0, 0])] * 3, "planar")
    legs = [Leg("RPR", [0, 0], [-0.2, -0.1]), Leg("RPR", [1, 0], [0.25, -0.2]),
            Leg("RPR", [0.5, 0.9], [0.05, 0.25])]
    m = optkin.Mechanism.from_legs(legs, "planar")
    assert json.loads(json.dumps(legs[0].to_dict())) == {
        "type": "RPR", "base": [0.0, 0.0], "platform": [-0.2, -0.1]}
    # the same mechanism as the library's 3-RPR with these points
    ref = M.rpr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    assert m.key == ref.key or all(
        a.type == b.type and np.allclose(a.base, b.base) and np.allclose(a.platform, b.platform)
        for a, b in zip(m.legs, ref.legs))


def test_nonsingular_checks_its_threshold(rpr3, closed):
    s = optkin.assembly_modes(rpr3, closed.qa)
    for bad in ("a", float("nan"), 0.5):
        with pytest.raises(MechanismError, match=r"max_cond: expected a number >= 1"):
            s.nonsingular(bad)
    cut = float(np.median([r.cond for r in s]))
    kept = s.nonsingular(cut)
    assert all(r.cond <= cut for r in kept) and len(kept) >= 1


def test_aspects_and_workspace_plot_name_a_bad_path():
    five = M.five_bar(9, 8, 5, 5, 8)
    for obj in (optkin.aspects(five), optkin.workspace(five)):
        with pytest.raises(MechanismError, match=r"path: expected a file name"):
            obj.plot(123)


def test_a_result_of_another_mechanism_is_named_as_such(rpr3, closed, tmp_path):
    five = M.five_bar(9, 8, 5, 5, 8)
    other = optkin.inverse(five, [4.5, 6.0])[0]
    calls = {
        "guess": [lambda: optkin.forward(rpr3, closed.qa, guess=other),
                  lambda: optkin.track(rpr3, [closed.qa, closed.qa * 1.01], guess=other)],
        "q": [lambda: optkin.jacobians(rpr3, other), lambda: optkin.classify(rpr3, other),
              lambda: statics.capability(rpr3, other, 1.0)],
        "results": [lambda: optkin.plot.draw(rpr3, other, str(tmp_path / "x.png"))],
    }
    for arg, fns in calls.items():
        for fn in fns:
            with pytest.raises(MechanismError,
                               match=rf"^{arg}: the KinResult belongs to another mechanism"):
                fn()
    # a result of a mechanism with the same joints (another 3-RPR) is a valid guess
    twin = M.rpr3(base=[[0, 0], [1.01, 0], [0.5, 0.9]],
                  platform=[[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]])
    qa_twin = optkin.inverse(twin, [0.45, 0.35, 0.1])[0].qa
    r = optkin.forward(twin, qa_twin, guess=closed)
    assert r.success and np.allclose(r.pose[:2, 3], [0.45, 0.35], atol=1e-8)


def test_statics_error_is_exported_at_the_top_level(rpr3, closed):
    assert "StaticsError" in optkin.__all__
    with pytest.raises(optkin.StaticsError, match="limits"):
        statics.capability(rpr3, closed, limits=-1.0)


def test_jacobians_and_static_model_to_dict_are_strict_json_far_from_closure(rpr3):
    q = np.full(9, 1e300)  # absurd but finite joint values: the matrices overflow
    jac = optkin.jacobians(rpr3, q)
    assert not jac.success and "NOT CLOSED" in _one_line(jac)
    d = json.loads(json.dumps(jac.to_dict(), allow_nan=False))
    assert d["residual"] is None or math.isfinite(d["residual"])
    sm = statics.static_model(rpr3, q)
    json.dumps(sm.to_dict(), allow_nan=False)


def test_show_says_when_it_draws_the_home_configuration_instead_of_a_task(tmp_path, capsys):
    """The five-bar's base joints are 9 apart; at q_a = (pi, 0) the elbows C = (-8, 0) and
    D = (17, 0) are 25 > L2 + L3 = 10 apart: the task cannot close."""
    f = tmp_path / "unreachable.toml"
    f.write_text('schema_version = 1\nname = "x"\n[mechanism]\ntype = "library"\n'
                 'name = "five_bar"\nargs = { L0 = 9, L1 = 8, L2 = 5, L3 = 5, L4 = 8 }\n'
                 '[[task]]\nkind = "forward"\nqa = [3.14159, 0.0]\n')
    png = tmp_path / "u.png"
    assert main(["show", str(f), "--out", str(png)]) == 0
    out = capsys.readouterr()
    assert "drawing the one at q_a = 0" in out.err and "Traceback" not in out.err
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_batch_result_to_dict_is_strict_json_with_diverged_rows(rpr3):
    import dataclasses

    b = optkin.forward_batch(rpr3, [[0.7, 0.6, 0.5], [0.7, 0.6, 0.5]], path=False)
    # rows of a batch that diverged carry NaN unknowns and an infinite residual
    bad = dataclasses.replace(b, residual=np.array([0.0, np.inf]),
                              x=np.vstack([b.x[0], np.full(3, np.nan)]))
    d = json.loads(json.dumps(bad.to_dict(), allow_nan=False))
    assert d["residual"] == [0.0, None] and d["x"][1] == [None, None, None]


def test_forward_failure_from_a_far_guess_points_at_other_guesses(rpr3, unclosed):
    """Leg lengths (0.7, 0.6, 0.5) close (solved from the home guess), yet the local solvers
    started from the unclosed configuration of ``unclosed`` stall: the message must not
    only blame the input."""
    assert optkin.forward(rpr3, [0.7, 0.6, 0.5]).success
    r = optkin.forward(rpr3, [0.7, 0.6, 0.5], guess=unclosed)
    if not r.success:  # data, not an exception; the message names both causes
        assert "out of reach" in r.message and "another guess" in r.message


def test_statics_plots_check_their_arguments(rpr3, closed, tmp_path):
    cap = statics.capability_polygon(rpr3, closed, 1.0, n=8)
    ws = statics.wrench_feasible_workspace(rpr3, [0, -0.1, 0], 1.0, poses=[[0.45, 0.35, 0.1]])
    png = str(tmp_path / "p.png")
    with pytest.raises(StaticsError, match=r"^res: expected a CapabilityResult"):
        statics.plot_capability(ws, png)
    with pytest.raises(StaticsError, match=r"^res: expected a WorkspaceResult"):
        statics.plot_workspace(cap, png)
    with pytest.raises(StaticsError, match=r"^plane: expected two different components"):
        statics.plot_capability(cap, png, plane=("fx", "fq"))
    with pytest.raises(StaticsError, match=r"^path: expected a file name"):
        statics.plot_capability(cap, 5)
    with pytest.raises(MechanismError, match=r"^path: expected a file name"):
        optkin.singular_curves(M.five_bar(9, 8, 5, 5, 8)).plot(5)
    import matplotlib.pyplot as plt

    before = set(plt.get_fignums())
    fig = statics.plot_capability(cap, png)
    assert Path(png).stat().st_size > 5000 and fig.axes[0].get_xlabel() == "fx"
    assert set(plt.get_fignums()) == before  # drawn for a file: out of pyplot
    fig2, ax = plt.subplots()
    try:  # into the caller's Axes: nothing written
        assert statics.plot_workspace(ws, ax=ax) is fig2
        assert statics.plot_capability(cap, ax=ax) is fig2
    finally:
        plt.close(fig2)
    import io

    buf = io.BytesIO()
    statics.plot_workspace(ws, buf)  # file-like objects are still accepted
    assert buf.getvalue()[:4] == b"\x89PNG"


@pytest.mark.parametrize("home", [{"t1": float("nan")}, {"t1": "up"}, [np.inf], "abc", [1.0, 2.0]])
def test_khalil_home_must_be_finite_joint_values(home):
    row = dict(a=0, mu=1, sigma=0, gamma=0, b=0, alpha=0, d=0, theta="t1", r=0)
    with pytest.raises(MechanismError, match=r"^home: expected 1 finite joint values \['t1'\]"):
        optkin.Mechanism.from_khalil([row], home=home)
    assert optkin.Mechanism.from_khalil([row], home={"t1": 0.2}).home.tolist() == [0.2]


def test_nonsingular_drops_singular_solutions(rpr3, closed):
    """A solution with an infinite condition number (W_p singular) is not nonsingular and is
    counted near-singular; NaN (not computed) is kept."""
    import dataclasses

    from optkin.results import SolutionSet

    s = optkin.assembly_modes(rpr3, closed.qa)
    assert len(s) >= 2 and all(np.isfinite(r.cond) for r in s)
    sols = list(s)
    sols[0] = dataclasses.replace(sols[0], cond=float("inf"))
    sols[1] = dataclasses.replace(sols[1], cond=float("nan"))
    t = SolutionSet(sols, s.kind, s.info, s.seed)
    kept = t.nonsingular()
    assert len(kept) == len(s) - 1 and all(not np.isinf(r.cond) for r in kept)
    assert "1 near-singular" in t.summary()
