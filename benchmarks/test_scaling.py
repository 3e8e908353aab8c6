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
runs the batch in a fresh process with its own empty compiled-code cache, and so does the
same batch sent to a Dask ``LocalCluster(P workers, 1 thread each)`` with ``--scheduler``.
``extra_info`` holds the wall times, the speed-ups over ``--jobs 1`` (the in-run baseline),
the efficiencies, whether the results equal those of ``--jobs 1``, and the prediction of
:func:`predict`, a model fed with what the ``--jobs 1`` run measured:

* the task costs (the runner's per-task times in ``summary.csv``),
* the fixed cost of a run that does not shrink with workers (start-up of the CLI, of a
  worker and the first compilation per topology: wall time minus the task times of the
  ``--jobs 1`` run, minus the per-unit overhead below),
* the scheduling overhead per unit of work (measured as the wall time a run of the same
  number of trivial problems takes per problem beyond its start-up),

and predicts the makespan at P workers as the fixed cost plus the longest-processing-time
schedule of the (bootstrapped) task costs plus overheads on P machines. Run it with
``python -m pytest benchmarks/test_scaling.py`` (about 2-4 minutes here), or rebuild the
batch with ``python benchmarks/test_scaling.py DIR [N]``.
"""

from __future__ import annotations

import csv
import heapq
import json
import os
import subprocess
import sys
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

def run_batch(batch: Path, out: Path, cache: Path, jobs: int = 1,
              scheduler: str | None = None) -> float:
    """Wall time of ``optkin run`` on ``batch`` in a fresh process (its own cache)."""
    env = dict(os.environ, OPTKIN_CACHE=str(cache))
    cmd = [sys.executable, "-m", "optkin", "run", str(batch), "--out", str(out),
           "--no-pictures", "-q", "--force"]
    cmd += ["--scheduler", scheduler] if scheduler else ["--jobs", str(jobs)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    if p.returncode not in (0, 1):  # 1: some task did not meet its expectation
        raise RuntimeError(f"optkin run failed ({p.returncode}): {p.stderr[-2000:]}")
    return wall


def task_times(out: Path) -> list[float]:
    with open(out / "summary.csv", newline="") as fh:
        return [float(r["time"]) for r in csv.DictReader(fh) if r.get("time")]


_VOLATILE = {"time", "elapsed", "created", "host", "pid", "started", "finished", "optkin",
             "python", "casadi", "platform_info"}


def _strip(obj):
    if isinstance(obj, dict):
        return {k: _strip(v) for k, v in obj.items()
                if k not in _VOLATILE and not k.endswith("_time")}
    if isinstance(obj, list):
        return [_strip(v) for v in obj]
    if isinstance(obj, float):
        return round(obj, 6)
    return obj


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

def lpt_makespan(costs, workers: int) -> float:
    """Makespan of the longest-processing-time-first schedule on ``workers`` machines."""
    loads = [0.0] * workers
    heapq.heapify(loads)
    for c in sorted(costs, reverse=True):
        heapq.heappush(loads, heapq.heappop(loads) + c)
    return max(loads)


def predict(costs, fixed: float, per_unit: float, workers: int, n: int,
            seed: int = 0) -> dict[str, float]:
    """Predicted wall time and efficiency of a batch of ``n`` tasks drawn from ``costs``.

    T(P) = fixed + LPT makespan of (c_i + per_unit) on P workers; the efficiency is
    T(1) / (P T(P)). The costs of the ``n`` tasks are the measured ones repeated (and, for
    a remainder, resampled with ``seed``), so the distribution is the measured one.
    """
    costs = np.asarray(costs, dtype=float)
    reps = n // len(costs)
    rest = np.random.default_rng(seed).choice(costs, n - reps * len(costs), replace=False)
    big = np.r_[np.tile(costs, reps), rest] + per_unit
    t1 = fixed + big.sum()
    tp = fixed + lpt_makespan(big, workers)
    return {"t1": t1, "tp": tp, "efficiency": t1 / (workers * tp)}


# ---------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------

def _local_cluster(workers: int):
    from distributed import LocalCluster
    return LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                        dashboard_address=None, silence_logs=50)


def test_scaling(benchmark, tmp_path):
    batch = tmp_path / "batch"
    make_batch(batch, N_PROBLEMS)
    cores = os.cpu_count() or 1
    counts = sorted({1, 2, cores} & set(range(1, cores + 1)))

    def measure():
        walls, same = {}, {}
        ref = None
        for P in counts:
            out = tmp_path / f"pool{P}"
            walls[f"pool{P}"] = run_batch(batch, out, tmp_path / f"cache_pool{P}", jobs=P)
            if P == 1:
                ref = results_of(out)
                costs = task_times(out)
            same[f"pool{P}"] = results_of(out) == ref
        try:
            import distributed  # noqa: F401
            have_dask = True
        except ImportError:
            have_dask = False
        if have_dask:
            for P in counts:
                out = tmp_path / f"dask{P}"
                with _local_cluster(P) as cluster:
                    walls[f"dask{P}"] = run_batch(batch, out, tmp_path / f"cache_dask{P}",
                                                  scheduler=cluster.scheduler_address)
                same[f"dask{P}"] = results_of(out) == ref
        # overhead per unit: trivial problems, 1 and 4 times as many
        triv_a, triv_b = tmp_path / "triv_a", tmp_path / "triv_b"
        make_trivial(triv_a, 8)
        make_trivial(triv_b, 32)
        ta = run_batch(triv_a, tmp_path / "triv_out_a", tmp_path / "cache_triv")
        tb = run_batch(triv_b, tmp_path / "triv_out_b", tmp_path / "cache_triv")
        per_unit = max(0.0, (tb - ta) / 24)
        return walls, same, costs, per_unit

    walls, same, costs, per_unit = benchmark.pedantic(measure, rounds=1, iterations=1)
    t1 = walls["pool1"]
    fixed = max(0.0, t1 - sum(costs) - per_unit * len(costs))
    info = {"n_problems": N_PROBLEMS, "cores": cores, "walls": walls, "same_results": same,
            "task_cost_sum": sum(costs), "task_cost_median": float(np.median(costs)),
            "task_cost_max": max(costs), "fixed": fixed, "per_unit": per_unit}
    for key, w in walls.items():
        P = int(key[4:])
        info[f"speedup_{key}"] = t1 / w
        info[f"efficiency_{key}"] = t1 / w / P
    for P in (2, 16, 64):
        pr = predict(costs, fixed, per_unit, P, 192)
        info[f"predicted_efficiency_192_at_{P}"] = pr["efficiency"]
    pr2 = predict(costs, fixed, per_unit, 2, N_PROBLEMS)
    info["predicted_speedup_here_at_2"] = pr2["t1"] / pr2["tp"]
    benchmark.extra_info.update(info)
    print(json.dumps(info, indent=1))
    assert all(same.values()), same


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("scaling_batch")
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 192
    make_batch(target, n)
    print(f"wrote {n} problem files to {target}")
