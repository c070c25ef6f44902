"""Algorithm 2's interface responses: n_γ back-solves against MUMPS' entries of J⁻¹, one process.

On the load-path problem (``benchmarks/load_path.py``: model 3, the cylinder at its first depth), the mixed
hybrid step's Ω₁ response T₁ = N J₁⁻¹ C and Ω₂'s J₀ responses (Yc, Sc, Yq, Sq) are taken twice with the
same factorizations: by back-solves in blocks of ``--chunk`` right-hand sides (``AffinePart.responses``) and
from the block of J⁻¹ on the stress unknowns that C, Qᵀ, N and Q touch (``MixedPart.responses`` with the
fraction rule switched off).  The table gives the CPU times, the size of that block against the unknowns and
the largest difference relative to the largest entry; ``MixedPart.responses`` takes the entries where the
block spans at most ``response.ENTRIES_FRACTION`` of the unknowns.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/mixed_interface_response.py --h 64 128 \\
        --out benchmarks/results/mixed_interface_response.md
"""

import argparse
import time
from pathlib import Path

import numpy as np

import fenics_contact as fc
from fenics_contact.hybrid import response
from fenics_contact.hybrid.options import InterfaceNewtonOptions
from fenics_contact.hybrid.response import AffinePart
from fenics_contact.io import machine_description
from fenics_contact.methods import get_method
from fenics_contact.problem.models import get_model


def _cpu(f):
    t = time.process_time()
    out = f()
    return out, time.process_time() - t


def rows(h: int, chunk: int) -> list[str]:
    cm = fc.unit_square(h, 16)
    obstacle = fc.Circle((3.0, 0.5), 2.0).indented(0.002, np.array([-1.0, 0.0]))
    problem = get_model(3, E_high=1e3).with_(obstacle=obstacle).on(cm)
    interface = get_method("mixed").build(problem, comm=problem.comm).interface_problem(InterfaceNewtonOptions())
    out = []
    parts = (("Ω₁: T₁", interface.omega1.part, False), ("Ω₂ (J₀): Yc, Sc, Yq, Sq", interface.omega2, True))
    for label, part, contact in parts:
        response.ENTRIES_FRACTION = 1.0  # entries whatever the block's size
        sizes = []
        inverse_block = part.solver.inverse_block
        part.solver.inverse_block = lambda r, f=inverse_block: sizes.append(r.size) or f(r)
        entries, t_entries = _cpu(lambda: part.responses(contact=contact, chunk=chunk))
        solves, t_solves = _cpu(lambda: AffinePart.responses(part, contact=contact, chunk=chunk))
        diff = max(
            float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), 1e-300))
            for a, b in zip(entries, solves)
        )
        out.append(
            f"| 1/{h} | {label} | {part.nown} | {part.n_g} | {part.n_c} | {sizes[0]} ({100 * sizes[0] / part.nown:.1f} %) "
            f"| {t_solves:.2f} | {t_entries:.2f} | {t_solves / t_entries:.2f} | {diff:.1e} |"
        )
        print(out[-1], flush=True)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[64, 128])
    parser.add_argument("--chunk", type=int, default=128, help="right-hand sides per back-solve block")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    fraction = response.ENTRIES_FRACTION
    lines = [
        "# Algorithm 2's interface responses: back-solves against entries of J⁻¹ (model 3, cylinder, contrast 1000, "
        "H = 1/16)",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/mixed_interface_response.py "
        f"--h {' '.join(map(str, args.h))} --chunk {args.chunk}{' --out ' + str(args.out) if args.out else ''}`",
        "",
        f"Machine: {machine_description()}; CPU times of one process (the machine may be shared: compare within a "
        "row).  Block: the stress unknowns that C, Qᵀ, N and Q touch, against all unknowns of the subproblem.  "
        f"`MixedPart.responses` takes the entries when the block is at most {100 * fraction:g} % of the unknowns.",
        "",
        "| h | response | unknowns | n_γ | n_c | block | back-solves [s] | entries [s] | speed-up | entries − solves |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for h in args.h:
        lines += rows(h, args.chunk)
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
