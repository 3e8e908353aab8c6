"""Per-topology compiled evaluation of a fully parallel mechanism at task points.

One CasADi Function per topology, built once from the model's symbols (the geometry p an
input, so a new design compiles nothing): for task coordinates t (the platform's
coordinates) and a working mode sigma (the signs of diag(B)), each leg's actuated value
from its closed-form inverse on the branch whose B_jj has the sign sigma_j, whether every
leg reaches, det A, and the conditioning of the forward kinematic Jacobian
J = -A^-1 B (t' = J q_a' [Chablat & Wenger 1998, A t' + B q_a' = 0]).

The conditioning is 1/kappa of the inverse Jacobian J^-1 = -B^-1 A (kappa(J) =
kappa(J^-1)) in the 2-norm, with the task's angular coordinates multiplied by a
characteristic length (an input) so that mixed units compare: 1/kappa = sigma_min /
sigma_max, written in closed form for 2 and 3 task coordinates (2 x 2: kappa + 1/kappa =
|M|_F^2 / |det M|; 3 x 3: the eigenvalues of M^T M by the trigonometric formula), so the
whole evaluation is one SX graph, mapped over points and designs together.
"""

from __future__ import annotations

import threading
from typing import Any

import casadi as ca
import numpy as np

from ..errors import MechanismError
from ..model import compiled as cc
from ..model import get_model

__all__ = ["Evaluator", "evaluator"]

#: points per mapped call (memory stays bounded; maps cached per power of two)
CHUNK = 4096


def _margin(ok: ca.SX) -> ca.SX:
    """A continuous margin of a leg's reach test ``a <= b`` (or ``a < b``): b - a, positive
    where the leg reaches (a sign only when the test is not a comparison)."""
    if ok.is_op(ca.OP_LE) or ok.is_op(ca.OP_LT):
        return ok.dep(1) - ok.dep(0)
    return ca.if_else(ok, 1.0, -1.0)


def _inv_kappa_2(M: ca.SX) -> ca.SX:
    T = ca.sumsqr(M)
    D = ca.fabs(ca.det(M))
    return 2 * D / (T + ca.sqrt(ca.fmax(T * T - 4 * D * D, 0)))


def _inv_kappa_3(M: ca.SX) -> ca.SX:
    # eigenvalues of the symmetric S = M^T M (Smith's trigonometric formula)
    S = ca.mtimes(M.T, M)
    q = ca.trace(S) / 3
    p1 = S[0, 1] ** 2 + S[0, 2] ** 2 + S[1, 2] ** 2
    p2 = (S[0, 0] - q) ** 2 + (S[1, 1] - q) ** 2 + (S[2, 2] - q) ** 2 + 2 * p1
    # (tiny offsets keep the derivatives finite at isotropy and at repeated eigenvalues)
    pp = ca.sqrt(p2 / 6 + 1e-300)
    Bm = (S - q * ca.SX.eye(3)) / pp
    r = ca.fmin(ca.fmax(ca.det(Bm) / 2, -1 + 1e-15), 1 - 1e-15)
    phi = ca.acos(r) / 3
    e1 = q + 2 * pp * ca.cos(phi)
    e3 = q + 2 * pp * ca.cos(phi + 2 * np.pi / 3)
    return ca.sqrt(ca.fmax(e3, 0) / ca.fmax(e1, 1e-300))


