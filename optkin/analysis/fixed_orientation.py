"""Singular curves of a spatial platform that keeps its orientation, section by section.

Some spatial platforms with three actuators only translate in an operation mode of theirs
(Tsai's 3-UPU, whose universal joints keep two pairs of parallel axes): their model has the
full pose and every passive joint as unknowns (19 for a 3-UPU), no closed-form chart, and
configuration-space singularities where the operation modes meet, so the augmented system
of :mod:`optkin.analysis.continuation` over all the unknowns is itself singular along the
very curves to trace (every point of the 3-UPU's constraint singularity is such a meeting
point). Restricted to the mode, the configuration is a smooth function of the platform
position p: with the orientation held at the mode's, the closure is solved for the actuated
and passive joints by Gauss-Newton (the rows are consistent but redundant), continued from
a neighbouring point so that every leg stays on its branch. On that chart the parallel
singularities are the zeros of

    g(p) = det(N W_p S),

W_p the closure's Jacobian over the unknowns x at the configuration of p, S its columns'
scales and N the rows' normalisation (so |g| <= 1, Hadamard): a smooth scalar field whose
zero set in a section z = const is a set of curves. They are traced here by a
predictor-corrector on g = 0 in the plane: the tangent normal to grad g (central
differences of 1e-6 mechanism sizes), the corrector a secant iteration along the normal
until |g| < ``tol``; curves stop at the box, where the chart fails (the mode's boundary),
or when they close. Seeds come from sign changes of g between neighbouring nodes of a grid
of the section (which only seeds: every point returned is a corrected point of g = 0 whose
closure residual is below 1e-12).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MechanismError

__all__ = ["FixedOrientation", "fixed_orientation", "section_curves"]


@dataclass
class _Section:
    points: np.ndarray  # (k, 3) in (x, y, z)
    v: np.ndarray  # (k, na + nx)
    closed: bool
    residual: np.ndarray  # (k,)
    working_mode: None = None


class FixedOrientation:
    """The chart p -> configuration of a platform that only translates (see the module
    docstring), from a configuration ``v_ref`` of that mode."""

    def __init__(self, model: Any, v_ref: np.ndarray) -> None:
        self.model = model
        self.na, self.nx, self.npl = model.na, model.nx, model.n_platform
        self.ev = model.fast("W")
        self.v_ref = np.asarray(v_ref, dtype=float).copy()
        na, npl = self.na, self.npl
        self.free = np.r_[np.arange(na), na + np.arange(npl, self.nx)]
        self.L = float(model.length)
        self.col = np.asarray(model.x_scale, dtype=float)
        self.vscale = np.r_[np.where([bool(model.mech.revolute[i])
                                      for i in model.mech.active_index], 1.0, self.L),
                            self.col][self.free]

    def _eval(self, v: np.ndarray):
        na = self.na
        self.ev(v[:na], v[na:])
        return self.ev.dense(0).ravel().copy(), self.ev.dense(1).copy(), self.ev.dense(2).copy()

    def solve(self, p: np.ndarray, v0: np.ndarray, tol: float = 1e-13) -> np.ndarray | None:
        """The configuration of platform position ``p`` (orientation kept), by Gauss-Newton
        on the closure from ``v0`` (a configuration of a nearby position), or None."""
        na, npl = self.na, self.npl
        v = v0.copy()
        v[na:na + 3] = p
        done = False
        for _ in range(30):
            phi, Wp, Wa = self._eval(v)
            r = float(np.max(np.abs(phi)))
            if not np.isfinite(r):
                return None
            if done:  # one update past the tolerance: the joints to rounding (g, a
                return v  # function of them, is then smooth to rounding too)
            done = r < tol * max(1.0, self.L)
            J = np.hstack([Wa, Wp[:, npl:]]) * self.vscale
            du = np.linalg.lstsq(J, -phi, rcond=None)[0]
            n = float(np.max(np.abs(du)))
            if n > 0.3:  # far from the chart's point: a damped step
                du *= 0.3 / n
            v[self.free] += du * self.vscale
        return None

    def g(self, v: np.ndarray) -> tuple[float, float]:
        """(g, closure residual) at a configuration: the normalised det W_p."""
        phi, Wp, _ = self._eval(v)
        W = Wp * self.col
        nr = np.linalg.norm(W, axis=1)
        if np.any(nr == 0):
            return 0.0, float(np.max(np.abs(phi)))
        return float(np.linalg.det(W / nr[:, None])), float(np.max(np.abs(phi)))


def _field(ch: FixedOrientation, z: float, xy: np.ndarray, v0: np.ndarray):
    v = ch.solve(np.array([xy[0], xy[1], z]), v0)
    if v is None:
        return None, None
    return ch.g(v)[0], v


def _grad(ch: FixedOrientation, z: float, xy: np.ndarray, v: np.ndarray) -> np.ndarray | None:
    h = 1e-6 * ch.L
    out = np.empty(2)
    for k in range(2):
        e = np.zeros(2)
        e[k] = h
        gp, _ = _field(ch, z, xy + e, v)
        gm, _ = _field(ch, z, xy - e, v)
        if gp is None or gm is None:
            return None
        out[k] = (gp - gm) / (2 * h)
    return out


def _correct(ch, z, xy, n, v0, g0, dg, tol, hcap):
    """Secant iteration for g(xy + s n) = 0 from s = 0 (g0 there, slope dg): converged
    when |g| < ``tol`` and the last secant step is below 1e-11 mechanism sizes."""
    s0, f0 = 0.0, g0
    if dg == 0 or not np.isfinite(dg):
        return None
    s1 = -g0 / dg
    v = v0
    for _ in range(16):
        if abs(s1) > hcap:
            return None
        f1, v1 = _field(ch, z, xy + s1 * n, v)
        if f1 is None:
            return None
        v = v1
        step = abs(s1 - s0)
        if f1 == 0 or (abs(f1) < tol and step < 1e-11 * ch.L):
            return xy + s1 * n, v1
        if f1 == f0:
            return (xy + s1 * n, v1) if abs(f1) < tol else None
        s0, s1, f0 = s1, s1 - f1 * (s1 - s0) / (f1 - f0), f1
    return None


def _trace(ch, z, xy0, v0, box, hmax, tol, max_steps):
    """Both directions from a point of g = 0: (points, configurations, closed)."""
    L = ch.L
    runs = []
    for sign in (1.0, -1.0):
        xy, v = xy0.copy(), v0.copy()
        gr = _grad(ch, z, xy, v)
        if gr is None or not np.any(gr):
            return None
        t = sign * np.array([-gr[1], gr[0]]) / np.linalg.norm(gr)
        h = 0.25 * hmax * L
        pts, vs = [xy.copy()], [v.copy()]
        closed = False
        for _ in range(max_steps):
            xp = xy + h * t
            gp, vp = _field(ch, z, xp, v)
            ok = None
            if gp is not None:
                nrm = np.array([t[1], -t[0]])
                dg = float(gr @ nrm)
                ok = _correct(ch, z, xp, nrm, vp, gp, dg, tol, 0.5 * h + 1e-3 * L)
            if ok is None:
                h *= 0.5
                if h < 1e-5 * hmax * L:
                    break
                continue
            xn, vn = ok
            grn = _grad(ch, z, xn, vn)
            if grn is None or not np.any(grn):
                break
            tn = np.array([-grn[1], grn[0]]) / np.linalg.norm(grn)
            if tn @ t < 0:
                tn = -tn
            turn = float(np.arccos(np.clip(tn @ t, -1, 1)))
            xy, v, t, gr = xn, vn, tn, grn
            pts.append(xy.copy())
            vs.append(v.copy())
            h = min(hmax * L, h * (1.5 if turn < 0.1 else 0.7 if turn > 0.3 else 1.0))
            if not (box[0, 0] <= xy[0] <= box[0, 1] and box[1, 0] <= xy[1] <= box[1, 1]):
                break
            if len(pts) > 8 and np.linalg.norm(xy - xy0) < 0.75 * h:
                closed = True  # back at the start
                break
        runs.append((pts, vs, closed))
        if closed:
            break
    (p1, v1, c1) = runs[0]
    if c1:
        P, V = np.array(p1[:-1]), np.array(v1[:-1])
        return P, V, True
    p2, v2, _ = runs[1]
    P = np.array(p2[::-1][:-1] + p1)
    V = np.array(v2[::-1][:-1] + v1)
    return P, V, False


def fixed_orientation(mech: Any, model: Any, v_ref: np.ndarray) -> FixedOrientation:
    """The chart of ``mech``'s translational mode through ``v_ref``; raises when the
    actuated motions there turn the platform."""
    from .velocity import jacobians

    jac = jacobians(mech, model.to_q(v_ref[:model.na], v_ref[model.na:]))
    Ja = np.asarray(jac.J_a, dtype=float)
    if Ja.shape[0] < 6 or np.abs(Ja[3:]).max() > 1e-8 * max(1.0, np.abs(Ja[:3]).max()):
        raise MechanismError(
            f"singular_surfaces: {mech.name}'s actuated motions turn its platform at the "
            "reference configuration: only platforms that translate (in an operation mode) "
            "have surfaces in (x, y, z)")
    return FixedOrientation(model, v_ref)


def section_curves(ch: FixedOrientation, z: float, v_start: np.ndarray, box: np.ndarray,
                   grid: int = 24, hmax: float = 0.05, tol: float = 1e-12,
                   max_steps: int = 4000) -> tuple[list[_Section], np.ndarray | None]:
    """The curves g = 0 of the section at height ``z`` within ``box`` ([[x_lo, x_hi],
    [y_lo, y_hi]]), the chart entered from the configuration ``v_start`` (moved to the
    section's centre in small steps). Returns the curves and a configuration at the
    section's centre (to start the next section from), or None there when the centre
    could not be reached."""
    L = ch.L
    c = box.mean(axis=1)
    p0 = v_start[ch.na:ch.na + 3]
    target = np.array([c[0], c[1], z])
    v = v_start
    k = max(1, int(math.ceil(np.linalg.norm(target - p0) / (0.05 * L))))
    for s in np.linspace(0, 1, k + 1)[1:]:
        v = ch.solve(p0 + s * (target - p0), v)
        if v is None:
            return [], None
    v_centre = v
    xs = np.linspace(box[0, 0], box[0, 1], grid)
    ys = np.linspace(box[1, 0], box[1, 1], grid)
    G = np.full((grid, grid), np.nan)
    Vg: dict[tuple[int, int], np.ndarray] = {}
    i0, j0 = int(np.argmin(np.abs(xs - c[0]))), int(np.argmin(np.abs(ys - c[1])))
    vv = ch.solve(np.array([xs[i0], ys[j0], z]), v_centre)
    if vv is None:
        return [], v_centre
    Vg[(i0, j0)] = vv
    G[i0, j0] = ch.g(vv)[0]
    queue = [(i0, j0)]
    while queue:  # breadth first from the centre: every node from a solved neighbour
        i, j = queue.pop(0)
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            a, b = i + di, j + dj
            if not (0 <= a < grid and 0 <= b < grid) or (a, b) in Vg or np.isfinite(G[a, b]):
                continue
            w = ch.solve(np.array([xs[a], ys[b], z]), Vg[(i, j)])
            if w is None:
                G[a, b] = np.inf  # outside the mode's chart: not crossed
                continue
            Vg[(a, b)] = w
            G[a, b] = ch.g(w)[0]
            queue.append((a, b))
    curves: list[_Section] = []
    traced: list[np.ndarray] = []
    hx = (box[0, 1] - box[0, 0]) / (grid - 1)

    def near(q):
        return any(np.min(np.linalg.norm(P - q, axis=1)) < 0.5 * hx for P in traced)

    for (i, j), w in list(Vg.items()):
        for a, b in ((i + 1, j), (i, j + 1)):
            if (a, b) not in Vg or np.sign(G[i, j]) == np.sign(G[a, b]):
                continue
            # the sign change on the edge: a secant iteration along it
            q0 = np.array([xs[i], ys[j]])
            q1 = np.array([xs[a], ys[b]])
            d = q1 - q0
            lo, hi, glo, ghi = 0.0, 1.0, G[i, j], G[a, b]
            vl = w
            found = None
            s_prev, side = -1.0, 0
            for _ in range(80):  # regula falsi, Illinois
                s = lo - glo * (hi - lo) / (ghi - glo)
                gs, vs = _field(ch, z, q0 + s * d, vl)
                if gs is None:
                    break
                if gs == 0 or (abs(gs) < tol and abs(s - s_prev) * float(np.linalg.norm(d))
                               < 1e-11 * ch.L):
                    found = (q0 + s * d, vs)
                    break
                s_prev = s
                if np.sign(gs) == np.sign(glo):
                    lo, glo, vl = s, gs, vs
                    if side == -1:
                        ghi *= 0.5
                    side = -1
                else:
                    hi, ghi = s, gs
                    if side == 1:
                        glo *= 0.5
                    side = 1
            if found is None or near(found[0]):
                continue
            out = _trace(ch, z, found[0], found[1], box, hmax, tol, max_steps)
            if out is None:
                continue
            P, V, closed = out
            traced.append(P)
            res = np.array([max(abs(gv), r) for gv, r in (ch.g(x) for x in V)])
            curves.append(_Section(np.c_[P, np.full(len(P), z)], V, closed, res))
    return curves, v_centre
