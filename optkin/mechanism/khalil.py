"""The Khalil-Kleinfinger description of tree and closed-chain robots
(Khalil & Dombre 2002, secs. 7.2-7.3).

One row per frame j: a(j), mu_j, sigma_j, gamma_j, b_j, alpha_j, d_j, theta_j, r_j.
sigma_j = 0 revolute, 1 prismatic, 2 constant frame. A closed chain with B loops is
described by its equivalent tree (frames 1..n), the B cut joints (frames n+1..n+B)
and their partner frames k+B (frames n+B+1..n+2B, sigma = 2), as in Tables 7.1 and 7.2.
numpy only.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._checks import as_float, as_int
from .._checks import show as _show
from ..errors import MechanismError
from .expr import evaluate

__all__ = ["KhalilFrame", "KhalilTable", "khalil_transform", "khalil_inverse", "COLUMNS"]

COLUMNS = ("a", "mu", "sigma", "gamma", "b", "alpha", "d", "theta", "r")
#: Most frames (rows) a table may have.
MAX_FRAMES = 200
_GEOM = ("gamma", "b", "alpha", "d", "theta", "r")


def khalil_transform(
    gamma: float, b: float, alpha: float, d: float, theta: float, r: float
) -> np.ndarray:
    """The 4x4 transform iT_j of [7.3]: Rot(z,gamma) Trans(z,b) Rot(x,alpha) Trans(x,d) Rot(z,theta) Trans(z,r).

    >>> T = khalil_transform(0, 0, 0, 1.0, np.pi / 2, 0)
    >>> np.round(T[:3, 3], 12).tolist()
    [1.0, 0.0, 0.0]
    """
    cg, sg = np.cos(gamma), np.sin(gamma)
    ca, sa = np.cos(alpha), np.sin(alpha)
    ct, st = np.cos(theta), np.sin(theta)
    return np.array(
        [
            [cg * ct - sg * ca * st, -cg * st - sg * ca * ct, sg * sa, d * cg + r * sg * sa],
            [sg * ct + cg * ca * st, -sg * st + cg * ca * ct, -cg * sa, d * sg - r * cg * sa],
            [sa * st, sa * ct, ca, r * ca + b],
            [0.0, 0.0, 0.0, 1.0],
        ]
    )


def khalil_inverse(
    gamma: float, b: float, alpha: float, d: float, theta: float, r: float
) -> np.ndarray:
    """The inverse transform jT_i of [7.4], written out (not a numerical inverse)."""
    T = khalil_transform(gamma, b, alpha, d, theta, r)
    A = T[:3, :3]
    ct, st = np.cos(theta), np.sin(theta)
    sa, ca = np.sin(alpha), np.cos(alpha)
    out = np.eye(4)
    out[:3, :3] = A.T
    # [7.4] gives the translation for gamma = 0; the general case adds the gamma rotation
    # of the d-offset, which is what -A^T p reduces to.
    if gamma == 0.0:
        out[:3, 3] = [-b * sa * st - d * ct, -b * sa * ct + d * st, -b * ca - r]
    else:
        out[:3, 3] = -A.T @ T[:3, 3]
    return out


@dataclass(frozen=True)
class KhalilFrame:
    """One row of a Khalil table, with its numeric geometry and its joint name."""

    j: int
    a: int
    mu: int
    sigma: int
    gamma: float
    b: float
    alpha: float
    d: float
    theta: float
    r: float
    name: str | None  # joint name, None for a constant frame (sigma = 2)
    source: Mapping[str, Any]  # the row as given (for echoing)

    @property
    def is_joint(self) -> bool:
        return self.sigma in (0, 1)

    def transform(self, q: float = 0.0) -> np.ndarray:
        """aT_j at joint value q (q is added to theta or r)."""
        th = self.theta + (q if self.sigma == 0 else 0.0)
        rr = self.r + (q if self.sigma == 1 else 0.0)
        return khalil_transform(self.gamma, self.b, self.alpha, self.d, th, rr)



def _row_dict(row: Any, j: int) -> dict[str, Any]:
    where = f"row {j} (frame j={j})"
    path = ("rows", j - 1)
    if isinstance(row, Mapping):
        d = dict(row)
        if "j" in d:
            jj = d.pop("j")
            if as_int(jj, f"{where}: j", path=path + ("j",)) != j:
                raise MechanismError(
                    f"{where}: j={_show(jj)} but frames must be listed in order 1, 2, ...; "
                    f"put this row at position {_show(jj)}", path=path + ("j",)
                )
        unknown = sorted(set(d) - set(COLUMNS), key=str)
        if unknown:
            raise MechanismError(
                f"{where}: unknown column(s) {unknown}; the columns are {list(COLUMNS)}",
                path=path + (str(unknown[0]),)
            )
        missing = [c for c in ("a",) if c not in d]
        if missing:
            raise MechanismError(f"{where}: missing column(s) {missing}", path=path)
        return d
    if isinstance(row, (Sequence, np.ndarray)) and not isinstance(row, (str, bytes)):
        if np.ndim(row) != 1 if isinstance(row, np.ndarray) else False:
            raise MechanismError(f"{where}: expected a mapping or a sequence of 9 values, "
                                 f"got an array of shape {row.shape}", path=path)
        if len(row) != len(COLUMNS):
            raise MechanismError(
                f"{where}: expected {len(COLUMNS)} values {list(COLUMNS)}, got {len(row)}",
                path=path
            )
        return dict(zip(COLUMNS, row))
    raise MechanismError(f"{where}: expected a mapping or a sequence of 9 values, got "
                         f"{_show(row)}", path=path)


def _int_col(d: Mapping[str, Any], key: str, where: str, path: tuple,
             default: int | None = None) -> int:
    v = d.get(key, default)
    try:
        return as_int(v, where, path=path + (key,))
    except MechanismError:
        raise MechanismError(f"{where}: {key} must be an integer, got {_show(v)}",
                             path=path + (key,)) from None


class KhalilTable:
    """A validated Khalil table: the equivalent tree, its cut joints and partner frames.

    Parameters
    ----------
    rows : sequence
        One entry per frame j = 1..n+2B, a mapping with the keys of :data:`COLUMNS` (or a
        sequence in that order). In a mapping only ``a`` is required: ``mu`` and ``sigma``
        default to 0 (a passive revolute joint) and the geometric columns to 0, as in
        problem files. Geometric entries are numbers or text (a parameter name,
        ``"pi/2"``, ``"-d8"``). The variable column of a joint (theta for sigma = 0, r for
        sigma = 1) holds the joint's name (``"theta3"``), ``None`` for the default name, or
        a number used as a constant offset.
    loops : int
        B, the number of cut joints (independent loops, [7.6]).
    params : mapping
        Values of the named parameters.
    """

    def __init__(
        self, rows: Sequence[Any], loops: int = 0, params: Mapping[str, float] | None = None
    ) -> None:
        if params is not None and not isinstance(params, Mapping):
            raise MechanismError(f"params: expected a mapping name -> value, got {_show(params)}",
                                 path=("params",))
        params = dict(params or {})
        for k, v in params.items():
            if not isinstance(k, str) or not k.isidentifier():
                raise MechanismError(f"params: {_show(k)} is not a valid parameter name",
                                     path=("params",))
            params[k] = as_float(v, f"params.{k}", path=("params", k))
        if isinstance(loops, bool) or not isinstance(loops, (int, np.integer)) or not (
                0 <= loops <= MAX_FRAMES):
            raise MechanismError(f"loops: expected a non-negative integer (at most "
                                 f"{MAX_FRAMES // 2}), got {_show(loops)}", path=("loops",))
        if isinstance(rows, (str, bytes)) or not isinstance(rows, (Sequence, np.ndarray)):
            raise MechanismError("rows: expected a list of rows, one per frame", path=("rows",))
        if len(rows) == 0:
            raise MechanismError("rows: the table is empty; give one row per frame j = 1..n+2B",
                                 path=("rows",))
        if len(rows) > MAX_FRAMES:
            raise MechanismError(f"rows: {len(rows)} frames; at most {MAX_FRAMES} are supported",
                                 path=("rows",))
        B = int(loops)
        total = len(rows)
        n = total - 2 * B
        if n < 1:
            raise MechanismError(
                f"loops: {B} loop(s) need 2*{B} cut/partner frames after at least one tree "
                f"frame, but the table has only {total} rows", path=("loops",)
            )
        self.params = params
        self.loops = B
        self.n = n
        frames: list[KhalilFrame] = []
        names: set[str] = set()
        for idx, raw in enumerate(rows):
            j = idx + 1
            where = f"row {j} (frame j={j})"
            at = ("rows", idx)
            d = _row_dict(raw, j)
            a = _int_col(d, "a", where, at)
            if a >= j or a < 0:
                raise MechanismError(
                    f"{where}: a(j)={a} must satisfy 0 <= a(j) < j (the antecedent frame is "
                    f"numbered before its successor); renumber the frames from the base outwards",
                    path=at + ("a",)
                )
            sigma = _int_col(d, "sigma", where, at, default=0)
            if sigma not in (0, 1, 2):
                raise MechanismError(
                    f"{where}: sigma={sigma} is not a joint type; use 0 (revolute), "
                    "1 (prismatic) or 2 (constant frame)", path=at + ("sigma",)
                )
            mu = _int_col(d, "mu", where, at, default=0)
            if mu not in (0, 1):
                raise MechanismError(f"{where}: mu={mu}; use 1 for an actuated joint, 0 otherwise",
                                     path=at + ("mu",))
            if sigma == 2 and mu == 1:
                raise MechanismError(
                    f"{where}: a constant frame (sigma=2) cannot be actuated; set mu=0",
                    path=at + ("mu",)
                )
            if a > n and a != 0:
                raise MechanismError(
                    f"{where}: a(j)={a} is a cut or partner frame; only tree frames 0..{n} "
                    "can carry other frames", path=at + ("a",)
                )
            var_col = "theta" if sigma == 0 else ("r" if sigma == 1 else None)
            geom: dict[str, float] = {}
            name: str | None = None
            for c in _GEOM:
                v = d.get(c, 0.0)
                if c == var_col and (v is None or (isinstance(v, str) and v.isidentifier()
                                                   and v not in params and v != "pi")):
                    name = v if v is not None else (f"theta{j}" if sigma == 0 else f"r{j}")
                    geom[c] = 0.0
                    continue
                if v is None:
                    raise MechanismError(f"{where}: column {c} is empty; give a number",
                                         path=at + (c,))
                if isinstance(v, str):
                    geom[c] = evaluate(v, params, f"{where}, column {c}", at + (c,))
                else:
                    geom[c] = as_float(v, f"{where}, column {c}", path=at + (c,))
            if sigma != 2 and name is None:
                name = f"theta{j}" if sigma == 0 else f"r{j}"
            if name is not None:
                if name in names:
                    raise MechanismError(
                        f"{where}: joint name {name!r} is used twice; give each joint its own name",
                        path=at + (var_col or "theta",)
                    )
                names.add(name)
            frames.append(
                KhalilFrame(j, a, mu, sigma, name=name, source=dict(d), **geom)  # type: ignore[arg-type]
            )
        # cut joints and their partners
        for k in range(n + 1, n + B + 1):
            fk, fp = frames[k - 1], frames[k + B - 1]
            if not fk.is_joint:
                raise MechanismError(
                    f"row {k} (frame j={k}): frame {k} is a cut joint of loop {k - n} but "
                    "sigma=2; a cut joint must be revolute (0) or prismatic (1)",
                    path=("rows", k - 1, "sigma")
                )
            if fk.mu != 0:
                raise MechanismError(
                    f"row {k} (frame j={k}): cut joint {k} is actuated (mu=1); cut each loop "
                    "at a passive joint", path=("rows", k - 1, "mu")
                )
            if fp.sigma != 2:
                raise MechanismError(
                    f"row {k + B} (frame j={k + B}): cut frame {k} has no partner frame: "
                    f"frame k+B={k + B} must be a constant frame (sigma=2) fixed on the other "
                    f"link of the cut joint (loops={B})", path=("rows", k + B - 1, "sigma")
                )
            if fp.a == fk.a:
                raise MechanismError(
                    f"row {k + B} (frame j={k + B}): the partner frame {k + B} sits on link "
                    f"{fp.a}, the same link as cut frame {k}; a(k+B) must be the other link of "
                    "the cut joint", path=("rows", k + B - 1, "a")
                )
        self.frames: tuple[KhalilFrame, ...] = tuple(frames)
        self.rows_source = [dict(f.source) for f in frames]

    # --- structure -------------------------------------------------------
    @property
    def joints(self) -> list[KhalilFrame]:
        """Frames that carry a joint variable (tree joints then cut joints)."""
        return [f for f in self.frames[: self.n + self.loops] if f.is_joint]

    @property
    def cut_frames(self) -> list[int]:
        return list(range(self.n + 1, self.n + self.loops + 1))

    def partner(self, k: int) -> int:
        return k + self.loops

    def chain(self, j: int) -> list[int]:
        """Frames from the base to frame j (excluding 0), in order."""
        out = []
        while j != 0:
            out.append(j)
            j = self.frames[j - 1].a
        return out[::-1]

    def transform_0(self, j: int, qmap: Mapping[str, float]) -> np.ndarray:
        """0T_j by [7.11] with joint values by name (numpy, for tests and drawing)."""
        T = np.eye(4)
        for f in (self.frames[i - 1] for i in self.chain(j)):
            T = T @ f.transform(qmap.get(f.name, 0.0) if f.name else 0.0)
        return T
