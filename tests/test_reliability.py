"""The batch runner under attack: nothing hangs, aborts, collides or gets lost.

Each test is built from a reproduction of the reliability issue (findings B1-B16, copies
in tests/data/repro/); the finding is named in the test's docstring.
"""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import socket
import stat
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from optkin.cli import main
from optkin.problems import runner as rn
from optkin.problems import workers as wk
from optkin.problems.schema import parse_toml

ROOT = Path(__file__).resolve().parents[1]
PROBLEMS = ROOT / "problems"
REPRO = Path(__file__).resolve().parent / "data" / "repro"
SMALL = ["four_bar.toml", "five_bar.toml", "rpr3.toml"]
#: the malformed reproductions and what the run must say about each
MALFORMED = {
    "deep_array.toml": "nested more than",
    "expr_recursion.toml": "mechanism.rows[1].d",
    "hugeint.toml": "task[0].pose[0]",
    "hugeint5000.toml": "5000 digits",
    "jacobians_hang.toml": "platform points coincide",
}
#: reproductions whose file is valid but whose task must fail fast with a clear error
TASK_ERRORS = {"grid_unbounded.toml": "grid"}


def optkin(*args: str, cwd: Path = ROOT, timeout: float = 300, env: dict | None = None
           ) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "optkin", *args], capture_output=True,
                          text=True, timeout=timeout, cwd=cwd,
                          env=dict(os.environ, PYTHONUNBUFFERED="1", **(env or {})))


def summary(out: Path) -> list[dict[str, str]]:
    return list(csv.DictReader((out / "summary.csv").open()))


def results(out: Path) -> dict[str, dict]:
    return {p.name: json.loads(p.read_text()) for p in sorted(out.rglob("*.json"))}


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


FIVE_BAR = """schema_version = 1
[mechanism]
type = "library"
name = "five_bar"
args = { L0 = 9.0, L1 = 8.0, L2 = 5.0, L3 = 5.0, L4 = 8.0 }
"""
RPR3 = """schema_version = 1
[mechanism]
type = "library"
name = "rpr3"
args = { base = [[0.0, 0.0], [4.0, 0.0], [0.0, 3.0]], platform = [[-0.5, -0.3], [0.5, -0.3], [0.0, 0.4]] }
"""
#: a task that takes a few seconds (a 6-6 platform, every start of a large budget)
SLOW_TASK = """
[[task]]
kind = "assembly_modes"
qa = [1.2, 1.25, 1.3, 1.2, 1.25, 1.3]
options = { starts = 200000, min_starts = 200000, target = 0.0, time_limit = 600.0 }
"""
STEWART = (PROBLEMS / "stewart_gough.toml").read_text().split("[[task]]")[0]


def _same_numbers(a: dict, b: dict) -> None:
    """Two results of one problem agree on every task's status and output."""
    assert [t["status"] for t in a["tasks"]] == [t["status"] for t in b["tasks"]]
    for ta, tb in zip(a["tasks"], b["tasks"]):
        assert ta["passed"] == tb["passed"]
        oa, ob = ta["output"] or {}, tb["output"] or {}
        for key in ("q", "qa", "pose", "count", "success"):
            if key in oa:
                assert json.dumps(oa[key]) == json.dumps(ob[key]), key


# ---------------------------------------------------------------------------
# B2 / the done-when run: bad files fail alone, the others equal a clean run
# ---------------------------------------------------------------------------


