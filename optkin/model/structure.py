"""The symbolic structure of a mechanism: its closure with the geometry as a parameter.

:func:`build_structure` turns a :class:`~optkin.mechanism.Mechanism` into a
:class:`Structure`: CasADi SX expressions of the closure rows Phi(q_a, x; p), the
end-effector pose, all joint values q, and the joint-level closure, over symbols q_a
(actuated joints), x (the model's unknowns) and p (the geometry, plus the mechanism's
length scale as its last entry). The expressions depend on the mechanism's topology only;
numbers enter through p. This module and :mod:`optkin.mechanism` are the only places that
know what kind of description a mechanism has.

Khalil tables (Khalil & Dombre 2002): x = the passive and cut joints; the rows are the position and
Gibbs vector of frame k+B in frame k for every cut joint k ([7.8]); p holds (gamma, b,
alpha, d, theta, r) of every frame.

Legs (:mod:`optkin.mechanism.legs`): x = the platform coordinates (see
:mod:`optkin.mechanism.platforms`) then the passive variables of the legs solved in their
chain form. A distance leg (reduced form) gives one row ``|P - C(q_a)| - l``; a chain
ending at a platform point gives the point's rows ``T_leg(q) e0 - T_platform b``; a chain
ending at the platform frame gives its position and the Gibbs vector of the relative
rotation. A spatial platform adds the quaternion norm row.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..mechanism import Mechanism
from ..mechanism.platforms import PLATFORMS
from .joints import JOINTS, chain_transform

__all__ = ["Structure", "LegSlots", "build_structure", "gibbs", "twist_jacobian",
           "structure_key", "platform_frame", "khalil_frames"]


def platform_frame(kind: str, x) -> tuple[Any, Any]:
    """(R 3x3, p 3x1) of a platform of ``kind`` as CasADi expressions of its
    coordinates x (see :mod:`optkin.mechanism.platforms`)."""
    if kind == "planar":
        c, s = ca.cos(x[2]), ca.sin(x[2])
        R = ca.vertcat(ca.horzcat(c, -s, 0), ca.horzcat(s, c, 0), ca.DM([[0, 0, 1]]))
        return R, ca.vertcat(x[0], x[1], 0)
    if kind == "planar_point":
        return ca.DM.eye(3), ca.vertcat(x[0], x[1], 0)
    if kind == "spatial":
        w, a, b, c = x[3], x[4], x[5], x[6]
        R = ca.vertcat(
            ca.horzcat(1 - 2 * (b * b + c * c), 2 * (a * b - c * w), 2 * (a * c + b * w)),
            ca.horzcat(2 * (a * b + c * w), 1 - 2 * (a * a + c * c), 2 * (b * c - a * w)),
            ca.horzcat(2 * (a * c - b * w), 2 * (b * c + a * w), 1 - 2 * (a * a + b * b)),
        )
        return R, ca.vertcat(x[0], x[1], x[2])
    if kind == "spatial_translational":
        return ca.DM.eye(3), ca.vertcat(x[0], x[1], x[2])
    raise ValueError(f"no frame for platform kind {kind!r}")


def gibbs(R):
    """Gibbs vector tan(angle/2) * axis of a rotation: zero only at the identity."""
    v = ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    return v / (1 + R[0, 0] + R[1, 1] + R[2, 2])


def twist_jacobian(R, p, z) -> ca.SX:
    """6 x n Jacobian of the twist (v, omega) of the frame (R, p) w.r.t. z (base frame):
    v = dp/dz zdot and [omega]_x = Rdot R^T."""
    Jp = ca.jacobian(p, z)
    cols = []
    for k in range(z.shape[0]):
        dR = ca.reshape(ca.jacobian(R, z[k]), 3, 3)
        S = ca.mtimes(dR, R.T)
        cols.append(ca.vertcat(0.5 * (S[2, 1] - S[1, 2]), 0.5 * (S[0, 2] - S[2, 0]),
                               0.5 * (S[1, 0] - S[0, 1])))
    Jw = ca.horzcat(*cols) if cols else ca.SX(3, 0)
    return ca.vertcat(Jp, Jw)


@dataclass
class LegSlots:
    """Where a leg's quantities sit in the model's vectors."""

    q: slice                      # its joint values in q
    qa: tuple[int, ...]           # its actuated variables in q_a
    x: tuple[int, ...]            # its passive variables solved in x (chain form)
    reported: tuple[int, ...]     # its variables computed from the orientation (in q)
    reduced: bool                 # rows in the distance form
    pivot: tuple[int, ...] = ()   # variables the distance form's pivot computes (in q)


@dataclass
class Structure:
    """Symbols and expressions of one mechanism topology (see the module docstring)."""

    qa: ca.SX
    x: ca.SX
    p: ca.SX
    phi: ca.SX                      # candidate closure rows (all of them)
    row_names: list[str]
    row_length: np.ndarray          # rows that are lengths (vs angles / unit-free)
    row_leg: np.ndarray             # leg of each row (-1: none)
    T: ca.SX                        # end-effector pose 4x4
    q: ca.SX                        # all joint values (mech.joint_names order)
    x_names: tuple[str, ...]
    x_angle: np.ndarray
    x_length: np.ndarray            # x entries that scale with the mechanism's size
    platform: str | None            # platform kind (legs) or None (Khalil)
    n_platform: int                 # how many leading x entries are platform coordinates
    legs: list[LegSlots] = field(default_factory=list)
    # joint-level closure: every joint variable (and the platform coordinates) unknown
    z: ca.SX = None                 # type: ignore[assignment]
    z_names: tuple[str, ...] = ()
    H: ca.SX = None                 # type: ignore[assignment]
    H_names: list[str] = field(default_factory=list)
    H_length: np.ndarray = None     # type: ignore[assignment]
    K: ca.SX = None                 # type: ignore[assignment]  twist Jacobian over z
    z_x: np.ndarray = None          # type: ignore[assignment]  where x's entries sit in z
    leg_frames: list[tuple[ca.SX, ca.SX]] = field(default_factory=list)  # (T_end(q), kind)
    distance: list[tuple[Any, Any, Any] | None] = field(default_factory=list)
    cache: dict[str, Any] = field(default_factory=dict)  # Functions built once per structure


def structure_key(mech: Mechanism, reduced: bool = True) -> tuple:
    """What the symbolic structure depends on (hashable)."""
    return (mech.topology, bool(reduced))


def build_structure(mech: Mechanism) -> Structure:
    """The :class:`Structure` of ``mech`` (its topology; the numbers stay in p)."""
    if mech.kind == "khalil":
        return _khalil(mech)
    return _legs(mech)


# --------------------------------------------------------------------------------------
# Khalil tables


def _khalil_T(gamma, b, alpha, d, theta, r):
    """[7.3] with every entry possibly symbolic."""
    cg, sg = ca.cos(gamma), ca.sin(gamma)
    cal, sal = ca.cos(alpha), ca.sin(alpha)
    ct, st = ca.cos(theta), ca.sin(theta)
    return ca.vertcat(
        ca.horzcat(cg * ct - sg * cal * st, -cg * st - sg * cal * ct, sg * sal,
                   d * cg + r * sg * sal),
        ca.horzcat(sg * ct + cg * cal * st, -sg * st + cg * cal * ct, -cg * sal,
                   d * sg - r * cg * sal),
        ca.horzcat(sal * st, sal * ct, cal, r * cal + b),
        ca.DM([[0, 0, 0, 1]]),
    )


def khalil_frames(mech: Mechanism, q, p) -> dict[int, Any]:
    """0T_j of every frame ([7.11]) from all joint values q and the geometry p."""
    table = mech.table
    index = {n: i for i, n in enumerate(mech.joint_names)}
    T: dict[int, Any] = {0: ca.DM.eye(4)}
    for k, f in enumerate(table.frames):
        g = p[6 * k: 6 * k + 6]
        th, rr = g[4], g[5]
        if f.sigma == 0:
            th = th + q[index[f.name]]
        elif f.sigma == 1:
            rr = rr + q[index[f.name]]
        T[f.j] = ca.mtimes(T[f.a], _khalil_T(g[0], g[1], g[2], g[3], th, rr))
    return T


def _khalil_rows(mech: Mechanism, T: dict[int, Any]) -> tuple[Any, list[str]]:
    rows, names = [], []
    table = mech.table
    for k in table.cut_frames:
        Tk, Tp = T[k], T[table.partner(k)]
        Rk = Tk[:3, :3]
        pe = ca.mtimes(Rk.T, Tp[:3, 3] - Tk[:3, 3])
        rows += [pe, gibbs(ca.mtimes(Rk.T, Tp[:3, :3]))]
        names += [f"loop:{k}.{c}" for c in ("px", "py", "pz", "rx", "ry", "rz")]
    return (ca.vertcat(*rows) if rows else ca.SX(0, 1)), names


def _khalil(mech: Mechanism) -> Structure:
    na = mech.n_actuated
    nq = len(mech.joint_names)
    act = np.array(mech.actuated)
    passive = np.flatnonzero(~act)
    qa = ca.SX.sym("qa", na)
    x = ca.SX.sym("x", passive.size)
    p = ca.SX.sym("p", 6 * len(mech.table.frames) + 1)
    parts, ia, ip = [], 0, 0
    for a in mech.actuated:
        if a:
            parts.append(qa[ia])
            ia += 1
        else:
            parts.append(x[ip])
            ip += 1
    q = ca.vertcat(*parts) if parts else ca.SX(0, 1)
    T = khalil_frames(mech, q, p)
    phi, names = _khalil_rows(mech, T)
    n_rows = len(names)
    x_names = tuple(mech.joint_names[i] for i in passive)
    x_angle = np.array([mech.revolute[i] for i in passive], dtype=bool)
    # the joint-level closure: the same rows over every joint
    z = ca.SX.sym("q", nq)
    Tz = khalil_frames(mech, z, p)
    H, _ = _khalil_rows(mech, Tz)
    Te = Tz[mech.end_effector]
    return Structure(
        qa=qa, x=x, p=p, phi=phi, row_names=names,
        row_length=np.array([n.split(".")[-1].startswith("p") for n in names], dtype=bool),
        row_leg=np.full(n_rows, -1), T=T[mech.end_effector], q=q, x_names=x_names,
        x_angle=x_angle, x_length=~x_angle, platform=None, n_platform=0,
        z=z, z_names=tuple(mech.joint_names), H=H, H_names=list(names),
        H_length=np.array([n.split(".")[-1].startswith("p") for n in names], dtype=bool),
        K=twist_jacobian(Te[:3, :3], Te[:3, 3], z), z_x=passive.copy(),
    )


# --------------------------------------------------------------------------------------
# legs


def _leg_params(p, off: int, leg) -> tuple[dict[str, Any], int]:
    """Symbolic views of one leg's geometry in p (layout of ``Leg.geometry``)."""
    n = len(leg.screws)
    g: dict[str, Any] = {}
    g["screws"] = [p[off + 6 * k: off + 6 * k + 6] for k in range(n)]
    off += 6 * n
    cols = [p[off + 3 * c: off + 3 * c + 3] for c in range(4)]
    g["home"] = ca.vertcat(ca.horzcat(*cols), ca.DM([[0, 0, 0, 1]]))
    off += 12
    g["b"] = p[off: off + 3]
    off += 3
    if leg.distance is not None:
        g["centre"] = p[off: off + 3]
        g["direction"] = p[off + 3: off + 6]
        g["length"] = p[off + 6]
        off += 7
    return g, off


