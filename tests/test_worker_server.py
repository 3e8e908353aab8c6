"""The worker server (``optkin workers start``): runs take workers it forks ready, get the
results a run without it gets, keep their time limits and death reports, and never use a
server they must not (another user's directory, another environment, changed files)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import pytest

from optkin.problems import server as sv
from optkin.problems import workers as wk

pytestmark = pytest.mark.skipif(not sv.supported(), reason="the worker server needs Linux "
                                "(fork, pidfd, file descriptors over a socket)")

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"
STEWART = (PROBLEMS / "stewart_gough.toml").read_text().split("[[task]]")[0]
#: a task that takes a few seconds (a 6-6 platform, every start of a large budget)
SLOW_TASK = """
[[task]]
kind = "assembly_modes"
qa = [1.2, 1.25, 1.3, 1.2, 1.25, 1.3]
options = { starts = 200000, min_starts = 200000, target = 0.0, time_limit = 600.0 }
"""


def _spec(name: str, file: str = "four_bar.toml", text: str | None = None) -> dict:
    path = PROBLEMS / file
    data = text.encode() if text is not None else path.read_bytes()
    return {"display": name, "data": data, "source": str(path), "pictures": False}


def _numbers(obj):
    """A task output without its timings."""
    if isinstance(obj, dict):
        return {k: _numbers(v) for k, v in obj.items()
                if not (k.endswith("_time") or k in ("time", "elapsed"))}
    if isinstance(obj, list):
        return [_numbers(v) for v in obj]
    return obj


def _ppid(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("PPid:"):
            return int(line.split()[1])
    raise AssertionError(pid)


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError):
        return False
    return state not in ("Z", "X")


def _wait_gone(pid: int, limit: float) -> bool:
    end = time.monotonic() + limit
    while time.monotonic() < end:
        if not _alive(pid):
            return True
        time.sleep(0.05)
    return False


def _drop_idle() -> None:
    """Close every idle worker of this process: the next run starts (or forks) new ones."""
    with wk._IDLE_LOCK:
        idle = [w for pool in wk._IDLE.values() for w in pool]
        wk._IDLE.clear()
    for w in idle:
        w.close(wait=5)


@pytest.fixture
def runtime(monkeypatch):
    """A private runtime directory (short: a socket path has at most 107 bytes)."""
    d = tempfile.mkdtemp(prefix="okw")
    monkeypatch.setenv("XDG_RUNTIME_DIR", d)
    monkeypatch.delenv(sv.ENV_DISABLE, raising=False)
    _drop_idle()
    yield Path(d)
    _drop_idle()
    sv.stop()
    shutil.rmtree(d, ignore_errors=True)


@pytest.fixture
def server(runtime):
    info = sv.start(idle_minutes=5)
    assert info["started_now"]
    yield info
    sv.stop()
    assert _wait_gone(info["pid"], 10)


def test_a_run_takes_workers_forked_by_the_server_and_gets_the_same_results(server,
                                                                            monkeypatch):
    specs = [("a", "four_bar.toml"), ("b", "rpr3.toml"), ("c", "five_bar.toml")]
    jobs = [wk.Job(n, _spec(n, f)) for n, f in specs]
    served = wk.run_jobs(jobs, n_workers=2, threads=1)
    assert [o.kind for o in served] == ["done"] * 3, [o.message for o in served]
    pids = {o.result["worker"]["pid"] for o in served}
    with wk._IDLE_LOCK:
        idle = [w for pool in wk._IDLE.values() for w in pool]
    assert {w.proc.pid for w in idle} == pids
    for w in idle:  # forked by the server, which is not this process
        assert isinstance(w.proc, sv.Forked) and _ppid(w.proc.pid) == server["pid"]
    assert sv.status()["forked"] == len(pids)
    # the same problems in workers this process starts itself
    _drop_idle()
    monkeypatch.setenv(sv.ENV_DISABLE, "0")
    own = wk.run_jobs([wk.Job(n, _spec(n, f)) for n, f in specs], n_workers=2, threads=1)
    assert not {o.result["worker"]["pid"] for o in own} & pids
    assert sv.status()["forked"] == len(pids)  # not asked
    for a, b in zip(sorted(served, key=lambda o: o.key), sorted(own, key=lambda o: o.key)):
        ta, tb = a.result["tasks"], b.result["tasks"]
        assert [t["status"] for t in ta] == [t["status"] for t in tb] == ["ok"] * len(ta)
        assert json.dumps(_numbers([t["output"] for t in ta])) == \
            json.dumps(_numbers([t["output"] for t in tb]))


def test_a_forked_worker_past_its_time_limit_is_killed_and_the_next_task_runs(server):
    text = STEWART + SLOW_TASK.replace("options = {", "time_limit = 0.5\noptions = {") + \
        '\n[[task]]\nkind = "dof"\n'
    t0 = time.perf_counter()
    (o,) = wk.run_jobs([wk.Job("slow", _spec("slow.toml", text=text))], threads=1)
    assert time.perf_counter() - t0 < 30
    first, second = o.result["tasks"]
    assert first["status"] == "error" and "time limit of 0.5 s exceeded" in first["message"]
    assert second["status"] == "ok"
    assert sv.status()["forked"] == 2  # the killed worker's task went to a fresh fork


def test_a_forked_worker_that_crashes_is_reported_with_its_signal(server):
    text = STEWART + SLOW_TASK + '\n[[task]]\nkind = "dof"\n'
    box: dict = {}
    t = threading.Thread(target=lambda: box.update(o=wk.run_jobs(
        [wk.Job("slow", _spec("slow.toml", text=text))], threads=1)))
    t.start()
    pid = None
    end = time.monotonic() + 60
    while pid is None and time.monotonic() < end:
        for w in list(wk._LIVE):
            if w.task == 0 and not w.dead and w.proc.poll() is None:
                pid = w.proc.pid
        time.sleep(0.02)
    assert pid is not None, "no worker ran the task"
    time.sleep(0.3)
    os.kill(pid, signal.SIGSEGV)  # a crash in a C library
    t.join(60)
    assert not t.is_alive()
    first, second = box["o"][0].result["tasks"]
    # the exit status comes from the server, the process's parent
    assert first["status"] == "error" and "killed by SIGSEGV" in first["message"], first
    assert second["status"] == "ok"


_CLIENT = r"""
import json, os, queue, sys, time
sys.path[:] = json.loads(sys.argv[2])  # the test's module path: the same server key
from optkin.problems import workers as wk
w = wk._Worker(wk._worker_env(1), queue.Queue())
assert w.events.get(timeout=60)[1][0] == "ready"
w.send(("job", "j", {"display": "slow.toml", "data": open(sys.argv[1], "rb").read(),
                     "source": sys.argv[1], "pictures": False}))
