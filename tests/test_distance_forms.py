"""The two closures of a distance leg agree, for every distance leg type.

A distance leg (RPR, RRR, PRR, UPS, SPS, RUS, RSS, PUS, and the Delta's arms) is solved by
default in its one-row form |P - C(q_a)| = l (``from_legs(..., reduced=True)``); with
``reduced=False`` the same legs close as joint-level chains (product of exponentials, one
row per component of the platform frame). Two independent formulations of one mechanism:
at random poses both inverse models give the same actuated values, and ``forward`` of the
chain form lands on the pose the reduced form was given. The leg lengths are also checked
against |P - C| written out here for the legs whose centre does not move (UPS, SPS, RPR).
"""

from __future__ import annotations

import numpy as np
import pytest

import optkin
from optkin import mechanisms as M
from optkin.mechanism import LEG_TYPES


def _stewart_specs(kind: str) -> tuple[list[dict], np.ndarray, np.ndarray]:
    ab = np.deg2rad([-10, 10, 110, 130, 230, 250])
    ap = np.deg2rad([-50, 50, 70, 170, 190, 290])
    base = np.c_[np.cos(ab), np.sin(ab), np.zeros(6)]
    plat = 0.5 * np.c_[np.cos(ap), np.sin(ap), np.zeros(6)]
    return ([{"type": kind, "base": base[i].tolist(), "platform": plat[i].tolist()}
             for i in range(6)], base, plat)


def _rss_specs() -> list[dict]:
    legs = []
    for i in range(6):
        a = 2 * np.pi * (i // 2) / 3 + (-0.3 if i % 2 == 0 else 0.3)
        b = 2 * np.pi * (i // 2) / 3 + (-0.25 if i % 2 == 0 else 0.25)
        u = np.array([np.cos(a), np.sin(a), 0.0])
        t = np.array([-np.sin(a), np.cos(a), 0.0])
        legs.append({"type": "RSS", "base": (0.5 * u).tolist(),
                     "platform": [0.15 * np.cos(b), 0.15 * np.sin(b), 0.0],
                     "lengths": [0.35, 0.8], "axis": t.tolist(), "arm": u.tolist()})
    return legs


#: name -> (legs, platform, a pose, the pose's random spread)
CASES = {
    "RPR": (M.rpr3([[0, 0], [1, 0], [0.5, 0.9]], [[-0.2, -0.1], [0.25, -0.2], [0.05, 0.25]]).legs,
            "planar", [0.45, 0.35, 0.1], 0.05),
    "RRR": (M.rrr3([[0, 0], [1, 0], [0.5, 0.9]], [[0, 0], [0.2, 0], [0.1, 0.17]], 0.6, 0.6).legs,
            "planar", [0.45, 0.3, 0.1], 0.03),
    "PRR": (M.prr3([[0, 0], [2, 0], [1, 2]], [[1, 0], [0, 1], [-1, 0]],
                   [[-0.2, -0.1], [0.2, -0.1], [0, 0.2]], 1.5).legs,
            "planar", [1.0, 1.0, 0.1], 0.05),
    "UPS": (_stewart_specs("UPS")[0], "spatial", [0.05, -0.03, 1.0, 0.1, -0.05, 0.2], 0.03),
    "SPS": (_stewart_specs("SPS")[0], "spatial", [0.05, -0.03, 1.0, 0.1, -0.05, 0.2], 0.03),
    "RUS": (M.hexa().legs, "spatial", [0.0, 0.0, -0.6, 0.0, 0.0, 0.0], 0.02),
    "RSS": (_rss_specs(), "spatial", [0.0, 0.0, -0.6, 0.0, 0.0, 0.0], 0.02),
    "PUS": (M.pus6().legs, "spatial", [0.0, 0.0, 0.6, 0.0, 0.0, 0.0], 0.03),
    "Delta": (M.delta(0.2, 0.05, 0.3, 0.8).legs, "spatial_translational", [0.02, -0.01, -0.7], 0.03),
}


def test_every_distance_leg_type_is_covered():
    """The cases above hold every leg type whose builder gives a distance leg."""
    distance = set()
    for name in LEG_TYPES:
        for legs, _platform, *_ in CASES.values():
            for leg in legs:
                t = leg.type if isinstance(leg, optkin.Leg) else leg["type"]
                if t == name:
                    distance.add(name)
    built = {t for t in LEG_TYPES
             if any(leg.distance is not None
                    for legs, platform, *_ in CASES.values()
                    for leg in optkin.Mechanism.from_legs(legs, platform).legs
                    if leg.type == t)}
    assert built == distance == {"RPR", "RRR", "PRR", "UPS", "SPS", "RUS", "RSS", "PUS"}


def _sorted_rows(sols, rev) -> np.ndarray:
    """The distinct actuated values of a set of postures, sorted (a leg in chain form may
    reach one leg line in two postures of its passive joints, e.g. a universal joint's two
    readings: one q_a)."""
    Q = np.array([np.asarray(s.qa, dtype=float) for s in sols])
    Q[:, rev] = (Q[:, rev] + np.pi) % (2 * np.pi) - np.pi
    Q = Q[np.lexsort(np.round(Q, 6).T[::-1])]
    keep = [0] + [i for i in range(1, len(Q)) if np.max(np.abs(Q[i] - Q[i - 1])) > 1e-9]
    return Q[keep]


def _pose(mech, s) -> np.ndarray:
    return np.asarray(s.pose, dtype=float)


#: Chain-form inverses of six-leg crank and slider platforms search 2^6 leg postures
#: (about 5 s a pose): in the slow run (the Delta's RUS arms stay in the default one).
SLOW = {"RUS", "RSS", "PUS"}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n
                                  for n in CASES])
