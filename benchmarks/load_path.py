"""The whole force–indentation curve, offline phase included, for every method against the monolithic solve.

A cylinder (``Circle(centre, radius)``, by default ``Circle((3.0, 0.5), 2.0)``) indents the contact side x = 1
of a built-in test model in load steps (``force_indentation``: each method built once, warm starts, every step
certified).  Each method runs in a fresh process (its own peak memory); the table gives its set-up (offline)
time, the offline work done inside the steps (the interface Newton's condensation: Ω₁'s response in the
first step and Ω₂'s per-component contact columns; a moved obstacle recombines them by sums), the median and the sum of the
steps, the whole curve (wall and CPU time of the process; CPU also to the end of step 1 and per step)
against the monolithic Newton's of the same discretization (primal or mixed), the peak resident memory and the
largest relative force difference to the monolithic curve.  With ``--cached`` the multiscale methods run a
second time on the offline data the first run stored (``cache_dir``): the set-up of a later curve on the same
Ω₁ (another obstacle, other depths).

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 128 --H 16 --steps 20 --cached \\
        --methods primal-monolithic primal primal-ms --out benchmarks/results/load_path.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 128 --H 16 --steps 20 --cached \\
        --methods mixed-monolithic mixed mixed-ms --out benchmarks/results/load_path.md --append
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 128 --H 16 --steps 100 \\
        --methods primal-monolithic primal-ms --out benchmarks/results/load_path.md --append
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 --cached \\
        --methods primal-monolithic primal primal-ms --out benchmarks/results/load_path_256.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 \\
        --methods primal-monolithic primal-ms --patch-group 1 2 4

``--patch-group`` runs Algorithm 3 once per value of ``CEMOptions.patch_group`` (coarse cells per direction
sharing one patch factorization; ``all``: one patch, all of Ω₁), a row each.

``--parts`` splits each method's CPU time by the factorizations it works with (``fem.linalg.DirectSolver``, by
options prefix: its factorizations, the first with MUMPS' analysis, its back-solves and its blocks of inverses
from the factors; each wrapped by a CPU timer in the child process only) and the rest (assembly, the interface
Newton, Python): what a method's curve costs in MUMPS work against the monolithic Newton's factorizations.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 --model 2 \\
        --methods primal-monolithic primal --parts

``--max-memory GB`` stops a method's process once its resident memory passes GB (on a shared machine; Linux): its
row says so, and the other rows of its family are then not compared with a monolithic curve if that was the one
stopped.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 \\
        --methods mixed-monolithic mixed mixed-ms --max-memory 8

``--factor`` chooses how the primal monolithic Newton factorizes its (symmetric positive definite) Jacobians:
MUMPS' Cholesky (the package's default), its LU (``-fc_spd_factor lu``, ``fem.linalg.spd_factor``), or ``both``:
two monolithic rows, and every ratio is taken against the faster of the two (wall time for the wall ratio, CPU
time for the CPU ratio), the fair baseline chosen by measurement in the same run.  The other methods keep the
package's factorizations.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/load_path.py --h 256 --H 16 --steps 20 \\
        --methods primal-monolithic primal --factor both

Only the work itself is timed: the package's modules are imported and the mesh and the problem built before the
clock starts.  Algorithm 3's per-step check of its multiscale Ω₁ against the fine Ω₁ solve
(``IndentationStep.omega1_check``: one fine solve per step, verification rather than the method) is off unless
``--check``.  Ratios are within one run;
on a machine shared with other jobs the CPU-time ratio is the steadier one (the machine line says which).
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
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
#: how the primal monolithic Newton may factorize its SPD Jacobians (``fem.linalg.SPD_FACTORS``; the child process
#: sets ``fem.linalg.SPD_FACTOR_OPTION``), and their names in the table
SPD_FACTORS = ("cholesky", "lu")
FACTOR_NAMES = {"cholesky": "Cholesky", "lu": "LU"}
#: the options passed on to the child process (``--one``)
FORWARD = (
    "h",
    "H",
    "model",
    "contrast",
    "steps",
    "first",
    "last",
    "centre",
    "radius",
    "direction",
    "layers",
    "nbasis",
    "tol",
    "accel",
    "check",
    "parts",
)
#: the ``DirectSolver`` methods ``--parts`` times, and their names in the table (one call, several)
PART_CALLS = {
    "set_operator": ("factorization", "factorizations"),
    "solve": ("back-solve", "back-solves"),
    "solve_sparse": ("back-solve (sparse right-hand side)", "back-solves (sparse right-hand side)"),
    "mat_solve": ("multi-right-hand-side solve", "multi-right-hand-side solves"),
    "inverse_block": ("block of the inverse", "blocks of the inverse"),
}


def time_direct_solvers() -> dict:
    """Wrap ``DirectSolver``'s factorizations and solves by CPU timers (this process only): {prefix: {call: [CPU
    time of each call]}}, filled as they run."""
    from fenics_contact.fem.linalg import DirectSolver

    times: dict = {}

    def timed(name, method):
        def wrapper(self, *args, **kwargs):
            start = time.process_time()
            try:
                return method(self, *args, **kwargs)
            finally:
                calls = times.setdefault(self.prefix, {})
                calls.setdefault(name, []).append(time.process_time() - start)

        return wrapper

    for name in PART_CALLS:
        setattr(DirectSolver, name, timed(name, getattr(DirectSolver, name)))
    return times


def one(args) -> dict:
    """One method's curve in this process (``--one``): times, forces, peak memory."""
    import fenics_contact as fc
    from fenics_contact.fem.linalg import SPD_FACTOR_OPTION
    from fenics_contact.indentation import force_indentation  # (imported before the clock: the work alone is timed)
    from fenics_contact.io import peak_rss_bytes
    from fenics_contact.problem.models import get_model

    cm = fc.unit_square(args.h, args.H)
    obstacle = fc.Circle(tuple(args.centre), args.radius)
    problem = get_model(args.model, E_high=args.contrast).with_(obstacle=obstacle).on(cm)
    depths = np.linspace(args.first, args.last, args.steps)
    options = {}
    if args.one.endswith("-ms"):
        options["layers"], options["nbasis"] = args.layers, args.nbasis
        if args.cache_dir:
            options["cache_dir"] = args.cache_dir
    if args.one == "primal-ms":
        options["check"] = args.check
        options["patch_group"] = args.patch_group[0] if args.patch_group[0] == "all" else int(args.patch_group[0])
    if not args.one.endswith("monolithic"):
        options["tol"] = args.tol
        if args.accel:
            options["accel"] = args.accel
    if args.one == "primal-monolithic":  # (before the solvers are made)
        from petsc4py import PETSc

        PETSc.Options()[SPD_FACTOR_OPTION] = args.factor
    parts = time_direct_solvers() if args.parts else {}
    marks = []  # the process's CPU time at the end of every step
    wall, cpu = time.perf_counter(), time.process_time()
    curve = force_indentation(
        problem,
        args.one,
        depths,
        direction=tuple(args.direction),
        on_step=lambda record, solver: marks.append(time.process_time()),
        **options,
    )
    wall, cpu_end = time.perf_counter() - wall, time.process_time()
    step_cpu = np.diff(marks)  # steps 2…N, their offline work included
    steps = [s.time_s for s in curve.steps]
    return {
        "method": args.one,
        # the factorization the monolithic Newton ran ("cholesky" or "lu": its PC type)
        "factor": curve.contact.solver.ksp.getPC().getType() if args.one == "primal-monolithic" else None,
        "setup_s": curve.time_offline_s,
        "offline_in_steps_s": float(sum(s.time_offline_s for s in curve.steps)),
        "step_median_s": float(np.median(steps)),
        "steps_s": float(np.sum(steps)),
        "total_s": wall,
        "cpu_s": cpu_end - cpu,
        "cpu_to_first_step_s": marks[0] - cpu,
        "cpu_step_median_s": float(np.median(step_cpu)) if step_cpu.size else float("nan"),
        "forces": curve.forces.tolist(),
        "converged": all(s.converged for s in curve.steps),
        "iterations": [s.iterations for s in curve.steps],
        "peak_rss_gb": peak_rss_bytes() / 1e9,
        "offline_parts": dict(getattr(curve.step, "offline_times", {})),  # Algorithm 3's set-up by phase
        # and parts of those phases (Algorithm 3: the patch factorizations and solves, the Gram matrices)
        "offline_subparts": dict(getattr(getattr(curve.step, "omega1", None), "time_parts", {})),
        # --check: the largest energy distance of the multiscale Ω₁ to the fine Ω₁ solve over the steps
        "omega1_check": max((s.omega1_check for s in curve.steps if s.omega1_check is not None), default=None),
        "parts": parts,  # --parts: {solver prefix: {DirectSolver call: [CPU time of each call]}}
    }


