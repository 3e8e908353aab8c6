"""Schema (version 1) of optkin problem files, validated with pydantic v2.

A problem file is TOML with one ``[mechanism]`` table and one or more ``[[task]]``
tables; each task may carry an ``[task.expected]`` table that the runner checks
(see ``problems/README.md``). :func:`load_problem` reads and validates a file;
every error is a :class:`~optkin.errors.ProblemFileError` whose message starts with
``file: key.path:``, e.g. ``five_bar.toml: task[2].grid: expected a positive integer,
got -3``. Key paths count from zero (``task[0]`` is the first ``[[task]]``).

The checks a schema cannot express (Khalil parents exist, loops close, the number
of actuated joints matches the degrees of freedom, a task's joint vector has one
entry per actuated joint) run after the schema, in :func:`check_problem`, partly by
building the mechanism with the library and converting its
:class:`~optkin.errors.MechanismError` into a :class:`ProblemFileError`.

Adding a task kind: write a small parameter model deriving from :class:`TaskBase`
with ``kind: Literal["my_kind"]``, and add it to :data:`TASK_MODELS`.
"""

import ast
import difflib
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PlainValidator,
    ValidationError,
    create_model,
    model_validator,
)
from pydantic_core import PydanticCustomError

from optkin._checks import MAX_ABS
from optkin.errors import MechanismError, ProblemFileError
from optkin.mechanism.legs import LEG_TYPES as _LEG_REGISTRY
from optkin.mechanism.legs import validate_legs
from optkin.mechanism.platforms import PLATFORMS as _PLATFORM_REGISTRY
from optkin.problems.files import (  # noqa: F401 - re-exported: this module's public names
    MAX_FILE_BYTES,
    MAX_INT_DIGITS,
    MAX_KEY_PARTS,
    MAX_NESTING,
    input_hash,
    optkin_version,
    parse_toml,
)
from optkin.problems.workers import MAX_TIME_LIMIT

__all__ = [
    "SCHEMA_VERSION",
    "TASK_KINDS",
    "TASK_MODELS",
    "LIBRARY_ARG_MODELS",
    "Problem",
    "ProblemFile",
    "Expected",
    "TaskBase",
    "load_problem",
    "validate_document",
    "check_problem",
    "build_mechanism",
    "parse_value_path",
    "format_key_path",
    "input_hash",
    "optkin_version",
]

SCHEMA_VERSION = 1

# ---------------------------------------------------------------------------
# value types with plain-language error messages
# ---------------------------------------------------------------------------


def _show(v: Any) -> str:
    """Short display of an offending input value, TOML-flavoured."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, dict):
        return "a table"
    if isinstance(v, list):
        return f"a list of {len(v)} item{'s' if len(v) != 1 else ''}"
    if isinstance(v, str):
        s = v if len(v) <= 40 else v[:37] + "..."
        return repr(s)
    if v is None:
        return "nothing"
    s = repr(v)
    return s if len(s) <= 40 else s[:37] + "..."


def _err(kind: str, msg: str, got: Any) -> PydanticCustomError:
    return PydanticCustomError(kind, msg + ", got {got}", {"got": _show(got)})


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(v: Any) -> float:
    if not _is_number(v):
        raise _err("number", "expected a number", v)
    if isinstance(v, int) and abs(v) > MAX_ABS:
        raise _err("finite", f"expected a number of magnitude at most {MAX_ABS:g}", v)
    if not math.isfinite(v):
        raise _err("finite", "expected a finite number", v)
    if abs(v) > MAX_ABS:
        raise _err("finite", f"expected a number of magnitude at most {MAX_ABS:g}", v)
    return float(v)


def _positive(v: Any) -> float:
    x = _number(v)
    if x <= 0:
        raise _err("positive", "expected a positive number", v)
    return x


def _nonneg(v: Any) -> float:
    x = _number(v)
    if x < 0:
        raise _err("nonnegative", "expected a number >= 0", v)
    return x


def _integer(v: Any) -> int:
    if not _is_int(v):
        raise _err("integer", "expected an integer", v)
    return int(v)


def _pos_int(v: Any) -> int:
    if not _is_int(v) or v <= 0:
        raise _err("positive_integer", "expected a positive integer", v)
    return int(v)


def _nonneg_int(v: Any) -> int:
    if not _is_int(v) or v < 0:
        raise _err("nonnegative_integer", "expected an integer >= 0", v)
    return int(v)


def _string(v: Any) -> str:
    if not isinstance(v, str):
        raise _err("string", "expected a string", v)
    return v


def _name(v: Any) -> str:
    if not isinstance(v, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", v):
        raise _err("name", "expected a name (letters, digits, _; not starting with a digit)", v)
    return v


def _boolean(v: Any) -> bool:
    if not isinstance(v, bool):
        raise _err("boolean", "expected true or false", v)
    return v


def _number_or_expr(v: Any) -> float | str:
    if isinstance(v, str):
        if not v.strip():
            raise _err("expression", "expected a number or an expression like 'pi/2'", v)
        return v
    return _number(v)


Number = Annotated[float, PlainValidator(_number)]
PositiveNumber = Annotated[float, PlainValidator(_positive)]
NonNegNumber = Annotated[float, PlainValidator(_nonneg)]
Integer = Annotated[int, PlainValidator(_integer)]
PositiveInt = Annotated[int, PlainValidator(_pos_int)]
NonNegInt = Annotated[int, PlainValidator(_nonneg_int)]
Str = Annotated[str, PlainValidator(_string)]
Name = Annotated[str, PlainValidator(_name)]
Bool = Annotated[bool, PlainValidator(_boolean)]
NumberOrExpr = Annotated[Union[float, str], PlainValidator(_number_or_expr)]  # noqa: UP007


def _list_of(item: Callable[[Any], Any], what: str, n: int | None = None, min_n: int = 0):
    """Validator of a list whose items pass ``item``; errors point at ``[i]``."""

    def check(v: Any) -> list:
        if not isinstance(v, list):
            raise _err("list", f"expected a list of {what}", v)
        if n is not None and len(v) != n:
            raise PydanticCustomError(
                "list_length", f"expected {n} {what}, got {len(v)}", {"got": len(v)}
            )
        if len(v) < min_n:
            raise PydanticCustomError(
                "list_length", f"expected at least {min_n} {what}, got {len(v)}", {"got": len(v)}
            )
        out, errors = [], []
        for i, x in enumerate(v):
            try:
                out.append(item(x))
            except PydanticCustomError as e:
                errors.append((i, e))
        if errors:
            i, e = errors[0]
            raise PydanticCustomError(
                "item", "{__loc__}" + e.message(), {"__loc__": f"[{i}]"}
            )
        return out

    return check


def _point(dim: int) -> Callable[[Any], list[float]]:
    return _list_of(_number, "numbers", n=dim)


def Points(count: int | None, dim: int) -> Any:  # noqa: N802 - type factory
    """A list of ``count`` points of ``dim`` coordinates (plain list of lists)."""
    return Annotated[list[list[float]], PlainValidator(_list_of(_point(dim), "points", n=count))]


def Numbers(n: int | None = None, min_n: int = 0, positive: bool = False) -> Any:  # noqa: N802
    """A list of numbers (``n`` of them when given)."""
    return Annotated[
        list[float], PlainValidator(_list_of(_positive if positive else _number, "numbers", n, min_n))
    ]


def _number_or_numbers(n: int | None, positive: bool) -> Callable[[Any], Any]:
    one = _positive if positive else _number
    many = _list_of(one, "numbers", n=n)

    def check(v: Any) -> float | list[float]:
        if isinstance(v, list):
            return many(v)
        return one(v)

    return check


def _vector_or_named(v: Any) -> list[float] | dict[str, float]:
    """A joint vector: a list of numbers, or a table ``{joint_name = value}``."""
    if isinstance(v, dict):
        out: dict[str, float] = {}
        for k, x in v.items():
            try:
                out[k] = _number(x)
            except PydanticCustomError as e:
                raise PydanticCustomError(
                    "item", "{__loc__}" + e.message(), {"__loc__": f"[{k!r}]"}
                ) from None
        return out
    if isinstance(v, list):
        return _list_of(_number, "numbers")(v)
    raise _err("vector", "expected a list of numbers or a table of joint values", v)


JointVector = Annotated[Union[list[float], dict[str, float]], PlainValidator(_vector_or_named)]  # noqa: UP007


def _rigid(T: list[list[float]]) -> list[list[float]]:
    """A 4x4 matrix that is a rigid transform: rotation block orthonormal with det +1 (to
    1e-6) and last row (0, 0, 0, 1)."""
    R = [row[:3] for row in T[:3]]
    for i in range(3):
        for j in range(3):
            dot = sum(R[k][i] * R[k][j] for k in range(3))
            if abs(dot - (1.0 if i == j else 0.0)) > 1e-6:
                raise PydanticCustomError(
                    "rigid", "expected a rigid transform: the rotation block (first 3 rows and "
                    "columns) must be orthonormal, its columns {i} and {j} are not", {"i": i, "j": j})
    det = (R[0][0] * (R[1][1] * R[2][2] - R[1][2] * R[2][1])
           - R[0][1] * (R[1][0] * R[2][2] - R[1][2] * R[2][0])
           + R[0][2] * (R[1][0] * R[2][1] - R[1][1] * R[2][0]))
    if det < 0:
        raise PydanticCustomError("rigid", "expected a rigid transform: the rotation block is a "
                                  "reflection (determinant -1)")
    if any(abs(a - b) > 1e-12 for a, b in zip(T[3], (0.0, 0.0, 0.0, 1.0))):
        raise PydanticCustomError("rigid", "expected a rigid transform: the last row must be "
                                  "[0, 0, 0, 1]")
    return T


def _pose(v: Any) -> list[float] | list[list[float]]:
    """A task vector (2, 3 or 6 numbers) or a 4x4 homogeneous matrix of a rigid motion."""
    if isinstance(v, list) and v and all(isinstance(r, list) for r in v):
        return _rigid(_list_of(_point(4), "rows of 4 numbers", n=4)(v))
    if isinstance(v, list):
        return _list_of(_number, "numbers", min_n=1)(v)
    raise _err("pose", "expected a task vector (list of numbers) or a 4x4 matrix", v)


Pose = Annotated[Union[list[float], list[list[float]]], PlainValidator(_pose)]  # noqa: UP007


# ---------------------------------------------------------------------------
# models
# ---------------------------------------------------------------------------


class Strict(BaseModel):
    """Base of every table: unknown keys are errors, values are not coerced."""

    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            raise _err("table", "expected a table", data)
        known = [f.alias or n for n, f in cls.model_fields.items()]
        for k in data:
            if k not in known:
                hint = difflib.get_close_matches(str(k), known, n=1)
                extra = f"; did you mean {hint[0]!r}?" if hint else ""
                raise PydanticCustomError(
                    "unknown_key",
                    "unknown key{__loc__}; allowed keys: {allowed}" + extra,
                    {"__key__": str(k), "__loc__": "", "allowed": ", ".join(known)},
                )
        return data


# ---- mechanisms: library ---------------------------------------------------


class Rpr3Args(Strict):
    """Planar 3-RPR: base and platform attachment points (3 points of 2 coordinates)."""

    base: Points(3, 2)
    platform: Points(3, 2)
    home: Numbers(3) | None = None


class Rpr4Args(Strict):
    """Planar 4-RPR (redundantly actuated): 4 base and 4 platform points."""

    base: Points(4, 2)
    platform: Points(4, 2)
    home: Numbers(3) | None = None


class Rrr3Args(Strict):
    """Planar 3-RRR: attachment points and link lengths (one for all legs, or 3)."""

    base: Points(3, 2)
    platform: Points(3, 2)
    proximal: Annotated[Any, PlainValidator(_number_or_numbers(3, True))]
    distal: Annotated[Any, PlainValidator(_number_or_numbers(3, True))]
    home: Numbers(3) | None = None


class FiveBarArgs(Strict):
    """Planar five-bar: ground link L0, proximal links L1, L4 and distal links L2, L3."""

    L0: PositiveNumber
    L1: PositiveNumber
    L2: PositiveNumber
    L3: PositiveNumber
    L4: PositiveNumber


class FourBarArgs(Strict):
    """Planar four-bar (Modern Robotics 7.3): crank L1, coupler L2, rocker L3, ground L4."""

    L1: PositiveNumber
    L2: PositiveNumber
    L3: PositiveNumber
    L4: PositiveNumber


class StewartGoughArgs(Strict):
    """6-UPS Stewart-Gough platform: 6 base points and 6 platform points in 3D."""

    base: Points(6, 3)
    platform: Points(6, 3)
    home: Numbers(6) | None = None


class DeltaArgs(Strict):
    """Delta robot: base radius, platform radius, upper (arm) and lower (forearm) lengths."""

    base_radius: PositiveNumber | None = None
    platform_radius: PositiveNumber | None = None
    upper: PositiveNumber | None = None
    lower: PositiveNumber | None = None


class Sr400Args(Strict):
    """Acma SR400, Table 7.1 of Khalil's chapter 7 (d9 = d3, d10 = -d8)."""

    d2: Number | None = None
    d3: PositiveNumber | None = None
    d4: Number | None = None
    d8: PositiveNumber | None = None
    rl4: Number | None = None


