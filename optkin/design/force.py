"""Force capability and leg lengths of platforms whose legs are length-actuated distance
legs (Stewart-Gough UPS/SPS, 3-RPR, ...), as functions of geometry.

With leg forces f along the unit leg directions u_i, the wrench on the platform (about its
origin) is w = G f with columns g_i = (u_i, r_i x u_i), r_i the platform point relative to
the platform origin (planar: (u_i, (r_i x u_i)_z)). The **force capability** at a pose is
the largest force the platform can exert in every direction at zero moment with
|f_i| <= f_max: with H the force columns of G^-1 (f = H F), the constraint |H_i . F| <=
f_max for F = t d holds for every unit d exactly when t <= f_max / max_i |H_i|, so the
capability is f_max / max_i |H_i|_2 (0 at a singular G). No characteristic length enters
(the moment rows do not act on force-only wrenches).

One CasADi Function per topology evaluates the leg lengths and G at task coordinates (a
spatial platform's roll, pitch, yaw with R = Rz(yaw) Ry(pitch) Rx(roll)), mapped over
poses and designs like the conditioning (:class:`optkin.design._evaluator.Mapped`).
"""

from __future__ import annotations

import itertools
from typing import Any

import casadi as ca
import numpy as np

from .._checks import as_float, as_int, as_vector, show
from ..errors import MechanismError
from ._evaluator import Mapped
from .problem import Measure

__all__ = ["ForceEvaluator", "ForceCapability", "LegStroke", "box_nodes"]


def _quat_rpy(r: Any, p: Any, y: Any) -> Any:
    cr, sr = ca.cos(r / 2), ca.sin(r / 2)
    cp, sp = ca.cos(p / 2), ca.sin(p / 2)
    cy, sy = ca.cos(y / 2), ca.sin(y / 2)
    return ca.vertcat(cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                      cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy)


class ForceEvaluator:
    """Leg lengths (N, n) and G (N, nw, n) at task coordinates (see the module docstring)."""

    def __init__(self, model: Any) -> None:
        plat = model.platform
        form = model.distance_form()
        if plat is None or form is None or not np.all(form.length_actuated):
            raise MechanismError(
                f"{model.mech.name}: force capability is written for platforms whose legs "
                "are all length-actuated distance legs (UPS, SPS, RPR, ...)")
        if plat.name not in ("spatial", "planar"):
            raise MechanismError(f"{model.mech.name}: force capability needs a platform that "
                                 f"turns (spatial or planar), not {plat.name!r}")
        st = model.structure
        self.spatial = plat.name == "spatial"
        self.nt = 6 if self.spatial else 3
        self.nw = self.nt
        self.nf = 3 if self.spatial else 2
        self.n = len(st.distance)
        t = ca.SX.sym("t", self.nt)
        x = ca.vertcat(t[:3], _quat_rpy(t[3], t[4], t[5])) if self.spatial else t
        pos = ca.vertcat(x[0], x[1], x[2] if self.spatial else 0)
        L, cols = [], []
        for C, P, _ in st.distance:
            P = ca.substitute(P, st.x, x)
            v = P - C
            ln = ca.norm_2(v)
            u = v / ln
            r = P - pos
            m = ca.cross(r, u)
            L.append(ln)
            cols.append(ca.vertcat(u, m) if self.spatial else ca.vertcat(u[0], u[1], m[2]))
        G = ca.horzcat(*cols)
        f = ca.Function("force_point", [t, st.p], [ca.vertcat(*L), ca.vec(G)])
        self._run = Mapped(f, f"force:{model.topology.key}", int(st.p.shape[0]))
        self.task_names = ("x", "y", "z", "roll", "pitch", "yaw") if self.spatial else \
            ("x", "y", "phi")

    def evaluate(self, T: np.ndarray, p0: np.ndarray, M: Any = None, D: Any = None
                 ) -> tuple[np.ndarray, np.ndarray]:
        lengths, g = self._run(T, p0, M, D, [])
        G = g.reshape(-1, self.n, self.nw).transpose(0, 2, 1)   # column-major vec
        return lengths, G

    def capability(self, G: np.ndarray, fmax: float = 1.0) -> np.ndarray:
        """f_max / max_i |H_i| per pose (0 where G is singular)."""
        out = np.zeros(len(G))
        with np.errstate(all="ignore"):
            cond = np.linalg.cond(G)
        ok = np.isfinite(cond) & (cond < 1e12)
        if ok.any():
            H = np.linalg.inv(G[ok])[:, :, :self.nf]
            out[ok] = fmax / np.linalg.norm(H, axis=2).max(axis=1)
        return out


