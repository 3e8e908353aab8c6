"""The memory and time budgets of optkin's public entry points.

Every size a caller chooses (``grid``, ``starts``, ``width``, ``max_steps``, path lengths,
grid values of maps, ...) is checked *before anything is allocated* against a memory
budget, with a :class:`~optkin.errors.MechanismError` that names the option and the
largest value allowed under the current budget. The cost of one unit of each option
(bytes per grid cell, per start, per path point, ...) was measured (peak resident memory,
``VmHWM``, of a fresh process; the figures are in the docstring of each function) and is
used here with a safety margin, so that a call with the largest accepted value stays
within the budget.

Budgets
-------
MEMORY_BUDGET : int
    Bytes one call may allocate for its sizes: 1 GiB by default. The environment variable
    ``OPTKIN_MEMORY_BUDGET`` overrides it (read at every call): a number of bytes, or a
    number with a unit, ``512M``, ``2GiB``, ``64MiB``, ``1e9``.
TIME_BUDGET : float
    Seconds a call without a ``time_limit`` option of its own may spend in its loops
    (continuation, path tracking, batch fallbacks, map sampling): 600 s by default,
    ``OPTKIN_TIME_BUDGET`` overrides it. When it runs out the call returns what it has with
    ``success=False`` and status ``"time_limit"`` (:data:`optkin.results.TIME_LIMIT`;
    ``"memory_limit"`` when tracing stops at the memory budget); the ``time_limit`` option of
    :func:`optkin.assembly_modes` defaults to at most the budget and may not exceed it.
    A single native call (one mapped CasADi evaluation, one IPOPT solve) is not
    interrupted, but its size is bounded by the memory budget.

Counts that do not allocate but multiply the work (iterations, unrolled Newton steps,
threads) have fixed upper bounds, :data:`MAX_ITERATIONS`, :data:`MAX_UNROLL` and
:data:`MAX_THREADS`.
"""

from __future__ import annotations

import math
import os
import re
import reprlib
import time
from collections.abc import Callable
from typing import Any

from ._checks import as_int
from .errors import MechanismError

__all__ = [
    "MEMORY_BUDGET",
    "TIME_BUDGET",
    "MAX_ITERATIONS",
    "MAX_UNROLL",
    "MAX_THREADS",
    "SAFETY",
    "memory_budget",
    "time_budget",
    "check_size",
    "check_sizes",
    "largest_size",
    "floor_pow2",
    "auto_threads",
    "show",
    "Deadline",
]

#: Default memory budget of one call, in bytes (``OPTKIN_MEMORY_BUDGET`` overrides it).
MEMORY_BUDGET: int = 1 << 30
#: Default time budget of one call, in seconds (``OPTKIN_TIME_BUDGET`` overrides it).
TIME_BUDGET: float = 600.0
#: Largest iteration count of any option (Newton iterations per start or point, rescues).
MAX_ITERATIONS: int = 100_000
#: Largest number of Newton steps unrolled into one compiled Function (its size grows
#: linearly with it: ``forward_batch``'s ``iters``).
MAX_UNROLL: int = 32
#: Largest number of threads of a mapped CasADi Function.
MAX_THREADS: int = 64


def auto_threads() -> int:
    """Threads a call uses when told ``"auto"``: the CPUs this process may run on, or 1
    where ``OMP_NUM_THREADS`` says 1 (as in the batch runner's workers when several run,
    and on its Dask workers: they parallelize by process)."""
    if os.environ.get("OMP_NUM_THREADS", "").strip() == "1":
        return 1
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    return max(1, min(n, MAX_THREADS))


#: Safety factor applied to every measured cost per unit (allocator slack, temporaries
#: that differ between platforms and library versions).
SAFETY: float = 1.5

_UNITS = {"": 1, "b": 1, "k": 1000, "kb": 1000, "kib": 1024, "m": 1000**2, "mb": 1000**2,
          "mib": 1024**2, "g": 1000**3, "gb": 1000**3, "gib": 1024**3, "t": 1000**4,
          "tb": 1000**4, "tib": 1024**4}
