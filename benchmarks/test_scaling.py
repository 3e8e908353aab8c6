"""Scale-out of the batch runner: speed-up and efficiency per worker count, local pool and Dask.

The batch (:func:`make_batch`, documented so that anyone can rebuild it): ``n`` problem files
in three equal groups, drawn from ``numpy.random.default_rng(seed)``

* random 6-6 Stewart-Gough platforms (base points on the unit circle at sorted uniform
  angles, platform points on a circle of radius 0.5, a pose near z = 1 with tilts up to
  0.15 rad) with one ``assembly_modes`` task at the leg lengths of that pose;
* random 3-RPR (base and platform points uniform in [-1, 1]^2 and [-0.4, 0.4]^2, a pose in
  [-0.3, 0.3]^2 x [-1, 1]) with one ``assembly_modes`` task at the leg lengths of that pose;
* random five-bars (L0 in [6, 10], L1 = L4 in [6, 9], L2 = L3 in [4, 6]) with one
  ``aspects`` task.

The leg lengths are computed here with numpy (|p + R b_i - a_i|), not by optkin.

For each worker count P up to the machine's cores, ``optkin run --no-pictures -q --jobs P``
runs the batch in a fresh process, and so does the same batch sent to a Dask
``LocalCluster(P workers, 1 thread each)`` with ``--scheduler``, twice: at once after the
cluster starts (its workers and the optkin processes their preload starts still importing
on the cores the run uses), **settled** (``_settled``: once those say ready, as on a
long-lived cluster that outlives runs) and, warm, **primed** (``_primed``: settled and after
a first run of the batch, whose optkin worker processes the cluster keeps: a long-lived
cluster after a user's first run); each **cold** (its own
empty compiled-code cache: every topology's code is compiled during the run, once per
cache) and **warm** (a cache filled by an earlier run, the state of every run after a
user's first), and once more with a **worker server** (``optkin workers start``,
warmed up by one run of the batch, one Dask run and one of the trivial problem before its
runs are measured: every run after a user's first with a server): the pool with its
workers forked by the server, Dask (settled and primed) with its client in a driver the
server forks, ``distributed`` already imported.
``extra_info`` holds the wall times, the speed-ups over ``--jobs 1`` in the
same state (the in-run baseline), the efficiencies, whether the results equal those of
the first run, and the predictions of :func:`predict`, a model fed with what the runs
measured:

* the unit costs: each problem's ``elapsed`` in the warm ``--jobs 1`` runs (the worker's
  time to fetch the model and run the tasks, from the result files; the median over the
  rounds), with the runner's estimated cost and topology group of each;
* the set-up of a topology in a worker (:func:`setups`): in fresh processes that have
  imported what a worker imports before they say ready, the first two problems of each
  topology run in both orders, each one's cost first less its cost second (warm cache);
  a worker pays it for every topology it meets. (The first unit's cost over the median
  of the others, used before, also counted how much that problem itself costs: the
  batch's first five-bar costs 0.5 s in every run against a median of 0.3 s; one problem
  run twice counted what is kept per geometry too);
* the compile of a topology (cold): the first unit's excess over the median of its
  topology in the cold run less that in the warm one (the problem's own cost cancels),
  paid once per cache; the model charges the wait to every worker that meets the topology
  before its code lands (an upper bound: those workers run the interpreted code
  meanwhile);
* the fixed cost: the wall time of a run of one trivial problem (a four-bar's forward
  model) less that problem's own time (median of :data:`FIXED_RUNS` runs): start-up of
  the command line and of a worker, the summary; paid once whatever the number of
  workers;
* the overhead per unit outside the worker (messages, the parent writing the result): the
  rest of the warm ``--jobs 1`` runs' median wall time, shared among its units;
* the parent's CPU time per unit (``time.process_time`` of the command-line process over
  that run, which excludes the workers, less that of the one-problem run: its start-up,
  already in the fixed cost, over the other units): the parent handles the results one
  after the other, so no schedule beats ``n`` times it;

and, with the worker server, the same unit costs (those measured without it, so that the
problems its warm-up ran save nothing) with its own fixed cost (``fixed_server``), set-ups
(measured the same way in workers it forks: ``warmup_per_topology_server``) and overhead
per unit;

and predicts the makespan at P workers by simulating the runner's own scheduling policy
(:class:`optkin.problems.costs.Affinity`) event by event, plus the fixed cost, or the
parent's serial share when longer. The same model predicts the ``--jobs 2`` runs measured
here. ``cpu_inflation_at_2`` is the measured ratio of the workers' summed unit costs with 2
workers to those with 1 (memory, caches and, cold, the compiler sharing the cores): the
16- and 64-worker predictions are given without it and with it.

optkin's bytecode is written first (:func:`_byte_compile`). Run it with
``python -m pytest benchmarks/test_scaling.py`` (about 5 minutes here;
``OPTKIN_SCALING_ROUNDS=3`` repeats the runs, interleaved, and reports medians), or rebuild
the batch with ``python benchmarks/test_scaling.py DIR [N]``.
"""

