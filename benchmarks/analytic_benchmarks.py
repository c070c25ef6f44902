"""Analytic benchmarks: errors and rates per method.

Methods: the primal P1 and mixed Arnold–Winther monolithic penalty solves, Algorithms 1 and 2, and the
multiscale Algorithms 3 and 4 for each number of oversampling layers m in ``--layers`` (coarse grid
H = 1/4 on the unit square; on the Hertz block the squares of side ``--hertz-coarse`` holding the fine
cells' centroids, ``problem.partition.centroid_coarse_cells``; the interface Newton method, Ω₁ being linear).
Writes a markdown report. Example (about 10 min on 2 cores):

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/analytic_benchmarks.py \
        --bar-sizes 8 16 32 64 --hertz-refinements 0.5 1 2 --out benchmarks/results/analytic.md

Sections:
1. The bar (ν = 0, E = 1, clamped at x = 0 only, top and bottom traction free, body force
   (±1, 0), wall at x = 1): pushing (full contact) and pulling (no contact). Errors against the
   exact solution (δ, ε → 0): e_u = ‖u_h − u‖/‖u‖, e_σ = ‖σ_h − σ‖/‖σ‖ (primal σ_h = σ(u_h)),
   e_F = |F_h − F|/|f₁|, F the contact force; rates between successive h.
2. The layered patch test (E = 1 | 10³ | 10 across γ, ν = 0, no load, traction-free top and
   bottom, a plane moved in by d₀): max-norm errors of σ_xx and of the force against the
   closed forms with the penalty (F = d₀/(C + δ) primal, d₀/C mixed), as a force–indentation
   curve in load steps (warm starts).
3. Plane-strain Hertz: a rigid cylinder (R = 5) pressed by d₀ = 1.2·10⁻³ into a block 80a × 40a
   (bottom clamped, sides traction free), F read off the solution: contact half-width error in
   contact-zone cells, peak pressure error, L² error of the pressure profile; "refinement r"
   refines the whole mesh (contact cells a/(20r)).
4. The Hertz cylinder pushed in load steps (``indentation.force_indentation``): the
   force–indentation curve, the Hertz errors at every step, and what the warm start saves.
5. (``--sections 5``) the Hertz errors over nine depths: their spread as the contact edge moves
   across a cell.
6. (``--sections 6``) P1 locking: the relative L² error of P1 for a divergence-free u = curl ψ on the
   clamped unit square (``fem.locking.p1_locking_error``) against ν and h; the primal methods warn
   from ν = ``fem.primal.P1_LOCKING_NU`` on.
"""

import argparse
import datetime
import sys
import time
from pathlib import Path

import numpy as np
import ufl
from common import write_report
from dolfinx import fem
from mpi4py import MPI

import fenics_contact  # noqa: F401  (dolfinx_solver first)
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.io import machine_description
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.analytic import (
    bar_model,
    bar_solution,
    hertz_errors,
    hertz_model,
    layered_model,
    layered_pressure,
)
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import mesh_extent, unit_square
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.meshes import hertz_block
from fenics_contact.problem.partition import centroid_coarse_cells

METHODS = ("primal monolithic", "Algorithm 1", "mixed monolithic", "Algorithm 2")
MULTISCALE = ("Algorithm 3", "Algorithm 4")
#: the multiscale methods iterate with the interface Newton method (Ω₁ is linear: one or two steps)
MS_ACCEL = "newton"


def _ms_options(options: IterationOptions) -> IterationOptions:
    return IterationOptions(tol=options.tol, accel=MS_ACCEL, max_iterations=options.max_iterations)


def _hertz_mesh(a: float, r: float, coarse: float | None = None):
    """The Hertz block; with ``coarse``, coarse cells = squares of that side holding the fine cells' centroids."""
    cm, spec = hertz_block(a, refinement=r)
    if coarse is not None:
        cells, _ = centroid_coarse_cells(cm.mesh, coarse)
        cm = cm._replace(coarse_cell=cells.astype(np.int32), H=coarse)
    return cm, spec


def _l2(expr, msh) -> float:
    form = fem.form(ufl.inner(expr, expr) * ufl.dx(domain=msh, metadata={"quadrature_degree": 6}))
    return float(np.sqrt(msh.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)))


def _rate(prev: float | None, cur: float) -> str:
    if prev is None or prev <= 0 or cur <= 0:
        return ""
    return f"{np.log2(prev / cur):.2f}"


