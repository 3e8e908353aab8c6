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

from .._dryrun import checkpoint
from ..errors import MechanismError
from ..limits import Deadline
from ..mechanism import Mechanism
from ..mechanism.geometry import wrap_angle
from ..mechanism.legs import leg_inverse
from ..mechanism.tasks import as_pose
from ..model import Model, compiled, get_model
from ..model import khalil as kh
from ..model.core import damped_step
from ..results import KinResult, SolutionSet, SolverStats
from .common import count_option, make_result, merge_options, newton, timer

__all__ = ["inverse", "INVERSE_DEFAULTS", "distinct"]

#: Options of :func:`inverse` and their defaults.
INVERSE_DEFAULTS: dict[str, Any] = {
    "tol": 1e-10,  # max |Phi| (and task error) for a solution
    "starts": 256,  # Khalil mechanisms: number of Newton starts
    "iters": 60,  # Khalil mechanisms: Newton iterations per start
    "seed": 0,
}

#: Largest accepted ``starts`` and ``iters`` (bounded work and memory per call).
MAX_STARTS = 2**16
MAX_ITERS = 1000


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
    for k, lo, hi in (("starts", 1, MAX_STARTS), ("iters", 0, MAX_ITERS), ("seed", 0, 2**63 - 1)):
        opts[k] = count_option(opts, k, "inverse", lo, hi, INVERSE_DEFAULTS)
    if not np.isfinite(opts["tol"]):
        raise MechanismError(f"inverse: option tol must be a finite number >= 0 (default "
                             f"{INVERSE_DEFAULTS['tol']!r}), got {opts['tol']!r}",
                             path=("options", "tol"))
    model = get_model(mech)
    T = as_pose(mech, pose)
    checkpoint()  # validation stops here: every argument is checked
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
        ev = model.fast("W")  # buffered (compiled when available) evaluation
        ev(qa, x)
        wm = tuple(int(np.sign(v)) for v in np.diag(ev.dense(2)))
        stats = SolverStats("closed-form", 0.0, timer() - t0, 0, "legs")
        r = make_result(model, qa, x, tol, 0, stats, posture=tuple(combo), working_mode=wm)
        r.q = q  # the closed-form joint values of this posture
        out.append(r)
    return SolutionSet(out, "postures", {"success": bool(out), "message": f"{len(out)} postures"})


def _newton_function(name, G, z, params, scale):
    """A damped Newton step on G(z; params) = 0 and the residual max |G| (CasADi Function)."""
    J = ca.jacobian(G, z)
    dz = -ca.solve(J, G)
    fG = ca.Function(name + "_G", [z, *params], [G])
    zn = damped_step(fG, z, dz, scale, params)
    step = ca.Function(name, [z, *params], [zn, ca.mmax(ca.fabs(G))])
    return step, fG


def _inverse_system(model: Model) -> dict[str, Any]:
    """The Functions of the Khalil inverse model (cached on the model).

    Following seed 000, 7.6: first the joints of the direct path base -> end effector are
    solved from the task equations, then the remaining joints from the loop closure. When
    the joint counts do not split that way, the whole system [Phi(q); task(q)] = 0 over all
    joints is used instead.
    """
    if model._inv is not None:
        return model._inv
    mech = model.mech
    nq = len(mech.joint_names)
    q = ca.SX.sym("q", nq)
    Td = ca.SX.sym("Td", 4, 4)
    T = kh.frames_0(mech, q)
    rows, names = kh.closure_rows(mech, T)
    phi = rows[[names.index(n) for n in model.row_names]]
    Te = T[mech.end_effector]
    comps = {"x": Te[0, 3] - Td[0, 3], "y": Te[1, 3] - Td[1, 3], "z": Te[2, 3] - Td[2, 3]}
    g = kh.gibbs(ca.mtimes(Te[:3, :3], Td[:3, :3].T))
    comps.update({"rx": g[0], "ry": g[1], "rz": g[2]})
    task = ca.vertcat(*[comps[c] for c in mech.task])
    if phi.shape[0] + task.shape[0] != nq:
        raise MechanismError(
            f"task: the inverse model needs as many equations as joints: {phi.shape[0]} closure "
            f"rows + {len(mech.task)} task components != {nq} joints; choose task components "
            "matching the degrees of freedom"
        )
    revolute = np.array(mech.revolute, dtype=bool)
    scale = np.where(revolute, 1.0, model.length)
    index = {n: i for i, n in enumerate(mech.joint_names)}
    path = [index[f.name] for f in (mech.table.frames[j - 1] for j in mech.table.chain(
        mech.end_effector)) if f.is_joint]
    off = [i for i in range(nq) if i not in path]
    out: dict[str, Any] = {"revolute": revolute, "scale": scale, "path": path, "off": off,
                           "task": ca.Function("task", [q, Td], [task])}
    if len(path) == task.shape[0] and len(off) == phi.shape[0]:
        zp, zo = ca.SX.sym("zp", len(path)), ca.SX.sym("zo", len(off))
        qq = ca.SX.zeros(nq)
        qq[path] = zp
        qq[off] = zo
        t1 = ca.substitute(task, q, qq)
        # the task equations depend on the path joints only ([7.11])
        t1 = ca.substitute(t1, zo, ca.DM.zeros(len(off)))
        out["stage1"] = _newton_function("inv_path", t1, zp, [Td], scale[path])[0]
        p2 = ca.substitute(phi, q, qq)
        out["stage2"] = _newton_function("inv_loops", p2, zo, [zp], scale[off])[0]
    else:
        G = ca.vertcat(phi, task)
        out["joint"] = _newton_function("inv_all", G, q, [Td], scale)[0]
    # compiled C versions of the batched Newton steps when a compiler is present (the
    # interpreted steps took ~90 % of the time of a Khalil inverse; optkin.model.compiled)
    keys = [k for k in ("stage1", "stage2", "joint") if k in out]
    lib = compiled.library("inv:" + mech.key, [out[k] for k in keys])
    if lib is not None:
        for k in keys:
            out[k] = lib[out[k].name()]
    model._inv = out
    return out