from __future__ import annotations

import heapq
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

N_PROBLEMS = int(os.environ.get("OPTKIN_SCALING_N", "64"))


# ---------------------------------------------------------------------------------------
# The batch
# ---------------------------------------------------------------------------------------

def _rot(roll: float, pitch: float, yaw: float) -> np.ndarray:
    from scipy.spatial.transform import Rotation
    return Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_matrix()


def _fmt(a) -> str:
    a = np.asarray(a, dtype=float)
    if a.ndim == 1:
        return "[" + ", ".join(f"{v:.9g}" for v in a) + "]"
    return "[" + ", ".join(_fmt(r) for r in a) + "]"


def make_batch(folder: Path, n: int = 64, seed: int = 0) -> list[Path]:
    """Write the documented batch of ``n`` problem files into ``folder``."""
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    for i in range(n):
        kind = i % 3
        if kind == 0:
            ab = np.sort(rng.uniform(0, 2 * np.pi, 6))
            ap = np.sort(rng.uniform(0, 2 * np.pi, 6))
            base = np.c_[np.cos(ab), np.sin(ab), np.zeros(6)]
            plat = 0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]
            p = np.r_[rng.uniform(-0.1, 0.1, 2), rng.uniform(0.8, 1.2)]
            R = _rot(*rng.uniform(-0.15, 0.15, 3))
            qa = np.linalg.norm(p + plat @ R.T - base, axis=1)
            text = (f'schema_version = 1\nname = "scale_sg_{i:03d}"\n\n[mechanism]\n'
                    f'type = "library"\nname = "stewart_gough"\n[mechanism.args]\n'
                    f"base = {_fmt(base)}\nplatform = {_fmt(plat)}\n\n"
                    f'[[task]]\nkind = "assembly_modes"\nqa = {_fmt(qa)}\nseed = 0\n')
        elif kind == 1:
            base = rng.uniform(-1, 1, (3, 2))
            plat = rng.uniform(-0.4, 0.4, (3, 2))
            x, y, phi = *rng.uniform(-0.3, 0.3, 2), rng.uniform(-1, 1)
            R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
            qa = np.linalg.norm(np.array([x, y]) + plat @ R.T - base, axis=1)
            text = (f'schema_version = 1\nname = "scale_rpr_{i:03d}"\n\n[mechanism]\n'
                    f'type = "library"\nname = "rpr3"\n[mechanism.args]\n'
                    f"base = {_fmt(base)}\nplatform = {_fmt(plat)}\n\n"
                    f'[[task]]\nkind = "assembly_modes"\nqa = {_fmt(qa)}\nseed = 0\n')
        else:
            L0, L1, L2 = rng.uniform(6, 10), rng.uniform(6, 9), rng.uniform(4, 6)
            text = (f'schema_version = 1\nname = "scale_fb_{i:03d}"\n\n[mechanism]\n'
                    f'type = "library"\nname = "five_bar"\n'
                    f"args = {{ L0 = {L0:.6f}, L1 = {L1:.6f}, L2 = {L2:.6f}, "
                    f"L3 = {L2:.6f}, L4 = {L1:.6f} }}\n\n"
                    f'[[task]]\nkind = "aspects"\n')
        f = folder / f"p{i:03d}.toml"
        f.write_text(text)
        files.append(f)
    return files


