"""Run problem files: build the mechanism once, run each task, check ``[expected]``.

Layers: :func:`run_problem` turns one validated :class:`~optkin.problems.schema.Problem`
into a JSON-ready result dict; :func:`run_job` is the picklable entry point used by
process pools and Dask workers (problem bytes in; result dict and PNG bytes out);
:func:`run_paths` finds problem files, skips those already done (resume), fans the
rest out, and writes every file atomically.

Task outcomes: the ``status`` of a task in the result JSON and in ``summary.csv`` is the runner's word
for how the task went (:data:`TASK_OUTCOMES`), not a result's status: ``ok`` (the analysis
ran and its result says ``success``), ``failed`` (it ran and its result says
``success=False``; the message is the result's), ``error`` (an exception, a worker that
died or ran out of time, an output that cannot be stored), ``unavailable`` (a task kind
this version of optkin does not have); a problem file that cannot be read is one row with
status ``invalid``. The analysis's own ``success``, ``status`` (one word of
:data:`optkin.results.STATUS`) and ``message`` are in the task's ``output``.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import platform
import tempfile
import time
import traceback
import uuid
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Any

from optkin.errors import MechanismError, ProblemFileError
from optkin.problems.files import MAX_FILE_BYTES, input_hash, optkin_version, parse_toml
from optkin.problems.workers import DEFAULT_TIME_LIMIT, Job, JobOutcome, run_jobs

if TYPE_CHECKING:
    from optkin.problems.schema import Expected, Problem
    from optkin.problems.tasks import TaskContext

# The command line's process (reading files, scheduling, writing results) imports only the
# standard library: the schema (pydantic), the tasks and numpy load where a problem is
# loaded or run, in the workers, or in this process for run_problem and run_job.

__all__ = [
    "DEFAULT_TIME_LIMIT",
    "RESULT_FORMAT",
    "TASK_OUTCOMES",
    "ProblemFileInfo",
    "RunReport",
    "atomic_write",
    "check_expected",
    "find_problem_files",
    "run_problem",
    "run_job",
    "run_paths",
    "validate_paths",
    "is_complete",
    "clean_json",
]

#: Version of the result JSON layout.
RESULT_FORMAT = 1

SUMMARY_FIELDS = ["problem", "task", "kind", "name", "status", "passed", "time", "message"]

#: The runner's words for how a task went (a task's ``status`` in the result JSON and
#: ``summary.csv``; see the module docstring); ``invalid`` marks a file that cannot be read.
TASK_OUTCOMES = ("ok", "failed", "error", "unavailable", "invalid")


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------


#: Prefix of every temporary file the runner makes (the stale-temp cleaner removes only these).
TEMP_PREFIX = ".optkin-tmp."
#: A temporary file of another host (or of a process that cannot be checked) counts as
#: stale after this many seconds.
STALE_AFTER = 24 * 3600.0

_UMASK: list[int] = []


def _umask() -> int:
    if not _UMASK:
        old = os.umask(0o022)
        os.umask(old)
        _UMASK.append(old)
    return _UMASK[0]


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file in the same dir + os.replace).

    The file gets the permissions of a newly created file (0666 minus the umask), and the
    temporary file's name starts with :data:`TEMP_PREFIX` and names this host and process.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tag = f"{TEMP_PREFIX}{platform.node() or 'host'}.{os.getpid()}."
    fd, tmp = tempfile.mkstemp(prefix=tag, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            if hasattr(os, "fchmod"):
                os.fchmod(f.fileno(), 0o666 & ~_umask())
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OSError):
        return True
    return True


def _clean_stale_temps(out: Path) -> None:
    """Remove temp files left by an interrupted run: only files this program made
    (:data:`TEMP_PREFIX`), and only when their process is gone (same host) or they are
    older than :data:`STALE_AFTER`."""
    if not out.is_dir():
        return
    host = platform.node() or "host"
    now = time.time()
    for p in out.rglob(TEMP_PREFIX + "*.tmp"):
        rest = p.name[len(TEMP_PREFIX):].split(".")
        try:
            pid = int(rest[-3]) if len(rest) >= 3 else None
            owner = ".".join(rest[:-3])
            age = now - p.lstat().st_mtime
        except (ValueError, OSError):
            continue
        stale = age > STALE_AFTER or (owner == host and pid is not None and not _pid_alive(pid))
        if stale and p.is_file() and not p.is_symlink():
            with contextlib.suppress(OSError):
                p.unlink()


@dataclass(frozen=True)
class ProblemFileInfo:
    """A problem file found under a run path and where its results go.

    ``rel`` is the file's path relative to the run path with only the final ``.toml``
    removed, so ``a.toml`` and ``a.v2.toml`` write ``a.json`` and ``a.v2.json``.
    """

    path: Path
    display: str  # the name errors and the summary use (relative to the run path)
    rel: str  # result path relative to OUT, without suffix (posix separators)

    def result_path(self, out: Path) -> Path:
        return out / (self.rel + ".json")

    @property
    def stem(self) -> str:
        """The file name without ``.toml`` (pictures are named after it)."""
        return self.rel.rsplit("/", 1)[-1]


def _strip_toml(name: str) -> str:
    return name[:-5] if name.lower().endswith(".toml") else name


def find_problem_files(paths: Sequence[str | os.PathLike]) -> list[ProblemFileInfo]:
    """Every ``*.toml`` under ``paths`` (recursively, sorted, README and hidden skipped).

    Raises
    ------
    ProblemFileError
        When a path does not exist, or when two files would write the same result file
        (before any work is done).
    """
    found: list[ProblemFileInfo] = []
    seen: set[Path] = set()
    for raw in paths:
        p = Path(raw)
        if p.is_dir():
            files = sorted(
                f for f in p.rglob("*.toml")
                if f.is_file() and not f.name.lower().startswith("readme")
                and not any(part.startswith(".") for part in f.relative_to(p).parts)
            )
            for f in files:
                rel = f.relative_to(p).as_posix()
                found.append(ProblemFileInfo(f, rel, _strip_toml(rel)))
        elif p.is_file():
            found.append(ProblemFileInfo(p, p.name, _strip_toml(p.name)))
        else:
            raise ProblemFileError(f"{raw}: (file): no such file or directory")
    unique: list[ProblemFileInfo] = []
    used: dict[str, str] = {}
    for info in found:
        key = info.path.resolve()
        if key in seen:
            continue
        seen.add(key)
        slot = info.rel.casefold()  # a.json and A.json are one file on some file systems
        if slot in used:
            other = used[slot]
            raise ProblemFileError(
                f"{info.path}: (file): its results ({info.rel}.json) would collide with those "
                f"of {other}; rename one of them or run them with separate --out directories")
        used[slot] = str(info.path)
        unique.append(info)
    return unique


def is_complete(result_path: Path, want_hash: str | None = None) -> dict[str, Any] | None:
    """The stored result if it is complete valid JSON (with ``want_hash``), else None."""
    try:
        data = json.loads(Path(result_path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("complete") is not True:
        return None
    if data.get("result_format") != RESULT_FORMAT:
        return None
    if want_hash is not None and data.get("input_hash") != want_hash:
        return None
    return data


# ---------------------------------------------------------------------------
# [expected]
# ---------------------------------------------------------------------------


def _names_for(parent: Any, key: str) -> list[str] | None:
    if not isinstance(parent, dict):
        return None
    for k in (f"{key}_names", {"q": "joint_names", "qa": "active_names"}.get(key, "")):
        names = parent.get(k) if k else None
        if isinstance(names, list):
            return [str(n) for n in names]
    return None


def _close(got: Any, want: Any, tol: float, rtol: float, wrap: bool) -> bool:
    if isinstance(want, bool) or isinstance(want, str):
        return got == want
    if isinstance(want, list):
        return (isinstance(got, list) and len(got) == len(want)
                and all(_close(g, w, tol, rtol, wrap) for g, w in zip(got, want)))
    if isinstance(got, bool) or not isinstance(got, (int, float)):
        return False
    d = float(got) - float(want)
    if wrap:
        d = math.remainder(d, 2 * math.pi)
    return abs(d) <= tol + rtol * abs(float(want))


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.10g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return json.dumps(v) if isinstance(v, (str, bool)) or v is None else str(v)


def _evaluate(node: Any, tokens: list[Any], pos: int, parent: Any, key: Any,
              test: Callable[[Any], bool]) -> tuple[bool, str]:
    """Walk ``tokens`` from ``node``; returns (ok, what was found)."""
    from optkin.problems.schema import ALL, ANY

    if pos == len(tokens):
        return test(node), _fmt(node)
    tok = tokens[pos]
    if tok in (ALL, ANY):
        if not isinstance(node, list):
            return False, f"not a list at {tok}"
        if not node:
            return False, "an empty list"
        results = [_evaluate(x, tokens, pos + 1, node, i, test) for i, x in enumerate(node)]
        if tok == ALL:
            bad = [(i, r[1]) for i, r in enumerate(results) if not r[0]]
            return (not bad), ("all match" if not bad else f"element {bad[0][0]}: {bad[0][1]}")
        good = [i for i, r in enumerate(results) if r[0]]
        if good:
            return True, f"element {good[0]} matches"
        return False, "no element matches (" + "; ".join(r[1] for r in results[:4]) + (
            "; ..." if len(results) > 4 else "") + ")"
    if isinstance(tok, int):
        if isinstance(node, list) and -len(node) <= tok < len(node):
            return _evaluate(node[tok], tokens, pos + 1, node, tok, test)
        return False, f"no index [{tok}]"
    if isinstance(node, dict):
        if tok in node:
            return _evaluate(node[tok], tokens, pos + 1, node, tok, test)
        return False, f"no key {tok!r} (keys: {', '.join(sorted(map(str, node)))})"
    if isinstance(node, list):
        names = _names_for(parent, str(key))
        if names and tok in names:
            return _evaluate(node[names.index(tok)], tokens, pos + 1, node, tok, test)
        return False, f"no element named {tok!r}" + (f" (names: {', '.join(names)})" if names else "")
    return False, f"cannot look up {tok!r} in {_fmt(node)}"


def check_expected(expected: Expected | None, output: dict[str, Any] | None,
                   status: str) -> dict[str, Any]:
    """Check a task's output against its ``[expected]`` block.

    Without a block a task passes when its status is ``ok``. Each check is recorded
    as ``{"check", "want", "got", "ok"}``.
    """
    if expected is None:
        return {"passed": status == "ok", "checks": []}
    checks: list[dict[str, Any]] = []
    out = output if isinstance(output, dict) else {}

    def add(name: str, want: Any, ok: bool, got: str) -> None:
        checks.append({"check": name, "want": want, "got": got, "ok": bool(ok)})

    if status in ("error", "unavailable"):
        add("runs", True, False, status)
    if expected.success is not None:
        got = out.get("success")
        add("success", expected.success, got == expected.success, _fmt(got))
    if expected.status is not None:
        got = out.get("status")
        add("status", expected.status, got == expected.status, _fmt(got))
    count = out.get("count")
    if expected.count is not None:
        add("count", expected.count, count == expected.count, _fmt(count))
    if expected.min_count is not None:
        ok = isinstance(count, int) and count >= expected.min_count
        add("min_count", expected.min_count, ok, _fmt(count))
    if expected.max_count is not None:
        ok = isinstance(count, int) and count <= expected.max_count
        add("max_count", expected.max_count, ok, _fmt(count))
    items: list[tuple[str, dict[str, Any]]] = [
        (path, spec if isinstance(spec, dict) else {"value": spec})
        for path, spec in expected.values.items()
    ]
    items += [(c.path, c.model_dump(exclude_none=True)) for c in expected.checks]
    for path, spec in items:
        want = spec["value"]
        tol = spec.get("tol") or expected.tol
        rtol = spec.get("rtol") if spec.get("rtol") is not None else expected.rtol
        wrap = bool(spec.get("wrap", False))
        from optkin.problems.schema import parse_value_path

        tokens = parse_value_path(path)
        ok, got = _evaluate(out, tokens, 0, None, None,
                            lambda v, w=want, t=tol, r=rtol, a=wrap: _close(v, w, t, r, a))
        add(path, want, ok, got)
    return {"passed": all(c["ok"] for c in checks), "checks": checks,
            "source": expected.source}


# ---------------------------------------------------------------------------
# one problem
# ---------------------------------------------------------------------------


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="seconds")


def _model_warmup(mech: Any) -> tuple[float, str | None]:
    """Build (or fetch) the compiled model once per problem; returns (seconds, note)."""
    t0 = time.perf_counter()
    try:
        from optkin.model import get_model
    except ImportError:
        return 0.0, None
    try:
        get_model(mech)
    except Exception as e:  # noqa: BLE001 - the tasks will report it
        return time.perf_counter() - t0, f"model build failed: {type(e).__name__}: {e}"
    return time.perf_counter() - t0, None


def clean_json(v: Any) -> Any:
    """``v`` as strict JSON data: :func:`optkin.results.jsonable` (NaN and inf become None,
    anything else unknown its repr), under the name the runner has always exported."""
    from optkin.results import jsonable

    return jsonable(v)


def _output_success(output: dict[str, Any]) -> bool:
    """False when the output (or its ``info``) says the analysis did not succeed."""
    if output.get("success") is False:
        return False
    info = output.get("info")
    return not (isinstance(info, dict) and info.get("success") is False)


def _task_limit(task: Any, default: float | None) -> float | None:
    limit = getattr(task, "time_limit", None)
    return float(limit) if limit is not None else default


def _abandoned_record(i: int, task: Any, why: str, elapsed: float | None) -> dict[str, Any]:
    return {
        "index": i, "kind": task.kind, "name": task.name, "status": "error", "passed": False,
        "message": why, "time": elapsed,
        "params": clean_json(task.model_dump(exclude={"expected"}, exclude_none=True)),
        "expected": check_expected(task.expected, None, "error"), "output": None,
        "pictures": [], "notes": [], "abandoned": True,
    }


def run_task_record(mech: Any, task: Any, i: int, ctx: TaskContext) -> dict[str, Any]:
    """Run task ``i`` and return its JSON-ready record (never raises for the task's sake)."""
    from optkin.problems.tasks import run_task

    t0 = time.perf_counter()
    output: dict[str, Any] | None = None
    message = ""
    try:
        output = run_task(mech, task, ctx)
        status = "ok" if _output_success(output) else "failed"
        if status == "failed":
            message = str(output.get("message") or (output.get("info") or {}).get("message")
                          or "the analysis did not succeed")
    except NotImplementedError as e:
        status, message = "unavailable", str(e)
    except (MechanismError, ValueError) as e:
        status, message = "error", f"{type(e).__name__}: {e}"
    except Exception as e:  # noqa: BLE001 - one task never stops the others
        status = "error"
        message = f"{type(e).__name__}: {e}"
        ctx.notes.append("".join(traceback.format_exception(e)[-3:]).strip())
    elapsed = time.perf_counter() - t0
    pictures = []
    if output is not None:
        pictures = [Path(p).name for p in output.pop("pictures", []) or []]
    try:
        output = clean_json(output)
        json.dumps(output, allow_nan=False)
    except (TypeError, ValueError, RecursionError) as e:
        status, message, output = "error", f"the task's output cannot be stored: {e}", None
    exp = check_expected(task.expected, output, status)
    if status == "ok" and not exp["passed"]:
        failed = [c for c in exp["checks"] if not c["ok"]]
        message = "; ".join(
            f"expected {c['check']} = {_fmt(c['want'])}, got {c['got']}" for c in failed
        )
    record = clean_json({
        "index": i,
        "kind": task.kind,  # type: ignore[attr-defined]
        "name": task.name,
        "status": status,
        "passed": exp["passed"],
        "message": message,
        "time": elapsed,
        "params": task.model_dump(exclude={"expected"}, exclude_none=True),
        "expected": exp,
        "output": None,
        "pictures": pictures,
        "notes": ctx.notes,
    })
    record["output"] = output  # already clean: not walked twice
    return record


def run_problem(
    problem: Problem,
    picture_dir: Path | None = None,
    stem: str | None = None,
    *,
    done_tasks: dict[int, dict[str, Any]] | None = None,
    time_limit: float | None = None,
    on_task_start: Callable[[int, float | None], None] | None = None,
    on_task_done: Callable[[int, dict[str, Any]], None] | None = None,
    only: Iterable[int] | None = None,
) -> dict[str, Any]:
    """Run every task of a validated problem; never raises for a failing task.

    The mechanism is built once (by validation) and its compiled model fetched once;
    every task reuses them. ``done_tasks`` holds records of tasks already run (by a
    worker that died since; ``{"abandoned": True, "message": why}`` for the task it was
    running): they are not run again. ``on_task_start(i, limit)`` and
    ``on_task_done(i, record)`` report progress (the worker protocol); the time limit of
    a task (its ``time_limit``, else ``time_limit``) is enforced by the worker's parent,
    not here. The result is ``complete`` when no task was abandoned. ``only`` runs a
    subset of the tasks (a unit of a problem split for scheduling; the other tasks are
    left out of the result).
    """
    from optkin.problems.tasks import TaskContext

    t_start = time.perf_counter()
    started = _now()
    mech = problem.mechanism
    done_tasks = dict(done_tasks or {})
    wanted = set(range(len(problem.spec.task))) if only is None else set(only)
    build_time, note = (0.0, None)
    if any(i not in done_tasks for i in wanted):
        build_time, note = _model_warmup(mech)
    stem = stem or Path(problem.display).stem
    tasks_out: list[dict[str, Any]] = []
    for i, task in enumerate(problem.spec.task):
        if i not in wanted:
            continue
        prior = done_tasks.get(i)
        if prior is not None:
            rec = (_abandoned_record(i, task, str(prior.get("message", "")), prior.get("time"))
                   if prior.get("abandoned") else prior)
            tasks_out.append(rec)
            continue
        if on_task_start is not None:
            on_task_start(i, _task_limit(task, time_limit))
        rec = run_task_record(mech, task, i, TaskContext(problem.display, i, picture_dir, stem))
        if on_task_done is not None:
            on_task_done(i, rec)
        tasks_out.append(rec)
    mech_echo = mech.to_dict() if hasattr(mech, "to_dict") else None
    result = clean_json({
        "result_format": RESULT_FORMAT,
        "complete": not any(t.get("abandoned") for t in tasks_out),
        "problem": problem.display,
        "run_id": uuid.uuid4().hex,
        "file": str(problem.path),
        "input_hash": problem.hash,
        "optkin_version": optkin_version(),
        "python": platform.python_version(),
        "worker": {"host": platform.node(), "pid": os.getpid()},
        "started": started,
        "elapsed": time.perf_counter() - t_start,
        "model_build_time": build_time,
        "model_note": note,
        "input": problem.document,
        "mechanism": mech_echo,
        "mechanism_key": getattr(mech, "key", None),
        "tasks": [],
        "passed": all(t["passed"] for t in tasks_out),
    })
    result["tasks"] = tasks_out  # records are clean already (run_task_record)
    return result


def _load_any(data: bytes, display: str, source: str) -> Problem:
    """:func:`load_problem_bytes`, with every failure turned into the file's error."""
    from optkin.problems.schema import load_problem_bytes

    try:
        return load_problem_bytes(data, display, path=source, check=True)
    except ProblemFileError:
        raise
    except (Exception, RecursionError, MemoryError) as e:  # noqa: BLE001
        raise ProblemFileError(f"{display}: (file): cannot be read: {type(e).__name__}: "
                               f"{str(e)[:200]}") from None


def worker_job(jid: str, spec: dict[str, Any], send: Callable[[Any], None]) -> tuple:
    """Run (or validate) one problem inside a worker process; the final message.

    ``spec`` holds ``display``, ``data`` (the file's bytes), ``source``, ``pictures``,
    ``validate``, ``time_limit`` and ``done_tasks``. Progress goes through ``send`` as
    ``("task", jid, i, limit)`` and ``("task_done", jid, i, record, pictures)``.
    """
    display = spec["display"]
    try:
        problem = _load_any(spec["data"], display, spec["source"])
        if spec.get("validate"):
            from optkin.problems.tasks import check_task

            for i, task in enumerate(problem.spec.task):
                check_task(problem.mechanism, task, i, display)
            return ("done", jid, {"tasks": len(problem.spec.task),
                                  "mechanism": getattr(problem.mechanism, "name", "?")})
    except ProblemFileError as e:
        return ("invalid", jid, str(e))
    except MemoryError:
        return ("invalid", jid, f"{display}: (file): too large to load in memory")
    pictures = bool(spec.get("pictures", True))
    stem = Path(display).name
    stem = stem[:-5] if stem.lower().endswith(".toml") else stem
    with contextlib.ExitStack() as stack:
        tmp = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="optkin-pics-"))) \
            if pictures else None

        def task_done(i: int, rec: dict[str, Any]) -> None:
            pngs = {}
            for name in rec.get("pictures", []):
                f = tmp / name if tmp is not None else None
                if f is not None and f.exists():
                    pngs[name] = f.read_bytes()
            send(("task_done", jid, i, rec, pngs))

        result = run_problem(
            problem, tmp, stem=stem, done_tasks=spec.get("done_tasks"),
            time_limit=spec.get("time_limit"),
            on_task_start=lambda i, limit: send(("task", jid, i, limit)),
            on_task_done=task_done, only=spec.get("only"))
    return ("done", jid, result)


