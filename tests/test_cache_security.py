"""The compiled-code cache runs only code optkin built for this model (issue 11, B3 and B7).

Built from ``../shared/repro/cache_tmp_hijack.sh`` and ``cache_truncated_so.sh``. optkin runs
in subprocesses with an explicit environment (their own cache and temp directories, never
the user's). Evidence, independent of the cache code: a marker file written by the
constructor of a planted library (it ran if the file exists), the results of the
interpreted Functions (``OPTKIN_COMPILE=off``), the closure residual of the interpreted SX
model, and the SHA-256 of a library computed here and compared with its record.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import stat
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import optkin
from optkin.model import compiled as cc
from optkin.model.core import Model

QA = [1.2, 1.9]
D_A, D_B = 7.9, 7.5  # two five-bars with the same Function signatures
ATTACKER = 4242  # the uid that plants libraries when the tests run as root
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0

needs_gcc = pytest.mark.skipif(shutil.which("gcc") is None, reason="no gcc")
posix = pytest.mark.skipif(not hasattr(os, "getuid"), reason="needs POSIX user ids")

SOLVE = """
import json, sys, optkin
from optkin.model.compiled import cache_dir
out = {"cache": str(cache_dir())}
qa = json.loads(sys.argv[1])
for d in map(float, sys.argv[2:]):
    m = optkin.mechanisms.five_bar(9, 8, 5, 5, d)
    r = optkin.forward(m, qa)
    out[str(d)] = {"x": [float(v) for v in r.x], "success": bool(r.success),
                   "compiled": optkin.get_model(m).compiled}
print(json.dumps(out))
"""

EVIL_C = r"""
#include <stdio.h>
__attribute__((constructor)) static void pwn(void) {
  FILE *f = fopen("%s", "w");
  if (f) { fputs("planted code ran\n", f); fclose(f); }
}
"""


def mech(d: float) -> optkin.Mechanism:
    return optkin.mechanisms.five_bar(9, 8, 5, 5, d)


def env_for(tmp: Path, cache: Path | None, compile_mode: str = "eager") -> dict[str, str]:
    """An environment with no trace of the user's cache settings."""
    env = {k: v for k, v in os.environ.items()
           if not k.startswith("OPTKIN_") and k not in ("XDG_CACHE_HOME", "TMPDIR", "CC")}
    (tmp / "tmp").mkdir(exist_ok=True)
    env.update(OPTKIN_COMPILE=compile_mode, TMPDIR=str(tmp / "tmp"),
               HOME=str(tmp / "home"), MPLCONFIGDIR=str(tmp / "mpl"))
    if cache is not None:
        env["OPTKIN_CACHE"] = str(cache)
    return env


