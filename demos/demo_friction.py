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
# # Friction: an indenter pressed into a heterogeneous block, then dragged
#
# A rigid cylinder (radius ½) is pressed into the side x = 1 of the unit square, whose Young's modulus has the
# stiff channels of test model 3 (contrast 10²) running up to the contact side, and then dragged along it.
# Coulomb friction (μ = 0.3) acts on Γ_C, penalized like the normal contact: at each Γ_C vertex the
# tangential traction is the return mapping of a tangential penalty,
#
# * t_trial = t_old − (1/δ_t) P (u − u_old − Δm)  (P = I − ν⊗ν, Δm the obstacle's motion in the step),
# * t = t_trial where |t_trial| ≤ μp (stick), t = μp t_trial/|t_trial| otherwise (slip),
#
# with p the normal penalty pressure.  The load path is quasi-static: each step starts from the previous one's
# displacement and traction, so the answer depends on the path and the slip dissipates energy.
#
# The friction acts on Γ_C ⊂ Ω₂ only, so Algorithm 1 (Ω₁ linear, Robin transmission on γ) keeps its fixed
# point: the monolithic penalized frictional solution (Theorem 3.1), checked at every step below (to round-off
# amplified by the stiff tangential penalty and carried along the path).  The mixed method (Algorithm 2) runs the
# same path with the law written on the traction.
#
# Open this file as a notebook with `jupytext --to notebook demo_friction.py` or run it as a script.
# `FENICS_CONTACT_DEMO_N` sets 1/h (default 64).

# %%
import os
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from dolfinx import fem

import fenics_contact  # noqa: F401  (imports dolfinx_solver before dolfinx)
from fenics_contact.fem.mixed import MixedSolution
from fenics_contact.methods import solve as fc_solve
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import model_3
from fenics_contact.problem.obstacles import Circle
from fenics_contact.problem.problem import ContactProblem, Frictionless
from fenics_contact.sliding import slide

n = int(os.environ.get("FENICS_CONTACT_DEMO_N", "64"))
out = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_friction"))
out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## The problem and the load path
# The cylinder touches x = 1 at y = ½; it is pressed in by 0.01 in two steps, then moved up along Γ_C by up to
# 0.03 (past sliding).

# %%
cm = unit_square(n, max(4, n // 8))
problem = ContactProblem(
    youngs_modulus=model_3(E_high=1e2).youngs_modulus,
    poisson_ratio=0.3,
    obstacle=Circle((1.5, 0.5), 0.5),
    law=Friction("coulomb", mu=0.3),
).on(cm)
depth = 0.01
motions = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.005), (-depth, 0.01), (-depth, 0.03)]

# %% [markdown]
# ## The monolithic solve and Algorithm 1 along the path

# %%
V = fem.functionspace(cm.mesh, ("Lagrange", 1, (2,)))
displacements = {"mono": [], "alg1": []}


def keep(name):
    def record(step, solver):
        u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
        displacements[name].append(u.x.array.copy())

    return record


mono = slide(problem, "primal-monolithic", motions, on_step=keep("mono"))
alg1 = slide(problem, "primal", motions, tol=1e-11, on_step=keep("alg1"))
print(mono.table())
for a, b, ua, ub in zip(mono.steps, alg1.steps, displacements["mono"], displacements["alg1"]):
    gap = np.max(np.abs(ua - ub)) / np.max(np.abs(ua))
    print(
        f"motion {a.motion}: Algorithm 1's displacement differs from the monolithic one by {gap:.1e} (relative); "
        f"{b.iterations} applications of T, {b.contact_newton_steps} contact Newton steps on the condensed Γ_C system"
    )
    assert gap < 1e-6  # the penalty's stick stiffness amplifies round-off: measured 1e-14 to 1.4e-7 at h = 1/32
assert all(s.dissipation >= 0.0 for s in mono.steps)
fp = mono.steps[-1].friction
ratio = np.sum(fp.weights * np.linalg.norm(fp.traction, axis=1)) / np.sum(fp.weights * fp.pressure)
print(f"sliding: Σ w|t| / Σ w p = {ratio:.12f} (μ = 0.3); stick nodes: {np.count_nonzero(fp.stick)}")
assert np.count_nonzero(fp.stick) == 0 and abs(ratio - 0.3) < 1e-10

