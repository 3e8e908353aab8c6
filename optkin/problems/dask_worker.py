"""What runs on a Dask worker for ``optkin run --scheduler``: the task and a worker plugin.

:func:`run_units` runs units of work (problems, or some of their tasks; consecutive
cheap units share a Dask task, :func:`optkin.problems.runner._dask_batches`) in an optkin
worker process of the Dask worker, under the same time limits as the local pool
(:func:`optkin.problems.workers.run_jobs`); the worker process stays for the next task,
one per Dask thread. :class:`PrestartWorkers`, registered by the runner when it connects,
starts those processes as soon as a Dask worker has the plugin, so that their start-up
(importing optkin, numpy, CasADi and pydantic, about 0.5 s) overlaps the transfer of the
first tasks, and they stay for later runs on the same cluster.

This module imports only the standard library, :mod:`distributed` and
:mod:`optkin.problems.workers` (itself standard library only): the Dask worker process
itself never imports numpy, CasADi or pydantic for optkin's sake.
"""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from optkin.problems.workers import Job, prestart, run_jobs

__all__ = ["PrestartWorkers", "run_unit", "run_units"]


def _threads(worker: Any = None) -> int:
    """Threads of a Dask worker (this one by default; 1 outside a Dask worker)."""
    try:
        if worker is None:
            from distributed import get_worker

            worker = get_worker()
        return max(1, int(worker.state.nthreads))
    except Exception:  # noqa: BLE001 - not on a Dask worker, or an older distributed
        return 1


def run_units(specs: list[dict[str, Any]], time_limit: float) -> list[dict[str, Any]]:
    """Dask task: run units one after the other in an optkin worker process of this Dask
    worker; their outcomes in the order given (each unit under its own time limits: one
    that overruns or kills its worker process fails alone, the next goes on in a fresh
    process)."""
    jobs = [Job(f"{i}:{spec['display']}", spec) for i, spec in enumerate(specs)]
    got: dict[str, Any] = {}
    run_jobs(jobs, n_workers=1, time_limit=time_limit, threads=1, keep=_threads(),
             on_outcome=lambda o: got.__setitem__(o.key, o))
    return [{"kind": got[j.key].kind, "result": got[j.key].result,
             "pictures": got[j.key].pictures, "message": got[j.key].message} for j in jobs]


def run_unit(spec: dict[str, Any], time_limit: float) -> dict[str, Any]:
    """Dask task: run one unit in an optkin worker process of this Dask worker (the runner
    submits :func:`run_units`; this stays for clients of earlier versions)."""
    return run_units([spec], time_limit)[0]


#: Interval (ms) of a Dask worker's event-loop health check once optkin's plugin or
#: preload is on it (Dask's default: 20 ms). The check warns when the loop was blocked
#: longer than ``distributed.admin.tick.limit`` (3 s by default), which a 500 ms tick
#: still sees; ticking 50 times a second cost each idle Dask worker 1.2-1.4 % of a core
#: here (2.1-2.3 % in all, 0.8-0.9 % with the tick at 500 ms), taken on a small machine
#: from the optkin worker processes doing the work.
TICK_MS = 500.0


def _quiet(worker: Any) -> None:
    """Stop the Dask worker's statistical profiler and slow its event-loop tick
    (:data:`TICK_MS`): optkin's work runs in a worker process of its own, so the profiler
    only samples a thread waiting on a pipe, at about 1.3 % of a core per worker measured
    here (an idle LocalCluster of two: 11 % -> 10 %), and nothing of optkin's blocks the
    loop that the tick watches."""
    try:
        for name in ("profile", "profile-cycle"):
            pc = worker.periodic_callbacks.pop(name, None)
            if pc is not None:
                pc.stop()
        tick = worker.periodic_callbacks.get("tick")
        if tick is not None and getattr(tick, "callback_time", TICK_MS) < TICK_MS:
            tick.stop()
            tick.callback_time = TICK_MS
            worker._tick_interval = TICK_MS / 1000  # what Dask reads it as
            tick.start()
    except Exception:  # noqa: BLE001 - another distributed version: leave it running
        pass


class PrestartWorkers(WorkerPlugin):
    """Start one optkin worker process per thread of each Dask worker, in the background."""

    name = "optkin-prestart-workers"

    def setup(self, worker: Any) -> None:
        _quiet(worker)
        prestart(_threads(worker), threads=1)


def dask_setup(worker: Any) -> None:
    """Dask preload hook: ``dask worker --preload optkin.problems.dask_worker`` (or
    ``LocalCluster(..., preload=["optkin.problems.dask_worker"])``) starts the optkin
    worker processes with the Dask worker, before any run connects."""
    _quiet(worker)
    prestart(_threads(worker), threads=1)
