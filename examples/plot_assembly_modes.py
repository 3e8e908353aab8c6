"""
Every assembly mode of a 3-RPR by parameter homotopy
====================================================

A planar 3-RPR platform is held by three legs whose lengths are the actuated joints. Its
direct kinematics reduces to a polynomial of degree six in tan(phi/2) (Modern Robotics,
section 7.1.1), so for given leg lengths there are at most six assembly modes.
:func:`optkin.assembly_modes` with ``method="homotopy"`` tracks all six paths of a
parameter homotopy from a start system shipped with optkin. When every path ends finite,
no mode can have been missed. The geometry below is the 3-RPR studied by Zein, Wenger and
Chablat (2006). At leg lengths (14.98, 15.38, 12) all six solutions are real, and each one
is drawn in its own panel.
"""

import matplotlib.pyplot as plt
import numpy as np

import optkin
from optkin import mechanisms as M

# %%
# The mechanism and its six assembly modes
# ----------------------------------------
# ``rpr3(base, platform)`` takes the three fixed joints A_i and the three platform joints
# B_i (in the platform frame). The homotopy gives an account of its paths in ``stats``.
# ``complete`` means every path ended finite, at infinity or singular, so none was lost.
rpr = M.rpr3(base=[[0, 0], [15.91, 0], [0, 10]],
             platform=[[0, 0], [17.04, 0], [13.2364, 16.0967]])
rho = [14.98, 15.38, 12.0]
modes = optkin.assembly_modes(rpr, rho, method="homotopy")
print(modes.summary())
print(modes.stats)

# %%
# A multi-start search finds the same six modes. Its Good-Turing estimate ``p_new`` is the
# chance that one more converged start would land on a new mode. ``certify=True`` proves
# each mode by Krawczyk's test in ball arithmetic: a small box around it holds exactly one
# solution.
starts = optkin.assembly_modes(rpr, rho, method="multistart")
print(starts.summary(), f"p_new = {starts.info['p_new']:.3f}")
proven = optkin.assembly_modes(rpr, rho, certify=True)
print(proven.summary())

# %%
# One panel per mode
# ------------------
# ``optkin.plot.draw(rpr, modes)`` alone returns a Figure with one panel per mode. Here
# each mode goes into its own panel of a 2 x 3 grid through ``ax=``. The panels share
# their limits, and each title gives the pose and the sign of det A, the parallel
# Jacobian of Chablat and Wenger's velocity model A t + B q_a' = 0. Modes with different
# signs are separated by a parallel singularity in the workspace.
fig, axs = plt.subplots(2, 3, figsize=(11, 7.4), sharex=True, sharey=True)
for i, (ax, r) in enumerate(zip(axs.flat, modes)):
    optkin.plot.draw(rpr, r, ax=ax)
    x, y, phi = r.x
    sign = "+" if np.linalg.det(optkin.jacobians(rpr, r).A) > 0 else "-"
    ax.set_title(f"mode {i + 1}: ({x:.1f}, {y:.1f}, {np.degrees(phi):.0f} deg), "
                 f"det A {sign}", fontsize=10)
lim = np.array([ax.dataLim.get_points() for ax in axs.flat])  # every panel's data
lo, hi = lim[:, 0].min(axis=0), lim[:, 1].max(axis=0)
c, h = (lo + hi) / 2, 0.55 * (hi - lo).max()
for ax in axs.flat:
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    ax.label_outer()
handles, labels = axs.flat[0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
fig.suptitle(f"3-RPR at leg lengths {tuple(rho)}: the {len(modes)} assembly modes")
fig.tight_layout(rect=(0, 0.04, 1, 1))

# %%
# Following each mode as one leg moves
# ------------------------------------
# :func:`optkin.track` follows one assembly mode along a path of leg lengths. It stops
# where det W_p would change sign, i.e. where a parallel singularity would be crossed.
# Here each mode is followed from rho_3 = 12 down to 2 and up to 30, with the other two
# legs fixed, and its orientation phi is plotted against rho_3. A curve ends (cross)
# where its mode meets another one at a singularity: the count of real modes drops from
# 6 to 4 on both sides and to 2 beyond rho_3 = 26.
down = np.linspace(12.0, 2.0, 101)
up = np.linspace(12.0, 30.0, 181)
fig, ax = plt.subplots(figsize=(7.5, 4.6))
for i, r in enumerate(modes):
    for k, r3 in enumerate((down, up)):
        path = np.column_stack([np.full_like(r3, rho[0]), np.full_like(r3, rho[1]), r3])
        tr = optkin.track(rpr, path, guess=r)
        phi = np.degrees(np.unwrap([s.x[2] for s in tr]))
        ax.plot(r3[:len(tr)], phi, color=f"C{i}", lw=2,
                label=f"mode {i + 1}" if k == 0 else None)
        if tr.info["stopped_at"] is not None:
            ax.plot(r3[len(tr) - 1], phi[-1], "x", color="k", ms=7, mew=1.5)
            print(f"mode {i + 1} stops at rho_3 = {tr.info['qa_stop'][2]:.3f}: "
                  f"{tr.info['status']}")
ax.axvline(rho[2], color="0.5", ls=":", lw=1)
ax.plot([], [], "kx", label="singularity: mode ends")
ax.set_xlabel(r"leg length $\rho_3$  ($\rho_1$ = 14.98, $\rho_2$ = 15.38 fixed)")
ax.set_ylabel(r"platform orientation $\phi$ (deg)")
ax.set_title(r"The six modes at $\rho_3$ = 12 followed in both directions")
ax.grid(alpha=0.3)
ax.legend(ncol=2, fontsize=8, loc="best")
fig.tight_layout()
