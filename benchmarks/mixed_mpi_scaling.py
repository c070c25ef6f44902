"""Strong scaling and memory of the mixed (Arnold–Winther) method under MPI: monolithic solve and Algorithm 2.

Launches one MPI job per (1/h, method, number of ranks) with ``mpiexec -n N`` (each job measures its own
peak memory: the high-water mark of the resident set of every rank, ``getrusage``), and writes a
markdown table with the machine description: times, DOFs, peak memory per rank (max over the ranks)
and in total, the speed-up against the 1-rank run of the same table, and a weak-scaling estimate.
Example (h = 1/64, about 2 min on a quiet 2-core machine):

    .venv/bin/python benchmarks/mixed_mpi_scaling.py --sizes 64 --ranks 1 2 \\
        --out benchmarks/results/mixed_mpi_scaling.md

h = 1/128 needs about 10 GB (1 rank) and 2 × 6 GB (2 ranks); run it alone on a quiet machine:

    .venv/bin/python benchmarks/mixed_mpi_scaling.py --sizes 128 --ranks 1 2 \\
        --out benchmarks/results/mixed_mpi_scaling_128.md

Methods: ``mono`` (``fem.mixed.solve_mixed_monolithic``: set-up + globalized semismooth Newton, UFL
residual check), ``hybrid`` (``hybrid.mixed.solve_mixed_hybrid``: Algorithm 2 with the default
β = √h, Anderson, tolerance 1e-6, no reference) and ``omega2`` (the Ω₂ strip subproblem alone, as
Algorithm 4's online phase solves it: set-up, a cold Newton solve, then --repeat warm solves, whose
mean time is the "warm solve" column).  Model and strip width: --model (2), --coarse (16).

**Weak-scaling estimate.**  From the runs of the largest 1/h the memory is split into a part per rank
that does not depend on the problem (the Python/PETSc/MUMPS baseline, measured by the first job on a
tiny mesh) and a part that grows with the number of DOFs n; the growth exponent p (memory ∝ n^p, p a
little above 1 for a 2D sparse LU) is fitted from the two largest sizes of the 1-rank runs (or taken as
1.1 with one size).  The table then lists, for h = 1/256 ... 1/1024, the total memory and the ranks
needed to keep it under --memory-per-rank per rank.
"""

import argparse
import datetime
import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

METHODS = ("mono", "hybrid", "omega2")


# ---------------------------------------------------------------------------------------------
# one job (run under mpiexec)
# ---------------------------------------------------------------------------------------------
def worker(args: argparse.Namespace) -> None:
    from mpi4py import MPI

    import fenics_contact  # noqa: F401  (dolfinx_solver first)
    from fenics_contact.fem.mixed import solve_mixed_monolithic
    from fenics_contact.hybrid.iteration import IterationOptions
    from fenics_contact.hybrid.mixed import solve_mixed_hybrid
    from fenics_contact.problem.geometry import unit_square
    from fenics_contact.problem.models import get_model

    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    cm = unit_square(args.n, min(args.coarse, args.n) if args.method == "baseline" else args.coarse)
    model = get_model(args.model)
    t_mesh = time.perf_counter() - t0
    out: dict = {"ranks": comm.size, "n": args.n, "method": args.method, "time_mesh_s": t_mesh}
    comm.Barrier()
    t0 = time.perf_counter()
    if args.method == "mono":
        sol = solve_mixed_monolithic(model.on(cm))
        out.update(
            dofs=sol.dofs["total"],
            newton=sol.newton.steps,
            time_s=sol.time_s,
            time_online_s=sol.time_newton_s,
            time_setup_s=sol.time_s - sol.time_newton_s,
        )
    elif args.method == "hybrid":
        res = solve_mixed_hybrid(model.on(cm), options=IterationOptions(tol=args.tol))
        out.update(
            dofs=res.dofs["omega1"] + res.dofs["omega2"],
            iterations=res.iterations,
            converged=res.converged,
            time_online_s=res.time_online_s,
            time_setup_s=res.time_offline_s,
        )
        out["time_s"] = out["time_online_s"] + out["time_setup_s"]
    elif args.method == "omega2":  # the Ω₂ strip alone: what Algorithm 4's online phase solves
        from fenics_contact.fem.mixed import contact_modulus, default_epsilon
        from fenics_contact.fem.mixed_subproblem import MixedSubproblem
        from fenics_contact.hybrid.transmission import split_mesh
        from fenics_contact.problem.fields import material_fields

        fields = material_fields(cm.mesh, model)
        eps = default_epsilon(cm.h, contact_modulus(cm.mesh, cm.facet_tags, fields.E, smallest=True))
        part = split_mesh(cm)[1]
        sub = MixedSubproblem(
            part.mesh,
            part.facet_tags,
            material_fields(part.mesh, model),
            epsilon=eps,
            beta=float(np.sqrt(cm.h)),
            prefix="bench_omega2_",
        )
        t_setup = time.perf_counter() - t0
        t1 = time.perf_counter()
        hist = sub.solve(np.zeros(sub.interface_range[1] - sub.interface_range[0]))
        t_first = time.perf_counter() - t1
        rng = np.random.default_rng(comm.rank)
        t1 = time.perf_counter()
        for _ in range(args.repeat):  # warm solves with small data changes: one Newton step each, no refactorization
            sub.solve(1e-3 * rng.standard_normal(sub.interface_range[1] - sub.interface_range[0]))
        t_warm = (time.perf_counter() - t1) / args.repeat
        out.update(
            dofs=sub.num_dofs["total"],
            newton=hist.steps,
            time_setup_s=t_setup,
            time_online_s=t_first,
            time_s=t_setup + t_first,
            time_warm_solve_s=t_warm,
        )
    elif args.method != "baseline":
        raise SystemExit(f"unknown method {args.method}")
    comm.Barrier()
    out["time_wall_s"] = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # KiB -> GiB
    peaks = comm.gather(peak, root=0)
    if comm.rank == 0:
        out["peak_gib_per_rank"] = peaks
        print("RESULT " + json.dumps(out), flush=True)


