"""The kinematic model: a mechanism compiled once into CasADi Functions.

``get_model(mech)`` returns the cached :class:`Model` of a mechanism (keyed by its content
hash, so a worker process that sees the same description twice builds it once). The model
holds the closure residual Phi(q_a, x) with independent rows [7.8]/[7.9], its Jacobians
W_p = dPhi/dx and W_a = dPhi/dq_a [7.49], a clamped Newton step (the algorithm of 7.9),
the end-effector pose, and lazily the IPOPT solver of the direct geometric model.
"""

from __future__ import annotations

import hashlib
import math
import threading
import time
from typing import Any

import casadi as ca
import numpy as np

from .._cache import KeyedCache
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..mechanism.geometry import homogeneous, matrix_to_quat, quat_to_matrix, rot2
from ..mechanism.legs import leg_forward, leg_joints
from . import compiled as cc
from . import fused
from . import khalil as kh
from . import legs as lg

__all__ = ["Model", "get_model", "clear_cache"]

_CACHE: KeyedCache[Model] = KeyedCache()
#: forward() calls on one model after which it is compiled (OPTKIN_COMPILE=auto)
HOT_USES = 100


def get_model(mech: Mechanism) -> Model:
    """The compiled model of ``mech``, built on first use and cached by content."""
    if not isinstance(mech, Mechanism):
        raise MechanismError(
            f"expected an optkin Mechanism, got {type(mech).__name__}; build one with "
            "optkin.mechanisms.* or Mechanism.from_khalil / from_legs"
        )
    return _CACHE.get(mech.key, lambda: Model(mech))


def clear_cache() -> None:
    _CACHE.clear()


def _length_scale(mech: Mechanism) -> float:
    vals: list[float] = []
    if mech.kind == "khalil":
        for f in mech.table.frames:
            vals += [abs(f.b), abs(f.d), abs(f.r)]
    else:
        for leg in mech.legs:
            vals += list(np.abs(leg.base)) + list(np.abs(leg.platform)) + list(leg.lengths)
    v = max(vals) if vals else 1.0
    return v if v > 0 else 1.0


