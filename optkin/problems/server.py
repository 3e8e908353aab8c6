"""A worker server: optkin's worker processes forked ready, for every run of this user.

Each ``optkin run`` starts its worker processes afresh, and each spends about 0.3 s
importing Python, numpy, CasADi, pydantic and optkin before its first problem: the fixed
cost of a run, paid again by every run. ``optkin workers start`` starts a server that
has imported all of that once and forks a worker for each request, ready in a few
milliseconds (``fork`` shares the loaded modules). While it runs, every ``optkin run``
(and :func:`optkin.problems.workers.run_jobs` in a notebook) of the same user, Python,
optkin and environment takes its workers from it; without one, or for a run it cannot
serve, workers start as before. The run still owns its workers: it talks to them over
its own pipes, enforces their time limits and kills them; a worker whose run ends or dies
exits too. ``optkin workers stop`` stops the server, which also exits after
``--idle`` minutes without a request (default :data:`IDLE_MINUTES`).

Safety:

* the socket lives in a directory of this user only (``$XDG_RUNTIME_DIR/optkin``, else
  ``/tmp/optkin-<uid>``), which must be a real directory owned by the user with no access
  for others: anything else is refused, never used;
* both ends check the other's user id (``SO_PEERCRED``);
* the socket's name is a hash of what the workers must share with the run: the Python
  executable, optkin's location and the modification times and sizes of its files, the
  module search path (and its directories' modification times, which an install or an
  upgrade changes), and the environment variables read when modules are imported
  (``PYTHON*``, ``LD_*``, ``MALLOC_*``, BLAS, numpy, CasADi, pydantic and ``OPTKIN_*``).
  A run with anything else different finds no server and starts its own workers, so a
  server never hands out stale code. The server checks the same for itself (on a
  request, at most once a second) and exits once it no longer matches.

After each run it has served, the run tells the server what it did (of each kind of work:
topology, task kinds, pictures or not, the unit estimated cheapest, if under
:data:`WARM_MAX_COST`). A copy of the server runs those units once, their results thrown
away, and takes over the socket (the old server first answers what is queued on it and
passes on what was asked meanwhile): the next run's workers are forked with those models,
compiled code and modules (matplotlib, cvxpy) loaded. Forking is safe only in a process of
one thread, so a unit that leaves a thread running (a solver's pool) is named in the log
and left out, and the copy starts again without it.

``optkin run --scheduler`` takes from the server a *Dask driver* instead: a forked process
that holds the run's Dask client (:func:`optkin.problems.dask_client.serve_driver`). After
the first such run the server imports ``distributed`` (:data:`DASK_MODULES`), so the next
run's client connects without the 0.3 s import, and the run itself never imports it.

A forked worker runs with one BLAS thread (as every worker of a parallel run does), in the
run's working directory and with the run's environment. Linux only (``fork``, file
descriptors passed over the socket, ``pidfd``); elsewhere runs start their own workers.

This module imports only the standard library; the server process imports the rest.
"""

from __future__ import annotations

import base64
import contextlib
import hashlib
import json
import os
import select
import signal
import socket
import stat
import struct
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["IDLE_MINUTES", "ServerError", "runtime_dir", "socket_path", "start", "status",
           "stop", "stop_all", "fork_worker"]

#: Minutes a server stays without a request before it exits.
IDLE_MINUTES = 30.0
#: Seconds a client waits for the server's answer (a healthy one answers in milliseconds).
_TIMEOUT = 5.0
#: Seconds ``start`` waits for a new server to import everything and answer.
_START_LIMIT = 120.0
#: Set to 0 to never use a server (the tests of other modules, to measure without one).
ENV_DISABLE = "OPTKIN_WORKER_SERVER"
#: Environment variables read when modules are imported (a server's workers must match
#: the run in these); the thread counts are left out: a server's workers run one thread.
_IMPORT_ENV = ("PYTHON", "LD_", "MALLOC_", "OMP_", "OPENBLAS_", "MKL_", "NPY_", "NUMPY_",
               "CASADI", "PYDANTIC", "DASK_", "OPTKIN_", "VIRTUAL_ENV", "CONDA_PREFIX")
