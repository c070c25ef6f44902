"""The whole force–indentation curve, offline phase included, for every method against the monolithic solve.

A cylinder (``Circle((3.0, 0.5), 2.0)``) indents the contact side x = 1 of a built-in test model in
load steps (``force_indentation``: each method built once, warm starts, every step certified); each
method runs in a fresh process (its own peak memory), and the table gives its set-up (offline) time,
the offline work done inside the first step (the interface Newton's Ω₁ response), the median and the
total of the steps, the whole curve against the monolithic Newton's, the peak resident memory and the
largest force difference to the monolithic curve of the same discretization (primal or mixed).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 \\
        --methods primal-monolithic primal primal-ms --out benchmarks/results/load_path.md

Time only the work itself: the mesh and the problem are built before the clock starts. Ratios are
within one run; run it on a quiet machine (the machine line of the results file says which).
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
FAMILY = {
    "primal-monolithic": "primal",
    "primal": "primal",
    "primal-ms": "primal",
    "mixed-monolithic": "mixed",
    "mixed": "mixed",
    "mixed-ms": "mixed",
}


def one(args) -> dict:
    """One method's curve in this process (``--one``): times, forces, peak memory."""
    import fenics_contact as fc
    from fenics_contact.io import peak_rss_bytes
    from fenics_contact.problem.models import get_model

    cm = fc.unit_square(args.h, args.H)
    problem = get_model(args.model, E_high=args.contrast).with_(obstacle=fc.Circle((3.0, 0.5), 2.0)).on(cm)
    depths = np.linspace(args.first, args.last, args.steps)
    options = {}
    if args.one.endswith("-ms"):
        options["layers"], options["nbasis"] = args.layers, args.nbasis
    if args.one in ("primal", "mixed", "primal-ms", "mixed-ms"):
        options["tol"] = args.tol
    start = time.perf_counter()
    curve = fc.force_indentation(problem, args.one, depths, direction=(-1.0, 0.0), **options)
    total = time.perf_counter() - start
    steps = [s.time_s for s in curve.steps]
    return {
        "method": args.one,
        "setup_s": curve.time_offline_s,
        "first_step_offline_s": curve.steps[0].time_offline_s,
        "step_median_s": float(np.median(steps)),
        "steps_s": float(np.sum(steps)),
        "total_s": total,
        "forces": curve.forces.tolist(),
        "converged": all(s.converged for s in curve.steps),
        "iterations": [s.iterations for s in curve.steps],
        "peak_rss_gb": peak_rss_bytes() / 1e9,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, default=256, help="1/h of the unit-square mesh")
    parser.add_argument("--H", type=int, default=16, help="1/H: the strip width and coarse size")
    parser.add_argument("--model", type=int, default=3)
    parser.add_argument("--contrast", type=float, default=1e3, help="E in the model's pattern (E = 1 elsewhere)")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--first", type=float, default=0.002, help="first indentation depth")
    parser.add_argument("--last", type=float, default=0.02, help="last indentation depth")
    parser.add_argument("--layers", type=int, default=4)
    parser.add_argument("--nbasis", type=int, default=3)
    parser.add_argument("--tol", type=float, default=1e-8, help="tolerance of the certificate (hybrid methods)")
    parser.add_argument(
        "--methods", nargs="+", default=["primal-monolithic", "primal", "primal-ms"], choices=list(FAMILY)
    )
    parser.add_argument("--out", type=Path, default=None, help="a markdown results file (default: print)")
    parser.add_argument("--one", choices=list(FAMILY), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print("RESULT " + json.dumps(one(args)))
        return
    from fenics_contact.io import machine_description

    results = {}
    for method in args.methods:
        cmd = [sys.executable, __file__, "--one", method] + [
            f"--{k}={v}"
            for k, v in (
                ("h", args.h),
                ("H", args.H),
                ("model", args.model),
                ("contrast", args.contrast),
                ("steps", args.steps),
                ("first", args.first),
                ("last", args.last),
                ("layers", args.layers),
                ("nbasis", args.nbasis),
                ("tol", args.tol),
            )
        ]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=os.environ, cwd=ROOT)
        line = next((row for row in proc.stdout.splitlines() if row.startswith("RESULT ")), None)
        if line is None:
            raise SystemExit(f"{method} failed:\n{proc.stderr[-3000:]}")
        results[method] = json.loads(line[7:])
        print(f"{method}: total {results[method]['total_s']:.2f} s", flush=True)
    lines = [
        f"# Load path: {args.steps} steps of a cylinder into model {args.model} (contrast {args.contrast:g}), "
        f"h = 1/{args.h}, H = 1/{args.H}",
        "",
        f"Command: `OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} .venv/bin/python "
        f"benchmarks/load_path.py {' '.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        "| method | set-up [s] | offline in step 1 [s] | step median [s] | steps [s] | whole curve [s] "
        "| / monolithic | peak memory [GB] | max force difference to the monolithic curve |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for method, r in results.items():
        mono = results.get(f"{FAMILY[method]}-monolithic")
        ratio = f"{r['total_s'] / mono['total_s']:.2f}" if mono else "—"
        diff = (
            f"{np.max(np.abs(np.subtract(r['forces'], mono['forces'])) / np.abs(mono['forces'])):.1e}"
            if mono and method != f"{FAMILY[method]}-monolithic"
            else "—"
        )
        lines.append(
            f"| {method} | {r['setup_s']:.2f} | {r['first_step_offline_s']:.2f} | {r['step_median_s']:.3f} "
            f"| {r['steps_s']:.2f} | {r['total_s']:.2f} | {ratio} | {r['peak_rss_gb']:.2f} | {diff} |"
        )
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