def _solve(method: str, cm, model, options, layers: int = 3):
    """(σ as a UFL vector (xx, xy, yy), u, contact profile, iterations, time) of one method (``layers``: m of
    Algorithms 3 and 4)."""
    t0 = time.perf_counter()
    if method.startswith("primal") or method in ("Algorithm 1", "Algorithm 3"):
        problem = model.on(cm)
        fields = problem.fields
        delta = default_penalty(cm.h, problem.contact_modulus())  # as force_indentation
        if method == "Algorithm 1":
            res = solve_primal_hybrid(problem, delta=delta, options=options)
            u, profile, its = res.u, res.profile, res.iterations
        elif method == "Algorithm 3":
            res = solve_primal_ms_hybrid(
                problem, alpha="Emin", delta=delta, cem=CEMOptions(layers=layers), options=_ms_options(options)
            )
            u, profile, its = res.u, res.profile, res.iterations
        else:
            ref = solve_primal_monolithic(problem, delta=delta)
            u, profile, its = ref.u, ref.profile, ref.newton.steps
        s = stress(strain(u), fields.lmbda, fields.mu)
        return ufl.as_vector([s[0, 0], s[0, 1], s[1, 1]]), u, profile, its, time.perf_counter() - t0
    if method == "Algorithm 2":
        res = solve_mixed_hybrid(model.on(cm), options=options)
        return res.sigma, res.u, res.profile, res.iterations, time.perf_counter() - t0
    if method == "Algorithm 4":
        res = solve_mixed_ms_hybrid(model.on(cm), cem=MixedCEMOptions(layers=layers), options=_ms_options(options))
        return res.sigma, res.u, res.profile, res.iterations, time.perf_counter() - t0
    ref = solve_mixed_monolithic(model.on(cm))
    return ref.sigma, ref.u, ref.profile, ref.newton.steps, time.perf_counter() - t0


def _runs(methods, layers):
    """(method, label, m) for the fine methods and for Algorithms 3 and 4 with each m in ``layers``."""
    out = []
    for method in methods:
        if method in MULTISCALE:
            out += [(method, f"{method} (m = {m})", m) for m in layers]
        else:
            out.append((method, method, 3))
    return out


