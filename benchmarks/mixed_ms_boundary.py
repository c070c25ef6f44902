"""Algorithm 4 with boundary conditions on Ω₁: errors against the fine mixed solutions per layer m.

Case A: model 2 (inclusions, contrast 10³) on the unit square, u_D = (0.01 sin 3y, 0.02 y²) on x = 0, a
traction t = (0.3 + x, −½) on the top (Gamma_N_top), the bottom traction free; errors against the
monolithic mixed solve (e_σ in the A-norm of the homogeneous part, the L² error of the glued stress, the
post-processed displacement, the contact force), for m in ``--layers``, with and without source correctors.
Case B: model 3 (channels through γ up to Γ_C, γ cutting inclusions, loads in Ω₁) with contrast ``--contrast``,
clamped at x = 0 only, t = (0.2, −½) on the top, the bottom free, against Algorithm 2 (L² stress difference,
contact force), and the same with top and bottom clamped (how much the free sides cost at small m).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/mixed_ms_boundary.py --out benchmarks/results/mixed_ms_boundary.md
"""

import argparse
import datetime
import sys
import time
from pathlib import Path

import numpy as np
from common import write_report

import fenics_contact  # noqa: F401  (dolfinx_solver first)
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.io import machine_description
from fenics_contact.multiscale.mixed import l2_stress_error, solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.problem import geometry, models
from fenics_contact.problem.boundary import BoundaryConditions


def _u_D(x: np.ndarray) -> np.ndarray:
    return np.stack([0.01 * np.sin(3.0 * x[1]), 0.02 * x[1] ** 2])


def _traction(x: np.ndarray) -> np.ndarray:
    return np.stack([0.3 + x[0], -0.5 * np.ones_like(x[0])])


def case_a(n: int, n_coarse: int, layers: list[int], options) -> list[str]:
    cm = geometry.unit_square(n, n_coarse, clamped=("left",), neumann={"top": "Gamma_N_top"})
    model = models.get_model(2).with_(
        boundary=BoundaryConditions(displacement=_u_D, tractions={"Gamma_N_top": _traction})
    )
    lines = [
        f"## A. Model 2, u_D on x = 0, traction on the top, bottom free (h = 1/{n}, H = 1/{n_coarse})",
        "",
        "| method | m | source correctors | e_σ (A) | e_σ (L²) | e_u (post) | force error | iterations | "
        "offline [s] | CPU [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    ref = solve_mixed_monolithic(model.on(cm))
    c = time.process_time()
    alg2 = solve_mixed_hybrid(model.on(cm), reference=ref, options=options)
    lines.append(
        f"| Algorithm 2 | | | {alg2.e_sigma:.2e} | {l2_stress_error(alg2.sigma, ref.sigma):.2e} | "
        f"{alg2.e_u:.2e} | {abs(alg2.profile.force / ref.profile.force - 1):.1e} | {alg2.iterations} | | "
        f"{time.process_time() - c:.1f} |"
    )
    print(lines[-1], flush=True)
    runs = [(m, True) for m in layers] + [(max(layers), False)]
    for m, sc in runs:
        c = time.process_time()
        res = solve_mixed_ms_hybrid(
            model.on(cm), cem=MixedCEMOptions(layers=m, source_correction=sc), reference=ref, options=options
        )
        lines.append(
            f"| Algorithm 4 | {m} | {'yes' if sc else 'no'} | {res.e_sigma:.2e} | {res.e_sigma_l2:.2e} | "
            f"{res.e_u_post:.2e} | {abs(res.profile.force / ref.profile.force - 1):.1e} | {res.iterations} | "
            f"{res.time_offline_s:.1f} | {time.process_time() - c:.1f} |"
        )
        print(lines[-1], flush=True)
    return lines + [""]


def case_b(n: int, n_coarse: int, layers: list[int], contrast: float, options) -> list[str]:
    lines = [
        f"## B. Model 3 (contrast {contrast:g}), traction on the top; against Algorithm 2 "
        f"(h = 1/{n}, H = 1/{n_coarse})",
        "",
        "| sides | m | L² stress difference | force difference | iterations | offline [s] | CPU [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for clamped, label in ((("left",), "bottom free"), (("left", "bottom"), "bottom clamped")):
        cm = geometry.unit_square(n, n_coarse, clamped=clamped, neumann={"top": "Gamma_N_top"})
        model = models.get_model(3, E_high=contrast).with_(
            boundary=BoundaryConditions(tractions={"Gamma_N_top": (0.2, -0.5)})
        )
        alg2 = solve_mixed_hybrid(model.on(cm), options=options)
        for m in layers:
            c = time.process_time()
            res = solve_mixed_ms_hybrid(model.on(cm), cem=MixedCEMOptions(layers=m), options=options)
            lines.append(
                f"| {label} | {m} | {l2_stress_error(res.sigma, alg2.sigma):.2e} | "
                f"{abs(res.profile.force / alg2.profile.force - 1):.1e} | {res.iterations} | "
                f"{res.time_offline_s:.1f} | {time.process_time() - c:.1f} |"
            )
            print(lines[-1], flush=True)
    return lines + [""]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--h", type=int, default=32, help="1/h")
    parser.add_argument("--H-a", type=int, default=8, help="1/H of case A")
    parser.add_argument("--H-b", type=int, default=4, help="1/H of case B")
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--layers-b", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--contrast", type=float, default=1e3)
    parser.add_argument("--tol", type=float, default=1e-10)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mixed_ms_boundary.md"))
    args = parser.parse_args(argv)
    options = IterationOptions(tol=args.tol, accel="newton")
    start = time.perf_counter()
    lines = [
        "# Algorithm 4 with boundary conditions on Ω₁",
        "",
        f"{datetime.date.today()}; {machine_description()}",
        "",
        "Command: `" + " ".join(["python", *sys.argv]) + "`",
        "",
        f"Interface Newton method to the transmission residual {args.tol:g}; CPU = process time (contended "
        "machine: wall times are not comparable).",
        "",
    ]
    lines += case_a(args.h, args.H_a, args.layers, options)
    lines += case_b(args.h, args.H_b, args.layers_b, args.contrast, options)
    lines.append(f"Total time {time.perf_counter() - start:.0f} s.")
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
