"""Algorithm 3 for two bodies: the energy error of the multiscale pair (a CEM-GMsFEM space in each bulk) against
Algorithm 1 (the fine solution) by oversampling layers, on the layered pair of the tests (strata of contrast 1e3
with inclusions, non-matching meshes; ``tests/multiscale/test_pair_multiscale.py``), frictionless; with
``--friction MU`` along a press-then-shear path with Coulomb friction (``tests/multiscale/
test_pair_multiscale_friction.py``), each method from its own last step's state: per step and layers the energy
error, Q/N (Σ w|t| over the normal force) and the slipping nodes, and Algorithm 3 with patches covering each bulk
and every local mode (``nbasis="all"``: the fine space) against Algorithm 1.

    python benchmarks/two_body_multiscale.py --n 16 --H 0.125 --layers 1 2 3 4 \
        --out benchmarks/results/two_body_multiscale.md
    python benchmarks/two_body_multiscale.py --n 16 --H 0.125 --layers 1 2 3 4 --friction 0.3 \
        --out benchmarks/results/two_body_multiscale.md --append
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).parent))

from common import friction_ratio, strata_pair, table_row, write_report  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.fem.two_body import stiffness  # noqa: E402
from fenics_contact.multiscale.cem import CEMOptions  # noqa: E402

CONTRAST = 1e3
#: Poisson ratios of the lower and the upper block
NU = (0.3, 0.2)
#: the frictional path: the upper block's top pressed, then moved along the fault past sliding
PATH = ((0.0, -0.005), (0.0, -0.01), (0.004, -0.01), (0.01, -0.01), (0.02, -0.01))
#: oversampling layers of the all-modes run: patches covering each bulk
EVERYWHERE = 50


def _problem(m, top, friction=None) -> fc.TwoBodyProblem:
    return strata_pair(m, top, friction, contrast=CONTRAST, nu=NU)


def _energy(problem, u, u0) -> float:
    K = stiffness(problem, u0.function_space)
    d = u.x.array - u0.x.array
    return float(np.sqrt((d @ (K @ d)) / (u0.x.array @ (K @ u0.x.array))))


def frictionless(m, args) -> list[str]:
    """The energy error by layers under the pressed top (0, −0.005)."""
    problem = _problem(m, (0.0, -0.005))
    fine = fc.solve(problem, "primal", tol=1e-11)
    lines = [
        f"# Algorithm 3 for two bodies: energy error by oversampling layers (n = {args.n}, H = {args.H})",
        "",
        "| layers | evaluations of T | energy error vs Algorithm 1 | factor | force balance | time (s) |",
        "|---|---|---|---|---|---|",
    ]
    previous = None
    for layers in args.layers:
        result = fc.solve(problem, "primal-ms", H=args.H, cem=CEMOptions(layers=layers), tol=1e-10)
        error = _energy(problem, result.u, fine.u)
        factor = f"{previous / error:.1f}" if previous else ""
        lines.append(
            table_row(
                str(layers),
                str(result.iterations),
                f"{error:.2e}",
                factor,
                f"{result.force_balance():.1e}",
                f"{result.time_s:.2f}",
            )
        )
        previous = error
    return lines


def frictional(m, args) -> list[str]:
    """Per step of ``PATH``: the energy error by layers, Q/N, the slip nodes; the all-modes distance."""
    law = fc.Friction("coulomb", mu=args.friction)
    runs = [CEMOptions(layers=k) for k in args.layers] + [CEMOptions(layers=EVERYWHERE, nbasis=None)]
    states = [None] * (1 + len(runs))
    head = " | ".join(f"m = {k}" for k in args.layers)
    lines = [
        f"## Coulomb friction μ = {args.friction:g} along a press-then-shear path (n = {args.n}, H = {args.H})",
        "",
        "Energy error of Algorithm 3 against Algorithm 1 by oversampling layers m (the rigid motions per coarse "
        f'cell), each from its own last step\'s state; "all modes": m = {EVERYWHERE} (patches covering each bulk), '
        'nbasis="all", its relative l² distance from Algorithm 1; Q/N and the slip nodes of the largest m, the '
        "force balance the largest over the runs.",
        "",
        f"| top (x, y) | {head} | all modes | Q/N | slip / contact nodes | force balance | T evaluations |",
        "|---|" + "---|" * len(args.layers) + "---|---|---|---|---|",
    ]
    for top in PATH:
        problem = _problem(m, top, law)
        fine = fc.solve(problem, "primal", state=states[0], tol=1e-11)
        results = [
            fc.solve(problem, "primal-ms", H=args.H, cem=cem, state=s, tol=1e-10 if cem.nbasis else 1e-11)
            for cem, s in zip(runs, states[1:], strict=True)
        ]
        states = [fine.state, *(r.state for r in results)]
        errors = " | ".join(f"{_energy(problem, r.u, fine.u):.2e}" for r in results[:-1])
        u0 = fine.u.x.array
        same = np.linalg.norm(results[-1].u.x.array - u0) / np.linalg.norm(u0)
        f = results[-2].friction
        balance = max(r.force_balance() for r in results)
        lines.append(
            table_row(
                f"({top[0]:g}, {top[1]:g})",
                errors,
                f"{same:.1e}",
                f"{friction_ratio(f):.6f}",
                f"{int(f.slip.sum())} / {int((f.pressure > 0).sum())}",
                f"{balance:.1e}",
                str(max(r.iterations for r in results)),
            )
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=16, help="cells along the lower block's contact face")
    parser.add_argument("--H", type=float, default=0.125, help="coarse cell size of both bulks")
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--friction", type=float, default=None, help="μ: the Coulomb path instead")
    parser.add_argument("--out", default="benchmarks/results/two_body_multiscale.md")
    parser.add_argument("--append", action="store_true", help="add the table to --out instead of replacing it")
    args = parser.parse_args()
    m = fc.two_blocks(args.n, args.n + 4, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    lines = frictionless(m, args) if args.friction is None else frictional(m, args)
    if args.append and Path(args.out).is_file():
        lines = [*Path(args.out).read_text().splitlines(), "", *lines]
    write_report(args.out, lines, MPI.COMM_SELF)


if __name__ == "__main__":
    main()