def test_malformed_files_fail_alone_and_good_results_equal_a_clean_run(tmp_path: Path) -> None:
    """B2, B8, B9, B15, B16: a folder of good problems plus every malformed reproduction
    finishes with exit 2, writes summary.csv, and the good results equal a clean run's."""
    good = tmp_path / "good"
    mixed = tmp_path / "mixed"
    for name in SMALL:
        write(good / name, (PROBLEMS / name).read_text())
        write(mixed / name, (PROBLEMS / name).read_text())
    for name in [*MALFORMED, *TASK_ERRORS]:
        shutil.copy(REPRO / name, mixed / name)
    shutil.copy(REPRO / "expr_abort_run" / "b_bad.toml", mixed / "b_bad.toml")
    write(mixed / "minus.toml",  # "-" * 100000 + "1": a MemoryError in the parser before
          'schema_version = 1\n[mechanism]\ntype = "khalil"\nloops = 0\nrows = [\n'
          '  { a = 0, mu = 1, sigma = 0, theta = "t1", d = "' + "-" * 100000 + '1" },\n]\n'
          '[[task]]\nkind = "dof"\n')
    write(mixed / "dots.toml", "schema_version = 1\nx" + ".x" * 20000 + " = 1\n")
    clean = optkin("run", str(good), "--out", str(tmp_path / "clean"), "--no-pictures")
    assert clean.returncode == 0, clean.stdout + clean.stderr
    t0 = time.perf_counter()
    r = optkin("run", str(mixed), "--out", str(tmp_path / "out"), "--no-pictures", "--jobs", "2")
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stdout + r.stderr
    assert time.perf_counter() - t0 < 120
    rows = summary(tmp_path / "out")
    by_problem = {}
    for row in rows:
        by_problem.setdefault(row["problem"], []).append(row)
    for name, needle in {**MALFORMED, "b_bad.toml": "mechanism.rows[1].d",
                         "minus.toml": "mechanism.rows[0].d",
                         "dots.toml": "dotted parts"}.items():
        assert name in by_problem, name
        assert by_problem[name][0]["status"] == "invalid", (name, by_problem[name])
        assert needle in by_problem[name][0]["message"], (name, by_problem[name][0]["message"])
    for name, needle in TASK_ERRORS.items():
        (row,) = by_problem[name]
        assert row["status"] == "error" and needle in row["message"], row
    a, b = results(tmp_path / "clean"), results(tmp_path / "out")
    for name in SMALL:
        key = name.replace(".toml", ".json")
        _same_numbers(a[key], b[key])


# ---------------------------------------------------------------------------
# bounded work: time limits
# ---------------------------------------------------------------------------


def test_a_task_past_its_time_limit_is_abandoned_and_the_rest_runs(tmp_path: Path) -> None:
    """B1: every task runs under a wall-time limit; a task past it is abandoned and
    reported as an error, its problem's other tasks and the other problems still run."""
    src = tmp_path / "p"
    text = STEWART + SLOW_TASK.replace("options = {", "time_limit = 0.5\noptions = {") + \
        '\n[[task]]\nkind = "dof"\n'
    write(src / "slow.toml", text)
    shutil.copy(PROBLEMS / "four_bar.toml", src / "four_bar.toml")
    t0 = time.perf_counter()
    report = rn.run_paths([src], out=tmp_path / "out", pictures=False)
    assert time.perf_counter() - t0 < 60
    res = report.results["slow.toml"]
    first, second = res["tasks"]
    assert first["status"] == "error" and first["abandoned"] is True
    assert "time limit of 0.5 s exceeded" in first["message"]
    assert second["status"] == "ok"  # the next task ran in a fresh worker
    assert res["complete"] is False  # so a rerun tries the abandoned task again
    assert all(t["status"] == "ok" for t in report.results["four_bar.toml"]["tasks"])
    assert report.exit_code == 1


def _busy_worker(problem: str | None = None, timeout: float = 60.0,
                 task: int | None = None) -> int | None:
    """The pid of a worker of this process that is running a task (of ``problem``; the
    task of index ``task``: with several workers the tasks of a problem may run apart)."""
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < timeout:
        for w in list(wk._LIVE):
            job = w.job
            # a live worker of a run in flight only: a dead worker object may keep its
            # task, and its pid may since belong to another process (pid_max is 32768)
            if w.dead or w.proc.poll() is not None:
                continue
            if w.task is not None and job is not None and (
                    problem is None or job.key.split("#")[0] == problem) and (
                    task is None or w.task == task):
                return w.proc.pid
        time.sleep(0.02)
    return None


def test_a_frozen_worker_cannot_hold_the_run(tmp_path: Path) -> None:
    """B1: a worker stuck where no signal handler runs (here: SIGSTOP, as a native call
    that never returns) is killed at the deadline; the run finishes."""
    src = tmp_path / "p"
    write(src / "slow.toml", STEWART + SLOW_TASK)
    box: dict = {}
    t = threading.Thread(target=lambda: box.update(r=rn.run_paths(
        [src], out=tmp_path / "out", pictures=False, time_limit=3.0)))
    t.start()
    pid = _busy_worker()
    assert pid is not None, "no worker ran the task"
    time.sleep(0.3)
    os.kill(pid, signal.SIGSTOP)
    t.join(90)
    assert not t.is_alive(), "the run did not finish"
    task = box["r"].results["slow.toml"]["tasks"][0]
    assert task["status"] == "error" and "time limit of 3 s exceeded" in task["message"]


