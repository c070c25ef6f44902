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
# # A sphere pressed into a fibre composite (3D)
#
# The block (0, 1)³ of the built-in model 5 (`fenics_contact.problem.composite3d`) holds six stiff fibres
# along y: prisms of twelve-sided section inscribed in circles of radius 0.06, 10⁶ times stiffer than the
# matrix. Two of them lie on the interface γ (the plane x = ¾) and cross it into the contact strip Ω₂; one
# lies in Ω₂ right under the middle of the contact face x = 1 (Γ_C), 0.06 below it. The block is clamped on
# x = 0; a rigid sphere of radius ½ is pressed into the middle of Γ_C in four load steps.
#
# Algorithm 1 solves Ω₁ (linear elasticity with the fibres) and Ω₂ (the contact) apart, exchanging Robin data
# on γ; its fixed point is the monolithic penalized solution (Theorem 3.1), which this demo checks at every load
# step, at the contrast 10⁶.
#
# `FENICS_CONTACT_DEMO_N` sets the mesh: cells of 4/N away from the contact and 0.75/N within 0.2 of the middle of
# Γ_C (default N = 32).

# %%
import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyvista

import fenics_contact as fc  # imports dolfinx_solver before dolfinx
from fenics_contact.indentation import force_indentation
from fenics_contact.io import write_vtx
from fenics_contact.paraview import Series, contact_grid
from fenics_contact.problem.composite3d import CONTACT_CENTRE_3D, FIBRE_RADIUS, fibre_block_3d, fibre_block_3d_mesh

N = int(os.environ.get("FENICS_CONTACT_DEMO_N", "32"))
OUT = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_sphere_composite_3d"))
OUT.mkdir(parents=True, exist_ok=True)

E_fibre, E_matrix, nu = 1e6, 1.0, 0.35
R = 0.5
depths = np.array([0.004, 0.008, 0.012, 0.016])
direction = np.array([-1.0, 0.0, 0.0])  # into the face x = 1

mesh = fibre_block_3d_mesh(max(N // 4, 4), contact_size=0.75 / N, contact_radius=0.2)
sphere = fc.Sphere((CONTACT_CENTRE_3D[0] + R, *CONTACT_CENTRE_3D[1:]), R)
problem = fibre_block_3d(E_high=E_fibre, E_low=E_matrix, nu=nu).on(mesh).with_(obstacle=sphere, load=np.zeros(3))
print(f"{mesh.mesh.topology.index_map(3).size_global} tetrahedra, contact cells {mesh.h:.3g}")

# %% [markdown]
# ## Force–indentation: Algorithm 1 against the monolithic solve
#
# Both run the four load steps with warm starts (`fc.indentation.force_indentation`). Algorithm 1 (the
# interface Newton) writes each step's contact to a ParaView series (`contact.pvd`).

# %%
series = Series(OUT, "contact", problem.comm)
hybrid = force_indentation(
    problem,
    "primal",
    depths,
    direction=direction,
    tol=1e-9,
    on_step=lambda step, solver: series.add(step.depth, contact_grid(step.profile, problem.comm)),
)
monolithic = force_indentation(problem, "primal-monolithic", depths, direction=direction)
print(hybrid.table())
assert all(step.converged for step in hybrid.steps)
np.testing.assert_allclose(hybrid.forces, monolithic.forces, rtol=1e-8)  # Theorem 3.1 at every load step

# %% [markdown]
# At the last depth, the whole displacement: Algorithm 1's glued solution against the monolithic one (the
# relative error e_u), and the same active set.

# %%
final = problem.with_(obstacle=sphere.indented(depths[-1], direction))
reference = fc.solve(final, "primal-monolithic")
result = fc.solve(final, "primal", tol=1e-9, reference=reference.u)
print(
    f"Algorithm 1: {result.history.newton_steps} interface Newton steps, transmission residual "
    f"{result.history.transmission_residual:.1e}, e_u = {result.e_u:.1e}; contact force {result.profile.force:.5g} "
    f"(monolithic {reference.profile.force:.5g})"
)
assert result.converged and result.e_u <= 1e-8  # Theorem 3.1 at contrast 1e6
assert np.array_equal(result.profile.active, reference.profile.active)
write_vtx(OUT / "u.bp", result.u)

# %% [markdown]
# The force against the depth, with Hertz's F = (4/3)E*√R d^{3/2} of a half-space of the matrix alone
# (E* = E/(1 − ν²)): the fibres, the one under the contact first, stiffen the block (the ratio at the last
# depth is printed).

# %%
E_star = E_matrix / (1 - nu**2)
d = np.linspace(0.0, depths[-1], 100)
fig, ax = plt.subplots(figsize=(5.2, 3.8))
ax.plot(depths, hybrid.forces, "o-", label="Algorithm 1")
ax.plot(depths, monolithic.forces, "kx", ms=9, label="monolithic")
ax.plot(d, 4.0 / 3.0 * E_star * np.sqrt(R) * d**1.5, "--", color="0.5", label="Hertz, matrix only")
ax.set(xlabel="indentation d", ylabel="contact force F", title="a sphere on the fibre composite")
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "force_indentation_3d.png", dpi=120)
hertz = 4.0 / 3.0 * E_star * np.sqrt(R) * depths[-1] ** 1.5
print(
    f"at d = {depths[-1]:g}: F = {hybrid.forces[-1]:.4g}, {hybrid.forces[-1] / hertz:.2f} times Hertz's of the matrix"
)

# %% [markdown]
# ## The pressure on the contact face
#
# The nodal pressure over the middle of Γ_C (x = 1, the square 0.3 ≤ y, z ≤ 0.7) at the last depth, rendered
# off-screen with pyvista; the white lines are the edges of the fibre below (x = 0.88, along y). The extent of the
# contact patch along the fibre and across it is printed.

# %%
profile = result.profile
pressure = np.maximum(-profile.sigma_c, 0.0)
y, z = profile.points[:, 1], profile.points[:, 2]
near = (np.abs(y - 0.5) <= 0.2) & (np.abs(z - 0.5) <= 0.2)
face = pyvista.PolyData(np.column_stack([y[near], z[near], np.zeros(np.count_nonzero(near))]))
face.point_data["pressure"] = pressure[near]
pyvista.OFF_SCREEN = True
plotter = pyvista.Plotter(off_screen=True, window_size=(800, 700))
plotter.add_mesh(
    face.delaunay_2d(),
    scalars="pressure",
    cmap="viridis",
    show_edges=True,
    edge_color="lightgray",
    scalar_bar_args={"title": "pressure", "vertical": True},
)
for edge in (0.5 - FIBRE_RADIUS, 0.5 + FIBRE_RADIUS):
    plotter.add_mesh(pyvista.Line((0.3, edge, 0.01), (0.7, edge, 0.01)), color="white", line_width=3)
plotter.add_text(f"contact pressure on x = 1 (y to the right, z up), d = {depths[-1]:g}", font_size=10)
plotter.view_xy()
plotter.screenshot(OUT / "pressure_map_3d.png")
plotter.close()
active = profile.active
spread = [float(np.ptp(c[active])) for c in (y, z)]
print(f"contact patch: {spread[0]:.3f} along the fibre (y), {spread[1]:.3f} across it (z)")

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above, with the
# ParaView files `contact.pvd` (each load step's contact) and `u.bp` (the displacement at the last depth).

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("force_indentation_3d.png", "pressure_map_3d.png"):
        display(Image(filename=str(OUT / png)))
