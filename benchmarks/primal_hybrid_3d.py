"""Algorithm 1 in 3D: which update reaches the fixed point fastest on the 3D channel model (one process).

The model is ``problem.models3d.channels_3d`` on ``channels_3d_mesh(n)`` (the unit cube, Γ_C the face x = 1,
Ω₂ the layer x > ¾, stiff channels through γ to Γ_C, the load in Ω₁, rollers on z = 0 and z = 1). For each
h and contrast it solves

* ``monolithic``: the primal monolithic penalized problem (the reference u_h);
* ``newton``: the interface Newton (condensed), its interface responses from the entries of J⁻¹ that MUMPS
  computes from the factors (``PrimalPart.responses`` on one process, the default);
* ``newton, back-solves``: the same with the responses by blocked multi-RHS back-solves
  (``AffinePart.responses``, this script only);
* ``anderson``: Anderson acceleration (depth 10) of the Robin iteration;
* ``newton, AMG Ω₁`` and ``anderson, AMG Ω₁``: Ω₁ solved by CG + AMG (``solver="amg"``, rtol ``--amg-rtol``,
  one AMG set-up for the whole solve): the matrix-free Newton–GMRES interface Newton (``hybrid.krylov_newton``;
  steps: Newton steps and in brackets the GMRES products, each one Ω₁ solve and one Ω₂ back-solve (the applications of
  T take Ω₁'s state as a combination of the products', corrected by a solve where it is off); its GMRES
  preconditioned by the band and AMG coarse model of Ω₁, ``hybrid.krylov_band``, the default) and Anderson
  (depth 10); ``newton, AMG Ω₁, unpreconditioned``: the Newton–GMRES without the preconditioner; ``--models L:C …``
  adds one Newton–GMRES row per preconditioner model (band of L layers, AMG coarse functions C levels down);

each to the transmission residual ``--tol``, and reports the times (offline: the subdomain factorizations
and the interface responses; online: the rest), the interface Newton's steps (and the local front
problems' iterations), the applications of T, the transmission residual and e_u against the monolithic
solution.  n_γ is the number of interface values, n_c of Γ_C unknowns: the dense interface matrices hold
O((n_γ + n_c)²) numbers.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 8 16 24 --contrast 1e3 1e6 \\
        --out benchmarks/results/primal_hybrid_3d.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 24 32 --contrast 1e3 1e6 \
        --variants "newton, AMG Ω₁" "anderson, AMG Ω₁" --out benchmarks/results/primal_hybrid_3d_amg.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 24 --contrast 1e3 1e6 --monolithic amg \
        --variants "newton, AMG Ω₁" "newton, AMG Ω₁, unpreconditioned" \
        --out benchmarks/results/primal_hybrid_3d_amg_preconditioned.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 --contrast 1e3 1e6 --variants \
        --models 3:0 6:0 0:1 2:1 3:1 2:2 --out benchmarks/results/primal_hybrid_3d_amg_models.md

``--windows W …`` instead compares the contact Newton's local front resolution on the contact surface
(``InterfaceNewtonOptions.front_window`` = W; 0: the plain semismooth Newton) at every h and contrast:

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 8 12 16 24 --contrast 1e6 \\
        --windows 0 3 8 --out benchmarks/results/primal_hybrid_3d_fronts.md
"""

import argparse
import shlex
import sys
import time
from pathlib import Path

import numpy as np

import fenics_contact as fc  # noqa: F401  (dolfinx_solver before petsc4py)
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.hybrid.response import AffinePart, PrimalPart
from fenics_contact.io import machine_description
from fenics_contact.methods import solve
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh

VARIANTS = (
    "newton",
    "newton, back-solves",
    "anderson",
    "newton, AMG Ω₁",
    "newton, AMG Ω₁, unpreconditioned",
    "anderson, AMG Ω₁",
)