def solve(env: dict[str, str], *ds: float) -> dict:
    """Forward solves at ``QA`` of five_bar(9, 8, 5, 5, d) for ``ds``, in a fresh process."""
    p = subprocess.run([sys.executable, "-c", SOLVE, json.dumps(QA), *map(str, ds)], env=env,
                       cwd=env["TMPDIR"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, f"exit {p.returncode} (-7 = SIGBUS): {p.stderr[-2000:]}"
    return json.loads(p.stdout.splitlines()[-1])


def residual(d: float, x) -> float:
    """Closure residual of the interpreted SX model of five_bar(..., d) at ``x``."""
    return float(np.max(np.abs(np.array(interpreted_model(d).phi(QA, x)))))


_MODELS: dict[float, Model] = {}


@pytest.fixture(autouse=True, scope="module")
def _forget_models():
    """The models are shared by this module's tests only: a test elsewhere that checks a
    five-bar topology is released once its models are (test_architecture's
    clear_cache test) must not find these holding it."""
    yield
    _MODELS.clear()


def interpreted_model(d: float) -> Model:
    """The model of five_bar(..., d) built with compiling off (it reads no cache)."""
    if d not in _MODELS:
        with pytest.MonkeyPatch.context() as mp:
            mp.setenv("OPTKIN_COMPILE", "off")
            _MODELS[d] = Model(mech(d))
    return _MODELS[d]


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> dict[float, np.ndarray]:
    """The interpreted (OPTKIN_COMPILE=off) solutions of both five-bars."""
    tmp = tmp_path_factory.mktemp("reference")
    out = solve(env_for(tmp, None, "off"), D_A, D_B)
    assert not out[str(D_A)]["compiled"]
    ref = {d: np.array(out[str(d)]["x"]) for d in (D_A, D_B)}
    for d, x in ref.items():
        assert residual(d, x) <= 1e-10
    assert np.max(np.abs(ref[D_A] - ref[D_B])) > 0.1  # a swapped library would show
    return ref


@pytest.fixture(scope="module")
def built_a(tmp_path_factory) -> Path:
    """A cache holding the library (and record) of five_bar A, built by optkin; tests copy
    it (``shutil.copytree`` keeps the modes)."""
    tmp = tmp_path_factory.mktemp("built-a")
    solve(env_for(tmp, tmp / "cache"), D_A)
    return tmp / "cache"


def copy_of(built: Path, tmp: Path) -> Path:
    return Path(shutil.copytree(built, tmp / "cache"))


@pytest.fixture(scope="module")
def evil(tmp_path_factory) -> tuple[Path, Path]:
    """A shared library whose constructor writes a marker file, and that marker's path."""
    tmp = tmp_path_factory.mktemp("evil")
    marker = tmp / "pwned"
    src = tmp / "evil.c"
    src.write_text(EVIL_C % marker)
    so = tmp / "evil.so"
    subprocess.run(["gcc", "-shared", "-fPIC", str(src), "-o", str(so)], check=True,
                   capture_output=True, timeout=60)
    return so, marker


def plant(evil_so: Path, so: Path, dest: Path) -> None:
    """Put the planted library in ``dest`` under the name of ``so``, with a copy of the
    record of ``so`` (when there is one) forged to vouch for the planted bytes."""
    data = evil_so.read_bytes()
    rec = so.with_suffix(".json")
    if rec.exists():
        forged = dict(json.loads(rec.read_text()), size=len(data),
                      sha256=hashlib.sha256(data).hexdigest())
        (dest / rec.name).write_text(json.dumps(forged))
    (dest / so.name).write_bytes(data)


def check_result(res: dict, d: float, reference) -> None:
    r = res[str(d)]
    assert r["success"] and r["compiled"]
    np.testing.assert_allclose(r["x"], reference[d], rtol=0, atol=1e-9)
    assert residual(d, r["x"]) <= 1e-10


def libs(cache: Path) -> set[Path]:
    return set(cache.glob("optkin_core_*.so"))


def record_vouches(so: Path, d: float) -> bool:
    """The record beside ``so`` names the topology of five_bar(..., d) (its libraries serve
    every geometry of it: the geometry is an input) and the SHA-256 of its bytes."""
    from optkin.model import get_model

    rec = json.loads(so.with_suffix(".json").read_text())
    data = so.read_bytes()
    return (rec["tag"] == "core:" + get_model(mech(d)).topology.key and rec["size"] == len(data)
            and rec["sha256"] == hashlib.sha256(data).hexdigest())


def private(d: Path) -> bool:
    st = os.lstat(d)
    return (stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid()
            and st.st_mode & 0o022 == 0)


# ------------------------------------------------------------------ B3: foreign directories
@needs_gcc
@posix
def test_planted_library_in_shared_temp_dir_never_runs(tmp_path, built_a, evil, reference):
    """cache_tmp_hijack.sh: ~/.cache is not writable; another user made the directory the
    old code fell back to (``$TMPDIR/optkin-cache-<uid>``, mode 0777) and planted libraries
    under the names optkin uses, with records that vouch for them."""
    evil_so, marker = evil
    names = libs(built_a)  # the names optkin gives this model's libraries
    assert names
    (tmp_path / "home").write_text("a file: ~/.cache cannot be created under it")
    shared = tmp_path / "tmp" / f"optkin-cache-{os.getuid()}"
    shared.mkdir(mode=0o777, parents=True)
    shared.chmod(0o777)
    for so in names:
        plant(evil_so, so, shared)
    if IS_ROOT:
        for p in [shared, *shared.iterdir()]:
            os.chown(p, ATTACKER, ATTACKER)
    res = solve(env_for(tmp_path, None), D_A)
    assert not marker.exists(), "the planted library was loaded"
    check_result(res, D_A, reference)
    used = Path(res["cache"])
    assert used != shared and shared not in used.parents
    assert not used.exists()  # the private fallback directory is removed at exit


@posix
def test_cache_dir_is_always_private(tmp_path, monkeypatch):
    """Whatever the candidates look like, cache_dir() returns a directory owned by us and
    writable by nobody else (or None), never a predictable shared one."""
    loose = tmp_path / "loose"
    loose.mkdir()
    loose.chmod(0o777)
    xdg = tmp_path / "xdg"
    (xdg / "optkin").mkdir(parents=True)
    (xdg / "optkin").chmod(0o775)
    tmp = tmp_path / "tmp"
    (tmp / f"optkin-cache-{os.getuid()}").mkdir(parents=True)
    (tmp / f"optkin-cache-{os.getuid()}").chmod(0o777)
    monkeypatch.setenv("OPTKIN_CACHE", str(loose))
    monkeypatch.setenv("XDG_CACHE_HOME", str(xdg))
    monkeypatch.setattr("tempfile.tempdir", str(tmp))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        d = cc.cache_dir()
    assert d is None or private(d)
    assert d not in (loose, xdg / "optkin", tmp / f"optkin-cache-{os.getuid()}")
    assert any(f"chmod 700 {loose}" in str(w.message) for w in said)


# ------------------------------------------------------------------ B7: broken libraries
@needs_gcc
def test_truncated_library_is_rebuilt(tmp_path, built_a, reference):
    """cache_truncated_so.sh: a truncated library crashed every later process (SIGBUS)."""
    cache = copy_of(built_a, tmp_path)
    env = env_for(tmp_path, cache)
    (so,) = libs(cache)
    size = so.stat().st_size
    os.truncate(so, 1000)
    res = solve(env, D_A)  # exit code 0 is checked by solve
    check_result(res, D_A, reference)
    assert libs(cache) == {so} and so.stat().st_size == size
    assert record_vouches(so, D_A)


@needs_gcc
def test_library_of_similar_mechanism_is_not_loaded(tmp_path, built_a, reference):
    """Mechanisms of one topology share its library (the geometry is an input): B's solve
    loads A's library and answers B. A library whose record names another owner (here A's
    record rewritten to another topology, as a copy from elsewhere would read) is not loaded:
    it is rebuilt, and the new record vouches for it."""
    cache = copy_of(built_a, tmp_path)
    env = env_for(tmp_path, cache)
    (so_a,) = libs(cache)
    res = solve(env, D_B)
    check_result(res, D_B, reference)  # B's answer through the shared library
    assert libs(cache) == {so_a} and res[str(D_B)]["compiled"]
    rec_path = so_a.with_suffix(".json")
    rec = json.loads(rec_path.read_text())
    rec["tag"] = "core:0123456789abcdef"  # another topology's library
    rec_path.write_text(json.dumps(rec))
    res = solve(env, D_B)
    check_result(res, D_B, reference)  # B's answer, not a foreign library's
    assert record_vouches(so_a, D_B)


@needs_gcc
@posix
def test_library_not_private_is_not_loaded(tmp_path, built_a, evil, reference):
    """A planted library with a record that vouches for it, in our own cache directory, but
    owned by another user (as root) or writable by group and others: never loaded."""
    evil_so, marker = evil
    cache = copy_of(built_a, tmp_path)
    env = env_for(tmp_path, cache)
    (so,) = libs(cache)
    plant(evil_so, so, cache)
    if IS_ROOT:
        os.chown(so, ATTACKER, ATTACKER)
    else:
        so.chmod(0o666)
    res = solve(env, D_A)
    assert not marker.exists(), "the planted library was loaded"
    check_result(res, D_A, reference)
    assert record_vouches(so, D_A) and so.stat().st_uid == os.getuid()


# ------------------------------------------------------------------ a rejected OPTKIN_CACHE
def _loose(d: Path) -> str:
    d.chmod(0o775)
    return f"writable by group or others (mode 0775). To use it, run `chmod 700 {d}`"


def _read_only(d: Path) -> str:
    d.chmod(0o500)
    return f"not writable. To use it, run `chmod 700 {d}`"


def _symlink(d: Path) -> str:
    real = d.with_name(d.name + "-real")
    real.mkdir(mode=0o700)
    d.rmdir()
    d.symlink_to(real)
    return "a symbolic link. To use it, use the directory it points to"


@posix
@pytest.mark.parametrize("spoil", [_loose, _read_only, _symlink])
def test_unusable_optkin_cache_is_reported_and_not_used(tmp_path, monkeypatch, spoil):
    bad = tmp_path / "bad"
    bad.mkdir(mode=0o700)
    says = spoil(bad)
    monkeypatch.setenv("OPTKIN_CACHE", str(bad))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    try:
        with pytest.warns(UserWarning) as said:
            d = cc.cache_dir()
        assert d == tmp_path / "xdg" / "optkin" and private(d)
        (msg,) = [str(w.message) for w in said]
        assert f"OPTKIN_CACHE={bad} is not used: it is {says}" in msg
        assert f"cached in {d} instead" in msg
        with warnings.catch_warnings():  # said once per process
            warnings.simplefilter("error")
            assert cc.cache_dir() == d
    finally:
        if not bad.is_symlink():
            bad.chmod(0o700)