def test_reduced_and_chain_closures_agree(name):
    legs, platform, x0, spread = CASES[name]
    red = optkin.Mechanism.from_legs(legs, platform)
    chain = optkin.Mechanism.from_legs(legs, platform, reduced=False)
    assert red.topology != chain.topology  # two formulations, two models
    rng = np.random.default_rng(7)
    for _ in range(2):
        x = np.asarray(x0, dtype=float) + spread * rng.uniform(-1, 1, len(x0))
        a, b = optkin.inverse(red, x), optkin.inverse(chain, x)
        assert a.info.get("success", True) and len(a) > 0, name
        rev = np.array([red.revolute[i] for i in red.active_index], dtype=bool)
        Qa, Qb = _sorted_rows(a, rev), _sorted_rows(b, rev)
        assert Qa.shape == Qb.shape, (name, Qa.shape, Qb.shape)
        d = Qa - Qb
        d[:, rev] = (d[:, rev] + np.pi) % (2 * np.pi) - np.pi
        assert np.max(np.abs(d)) < 1e-9, name
        # forward of the chain form from a nearby guess lands on the pose
        s = a[0]
        f = optkin.forward(chain, s.qa, guess=np.asarray(x) + 1e-3)
        assert f.success, (name, f.message)
        np.testing.assert_allclose(_pose(chain, f), _pose(red, s), atol=1e-9)


@pytest.mark.parametrize("kind", ["UPS", "SPS"])
def test_leg_lengths_are_the_distances_written_out(kind):
    """For fixed centres: q_a,i = |p + R b_i - a_i| (Modern Robotics eq. 7.6)."""
    from scipy.spatial.transform import Rotation

    legs, base, plat = _stewart_specs(kind)
    chain = optkin.Mechanism.from_legs(legs, "spatial", reduced=False)
    x = np.array([0.05, -0.03, 1.0, 0.1, -0.05, 0.2])
    R = Rotation.from_euler("ZYX", x[[5, 4, 3]]).as_matrix()
    rho = np.linalg.norm(x[:3] + plat @ R.T - base, axis=1)
    sols = optkin.inverse(chain, x)
    assert len(sols) >= 1
    for s in sols:
        np.testing.assert_allclose(s.qa, rho, atol=1e-10)
