"""Friction: Algorithm 1 against the monolithic solve along a press-and-drag path, and Cattaneo–Mindlin.

(1) Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁), Coulomb μ = 0.3, the wall on x = 1 pressed in by
2e-3 in two steps and dragged by 0.002, 0.008, 0.03: per load step and contrast, Algorithm 1's applications of
T, its Newton steps on the interface data after the condensed solve, the steps of the condensed contact Newton
(the thresholds' fixed point included), and the largest displacement difference to the monolithic path.
``--strategy interface`` runs the interface Newton's "interface" strategy instead.

(2) A cylinder (R = 5) pressed into the Hertz block (contact cells a/(20 r)) with P, then moved sideways: per
drag step Q/(μP), the stick zone's half-width and centre against c = a√(1 − Q/(μP)) (in contact cells), and the
L² distance of |t| to μp₀[√(1 − x²/a²) − (c/a)√(1 − x²/c²)] over the contact zone.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --h 32 --H 8 --nu 0.45 0.49 --refinement 0.5
"""

import argparse

import numpy as np
from dolfinx import fem

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.problem.analytic import hertz_model
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Plane
from fenics_contact.sliding import slide

MU = 0.3


def theorem_table(n: int, n_coarse: int, strategy: str) -> str:
    depth = 2e-3
    path = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.008), (-depth, 0.03)]
    rows = [
        "| contrast | motion | applications of T | interface steps after the condensed solve | condensed contact "
        "Newton steps | max rel. displacement difference |",
        "|---|---|---|---|---|---|",
    ]
    for contrast in (1e3, 1e6):
        model = get_model(3, E_high=contrast).with_(
            obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=Friction("coulomb", mu=MU)
        )
        problem = model.on(unit_square(n, n_coarse))
        V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (2,)))
        fields = {"mono": [], "alg1": []}

        def keep(name):
            def record(step, solver):
                u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
                fields[name].append(u.x.array.copy())

            return record

        slide(problem, "primal-monolithic", path, on_step=keep("mono"))
        alg1 = slide(problem, "primal", path, tol=1e-11, strategy=strategy, on_step=keep("alg1"))
        for step, ua, ub in zip(alg1.steps, fields["mono"], fields["alg1"]):
            gap = np.max(np.abs(ua - ub)) / np.max(np.abs(ua))
            rows.append(
                f"| {contrast:g} | {step.motion.tolist()} | {step.iterations} | "
                f"{step.interface_newton_steps - step.contact_newton_steps} | {step.contact_newton_steps} | {gap:.1e} |"
            )
    return "\n".join(rows)


def cattaneo_table(nus, refinement: float) -> str:
    a_target, radius, depth = 0.05, 5.0, 1.2e-3
    cm, spec = hertz_block(a_target, refinement=refinement)
    hc = spec.h_contact
    rows = [
        f"contact cells h_c = {hc:.4g} (a/{a_target / hc:.0f})",
        "",
        "| ν | Q/(μP) | stick half-width − c [cells] | stick centre [cells] | L² error of q |",
        "|---|---|---|---|---|",
    ]
    for nu in nus:
        model = hertz_model(radius=radius, E=1.0, nu=nu, depth=0.0).with_(law=Friction("coulomb", mu=MU))
        motions = [(0.0, -depth / 2), (0.0, -depth), (2e-4, -depth), (4e-4, -depth)]
        for step in slide(model.on(cm), "primal-monolithic", motions).steps[2:]:
            fp = step.friction
            P, Q = step.normal_force, abs(step.tangential_force[0])
            a = 2.0 * np.sqrt(radius * P / (np.pi / (1.0 - nu**2)))
            p0, ratio = 2.0 * P / (np.pi * a), Q / (MU * P)
            c = a * np.sqrt(max(1.0 - ratio, 0.0))
            lo, hi = fp.extent("stick")
            x = fp.points[:, 0]
            exact = MU * p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
            exact -= np.where(np.abs(x) < c, MU * p0 * (c / a) * np.sqrt(np.maximum(1.0 - (x / c) ** 2, 0.0)), 0.0)
            inside, w = np.abs(x) < a, fp.weights
            q = np.abs(fp.traction[:, 0])
            l2 = np.sqrt(np.sum((w * (q - exact) ** 2)[inside]) / np.sum((w * exact**2)[inside]))
            rows.append(
                f"| {nu:g} | {ratio:.3f} | {(0.5 * (hi - lo) - c) / hc:+.2f} | {0.5 * (hi + lo) / hc:+.2f} | {l2:.3f} |"
            )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=int, default=32, help="1/h of the unit square (Theorem 3.1 table)")
    parser.add_argument("--H", type=int, default=8, help="1/H")
    parser.add_argument("--strategy", default="condensed", choices=("condensed", "interface"))
    parser.add_argument("--nu", type=float, nargs="+", default=[0.45, 0.49], help="Poisson ratios (Cattaneo–Mindlin)")
    parser.add_argument("--refinement", type=float, default=0.5, help="Hertz block refinement r: contact cells a/(20r)")
    args = parser.parse_args()
    print("## Algorithm 1 and the monolithic solve along a frictional path\n")
    print(theorem_table(args.h, args.H, args.strategy))
    print("\n## Cattaneo–Mindlin\n")
    print(cattaneo_table(args.nu, args.refinement))


if __name__ == "__main__":
    main()
