"""The compiled path (optkin.model.compiled), the fused result evaluation and forward_batch.

Evidence: the compiled Functions are compared with the interpreted SX Functions they were
generated from, the fused joint values with the numpy implementation of the legs
(``Model.to_q``), and forward_batch with per-call forward and with the closed-form inverse
model of the 3-RPR (leg lengths = distances between the solved platform points and the base
points, written here in numpy). Only small mechanisms are compiled, into a per-session cache.
No timings here: those are in benchmarks/.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import textwrap

import casadi as ca
import numpy as np
import pytest

import optkin
from optkin import mechanisms as lib
from optkin.model import compiled as cc
from optkin.model.core import Model, get_model
from optkin.model.fused import result_function

RNG = np.random.default_rng(8)

BASE3 = [[0.0, 0.0], [1.0, 0.0], [0.3, 0.9]]
PLAT3 = [[0.0, 0.0], [0.25, 0.0], [0.1, 0.2]]


def rpr() -> optkin.Mechanism:
    return lib.rpr3(BASE3, PLAT3)


def stewart() -> optkin.Mechanism:
    ab = np.deg2rad([-10, 10, 110, 130, 230, 250])
    ap = np.deg2rad([-50, 50, 70, 170, 190, 290])
    base = np.c_[np.cos(ab), np.sin(ab), np.zeros(6)]
    plat = 0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]
    return lib.stewart_gough(base, plat, home=[0.05, -0.03, 1.0, 0.1, -0.05, 0.2])


def small_library() -> dict[str, optkin.Mechanism]:
    return {
        "rpr3": rpr(),
        "rrr3": lib.rrr3(BASE3, PLAT3, 0.6, 0.6),
        "five_bar": lib.five_bar(1.0, 1.0, 1.0, 1.0, 1.0),
        "four_bar": lib.four_bar(1.0, 2.0, 2.0, 2.5),
        "stewart": stewart(),
        "delta": lib.delta(),
        "sr400": lib.sr400(),
    }


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    d = tmp_path_factory.mktemp("optkin-cache")
    mp = pytest.MonkeyPatch()
    mp.setenv("OPTKIN_CACHE", str(d))
    mp.setenv("OPTKIN_COMPILE", "auto")
    mp.delenv("OPTKIN_CC", raising=False)
    # the compiled libraries live per topology for the whole process: start without them,
    # so that the topologies of these tests compile into this cache
    optkin.model.clear_cache()
    yield d
    mp.undo()
    optkin.model.clear_cache()


def _random_inputs(model: Model, n: int):
    for _ in range(n):
        qa = RNG.uniform(0.5, 1.5, model.na)
        x = model.default_x(qa) + RNG.normal(0, 0.1, model.nx)
        yield qa, x


def _same_angles(a, b) -> float:
    d = np.asarray(a) - np.asarray(b)
    return float(np.max(np.abs(np.arctan2(np.sin(d), np.cos(d)))))


needs_cc = pytest.mark.skipif(cc.find_compiler() is None, reason="no C compiler")


@needs_cc
@pytest.mark.parametrize("name", ["rpr3", "four_bar"])
def test_compiled_functions_match_interpreted(cache, name):
    mech = small_library()[name]
    model = Model(mech)
    assert model.compile()
    assert model.compiled and model.step.is_a("External")
    assert any(p.suffix in (".so", ".dll") for p in cache.iterdir())
    lib_fns = model.compiled_fns
    topo = model.topology  # the Functions of the topology: the geometry is their last input
    result_sx = result_function(topo)
    for qa, x in _random_inputs(model, 20):
        # phi, jac and pose_fn stay the interpreted SX Functions; step_sx is the SX step
        pairs = [(lib_fns["Phi"], topo.phi), (lib_fns["W"], topo.jac),
                 (lib_fns["newton_step"], model.step_sx), (lib_fns["pose"], topo.pose_fn),
                 (lib_fns["result"], result_sx)]
        for fc, fi in pairs:
            assert not fi.is_a("External")
            oc, oi = fc(qa, x, model.p), fi(qa, x, model.p)
            oc = oc if isinstance(oc, (list, tuple)) else [oc]
            oi = oi if isinstance(oi, (list, tuple)) else [oi]
            for a, b in zip(oc, oi):
                np.testing.assert_allclose(np.array(a), np.array(b), rtol=0, atol=1e-12)
        # the buffered evaluators give the same numbers as the Function call
        xn, r = model.fast("newton_step")(qa, x)
        xi, ri = model.step_sx(qa, x, model.p)
        np.testing.assert_allclose(xn, np.array(xi).ravel(), rtol=0, atol=1e-12)
        assert abs(r[0] - float(ri)) <= 1e-12


@needs_cc
def test_second_model_loads_from_cache(cache):
    mech = rpr()
    m1 = Model(mech)
    assert m1.compile()
    m2 = Model(mech)  # auto mode: a cached library is loaded when the model is built
    assert m2.compiled


def test_new_geometries_do_not_digest_the_core_again(tmp_path, monkeypatch):
    """In the auto mode every new geometry's Model looks for the topology's compiled core;
    its cache key (a digest of the serialized Functions) is computed once per topology, not
    once per geometry; and a core compiled later is still found by the next Model."""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))  # an empty cache: nothing to load
    monkeypatch.setenv("OPTKIN_COMPILE", "auto")
    optkin.model.clear_cache()  # the topology anew (its key not yet computed)
    calls = []
    real = cc._digest
    monkeypatch.setattr(cc, "_digest", lambda tag, fs: calls.append(tag) or real(tag, fs))
    rng = np.random.default_rng(5)
    models = [Model(lib.rpr3(BASE3, np.asarray(PLAT3) + rng.uniform(-0.02, 0.02, (3, 2))))
              for _ in range(6)]
    assert sum(t.startswith("core:") for t in calls) == 1
    assert not any(m.compiled for m in models)
    if cc.find_compiler() is not None:
        assert models[0].compile()
        assert Model(lib.rpr3(BASE3, np.asarray(PLAT3) + 0.01)).compiled


@needs_cc
def test_compiled_tracker_matches_interpreted(cache, monkeypatch):
    mech = rpr()
    model = Model(mech)
    f_c, compiled = model.tracker(16, 2)
    assert compiled
    monkeypatch.setenv("OPTKIN_COMPILE", "off")
    optkin.model.clear_cache()  # what is built lives per topology: start without it
    f_i, compiled_i = Model(mech).tracker(16, 2)
    assert not compiled_i
    x0 = model.default_x(np.ones(3))
    qa0 = np.array([0.8, 0.9, 0.7])
    QA = qa0[:, None] + 0.01 * RNG.normal(size=(3, 16))
    for a, b in zip(f_c(x0, qa0, QA, model.p), f_i(x0, qa0, QA, model.p)):
        np.testing.assert_allclose(np.array(a), np.array(b), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", list(small_library()))
def test_fused_joint_values_match_numpy(name):
    """The joint values of the fused result Function vs Model.to_q (numpy leg_joints)."""
    mech = small_library()[name]
    model = optkin.get_model(mech)
    f = result_function(model.topology)
    for qa, x in _random_inputs(model, 10):
        x = model.canonical_x(x)
        phi, Wp, T, q = (np.array(v) for v in f(qa, x, model.p))
        assert _same_angles(q.ravel(), model.to_q(qa, x)) <= 1e-12
        np.testing.assert_allclose(T, model.pose(qa, x), atol=1e-14)
        _, Wp_ref, _ = model.jac(qa, x)
        np.testing.assert_allclose(Wp, np.array(Wp_ref), atol=1e-14)


def test_fallback_without_compiler(tmp_path, monkeypatch):
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    monkeypatch.setenv("OPTKIN_CC", "no-such-compiler-optkin")
    assert cc.find_compiler() is None
    optkin.model.clear_cache()  # (a topology compiled by an earlier test keeps its code)
    mech = lib.five_bar(1.0, 1.0, 1.0, 1.0, 1.1)
    model = Model(mech)
    assert model.compile() is False
    assert not model.compiled and model.step is model.step_sx
    # the interpreted step, mapped; its inputs (q_a, x, geometry): the geometry became an
    # input of every Function of the model with issue 12 (was 2: q_a, x)
    assert model.compiled_batch_step(4).n_in() == 3
    f, compiled = model.tracker(8, 2)
    assert not compiled
    assert list(tmp_path.glob("*.so")) == []


def test_compile_off(monkeypatch):
    monkeypatch.setenv("OPTKIN_COMPILE", "off")
    assert cc.find_compiler() is None
    assert cc.library("core:x", []) is None
    model = Model(lib.five_bar(1.0, 1.0, 1.0, 1.0, 1.2))
    assert model.compile() is False


def test_cache_dir_falls_back_when_not_writable(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("OPTKIN_CACHE", str(blocker / "sub"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocker / "xdg"))
    d = cc.cache_dir()
    assert d is not None and d.is_dir() and os.access(d, os.W_OK)
    assert blocker not in d.parents


def test_model_pickles_by_mechanism():
    mech = rpr()
    model = optkin.get_model(mech)
    assert pickle.loads(pickle.dumps(model)) is model


# ------------------------------------------------------------------ forward_batch
def _rpr_path(mech, n):
    """Platform poses along a smooth path and their leg lengths (closed form, numpy)."""
    t = np.linspace(0.0, 1.0, n)
    X = np.c_[0.45 + 0.05 * np.sin(2 * np.pi * t), 0.35 + 0.05 * t,
              0.2 + 0.3 * np.sin(np.pi * t)]
    QA = np.empty((n, 3))
    for i, (x, y, phi) in enumerate(X):
        c, s = np.cos(phi), np.sin(phi)
        for k, leg in enumerate(mech.legs):
            b = np.asarray(leg.base)[:2]
            p = np.asarray(leg.platform)[:2]
            P = np.array([x + c * p[0] - s * p[1], y + s * p[0] + c * p[1]])
            QA[i, k] = np.linalg.norm(P - b)
    return X, QA


def _rpr_leg_lengths(mech, X):
    out = np.empty((len(X), 3))
    for i, (x, y, phi) in enumerate(X):
        c, s = np.cos(phi), np.sin(phi)
        for k, leg in enumerate(mech.legs):
            b = np.asarray(leg.base)[:2]
            p = np.asarray(leg.platform)[:2]
            out[i, k] = np.hypot(x + c * p[0] - s * p[1] - b[0], y + s * p[0] + c * p[1] - b[1])
    return out


@pytest.mark.parametrize("path", [True, False])
def test_forward_batch_rpr_closed_form(cache, path):
    mech = rpr()
    Xtrue, QA = _rpr_path(mech, 400)
    guess = Xtrue[0] if path else Xtrue + 0.01
    br = optkin.forward_batch(mech, QA, guess=guess, path=path)
    assert br.all_success and br.status == "optimal"
    assert br.x.shape == (400, 3) and len(br) == 400
    assert np.max(br.residual) <= 1e-10
    # closed form: the legs of the solved poses have the given lengths
    np.testing.assert_allclose(_rpr_leg_lengths(mech, br.x), QA, rtol=0, atol=1e-10)
    # continuity: the assembly mode of the generating path is the one followed
    np.testing.assert_allclose(br.x[:, :2], Xtrue[:, :2], atol=1e-8)
    assert _same_angles(br.x[:, 2], Xtrue[:, 2]) <= 1e-8


def test_forward_batch_matches_forward(cache):
    mech = rpr()
    Xtrue, QA = _rpr_path(mech, 60)
    br = optkin.forward_batch(mech, QA, guess=Xtrue[0], chunk=16)
    r = optkin.forward(mech, QA[0], guess=Xtrue[0])
    for i in range(len(QA)):
        r = optkin.forward(mech, QA[i], guess=r)  # warm-started per-call tracking
        assert r.success
        assert np.max(np.abs(r.x - br.x[i])) <= 1e-9
    kr = br.result(30)
    assert kr.success and kr.q.shape == (9,)
    np.testing.assert_allclose(br.q()[30], kr.q, atol=1e-12)
    np.testing.assert_allclose(br.poses()[30], kr.pose, atol=1e-12)
    # columns layout (na, n) is accepted too
    bc = optkin.forward_batch(mech, QA.T, guess=Xtrue[0], chunk=16)
    np.testing.assert_allclose(bc.x, br.x, atol=1e-12)


def test_forward_batch_interpreted_fallback(monkeypatch):
    monkeypatch.setenv("OPTKIN_COMPILE", "off")
    mech = lib.rpr3(BASE3, [[0.0, 0.0], [0.25, 0.0], [0.1, 0.21]])
    Xtrue, QA = _rpr_path(mech, 50)
    br = optkin.forward_batch(mech, QA, guess=Xtrue[0], chunk=16)
    assert br.all_success and br.stats.extra["compiled"] is False
    np.testing.assert_allclose(_rpr_leg_lengths(mech, br.x), QA, atol=1e-10)


def test_forward_batch_reports_unreachable_rows(cache):
    mech = rpr()
    Xtrue, QA = _rpr_path(mech, 40)
    QA = QA.copy()
    QA[20] = [0.01, 5.0, 0.01]  # the legs cannot close
    br = optkin.forward_batch(mech, QA, guess=Xtrue[0], chunk=16)
    assert not br.closed[20] and br.closed.sum() == 39 and br.success is False
    assert br.status == "infeasible" and "row 20" in br.message
    np.testing.assert_allclose(br.x[21:, :2], Xtrue[21:, :2], atol=1e-8)


def test_forward_batch_bad_input():
    with pytest.raises(optkin.MechanismError, match=r"QA: expected an \(n, 3\) array"):
        optkin.forward_batch(rpr(), np.ones((5, 4)))
    with pytest.raises(optkin.MechanismError, match="positive"):
        optkin.forward_batch(rpr(), -np.ones((5, 3)))


@needs_cc
@pytest.mark.slow
def test_concurrent_compilation(tmp_path):
    """Two processes compiling the same model at once both end with a working library."""
    code = textwrap.dedent("""
        import numpy as np, optkin
        from optkin.model.core import Model
        m = Model(optkin.mechanisms.five_bar(1.0, 1.0, 1.0, 1.0, 1.05))
        assert m.compile()
        r = optkin.forward(m.mech, [1.4, 1.8])
        print(m.compiled, r.success)
    """)
    env = dict(os.environ, OPTKIN_CACHE=str(tmp_path))
    procs = [subprocess.Popen([sys.executable, "-c", code], env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True) for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err
        assert out.split() == ["True", "True"]
    assert len(list(tmp_path.glob("*.so"))) == 1
    assert not list(tmp_path.glob(".build-*"))


def test_forward_batch_docstring_example():
    import doctest

    import optkin.solvers.batch as batch

    res = doctest.testmod(batch, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert res.attempted > 0 and res.failed == 0


@needs_cc
def test_background_build_gives_the_same_function(tmp_path, monkeypatch):
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    model = Model(rpr())
    f = model.topology.phi
    pending = cc.start_library("bg:test", [f])
    assert isinstance(pending, cc.PendingLibrary)
    lib_fns = pending.wait()
    assert isinstance(lib_fns, dict) and pending.poll() is lib_fns
    assert not any(p.name.startswith(".build-") for p in tmp_path.iterdir())  # cleaned up
    g = lib_fns[f.name()]
    assert g.is_a("External")
    for qa, x in _random_inputs(model, 5):
        np.testing.assert_array_equal(np.array(g(qa, x, model.p)), np.array(f(qa, x, model.p)))
    again = cc.start_library("bg:test", [f])  # now in the cache: loaded, nothing started
    assert isinstance(again, dict)


def test_background_build_failure_is_reported(tmp_path, monkeypatch):
    fake = tmp_path / "fakecc"
    fake.write_text("#!/bin/sh\necho 'fake compiler: refused' >&2\nexit 3\n")
    fake.chmod(0o755)
    cache_dir = tmp_path / "cache"
    cache_dir.mkdir(mode=0o700)
    monkeypatch.setenv("OPTKIN_CACHE", str(cache_dir))
    monkeypatch.setenv("OPTKIN_CC", str(fake))
    pending = cc.start_library("bg:fail", [Model(rpr()).topology.phi])
    assert isinstance(pending, cc.PendingLibrary)
    assert pending.wait() is False and pending.poll() is False
    assert list(cache_dir.iterdir()) == []


@needs_cc
def test_assembly_modes_compiles_in_the_background(tmp_path, monkeypatch):
    """The multistart's jit="auto" on a 6+ unknown model with an empty cache: the first
    call runs the interpreted step while the compiler works, a later one the compiled step;
    the modes are the same. (method="auto" takes the homotopy on this platform since its
    12 paths to infinity are told from failures.)"""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    optkin.model.clear_cache()
    mech = stewart()
    qa = np.full(6, 1.05)
    first = optkin.assembly_modes(mech, qa, seed=1, method="multistart")
    assert first.info["jit"] is False
    store = get_model(mech).topology._store  # the step entry holds the running build
    pending = [e["pending"] for e in store.values() if isinstance(e, dict) and "pending" in e]
    assert len(pending) == 1
    assert isinstance(pending[0].wait(), dict)
    second = optkin.assembly_modes(mech, qa, seed=1, method="multistart")
    assert second.info["jit"] is True
    assert len(first) == len(second) >= 1
    for a, b in zip(first, second):
        np.testing.assert_array_equal(a.x, b.x)
    optkin.model.clear_cache()


# ------------------------------------------------------------ one build per shared cache
_SLOW_CC = """#!/bin/sh
echo "$$" >> {log}
sleep {pause}
exec {cc} "$@"
"""


def _slow_compiler(tmp_path, pause: float = 1.0):
    """A compiler that logs each call (one line) and takes ``pause`` s longer."""
    log = tmp_path / "calls.log"
    fake = tmp_path / "slowcc"
    fake.write_text(_SLOW_CC.format(log=log, pause=pause, cc=cc.find_compiler()))
    fake.chmod(0o755)
    return fake, log


_BUILD_ONE = textwrap.dedent("""
    import sys, time
    from optkin import mechanisms as lib
    from optkin.model import compiled as cc
    from optkin.model.core import Model
    f = Model(lib.rpr3(base=[[0, 0], [10, 0], [3, 8]], platform=[[0, 0], [2, 0], [1, 1.5]])
              ).topology.phi
    go = float(sys.argv[1])
    while time.time() < go:
        time.sleep(0.005)
    if sys.argv[2] == "sync":
        out = cc.library("shared:test", [f])
    else:
        out = cc.start_library("shared:test", [f])
        out = out if isinstance(out, dict) else out.wait(60)
    print("compiled" if out and out[f.name()].is_a("External") else "interpreted")
