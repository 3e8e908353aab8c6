"""
Stewart-Gough platforms: assembly modes in 3-D and a tracked motion
===================================================================

A 6-6 Stewart-Gough platform has six legs of variable length, each with a universal
joint on the base and a spherical joint on the platform. Its direct kinematics (the pose
from the six leg lengths) has 40 complex solutions in general (Raghavan and Roth; Modern
Robotics, section 7.5). This example finds the real ones, i.e. the assembly modes, for a
hexapod with hexagonal base and platform. It then reproduces Dietmaier's (1998) platform,
for which all 40 solutions are real, and proves each of them. Last, it follows one
assembly mode along a motion of the legs.
"""

import matplotlib.pyplot as plt
import numpy as np

import optkin

# %%
# A hexapod and one pose
# ----------------------
# The base joints lie in pairs at 0, 120 and 240 degrees (+-15 degrees) on a circle of
# radius 1. The platform joints lie in pairs at 60, 180 and 300 degrees (+-15 degrees) on
# a circle of radius 0.5 in the platform frame. The two legs from a base pair go to two
# neighbouring platform pairs. ``stewart_gough(base, platform)`` builds the 6-UPS
# mechanism. Its task coordinates are (x, y, z, roll, pitch, yaw), and
# :func:`optkin.inverse` gives the leg lengths of a pose.
k = np.repeat([0.0, 120.0, 240.0], 2)
s = np.tile([1.0, -1.0], 3)
a_base, a_plat = np.radians(k + 15 * s), np.radians(k + 45 * s)
base = np.column_stack([np.cos(a_base), np.sin(a_base), np.zeros(6)])
plat = 0.5 * np.column_stack([np.cos(a_plat), np.sin(a_plat), np.zeros(6)])
hexapod = optkin.mechanisms.stewart_gough(base, plat, home=[0, 0, 0.8, 0, 0, 0])
pose = [0.05, -0.03, 0.8, 0.1, -0.05, 0.2]
legs = optkin.inverse(hexapod, pose)[0].qa
print("leg lengths:", np.round(legs, 4))

# %%
# Its assembly modes
# ------------------
# The default ``method="auto"`` tracks the paths of the parameter homotopy from the
# start system of the general 6-6 platform (40 paths). This hexapod is special (planar
# base and platform, joints in pairs): 12 of its paths go to infinity, which the tracker
# tells from failures by their growth near the end, so every path is accounted for and
# the answer is complete (``modes.stats``). Where a path fails, ``auto`` says so and runs
# the multi-start search instead. Because base and platform are planar, every mode has a
# mirror image through the base plane. The modes with the platform above the base are
# drawn.
modes = optkin.assembly_modes(hexapod, legs)
print(modes.info["message"])
print(modes.summary(), modes.stats)


def frame(ax, elev, azim):
    """The hexapod's box: 2.2 x 2.2 x 1 with sparse ticks, seen from (elev, azim)."""
    ax.set_xlim(-1.1, 1.1)
    ax.set_ylim(-1.1, 1.1)
    ax.set_zlim(0.0, 1.0)
    ax.set_box_aspect((2.2, 2.2, 1.0))
    ax.set_xticks([-1, 0, 1])
    ax.set_yticks([-1, 0, 1])
    ax.set_zticks([0, 0.5, 1])
    ax.view_init(elev=elev, azim=azim)


above = [r for r in modes if r.pose[2, 3] > 0]
fig = plt.figure(figsize=(10, 7.4))
for i, r in enumerate(above):
    ax = fig.add_subplot(2, 2, i + 1, projection="3d")
    optkin.plot.draw(hexapod, r, ax=ax)
    x, y, z = r.pose[:3, 3]
    ax.set_title(f"mode {i + 1}: platform centre ({x:.2f}, {y:.2f}, {z:.2f})", fontsize=11)
    frame(ax, elev=20, azim=-60)
