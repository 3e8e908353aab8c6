"""Worker processes that run problem files under per-task time limits.

The process that reads the command line never runs a problem itself. Each worker is a
fresh Python process started with :mod:`subprocess` (so it also works inside Dask's
daemonic worker processes), importing the *same* optkin package as the parent whatever
the working directory holds. A worker receives a problem as bytes, loads and validates it,
and reports the start and the end of every task over a pipe. The parent keeps the deadline
of the task in flight: a task that overruns its time limit has its worker killed (a stuck
native call cannot be interrupted any other way), a worker that dies (the out-of-memory
killer, a crash in a C library) is noticed at once; either way the task is recorded as an
``error`` with the reason, the tasks already finished are kept, and the problem's remaining
tasks go to a fresh worker. Nothing else is lost.

Idle workers are kept for the next run in the same process (a notebook, the tests), keyed
by the environment they were started with.
"""

from __future__ import annotations

import atexit
import contextlib
import gc
import os
import pickle
import queue
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import traceback
import weakref
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from optkin._exit import fast_exit

__all__ = ["Job", "JobOutcome", "run_jobs", "prestart", "DEFAULT_TIME_LIMIT", "MAX_TIME_LIMIT"]

#: Seconds a task may run when neither the task (``time_limit``) nor the run
#: (``--time-limit``) says otherwise. Loading a problem and building its model have the
#: same limit.
DEFAULT_TIME_LIMIT = 600.0
#: Largest accepted time limit (one day).
MAX_TIME_LIMIT = 86400.0
#: Extra seconds granted after a deadline before the worker is killed (message latency).
_GRACE = 0.5
#: Largest message accepted on a worker pipe (a corrupt length never allocates more).
_MAX_MESSAGE = 1 << 31
#: A worker that dies this many times while loading the same problem fails that problem.
_MAX_SETUP_DEATHS = 2
#: Seconds a new worker may take to import optkin and say it is ready.
_START_LIMIT = 120.0
#: Seconds a worker may take to acknowledge a problem sent to it (a healthy one answers in
#: microseconds; one that does not, a stopped or wedged process, is replaced at once
#: rather than at the end of the problem's time limit).
_ACK_LIMIT = 30.0


# ---------------------------------------------------------------------------
# framing: 8-byte length + pickle, over raw pipe file descriptors
# ---------------------------------------------------------------------------


