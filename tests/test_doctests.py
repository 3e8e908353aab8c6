"""The numeric examples in the docstrings run as doctests."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "optkin._checks",
    "optkin.mechanism.expr",
    "optkin.mechanism.khalil",
    "optkin.mechanism.core",
    "optkin.mechanisms",
    "optkin.solvers.forward",
    "optkin.solvers.inverse",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    mod = importlib.import_module(name)
    failures, tried = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert tried > 0, f"{name} has no examples"
    assert failures == 0
