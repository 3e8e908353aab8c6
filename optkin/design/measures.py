"""Performance measures of a design, as functions of its geometry.

Every measure is evaluated by the topology's compiled point evaluation
(:mod:`optkin.design._evaluator`: the closed-form inverse in one working mode, det A and
the conditioning of J = -A^-1 B at once), so a new design compiles nothing. The working
mode ``mode`` is the tuple of signs of diag(B) (:meth:`optkin.get_model(m).working_modes`),
as for :func:`optkin.aspects`.

Formulas (t the task coordinates, J the forward Jacobian t' = J q_a'):

- **local conditioning** 1/kappa = sigma_min(J) / sigma_max(J) in the 2-norm, in [0, 1]
  (1: isotropic); the angular task coordinates of a planar platform are multiplied by a
  characteristic ``length`` first, so that mixed units compare.
- **global conditioning index** (Gosselin and Angeles 1991): the area-weighted mean
  GCI = int_R 1/kappa dA / int_R dA over a region R of the task plane, by Gauss quadrature
  (Liu, Wang and Pritschow print the unweighted mean over a polar grid instead; optkin
  computes the weighted integral, their Eq. 4). Points of R the mechanism cannot reach in
  the working mode count with 1/kappa = 0.
- **velocity and force extremes**: the singular values of J (largest and smallest
  end-effector speed per unit actuator speed; forces are their reciprocals).
- **area** of a region's reachable part, or of an aspect (:class:`Aspect`: the connected
  set containing a seed point where every leg reaches in the working mode, det A keeps
  its sign, the actuators stay within their limits and 1/kappa >= ``gamma``), by
  scanline Gauss quadrature whose interval ends are found exactly (bisection on the
  closed-form tests, to 1e-12 of the size).
- **largest inscribed disc or square** (:func:`largest_inscribed`) in such an aspect,
  centred at a given point, on a given line, or anywhere: its size is the least first
  exit distance over rays from the centre to the shape's boundary, each exit found by
  marching and bisection and the least refined by Brent's method over the ray direction.

Regions are in the plane of the translation coordinates; a planar platform with an
orientation takes it from ``fixed`` (``{"phi": 0.0}``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import minimize_scalar

from .._checks import as_float, as_int, as_vector, check_mechanism, show
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model
from ..results import jsonable
from ._evaluator import Evaluator, evaluator

__all__ = ["Disc", "Box", "Aspect", "Integral", "Inscribed", "conditioning",
           "singular_values", "gci", "area", "largest_inscribed"]

# reason codes of an infeasible point
REACH, PARALLEL, LIMIT, CONDITIONING, BOUNDS = 1, 2, 3, 4, 5
_REASON = {0: "none", REACH: "serial", PARALLEL: "parallel", LIMIT: "limit",
           CONDITIONING: "conditioning", BOUNDS: "bounds"}


# --------------------------------------------------------------------------- regions
@dataclass(frozen=True)
class Disc:
    """The disc of the task plane about ``centre``: the points P with distance to it <= radius."""

    centre: tuple[float, float]
    radius: float

    def __post_init__(self) -> None:
        c = as_vector(self.centre, "Disc.centre", 2)
        object.__setattr__(self, "centre", (float(c[0]), float(c[1])))
        object.__setattr__(self, "radius", as_float(self.radius, "Disc.radius", lo=0.0))
        if self.radius <= 0:
            raise MechanismError("Disc.radius: expected a positive radius")

    def nodes(self, order: int = 16) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Legendre in the radius (weight r) x the trapezoidal rule in the angle
        (exact for trigonometric polynomials): points (N, 2) and weights summing to the
        area."""
        xg, wg = np.polynomial.legendre.leggauss(order)
        r = 0.5 * self.radius * (xg + 1)
        wr = 0.5 * self.radius * wg * r
        nth = 4 * order
        th = 2 * np.pi * np.arange(nth) / nth
        R, TH = np.meshgrid(r, th, indexing="ij")
        W = np.repeat(wr[:, None], nth, axis=1) * (2 * np.pi / nth)
        P = np.stack([self.centre[0] + R * np.cos(TH), self.centre[1] + R * np.sin(TH)], -1)
        return P.reshape(-1, 2), W.reshape(-1)

    @property
    def area(self) -> float:
        return float(np.pi * self.radius ** 2)

    def boundary(self, n: int = 256) -> np.ndarray:
        th = 2 * np.pi * np.arange(n) / n
        return np.stack([self.centre[0] + self.radius * np.cos(th),
                         self.centre[1] + self.radius * np.sin(th)], -1)


@dataclass(frozen=True)
class Box:
    """The rectangle lo <= P <= hi of the task plane."""

    lo: tuple[float, float]
    hi: tuple[float, float]

    def __post_init__(self) -> None:
        lo = as_vector(self.lo, "Box.lo", 2)
        hi = as_vector(self.hi, "Box.hi", 2)
        if not np.all(lo < hi):
            raise MechanismError(f"Box: lo < hi required in each coordinate, got {show(lo)} "
                                 f"and {show(hi)}")
        object.__setattr__(self, "lo", (float(lo[0]), float(lo[1])))
        object.__setattr__(self, "hi", (float(hi[0]), float(hi[1])))

    def nodes(self, order: int = 16) -> tuple[np.ndarray, np.ndarray]:
        """Tensor Gauss-Legendre points (N, 2) and weights summing to the area."""
        xg, wg = np.polynomial.legendre.leggauss(order)
        lo, hi = np.array(self.lo), np.array(self.hi)
        h = 0.5 * (hi - lo)
        x = lo[0] + h[0] * (xg + 1)
        y = lo[1] + h[1] * (xg + 1)
        X, Y = np.meshgrid(x, y, indexing="ij")
        W = np.outer(wg * h[0], wg * h[1])
        return np.stack([X, Y], -1).reshape(-1, 2), W.reshape(-1)

    @property
    def area(self) -> float:
        return float(np.prod(np.subtract(self.hi, self.lo)))

    def boundary(self, n: int = 256) -> np.ndarray:
        (a, b), (c, d) = self.lo, self.hi
        return np.array([[a, b], [c, b], [c, d], [a, d]])


@dataclass(frozen=True)
class Aspect:
    """The connected part of the task plane containing ``seed`` where every leg reaches in
    the working mode, det A keeps the sign it has at ``seed``, the actuators stay within
    their limits and 1/kappa >= gamma (see the module docstring); ``bounds`` [[xlo, xhi],
    [ylo, yhi]] limits the search (default: the legs' reach)."""

    seed: tuple[float, float]
    bounds: Any = None

    def __post_init__(self) -> None:
        s = as_vector(self.seed, "Aspect.seed", 2)
        object.__setattr__(self, "seed", (float(s[0]), float(s[1])))