def test_task_time_limit_is_validated(tmp_path: Path, capsys) -> None:
    p = write(tmp_path / "t.toml", FIVE_BAR + '[[task]]\nkind = "dof"\ntime_limit = -1\n')
    assert main(["validate", str(p)]) == 2
    assert "task[0].time_limit: expected a positive number" in capsys.readouterr().err
    p = write(tmp_path / "t.toml", FIVE_BAR + '[[task]]\nkind = "dof"\ntime_limit = 1e9\n')
    assert main(["validate", str(p)]) == 2
    assert "at most 86400 seconds" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# isolation: dead workers, the working directory, the parent's optkin
# ---------------------------------------------------------------------------


def test_a_killed_worker_loses_at_most_the_task_it_held(tmp_path: Path) -> None:
    """B6: kill -9 one pool worker during --jobs 2 (what the OOM killer does): only the
    task it was running is lost; every other problem and task completes."""
    src = tmp_path / "p"
    write(src / "a_slow.toml", STEWART + SLOW_TASK + '\n[[task]]\nkind = "dof"\n')
    for i in range(6):
        shutil.copy(PROBLEMS / SMALL[i % 3], src / f"b{i}_{SMALL[i % 3]}")
    box: dict = {}
    t = threading.Thread(target=lambda: box.update(r=rn.run_paths(
        [src], out=tmp_path / "out", pictures=False, jobs=2)))
    t.start()
    killed = _busy_worker("a_slow.toml", task=0)
    assert killed is not None, "no worker ran the slow task"
    time.sleep(0.5)
    os.kill(killed, signal.SIGKILL)
    t.join(120)
    assert not t.is_alive()
    r = box["r"]
    assert not r.crashed, r.crashed
    lost = [(name, t_["index"]) for name, t_ in r.tasks if t_["status"] != "ok"]
    assert len(lost) <= 1, lost
    assert len(r.results) == 7
    for name, res in r.results.items():
        if name != "a_slow.toml":
            assert all(t_["status"] == "ok" for t_ in res["tasks"]), name
    slow = r.results["a_slow.toml"]["tasks"]
    assert slow[1]["status"] == "ok"  # the task after the lost one still ran
    if lost:
        assert "SIGKILL" in slow[0]["message"]


def test_workers_import_this_optkin_whatever_the_working_directory(tmp_path: Path) -> None:
    """B4: with an optkin/ folder in the working directory (here the --out folder itself),
    --jobs 2 workers still import the installed optkin and every task runs."""
    cwd = tmp_path / "cwd"
    (cwd / "optkin").mkdir(parents=True)
    (cwd / "optkin" / "__init__.py").write_text("raise ImportError('the wrong optkin')\n")
    script = Path(sys.executable).with_name("optkin")  # the console script, as a user runs it
    if not script.exists():
        pytest.skip("the optkin console script is not installed beside this python")
    r = subprocess.run([str(script), "run", str(PROBLEMS / "rpr3.toml"),
                        str(PROBLEMS / "four_bar.toml"), "--out", "optkin", "--jobs", "2",
                        "--no-pictures"], capture_output=True, text=True, timeout=300, cwd=cwd)
    assert r.returncode == 0, r.stdout + r.stderr
    assert {row["status"] for row in summary(cwd / "optkin")} == {"ok"}


# ---------------------------------------------------------------------------
# results: names, NaN, success, permissions, temp files, the summary
# ---------------------------------------------------------------------------


def test_dotted_names_do_not_collide(tmp_path: Path) -> None:
    """B5: a.toml and a.v2.toml write a.json and a.v2.json; a rerun skips both."""
    out = tmp_path / "out"
    report = rn.run_paths([REPRO / "collide"], out=out, pictures=False)
    assert sorted(p.name for p in out.glob("*.json")) == ["a.json", "a.v2.json"]
    assert report.exit_code == 0
    again = rn.run_paths([REPRO / "collide"], out=out, pictures=False)
    assert sorted(again.skipped) == ["a.toml", "a.v2.toml"] and not again.ran


