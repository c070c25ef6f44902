"""Benchmark of Algorithm 3 (CEM-GMsFEM in Ω₁, primal FEM with contact in Ω₂), paper Table 5.3 style.

Errors are relative to the fine-scale monolithic penalized solution on the same
fine mesh (METHOD §6): e_u in L², e_a in the energy norm (Σ_i a_i(·,·) over Ω₁, Ω₂).

    (a) error vs oversampling layers m = 1..5 (H = 1/16, h = 1/64), both models
    (b) contrast robustness, E_high/E_low ∈ {1e2, 1e3, 1e4, 1e6}, fixed m
    (c) number of local modes l = 1..5, fixed m
    (d) DOFs (coarse vs fine Ω₁) and offline/online times for H = 1/8, 1/16, 1/32,
        with Algorithm 1 (fine FEM in Ω₁) for comparison
    (e) the weight factor c of the CEM inner product, κ̃ = c (λ+2μ) H⁻², c ∈ {1, 2, 3, 10, 30, 100}

Run:  python benchmarks/multiscale_primal.py --output multiscale_primal.md
      python benchmarks/multiscale_primal.py --output quick.md --n 32 --n-coarse 8 --coarse-list 4,8 --parts a,d
"""

import argparse
import logging
import os
import platform
import sys
import time
from pathlib import Path

# One thread per process unless the caller says otherwise: on small machines the
# OpenMP threads of MUMPS spin-wait and starve multithreaded BLAS calls (SuperLU
# solves with many right-hand sides were measured 30x slower on 2 cores).
os.environ.setdefault("OMP_NUM_THREADS", "1")

import fenics_contact  # noqa: F401  (imports dolfinx_solver before dolfinx/petsc4py)

import dolfinx
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.fem import primal
from fenics_contact.hybrid import primal as primal_hybrid
from fenics_contact.multiscale import cem
from fenics_contact.multiscale import primal as primal_ms
from fenics_contact.problem import geometry, models
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.problem.fields import material_fields

log = logging.getLogger("multiscale_primal")


def _ints(text: str) -> list[int]:
    return [int(t) for t in text.split(",") if t]


def _floats(text: str) -> list[float]:
    return [float(t) for t in text.split(",") if t]


def machine() -> str:
    """One line describing the machine and the software stack."""
    return (
        f"{platform.platform()}, {platform.machine()} ({platform.processor() or 'unknown CPU'}), "
        f"os.cpu_count() = {os.cpu_count()}, Python {platform.python_version()}, DOLFINx {dolfinx.__version__}, "
        f"PETSc {'.'.join(map(str, PETSc.Sys.getVersion()))}, fenics-contact {fenics_contact.__version__}, "
        f"MPI ranks = {MPI.COMM_WORLD.size}, OMP_NUM_THREADS = {os.environ.get('OMP_NUM_THREADS')}"
    )


