"""Compiled CasADi Functions: C code generated once per mechanism and cached on disk.

A model's Functions (closure residual, Jacobians, the damped Newton step, poses, the fused
result evaluation, the path tracker of :func:`optkin.forward_batch`) are generated to C with
``casadi.CodeGenerator``, built into a shared library with the system C compiler
(``gcc -O1 -shared -fPIC``) and loaded back with ``casadi.external``. The library is cached
on disk under a name that hashes the mechanism's content key, the CasADi version,
:data:`CODE_VERSION` and the Functions' signatures, so a second process loads it in
milliseconds. Whenever something is missing (no compiler, no usable cache directory, a
failed build) the interpreted SX Functions are used instead (a ``logging`` debug line says
why).

Where the cache lives, and what it trusts
-----------------------------------------
The cache directory is ``OPTKIN_CACHE`` when set, else ``$XDG_CACHE_HOME/optkin`` or
``~/.cache/optkin`` (created with mode 0700). A directory is used only when it is a real
directory (not a symbolic link), owned by the current user and not writable by group or
others. When neither is usable, each process compiles into a fresh private directory of
its own (``tempfile.mkdtemp``, removed at exit); a shared, predictable path is never used.
An ``OPTKIN_CACHE`` (or an existing default directory) that cannot be used is reported once
per process with a warning naming the reason and the fix.

Beside each library ``<name>.so`` a record ``<name>.json`` holds the SHA-256 and size of the
library, the tag (model key) and cache key it was built for, the CasADi version and
:data:`CODE_VERSION`. Both are written atomically after the build. A library is loaded only
when both files are regular files owned by the current user and not writable by group or
others, the record names the requested tag and key, and the library's bytes match the
digest; anything else (a truncated, garbled, foreign or copied library) is rebuilt, never
loaded. (On platforms without user ids, such as Windows, only the record is checked.)

Processes sharing a cache build each library once: its builder holds ``<name>.lock``
(created exclusively) while its compiler runs; another process that needs the library
meanwhile waits for it (:func:`library`) or keeps its interpreted Functions until it lands
(:func:`start_library`) instead of compiling it a second time. A lock whose process is
gone (same host) or older than :data:`LOCK_STALE` seconds is taken over. The builder is a
small process of its own (the compiler, then the atomic install of library and record,
then the removal of its build directory and lock), detached from the process that
generated the C code: a library whose worker exits first still lands in the cache, and
the next run loads it.

Environment variables
---------------------
``OPTKIN_COMPILE``
    ``auto`` (default): load a cached library when the model is built, compile on demand
    (``forward_batch``, ``Model.compile()``, or a model that has served many ``forward``
    calls); ``eager``: compile when the model is built; ``off`` (or ``0``): never.
``OPTKIN_CACHE``
    The cache directory (see above).
``OPTKIN_CC``
    The C compiler (default ``$CC``, else ``gcc``, else ``cc``). Set it to a name that does
    not exist to simulate a machine without a compiler.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import json
import logging
import os
import platform
import shutil
import stat
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

__all__ = [
    "CODE_VERSION",
    "FastFn",
    "BoundFast",
    "cache_dir",
    "compile_mode",
    "find_compiler",
    "library",
    "start_library",
    "memo_function",
    "map_shared",
    "PendingLibrary",
]

log = logging.getLogger("optkin.compiled")

#: Bump when the generated Functions or the cache layout change (part of every cache key).
CODE_VERSION = "3"

_FLAGS = ("-O1", "-shared", "-fPIC")  # -O2 compiles twice as long, runs no faster
_EXT = ".dll" if sys.platform == "win32" else ".so"
_BUILD_LOCK = threading.Lock()
_STATE_LOCK = threading.Lock()
_UID = os.getuid() if hasattr(os, "getuid") else None
# a symbolic link is never followed; a FIFO planted in place of a file does not block
_OPEN_FLAGS = os.O_RDONLY | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0)
_RECORD_MAX = 1 << 16  # bytes; a longer record is not one of ours
_tmp_cache: tuple[int, Path] | None = None  # (pid, dir): this process's private fallback
_warned: set[tuple[str, str]] = set()
#: Seconds after which another process's build lock is presumed abandoned.
LOCK_STALE = 300.0
_HOST = platform.node()


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


# ------------------------------------------------------------------ the cache directory
def _not_private(st: os.stat_result) -> str | None:
    """Why a file or directory with status ``st`` could be changed by someone else, or None.

    Parameters
    ----------
    st : os.stat_result
        From ``os.lstat`` or ``os.fstat``.

    Returns
    -------
    str or None
        The reason, phrased to follow "it is", or None when only the current user can
        change it (always None on platforms without user ids).
    """
    if _UID is None:
        return None
    if st.st_uid != _UID:
        return f"owned by uid {st.st_uid}, not by the current user (uid {_UID})"
    if st.st_mode & 0o022:
        return f"writable by group or others (mode {stat.S_IMODE(st.st_mode):04o})"
    return None


def _make_dirs(d: Path) -> None:
    """Create ``d`` and its missing parents with mode 0700 (``mkdir -p -m 700``)."""
    missing = []
    p = d
    while not os.path.lexists(p) and p != p.parent:
        missing.append(p)
        p = p.parent
    for p in reversed(missing):
        try:
            os.mkdir(p, 0o700)
        except FileExistsError:  # created meanwhile by another process
            pass


def _unusable(d: Path) -> tuple[str, str] | None:
    """Why ``d`` cannot be the cache directory and how to fix it, or None when it can.

    Creates ``d`` (mode 0700) when it is missing. ``d`` is usable when it is a directory
    (not a symbolic link) owned by the current user, not writable by group or others, and
    writable and searchable by its owner.

    Parameters
    ----------
    d : pathlib.Path
        The candidate directory.

    Returns
    -------
    tuple of str or None
        (reason, fix), or None.
    """
    try:
        _make_dirs(d)
        st = os.lstat(d)
    except OSError as exc:
        return f"it cannot be created ({exc.strerror})", "choose a path you can create"
    if stat.S_ISLNK(st.st_mode):
        return "it is a symbolic link", "use the directory it points to, not the link"
    if not stat.S_ISDIR(st.st_mode):
        return "it is not a directory", "choose a directory"
    why = _not_private(st)
    if why is not None:
        if st.st_uid != _UID:
            return f"it is {why}", "choose a directory of your own"
        return f"it is {why}", f"run `chmod 700 {d}`"
    if st.st_mode & 0o300 != 0o300 or not os.access(d, os.W_OK | os.X_OK):
        return "it is not writable", f"run `chmod 700 {d}` (or choose a writable directory)"
    return None


def _remove_tmp_cache(pid: int, d: Path) -> None:
    """Remove the private fallback directory ``d`` at exit of the process that made it."""
    if os.getpid() == pid:
        shutil.rmtree(d, ignore_errors=True)


def _process_tmp_cache() -> Path | None:
    """This process's private fallback cache directory (``tempfile.mkdtemp``, mode 0700,
    removed at exit), made on first use; None when it cannot be made."""
    global _tmp_cache
    with _STATE_LOCK:
        if _tmp_cache is None or _tmp_cache[0] != os.getpid():  # a forked child makes its own
            try:
                d = Path(tempfile.mkdtemp(prefix="optkin-cache-"))
            except OSError as exc:
                log.debug("optkin: cannot make a temporary cache directory (%s)", exc)
                return None
            _tmp_cache = (os.getpid(), d)
            atexit.register(_remove_tmp_cache, os.getpid(), d)
        return _tmp_cache[1]


def cache_dir() -> Path | None:
    """The cache directory (see the module docstring), or None when there is none.

    The first usable one of ``OPTKIN_CACHE`` and ``$XDG_CACHE_HOME/optkin`` (or
    ``~/.cache/optkin``), else this process's private temporary directory. A candidate
    that is rejected is reported once per process with a warning when it was chosen by the
    user (``OPTKIN_CACHE``) or exists but is not private.

    Returns
    -------
    pathlib.Path or None
        A directory owned by the current user and writable by nobody else.
    """
    cands: list[tuple[Path, bool]] = []  # (directory, set by the user)
    env = os.environ.get("OPTKIN_CACHE")
    if env:
        cands.append((Path(env).expanduser(), True))
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and os.path.isabs(xdg):  # the XDG spec: ignore a relative path
        cands.append((Path(xdg) / "optkin", False))
    else:
        try:
            cands.append((Path.home() / ".cache" / "optkin", False))
        except RuntimeError:  # no home directory
            pass
    rejected = []
    chosen = None
    for d, by_user in cands:
        why = _unusable(d)
        if why is None:
            chosen = d
            break
        log.debug("optkin: cache directory %s not used: %s", d, why[0])
        if by_user or os.path.lexists(d):
            rejected.append((d, by_user, *why))
    if chosen is not None:
        instead = f"Compiled code is cached in {chosen} instead."
    else:
        chosen = _process_tmp_cache()
        instead = ("Compiled code is not cached." if chosen is None else
                   f"Compiled code is cached in {chosen} instead, for this process only.")
    for d, by_user, reason, fix in rejected:
        with _STATE_LOCK:
            if (str(d), reason) in _warned:
                continue
            _warned.add((str(d), reason))
        name = f"OPTKIN_CACHE={d}" if by_user else f"the cache directory {d}"
        warnings.warn(f"optkin: {name} is not used: {reason}. To use it, {fix}. {instead}",
                      stacklevel=2)
    return chosen


# ------------------------------------------------------------------ libraries and records
def fingerprint(f: ca.Function) -> str:
    """SHA-256 (hex) of ``f``'s serialized graph: what a cache key holds of a Function.

    Computed once per Function object (serializing a 6-6 platform's tracker takes about
    10 ms) and kept on it; a Function read back by :func:`memo_function` carries the
    verified digest of the payload it was read from, so it is never serialized again."""
    fp = getattr(f, "_optkin_fingerprint", None)
    if fp is None:
        fp = hashlib.sha256(f.serialize().encode()).hexdigest()
        with contextlib.suppress(AttributeError):
            f._optkin_fingerprint = fp
    return fp


def _digest(tag: str, funcs: Sequence[ca.Function]) -> str:
    """The cache key of ``funcs`` built for ``tag`` (a SHA-256 hex digest)."""
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
        h.update(fingerprint(f).encode())
    return h.hexdigest()


def _record_path(lib: Path) -> Path:
    return lib.with_suffix(".json")


def _read_private(path: Path, limit: int = -1) -> bytes:
    """The bytes of ``path`` (at most ``limit``), which must be a regular file (not a
    symbolic link) owned by the current user and writable by nobody else.

    Raises
    ------
    OSError
        It cannot be read, or it is a symbolic link.
    ValueError
        It is not a regular file, or it is not private.
    """
    fd = os.open(path, _OPEN_FLAGS)
    with os.fdopen(fd, "rb") as f:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{path.name} is not a regular file")
        why = _not_private(st)
        if why is not None:
            raise ValueError(f"{path.name} is {why}")
        return f.read(limit)


def _rejection(lib: Path, tag: str, key: str) -> str | None:
    """Why the library ``lib`` must not be loaded for ``tag``, or None when its record
    vouches for it (same tag and cache key, same size and SHA-256)."""
    try:
        rec = json.loads(_read_private(_record_path(lib), _RECORD_MAX))
        data = _read_private(lib)
    except (OSError, ValueError) as exc:  # ValueError includes json.JSONDecodeError
        return f"no valid record or library ({exc})"
    if not isinstance(rec, dict):
        return "its record is not a JSON object"
    if rec.get("tag") != tag or rec.get("key") != key:
        return f"its record is for another model or build (tag {rec.get('tag')!r})"
    if rec.get("size") != len(data) or rec.get("sha256") != hashlib.sha256(data).hexdigest():
        return "its bytes differ from its record (truncated or changed)"
    return None


def _record_fields(lib: Path, tag: str, key: str) -> dict[str, Any]:
    """The record of ``lib`` but its size and digest (the builder adds those)."""
    return {"tag": tag, "key": key, "file": lib.name, "casadi": ca.__version__,
            "code_version": CODE_VERSION}


def _load(path: Path, tag: str, key: str,
          funcs: Sequence[ca.Function]) -> dict[str, ca.Function] | None:
    """The Functions of the cached library ``path`` when its record vouches for it (see
    :func:`_rejection`) and their signatures match ``funcs``; else None."""
    if not os.path.lexists(path):
        return None
    why = _rejection(path, tag, key)
    if why is not None:
        log.info("optkin: not loading %s: %s; rebuilding it", path, why)
        return None
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
    except Exception as exc:  # a library that does not define these Functions: rebuild
        log.debug("optkin: cannot load %s (%s)", path, exc)
        return None


def _library_path(d: Path, tag: str, key: str) -> Path:
    return d / f"optkin_{tag.split(':')[0]}_{key[:20]}{_EXT}"


#: The builder: a process of its own (``python -S``, no optkin import) that runs the compiler
#: on C code already generated, installs the library and its record in the cache
#: atomically (library first: a reader of the old record sees a mismatch), then removes
#: the build directory and its lock. Detached from the process that started it (a session
#: of its own), it finishes even when that process exits or is killed: the next run loads
#: the library instead of compiling it again.
_BUILDER = r"""
import hashlib, json, os, shutil, subprocess, sys
a = json.loads(sys.argv[1])
me = "%d %s" % (os.getpid(), a["host"])
tmp, lock = a["tmp"], a["lock"]
try:  # the lock now names this process (the starter may exit first)
    t = os.path.join(tmp, "lock")
    with open(t, "w") as f:
        f.write(me)
    os.replace(t, lock)
