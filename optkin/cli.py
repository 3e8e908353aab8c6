"""The ``optkin`` command: ``run``, ``validate`` and ``show`` problem files.

Exit status: 0 everything passed; 1 some task failed or missed its ``[expected]``;
2 invalid input (a malformed problem file, a missing path, bad options). User errors
print a one-line message per problem, never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from optkin._exit import fast_exit
from optkin.errors import OptkinError, ProblemFileError

__all__ = ["main", "build_parser"]

EXIT_OK, EXIT_FAILED, EXIT_INVALID = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # exit 2 with usage, as argparse does
        self.print_usage(sys.stderr)
        self.exit(EXIT_INVALID, f"{self.prog}: error: {message}\n")


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _jobs(text: str) -> int | str:
    """``--jobs``: a positive integer or ``auto``."""
    if text.strip().lower() == "auto":
        return "auto"
    try:
        return _positive_int(text)
    except argparse.ArgumentTypeError:
        raise argparse.ArgumentTypeError(
            f"expected a positive integer or 'auto', got {text!r}") from None


#: Memory a worker process is allowed for in ``--jobs auto`` (measured peak of the bundled
#: problems here: 389 MiB with one worker, 676 MiB with two, parent included, 2026-12-06)
WORKER_MEMORY = 512 * 2**20


def auto_jobs(paths: Sequence[str]) -> int:
    """``--jobs auto``: one worker per CPU this process may use, no more than the problem
    files nor than the physical memory holds at :data:`WORKER_MEMORY` each. Measured on the
    2-core machine: the bundled problems 1.85-1.9x faster with 2 workers than with 1 (13.0-14.5
    s against 24.6-27.5 s, pictures drawn, 2026-12-06), the same results."""
    try:
        cpus = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # not Linux
        cpus = os.cpu_count() or 1
    try:
        mem = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, OSError, ValueError):
        mem = 0
    by_mem = max(1, mem // WORKER_MEMORY) if mem > 0 else cpus
    return max(1, min(cpus, by_mem, _count_toml(paths, cpus)))


def _positive_seconds(text: str) -> float:
    from optkin.problems.workers import MAX_TIME_LIMIT

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not 0 < v <= MAX_TIME_LIMIT:
        raise argparse.ArgumentTypeError(
            f"expected a number of seconds in (0, {MAX_TIME_LIMIT:g}], got {text!r}")
    return v


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``optkin`` (subcommands run, validate, show)."""
    import optkin  # its version only: the problem schema (pydantic) loads when needed

    p = _Parser(prog="optkin", description="Kinematics of closed-chain and parallel robots: "
                "run problem files (TOML) and collect results.")
    p.add_argument("--version", action="version", version=f"optkin {optkin.__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    r = sub.add_parser("run", help="run every problem file under the paths")
    r.add_argument("paths", nargs="+", metavar="PATH", help="problem files or directories")
    r.add_argument("--out", default="results", metavar="DIR",
                   help="where results go (default: results/)")
    r.add_argument("--jobs", "-j", type=_jobs, default="auto", metavar="N",
                   help="problems run in N parallel processes (default auto: one per CPU, "
                        "at most one per problem file and per 512 MiB of memory)")
    r.add_argument("--force", action="store_true",
                   help="rerun problems whose results are complete and unchanged")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="send problems to a Dask distributed scheduler (e.g. tcp://host:8786)")
    r.add_argument("--time-limit", type=_positive_seconds, default=None, metavar="SECONDS",
                   help="wall-time limit of each task without its own time_limit "
                        "(default 600); a task past it is abandoned and reported as an error")
    r.add_argument("--no-pictures", action="store_true", help="do not draw PNG pictures")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar: print only failures and the summary line")

    v = sub.add_parser("validate", help="check problem files without solving")
    v.add_argument("paths", nargs="+", metavar="PATH", help="problem files or directories")

    j = sub.add_parser("schema", help="print the JSON Schema of problem files (for editors)")
    j.add_argument("--out", "-o", metavar="FILE", default=None,
                   help="write it to FILE instead of standard output")

    w = sub.add_parser("workers", help="start, stop or query this user's worker server "
                       "(runs then take workers forked ready instead of starting their own)")
    w.add_argument("action", choices=("start", "stop", "status"))
    w.add_argument("--idle", type=float, default=None, metavar="MINUTES",
                   help="start: exit after MINUTES without a request (default 30)")
    w.add_argument("--all", action="store_true",
                   help="stop: every server of this user (other environments, earlier "
                        "optkin files), not only this environment's")

    s = sub.add_parser("show", help="draw a problem's mechanism at its first solved configuration")
    s.add_argument("file", metavar="FILE", help="a problem file")
    s.add_argument("--out", "-o", metavar="PNG", default=None,
                   help="picture path (default: FILE with .png)")
    return p


