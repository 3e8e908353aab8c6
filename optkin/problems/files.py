"""Reading problem files: bounded TOML parsing and the resume key.

Standard library only: the command line's process reads, hashes and estimates the cost of
every problem file with these and never imports pydantic, numpy or CasADi (the workers
validate the files against :mod:`optkin.problems.schema`, which re-exports these names).
"""

from __future__ import annotations

import hashlib
import re
import sys
from typing import Any

from optkin.errors import ProblemFileError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

__all__ = ["MAX_FILE_BYTES", "input_hash", "optkin_version", "parse_toml"]


def optkin_version() -> str:
    """The installed optkin version ("0+unknown" when not installed)."""
    try:
        import optkin

        v = getattr(optkin, "__version__", None)
        if v:
            return str(v)
    except Exception:  # pragma: no cover - partial installs
        pass
    try:
        from importlib.metadata import version

        return version("optkin")
    except Exception:  # pragma: no cover
        return "0+unknown"


def input_hash(data: bytes) -> str:
    """sha256 of the problem file bytes plus the optkin version (the resume key)."""
    h = hashlib.sha256()
    h.update(data)
    h.update(b"\0optkin ")
    h.update(optkin_version().encode())
    return h.hexdigest()


#: Largest problem file parsed (bytes).
MAX_FILE_BYTES = 4 << 20
#: Deepest nesting of arrays and inline tables accepted in a problem file.
MAX_NESTING = 32
#: Most dotted parts accepted in one TOML key (``a.b.c`` has 3).
MAX_KEY_PARTS = 32
#: Longest integer literal accepted (digits).
MAX_INT_DIGITS = 400

_TOML_TOKENS = re.compile(
    r"#[^\n]*"                                  # comment
    r'|"""(?:[^"\\]|\\.|"(?!""))*"""'           # multi-line basic string
    r"|'''[\s\S]*?'''"                          # multi-line literal string
    r'|"(?:[^"\\\n]|\\.)*"'                     # basic string
    r"|'[^'\n]*'"                               # literal string
    r"|[0-9][0-9_]*"                            # digits (integer literals, dates, floats)
    r"|[\[\]{}=,.\n]"                           # structure
)


def _guard_toml(text: str, filename: str) -> None:
    """Refuse, before parsing, what would make the parser recurse or allocate without
    bound: deep nesting, keys with very many dotted parts, huge integer literals."""
    depth = parts = 0
    line = 1
    for m in _TOML_TOKENS.finditer(text):
        tok = m.group()
        c = tok[0]
        if c == "\n":
            line += 1
            parts = 0
        elif c in "\"'":
            line += tok.count("\n")
        elif c in "[{":
            depth += 1
            parts = 0
            if depth > MAX_NESTING:
                raise ProblemFileError(f"{filename}: line {line}: arrays and tables nested more "
                                       f"than {MAX_NESTING} deep; flatten the file")
        elif c in "]}":
            depth = max(0, depth - 1)
            parts = 0
        elif c in "=,":
            parts = 0
        elif c == ".":
            parts += 1
            if parts >= MAX_KEY_PARTS:
                raise ProblemFileError(f"{filename}: line {line}: a key with more than "
                                       f"{MAX_KEY_PARTS} dotted parts; use tables instead")
        elif c.isdigit() and len(tok) > MAX_INT_DIGITS:
            raise ProblemFileError(f"{filename}: line {line}: a number with {len(tok)} digits; "
                                   f"at most {MAX_INT_DIGITS} are read")


def parse_toml(data: bytes, filename: str) -> dict[str, Any]:
    """Parse TOML bytes; errors become ``file: line L, column C: ...``.

    Size, nesting, dotted keys and integer literals are bounded before parsing
    (:data:`MAX_FILE_BYTES`, :data:`MAX_NESTING`, :data:`MAX_KEY_PARTS`,
    :data:`MAX_INT_DIGITS`), so no file can exhaust the parser's stack or memory.
    """
    if len(data) > MAX_FILE_BYTES:
        raise ProblemFileError(f"{filename}: (file): {len(data)} bytes is larger than the "
                               f"{MAX_FILE_BYTES} bytes a problem file may have")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ProblemFileError(f"{filename}: (file): not UTF-8 text ({e.reason} at byte {e.start})") from None
    _guard_toml(text, filename)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        msg = str(e)
        m = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        where = f"line {m.group(1)}, column {m.group(2)}" if m else "(file)"
        reason = re.sub(r"\s*\(at line \d+, column \d+\)", "", msg) or "syntax error"
        if m is None and "end of document" in msg:
            where = "end of file"
        raise ProblemFileError(f"{filename}: {where}: invalid TOML: {reason}") from None
    except (ValueError, RecursionError, MemoryError, OverflowError) as e:
        raise ProblemFileError(f"{filename}: (file): invalid TOML: {type(e).__name__}: "
                               f"{str(e)[:120]}") from None
