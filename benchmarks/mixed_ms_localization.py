"""Why Algorithm 4 needs more Stage I modes as ν → ½, measured: decay of the global Stage II bases.

    OMP_NUM_THREADS=1 python benchmarks/mixed_ms_localization.py --n 64 --n-coarse 16

For a homogeneous Ω₁ (E = 1) with Poisson ratio ν, the global stress bases ψ of a central coarse
cell (patch = all of Ω₁) are computed and the profile √(A-energy at coarse distance ≥ d / total) is
tabulated for d = 1, 2, ...: the error of m oversampling layers follows it at d ≈ m.  Rows: the
paper's fixed l = 3 and the default adaptive Stage I (modes added until the first eigenvalue left
out is Λ ≥ min_gap).  Part (b): the same profile's rate for fixed l.  Part (c) counts the Stage I modes the adaptive rule keeps in the paper's
Table 5.3–5.7 cases.
"""

import argparse
import time
from pathlib import Path

import numpy as np
from common import write_report

import fenics_contact  # noqa: F401  (must precede dolfinx / petsc4py)
from fenics_contact.hybrid.mixed import MixedHybridStep
from fenics_contact.io import machine_description
from fenics_contact.multiscale import mixed_cem as mm
from fenics_contact.multiscale.coarse import coarse_grid
from fenics_contact.problem import geometry, models

CASES = {  # the paper's cases: (model, E₁/E₂, ν₁ (pattern), ν₂ (rest))
    "5.3": (2, None, None, None),
    "5.5": (1, 1.0e-4, 0.35, 0.499),
    "5.6": (1, 1.0e4, 0.499, 0.35),
    "5.7": (1, 1.0, 0.499, 0.499),
}


def omega1(n: int, n_coarse: int, model):
    cm = geometry.unit_square(n, n_coarse)
    step = MixedHybridStep(model.on(cm), beta="sqrt-h")
    part = step.parts[0]
    return cm, step.sub[0], coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)


