"""Algorithm 1's affine interface responses (the interface Newton's offline work): three ways, one process.

* back-solves: ``AffinePart.responses``, J back-solved for the n_γ data and n_c contact columns in blocks of
  ``--chunk`` right-hand sides (one MatMatSolve each: MUMPS solves a block with BLAS-3);
* Schur: MUMPS' Schur complement S of J on the γ and Γ_C unknowns (ICNTL(19), a second factorization), then
  (J⁻¹)_II = S⁻¹ by a dense LU (this script only: ``MatFactorSetSchurIS`` through ctypes);
* entries: the block (J⁻¹)_II from the factors J already has (MUMPS ICNTL(30): ``fem.inverse_entries``,
  what ``PrimalPart.responses`` does on one process).

Part 1 times the responses of Ω₁ (T₁) and of Ω₂ with J₀ (Yc, Sc, Yq, Sq) on the load-path problem
(``benchmarks/load_path.py``: model 3, the cylinder) and compares them with the back-solves' (largest
difference relative to the largest entry).  Part 2 runs the load path with ``primal`` (interface Newton)
twice per repetition, with the back-solves (``PrimalPart.responses = AffinePart.responses``, this script
only) and with the entries, and compares forces and iteration counts.  Every time is the minimum of
``--repeat`` repetitions, alternating the variants.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/interface_response.py --h 128 256 \\
        --out benchmarks/results/interface_response.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/interface_response.py --h 256 --blocking \\
        --out benchmarks/results/interface_response.md      # appends the block-size table
"""

import argparse
import ctypes
import os
import sys
import time
from pathlib import Path

import numpy as np
import scipy.linalg as sla
from petsc4py import PETSc

import fenics_contact as fc  # noqa: F401  (dolfinx_solver before petsc4py)
from fenics_contact.fem import inverse_entries
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import AffinePart, PrimalPart
from fenics_contact.io import machine_description
from fenics_contact.problem.models import get_model


def problem_on(h: int, H: int, contrast: float):
    cm = fc.unit_square(h, H)
    return get_model(3, E_high=contrast).with_(obstacle=fc.Circle((3.0, 0.5), 2.0)).on(cm)


def schur_inverse(A: PETSc.Mat, rows: np.ndarray) -> np.ndarray:
    """S⁻¹ = (A⁻¹)[rows][:, rows] from MUMPS' Schur complement of A on ``rows`` (sorted), a new factorization."""
    lib = inverse_entries._library()
    for name in (
        "MatFactorSetSchurIS",
        "MatFactorGetSchurComplement",
        "MatFactorRestoreSchurComplement",
        "MatDenseGetArrayRead",
        "MatDenseRestoreArrayRead",
        "MatDenseGetLDA",
    ):
        getattr(lib, name).restype = ctypes.c_int
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A)
    ksp.setType("preonly")
    pc = ksp.getPC()
    pc.setType("lu")
    pc.setFactorSolverType("mumps")
    pc.setFactorSetUpSolverType()
    F = ctypes.c_void_p(pc.getFactorMatrix().handle)
    index = PETSc.IS().createGeneral(rows.astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    assert lib.MatFactorSetSchurIS(F, ctypes.c_void_p(index.handle)) == 0
    ksp.setUp()
    assert pc.getFailedReason() == 0
    S, status = ctypes.c_void_p(), ctypes.c_int()
    assert lib.MatFactorGetSchurComplement(F, ctypes.byref(S), ctypes.byref(status)) == 0
    lda = (ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32)()
    data = ctypes.POINTER(ctypes.c_double)()
    assert lib.MatDenseGetLDA(S, ctypes.byref(lda)) == 0
    assert lib.MatDenseGetArrayRead(S, ctypes.byref(data)) == 0
    n = rows.size
    dense = np.ctypeslib.as_array(data, shape=(n, lda.value))[:, :n].T.copy()  # column-major, leading dim lda
    lib.MatDenseRestoreArrayRead(S, ctypes.byref(data))
    lib.MatFactorRestoreSchurComplement(F, ctypes.byref(S), status)
    index.destroy()
    ksp.destroy()
    return sla.lu_solve(sla.lu_factor(dense), np.eye(n))


class SchurSolver:
    """Stands in for a part's DirectSolver in ``PrimalPart.responses``: the inverse block from a Schur complement."""

    def __init__(self, solver) -> None:
        self.solver = solver
        self.ksp = solver.ksp

    def has_inverse_entries(self) -> bool:
        return True

    def inverse_block(self, rows: np.ndarray, *, sweep: np.ndarray | None = None) -> np.ndarray:
        """The whole block (``sweep``, the triangle ``DirectSolver.inverse_block`` takes, does not apply here)."""
        return schur_inverse(self.ksp.getOperators()[0], rows)


def relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), np.finfo(float).tiny))