def make_trivial(folder: Path, n: int) -> None:
    """``n`` problems of one cheap task (a four-bar's forward model), for the overhead."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        (folder / f"t{i:03d}.toml").write_text(
            f'schema_version = 1\nname = "trivial_{i:03d}"\n\n[mechanism]\ntype = "library"\n'
            f'name = "four_bar"\nargs = {{ L1 = 4.0, L2 = 4.0, L3 = 2.0, L4 = 2.0 }}\n\n'
            f'[[task]]\nkind = "forward"\nqa = [0.{i % 9 + 1}]\n')


# ---------------------------------------------------------------------------------------
# Runs
# ---------------------------------------------------------------------------------------

#: The ``optkin`` command (:func:`optkin.cli.console`: main, then fast_exit), reporting the
#: CPU time of its own process
_CLI = ("import sys, time\nfrom optkin.cli import main\n"
        "from optkin._exit import fast_exit\nrc = main(sys.argv[1:])\n"
        "print(f'parent-cpu {time.process_time():.6f}', file=sys.stderr)\nfast_exit(rc)\n")


#: This process's environment before any Dask ``LocalCluster``: one sets, in the process
#: that starts it, and leaves behind ``PYTHONHASHSEED``, one BLAS thread
#: (``OMP_NUM_THREADS`` and kin), ``MALLOC_TRIM_THRESHOLD_`` and ``__DASK_PARENT_PID``,
#: which would otherwise reach every run after the first cluster (a ``--jobs 1`` run's
#: BLAS threads among them)
_BASE_ENV = dict(os.environ)


def _env(cache: Path, runtime: Path | None = None) -> dict[str, str]:
    """The environment of a run: its compiled-code cache; with ``runtime`` the worker
    server of that runtime directory (:func:`start_server`), else none (not even the
    user's: ``OPTKIN_WORKER_SERVER=0``)."""
    env = dict(_BASE_ENV, OPTKIN_CACHE=str(cache))
    if runtime is None:
        env["OPTKIN_WORKER_SERVER"] = "0"
    else:
        env.pop("OPTKIN_WORKER_SERVER", None)
        env["XDG_RUNTIME_DIR"] = str(runtime)
    return env


def run_batch(batch: Path, out: Path, cache: Path, jobs: int = 1,
              scheduler: str | None = None, runtime: Path | None = None
              ) -> tuple[float, float]:
    """Wall time of ``optkin run`` on ``batch`` in a fresh process (its own cache), and the
    CPU time of that command-line process alone (not its workers); with ``runtime``, its
    workers forked by the worker server there."""
    env = _env(cache, runtime)
    cmd = [sys.executable, "-c", _CLI, "run", str(batch), "--out", str(out),
           "--no-pictures", "-q", "--force"]
    cmd += ["--scheduler", scheduler] if scheduler else ["--jobs", str(jobs)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 1):  # 1: some task did not meet its expectation
        raise RuntimeError(f"optkin run failed ({p.returncode}): {p.stderr[-2000:]}")
    cpu = [float(line.split()[1]) for line in p.stderr.splitlines()
           if line.startswith("parent-cpu ")]
    return wall, (cpu[-1] if cpu else float("nan"))


def unit_costs(out: Path, batch: Path) -> list[tuple[str, str, float, float]]:
    """(problem, topology, elapsed, estimated cost) of every result of a run of ``batch``,
    in the order a one-worker run starts them (the runner's own units and policy)."""
    from optkin.problems.costs import Affinity
    from optkin.problems.runner import _units, find_problem_files

    rows = {}
    for f in out.glob("*.json"):
        data = json.loads(f.read_text())
        if "elapsed" in data:
            rows[data["problem"]] = (data["input"]["mechanism"].get("name", "?"),
                                     float(data["elapsed"]))
    todo = [(i, i.path.read_bytes()) for i in find_problem_files([str(batch)])]
    jobs = _units(todo, False, split=False)
    policy = Affinity([(j.cost, j.group) for j in jobs])
    order = [jobs[policy.take(0)] for _ in jobs]
    return [(j.spec["display"], *rows[j.spec["display"]], j.cost) for j in order
            if j.spec["display"] in rows]


#: Provenance, not results: times, where it ran, and whether a step ran compiled (the first
#: solves of a topology use the interpreted step while the compiler runs; the numbers agree).
_VOLATILE = {"time", "elapsed", "created", "host", "pid", "started", "finished", "optkin",
             "python", "casadi", "platform_info", "jit"}


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items()
                if k not in _VOLATILE and not k.endswith("_time")}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    if isinstance(obj, float):
        return round(obj, 6)
    return obj