class Akr3000Args(Strict):
    """AKR-3000 painting robot, Table 7.2 of Khalil's chapter 7."""

    d3: PositiveNumber | None = None
    d4: PositiveNumber | None = None
    d7: PositiveNumber | None = None
    r8: Number | None = None
    d13: PositiveNumber | None = None
    d14: PositiveNumber | None = None
    gamma13: Number | None = None
    gamma14: Number | None = None


#: Argument models of the library mechanisms (name -> model). A library mechanism
#: without a model here still works; its arguments are then checked by the library.
LIBRARY_ARG_MODELS: dict[str, type[Strict]] = {
    "rpr3": Rpr3Args,
    "rpr4": Rpr4Args,
    "rrr3": Rrr3Args,
    "five_bar": FiveBarArgs,
    "four_bar": FourBarArgs,
    "stewart_gough": StewartGoughArgs,
    "delta": DeltaArgs,
    "sr400": Sr400Args,
    "akr3000": Akr3000Args,
}


class LibraryMechanism(Strict):
    """A mechanism of ``optkin.mechanisms.LIBRARY`` by name, with its arguments."""

    type: Literal["library"]
    name: Name
    args: dict[str, Any] = Field(default_factory=dict)



# ---- mechanisms: Khalil table ---------------------------------------------


class KhalilRow(Strict):
    """One frame j of a Khalil table (columns of Tables 7.1/7.2).

    ``a`` is the antecedent frame a(j) (0 = base), ``mu`` 1 for an actuated joint,
    ``sigma`` 0 revolute, 1 prismatic, 2 fixed frame. The joint variable column
    (``theta`` when sigma = 0, ``r`` when sigma = 1) holds the joint's name (or a number,
    a constant offset, the joint then being called ``theta<j>``/``r<j>``); the other
    columns hold numbers or expressions of the table's ``params`` (``"pi/2"``, ``"-d8"``).
    """

    a: NonNegInt
    mu: Annotated[int, PlainValidator(lambda v: _choice(v, (0, 1)))] = 0
    sigma: Annotated[int, PlainValidator(lambda v: _choice(v, (0, 1, 2)))] = 0
    gamma: NumberOrExpr = 0.0
    b: NumberOrExpr = 0.0
    alpha: NumberOrExpr = 0.0
    d: NumberOrExpr = 0.0
    theta: NumberOrExpr = 0.0
    r: NumberOrExpr = 0.0


def _choice(v: Any, allowed: tuple) -> Any:
    if isinstance(v, bool) or v not in allowed:
        raise _err("choice", "expected one of " + ", ".join(map(str, allowed)), v)
    return v


class KhalilMechanism(Strict):
    """A closed-chain robot by its Khalil table (Khalil & Dombre, chapter 7)."""

    type: Literal["khalil"]
    name: Name = "khalil"
    rows: Annotated[list[KhalilRow], Field(min_length=1)]
    loops: NonNegInt = 0
    params: dict[str, Number] = Field(default_factory=dict)
    end_effector: PositiveInt | None = None
    task: list[Literal["x", "y", "z", "rx", "ry", "rz"]] | None = None
    home: JointVector | None = None
    dof: PositiveInt | None = None


