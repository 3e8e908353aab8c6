"""CasADi expressions for leg-described platforms: one closure equation per leg.

The unknowns x are the platform coordinates: (x, y, phi) for planar platforms, (x, y) for
planar point platforms, (x, y, z, qw, qx, qy, qz) for spatial ones (a unit quaternion,
whose norm is one more closure row) and (x, y, z) for translational ones. Leg i gives
f_i(x, q_a,i) = |P_i(x) - C_i(q_a,i)| - l_i = 0, the leg-by-leg model of seed 003, so that
A = df/dx and B = df/dq_a (diagonal) are Chablat and Wenger's matrices (seed 004).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..mechanism import Mechanism

__all__ = ["platform_frame", "leg_rows", "x_dim"]


def x_dim(platform: str) -> int:
    return {"planar": 3, "planar_point": 2, "spatial": 7, "spatial_translational": 3}[platform]


def platform_frame(platform: str, x) -> tuple:
    """(R, p) of the platform as CasADi expressions of x (R is 3x3, p is 3x1)."""
    if platform == "planar":
        c, s = ca.cos(x[2]), ca.sin(x[2])
        R = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.horzcat(0, 0, 1))
        p = ca.vertcat(x[0], x[1], 0)
    elif platform == "planar_point":
        R = ca.SX.eye(3) if isinstance(x, ca.SX) else ca.DM.eye(3)
        p = ca.vertcat(x[0], x[1], 0)
    elif platform == "spatial":
        w, a, b, c = x[3], x[4], x[5], x[6]
        R = ca.vertcat(
            ca.horzcat(1 - 2 * (b * b + c * c), 2 * (a * b - c * w), 2 * (a * c + b * w)),
            ca.horzcat(2 * (a * b + c * w), 1 - 2 * (a * a + c * c), 2 * (b * c - a * w)),
            ca.horzcat(2 * (a * c - b * w), 2 * (b * c + a * w), 1 - 2 * (a * a + b * b)),
        )
        p = ca.vertcat(x[0], x[1], x[2])
    else:
        R = ca.SX.eye(3) if isinstance(x, ca.SX) else ca.DM.eye(3)
        p = ca.vertcat(x[0], x[1], x[2])
    return R, p


def _pad3(v: np.ndarray) -> np.ndarray:
    return np.concatenate([v, np.zeros(3 - v.size)]) if v.size < 3 else v


def leg_rows(mech: Mechanism, qa, x) -> tuple[ca.SX, list[str]]:
    """The closure rows f_i(x, q_a,i), one per leg (+ the quaternion norm for spatial)."""
    R, p = platform_frame(mech.platform, x)
    rows, names = [], []
    for i, leg in enumerate(mech.legs):
        P = p + ca.mtimes(R, _pad3(leg.platform))
        A = _pad3(leg.base)
        t = leg.type
        qi = qa[i]
        if t in ("RPR", "UPS", "SPS"):
            rows.append(ca.norm_2(P - A) - qi)
        elif t == "RRR":
            l1, l2 = leg.lengths
            C = A + l1 * ca.vertcat(ca.cos(qi), ca.sin(qi), 0)
            rows.append(ca.norm_2(P - C) - l2)
        else:  # RUS / RSS
            la, lb = leg.lengths
            w = np.cross(leg.axis, leg.arm)
            C = A + la * (ca.cos(qi) * leg.arm + ca.sin(qi) * w)
            rows.append(ca.norm_2(P - C) - lb)
        names.append(f"leg:{i + 1}")
    if mech.platform == "spatial":
        rows.append(ca.sumsqr(x[3:7]) - 1)
        names.append("quaternion:norm")
    return ca.vertcat(*rows), names
