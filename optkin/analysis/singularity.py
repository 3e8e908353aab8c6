"""Singularity classification at one configuration: :func:`classify`.

The verdicts, each with the smallest relevant singular value as its margin. The matrices
are first made dimensionless (length rows divided and length columns multiplied by the
mechanism's length scale); each margin is then relative to the 2-norm of a matrix that
does not vanish with it ([W_a W_p] for W_p, [A B] for A, the leg's row [A_i B_i] for B_ii,
[H; K_task] for H and for J1, H for H_p, K_task for the end-effector map). A verdict holds
when its margin is below ``rtol``.

===================== ======================================================================
``serial``            J1 of [7.60] singular: some qdot_a != 0 gives no end-effector motion.
                      Platforms whose unknowns are the platform coordinates: B
                      (Chablat-Wenger) singular - a leg at a PSIK/MSIK pose. Otherwise
                      (Khalil tables, legs in chain form): some M_a qdot_a lies in
                      range(M_p) for M = [H; K_task] = [M_a M_p] (the task rows of J_a lose
                      rank when W_p is regular).
``parallel``          J2 of [7.60] singular: the end effector moves with the actuators
                      locked. Platforms whose unknowns are the platform coordinates: A
                      singular (PSFK/MSFK); otherwise W_p singular with a null motion that
                      moves the end effector.
``internal``          W_p of [7.49] singular (Khalil & Dombre 2002, sec. 7.11): passive motion with
                      qdot_a = 0 (where W_p = dPhi/dx over the platform coordinates it
                      coincides with ``parallel``).
``configuration_space`` rank H < c, c the generic rank of the constraint Jacobian over all
                      joints (Modern Robotics 7.3; bifurcation points of the four-bar).
``actuator``          rank H_p < p (MR 7.3).
``actuator_degenerate`` an actuator singularity where the locked mechanism still moves at
                      second order: u^T d^2Phi/dx^2 [v, v] = 0 for the left/right null
                      vectors u, v of W_p (MR's degenerate case); otherwise non-degenerate.
``end_effector``      the end-effector task twist restricted to the tangent space null(H)
                      loses rank (MR 7.3, independent of the actuated joints).
===================== ======================================================================

Aliases of the slides (Özgören) are reported in ``aliases``: PSFK and MSFK for parallel,
PSIK and MSIK for serial (with the legs concerned), and the [7.60] case "both".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import numeric
from .._checks import check_option
from ..errors import NumericError
from ..mechanism import Mechanism
from ..model import Model, get_model
from ..model.analysis import analysis_functions, task_rows
from ..results import ERROR, OPTIMAL, jsonable
from .mobility import dof, rank_of, var_scale
from .velocity import Jacobians, jacobians, twist_rows

__all__ = ["SingularityReport", "classify", "CLASSIFY_DEFAULTS", "TYPES"]

TYPES = ("serial", "parallel", "internal", "configuration_space", "actuator",
         "actuator_degenerate", "end_effector")

#: Options of :func:`classify`.
CLASSIFY_DEFAULTS: dict[str, Any] = {
    "rtol": 1e-6,  # relative singular-value threshold of every first-order verdict
    "second_order_tol": 1e-6,  # |u^T Phi''[v, v]| below this: degenerate
}

#: Generic ranks kept per topology (one per geometry, most recent last)
_MAX_RANKS = 256


@dataclass
class SingularityReport:
    """Which singularities hold at a configuration (see :func:`classify`).

    Attributes
    ----------
    types : set of str
        Drawn from :data:`TYPES`; empty at a regular configuration.
    margins : dict
        Type -> the smallest relative singular value behind the verdict (the second-order
        coefficient for ``actuator_degenerate``; NaN when not evaluated).
    aliases : dict
        Slide names (Özgören) -> bool: PSFK, MSFK (= parallel), PSIK, MSIK (= serial), and
        "both" ([7.60] iii).
    legs_at_psik : tuple of int
        Legs (1-based) whose B_ii vanishes (PSIK(k) of the slides); platforms only.
    jacobians : Jacobians
        The velocity model the verdicts come from.
    success, status, message :
        As every result (:mod:`optkin.results`): the status of the velocity model
        (``"optimal"``; ``"infeasible"`` when q does not close the loops, the verdicts then
        holding for the matrices evaluated there), or ``"error"`` when the verdicts could
        not be computed (an undefined model, a failed decomposition).
    """

    types: set[str]
    margins: dict[str, float]
    aliases: dict[str, bool]
    rtol: float
    success: bool = True
    message: str = ""
    status: str = OPTIMAL
    legs_at_psik: tuple[int, ...] = ()
    null_motions: dict[str, np.ndarray] = field(default_factory=dict)
    jacobians: Jacobians | None = None

    @property
    def singular(self) -> bool:
        return bool(self.types)

    @property
    def names(self) -> set[str]:
        """Every name that holds: the types and the slide aliases."""
        return set(self.types) | {k for k, v in self.aliases.items() if v}

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def __repr__(self) -> str:
        t = ", ".join(sorted(self.types)) or "regular"
        if not self.success and not any(np.isfinite(v) for v in self.margins.values()):
            return "SingularityReport(undefined; NOT CLOSED)"
        if not self.success:  # the verdicts hold for a configuration that does not close
            t += "; NOT CLOSED"
        return f"SingularityReport({t})"

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({
            "types": sorted(self.types), "margins": self.margins,
            "aliases": dict(self.aliases), "rtol": self.rtol, "success": self.success,
            "status": self.status, "message": self.message,
            "legs_at_psik": list(self.legs_at_psik),
        })


def _rel_min(M: np.ndarray, k: int | None = None, ref: float | None = None
             ) -> tuple[float, np.ndarray, np.ndarray]:
    """(sigma_k / ref, U, Vt): the k-th singular value (default the last) relative to
    ``ref``, the 2-norm of a larger matrix that does not vanish with it (default M's)."""
    if M.size == 0:
        return float("inf"), np.zeros((M.shape[0], 0)), np.zeros((0, M.shape[1]))
    U, s, Vt = numeric.svd(M, "classify")
    n = min(M.shape) if k is None else k
    if n <= 0:
        return float("inf"), U, Vt
    ref = float(s[0]) if ref is None else float(ref)
    if ref <= 0:
        return 0.0, U, Vt
    return float(s[n - 1] / ref), U, Vt


def _generic_rank(model: Model) -> int:
    """c of [7.59] for the model's geometry (kept in its topology's cache); the intended
    count when no closure is found."""
    store: dict[bytes, int] = model.cached("generic_rank", dict)
    key = model.p.tobytes()
    c = store.get(key)
    if c is None:
        mech = model.mech
        rep = dof(mech, samples=3)
        c = rep.constraints if rep.success else analysis_functions(model).nvar - mech.dof
        while len(store) >= _MAX_RANKS:
            try:
                del store[next(iter(store))]
            except (KeyError, StopIteration, RuntimeError):  # another thread got there first
                break
        store[key] = c
    return c


def classify(mech: Mechanism, q: Any, **options: Any) -> SingularityReport:
    """Every singularity type that holds at the configuration ``q``.

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        All joint values (as ``KinResult.q``) or a solve result.
    **options
        ``rtol`` (default 1e-6): relative singular-value threshold; ``second_order_tol``
        (default 1e-6): threshold of the degenerate-actuator test. See
        :data:`CLASSIFY_DEFAULTS`.

    Returns
    -------
    SingularityReport

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = optkin.mechanisms.five_bar(1, 1.5, 1.5, 1, 1)
    >>> # P = (1, 2) is at distance L3 + L4 = 2 from B = (1, 0): leg 2 is stretched
    >>> r = optkin.inverse(m, [1.0, 2.0])
    >>> rep = optkin.classify(m, r[0])
    >>> sorted(rep.types)
    ['end_effector', 'serial']
    """
    from ..solvers.common import merge_options

    opts = merge_options(CLASSIFY_DEFAULTS, options, "classify")
    rtol, tol2 = (check_option(opts, k, "classify", CLASSIFY_DEFAULTS, lo=0.0, lo_open=True)
                  for k in ("rtol", "second_order_tol"))
    return classify_jacobians(mech, jacobians(mech, q), rtol, tol2)


def classify_jacobians(mech: Mechanism, jac: Jacobians,
                       rtol: float = CLASSIFY_DEFAULTS["rtol"],
                       tol2: float = CLASSIFY_DEFAULTS["second_order_tol"]) -> SingularityReport:
    """:func:`classify` from Jacobians already evaluated at the configuration (for callers
    that have them: :func:`optkin.singularity_map` evaluates them once a grid point)."""
    if not jac.info.get("defined", True):  # no numeric kernel sees the NaN of an undefined model
        return _undefined_report(jac, rtol, jac.message)
    try:
        return _classify(mech, jac, rtol, tol2)
    except NumericError as e:
        return _undefined_report(jac, rtol, f"the singularity tests failed at q: {e}")


def _undefined_report(jac: Jacobians, rtol: float, message: str) -> SingularityReport:
    """The report of a configuration where the verdicts cannot be computed."""
    return SingularityReport(
        types=set(), margins={t: float("nan") for t in TYPES},
        aliases={k: False for k in ("PSFK", "MSFK", "PSIK", "MSIK", "both", "type_1", "type_2")},
        rtol=rtol, success=False, message=message, status=ERROR, jacobians=jac)


def _classify(mech: Mechanism, jac: Jacobians, rtol: float, tol2: float) -> SingularityReport:
    model = get_model(mech)
    f = analysis_functions(model)
    L = model.length
    act = np.array(mech.actuated)
    types: set[str] = set()
    margins: dict[str, float] = {t: float("nan") for t in TYPES}
    nulls: dict[str, np.ndarray] = {}
    legs_psik: tuple[int, ...] = ()

    # scaling of the model-level matrices
    qa_scale = np.where(np.array(mech.revolute)[act], 1.0, L)
    rs = np.where(model.row_length, 1.0 / L, 1.0)
    _, Wp_m, Wa_m = (np.array(v) for v in model.jac(jac.qa, jac.x))
    Wp_s = rs[:, None] * Wp_m * model.x_scale[None, :]

    # joint-level H and K (scaled)
    vs = var_scale(model)
    Hs = np.where(f.row_length, 1.0 / L, 1.0)[:, None] * jac.H * vs[None, :]
    tw = twist_rows(model)
    trows = task_rows(model)
    krs = np.array([1.0 / L if i < 3 else 1.0 for i in trows])
    Ks = krs[:, None] * jac.K[trows] * vs[None, :]
    pas = np.ones(f.nvar, bool)
    pas[np.flatnonzero(act)] = False

    # internal: W_p of [7.49] (model level, all unknowns)
    Wa_s = rs[:, None] * Wa_m * qa_scale[None, :]
    ref_int = numeric.norm2(np.hstack([Wa_s, Wp_s]), "[W_a W_p]")
    m_int, U_int, Vt_int = _rel_min(Wp_s, ref=ref_int)
    margins["internal"] = m_int
    internal = m_int < rtol
    if internal:
        types.add("internal")
        nulls["internal"] = Vt_int[-1] * model.x_scale

    # parallel
    if jac.A is not None and jac.B is not None:
        legrows = np.flatnonzero(model.row_leg >= 0)
        E_scale = np.array([L if i < 3 else 1.0 for i in tw])
        ls = rs[legrows][:, None]
        A_s = (jac.A * ls) * E_scale[None, :]
        B_s = (jac.B * ls) * qa_scale[None, :]
        m_par, _, Vt_par = _rel_min(A_s, ref=numeric.norm2(np.hstack([A_s, B_s]), "[A B]"))
        margins["parallel"] = m_par
        if m_par < rtol:
            types.add("parallel")
            nulls["parallel"] = Vt_par[-1] * E_scale
        # serial: each leg's B_ii against its whole row [A_i, B_i]
        leg_m = []
        for i in range(B_s.shape[0]):
            row = np.concatenate([A_s[i], B_s[i]])
            nr = float(np.linalg.norm(row))
            leg_m.append(float(np.linalg.norm(B_s[i]) / nr) if nr > 0 else 0.0)
        margins["serial"] = float(min(leg_m)) if leg_m else float("inf")
        legs_psik = tuple(sorted({int(model.row_leg[legrows[i]]) + 1
                                  for i, v in enumerate(leg_m) if v < rtol}))
        if legs_psik:
            types.add("serial")
    else:
        margins["parallel"] = m_int
        if internal:
            sv = numeric.singular_values(Wp_s, "W_p")
            k = int(np.sum(sv < rtol * ref_int)) + (Wp_s.shape[1] - sv.size)
            V = Vt_int[-max(k, 1):]
            # the end-effector twist over the model's unknowns (scaled as Ks)
            Ka, Kx = (np.array(v) for v in f.twist(jac.qa, jac.x, model.p))
            Ka_s = krs[:, None] * Ka[trows] * qa_scale[None, :]
            Kx_s = krs[:, None] * Kx[trows] * model.x_scale[None, :]
            ref_k = numeric.norm2(np.hstack([Ka_s, Kx_s]), "K")
            move = numeric.norm2(Kx_s @ V.T, "K V") / max(ref_k, 1e-300)
            if move > np.sqrt(rtol):
                types.add("parallel")
        # serial: J1 of [7.60]. With M = [H; K_task] split into active columns M_a and
        # passive ones M_p, some qdot_a != 0 leaves the end effector still iff M_a qdot_a
        # lies in range(M_p), i.e. iff (I - Q Q^T) M_a loses column rank (Q an orthonormal
        # basis of range(M_p)). Where W_p is regular this is the rank of J_a's task rows.
        M = np.vstack([Hs, Ks])
        Ma, Mp = M[:, ~pas], M[:, pas]
        U, sp, _ = numeric.svd(Mp, "M_p", full_matrices=False)
        Q = U[:, : rank_of(sp, rtol)]
        Rm = Ma - Q @ (Q.T @ Ma)
        sR = numeric.singular_values(Rm, "J1")
        s1 = numeric.norm2(M, "[H; K]")
        margins["serial"] = float(sR[-1] / s1) if s1 > 0 and sR.size else 0.0
        if sR.size < Ma.shape[1] or margins["serial"] < rtol:
            types.add("serial")
            nulls["serial"] = numeric.svd(Rm, "J1")[2][-1] * qa_scale

    # Modern Robotics: configuration space, actuator, end effector
    c = _generic_rank(model)
    m_cs, _, _ = _rel_min(Hs, c, ref=numeric.norm2(np.vstack([Hs, Ks]), "[H; K]"))
    margins["configuration_space"] = m_cs
    if m_cs < rtol:
        types.add("configuration_space")
    Hp_s = Hs[:, pas]
    r = min(int(pas.sum()), c)
    m_act, _, _ = _rel_min(Hp_s, r, ref=numeric.norm2(Hs, "H"))
    margins["actuator"] = m_act
    actuator = m_act < rtol
    if actuator:
        types.add("actuator")
        deg, q2 = _degenerate(jac, model, f, Wp_s, rs, rtol * ref_int, tol2)
        margins["actuator_degenerate"] = q2
        if deg:
            types.add("actuator_degenerate")
    # end effector: task twist on the tangent space (generic dimension nvar - c)
    _, _, Vt_h = numeric.svd(Hs, "H")
    T = Vt_h[c:].T
    m_ee, _, Vt_ee = _rel_min(Ks @ T, ref=numeric.norm2(Ks, "K"))
    margins["end_effector"] = m_ee
    if m_ee < rtol:
        types.add("end_effector")

    par = "parallel" in types
    ser = "serial" in types
    aliases = {"PSFK": par, "MSFK": par, "PSIK": ser, "MSIK": ser, "both": par and ser,
               "type_1": ser, "type_2": par}
    verdict = (f"singular: {', '.join(sorted(types))}" if types else
               f"regular: no singularity at rtol {rtol:g}")
    msg = f"{verdict}; {jac.message}" if jac.message else verdict
    return SingularityReport(types=types, margins=margins, aliases=aliases, rtol=rtol,
                             success=jac.success, message=msg, status=jac.status,
                             legs_at_psik=legs_psik,
                             null_motions=nulls, jacobians=jac)


def _degenerate(jac: Jacobians, model: Any, f: Any, Wp_s: np.ndarray, rs: np.ndarray,
                atol: float, tol2: float) -> tuple[bool, float]:
    """Second-order test at an actuator singularity with the actuators locked.

    With u_j the left and V the right null vectors of W_p (scaled), the locked mechanism can
    follow x(s) = x + s v + s^2/2 w only if u_j^T Phi''[v, v] = 0 for every j; a real
    v != 0 in span(V) solving these quadratics means a degenerate singularity.
    """
    if Wp_s.size == 0:
        return False, float("nan")
    U, s, Vt = numeric.svd(Wp_s, "W_p")
    small = int(np.sum(s < atol))
    # at least one direction: this runs only at an actuator singularity (H_p rank-deficient)
    k_r = max(1, small + (Wp_s.shape[1] - s.size))
    k_l = max(1, small + (Wp_s.shape[0] - s.size))
    V = Vt[-k_r:].T  # scaled x directions
    Ul = U[:, -k_l:]
    Ms = []
    for j in range(k_l):
        u = rs * Ul[:, j]  # weights on the unscaled rows
        Hx = np.array(f.hess_x(jac.qa, jac.x, u, model.p))
        Dv = model.x_scale[:, None] * V
        Ms.append(Dv.T @ Hx @ Dv)
    if not all(np.isfinite(M).all() for M in Ms):  # second derivatives overflow: no verdict
        return False, float("nan")
    if k_r == 1:
        q2 = float(max(abs(M[0, 0]) for M in Ms))
        return q2 < tol2, q2
    # several null directions: minimise sum_j (v^T M_j v)^2 on the unit sphere
    from scipy.optimize import minimize

    def obj(v):
        v = v / np.linalg.norm(v)
        with np.errstate(over="ignore", invalid="ignore"):
            return float(sum(np.square(v @ M @ v) for M in Ms))

    rng = np.random.default_rng(0)
    best = min(minimize(obj, rng.normal(size=k_r), method="Nelder-Mead",
                        options={"xatol": 1e-12, "fatol": 1e-20}).fun for _ in range(8))
    q2 = float(np.sqrt(best))
    return q2 < tol2, q2
