"""What a load step of Algorithm 1 (``primal``, interface Newton) costs, part by part, and its interface response
against one factorization of Ω₁.

The load path of ``benchmarks/load_path.py`` (model 3, the cylinder ``Circle((3.0, 0.5), 2.0)`` moved along
(−1, 0) from depth 0.002 to 0.02, ``IterationOptions(accel="newton", tol=1e-8)``).  Part 1: Ω₁'s factorization
(analysis and numeric, then numeric alone on the kept analysis) and its interface response T₁ (the block of
J₁⁻¹ on γ from MUMPS' factors, one triangle swept along γ and the other by symmetry, what ``FineResponse``
takes; beside it the whole block, every entry requested; minimum of ``--repeat``).  Part 2: the CPU time of
the load steps 2…N split by the functions that do the work (each wrapped by a CPU timer in this script only):
the rest is the Python around them (records, the obstacle's motion, logging).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_step_cost.py --h 128 256 \\
        --out benchmarks/results/load_step_cost.md
"""

import argparse
import functools
import os
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
from common import write_report

import fenics_contact as fc
from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.hybrid import condensation, primal
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import PrimalPart
from fenics_contact.hybrid.transmission import InterfaceSpace
from fenics_contact.indentation import force_indentation
from fenics_contact.io import machine_description
from fenics_contact.problem.models import get_model

#: (label, owner, attribute): the functions timed in part 2 (one called inside another counts for the outer one)
PARTS = (
    ("obstacle moved (ν, gap at the Γ_C nodes)", PrimalSubproblem, "set_obstacle"),
    ("condensation for the new normals (sums)", CondensedInterface, "__init__"),
    ("load term s_L (kept J⁻¹b, one dense solve)", CondensedInterface, "load_terms"),
    ("contact Newton on Γ_C", condensation, "contact_solve"),
    ("Ω₂ warm state (one J₀ back-solve)", PrimalPart, "solve"),
    ("Ω₁ solve (kept J⁻¹b + one back-solve of the data: a sparse right-hand side)", PrimalHybridStep, "_solve_omega1"),
    ("Ω₂ check (its residual at the warm state)", primal, "solve_or_verify"),
    ("γ traces and data (transfers)", InterfaceSpace, "from_part"),
    ("γ traces and data (transfers)", InterfaceSpace, "to_part"),
    ("relative change (Ω₁: M u₁, K u₁ from its equations; Ω₂: two products)", PrimalHybridStep, "_measure"),
    ("certificate", primal, "primal_certificate"),
    ("force (contact profile: Ω₂'s reaction)", PrimalSubproblem, "contact_profile"),
)


def problem_on(h: int, H: int):
    cm = fc.unit_square(h, H)
    return get_model(3, E_high=1e3).with_(obstacle=fc.Circle((3.0, 0.5), 2.0)).on(cm)


def factorization_and_response(h: int, H: int, repeat: int) -> str:
    """Part 1: a table row."""
    step = PrimalHybridStep(problem_on(h, H))
    sub = step.sub[0]
    start = time.process_time()
    sub.factorize()
    full = time.process_time() - start
    numeric = response = whole = np.inf
    part = PrimalPart(sub, step.interface, 0, contact=False)
    rows = np.unique(np.concatenate([part.trace_at, part.data_at]))
    for _ in range(repeat):
        sub.A.assemble()  # (a new state of the same matrix: the numeric factorization on the kept analysis)
        start = time.process_time()
        sub.solver.set_operator(sub.A)
        numeric = min(numeric, time.process_time() - start)
        part._kept_inverse = None
        start = time.process_time()
        part.responses(contact=False, chunk=128)
        response = min(response, time.process_time() - start)
        start = time.process_time()
        sub.solver.inverse_block(rows)  # every entry of the block requested (no sweep)
        whole = min(whole, time.process_time() - start)
    return (
        f"| 1/{h} | {sub.num_dofs} | {part.n_g} | {full:.3f} | {numeric:.3f} | {response:.3f} | {whole:.3f} "
        f"| {response / numeric:.2f} | {response / full:.2f} |"
    )


def step_parts(h: int, H: int, steps: int) -> tuple[dict, float, int]:
    """Part 2: CPU seconds per part over the steps 2…N, their total, the number of steps."""
    spent: dict[str, float] = defaultdict(float)
    timing = {"on": False, "depth": 0}
    originals = []
    for label, owner, name in PARTS:
        fn = getattr(owner, name)
        originals.append((owner, name, fn))

        @functools.wraps(fn)
        def timed(*args, _fn=fn, _label=label, **kwargs):
            start = time.process_time()
            timing["depth"] += 1
            try:
                return _fn(*args, **kwargs)
            finally:
                timing["depth"] -= 1
                if timing["on"] and timing["depth"] == 0:  # (a timed call inside another is the outer one's)
                    spent[_label] += time.process_time() - start

        setattr(owner, name, timed)
    marks = []

    def on_step(record, solver):
        marks.append(time.process_time())
        timing["on"] = True

    try:
        force_indentation(
            problem_on(h, H),
            "primal",
            np.linspace(0.002, 0.02, steps),
            direction=(-1.0, 0.0),
            tol=1e-8,
            accel="newton",
            on_step=on_step,
        )
    finally:
        for owner, name, fn in originals:
            setattr(owner, name, fn)
    return dict(spent), marks[-1] - marks[0], steps - 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[128, 256])
    parser.add_argument("--H", type=int, default=16)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = [
        "# Algorithm 1's load step by part, and its interface response against one Ω₁ factorization",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_step_cost.py --h {' '.join(map(str, args.h))}"
        f"{'' if args.out is None else f' --out {args.out}'}`",
        "",
        f"Machine: {machine_description()}; load average {os.getloadavg()[0]:.1f} at the start; CPU times of the "
        "process (`time.process_time`), which rise with the load of a shared machine too.",
        "",
        f"## Ω₁'s factorization and interface response (minimum of {args.repeat})",
        "",
        "| h | Ω₁ DOFs | n_γ | factorization (analysis + numeric) [s] | numeric [s] | T₁ from the factors [s] "
        "| the whole block [s] | T₁ / numeric | T₁ / factorization |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for h in args.h:
        lines.append(factorization_and_response(h, args.H, args.repeat))
        print(lines[-1], flush=True)
    lines += [
        "",
        f"## A load step ({args.steps} steps; CPU per step, mean over steps 2…{args.steps})",
        "",
        "| part | " + " | ".join(f"h = 1/{h} [ms]" for h in args.h) + " |",
        "|---|" + "---|" * len(args.h),
    ]
    results = [step_parts(h, args.H, args.steps) for h in args.h]
    labels = list(dict.fromkeys(label for label, _, _ in PARTS))
    for label in labels:
        lines.append(f"| {label} | " + " | ".join(f"{1e3 * r[0].get(label, 0.0) / r[2]:.1f}" for r in results) + " |")
    lines.append(
        "| rest (Python: records, data, logging) | "
        + " | ".join(f"{1e3 * (r[1] - sum(r[0].values())) / r[2]:.1f}" for r in results)
        + " |"
    )
    lines.append("| **the step** | " + " | ".join(f"**{1e3 * r[1] / r[2]:.1f}**" for r in results) + " |")
    if args.out:
        write_report(args.out, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
