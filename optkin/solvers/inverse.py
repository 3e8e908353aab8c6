"""The inverse geometric model: every posture for a given end-effector pose.

Leg-described platforms are solved leg by leg in closed form (seed 003): each leg has one
or two postures, and the set holds every combination, labelled with its working mode (the
sign of each diagonal entry of B, seed 004). Khalil mechanisms solve the direct path and the
loops together: the square system [Phi(q); task error(q)] = 0 over all joints is solved by
batched Newton from low-discrepancy starts, and distinct solutions are kept (seed 000, 7.6).
"""

from __future__ import annotations

import itertools
from typing import Any

import casadi as ca
import numpy as np
from scipy.stats import qmc

from ..mechanism import Mechanism
from ..mechanism.geometry import wrap_angle
from ..mechanism.legs import leg_inverse
from ..mechanism.tasks import as_pose
from ..model import Model, get_model
from ..model import khalil as kh
from ..model.core import damped_step
from ..results import KinResult, SolutionSet, SolverStats
from .common import make_result, merge_options, newton, timer

__all__ = ["inverse", "INVERSE_DEFAULTS", "distinct"]

#: Options of :func:`inverse` and their defaults.
INVERSE_DEFAULTS: dict[str, Any] = {
    "tol": 1e-10,  # max |Phi| (and task error) for a solution
    "starts": 256,  # Khalil mechanisms: number of Newton starts
    "iters": 60,  # Khalil mechanisms: Newton iterations per start
    "seed": 0,
}


def inverse(mech: Mechanism, pose: Any, **options: Any) -> SolutionSet:
    """Inverse geometric model: all postures reaching ``pose``.

    Parameters
    ----------
    mech : Mechanism
    pose : array
        A 4x4 homogeneous matrix, or task coordinates (``mech.task``): planar (x, y, phi),
        planar point (x, y), spatial (x, y, z, roll, pitch, yaw), translational (x, y, z).

    Returns
    -------
    SolutionSet
        One :class:`KinResult` per posture (empty, with ``info["message"]``, when the pose is
        out of reach). For platforms each result carries ``posture`` (the branch of each
        leg) and ``working_mode`` (the sign of each B_jj).

    Examples
    --------
    >>> import optkin
    >>> m = optkin.mechanisms.five_bar(1.0, 1.0, 1.0, 1.0, 1.0)
    >>> len(optkin.inverse(m, [0.5, 1.2]))
    4
    """
    opts = merge_options(INVERSE_DEFAULTS, options, "inverse")
    model = get_model(mech)
    T = as_pose(mech, pose)
    if mech.kind == "legs":
        return _inverse_legs(model, T, float(opts["tol"]))
    return _inverse_khalil(model, T, opts)


def _inverse_legs(model: Model, T: np.ndarray, tol: float) -> SolutionSet:
    mech = model.mech
    t0 = timer()
    R, p = T[:3, :3], T[:3, 3]
    if mech.planar:
        R, p = R[:2, :2], p[:2]
    per_leg = []
    for i, leg in enumerate(mech.legs):
        sols = leg_inverse(leg, R, p)
        if not sols:
            return SolutionSet(
                [], "postures",
                {"success": False, "message": f"leg {i + 1} ({leg.type}) cannot reach this pose"},
            )
        per_leg.append(sols)
    x = model.x_from_pose(T)
    out: list[KinResult] = []
    act = np.array(mech.actuated)
    for combo in itertools.product(*[range(len(s)) for s in per_leg]):
        q = np.concatenate([per_leg[i][c][0] for i, c in enumerate(combo)])
        qa = q[act]
        if np.any(qa[[n.endswith(".rho") for n in mech.active_names]] <= 0):
            continue
        _, _, Wa = model.jac(qa, x)
        wm = tuple(int(np.sign(v)) for v in np.diag(np.array(Wa)))
        stats = SolverStats("closed-form", 0.0, timer() - t0, 0, "legs")
        r = make_result(model, qa, x, tol, 0, stats, posture=tuple(combo), working_mode=wm)
        r.q = q  # the closed-form joint values of this posture
        out.append(r)
    return SolutionSet(out, "postures", {"success": bool(out), "message": f"{len(out)} postures"})


