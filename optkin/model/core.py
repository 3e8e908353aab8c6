"""The kinematic model: one frozen interface over every mechanism, geometry as a parameter.

``get_model(mech)`` returns the :class:`Model` of a mechanism. A model binds the numbers of
the mechanism (its geometry vector p) to the :class:`Topology` it shares with every
mechanism of the same structure: CasADi Functions of the closure residual Phi(q_a, x; p)
with independent rows [7.8]/[7.9], its Jacobians W_p = dPhi/dx and W_a = dPhi/dq_a
[7.49], a clamped Newton step (7.9), the end-effector pose, every joint value, the
joint-level closure, and lazily the compiled code, batch maps, the IPOPT solver of the
direct model and whatever a solver or analysis builds per topology (:meth:`Model.cached`).
A new geometry of a known topology compiles nothing.

Solvers and analyses see only this interface: names, scales and angle flags of the
unknowns, row names and the leg each row belongs to, conversions between joint values,
unknowns, poses and task coordinates, and the evaluators of the topology's Functions with
the geometry filled in. Models are immutable; :func:`clear_cache` empties every cache.
"""

from __future__ import annotations

import hashlib
import math
import threading
import time
from collections import OrderedDict
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .._cache import KeyedCache
from .._checks import check_mechanism
from ..errors import MechanismError
from ..mechanism import Mechanism
from ..mechanism.joints import JOINT_TYPES
from ..mechanism.platforms import PLATFORMS
from . import compiled as cc
from . import fused
from .structure import Structure, build_structure

__all__ = ["Model", "Topology", "DistanceForm", "get_model", "clear_cache"]

#: forward() calls on one model after which it is compiled (OPTKIN_COMPILE=auto)
HOT_USES = 100
#: Geometry-bound models kept (least recently used first out); topologies are all kept.
MAX_MODELS = 512

_STRUCTURES: KeyedCache[Structure] = KeyedCache()
_TOPOLOGIES: KeyedCache[Topology] = KeyedCache()
#: Per thread: (topology key, evaluator name, compiled generation) -> its FastFn, shared
#: by the geometries of the topology (:meth:`Model.fast`)
_SHARED_FAST = threading.local()
_MODELS: OrderedDict[str, Model] = OrderedDict()
_MODELS_LOCK = threading.Lock()


def get_model(mech: Mechanism) -> Model:
    """The model of ``mech``: its topology's Functions with its geometry filled in."""
    check_mechanism(mech)
    with _MODELS_LOCK:
        m = _MODELS.get(mech.key)
        if m is not None:
            _MODELS.move_to_end(mech.key)
            return m
    m = Model(mech)
    with _MODELS_LOCK:
        m = _MODELS.setdefault(mech.key, m)
        while len(_MODELS) > MAX_MODELS:
            _MODELS.popitem(last=False)
    return m


def clear_cache() -> None:
    """Forget every model, topology and everything built per topology."""
    with _MODELS_LOCK:
        _MODELS.clear()
    _SHARED_FAST.__dict__.clear()  # this thread's shared evaluators
    _TOPOLOGIES.clear()
    _STRUCTURES.clear()


def _length_scale(mech: Mechanism) -> float:
    if mech.kind == "khalil":
        vals = [abs(v) for f in mech.table.frames for v in (f.b, f.d, f.r)]
    else:
        vals = []
        for leg in mech.legs:
            vals += list(np.abs(leg.base)) + list(np.abs(leg.platform)) + list(leg.lengths)
            if not leg.base.size:  # a chain from screws: its home positions
                vals += list(np.abs(leg.home[:3, 3])) + list(np.abs(leg.platform_point))
    v = max(vals) if vals else 1.0
    return v if v > 0 else 1.0


def _select_rows(st: Structure, p: np.ndarray, mech: Mechanism, samples: int = 4,
                 seed: int = 7) -> list[int]:
    """Independent closure rows, by rank over random configurations (with these numbers).

    A row whose gradient vanishes everywhere (a planar loop's out-of-plane rows) or that is
    a combination of kept rows at every sample is dropped. A dropped row whose value is a
    non-zero constant means the loop can never close: that is a description error.
    """
    phi = st.phi
    key = ("rows", samples)
    f = st.cache.get(key)
    if f is None:  # once per structure: every geometry of it is checked with this Function,
        # all samples in one call (the rows and their Jacobians side by side), through
        # preallocated buffers (a numpy call of a Function costs 100 us)
        if phi.shape[0] == 0:  # (an SX's shape costs microseconds: looked at once)
            return []
        v = ca.vertcat(st.qa, st.x)
        one = ca.Function("rows", [v, st.p], [ca.densify(phi), ca.densify(ca.jacobian(phi, v))])
        fm = one.map("rows_map", "serial", samples, [1], [])
        rng = np.random.default_rng(seed)
        n = v.shape[0]
        Z = rng.uniform(-np.pi, np.pi, (samples, n))  # the same draws as one row at a time
        is_len = np.concatenate([np.zeros(st.qa.shape[0], bool), st.x_length])
        f = st.cache[key] = (cc.FastFn(fm), Z, is_len, threading.Lock(), int(phi.shape[0]))
    fm, Z, is_len, lock, m = f
    n = Z.shape[1]
    Z = Z * np.where(is_len, float(p[-1]) / np.pi, 1.0)
    with lock:
        out = fm(Z.ravel(), p)
        # column-major outputs: (m, samples) values, (m, n * samples) Jacobians
        V = out[0].reshape(samples, m).T.copy()
        G = out[1].reshape(n * samples, m).T.copy()
    vals = [V[:, k] for k in range(samples)]
    if not np.all(np.isfinite(G)):
        raise MechanismError("the closure rows are not finite at random configurations; "
                             "check the geometry", path=())
    scale = max(1.0, float(np.abs(G).max()))
    sv = np.linalg.svd(G, compute_uv=False)  # (numpy's matrix_rank, without its overhead)
    if int(np.sum(sv > 1e-9 * scale)) == G.shape[0]:
        # every row independent (the usual case): the loop below would keep them all,
        # since a subset of rows of a full-rank G has no smaller singular value
        return list(range(G.shape[0]))
    kept: list[int] = []
    basis = np.zeros((0, G.shape[1]))
    for i in range(G.shape[0]):
        cand = np.vstack([basis, G[i]])
        if np.linalg.matrix_rank(cand, tol=1e-9 * scale) > basis.shape[0]:
            kept.append(i)
            basis = cand
        elif np.allclose(G[i], 0.0, atol=1e-12 * scale):
            const = np.array([vv[i] for vv in vals])
            if np.all(np.isfinite(const)) and np.max(np.abs(const)) > 1e-9:
                raise MechanismError(
                    f"{st.row_names[i]}: this closure row is the constant {const[0]:.6g} for "
                    "every configuration, so the loop can never close; check the offsets "
                    "(b, r, d) of the frames of this loop")
    return kept


