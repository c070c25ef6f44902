"""Algorithm 3 in 3D: the energy error of the CEM-GMsFEM/FEM hybrid against the fine solution per oversampling layer.

The model is ``problem.models3d.channels_3d`` (contrast ``--contrast``) on ``channels_3d_mesh(n, strip=H, H=H)``:
the unit cube of tetrahedra, h = 1/n, Ω₂ the layer x > 1 − H one coarse cell wide, Ω₁ covered by cubes of
side H, stiff channels through γ to Γ_C, the load in Ω₁ (source-corrected), rollers on z = 0 and z = 1.  For
each h, H and number of local modes l it solves the primal monolithic problem (the reference u_h) and
Algorithm 3 with m = ``--layers`` oversampling layers (the interface Newton to the transmission residual
``--tol``), and reports

* offline [s]: assembly, the local eigenproblems, the patch problems (bases, Robin and source correctors) and
  the coarse operators (Gram matrices, the coarse factorization; the breakdown: eigen / patches / coarse);
* online [s] and per step [s]: the interface Newton's time and that time per Newton step;
* the interface Newton steps, the transmission residual (certificate);
* e_E: the relative energy error Σ_i a_i(u_h − u, u_h − u) / Σ_i a_i(u_h, u_h), ½-power, and its ratio to the
  previous layer's; e_u: the relative L² error.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/multiscale_primal_3d.py --h 16 --H 8 --layers 1 2 3 \\
        --out benchmarks/results/multiscale_primal_3d.md
"""

import argparse
import sys
import time
from pathlib import Path

import fenics_contact as fc  # noqa: F401  (dolfinx_solver before petsc4py)
from fenics_contact.io import machine_description
from fenics_contact.methods import solve
from fenics_contact.multiscale.cem.options import RIGID_MOTIONS
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh


def run(n: int, n_coarse: int, contrast: float, nbasis, layers, tol: float):
    """The rows of one mesh, coarse grid, contrast and l: the layers one by one."""
    H = 1.0 / n_coarse
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n, strip=H, H=H))
    start = time.perf_counter()
    ref = solve(problem, "primal-monolithic")
    t_ref = time.perf_counter() - start
    previous = None
    for m in layers:
        result = solve(problem, "primal-ms", layers=m, nbasis=nbasis, tol=tol, reference=ref.u)
        step = result.step
        times = step.offline_times
        e_energy = step.error_energy()
        steps = result.history.newton_steps
        yield {
            "h": f"1/{n}",
            "H": f"1/{n_coarse}",
            "contrast": f"{contrast:.0e}",
            "l": step.cem.nbasis,
            "m": m,
            "dofs": f"{result.dofs['omega1']} → {result.dofs['omega1_ms']} + {result.dofs['omega2']}",
            "monolithic": t_ref,
            "offline": result.time_offline_s,
            "breakdown": f"{times['eigen']:.1f} / {times['patches']:.1f} / {times['coarse']:.1f}",
            "online": result.time_online_s,
            "per_step": result.time_online_s / max(steps, 1),
            "steps": steps,
            "residual": result.history.transmission_residual,
            "e_energy": f"{e_energy:.2e}",
            "ratio": f"{previous / e_energy:.1f}" if previous is not None and e_energy > 0 else None,
            "e_u": f"{result.e_u:.2e}",
            "converged": result.converged,
        }
        previous = e_energy


def _cell(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.2f}" if 0.01 <= value < 1e4 else f"{value:.1e}"
    return str(value)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[16], help="1/h of the cube meshes")
    parser.add_argument("--H", type=int, nargs="+", default=[8], help="1/H of the coarse cubes (and the strip)")
    parser.add_argument("--contrast", type=float, nargs="+", default=[1e3])
    parser.add_argument(
        "--nbasis",
        nargs="+",
        default=[RIGID_MOTIONS],
        help="local modes l per coarse cell (rigid: the 6 rigid motions)",
    )
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3], help="oversampling layers m")
    parser.add_argument("--tol", type=float, default=1e-9, help="transmission residual to reach")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    head = ["h", "H", "contrast", "l", "m", "DOFs Ω₁ → V_ms + Ω₂", "monolithic [s]", "offline [s]",
            "eigen / patches / coarse [s]", "online [s]", "per Newton step [s]", "Newton steps", "transmission residual",
            "e_E", "e_E ratio to m − 1", "e_u", "converged"]  # fmt: skip
    keys = ["h", "H", "contrast", "l", "m", "dofs", "monolithic", "offline", "breakdown", "online", "per_step",
            "steps", "residual", "e_energy", "ratio", "e_u", "converged"]  # fmt: skip
    lines = [
        "# Algorithm 3 in 3D: the energy error per oversampling layer on the 3D channel model",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/multiscale_primal_3d.py {' '.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        f"Every solve is the interface Newton to the transmission residual {args.tol:g}; e_E, e_u: relative "
        "energy and L² distance to the primal monolithic solution u_h; times on one process of a machine shared "
        "with other jobs.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for n in args.h:
        for n_coarse in args.H:
            for contrast in args.contrast:
                for nbasis in args.nbasis:
                    l_value = nbasis if nbasis == RIGID_MOTIONS else int(nbasis)
                    for row in run(n, n_coarse, contrast, l_value, args.layers, args.tol):
                        lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
                        print(lines[-1], flush=True)
                        if args.out is not None:
                            args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