def run_child(method: str, args, cache_dir: str | None, patch_group: str = "1", factor: str | None = None) -> dict:
    cmd = [sys.executable, __file__, "--one", method, f"--patch-group={patch_group}"]
    cmd += [f"--factor={factor}"] if factor else []
    for name in FORWARD:
        value = getattr(args, name)
        if isinstance(value, bool):
            cmd += [f"--{name}"] if value else []
        elif isinstance(value, list | tuple):
            cmd += [f"--{name}", *map(str, value)]
        elif value is not None:
            cmd += [f"--{name}={value}"]
    if cache_dir:
        cmd += [f"--cache-dir={cache_dir}"]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        start = time.perf_counter()
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True, env=os.environ, cwd=ROOT)
        peak = 0.0
        while proc.poll() is None:
            peak = max(peak, resident_gb(proc.pid))
            if args.max_memory is not None and peak > args.max_memory:
                cpu = cpu_seconds(proc.pid)
                proc.kill()  # (this child only)
                proc.wait()
                return {
                    "method": method,
                    "stopped_gb": peak,
                    "stopped_after_s": time.perf_counter() - start,
                    "stopped_cpu_s": cpu,
                }
            time.sleep(0.5)
        out.seek(0)
        err.seek(0)
        line = next((row for row in out.read().splitlines() if row.startswith("RESULT ")), None)
        if line is None:
            raise SystemExit(f"{method} failed:\n{err.read()[-3000:]}")
    return json.loads(line[7:])


