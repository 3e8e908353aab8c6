"""Task registry: task kind -> function(mech, params, context) -> JSON-ready dict.

Each function receives the built mechanism, the validated task model of
:mod:`optkin.problems.schema` and a :class:`TaskContext`; it returns a dict of
JSON-ready results. A ``"success"`` key (when present) decides between the task
statuses ``ok`` and ``failed``; a ``"pictures"`` key lists PNG files written into
``context.picture_dir``.

Library functions are looked up on the :mod:`optkin` module at run time, so a kind
whose analysis lands in a later version is dispatched to it as soon as it exists;
until then the task fails with "not available in this version".
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from optkin._dryrun import Checked, computing, validating
from optkin.errors import MechanismError
from optkin.problems.schema import TaskBase
from optkin.results import jsonable

__all__ = ["TASKS", "OPTIONS", "OptionSpec", "TaskContext", "check_options", "check_task",
           "jsonable", "library_function", "register", "run_task"]


@dataclasses.dataclass
class TaskContext:
    """Where a task is running and where it may write pictures.

    ``picture_dir`` is None when pictures are not wanted.
    """

    problem: str
    index: int
    picture_dir: Path | None = None
    stem: str = "problem"
    notes: list[str] = dataclasses.field(default_factory=list)

    def picture_path(self, suffix: str = "") -> Path | None:
        """A PNG path for this task (``<stem>.task<i><suffix>.png``), or None."""
        if self.picture_dir is None:
            return None
        return self.picture_dir / f"{self.stem}.task{self.index}{suffix}.png"


#: Most configurations drawn in one picture (drawing dominates the time of small tasks).
MAX_PANELS = 8

TaskFunction = Callable[[Any, TaskBase, TaskContext], dict[str, Any]]

#: Task kind -> function. Later issues register their kinds here.
TASKS: dict[str, TaskFunction] = {}


@dataclasses.dataclass(frozen=True)
class OptionSpec:
    """Which ``options`` a task kind accepts: the keys of a library ``*_DEFAULTS`` mapping
    (``defaults``, dotted under ``optkin``) or else the keyword parameters of the library
    function ``function``, minus those the task sets itself from its own fields
    (``explicit``)."""

    function: str
    defaults: str | None = None
    explicit: tuple[str, ...] = ()

    def allowed(self) -> list[str]:
        if self.defaults is not None:
            module, _, name = self.defaults.rpartition(".")
            keys = getattr(importlib.import_module(f"optkin.{module}"), name)
            return sorted(k for k in keys if k not in self.explicit)
        import inspect

        fn = library_function(self.function, self.function)
        params = list(inspect.signature(fn).parameters.values())[1:]  # after mech
        return sorted(p.name for p in params
                      if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)
                      and p.name not in self.explicit)


#: Task kind -> the options it accepts.
OPTIONS: dict[str, OptionSpec] = {}


def register(kind: str, options: OptionSpec | None = None
             ) -> Callable[[TaskFunction], TaskFunction]:
    """Decorator registering a task function for ``kind`` (and the options it accepts)."""

    def deco(fn: TaskFunction) -> TaskFunction:
        TASKS[kind] = fn
        if options is not None:
            OPTIONS[kind] = options
        return fn

    return deco


def check_options(task: Any) -> None:
    """Raise a MechanismError (with ``path = ("options", name)``) for an option the task's
    library function does not know; problem files treat unknown options as errors."""
    spec = OPTIONS.get(str(getattr(task, "kind", "")))
    opts = dict(getattr(task, "options", {}) or {})
    if spec is None or not opts:
        return
    allowed = spec.allowed()
    for k in opts:
        if k not in allowed:
            import difflib

            hint = difflib.get_close_matches(k, allowed, n=1)
            extra = f"; did you mean {hint[0]!r}?" if hint else ""
            raise MechanismError(
                f"unknown option {k!r} of {spec.function}; known options: "
                f"{', '.join(allowed) or 'none'}{extra}", path=("options", k))


def library_function(dotted: str, kind: str) -> Callable[..., Any]:
    """``optkin.<dotted>`` (e.g. ``"statics.capability"``), or NotImplementedError."""
    import optkin

    obj: Any = optkin
    parts = dotted.split(".")
    for i, part in enumerate(parts):
        nxt = getattr(obj, part, None)
        if nxt is None and i < len(parts) - 1:
            try:  # a submodule not imported by optkin/__init__
                nxt = importlib.import_module(".".join(["optkin", *parts[: i + 1]]))
            except ImportError:
                nxt = None
        if nxt is None:
            raise NotImplementedError(
                f"task kind {kind!r} is not available in this version of optkin "
                f"(optkin.{dotted} does not exist yet)"
            )
        obj = nxt
    if not callable(obj):
        raise NotImplementedError(f"task kind {kind!r}: optkin.{dotted} is not callable")
    return obj


def _vector(v: Any, names: Sequence[str], fill: Sequence[float] | None = None) -> Any:
    """A list of numbers from a list or a ``{name: value}`` table (in ``names`` order)."""
    if v is None:
        return None
    if isinstance(v, Mapping):
        base = list(fill) if fill is not None else [0.0] * len(names)
        return [float(v[n]) if n in v else base[i] for i, n in enumerate(names)]
    return [float(x) for x in v]


def _home_q(mech: Any) -> list[float]:
    """All joint values at the mechanism's home configuration (where a guess table that
    names only some joints takes the others from): the home joint values a description
    gives, else the first posture at its home pose, else zeros."""
    from optkin.model import get_model
    from optkin.model.home import home_joints, home_task

    try:
        with computing():
            model = get_model(mech)
            q = home_joints(model)
            if q is not None:
                return [float(x) for x in q]
            pose = home_task(model)
            if pose is not None:
                sols = library_function("inverse", "inverse")(mech, pose)
                if len(sols):
                    return [float(x) for x in sols[0].q]
    except Exception:  # noqa: BLE001 - fall back to zeros below
        pass
    return [0.0] * len(mech.joint_names)


def _guess(mech: Any, v: Any) -> Any:
    """A guess from a list (passed on as is) or a table by joint name: joints the table
    does not name take their values at the home configuration."""
    if not isinstance(v, Mapping):
        return _vector(v, mech.joint_names)
    names = list(mech.joint_names)
    for k in v:
        if k not in names:
            raise MechanismError(f"unknown joint {k!r}; joints: {', '.join(names)}",
                                 path=("guess", k))
    fill = _home_q(mech)
    return [float(v[n]) if n in v else fill[i] for i, n in enumerate(names)]


def _pose(v: Any) -> Any:
    return None if v is None else np.asarray(v, dtype=float)


def _task_coordinates(mech: Any, pose: Any) -> list[float] | None:
    try:
        from optkin.mechanism.tasks import pose_to_task

        return [float(x) for x in pose_to_task(mech, np.asarray(pose, dtype=float))]
    except Exception:  # noqa: BLE001 - a convenience field only
        return None


def _draw(mech: Any, what: Any, ctx: TaskContext, suffix: str = "") -> list[str]:
    """Draw with ``optkin.plot.draw`` when it exists; silently skip otherwise."""
    path = ctx.picture_path(suffix)
    if path is None:
        return []
    try:
        draw = library_function("plot.draw", "draw")
    except NotImplementedError:
        ctx.notes.append("no picture: optkin.plot.draw is not available in this version")
        return []
    try:
        draw(mech, what, str(path))
    except Exception as e:  # noqa: BLE001 - a picture never fails a task
        ctx.notes.append(f"no picture: drawing failed ({type(e).__name__}: {e})")
        return []
    return [str(path)] if Path(path).exists() else []


def _kin_output(mech: Any, res: Any) -> dict[str, Any]:
    out = jsonable(res)
    if isinstance(out, dict):
        out["active_names"] = list(mech.active_names)
        if out.get("pose") is not None and "task_coordinates" not in out:
            out["task_coordinates"] = _task_coordinates(mech, out["pose"])
    return out


def _q_of(mech: Any, task: Any, ctx: TaskContext) -> Any:
    """Joint values from ``task.q``, or solved from ``task.qa`` by forward kinematics."""
    q = getattr(task, "q", None)
    if q is not None:
        return _guess(mech, q)  # a partial table takes the other joints at home
    qa = getattr(task, "qa", None)
    if qa is not None:
        with computing():  # the configuration is an input of the task, also when validating
            res = library_function("forward", "forward")(mech, _vector(qa, mech.active_names))
        if not res.success:
            raise ValueError(f"forward kinematics at qa = {list(qa)} failed: {res.message}")
        ctx.notes.append("configuration solved from qa by forward kinematics")
        return np.asarray(res.q, dtype=float)
    return None


# ---------------------------------------------------------------------------
# implemented kinds
# ---------------------------------------------------------------------------


@register("forward", OptionSpec("forward", "solvers.forward.FORWARD_DEFAULTS"))
def forward_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.forward(mech, qa, guess, **options)``; pictures the configuration."""
    fn = library_function("forward", "forward")
    qa = _vector(task.qa, mech.active_names)
    res = fn(mech, qa, guess=_guess(mech, task.guess), **dict(task.options))
    out = _kin_output(mech, res)
    if task.draw and res.success:
        out["pictures"] = _draw(mech, res, ctx)
    return out


