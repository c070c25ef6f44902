"""Cost of Algorithm 4 as the fine mesh is refined: offline, online, memory, cache, MPI, next to the monolithic solve.

    OMP_NUM_THREADS=1 python benchmarks/mixed_ms_scaling.py --sizes 32,64,128 --ranks 2 \\
        --out benchmarks/results/mixed_ms_scaling.md

Model 2 (built-in loads), H = 1/16, m = 3, β = √h, default Stage I rule and source correctors.
Every measurement runs in a fresh process (its peak resident memory is that of the one phase):

* ``monolithic``: the fine monolithic mixed solve (set-up + semismooth Newton), the reference of
  Table 5.8 and the cost scale;
* ``mixed-ms``: Algorithm 4 with an offline cache (built): offline time and its parts, online time
  (the iteration), peak RSS, cache size; then a second process that loads the cache;
* ``mixed-ms`` under ``mpiexec -n R`` (``--ranks R``): the offline phase shared out, without a cache
  (so the patch functions stay on the rank that computed them); speed-up = serial offline without its
  cache write / parallel offline, both of the same run of this script;
* ``--repeats K`` (sizes of ``--mpi-sizes``): K interleaved pairs, a serial process without a cache then
  the R-rank one, each pair's ratio and their median (on a VM whose speed drifts by 10–20 % within
  minutes, one pair is one sample, not the speed-up).  Before each pair, the machine's own ceiling:
  a fixed CPU-bound probe (dense 300 × 300 LU solves and a Python loop, ~1.5 s) run in one process, then
  in R processes at once (``mpiexec``); the ceiling is Σ_r t_alone / t_r, the speed-up that perfectly
  shared work would get from these cores at that moment (two vCPUs of this VM at once ran the probe at
  1.0× to 0.65× of one alone, varying from minute to minute).

Cost exponents are least-squares slopes of log(cost) against log(DOFs) over the sizes run
(DOFs: the fine mixed problem on Ω, AW + displacement). Times on a shared machine vary by 1.5–2×;
ratios are taken within one run of this script.
"""

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

RESULT = "RESULT "


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process so far."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _peak_rss_gb(comm=None) -> float:
    from fenics_contact.io import peak_rss_bytes

    rss = peak_rss_bytes() / 1e9  # GB (10⁹ bytes)
    if comm is not None and comm.size > 1:
        from mpi4py import MPI

        rss = comm.allreduce(rss, op=MPI.MAX)
    return rss


def probe() -> float:
    """Seconds for a fixed CPU-bound load (dense LU solves like MUMPS' fronts, then interpreted Python)."""
    rng = np.random.default_rng(0)
    A = rng.random((300, 300)) + 300.0 * np.eye(300)
    t = time.perf_counter()
    for _ in range(200):
        np.linalg.solve(A, A)
    x = 0
    for i in range(4_000_000):
        x += i
    return time.perf_counter() - t


def worker(args: argparse.Namespace) -> dict:
    """One measurement in this process (``--worker``)."""
    from mpi4py import MPI

    import fenics_contact  # noqa: F401  (must precede dolfinx / petsc4py)
    from fenics_contact.fem.mixed import solve_mixed_monolithic
    from fenics_contact.hybrid.iteration import IterationOptions
    from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
    from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
    from fenics_contact.problem import geometry, models

    comm = MPI.COMM_WORLD
    if args.worker == "probe":
        comm.Barrier()
        return {"probe_s": comm.allgather(probe())}
    model = models.get_model(2)
    t0 = time.perf_counter()
    cm = geometry.unit_square(args.n, args.n_coarse, comm=MPI.COMM_SELF)
    out = {"n": args.n, "ranks": comm.size, "time_mesh_s": time.perf_counter() - t0}
    if args.worker == "monolithic":
        cpu0 = _cpu_s()
        ref = solve_mixed_monolithic(model.on(cm))
        out.update(
            dofs=ref.dofs["total"],
            time_s=ref.time_s,
            time_newton_s=ref.time_newton_s,
            newton_steps=ref.newton.steps,
            cpu_s=_cpu_s() - cpu0,
        )
        ref.free()
    else:
        res = solve_mixed_ms_hybrid(
            model.on(cm),
            cem=MixedCEMOptions(layers=args.layers),
            offline_comm=comm,
            cache_dir=args.cache_dir,
            options=IterationOptions(max_iterations=1000),
        )
        om = res.step.omega1
        cache = om.cache_path
        out.update(
            dofs_fine=res.dofs["omega1"] + res.dofs["omega2"],
            dofs_ms=res.dofs["omega1_ms"],
            dofs_omega2=res.dofs["omega2"],
            iterations=res.iterations,
            converged=res.converged,
            time_offline_s=res.time_offline_s,
            time_online_s=res.time_online_s,
            offline_times={k: round(v, 2) for k, v in res.offline_times.items()},
            offline_cpu={k: round(v, 2) for k, v in om.cpu_times.items()},
            cpu_offline_omega1_s=sum(v for k, v in om.cpu_times.items() if k != "load"),
            cpu_total_s=_cpu_s(),
            cache_status=om.cache_status,
            cache_gb=cache.stat().st_size / 1e9 if cache is not None and cache.is_file() else None,
            functions_gb=sum(f.nbytes for f in om.basis + om.corr if f is not None) / 1e9,
            nbasis=list(om.nbasis_range),
        )
    out["peak_rss_gb"] = _peak_rss_gb(comm)
    return out