def _wait_builds(cache: Path, limit: float = 300.0) -> None:
    """Wait until no library is being built in ``cache`` (no build lock or directory left):
    a library a run started (the SIMD lanes of a topology, compiled by a detached builder
    for 5-10 s) would otherwise still be compiling, on the cores being measured, during the
    warm runs that follow."""
    end = time.monotonic() + limit
    while time.monotonic() < end and (any(cache.glob("*.lock"))
                                       or any(cache.glob(".build-*"))):
        time.sleep(0.2)


def results_of(out: Path) -> dict[str, object]:
    """The problem results of a run with times and provenance removed."""
    res = {}
    for f in sorted(out.glob("*.json")):
        data = json.loads(f.read_text())
        res[f.name] = _strip(data.get("tasks", data))
    return res


# ---------------------------------------------------------------------------------------
# The model
# ---------------------------------------------------------------------------------------

def warmups(units) -> dict[str, float]:
    """Per topology, the first unit's cost over the median of the others. This mixes the
    set-up with how much the first problem itself costs (the batch's first five-bar costs
    0.5 s at every run, the median 0.3 s); it serves only where that cancels: the compile
    of a topology, this excess in a cold run less that in a warm one."""
    by: dict[str, list[float]] = {}
    for _, topo, c, _ in units:
        by.setdefault(topo, []).append(c)
    return {t: max(0.0, cs[0] - float(np.median(cs[1:]))) if len(cs) > 1 else 0.0
            for t, cs in by.items()}


_SETUP = """
import json, sys
from optkin.problems.workers import _preload
from optkin.problems.runner import run_job
_preload()  # as a worker does before it says ready
out = {}
for topo, files in json.loads(sys.argv[1]):
    out[topo] = [run_job(f, open(f, "rb").read(), f, pictures=False)["result"]["elapsed"]
                 for f in files]
print(json.dumps(out))
"""


def setups(units, batch: Path, cache: Path, reps: int = 3,
           runtime: Path | None = None) -> dict[str, float]:
    """The set-up of each topology in a worker: in a fresh process that has imported what
    a worker imports before it says ready, the first two units A and B of each topology
    (in the runner's order) run one after the other, and in another such process B then
    A; the set-up is the mean of A's cost first less its cost after B, and B's first
    less after A (the median of ``reps`` pairs of processes). A worker never runs one
    problem twice: the second run of the same problem, used before, also saved what is
    kept per geometry (about 10 ms of a five-bar's aspects), which is no set-up."""
    two: dict[str, list[str]] = {}
    for prob, topo, _, _ in units:
        if len(two.setdefault(topo, [])) < 2:
            two[topo].append(str(batch / prob))
    env = _env(cache, runtime)
    code = _SETUP if runtime is None else _SETUP_SERVED

    def run(order: list) -> dict:
        p = subprocess.run([sys.executable, "-c", code, json.dumps(order)], env=env,
                           capture_output=True, text=True, timeout=600, check=True)
        return json.loads(p.stdout.splitlines()[-1])

    est: dict[str, list[float]] = {t: [] for t in two}
    for _ in range(reps):
        ab = run([(t, fs) for t, fs in two.items()])
        ba = run([(t, fs[::-1]) for t, fs in two.items()])
        for t, fs in two.items():
            if len(fs) < 2:  # one unit of this topology: its own second run
                continue
            a1, b1 = ab[t]
            b2, a2 = ba[t]
            est[t].append(max(0.0, 0.5 * ((a1 - a2) + (b2 - b1))))
    return {t: float(np.median(v)) if v else 0.0 for t, v in est.items()}


def workers_cmd(action: str, cache: Path, runtime: Path) -> str:
    """``optkin workers ACTION`` as the runs see it (the same interpreter, module path and
    environment, so the same server); its output."""
    p = subprocess.run([sys.executable, "-c", _CLI, "workers", action],
                       env=_env(cache, runtime), capture_output=True, text=True, timeout=180)
    return p.stdout + p.stderr


