"""A rough cost (seconds on one core) of each task of a problem file, for scheduling.

The batch runner splits problems into units of tasks and starts the longest first (the LPT
rule: with the costs known to within a factor, no worker idles long while another still
has much to do). The figures are medians measured on the bundled problems and the
benchmark batches (``benchmarks/test_scaling.py``), scaled by the sizes a task asks for;
they only need to order the work, not predict it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

__all__ = ["task_costs", "BASE_COST", "PROBLEM_COST"]

#: Seconds per task kind at its default sizes.
BASE_COST: dict[str, float] = {
    "forward": 0.01,
    "inverse": 0.03,
    "assembly_modes": 0.15,
    "track": 0.005,  # per path point
    "jacobians": 0.02,
    "dof": 0.15,
    "classify": 0.05,
    "singular_curves": 0.4,
    "working_modes": 0.03,
    "aspects": 1.2,
    "workspace": 0.6,
    "statics": 0.08,
    "design": 6.0,
}
#: Seconds to load a problem and fetch its model (per unit of work).
PROBLEM_COST = 0.05


def _num(v: Any, default: float) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(
        float(v)) else default


def _size(mech: Mapping[str, Any]) -> float:
    """A factor for the mechanism's size: its number of legs or rows."""
    legs = mech.get("legs")
    if isinstance(legs, list):
        return max(1.0, len(legs) / 3.0)
    rows = mech.get("rows")
    if isinstance(rows, list):
        return max(1.0, len(rows) / 4.0)
    args = mech.get("args")
    if isinstance(args, Mapping):
        for key in ("base", "rails", "platform"):
            pts = args.get(key)
            if isinstance(pts, list):
                return max(1.0, len(pts) / 3.0)
    name = mech.get("name")
    return 2.0 if name in ("stewart_gough", "hexa", "pus6", "sr400", "akr3000") else 1.0


def task_costs(doc: Any) -> list[float]:
    """The estimated cost of each task of a parsed problem document (1 s each for what
    cannot be read: the worker will say what is wrong)."""
    if not isinstance(doc, Mapping) or not isinstance(doc.get("task"), list):
        return [1.0]
    mech = doc.get("mechanism") if isinstance(doc.get("mechanism"), Mapping) else {}
    k = _size(mech)
    out = []
    for t in doc["task"]:
        if not isinstance(t, Mapping):
            out.append(1.0)
            continue
        kind = t.get("kind")
        c = BASE_COST.get(kind, 1.0) if isinstance(kind, str) else 1.0
        opts = t.get("options") if isinstance(t.get("options"), Mapping) else {}
        if kind == "track":
            path = t.get("qa_path")
            c *= len(path) if isinstance(path, list) else 50
        if kind == "assembly_modes":
            c *= k * k * max(1.0, _num(opts.get("starts"), 2000) / 2000)
        elif kind in ("aspects", "workspace", "singular_curves"):
            g = _num(t.get("grid"), 32)
            c *= max(1.0, (g / 32) ** 2)
        else:
            c *= k
        out.append(c)
    return out
