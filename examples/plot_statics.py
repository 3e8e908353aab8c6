"""
Statics: force capability and wrench-feasible workspace of planar platforms
===========================================================================

optkin's static model comes from virtual work. The wrench F that the end effector applies
(the load it resists is -F) and the actuator forces tau are related through the
Jacobians of the closure equations. Force capability, wrench feasibility and force
distribution are then linear or quadratic programs, built once with cvxpy parameters and
re-solved for each pose. This example compares the force capability polygon of a
redundantly actuated 4-RPR with that of the same platform on three of its legs. It shares
a load among the four legs with two norms, and maps where a 3-RPR can resist a whole box
of wrenches.
"""

import matplotlib.pyplot as plt
import numpy as np

import optkin
from optkin import statics

# %%
# A redundant 4-RPR and the same platform on three legs
# -----------------------------------------------------
# The 4-RPR of ``problems/rpr4.toml``: a 1 x 0.6 platform in a 4 x 3 frame, with a leg
# from each corner of the frame to the matching corner of the platform. Dropping the
# fourth leg leaves a 3-RPR. Both are put in the pose (x, y, phi) = (2.1, 1.4, -0.25).
frame = [[0, 0], [4, 0], [4, 3], [0, 3]]
corners = [[-0.5, -0.3], [0.5, -0.3], [0.5, 0.3], [-0.5, 0.3]]
rpr4 = optkin.mechanisms.rpr4(frame, corners)
rpr3 = optkin.mechanisms.rpr3(frame[:3], corners[:3])
pose = [2.1, 1.4, -0.25]
s4 = optkin.inverse(rpr4, pose)[0]
s3 = optkin.inverse(rpr3, pose)[0]

# %%
# Force capability polygons
# -------------------------
# :func:`optkin.statics.capability_polygon` solves, for each of 72 directions in the
# (fx, fy) plane at zero moment, the largest force the platform can apply with
# ``|tau_i| <= 100``. The result is the polygon drawn solid. The capability set is the image
# of the actuator box, a zonotope given whole by :func:`optkin.statics.polytope`. Its
# exact section by the plane mz = 0 is drawn dashed. The two agree. The fourth leg adds a
# generator to the zonotope, so the 4-RPR's polygon contains the 3-RPR's.
cap4 = statics.capability_polygon(rpr4, s4, 100.0, n=72)
cap3 = statics.capability_polygon(rpr3, s3, 100.0, n=72)
exact4 = statics.polytope(rpr4, s4, 100.0).section(("fx", "fy"))
exact3 = statics.polytope(rpr3, s3, 100.0).section(("fx", "fy"))
for name, cap in (("4-RPR", cap4), ("3-RPR", cap3)):
    print(f"{name}: {cap.status}, largest force {cap.max.min():.1f} in the weakest "
          f"direction, {cap.max.max():.1f} in the strongest")

fig, axs = plt.subplots(1, 2, figsize=(12, 5.4), width_ratios=[1.1, 1])
optkin.plot.draw(rpr4, s4, ax=axs[0], title="4-RPR at (2.1, 1.4, -0.25 rad)")
axs[0].set_xlim(-0.3, 4.3)
axs[0].set_ylim(-0.3, 3.3)
axs[0].legend(fontsize=9, loc="upper center", bbox_to_anchor=(0.5, -0.12), ncol=4,
              frameon=False)
ax = axs[1]
statics.plot_capability(cap4, exact=exact4, ax=ax)
order = np.argsort(np.arctan2(cap3.directions[:, 1], cap3.directions[:, 0]))
P3 = cap3.points[order][:, :2]
ax.fill(P3[:, 0], P3[:, 1], color="C1", alpha=0.3)
ax.plot(*np.vstack([P3, P3[:1]]).T, color="C1", lw=1.5,
        label="3-RPR (legs 1-3): capability LP")
