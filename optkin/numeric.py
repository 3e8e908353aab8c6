"""Finite-checked linear algebra: LAPACK never sees NaN or inf.

Some LAPACK builds loop forever on non-finite input (``DLASCL parameter number 4 had an
illegal value``), others raise ``LinAlgError`` or return garbage. Every dense kernel of the
analyses goes through the wrappers below, which

* raise :class:`~optkin.errors.NumericError` (a ``MechanismError``) naming ``where`` when the
  input has a NaN or inf entry, so that the caller can return ``success=False``;
* scale the input by a power of two (exact) before the call, so that finite entries near
  the float64 limits (1e300) neither overflow nor underflow inside LAPACK;
* turn a ``LinAlgError`` (no convergence) into a :class:`~optkin.errors.NumericError`.

Examples
--------
>>> import numpy as np
>>> singular_values(np.diag([3.0, 4.0]), "W_p").tolist()
[4.0, 3.0]
>>> svd(np.array([[np.nan, 0.0], [0.0, 1.0]]), "W_p")
Traceback (most recent call last):
...
optkin.errors.NumericError: W_p: the matrix has non-finite entries (NaN or inf) at row 0, column 0; the model is undefined here
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .errors import NumericError

__all__ = ["check_finite", "svd", "singular_values", "lstsq", "solve", "inv", "rank", "cond",
           "norm2", "pinv"]


def check_finite(a: Any, where: str) -> np.ndarray:
    """``a`` as a float array, or a :class:`NumericError` naming the first bad entry."""
    try:
        arr = np.asarray(a, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise NumericError(f"{where}: expected a numeric array") from None
    if not np.isfinite(arr).all():
        i = np.unravel_index(int(np.flatnonzero(~np.isfinite(arr.ravel()))[0]), arr.shape)
        at = (f" at row {i[0]}, column {i[1]}" if len(i) == 2 else
              f" at entry {i[0]}" if len(i) == 1 else "")
        raise NumericError(f"{where}: the matrix has non-finite entries (NaN or inf){at}; the "
                           "model is undefined here")
    return arr


def _scale(a: np.ndarray) -> float:
    """The power of two at or just below max |a| (1.0 for an all-zero or empty array)."""
    m = float(np.max(np.abs(a))) if a.size else 0.0
    if m == 0.0:
        return 1.0
    return math.ldexp(1.0, math.frexp(m)[1] - 1)


def svd(a: Any, where: str, *, full_matrices: bool = True) -> tuple[np.ndarray, np.ndarray,
                                                                      np.ndarray]:
    """(U, s, Vt) of ``a`` (numpy's convention), finite-checked and scaled."""
    a = check_finite(a, where)
    s0 = _scale(a)
    try:
        U, s, Vt = np.linalg.svd(a / s0, full_matrices=full_matrices)
    except np.linalg.LinAlgError as e:
        raise NumericError(f"{where}: the singular value decomposition failed ({e})") from None
    return U, s * s0, Vt


def singular_values(a: Any, where: str) -> np.ndarray:
    """The singular values of ``a``, largest first (empty for an empty matrix)."""
    a = check_finite(a, where)
    if a.size == 0:
        return np.zeros(0)
    s0 = _scale(a)
    try:
        return np.linalg.svd(a / s0, compute_uv=False) * s0
    except np.linalg.LinAlgError as e:
        raise NumericError(f"{where}: the singular value decomposition failed ({e})") from None


def norm2(a: Any, where: str) -> float:
    """The spectral norm (largest singular value) of ``a``; 0 for an empty matrix."""
    s = singular_values(np.atleast_2d(a), where)
    return float(s[0]) if s.size else 0.0


def cond(a: Any, where: str) -> float:
    """2-norm condition number s_max / s_min (inf when singular; 1 for an empty matrix)."""
    s = singular_values(a, where)
    if s.size == 0:
        return 1.0
    return float(s[0] / s[-1]) if s[-1] > 0 else float("inf")


def rank(a: Any, where: str, rtol: float = 1e-9, atol: float = 0.0) -> int:
    """Numerical rank: singular values above ``max(atol, rtol * s_max)``."""
    s = singular_values(a, where)
    if s.size == 0 or s[0] == 0:
        return 0
    return int(np.sum(s > max(atol, rtol * s[0])))


def lstsq(a: Any, b: Any, where: str) -> np.ndarray:
    """The minimum-norm least-squares solution x of a x = b."""
    a = check_finite(a, where)
    b = check_finite(b, where + " (right-hand side)")
    if a.shape[0] == 0 or a.shape[1] == 0:
        return np.zeros((a.shape[1],) + b.shape[1:])
    sa, sb = _scale(a), _scale(b)
    try:
        x = np.linalg.lstsq(a / sa, b / sb, rcond=None)[0]
    except np.linalg.LinAlgError as e:
        raise NumericError(f"{where}: the least-squares solve failed ({e})") from None
    with np.errstate(over="ignore"):
        x = x * (sb / sa)
    if not np.isfinite(x).all():
        raise NumericError(f"{where}: the least-squares solution overflows")
    return x


def solve(a: Any, b: Any, where: str, max_cond: float = 1e14) -> np.ndarray:
    """a^-1 b for a square ``a`` of condition below ``max_cond``, else :func:`lstsq`."""
    a = check_finite(a, where)
    b = check_finite(b, where + " (right-hand side)")
    if a.shape[0] == 0 or a.shape[1] == 0:
        return np.zeros((a.shape[1],) + b.shape[1:])
    if a.shape[0] == a.shape[1] and cond(a, where) < max_cond:
        sa, sb = _scale(a), _scale(b)
        try:
            x = np.linalg.solve(a / sa, b / sb) * (sb / sa)
        except np.linalg.LinAlgError:
            x = None
        if x is not None and np.isfinite(x).all():
            return x
    return lstsq(a, b, where)


def inv(a: Any, where: str, max_cond: float = 1e14) -> np.ndarray | None:
    """The inverse of a square ``a``, or None when ``a`` is singular (cond >= ``max_cond``)."""
    a = check_finite(a, where)
    if a.ndim != 2 or a.shape[0] != a.shape[1]:
        raise NumericError(f"{where}: expected a square matrix, got shape {a.shape}")
    if a.size == 0:
        return np.zeros_like(a)
    if not cond(a, where) < max_cond:
        return None
    sa = _scale(a)
    try:
        out = np.linalg.inv(a / sa) / sa
    except np.linalg.LinAlgError:
        return None
    return out if np.isfinite(out).all() else None


def pinv(a: Any, where: str, rtol: float = 1e-12) -> np.ndarray:
    """The Moore-Penrose pseudo-inverse (singular values below ``rtol * s_max`` dropped)."""
    a = check_finite(a, where)
    if a.size == 0:
        return np.zeros(a.shape[::-1])
    U, s, Vt = svd(a, where, full_matrices=False)
    keep = s > rtol * (s[0] if s.size else 0.0)
    return (Vt[keep].T / s[keep]) @ U[:, keep].T
