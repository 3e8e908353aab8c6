"""Exceptions raised by optkin.

Every user error is a subclass of a builtin so callers can catch it generically;
messages name the offending item and say how to fix it. Where the library knows the
location of the problem in its input, the error carries it as data in :attr:`path`
(as pydantic's ``loc``), so that a caller such as the problem-file layer can prefix its
own key path instead of parsing the message text.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["OptkinError", "MechanismError", "NumericError", "ProblemFileError", "SolverError",
           "StaticsError"]


class OptkinError(Exception):
    """Base class of every optkin exception.

    Parameters
    ----------
    *args
        The message (as for any exception).
    path : iterable of str and int, optional
        Where the problem is in the input, as keys and 0-based indices, e.g.
        ``("rows", 1, "d")`` for column d of the second Khalil row or ``("legs", 2, "base")``;
        empty when unknown.

    Examples
    --------
    >>> e = MechanismError("row 2 (frame j=2), column d: cannot read '1/'", path=("rows", 1, "d"))
    >>> e.path
    ('rows', 1, 'd')
    >>> import pickle; pickle.loads(pickle.dumps(e)).path
    ('rows', 1, 'd')
    """

    def __init__(self, *args: object, path: Iterable[str | int] = ()) -> None:
        super().__init__(*args)
        self.path: tuple[str | int, ...] = tuple(path)

    def __reduce__(self):  # keep ``path`` through pickling (worker processes)
        return (_rebuild, (type(self), self.args, self.path))


def _rebuild(cls: type[OptkinError], args: tuple, path: tuple) -> OptkinError:
    return cls(*args, path=path)


class MechanismError(OptkinError, ValueError):
    """A mechanism description (Khalil table, legs, library arguments) is malformed."""


class NumericError(MechanismError):
    """A numeric kernel was handed NaN, inf or numbers it cannot represent.

    Raised by the finite-checked linear algebra of :mod:`optkin.numeric` instead of letting
    LAPACK see them (some builds loop forever on NaN); the analyses turn it into a result
    with ``success=False`` where they can.
    """


class ProblemFileError(OptkinError, ValueError):
    """A problem file is malformed: the message starts with ``file: key.path:``."""


class SolverError(OptkinError, RuntimeError):
    """An internal solver failure that cannot be expressed as an unsuccessful result."""


class StaticsError(OptkinError, ValueError):
    """Malformed input of a statics analysis (limits, wrenches, directions)."""
