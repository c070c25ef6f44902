"""Friction: Algorithm 1 against the monolithic solve along a press-and-drag path, and Cattaneo–Mindlin.

(1) Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁), Coulomb μ = 0.3, the wall on x = 1 pressed in by
2e-3 in two steps and dragged by 0.002, 0.008, 0.03: per load step and contrast, Algorithm 1's applications of
T, its Newton steps on the interface data after the condensed solve, the steps of the condensed contact Newton
(the thresholds' fixed point included), and the largest displacement difference to the monolithic path.
``--strategy interface`` runs the interface Newton's "interface" strategy instead, ``--method primal-ms``
Algorithm 3 instead of Algorithm 1 (the difference is then its multiscale error), ``--frictionless`` the same path
with no friction (these print table (1) only).  ``--dim 3``: the same on the
3D channel cube (h = 1/``--h``), the wall on x = 1 pressed in by 0.01 and dragged along y by 0.005, 0.01, 0.02
(this table only).

(2) A cylinder (R = 5) pressed into the Hertz block (contact cells a/(20 r)) with P, then moved sideways: per
drag step Q/(μP), the stick zone's half-width and centre against c = a√(1 − Q/(μP)) (in contact cells), and the
L² distance of |t| to μp₀[√(1 − x²/a²) − (c/a)√(1 − x²/c²)] over the contact zone.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --h 32 --H 8 --nu 0.45 0.49 --refinement 0.5
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --dim 3 --h 6

``--mixed``: (1) with Algorithm 2 against the monolithic frictional path on X̃_h (its exact fixed point: e_σ, e_u
per step), (2) with ``mixed-monolithic`` and a step back to 2e-4 (Mindlin–Deresiewicz); ``--width``, ``--depth``:
the Hertz block's size in units of a.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --mixed --h 32 --H 8 --nu 0.4999 --refinement 0.5
"""

import argparse

import numpy as np
from dolfinx import fem

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.fem.mixed import MixedSolution
from fenics_contact.problem.analytic import cattaneo_mindlin, hertz_model
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block
from fenics_contact.problem.models import get_model
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane
from fenics_contact.problem.problem import Frictionless
from fenics_contact.sliding import slide

MU = 0.3


def theorem_table(
    n: int, n_coarse: int, strategy: str, dim: int = 2, method: str = "primal", frictionless: bool = False
) -> str:
    if dim == 2:
        depth = 2e-3
        path = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.008), (-depth, 0.03)]
    else:
        path = [(-0.01, 0.0, 0.0), (-0.01, 0.005, 0.0), (-0.01, 0.01, 0.0), (-0.01, 0.02, 0.0)]
    rows = [
        "| contrast | motion | applications of T | interface steps after the condensed solve | condensed contact "
        "Newton steps | max rel. displacement difference |",
        "|---|---|---|---|---|---|",
    ]
    for contrast in (1e3, 1e6):
        law = Frictionless() if frictionless else Friction("coulomb", mu=MU)
        if dim == 2:
            model = get_model(3, E_high=contrast).with_(obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=law)
            problem = model.on(unit_square(n, n_coarse))
        else:
            wall = Plane((1.0, 0.5, 0.5), (-1.0, 0.0, 0.0))
            problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n)).with_(obstacle=wall, law=law)
        V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (dim,)))
        fields = {"mono": [], "alg1": []}

        def keep(name):
            def record(step, solver):
                u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
                fields[name].append(u.x.array.copy())

            return record

        slide(problem, "primal-monolithic", path, on_step=keep("mono"))
        alg1 = slide(problem, method, path, tol=1e-11, strategy=strategy, on_step=keep("alg1"))
        for step, ua, ub in zip(alg1.steps, fields["mono"], fields["alg1"]):
            gap = np.max(np.abs(ua - ub)) / np.max(np.abs(ua))
            rows.append(
                f"| {contrast:g} | {step.motion.tolist()} | {step.iterations} | "
                f"{step.interface_newton_steps - step.contact_newton_steps} | {step.contact_newton_steps} | {gap:.1e} |"
            )
    return "\n".join(rows)


def mixed_theorem_table(n: int, n_coarse: int) -> str:
    """Algorithm 2 against the monolithic frictional path on X̃_h (its exact fixed point), model 3, per load step."""
    depth = 2e-3
    path = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.008), (-depth, 0.03)]
    rows = [
        "| contrast | motion | applications of T | interface Newton steps | stick / slip nodes | e_σ | e_u |",
        "|---|---|---|---|---|---|---|",
    ]
    for contrast in (1e3, 1e6):
        law = Friction("coulomb", mu=MU)
        model = get_model(3, E_high=contrast).with_(obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=law)
        problem = model.on(unit_square(n, n_coarse))
        solutions, errors = [], []

        def keep(step, solver):
            sub = solver.contact
            solutions.append(
                MixedSolution(sub.sigma_function(), sub.u_function(), None, None, sub.epsilon, {}, 0.0, 0.0, None, True)
            )

        def compare(step, solver):
            solver.set_reference(solutions[len(errors)])
            errors.append(solver.errors())

        slide(problem, "mixed-monolithic", path, split_interface=True, on_step=keep)
        alg2 = slide(problem, "mixed", path, tol=1e-11, on_step=compare)
        for step, (e_s, e_u) in zip(alg2.steps, errors):
            rows.append(
                f"| {contrast:g} | {step.motion.tolist()} | {step.iterations} | {step.interface_newton_steps} | "
                f"{step.stick_nodes} / {step.slip_nodes} | {e_s:.1e} | {e_u:.1e} |"
            )
    return "\n".join(rows)