def _server_pid(cache: Path, runtime: Path) -> int | None:
    out = workers_cmd("status", cache, runtime)
    return int(out.split("(pid ")[1].split(",")[0]) if "(pid " in out else None


def start_server(batch: Path, cache: Path, runtime: Path, tmp: Path) -> int:
    """Start a worker server for the runs and let it warm up as a user's would: one run of
    ``batch`` through it (after which a copy of it that ran one unit of each kind takes
    over); its pid once that copy serves."""
    out = workers_cmd("start", cache, runtime)
    first = _server_pid(cache, runtime)
    if first is None:
        raise RuntimeError(f"optkin workers start: {out}")
    run_batch(batch, tmp, cache, runtime=runtime)
    pid = _handed_over(cache, runtime, first, 120.0)
    if pid is None:
        raise RuntimeError("the worker server did not warm up within 120 s")
    return pid


def _handed_over(cache: Path, runtime: Path, old: int | None, limit: float) -> int | None:
    """The pid of the server that took over from ``old`` (its warmed copy), or None when
    none did within ``limit`` seconds (a run that brought no new kind of work)."""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        pid = _server_pid(cache, runtime)
        if pid is not None and pid != old:
            return pid
        time.sleep(0.2)
    return None


_SETUP_SERVED = """
import json, sys
from optkin.problems.workers import Job, run_jobs
out = {}
for topo, files in json.loads(sys.argv[1]):
    out[topo] = []
    for f in files:  # one worker (kept idle between the calls), forked by the server
        spec = {"display": f, "data": open(f, "rb").read(), "source": f, "pictures": False}
        (o,) = run_jobs([Job(f, spec)], n_workers=1, threads=1)
        out[topo].append(o.result["elapsed"])
print(json.dumps(out))
"""


def unit_net_costs(units, setup: dict[str, float]) -> list[float]:
    """The unit costs with the set-up taken out of each topology's first unit."""
    seen: set[str] = set()
    costs = []
    for _, topo, c, _ in units:
        costs.append(max(0.0, c - setup.get(topo, 0.0)) if topo not in seen else c)
        seen.add(topo)
    return costs


def predict(units, costs, fixed: float, per_unit: float, warm: dict[str, float],
            parent: float, workers: int, n: int, compile_: dict[str, float] | None = None,
            inflation: float = 1.0) -> dict[str, float]:
    """Predicted wall time and efficiency of a batch of ``n`` units like ``units``.

    The batch: the measured units repeated (their topologies, estimated costs and measured
    ``costs``) up to ``n``. The schedule: the runner's own policy
    (:class:`optkin.problems.costs.Affinity`, fed with the estimated costs) on ``workers``
    workers, event by event; a unit lasts its cost times ``inflation`` plus ``per_unit``,
    plus ``warm[topology]`` the first time a worker meets its topology. With ``compile_``
    (a cold cache), a topology's compiled code lands ``compile_[topology]`` seconds after
    the first worker meets it, and every worker that meets it before then is charged the
    wait (an upper bound: meanwhile it runs the interpreted code). T(P) = fixed +
    max(makespan, n * parent); the efficiency is T(1) / (P T(P)), T(1) the same model at
    one worker without inflation.
    """
    from optkin.problems.costs import Affinity

    reps = -(-n // len(units))
    big = [(topo, est, c) for _ in range(reps) for (_, topo, _, est), c in zip(units, costs)]
    big = big[:n]
    order = sorted(range(n), key=lambda i: -big[i][1])  # the runner's order: LPT, stable

    def makespan(P: int, infl: float) -> float:
        policy = Affinity([(big[i][1], big[i][0]) for i in order])
        free = [(0.0, w) for w in range(P)]
        seen: list[set[str]] = [set() for _ in range(P)]
        ready: dict[str, float] = {}
        end = 0.0
        while len(policy):
            t, w = heapq.heappop(free)
            topo, _, c = big[order[policy.take(w)]]
            d = c * infl + per_unit
            if topo not in seen[w]:
                seen[w].add(topo)
                d += warm.get(topo, 0.0)
                if compile_ is not None:
                    r = ready.setdefault(topo, t + compile_.get(topo, 0.0))
                    d += max(0.0, r - t)
            end = max(end, t + d)
            heapq.heappush(free, (t + d, w))
        return fixed + max(end, n * parent)

    t1 = makespan(1, 1.0)
    tp = makespan(workers, inflation)
    return {"t1": t1, "tp": tp, "efficiency": t1 / (workers * tp)}


# ---------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------

def _local_cluster(workers: int, cache: Path):
    from distributed import LocalCluster
    # started as the README says to start Dask workers for optkin: with its preload, which
    # starts the optkin worker processes with the Dask workers; like every other run, with
    # its own empty compiled-code cache (the workers' environment, not this process's)
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                        dashboard_address=None, silence_logs=50,
                        preload=["optkin.problems.dask_worker"],
                        env={"OPTKIN_CACHE": str(cache)})