@register("inverse", OptionSpec("inverse", "solvers.inverse.INVERSE_DEFAULTS"))
def inverse_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.inverse(mech, pose, **options)``: every posture; pictures them all."""
    fn = library_function("inverse", "inverse")
    sols = fn(mech, _pose(task.pose), **dict(task.options))
    out = jsonable(sols)
    if not isinstance(out, dict):
        out = {"solutions": out}
    for s in out.get("solutions", []) or []:
        if isinstance(s, dict):
            s["active_names"] = list(mech.active_names)
            if s.get("pose") is not None:
                s["task_coordinates"] = _task_coordinates(mech, s["pose"])
    sol_list = list(sols) if isinstance(sols, Sequence) or hasattr(sols, "__iter__") else []
    out["count"] = out.get("count", len(sol_list))
    out["success"] = bool(sol_list) and all(bool(getattr(s, "success", True)) for s in sol_list)
    if task.draw and sol_list:
        if len(sol_list) > MAX_PANELS:
            ctx.notes.append(f"picture shows the first {MAX_PANELS} of {len(sol_list)} solutions")
        out["pictures"] = _draw(mech, sol_list[:MAX_PANELS], ctx)
    return out


# ---------------------------------------------------------------------------
# kinds dispatched to library functions of later versions
# ---------------------------------------------------------------------------


def _generic(res: Any) -> dict[str, Any]:
    out = jsonable(res)
    if not isinstance(out, dict):
        out = {"value": out}
    if "count" not in out and hasattr(res, "__len__") and not isinstance(res, Mapping):
        try:
            out["count"] = len(res)
        except TypeError:
            pass
    return out


def _accepts(fn: Callable[..., Any], name: str) -> bool:
    """Whether ``fn`` has a parameter ``name`` (its ``**options`` are checked against its
    ``*_DEFAULTS``, which :class:`OptionSpec` knows, so they do not count)."""
    import inspect

    try:
        params = inspect.signature(fn).parameters
    except (TypeError, ValueError):
        return True
    return name in params and params[name].kind is not inspect.Parameter.VAR_KEYWORD


def _kw(task: Any, *keys: str) -> dict[str, Any]:
    return {k: getattr(task, k) for k in keys if getattr(task, k, None) is not None}


@register("assembly_modes", OptionSpec("assembly_modes", "solvers.enumerate.ASSEMBLY_DEFAULTS",
                                       ("seed",)))
def assembly_modes_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.assembly_modes(mech, qa, seed=seed, **options)``."""
    fn = library_function("assembly_modes", "assembly_modes")
    res = fn(mech, _vector(task.qa, mech.active_names), seed=task.seed, **dict(task.options))
    out = _generic(res)
    for s in out.get("solutions", []) or []:
        if isinstance(s, dict):
            s["active_names"] = list(mech.active_names)
            if s.get("pose") is not None:
                s["task_coordinates"] = _task_coordinates(mech, s["pose"])
    if getattr(task, "draw", False) and 0 < len(res) <= 16:  # side by side (MR Fig. 7.3b)
        out["pictures"] = _draw(mech, list(res), ctx)
    return out