# ---- mechanisms: legs ------------------------------------------------------
#
# The leg types, the keys each takes (with how many numbers) and the platform kinds are
# the library's registries (optkin.mechanism.legs.LEG_TYPES, optkin.mechanism.platforms.
# PLATFORMS): a leg type or platform kind added there is accepted here.

#: The keys of a leg given by its screws (``optkin.Leg.from_screws``).
CHAIN_KEYS = ("screws", "home", "actuated", "joints", "name")


def _type_keys() -> tuple[str, ...]:
    """Every key some leg type takes besides base, platform and actuated (registry order)."""
    out: dict[str, None] = {}
    for lt in _LEG_REGISTRY.values():
        for k in lt.keys:
            out.setdefault(k, None)
    return tuple(out)


def _index_or_name(v: Any) -> int | str | list[int]:
    """A leg's actuated variable: its index or name (a type), or indices (screws)."""
    if isinstance(v, str):
        return v
    if isinstance(v, list):
        if not v:
            raise _err("actuated", "expected an index, a name or a non-empty list of indices", v)
        return _list_of(_nonneg_int, "indices")(v)
    return _nonneg_int(v)


def _screw_rows(v: Any) -> list[list[float]]:
    """Screws: a list of rows (omega, v) of 6 numbers."""
    return _list_of(_point(6), "screws (rows of 6 numbers)", min_n=1)(v)


def _home_matrix(v: Any) -> list[list[float]]:
    """A leg's home: the 4x4 pose of the platform frame with every joint at zero."""
    if not (isinstance(v, list) and v and all(isinstance(r, list) for r in v)):
        raise _err("matrix", "expected a 4x4 homogeneous matrix (4 rows of 4 numbers)", v)
    return _rigid(_list_of(_point(4), "rows of 4 numbers", n=4)(v))


def _leg_fields() -> dict[str, Any]:
    """The fields of a leg table, read from the registries."""
    fields: dict[str, Any] = {
        "type": (Literal[tuple(_LEG_REGISTRY)] | None, None),  # type: ignore[misc]
        "base": (Numbers() | None, None),
        "platform": (Numbers() | None, None),
    }
    for k in _type_keys():
        fields[k] = (Numbers(positive=k == "lengths") | None, None)
    fields["actuated"] = (Annotated[Any, PlainValidator(_index_or_name)], None)
    fields["screws"] = (Annotated[list[list[float]], PlainValidator(_screw_rows)] | None, None)
    fields["home"] = (Annotated[list[list[float]], PlainValidator(_home_matrix)] | None, None)
    fields["joints"] = (Str | None, None)
    fields["name"] = (Str | None, None)
    return fields


Leg = create_model(
    "Leg", __base__=Strict, __module__=__name__,
    __doc__="One leg: a leg type (``type``, ``base``, ``platform`` and the keys the type "
            "takes, see ``optkin.mechanism.legs.LEG_TYPES``) or a chain given by its screws "
            "(``screws``, ``home``, ``actuated``, optional ``joints`` and ``name``; "
            "``optkin.Leg.from_screws``).",
    **_leg_fields(),
)


class LegsMechanism(Strict):
    """A parallel robot as a platform carried by legs. ``platform`` is one of the platform
    kinds (``optkin.mechanism.platforms.PLATFORMS``); when left out, the kind of the legs'
    dimension whose degrees of freedom equal the number of actuated joints."""

    type: Literal["legs"]
    name: Name = "legs"
    platform: Literal[tuple(_PLATFORM_REGISTRY)] | None = None  # type: ignore[valid-type]
    legs: Annotated[list[Leg], Field(min_length=1)]  # type: ignore[valid-type]
    home: Numbers() | None = None
    redundant: Bool = False


MechanismSpec = Annotated[
    Union[LibraryMechanism, KhalilMechanism, LegsMechanism],  # noqa: UP007
    Field(discriminator="type"),
]


# ---- expected blocks -------------------------------------------------------


_VALUE_KEYS = ("value", "tol", "rtol", "wrap")


def _expected_value(v: Any) -> Any:
    """An expected value: number, boolean, string, (nested) list of numbers, or a
    table ``{value = 1.2, tol = 1e-3, rtol = 0, wrap = true}`` (``wrap`` compares
    angles modulo 2 pi)."""
    if isinstance(v, dict):
        for k in v:
            if k not in _VALUE_KEYS:
                raise PydanticCustomError(
                    "unknown_key", "{__loc__}unknown key; allowed keys: " + ", ".join(_VALUE_KEYS),
                    {"__loc__": f"[{k!r}]"},
                )
        if "value" not in v:
            raise PydanticCustomError("missing", "{__loc__}missing required key", {"__loc__": ".value"})
        out = {"value": _expected_value(v["value"])}
        if isinstance(out["value"], dict):
            raise _err("expected_value", "expected a number, list, boolean or string", v["value"])
        for k, check in (("tol", _positive), ("rtol", _nonneg), ("wrap", _boolean)):
            if k in v:
                try:
                    out[k] = check(v[k])
                except PydanticCustomError as e:
                    raise PydanticCustomError(
                        "item", "{__loc__}" + e.message(), {"__loc__": f".{k}"}
                    ) from None
        return out
    if isinstance(v, (bool, str)):
        return v
    if _is_number(v):
        return _number(v)
    if isinstance(v, list):
        out_list = []
        for i, x in enumerate(v):
            try:
                out_list.append(_expected_value(x) if isinstance(x, list) else _number(x))
            except PydanticCustomError as e:
                raise PydanticCustomError("item", "{__loc__}" + e.message(), {"__loc__": f"[{i}]"}) from None
        return out_list
    raise _err("expected_value", "expected a number, list, boolean, string or table", v)


def _path(v: Any) -> str:
    s = _string(v)
    try:
        parse_value_path(s)
    except ValueError as e:
        raise PydanticCustomError("value_path", str(e)) from None
    return s


class Check(Strict):
    """One value check: ``{ path = "solutions[any].qa", value = [..], tol = 1e-6 }``."""

    path: Annotated[str, PlainValidator(_path)]
    value: Annotated[Any, PlainValidator(_expected_value)]
    tol: PositiveNumber | None = None
    rtol: NonNegNumber | None = None
    wrap: Bool = False


class Expected(Strict):
    """What a task must produce; checked by the runner (pass/fail per task).

    ``values`` maps result paths (``"q[theta3]"``, ``"pose[0][3]"``,
    ``"solutions[any].qa"``, ``"solutions[*].success"``) to expected values;
    ``checks`` lists the same as tables (use it to check one path several times).
    """

    success: Bool | None = None
    status: Str | None = None
    count: NonNegInt | None = None
    min_count: NonNegInt | None = None
    max_count: NonNegInt | None = None
    values: dict[str, Annotated[Any, PlainValidator(_expected_value)]] = Field(default_factory=dict)
    checks: list[Check] = Field(default_factory=list)
    tol: PositiveNumber = 1e-6
    rtol: NonNegNumber = 0.0
    source: Str | None = None

    @model_validator(mode="after")
    def _paths(self) -> "Expected":
        for k in self.values:
            try:
                parse_value_path(k)
            except ValueError as e:
                raise PydanticCustomError(
                    "value_path", "{__loc__}" + str(e), {"__loc__": f".values[{k!r}]"}
                ) from None
        return self


# ---- tasks -----------------------------------------------------------------

Scalar = Annotated[Any, PlainValidator(lambda v: _scalar_option(v))]


def _scalar_option(v: Any) -> Any:
    if isinstance(v, (bool, str)) or _is_number(v):
        return v
    raise _err("option", "expected a number, string or boolean", v)


def _time_limit(v: Any) -> float:
    x = _positive(v)
    if x > MAX_TIME_LIMIT:
        raise _err("time_limit", f"expected at most {MAX_TIME_LIMIT:g} seconds", v)
    return x


class TaskBase(Strict):
    """Keys shared by every task: a label, solver options, the expected block and the
    task's wall-time limit in seconds (default: the run's ``--time-limit``, 600 s)."""

    name: Str | None = None
    options: dict[str, Scalar] = Field(default_factory=dict)
    expected: Expected | None = None
    time_limit: Annotated[float, PlainValidator(_time_limit)] | None = None


class ForwardTask(TaskBase):
    """Forward (direct) kinematics: actuated joint values -> configuration and pose."""

    kind: Literal["forward"]
    qa: JointVector
    guess: JointVector | None = None
    draw: Bool = True


