"""Dimensional synthesis: optimize(family, variables, objective, constraints).

Strategy (documented for users in :func:`optimize`):

1. **Global**: differential evolution (scipy) over the free design variables, each
   generation evaluated as one batch: measures over fixed nodes are one mapped call of the
   topology's compiled evaluation for every design and node at once; the others (largest
   inscribed shapes, aspect areas) design by design. Constraints enter as a penalty
   (100 x the summed violations, bounds of the eliminated variables included).
2. **Local**: where the objective and every constraint are smooth (GCI, least
   conditioning over a region, dimensions) and the family's geometry is affine, IPOPT on
   the CasADi NLP from the global best: the least conditioning over a region is imposed at
   sample nodes (1/kappa >= gamma, every leg reaching, det A keeping its sign), refined by
   an exchange step (verify on nodes twice as dense with the boundary, add the violated
   points, solve again); the objective's region is kept inside one aspect the same way.
   Otherwise Nelder-Mead on the penalised objective polishes the global best.
3. **Verification**: each constraint re-evaluated at the optimum on a denser set (or with
   more rays), reported in ``verification``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._checks import as_float, as_int, show
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..results import TIME_LIMIT, jsonable
from .family import Family
from .problem import (
    GCI,
    Constraint,
    Dimension,
    JointRange,
    Maximize,
    Measure,
    MinConditioning,
    Minimize,
    _sym_points,
)

__all__ = ["DesignResult", "optimize"]

PENALTY = 100.0


@dataclass
class DesignResult:
    """The outcome of :func:`optimize`.

    Attributes
    ----------
    dimensions : dict
        Every dimension of the optimum (design variables, eliminated ones, constants).
    z : ndarray
        The free design variables.
    value : float
        The objective measure there.
    measures : dict
        Objective and constraint measures at the optimum.
    active : list of str
        Constraints within 1e-6 (relative) of their bound, and variables at a bound.
    verification : dict
        Each constraint re-evaluated on a denser set: ``{repr: {"value", "ok"}}``.
    evaluations : int
        Designs evaluated.
    history : list of (evaluations, best objective)
        For plotting the convergence.
    method : str
    mechanism : Mechanism
        The optimum as a mechanism.
    details : dict
        ``"objective"``: the objective's full result where it has one (the
        :class:`~optkin.design.Inscribed` shape: centre, contact, binding).
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"``; ``"infeasible"`` when no
        design satisfies every constraint (the least violating is returned),
        ``"inaccurate"`` when the denser verification or IPOPT's polish fails,
        ``"time_limit"`` at ``time_limit``, ``"iteration_limit"`` when the exchange step
        still finds violated points after ``rounds`` rounds.
    """

    dimensions: dict[str, float]
    z: np.ndarray
    value: float
    measures: dict[str, float]
    active: list[str]
    verification: dict[str, dict[str, Any]]
    evaluations: int
    history: list[tuple[int, float]]
    method: str
    mechanism: Any = None
    details: dict[str, Any] | None = None
    objective: str = ""
    free: tuple[str, ...] = ()
    time: float = 0.0
    success: bool = True
    status: str = "optimal"
    message: str = ""

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`; the mechanism left out)."""
        d = {k: v for k, v in self.__dict__.items() if k not in ("mechanism", "details")}
        d["details"] = dict(self.details or {})
        return jsonable(d)

    def __repr__(self) -> str:
        dims = ", ".join(f"{k}={v:.6g}" for k, v in self.dimensions.items()
                         if isinstance(v, float))
        return (f"DesignResult({dims}; value={self.value:.6g}, status={self.status!r}, "
                f"evaluations={self.evaluations})")

    def plot(self, path: str | None = None, ax: Any = None) -> Any:
        """The best objective against the designs evaluated."""
        import matplotlib.pyplot as plt

        from ..analysis.aspects import _save

        own = ax is None
        if own:
            fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=150)
        else:
            fig = ax.figure
        if self.history:
            h = np.array(self.history, dtype=float)
            ax.step(h[:, 0], h[:, 1], where="post", color="C0")
        ax.set_xlabel("designs evaluated")
        ax.set_ylabel(f"best {self.objective}")
        dims = ", ".join(f"{k} = {v:.4g}" for k, v in self.dimensions.items()
                         if isinstance(v, float) and k in dict(zip(self.free, self.z)))
        ax.set_title(f"design optimization: {self.objective} = {self.value:.5g}\n{dims}",
                     fontsize=9)
        ax.grid(alpha=0.3)
        if path is not None:
            _save(fig, path)
        return fig