# %% [markdown]
# ## The mixed method: Algorithm 2 along the same path
# The mixed (Arnold–Winther) discretization writes the law on the traction: the tangential traction σ_t = t·σn is
# an unknown on Γ_C, a sticking node moves with the cylinder exactly, and a slipping one carries μp plus ε_t times
# its slip in the step (``fem.mixed_friction``).  Algorithm 2's fixed point is the monolithic frictional solution
# on X̃_h (σ_tt split at the γ vertices), checked at every step.  The forces are those of another discretization
# of the same problem: with the stiff channels reaching Γ_C they differ from the primal ones by the discretization
# error, as the frictionless normal forces at the deepest press do (printed below; the two approach each other
# as h falls).

# %%
references, errors = [], []


def keep_mixed(step, solver):
    sub = solver.contact
    references.append(
        MixedSolution(sub.sigma_function(), sub.u_function(), None, None, sub.epsilon, {}, 0, 0, None, True)
    )


def compare(step, solver):
    solver.set_reference(references[len(errors)])
    errors.append(solver.errors())


slide(problem, "mixed-monolithic", motions, split_interface=True, on_step=keep_mixed)
alg2 = slide(problem, "mixed", motions, tol=1e-11, on_step=compare)
for a, b, (e_sigma, e_u) in zip(mono.steps, alg2.steps, errors):
    print(
        f"motion {b.motion}: Algorithm 2 against the monolithic mixed solution e_σ = {e_sigma:.1e}, e_u = {e_u:.1e}; "
        f"normal force {b.normal_force:.5f} (primal {a.normal_force:.5f}), tangential force "
        f"{b.tangential_force[1]:.5f} (primal {a.tangential_force[1]:.5f}), "
        f"{b.stick_nodes} stick / {b.slip_nodes} slip nodes"
    )
    assert e_sigma < 1e-8 and e_u < 1e-8
pressed = problem.on(cm).with_(law=Frictionless(), obstacle=problem.obstacle.translated(motions[1]))
forces = [fc_solve(pressed, method).profile.force for method in ("primal-monolithic", "mixed-monolithic")]
print(f"without friction, pressed in by {depth}: normal force {forces[0]:.5f} (primal), {forces[1]:.5f} (mixed)")
fp = alg2.steps[-1].friction
excess = np.sum((fp.weights * np.abs(fp.shear))[fp.slip]) / np.sum((fp.weights * 0.3 * fp.pressure)[fp.slip]) - 1.0
print(f"sliding (mixed): Σ w|σ_t| / Σ w μp over the slipping nodes − 1 = {excess:.2e} (the slip penalty's excess)")
assert 0.0 <= excess < 1e-2 and all(s.dissipation >= 0.0 for s in alg2.steps)

# %% [markdown]
# ## Normal and tangential traction with the stick and slip zones
# Each curve is one step of the drag; the slip zone grows from the contact edges inwards until the whole zone
# slips and |t| = μp everywhere.

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
for step in mono.steps[1:]:
    fp = step.friction
    y = fp.points[:, 1]
    (line,) = axes[0].plot(y, fp.pressure, label=f"drag {step.motion[1]:g}")
    axes[1].plot(y, fp.shear, color=line.get_color())
    axes[1].plot(y[fp.stick], fp.shear[fp.stick], "o", color=line.get_color(), markersize=4)
    axes[1].plot(y[fp.slip], fp.shear[fp.slip], "x", color=line.get_color(), markersize=4)
for ax, title in zip(axes, ("normal pressure p", "tangential traction t·τ (o stick, x slip)")):
    ax.set_xlim(0.3, 0.7)
    ax.set_xlabel("y on Γ_C")
    ax.set_title(title)
axes[0].legend()
fig.tight_layout()
fig.savefig(out / "friction_tractions.png", dpi=120)
plt.close(fig)

# %% [markdown]
# ## Force–displacement and dissipation

# %%
drag = [s.motion[1] for s in mono.steps]
fig, ax = plt.subplots(figsize=(5, 3.5))
ax.plot(drag, mono.normal_forces, "o-", label="normal force")
ax.plot(drag, np.abs(mono.tangential_forces[:, 1]), "s-", label="tangential force")
ax.plot(drag, 0.3 * mono.normal_forces, "k:", label="μ × normal force")
ax.plot(drag, np.abs(alg2.tangential_forces[:, 1]), "+--", label="tangential force (mixed, Algorithm 2)")
ax.set_xlabel("drag of the cylinder")
ax.legend()
fig.tight_layout()
fig.savefig(out / "friction_forces.png", dpi=120)
plt.close(fig)
print(f"dissipated along the path: {mono.dissipation:.4e}")

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above.

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("friction_tractions.png", "friction_forces.png"):
        display(Image(filename=str(out / png)))
