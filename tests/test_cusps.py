"""Assembly-mode changes without a singularity (optkin.analysis.cusps).

Evidence: the path returned is followed again here by a small-step Newton iteration on the
3-RPR's leg equations written in this file, with det A by hand (rows (P_i - A_i,
(R b_i) x (P_i - A_i)), tests/test_continuation.py); along it det A keeps its sign and the
end is the target mode, not the start. The 3-RPR is the cuspidal design of Zein, Wenger
and Chablat (A1 = (0, 0), A2 = (15.91, 0), A3 = (0, 10); sides 17.04, 16.54, 20.84).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_assembly_modes import DIET_A, DIET_B
from test_continuation import BASE3, PLAT3, rpr_det

import optkin
from optkin.analysis.cusps import is_cuspidal, mode_change_path

QA = np.array([14.98, 13.85146, 6.7713])  # inside the wedge of a cusp of the section


def _legs(x, rho):
    c, s = np.cos(x[2]), np.sin(x[2])
    R = np.array([[c, -s], [s, c]])
    d = x[:2] + PLAT3 @ R.T - BASE3
    return np.sum(d * d, axis=1) - rho**2


def _newton(x, rho):
    for _ in range(30):
        F = _legs(x, rho)
        J = np.empty((3, 3))
        for k in range(3):
            e = np.zeros(3)
            e[k] = 1e-7
            J[:, k] = (_legs(x + e, rho) - _legs(x - e, rho)) / 2e-7
        dx = np.linalg.solve(J, F)
        x = x - dx
        if np.max(np.abs(dx)) < 1e-12:
            return x
    raise AssertionError("the test's Newton iteration did not converge")


def _retrack(path, x0, sub=8):
    """The test's own continuation: ``sub`` plain Newton sub-steps per path segment."""
    xs, dets = [x0], [rpr_det(*x0)]
    x = x0
    for a, b in zip(path[:-1], path[1:]):
        for s in np.linspace(0, 1, sub + 1)[1:]:
            x = _newton(x, (1 - s) * a + s * b)
            dets.append(rpr_det(*x))
        xs.append(x)
    return np.array(xs), np.array(dets)


@pytest.fixture(scope="module")
def rpr():
    return optkin.mechanisms.rpr3(BASE3, PLAT3)


def _gap(a, b):
    """|a - b| with the angle phi compared modulo 2 pi."""
    d = np.abs(np.asarray(a) - np.asarray(b))
    d[..., 2] = np.abs((d[..., 2] + np.pi) % (2 * np.pi) - np.pi)
    return d


def _check_path(r, rpr):
    modes = optkin.assembly_modes(rpr, r.qa)
    X, dets = _retrack(r.qa_path, r.start)
    assert np.all(np.sign(dets) == np.sign(dets[0])), "det A changed sign"
    assert np.min(np.abs(dets)) > 1e-6 * np.max(np.abs(dets))
    assert np.max(_gap(X, r.x)) < 1e-7  # the path optkin reports is the same
    assert np.max(_gap(X[-1], r.target)) < 1e-7  # it ends at the target ...
    assert np.max(_gap(X[-1], r.start)) > 1e-2  # ... which is another mode
    assert min(np.max(_gap(X[-1], m.x)) for m in modes) < 1e-7
    np.testing.assert_allclose(r.qa_path[0], r.qa)
    np.testing.assert_allclose(r.qa_path[-1], r.qa)


def test_mode_change_path_on_the_cuspidal_3rpr(rpr):
    modes = optkin.assembly_modes(rpr, QA)
    assert len(modes) == 6
    r = mode_change_path(rpr, QA, 1, 2)
    assert r.success and r.status == "optimal", r.message
    assert r.modes == [1, 2] and len(r.cusps) == 1
    assert np.allclose(r.qa_path[:, 0], QA[0])  # in the section rho1 = qa[0]
    assert 0 < r.min_conditioning < 1
    _check_path(r, rpr)
    assert r.to_dict()["success"] is True


def test_modes_in_different_aspects_are_refused(rpr):
    modes = optkin.assembly_modes(rpr, QA)
    d = [np.sign(rpr_det(*m.x)) for m in modes]
    i, j = 0, next(k for k in range(1, len(modes)) if d[k] != d[0])
    r = mode_change_path(rpr, QA, i, j)
    assert not r.success and r.status == "infeasible"
    assert "different aspects" in r.message and f"modes {i} and {j}" in r.message
    assert len(r.qa_path) == 0


def test_is_cuspidal_gives_a_path_as_evidence(rpr):
    res = is_cuspidal(rpr, sections=[14.98])
    assert res.cuspidal is True and bool(res)
    _check_path(res.evidence, rpr)


