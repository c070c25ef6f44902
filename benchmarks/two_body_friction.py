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

from common import write_report  # noqa: E402

import fenics_contact as fc  # noqa: E402
from fenics_contact.problem.pair_meshes import fault_strata

T = fc.PairTag
PRESS = [(0.0, -0.005), (0.0, -0.01)]
SHEAR = [(s, -0.01) for s in (0.004, 0.008, 0.01, 0.011, 0.012, 0.014, 0.02)]


def strata(contrast: float):
    """E of the lower and the upper block (``pair_meshes.fault_strata``)."""
    return fault_strata(contrast)


def path(n: int, contrast: float, law: fc.Friction) -> list[str]:
    """The table rows of one path."""
    m = fc.two_blocks(n, int(1.3 * n) + 1, heights=(0.5, 0.4))
    lower, upper = strata(contrast)
    states = [None, None]
    rows = []
    for top in PRESS + SHEAR:
        problem = fc.TwoBodyProblem(
            m.mesh,
            m.cell_tags,
            m.facet_tags,
            bodies=(fc.Body(T.LOWER, lower, 0.3), fc.Body(T.UPPER, upper, 0.25)),
            pair=fc.ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=law),
            supports=(fc.Support(T.LOWER_BOTTOM), fc.Support(T.UPPER_TOP, top)),
        )
        t0 = time.perf_counter()
        mono = fc.solve(problem, "primal-monolithic", state=states[0])
        t1 = time.perf_counter()
        alg1 = fc.solve(problem, "primal", state=states[1])
        t2 = time.perf_counter()
        states = [mono.state, alg1.state]
        f = mono.friction
        u = mono.u.x.array
        e_u = np.linalg.norm(alg1.u.x.array - u) / np.linalg.norm(u)
        ratio = float(np.sum(f.weights * np.linalg.norm(f.traction, axis=1)) / f.normal_force)
        rows.append(
            f"| {n} | {contrast:g} | {law.name} | {top[0]:g} | {f.normal_force:.6g} | {f.tangential_force[0]:.6g} | "
            f"{ratio:.10f} | {np.count_nonzero(f.stick)} | {np.count_nonzero(f.slip)} | {mono.dissipation:.3e} | "
            f"{mono.force_balance():.1e} | {mono.newton.steps} | {alg1.iterations} | {e_u:.1e} | {t1 - t0:.2f} | "
            f"{t2 - t1:.2f} |"
        )
        print(rows[-1], flush=True)
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
