"""Problem files: schema, error messages (file and key path), [expected] checks, runner.

The malformed files below (MALFORMED, more than 30) each must give exit status 2 from
``optkin validate`` and a message that starts with ``<file>: <key path>:``.
"""

from __future__ import annotations

import copy
import json
import math
import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import optkin
from optkin.cli import main
from optkin.errors import ProblemFileError
from optkin.problems.runner import check_expected, run_problem
from optkin.problems.schema import (
    TASK_KINDS,
    check_problem,
    load_problem,
    load_problem_bytes,
    parse_toml,
    parse_value_path,
    validate_document,
)

ROOT = Path(__file__).resolve().parents[1]
BUNDLED = sorted((ROOT / "problems").glob("*.toml"))


# ---------------------------------------------------------------------------
# a tiny TOML writer for building test documents from dicts
# ---------------------------------------------------------------------------


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _val(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, int):
        return str(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_val(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_val(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def to_toml(doc: dict[str, Any]) -> str:
    """Top-level scalars, then [tables] and [[arrays of tables]]; nested values inline."""
    lines = []
    tables = []
    for k, v in doc.items():
        if isinstance(v, dict):
            tables.append((k, v, False))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            tables.append((k, v, True))
        else:
            lines.append(f"{_key(k)} = {_val(v)}")
    for k, v, many in tables:
        for item in (v if many else [v]):
            lines.append(f"\n[[{_key(k)}]]" if many else f"\n[{_key(k)}]")
            lines += [f"{_key(a)} = {_val(b)}" for a, b in item.items()]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------
# valid base documents
# ---------------------------------------------------------------------------

FIVE_BAR = {
    "schema_version": 1,
    "mechanism": {"type": "library", "name": "five_bar",
                  "args": {"L0": 9.0, "L1": 8.0, "L2": 5.0, "L3": 5.0, "L4": 8.0}},
    "task": [
        {"kind": "forward", "qa": [0.5938610234202074, 2.5477316301695856], "draw": False},
        {"kind": "inverse", "pose": [4.5, 9.0], "draw": False,
         "expected": {"count": 4, "success": True}},
    ],
}

H = "pi/2"
SR400_ROWS = [
    {"a": 0, "mu": 1, "sigma": 0, "alpha": 0, "d": 0, "theta": "theta1"},
    {"a": 1, "mu": 1, "sigma": 0, "alpha": "-pi/2", "d": "d2", "theta": "theta2"},
    {"a": 2, "mu": 0, "sigma": 0, "alpha": 0, "d": "d3", "theta": "theta3"},
    {"a": 3, "mu": 1, "sigma": 0, "alpha": "-pi/2", "d": "d4", "theta": "theta4", "r": "RL4"},
    {"a": 4, "mu": 1, "sigma": 0, "alpha": H, "d": 0, "theta": "theta5"},
    {"a": 5, "mu": 1, "sigma": 0, "alpha": "-pi/2", "d": 0, "theta": "theta6"},
    {"a": 1, "mu": 1, "sigma": 0, "alpha": "-pi/2", "d": "d2", "theta": "theta7"},
    {"a": 7, "mu": 0, "sigma": 0, "alpha": 0, "d": "d8", "theta": "theta8"},
    {"a": 8, "mu": 0, "sigma": 0, "alpha": 0, "d": "d3", "theta": "theta9"},
    {"a": 3, "mu": 0, "sigma": 2, "gamma": H, "alpha": 0, "d": "-d8", "theta": 0},
]
SR400 = {
    "schema_version": 1,
    "mechanism": {"type": "khalil", "name": "SR400", "loops": 1, "end_effector": 6,
                  "params": {"d2": 0.15, "d3": 0.6, "d4": 0.1, "d8": 0.25, "RL4": 0.65},
                  "rows": SR400_ROWS,
                  "home": {"theta3": 1.5707963267948966, "theta8": 0.0,
                           "theta9": 3.141592653589793}},
    "task": [{"kind": "forward", "qa": [0.3, -0.4, 0.5, 0.7, -0.2, 0.6], "draw": False}],
}

RPR_LEGS = {
    "schema_version": 1,
    "mechanism": {"type": "legs", "platform": "planar", "legs": [
        {"type": "RPR", "base": [0.0, 0.0], "platform": [-0.5, -0.3]},
        {"type": "RPR", "base": [4.0, 0.0], "platform": [0.5, -0.3]},
        {"type": "RPR", "base": [0.0, 3.0], "platform": [0.0, 0.4]},
    ]},
    "task": [{"kind": "inverse", "pose": [1.6, 1.2, 0.3], "draw": False}],
}

RRR_LEGS = copy.deepcopy(RPR_LEGS)
RRR_LEGS["mechanism"]["legs"] = [
    {"type": "RRR", "base": [0.0, 0.0], "platform": [-0.4, -0.25], "lengths": [1.6, 1.6]},
    {"type": "RRR", "base": [4.0, 0.0], "platform": [0.4, -0.25], "lengths": [1.6, 1.6]},
    {"type": "RRR", "base": [2.0, 3.5], "platform": [0.0, 0.45], "lengths": [1.6, 1.6]},
]


def mutate(base: dict[str, Any], path: str, value: Any = None, delete: bool = False) -> dict:
    """A deep copy of ``base`` with the value at ``path`` ("task.0.qa") replaced."""
    doc = copy.deepcopy(base)
    parts = [int(p) if p.isdigit() else p for p in path.split(".")]
    node: Any = doc
    for p in parts[:-1]:
        node = node[p]
    if delete:
        del node[parts[-1]]
    else:
        node[parts[-1]] = value
    return doc


def rpr3_args(**kw: Any) -> dict:
    args = {"base": [[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]],
            "platform": [[-0.5, -0.3], [0.5, -0.3], [0.0, 0.4]]}
    args.update(kw)
    return {"schema_version": 1, "mechanism": {"type": "library", "name": "rpr3", "args": args},
            "task": [{"kind": "inverse", "pose": [1.6, 1.2, 0.3]}]}


def sg_args(**kw: Any) -> dict:
    pts = [[1.0, 0.0, 0.0], [0.5, 0.8, 0.0], [-0.5, 0.8, 0.0], [-1.0, 0.0, 0.0],
           [-0.5, -0.8, 0.0], [0.5, -0.8, 0.0]]
    args = {"base": pts, "platform": [[x / 2 for x in p] for p in pts]}
    args.update(kw)
    return {"schema_version": 1,
            "mechanism": {"type": "library", "name": "stewart_gough", "args": args},
            "task": [{"kind": "inverse", "pose": [0, 0, 0.8, 0, 0, 0]}]}


def with_extra_row_key() -> dict:
    doc = copy.deepcopy(SR400)
    doc["mechanism"]["rows"][0]["beta"] = 0
    return doc


# (file name, document dict or raw TOML text or bytes, expected "key path: message" regex)
MALFORMED: list[tuple[str, Any, str]] = [
    ("bad_toml", "schema_version = 1\n[mechanism\ntype = 'library'\n", r"line 2, column \d+: invalid TOML"),
    ("duplicate_key", "schema_version = 1\nschema_version = 1\n", r"line 2, column \d+: invalid TOML"),
    ("unterminated_string", 'schema_version = 1\nname = "abc\n', r"line 2, column \d+: invalid TOML"),
    ("not_utf8", b"schema_version = 1\nname = '\xff\xfe'\n", r"\(file\): not UTF-8"),
    ("no_version", mutate(FIVE_BAR, "schema_version", delete=True), r"schema_version: missing required key"),
    ("version_2", mutate(FIVE_BAR, "schema_version", 2), r"schema_version: this optkin reads schema version 1, got 2"),
    ("version_str", mutate(FIVE_BAR, "schema_version", "1"), r"schema_version: .*got '1'"),
    ("unknown_top_key", mutate(FIVE_BAR, "solver", "ipopt"), r"solver: unknown key; allowed keys: .*mechanism"),
    ("no_mechanism", mutate(FIVE_BAR, "mechanism", delete=True), r"mechanism: missing required key"),
    ("mechanism_not_table", mutate(FIVE_BAR, "mechanism", 3), r"mechanism: expected a table, got 3"),
    ("no_mech_type", mutate(FIVE_BAR, "mechanism.type", delete=True), r"mechanism\.type: missing required key"),
    ("bad_mech_type", mutate(FIVE_BAR, "mechanism.type", "robot"), r"mechanism\.type: unknown mechanism type 'robot'"),
    ("unknown_mechanism", mutate(FIVE_BAR, "mechanism.name", "six_bar"), r"mechanism\.name: unknown mechanism 'six_bar'"),
    ("arg_wrong_type", mutate(FIVE_BAR, "mechanism.args.L1", "one"), r"mechanism\.args\.L1: expected a number, got 'one'"),
    ("arg_bool", mutate(FIVE_BAR, "mechanism.args.L2", True), r"mechanism\.args\.L2: expected a number, got true"),
    ("negative_length", mutate(FIVE_BAR, "mechanism.args.L1", -1.0), r"mechanism\.args\.L1: expected a positive number, got -1\.0"),
    ("nan_length", mutate(FIVE_BAR, "mechanism.args.L3", float("nan")), r"mechanism\.args\.L3: expected a finite number, got nan"),
    ("unknown_arg", mutate(FIVE_BAR, "mechanism.args.L9", 1.0), r"mechanism\.args\.L9: unknown key"),
    ("missing_arg", mutate(FIVE_BAR, "mechanism.args.L4", delete=True), r"mechanism\.args\.L4: missing required key"),
    ("args_not_table", mutate(FIVE_BAR, "mechanism.args", [1, 2]), r"mechanism\.args: expected a table"),
    ("too_few_base_points", rpr3_args(base=[[0.0, 0.0], [4.0, 0.0]]), r"mechanism\.args\.base: expected 3 points, got 2"),
    ("point_3_coords", rpr3_args(base=[[0.0, 0.0], [4.0, 0.0, 1.0], [0.0, 3.0]]), r"mechanism\.args\.base\[1\]: expected 2 numbers, got 3"),
    ("sg_five_points", sg_args(platform=[[0.0, 0.0, 0.0]] * 5), r"mechanism\.args\.platform: expected 6 points, got 5"),
    ("sg_point_string", sg_args(base=[[1.0, 0.0, "z"]] + [[0.0, 1.0, 0.0]] * 5), r"mechanism\.args\.base\[0\]\[2\]: expected a number, got 'z'"),
    ("missing_parent", mutate(SR400, "mechanism.rows.2.a", 5), r"mechanism\.rows\[2\]\.a: frame 3 names parent a\(3\) = 5, which is not defined"),
    ("parent_self", mutate(SR400, "mechanism.rows.0.a", 1), r"mechanism\.rows\[0\]\.a: frame 1 names parent a\(1\) = 1"),
    ("negative_parent", mutate(SR400, "mechanism.rows.1.a", -1), r"mechanism\.rows\[1\]\.a: expected an integer >= 0, got -1"),
    ("bad_sigma", mutate(SR400, "mechanism.rows.1.sigma", 3), r"mechanism\.rows\[1\]\.sigma: expected one of 0, 1, 2, got 3"),
    ("bad_mu", mutate(SR400, "mechanism.rows.1.mu", 2), r"mechanism\.rows\[1\]\.mu: expected one of 0, 1, got 2"),
    ("unknown_column", with_extra_row_key(), r"mechanism\.rows\[0\]\.beta: unknown key"),
    ("unknown_param", mutate(SR400, "mechanism.rows.2.d", "d9"), r"mechanism\.rows\[2\]\.d: unknown parameter 'd9'"),
    ("bad_expression", mutate(SR400, "mechanism.rows.1.alpha", "__import__('os')"), r"mechanism\.rows\[1\]\.alpha: .*not allowed"),
    ("too_many_loops", mutate(SR400, "mechanism.loops", 6), r"mechanism\.loops: 6 loop\(s\) need 12 rows"),
    ("partner_not_fixed", mutate(SR400, "mechanism.rows.9.sigma", 0), r"mechanism\.rows\[9\]\.sigma: with loops = 1, rows\[9\] \(frame 10\) is the partner frame"),
    ("cut_joint_actuated", mutate(SR400, "mechanism.rows.8.mu", 1), r"mechanism\.rows\[8\]\.mu: .*cut joints are passive"),
    ("no_actuated", mutate(SR400, "mechanism.rows", [dict(r, mu=0) for r in SR400_ROWS]), r"mechanism\.rows: no actuated joint"),
    ("dof_mismatch", mutate(SR400, "mechanism.dof", 5), r"mechanism\.dof: .*5 degrees of freedom but 6 joints are actuated"),
    ("duplicate_joint", mutate(SR400, "mechanism.rows.3.theta", "theta2"), r"mechanism\.rows\[3\]\.theta: joint name 'theta2' is already used by rows\[1\]"),
    ("end_effector_missing", mutate(SR400, "mechanism.end_effector", 12), r"mechanism\.end_effector: frame 12 does not exist"),
    ("fixed_frame_actuated", mutate(SR400, "mechanism.rows.9.mu", 1), r"mechanism\.rows\[9\]\.mu: frame 10 is a fixed frame"),
    ("two_legs_planar", mutate(RPR_LEGS, "mechanism.legs", RPR_LEGS["mechanism"]["legs"][:2]), r"mechanism\.legs: a planar platform needs 3 legs, got 2"),
    ("leg_point_3d", mutate(RPR_LEGS, "mechanism.legs.1.base", [4.0, 0.0, 0.0]), r"mechanism\.legs\[1\]\.base: expected 2 numbers, got 3"),
    ("leg_bad_type", mutate(RPR_LEGS, "mechanism.legs.0.type", "PRR"), r"mechanism\.legs\[0\]\.type: expected 'RPR'.*got 'PRR'"),
    ("leg_negative_length", mutate(RRR_LEGS, "mechanism.legs.0.lengths", [1.6, -0.5]), r"mechanism\.legs\[0\]\.lengths\[1\]: expected a positive number, got -0\.5"),
    ("leg_missing_lengths", mutate(RRR_LEGS, "mechanism.legs.2.lengths", delete=True), r"mechanism\.legs\[2\]\.lengths: a RRR leg has 2 link length\(s\), got 0"),
    ("leg_spatial_on_planar", mutate(RPR_LEGS, "mechanism.legs.0.type", "SPS"), r"mechanism\.legs\[0\]\.type: a SPS leg does not fit a planar platform"),
    ("leg_bad_platform", mutate(RPR_LEGS, "mechanism.platform", "spherical"), r"mechanism\.platform: expected 'planar'.*got 'spherical'"),
    ("no_tasks", mutate(FIVE_BAR, "task", delete=True), r"task: missing required key"),
    ("task_table", "schema_version = 1\n[mechanism]\ntype = 'library'\nname = 'four_bar'\n"
                   "args = {L1 = 1.0, L2 = 2.0, L3 = 2.0, L4 = 2.5}\n[task]\nkind = 'forward'\n",
     r"task: expected one or more \[\[task\]\] tables"),
    ("unknown_task", mutate(FIVE_BAR, "task.1.kind", "forwards"), r"task\[1\]\.kind: unknown task kind 'forwards'.*did you mean 'forward'"),
    ("task_no_kind", mutate(FIVE_BAR, "task.0.kind", delete=True), r"task\[0\]\.kind: missing required key"),
    ("negative_grid", mutate(FIVE_BAR, "task.1", {"kind": "singular_curves", "grid": -3}), r"task\[1\]\.grid: expected a positive integer, got -3"),
    ("qa_wrong_length", mutate(FIVE_BAR, "task.0.qa", [0.1, 0.2, 0.3]), r"task\[0\]\.qa: expected 2 numbers \(one per actuated joint: L1\.theta1, L2\.theta1\), got 3"),
    ("qa_unknown_joint", mutate(FIVE_BAR, "task.0.qa", {"theta9": 1.0}), r"task\[0\]\.qa\.theta9: unknown actuated joint 'theta9'"),
    ("qa_string", mutate(FIVE_BAR, "task.0.qa", [0.1, "x"]), r"task\[0\]\.qa\[1\]: expected a number, got 'x'"),
    ("task_unknown_key", mutate(FIVE_BAR, "task.0.seed", 3), r"task\[0\]\.seed: unknown key; allowed keys: .*qa"),
    ("pose_wrong_length", mutate(FIVE_BAR, "task.1.pose", [1.0, 2.0, 3.0]), r"task\[1\]\.pose: expected 2 numbers"),
    ("expected_typo", mutate(FIVE_BAR, "task.1.expected", {"cnt": 4}), r"task\[1\]\.expected\.cnt: unknown key.*did you mean 'count'"),
    ("expected_negative_count", mutate(FIVE_BAR, "task.1.expected", {"count": -1}), r"task\[1\]\.expected\.count: expected an integer >= 0, got -1"),
    ("expected_bad_path", mutate(FIVE_BAR, "task.1.expected", {"values": {"a..b": 1.0}}), r"task\[1\]\.expected\.values\['a\.\.b'\]: cannot read the result path"),
    ("expected_value_key", mutate(FIVE_BAR, "task.1.expected", {"values": {"x": {"value": 1, "tl": 2}}}), r"task\[1\]\.expected\.values\.x\.tl: unknown key"),
    ("expected_check_path", mutate(FIVE_BAR, "task.1.expected", {"checks": [{"path": "q[", "value": 1}]}), r"task\[1\]\.expected\.checks\[0\]\.path: cannot read the result path"),
    ("option_table", mutate(FIVE_BAR, "task.0.options", {"tol": {"a": 1}}), r"task\[0\]\.options\.tol: expected a number, string or boolean"),
    ("draw_not_bool", mutate(FIVE_BAR, "task.0.draw", "yes"), r"task\[0\]\.draw: expected true or false, got 'yes'"),
]


def _write(tmp_path: Path, name: str, content: Any) -> Path:
    path = tmp_path / f"{name}.toml"
    if isinstance(content, dict):
        path.write_text(to_toml(content), encoding="utf-8")
    elif isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content, encoding="utf-8")
    return path


def test_at_least_30_malformed_cases() -> None:
    assert len(MALFORMED) >= 30
    assert len({name for name, _, _ in MALFORMED}) == len(MALFORMED)


@pytest.mark.parametrize("name,content,pattern", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_names_file_and_key_path(tmp_path, capsys, name, content, pattern) -> None:
    path = _write(tmp_path, name, content)
    with pytest.raises(ProblemFileError) as info:
        load_problem(path)
    first = str(info.value).splitlines()[0]
    assert re.match(rf"{re.escape(name)}\.toml: {pattern}", first), first
    # the command: exit status 2, the same message, no traceback
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{name}.toml: " in err
    assert re.search(pattern, err)
    assert "Traceback" not in err


def test_message_example_from_the_issue(tmp_path) -> None:
    doc = copy.deepcopy(FIVE_BAR)
    doc["task"].append({"kind": "singular_curves", "grid": -3})
    path = _write(tmp_path, "five_bar", doc)
    with pytest.raises(ProblemFileError, match=r"^five_bar\.toml: task\[2\]\.grid: expected a positive integer, got -3$"):
        load_problem(path)


def test_several_errors_are_reported_together(tmp_path) -> None:
    doc = mutate(FIVE_BAR, "task.0.qa", [0.1, "x"])
    doc = mutate(doc, "task.1", {"kind": "aspects", "grid": 0})
    with pytest.raises(ProblemFileError) as info:
        validate_document(doc, "f.toml")
    lines = str(info.value).splitlines()
    assert any(line.startswith("f.toml: task[0].qa[1]:") for line in lines)
    assert any(line.startswith("f.toml: task[1].grid:") for line in lines)


# ---------------------------------------------------------------------------
# valid files
# ---------------------------------------------------------------------------


def test_bundled_problems_cover_every_library_mechanism_and_kind() -> None:
    from optkin.problems.tasks import TASKS, library_function

    both: set[str] = set()
    kinds: set[str] = set()
    for path in BUNDLED:
        p = load_problem(path)
        m = p.spec.mechanism
        task_kinds = {t.kind for t in p.spec.task}
        kinds |= task_kinds
        if m.type == "library" and {"forward", "inverse"} <= task_kinds:
            both.add(m.name)
        for t in p.spec.task:
            assert t.expected is not None, f"{path.name}: every bundled task has [expected]"
    # one file per library mechanism with forward and inverse tasks
    assert set(optkin.mechanisms.LIBRARY) <= both
    # and every task kind whose library function exists
    available = set()
    for kind in TASKS:
        try:
            library_function({"statics": "statics.capability"}.get(kind, kind), kind)
            available.add(kind)
        except NotImplementedError:
            pass
    assert available <= kinds, available - kinds


@pytest.mark.parametrize("path", BUNDLED, ids=[p.name for p in BUNDLED])
def test_bundled_problem_validates(path: Path) -> None:
    problem = load_problem(path)
    assert problem.mechanism is not None
    assert len(problem.hash) == 64


def test_khalil_legs_and_library_forms_build() -> None:
    for doc in (SR400, RPR_LEGS, RRR_LEGS, FIVE_BAR):
        spec = validate_document(doc, "x.toml")
        mech = check_problem(spec, "x.toml")
        assert mech.dof == len(mech.active_names)


def test_legs_read_the_registries_and_screws() -> None:
    """The schema takes every registered leg type with its keys, a leg by its screws
    (Leg.from_screws) mixed with typed legs, and the platform kind from the legs."""
    from optkin.mechanism.legs import LEG_TYPES

    legs = copy.deepcopy(RPR_LEGS["mechanism"]["legs"])
    # the third RPR leg by its screws (revolutes about z through (0, 3), slide along x)
    legs[2] = {"screws": [[0, 0, 1, 3.0, 0, 0], [0, 0, 0, 1, 0, 0], [0, 0, 1, 3.0, 0, 0]],
               "home": [[1, 0, 0, 0.0], [0, 1, 0, 2.6], [0, 0, 1, 0], [0, 0, 0, 1]],
               "actuated": 1, "joints": "RPR"}
    doc = mutate(RPR_LEGS, "mechanism.legs", legs)
    mech = check_problem(validate_document(doc, "s.toml"), "s.toml")
    ref = check_problem(validate_document(RPR_LEGS, "r.toml"), "r.toml")
    qa = [abs(x) for x in optkin.inverse(mech, [1.6, 1.2, 0.3])[0].qa]
    assert qa == pytest.approx(list(optkin.inverse(ref, [1.6, 1.2, 0.3])[0].qa), abs=1e-10)
    # the platform kind follows from the legs when left out
    no_plat = copy.deepcopy(RPR_LEGS)
    del no_plat["mechanism"]["platform"]
    assert check_problem(validate_document(no_plat, "p.toml"), "p.toml").platform == "planar"
    # a type the library registered is accepted with its keys and counts
    prr = dict(RPR_LEGS["mechanism"]["legs"][2], type="PRR", direction=[1.0, 0.0],
               lengths=[1.0])
    assert "PRR" in LEG_TYPES
    doc = mutate(RPR_LEGS, "mechanism.legs.2", prr)
    mech = check_problem(validate_document(doc, "prr.toml"), "prr.toml")
    assert mech.active_names[2] == "L3.s"
    for path, value, msg in (
            ("mechanism.legs.2.direction", [1.0, 0.0, 0.0],
             r"legs\[2\]\.direction: expected 2 numbers \(the slider's unit direction\), got 3"),
            ("mechanism.legs.2.axis", [0.0, 0.0, 1.0], r"legs\[2\]\.axis: unknown key for a PRR leg"),
            ("mechanism.legs.2.screws", [[0, 0, 0, 1, 0, 0]],
             r"legs\[2\]\.type: unknown key for a leg given by its screws")):
        with pytest.raises(ProblemFileError, match=msg):
            check_problem(validate_document(mutate(doc, path, value), "bad.toml"), "bad.toml")
    bad = mutate(RPR_LEGS, "mechanism.legs.2", dict(legs[2], screws=[[0, 0, 2, 0, 0, 0]] * 3))
    with pytest.raises(ProblemFileError, match=r"legs\[2\]\.screws\[0\]: the rotation axis omega "
                                               r"must be a unit vector"):
        check_problem(validate_document(bad, "bad.toml"), "bad.toml")
    bad = mutate(RPR_LEGS, "mechanism.legs.2", {k: v for k, v in legs[2].items() if k != "home"})
    with pytest.raises(ProblemFileError, match=r"legs\[2\]\.home: missing required key"):
        check_problem(validate_document(bad, "bad.toml"), "bad.toml")


def test_joint_vector_by_name_and_guess() -> None:
    doc = mutate(SR400, "task.0.qa", {"theta1": 0.3, "theta2": -0.4, "theta4": 0.5,
                                      "theta5": 0.7, "theta6": -0.2, "theta7": 0.6})
    p = load_problem_bytes(to_toml(doc).encode(), "sr.toml")
    res = run_problem(p)
    t = res["tasks"][0]
    assert t["status"] == "ok", t["message"]
    q = dict(zip(t["output"]["joint_names"], t["output"]["q"]))
    # Khalil [7.41]: theta3 = pi/2 - theta2 + theta7
    assert math.isclose(q["theta3"], math.pi / 2 + 0.4 + 0.6, abs_tol=1e-8)


# ---------------------------------------------------------------------------
# hypothesis: the validator only ever raises ProblemFileError
# ---------------------------------------------------------------------------

_scalars = st.one_of(
    st.integers(-5, 12), st.floats(allow_nan=True, allow_infinity=True), st.booleans(),
    st.text(max_size=8), st.sampled_from(["library", "khalil", "legs", "five_bar", "rpr3",
                                          "forward", "inverse", "RPR", "pi/2", "theta1", "d3"]),
)
_keys = st.one_of(st.sampled_from(["schema_version", "mechanism", "task", "type", "name", "args",
                                   "rows", "legs", "kind", "qa", "pose", "expected", "values",
                                   "a", "mu", "sigma", "theta", "d", "loops", "params", "base",
                                   "platform", "lengths", "count", "grid", "L0", "L1"]),
                  st.text(max_size=6))
_values = st.recursive(
    _scalars,
    lambda kids: st.one_of(st.lists(kids, max_size=5), st.dictionaries(_keys, kids, max_size=5)),
    max_leaves=25,
)


def _leaf_paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(node, dict):
        for k, v in node.items():
            out += _leaf_paths(v, prefix + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _leaf_paths(v, prefix + (i,))
    return out


def _validate_everything(doc: Any) -> None:
    try:
        spec = validate_document(doc, "random.toml")
        check_problem(spec, "random.toml")
    except ProblemFileError as e:
        assert str(e).startswith("random.toml: ")


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.dictionaries(_keys, _values, max_size=6))
def test_random_documents_only_raise_problem_file_error(doc) -> None:
    if "schema_version" not in doc:
        doc["schema_version"] = 1
    _validate_everything(doc)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.sampled_from([FIVE_BAR, SR400, RPR_LEGS, RRR_LEGS, rpr3_args(), sg_args()]),
       st.data())
def test_mutated_valid_documents_only_raise_problem_file_error(base, data) -> None:
    doc = copy.deepcopy(base)
    for _ in range(data.draw(st.integers(1, 3))):
        paths = _leaf_paths(doc)
        path = data.draw(st.sampled_from(paths))
        node = doc
        for p in path[:-1]:
            node = node[p]
        if data.draw(st.booleans()) and isinstance(node, dict):
            del node[path[-1]]
        else:
            node[path[-1]] = data.draw(_values)
    _validate_everything(doc)


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=200) | st.text(max_size=200).map(str.encode))
def test_random_bytes_only_raise_problem_file_error(data) -> None:
    try:
        doc = parse_toml(data, "junk.toml")
    except ProblemFileError as e:
        assert str(e).startswith("junk.toml: ")
        return
    _validate_everything(doc)


