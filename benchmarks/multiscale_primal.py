"""Benchmark of Algorithm 3 (CEM-GMsFEM in Ω₁, primal FEM with contact in Ω₂), paper Table 5.3 style.

Errors are relative to the fine-scale monolithic penalized solution on the same
fine mesh: e_u in L², e_a in the energy norm (Σ_i a_i(·,·) over Ω₁, Ω₂).

    (a) error vs oversampling layers m = 1..5 (H = 1/16, h = 1/64), both models (built-in loads, in Ω₂)
    (b) contrast robustness, E_high/E_low ∈ {1e2, 1e3, 1e4, 1e6}, fixed m
    (c) number of local modes l = 1..5, fixed m
    (d) DOFs and offline/online times for H = 1/8, 1/16, 1/32, with Algorithm 1 for comparison
    (e) the weight factor c of the CEM inner product, κ̃ = c (λ+2μ) H⁻², c ∈ {1, 2, 3, 10, 30, 100}
    (f) loads inside Ω₁: models 1 and 2 with their bands moved to x ∈ [1/2, 15/16] (pushing and
        pulling) and model 3 (heterogeneous strip, E_high 1e3 and 1e6); m = 1..4 at H = 1/16 and 1/8,
        with the source correction (default) and without it (the paper's algorithm)
    (g) cost scaling (model 2, H = 1/16, m = 3): offline, online and peak memory against h, each
        measurement in a fresh process, ratios to the monolithic solve of the same run, fitted exponents
    (h) MPI: offline and online time with 1 and 2 ranks (mpiexec -n 2), same problem, same run
    (i) Ω₁ alone with the exact interface data of the monolithic solution (the CEM error free of the
        interface iteration; the cases of (f))
    (j) ν → ½: the energy error against m for ν from 0.35 to 0.499 with the smallest local eigenvalue
        left out, Λ (the primal CEM's limit: Λ ∝ μ/(λ+2μ), and the bases localize slowly)

Run (the whole table, as recorded in benchmarks/results/multiscale_primal.md):

    python benchmarks/multiscale_primal.py --output benchmarks/results/multiscale_primal.md

Subsets: ``--parts f`` (loads in Ω₁ only), ``--parts g --scaling-n 64,128,256,512`` (h = 1/512
needs ~4 GB), ``--n 32 --n-coarse 8 --coarse-list 4,8 --parts a,d`` (quick).
"""

import argparse
import json
import logging
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

# One thread per process unless the caller says otherwise: on small machines the
# OpenMP threads of MUMPS spin-wait and starve multithreaded BLAS calls (SuperLU
# solves with many right-hand sides were measured 30x slower on 2 cores).
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from mpi4py import MPI

import fenics_contact  # noqa: F401  (imports dolfinx_solver before dolfinx/petsc4py)
from fenics_contact.fem import primal
from fenics_contact.hybrid import primal as primal_hybrid
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.io import machine_description
from fenics_contact.multiscale import cem
from fenics_contact.multiscale import primal as primal_ms
from fenics_contact.problem import geometry, models
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.problem import ContactProblem

log = logging.getLogger("multiscale_primal")


def _ints(text: str) -> list[int]:
    return [int(t) for t in text.split(",") if t]


def _floats(text: str) -> list[float]:
    return [float(t) for t in text.split(",") if t]


def make_model(name: str, contrast: float = 1e3, nu: float = 0.35) -> ContactProblem:
    """'1', '2', '3' (built-in) or '1L', '2L' (built-in with the loads moved into Ω₁)."""
    number = int(name[0])
    model = models.get_model(number, E_high=contrast, nu=nu)
    if name.endswith("L"):
        model = model.with_(
            load=models.band_load(models.LOADS_IN_OMEGA1[number]), description=model.description + ", loads in Omega1"
        )
    return model


