"""The ``optkin`` command: run / validate / show, exit codes, resume, kill -9, jobs, Dask."""

from __future__ import annotations

import csv
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from optkin.cli import main
from optkin.problems.runner import is_complete
from optkin.problems.schema import input_hash

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
#: quick bundled problems (each well under a second)
SMALL = ["four_bar.toml", "five_bar.toml", "rpr3.toml", "rpr3_legs.toml", "stewart_gough.toml"]


def optkin(*args: str, timeout: float = 180) -> subprocess.CompletedProcess:
    """``python -m optkin ARGS`` in a subprocess (stdout is a pipe, not a TTY)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    return subprocess.run([sys.executable, "-m", "optkin", *args], capture_output=True,
                          text=True, timeout=timeout, env=env, cwd=ROOT)


@pytest.fixture
def small(tmp_path: Path) -> Path:
    d = tmp_path / "problems"
    d.mkdir()
    for name in SMALL:
        shutil.copy(PROBLEMS / name, d / name)
    (d / "README.md").write_text("not a problem\n")
    return d


def _results(out: Path) -> dict[str, dict[str, Any]]:
    return {p.name: json.loads(p.read_text()) for p in sorted(out.glob("*.json"))}


def _numbers(node: Any, prefix: str = "") -> dict[str, Any]:
    """The numeric/boolean/string leaves of a result, minus timings and host details."""
    skip = {"time", "elapsed", "started", "stats", "worker", "model_build_time", "solve_time",
            "setup_time", "t_wall_total", "file", "notes", "run_id"}
    out: dict[str, Any] = {}
    if isinstance(node, dict):
        for k, v in node.items():
            if k not in skip:
                out.update(_numbers(v, f"{prefix}.{k}"))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.update(_numbers(v, f"{prefix}[{i}]"))
    elif isinstance(node, str):
        # messages quote residuals such as "max |Phi| = 1.1e-16": compare them with the
        # round-off-level numbers masked (the numbers themselves are compared as floats)
        out[prefix] = re.sub(r"\d\.\d+e-1\d", "<tiny>", node)
    else:
        out[prefix] = node
    return out


def assert_same_results(a: dict[str, dict], b: dict[str, dict]) -> None:
    assert a.keys() == b.keys()
    for name in a:
        na, nb = _numbers(a[name]), _numbers(b[name])
        assert na.keys() == nb.keys(), name
        for k in na:
            x, y = na[k], nb[k]
            if isinstance(x, float) and isinstance(y, float):
                assert math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-9), (name, k, x, y)
            else:
                assert x == y, (name, k, x, y)


# ---------------------------------------------------------------------------
# the README's first command
# ---------------------------------------------------------------------------


def test_bundled_problems_pass_then_resume(tmp_path: Path, capsys) -> None:
    out = tmp_path / "results"
    t0 = time.perf_counter()
    r = optkin("run", "problems/", "--out", str(out), "--jobs", "2")
    first = time.perf_counter() - t0
    assert r.returncode == 0, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    n = len([p for p in PROBLEMS.glob("*.toml")])
    res = _results(out)
    assert len(res) == n
    for name, d in res.items():
        assert d["complete"] is True
        for t in d["tasks"]:
            # an analysis that did not succeed is never "ok" (a track stopped at a
            # singularity is "failed"); it passes when its [expected] block says so
            assert t["passed"] and t["status"] in ("ok", "failed"), (name, t["index"],
                                                                    t["message"])
            if t["status"] == "failed":
                assert t["output"]["success"] is False, (name, t["index"])
            assert t["expected"]["checks"], (name, t["index"])
    pngs = list(out.glob("*.png"))
    if pngs:  # drawing is optional (optkin.plot); when present every task has a picture
        assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in pngs)
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert len(rows) == sum(len(d["tasks"]) for d in res.values())
    assert {r_["passed"] for r_ in rows} == {"True"}
    assert set(rows[0]) == {"problem", "task", "kind", "name", "status", "passed", "time", "message"}
    # the same run again does no work
    mtimes = {p: p.stat().st_mtime_ns for p in out.iterdir()}
    t0 = time.perf_counter()
    assert main(["run", str(PROBLEMS), "--out", str(out)]) == 0
    again = time.perf_counter() - t0
    assert f"0 run, {n} skipped" in capsys.readouterr().out
    for p, m in mtimes.items():
        if p.name != "summary.csv":
            assert p.stat().st_mtime_ns == m, p
    assert again < first


def test_force_redoes_and_changed_input_reruns(small: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    args = ["run", str(small), "--out", str(out), "--no-pictures"]
    assert main(args) == 0
    runs = {p.name: json.loads(p.read_text())["run_id"] for p in out.glob("*.json")}
    assert len(runs) == len(SMALL)
    # an edited file (even a comment) has a new hash: only it reruns
    f = small / "rpr3.toml"
    f.write_text(f.read_text() + "\n# edited\n")
    capsys.readouterr()
    assert main(args) == 0
    assert f"1 run, {len(SMALL) - 1} skipped" in capsys.readouterr().out
    after = {p.name: json.loads(p.read_text())["run_id"] for p in out.glob("*.json")}
    assert [n for n in after if after[n] != runs[n]] == ["rpr3.json"]
    # --force reruns everything
    assert main(args + ["--force"]) == 0
    assert f"{len(SMALL)} run, 0 skipped" in capsys.readouterr().out
    forced = {p.name: json.loads(p.read_text())["run_id"] for p in out.glob("*.json")}
    assert all(forced[n] != after[n] for n in forced)


def test_input_hash_includes_the_optkin_version(monkeypatch) -> None:
    import optkin as ok

    h1 = input_hash(b"schema_version = 1\n")
    monkeypatch.setattr(ok, "__version__", "999.0")
    assert input_hash(b"schema_version = 1\n") != h1


def test_result_json_echoes_inputs_status_numbers_timings(small: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["run", str(small / "five_bar.toml"), "--out", str(out), "--no-pictures"]) == 0
    d = json.loads((out / "five_bar.json").read_text())
    assert d["input"]["mechanism"]["args"]["L0"] == 9.0
    assert d["mechanism"]["kind"] == "legs"
    assert d["input_hash"] == input_hash((small / "five_bar.toml").read_bytes())
    assert is_complete(out / "five_bar.json", d["input_hash"]) is not None
    inv = d["tasks"][0]
    assert inv["kind"] == "inverse" and inv["status"] == "ok" and inv["passed"]
    assert inv["output"]["count"] == 4 and inv["time"] > 0
    assert "stats" in inv["output"]["solutions"][0]
    assert inv["expected"]["source"]
    fwd = d["tasks"][1]
    assert fwd["output"]["success"] is True and "stats" in fwd["output"]


# ---------------------------------------------------------------------------
# exit codes and messages
# ---------------------------------------------------------------------------


def test_missed_expected_gives_exit_1(small: Path, tmp_path: Path, capsys) -> None:
    f = small / "four_bar.toml"
    f.write_text(f.read_text().replace("count = 2", "count = 3"))
    code = main(["run", str(small), "--out", str(tmp_path / "o"), "--no-pictures"])
    assert code == 1
    out = capsys.readouterr().out
    assert "four_bar.toml: task[1] (inverse, rocker at 2 rad): MISSED EXPECTED: expected count = 3, got 2" in out
    rows = list(csv.DictReader((tmp_path / "o" / "summary.csv").open()))
    bad = [r for r in rows if r["passed"] == "False"]
    assert [(r["problem"], r["task"]) for r in bad] == [("four_bar.toml", "1")]


def test_invalid_file_in_a_run_gives_exit_2_and_others_still_run(small: Path, tmp_path: Path) -> None:
    (small / "zz_broken.toml").write_text(
        "schema_version = 1\n[mechanism]\ntype = 'library'\nname = 'five_bar'\n"
        "args = {L0 = 9.0, L1 = 8.0, L2 = 5.0, L3 = 5.0, L4 = 8.0}\n"
        "[[task]]\nkind = 'singular_curves'\n[[task]]\nkind = 'forward'\nqa = [1, 2]\n"
        "[[task]]\nkind = 'singular_curves'\ngrid = -3\n"
    )
    out = tmp_path / "o"
    r = optkin("run", str(small), "--out", str(out), "--no-pictures")
    assert r.returncode == 2
    assert "zz_broken.toml: task[2].grid: expected a positive integer, got -3" in r.stderr
    assert "Traceback" not in r.stderr
    assert len(list(out.glob("*.json"))) == len(SMALL)
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert any(r_["problem"] == "zz_broken.toml" and r_["status"] == "invalid" for r_ in rows)


@pytest.mark.parametrize("argv,needle", [
    (["run", "does/not/exist"], "does/not/exist: (file): no such file or directory"),
    (["validate", "nowhere.toml"], "nowhere.toml: (file): no such file or directory"),
    (["run", "--jobs", "0", "problems"], "expected a positive integer or 'auto', got '0'"),
    (["run", "--jobs", "all", "problems"], "expected a positive integer or 'auto', got 'all'"),
    (["frobnicate"], "invalid choice"),
    (["show", "nowhere.toml"], "nowhere.toml: (file): cannot read"),
])
def test_user_errors_exit_2_without_traceback(argv, needle, capsys) -> None:
    try:
        code = main(argv)
    except SystemExit as e:  # argparse usage errors
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    assert needle in err
    assert "Traceback" not in err


def test_empty_directory_exits_2(tmp_path: Path, capsys) -> None:
    assert main(["run", str(tmp_path), "--out", str(tmp_path / "o")]) == 2
    assert "no problem files" in capsys.readouterr().err


def test_validate_bundled_problems(capsys) -> None:
    assert main(["validate", str(PROBLEMS)]) == 0
    out = capsys.readouterr().out
    assert out.count(": ok (") == len(list(PROBLEMS.glob("*.toml")))


def test_python_m_optkin_and_quiet_progress_when_not_a_tty(small: Path, tmp_path: Path) -> None:
    r = optkin("--version")
    assert r.returncode == 0 and r.stdout.startswith("optkin ")
    r = optkin("run", str(small / "rpr3.toml"), "--out", str(tmp_path / "o"), "--no-pictures")
    assert r.returncode == 0
    assert "%|" not in r.stderr and "problem/s" not in r.stderr  # no tqdm bar in a pipe


def test_quiet_run_prints_the_summary_line_only_and_failures_with_their_reason(tmp_path):
    """``-q``: no progress bar, no third-party banner (HiGHS, IPOPT) on stdout or stderr, the
    summary line alone when every task passes; a failed task is printed with the reason
    Python gives (an unreachable pose names the leg)."""
    statics = [str(PROBLEMS / f"statics_{n}.toml") for n in ("rpr3", "rpr4", "rpr3_mr")]
    r = optkin("run", *statics, "--out", str(tmp_path / "s"), "-q")
    assert r.returncode == 0, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    assert len(lines) == 1 and lines[0].startswith("optkin: 3 problem(s): 3 run"), r.stdout
    assert "3 problem(s)" in lines[0] and r.stderr == "", r.stderr
    bad = tmp_path / "unreachable.toml"
    bad.write_text('schema_version = 1\n[mechanism]\ntype = "library"\nname = "five_bar"\n'
                   'args = { L0 = 1.0, L1 = 1.0, L2 = 1.0, L3 = 1.0, L4 = 1.0 }\n'
                   '[[task]]\nkind = "inverse"\npose = [10.0, 10.0]\n')
    r = optkin("run", str(bad), "--out", str(tmp_path / "u"), "-q")
    assert r.returncode == 1
    assert r.stdout.splitlines()[0] == ("unreachable.toml: task[0] (inverse): FAILED: leg 1 "
                                        "(RRR) cannot reach this pose"), r.stdout
    assert r.stdout.splitlines()[1].startswith("optkin: 1 problem(s)")


def test_show_draws_a_png(tmp_path: Path) -> None:
    png = tmp_path / "five.png"
    assert main(["show", str(PROBLEMS / "five_bar.toml"), "--out", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"


# ---------------------------------------------------------------------------
# safe with data: kill -9 mid-run, then resume
# ---------------------------------------------------------------------------


def test_sigkill_mid_run_leaves_complete_files_and_rerun_finishes(tmp_path: Path, capsys) -> None:
    src = tmp_path / "many"
    src.mkdir()
    names = []
    for i in range(14):
        name = f"p{i:02d}_{SMALL[i % 3]}"
        text = (PROBLEMS / SMALL[i % 3]).read_text() + f"\n# copy {i}\n"
        (src / name).write_text(text)
        names.append(Path(name).stem + ".json")
    out = tmp_path / "out"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "optkin", "run", str(src), "--out", str(out)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=ROOT)
    try:
        deadline = time.time() + 120
        while time.time() < deadline:
            if out.is_dir() and len(list(out.glob("*.json"))) >= 2:
                break
            assert proc.poll() is None, "the run ended before it could be killed"
            time.sleep(0.005)
        assert proc.poll() is None, "the run ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == -signal.SIGKILL
    left = sorted(out.glob("*.json"))
    assert 2 <= len(left) < len(names), "kill the run mid-way"
    for p in left:  # every result file is complete, valid JSON
        d = json.loads(p.read_text())
        assert d["complete"] is True and d["tasks"]
    for p in out.iterdir():  # anything else is a hidden temp file or a finished picture
        assert p.suffix in (".json", ".png", ".tmp"), p
        if p.suffix == ".tmp":
            assert p.name.startswith(".")
    done_before = {p.name for p in left}
    assert main(["run", str(src), "--out", str(out)]) == 0
    assert f"{len(names) - len(done_before)} run, {len(done_before)} skipped" in capsys.readouterr().out
    assert sorted(p.name for p in out.glob("*.json")) == sorted(names)
    assert not list(out.glob(".*.tmp"))
    for p in out.glob("*.json"):
        assert json.loads(p.read_text())["complete"] is True


# ---------------------------------------------------------------------------
# scale out: process pool and Dask
# ---------------------------------------------------------------------------


def test_jobs_auto_is_the_default_and_counts_cpus_files_and_memory(tmp_path, monkeypatch):
    """``--jobs auto`` (the default): one worker per usable CPU, at most one per problem
    file and per WORKER_MEMORY of physical memory."""
    import optkin.cli as cli

    args = cli.build_parser().parse_args(["run", "problems/"])
    assert args.jobs == "auto"
    for i in range(5):
        (tmp_path / f"p{i}.toml").write_text("")
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1, 2, 3}, raising=False)
    page = 4096
    pages = {"SC_PAGE_SIZE": page, "SC_PHYS_PAGES": 64 * 2**30 // page}
    monkeypatch.setattr(os, "sysconf", lambda k: pages[k])
    assert cli.auto_jobs([str(tmp_path)]) == 4  # the CPUs
    assert cli.auto_jobs([str(tmp_path / "p0.toml"), str(tmp_path / "p1.toml")]) == 2  # files
    pages["SC_PHYS_PAGES"] = int(1.5 * cli.WORKER_MEMORY) // page
    assert cli.auto_jobs([str(tmp_path)]) == 1  # memory for one worker only


def test_jobs_2_gives_the_same_results_as_jobs_1(small: Path, tmp_path: Path) -> None:
    for jobs in ("1", "2"):
        args = ["run", str(small), "--out", str(tmp_path / f"j{jobs}"), "--no-pictures"]
        assert main(args + ["--jobs", jobs]) == 0
    a, b = _results(tmp_path / "j1"), _results(tmp_path / "j2")
    assert_same_results(a, b)
    assert os.getpid() not in {d["worker"]["pid"] for d in b.values()}  # ran in workers
    s1 = [(r["problem"], r["task"], r["status"], r["passed"])
          for r in csv.DictReader((tmp_path / "j1" / "summary.csv").open())]
    s2 = [(r["problem"], r["task"], r["status"], r["passed"])
          for r in csv.DictReader((tmp_path / "j2" / "summary.csv").open())]
    assert s1 == s2


def test_dask_local_cluster_gives_the_same_results(small: Path, tmp_path: Path) -> None:
    import distributed  # the test extra installs it (dask[distributed])
    assert main(["run", str(small), "--out", str(tmp_path / "serial"), "--no-pictures"]) == 0
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        code = main(["run", str(small), "--out", str(tmp_path / "dask"), "--no-pictures",
                     "--scheduler", cluster.scheduler_address])
    assert code == 0
    assert_same_results(_results(tmp_path / "serial"), _results(tmp_path / "dask"))


def test_dask_workers_get_a_quiet_profiler_and_a_slow_tick(small: Path, tmp_path: Path) -> None:
    """The plugin a run registers stops the Dask worker's profiler and slows its 20 ms
    event-loop tick (optkin's work runs in processes of its own, nothing of it blocks the
    loop): measured, an idle Dask worker's CPU falls from 2.1-2.3 % to 0.8-0.9 %."""
    import distributed

    from optkin.problems.dask_worker import TICK_MS

    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        (w,) = cluster.workers.values()
        pcs = w.periodic_callbacks
        if pcs["tick"].callback_time >= TICK_MS:
            pytest.skip("this Dask's configured tick is already slow")
        assert "profile" in pcs
        code = main(["run", str(small), "--out", str(tmp_path / "dask"), "--no-pictures",
                     "--scheduler", cluster.scheduler_address])
        assert code == 0
        assert "profile" not in pcs and "profile-cycle" not in pcs
        assert pcs["tick"].callback_time == TICK_MS and pcs["tick"].is_running()