print(type(w.proc).__name__, w.proc.pid, flush=True)
time.sleep(600)
"""


def test_a_forked_worker_exits_when_its_run_dies(server, tmp_path):
    """A worker the run started itself gets SIGKILL from Linux when its parent dies; a
    forked one watches the run's end of its pipe: a killed run leaves no worker behind,
    even one in the middle of a long task."""
    f = tmp_path / "slow.toml"  # three times the budget: about 12 s alone
    f.write_text(STEWART + SLOW_TASK.replace("200000", "600000"))
    client = subprocess.Popen([sys.executable, "-c", _CLIENT, str(f),
                               json.dumps(wk._boot_path())],
                              stdout=subprocess.PIPE, text=True, env=dict(os.environ))
    try:
        kind, pid = client.stdout.readline().split()
        assert kind == "Forked" and _ppid(int(pid)) == server["pid"]
        time.sleep(0.5)
        assert _alive(int(pid))  # busy with the task
    finally:
        client.kill()
        client.wait()
    # at once, not when the task ends and its report finds no reader
    assert _wait_gone(int(pid), 3), "the worker outlived its run"


def test_an_unsafe_runtime_directory_is_refused_and_runs_start_their_own(runtime, capsys,
                                                                          monkeypatch):
    d = runtime / "optkin"
    d.mkdir(mode=0o755)
    d.chmod(0o755)  # (the umask may have removed bits; these must be there)
    with pytest.raises(sv.ServerError, match=r"not a private directory.*set XDG_RUNTIME_DIR"):
        sv.start()
    from optkin.cli import main

    assert main(["workers", "start"]) == 2
    assert "not a private directory" in capsys.readouterr().err
    assert sv.fork_worker(wk._worker_env(1), 0, 0, 0) is None
    (o,) = wk.run_jobs([wk.Job("a", _spec("a"))], threads=1)  # its own worker
    assert o.kind == "done"
    d.rmdir()
    target = runtime / "elsewhere"
    target.mkdir(mode=0o700)
    d.symlink_to(target)  # a link, even to a private directory, is not used
    with pytest.raises(sv.ServerError, match="not a private directory"):
        sv.start()


def test_a_server_for_another_environment_is_not_used(server, monkeypatch):
    env = wk._worker_env(1)
    assert sv.socket_path(env).exists()
    other = dict(env, OPTKIN_SOMETHING="1")  # read at import time, as far as we know
    assert sv.socket_path(other) != sv.socket_path(env)
    assert sv.fork_worker(other, 0, 0, 0) is None
    # the thread counts and Dask's malloc setting are not part of the key
    same = dict(env, OMP_NUM_THREADS="4", MALLOC_TRIM_THRESHOLD_="65536")
    assert sv.socket_path(same) == sv.socket_path(env)


def test_a_server_whose_module_path_changed_exits_instead_of_forking(runtime, tmp_path,
                                                                     monkeypatch):
    """An install or upgrade changes a directory of the module path: the server (which
    still has the old modules loaded) then exits at the next request instead of forking."""
    extra = tmp_path / "site"
    extra.mkdir()
    monkeypatch.syspath_prepend(str(extra))
    sv._KEYS.clear()
    info = sv.start(idle_minutes=5)
    try:
        env = wk._worker_env(1)
        r, w = os.pipe()
        try:
            got = sv.fork_worker(env, r, w, 2)
            assert got is not None
            got.kill()
            assert got.wait(10) == -signal.SIGKILL
            (extra / "new_package.py").write_text("")
            time.sleep(1.2)  # the server checks at most once a second
            with pytest.raises(sv.ServerError, match="did not answer"):
                sv.fork_worker(env, r, w, 2)
        finally:
            os.close(r)
            os.close(w)
        assert _wait_gone(info["pid"], 10)
        (o,) = wk.run_jobs([wk.Job("a", _spec("a"))], threads=1)  # a worker of its own
        assert o.kind == "done"
    finally:
        sv.stop()
        sv._KEYS.clear()


def test_a_server_exits_when_idle_and_when_stopped(runtime):
    info = sv.start(idle_minutes=1 / 60)  # one second
    sock = Path(info["socket"])
    assert sock.exists()
    assert _wait_gone(info["pid"], 15)
    assert not sock.exists()
    info = sv.start(idle_minutes=5)
    assert sv.stop()
    assert _wait_gone(info["pid"], 10)
    assert not sock.exists()
    assert sv.status() is None and not sv.stop()


def test_the_workers_command(runtime):
    def optkin(*args):
        return subprocess.run([sys.executable, "-m", "optkin", *args], capture_output=True,
                              text=True, timeout=120, env=dict(os.environ))

    r = optkin("workers", "status")
    assert r.returncode == 1 and "none running" in r.stdout
    r = optkin("workers", "start", "--idle", "5")
    assert r.returncode == 0 and "started (pid" in r.stdout, r.stdout + r.stderr
    r = optkin("workers", "start")
    assert r.returncode == 0 and "already running" in r.stdout
    r = optkin("workers", "status")
    assert r.returncode == 0 and "running (pid" in r.stdout
    r = optkin("workers", "stop")
    assert r.returncode == 0 and "stopped" in r.stdout
    # a server of another environment (other import-time variables), and --all
    other = dict(os.environ, OPTKIN_SOMETHING="1")
    r = subprocess.run([sys.executable, "-m", "optkin", "workers", "start"],
                       capture_output=True, text=True, timeout=120, env=other)
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.split("(pid ")[1].split(",")[0])
    r = optkin("workers", "stop")
    assert r.returncode == 0 and "none running" in r.stdout  # not this environment's
    assert _alive(pid)
    r = optkin("workers", "stop", "--all")
    assert r.returncode == 0 and "stopped 1 server(s)" in r.stdout
    assert _wait_gone(pid, 10) and not list((runtime / "optkin").glob("*.sock"))
    r = optkin("workers", "start", "--idle", "-1")
    assert r.returncode == 2 and "--idle must be in" in r.stderr


def test_the_console_script_and_python_m_find_the_same_server(runtime):
    """``optkin`` (its module path starts with the scripts folder) and ``python -m optkin``
    (which does not) share one server."""
    script = Path(sys.executable).with_name("optkin")
    if not script.exists():
        pytest.skip("the optkin console script is not installed next to this Python")
    r = subprocess.run([sys.executable, "-m", "optkin", "workers", "start", "--idle", "5"],
                       capture_output=True, text=True, timeout=120, env=dict(os.environ))
    assert r.returncode == 0 and "started (pid" in r.stdout, r.stdout + r.stderr
    pid = int(r.stdout.split("(pid ")[1].split(",")[0])
    r = subprocess.run([str(script), "workers", "status"], capture_output=True, text=True,
                       timeout=120, env=dict(os.environ))
    assert r.returncode == 0 and f"running (pid {pid}" in r.stdout, r.stdout + r.stderr
    r = subprocess.run([str(script), "workers", "stop"], capture_output=True, text=True,
                       timeout=120, env=dict(os.environ))
    assert r.returncode == 0 and "stopped" in r.stdout
    assert _wait_gone(pid, 10)


def _maps(pid: int) -> str:
    return Path(f"/proc/{pid}/maps").read_text()


def _children(pid: int) -> list[int]:
    kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    return [int(k) for k in kids]


def _served_by_a_new_server(old: int, limit: float = 60.0) -> dict:
    end = time.monotonic() + limit
    while time.monotonic() < end:
        info = sv.status()
        if info is not None and info["pid"] != old:
            return info
        time.sleep(0.05)
    raise AssertionError("no warmed server took over")


def test_after_a_run_the_server_warms_up_with_its_work_and_forks_warm_workers(server):
    """The run tells the server what it did; a copy of the server runs one unit of each
    kind once and takes over. Evidence in the processes themselves: the plain server has
    no drawing code loaded; after a run that drew pictures, the new server and the worker
    it forks have matplotlib's font renderer mapped before they run anything."""
    assert "ft2font" not in _maps(server["pid"])
    spec = dict(_spec("a.toml"), pictures=True)
    (o,) = wk.run_jobs([wk.Job("a", spec, group="four_bar", kinds=("forward",))], threads=1)
    assert o.kind == "done" and o.pictures  # it drew
    _drop_idle()
    info = _served_by_a_new_server(server["pid"])
    assert info["warmed"] == ["four_bar|forward|True"]
    assert _wait_gone(server["pid"], 15)  # the old server handed over and ended
    assert "ft2font" in _maps(info["pid"])
    (o,) = wk.run_jobs([wk.Job("b", _spec("b.toml"))], threads=1)  # forked warm
    assert o.kind == "done"
    with wk._IDLE_LOCK:
        (w,) = [w for pool in wk._IDLE.values() for w in pool]
    assert isinstance(w.proc, sv.Forked) and _ppid(w.proc.pid) == info["pid"]
    assert "ft2font" in _maps(w.proc.pid)
    sv.stop()
    assert _wait_gone(info["pid"], 10)


