"""The ends of Γ_C next to a traction-free side in the mixed (Arnold–Winther) methods.

Two tables.  The Hertz block (half-space-like, ``--half-space`` of ``friction.py``) pressed by 1.7e-4, frictionless
and Coulomb μ = 0.3: σ_c, the pressure (−σ_c)⁺, the gap at the end nodes x = ±3a of Γ_C (in line with the free
top, where σ_c = 0 identically) and the largest pressure beyond the Hertz zone (a + one cell), with the primal
method's for comparison.  The sliding block of ``tests/fem/test_mixed_friction.py`` (μ = 0.3, pressed 0.01,
dragged 0.05) at several h: the share of the normal force at the right-angled corner where σ_t is fixed to 0,
1 − T/(μN), and T/(μ(N − corner)) − 1 (the slip penalty's excess).

    python benchmarks/mixed_corner.py --refinement 0.5 1 --sizes 16 32 64 --out benchmarks/results/mixed_corner.md
"""

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

from common import write_report  # noqa: E402

from fenics_contact.problem.analytic import cattaneo_mindlin, hertz_model  # noqa: E402
from fenics_contact.problem.friction import Friction  # noqa: E402
from fenics_contact.problem.geometry import unit_square  # noqa: E402
from fenics_contact.problem.meshes import hertz_block  # noqa: E402
from fenics_contact.problem.obstacles import Plane  # noqa: E402
from fenics_contact.problem.problem import ContactProblem  # noqa: E402
from fenics_contact.sliding import slide  # noqa: E402

A, MU = 0.05, 0.3
HALF_SPACE = {"width": 1000.0, "depth": 500.0, "h_far": 64.0}
R, PRESS = 1000.0 * A, 1.7e-4
WALL = Plane((1.0, 0.0), (-1.0, 0.0))
BLOCK_PATH = [(-0.005, 0.0), (-0.01, 0.0), (-0.01, 0.005), (-0.01, 0.02), (-0.01, 0.05)]


def hertz_row(refinement: float, nu: float, law: Friction | None, method: str) -> str:
    """One pressed Hertz block: the end nodes and the pressure beyond the Hertz zone."""
    cm, spec = hertz_block(A, refinement=refinement, **HALF_SPACE)
    model = hertz_model(radius=R, E=1.0, nu=nu, depth=0.0)
    if law is not None:
        model = model.with_(law=law)
    step = slide(model.on(cm), method, [(0.0, -PRESS / 2), (0.0, -PRESS)]).steps[-1]
    prof = step.profile
    x = prof.points[:, 0]
    ends = np.argsort(x)[[0, -1]]
    p = np.maximum(-prof.sigma_c, 0.0) if hasattr(prof, "sigma_c") else step.friction.pressure
    a = cattaneo_mindlin(x, normal=step.normal_force, tangential=0.0, mu=MU, radius=R, nu=nu).a
    beyond = np.abs(x) > a + spec.h_contact
    sigma = "–" if not hasattr(prof, "sigma_c") else " / ".join(f"{v:.1e}" for v in prof.sigma_c[ends])
    return (
        f"| {method} | a/{round(A / spec.h_contact)} | {nu} | {'coulomb' if law else 'none'} | {sigma} "
        f"| {' / '.join(f'{v:.1e}' for v in p[ends])} | {' / '.join(f'{v:.2e}' for v in prof.gap[ends])} "
        f"| {np.max(p[beyond], initial=0.0):.1e} | {np.max(p):.3e} |"
    )


def block_row(n: int) -> str:
    """The sliding block at h = 1/n: the corner's share and the tangential force."""
    nodes = []
    problem = ContactProblem(1.0, 0.3, obstacle=WALL, law=Friction("coulomb", mu=MU))
    path = slide(
        problem.on(unit_square(n, max(n // 4, 1), clamped=("left",))),
        "mixed-monolithic",
        BLOCK_PATH,
        on_step=lambda step, solver: nodes.append(solver.contact.contact_nodes),
    )
    last = path.steps[-1]
    fp, N, T = last.friction, last.normal_force, last.tangential_force[1]
    fixed = nodes[-1].shear_fixed[nodes[-1].profile_nodes]
    corner = float(np.sum((fp.weights * fp.pressure)[fixed]))
    return (
        f"| 1/{n} | {np.count_nonzero(fixed)} | {corner / N:.4e} | {1.0 - T / (MU * N):.4e} "
        f"| {T / (MU * (N - corner)) - 1.0:.3e} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--refinement", type=float, nargs="*", default=[0.5, 1.0])
    parser.add_argument("--nu", type=float, nargs="*", default=[0.3, 0.4999])
    parser.add_argument("--sizes", type=int, nargs="*", default=[16, 32, 64])
    parser.add_argument("--out", default="benchmarks/results/mixed_corner.md")
    args = parser.parse_args()
    lines = [
        "# The ends of Γ_C next to a traction-free side (mixed methods)",
        "",
        "`python benchmarks/mixed_corner.py` (arguments in the file's docstring)",
        "",
        "Hertz block pressed by 1.7e-4 (R = 1000a, half-space-like): the end nodes x = −3a / +3a and the largest",
        "pressure beyond the Hertz zone (a + one cell); p = (−σ_c)⁺ of the contact profile (the primal one's σ_c is",
        "its own nodal normal stress).",
        "",
        "| method | h_c | ν | friction | σ_c ends | p ends | gap ends | max p beyond a + h_c | max p |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in args.refinement:
        for nu in args.nu:
            for law in (None, Friction("coulomb", mu=MU)):
                lines.append(hertz_row(r, nu, law, "mixed-monolithic"))
            lines.append(hertz_row(r, nu, Friction("coulomb", mu=MU), "primal-monolithic"))
    lines += [
        "",
        "Sliding block (1 × 1, clamped left, wall at x = 1, μ = 0.3, pressed 0.01, dragged 0.05): the nodes where",
        "σ_t is fixed (the right-angled corners), their share of N, the deficit 1 − T/(μN), and T/(μ(N − corner)) − 1.",
        "",
        "| h | fixed nodes | corner share | 1 − T/(μN) | T/(μ(N − corner)) − 1 |",
        "|---|---|---|---|---|",
    ]
    lines += [block_row(n) for n in args.sizes]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
