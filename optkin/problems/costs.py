"""A rough cost (seconds on one core) of each task of a problem file, for scheduling.

The batch runner splits problems into units of tasks and starts the longest first (the LPT
rule: with the costs known to within a factor, no worker idles long while another still
has much to do). The figures are medians measured on the bundled problems and the
benchmark batches (``benchmarks/test_scaling.py``), scaled by the sizes a task asks for;
they only need to order the work, not predict it.

:class:`Affinity` keeps each worker on the mechanisms it has already set up where that
costs the schedule nothing: the first problem of a topology in a worker builds its model
and loads (or waits for) its compiled code, about 0.1-0.4 s, which the next problems of
that topology do not pay again.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["task_costs", "topology_group", "Affinity", "BASE_COST", "PROBLEM_COST",
           "SETUP_COST"]

#: Seconds per task kind at its default sizes (assembly modes and aspects re-measured on
#: the scaling benchmark's batch on 2026-12-03, one thread, warm: a 3-RPR's homotopy
#: 3-6 ms, a 6-6 platform's 40 ms, a five-bar's aspects 0.45-0.70 s).
BASE_COST: dict[str, float] = {
    "forward": 0.01,
    "inverse": 0.03,
    "assembly_modes": 0.005,  # the parameter homotopy, x size^3 (multistart: x 4)
    "track": 0.005,  # per path point
    "jacobians": 0.02,
    "dof": 0.15,
    "classify": 0.05,
    "singular_curves": 0.4,
    "working_modes": 0.03,
    "aspects": 0.5,
    "workspace": 0.6,
    "statics": 0.08,
    "design": 6.0,
}
#: Seconds to load a problem and fetch its model (per unit of work; measured 3-6 ms warm).
PROBLEM_COST = 0.005


def _num(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(
        float(v)) else default


def _size(mech: Mapping[str, Any]) -> float:
    """A factor for the mechanism's size: its number of legs or rows."""
    legs = mech.get("legs")
    if isinstance(legs, list):
        return max(1.0, len(legs) / 3.0)
    rows = mech.get("rows")
    if isinstance(rows, list):
        return max(1.0, len(rows) / 4.0)
    args = mech.get("args")
    if isinstance(args, Mapping):
        for key in ("base", "rails", "platform"):
            pts = args.get(key)
            if isinstance(pts, list):
                return max(1.0, len(pts) / 3.0)
    name = mech.get("name")
    return 2.0 if name in ("stewart_gough", "hexa", "pus6", "sr400", "akr3000") else 1.0


def task_costs(doc: Any) -> list[float]:
    """The estimated cost of each task of a parsed problem document (1 s each for what
    cannot be read: the worker will say what is wrong)."""
    if not isinstance(doc, Mapping) or not isinstance(doc.get("task"), list):
        return [1.0]
    mech = doc.get("mechanism") if isinstance(doc.get("mechanism"), Mapping) else {}
    k = _size(mech)
    out = []
    for t in doc["task"]:
        if not isinstance(t, Mapping):
            out.append(1.0)
            continue
        kind = t.get("kind")
        c = BASE_COST.get(kind, 1.0) if isinstance(kind, str) else 1.0
        opts = t.get("options") if isinstance(t.get("options"), Mapping) else {}
        if kind == "track":
            path = t.get("qa_path")
            c *= len(path) if isinstance(path, list) else 50
        if kind == "assembly_modes":
            c *= k ** 3 * max(1.0, _num(opts.get("starts"), 2000) / 2000)
            if t.get("method", opts.get("method")) == "multistart":
                c *= 4.0
        elif kind in ("aspects", "workspace", "singular_curves"):
            g = _num(t.get("grid"), 32)
            c *= max(1.0, (g / 32) ** 2)
        else:
            c *= k
        out.append(c)
    return out