# ---------------------------------------------------------------------------------------------
# the driver
# ---------------------------------------------------------------------------------------------
def _mpiexec() -> str:
    local = Path(sys.executable).with_name("mpiexec")
    found = str(local) if local.exists() else shutil.which("mpiexec")
    if found is None:
        raise SystemExit("no mpiexec found")
    return found


def run_job(ranks: int, n: int, method: str, args: argparse.Namespace) -> dict:
    cmd = [
        _mpiexec(),
        "-n",
        str(ranks),
        sys.executable,
        __file__,
        "--worker",
        "--n",
        str(n),
        "--method",
        method,
        "--model",
        str(args.model),
        "--coarse",
        str(args.coarse),
        "--tol",
        str(args.tol),
        "--repeat",
        str(args.repeat),
    ]
    env = dict(os.environ, OMP_NUM_THREADS="1")
    print(f"  {' '.join(cmd[:3])} ... --n {n} --method {method}", flush=True)
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise SystemExit(f"job failed (exit {proc.returncode}):\n{(proc.stdout + proc.stderr)[-3000:]}")
    line = next(row for row in proc.stdout.splitlines() if row.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def weak_scaling(rows: list[dict], baseline: float, budget: float) -> list[str]:
    """Estimated total memory and ranks for finer meshes from the measured 1-rank memory."""
    ones = sorted((r for r in rows if r["ranks"] == 1 and r["method"] != "baseline"), key=lambda r: r["dofs"])
    lines = []
    for method in ("mono", "hybrid"):
        pts = [(r["dofs"], max(r["peak_gib_per_rank"]) - baseline) for r in ones if r["method"] == method]
        if not pts:
            continue
        if len(pts) >= 2 and pts[-1][0] > pts[-2][0] and pts[-2][1] > 0:
            p = float(np.log(pts[-1][1] / pts[-2][1]) / np.log(pts[-1][0] / pts[-2][0]))
            how = "fitted"
        else:
            p, how = 1.1, "assumed: one size measured"
        n0, m0 = pts[-1]
        par = [r for r in rows if r["method"] == method and r["ranks"] > 1 and r["dofs"] == n0]
        overhead = ""
        if par:  # distributed overhead: total over ranks / 1-rank memory (problem part)
            r = max(par, key=lambda r: r["ranks"])
            total = sum(r["peak_gib_per_rank"]) - r["ranks"] * baseline
            overhead = f"; {r['ranks']} ranks hold {total / m0:.2f}× the 1-rank problem memory"
            factor = total / m0
        else:
            factor = 1.0
        lines.append(f"**{method}**: memory − baseline ∝ DOFs^{p:.2f} ({how}), {m0:.2f} GiB at {n0:,} DOFs{overhead}.")
        lines.append("")
        lines.append("| 1/h | DOFs | est. total GiB | ranks for ≤ {:.0f} GiB/rank | GiB per rank |".format(budget))
        lines.append("|---|---|---|---|---|")
        n_meas = next(r["n"] for r in ones if r["dofs"] == n0)
        for inv_h in (256, 512, 1024):
            dofs = n0 * (inv_h / n_meas) ** 2
            mem = m0 * (dofs / n0) ** p * factor
            ranks = 1
            while mem / ranks + baseline > budget:
                ranks *= 2
            lines.append(
                f"| {inv_h} | {dofs:,.0f} | {mem + ranks * baseline:.1f} | {ranks} | {mem / ranks + baseline:.1f} |"
            )
        lines.append("")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--n", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--method", default="mono", help=argparse.SUPPRESS)
    parser.add_argument("--sizes", type=int, nargs="+", default=[64], help="values of 1/h")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--model", type=int, default=2)
    parser.add_argument("--coarse", type=int, default=16, help="1/H (strip width)")
    parser.add_argument("--tol", type=float, default=1e-6, help="Algorithm 2 tolerance")
    parser.add_argument("--repeat", type=int, default=20, help="omega2: warm solves timed")
    parser.add_argument("--memory-per-rank", type=float, default=8.0, help="GiB per rank in the weak-scaling estimate")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mixed_mpi_scaling.md"))
    args = parser.parse_args()
    if args.worker:
        worker(args)
        return

    from fenics_contact.io import machine_description

    start = time.perf_counter()
    base = run_job(1, 8, "baseline", args)
    baseline = max(base["peak_gib_per_rank"])
    rows = []
    loads = [os.getloadavg()[0]]
    for n in args.sizes:
        for method in args.methods:
            for ranks in args.ranks:
                rows.append(run_job(ranks, n, method, args))
                loads.append(os.getloadavg()[0])
    lines = [
        "# Mixed method under MPI: strong scaling and memory",
        "",
        f"{datetime.date.today()}; {machine_description()}; wall time of this report "
        f"{time.perf_counter() - start:.0f} s; 1-minute load average {min(loads):.1f}–{max(loads):.1f} while it ran "
        "(above 2 the machine was shared: contended times, the ratios within one row pair say little).",
        "",
        f"Command: `{' '.join([Path(sys.executable).name, *sys.argv])}`",
        "",
        f"Model {args.model}, H = 1/{args.coarse}; mono = monolithic mixed solve (set-up + Newton + UFL residual "
        f"check), hybrid = Algorithm 2 (β = √h, Anderson, tolerance {args.tol:g}, no reference). Times are wall "
        "times of the solve (mesh excluded); peak = high-water mark of the resident set (GiB), max over the "
        "ranks and summed; speed-up = time(1 rank) / time(N ranks) of the same table. "
        f"Baseline of one rank on a tiny mesh (Python, PETSc, MUMPS): {baseline:.2f} GiB.",
        "",
        "| 1/h | method | ranks | DOFs | Newton / its | set-up s | online s | total s | speed-up | warm solve s | "
        "peak GiB/rank | peak GiB total |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        one = next((r for r in rows if r["n"] == row["n"] and r["method"] == row["method"] and r["ranks"] == 1), None)
        speedup = f"{one['time_s'] / row['time_s']:.2f}" if one else "–"
        steps = row.get("newton", row.get("iterations"))
        warm = f"{row['time_warm_solve_s']:.3f}" if "time_warm_solve_s" in row else "–"
        lines.append(
            f"| {row['n']} | {row['method']} | {row['ranks']} | {row['dofs']:,} | {steps} | "
            f"{row['time_setup_s']:.1f} | {row['time_online_s']:.1f} | {row['time_s']:.1f} | {speedup} | {warm} | "
            f"{max(row['peak_gib_per_rank']):.2f} | {sum(row['peak_gib_per_rank']):.2f} |"
        )
    lines += ["", "## Weak-scaling estimate (memory)", ""]
    lines += weak_scaling(rows, baseline, args.memory_per_rank)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n")
    args.out.with_suffix(".json").write_text(json.dumps({"baseline_gib": baseline, "rows": rows}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