def test_two_files_with_one_result_path_are_refused_before_any_work(tmp_path: Path) -> None:
    a = write(tmp_path / "x" / "p.toml", (PROBLEMS / "rpr3.toml").read_text())
    b = write(tmp_path / "y" / "p.toml", (PROBLEMS / "four_bar.toml").read_text())
    out = tmp_path / "out"
    with pytest.raises(rn.ProblemFileError, match="would collide with those of"):
        rn.run_paths([a.parent, b.parent], out=out)
    assert not out.exists()


def test_a_non_finite_number_in_one_task_loses_nothing(tmp_path: Path, monkeypatch) -> None:
    """B8: NaN or inf in one task's output become null; the problem's JSON is written
    with every other task's result."""
    from optkin.problems import tasks as tk
    from optkin.problems.schema import load_problem

    real = tk.TASKS["inverse"]

    def with_nan(mech, task, ctx):
        out = real(mech, task, ctx)
        out["odd"] = [float("nan"), float("inf"), {"deep": float("-inf")}]
        return out

    monkeypatch.setitem(tk.TASKS, "inverse", with_nan)
    p = load_problem(PROBLEMS / "rpr3.toml")
    res = rn.run_problem(p)
    text = json.dumps(res, allow_nan=False)  # strict JSON
    assert [t["status"] for t in res["tasks"]] == ["ok", "ok"]
    assert res["tasks"][0]["output"]["odd"] == [None, None, {"deep": None}]
    assert "NaN" not in text and "Infinity" not in text


def test_unsuccessful_analysis_is_never_ok(tmp_path: Path) -> None:
    """B12: assembly_modes that finds no mode is 'failed', not 'ok'."""
    report = rn.run_paths([REPRO / "assembly_modes_none_ok.toml"], out=tmp_path / "o",
                          pictures=False)
    statuses = [t["status"] for _, t in report.tasks]
    assert statuses == ["failed", "failed"]
    assert report.exit_code == 1


def test_result_files_honour_the_umask(tmp_path: Path) -> None:
    """Lesser: result files were created 0600; now 0666 minus the umask."""
    old = os.umask(0o022)
    try:
        rn._UMASK.clear()
        rn.run_paths([PROBLEMS / "four_bar.toml"], out=tmp_path / "o")
    finally:
        os.umask(old)
        rn._UMASK.clear()
    files = list((tmp_path / "o").iterdir())
    assert {p.suffix for p in files} >= {".json", ".csv", ".png"}
    for p in files:
        assert stat.S_IMODE(p.stat().st_mode) == 0o644, p


def test_stale_temp_cleaner_removes_only_its_own_stale_files(tmp_path: Path) -> None:
    """B13: the user's hidden *.tmp files survive; only optkin's temp files of dead
    processes (or very old ones) are removed, never another live run's."""
    out = tmp_path / "out"
    user = [write(out / ".bash_history.tmp", "important"),
            write(out / "project" / ".draft.tmp", "work")]
    host = rn.platform.node() or "host"
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    mine_dead = write(out / f"{rn.TEMP_PREFIX}{host}.{dead.pid}.abc123.tmp", "x")
    live = write(out / "sub" / f"{rn.TEMP_PREFIX}{host}.{os.getpid()}.def456.tmp", "x")
    other_host = write(out / f"{rn.TEMP_PREFIX}elsewhere.example.7.ghi789.tmp", "x")
    old_other = write(out / f"{rn.TEMP_PREFIX}elsewhere.example.8.jkl000.tmp", "x")
    ancient = time.time() - rn.STALE_AFTER - 60
    os.utime(old_other, (ancient, ancient))
    rn.run_paths([PROBLEMS / "four_bar.toml"], out=out, pictures=False)
    for p in user + [live, other_host]:
        assert p.exists(), p
    assert not mine_dead.exists() and not old_other.exists()


def test_summary_cells_are_not_spreadsheet_formulas(tmp_path: Path) -> None:
    """Lesser: a task name or message starting with = + - @ is prefixed with '."""
    p = write(tmp_path / "p" / "f.toml", FIVE_BAR + '[[task]]\nkind = "dof"\n'
              'name = "=HYPERLINK(\\"http://x\\")"\n')
    rn.run_paths([p.parent], out=tmp_path / "o", pictures=False)
    row = summary(tmp_path / "o")[0]
    assert row["name"].startswith("'=HYPERLINK")


