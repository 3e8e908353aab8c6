"""The connection of ``optkin run --scheduler`` to a Dask scheduler.

:func:`preconnect` starts connecting as soon as the command line knows the address, before
it imports the runner and reads the problem files; once connected it registers
:class:`optkin.problems.dask_worker.PrestartWorkers`, so the Dask workers start their
optkin worker processes meanwhile. :func:`connect` waits for that connection, never longer
than the connect timeout: a service that is not a Dask scheduler (one that sends a banner,
or keeps the connection open without answering) can neither hang the run nor escape as a
raw exception. It returns a :class:`Session`, which submits the run's Dask tasks and hands
back their outcomes as they finish.

Where a worker server runs (:mod:`optkin.problems.server`), the Dask client lives in a
process the server forks, a *driver* (:func:`serve_driver`): after the first such run the
server has ``distributed`` imported, so the driver connects in milliseconds, where this
process would spend about 0.3 s importing ``distributed`` before its first task could be
sent (on a small machine, a tenth of a run of 64 problems). The command line then never
imports ``distributed``; it sends the tasks to the driver over a pipe and reads their
outcomes back. A driver that dies fails the tasks not yet done, with the reason; a run
that ends or dies takes its driver with it. Without a server, the client runs in a thread
of this process, as before.

Standard library only until connecting.
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
from collections.abc import Callable
from typing import Any

from optkin.errors import ProblemFileError

__all__ = ["DASK_CONNECT_TIMEOUT", "Session", "connect", "preconnect", "serve_driver"]

#: Seconds allowed to reach a Dask scheduler and exchange the first messages.
DASK_CONNECT_TIMEOUT = 10.0

#: A Dask task: its key, its priority and the unit specs it runs
#: (:func:`optkin.problems.dask_worker.run_units`).
Task = tuple[str, int, list[dict[str, Any]]]
#: Called with a task's index and either its outcomes (one per unit) or why it failed.
OnDone = Callable[[int, "list[dict[str, Any]] | None", "str | None"], None]

_PENDING: dict[str, Any] = {}
_LOCK = threading.Lock()


def _connect(address: str, box: dict[str, Any], timeout: float) -> None:
    try:
        from distributed import Client
    except ImportError:
        box["missing"] = True
        return
    try:
        box["client"] = Client(address, timeout=f"{timeout:g}s")
    except BaseException as e:  # noqa: BLE001 - reported by connect(), whatever it is
        box["error"] = e
        return
    try:  # the Dask workers start optkin's worker processes now; without it, on first use
        from optkin.problems.dask_worker import PrestartWorkers

        box["client"].register_plugin(PrestartWorkers(), name=PrestartWorkers.name)
    except Exception:  # noqa: BLE001 - an older distributed, a worker that refuses
        pass


def _missing() -> ProblemFileError:
    return ProblemFileError(
        "--scheduler: dask.distributed is not installed; pip install 'optkin[dask]'")


def _cannot(address: str, why: str) -> ProblemFileError:
    return ProblemFileError(f"--scheduler: cannot connect to {address!r}: {why}; give the "
                            "address of a Dask scheduler (e.g. tcp://host:8786)")


def _why(box: dict[str, Any], alive: bool, waited: float) -> str:
    if alive:
        return f"no Dask scheduler answered within {waited:g} s"
    e = box.get("error")
    return (f"{type(e).__name__}: {str(e)[:200]}" if not isinstance(e, MemoryError)
            else "the service there does not speak the Dask protocol")


class Session:
    """A connected Dask client: :meth:`run` submits tasks and reports each as it ends."""

    def __init__(self, client: Any) -> None:
        self.client = client
        #: what a driver says of itself (``distributed`` already imported when it began)
        self.info: dict[str, Any] = {"driver": False}

    @property
    def slots(self) -> int:
        """Threads of the cluster's workers (0 when the scheduler does not say)."""
        try:
            return int(sum(self.client.nthreads().values()))
        except Exception:  # noqa: BLE001 - a scheduler that does not say
            return 0

    def run(self, tasks: list[Task], time_limit: float, on_done: OnDone) -> None:
        """Submit ``tasks`` (the highest priority first) and call ``on_done`` for each as
        it finishes, in this thread."""
        from distributed import as_completed

        from optkin.problems.dask_worker import run_units

        futures = {self.client.submit(run_units, specs, time_limit, key=key,
                                      priority=priority, pure=False): i
                   for i, (key, priority, specs) in enumerate(tasks)}
        for f in as_completed(list(futures)):
            i = futures[f]
            try:
                rs = f.result()
            except Exception as e:  # noqa: BLE001 - a lost Dask worker, a cancelled task
                on_done(i, None, f"{type(e).__name__}: {e}")
                continue
            on_done(i, rs, None)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.close()