_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_NOT_KEYED = (ENV_DISABLE, "MALLOC_TRIM_THRESHOLD_", *_THREAD_ENV)
_MAX_REQUEST = 1 << 20


class ServerError(RuntimeError):
    """The worker server cannot be used (its directory is unsafe, it does not answer)."""


def supported() -> bool:
    return (sys.platform.startswith("linux") and hasattr(os, "pidfd_open")
            and hasattr(socket, "send_fds") and hasattr(os, "fork"))


def runtime_dir(create: bool = False) -> Path:
    """This user's directory for worker-server sockets, checked: a directory (not a
    link) owned by this user, with no access for group or others. ``ServerError``
    names it and the fix otherwise."""
    base = os.environ.get("XDG_RUNTIME_DIR")
    uid = os.getuid()
    d = Path(base) / "optkin" if base and os.path.isdir(base) else Path(f"/tmp/optkin-{uid}")
    if create:
        with contextlib.suppress(FileExistsError):
            os.mkdir(d, 0o700)
    try:
        st = os.lstat(d)
    except FileNotFoundError:
        raise ServerError(f"{d} does not exist") from None
    if not stat.S_ISDIR(st.st_mode) or st.st_uid != uid or st.st_mode & 0o077:
        raise ServerError(
            f"{d} is not a private directory of this user (owner uid {st.st_uid}, mode "
            f"{stat.filemode(st.st_mode)}); remove it or set XDG_RUNTIME_DIR to one")
    return d


def _optkin_root() -> Path:
    import optkin

    return Path(optkin.__file__).resolve().parent


def boot_path() -> list[str]:
    """The module search path of workers (:func:`optkin.problems.workers._boot_path`)."""
    from optkin.problems.workers import _boot_path

    return _boot_path()


def _fingerprint(path: list[str]) -> str:
    h = hashlib.sha256()
    root = _optkin_root()
    # (the interpreter itself: ``optkin``'s script names ``python3``, ``python -m`` may be
    # ``python``, links to one file; the module path below tells environments apart)
    h.update(f"{os.path.realpath(sys.executable)}\0{sys.version}\0{root}\0".encode())
    for p in sorted(root.rglob("*.py")):
        with contextlib.suppress(OSError):
            st = p.stat()
            h.update(f"{p}\0{st.st_mtime_ns}\0{st.st_size}\0".encode())
    for p in path:
        try:
            st = os.stat(p)
            h.update(f"{p}\0{st.st_mtime_ns}\0".encode())
        except OSError:
            h.update(f"{p}\0-\0".encode())
    return h.hexdigest()


def _env_part(env: dict[str, str]) -> list[tuple[str, str]]:
    return sorted((k, v) for k, v in env.items()
                  if k.startswith(_IMPORT_ENV) and k not in _NOT_KEYED)


_KEYS: dict[tuple, str] = {}


def key(env: dict[str, str], path: list[str] | None = None, fresh: bool = False) -> str:
    """The name a server for workers of this environment (and this process's Python,
    optkin and module path) listens under; ``fresh`` stats the files again."""
    path = boot_path() if path is None else path
    memo = (tuple(path), tuple(_env_part(env)))
    if fresh or memo not in _KEYS:  # the files are stat'ed once per process (1-2 ms)
        h = hashlib.sha256(_fingerprint(path).encode())
        h.update(json.dumps(_env_part(env)).encode())
        _KEYS[memo] = h.hexdigest()[:20]
    return _KEYS[memo]


def socket_path(env: dict[str, str] | None = None, create: bool = False) -> Path:
    env = dict(os.environ) if env is None else env
    return runtime_dir(create) / f"workers-{key(env)}.sock"


# ---------------------------------------------------------------------------
# messages: 4-byte length + JSON, file descriptors alongside the first bytes
# ---------------------------------------------------------------------------


def _send_msg(sock: socket.socket, obj: Any, fds: list[int] = ()) -> None:
    data = json.dumps(obj).encode()
    data = struct.pack("<I", len(data)) + data
    if fds:
        n = socket.send_fds(sock, [data], list(fds))
        data = data[n:]
    if data:  # (an empty send to a peer that has read all and closed fails: EPIPE)
        sock.sendall(data)


