"""The monolithic baseline against an independent solver: PETSc's SNES variational-inequality Newton
(``vinewtonrsls``, reduced-space active set) on the penalty-free Signorini problem, as dolfinx_contact uses for
its reference, against the package's penalized semismooth Newton (``fc.solve(problem, "primal-monolithic")``).

The problem: a built-in test model (body force towards Γ_C = {x = 1}, a rigid wall flush with it, the other
sides clamped) on the unit square; Signorini is u_x ≤ 0 at the Γ_C nodes, a bound on those DOFs, so SNES VI
solves it exactly (no penalty). Reported: the wall time of each solve (assembly included, mesh and fields built
before the clock), its Newton steps, the contact force (the reaction Σ (K u − f)_x over Γ_C for SNES VI, the
penalty force for the package) and the contact zone; the difference of the forces is the penalty's O(δ).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/snes_vi_baseline.py --h 64 128 256 \\
        --out benchmarks/results/snes_vi_baseline.md
"""

import argparse
import time

import dolfinx.fem.petsc
import numpy as np
import ufl
from common import write_report
from dolfinx import fem
from petsc4py import PETSc

import fenics_contact as fc
from fenics_contact.fem.forms_primal import elastic_form
from fenics_contact.io import machine_description
from fenics_contact.problem.tags import Boundary


def snes_vi(problem) -> dict:
    """Signorini by SNES vinewtonrsls: K u = f on the free DOFs, u_x ≤ 0 at the Γ_C nodes, u = 0 on Γ_D."""
    cm, F = problem.cm, problem.fields
    msh = cm.mesh
    start = time.perf_counter()
    V = fem.functionspace(msh, ("Lagrange", 1, (2,)))
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    a = fem.form(elastic_form(u, v, F.lmbda, F.mu))
    L = fem.form(ufl.inner(F.f, v) * ufl.dx)
    clamped = fem.locate_dofs_topological(V, 1, cm.facet_tags.find(Boundary.GAMMA_D))
    bc = fem.dirichletbc(np.zeros(2), clamped, V)
    K = dolfinx.fem.petsc.assemble_matrix(a, bcs=[bc])
    K.assemble()
    b = dolfinx.fem.petsc.assemble_vector(L)
    dolfinx.fem.petsc.apply_lifting(b, [a], [[bc]])
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    dolfinx.fem.petsc.set_bc(b, [bc])
    contact_x = fem.locate_dofs_topological(V.sub(0), 1, cm.facet_tags.find(Boundary.GAMMA_C))
    x = K.createVecRight()
    lower, upper = x.duplicate(), x.duplicate()
    lower.set(-PETSc.INFINITY)
    upper.set(PETSc.INFINITY)
    upper.array[contact_x[contact_x < V.dofmap.index_map.size_local * 2]] = 0.0

    def residual(snes, x, r):
        K.mult(x, r)
        r.axpy(-1.0, b)

    def jacobian(snes, x, J, P):
        pass  # K, assembled once

    snes = PETSc.SNES().create(msh.comm)
    snes.setType("vinewtonrsls")
    snes.setFunction(residual, x.duplicate())
    snes.setJacobian(jacobian, K)
    snes.setVariableBounds(lower, upper)
    snes.getKSP().setType("preonly")
    snes.getKSP().getPC().setType("lu")
    snes.getKSP().getPC().setFactorSolverType("mumps")
    snes.setTolerances(rtol=1e-10, atol=1e-12, max_it=100)
    snes.solve(None, x)
    elapsed = time.perf_counter() - start
    r = x.duplicate()
    K.mult(x, r)
    r.axpy(-1.0, b)
    local = contact_x[contact_x < V.dofmap.index_map.size_local * 2]
    force = float(-np.sum(r.array[local]))  # serial: the reaction on the Γ_C x-DOFs
    free = local[~np.isin(local, 2 * clamped)]  # the Γ_C x-DOFs that are not clamped (its end points are)
    active = int(np.count_nonzero(x.array[free] > -1e-12 * max(np.abs(x.array).max(), 1e-300)))
    return {
        "time_s": elapsed,
        "steps": snes.getIterationNumber(),
        "reason": snes.getConvergedReason(),
        "force": abs(force),
        "active": active,
    }


def package(problem) -> dict:
    start = time.perf_counter()
    sol = fc.solve(problem, "primal-monolithic")
    return {
        "time_s": time.perf_counter() - start,
        "steps": sol.newton.steps,
        "force": sol.profile.force,
        "active": int(np.count_nonzero(sol.profile.active)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--model", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--out", default="benchmarks/results/snes_vi_baseline.md")
    args = parser.parse_args()
    lines = [
        "# The monolithic baseline against PETSc's SNES VI Newton (Signorini, no penalty)",
        "",
        f"`OMP_NUM_THREADS=1 .venv/bin/python benchmarks/snes_vi_baseline.py --h {' '.join(map(str, args.h))} "
        f"--model {args.model}`; model {args.model} (contrast 10³, body force onto a wall flush with x = 1), "
        f"times the minimum of {args.repeats} (assembly included), serial.",
        "",
        f"Machine: {machine_description()}.",
        "",
        "## Solves",
        "",
        "| h | DOFs | package: time [s] | Newton steps | SNES VI: time [s] | steps | reason | contact nodes "
        "(package / VI) | force (package) | force (VI) | relative difference |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in args.h:
        problem = fc.models.get_model(args.model).on(fc.unit_square(n, 16))
        problem.fields
        ours = min((package(problem) for _ in range(args.repeats)), key=lambda r: r["time_s"])
        vi = min((snes_vi(problem) for _ in range(args.repeats)), key=lambda r: r["time_s"])
        dofs = 2 * (n + 1) ** 2
        lines.append(
            f"| 1/{n} | {dofs} | {ours['time_s']:.3f} | {ours['steps']} | {vi['time_s']:.3f} | {vi['steps']} | "
            f"{vi['reason']} | {ours['active']} / {vi['active']} | {ours['force']:.6g} | {vi['force']:.6g} | "
            f"{abs(ours['force'] - vi['force']) / vi['force']:.2e} |"
        )
        print(lines[-1], flush=True)
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
