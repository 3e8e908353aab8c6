"""The connection of ``optkin run --scheduler`` to a Dask scheduler.

:func:`preconnect` starts connecting in a background thread as soon as the command line
knows the address, before it imports the runner and reads the problem files; once
connected it registers :class:`optkin.problems.dask_worker.PrestartWorkers`, so the Dask
workers start their optkin worker processes meanwhile. :func:`connect` waits for that
connection, never longer than the connect timeout: a service that is not a Dask scheduler
(one that sends a banner, or keeps the connection open without answering) can neither hang
the run nor escape as a raw exception. Standard library only until connecting.
"""

from __future__ import annotations

import threading
from typing import Any

from optkin.errors import ProblemFileError

__all__ = ["DASK_CONNECT_TIMEOUT", "connect", "preconnect"]

#: Seconds allowed to reach a Dask scheduler and exchange the first messages.
DASK_CONNECT_TIMEOUT = 10.0

_PENDING: dict[str, tuple[threading.Thread, dict[str, Any], float]] = {}
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


def preconnect(address: str) -> None:
    """Start connecting to the scheduler at ``address`` in the background."""
    with _LOCK:
        if address in _PENDING:
            return
        box: dict[str, Any] = {}
        timeout = float(DASK_CONNECT_TIMEOUT)
        t = threading.Thread(target=_connect, args=(address, box, timeout), daemon=True,
                             name="optkin-dask-connect")
        _PENDING[address] = (t, box, timeout)
        t.start()


def connect(address: str) -> Any:
    """A ``distributed.Client`` of ``address``, or a ProblemFileError within the timeout."""
    preconnect(address)
    with _LOCK:
        t, box, timeout = _PENDING.pop(address)
    t.join(timeout + 5.0)
    if box.get("missing"):
        raise ProblemFileError(
            "--scheduler: dask.distributed is not installed; pip install 'optkin[dask]'")
    if "client" in box:
        return box["client"]
    if t.is_alive():
        why = f"no Dask scheduler answered within {timeout + 5.0:g} s"
    else:
        e = box.get("error")
        why = (f"{type(e).__name__}: {str(e)[:200]}" if not isinstance(e, MemoryError)
               else "the service there does not speak the Dask protocol")
    raise ProblemFileError(f"--scheduler: cannot connect to {address!r}: {why}; give the "
                           "address of a Dask scheduler (e.g. tcp://host:8786)")
