"""Velocity and acceleration models of closed chains: :func:`jacobians`.

Khalil mechanisms (Khalil & Dombre 2002, sec. 7.8): the kinematic constraint equation [7.49]

    [W_a  W_p  0  ] [qdot_a]
    [W_ac W_pc W_c] [qdot_p] = 0,      qdot_p = -W_p^-1 W_a qdot_a = W qdot_a   [7.51]
                    [qdot_c]

obtained by automatic differentiation of the model's independent closure rows (position of
R_{k+B} in R_k and the Gibbs vector of their relative rotation, [7.8]). At a closed
configuration the position and the x/y rotation rows of a loop do not depend on the
velocity of a revolute cut joint (its frame origin and z axis do not move with it), so
the rows split into the two block rows of [7.49] exactly as in Example 7.8 (ii).

Leg-described platforms (Chablat & Wenger 1998): where the model's unknowns are the platform
coordinates (every leg in its reduced form), the model rows f_i(q_a, x) = |P_i(x) -
C_i(q_a,i)| - l_i give Chablat and Wenger's A t + B qdot_a = 0 with A = (df/dx) E(x) (E
maps the platform twist t to coordinate rates x_dot) and B = df/dq_a diagonal. Legs in
their chain form add their passive joints to the unknowns; the velocity model is then
[7.49] without cut joints. H_a, H_p of Modern Robotics (7.13) come from the joint-level
closure (each leg chain reaches the platform), with the platform coordinates as extra
passive coordinates.

Every matrix comes from the model's interface (:mod:`optkin.model.analysis`): the split of
[7.49] follows the cut joints the model has, whatever the description.

The end-effector twist is t = (v, omega): the velocity of the end-effector frame origin and
the angular velocity, both in base coordinates (Khalil's [7.44] ordering). For planar
platforms t = (vx, vy, omega_z), for point platforms (vx, vy), for translational ones
(vx, vy, vz). ``J_s`` is Modern Robotics' spatial twist (omega_s, v_s) Jacobian.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import numeric
from .._checks import as_vector, check_mechanism, check_option
from .._checks import show as _show
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import Model, get_model
from ..model.analysis import analysis_functions, leg_labels, platform_unknowns_only, task_rows, z_of
from ..model.analysis import twist_rows as _twist_rows
from ..results import INFEASIBLE, OPTIMAL, SINGULAR, KinResult, jsonable

__all__ = ["Jacobians", "jacobians", "JACOBIANS_DEFAULTS", "config_of", "twist_rows",
           "TWIST_NAMES"]

#: Options of :func:`jacobians`.
JACOBIANS_DEFAULTS: dict[str, Any] = {
    "tol": 1e-8,  # largest closure residual max|Phi| (model units) for success
}

TWIST_NAMES = ("vx", "vy", "vz", "wx", "wy", "wz")


def twist_rows(mech: Mechanism | Model) -> list[int]:
    """Which of (vx, vy, vz, wx, wy, wz) the end-effector twist of ``mech`` keeps."""
    return _twist_rows(mech if isinstance(mech, Model) else get_model(mech))


def config_of(mech: Mechanism, q: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, q_a, x) from a full joint vector or a :class:`KinResult`."""
    model = get_model(mech)
    nq = len(mech.joint_names)
    act = np.array(mech.actuated)
    if isinstance(q, KinResult):
        from ..solvers.common import check_result_of

        check_result_of(mech, q, "q")
        qv = np.asarray(q.q, dtype=float)
        x = np.asarray(q.x, dtype=float)
        if qv.shape != (nq,) or not np.all(np.isfinite(qv)) or not np.all(np.isfinite(x)):
            raise MechanismError(
                "q: the KinResult has no complete joint vector (failed solve?); pass a "
                "successful result or all joint values", path=("q",)
            )
        return qv, qv[act], x
    try:
        shape = np.shape(q)
    except (TypeError, ValueError, RecursionError):
        shape = None
    if shape is not None and len(shape) >= 1 and shape != (nq,):
        raise MechanismError(
            f"q: expected all {nq} joint values {list(mech.joint_names)} (as in KinResult.q), "
            f"got shape {shape}", path=("q",)
        )
    try:  # any finite value: where the model overflows the result says success=False
        qv = as_vector(q, "q", nq, names=mech.joint_names, path=("q",), max_abs=np.inf)
    except MechanismError as e:
        if "non-finite" in str(e):
            raise MechanismError(f"q: has non-finite entries ({str(e).split(': ', 1)[1]}); give "
                                 "a closed configuration", path=e.path) from None
        raise MechanismError(f"q: expected {nq} joint values or a KinResult ({str(e)[3:]})",
                             path=("q",)) from None
    with np.errstate(all="ignore"):
        x = model.x_from_q(qv)
    return qv, qv[act], x


