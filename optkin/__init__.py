"""optkin: kinematics of closed-chain and parallel robots as constrained optimization.

Describe a mechanism (a Khalil-Kleinfinger table or a parallel platform by its legs), and
optkin compiles it once into CasADi Functions and solves its direct and inverse geometric
models, returning result objects that say what happened.

The public names below are imported on first use (PEP 562), so ``import optkin`` is quick
and loads CasADi, cvxpy or matplotlib only when something needs them.
"""

from __future__ import annotations

import sys as _sys

if _sys.argv[:1] == ["-m"]:  # ``python -m optkin``: runpy imports this package first
    from ._exit import quiet_interrupts as _quiet_interrupts

    _quiet_interrupts()  # a Ctrl-C during these imports ends the command without a traceback

import importlib
from typing import TYPE_CHECKING, Any

from .errors import MechanismError, OptkinError, ProblemFileError, SolverError, StaticsError

__version__ = "0.1.0"

#: public name -> module that defines it (submodules map to themselves)
_LAZY: dict[str, str] = {
    # subpackages, reachable as attributes as scipy's are (``optkin.mechanism.geometry``)
    **{name: f"optkin.{name}" for name in ("analysis", "design", "mechanism", "model",
                                          "problems", "solvers")},
    "mechanisms": "optkin.mechanisms",
    "plot": "optkin.plot",
    "statics": "optkin.statics",
    "DofReport": "optkin.analysis",
    "Jacobians": "optkin.analysis",
    "SingularityReport": "optkin.analysis",
    "classify": "optkin.analysis",
    "dof": "optkin.analysis",
    "jacobians": "optkin.analysis",
    "plot_singularity_map": "optkin.analysis",
    "singularity_map": "optkin.analysis",
    "SingularityMap": "optkin.analysis",
    "Aspects": "optkin.analysis.aspects",
    "Workspace": "optkin.analysis.aspects",
    "aspects": "optkin.analysis.aspects",
    "workspace": "optkin.analysis.aspects",
    "SingularCurves": "optkin.analysis.continuation",
    "Aspects3D": "optkin.analysis.aspects3d",
    "aspects3d": "optkin.analysis.aspects3d",
    "SingularSurface": "optkin.analysis.surfaces",
    "singular_surfaces": "optkin.analysis.surfaces",
    "Cuspidality": "optkin.analysis.cusps",
    "CuspCurves": "optkin.analysis.cusps",
    "cusp_curves": "optkin.analysis.cusps",
    "ModeChangePath": "optkin.analysis.cusps",
    "is_cuspidal": "optkin.analysis.cusps",
    "mode_change_path": "optkin.analysis.cusps",
    "singular_curves": "optkin.analysis.continuation",
    "Leg": "optkin.mechanism",
    "Mechanism": "optkin.mechanism",
    "get_model": "optkin.model",
    "KinResult": "optkin.results",
    "SolutionSet": "optkin.results",
    "SolverStats": "optkin.results",
    "forward": "optkin.solvers",
    "inverse": "optkin.solvers",
    "BatchResult": "optkin.solvers.batch",
    "forward_batch": "optkin.solvers.batch",
    "WorkingModes": "optkin.solvers.enumerate",
    "assembly_modes": "optkin.solvers.enumerate",
    "track": "optkin.solvers.enumerate",
    "working_modes": "optkin.solvers.enumerate",
    "Certificate": "optkin.solvers.certify",
    "certify": "optkin.solvers.certify",
}

__all__ = [
    "Aspects",
    "Aspects3D",
    "BatchResult",
    "Certificate",
    "CuspCurves",
    "Cuspidality",
    "DofReport",
    "Jacobians",
    "KinResult",
    "Leg",
    "Mechanism",
    "MechanismError",
    "ModeChangePath",
    "OptkinError",
    "ProblemFileError",
    "SingularCurves",
    "SingularSurface",
    "SingularityMap",
    "SingularityReport",
    "SolutionSet",
    "SolverError",
    "SolverStats",
    "StaticsError",
    "WorkingModes",
    "Workspace",
    "__version__",
    "aspects",
    "aspects3d",
    "assembly_modes",
    "certify",
    "classify",
    "cusp_curves",
    "dof",
    "forward",
    "forward_batch",
    "get_model",
    "inverse",
    "is_cuspidal",
    "jacobians",
    "mechanisms",
    "mode_change_path",
    "plot",
    "plot_singularity_map",
    "singularity_map",
    "singular_curves",
    "singular_surfaces",
    "statics",
    "track",
    "working_modes",
    "workspace",
]


_RESOLVED: set[str] = set()


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    # a name is resolved once; deleting it afterwards hides it, as with an eager import
    if module is None or name in _RESOLVED:
        raise AttributeError(f"module 'optkin' has no attribute {name!r}")
    mod = importlib.import_module(module)
    value = mod if module == f"optkin.{name}" else getattr(mod, name)
    globals()[name] = value  # next time, a plain attribute
    _RESOLVED.add(name)
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs
    from . import mechanisms, plot, statics
    from .analysis import (
        DofReport,
        Jacobians,
        SingularityMap,
        SingularityReport,
        classify,
        dof,
        jacobians,
        plot_singularity_map,
        singularity_map,
    )
    from .analysis.aspects import Aspects, Workspace, aspects, workspace
    from .analysis.aspects3d import Aspects3D, aspects3d
    from .analysis.continuation import SingularCurves, singular_curves
    from .analysis.cusps import (
        CuspCurves,
        Cuspidality,
        ModeChangePath,
        cusp_curves,
        is_cuspidal,
        mode_change_path,
    )
    from .analysis.surfaces import SingularSurface, singular_surfaces
    from .mechanism import Leg, Mechanism
    from .model import get_model
    from .results import KinResult, SolutionSet, SolverStats
    from .solvers import forward, inverse
    from .solvers.batch import BatchResult, forward_batch
    from .solvers.certify import Certificate, certify
    from .solvers.enumerate import WorkingModes, assembly_modes, track, working_modes

if _sys.argv[:1] == ["-m"]:  # (``optkin.__main__`` keeps them quiet until the CLI is in)
    _quiet_interrupts(False)