_SIZE_RE = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?)\s*([a-zA-Z]*)\s*$")
#: Smallest budget accepted from the environment (a smaller one refuses everything).
_MIN_BUDGET = 1 << 20


_REPR = reprlib.Repr()
_REPR.maxstring = _REPR.maxother = 40
_REPR.maxlist = _REPR.maxtuple = _REPR.maxset = _REPR.maxdict = 6
_REPR.maxlevel = 3


def show(v: Any, n: int = 60) -> str:
    """A short, safe repr of a user's value for a message: never raises, never builds a
    long string (an int beyond 4300 digits has no str(); a list of 10^8 items)."""
    if isinstance(v, int) and not isinstance(v, bool) and v.bit_length() > 80:
        return f"{'-' if v < 0 else ''}(an integer of {v.bit_length()} bits)"
    try:
        s = _REPR.repr(v)
    except Exception:  # noqa: BLE001 - any repr may fail (huge ints inside, broken objects)
        s = f"<{type(v).__name__}>"
    return s if len(s) <= n else s[: n - 3] + "..."


def _parse_bytes(text: str) -> int:
    m = _SIZE_RE.match(text)
    unit = m.group(2).lower() if m else None
    if m is None or unit not in _UNITS:
        raise MechanismError(
            f"OPTKIN_MEMORY_BUDGET: expected a number of bytes, optionally with a unit "
            f"(e.g. 536870912, 512MiB, 2G), got {text[:40]!r}")
    v = float(m.group(1)) * _UNITS[unit]
    if not (math.isfinite(v) and _MIN_BUDGET <= v <= 1 << 60):
        raise MechanismError(f"OPTKIN_MEMORY_BUDGET: {text[:40]!r} is out of range "
                             f"(between 1 MiB and 1 EiB)")
    return int(v)


def memory_budget() -> int:
    """The memory budget of one call in bytes: ``OPTKIN_MEMORY_BUDGET`` when set, else
    :data:`MEMORY_BUDGET`."""
    env = os.environ.get("OPTKIN_MEMORY_BUDGET")
    if env is not None and env.strip():
        return _parse_bytes(env)
    return int(MEMORY_BUDGET)


def time_budget() -> float:
    """The time budget of one call in seconds: ``OPTKIN_TIME_BUDGET`` when set, else
    :data:`TIME_BUDGET`."""
    env = os.environ.get("OPTKIN_TIME_BUDGET")
    if env is not None and env.strip():
        try:
            v = float(env)
        except ValueError:
            v = float("nan")
        if not (math.isfinite(v) and v > 0):
            raise MechanismError(f"OPTKIN_TIME_BUDGET: expected a number of seconds > 0, "
                                 f"got {env[:40]!r}")
        return v
    return float(TIME_BUDGET)


def _fmt_bytes(n: float) -> str:
    for unit, k in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= k:
            return f"{n / k:.3g} {unit}"
    return f"{n:.0f} bytes"


def largest_size(bytes_per_unit: float, *, fixed: float = 0.0, power: int = 1,
                 budget: int | None = None) -> int:
    """The largest v with ``fixed + SAFETY * bytes_per_unit * v**power <= budget``."""
    budget = memory_budget() if budget is None else budget
    room = budget - fixed
    unit = SAFETY * float(bytes_per_unit)
    if room <= 0 or unit <= 0:
        return 0 if room <= 0 else 1 << 62
    v = int((room / unit) ** (1.0 / power))
    while v > 0 and fixed + unit * float(v) ** power > budget:
        v -= 1
    while fixed + unit * float(v + 1) ** power <= budget:
        v += 1
    return v