class Runner:
    """Meshes and fine monolithic references, built once per (n, N, model, contrast)."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self._meshes: dict = {}
        self._refs: dict = {}
        self.options = IterationOptions(tol=args.tol, accel=args.accel, max_iterations=args.max_iterations)

    def mesh(self, n: int, N: int) -> geometry.ContactMesh:
        if (n, N) not in self._meshes:
            self._meshes[(n, N)] = geometry.unit_square(n, N)
        return self._meshes[(n, N)]

    def reference(self, n: int, N: int, name: str, contrast: float, nu: float = 0.35):
        key = (n, N, name, contrast, nu)
        if key not in self._refs:
            cm = self.mesh(n, N)
            model = make_model(name, contrast, nu)
            fields = material_fields(cm.mesh, model)
            E_c = cm.comm.allreduce(float(np.max(fields.E.x.array[cm.cell_tags.find(2)], initial=0.0)), op=MPI.MAX)
            delta = primal.default_penalty(cm.h, E_c)
            ref = primal.solve_primal_monolithic(model.on(cm), delta=delta, prefix=f"bench_mono_{len(self._refs)}_")
            self._refs[key] = (model, delta, ref)
        return self._refs[key]

    def alg3(
        self,
        n: int,
        N: int,
        name,
        *,
        layers: int,
        nbasis: int,
        contrast: float = 1e3,
        s_factor: float | None = None,
        source_correction: bool = True,
        nu: float = 0.35,
    ) -> dict:
        cm = self.mesh(n, N)
        model, delta, ref = self.reference(n, N, str(name), contrast, nu)
        start = time.perf_counter()
        res = primal_ms.solve_primal_ms_hybrid(
            model.on(cm),
            alpha=self.args.alpha,
            delta=delta,
            cem=cem.CEMOptions(
                layers=layers,
                nbasis=nbasis,
                source_correction=source_correction,
                s_factor=self.args.s_factor if s_factor is None else s_factor,
            ),
            options=self.options,
            reference=ref.u,
        )
        row = {
            "model": name,
            "H": f"1/{N}",
            "h": f"1/{n}",
            "m": layers,
            "l": nbasis,
            "contrast": contrast,
            "its": res.iterations,
            "converged": res.converged,
            "e_u": res.e_u,
            "e_a": res.step.error_energy(),
            "dofs": res.dofs,
            "offline": res.time_offline_s,
            "online": res.time_online_s,
            "offline_parts": res.step.offline_times,
            "wall": time.perf_counter() - start,
            "mono_time": ref.time_s,
            "gap": res.step.omega1.spectral_gap,
        }
        log.info("alg3 %s", {k: v for k, v in row.items() if k not in ("offline_parts",)})
        return row

    def alg1(self, n: int, N: int, name) -> dict:
        cm = self.mesh(n, N)
        model, delta, ref = self.reference(n, N, str(name), 1e3)
        res = primal_hybrid.solve_primal_hybrid(
            model.on(cm), alpha=self.args.alpha, delta=delta, options=self.options, reference=ref.u
        )
        return {
            "its": res.iterations,
            "e_u": res.e_u,
            "offline": res.time_offline_s,
            "online": res.time_online_s,
            "dofs": res.dofs,
        }


def _e(x: float) -> str:
    return f"{x:.2e}"


def _its(row: dict) -> str:
    return f"{row['its']}" + ("" if row["converged"] else " (not conv.)")


def part_a(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (a) Error vs oversampling layers m (h = 1/{a.n}, H = 1/{a.n_coarse}, l = {a.nbasis}, "
        f"E_high/E_low = 1e3; the built-in loads, which act in Ω₂)",
        "",
        "| model | m | dim V_ms | its | e_u (L²) | e_a (energy) | offline [s] | online [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for m in a.layers:
            r = run.alg3(a.n, a.n_coarse, number, layers=m, nbasis=a.nbasis)
            lines.append(
                f"| {number} | {m} | {r['dofs']['omega1_ms']} | {_its(r)} | {_e(r['e_u'])} | {_e(r['e_a'])} "
                f"| {r['offline']:.2f} | {r['online']:.2f} |"
            )
    return lines


def part_b(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (b) Contrast robustness (h = 1/{a.n}, H = 1/{a.n_coarse}, m = {a.fixed_layers}, l = {a.nbasis}, "
        "E_low = 1)",
        "",
        "| model | E_high/E_low | its | e_u (L²) | e_a (energy) | online [s] |",
        "|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for c in a.contrasts:
            r = run.alg3(a.n, a.n_coarse, number, layers=a.fixed_layers, nbasis=a.nbasis, contrast=c)
            lines.append(f"| {number} | {c:.0e} | {_its(r)} | {_e(r['e_u'])} | {_e(r['e_a'])} | {r['online']:.2f} |")
    return lines


def part_c(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (c) Local modes l per coarse cell (h = 1/{a.n}, H = 1/{a.n_coarse}, m = {a.fixed_layers}, "
        "E_high/E_low = 1e3)",
        "",
        "| model | l | dim V_ms | its | e_u (L²) | e_a (energy) | offline [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for nb in a.nbasis_list:
            r = run.alg3(a.n, a.n_coarse, number, layers=a.fixed_layers, nbasis=nb)
            lines.append(
                f"| {number} | {nb} | {r['dofs']['omega1_ms']} | {_its(r)} | {_e(r['e_u'])} | "
                f"{_e(r['e_a'])} | {r['offline']:.2f} |"
            )
    return lines


def part_d(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (d) DOFs and times (h = 1/{a.n}, m = {a.fixed_layers}, l = {a.nbasis}, E_high/E_low = 1e3)",
        "",
        "Offline = assembly + local eigenproblems + patch problems (bases, N, N_f) + coarse operators (Gram "
        "matrices, factorization); online = the iteration (coarse solves, Ω₂ Newton, update). Algorithm 1 solves "
        "Ω₁ on the fine mesh on the same two subdomains.",
        "",
        "| model | H | fine Ω₁ DOFs | dim V_ms | Ω₂ DOFs | its | e_u | offline [s] (eigen / patches / coarse) "
        "| online [s] | online per it. [ms] | Alg. 1 its | Alg. 1 online [s] | monolithic Newton [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for N in a.coarse_list:
            a1 = run.alg1(a.n, N, number) if a.compare_alg1 else None
            r = run.alg3(a.n, N, number, layers=a.fixed_layers, nbasis=a.nbasis)
            p = r["offline_parts"]
            parts = f"{p['eigen']:.2f} / {p['patches']:.2f} / {p['coarse']:.2f}"
            alg1 = f"| {a1['its']} | {a1['online']:.2f} " if a1 else "| – | – "
            lines.append(
                f"| {number} | 1/{N} | {r['dofs']['omega1']} | {r['dofs']['omega1_ms']} | {r['dofs']['omega2']} | "
                f"{_its(r)} | {_e(r['e_u'])} | {r['offline']:.2f} ({parts}) | {r['online']:.2f} | "
                f"{1e3 * r['online'] / r['its']:.1f} {alg1}| {r['mono_time']:.2f} |"
            )
    return lines


def part_e(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (e) Weight factor c of the CEM inner product, κ̃ = c (λ+2μ) H⁻² (h = 1/{a.n}, H = 1/{a.n_coarse}, "
        f"l = {a.nbasis}, E_high/E_low = 1e3)",
        "",
        "| model | c | m | its | e_u (L²) | e_a (energy) |",
        "|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for c in a.s_factors:
            for m in (4, 5):
                r = run.alg3(a.n, a.n_coarse, number, layers=m, nbasis=a.nbasis, s_factor=c)
                lines.append(f"| {number} | {c:g} | {m} | {_its(r)} | {_e(r['e_u'])} | {_e(r['e_a'])} |")
    return lines


def _cases(text: str) -> list[tuple[str, float]]:
    """'1L:1e3,3:1e6' → [('1L', 1000.0), ('3', 1e6)]."""
    out = []
    for item in text.split(","):
        name, _, contrast = item.partition(":")
        out.append((name, float(contrast or 1e3)))
    return out


def part_f(run: Runner) -> list[str]:
    a = run.args
    cases = a.f_cases
    lines = [
        f"### (f) Loads inside Ω₁: the source correction (h = 1/{a.n}, l = {a.nbasis})",
        "",
        "Models 1L and 2L are models 1 and 2 with their load bands moved to x ∈ [1/2, 15/16] (1L: f₁ = 1 on "
        "y < 1/2, −1 above; 2L: −1, 2, −1 on y < 3/8, 3/8–5/8, > 5/8); model 3 is the heterogeneous strip "
        "(stiff channels through γ up to Γ_C, loads on x ≥ 1/2). Energy error e_a and its ratio to the "
        "previous m; 'paper' = without the source correction (CEMOptions(source_correction=False)).",
        "",
        "| model | E_high | H | variant | "
        + " | ".join(f"e_a m={m}" for m in a.f_layers)
        + f" | ratios per layer | its (m={a.f_layers[-1]}) |",
        "|---|---|---|---|" + "---|" * len(a.f_layers) + "---|---|",
    ]
    for name, contrast in cases:
        for N in a.f_coarse:
            for source in (True, False):
                if not source and N != a.f_coarse[0]:
                    continue
                rows = [
                    run.alg3(a.n, N, name, layers=m, nbasis=a.nbasis, contrast=contrast, source_correction=source)
                    for m in a.f_layers
                ]
                e = np.array([r["e_a"] for r in rows])
                conv = all(r["converged"] for r in rows)
                ratios = " / ".join(f"{x:.1f}" for x in e[:-1] / e[1:])
                cells = " | ".join(_e(x) for x in e)
                lines.append(
                    f"| {name} | {contrast:.0e} | 1/{N} | {'N_f' if source else 'paper'} | {cells} | "
                    f"{ratios} | {rows[-1]['its']}{'' if conv else ' (not all conv.)'} |"
                )
    return lines


def part_i(run: Runner) -> list[str]:
    """Ω₁ alone: the multiscale Robin solve with the exact interface data of the monolithic solution."""
    a = run.args
    cases = a.f_cases
    lines = [
        f"### (i) Ω₁ alone with the exact interface data (h = 1/{a.n}, l = {a.nbasis})",
        "",
        "The multiscale Ω₁ Robin problem with the data g₁₂ for which the fine Ω₁ solution is the fine "
        "monolithic solution u_h|Ω₁ (g₁₂ = W⁻¹((K + R) u_h − ℓ) at the γ vertices): the error of the CEM "
        "approximation itself, free of the interface iteration. Relative energy error a₁(u₁ − u_h, ·)^½ / "
        "a₁(u_h, u_h)^½ over Ω₁.",
        "",
        "| model | E_high | H | variant | " + " | ".join(f"m={m}" for m in a.f_layers) + " | ratios per layer |",
        "|---|---|---|---|" + "---|" * len(a.f_layers) + "---|",
    ]
    for name, contrast in cases:
        for N in a.f_coarse:
            cm = run.mesh(a.n, N)
            model, delta, ref = run.reference(a.n, N, name, contrast)
            for source in (True, False):
                errors = []
                for m in a.f_layers:
                    om, _, _ = cem.build_omega1_multiscale(
                        model.on(cm),
                        alpha=a.alpha,
                        cem=cem.CEMOptions(layers=m, nbasis=a.nbasis, s_factor=a.s_factor, source_correction=source),
                    )
                    ops = om.ops
                    r1 = om.from_parent(ref.u)
                    residual = ops.A @ r1 - ops.F
                    weights = ops.G.diagonal()[ops.gamma]
                    g = residual[ops.gamma] / weights
                    d = om.solver.solve(g) - r1
                    errors.append(np.sqrt(om.energy_norm2(d) / om.energy_norm2(r1)))
                e = np.array(errors)
                lines.append(
                    f"| {name} | {contrast:.0e} | 1/{N} | {'N_f' if source else 'paper'} | "
                    + " | ".join(_e(x) for x in e)
                    + " | "
                    + " / ".join(f"{x:.1f}" for x in e[:-1] / e[1:])
                    + " |"
                )
    return lines


def part_j(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (j) Nearly incompressible Ω₁ (h = 1/{a.n}, H = 1/{a.n_coarse}, l = {a.nbasis}, ν everywhere)",
        "",
        "Energy error e_a against m and Λ·c, the smallest local eigenvalue left out times the weight factor c "
        "(Algorithm 3 warns for ν > `cem.NEARLY_INCOMPRESSIBLE` = 0.42). The reference is the fine P1 solution, "
        "which itself locks as ν → ½; Algorithm 4 (mixed, Arnold–Winther) is the one robust in ν.",
        "",
        "| model | E_high | ν | Λ·c | " + " | ".join(f"e_a m={m}" for m in a.j_layers) + " | its |",
        "|---|---|---|---|" + "---|" * len(a.j_layers) + "---|",
    ]
    for name, contrast in a.j_cases:
        for nu in a.j_nu:
            rows = [
                run.alg3(a.n, a.n_coarse, name, layers=m, nbasis=a.nbasis, contrast=contrast, nu=nu) for m in a.j_layers
            ]
            cells = " | ".join(_e(r["e_a"]) for r in rows)
            its = "/".join(_its(r) for r in rows)
            lines.append(f"| {name} | {contrast:.0e} | {nu} | {rows[0]['gap'] * a.s_factor:.2f} | {cells} | {its} |")
    return lines


# -- (g) scaling and (h) MPI: measurements in fresh processes ---------------------------------------------
def _worker(args: argparse.Namespace) -> dict:
    """One measurement (``--worker mono|alg3``) in this process: times and peak RSS, as JSON on rank 0."""
    comm = MPI.COMM_WORLD
    t0 = time.perf_counter()
    cm = geometry.unit_square(args.n, args.n_coarse)
    model = make_model(str(args.models[0]))
    delta = primal.default_penalty(cm.h, 1.0)
    out = {"n": args.n, "ranks": comm.size, "mesh": time.perf_counter() - t0}
    if args.worker == "mono":
        ref = primal.solve_primal_monolithic(model.on(cm), delta=delta)
        out.update(time=ref.time_s, dofs=2 * (args.n + 1) ** 2, newton=ref.newton.steps)
    else:
        res = primal_ms.solve_primal_ms_hybrid(
            model.on(cm),
            alpha=args.alpha,
            delta=delta,
            cem=cem.CEMOptions(layers=args.fixed_layers, nbasis=args.nbasis),
            options=IterationOptions(tol=args.tol),
        )
        om = res.step.omega1
        out.update(
            offline=res.time_offline_s,
            online=res.time_online_s,
            its=res.iterations,
            converged=bool(res.converged),
            parts=res.step.offline_times,
            dofs=2 * (args.n + 1) ** 2,
            dim_ms=om.num_coarse_dofs,
            bases_mb=om.space.nbytes / 1e6,
        )
    from fenics_contact.io import peak_rss_bytes

    rss = peak_rss_bytes() / 1e6  # MB (10⁶ bytes)
    out["peak_rss_mb"] = comm.allreduce(rss, op=MPI.MAX)
    out["peak_rss_sum_mb"] = comm.allreduce(rss, op=MPI.SUM)
    return out


def _spawn(args: argparse.Namespace, worker: str, n: int, *, ranks: int = 1) -> dict:
    cmd = [
        sys.executable,
        __file__,
        "--output",
        os.devnull,
        "--worker",
        worker,
        "--n",
        str(n),
        "--n-coarse",
        str(args.n_coarse),
        "--models",
        str(args.scaling_model),
        "--fixed-layers",
        str(args.scaling_layers),
        "--nbasis",
        str(args.nbasis),
        "--alpha",
        args.alpha,
        "--tol",
        str(args.tol),
    ]
    if ranks > 1:
        mpiexec = Path(sys.executable).with_name("mpiexec")
        cmd = [str(mpiexec) if mpiexec.exists() else shutil.which("mpiexec"), "-n", str(ranks), *cmd]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, OMP_NUM_THREADS="1"))
    if proc.returncode != 0:
        raise RuntimeError(f"worker {worker} n={n} failed:\n{proc.stderr[-3000:]}")
    line = next(l for l in proc.stdout.splitlines() if l.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def _fit(x, y) -> float:
    return float(np.polyfit(np.log(x), np.log(y), 1)[0])


def part_g(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (g) Cost scaling (model {a.scaling_model}, H = 1/{a.n_coarse}, m = {a.scaling_layers}, l = {a.nbasis}; "
        "each entry a fresh process, serial)",
        "",
        "Monolithic = the fine penalized semismooth Newton solve (MUMPS); offline = Ω₁ assembly, local "
        "eigenproblems, patch problems, coarse operators; online = the Algorithm 3 iteration; peak RSS of the "
        "process (the monolithic run and the Algorithm 3 run are separate processes: no reference in the latter).",
        "",
        "| h | DOFs | monolithic [s] | mono. RSS [MB] | offline [s] (eigen / patches / coarse) | offline / mono. "
        "| online [s] (its) | online / mono. | Alg. 3 RSS [MB] | bases [MB] |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    data = []
    for n in a.scaling_n:
        mono = _spawn(a, "mono", n)
        ms = _spawn(a, "alg3", n)
        data.append((mono, ms))
        p = ms["parts"]
        lines.append(
            f"| 1/{n} | {mono['dofs']} | {mono['time']:.2f} | {mono['peak_rss_mb']:.0f} | {ms['offline']:.2f} "
            f"({p['eigen']:.2f} / {p['patches']:.2f} / {p['coarse']:.2f}) | {ms['offline'] / mono['time']:.2f} | "
            f"{ms['online']:.2f} ({ms['its']}) | {ms['online'] / mono['time']:.3f} | {ms['peak_rss_mb']:.0f} | "
            f"{ms['bases_mb']:.0f} |"
        )
    if len(data) >= 2:
        dofs = [d[0]["dofs"] for d in data]
        lines += [
            "",
            "Fitted cost exponents p in cost ∝ DOFs^p (least squares over the rows above):",
            "",
            "| monolithic time | offline | online | monolithic RSS | Alg. 3 RSS |",
            "|---|---|---|---|---|",
            f"| {_fit(dofs, [d[0]['time'] for d in data]):.2f} | {_fit(dofs, [d[1]['offline'] for d in data]):.2f} | "
            f"{_fit(dofs, [d[1]['online'] for d in data]):.2f} | {_fit(dofs, [d[0]['peak_rss_mb'] for d in data]):.2f} "
            f"| {_fit(dofs, [d[1]['peak_rss_mb'] for d in data]):.2f} |",
        ]
    return lines


def part_h(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (h) MPI (model {a.scaling_model}, H = 1/{a.n_coarse}, m = {a.scaling_layers}, l = {a.nbasis})",
        "",
        "The local eigenproblems and patch problems are shared out across the ranks (each computed once), the "
        "coarse-cell blocks of the Gram matrices summed with Allreduce; every rank holds a serial copy of Ω₁. "
        "Online every rank solves the small coarse problem itself (one Allgather of the γ data per "
        "iteration; nothing of fine-mesh size in Ω₁), Ω₂ is distributed as in Algorithm 1.",
        "",
        "| h | ranks | offline [s] (eigen / patches / coarse) | offline speed-up | online [s] (its) | "
        "online speed-up | peak RSS per rank [MB] |",
        "|---|---|---|---|---|---|---|",
    ]
    for n in a.mpi_n:
        serial = _spawn(a, "alg3", n)
        rows = [serial] + [_spawn(a, "alg3", n, ranks=r) for r in a.mpi_ranks]
        for r in rows:
            p = r["parts"]
            lines.append(
                f"| 1/{n} | {r['ranks']} | {r['offline']:.2f} ({p['eigen']:.2f} / {p['patches']:.2f} / "
                f"{p['coarse']:.2f}) | {serial['offline'] / r['offline']:.2f} | {r['online']:.2f} ({r['its']}) | "
                f"{serial['online'] / r['online']:.2f} | {r['peak_rss_mb']:.0f} |"
            )
    return lines


PARTS = {
    "a": part_a,
    "b": part_b,
    "c": part_c,
    "d": part_d,
    "e": part_e,
    "f": part_f,
    "i": part_i,
    "g": part_g,
    "h": part_h,
    "j": part_j,
}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--output", type=Path, required=True, help="markdown file to write")
    p.add_argument("--parts", default="a,b,c,d,e,f,i,g,h", help="comma-separated subset of a..i")
    p.add_argument("--models", type=lambda t: [s for s in t.split(",") if s], default=["1", "2"])
    p.add_argument("--n", type=int, default=64, help="1/h")
    p.add_argument("--n-coarse", type=int, default=16, help="1/H for parts a-c, g, h")
    p.add_argument("--layers", type=_ints, default=[1, 2, 3, 4, 5], help="m values for part a")
    p.add_argument("--fixed-layers", type=int, default=5, help="m for parts b-d")
    p.add_argument("--nbasis", type=int, default=3, help="l for parts a, b, d, f, g, h")
    p.add_argument("--nbasis-list", type=_ints, default=[1, 2, 3, 4, 5], help="l values for part c")
    p.add_argument("--contrasts", type=_floats, default=[1e2, 1e3, 1e4, 1e6])
    p.add_argument("--coarse-list", type=_ints, default=[8, 16, 32], help="1/H values for part d")
    p.add_argument("--f-coarse", type=_ints, default=[16, 8], help="1/H values for part f")
    p.add_argument("--f-layers", type=_ints, default=[1, 2, 3, 4], help="m values for parts f, i")
    p.add_argument(
        "--f-cases",
        type=_cases,
        default=_cases("1L:1e3,2L:1e3,3:1e3,3:1e6"),
        help="model:E_high pairs for parts f, i (1L/2L: models 1/2 with the loads in Omega1)",
    )
    p.add_argument("--j-cases", type=_cases, default=_cases("3:1e6,1:1e3"), help="model:E_high pairs for part j")
    p.add_argument("--j-nu", type=_floats, default=[0.35, 0.4, 0.45, 0.48, 0.49, 0.499], help="ν values, part j")
    p.add_argument("--j-layers", type=_ints, default=[3, 4, 5, 6], help="m values for part j")
    p.add_argument("--scaling-n", type=_ints, default=[64, 128, 256], help="1/h values for part g")
    p.add_argument("--scaling-model", default="2", help="model of parts g, h")
    p.add_argument("--scaling-layers", type=int, default=3, help="m for parts g, h")
    p.add_argument("--mpi-n", type=_ints, default=[128], help="1/h values for part h")
    p.add_argument("--mpi-ranks", type=_ints, default=[2], help="rank counts for part h (besides 1)")
    p.add_argument(
        "--alpha", default=primal_hybrid.DEFAULT_ALPHA, help="Robin coefficient (see fenics-contact run --help)"
    )
    p.add_argument("--s-factor", type=float, default=cem.DEFAULT_S_FACTOR, help="c in κ̃ = c (λ+2μ) H⁻²")
    p.add_argument("--s-factors", type=_floats, default=[1, 2, 3, 10, 30, 100], help="c values for part e")
    p.add_argument("--tol", type=float, default=1e-6, help="stopping tolerance of the iteration")
    p.add_argument("--max-iterations", type=int, default=2000)
    p.add_argument("--accel", default="anderson", choices=["anderson", "none", "newton"])
    p.add_argument("--no-alg1", dest="compare_alg1", action="store_false", help="skip the Algorithm 1 comparison")
    p.add_argument("--worker", choices=["mono", "alg3"], help=argparse.SUPPRESS)
    p.add_argument("-v", "--verbose", action="store_true")
    args = p.parse_args(argv)
    bad = set(args.parts.split(",")) - set(PARTS)
    if bad:
        p.error(f"unknown part(s) {sorted(bad)}; choose from {','.join(PARTS)}")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(asctime)s %(name)s %(message)s"
    )
    if args.worker is not None:
        out = _worker(args)
        if MPI.COMM_WORLD.rank == 0:
            print("RESULT " + json.dumps(out))
        return 0
    if MPI.COMM_WORLD.size > 1:
        print("start the benchmark without mpiexec (part h launches its own MPI jobs)", file=sys.stderr)
        return 2
    run = Runner(args)
    start = time.perf_counter()
    lines = [
        "# Algorithm 3 (CEM-GMsFEM in Ω₁ + primal FEM/contact in Ω₂) — benchmark",
        "",
        f"Machine: {machine_description()}",
        "",
        f"Command: `python benchmarks/{Path(sys.argv[0]).name} {' '.join(argv if argv is not None else sys.argv[1:])}`",
        "",
        f"Robin α = {args.alpha!r}; κ̃ factor c = {args.s_factor:g}; stopping rule: transmission residual < "
        f"{args.tol:g} ({args.accel} update); penalty δ = 1e-3·h/E_c (E_c the largest E in Ω₂). Errors against the fine "
        "monolithic penalized solution. Timings are wall-clock on the machine above; when it was shared with "
        "other jobs they are marked contended (ratios are taken within one run).",
        "",
    ]
    for name in args.parts.split(","):
        t0 = time.perf_counter()
        lines += PARTS[name](run)
        lines += ["", f"_part ({name}): {time.perf_counter() - t0:.1f} s wall_", ""]
        args.output.write_text("\n".join(lines) + "\n")  # partial results survive an interruption
    lines.append(f"Total wall time {time.perf_counter() - start:.1f} s.")
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