def _inverse_system(model: Model) -> tuple[ca.Function, ca.Function, np.ndarray, np.ndarray]:
    """Newton step and residual of [Phi(q); task error(q)] = 0 over all joints (cached)."""
    if model._inv is not None:
        return model._inv
    mech = model.mech
    nq = len(mech.joint_names)
    q = ca.SX.sym("q", nq)
    Td = ca.SX.sym("Td", 4, 4)
    T = kh.frames_0(mech, q)
    rows, names = kh.closure_rows(mech, T)
    keep = [names.index(n) for n in model.row_names]
    phi = rows[keep]
    Te = T[mech.end_effector]
    comps = {"x": Te[0, 3] - Td[0, 3], "y": Te[1, 3] - Td[1, 3], "z": Te[2, 3] - Td[2, 3]}
    g = kh.gibbs(ca.mtimes(Te[:3, :3], Td[:3, :3].T))
    comps.update({"rx": g[0], "ry": g[1], "rz": g[2]})
    G = ca.vertcat(phi, *[comps[c] for c in mech.task])
    if G.shape[0] != nq:
        from ..errors import MechanismError

        raise MechanismError(
            f"task: the inverse model needs as many equations as joints: {phi.shape[0]} closure "
            f"rows + {len(mech.task)} task components != {nq} joints; choose task components "
            "matching the degrees of freedom"
        )
    J = ca.jacobian(G, q)
    revolute = np.array(mech.revolute, dtype=bool)
    scale = np.where(revolute, 1.0, model.length)
    dq = -ca.solve(J, G)
    fG = ca.Function("G", [q, Td], [G])
    qn = damped_step(fG, q, dq, scale, [Td])
    step = ca.Function("inv_step", [q, Td], [qn, ca.mmax(ca.fabs(G))])
    res = ca.Function("inv_res", [q, Td], [G])
    model._inv = (step, res, revolute, scale)
    return model._inv


def distinct(
    X: np.ndarray, angle: np.ndarray, scale: np.ndarray, tol: float = 1e-6
) -> list[int]:
    """Indices of the distinct columns of X (angles compared modulo 2 pi)."""
    keep: list[int] = []
    for j in range(X.shape[1]):
        new = True
        for k in keep:
            d = X[:, j] - X[:, k]
            d[angle] = wrap_angle(d[angle])
            if np.max(np.abs(d) / scale) < tol:
                new = False
                break
        if new:
            keep.append(j)
    return keep


def _inverse_khalil(model: Model, T: np.ndarray, opts: dict[str, Any]) -> SolutionSet:
    mech = model.mech
    step, res, revolute, scale = _inverse_system(model)
    nq = len(mech.joint_names)
    n = int(opts["starts"])
    tol = float(opts["tol"])
    t0 = timer()
    sob = qmc.Sobol(nq, scramble=True, seed=int(opts["seed"]))
    U = sob.random(n)
    lo = np.where(revolute, -np.pi, -2 * model.length)
    hi = np.where(revolute, np.pi, 2 * model.length)
    Q = (lo + U * (hi - lo)).T  # nq x n
    fmap = step.map(n, "thread", 2)
    Td = np.tile(T, (1, n))
    r = np.full(n, np.inf)
    for _ in range(int(opts["iters"])):
        Qn, r = fmap(Q, Td)
        Qn = np.array(Qn)
        r = np.array(r).ravel()
        good = np.all(np.isfinite(Qn), axis=0)
        Q[:, good] = Qn[:, good]
    _, r = fmap(Q, Td)
    r = np.array(r).ravel()
    ok = np.flatnonzero(r <= 1e3 * tol)
    Qok = Q[:, ok]
    Qok[revolute] = wrap_angle(Qok[revolute])
    idx = distinct(Qok, revolute, scale, 1e-6)
    act = np.array(mech.actuated)
    out: list[KinResult] = []
    for j in idx:
        q = Qok[:, j]
        # final polish of the closure with the active joints fixed
        qa = q[act]
        x, _, nit, _ = newton(model, qa, q[~act], tol, 5)
        stats = SolverStats("newton-multistart", 0.0, timer() - t0, int(opts["iters"]), "khalil",
                            {"starts": n, "converged": int(ok.size)})
        kr = make_result(model, qa, x, tol, nit, stats)
        task_err = float(np.max(np.abs(np.array(res(kr.q, T)).ravel())))
        if task_err > 1e-8:
            continue
        out.append(kr)
    info = {"success": bool(out), "starts": n, "converged": int(ok.size),
            "message": f"{len(out)} postures from {n} starts ({ok.size} converged)"}
    return SolutionSet(out, "postures", info, seed=int(opts["seed"]))
