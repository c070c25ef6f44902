"""Algorithm 1 study: Theorem 3.1 check and iterations against α and the update.

Writes a markdown report (tables + the machine) to --out. Example:

    .venv/bin/python benchmarks/primal_hybrid_study.py --sizes 64 128 --out benchmarks/results/primal_hybrid.md

Table 1: Algorithm 1 (α = E·h^-1/2, Anderson) to tol 1e-10 against the monolithic penalized
solve: iterations, e_u, times, DOFs. Table 2: iterations to the 1e-6 rule for
α ∈ {1, h^-1/2, E, E·h^-1/2} and update ∈ {none (the paper's), anderson}, with the
true error at stop. Plain runs are capped (--cap); capped runs say so.
"""

import argparse
import datetime
import time
from pathlib import Path

import fenics_contact  # noqa: F401
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.io import machine_description
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model


def setup(n: int, n_coarse: int, number: int):
    t0 = time.perf_counter()
    cm = unit_square(n, n_coarse)
    model = get_model(number)
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    return cm, model, delta, ref, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", type=int, nargs="+", default=[64, 128], help="1/h values")
    parser.add_argument(
        "--configs",
        nargs="+",
        default=["1:16", "2:16", "1:4"],
        help="model:1/H pairs; 1:4 puts γ across the channels of model 1",
    )
    parser.add_argument("--alphas", nargs="+", default=["1", "h^-1/2", "E", "E*h^-1/2"])
    parser.add_argument("--cap", type=int, default=20000, help="iteration cap of the plain update")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()

    lines = [
        "# Algorithm 1 (primal hybrid) study",
        "",
        f"Machine: {machine_description()}. Date: {datetime.date.today()}. "
        f"Command: `python benchmarks/primal_hybrid_study.py --sizes {' '.join(map(str, args.sizes))} "
        f"--configs {' '.join(args.configs)} --cap {args.cap}`. δ = 1e-3·h, test models of "
        "`fenics_contact.problem.models`. With 1/H = 16 the interface γ (x = 15/16) lies in the homogeneous E = 1 "
        "region, so α = E equals α = 1 there; with model 1 and 1/H = 4, γ (x = 3/4) crosses the "
        "10³-modulus channels (and Ω₂ is heterogeneous).",
        "",
        "## Theorem 3.1: Algorithm 1 to tol 1e-10 equals the monolithic penalized solution",
        "",
        "| model | 1/H | 1/h | DOFs Ω₁ / Ω₂ / γ | monolithic Newton steps | monolithic time [s] | iterations | "
        "e_u | offline [s] | online [s] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    study = [
        "",
        "## Iterations to the 1e-6 relative-change rule against α and the update",
        "",
        "e_u is the true relative L² error of the final iterate against the monolithic solve.",
        "",
        "| model | 1/H | 1/h | α | update | iterations | converged | e_u at stop | online [s] |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for config in args.configs:
        number, n_coarse = (int(v) for v in config.split(":"))
        for n in args.sizes:
            cm, model, delta, ref, t_ref = setup(n, n_coarse, number)
            res = solve_primal_hybrid(
                model.on(cm),
                alpha="E*h^-1/2",
                delta=delta,
                reference=ref.u,
                options=IterationOptions(tol=1e-10, accel="anderson"),
            )
            d = res.dofs
            lines.append(
                f"| {number} | {n_coarse} | {n} | {d['omega1']} / {d['omega2']} / {d['interface']} | {ref.newton.steps} | "
                f"{ref.time_s:.2f} | {res.iterations} | {res.e_u:.1e} | {res.time_offline_s:.2f} | "
                f"{res.time_online_s:.2f} |"
            )
            print(lines[-1], flush=True)
            for alpha in args.alphas:
                for accel in ("none", "anderson"):
                    cap = args.cap if accel == "none" else 5000
                    r = solve_primal_hybrid(
                        model.on(cm),
                        alpha=alpha,
                        delta=delta,
                        reference=ref.u,
                        options=IterationOptions(tol=1e-6, accel=accel, max_iterations=cap),
                    )
                    its = f"{r.iterations}" if r.converged else f"> {r.iterations} (cap)"
                    study.append(
                        f"| {number} | {n_coarse} | {n} | {alpha} | {accel} | {its} | {r.converged} | "
                        f"{r.e_u:.1e} | {r.time_online_s:.1f} |"
                    )
                    print(study[-1], flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines + study) + "\n")
    print(f"written {args.out}")


if __name__ == "__main__":
    main()