class Runner:
    """Meshes and fine monolithic references, built once per (n, N, model)."""

    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        self._meshes: dict = {}
        self._refs: dict = {}
        self.options = IterationOptions(tol=args.tol, accel=args.accel)

    def mesh(self, n: int, N: int) -> geometry.ContactMesh:
        if (n, N) not in self._meshes:
            self._meshes[(n, N)] = geometry.unit_square(n, N)
        return self._meshes[(n, N)]

    def reference(self, n: int, N: int, number: int, contrast: float):
        key = (n, N, number, contrast)
        if key not in self._refs:
            cm = self.mesh(n, N)
            model = models.get_model(number, E_high=contrast)
            delta = primal.default_penalty(cm.h, 1.0)
            ref = primal.solve_primal_monolithic(
                cm.mesh, cm.facet_tags, material_fields(cm.mesh, model), delta=delta,
                prefix=f"bench_mono_{len(self._refs)}_",
            )
            self._refs[key] = (model, delta, ref)
        return self._refs[key]

    def alg3(self, n: int, N: int, number: int, *, layers: int, nbasis: int, contrast: float = 1e3,
             s_factor: float | None = None) -> dict:
        cm = self.mesh(n, N)
        model, delta, ref = self.reference(n, N, number, contrast)
        start = time.perf_counter()
        res = primal_ms.solve_primal_ms_hybrid(
            cm, model, alpha=self.args.alpha, delta=delta, layers=layers, nbasis=nbasis,
            options=self.options, reference=ref.u,
            s_factor=self.args.s_factor if s_factor is None else s_factor,
        )
        row = {
            "model": number, "H": f"1/{N}", "h": f"1/{n}", "m": layers, "l": nbasis, "contrast": contrast,
            "its": res.iterations, "converged": res.converged, "e_u": res.e_u, "e_a": res.step.error_energy(),
            "dofs": res.dofs, "offline": res.time_offline_s, "online": res.time_online_s,
            "offline_parts": res.step.offline_times, "wall": time.perf_counter() - start,
            "mono_time": ref.time_s,
        }
        log.info("alg3 %s", {k: v for k, v in row.items() if k not in ("offline_parts",)})
        return row

    def alg1(self, n: int, N: int, number: int) -> dict:
        cm = self.mesh(n, N)
        model, delta, ref = self.reference(n, N, number, 1e3)
        res = primal_hybrid.solve_primal_hybrid(
            cm, model, alpha=self.args.alpha, delta=delta, options=self.options, reference=ref.u
        )
        return {"its": res.iterations, "e_u": res.e_u, "offline": res.time_offline_s, "online": res.time_online_s,
                "dofs": res.dofs}


def _e(x: float) -> str:
    return f"{x:.2e}"


def _its(row: dict) -> str:
    return f"{row['its']}" + ("" if row["converged"] else " (not conv.)")