@register("track", OptionSpec("track", "solvers.enumerate.TRACK_DEFAULTS"))
def track_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.track(mech, qa_path, guess, **options)``."""
    fn = library_function("track", "track")
    path = [_vector(p, mech.active_names) for p in task.qa_path]
    guess = _guess(mech, task.guess)
    return _generic(fn(mech, np.asarray(path, dtype=float), guess, **dict(task.options)))


@register("jacobians", OptionSpec("jacobians", "analysis.velocity.JACOBIANS_DEFAULTS"))
def jacobians_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.jacobians(mech, q, **options)`` at ``q`` (or solved from ``qa``)."""
    fn = library_function("jacobians", "jacobians")
    return _generic(fn(mech, _q_of(mech, task, ctx), **dict(task.options)))


@register("dof", OptionSpec("dof", "analysis.mobility.DOF_DEFAULTS"))
def dof_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.dof(mech[, q], **options)``."""
    fn = library_function("dof", "dof")
    q = _q_of(mech, task, ctx)
    kw = dict(task.options)
    if q is not None:
        if not _accepts(fn, "q"):
            raise ValueError("this optkin's dof() takes no configuration; remove 'q'")
        kw["q"] = q
    return _generic(fn(mech, **kw))


@register("classify", OptionSpec("classify", "analysis.singularity.CLASSIFY_DEFAULTS"))
def classify_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.classify(mech, q, **options)`` at ``q`` (or solved from ``qa``)."""
    fn = library_function("classify", "classify")
    return _generic(fn(mech, _q_of(mech, task, ctx), **dict(task.options)))