# ---------------------------------------------------------------------------
# problem files: parser bounds, tables of joint values, validate = run's checks
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("text, needle", [
    ("schema_version = 1\nx = " + "[" * 400 + "]" * 400 + "\n", "nested more than"),
    ("schema_version = 1\nx" + ".x" * 20000 + " = 1\n", "dotted parts"),
    ("schema_version = 1\n[x" + ".x" * 20000 + "]\n", "dotted parts"),
    ("schema_version = 1\nx = " + "9" * 5000 + "\n", "5000 digits"),
    ("schema_version = 1\nx = " + "9" * 390 + "\n", None),  # parses; the schema refuses it
])
def test_parser_inputs_are_bounded_before_parsing(text: str, needle: str | None) -> None:
    """B2 and lesser: TOML nested 400 deep, a key of 20000 dotted parts (1.7 GB in tomllib)
    and huge integer literals are refused quickly, before the parser sees them."""
    import resource

    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    if needle is None:
        parse_toml(text.encode(), "x.toml")
    else:
        with pytest.raises(rn.ProblemFileError, match=needle):
            parse_toml(text.encode(), "x.toml")
    assert time.perf_counter() - t0 < 1.0
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 100_000  # KB


def test_numbers_beyond_float_range_name_their_key(tmp_path: Path, capsys) -> None:
    """B2: an integer literal beyond float range is the file's error, with its key path."""
    assert main(["validate", str(REPRO / "hugeint.toml")]) == 2
    err = capsys.readouterr().err
    assert "hugeint.toml: task[0].pose[0]: expected a number of magnitude at most" in err


def test_guess_table_by_joint_name(tmp_path: Path, capsys) -> None:
    """B11: a guess table keyed by joint names works in run and show (no IndexError);
    joints it does not name take their home values; unknown names are errors."""
    out = tmp_path / "o"
    report = rn.run_paths([REPRO / "guess_table.toml"], out=out, pictures=False)
    (task,) = report.results["guess_table.toml"]["tasks"]
    assert task["status"] == "ok", task["message"]
    assert main(["show", str(REPRO / "guess_table.toml"), "-o", str(tmp_path / "s.png")]) == 0
    assert (tmp_path / "s.png").exists()
    bad = write(tmp_path / "b.toml", FIVE_BAR + '[[task]]\nkind = "forward"\nqa = [1.2, 1.9]\n'
                'guess = { "L1.theta9" = 0.05 }\n')
    assert main(["validate", str(bad)]) == 2
    assert "task[0].guess['L1.theta9']: unknown joint 'L1.theta9'" in capsys.readouterr().err


B16_CASES = {
    "guess_length": (FIVE_BAR + '[[task]]\nkind = "forward"\nqa = [1.2, 1.9]\n'
                     "guess = [1.0, 2.0, 3.0]\n", "task[0]", "guess"),
    "reversed_bounds": (FIVE_BAR + '[[task]]\nkind = "aspects"\n'
                        "bounds = [[5.0, 1.0], [0.0, 9.0]]\n", "task[0].bounds[0]", "low < high"),
    "plane_name": (FIVE_BAR + '[[task]]\nkind = "singular_curves"\nplane = ["foo", "bar"]\n',
                   "task[0]", "foo"),
    "curve_name": (FIVE_BAR + '[[task]]\nkind = "singular_curves"\ncurves = "paralel"\n',
                   "task[0]", "paralel"),
    "statics_sizes": (RPR3 + '[[task]]\nkind = "statics"\npose = [1.6, 1.2, 0.3]\n'
                      "limits = [1.0, 1.0]\n", "task[0]", "limits"),
    "posture": (RPR3 + '[[task]]\nkind = "statics"\npose = [1.6, 1.2, 0.3]\nposture = 5\n'
                "limits = 1.0\n", "task[0].posture", "no posture 5"),
    "rigid_pose": (RPR3 + '[[task]]\nkind = "inverse"\npose = [[2.0, 0.0, 0.0, 1.6], '
                   "[0.0, 1.0, 0.0, 1.2], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]\n",
                   "task[0].pose", "rigid transform"),
    "option_typo": (FIVE_BAR + '[[task]]\nkind = "forward"\nqa = [1.2, 1.9]\n'
                    "options = { tool = 1e-9 }\n", "task[0].options.tool",
                    "did you mean 'tol'"),
}