class InverseTask(TaskBase):
    """Inverse kinematics: end-effector pose -> actuated joints, one per posture."""

    kind: Literal["inverse"]
    pose: Pose
    draw: Bool = True


class AssemblyModesTask(TaskBase):
    """All assembly modes (forward solutions) for given actuated joint values."""

    kind: Literal["assembly_modes"]
    qa: JointVector
    seed: NonNegInt = 0
    draw: Bool = True


class TrackTask(TaskBase):
    """Follow a path of actuated joint values, continuing one assembly mode."""

    kind: Literal["track"]
    qa_path: Annotated[list[list[float]], PlainValidator(
        _list_of(_list_of(_number, "numbers"), "points", min_n=1))]
    guess: JointVector | None = None


class JacobiansTask(TaskBase):
    """Jacobians (W_a, W_p, [7.49]) at a configuration given by q, or solved from qa."""

    kind: Literal["jacobians"]
    q: JointVector | None = None
    qa: JointVector | None = None


class DofTask(TaskBase):
    """Degrees of freedom (rank of the constraint Jacobian, [7.57])."""

    kind: Literal["dof"]
    q: JointVector | None = None


class ClassifyTask(TaskBase):
    """Classify a configuration (serial / parallel / internal singularity)."""

    kind: Literal["classify"]
    q: JointVector | None = None
    qa: JointVector | None = None


def _range(v: Any) -> list[float]:
    """A range [low, high] with low < high."""
    lo, hi = _point(2)(v)
    if not lo < hi:
        raise PydanticCustomError("range", "expected a range [low, high] with low < high, got "
                                  "[{lo}, {hi}]", {"lo": f"{lo:g}", "hi": f"{hi:g}"})
    return [lo, hi]


_Ranges = Annotated[list[list[float]], PlainValidator(_list_of(_range, "ranges [low, high]"))]
_Section = dict[str, Number]
_Limits = dict[str, Annotated[list[float], PlainValidator(_range)]]


class SingularCurvesTask(TaskBase):
    """Singular curves traced by continuation (``optkin.singular_curves``): ``plane``
    ("joint", "workspace" or two coordinate names), ``curves`` (the singularity kind:
    "parallel", "serial", "limit", "closure", "all" or a list), ``fixed`` (a section,
    ``{ phi = 0.5 }``), ``limits`` (``{ "L1.theta1" = [lo, hi] }``), ``grid`` (seeding grid
    only), ``bounds`` (a box in the plane)."""

    kind: Literal["singular_curves"]
    plane: Str | Annotated[list[str], PlainValidator(_list_of(_string, "names", n=2))] = "joint"
    curves: Str | Annotated[list[str], PlainValidator(_list_of(_string, "kinds"))] = "parallel"
    fixed: _Section | None = None
    limits: _Limits | None = None
    grid: PositiveInt | None = None
    bounds: _Ranges | None = None


class WorkingModesTask(TaskBase):
    """Working modes (signs of the B_jj, Chablat & Wenger) of the mechanism."""

    kind: Literal["working_modes"]
    pose: Pose | None = None


class AspectsTask(TaskBase):
    """Generalized aspects per working mode (``optkin.aspects``): ``fixed`` (a section at
    fixed phi for 3-DoF platforms), ``limits``, ``grid`` (seeding only), ``bounds``."""

    kind: Literal["aspects"]
    fixed: _Section | None = None
    limits: _Limits | None = None
    grid: PositiveInt | None = None
    bounds: _Ranges | None = None


class WorkspaceTask(TaskBase):
    """Reachable workspace per working mode and its area (``optkin.workspace``)."""

    kind: Literal["workspace"]
    fixed: _Section | None = None
    limits: _Limits | None = None
    grid: PositiveInt | None = None
    bounds: _Ranges | None = None


def _statics_limits(v: Any) -> float | list:
    """A bound for every actuator, one bound each, or one pair [lo, hi] each."""
    if _is_number(v):
        return _nonneg(v)
    if isinstance(v, list) and v and all(isinstance(x, list) for x in v):
        return _list_of(_range, "pairs [lo, hi]", min_n=1)(v)
    if isinstance(v, list):
        return _list_of(_nonneg, "numbers >= 0", min_n=1)(v)
    raise _err("limits", "expected a number, a list of bounds or a list of pairs [lo, hi]", v)


def _statics_directions(v: Any) -> list:
    """Wrench directions: lists of numbers, or component names such as "fx", "-mz"."""
    def one(d: Any) -> Any:
        if isinstance(d, str):
            if not re.fullmatch(r"[+-]?[fm][xyz]", d):
                raise _err("direction", "expected a component name like 'fx' or '-mz'", d)
            return d
        return _list_of(_number, "numbers", min_n=1)(d)

    return _list_of(one, "directions", min_n=1)(v)


def _statics_norm(v: Any) -> str:
    if v in (2, "2"):
        return "2"
    if v == "inf":
        return "inf"
    raise _err("norm", "expected 2 or \"inf\"", v)


class StaticsTask(TaskBase):
    """Statics (``optkin.statics``) at a configuration given by ``q``, ``qa`` (solved by
    forward first) or ``pose`` (solved by inverse, posture ``posture``):

    * ``analysis = "capability"``: ``limits``, optional ``directions`` (default +-each
      component); a capability-polygon picture when ``draw`` (planar platforms);
    * ``analysis = "feasible"``: ``limits`` and a wrench set: ``wrench`` (one wrench),
      ``wrench_lower`` + ``wrench_upper`` (a box) or ``wrench_vertices``;
    * ``analysis = "distribute"``: ``wrench``, optional ``limits``, ``norm`` (2 or "inf").
    """

    kind: Literal["statics"]
    analysis: Literal["capability", "feasible", "distribute"] = "capability"
    qa: JointVector | None = None
    q: JointVector | None = None
    pose: Pose | None = None
    posture: NonNegInt = 0
    limits: Annotated[Any, PlainValidator(_statics_limits)] | None = None
    directions: Annotated[list, PlainValidator(_statics_directions)] | None = None
    wrench: Numbers(min_n=1) | None = None
    wrench_lower: Numbers(min_n=1) | None = None
    wrench_upper: Numbers(min_n=1) | None = None
    wrench_vertices: Annotated[list[list[float]], PlainValidator(
        _list_of(_list_of(_number, "numbers", min_n=1), "wrenches", min_n=1))] | None = None
    norm: Annotated[str, PlainValidator(_statics_norm)] = "2"
    draw: Bool = True

    @model_validator(mode="after")
    def _needs(self) -> "StaticsTask":
        def fail(key: str, msg: str) -> PydanticCustomError:
            return PydanticCustomError("statics", "{__loc__}" + msg, {"__loc__": f"[{key!r}]"})

        if sum(x is not None for x in (self.q, self.qa, self.pose)) != 1:
            raise fail("q", "give exactly one of q, qa or pose (the configuration)")
        if self.analysis in ("capability", "feasible") and self.limits is None:
            raise fail("limits", f"required for analysis = {self.analysis!r}")
        if self.analysis == "distribute" and self.wrench is None:
            raise fail("wrench", "required for analysis = 'distribute'")
        if self.analysis == "feasible":
            given = [self.wrench is not None, self.wrench_vertices is not None,
                     self.wrench_lower is not None or self.wrench_upper is not None]
            if sum(given) != 1:
                raise fail("wrench", "give one wrench set: wrench, wrench_vertices, or "
                           "wrench_lower with wrench_upper")
            if given[2] and (self.wrench_lower is None or self.wrench_upper is None):
                raise fail("wrench_upper", "a wrench box needs wrench_lower and wrench_upper")
        return self