class _Driver(Session):
    """A Dask client in a process forked by the worker server, spoken to over pipes."""

    def __init__(self, proc: Any, rfd: int, wfd: int, stderr: Any, address: str,
                 timeout: float) -> None:
        self.proc, self.rfd, self.wfd, self.stderr = proc, rfd, wfd, stderr
        self.address, self.timeout = address, timeout
        self.info = {"driver": True, "pid": proc.pid}
        self._slots = 0

    @property
    def slots(self) -> int:
        return self._slots

    def _recv(self, limit: float | None) -> Any:
        """The driver's next message; EOFError when it ended, TimeoutError when ``limit``
        seconds passed without one."""
        from optkin.problems.workers import _recv

        if limit is not None:
            r, _, _ = select.select([self.rfd], [], [], max(0.0, limit))
            if not r:
                raise TimeoutError(f"no answer within {limit:g} s")
        return _recv(self.rfd)

    def connected(self) -> Session | None:
        """Wait for the driver's connection: this session, None when the driver could not
        be used (it died: connect in this process instead), or ProblemFileError."""
        import pickle
        import struct

        waited = self.timeout + 5.0
        try:
            msg = self._recv(waited)
        except TimeoutError:  # alive and silent past the connect timeout
            self.close()
            raise _cannot(self.address, _why({}, True, waited)) from None
        except (EOFError, OSError, pickle.UnpicklingError, struct.error):
            self.close()
            return None
        if msg[0] == "connected":
            self._slots = int(msg[1])
            self.info.update(msg[2])
            return self
        self.close()
        if msg[0] == "missing":
            raise _missing()
        raise _cannot(self.address, str(msg[1]))

    def run(self, tasks: list[Task], time_limit: float, on_done: OnDone) -> None:
        import pickle
        import struct

        from optkin.problems.workers import _send

        left = set(range(len(tasks)))
        why = "the Dask driver process ended"
        lost: BaseException | None = None
        try:
            _send(self.wfd, ("run", tasks, time_limit))
        except OSError as e:
            lost = e
        while left and lost is None:
            try:
                msg = self._recv(None)
            except (EOFError, OSError, pickle.UnpicklingError, struct.error) as e:
                lost = e
                break
            if msg[0] == "done":  # (the run's own errors, in on_done, are not the driver's)
                left.discard(msg[1])
                on_done(msg[1], msg[2], msg[3])
            elif msg[0] == "failed":
                why = str(msg[1])
                break
        if lost is not None:
            why = self._death(why, lost)
        for i in sorted(left):
            on_done(i, None, why)

    def _death(self, why: str, e: BaseException) -> str:
        """What is known of the driver's end: the error, its exit status, its last word."""
        why = f"{why} ({type(e).__name__}: {e})" if str(e) else why
        with contextlib.suppress(Exception):
            self.proc.wait(timeout=1.0)
        with contextlib.suppress(Exception):
            status = self.proc.poll()
            if status is not None:
                why = f"{why}, status {status}"
        with contextlib.suppress(OSError, ValueError):
            self.stderr.seek(0)
            tail = self.stderr.read()[-400:].decode(errors="replace").strip()
            if tail:
                why = f"{why}: {tail.splitlines()[-1]}"
        return why

    def close(self) -> None:
        for fd in (self.wfd, self.rfd):  # the driver exits when its pipe closes
            with contextlib.suppress(OSError):
                os.close(fd)
        self.wfd = self.rfd = -1
        with contextlib.suppress(Exception):
            self.proc.wait(timeout=2.0)
        with contextlib.suppress(Exception):
            if self.proc.poll() is None:
                self.proc.kill()
        with contextlib.suppress(Exception):
            self.stderr.close()