def _solve(M: np.ndarray, R: np.ndarray) -> np.ndarray:
    """M^-1 R for square regular M, else the least-squares / minimum-norm solution; NaN
    (without calling LAPACK) where M or R is not finite (the model undefined there)."""
    if M.shape[0] == 0 or M.shape[1] == 0:
        return np.zeros((M.shape[1],) + R.shape[1:])
    if not (np.isfinite(M).all() and np.isfinite(R).all()):
        return np.full((M.shape[1],) + R.shape[1:], np.nan)
    try:
        return numeric.solve(M, R, "W_p")
    except MechanismError:  # numeric.NumericError: no convergence or overflow
        return np.full((M.shape[1],) + R.shape[1:], np.nan)


@dataclass
class Jacobians:
    """Velocity model of a closed chain at one configuration (see :func:`jacobians`).

    Attributes
    ----------
    W_a, W_p, W_ac, W_pc, W_c : ndarray
        The blocks of [7.49] (columns q_a / q_p / q_c in joint order). Without cut joints
        (platforms) W_a, W_p are the model's dPhi/dq_a and dPhi/dx over its unknowns (the
        platform coordinates, then the passive joints of legs in chain form), and W_ac,
        W_pc, W_c are empty.
    W : ndarray
        -W_p^-1 W_a [7.51]: qdot_p (Khalil) or x_dot (platforms) per unit qdot_a.
    W_x : ndarray
        Rates of all the model's unknowns x (passive and cut joints; platform coordinates).
    H, H_a, H_p : ndarray
        Modern Robotics (7.13): the constraint Jacobian over all joints, split into the
        actuated and passive columns (passive = every non-actuated joint, in joint order;
        platforms: passive leg joints, then the platform coordinates).
    J_a : ndarray
        End-effector twist per unit qdot_a (MR (7.21)), rows ``twist_names``.
    J_s : ndarray
        The same as a spatial twist (omega_s, v_s) of Modern Robotics (6 rows).
    A, B : ndarray or None
        Chablat and Wenger: A t + B qdot_a = 0 (platforms whose model unknowns are the
        platform coordinates; None otherwise).
    G_statics : ndarray or None
        Stewart-Gough inverse Jacobian from statics (MR 7.2.1): qdot_a = G_statics V_s with
        V_s = (omega_s, v_s); spatial platforms whose legs are length-actuated distances
        only.
    K : ndarray
        End-effector twist Jacobian over all joint variables (``var_names``).
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"`` when q closes the loops;
        ``"infeasible"`` when it does not (the matrices are evaluated there anyway);
        ``"singular"`` when the model is undefined at q (e.g. a zero-length leg).
    """

    mech: Mechanism
    q: np.ndarray
    qa: np.ndarray
    x: np.ndarray
    success: bool
    status: str
    message: str
    residual: float
    W_a: np.ndarray
    W_p: np.ndarray
    W_ac: np.ndarray
    W_pc: np.ndarray
    W_c: np.ndarray
    W: np.ndarray
    W_x: np.ndarray
    H: np.ndarray
    H_a: np.ndarray
    H_p: np.ndarray
    J_a: np.ndarray
    J_s: np.ndarray
    K: np.ndarray
    A: np.ndarray | None = None
    B: np.ndarray | None = None
    G_statics: np.ndarray | None = None
    twist_names: tuple[str, ...] = ()
    row_names: tuple[str, ...] = ()
    var_names: tuple[str, ...] = ()
    qa_names: tuple[str, ...] = ()
    qp_names: tuple[str, ...] = ()
    qc_names: tuple[str, ...] = ()
    x_names: tuple[str, ...] = ()
    info: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------------ aliases
    @property
    def J(self) -> np.ndarray:
        """The full kinematic constraint matrix of [7.48]/[7.49], columns (q_a, q_p, q_c)."""
        top = np.hstack([self.W_a, self.W_p, np.zeros((self.W_a.shape[0], self.W_c.shape[1]))])
        bot = np.hstack([self.W_ac, self.W_pc, self.W_c])
        return np.vstack([top, bot])

    @property
    def J_task(self) -> np.ndarray:
        """Rows of J_a for the task components of the mechanism (``mech.task``)."""
        rows = self.info.get("task_rows")
        if rows is None:
            return self.J_a
        return self.J_a[[self.twist_names.index(TWIST_NAMES[i]) for i in rows]]

    # ------------------------------------------------------------------ rates
    def passive_rates(self, qa_dot: Any) -> np.ndarray:
        """qdot_p = W qdot_a [7.51] (platforms: the platform coordinate rates x_dot)."""
        return self.W @ _rates("qa_dot", qa_dot, self.mech.active_names)

    def x_rates(self, qa_dot: Any) -> np.ndarray:
        """Rates of the model's unknowns x for given active rates."""
        return self.W_x @ _rates("qa_dot", qa_dot, self.mech.active_names)

    def joint_rates(self, qa_dot: Any) -> np.ndarray:
        """All joint rates (``mech.joint_names`` order) for given active rates."""
        qa_dot = _rates("qa_dot", qa_dot, self.mech.active_names)
        act = np.array(self.mech.actuated)
        npas = int((~act).sum())
        yp = _solve(self.H_p, -self.H_a @ qa_dot)
        out = np.empty(act.size)
        out[act] = qa_dot
        out[~act] = yp[:npas]
        return out

    def twist(self, qa_dot: Any) -> np.ndarray:
        """End-effector twist J_a qdot_a (rows ``twist_names``)."""
        return self.J_a @ _rates("qa_dot", qa_dot, self.mech.active_names)

    def accel_term(self, qa_dot: Any = None, qdot: Any = None) -> tuple[np.ndarray, np.ndarray]:
        """(Psi, Phi) of [7.52]: (dJ/dt) qdot, by automatic differentiation.

        Give either the active rates ``qa_dot`` (the other rates follow from [7.49]) or,
        where the model's unknowns are joints (Khalil mechanisms), all joint rates
        ``qdot`` (``mech.joint_names`` order). Rows in the order of [7.49] (top block Psi,
        bottom block Phi, the rows involving cut joints); without cut joints (platforms)
        Psi is the model rows' second derivative at zero accelerations and Phi is empty.
        """
        model = get_model(self.mech)
        f = analysis_functions(model)
        nq = len(self.mech.joint_names)
        act = np.array(self.mech.actuated)
        if qdot is not None:
            if np.any(f.z_x >= nq):
                raise MechanismError("accel_term: give qa_dot (the active rates) for a "
                                     "platform: its unknowns are not all joints")
            qd = _rates("qdot", qdot, self.mech.joint_names)
            qa_dot, xd = qd[act], qd[f.z_x]
        elif qa_dot is not None:
            qa_dot = _rates("qa_dot", qa_dot, self.mech.active_names)
            xd = self.W_x @ qa_dot
        else:
            raise MechanismError("accel_term: give qa_dot or qdot")
        a = np.array(f.acc_x(self.qa, self.x, qa_dot, xd, model.p)).ravel()
        top, bot = self.info["rows_top"], self.info["rows_bottom"]
        return a[top], a[bot]

    def passive_accelerations(self, qa_dot: Any, qa_ddot: Any) -> np.ndarray:
        """x_ddot (all unknowns of the model) for active rates and accelerations [7.52]."""
        model = get_model(self.mech)
        f = analysis_functions(model)
        qa_dot = _rates("qa_dot", qa_dot, self.mech.active_names)
        qa_ddot = _rates("qa_ddot", qa_ddot, self.mech.active_names)
        _, Wp, Wa = (np.array(v) for v in model.jac(self.qa, self.x))
        xd = self.W_x @ qa_dot
        a = np.array(f.acc_x(self.qa, self.x, qa_dot, xd, model.p)).ravel()
        return _solve(Wp, -(Wa @ qa_ddot) - a)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"success": bool(self.success), "status": self.status,
                               "message": self.message, "residual": float(self.residual)}
        for k in ("q", "qa", "x", "W_a", "W_p", "W_ac", "W_pc", "W_c", "W", "W_x", "H_a", "H_p",
                  "J_a", "J_s", "A", "B", "G_statics"):
            v = getattr(self, k)
            out[k] = None if v is None else np.asarray(v).tolist()
        for k in ("twist_names", "row_names", "qa_names", "qp_names", "qc_names", "x_names"):
            out[k] = list(getattr(self, k))
        return jsonable(out)  # NaN / inf entries (unclosed or singular q) -> None

    def __repr__(self) -> str:
        flag = "ok" if self.success else "NOT CLOSED"
        return (f"Jacobians({self.mech.name!r}, {flag}, W_p {self.W_p.shape}, "
                f"J_a {self.J_a.shape}, cond(W_p)={self.info.get('cond_W_p', np.nan):.3g})")