def test_a_warm_up_that_dies_leaves_the_server_serving(server):
    spec = dict(_spec("a.toml"), pictures=True)
    (o,) = wk.run_jobs([wk.Job("a", spec, group="four_bar", kinds=("forward",))], threads=1)
    _drop_idle()
    end = time.monotonic() + 30
    warmer = []
    while not warmer and time.monotonic() < end:  # the server's child that is no worker
        warmer = [p for p in _children(server["pid"]) if p != o.result["worker"]["pid"]]
    assert warmer, "no warm-up started"
    os.kill(warmer[0], signal.SIGKILL)
    time.sleep(1.5)
    info = sv.status()
    assert info["pid"] == server["pid"] and info["warmed"] == [] and not info["warming"]
    (o,) = wk.run_jobs([wk.Job("b", _spec("b.toml"))], threads=1)
    assert o.kind == "done"
    assert sv.status()["forked"] == 2  # still forking, from the plain server


_LEAVES_THREAD = r"""
import os, sys
from optkin.problems.runner import worker_job
f = sys.argv[1]
n = len(os.listdir("/proc/self/task"))
worker_job("w", {"display": "s", "data": open(f, "rb").read(), "source": f,
                 "pictures": False}, lambda m: None)
print(len(os.listdir("/proc/self/task")) - n)
"""