except OSError:
    pass
ok = False
try:
    with open(os.path.join(tmp, "compiler.log"), "wb") as log:
        p = subprocess.Popen(a["cmd"], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=log)
        try:
            rc = p.wait(timeout=a["timeout"])
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
            rc = -1
    if rc == 0:
        with open(a["so"], "rb") as f:
            data = f.read()
        rec = dict(a["record"], size=len(data), sha256=hashlib.sha256(data).hexdigest())
        rt = os.path.join(tmp, "record.json")
        fd = os.open(rt, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as f:
            json.dump(rec, f, indent=1)
        os.chmod(a["so"], 0o700)  # whatever the umask: group-writable files are refused
        os.replace(a["so"], a["lib"])
        os.replace(rt, a["rec"])
        ok = True
    else:
        with open(os.path.join(tmp, "compiler.log"), "rb") as f:
            sys.stderr.write(f.read()[-2000:].decode(errors="replace"))
finally:
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        with open(lock) as f:
            mine = f.read() == me
        if mine:
            os.unlink(lock)
    except OSError:
        pass
sys.exit(0 if ok else 1)
"""
#: Seconds the compiler may run.
COMPILE_LIMIT = 600.0
_BUILDERS: list[subprocess.Popen] = []  # kept referenced until they end (no warnings)


def _start_builder(cc: str, d: Path, path: Path, tag: str, key: str,
                   funcs: Sequence[ca.Function], wait: bool = False,
                   source: Any = None, flags: Sequence[str] | None = None
                   ) -> subprocess.Popen:
    """Generate the C code of ``funcs`` (in this thread) into a fresh build directory of
    ``d`` and start the builder on it (the lock of ``path`` must be this process's).
    ``source``: a callable giving the C text to compile instead of CasADi's code of
    ``funcs`` (which then only give the signatures to check on loading), compiled with
    ``flags`` (default the usual ones)."""
    tmp = tempfile.mkdtemp(dir=d, prefix=".build-")
    try:
        src = Path(tmp) / (path.stem + ".c")
        if source is None:
            cg = ca.CodeGenerator(src.name, {"with_header": False})
            for f in funcs:
                cg.add(f)
            cg.generate(tmp + os.sep)
        else:
            src.write_text(source(), encoding="utf-8")
        so = Path(tmp) / path.name
        args = {"host": _HOST, "tmp": tmp, "lock": str(_lock_path(path)),
                "cmd": [cc, *(_FLAGS if flags is None else flags), str(src), "-o", str(so),
                        "-lm"], "so": str(so),
                "lib": str(path), "rec": str(_record_path(path)),
                "record": _record_fields(path, tag, key), "timeout": COMPILE_LIMIT}
        proc = subprocess.Popen(
            [sys.executable, "-S", "-c", _BUILDER, json.dumps(args)],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE if wait else subprocess.DEVNULL,
            start_new_session=True, close_fds=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    proc.build_dir = tmp  # (removed by the builder; by _kill_builder if it is stopped)
    _BUILDERS[:] = [b for b in _BUILDERS if b.poll() is None] + [proc]
    return proc


def library(
    tag: str, funcs: Sequence[ca.Function], build: bool = True
) -> dict[str, ca.Function] | None:
    """The compiled versions of ``funcs`` (by name), from the disk cache or built now.

    Parameters
    ----------
    tag : str
        What the Functions belong to, e.g. ``"core:" + mech.key``; part of the cache key
        and recorded beside the library.
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


def memo_function(tag: str, parts: Sequence[str | bytes],
                  build: Any) -> ca.Function:
    """``build()``, once per cache directory: a Function whose graph is costly to build in
    Python (op by op) is stored serialized in the cache under a digest of ``parts`` (all
    that determines it: the serialized inputs, the options, the building code's source
    digest), the CasADi version and :data:`CODE_VERSION`; later processes read it back in
    a few milliseconds. The file is trusted as a library is (a private regular file) and
    holds the SHA-256 of its payload; anything else is rebuilt."""
    d = cache_dir()
    if d is None:
        return build()
    h = hashlib.sha256(f"{tag}|casadi {ca.__version__}|code {CODE_VERSION}".encode())
    for part in parts:
        h.update(part if isinstance(part, bytes) else part.encode())
        h.update(b"\0")
    path = d / f"optkin_fn_{tag}_{h.hexdigest()[:24]}.casadi"
    try:
        digest, _, payload = _read_private(path).partition(b"\n")
        if hashlib.sha256(payload).hexdigest().encode() == digest:
            f = ca.Function.deserialize(payload.decode())
            with contextlib.suppress(AttributeError):
                f._optkin_fingerprint = digest.decode()
            return f
    except FileNotFoundError:
        pass
    except (OSError, ValueError, RuntimeError) as exc:
        log.debug("optkin: not reading %s (%s); rebuilding it", path.name, exc)
    f = build()
    try:
        payload = f.serialize().encode()
        with contextlib.suppress(AttributeError):
            f._optkin_fingerprint = hashlib.sha256(payload).hexdigest()
        fd, tmp = tempfile.mkstemp(dir=d, prefix=".fn-")
        try:
            with os.fdopen(fd, "wb") as out:
                out.write(hashlib.sha256(payload).hexdigest().encode() + b"\n" + payload)
            os.replace(tmp, path)  # atomic: a concurrent reader sees none or all of it
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            raise
    except (OSError, RuntimeError) as exc:
        log.debug("optkin: cannot store %s (%s)", path.name, exc)
    return f


def _lock_path(lib: Path) -> Path:
    return lib.with_suffix(".lock")


def _lock_holder(lock: Path) -> tuple[str, str]:
    """(pid, host) written in the build lock ``lock``. Raises OSError or ValueError as
    :func:`_read_private` does."""
    pid, _, host = _read_private(lock, 256).decode(errors="replace").partition(" ")
    return pid, host.strip()


def _holder_gone(lock: Path) -> bool:
    """Whether the build lock ``lock`` is abandoned: older than :data:`LOCK_STALE`, or
    written by a process of this host that no longer exists (a missing lock counts)."""
    try:
        st = os.lstat(lock)
        if time.time() - st.st_mtime > LOCK_STALE:
            return True
        pid, host = _lock_holder(lock)
    except FileNotFoundError:
        return True
    except (OSError, ValueError):  # unreadable or not ours: honoured until it is stale
        return False
    if host != _HOST or not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except OSError:  # exists, owned by someone else
        return False
    return False


def _claim(lib: Path) -> bool:
    """Claim the build of ``lib`` for this process (its lock file, created exclusively);
    False while another live process holds it. A lock that cannot be made at all (a
    read-only cache, say) does not stop the build: the install is atomic anyway."""
    lock = _lock_path(lib)
    for _ in range(3):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL
                         | getattr(os, "O_NOFOLLOW", 0), 0o600)
        except FileExistsError:
            if not _holder_gone(lock):
                return False
            try:  # abandoned: take it over (another process may race us to it: retry)
                os.unlink(lock)
            except FileNotFoundError:
                pass
            except OSError:
                return True
            continue
        except OSError:
            return True
        with os.fdopen(fd, "w") as f:
            f.write(f"{os.getpid()} {_HOST}")
        return True
    return False


def _release(lib: Path, *pids: int) -> None:
    """Remove the build lock of ``lib`` when it names this process (or one of ``pids``)."""
    try:
        if _lock_holder(_lock_path(lib))[0] in {str(os.getpid()), *map(str, pids)}:
            os.unlink(_lock_path(lib))
    except (OSError, ValueError):
        pass


def libraries(
    requests: Sequence[tuple[str, Sequence[ca.Function]] | tuple[str, Sequence[ca.Function], str]],
    build: bool = True
) -> list[dict[str, ca.Function] | None]:
    """:func:`library` for several libraries; the missing ones are compiled in parallel
    (one builder process each; the C code is generated in this thread). A cached library
    whose record does not vouch for it is rebuilt like a missing one; one that another
    process is building is waited for. A request may carry its key (:func:`_digest` of its
    tag and Functions) when the caller keeps it: the digest serializes every Function (a
    3-RPR's core: 3.5 ms), which a caller asking again and again should pay once."""
    out: list[dict[str, ca.Function] | None] = [None] * len(requests)
    if compile_mode() == "off" or not requests:
        return out
    d = cache_dir()
    if d is None:
        log.debug("optkin: no usable cache directory; using interpreted Functions")
        return out
    todo = []
    for k, req in enumerate(requests):
        tag, funcs = req[0], req[1]
        key = req[2] if len(req) > 2 else _digest(tag, funcs)  # type: ignore[misc]
        path = _library_path(d, tag, key)
        out[k] = _load(path, tag, key, funcs)
        if out[k] is None:
            todo.append((k, tag, key, path, funcs))
    if not todo or not build:
        return out
    cc = find_compiler()
    if cc is None:
        log.debug("optkin: no C compiler found; using interpreted Functions")
        return out
    with _BUILD_LOCK:
        procs, others = [], []
        for k, tag, key, path, funcs in todo:
            out[k] = _load(path, tag, key, funcs)  # built meanwhile by another thread?
            if out[k] is not None:
                continue
            if not _claim(path):  # another process is building it
                others.append((k, tag, key, path, funcs))
                continue
            try:
                procs.append((k, tag, key, path, funcs,
                              _start_builder(cc, d, path, tag, key, funcs, wait=True)))
            except (OSError, RuntimeError) as exc:
                _release(path)
                log.debug("optkin: generating %s failed (%s)", path.stem, exc)
        for k, tag, key, path, funcs, p in procs:
            try:
                _, err = p.communicate(timeout=COMPILE_LIMIT + 60)
            except subprocess.SubprocessError as exc:
                _kill_builder(p, path)
                log.debug("optkin: compiling %s failed (%s)", path.name, exc)
                continue
            if p.returncode != 0:
                log.debug("optkin: compiler failed: %s", err.decode(errors="replace"))
                continue
            out[k] = _load(path, tag, key, funcs)
    for k, tag, key, path, funcs in others:  # (taken over if that process gives up)
        out[k] = PendingLibrary(tag, key, path, funcs).wait() or None
    return out


def _kill_builder(proc: subprocess.Popen, path: Path) -> None:
    """Stop a builder and its compiler (its session); remove what it leaves."""
    import signal

    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except OSError:
        pass
    proc.wait()
    _release(path, proc.pid)  # the lock names the builder (or still this process)
    shutil.rmtree(proc.build_dir, ignore_errors=True)


class PendingLibrary:
    """A library being compiled in the background (:func:`start_library`), by a builder
    this process started or by another process sharing the cache.

    The C code was generated in the calling thread; the builder (a detached process)
    compiles it and installs the library in the cache, whether or not anyone asks, and
    even after this process exits. :meth:`poll` returns None while the build runs, then
    (once) the loaded Functions, or ``False`` when the build failed; afterwards it keeps
    returning that outcome. A build of another process that gave up is taken over.
    """

    def __init__(self, tag: str, key: str, path: Path, funcs: Sequence[ca.Function],
                 proc: subprocess.Popen | None = None, source: Any = None,
                 flags: Sequence[str] | None = None) -> None:
        self.tag, self.key, self.path, self.funcs = tag, key, path, list(funcs)
        self.source, self.flags = source, flags
        self._proc = proc
        self._out: dict[str, ca.Function] | bool | None = None
        self._next_look = 0.0

    @property
    def own(self) -> bool:
        """Whether this process started the builder (else another process did)."""
        return self._proc is not None

    def poll(self) -> dict[str, ca.Function] | bool | None:
        if self._out is not None:
            return self._out
        if self._proc is not None:
            if self._proc.poll() is None:
                return None
            self._out = _load(self.path, self.tag, self.key, self.funcs) or False
            return self._out
        now = time.monotonic()
        if now < self._next_look:
            return None
        self._next_look = now + 0.02
        # the lock first: a library installed just before its lock is removed is then
        # seen by the next line, not missed
        gone = _holder_gone(_lock_path(self.path))
        lib = _load(self.path, self.tag, self.key, self.funcs)
        if lib is not None:
            self._out = lib
        elif gone:  # the other process gave up: build it here
            nxt = start_library(self.tag, self.funcs, self.source, self.flags)
            if isinstance(nxt, dict):
                self._out = nxt
            elif nxt is None:
                self._out = False
            elif nxt._proc is not None:
                self._proc, nxt._proc = nxt._proc, None
        return self._out

    def wait(self, timeout: float = COMPILE_LIMIT + 60) -> dict[str, ca.Function] | bool:
        """The outcome, waiting at most ``timeout`` s (then this process's builder is
        stopped and the outcome is ``False``)."""
        end = time.monotonic() + timeout
        while True:
            out = self.poll()
            if out is not None:
                return out
            left = end - time.monotonic()
            if left <= 0:
                if self._proc is not None:
                    _kill_builder(self._proc, self.path)
                self._out = False
                return False
            if self._proc is not None:
                try:
                    self._proc.wait(timeout=min(left, 1.0))
                except subprocess.TimeoutExpired:
                    pass
            else:
                time.sleep(min(left, 0.02))


def start_library(tag: str, funcs: Sequence[ca.Function], source: Any = None,
                  flags: Sequence[str] | None = None
                  ) -> dict[str, ca.Function] | PendingLibrary | None:
    """:func:`library` without waiting for the compiler: the cached library when there is
    one, else a :class:`PendingLibrary` whose builder runs in the background (or that
    waits for another process building the same library), else None (compiling off, no
    cache directory, no compiler, or the C code could not be generated). The caller keeps
    using the interpreted Functions until :meth:`PendingLibrary.poll` gives the compiled
    ones. ``source`` and ``flags``: as :func:`_start_builder` (C of our own; the ``tag``
    must then name everything that source depends on, the flags included: the key is made
    of the tag and ``funcs``)."""
    if compile_mode() == "off":
        return None
    d = cache_dir()
    if d is None:
        return None
    key = _digest(tag, funcs)
    path = _library_path(d, tag, key)
    lib = _load(path, tag, key, funcs)
    if lib is not None:
        return lib
    cc = find_compiler()
    if cc is None:
        return None
    if not _claim(path):
        return PendingLibrary(tag, key, path, funcs, source=source, flags=flags)
    try:
        proc = _start_builder(cc, d, path, tag, key, funcs, source=source, flags=flags)
    except (OSError, RuntimeError, ValueError) as exc:
        log.debug("optkin: generating %s failed (%s)", path.stem, exc)
        _release(path)
        return None
    return PendingLibrary(tag, key, path, funcs, proc, source=source, flags=flags)


class LateCompiled:
    """A Function compiled in the background (:func:`start_library`):
    until its library lands the interpreted Function answers; its maps (through call
    buffers, one per width) are rebuilt once when the compiled code takes over."""

    def __init__(self, tag: str, f: ca.Function, build: bool = True) -> None:
        self.f = f
        self.tag = tag
        self.pending: Any = None
        self._maps: dict[int, Any] = {}
        #: whether its build is yet to be started (``build=False``: a cached library is
        #: loaded, none is built until :meth:`start`)
        self.deferred = False
        if not build:
            lib = library(tag, [f], build=False)
            if lib is not None:
                self.f = lib[f.name()]
                self.compiled = True
                return
            self.deferred = True
            self.compiled = (compile_mode() != "off" and cache_dir() is not None
                             and find_compiler() is not None)
            return
        lib = start_library(tag, [f])
        if isinstance(lib, dict):
            self.f = lib[f.name()]
        elif lib is not None:
            self.pending = lib
        #: whether a compiler is (or will be) behind it (False: none available)
        self.compiled = lib is not None

    def start(self) -> None:
        """Start the build deferred at construction (nothing when there is none)."""
        if not self.deferred:
            return
        self.deferred = False
        lib = start_library(self.tag, [self.f])
        if isinstance(lib, dict):
            self.f = lib[self.f.name()]
            self._maps = {}
        elif lib is not None:
            self.pending = lib

    def poll(self) -> None:
        """Switch to the compiled Function once its build has finished."""
        if self.pending is not None:
            done = self.pending.poll()
            if done is not None:
                self.pending = None
                if done is not False:
                    self.f = done[self.f.name()]
                    self._maps = {}

    def mapped(self, N: int, make: Any, part: int = 0) -> Any:
        """The call buffer of ``make(f, N)`` (a map of the current Function over N); one
        per ``part``, for calls from several threads at once."""
        self.poll()
        fm = self._maps.get((N, part))
        if fm is None:
            fm = self._maps[(N, part)] = FastFn(make(self.f, N))
        return fm


#: Columns of the inner map of :func:`map_shared`.
_INNER = 64


def map_shared(f: ca.Function, name: str, n: int, shared: Sequence[int]) -> ca.Function:
    """``f.map(name, "serial", n, shared, [])``: ``f`` over ``n`` columns, the inputs
    ``shared`` the same for every column; the same Function (signature, names, values),
    built faster. CasADi builds such a map with a wrapper whose size grows with ``n``
    (1.8 ms for 2048 columns of a small Function, 3.5 ms for 4096: a five-bar's aspects
    built 34 ms of maps in each new process); a map of maps of 64 columns costs a
    fraction of that (0.8 ms for 2048) and evaluates as fast (measured: 9.5 ms a call
    either way for 2048 columns, the same values)."""
    n = int(n)
    shared = list(shared)
    if not shared or n < 4 * _INNER or n % _INNER:
        return f.map(name, "serial", n, shared, [])
    inner = f.map(f"{name}_in", "serial", _INNER, shared, [])
    return inner.map(name, "serial", n // _INNER, shared, [])


class FastFn:
    """A Function evaluated through preallocated numpy buffers (``Function.buffer``).

    About 1 us per call for a compiled Function instead of the 10-40 us of
    ``f(numpy, numpy)``. Outputs are views into buffers reused by the next call: copy what
    you keep. Not thread-safe: keep one per thread (``Model.fast`` does).

    Matrix arguments are column-major: pass an (n, m) C-ordered array for an (m, n) input.
    ``fixed`` values fill the last inputs once (a model's geometry vector): calls then pass
    only the leading inputs.
    """

    __slots__ = ("f", "_buf", "_trig", "_args", "_res", "_dense", "_fixed", "owner")

    def __init__(self, f: ca.Function, fixed: Sequence[np.ndarray] = ()) -> None:
        self.f = f
        self._buf, self._trig = f.buffer()
        self._args = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self._res = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))
        self._dense: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._fixed = len(fixed)
        self.owner: object = None  #: who set the fixed inputs last (:class:`BoundFast`)
        self.set_fixed(fixed)

    def set_fixed(self, fixed: Sequence[np.ndarray]) -> None:
        """Fill the last ``len(fixed)`` inputs (kept for the following calls)."""
        n = self.f.n_in()
        for k, v in enumerate(fixed):
            self._args[n - len(fixed) + k][:] = np.ravel(v, order="F")

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

    def ok(self) -> bool:
        """Whether the last call succeeded (an interpreted Function can fail where compiled
        code returns inf or NaN: CasADi's QR solver on an exactly singular matrix)."""
        return self._buf.ret() == 0

    def into(self, args: Sequence[np.ndarray], res: Sequence[np.ndarray]) -> None:
        """Evaluate with caller-owned contiguous float64 arrays (no copies; the fixed
        inputs keep their values)."""
        for i, a in enumerate(args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(res):
            self._buf.set_res(i, memoryview(r))
        self._trig()
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buf.set_res(i, memoryview(r))


class BoundFast:
    """One evaluator (:class:`FastFn`) shared by every geometry of a topology in a thread,
    seen with one geometry: each call first puts this geometry in the fixed inputs unless
    it is already there (a Function's buffer costs 0.2-0.5 ms to set up, which a model of a
    new geometry would otherwise pay for each evaluator it uses; the geometry, a few
    numbers). The outputs are the shared buffers: copy what you keep."""

    __slots__ = ("ev", "fixed")

    def __init__(self, ev: FastFn, fixed: Sequence[np.ndarray]) -> None:
        self.ev, self.fixed = ev, tuple(fixed)

    @property
    def f(self) -> ca.Function:
        return self.ev.f

    def _mine(self) -> FastFn:
        ev = self.ev
        if ev.owner is not self:
            ev.set_fixed(self.fixed)
            ev.owner = self
        return ev

    def __call__(self, *args: np.ndarray) -> list[np.ndarray]:
        return self._mine()(*args)

    def into(self, args: Sequence[np.ndarray], res: Sequence[np.ndarray]) -> None:
        self._mine().into(args, res)

    def dense(self, i: int) -> np.ndarray:
        """Output ``i`` of the last call (this evaluator's, if no other call came between)."""
        return self.ev.dense(i)

    def ok(self) -> bool:
        return self.ev.ok()