def timed(fn, repeat: int):
    best, out = np.inf, None
    for _ in range(repeat):
        start = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - start)
    return best, out


def responses(args, h: int) -> list[str]:
    """Part 1: rows of the response table at h = 1/h."""
    step = PrimalHybridStep(problem_on(h, args.H, args.contrast))
    step.prepare()
    parts = [
        (r"Ω₁: T₁", PrimalPart(step.sub[0], step.interface, 0, contact=False), False),
        (r"Ω₂ (J₀): Yc, Sc, Yq, Sq", PrimalPart(step.sub[1], step.interface, 1, contact=True), True),
    ]
    rows = []
    for name, part, contact in parts:
        times = {}
        for _ in range(args.repeat):  # alternate the variants
            for variant, fn in (
                ("solves", lambda: AffinePart.responses(part, contact=contact, chunk=args.chunk)),
                ("schur", lambda: part.responses(contact=contact, chunk=args.chunk, solver=SchurSolver(part.solver))),
                ("entries", lambda: part.responses(contact=contact, chunk=args.chunk)),
            ):
                t, out = timed(fn, 1)
                best, _ = times.get(variant, (np.inf, None))
                times[variant] = (min(best, t), out)
        ref = times["solves"][1]
        diff = {v: max(relative(a, b) for a, b in zip(times[v][1], ref)) for v in ("schur", "entries")}
        n_dofs = part.nown
        rows.append(
            f"| 1/{h} | {name} | {n_dofs} | {part.n_g} | {part.n_c if contact else 0} "
            f"| {times['solves'][0]:.2f} | {times['schur'][0]:.2f} | {times['entries'][0]:.3f} "
            f"| {times['solves'][0] / times['entries'][0]:.1f} | {diff['schur']:.1e} | {diff['entries']:.1e} |"
        )
        print(rows[-1], flush=True)
    parts[1][1].destroy()
    return rows


def blocking(args, h: int) -> list[str]:
    """Ω₁'s back-solves at h = 1/h in blocks of 32, 128, 1024 columns and MUMPS multi-RHS blocking ICNTL(27)."""
    step = PrimalHybridStep(problem_on(h, args.H, args.contrast))
    step.prepare()
    part = PrimalPart(step.sub[0], step.interface, 0, contact=False)
    factor = part.solver.ksp.getPC().getFactorMatrix()
    default = factor.getMumpsIcntl(27)
    rows = []
    for icntl27 in (default, 128, 512):
        factor.setMumpsIcntl(27, icntl27)
        times = [
            timed(lambda: AffinePart.responses(part, contact=False, chunk=chunk), args.repeat)[0]
            for chunk in (32, 128, 1024)
        ]
        rows.append(f"| 1/{h} | {icntl27} | " + " | ".join(f"{t:.2f}" for t in times) + " |")
        print(rows[-1], flush=True)
    factor.setMumpsIcntl(27, default)
    return rows


