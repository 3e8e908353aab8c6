"""Solutions that are not isolated: continua of configurations (self-motions, operation
modes of higher dimension, architecture singularities).

Where the closure Phi(q_a, x) = 0 has a positive-dimensional set of solutions, Newton's
method with the square Jacobian stalls near it (W_p is singular all along it) and a
multi-start search finds nothing, or a cloud of "solutions" that are points of the same
continuum. Here:

* :func:`project` moves a point onto the solution set by Gauss-Newton steps of least norm
  (``numpy.linalg.lstsq`` on the scaled Jacobian), which converge onto a set of constant
  rank whatever its dimension;
* :func:`local_dimension` decides whether a solution x is isolated: W_p's numerical nullity
  k (singular values below ``rtol`` times the largest) is the candidate dimension; it is
  a continuum when points moved by h along null directions project back onto the set at
  distances near h from x rather than back to x (an isolated multiple root); the
  dimension is the number of independent directions of those moves (at a point where the
  set is degenerate, W_p's nullity may exceed it);
* :func:`group` joins samples into components: two samples are on one component when the
  chord between them, projected point by point, stays on the set in steps no longer than
  the chord's pieces.

This is a numerical account (the dimension of a component at its samples, with samples of
each), not a proof; certified isolated solutions are :mod:`optkin.solvers.certify`'s.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Component", "group", "local_dimension", "project"]

#: Relative singular value under which W_p is taken as rank-deficient.
RTOL = 1e-7


@dataclass
class Component:
    """A positive-dimensional set of solutions, seen through samples on it.

    Attributes
    ----------
    dimension : int
        Local dimension at the samples (the nullity of W_p along the set).
    samples : list of KinResult
        Configurations on the component (each closes the loops; ``cond`` is large or inf:
        every point of a continuum is singular).
    """

    dimension: int
    samples: list = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {"dimension": int(self.dimension),
                "samples": [s.to_dict() for s in self.samples]}

    def __repr__(self) -> str:
        return f"Component(dimension={self.dimension}, {len(self.samples)} samples)"


def _scaled_jac(model, qa: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    phi, Wp, _ = model.jac(qa, x)
    return np.array(phi, dtype=float).ravel(), np.array(Wp, dtype=float) * model.x_scale[None, :]


def project(model, qa: np.ndarray, x: np.ndarray, tol: float, iters: int = 60,
            step_max: float = 0.5) -> tuple[np.ndarray, float, bool]:
    """Gauss-Newton of least norm from ``x`` onto Phi(q_a, .) = 0: (x, max |Phi|, closed).

    Steps are clamped to ``step_max`` (scaled units); singular directions get no step
    (``lstsq`` with a relative cutoff), so a point slides onto a continuum along its normal.
    """
    x = np.array(x, dtype=float)
    scale = model.x_scale
    res = best = np.inf
    slow = 0
    for _ in range(iters):
        phi, J = _scaled_jac(model, qa, x)
        res = float(np.max(np.abs(phi))) if phi.size else 0.0
        if not np.isfinite(res):
            return x, res, False
        if res <= tol:
            return x, res, True
        # stalled at a least-squares point that is not a solution (out of reach)
        slow = slow + 1 if res > 0.9 * best else 0
        best = min(best, res)
        if slow >= 4:
            return x, res, False
        dz = np.linalg.lstsq(J, -phi, rcond=1e-10)[0]
        nrm = float(np.linalg.norm(dz))
        if nrm > step_max:
            dz *= step_max / nrm
        x = x + dz * scale
    return x, res, res <= tol


def _nullspace(model, qa, x) -> tuple[np.ndarray, np.ndarray]:
    _, J = _scaled_jac(model, qa, x)
    _, s, Vt = np.linalg.svd(J)
    if s.size == 0 or s[0] == 0:
        return s, Vt
    k = int(np.sum(s < RTOL * s[0])) + max(0, J.shape[1] - s.size)
    return s, Vt[Vt.shape[0] - k:] if k else Vt[:0]


def local_dimension(model, qa: np.ndarray, x: np.ndarray, tol: float,
                    h: float = 1e-3) -> int:
    """0 when the solution ``x`` is isolated, else the dimension of the continuum through it
    (see the module docstring); ``h`` is the probe step in scaled units."""
    _, N = _nullspace(model, qa, x)
    if N.shape[0] == 0:
        return 0
    scale = model.x_scale
    moves = []
    for v in N[:8]:
        for sign in (1.0, -1.0):
            y, _, ok = project(model, qa, x + sign * h * v * scale, tol)
            d = float(np.linalg.norm((y - x) / scale))
            if ok and d > 0.1 * h:  # on the set, away from x: a direction of the set
                moves.append((y - x) / scale / d)
            # (back at x: an isolated multiple root in that direction; or not closed)
            # A null direction only to first order (a Gosselin-Angeles platform's rotation
            # about its legs) is projected back onto the set's tangent: the moves, made unit,
            # span the directions the set extends in, whatever the null-space basis
    if not moves:
        return 0
    sv = np.linalg.svd(np.array(moves), compute_uv=False)
    return int(np.sum(sv > 0.2 * sv[0]))


def group(model, qa: np.ndarray, xs: list[np.ndarray], tol: float,
          pieces: int = 8) -> list[list[int]]:
    """Indices of ``xs`` (points of continua) joined into components (see the module
    docstring); each list is one component."""
    n = len(xs)
    parent = list(range(n))

    def find(a: int) -> int:
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    scale = model.x_scale
    for a in range(n):
        for b in range(a):
            if find(a) == find(b):
                continue
            chord = (xs[b] - xs[a]) / pieces
            step = float(np.linalg.norm(chord / scale))
            prev, joined = xs[a], True
            for t in range(1, pieces + 1):
                y, _, ok = project(model, qa, xs[a] + t * chord, tol)
                if not ok or np.linalg.norm((y - prev) / scale) > 3 * step + 1e-9:
                    joined = False
                    break
                prev = y
            if joined and np.linalg.norm((prev - xs[b]) / scale) <= 3 * step + 1e-9:
                parent[find(a)] = find(b)
    comps: dict[int, list[int]] = {}
    for i in range(n):
        comps.setdefault(find(i), []).append(i)
    return list(comps.values())
