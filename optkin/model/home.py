"""A mechanism's home configuration as the model sees it.

A description gives its home either as joint values (a Khalil table: the default guess of
its passive and cut joints, every joint listed) or as a pose (a platform: task
coordinates). Consumers ask here instead of telling the two apart by the vector's length.
"""

from __future__ import annotations

import numpy as np

from .core import Model

__all__ = ["home_task", "home_joints"]


def home_task(model: Model) -> np.ndarray | None:
    """The task coordinates of the mechanism's home pose (a platform with a home), else
    None (a home given as joint values is not a pose)."""
    home = model.mech.home
    if model.platform is None or home is None:
        return None
    return np.array(home, dtype=float)


def home_joints(model: Model) -> np.ndarray | None:
    """Every joint value at home when the description gives them (a Khalil table's home),
    else None (a platform's home is a pose: its joint values come from the inverse
    model)."""
    home = model.mech.home
    if model.platform is not None or home is None:
        return None
    return np.array(home, dtype=float)
