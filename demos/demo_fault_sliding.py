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
# # Fault sliding: one stratum sliding on another (Coulomb friction between two bodies)
#
# Two layered blocks, meshed independently, meet across a horizontal fault:
#
# * the **lower** block (0, 1) × (−½, 0): strata of contrast 10³ with a stiff inclusion, clamped at its bottom;
# * the **upper** block (0, 1) × (0, 0.4): strata the other way round with a soft inclusion; its top is pressed
#   down by 0.01, then moved along the fault step by step until the upper block slides.
#
# Coulomb friction (μ = 0.4) acts on the relative slip of the two faces: at each slave node the slave
# displacement minus the master's at the projected point, its normal part the penetration and its tangential
# part the slip (the theory page, "Friction between two bodies").  Each load step starts from the friction
# state the previous one committed, so the path matters and sliding dissipates energy.  We solve the path with
# the monolithic Newton and with Algorithm 1 (a contact strip on each side of the fault, Robin transmission to
# each bulk, interface Newton) and check: the two agree step by step (Theorem 3.1 with friction), the forces
# on the two bodies are equal and opposite, and once the whole fault slips the tangential force is μ times the
# normal force. Algorithm 3 (a multiscale space in each bulk) follows the same path up to its multiscale error.
#
# `FENICS_CONTACT_DEMO_N` sets the number of lower-block cells along the fault (default 48).

# %%
import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.fem.two_body import stiffness
from fenics_contact.problem.pair_meshes import fault_strata

n = int(os.environ.get("FENICS_CONTACT_DEMO_N", "48"))
out = Path(os.environ.get("FENICS_CONTACT_DEMO_OUT", "results/demo_fault_sliding"))
out.mkdir(parents=True, exist_ok=True)

# %% [markdown]
# ## The layered pair and the load path

# %%
T = fc.PairTag
mesh = fc.two_blocks(n, int(1.3 * n) + 1, heights=(0.5, 0.4))  # non-matching along the fault
MU, CONTRAST = 0.4, 1e3


# strata about 0.13 thick alternating E = 10³ and 1 with a stiff disc below the fault, the other way round with a
# soft disc above it (`fault_strata`)
lower_strata, upper_strata = fault_strata(CONTRAST)


def pair_at(top):
    """The pair with the upper block's top moved by ``top``."""
    return fc.TwoBodyProblem(
        mesh.mesh,
        mesh.cell_tags,
        mesh.facet_tags,
        bodies=(fc.Body(T.LOWER, lower_strata, 0.3), fc.Body(T.UPPER, upper_strata, 0.25)),
        pair=fc.ContactPair(slave=T.UPPER_BOTTOM, master=T.LOWER_TOP, friction=fc.Friction("coulomb", mu=MU)),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, top)),
    )


press = [(0.0, -0.005), (0.0, -0.01)]
shear = [(s, -0.01) for s in (0.004, 0.008, 0.01, 0.011, 0.012, 0.014, 0.02)]
path = press + shear

# %% [markdown]
# ## Monolithic and Algorithm 1 along the path
# Each solve takes the previous step's `state` (its friction anchors, warm start and, for Algorithm 1, its
# interface data).

# %%
mono, alg1 = [], []
for top in path:
    problem = pair_at(top)
    mono.append(fc.solve(problem, "primal-monolithic", state=mono[-1].state if mono else None))
    alg1.append(fc.solve(problem, "primal", state=alg1[-1].state if alg1 else None))
    a, b = mono[-1], alg1[-1]
    gap = np.linalg.norm(b.u.x.array - a.u.x.array) / np.linalg.norm(a.u.x.array)
    f = a.friction
    print(
        f"top {top}: normal {f.normal_force:.5f}, tangential {f.tangential_force[0]:+.5f}, "
        f"stick {np.count_nonzero(f.stick):3d}, slip {np.count_nonzero(f.slip):3d}, dissipation {a.dissipation:.3e}; "
        f"Algorithm 1: {b.iterations} evaluations of T, differs by {gap:.1e}"
    )
    assert b.converged and gap < 1e-8 and b.iterations <= 8
    assert a.force_balance() < 1e-13 and a.dissipation >= 0.0
last = mono[-1].friction
ratio = abs(last.tangential_force[0]) / last.normal_force
print(f"sliding: tangential / normal force = {ratio:.12f} (μ = {MU}); stick nodes {np.count_nonzero(last.stick)}")
assert np.count_nonzero(last.stick) == 0 and abs(ratio - MU) < 1e-10

