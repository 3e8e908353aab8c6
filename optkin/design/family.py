"""A design family: named dimensions -> mechanisms of one topology, geometry p(d).

A family is a library factory (``optkin.mechanisms.five_bar``) or any function from named
dimensions to a mechanism; :class:`Family` binds it to the design variables (names and
bounds), constants, and linear equalities among the dimensions (a fixed sum, a ratio),
which it eliminates: each equality fixes one variable (its pivot) from the others, whose
bounds become inequality constraints (:meth:`Family.bound_violation`).

The geometry vector p of a mechanism is affine in the dimensions for the library's planar
and translational factories (lengths and coordinates enter p linearly); the family checks
this at two random designs and then writes p = p0 + M d, so evaluating a thousand designs
is one mapped call of the topology's compiled Function with small inputs. A family that is
not affine (radii and angles through cos and sin) is evaluated design by design.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .._checks import as_float, show
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model

__all__ = ["Family"]


class Family:
    """Named dimensions -> mechanisms of one topology (see the module docstring).

    Parameters
    ----------
    build : callable
        ``build(**dims) -> Mechanism`` (a library factory or any function).
    variables : mapping name -> (lo, hi)
        The design variables and their bounds (lo < hi, finite).
    fixed : mapping name -> float, optional
        Constant keyword arguments of ``build``.
    equal : sequence of (mapping name -> coefficient, value), optional
        Linear equalities sum_i c_i v_i = value among the variables; each eliminates the
        last variable it names that no earlier equality eliminated.

    Attributes
    ----------
    names : tuple of str
        Every variable, in the order given.
    free : tuple of str
        The variables the optimizer moves (the others follow from the equalities).
    lower, upper : ndarray
        Bounds of the free variables.
    affine : bool
        p = p0 + M d holds (checked).
    """

    def __init__(self, build: Callable[..., Mechanism], variables: Mapping[str, Any],
                 fixed: Mapping[str, Any] | None = None,
                 equal: Sequence[tuple[Mapping[str, float], float]] = ()) -> None:
        if not callable(build):
            raise MechanismError(f"family: expected a function from dimensions to a mechanism "
                                 f"(e.g. optkin.mechanisms.five_bar), got {show(build)}")
        if not isinstance(variables, Mapping) or not variables:
            raise MechanismError("variables: expected a mapping name -> (lo, hi), e.g. "
                                 "{'L1': (0.5, 2.0)}")
        self.build = build
        self.names = tuple(str(k) for k in variables)
        lo, hi = [], []
        for k in self.names:
            pair = variables[k]
            if not isinstance(pair, (tuple, list, np.ndarray)) or len(pair) != 2:
                raise MechanismError(f"variables[{k!r}]: expected (lo, hi), got {show(pair)}")
            a = as_float(pair[0], f"variables[{k!r}][0]", error=MechanismError)
            b = as_float(pair[1], f"variables[{k!r}][1]", error=MechanismError)
            if not a < b:
                raise MechanismError(f"variables[{k!r}]: lo < hi required, got ({a}, {b})")
            lo.append(a)
            hi.append(b)
        self.all_lower, self.all_upper = np.array(lo), np.array(hi)
        self.fixed = {str(k): v for k, v in (fixed or {}).items()}
        clash = set(self.fixed) & set(self.names)
        if clash:
            raise MechanismError(f"fixed: {sorted(clash)} are also design variables; "
                                 "give each name once")
        # equalities: eliminate one pivot each
        self._eq: list[tuple[int, np.ndarray, float]] = []   # (pivot, coeffs over names, value)
        pivots: list[int] = []
        for e, item in enumerate(equal):
            if not isinstance(item, (tuple, list)) or len(item) != 2 \
                    or not isinstance(item[0], Mapping):
                raise MechanismError(f"equal[{e}]: expected ({{name: coefficient}}, value), "
                                     f"e.g. ({{'r1': 1, 'r2': 1, 'r3': 1}}, 3.0)")
            coef = np.zeros(len(self.names))
            for k, c in item[0].items():
                if k not in self.names:
                    raise MechanismError(f"equal[{e}]: {k!r} is not a design variable; "
                                         f"known: {', '.join(self.names)}")
                coef[self.names.index(k)] = as_float(c, f"equal[{e}][{k!r}]",
                                                     error=MechanismError)
            val = as_float(item[1], f"equal[{e}] value", error=MechanismError)
            cand = [i for i in np.flatnonzero(coef) if i not in pivots]
            if not cand:
                raise MechanismError(f"equal[{e}]: every variable it names is already fixed "
                                     "by an earlier equality")
            piv = int(cand[-1])
            pivots.append(piv)
            self._eq.append((piv, coef, val))
        for e, (piv, coef, _) in enumerate(self._eq):
            later = {q for q, _, _ in self._eq[e + 1:]}
            bad = [self.names[i] for i in np.flatnonzero(coef) if i != piv and i in later]
            if bad:
                raise MechanismError(f"equal[{e}]: it names {bad}, which a later equality "
                                     "fixes; put that equality first")
        self.free_index = np.array([i for i in range(len(self.names)) if i not in pivots],
                                   dtype=int)
        self.free = tuple(self.names[i] for i in self.free_index)
        self.lower = self.all_lower[self.free_index]
        self.upper = self.all_upper[self.free_index]
        self._check_family()

    # -------------------------------------------------------------- values
    def full(self, z: Any) -> np.ndarray:
        """Every variable's value from the free ones (equalities applied in order)."""
        z = np.asarray(z, dtype=float)
        v = np.full(z.shape[:-1] + (len(self.names),), np.nan)
        v[..., self.free_index] = z
        for piv, coef, val in self._eq:
            c = coef.copy()
            c[piv] = 0.0
            rest = np.nansum(v * c, axis=-1) if np.any(c) else 0.0
            v[..., piv] = (val - rest) / coef[piv]
        return v

    def dims(self, z: Any) -> dict[str, float]:
        """The keyword arguments of ``build`` for free values z."""
        v = self.full(z)
        out = dict(self.fixed)
        out.update({k: float(x) for k, x in zip(self.names, v)})
        return out

    def full_affine(self) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) with every variable's value A z + b (the equalities are linear)."""
        k = len(self.free)
        b = self.full(np.zeros(k))
        A = np.stack([self.full(np.eye(k)[i]) - b for i in range(k)], axis=1)
        return A, b

    def bound_violation(self, z: Any) -> np.ndarray:
        """max(0, lo - v, v - hi) over the eliminated variables (0 when within bounds)."""
        v = self.full(z)
        return np.maximum(0.0, np.maximum(self.all_lower - v, v - self.all_upper)).max(axis=-1)

    def mechanism(self, z: Any) -> Mechanism:
        return self.build(**self.dims(z))

    def centre(self) -> np.ndarray:
        return 0.5 * (self.lower + self.upper)

    def _reference(self) -> np.ndarray:
        """A design within every bound (eliminated variables too): the centre of the free
        box if it is, else the first such point of a Sobol sequence."""
        z = self.centre()
        if self.bound_violation(z) <= 0:
            return z
        from scipy.stats import qmc

        pts = self.lower + qmc.Sobol(len(z), seed=0).random(1024) * (self.upper - self.lower)
        ok = pts[self.bound_violation(pts) <= 0]
        if not len(ok):
            raise MechanismError(f"no design within the bounds satisfies the equalities "
                                 f"({', '.join(self.names)}); widen the bounds")
        # the feasible point nearest the centre of the feasible ones
        c = ok.mean(axis=0)
        return ok[np.argmin(np.linalg.norm(ok - c, axis=1))]

    # -------------------------------------------------------------- geometry
    def _p(self, z: np.ndarray) -> np.ndarray:
        m = self.mechanism(z)
        if not isinstance(m, Mechanism):
            raise MechanismError(f"family: build(**dims) returned {type(m).__name__}, not a "
                                 "Mechanism")
        return np.concatenate([m.geometry, [1.0]])

    def _check_family(self) -> None:
        """The topology at the centre; p affine in z (p0, M) if it is."""
        z0 = self._reference()
        try:
            m0 = self.mechanism(z0)
        except Exception as e:  # the builder's own message says what is wrong
            raise MechanismError(f"family: building the centre design {self.dims(z0)} "
                                 f"failed: {e}") from e
        self.model0 = get_model(m0)
        self.key = self.model0.topology.key
        p0 = self._p(z0)
        k = len(z0)
        M = np.zeros((p0.size, k))
        span = self.upper - self.lower
        for i in range(k):
            h = np.zeros(k)
            h[i] = 1e-3 * span[i]
            M[:, i] = (self._p(z0 + h) - self._p(z0 - h)) / (2 * h[i])
        rng = np.random.default_rng(12345)
        affine = True
        tried = 0
        for _ in range(50):
            z = self.lower + rng.random(k) * span
            if self.bound_violation(z) > 0:
                continue
            try:
                p = self._p(z)
            except Exception:
                continue
            tried += 1
            if np.max(np.abs(p - (p0 + M @ (z - z0)))) > 1e-9 * (1 + np.max(np.abs(p))):
                affine = False
            if tried == 2:
                break
        self.affine = affine
        self.z0, self.p0, self.M = z0, p0 - M @ z0, M

    def geometry(self, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(p0, M, D) with p = p0 + M d for the rows d of D, one per design in Z (N, k)
        (a non-affine family: M None and D the geometry vectors themselves)."""
        Z = np.atleast_2d(np.asarray(Z, dtype=float))
        if self.affine:
            return self.p0, self.M, Z
        P = np.array([self._p(z) for z in Z])
        return np.zeros(P.shape[1]), None, P