ax.plot(*np.vstack([exact3, exact3[:1]]).T, "--", color="k", lw=1.0)
lim = 1.1 * np.abs(cap4.points[:, :2]).max()
ax.set_aspect("equal", adjustable="box")
ax.set_xlim(-lim, lim)
ax.set_ylim(-lim, lim)
ax.set_xlabel("fx (force units)")
ax.set_ylabel("fy (force units)")
handles, labels = ax.get_legend_handles_labels()
labels = [lab.replace("capability LP", "4-RPR: capability LP") if lab.startswith("capa")
          else "exact sections of the zonotopes" if lab == "polytope section" else lab
          for lab in labels]
ax.legend(handles, labels, fontsize=9, loc="upper center", bbox_to_anchor=(0.5, -0.12),
          ncol=2, frameon=False)
ax.set_title(r"force capability at zero moment, $|\tau_i| \leq 100$", fontsize=11)
axs[0].title.set_fontsize(11)
fig.tight_layout()

# %%
# Sharing a load among redundant actuators
# ----------------------------------------
# With four legs for three degrees of freedom, a wrench can be produced by infinitely
# many sets of actuator forces. :func:`optkin.statics.distribute` picks the one with the
# smallest 2-norm (a QP) or the smallest largest entry (``norm="inf"``, an LP). The
# 3-RPR has a single solution, tau = G^-1 F.
F = [0.0, -50.0, 5.0]  # (fx, fy, mz) applied by the platform
dist = [("4-RPR, least 2-norm", r"4-RPR, min $\|\tau\|_2$",
         statics.distribute(rpr4, s4, F, norm=2)),
        ("4-RPR, least largest entry", r"4-RPR, min $\max_i |\tau_i|$",
         statics.distribute(rpr4, s4, F, norm="inf")),
        ("3-RPR (unique)", "3-RPR (unique)", statics.distribute(rpr3, s3, F))]
fig, ax = plt.subplots(figsize=(7.5, 4))
width = 0.26
for k, (name, label, d) in enumerate(dist):
    tau = np.append(d.tau, np.nan) if len(d.tau) == 3 else d.tau
    ax.bar(np.arange(4) + (k - 1) * width, tau, width, label=label)
    print(f"{name}: tau = {np.round(d.tau, 2)}, residual {d.residual:.1e}")
ax.axhline(0, color="k", lw=0.8)
ax.set_xticks(range(4), [f"leg {i + 1}" for i in range(4)])
ax.set_ylabel(r"actuator force $\tau_i$")
ax.set_title(f"Actuator forces producing F = (fx, fy, mz) = {tuple(F)}", fontsize=11)
ax.legend(fontsize=9)
ax.grid(axis="y", alpha=0.3)
fig.tight_layout()

# %%
# Wrench-feasible workspace
# -------------------------
# The 3-RPR of ``problems/statics_rpr3.toml`` (base (0, 0), (4, 0), (0, 3)) at phi = 0.1
# should apply every wrench of the box fx in [-0.5, 0.5], fy in [-1, 0], mz in
# [-0.1, 0.1] with ``|tau_i| <= 2``. :func:`optkin.statics.wrench_feasible_workspace`
# solves one margin LP per grid point: the fraction of the actuator limit left at the
# worst vertex of the box. The black curve, margin = 0, bounds the wrench-feasible
# workspace. A 29 x 23 grid keeps this example fast; the LP is built once and only its
# parameters change from point to point.
m3 = optkin.mechanisms.rpr3([[0, 0], [4, 0], [0, 3]], [[-0.5, -0.3], [0.5, -0.3], [0, 0.4]])
box = {"lower": [-0.5, -1.0, -0.1], "upper": [0.5, 0.0, 0.1]}
ws = statics.wrench_feasible_workspace(m3, box, 2.0, grid=(29, 23),
                                       bounds=[[0.3, 3.6], [0.2, 2.8]], fixed=[0.0, 0.0, 0.1])
print(ws.message)
fig, ax = plt.subplots(figsize=(7.5, 5.6))
statics.plot_workspace(ws, ax=ax, title=f"3-RPR at $\\phi$ = 0.1: wrench-feasible for "
                                        f"{ws.fraction:.0%} of the reachable poses")
ax.title.set_fontsize(11)
fig.tight_layout()
