"""The start systems that ship with optkin, and how they are made.

A start system belongs to a topology and to the pattern of its structural geometry
entries (:func:`optkin.solvers.homotopy.structural`: entries equal to 0, +-pi/2 or +-pi
stay fixed). :data:`CATALOGUE` lists one representative mechanism per shipped topology
and pattern: the library's planar and spatial platforms with generic geometry (no
structural zeros), and the library constructors whose own geometry fixes the pattern
(five-bar, four-bar and the Khalil tables, the Delta). A user's mechanism of the same
topology and pattern uses the shipped file; any other builds its own by monodromy on the
first call (stored in the compiled-code cache).

Regenerate the files (``optkin/data/start/``) with::

    python -m optkin.solvers.shipped

Each is built by monodromy and checked by the trace test (:mod:`optkin.solvers.trace`),
also where the structure's bound already makes it complete; ``tests/test_trace.py``
re-verifies every shipped file with the trace test.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import numpy as np

__all__ = ["CATALOGUE", "TRACE_OPTIONS", "UNVERIFIED", "ship"]


def _generic_rpr3():
    from .. import mechanisms as M

    return M.rpr3([[0.1, 0.2], [10.3, -0.4], [4.1, 8.7]],
                  [[-1.1, -0.6], [1.3, -0.9], [0.2, 1.4]])


def _generic_rrr3():
    from .. import mechanisms as M

    return M.rrr3([[0.1, 0.2], [10.3, -0.4], [4.1, 8.7]],
                  [[-1.1, -0.6], [1.3, -0.9], [0.2, 1.4]], [4.2, 4.9, 4.4], [5.1, 4.7, 5.3])


def _generic_prr3():
    from .. import mechanisms as M

    d = np.array([[0.93, 0.37], [-0.28, 0.96], [-0.71, -0.7]])
    return M.prr3([[0.1, 0.2], [10.3, -0.4], [4.1, 8.7]],
                  d / np.linalg.norm(d, axis=1, keepdims=True),
                  [[-1.1, -0.6], [1.3, -0.9], [0.2, 1.4]], [3.1, 3.4, 2.9])


def _generic_stewart():
    from .. import mechanisms as M

    rng = np.random.default_rng(12)
    ang = np.sort(rng.uniform(0, 2 * np.pi, 6))
    A = np.c_[2 * np.cos(ang), 2 * np.sin(ang), rng.uniform(-0.1, 0.1, 6)]
    ang = np.sort(rng.uniform(0, 2 * np.pi, 6))
    B = np.c_[np.cos(ang), np.sin(ang), rng.uniform(-0.1, 0.1, 6)]
    return M.stewart_gough(A + 0.01, B + 0.01)


def _lib(name: str, *args) -> Callable:
    def make():
        from .. import mechanisms as M

        return M.LIBRARY[name](*args)

    return make


#: (name, builder, slow): the representative mechanism of each shipped start system;
#: ``slow`` ones take more than a few seconds to re-verify by the trace test.
CATALOGUE: list[tuple[str, Callable, bool]] = [
    ("rpr3", _generic_rpr3, False),
    ("rrr3", _generic_rrr3, False),
    ("prr3", _generic_prr3, False),
    ("five_bar", _lib("five_bar", 1.3, 0.8, 1.1, 0.9, 0.7), False),
    ("four_bar", _lib("four_bar", 1.0, 0.4, 1.2, 0.9), False),
    ("delta", _lib("delta"), False),
    ("rps3", _lib("rps3"), True),  # joint level: 16 solutions, trace test 10-20 s
    ("sr400", _lib("sr400"), True),  # 20 s: its 11 500-operation system compiles slowly
    ("akr3000", _lib("akr3000"), True),
    ("stewart_gough", _generic_stewart, True),
    ("hexa", _lib("hexa"), True),
    # Tsai's 3-UPU at joint level, the library's default geometry (its base radius 1 makes
    # one base coordinate structural): 672 solutions, 84 orbits of its legs' flips
    # (homotopy.symmetry), found by monodromy (seeds 0, 1 and 2 all stop there) and
    # verified by the trace test along the leg lengths, sliced by the pose (TRACE_OPTIONS:
    # residual 1.7e-10, 2 560 witnesses, 16 loops, 12 min here)
    ("upu3", _lib("upu3"), True),
]

#: The trace test's options (:func:`optkin.solvers.trace.trace_test`) per shipped start
#: system, where not the defaults: Tsai's 3-UPU's curve along the leg lengths, sliced by
#: the platform's pose (2 560 witnesses; along c with every invariant coordinate, 23 304
#: after 100 minutes, whose t-tracks then failed).
TRACE_OPTIONS: dict[str, dict[str, str]] = {
    "upu3": {"direction": "qa", "slice": "pose"},
}

#: Start systems shipped although the trace test has not verified them (it cannot yet in
#: reasonable time), with why: :func:`ship` builds them with a long ``stale`` and stores
#: them with ``stopped="stale"``, so that a call accounts for every path but never says
#: ``complete`` (the message says the start system is not verified). None at present:
#: Tsai's 3-UPU was, until the trace test summed only the coordinates its slice reads.
UNVERIFIED: dict[str, str] = {}
#: Loops in a row without a new solution before an unverified start system is stored.
UNVERIFIED_STALE = 30


def ship(names: list[str] | None = None, out=sys.stdout) -> None:
    """Build, trace-test and write the start systems of ``names`` (default: all)."""
    from ..limits import Deadline
    from ..model import get_model
    from . import homotopy as H
    from .trace import trace_test

    H.SHIPPED.mkdir(parents=True, exist_ok=True)
    for name, make, slow in CATALOGUE:
        if names and name not in names:
            continue
        model = get_model(make())
        t0 = time.perf_counter()
        if name in UNVERIFIED:
            S = H.start_system(model, seed=0, stale=UNVERIFIED_STALE, max_loops=200,
                               verify=False, deadline=Deadline(3600.0))
            if S.stopped != "stale":
                print(f"{name}: not shipped, monodromy stopped by {S.stopped}", file=out)
                continue
            path = H.shipped_path(model)
            H.save_start(S, path)
            path.chmod(0o644)
            print(f"{name}: {S.root_count} solutions ({S.loops} loops, not verified), "
                  f"{time.perf_counter() - t0:.1f} s -> {path.name}", file=out)
            continue
        topts = TRACE_OPTIONS.get(name, {})
        limit = 3600.0 if slow else 600.0
        S = H.start_system(model, seed=0, deadline=Deadline(limit), trace_options=topts)
        if S.stopped not in ("bound", "trace"):
            print(f"{name}: not shipped, monodromy stopped by {S.stopped}", file=out)
            continue
        if not np.isfinite(S.trace):
            T = trace_test(model, S, deadline=Deadline(limit), **topts)
            if not T.passed:
                print(f"{name}: not shipped, {T.message}", file=out)
                continue
            S.trace = T.residual
        path = H.shipped_path(model)
        H.save_start(S, path)
        path.chmod(0o644)  # package data: readable by all (the cache's files are private)
        print(f"{name}: {S.root_count} solutions ({S.stopped}), trace residual "
              f"{S.trace:.1e}, {time.perf_counter() - t0:.1f} s -> {path.name}", file=out)


if __name__ == "__main__":
    ship(sys.argv[1:] or None)