# ---------------------------------------------------------------------------
# [expected] checks
# ---------------------------------------------------------------------------

OUTPUT = {
    "success": True,
    "count": 2,
    "solutions": [
        {"q": [0.1, 6.2], "joint_names": ["a", "b"], "qa": [0.1], "active_names": ["a"]},
        {"q": [0.3, -0.08], "joint_names": ["a", "b"], "qa": [0.3], "active_names": ["a"]},
    ],
    "pose": [[1.0, 0.0], [0.0, 1.0]],
}


def _expected(**kw: Any):
    from optkin.problems.schema import Expected

    return Expected.model_validate(kw)


@pytest.mark.parametrize("spec,passed", [
    ({"count": 2, "success": True}, True),
    ({"count": 3}, False),
    ({"min_count": 1, "max_count": 2}, True),
    ({"success": False}, False),
    ({"values": {"solutions[any].qa": [0.3]}}, True),
    ({"values": {"solutions[*].qa": [0.3]}}, False),
    ({"values": {"solutions[1].q[a]": 0.3}}, True),
    ({"values": {"solutions[0].qa[a]": 0.1}}, True),
    ({"values": {"solutions[0].q[b]": -0.0831853}}, False),
    ({"values": {"solutions[0].q[b]": {"value": -0.0831853, "wrap": True, "tol": 1e-6}}}, True),
    ({"values": {"pose[1][1]": 1.0, "pose": [[1.0, 0.0], [0.0, 1.0]]}}, True),
    ({"values": {"pose[0][0]": 1.1}, "tol": 0.2}, True),
    ({"values": {"pose[0][0]": 1.1}, "rtol": 0.01}, False),
    ({"values": {"missing.key": 1.0}}, False),
    ({"checks": [{"path": "solutions[any].qa", "value": [0.1]},
                 {"path": "solutions[any].qa", "value": [0.3]}]}, True),
    ({"checks": [{"path": "solutions[any].qa", "value": [0.2], "tol": 0.05}]}, False),
])
def test_check_expected(spec, passed) -> None:
    res = check_expected(_expected(**spec), OUTPUT, "ok")
    assert res["passed"] is passed, res["checks"]


