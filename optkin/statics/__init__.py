"""Statics of closed chains with cvxpy: force capability, wrench feasibility, force distribution.

The static model (:func:`static_model`) follows from the principle of virtual work on the
velocity constraint A t + B qa_dot + P qp_dot = 0 (Chablat and Wenger's A t + B qa_dot = 0
for platforms, Chablat & Wenger 1998; the closure [7.49] for Khalil tables, Khalil & Dombre
2002; Lynch & Park 2017, 7.2): F = A^T lambda, tau = -B^T lambda, P^T lambda = 0, where F is the wrench the end
effector APPLIES to the environment (moments about the end-effector point, base frame) and
tau the actuator forces; the load resisted is -F. See :mod:`optkin.statics.model`.

The analyses are convex programs built once per problem shape with ``cp.Parameter`` s and
re-solved at every pose (cvxpy DPP): :func:`capability` (LP; :func:`capability_many` puts
a chunk of poses in one LP), :func:`feasible` and :func:`wrench_feasible_workspace` (LP
margin), :func:`distribute` (QP or LP); the capability polytope (:func:`polytope`) is the
zonotope of the actuator box. Pictures: :func:`plot_capability` (via
:func:`capability_polygon`) and :func:`plot_workspace`.

Singular configurations are results, not errors: at a parallel singularity the wrenches
that do work on the twist the platform can follow with locked actuators get capability 0
(``direction_status`` ``"unresisted"``, ``status="singular"``); at a serial singularity
the wrenches carried without actuator force are ``"unbounded"``.
"""

from .core import (
    STATICS_DEFAULTS,
    box,
    capability,
    capability_many,
    capability_polygon,
    distribute,
    feasible,
    limits_of,
    polytope,
    wrench_feasible_workspace,
)
from .model import StaticModel, static_model, wrench_names
from .plots import plot_capability, plot_workspace
from .results import (
    CapabilityResult,
    DistributionResult,
    FeasibilityResult,
    PolytopeResult,
    WorkspaceResult,
)

__all__ = [
    "STATICS_DEFAULTS",
    "CapabilityResult",
    "DistributionResult",
    "FeasibilityResult",
    "PolytopeResult",
    "StaticModel",
    "WorkspaceResult",
    "box",
    "capability",
    "capability_many",
    "capability_polygon",
    "distribute",
    "feasible",
    "limits_of",
    "plot_capability",
    "plot_workspace",
    "polytope",
    "static_model",
    "wrench_feasible_workspace",
    "wrench_names",
]
