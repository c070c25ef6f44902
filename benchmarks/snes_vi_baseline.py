"""The monolithic baseline against an independent solver along a load path: PETSc's SNES variational-inequality
Newton (``vinewtonrsls``, reduced-space active set) on the penalty-free Signorini problem, as dolfinx_contact
uses for its reference, against the package's penalized semismooth Newton (``force_indentation(problem,
"primal-monolithic", …)``: its symbolic analysis kept, each step warm-started from the last and its active set).

The case: a cylinder ``Circle(centre, radius)`` indents Γ_C = {x = 1} of a built-in test model along
``direction`` in load steps.  The Signorini condition at a Γ_C node p is u_p·ν_p ≤ g_p (ν_p, g_p the obstacle's
normal and gap at the node, the same nodal constraint the penalty (w_p/δ)(u_p·ν_p − g_p)⁺ acts on): not a bound
on the x/y unknowns when ν_p turns along Γ_C.  It becomes one in each contact node's own frame: the node's two
unknowns are rotated to (u·ν_p, u·t_p), u = R u' with R block-diagonal (the identity off Γ_C), so the problem is
K' u' = f' with K' = Rᵀ K R, f' = Rᵀ f (K the stiffness with the clamped rows, f the body load) and the bound
u'_n ≤ g on the normal unknowns only.  Each step moves the obstacle (new ν, g: a new R and K' = Rᵀ K R by
PETSc's PtAP), warm-starts from the last step's displacement and lets SNES VI solve; its linear solves are
MUMPS on the reduced (inactive) block, as in dolfinx_contact's reference, here its Cholesky as the package's
(the blocks are symmetric positive definite).

Reported per model and h: the set-up and the time per step (median) and the whole curve for both solvers (the
SNES VI's set-up: the package's contact subproblem built for its nodal ν and g, the stiffness and load
assembled; the package's: its solver built), the Newton steps, the
contact nodes of the last step (package / VI, and how many differ over the path), and the largest relative
difference of the forces (the obstacle's resultant along ``direction``: Σ_p (r_p·ν_p)(ν_p·d) with r = K u − f
the reaction at the Γ_C nodes, for both solvers) over the steps: the penalty's O(δ).  ``--delta-factors``
repeats the package's curve with δ scaled, to show the difference shrinking with δ.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/snes_vi_baseline.py --models 3 2 --h 64 128 256 --steps 20 \\
        --delta-factors 0.1 0.01 --out benchmarks/results/snes_vi_baseline.md
"""

import argparse
import os
import time

import numpy as np
from common import write_report
from petsc4py import PETSc

import fenics_contact as fc
from fenics_contact.fem.primal import penalty_for
from fenics_contact.indentation import force_indentation
from fenics_contact.io import machine_description
from fenics_contact.methods import get_method
from fenics_contact.problem.models import get_model


def problem_on(model: int, h: int, H: int, centre, radius):
    obstacle = fc.Circle(tuple(centre), radius)
    return get_model(model, E_high=1e3).with_(obstacle=obstacle).on(fc.unit_square(h, H))


def rotation(n: int, nodes: np.ndarray, nu: np.ndarray) -> PETSc.Mat:
    """R (n × n, 2D): the identity, with the block [ν_p t_p] (t_p = ν_p turned by 90°) at each contact node p:
    u_x = ν_x u_n − ν_y u_t, u_y = ν_y u_n + ν_x u_t."""
    counts = np.ones(n, dtype=PETSc.IntType)
    counts[2 * nodes] = counts[2 * nodes + 1] = 2
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
    indices = np.empty(indptr[-1], dtype=PETSc.IntType)
    data = np.empty(indptr[-1])
    indices[indptr[:-1]] = np.arange(n)
    data[indptr[:-1]] = 1.0
    x, y = 2 * nodes, 2 * nodes + 1
    for row, first, second in ((x, nu[:, 0], -nu[:, 1]), (y, nu[:, 1], nu[:, 0])):
        indices[indptr[row]], indices[indptr[row] + 1] = x, y
        data[indptr[row]], data[indptr[row] + 1] = first, second
    R = PETSc.Mat().createAIJ((n, n), csr=(indptr, indices, data), comm=PETSc.COMM_SELF)
    R.assemble()
    return R


