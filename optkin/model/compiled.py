"""Compiled CasADi Functions: C code generated once per mechanism and cached on disk.

A model's Functions (closure residual, Jacobians, the damped Newton step, poses, the fused
result evaluation, the path tracker of :func:`optkin.forward_batch`) are generated to C with
``casadi.CodeGenerator``, built into a shared library with the system C compiler
(``gcc -O1 -shared -fPIC``) and loaded back with ``casadi.external``. The library is cached
on disk under a name that hashes the mechanism's content key, the CasADi version,
:data:`CODE_VERSION` and the Functions' signatures, so a second process loads it in
milliseconds. Whenever something is missing (no compiler, a read-only disk, a failed
build) the interpreted SX Functions are used instead, silently (a ``logging`` debug line
says why).

Environment variables
---------------------
``OPTKIN_COMPILE``
    ``auto`` (default): load a cached library when the model is built, compile on demand
    (``forward_batch``, ``Model.compile()``, or a model that has served many ``forward``
    calls); ``eager``: compile when the model is built; ``off`` (or ``0``): never.
``OPTKIN_CACHE``
    The cache directory (default ``$XDG_CACHE_HOME/optkin`` or ``~/.cache/optkin``; when
    that is not writable, a directory under the system temp dir).
``OPTKIN_CC``
    The C compiler (default ``$CC``, else ``gcc``, else ``cc``). Set it to a name that does
    not exist to simulate a machine without a compiler.
"""

from __future__ import annotations

import hashlib
import logging
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path

import casadi as ca
import numpy as np

__all__ = [
    "CODE_VERSION",
    "FastFn",
    "cache_dir",
    "compile_mode",
    "find_compiler",
    "library",
]

log = logging.getLogger("optkin.compiled")

#: Bump when the generated Functions change meaning (part of every cache key).
CODE_VERSION = "2"

_FLAGS = ("-O1", "-shared", "-fPIC")  # -O2 compiles twice as long, runs no faster
_BUILD_LOCK = threading.Lock()


def compile_mode() -> str:
    """``"auto"``, ``"eager"`` or ``"off"``, from ``OPTKIN_COMPILE``."""
    v = os.environ.get("OPTKIN_COMPILE", "auto").strip().lower()
    if v in ("0", "off", "no", "false", "never"):
        return "off"
    if v in ("eager", "always", "1", "yes", "true"):
        return "eager"
    return "auto"


def find_compiler() -> str | None:
    """Path of the C compiler, or None (``OPTKIN_CC``, ``CC``, gcc, cc)."""
    if compile_mode() == "off":
        return None
    names = [os.environ.get("OPTKIN_CC"), os.environ.get("CC")]
    if not names[0]:
        names += ["gcc", "cc"]
    else:
        names = names[:1]
    for n in names:
        if n:
            p = shutil.which(n)
            if p:
                return p
    return None