def test_check_expected_reports_what_was_found() -> None:
    res = check_expected(_expected(count=3, values={"solutions[9].qa": 1.0}), OUTPUT, "ok")
    got = {c["check"]: c["got"] for c in res["checks"]}
    assert got["count"] == "2"
    assert "no index [9]" in got["solutions[9].qa"]


def test_without_expected_a_task_passes_when_ok() -> None:
    assert check_expected(None, OUTPUT, "ok")["passed"] is True
    assert check_expected(None, None, "error")["passed"] is False


def test_an_error_misses_any_expected_block() -> None:
    assert check_expected(_expected(), None, "error")["passed"] is False


def test_value_paths() -> None:
    assert parse_value_path("solutions[any].q[theta3]") == ["solutions", "[any]", "q", "theta3"]
    assert parse_value_path("pose[0][3]") == ["pose", 0, 3]
    assert parse_value_path("q['L1.rho']") == ["q", "L1.rho"]
    for bad in ("", ".a", "a..b", "a[", "a b", "[x"):
        with pytest.raises(ValueError):
            parse_value_path(bad)


# ---------------------------------------------------------------------------
# running a problem
# ---------------------------------------------------------------------------


def test_one_failing_task_never_stops_the_others(monkeypatch) -> None:
    doc = copy.deepcopy(FIVE_BAR)
    doc["task"] = [
        {"kind": "forward", "qa": [0.59, 2.55], "guess": [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0],
         "draw": False},                                              # error: bad guess
        {"kind": "dof"},                                               # unavailable (removed below)
        {"kind": "forward", "qa": [3.14159, 0.0], "draw": False},        # |CD| = 25 > L2 + L3: failed
        {"kind": "forward", "qa": [0.5938610234202074, 2.5477316301695856], "draw": False,
         "expected": {"success": True, "values": {"task_coordinates": [4.5, 9.0]}}},
    ]
    monkeypatch.delattr(optkin, "dof", raising=False)
    p = load_problem_bytes(to_toml(doc).encode(), "mixed.toml")
    res = run_problem(p)
    st_ = [t["status"] for t in res["tasks"]]
    assert st_ == ["error", "unavailable", "failed", "ok"], [t["message"] for t in res["tasks"]]
    assert "guess" in res["tasks"][0]["message"]
    assert "not available in this version" in res["tasks"][1]["message"]
    assert [t["passed"] for t in res["tasks"]] == [False, False, False, True]
    json.dumps(res, allow_nan=False)  # JSON-ready


