"""
Singularity maps: distance to singularities over a slice
========================================================

:func:`optkin.singularity_map` samples a grid over two coordinates. These are
task coordinates for a platform (solved leg by leg in one working mode) or active joints
for a Khalil table (solved by the direct model with warm starts). At every grid point it
evaluates the margins of :func:`optkin.classify`: ``parallel`` (smallest singular value
of A, zero at a parallel singularity), ``serial`` (zero at a serial one), their minimum
``distance``, and Yoshikawa's ``manipulability``. On a log scale, the singular curves
show as dark valleys. This example maps the five-bar of Chablat and Wenger (1998) and
checks the valleys against the curves traced exactly by continuation. It also maps the
Acma SR400 of Khalil's Table 7.1 over a joint slice, where the valley is its elbow
singularity.
"""

import matplotlib.pyplot as plt
import numpy as np

import optkin

# %%
# The five-bar over its workspace
# -------------------------------
# The upper half of the workspace is sampled in the working mode (+, -). The grid is
# coarse (34 x 23 points, about 0.55 apart) to keep the build fast; each point solves
# the inverse model and evaluates the Jacobians. The continuation curves of
# :func:`optkin.singular_curves` are drawn on top. The parallel valleys follow the
# parallel curves of this working mode, and the serial margin vanishes on the boundary
# circles of the workspace.
#
# :meth:`SingularityMap.plot <optkin.SingularityMap.plot>` draws one measure into our
# own Axes (``optkin.plot_singularity_map(mech, u, v, path)`` samples and draws in one
# call).
five = optkin.mechanisms.five_bar(9, 8, 5, 5, 8)
mode = (1, -1)
sm = optkin.singularity_map(five, np.linspace(-5, 14, 34), np.linspace(0.2, 12.8, 23),
                     working_mode=mode)
print(sm, "-", sm.message)
curves = optkin.singular_curves(five, plane="workspace", kind=["parallel", "serial"])


fig, axs = plt.subplots(1, 2, figsize=(12.5, 4.1))
for ax, measure in zip(axs, ("parallel", "serial")):
    sm.plot(measure, ax=ax)
    for c in curves.curves:
        if not c.kind.startswith(measure):
            continue
        P = c.points.copy()
        if measure == "parallel":  # only where this working mode meets the curve
            P[~np.all(c.working_mode == np.array(mode), axis=1)] = np.nan
        ax.plot(P[:, 0], P[:, 1], color="tab:red", lw=1.2)
    ax.plot([], [], color="tab:red", lw=1.2, label=f"{measure} singular curves (continuation)")
    ax.set_xlim(sm.u[0], sm.u[-1])
    ax.set_ylim(0, sm.v[-1])
    ax.set_aspect("equal")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), frameon=False, fontsize=9)
    ax.set_title(f"five-bar, working mode (+, -): {measure} margin", fontsize=11)
fig.tight_layout()

# %%
# The SR400 over a joint slice
# ----------------------------
# The Acma SR400 (Khalil's Table 7.1) is a six-axis arm with a closed loop (a
# parallelogram driving the elbow). Its joint theta3 is passive, theta3 = pi/2 - theta2 +
# theta7 [7.41]. On the slice (theta2, theta7), with theta5 = 0.8 to stay away from the
# wrist singularity theta5 = 0, the valley is the elbow singularity: the arm stretched,
# theta3 = pi/2, i.e. the line theta7 = theta2. An even number of grid points keeps the
# samples off that line. The curved valleys crossing it come from the serial margin of
# :func:`optkin.classify`, not from the elbow.
sr = optkin.mechanisms.sr400()
g = np.linspace(-1.5, 1.5, 18)
sm_sr = optkin.singularity_map(sr, g, g, axes=("theta2", "theta7"), fixed={"theta5": 0.8})
print(sm_sr, "-", sm_sr.message)
# the passive joints (theta3, theta8, theta9) of the parallelogram closure as the guess
r = optkin.forward(sr, [0, 0.4, 0, 0.8, 0, 0.1], guess=[np.pi / 2 - 0.3, 0.3, -np.pi - 0.3])
theta3 = dict(zip(sr.joint_names, r.q))["theta3"]
print(f"theta3 at theta2 = 0.4, theta7 = 0.1: {theta3:.12f} = pi/2 - 0.3: "
      f"{np.pi / 2 - 0.3:.12f}")
fig, ax = plt.subplots(figsize=(6.8, 5.4))
sm_sr.plot("distance", ax=ax)
ax.plot(g, g, "--", color="tab:red", lw=1.4, label=r"$\theta_3 = \pi/2$ (elbow stretched)")
ax.set_aspect("equal")
ax.set_xlabel(r"$\theta_2$ (rad)")
ax.set_ylabel(r"$\theta_7$ (rad)")
ax.legend(loc="lower right", fontsize=9)
ax.set_title(r"SR400, $\theta_5$ = 0.8, other active joints 0", fontsize=11)
fig.tight_layout()
# sphinx_gallery_thumbnail_number = 1
