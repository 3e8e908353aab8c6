"""Pictures of dimensional synthesis with optkin.design (PNG).

    python examples/design_pictures.py [out_dir]   # default docs/pictures

1. Liu, Wang and Pritschow's normalised 5R (r1 + r2 + r3 = 3, both elbows outward): an
   atlas of the GCI over a disc on the symmetry axis across the design triangle.
2. A symmetric five-bar: the GCI over a disc maximised subject to L1 + L2 <= 2.6 and
   1/kappa >= 0.3 on the disc; the optimum's workspace with the disc and its largest
   singularity-free disc on the axis, and the convergence.
3. Le, Kang and Doan's five-bar: the largest square with 1/kappa >= 0.5 on the axis at the
   published rho = 1.9721 and at optkin's optimum.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import optkin  # noqa: E402
from optkin import design  # noqa: E402

OUT = (1, -1)


def liu(r1, r2, r3):
    return optkin.mechanisms.five_bar(2 * r3, r1, r2, r2, r1)


def lkd(rho):
    return optkin.mechanisms.five_bar(np.sqrt(2) * (rho - 1), 1.0, rho, rho, 1.0)


def _region(ax, mech, shape_res, region=None, title=""):
    """The working mode's feasible points (light), the region and the inscribed shape."""
    pr = design.measures._probe(mech, OUT)
    b = pr.reach
    X, Y = np.meshgrid(np.linspace(*b[0], 400), np.linspace(*b[1], 400))
    o = pr.eval(np.stack([X.ravel(), Y.ravel()], -1))
    s0 = np.sign(pr.eval(shape_res.centre[None])["det"][0])
    ok = (o["valid"] & (np.sign(o["det"]) == s0)).reshape(X.shape)
    ik = np.where(ok, o["inv_kappa"].reshape(X.shape), np.nan)
    cs = ax.contourf(X, Y, ik, levels=np.linspace(0, 1, 11), cmap="viridis")
    plt.colorbar(cs, ax=ax, label="1/kappa (this aspect)")
    c, h = shape_res.centre, shape_res.size
    if shape_res.shape == "disc":
        ax.add_patch(plt.Circle(c, h, fill=False, color="r", lw=1.5,
                                label=f"largest disc r = {h:.4f}"))
    else:
        ax.add_patch(plt.Rectangle(c - h, 2 * h, 2 * h, fill=False, color="r", lw=1.5,
                                   label=f"largest square side {2 * h:.4f}"))
    ax.plot(*shape_res.contact, "rx", ms=8, label=f"contact ({shape_res.binding})")
    if region is not None:
        ax.add_patch(plt.Circle(region.centre, region.radius, fill=False, color="k", ls="--",
                                lw=1.2, label="prescribed disc"))
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="lower left", fontsize=7)


def main(out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    # 1. Liu's design triangle
    at = design.atlas(liu, {"r1": (0.05, 2.95), "r2": (0.05, 2.95), "r3": (0.05, 2.95)},
                      {"GCI over a disc of radius 0.2 on the axis at (r1 + r2) / 2":
                       design.GCI(lambda d: design.Disc((d["r3"], 0.5 * (d["r1"] + d["r2"])),
                                                        0.2), OUT)},
                      equal=[({"r1": 1, "r2": 1, "r3": 1}, 3.0)], n=120)
    at.plot(out / "design_liu_atlas.png")
    # 2. a five-bar optimised
    disc = design.Disc((0.5, 1.3), 0.3)
    five = lambda a, b: optkin.mechanisms.five_bar(1.0, a, b, b, a)   # noqa: E731
    res = design.optimize(five, {"a": (0.5, 1.8), "b": (0.5, 1.8)},
                          design.Maximize(design.GCI(disc, OUT)),
                          [design.Dimension({"a": 1, "b": 1}) <= 2.6,
                           design.MinConditioning(disc, OUT) >= 0.3])
    best = design.largest_inscribed(res.mechanism, OUT, line=((0.5, 0), (0, 1), (0, 2.5)))
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.4), dpi=150)
    _region(axs[0], res.mechanism, best, disc,
            f"optimum a = {res.dimensions['a']:.4f}, b = {res.dimensions['b']:.4f}: "
            f"GCI {res.value:.4f}")
    res.plot(ax=axs[1])
    fig.tight_layout()
    fig.savefig(out / "design_five_bar_optimum.png")
    plt.close(fig)
    # 3. Le, Kang and Doan
    sq = design.LargestInscribed(OUT, shape="square", gamma=0.5,
                                 line=lambda d: ((np.sqrt(2) / 2 * (d["rho"] - 1), 0), (0, 1),
                                                 (0, 1 + d["rho"])))
    opt = design.optimize(lkd, {"rho": (1.2, 3.0)}, design.Maximize(sq))
    fam = design.Family(lkd, {"rho": (1.2, 3.0)})
    fig, axs = plt.subplots(1, 2, figsize=(11, 4.4), dpi=150)
    for ax, rho, what in ((axs[0], 1.9721, "published"), (axs[1], opt.dimensions["rho"],
                                                          "optkin")):
        r = sq.result(fam, np.array([rho]))
        _region(ax, lkd(rho), r, None, f"{what}: rho = {rho:.4f}")
    fig.tight_layout()
    fig.savefig(out / "design_le_kang_doan.png")
    plt.close(fig)
    print(f"pictures in {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/pictures"))
