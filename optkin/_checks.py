"""One place that turns user input into numbers: every public function converts through here.

Whatever the caller passes (a Python int with 400 digits, a string, a nested list, NaN,
``1e308``), the converters below either return a finite float64 value of the expected
shape or raise the project's own error class naming the argument (``where``) and the fix.
They never let ``OverflowError``, ``TypeError`` or a numpy ``ValueError`` escape.

Numeric kernels (LAPACK through numpy) must never receive NaN or inf: some LAPACK builds
loop forever on them (``DLASCL parameter number 4 had an illegal value``).
:func:`finite_matrix` is the guard to put in front of them; the finite-checked linear
algebra helpers live in :mod:`optkin.numeric`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import MechanismError

__all__ = [
    "as_float",
    "as_int",
    "as_vector",
    "as_matrix",
    "finite_matrix",
]

#: Largest magnitude accepted for a coordinate, length or angle anywhere in optkin.
#: Beyond it, squares overflow float64 (1e154 ** 2 = 1e308) and every residual is inf.
MAX_ABS = 1e150


def _err(error: type[Exception], where: str, msg: str) -> Exception:
    return error(f"{where}: {msg}")


def _scalar(v: Any, where: str, error: type[Exception]) -> float:
    if isinstance(v, bool) or isinstance(v, np.bool_):
        raise _err(error, where, f"expected a number, got {v!r}")
    if isinstance(v, numbers.Integral):
        iv = int(v)
        if abs(iv) > MAX_ABS:
            raise _err(error, where, f"the integer {str(iv)[:20]}... is too large "
                       f"(magnitude above {MAX_ABS:g}); give a number of sensible size")
        return float(iv)
    if isinstance(v, numbers.Real):
        return float(v)
    if isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected a number, got the string {str(v)[:40]!r}")
    if isinstance(v, numbers.Complex):
        raise _err(error, where, f"expected a real number, got {v!r}")
    raise _err(error, where, f"expected a number, got {type(v).__name__}")


def as_float(v: Any, where: str, *, lo: float | None = None, hi: float | None = None,
             finite: bool = True, error: type[Exception] = MechanismError) -> float:
    """``v`` as a float; ``lo``/``hi`` bound it inclusively; NaN is always rejected.

    >>> as_float(3, "tol")
    3.0
    >>> as_float("x", "tol")
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: tol: expected a number, got the string 'x'
    """
    x = _scalar(v, where, error)
    if math.isnan(x) or (finite and not math.isfinite(x)):
        raise _err(error, where, f"expected a finite number, got {x!r}")
    if finite and abs(x) > MAX_ABS:
        raise _err(error, where, f"{x:g} is too large (magnitude above {MAX_ABS:g})")
    if lo is not None and x < lo:
        raise _err(error, where, f"expected a number >= {lo:g}, got {x:g}")
    if hi is not None and x > hi:
        raise _err(error, where, f"expected a number <= {hi:g}, got {x:g}")
    return x


def as_int(v: Any, where: str, *, lo: int | None = None, hi: int | None = None,
           error: type[Exception] = MechanismError) -> int:
    """``v`` as an int (integral floats such as ``4.0`` accepted); bounds inclusive.

    >>> as_int(4.0, "starts", lo=1)
    4
    """
    if isinstance(v, (bool, np.bool_)) or isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected an integer, got {v!r}")
    if isinstance(v, numbers.Integral):
        iv = int(v)
    elif isinstance(v, numbers.Real) and math.isfinite(float(v)) and float(v).is_integer():
        iv = int(v)
    else:
        raise _err(error, where, f"expected an integer, got {str(v)[:40]}")
    if lo is not None and iv < lo:
        raise _err(error, where, f"expected an integer >= {lo}, got {iv}")
    if hi is not None and iv > hi:
        raise _err(error, where, f"expected an integer <= {hi}, got {str(iv)[:24]}")
    return iv


def _to_array(v: Any, where: str, error: type[Exception]) -> np.ndarray:
    if isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected numbers, got the string {str(v)[:40]!r}")
    if isinstance(v, np.ndarray) and v.dtype.kind in "fiu":
        a = v.astype(float, copy=False)
    else:
        try:
            a = np.asarray(v, dtype=float)
        except OverflowError:
            raise _err(error, where, f"a value is too large (magnitude above {MAX_ABS:g})") from None
        except (TypeError, ValueError):
            raise _err(error, where, "expected numbers (a list or array of the right shape), "
                       f"got {_show(v)}") from None
    return a


def _show(v: Any) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def _check_finite(a: np.ndarray, where: str, names: Sequence[str] | None,
                  error: type[Exception]) -> None:
    bad = ~np.isfinite(a) | (np.abs(np.nan_to_num(a)) > MAX_ABS)
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        label = f" ({names[i]})" if names is not None and i < len(names) else ""
        raise _err(error, where, f"entry {i}{label} is {float(a.ravel()[i])!r}; give finite values "
                   f"of magnitude at most {MAX_ABS:g}")


def as_vector(v: Any, where: str, n: int | None = None, *, names: Sequence[str] | None = None,
              error: type[Exception] = MechanismError) -> np.ndarray:
    """``v`` as a finite 1-D float array (of ``n`` entries when given); a new array.

    ``names`` (the entries' names, e.g. joint names) make the messages precise.

    >>> as_vector([1, 2], "qa", 2)
    array([1., 2.])
    >>> as_vector([1, float("nan")], "qa", 2, names=["t1", "t2"])
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: qa: entry 1 (t2) is nan; give finite values of magnitude at most 1e+150
    """
    a = _to_array(v, where, error)
    if a.ndim == 0 and n in (None, 1):
        a = a.reshape(1)
    if a.ndim != 1 or (n is not None and a.size != n):
        want = (f"{n} number{'s' if n != 1 else ''}" if n is not None
                else "a list of numbers")
        if names is not None and n is not None:
            want += f" ({', '.join(names)})"
        raise _err(error, where, f"expected {want}, got shape {a.shape}")
    _check_finite(a, where, names, error)
    return np.array(a, dtype=float)


def as_matrix(v: Any, where: str, shape: tuple[int | None, int | None] | None = None, *,
              error: type[Exception] = MechanismError) -> np.ndarray:
    """``v`` as a finite 2-D float array; ``shape`` entries of None match any size."""
    a = _to_array(v, where, error)
    if a.ndim != 2 or (shape is not None and any(
            s is not None and s != d for s, d in zip(shape, a.shape))):
        want = "x".join("n" if s is None else str(s) for s in shape) if shape else "2-D"
        raise _err(error, where, f"expected a {want} array, got shape {a.shape}")
    _check_finite(a, where, None, error)
    return np.array(a, dtype=float)


def finite_matrix(a: np.ndarray) -> bool:
    """True when every entry of ``a`` is finite (guard before any LAPACK call)."""
    return bool(np.isfinite(a).all())