def _family(family: Any, variables: Any, fixed: Any, equal: Any) -> Family:
    if isinstance(family, Family):
        if variables is not None or fixed or equal:
            raise MechanismError("give variables, fixed and equal either to Family(...) or to "
                                 "optimize(...), not both")
        return family
    if variables is None:
        raise MechanismError("variables: expected a mapping name -> (lo, hi)")
    return Family(family, variables, fixed, equal or ())


def _objective(objective: Any) -> tuple[Measure, float]:
    if isinstance(objective, (Maximize, Minimize)):
        if not isinstance(objective.measure, Measure):
            raise MechanismError(f"objective: expected a measure inside Maximize/Minimize, got "
                                 f"{show(objective.measure)}")
        return objective.measure, objective.sign
    raise MechanismError("objective: expected optkin.design.Maximize(measure) or "
                         f"Minimize(measure), got {show(objective)}")


def _constraints(constraints: Any) -> list[Constraint]:
    if isinstance(constraints, Constraint):
        constraints = [constraints]
    out = list(constraints or ())
    for i, c in enumerate(out):
        if not isinstance(c, Constraint):
            raise MechanismError(f"constraints[{i}]: expected a comparison of a measure with "
                                 f"a number (e.g. MinConditioning(disc) >= 0.5), got {show(c)}")
    return out


class _Counter:
    def __init__(self, fam: Family, meas: Measure, sign: float, cons: list[Constraint],
                 deadline: float) -> None:
        self.fam, self.meas, self.sign, self.cons = fam, meas, sign, cons
        self.n = 0
        self.best = np.inf
        self.best_z: np.ndarray | None = None
        self.history: list[tuple[int, float]] = []
        self.deadline = deadline

    def penalised(self, Z: np.ndarray, search: bool = False) -> np.ndarray:
        Z = np.atleast_2d(Z)
        self.n += len(Z)

        def val(m: Measure) -> np.ndarray:
            return m.search_values(self.fam, Z) if search else m.values(self.fam, Z)

        f = self.sign * val(self.meas)
        viol = self.fam.bound_violation(Z)
        for c in self.cons:
            viol = viol + c.violation(val(c.measure))
        f = np.where(np.isfinite(f), f, 1e6) + PENALTY * viol
        k = int(np.argmin(f))
        if f[k] < self.best:
            self.best, self.best_z = float(f[k]), Z[k].copy()
            # the objective measure itself (f = sign * value when feasible)
            self.history.append((self.n, float(self.sign * f[k]) if viol[k] == 0
                                 else float("nan")))
        return f


