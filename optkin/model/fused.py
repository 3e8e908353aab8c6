"""Fused CasADi Functions for the fast paths: one evaluation instead of several calls.

``result_function(model)``: (q_a, x) -> (Phi, W_p, T, q), everything a
:class:`~optkin.results.KinResult` needs (the joint values q as in ``Model.to_q``, written
here as CasADi expressions mirroring ``optkin.mechanism.legs.leg_joints``).

``tracker_function(model, iters)``: one point of a path: from the solution x_prev at
q_a,prev, the Euler predictor x_prev - W_p^-1 W_a (q_a - q_a,prev) (the velocity model
[7.51]) followed by ``iters`` Newton corrections (7.9); returns the new x, q_a (the
accumulated state of ``mapaccum``) and max |Phi|.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["result_function", "tracker_function", "q_expression"]


def _wrap(a):
    return ca.atan2(ca.sin(a), ca.cos(a))


def _clip1(v):
    return ca.fmin(ca.fmax(v, -1.0), 1.0)


def _pad3(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return np.concatenate([v, np.zeros(3 - v.size)]) if v.size < 3 else v


def _leg_joints_sx(leg, R, p, a, planar: bool) -> list:
    """CasADi twin of ``optkin.mechanism.legs.leg_joints`` (same conventions)."""
    if planar:
        P = p[:2] + ca.mtimes(R[:2, :2], np.asarray(leg.platform, dtype=float)[:2])
        A = np.asarray(leg.base, dtype=float)[:2]
        phi = ca.atan2(R[1, 0], R[0, 0])
        if leg.type == "RPR":
            d = P - A
            th = ca.atan2(d[1], d[0])
            return [th, a, _wrap(phi - th)]
        if leg.type == "RRR":
            l1 = float(leg.lengths[0])
            C = A + l1 * ca.vertcat(ca.cos(a), ca.sin(a))
            e = P - C
            th12 = ca.atan2(e[1], e[0])
            return [a, _wrap(th12 - a), _wrap(phi - th12)]
        raise NotImplementedError(leg.type)
    P = p + ca.mtimes(R, _pad3(leg.platform))
    A = _pad3(leg.base)
    if leg.type in ("UPS", "SPS"):
        d = P - A
        n = ca.norm_2(d)
        u = ca.if_else(n > 0, d / n, ca.DM([0.0, 0.0, 1.0]))
        ub = ca.asin(_clip1(u[0]))
        ua = ca.atan2(-u[1], u[2])
        ca_, sa, cb, sb = ca.cos(ua), ca.sin(ua), ca.cos(ub), ca.sin(ub)
        Rx = ca.vertcat(ca.horzcat(1, 0, 0), ca.horzcat(0, ca_, -sa), ca.horzcat(0, sa, ca_))
        Ry = ca.vertcat(ca.horzcat(cb, 0, sb), ca.horzcat(0, 1, 0), ca.horzcat(-sb, 0, cb))
        RS = ca.mtimes(ca.mtimes(Rx, Ry).T, R)
        e_b = ca.asin(_clip1(RS[0, 2]))
        e_a = ca.atan2(-RS[1, 2], RS[2, 2])
        e_c = ca.atan2(-RS[0, 1], RS[0, 0])
        return [ua, ub, a, e_a, e_b, e_c]
    # RUS / RSS
    la = float(leg.lengths[0])
    u0 = np.asarray(leg.arm, dtype=float)
    ax = np.asarray(leg.axis, dtype=float)
    w = np.cross(ax, u0)
    armv = ca.cos(a) * u0 + ca.sin(a) * w
    C = A + la * armv
    v = P - C
    n = ca.norm_2(v)
    v = ca.if_else(n > 0, v / n, armv)
    F = ca.horzcat(armv, ax, ca.cross(armv, ca.DM(ax)))
    vl = ca.mtimes(F.T, v)
    return [a, ca.atan2(-vl[1], vl[2]), ca.asin(_clip1(vl[0]))]


def q_expression(model, qa, x, T):
    """All joint values (``mech.joint_names`` order) as an SX expression of (q_a, x)."""
    mech = model.mech
    if mech.kind == "khalil":
        return model._assemble_sx(qa, x)
    R, p = T[:3, :3], T[:3, 3]
    parts = []
    for k, leg in enumerate(mech.legs):
        parts += _leg_joints_sx(leg, R, p, qa[k], mech.planar)
    return ca.vertcat(*parts)


def result_function(model) -> ca.Function:
    """(q_a, x) -> (Phi, W_p, T, q): the fields of a KinResult in one evaluation."""
    qa, x = model.qa_sym, model.x_sym
    phi = model.phi_sym
    Wp = ca.jacobian(phi, x)
    T = model.pose_fn(qa, x)
    q = q_expression(model, qa, x, T)
    outs = [ca.densify(e) for e in (phi, Wp, T, q)]
    return ca.Function("result", [qa, x], outs, ["qa", "x"], ["Phi", "W_p", "T", "q"])


def _newton_dx(Wp, phi, square: bool):
    if square:
        return -ca.solve(Wp, phi)
    return -ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, phi))


def tracker_function(model, iters: int = 2) -> ca.Function:
    """One path point: Euler predictor from (x_prev, q_a,prev) then ``iters`` Newton steps.

    Inputs (x_prev, qa_prev, qa); outputs (x, qa, res) with res = max |Phi(q_a, x)|, so
    that ``F.mapaccum(n, 2)`` tracks n consecutive points.
    """
    nx, na = model.nx, model.na
    square = model.m == nx
    xp = ca.SX.sym("x_prev", nx)
    qp = ca.SX.sym("qa_prev", na)
    qa = ca.SX.sym("qa", na)
    f = ca.Function("f", [model.qa_sym, model.x_sym],
                    [model.phi_sym, ca.jacobian(model.phi_sym, model.x_sym),
                     ca.jacobian(model.phi_sym, model.qa_sym)])
    _, Wp, Wa = f(qp, xp)
    x = xp + _newton_dx(Wp, ca.mtimes(Wa, qa - qp), square)
    for _ in range(iters):
        phi, Wp, _ = f(qa, x)
        x = x + _newton_dx(Wp, phi, square)
    phi = ca.substitute(model.phi_sym, ca.vertcat(model.qa_sym, model.x_sym), ca.vertcat(qa, x))
    res = ca.mmax(ca.fabs(phi)) if model.m else ca.SX(0)
    return ca.Function("track1", [xp, qp, qa], [x, qa, res],
                       ["x_prev", "qa_prev", "qa"], ["x", "qa_next", "res"])