def _writable(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(d, os.W_OK | os.X_OK)


def cache_dir() -> Path | None:
    """The first writable cache directory (see the module docstring), or None."""
    cands: list[Path] = []
    env = os.environ.get("OPTKIN_CACHE")
    if env:
        cands.append(Path(env).expanduser())
    xdg = os.environ.get("XDG_CACHE_HOME")
    cands.append(Path(xdg).expanduser() / "optkin" if xdg else Path.home() / ".cache" / "optkin")
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    cands.append(Path(tempfile.gettempdir()) / f"optkin-cache-{uid}")
    for d in cands:
        if _writable(d):
            return d
    return None


def _digest(tag: str, funcs: Sequence[ca.Function]) -> str:
    h = hashlib.sha256()
    h.update(
        f"{tag}|casadi {ca.__version__}|code {CODE_VERSION}|{sys.platform}|"
        f"{platform.machine()}|{' '.join(_FLAGS)}".encode()
    )
    for f in funcs:
        sig = [f.name(), str(f.n_instructions())]
        sig += [f"{f.name_in(i)}:{f.size1_in(i)}x{f.size2_in(i)}" for i in range(f.n_in())]
        sig += [f"{f.name_out(i)}:{f.size1_out(i)}x{f.size2_out(i)}:{f.nnz_out(i)}"
                for i in range(f.n_out())]
        h.update("|".join(sig).encode())
        # the whole expression graph, so that a changed body (e.g. of a mapped tracker whose
        # outer signature is unchanged) never loads a stale library
        h.update(f.serialize().encode())
    return h.hexdigest()[:20]


def _load(path: Path, funcs: Sequence[ca.Function]) -> dict[str, ca.Function] | None:
    try:
        out = {}
        for f in funcs:
            e = ca.external(f.name(), str(path))
            if e.n_in() != f.n_in() or e.n_out() != f.n_out() or any(
                e.size_in(i) != f.size_in(i) for i in range(f.n_in())
            ):
                raise RuntimeError(f"signature mismatch for {f.name()}")
            out[f.name()] = e
        return out
    except Exception as exc:  # a corrupt or foreign library: rebuild
        log.debug("optkin: cannot load %s (%s)", path, exc)
        return None


def library(
    tag: str, funcs: Sequence[ca.Function], build: bool = True
) -> dict[str, ca.Function] | None:
    """The compiled versions of ``funcs`` (by name), from the disk cache or built now.

    Parameters
    ----------
    tag : str
        What the Functions belong to, e.g. ``"core:" + mech.key``; part of the cache key.
    funcs : sequence of casadi.Function
        Functions with distinct names; they are generated into one C file.
    build : bool
        False: only load a library already in the cache.

    Returns
    -------
    dict or None
        ``{name: casadi.external Function}``, or None when compiling is off, no compiler
        or cache directory is available, or the build failed (the caller keeps the
        interpreted Functions).
    """
    return libraries([(tag, funcs)], build)[0]


def libraries(
    requests: Sequence[tuple[str, Sequence[ca.Function]]], build: bool = True
) -> list[dict[str, ca.Function] | None]:
    """:func:`library` for several libraries; the missing ones are compiled in parallel
    (one compiler process each; the C code is generated in this thread)."""
    out: list[dict[str, ca.Function] | None] = [None] * len(requests)
    if compile_mode() == "off" or not requests:
        return out
    d = cache_dir()
    if d is None:
        log.debug("optkin: no writable cache directory; using interpreted Functions")
        return out
    todo = []
    for k, (tag, funcs) in enumerate(requests):
        name = f"optkin_{tag.split(':')[0]}_{_digest(tag, funcs)}"
        path = d / (name + (".dll" if sys.platform == "win32" else ".so"))
        if path.exists():
            out[k] = _load(path, funcs)
        if out[k] is None:
            todo.append((k, name, path, funcs))
    if not todo or not build:
        return out
    cc = find_compiler()
    if cc is None:
        log.debug("optkin: no C compiler found; using interpreted Functions")
        return out
    with _BUILD_LOCK, tempfile.TemporaryDirectory(dir=d, prefix=".build-") as tmp:
        procs = []
        for k, name, path, funcs in todo:
            if path.exists():  # built meanwhile by another thread
                out[k] = _load(path, funcs)
                if out[k] is not None:
                    continue
            try:
                src = Path(tmp) / (name + ".c")
                cg = ca.CodeGenerator(src.name, {"with_header": False})
                for f in funcs:
                    cg.add(f)
                cg.generate(tmp + os.sep)
                so = Path(tmp) / path.name
                p = subprocess.Popen([cc, *_FLAGS, str(src), "-o", str(so), "-lm"],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                procs.append((k, path, funcs, so, p))
            except (OSError, RuntimeError) as exc:
                log.debug("optkin: generating %s failed (%s)", name, exc)
        for k, path, funcs, so, p in procs:
            try:
                _, err = p.communicate(timeout=600)
            except subprocess.SubprocessError as exc:
                p.kill()
                log.debug("optkin: compiling %s failed (%s)", path.name, exc)
                continue
            if p.returncode != 0:
                log.debug("optkin: compiler failed: %s", err[-2000:])
                continue
            try:
                os.replace(so, path)  # atomic: a concurrent reader sees old or new
            except OSError as exc:
                log.debug("optkin: cannot store %s (%s)", path, exc)
                continue
            out[k] = _load(path, funcs)
    return out


class FastFn:
    """A Function evaluated through preallocated numpy buffers (``Function.buffer``).

    About 1 us per call for a compiled Function instead of the 10-40 us of
    ``f(numpy, numpy)``. Outputs are views into buffers reused by the next call: copy what
    you keep. Not thread-safe: keep one per thread (``Model.fast`` does).

    Matrix arguments are column-major: pass an (n, m) C-ordered array for an (m, n) input.
    """

    __slots__ = ("f", "_buf", "_trig", "_args", "_res", "_dense")

    def __init__(self, f: ca.Function) -> None:
        self.f = f
        self._buf, self._trig = f.buffer()
        self._args = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self._res = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))
        self._dense: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def dense(self, i: int) -> np.ndarray:
        """Output ``i`` of the last call as a new dense (n1, n2) array."""
        sp = self.f.sparsity_out(i)
        n1, n2 = sp.size1(), sp.size2()
        if sp.is_dense():
            return self._res[i].reshape((n2, n1)).T.copy()
        if i not in self._dense:
            rows = np.array(sp.row(), dtype=int)
            cols = np.repeat(np.arange(n2), np.diff(np.array(sp.colind(), dtype=int)))
            self._dense[i] = (rows, cols)
        rows, cols = self._dense[i]
        out = np.zeros((n1, n2))
        out[rows, cols] = self._res[i]
        return out

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        for dst, a in zip(self._args, args):
            try:
                dst[:] = a
            except ValueError:  # a matrix: CasADi stores columns
                dst[:] = np.ravel(a, order="F")
        self._trig()
        return self._res

    def into(self, args: Sequence[np.ndarray], res: Sequence[np.ndarray]) -> None:
        """Evaluate with caller-owned contiguous float64 arrays (no copies)."""
        for i, a in enumerate(args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(res):
            self._buf.set_res(i, memoryview(r))
        self._trig()
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))