def _unloading_row(nu: float, radius: float, hc: float, loaded, step) -> str:
    """Mindlin–Deresiewicz: moved back from Q* to Q, against c' = a√(1 − (Q* − Q)/(2μP)) and
    q = μp₀[−√(1 − x²/a²) + 2(c'/a)√(1 − x²/c'²) − (c/a)√(1 − x²/c²)]."""
    fp, P = step.friction, step.normal_force
    Q_star, Q = loaded.tangential_force[0], step.tangential_force[0]
    x, w = fp.points[:, 0], fp.weights
    md = cattaneo_mindlin(x, normal=P, tangential=Q, mu=MU, radius=radius, nu=nu, peak=Q_star)
    a, c_back, exact = md.a, md.c_back, md.shear
    inside = np.abs(x) < a
    l2 = np.sqrt(np.sum((w * (fp.traction[:, 0] - exact) ** 2)[inside]) / np.sum((w * exact**2)[inside]))
    lo, hi = fp.extent("stick")
    return (
        f"| {nu:g} | {Q_star / (MU * P):.3f} → {Q / (MU * P):.3f} | {(0.5 * (hi - lo) - c_back) / hc:+.2f} "
        f"| {0.5 * (hi + lo) / hc:+.2f} | {l2:.3f} |"
    )


def cattaneo_table(
    nus,
    refinement: float,
    method: str = "primal-monolithic",
    width: float = 80.0,
    depth_a: float = 40.0,
    unload: bool = False,
) -> str:
    a_target, radius, depth = 0.05, 5.0, 1.2e-3
    cm, spec = hertz_block(a_target, refinement=refinement, width=width, depth=depth_a)
    hc = spec.h_contact
    rows = [
        f"contact cells h_c = {hc:.4g} (a/{a_target / hc:.0f})",
        "",
        "| ν | Q/(μP) | stick half-width − c [cells] | stick centre [cells] | L² error of q | L² error of p |",
        "|---|---|---|---|---|---|",
    ]
    unloading = [
        "",
        "Moved back to 2e-4 (Mindlin–Deresiewicz):",
        "",
        "| ν | Q*/(μP) → Q/(μP) | stick half-width − c' [cells] | stick centre [cells] | L² error of q |",
        "|---|---|---|---|---|",
    ]
    for nu in nus:
        model = hertz_model(radius=radius, E=1.0, nu=nu, depth=0.0).with_(law=Friction("coulomb", mu=MU))
        motions = [(0.0, -depth / 2), (0.0, -depth), (2e-4, -depth), (4e-4, -depth)]
        path = slide(model.on(cm), method, motions + [(2e-4, -depth)] if unload else motions)
        if unload:
            unloading.append(_unloading_row(nu, radius, hc, path.steps[3], path.steps[4]))
        for step in path.steps[2:4]:
            fp = step.friction
            P, Q = step.normal_force, abs(step.tangential_force[0])
            ratio = Q / (MU * P)
            lo, hi = fp.extent("stick")
            x = fp.points[:, 0]
            cat = cattaneo_mindlin(x, normal=P, tangential=Q, mu=MU, radius=radius, nu=nu)
            a, p0, c, exact = cat.a, cat.p0, cat.c, cat.shear
            inside, w = np.abs(x) < a, fp.weights
            q = np.abs(fp.traction[:, 0])
            l2 = np.sqrt(np.sum((w * (q - exact) ** 2)[inside]) / np.sum((w * exact**2)[inside]))
            hertz = p0 * np.sqrt(np.maximum(1.0 - (x / a) ** 2, 0.0))
            l2p = np.sqrt(np.sum(w * (fp.pressure - hertz) ** 2) / np.sum(w * hertz**2))
            rows.append(
                f"| {nu:g} | {ratio:.3f} | {(0.5 * (hi - lo) - c) / hc:+.2f} | {0.5 * (hi + lo) / hc:+.2f} | {l2:.3f} "
                f"| {l2p:.3f} |"
            )
    return "\n".join(rows + (unloading if unload else []))