def _err(msg: str) -> None:
    print(msg, file=sys.stderr)


def _progress_factory(enabled: bool):
    if not enabled:
        return None

    def make(total: int) -> Any:
        from tqdm import tqdm

        return tqdm(total=total, unit="problem", desc="optkin", file=sys.stderr,
                    dynamic_ncols=True, leave=False)

    return make


def _count_toml(paths: Sequence[str], most: int) -> int:
    """How many ``*.toml`` files the paths hold, counting no further than ``most``."""
    n = 0
    for p in map(Path, paths):
        try:
            if p.is_file():
                n += 1
            elif p.is_dir():
                for _ in p.rglob("*.toml"):
                    n += 1
                    if n >= most:
                        break
        except OSError:
            continue
        if n >= most:
            break
    return n


def _cmd_run(args: argparse.Namespace) -> int:
    if args.jobs == "auto":
        args.jobs = 1 if args.scheduler else auto_jobs(args.paths)
    if args.scheduler:  # connect (and have the Dask workers start theirs) meanwhile
        from optkin.problems.dask_client import preconnect

        preconnect(args.scheduler)
    elif isinstance(args.jobs, int) and args.jobs >= 1:
        # the workers start while this process imports the runner and reads the files
        from optkin.problems.workers import prestart

        prestart(_count_toml(args.paths, args.jobs), threads=1 if args.jobs > 1 else None)
    from optkin.problems.runner import find_problem_files, run_paths

    if not find_problem_files(args.paths):
        _err(f"optkin: no problem files (*.toml) under {' '.join(args.paths)}")
        return EXIT_INVALID

    tty = sys.stdout.isatty()
    t0 = time.perf_counter()
    from optkin.problems.workers import DEFAULT_TIME_LIMIT

    report = run_paths(
        args.paths,
        out=args.out,
        jobs=args.jobs,
        force=args.force,
        scheduler=args.scheduler,
        pictures=not args.no_pictures,
        progress=_progress_factory(tty and not args.quiet),
        time_limit=args.time_limit or DEFAULT_TIME_LIMIT,
    )
    for msg in report.invalid.values():
        _err(msg)
    for name, msg in report.crashed.items():
        print(f"{name}: ERROR: {msg}")
    n_tasks = n_pass = 0
    for name, t in report.tasks:
        n_tasks += 1
        if t.get("passed"):
            n_pass += 1
            continue
        label = f"task[{t.get('index')}] ({t.get('kind')}{', ' + t['name'] if t.get('name') else ''})"
        state = "MISSED EXPECTED" if t.get("status") == "ok" else str(t.get("status", "")).upper()
        print(f"{name}: {label}: {state}: {t.get('message', '')}")
    elapsed = time.perf_counter() - t0
    # the summary line, also with --quiet
    parts = [f"{len(report.ran)} run", f"{len(report.skipped)} skipped (unchanged)"]
    if report.invalid:
        parts.append(f"{len(report.invalid)} invalid")
    if report.crashed:
        parts.append(f"{len(report.crashed)} crashed")
    print(f"optkin: {len(report.ran) + len(report.skipped) + len(report.invalid) + len(report.crashed)}"
          f" problem(s): {', '.join(parts)}; {n_pass}/{n_tasks} task(s) passed; "
          f"{elapsed:.1f} s; results in {args.out}/")
    return report.exit_code


