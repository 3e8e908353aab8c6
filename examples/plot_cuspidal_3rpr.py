"""
A cuspidal 3-RPR: changing assembly mode without a singularity
==============================================================

A parallel robot is *cuspidal* when it can move from one assembly mode to another without
crossing a parallel singularity (Innocenti and Parenti-Castelli 1992, McAree and Daniel
1999). Near a cusp of the singular curves in the joint space, the direct kinematics has
the local form x^3 + a x + b = 0. A loop of the legs around the cusp therefore carries
one solution to another while det A keeps its sign (Zein, Wenger and Chablat 2006). This
example uses their 3-RPR (base joints A1 = (0, 0), A2 = (15.91, 0), A3 = (0, 10),
platform sides 17.04, 16.54 and 20.84). It traces the section rho_1 = 14.98 of its
singular surface with the cusps, lets :func:`optkin.mode_change_path` find such a loop,
and shows the platform moving along it.
"""

import matplotlib.pyplot as plt
import numpy as np

import optkin
from optkin import mechanisms as M

rpr = M.rpr3([[0, 0], [15.91, 0], [0, 10]], [[0, 0], [17.04, 0], [13.2364, 16.0967]])
qa = [14.98, 13.85146, 6.7713]  # inside the wedge of a cusp of the section

# %%
# The joint-space section and its cusps
# -------------------------------------
# With rho_1 fixed, the parallel singularities (det A = 0) form curves in the plane of
# (rho_2, rho_3). :func:`optkin.singular_curves` traces them by continuation and finds the
# cusps, the points where a curve turns back on itself.
section = optkin.singular_curves(rpr, plane="joint", fixed={"L1.rho": qa[0]},
                                 bounds=[[0, 40], [0, 40]])
print(section.message, f"; {len(section.cusps)} cusps")
print(np.round(section.plane_points(section.cusps), 3))

# %%
# The assembly modes at qa
# ------------------------
# At qa = (14.98, 13.85, 6.77) all six assembly modes are real. Modes 1 and 2 (counted
# from 0, in the order of :func:`optkin.assembly_modes`) have the same sign of det A, so
# they lie in one aspect (det A does not change sign in between), yet they are distinct
# solutions.
modes = optkin.assembly_modes(rpr, qa)
for i, r in enumerate(modes):
    d = np.linalg.det(optkin.jacobians(rpr, r).A)
    print(f"mode {i}: x = {r.x[0]:8.3f}, y = {r.x[1]:8.3f}, phi = {r.x[2]:+.4f}, "
          f"det A {'+' if d > 0 else '-'}")

# %%
# A loop around a cusp
# --------------------
# :func:`optkin.mode_change_path` tries loops from qa around each cusp of the section.
# It follows each one with :func:`optkin.track` and keeps a loop that brings mode 1 back
# as mode 2. Along the loop det W_p keeps one sign, and ``min_conditioning`` is the
# smallest 1/cond(W_p) met on the way.
chg = optkin.mode_change_path(rpr, qa, start=1, target=2, curves=section)
print(chg.message)
print(f"min 1/cond(W_p) along the path: {chg.min_conditioning:.4f}")

fig, (ax, axd) = plt.subplots(1, 2, figsize=(12, 5.4), width_ratios=[1, 1.15])
chg.plot(ax=ax, title=r"section $\rho_1$ = 14.98: singular curves, cusps and the loop")
ax.set_xlabel(r"$\rho_2$")
ax.set_ylabel(r"$\rho_3$")
ax.title.set_fontsize(11)
s = np.linspace(0, 1, len(chg.det))
axd.plot(s, chg.det, color="tab:green", lw=2, label=r"det $W_p$ along the loop")
axd.axhline(0, color="tab:red", lw=1, ls="--", label="parallel singularity (det = 0)")
axd.set_xlabel("fraction of the path")
axd.set_ylabel(r"det $W_p$ (columns scaled by the size)")
axd.set_title(r"det $W_p$ keeps its sign: no singularity is crossed", fontsize=11)
axd.grid(alpha=0.3)
axd.legend(loc="best", fontsize=9)
fig.tight_layout()

# %%
# The platform along the loop
# ---------------------------
# ``chg.results`` holds the configuration at every point of the path. Six snapshots
# drawn with ``optkin.plot.draw(..., ax=)`` show the platform going from mode 1 (first
# panel) to mode 2 (last panel) while the legs return to their initial lengths. The
# dotted line is the path of the platform's reference point.
idx = np.linspace(0, len(chg.results) - 1, 6).round().astype(int)
origin = np.array([r.pose[:2, 3] for r in chg.results])
fig, axs = plt.subplots(2, 3, figsize=(11, 7.6), sharex=True, sharey=True)
for k, (ax, i) in enumerate(zip(axs.flat, idx)):
    optkin.plot.draw(rpr, chg.results[i], ax=ax)
    ax.plot(origin[:, 0], origin[:, 1], ":", color="0.3", lw=1.2)
    rho = chg.qa_path[i]
    what = "mode 1 (start)" if k == 0 else "mode 2 (end)" if k == len(idx) - 1 else \
        f"{100 * i / (len(chg.results) - 1):.0f} % of the loop"
    ax.set_title(f"{what}\n" + r"$\rho$ = " + f"({rho[0]:.2f}, {rho[1]:.2f}, {rho[2]:.2f})",
                 fontsize=10)
pts = np.vstack([np.vstack(optkin.plot.chain_points(rpr, chg.results[i])) for i in idx])
lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
c, h = (lo + hi) / 2, 0.55 * (hi - lo).max()
for ax in axs.flat:
    ax.set_xlim(c[0] - h, c[0] + h)
    ax.set_ylim(c[1] - h, c[1] + h)
    ax.label_outer()
handles, labels = axs.flat[0].get_legend_handles_labels()
fig.legend(handles, labels, loc="lower center", ncol=len(labels), frameon=False)
fig.suptitle("Non-singular change of assembly mode: mode 1 to mode 2 at the same leg lengths")
fig.tight_layout(rect=(0, 0.04, 1, 1))

# %%
# Aspects at constant orientation
# -------------------------------
# An aspect is a connected region of the workspace free of parallel singularities. On a
# cuspidal robot one aspect can hold several assembly modes for the same leg lengths,
# as modes 1 and 2 above show. The aspects in the (x, y) section at phi = 0.5, with leg
# strokes [10, 30], come from :func:`optkin.aspects`. A 3-RPR has a single working mode (a prismatic leg has one
# posture), and the parallel singular curves cut the section into four aspects.
# ``optkin.aspects(rpr, limits=...)`` without ``fixed`` gives the aspects in
# (x, y, phi), by exact sections linked across phi (:func:`optkin.aspects3d`).
strokes = {f"L{i}.rho": (10.0, 30.0) for i in (1, 2, 3)}
asp = optkin.aspects(rpr, fixed={"phi": 0.5}, limits=strokes)
print(asp.message)
fig = asp.plot()
fig.set_size_inches(8.6, 5.4)  # constrained layout: no tight_layout
fig.suptitle(r"3-RPR: aspects of the section $\phi$ = 0.5, strokes [10, 30]", fontsize=12)
ax = fig.axes[0]
ax.title.set_fontsize(10)
ax.get_legend().remove()
ax.legend(fontsize=9, loc="upper left", bbox_to_anchor=(1.02, 1), frameon=False)