def primal_mixed_table(nus, refinement: float) -> str:
    """Cattaneo–Mindlin where ν < ½: ``primal-monolithic`` against ``mixed-monolithic`` on the same block and path
    (the formula neglects the normal–tangential coupling ν < ½ brings; the two discretizations do not): per drag
    step the stick half-widths (in contact cells) and the L² distance of the primal shear traction to the mixed one
    (interpolated to the primal nodes) over the mixed contact zone, beside each one's distance to the formula."""
    a_target, radius, depth = 0.05, 5.0, 1.2e-3
    cm, spec = hertz_block(a_target, refinement=refinement)
    hc = spec.h_contact
    rows = [
        f"contact cells h_c = {hc:.4g} (a/{a_target / hc:.0f})",
        "",
        "| ν | Q/(μP) | stick half-width − c, primal / mixed [cells] | ‖q_primal − q_mixed‖/‖q_mixed‖ | "
        "L² error of q to the formula, primal / mixed |",
        "|---|---|---|---|---|",
    ]
    motions = [(0.0, -depth / 2), (0.0, -depth), (2e-4, -depth), (4e-4, -depth)]
    for nu in nus:
        model = hertz_model(radius=radius, E=1.0, nu=nu, depth=0.0).with_(law=Friction("coulomb", mu=MU))
        paths = [slide(model.on(cm), method, motions) for method in ("primal-monolithic", "mixed-monolithic")]
        for primal, mixed in zip(paths[0].steps[2:], paths[1].steps[2:]):
            P, Q = mixed.normal_force, abs(mixed.tangential_force[0])
            ratio = Q / (MU * P)
            widths, errors = [], []
            for step in (primal, mixed):
                fp = step.friction
                x, w = fp.points[:, 0], fp.weights
                exact = cattaneo_mindlin(x, normal=P, tangential=Q, mu=MU, radius=radius, nu=nu)
                lo, hi = fp.extent("stick")
                widths.append((0.5 * (hi - lo) - exact.c) / hc)
                a, exact = exact.a, exact.shear
                inside = np.abs(x) < a
                q = np.abs(fp.traction[:, 0])
                errors.append(np.sqrt(np.sum((w * (q - exact) ** 2)[inside]) / np.sum((w * exact**2)[inside])))
            fm, fp = mixed.friction, primal.friction
            xm, qm = fm.points[:, 0], np.abs(fm.traction[:, 0])
            order = np.argsort(xm)
            x, w = fp.points[:, 0], fp.weights
            reference = np.interp(x, xm[order], qm[order])
            zone = (x >= np.min(xm[fm.stick | fm.slip])) & (x <= np.max(xm[fm.stick | fm.slip]))
            q = np.abs(fp.traction[:, 0])
            gap = np.sqrt(np.sum((w * (q - reference) ** 2)[zone]) / np.sum((w * reference**2)[zone]))
            rows.append(
                f"| {nu:g} | {ratio:.3f} | {widths[0]:+.2f} / {widths[1]:+.2f} | {gap:.3f} | "
                f"{errors[0]:.3f} / {errors[1]:.3f} |"
            )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--h", type=int, default=32, help="1/h of the unit square (Theorem 3.1 table)")
    parser.add_argument("--H", type=int, default=8, help="1/H")
    parser.add_argument("--strategy", default="condensed", choices=("condensed", "interface"))
    parser.add_argument(
        "--method", default="primal", choices=("primal", "primal-ms"), help="the hybrid method of table (1)"
    )
    parser.add_argument("--frictionless", action="store_true", help="table (1) without friction")
    parser.add_argument("--dim", type=int, default=2, choices=(2, 3), help="3: the 3D channel cube, h = 1/--h")
    parser.add_argument("--nu", type=float, nargs="+", default=[0.45, 0.49], help="Poisson ratios (Cattaneo–Mindlin)")
    parser.add_argument("--refinement", type=float, default=0.5, help="Hertz block refinement r: contact cells a/(20r)")
    parser.add_argument(
        "--mixed", action="store_true", help="the mixed methods: Algorithm 2 and mixed-monolithic (Cattaneo–Mindlin)"
    )
    parser.add_argument("--width", type=float, default=80.0, help="Hertz block width / a (Cattaneo–Mindlin)")
    parser.add_argument("--depth", type=float, default=40.0, help="Hertz block depth / a (Cattaneo–Mindlin)")
    parser.add_argument(
        "--primal-mixed", action="store_true", help="Cattaneo–Mindlin: primal-monolithic against mixed-monolithic"
    )
    args = parser.parse_args()
    if args.primal_mixed:
        print("## Cattaneo–Mindlin: primal-monolithic against mixed-monolithic\n")
        print(primal_mixed_table(args.nu, args.refinement))
        return
    if args.mixed:
        print("## Algorithm 2 and the monolithic solve on X̃_h along a frictional path\n")
        print(mixed_theorem_table(args.h, args.H))
        print("\n## Cattaneo–Mindlin (mixed-monolithic)\n")
        print(cattaneo_table(args.nu, args.refinement, "mixed-monolithic", args.width, args.depth, unload=True))
        return
    print("## Algorithm 1 and the monolithic solve along a frictional path\n")
    print(theorem_table(args.h, args.H, args.strategy, args.dim, args.method, args.frictionless))
    if args.method != "primal" or args.frictionless:
        return
    if args.dim == 3:
        return
    print("\n## Cattaneo–Mindlin\n")
    print(cattaneo_table(args.nu, args.refinement))


if __name__ == "__main__":
    main()