@pytest.mark.parametrize("case", sorted(B16_CASES))
def test_validate_runs_every_check_run_makes(case: str, tmp_path: Path, capsys) -> None:
    """B16: files that failed at run time now fail `optkin validate` (exit 2, key path),
    and `optkin run` reports the same error for the task."""
    text, where, needle = B16_CASES[case]
    p = write(tmp_path / "p" / f"{case}.toml", text)
    assert main(["validate", str(p)]) == 2
    err = capsys.readouterr().err
    assert f"{case}.toml: {where}" in err and needle in err, err
    report = rn.run_paths([p.parent], out=tmp_path / "o", pictures=False)
    msgs = list(report.invalid.values()) + [t["message"] for _, t in report.tasks]
    assert report.exit_code in (1, 2) and any(needle in m for m in msgs), msgs


def test_validate_accepts_the_bundled_problems(capsys) -> None:
    assert main(["validate", str(PROBLEMS)]) == 0
    assert capsys.readouterr().out.count(": ok (") == len(list(PROBLEMS.glob("*.toml")))


# ---------------------------------------------------------------------------
# --scheduler that is not Dask; Ctrl-C
# ---------------------------------------------------------------------------


def _serve(banner: bytes | None) -> tuple[socket.socket, threading.Thread]:
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", 0))
    srv.listen(8)
    conns = []

    def loop() -> None:
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            conns.append(c)  # keep it open, say nothing more
            if banner:
                c.sendall(banner)

    t = threading.Thread(target=loop, daemon=True)
    t.start()
    return srv, t


@pytest.mark.parametrize("banner", [b"SSH-2.0-OpenSSH_9.6\r\n", None])
def test_scheduler_that_is_not_dask_is_a_quick_user_error(banner, tmp_path: Path, capsys,
                                                          monkeypatch) -> None:
    """B14: a service that sends a banner (a 2.8 EiB frame length) or keeps the connection
    open without answering gives exit 2 with one line, within the connect timeout."""
    from optkin.problems import dask_client

    monkeypatch.setattr(dask_client, "DASK_CONNECT_TIMEOUT", 2.0)
    srv, _ = _serve(banner)
    try:
        t0 = time.perf_counter()
        code = main(["run", str(PROBLEMS / "four_bar.toml"), "--out", str(tmp_path / "o"),
                     "--scheduler", f"tcp://127.0.0.1:{srv.getsockname()[1]}"])
        elapsed = time.perf_counter() - t0
    finally:
        srv.close()
    err = capsys.readouterr().err
    assert code == 2, err
    assert "--scheduler: cannot connect" in err and "Traceback" not in err
    assert elapsed < 2.0 + 5.0 + 3.0


def test_ctrl_c_at_any_moment_prints_no_traceback(tmp_path: Path) -> None:
    """Lesser: Ctrl-C during start-up (imports) or the run ends without a traceback.

    (Within the first tenth of a second Python itself is still starting: a Ctrl-C there
    is the interpreter's, before any optkin code runs.)"""
    for delay in (0.25, 0.6, 1.2, 2.5):
        p = subprocess.Popen([sys.executable, "-m", "optkin", "run", str(PROBLEMS / "rpr3.toml"),
                              "--out", str(tmp_path / f"o{delay}")], cwd=ROOT,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=60)
        # on a loaded machine the first delay may still fall in Python's own start-up
        # (runpy, the standard library), before any optkin code: no frame of optkin's then
        optkin_frames = re.findall(r'File "[^"]*[/\\]optkin[/\\][^"]*"', err)
        if "Traceback" in err:
            assert delay < 0.5 and not optkin_frames, (delay, err)
            continue
        assert p.returncode in (0, 130, -signal.SIGINT), (delay, p.returncode, err)


def test_idle_workers_are_reused_and_closed(tmp_path: Path) -> None:
    rn.run_paths([PROBLEMS / "four_bar.toml"], out=tmp_path / "a", pictures=False)
    first = {w.proc.pid for pool in wk._IDLE.values() for w in pool}
    rn.run_paths([PROBLEMS / "four_bar.toml"], out=tmp_path / "b", pictures=False, force=True)
    second = {w.proc.pid for pool in wk._IDLE.values() for w in pool}
    assert first and first == second
    wk._close_idle()
    assert not wk._IDLE


# ---------------------------------------------------------------------------
# fuzz: mutated bundled problems, run end to end
# ---------------------------------------------------------------------------