def check_size(where: str, option: str, value: Any, bytes_per_unit: float, *,
               fixed: float = 0.0, power: int = 1, lo: int = 1, hi: int | None = None,
               unit: str = "", fit: Callable[[int], int] | None = None) -> int:
    """``value`` as an int, checked before anything of that size is allocated.

    The call will allocate about ``fixed + bytes_per_unit * value**power`` bytes for this
    option (``bytes_per_unit`` as measured, :data:`SAFETY` applied here; ``fixed``: bytes
    already committed by other options of the call, safety included). Raises a
    :class:`MechanismError` naming ``where`` and ``option`` when ``value`` is not an
    integer >= ``lo``, is above ``hi`` (a fixed maximum, when given), or when the cost
    exceeds the memory budget; the message gives the largest allowed value under the
    current budget (rounded down by ``fit`` when only some values are valid, e.g. powers
    of 2). ``unit`` says in a few words what one unit is.

    >>> check_size("workspace", "grid", 64, 300.0, power=2)
    64
    >>> check_size("workspace", "grid", 10**6, 300.0, power=2)  # the default budget, 1 GiB
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: workspace: option grid = 1000000 needs about 4.19e+05 GiB (grid^2 x 450 bytes), above the memory budget of 1 GiB (OPTKIN_MEMORY_BUDGET); the largest allowed grid is 1544
    """
    v = as_int(value, f"{where}: option {option}", lo=lo)
    budget = memory_budget()
    per = SAFETY * float(bytes_per_unit)
    need = fixed + per * float(v) ** power
    if need > budget or (hi is not None and v > hi):
        best = largest_size(bytes_per_unit, fixed=fixed, power=power, budget=budget)
        if hi is not None:
            best = min(best, hi)
        if fit is not None and best >= lo:
            best = fit(best)
        shape = f"{option}^{power}" if power != 1 else option
        if need > budget:
            why = (f"needs about {_fmt_bytes(need)} ({shape} x {_fmt_bytes(per)}"
                   f"{', ' + unit if unit else ''}), above the memory budget of "
                   f"{_fmt_bytes(budget)} (OPTKIN_MEMORY_BUDGET)")
        else:
            why = f"is above the fixed maximum {hi}"
        if best < lo:
            tail = (f"; even {option} = {lo} does not fit: raise OPTKIN_MEMORY_BUDGET or "
                    "choose a smaller problem")
        else:
            tail = f"; the largest allowed {option} is {best}"
        raise MechanismError(f"{where}: option {option} = {show(v)} {why}{tail}")
    return v


def check_sizes(where: str, *items: tuple[str, Any, float, dict[str, Any]],
                fixed: float = 0.0) -> list[int]:
    """Several size options of one call that share the budget, as ``(option, value,
    bytes_per_unit, keywords of check_size)``: each is checked with the cost of the others
    (and ``fixed``) already committed, the costliest first, so that the message blames the
    option that takes the most and gives its largest value next to the others.
    Returns the values, as ints, in the order given."""
    vals, costs = [], []
    for option, value, per, kw in items:
        v = as_int(value, f"{where}: option {option}", lo=kw.get("lo", 1))
        vals.append(v)
        costs.append(SAFETY * float(per) * float(v) ** kw.get("power", 1))
    total = fixed + sum(costs)
    for i in sorted(range(len(items)), key=lambda k: -costs[k]):
        option, _, per, kw = items[i]
        check_size(where, option, vals[i], per, fixed=total - costs[i], **kw)
    return vals


def floor_pow2(v: int) -> int:
    """The largest power of 2 <= v (v >= 1)."""
    return 1 << (int(v).bit_length() - 1)


class Deadline:
    """A wall-clock bound for one call: ``expired()`` once ``seconds`` (default
    :func:`time_budget`) have passed since it was made."""

    __slots__ = ("seconds", "end")

    def __init__(self, seconds: float | None = None) -> None:
        self.seconds = time_budget() if seconds is None else float(seconds)
        self.end = time.monotonic() + self.seconds

    def expired(self) -> bool:
        return time.monotonic() > self.end

    def left(self) -> float:
        return self.end - time.monotonic()

    def message(self, where: str) -> str:
        return (f"{where}: stopped at the time budget of {self.seconds:g} s "
                "(OPTKIN_TIME_BUDGET); the result is incomplete")