""")


@needs_cc
@pytest.mark.parametrize("how", ["sync", "background"])
def test_processes_sharing_a_cache_build_a_library_once(tmp_path, how):
    """Three processes ask for the same missing library at the same moment: the compiler
    runs once (the others wait for its library) and all three load the compiled code."""
    import time

    fake, log = _slow_compiler(tmp_path)
    cache = tmp_path / "cache"
    cache.mkdir(mode=0o700)
    env = dict(os.environ, OPTKIN_CACHE=str(cache), OPTKIN_CC=str(fake))
    go = time.time() + 3.0  # after every interpreter has imported optkin
    procs = [subprocess.Popen([sys.executable, "-c", _BUILD_ONE, str(go), how], env=env,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(3)]
    outs = [p.communicate(timeout=120) for p in procs]
    assert [p.returncode for p in procs] == [0, 0, 0], [o[1][-800:] for o in outs]
    assert [o[0].strip() for o in outs] == ["compiled"] * 3
    assert len(log.read_text().split()) == 1
    assert not [p.name for p in cache.iterdir() if p.suffix == ".lock"
                or p.name.startswith(".build-")]


@needs_cc
def test_an_abandoned_build_lock_is_taken_over(tmp_path, monkeypatch):
    """A lock left by a process that died (this host) does not stop the build; one of a
    live process is honoured until it is stale."""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    f = Model(rpr()).topology.phi
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    key = cc._digest("lock:test", [f])
    path = cc._library_path(tmp_path, "lock:test", key)
    lock = path.with_suffix(".lock")
    fd = os.open(lock, os.O_WRONLY | os.O_CREAT, 0o600)
    os.write(fd, f"{dead.pid} {cc._HOST}".encode())
    os.close(fd)
    lib_fns = cc.library("lock:test", [f])
    assert lib_fns is not None and lib_fns[f.name()].is_a("External")
    assert not lock.exists()

    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        key2 = cc._digest("lock:test2", [f])
        path2 = cc._library_path(tmp_path, "lock:test2", key2)
        fd = os.open(path2.with_suffix(".lock"), os.O_WRONLY | os.O_CREAT, 0o600)
        os.write(fd, f"{alive.pid} {cc._HOST}".encode())
        os.close(fd)
        pending = cc.start_library("lock:test2", [f])
        assert isinstance(pending, cc.PendingLibrary) and not pending.own
        assert pending.poll() is None  # waits for the other process
        monkeypatch.setattr(cc, "LOCK_STALE", 0.0)  # now it counts as abandoned
        pending._next_look = 0.0
        out = pending.poll()
        out = out if out is not None else pending.wait(60)
        assert isinstance(out, dict) and out[f.name()].is_a("External")
    finally:
        alive.kill()
        alive.wait()


@needs_cc
def test_a_background_build_lands_though_nobody_asks(tmp_path, monkeypatch):
    """The library of a background build is installed when the compiler ends even if its
    owner never polls (a topology whose last problem ran before the compiler finished)."""
    import time

    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    f = Model(rpr()).topology.phi
    pending = cc.start_library("land:test", [f])
    assert isinstance(pending, cc.PendingLibrary) and pending.own
    del pending
    key = cc._digest("land:test", [f])
    path = cc._library_path(tmp_path, "land:test", key)
    end = time.monotonic() + 60
    while cc._load(path, "land:test", key, [f]) is None and time.monotonic() < end:
        time.sleep(0.05)
    assert cc._load(path, "land:test", key, [f]) is not None
    time.sleep(0.2)
    assert sorted(p.suffix for p in tmp_path.iterdir()) == [".json", ".so"]


# ------------------------------------------------------------ graphs kept in the cache
def test_memo_function_reads_back_only_what_it_wrote(tmp_path, monkeypatch):
    """A stored graph is read back instead of rebuilt, evaluates as the built one; a
    changed payload, or a file others can write, is rebuilt, never read."""
    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 3)
    calls = []

    def build():
        calls.append(1)
        return ca.Function("g", [x], [ca.sin(x) * ca.sumsqr(x)])

    f1 = cc.memo_function("test", ["parts", b"more"], build)
    (path,) = [p for p in tmp_path.iterdir() if p.name.startswith("optkin_fn_test_")]
    f2 = cc.memo_function("test", ["parts", b"more"], build)
    assert len(calls) == 1
    v = np.array([0.3, -1.2, 2.5])
    np.testing.assert_array_equal(np.array(f2(v)), np.array(f1(v)))
    cc.memo_function("test", ["other parts"], build)  # other parts: another graph
    assert len(calls) == 2
    data = path.read_bytes()
    path.write_bytes(data.replace(b"sin", b"cos", 1) if b"sin" in data else data[:-10])
    cc.memo_function("test", ["parts", b"more"], build)
    assert len(calls) == 3  # the digest no longer matched
    path.chmod(0o666)
    cc.memo_function("test", ["parts", b"more"], build)
    assert len(calls) == 4  # not private: not read


def test_fingerprint_is_the_graphs_digest_whether_built_or_read_back(tmp_path, monkeypatch):
    """A library's cache key holds each Function's fingerprint: the SHA-256 of its
    serialized graph (computed here with hashlib), the same for the Function a process
    built and the one the next process reads back from the cache without serializing it;
    another graph of the same signature has another fingerprint."""
    import hashlib

    monkeypatch.setenv("OPTKIN_CACHE", str(tmp_path))
    x = ca.SX.sym("x", 3)
    built = cc.memo_function("fp", ["parts"], lambda: ca.Function("g", [x], [ca.sin(x)]))
    want = hashlib.sha256(built.serialize().encode()).hexdigest()
    assert cc.fingerprint(built) == want
    read = cc.memo_function("fp", ["parts"], lambda: pytest.fail("rebuilt"))
    assert cc.fingerprint(read) == want
    fresh = ca.Function("g", [x], [ca.sin(x)])  # built again in this process, not memoized
    assert cc.fingerprint(fresh) == want
    other = ca.Function("g", [x], [ca.cos(x)])
    assert cc.fingerprint(other) == hashlib.sha256(other.serialize().encode()).hexdigest()
    assert cc.fingerprint(other) != want
    assert cc._digest("t", [read]) == cc._digest("t", [fresh]) != cc._digest("t", [other])


def test_geometries_of_a_topology_share_buffers_without_mixing_them():
    """Models of one topology share each evaluator's buffers in a thread (a new geometry
    sets none up); calls that alternate between geometries each see their own, checked
    against the CasADi call with the geometry passed explicitly (Model.residual), and a
    thread of its own gets buffers of its own."""
    import threading

    import optkin
    from optkin.model.compiled import BoundFast

    rng = np.random.default_rng(5)
    models = [optkin.get_model(optkin.mechanisms.rpr3(rng.uniform(-10, 10, (3, 2)),
                                                      rng.uniform(-4, 4, (3, 2))))
              for _ in range(3)]
    assert len({m.topology.key for m in models}) == 1
    evs = [m.fast("Phi") for m in models]
    assert all(isinstance(e, BoundFast) for e in evs)
    assert len({id(e.ev) for e in evs}) == 1  # one buffer set for the three geometries
    qa, x = np.array([7.0, 6.5, 6.0]), np.array([1.0, 2.0, 0.3])
    for k in [0, 1, 2, 1, 0, 0, 2]:
        np.testing.assert_allclose(evs[k](qa, x)[0].copy(), models[k].residual(qa, x),
                                   rtol=0, atol=1e-12)
    other = []
    t = threading.Thread(target=lambda: other.append(models[0].fast("Phi")))
    t.start()
    t.join()
    assert other[0].ev is not evs[0].ev


@pytest.mark.parametrize("n", [1, 100, 256, 2048])
def test_map_shared_is_the_function_column_by_column(n):
    """map_shared(f, name, n, shared): every column equals f called on that column alone
    with the shared inputs; the signature (names, shapes) is that of f.map(..., shared)."""
    from optkin.model.compiled import map_shared

    x, p, q = ca.SX.sym("x", 3), ca.SX.sym("p", 4), ca.SX.sym("q", 2)
    f = ca.Function("f", [x, p, q], [ca.sin(x) * p[0] + q[1], ca.dot(x, p[1:]) * q[0]],
                    ["x", "p", "q"], ["y", "z"])
    g = map_shared(f, f"f_{n}", n, [1])
    ref = f.map(f"f_{n}", "serial", n, [1], [])
    assert g.name() == ref.name() and g.name_in() == ref.name_in()
    assert g.name_out() == ref.name_out()
    assert [g.sparsity_in(i).shape for i in range(3)] == [ref.sparsity_in(i).shape
                                                          for i in range(3)]
    rng = np.random.default_rng(n)
    X, P, Q = rng.normal(size=(3, n)), rng.normal(size=4), rng.normal(size=(2, n))
    Y, Z = (np.array(v) for v in g(X, P, Q))
    for k in range(n):
        y, z = f(X[:, k], P, Q[:, k])
        assert np.allclose(Y[:, k], np.array(y).ravel(), atol=1e-14)
        assert np.allclose(Z[0, k], float(z), atol=1e-14)
