"""Friction: Algorithm 1 against the monolithic solve along a press-and-drag path, and Cattaneo–Mindlin.

(1) Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁), Coulomb μ = 0.3, the wall on x = 1 pressed in by
2e-3 in two steps and dragged by 0.002, 0.008, 0.03: per load step and contrast, Algorithm 1's applications of
T, its Newton steps on the interface data after the condensed solve, the steps of the condensed contact Newton
(the thresholds' fixed point and every Newton that did not converge included), the monolithic frictional Newton's
steps (counted alike), and the largest displacement difference to the monolithic path.
``--strategy interface`` runs the interface Newton's "interface" strategy instead, ``--method primal-ms``
Algorithm 3 instead of Algorithm 1 (the difference is then its multiscale error), ``--frictionless`` the same path
with no friction (these print table (1) only).  ``--dim 3``: the same on the
3D channel cube (h = 1/``--h``, Poisson ratio ``--cube-nu``), the wall on x = 1 pressed in by 0.01 and dragged along
y by 0.005, 0.01, 0.02 (this table only); ``--contrast`` the contrasts (default 10³ and 10⁶).

(2) A cylinder (R = 100a) pressed into the Hertz block (80a × 40a, contact cells a/(20 r), a = 0.05) with P, then
moved sideways: the pressed state against Hertz (a, p₀ from the computed normal force P: the contact half-width,
the peak and the L² error of p), and per drag step Q/(μP), the stick zone's half-width and centre against
c = a√(1 − Q/(μP)) (in contact cells), and the L² distance of |t| to μp₀[√(1 − x²/a²) − (c/a)√(1 − x²/c²)] over the
contact zone.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --h 32 --H 8 --nu 0.45 0.49 --refinement 0.5
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --dim 3 --h 6

``--mixed``: (1) with Algorithm 2 against the monolithic frictional path on X̃_h (its exact fixed point: e_σ, e_u
per step), (2) with ``mixed-monolithic`` and a step back (Mindlin–Deresiewicz), at each ``--refinement`` and the L²
errors' observed rates.  ``--half-space``: the block 1000a × 500a graded to 64a cells and R = 1000a
(``HALF_SPACE``), where the half-space formulas hold; ``--width``, ``--depth``, ``--radius`` (in units of a) change
the block and the cylinder; ``--cattaneo``: the tables of (2) only.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/friction.py --mixed --half-space --nu 0.4999 --refinement 0.5 1 2
"""

