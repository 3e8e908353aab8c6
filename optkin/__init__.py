"""optkin: kinematics of closed-chain and parallel robots as constrained optimization.

Describe a mechanism (a Khalil-Kleinfinger table or a parallel platform by its legs), and
optkin compiles it once into CasADi Functions and solves its direct and inverse geometric
models, returning result objects that say what happened.
"""

from . import mechanisms, plot, statics
from .analysis import (
    DofReport,
    Jacobians,
    SingularityReport,
    classify,
    dof,
    jacobians,
    plot_singularity_map,
)
from .analysis.aspects import Aspects, Workspace, aspects, workspace
from .analysis.continuation import SingularCurves, singular_curves
from .errors import MechanismError, OptkinError, ProblemFileError, SolverError, StaticsError
from .mechanism import Leg, Mechanism
from .model import get_model
from .results import KinResult, SolutionSet, SolverStats
from .solvers import forward, inverse
from .solvers.batch import BatchResult, forward_batch
from .solvers.enumerate import WorkingModes, assembly_modes, track, working_modes

__version__ = "0.1.0"

__all__ = [
    "Aspects",
    "SingularCurves",
    "Workspace",
    "aspects",
    "singular_curves",
    "workspace",
    "DofReport",
    "Jacobians",
    "KinResult",
    "Leg",
    "Mechanism",
    "MechanismError",
    "OptkinError",
    "ProblemFileError",
    "SingularityReport",
    "SolutionSet",
    "SolverError",
    "SolverStats",
    "StaticsError",
    "WorkingModes",
    "__version__",
    "assembly_modes",
    "classify",
    "dof",
    "BatchResult",
    "forward",
    "forward_batch",
    "get_model",
    "inverse",
    "jacobians",
    "plot_singularity_map",
    "mechanisms",
    "plot",
    "statics",
    "track",
    "working_modes",
]