def cpu_seconds(pid: int) -> float:
    """The CPU time of process ``pid`` so far [s] (Linux: /proc, user and system; nan where it cannot be read)."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            fields = stat.read().rsplit(")", 1)[1].split()
    except OSError:
        return float("nan")
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")  # (utime, stime: fields 14, 15)


def resident_gb(pid: int) -> float:
    """The resident memory of process ``pid`` [GB] (Linux: /proc; 0 where it cannot be read)."""
    try:
        with open(f"/proc/{pid}/status") as status:
            kb = next((int(row.split()[1]) for row in status if row.startswith("VmRSS:")), 0)
    except OSError:
        return 0.0
    return kb * 1024 / 1e9


def table(args, results: dict) -> str:
    lines = [
        f"# Load path: {args.steps} steps of a cylinder into model {args.model} (contrast {args.contrast:g}), "
        f"h = 1/{args.h}, H = 1/{args.H}",
        "",
        f"Command: `OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} .venv/bin/python "
        f"benchmarks/load_path.py {' '.join(sys.argv[1:])}`",
        "",
        f"Obstacle `Circle({tuple(args.centre)}, {args.radius})` moved along {tuple(args.direction)} from depth "
        f"{args.first:g} to {args.last:g}; hybrid methods: tol {args.tol:g}, accel {args.accel or 'the default'}; "
        f"multiscale: m = {args.layers}, l = {args.nbasis} (Algorithm 3's patch groups: "
        f"{', '.join(args.patch_group)}); Algorithm 3's fine Ω₁ check "
        f"{'on' if args.check else 'off'}.",
        "",
        f"Machine: {machine()}",
        "",
        "| method | set-up [s] | offline in steps [s] | step median [s] | steps [s] | whole curve [s] "
        "| / monolithic | CPU [s] | CPU / monolithic | CPU to step 1 [s] | CPU step median [s] | peak memory [GB] "
        "| max force difference |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for label, r in results.items():
        method = r["method"]
        if "stopped_gb" in r:  # (--max-memory)
            lines.append(
                f"| {label} (stopped: its resident memory passed {r['stopped_gb']:.1f} GB after "
                f"{r['stopped_after_s']:.0f} s, {r['stopped_cpu_s']:.0f} s of CPU time) |" + " — |" * 12
            )
            continue
        monos = [m for m in results.values() if m["method"] == f"{FAMILY[method]}-monolithic" and "stopped_gb" not in m]
        wall_base = min(monos, key=lambda m: m["total_s"]) if monos else None  # the faster monolithic curve
        cpu_base = min(monos, key=lambda m: m["cpu_s"]) if monos else None
        ratio = f"{r['total_s'] / wall_base['total_s']:.3f}" if monos else "—"
        cpu_ratio = f"{r['cpu_s'] / cpu_base['cpu_s']:.3f}" if monos else "—"
        diff = (
            f"{np.max(np.abs(np.subtract(r['forces'], wall_base['forces'])) / np.abs(wall_base['forces'])):.1e}"
            if monos and method != f"{FAMILY[method]}-monolithic"
            else "—"
        )
        converged = "" if r["converged"] else " (not all steps converged)"
        lines.append(
            f"| {label}{converged} | {r['setup_s']:.2f} | {r['offline_in_steps_s']:.2f} | {r['step_median_s']:.4f} "
            f"| {r['steps_s']:.2f} | {r['total_s']:.2f} | {ratio} | {r['cpu_s']:.2f} | {cpu_ratio} "
            f"| {r['cpu_to_first_step_s']:.2f} | {r['cpu_step_median_s']:.4f} | {r['peak_rss_gb']:.2f} | {diff} |"
        )
    for label, r in results.items():
        parts = r.get("offline_parts") or {}
        if parts:
            text = ", ".join(f"{k} {v:.2f}" for k, v in parts.items() if isinstance(v, int | float))
            sub = r.get("offline_subparts") or {}
            if sub:
                text += " (of which " + ", ".join(f"{k} {v:.2f}" for k, v in sub.items()) + ")"
            lines += ["", f"Set-up of {label} by phase [s]: {text}"]
        if r.get("omega1_check") is not None:
            lines += [
                "",
                f"{label}: Ω₁ against the fine Ω₁ solve (energy, largest over the steps): {r['omega1_check']:.2e}",
            ]
    for label, r in results.items():
        if r.get("parts"):
            lines += ["", parts_line(label, r)]
    factors = [r["factor"] for r in results.values() if r.get("factor")]
    if len(factors) == 1:
        lines += ["", f"The primal monolithic Newton factorizes its Jacobians by MUMPS' {FACTOR_NAMES[factors[0]]}."]
    elif factors:
        primal = [(label, r) for label, r in results.items() if r["method"] == "primal-monolithic"]
        wall = min(primal, key=lambda x: x[1]["total_s"])[0]
        cpu = min(primal, key=lambda x: x[1]["cpu_s"])[0]
        lines += [
            "",
            f"The primal ratios are against the faster monolithic curve: {wall} by wall time, {cpu} by CPU time "
            "(the force differences against the former).",
        ]
    lines += [
        "",
        "Set-up: building the solver before the first step (the multiscale Ω₁'s offline phase, factorizations); "
        "offline in steps: the interface Newton's condensation done inside the steps (Ω₁'s response in the first, "
        "Ω₂'s contact columns per displacement component, which a moved obstacle recombines by sums); steps: the "
        "online work (wall times).  CPU: "
        "the process's CPU time, for the whole curve, to the end of step 1 (set-up and first step) and per step "
        "(steps 2…N, offline work included).  The force difference is relative to the monolithic force of each "
        "step.",
    ]
    return "\n".join(lines) + "\n"


def outcome(r: dict) -> str:
    """A child run in a few words (progress output)."""
    if "stopped_gb" in r:
        return (
            f"stopped, resident memory above {r['stopped_gb']:.1f} GB after {r['stopped_after_s']:.0f} s "
            f"({r['stopped_cpu_s']:.0f} s of CPU time)"
        )
    return f"whole curve {r['total_s']:.2f} s"


def parts_line(label: str, r: dict) -> str:
    """``--parts``: a method's CPU time by factorization (prefix) and call, and the rest."""
    texts, timed = [], 0.0
    for prefix, calls in r["parts"].items():
        items = []
        for name, what in PART_CALLS.items():
            cpu = calls.get(name, [])
            if not cpu:
                continue
            timed += sum(cpu)
            item = f"{len(cpu)} {what[len(cpu) > 1]} {sum(cpu):.3f}"
            if name == "set_operator" and len(cpu) > 1:
                item += f" (the first, with the analysis, {cpu[0]:.3f}; the others' median {np.median(cpu[1:]):.3f})"
            elif len(cpu) > 1:
                item += f" (median {np.median(cpu):.4f})"
            items.append(item)
        texts.append(f"`{prefix}`: " + ", ".join(items))
    return (
        f"CPU of {label} by factorization [s]: " + "; ".join(texts) + f"; the rest {r['cpu_s'] - timed:.2f} "
        f"(of {r['cpu_s']:.2f})"
    )