def homogeneous_omega1(n: int, n_coarse: int, nu: float):
    """(mesh, Ω₁ subproblem, coarse grid, central coarse cell) of a homogeneous Ω₁ (E = 1) with Poisson ratio ν."""
    cm, sub, grid = omega1(n, n_coarse, models.paper_phase_model(1, E_ratio=1.0, nu_pattern=nu, nu_rest=nu))
    centre = np.array([grid.ij[:, 0].max() // 2, grid.ij[:, 1].max() // 2])
    return cm, sub, grid, int(np.flatnonzero((grid.ij == centre).all(axis=1))[0])


def decay(cm, sub, grid, k: int, options: mm.MixedCEMOptions):
    """(U_aux, decay profile of the global bases of cell k, mean rate ρ per layer from d = 2 to d_max − 1)."""
    ops, topo, aux = mm.stage_one_of(sub, grid, options, H=cm.H)
    prof = mm.basis_decay_profile(ops, topo, grid, aux, k)
    return aux, prof, -np.log(prof[-2] / prof[1]) / (prof.size - 3)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=64, help="fine cells per side (h = 1/n)")
    parser.add_argument("--n-coarse", type=int, default=16, help="coarse cells per side (H = 1/n_coarse)")
    parser.add_argument("--nu", default="0.3,0.49,0.499,0.4999", help="Poisson ratios for part (a)")
    parser.add_argument("--sweep-nu", default="0.499,0.4999", help="Poisson ratios for part (b)")
    parser.add_argument("--sweep-l", default="3,8,12,20,32", help="fixed l values for part (b)")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mixed_ms_localization.md"))
    args = parser.parse_args()
    start = time.perf_counter()
    fixed, adaptive = mm.MixedCEMOptions(min_gap=None), mm.MixedCEMOptions()
    lines = [
        "# Mixed CEM (Algorithm 4): localization of the Stage II bases as ν → ½",
        "",
        f"Machine: {machine_description()}. Command: `OMP_NUM_THREADS=1 python benchmarks/mixed_ms_localization.py "
        f"--n {args.n} --n-coarse {args.n_coarse}`.",
        "",
        f"### (a) Decay of the global bases of a central coarse cell, homogeneous Ω₁ (E = 1), h = 1/{args.n}, "
        f"H = 1/{args.n_coarse}, c = {fixed.s_factor:g}",
        "",
        "√(A-energy at coarse distance ≥ d / total), the largest over the cell's bases. ρ: the mean decay rate "
        "per layer, −ln(profile(d_max−1)/profile(2))/(d_max−3). Λ: the smallest Stage I eigenvalue left out "
        f"(over all cells). 'adaptive': modes added until Λ ≥ {adaptive.min_gap:g} (at most {adaptive.max_nbasis}).",
        "",
    ]
    rows = []
    dmax = 0
    for nu in (float(x) for x in args.nu.split(",")):
        cm, sub, grid, k = homogeneous_omega1(args.n, args.n_coarse, nu)
        for name, opts in (("l = 3", fixed), ("adaptive", adaptive)):
            aux, prof, rate = decay(cm, sub, grid, k, opts)
            counts = np.diff(aux.offsets)
            rows.append((nu, name, f"{counts.min()}–{counts.max()}", float(np.min(aux.gaps)), rate, prof))
            dmax = max(dmax, prof.size)
            print(rows[-1][:5], " ".join(f"{p:.1e}" for p in prof), flush=True)
    lines.append("| ν | Stage I | l per cell | Λ | ρ | " + " | ".join(f"d = {d}" for d in range(1, dmax + 1)) + " |")
    lines.append("|---|---|---|---|---|" + "---|" * dmax)
    for nu, name, lr, gap, rate, prof in rows:
        cells = [f"{p:.1e}" for p in prof] + [""] * (dmax - prof.size)
        lines.append(f"| {nu:g} | {name} | {lr} | {gap:.2g} | {rate:.2f} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "### (b) Decay rate ρ for a fixed number l of Stage I modes per cell (same set-up as (a))",
        "",
        "| ν | l | Λ | ρ |",
        "|---|---|---|---|",
    ]
    for nu in (float(x) for x in args.sweep_nu.split(",")):
        cm, sub, grid, k = homogeneous_omega1(args.n, args.n_coarse, nu)
        for nb in (int(x) for x in args.sweep_l.split(",")):
            opts = mm.MixedCEMOptions(nbasis=nb, min_gap=None, max_nbasis=max(nb, mm.DEFAULT_MAX_NBASIS))
            aux, _, rate = decay(cm, sub, grid, k, opts)
            row = f"| {nu:g} | {nb} | {np.min(aux.gaps):.2g} | {rate:.2f} |"
            lines.append(row)
            print(row, flush=True)
    lines += [
        "",
        f"### (c) Stage I modes per coarse cell in the paper's cases (h = 1/{args.n}, H = 1/{args.n_coarse})",
        "",
        "| case | Λ with l = 3 | adaptive: l per cell (mean) | dim U_aux (l = 3 → adaptive) | Λ adaptive |",
        "|---|---|---|---|---|",
    ]
    for case, (number, ratio, nu1, nu2) in CASES.items():
        model = (
            models.get_model(number)
            if ratio is None
            else models.paper_phase_model(number, E_ratio=ratio, nu_pattern=nu1, nu_rest=nu2)
        )
        cm, sub, grid = omega1(args.n, args.n_coarse, model)
        _, _, a3 = mm.stage_one_of(sub, grid, fixed, H=cm.H)
        _, _, aa = mm.stage_one_of(sub, grid, adaptive, H=cm.H)
        counts = np.diff(aa.offsets)
        row = (
            f"| {case} | {np.min(a3.gaps):.2g} | {counts.min()}–{counts.max()} ({counts.mean():.1f}) | "
            f"{a3.size} → {aa.size} | {np.min(aa.gaps):.2g} |"
        )
        lines.append(row)
        print(row, flush=True)
    lines += ["", f"Total wall time {time.perf_counter() - start:.0f} s."]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