def topology_group(doc: Any) -> str:
    """A label shared by problems whose mechanisms (probably) have one topology: the
    mechanism's kind, library name and size, read from the parsed document (the worker
    knows the real topology; this only groups the work)."""
    mech = doc.get("mechanism") if isinstance(doc, Mapping) else None
    if not isinstance(mech, Mapping):
        return "?"
    parts = [str(mech.get("type", "?")), str(mech.get("name", ""))]
    for key in ("legs", "rows"):
        v = mech.get(key)
        if isinstance(v, list):
            parts.append(f"{key}{len(v)}")
            parts += sorted({str(x.get("type", x.get("kind", ""))) for x in v
                             if isinstance(x, Mapping)})
    return ":".join(parts)


#: Seconds a worker's first problem of a topology costs over the next ones (building the
#: model, loading the compiled code: 0.1-0.4 s measured by the scaling benchmark).
SETUP_COST = 0.3


class Affinity:
    """Which pending unit a free worker takes next: the longest first (LPT), except that a
    unit of a topology group (:func:`topology_group`) the worker has already set up is
    preferred to any unit at most ``setup`` seconds longer (its set-up would cost about
    that). A worker with no such unit joins, among the groups whose longest unit is
    within ``setup`` of the longest, the one with the most estimated work left per worker
    on it. So workers spread over groups of similar costs and stay on them, while long
    units still start first (LPT keeps the tail short: with 16 workers, keeping workers on
    their groups regardless of the costs gave a 30 % longer schedule on the scaling
    benchmark's batch). The same policy drives the local pool and the scaling benchmark's
    model (``benchmarks/test_scaling.py``).

    ``units`` are (cost, group) pairs in the runner's order (longest first); :meth:`take`
    returns the index of the chosen unit (:meth:`take_any` for no worker); :meth:`put_back`
    returns a unit to the pool (a worker that died), :meth:`leave` forgets a worker.
    """

    def __init__(self, units: list[tuple[float, str]], setup: float = SETUP_COST) -> None:
        self.cost = [float(c) for c, _ in units]
        self.group = [g for _, g in units]
        self.setup = float(setup)
        self.left: dict[str, list[int]] = {}  # group -> unit indices, longest first
        for i, g in enumerate(self.group):
            self.left.setdefault(g, []).append(i)
        for ix in self.left.values():
            ix.sort(key=lambda i: (-self.cost[i], i))
        self.work = {g: sum(self.cost[i] for i in ix) for g, ix in self.left.items()}
        self.on: dict[object, str] = {}  # worker -> the group of its last unit
        self.seen: dict[object, set[str]] = {}  # worker -> the groups it has set up

    def _head(self, g: str) -> tuple[float, int]:
        i = self.left[g][0]
        return self.cost[i], -i

    def take(self, worker: object) -> int | None:
        live = [g for g, ix in self.left.items() if ix]
        if not live:
            return None
        top = max(self._head(g)[0] for g in live)
        near = [g for g in live if self._head(g)[0] >= top - self.setup]
        seen = self.seen.setdefault(worker, set())
        mine = [g for g in near if g in seen]
        if mine:
            g = max(mine, key=self._head)
        else:
            crowd: dict[str, int] = {}
            for w, h in self.on.items():
                if w is not worker:
                    crowd[h] = crowd.get(h, 0) + 1
            g = max(near, key=lambda h: (self.work[h] / (crowd.get(h, 0) + 1), self._head(h)))
        seen.add(g)
        self.on[worker] = g
        return self._pop(g)

    def take_any(self) -> int | None:
        """The longest unit left, for no worker (the runner failing what is left)."""
        live = [g for g, ix in self.left.items() if ix]
        return self._pop(max(live, key=self._head)) if live else None

    def _pop(self, g: str) -> int:
        i = self.left[g].pop(0)
        self.work[g] -= self.cost[i]
        return i

    def put_back(self, i: int) -> None:
        g = self.group[i]
        ix = self.left.setdefault(g, [])
        ix.insert(0, i)  # (it was the longest when taken; a retry goes first)
        self.work[g] = self.work.get(g, 0.0) + self.cost[i]

    def leave(self, worker: object) -> None:
        """The worker is gone: it no longer counts on its group."""
        self.on.pop(worker, None)
        self.seen.pop(worker, None)

    def __len__(self) -> int:
        return sum(len(ix) for ix in self.left.values())