class MeasureSpec(Strict):
    """A design measure (``optkin.design``): ``measure`` ("gci", "min_conditioning",
    "largest_inscribed", "aspect_area", "dimension"), its region (``region = { centre =
    [x, y], radius = r }`` or ``{ lo = [x, y], hi = [x, y] }``), ``mode`` (the working
    mode), ``fixed`` (the orientation of a 3-DoF platform), ``length``, ``order``;
    largest inscribed shapes: ``shape`` (and a box's ``aspect``), ``centre`` or ``line = [[x, y], [dx, dy], [lo,
    hi]]``, ``gamma``, ``limits``, ``bounds``; aspect areas: ``seed``; dimensions: ``of =
    { name = coefficient }``; joint ranges: ``joint`` (default: the largest); force
    capability and leg strokes over a box of poses ``region = { lo = [...], hi = [...] }``
    (every task coordinate) on an ``n``-point grid per coordinate, ``fmax``. As an objective ``sense = "max"`` or ``"min"``; as a
    constraint ``at_least`` or ``at_most``."""

    measure: Literal["gci", "min_conditioning", "largest_inscribed", "aspect_area",
                     "dimension", "joint_range", "force_capability", "leg_stroke"]
    region: dict[str, Annotated[list[float], PlainValidator(_list_of(_number, "numbers"))]
                 | Number] | None = None
    mode: Annotated[list[float], PlainValidator(_list_of(_number, "signs"))] | None = None
    fixed: dict[str, Number] | None = None
    length: Number = 1.0
    order: PositiveInt = 12
    shape: Literal["disc", "square", "box"] = "disc"
    aspect: Numbers(n=2) = Field(default_factory=lambda: [1.0, 1.0])
    centre: Numbers(n=2) | None = None
    line: Annotated[list[list[float]], PlainValidator(
        _list_of(_list_of(_number, "numbers", n=2), "[point, direction, range]", n=3))] | None \
        = None
    gamma: Number = 0.0
    limits: dict[str, Annotated[list[float], PlainValidator(_range)]] | None = None
    bounds: _Ranges | None = None
    seed: Numbers(n=2) | None = None
    of: dict[str, Number] | None = None
    joint: Str | None = None
    fmax: Number = 1.0
    n: PositiveInt = 3
    sense: Literal["max", "min"] | None = None
    at_least: Number | None = None
    at_most: Number | None = None


class EqualSpec(Strict):
    """A linear equality among design variables: sum of coefficient x variable = value."""

    coefficients: dict[str, Number]
    value: Number


class DesignTask(TaskBase):
    """Dimensional synthesis (``optkin.design``): ``family`` (a factory of
    ``optkin.mechanisms``), ``fixed`` (its constant arguments), ``variables`` ({ name = [lo,
    hi] }), ``equal`` (linear equalities); ``analysis = "optimize"`` with ``objective``
    and ``constraints`` (measures, :class:`MeasureSpec`), or ``"atlas"`` with ``measures``
    (a table name -> measure) over an ``n`` x ``n`` grid."""

    kind: Literal["design"]
    analysis: Literal["optimize", "atlas"] = "optimize"
    family: Str
    fixed: dict[str, Number] = Field(default_factory=dict)
    variables: dict[str, Annotated[list[float], PlainValidator(_range)]]
    equal: list[EqualSpec] = Field(default_factory=list)
    objective: MeasureSpec | None = None
    constraints: list[MeasureSpec] = Field(default_factory=list)
    measures: dict[str, MeasureSpec] | None = None
    n: PositiveInt = 40
    seed: NonNegInt = 0
    maxiter: PositiveInt = 40
    popsize: PositiveInt = 12
    draw: Bool = True

    @model_validator(mode="after")
    def _needs(self) -> "DesignTask":
        def fail(key: str, msg: str) -> PydanticCustomError:
            return PydanticCustomError("design", "{__loc__}" + msg, {"__loc__": f"[{key!r}]"})

        if self.analysis == "optimize":
            if self.objective is None:
                raise fail("objective", "required for analysis = 'optimize'")
            if self.objective.sense is None:
                raise fail("objective", "give sense = 'max' or 'min'")
            for i, c in enumerate(self.constraints):
                if (c.at_least is None) == (c.at_most is None):
                    raise fail("constraints", f"[{i}]: give exactly one of at_least, at_most")
        elif not self.measures:
            raise fail("measures", "required for analysis = 'atlas'")
        return self


#: Task kind -> its parameter model. Later issues add their kinds here.
TASK_MODELS: dict[str, type[TaskBase]] = {
    "forward": ForwardTask,
    "inverse": InverseTask,
    "assembly_modes": AssemblyModesTask,
    "track": TrackTask,
    "jacobians": JacobiansTask,
    "dof": DofTask,
    "classify": ClassifyTask,
    "singular_curves": SingularCurvesTask,
    "working_modes": WorkingModesTask,
    "aspects": AspectsTask,
    "workspace": WorkspaceTask,
    "statics": StaticsTask,
    "design": DesignTask,
}
TASK_KINDS: tuple[str, ...] = tuple(TASK_MODELS)


def task_union() -> Any:
    """The discriminated union of every registered task model (on ``kind``)."""
    return Annotated[Union[tuple(TASK_MODELS.values())], Field(discriminator="kind")]  # noqa: UP007


class ProblemFile(Strict):
    """The whole file: ``schema_version``, ``[mechanism]`` and ``[[task]]``."""

    schema_version: Literal[1]
    name: Str | None = None
    description: Str = ""
    source: Str | None = None
    mechanism: MechanismSpec
    task: Annotated[list[task_union()], Field(min_length=1)]


# ---------------------------------------------------------------------------
# errors: pydantic -> "file: key.path: message"
# ---------------------------------------------------------------------------

_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")


def format_key_path(loc: Sequence[Any]) -> str:
    """``("task", 2, "grid")`` -> ``"task[2].grid"``; odd keys are quoted."""
    out = ""
    for p in loc:
        if isinstance(p, int):
            out += f"[{p}]"
        elif _IDENT.match(str(p)):
            out += ("." if out else "") + str(p)
        else:
            out += f"[{str(p)!r}]"
    return out or "(top level)"


_TAGS = {"library", "khalil", "legs"}

_GENERIC = {
    "missing": "missing required key",
    "int_type": "expected an integer",
    "float_type": "expected a number",
    "string_type": "expected a string",
    "bool_type": "expected true or false",
    "list_type": "expected a list",
    "dict_type": "expected a table",
    "model_type": "expected a table",
    "model_attributes_type": "expected a table",
    "extra_forbidden": "unknown key",
    "finite_number": "expected a finite number",
}


def _message(err: Mapping[str, Any]) -> tuple[list[Any], str]:
    """Key path and plain message of one pydantic error."""
    loc = list(err.get("loc", ()))
    # discriminated unions put the tag into the path: mechanism.khalil.rows -> mechanism.rows
    if len(loc) >= 2 and loc[0] == "mechanism" and loc[1] in _TAGS:
        del loc[1]
    if (len(loc) >= 3 and loc[0] == "task" and isinstance(loc[1], int)
            and loc[2] in TASK_MODELS):
        del loc[2]
    ctx = dict(err.get("ctx") or {})
    typ = err.get("type", "")
    msg = str(err.get("msg", ""))
    if "__key__" in ctx:
        loc.append(ctx["__key__"])
    if "__loc__" in ctx:
        # our validators prefix their message with a location suffix: "[1][0]expected ..."
        m = _LOC_PREFIX.match(msg)
        if m:
            loc.extend(_split_suffix(m.group(0)))
            msg = msg[m.end():]
    is_task = len(loc) == 2 and loc[0] == "task"
    if typ == "union_tag_invalid" and is_task:
        hint = difflib.get_close_matches(str(ctx.get("tag")), TASK_KINDS, n=1)
        extra = f"; did you mean {hint[0]!r}?" if hint else ""
        inp = err.get("input")
        got = inp.get("kind") if isinstance(inp, dict) else ctx.get("tag")
        msg = f"unknown task kind {_show(got)}; known kinds: {', '.join(TASK_KINDS)}{extra}"
        loc.append("kind")
    elif typ == "union_tag_not_found" and is_task:
        msg = f"missing required key (the task kind, one of: {', '.join(TASK_KINDS)})"
        loc.append("kind")
    elif typ == "list_type" and loc == ["task"]:
        msg = f"expected one or more [[task]] tables, got {_show(err.get('input'))}"
    elif typ == "union_tag_invalid":
        tags = ", ".join(repr(t) for t in sorted(_TAGS))
        msg = f"unknown mechanism type {_show(ctx.get('tag'))}; expected one of {tags}"
        loc.append("type")
    elif typ == "union_tag_not_found":
        msg = "missing required key 'type' (one of 'library', 'khalil', 'legs')"
        loc.append("type")
    elif typ == "literal_error":
        msg = f"expected {ctx.get('expected')}, got {_show(err.get('input'))}"
    elif typ in ("too_short", "too_long"):
        n = ctx.get("min_length") if typ == "too_short" else ctx.get("max_length")
        msg = f"expected {'at least' if typ == 'too_short' else 'at most'} {n} item(s), got {ctx.get('actual_length')}"
    elif typ in _GENERIC:
        msg = _GENERIC[typ]
        if typ not in ("missing", "extra_forbidden"):
            msg += f", got {_show(err.get('input'))}"
    return loc, msg