def _legs(mech: Mechanism, reduced: bool | None = None) -> Structure:
    plat = PLATFORMS[mech.platform]
    reduced = mech.reduced if reduced is None else reduced
    legs = mech.legs
    na = mech.n_actuated
    nq = len(mech.joint_names)
    npl = plat.nx()
    # x: platform coordinates, then the passive variables of the legs in chain form
    slots: list[LegSlots] = []
    x_names = list(plat.coords)
    x_angle = list(plat.angles)
    x_length = list(plat.lengths)
    iq = ia = 0
    for k, leg in enumerate(legs):
        n = len(leg.names)
        rep = tuple(range(iq + n - leg.n_reported, iq + n))
        red = reduced and leg.distance is not None
        qa_idx = tuple(range(ia, ia + len(leg.actuated)))
        ia += len(leg.actuated)
        xs: list[int] = []
        piv: tuple[int, ...] = ()
        kinds = leg.kinds
        if red:
            d = leg.distance
            start = sum(JOINTS[c].n() for c in leg.joints[:d.pivot])
            piv = tuple(range(iq + start, iq + start + JOINTS[leg.joints[d.pivot]].n()))
        else:
            for v in range(n):
                if v in leg.actuated or iq + v in rep:
                    continue
                xs.append(len(x_names))
                x_names.append(f"L{k + 1}.{leg.names[v]}")
                x_angle.append(kinds[v] == "R")
                x_length.append(kinds[v] == "P")
        slots.append(LegSlots(slice(iq, iq + n), qa_idx, tuple(xs), rep, red, piv))
        iq += n
    nx = len(x_names)
    qa = ca.SX.sym("qa", na)
    x = ca.SX.sym("x", nx)
    sizes = [len(leg.geometry()) for leg in legs]
    p = ca.SX.sym("p", sum(sizes) + 1)
    R, pv = platform_frame(plat.name, x[:npl])
    T_ee = ca.vertcat(ca.horzcat(R, pv), ca.DM([[0, 0, 0, 1]]))
    rows: list[Any] = []
    names: list[str] = []
    is_len: list[bool] = []
    row_leg: list[int] = []
    q_parts: list[Any] = []
    H_rows: list[Any] = []
    H_names: list[str] = []
    H_len: list[bool] = []
    z = ca.SX.sym("q", nq)
    zx = ca.SX.sym("xp", npl)
    Rz, pz = platform_frame(plat.name, zx)
    leg_frames = []
    distance = []
    off = 0
    for k, (leg, sl) in enumerate(zip(legs, slots)):
        g, off = _leg_params(p, off, leg)
        n = len(leg.names)
        kinds = leg.kinds
        # this leg's variables in the model: actuated from qa, solved ones from x; the
        # reported (end joint) and pivot ones are computed below
        var: list[Any] = [None] * n
        for j, a in enumerate(leg.actuated):
            var[a] = qa[sl.qa[j]]
        free = [v for v in range(n) if v not in leg.actuated and sl.q.start + v not in sl.reported]
        if not sl.reduced:
            for v, xi in zip(free, sl.x):
                var[v] = x[xi]
        P = pv + ca.mtimes(R, g["b"])
        label = f"leg:{k + 1}"
        if sl.reduced:
            d = leg.distance
            drv = d.driver
            Td = chain_transform(g["screws"][:drv], kinds[:drv], var[:drv]) if drv else ca.DM.eye(4)
            C = ca.mtimes(Td[:3, :3], g["centre"]) + Td[:3, 3]
            dist = ca.norm_2(P - C)
            length = var[leg.actuated[0]] if d.length is None else g["length"]
            rows.append(dist - length)
            names.append(label)
            is_len.append(True)
            row_leg.append(k)
            # the pivot turns the link from its home direction towards P
            pj = JOINTS[leg.joints[d.pivot]]
            pstart = sum(JOINTS[c].n() for c in leg.joints[:d.pivot])
            axes = [ca.mtimes(Td[:3, :3], g["screws"][pstart + i][:3]) for i in range(3)] \
                if pj.n() == 3 else [ca.mtimes(Td[:3, :3], g["screws"][pstart + i][:3])
                                     for i in range(pj.n())]
            u = (P - C) / (dist + 1e-300)
            dh = ca.mtimes(Td[:3, :3], g["direction"])
            if pj.n() == 3:  # a spherical pivot: its third axis completes the frame
                axes = axes[:2] + [ca.cross(axes[0], axes[1])]
            pv_vals = pj.align(axes, dh, u)
            for i, v in enumerate(range(pstart, pstart + pj.n())):
                var[v] = pv_vals[i]
            # variables between the pivot and the end that are neither actuated nor
            # reported (none for the builders' distance legs) stay at zero
            for v in range(n):
                if var[v] is None and sl.q.start + v not in sl.reported:
                    var[v] = ca.SX(0)
            distance.append((C, P, length))
        else:
            distance.append(None)
            if leg.end == "point":
                qv = [var[v] if var[v] is not None else ca.SX(0) for v in range(n)]
                Tl = chain_transform(g["screws"], kinds, qv, g["home"])
                e = Tl[:3, 3]
                for c in plat.point_rows:
                    rows.append(e[c] - P[c])
                    names.append(f"{label}.{'xyz'[c]}")
                    is_len.append(True)
                    row_leg.append(k)
            else:
                qv = [var[v] for v in range(n)]
                Tl = chain_transform(g["screws"], kinds, qv, g["home"])
                _frame_rows(plat, Tl, R, pv, label, k, rows, names, is_len, row_leg)
        # reported end joint: its angles from the orientation left to it
        if sl.reported:
            nr = len(sl.reported)
            first = n - nr
            pre = [var[v] if var[v] is not None else ca.SX(0) for v in range(first)]
            Tp = chain_transform(g["screws"][:first], kinds[:first], pre) if first else \
                ca.DM.eye(4)
            axes = [ca.mtimes(Tp[:3, :3], g["screws"][first + i][:3]) for i in range(nr)]
            Rrel = ca.mtimes(R, Tp[:3, :3].T)
            ej = JOINTS[leg.joints[-1]]
            if ej.n() == 3:
                vals = ej.orient(axes, Rrel)
            else:
                vals = ej.orient(axes, Rrel)
            for i in range(nr):
                var[first + i] = vals[i]
        q_parts += [var[v] if var[v] is not None else ca.SX(0) for v in range(n)]
        # the joint-level closure: every variable unknown (z), the platform in zx
        ql = [z[sl.q.start + v] for v in range(n)]
        Tj = chain_transform(g["screws"], kinds, ql, g["home"])
        Pz = pz + ca.mtimes(Rz, g["b"])
        leg_frames.append(Tj)
        if leg.end == "point" and not leg.reported:
            for c in plat.point_rows:
                H_rows.append(Tj[c, 3] - Pz[c])
                H_names.append(f"{label}.p{'xyz'[c]}")
                H_len.append(True)
        else:
            if leg.end == "point":  # the end joint joins the chain's frame to the platform
                Tp_ = ca.vertcat(ca.horzcat(Rz, Pz), ca.DM([[0, 0, 0, 1]]))
                hr: list[Any] = []
                hn: list[str] = []
                hl: list[bool] = []
                _frame_rows(plat, Tj, Tp_[:3, :3], Tp_[:3, 3], label, k, hr, hn, hl, [],
                            prefix=True)
            else:
                hr, hn, hl = [], [], []
                _frame_rows(plat, Tj, Rz, pz, label, k, hr, hn, hl, [], prefix=True)
            H_rows += hr
            H_names += hn
            H_len += hl
    if plat.norm_row:
        rows.append(ca.sumsqr(x[3:7]) - 1)
        names.append("quaternion:norm")
        is_len.append(False)
        row_leg.append(-1)
        H_rows.append(ca.sumsqr(zx[3:7]) - 1)
        H_names.append("quaternion:norm")
        H_len.append(False)
    phi = ca.vertcat(*rows) if rows else ca.SX(0, 1)
    Z = ca.vertcat(z, zx)
    K = ca.horzcat(ca.SX(6, nq), twist_jacobian(Rz, pz, zx))
    z_x = np.concatenate([nq + np.arange(npl), np.zeros(0, dtype=int)])
    # solved leg variables sit in q
    xq = []
    for leg, sl in zip(legs, slots):
        n = len(leg.names)
        free = [v for v in range(n) if v not in leg.actuated and sl.q.start + v not in sl.reported]
        if not sl.reduced:
            xq += [sl.q.start + v for v in free]
    z_x = np.concatenate([z_x, np.array(xq, dtype=int)]).astype(int)
    return Structure(
        qa=qa, x=x, p=p, phi=phi, row_names=names, row_length=np.array(is_len, dtype=bool),
        row_leg=np.array(row_leg, dtype=int), T=T_ee, q=ca.vertcat(*q_parts),
        x_names=tuple(x_names), x_angle=np.array(x_angle, dtype=bool),
        x_length=np.array(x_length, dtype=bool), platform=plat.name, n_platform=npl,
        legs=slots, z=Z, z_names=tuple(mech.joint_names) + tuple(f"x.{c}" for c in plat.coords),
        H=ca.vertcat(*H_rows) if H_rows else ca.SX(0, 1), H_names=H_names,
        H_length=np.array(H_len, dtype=bool), K=K, z_x=z_x, leg_frames=leg_frames,
        distance=distance,
    )


def _frame_rows(plat, Tl, R, pv, label, k, rows, names, is_len, row_leg, prefix=False):
    """The rows of a chain ending at the platform frame (position, Gibbs vector)."""
    dp = Tl[:3, 3] - pv
    g = gibbs(ca.mtimes(R.T, Tl[:3, :3]))
    comps = ("px", "py", "pz", "rx", "ry", "rz") if prefix else ("x", "y", "z", "rx", "ry", "rz")
    for c in plat.frame_rows:
        rows.append(dp[c] if c < 3 else g[c - 3])
        names.append(f"{label}.{comps[c]}")
        is_len.append(c < 3)
        row_leg.append(k)