Region = Disc | Box | Aspect


def _box_arg(bounds: Any) -> np.ndarray:
    try:
        b = np.asarray(bounds, dtype=float)
    except (TypeError, ValueError):
        b = np.zeros(0)
    if b.shape != (2, 2) or not np.all(np.isfinite(b)) or not np.all(b[:, 0] < b[:, 1]):
        raise MechanismError(f"bounds: expected [[xlo, xhi], [ylo, yhi]] with lo < hi, got "
                             f"{show(bounds)}")
    return b


# --------------------------------------------------------------------------- a bound design
@dataclass
class Probe:
    """One design in one working mode: the evaluator with the geometry filled in, the
    plane's embedding into the task coordinates, limits and the conditioning floor."""

    ev: Evaluator
    p0: np.ndarray
    M: np.ndarray | None
    d: np.ndarray | None
    sigma: tuple[int, ...]
    length: float
    plane: tuple[int, int]
    template: np.ndarray
    limits: dict[int, tuple[float, float]]
    gamma: float
    scale: float
    reach: np.ndarray  # [[xlo, xhi], [ylo, yhi]]
    evals: list[int] = field(default_factory=lambda: [0])

    def task(self, P: np.ndarray) -> np.ndarray:
        P = np.atleast_2d(P)
        T = np.repeat(self.template[None], len(P), axis=0)
        T[:, self.plane[0]] = P[:, 0]
        T[:, self.plane[1]] = P[:, 1]
        return T

    def eval(self, P: np.ndarray, jacobian: bool = False) -> dict[str, np.ndarray]:
        P = np.atleast_2d(np.asarray(P, dtype=float))
        self.evals[0] += len(P)
        D = None if self.d is None else np.repeat(self.d[None], len(P), axis=0)
        if self._dm is None:
            self._dm = {}
        return self.ev.evaluate(self.task(P), self.sigma, self.p0, self.M, D,
                                self.length, jacobian, self._dm)

    def margin(self, P: np.ndarray, s0: float | None = None
               ) -> tuple[np.ndarray, np.ndarray, dict]:
        """A continuous margin F per point, positive exactly where the point is feasible
        (the least of: each leg's reach margin, s0 det A, the actuator limits' margins,
        1/kappa - gamma, the clip box's margins), the reason code of the least one where
        F <= 0 (0 where feasible), and the evaluation."""
        P = np.atleast_2d(P)
        o = self.eval(P)
        with np.errstate(invalid="ignore"):
            parts = [o["reach"].min(axis=1)]
            kinds = [REACH]
            if s0 is not None:
                parts.append(np.asarray(s0) * o["raw_det"])
                kinds.append(PARALLEL)
            if self.limits:
                qa = o["qa"]
                lm = np.full(len(P), np.inf)
                for j, (lo, hi) in self.limits.items():
                    q = qa[:, j]
                    if self.ev_angle_qa[j]:
                        best = np.full(len(q), -np.inf)
                        for k in (-1, 0, 1):
                            qq = q + 2 * np.pi * k
                            best = np.maximum(best, np.minimum(qq - lo, hi - qq))
                    else:
                        best = np.minimum(q - lo, hi - q)
                    lm = np.minimum(lm, best)
                parts.append(lm)
                kinds.append(LIMIT)
            if self.gamma > 0:
                parts.append(o["inv_kappa"] - self.gamma)
                kinds.append(CONDITIONING)
            if self.clip is not None:
                b = self.clip
                parts.append(np.minimum.reduce([P[:, 0] - b[0, 0], b[0, 1] - P[:, 0],
                                                P[:, 1] - b[1, 0], b[1, 1] - P[:, 1]])
                             / self.scale)
                kinds.append(BOUNDS)
            G = np.vstack(parts)
            G = np.where(np.isnan(G), -1.0, G)
            k = G.argmin(axis=0)
            F = G[k, np.arange(len(P))]
            # a leg whose closed form fails though its margin is positive: infeasible
            F = np.where(~o["valid"] & (F > 0), -1e-300, F)
            code = np.where(F > 0, 0, np.asarray(kinds)[k])
            code = np.where((F <= 0) & ~o["valid"], REACH, code)
        return F, code, o

    def reasons(self, P: np.ndarray, s0: float | None = None) -> tuple[np.ndarray, dict]:
        """Reason code per point (0: feasible) and the evaluation."""
        _, code, o = self.margin(P, s0)
        return code, o

    ev_angle_qa: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    clip: np.ndarray | None = None
    _dm: Any = None


def _mode_arg(model: Any, mode: Any) -> tuple[int, ...]:
    modes = model.working_modes()
    if mode is None:
        if len(modes) == 1:
            return modes[0]
        raise MechanismError(f"{model.mech.name}: give the working mode, one of {modes} "
                             "(signs of diag B, as in optkin.aspects)")
    try:
        m = tuple(int(v) for v in mode)
    except (TypeError, ValueError):
        m = None
    if m not in modes:
        raise MechanismError(f"mode: {show(mode)} is not a working mode of {model.mech.name}; "
                             f"known: {modes}")
    return m


