"""Algorithm 3 with a prescribed displacement and free sides on Ω₁: errors against Algorithm 1 per layer m.

Model 3 (high-modulus channels running through γ up to Γ_C, γ cutting inclusions, loads in Ω₁) at each contrast of
``--contrasts``; u_D = (0.01, 0.002) on x = 0 (its lifting u_g, source-corrected), the top and the bottom
traction free, the default penalty δ = 10⁻³ h / E_c (E_c the largest E in Ω₂) and α = Emin·h^-1/2.  For each m
the energy and L² errors of the glued Algorithm 3 solution against Algorithm 1's fixed point (which is the
monolithic solution) and the contact force difference; both run with the interface Newton to a transmission
residual of ``--tol``.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/multiscale_primal_boundary.py \\
        --out benchmarks/results/multiscale_primal_boundary.md
"""

import argparse
import datetime
import sys
import time
from pathlib import Path

from common import write_report

import fenics_contact  # noqa: F401  (dolfinx_solver first)
from fenics_contact.fem.primal import default_penalty
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.io import machine_description
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem import geometry, models
from fenics_contact.problem.boundary import BoundaryConditions

U_D = (0.01, 0.002)


def contrast_rows(n: int, n_coarse: int, contrast: float, layers: list[int], options) -> list[str]:
    cm = geometry.unit_square(n, n_coarse, clamped=("left",))  # top and bottom traction free
    model = models.get_model(3, E_high=contrast).with_(boundary=BoundaryConditions(displacement=U_D))
    delta = default_penalty(cm.h, contrast)  # the channels reach Γ_C: E_c = E_high
    fine = solve_primal_hybrid(model.on(cm), delta=delta, options=options)
    if not fine.converged:
        raise RuntimeError(f"Algorithm 1 did not converge at contrast {contrast:g}")
    rows = []
    for m in layers:
        c = time.process_time()
        res = solve_primal_ms_hybrid(
            model.on(cm),
            alpha="Emin",
            delta=delta,
            cem=CEMOptions(layers=m, nbasis=3),
            reference=fine.u,
            options=options,
        )
        rows.append(
            f"| {contrast:.0e} | {m} | {res.step.error_energy():.2e} | {res.e_u:.2e} | "
            f"{abs(res.profile.force / fine.profile.force - 1):.1e} | {res.converged} | "
            f"{res.transmission_residual:.1e} | {res.time_offline_s:.1f} | "
            f"{time.process_time() - c:.1f} |"
        )
        print(rows[-1], flush=True)
    return rows


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--h", type=int, default=32, help="1/h")
    parser.add_argument("--H", type=int, default=8, help="1/H")
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--contrasts", type=float, nargs="+", default=[1e3, 1e6])
    parser.add_argument("--tol", type=float, default=1e-10)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/multiscale_primal_boundary.md"))
    args = parser.parse_args(argv)
    options = IterationOptions(tol=args.tol, accel="newton")
    start = time.perf_counter()
    lines = [
        "# Algorithm 3 with u_D and free sides on Ω₁ (model 3)",
        "",
        f"{datetime.date.today()}; {machine_description()}",
        "",
        "Command: `" + " ".join(["python", *sys.argv]) + "`",
        "",
        f"h = 1/{args.h}, H = 1/{args.H}, l = 3, u_D = {U_D} on x = 0, top and bottom traction free; errors "
        "of the glued solution against Algorithm 1 (interface Newton, transmission residual "
        f"< {args.tol:g}); CPU = process time of the Algorithm 3 run.",
        "",
        "| contrast | m | energy error | L² error | force difference | converged | transmission residual "
        "| offline [s] | CPU [s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for contrast in args.contrasts:
        lines += contrast_rows(args.h, args.H, contrast, args.layers, options)
    lines += ["", f"Total time {time.perf_counter() - start:.0f} s."]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
