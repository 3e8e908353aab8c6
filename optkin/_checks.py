"""One place that turns user input into numbers: every public function converts through here.

Whatever the caller passes (a Python int with 400 digits, a string, a nested list, NaN,
``1e308``), the converters below either return a finite float64 value of the expected
shape or raise the project's own error class naming the argument (``where``) and the fix,
with the argument's location as data (``path``, see :class:`optkin.errors.OptkinError`).
They never let ``OverflowError``, ``TypeError`` or a numpy ``ValueError`` escape.

Numeric kernels (LAPACK through numpy) must never receive NaN or inf: some LAPACK builds
loop forever on them (``DLASCL parameter number 4 had an illegal value``).
:func:`finite_matrix` is the guard to put in front of them; the finite-checked linear
algebra helpers live in :mod:`optkin.numeric`.

The checks every public function shares live here too: :func:`check_mechanism` (the one
"expected an optkin Mechanism" message), :func:`check_number` (a number or integer within
bounds: the one validator of numeric arguments) and :func:`check_option` (the same for an
option of a ``*_DEFAULTS`` mapping, whose message names the option and its default).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

import numpy as np

from .errors import MechanismError

__all__ = [
    "MAX_ABS",
    "as_float",
    "as_int",
    "as_vector",
    "as_matrix",
    "check_mechanism",
    "check_number",
    "check_option",
    "finite_matrix",
    "show",
]

#: Largest magnitude accepted for a coordinate, length, angle, force or option anywhere in
#: optkin. Beyond it, squares overflow float64 (1e154 ** 2 = 1e308) and every residual is inf.
MAX_ABS = 1e150

Path = Sequence[str | int]


def _exc(error: type[Exception], msg: str, path: Path = ()) -> Exception:
    """``error(msg)``, with ``path`` attached when the class takes one (optkin's)."""
    try:
        return error(msg, path=tuple(path))  # type: ignore[call-arg]
    except TypeError:
        return error(msg)


def _err(error: type[Exception], where: str, msg: str, path: Path = ()) -> Exception:
    """``error("where: msg")`` (:func:`_exc`)."""
    return _exc(error, f"{where}: {msg}", path)


def _digits(iv: int) -> str:
    """An int for a message: itself when short, else its first digits and size (str() of an
    int of more than 4300 digits raises ValueError)."""
    if abs(iv) < 10**24:
        return str(iv)
    if iv.bit_length() > 10_000:
        return f"{'-' if iv < 0 else ''}(an integer of {iv.bit_length()} bits)"
    s = str(iv)
    return f"{s[:20]}... ({len(s.lstrip('-'))} digits)"


def _scalar(v: Any, where: str, error: type[Exception], path: Path) -> float:
    if isinstance(v, bool) or isinstance(v, np.bool_):
        raise _err(error, where, f"expected a number, got {v!r}", path)
    if isinstance(v, numbers.Integral):
        iv = int(v)
        if abs(iv) > MAX_ABS:
            raise _err(error, where, f"the integer {_digits(iv)} is too large "
                       f"(magnitude above {MAX_ABS:g}); give a number of sensible size", path)
        return float(iv)
    if isinstance(v, numbers.Real):
        try:
            return float(v)
        except (OverflowError, TypeError, ValueError):  # e.g. a huge Fraction or Decimal
            raise _err(error, where, f"cannot represent {_show(v)} as a float", path) from None
    if isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected a number, got the string {str(v)[:40]!r}", path)
    if isinstance(v, numbers.Complex):
        raise _err(error, where, f"expected a real number, got {v!r}", path)
    raise _err(error, where, f"expected a number, got {type(v).__name__}", path)


def as_float(v: Any, where: str, *, lo: float | None = None, hi: float | None = None,
             finite: bool = True, error: type[Exception] = MechanismError,
             path: Path = ()) -> float:
    """``v`` as a float; ``lo``/``hi`` bound it inclusively; NaN is always rejected.

    ``finite=False`` also accepts +-inf (e.g. an option where inf disables a limit).

    >>> as_float(3, "tol")
    3.0
    >>> as_float("x", "tol")
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: tol: expected a number, got the string 'x'
    >>> as_float(10**400, "qa")
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: qa: the integer 10000000000000000000... is too large (magnitude above 1e+150); give a number of sensible size
    """
    x = _scalar(v, where, error, path)
    if math.isnan(x) or (finite and not math.isfinite(x)):
        raise _err(error, where, f"expected a finite number, got {x!r}", path)
    if finite and abs(x) > MAX_ABS:
        raise _err(error, where, f"{x:g} is too large (magnitude above {MAX_ABS:g})", path)
    if lo is not None and x < lo:
        raise _err(error, where, f"expected a number >= {lo:g}, got {x:g}", path)
    if hi is not None and x > hi:
        raise _err(error, where, f"expected a number <= {hi:g}, got {x:g}", path)
    return x


def as_int(v: Any, where: str, *, lo: int | None = None, hi: int | None = None,
           error: type[Exception] = MechanismError, path: Path = ()) -> int:
    """``v`` as an int (integral floats such as ``4.0`` accepted); bounds inclusive.

    Integers of magnitude above :data:`MAX_ABS` are rejected even without ``hi``.

    >>> as_int(4.0, "starts", lo=1)
    4
    >>> as_int(2**70, "starts", hi=2**20)
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: starts: expected an integer <= 1048576, got 1180591620717411303424
    """
    if isinstance(v, (bool, np.bool_)) or isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected an integer, got {_show(v)}", path)
    if isinstance(v, numbers.Integral):
        iv = int(v)
    elif isinstance(v, numbers.Real) and math.isfinite(float(v)) and float(v).is_integer():
        iv = int(v)
    else:
        raise _err(error, where, f"expected an integer, got {_show(v)}", path)
    if lo is not None and iv < lo:
        raise _err(error, where, f"expected an integer >= {lo}, got {_digits(iv)}", path)
    if hi is not None and iv > hi:
        raise _err(error, where, f"expected an integer <= {hi}, got {_digits(iv)}", path)
    if abs(iv) > MAX_ABS:
        raise _err(error, where, f"the integer {_digits(iv)} is too large", path)
    return iv


def _to_array(v: Any, where: str, error: type[Exception], path: Path) -> np.ndarray:
    if isinstance(v, (str, bytes)):
        raise _err(error, where, f"expected numbers, got the string {str(v)[:40]!r}", path)
    if isinstance(v, np.ndarray) and v.dtype.kind in "fiu":
        a = v.astype(float, copy=False)
    else:
        try:
            a = np.asarray(v, dtype=float)
        except OverflowError:
            raise _err(error, where, f"a value is too large (magnitude above {MAX_ABS:g})",
                       path) from None
        except (TypeError, ValueError, RecursionError):
            raise _err(error, where, "expected numbers (a list or array of the right shape), "
                       f"got {_show(v)}", path) from None
    return a


def show(v: Any, limit: int = 60) -> str:
    """``repr(v)`` cut to ``limit`` characters, for messages (never raises).

    >>> show("-" * 100)
    "'--------------------------------------------------------..."
    """
    try:
        s = repr(v)
    except Exception:  # noqa: BLE001 - a repr that fails must not hide the real message
        s = f"<{type(v).__name__}>"
    return s if len(s) <= limit else s[:limit - 3] + "..."


_show = show


def _check_finite(a: np.ndarray, where: str, names: Sequence[str] | None,
                  error: type[Exception], path: Path, max_abs: float = MAX_ABS) -> None:
    ok = np.abs(a) <= max_abs  # False for NaN, and for inf unless max_abs is inf
    if not math.isfinite(max_abs):
        ok &= np.isfinite(a)
    bad = ~ok
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        x = float(a.ravel()[i])
        what = "non-finite value" if not math.isfinite(x) else f"value {x:g} too large"
        at = f"for [{names[i]!r}]" if names is not None and i < len(names) else f"at entry {i}"
        limit = f" of magnitude at most {max_abs:g}" if math.isfinite(max_abs) else ""
        raise _err(error, where, f"{what} {at}; give finite values{limit}",
                   tuple(path) + ((i,) if a.ndim == 1 else ()))


def as_vector(v: Any, where: str, n: int | None = None, *, names: Sequence[str] | None = None,
              error: type[Exception] = MechanismError, path: Path = (),
              max_abs: float = MAX_ABS) -> np.ndarray:
    """``v`` as a finite 1-D float array (of ``n`` entries when given); a new array.

    ``names`` (the entries' names, e.g. joint names) make the messages precise. Entries of
    magnitude above ``max_abs`` are rejected (``max_abs=inf``: any finite value, for
    configurations whose overflow the caller reports as an unsuccessful result).

    >>> as_vector([1, 2], "qa", 2)
    array([1., 2.])
    >>> as_vector([1, float("nan")], "qa", 2, names=["t1", "t2"])
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: qa: non-finite value for ['t2']; give finite values of magnitude at most 1e+150
    """
    a = _to_array(v, where, error, path)
    if a.ndim == 0 and n in (None, 1):
        a = a.reshape(1)
    if a.ndim != 1 or (n is not None and a.size != n):
        want = (f"{n} number{'s' if n != 1 else ''}" if n is not None
                else "a list of numbers")
        if names is not None and n is not None:
            want += f" ({', '.join(names)})"
        raise _err(error, where, f"expected {want}, got shape {a.shape}", path)
    _check_finite(a, where, names, error, path, max_abs)
    return np.array(a, dtype=float)


def as_matrix(v: Any, where: str, shape: tuple[int | None, int | None] | None = None, *,
              error: type[Exception] = MechanismError, path: Path = (),
              max_abs: float = MAX_ABS) -> np.ndarray:
    """``v`` as a finite 2-D float array; ``shape`` entries of None match any size.

    >>> as_matrix([[0, 0], [1, 0], [0, 1]], "base", (3, 2)).shape
    (3, 2)
    >>> as_matrix([[0, 0], [1, 0]], "base", (3, 2))
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: base: expected a 3x2 array, got shape (2, 2)
    """
    a = _to_array(v, where, error, path)
    if a.ndim != 2 or (shape is not None and any(
            s is not None and s != d for s, d in zip(shape, a.shape))):
        want = "x".join("n" if s is None else str(s) for s in shape) if shape else "2-D"
        raise _err(error, where, f"expected a {want} array, got shape {a.shape}", path)
    _check_finite(a, where, None, error, path, max_abs)
    return np.array(a, dtype=float)


def finite_matrix(a: np.ndarray) -> bool:
    """True when every entry of ``a`` is finite (guard before any LAPACK call).

    >>> finite_matrix(np.array([[1.0, np.nan]]))
    False
    """
    return bool(np.isfinite(a).all())


# ------------------------------------------------------------------ shared argument checks

def check_mechanism(mech: Any, where: str | None = None) -> None:
    """Raise a MechanismError unless ``mech`` is an optkin Mechanism.

    ``where`` (the function, or the argument) starts the message.

    >>> check_mechanism("five_bar", "forward")
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: forward: expected an optkin Mechanism, got str; build one with optkin.mechanisms.* or Mechanism.from_khalil / from_legs
    """
    from .mechanism import Mechanism

    if not isinstance(mech, Mechanism):
        head = f"{where}: " if where else ""
        raise MechanismError(
            f"{head}expected an optkin Mechanism, got {type(mech).__name__}; build one with "
            "optkin.mechanisms.* or Mechanism.from_khalil / from_legs")


_UNSET: Any = object()


def _nonfinite(v: Any) -> bool:
    """NaN or +-inf (a float of any kind)."""
    return isinstance(v, (float, np.floating)) and not math.isfinite(float(v))


def _bound(x: float, integer: bool) -> str:
    return str(int(x)) if integer and float(x).is_integer() else f"{x:g}"


def check_number(v: Any, where: str, *, integer: bool = False, lo: float | None = None,
                 hi: float | None = None, lo_open: bool = False, hi_open: bool = False,
                 finite: bool = True, optional: bool = False, default: Any = _UNSET,
                 want: str | None = None, error: type[Exception] = MechanismError,
                 path: Path = ()) -> Any:
    """``v`` as a float (an int with ``integer``) within the bounds, else ``error``.

    The one validator of numeric arguments and options: it never lets a TypeError or an
    OverflowError through, and its message names the argument (``where``), what it must
    be and what was given.

    Parameters
    ----------
    v : any
        The value given.
    where : str
        The argument, e.g. ``"grid"`` or ``"dof: samples"`` (or ``"forward: option tol"``).
    integer : bool
        A whole number (integral floats such as ``4.0`` accepted; booleans never).
    lo, hi : float, optional
        Bounds, inclusive unless ``lo_open`` / ``hi_open``.
    finite : bool
        False also accepts +-inf (e.g. a limit that inf disables); NaN never.
    optional : bool
        None is accepted (and returned).
    default : optional
        The argument's default: the message then reads ``"{where} must be ... (default
        d), got v"`` (the style of options); without it, ``"{where}: expected ..., got v"``.
    want : str, optional
        What the value must be, in words, where the bounds do not say it (``"a positive
        length"``); default: the kind and the bounds (``"an integer >= 1 and <= 100"``).
    error : exception class
        Raised (MechanismError; StaticsError for the statics).
    path : sequence
        The argument's location (``OptkinError.path``), e.g. ``("options", "tol")``.

    Returns
    -------
    float or int or None

    Examples
    --------
    >>> check_number(4.0, "grid", integer=True, lo=2)
    4
    >>> check_number(0, "step", lo=0, lo_open=True)
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: step: expected a number > 0, got 0
    >>> check_number(-1, "forward: option tol", lo=0, default=1e-10)
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: forward: option tol must be a number >= 0 (default 1e-10), got -1
    """
    if v is None and optional:
        return None
    why = ""  # what the conversion found wrong, when it is more than the bounds say
    try:
        x: Any = as_int(v, where) if integer else as_float(v, where, finite=finite)
        ok = integer or math.isfinite(x) or not finite
        if not integer and math.isfinite(x) and abs(x) > MAX_ABS:
            ok, why = False, f"magnitude above {MAX_ABS:g}"
    except MechanismError as e:
        x, ok = None, False
        if "too large" in str(e):
            why = str(e)[len(where) + 2:]
    if ok and lo is not None and (x <= lo if lo_open else x < lo):
        ok = False
    if ok and hi is not None and (x >= hi if hi_open else x > hi):
        ok = False
    if ok:
        return x
    if want is None:
        kind = "an integer" if integer else "a number"
        if finite and not integer and _nonfinite(v):
            kind = "a finite number"
        parts = []
        if lo is not None and math.isfinite(lo):
            parts.append(f"{'>' if lo_open else '>='} {_bound(lo, integer)}")
        if hi is not None and math.isfinite(hi):
            parts.append(f"{'<' if hi_open else '<='} {_bound(hi, integer)}")
        want = kind + (" " + " and ".join(parts) if parts else "")
    if default is _UNSET:
        msg = f"{where}: expected {want}, got {_show(v)}"
    else:
        msg = f"{where} must be {want} (default {default!r}), got {_show(v)}"
    if why:
        msg += f" ({why})"
    raise _exc(error, msg, path)


def check_option(opts: Any, name: str, where: str, defaults: Any, **bounds: Any) -> Any:
    """``opts[name]`` through :func:`check_number`, as the option ``name`` of the function
    ``where`` whose defaults are ``defaults`` (the message gives the default; the error's
    path is ``("options", name)``).

    >>> check_option({"starts": 0}, "starts", "inverse", {"starts": 256}, integer=True, lo=1)
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: inverse: option starts must be an integer >= 1 (default 256), got 0
    """
    return check_number(opts[name], f"{where}: option {name}", default=defaults[name],
                        path=("options", name), **bounds)
