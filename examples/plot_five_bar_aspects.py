"""
Working modes and aspects of a five-bar (Chablat and Wenger 1998)
=================================================================

The RR-RRR five-bar of Chablat and Wenger, "Working modes and aspects in fully parallel
manipulators" (ICRA 1998), has base length L0 = 9, proximal links L1 = L4 = 8 and distal
links L2 = L3 = 5. This example reproduces the paper's analysis with optkin: the four
working modes (the signs of the two legs' elbows), the parallel and serial singular
curves in the joint space and in the workspace (sections 3.2-3.3), traced by
pseudo-arclength continuation, and the generalized aspects of each working mode, which
are the regions free of parallel singularities.
"""

import matplotlib.pyplot as plt

import optkin

five = optkin.mechanisms.five_bar(9, 8, 5, 5, 8)

# %%
# Four working modes at one point
# -------------------------------
# The inverse kinematics of each leg has two solutions (elbow one way or the other). A
# point of the workspace is therefore reached in up to four postures, one per *working
# mode* ``(s1, s2)``, the signs of the diagonal of the serial Jacobian B.
# ``optkin.plot.draw`` with no ``ax`` gives one panel per posture.
postures = optkin.inverse(five, [4.5, 6.0])
print(postures.summary())
fig = optkin.plot.draw(five, postures, title="five-bar (9, 8, 5, 5, 8) at P = (4.5, 6)")
fig.set_size_inches(12, 4.2)
for ax, r in zip(fig.axes, postures):
    signs = ", ".join("+" if w > 0 else "-" for w in r.working_mode)
    ax.set_title(f"working mode ({signs})", fontsize=11)
fig.tight_layout(rect=(0, 0.06, 1, 1))

# %%
# Singular curves
# ---------------
# Parallel singularities (det A = 0: C, D and P aligned) and serial singularities (a leg
# stretched or folded, B_ii = 0), traced by continuation in the plane of the actuated
# joints and in the workspace. In the joint space, the parallel curve C, D, P aligned with
# ``|CD| = L2 + L3`` is one closed curve on the torus. The workspace is bounded by the serial
# curves, which are circles of radius L1 - L2 = 3 and L1 + L2 = 13 about each base joint.
fig, axs = plt.subplots(1, 2, figsize=(10.5, 5.4), width_ratios=[1, 0.68])
for ax, plane in zip(axs, ("joint", "workspace")):
    curves = optkin.singular_curves(five, plane=plane, kind=["parallel", "serial"])
    curves.plot(ax=ax, title=f"singular curves in the {plane} plane")
    print(f"{plane}: {curves.message}")
    ax.set_aspect("equal")
    ax.title.set_fontsize(12)
    ax.legend(fontsize=9, loc="upper right", framealpha=0.9)
axs[0].set_xlabel(r"$\theta_1$ of leg 1 (rad)")
axs[0].set_ylabel(r"$\theta_1$ of leg 2 (rad)")
axs[1].set_xlabel("x")
axs[1].set_ylabel("y")
fig.tight_layout()

# %%
# Generalized aspects of each working mode
# ----------------------------------------
# Within one working mode, the parallel singular curves cut the workspace into *aspects*,
# the largest connected regions where det A keeps one sign. :func:`optkin.aspects`
# builds them from the traced curves as faces of a planar arrangement, with exact polygon
# areas, and their images QA in the joint space. The two pairs of symmetric working modes
# have 2 and 3 aspects.
asp = optkin.aspects(five)
print(asp.message)
for a in asp.aspects:
    print(f"working mode {a.working_mode}, det A {'+' if a.det_sign > 0 else '-'}: "
          f"area {a.area:7.2f} in the workspace, {a.qa_area:5.2f} rad^2 in the joint space")
for w in asp.working_modes:
    print(f"working mode {w}: aspects cover {sum(a.area for a in asp.of_mode(w)):.2f}")

# %%
# ``asp.plot()`` draws one column per working mode: the aspects in the workspace (top,
# with the parallel singular curves that bound them, each aspect's area in the legend) and
# in the joint space (bottom). It returns the Figure; ``asp.plot(fig=...)`` draws into
# one of yours, ``asp.plot("aspects.svg")`` writes it.
fig = asp.plot(title="five-bar (9, 8, 5, 5, 8): generalized aspects of each working mode")
# sphinx_gallery_thumbnail_number = 3
