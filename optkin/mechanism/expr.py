"""A tiny, safe evaluator for geometric parameters written as text ("pi/2", "-d8", "d3").

Only numbers, parameter names, ``pi``, parentheses and ``+ - * / **`` are read. The work is
bounded before anything is computed: the text is at most :data:`MAX_LENGTH` characters and
its syntax tree at most :data:`MAX_NODES` nodes and :data:`MAX_DEPTH` levels deep, and the
tree is evaluated without recursion, in floating point (so ``9**9**9`` overflows at once
instead of building a huge integer). Division by zero, overflow and complex results
(``(-1)**0.5``) are errors that name the entry.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Mapping, Sequence

from .._checks import MAX_ABS as _MAX_ABS
from ..errors import MechanismError

__all__ = ["evaluate", "MAX_LENGTH", "MAX_NODES", "MAX_DEPTH"]

#: Longest expression text accepted (characters).
MAX_LENGTH = 1000
#: Largest syntax tree accepted (nodes: numbers, names and operators).
MAX_NODES = 500
#: Deepest nesting accepted (operators within operators).
MAX_DEPTH = 100

_CONST = {"pi": math.pi}
_OPS = {ast.Add: "+", ast.Sub: "-", ast.Mult: "*", ast.Div: "/", ast.Pow: "**",
        ast.USub: "-", ast.UAdd: "+"}


def _fail(where: str, msg: str, path: Sequence[str | int]) -> MechanismError:
    return MechanismError(f"{where}: {msg}", path=tuple(path))


def _parse(text: str, where: str, path: Sequence[str | int]) -> ast.Expression:
    """The syntax tree of ``text``, after the size checks."""
    src = str(text).strip()
    if len(src) > MAX_LENGTH:
        raise _fail(where, f"the expression is {len(src)} characters long; at most "
                    f"{MAX_LENGTH} are read: give the value as a number or a parameter", path)
    try:
        tree = ast.parse(src, mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError):
        raise _fail(where, f"cannot read {src[:60]!r}; write a number, a parameter name or "
                    "simple arithmetic such as 'pi/2' or '-d8'", path) from None
    # size and depth, iteratively (the tree may be deep: "-" * 400 + "1")
    count, stack = 0, [(tree.body, 1)]
    while stack:
        node, depth = stack.pop()
        count += 1
        if count > MAX_NODES:
            raise _fail(where, f"the expression has more than {MAX_NODES} terms; give the value "
                        "as a number or a parameter", path)
        if depth > MAX_DEPTH:
            raise _fail(where, f"the expression is nested more than {MAX_DEPTH} levels deep; "
                        "simplify it", path)
        for child in ast.iter_child_nodes(node):
            if not isinstance(child, (ast.operator, ast.unaryop, ast.expr_context)):
                stack.append((child, depth + 1))
    return tree


def _apply(op: ast.AST, a: float, b: float | None, where: str, text: str,
           path: Sequence[str | int]) -> float:
    """One operation on floats; errors instead of exceptions, inf, NaN or complex."""
    try:
        if b is None:
            r = -a if isinstance(op, ast.USub) else a
        elif isinstance(op, ast.Add):
            r = a + b
        elif isinstance(op, ast.Sub):
            r = a - b
        elif isinstance(op, ast.Mult):
            r = a * b
        elif isinstance(op, ast.Div):
            if b == 0.0:
                raise _fail(where, f"{text!r} divides by zero", path)
            r = a / b
        else:  # ast.Pow: math.pow stays real and raises instead of returning complex
            if a < 0 and not float(b).is_integer():
                raise _fail(where, f"{text!r} raises a negative number to a fractional power "
                            "(a complex number); expected a real number", path)
            if a == 0.0 and b < 0:
                raise _fail(where, f"{text!r} divides by zero (0 to a negative power)", path)
            r = math.pow(a, b)
    except OverflowError:
        r = math.inf
    if not math.isfinite(r):
        raise _fail(where, f"{text!r} overflows (a value beyond {_MAX_ABS:g}); expected a "
                    "finite number of sensible size", path)
    return r


def evaluate(text: str, params: Mapping[str, float], where: str,
             path: Sequence[str | int] = ()) -> float:
    """Evaluate ``text`` with the named ``params``; errors name ``where`` and carry ``path``.

    >>> evaluate("-d8/2", {"d8": 0.5}, "row 10, d")
    -0.25
    >>> evaluate("9**9**9", {}, "row 2 (frame j=2), column d", ("rows", 1, "d"))
    Traceback (most recent call last):
    ...
    optkin.errors.MechanismError: row 2 (frame j=2), column d: '9**9**9' overflows (a value beyond 1e+150); expected a finite number of sensible size
    """
    tree = _parse(text, where, path)
    src = str(text).strip()
    shown = src if len(src) <= 60 else src[:57] + "..."
    values: list[float] = []
    # post-order walk with an explicit stack: (node, children done?)
    stack: list[tuple[ast.AST, bool]] = [(tree.body, False)]
    while stack:
        node, done = stack.pop()
        if isinstance(node, ast.Constant):
            v = node.value
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise _fail(where, f"{shown!r} is not allowed; only numbers, parameter names, "
                            "pi and + - * / **", path)
            try:
                fv = float(v)
            except OverflowError:
                fv = math.inf
            if not math.isfinite(fv) or abs(fv) > _MAX_ABS:
                lit = ast.get_source_segment(src, node) or str(v)
                raise _fail(where, f"the number {lit[:20]} in {shown!r} is too large "
                            f"(magnitude above {_MAX_ABS:g})", path)
            values.append(fv)
        elif isinstance(node, ast.Name):
            if node.id in params:
                values.append(float(params[node.id]))
            elif node.id in _CONST:
                values.append(_CONST[node.id])
            else:
                known = ", ".join(sorted(params)) or "none"
                raise _fail(where, f"unknown parameter {node.id!r}; give its value in params "
                            f"(known parameters: {known})", path)
        elif isinstance(node, ast.BinOp) and type(node.op) in _OPS:
            if not done:
                stack += [(node, True), (node.right, False), (node.left, False)]
            else:
                b, a = values.pop(), values.pop()
                values.append(_apply(node.op, a, b, where, shown, path))
        elif isinstance(node, ast.UnaryOp) and type(node.op) in _OPS:
            if not done:
                stack += [(node, True), (node.operand, False)]
            else:
                values.append(_apply(node.op, values.pop(), None, where, shown, path))
        else:
            raise _fail(where, f"{shown!r} is not allowed; only numbers, parameter names, pi "
                        "and + - * / **", path)
    value = values.pop()
    if abs(value) > _MAX_ABS:
        raise _fail(where, f"{shown!r} evaluates to {value:g}, beyond {_MAX_ABS:g}; expected a "
                    "finite number of sensible size", path)
    return value