def bar_section(sizes: list[int], options, layers=(), ms_sizes=()) -> list[str]:
    lines = [
        "## 1. The bar (clamped at x = 0 only; top and bottom traction free)",
        "",
        "Algorithms 3 and 4: coarse grid H = 1/4 (3 × 4 coarse cells in Ω₁; m = 3 covers Ω₁).",
        "",
        "| method | case | 1/h | e_u | rate | e_σ | rate | e_F | iterations | time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for method, label, m in _runs(METHODS + MULTISCALE, layers):
        for f1, case in ((1.0, "push"), (-1.0, "pull")):
            prev_u = prev_s = None
            exact = bar_solution(f1)
            for n in ms_sizes if method in MULTISCALE else sizes:
                cm = unit_square(n, 4, clamped=("left",))
                sigma, u, profile, its, elapsed = _solve(method, cm, bar_model(f1), options, m)
                X = ufl.SpatialCoordinate(cm.mesh)
                s_ex = ufl.as_vector([exact.sigma_xx(X), 0.0, 0.0])
                u_ex = ufl.as_vector([exact.u_x(X), 0.0])
                e_u = _l2(u - u_ex, cm.mesh) / _l2(u_ex, cm.mesh)
                e_s = _l2(sigma - s_ex, cm.mesh) / _l2(s_ex, cm.mesh)
                e_F = abs(profile.force + exact.sigma_end) / abs(f1)
                lines.append(
                    f"| {label} | {case} | {n} | {e_u:.2e} | {_rate(prev_u, e_u)} | {e_s:.2e} | "
                    f"{_rate(prev_s, e_s)} | {e_F:.1e} | {its} | {elapsed:.2f} |"
                )
                prev_u, prev_s = e_u, e_s
                print(lines[-1], flush=True)
    return lines + [""]


def patch_section(n: int, options, layers=()) -> list[str]:
    bounds, moduli = [0.0, 6 / 16, 13 / 16, 1.0], [1.0, 1e3, 10.0]
    depths = [0.01, 0.02, 0.03]
    lines = [
        f"## 2. Layered patch test (E = {moduli}, layers at x = 6/16, 13/16, γ at x = 3/4; 1/h = {n})",
        "",
        "Force–indentation in load steps; errors against the closed forms with the penalty.",
        "",
        "| method | depth | force | max rel. force error | max |σ_xx + p|/p | iterations | time [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    names = {
        "primal monolithic": "primal-monolithic",
        "Algorithm 1": "primal",
        "mixed monolithic": "mixed-monolithic",
        "Algorithm 2": "mixed",
    }
    cm = unit_square(n, 4, clamped=("left",))
    for method in METHODS:
        iteration = {} if names[method].endswith("monolithic") else {"options": options}
        curve = force_indentation(
            layered_model(bounds, moduli, depth=0.0).on(cm), names[method], depths, direction=(-1.0, 0.0), **iteration
        )
        delta = default_penalty(cm.h, moduli[-1]) if "primal" in names[method] else 0.0
        for step in curve.steps:
            p = layered_pressure(bounds, moduli, step.depth, delta=delta)
            lines.append(
                f"| {method} | {step.depth:g} | {step.force:.10f} | {abs(step.force / p - 1):.1e} | "
                f"{np.max(np.abs(-step.profile.sigma_c / p - 1)):.1e} | {step.iterations} | "
                f"{step.time_s:.2f} |"
            )
            print(lines[-1], flush=True)
    # the multiscale methods: one solve per depth (coarse grid H = 1/4; m = 3 covers Ω₁)
    for method, label, m in _runs(MULTISCALE, layers):
        for d in depths:
            _, _, profile, its, elapsed = _solve(method, cm, layered_model(bounds, moduli, depth=d), options, m)
            delta = default_penalty(cm.h, moduli[-1]) if method == "Algorithm 3" else 0.0
            p = layered_pressure(bounds, moduli, d, delta=delta)
            lines.append(
                f"| {label} | {d:g} | {profile.force:.10f} | {abs(profile.force / p - 1):.1e} | "
                f"{np.max(np.abs(-profile.sigma_c / p - 1)):.1e} | {its} | {elapsed:.2f} |"
            )
            print(lines[-1], flush=True)
    return lines + [""]


def hertz_section(
    refinements: list[float], mixed_max: float, options, layers=(), ms_refinements=(), coarse: float = 0.5
) -> list[str]:
    a, R, E, nu, d0 = 0.05, 5.0, 1.0, 0.3, 1.2e-3
    lines = [
        "## 3. Plane-strain Hertz (R = 5, E = 1, ν = 0.3, d₀ = 1.2e-3, block 80a × 40a, a ≈ 0.053)",
        "",
        f"Algorithms 3 and 4: coarse cells = the squares of side {coarse:g} holding the fine cells' centroids.",
        "",
        "| method | r | cells | a/h | F | (a_h − a)/h | p_max/p₀ − 1 | L² error | rate | iterations | time [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for method, label, m in _runs(METHODS + MULTISCALE, layers):
        prev = None
        for r in ms_refinements if method in MULTISCALE else refinements:
            if "mixed" in method.lower() or method in ("Algorithm 2", "Algorithm 4"):
                if r > mixed_max:
                    continue
            cm, spec = _hertz_mesh(a, r, coarse if method in MULTISCALE else None)
            _, _, profile, its, elapsed = _solve(method, cm, hertz_model(radius=R, E=E, nu=nu, depth=d0), options, m)
            e = hertz_errors(profile, radius=R, E=E, nu=nu, h_contact=spec.h_contact)
            cells = cm.mesh.topology.index_map(2).size_local
            lines.append(
                f"| {label} | {r:g} | {cells} | {e.a / spec.h_contact:.1f} | {e.force:.5e} | "
                f"{e.half_width_cells:+.2f} | {e.peak_error:+.2%} | {e.l2_error:.2%} | "
                f"{_rate(prev, e.l2_error)} | {its} | {elapsed:.2f} |"
            )
            prev = e.l2_error
            print(lines[-1], flush=True)
    return lines + [""]


def indentation_section(refinement: float, steps: int, options) -> list[str]:
    """Hertz force–indentation in load steps (warm starts) against a cold start at the last depth."""
    a, R, E, nu = 0.05, 5.0, 1.0, 0.3
    depths = np.linspace(1.2e-3 / steps, 1.2e-3, steps)
    lines = [
        f"## 4. Hertz force–indentation in {steps} load steps (r = {refinement:g}; warm starts)",
        "",
        "The obstacle moves down by d; F is read off the contact; a, p₀ from F. Iterations: Newton "
        "steps (monolithic) or hybrid iterations; the last column is a cold start at the last depth.",
        "",
        "| method | d | F | a | p_max/p₀ − 1 | L² error | iterations | time [s] | cold start: iterations, time [s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    names = {
        "primal monolithic": "primal-monolithic",
        "Algorithm 1": "primal",
        "mixed monolithic": "mixed-monolithic",
        "Algorithm 2": "mixed",
    }
    cm, spec = hertz_block(a, refinement=refinement)
    base = hertz_model(radius=R, E=E, nu=nu, depth=0.0)
    for method in METHODS:
        iteration = {} if names[method].endswith("monolithic") else {"options": options}
        curve = force_indentation(base.on(cm), names[method], depths, direction=(0.0, -1.0), **iteration)
        cold = force_indentation(base.on(cm), names[method], depths[-1:], direction=(0.0, -1.0), **iteration)
        for k, step in enumerate(curve.steps):
            e = hertz_errors(step.profile, radius=R, E=E, nu=nu, h_contact=spec.h_contact)
            last = f"{cold.steps[0].iterations}, {cold.steps[0].time_s:.2f}" if k == len(curve.steps) - 1 else ""
            lines.append(
                f"| {method} | {step.depth:.3g} | {step.force:.5e} | {e.a:.4f} | {e.peak_error:+.2%} | "
                f"{e.l2_error:.2%} | {step.iterations} | {step.time_s:.2f} | {last} |"
            )
            print(lines[-1], flush=True)
    return lines + [""]


def edge_sweep_section(refinements: list[float], mixed_max: float, count: int = 9, nu: float = 0.3) -> list[str]:
    """Hertz errors over depths 1.1–1.3·10⁻³ at Poisson's ratio ``nu``: how much they depend on where the contact
    edge falls."""
    from fenics_contact.fem.mixed import default_epsilon
    from fenics_contact.fem.mixed_subproblem import MixedSubproblem
    from fenics_contact.fem.primal import PrimalSubproblem

    a, R, E = 0.05, 5.0, 1.0
    depths = np.linspace(1.1e-3, 1.3e-3, count)
    lines = [
        f"## 5. Hertz errors over {count} depths from 1.1 to 1.3·10⁻³ (the contact edge moves across a cell)"
        + (f", ν = {nu:g}" if nu != 0.3 else ""),
        "",
        "| method | r | a/h | (a_h − a)/h: min, max | p_max/p₀ − 1: min, max | L² error: min, max |",
        "|---|---|---|---|---|---|",
    ]
    for method in ("primal monolithic", "mixed monolithic"):
        for r in refinements:
            if method.startswith("mixed") and r > mixed_max:
                continue
            cm, spec = hertz_block(a, refinement=r)
            fields = material_fields(cm.mesh, hertz_model(radius=R, E=E, nu=nu, depth=depths[0]))
            if method.startswith("primal"):
                sub = PrimalSubproblem(
                    cm.mesh,
                    cm.facet_tags,
                    fields,
                    delta=default_penalty(cm.h, E),
                    alpha=None,
                    prefix="fc_bench_edge_p_",
                )
            else:
                sub = MixedSubproblem(
                    cm.mesh,
                    cm.facet_tags,
                    fields,
                    epsilon=default_epsilon(cm.h, E, length=mesh_extent(cm.mesh)),
                    beta=None,
                    prefix="fc_bench_edge_m_",
                )
            rows = []
            for d in depths:
                sub.set_obstacle(hertz_model(radius=R, E=E, nu=nu, depth=d).obstacle)
                sub.solve()
                e = hertz_errors(sub.contact_profile(), radius=R, E=E, nu=nu, h_contact=spec.h_contact)
                rows.append((e.a / spec.h_contact, e.half_width_cells, e.peak_error, e.l2_error))
            rows = np.array(rows)
            lines.append(
                f"| {method} | {r:g} | {rows[:, 0].min():.1f}–{rows[:, 0].max():.1f} | "
                f"{rows[:, 1].min():+.2f}, {rows[:, 1].max():+.2f} | {rows[:, 2].min():+.2%}, "
                f"{rows[:, 2].max():+.2%} | {rows[:, 3].min():.2%}, {rows[:, 3].max():.2%} |"
            )
            print(lines[-1], flush=True)
    return lines + [""]


def locking_section(sizes: list[int], nus=(0.3, 0.4, 0.45, 0.48, 0.49, 0.499, 0.4999)) -> list[str]:
    """P1 on u = curl ψ, clamped square: the L² error against ν and h (no contact)."""
    from fenics_contact.fem.locking import p1_locking_error

    lines = [
        "## 6. P1 locking: u = curl ψ on the clamped unit square (no contact)",
        "",
        "| ν | " + " | ".join(f"e_u h = 1/{n}" for n in sizes) + " | ratio to ν = 0.3 (finest h) |",
        "|---|" + "---|" * len(sizes) + "---|",
    ]
    base = None
    for nu in nus:
        e = [p1_locking_error(n, nu) for n in sizes]
        base = e[-1] if base is None else base
        lines.append(f"| {nu} | " + " | ".join(f"{x:.2e}" for x in e) + f" | {e[-1] / base:.1f} |")
        print(lines[-1], flush=True)
    return lines + [""]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bar-sizes", type=int, nargs="+", default=[8, 16, 32, 64])
    parser.add_argument("--patch-size", type=int, default=32)
    parser.add_argument("--hertz-refinements", type=float, nargs="+", default=[0.5, 1.0, 2.0])
    parser.add_argument("--hertz-mixed-max", type=float, default=2.0, help="largest refinement for the mixed methods")
    parser.add_argument(
        "--sections",
        type=int,
        nargs="+",
        default=[1, 2, 3, 4],
        help="which sections to run (5: the Hertz edge-position sweep, 6: P1 locking; not in the default)",
    )
    parser.add_argument("--indentation-steps", type=int, default=4, help="load steps of section 4")
    parser.add_argument("--indentation-refinement", type=float, default=1.0)
    parser.add_argument("--tol", type=float, default=1e-8, help="tolerance of Algorithms 1–4 (transmission residual)")
    parser.add_argument(
        "--layers",
        type=int,
        nargs="*",
        default=[1, 2, 3],
        help="oversampling layers m of Algorithms 3 and 4 (none: skip them)",
    )
    parser.add_argument("--ms-bar-sizes", type=int, nargs="+", default=[16, 32], help="1/h of the bar, Algorithms 3, 4")
    parser.add_argument(
        "--ms-hertz-refinements",
        type=float,
        nargs="+",
        default=[0.5, 1.0],
        help="Hertz refinements of Algorithms 3 and 4",
    )
    parser.add_argument("--hertz-nu", type=float, nargs="+", default=[0.3], help="Poisson's ratios of section 5")
    parser.add_argument("--hertz-coarse", type=float, default=0.5, help="coarse-cell side on the Hertz block")
    parser.add_argument("--locking-sizes", type=int, nargs="+", default=[16, 32, 64], help="1/h of section 6")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/analytic.md"))
    args = parser.parse_args(argv)
    options = IterationOptions(tol=args.tol)
    start = time.perf_counter()
    lines = [
        "# Analytic benchmarks (fine discretizations and the multiscale Algorithms 3 and 4)",
        "",
        f"{datetime.date.today()}; {machine_description()}",
        "",
        "Command: `" + " ".join(["python", *sys.argv]) + "`",
        "",
        f"Algorithms 1 and 2 run to the tolerance {args.tol:g} (Anderson update), Algorithms 3 and 4 to the "
        f"same with the interface Newton method; the penalties are the defaults δ = 1e-3·h/E_c, ε = 1e-3·(h/L)·E_c/L (L the body's size).",
        "",
    ]
    sections = {
        1: lambda: bar_section(args.bar_sizes, options, args.layers, args.ms_bar_sizes),
        2: lambda: patch_section(args.patch_size, options, args.layers),
        3: lambda: hertz_section(
            args.hertz_refinements,
            args.hertz_mixed_max,
            options,
            args.layers,
            args.ms_hertz_refinements,
            args.hertz_coarse,
        ),
        4: lambda: indentation_section(args.indentation_refinement, args.indentation_steps, options),
        5: lambda: [
            line
            for nu in args.hertz_nu
            for line in edge_sweep_section(args.hertz_refinements, args.hertz_mixed_max, nu=nu)
        ],
        6: lambda: locking_section(args.locking_sizes),
    }
    for number in args.sections:
        if number not in sections:
            parser.error(f"unknown section {number}; choose among 1 2 3 4 5 6")
        lines += sections[number]()
    lines.append(f"Total time {time.perf_counter() - start:.0f} s.")
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
