"""Run problem files: build the mechanism once, run each task, check ``[expected]``.

Layers: :func:`run_problem` turns one validated :class:`~optkin.problems.schema.Problem`
into a JSON-ready result dict; :func:`run_job` is the picklable entry point used by
process pools and Dask workers (problem bytes in; result dict and PNG bytes out);
:func:`run_paths` finds problem files, skips those already done (resume), fans the
rest out, and writes every file atomically.
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
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from optkin.errors import MechanismError, ProblemFileError
from optkin.problems.schema import (
    ALL,
    ANY,
    Expected,
    Problem,
    input_hash,
    load_problem,
    load_problem_bytes,
    optkin_version,
    parse_value_path,
)
from optkin.problems.tasks import TaskContext, jsonable, run_task

__all__ = [
    "RESULT_FORMAT",
    "ProblemFileInfo",
    "RunReport",
    "atomic_write",
    "check_expected",
    "find_problem_files",
    "run_problem",
    "run_job",
    "run_paths",
    "is_complete",
]

#: Version of the result JSON layout.
RESULT_FORMAT = 1

SUMMARY_FIELDS = ["problem", "task", "kind", "name", "status", "passed", "time", "message"]


# ---------------------------------------------------------------------------
# files
# ---------------------------------------------------------------------------


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically (temp file in the same dir + os.replace)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _clean_stale_temps(out: Path) -> None:
    """Remove temp files left by an interrupted run (``.<name>.<random>.tmp``)."""
    if not out.is_dir():
        return
    for p in out.rglob(".*.tmp"):
        with contextlib.suppress(OSError):
            p.unlink()


@dataclass(frozen=True)
class ProblemFileInfo:
    """A problem file found under a run path and where its results go."""

    path: Path
    display: str  # the name errors and the summary use (relative to the run path)
    rel: Path  # result path relative to OUT, without suffix

    def result_path(self, out: Path) -> Path:
        return out / self.rel.with_suffix(".json")


def find_problem_files(paths: Sequence[str | os.PathLike]) -> list[ProblemFileInfo]:
    """Every ``*.toml`` under ``paths`` (recursively, sorted, README skipped).

    Raises
    ------
    ProblemFileError
        When a path does not exist or names a non-TOML file.
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
                rel = f.relative_to(p)
                found.append(ProblemFileInfo(f, rel.as_posix(), rel.with_suffix("")))
        elif p.is_file():
            found.append(ProblemFileInfo(p, p.name, Path(p.stem)))
        else:
            raise ProblemFileError(f"{raw}: (file): no such file or directory")
    unique: list[ProblemFileInfo] = []
    used: dict[Path, str] = {}
    for info in found:
        key = info.path.resolve()
        if key in seen:
            continue
        seen.add(key)
        if info.rel in used:
            raise ProblemFileError(
                f"{info.path}: (file): its results would overwrite those of {used[info.rel]}; "
                "run the two in separate --out directories"
            )
        used[info.rel] = str(info.path)
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


def run_problem(problem: Problem, picture_dir: Path | None = None,
                stem: str | None = None) -> dict[str, Any]:
    """Run every task of a validated problem; never raises for a failing task.

    The mechanism is built once (by validation) and its compiled model fetched once;
    every task reuses them.
    """
    t_start = time.perf_counter()
    started = _now()
    mech = problem.mechanism
    build_time, note = _model_warmup(mech)
    stem = stem or Path(problem.display).stem
    tasks_out: list[dict[str, Any]] = []
    for i, task in enumerate(problem.spec.task):
        ctx = TaskContext(problem.display, i, picture_dir, stem)
        t0 = time.perf_counter()
        output: dict[str, Any] | None = None
        message = ""
        try:
            output = run_task(mech, task, ctx)
            status = "ok" if output.get("success", True) is not False else "failed"
            if status == "failed":
                message = str(output.get("message") or "the analysis did not succeed")
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
        exp = check_expected(task.expected, output, status)
        if status == "ok" and not exp["passed"]:
            failed = [c for c in exp["checks"] if not c["ok"]]
            message = "; ".join(
                f"expected {c['check']} = {_fmt(c['want'])}, got {c['got']}" for c in failed
            )
        tasks_out.append({
            "index": i,
            "kind": task.kind,  # type: ignore[attr-defined]
            "name": task.name,
            "status": status,
            "passed": exp["passed"],
            "message": message,
            "time": elapsed,
            "params": jsonable(task.model_dump(exclude={"expected"}, exclude_none=True)),
            "expected": exp,
            "output": output,
            "pictures": pictures,
            "notes": ctx.notes,
        })
    mech_echo = mech.to_dict() if hasattr(mech, "to_dict") else None
    return {
        "result_format": RESULT_FORMAT,
        "complete": True,
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
        "input": jsonable(problem.document),
        "mechanism": jsonable(mech_echo),
        "mechanism_key": getattr(mech, "key", None),
        "tasks": tasks_out,
        "passed": all(t["passed"] for t in tasks_out),
    }


def run_job(display: str, data: bytes, source: str, pictures: bool = True) -> dict[str, Any]:
    """Worker entry point: run one problem given as bytes.

    Returns ``{"result": dict, "pictures": {filename: png bytes}}``; the caller writes
    them (so workers need no shared file system). Pictures are drawn in a private
    temporary directory.
    """
    problem = load_problem_bytes(data, display, path=source, check=True)
    stem = Path(display).with_suffix("").as_posix().replace("/", "__")
    pngs: dict[str, bytes] = {}
    if pictures:
        with tempfile.TemporaryDirectory(prefix="optkin-pics-") as tmp:
            result = run_problem(problem, Path(tmp), stem=Path(display).stem)
            for t in result["tasks"]:
                for name in t["pictures"]:
                    f = Path(tmp) / name
                    if f.exists():
                        pngs[name] = f.read_bytes()
    else:
        result = run_problem(problem, None, stem=stem)
    return {"result": result, "pictures": pngs}


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