def _recv_msg(sock: socket.socket, maxfds: int = 0) -> tuple[Any, list[int]]:
    fds: list[int] = []
    if maxfds:
        buf, fds, _, _ = socket.recv_fds(sock, 65536, maxfds)
    else:
        buf = sock.recv(65536)
    while len(buf) < 4:
        more = sock.recv(65536)
        if not more:
            raise EOFError
        buf += more
    (n,) = struct.unpack("<I", buf[:4])
    if n > _MAX_REQUEST:
        raise EOFError(f"message of {n} bytes refused")
    while len(buf) < 4 + n:
        more = sock.recv(65536)
        if not more:
            raise EOFError
        buf += more
    return json.loads(buf[4:4 + n]), fds


def _peer_uid(sock: socket.socket) -> int:
    creds = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    return struct.unpack("3i", creds)[1]


def _request(path: Path, obj: Any, fds: list[int] = (), maxfds: int = 0,
             timeout: float = _TIMEOUT) -> tuple[Any, list[int]]:
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
        s.settimeout(timeout)
        s.connect(str(path))
        if _peer_uid(s) != os.getuid():
            raise ServerError(f"{path}: the server is another user's")
        _send_msg(s, obj, fds)
        return _recv_msg(s, maxfds)


# ---------------------------------------------------------------------------
# the client side
# ---------------------------------------------------------------------------


class Forked:
    """A worker forked by the server, with the part of ``subprocess.Popen`` the runner
    uses (``pid``, ``poll``, ``wait``, ``kill``, ``returncode``), through a pidfd: the
    run is not its parent, the server is (and reports its exit status)."""

    def __init__(self, pid: int, pidfd: int, server: Path) -> None:
        self.pid, self._pidfd, self._server = pid, pidfd, server
        self.returncode: int | None = None
        self._killed = False

    def _ended(self, timeout: float | None) -> bool:
        if self._pidfd < 0:
            return True
        r, _, _ = select.select([self._pidfd], [], [], timeout)
        return bool(r)

    def _collect(self) -> int:
        code = None
        with contextlib.suppress(Exception):
            got, _ = _request(self._server, {"op": "status", "pid": self.pid})
            if got.get("status") is not None:
                code = os.waitstatus_to_exitcode(int(got["status"]))
        if code is None:  # the server is gone: what is known
            code = -signal.SIGKILL if self._killed else 255
        self.returncode = code
        with contextlib.suppress(OSError):
            os.close(self._pidfd)
        self._pidfd = -1
        return code

    def poll(self) -> int | None:
        if self.returncode is None and self._ended(0):
            self._collect()
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if self.returncode is None:
            if not self._ended(timeout):
                raise subprocess.TimeoutExpired(f"worker {self.pid}", timeout or 0.0)
            self._collect()
        return self.returncode  # type: ignore[return-value]

    def kill(self) -> None:
        if self.returncode is None and self._pidfd >= 0:
            self._killed = True
            with contextlib.suppress(ProcessLookupError, OSError):
                signal.pidfd_send_signal(self._pidfd, signal.SIGKILL)

    def __del__(self) -> None:
        if self._pidfd >= 0:
            with contextlib.suppress(OSError):
                os.close(self._pidfd)


def fork_worker(env: dict[str, str], rfd: int, wfd: int, errfd: int,
                role: str = "worker") -> Forked | None:
    """A worker forked by this environment's server, on the given pipe ends (its stdin
    side ``rfd``, its stdout side ``wfd``, its stderr ``errfd``), or None when there is no
    server to use (none running, disabled, unsupported): the caller starts its own worker.
    ``role`` ``"dask"``: the process is instead a Dask driver for ``optkin run
    --scheduler`` (:func:`optkin.problems.dask_client.serve_driver`).

    ``ServerError`` when the ends were sent but no answer came back (a server that died or
    hangs): a worker may have been forked on them, so the caller must not give them to
    another (it makes new ones; that worker, if any, exits when they close)."""
    if env.get(ENV_DISABLE, os.environ.get(ENV_DISABLE, "1")) == "0" or not supported():
        return None
    try:
        d = runtime_dir()
        if not any(n.startswith("workers-") and n.endswith(".sock") for n in os.listdir(d)):
            return None  # no server at all (the key's 5 ms are not spent)
        path = socket_path(env)
        if not path.exists():
            return None
        try:
            cwd = os.getcwd()
        except OSError:
            cwd = "/"
    except (OSError, ServerError, ValueError):
        return None
    try:
        got, fds = _request(path, {"op": "fork", "env": env, "cwd": cwd, "role": role},
                            [rfd, wfd, errfd], maxfds=1)
    except (OSError, ServerError, EOFError, ValueError) as e:
        raise ServerError(f"the worker server at {path} did not answer: "
                          f"{type(e).__name__}: {e}") from None
    if not got.get("pid") or len(fds) != 1:
        for fd in fds:
            os.close(fd)
        raise ServerError(f"the worker server at {path} forked no worker: {got}")
    return Forked(int(got["pid"]), fds[0], path)


