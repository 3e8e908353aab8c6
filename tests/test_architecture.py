"""The architecture the core promises: one frozen model, no branching on the kind of
mechanism outside the description and model layers, one cache that clear_cache empties."""

from __future__ import annotations

import ast
import gc
import pathlib
import re

import numpy as np
import pytest

import optkin
from optkin import mechanisms as M
from optkin.mechanism import LEG_TYPES, PLATFORMS
from optkin.model import clear_cache, get_model

ROOT = pathlib.Path(optkin.__file__).parent
#: where solvers and analyses live: they see the model, never the kind of description
CONSUMERS = [ROOT / "solvers", ROOT / "analysis", ROOT / "statics", ROOT / "plot.py"]


def _files():
    for c in CONSUMERS:
        yield from ([c] if c.suffix == ".py" else sorted(c.rglob("*.py")))


def _strings(tree: ast.AST) -> list[tuple[int, str]]:
    """String literals of a module, docstrings excluded."""
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = getattr(node, "body", [])
            if body and isinstance(body[0], ast.Expr) and isinstance(
                    getattr(body[0], "value", None), ast.Constant):
                docs.add(id(body[0].value))
    return [(n.lineno, n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs]


def test_no_branch_on_the_kind_of_mechanism_outside_mechanism_and_model():
    """No `.kind ==`, no platform names, no leg-type names in solvers, analyses, statics
    and drawing (issue 12's measure)."""
    words = set(PLATFORMS) | set(LEG_TYPES) | {"khalil", "legs"}
    bad = []
    for f in _files():
        text = f.read_text()
        for i, line in enumerate(text.splitlines(), 1):
            if re.search(r"\.kind\s*(==|!=|in\b)", line) and "task.kind" not in line:
                bad.append(f"{f.relative_to(ROOT)}:{i}: {line.strip()}")
        for lineno, s in _strings(ast.parse(text)):
            if s in words:
                bad.append(f"{f.relative_to(ROOT)}:{lineno}: string {s!r}")
        for attr in ("mech.legs", "mech.platform", "mech.table", "leg.type", "mech.planar"):
            for i, line in enumerate(text.splitlines(), 1):
                if re.search(re.escape(attr) + r"\b", line):
                    bad.append(f"{f.relative_to(ROOT)}:{i}: {attr}")
    assert not bad, "\n".join(bad)


def test_model_is_frozen_and_mechanism_arrays_read_only():
    m = M.rpr3(base=[[0, 0], [1, 0], [0.5, 0.9]], platform=[[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]],
               home=[0.4, 0.3, 0.0])
    model = get_model(m)
    with pytest.raises(AttributeError, match="immutable"):
        model._inv = 1  # type: ignore[misc]
    with pytest.raises(AttributeError, match="immutable"):
        model.nx = 4  # type: ignore[misc]
    for arr in (m.home, m.geometry, model.p, model.x_scale, m.legs[0].screws, m.legs[0].base):
        with pytest.raises(ValueError):
            arr[0] = 9.0
    with pytest.raises(AttributeError):
        m.home = np.zeros(3)  # type: ignore[misc]


def test_one_topology_serves_every_geometry():
    """Two geometries of one topology share the compiled Functions (the numbers are an
    input); another topology does not."""
    rng = np.random.default_rng(1)
    a = M.rpr3(rng.uniform(0, 4, (3, 2)), rng.uniform(-0.5, 0.5, (3, 2)))
    b = M.rpr3(rng.uniform(0, 4, (3, 2)), rng.uniform(-0.5, 0.5, (3, 2)))
    c = M.five_bar(9, 8, 5, 5, 8)
    assert a.topology == b.topology and a.key != b.key
    assert get_model(a).topology is get_model(b).topology
    assert get_model(c).topology is not get_model(a).topology
    assert not np.array_equal(get_model(a).p, get_model(b).p)


def test_clear_cache_empties_every_cache():
    m = M.five_bar(9, 8, 5, 5, 8)
    model = get_model(m)
    optkin.assembly_modes(m, [1.2, 1.9])
    optkin.inverse(m, [4.5, 9.0])
    topo = model.topology
    assert topo._store  # something was built per topology
    import weakref

    ref = weakref.ref(topo)
    clear_cache()
    del model, topo
    gc.collect()
    assert ref() is None, "a cache still holds the topology"
    assert get_model(m).topology is not None


def test_screw_exp_against_rotations_about_a_point_and_translations():
    """exp([S] theta) of a revolute screw (w, -w x c) is the turn by theta about the line
    through c along w (scipy's Rotation, with p = c - R c), of a prismatic one (0, v) the
    shift theta v; alike for DM, SX (evaluated) and MX arguments, and in a product."""
    import casadi as ca
    from scipy.spatial.transform import Rotation

    from optkin.model.joints import chain_transform, screw_exp

    rng = np.random.default_rng(7)
    for _ in range(5):
        w = rng.normal(size=3)
        w /= np.linalg.norm(w)
        c, v, th = rng.normal(size=3), rng.normal(size=3), float(rng.normal())
        S = np.r_[w, -np.cross(w, c)]
        R = Rotation.from_rotvec(th * w).as_matrix()
        want_r = np.eye(4)
        want_r[:3, :3], want_r[:3, 3] = R, c - R @ c
        want_p = np.eye(4)
        want_p[:3, 3] = th * v
        Sp = np.r_[np.zeros(3), v]
        s_sym, t_sym = ca.SX.sym("S", 6), ca.SX.sym("t")
        m_sym, u_sym = ca.MX.sym("S", 6), ca.MX.sym("t")
        for Sk, kind, want in ((S, "R", want_r), (Sp, "P", want_p)):
            got_dm = np.array(screw_exp(ca.DM(Sk), th, kind))
            f_sx = ca.Function("f", [s_sym, t_sym], [screw_exp(s_sym, t_sym, kind)])
            f_mx = ca.Function("f", [m_sym, u_sym], [screw_exp(m_sym, u_sym, kind)])
            for got in (got_dm, np.array(f_sx(Sk, th)), np.array(f_mx(Sk, th))):
                assert np.allclose(got, want, atol=1e-12)
        both = np.array(chain_transform([ca.DM(S), ca.DM(Sp)], "RP", [th, th]))
        assert np.allclose(both, want_r @ want_p, atol=1e-12)
    with pytest.raises(ValueError, match="screw kind"):
        screw_exp(ca.DM(S), 0.1, "H")


def test_revolute_screw_is_the_axis_and_its_moment():
    """revolute_screw(w, q) = (w, -w x q) (numpy's cross), 2-D points in the plane z = 0."""
    from optkin.mechanism.legs import revolute_screw

    rng = np.random.default_rng(11)
    for _ in range(50):
        w, q = rng.normal(size=3), rng.normal(size=3)
        assert np.array_equal(revolute_screw(w, q), np.r_[w, -np.cross(w, q)])
    w, q2 = rng.normal(size=3), rng.normal(size=2)
    assert np.array_equal(revolute_screw(w, q2), np.r_[w, -np.cross(w, np.r_[q2, 0.0])])