def test_dask_tasks_of_several_units_fail_only_the_bad_unit(small: Path, tmp_path: Path,
                                                            monkeypatch) -> None:
    """Consecutive cheap units share a Dask task: an invalid problem and a task past its
    time limit among them fail alone, the others are written as in a serial run."""
    import distributed

    from optkin.problems import runner

    seen = []
    batches = runner._dask_batches
    monkeypatch.setattr(runner, "DASK_TASK_COST", 100.0)  # everything shareable
    monkeypatch.setattr(runner, "_dask_batches",
                        lambda jobs, slots: seen.append(b := batches(jobs, 1)) or b)
    (small / "zz_bad.toml").write_text('schema_version = 1\nname = "bad"\n[mechanism]\n'
                                       'type = "library"\nname = "no_such_mechanism"\n'
                                       '[[task]]\nkind = "forward"\nqa = [1.0]\n')
    # aspects at step 0.01 take about 2 s here, far past the 0.02 s limit and the 0.5 s of
    # grace before the worker is killed (at the default step, 0.45-0.5 s: they could end
    # within the grace, and did on a fast day)
    (small / "zz_slow.toml").write_text(
        'schema_version = 1\nname = "slow"\n[mechanism]\ntype = "library"\n'
        'name = "five_bar"\nargs = { L0 = 8.0, L1 = 7.0, L2 = 5.0, L3 = 5.0, L4 = 7.0 }\n'
        '[[task]]\nkind = "aspects"\ntime_limit = 0.02\noptions = { step = 0.01 }\n'
        '[[task]]\nkind = "forward"\nqa = [1.0, 2.0]\n')
    assert main(["run", str(small), "--out", str(tmp_path / "serial"), "--no-pictures"]) == 2
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster:
        code = main(["run", str(small), "--out", str(tmp_path / "dask"), "--no-pictures",
                     "--scheduler", cluster.scheduler_address])
    assert code == 2  # the invalid file
    assert seen and max(len(b) for b in seen[0]) > 1  # units did share a task
    serial, dask = _results(tmp_path / "serial"), _results(tmp_path / "dask")
    assert sorted(dask) == sorted(serial) and "zz_bad.json" not in dask
    slow = dask["zz_slow.json"]["tasks"]
    assert slow[0]["status"] == "error" and "time limit" in slow[0]["message"]
    assert slow[1]["status"] == "ok"  # the problem's next task, in a fresh worker
    assert_same_results(serial, dask)


