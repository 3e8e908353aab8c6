"""Design optimization: performance measures as functions of geometry, optimization of a
mechanism's dimensions over them, and atlases over a design space.

- :mod:`~optkin.design.measures`: local conditioning, singular values, the global
  conditioning index, areas of regions and aspects, the largest inscribed disc or square.
- :mod:`~optkin.design.problem`: the same as objects of a design problem (``GCI``,
  ``MinConditioning``, ``LargestInscribed``, ``AspectArea``, ``Dimension``), compared with
  numbers into constraints and wrapped in ``Maximize`` / ``Minimize``.
- :func:`optimize`: differential evolution over the design space, then IPOPT with an
  exchange step where everything is smooth; :func:`atlas`: measures over a design grid.
"""

from .atlas import Atlas, atlas
from .family import Family
from .force import ForceCapability, LegStroke
from .measures import (
    Aspect,
    Box,
    Disc,
    Inscribed,
    Integral,
    area,
    conditioning,
    gci,
    largest_inscribed,
    singular_values,
)
from .optimize import DesignResult, optimize
from .problem import (
    GCI,
    AspectArea,
    Constraint,
    Dimension,
    JointRange,
    LargestInscribed,
    Maximize,
    Measure,
    MinConditioning,
    Minimize,
)

__all__ = ["Atlas", "atlas", "Family", "ForceCapability", "LegStroke", "Aspect", "Box", "Disc", "Inscribed", "Integral", "area",
           "conditioning", "gci", "largest_inscribed", "singular_values", "DesignResult",
           "optimize", "GCI", "AspectArea", "Constraint", "Dimension", "JointRange", "LargestInscribed",
           "Maximize", "Measure", "MinConditioning", "Minimize"]