def status(env: dict[str, str] | None = None) -> dict[str, Any] | None:
    """What the worker server for this environment says of itself, or None when none
    answers (``optkin workers status``).

    ``env`` is the environment of the runs it would serve (default: this process's).
    The answer holds ``pid``, ``socket``, ``forked`` (workers forked so far), ``warmed``
    (the kinds of work its workers start warm for, ``topology|task kinds|pictures``),
    ``warming`` (a warm-up in progress), ``idle_for`` and ``idle_seconds``.
    """
    try:
        path = socket_path(env)
        if not path.exists():
            return None
        got, _ = _request(path, {"op": "ping"})
        return dict(got, socket=str(path))
    except (OSError, ServerError, EOFError, ValueError):
        return None


def stop_all() -> int:
    """Stop every worker server of this user (``optkin workers stop --all``), those of
    other environments and of earlier optkin files too; how many answered."""
    try:
        socks = sorted(runtime_dir().glob("workers-*.sock"))
    except (OSError, ServerError):
        return 0
    n = 0
    for path in socks:
        with contextlib.suppress(OSError, ServerError, EOFError, ValueError):
            _request(path, {"op": "stop"})
            n += 1
    return n


def stop(env: dict[str, str] | None = None) -> bool:
    """Stop the worker server for this environment (``optkin workers stop``); whether
    one was running. Workers it forked for runs still going on are not touched: they
    belong to their runs."""
    try:
        path = socket_path(env)
        _request(path, {"op": "stop"})
        return True
    except (OSError, ServerError, EOFError, ValueError):
        return False


#: A unit is used to warm a server up when its estimated cost is at most this (seconds).
WARM_MAX_COST = 2.0


def warm(env: dict[str, str], units: list[dict[str, Any]]) -> bool:
    """Ask the server that forked a run's workers to warm up with ``units`` (one
    problem of each kind of work the run did: ``label``, ``display``, ``source``, the
    file's bytes as ``data``, ``pictures``, ``only``): it runs them once in a copy of
    itself that then takes over, so the next run's workers find their models loaded.
    Never raises; whether the server took the request."""
    try:
        return _warm_request(socket_path(env), units, timeout=1.0)
    except (OSError, ServerError, EOFError, ValueError, KeyError, TypeError):
        return False


def _warm_request(path: Path, units: list[dict[str, Any]], timeout: float) -> bool:
    """Send ``units`` (their ``data`` as bytes) to the server at ``path`` to warm up with."""
    req = {"op": "warm", "units": [
        dict(u, data=base64.b64encode(u["data"]).decode()) if "data" in u else dict(u)
        for u in units]}
    got, _ = _request(path, req, timeout=timeout)
    return bool(got.get("ok"))


_SERVER_BOOT = (
    "import gc, sys\n"
    "gc.disable()\n"
    "root, sock, idle = sys.argv[1], sys.argv[2], float(sys.argv[3])\n"
    "sys.path[:] = [root] + [p for p in sys.argv[4:] if p not in ('', '.', root)]\n"
    "from optkin.problems.server import serve_forever\n"
    "serve_forever(sock, idle)\n"
)