@register("singular_curves", OptionSpec(
    "singular_curves", "analysis.continuation.SINGULAR_CURVES_DEFAULTS",
    ("limits", "grid", "bounds")))
def singular_curves_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.singular_curves(mech, plane=..., kind=curves, fixed=..., ...)`` (+ a PNG)."""
    fn = library_function("singular_curves", "singular_curves")
    res = fn(mech, plane=task.plane, kind=task.curves,
             **_kw(task, "fixed", "limits", "grid", "bounds"), **dict(task.options))
    return _with_picture(_generic(res), res, ctx)


def _with_picture(out: dict[str, Any], res: Any, ctx: TaskContext) -> dict[str, Any]:
    path = ctx.picture_path()
    if path is not None and hasattr(res, "plot"):
        try:
            res.plot(str(path))
            out["pictures"] = [path.name]
        except Exception as e:  # a picture never fails the task
            ctx.notes.append(f"picture not drawn: {e}")
    return out


@register("working_modes", OptionSpec("working_modes", explicit=("pose",)))
def working_modes_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.working_modes(mech[, pose=...], **options)``."""
    fn = library_function("working_modes", "working_modes")
    kw = {"pose": _pose(task.pose)} if task.pose is not None else {}
    return _generic(fn(mech, **kw, **dict(task.options)))


@register("aspects", OptionSpec("aspects", "analysis.aspects.ASPECTS_DEFAULTS",
                                ("limits", "grid", "bounds")))
def aspects_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.aspects(mech, fixed=..., limits=..., grid=..., bounds=..., **options)``."""
    fn = library_function("aspects", "aspects")
    res = fn(mech, **_kw(task, "fixed", "limits", "grid", "bounds"), **dict(task.options))
    return _with_picture(_generic(res), res, ctx)


@register("workspace", OptionSpec("workspace", "analysis.aspects.ASPECTS_DEFAULTS",
                                  ("limits", "grid", "bounds")))
def workspace_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.workspace(mech, fixed=..., limits=..., grid=..., bounds=..., **options)``."""
    fn = library_function("workspace", "workspace")
    res = fn(mech, **_kw(task, "fixed", "limits", "grid", "bounds"), **dict(task.options))
    return _with_picture(_generic(res), res, ctx)