def _force_evaluator(family: Any) -> ForceEvaluator:
    return family.model0.cached("design_force", lambda: ForceEvaluator(family.model0))


def box_nodes(lo: np.ndarray, hi: np.ndarray, n: int) -> np.ndarray:
    """The n^d tensor grid of a box (corners included)."""
    axes = [np.linspace(a, b, n) if b > a else np.array([a]) for a, b in zip(lo, hi)]
    return np.array(list(itertools.product(*axes)))


class _PoseBox(Measure):
    def __init__(self, lo: Any, hi: Any, n: int) -> None:
        self.lo = as_vector(lo, f"{type(self).__name__}.lo")
        self.hi = as_vector(hi, f"{type(self).__name__}.hi", len(self.lo))
        if np.any(self.hi < self.lo):
            raise MechanismError(f"{type(self).__name__}: lo <= hi required, got "
                                 f"{show(self.lo)} and {show(self.hi)}")
        self.n = as_int(n, "n", lo=2, hi=50)

    def _eval(self, family: Any, Z: np.ndarray, dense: int = 1
              ) -> tuple[ForceEvaluator, np.ndarray, np.ndarray]:
        fe = _force_evaluator(family)
        if len(self.lo) != fe.nt:
            raise MechanismError(f"{type(self).__name__}: the box has {len(self.lo)} "
                                 f"coordinates; this platform's poses have {fe.nt} "
                                 f"({', '.join(fe.task_names)})")
        T = box_nodes(self.lo, self.hi, (self.n - 1) * dense + 1)
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        p0, M, D = family.geometry(Z)
        nT = len(T)
        lengths, G = fe.evaluate(np.tile(T, (len(Z), 1)), p0, M, np.repeat(D, nT, axis=0))
        return fe, lengths.reshape(len(Z), nT, -1), G.reshape(len(Z), nT, fe.nw, fe.n)


class ForceCapability(_PoseBox):
    """The least force capability (see the module docstring) over the n^d grid of a box of
    poses [lo, hi] (task coordinates; corners included), with leg force limit ``fmax``."""

    name = "force capability"

    def __init__(self, lo: Any, hi: Any, fmax: float = 1.0, n: int = 3) -> None:
        super().__init__(lo, hi, n)
        self.fmax = as_float(fmax, "fmax", lo=0.0)

    def values(self, family: Any, Z: np.ndarray, dense: int = 1) -> np.ndarray:
        fe, _, G = self._eval(family, Z, dense)
        cap = fe.capability(G.reshape(-1, fe.nw, fe.n), self.fmax)
        return cap.reshape(G.shape[0], G.shape[1]).min(axis=1)


class LegStroke(_PoseBox):
    """The largest range max - min of a leg's length over the n^d grid of a box of poses
    (the stroke the actuators need); ``which="max"`` or ``"min"``: the longest or the
    shortest leg length instead."""

    name = "leg stroke"

    def __init__(self, lo: Any, hi: Any, n: int = 3, which: str = "stroke") -> None:
        super().__init__(lo, hi, n)
        if which not in ("stroke", "max", "min"):
            raise MechanismError(f"which: expected 'stroke', 'max' or 'min', got {show(which)}")
        self.which = which
        self.name = {"stroke": "leg stroke", "max": "longest leg", "min": "shortest leg"}[which]

    def values(self, family: Any, Z: np.ndarray, dense: int = 1) -> np.ndarray:
        _, L, _ = self._eval(family, Z, dense)
        if self.which == "max":
            return L.max(axis=(1, 2))
        if self.which == "min":
            return L.min(axis=(1, 2))
        return (L.max(axis=1) - L.min(axis=1)).max(axis=1)
