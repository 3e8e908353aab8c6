"""Unscrambled Sobol' points without importing :mod:`scipy.stats`.

``import scipy.stats`` costs about 1.1 s (SciPy 1.17: it builds the docstrings of every
distribution), four times all of ``import optkin``, and every batch worker would pay it for
:class:`scipy.stats.qmc.Sobol` alone. The points here are SciPy's own: the direction numbers
are read from the table SciPy ships with ``qmc.Sobol`` (Joe and Kuo's, 21 201 dimensions),
expanded by the standard recurrence (Bratley and Fox, ACM TOMS 14, 1988, Algorithm 659) and
combined in Gray-code order, as ``qmc.Sobol(d, scramble=False)`` does; the test suite checks
that the two agree bit for bit. Should the table move in a later SciPy, the points come
from ``qmc.Sobol`` itself.
"""

from __future__ import annotations

import os
import threading
import warnings

import numpy as np

__all__ = ["sobol_points"]

#: Bits per coordinate (SciPy's default for unscrambled points).
BITS = 30

_DIRECTIONS: dict[int, np.ndarray] = {}
_LOCK = threading.Lock()
_TABLE: tuple[np.ndarray, np.ndarray] | None = None


def _table() -> tuple[np.ndarray, np.ndarray] | None:
    """SciPy's (poly, vinit) direction-number table, or None when it cannot be read."""
    global _TABLE
    if _TABLE is None:
        import scipy

        path = os.path.join(os.path.dirname(scipy.__file__), "stats",
                            "_sobol_direction_numbers.npz")
        try:
            with np.load(path, allow_pickle=False) as data:
                _TABLE = (np.asarray(data["poly"], dtype=np.int64),
                          np.asarray(data["vinit"], dtype=np.int64))
        except (OSError, KeyError, ValueError):
            return None
    return _TABLE


def _directions(dim: int) -> np.ndarray | None:
    """The (dim, BITS) direction integers, scaled to BITS bits."""
    with _LOCK:
        V = _DIRECTIONS.get(dim)
        if V is not None:
            return V
        table = _table()
        if table is None or dim > table[0].size:
            return None
        poly, vinit = table
        V = np.zeros((dim, BITS), dtype=np.uint64)
        for a in range(dim):
            if a == 0:
                v = [1] * BITS
            else:
                p = int(poly[a])
                m = p.bit_length() - 1  # degree of the primitive polynomial
                v = [int(x) for x in vinit[a, :m]] + [0] * (BITS - m)
                for j in range(m, BITS):
                    new = v[j - m] ^ (v[j - m] << m)
                    for k in range(1, m):
                        if (p >> (m - k)) & 1:
                            new ^= v[j - k] << k
                    v[j] = new
            V[a] = [v[j] << (BITS - 1 - j) for j in range(BITS)]
        _DIRECTIONS[dim] = V
        return V


def sobol_points(dim: int, n: int, start: int = 0) -> np.ndarray:
    """Points ``start .. start + n - 1`` of the unscrambled Sobol' sequence in ``dim``
    dimensions, an (n, dim) array in [0, 1): the same numbers as
    ``qmc.Sobol(dim, scramble=False)`` fast-forwarded by ``start``."""
    dim, n, start = int(dim), int(n), int(start)
    if dim < 1 or n < 0 or start < 0:
        raise ValueError(f"sobol_points: dim >= 1, n >= 0 and start >= 0 (got {dim}, {n}, "
                         f"{start})")
    if start + n > 1 << BITS:
        raise ValueError(f"sobol_points: at most 2**{BITS} points")
    V = _directions(dim)
    if V is None:  # SciPy's table is not where it was: ask SciPy itself
        from scipy.stats import qmc

        engine = qmc.Sobol(dim, scramble=False)
        if start:
            engine.fast_forward(start)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the balance warning for n not a power of 2
            return engine.random(n)
    i = np.arange(start, start + n, dtype=np.uint64)
    gray = i ^ (i >> np.uint64(1))
    x = np.zeros((n, dim), dtype=np.uint64)
    for j in range(max(1, (start + n).bit_length())):
        on = ((gray >> np.uint64(j)) & np.uint64(1)).astype(bool)
        x[on] ^= V[:, j]
    return x * (1.0 / (1 << BITS))
