"""Fused CasADi Functions for the fast paths: one evaluation instead of several calls.

``result_function(model)``: (q_a, x) -> (Phi, W_p, T, q), everything a
:class:`~optkin.results.KinResult` needs (the joint values q as in ``Model.to_q``, written
here as CasADi expressions mirroring ``optkin.mechanism.legs.leg_joints``).

``tracker_function(model, iters)``: one point of a path: from the solution x_prev at
q_a,prev, the Euler predictor x_prev - W_p^-1 W_a (q_a - q_a,prev) (the velocity model
[7.51]) followed by ``iters`` Newton corrections (7.9); returns the new x, q_a (the
accumulated state of ``mapaccum``) and max |Phi|.

``guard_function(model)``: what a path point is checked with against the previous one
(det W_p, a conditioning indicator, and the Euler predictions of the steps to and from it),
mapped over the rows of a batch by :func:`optkin.forward_batch`.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

__all__ = ["result_function", "tracker_function", "guard_function", "q_expression"]


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


def det_solve(M, B=None):
    """(det M, M^-1 B) of a square SX matrix by Householder QR, unrolled.

    Branch-free apart from the sign of each reflection (``casadi.det`` expands cofactors:
    8384 instructions for the 7x7 W_p of a Stewart-Gough platform; a pivoted LU written
    with ``if_else`` row swaps ran 2.3x slower than this when compiled). Every reflection
    H = I - 2 v v^T / v^T v has det -1, so det M = (-1)^(reflections) prod R_kk.
    """
    n = M.shape[0]
    k_b = 0 if B is None else B.shape[1]
    A = [[M[i, j] for j in range(n)] + [B[i, j] for j in range(k_b)] for i in range(n)]
    w = n + k_b
    det = ca.SX(1)
    for k in range(n - 1):
        x = [A[i][k] for i in range(k, n)]
        nrm = ca.sqrt(sum(xi * xi for xi in x))
        sgn = ca.if_else(x[0] >= 0, 1, -1)
        v = [x[0] + sgn * nrm] + x[1:]
        vtv = sum(vi * vi for vi in v)
        beta = ca.if_else(vtv > 0, 2 / vtv, 0)
        det = ca.if_else(vtv > 0, -det, det)
        for j in range(k, w):
            f = beta * sum(v[i] * A[k + i][j] for i in range(len(v)))
            for i in range(len(v)):
                A[k + i][j] = A[k + i][j] - f * v[i]
    for k in range(n):
        det = det * A[k][k]
    if not k_b:
        return det, None
    X = [[None] * k_b for _ in range(n)]
    for i in range(n - 1, -1, -1):  # back substitution with R
        inv = ca.if_else(A[i][i] == 0, 0, 1 / A[i][i])
        for j in range(k_b):
            v = A[i][n + j]
            for c in range(i + 1, n):
                v = v - A[i][c] * X[c][j]
            X[i][j] = v * inv
    return det, ca.vertcat(*[ca.horzcat(*row) for row in X])


def det_sx(M) -> ca.SX:
    """det M of a square SX matrix (:func:`det_solve`)."""
    return det_solve(M)[0]


def guard_function(model) -> ca.Function:
    """What :func:`optkin.forward_batch` checks at every solved row of a path.

    Inputs (qa_prev, x_prev, qa, x, qa_next, x_next): the row and its neighbours on the
    path (the row itself where there is none); outputs

    * ``det``: det W_p(q_a, x) (square W_p; 1 when W_p has more rows than columns, which has
      no orientation);
    * ``h``: a conditioning indicator in [0, 1], the Hadamard ratio of W_p with columns
      scaled by ``x_scale``: |det(W_p S)| / prod_i |row_i(W_p S)| (rows normalised first and
      sqrt det(N^T N) for a non-square W_p). 1 for orthogonal rows, 0 at a singularity;
      invariant to the scaling of the rows; s^n <= h <= s n^((n-1)/2) with s the smallest
      singular value of the row-normalised matrix;
    * ``cp`` = [c_back, p_back, c_fwd, p_fwd]: the Euler predictions dx = -W_p^-1 W_a dq_a
      (the velocity model [7.51], W_p and W_a at this row) of the step from the previous
      row (back) and of the step to the next row (fwd): the predicted move |dx| (p_) and
      the distance of the actual move from it (c_), both in the max norm of scaled units
      (lengths / ``x_scale``, angle differences wrapped). Along a smooth branch the
      distances are second order in the step; a jump to another solution makes them as
      large as the move itself.

    det and W_p^-1 W_a dq_a come from one Householder QR factorisation (:func:`det_solve`).
    """
    nx, na, m = model.nx, model.na, model.m
    scale = np.asarray(model.x_scale, dtype=float)
    angle = np.asarray(model.x_angle, dtype=bool)
    qa, x = model.qa_sym, model.x_sym
    qp, xp = ca.SX.sym("qa_prev", na), ca.SX.sym("x_prev", nx)
    qn, xn = ca.SX.sym("qa_next", na), ca.SX.sym("x_next", nx)
    Wp = ca.jacobian(model.phi_sym, x)
    Wa = ca.jacobian(model.phi_sym, qa)
    rhs = ca.mtimes(Wa, ca.horzcat(qa - qp, qn - qa))
    Ws = ca.mtimes(Wp, ca.diag(ca.DM(scale)))
    rn = ca.sqrt(ca.sum2(Ws * Ws)) + 1e-300
    if m == nx:  # det(W_p S) / prod |rows| = det W_p prod(S) / prod |rows|
        det, D = det_solve(Wp, rhs)
        h = ca.fabs(det) * float(np.prod(scale))
        for i in range(m):
            h = h / rn[i]
    else:
        N = Ws / ca.repmat(rn, 1, nx)
        det = ca.SX(1)
        h = ca.sqrt(ca.fmax(det_sx(ca.mtimes(N.T, N)), 0))
        D = ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, rhs))
    tau = 2 * np.pi
    sc = ca.DM(1.0 / scale)

    def move(a, b):  # b - a, angles wrapped
        d = b - a
        return ca.vertcat(*[d[i] - tau * ca.floor(d[i] / tau + 0.5) if angle[i] else d[i]
                            for i in range(nx)])

    def mx(v):
        return ca.mmax(ca.fabs(v * sc))

    db, df = -D[:, 0], -D[:, 1]
    cp = ca.vertcat(mx(move(xp, x) - db), mx(db), mx(move(x, xn) - df), mx(df))
    return ca.Function("guard", [qp, xp, qa, x, qn, xn], [det, h, cp],
                       ["qa_prev", "x_prev", "qa", "x", "qa_next", "x_next"],
                       ["det", "h", "cp"])