def _probe(mech: Mechanism, mode: Any = None, fixed: Mapping[str, float] | None = None,
           limits: Mapping[str, Any] | None = None, gamma: float = 0.0,
           length: float = 1.0, family: Any = None, z: Any = None) -> Probe:
    """A :class:`Probe` of ``mech`` (or of the design z of ``family``: the family's affine
    geometry, no mechanism built when it is affine)."""
    if family is not None:
        model = family.model0
    else:
        check_mechanism(mech)
        model = get_model(mech)
    ev = evaluator(model.mech) if family is None else family.model0.cached(
        "design_evaluator", lambda: Evaluator(family.model0))
    sigma = _mode_arg(model, mode)
    names = list(model.x_names)
    ang = [i for i in range(len(names)) if model.x_angle[i]]
    trans = [i for i in range(len(names)) if not model.x_angle[i]]
    if len(trans) != 2:
        raise MechanismError(f"{model.mech.name}: regions are planar; this platform "
                             f"translates in {len(trans)} coordinates")
    fixed = dict(fixed or {})
    want = {names[i] for i in ang}
    if set(fixed) != want:
        need = ", ".join(f"{n!r}: value" for n in sorted(want)) or "nothing"
        raise MechanismError(f"fixed: {model.mech.name} needs the orientation fixed "
                             f"({need}), got {show(fixed)}")
    template = np.zeros(len(names))
    for k, v in fixed.items():
        template[names.index(k)] = as_float(v, f"fixed[{k!r}]")
    act = list(model.mech.active_names)
    lim = {}
    for k, pair in (limits or {}).items():
        if k not in act:
            raise MechanismError(f"limits: {show(k)} is not an actuated joint of "
                                 f"{model.mech.name}; known: {', '.join(act)}")
        lo, hi = as_vector(pair, f"limits[{k!r}]", 2)
        if not lo < hi:
            raise MechanismError(f"limits[{k!r}]: lo < hi required, got {show(pair)}")
        lim[act.index(k)] = (float(lo), float(hi))
    gamma = as_float(gamma, "gamma", lo=0.0, hi=1.0)
    length = as_float(length, "length", lo=0.0)
    if length <= 0:
        raise MechanismError("length: expected a positive characteristic length")
    if family is not None:
        z = np.asarray(z, dtype=float)
        if family.affine:
            p0, M, d = family.p0, family.M, z
        else:
            p0, M, d = np.concatenate([family.mechanism(z).geometry, [1.0]]), None, None
        reach_mech = None
    else:
        p0, M, d = model.p, None, None
        reach_mech = model
    from ..model.charts import planar_chart

    chart = planar_chart(reach_mech if reach_mech is not None else
                         get_model(family.mechanism(z)))
    box = chart.reach_box() if chart is not None else np.array([[-1.0, 1.0], [-1.0, 1.0]])
    box = np.asarray(box, dtype=float)[:2]
    scale = float(max(box[:, 1] - box[:, 0]))
    pr = Probe(ev, np.asarray(p0, float), M, None if d is None else np.asarray(d, float),
               sigma, length, (trans[0], trans[1]), template, lim, gamma, scale, box)
    pr.ev_angle_qa = np.array([bool(model.mech.revolute[i]) for i in model.mech.active_index])
    return pr


# --------------------------------------------------------------------------- point measures
def conditioning(mech: Mechanism, points: Any, mode: Any = None,
                 fixed: Mapping[str, float] | None = None, length: float = 1.0) -> np.ndarray:
    """Local conditioning 1/kappa of the forward Jacobian at task-plane points (N, 2)
    (NaN where a leg cannot reach in the working mode).

    >>> import optkin
    >>> from optkin.design import conditioning
    >>> m = optkin.mechanisms.five_bar(1.6, 1.2, 1.0, 1.0, 1.2)
    >>> conditioning(m, [[0.8, 1.2]], mode=(1, 1)).round(4)
    array([0.6667])
    """
    pr = _probe(mech, mode, fixed, length=length)
    P = np.atleast_2d(as_vector(np.asarray(points, float).reshape(-1), "points")).reshape(-1, 2)
    return pr.eval(P)["inv_kappa"]


def singular_values(mech: Mechanism, points: Any, mode: Any = None,
                    fixed: Mapping[str, float] | None = None,
                    length: float = 1.0) -> np.ndarray:
    """Singular values of the forward Jacobian J (N, n), largest first: the largest and
    smallest end-effector speed per unit actuator speed; their reciprocals bound the
    end-effector force per unit actuator effort, and with equal actuator stiffnesses k the
    end-effector stiffness k J^-T J^-1 has eigenvalues k / sigma_i^2 (its extremes). NaN
    where unreachable."""
    pr = _probe(mech, mode, fixed, length=length)
    P = np.asarray(points, dtype=float).reshape(-1, 2)
    return pr.eval(P, jacobian=True)["sv"]


# --------------------------------------------------------------------------- integrals
@dataclass
class Integral:
    """A region integral of a measure, with its account.

    ``value`` the measure (GCI or area), ``area`` the region's area,
    ``reachable`` the fraction of the region's area the mechanism reaches in the working
    mode (and within limits), ``nodes`` the quadrature points used; ``success``,
    ``status`` and ``message`` as every result (:mod:`optkin.results`): ``"infeasible"``
    when an aspect's seed is not a point of the working mode, ``"inaccurate"`` when the
    adaptive quadrature stopped short of its tolerance."""

    value: float
    area: float
    reachable: float
    nodes: int
    kind: str
    success: bool = True
    status: str = "optimal"
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable(self.__dict__.copy())