def test_a_unit_that_leaves_a_thread_running_is_not_warmed_and_the_rest_is(server):
    """Forking a process with other threads is unsafe (the child has only the forking
    thread; a pool waiting on the others would hang). A unit whose solver leaves a thread
    behind (here cvxpy's, on the statics of a 3-RPR) is named by the warm-up, which
    starts again without it."""
    statics = PROBLEMS / "statics_rpr3.toml"
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    left = subprocess.run([sys.executable, "-c", _LEAVES_THREAD, str(statics)], env=env,
                          capture_output=True, text=True, timeout=300)
    if left.stdout.strip() in ("", "0"):
        pytest.skip("this installation's statics solver leaves no thread behind")
    jobs = [wk.Job("s", _spec("s", "statics_rpr3.toml"), group="rpr3", kinds=("statics",)),
            wk.Job("a", _spec("a"), group="four_bar", kinds=("forward",))]
    assert [o.kind for o in wk.run_jobs(jobs, threads=1)] == ["done", "done"]
    _drop_idle()
    info = _served_by_a_new_server(server["pid"], limit=120)
    assert info["warmed"] == ["four_bar|forward|False"]
    log = Path(info["socket"]).with_suffix(".log").read_text()
    assert "rpr3|statics|False: leaves 1 thread(s) running; not warmed" in log
    assert _threads(info["pid"]) == 1
    (o,) = wk.run_jobs([wk.Job("b", _spec("b"))], threads=1)
    assert o.kind == "done"