def _write_result(out: Path, info: ProblemFileInfo, job: dict[str, Any]) -> None:
    rel_dir = (out / info.rel).parent
    for name, data in job.get("pictures", {}).items():
        atomic_write(rel_dir / name, data)
    blob = json.dumps(job["result"], indent=1, sort_keys=False, allow_nan=False)
    atomic_write(info.result_path(out), blob.encode("utf-8"))


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
                    "passed": bool(t.get("passed")), "time": f"{float(t.get('time') or 0):.4f}",
                    "message": (t.get("message") or "").replace("\n", " ")[:500],
                })
    return rows


def _write_summary(out: Path, rows: Iterable[dict[str, Any]]) -> Path:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_FIELDS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    path = out / "summary.csv"
    atomic_write(path, buf.getvalue().encode("utf-8"))
    return path


def _dask_client(address: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise ProblemFileError(
            "--scheduler: dask.distributed is not installed; pip install 'optkin[dask]'"
        ) from None
    try:
        return Client(address, timeout="10s")
    except (OSError, TimeoutError, ValueError) as e:
        raise ProblemFileError(f"--scheduler: cannot connect to {address!r}: {e}") from None


def run_paths(
    paths: Sequence[str | os.PathLike],
    out: str | os.PathLike = "results",
    jobs: int = 1,
    force: bool = False,
    scheduler: str | None = None,
    pictures: bool = True,
    progress: Callable[[int], Any] | None = None,
    on_result: Callable[[str, dict[str, Any]], None] | None = None,
) -> RunReport:
    """Run every problem file under ``paths``, writing results into ``out``.

    Problems whose complete result exists with the same input hash are skipped unless
    ``force``. ``jobs`` > 1 runs problems in a process pool; ``scheduler`` (a Dask
    scheduler address) sends them to a Dask cluster instead. ``progress(total)`` returns
    a progress object with ``update()``/``close()`` (e.g. a tqdm bar).
    """
    out = Path(out)
    report = RunReport()
    infos = find_problem_files(paths)
    out.mkdir(parents=True, exist_ok=True)
    _clean_stale_temps(out)
    todo: list[tuple[ProblemFileInfo, bytes]] = []
    for info in infos:
        try:
            problem = load_problem(info.path, display=info.display, check=True)
        except ProblemFileError as e:
            report.invalid[info.display] = str(e)
            continue
        prev = None if force else is_complete(info.result_path(out), problem.hash)
        if prev is not None:
            report.skipped.append(info.display)
            report.results[info.display] = prev
        else:
            todo.append((info, problem.data))
    bar = progress(len(todo)) if (progress and todo) else None

    def done(info: ProblemFileInfo, job: dict[str, Any] | None, err: str | None) -> None:
        if job is not None:
            try:
                _write_result(out, info, job)
                report.results[info.display] = job["result"]
                report.ran.append(info.display)
            except (OSError, TypeError, ValueError) as e:
                err = f"cannot write results: {e}"
        if err is not None:
            report.crashed[info.display] = err
        if on_result is not None:
            on_result(info.display, report.results.get(info.display, {"error": err}))
        if bar is not None:
            bar.update(1)

    try:
        if scheduler:
            _run_dask(scheduler, todo, pictures, done)
        elif jobs > 1 and len(todo) > 1:
            _run_pool(min(jobs, len(todo)), todo, pictures, done)
        else:
            for info, data in todo:
                try:
                    job = run_job(info.display, data, str(info.path), pictures)
                    done(info, job, None)
                except Exception as e:  # noqa: BLE001 - one problem never stops the others
                    done(info, None, f"{type(e).__name__}: {e}")
    finally:
        if bar is not None:
            bar.close()
    report.summary_path = _write_summary(out, _summary_rows(report, infos))
    return report


def _run_pool(jobs: int, todo: list[tuple[ProblemFileInfo, bytes]], pictures: bool,
              done: Callable[[ProblemFileInfo, dict[str, Any] | None, str | None], None]) -> None:
    import multiprocessing as mp

    method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
    ctx = mp.get_context(method)
    if method == "forkserver":  # workers fork from a server that has optkin imported
        ctx.set_forkserver_preload(["optkin.problems.runner"])
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=ctx)
    try:
        futures: dict[Future, ProblemFileInfo] = {
            pool.submit(run_job, info.display, data, str(info.path), pictures): info
            for info, data in todo
        }
        pending = set(futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in finished:
                info = futures[f]
                try:
                    done(info, f.result(), None)
                except Exception as e:  # noqa: BLE001 - includes a crashed worker
                    done(info, None, f"{type(e).__name__}: {e}")
    except BaseException:  # Ctrl-C: drop queued problems, keep what is written
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown(wait=True)


def _run_dask(address: str, todo: list[tuple[ProblemFileInfo, bytes]], pictures: bool,
              done: Callable[[ProblemFileInfo, dict[str, Any] | None, str | None], None]) -> None:
    client = _dask_client(address)
    try:
        from distributed import as_completed

        futures = {
            client.submit(run_job, info.display, data, str(info.path), pictures,
                          key=f"optkin-{input_hash(data)[:12]}-{i}", pure=False): info
            for i, (info, data) in enumerate(todo)
        }
        for f in as_completed(list(futures)):
            info = futures[f]
            try:
                done(info, f.result(), None)
            except Exception as e:  # noqa: BLE001
                done(info, None, f"{type(e).__name__}: {e}")
    finally:
        client.close()
