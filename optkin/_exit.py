"""Ending a process whose work is done, without the interpreter's teardown.

Standard library only: the command line imports it with its first module, and a worker
process with the worker machinery.
"""

from __future__ import annotations

import atexit
import contextlib
import os
import signal
import sys
from typing import NoReturn

__all__ = ["fast_exit", "quiet_interrupts"]


def fast_exit(code: int = 0) -> NoReturn:
    """End this process at once with status ``code``, its work done: the exit handlers
    (``atexit``: a private compiled-code cache removed, idle workers told to exit, logging
    flushed) run and the standard streams are flushed, then the interpreter's teardown
    (freeing every module's objects one by one: 50-70 ms with numpy, CasADi and pydantic
    loaded) is skipped. Threads still running are not waited for (the library builders
    of the compiled-code cache are processes of their own and finish regardless)."""
    try:
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(code)


def _interrupted(signum: int, frame: object) -> None:
    with contextlib.suppress(Exception):
        sys.stderr.write("optkin: interrupted\n")
        sys.stderr.flush()
    os._exit(130)


def quiet_interrupts(on: bool = True) -> None:
    """While the command line is still importing (``python -m optkin`` imports the package,
    then its ``__main__``), a Ctrl-C ends the process with status 130 and one line, not a
    traceback through whatever module was loading; ``on=False`` gives Ctrl-C back to
    Python (``KeyboardInterrupt``), which the command line handles once it runs. Nothing
    has been written yet at that point, so nothing is lost."""
    with contextlib.suppress(ValueError):  # (not the main thread: leave signals alone)
        signal.signal(signal.SIGINT, _interrupted if on else signal.default_int_handler)