_MAPS: dict[tuple[str, int], tuple[ca.Function, ca.Function]] = {}


def _multistart(step, params: np.ndarray, lo, hi, n: int, iters: int, seed: int,
                deadline: Deadline | None = None):
    """Batched Newton from n Sobol starts in the box [lo, hi]; returns (Z, residuals).

    The iterations stop early when ``deadline`` expires (the residuals say what converged).
    """
    dim = len(lo)
    U = qmc.Sobol(dim, scramble=True, seed=seed).random(n)
    Z = (lo + U * (hi - lo)).T
    key = (step.name(), n)
    fmap = _MAPS.get(key)
    if fmap is None or fmap[0] is not step:
        fmap = (step, step.map(n, "thread", 2))
        _MAPS[key] = fmap
    fmap = fmap[1]
    P = np.tile(params, (1, n))
    for _ in range(iters):
        if deadline is not None and deadline.expired():
            break
        Zn, _ = fmap(Z, P)
        Zn = np.array(Zn)
        good = np.all(np.isfinite(Zn), axis=0)
        Z[:, good] = Zn[:, good]
    _, r = fmap(Z, P)
    return Z, np.array(r).ravel()


def distinct(
    X: np.ndarray, angle: np.ndarray, scale: np.ndarray, tol: float = 1e-6
) -> list[int]:
    """Indices of the distinct columns of X (angles compared modulo 2 pi)."""
    keep: list[int] = []
    sc = np.reshape(np.asarray(scale, dtype=float), (-1, 1))
    for j in range(X.shape[1]):
        if keep:  # compare with every kept column at once
            d = X[:, keep] - X[:, j:j + 1]
            d[angle] = wrap_angle(d[angle])
            if np.min(np.max(np.abs(d) / sc, axis=0)) < tol:
                continue
        keep.append(j)
    return keep


def _inverse_khalil(model: Model, T: np.ndarray, opts: dict[str, Any]) -> SolutionSet:
    mech = model.mech
    sysf = _inverse_system(model)
    revolute, scale = sysf["revolute"], sysf["scale"]
    nq = len(mech.joint_names)
    n, iters, seed = int(opts["starts"]), int(opts["iters"]), int(opts["seed"])
    tol = float(opts["tol"])
    t0 = timer()
    deadline = Deadline()  # the time budget of one call (optkin.limits)
    lo = np.where(revolute, -np.pi, -2 * model.length)
    hi = np.where(revolute, np.pi, 2 * model.length)
    candidates: list[np.ndarray] = []
    runs = 0
    if "stage1" in sysf:
        path, off = sysf["path"], sysf["off"]
        Zp, r1 = _multistart(sysf["stage1"], T, lo[path], hi[path], n, iters, seed, deadline)
        runs += n
        ok1 = np.flatnonzero(r1 <= 1e3 * tol)
        Zp = Zp[:, ok1]
        Zp[revolute[path]] = wrap_angle(Zp[revolute[path]])
        for j in distinct(Zp, revolute[path], scale[path]):
            if deadline.expired():
                break
            zp = Zp[:, j]
            n2 = max(32, n // 4)
            Zo, r2 = _multistart(sysf["stage2"], zp[:, None], lo[off], hi[off], n2, iters,
                                 seed + 1, deadline)
            runs += n2
            for i in np.flatnonzero(r2 <= 1e3 * tol):
                qv = np.empty(nq)
                qv[path] = zp
                qv[off] = Zo[:, i]
                candidates.append(qv)
    else:
        Q, r = _multistart(sysf["joint"], T, lo, hi, n, iters, seed, deadline)
        runs += n
        candidates = [Q[:, i] for i in np.flatnonzero(r <= 1e3 * tol)]
    converged = len(candidates)
    if candidates:
        Q = np.array(candidates).T
        Q[revolute] = wrap_angle(Q[revolute])
        idx = distinct(Q, revolute, scale, 1e-6)
    else:
        Q, idx = np.zeros((nq, 0)), []
    act = np.array(mech.actuated)
    out: list[KinResult] = []
    outside = 0
    for j in idx:
        q = Q[:, j]
        qa = q[act]
        # final polish of the closure with the active joints fixed
        x, _, nit, _ = newton(model, qa, q[~act], tol, 5)
        stats = SolverStats("newton-multistart", 0.0, timer() - t0, iters, "khalil",
                            {"starts": runs, "converged": converged})
        kr = make_result(model, qa, x, tol, nit, stats)
        task_err = float(np.max(np.abs(np.array(sysf["task"](kr.q, T)).ravel())))
        if not kr.success or task_err > 1e-8:
            continue
        if not mech.within_limits(kr.q):
            outside += 1
            continue
        out.append(kr)
    method = "direct path then loops (7.6)" if "stage1" in sysf else "all joints"
    info = {"success": bool(out), "starts": runs, "converged": converged, "method": method,
            "outside_limits": outside,
            "message": f"{len(out)} postures from {runs} starts ({converged} converged; {method})"
            + (f"; {outside} outside the joint limits left out" if outside else "")}
    if deadline.expired():  # the enumeration was cut short: say so, never claim success
        info.update(success=False, status="time_limit",
                    message=deadline.message("inverse") + f"; {info['message']}")
    return SolutionSet(out, "postures", info, seed=seed)