def machine() -> str:
    from fenics_contact.io import machine_description

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    text = f"{machine_description()}; load average {load:.1f} at the end of the run"
    if load > 1.5:  # more than the one process of the run
        text += (
            ". The machine was shared with other jobs: the wall times are contended, compare the CPU times (and "
            "ratios within this table only)"
        )
    return text


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, default=128, help="1/h of the unit-square mesh")
    parser.add_argument("--H", type=int, default=16, help="1/H: the strip width and coarse size")
    parser.add_argument("--model", type=int, default=3)
    parser.add_argument("--contrast", type=float, default=1e3, help="E in the model's pattern (E = 1 elsewhere)")
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--first", type=float, default=0.002, help="first indentation depth")
    parser.add_argument("--last", type=float, default=0.02, help="last indentation depth")
    parser.add_argument("--centre", type=float, nargs=2, default=[3.0, 0.5], help="the cylinder's centre")
    parser.add_argument("--radius", type=float, default=2.0, help="the cylinder's radius")
    parser.add_argument("--direction", type=float, nargs=2, default=[-1.0, 0.0], help="the obstacle's motion")
    parser.add_argument("--layers", type=int, default=4)
    parser.add_argument("--nbasis", type=int, default=3)
    parser.add_argument("--tol", type=float, default=1e-8, help="tolerance of the certificate (hybrid methods)")
    parser.add_argument("--accel", default="newton", help="the hybrid methods' update (IterationOptions.accel)")
    parser.add_argument("--check", action="store_true", help="Algorithm 3's fine Ω₁ check at every step")
    parser.add_argument(
        "--parts", action="store_true", help="split each method's CPU time by factorization (DirectSolver calls)"
    )
    parser.add_argument("--cached", action="store_true", help="run the multiscale methods again on cached data")
    parser.add_argument(
        "--patch-group",
        nargs="+",
        default=["1"],
        help="primal-ms: coarse cells per direction sharing one patch factorization (CEMOptions.patch_group; "
        "'all': one patch), one row per value",
    )
    parser.add_argument(
        "--methods", nargs="+", default=["primal-monolithic", "primal", "primal-ms"], choices=list(FAMILY)
    )
    parser.add_argument(
        "--factor",
        choices=[*SPD_FACTORS, "both"],
        default="cholesky",
        help="how the primal monolithic Newton factorizes its SPD Jacobians (both: a row each, the ratios against "
        "the faster)",
    )
    parser.add_argument(
        "--max-memory",
        type=float,
        default=None,
        help="stop a method whose process's resident memory passes this many GB (a row saying so; Linux)",
    )
    parser.add_argument("--out", type=Path, default=None, help="a markdown results file (default: print)")
    parser.add_argument("--append", action="store_true", help="add the table to --out instead of replacing it")
    parser.add_argument("--one", choices=list(FAMILY), help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print("RESULT " + json.dumps(one(args)))
        return
    results = {}
    with tempfile.TemporaryDirectory(prefix="load_path_cache_") as cache:
        for method in args.methods:
            multiscale = method.endswith("-ms")
            if method == "primal-monolithic":
                for factor in SPD_FACTORS if args.factor == "both" else [args.factor]:
                    name = method if args.factor != "both" else f"{method} ({FACTOR_NAMES[factor]})"
                    results[name] = run_child(method, args, None, factor=factor)
                    print(f"{name}: {outcome(results[name])}", flush=True)
                continue
            for group in args.patch_group if method == "primal-ms" else ["1"]:
                name = method if group == "1" else f"{method}, patch group {group}"
                # (the offline data are written only for the run on them: a cold curve writes no cache file)
                results[name] = run_child(method, args, cache if multiscale and args.cached else None, group)
                print(f"{name}: {outcome(results[name])}", flush=True)
                if multiscale and args.cached:
                    label = f"{name}, offline data from the cache"
                    results[label] = run_child(method, args, cache, group)
                    print(f"{label}: {outcome(results[label])}", flush=True)
    text = table(args, results)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        if args.append and args.out.is_file():
            text = args.out.read_text() + "\n" + text.replace("# Load path", "## Load path", 1)
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