def _ipopt(fam: Family, meas: Measure, sign: float, cons: list[Constraint], z0: np.ndarray,
           rounds: int, deadline: float) -> tuple[np.ndarray, str, str, int]:
    """IPOPT from z0 with the exchange step (see the module docstring). Returns (z, status,
    message, rounds used)."""
    k = len(z0)
    z = ca.MX.sym("z", k)
    A, b = fam.full_affine()
    g_lin = ca.mtimes(ca.DM(A), z) + ca.DM(b)
    # node sets for the region constraints: the objective's region and each MinConditioning
    # (measure, gamma, working mode, [T blocks])
    regions: list[tuple[Any, float, tuple, list[np.ndarray]]] = []
    for c in cons:
        if isinstance(c.measure, MinConditioning) and c.sense == ">=":
            mode, T = c.measure.points(fam)
            regions.append((c.measure, c.bound, mode, [T]))
    if isinstance(meas, GCI):
        mode, T, _ = meas._setup(fam)
        regions.append((meas, 0.0, mode, [T]))
    # det A signs at the start design, per region
    signs = []
    for m_, _, mode, blocks in regions:
        o = fam_eval(fam, z0, blocks[0][:1], mode, m_.length)
        signs.append(float(np.sign(o["raw_det"][0])) or 1.0)
    status, message = "optimal", ""
    z_best = z0.copy()
    used = 0
    for used in range(1, rounds + 1):  # noqa: B007 (the count is returned)
        g, lbg, ubg = [g_lin], [fam.all_lower], [fam.all_upper]
        for c in cons:
            if isinstance(c.measure, MinConditioning):
                continue
            e = c.measure.symbolic(fam, z)
            g.append(e)
            lbg.append([c.bound if c.sense == ">=" else -np.inf])
            ubg.append([c.bound if c.sense == "<=" else np.inf])
        for (m_, gam, mode, blocks), s0 in zip(regions, signs):
            T = np.vstack(blocks)
            ik, det, reach = _sym_points(fam, T, mode, m_.length, z)
            n = T.shape[0]
            g += [ca.vec(reach), s0 * det.T]
            lbg += [np.full(reach.numel(), 1e-9), np.full(n, 0.0)]
            ubg += [np.full(reach.numel(), np.inf), np.full(n, np.inf)]
            if gam > 0:
                g.append(ik.T)
                lbg.append(np.full(n, gam))
                ubg.append(np.full(n, np.inf))
        f = sign * meas.symbolic(fam, z)
        left = max(1.0, deadline - time.perf_counter())
        solver = ca.nlpsol("design", "ipopt", {"x": z, "f": f, "g": ca.vertcat(*g)},
                           {"ipopt.print_level": 0, "print_time": False,
                            "ipopt.sb": "yes", "ipopt.max_cpu_time": left,
                            "ipopt.tol": 1e-10, "ipopt.max_iter": 500,
                            "ipopt.hessian_approximation": "limited-memory"})
        sol = solver(x0=z_best, lbx=fam.lower, ubx=fam.upper,
                     lbg=np.concatenate([np.ravel(v) for v in lbg]),
                     ubg=np.concatenate([np.ravel(v) for v in ubg]))
        st = solver.stats()
        z_new = np.array(sol["x"]).ravel()
        if not st["success"]:
            status, message = "inaccurate", f"IPOPT: {st['return_status']}"
            if not regions:
                z_best = z_new
            break
        z_best = z_new
        status, message = "optimal", ""
        # exchange: verify the region constraints on a denser set
        added = False
        for idx, (m_, gam, mode, blocks) in enumerate(regions):
            _, Td = m_.points(fam, dense=2)    # centre, nodes and boundary twice as dense
            o = fam_eval(fam, z_best, Td, mode, m_.length)
            bad = ~o["valid"] | (np.sign(o["raw_det"]) != signs[idx])
            if gam > 0:
                bad |= ~(o["inv_kappa"] >= gam - 1e-9)
            if bad.any():
                blocks.append(Td[bad])
                added = True
        if not added:
            break
        if time.perf_counter() > deadline:
            status, message = TIME_LIMIT, "time limit reached in the exchange step"
            break
    else:
        status, message = "iteration_limit", (f"the exchange step still found violated "
                                              f"points after {rounds} rounds")
    return z_best, status, message, used


def fam_eval(fam: Family, z: np.ndarray, T: np.ndarray, mode: Any, length: float
             ) -> dict[str, np.ndarray]:
    from .problem import _batch

    o = _batch(fam, np.atleast_2d(z), T, tuple(mode), length)
    return {k: v[0] for k, v in o.items()}


