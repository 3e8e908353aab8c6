"""CasADi Functions of the velocity/acceleration analysis, built once per mechanism.

:func:`analysis_functions` returns the cached :class:`AnalysisFunctions` of a mechanism
(keyed by ``mech.key``, beside the model of :func:`optkin.model.get_model`). They are
obtained by automatic differentiation of the same independent closure rows as the model:

* Khalil mechanisms: the rows Phi(q) of [7.8] over *all* joints q (active, passive, cut),
  their Jacobian J = dPhi/dq [7.48], the acceleration term (dJ/dt) qdot [7.52], the
  end-effector twist Jacobian over all joints, and the Hessian of u^T Phi over the unknowns
  (second-order singularity test).
* leg-described platforms: a joint-level closure H(q, x) = 0 (each leg's serial chain must
  reach the platform), with the platform coordinates x as extra passive coordinates, so that
  Modern Robotics' H_a, H_p (7.13) are available; plus the model rows f_i(q_a, x) whose
  Jacobians are Chablat and Wenger's A and B.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .._cache import KeyedCache
from ..mechanism import Mechanism
from ..model import get_model
from ..model import khalil as kh
from ..model import legs as lg

__all__ = ["AnalysisFunctions", "analysis_functions"]

_CACHE: KeyedCache[AnalysisFunctions] = KeyedCache()


def analysis_functions(mech: Mechanism) -> AnalysisFunctions:
    """The cached analysis Functions of ``mech`` (built on first use)."""
    return _CACHE.get(mech.key, lambda: AnalysisFunctions(mech))


def _twist_jacobian(R: ca.SX, p: ca.SX, q: ca.SX) -> ca.SX:
    """6 x n Jacobian of the twist (v, omega) of the frame (R, p) w.r.t. q (base frame).

    v = dp/dq qdot, and [omega]_x = Rdot R^T, i.e. omega_k = vee(dR/dq_k R^T).
    """
    Jp = ca.jacobian(p, q)
    n = q.shape[0]
    cols = []
    for k in range(n):
        dR = ca.jacobian(R, q[k])  # 9 x 1, column-major vec(R)
        dRm = ca.reshape(dR, 3, 3)
        S = ca.mtimes(dRm, R.T)
        cols.append(ca.vertcat(0.5 * (S[2, 1] - S[1, 2]), 0.5 * (S[0, 2] - S[2, 0]),
                               0.5 * (S[1, 0] - S[0, 1])))
    Jw = ca.horzcat(*cols) if cols else ca.SX(3, 0)
    return ca.vertcat(Jp, Jw)


def _rot2_sx(phi) -> ca.SX:
    c, s = ca.cos(phi), ca.sin(phi)
    return ca.vertcat(ca.horzcat(c, -s), ca.horzcat(s, c))


def _rx(a):
    c, s = ca.cos(a), ca.sin(a)
    return ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, c, -s), ca.horzcat(0, s, c))


def _ry(a):
    c, s = ca.cos(a), ca.sin(a)
    return ca.vertcat(ca.horzcat(c, 0, s), ca.horzcat(0, 1, 0), ca.horzcat(-s, 0, c))


def _rz(a):
    c, s = ca.cos(a), ca.sin(a)
    return ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))


def leg_chain_sx(leg: Any, q: ca.SX, planar_point: bool) -> tuple[ca.SX, ca.SX]:
    """(R, P) reached by the serial chain of a leg: R its end orientation, P the platform
    joint centre, as CasADi expressions of the leg's joints (same conventions as
    :func:`optkin.mechanism.legs.leg_forward`)."""
    t = leg.type
    A = ca.DM(np.asarray(leg.base, dtype=float))
    if t == "RPR":
        th, rho, psi = q[0], q[1], q[2]
        P = A + rho * ca.vertcat(ca.cos(th), ca.sin(th))
        return th + psi, P
    if t == "RRR":
        l1, l2 = leg.lengths
        t1, t2, t3 = q[0], q[1], q[2]
        C = A + l1 * ca.vertcat(ca.cos(t1), ca.sin(t1))
        P = C + l2 * ca.vertcat(ca.cos(t1 + t2), ca.sin(t1 + t2))
        return (t1 + t2 + t3), P
    if t in ("UPS", "SPS"):
        ua, ub, rho, sa, sb, sc = (q[i] for i in range(6))
        Rl = ca.mtimes(_rx(ua), _ry(ub))
        P = A + rho * Rl[:, 2]
        R = ca.mtimes(ca.mtimes(Rl, _rx(sa)), ca.mtimes(_ry(sb), _rz(sc)))
        return R, P
    la, lb = leg.lengths
    th, ua, ub = q[0], q[1], q[2]
    u0 = np.asarray(leg.arm, dtype=float)
    ax = np.asarray(leg.axis, dtype=float)
    w = np.cross(ax, u0)
    armv = ca.cos(th) * ca.DM(u0) + ca.sin(th) * ca.DM(w)
    C = A + la * armv
    F = ca.horzcat(armv, ca.DM(ax), ca.vertcat(
        armv[1] * ax[2] - armv[2] * ax[1], armv[2] * ax[0] - armv[0] * ax[2],
        armv[0] * ax[1] - armv[1] * ax[0]))
    v = ca.mtimes(F, ca.mtimes(_rx(ua), _ry(ub))[:, 2])
    return ca.SX.eye(3), C + lb * v


class AnalysisFunctions:
    """Compiled Functions for :func:`optkin.jacobians`, :func:`optkin.dof`, :func:`optkin.classify`.

    Attributes (all ``casadi.Function``)
    ------------------------------------
    rows_q(q) -> (Phi, J, K)
        Closure rows over every joint (Khalil) or over (q, x) (legs, joint level), their
        Jacobian, and the end-effector twist Jacobian K over the same variables.
    acc_q(q, qd) -> Jdot qdot
        The acceleration term of [7.52] along the velocity qd (by AD, jtimes twice).
    hess_x(qa, x, u) -> d^2 (u^T Phi) / dx^2
        Over the model's unknowns x (second-order actuator-singularity test).
    acc_x(qa, x, qad, xd) -> second derivative of the model rows along (qad, xd).
    """

    def __init__(self, mech: Mechanism) -> None:
        self.mech = mech
        model = get_model(mech)
        self.model = model
        if mech.kind == "khalil":
            nq = len(mech.joint_names)
            q = ca.SX.sym("q", nq)
            T = kh.frames_0(mech, q)
            rows, names = kh.closure_rows(mech, T)
            keep = [names.index(n) for n in model.row_names]
            phi = rows[keep] if keep else ca.SX(0, 1)
            Tee = T[mech.end_effector]
            K = _twist_jacobian(Tee[:3, :3], Tee[:3, 3], q)
            self.nvar = nq
            self.var_names = tuple(mech.joint_names)
            self.row_names = tuple(model.row_names)
            self.row_length = np.array([n.split(".")[-1].startswith("p") for n in names])[keep]
        else:
            q, phi, K, rnames, rlen = self._leg_joint_level(mech, model)
            self.nvar = q.shape[0]
            self.var_names = tuple(mech.joint_names) + tuple(f"x.{n}" for n in model.x_names)
            self.row_names = tuple(rnames)
            self.row_length = np.array(rlen, dtype=bool)
        J = ca.jacobian(phi, q)
        qd = ca.SX.sym("qd", q.shape[0])
        Jqd = ca.mtimes(J, qd)
        acc = ca.jtimes(Jqd, q, qd)
        self.rows_q = ca.Function("rows_q", [q], [phi, J, K], ["q"], ["Phi", "J", "K"])
        self.acc_q = ca.Function("acc_q", [q, qd], [acc], ["q", "qd"], ["Jdot_qd"])
        # model-level second-order terms
        qa, x, ph = model.qa_sym, model.x_sym, model.phi_sym
        u = ca.SX.sym("u", model.m)
        self.hess_x = ca.Function("hess_x", [qa, x, u], [ca.hessian(ca.dot(u, ph), x)[0]],
                                  ["qa", "x", "u"], ["H"])
        qad = ca.SX.sym("qad", model.na)
        xd = ca.SX.sym("xd", model.nx)
        z = ca.vertcat(qa, x)
        zd = ca.vertcat(qad, xd)
        first = ca.jtimes(ph, z, zd)
        second = ca.jtimes(first, z, zd)
        self.acc_x = ca.Function("acc_x", [qa, x, qad, xd], [second],
                                 ["qa", "x", "qad", "xd"], ["Wdot_zd"])
        if mech.kind == "legs":
            R, p = lg.platform_frame(mech.platform, x)
            Kx = _twist_jacobian(R, p, x)
            self.twist_x = ca.Function("twist_x", [x], [Kx], ["x"], ["K"])

    @staticmethod
    def _leg_joint_level(mech: Mechanism, model: Any):
        nq = len(mech.joint_names)
        q = ca.SX.sym("q", nq)
        x = ca.SX.sym("xp", model.nx)
        z = ca.vertcat(q, x)
        R, p = lg.platform_frame(mech.platform, x)
        planar = mech.planar
        point = mech.platform in ("planar_point", "spatial_translational")
        rows, names, is_len = [], [], []
        i = 0
        for k, leg in enumerate(mech.legs):
            n = len(leg.joint_names)
            ql = q[i:i + n]
            i += n
            Rl, P = leg_chain_sx(leg, ql, mech.platform == "planar_point")
            if planar:
                Pp = p[:2] + ca.mtimes(R[:2, :2], ca.DM(np.asarray(leg.platform, float)))
                rows += [P[0] - Pp[0], P[1] - Pp[1]]
                names += [f"leg:{k + 1}.px", f"leg:{k + 1}.py"]
                is_len += [True, True]
                phi_p = ca.SX(0) if mech.platform == "planar_point" else x[2]
                # the leg's end orientation equals the platform's (planar_point: a fictitious
                # platform of orientation 0 fixes the last leg joint)
                rows.append(Rl - phi_p)
                names.append(f"leg:{k + 1}.rz")
                is_len.append(False)
            else:
                Pp = p + ca.mtimes(R, ca.DM(np.asarray(leg.platform, float)))
                d = P - Pp
                rows += [d[0], d[1], d[2]]
                names += [f"leg:{k + 1}.{c}" for c in ("px", "py", "pz")]
                is_len += [True] * 3
                if not point:
                    g = kh.gibbs(ca.mtimes(R.T, Rl))
                    rows += [g[0], g[1], g[2]]
                    names += [f"leg:{k + 1}.{c}" for c in ("rx", "ry", "rz")]
                    is_len += [False] * 3
        if mech.platform == "spatial":
            rows.append(ca.sumsqr(x[3:7]) - 1)
            names.append("quaternion:norm")
            is_len.append(False)
        phi = ca.vertcat(*rows)
        # twist of the platform frame over (q, x): only x moves it
        Kx = _twist_jacobian(R, p, x)
        K = ca.horzcat(ca.SX(6, nq), Kx)
        return z, phi, K, names, is_len