_JUNK = [10**400 // 10**200, -1, 0, 1e150, -1e149, 3.5, 1e-300, "x", "pi/0", "", True, [],
         [1.0] * 40, [[1.0, 2.0]] * 3, {"a": 1.0}, 2**62, 10**6]


_NUMBERS = [1e150, -1e149, 0.0, -1.0, 1e-300, 3.5, 1e6, 1e100, -7.25, 2.0**62]


def _get(doc, path):
    for k in path:
        doc = doc[k]
    return doc


def _mutations():
    import tomllib
    from hypothesis import strategies as st

    docs = [tomllib.loads((PROBLEMS / n).read_text())
            for n in ("five_bar.toml", "rpr3.toml", "four_bar.toml", "statics_rpr3.toml",
                      "five_bar_aspects.toml", "assembly_modes_rpr3.toml", "sr400_table.toml")]

    def leaves(node, prefix=()):
        out = [prefix] if prefix else []
        if isinstance(node, dict):
            for k, v in node.items():
                out += leaves(v, prefix + (k,))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                out += leaves(v, prefix + (i,))
        return out

    @st.composite
    def mutated(draw):
        import copy

        doc = copy.deepcopy(draw(st.sampled_from(docs)))
        numeric_only = draw(st.booleans())  # half the time: files the schema accepts
        for _ in range(draw(st.integers(1, 3))):
            paths = [p for p in leaves(doc) if p and p[0] != "schema_version"]
            if numeric_only:
                paths = [p for p in paths if isinstance(_get(doc, p), float)]
            if not paths:
                break
            path = draw(st.sampled_from(paths))
            node = _get(doc, path[:-1])
            junk = _NUMBERS if numeric_only else _JUNK
            node[path[-1]] = copy.deepcopy(draw(st.sampled_from(junk)))  # no shared lists
        return doc

    return mutated()


def _fuzz_runs(n_examples: int, tmp_path_factory) -> None:
    from hypothesis import HealthCheck, given, settings
    from test_problems import to_toml

    @settings(max_examples=n_examples, deadline=None, derandomize=True,
              suppress_health_check=list(HealthCheck))
    @given(_mutations())
    def run_one(doc):
        d = tmp_path_factory.mktemp("fuzz")
        try:
            text = to_toml(doc)
        except (TypeError, ValueError):  # not representable as TOML: nothing to run
            return
        (d / "p" ).mkdir()
        (d / "p" / "m.toml").write_text(text)
        t0 = time.perf_counter()
        report = rn.run_paths([d / "p"], out=d / "o", pictures=False, time_limit=30.0)
        assert time.perf_counter() - t0 < 120
        assert not report.crashed, report.crashed  # only the file's or a task's own errors
        assert (d / "o" / "summary.csv").exists()
        for _, t in report.tasks:
            assert t["status"] in ("ok", "failed", "error"), t
            if t["status"] == "error":  # our errors, never an unexpected exception
                assert t["message"].split(":")[0] in (
                    "MechanismError", "StaticsError", "NumericError", "ValueError",
                    "ProblemFileError") or "time limit" in t["message"], t["message"]
        for msg in report.invalid.values():
            assert msg.startswith("m.toml: "), msg

    run_one()


def test_fuzz_problem_files_end_to_end(tmp_path_factory) -> None:
    """Mutated bundled problems (huge, tiny, wrong-typed values anywhere) run through the
    workers: only the file's own error or task errors of the project's kinds, no crash of
    the run, every call within its time bound."""
    _fuzz_runs(12, tmp_path_factory)


@pytest.mark.slow
def test_fuzz_problem_files_end_to_end_slow(tmp_path_factory) -> None:
    _fuzz_runs(200, tmp_path_factory)


def test_partial_q_table_of_a_leg_mechanism() -> None:
    """A q table naming some joints of a leg mechanism (whose home is task coordinates)
    took the others from the home pose's numbers (IndexError); now from its configuration.
    (Problem files must name every joint of q; the task layer is also used directly.)"""
    from optkin import mechanisms as lib
    from optkin.problems.tasks import _q_of

    m = lib.five_bar(9.0, 8.0, 5.0, 5.0, 8.0)

    class Task:
        q = {"L1.theta1": 1.2}
        qa = None

    q = _q_of(m, Task(), None)
    assert len(q) == len(m.joint_names) and q[0] == 1.2