def _threads(pid: int) -> int:
    return len(os.listdir(f"/proc/{pid}/task"))


def test_a_server_that_does_not_answer_costs_a_run_seconds_not_its_workers(server):
    """A stopped (or wedged) server: the run's request times out and it starts a worker
    of its own, on new pipes, since the server may still fork one on the ends it was sent
    (here it does, once continued: that worker finds its run's end closed and exits)."""
    os.kill(server["pid"], signal.SIGSTOP)
    try:
        t0 = time.monotonic()
        (o,) = wk.run_jobs([wk.Job("a", _spec("a"))], threads=1)
        assert o.kind == "done" and time.monotonic() - t0 < 30
        with wk._IDLE_LOCK:
            (w,) = [w for pool in wk._IDLE.values() for w in pool]
        assert not isinstance(w.proc, sv.Forked)
    finally:
        os.kill(server["pid"], signal.SIGCONT)
    time.sleep(1.0)  # it forks on the stale ends now
    assert sv.status()["forked"] <= 1
    (o,) = wk.run_jobs([wk.Job("b", _spec("b"))], threads=1)  # the own worker, still right
    assert o.kind == "done" and o.result["worker"]["pid"] == w.proc.pid
    end = time.monotonic() + 10
    while [c for c in _children(server["pid"]) if _alive(c)] and time.monotonic() < end:
        time.sleep(0.05)
    assert [c for c in _children(server["pid"]) if _alive(c)] == []


# ---------------------------------------------------------------------------------------
# the Dask driver: `optkin run --scheduler` with its client in a process the server forks
# ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def cluster():
    """A Dask worker in a process of its own (one in this process would put its directory
    on this process's module path: another environment, which no server serves)."""
    distributed = pytest.importorskip("distributed")
    env, path = dict(os.environ), list(sys.path)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=50) as c:
        # starting one leaves PYTHONHASHSEED, thread counts and a malloc variable here, and
        # its scheduler's scratch folders on the module path (whose modification times
        # change as Dask works in them: a key no server would keep)
        os.environ.clear()
        os.environ.update(env)
        sys.path[:] = path
        yield c


def _outputs(out: Path) -> dict[str, str]:
    return {p.name: json.dumps(_numbers([t["output"] for t in json.loads(p.read_text())["tasks"]]))
            for p in sorted(out.glob("*.json")) if p.name != "summary.json"}