@register("statics", OptionSpec("statics", "statics.core.STATICS_DEFAULTS"))
def statics_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.statics.capability / feasible / distribute`` at ``q``, ``qa`` or ``pose``."""
    fn = library_function(f"statics.{task.analysis}", "statics")
    if getattr(task, "pose", None) is not None:
        with computing():  # the configuration is an input of the task, also when validating
            sols = library_function("inverse", "inverse")(mech, _pose(task.pose))
        if len(sols) <= task.posture:
            raise MechanismError(f"pose {list(task.pose)} has {len(sols)} posture(s), so there "
                                 f"is no posture {task.posture}; posture counts from 0",
                                 path=("posture",))
        q = sols[task.posture]
        ctx.notes.append(f"configuration solved from pose by inverse (posture {task.posture})")
    else:
        q = _q_of(mech, task, ctx)
    opts = dict(task.options)
    if task.analysis == "capability":
        res = fn(mech, q, task.limits, task.directions, **opts)
    elif task.analysis == "feasible":
        if task.wrench_lower is not None:
            wset: Any = {"lower": task.wrench_lower, "upper": task.wrench_upper}
        else:
            wset = task.wrench_vertices if task.wrench_vertices is not None else task.wrench
        res = fn(mech, q, wset, task.limits, **opts)
    else:
        res = fn(mech, q, task.wrench, task.limits, norm=task.norm, **opts)
    out = _generic(res)
    out["configuration"] = jsonable(getattr(q, "q", q))
    path = ctx.picture_path()
    if (task.analysis == "capability" and task.draw and path is not None
            and getattr(res, "success", False) and {"fx", "fy"} <= set(res.wrench_names)):
        try:  # the force polygon (fx, fy at zero moment) over 72 directions
            poly = library_function("statics.capability_polygon", "statics")
            poly(mech, q, task.limits, n=72, path=str(path), **opts)
            out["pictures"] = [str(path)]
        except Exception as e:  # noqa: BLE001 - a picture never fails a task
            ctx.notes.append(f"no picture: {type(e).__name__}: {e}")
    return out


def _measure(spec: Any, where: tuple) -> Any:
    """An optkin.design measure from a :class:`MeasureSpec`."""
    from optkin import design

    def need(key: str, v: Any) -> Any:
        if v is None:
            raise MechanismError(f"measure {spec.measure!r} needs {key!r}",
                                 path=(*where, key))
        return v

    if spec.measure in ("force_capability", "leg_stroke"):
        r = dict(need("region", spec.region))
        if set(r) != {"lo", "hi"}:
            raise MechanismError("region: a box of poses { lo = [...], hi = [...] } (every "
                                 f"task coordinate), got keys {sorted(r)}",
                                 path=(*where, "region"))
        if spec.measure == "force_capability":
            return design.ForceCapability(r["lo"], r["hi"], fmax=spec.fmax, n=spec.n)
        return design.LegStroke(r["lo"], r["hi"], n=spec.n)
    region = None
    if spec.region is not None:
        r = dict(spec.region)
        if set(r) == {"centre", "radius"}:
            region = design.Disc(tuple(r["centre"]), float(r["radius"]))
        elif set(r) == {"lo", "hi"}:
            region = design.Box(tuple(r["lo"]), tuple(r["hi"]))
        else:
            raise MechanismError("region: expected { centre = [x, y], radius = r } or "
                                 f"{{ lo = [x, y], hi = [x, y] }}, got keys {sorted(r)}",
                                 path=(*where, "region"))
    mode = None if spec.mode is None else tuple(int(v) for v in spec.mode)
    kw = dict(mode=mode, fixed=spec.fixed, length=spec.length)
    if spec.measure == "gci":
        return design.GCI(need("region", region), order=spec.order, **kw)
    if spec.measure == "min_conditioning":
        return design.MinConditioning(need("region", region), order=spec.order, **kw)
    if spec.measure == "largest_inscribed":
        line = None if spec.line is None else (spec.line[0], spec.line[1], spec.line[2])
        return design.LargestInscribed(shape=spec.shape, aspect=tuple(spec.aspect),
                                       centre=spec.centre, line=line,
                                       gamma=spec.gamma, limits=spec.limits,
                                       bounds=spec.bounds, **kw)
    if spec.measure == "joint_range":
        return design.JointRange(need("region", region), mode=mode, fixed=spec.fixed,
                                 order=spec.order, joint=spec.joint)
    if spec.measure == "aspect_area":
        return design.AspectArea(need("seed", spec.seed), limits=spec.limits,
                                 gamma=spec.gamma, bounds=spec.bounds, **kw)
    return design.Dimension(need("of", spec.of))


@register("design")
def design_task(mech: Any, task: Any, ctx: TaskContext) -> dict[str, Any]:
    """``optkin.design.optimize`` or ``optkin.design.atlas`` over a library family (+ a
    PNG: the convergence, or the atlas' contour maps)."""
    from optkin import design

    build = library_function(f"mechanisms.{task.family}", "design")
    equal = [(dict(e.coefficients), float(e.value)) for e in task.equal]
    variables = {k: tuple(v) for k, v in task.variables.items()}
    if task.analysis == "atlas":
        meas = {k: _measure(m, ("measures", k)) for k, m in task.measures.items()}
        res = design.atlas(build, variables, meas, n=task.n, fixed=task.fixed, equal=equal)
        out = _generic(res)
        out["best"] = {k: res.best(k) for k in meas}
    else:
        obj = _measure(task.objective, ("objective",))
        objective = design.Maximize(obj) if task.objective.sense == "max" else \
            design.Minimize(obj)
        cons = []
        for i, c in enumerate(task.constraints):
            m = _measure(c, ("constraints", i))
            cons.append(m >= c.at_least if c.at_least is not None else m <= c.at_most)
        res = design.optimize(build, variables, objective, cons, fixed=task.fixed,
                              equal=equal, seed=task.seed, maxiter=task.maxiter,
                              popsize=task.popsize)
        out = _generic(res)
    return _with_picture(out, res, ctx) if task.draw else out


def run_task(mech: Any, task: TaskBase, ctx: TaskContext) -> dict[str, Any]:
    """Run one task through the registry (exceptions propagate to the runner)."""
    kind = getattr(task, "kind", None)
    fn = TASKS.get(str(kind))
    if fn is None:
        raise NotImplementedError(f"task kind {kind!r} has no runner in this version of optkin")
    check_options(task)
    out = fn(mech, task, ctx)
    if not isinstance(out, dict):
        out = {"value": jsonable(out)}
    return out


def check_task(mech: Any, task: TaskBase, index: int, filename: str) -> None:
    """Every check running ``task`` would make, without its work (``optkin validate``).

    The task function runs in :func:`optkin._dryrun.validating` mode: the library
    functions check their arguments and stop at their checkpoint. A failed check raises
    :class:`~optkin.errors.ProblemFileError` as ``file: task[i].key: message``.
    """
    from optkin.errors import OptkinError, ProblemFileError
    from optkin.problems.schema import format_key_path

    def fail(e: Exception) -> ProblemFileError:
        path = list(getattr(e, "path", ()) or ())
        where = format_key_path(["task", index, *path])
        msg = str(e)
        return ProblemFileError(f"{filename}: {where}: {msg}")

    try:
        with validating():
            run_task(mech, task, TaskContext(filename, index, None))
    except Checked:
        return
    except NotImplementedError as e:
        raise fail(e) from None
    except (OptkinError, ValueError, TypeError, IndexError, KeyError, ArithmeticError) as e:
        raise fail(e) from None
