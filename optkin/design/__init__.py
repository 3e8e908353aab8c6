"""Design optimization: performance measures as functions of geometry, optimization of a
mechanism's dimensions over them, and atlases over a design space."""

from .family import Family
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

__all__ = ["Family", "Aspect", "Box", "Disc", "Inscribed", "Integral", "area",
           "conditioning", "gci", "largest_inscribed", "singular_values"]