def run_job(display: str, data: bytes, source: str, pictures: bool = True) -> dict[str, Any]:
    """Run one problem given as bytes in this process (no time limits).

    Returns ``{"result": dict, "pictures": {filename: png bytes}}``.
    """
    out: dict[str, Any] = {"pictures": {}}

    def collect(msg: tuple) -> None:
        if msg[0] == "task_done":
            out["pictures"].update(msg[4])

    spec = {"display": display, "data": data, "source": source, "pictures": pictures}
    final = worker_job(display, spec, collect)
    if final[0] != "done":
        raise ProblemFileError(final[2])
    out["result"] = final[2]
    return out


# ---------------------------------------------------------------------------
# many problems
# ---------------------------------------------------------------------------


@dataclass
class RunReport:
    """What :func:`run_paths` did."""

    ran: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)
    invalid: dict[str, str] = field(default_factory=dict)  # display -> message
    crashed: dict[str, str] = field(default_factory=dict)  # display -> message
    results: dict[str, dict[str, Any]] = field(default_factory=dict)  # display -> result
    summary_path: Path | None = None

    @property
    def tasks(self) -> Iterator[tuple[str, dict[str, Any]]]:
        for name, res in self.results.items():
            for t in res.get("tasks", []):
                yield name, t

    @property
    def exit_code(self) -> int:
        """0 all passed; 1 a task failed or missed its [expected]; 2 invalid input."""
        if self.invalid:
            return 2
        if self.crashed or any(not t.get("passed") for _, t in self.tasks):
            return 1
        return 0


