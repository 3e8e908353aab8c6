"""
Design: a GCI atlas and the optimal dimensions of a five-bar
============================================================

:mod:`optkin.design` treats performance measures as functions of a mechanism's
dimensions. A symmetric five-bar has base length 1, proximal links a and distal links b.
It should work well over a prescribed disc of radius 0.3 centred at (0.5, 1.3), in the
working mode (+, -). The global conditioning index (GCI, Gosselin and Angeles 1991) is
the area-weighted mean over the disc of 1/kappa, the inverse condition number of the
forward Jacobian. This example first maps the GCI and the least 1/kappa on the disc over
the (a, b) design plane. It then maximises the GCI subject to a + b <= 2.6 and
1/kappa >= 0.3 everywhere on the disc (the problem of optkin's README) and checks the
optimum on a conditioning map.
"""

import matplotlib.pyplot as plt
import numpy as np
from matplotlib import patheffects

import optkin
from optkin import design
from optkin import mechanisms as M


def five(a, b):
    """The family: base 1, proximal links a, distal links b."""
    return M.five_bar(1.0, a, b, b, a)


disc = design.Disc((0.5, 1.3), 0.3)
mode = (1, -1)
bounds = {"a": (0.5, 1.8), "b": (0.5, 1.8)}

# %%
# An atlas of the design plane
# ----------------------------
# :func:`optkin.design.atlas` evaluates the measures on a grid of designs. One compiled
# evaluation per topology serves every design (the geometry is an input of the compiled
# functions). A 32 x 32 grid keeps the build fast. Points of the disc that a design
# cannot reach in the working mode count 0, so such designs score low.
at = design.atlas(five, bounds, {"GCI over the disc": design.GCI(disc, mode),
                                 "least 1/kappa on disc": design.MinConditioning(disc, mode)},
                  n=32)
print(at.message or f"{at.values['GCI over the disc'].size} designs in {at.time:.1f} s")

# %%
# The optimum
# -----------
# :func:`optkin.design.optimize` with ``method="ipopt"`` starts IPOPT from the centre of
# the bounds. It imposes the conditioning constraint at quadrature nodes of the disc and
# refines them by an exchange step. The default ``method="auto"`` first runs a global
# search (differential evolution), which the atlas makes unnecessary here: the GCI has a
# single maximum in the bounds. ``verification`` re-checks every constraint on a denser
# set of points.
res = design.optimize(five, bounds, design.Maximize(design.GCI(disc, mode)),
                      [design.Dimension({"a": 1, "b": 1}) <= 2.6,
                       design.MinConditioning(disc, mode) >= 0.3], method="ipopt")
a_opt, b_opt = res.dimensions["a"], res.dimensions["b"]
print(res)
for name, v in res.verification.items():
    print(f"  {name}: {v['value']:.4f} ({'ok' if v['ok'] else 'violated'}, {v['how']})")

# %%
# ``Atlas.plot`` draws one contour map per measure, with a star at the grid's best
# design. On top are the constraint a + b = 2.6 (dashed), the boundary of the region
# where the least 1/kappa reaches 0.3 (red) and the optimum found by IPOPT (red dot).
# The feasible designs lie below the dashed line and inside the red curve. The contour
# values are read from the colour bars, so the contour labels are removed.
fig = at.plot()
fig.set_size_inches(11, 5.4)
X, Y = np.meshgrid(*at.axes)
for ax in [ax for ax in fig.axes if ax.get_xlabel() == "a"]:
    for text in list(ax.texts):  # the contour labels
        text.remove()
    s = np.array([2.6 - at.axes[1][-1], at.axes[0][-1]])  # the segment within the grid
    ax.plot(s, 2.6 - s, "--", color="w", lw=1.8, label="a + b = 2.6",
            path_effects=[patheffects.withStroke(linewidth=3.2, foreground="k")])
    ax.contour(X, Y, at.values["least 1/kappa on disc"], levels=[0.3], colors="tab:red",
               linewidths=1.6)
    ax.plot([], [], color="tab:red", lw=1.6, label="least 1/kappa = 0.3")
    ax.plot(a_opt, b_opt, "o", color="tab:red", mec="w", ms=8,
            label=f"optimum ({a_opt:.3f}, {b_opt:.3f})")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8,
              frameon=False)

# %%
# The optimal five-bar and its conditioning
# -----------------------------------------
# :func:`optkin.design.conditioning` evaluates 1/kappa at many task points in one call.
# Unreachable points, and those of the other working modes, are left blank. The
# prescribed disc (dashed) lies where 1/kappa is high. The largest singularity-free disc
# about the same centre (:func:`optkin.design.largest_inscribed`) is bounded by the
# serial singularity where it touches the workspace boundary.
best = res.mechanism
X, Y = np.meshgrid(np.linspace(-1.4, 2.4, 240), np.linspace(-0.3, 2.5, 180))
ik = design.conditioning(best, np.column_stack([X.ravel(), Y.ravel()]), mode=mode)
free = design.largest_inscribed(best, mode, centre=disc.centre)
print(free)
pose = optkin.inverse(best, list(disc.centre))
wm = [r for r in pose if tuple(r.working_mode) == mode]

fig, ax = plt.subplots(figsize=(8, 6))
cs = ax.contourf(X, Y, ik.reshape(X.shape), levels=np.linspace(0, 1, 11), cmap="viridis")
fig.colorbar(cs, ax=ax, shrink=0.8, label="1/kappa (working mode (+, -))")
ax.add_patch(plt.Circle(disc.centre, disc.radius, fill=False, color="k", ls="--", lw=1.8,
                        label=f"prescribed disc, GCI {res.value:.4f}"))
ax.add_patch(plt.Circle(free.centre, free.size, fill=False, color="tab:red", lw=1.6,
                        label=f"largest singularity-free disc, r = {free.size:.3f}"))
optkin.plot.draw(best, wm[0], ax=ax)
ax.set_xlim(X.min(), X.max())
ax.set_ylim(Y.min(), Y.max())
ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.1), ncol=2, fontsize=8, frameon=False)
ax.set_title(f"optimal five-bar: a = {a_opt:.4f}, b = {b_opt:.4f}", fontsize=11)
fig.tight_layout()