def optimize(family: Callable[..., Any] | Family, variables: Mapping[str, Any] | None = None,
             objective: Maximize | Minimize | None = None,
             constraints: Sequence[Constraint] | Constraint = (), *,
             fixed: Mapping[str, Any] | None = None,
             equal: Sequence[tuple[Mapping[str, float], float]] = (),
             method: str = "auto", seed: int = 0, popsize: int = 12, maxiter: int = 40,
             time_limit: float = 300.0, rounds: int = 6) -> DesignResult:
    """Choose a mechanism's dimensions: maximise or minimise a measure subject to
    constraints on measures (see the module docstring for the strategy).

    Parameters
    ----------
    family : callable or Family
        A function from named dimensions to a mechanism of one topology (a library factory
        such as ``optkin.mechanisms.five_bar``), or a :class:`Family`.
    variables : mapping name -> (lo, hi)
        The design variables and their bounds.
    objective : Maximize or Minimize
        Of a measure: :class:`GCI`, :class:`MinConditioning`, :class:`LargestInscribed`,
        :class:`AspectArea`, :class:`Dimension`.
    constraints : sequence of Constraint
        ``measure >= value`` or ``measure <= value``.
    fixed : mapping, optional
        Constant arguments of the family.
    equal : sequence of ({name: coefficient}, value), optional
        Linear equalities among the variables (a fixed sum, a ratio).
    method : {"auto", "global", "ipopt"}
        "auto": the global search, then IPOPT where everything is smooth (else
        Nelder-Mead); "global": the global search and Nelder-Mead; "ipopt": IPOPT from the
        centre of the bounds only.
    seed : int
    popsize, maxiter : int
        Differential evolution's population multiplier and generations.
    time_limit : float
        Seconds for the whole call (the search stops, the best design so far is returned
        with ``status="time_limit"``).
    rounds : int
        Exchange rounds of the IPOPT path.

    Returns
    -------
    DesignResult

    Examples
    --------
    >>> import optkin
    >>> from optkin import design
    >>> five = lambda a, b: optkin.mechanisms.five_bar(1.0, a, b, b, a)
    >>> r = design.optimize(five, {"a": (0.6, 1.4), "b": (0.6, 1.4)},
    ...                     design.Maximize(design.GCI(design.Disc((0.5, 1.0), 0.2), (1, -1))),
    ...                     [design.Dimension({"a": 1, "b": 1}) <= 2.0], maxiter=10)
    >>> r.success, r.dimensions["a"] + r.dimensions["b"] <= 2.0 + 1e-6
    (True, True)
    """
    from scipy.optimize import differential_evolution, minimize

    t0 = time.perf_counter()
    fam = _family(family, variables, fixed, equal)
    meas, sign = _objective(objective)
    cons = _constraints(constraints)
    if method not in ("auto", "global", "ipopt"):
        raise MechanismError(f"method: expected 'auto', 'global' or 'ipopt', got {show(method)}")
    seed = as_int(seed, "seed", lo=0)
    popsize = as_int(popsize, "popsize", lo=4, hi=1000)
    maxiter = as_int(maxiter, "maxiter", lo=1, hi=100000)
    time_limit = as_float(time_limit, "time_limit", lo=0.0)
    deadline = t0 + time_limit
    checkpoint()
    smooth = meas.smooth and all(c.measure.smooth for c in cons) and fam.affine
    ctr = _Counter(fam, meas, sign, cons, deadline)
    status, message, used = "optimal", "", "global"
    bounds = list(zip(fam.lower, fam.upper))
    timed_out = False
    if method in ("auto", "global"):
        def stop(*_a: Any, **_k: Any) -> bool:
            return time.perf_counter() > deadline

        differential_evolution(lambda X: ctr.penalised(X.T, search=True), bounds,
                               vectorized=True,
                               updating="deferred", seed=seed, popsize=popsize,
                               maxiter=maxiter, polish=False, tol=1e-8, callback=stop,
                               init="sobol" if len(bounds) > 1 else "latinhypercube")
        timed_out = time.perf_counter() > deadline
        z = ctr.best_z
        if z is not None:   # the search's estimate replaced by the exact value
            ctr.best = np.inf
            ctr.penalised(z[None])
    else:
        z = fam.centre()
        ctr.penalised(z[None])
    if z is None:
        z = fam.centre()
    if not timed_out and method in ("auto", "ipopt") and smooth:
        z_loc, st, msg, _ = _ipopt(fam, meas, sign, cons, np.asarray(z), rounds, deadline)
        f_glob = ctr.best
        f_loc = ctr.penalised(z_loc[None])[0]
        used = "global+ipopt" if method == "auto" else "ipopt"
        if method == "ipopt" or (f_loc <= f_glob + 1e-12 and st == "optimal"):
            z = z_loc
            if st != "optimal":
                status, message = st, msg
        elif st != "optimal":
            # the global search's design stands (verified below like any other)
            message = f"the IPOPT polish stopped ({msg}); the global search's design is kept"
            used = "global"
    elif not timed_out and method in ("auto", "global"):
        # Nelder-Mead from the global best, on the search's values (the measures' quick
        # estimates where they have them); the design it ends at is evaluated exactly
        span = fam.upper - fam.lower
        z_start = np.asarray(z, dtype=float)
        f_start = float(ctr.penalised(z_start[None], search=True)[0])

        def fz(v: np.ndarray) -> float:
            v = np.clip(v, fam.lower, fam.upper)
            if time.perf_counter() > deadline:
                return f_start
            return float(ctr.penalised(v[None], search=True)[0])

        simplex = np.vstack([z_start] + [z_start + 0.02 * span * np.eye(len(z_start))[i]
                                         for i in range(len(z_start))])
        res = minimize(fz, z_start, method="Nelder-Mead",
                       options={"initial_simplex": np.clip(simplex, fam.lower, fam.upper),
                                "xatol": 1e-4 * float(span.max()), "fatol": 1e-7,
                                "maxfev": 30 * len(z_start) + 20})
        zn = np.clip(res.x, fam.lower, fam.upper)
        z = zn if res.fun <= f_start else z_start
        used = "global+nelder-mead"
    if time.perf_counter() > deadline:
        status, message = TIME_LIMIT, f"time limit of {time_limit:g} s reached"
    z = np.asarray(z, dtype=float)
    details: dict[str, Any] = {}
    if hasattr(meas, "result"):
        details["objective"] = meas.result(fam, z)
        value = float(details["objective"].size)
    else:
        value = float(meas.values(fam, z[None])[0])
    measures = {repr(meas): value}
    active, verification = [], {}
    viol = float(fam.bound_violation(z))
    for c in cons:
        v = float(c.measure.values(fam, z[None])[0])
        measures[repr(c)] = v
        viol += float(c.violation(np.array([v]))[0])
        if abs(v - c.bound) <= 1e-6 * max(1.0, abs(c.bound)):
            active.append(repr(c))
        verification[repr(c)] = _verify(fam, c, z)
    for i, name in enumerate(fam.free):
        if min(z[i] - fam.lower[i], fam.upper[i] - z[i]) <= 1e-9 * (fam.upper[i] - fam.lower[i]):
            active.append(f"{name} at a bound")
    ok = viol <= 1e-6 and all(v["ok"] for v in verification.values())
    if viol > 1e-6:
        status = "infeasible"
        message = ("no design found satisfies every constraint (violation "
                   f"{viol:.3g}); the returned design is the least violating"
                   + (f" ({message})" if message else ""))
    elif not ok:
        bad = [k for k, v in verification.items() if not v["ok"]]
        status, message = "inaccurate", f"the denser verification fails for {bad}"
    elif not message:
        message = (f"{repr(meas)} = {value:.6g} at the design found by {used} "
                   f"({ctr.n} designs evaluated)")
    return DesignResult(dimensions=fam.dims(z), z=z, value=value, measures=measures,
                        active=active, verification=verification, evaluations=ctr.n,
                        history=ctr.history, method=used, mechanism=fam.mechanism(z),
                        details=details, objective=repr(meas), free=fam.free,
                        time=time.perf_counter() - t0, success=ok and status == "optimal",
                        status=status, message=message)


def _verify(fam: Family, c: Constraint, z: np.ndarray) -> dict[str, Any]:
    m = c.measure
    if isinstance(m, (MinConditioning, JointRange)):
        v = float(m.values(fam, z[None], dense=3)[0])
        how = "nodes 3x denser, with the boundary"
    elif isinstance(m, GCI):
        old = m.order
        m.order = 2 * old
        try:
            v = float(m.values(fam, z[None])[0])
        finally:
            m.order = old
        how = "quadrature of twice the order"
    elif hasattr(m, "lo") and hasattr(m, "n"):      # a box of poses
        v = float(m.values(fam, z[None], dense=2)[0])
        how = "grid of the box twice as fine"
    elif isinstance(m, Dimension):
        v = float(m.values(fam, z[None])[0])
        how = "exact"
    elif hasattr(m, "result"):
        v = float(m.result(fam, z, rays=256, steps=128).size)
        how = "256 rays, 128 steps"
    else:
        v = float(m.values(fam, z[None])[0])
        how = "re-evaluated"
    tol = 1e-6 * max(1.0, abs(c.bound))
    ok = bool(v >= c.bound - tol) if c.sense == ">=" else bool(v <= c.bound + tol)
    return {"value": v, "ok": ok, "how": how}