def test_expected_failure_is_reported(tmp_path) -> None:
    doc = copy.deepcopy(FIVE_BAR)
    doc["task"][1]["expected"] = {"count": 3}
    p = load_problem_bytes(to_toml(doc).encode(), "wrong.toml")
    res = run_problem(p)
    t = res["tasks"][1]
    assert t["status"] == "ok" and t["passed"] is False
    assert "expected count = 3, got 4" in t["message"]


def test_compiled_model_is_built_once_per_problem(monkeypatch) -> None:
    from optkin.model import core

    builds = []
    real = core.Model.__init__

    def counting(self, *a, **k):
        builds.append(1)
        real(self, *a, **k)

    monkeypatch.setattr(core.Model, "__init__", counting)
    core.clear_cache()
    doc = copy.deepcopy(FIVE_BAR)
    doc["task"] = [{"kind": "forward", "qa": [0.59 + 0.01 * i, 2.55], "draw": False}
                   for i in range(4)] + [{"kind": "inverse", "pose": [4.5, 9.0], "draw": False}]
    res = run_problem(load_problem_bytes(to_toml(doc).encode(), "five.toml"))
    assert all(t["status"] == "ok" for t in res["tasks"])
    assert len(builds) == 1


@pytest.mark.parametrize("kind", TASK_KINDS)
def test_every_kind_has_a_runner_and_a_model(kind) -> None:
    from optkin.problems.schema import TASK_MODELS
    from optkin.problems.tasks import TASKS

    assert kind in TASKS and kind in TASK_MODELS