def load_path(args, h: int) -> list[str]:
    """Part 2: the load path with the back-solves and with the entries (alternating), min over repetitions."""
    depths = np.linspace(0.002, 0.02, args.steps)
    problem = problem_on(h, args.H, args.contrast)
    own = PrimalPart.responses
    runs: dict[str, list] = {"solves": [], "entries": []}
    for _ in range(args.repeat):
        for variant in runs:
            PrimalPart.responses = AffinePart.responses if variant == "solves" else own
            try:
                start = time.perf_counter()
                curve = fc.force_indentation(problem, "primal", depths, direction=(-1.0, 0.0), tol=args.tol)
                total = time.perf_counter() - start
            finally:
                PrimalPart.responses = own
            runs[variant].append(
                (
                    total,
                    curve.steps[0].time_offline_s,
                    curve.forces,
                    [s.iterations for s in curve.steps],
                    [s.interface_newton_steps for s in curve.steps],
                    all(s.converged for s in curve.steps),
                )
            )
    ref = runs["solves"][0]
    rows = []
    for variant, out in runs.items():
        forces, its, newton = out[0][2], out[0][3], out[0][4]
        same = all(o[3] == its and o[4] == newton for o in out) and its == ref[3] and newton == ref[4]
        rows.append(
            f"| 1/{h} | {variant} | {min(o[1] for o in out):.2f} | {min(o[0] for o in out):.2f} "
            f"| {relative(forces, ref[2]):.1e} | {sum(its)} / {sum(newton)} | {'yes' if same else 'NO'} "
            f"| {'yes' if all(o[5] for o in out) else 'NO'} |"
        )
        print(rows[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[128, 256], help="1/h of the unit-square meshes")
    parser.add_argument("--H", type=int, default=16)
    parser.add_argument("--contrast", type=float, default=1e3)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--tol", type=float, default=1e-8)
    parser.add_argument("--chunk", type=int, default=InterfaceNewtonOptions().chunk)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--skip-load-path", action="store_true")
    parser.add_argument(
        "--blocking",
        action="store_true",
        help="only Ω₁'s back-solves at the largest h: block sizes against MUMPS' ICNTL(27)",
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    lines = [
        f"# Algorithm 1's interface responses: back-solves, Schur complement, entries of J⁻¹ (model 3, "
        f"cylinder, contrast {args.contrast:g}, H = 1/{args.H})",
        "",
        f"Command: `OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} .venv/bin/python "
        f"benchmarks/interface_response.py {' '.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        f"Times: minimum of {args.repeat} repetitions, the variants alternating, in one process.",
        "",
        f"## Responses (back-solves in blocks of {args.chunk} right-hand sides)",
        "",
        "| h | response | DOFs | n_γ | n_c | back-solves [s] | Schur [s] | entries [s] | speed-up (entries) "
        "| Schur − solves | entries − solves |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    if args.blocking:
        h = max(args.h)
        lines = [
            f"## Ω₁'s back-solves at h = 1/{h}: columns per MatMatSolve against MUMPS' ICNTL(27)",
            "",
            f"Command: `OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} .venv/bin/python "
            f"benchmarks/interface_response.py {' '.join(sys.argv[1:])}` (minimum of {args.repeat})",
            "",
            "| h | ICNTL(27) | 32 columns [s] | 128 columns [s] | 1024 columns [s] |",
            "|---|---|---|---|---|",
        ]
        lines += blocking(args, h)
        print("\n".join(lines))
        if args.out:
            with args.out.open("a") as out:
                out.write("\n" + "\n".join(lines) + "\n")
        return
    for h in args.h:
        lines += responses(args, h)
    if not args.skip_load_path:
        lines += [
            "",
            f"## Load path ({args.steps} steps, ``primal``, tol {args.tol:g})",
            "",
            "forces: largest difference to the back-solves' curve, relative to its largest force; iterations: "
            "applications of T / interface Newton steps over all steps; same: those counts equal in every "
            "repetition and to the back-solves'.",
            "",
            "| h | responses | offline in step 1 [s] | whole curve [s] | forces − back-solves "
            "| iterations / Newton steps | same | all certified |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for h in args.h:
            lines += load_path(args, h)
    text = "\n".join(lines) + "\n"
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
