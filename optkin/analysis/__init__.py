"""Analyses of a compiled mechanism: velocity and acceleration models, degrees of freedom,
singularity classification and maps (Khalil & Dombre 2002, 7.8-7.11; Lynch & Park 2017,
7.2-7.3; Özgören; Chablat & Wenger 1998)."""

from .aspects import Aspect, Aspects, Workspace, aspects, workspace
from .continuation import Curve, SingularCurves, singular_curves
from .maps import SingularityMap, plot_singularity_map, singularity_map
from .mobility import DofReport, dof
from .singularity import SingularityReport, classify
from .velocity import Jacobians, jacobians

__all__ = [
    "Aspect", "Aspects", "Workspace", "aspects", "workspace",
    "Curve", "DofReport", "Jacobians", "SingularCurves", "SingularityMap", "SingularityReport",
    "classify", "dof", "jacobians", "plot_singularity_map", "singular_curves",
    "singularity_map",
]
