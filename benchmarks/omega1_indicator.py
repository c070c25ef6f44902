"""The multiscale Ω₁ accuracy check of Algorithm 3 (``result.omega1_check``) against the true error.

For each model and each number of oversampling layers m, Algorithm 3 runs with the interface Newton to the
certificate; the table gives the energy-norm error of the coupled solution against the fine monolithic solve
(e_a, the true error, which a user does not have), the check (the multiscale Ω₁ against the fine Ω₁ solve for
the run's own interface data, which every run reports) and their ratio (the effectivity), and whether the run
warns (check above ``OMEGA1_CHECK_WARN``). The models have loads in Ω₁ and traction-free sides, where too few
layers hurt most:

* model 1 (stiff channels through γ) with all three other sides clamped;
* model 3 (stiff channels reaching Γ_C) with a traction-free bottom;
* a log-normal E field (contrast 10⁴, a smooth Gaussian random field of correlation length 0.1, seed 1) with a
  traction-free bottom and a downward traction on the top side.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/omega1_indicator.py --h 32 --H 8 \\
        --out benchmarks/results/omega1_indicator.md
"""

import argparse
import time

import numpy as np
from common import write_report

import fenics_contact as fc
from fenics_contact.io import machine_description
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import OMEGA1_CHECK_WARN
from fenics_contact.problem.models import pixel_field


def log_normal_field(n: int = 64, contrast: float = 1e4, length: float = 0.1, seed: int = 1):
    """A pixel map of E = 10^(log10(contrast)·(G − min G)/(max G − min G)) over (0, 1)², G a Gaussian random field
    (white noise smoothed by a Gaussian kernel of width ``length``)."""
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((n, n))
    k = np.fft.fftfreq(n)[:, None] ** 2 + np.fft.fftfreq(n)[None, :] ** 2
    field = np.real(np.fft.ifft2(np.fft.fft2(noise) * np.exp(-2.0 * (np.pi * length * n) ** 2 * k)))
    field = (field - field.min()) / (field.max() - field.min())
    return pixel_field(10.0 ** (np.log10(contrast) * field))


def problems(h: int, H: int) -> dict:
    clamped = fc.unit_square(h, H)
    free_bottom = fc.unit_square(h, H, clamped=("left", "top"))
    top_traction = fc.unit_square(h, H, clamped=("left",), neumann={"top": "Gamma_N_top"})
    log_normal = fc.models.model_1().with_(
        youngs_modulus=log_normal_field(),
        poisson_ratio=lambda x: np.full(x.shape[1], 0.3),
        boundary=fc.BoundaryConditions(tractions={"Gamma_N_top": (0.0, -0.05)}),
        description="log-normal E, contrast 1e4, free bottom, top traction",
    )
    return {
        "model 1, clamped sides": fc.models.model_1().on(clamped),
        "model 3, free bottom": fc.models.model_3().on(free_bottom),
        "log-normal E (10⁴), free bottom, top traction": log_normal.on(top_traction),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, default=32)
    parser.add_argument("--H", type=int, default=8)
    parser.add_argument("--layers", type=int, nargs="+", default=[1, 2, 3, 4])
    parser.add_argument("--out", default="benchmarks/results/omega1_indicator.md")
    args = parser.parse_args()
    lines = [
        "# The multiscale Ω₁ check of Algorithm 3 against the true error",
        "",
        f"`OMP_NUM_THREADS=1 .venv/bin/python benchmarks/omega1_indicator.py --h {args.h} --H {args.H}`; "
        f"h = 1/{args.h}, H = 1/{args.H}, 3 modes per coarse cell, the interface Newton to tol 1e-8; a run warns "
        f"when the check exceeds {OMEGA1_CHECK_WARN:g}.",
        "",
        f"Machine: {machine_description()}.",
        "",
        "## Check against the true error",
        "",
        "| problem | m | e_a (true, energy) | check | check / e_a | warns | time (s) |",
        "|---|---|---|---|---|---|---|",
    ]
    for name, problem in problems(args.h, args.H).items():
        reference = fc.solve(problem, "primal-monolithic")
        for m in args.layers:
            start = time.perf_counter()
            result = fc.solve(problem, "primal-ms", cem=CEMOptions(layers=m), reference=reference.u, tol=1e-8)
            elapsed = time.perf_counter() - start
            error = result.step.error_energy()
            check = result.omega1_check
            lines.append(
                f"| {name} | {m} | {error:.3g} | {check:.3g} | {check / error:.3f} | "
                f"{'yes' if check > OMEGA1_CHECK_WARN else 'no'} | {elapsed:.1f} |"
            )
            print(lines[-1], flush=True)
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
