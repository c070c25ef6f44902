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
# # Algorithm 3 in three dimensions: CEM-GMsFEM on a grid of cubes
#
# The 3D channel model (`fenics_contact.problem.models3d`): the unit cube of tetrahedra, clamped on x = 0 and
# y = 0, rollers (u_z = 0) on z = 0 and z = 1, traction free on y = 1, resting with its face x = 1 (Γ_C) on a
# rigid wall. Three stiff channels (E = 10³ against 1) run from x = ¼ through γ to the wall; the load acts in
# Ω₁ (the slab ½ < x < ¾ pushes the lower half onto the wall and pulls the top quarter away).
#
# Algorithm 3 covers Ω₁ with cubes of side H = ¼ (3 × 4 × 4 of them; Ω₂ is the layer x > ¾, one cube wide)
# and replaces the fine P1 space of Ω₁ by the CEM-GMsFEM space: on each cube the six smallest eigenfunctions
# of the local spectral problem (a floating cube's six rigid motions), then basis functions minimizing the
# energy on the patch of m oversampling layers around it, with the Robin and source correctors. Ω₂ stays
# fine and carries the contact. The energy error against the fine monolithic solution falls with m; with
# m = 3 the patches cover Ω₁ and Algorithm 3 is the fine solution.
#
# `FENICS_CONTACT_DEMO_N` sets the mesh: h = 1/(N/2) (default N = 16: h = 1/8; N = 32: h = 1/16).

# %%
import os
import sys
import time
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import fenics_contact as fc  # imports dolfinx_solver before dolfinx
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.tags import Subdomain

N = int(os.environ.get("FENICS_CONTACT_DEMO_N", "16"))
OUT = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_multiscale_3d"))
OUT.mkdir(parents=True, exist_ok=True)

H = 0.25  # the side of the coarse cubes and the width of the contact strip Ω₂
n = max(N // 2, 4)
problem = channels_3d(E_high=1e3).on(channels_3d_mesh(n, strip=H, H=H))
cells = problem.cm.mesh.topology.index_map(3).size_global
print(f"h = 1/{n}, H = {H}: {cells} tetrahedra, {np.unique(problem.cm.coarse_cell).size} coarse cubes")

# %% [markdown]
# ## The fine reference and Algorithm 3 for m = 1, 2, 3
#
# The monolithic penalized solve (semismooth Newton on the whole cube) is the reference u_h. Algorithm 3 runs its
# interface Newton to the transmission residual 10⁻⁹; its offline time covers the assembly, the local
# eigenproblems, the patch problems and the coarse operators, its online time the interface Newton.

# %%
start = time.perf_counter()
reference = fc.solve(problem, "primal-monolithic")
time_reference = time.perf_counter() - start
force_reference = reference.profile.force
print(f"monolithic: {time_reference:.2f} s, {reference.newton.steps} Newton steps, contact force {force_reference:.6f}")

layers = [1, 2, 3]
results = {}
for m in layers:
    r = fc.solve(problem, "primal-ms", layers=m, tol=1e-9, reference=reference.u)
    assert r.converged and r.history.transmission_residual < 1e-9
    results[m] = r
    print(
        f"m = {m}: dim V_ms = {r.dofs['omega1_ms']} (fine Ω₁: {r.dofs['omega1']}), "
        f"energy error {r.step.error_energy():.2e}, e_u {r.e_u:.2e}, "
        f"offline {r.time_offline_s:.2f} s, online {r.time_online_s:.2f} s "
        f"({r.history.newton_steps} interface Newton steps), "
        f"contact force {r.profile.force:.6f} (monolithic {force_reference:.6f})"
    )

# %% [markdown]
# Each layer divides the energy error: the bases decay exponentially away from their cube, and the
# patches of m = 3 cover Ω₁ (no localization: the fine solution to the solver's tolerance). The contact force
# follows the error.

# %%
errors = np.array([results[m].step.error_energy() for m in layers])
force_errors = np.array([abs(results[m].profile.force - force_reference) / force_reference for m in layers])
factors = errors[:-1] / errors[1:]
print("energy error divided per layer: " + ", ".join(f"{f:.1f}×" for f in factors))
print("relative contact force error: " + ", ".join(f"{e:.1e}" for e in force_errors))
assert np.all(factors > 4.0), factors  # the error falls with every layer
assert errors[-1] < 1e-8  # patches = Ω₁: the fine solution
assert np.all(force_errors <= 2.0 * errors + 1e-9)  # the force within the energy error
np.testing.assert_array_equal(results[3].profile.active, reference.profile.active)

fig, ax = plt.subplots(figsize=(5.0, 3.6))
ax.semilogy(layers, errors, "o-", label="energy error")
ax.semilogy(layers, np.maximum(force_errors, 1e-16), "s--", label="contact force error")
ax.set(xlabel="oversampling layers m", ylabel="relative error vs monolithic", xticks=layers)
ax.set_title(f"Algorithm 3 in 3D, h = 1/{n}, H = {H}, l = 6", fontsize=10)
ax.grid(True, which="both", alpha=0.3)
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "error_vs_layers_3d.png", dpi=120)