class Evaluator:
    """The compiled point evaluation of one topology (see the module docstring).

    ``evaluate(T, sigma, p0, M, D, length)`` with T (N, nt) task points and the geometry
    p0 + M d (d a row of D: a design per point; M None and D whole geometry vectors: p0 +
    d; see :mod:`optkin.design.family`) returns a dict of arrays: ``qa`` (N, na), ``valid`` (N,) (every leg
    reaches on the branch of its working-mode sign), ``det`` (N,) det A, ``inv_kappa``
    (N,), ``sv`` (N, nt) the singular values of J (largest first; velocity
    amplification), NaN where invalid; ``reach`` (N, na) each leg's continuous reach
    margin (positive where it reaches) and ``raw_det`` det A wherever it evaluates.
    """

    def __init__(self, model: Any) -> None:
        from ..model.inverse import ClosedPart

        plat = model.platform
        if plat is None or not model.fully_parallel or model.nx != model.n_platform \
                or model.m != model.nx:
            raise MechanismError(
                f"{model.mech.name}: design measures are computed for fully parallel "
                "mechanisms whose unknowns are the platform's coordinates (five-bar, "
                "3-RRR, 3-RPR, 3-PRR, Delta, ...); this one is not")
        parts = model.inverse_parts()
        if not all(isinstance(pt, ClosedPart) for pt in parts):
            raise MechanismError(f"{model.mech.name}: every leg needs a closed-form inverse")
        self.na, self.nt = model.na, model.nx
        self.angle = np.array(model.x_angle, dtype=bool)
        self.task_names = tuple(model.x_names)
        self.key = model.topology.key
        st = model.structure
        qa, x, p = st.qa, st.x, st.p
        phi = model.topology.phi_sym
        t = ca.SX.sym("t", self.nt)
        sig = ca.SX.sym("sigma", self.na)
        L = ca.SX.sym("length")
        Bsym = ca.jacobian(phi, qa)
        qsel, valid, margin = [], [], []
        for part in parts:
            QA, _, V = part.fn(t, p)
            j = part.qa[0]
            margin.append(_margin(V[0]))
            if part.branches == 1:
                qsel.append(QA[0])
                valid.append(V[0])
                continue
            # the branch whose B_jj has the sign sigma_j
            bjj = ca.substitute(Bsym[j, j], ca.vertcat(qa[j], x), ca.vertcat(QA[0], t))
            first = bjj * sig[j] > 0
            qsel.append(ca.if_else(first, QA[0], QA[1]))
            valid.append(ca.if_else(first, V[0], V[1]))
        qv = ca.vertcat(*qsel)
        ok = valid[0]
        for v in valid[1:]:
            ok = ca.logic_and(ok, v)
        sub_from, sub_to = ca.vertcat(qa, x), ca.vertcat(qv, t)
        A = ca.substitute(ca.jacobian(phi, x), sub_from, sub_to)
        B = ca.substitute(Bsym, sub_from, sub_to)
        scale = ca.vertcat(*[1 / L if a else 1 for a in self.angle])
        Jinv = ca.mtimes(ca.solve(B, A), ca.diag(scale))   # = -J^-1, columns homogenised
        if self.nt == 2:
            ik = _inv_kappa_2(Jinv)
        elif self.nt == 3:
            ik = _inv_kappa_3(Jinv)
        else:
            raise MechanismError(f"{model.mech.name}: conditioning is written for 2 or 3 task "
                                 "coordinates")
        self._point = ca.Function(f"design_point_{self.nt}", [t, p, sig, L],
                                  [qv, ok, ca.det(A), ik, ca.vec(Jinv), ca.vertcat(*margin)],
                                  ["t", "p", "sigma", "length"],
                                  ["qa", "valid", "det", "inv_kappa", "Jinv", "reach"])
        self.np = int(p.shape[0])
        self._run = Mapped(self._point, f"design:{self.key}", self.np)

    def evaluate(self, T: np.ndarray, sigma: Any, p0: np.ndarray, M: np.ndarray | None = None,
                 D: np.ndarray | None = None, length: float = 1.0, jacobian: bool = False,
                 buffers: dict | None = None) -> dict[str, np.ndarray]:
        """Evaluate at the task points T (N, nt) with the geometry p0 + M d, d the rows of
        D (N, k) (one design per point; None: p0 everywhere)."""
        nt, na = self.nt, self.na
        qa, valid, det, ik, jinv, reach = self._run(
            T, p0, M, D, [np.asarray(sigma, dtype=float).reshape(-1), float(length)], buffers)
        N = len(qa)
        det, ik = det[:, 0], ik[:, 0]
        with np.errstate(invalid="ignore"):
            ok = (valid[:, 0] > 0.5) & np.isfinite(det) & np.all(np.isfinite(qa), axis=1)
        out = {"qa": qa, "valid": ok, "det": np.where(ok, det, np.nan),
               "inv_kappa": np.where(ok, ik, np.nan), "raw_det": det, "reach": reach}
        if jacobian:
            Ji = jinv.reshape(N, nt, na).transpose(0, 2, 1)   # (N, na, nt)
            with np.errstate(all="ignore"):
                sv = np.linalg.svd(np.where(ok[:, None, None], Ji, 1.0), compute_uv=False)
                sv = 1.0 / sv[:, ::-1]   # singular values of J = inverses of J^-1's
            out["sv"] = np.where(ok[:, None], sv, np.nan)
        return out