class SignoriniVI:
    """The penalty-free Signorini problem of a primal contact subproblem solved by SNES ``vinewtonrsls``."""

    def __init__(self, sub) -> None:
        self.sub = sub
        self.K = sub.contact_free_matrix()  # the stiffness, identity on Γ_D (no contact, no Robin term)
        self.f = sub.body_load(self.K.createVecLeft())
        self.n = self.K.getSize()[0]
        self.u = self.K.createVecRight()  # the displacement (x/y frame), the warm start of the next step
        self.x = self.u.duplicate()  # the rotated unknowns
        self.rhs = self.u.duplicate()
        self.lower, self.upper = self.u.duplicate(), self.u.duplicate()
        self.lower.set(-PETSc.INFINITY)
        self.Kr: PETSc.Mat | None = None
        self.snes = PETSc.SNES().create(PETSc.COMM_SELF)
        self.snes.setType("vinewtonrsls")
        self.snes.setFunction(self._residual, self.u.duplicate())
        self.snes.getKSP().setType("preonly")
        self.snes.getKSP().getPC().setType("cholesky")  # (the reduced blocks of K' are SPD, like the package's J)
        self.snes.getKSP().getPC().setFactorSolverType("mumps")
        self.snes.setTolerances(rtol=1e-10, atol=1e-12 * self.f.norm(), stol=0.0, max_it=100)

    def _residual(self, snes, x, r) -> None:
        self.Kr.mult(x, r)
        r.axpy(-1.0, self.rhs)

    def solve(self) -> dict:
        """One load step at the subproblem's current obstacle: Newton steps, the contact nodes (block indices of
        the nodes at their bound), the force along ``direction`` is taken by ``force``."""
        nodes, nu, _, gap = self.sub.contact_nodes()
        R = rotation(self.n, nodes, nu)
        self.Kr = self.K.PtAP(R) if self.Kr is None else self.K.PtAP(R, result=self.Kr)
        R.multTranspose(self.f, self.rhs)
        R.multTranspose(self.u, self.x)  # the last displacement in the new frame (R orthogonal)
        self.upper.set(PETSc.INFINITY)
        self.upper.array[2 * nodes] = gap
        self.x.array[2 * nodes] = np.minimum(self.x.array[2 * nodes], gap)
        self.snes.setJacobian(lambda snes, x, J, P: None, self.Kr)
        self.snes.setVariableBounds(self.lower, self.upper)
        self.snes.solve(None, self.x)
        reason = self.snes.getConvergedReason()
        if reason <= 0:
            raise RuntimeError(f"SNES VI did not converge (reason {reason})")
        R.mult(self.x, self.u)
        R.destroy()
        xn = self.x.array[2 * nodes]
        at_bound = np.abs(xn - gap) <= 1e-12 * max(np.abs(gap).max(initial=0.0), np.abs(xn).max(initial=0.0), 1e-300)
        return {"steps": self.snes.getIterationNumber(), "active": nodes[at_bound]}

    def force(self, direction: np.ndarray) -> float:
        """The obstacle's force along ``direction``: Σ_p (r_p·ν_p)(ν_p·d), r = K u − f at the contact nodes."""
        nodes, nu, _, _ = self.sub.contact_nodes()
        r = self.u.duplicate()
        self.K.mult(self.u, r)
        r.axpy(-1.0, self.f)
        rp = r.array.reshape(-1, 2)[nodes]
        force = float(np.sum(np.sum(rp * nu, axis=1) * (nu @ direction)))
        r.destroy()
        return force


def vi_curve(problem, depths: np.ndarray, direction: np.ndarray) -> dict:
    """The SNES VI's load path: set-up, per-step times, forces and contact nodes."""
    base = problem.obstacle
    start = time.perf_counter()
    solver = get_method("primal-monolithic").build(problem.with_(obstacle=base.indented(depths[0], direction)))
    sub = solver.contact
    vi = SignoriniVI(sub)
    setup = time.perf_counter() - start
    times, forces, actives, steps = [], [], [], []
    for depth in depths:
        start = time.perf_counter()
        sub.set_obstacle(base.indented(depth, direction))
        out = vi.solve()
        forces.append(vi.force(direction))
        times.append(time.perf_counter() - start)
        steps.append(out["steps"])
        actives.append(out["active"])
    coords = sub.V.tabulate_dof_coordinates()
    y = [np.sort(coords[a, 1]) for a in actives]
    return {"setup": setup, "times": np.array(times), "forces": np.array(forces), "steps": steps, "active_y": y}


def package_curve(problem, depths: np.ndarray, direction: np.ndarray, delta: float | None = None) -> dict:
    """The package's monolithic load path (``force_indentation``): set-up, per-step times, forces, contact nodes."""
    start = time.perf_counter()
    curve = force_indentation(
        problem, "primal-monolithic", depths, direction=tuple(direction), **({} if delta is None else {"delta": delta})
    )
    total = time.perf_counter() - start
    return {
        "setup": curve.time_offline_s,
        "times": np.array([s.time_s for s in curve.steps]),
        "total": total,
        "forces": curve.forces,
        "steps": [s.iterations for s in curve.steps],
        "active_y": [np.sort(s.profile.y[s.profile.active]) for s in curve.steps],
    }


