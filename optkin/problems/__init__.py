"""Problem files (TOML, schema version 1), their validation, tasks and the batch runner.

>>> from optkin.problems import load_problem, run_paths  # doctest: +SKIP
"""

from optkin.problems.runner import (
    RunReport,
    check_expected,
    find_problem_files,
    run_paths,
    run_problem,
)
from optkin.problems.schema import (
    SCHEMA_VERSION,
    TASK_KINDS,
    Problem,
    ProblemFile,
    load_problem,
    validate_document,
)
from optkin.problems.tasks import TASKS, register

__all__ = [
    "SCHEMA_VERSION",
    "TASK_KINDS",
    "TASKS",
    "Problem",
    "ProblemFile",
    "RunReport",
    "check_expected",
    "find_problem_files",
    "load_problem",
    "register",
    "run_paths",
    "run_problem",
    "validate_document",
]