def _spatial_from_twist(J6: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(v, omega) at the origin of the frame at p -> Modern Robotics (omega_s, v_s)."""
    v, w = J6[:3], J6[3:]
    vs = v - np.cross(w.T, p).T  # v_s = v - omega x p = v + p x omega
    return np.vstack([w, vs])


def jacobians(mech: Mechanism, q: Any, **options: Any) -> Jacobians:
    """Velocity model of ``mech`` at the closed configuration ``q``.

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        All joint values (``mech.joint_names`` order, as ``KinResult.q``) or a result of
        :func:`optkin.forward` / :func:`optkin.inverse`.
    **options
        The options below, by keyword, over :data:`JACOBIANS_DEFAULTS` (an unknown name is a
        :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    tol : float
        Largest closure residual max|Phi| (in the model's units) for ``success``
        (default 1e-8).

    Returns
    -------
    Jacobians
        ``success=False`` (with a message) when q does not close the loops; the matrices
        are then evaluated anyway. Where the model itself is undefined (a prismatic leg of
        zero length has no direction) ``success=False``, ``status="singular"``,
        ``info["defined"]`` is False and the matrices that depend on it are NaN; no numeric
        kernel is called with them.

    Examples
    --------
    >>> import numpy as np, optkin
    >>> m = optkin.mechanisms.sr400()
    >>> r = optkin.forward(m, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    >>> jac = optkin.jacobians(m, r)
    >>> np.round(jac.W @ [0, 1, 0, 0, 0, 0], 12).tolist()   # [7.41]: theta3dot = -theta2dot
    [-1.0, 1.0]
    """
    from ..solvers.common import merge_options

    opts = merge_options(JACOBIANS_DEFAULTS, options, "jacobians")
    tol = check_option(opts, "tol", "jacobians", JACOBIANS_DEFAULTS, lo=0.0, lo_open=True)
    check_mechanism(mech, "jacobians")
    model = get_model(mech)
    f = analysis_functions(model)
    qv, qa, x = config_of(mech, q)
    checkpoint()  # validation stops here: every argument is checked
    phi_m, Wp_m, Wa_m = (np.array(v) for v in model.jac(qa, x))
    defined = bool(np.isfinite(phi_m).all() and np.isfinite(Wp_m).all()
                   and np.isfinite(Wa_m).all())
    res = float(np.max(np.abs(phi_m))) if phi_m.size else 0.0
    ok = res <= tol and defined
    msg = "" if ok else (
        f"q does not close the loops (max |Phi| = {res:.2e} > tol {tol:g}); the matrices are "
        "evaluated there anyway; solve with optkin.forward first"
    )
    if not defined:
        msg = _undefined_message(model, phi_m, Wp_m, Wa_m)
    W_x = _solve(Wp_m, -Wa_m)
    act = np.array(mech.actuated)
    nq = qv.size
    tw = _twist_rows(model)
    info: dict[str, Any] = {"defined": defined, "nq": nq, "task_rows": task_rows(model)}
    try:
        info["cond_W_p"] = numeric.cond(Wp_m, "W_p") if Wp_m.size else 1.0
    except MechanismError:  # not finite: the model is undefined at q
        info["cond_W_p"] = float("nan")
    # [7.49]: the unknowns split into the tree's passive joints and the cut joints, the
    # rows into those that do not involve a cut joint's rate (top) and those that do
    cut_x = np.isin(f.z_x, model.qc_index) if model.qc_index.size else np.zeros(x.size, bool)
    Wc_cols = Wp_m[:, cut_x]
    scale = max(1.0, float(np.abs(np.hstack([Wa_m, Wp_m])).max())) if Wp_m.size or Wa_m.size \
        else 1.0
    if not np.isfinite(scale):
        scale = 1.0
    has_c = np.any(np.abs(Wc_cols) > 1e-7 * scale, axis=1) if cut_x.any() else \
        np.zeros(Wp_m.shape[0], bool)
    top, bot = np.flatnonzero(~has_c), np.flatnonzero(has_c)
    info["split"] = "rows"
    W_a, W_p = Wa_m[top], Wp_m[np.ix_(top, np.flatnonzero(~cut_x))]
    W_ac = Wa_m[bot]
    W_pc = Wp_m[np.ix_(bot, np.flatnonzero(~cut_x))]
    W_c = Wp_m[np.ix_(bot, np.flatnonzero(cut_x))]
    if bot.size != int(cut_x.sum()):
        info["split"] = "inexact"
        msg = (msg + "; " if msg else "") + (
            f"{bot.size} closure rows involve the {int(cut_x.sum())} cut joint(s): the [7.49] "
            "split is not square here")
    info["rows_top"], info["rows_bottom"] = top, bot
    W = W_x if not cut_x.any() else (
        _solve(W_p, -W_a) if W_p.size else np.zeros((0, qa.size)))
    # Modern Robotics (7.13): the joint-level closure over every joint (and the platform)
    z = z_of(model, qv, x)
    _, H, K = (np.array(v) for v in f.rows_q(z, model.p))
    pas = np.ones(f.nvar, bool)
    pas[np.flatnonzero(act)] = False
    H_a = H[:, ~pas]
    H_p = H[:, pas]
    # the end-effector twist per unit qdot_a through the unknowns: K_a + K_x W_x
    Ka, Kx = (np.array(v) for v in f.twist(qa, x, model.p))
    J6 = Ka + Kx @ W_x
    T = model.pose(qa, x)
    J_a = J6[tw]
    rows = np.concatenate([top, bot])
    row_names = tuple(model.row_names[i] for i in rows)
    A = B = None
    if platform_unknowns_only(model):
        # Chablat-Wenger: A t + B qdot_a = 0 on the leg rows (quaternion norm row dropped)
        legrows = np.flatnonzero(model.row_leg >= 0)
        E = model.platform.xdot_of_twist(x[: model.n_platform])
        A = Wp_m[legrows] @ E
        B = Wa_m[legrows]
    J_s = _spatial_from_twist(J6, T[:3, 3])
    G = stewart_gough_statics(model, qa, T)
    if defined and not all(np.isfinite(a).all() for a in (H, K, J_a)):
        defined = info["defined"] = ok = False
        msg = "the velocity model is not finite at q (values too large?); it is undefined there"
    status = OPTIMAL if ok else (SINGULAR if not defined else INFEASIBLE)
    if ok and not msg:
        msg = (f"q closes the loops (max |Phi| = {res:.2e}); cond W_p = "
               f"{info['cond_W_p']:.3g}")
    elif ok:
        msg = f"q closes the loops (max |Phi| = {res:.2e}); {msg}"
    return Jacobians(
        mech=mech, q=qv, qa=qa, x=x, success=ok, status=status,
        message=msg, residual=res, W_a=W_a, W_p=W_p, W_ac=W_ac, W_pc=W_pc, W_c=W_c, W=W,
        W_x=W_x, H=H, H_a=H_a, H_p=H_p, J_a=J_a, J_s=J_s, K=K, A=A, B=B, G_statics=G,
        twist_names=tuple(TWIST_NAMES[i] for i in tw), row_names=row_names,
        var_names=f.var_names, qa_names=tuple(mech.active_names),
        qp_names=tuple(mech.passive_names), qc_names=tuple(mech.cut_names),
        x_names=tuple(model.x_names), info=info,
    )


def stewart_gough_statics(model: Model, qa: np.ndarray, T: np.ndarray) -> np.ndarray | None:
    """The inverse Jacobian of a Stewart-Gough platform by statics (MR 7.2.1).

    Row i is (-n_i x q_i, n_i)^T, with n_i the unit vector along leg i (from the base joint
    q_i to the platform joint) and q_i the base joint centre, so that qdot_a = G V_s for
    the spatial twist V_s = (omega_s, v_s) (J_s^-1 of MR). Defined for spatial platforms
    that turn, whose legs are all distances actuated in length (the model's distance form
    with fixed centres); None otherwise.
    """
    plat = model.platform
    if plat is None or not plat.rotates or plat.space_dim != 3:
        return None
    df = model.distance_form()
    if df is None or not np.all(df.length_actuated):
        return None
    C, _ = df.centres_radii(qa)
    R, p = T[:3, :3], T[:3, 3]
    rows = []
    for qi, b in zip(C[0], df.platform_points):
        Pi = p + R @ b
        d = float(np.linalg.norm(Pi - qi))
        n = (Pi - qi) / d if d > 0 else np.full(3, np.nan)  # a leg of zero length: undefined
        rows.append(np.concatenate([-np.cross(n, qi), n]))
    return np.array(rows)


def _rates(name: str, v: Any, names: Any) -> np.ndarray:
    """Joint rates as a float vector of one entry per name, else a MechanismError."""
    try:
        return as_vector(v, name, len(names), path=(name,))
    except MechanismError:
        raise MechanismError(
            f"{name}: expected {len(names)} finite rates, one per joint {list(names)}, got "
            f"{_show(v)}", path=(name,)) from None


def _undefined_message(model: Model, phi: np.ndarray, Wp: np.ndarray, Wa: np.ndarray) -> str:
    """Why the model rows or their Jacobian are not finite at a configuration."""
    bad = ~(np.isfinite(phi.ravel()) & np.isfinite(Wp).all(axis=1) & np.isfinite(Wa).all(axis=1))
    rows = [model.row_names[i] for i in np.flatnonzero(bad)]
    if not np.isfinite(phi).all():
        return (f"the model overflows at q (the closure rows {rows} are not finite): the joint "
                "values are far beyond the mechanism's size; give a closed configuration")
    legs = sorted({int(model.row_leg[i]) for i in np.flatnonzero(bad) if model.row_leg[i] >= 0})
    if legs:
        labels = leg_labels(model)
        which = ", ".join(f"leg {k + 1} ({labels[k]})" for k in legs)
        return (f"the velocity model is undefined at q: {which} has zero length there (its "
                "platform point is on its base point), so its direction is undefined; give a "
                "configuration with every leg of positive length")
    return (f"the velocity model is undefined at q: the closure rows {rows} or their "
            "derivatives are not finite there")