# %% [markdown]
# ## The coarse cubes and the displacement
#
# Left: the cells of Ω₁ coloured by their coarse cube (a checkerboard of the cube indices) and the contact
# strip Ω₂ in grey, seen from the traction-free side y = 1. Right: |u| of Algorithm 3 with m = 2 on the
# deformed cube (magnified), rendered off-screen with pyvista.

# %%
if not os.environ.get("DISPLAY"):  # off-screen OpenGL, no X server needed
    os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
import pyvista  # noqa: E402
from dolfinx import plot  # noqa: E402

msh = problem.cm.mesh
topology, cell_types, x = plot.vtk_mesh(msh)
grid = pyvista.UnstructuredGrid(topology, cell_types, x)
n_local = msh.topology.index_map(3).size_local
in_omega2 = np.zeros(n_local, dtype=bool)
in_omega2[problem.cm.cell_tags.find(Subdomain.OMEGA2)] = True
cube = problem.cm.coarse_cell[:n_local]
nx = round(1 / H)
parity = (cube + cube // nx + cube // nx**2) % 2  # a 3D checkerboard of the cube indices
grid.cell_data["part"] = np.where(in_omega2, -1.0, parity.astype(float))

u = results[2].u
V = u.function_space
ugrid = pyvista.UnstructuredGrid(*plot.vtk_mesh(V))
disp = u.x.array.reshape(-1, 3)
ugrid.point_data["|u|"] = np.linalg.norm(disp, axis=1)
ugrid.points = ugrid.points + 0.1 / max(float(np.abs(disp).max()), 1e-30) * disp

pyvista.OFF_SCREEN = True
plotter = pyvista.Plotter(off_screen=True, shape=(1, 2), window_size=(1400, 650))
plotter.subplot(0, 0)
plotter.add_mesh(
    grid, scalars="part", cmap=["lightgray", "steelblue", "orange"], show_edges=True, show_scalar_bar=False
)
plotter.add_text("coarse cubes of Omega_1 (blue/orange), Omega_2 (grey)", font_size=10)  # (VTK fonts: ASCII)
plotter.view_vector((0.6, 1.0, 0.5))
plotter.subplot(0, 1)
plotter.add_mesh(ugrid, scalars="|u|", cmap="viridis", scalar_bar_args={"title": "displacement magnitude"})
plotter.add_text("displacement magnitude, Algorithm 3 with m = 2 (magnified)", font_size=10)
plotter.view_vector((0.6, 1.0, 0.5))
plotter.screenshot(OUT / "cubes_and_displacement_3d.png")
plotter.close()

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above.

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("error_vs_layers_3d.png", "cubes_and_displacement_3d.png"):
        display(Image(filename=str(OUT / png)))
