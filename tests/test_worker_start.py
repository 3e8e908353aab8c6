"""Worker start-up: workers started ahead of a run are the ones it uses, the worker machinery
imports no heavy module, and a worker does not inherit Dask's malloc setting."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from optkin.problems import workers as wk

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def _spec(name: str) -> dict:
    path = PROBLEMS / "four_bar.toml"
    return {"display": name, "data": path.read_bytes(), "source": str(path), "pictures": False}


def _close_idle(key: tuple) -> None:
    """Close the idle workers a test left for its own environment."""
    with wk._IDLE_LOCK:
        idle = wk._IDLE.pop(key, [])
    for w in idle:
        w.close()


def test_a_run_takes_the_prestarted_worker_even_while_it_starts(monkeypatch):
    threads = 3  # an environment (OMP_NUM_THREADS=3) no other test uses
    key = wk._env_key(wk._worker_env(threads))
    made = []
    init = wk._Worker.__init__

    def counting(self, *a, **k):
        made.append(1)
        init(self, *a, **k)

    monkeypatch.setattr(wk._Worker, "__init__", counting)
    try:
        assert wk.prestart(1, threads=threads) == 1
        assert wk.prestart(1, threads=threads) == 0  # one is starting already
        # at once, while it still starts: the run waits for it instead of starting another
        first = wk.run_jobs([wk.Job("a", _spec("a"))], n_workers=1, threads=threads)
        second = wk.run_jobs([wk.Job("b", _spec("b"))], n_workers=1, threads=threads)
        assert [o.kind for o in first + second] == ["done", "done"]
        pids = {o.result["worker"]["pid"] for o in first + second}
        assert len(made) == 1 and len(pids) == 1
        assert [w.proc.pid for w in wk._IDLE[key]] == list(pids)
    finally:
        _close_idle(key)


def test_a_ready_worker_starts_its_unit_before_the_next_worker_is_up(monkeypatch):
    """With several workers, the first that is up takes the longest unit at once: the
    run does not wait until the last of its workers has booted (the checkout of the
    second worker is held here until a unit has started, or 20 s)."""
    import threading

    threads = 5  # an environment no other test uses
    key = wk._env_key(wk._worker_env(threads))
    started = threading.Event()
    waited: list[bool] = []
    real = wk._checkout

    def checkout(env, events):
        if wk._IDLE.get(key):  # the prestarted, ready worker
            return real(env, events)
        waited.append(started.wait(timeout=20))  # a worker still to boot
        return real(env, events)

    monkeypatch.setattr(wk, "_checkout", checkout)
    try:
        assert wk.prestart(1, threads=threads) == 1
        with wk._BOOTED:
            assert wk._BOOTED.wait_for(lambda: not wk._BOOTING.get(key), 60)
        out = wk.run_jobs([wk.Job(n, _spec(n)) for n in "ab"], n_workers=2,
                          threads=threads, on_start=lambda job: started.set())
        assert sorted(o.kind for o in out) == ["done", "done"]
        assert waited == [True]
    finally:
        _close_idle(key)


def test_an_idle_worker_that_exits_as_it_is_checked_out_is_replaced(monkeypatch):
    """An idle worker that ends between the checkout's liveness check and the unit sent to
    it: its reader has already reported the end, to the queue of the run it idled after,
    and the send fails. The run replaces it at once and finishes (it waited forever
    before: no event was coming and no deadline was set)."""
    import threading

    threads = 7  # an environment no other test uses
    key = wk._env_key(wk._worker_env(threads))
    try:
        assert wk.prestart(1, threads=threads) == 1
        with wk._BOOTED:
            assert wk._BOOTED.wait_for(lambda: not wk._BOOTING.get(key), 60)
        (w,) = wk._IDLE[key]
        w.kill()  # ... and its reader reports the end to the prestart's own queue
        w.thread.join(10)
        assert not w.thread.is_alive()
        monkeypatch.setattr(w.proc, "poll", lambda: None)  # still alive, says the check
        box: dict = {}
        t = threading.Thread(target=lambda: box.update(out=wk.run_jobs(
            [wk.Job("a", _spec("a"))], n_workers=1, threads=threads)), daemon=True)
        t.start()
        t.join(60)
        assert not t.is_alive(), "the run hung on a worker that ended at its checkout"
        assert [o.kind for o in box["out"]] == ["done"]
        assert box["out"][0].result["worker"]["pid"] != w.proc.pid
    finally:
        _close_idle(key)


def test_workers_do_not_inherit_dasks_malloc_trim(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    for threads in (None, 1):
        env = wk._worker_env(threads)
        assert "MALLOC_TRIM_THRESHOLD_" not in env


@pytest.mark.parametrize("module, heavy", [
    ("optkin.problems.workers", ("numpy", "casadi", "pydantic", "scipy")),
    ("optkin.problems.dask_worker", ("casadi", "pydantic", "scipy")),  # numpy: distributed's
    ("optkin.cli", ("numpy", "casadi", "pydantic", "scipy")),
    ("optkin.problems.runner", ("numpy", "casadi", "pydantic", "scipy")),
])
def test_worker_machinery_imports_no_heavy_module(module, heavy):
    code = (f"import sys, {module}; print(sorted(m for m in {heavy!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", out


def test_a_whole_run_leaves_the_heavy_modules_to_the_workers(tmp_path):
    """The command line's process reads, schedules and writes two problems (one of them
    invalid, one split into units on two workers) without importing numpy, CasADi or
    pydantic: the workers validate and run them."""
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "ok.toml").write_bytes((PROBLEMS / "five_bar.toml").read_bytes())
    (tmp_path / "in" / "bad.toml").write_text("schema_version = 1\n[mechanism]\n")
    code = (
        "import sys, json\n"
        "from optkin.cli import main\n"
        f"rc = main(['run', {str(tmp_path / 'in')!r}, '--out', {str(tmp_path / 'out')!r},"
        " '--no-pictures', '-q', '--jobs', '2'])\n"
        "heavy = sorted(m for m in ('numpy', 'casadi', 'pydantic', 'scipy') if m in sys.modules)\n"
        "print(json.dumps([rc, heavy]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    rc, heavy = json.loads(out.stdout.strip().splitlines()[-1])
    assert heavy == [], heavy
    assert rc == 2  # the invalid file (status 2: invalid input)
    res = json.loads((tmp_path / "out" / "ok.json").read_text())
    assert res["complete"] and len(res["tasks"]) > 1
    assert all(t["status"] == "ok" for t in res["tasks"]), [t["message"] for t in res["tasks"]]
    summary = (tmp_path / "out" / "summary.csv").read_text()
    assert "bad" in summary and "mechanism" in summary


def test_a_stopped_idle_worker_is_replaced_within_the_ack_limit(monkeypatch):
    import os
    import signal
    import time

    threads = 5  # an environment of its own
    key = wk._env_key(wk._worker_env(threads))
    monkeypatch.setattr(wk, "_ACK_LIMIT", 2.0)
    try:
        first = wk.run_jobs([wk.Job("a", _spec("a"))], n_workers=1, threads=threads)
        pid = first[0].result["worker"]["pid"]
        os.kill(pid, signal.SIGSTOP)  # idle, alive, and deaf: a wedged process
        t0 = time.perf_counter()
        second = wk.run_jobs([wk.Job("b", _spec("b"))], n_workers=1, threads=threads)
        assert second[0].kind == "done"
        assert second[0].result["worker"]["pid"] != pid
        assert time.perf_counter() - t0 < 2.0 + wk._GRACE + 20.0
    finally:
        _close_idle(key)


def test_dask_preload_hook_starts_one_worker_per_thread(monkeypatch):
    from types import SimpleNamespace

    from optkin.problems import dask_worker

    calls = []
    monkeypatch.setattr(dask_worker, "prestart", lambda n, threads=None: calls.append((n, threads)))
    dask_worker.dask_setup(SimpleNamespace(state=SimpleNamespace(nthreads=3)))
    dask_worker.PrestartWorkers().setup(SimpleNamespace(state=SimpleNamespace(nthreads=2)))
    assert calls == [(3, 1), (2, 1)]


def _env_buffered() -> dict:
    return {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}


def test_fast_exit_runs_the_exit_handlers_and_flushes(tmp_path):
    """fast_exit skips only the interpreter's teardown: the status is kept, buffered output
    (a pipe: block-buffered) and what the exit handlers write arrive, in order."""
    flag = tmp_path / "handler_ran"
    code = ("import atexit, sys\n"
            "from optkin._exit import fast_exit\n"
            f"atexit.register(lambda: open({str(flag)!r}, 'w').write('yes'))\n"
            "atexit.register(lambda: print('from the handler'))\n"
            "print('before', end=' ')\n"
            "print('to stderr', file=sys.stderr, end='')\n"
            "fast_exit(3)\n"
            "print('never')\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       timeout=60, env=_env_buffered())
    assert r.returncode == 3
    assert r.stdout == "before from the handler\n" and r.stderr == "to stderr"
    assert flag.read_text() == "yes"


def test_the_console_script_keeps_its_exit_status_and_output(tmp_path):
    """``python -m optkin`` (the console script's function): argparse's exits, a run with
    nothing to do, a run that writes results; each with the status and output of
    :func:`optkin.cli.main`."""
    env = _env_buffered()

    def run(*args):
        return subprocess.run([sys.executable, "-m", "optkin", *args], capture_output=True,
                              text=True, timeout=300, env=env, cwd=tmp_path)

    r = run("--version")
    assert r.returncode == 0 and r.stdout.startswith("optkin ")
    r = run("run")  # no PATH: a usage error
    assert r.returncode == 2 and "required: PATH" in r.stderr
    r = run("run", str(tmp_path / "nothing_here"))
    assert r.returncode == 2 and "no such file or directory" in r.stderr
    r = run("run", str(PROBLEMS / "four_bar.toml"), "--out", "res", "--no-pictures", "-q")
    assert r.returncode == 0, r.stderr
    assert "1 problem(s): 1 run" in r.stdout
    assert (tmp_path / "res" / "four_bar.json").is_file()
    assert (tmp_path / "res" / "summary.csv").read_text().count("\n") >= 2


def test_workers_start_without_site_on_the_parents_path(monkeypatch, tmp_path):
    """Workers start with ``python -S`` and the parent's module path less the working
    directory (and '' / '.'), so a folder on the parent's path (as PYTHONPATH or a
    notebook's sys.path.append puts one) is on the worker's too."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", ["", ".", str(tmp_path), "/some/where", *sys.path])
    path = wk._boot_path()
    assert "" not in path and "." not in path and str(tmp_path) not in path
    assert path[0] == "/some/where"
    made = []
    popen = subprocess.Popen

    def spy(args, *a, **k):
        made.append(list(args))
        return popen(args, *a, **k)

    monkeypatch.setattr(subprocess, "Popen", spy)
    out = wk.run_jobs([wk.Job("a", _spec("a"))], n_workers=1, threads=5)
    assert [o.kind for o in out] == ["done"]
    if made:  # (none when an idle worker of this environment was left by another test)
        args = made[0]
        assert args[1] == "-S" and "/some/where" in args
        assert str(tmp_path) not in args[args.index("-c") + 2:]