def test_a_dask_run_drives_its_client_from_a_forked_process(server, cluster, tmp_path):
    """With a server, ``--scheduler`` sends its tasks through a driver the server forks
    and gets what a run without Dask gets; the server then imports ``distributed``, and the
    next driver starts with it loaded (its own account: ``preloaded``)."""
    from optkin.cli import main
    from optkin.problems import dask_client

    src = tmp_path / "problems"
    src.mkdir()
    for f in ("four_bar.toml", "rpr3.toml", "five_bar.toml"):
        shutil.copy(PROBLEMS / f, src / f)
    assert main(["run", str(src), "--out", str(tmp_path / "serial"), "--no-pictures",
                 "--jobs", "1", "-q"]) == 0
    assert main(["run", str(src), "--out", str(tmp_path / "dask"), "--no-pictures", "-q",
                 "--scheduler", cluster.scheduler_address]) == 0
    assert _outputs(tmp_path / "dask") == _outputs(tmp_path / "serial")
    assert len(_outputs(tmp_path / "dask")) == 3
    info = _served_by_a_new_server(server["pid"])
    end = time.monotonic() + 60  # (a unit's warm-up may take over first)
    while sv.DASK_LABEL not in info["warmed"] and time.monotonic() < end:
        time.sleep(0.1)
        info = sv.status() or info
    assert sv.DASK_LABEL in info["warmed"], info
    session = dask_client.connect(cluster.scheduler_address)
    try:
        assert session.info["driver"] and session.info["preloaded"], session.info
        assert _ppid(session.info["pid"]) == sv.status()["pid"]
        assert session.slots == 1
        got = []
        session.run([("optkin-test-0", 1, [_spec("a", "rpr3.toml")])], 60.0,
                    lambda i, rs, why: got.append((i, rs, why)))
        ((i, (r,), why),) = got
        assert i == 0 and why is None and r["kind"] == "done"
        assert json.dumps(_numbers([t["output"] for t in r["result"]["tasks"]])) == \
            _outputs(tmp_path / "serial")["rpr3.json"]
    finally:
        session.close()
    # without a server the client runs here, as before
    os.environ[sv.ENV_DISABLE] = "0"
    try:
        session = dask_client.connect(cluster.scheduler_address)
        assert not session.info["driver"]
        session.close()
    finally:
        del os.environ[sv.ENV_DISABLE]


def test_a_dask_driver_that_dies_fails_the_tasks_left_and_one_left_alone_exits(server,
                                                                              cluster):
    from optkin.problems import dask_client

    session = dask_client.connect(cluster.scheduler_address)
    assert session.info["driver"]
    session.proc.kill()
    got = []
    t0 = time.monotonic()
    session.run([("optkin-test-1", 2, [_spec("a")]), ("optkin-test-2", 1, [_spec("b")])],
                60.0, lambda i, rs, why: got.append((i, rs, why)))
    session.close()
    assert time.monotonic() - t0 < 10
    assert [(i, rs) for i, rs, _ in got] == [(0, None), (1, None)]
    assert all("Dask driver process ended" in why for _, _, why in got), got
    # a run that ends (or dies) closes its pipes: the driver waiting for tasks exits
    session = dask_client.connect(cluster.scheduler_address)
    pid = session.info["pid"]
    assert _alive(pid)
    for fd in (session.wfd, session.rfd):
        os.close(fd)
    assert _wait_gone(pid, 5)
    session.wfd = session.rfd = -1
    session.close()


def test_a_scheduler_that_is_not_dask_is_a_user_error_through_the_driver(server, monkeypatch):
    import socket

    from optkin.errors import ProblemFileError
    from optkin.problems import dask_client

    monkeypatch.setattr(dask_client, "DASK_CONNECT_TIMEOUT", 2.0)
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)  # accepts (the kernel does), never answers
    forked = sv.status()["forked"]
    try:
        t0 = time.monotonic()
        with pytest.raises(ProblemFileError, match="--scheduler: cannot connect"):
            dask_client.connect(f"tcp://127.0.0.1:{srv.getsockname()[1]}")
        assert time.monotonic() - t0 < 2.0 + 5.0 + 3.0
    finally:
        srv.close()
    assert sv.status()["forked"] == forked + 1  # the driver said so


def test_a_driver_that_dies_before_it_connects_leaves_the_run_its_own_client(cluster,
                                                                             monkeypatch):
    """A driver gone before its first answer (a server stopping) costs nothing but the
    fork: the run connects from its own process instead."""
    from optkin.problems import dask_client

    def dead(address, timeout):
        r, w = os.pipe()
        os.close(w)  # what the run reads from it: end of file at once
        r2, w2 = os.pipe()
        os.close(r2)
        proc = subprocess.Popen([sys.executable, "-c", "pass"])
        proc.wait()
        return dask_client._Driver(proc, r, w2, tempfile.TemporaryFile(), address, timeout)

    monkeypatch.setattr(dask_client, "_fork_driver", dead)
    session = dask_client.connect(cluster.scheduler_address)
    try:
        assert not session.info["driver"] and session.slots == 1
        got = []
        session.run([("optkin-test-3", 1, [_spec("a")])], 60.0,
                    lambda i, rs, why: got.append((i, rs, why)))
        ((i, (r,), why),) = got
        assert i == 0 and why is None and r["kind"] == "done", r
    finally:
        session.close()
