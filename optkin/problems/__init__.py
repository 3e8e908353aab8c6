"""Problem files (TOML, schema version 1), their validation, tasks and the batch runner.

>>> from optkin.problems import load_problem, run_paths  # doctest: +SKIP

The names below load their modules on first use: the worker machinery
(:mod:`optkin.problems.workers`, :mod:`optkin.problems.dask_worker`) imports only the
standard library, so a batch run starts its workers before it imports pydantic or numpy.
"""

from __future__ import annotations

import importlib
from typing import Any

_NAMES = {
    "RunReport": "optkin.problems.runner",
    "check_expected": "optkin.problems.runner",
    "find_problem_files": "optkin.problems.runner",
    "run_paths": "optkin.problems.runner",
    "run_problem": "optkin.problems.runner",
    "SCHEMA_VERSION": "optkin.problems.schema",
    "TASK_KINDS": "optkin.problems.schema",
    "Problem": "optkin.problems.schema",
    "ProblemFile": "optkin.problems.schema",
    "load_problem": "optkin.problems.schema",
    "validate_document": "optkin.problems.schema",
    "TASKS": "optkin.problems.tasks",
    "register": "optkin.problems.tasks",
}

__all__ = sorted(_NAMES)


def __getattr__(name: str) -> Any:
    module = _NAMES.get(name)
    if module is None:
        raise AttributeError(f"module 'optkin.problems' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_NAMES))
