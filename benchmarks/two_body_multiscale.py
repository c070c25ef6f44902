"""Algorithm 3 for two bodies: the energy error of the multiscale pair (a CEM-GMsFEM space in each bulk) against
Algorithm 1 (the fine solution) by oversampling layers, on the layered pair of the tests (strata of contrast 1e3
with inclusions, non-matching meshes; ``tests/multiscale/test_pair_multiscale.py``).

    python benchmarks/two_body_multiscale.py --n 16 --H 0.125 --layers 1 2 3 4 \
        --out benchmarks/results/two_body_multiscale.md
"""

import argparse
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).parent))

from common import write_report  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.fem.two_body import stiffness  # noqa: E402
from fenics_contact.multiscale.cem import CEMOptions  # noqa: E402
from fenics_contact.problem.pair_meshes import fault_strata

T = fc.PairTag
CONTRAST = 1e3


_lower, _upper = fault_strata(CONTRAST)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=16, help="cells along the lower block's contact face")
    parser.add_argument("--H", type=float, default=0.125, help="coarse cell size of both bulks")
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--out", default="benchmarks/results/two_body_multiscale.md")
    args = parser.parse_args()
    m = fc.two_blocks(args.n, args.n + 4, heights=(0.5, 0.4), comm=MPI.COMM_SELF)
    problem = fc.TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(fc.Body(T.LOWER, _lower, 0.3), fc.Body(T.UPPER, _upper, 0.2)),
        pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, (0.0, -0.005))),
    )
    fine = fc.solve(problem, "primal", tol=1e-11)
    u0 = fine.u.x.array
    K = stiffness(problem, fine.u.function_space)
    lines = [
        f"# Algorithm 3 for two bodies: energy error by oversampling layers (n = {args.n}, H = {args.H})",
        "",
        "| layers | evaluations of T | energy error vs Algorithm 1 | factor | force balance | time (s) |",
        "|---|---|---|---|---|---|",
    ]
    previous = None
    for layers in args.layers:
        result = fc.solve(problem, "primal-ms", H=args.H, cem=CEMOptions(layers=layers), tol=1e-10)
        d = result.u.x.array - u0
        error = float(np.sqrt((d @ (K @ d)) / (u0 @ (K @ u0))))
        factor = f"{previous / error:.1f}" if previous else ""
        lines.append(
            f"| {layers} | {result.iterations} | {error:.2e} | {factor} | {result.force_balance():.1e} | "
            f"{result.time_s:.2f} |"
        )
        print(lines[-1], flush=True)
        previous = error
    write_report(args.out, lines, MPI.COMM_SELF)


if __name__ == "__main__":
    main()
