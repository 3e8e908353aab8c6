"""Worker start-up: workers started ahead of a run are the ones it uses, the worker machinery
imports no heavy module, and a worker does not inherit Dask's malloc setting."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from optkin.problems import workers as wk

PROBLEMS = Path(__file__).resolve().parents[1] / "problems"


def _spec(name: str) -> dict:
    path = PROBLEMS / "four_bar.toml"
    return {"display": name, "data": path.read_bytes(), "source": str(path), "pictures": False}


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
        with wk._IDLE_LOCK:
            idle = wk._IDLE.pop(key, [])
        for w in idle:
            w.close()


def test_workers_do_not_inherit_dasks_malloc_trim(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "65536")
    for threads in (None, 1):
        env = wk._worker_env(threads)
        assert "MALLOC_TRIM_THRESHOLD_" not in env


@pytest.mark.parametrize("module, heavy", [
    ("optkin.problems.workers", ("numpy", "casadi", "pydantic", "scipy")),
    ("optkin.problems.dask_worker", ("casadi", "pydantic", "scipy")),  # numpy: distributed's
    ("optkin.cli", ("numpy", "casadi", "pydantic", "scipy")),
])
def test_worker_machinery_imports_no_heavy_module(module, heavy):
    code = (f"import sys, {module}; print(sorted(m for m in {heavy!r} if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == "[]", out


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
        with wk._IDLE_LOCK:
            idle = wk._IDLE.pop(key, [])
        for w in idle:
            w.close()


def test_dask_preload_hook_starts_one_worker_per_thread(monkeypatch):
    from types import SimpleNamespace

    from optkin.problems import dask_worker

    calls = []
    monkeypatch.setattr(dask_worker, "prestart", lambda n, threads=None: calls.append((n, threads)))
    dask_worker.dask_setup(SimpleNamespace(state=SimpleNamespace(nthreads=3)))
    dask_worker.PrestartWorkers().setup(SimpleNamespace(state=SimpleNamespace(nthreads=2)))
    assert calls == [(3, 1), (2, 1)]