def run(
    n: int,
    contrast: float,
    variants,
    tol: float,
    max_iterations: int,
    amg_rtol: float = 1e-10,
    monolithic: str = "auto",
    models=(),
):
    """The rows of one mesh and contrast, one by one; ``models``: (layers, coarse) pairs of the Newton–GMRES
    preconditioner's Ω₁ model, each run as a variant ``newton, AMG Ω₁ [layers:coarse]``."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n))
    start, cpu = time.perf_counter(), time.process_time()
    ref = solve(problem, "primal-monolithic", solver=monolithic)
    cpu = time.process_time() - cpu
    its = ref.krylov_iterations
    yield {
        "h": f"1/{n}",
        "contrast": f"{contrast:.0e}",
        "variant": f"monolithic ({ref.linear_solver})",
        "dofs": ref.dofs,
        "offline": None,
        "online": time.perf_counter() - start,
        "cpu": cpu,
        "steps": f"{ref.newton.steps} (Newton)" + (f", CG {min(its)}–{max(its)}" if its else ""),
        "T": None,
        "residual": None,
        "e_u": None,
    }
    entries = PrimalPart.responses
    runs = [(v, {"krylov_layers": None} if v.endswith("unpreconditioned") else {}) for v in variants]
    runs += [(f"newton, AMG Ω₁ [{m[0]}:{m[1]}]", {"krylov_layers": m[0], "krylov_coarse": m[1]}) for m in models]
    for variant, krylov in runs:
        accel = variant.split(",")[0]
        amg = "AMG Ω₁" in variant
        solver = LinearSolverOptions(kind="amg", rtol=amg_rtol) if amg else "direct"
        if variant.endswith("back-solves"):
            PrimalPart.responses = AffinePart.responses
        cpu = time.process_time()
        try:
            result = solve(
                problem,
                "primal",
                accel=accel,
                tol=tol,
                reference=ref.u,
                max_iterations=max_iterations,
                solver=solver,
                **krylov,
            )
        finally:
            PrimalPart.responses = entries
        cpu = time.process_time() - cpu
        history = result.history
        ch = history.contact_newton
        if accel == "newton" and amg:
            kry = result.step.krylov_interface()
            per = kry.products / max(history.newton_steps, 1)
            steps = f"{history.newton_steps} ({kry.products} products, {per:.1f} per step)"
            band = kry.preconditioner
            if band is not None:
                steps += f"; Ω₁ model {band.size} unknowns, {band.factorizations} factorizations"
        elif accel == "newton":
            steps = f"{history.newton_steps} ({ch.local_iterations} local)"
        else:
            steps = f"{history.iterations}"
        if amg:
            cg = result.step.sub[0].solver.iterations
            steps += f"; {len(cg)} Ω₁ solves, CG median {int(np.median(cg))}, {sum(cg)} in all"
        yield (
            {
                "h": f"1/{n}",
                "contrast": f"{contrast:.0e}",
                "variant": variant,
                "dofs": f"{result.dofs['omega1']} + {result.dofs['omega2']}, n_γ {result.dofs['interface']}, "
                f"n_c {result.profile.points.shape[0]}",
                "offline": result.time_offline_s,
                "online": result.time_online_s,
                "cpu": cpu,
                "steps": steps,
                "T": history.iterations,
                "residual": history.transmission_residual,
                "e_u": result.e_u,
                "converged": result.converged,
            }
        )
        result.step.reset()


def windows(n: int, contrast: float, widths, tol: float):
    """The interface Newton with each front window on one mesh and contrast: its rows, one by one."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n))
    ref = solve(problem, "primal-monolithic")
    step = None
    for width in widths:
        result = solve(problem, "primal", accel="newton", front_window=width, tol=tol, reference=ref.u, step=step)
        step = result.step
        ch = result.history.contact_newton
        yield {
            "h": f"1/{n}",
            "contrast": f"{contrast:.0e}",
            "window": width,
            "n_c": result.profile.points.shape[0],
            "monolithic": ref.newton.steps,
            "steps": result.history.newton_steps,
            "sizes": " ".join(str(k) for k in ch.active_sizes),
            "local": f"{sum(w for w, _, _ in ch.local)} / {ch.local_iterations} / "
            f"{max([m for _, _, m in ch.local] or [0])}",
            "online": result.time_online_s,
            "e_u": result.e_u,
        }
        step.reset()