def start(idle_minutes: float = IDLE_MINUTES,
          env: dict[str, str] | None = None) -> dict[str, Any]:
    """Start the worker server for this environment, or find it running (``optkin
    workers start``); what it says of itself (:func:`status`, with ``started_now``).

    The server is a process of its own (it outlives the caller), which exits after
    ``idle_minutes`` without a request, at :func:`stop`, or at its first request once
    optkin's files or the module path's directories have changed. ``env``: the
    environment of the runs to serve (default: this process's). Raises
    :class:`ServerError`, with the reason and what to do, when it cannot start (not
    Linux, an unsafe runtime directory, a server that does not come up: its log is
    named)."""
    if not supported():
        raise ServerError("the worker server needs Linux (fork, pidfd); runs start their "
                          "own workers here")
    env = dict(os.environ if env is None else env)
    env.pop(ENV_DISABLE, None)
    up = status(env)
    if up is not None:
        return dict(up, started_now=False)
    path = socket_path(env, create=True)
    for k in _THREAD_ENV:
        env[k] = "1"
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    log = path.with_suffix(".log")
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC | os.O_NOFOLLOW, 0o600)
    try:
        proc = subprocess.Popen(
            [sys.executable, "-S", "-c", _SERVER_BOOT, str(_optkin_root().parent), str(path),
             str(max(0.0, idle_minutes) * 60.0), *boot_path()],
            stdin=subprocess.DEVNULL, stdout=fd, stderr=fd, env=env, cwd="/",
            start_new_session=True, close_fds=True)
    finally:
        os.close(fd)
    end = time.monotonic() + _START_LIMIT
    while time.monotonic() < end:
        up = status(env)
        if up is not None:
            return dict(up, started_now=True)
        if proc.poll() is not None:
            tail = log.read_text(errors="replace").strip().splitlines()[-1:] or ["(nothing)"]
            raise ServerError(f"the worker server exited with status {proc.returncode}: "
                              f"{tail[0][:300]} (log: {log})")
        time.sleep(0.02)
    proc.kill()
    raise ServerError(f"the worker server did not answer within {_START_LIMIT:g} s "
                      f"(log: {log})")


# ---------------------------------------------------------------------------
# the server side
# ---------------------------------------------------------------------------


class _Stop(Exception):
    pass


def _threads() -> int:
    """Threads of this process, the native ones too."""
    return len(os.listdir("/proc/self/task"))


def _watch_run(fd: int) -> None:
    """In a forked worker: exit when the run's end of its pipe closes (the run ended or
    died; a worker started by the run itself gets this from ``PR_SET_PDEATHSIG``)."""
    p = select.poll()
    p.register(fd, 0)  # hang-up and errors are always reported
    while True:
        for _, ev in p.poll():
            if ev & (select.POLLHUP | select.POLLERR | select.POLLNVAL):
                os._exit(0)


def _child(req: dict[str, Any], rfd: int, wfd: int, errfd: int,
           close: list[socket.socket], close_fds: list[int] = ()) -> None:
    try:
        for s in close:
            s.close()
        for fd in close_fds:
            os.close(fd)
        os.dup2(errfd, 2)
        os.close(errfd)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)  # not the server's log (a solver's banner, a stray print)
        os.close(null)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        with contextlib.suppress(OSError):
            os.chdir(req.get("cwd") or "/")
        env = {str(k): str(v) for k, v in dict(req.get("env") or {}).items()}
        for k in _THREAD_ENV:
            env[k] = "1"
        os.environ.clear()
        os.environ.update(env)
        import threading

        threading.Thread(target=_watch_run, args=(rfd,), daemon=True).start()
        if req.get("role") == "dask":
            from optkin.problems.dask_client import serve_driver

            serve_driver(rfd, wfd)
        else:
            from optkin.problems.workers import serve

            serve(rfd, wfd, None)
    except BaseException:  # noqa: BLE001 - a worker never returns into the server's loop
        import traceback

        traceback.print_exc()
        os._exit(1)
    os._exit(0)


