"""Validation by the same code path as the run: check a call's arguments, skip its work.

Every public function checks its arguments first and then calls :func:`checkpoint`.
Inside ``with validating():`` the checkpoint raises :class:`Checked`, so a caller (the
problem-file validator) runs exactly the checks a real call would make, and nothing else.
``with computing():`` switches the checkpoints off again for a call whose *result* the
validator needs (the configuration of a pose-based statics task, say).

>>> with validating():
...     try:
...         checkpoint()
...     except Checked:
...         print("arguments checked")
arguments checked
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator

__all__ = ["Checked", "checkpoint", "computing", "validating"]

_VALIDATING: contextvars.ContextVar[bool] = contextvars.ContextVar("optkin_validating",
                                                                   default=False)


class Checked(Exception):  # noqa: N818 - a signal, not an error
    """Raised by :func:`checkpoint` while validating: the arguments passed every check."""


def checkpoint() -> None:
    """Call after the argument checks of a public function, before any work."""
    if _VALIDATING.get():
        raise Checked


@contextlib.contextmanager
def _set(var: contextvars.ContextVar[bool], value: bool) -> Iterator[None]:
    token = var.set(value)
    try:
        yield
    finally:
        var.reset(token)


def validating() -> contextlib.AbstractContextManager[None]:
    """Within this block, public functions stop at their checkpoint (raise Checked)."""
    return _set(_VALIDATING, True)


def computing() -> contextlib.AbstractContextManager[None]:
    """Within this block, public functions run in full even while validating."""
    return _set(_VALIDATING, False)
