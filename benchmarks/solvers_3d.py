"""The 3D monolithic contact solve with MUMPS and with CG + AMG at growing sizes.

The sphere on the quarter block of ``problem.analytic.hertz_sphere_model`` (a = 0.1, R = 10a, block 20a,
δ = 10⁻³ h_c/E*) with contact cells h_c = a/n, solved by ``primal-monolithic`` with ``solver="direct"`` (MUMPS LU
per Newton step) and ``solver="amg"`` (CG + smoothed-aggregation AMG, the rigid-body near-nullspace): DOFs, the
solve's wall time, Newton steps, CG iterations per step, the process's peak memory (``ru_maxrss``; each run in a
process of its own) and the contact force.  A run whose memory, extrapolated from the last size (LU:
∝ DOFs^1.5; AMG: ∝ DOFs), would exceed ``--max-memory-gb`` is skipped.

    OMP_NUM_THREADS=1 python benchmarks/solvers_3d.py --cells 10 15 20 25 30 40 --out benchmarks/results/solvers_3d.md
    OMP_NUM_THREADS=1 python benchmarks/solvers_3d.py --mesh graded --cells 8 --out benchmarks/results/solvers_3d_graded.md
    OMP_NUM_THREADS=1 python benchmarks/solvers_3d.py --cells 50 60 --solvers amg --out benchmarks/results/solvers_3d_large.md
    python benchmarks/solvers_3d.py --fit benchmarks/results/solvers_3d.md benchmarks/results/solvers_3d_large.md

``--fit`` reads result tables and fits, per solver over its two largest sizes, peak memory − ``BASE_GB`` (the
process before any solve) and the solve time as c·DOFs^p, and prints the DOFs that reach 10 GB and 24 GB.
"""

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from common import write_report

from fenics_contact.io import machine_description, peak_rss_bytes

A, R, E, NU = 0.1, 1.0, 1.0, 0.3
SOLVERS = ("direct", "amg")
#: the peak memory of the process before the solve (Python, DOLFINx, PETSc, a small mesh), subtracted in the fits
BASE_GB = 0.2


def _graded(h: float):
    """The sphere on the quarter block (0, 40a)² × (−40a, 0) over a graded grid of planes (``fc.box_mesh``:
    spacing h on 1.25a, growing by 1.3 per cell beyond; its cells stretched where a fine plane crosses a
    coarse one): the mesh of ``tests/fem/test_primal_3d.py``."""
    import fenics_contact as fc
    from fenics_contact.problem.meshes3d import graded_planes

    planes = graded_planes(40 * A, fine=1.25 * A, h=h, growth=1.3)
    region = lambda p: (p[0] <= 3 * A + 1e-12) & (p[1] <= 3 * A + 1e-12)  # noqa: E731
    cm = fc.box_mesh(planes, planes, -planes[::-1], contact="zmax", contact_region=region, strip=2 * A)
    sphere = fc.Sphere((0.0, 0.0, R), R).indented(A * A / R, (0.0, 0.0, -1.0))
    rollers = fc.BoundaryConditions(rollers=((0, 0.0), (1, 0.0)))
    return fc.ContactProblem(youngs_modulus=E, poisson_ratio=NU, obstacle=sphere, mesh=cm, boundary=rollers)


def run_one(cells: int, solver: str, mesh: str = "block") -> dict:
    """One solve in this process: its sizes, time, Newton steps, CG iterations, peak memory and force."""
    import fenics_contact as fc
    from fenics_contact.problem.analytic import hertz_sphere_errors, hertz_sphere_model, hertz_sphere_penalty

    h = A / cells
    start = time.perf_counter()
    problem = hertz_sphere_model(A, h, radius=R, E=E, nu=NU) if mesh == "block" else _graded(h)
    mesh_s = time.perf_counter() - start
    solution = fc.solve(problem, "primal-monolithic", delta=hertz_sphere_penalty(h, E=E, nu=NU), solver=solver)
    errors = hertz_sphere_errors(solution.profile, radius=R, E=E, nu=NU, h_contact=h)
    return {
        "cells": cells,
        "solver": solution.linear_solver,
        "dofs": solution.dofs,
        "mesh_s": mesh_s,
        "solve_s": solution.time_s,
        "newton": solution.newton.steps,
        "krylov": solution.krylov_iterations,
        "active": solution.newton.active_sizes[-1],
        "peak_gb": peak_rss_bytes() / 1e9,
        "force": errors.force,
        "l2": errors.l2_error,
    }


def _subprocess(cells: int, solver: str, mesh: str) -> dict:
    command = [sys.executable, str(Path(__file__).resolve()), "--single", str(cells), solver, "--mesh", mesh]
    proc = subprocess.run(command, capture_output=True, text=True)
    line = next((row for row in proc.stdout.splitlines() if row.startswith("RESULT ")), None)
    if line is None:
        raise SystemExit(f"a/{cells} {solver} failed:\n{proc.stderr[-3000:]}")
    return json.loads(line.removeprefix("RESULT "))


