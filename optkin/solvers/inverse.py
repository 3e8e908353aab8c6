"""The inverse geometric model: every posture for a given end-effector pose.

The model splits the joint values into parts solved on their own (:mod:`optkin.model.
inverse`): a distance leg in closed form (Özgören: one or two postures per leg), a leg in
chain form or a Khalil table (Khalil & Dombre 2002, sec. 7.6) by batched Newton from low-discrepancy starts,
keeping distinct solutions. The postures are every combination of the parts' solutions,
labelled with their working mode (the sign of each diagonal entry of B, Chablat & Wenger 1998) where
the mechanism is fully parallel.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from .._checks import check_option
from .._dryrun import checkpoint
from ..limits import Deadline
from ..mechanism import Mechanism
from ..mechanism.geometry import wrap_angle
from ..mechanism.tasks import as_pose
from ..model import Model, get_model
from ..model.inverse import ClosedPart, SearchPart
from ..results import (
    INFEASIBLE,
    OPTIMAL,
    TIME_LIMIT,
    EnumerationStats,
    KinResult,
    SolutionSet,
    SolverStats,
)
from .common import check_mechanism, count_option, make_result, merge_options, newton, timer
from .enumerate import _sobol

__all__ = ["inverse", "INVERSE_DEFAULTS", "distinct"]

#: Options of :func:`inverse` and their defaults.
INVERSE_DEFAULTS: dict[str, Any] = {
    "tol": 1e-10,  # max |Phi| (and task error) for a solution
    "starts": 256,  # searched parts: number of Newton starts
    "iters": 60,  # searched parts: Newton iterations per start
    "seed": 0,  # searched parts: of the Sobol scrambling (a run is reproducible from it)
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
        leg) and ``working_mode`` (the sign of each B_jj) where that applies.

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
    opts["tol"] = check_option(opts, "tol", "inverse", INVERSE_DEFAULTS, lo=0.0)
    check_mechanism(mech, "inverse")
    model = get_model(mech)
    T = as_pose(mech, pose)
    checkpoint()  # validation stops here: every argument is checked
    return _inverse(model, T, opts)


def _inverse(model: Model, T: np.ndarray, opts: dict[str, Any]) -> SolutionSet:
    mech = model.mech
    tol = float(opts["tol"])
    n, iters, seed = int(opts["starts"]), int(opts["iters"]), int(opts["seed"])
    t0 = timer()
    deadline = Deadline()  # the time budget of one call (optkin.limits)
    nq = len(mech.joint_names)
    plat = model.platform
    xplat = plat.x_from_pose(T) if plat is not None else None
    parts = model.inverse_parts()
    per_part: list[list[np.ndarray]] = []  # for each part, its solutions as full-q patches
    runs = converged = 0
    searched = False
    for part in parts:
        if isinstance(part, ClosedPart):
            QA, Q, V = (np.array(v) for v in part.fn(xplat, model.p))
            sols = []
            rev = np.array(mech.revolute, dtype=bool)[part.q]
            act_q = np.flatnonzero(np.array(mech.actuated, dtype=bool))  # q index of each q_a
            rev_a = np.array(mech.revolute, dtype=bool)[act_q[list(part.qa)]]
            drivers: list[np.ndarray] = []
            for b in range(part.branches):
                if V[b, 0] < 0.5 or not np.all(np.isfinite(Q[b])):
                    continue
                qb = np.where(rev, wrap_angle(Q[b]), Q[b])
                # the branches are the two roots of the leg's driver: when they meet (a
                # stretched leg, a double root sqrt(eps) apart) they are one posture, even
                # where the passive angles derived from it differ (a universal joint at
                # its gimbal lock reads either of two equal configurations)
                d = np.atleast_1d(QA[b]).astype(float)
                if any(np.max(np.abs(np.where(rev_a, wrap_angle(d - d_), (d - d_) / model.length)),
                              initial=0.0) < 1e-7 for d_ in drivers):
                    continue
                drivers.append(d)
                sols.append(qb)
            if not sols:
                label = model.leg_labels[part.leg]
                # every branch of the leg's closed form examined: "none" is the whole answer
                return SolutionSet([], "postures", {
                    "success": False, "status": INFEASIBLE, "complete": True,
                    "message": f"leg {part.leg + 1} ({label}) cannot reach this pose"},
                    stats=EnumerationStats("closed-form", 0, 0, 0, 0, 0, 0, True))
            per_part.append([_patch(nq, part.q, q_) for q_ in sols])
        else:
            searched = True
            sols, r_, c_ = _search(model, part, T, xplat, n, iters, seed, tol, deadline)
            runs += r_
            converged += c_
            if not sols and part.leg >= 0:
                label = model.leg_labels[part.leg]
                return SolutionSet([], "postures", {
                    "success": False, "status": INFEASIBLE, "starts": runs, "complete": False,
                    "message": f"leg {part.leg + 1} ({label}) cannot reach this pose "
                               f"({n} starts)"},
                    seed=seed, stats=EnumerationStats("multistart", runs, converged, 0, 0,
                                                      max(0, runs - converged), None, False))
            per_part.append(sols)
    act = np.array(mech.actuated)
    out: list[KinResult] = []
    outside = 0
    combos = 0
    checks = [p_ for p_ in parts if isinstance(p_, SearchPart) and p_.check is not None]
    for combo in itertools.product(*[range(len(s_)) for s_ in per_part]):
        combos += 1
        q = np.zeros(nq)
        for i, c in enumerate(combo):
            patch = per_part[i][c]
            mask = ~np.isnan(patch)
            q[mask] = patch[mask]
        qa = q[act]
        if np.any(qa[model.qa_positive] <= 0):
            continue
        x = model.x_from_q(q, pose=T)
        if searched:  # polish the closure with the active joints fixed
            x, _, nit, _ = newton(model, qa, x, tol, 5)
        else:
            nit = 0
        stats = SolverStats("closed-form" if not searched else "newton-multistart", 0.0,
                            timer() - t0, nit, _method(parts),
                            {"starts": runs, "converged": converged} if searched else {})
        posture = tuple(combo) if plat is not None else None
        r = make_result(model, qa, x, tol, nit, stats, posture=posture,
                        working_mode=model.working_mode(qa, x))
        if not r.success:
            continue
        if any(float(np.max(np.abs(np.array(c_.check(r.q, T, model.p)).ravel()))) > 1e-8
               for c_ in checks):
            continue
        if not mech.within_limits(r.q):
            outside += 1
            continue
        if not searched:
            r.q = q  # the closed-form joint values of this posture
        out.append(r)
    if searched:
        out = [out[j] for j in distinct(np.array([r_.q for r_ in out]).T, np.array(
            mech.revolute, dtype=bool), np.where(mech.revolute, 1.0, model.length), 1e-6)] \
            if out else out
    method = _method(parts)
    msg = f"{len(out)} postures"
    if searched:
        msg += f" from {runs} starts ({converged} converged; {method})"
    if outside:
        msg += f"; {outside} outside the joint limits left out"
    if not out:
        msg += "; no posture reaches this pose" + (" within the joint limits" if outside else "")
    info: dict[str, Any] = {"success": bool(out), "status": OPTIMAL if out else INFEASIBLE,
                            "message": msg}
    if searched:
        info.update(starts=runs, converged=converged, method=method, outside_limits=outside)
    if deadline.expired():  # the enumeration was cut short: say so, never claim success
        info.update(success=False, status=TIME_LIMIT,
                    message=deadline.message("inverse") + f"; {info['message']}")
    n_sing = sum(1 for r_ in out if not r_.cond <= 1e8)
    if searched:  # a numerical search: every start accounted for, completeness unproven
        account = EnumerationStats("multistart", runs, converged, 0, n_sing,
                                   max(0, runs - converged), None, False)
    else:  # every branch of every leg's closed form: complete
        account = EnumerationStats("closed-form", combos, len(out) + outside, 0, n_sing,
                                   0, combos, not deadline.expired())
    info["complete"] = account.complete
    return SolutionSet(out, "postures", info, seed=seed if searched else None, stats=account)


def _method(parts: list) -> str:
    search = [p_ for p_ in parts if isinstance(p_, SearchPart)]
    if not search:
        return "closed form, leg by leg"
    if search[0].pose_kind == "matrix":
        return "direct path then loops (7.6)" if len(search[0].stages) == 2 else "all joints"
    return "leg by leg (closed form and search)"


def _patch(nq: int, sl: slice, values: np.ndarray) -> np.ndarray:
    out = np.full(nq, np.nan)
    out[sl] = values
    return out


def _search(model: Model, part: SearchPart, T: np.ndarray, xplat: np.ndarray | None, n: int,
            iters: int, seed: int, tol: float, deadline: Deadline
            ) -> tuple[list[np.ndarray], int, int]:
    """The distinct solutions of a searched part (as full-q patches), starts, converged."""
    nq = len(model.mech.joint_names)
    vars_ = np.array(part.vars, dtype=int)
    angle = np.asarray(part.angle, dtype=bool)
    scale = np.where(angle, 1.0, model.length)
    lo = np.where(angle, -np.pi, -2 * model.length)
    hi = np.where(angle, np.pi, 2 * model.length)
    pose = (np.asarray(T, dtype=float).ravel(order="F") if part.pose_kind == "matrix"
            else np.asarray(xplat, dtype=float))
    runs = 0
    cands: list[np.ndarray] = []
    first = part.stages[0]
    idx1 = np.array(first.idx, dtype=int)
    Z1, r1 = _multistart(model, first.step, pose, lo[idx1], hi[idx1], n, iters, seed, deadline,
                         scale[idx1])
    runs += n
    Z1 = Z1[:, np.flatnonzero(r1 <= 1e3 * tol)]
    Z1[angle[idx1]] = wrap_angle(Z1[angle[idx1]])
    if len(part.stages) == 1:
        cands = [Z1[:, j] for j in range(Z1.shape[1])]
        full_idx = idx1
    else:
        second = part.stages[1]
        idx2 = np.array(second.idx, dtype=int)
        for j in distinct(Z1, angle[idx1], scale[idx1]):
            if deadline.expired():
                break
            z1 = Z1[:, j]
            n2 = max(32, n // 4)
            Z2, r2 = _multistart(model, second.step, z1, lo[idx2], hi[idx2], n2, iters,
                                 seed + 1, deadline, scale[idx2])
            runs += n2
            for i in np.flatnonzero(r2 <= 1e3 * tol):
                cands.append(np.concatenate([z1, Z2[:, i]]))
        full_idx = np.concatenate([idx1, idx2])
    converged = len(cands)
    if not cands:
        return [], runs, 0
    Z = np.array(cands).T
    Z[angle[full_idx]] = wrap_angle(Z[angle[full_idx]])
    patches = []
    for j in range(Z.shape[1]):
        q = np.zeros(nq)
        q[vars_[full_idx]] = Z[:, j]
        q = model.canonical_q(q)  # one representation of each spherical joint's rotation
        Z[:, j] = q[vars_[full_idx]]
    keep = distinct(Z, angle[full_idx], scale[full_idx], 1e-6)
    for j in keep:
        patch = np.full(nq, np.nan)
        patch[vars_[full_idx]] = Z[:, j]
        patches.append(patch)
    return patches, runs, converged


def _multistart(model: Model, step, param: np.ndarray, lo, hi, n: int, iters: int, seed: int,
                deadline: Deadline | None = None, scale: np.ndarray | None = None):
    """Batched Newton from n Sobol starts in the box [lo, hi]; returns (Z, residuals).

    The iterations stop early when ``deadline`` expires (the residuals say what converged).
    """
    dim = len(lo)
    U = _sobol(dim, seed).random(n)
    Z = (lo + U * (hi - lo)).T
    fmap = model.cached(("inverse_map", step.name(), n, step.is_a("External")),
                        lambda: step.map(f"{step.name()}_{n}", "serial", n, [1, 2], []))
    param = np.asarray(param, dtype=float).reshape(-1, 1)
    sc = (np.ones(dim) if scale is None else np.asarray(scale, dtype=float))[:, None]
    for _ in range(iters):
        if deadline is not None and deadline.expired():
            break
        Zn, _ = fmap(Z, param, model.p)
        Zn = np.array(Zn)
        good = np.all(np.isfinite(Zn), axis=0)
        moved = np.abs(Zn[:, good] - Z[:, good]) / sc
        Z[:, good] = Zn[:, good]
        if not moved.size or float(moved.max()) < 1e-13:  # every start has settled
            break
    _, r = fmap(Z, param, model.p)
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