def part_a(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (a) Error vs oversampling layers m (h = 1/{a.n}, H = 1/{a.n_coarse}, l = {a.nbasis}, "
        f"E_high/E_low = 1e3)", "",
        "| model | m | dim V_ms | its | e_u (L²) | e_a (energy) | offline [s] | online [s] |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for m in a.layers:
            r = run.alg3(a.n, a.n_coarse, number, layers=m, nbasis=a.nbasis)
            lines.append(f"| {number} | {m} | {r['dofs']['omega1_ms']} | {_its(r)} | {_e(r['e_u'])} | {_e(r['e_a'])} "
                         f"| {r['offline']:.2f} | {r['online']:.2f} |")
    return lines


def part_b(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (b) Contrast robustness (h = 1/{a.n}, H = 1/{a.n_coarse}, m = {a.fixed_layers}, l = {a.nbasis}, "
        "E_low = 1)", "",
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
        "E_high/E_low = 1e3)", "",
        "| model | l | dim V_ms | its | e_u (L²) | e_a (energy) | offline [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for nb in a.nbasis_list:
            r = run.alg3(a.n, a.n_coarse, number, layers=a.fixed_layers, nbasis=nb)
            lines.append(f"| {number} | {nb} | {r['dofs']['omega1_ms']} | {_its(r)} | {_e(r['e_u'])} | "
                         f"{_e(r['e_a'])} | {r['offline']:.2f} |")
    return lines


def part_d(run: Runner) -> list[str]:
    a = run.args
    lines = [
        f"### (d) DOFs and times (h = 1/{a.n}, m = {a.fixed_layers}, l = {a.nbasis}, E_high/E_low = 1e3)", "",
        "Offline = assembly + local eigenproblems + CEM bases + Robin correction N + coarse factorization; "
        "online = the iteration (coarse solves, Ω₂ Newton, update). Algorithm 1 solves Ω₁ on the fine mesh "
        "on the same two subdomains.", "",
        "| model | H | fine Ω₁ DOFs | dim V_ms | Ω₂ DOFs | its | e_u | offline [s] (eigen / bases / N / coarse) "
        "| online [s] | online per it. [ms] | Alg. 1 its | Alg. 1 online [s] | monolithic Newton [s] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for N in a.coarse_list:
            a1 = run.alg1(a.n, N, number) if a.compare_alg1 else None
            r = run.alg3(a.n, N, number, layers=a.fixed_layers, nbasis=a.nbasis)
            p = r["offline_parts"]
            parts = f"{p['eigen']:.2f} / {p['basis']:.2f} / {p['correction']:.2f} / {p['coarse']:.2f}"
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
        f"l = {a.nbasis}, E_high/E_low = 1e3)", "",
        "| model | c | m | its | e_u (L²) | e_a (energy) |",
        "|---|---|---|---|---|---|",
    ]
    for number in a.models:
        for c in a.s_factors:
            for m in (4, 5):
                r = run.alg3(a.n, a.n_coarse, number, layers=m, nbasis=a.nbasis, s_factor=c)
                lines.append(f"| {number} | {c:g} | {m} | {_its(r)} | {_e(r['e_u'])} | {_e(r['e_a'])} |")
    return lines


PARTS = {"a": part_a, "b": part_b, "c": part_c, "d": part_d, "e": part_e}


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--output", type=Path, required=True, help="markdown file to write")
    p.add_argument("--parts", default="a,b,c,d,e", help="comma-separated subset of a,b,c,d,e")
    p.add_argument("--models", type=_ints, default=[1, 2])
    p.add_argument("--n", type=int, default=64, help="1/h")
    p.add_argument("--n-coarse", type=int, default=16, help="1/H for parts a-c")
    p.add_argument("--layers", type=_ints, default=[1, 2, 3, 4, 5], help="m values for part a")
    p.add_argument("--fixed-layers", type=int, default=5, help="m for parts b-d")
    p.add_argument("--nbasis", type=int, default=3, help="l for parts a, b, d")
    p.add_argument("--nbasis-list", type=_ints, default=[1, 2, 3, 4, 5], help="l values for part c")
    p.add_argument("--contrasts", type=_floats, default=[1e2, 1e3, 1e4, 1e6])
    p.add_argument("--coarse-list", type=_ints, default=[8, 16, 32], help="1/H values for part d")
    p.add_argument("--alpha", default=primal_hybrid.DEFAULT_ALPHA, help="Robin coefficient (see fenics-contact run --help)")
    p.add_argument("--s-factor", type=float, default=cem.DEFAULT_S_FACTOR, help="c in κ̃ = c (λ+2μ) H⁻²")
    p.add_argument("--s-factors", type=_floats, default=[1, 2, 3, 10, 30, 100], help="c values for part e")
    p.add_argument("--tol", type=float, default=1e-6, help="relative-change stopping tolerance")
    p.add_argument("--accel", default="anderson", choices=["anderson", "none"])
    p.add_argument("--no-alg1", dest="compare_alg1", action="store_false", help="skip the Algorithm 1 comparison")
    p.add_argument("-v", "--verbose", action="store_true")
    args = p.parse_args(argv)
    bad = set(args.parts.split(",")) - set(PARTS)
    if bad:
        p.error(f"unknown part(s) {sorted(bad)}; choose from a,b,c,d,e")
    return args


def main(argv=None) -> int:
    args = parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(asctime)s %(name)s %(message)s")
    if MPI.COMM_WORLD.size > 1:
        print("Algorithm 3 runs serially; start the benchmark without mpiexec", file=sys.stderr)
        return 2
    run = Runner(args)
    start = time.perf_counter()
    lines = [
        "# Algorithm 3 (CEM-GMsFEM in Ω₁ + primal FEM/contact in Ω₂) — benchmark", "",
        f"Machine: {machine()}", "",
        f"Command: `{' '.join([Path(sys.argv[0]).name] + (argv if argv is not None else sys.argv[1:]))}`", "",
        f"Robin α = {args.alpha!r}; κ̃ factor c = {args.s_factor:g}; stopping rule: relative change < {args.tol:g} ({args.accel} update); "
        "penalty δ = 1e-3·h/E_c. Errors against the fine monolithic penalized solution.", "",
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
