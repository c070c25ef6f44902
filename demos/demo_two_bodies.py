# ---
# jupyter:
#   jupytext:
#     text_representation:
#       extension: .py
#       format_name: percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Two heterogeneous bodies in contact (non-matching meshes)
#
# Two deformable blocks, meshed independently, one pressed onto the other (frictionless contact):
#
# * the **lower** block (0, 1) × (−½, 0): horizontal layers of contrast 10³ cut by an inclined weak band
#   (a fault), clamped at its bottom;
# * the **upper** block, shifted right by 0.2 and overhanging the lower one: a soft matrix with stiff round
#   inclusions (contrast 10³), its top pushed down by d and held sideways.
#
# The contact integral lives on the upper block's bottom (the slave surface Γ_C, its mesh coarser than the
# lower block's); each of its quadrature points is projected onto the lower block's top (the master surface)
# on the reference configuration, the segments cut at the master vertices (segment-to-segment), and the
# penalty acts on the mortar-weighted nodal gaps (the theory page, "Two deformable bodies").  One semismooth
# Newton solves both bodies at once (`fc.solve(problem, "primal-monolithic")`).  We check what must hold
# whatever the heterogeneity: the contact forces on the two bodies are equal and opposite, to round-off.
#
# `FENICS_CONTACT_DEMO_N` sets the number of lower-block cells across (default 64).

# %%
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.plots import plot_cell_field, plot_displacement  # noqa: E402

n = int(os.environ.get("FENICS_CONTACT_DEMO_N", "64"))
out = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_two_bodies"))
out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## Two meshes that do not match, two heterogeneous materials

# %%
T = fc.PairTag
mesh = fc.two_blocks(n, int(0.7 * n) + 1, heights=(0.5, 0.4), offset=0.2)


def layered_with_fault(x):
    """Layers 0.1 thick alternating E = 1e3 and 1, cut by a weak band 0.03 wide along y = 0.8 (x − 0.55)."""
    layers = np.where(np.floor(-x[1] / 0.1) % 2 == 0, 1e3, 1.0)
    fault = np.abs(x[1] + 0.5 - 0.8 * (x[0] - 0.15)) / np.hypot(1.0, 0.8) < 0.03
    return np.where(fault, 1.0, layers)


def inclusions(x):
    """Stiff discs (E = 1e3) of radius 0.07 on a lattice of spacing 0.2 in a soft matrix (E = 1)."""
    cx = 0.2 + 0.1 + 0.2 * np.round((x[0] - 0.3) / 0.2)
    cy = 0.1 + 0.2 * np.round((x[1] - 0.1) / 0.2)
    return np.where(np.hypot(x[0] - cx, x[1] - cy) < 0.07, 1e3, 1.0)


d = 0.005
problem = fc.TwoBodyProblem(
    mesh.mesh,
    mesh.cell_tags,
    mesh.facet_tags,
    bodies=(fc.Body(T.LOWER, layered_with_fault, 0.3), fc.Body(T.UPPER, inclusions, 0.25)),
    pair=fc.ContactPair(slave=T.UPPER_BOTTOM, master=T.LOWER_TOP),
    supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, (0.0, -d))),
)
plot_cell_field(problem.fields.E, out / "E.png", title="Young's modulus of the two bodies", log=True)

# %% [markdown]
# ## The monolithic two-body solve

# %%
result = fc.solve(problem, "primal-monolithic")
print(
    f"{result.dofs} DOFs, δ = {result.delta:.3g}, Newton steps {result.newton.steps}, "
    f"active-set sizes {result.newton.active_sizes}"
)
upper_force, lower_force = result.forces
print("contact force on the upper body:", upper_force, " on the lower body:", lower_force)
print(f"relative force imbalance: {result.force_balance():.1e}")
assert result.force_balance() < 1e-10, "the forces on the two bodies are equal and opposite"
assert upper_force[1] > 0 and result.slave.force > 0, "the lower block pushes the upper one up"
plot_displacement(result.u, out / "displacement.png", title="(two bodies)")

# %% [markdown]
# ## Algorithm 1 for two bodies
#
# Each body is split into its bulk and a strip of two cell layers along its contact surface: the two bulks
# (linear, factorized once) and the two strips (the contact between them, semismooth Newton) exchange Robin
# data on the interfaces γ between strip and bulk.  With vertex quadrature on γ the fixed point is the
# monolithic solution above; the interface Newton method reaches it in a few pairs of subdomain solves.

# %%
hybrid = fc.solve(problem, "primal", tol=1e-10)
error = np.linalg.norm(hybrid.u.x.array - result.u.x.array) / np.linalg.norm(result.u.x.array)
print(
    f"Algorithm 1: {hybrid.iterations} evaluations of T, transmission residual {hybrid.transmission_residual:.1e}, "
    f"relative distance to the monolithic solution {error:.1e}"
)
assert hybrid.converged and error < 1e-8, "the hybrid fixed point is the monolithic two-body solution"

# %% [markdown]
# ## The contact pressure on both faces
#
# The nodal pressure p = −σ_c on each surface (its nodes' contact forces over their lumped weights): the
# upper block's bottom (slave) and the lower block's top (master) carry the same pressure, each on its own
# nodes; it concentrates under the stiff inclusions and the stiff layers, and vanishes where the upper block
# overhangs (x > 1) and where the lower block is uncovered (x < 0.2).

# %%
fig, ax = plt.subplots(figsize=(7, 3.5))
faces = ((result.slave, "upper body (slave)", "-o"), (result.master, "lower body (master)", "--s"))
for profile, label, style in faces:
    ax.plot(profile.points[:, 0], -profile.sigma_c, style, ms=3, label=label)
ax.set_xlabel("x")
ax.set_ylabel("contact pressure p")
ax.axhline(0.0, color="k", lw=0.5)
ax.legend()
fig.tight_layout()
fig.savefig(out / "pressure.png", dpi=120)
plt.close(fig)
print("resultants (normal part) on the two faces:", result.slave.force, result.master.force)

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above.

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("displacement.png", "pressure.png"):
        display(Image(filename=str(out / png)))