_LOC_PREFIX = re.compile(r"(?:\[\d+\]|\['(?:[^'\\]|\\.)*'\]|\[\"[^\"]*\"\]|\.[A-Za-z_][A-Za-z0-9_]*)+")


def _split_suffix(s: str) -> list[Any]:
    out: list[Any] = []
    for m in re.finditer(r"\[(\d+)\]|\[('(?:[^'\\]|\\.)*'|\"[^\"]*\")\]|\.([A-Za-z_][A-Za-z0-9_]*)", s):
        if m.group(1) is not None:
            out.append(int(m.group(1)))
        elif m.group(2) is not None:
            out.append(ast.literal_eval(m.group(2)))
        else:
            out.append(m.group(3))
    return out


def _convert(e: ValidationError, filename: str) -> ProblemFileError:
    lines = []
    seen = set()
    for err in e.errors(include_url=False):
        loc, msg = _message(err)
        line = f"{filename}: {format_key_path(loc)}: {msg}"
        if line not in seen:
            seen.add(line)
            lines.append(line)
    return ProblemFileError("\n".join(lines))


# ---------------------------------------------------------------------------
# loading
# ---------------------------------------------------------------------------


def problem_json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of a problem file, as data read from TOML: what
    ``optkin schema`` prints (from the pydantic model :class:`ProblemFile`)."""
    sch = ProblemFile.model_json_schema()
    return {"$schema": "https://json-schema.org/draft/2020-12/schema",
            "$id": "https://optkin.invalid/problem-file.schema.json",
            **{k: v for k, v in sch.items() if k != "title"},
            "title": "optkin problem file"}


@dataclass(frozen=True)
class Problem:
    """A validated problem file: its model, the raw document and where it came from."""

    path: Path
    display: str
    spec: ProblemFile
    document: dict[str, Any]
    data: bytes
    hash: str
    mechanism: Any = field(default=None, compare=False, repr=False)

    @property
    def tasks(self) -> list[TaskBase]:
        return list(self.spec.task)


def validate_document(doc: Any, filename: str = "<problem>") -> ProblemFile:
    """Validate a parsed document against the schema (no library calls).

    Raises
    ------
    ProblemFileError
        One line per problem, each ``file: key.path: message``.
    """
    if not isinstance(doc, dict):
        raise ProblemFileError(f"{filename}: (top level): expected a table, got {_show(doc)}")
    if "schema_version" not in doc:
        raise ProblemFileError(
            f"{filename}: schema_version: missing required key; add 'schema_version = 1' at the top"
        )
    sv = doc.get("schema_version")
    if sv != SCHEMA_VERSION or isinstance(sv, bool):
        raise ProblemFileError(
            f"{filename}: schema_version: this optkin reads schema version {SCHEMA_VERSION}, "
            f"got {_show(sv)}"
        )
    try:
        spec = ProblemFile.model_validate(doc)
    except ValidationError as e:
        raise _convert(e, filename) from None
    except (RecursionError, TypeError, ValueError) as e:  # defensive: never leak others
        raise ProblemFileError(f"{filename}: (top level): cannot validate: {e}") from None
    if isinstance(spec.mechanism, LibraryMechanism):
        library_args(spec.mechanism, filename)
    return spec


def library_args(m: LibraryMechanism, filename: str) -> dict[str, Any]:
    """The arguments of a library mechanism, checked against its model when there is one."""
    args = dict(m.args)
    model = LIBRARY_ARG_MODELS.get(m.name)
    if model is None:
        return args
    try:
        parsed = model.model_validate(args)
    except ValidationError as e:
        err = _convert(e, filename)
        lines = [_prefix_args(line, filename) for line in str(err).splitlines()]
        raise ProblemFileError("\n".join(lines)) from None
    return {k: v for k, v in parsed.model_dump(exclude_none=True).items() if k in args}


def load_problem(path: str | Path, display: str | None = None, check: bool = True) -> Problem:
    """Read, parse and validate one problem file.

    With ``check`` (default) the semantic checks of :func:`check_problem` run too
    and the built mechanism is kept on ``problem.mechanism``.
    """
    path = Path(path)
    name = display or path.name
    try:
        data = path.read_bytes()
    except OSError as e:
        raise ProblemFileError(f"{name}: (file): cannot read: {e.strerror or e}") from None
    return load_problem_bytes(data, name, path=path, check=check)


def load_problem_bytes(
    data: bytes, display: str, path: str | Path | None = None, check: bool = True
) -> Problem:
    """Like :func:`load_problem` on bytes already read (used by remote workers)."""
    doc = parse_toml(data, display)
    spec = validate_document(doc, display)
    mech = check_problem(spec, display) if check else None
    return Problem(
        path=Path(path) if path is not None else Path(display),
        display=display,
        spec=spec,
        document=doc,
        data=data,
        hash=input_hash(data),
        mechanism=mech,
    )


# ---------------------------------------------------------------------------
# checks a schema cannot express
# ---------------------------------------------------------------------------

def _fail(filename: str, loc: Sequence[Any], msg: str) -> ProblemFileError:
    return ProblemFileError(f"{filename}: {format_key_path(loc)}: {msg}")


def _check_khalil(m: KhalilMechanism, fn: str) -> None:
    rows = m.rows
    n = len(rows)
    names: dict[str, int] = {}
    B = m.loops
    if 2 * B > n:
        raise _fail(fn, ["mechanism", "loops"],
                    f"{B} loop(s) need {2 * B} rows at the end of the table (the cut joints, "
                    f"then their partner frames), but the table has only {n} rows")
    for i, row in enumerate(rows):
        j = i + 1
        base = ["mechanism", "rows", i]
        if row.a >= j:
            raise _fail(fn, base + ["a"],
                        f"frame {j} names parent a({j}) = {row.a}, which is not defined "
                        f"before it; a(j) must be smaller than j (0 is the base)")
        var = {0: "theta", 1: "r"}.get(row.sigma)
        for col in ("gamma", "b", "alpha", "d", "theta", "r"):
            v = getattr(row, col)
            if col == var and not (isinstance(v, str) and _IDENT.match(v)
                                   and v not in m.params and v != "pi"):
                v = f"{col}{j}"  # a number (or parameter expression): a constant offset
                if v in names:
                    raise _fail(fn, base + [col],
                                f"the default joint name {v!r} is already used by "
                                f"rows[{names[v]}]; give this joint a name")
                names[v] = i
                continue
            if col == var:
                if v in names:
                    raise _fail(fn, base + [col],
                                f"joint name {v!r} is already used by rows[{names[v]}]")
                names[v] = i
            # expressions are read (and their errors located) by the library's evaluator
        if row.sigma == 2 and row.mu == 1:
            raise _fail(fn, base + ["mu"], f"frame {j} is a fixed frame (sigma = 2) and cannot be actuated")
    if B:
        first_cut = n - 2 * B
        for k in range(B):
            cut, partner = first_cut + k, first_cut + B + k
            if rows[cut].sigma == 2:
                raise _fail(fn, ["mechanism", "rows", cut, "sigma"],
                            f"with loops = {B}, rows[{cut}] (frame {cut + 1}) is a cut joint and "
                            f"must be revolute or prismatic (sigma 0 or 1), got 2")
            if rows[cut].mu == 1:
                raise _fail(fn, ["mechanism", "rows", cut, "mu"],
                            f"with loops = {B}, rows[{cut}] (frame {cut + 1}) is a cut joint; "
                            f"cut joints are passive (mu = 0)")
            if rows[partner].sigma != 2:
                raise _fail(fn, ["mechanism", "rows", partner, "sigma"],
                            f"with loops = {B}, rows[{partner}] (frame {partner + 1}) is the "
                            f"partner frame of the cut joint {cut + 1} and must be a fixed frame "
                            f"(sigma = 2), got {rows[partner].sigma}")
    if not any(r.mu == 1 and r.sigma != 2 for r in rows):
        raise _fail(fn, ["mechanism", "rows"], "no actuated joint: set mu = 1 on the actuated rows")
    if m.end_effector is not None and m.end_effector > n:
        raise _fail(fn, ["mechanism", "end_effector"],
                    f"frame {m.end_effector} does not exist (the table has frames 1..{n})")


def _platform_of(m: LegsMechanism, fn: str) -> str:
    """The platform kind: as given, else the kind of the legs' dimension whose degrees of
    freedom equal the number of actuated joints (one kind, else the file must say)."""
    if m.platform is not None:
        return m.platform
    dims = {_leg_dim(leg) for leg in m.legs}
    n_act = sum(_n_actuated(leg) for leg in m.legs)
    fits = [name for name, p in _PLATFORM_REGISTRY.items()
            if p.space_dim in dims and p.dof == n_act]
    if len(dims) != 1 or len(fits) != 1 or m.redundant:
        raise _fail(fn, ["mechanism", "platform"],
                    "missing required key (the platform kind, one of: "
                    f"{', '.join(_PLATFORM_REGISTRY)}); it cannot be told from the legs")
    return fits[0]


def _leg_dim(leg: Any) -> int | None:
    if leg.type is not None:
        return _LEG_REGISTRY[leg.type].dim
    return None  # a chain: its dimension follows from its screws


def _n_actuated(leg: Any) -> int:
    """How many actuated joints a leg table declares (a type: one)."""
    if leg.screws is not None and isinstance(leg.actuated, list):
        return len(leg.actuated)
    return 1


def _given(leg: Any, keys: Sequence[str]) -> list[str]:
    return [k for k in keys if getattr(leg, k) is not None]


def _check_chain_leg(leg: Any, loc: list[Any]) -> list[str]:
    """A leg given by its screws: only the chain's keys; home and actuated present."""
    other = _given(leg, [k for k in type(leg).model_fields if k not in CHAIN_KEYS])
    if other:
        return [loc + [other[0]], f"unknown key for a leg given by its screws; it takes "
                f"{', '.join(CHAIN_KEYS)} (or give a leg type instead of screws)"]
    for key in ("home", "actuated"):
        if getattr(leg, key) is None:
            return [loc + [key], "missing required key (a leg given by its screws needs "
                    "screws, home and actuated)"]
    return []