import argparse
from dataclasses import dataclass, replace

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
    n: int,
    n_coarse: int,
    strategy: str,
    dim: int = 2,
    method: str = "primal",
    frictionless: bool = False,
    contrasts=(1e3, 1e6),
    cube_nu: float | None = None,
) -> str:
    if dim == 2:
        depth = 2e-3
        path = [(-depth / 2, 0.0), (-depth, 0.0), (-depth, 0.002), (-depth, 0.008), (-depth, 0.03)]
    else:
        path = [(-0.01, 0.0, 0.0), (-0.01, 0.005, 0.0), (-0.01, 0.01, 0.0), (-0.01, 0.02, 0.0)]
    rows = [
        "| contrast | motion | applications of T | interface steps after the condensed solve | condensed contact "
        "Newton steps | monolithic Newton steps | max rel. displacement difference |",
        "|---|---|---|---|---|---|---|",
    ]
    for contrast in contrasts:
        law = Frictionless() if frictionless else Friction("coulomb", mu=MU)
        if dim == 2:
            model = get_model(3, E_high=contrast).with_(obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=law)
            problem = model.on(unit_square(n, n_coarse))
        else:
            wall = Plane((1.0, 0.5, 0.5), (-1.0, 0.0, 0.0))
            model = channels_3d(E_high=contrast, **({} if cube_nu is None else {"nu": cube_nu}))
            problem = model.on(channels_3d_mesh(n)).with_(obstacle=wall, law=law)
        V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (dim,)))
        fields = {"mono": [], "alg1": []}

        def keep(name):
            def record(step, solver):
                u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
                fields[name].append(u.x.array.copy())

            return record

        mono = slide(problem, "primal-monolithic", path, on_step=keep("mono"))
        alg1 = slide(problem, method, path, tol=1e-11, strategy=strategy, on_step=keep("alg1"))
        for step, reference, ua, ub in zip(alg1.steps, mono.steps, fields["mono"], fields["alg1"]):
            gap = np.max(np.abs(ua - ub)) / np.max(np.abs(ua))
            rows.append(
                f"| {contrast:g} | {step.motion.tolist()} | {step.iterations} | "
                f"{step.interface_newton_steps - step.contact_newton_steps} | {step.contact_newton_steps} | "
                f"{reference.iterations} | {gap:.1e} |"
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


@dataclass(frozen=True)
class CattaneoSetup:
    """The cylinder and block of the Cattaneo–Mindlin tables, lengths in units of a = 0.05: the cylinder's radius,
    the block's width and depth, its far mesh size (``hertz_block``'s ``h_far`` at refinement 1), the indentation
    and the tangential motion of each drag step (the load steps: pressed by ``press``/2 and ``press``, then moved
    sideways by ``drag``, 2·``drag`` and back to ``drag``)."""

    radius: float = 100.0
    width: float = 80.0
    depth: float = 40.0
    h_far: float = 8.0
    press: float = 1.2e-3
    drag: float = 2e-4


#: a half-space to the contact: the block 1000a × 500a graded from the contact cells to 64a cells (1.4·10³ cells at
#: h_c = a/10), the cylinder's radius 1000a (the law's tangent turns by x/R across the contact: |x|/R ≤ 10⁻³)
HALF_SPACE = CattaneoSetup(radius=1000.0, width=1000.0, depth=500.0, h_far=64.0, press=1.7e-4, drag=2.4e-5)


def _l2(values: np.ndarray, exact: np.ndarray, weights: np.ndarray, inside) -> float:
    return float(np.sqrt(np.sum((weights * (values - exact) ** 2)[inside]) / np.sum((weights * exact**2)[inside])))


def _contact_half_width(x: np.ndarray, p: np.ndarray) -> float:
    """Half the extent of the run of Γ_C nodes in contact (p > 0) around the node nearest the axis."""
    order = np.argsort(x)
    x, touching = x[order], p[order] > 0.0
    centre = int(np.argmin(np.abs(x)))
    lo = hi = centre
    while lo > 0 and touching[lo - 1]:
        lo -= 1
    while hi < x.size - 1 and touching[hi + 1]:
        hi += 1
    return 0.5 * float(x[hi] - x[lo])


def cattaneo_table(nus, refinement: float, method: str = "primal-monolithic", setup=CattaneoSetup(), unload=False):
    """Per ν: the pressed state against Hertz (a, p₀ from the computed normal force P), each drag step against
    Cattaneo–Mindlin and (``unload``) the step back against Mindlin–Deresiewicz."""
    return "\n".join(_cattaneo_rows(nus, refinement, method, setup, unload)[0])


def _cattaneo_rows(nus, refinement: float, method: str, setup: CattaneoSetup, unload: bool):
    a_target = 0.05
    radius = setup.radius * a_target
    cm, spec = hertz_block(a_target, refinement=refinement, width=setup.width, depth=setup.depth, h_far=setup.h_far)
    hc = spec.h_contact
    cells = cm.mesh.topology.index_map(cm.mesh.topology.dim).size_global
    head = [
        f"contact cells h_c = {hc:.4g} (a/{a_target / hc:.0f}), {cells} cells",
        "",
        "| ν | pressed: P | a/h_c | contact half-width − a [cells] | max p/p₀ − 1 | L² error of p |",
        "|---|---|---|---|---|---|",
    ]
    rows = [
        "",
        "| ν | Q/(μP) | stick half-width − c [cells] | stick centre [cells] | L² error of q | L² error of p |",
        "|---|---|---|---|---|---|",
    ]
    unloading = [
        "",
        "Moved back (Mindlin–Deresiewicz):",
        "",
        "| ν | Q*/(μP) → Q/(μP) | stick half-width − c' [cells] | stick centre [cells] | L² error of q |",
        "|---|---|---|---|---|",
    ]
    errors = {"p": [], "q": [], "md": []}
    d, t = setup.press, setup.drag
    for nu in nus:
        model = hertz_model(radius=radius, E=1.0, nu=nu, depth=0.0).with_(law=Friction("coulomb", mu=MU))
        motions = [(0.0, -d / 2), (0.0, -d), (t, -d), (2 * t, -d)]
        path = slide(model.on(cm), method, motions + [(t, -d)] if unload else motions)
        pressed = path.steps[1].friction
        x, w = pressed.points[:, 0], pressed.weights
        hertz = cattaneo_mindlin(x, normal=path.steps[1].normal_force, tangential=0.0, mu=MU, radius=radius, nu=nu)
        exact_p = hertz.p0 * np.sqrt(np.maximum(1.0 - (x / hertz.a) ** 2, 0.0))
        errors["p"].append(_l2(pressed.pressure, exact_p, w, slice(None)))
        head.append(
            f"| {nu:g} | {path.steps[1].normal_force:.4e} | {hertz.a / hc:.2f} | "
            f"{(_contact_half_width(x, pressed.pressure) - hertz.a) / hc:+.2f} | "
            f"{pressed.pressure.max() / hertz.p0 - 1.0:+.4f} | {errors['p'][-1]:.4f} |"
        )
        for step in path.steps[2:4]:
            fp = step.friction
            P, Q = step.normal_force, abs(step.tangential_force[0])
            lo, hi = fp.extent("stick")
            x, w = fp.points[:, 0], fp.weights
            cat = cattaneo_mindlin(x, normal=P, tangential=Q, mu=MU, radius=radius, nu=nu)
            errors["q"].append(_l2(np.abs(fp.traction[:, 0]), cat.shear, w, np.abs(x) < cat.a))
            exact_p = cat.p0 * np.sqrt(np.maximum(1.0 - (x / cat.a) ** 2, 0.0))
            rows.append(
                f"| {nu:g} | {Q / (MU * P):.3f} | {(0.5 * (hi - lo) - cat.c) / hc:+.2f} | {0.5 * (hi + lo) / hc:+.2f} "
                f"| {errors['q'][-1]:.4f} | {_l2(fp.pressure, exact_p, w, slice(None)):.4f} |"
            )
        if unload:
            step, loaded = path.steps[4], path.steps[3]
            fp, P = step.friction, step.normal_force
            Q_star, Q = loaded.tangential_force[0], step.tangential_force[0]
            x, w = fp.points[:, 0], fp.weights
            md = cattaneo_mindlin(x, normal=P, tangential=Q, mu=MU, radius=radius, nu=nu, peak=Q_star)
            errors["md"].append(_l2(fp.traction[:, 0], md.shear, w, np.abs(x) < md.a))
            lo, hi = fp.extent("stick")
            unloading.append(
                f"| {nu:g} | {Q_star / (MU * P):.3f} → {Q / (MU * P):.3f} | {(0.5 * (hi - lo) - md.c_back) / hc:+.2f} "
                f"| {0.5 * (hi + lo) / hc:+.2f} | {errors['md'][-1]:.4f} |"
            )
    return head + rows + (unloading if unload else []), hc, errors


def cattaneo_rates(nus, refinements, method: str, setup: CattaneoSetup) -> str:
    """The Cattaneo–Mindlin tables at each refinement, then the L² errors against h_c with the observed rates."""
    out, table = [], []
    for r in refinements:
        rows, hc, errors = _cattaneo_rows(nus, r, method, setup, unload=True)
        out += [f"### h_c = a/{0.05 / hc:.0f}", ""] + rows + [""]
        table.append((hc, errors))
    out += [
        "### L² errors against h_c (the first ν; observed rate: log₂ of the ratio between successive h_c)",
        "",
        "| h_c | p (pressed) | q at the first drag | q at the second drag | q moved back |",
        "|---|---|---|---|---|",
    ]
    previous = None
    for hc, errors in table:
        values = [errors["p"][0], errors["q"][0], errors["q"][1], errors["md"][0]]
        cells = []
        for i, v in enumerate(values):
            rate = "" if previous is None else f" ({np.log(previous[1][i] / v) / np.log(previous[0] / hc):.2f})"
            cells.append(f"{v:.4f}{rate}")
        out.append(f"| a/{0.05 / hc:.0f} | " + " | ".join(cells) + " |")
        previous = (hc, values)
    return "\n".join(out)


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
    parser.add_argument("--cube-nu", type=float, help="the channel cube's Poisson ratio (--dim 3; default 0.35)")
    parser.add_argument(
        "--contrast", type=float, nargs="+", default=[1e3, 1e6], help="the contrasts of table (1) (E_high/E_low)"
    )
    parser.add_argument(
        "--refinement",
        type=float,
        nargs="+",
        default=[0.5],
        help="Hertz block refinement r: contact cells a/(20r) (several with --mixed: the L² errors' rates)",
    )
    parser.add_argument(
        "--mixed", action="store_true", help="the mixed methods: Algorithm 2 and mixed-monolithic (Cattaneo–Mindlin)"
    )
    parser.add_argument(
        "--half-space",
        action="store_true",
        help="Cattaneo–Mindlin on the 1000a × 500a graded block under a cylinder of radius 1000a (HALF_SPACE)",
    )
    parser.add_argument("--width", type=float, help="Hertz block width / a (Cattaneo–Mindlin; default 80)")
    parser.add_argument("--depth", type=float, help="Hertz block depth / a (Cattaneo–Mindlin; default 40)")
    parser.add_argument(
        "--radius", type=float, help="the cylinder's radius / a (Cattaneo–Mindlin; default 100; the motions ∝ 1/R)"
    )
    parser.add_argument("--cattaneo", action="store_true", help="with --mixed: only the Cattaneo–Mindlin tables")
    parser.add_argument(
        "--primal-mixed", action="store_true", help="Cattaneo–Mindlin: primal-monolithic against mixed-monolithic"
    )
    args = parser.parse_args()
    setup = HALF_SPACE if args.half_space else CattaneoSetup()
    given = {"width": args.width, "depth": args.depth, "radius": args.radius}
    setup = replace(setup, **{key: value for key, value in given.items() if value is not None})
    if args.radius is not None:  # the same a: P and the motions scale with 1/R
        scale = (HALF_SPACE if args.half_space else CattaneoSetup()).radius / args.radius
        setup = replace(setup, press=setup.press * scale, drag=setup.drag * scale)
    if args.primal_mixed:
        print("## Cattaneo–Mindlin: primal-monolithic against mixed-monolithic\n")
        print(primal_mixed_table(args.nu, args.refinement[0]))
        return
    if args.mixed:
        if not args.cattaneo:
            print("## Algorithm 2 and the monolithic solve on X̃_h along a frictional path\n")
            print(mixed_theorem_table(args.h, args.H))
        print("\n## Cattaneo–Mindlin (mixed-monolithic)\n")
        print(cattaneo_rates(args.nu, args.refinement, "mixed-monolithic", setup))
        return
    print("## Algorithm 1 and the monolithic solve along a frictional path\n")
    print(
        theorem_table(
            args.h, args.H, args.strategy, args.dim, args.method, args.frictionless, args.contrast, args.cube_nu
        )
    )
    if args.method != "primal" or args.frictionless:
        return
    if args.dim == 3:
        return
    print("\n## Cattaneo–Mindlin\n")
    print(cattaneo_table(args.nu, args.refinement[0], setup=setup))


if __name__ == "__main__":
    main()