def _run(cmd: list[str]) -> dict:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed:\n{proc.stderr[-4000:]}")
    line = next(l for l in proc.stdout.splitlines() if l.startswith(RESULT))
    return json.loads(line[len(RESULT) :])


def _slope(x: list[float], y: list[float]) -> float | None:
    if len(x) < 2:
        return None
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="32,64,128", help="fine cells per side (h = 1/n), comma list")
    parser.add_argument("--n-coarse", type=int, default=16)
    parser.add_argument("--layers", type=int, default=3)
    parser.add_argument("--ranks", type=int, default=2, help="MPI ranks for the shared offline phase (0: skip)")
    parser.add_argument("--mpi-sizes", default=None, help="sizes for the MPI run (default: the largest)")
    parser.add_argument(
        "--repeats",
        type=int,
        default=0,
        help="interleaved (serial without cache, R ranks) pairs per MPI size, median ratio (0: none)",
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mixed_ms_scaling.md"))
    parser.add_argument("--worker", choices=("monolithic", "mixed-ms", "probe"), help=argparse.SUPPRESS)
    parser.add_argument("--n", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--cache-dir", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        result = worker(args)
        from mpi4py import MPI

        if MPI.COMM_WORLD.rank == 0:
            print(RESULT + json.dumps(result), flush=True)
        return

    from common import write_report

    from fenics_contact.io import machine_description

    sizes = [int(s) for s in args.sizes.split(",")]
    mpi_sizes = [int(s) for s in args.mpi_sizes.split(",")] if args.mpi_sizes else sizes[-1:]
    me = [sys.executable, os.path.abspath(__file__), "--n-coarse", str(args.n_coarse), "--layers", str(args.layers)]
    mpiexec = (
        str(Path(sys.executable).with_name("mpiexec"))
        if Path(sys.executable).with_name("mpiexec").exists()
        else shutil.which("mpiexec")
    )
    rows = []
    start = time.perf_counter()
    for n in sizes:
        tmp = tempfile.mkdtemp(prefix="mixed_ms_scaling_")
        try:
            mono = _run([*me, "--worker", "monolithic", "--n", str(n)])
            built = _run([*me, "--worker", "mixed-ms", "--n", str(n), "--cache-dir", tmp])
            loaded = _run([*me, "--worker", "mixed-ms", "--n", str(n), "--cache-dir", tmp])
            par = None
            if args.ranks > 1 and n in mpi_sizes and mpiexec is not None:
                par = _run([mpiexec, "-n", str(args.ranks), *me, "--worker", "mixed-ms", "--n", str(n)])
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        pairs = []
        if args.ranks > 1 and n in mpi_sizes and mpiexec is not None:
            for _ in range(args.repeats):
                alone = _run([*me, "--worker", "probe"])["probe_s"][0]
                together = _run([mpiexec, "-n", str(args.ranks), *me, "--worker", "probe"])["probe_s"]
                ceiling = sum(alone / t for t in together)
                serial = _run([*me, "--worker", "mixed-ms", "--n", str(n)])
                ranks = _run([mpiexec, "-n", str(args.ranks), *me, "--worker", "mixed-ms", "--n", str(n)])
                pairs.append(
                    (
                        serial["time_offline_s"],
                        ranks["time_offline_s"],
                        serial["offline_times"],
                        ranks["offline_times"],
                        ceiling,
                    )
                )
                print(json.dumps({"n": n, "pair": pairs[-1][:2], "ceiling": ceiling}), flush=True)
        row = {"n": n, "mono": mono, "built": built, "loaded": loaded, "par": par, "pairs": pairs}
        rows.append(row)
        print(json.dumps(row), flush=True)

    load = os.getloadavg()
    lines = [
        "# Algorithm 4 cost against the fine mesh (`benchmarks/mixed_ms_scaling.py`)",
        "",
        f"Machine: {machine_description()}. Load average at the end of the run: "
        f"{load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} (1 / 5 / 15 min; above the core count the wall times are "
        f"contended, the CPU times less so). Model 2, H = 1/{args.n_coarse}, m = {args.layers}, β = √h, default "
        "Stage I rule, source correctors on. Each entry is a separate process (peak RSS of that process; "
        "under MPI the largest over the ranks; no reference solve in the Algorithm 4 process). Offline: "
        "assembly of the cell operators, Stage I, Stage II, coarse operators, cache write (wall s, CPU s in "
        "parentheses); the subproblem set-up (meshes, AW spaces of Ω₁ and Ω₂) is 'setup' (wall only).",
        "",
        "| h | DOFs (fine) | monolithic s (Newton s) [CPU s] | mono. peak GB | offline s [Ω₁ CPU s] | offline / mono. | "
        "setup; assembly, Stage I, Stage II, coarse, save s (CPU) | online s | online / mono. Newton | peak GB | "
        f"cache GB | cache load s | offline s, {args.ranks} ranks, no cache (peak GB per rank) | "
        "speed-up (serial offline without the cache write) |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        mono, b, ld, par = r["mono"], r["built"], r["loaded"], r["par"]
        t, c = b["offline_times"], b["offline_cpu"]
        parts = f"{t.get('setup', 0):.1f}; " + ", ".join(
            f"{t.get(k, 0):.1f} ({c.get(k, 0):.1f})" for k in ("assembly", "eigen", "basis", "coarse", "save")
        )
        # the ranks run without a cache (the functions then stay where they were computed): the speed-up is
        # taken against the serial offline time without its cache write
        par_cols = (
            f"{par['time_offline_s']:.1f} ({par['peak_rss_gb']:.2f} GB) | "
            f"{(b['time_offline_s'] - t.get('save', 0.0)) / par['time_offline_s']:.2f}"
            if par
            else "— | —"
        )
        lines.append(
            f"| 1/{r['n']} | {mono['dofs']} | {mono['time_s']:.1f} ({mono['time_newton_s']:.1f}) "
            f"[{mono['cpu_s']:.1f}] | {mono['peak_rss_gb']:.2f} | {b['time_offline_s']:.1f} "
            f"[{b['cpu_offline_omega1_s']:.1f}] | {b['time_offline_s'] / mono['time_s']:.1f} | "
            f"{parts} | {b['time_online_s']:.2f} | {b['time_online_s'] / mono['time_newton_s']:.2f} | "
            f"{b['peak_rss_gb']:.2f} | {b['cache_gb']:.3f} | {ld['offline_times'].get('load', float('nan')):.1f} | "
            f"{par_cols} |"
        )
    if any(r["pairs"] for r in rows):
        lines += [
            "",
            f"Interleaved pairs (`--repeats {args.repeats}`): a serial process without a cache, then "
            f"{args.ranks} ranks; offline wall s (set-up; Stage I, Stage II, coarse); the machine's ceiling "
            f"just before the pair (Σ_r t_alone / t_r of a CPU-bound probe in one, then {args.ranks} processes)"
            " and the ratio's share of it:",
            "",
            f"| h | pair | serial s | {args.ranks} ranks s | ratio | ceiling | ratio / ceiling |",
            "|---|---|---|---|---|---|---|",
        ]

        def parts(t: dict) -> str:
            return f"{t.get('setup', 0):.1f}; " + ", ".join(f"{t.get(k, 0):.1f}" for k in ("eigen", "basis", "coarse"))

        for r in rows:
            ratios = [s / p for s, p, *_ in r["pairs"]]
            ceilings = [c for *_, c in r["pairs"]]
            for k, (s, p, ts, tp, c) in enumerate(r["pairs"]):
                lines.append(
                    f"| 1/{r['n']} | {k + 1} | {s:.1f} ({parts(ts)}) | {p:.1f} ({parts(tp)}) | "
                    f"{s / p:.2f} | {c:.2f} | {s / p / c:.2f} |"
                )
            if ratios:
                lines.append(
                    f"| 1/{r['n']} | median | {np.median([s for s, *_ in r['pairs']]):.1f} | "
                    f"{np.median([p for _, p, *_ in r['pairs']]):.1f} | **{np.median(ratios):.2f}** | "
                    f"{np.median(ceilings):.2f} | "
                    f"{np.median([a / c for a, c in zip(ratios, ceilings)]):.2f} |"
                )
    dofs = [r["mono"]["dofs"] for r in rows]
    fits = {
        "monolithic solve (time)": [r["mono"]["time_s"] for r in rows],
        "monolithic peak memory": [r["mono"]["peak_rss_gb"] for r in rows],
        "monolithic solve (CPU)": [r["mono"]["cpu_s"] for r in rows],
        "Algorithm 4 offline (time)": [r["built"]["time_offline_s"] for r in rows],
        "Algorithm 4 offline, Ω₁ parts (CPU)": [r["built"]["cpu_offline_omega1_s"] for r in rows],
        "Algorithm 4 Stage I (CPU)": [r["built"]["offline_cpu"]["eigen"] for r in rows],
        "Algorithm 4 Stage II (CPU)": [r["built"]["offline_cpu"]["basis"] for r in rows],
        "Algorithm 4 online (time)": [r["built"]["time_online_s"] for r in rows],
        "Algorithm 4 peak memory": [r["built"]["peak_rss_gb"] for r in rows],
        "Algorithm 4 cache size": [r["built"]["cache_gb"] for r in rows],
    }
    lines += [
        "",
        "Fitted cost exponents p (cost ∝ DOFs^p, least squares over the sizes above):",
        "",
        "| quantity | p |",
        "|---|---|",
    ]
    for name, ys in fits.items():
        p = _slope(dofs, ys)
        lines.append(f"| {name} | {p:.2f} |" if p is not None else f"| {name} | — |")
    lines += ["", f"Total wall time {time.perf_counter() - start:.0f} s.", ""]
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
