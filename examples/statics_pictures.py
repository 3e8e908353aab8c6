"""Statics pictures: a capability polygon and a wrench-feasible workspace map (PNG).

    python examples/statics_pictures.py [out_dir]   # default docs/pictures

1. The force capability polygon (fx, fy at zero moment) of the redundantly actuated 4-RPR
   of problems/rpr4.toml at the pose (2.1, 1.4, -0.25), legs limited to |tau_i| <= 100:
   72 capability LPs (solid) and the exact section of the capability zonotope (dashed).
2. The wrench-feasible workspace of the Modern Robotics 3-RPR of problems/rpr3.toml at
   phi = 0.1: where the platform can apply every wrench of the box fx in [-0.5, 0.5],
   fy in [-1, 0], mz in [-0.1, 0.1] with |tau_i| <= 2, coloured by the margin (fraction of
   the actuator limit left at the worst vertex); the black curve is margin = 0.
"""

from __future__ import annotations

import sys
from pathlib import Path

import optkin
from optkin import statics


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    m4 = optkin.mechanisms.rpr4([[0, 0], [4, 0], [4, 3], [0, 3]],
                                [[-0.5, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.5, 0.3]])
    s4 = optkin.inverse(m4, [2.1, 1.4, -0.25])[0]
    cap = statics.capability_polygon(m4, s4, 100.0, n=72, path=str(out / "statics_capability.png"))
    print("capability polygon:", cap.status, f"min {cap.max.min():.4g}, max {cap.max.max():.4g}")
    m3 = optkin.mechanisms.rpr3([[0, 0], [4, 0], [0, 3]], [[-0.5, -0.3], [0.5, -0.3], [0, 0.4]])
    ws = statics.wrench_feasible_workspace(
        m3, {"lower": [-0.5, -1.0, -0.1], "upper": [0.5, 0.0, 0.1]}, 2.0, grid=41,
        bounds=[[0.3, 3.6], [0.2, 2.8]], fixed=[0.0, 0.0, 0.1],
        path=str(out / "statics_workspace.png"))
    print("workspace:", ws.message, f"({ws.stats.solve_time:.1f} s)")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent.parent / "docs" / "pictures")