def _cmd_validate(args: argparse.Namespace) -> int:
    from optkin.problems.runner import find_problem_files, validate_paths

    if not find_problem_files(args.paths):
        _err(f"optkin: no problem files (*.toml) under {' '.join(args.paths)}")
        return EXIT_INVALID
    bad = 0
    for ok, message in validate_paths(args.paths).values():
        if ok:
            print(message)
        else:
            bad += 1
            _err(message)
    return EXIT_INVALID if bad else EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    """The JSON Schema of a problem file (a TOML file read as JSON data): editors such as
    VS Code (Even Better TOML, ``#:schema`` or ``[[schemas]]``) validate and complete with
    it."""
    import json

    from optkin.problems.schema import problem_json_schema

    text = json.dumps(problem_json_schema(), indent=2) + "\n"
    if args.out is None:
        sys.stdout.write(text)
    else:
        Path(args.out).write_text(text, encoding="utf-8")
    return EXIT_OK


def _cmd_show(args: argparse.Namespace) -> int:
    import numpy as np

    from optkin.problems.schema import load_problem
    from optkin.problems.tasks import library_function

    path = Path(args.file)
    problem = load_problem(path, display=path.name, check=True)
    mech = problem.mechanism
    try:
        draw = library_function("plot.draw", "show")
    except NotImplementedError:
        _err(f"{path.name}: drawing is not available in this version of optkin (no optkin.plot.draw)")
        return EXIT_FAILED
    from optkin.problems.tasks import _guess, check_options

    what = None
    for i, task in enumerate(problem.spec.task):
        if task.kind not in ("forward", "inverse"):  # type: ignore[attr-defined]
            continue
        try:  # a task whose inputs the library rejects is skipped, as a failed one is
            check_options(task)
            if task.kind == "forward":  # type: ignore[attr-defined]
                guess = _guess(mech, task.guess)  # type: ignore[attr-defined]
                res = library_function("forward", "forward")(
                    mech, _as_list(task.qa, mech.active_names), guess=guess,  # type: ignore[attr-defined]
                    **dict(task.options))  # type: ignore[attr-defined]
                if res.success:
                    what = res
                    break
            else:
                sols = library_function("inverse", "inverse")(
                    mech, np.asarray(task.pose, dtype=float), **dict(task.options))  # type: ignore[attr-defined]
                if len(sols):
                    what = sols[0]
                    break
        except (OptkinError, ValueError) as e:
            _err(f"{path.name}: task[{i}] ({task.kind}) skipped: {e}")  # type: ignore[attr-defined]
    if what is None:
        home = getattr(mech, "home", None)
        try:
            res = library_function("forward", "forward")(mech, np.zeros(len(mech.active_names)),
                                                         guess=home)
        except Exception:  # noqa: BLE001
            res = None
        if res is None or not res.success:
            _err(f"{path.name}: no task gave a configuration to draw; add a forward or inverse task")
            return EXIT_FAILED
        _err(f"{path.name}: no forward or inverse task gave a configuration; drawing the one at "
             "q_a = 0 nearest to the mechanism's home instead")
        what = res
    out = Path(args.out) if args.out else path.with_suffix(".png")
    if out.is_dir():  # -o DIR: the picture goes into it, named after the problem file
        out = out / path.with_suffix(".png").name
    elif not out.suffix:  # matplotlib appends .png: report the file actually written
        out = out.with_suffix(".png")
    out.parent.mkdir(parents=True, exist_ok=True)
    draw(mech, what, str(out))
    print(f"{path.name}: wrote {out}")
    return EXIT_OK


def _as_list(v: Any, names: Sequence[str]) -> list[float]:
    if isinstance(v, dict):
        return [float(v[n]) for n in names]
    return [float(x) for x in v]


#: Set by the SIGINT handler :func:`main` installs: a Ctrl-C that a library turned into
#: an exception of its own (pydantic-core wraps one raised while it builds a validator in
#: a SchemaError) is still an interrupt, reported as such and without a traceback.
_INTERRUPTED = False
_INTERRUPTED_RUN = "optkin: interrupted; completed results are kept, rerun to resume"