def _booted(timeout: float = 60.0) -> bool:
    """On a Dask worker: wait until the optkin worker processes its preload started say
    ready."""
    from optkin.problems import workers as w

    with w._BOOTED:
        return w._BOOTED.wait_for(lambda: not any(w._BOOTING.values()), timeout)


def _settle(cluster) -> None:
    """A cluster as a long-lived one is when a run arrives: its Dask workers and the
    optkin worker processes their preload starts are up (``dask worker --preload``, as the
    README runs it; started with the cluster, they are otherwise still importing when the
    run begins, on the cores the run uses)."""
    from distributed import Client

    with Client(cluster) as c:
        c.run(_booted)


ROUNDS = int(os.environ.get("OPTKIN_SCALING_ROUNDS", "1"))
#: One-problem runs behind the fixed cost (their median; the samples are in extra_info:
#: on this machine they spread over 0.4-0.7 s within a day)
FIXED_RUNS = 5


def _byte_compile() -> None:
    """Write optkin's bytecode (``__pycache__``), as ``pip install`` does for a package: this
    machine sets PYTHONDONTWRITEBYTECODE, and an editable install then recompiles every
    module in every process (about 0.15 s per worker)."""
    import compileall

    import optkin
    compileall.compile_dir(str(Path(optkin.__file__).parent), quiet=1)