def test_toml_and_python_take_the_same_names_and_defaults() -> None:
    """A problem file and Python describe mechanisms with the same words and defaults:
    library arguments are the factories' parameters, and a Khalil row missing a column
    means the same in both (here ``mu``, ``sigma`` and the geometry left out of every row
    of the SR400 where they are 0: a passive revolute, as ``sigma = 0`` says)."""
    import inspect

    from optkin.problems.schema import LIBRARY_ARG_MODELS

    for name, model in LIBRARY_ARG_MODELS.items():
        params = inspect.signature(optkin.mechanisms.LIBRARY[name]).parameters
        assert set(model.model_fields) == set(params), name
        for k, f in model.model_fields.items():  # a TOML default is the library's (None)
            if f.is_required():
                assert params[k].default is inspect.Parameter.empty, (name, k)
            else:
                assert f.default is None or f.default == params[k].default, (name, k)

    def sparse(row: dict) -> dict:
        return {k: v for k, v in row.items() if k == "a" or v not in (0, "0")}

    rows = [sparse(r) for r in SR400_ROWS]
    assert sum("sigma" not in r for r in rows) == 9 and sum("mu" not in r for r in rows) == 4
    spec = SR400["mechanism"]
    py = optkin.Mechanism.from_khalil(rows, loops=1, params=spec["params"],
                                      end_effector=spec["end_effector"])
    full = optkin.Mechanism.from_khalil(SR400_ROWS, loops=1, params=spec["params"],
                                        end_effector=spec["end_effector"])
    toml = check_problem(validate_document(mutate(SR400, "mechanism.rows", rows), "s.toml"),
                         "s.toml")
    for m in (py, toml):
        assert m.topology == full.topology
        np.testing.assert_array_equal(m.geometry, full.geometry)
    # a row without its antecedent is refused by both
    with pytest.raises(optkin.MechanismError, match=r"row 1 \(frame j=1\): missing column"):
        optkin.Mechanism.from_khalil([{"sigma": 0}])
    with pytest.raises(ProblemFileError, match=r"rows\[0\]\.a"):
        check_problem(validate_document(mutate(SR400, "mechanism.rows.0", {"sigma": 0}),
                                        "s.toml"), "s.toml")