class Mapped:
    """A point Function ``f(t, p, *shared)`` evaluated at many points, each with its own
    design: the geometry p = p0 + M d (d: k design variables per point) or p = p0 + d
    (whole geometry vectors per point), mapped over the points with p0, M and the shared
    inputs unmapped, compiled once per topology and k (when a compiler is present), and
    called through preallocated buffers (one set per thread)."""

    def __init__(self, point: ca.Function, tag: str, n_p: int) -> None:
        self.point, self.tag, self.np = point, tag, n_p
        self.nt = point.size1_in(0)
        self.n_shared = point.n_in() - 2
        self.sizes = [point.nnz_out(i) for i in range(point.n_out())]
        self._fns: dict[int, ca.Function] = {}
        self._maps: dict[tuple[int, int], ca.Function] = {}
        self._tls = threading.local()
        self._lock = threading.Lock()

    def _fn(self, k: int) -> ca.Function:
        f = self._fns.get(k)
        if f is None:
            t = ca.SX.sym("t", self.nt)
            d = ca.SX.sym("d", self.np if k < 0 else k)
            p0 = ca.SX.sym("p0", self.np)
            M = ca.SX.sym("M", self.np, 1 if k < 0 else k)
            shared = [ca.SX.sym(f"s{i}", self.point.sparsity_in(2 + i))
                      for i in range(self.n_shared)]
            p = p0 + d if k < 0 else p0 + ca.mtimes(M, d)
            out = self.point(t, p, *shared)
            out = out if isinstance(out, (list, tuple)) else [out]
            name = f"{self.point.name()}_{'p' if k < 0 else k}"
            f = ca.Function(name, [t, d, p0, M, *shared], list(out))
            lib = cc.library(f"{self.tag}:{name}", [f]) if cc.find_compiler() else None
            if lib is not None:
                f = lib[f.name()]
            self._fns[k] = f
        return f

    def _mapped(self, k: int, n: int) -> ca.Function:
        with self._lock:
            f = self._maps.get((k, n))
            if f is None:
                f = self._maps[(k, n)] = self._fn(k).map(
                    f"map_{self.point.name()}_{k % 1000}_{n}", "serial", n,
                    list(range(2, 4 + self.n_shared)), [])
        return f

    def __call__(self, T: np.ndarray, p0: np.ndarray, M: np.ndarray | None,
                 D: np.ndarray | None, shared: list, buffers: dict | None = None
                 ) -> list[np.ndarray]:
        """The outputs (N, size) at the points T (N, nt)."""
        T = np.atleast_2d(np.asarray(T, dtype=float))
        N = T.shape[0]
        if D is None:
            M, D = None, np.zeros((N, 1))
        D = np.asarray(D, dtype=float).reshape(N, -1)
        k = D.shape[1]
        if M is None and k == self.np:     # whole geometry vectors: p = p0 + d
            k = -1
        Mf = np.zeros((self.np, 1)) if M is None else np.asarray(M, dtype=float)
        if buffers is None:
            buffers = getattr(self._tls, "buffers", None)
            if buffers is None:
                buffers = self._tls.buffers = {}
        n = 1
        while n < min(N, CHUNK):
            n *= 2
        fast = buffers.get((k, n))
        if fast is None:
            fast = buffers[(k, n)] = cc.FastFn(self._mapped(k, n))
        fast._args[2][:] = np.ravel(p0)          # the shared inputs: a few hundred numbers
        fast._args[3][:] = np.ravel(Mf, order="F")
        for i, v in enumerate(shared):
            fast._args[4 + i][:] = np.ravel(np.asarray(v, dtype=float), order="F")
        nt, nd = self.nt, D.shape[1]
        outs = [np.empty((N, z)) for z in self.sizes]
        for s in range(0, N, n):
            m_ = min(n, N - s)
            tb = fast._args[0].reshape(n, nt)
            db = fast._args[1].reshape(n, nd)
            tb[:m_] = T[s:s + m_]
            db[:m_] = D[s:s + m_]
            if m_ < n:
                tb[m_:] = T[s + m_ - 1]
                db[m_:] = D[s + m_ - 1]
            fast._trig()
            for o, r, z in zip(outs, fast._res, self.sizes):
                o[s:s + m_] = r.reshape(n, z)[:m_]
        return outs


def evaluator(mech: Any) -> Evaluator:
    """The evaluator of ``mech``'s topology (built once per topology)."""
    model = get_model(mech)
    return model.cached("design_evaluator", lambda: Evaluator(model))