def _write_result(out: Path, info: ProblemFileInfo, result: dict[str, Any],
                  pictures: dict[str, bytes]) -> None:
    rel_dir = info.result_path(out).parent
    for name, data in pictures.items():
        atomic_write(rel_dir / Path(name).name, data)
    try:  # results come clean from the workers; clean them here only when they are not
        blob = json.dumps(result, indent=1, sort_keys=False, allow_nan=False)
    except (TypeError, ValueError):
        blob = json.dumps(clean_json(result), indent=1, sort_keys=False, allow_nan=False)
    atomic_write(info.result_path(out), blob.encode("utf-8"))


_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def _cell(v: Any) -> Any:
    """A summary cell a spreadsheet will not run as a formula (leading ``'``)."""
    if isinstance(v, str) and v.startswith(_FORMULA_START):
        return "'" + v
    return v


def _summary_rows(report: RunReport, order: Sequence[ProblemFileInfo]) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for info in order:
        name = info.display
        if name in report.invalid:
            rows.append({"problem": name, "task": "", "kind": "", "name": "", "status": "invalid",
                         "passed": False, "time": "", "message": report.invalid[name]})
        elif name in report.crashed:
            rows.append({"problem": name, "task": "", "kind": "", "name": "", "status": "error",
                         "passed": False, "time": "", "message": report.crashed[name]})
        elif name in report.results:
            for t in report.results[name].get("tasks", []):
                rows.append({
                    "problem": name, "task": t.get("index"), "kind": t.get("kind"),
                    "name": t.get("name") or "", "status": t.get("status"),
                    "passed": bool(t.get("passed")),
                    "time": f"{float(t.get('time') or 0):.4f}",
                    "message": (t.get("message") or "").replace("\n", " ")[:500],
                })
    return [{k: _cell(v) for k, v in r.items()} for r in rows]


