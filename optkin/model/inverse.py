"""The inverse geometric model of a topology, as independent parts.

Given the end-effector pose, a mechanism's joint values split into parts solved on their
own and then combined:

* a distance leg (Özgören: one equation per leg) in closed form: its actuated variable
  from :meth:`~optkin.mechanism.joints.Joint.solve_distance` of the joint that moves its
  centre (or |P - C| itself when the actuated joint is the distance), one or two branches,
  its other joints from the model's joint values (:class:`ClosedPart`);
* a leg in chain form by a batched Newton search over its variables, the pose given
  (:class:`SearchPart`);
* a Khalil table (Khalil & Dombre 2002, sec. 7.6) by a search in two stages, the joints of the direct path
  from the task equations then the others from the loops, or over all joints at once when
  the counts do not split that way.

:func:`inverse_parts` builds them once per topology; numbers enter as the geometry p.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..errors import MechanismError
from ..mechanism.platforms import PLATFORMS
from .joints import JOINTS
from .structure import gibbs, khalil_frames, platform_frame

__all__ = ["ClosedPart", "SearchPart", "Stage", "inverse_parts"]


@dataclass(frozen=True)
class ClosedPart:
    """A leg solved in closed form: ``fn(x_platform, p) -> (QA (b x na_leg), Q (b x nq_leg),
    valid (b))`` for its ``branches`` branches."""

    fn: ca.Function
    q: slice
    qa: tuple[int, ...]
    branches: int
    leg: int


@dataclass(frozen=True)
class Stage:
    """One Newton search: ``step(z, param, p) -> (z_next, max |G|)`` over the variables
    ``idx`` (indices into the part's ``vars``); ``param`` is the pose parameter (stage 0)
    or the previous stage's solution."""

    step: ca.Function
    idx: tuple[int, ...]


@dataclass(frozen=True)
class SearchPart:
    """Joints found by a batched Newton search (stages in order)."""

    vars: tuple[int, ...]          # indices into q
    angle: np.ndarray              # which of vars are angles
    length: np.ndarray             # which of vars scale with the mechanism's size
    stages: tuple[Stage, ...]
    pose_kind: str                 # "matrix" (4x4, column-major) or "platform" (x coords)
    check: ca.Function | None = None  # (q, T, p) -> task error (Khalil)
    leg: int = -1
    extra: dict[str, Any] = field(default_factory=dict)


def inverse_parts(topo, mech) -> list[ClosedPart | SearchPart]:
    """The parts of ``topo``'s inverse model (``mech`` gives the structure's details)."""
    st = topo.st
    if st.platform is None:
        return [_khalil_part(topo, mech)]
    plat = PLATFORMS[st.platform]
    npl = plat.nx()
    parts: list[ClosedPart | SearchPart] = []
    xp = ca.SX.sym("xp", npl)
    R, pv = platform_frame(plat.name, xp)
    qexpr = st.q
    off = 0
    for k, (leg, sl) in enumerate(zip(mech.legs, st.legs)):
        size = len(leg.geometry())
        g_off = off
        off += size
        if sl.reduced:
            parts.append(_closed_leg(topo, leg, sl, k, xp, R, pv, qexpr, g_off))
        else:
            parts.append(_search_leg(topo, leg, sl, k, xp, g_off))
    return parts


def _closed_leg(topo, leg, sl, k, xp, R, pv, qexpr, g_off) -> ClosedPart:
    st = topo.st
    p = st.p
    npl = xp.shape[0]
    n_scr = len(leg.screws)
    screws = [p[g_off + 6 * i: g_off + 6 * i + 6] for i in range(n_scr)]
    b = p[g_off + 6 * n_scr + 12: g_off + 6 * n_scr + 15]
    base = g_off + 6 * n_scr + 15
    centre, length = p[base: base + 3], p[base + 6]
    d = leg.distance
    P = pv + ca.mtimes(R, b)
    if d.length is None:  # the actuated joint is the distance: one branch
        rho = ca.norm_2(P - centre)
        branches = [(rho, rho > 1e-12 * p[p.shape[0] - 1])]
    else:
        drv = JOINTS[leg.joints[0]]  # the driver: the joint that moves the centre
        if d.driver != 1 or drv.n() != 1:
            raise MechanismError(f"leg {k + 1}: a distance leg's centre must be moved by one "
                                 "actuated one-variable joint")
        branches = drv.solve_distance(screws[0], centre, P, length)
    # the leg's joint values at each branch: the model's q with this leg's q_a substituted
    qleg = qexpr[sl.q.start: sl.q.stop]
    qa_leg = ca.vertcat(*[st.qa[i] for i in sl.qa])
    xsub = ca.vertcat(xp, ca.SX.zeros(st.x.shape[0] - npl))
    qleg = ca.substitute(qleg, st.x, xsub)
    QA, Q, V = [], [], []
    for val, ok in branches:
        QA.append(val)
        Q.append(ca.substitute(qleg, qa_leg, val).T)
        V.append(ok)
    fn = ca.Function(f"inv_leg{k + 1}", [xp, p],
                     [ca.vertcat(*QA), ca.vertcat(*Q), ca.vertcat(*V)],
                     ["x_platform", "p"], ["QA", "Q", "valid"])
    return ClosedPart(fn, sl.q, sl.qa, len(branches), k)


def _newton_step(name: str, G, z, params: list, scale) -> ca.Function:
    """A damped (Gauss-)Newton step on G(z; params) = 0 and max |G|."""
    from .core import damped_step

    J = ca.jacobian(G, z)
    if G.shape[0] == z.shape[0]:
        dz = -ca.solve(J, G)
    else:  # more equations than unknowns (a leg that constrains the platform)
        dz = -ca.solve(ca.mtimes(J.T, J) + 1e-12 * ca.DM.eye(z.shape[0]), ca.mtimes(J.T, G))
    fG = ca.Function(name + "_G", [z, *params], [G])
    zn = damped_step(fG, z, dz, scale, params)
    return ca.Function(name, [z, *params], [zn, ca.mmax(ca.fabs(G))])


def _search_leg(topo, leg, sl, k, xp, g_off) -> SearchPart:
    """A chain leg: its variables (actuated and solved; not the reported ones) such that
    its rows vanish at the given platform pose."""
    st = topo.st
    p = st.p
    npl = xp.shape[0]
    n = len(leg.names)
    own = [v for v in range(n) if sl.q.start + v not in sl.reported]
    z = ca.SX.sym(f"z{k + 1}", len(own))
    # the leg's candidate rows, with its actuated and solved variables replaced by z
    rows = [i for i, r in enumerate(st.row_leg) if r == k]
    G = ca.vertcat(*[st.phi[i] for i in rows])
    subs_from = [st.x[:npl]]
    subs_to = [xp]
    zi = 0
    act = list(leg.actuated)
    xs = iter(sl.x)
    for v in own:
        if v in act:
            subs_from.append(st.qa[sl.qa[act.index(v)]])
        else:
            subs_from.append(st.x[next(xs)])
        subs_to.append(z[zi])
        zi += 1
    G = ca.substitute(G, ca.vertcat(*subs_from), ca.vertcat(*subs_to))
    kinds = leg.kinds
    angle = np.array([kinds[v] == "R" for v in own])
    L = p[p.shape[0] - 1]
    scale = ca.vertcat(*[ca.SX(1) if a else L for a in angle])
    step = _newton_step(f"inv_leg{k + 1}", G, z, [xp, p], scale)
    return SearchPart(vars=tuple(sl.q.start + v for v in own), angle=angle, length=~angle,
                      stages=(Stage(step, tuple(range(len(own)))),), pose_kind="platform",
                      leg=k)


def _khalil_part(topo, mech) -> SearchPart:
    st = topo.st
    p = st.p
    nq = len(mech.joint_names)
    q = ca.SX.sym("q", nq)
    Td = ca.SX.sym("Td", 4, 4)
    T = khalil_frames(mech, q, p)
    table = mech.table
    rows, names = [], []
    for kk in table.cut_frames:
        Tk, Tp = T[kk], T[table.partner(kk)]
        Rk = Tk[:3, :3]
        rows += [ca.mtimes(Rk.T, Tp[:3, 3] - Tk[:3, 3]), gibbs(ca.mtimes(Rk.T, Tp[:3, :3]))]
        names += [f"loop:{kk}.{c}" for c in ("px", "py", "pz", "rx", "ry", "rz")]
    allrows = ca.vertcat(*rows) if rows else ca.SX(0, 1)
    phi = allrows[[names.index(n) for n in topo.row_names]] if topo.row_names else ca.SX(0, 1)
    Te = T[mech.end_effector]
    comps = {"x": Te[0, 3] - Td[0, 3], "y": Te[1, 3] - Td[1, 3], "z": Te[2, 3] - Td[2, 3]}
    gg = gibbs(ca.mtimes(Te[:3, :3], Td[:3, :3].T))
    comps.update({"rx": gg[0], "ry": gg[1], "rz": gg[2]})
    task = ca.vertcat(*[comps[c] for c in mech.task])
    if phi.shape[0] + task.shape[0] != nq:
        raise MechanismError(
            f"task: the inverse model needs as many equations as joints: {phi.shape[0]} closure "
            f"rows + {len(mech.task)} task components != {nq} joints; choose task components "
            "matching the degrees of freedom")
    revolute = np.array(mech.revolute, dtype=bool)
    L = p[p.shape[0] - 1]
    scale = ca.vertcat(*[ca.SX(1) if r else L for r in revolute])
    index = {n_: i for i, n_ in enumerate(mech.joint_names)}
    path = [index[f.name] for f in (table.frames[j - 1] for j in table.chain(mech.end_effector))
            if f.is_joint]
    off = [i for i in range(nq) if i not in path]
    check = ca.Function("task", [q, Td, p], [task])
    Tv = ca.reshape(Td, 16, 1)
    if len(path) == task.shape[0] and len(off) == phi.shape[0]:
        zp, zo = ca.SX.sym("zp", len(path)), ca.SX.sym("zo", len(off))
        qq = ca.SX.zeros(nq)
        qq[path] = zp
        qq[off] = zo
        t1 = ca.substitute(task, q, qq)
        t1 = ca.substitute(t1, zo, ca.DM.zeros(len(off)))  # [7.11]: the path joints only
        tv = ca.SX.sym("Tv", 16)
        t1 = ca.substitute(t1, Tv, tv)
        s1 = _newton_step("inv_path", t1, zp, [tv, p], scale[path])
        p2 = ca.substitute(phi, q, qq)
        s2 = _newton_step("inv_loops", p2, zo, [zp, p], scale[off])
        stages = (Stage(s1, tuple(path)), Stage(s2, tuple(off)))
    else:
        G = ca.vertcat(phi, task)
        tv = ca.SX.sym("Tv", 16)
        G = ca.substitute(G, Tv, tv)
        stages = (Stage(_newton_step("inv_all", G, q, [tv, p], scale), tuple(range(nq))),)
    return SearchPart(vars=tuple(range(nq)), angle=revolute, length=~revolute, stages=stages,
                      pose_kind="matrix", check=check)
