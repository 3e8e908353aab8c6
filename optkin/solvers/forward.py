"""The direct geometric model: solve Phi(q_a, x) = 0 for the unknowns x."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._checks import check_option
from .._checks import show as _show
from .._dryrun import checkpoint
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..model import get_model
from ..results import KinResult, SolverStats, ipopt_status
from .common import (
    check_mechanism,
    check_qa,
    count_option,
    make_result,
    merge_options,
    newton,
    parse_guess,
    timer,
)

__all__ = ["forward", "FORWARD_DEFAULTS"]

#: Options of :func:`forward` and their defaults.
FORWARD_DEFAULTS: dict[str, Any] = {
    "method": "auto",  # "auto": Newton from the guess, IPOPT if it fails; "ipopt"; "newton"
    "tol": 1e-10,  # max |Phi| for success
    "max_iter": 50,  # Newton iterations (at most MAX_ITER)
    "polish": 8,  # Newton iterations after IPOPT (at most MAX_ITER)
}

#: Largest accepted ``max_iter`` and ``polish`` (bounded work per call).
MAX_ITER = 10_000


def forward(mech: Mechanism, qa: Any, guess: Any = None, **options: Any) -> KinResult:
    """Direct geometric model: the closed configuration for active joint values ``qa``.

    The closure Phi(q_a, x) = 0 is posed as the NLP  min ``|x - x_guess|^2``  s.t.  Phi = 0
    and solved with IPOPT (the solver is built once per mechanism and reused, q_a and the
    guess being its parameters), so the guess selects the assembly mode nearest to it. With
    ``method="auto"`` (default) a clamped Newton iteration from the guess (Khalil & Dombre 2002, sec. 7.9) is
    tried first and IPOPT runs only when it fails; both end with a Newton polish.

    Parameters
    ----------
    mech : Mechanism
    qa : array (dof,)
        Active joint values, in ``mech.active_names`` order.
    guess : optional
        None (the mechanism's home), a :class:`KinResult`, the unknowns x, all joint values
        q, the passive joint values, or (platforms) a 4x4 pose / task coordinates.
    **options
        See :data:`FORWARD_DEFAULTS`.

    Returns
    -------
    KinResult
        ``success=False`` with a status and message when the loops cannot close.

    Examples
    --------
    >>> import optkin
    >>> m = optkin.mechanisms.four_bar(1.0, 2.0, 2.0, 2.5)
    >>> r = optkin.forward(m, [1.0])
    >>> r.success, r.residual < 1e-10
    (True, True)
    """
    opts = merge_options(FORWARD_DEFAULTS, options, "forward")
    check_mechanism(mech, "forward")
    model = get_model(mech)
    model.note_use()  # compiles the model's Functions once it is in heavy use
    qa = check_qa(model, qa)
    x0 = parse_guess(model, qa, guess)
    tol = check_option(opts, "tol", "forward", FORWARD_DEFAULTS, lo=0.0, lo_open=True)
    max_iter, polish = (count_option(opts, k, "forward", 0, MAX_ITER, FORWARD_DEFAULTS)
                        for k in ("max_iter", "polish"))
    method = opts["method"]
    if not isinstance(method, str) or method not in ("auto", "ipopt", "newton"):
        raise MechanismError(
            f"forward: option method must be 'auto', 'ipopt' or 'newton', got {_show(method)}",
            path=("options", "method"))
    checkpoint()  # validation stops here: every argument is checked
    t0 = timer()
    if method in ("auto", "newton"):
        x, r, nit, ok = newton(model, qa, x0.copy(), tol, max_iter)
        if ok or method == "newton":
            stats = SolverStats("newton", 0.0, timer() - t0, nit, "converged" if ok else "failed")
            status = None if ok else ("iteration_limit" if np.isfinite(r) else "error")
            msg = None if ok else (
                f"Newton did not converge in {nit} iterations (max |Phi| = {r:.2e}); "
                "try method='ipopt' or another guess"
            )
            return make_result(model, qa, x, tol, nit, stats, status, msg)
    solver = model.nlp()
    t1 = timer()
    sol = solver(x0=x0, p=np.concatenate([qa, x0, model.p]), lbg=0, ubg=0)
    st = solver.stats()
    raw = str(st.get("return_status", ""))
    x = np.array(sol["x"]).ravel()
    nit = int(st.get("iter_count", 0))
    x, r, npol, ok = newton(model, qa, x, tol, polish)
    stats = SolverStats(
        "ipopt", model.nlp_build_time, timer() - t1, nit + npol, raw,
        {"ipopt_iter": nit, "polish_iter": npol, "t_wall_total": st.get("t_wall_total")},
    )
    status = None if ok else ipopt_status(raw)
    if not ok and status in ("optimal", "inaccurate"):
        status = "infeasible"
    msg = None
    if not ok:
        msg = (
            f"no closed configuration found (IPOPT: {raw}; max |Phi| = {r:.2e}): the active "
            "joint values may be out of reach (e.g. legs too short to close), or the guess too "
            "far from any closed configuration: try another guess, or optkin.assembly_modes"
        )
    return make_result(model, qa, x, tol, nit + npol, stats, status, msg)