#: Seconds a warm-up (the server's copy running the problems of a run once) may take.
WARM_LIMIT = 60.0
#: Seconds a warmed copy waits to take over while workers of the old server still run
#: (their exit statuses are the old server's to report).
_HANDOFF_WAIT = 10.0
#: Most units a server keeps to warm up with (the most recent first).
WARM_MAX = 24
#: What a server imports once a run has used a Dask driver it forked (label
#: :data:`DASK_LABEL`): the next driver connects without importing ``distributed`` (0.3 s).
DASK_MODULES = ("distributed", "optkin.problems.dask_worker", "optkin.problems.dask_client")
DASK_LABEL = "dask-driver"


class _Server:
    """The server's state and loop (one process; a warmed copy of it takes over)."""

    def __init__(self, path: Path, idle: float) -> None:
        self.path, self.idle = path, idle
        self.env = dict(os.environ)
        self.keyed = sys.argv[4:]  # the module path the key was made with (the starter's)
        self.mine = key(self.env, self.keyed, fresh=True)
        if path.name != f"workers-{self.mine}.sock":  # another optkin or environment
            raise ServerError(f"{path}: not this server's name (workers-{self.mine}.sock)")
        self.checked = self.last = time.monotonic()
        self.info: dict[str, Any] = {
            "pid": os.getpid(), "started": time.time(), "idle_seconds": idle,
            "python": sys.executable, "optkin": str(_optkin_root()), "forked": 0,
            "warmed": []}
        self.statuses: dict[int, int] = {}
        self.live: set[int] = set()  # workers forked and not yet ended
        self.specs: dict[str, dict[str, Any]] = {}  # units to warm up with, by label
        self.warmed: set[str] = set()
        self.failed: set[str] = set()
        self.warmer: dict[str, Any] | None = None
        self.want_warm = False
        self.handed: set[str] = set()
        self.listener, self.ino = self._listen()

    def _listen(self) -> tuple[socket.socket, int]:
        """A listening socket at a private name (:meth:`_publish` gives it the path)."""
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        s = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        s.bind(str(tmp))
        os.chmod(tmp, 0o600)
        s.listen(64)
        return s, os.stat(tmp).st_ino

    def _publish(self, pid: int | None = None) -> None:
        """Rename the listening socket of this process (or of ``pid``) to the path: a
        stale socket of a server that died, or this server's own, is replaced at once."""
        os.replace(self.path.with_name(f".{self.path.name}.{pid or os.getpid()}"), self.path)

    # -- requests ----------------------------------------------------------------------

    def reap(self) -> None:
        while True:
            try:
                pid, st = os.waitpid(-1, os.WNOHANG)
            except ChildProcessError:
                return
            if pid == 0:
                return
            self.statuses[pid] = st
            self.live.discard(pid)
            while len(self.statuses) > 10000:
                self.statuses.pop(next(iter(self.statuses)))

    def handle(self, conn: socket.socket) -> None:
        conn.settimeout(_TIMEOUT)
        if _peer_uid(conn) != os.getuid():
            return
        req, fds = _recv_msg(conn, maxfds=3)
        try:
            op = req.get("op")
            if op == "ping":
                _send_msg(conn, dict(self.info, idle_for=time.monotonic() - self.last,
                                     warming=self.warmer is not None))
            elif op == "stop":
                _send_msg(conn, {"stopping": True})
                raise _Stop
            elif op == "status":
                self.reap()
                _send_msg(conn, {"status": self.statuses.get(int(req["pid"]))})
            elif op == "fork" and len(fds) == 3:
                pid = os.fork()
                if pid == 0:
                    _child(req, *fds, close=[self.listener, conn],
                           close_fds=[self.warmer["ready"], self.warmer["go"]]
                           if self.warmer else [])
                self.info["forked"] += 1
                self.live.add(pid)
                pidfd = os.pidfd_open(pid)
                try:
                    _send_msg(conn, {"pid": pid}, [pidfd])
                finally:
                    os.close(pidfd)
            elif op == "warm":
                _send_msg(conn, {"ok": True})
                for u in list(req.get("units") or [])[:WARM_MAX]:
                    label = str(u["label"])
                    if label in self.failed:
                        continue
                    self.specs.pop(label, None)  # the most recent last
                    if u.get("dask"):  # a Dask driver's modules, nothing else
                        self.specs[label] = {"dask": True}
                        continue
                    self.specs[label] = {
                        "display": str(u["display"]), "source": str(u["source"]),
                        "data": base64.b64decode(u["data"]),
                        "pictures": bool(u.get("pictures")), "only": u.get("only")}
                while len(self.specs) > WARM_MAX:
                    self.specs.pop(next(iter(self.specs)))
                self.want_warm = True  # once this connection is closed
            else:
                _send_msg(conn, {"error": f"unknown request {op!r}"})
        finally:
            for fd in fds:
                os.close(fd)

    # -- warming up --------------------------------------------------------------------

    def _start_warmer(self) -> None:
        """Fork a copy that runs one unit of each label not yet warmed (results thrown
        away) and then takes over: workers forked from it find the models, compiled code
        and modules those problems need already loaded."""
        labels = [x for x in self.specs if x not in self.failed]
        if set(labels) <= self.warmed:
            return
        r_ready, w_ready = os.pipe()
        r_go, w_go = os.pipe()
        pid = os.fork()
        if pid == 0:
            try:
                os.close(r_ready)
                os.close(w_go)
                self._warm(labels, w_ready, r_go)
            except BaseException:  # noqa: BLE001 - never back into the old server's loop
                import traceback

                traceback.print_exc()
            os._exit(1)
        os.close(w_ready)
        os.close(r_go)
        self.warmer = {"pid": pid, "ready": r_ready, "go": w_go, "labels": labels,
                       "until": time.monotonic() + WARM_LIMIT, "since": None}

    def _warm(self, labels: list[str], ready: int, go: int) -> None:
        """In the warming copy: run the units, then wait for the old server's word."""
        import gc
        import importlib

        from optkin.problems.runner import worker_job

        self.listener.close()  # the old server's: this copy answers on its own
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.close(null)
        done = []
        t0 = time.monotonic()
        for label in labels:
            if label in self.warmed:
                done.append(label)
                continue
            if time.monotonic() - t0 > WARM_LIMIT / 2:  # the rest at the next warm-up
                break
            spec = dict(self.specs[label], validate=False, time_limit=None)
            t = time.monotonic()
            try:
                if spec.get("dask"):
                    for name in DASK_MODULES:
                        importlib.import_module(name)
                else:
                    worker_job("warm", spec, lambda msg: None)
                done.append(label)
            except BaseException as e:  # noqa: BLE001 - a problem that fails warms nothing
                print(f"warm-up {label}: {type(e).__name__}: {e}", file=sys.stderr)
            # forking is safe in one thread only: a unit that leaves a thread running (a
            # solver's pool) is named to the server, which warms up again without it
            end = time.monotonic() + 2.0
            while _threads() > 1 and time.monotonic() < end:
                time.sleep(0.02)
            if _threads() > 1:
                print(f"warm-up {label}: leaves {_threads() - 1} thread(s) running; not "
                      "warmed", file=sys.stderr, flush=True)
                os.write(ready, b"b" + label.encode() + b"\n")
                os._exit(3)
            print(f"warm-up {label}: {time.monotonic() - t:.2f} s", file=sys.stderr,
                  flush=True)
        gc.collect()
        gc.freeze()
        self.listener, self.ino = self._listen()
        os.write(ready, b"r")
        if os.read(go, 1) != b"g":  # the old server ended without handing over
            with contextlib.suppress(OSError):
                self.path.with_name(f".{self.path.name}.{os.getpid()}").unlink()
            os._exit(0)
        os.close(ready)
        os.close(go)
        self.warmed |= set(done)
        self.statuses.clear()
        self.live.clear()
        self.warmer = None
        self.info.update(pid=os.getpid(), warmed=sorted(self.warmed))
        self.loop()
        os._exit(0)

    def _check_warmer(self, readable: bool) -> bool:
        """Follow the warming copy; True once it has taken over (this server then ends)."""
        w = self.warmer
        assert w is not None
        now = time.monotonic()
        if readable:
            got = os.read(w["ready"], 4096)
            if got == b"r":
                w["since"] = now
            elif got.startswith(b"b"):  # a unit that leaves a thread: again without it
                self.failed.add(got[1:].split(b"\n")[0].decode(errors="replace"))
                self._drop_warmer(kill=False, fail=False)
                self._start_warmer()
                return False
            else:  # it ended before it was ready
                self._drop_warmer(kill=False)
                return False
        if w["since"] is None:
            if now > w["until"]:
                self._drop_warmer(kill=True)
            return False
        if self.live and now - w["since"] < _HANDOFF_WAIT:
            return False
        self._publish(w["pid"])
        os.write(w["go"], b"g")
        self.handed = set(w["labels"])
        for fd in (w["ready"], w["go"]):
            os.close(fd)
        self.warmer = None  # (not to be killed on the way out: it serves now)
        return True

    def _drop_warmer(self, kill: bool, fail: bool = True) -> None:
        w = self.warmer
        assert w is not None
        if kill:
            with contextlib.suppress(ProcessLookupError):
                os.kill(w["pid"], signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(w["pid"], 0)
        for fd in (w["ready"], w["go"]):
            os.close(fd)
        with contextlib.suppress(OSError):
            self.path.with_name(f".{self.path.name}.{w['pid']}").unlink()
        if fail:
            self.failed |= set(w["labels"]) - self.warmed
        self.warmer = None

    # -- the loop ----------------------------------------------------------------------

    def _forward(self) -> None:
        """Pass to the warmed copy the units asked for since it was forked."""
        units = [{"label": label, "dask": True} if u.get("dask") else
                 {"label": label, "display": u["display"], "source": u["source"],
                  "data": u["data"], "pictures": u["pictures"], "only": u["only"]}
                 for label, u in self.specs.items() if label not in self.handed]
        if units:  # (to the path, which names the copy now: not this process's key)
            with contextlib.suppress(OSError, ServerError, EOFError, ValueError):
                _warm_request(self.path, units, timeout=_TIMEOUT)

    def _drain(self) -> None:
        """Answer the connections already queued here: since the path names the warmed
        copy's socket, no new one comes, and those would otherwise be reset."""
        self.listener.setblocking(False)
        while True:
            try:
                conn, _ = self.listener.accept()
            except OSError:  # none left (BlockingIOError)
                return
            with conn:
                with contextlib.suppress(_Stop, OSError, EOFError, ValueError, KeyError,
                                         TypeError):
                    conn.setblocking(True)
                    self.handle(conn)

    def loop(self) -> None:
        """Serve until idle, stopped, replaced, or out of date."""
        try:
            while True:
                self.reap()
                if time.monotonic() - self.last > self.idle:
                    return
                try:  # the socket replaced or removed: no longer ours
                    if os.stat(self.path).st_ino != self.ino:
                        return
                except OSError:
                    return
                watch = [self.listener] + ([self.warmer["ready"]] if self.warmer else [])
                r, _, _ = select.select(watch, [], [], 0.5 if self.warmer else 1.0)
                if self.warmer is not None and self._check_warmer(self.warmer["ready"] in r):
                    self._drain()
                    self._forward()
                    return
                if self.listener not in r:
                    continue
                try:
                    conn, _ = self.listener.accept()
                except (BlockingIOError, TimeoutError):
                    continue
                with conn:
                    if time.monotonic() - self.checked > 1.0:  # optkin or a package changed?
                        self.checked = time.monotonic()
                        if key(self.env, self.keyed, fresh=True) != self.mine:
                            return
                    try:
                        self.handle(conn)
                    except _Stop:
                        return
                    except (OSError, EOFError, ValueError, KeyError, TypeError):
                        pass
                self.last = time.monotonic()
                if self.want_warm and self.warmer is None:
                    self.want_warm = False
                    self._start_warmer()
        finally:
            with contextlib.suppress(OSError):
                if os.stat(self.path).st_ino == self.ino:
                    self.path.unlink()
            self.listener.close()
            if self.warmer is not None:
                self._drop_warmer(kill=True)


def serve_forever(sock_path: str, idle: float) -> None:
    """The server process: import what workers import, then fork one per request."""
    import gc

    from optkin.problems import (
        runner,  # noqa: F401 - loaded once, shared by every fork
        schema,  # noqa: F401
    )
    from optkin.problems.workers import _preload

    _preload()
    gc.freeze()
    gc.enable()
    server = _Server(Path(sock_path), idle)
    server._publish()
    server.loop()
