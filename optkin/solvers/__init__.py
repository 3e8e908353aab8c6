"""Solvers that take a model: forward, inverse (and, later, enumeration and tracking)."""

from .forward import FORWARD_DEFAULTS, forward
from .inverse import INVERSE_DEFAULTS, inverse

__all__ = ["FORWARD_DEFAULTS", "INVERSE_DEFAULTS", "forward", "inverse"]