def test_scaling(benchmark, tmp_path):
    _byte_compile()
    batch = tmp_path / "batch"
    make_batch(batch, N_PROBLEMS)
    cores = os.cpu_count() or 1
    counts = sorted({1, 2, cores} & set(range(1, cores + 1)))
    try:
        import distributed  # noqa: F401
        have_dask = True
    except ImportError:
        have_dask = False
    filled = tmp_path / "cache_filled"  # the warm runs' cache: filled by a first run
    run_batch(batch, tmp_path / "fill", filled)
    _wait_builds(filled)  # and by the builds it started (detached, they outlive the run)
    # a worker server for the "server" runs, in a runtime directory of its own (short: a
    # socket path has at most 107 bytes), warmed up by one run of the batch
    runtime = Path(tempfile.mkdtemp(prefix="okb"))

    def measure():
        walls: dict[str, list[float]] = {}
        same: dict[str, bool] = {}
        ref = None
        units: dict[str, list] = {}  # per state, the one-worker runs' units
        parent_cpu: dict[str, list[float]] = {}
        sums: dict[str, list[float]] = {}
        for r in range(ROUNDS):  # interleaved, so that a slow spell of the machine hits all
            for state in ("cold", "warm", "server"):
                for P in counts:
                    key = f"pool{P}_{state}"
                    out = tmp_path / f"{key}_{r}"
                    cache = filled if state != "cold" else tmp_path / f"cache_{key}_{r}"
                    wall, cpu = run_batch(batch, out, cache, jobs=P,
                                          runtime=runtime if state == "server" else None)
                    _wait_builds(cache)  # a cold run's builders must not load the next run
                    walls.setdefault(key, []).append(wall)
                    u = unit_costs(out, batch)
                    sums.setdefault(key, []).append(sum(c for _, _, c, _ in u))
                    if P == 1:
                        units.setdefault(state, []).append(u)
                        parent_cpu.setdefault(state, []).append(cpu)
                    if ref is None:
                        ref = results_of(out)
                    same[key] = same.get(key, True) and results_of(out) == ref
                # a cluster at once, settled, and (warm) primed: after a first run; with
                # the server (its Dask driver has distributed loaded) settled and primed
                modes = {"warm": ("", "_settled", "_primed"), "cold": ("", "_settled"),
                         "server": ("_settled", "_primed")}[state]
                for P, mode in [(P, m) for P in counts for m in modes if have_dask]:
                    key = f"dask{P}_{state}{mode}"
                    out = tmp_path / f"{key}_{r}"
                    cache = filled if state != "cold" else tmp_path / f"cache_{key}_{r}"
                    rt = runtime if state == "server" else None
                    with _local_cluster(P, cache) as cluster:
                        if mode:
                            _settle(cluster)
                        if mode == "_primed":
                            run_batch(batch, tmp_path / f"{key}_prime_{r}", cache,
                                      scheduler=cluster.scheduler_address, runtime=rt)
                        wall, _ = run_batch(batch, out, cache, runtime=rt,
                                            scheduler=cluster.scheduler_address)
                    _wait_builds(cache)
                    walls.setdefault(key, []).append(wall)
                    same[key] = same.get(key, True) and results_of(out) == ref
        # the fixed cost: a run of one trivial problem, less that problem's own time
        triv = tmp_path / "triv"
        make_trivial(triv, 1)
        fixed: dict[str, list[float]] = {"warm": [], "server": []}
        triv_cpu = []
        # the server warms up with the trivial problem too (a new kind of work) before
        # its runs are measured, as it would have after a user's first such run
        first = _server_pid(filled, runtime)
        run_batch(triv, tmp_path / "triv_prime", filled, runtime=runtime)
        _handed_over(filled, runtime, first, 60.0)
        for k in range(FIXED_RUNS):
            for state in ("warm", "server"):
                out = tmp_path / f"triv_{state}{k}"
                t_one, c_one = run_batch(triv, out, filled,
                                         runtime=runtime if state == "server" else None)
                fixed[state].append(max(0.0, t_one - sum(c for _, _, c, _ in
                                                         unit_costs(out, triv))))
                if state == "warm":
                    triv_cpu.append(c_one)
        return (walls, same, units, parent_cpu, fixed, sums, float(np.median(triv_cpu)))

    try:
        pid = start_server(batch, filled, runtime, tmp_path / "prime")
        if have_dask:  # and by one Dask run: it then imports distributed for the drivers
            with _local_cluster(2, filled) as cluster:
                run_batch(batch, tmp_path / "prime_dask", filled, runtime=runtime,
                          scheduler=cluster.scheduler_address)
            _handed_over(filled, runtime, pid, 60.0)
        walls, same, units, parent_cpu, fixed_samples, sums, triv_cpu = benchmark.pedantic(
            measure, rounds=1, iterations=1)
        # the set-up of each topology in a worker forked by the (warmed) server
        # (the first round's units: only their order matters here, the same in every run)
        excess_server = setups(units["warm"][0], batch, filled, runtime=runtime)
    finally:
        workers_cmd("stop", filled, runtime)
        shutil.rmtree(runtime, ignore_errors=True)
    fixed_server = float(np.median(fixed_samples["server"]))
    fixed_samples = fixed_samples["warm"]
    fixed = float(np.median(fixed_samples))
    # each unit's median over the rounds (the order is the same in every run)
    units = {st: [(*rows[0][i][:2], float(np.median([r[i][2] for r in rows])), rows[0][i][3])
                  for i in range(len(rows[0]))] for st, rows in units.items()}
    n = len(units["warm"])
    med = {k: float(np.median(v)) for k, v in walls.items()}
    info = {"n_problems": N_PROBLEMS, "cores": cores, "rounds": ROUNDS, "walls": walls,
            "wall_median": med, "same_results": same, "fixed": fixed,
            "fixed_samples": fixed_samples, "fixed_server": fixed_server}
    # the model, fed with the first one-worker runs: warm for the steady state, cold for
    # the compile of each topology (its first unit's excess over the warm run's)
    excess = setups(units["warm"], batch, filled)
    costs = unit_net_costs(units["warm"], excess)
    first_warm, first_cold = warmups(units["warm"]), warmups(units["cold"])
    compile_ = {t: max(0.0, first_cold[t] - first_warm.get(t, 0.0)) for t in first_cold}
    t1 = med["pool1_warm"]  # the runs the unit costs come from
    # the parent's CPU per unit beyond its start-up (that of the one-problem run; the
    # start-up is in the fixed cost already): measured 0.50-0.55 s for the 64 problems
    # against 0.56 s for one, i.e. next to nothing per unit
    parent_total = float(np.median(parent_cpu["warm"]))
    parent = max(0.0, parent_total - triv_cpu) / max(1, n - 1)
    per_unit = max(0.0, (t1 - fixed - sum(excess.values()) - sum(costs)) / n)
    inflation = {st: float(np.median(sums[f"pool2_{st}"])) / float(np.median(sums[f"pool1_{st}"]))
                 for st in ("cold", "warm") if f"pool2_{st}" in sums}
    info.update({"unit_cost_sum": sum(costs), "unit_cost_median": float(np.median(costs)),
                 "unit_cost_max": max(costs), "warmup_per_topology": excess,
                 "compile_per_topology": compile_, "per_unit": per_unit,
                 "parent_cpu_per_unit": parent, "parent_cpu_total": parent_total,
                 "parent_cpu_one_problem": triv_cpu, "cpu_inflation_at_2": inflation,
                 # what the model was fed, to re-run it offline: (problem, topology,
                 # measured cost less the set-up, estimated cost) in the runner's order
                 "units_warm": [(u[0], u[1], c, u[3]) for u, c in zip(units["warm"], costs)],
                 "units_cold": units["cold"]})
    for key, ws in walls.items():
        P, state = int(key.split("_")[0][4:]), key.split("_")[1]
        ratios = [w1 / w for w1, w in zip(walls[f"pool1_{state}"], ws)]  # round by round
        info[f"speedup_{key}"] = float(np.median(ratios))
        info[f"efficiency_{key}"] = float(np.median(ratios)) / P
    model = dict(units=units["warm"], costs=costs, fixed=fixed, per_unit=per_unit,
                 warm=excess, parent=parent)
    for state, comp in (("warm", None), ("cold", compile_)):
        if f"pool2_{state}" in walls:
            pr = predict(**model, workers=2, n=n, compile_=comp,
                         inflation=inflation.get(state, 1.0))
            info[f"predicted_speedup_pool2_{state}"] = pr["t1"] / pr["tp"]
        for P in (16, 64):
            info[f"predicted_efficiency_192_at_{P}_{state}"] = predict(
                **model, workers=P, n=192, compile_=comp)["efficiency"]
            info[f"predicted_efficiency_192_at_{P}_{state}_inflated"] = predict(
                **model, workers=P, n=192, compile_=comp,
                inflation=inflation.get(state, 1.0))["efficiency"]
    # with the worker server (warmed by the runs before, as after a user's first): the
    # same unit costs (those of the runs without it, so that the problems its warm-up ran
    # save nothing here), its own fixed cost, set-ups and overhead per unit
    per_unit_server = max(0.0, (med["pool1_server"] - fixed_server
                                - sum(excess_server.values()) - sum(costs)) / n)
    served = dict(model, fixed=fixed_server, per_unit=per_unit_server, warm=excess_server)
    info.update({"warmup_per_topology_server": excess_server,
                 "per_unit_server": per_unit_server})
    pr = predict(**served, workers=2, n=n, inflation=inflation.get("warm", 1.0))
    info["predicted_speedup_pool2_server"] = pr["t1"] / pr["tp"]
    for P in (16, 64):
        info[f"predicted_efficiency_192_at_{P}_server"] = predict(
            **served, workers=P, n=192)["efficiency"]
        info[f"predicted_efficiency_192_at_{P}_server_inflated"] = predict(
            **served, workers=P, n=192, inflation=inflation.get("warm", 1.0))["efficiency"]
    benchmark.extra_info.update(info)
    print(json.dumps(info, indent=1))
    assert all(same.values()), same


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("scaling_batch")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 192
    make_batch(target, n)
    print(f"wrote {n} problem files to {target}")
