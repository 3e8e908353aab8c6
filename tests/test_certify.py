"""Certification by Krawczyk's test (optkin.solvers.certify).

Evidence: the ball evaluation of a model's closure and Jacobian is checked against CasADi's
floating-point evaluation (the balls must contain the floats at exact points, and over a box
the values at random points of the box); Dietmaier's platform (40 real postures, a
published number) and random 3-RPR are certified completely; a candidate moved by 1e-3, a
mechanism whose solutions are not isolated (base and platform similar triangles: a
self-motion) and a duplicated solution are refused.
"""

from __future__ import annotations

import dataclasses

import flint
import numpy as np
import pytest
from test_assembly_modes import DIET_A, DIET_B, DIET_L  # Dietmaier's platform

import optkin
from optkin import MechanismError
from optkin.model import get_model
from optkin.solvers.certify import BallProgram, certify_point


def _mechanisms():
    ab = np.deg2rad([-10, 10, 110, 130, 230, 250])
    ap = np.deg2rad([-50, 50, 70, 170, 190, 290])
    return {
        "rpr3": optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]],
                                       [[0, 0], [0.25, 0], [0.1, 0.2]]),
        "stewart": optkin.mechanisms.stewart_gough(
            np.c_[np.cos(ab), np.sin(ab), np.zeros(6)],
            0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]),
        "five_bar": optkin.mechanisms.five_bar(8.0, 7.0, 5.0, 5.0, 7.0),
        "four_bar": optkin.mechanisms.four_bar(1.0, 2.0, 2.0, 2.5),
        "delta": optkin.mechanisms.delta(),
    }


@pytest.mark.parametrize("name", list(_mechanisms()))
def test_ball_evaluation_encloses_casadi(name):
    mech = _mechanisms()[name]
    model = get_model(mech)
    topo = model.topology
    prog = BallProgram(topo.jac)
    rng = np.random.default_rng(1)
    for _ in range(3):
        qa = rng.uniform(0.5, 1.5, model.na)
        x = model.default_x(qa) + rng.normal(0, 0.1, model.nx)
        ref = [np.array(v, dtype=float).ravel(order="F") for v in topo.jac(qa, x, model.p)]
        got = prog(qa, x, model.p)  # exact inputs: balls around the exact values
        for r, g in zip(ref, got):
            assert len(r) == len(g)
            for a, b in zip(r, g):
                # CasADi's float differs from the exact value by round-off only
                assert b.overlaps(flint.arb(a, 1e-12 * (1 + abs(a)))), (name, a, b)
                assert float(b.rad()) < 1e-9 * (1 + abs(a))
        # over a box: the enclosure holds the value at every point of the box
        r = 1e-3 * np.asarray(model.x_scale)
        box = [flint.arb(float(v), float(w)) for v, w in zip(x, r)]
        enclosure = prog(qa, box, model.p)
        for _ in range(20):
            y = x + rng.uniform(-1, 1, x.size) * r
            vals = [np.array(v, dtype=float).ravel(order="F") for v in topo.jac(qa, y, model.p)]
            for v, e in zip(vals, enclosure):
                for a, b in zip(v, e):
                    assert b.overlaps(flint.arb(a, 1e-12 * (1 + abs(a)))), (name, a, b)


def test_dietmaier_every_posture_certified():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    modes = optkin.assembly_modes(m, DIET_L, seed=3, certify=True)
    assert len(modes) == 40
    assert all(r.certified for r in modes), [r.stats.extra["certificate"] for r in modes]
    assert modes.info["certified"] == 40
    assert modes.summary().endswith("40 certified")
    assert all(r.to_dict()["certified"] is True for r in modes)


def test_random_3rpr_every_mode_certified():
    rng = np.random.default_rng(5)
    count = 0
    for k in range(20):
        A, B = rng.uniform(-10, 10, (3, 2)), rng.uniform(-4, 4, (3, 2))
        x, y, ph = *rng.uniform(-3, 3, 2), rng.uniform(-np.pi, np.pi)
        R = np.array([[np.cos(ph), -np.sin(ph)], [np.sin(ph), np.cos(ph)]])
        L = np.linalg.norm(np.array([x, y]) + B @ R.T - A, axis=1)
        m = optkin.mechanisms.rpr3(A, B)
        modes = optkin.assembly_modes(m, L, seed=k, certify=True)
        assert len(modes) >= 1
        assert all(r.certified for r in modes), (k, [r.stats.extra["certificate"] for r in modes])
        certs = optkin.certify(m, modes)  # the function gives the same verdicts
        assert [c.certified for c in certs] == [True] * len(modes)
        for c, r in zip(certs, modes):  # each box holds its solution, and is small
            assert np.all((c.box[:, 0] < r.x) & (r.x < c.box[:, 1]))
            assert c.radius < 1e-6
        count += len(modes)
    assert count >= 40


def test_a_moved_candidate_is_not_certified():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    r = optkin.assembly_modes(m, DIET_L, seed=0)[0]
    moved = dataclasses.replace(r, x=r.x + 1e-3)
    c = optkin.certify(m, moved)[0]
    assert not c.certified and "not inside" in c.message
    assert optkin.certify(m, r)[0].certified


def test_a_self_motion_is_not_certified():
    # base and platform the same triangle, every leg 0.5: the platform translates on the
    # circle |p| = 0.5 (phi = 0) with every leg closed; no point of it is an isolated
    # solution, so none may be certified
    tri = [[0, 0], [1, 0], [0, 1]]
    m = optkin.mechanisms.rpr3(tri, tri)
    modes = optkin.assembly_modes(m, [0.5, 0.5, 0.5], seed=0, starts=512, certify=True)
    assert modes.info["certified"] == len(modes)  # the isolated ones (the circle apart)
    on_circle = [r for c in modes.components for r in c.samples
                 if abs(np.hypot(*r.x[:2]) - 0.5) < 1e-9 and abs(r.x[2]) < 1e-9]
    assert len(on_circle) >= 3
    model = get_model(m)
    for r in on_circle:
        c = certify_point(model, r.qa, r.x)
        assert not c.certified, c


def test_a_duplicate_is_not_proven_distinct():
    m = _mechanisms()["rpr3"]
    modes = optkin.assembly_modes(m, [0.6, 0.7, 0.65])
    certs = optkin.certify(m, [modes[0], modes[0]])
    assert [c.certified for c in certs] == [False, False]
    assert "overlaps" in certs[0].message


def test_bad_input_names_the_item():
    m = _mechanisms()["rpr3"]
    with pytest.raises(MechanismError, match="item 1 is a list"):
        optkin.certify(m, [optkin.forward(m, [0.6, 0.7, 0.65]), [1, 2, 3]])
    with pytest.raises(MechanismError, match="expected an optkin Mechanism"):
        optkin.certify("rpr3", [])
    with pytest.raises(MechanismError, match="certify must be True or False"):
        optkin.assembly_modes(m, [0.6, 0.7, 0.65], certify="yes")