def _check_type_leg(leg: Any, dim: int, platform: str, loc: list[Any]) -> list[Any]:
    """A leg of a registered type: fits the platform, takes the type's keys with as many
    numbers as the type says ("lengths": the link lengths, possibly none)."""
    if leg.type is None:
        return [loc + ["type"], f"missing required key (a leg type, one of: "
                f"{', '.join(_LEG_REGISTRY)}; or the leg's screws, home and actuated)"]
    lt = _LEG_REGISTRY[leg.type]
    if lt.dim != dim:
        return [loc + ["type"], f"a {leg.type} leg does not fit a {platform} platform"]
    chain = _given(leg, [k for k in CHAIN_KEYS if k != "actuated"])
    if chain:
        return [loc + [chain[0]], f"unknown key for a {leg.type} leg (a leg type takes "
                f"type, base, platform, actuated{''.join(', ' + k for k in lt.keys)}; "
                "screws, home, joints and name describe a leg without a type)"]
    for key in ("base", "platform"):
        pts = getattr(leg, key)
        if pts is None:
            return [loc + [key], f"missing required key (the joint centre, {dim} numbers)"]
        if len(pts) != dim:
            return [loc + [key], f"expected {dim} numbers, got {len(pts)}"]
    # the keys other than the link lengths tell the types apart
    given = set(_given(leg, [k for k in _type_keys() if k != "lengths"]))

    def fits(t: Any) -> bool:
        need = {k for k in t.keys if k != "lengths" and k not in t.optional}
        return t.dim == dim and need <= given <= set(t.keys)

    if not fits(lt):
        extra = sorted(given - set(lt.keys))
        if extra:
            return [loc + [extra[0]], f"unknown key for a {leg.type} leg; it takes type, base, "
                    f"platform, actuated{''.join(', ' + k for k in lt.keys)}"]
        need = [k for k in lt.keys if k != "lengths" and k not in lt.optional
                and k not in given]
        what = " and ".join(f"{k} ({lt.doc.get(k, str(lt.keys[k]) + ' numbers')})"
                            for k in need)
        others = [n for n, t in _LEG_REGISTRY.items() if fits(t)]
        if others:
            keys = ", ".join(["base", "platform", *sorted(given), "lengths"])
            return [loc + ["type"], f"expected {' or '.join(repr(o) for o in others)} (the "
                    f"leg types that take {keys}), got {leg.type!r}, which also needs {what}"]
        return [loc + [need[0]], f"missing required key: a {leg.type} leg needs {what}"]
    nl = lt.keys.get("lengths", 0)
    got = len(leg.lengths or [])
    if got != nl:
        return [loc + ["lengths"], f"a {leg.type} leg has {nl} link length(s), got {got}"]
    for key, n in lt.keys.items():
        v = getattr(leg, key)
        if key != "lengths" and v is not None and len(v) != n:
            return [loc + [key], f"expected {n} numbers ({lt.doc.get(key, key)}), got {len(v)}"]
    return []


def _check_legs(m: LegsMechanism, fn: str) -> str:
    """Each leg against the registries, then the number of actuated joints against the
    platform's degrees of freedom; returns the platform kind."""
    platform = _platform_of(m, fn)
    plat = _PLATFORM_REGISTRY[platform]
    dim = plat.space_dim
    for i, leg in enumerate(m.legs):
        loc = ["mechanism", "legs", i]
        if leg.screws is not None:
            bad = _check_chain_leg(leg, loc)
        else:
            bad = _check_type_leg(leg, dim, platform, loc)
        if bad:
            raise _fail(fn, bad[0], bad[1])
    n_act = sum(_n_actuated(leg) for leg in m.legs)
    dof = plat.dof
    if (n_act > dof) if m.redundant else (n_act == dof):
        return platform
    # legs that reach the platform frame may have fewer actuated joints than the
    # platform's freedoms (their chains constrain it): the library decides
    try:
        validate_legs([_leg_spec(leg) for leg in m.legs], platform, redundant=m.redundant)
    except MechanismError as e:
        if tuple(getattr(e, "path", ())) != ("legs",):
            raise
        one = all(_n_actuated(leg) == 1 for leg in m.legs)
        what, got = ("legs", len(m.legs)) if one else ("actuated joints", n_act)
        if m.redundant:
            raise _fail(fn, ["mechanism", "legs"],
                        f"a redundantly actuated {platform} platform needs more than {dof} "
                        f"{'actuated legs' if one else what}, got {got}") from None
        extra = "; set redundant = true for redundant actuation" if n_act > dof else ""
        raise _fail(fn, ["mechanism", "legs"],
                    f"a {platform} platform needs {dof} {what}, got {got}{extra}") from None
    return platform


def _leg_spec(leg: Any) -> dict[str, Any]:
    """The mapping ``optkin.Leg.from_spec`` takes (keys the leg left out omitted)."""
    d = leg.model_dump(exclude_none=True)
    if leg.type is not None and "lengths" not in _LEG_REGISTRY[leg.type].keys \
            and not d.get("lengths", [0]):
        del d["lengths"]  # an empty list of link lengths for a type without any
    return d


_ROW_IN_MESSAGE = re.compile(r"^row (\d+) \(frame j=\d+\)(?:, column (\w+))?:\s*(.*)$", re.S)
_PATH_IN_MESSAGE = re.compile(r"^([A-Za-z_]\w*(?:\[\d+\])*(?:\.[A-Za-z_]\w*(?:\[\d+\])*)*):\s*(.*)$", re.S)


