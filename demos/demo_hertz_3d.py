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
# # A rigid sphere on an elastic block: 3D contact against Hertz
#
# A rigid sphere of radius R is pressed a depth d into the flat top of an elastic block (E, ν). Hertz's
# solution for a half-space: the contact is a disc of radius a = √(R d), the force F = 4E*a³/(3R) with
# E* = E/(1 − ν²), and the pressure p(r) = p₀√(1 − r²/a²) with p₀ = 3F/(2πa²).
#
# The block is a quarter, (0, L)² × (−L, 0) with L = 40a, on rollers (u·n = 0) on the symmetry planes
# x = 0 and y = 0 and clamped at the bottom; its tetrahedra are of size h near the contact and grow away
# from it. The primal penalty contact is solved by semismooth Newton on the whole block (the monolithic
# solve: the hybrid methods are two-dimensional so far).
#
# `FENICS_CONTACT_DEMO_N` sets the contact cells: h = a/(N/4) (default N = 16: h = a/4).

# %%
import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import fenics_contact as fc  # imports dolfinx_solver before dolfinx
from fenics_contact.io import write_vtx
from fenics_contact.problem.meshes3d import graded_planes

N = int(os.environ.get("FENICS_CONTACT_DEMO_N", "16"))
OUT = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_hertz_3d"))
OUT.mkdir(parents=True, exist_ok=True)

E, nu, R, a = 1.0, 0.3, 1.0, 0.1
h = a / max(N / 4.0, 2.0)
planes = graded_planes(40 * a, fine=1.25 * a, h=h, growth=1.4)
cm = fc.box_mesh(
    planes,
    planes,
    -planes[::-1],
    contact="zmax",
    clamped=("zmin",),
    contact_region=lambda p: (p[0] <= 3 * a + 1e-12) & (p[1] <= 3 * a + 1e-12),
)
sphere = fc.Sphere((0.0, 0.0, R), R).indented(a * a / R, (0.0, 0.0, -1.0))
problem = fc.ContactProblem(
    youngs_modulus=E,
    poisson_ratio=nu,
    obstacle=sphere,
    mesh=cm,
    boundary=fc.BoundaryConditions(rollers=((0, 0.0), (1, 0.0))),
)
solution = fc.solve(problem, "primal-monolithic")
print(f"{cm.mesh.topology.index_map(3).size_global} tetrahedra, h = a/{a / h:g}, {solution.newton.steps} Newton steps")

# %% [markdown]
# The computed contact against Hertz's: the force of the whole block is four times the quarter's; the
# contact radius and peak pressure are compared with Hertz's for the computed force.

# %%
E_star = E / (1 - nu**2)
profile = solution.profile
force = 4 * profile.force
a_F = (3 * force * R / (4 * E_star)) ** (1 / 3)
p0 = 3 * force / (2 * np.pi * a_F**2)
r = np.hypot(profile.points[:, 0], profile.points[:, 1])
reach = float(r[profile.active].max())
print(
    f"force {force:.5g} (Hertz at this depth {4 * E_star * a**3 / (3 * R):.5g}), contact radius {reach:.4g} "
    f"(Hertz {a_F:.4g}, cell {h:.3g}), peak pressure {profile.max_pressure:.4g} (Hertz {p0:.4g})"
)
assert abs(reach - a_F) <= 2 * h, "the contact radius is within two contact cells of Hertz's"
assert abs(profile.max_pressure / p0 - 1) < 0.05, "the peak pressure is within 5 % of Hertz's"

# %%
order = np.argsort(r)
fig, ax = plt.subplots(figsize=(6, 3.5))
ax.plot(r[order] / a, -profile.sigma_c[order] / p0, ".", ms=3, label="computed (nodes of Γ_C)")
s = np.linspace(0, 1, 200)
ax.plot(s * a_F / a, np.sqrt(1 - s**2), "k-", label="Hertz, p₀√(1 − r²/a²)")
ax.set(xlim=(0, 2), xlabel="r / a", ylabel="p / p₀", title=f"Sphere on a block, h = a/{a / h:g}")
ax.legend()
fig.tight_layout()
fig.savefig(OUT / "hertz_3d_pressure.png", dpi=120)

# %% [markdown]
# The pressure over the contact surface (the quarter, seen from above) and the displacement for ParaView
# (`u.bp`, ADIOS2/VTX).

# %%
pressure = -profile.sigma_c
near = (profile.points[:, 0] <= 2 * a) & (profile.points[:, 1] <= 2 * a)
fig, ax = plt.subplots(figsize=(4.5, 4))
dots = ax.scatter(profile.points[near, 0] / a, profile.points[near, 1] / a, c=pressure[near] / p0, s=12, cmap="viridis")
ax.add_patch(plt.Circle((0, 0), a_F / a, fill=False, color="k", ls="--", label="Hertz contact radius"))
ax.set(
    xlabel="x / a", ylabel="y / a", xlim=(-0.05, 2), ylim=(-0.05, 2), aspect="equal", title="contact pressure p / p₀"
)
fig.colorbar(dots, ax=ax)
ax.legend(loc="upper right")
fig.tight_layout()
fig.savefig(OUT / "hertz_3d_pressure_map.png", dpi=120)
write_vtx(OUT / "u.bp", solution.u)

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above.

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("hertz_3d_pressure.png", "hertz_3d_pressure_map.png"):
        display(Image(filename=str(OUT / png)))