def test_bad_arguments(rpr):
    with pytest.raises(optkin.MechanismError, match="start = 9 is not an assembly mode"):
        mode_change_path(rpr, QA, 9, 0)
    with pytest.raises(optkin.MechanismError, match="same assembly mode"):
        mode_change_path(rpr, QA, 1, 1)
    with pytest.raises(optkin.MechanismError, match="qa must be 3 finite numbers"):
        mode_change_path(rpr, [1.0, 2.0], 0, 1)
    with pytest.raises(optkin.MechanismError, match="depth must be an integer >= 1"):
        mode_change_path(rpr, QA, 1, 2, depth=0)
    with pytest.raises(optkin.MechanismError, match="radius"):
        mode_change_path(rpr, QA, 1, 2, radius=-1.0)
    with pytest.raises(optkin.MechanismError, match="time_limit"):
        is_cuspidal(rpr, time_limit=float("nan"))
    refused = mode_change_path(rpr, QA, 0, 1)
    with pytest.raises(optkin.MechanismError, match="no path"):
        refused.plot()
    m = optkin.mechanisms.stewart_gough(DIET_A, DIET_B)
    with pytest.raises(optkin.MechanismError, match="needs 2 or 3 actuated joints"):
        mode_change_path(m, np.ones(6), 0, 1)


def test_pictures(rpr, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r = mode_change_path(rpr, QA, 1, 2)
    fig, ax = plt.subplots()
    assert r.plot(ax=ax) is fig
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "mode-change path" in labels and "cusp looped" in labels
    assert ax.get_xlabel() == "L2.rho" and ax.get_ylabel() == "L3.rho"
    plt.close(fig)
    out = tmp_path / "change.gif"
    anim = r.animate(str(out), frames=3)
    assert out.stat().st_size > 1000 and anim is not None
    plt.close("all")
    refused = mode_change_path(rpr, QA, 0, 1)
    with pytest.raises(optkin.MechanismError, match="no path"):
        refused.animate()


def _cusp_ratio(rho1, psi, phi, e=1e-6):
    """|J tau| / (|J| |tau|) at the configuration with leg 1 of length rho1 at angle psi
    and orientation phi: tau the tangent of det A = 0 in (psi, phi), J the Jacobian of
    (rho2, rho3); zero at a cusp of the section's joint-space curve (finite differences,
    as in tests/test_continuation.py, with rho1 free)."""
    def pose(a, b):
        c, s = np.cos(b), np.sin(b)
        x = BASE3[0, 0] + rho1 * np.cos(a) - (c * PLAT3[0, 0] - s * PLAT3[0, 1])
        y = BASE3[0, 1] + rho1 * np.sin(a) - (s * PLAT3[0, 0] + c * PLAT3[0, 1])
        rh = [np.hypot(x + c * bb[0] - s * bb[1] - A[0], y + s * bb[0] + c * bb[1] - A[1])
              for A, bb in zip(BASE3[1:], PLAT3[1:])]
        return x, y, np.array(rh)

    def D(a, b):
        x, y, _ = pose(a, b)
        return rpr_det(x, y, b)

    g = np.array([(D(psi + e, phi) - D(psi - e, phi)) / (2 * e),
                  (D(psi, phi + e) - D(psi, phi - e)) / (2 * e)])
    tau = np.array([-g[1], g[0]])
    J = np.stack([(pose(psi + e, phi)[2] - pose(psi - e, phi)[2]) / (2 * e),
                  (pose(psi, phi + e)[2] - pose(psi, phi - e)[2]) / (2 * e)], 1)
    return np.linalg.norm(J @ tau) / (np.linalg.norm(J) * np.linalg.norm(tau))


def test_cusp_curves_of_the_cuspidal_3rpr(rpr):
    lim = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
    c = optkin.cusp_curves(rpr, limits=lim, slices=12)
    assert c.success and len(c) >= 3, c.message
    ratios = []
    for V in c.v:
        assert np.all(np.diff(V[:, 0]) > 0)  # ordered along rho1, one point per section
        for v in V:
            x, y, phi = v[3:]
            P1 = np.array([x + np.cos(phi) * PLAT3[0, 0] - np.sin(phi) * PLAT3[0, 1],
                           y + np.sin(phi) * PLAT3[0, 0] + np.cos(phi) * PLAT3[0, 1]])
            psi = np.arctan2(*(P1 - BASE3[0])[::-1])
            assert abs(np.hypot(*(P1 - BASE3[0])) - v[0]) < 1e-8
            ratios.append(_cusp_ratio(v[0], psi, phi))
            assert abs(rpr_det(x, y, phi)) < 1e-9 * 40**3
    assert max(ratios) < 1e-4
    assert all(10 <= p <= 30 for p in np.ravel(c.points))


def test_is_cuspidal_stops_at_its_time_limit():
    """The five-bar's joint space has 20 cusps and no mode change to find (52 s of loops):
    the search stops at its time limit and says it proves nothing."""
    import time

    m = optkin.mechanisms.five_bar(9.0, 8.0, 5.0, 5.0, 8.0)
    t0 = time.perf_counter()
    res = is_cuspidal(m, time_limit=3.0)
    assert time.perf_counter() - t0 < 20
    assert res.cuspidal is None and "time limit" in res.message and "not a proof" in res.message
