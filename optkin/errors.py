"""Exceptions raised by optkin.

Every user error is a subclass of a builtin so callers can catch it generically;
messages name the offending item and say how to fix it.
"""

from __future__ import annotations

__all__ = ["OptkinError", "MechanismError", "ProblemFileError", "SolverError", "StaticsError"]


class OptkinError(Exception):
    """Base class of every optkin exception."""


class MechanismError(OptkinError, ValueError):
    """A mechanism description (Khalil table, legs, library arguments) is malformed."""


class ProblemFileError(OptkinError, ValueError):
    """A problem file is malformed: the message starts with ``file: key.path:``."""


class SolverError(OptkinError, RuntimeError):
    """An internal solver failure that cannot be expressed as an unsuccessful result."""


class StaticsError(OptkinError, ValueError):
    """Malformed input of a statics analysis (limits, wrenches, directions)."""