def _section(pr: Probe, s0: float | None, lo: np.ndarray, hi: np.ndarray, points: Any,
             tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Shrink brackets [lo, hi] of a parameter (lo feasible, hi not) to the boundary
    between, to width ``tol``: the Illinois variant of regula falsi on the continuous
    margin F (:meth:`Probe.margin`), every third step a bisection. ``points(v, rows)``
    maps parameter values of the brackets ``rows`` to task points."""
    lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
    n = len(lo)
    if n == 0:
        return lo, hi
    rows = np.arange(n)
    sv = None if s0 is None else np.broadcast_to(np.asarray(s0, dtype=float), (n,))

    def S(r: np.ndarray) -> Any:
        return None if sv is None else sv[r]

    F = pr.margin(points(np.concatenate([lo, hi]), np.concatenate([rows, rows])),
                  S(np.concatenate([rows, rows])))[0]
    flo, fhi = F[:n].copy(), F[n:].copy()
    flo = np.where(flo > 0, flo, np.nan)      # a feasible end with F <= 0 cannot happen
    fhi = np.minimum(fhi, 0.0)
    side = np.zeros(n, dtype=int)
    for it in range(200):
        act = np.flatnonzero(np.abs(hi - lo) >= tol)
        if not len(act):
            break
        a, b, fa, fb = lo[act], hi[act], flo[act], fhi[act]
        with np.errstate(all="ignore"):
            t = fa / (fa - fb)          # regula falsi, as a fraction from a towards b
        t = np.where(np.isfinite(t) & (it % 3 != 2), np.clip(t, 0.01, 0.99), 0.5)
        x = a + t * (b - a)
        fx = pr.margin(points(x, act), S(act))[0]
        good = fx > 0
        # Illinois: halve the retained end's value when the same end moves twice
        lo[act] = np.where(good, x, a)
        hi[act] = np.where(good, b, x)
        new_side = np.where(good, 1, -1)
        same = new_side == side[act]
        flo[act] = np.where(good, fx, np.where(same, 0.5 * fa, fa))
        fhi[act] = np.where(good, np.where(same, 0.5 * fb, fb), np.minimum(fx, 0.0))
        side[act] = new_side
    return lo, hi


class _Lines:
    """Exact feasible intervals of the task plane's horizontal lines (sampling, then
    bisection of each interval's ends to 1e-13 of the size) for one design, working mode
    and det A sign."""

    def __init__(self, pr: Probe, s0: float, box: np.ndarray, samples: int) -> None:
        self.pr, self.s0, self.box = pr, s0, box
        self.xs = np.linspace(box[0, 0], box[0, 1], samples)

    def __call__(self, ys: np.ndarray) -> list[np.ndarray]:
        xs, pr = self.xs, self.pr
        S = len(xs)
        X, Y = np.meshgrid(xs, ys)
        F, _, _ = pr.margin(np.stack([X.ravel(), Y.ravel()], -1), self.s0)
        F = F.reshape(X.shape)
        ok = F > 0
        # intervals narrower than the sampling: peaks of F between samples
        hid = _hidden(pr, self.s0, np.broadcast_to(xs, F.shape), F, +1,
                      lambda v, r: np.stack([v, ys[r]], -1))
        extra: dict[int, list[tuple[float, int]]] = {}
        for r, i, x in hid:
            extra.setdefault(r, []).append((x, i))
        raw: list[list[list[Any]]] = []
        ends: list[tuple[float, float, float]] = []   # (y, x ok, x bad)
        for j in range(len(ys)):
            row = ok[j]
            rows: list[list[Any]] = []
            raw.append(rows)
            if row.any():
                d = np.diff(row.astype(np.int8))
                starts = list(np.flatnonzero(d == 1) + 1)
                stops = list(np.flatnonzero(d == -1))
                if row[0]:
                    starts = [0] + starts
                if row[-1]:
                    stops = stops + [S - 1]
                for a, b in zip(starts, stops):
                    iv: list[Any] = [xs[a], xs[b]]
                    if a > 0:
                        iv[0] = -1 - len(ends)
                        ends.append((ys[j], xs[a], xs[a - 1]))
                    if b < S - 1:
                        iv[1] = -1 - len(ends)
                        ends.append((ys[j], xs[b], xs[b + 1]))
                    rows.append(iv)
            for x, i in extra.get(j, []):
                rows.append([-1 - len(ends), -2 - len(ends)])
                ends.append((ys[j], x, xs[i - 1]))
                ends.append((ys[j], x, xs[i + 1]))
        xe = np.zeros(0)
        if ends:
            E = np.array(ends)
            lo, hi = _section(pr, self.s0, E[:, 1], E[:, 2],
                              lambda x, rows: np.stack([x, E[rows, 0]], -1),
                              1e-13 * pr.scale)
            xe = 0.5 * (lo + hi)
        out = []
        for rows in raw:
            arr = np.array([[xe[-1 - v] if isinstance(v, (int, np.integer)) and v < 0 else v
                             for v in iv] for iv in rows], dtype=float).reshape(-1, 2)
            out.append(_union(arr))
        return out


def _union(arr: np.ndarray) -> np.ndarray:
    """Intervals (k, 2) sorted and merged where they overlap."""
    if len(arr) < 2:
        return arr
    arr = arr[np.argsort(arr[:, 0])]
    out = [arr[0].copy()]
    for a, b in arr[1:]:
        if a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append(np.array([a, b]))
    return np.array(out)


def _hidden(pr: Probe, s0: Any, V: np.ndarray, F: np.ndarray, want: int,
            points: Any, iters: int = 48, before: np.ndarray | None = None
            ) -> list[tuple[int, int, float]]:
    """Where the margin F sampled along rows (parameters V (R, S)) may change sign twice
    between samples: at each interior local maximum of g = want * F with g <= 0 at it and
    both neighbours, that could reach 0 (g + 3 x the larger neighbour difference > 0), the
    maximum of g over the two neighbouring cells by golden-section search, a candidate
    dropped once it cannot reach 0 (its best value plus 4 x the sampled slope times the
    bracket stays negative). Returns (row, sample index, parameter) where g > 0 was
    found: a feasible point between infeasible samples (want = +1), or the reverse
    (want = -1). ``before``: per row, only samples before this index."""
    g = want * F
    if g.shape[1] < 3:
        return []
    s0v = None if s0 is None else np.broadcast_to(np.asarray(s0, dtype=float), (g.shape[0],))

    def S(r: np.ndarray) -> Any:
        return None if s0v is None else s0v[r]

    c, l_, r_ = g[:, 1:-1], g[:, :-2], g[:, 2:]
    cand = (c <= 0) & (l_ <= 0) & (r_ <= 0) & (c >= l_) & (c > r_) & \
        (c + 3 * np.maximum(c - l_, c - r_) > 0) & np.isfinite(c)
    if before is not None:
        cand &= np.arange(1, g.shape[1] - 1)[None] < np.asarray(before)[:, None] - 1
    R, I = np.nonzero(cand)
    if not len(R):
        return []
    I = I + 1
    a, b = V[R, I - 1].astype(float), V[R, I + 1].astype(float)
    slope = 4 * np.maximum(np.abs(c[R, I - 1] - l_[R, I - 1]),
                           np.abs(c[R, I - 1] - r_[R, I - 1])) / np.maximum(b - a, 1e-300)
    phi = (np.sqrt(5) - 1) / 2
    x1, x2 = b - phi * (b - a), a + phi * (b - a)
    g12 = want * pr.margin(points(np.concatenate([x1, x2]), np.concatenate([R, R])),
                           S(np.concatenate([R, R])))[0]
    g1, g2 = g12[:len(R)], g12[len(R):]
    found = np.zeros(len(R), dtype=bool)
    best = np.where(g1 > g2, x1, x2)
    act = np.arange(len(R))
    for _ in range(iters):
        hit = (g1[act] > 0) | (g2[act] > 0)
        found[act[hit]] = True
        best[act[hit]] = np.where(g1[act[hit]] > g2[act[hit]], x1[act[hit]], x2[act[hit]])
        gm = np.maximum(g1[act], g2[act])
        hope = gm + slope[act] * (b[act] - a[act]) > 0
        act = act[~hit & hope]
        if not len(act):
            break
        left = g1[act] > g2[act]
        A, B = a[act], b[act]
        B = np.where(left, x2[act], B)
        A = np.where(left, A, x1[act])
        x2n = np.where(left, x1[act], A + phi * (B - A))
        x1n = np.where(left, B - phi * (B - A), x2[act])
        xq = np.where(left, x1n, x2n)
        gq = want * pr.margin(points(xq, R[act]), S(R[act]))[0]
        g1n = np.where(left, gq, g2[act])
        g2n = np.where(left, g1[act], gq)
        a[act], b[act], x1[act], x2[act], g1[act], g2[act] = A, B, x1n, x2n, g1n, g2n
    return [(int(R[k]), int(I[k]), float(best[k])) for k in np.flatnonzero(found)]


def _overlaps(iv: np.ndarray, ref: np.ndarray) -> np.ndarray:
    if len(iv) == 0 or len(ref) == 0:
        return np.zeros(len(iv), dtype=bool)
    return np.any((np.minimum(iv[:, None, 1], ref[None, :, 1])
                   >= np.maximum(iv[:, None, 0], ref[None, :, 0])), axis=1)


def aspect_integral(pr: Probe, seed: np.ndarray, bounds: Any = None, f: Any = None,
                    tol: float = 1e-9, base: int = 256, samples: int = 384,
                    max_lines: int = 20000) -> tuple[float, float, int, bool]:
    """(area, integral of f, lines, converged) over the aspect containing ``seed``.

    The component is found on ``base`` uniform lines (intervals linked across neighbouring
    lines where they overlap); the integral over y is adaptive Gauss-Legendre (8 points on
    a panel against 8 on each half, panels split until they agree to ``tol`` times the
    area), each line's part of the component being its exact intervals that overlap the
    component's on the nearest base lines; along x, 8-point Gauss-Legendre per interval
    (composite on long ones). ``f(P) -> values`` is integrated besides the area."""
    box = _box_arg(bounds) if bounds is not None else pr.reach
    code0, o0 = pr.reasons(seed[None])
    if code0[0] != 0 or not np.isfinite(o0["det"][0]) or o0["det"][0] == 0:
        return 0.0, 0.0, 0, False
    s0 = float(np.sign(o0["det"][0]))
    lines = _Lines(pr, s0, box, samples)
    yb = np.linspace(box[1, 0], box[1, 1], base)
    ivs = lines(yb)
    # link base intervals into components
    idx = [(j, k) for j in range(base) for k in range(len(ivs[j]))]
    pos = {jk: n for n, jk in enumerate(idx)}
    parent = list(range(len(idx)))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for j in range(base - 1):
        a, b = ivs[j], ivs[j + 1]
        if len(a) and len(b):
            hit = (np.minimum(a[:, None, 1], b[None, :, 1])
                   >= np.maximum(a[:, None, 0], b[None, :, 0]))
            for k, k2 in zip(*np.nonzero(hit)):
                parent[find(pos[(j, int(k))])] = find(pos[(j + 1, int(k2))])
    jn = int(np.argmin(np.abs(yb - seed[1])))
    best, bd = None, np.inf
    for jj in range(max(0, jn - 1), min(base, jn + 2)):
        for k, (x0, x1) in enumerate(ivs[jj]):
            dist = (0.0 if x0 <= seed[0] <= x1 else min(abs(seed[0] - x0), abs(seed[0] - x1)))
            dist += abs(yb[jj] - seed[1])
            if dist < bd:
                best, bd = pos[(jj, k)], dist
    if best is None:
        return 0.0, 0.0, 0, False
    root = find(best)
    single = all(find(i) == root for i in range(len(idx)))
    comp = [np.array([ivs[j][k] for k in range(len(ivs[j])) if find(pos[(j, k)]) == root])
            .reshape(-1, 2) for j in range(base)]
    rows = [j for j in range(base) if len(comp[j])]
    h = yb[1] - yb[0]
    y_lo = max(box[1, 0], yb[rows[0]] - h)
    y_hi = min(box[1, 1], yb[rows[-1]] + h)
    xg, wg = np.polynomial.legendre.leggauss(8)
    width = box[0, 1] - box[0, 0]
    n_lines = [0]

    def g(ys: np.ndarray) -> np.ndarray:
        """(2, len(ys)): the component's length and integral of f on each line."""
        n_lines[0] += len(ys)
        out = np.zeros((2, len(ys)))
        lv = lines(ys)
        pts, who, wts = [], [], []
        for i, (y, iv) in enumerate(zip(ys, lv)):
            if not len(iv):
                continue
            if not single:   # the intervals overlapping the component's on nearby lines
                j = int(np.clip(np.floor((y - yb[0]) / h), 0, base - 1))
                ref = np.vstack([comp[k] for k in range(max(0, j - 1), min(base, j + 3))])
                iv = iv[_overlaps(iv, ref)]
            for x0, x1 in iv:
                out[0, i] += x1 - x0
                if f is not None and x1 > x0:
                    npan = max(1, int(np.ceil(8 * (x1 - x0) / width)))
                    e = np.linspace(x0, x1, npan + 1)
                    hx = 0.5 * (e[1:] - e[:-1])
                    xq = (e[:-1, None] + hx[:, None] * (xg[None] + 1)).reshape(-1)
                    pts.append(np.stack([xq, np.full_like(xq, y)], -1))
                    wts.append((hx[:, None] * wg[None]).reshape(-1))
                    who.append(np.full(len(xq), i))
        if pts:
            vals = np.nan_to_num(np.asarray(f(np.vstack(pts)), dtype=float))
            np.add.at(out[1], np.concatenate(who), vals * np.concatenate(wts))
        return out

    def rule(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """8-point Gauss on each panel and on its halves: (whole, halves) (2, n)."""
        m = 0.5 * (a + b)
        ys = np.concatenate([(0.5 * (b - a))[:, None] * (xg[None] + 1) + a[:, None],
                             (0.5 * (m - a))[:, None] * (xg[None] + 1) + a[:, None],
                             (0.5 * (b - m))[:, None] * (xg[None] + 1) + m[:, None]], 1)
        G = g(ys.reshape(-1)).reshape(2, len(a), 3, 8)
        w = wg[None, None]
        whole = (G[:, :, 0] * w).sum(-1) * (0.5 * (b - a))
        halves = (G[:, :, 1] * w).sum(-1) * (0.5 * (m - a)) + \
            (G[:, :, 2] * w).sum(-1) * (0.5 * (b - m))
        return whole, halves

    edges = np.linspace(y_lo, y_hi, 17)
    a, b = edges[:-1], edges[1:]
    total = np.zeros(2)
    guess = None
    converged = True
    while len(a):
        whole, halves = rule(a, b)
        if guess is None:
            guess = max(abs(halves[0].sum()), 1e-300)
        err = np.abs(whole - halves).max(axis=0)
        done = err <= tol * guess * (b - a) / (y_hi - y_lo) + 1e-15 * guess
        # panels below 1e-7 of the range are kept as they are (a jump of the integrand,
        # e.g. a sliver narrower than the sampling seen on one line and not the next)
        done |= (b - a) < 1e-7 * (y_hi - y_lo)
        total += halves[:, done].sum(axis=1)
        a, b = a[~done], b[~done]
        if n_lines[0] > max_lines:
            total += halves[:, ~done].sum(axis=1)
            converged = not len(a)
            break
        m = 0.5 * (a + b)
        a, b = np.concatenate([a, m]), np.concatenate([m, b])
    return float(total[0]), float(total[1]), n_lines[0], converged


def _integral(pr: Probe, region: Region, kind: str, order: int) -> Integral:
    if isinstance(region, Aspect):
        fn = (lambda P: pr.eval(P)["inv_kappa"]) if kind == "gci" else None
        A, I, n, conv = aspect_integral(pr, np.array(region.seed), region.bounds, fn)
        if A <= 0:
            return Integral(0.0, 0.0, 0.0, 0, kind, False, "infeasible",
                            f"the seed {region.seed} is not a feasible point of the working "
                            f"mode {pr.sigma}")
        val = I / A if kind == "gci" else A
        if not conv:
            return Integral(val, A, 1.0, n, kind, False, "inaccurate",
                            "the adaptive quadrature stopped before reaching its tolerance")
        return Integral(val, A, 1.0, n, kind, message=f"{kind} = {val:.6g} over the aspect "
                        f"(area {A:.6g}, {n} quadrature nodes)")
    if not isinstance(region, (Disc, Box)):
        raise MechanismError(f"region: expected optkin.design.Disc, Box or Aspect, got "
                             f"{type(region).__name__}")
    P, W = region.nodes(order)
    code, o = pr.reasons(P)
    ok = code == 0
    A = float(W.sum())
    reach = float(W[ok].sum() / A)
    if kind == "gci":
        val = float(np.dot(np.where(ok, np.nan_to_num(o["inv_kappa"]), 0.0), W) / A)
    else:
        val = float(W[ok].sum())
    msg = f"{kind} = {val:.6g} over the region (area {A:.6g}, {len(W)} quadrature nodes)"
    if reach != 1.0:
        msg += (f"; {100 * (1 - reach):.3g} % of the region is outside the working mode's "
                "reach or limits (counted as 1/kappa = 0)")
    return Integral(val, A, reach, len(W), kind, message=msg)


def gci(mech: Mechanism, region: Region, mode: Any = None,
        fixed: Mapping[str, float] | None = None, length: float = 1.0,
        limits: Mapping[str, Any] | None = None, order: int = 16) -> Integral:
    """The global conditioning index over ``region`` (area-weighted; see the module
    docstring): ``.value``; Gauss quadrature of ``order`` points per direction (a disc:
    ``order`` radii x ``4 order`` angles).

    >>> import optkin
    >>> from optkin.design import gci, Disc
    >>> m = optkin.mechanisms.five_bar(1.6, 1.2, 1.0, 1.0, 1.2)
    >>> r = gci(m, Disc((0.8, 1.3), 0.3), mode=(1, 1))
    >>> round(r.value, 3), r.reachable
    (0.637, 1.0)
    """
    pr = _probe(mech, mode, fixed, limits, 0.0, length)
    return _integral(pr, region, "gci", as_int(order, "order", lo=2, hi=256))


def area(mech: Mechanism, region: Region, mode: Any = None,
         fixed: Mapping[str, float] | None = None, limits: Mapping[str, Any] | None = None,
         gamma: float = 0.0, length: float = 1.0, order: int = 16) -> Integral:
    """The area of ``region`` the mechanism reaches in the working mode within limits (and
    with 1/kappa >= gamma); for an :class:`Aspect`, the aspect's area."""
    pr = _probe(mech, mode, fixed, limits, gamma, length)
    return _integral(pr, region, "area", as_int(order, "order", lo=2, hi=256))


# --------------------------------------------------------------------------- inscribed
@dataclass
class Inscribed:
    """The largest singularity-free disc or square of one working mode and aspect.

    Attributes
    ----------
    shape : str
        ``"disc"`` (``size`` is its radius) or ``"square"`` (``size`` is half its side).
    size : float
    centre : ndarray (2,)
    contact : ndarray (2,)
        The boundary point the shape touches.
    binding : str
        What bounds it there: ``"serial"`` (a leg at the end of its reach), ``"parallel"``
        (det A = 0), ``"limit"`` (an actuator limit) or ``"conditioning"`` (1/kappa =
        gamma).
    det_sign : int
        The sign of det A in the aspect.
    evaluations : int
        Point evaluations spent.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"infeasible"`` when no feasible centre
        exists, ``"inaccurate"`` for a quick estimate (``exact=False``).
    """

    shape: Any
    size: float
    centre: np.ndarray
    contact: np.ndarray
    binding: str
    det_sign: int
    evaluations: int
    success: bool = True
    status: str = "optimal"
    message: str = ""

    aspect: tuple[float, float] = (1.0, 1.0)

    @property
    def area(self) -> float:
        if self.shape == "disc":
            return float(np.pi * self.size ** 2)
        return float(4 * self.aspect[0] * self.aspect[1] * self.size ** 2)

    def to_dict(self) -> dict[str, Any]:
        d = self.__dict__.copy()
        d["area"] = self.area
        return jsonable(d)

    def __repr__(self) -> str:
        what = "radius" if self.shape == "disc" else "half-side"
        return (f"Inscribed({self.shape}, {what}={self.size:.6g}, centre={np.round(self.centre, 6)}, "
                f"binding={self.binding!r}, status={self.status!r})")


def _unit(shape: Any, th: np.ndarray) -> np.ndarray:
    """Points of the unit shape's boundary at polar angles th: the circle, the square's
    (L-infinity) boundary, or a box's ``("box", ax, ay)`` (half sides ax, ay)."""
    u = np.stack([np.cos(th), np.sin(th)], -1)
    if shape != "disc":
        u = u / np.max(np.abs(u), axis=1, keepdims=True)
    if isinstance(shape, tuple):
        u = u * np.array([shape[1], shape[2]])
    return u


def _exits(pr: Probe, c: np.ndarray, s0: Any, U: np.ndarray, rmax: float, steps: int,
           tol: float) -> tuple[np.ndarray, np.ndarray]:
    """First exit distance along each ray c + t U_k (t in (0, rmax]) and the reason code
    just past it (rmax and 0 when the ray stays inside): marching, a search for thin
    infeasible parts between the steps (:func:`_hidden`), then the boundary to ``tol``.
    ``c`` and ``s0`` (the det A sign kept) may be one per ray."""
    K = len(U)
    C = np.broadcast_to(np.asarray(c, dtype=float), (K, 2))
    sv = np.broadcast_to(np.asarray(s0, dtype=float), (K,))
    t = rmax * np.arange(1, steps + 1) / steps
    P = (C[:, None] + t[None, :, None] * U[:, None, :]).reshape(-1, 2)
    F, _, _ = pr.margin(P, np.repeat(sv, steps))
    F = F.reshape(K, steps)
    bad = F <= 0
    first = np.where(bad.any(1), bad.argmax(1), steps)
    hi = np.where(first < steps, t[np.minimum(first, steps - 1)], np.inf)
    lo = np.where(first > 0, t[np.maximum(first - 1, 0)], 0.0)
    Fz = np.hstack([np.full((K, 1), 1.0), F])        # t = 0: the centre, feasible
    Tz = np.broadcast_to(np.concatenate([[0.0], t]), Fz.shape)
    for r, i, x in _hidden(pr, sv, Tz, Fz, -1, lambda v, rows: C[rows] + v[:, None] * U[rows],
                           before=first + 1):
        if x < hi[r]:
            hi[r], lo[r] = x, Tz[r, i - 1]
    out = np.full(K, rmax)
    why = np.zeros(K, dtype=int)
    idx = np.flatnonzero(np.isfinite(hi))
    if len(idx):
        Ui, Ci = U[idx], C[idx]
        a, b = _section(pr, sv[idx], lo[idx], hi[idx],
                        lambda v, rows: Ci[rows] + v[:, None] * Ui[rows], tol)
        cm, _ = pr.reasons(Ci + b[:, None] * Ui, sv[idx])
        out[idx] = a
        why[idx] = cm
    return out, why


def _coarse(pr: Probe, C: np.ndarray, shape: str, rays: int, steps: int,
            tol: float = 1e-9) -> np.ndarray:
    """The unrefined size (least exit over ``rays`` rays) of the shape at each centre of C
    (n, 2), all centres in one batch (0 where a centre is infeasible)."""
    code, o = pr.reasons(C)
    ok = (code == 0) & np.isfinite(o["det"]) & (o["det"] != 0)
    out = np.zeros(len(C))
    if not ok.any():
        return out
    Cs, s0 = C[ok], np.sign(o["det"][ok])
    th = 2 * np.pi * np.arange(rays) / rays
    U = _unit(shape, th)
    n = len(Cs)
    h, _ = _exits(pr, np.repeat(Cs, rays, axis=0), np.repeat(s0, rays), np.tile(U, (n, 1)),
                  2.0 * pr.scale, steps, tol * pr.scale)
    out[ok] = h.reshape(n, rays).min(axis=1)
    return out


def _inscribed_at(pr: Probe, c: np.ndarray, shape: str, rays: int, steps: int,
                  refine: bool = True) -> tuple[float, np.ndarray, int, float]:
    """(size, contact point, reason, det sign) of the largest shape centred at c: the
    least exit over ``rays`` rays, each of the (up to 4) least local minima over the ray
    direction refined by zooming (to 1e-10 rad)."""
    code, o = pr.reasons(c[None])
    if code[0] != 0 or not o["det"][0] or not np.isfinite(o["det"][0]):
        return 0.0, c.copy(), int(code[0] or PARALLEL), 0.0
    s0 = float(np.sign(o["det"][0]))
    rmax = 2.0 * pr.scale
    tol = 1e-13 * pr.scale
    th = 2 * np.pi * np.arange(rays) / rays
    h, why = _exits(pr, c, s0, _unit(shape, th), rmax, steps, tol)
    k = int(np.argmin(h))
    best_h, best_th, best_why = h[k], th[k], why[k]
    if refine and best_h < rmax:
        # zoom on each of the (up to 4) least local minima over the direction at once: 9
        # directions a bracket, the bracket shrunk to the least one's neighbours (x 1/4)
        local = np.flatnonzero((h <= np.roll(h, 1)) & (h <= np.roll(h, -1)) & (h < rmax))
        local = local[np.argsort(h[local])][:4]
        centre_th = th[local].astype(float)
        half = np.full(len(local), 2 * np.pi / rays)
        reach = min(rmax, 1.5 * best_h + 1e-9)
        off = np.linspace(-1, 1, 9)
        for _ in range(16):
            A = (centre_th[:, None] + half[:, None] * off[None]).reshape(-1)
            hh, ww = _exits(pr, c, s0, _unit(shape, A), reach, 16, tol)
            hh = hh.reshape(len(local), 9)
            j = hh.argmin(1)
            centre_th = centre_th + half * off[j]
            half = half / 4
            kk = int(np.argmin(hh.min(1)))
            if hh[kk, j[kk]] < best_h:
                best_h, best_th = float(hh[kk, j[kk]]), float(centre_th[kk])
                best_why = int(ww.reshape(len(local), 9)[kk, j[kk]])
            # done when no bracket can still go below the best by more than 1e-12 of the
            # size (the exits across each bracket differ by less than that)
            spread = hh.max(1) - hh.min(1)
            if half.max() < 1e-10 or np.all((spread < 1e-12 * pr.scale)
                                            | (hh.min(1) > best_h + spread)):
                break
    contact = c + best_h * _unit(shape, np.array([best_th]))[0]
    return float(best_h), contact, int(best_why), s0


def largest_inscribed(mech: Mechanism, mode: Any = None, shape: str = "disc",
                      centre: Any = None, line: Any = None, fixed: Mapping[str, float] |
                      None = None, limits: Mapping[str, Any] | None = None,
                      gamma: float = 0.0, length: float = 1.0, bounds: Any = None,
                      rays: int = 128, steps: int = 64, family: Any = None,
                      z: Any = None, exact: bool = True, aspect: Any = (1.0, 1.0)
                      ) -> Inscribed:
    """The largest disc (radius) or square (half side) free of singularities, in one working
    mode and aspect, within actuator ``limits`` and with 1/kappa >= ``gamma``.

    Parameters
    ----------
    mech : Mechanism
    mode : tuple of int
        The working mode (signs of diag B).
    shape : {"disc", "square", "box"}
        A box has half sides in the ratio ``aspect`` (x, y); its ``size`` is the longer
        half side.
    centre : (x, y), optional
        Centre the shape here.
    line : ((x, y), (dx, dy), (s_lo, s_hi)), optional
        Centre it on the segment point + s * direction (s in [s_lo, s_hi]): the best s is
        found by a scan of 32 positions refined by Brent's method.
    (neither: the centre is free within ``bounds``, default the legs' reach: the best of a
    40 x 40 scan refined by Nelder-Mead)
    bounds : [[xlo, xhi], [ylo, yhi]], optional
        The shape must lie within this box too (binding ``"bounds"``).
    fixed : dict, optional
        The orientation of a 3-DoF planar platform.
    limits : dict name -> (lo, hi), optional
        Actuator limits (angles compared modulo 2 pi).
    gamma : float
        Conditioning floor (Le, Kang and Doan use 0.5).
    length : float
        Characteristic length for the conditioning of mixed units.
    rays, steps : int
        Rays from the centre and march steps along each (then the boundary to 1e-13 of
        the size, and the nearest exit's direction refined).
    exact : bool
        False: a quick estimate for searches (centres on a line by two batched scans, no
        refinement of directions; a little larger than the exact size, by about
        size (pi / rays)^2 / 2), ``status="inaccurate"``.

    Returns
    -------
    Inscribed
    """
    if shape not in ("disc", "square", "box"):
        raise MechanismError(f"shape: expected 'disc', 'square' or 'box', got {show(shape)}")
    aspect_ = (1.0, 1.0)
    if shape == "box":
        a_ = as_vector(aspect, "aspect", 2)
        if not np.all(a_ > 0):
            raise MechanismError(f"aspect: expected two positive numbers, got {show(aspect)}")
        a_ = a_ / a_.max()
        aspect_ = (float(a_[0]), float(a_[1]))
        shape = ("box", aspect_[0], aspect_[1])
    pr = _probe(mech, mode, fixed, limits, gamma, length, family, z)
    rays = as_int(rays, "rays", lo=8, hi=100000)
    steps = as_int(steps, "steps", lo=8, hi=100000)
    if bounds is not None:
        pr.clip = _box_arg(bounds)
    box = pr.clip if pr.clip is not None else pr.reach
    if centre is not None and line is not None:
        raise MechanismError("give centre or line, not both")
    if centre is not None:
        c = as_vector(centre, "centre", 2)
        h, P, why, s0 = _inscribed_at(pr, c, shape, rays, steps, refine=exact)
    elif not exact and line is not None:
        a, u, (s_lo, s_hi) = _line_arg(line)
        S = np.linspace(s_lo, s_hi, 24)
        co = _coarse(pr, a[None] + S[:, None] * u[None], shape, 32, 24, 1e-5)
        k = int(np.argmax(co))
        ds = S[1] - S[0]
        S2 = np.linspace(max(s_lo, S[k] - ds), min(s_hi, S[k] + ds), 17)
        co2 = _coarse(pr, a[None] + S2[:, None] * u[None], shape, rays, 32, 1e-7)
        k2 = int(np.argmax(co2))
        c = a + S2[k2] * u
        h, P, why, s0 = _inscribed_at(pr, c, shape, rays, steps, refine=False)
    else:
        if line is not None:
            a, u, (s_lo, s_hi) = _line_arg(line)
            S = np.linspace(s_lo, s_hi, 32)
            coarse = _coarse(pr, a[None] + S[:, None] * u[None], shape, 64, 32)
            k = int(np.argmax(coarse))
            ds = S[1] - S[0]
            res = minimize_scalar(
                lambda s: -_inscribed_at(pr, a + s * u, shape, rays, steps)[0],
                bounds=(max(s_lo, S[k] - ds), min(s_hi, S[k] + ds)), method="bounded",
                options={"xatol": 1e-8 * pr.scale})
            c = a + float(res.x) * u
        else:
            from scipy.optimize import minimize

            g = np.linspace(0, 1, 42)[1:-1]
            X, Y = np.meshgrid(box[0, 0] + g * (box[0, 1] - box[0, 0]),
                               box[1, 0] + g * (box[1, 1] - box[1, 0]))
            C = np.stack([X.ravel(), Y.ravel()], -1)
            code, o = pr.reasons(C)
            C = C[code == 0]
            if len(C) == 0:
                nan2 = np.full(2, np.nan)
                return _named(Inscribed(shape, 0.0, nan2, nan2, "none", 0, pr.evals[0], False,
                                        "infeasible", "no feasible point of the working mode "
                                        "within the bounds"), aspect_)
            coarse = _coarse(pr, C, shape, 32, 32)
            order = np.argsort(-coarse)[:4]
            best_c, best_h = C[order[0]], -1.0
            for i in order:
                res = minimize(lambda v: -_inscribed_at(pr, v, shape, max(64, rays // 2),
                                                        steps, refine=False)[0], C[i],
                               method="Nelder-Mead",
                               options={"xatol": 1e-7 * pr.scale, "fatol": 1e-9 * pr.scale,
                                        "initial_simplex": C[i] + 0.02 * pr.scale *
                                        np.array([[0, 0], [1, 0], [0, 1]])})
                if -res.fun > best_h:
                    best_h, best_c = -res.fun, res.x
            c = np.asarray(best_c, dtype=float)
        h, P, why, s0 = _inscribed_at(pr, c, shape, rays, steps)
    if h <= 0:
        return _named(Inscribed(shape, 0.0, c, c, _REASON.get(why, "none"), int(s0),
                                pr.evals[0], False, "infeasible",
                                f"the centre {np.round(c, 6)} is not a feasible point of the "
                                f"working mode {pr.sigma} ({_REASON.get(why)})"), aspect_)
    if not exact:
        return _named(Inscribed(shape, h, c, P, _REASON[why], int(s0), pr.evals[0], True,
                         "inaccurate", "a quick estimate (exact=False)"), aspect_)
    return _named(Inscribed(shape, h, c, P, _REASON[why], int(s0), pr.evals[0],
                            message=f"size {h:.6g} at the centre {np.round(c, 6).tolist()}, "
                                    f"bounded by the {_REASON[why]} boundary"), aspect_)


def _named(res: Inscribed, aspect: tuple[float, float]) -> Inscribed:
    if isinstance(res.shape, tuple):
        res.shape = "box"
    res.aspect = aspect
    return res


def _line_arg(line: Any) -> tuple[np.ndarray, np.ndarray, tuple[float, float]]:
    try:
        a, u, (s_lo, s_hi) = line
        a = as_vector(a, "line point", 2)
        u = as_vector(u, "line direction", 2)
        s_lo, s_hi = float(s_lo), float(s_hi)
    except (TypeError, ValueError, MechanismError) as e:
        raise MechanismError("line: expected ((x, y), (dx, dy), (s_lo, s_hi)), got "
                             f"{show(line)}") from e
    if not s_lo < s_hi or not np.linalg.norm(u) > 0:
        raise MechanismError(f"line: s_lo < s_hi and a nonzero direction required, "
                             f"got {show(line)}")
    return a, u / np.linalg.norm(u), (s_lo, s_hi)