handles, labels = fig.axes[0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
fig.suptitle(f"Hexapod, legs ({', '.join(f'{v:.3f}' for v in legs)}): "
             f"the {len(above)} of {len(modes)} assembly modes above the base", fontsize=12)
fig.tight_layout(rect=(0, 0.04, 1, 1))

# %%
# Dietmaier's platform: 40 real assembly modes, each certified
# ------------------------------------------------------------
# Dietmaier (1998) showed a general Stewart-Gough platform whose 40 solutions are all
# real. The homotopy accounts for every one of its 40 paths. With ``certify=True`` each
# solution is proved by Krawczyk's test in ball arithmetic: a box around it holds exactly
# one solution, and the boxes are disjoint.
A = np.array([[0, 0, 0], [1.107915, 0, 0], [0.549094, 0.756063, 0],
              [0.735077, -0.223935, 0.525991], [0.514188, -0.526063, -0.368418],
              [0.590473, 0.094733, -0.205018]])
B = np.array([[0, 0, 0], [0.542805, 0, 0], [0.956919, -0.528915, 0],
              [0.665885, -0.353482, 1.402538], [0.478359, 1.158742, 0.107672],
              [-0.137087, -0.235121, 0.353913]])
L = [1, 0.645275, 1.086284, 1.503439, 1.281933, 0.771071]
dietmaier = optkin.mechanisms.stewart_gough(A, B)
forty = optkin.assembly_modes(dietmaier, L, certify=True)
print(forty.summary())
print(forty.stats)

P = np.array([r.pose[:3, 3] for r in forty])
angle = np.degrees([np.arccos(np.clip((np.trace(r.pose[:3, :3]) - 1) / 2, -1, 1))
                    for r in forty])
fig = plt.figure(figsize=(8.5, 6.4))
ax = fig.add_subplot(projection="3d")
sc = ax.scatter(P[:, 0], P[:, 1], P[:, 2], c=angle, cmap="viridis", s=45, depthshade=False,
                label="platform origin, one per mode")
ax.scatter(A[:, 0], A[:, 1], A[:, 2], marker="^", c="k", s=50, depthshade=False,
           label="base joints")
ax.set_xlabel("x")
ax.set_ylabel("y")
ax.set_zlabel("z")
ax.set_box_aspect(np.ptp(np.vstack([P, A]), axis=0))
fig.colorbar(sc, ax=ax, shrink=0.65, pad=0.02, label="rotation angle of the platform (deg)")
ax.legend(loc="upper left", fontsize=9)
n_cert = sum(bool(r.certified) for r in forty)
ax.set_title(f"Dietmaier's platform: {len(forty)} real assembly modes, "
             f"{n_cert} certified", fontsize=12)
fig.tight_layout()

# %%
# A tracked motion
# ----------------
# The hexapod's platform should move along a closed path: a circle of radius 0.15 in
# x-y while z, roll and yaw oscillate. The inverse kinematics gives the leg lengths at
# 201 instants. :func:`optkin.track` follows the assembly mode through those leg lengths
# (predictor-corrector continuation, stopping at any singularity), and the pose it
# recovers is compared with the commanded one: they agree to the corrector's tolerance.
# :func:`optkin.forward_batch` solves the same 201 problems in one compiled call.
t = np.linspace(0.0, 1.0, 201)
w = 2 * np.pi * t
commanded = np.column_stack([0.15 * np.cos(w), 0.15 * np.sin(w), 0.8 + 0.05 * np.sin(2 * w),
                             0.1 * np.sin(w), np.zeros_like(t), 0.25 * np.sin(w)])
qa_path = np.array([optkin.inverse(hexapod, c)[0].qa for c in commanded])
path = optkin.track(hexapod, qa_path, guess=commanded[0])
print(path.info["message"], f"; max cond(W_p) {path.info['max_cond']:.1f}")
batch = optkin.forward_batch(hexapod, qa_path, guess=path[0])
print(f"forward_batch: {int(np.sum(batch.success))} of {len(t)} solved")
tracked = np.array([r.pose[:3, 3] for r in path])
error = np.max(np.abs(tracked - commanded[:, :3]), axis=1)

fig = plt.figure(figsize=(12, 5.4))
ax = fig.add_subplot(1, 2, 1, projection="3d")
optkin.plot.draw(hexapod, path[0], ax=ax)
ax.plot(tracked[:, 0], tracked[:, 1], tracked[:, 2], color="C3", lw=2.2,
        label="tracked platform centre")
ax.legend(loc="upper center", bbox_to_anchor=(0.5, 0.02), ncol=3, fontsize=8, frameon=False)
frame(ax, elev=25, azim=-55)
ax.set_title("the hexapod at t = 0 and the tracked path", fontsize=11)
axl = fig.add_subplot(2, 2, 2)
for i in range(6):
    axl.plot(t, qa_path[:, i], lw=1.6, label=f"leg {i + 1}")
axl.set_ylabel("leg length")
axl.set_title("actuated joints along the motion", fontsize=11)
axl.legend(ncol=3, fontsize=8, loc="upper right")
axl.grid(alpha=0.3)
axl.tick_params(labelbottom=False)
axe = fig.add_subplot(2, 2, 4, sharex=axl)
axe.semilogy(t, np.maximum(error, 1e-17), color="C3", lw=1.6)
axe.set_xlabel("time t (one period)")
axe.set_ylabel("|tracked - commanded|")
axe.set_title("position error of the tracked mode", fontsize=11)
axe.grid(alpha=0.3)
fig.tight_layout()