def differing(a: list, b: list) -> int:
    """Contact nodes in one set only, summed over the steps (nodes matched by their y on Γ_C)."""
    return sum(np.setxor1d(np.round(x, 12), np.round(y, 12)).size for x, y in zip(a, b))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--models", type=int, nargs="+", default=[3, 2])
    parser.add_argument("--h", type=int, nargs="+", default=[64, 128, 256])
    parser.add_argument("--H", type=int, default=16)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--first", type=float, default=0.002)
    parser.add_argument("--last", type=float, default=0.02)
    parser.add_argument("--centre", type=float, nargs=2, default=[3.0, 0.5])
    parser.add_argument("--radius", type=float, default=2.0)
    parser.add_argument("--direction", type=float, nargs=2, default=[-1.0, 0.0])
    parser.add_argument("--delta-factors", type=float, nargs="*", default=[], help="δ/δ_default for the δ study")
    parser.add_argument("--delta-h", type=int, default=64, help="1/h of the δ study")
    parser.add_argument("--out", default=None)
    args = parser.parse_args()
    depths = np.linspace(args.first, args.last, args.steps)
    direction = np.asarray(args.direction, dtype=float) / np.linalg.norm(args.direction)
    command = (
        f"OMP_NUM_THREADS=1 .venv/bin/python benchmarks/snes_vi_baseline.py --models {' '.join(map(str, args.models))} "
        f"--h {' '.join(map(str, args.h))} --steps {args.steps}"
        + (f" --delta-factors {' '.join(f'{f:g}' for f in args.delta_factors)}" if args.delta_factors else "")
        + (f" --out {args.out}" if args.out else "")
    )
    lines = [
        "# The monolithic baseline against PETSc's SNES VI Newton along a load path (Signorini, no penalty)",
        "",
        f"Command: `{command}`",
        "",
        f"A cylinder `Circle({tuple(args.centre)}, {args.radius})` indents x = 1 along {tuple(map(float, direction))} from depth "
        f"{args.first:g} to {args.last:g} in {args.steps} steps (contrast 10³).  Package: `force_indentation(problem, "
        '"primal-monolithic", …)`, the penalized semismooth Newton (MUMPS Cholesky, analysis kept, warm starts).  SNES VI: '
        "`vinewtonrsls` on the rotated Signorini problem (K' = Rᵀ K R, bound u·ν ≤ g on the contact nodes' normal "
        "unknowns), warm-started from the last step, MUMPS Cholesky on the reduced blocks.  Wall times in one process, the two solvers one "
        "after the other.",
        "",
        f"Machine: {machine_description()}; load average {os.getloadavg()[0]:.1f} at the start.",
        "",
        "## Solves",
        "",
        "| model | h | DOFs | package: set-up [s] | step median [s] | curve [s] | Newton steps | SNES VI: set-up [s] "
        "| step median [s] | curve [s] | VI steps | package / VI (curve) | contact nodes, last step (package / VI) "
        "| nodes differing over the path | max force difference |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for model in args.models:
        for h in args.h:
            ours = package_curve(problem_on(model, h, args.H, args.centre, args.radius), depths, direction)
            vi = vi_curve(problem_on(model, h, args.H, args.centre, args.radius), depths, direction)
            ours_curve = ours["setup"] + ours["times"].sum()
            vi_total = vi["setup"] + vi["times"].sum()
            diff = np.max(np.abs(ours["forces"] - vi["forces"]) / np.abs(vi["forces"]))
            lines.append(
                f"| {model} | 1/{h} | {2 * (h + 1) ** 2} | {ours['setup']:.2f} | {np.median(ours['times']):.3f} "
                f"| {ours_curve:.2f} | {sum(ours['steps'])} | {vi['setup']:.2f} | {np.median(vi['times']):.3f} "
                f"| {vi_total:.2f} | {sum(vi['steps'])} | {ours_curve / vi_total:.2f} "
                f"| {ours['active_y'][-1].size} / {vi['active_y'][-1].size} "
                f"| {differing(ours['active_y'], vi['active_y'])} | {diff:.2e} |"
            )
            print(lines[-1], flush=True)
    if args.delta_factors:
        lines += [
            "",
            f"## The force difference against δ (h = 1/{args.delta_h})",
            "",
            "| model | δ / δ_default | δ | max force difference |",
            "|---|---|---|---|",
        ]
        for model in args.models:
            problem = problem_on(model, args.delta_h, args.H, args.centre, args.radius)
            vi = vi_curve(problem, depths, direction)
            default = penalty_for(problem)
            for factor in [1.0, *args.delta_factors]:
                problem = problem_on(model, args.delta_h, args.H, args.centre, args.radius)
                ours = package_curve(problem, depths, direction, delta=factor * default)
                diff = np.max(np.abs(ours["forces"] - vi["forces"]) / np.abs(vi["forces"]))
                lines.append(f"| {model} | {factor:g} | {factor * default:.2e} | {diff:.2e} |")
                print(lines[-1], flush=True)
    if args.out:
        write_report(args.out, lines)
    else:
        print("\n".join(lines))


if __name__ == "__main__":
    main()
