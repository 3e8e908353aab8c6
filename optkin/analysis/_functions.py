"""The analysis Functions of a mechanism's model (see :mod:`optkin.model.analysis`).

:func:`analysis_functions` returns the :class:`~optkin.model.analysis.AnalysisFunctions` of
the mechanism's topology, built once and kept in the model's per-topology cache. Their
Functions take the geometry as their last input: call them with ``model.p`` or through
``model.bind``.
"""

from __future__ import annotations

from typing import Any

from ..model import Model, get_model
from ..model.analysis import AnalysisFunctions
from ..model.analysis import analysis_functions as _model_functions
from ..model.structure import twist_jacobian as _twist_jacobian

__all__ = ["AnalysisFunctions", "analysis_functions"]


def analysis_functions(mech: Any) -> AnalysisFunctions:
    """The analysis Functions of ``mech`` (a Mechanism or its Model), shared by every
    mechanism of its topology."""
    model = mech if isinstance(mech, Model) else get_model(mech)
    return _model_functions(model)


# kept for modules that imported the twist Jacobian from here
twist_jacobian = _twist_jacobian