class Model:
    """CasADi Functions of one mechanism. Build with :func:`get_model`."""

    def __init__(self, mech: Mechanism) -> None:
        t0 = time.perf_counter()
        self.mech = mech
        self.length = _length_scale(mech)
        na = mech.n_actuated  # = dof unless the mechanism is redundantly actuated
        self.na = na
        qa = ca.SX.sym("qa", na)
        self._nlp: Any = None
        self._inv: Any = None
        self._batch: dict[int, ca.Function] = {}
        if mech.kind == "khalil":
            self.passive_index = np.flatnonzero(~np.array(mech.actuated))
            nx = self.passive_index.size
            x = ca.SX.sym("x", nx)
            q = self._assemble_sx(qa, x)
            T = kh.frames_0(mech, q)
            rows, names = kh.closure_rows(mech, T)
            qfull = ca.SX.sym("q", len(mech.joint_names))
            Tf = kh.frames_0(mech, qfull)
            rows_f, _ = kh.closure_rows(mech, Tf)
            keep = kh.select_rows(mech, qfull, rows_f, names)
            if len(keep) < nx:
                raise MechanismError(
                    f"the loops give {len(keep)} independent closure equations for {nx} passive "
                    f"joints: the mechanism has {nx - len(keep)} more degree(s) of freedom than "
                    "actuated joints; actuate more joints (mu=1) or add loops"
                )
            phi = rows[keep] if keep else ca.SX(0, 1)
            self.row_names = [names[i] for i in keep]
            self.x_names = tuple(mech.joint_names[i] for i in self.passive_index)
            self.x_angle = np.array([mech.revolute[i] for i in self.passive_index], dtype=bool)
            self.x_scale = np.where(self.x_angle, 1.0, self.length)
            Tee = T[mech.end_effector]
            self._T_all = T
            self._q_sym = q
        else:
            nx = lg.x_dim(mech.platform)
            x = ca.SX.sym("x", nx)
            phi, self.row_names = lg.leg_rows(mech, qa, x)
            R, p = lg.platform_frame(mech.platform, x)
            Tee = ca.vertcat(ca.horzcat(R, p), ca.horzcat(0, 0, 0, 1))
            coords = {"planar": ("x", "y", "phi"), "planar_point": ("x", "y"),
                      "spatial": ("x", "y", "z", "qw", "qx", "qy", "qz"),
                      "spatial_translational": ("x", "y", "z")}[mech.platform]
            self.x_names = coords
            self.x_angle = np.array([c == "phi" for c in coords], dtype=bool)
            self.x_scale = np.array(
                [1.0 if (c == "phi" or c.startswith("q")) else self.length for c in coords]
            )
            self.passive_index = np.flatnonzero(~np.array(mech.actuated))
        self.nx = nx
        self.m = int(phi.shape[0])
        self.qa_sym, self.x_sym, self.phi_sym = qa, x, phi
        Wp = ca.jacobian(phi, x)
        Wa = ca.jacobian(phi, qa)
        self.phi = ca.Function("Phi", [qa, x], [phi], ["qa", "x"], ["Phi"])
        self.jac = ca.Function("W", [qa, x], [phi, Wp, Wa], ["qa", "x"], ["Phi", "W_p", "W_a"])
        self.pose_fn = ca.Function("pose", [qa, x], [Tee], ["qa", "x"], ["T"])
        # damped Newton step (7.9): dx = -W_p^+ Phi with a line search on |Phi|
        if self.m == nx:
            dx = -ca.solve(Wp, phi)
        else:
            dx = -ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, phi))
        fphi = ca.Function("Phi_x", [x, qa], [phi])
        xn = damped_step(fphi, x, dx, self.x_scale, [qa])
        res = ca.mmax(ca.fabs(phi)) if self.m else ca.SX(0)
        self.step = ca.Function("newton_step", [qa, x], [xn, res], ["qa", "x"], ["x_next", "res"])
        # compiled twins (optkin.model.compiled): loaded from the disk cache when present
        self.step_sx = self.step  # the interpreted step (for symbolic use)
        self.compiled_step: ca.Function | None = None
        self.compiled_fns: dict[str, ca.Function] = {}
        self.uses = 0
        self._tls = threading.local()
        self._gen = 0
        self._result_fn: ca.Function | None = None
        self._tracker: dict[tuple[int, int], ca.Function] = {}
        self._guard: dict[int, ca.Function] = {}
        self._compile_lock = threading.Lock()
        self._compile_failed = False
        mode = cc.compile_mode()
        if mode != "off":
            self.compile(build=mode == "eager")
        self.build_time = time.perf_counter() - t0

    # -------------------------------------------------------------- conversions
    def _assemble_sx(self, qa, x):
        parts = []
        ia = ip = 0
        for a in self.mech.actuated:
            if a:
                parts.append(qa[ia])
                ia += 1
            else:
                parts.append(x[ip])
                ip += 1
        return ca.vertcat(*parts)

    def residual(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.array(self.phi(qa, x)).ravel()

    def pose(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.array(self.pose_fn(qa, x))

    def to_q(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        """All joint values (``mech.joint_names`` order) from q_a and the unknowns x."""
        mech = self.mech
        q = np.empty(len(mech.joint_names))
        act = np.array(mech.actuated)
        q[act] = qa
        if mech.kind == "khalil":
            q[~act] = x
            return q
        T = self.pose(qa, x)
        R, p = T[:3, :3], T[:3, 3]
        if mech.planar:
            R, p = R[:2, :2], p[:2]
        i = 0
        for k, leg in enumerate(mech.legs):
            n = len(leg.joint_names)
            q[i:i + n] = leg_joints(leg, R, p, float(qa[k]))
            i += n
        return q

    def qa_of(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q, dtype=float)[np.array(self.mech.actuated)]

    def x_from_q(self, q: np.ndarray) -> np.ndarray:
        """The unknowns x of a full joint vector (legs: mean of each leg's chain pose)."""
        mech = self.mech
        q = np.asarray(q, dtype=float)
        if mech.kind == "khalil":
            return q[self.passive_index].copy()
        Rs, ps = [], []
        i = 0
        pp = mech.platform in ("planar_point", "spatial_translational")
        for leg in mech.legs:
            n = len(leg.joint_names)
            R, p = leg_forward(leg, q[i:i + n], planar_point=pp)
            Rs.append(R)
            ps.append(p)
            i += n
        p = np.mean(ps, axis=0)
        if mech.planar:
            phis = [np.arctan2(R[1, 0], R[0, 0]) for R in Rs]
            phi = float(np.arctan2(np.mean(np.sin(phis)), np.mean(np.cos(phis))))
            return self.x_from_pose(homogeneous(rot2(phi), p))
        quats = [matrix_to_quat(R) for R in Rs]
        ref = quats[0]
        qm = np.mean([qq if qq @ ref >= 0 else -qq for qq in quats], axis=0)
        return self.x_from_pose(homogeneous(quat_to_matrix(qm), p))

    def x_from_pose(self, T: np.ndarray) -> np.ndarray:
        """The unknowns x of a platform pose (leg-described mechanisms)."""
        mech = self.mech
        T = np.asarray(T, dtype=float)
        if mech.kind == "khalil":
            raise MechanismError(
                "guess: a pose cannot seed a Khalil mechanism's direct model; give joint values"
            )
        plat = mech.platform
        if plat == "planar":
            return np.array([T[0, 3], T[1, 3], np.arctan2(T[1, 0], T[0, 0])])
        if plat == "planar_point":
            return T[:2, 3].copy()
        if plat == "spatial":
            return np.concatenate([T[:3, 3], matrix_to_quat(T[:3, :3])])
        return T[:3, 3].copy()

    def canonical_x(self, x: np.ndarray) -> np.ndarray:
        """Angles wrapped to (-pi, pi], quaternions normalised with w >= 0."""
        x = np.array(x, dtype=float)
        idx = self.__dict__.get("_angle_idx")
        if idx is None:
            idx = self._angle_idx = [int(i) for i in np.flatnonzero(self.x_angle)]
        for i in idx:  # scalar wrap_angle: a few angles, no array overhead
            a = math.remainder(x[i], 2 * math.pi) if math.isfinite(x[i]) else x[i]
            x[i] = math.pi if a <= -math.pi else a
        if self.mech.kind == "legs" and self.mech.platform == "spatial":
            qq = x[3:7] / math.sqrt(float(x[3:7] @ x[3:7]))
            x[3:7] = qq if qq[0] >= 0 else -qq
        return x

    def default_x(self, qa: np.ndarray) -> np.ndarray:
        """A default starting point: the mechanism's home, else a central configuration."""
        mech = self.mech
        if mech.kind == "khalil":
            if mech.home is not None:
                return mech.home[self.passive_index].copy()
            return np.full(self.nx, 0.1)
        if mech.home is not None:
            from ..mechanism.tasks import task_to_pose

            return self.x_from_pose(task_to_pose(mech, mech.home))
        base = np.mean([leg.base for leg in mech.legs], axis=0)
        plat = np.mean([leg.platform for leg in mech.legs], axis=0)
        p = base - plat
        if mech.platform == "planar":
            return np.array([p[0], p[1], 0.0])
        if mech.platform == "planar_point":
            return p[:2] + np.array([0.0, 0.5 * self.length])
        reach = float(np.mean(qa)) if mech.legs[0].type in ("UPS", "SPS") else -0.7 * sum(
            mech.legs[0].lengths)
        p = p + np.array([0.0, 0.0, reach])
        if mech.platform == "spatial":
            return np.concatenate([p, [1.0, 0.0, 0.0, 0.0]])
        return p

    # -------------------------------------------------------------- compiled code
    def __reduce__(self):
        return (get_model, (self.mech,))

    @property
    def compiled(self) -> bool:
        """True when the compiled C Functions are in use."""
        return self.compiled_step is not None

    def result_fn(self) -> ca.Function:
        """(q_a, x) -> (Phi, W_p, T, q) in one evaluation (compiled when available)."""
        f = self.compiled_fns.get("result")
        if f is None:
            if self._result_fn is None:
                self._result_fn = fused.result_function(self)
            f = self._result_fn
        return f

    def compile(self, build: bool = True, tracker: tuple[int, int] | None = None,
                guard: int | None = None) -> bool:
        """Use compiled C versions of the step, residual, Jacobians, pose and result.

        Loads them from the disk cache, or (``build=True``) generates and compiles them
        with the system C compiler (see :mod:`optkin.model.compiled`). ``step`` becomes the
        compiled Newton step; ``phi``, ``jac`` and ``pose_fn`` stay the SX Functions (they
        are used symbolically), their compiled twins are in ``compiled_fns``. ``tracker``
        = (chunk, iters) also prepares :meth:`tracker`, the two libraries being compiled
        in parallel; ``guard`` = chunk likewise prepares :meth:`guard`. Returns whether
        compiled code is in use; without a compiler nothing changes.
        """
        want_tr = tracker is not None and (int(tracker[0]), int(tracker[1])) not in self._tracker
        want_g = guard is not None and int(guard) not in self._guard
        if self.compiled_step is not None and not want_tr and not want_g:
            return True
        if self._compile_failed and build:
            return False
        with self._compile_lock:
            reqs: list[tuple[str, list[ca.Function]]] = []
            if self.compiled_step is None:
                if self._result_fn is None:
                    self._result_fn = fused.result_function(self)
                reqs.append(("core:" + self.mech.key,
                             [self.phi, self.jac, self.step_sx, self.pose_fn, self._result_fn]))
            if want_tr:
                f_tr = self._tracker_sx(*tracker)
                reqs.append((self._tracker_tag(*tracker), [f_tr]))
            if want_g:
                f_g, tag_g = self._guard_sx(int(guard))
                reqs.append((tag_g, [f_g]))
            libs = cc.libraries(reqs, build=build)
            if want_g:
                lib_g = libs.pop()
                self._guard[int(guard)] = lib_g[f_g.name()] if lib_g is not None else f_g
            if want_tr:
                lib_tr = libs[-1]
                self._tracker[(int(tracker[0]), int(tracker[1]))] = (
                    lib_tr[f_tr.name()] if lib_tr is not None else f_tr)
            if self.compiled_step is None:
                lib = libs[0]
                if lib is None:
                    self._compile_failed = build
                    return False
                self.compiled_fns = lib
                self.step = lib["newton_step"]
                self._batch = {}
                self._gen += 1
                self.compiled_step = lib["newton_step"]
        return True

    def note_use(self) -> None:
        """Count a solve; compile (``OPTKIN_COMPILE=auto``) once the model is in heavy use."""
        self.uses += 1
        if self.uses == HOT_USES and self.compiled_step is None and cc.compile_mode() != "off":
            self.compile()

    def fast(self, name: str) -> cc.FastFn:
        """A per-thread buffered evaluator of ``newton_step``, ``result``, ``Phi``, ``W``,
        ``pose`` (compiled when available); outputs are reused buffers, copy what you keep."""
        d = getattr(self._tls, "d", None)
        if d is None or self._tls.gen != self._gen:
            d = self._tls.d = {}
            self._tls.gen = self._gen
        ev = d.get(name)
        if ev is None:
            f = self.compiled_fns.get(name)
            if f is None:
                interp = {"newton_step": self.step_sx, "Phi": self.phi, "W": self.jac,
                          "pose": self.pose_fn}
                f = interp[name] if name in interp else self.result_fn()
            ev = d[name] = cc.FastFn(f)
        return ev

    def compiled_batch_step(self, n: int) -> ca.Function:
        """The compiled Newton step mapped over n columns (threads); compiles if needed,
        falls back to the interpreted step without a compiler."""
        self.compile()
        return self.batch_step(n)

    def _tracker_sx(self, chunk: int, iters: int) -> ca.Function:
        one = fused.tracker_function(self, int(iters))
        return one.mapaccum(f"track_{int(chunk)}_{int(iters)}", int(chunk), 2)

    def _tracker_tag(self, chunk: int, iters: int) -> str:
        return f"track:{self.mech.key}:{int(chunk)}:{int(iters)}"

    def tracker(self, chunk: int, iters: int = 2) -> tuple[ca.Function, bool]:
        """The path tracker of ``forward_batch`` over ``chunk`` points (``mapaccum`` of
        :func:`optkin.model.fused.tracker_function`), and whether it is compiled."""
        key = (int(chunk), int(iters))
        f = self._tracker.get(key)
        if f is None:
            f = self._tracker_sx(chunk, iters)
            lib = cc.library(self._tracker_tag(chunk, iters), [f])
            if lib is not None:
                f = lib[f.name()]
            self._tracker[key] = f
        return f, f.is_a("External")

    def _guard_sx(self, chunk: int) -> tuple[ca.Function, str]:
        """The mapped guard and its cache tag (which hashes the inner Function: the
        signature of a mapped Function does not change with its body)."""
        one = fused.guard_function(self)
        body = hashlib.sha256(one.serialize().encode()).hexdigest()[:16]
        f = one.map(f"guard_{int(chunk)}", "serial", int(chunk), [], [])
        return f, f"guard:{self.mech.key}:{int(chunk)}:{body}"

    def guard(self, chunk: int) -> tuple[ca.Function, bool]:
        """What ``forward_batch`` checks its rows with (det W_p, conditioning,
        W_p^-1 W_a; :func:`optkin.model.fused.guard_function`) mapped over ``chunk`` rows,
        and whether it is compiled."""
        f = self._guard.get(int(chunk))
        if f is None:
            f, tag = self._guard_sx(chunk)
            lib = cc.library(tag, [f])
            if lib is not None:
                f = lib[f.name()]
            self._guard[int(chunk)] = f
        return f, f.is_a("External")

    # -------------------------------------------------------------- solvers
    def batch_step(self, n: int) -> ca.Function:
        """The Newton step mapped over n columns (threads); compiled when available."""
        f = self._batch.get(n)
        if f is None:
            f = self.step.map(n, "thread", 2)
            self._batch[n] = f
        return f

    def nlp(self) -> Any:
        """The IPOPT solver of the direct model: min |(x - x_guess)/scale|^2 s.t. Phi = 0
        (redundantly actuated platforms: min |Phi|^2, unconstrained)."""
        if self._nlp is None:
            x = self.x_sym
            p = ca.SX.sym("p", self.na + self.nx)
            qa, xg = p[: self.na], p[self.na:]
            phi = ca.substitute(self.phi_sym, self.qa_sym, qa)
            f = ca.sumsqr((x - xg) / self.x_scale)
            g = phi
            if self.m > self.nx:
                # redundant actuation: more closure rows than unknowns; IPOPT refuses an
                # overdetermined equality system, so minimise |Phi|^2 (a tiny pull towards the
                # guess keeps the Hessian regular) and let the Newton polish decide success
                f = ca.sumsqr(phi) + 1e-10 * f
                g = ca.SX(0, 1)
            opts = {
                "ipopt.print_level": 0,
                "ipopt.sb": "yes",
                "print_time": False,
                "ipopt.tol": 1e-12,
                "ipopt.constr_viol_tol": 1e-12,
                "ipopt.max_iter": 300,
                "error_on_fail": False,
            }
            t0 = time.perf_counter()
            self._nlp = ca.nlpsol("forward", "ipopt", {"x": x, "p": p, "f": f, "g": g}, opts)
            self.nlp_build_time = time.perf_counter() - t0
        return self._nlp


def damped_step(F, z, dz, scale, params, max_step: float = 1.0):
    """z + a*dz with a in {1, 1/2, ..., 1/32} minimising |F|^2 (a backtracking line search
    unrolled into the expression graph, so that it maps and compiles), the step length first
    clamped to ``max_step`` in scaled units (the threshold S of 7.9)."""
    nrm = ca.norm_2(dz / scale)
    dz = dz * ca.fmin(1, max_step / (nrm + 1e-300))
    best, nb = None, None
    for a in (1 / 32, 1 / 16, 1 / 8, 1 / 4, 1 / 2, 1.0):
        zc = z + a * dz
        nc = ca.sumsqr(F(zc, *params))
        if best is None:
            best, nb = zc, nc
        else:
            better = nc < nb
            best = ca.if_else(better, zc, best)
            nb = ca.if_else(better, nc, nb)
    return best
