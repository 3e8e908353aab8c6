"""Where a mechanism's joints are in a configuration: the polylines of a drawing.

Every leg is drawn along its chain (:mod:`optkin.mechanism.legs`): each joint at a point of
its axis, carried by the product of exponentials of the joints before it (Lynch & Park,
*Modern Robotics* (4.14); :func:`optkin.model.joints.chain_transform`, evaluated on the
model's joint values), from the base to the leg's platform point; the platform is the
polygon of those points. A Khalil table is drawn as the segments from each frame's origin
to its antecedent's ([7.11], :func:`optkin.model.structure.khalil_frames`). The
transforms are Functions of the topology with the geometry p as their last input, built
once per topology (:meth:`Model.cached`).

A joint's point on its axis is chosen at the home configuration (every variable zero):
where its axis meets the next joint's (the foot of their common perpendicular), else the
axis point nearest the point chosen before it (the first joint: nearest the chain's end).
A prismatic joint sits where the joint before it sits (the first one: where the next
joint sits): its travel is the segment that lengthens.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .joints import chain_transform
from .structure import _leg_params, khalil_frames

__all__ = ["Drawing", "drawing", "platform_points"]


@dataclass(frozen=True)
class Drawing:
    """The polylines of a mechanism in one configuration (arrays (k, 3)).

    Attributes
    ----------
    legs : list of ndarray
        One polyline per leg, from its base (the first joint) to its platform point.
    platform : ndarray or None
        The platform polygon through the legs' platform points, closed (more than two legs),
        in geometric order (by angle about the centroid in their plane).
    links : list of ndarray
        Khalil tables: one segment per frame, from its antecedent's origin.
    base : ndarray (k, 3)
        The fixed joints (each leg's first point).
    dim : int
        2 when the mechanism moves in the plane z = 0, else 3.
    """

    legs: list[np.ndarray]
    platform: np.ndarray | None
    links: list[np.ndarray]
    base: np.ndarray
    dim: int

    @property
    def lines(self) -> list[np.ndarray]:
        """Every polyline: the legs, the platform polygon, the links."""
        out = list(self.legs)
        if self.platform is not None:
            out.append(self.platform)
        return out + list(self.links)


def drawing(model: Any, q: np.ndarray, pose: np.ndarray | None = None) -> Drawing:
    """The :class:`Drawing` of ``model``'s mechanism at joint values ``q`` (in
    ``mech.joint_names`` order) with the platform at ``pose`` (4x4; default: where the first
    leg's chain puts it)."""
    q = np.asarray(q, dtype=float).ravel()
    if model.platform is None:
        return _khalil_drawing(model, q)
    mech = model.mech
    F = model.cached("drawing:frames", lambda: _frames_function(model))
    out = np.array(F(q, model.p))
    legs, base = [], []
    col = 0
    tol = 1e-9 * max(1.0, float(model.length))
    for leg in mech.legs:
        n = len(leg.names)
        Ts = [np.eye(4)] + [out[:, col + 4 * k: col + 4 * k + 4] for k in range(n + 1)]
        col += 4 * (n + 1)
        refs, b = _reference_points(leg)
        line = [(Ts[k] @ np.append(r, 1.0))[:3] for k, r in enumerate(refs)]
        end = (Ts[n + 1] @ np.append(b, 1.0))[:3]  # the chain's end at the platform point
        line.append(end)
        keep = [line[0]]
        for pnt in line[1:]:
            if np.linalg.norm(pnt - keep[-1]) > tol:
                keep.append(pnt)
        legs.append(np.array(keep))
        base.append(line[0])
    if pose is not None:  # the platform's points where the platform is
        T = np.asarray(pose, dtype=float)
        P = [T[:3, :3] @ bp + T[:3, 3] for bp in platform_points(mech)]
    else:  # where the legs' chains end
        P = [ln[-1] for ln in legs]
    platform = _polygon(np.array(P)) if len(P) > 2 else None
    return Drawing(legs=legs, platform=platform, links=[], base=np.array(base),
                   dim=int(model.platform.space_dim))


def _polygon(P: np.ndarray) -> np.ndarray:
    """The closed polygon through the points P (k, 3) in geometric order: by angle about
    their centroid in their best-fitting plane, starting at the first point (in leg order
    the six joints of a 6-6 platform draw a self-intersecting hexagon). Points that are
    (nearly) collinear or coincide keep the leg order."""
    C = P - P.mean(axis=0)
    _, sv, Vt = np.linalg.svd(C)
    if len(P) > 3 and sv[1] > 1e-9 * max(sv[0], 1e-300):
        ang = np.arctan2(C @ Vt[1], C @ Vt[0])
        order = np.argsort((ang - ang[0]) % (2 * np.pi), kind="stable")
        P = P[order]
    return np.vstack([P, P[:1]])


def platform_points(mech: Any) -> list[np.ndarray]:
    """Each leg's platform point in the platform frame: a point end's own, a frame end's
    last joint (where the chain reaches the platform)."""
    return [np.asarray(leg.platform_point, dtype=float) if leg.end == "point"
            else _reference_points(leg)[1] for leg in mech.legs]


def _reference_points(leg: Any) -> tuple[list[np.ndarray], np.ndarray]:
    """Each joint's point at home (see the module docstring), and the leg's platform point
    in the frame its chain ends at (``home`` times it is where the chain ends at home): a
    point end's is that frame's origin; a frame end's is its last joint's point, in the
    platform frame."""
    S = np.asarray(leg.screws, dtype=float)
    kinds = leg.kinds
    H = np.asarray(leg.home, dtype=float)
    n = len(kinds)
    end_home = H[:3, 3] if leg.end == "point" else H[:3, :3] @ np.asarray(
        leg.platform_point, dtype=float) + H[:3, 3]
    refs: list[np.ndarray | None] = [None] * n
    prev: np.ndarray | None = None
    for k in range(n):
        if kinds[k] != "R":
            continue
        w, a = _axis(S[k])
        pt = None
        if k + 1 < n and kinds[k + 1] == "R":
            w2, a2 = _axis(S[k + 1])
            pt = _common_foot(w, a, w2, a2)
        if pt is None:
            target = prev if prev is not None else end_home
            pt = a + w * float(w @ (target - a))
        refs[k] = pt
        prev = pt
    for k in range(n):  # prismatic joints: where the joint before (or after) them sits
        if refs[k] is None:
            before = [refs[i] for i in range(k - 1, -1, -1) if refs[i] is not None]
            after = [refs[i] for i in range(k + 1, n) if refs[i] is not None]
            refs[k] = before[0] if before else (after[0] if after else end_home)
    if leg.end == "point":
        b = np.zeros(3)  # the chain's end frame: its origin is the platform point
    else:
        last = refs[-1] if n else end_home
        b = np.linalg.solve(H, np.append(last, 1.0))[:3]
    return [np.asarray(r, dtype=float) for r in refs], b


def _axis(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit direction and the point nearest the origin of a revolute screw's axis."""
    w, v = s[:3], s[3:]
    return w, np.cross(w, v)


def _common_foot(w1, a1, w2, a2) -> np.ndarray | None:
    """The point of axis 1 nearest axis 2 (None for parallel axes)."""
    c = np.cross(w1, w2)
    cc = float(c @ c)
    if cc < 1e-18:
        return None
    d = a2 - a1
    t = float(np.cross(d, w2) @ c) / cc
    return a1 + t * w1


def _frames_function(model: Any) -> ca.Function:
    """(q, p) -> per leg, the 4x4 products exp([S_1] q_1) ... exp([S_k] q_k) for k = 1..n
    and that product times the leg's end frame at home, side by side."""
    st = model.structure
    mech = model.mech
    nq = len(mech.joint_names)
    q = ca.SX.sym("q", nq)
    p = st.p
    blocks = []
    off = 0
    iq = 0
    for leg in mech.legs:
        g, off = _leg_params(p, off, leg)
        n = len(leg.names)
        kinds = leg.kinds
        ql = [q[iq + v] for v in range(n)]
        iq += n
        T = None
        for k in range(n):
            T = chain_transform(g["screws"][k:k + 1], kinds[k], ql[k:k + 1]) if T is None \
                else ca.mtimes(T, chain_transform(g["screws"][k:k + 1], kinds[k], ql[k:k + 1]))
            blocks.append(T)
        blocks.append(ca.mtimes(T, g["home"]) if T is not None else g["home"])
    return ca.Function("drawing_frames", [q, p], [ca.horzcat(*blocks)])


def _khalil_drawing(model: Any, q: np.ndarray) -> Drawing:
    mech = model.mech
    frames = mech.table.frames

    def build() -> ca.Function:
        qs = ca.SX.sym("q", len(mech.joint_names))
        p = model.structure.p
        T = khalil_frames(mech, qs, p)
        return ca.Function("drawing_origins", [qs, p],
                           [ca.horzcat(T[0][:3, 3], *[T[f.j][:3, 3] for f in frames])])

    F = model.cached("drawing:origins", build)
    O = np.array(F(q, model.p))
    origin = {0: O[:, 0]}
    for k, f in enumerate(frames):
        origin[f.j] = O[:, k + 1]
    links = [np.array([origin[f.a], origin[f.j]]) for f in frames]
    pts = np.vstack(links)
    dim = 2 if np.ptp(pts[:, 2]) < 1e-9 else 3
    return Drawing(legs=[], platform=None, links=links, base=np.zeros((0, 3)), dim=dim)