def _write_summary(out: Path, rows: Iterable[dict[str, Any]]) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    path = out / "summary.csv"
    atomic_write(path, buf.getvalue().encode("utf-8"))
    return path


def _read_problem_file(info: ProblemFileInfo) -> bytes:
    try:
        size = info.path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise ProblemFileError(
                f"{info.display}: (file): {size} bytes is larger than the {MAX_FILE_BYTES} "
                "bytes a problem file may have; split it into several files")
        with info.path.open("rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as e:
        raise ProblemFileError(f"{info.display}: (file): cannot read: {e.strerror or e}") from None
    if len(data) > MAX_FILE_BYTES:
        raise ProblemFileError(f"{info.display}: (file): larger than {MAX_FILE_BYTES} bytes")
    return data


def run_paths(
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike = "results",
    jobs: int = 1,
    force: bool = False,
    scheduler: str | None = None,
    pictures: bool = True,
    progress: Callable[[int], Any] | None = None,
    on_result: Callable[[str, dict[str, Any]], None] | None = None,
    time_limit: float = DEFAULT_TIME_LIMIT,
) -> RunReport:
    """Run every problem file under ``paths``, writing results into ``out``.

    Every problem runs in a worker process (``jobs`` of them; with ``scheduler``, a Dask
    scheduler address, in a worker process on a Dask worker), so that a task past its
    time limit (its ``time_limit`` key, else ``time_limit`` seconds) or a worker that
    dies fails only that task: the problem's other tasks and the other problems go on.
    Problems whose complete result exists with the same input hash are skipped unless
    ``force``. ``progress(total)`` returns a progress object with ``update()``/``close()``
    (e.g. a tqdm bar); with ``set_postfix_str`` too, it is told the problems in flight.
    """
    out = Path(out)
    report = RunReport()
    infos = find_problem_files(paths)
    out.mkdir(parents=True, exist_ok=True)
    _clean_stale_temps(out)
    todo: list[tuple[ProblemFileInfo, bytes]] = []
    for info in infos:
        try:
            data = _read_problem_file(info)
        except ProblemFileError as e:
            report.invalid[info.display] = str(e)
            continue
        prev = None if force else is_complete(info.result_path(out), input_hash(data))
        if prev is not None:
            report.skipped.append(info.display)
            report.results[info.display] = prev
        else:
            todo.append((info, data))
    bar = progress(len(todo)) if (progress and todo) else None
    units = _units(todo, pictures, split=(jobs > 1 or bool(scheduler)))
    by_key = {info.display: info for info, _ in todo}
    pending: dict[str, list[JobOutcome]] = {}
    n_units = {}
    for u in units:
        n_units[u.spec["display"]] = n_units.get(u.spec["display"], 0) + 1

    in_flight: dict[str, int] = {}  # problem -> its units running, named on the bar

    def show_in_flight() -> None:
        if bar is not None and hasattr(bar, "set_postfix_str"):
            names = sorted(k for k, v in in_flight.items() if v > 0)
            text = ", ".join(names)
            bar.set_postfix_str(text if len(text) <= 60 else text[:57] + "...", refresh=True)

    def started(job: Job) -> None:
        name = job.key.split("#", 1)[0]
        in_flight[name] = in_flight.get(name, 0) + 1
        show_in_flight()

    def done(o: JobOutcome) -> None:
        name = o.key.split("#", 1)[0]
        if in_flight.get(name, 0) > 0:
            in_flight[name] -= 1
            show_in_flight()
        got = pending.setdefault(name, [])
        got.append(o)
        if len(got) < n_units[name]:
            return  # the problem's other units are still running
        o = _merge(name, got)
        info = by_key[name]
        if o.kind == "done" and o.result is not None:
            try:
                _write_result(out, info, o.result, o.pictures)
                report.results[info.display] = o.result
                report.ran.append(info.display)
            except (OSError, TypeError, ValueError) as e:
                report.crashed[info.display] = f"cannot write results: {e}"
        elif o.kind == "invalid":
            report.invalid[info.display] = o.message
        else:
            report.crashed[info.display] = o.message
        if on_result is not None:
            on_result(info.display, report.results.get(info.display, {"error": o.message}))
        if bar is not None:
            bar.update(1)

    try:
        if scheduler:
            _run_dask(scheduler, units, time_limit, done)
        else:
            run_jobs(units, n_workers=jobs, time_limit=time_limit, on_outcome=done,
                     threads=1 if jobs > 1 else None, on_start=started)
    finally:
        if bar is not None:
            bar.close()
        report.summary_path = _write_summary(out, _summary_rows(report, infos))
    return report


def _units(todo: list[tuple[ProblemFileInfo, bytes]], pictures: bool, split: bool
           ) -> list[Job]:
    """The units of work, longest first (LPT): a problem is split into one unit per task
    when several workers share the work (a unit costs little more than its task: the
    worker keeps the problem's model), else one unit per problem. Ties keep file order."""
    from optkin.problems.costs import PROBLEM_COST, task_costs, topology_group

    units: list[tuple[int, Job]] = []
    for n, (info, data) in enumerate(todo):
        spec = {"display": info.display, "data": data, "source": str(info.path),
                "pictures": pictures}
        try:
            doc = parse_toml(data, info.display)
            costs, group = task_costs(doc), topology_group(doc)
            tasks = doc.get("task") if isinstance(doc.get("task"), list) else []
            kinds = [str(t.get("kind")) if isinstance(t, dict) else "?" for t in tasks]
        except Exception:  # noqa: BLE001 - the worker reports what is wrong with the file
            costs, group, kinds = [1.0], "?", []
        if split and len(costs) > 1:
            units += [(n, Job(f"{info.display}#{i}", dict(spec, only=[i]),
                              cost=PROBLEM_COST + c, group=group,
                              kinds=tuple(kinds[i:i + 1])))
                      for i, c in enumerate(costs)]
        else:
            units.append((n, Job(info.display, spec, cost=PROBLEM_COST + sum(costs),
                                 group=group, kinds=tuple(kinds))))
    units.sort(key=lambda u: (-u[1].cost, u[0]))
    return [job for _, job in units]


def _merge(name: str, parts: list[JobOutcome]) -> JobOutcome:
    """One problem's outcome from its units' (tasks in order, written once)."""
    if len(parts) == 1 and "#" not in parts[0].key:
        return parts[0]
    bad = [p_ for p_ in parts if p_.kind != "done" or p_.result is None]
    if bad:
        return JobOutcome(name, bad[0].kind, message=bad[0].message)
    results = [p_.result for p_ in parts]
    first = min(results, key=lambda r: r["tasks"][0]["index"] if r["tasks"] else 0)
    merged = dict(first)
    merged["tasks"] = sorted((t for r in results for t in r["tasks"]), key=lambda t: t["index"])
    merged["elapsed"] = sum(float(r.get("elapsed") or 0) for r in results)
    merged["model_build_time"] = max(float(r.get("model_build_time") or 0) for r in results)
    merged["complete"] = all(r.get("complete") for r in results)
    merged["passed"] = all(t["passed"] for t in merged["tasks"])
    pics: dict[str, bytes] = {}
    for p_ in parts:
        pics.update(p_.pictures)
    return JobOutcome(name, "done", merged, pics)


def validate_paths(paths: Sequence[str | os.PathLike],
                   time_limit: float = DEFAULT_TIME_LIMIT) -> dict[str, tuple[bool, str]]:
    """Validate every problem file under ``paths`` with every check :func:`run_paths`
    makes before solving (in a worker process, under ``time_limit``).

    Returns ``{display: (ok, message)}`` in file order.
    """
    infos = find_problem_files(paths)
    out: dict[str, tuple[bool, str]] = {}
    jobs = []
    for info in infos:
        try:
            data = _read_problem_file(info)
        except ProblemFileError as e:
            out[info.display] = (False, str(e))
            continue
        out[info.display] = (False, "")
        jobs.append(Job(info.display, {"display": info.display, "data": data,
                                       "source": str(info.path), "validate": True}))
    for o in run_jobs(jobs, n_workers=1, time_limit=time_limit):
        if o.kind == "done" and o.result is not None:
            out[o.key] = (True, f"{o.key}: ok ({o.result['tasks']} task(s), mechanism "
                                f"{o.result['mechanism']})")
        elif o.kind == "invalid":
            out[o.key] = (False, o.message)
        else:
            out[o.key] = (False, f"{o.key}: (file): {o.message}")
    return out


# ---------------------------------------------------------------------------
# Dask
# ---------------------------------------------------------------------------

#: A Dask task holds consecutive units (in the runner's order, longest first) up to this
#: estimated cost: each Dask task costs the cluster 15-25 ms of CPU (the client's event
#: loop, the scheduler, the Dask worker; measured on 2 cores, where that CPU is taken from
#: the optkin workers), more than a 3-RPR's whole unit. A unit costlier than this is a
#: task of its own.
DASK_TASK_COST = 0.25


def _dask_batches(jobs: list[Job], slots: int) -> list[list[Job]]:
    """``jobs`` (longest first) as Dask tasks of consecutive units: a task grows while
    its estimated cost stays within :data:`DASK_TASK_COST` and half a Dask thread's share
    of the whole (``slots`` threads), so that the grouping never unbalances the cluster."""
    if not jobs:
        return []
    total = sum(j.cost for j in jobs)
    cap = min(DASK_TASK_COST, total / (2 * max(1, slots)))
    batches: list[list[Job]] = []
    cost = 0.0
    for j in jobs:
        if batches and cost + j.cost <= cap + 1e-12:
            batches[-1].append(j)
            cost += j.cost
        else:
            batches.append([j])
            cost = j.cost
    return batches


def _run_dask(address: str, jobs: list[Job], time_limit: float,
              done: Callable[[JobOutcome], None]) -> None:
    from optkin.problems.dask_client import connect

    # (the connection registered the plugin that prestarts the Dask workers' optkin workers)
    session = connect(address)
    try:
        batches = _dask_batches(jobs, session.slots or len(jobs))
        tasks = [  # the longest first, as for the local pool (jobs come sorted)
            (f"optkin-{input_hash(batch[0].spec['data'])[:12]}-{i}", len(batches) - i,
             [job.spec for job in batch]) for i, batch in enumerate(batches)]

        def finished(i: int, rs: list[dict[str, Any]] | None, why: str | None) -> None:
            if rs is None:
                for job in batches[i]:
                    done(JobOutcome(job.key, "error", message=why or "the Dask task failed"))
                return
            for job, r in zip(batches[i], rs):
                done(JobOutcome(job.key, r["kind"], r["result"], r["pictures"], r["message"]))

        session.run(tasks, time_limit, finished)
    finally:
        session.close()
    if session.info.get("driver") and not session.info.get("preloaded"):
        # the worker server imports distributed for the next run's driver
        from optkin.problems import server
        from optkin.problems.workers import _worker_env

        server.warm(_worker_env(None), [{"label": server.DASK_LABEL, "dask": True}])