def fit(paths: list[str]) -> list[str]:
    """Per solver: the growth exponents of memory and time over its two largest sizes in the tables at ``paths``,
    and the DOFs at which the fitted memory reaches 10 GB and 24 GB."""
    rows = {}
    for path in paths:
        for line in Path(path).read_text().splitlines():
            cells = [c.strip() for c in line.strip("|").split("|")]
            if len(cells) >= 7 and cells[0].startswith("a/") and cells[2] in SOLVERS:
                dofs = int(cells[1].replace(",", ""))
                rows.setdefault(cells[2], {})[dofs] = (float(cells[3]), float(cells[6]))
    lines = []
    for solver, by_dofs in rows.items():
        if len(by_dofs) < 2:
            continue
        (n0, (t0, m0)), (n1, (t1, m1)) = sorted(by_dofs.items())[-2:]
        p_mem = np.log((m1 - BASE_GB) / (m0 - BASE_GB)) / np.log(n1 / n0)
        p_time = np.log(t1 / t0) / np.log(n1 / n0)
        at = {gb: n1 * ((gb - BASE_GB) / (m1 - BASE_GB)) ** (1.0 / p_mem) for gb in (10.0, 24.0)}
        lines.append(
            f"{solver}: from {n0:,} to {n1:,} DOFs memory ∝ DOFs^{p_mem:.2f}, time ∝ DOFs^{p_time:.2f}; "
            f"10 GB at {at[10.0]:,.0f} DOFs, 24 GB at {at[24.0]:,.0f} DOFs"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[10, 20, 30, 40], help="contact cells h_c = a/n")
    parser.add_argument("--max-memory-gb", type=float, default=8.0, help="skip a run predicted above this")
    parser.add_argument("--out", default="benchmarks/results/solvers_3d.md")
    parser.add_argument(
        "--mesh",
        choices=("block", "graded"),
        default="block",
        help="block: hertz_quarter_block (gmsh, well-shaped cells); graded: a graded grid of planes (stretched cells)",
    )
    parser.add_argument("--solvers", nargs="+", choices=SOLVERS, default=list(SOLVERS), help="the solvers to run")
    parser.add_argument("--fit", nargs="+", metavar="TABLE", help="fit the growth in these result tables")
    parser.add_argument("--single", nargs=2, metavar=("CELLS", "SOLVER"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.fit:
        print("\n".join(fit(args.fit)))
        return
    if args.single:
        print("RESULT " + json.dumps(run_one(int(args.single[0]), args.single[1], args.mesh)))
        return
    rows, last = [], {}
    for cells in args.cells:
        forces = {}
        for solver in args.solvers:
            if solver in last:  # extrapolate the memory from the last size (DOFs ∝ cells³)
                prev = last[solver]
                ratio = (cells / prev["cells"]) ** 3
                predicted = prev["peak_gb"] * ratio ** (1.5 if solver == "direct" else 1.0)
                if predicted > args.max_memory_gb:
                    print(f"a/{cells} {solver}: skipped (about {predicted:.1f} GB predicted)", flush=True)
                    continue
            result = _subprocess(cells, solver, args.mesh)
            last[solver] = result
            forces[solver] = result["force"]
            rows.append(result)
            print(json.dumps(result), flush=True)
        if len(forces) == 2:
            rows[-1]["force_diff"] = abs(forces["amg"] / forces["direct"] - 1.0)
    lines = [
        "# The 3D monolithic contact solve: MUMPS against CG + AMG",
        "",
        f"`OMP_NUM_THREADS=1 python {' '.join(sys.argv)}`",
        "",
        f"Machine: {machine_description()}. The machine was shared with other jobs while this ran: the times",
        "are upper bounds; compare the two solvers at one size, not with other tables.",
        "",
        (
            "The sphere on the quarter block (`hertz_sphere_model`: a = 0.1, R = 10a, block 20a, δ = 10⁻³ h_c/E*),"
            if args.mesh == "block"
            else "The sphere (a = 0.1, R = 10a, δ = 10⁻³ h_c/E*) on the quarter block 40a over a graded grid of planes,"
        ),
        'contact cells h_c = a/n; `primal-monolithic` with `solver="direct"` (MUMPS LU per Newton step) and',
        '`solver="amg"` (CG + smoothed-aggregation AMG with the rigid-body near-nullspace, rtol 10⁻⁸). Solve:',
        "the wall time of the Newton solve (mesh not included); peak memory: the process's ru_maxrss (one",
        "process per run); force difference: |F_AMG/F_MUMPS − 1| at the size.",
        "",
        "| h_c | DOFs | solver | solve (s) | Newton steps | CG iterations per step | peak memory (GB) | contact nodes | "
        "force difference |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        its = f"{min(r['krylov'])}–{max(r['krylov'])}" if r["krylov"] else "—"
        diff = f"{r['force_diff']:.1e}" if "force_diff" in r else ""
        lines.append(
            f"| a/{r['cells']} | {r['dofs']:,} | {r['solver']} | {r['solve_s']:.1f} | {r['newton']} | {its} | "
            f"{r['peak_gb']:.2f} | {r['active']} | {diff} |"
        )
    amg = [r for r in rows if r["solver"] == "amg"]
    if amg:
        lines += ["", f"AMG CG iterations over all steps: median {np.median(sum((r['krylov'] for r in amg), [])):g}."]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
