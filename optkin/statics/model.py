"""The static model of a closed chain at one configuration (numpy, from the CasADi model).

Derivation and sign convention
------------------------------
Every mechanism is written at a configuration as one linear velocity constraint

    A t + B qa_dot + P qp_dot = 0                                               (1)

between the end-effector twist ``t``, the actuated joint rates ``qa_dot`` and the rates of
the remaining unknowns ``qp_dot`` (passive and cut joints):

* fully parallel platforms (one distance row and one actuator per leg, see
  :attr:`optkin.model.Model.fully_parallel`): the closure f_i(x, q_a,i) = |P_i(x) -
  C_i(q_a,i)| - l_i = 0 differentiates to Chablat and Wenger's A t + B qa_dot = 0 (seed
  004), with A = W_p written in twist coordinates and B = W_a diagonal; P is empty (the
  passive leg joints were eliminated leg by leg). Planar platforms: x = (x, y, phi) so
  t = (vx, vy, wz) = x_dot. Spatial platforms: x = (p, quaternion), and the quaternion
  rate of a base-frame angular velocity w is quat_dot = 1/2 (0, w) * quat, so A = W_p [I 0;
  0 1/2 E(quat)] (the row of the quaternion norm vanishes on these motions and is dropped).
* every other mechanism (Khalil tables, Khalil & Dombre 2002, sec. 7.5-7.7; legs in chain form): the task
  rows t - J_a qa_dot - J_x x_dot = 0 (J the twist Jacobian of the end-effector frame)
  stacked over the closure W_a qa_dot + W_p x_dot = 0 [7.49], i.e. A = [I; 0],
  B = [-J_a; W_a], P = [-J_x; W_p].

Both forms come from the model (:mod:`optkin.model.statics`).

Let ``F`` be the wrench the end effector APPLIES TO THE ENVIRONMENT (Modern Robotics 5.2 and
7.2: "the wrench applied by the end-effector"), written in the base frame with moments
about the end-effector point (planar: (fx, fy, mz); spatial: (fx, fy, fz, mx, my, mz)), and
``tau`` the actuator forces/torques (a positive leg force extends the leg). With massless
links and frictionless passive joints, the principle of virtual work says that the power
the actuators put in is the power the end effector delivers, for every motion allowed by
(1) with the passive joints doing no work:

    tau . qa_dot = F . t     for all (t, qa_dot, qp_dot) with A t + B qa_dot + P qp_dot = 0.

So (F, -tau, 0) is orthogonal to the kernel of [A B P], i.e. lies in the range of its
transpose: there are multipliers lambda (one per constraint row: the leg forces, the
constraint forces of the loops) with

    F = A^T lambda,    tau = -B^T lambda,    P^T lambda = 0.                     (2)

For an n-RPR platform B = -I, so tau = lambda and F = sum_i tau_i [u_i; r_i x u_i] with u_i
the unit vector from the base joint to the platform joint and r_i the platform joint
relative to the end-effector point: the familiar "F = J^-T tau". When B is invertible (no
serial singularity) and P = 0, F = G tau with G = -A^T B^-T = J_inv^T, where qa_dot =
J_inv t is the inverse velocity model, and for a non-redundant, non-singular mechanism
tau = J^T F with t = J qa_dot (MR 7.2.2). The LOAD the mechanism resists (gravity, a
contact force acting on the platform) is W_ext = -F: with symmetric actuator limits the
sets of achievable F and of resisted W_ext coincide; with asymmetric limits ``(lo, hi)``
(e.g. cables) the wrench to pass is F = -W_ext.

Two kinds of singular configurations show up in (2):

* parallel (type 2): a twist t0 != 0 with A t0 + P qp_dot = 0 for some qp_dot (the platform
  moves with the actuators locked). Then t0 . F = t0 . A^T lambda = -(P qp_dot) . lambda
  = 0 for every achievable F: wrenches doing work on t0 are NOT resisted by any actuator
  force. :attr:`StaticModel.unresisted` holds an orthonormal basis of these twists.
* serial (type 1): multipliers lambda with B^T lambda = 0 and P^T lambda = 0 but
  A^T lambda != 0: the structure carries the wrench A^T lambda with no actuator force, and
  the capability along it is unbounded. :attr:`StaticModel.free_wrenches` holds them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import numeric
from .._checks import as_vector, check_mechanism, check_number
from .._checks import show as _show
from ..errors import MechanismError, NumericError, StaticsError
from ..mechanism import Mechanism
from ..model import Model, get_model
from ..model import statics as ms
from ..results import KinResult, jsonable

__all__ = ["StaticModel", "static_model", "wrench_names"]

#: default relative tolerance on singular values for the singularity tests
SING_TOL = 1e-9


def wrench_names(mech: Mechanism) -> tuple[str, ...]:
    """Names of the task wrench components of ``mech`` (order of ``F``).

    Parameters
    ----------
    mech : Mechanism

    Returns
    -------
    tuple of str
        E.g. ``("fx", "fy", "mz")`` for a planar platform.

    Examples
    --------
    >>> import optkin
    >>> wrench_names(optkin.mechanisms.five_bar(2.0, 1.5, 2.0, 2.0, 1.5))
    ('fx', 'fy')
    """
    check_mechanism(mech, "mech")
    return ms.wrench_names(get_model(mech))


@dataclass
class StaticModel:
    """The static model (2) at one configuration: F = A^T lambda, tau = -B^T lambda, P^T lambda = 0.

    Attributes
    ----------
    A, B, P : arrays (r, m), (r, na), (r, np)
        The velocity constraint (1) A t + B qa_dot + P qp_dot = 0 in twist coordinates.
    G : array (m, na) or None
        F = G tau (= J_inv^T) when B restricted to P^T lambda = 0 is invertible (no serial
        singularity); None otherwise.
    J : array (m, na) or None
        The forward velocity Jacobian t = J qa_dot (tau = J^T F) of a non-redundant,
        non-singular mechanism; None otherwise.
    unresisted : array (m, k)
        Orthonormal twists the platform can follow with the actuators locked (parallel
        singularity when k > 0); a wrench with a component along them cannot be resisted.
    free_wrenches : array (m, k)
        Orthonormal wrenches carried without actuator force (serial singularity when k > 0).
    singularity : str
        ``"none"``, ``"parallel"``, ``"serial"`` or ``"parallel+serial"``; ``"undefined"``
        where the model has no finite derivative (``extra["why"]`` says why); analyses of
        such a model return ``success=False``.
    cond : float
        Condition number of the part of the constraint that fixes the platform ([A P]);
        large near a parallel singularity.
    """

    A: np.ndarray
    B: np.ndarray
    P: np.ndarray
    wrench_names: tuple[str, ...]
    actuator_names: tuple[str, ...]
    G: np.ndarray | None
    J: np.ndarray | None
    unresisted: np.ndarray
    free_wrenches: np.ndarray
    singularity: str
    cond: float
    sing_tol: float = SING_TOL
    extra: dict[str, Any] = field(default_factory=dict)

    def __repr__(self) -> str:
        return (f"StaticModel(wrench {list(self.wrench_names)}, actuators "
                f"{list(self.actuator_names)}, singularity={self.singularity!r}, "
                f"cond={self.cond:.3g})")

    @property
    def m(self) -> int:
        """Dimension of the wrench (task) space."""
        return self.A.shape[1]

    @property
    def na(self) -> int:
        """Number of actuators."""
        return self.B.shape[1]

    def wrench(self, tau: Any) -> np.ndarray:
        """The wrench F = G tau applied by the end effector for actuator forces ``tau``.

        Raises :class:`~optkin.errors.StaticsError` at a serial singularity (G undefined).
        """
        try:
            t = as_vector(tau, "tau", self.na, error=StaticsError, path=("tau",))
        except StaticsError:
            raise StaticsError(
                f"tau: expected {self.na} finite actuator forces {list(self.actuator_names)}, "
                f"got {_show(tau)}", path=("tau",)
            ) from None
        if self.singularity == "undefined":
            raise StaticsError(f"wrench: {self.extra.get('why', 'the static model is undefined')}",
                               path=("tau",))
        if self.G is None:
            raise StaticsError(
                "wrench: the static map F = G tau is undefined at this serial singularity "
                "(some actuator carries no load); use the multipliers of the static model"
            )
        return self.G @ t

    def to_dict(self) -> dict[str, Any]:
        def arr(a):
            return None if a is None else np.asarray(a).tolist()

        return jsonable({
            "A": arr(self.A), "B": arr(self.B), "P": arr(self.P), "G": arr(self.G),
            "J": arr(self.J), "wrench_names": list(self.wrench_names),
            "actuator_names": list(self.actuator_names),
            "unresisted": arr(self.unresisted), "free_wrenches": arr(self.free_wrenches),
            "singularity": self.singularity,
            "cond": self.cond if np.isfinite(self.cond) else None,
        })


# --------------------------------------------------------------------------------------


def _config(model: Model, q: Any) -> tuple[np.ndarray, np.ndarray]:
    """(q_a, x) from a KinResult or a full joint vector."""
    mech = model.mech
    if isinstance(q, KinResult):
        from ..solvers.common import check_result_of

        check_result_of(mech, q, "q")
        if not q.success:
            raise MechanismError(
                f"q: the KinResult did not close the loops (status {q.status!r}, max |Phi| = "
                f"{q.residual:.2e}); statics needs a closed configuration: pass a successful "
                "result of optkin.forward / optkin.inverse", path=("q",))
        qa, x = np.asarray(q.qa, dtype=float), np.asarray(q.x, dtype=float)
        if not (np.isfinite(qa).all() and np.isfinite(x).all()):
            raise MechanismError("q: the KinResult has non-finite joint values", path=("q",))
        return qa, x
    nq = len(mech.joint_names)
    try:
        qq = as_vector(q, "q", nq, names=mech.joint_names, path=("q",), max_abs=np.inf)
    except MechanismError:
        raise MechanismError(
            f"q: expected {nq} finite joint values {list(mech.joint_names)} (KinResult.q) or "
            f"a KinResult, got {_show(q)}", path=("q",)
        ) from None
    with np.errstate(all="ignore"):
        return model.qa_of(qq), model.x_from_q(qq)


def _null(M: np.ndarray, tol: float) -> np.ndarray:
    """Orthonormal basis of the null space of M (singular values <= tol * largest)."""
    if M.shape[1] == 0:
        return np.zeros((0, 0))
    if M.shape[0] == 0:
        return np.eye(M.shape[1])
    _, s, Vt = numeric.svd(M, "static model")
    smax = s[0] if s.size else 0.0
    rank = int(np.sum(s > tol * max(smax, 1e-300)))
    return Vt[rank:].T.copy()


def _range(M: np.ndarray, tol: float, scale: float) -> np.ndarray:
    """Orthonormal basis of the range of M (singular values > tol * scale)."""
    if M.size == 0:
        return np.zeros((M.shape[0], 0))
    U, s, _ = numeric.svd(M, "static model", full_matrices=False)
    rank = int(np.sum(s > tol * max(scale, 1e-300)))
    return U[:, :rank].copy()


def static_model(mech: Mechanism, q: Any, sing_tol: float = SING_TOL) -> StaticModel:
    """The static model (2) of ``mech`` at configuration ``q``.

    Parameters
    ----------
    mech : Mechanism
    q : array or KinResult
        A configuration: ``KinResult.q`` (all joints) or the KinResult itself.
    sing_tol : float
        Relative tolerance on singular values for the singularity tests.

    Returns
    -------
    StaticModel

    Examples
    --------
    A 3-RPR whose three legs meet at the platform origin cannot resist a moment there:

    >>> import numpy as np, optkin
    >>> c, s = np.cos(2 * np.pi / 3), np.sin(2 * np.pi / 3)
    >>> base = np.array([[1, 0], [c, s], [c, -s]])
    >>> m = optkin.mechanisms.rpr3(base, 0.2 * base)
    >>> sm = static_model(m, optkin.inverse(m, [0, 0, 0])[0])
    >>> sm.singularity, np.round(np.abs(sm.unresisted.ravel()), 12).tolist()
    ('parallel', [0.0, 0.0, 1.0])
    """
    sing_tol = check_number(sing_tol, "static_model: sing_tol", lo=0.0, hi=1.0,
                            default=SING_TOL, error=StaticsError, path=("sing_tol",))
    check_mechanism(mech, "static_model")
    model = get_model(mech)
    qa, x = _config(model, q)
    names = ms.wrench_names(model)
    with np.errstate(all="ignore"):
        A, B, P = ms.velocity_constraint(model, qa, x)
    act = tuple(mech.active_names)
    if not all(np.isfinite(M).all() for M in (A, B, P)):
        return _undefined(A, B, P, names, act, sing_tol, "the closure rows have no finite "
                          "derivative at q (a leg of zero length, or values that overflow)")
    try:
        return _assemble(A, B, P, names, act, sing_tol)
    except NumericError as e:
        return _undefined(A, B, P, names, act, sing_tol, str(e))


def _undefined(A, B, P, names, act_names, sing_tol, why: str) -> StaticModel:
    """The static model of a configuration where it does not exist: no numeric kernel runs,
    ``singularity="undefined"``, and every analysis of it returns ``success=False``."""
    m = A.shape[1]
    return StaticModel(A, B, P, tuple(names), tuple(act_names), None, None, np.zeros((m, 0)),
                       np.zeros((m, 0)), "undefined", float("nan"), sing_tol,
                       {"why": f"the static model is undefined here: {why}"})


def _assemble(A, B, P, names, act_names, sing_tol) -> StaticModel:
    m, na = A.shape[1], B.shape[1]
    AP = np.hstack([A, P])
    sv = numeric.singular_values(AP, "[A P]") if AP.size else np.zeros(0)
    # parallel singularity: twists t with A t + P qp_dot = 0
    Nap = _null(AP, sing_tol)
    unres = _range(Nap[:m], sing_tol, 1.0) if Nap.size else np.zeros((m, 0))
    # serial singularity: multipliers with B^T l = 0 and P^T l = 0 but A^T l != 0
    Nbp = _null(np.hstack([B, P]).T, sing_tol)
    scaleA = numeric.norm2(A, "A") if A.size else 1.0
    free = _range(A.T @ Nbp, sing_tol, scaleA) if Nbp.size else np.zeros((m, 0))
    kinds = [k for k, v in (("parallel", unres.shape[1]), ("serial", free.shape[1])) if v]
    singularity = "+".join(kinds) if kinds else "none"
    smin_needed = sv[min(m + P.shape[1], sv.size) - 1] if sv.size else 0.0
    cond = float(sv[0] / smin_needed) if sv.size and smin_needed > 0 else float("inf")
    # G: F = G tau on the multipliers with P^T l = 0
    G = J = None
    Npl = _null(P.T, sing_tol) if P.shape[1] else np.eye(A.shape[0])
    BN = B.T @ Npl
    if BN.shape[0] == BN.shape[1] and "serial" not in kinds:
        BNi = numeric.inv(BN, "B", max_cond=np.inf)
        G = None if BNi is None else -(A.T @ Npl) @ BNi
    if G is not None and m == na and "parallel" not in kinds:
        J = numeric.inv(G.T, "G", max_cond=np.inf)
    return StaticModel(A, B, P, tuple(names), tuple(act_names), G, J, unres, free, singularity,
                       cond, sing_tol)
