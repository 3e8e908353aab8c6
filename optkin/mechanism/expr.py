"""A tiny, safe evaluator for geometric parameters written as text ("pi/2", "-d8", "d3")."""

from __future__ import annotations

import ast
import math
import operator
from collections.abc import Mapping

from ..errors import MechanismError

_BIN = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.Pow: operator.pow,
}
_UN = {ast.USub: operator.neg, ast.UAdd: operator.pos}
_CONST = {"pi": math.pi}


def evaluate(text: str, params: Mapping[str, float], where: str) -> float:
    """Evaluate ``text`` with the named ``params``; errors name ``where``.

    >>> evaluate("-d8/2", {"d8": 0.5}, "row 10, d")
    -0.25
    """
    try:
        tree = ast.parse(str(text).strip(), mode="eval")
    except SyntaxError:
        raise MechanismError(
            f"{where}: cannot read {text!r}; write a number, a parameter name or simple "
            "arithmetic such as 'pi/2' or '-d8'"
        ) from None

    def ev(node: ast.AST) -> float:
        if isinstance(node, ast.Expression):
            return ev(node.body)
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)):
            return float(node.value)
        if isinstance(node, ast.Name):
            if node.id in params:
                return float(params[node.id])
            if node.id in _CONST:
                return _CONST[node.id]
            known = ", ".join(sorted(params)) or "none"
            raise MechanismError(
                f"{where}: unknown parameter {node.id!r}; give its value in params "
                f"(known parameters: {known})"
            )
        if isinstance(node, ast.BinOp) and type(node.op) in _BIN:
            return _BIN[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp) and type(node.op) in _UN:
            return _UN[type(node.op)](ev(node.operand))
        raise MechanismError(
            f"{where}: {text!r} is not allowed; only numbers, parameter names, pi and + - * / **"
        )

    value = ev(tree)
    if not math.isfinite(value):
        raise MechanismError(f"{where}: {text!r} evaluates to {value}, expected a finite number")
    return value
