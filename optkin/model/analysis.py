"""What the analyses need from a model beyond its closure: built once per topology.

:func:`analysis_functions` returns the :class:`AnalysisFunctions` of a model's topology
(kept in :meth:`Model.cached`, emptied by :func:`optkin.model.clear_cache`). Every Function
takes the geometry p as its last input (call it with ``model.p`` or through
:meth:`Model.bind`). They are obtained by automatic differentiation of the structure's
expressions (:mod:`optkin.model.structure`):

* ``rows_q`` - the joint-level closure H(z) = 0 over every joint variable z (Khalil
  tables: the model's independent loop rows [7.8] over all joints; platforms: each leg's
  chain reaches the platform, the platform coordinates as extra passive variables, so
  that Modern Robotics' H_a, H_p (7.13) are available), its Jacobian dH/dz [7.48] and the
  end-effector twist Jacobian K over z;
* ``acc_q`` - (dJ/dt) zdot of [7.52] along a velocity zdot;
* ``hess_x`` and ``acc_x`` - second derivatives of the model's rows Phi(q_a, x) over its
  unknowns (the second-order actuator-singularity test; [7.52] at the model level);
* ``twist`` - the end-effector twist Jacobians over q_a and over x (Khalil [7.44] order:
  linear velocity of the frame origin, then angular velocity, base coordinates).

Besides, from the model's description: the Grubler-Kutzbach inventory
(:func:`joint_inventory`: each leg's ``inventory``, a point platform's shared joint, a
Khalil table's links and the rank of each loop), the twist and task components of the
end effector (:func:`twist_rows`, :func:`task_rows`), where the model's unknowns sit among
the joint-level variables (:func:`z_of`) and the legs' labels for messages. This is the
one place of the analyses that knows what kind of description a model has.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .. import numeric
from ..errors import MechanismError
from .structure import twist_jacobian

__all__ = ["AnalysisFunctions", "analysis_functions", "joint_inventory", "loop_lambda",
           "twist_rows", "task_rows", "z_of", "leg_labels", "platform_unknowns_only"]

#: Khalil task component -> row of the twist (vx, vy, vz, wx, wy, wz).
_TASK_TO_TWIST = {"x": 0, "y": 1, "z": 2, "rx": 3, "ry": 4, "rz": 5}


@dataclass(frozen=True)
class AnalysisFunctions:
    """The analysis Functions of one topology (the geometry p is every one's last input).

    Attributes
    ----------
    rows_q : Function (z, p) -> (Phi, J, K)
        The joint-level closure rows over ``var_names``, their Jacobian, and the
        end-effector twist Jacobian over the same variables.
    acc_q : Function (z, zd, p) -> Jdot zd
        The acceleration term of [7.52] along the velocity zd (AD, jtimes twice).
    hess_x : Function (qa, x, u, p) -> d^2 (u^T Phi) / dx^2
        Over the model's unknowns x (second-order actuator-singularity test).
    acc_x : Function (qa, x, qad, xd, p) -> second derivative of the model rows along
        (qad, xd).
    twist : Function (qa, x, p) -> (K_a, K_x)
        The end-effector twist (v, omega) per unit q_a and per unit x.
    loop_jac : Function (z, p) -> dH_all/dz or None
        Khalil tables: the Jacobian of every loop's six rows (dependent ones included),
        for the rank of each loop.
    nvar : int
        Number of joint-level variables z.
    var_names, row_names : tuple of str
    row_length : ndarray of bool
        Which joint-level rows are lengths.
    z_x : ndarray of int
        Where the model's unknowns x sit in z.
    n_joints : int
        How many leading entries of z are the joint values (``mech.joint_names``).
    """

    rows_q: ca.Function
    acc_q: ca.Function
    hess_x: ca.Function
    acc_x: ca.Function
    twist: ca.Function
    loop_jac: ca.Function | None
    nvar: int
    var_names: tuple[str, ...]
    row_names: tuple[str, ...]
    row_length: np.ndarray
    z_x: np.ndarray
    n_joints: int


def analysis_functions(model: Any) -> AnalysisFunctions:
    """The :class:`AnalysisFunctions` of ``model``'s topology (built on first use, shared
    by every geometry of the topology)."""
    topo = model.topology
    return model.cached("analysis_functions", lambda: _build(topo, len(model.mech.joint_names)))


def _build(topo: Any, nq: int) -> AnalysisFunctions:
    st = topo.st
    p = st.p
    z = st.z
    if st.platform is None:
        # Khalil: the model's independent rows, written over every joint
        idx = [st.H_names.index(n) for n in topo.row_names]
        H = st.H[idx] if idx else ca.SX(0, 1)
        names = tuple(st.H_names[i] for i in idx)
        length = np.array([st.H_length[i] for i in idx], dtype=bool)
        loop_jac = ca.Function("loop_jac", [z, p], [ca.jacobian(st.H, z)], ["z", "p"], ["J"])
    else:
        H = st.H
        names = tuple(st.H_names)
        length = np.array(st.H_length, dtype=bool)
        loop_jac = None
    length.setflags(write=False)
    J = ca.jacobian(H, z)
    zd = ca.SX.sym("zd", z.shape[0])
    acc = ca.jtimes(ca.mtimes(J, zd), z, zd)
    rows_q = ca.Function("rows_q", [z, p], [H, J, st.K], ["z", "p"], ["Phi", "J", "K"])
    acc_q = ca.Function("acc_q", [z, zd, p], [acc], ["z", "zd", "p"], ["Jdot_zd"])
    qa, x, phi = st.qa, st.x, topo.phi_sym
    u = ca.SX.sym("u", topo.m)
    hess_x = ca.Function("hess_x", [qa, x, u, p], [ca.hessian(ca.dot(u, phi), x)[0]],
                         ["qa", "x", "u", "p"], ["H"])
    qad = ca.SX.sym("qad", topo.na)
    xd = ca.SX.sym("xd", topo.nx)
    v = ca.vertcat(qa, x)
    vd = ca.vertcat(qad, xd)
    second = ca.jtimes(ca.jtimes(phi, v, vd), v, vd)
    acc_x = ca.Function("acc_x", [qa, x, qad, xd, p], [second],
                        ["qa", "x", "qad", "xd", "p"], ["Wdot_zd"])
    T = st.T
    twist = ca.Function("twist", [qa, x, p], [twist_jacobian(T[:3, :3], T[:3, 3], qa),
                                              twist_jacobian(T[:3, :3], T[:3, 3], x)],
                        ["qa", "x", "p"], ["K_a", "K_x"])
    z_x = np.asarray(st.z_x, dtype=int).copy()
    z_x.setflags(write=False)
    return AnalysisFunctions(
        rows_q=rows_q, acc_q=acc_q, hess_x=hess_x, acc_x=acc_x, twist=twist,
        loop_jac=loop_jac, nvar=int(z.shape[0]), var_names=tuple(st.z_names),
        row_names=names, row_length=length, z_x=z_x, n_joints=nq)


# --------------------------------------------------------------------------------------
# the model's unknowns among the joint-level variables


def z_of(model: Any, q: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The joint-level variables z of a configuration: the joint values ``q``, then the
    platform coordinates (from the unknowns ``x``)."""
    f = analysis_functions(model)
    z = np.zeros(f.nvar)
    q = np.asarray(q, dtype=float)
    z[: q.size] = q
    z[f.z_x] = np.asarray(x, dtype=float)
    return z


