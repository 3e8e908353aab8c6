"""Singularity pictures: distance-to-singularity maps over 2-D slices (PNG).

    python examples/singularity_maps.py [out_dir]   # default docs/pictures

1. The five-bar of Chablat & Wenger 1998 (L0 = 9, L1 = 8, L2 = 5, L3 = 5, L4 = 8) over
   its workspace (x, y) in the working mode of the first posture found: log10 of
   min(parallel, serial margin) of optkin.classify; the dark valleys are the parallel
   singularities (C, P, D aligned) and the workspace boundary the serial ones.
2. The Acma SR400 (Table 7.1) over the joint slice (theta2, theta7) with theta5 = 0.8 (away
   from the wrist singularity theta5 = 0): the valley is the elbow singularity (arm
   stretched, theta3 = pi/2 - theta2 + theta7 close to pi/2).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import optkin


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    m = optkin.mechanisms.five_bar(9.0, 8.0, 5.0, 5.0, 8.0)
    sm = optkin.plot_singularity_map(m, np.linspace(-6, 15, 64), np.linspace(0.2, 13, 64),
                                     str(out / "singularity_five_bar.png"))
    print("five-bar:", sm.path, f"reachable {sm.reachable.mean():.0%}")
    sr = optkin.mechanisms.sr400()
    sm = optkin.plot_singularity_map(sr, np.linspace(-1.5, 1.5, 41), np.linspace(-1.5, 1.5, 41),
                                     str(out / "singularity_sr400.png"), axes=("theta2", "theta7"),
                                     fixed={"theta5": 0.8})
    print("SR400:", sm.path, f"min distance {np.nanmin(sm.values['distance']):.2e}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/pictures"))
