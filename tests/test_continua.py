"""Solutions that are not isolated (optkin.solvers.continua, assembly_modes' account).

Evidence: mechanisms whose continua are known in closed form. A 3-RPR whose base and
platform are the same triangle with every leg 0.5 has the circle |p| = 0.5, phi = 0 of pure
translations as solutions; the 6-6 platform of Gosselin and Angeles' kind (platform = base,
every leg 1) has the unit sphere of translations with R = I. Samples must close the legs
(residuals written here in numpy), lie where the closed form says, and the account must
never call such a set complete. A generic platform (Dietmaier's) gives dimension 0.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_assembly_modes import DIET_A, DIET_B, DIET_L  # Dietmaier's platform

import optkin
from optkin.model import get_model
from optkin.solvers.continua import group, local_dimension, project

TRI = [[0, 0], [1, 0], [0, 1]]
AB = np.deg2rad([-10, 10, 110, 130, 230, 250])
HEX = np.c_[np.cos(AB), np.sin(AB), np.zeros(6)]


def _legs_3d(T, a, b):
    return np.linalg.norm(T[:3, 3] + b @ T[:3, :3].T - a, axis=1)


def test_3rpr_circle_of_translations():
    m = optkin.mechanisms.rpr3(TRI, TRI)
    modes = optkin.assembly_modes(m, [0.5, 0.5, 0.5], seed=0)
    assert modes.dimension == 1 and modes.info["dimension"] == 1
    assert modes.info["complete"] is False and modes.info["status"] == "singular"
    assert "not isolated" in modes.info["message"]
    assert len(modes.components) == 1  # one circle: its samples joined by projections
    comp = modes.components[0]
    assert comp.dimension == 1 and len(comp.samples) >= 6
    for s in comp.samples:
        x, y, phi = s.x
        assert abs(np.hypot(x, y) - 0.5) < 1e-9 and abs(phi) < 1e-9
        assert s.status == "singular" and not s.cond < 1e8
    for s in modes:  # what is left is isolated: a finite condition number
        assert s.cond < 1e8
    d = modes.to_dict()
    assert d["dimension"] == 1 and len(d["components"][0]["samples"]) == len(comp.samples)
    assert "continuum component" in modes.summary()


def test_gosselin_angeles_platform_sphere():
    m = optkin.mechanisms.stewart_gough(HEX, HEX)
    modes = optkin.assembly_modes(m, np.ones(6), seed=0)
    assert modes.dimension >= 1
    assert modes.info["complete"] is False and modes.components
    for c in modes.components:
        for s in c.samples:
            assert np.max(np.abs(_legs_3d(s.pose, HEX, HEX) - 1.0)) < 1e-9
    # a point of the sphere, reached by forward: a continuum of dimension 2 through it
    r = optkin.forward(m, np.ones(6), guess=[0.1, 0.2, 0.9, 0, 0, 0])
    assert r.success and abs(np.linalg.norm(r.pose[:3, 3]) - 1) < 1e-9
    assert local_dimension(get_model(m), r.qa, r.x, 1e-10) == 2


def test_generic_platform_has_dimension_zero():
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    modes = optkin.assembly_modes(m, DIET_L)
    assert len(modes) == 40 and modes.dimension == 0 and modes.components == []
    assert modes.info["complete"] is True


def test_an_isolated_double_root_is_not_a_continuum():
    # a five-bar whose distal links are in line (|A1 A2| = L2 + L3): the two assembly modes
    # merge into one double root, isolated (dimension 0) though W_p is singular there.
    # theta1 = pi/2 puts A1 at (0, 7); theta4 from |(8 + 7 c, 7 s - 7)| = 10, i.e.
    # 112 c - 98 s + 62 = 0
    m = optkin.mechanisms.five_bar(8.0, 7.0, 5.0, 5.0, 7.0)
    t4 = np.arccos(-62 / np.hypot(112, 98)) - np.arctan2(98, 112)
    A1, A2 = np.array([0.0, 7.0]), np.array([8.0, 0.0]) + 7 * np.array([np.cos(t4), np.sin(t4)])
    assert abs(np.linalg.norm(A2 - A1) - 10) < 1e-12
    r = optkin.forward(m, [np.pi / 2, t4])
    assert r.success and np.linalg.norm(r.pose[:2, 3] - (A1 + 0.5 * (A2 - A1))) < 1e-4
    assert r.cond > 1e5  # near the double root
    assert local_dimension(get_model(m), r.qa, r.x, 1e-9) == 0


def test_projection_and_grouping_on_two_circles():
    # two separate continua: the congruent 3-RPR's circle, sampled twice apart, is one
    # component; adding points from another leg length gives none joined to it
    m = optkin.mechanisms.rpr3(TRI, TRI)
    model = get_model(m)
    qa = np.full(3, 0.5)
    pts = []
    for ang in np.linspace(0, 2 * np.pi, 7)[:-1]:
        y, res, ok = project(model, qa, np.array([0.45 * np.cos(ang), 0.45 * np.sin(ang),
                                                  0.01]), 1e-11)
        assert ok and abs(np.hypot(*y[:2]) - 0.5) < 1e-9
        pts.append(y)
    assert group(model, qa, pts, 1e-11) == [list(range(6))]


def test_continua_option_is_validated():
    m = optkin.mechanisms.rpr3(TRI, TRI)
    with pytest.raises(optkin.MechanismError, match="continua must be True or False"):
        optkin.assembly_modes(m, [0.5, 0.5, 0.5], continua=1)
    plain = optkin.assembly_modes(m, [0.5, 0.5, 0.5], continua=False)
    assert plain.components == [] and plain.info["complete"] is False  # > bound: not complete


def test_the_account_is_typed_and_adds_up():
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.3, 0.9]], [[0, 0], [0.25, 0], [0.1, 0.2]])
    modes = optkin.assembly_modes(m, [0.6, 0.7, 0.65], method="multistart")
    st = modes.stats
    assert isinstance(st, optkin.results.EnumerationStats) and st.method == "multistart"
    assert st.paths == modes.info["starts"] and st.finite == modes.info["converged"]
    assert st.paths == st.finite + st.at_infinity + st.failed
    assert st.root_count == 6 and st.singular == 0
    assert modes.complete is st.complete is modes.info["complete"] is False  # 2 of 6 real
    assert "converged" in modes.summary() and modes.to_dict()["stats"]["method"] == "multistart"
    # a continuum: singular samples counted, never complete
    circle = optkin.assembly_modes(optkin.mechanisms.rpr3(TRI, TRI), [0.5, 0.5, 0.5])
    n_samples = sum(len(c.samples) for c in circle.components)
    assert circle.stats.singular >= n_samples > 0 and circle.complete is False


def test_inverse_gives_the_same_account():
    # closed form (every branch of every leg): complete; a numerical search: every start
    # accounted for, completeness not claimed
    m = optkin.mechanisms.rpr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.2, -0.1], [0.25, -0.2],
                                                              [0.05, 0.25]])
    p = optkin.inverse(m, [0.45, 0.35, 0.1])
    assert p.stats.method == "closed-form" and p.complete and p.stats.finite >= len(p)
    sr = optkin.mechanisms.sr400()
    q = optkin.forward(sr, [0.3, -0.4, 0.2, 0.5, 0.4, 0.6], guess=[np.pi / 2 + 1, -1, np.pi + 1])
    inv = optkin.inverse(sr, q.pose)
    st = inv.stats
    assert st.method == "multistart" and not inv.complete
    assert st.paths == inv.info["starts"] == st.finite + st.failed
    assert f"of {st.paths} starts converged" in inv.summary()
