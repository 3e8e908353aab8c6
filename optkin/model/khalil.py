"""CasADi expressions for Khalil-table mechanisms: frames [7.3], loop closure [7.8]."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import MechanismError
from ..mechanism import Mechanism

__all__ = ["khalil_T", "frames_0", "gibbs", "closure_rows", "select_rows"]


def khalil_T(gamma, b, alpha, d, theta, r):
    """[7.3] as a CasADi 4x4 expression."""
    cg, sg = ca.cos(gamma), ca.sin(gamma)
    cal, sal = np.cos(alpha), np.sin(alpha)
    ct, st = ca.cos(theta), ca.sin(theta)
    return ca.vertcat(
        ca.horzcat(cg * ct - sg * cal * st, -cg * st - sg * cal * ct, sg * sal, d * cg + r * sg * sal),
        ca.horzcat(sg * ct + cg * cal * st, -sg * st + cg * cal * ct, -cg * sal, d * sg - r * cg * sal),
        ca.horzcat(sal * st, sal * ct, cal, r * cal + b),
        ca.horzcat(0, 0, 0, 1),
    )


def frames_0(mech: Mechanism, q: ca.SX) -> dict[int, ca.SX]:
    """0T_j for every frame j, by [7.11], with joint values q (all joints, in order)."""
    table = mech.table
    index = {n: i for i, n in enumerate(mech.joint_names)}
    T: dict[int, ca.SX] = {0: ca.SX.eye(4)}
    for f in table.frames:
        th, rr = f.theta, f.r
        if f.sigma == 0:
            th = th + q[index[f.name]]
        elif f.sigma == 1:
            rr = rr + q[index[f.name]]
        T[f.j] = ca.mtimes(T[f.a], khalil_T(f.gamma, f.b, f.alpha, f.d, th, rr))
    return T


def gibbs(R):
    """Gibbs vector tan(angle/2) * axis of a rotation: zero only at the identity."""
    v = ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    return v / (1 + R[0, 0] + R[1, 1] + R[2, 2])


def closure_rows(mech: Mechanism, T: dict[int, ca.SX]) -> tuple[ca.SX, list[str]]:
    """All 6B candidate rows of [7.8]: the pose of R_{k+B} in R_k (position, Gibbs vector)."""
    rows, names = [], []
    table = mech.table
    for k in table.cut_frames:
        Tk, Tp = T[k], T[table.partner(k)]
        Rk = Tk[:3, :3]
        pe = ca.mtimes(Rk.T, Tp[:3, 3] - Tk[:3, 3])
        Re = ca.mtimes(Rk.T, Tp[:3, :3])
        rows += [pe, gibbs(Re)]
        names += [f"loop:{k}.{c}" for c in ("px", "py", "pz", "rx", "ry", "rz")]
    return (ca.vertcat(*rows) if rows else ca.SX(0, 1)), names


def select_rows(
    mech: Mechanism, q: ca.SX, rows: ca.SX, names: list[str], samples: int = 4, seed: int = 7
) -> list[int]:
    """Pick independent closure rows by rank over random configurations.

    A row whose gradient vanishes everywhere (a planar loop's out-of-plane rows) or that is a
    combination of kept rows at every sample is dropped. A dropped row whose value is a
    non-zero constant means the loop can never close: that is a description error.
    """
    if rows.shape[0] == 0:
        return []
    f = ca.Function("rows", [q], [rows, ca.jacobian(rows, q)])
    rng = np.random.default_rng(seed)
    nq = q.shape[0]
    vals, jacs = [], []
    for _ in range(samples):
        qs = rng.uniform(-np.pi, np.pi, nq)
        v, J = f(qs)
        vals.append(np.array(v).ravel())
        jacs.append(np.array(J))
    G = np.hstack(jacs)  # rows x (samples * nq)
    scale = max(1.0, float(np.abs(G).max()))
    kept: list[int] = []
    basis = np.zeros((0, G.shape[1]))
    for i in range(G.shape[0]):
        cand = np.vstack([basis, G[i]])
        if np.linalg.matrix_rank(cand, tol=1e-9 * scale) > basis.shape[0]:
            kept.append(i)
            basis = cand
        elif np.allclose(G[i], 0.0, atol=1e-12 * scale):
            const = np.array([v[i] for v in vals])
            if np.all(np.isfinite(const)) and np.max(np.abs(const)) > 1e-9:
                raise MechanismError(
                    f"{names[i]}: this closure row is the constant {const[0]:.6g} for every "
                    "configuration, so the loop can never close; check the offsets (b, r, d) "
                    "of the frames of this loop"
                )
    return kept
