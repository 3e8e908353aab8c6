"""What the static model of :mod:`optkin.statics` needs from a model.

The statics analyses see a mechanism only through its :class:`~optkin.model.Model`; this
module turns the model's interface into the velocity constraint

    A t + B qa_dot + P qp_dot = 0

of :mod:`optkin.statics.model` at one configuration, and names the twist and wrench
components of the end effector:

* fully parallel mechanisms (:attr:`Model.fully_parallel`: one row and one actuator per
  leg, Chablat and Wenger's A t + B qa_dot = 0, Chablat & Wenger 1998): the leg rows of the closure,
  A = W_p E with E mapping the platform twist to the rates of its coordinates
  (:meth:`Platform.xdot_of_twist`), B = W_a, P empty;
* every other description (Khalil tables, legs in chain form): the augmented form
  t - J_a qa_dot - J_x x_dot = 0 stacked over the closure W_a qa_dot + W_p x_dot = 0, i.e.
  A = [I; 0], B = [-J_a; W_a], P = [-J_x; W_p], with J the twist Jacobian of the end
  effector's frame (rows: the task's twist components).

It also gives the default bounds of a grid of poses: the box of the legs' base points.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..mechanism.core import TASK_COMPONENTS
from ..mechanism.platforms import TWIST_NAMES, WRENCH_NAMES
from .core import Model
from .structure import twist_jacobian

__all__ = ["twist_rows", "wrench_names", "twist_names", "twist_function",
           "velocity_constraint", "base_box"]


def twist_rows(model: Model) -> tuple[int, ...]:
    """Which of the six twist components (v, omega) of the end effector are the task's:
    the platform's twist rows, or the components a Khalil table's task names."""
    plat = model.platform
    if plat is not None:
        return tuple(plat.twist_rows)
    return tuple(TASK_COMPONENTS.index(c) for c in model.mech.task)


def wrench_names(model: Model) -> tuple[str, ...]:
    """Names of the task wrench components (force, then moment about the end-effector
    point), in the order of the twist rows."""
    return tuple(WRENCH_NAMES[i] for i in twist_rows(model))


def twist_names(model: Model) -> tuple[str, ...]:
    return tuple(TWIST_NAMES[i] for i in twist_rows(model))


def twist_function(model: Model) -> ca.Function:
    """(q_a, x, p) -> (J_a, J_x): the 6-row twist Jacobian (v; omega) of the end-effector
    frame in the base frame, built once per topology."""

    def build() -> ca.Function:
        qa, x, p, _ = model.symbols
        T = model.topology.pose_fn(qa, x, p)
        J = twist_jacobian(T[:3, :3], T[:3, 3], ca.vertcat(qa, x))
        na = model.na
        return ca.Function("statics_twist", [qa, x, p], [J[:, :na], J[:, na:]],
                           ["qa", "x", "p"], ["J_a", "J_x"])

    return model.cached(("statics", "twist"), build)


def velocity_constraint(model: Model, qa: np.ndarray, x: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A, B, P) of A t + B qa_dot + P qp_dot = 0 at (q_a, x) (see the module docstring)."""
    _, Wp, Wa = model.jac(qa, x)
    Wp, Wa = np.array(Wp), np.array(Wa)
    rows = twist_rows(model)
    if model.fully_parallel:
        keep = np.asarray(model.row_leg) >= 0  # the legs' rows (not the quaternion norm)
        npl = model.n_platform
        E = model.platform.xdot_of_twist(np.asarray(x, dtype=float)[:npl])
        A = Wp[keep][:, :npl] @ E
        B = Wa[keep]
        return A, B, np.zeros((B.shape[0], 0))
    Ja, Jx = (np.array(v) for v in twist_function(model)(qa, x, model.p))
    r = list(rows)
    m, nr = len(r), Wp.shape[0]
    A = np.vstack([np.eye(m), np.zeros((nr, m))])
    B = np.vstack([-Ja[r], Wa])
    P = np.vstack([-Jx[r], Wp])
    return A, B, P


def base_box(model: Model) -> np.ndarray | None:
    """[[lo, hi], [lo, hi]]: the box of the legs' base points in the first two
    coordinates (a platform), else None. A leg given by its screws counts the position of
    its home frame."""
    if model.platform is None:
        return None
    pts = []
    for leg in model.mech.legs:
        b = np.asarray(leg.base, dtype=float).ravel()
        pts.append(b[:2] if b.size >= 2 else np.asarray(leg.home, dtype=float)[:2, 3])
    P = np.array(pts, dtype=float)
    return np.column_stack([P.min(axis=0), P.max(axis=0)])