def _fork_driver(address: str, timeout: float) -> _Driver | None:
    """A driver forked by this environment's worker server and told to connect, or None
    (no server to use)."""
    from optkin.problems.workers import _send, _worker_env, fork_from_server

    got = fork_from_server(_worker_env(None), role="dask")
    if got is None:
        return None
    proc, wfd, rfd, stderr = got
    driver = _Driver(proc, rfd, wfd, stderr, address, timeout)
    try:
        _send(wfd, ("connect", address, timeout))
    except OSError:
        driver.close()
        return None
    return driver


def _in_thread(address: str, timeout: float) -> tuple[threading.Thread, dict[str, Any], float]:
    box: dict[str, Any] = {}
    t = threading.Thread(target=_connect, args=(address, box, timeout), daemon=True,
                         name="optkin-dask-connect")
    t.start()
    return t, box, timeout


def preconnect(address: str) -> None:
    """Start connecting to the scheduler at ``address``: in a driver forked by the worker
    server if one runs, else in a background thread."""
    with _LOCK:
        if address in _PENDING:
            return
        timeout = float(DASK_CONNECT_TIMEOUT)
        # (an in-process scheduler, inproc://, is reachable from this process only)
        driver = None if address.startswith("inproc:") else _fork_driver(address, timeout)
        _PENDING[address] = driver if driver is not None else _in_thread(address, timeout)


def connect(address: str) -> Session:
    """A :class:`Session` with the scheduler at ``address``, or a ProblemFileError within
    the timeout."""
    preconnect(address)
    with _LOCK:
        pending = _PENDING.pop(address)
    if isinstance(pending, _Driver):
        session = pending.connected()
        if session is not None:
            return session
        # the driver died before it answered (a server stopping): connect here instead
        pending = _in_thread(address, pending.timeout)
    t, box, timeout = pending
    t.join(timeout + 5.0)
    if box.get("missing"):
        raise _missing()
    if "client" in box:
        return Session(box["client"])
    raise _cannot(address, _why(box, t.is_alive(), timeout + 5.0))


def serve_driver(rfd: int, wfd: int) -> None:
    """A Dask driver's main loop (in a process forked by the worker server): connect as
    told, run the tasks it is sent, report each as it ends; exit when the run's pipe
    closes."""
    import signal
    import sys

    from optkin._exit import fast_exit
    from optkin.problems.workers import _recv, _send

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the run handles Ctrl-C
    preloaded = "distributed" in sys.modules
    try:
        _, address, timeout = _recv(rfd)
        t0 = time.perf_counter()
        if preloaded:  # Dask's configuration as this run finds it (its files, DASK_*), not
            import dask.config  # as it was when the server imported distributed (1 ms)

            dask.config.refresh()
        box: dict[str, Any] = {}
        _connect(address, box, float(timeout))
        if box.get("missing"):
            _send(wfd, ("missing",))
            fast_exit(0)
        if "client" not in box:
            _send(wfd, ("error", _why(box, False, float(timeout))))
            fast_exit(0)
        session = Session(box["client"])
        _send(wfd, ("connected", session.slots, {
            "preloaded": preloaded, "connect_seconds": time.perf_counter() - t0}))
        msg = _recv(rfd)
        if msg[0] != "run":
            fast_exit(0)
        _, tasks, time_limit = msg
        session.run(tasks, time_limit, lambda i, rs, why: _send(wfd, ("done", i, rs, why)))
        session.close()
    except (EOFError, BrokenPipeError):  # the run ended
        fast_exit(0)
    except BaseException as e:  # noqa: BLE001 - said to the run, which fails what is left
        with contextlib.suppress(OSError):
            _send(wfd, ("failed", f"{type(e).__name__}: {e}"))
    fast_exit(0)