class Topology:
    """The Functions of one mechanism topology, with the geometry p as their last input.

    Shared by every mechanism of the structure (:attr:`Mechanism.topology`) and the same
    independent rows; compiled once. Everything a solver or analysis builds lazily for a
    topology lives in :meth:`cached`.
    """

    def __init__(self, st: Structure, keep: list[int], key: str, redundant: bool) -> None:
        self.st = st
        self.key = key
        self.keep = tuple(keep)
        qa, x, p = st.qa, st.x, st.p
        self.na, self.nx = int(qa.shape[0]), int(x.shape[0])
        phi = st.phi[list(keep)] if keep else ca.SX(0, 1)
        self.m = int(phi.shape[0])
        if self.m < self.nx:
            raise MechanismError(
                f"the loops give {self.m} independent closure equations for {self.nx} "
                f"unknowns: the mechanism has {self.nx - self.m} more degree(s) of freedom "
                "than actuated joints; actuate more joints or add loops")
        self.row_names = [st.row_names[i] for i in keep]
        self.row_length = st.row_length[list(keep)] if keep else np.zeros(0, bool)
        self.row_leg = st.row_leg[list(keep)] if keep else np.zeros(0, int)
        self.phi_sym = phi
        # the scale of every unknown: lengths scale with the mechanism (p[-1])
        L = p[p.shape[0] - 1]
        self.x_scale_sym = ca.vertcat(*[L if st.x_length[i] else ca.SX(1)
                                        for i in range(self.nx)]) if self.nx else ca.SX(0, 1)
        Wp = ca.jacobian(phi, x)
        Wa = ca.jacobian(phi, qa)
        self.phi = ca.Function("Phi", [qa, x, p], [phi], ["qa", "x", "p"], ["Phi"])
        self.jac = ca.Function("W", [qa, x, p], [phi, Wp, Wa], ["qa", "x", "p"],
                               ["Phi", "W_p", "W_a"])
        self.pose_fn = ca.Function("pose", [qa, x, p], [st.T], ["qa", "x", "p"], ["T"])
        if self.m == self.nx:
            dx = -ca.solve(Wp, phi)
        else:
            dx = -ca.solve(ca.mtimes(Wp.T, Wp), ca.mtimes(Wp.T, phi))
        fphi = ca.Function("Phi_x", [x, qa, p], [phi])
        xn = damped_step(fphi, x, dx, self.x_scale_sym, [qa, p])
        res = ca.mmax(ca.fabs(phi)) if self.m else ca.SX(0)
        self.step_sx = ca.Function("newton_step", [qa, x, p], [xn, res], ["qa", "x", "p"],
                                   ["x_next", "res"])
        self.q_fn = ca.Function("q", [qa, x, p], [st.q], ["qa", "x", "p"], ["q"])
        self.result_sx = fused.result_function(self)
        self.compiled_fns: dict[str, ca.Function] = {}
        self._store: dict[Hashable, Any] = {}
        self._lock = threading.RLock()
        self._compile_failed = False
        self._core_key: str | None = None

    # -------------------------------------------------------------- per-topology store
    def cached(self, key: Hashable, build: Callable[[], Any]) -> Any:
        """``build()`` once per key for this topology (thread-safe)."""
        v = self._store.get(key)
        if v is None:
            with self._lock:
                v = self._store.get(key)
                if v is None:
                    v = build()
                    self._store[key] = v
        return v

    def forget(self, key: Hashable) -> None:
        """Drop what :meth:`cached` keeps under ``key`` (a result that must not be reused)."""
        with self._lock:
            self._store.pop(key, None)

    @property
    def compiled(self) -> bool:
        return "newton_step" in self.compiled_fns

    def core_functions(self) -> list[ca.Function]:
        return [self.phi, self.jac, self.step_sx, self.pose_fn, self.result_sx]

    def compile(self, build: bool = True, extra: list[tuple[str, list[ca.Function]]] = ()
                ) -> list[dict[str, ca.Function] | None]:
        """Load (or build) the compiled twins of the core Functions and of ``extra``
        libraries; returns the extra libraries (None where compiling is unavailable)."""
        with self._lock:
            reqs: list[tuple] = []
            want_core = not self.compiled and not (self._compile_failed and build)
            if want_core:
                # the key once per topology: each new geometry's Model asks again (in the
                # "auto" mode, a load that finds nothing until the core is compiled)
                if self._core_key is None:
                    self._core_key = cc._digest("core:" + self.key, self.core_functions())
                reqs.append(("core:" + self.key, self.core_functions(), self._core_key))
            reqs += list(extra)
            libs = cc.libraries(reqs, build=build) if reqs else []
            if want_core:
                lib = libs.pop(0)
                if lib is None:
                    self._compile_failed = build
                else:
                    self.compiled_fns = lib
            return libs


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


