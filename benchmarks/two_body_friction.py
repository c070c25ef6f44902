"""Friction between two deformable bodies: a layered pair pressed, then sheared past sliding, solved along the
path by the monolithic frictional Newton and by Algorithm 1 (a strip on each side, interface Newton).

Per load step: the normal and tangential force, the stick and slip nodes, the dissipation, the Newton steps, the
evaluations of T and Algorithm 1's distance from the monolithic solution.

    python benchmarks/two_body_friction.py --sizes 32 64 --contrast 1e3 1e6 --out benchmarks/results/two_body_friction.md
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from common import friction_ratio, strata_pair, table_row, write_report  # noqa: E402

import fenics_contact as fc  # noqa: E402

PRESS = [(0.0, -0.005), (0.0, -0.01)]
SHEAR = [(s, -0.01) for s in (0.004, 0.008, 0.01, 0.011, 0.012, 0.014, 0.02)]
#: Poisson ratios of the lower and the upper block
NU = (0.3, 0.25)


def path(n: int, contrast: float, law: fc.Friction) -> list[str]:
    """The table rows of one path."""
    m = fc.two_blocks(n, int(1.3 * n) + 1, heights=(0.5, 0.4))
    states = [None, None]
    rows = []
    for top in PRESS + SHEAR:
        problem = strata_pair(m, top, law, contrast=contrast, nu=NU)
        t0 = time.perf_counter()
        mono = fc.solve(problem, "primal-monolithic", state=states[0])
        t1 = time.perf_counter()
        alg1 = fc.solve(problem, "primal", state=states[1])
        t2 = time.perf_counter()
        states = [mono.state, alg1.state]
        f = mono.friction
        u = mono.u.x.array
        e_u = np.linalg.norm(alg1.u.x.array - u) / np.linalg.norm(u)
        rows.append(
            table_row(
                str(n),
                f"{contrast:g}",
                law.name,
                f"{top[0]:g}",
                f"{f.normal_force:.6g}",
                f"{f.tangential_force[0]:.6g}",
                f"{friction_ratio(f):.10f}",
                str(np.count_nonzero(f.stick)),
                str(np.count_nonzero(f.slip)),
                f"{mono.dissipation:.3e}",
                f"{mono.force_balance():.1e}",
                str(mono.newton.steps),
                str(alg1.iterations),
                f"{e_u:.1e}",
                f"{t1 - t0:.2f}",
                f"{t2 - t1:.2f}",
            )
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[32, 64], help="lower-block cells along the fault")
    parser.add_argument("--contrast", type=float, nargs="+", default=[1e3, 1e6])
    parser.add_argument("--mu", type=float, default=0.4)
    parser.add_argument("--threshold", type=float, default=0.005)
    parser.add_argument("--out", default="benchmarks/results/two_body_friction.md")
    args = parser.parse_args()
    lines = [
        "# Friction between two bodies: a layered pair sheared past sliding",
        "",
        f"`python benchmarks/two_body_friction.py --sizes {' '.join(map(str, args.sizes))} --contrast "
        f"{' '.join(f'{c:g}' for c in args.contrast)}`",
        "",
        "Lower block (0, 1) × (−½, 0), n cells along the fault, strata of E = contrast and 1 with a stiff disc, "
        "clamped at its bottom; upper block (0, 1) × (0, 0.4), 1.3n + 1 cells along the fault (non-matching), "
        "strata the other way with a soft disc; its top pressed by 0.005, 0.01, then moved along x by the shear "
        f"s at u_y = −0.01. Coulomb μ = {args.mu:g}, Tresca s = {args.threshold:g}. Each step from the previous "
        "one's state. ratio: Σ w|t| / Σ w p (μ once every node slips; Tresca: s |Γ_C| / normal force). "
        "T: Algorithm 1's evaluations of T (interface Newton, strips of 2 layers); e_u: ‖u₁ − u_mono‖/‖u_mono‖.",
        "",
        "| n | contrast | law | shear | normal force | tangential force | ratio | stick | slip | dissipation | "
        "balance | Newton | T | e_u | monolithic [s] | Algorithm 1 [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for n in args.sizes:
        for contrast in args.contrast:
            for law in (fc.Friction("coulomb", mu=args.mu), fc.Friction("tresca", threshold=args.threshold)):
                lines += path(n, contrast, law)
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