def _mechanism_error(e: Exception, spec: ProblemFile, fn: str) -> ProblemFileError:
    """A MechanismError (or other library complaint) as ``file: mechanism.<path>: msg``.

    The library names rows as ``row J (frame j=J)`` (1-based) and other items as key
    paths (``legs[2].base``); both are mapped onto the file's key paths.
    """
    msg = str(e).strip() or type(e).__name__
    m = spec.mechanism
    prefix = "mechanism.args" if isinstance(m, LibraryMechanism) else "mechanism"
    path = tuple(getattr(e, "path", ()) or ())
    if path:  # the library says where: keep only the explanation from its message
        r = _ROW_IN_MESSAGE.match(msg)
        text = r.group(3) if r else msg
        where = format_key_path(path)
        if text.startswith(where + ": "):  # the library's message names the path too
            text = text[len(where) + 2:]
        return ProblemFileError(f"{fn}: {prefix}.{where}: {text}")
    r = _ROW_IN_MESSAGE.match(msg)
    if r:
        path = f"rows[{int(r.group(1)) - 1}]" + (f".{r.group(2)}" if r.group(2) else "")
        return ProblemFileError(f"{fn}: {prefix}.{path}: {r.group(3)}")
    p = _PATH_IN_MESSAGE.match(msg)
    if p:
        head = re.match(r"[A-Za-z_]\w*", p.group(1)).group(0)  # type: ignore[union-attr]
        known = set(type(m).model_fields) | (set(m.args) if isinstance(m, LibraryMechanism) else set())
        if head in known or "[" in p.group(1):
            return ProblemFileError(f"{fn}: {prefix}.{p.group(1)}: {p.group(2)}")
    return ProblemFileError(f"{fn}: {prefix}: {msg}")


def build_mechanism(spec: ProblemFile, filename: str = "<problem>") -> Any:
    """Build the library mechanism a validated problem describes.

    Library errors (``MechanismError``, bad arguments) become ``ProblemFileError``
    naming the file and the key path.
    """
    try:
        import optkin
    except ImportError as e:  # pragma: no cover
        raise ProblemFileError(f"{filename}: mechanism: optkin cannot be imported: {e}") from None
    m = spec.mechanism
    try:
        if isinstance(m, LibraryMechanism):
            try:
                from optkin import mechanisms as lib
            except ImportError:
                raise ProblemFileError(
                    f"{filename}: mechanism.name: this optkin has no mechanism library yet"
                ) from None
            library = getattr(lib, "LIBRARY", {})
            if m.name not in library:
                hint = difflib.get_close_matches(m.name, list(library), n=1)
                extra = f"; did you mean {hint[0]!r}?" if hint else ""
                raise _fail(filename, ["mechanism", "name"],
                            f"unknown mechanism {m.name!r}; the library has: "
                            f"{', '.join(sorted(library))}" + extra)
            args = library_args(m, filename)
            try:
                return library[m.name](**args)
            except TypeError as e:
                raise _fail(filename, ["mechanism", "args"],
                            f"the library's {m.name}() does not accept these arguments: {e}") from None
        if isinstance(m, KhalilMechanism):
            _check_khalil(m, filename)
            rows = [r.model_dump() for r in m.rows]
            kw: dict[str, Any] = {"loops": m.loops, "params": dict(m.params), "name": m.name}
            for key in ("end_effector", "task", "home", "dof"):
                if getattr(m, key) is not None:
                    kw[key] = getattr(m, key)
            return optkin.Mechanism.from_khalil(rows, **kw)
        if isinstance(m, LegsMechanism):
            platform = _check_legs(m, filename)
            legs = [_leg_spec(leg) for leg in m.legs]
            kw: dict[str, Any] = {"home": m.home} if m.home is not None else {}
            if m.redundant:
                kw["redundant"] = True
            return optkin.Mechanism.from_legs(legs, platform=platform, name=m.name, **kw)
    except ProblemFileError:
        raise
    except MechanismError as e:
        raise _mechanism_error(e, spec, filename) from None
    except (AttributeError, ImportError) as e:
        raise _fail(filename, ["mechanism", "type"],
                    f"this optkin cannot build {m.type!r} mechanisms yet ({e})") from None
    except (ValueError, TypeError, ArithmeticError, IndexError, KeyError) as e:
        raise _fail(filename, ["mechanism"], f"the library rejected the mechanism: {e}") from None
    raise _fail(filename, ["mechanism", "type"], f"unsupported mechanism type {m.type!r}")


def _prefix_args(line: str, filename: str) -> str:
    head = f"{filename}: "
    rest = line[len(head):] if line.startswith(head) else line
    return f"{head}mechanism.args{'' if rest.startswith('[') else '.'}{rest}"


def _check_vector(v: Any, names: Sequence[str], loc: list[Any], fn: str, what: str) -> None:
    if v is None:
        return
    if isinstance(v, dict):
        for k in v:
            if k not in names:
                raise _fail(fn, loc + [k], f"unknown {what} {k!r}; expected one of: {', '.join(names)}")
        missing = [n for n in names if n not in v]
        if missing:
            raise _fail(fn, loc, f"missing value for {', '.join(missing)}")
    elif len(v) != len(names):
        raise _fail(fn, loc, f"expected {len(names)} numbers (one per {what}: "
                             f"{', '.join(names)}), got {len(v)}")


def check_problem(spec: ProblemFile, filename: str = "<problem>") -> Any:
    """Checks a schema cannot express; returns the built mechanism.

    Builds the mechanism (Khalil parents exist, loops close, legs fit their platform,
    library arguments), checks the number of actuated joints against the degrees of
    freedom and each task's vectors against the mechanism's joints.
    """
    mech = build_mechanism(spec, filename)
    active = tuple(getattr(mech, "active_names", ()) or ())
    joints = tuple(getattr(mech, "joint_names", ()) or ())
    dof = getattr(mech, "dof", None)
    if _is_int(dof) and active and len(active) != dof and not getattr(mech, "redundant", False):
        where = "rows" if isinstance(spec.mechanism, KhalilMechanism) else (
            "legs" if isinstance(spec.mechanism, LegsMechanism) else "args")
        raise _fail(filename, ["mechanism", where],
                    f"{len(active)} actuated joint(s) ({', '.join(active)}) but the mechanism "
                    f"has {dof} degree(s) of freedom; actuate exactly {dof} joints")
    task_dim = getattr(mech, "task_dim", None)
    for i, t in enumerate(spec.task):
        loc = ["task", i]
        if active:
            for key in ("qa",):
                _check_vector(getattr(t, key, None), active, loc + [key], filename, "actuated joint")
            path = getattr(t, "qa_path", None)
            if path:
                for k, p in enumerate(path):
                    _check_vector(p, active, loc + ["qa_path", k], filename, "actuated joint")
        if joints:
            _check_vector(getattr(t, "q", None), joints, loc + ["q"], filename, "joint")
        pose = getattr(t, "pose", None)
        if pose is not None and _is_int(task_dim) and pose and not isinstance(pose[0], list):
            if len(pose) != task_dim:
                raise _fail(filename, loc + ["pose"],
                            f"expected {task_dim} numbers (the task vector of a "
                            f"{getattr(mech, 'task', '') or str(task_dim) + '-dimensional'} "
                            f"platform) or a 4x4 matrix, got {len(pose)}")
    return mech


# ---------------------------------------------------------------------------
# result paths used by [expected].values
# ---------------------------------------------------------------------------

ANY = "[any]"
ALL = "[*]"

_PATH_TOKEN = re.compile(
    r"(?P<dot>\.)?(?P<name>[A-Za-z_][A-Za-z0-9_]*)|\[(?P<idx>-?\d+|\*|any|all|[A-Za-z_][A-Za-z0-9_]*|"
    r"'[^']*'|\"[^\"]*\")\]"
)


def parse_value_path(path: str) -> list[Any]:
    """Parse ``"solutions[any].q[theta3]"`` into ``["solutions", ANY, "q", "theta3"]``.

    Integers index lists, names index tables (or a joint vector by joint name),
    ``[*]``/``[all]`` means every element, ``[any]`` at least one.
    """
    if not isinstance(path, str) or not path:
        raise ValueError("empty result path")
    out: list[Any] = []
    pos = 0
    while pos < len(path):
        m = _PATH_TOKEN.match(path, pos)
        if not m or (m.group("dot") and pos == 0) or (m.group("name") and pos > 0 and not m.group("dot")):
            raise ValueError(
                f"cannot read the result path {path!r} at character {pos + 1}; "
                "use names, [index], [*] or [any], e.g. 'solutions[any].q[theta3]'"
            )
        if m.group("name"):
            out.append(m.group("name"))
        else:
            tok = m.group("idx")
            if tok in ("*", "all"):
                out.append(ALL)
            elif tok == "any":
                out.append(ANY)
            elif tok[0] in "'\"":
                out.append(tok[1:-1])
            elif re.fullmatch(r"-?\d+", tok):
                out.append(int(tok))
            else:
                out.append(tok)
        pos = m.end()
    return out
