"""Pictures of singular loci traced by continuation, working modes and aspects (PNG).

    python examples/aspects_pictures.py [out_dir]   # default docs/pictures

1. The five-bar of Chablat & Wenger 1998 (L0 = 9, L1 = 8, L2 = 5, L3 = 5, L4 = 8):
   parallel (red) and serial (blue) singular curves in the joint space and in the
   workspace (Chablat & Wenger 1998, sections 3.2-3.3), the workspace of each of the four working
   modes (Figs. 9-12), and the generalized aspects of each working mode, coloured, with
   their joint-space projections (serial aspects QA).
2. A 3-RPR (A1 = (0, 0), A2 = (15.91, 0), A3 = (0, 10); platform sides 17.04, 16.54,
   20.84): the section rho1 = 14.98 of its singular surface in (rho2, rho3) with its cusps,
   and its aspects at constant orientation phi = 0.5 with leg strokes [10, 30].
3. The four-bar of Modern Robotics 7.3 (L1 = L2 = 4, L3 = L4 = 2): its C-space in
   (theta, phi) through the two bifurcation points.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import optkin  # noqa: E402


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    m = optkin.mechanisms.five_bar(9.0, 8.0, 5.0, 5.0, 8.0)
    fig, axs = plt.subplots(1, 2, figsize=(11, 5.5))
    for ax, plane in zip(axs, ("joint", "workspace")):
        r = optkin.singular_curves(m, plane=plane, kind="all")
        r.plot(ax=ax, title=f"five-bar: singular curves ({plane})")
        print(f"five-bar {plane}: {r.message}")
    fig.savefig(out / "five_bar_singular_curves.png", dpi=90, bbox_inches="tight")
    plt.close(fig)
    ws = optkin.workspace(m)
    ws.plot(str(out / "five_bar_working_modes.png"))
    print("five-bar workspace:", ws.message)
    asp = optkin.aspects(m)
    asp.plot(str(out / "five_bar_aspects.png"))
    print("five-bar aspects:", asp.message)

    d1, d2, d3 = 17.04, 16.54, 20.84
    al = np.arccos((d1**2 + d3**2 - d2**2) / (2 * d1 * d3))
    rpr = optkin.mechanisms.rpr3([[0, 0], [15.91, 0], [0, 10]],
                                 [[0, 0], [d1, 0], [d3 * np.cos(al), d3 * np.sin(al)]])
    r = optkin.singular_curves(rpr, plane="joint", fixed={"L1.rho": 14.98},
                               bounds=[[0, 40], [0, 40]])
    r.plot(str(out / "rpr3_joint_section_cusps.png"),
           title="3-RPR: singular curve at rho1 = 14.98, cusps")
    print("3-RPR section:", r.message, f"{len(r.cusps)} cusps")
    lim = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
    a = optkin.aspects(rpr, fixed={"phi": 0.5}, limits=lim)
    a.plot(str(out / "rpr3_aspects_phi.png"), title="3-RPR: aspects at phi = 0.5")
    print("3-RPR aspects:", a.message)

    fb = optkin.mechanisms.four_bar(4.0, 4.0, 2.0, 2.0)
    r = optkin.singular_curves(fb, plane=("theta", "phi"))
    r.plot(str(out / "four_bar_cspace.png"), title="four-bar (4, 4, 2, 2): C-space")
    print("four-bar:", r.message)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent.parent
         / "docs" / "pictures")