@pytest.mark.slow  # waits for the connection timeout
def test_dask_unreachable_scheduler_is_a_user_error(small: Path, tmp_path: Path, capsys) -> None:
    code = main(["run", str(small / "rpr3.toml"), "--out", str(tmp_path / "o"),
                 "--scheduler", "tcp://127.0.0.1:9"])
    assert code == 2
    assert "--scheduler: cannot connect" in capsys.readouterr().err


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="pty with a window size")
def test_progress_bar_on_a_terminal(small: Path, tmp_path: Path) -> None:
    import fcntl
    import pty
    import struct
    import termios

    argv = [sys.executable, "-m", "optkin", "run", str(small / "rpr3.toml"),
            str(small / "four_bar.toml"), "--out", str(tmp_path / "o"), "--no-pictures"]
    pid, fd = pty.fork()
    if pid == 0:  # child: a 100-column terminal
        fcntl.ioctl(1, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 100, 0, 0))
        os.chdir(ROOT)
        os.execv(sys.executable, argv)
    out = b""
    while True:
        try:
            chunk = os.read(fd, 4096)
        except OSError:
            break
        if not chunk:
            break
        out += chunk
    _, status = os.waitpid(pid, 0)
    text = out.decode(errors="replace")
    assert os.waitstatus_to_exitcode(status) == 0, text
    # the tqdm bar, drawn at least once (a fast run may end before it redraws at 2/2)
    assert re.search(r"[0-2]/2 \[", text) and "problem" in text, text
    # the bar names the problem in flight (the worker protocol reports each start)
    assert re.search(r"problem.*(rpr3|four_bar)\.toml", text), text
    assert "4/4 task(s) passed" in text