def _cmd_workers(args: argparse.Namespace) -> int:
    from optkin.problems import server

    try:
        if args.action == "start":
            idle = server.IDLE_MINUTES if args.idle is None else args.idle
            if not 0 < idle <= 7 * 24 * 60:
                _err(f"optkin workers: --idle must be in (0, {7 * 24 * 60}] minutes, got "
                     f"{idle:g}")
                return EXIT_INVALID
            info = server.start(idle)
            state = "started" if info.get("started_now") else "already running"
            print(f"optkin workers: {state} (pid {info['pid']}, {info['socket']}); it exits "
                  f"after {info['idle_seconds'] / 60:g} min without a run, or with "
                  "'optkin workers stop'")
            return 0
        if args.action == "stop" and args.all:
            print(f"optkin workers: stopped {server.stop_all()} server(s)")
            return 0
        if args.action == "stop":
            stopped = server.stop()
            print("optkin workers: stopped" if stopped else
                  "optkin workers: none running for this environment")
            return 0
        info = server.status()
        if info is None:
            print("optkin workers: none running for this environment (runs start their own "
                  "workers; 'optkin workers start' starts a server)")
            return 1
        warm = (f"warmed up with {len(info['warmed'])} kind(s) of work"
                + (", warming up" if info.get("warming") else ""))
        print(f"optkin workers: running (pid {info['pid']}, {info['socket']}); "
              f"{info['forked']} worker(s) forked, {warm}; idle for {info['idle_for']:.0f} "
              f"s of {info['idle_seconds']:.0f}")
        return 0
    except server.ServerError as e:
        _err(f"optkin workers: {e}")
        return EXIT_INVALID


def _on_sigint(signum: int, frame: Any) -> None:
    global _INTERRUPTED
    _INTERRUPTED = True
    raise KeyboardInterrupt


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``optkin`` console script; returns the exit status."""
    import signal
    import threading

    global _INTERRUPTED
    _INTERRUPTED = False
    if threading.current_thread() is not threading.main_thread():
        return _main(argv)
    previous = signal.signal(signal.SIGINT, _on_sigint)
    try:
        return _main(argv)
    finally:
        signal.signal(signal.SIGINT, previous)


def _main(argv: Sequence[str] | None) -> int:
    try:
        parser = build_parser()
    except KeyboardInterrupt:
        _err("optkin: interrupted")
        return 130
    except Exception:
        if _INTERRUPTED:
            _err("optkin: interrupted")
            return 130
        raise
    args = parser.parse_args(list(argv) if argv is not None else None)
    try:
        if args.command == "run":
            return _cmd_run(args)
        if args.command == "validate":
            return _cmd_validate(args)
        if args.command == "show":
            return _cmd_show(args)
        if args.command == "schema":
            return _cmd_schema(args)
        if args.command == "workers":
            return _cmd_workers(args)
    except ProblemFileError as e:
        _err(str(e))
        return EXIT_INVALID
    except OptkinError as e:
        _err(f"optkin: {e}")
        return EXIT_INVALID
    except KeyboardInterrupt:
        _err(_INTERRUPTED_RUN)
        return 130
    except BrokenPipeError:
        return EXIT_FAILED
    except OSError as e:  # an output path that cannot be created or written
        if _INTERRUPTED:
            _err(_INTERRUPTED_RUN)
            return 130
        where = f": {e.filename}" if getattr(e, "filename", None) else ""
        _err(f"optkin: cannot write the output ({e.strerror or e}{where}); choose another "
             "path with --out")
        return EXIT_INVALID
    except Exception:
        if _INTERRUPTED:  # a Ctrl-C some library wrapped in its own exception
            _err(_INTERRUPTED_RUN)
            return 130
        raise
    parser.error(f"unknown command {args.command!r}")
    return EXIT_INVALID


def console() -> None:
    """The ``optkin`` console script: :func:`main`, then a prompt exit.

    A finished command has written and flushed everything; what is left of the process is
    Python's own teardown (freeing the modules of numpy, pydantic and their kin one by
    one), about 60 ms here, which every invocation, and every batch run's wall time, paid.
    The exit handlers (idle workers told to exit, a private compiled-code cache removed,
    logging flushed) run first, then the process ends with the command's status."""
    try:
        code = main()
    except SystemExit as e:  # argparse: --help, --version, usage errors
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
        if e.code is not None and not isinstance(e.code, int):
            _err(str(e.code))
    except KeyboardInterrupt:  # before main's handler took over (still starting)
        _err("optkin: interrupted")
        code = 130
    try:
        fast_exit(code)
    except KeyboardInterrupt:  # a Ctrl-C in the last milliseconds: the work is written
        os._exit(130)


if __name__ == "__main__":  # pragma: no cover
    console()
