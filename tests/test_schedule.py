"""The batch runner's scheduling policy (:class:`optkin.problems.costs.Affinity`).

Checked against list schedules simulated here: every unit handed out exactly once; no
worker idle while work is pending (Graham's bound, met by any greedy list schedule);
longest first up to the set-up allowance; workers kept on their topologies when the costs
allow it (fewer set-ups than plain longest-first), never a longer schedule on the scaling
benchmark's batch shape.
"""

from __future__ import annotations

import heapq

import numpy as np
import pytest

from optkin.problems.costs import Affinity, topology_group


def _simulate(units, P, warm=0.0, policy="affinity", setup=0.3):
    """Makespan, set-ups per worker and hand-out order (index, pending max cost at that
    moment) of a greedy schedule of ``units`` (cost, group) on P workers; a worker's
    first unit of a group costs ``warm`` more."""
    aff = Affinity(units, setup)
    todo = sorted(range(len(units)), key=lambda i: (-units[i][0], i))  # plain LPT
    pend = set(range(len(units)))
    free = [(0.0, w) for w in range(P)]
    seen = [set() for _ in range(P)]
    taken, end = [], 0.0
    while pend:
        t, w = heapq.heappop(free)
        top = max(units[j][0] for j in pend)
        i = aff.take(w) if policy == "affinity" else todo.pop(0)
        pend.remove(i)
        taken.append((i, top))
        c, g = units[i]
        d = c + (warm if g not in seen[w] else 0.0)
        seen[w].add(g)
        end = max(end, t + d)
        heapq.heappush(free, (t + d, w))
    return end, [len(s) for s in seen], taken


def _batch(rng, n_groups, n):
    units = [(float(rng.uniform(0.05, 2.0)), f"g{rng.integers(n_groups)}") for _ in range(n)]
    return sorted(units, key=lambda u: -u[0])


@pytest.mark.parametrize("P", [1, 2, 3, 8, 16])
def test_every_unit_once_longest_first_and_no_worker_idles(P):
    rng = np.random.default_rng(P)
    for _ in range(20):
        units = _batch(rng, int(rng.integers(1, 6)), int(rng.integers(1, 80)))
        span, _, taken = _simulate(units, P)
        assert sorted(i for i, _ in taken) == list(range(len(units)))
        assert all(units[i][0] >= top - 0.3 - 1e-12 for i, top in taken)
        costs = [c for c, _ in units]
        # any list schedule that never idles a worker with work pending meets this
        assert span <= sum(costs) / P + max(costs) + 1e-9


def test_workers_stay_on_their_topology_when_costs_are_alike():
    """Three topologies of like costs, files interleaved: plain longest-first sends every
    worker to every topology; the policy gives each of three workers one."""
    rng = np.random.default_rng(3)
    units = [(1.0 + 0.01 * rng.uniform(), f"g{k % 3}") for k in range(60)]
    units.sort(key=lambda u: -u[0])
    span, setups, _ = _simulate(units, 3, warm=0.3)
    l_span, l_setups, _ = _simulate(units, 3, warm=0.3, policy="lpt")
    assert setups == [1, 1, 1] and l_setups == [3, 3, 3]
    assert span < l_span


def test_no_longer_than_lpt_on_the_benchmark_shape():
    """The scaling benchmark's batch: aspects ~1.25 s, Stewart ~0.65 s, 3-RPR ~0.2 s (21-22
    of each), 0.4 s to set a topology up in a worker."""
    units = sorted([(1.25, "five_bar")] * 21 + [(0.65, "stewart")] * 22 + [(0.2, "rpr")] * 21,
                   key=lambda u: -u[0])
    for P in (2, 4, 16):
        a_span, a_setups, _ = _simulate(units, P, warm=0.4)
        l_span, l_setups, _ = _simulate(units, P, warm=0.4, policy="lpt")
        assert sum(a_setups) <= sum(l_setups)
        assert a_span <= l_span + 1e-9


def test_a_unit_put_back_goes_first():
    units = [(3.0, "a"), (2.0, "a"), (1.0, "b")]
    aff = Affinity(units)
    i = aff.take("w1")
    assert i == 0
    aff.leave("w1")
    aff.put_back(i)
    assert aff.take("w2") == 0 and len(aff) == 2


def test_topology_groups():
    lib = {"mechanism": {"type": "library", "name": "rpr3", "args": {}}}
    legs = {"mechanism": {"type": "legs", "legs": [{"type": "RPR"}] * 3}}
    assert topology_group(lib) == "library:rpr3"
    assert topology_group(legs) == "legs::legs3:RPR"
    assert topology_group({"task": []}) == "?"


@pytest.mark.parametrize("slots", [1, 2, 16])
def test_dask_tasks_hold_consecutive_units_within_the_cost_cap(slots):
    """Every unit in exactly one Dask task, in the runner's order; a task of several units
    within DASK_TASK_COST and half a thread's share of the whole; the benchmark's shape (a
    few costly units, many cheap ones) in fewer tasks."""
    from optkin.problems.runner import DASK_TASK_COST, _dask_batches
    from optkin.problems.workers import Job

    rng = np.random.default_rng(slots)
    costs = sorted(np.r_[rng.uniform(0.4, 0.7, 21), rng.uniform(0.03, 0.05, 22),
                         rng.uniform(0.005, 0.01, 21)], reverse=True)
    jobs = [Job(f"u{i}", {}, cost=float(c)) for i, c in enumerate(costs)]
    batches = _dask_batches(jobs, slots)
    assert [j.key for b in batches for j in b] == [j.key for j in jobs]
    cap = min(DASK_TASK_COST, sum(costs) / (2 * slots))
    for b in batches:
        assert len(b) == 1 or sum(j.cost for j in b) <= cap + 1e-12
    assert 21 < len(batches) <= 21 + 8  # the costly units alone, the cheap ones shared
    assert _dask_batches([], slots) == []
    few = _dask_batches(jobs[-3:], slots)  # three cheap units
    assert [j.key for b in few for j in b] == [j.key for j in jobs[-3:]]
    assert len(few) >= 2  # (a task holds at most half a thread's share)