def _cell(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.2f}" if value >= 0.01 else f"{value:.1e}"
    return str(value)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[8, 16, 24], help="1/h of the cube meshes")
    parser.add_argument("--contrast", type=float, nargs="+", default=[1e3, 1e6])
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--tol", type=float, default=1e-8, help="transmission residual to reach")
    parser.add_argument("--max-iterations", type=int, default=1000, help="Anderson's cap")
    parser.add_argument("--amg-rtol", type=float, default=1e-10, help="the AMG Ω₁'s CG tolerance")
    parser.add_argument(
        "--monolithic", default="auto", choices=("auto", "direct", "amg"), help="the monolithic solve's linear solver"
    )
    parser.add_argument(
        "--models",
        nargs="+",
        default=[],
        metavar="LAYERS:COARSE",
        help="Newton–GMRES preconditioner models to compare (band layers : AMG coarse depth, 0 none)",
    )
    parser.add_argument("--windows", type=int, nargs="+", default=None, help="compare these front windows")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    models = [tuple(int(k) for k in m.split(":")) for m in args.models]
    if args.windows is not None:
        return _windows_table(args)
    head = ["h", "contrast", "variant", "DOFs", "offline [s]", "online [s]", "CPU [s]", "steps", "applications of T",
            "transmission residual", "e_u", "converged"]  # fmt: skip
    keys = [
        "h",
        "contrast",
        "variant",
        "dofs",
        "offline",
        "online",
        "cpu",
        "steps",
        "T",
        "residual",
        "e_u",
        "converged",
    ]
    lines = [
        "# Algorithm 1 in 3D: interface Newton and Anderson on the 3D channel model",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py {shlex.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        f"Every hybrid solve stops at the transmission residual {args.tol:g} (Anderson at most "
        f"{args.max_iterations} iterations); steps: the interface Newton's (contact Newton steps and "
        "corrections; in brackets the iterations of its local front problems) or Anderson's iterations; "
        "with an AMG Ω₁ (CG rtol " + f"{args.amg_rtol:g}" + ") the Newton–GMRES steps and its products (each one "
        "Ω₁ solve and one Ω₂ back-solve), the size of the preconditioner's Ω₁ model and its factorizations, the Ω₁ "
        "solves in all (the products, and the solves correcting a combination of their states: the first and the "
        "certified pair among them), their median CG iterations and their sum; "
        "e_u: relative L² distance to the monolithic solution; times on a machine shared with other jobs "
        "(CPU: the process's CPU time of the whole solve, offline and online, which the sharing does not inflate).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for n in args.h:
        for contrast in args.contrast:
            for row in run(
                n, contrast, args.variants, args.tol, args.max_iterations, args.amg_rtol, args.monolithic, models
            ):
                lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
                print(lines[-1], flush=True)
                if args.out is not None:
                    args.out.write_text("\n".join(lines) + "\n")


def _windows_table(args) -> None:
    head = ["h", "contrast", "front window", "n_c", "monolithic Newton steps", "interface Newton steps",
            "active-set sizes", "local problems / iterations / largest window", "online [s]", "e_u"]  # fmt: skip
    keys = ["h", "contrast", "window", "n_c", "monolithic", "steps", "sizes", "local", "online", "e_u"]
    lines = [
        "# Algorithm 1 in 3D: the contact Newton's local front resolution on the contact surface",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py {shlex.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        "The 3D channel model; the interface Newton (condensed) with the front window W (0: the plain "
        "semismooth Newton on the Γ_C unknowns), the same step reused; local: the front problems solved, "
        "their semismooth iterations and the largest window (unknowns).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for n in args.h:
        for contrast in args.contrast:
            for row in windows(n, contrast, args.windows, args.tol):
                lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
                print(lines[-1], flush=True)
                if args.out is not None:
                    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
