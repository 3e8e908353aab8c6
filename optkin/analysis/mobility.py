"""Degrees of freedom: Grubler-Kutzbach count and rank-based mobility ([7.56]-[7.59]).

:func:`dof` reports two numbers that should agree for ordinary mechanisms:

* ``grubler`` - the Kutzbach-Grubler count of Özgören,
  m = lambda n_mb - sum_k (lambda - k) j_k, written with the number of independent
  kinematic loops n_ikl = j_tot - n_mb as m = sum_i f_i - sum_loops lambda_j (so that a
  planar loop counts lambda = 3 and a spatial loop lambda = 6, [7.57]). It counts links and
  joints and ignores the geometry.
* ``mobility`` - N = min_q dim null(J(q)) [7.58] over random closed configurations, with
  c = max_q rank J(q) [7.59] the number of independent constraints. J is the constraint
  Jacobian over every joint (Khalil tables), or over every leg joint and the platform
  coordinates (leg-described platforms: each leg's chain reaches the platform frame, its
  reported end joint included).

The links and joints counted come from the model (:func:`optkin.model.analysis.
joint_inventory`): each leg's inventory, a Khalil table's frames and the rank of its loops.

They disagree for overconstrained linkages (Bennett: Grubler -2, mobility 1) and when
links spin idly (S-S rods): the report says so in ``message``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import numeric
from .._checks import as_float, as_int, check_mechanism, check_option
from .._dryrun import checkpoint
from ..errors import NumericError
from ..mechanism import Mechanism
from ..model import Model, get_model
from ..model.analysis import analysis_functions, z_of
from ..model.analysis import joint_inventory as _joint_inventory
from ..results import INFEASIBLE, OPTIMAL, jsonable

__all__ = ["DofReport", "dof", "DOF_DEFAULTS", "closed_configurations", "joint_inventory",
           "MAX_SAMPLES"]

#: Largest number of closed configurations :func:`dof` samples.
MAX_SAMPLES = 1000

#: Options of :func:`dof`.
DOF_DEFAULTS: dict[str, Any] = {
    "samples": 5,  # random closed configurations for [7.58]/[7.59] (1 to MAX_SAMPLES)
    "seed": 0,  # of the random starts (a run is reproducible)
    "rtol": 1e-8,  # relative singular-value threshold of the rank (scaled Jacobian), in (0, 1)
}


@dataclass
class DofReport:
    """Degrees of freedom of a mechanism (see :func:`dof`).

    Attributes
    ----------
    grubler : int
        The Kutzbach-Grubler count (Özgören).
    mobility : int
        min dim null(J) over the sampled closed configurations [7.58].
    constraints : int
        c = max rank J [7.59].
    agree : bool
        Whether ``grubler - idle == mobility``.
    idle : int
        Idle degrees of freedom the count includes (spin of S-S rods about their axis).
    n_links, n_joints, n_loops : int
        Movable bodies, joints (a joint with k freedoms counts once in ``joint_freedoms``),
        independent loops n_ikl = j_tot - n_mb.
    loop_lambda : tuple of int
        lambda of each loop (3 planar, 6 spatial; from the rank of the loop's rows).
    nullity : list of int
        dim null(J) at each sampled configuration.
    success, status, message :
        As every result (:mod:`optkin.results`): ``"optimal"`` when closed configurations
        were sampled, ``"infeasible"`` (``success`` False, mobility -1) when least squares
        found none; the message gives the verdict.
    """

    mech_name: str
    grubler: int
    mobility: int
    constraints: int
    agree: bool
    message: str
    success: bool = True
    status: str = ""
    idle: int = 0
    n_links: int = 0
    n_joints: int = 0
    n_loops: int = 0
    joint_freedoms: dict[int, int] = field(default_factory=dict)
    loop_lambda: tuple[int, ...] = ()
    nullity: list[int] = field(default_factory=list)
    intended: int = 0
    samples: int = 0
    residual: float = 0.0

    def __post_init__(self) -> None:
        if not self.status:
            self.status = OPTIMAL if self.success else INFEASIBLE

    def __repr__(self) -> str:
        flag = "agree" if self.agree else "DISAGREE"
        return (f"DofReport({self.mech_name!r}: grubler={self.grubler}, "
                f"mobility={self.mobility}, {flag})")

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (:func:`optkin.results.jsonable`)."""
        return jsonable({
            "mech_name": self.mech_name, "grubler": int(self.grubler),
            "mobility": int(self.mobility), "constraints": int(self.constraints),
            "agree": bool(self.agree), "success": bool(self.success), "status": self.status,
            "message": self.message,
            "idle": int(self.idle), "n_links": int(self.n_links), "n_joints": int(self.n_joints),
            "n_loops": int(self.n_loops),
            "joint_freedoms": {str(k): int(v) for k, v in self.joint_freedoms.items()},
            "loop_lambda": [int(v) for v in self.loop_lambda],
            "nullity": [int(v) for v in self.nullity], "intended": int(self.intended),
            "samples": int(self.samples), "residual": float(self.residual),
        })


# ----------------------------------------------------------------------------- counting
def joint_inventory(mech: Mechanism | Model) -> dict[str, Any]:
    """Links, joints (with their freedoms) and loop subspace dimensions of ``mech``.

    Khalil tables: one movable link per tree joint frame, one joint per joint variable (cut
    joints included), lambda of each loop = generic rank of its six closure rows.
    Platforms: the joints of each leg (its ``inventory``) plus the platform; legs of a point
    platform meet in one multiple joint (l - 1 joints, no platform body); the legs of a
    Delta are R + a parallelogram of two S-S rods (their inventory says so).
    """
    return _joint_inventory(mech if isinstance(mech, Model) else get_model(mech))


# ----------------------------------------------------------------------------- sampling
def closed_configurations(
    mech: Mechanism, n: int = 5, seed: int = 0, tol: float = 1e-10, max_starts: int = 60
) -> tuple[list[np.ndarray], float]:
    """Random closed configurations by least squares over all joint variables.

    Returns the configurations (Khalil: all joints; platforms: all joints then the platform
    coordinates x) and the largest residual among them.
    """
    n = as_int(n, "closed_configurations: n", lo=0, hi=MAX_SAMPLES, path=("n",))
    seed = as_int(seed, "closed_configurations: seed", lo=0, path=("seed",))
    tol = as_float(tol, "closed_configurations: tol", lo=0.0, path=("tol",))
    max_starts = as_int(max_starts, "closed_configurations: max_starts", lo=0,
                        hi=MAX_SAMPLES * 12, path=("max_starts",))
    model = get_model(mech)
    f = analysis_functions(model)
    rng = np.random.default_rng(seed)
    L = model.length
    nv = f.nvar
    rows_q = model.bind(f.rows_q)

    def fun(z):
        return np.array(rows_q(z)[0]).ravel()

    def jac(z):
        return np.array(rows_q(z)[1])

    prismatic = np.zeros(nv, bool)
    nj = len(mech.joint_names)
    prismatic[:nj] = ~np.array(mech.revolute)
    x_home = None
    if model.n_platform:  # start near a central pose of the platform
        with np.errstate(all="ignore"):
            x_home = model.default_x(np.zeros(model.na) + L)
        if not np.all(np.isfinite(x_home)):
            x_home = None
    out: list[np.ndarray] = []
    worst = 0.0
    for _ in range(max_starts):
        if len(out) >= n:
            break
        z0 = rng.uniform(-np.pi, np.pi, nv)
        z0[prismatic] = rng.uniform(0.5, 1.5, prismatic.sum()) * L
        if x_home is not None:
            x0 = x_home + rng.normal(0, 0.05, x_home.size) * model.x_scale
            zp = z_of(model, np.zeros(nj), x0)
            z0[nj:] = zp[nj:]
        z, r = _gauss_newton(fun, jac, z0)
        if r <= tol:
            out.append(z)
            worst = max(worst, r)
    return out, worst


def _gauss_newton(fun, jac, z, max_iter: int = 100) -> tuple[np.ndarray, float]:
    """Minimum-norm Gauss-Newton steps on |Phi(z)|^2 with backtracking."""
    r = fun(z)
    nr = float(r @ r)
    for _ in range(max_iter):
        if nr < 1e-26 or not np.isfinite(nr):
            break
        try:
            dz = numeric.lstsq(jac(z), -r, "closure Jacobian")
        except NumericError:  # the rows are undefined here (a leg of zero length): stop
            break
        step = 1.0
        nrm = float(np.linalg.norm(dz))
        if nrm > 1.0:
            dz = dz / nrm
        while step > 1e-4:
            zn = z + step * dz
            rn = fun(zn)
            nn = float(rn @ rn)
            if nn < nr:
                z, r, nr = zn, rn, nn
                break
            step *= 0.5
        else:
            break
    return z, float(np.max(np.abs(r))) if r.size else 0.0


def var_scale(model: Model) -> np.ndarray:
    """The scale of each joint-level variable z: the mechanism's size for prismatic joints
    and platform positions, 1 for angles (and unit quaternions)."""
    f = analysis_functions(model)
    L = model.length
    nj = len(model.mech.joint_names)
    cs = np.ones(f.nvar)
    cs[:nj][~np.array(model.mech.revolute)] = L
    cs[f.z_x] = model.x_scale
    return cs


def _scaled(mech: Mechanism, J: np.ndarray) -> np.ndarray:
    """Rows of lengths divided and prismatic/position columns multiplied by the length
    scale, so that the singular values are dimensionless."""
    model = get_model(mech)
    f = analysis_functions(model)
    rs = np.where(f.row_length, 1.0 / model.length, 1.0)
    return rs[:, None] * J * var_scale(model)[None, :]


def rank_of(s: np.ndarray, rtol: float) -> int:
    """Numerical rank from singular values ``s`` with a relative tolerance."""
    if s.size == 0 or s[0] == 0:
        return 0
    return int(np.sum(s > rtol * s[0]))


def dof(mech: Mechanism, **options: Any) -> DofReport:
    """Degrees of freedom of ``mech``: Grubler's count and the rank-based mobility.

    Parameters
    ----------
    mech : Mechanism
    **options
        The options below, by keyword, over :data:`DOF_DEFAULTS` (an unknown name is a
        :class:`~optkin.MechanismError`).

    Other Parameters
    ----------------
    samples : int
        Number of random closed configurations for [7.58]/[7.59] (default 5, at most
        :data:`MAX_SAMPLES`).
    seed : int
        Seed of the random starts (default 0).
    rtol : float
        Relative singular-value threshold for the rank (of the scaled Jacobian; default
        1e-8).

    Returns
    -------
    DofReport
        ``grubler``, ``mobility``, ``constraints`` and whether they agree.

    Examples
    --------
    >>> import optkin
    >>> r = optkin.dof(optkin.mechanisms.four_bar(4, 4, 2, 2))
    >>> (r.grubler, r.mobility, r.agree)
    (1, 1, True)
    """
    from ..solvers.common import merge_options

    opts = merge_options(DOF_DEFAULTS, options, "dof")
    check_mechanism(mech, "dof")
    samples = check_option(opts, "samples", "dof", DOF_DEFAULTS, integer=True, lo=1,
                           hi=MAX_SAMPLES)
    rtol = check_option(opts, "rtol", "dof", DOF_DEFAULTS, lo=0.0, hi=1.0, lo_open=True,
                        hi_open=True)
    seed = check_option(opts, "seed", "dof", DOF_DEFAULTS, integer=True, lo=0)
    checkpoint()  # validation stops here: every argument is checked
    inv = joint_inventory(mech)
    freedoms = inv["freedoms"]
    lam = inv["lambda"]
    grub = int(sum(freedoms) - sum(lam))
    hist: dict[int, int] = {}
    for k in freedoms:
        hist[k] = hist.get(k, 0) + 1
    model = get_model(mech)
    rows_q = model.bind(analysis_functions(model).rows_q)
    confs, worst = closed_configurations(mech, n=samples, seed=seed)
    nullity, ranks = [], []
    for z in confs:
        J = np.array(rows_q(z)[1])
        try:
            s = numeric.singular_values(_scaled(mech, J), "constraint Jacobian")
        except NumericError:  # undefined at this sample: leave it out
            continue
        r = rank_of(s, rtol)
        ranks.append(r)
        nullity.append(J.shape[1] - r)
    ok = bool(nullity)
    mob = int(min(nullity)) if ok else -1
    c = int(max(ranks)) if ok else -1
    idle = int(inv["idle"])
    agree = ok and grub - idle == mob
    if not ok:
        msg = ("no closed configuration found by least squares from random starts; the "
               "mobility is unknown")
    elif agree and idle:
        msg = (f"Grubler counts {grub}, of which {idle} idle rotation(s) of S-S rods; "
               f"mobility {mob} from the Jacobian rank")
    elif agree:
        msg = f"Grubler and the Jacobian rank agree: {mob} degree(s) of freedom"
    elif mob == 0:
        msg = (f"Grubler-Kutzbach counts {grub} and the constraint Jacobian has full rank {c} "
               "at every sampled closed configuration: the closures are isolated, the "
               "linkage is a rigid structure")
    else:
        msg = (f"Grubler-Kutzbach counts {grub}"
               + (f" ({grub - idle} without {idle} idle rotation(s))" if idle else "")
               + f" but the constraint Jacobian has rank {c} and nullity {mob} at every sampled "
               "closed configuration: the linkage is "
               + ("overconstrained (special geometry, e.g. Bennett)" if mob > grub - idle
                  else "constrained beyond what its joints count (the platform kind keeps "
                  "freedoms fixed that the legs' joints leave free, e.g. a translational "
                  "platform on legs that do not hold its orientation)")
               + f"; it moves with {mob} degree(s) of freedom")
    return DofReport(
        mech_name=mech.name, grubler=grub, mobility=mob, constraints=c, agree=bool(agree),
        message=msg, success=ok, idle=idle, n_links=int(inv["n_links"]),
        n_joints=len(freedoms), n_loops=int(inv["loops"]), joint_freedoms=hist,
        loop_lambda=tuple(int(v) for v in lam), nullity=nullity, intended=int(mech.dof),
        samples=len(confs), residual=worst,
    )