def platform_unknowns_only(model: Any) -> bool:
    """The model's unknowns are exactly the platform's coordinates (every leg in its
    reduced form): Chablat and Wenger's A t + B qdot_a = 0 is then the model's velocity
    equation, one row (or more) per leg."""
    return model.n_platform > 0 and model.nx == model.n_platform


def twist_rows(model: Any) -> list[int]:
    """Which of (vx, vy, vz, wx, wy, wz) the end-effector twist has."""
    plat = model.platform
    return list(range(6)) if plat is None else list(plat.twist_rows)


def task_rows(model: Any) -> list[int]:
    """The twist components of the mechanism's task coordinates (Khalil tables: its
    ``task``; platforms: the platform's twist)."""
    if model.platform is None:
        return [_TASK_TO_TWIST[t] for t in model.mech.task]
    return twist_rows(model)


def leg_labels(model: Any) -> tuple[str, ...]:
    """The label (type or joint string) of each leg, for messages; empty for Khalil."""
    return tuple(leg.type for leg in model.mech.legs)


# --------------------------------------------------------------------------------------
# Grubler-Kutzbach


def joint_inventory(model: Any) -> dict[str, Any]:
    """Links, joints (with their freedoms) and loop subspace dimensions.

    Khalil tables: one movable link per tree joint frame, one joint per joint variable
    (cut joints included), lambda of each loop = the generic rank of its six closure rows.
    Platforms: each leg's ``inventory`` (joint freedoms base to platform, moving links,
    idle freedoms: a Delta's parallelogram is two S-S rods) plus the platform body; legs
    of a point platform (``shared_point``) have no platform body and meet in one multiple
    joint (l - 1 joints of the legs' last joint).
    """
    mech = model.mech
    plat = model.platform
    if plat is None:
        table = mech.table
        n_links = sum(1 for f in table.frames[: table.n] if f.is_joint)
        freedoms = [1] * len(mech.joint_names)
        lam = loop_lambda(model)
        return {"n_links": n_links, "freedoms": freedoms, "lambda": lam,
                "loops": len(freedoms) - n_links, "idle": 0}
    space = 3 if plat.space_dim == 2 else 6
    freedoms: list[int] = []
    n_links = idle = 0
    legs = mech.legs
    for k, leg in enumerate(legs):
        fr, links, idl = leg.inventory
        fr = list(fr)
        if plat.shared_point:  # the last joints form one multiple joint
            last = fr.pop()
            if k:
                freedoms.append(last)
        freedoms += fr
        n_links += links
        idle += idl
    if not plat.shared_point:
        n_links += 1
    loops = len(freedoms) - n_links
    return {"n_links": n_links, "freedoms": freedoms, "lambda": [space] * loops,
            "loops": loops, "idle": idle}


def loop_lambda(model: Any, samples: int = 4, seed: int = 11) -> list[int]:
    """Generic rank of each Khalil loop's six closure rows (3 planar/spherical, 6
    spatial); empty for platforms."""
    f = analysis_functions(model)
    if f.loop_jac is None:
        return []
    nz = f.nvar
    rng = np.random.default_rng(seed)
    G = np.hstack([np.array(f.loop_jac(rng.uniform(-np.pi, np.pi, nz), model.p))
                   for _ in range(samples)])
    out = []
    for j in range(G.shape[0] // 6):
        g = G[6 * j: 6 * j + 6]
        if not np.isfinite(g).all():  # cannot happen for finite geometry: say so, not hang
            raise MechanismError(f"the closure rows of loop {j + 1} are not finite at random "
                                 "joint values; check the table's geometry", path=("rows",))
        scale = max(1.0, float(np.abs(g).max()))
        out.append(numeric.rank(g, f"loop {j + 1}", rtol=0.0, atol=1e-9 * scale))
    return out
