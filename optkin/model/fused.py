"""Fused CasADi Functions for the fast paths: one evaluation instead of several calls.

``result_function(topology)``: (q_a, x, p) -> (Phi, W_p, T, q), everything a
:class:`~optkin.results.KinResult` needs (the joint values q of the model's structure).

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

__all__ = ["result_function", "tracker_function", "tracker_chunk", "guard_function",
           "guard_chunk", "det_solve", "det_sx"]


def result_function(topo) -> ca.Function:
    """(q_a, x, p) -> (Phi, W_p, T, q): the fields of a KinResult in one evaluation."""
    st = topo.st
    qa, x, p = st.qa, st.x, st.p
    phi = topo.phi_sym
    Wp = ca.jacobian(phi, x)
    outs = [ca.densify(e) for e in (phi, Wp, st.T, st.q)]
    return ca.Function("result", [qa, x, p], outs, ["qa", "x", "p"], ["Phi", "W_p", "T", "q"])


def _newton_dx(Wp, phi, square: bool):
    if square:
        return -ca.solve(Wp, phi)
    return -ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, phi))


def tracker_function(topo, iters: int = 2) -> ca.Function:
    """One path point: Euler predictor from (x_prev, q_a,prev) then ``iters`` Newton steps.

    Inputs (x_prev, qa_prev, qa, p); outputs (x, qa, res) with res = max |Phi(q_a, x)|, so
    that ``F.mapaccum(n, 2)`` tracks n consecutive points.
    """
    st = topo.st
    nx, na = topo.nx, topo.na
    square = topo.m == nx
    xp = ca.SX.sym("x_prev", nx)
    qp = ca.SX.sym("qa_prev", na)
    qa = ca.SX.sym("qa", na)
    p = ca.SX.sym("p", st.p.shape[0])
    phi_s = topo.phi_sym
    f = ca.Function("f", [st.qa, st.x, st.p],
                    [phi_s, ca.jacobian(phi_s, st.x), ca.jacobian(phi_s, st.qa)])
    _, Wp, Wa = f(qp, xp, p)
    x = xp + _newton_dx(Wp, ca.mtimes(Wa, qa - qp), square)
    for _ in range(iters):
        phi, Wp, _ = f(qa, x, p)
        x = x + _newton_dx(Wp, phi, square)
    phi = f(qa, x, p)[0]
    res = ca.mmax(ca.fabs(phi)) if topo.m else ca.SX(0)
    return ca.Function("track1", [xp, qp, qa, p], [x, qa, res],
                       ["x_prev", "qa_prev", "qa", "p"], ["x", "qa_next", "res"])


def tracker_chunk(topo, chunk: int, iters: int) -> ca.Function:
    """``chunk`` consecutive path points: (x0, qa0, QA (na x chunk), p) -> (X, QA, res);
    the geometry is repeated inside the graph (``mapaccum`` maps its other inputs)."""
    one = tracker_function(topo, iters)
    acc = one.mapaccum(f"track_acc_{chunk}_{iters}", chunk, 2)
    x0 = ca.MX.sym("x0", topo.nx)
    q0 = ca.MX.sym("qa0", topo.na)
    QA = ca.MX.sym("QA", topo.na, chunk)
    p = ca.MX.sym("p", topo.st.p.shape[0])
    X, Q, R = acc(x0, q0, QA, ca.repmat(p, 1, chunk))
    return ca.Function(f"track_{chunk}_{iters}", [x0, q0, QA, p], [X, Q, R],
                       ["x0", "qa0", "QA", "p"], ["X", "QA_out", "res"])


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


def guard_function(topo) -> ca.Function:
    """What :func:`optkin.forward_batch` checks at every solved row of a path.

    Inputs (qa_prev, x_prev, qa, x, qa_next, x_next, p): the row and its neighbours on the
    path (the row itself where there is none); outputs

    * ``det``: det W_p(q_a, x) (square W_p; 1 when W_p has more rows than columns, which has
      no orientation);
    * ``h``: a conditioning indicator in [0, 1], the Hadamard ratio of W_p with columns
      scaled by the unknowns' scales: |det(W_p S)| / prod_i |row_i(W_p S)| (rows normalised
      first and sqrt det(N^T N) for a non-square W_p). 1 for orthogonal rows, 0 at a
      singularity; invariant to the scaling of the rows;
    * ``cp`` = [c_back, p_back, c_fwd, p_fwd]: the Euler predictions dx = -W_p^-1 W_a dq_a
      (the velocity model [7.51], W_p and W_a at this row) of the step from the previous
      row (back) and of the step to the next row (fwd): the predicted move |dx| (p_) and
      the distance of the actual move from it (c_), both in the max norm of scaled units
      (angle differences wrapped). Along a smooth branch the distances are second order in
      the step; a jump to another solution makes them as large as the move itself.

    det and W_p^-1 W_a dq_a come from one Householder QR factorisation (:func:`det_solve`).
    """
    st = topo.st
    nx, na, m = topo.nx, topo.na, topo.m
    angle = np.asarray(st.x_angle, dtype=bool)
    qa, x, p = st.qa, st.x, st.p
    scale = topo.x_scale_sym
    qp, xp = ca.SX.sym("qa_prev", na), ca.SX.sym("x_prev", nx)
    qn, xn = ca.SX.sym("qa_next", na), ca.SX.sym("x_next", nx)
    Wp = ca.jacobian(topo.phi_sym, x)
    Wa = ca.jacobian(topo.phi_sym, qa)
    rhs = ca.mtimes(Wa, ca.horzcat(qa - qp, qn - qa))
    Ws = ca.mtimes(Wp, ca.diag(scale))
    rn = ca.sqrt(ca.sum2(Ws * Ws)) + 1e-300
    if m == nx:  # det(W_p S) / prod |rows| = det W_p prod(S) / prod |rows|
        det, D = det_solve(Wp, rhs)
        h = ca.fabs(det)
        for i in range(nx):
            h = h * scale[i]
        for i in range(m):
            h = h / rn[i]
    else:
        N = Ws / ca.repmat(rn, 1, nx)
        det = ca.SX(1)
        h = ca.sqrt(ca.fmax(det_sx(ca.mtimes(N.T, N)), 0))
        D = ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, rhs))
    tau = 2 * np.pi
    sc = 1.0 / scale

    def move(a, b):  # b - a, angles wrapped
        d = b - a
        return ca.vertcat(*[d[i] - tau * ca.floor(d[i] / tau + 0.5) if angle[i] else d[i]
                            for i in range(nx)])

    def mx(v):
        return ca.mmax(ca.fabs(v * sc))

    db, df = -D[:, 0], -D[:, 1]
    cp = ca.vertcat(mx(move(xp, x) - db), mx(db), mx(move(x, xn) - df), mx(df))
    return ca.Function("guard", [qp, xp, qa, x, qn, xn, p], [det, h, cp],
                       ["qa_prev", "x_prev", "qa", "x", "qa_next", "x_next", "p"],
                       ["det", "h", "cp"])


def guard_chunk(topo, chunk: int) -> tuple[ca.Function, str]:
    """The guard mapped over ``chunk`` rows (the geometry unmapped) and its cache tag
    (which hashes the inner Function: a mapped Function's signature hides its body)."""
    import hashlib

    one = guard_function(topo)
    body = hashlib.sha256(one.serialize().encode()).hexdigest()[:16]
    f = one.map(f"guard_{int(chunk)}", "serial", int(chunk), [6], [])
    return f, f"guard:{topo.key}:{int(chunk)}:{body}"