def test_schema_validates_every_bundled_problem_and_refuses_broken_ones(tmp_path: Path) -> None:
    """``optkin schema``: a JSON Schema (draft 2020-12) that a standard validator
    (jsonschema, as editors use) accepts every bundled problem file with, and that refuses
    an unknown key, a task of no known kind and a mistyped value; ``--out`` writes it."""
    import jsonschema
    import tomllib

    p = optkin("schema")
    assert p.returncode == 0, p.stderr
    sch = json.loads(p.stdout)
    jsonschema.Draft202012Validator.check_schema(sch)
    V = jsonschema.Draft202012Validator(sch)
    files = sorted((ROOT / "problems").glob("*.toml"))
    assert len(files) >= 30
    for f in files:
        errs = [e.message for e in V.iter_errors(tomllib.loads(f.read_text()))]
        assert not errs, (f.name, errs[:2])
    good = tomllib.loads((ROOT / "problems" / "rpr3.toml").read_text())
    for broken in ({**good, "mechanizm": good["mechanism"]},
                   {**good, "task": [{"kind": "fly", "qa": [1, 2, 3]}]},
                   {**good, "schema_version": "one"}):
        assert list(V.iter_errors(broken)), broken
    out = tmp_path / "problem.schema.json"
    assert optkin("schema", "--out", str(out)).returncode == 0
    assert json.loads(out.read_text()) == sch