def _topology_for(mech: Mechanism, p: np.ndarray) -> Topology:
    st = _STRUCTURES.get(mech.topology, lambda: build_structure(mech))
    keep = _select_rows(st, p, mech)
    full = (mech.topology, tuple(keep))
    return _TOPOLOGIES.get(full, lambda: Topology(
        st, keep, hashlib.sha256(repr(full).encode()).hexdigest()[:16], mech.redundant))


class Model:
    """A mechanism's Functions with its geometry filled in. Build with :func:`get_model`.

    Attributes
    ----------
    mech : Mechanism
    topology : Topology
        The shared Functions (their last input is the geometry :attr:`p`).
    p : ndarray
        The geometry vector (read-only), the mechanism's length scale last.
    na, nx, m : int
        Actuated joints, unknowns, independent closure rows.
    x_names, x_angle, x_scale :
        Names of the unknowns, which are angles, and their scales (lengths: the
        mechanism's size; angles and unit quaternions: 1).
    row_names, row_leg, row_length :
        The closure rows: names, the leg each belongs to (-1 for none), which are lengths.
    length : float
        The mechanism's size (largest offset or length of its description).
    """

    __slots__ = ("mech", "topology", "p", "length", "na", "nx", "m", "x_names", "x_angle",
                 "x_scale", "row_names", "row_leg", "row_length", "passive_index", "qp_index", "qc_index",
                 "qa_positive", "build_time", "_tls", "_uses", "_frozen", "_spherical",
                 "__weakref__")

    def __init__(self, mech: Mechanism) -> None:
        t0 = time.perf_counter()
        set_ = object.__setattr__
        set_(self, "mech", mech)
        L = _length_scale(mech)
        p = np.concatenate([mech.geometry, [L]])
        p.setflags(write=False)
        topo = _topology_for(mech, p)
        st = topo.st
        set_(self, "topology", topo)
        set_(self, "p", p)
        set_(self, "length", L)
        set_(self, "na", topo.na)
        set_(self, "nx", topo.nx)
        set_(self, "m", topo.m)
        set_(self, "x_names", tuple(st.x_names))
        xa = np.array(st.x_angle, dtype=bool)
        xa.setflags(write=False)
        set_(self, "x_angle", xa)
        xs = np.where(st.x_length, L, 1.0)
        xs.setflags(write=False)
        set_(self, "x_scale", xs)
        set_(self, "row_names", list(topo.row_names))
        set_(self, "row_leg", topo.row_leg.copy())
        set_(self, "row_length", topo.row_length.copy())
        act = np.array(mech.actuated, dtype=bool)
        set_(self, "passive_index", np.flatnonzero(~act))
        cut = set(mech.cut_names)
        is_cut = np.array([n in cut for n in mech.joint_names], dtype=bool)
        set_(self, "qp_index", np.flatnonzero(~act & ~is_cut))
        set_(self, "qc_index", np.flatnonzero(is_cut))
        qpos = np.zeros(topo.na, dtype=bool)
        s_x: list[tuple[int, int, int]] = []
        s_q: list[tuple[int, int, int]] = []
        if mech.kind == "legs":
            k = 0
            for leg, sl in zip(mech.legs, st.legs):
                for a in leg.actuated:
                    qpos[k] = (leg.distance is not None and leg.distance.length is None
                               and leg.kinds[a] == "P") or a in leg.positive
                    k += 1
                # spherical joints solved in chain form: three angles, two branches of one
                # rotation (canonical: the middle angle's cosine >= 0)
                v = 0
                for c in leg.joints:
                    n_ = len(JOINT_TYPES[c].kinds)
                    if c == "S" and not sl.reduced and sl.q.start + v not in sl.reported:
                        s_q.append(tuple(sl.q.start + v + i for i in range(3)))
                    v += n_
            xpos = {}
            for sl, leg in zip(st.legs, mech.legs):
                free = [v_ for v_ in range(len(leg.names)) if v_ not in leg.actuated
                        and sl.q.start + v_ not in sl.reported]
                if not sl.reduced:
                    for v_, xi in zip(free, sl.x):
                        xpos[sl.q.start + v_] = xi
            s_x = [tuple(xpos[i] for i in t) for t in s_q if all(i in xpos for i in t)]
        set_(self, "qa_positive", qpos)
        set_(self, "_spherical", (tuple(s_x), tuple(s_q)))
        set_(self, "_tls", threading.local())
        set_(self, "_uses", [0])
        mode = cc.compile_mode()
        if mode != "off":
            topo.compile(build=mode == "eager")
        set_(self, "build_time", time.perf_counter() - t0)
        set_(self, "_frozen", True)

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("a Model is immutable; per-topology data goes in Model.cached")

    def __reduce__(self):
        return (get_model, (self.mech,))

    # -------------------------------------------------------------- structure
    @property
    def structure(self) -> Structure:
        return self.topology.st

    @property
    def task_names(self) -> tuple[str, ...]:
        """The names of the mechanism's task coordinates (``mech.task``)."""
        return tuple(self.mech.task)

    @property
    def task_space(self) -> str:
        """The kind of task coordinates (:func:`optkin.mechanism.tasks.task_space`)."""
        from ..mechanism.tasks import task_space

        return task_space(self.mech)

    @property
    def platform(self):
        """The platform kind class (legs), or None (Khalil tables)."""
        st = self.topology.st
        return PLATFORMS[st.platform] if st.platform else None

    @property
    def leg_labels(self) -> tuple[str, ...]:
        """The type (or joint string) of each leg, for messages; empty for Khalil tables."""
        return tuple(leg.type for leg in self.mech.legs)

    @property
    def n_platform(self) -> int:
        """How many leading unknowns are the platform's coordinates (0 for Khalil)."""
        return self.topology.st.n_platform

    @property
    def symbols(self) -> tuple[ca.SX, ca.SX, ca.SX, ca.SX]:
        """(q_a, x, p, Phi) as SX: build Functions with p as an input and call them with
        :attr:`p` (or through :meth:`bind`)."""
        t = self.topology
        return t.st.qa, t.st.x, t.st.p, t.phi_sym

    def cached(self, key: Hashable, build: Callable[[], Any]) -> Any:
        """Something built once per topology (Functions, maps, masks)."""
        return self.topology.cached(key, build)

    def bind(self, f: ca.Function) -> Callable[..., Any]:
        """``f`` with its last input (the geometry) filled in."""
        p = self.p

        def call(*args: Any) -> Any:
            return f(*args, p)

        return call

    # -------------------------------------------------------------- evaluations
    @property
    def phi(self) -> Callable[..., Any]:
        return self.bind(self.topology.phi)

    @property
    def jac(self) -> Callable[..., Any]:
        return self.bind(self.topology.jac)

    @property
    def pose_fn(self) -> Callable[..., Any]:
        return self.bind(self.topology.pose_fn)

    def residual(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.array(self.topology.phi(qa, x, self.p)).ravel()

    def pose(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        return np.array(self.topology.pose_fn(qa, x, self.p))

    def fast(self, name: str) -> cc.BoundFast:
        """A per-thread buffered evaluator of ``newton_step``, ``result``, ``Phi``, ``W``,
        ``pose`` (compiled when available), the geometry filled in; outputs are reused
        buffers, copy what you keep. The buffers are the topology's, shared in the thread by
        every geometry (:class:`optkin.model.compiled.BoundFast`)."""
        topo = self.topology
        d = getattr(self._tls, "d", None)
        gen = len(topo.compiled_fns)
        if d is None or self._tls.gen != gen:
            d = self._tls.d = {}
            self._tls.gen = gen
        ev = d.get(name)
        if ev is None:
            shared = getattr(_SHARED_FAST, "d", None)
            if shared is None:
                shared = _SHARED_FAST.d = {}
            key = (topo.key, name, gen)
            ev_t = shared.get(key)
            if ev_t is None:
                f = topo.compiled_fns.get(name)
                if f is None:
                    f = {"newton_step": topo.step_sx, "Phi": topo.phi, "W": topo.jac,
                         "pose": topo.pose_fn, "result": topo.result_sx}[name]
                ev_t = shared[key] = cc.FastFn(f, fixed=(self.p,))
            ev = d[name] = cc.BoundFast(ev_t, (self.p,))
        return ev

    # -------------------------------------------------------------- conversions
    def to_q(self, qa: np.ndarray, x: np.ndarray) -> np.ndarray:
        """All joint values (``mech.joint_names`` order) from q_a and the unknowns x."""
        return np.array(self.topology.q_fn(qa, x, self.p)).ravel()

    def qa_of(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q, dtype=float)[np.array(self.mech.actuated)]

    def x_from_q(self, q: np.ndarray, pose: np.ndarray | None = None) -> np.ndarray:
        """The unknowns x of a full joint vector (platforms: the given ``pose``, else the
        pose that best fits the legs' chains; then the legs' solved variables)."""
        q = np.asarray(q, dtype=float)
        st = self.topology.st
        if st.platform is None:
            return q[~np.array(self.mech.actuated)].copy()
        if pose is not None:
            x = np.zeros(self.nx)
            x[: self.n_platform] = self.platform.x_from_pose(np.asarray(pose, dtype=float))
            self._solved_from_q(q, x)
            return x
        frames = self.cached("leg_frames", lambda: ca.Function(
            "leg_frames", [st.z[: len(self.mech.joint_names)], st.p],
            [ca.horzcat(*[T.reshape((16, 1)) for T in st.leg_frames])]))
        F = np.array(frames(q, self.p)).reshape((16, -1), order="F")
        plat = self.platform
        pts, ref, rots = [], [], []
        for k, leg in enumerate(self.mech.legs):
            T = F[:, k].reshape((4, 4), order="F")
            if leg.end == "frame" or leg.reported:
                rots.append(T[:3, :3] if leg.end == "frame" else T[:3, :3])
            if leg.end == "point":
                pts.append(T[:3, 3])
                ref.append(np.asarray(leg.platform_point, dtype=float))
            else:
                pts.append(T[:3, 3])
                ref.append(np.zeros(3))
        R, pvec = _fit_pose(np.array(pts), np.array(ref), rots, plat)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, pvec
        x = np.zeros(self.nx)
        x[: st.n_platform] = plat.x_from_pose(T)
        self._solved_from_q(q, x)
        return x

    def _solved_from_q(self, q: np.ndarray, x: np.ndarray, only: int | None = None) -> None:
        """Copy the legs' solved variables (chain form) from q into x (leg ``only``)."""
        st = self.topology.st
        for k, (sl, leg) in enumerate(zip(st.legs, self.mech.legs)):
            if sl.reduced or (only is not None and k != only):
                continue
            n = len(leg.names)
            free = [v for v in range(n) if v not in leg.actuated
                    and sl.q.start + v not in sl.reported]
            for v, xi in zip(free, sl.x):
                x[xi] = q[sl.q.start + v]

    def x_from_pose(self, T: np.ndarray, qa: np.ndarray | None = None) -> np.ndarray:
        """The unknowns x of a platform pose; the variables of legs in chain form solved
        for that pose (with the actuated values ``qa`` when given), nearest their home
        values. A Khalil mechanism's direct model cannot start from a pose."""
        plat = self.platform
        if plat is None:
            raise MechanismError(
                "guess: a pose cannot seed a Khalil mechanism's direct model; give joint values")
        x = np.zeros(self.nx)
        x[: self.n_platform] = plat.x_from_pose(np.asarray(T, dtype=float))
        self._chain_legs_at(x, qa)
        return x

    def _chain_legs_at(self, x: np.ndarray, qa: np.ndarray | None) -> None:
        """Fill the variables of legs in chain form for the platform coordinates in x: a
        Gauss-Newton search over them (the platform fixed) from their home values and a
        few spread starts, keeping the solution nearest home. Without ``qa`` the actuated
        variables are searched too (each leg's inverse)."""
        from .inverse import SearchPart

        st = self.topology.st
        idx = [i for sl in st.legs if not sl.reduced for i in sl.x]
        if not idx:
            return
        idx_a = np.array(idx, dtype=int)
        ang = self.x_angle[idx_a]
        starts = [np.zeros(idx_a.size)] + [np.where(ang, a, 0.0)
                                            for a in (np.pi / 2, -np.pi / 2, np.pi)]
        tol = 1e-9 * max(1.0, self.length)
        if qa is None:  # each leg on its own, its actuated variables free
            nq = len(self.mech.joint_names)
            for part in self.inverse_parts():
                if not isinstance(part, SearchPart) or part.leg < 0:
                    continue
                step = part.stages[0].step
                n = len(part.vars)
                best = _nearest_root(
                    lambda z, step=step: step(z, x[: self.n_platform], self.p),
                    [np.where(part.angle, a, 0.0) for a in (0.0, np.pi / 2, -np.pi / 2, np.pi)]
                    if n else [], part.angle, self.length, tol)
                if best is not None:
                    q = np.zeros(nq)
                    q[list(part.vars)] = best
                    self._solved_from_q(q, x, only=part.leg)
            return
        f = self.cached("passive_step", lambda: _passive_step(self.topology))
        qa = np.asarray(qa, dtype=float)

        def step(z):
            xx = x.copy()
            xx[idx_a] = z
            xn, r = f(qa, xx, self.p)
            return np.array(xn).ravel()[idx_a], r

        best = _nearest_root(step, starts, ang, self.length, tol, lsq=True)
        if best is not None:
            x[idx_a] = best

    def x_from_task(self, t: np.ndarray, qa: np.ndarray | None = None) -> np.ndarray:
        plat = self.platform
        if plat is None:
            raise MechanismError("guess: task coordinates cannot seed a Khalil mechanism's "
                                 "direct model; give joint values")
        return self.x_from_pose(plat.task_to_pose(np.asarray(t, dtype=float)), qa)

    def canonical_x(self, x: np.ndarray) -> np.ndarray:
        """Angles wrapped to (-pi, pi], quaternions normalised with w >= 0."""
        x = np.array(x, dtype=float)
        for i in np.flatnonzero(self.x_angle):
            if math.isfinite(x[i]):
                a = math.remainder(x[i], 2 * math.pi)
                x[i] = math.pi if a <= -math.pi else a
        plat = self.platform
        if plat is not None and plat.norm_row:
            x[: self.n_platform] = plat.canonical(x[: self.n_platform])
        _canonical_spherical(x, self._spherical[0])
        return x

    def canonical_q(self, q: np.ndarray) -> np.ndarray:
        """Joint values with the angles of spherical joints on their canonical branch."""
        q = np.array(q, dtype=float)
        _canonical_spherical(q, self._spherical[1])
        return q

    def default_x(self, qa: np.ndarray) -> np.ndarray:
        """A default starting point: the mechanism's home, else a central configuration."""
        mech = self.mech
        plat = self.platform
        if plat is None:
            if mech.home is not None:
                return np.asarray(mech.home, dtype=float)[self.passive_index].copy()
            return np.full(self.nx, 0.1)
        if mech.home is not None:
            return self.x_from_task(mech.home, qa)
        legs = mech.legs
        base = np.mean([_pad3(leg.base) if leg.base.size else leg.home[:3, 3]
                        for leg in legs], axis=0)
        pts = np.mean([_pad3(leg.platform) if leg.platform.size else leg.platform_point
                       for leg in legs], axis=0)
        p = base - pts
        if plat.name == "planar_point":
            p = p + np.array([0.0, 0.5 * self.length, 0.0])
        elif plat.space_dim == 3:
            lens = [sum(leg.lengths) for leg in legs if leg.lengths]
            if lens and all(leg.distance is not None and leg.distance.length is not None
                            for leg in legs):
                reach = -0.7 * float(np.mean(lens))
            else:
                reach = float(np.mean(qa)) if np.size(qa) else 0.0
            p = p + np.array([0.0, 0.0, reach])
        T = np.eye(4)
        T[:3, 3] = p
        return self.x_from_pose(T, qa)

    # -------------------------------------------------------------- compiled code
    @property
    def compiled(self) -> bool:
        """True when the compiled C Functions are in use."""
        return self.topology.compiled

    @property
    def compiled_fns(self) -> dict[str, ca.Function]:
        return self.topology.compiled_fns

    @property
    def step(self) -> ca.Function:
        """The Newton step (q_a, x, p) -> (x_next, res), compiled when available."""
        return self.topology.compiled_fns.get("newton_step", self.topology.step_sx)

    @property
    def step_sx(self) -> ca.Function:
        return self.topology.step_sx

    def result_fn(self) -> ca.Function:
        """(q_a, x, p) -> (Phi, W_p, T, q) in one evaluation (compiled when available)."""
        return self.topology.compiled_fns.get("result", self.topology.result_sx)

    def compile(self, build: bool = True, tracker: tuple[int, int] | None = None,
                guard: int | None = None) -> bool:
        """Use compiled C versions of the topology's Functions (and prepare the tracker
        of ``forward_batch`` over ``tracker`` = (chunk, iters) points and its guard over
        ``guard`` rows, compiled in parallel). Returns whether compiled code is in use."""
        topo = self.topology
        extra: list[tuple[str, list[ca.Function]]] = []
        tr_key = g_key = None
        if tracker is not None:
            tr_key = ("tracker", int(tracker[0]), int(tracker[1]))
            if tr_key not in topo._store:
                f_tr = fused.tracker_chunk(topo, int(tracker[0]), int(tracker[1]))
                extra.append((f"track:{topo.key}:{int(tracker[0])}:{int(tracker[1])}", [f_tr]))
        if guard is not None:
            g_key = ("guard", int(guard))
            if g_key not in topo._store:
                f_g, tag = fused.guard_chunk(topo, int(guard))
                extra.append((tag, [f_g]))
        libs = topo.compile(build=build, extra=extra)
        for (tag, fs), lib in zip(extra, libs):
            f = fs[0]
            key = tr_key if tag.startswith("track:") else g_key
            topo._store[key] = lib[f.name()] if lib is not None else f
        return topo.compiled

    def note_use(self) -> None:
        """Count a solve; compile (``OPTKIN_COMPILE=auto``) once the model is in heavy use."""
        self._uses[0] += 1
        if self._uses[0] == HOT_USES and not self.compiled and cc.compile_mode() != "off":
            self.compile()

    def tracker(self, chunk: int, iters: int = 2) -> tuple[ca.Function, bool]:
        """The path tracker of ``forward_batch`` over ``chunk`` points (inputs x0, q_a0,
        QA, p) and whether it is compiled."""
        topo = self.topology
        key = ("tracker", int(chunk), int(iters))

        def build() -> ca.Function:
            f = fused.tracker_chunk(topo, int(chunk), int(iters))
            lib = cc.library(f"track:{topo.key}:{int(chunk)}:{int(iters)}", [f])
            return lib[f.name()] if lib is not None else f

        f = topo.cached(key, build)
        return f, f.is_a("External")

    def guard(self, chunk: int) -> tuple[ca.Function, bool]:
        """The row checks of ``forward_batch`` mapped over ``chunk`` rows (geometry as the
        last, unmapped input) and whether they are compiled."""
        topo = self.topology

        def build() -> ca.Function:
            f, tag = fused.guard_chunk(topo, int(chunk))
            lib = cc.library(tag, [f])
            return lib[f.name()] if lib is not None else f

        f = topo.cached(("guard", int(chunk)), build)
        return f, f.is_a("External")

    def batch_step(self, n: int) -> ca.Function:
        """The Newton step mapped over n columns, the geometry unmapped (serially: CasADi's
        threaded map with unmapped inputs ran 5-15x slower here)."""
        topo = self.topology
        return topo.cached(("batch", int(n), topo.compiled), lambda: self.step.map(
            f"newton_step_{int(n)}", "serial", int(n), [2], []))

    def compiled_batch_step(self, n: int) -> ca.Function:
        """The compiled Newton step mapped over n columns; compiles if needed (falls back
        to the interpreted step without a compiler)."""
        self.compile()
        return self.batch_step(n)

    def inverse_parts(self) -> list:
        """The parts of the inverse geometric model (:mod:`optkin.model.inverse`), built
        once per topology (their Newton steps compiled when a compiler is present)."""
        topo = self.topology

        def build() -> list:
            from . import inverse as inv

            parts = inv.inverse_parts(topo, self.mech)
            steps = [st_.step for part in parts if isinstance(part, inv.SearchPart)
                     for st_ in part.stages]
            lib = cc.library("inv:" + topo.key, steps) if steps else None
            if lib is None:
                return parts
            out = []
            for part in parts:
                if isinstance(part, inv.SearchPart):
                    stages = tuple(inv.Stage(lib[s_.step.name()], s_.idx) for s_ in part.stages)
                    part = inv.SearchPart(part.vars, part.angle, part.length, stages,
                                          part.pose_kind, part.check, part.leg, part.extra)
                out.append(part)
            return out

        return topo.cached("inverse_parts", build)

    @property
    def fully_parallel(self) -> bool:
        """Every leg a distance leg with one actuator and one row (Chablat and Wenger's
        fully parallel mechanisms): W_a is diagonal and its signs are the working mode."""
        st = self.topology.st
        return bool(st.legs) and all(sl.reduced and len(sl.qa) == 1 for sl in st.legs) \
            and self.m == self.na + (1 if self.platform.norm_row else 0)

    @property
    def working_mode_signs(self) -> tuple[tuple[int, ...], ...] | None:
        """For each actuator, the signs its diagonal entry of B can take (fully parallel
        mechanisms): a leg whose actuated joint moves its centre has two postures (+1, -1);
        one whose actuated joint is the distance has B_jj = -1 always. None otherwise."""
        if not self.fully_parallel:
            return None
        return tuple((-1,) if leg.distance.length is None else (1, -1)
                     for leg in self.mech.legs)

    def working_modes(self) -> list[tuple[int, ...]]:
        """Every sign pattern of diag(B) (Chablat and Wenger, Definition 4), in one order
        (+1 before -1, the first leg slowest); empty when not fully parallel."""
        import itertools

        signs = self.working_mode_signs
        return [] if signs is None else [tuple(m_) for m_ in itertools.product(*signs)]

    def distance_form(self) -> DistanceForm | None:
        """The legs as distance constraints |P_i - C_i(q_a)| = r_i(q_a) (every leg in the
        reduced form), else None: centres and radii per actuated values, platform points."""
        st = self.topology.st
        if not st.legs or not all(sl.reduced for sl in st.legs):
            return None
        fn = self.cached("distance_form", lambda: ca.Function(
            "distance_form", [st.qa, st.p],
            [ca.horzcat(*[d[0] for d in st.distance]),
             ca.horzcat(*[d[2] for d in st.distance])], ["qa", "p"], ["C", "r"]))
        legs = self.mech.legs
        return DistanceForm(
            fn=fn, p=self.p,
            platform_points=np.array([leg.platform_point for leg in legs], dtype=float),
            length_actuated=np.array([leg.distance.length is None for leg in legs]),
            driver_revolute=np.array([leg.distance.driver > 0 and leg.kinds[0] == "R"
                                      for leg in legs]),
            space_dim=self.platform.space_dim)

    def working_mode(self, qa: np.ndarray, x: np.ndarray) -> tuple[int, ...] | None:
        """The signs of the diagonal of B = W_a (fully parallel mechanisms), else None."""
        if not self.fully_parallel:
            return None
        ev = self.fast("W")
        ev(qa, x)
        Wa = ev.dense(2)
        return tuple(int(np.sign(Wa[i, i])) for i in range(self.na))

    def nlp(self) -> Any:
        """The IPOPT solver of the direct model: min |(x - x_guess)/scale|^2 s.t. Phi = 0
        (redundantly actuated: min |Phi|^2), parameters (q_a, x_guess, geometry)."""
        return self.topology.cached("nlp", lambda: _build_nlp(self.topology))

    @property
    def nlp_build_time(self) -> float:
        return float(self.topology.cached("nlp_build_time", lambda: 0.0))


@dataclass(frozen=True)
class DistanceForm:
    """Legs as distance constraints |P_i - C_i(q_a)| = r_i(q_a) (see
    :meth:`Model.distance_form`).

    Attributes
    ----------
    platform_points : ndarray (n, 3)
        P_i in the platform frame.
    length_actuated : ndarray (n,) of bool
        The actuated joint is the distance (RPR, UPS): C_i fixed, r_i = q_a,i.
    driver_revolute : ndarray (n,) of bool
        The actuated joint turns C_i about an axis (RRR, RUS): C_i on a circle.
    space_dim : int
    """

    fn: ca.Function
    p: np.ndarray
    platform_points: np.ndarray
    length_actuated: np.ndarray
    driver_revolute: np.ndarray
    space_dim: int

    def centres_radii(self, QA: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """C (N, n, 3) and r (N, n) for N rows of actuated values (N, na)."""
        QA = np.atleast_2d(np.asarray(QA, dtype=float))
        N = QA.shape[0]
        # (one row in every caller; more rows map serially with the geometry shared)
        f = self.fn.map(f"{self.fn.name()}_{N}", "serial", N, [1], []) if N > 1 else self.fn
        C, r = f(QA.T, self.p)
        n = self.platform_points.shape[0]
        C = np.array(C).reshape((3, N, n), order="F").transpose(1, 2, 0)
        r = np.array(r).reshape((N, n))
        return C, r


def _build_nlp(topo: Topology) -> Any:
    st = topo.st
    x = st.x
    na, nx = topo.na, topo.nx
    npar = st.p.shape[0]
    P = ca.SX.sym("p", na + nx + npar)
    qa, xg, pg = P[:na], P[na: na + nx], P[na + nx:]
    phi = ca.substitute(topo.phi_sym, ca.vertcat(st.qa, st.p), ca.vertcat(qa, pg))
    scale = ca.substitute(topo.x_scale_sym, st.p, pg)
    f = ca.sumsqr((x - xg) / scale)
    g = phi
    if topo.m > nx:
        # redundant actuation: more closure rows than unknowns; IPOPT refuses an
        # overdetermined equality system, so minimise |Phi|^2 (a tiny pull towards the
        # guess keeps the Hessian regular) and let the Newton polish decide success
        f = ca.sumsqr(phi) + 1e-10 * f
        g = ca.SX(0, 1)
    opts = {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False,
            "ipopt.tol": 1e-12, "ipopt.constr_viol_tol": 1e-12, "ipopt.max_iter": 300,
            "error_on_fail": False}
    t0 = time.perf_counter()
    solver = ca.nlpsol("forward", "ipopt", {"x": x, "p": P, "f": f, "g": g}, opts)
    topo._store["nlp_build_time"] = time.perf_counter() - t0
    return solver


def _canonical_spherical(v: np.ndarray, triplets) -> None:
    """(a, b, c) -> (a + pi, pi - b, c + pi) where cos b < 0: the same rotation
    Rot(a) Rot(b) Rot(c) about orthonormal axes, with b in [-pi/2, pi/2]; angles wrapped."""
    for i, j, k in triplets:
        if math.isfinite(v[j]) and math.cos(v[j]) < 0:
            v[i], v[j], v[k] = v[i] + math.pi, math.pi - v[j], v[k] + math.pi
        for t in (i, j, k):
            if math.isfinite(v[t]):
                a = math.remainder(v[t], 2 * math.pi)
                v[t] = math.pi if a <= -math.pi else a


def _passive_step(topo: Topology) -> ca.Function:
    """A Gauss-Newton step over the variables of legs in chain form, the platform and q_a
    fixed: (q_a, x, p) -> (x_next, max |Phi|)."""
    st = topo.st
    idx = [i for sl in st.legs if not sl.reduced for i in sl.x]
    z = st.x[idx]
    phi = topo.phi_sym
    J = ca.jacobian(phi, z)
    dz = -ca.solve(ca.mtimes(J.T, J) + 1e-12 * ca.DM.eye(len(idx)), ca.mtimes(J.T, phi))
    xn = ca.SX(st.x)
    for k, i in enumerate(idx):
        xn[i] = st.x[i] + dz[k]
    res = ca.mmax(ca.fabs(phi)) if topo.m else ca.SX(0)
    return ca.Function("passive_step", [st.qa, st.x, st.p], [xn, res])


def _nearest_root(step, starts, angle, length, tol, iters: int = 40, lsq: bool = False):
    """Iterate ``step(z) -> (z_next, res)`` from each start; the converged z nearest zero
    (angles wrapped, lengths scaled), or None. With ``lsq`` (a guess that need not close)
    the points of smallest residual count as converged."""
    found = []
    for z in starts:
        z = np.array(z, dtype=float)
        r = np.inf
        for _ in range(iters):
            zn, r = step(z)
            zn = np.array(zn).ravel()
            if not np.all(np.isfinite(zn)):
                break
            z = zn
        if np.all(np.isfinite(z)) and math.isfinite(float(r)):
            zw = np.where(angle, np.remainder(z + np.pi, 2 * np.pi) - np.pi, z)
            found.append((float(r), float(np.linalg.norm(np.where(angle, zw, z / length))), zw))
    if not found:
        return None
    rmin = min(f[0] for f in found)
    limit = max(tol, 1.01 * rmin + tol) if lsq else tol
    ok = [f for f in found if f[0] <= limit]
    return min(ok, key=lambda f: f[1])[2] if ok else None


def _pad3(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float).ravel()
    return np.concatenate([v, np.zeros(3 - v.size)]) if v.size < 3 else v


def _fit_pose(E: np.ndarray, B: np.ndarray, rots: list[np.ndarray], plat) -> tuple:
    """The platform pose (R, p) with R b_i + p closest to e_i (Kabsch) and R closest to
    the chains' end orientations ``rots`` when the platform turns."""
    if not plat.rotates:
        return np.eye(3), np.mean(E - B, axis=0)
    if rots:  # chains reaching the platform frame give the orientation
        M = np.sum(rots, axis=0)
        U, _, Vt = np.linalg.svd(M)
        R = U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        return R, np.mean(E - B @ R.T, axis=0)
    if plat.space_dim == 2:
        e, b = E[:, :2] - E[:, :2].mean(0), B[:, :2] - B[:, :2].mean(0)
        H = b.T @ e
        phi = math.atan2(H[0, 1] - H[1, 0], H[0, 0] + H[1, 1])
        R = np.array([[math.cos(phi), -math.sin(phi), 0], [math.sin(phi), math.cos(phi), 0],
                      [0, 0, 1.0]])
    else:
        e, b = E - E.mean(0), B - B.mean(0)
        U, _, Vt = np.linalg.svd(b.T @ e)
        D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
    return R, np.mean(E - B @ R.T, axis=0)
