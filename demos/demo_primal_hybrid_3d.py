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
# # Algorithm 1 in three dimensions: stiff channels pressing on a wall
#
# The unit cube is clamped on x = 0 and y = 0, held by symmetry planes (rollers, u_z = 0) on z = 0 and
# z = 1, traction free on y = 1, and rests with its face x = 1 (Γ_C) on a rigid wall. Three stiff channels
# (E = 10³ against 1) run from x = ¼ through the interface γ (the plane x = ¾) and the contact strip Ω₂ up
# to the wall; a body force in Ω₁ pushes the lower half onto the wall and pulls the top quarter away
# (`fenics_contact.problem.models3d`).
#
# Algorithm 1 solves Ω₁ (linear) and Ω₂ (the contact) apart and exchanges Robin data at the vertices of the
# surface γ. With that vertex quadrature its fixed point is the monolithic penalized solution (Theorem 3.1),
# which this demo checks; the interface Newton reaches it in a few steps.
#
# `FENICS_CONTACT_DEMO_N` sets the mesh: h = 1/(N/2) (default N = 16: h = 1/8).

# %%
import os
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import fenics_contact as fc  # imports dolfinx_solver before dolfinx
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh

N = int(os.environ.get("FENICS_CONTACT_DEMO_N", "16"))
OUT = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_primal_hybrid_3d"))
OUT.mkdir(parents=True, exist_ok=True)

n = max(N // 2, 4)
problem = channels_3d(E_high=1e3).on(channels_3d_mesh(n))
print(f"h = 1/{n}: {problem.cm.mesh.topology.index_map(3).size_global} tetrahedra")

# %% [markdown]
# The monolithic penalized solve (semismooth Newton on the whole cube) is the reference; Algorithm 1 with its
# default update, the interface Newton, is compared with it.

# %%
reference = fc.solve(problem, "primal-monolithic")
hybrid = fc.solve(problem, "primal", tol=1e-9, reference=reference.u)
print(f"monolithic: {reference.newton.steps} Newton steps, contact force {reference.profile.force:.6f}")
print(
    f"Algorithm 1: {hybrid.history.newton_steps} interface Newton steps, {hybrid.iterations} application(s) of T, "
    f"transmission residual {hybrid.history.transmission_residual:.1e}, e_u = {hybrid.e_u:.1e}, "
    f"contact force {hybrid.profile.force:.6f}"
)
print(f"DOFs: Ω₁ {hybrid.dofs['omega1']}, Ω₂ {hybrid.dofs['omega2']}, interface values {hybrid.dofs['interface']}")
assert hybrid.converged and hybrid.e_u < 1e-8  # Theorem 3.1
assert hybrid.history.newton_steps <= 8
assert np.array_equal(hybrid.profile.active, reference.profile.active)

# %% [markdown]
# The contact pressure at the nodes of the face x = 1 (grey rings: open): the stiff channel in the pushed
# half carries the load onto the wall (the pressure peaks on its section), and the half y > ½ is open.

# %%
points, pressure, active = hybrid.profile.points, -hybrid.profile.sigma_c, hybrid.profile.active
fig, ax = plt.subplots(figsize=(5.2, 4.2))
shown = ax.scatter(points[:, 1], points[:, 2], c=np.maximum(pressure, 0.0), s=36, cmap="viridis")
ax.scatter(*points[~active][:, 1:].T, s=36, facecolors="none", edgecolors="0.6", label="open")
ax.set(xlabel="y", ylabel="z", title=f"contact pressure on x = 1 (h = 1/{n})", aspect="equal")
ax.legend(loc="upper right", fontsize=8)
fig.colorbar(shown, ax=ax, label="p = −σ_c")
fig.tight_layout()
fig.savefig(OUT / "contact_pressure_3d.png", dpi=120)