# %% [markdown]
# ## Multiscale bulks: Algorithm 3 along the same path
# Each bulk a CEM-GMsFEM space on coarse squares of side H = 1/8 (m = 3 oversampling layers, the rigid motions
# of a coarse cell per cell); the strips, the contact and the friction are Algorithm 1's, so the path carries
# the same `state`. What separates it from Algorithm 1 is the multiscale error of the bulks (energy norm), which
# falls with the layers (`benchmarks/results/two_body_multiscale.md`).

# %%
K = stiffness(pair_at(path[0]), alg1[0].u.function_space)
alg3 = []
for top, fine in zip(path, alg1, strict=True):
    alg3.append(
        fc.solve(
            pair_at(top), "primal-ms", H=0.125, cem=fc.CEMOptions(layers=3), state=alg3[-1].state if alg3 else None
        )
    )
    c, u = alg3[-1], fine.u.x.array
    d = c.u.x.array - u
    error = np.sqrt((d @ (K @ d)) / (u @ (K @ u)))
    print(f"top {top}: Algorithm 3, {c.iterations} evaluations of T, energy error {error:.1e} against Algorithm 1")
    assert c.converged and c.force_balance() < 1e-12 and error < 0.1
f = alg3[-1].friction
print(f"Algorithm 3 sliding: tangential / normal force = {abs(f.tangential_force[0]) / f.normal_force:.12f}")
assert np.count_nonzero(f.stick) == 0 and abs(abs(f.tangential_force[0]) / f.normal_force - MU) < 1e-10

# %% [markdown]
# ## Shear traction along the fault: stick and slip
# One curve per shear step: slip (x) starts where the shear traction first reaches μp and spreads, the stick
# zone (o) shrinks, and at the last step all of the fault slips with |t| = μp.

# %%
fig, axes = plt.subplots(1, 2, figsize=(11, 4))
for k, solution in enumerate(mono[len(press) :]):
    f = solution.friction
    x = f.points[:, 0]
    (line,) = axes[1].plot(x, -f.shear, label=f"shear {shear[k][0]:g}")
    axes[1].plot(x[f.stick], -f.shear[f.stick], "o", color=line.get_color(), markersize=3)
    axes[1].plot(x[f.slip], -f.shear[f.slip], "x", color=line.get_color(), markersize=4)
    axes[0].plot(x, f.pressure, color=line.get_color())
axes[1].plot(x, MU * mono[-1].friction.pressure, "k:", label="μ p (last step)")
for ax, title in zip(axes, ("contact pressure p", "shear traction on the upper block (o stick, x slip)")):
    ax.set_xlabel("x along the fault")
    ax.set_title(title)
axes[1].legend(fontsize=8)
fig.tight_layout()
fig.savefig(out / "fault_tractions.png", dpi=120)
plt.close(fig)

# %% [markdown]
# ## Forces and dissipation along the path

# %%
s = np.array([top[0] for top in path])
normal = np.array([m.friction.normal_force for m in mono])
tangential = np.array([abs(m.friction.tangential_force[0]) for m in mono])
fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.6))
ax.plot(s[len(press) - 1 :], normal[len(press) - 1 :], "o-", label="normal force")
ax.plot(s[len(press) - 1 :], tangential[len(press) - 1 :], "s-", label="tangential force (monolithic)")
ax.plot(s[len(press) - 1 :], [abs(a.friction.tangential_force[0]) for a in alg1[len(press) - 1 :]], "k+",
        markersize=10, label="tangential force (Algorithm 1)")  # fmt: skip
ax.plot(s[len(press) - 1 :], MU * normal[len(press) - 1 :], "k:", label="μ × normal force")
ax.set_xlabel("shear of the upper block's top")
ax.locator_params(axis="x", nbins=5)
ax.legend(fontsize=8, loc="center right")
bx.bar(np.arange(1, len(path) + 1), [m.dissipation for m in mono])
bx.set_xlabel("load step")
bx.set_ylabel("dissipation of the step")
fig.tight_layout()
fig.savefig(out / "fault_forces.png", dpi=120)
plt.close(fig)
print(f"dissipated along the path: {sum(m.dissipation for m in mono):.4e}")

# %% [markdown]
# ## The figures
# Inline when this file runs as a notebook; run as a script, it leaves them as the PNG files above.

# %%
if "ipykernel" in sys.modules:  # a notebook kernel: show the figures written above
    from IPython.display import Image, display

    for png in ("fault_tractions.png", "fault_forces.png"):
        display(Image(filename=str(out / png)))
