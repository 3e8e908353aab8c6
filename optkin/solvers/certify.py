"""Certified real solutions: Krawczyk's test in ball arithmetic.

A solver's answer x~ with a small residual is evidence, not proof, that a closed
configuration lies near it. :func:`certify` turns it into a proof, as HomotopyContinuation.jl's
``certify`` does (Breiding, Rose and Timme, "Certifying zeros of polynomial systems using
interval arithmetic", arXiv:2011.05000), for the square closure system Phi(q_a, x) = 0 of
any mechanism optkin describes:

* X is a box around x~ (half-width r_i in the unit of each unknown: radians, or lengths
  relative to the mechanism size), Y a floating-point inverse of W_p(x~);
* the Krawczyk operator K(X) = x~ - Y Phi(x~) + (I - Y W_p(X)) (X - x~) is enclosed in
  ball arithmetic (python-flint's ``arb``: every rounding is accounted for), with Phi(x~)
  and W_p(X) evaluated by running the model's own CasADi expression graph instruction by
  instruction on balls;
* if K(X) lies in the interior of X, then X contains exactly one solution of the system
  (Krawczyk 1969, Moore 1977), and it is real, since X is a real box. Boxes of distinct
  certified solutions that do not overlap prove the solutions distinct.

The geometry and the actuated values enter as exact numbers (the floats given). A test that
fails is data: ``certified=False`` with the reason (a singular or near-singular Jacobian at
the candidate, a box in which the Jacobian varies too much, an operation without a ball
form). Radii are tried from a few times the Newton correction upwards.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from ..errors import MechanismError
from ..results import ERROR, INACCURATE, OPTIMAL, SINGULAR, jsonable

__all__ = ["Certificate", "certify", "certify_point"]


@dataclass(frozen=True)
class Certificate:
    """The outcome of Krawczyk's test for one candidate solution.

    Attributes
    ----------
    certified : bool
        True when the box provably contains exactly one real solution.
    box : ndarray (n, 2)
        Lower and upper bounds of the box tried last (outward rounded), in the unknowns x.
    radius : float
        Half-width of that box in scaled units (radians; lengths / mechanism size).
    message : str
        Why not, when not certified; the contraction achieved otherwise.
    success, status :
        As every result (:mod:`optkin.results`): ``success`` is ``certified``; status
        ``"optimal"`` when certified, ``"singular"`` when W_p is (numerically) singular at
        the candidate, ``"error"`` when the test does not apply (a non-square or
        non-finite system, an operation without a ball form), else ``"inaccurate"`` (no
        box contracted, or the box overlaps another solution's: not proven).
    """

    certified: bool
    box: np.ndarray = field(repr=False)
    radius: float
    message: str
    status: str = ""

    def __post_init__(self) -> None:
        if not self.status:
            object.__setattr__(self, "status", OPTIMAL if self.certified else INACCURATE)

    @property
    def success(self) -> bool:
        """The same as :attr:`certified`."""
        return bool(self.certified)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({"certified": bool(self.certified), "success": self.success,
                         "status": self.status, "message": self.message,
                         "radius": float(self.radius), "box": self.box})


# ---------------------------------------------------------------------------------------
# a CasADi SX Function run on balls
# ---------------------------------------------------------------------------------------

class _Unsupported(Exception):
    pass


def _ball_ops() -> dict[int, Any]:
    import flint

    arb = flint.arb

    def sq(a):
        return a ** 2  # tighter than a * a on a ball around 0

    def if_else_zero(c, a):
        if c.is_zero():
            return arb(0)
        if not c.contains(0):
            return a
        return a.union(arb(0))

    def undecided(name):
        def f(*_):
            raise _Unsupported(f"the comparison {name} of balls")
        return f

    ops: dict[int, Any] = {
        ca.OP_ASSIGN: lambda a: a,
        ca.OP_ADD: lambda a, b: a + b,
        ca.OP_SUB: lambda a, b: a - b,
        ca.OP_MUL: lambda a, b: a * b,
        ca.OP_DIV: lambda a, b: a / b,
        ca.OP_NEG: lambda a: -a,
        ca.OP_SQ: sq,
        ca.OP_TWICE: lambda a: 2 * a,
        ca.OP_INV: lambda a: 1 / a,
        ca.OP_SQRT: lambda a: a.sqrt(),
        ca.OP_SIN: lambda a: a.sin(),
        ca.OP_COS: lambda a: a.cos(),
        ca.OP_TAN: lambda a: a.tan(),
        ca.OP_ASIN: lambda a: a.asin(),
        ca.OP_ACOS: lambda a: a.acos(),
        ca.OP_ATAN: lambda a: a.atan(),
        ca.OP_ATAN2: lambda a, b: arb.atan2(a, b),
        ca.OP_EXP: lambda a: a.exp(),
        ca.OP_LOG: lambda a: a.log(),
        ca.OP_POW: lambda a, b: a ** b,
        ca.OP_CONSTPOW: lambda a, b: a ** b,
        ca.OP_FABS: lambda a: abs(a),
        ca.OP_SINH: lambda a: a.sinh(),
        ca.OP_COSH: lambda a: a.cosh(),
        ca.OP_TANH: lambda a: a.tanh(),
        ca.OP_FMIN: lambda a, b: a.min(b),
        ca.OP_FMAX: lambda a, b: a.max(b),
        ca.OP_IF_ELSE_ZERO: if_else_zero,
    }
    for name in ("OP_LT", "OP_LE", "OP_EQ", "OP_NE", "OP_NOT", "OP_AND", "OP_OR",
                 "OP_SIGN", "OP_FLOOR", "OP_CEIL", "OP_FMOD"):
        if hasattr(ca, name):
            ops[getattr(ca, name)] = undecided(name[3:].lower())
    return ops


_OP_NAMES = {getattr(ca, k): k[3:].lower() for k in dir(ca) if k.startswith("OP_")}


class BallProgram:
    """A CasADi SX Function evaluated on python-flint ``arb`` balls.

    The instruction list is read once (``Function.instruction_id/input/output/constant``);
    a call runs it on balls: inputs are sequences of balls (or floats, taken exactly) in the
    order of the Function's inputs; outputs are dense lists of balls (column-major), with
    the structural zeros exact.
    """

    def __init__(self, f: ca.Function) -> None:
        if not f.is_a("SXFunction"):
            raise TypeError(f"BallProgram needs an SX Function, got {f.class_name()}")
        self.f = f
        self.n_w = int(f.sz_w())
        self.code = []
        for k in range(f.n_instructions()):
            op = int(f.instruction_id(k))
            self.code.append((op, list(f.instruction_input(k)), list(f.instruction_output(k)),
                              float(f.instruction_constant(k)) if op == ca.OP_CONST else 0.0))
        self.in_nz = [np.array(f.sparsity_in(i).find(), dtype=int) for i in range(f.n_in())]
        self.out_nz = [np.array(f.sparsity_out(i).find(), dtype=int) for i in range(f.n_out())]
        self.out_numel = [int(f.numel_out(i)) for i in range(f.n_out())]
        self.ops = _ball_ops()

    def __call__(self, *inputs: Any) -> list[list[Any]]:
        import flint

        arb = flint.arb
        zero = arb(0)
        ins = [[v if isinstance(v, arb) else arb(float(v)) for v in x] for x in inputs]
        outs = [[zero] * n for n in self.out_numel]
        w: list[Any] = [zero] * self.n_w
        ops = self.ops
        for op, i, o, c in self.code:
            if op == ca.OP_INPUT:
                w[o[0]] = ins[i[0]][int(self.in_nz[i[0]][i[1]])]
            elif op == ca.OP_OUTPUT:
                outs[o[0]][int(self.out_nz[o[0]][o[1]])] = w[i[0]]
            elif op == ca.OP_CONST:
                w[o[0]] = arb(c)
            else:
                fn = ops.get(op)
                if fn is None:
                    raise _Unsupported(f"the operation {_OP_NAMES.get(op, op)}")
                w[o[0]] = fn(*(w[j] for j in i))
        return outs


# ---------------------------------------------------------------------------------------
# Krawczyk's test
# ---------------------------------------------------------------------------------------

def _program(model) -> BallProgram:
    topo = model.topology

    def build() -> BallProgram:
        st = topo.st
        phi = topo.phi_sym
        Wp = ca.jacobian(phi, st.x)
        return BallProgram(ca.Function("certify_closure", [st.qa, st.x, st.p], [phi, Wp]))

    return topo.cached("certify:program", build)


def _fail(x: np.ndarray, r: np.ndarray, scale_r: float, why: str,
          status: str = INACCURATE) -> Certificate:
    box = np.c_[x - r, x + r] if np.all(np.isfinite(r)) else np.c_[x, x]
    return Certificate(False, box, float(scale_r), why, status)


def certify_point(model, qa: np.ndarray, x: np.ndarray, radii=(4.0, 64.0, 1024.0),
                  floor: float = 1e-13, ceiling: float = 1e-3) -> Certificate:
    """Krawczyk's test around the candidate ``x`` of ``model`` at the actuated values ``qa``.

    The box half-widths are ``t * max(|Y Phi(x)|, floor)`` per unknown (scaled), for each
    ``t`` in ``radii`` in turn (never above ``ceiling``, scaled); the first box that
    contracts certifies.
    """
    import flint

    arb = flint.arb
    qa = np.asarray(qa, dtype=float).ravel()
    x = np.asarray(x, dtype=float).ravel()
    n = x.size
    if model.topology.m != n:
        return _fail(x, np.full(n, np.nan), float("nan"),
                     f"the closure has {model.topology.m} equations for {n} unknowns: "
                     "Krawczyk's test needs a square system", ERROR)
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(qa))):
        return _fail(x, np.full(n, np.nan), float("nan"), "the candidate is not finite",
                     ERROR)
    prog = _program(model)
    p = np.asarray(model.p, dtype=float).ravel()
    scale = np.asarray(model.x_scale, dtype=float).ravel()
    # floating-point data: Y = W_p(x)^-1 and the Newton correction
    phi0, Wp0 = (np.array(v, dtype=float) for v in model.topology.jac(qa, x, p)[:2])
    phi0 = phi0.ravel()
    try:
        Y = np.linalg.inv(Wp0)
    except np.linalg.LinAlgError:
        return _fail(x, np.zeros(n), 0.0, "W_p is singular at the candidate", SINGULAR)
    if not np.all(np.isfinite(Y)) or np.linalg.cond(Wp0) > 1e14:
        return _fail(x, np.zeros(n), 0.0,
                     f"W_p is numerically singular at the candidate (cond "
                     f"{np.linalg.cond(Wp0):.2g})", SINGULAR)
    eta = np.abs(Y @ phi0) / scale
    base = max(float(np.max(eta)), floor)
    try:
        xb = [arb(float(v)) for v in x]
        phi_x, _ = prog(qa, xb, p)
        Ym = flint.arb_mat([[arb(float(v)) for v in row] for row in Y])
        YF = Ym * flint.arb_mat([[v] for v in phi_x])
        last = None
        for t in radii:
            rs = min(t * base, ceiling)
            r = rs * scale
            X = [arb(float(x[i]), float(r[i])) for i in range(n)]
            _, jx = prog(qa, X, p)
            J = flint.arb_mat(n, n)
            for k, v in enumerate(jx):  # column-major
                J[k % n, k // n] = v
            C = flint.arb_mat([[1 if i == j else 0 for j in range(n)] for i in range(n)]) - Ym * J
            D = flint.arb_mat([[arb(0, float(r[i]))] for i in range(n)])  # X - x~
            CD = C * D
            K = [xb[i] - YF[i, 0] + CD[i, 0] for i in range(n)]
            rad = np.array([float(X[i].rad()) for i in range(n)])
            box = np.c_[x - rad, x + rad]
            if all(X[i].contains_interior(K[i]) for i in range(n)):
                width = max(float(K[i].rad()) / r[i] for i in range(n))
                return Certificate(True, box, rs,
                                   f"K(X) inside X (widths <= {width:.2g} of X's), "
                                   f"half-width {rs:.2g} (scaled)")
            last = (box, rs)
            if rs >= ceiling:
                break
    except _Unsupported as e:
        return _fail(x, np.zeros(n), 0.0, f"{e} has no ball form in optkin", ERROR)
    box, rs = last
    return Certificate(False, box, rs,
                       f"K(X) is not inside X for half-widths up to {rs:.2g} (scaled): no "
                       "unique solution was proven near the candidate (it may be near a "
                       "singularity, or not close to a solution)")


def certify(mech, results) -> list[Certificate]:
    """Certify solutions of ``mech``: each :class:`~optkin.results.KinResult` of
    ``results`` (one result, a :class:`~optkin.results.SolutionSet` or a list) by
    Krawczyk's test around its ``x`` at its ``qa``. Returns one :class:`Certificate` per
    result, in order; two certified results whose boxes overlap are both marked
    uncertified (not proven distinct)."""
    from ..model import get_model
    from ..results import KinResult
    from .common import check_mechanism

    check_mechanism(mech, "certify")
    items = [results] if isinstance(results, KinResult) else list(results)
    for k, r in enumerate(items):
        if not isinstance(r, KinResult):
            raise MechanismError(f"certify: item {k} is a {type(r).__name__}, expected a "
                                 "KinResult (from forward, assembly_modes, ...)")
    model = get_model(mech)
    certs = [certify_point(model, r.qa, r.x) for r in items]
    return mark_overlaps(certs)


def stamp(model, qa: np.ndarray, results) -> int:
    """Certify each result of one solve at ``qa`` (overlaps withdrawn), set its
    ``certified`` flag and ``stats.extra["certificate"]``; the number certified."""
    certs = mark_overlaps([certify_point(model, qa, kr.x) for kr in results])
    for kr, c in zip(results, certs):
        kr.certified = c.certified
        kr.stats.extra["certificate"] = c.message
    return sum(c.certified for c in certs)


def mark_overlaps(certs: list[Certificate]) -> list[Certificate]:
    """The certificates with those whose boxes overlap another certified box withdrawn."""
    ok = [k for k, c in enumerate(certs) if c.certified]
    bad = set()
    for a in range(len(ok)):
        for b in range(a):
            A, B = certs[ok[a]].box, certs[ok[b]].box
            if np.all((A[:, 0] <= B[:, 1]) & (B[:, 0] <= A[:, 1])):
                bad.update((ok[a], ok[b]))
    out = list(certs)
    for k in bad:
        c = certs[k]
        out[k] = Certificate(False, c.box, c.radius,
                             "its box overlaps another solution's: not proven distinct")
    return out