def _send(fd: int, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(struct.pack("<Q", len(data)) + data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


def _read_exactly(fd: int, n: int) -> bytes:
    chunks = []
    while n:
        b = os.read(fd, min(n, 1 << 20))
        if not b:
            raise EOFError
        chunks.append(b)
        n -= len(b)
    return b"".join(chunks)


def _recv(fd: int) -> Any:
    (n,) = struct.unpack("<Q", _read_exactly(fd, 8))
    if n > _MAX_MESSAGE:
        raise EOFError(f"message of {n} bytes refused")
    return pickle.loads(_read_exactly(fd, n))


# ---------------------------------------------------------------------------
# the worker side
# ---------------------------------------------------------------------------


def _die_with_parent(parent: int) -> None:
    """Linux: get SIGKILL when the parent dies (a killed run leaves no orphan running)."""
    if not sys.platform.startswith("linux"):
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)


#: What every problem's first task imports (CasADi alone about 0.4 s), imported before a
#: worker says it is ready: workers start while the command line is still reading the
#: problem files, so this overlaps it, instead of being paid by each worker's first unit.
#: Nothing heavy that only some tasks use (cvxpy, matplotlib, scipy.special/spatial).
_PRELOAD = ("casadi", "numpy.random", "optkin.model.core", "optkin.solvers.enumerate",
            "optkin.solvers.homotopy", "optkin.analysis.continuation",
            "optkin.analysis.aspects", "optkin.problems.tasks")


def _preload() -> None:
    import importlib

    for name in _PRELOAD:
        try:
            importlib.import_module(name)
        except Exception:  # noqa: BLE001 - the task that needs it will report it
            pass


def serve(rfd: int, wfd: int, parent: int | None) -> None:
    """Worker main loop: read jobs from ``rfd``, report on ``wfd`` until told to exit.
    ``parent``: the pid of the run that started this process (None when forked by the
    worker server, :mod:`optkin.problems.server`, which watches the run's pipe instead)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    if parent is not None:
        _die_with_parent(parent)
    import optkin
    from optkin.problems import runner

    _preload()
    # the modules loaded: into the permanent generation, which the collector no longer
    # traverses, and collection back on (the boot turned it off, :data:`_BOOT`)
    gc.freeze()
    gc.enable()
    _send(wfd, ("ready", {"pid": os.getpid(),
                          "optkin": str(Path(optkin.__file__).resolve().parent),
                          "version": getattr(optkin, "__version__", "")}))
    while True:
        try:
            msg = _recv(rfd)
        except EOFError:
            fast_exit(0)
        if msg[0] == "exit":
            fast_exit(0)
        _, jid, spec = msg
        try:
            _send(wfd, ("got", jid))  # at once: the parent knows this worker is responsive
            _send(wfd, runner.worker_job(jid, spec, lambda m: _send(wfd, m)))
        except BrokenPipeError:
            fast_exit(0)
        except BaseException as e:  # noqa: BLE001 - report anything, keep serving
            _send(wfd, ("error", jid, f"{type(e).__name__}: {e}",
                        "".join(traceback.format_exception(e)[-4:])))


_BOOT = (
    # no cyclic garbage collection while the worker imports (each import allocates objects
    # that live as long as the process; the collections paid for nothing, about 5 % of
    # the start: 218 against 230 ms here); :func:`serve` turns it back on
    "import gc, sys\n"
    "gc.disable()\n"
    "root, rfd, wfd, parent = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])\n"
    # the parent's optkin first, then the parent's path; never the working directory
    # ('' for python -c)
    "sys.path[:] = [root] + [p for p in sys.argv[5:] if p not in ('', '.', root)]\n"
    "from optkin.problems.workers import serve\n"
    "serve(rfd, wfd, parent)\n"
)


def _boot_path() -> list[str]:
    """The module search path a worker gets: the parent's, less the working directory.
    Workers start with ``python -S`` (no ``site``: its processing of the installation's
    ``.pth`` files, an editable install's finder among them, took 25-30 ms of each
    worker's start here) and take this path, which ``site`` made in the parent, instead."""
    try:
        cwd = os.getcwd()
    except OSError:  # the working directory was removed
        cwd = "."
    path = list(sys.path)
    if path and path[0] in _script_dirs():  # the ``optkin`` console script's own folder
        path = path[1:]
    return [p for p in path if p and p not in (".", cwd)]


def _script_dirs() -> set[str]:
    """Where console scripts are installed (the interpreter's, the installation's and the
    user's): the first entry of the module path of a process started as ``optkin``, which
    ``python -m optkin`` does not have; no module is imported from there. Left out of a
    worker's path, so that both find the same worker server
    (:func:`optkin.problems.server.key` hashes the path)."""
    import sysconfig

    dirs = {os.path.dirname(sys.executable)}
    for scheme in (None, f"{os.name}_user"):
        with contextlib.suppress(KeyError, ValueError):
            got = sysconfig.get_path("scripts", scheme) if scheme else \
                sysconfig.get_path("scripts")
            if got:
                dirs.add(got)
    return dirs


# ---------------------------------------------------------------------------
# the parent side
# ---------------------------------------------------------------------------


@dataclass
class Job:
    """One problem to run (or only validate) in a worker.

    ``tasks`` collects the records of tasks already finished: when a worker dies they are
    sent to the next one, which skips them.
    """

    key: str
    spec: dict[str, Any]
    tasks: dict[int, dict[str, Any]] = field(default_factory=dict)
    #: the estimated cost and the topology group, for scheduling (:mod:`.costs`)
    cost: float = 1.0
    group: str = ""
    pictures: dict[str, bytes] = field(default_factory=dict)
    setup_deaths: int = 0
    #: the kinds of its tasks (which a worker server warms up with, :func:`_warm_server`)
    kinds: tuple[str, ...] = ()


@dataclass
class JobOutcome:
    """What became of a job: ``kind`` is ``"done"``, ``"invalid"`` or ``"error"``."""

    key: str
    kind: str
    result: dict[str, Any] | None = None
    pictures: dict[str, bytes] = field(default_factory=dict)
    message: str = ""


class _Pending:
    """The jobs not yet running, handed out by :class:`optkin.problems.costs.Affinity`."""

    def __init__(self, jobs: Iterable[Job]) -> None:
        from optkin.problems.costs import Affinity

        self.jobs = list(jobs)
        self.policy = Affinity([(j.cost, j.group) for j in self.jobs])
        self.index = {id(j): i for i, j in enumerate(self.jobs)}

    def __len__(self) -> int:
        return len(self.policy)

    def take(self, worker: object) -> Job:
        return self.jobs[self.policy.take(worker)]

    def popleft(self) -> Job:
        i = self.policy.take_any()
        if i is None:
            raise IndexError("no pending job")
        return self.jobs[i]

    def appendleft(self, job: Job) -> None:
        self.policy.put_back(self.index[id(job)])


def fork_from_server(env: dict[str, str], role: str = "worker"
                     ) -> tuple[Any, int, int, Any] | None:
    """A process forked by this environment's worker server on new pipes (a worker, or a
    Dask driver with ``role="dask"``): ``(proc, wfd, rfd, stderr)``, its input's write end,
    its output's read end and its standard error (a temporary file); None when there is no
    server to use. Nothing is left open then: ends sent to a server that did not answer
    are closed here (a process it forks late on them exits when they close)."""
    from optkin.problems.server import ServerError, fork_worker

    p2c_r, p2c_w = os.pipe()
    c2p_r, c2p_w = os.pipe()
    stderr = tempfile.TemporaryFile()
    try:
        proc = fork_worker(env, p2c_r, c2p_w, stderr.fileno(), role=role)
    except ServerError:
        proc = None
    finally:
        os.close(p2c_r)
        os.close(c2p_w)
    if proc is None:
        os.close(p2c_w)
        os.close(c2p_r)
        stderr.close()
        return None
    return proc, p2c_w, c2p_r, stderr


class _Worker:
    """A worker process, its pipes, and the reader thread feeding the shared queue."""

    def __init__(self, env: dict[str, str], events: queue.Queue) -> None:
        import optkin

        root = str(Path(optkin.__file__).resolve().parent.parent)
        # forked ready by this user's worker server when one runs for this environment,
        # else a new process that imports everything itself
        got = fork_from_server(env)
        self.forked = got is not None
        self.proc: Any
        if got is not None:
            self.proc, self.wfd, self.rfd, self.stderr = got
        else:
            p2c_r, p2c_w = os.pipe()
            c2p_r, c2p_w = os.pipe()
            self.stderr = tempfile.TemporaryFile()
            try:
                self.proc = subprocess.Popen(
                    [sys.executable, "-S", "-c", _BOOT, root, str(p2c_r), str(c2p_w),
                     str(os.getpid()), *_boot_path()],
                    pass_fds=(p2c_r, c2p_w), stdin=subprocess.DEVNULL,
                    stdout=subprocess.DEVNULL, stderr=self.stderr, env=env,
                    start_new_session=True)
            finally:
                os.close(p2c_r)
                os.close(c2p_w)
            self.wfd, self.rfd = p2c_w, c2p_r
        self.events = events
        self.job: Job | None = None
        self.deadline: float | None = None
        self.task: int | None = None
        self.limit = 0.0
        self.started = time.monotonic()
        self.ready = False
        self.acked = False
        self.info: dict[str, Any] = {}
        self.dead = False
        # a worker that cannot even start (broken installation) must not hang the run
        self.deadline = time.monotonic() + _START_LIMIT
        self.thread = threading.Thread(target=self._read, daemon=True)
        self.thread.start()
        _LIVE.add(self)

    def _read(self) -> None:
        """Feed the worker's messages to the queue; this thread owns (and closes) ``rfd``."""
        while True:
            try:
                msg = _recv(self.rfd)
            except (EOFError, OSError, pickle.UnpicklingError, struct.error):
                with contextlib.suppress(OSError):
                    os.close(self.rfd)
                self.events.put((self, None))
                return
            self.events.put((self, msg))

    def send(self, msg: Any) -> bool:
        try:
            _send(self.wfd, msg)
            return True
        except OSError:
            return False

    def kill(self) -> None:
        with contextlib.suppress(OSError):
            self.proc.kill()
        with contextlib.suppress(subprocess.TimeoutExpired):
            self.proc.wait(timeout=10)

    def close(self, wait: float = 0.0) -> None:
        """Tell the worker to exit (it ends by itself; ``wait`` seconds before a kill)."""
        if self.wfd < 0:  # closed already
            return
        self.send(("exit",))
        if wait:
            try:
                self.proc.wait(timeout=wait)
            except subprocess.TimeoutExpired:
                self.kill()
        with contextlib.suppress(OSError):  # the child sees EOF; the reader closes rfd
            os.close(self.wfd)
        self.wfd = -1
        self.stderr.close()

    def death_reason(self) -> str:
        """Why the worker ended (its exit status and the tail of what it printed)."""
        code = self.proc.poll()
        if code is None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                code = self.proc.wait(timeout=5)
        if code is not None and code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = str(-code)
            why = f"the worker process was killed by {name}"
            if -code == signal.SIGKILL:
                why += " (for example by the out-of-memory killer)"
        else:
            why = f"the worker process exited with status {code}"
        try:
            self.stderr.seek(0, os.SEEK_END)
            size = self.stderr.tell()
            self.stderr.seek(max(0, size - 400))
            tail = self.stderr.read().decode(errors="replace").strip().splitlines()
        except OSError:
            tail = []
        if tail:
            why += f"; it printed: {tail[-1][:200]}"
        return why


#: Every worker process alive in this process (for inspection and for cleanup).
_LIVE: weakref.WeakSet[_Worker] = weakref.WeakSet()


#: Environment variables that change while a process runs without mattering to a worker.
_VOLATILE = ("PYTEST_CURRENT_TEST",)


def _env_key(env: dict[str, str]) -> tuple:
    return tuple(sorted((k, v) for k, v in env.items() if k not in _VOLATILE))


_IDLE: dict[tuple, list[_Worker]] = {}
_IDLE_LOCK = threading.Lock()
#: Most idle workers kept in all (each holds a Python process with optkin loaded).
MAX_IDLE = 4


#: Variables a worker does not inherit. Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536``
#: for its workers (to hand memory back to the system early); inherited by an optkin
#: worker, it makes glibc trim the heap after nearly every numpy temporary, and the
#: solvers ran 15-30 % slower (aspects of a five-bar: 1.03-1.13 s of CPU against
#: 0.87-0.98 s). A worker lives for one run and gives all its memory back when it exits.
_NOT_INHERITED = ("MALLOC_TRIM_THRESHOLD_",)


def _worker_env(threads: int | None) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in _NOT_INHERITED}
    if threads is not None:  # one BLAS / OpenMP thread per worker when several run
        for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
            env.setdefault(k, str(threads))
    return env


#: Workers of each environment still starting in the background (:func:`prestart`).
_BOOTING: dict[tuple, int] = {}
_BOOTED = threading.Condition(_IDLE_LOCK)


def _checkout(env: dict[str, str], events: queue.Queue) -> _Worker:
    """An idle worker of this environment, one that :func:`prestart` is starting (waited
    for: it is further along than a new one), or a new worker."""
    key = _env_key(env)
    until = time.monotonic() + _START_LIMIT
    with _IDLE_LOCK:
        while True:
            pool = _IDLE.get(key, [])
            while pool:
                w = pool.pop()
                if w.proc.poll() is None:
                    w.events = events
                    return w
                w.close()
            left = until - time.monotonic()
            if _BOOTING.get(key, 0) <= 0 or left <= 0:
                break
            _BOOTED.wait(timeout=left)
    return _Worker(env, events)


def _mine() -> str:
    import optkin

    return str(Path(optkin.__file__).resolve().parent)


def _await_ready(w: _Worker | None, events: queue.Queue, key: tuple) -> None:
    """Wait until a prestarted worker is ready, then keep it idle (a background thread)."""
    try:
        if w is not None:
            try:
                _, msg = events.get(timeout=_START_LIMIT)
            except queue.Empty:
                msg = None
            if msg is not None and msg[0] == "ready" and msg[1].get("optkin") == _mine():
                w.ready, w.info, w.deadline = True, msg[1], None
            else:  # it died, hung, or imported another optkin: a run will start its own
                w.kill()
                w.close()
                w = None
    except Exception:  # noqa: BLE001 - a run that needs a worker will say why it cannot
        w = None
    finally:
        with _IDLE_LOCK:
            _BOOTING[key] = _BOOTING.get(key, 1) - 1
            if w is not None:
                _IDLE.setdefault(key, []).append(w)
            _BOOTED.notify_all()


def prestart(n: int, threads: int | None = None) -> int:
    """Start up to ``n`` workers for a run about to begin in this process.

    A worker's start-up (a Python process importing optkin, numpy, CasADi and pydantic,
    about 0.5 s) then overlaps whatever the caller does next (the command line imports the
    runner and reads the problem files meanwhile; a Dask worker unpickles its first task).
    :func:`run_jobs` takes these workers (waiting for one still starting rather than
    starting another); workers a run does not take are closed at exit like any idle worker.
    ``threads`` as for :func:`run_jobs`. Returns the number of workers started.

    The processes are started from the calling thread, which must outlive them (Linux
    kills a worker when the *thread* that started it ends: ``PR_SET_PDEATHSIG``); only the
    wait for their first message runs in the background.
    """
    env = _worker_env(threads)
    key = _env_key(env)
    with _IDLE_LOCK:
        have = len(_IDLE.get(key, [])) + _BOOTING.get(key, 0)
        k = max(0, int(n) - have)
        _BOOTING[key] = _BOOTING.get(key, 0) + k
    for _ in range(k):
        events: queue.Queue = queue.Queue()
        try:
            w: _Worker | None = _Worker(env, events)
        except Exception:  # noqa: BLE001 - cannot start one now: a run will try, and say why
            w = None
        threading.Thread(target=_await_ready, args=(w, events, key), daemon=True,
                         name="optkin-worker-start").start()
    return k


def _checkin(w: _Worker, env: dict[str, str], keep: int) -> None:
    if w.dead or w.proc.poll() is not None:
        w.close()
        return
    evicted: list[_Worker] = []
    with _IDLE_LOCK:
        pool = _IDLE.setdefault(_env_key(env), [])
        if len(pool) < keep:
            pool.append(w)
            w = None
        # beyond MAX_IDLE in all (or the run's own count), other environments' go first
        while sum(map(len, _IDLE.values())) > max(MAX_IDLE, keep):
            key = next(k for k, v in _IDLE.items() if v and (v is not pool or len(_IDLE) == 1))
            evicted.append(_IDLE[key].pop(0))
            if not _IDLE[key]:
                del _IDLE[key]
    for x in evicted + ([w] if w is not None else []):
        x.close()


@atexit.register
def _close_idle() -> None:
    with _IDLE_LOCK:
        workers = [w for pool in _IDLE.values() for w in pool]
        _IDLE.clear()
    for w in workers:
        w.close()


def run_jobs(
    jobs: Iterable[Job],
    n_workers: int = 1,
    time_limit: float = DEFAULT_TIME_LIMIT,
    on_outcome: Callable[[JobOutcome], None] | None = None,
    threads: int | None = None,
    keep: int | None = None,
    on_start: Callable[[Job], None] | None = None,
) -> list[JobOutcome]:
    """Run ``jobs`` on up to ``n_workers`` worker processes; return their outcomes.

    ``time_limit`` bounds loading each problem (its tasks bring their own limits, the
    worker falling back to the run's default). A task past its limit, or a worker that
    dies, becomes an ``error`` record of that task; the problem goes on in a new worker.
    ``on_start`` is called as a job is handed to a worker, ``on_outcome`` as each job ends
    (both in the calling thread). Afterwards up to
    ``keep`` (default ``n_workers``) workers stay idle for the next call in this process.
    """
    pending = _Pending(jobs)
    outcomes: list[JobOutcome] = []
    if not pending:
        return outcomes
    env = _worker_env(threads)
    events: queue.Queue = queue.Queue()
    workers: list[_Worker] = []
    n_workers = max(1, min(n_workers, len(pending)))
    served = False  # a worker came from a worker server

    def finish(o: JobOutcome) -> None:
        outcomes.append(o)
        if on_outcome is not None:
            on_outcome(o)

    def assign(w: _Worker) -> None:
        if not pending or not w.ready:
            return
        job = pending.take(w)
        spec = dict(job.spec, done_tasks=job.tasks, time_limit=time_limit)
        w.job, w.task, w.acked = job, None, False
        w.limit = time_limit
        w.deadline = time.monotonic() + min(_ACK_LIMIT, time_limit + _GRACE)
        if not w.send(("run", job.key, spec)):
            pending.appendleft(job)
            w.job = w.deadline = None
            w.dead = True
        elif on_start is not None:
            on_start(job)

    start_failures = []

    def abandon(w: _Worker, why: str) -> None:
        """The worker is gone: record its task (if any) and requeue the rest."""
        w.dead = True
        pending.policy.leave(w)
        if not w.ready:  # it never started: after two such deaths, stop trying
            start_failures.append(why)
            if len(start_failures) >= 2:
                while pending:
                    job = pending.popleft()
                    finish(JobOutcome(job.key, "error",
                                      message=f"cannot start a worker process: {why}"))
            return
        job = w.job
        w.job = w.deadline = None
        if job is None:
            return
        if w.task is None:  # died while loading or building the model
            job.setup_deaths += 1
            if job.setup_deaths >= _MAX_SETUP_DEATHS:
                finish(JobOutcome(job.key, "error", message=f"{why} while loading the problem"))
                return
        else:
            job.tasks[w.task] = {"abandoned": True, "message": why,
                                 "time": time.monotonic() - w.started}
        pending.appendleft(job)

    try:
        while pending or any(w.job is not None for w in workers):
            for w in workers:
                if w.dead:
                    w.close()
            workers = [w for w in workers if not w.dead]
            while len(workers) < n_workers and len(workers) < len(pending) + sum(
                    w.job is not None for w in workers):
                # a worker that is ready starts its unit now, not once the next one has
                # booted (:func:`_checkout` waits for a prestarted worker: without this
                # the first unit began when the last of the run's workers was up)
                workers.append(_checkout(env, events))
                assign(workers[-1])
            for w in workers:
                if w.job is None and w.ready:
                    assign(w)
            if any(w.dead for w in workers):
                # a worker whose pipe broke as a unit was sent to it (it was exiting when
                # it was checked out): replaced at once, not when its end is reported, which
                # its reader may have done already, to the queue of the run it idled after
                continue
            now = time.monotonic()
            deadlines = [w.deadline for w in workers if w.deadline is not None]
            timeout = max(0.0, min(deadlines) - now) if deadlines else None
            try:
                w, msg = events.get(timeout=timeout)
            except queue.Empty:
                w, msg = None, None
            if w is not None and w not in workers:  # a stale message from a killed worker
                continue
            if w is None:  # a deadline passed
                now = time.monotonic()
                for x in workers:
                    if x.deadline is not None and now >= x.deadline:
                        if x.job is not None and not x.acked:
                            x.kill()  # the problem goes to a fresh worker
                            abandon(x, f"the worker did not take the problem within "
                                       f"{min(_ACK_LIMIT, x.limit + _GRACE):g} s")
                            continue
                        where = (f"task[{x.task}]" if x.task is not None
                                 else "loading the problem")
                        x.kill()
                        abandon(x, f"time limit of {x.limit:g} s exceeded ({where}); the "
                                   "work was abandoned: raise the task's time_limit (or "
                                   "--time-limit) if it needs longer")
                continue
            if msg is None:  # EOF: the worker died
                why = w.death_reason()
                w.kill()
                abandon(w, why)
                continue
            tag = msg[0]
            if tag == "ready":
                mine = _mine()
                if msg[1].get("optkin") != mine:  # never run another optkin's code
                    w.kill()
                    abandon(w, f"the worker imported optkin from {msg[1].get('optkin')}, "
                               f"not {mine}")
                else:
                    w.ready, w.info, w.deadline = True, msg[1], None
                continue
            job = w.job
            if job is None or msg[1] != job.key:
                continue
            if tag == "got":
                w.acked = True
                w.deadline = time.monotonic() + time_limit + _GRACE
            elif tag == "task":
                _, _, i, limit = msg
                limit = time_limit if limit is None else limit
                w.task, w.limit, w.started = i, float(limit), time.monotonic()
                w.deadline = time.monotonic() + float(limit) + _GRACE
            elif tag == "task_done":
                _, _, i, record, pics = msg
                job.tasks[i] = record
                job.pictures.update(pics)
                w.task = None
                w.limit = time_limit
                w.deadline = time.monotonic() + time_limit + _GRACE
            elif tag in ("done", "invalid", "error"):
                w.job = w.deadline = w.task = None
                # the worker's next unit first: the outcome's handling (the parent writes
                # and fsyncs the result, ~8 ms) then overlaps its work
                assign(w)
                if tag == "done":
                    finish(JobOutcome(job.key, "done", msg[2], job.pictures))
                else:
                    finish(JobOutcome(job.key, tag, message=msg[2]))
    except BaseException:
        for w in workers:
            w.kill()
            w.dead = True
        raise
    finally:
        for w in workers:
            if w.job is not None:
                w.kill()
                w.dead = True
            served = served or getattr(w, "forked", False)
            _checkin(w, env, n_workers if keep is None else keep)
    if served:
        _warm_server(env, pending.jobs)
    return outcomes


def _warm_server(env: dict[str, str], jobs: list[Job]) -> None:
    """Tell the worker server that forked this run's workers what the run did: of each
    kind of work (topology, task kinds, pictures or not), the unit estimated cheapest,
    if it is cheap (:data:`optkin.problems.server.WARM_MAX_COST`). The server runs these
    once in a copy of itself that then forks the next run's workers with their models
    and modules loaded (:mod:`optkin.problems.server`)."""
    from optkin.problems import server

    best: dict[str, Job] = {}
    for j in jobs:
        if j.spec.get("validate") or j.cost > server.WARM_MAX_COST \
                or len(j.spec.get("data", b"")) > 1 << 18:
            continue
        label = f"{j.group}|{','.join(sorted(set(j.kinds)))}|{bool(j.spec.get('pictures'))}"
        if label not in best or j.cost < best[label].cost:
            best[label] = j
    if best:
        server.warm(env, [{"label": label, "display": j.spec["display"],
                           "source": j.spec.get("source", ""), "data": j.spec["data"],
                           "pictures": bool(j.spec.get("pictures")),
                           "only": j.spec.get("only")} for label, j in best.items()])
