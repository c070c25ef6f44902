"""Algorithm 1 in 3D: which update reaches the fixed point fastest on the 3D channel model (one process).

The model is ``problem.models3d.channels_3d`` on ``channels_3d_mesh(n)`` (the unit cube, Γ_C the face x = 1,
Ω₂ the layer x > ¾, stiff channels through γ to Γ_C, the load in Ω₁, rollers on z = 0 and z = 1). For each
h and contrast it solves

* ``monolithic``: the primal monolithic penalized problem (the reference u_h);
* ``newton``: the interface Newton (condensed), its interface responses from the entries of J⁻¹ that MUMPS
  computes from the factors (``PrimalPart.responses`` on one process, the default);
* ``newton, back-solves``: the same with the responses by blocked multi-RHS back-solves
  (``AffinePart.responses``, this script only);
* ``anderson``: Anderson acceleration (depth 10) of the Robin iteration;
* ``newton, AMG Ω₁`` and ``anderson, AMG Ω₁``: Ω₁ solved by CG + AMG (``solver="amg"``, rtol ``--amg-rtol``,
  one AMG set-up for the whole solve): the matrix-free Newton–GMRES interface Newton (``hybrid.krylov_newton``;
  steps: Newton steps and in brackets the GMRES products, each one Ω₁ solve and one Ω₂ back-solve (the applications of
  T take Ω₁'s state as a combination of the products', corrected by a solve where it is off); its GMRES
  preconditioned by the band and AMG coarse model of Ω₁, ``hybrid.krylov_band``, the default) and Anderson
  (depth 10); ``newton, AMG Ω₁, unpreconditioned``: the Newton–GMRES without the preconditioner; ``--models L:C …``
  adds one Newton–GMRES row per preconditioner model (band of L layers, AMG coarse functions C levels down);

each to the transmission residual ``--tol``, and reports the times (offline: the subdomain factorizations
and the interface responses; online: the rest), the interface Newton's steps (and the local front
problems' iterations), the applications of T, the transmission residual and e_u against the monolithic
solution.  n_γ is the number of interface values, n_c of Γ_C unknowns: the dense interface matrices hold
O((n_γ + n_c)²) numbers.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 8 16 24 --contrast 1e3 1e6 \\
        --out benchmarks/results/primal_hybrid_3d.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 24 32 --contrast 1e3 1e6 \
        --variants "newton, AMG Ω₁" "anderson, AMG Ω₁" --out benchmarks/results/primal_hybrid_3d_amg.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 24 --contrast 1e3 1e6 --monolithic amg \
        --variants "newton, AMG Ω₁" "newton, AMG Ω₁, unpreconditioned" \
        --out benchmarks/results/primal_hybrid_3d_amg_preconditioned.md
    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 --contrast 1e3 1e6 --variants \
        --models 3:0 6:0 0:1 2:1 3:1 2:2 --out benchmarks/results/primal_hybrid_3d_amg_models.md

``--windows W …`` instead compares the contact Newton's local front resolution on the contact surface
(``InterfaceNewtonOptions.front_window`` = W; 0: the plain semismooth Newton) at every h and contrast:

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 8 12 16 24 --contrast 1e6 \\
        --windows 0 3 8 --out benchmarks/results/primal_hybrid_3d_fronts.md

``--load-path N`` instead measures what a load step costs: the model pressed by the plane x ≥ 1 − d moved along −x
in N steps (``force_indentation``), the CPU time per load step of the monolithic solve (and per Newton step) and of
Algorithm 1 (the condensed interface Newton, MUMPS in Ω₁; A/B: the condensed interface's load-step savings on and
off, alternated ``--repeat`` times on the same step), Algorithm 1's step by part (CPU timers around the functions
that do the work) and, over several h, a log-log fit of both per-step costs against the DOFs:

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py --h 16 24 32 --contrast 1e3 1e6 \\
        --load-path 6 --repeat 3 --monolithic amg --out benchmarks/results/primal_hybrid_3d_load_steps.md
"""

import argparse
import contextlib
import functools
import shlex
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

import fenics_contact as fc  # noqa: F401  (dolfinx_solver before petsc4py)
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.hybrid import condensation, primal
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import AffinePart, PrimalPart
from fenics_contact.hybrid.transmission import InterfaceSpace
from fenics_contact.indentation import force_indentation
from fenics_contact.io import machine_description
from fenics_contact.methods import solve
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane

VARIANTS = (
    "newton",
    "newton, back-solves",
    "anderson",
    "newton, AMG Ω₁",
    "newton, AMG Ω₁, unpreconditioned",
    "anderson, AMG Ω₁",
)


def run(
    n: int,
    contrast: float,
    variants,
    tol: float,
    max_iterations: int,
    amg_rtol: float = 1e-10,
    monolithic: str = "auto",
    models=(),
):
    """The rows of one mesh and contrast, one by one; ``models``: (layers, coarse) pairs of the Newton–GMRES
    preconditioner's Ω₁ model, each run as a variant ``newton, AMG Ω₁ [layers:coarse]``."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n))
    start, cpu = time.perf_counter(), time.process_time()
    ref = solve(problem, "primal-monolithic", solver=monolithic)
    cpu = time.process_time() - cpu
    its = ref.krylov_iterations
    yield {
        "h": f"1/{n}",
        "contrast": f"{contrast:.0e}",
        "variant": f"monolithic ({ref.linear_solver})",
        "dofs": ref.dofs,
        "offline": None,
        "online": time.perf_counter() - start,
        "cpu": cpu,
        "steps": f"{ref.newton.steps} (Newton)" + (f", CG {min(its)}–{max(its)}" if its else ""),
        "T": None,
        "residual": None,
        "e_u": None,
    }
    entries = PrimalPart.responses
    runs = [(v, {"krylov_layers": None} if v.endswith("unpreconditioned") else {}) for v in variants]
    runs += [(f"newton, AMG Ω₁ [{m[0]}:{m[1]}]", {"krylov_layers": m[0], "krylov_coarse": m[1]}) for m in models]
    for variant, krylov in runs:
        accel = variant.split(",")[0]
        amg = "AMG Ω₁" in variant
        solver = LinearSolverOptions(kind="amg", rtol=amg_rtol) if amg else "direct"
        if variant.endswith("back-solves"):
            PrimalPart.responses = AffinePart.responses
        cpu = time.process_time()
        try:
            result = solve(
                problem,
                "primal",
                accel=accel,
                tol=tol,
                reference=ref.u,
                max_iterations=max_iterations,
                solver=solver,
                **krylov,
            )
        finally:
            PrimalPart.responses = entries
        cpu = time.process_time() - cpu
        history = result.history
        ch = history.contact_newton
        if accel == "newton" and amg:
            kry = result.step.krylov_interface()
            per = kry.products / max(history.newton_steps, 1)
            steps = f"{history.newton_steps} ({kry.products} products, {per:.1f} per step)"
            band = kry.preconditioner
            if band is not None:
                steps += f"; Ω₁ model {band.size} unknowns, {band.factorizations} factorizations"
        elif accel == "newton":
            steps = f"{history.newton_steps} ({ch.local_iterations} local)"
        else:
            steps = f"{history.iterations}"
        if amg:
            cg = result.step.sub[0].solver.iterations
            steps += f"; {len(cg)} Ω₁ solves, CG median {int(np.median(cg))}, {sum(cg)} in all"
        yield (
            {
                "h": f"1/{n}",
                "contrast": f"{contrast:.0e}",
                "variant": variant,
                "dofs": f"{result.dofs['omega1']} + {result.dofs['omega2']}, n_γ {result.dofs['interface']}, "
                f"n_c {result.profile.points.shape[0]}",
                "offline": result.time_offline_s,
                "online": result.time_online_s,
                "cpu": cpu,
                "steps": steps,
                "T": history.iterations,
                "residual": history.transmission_residual,
                "e_u": result.e_u,
                "converged": result.converged,
            }
        )
        result.step.reset()


def windows(n: int, contrast: float, widths, tol: float):
    """The interface Newton with each front window on one mesh and contrast: its rows, one by one."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(n))
    ref = solve(problem, "primal-monolithic")
    step = None
    for width in widths:
        result = solve(problem, "primal", accel="newton", front_window=width, tol=tol, reference=ref.u, step=step)
        step = result.step
        ch = result.history.contact_newton
        yield {
            "h": f"1/{n}",
            "contrast": f"{contrast:.0e}",
            "window": width,
            "n_c": result.profile.points.shape[0],
            "monolithic": ref.newton.steps,
            "steps": result.history.newton_steps,
            "sizes": " ".join(str(k) for k in ch.active_sizes),
            "local": f"{sum(w for w, _, _ in ch.local)} / {ch.local_iterations} / "
            f"{max([m for _, _, m in ch.local] or [0])}",
            "online": result.time_online_s,
            "e_u": result.e_u,
        }
        step.reset()


#: (label, owner, attribute): the functions of a load step timed by ``--load-path`` (a call inside another timed one
#: counts for the outer one); the rest of the step is the Python around them
PARTS = (
    ("obstacle moved (gap at the Γ_C nodes)", PrimalSubproblem, "set_obstacle"),
    ("load term s_L (kept J⁻¹b, one dense solve)", CondensedInterface, "load_terms"),
    ("contact Newton on Γ_C (dense)", condensation, "contact_solve"),
    ("data from λ (products with the condensation)", CondensedInterface, "times"),
    ("Ω₂ warm state (one J₀ back-solve)", PrimalPart, "solve"),
    ("Ω₁ solve (kept J⁻¹b + one back-solve of the data)", PrimalHybridStep, "_solve_omega1"),
    ("Ω₂ check (its residual at the warm state)", primal, "solve_or_verify"),
    ("γ traces and data (transfers)", InterfaceSpace, "from_part"),
    ("γ traces and data (transfers)", InterfaceSpace, "to_part"),
    ("relative change (products)", PrimalHybridStep, "_measure"),
    ("certificate", primal, "primal_certificate"),
    ("force (contact profile of Ω₂)", PrimalSubproblem, "contact_profile"),
)


class _PartTimers:
    """CPU timers around ``PARTS`` while ``on`` (installed by ``with``)."""

    def __init__(self) -> None:
        self.spent: dict[str, float] = defaultdict(float)
        self.on, self._depth, self._originals = False, 0, []

    def __enter__(self):
        for label, owner, name in PARTS:
            fn = getattr(owner, name)
            self._originals.append((owner, name, fn))

            @functools.wraps(fn)
            def timed(*args, _fn=fn, _label=label, **kwargs):
                start = time.process_time()
                self._depth += 1
                try:
                    return _fn(*args, **kwargs)
                finally:
                    self._depth -= 1
                    if self.on and self._depth == 0:
                        self.spent[_label] += time.process_time() - start

            setattr(owner, name, timed)
        return self

    def __exit__(self, *exc) -> None:
        for owner, name, fn in reversed(self._originals):
            setattr(owner, name, fn)


@contextlib.contextmanager
def _plain_online():
    """B of ``--load-path``'s A/B: ``CondensedInterface`` with its load-step savings off (the contact Newton from
    ``start``, {s_L > 0} on a fixed obstacle, warm start or not, no factors kept; the load term's dense solve at
    every step; Gq, Yq never formed: ``times`` by the per-component pieces)."""
    solve, load_terms, form = CondensedInterface.solve, CondensedInterface.load_terms, CondensedInterface.form_products

    def plain_solve(self, options, name, *, warm=False):
        self._factors = None  # (every dense system factorized afresh)
        try:
            return solve(self, options, name)
        finally:
            self._factors = {}

    def plain_load_terms(self):
        self._load = None
        return load_terms(self)

    CondensedInterface.solve, CondensedInterface.load_terms = plain_solve, plain_load_terms
    CondensedInterface.form_products = lambda self: None
    try:
        yield
    finally:
        CondensedInterface.solve, CondensedInterface.load_terms, CondensedInterface.form_products = (
            solve,
            load_terms,
            form,
        )


def _curve(problem, method, depths, timers=None, **options):
    """One force–indentation curve: (curve, CPU seconds of each load step)."""
    cpu, last = [], [time.process_time()]

    def on_step(record, solver):
        now = time.process_time()
        cpu.append(now - last[0])
        last[0] = now
        if timers is not None:
            timers.on = True  # (from the second step on)

    curve = force_indentation(problem, method, depths, direction=(-1.0, 0.0, 0.0), on_step=on_step, **options)
    if timers is not None:
        timers.on = False
    return curve, np.array(cpu)


def load_path(n: int, contrast: float, steps: int, depth: float, repeat: int, tol: float, monolithic: str):
    """The load path of ``--load-path`` on one mesh and contrast: (row, parts) with the CPU per load step of both
    methods (steps 2…N) and Algorithm 1's parts (ms per step, over its warm-started curves)."""
    problem = channels_3d(E_high=contrast).with_(obstacle=Plane((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0)))
    problem = problem.on(channels_3d_mesh(n))
    depths = np.linspace(0.0, depth, steps)
    mono, mono_cpu = _curve(problem, "primal-monolithic", depths, solver=monolithic)
    newton = np.array([s.iterations for s in mono.steps])
    cold_step = mono_cpu[0] / newton[0]  # the first step: the cold solve of the problem with the plane at x = 1
    mono_step = mono_cpu[1:].mean()
    mono_newton = mono_cpu[1:].sum() / newton[1:].sum()
    opts = dict(accel="newton", tol=tol)
    cpu = time.process_time()
    first, first_cpu = _curve(problem, "primal", depths, **opts)
    offline = time.process_time() - cpu - first_cpu[1:].sum()  # (the build and the first step)
    step = first.step
    per = {"A": [], "B": []}
    forces, residuals, newton_steps = [], [], {"A": [], "B": []}
    with _PartTimers() as timers:
        for _ in range(repeat):
            for build in ("A", "B"):  # alternated: the machine's load falls on both alike
                with _plain_online() if build == "B" else contextlib.nullcontext():
                    curve, cpu = _curve(problem, "primal", depths, timers if build == "A" else None, step=step, **opts)
                per[build].append(cpu[1:].mean())
                newton_steps[build] += [s.interface_newton_steps for s in curve.steps[1:]]
                forces.append(curve.forces)
                residuals.append(curve.transmission_residuals.max())
    a, b = float(np.median(per["A"])), float(np.median(per["B"]))
    force_error = max(float(np.max(np.abs(f / mono.forces - 1.0))) for f in forces)
    sub = first.step.sub
    row = {
        "h": f"1/{n}",
        "contrast": f"{contrast:.0e}",
        "dofs": f"{mono.contact.num_dofs} ({sub[0].num_dofs} + {sub[1].num_dofs})",
        "cold": f"{mono_cpu[0]:.2f} / {newton[0]} = {cold_step:.3f}",
        "mono": f"{mono_step:.3f} ({newton[1:].mean():.1f} Newton steps: {mono_newton:.3f} each)",
        "offline": offline,
        "A": f"{1e3 * a:.1f} ({np.mean(newton_steps['A']):.1f})",
        "B": f"{1e3 * b:.1f} ({np.mean(newton_steps['B']):.1f})",
        "ratio": f"{a / mono_newton:.3f} / {b / mono_newton:.3f}",
        "ratio_cold": f"{a / cold_step:.3f}",
        "ratio_step": f"{a / mono_step:.4f}",
        "force": force_error,
        "residual": max(residuals),
        "_fit": (mono.contact.num_dofs, a, mono_newton, cold_step),
    }
    count = repeat * (steps - 1)
    parts = {label: 1e3 * t / count for label, t in timers.spent.items()}
    parts["rest (Python around the parts)"] = 1e3 * float(np.mean(per["A"])) - sum(parts.values())
    return row, parts


def _cell(value) -> str:
    if value is None:
        return "—"
    if isinstance(value, float):
        return f"{value:.2f}" if value >= 0.01 else f"{value:.1e}"
    return str(value)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--h", type=int, nargs="+", default=[8, 16, 24], help="1/h of the cube meshes")
    parser.add_argument("--contrast", type=float, nargs="+", default=[1e3, 1e6])
    parser.add_argument("--variants", nargs="*", default=list(VARIANTS), choices=VARIANTS)
    parser.add_argument("--tol", type=float, default=1e-8, help="transmission residual to reach")
    parser.add_argument("--max-iterations", type=int, default=1000, help="Anderson's cap")
    parser.add_argument("--amg-rtol", type=float, default=1e-10, help="the AMG Ω₁'s CG tolerance")
    parser.add_argument(
        "--monolithic", default="auto", choices=("auto", "direct", "amg"), help="the monolithic solve's linear solver"
    )
    parser.add_argument(
        "--models",
        nargs="+",
        default=[],
        metavar="LAYERS:COARSE",
        help="Newton–GMRES preconditioner models to compare (band layers : AMG coarse depth, 0 none)",
    )
    parser.add_argument("--windows", type=int, nargs="+", default=None, help="compare these front windows")
    parser.add_argument(
        "--load-path", type=int, default=None, metavar="STEPS", help="CPU per load step of a path of STEPS steps"
    )
    parser.add_argument("--depth", type=float, default=0.02, help="the load path's last depth of the plane")
    parser.add_argument("--repeat", type=int, default=3, help="the load path's A/B alternations")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    models = [tuple(int(k) for k in m.split(":")) for m in args.models]
    if args.windows is not None:
        return _windows_table(args)
    if args.load_path is not None:
        return _load_path_table(args)
    head = ["h", "contrast", "variant", "DOFs", "offline [s]", "online [s]", "CPU [s]", "steps", "applications of T",
            "transmission residual", "e_u", "converged"]  # fmt: skip
    keys = [
        "h",
        "contrast",
        "variant",
        "dofs",
        "offline",
        "online",
        "cpu",
        "steps",
        "T",
        "residual",
        "e_u",
        "converged",
    ]
    lines = [
        "# Algorithm 1 in 3D: interface Newton and Anderson on the 3D channel model",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py {shlex.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        f"Every hybrid solve stops at the transmission residual {args.tol:g} (Anderson at most "
        f"{args.max_iterations} iterations); steps: the interface Newton's (contact Newton steps and "
        "corrections; in brackets the iterations of its local front problems) or Anderson's iterations; "
        "with an AMG Ω₁ (CG rtol " + f"{args.amg_rtol:g}" + ") the Newton–GMRES steps and its products (each one "
        "Ω₁ solve and one Ω₂ back-solve), the size of the preconditioner's Ω₁ model and its factorizations, the Ω₁ "
        "solves in all (the products, and the solves correcting a combination of their states: the first and the "
        "certified pair among them), their median CG iterations and their sum; "
        "e_u: relative L² distance to the monolithic solution; times on a machine shared with other jobs "
        "(CPU: the process's CPU time of the whole solve, offline and online, which the sharing does not inflate).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for n in args.h:
        for contrast in args.contrast:
            for row in run(
                n, contrast, args.variants, args.tol, args.max_iterations, args.amg_rtol, args.monolithic, models
            ):
                lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
                print(lines[-1], flush=True)
                if args.out is not None:
                    args.out.write_text("\n".join(lines) + "\n")


def _windows_table(args) -> None:
    head = ["h", "contrast", "front window", "n_c", "monolithic Newton steps", "interface Newton steps",
            "active-set sizes", "local problems / iterations / largest window", "online [s]", "e_u"]  # fmt: skip
    keys = ["h", "contrast", "window", "n_c", "monolithic", "steps", "sizes", "local", "online", "e_u"]
    lines = [
        "# Algorithm 1 in 3D: the contact Newton's local front resolution on the contact surface",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py {shlex.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        "The 3D channel model; the interface Newton (condensed) with the front window W (0: the plain "
        "semismooth Newton on the Γ_C unknowns), the same step reused; local: the front problems solved, "
        "their semismooth iterations and the largest window (unknowns).",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for n in args.h:
        for contrast in args.contrast:
            for row in windows(n, contrast, args.windows, args.tol):
                lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
                print(lines[-1], flush=True)
                if args.out is not None:
                    args.out.write_text("\n".join(lines) + "\n")


def _fit(points) -> str:
    """log-log least squares of (DOFs, Algorithm 1's step, the monolithic Newton step): exponents, the ratio at 10⁶."""
    N, a, m, _ = (np.array(v, dtype=float) for v in zip(*points))
    pa, ca = np.polyfit(np.log(N), np.log(a), 1)
    pm, cm = np.polyfit(np.log(N), np.log(m), 1)
    at = np.exp(ca + pa * np.log(1e6)) / np.exp(cm + pm * np.log(1e6))
    return f"Algorithm 1's load step ∝ N^{pa:.2f}, the monolithic Newton step ∝ N^{pm:.2f}: ratio {at:.3f} at N = 10⁶"


def _load_path_table(args) -> None:
    head = ["h", "contrast", "DOFs (Ω₁ + Ω₂)", "monolithic cold solve: CPU / Newton steps [s]",
            "monolithic load step [s]", "Alg. 1 offline and first step [s]",
            "Alg. 1 load step A [ms] (interface Newton steps)", "B [ms] (steps)",
            "per monolithic Newton step (A / B)", "per cold Newton step", "per monolithic load step",
            "max |F/F_mono − 1|", "max transmission residual"]  # fmt: skip
    keys = ["h", "contrast", "dofs", "cold", "mono", "offline", "A", "B", "ratio", "ratio_cold", "ratio_step",
            "force", "residual"]  # fmt: skip
    lines = [
        "# Algorithm 1 in 3D: CPU per load step against the monolithic Newton step",
        "",
        f"Command: `OMP_NUM_THREADS=1 .venv/bin/python benchmarks/primal_hybrid_3d.py {shlex.join(sys.argv[1:])}`",
        "",
        f"Machine: {machine_description()}",
        "",
        f"The 3D channel model pressed by the plane x ≥ 1 − d (``Plane((1, 0, 0), (−1, 0, 0))`` moved along −x), "
        f"d = 0 … {args.depth:g} in {args.load_path} load steps (``force_indentation``, warm starts); the "
        f"monolithic solve with solver `{args.monolithic}`, Algorithm 1 with MUMPS in Ω₁ and the condensed "
        f"interface Newton to the transmission residual {args.tol:g}.  CPU times of the process "
        "(`time.process_time`; the machine is shared, wall times are not comparable): the monolithic cold solve "
        "(the first step) per Newton step; a load step: the mean over steps 2…N (monolithic: and per Newton step); "
        "Algorithm 1 after its first curve, the same step reused by "
        f"{args.repeat} pairs of curves, alternately A (the condensed interface's load-step savings: the contact "
        "Newton from the last step's active set, its dense system's factors kept, the load term's dense solve kept "
        "while the load responses are, "
        "Gq and Yq formed once per normals) and B (without them: from {s_L > 0}, the dense solve at every step, "
        "the products by components); their medians, in brackets the interface Newton steps per load step.  The ratios: "
        "A's load step over the monolithic load step's Newton step (A / B), over the cold solve's Newton step, "
        "over the monolithic load step.  F: the contact force of every step of every curve against the monolithic "
        "one.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    parts, fits = {}, defaultdict(list)

    def write(extra=()):
        if args.out is not None:
            args.out.write_text("\n".join(lines + list(extra)) + "\n")

    for n in args.h:
        for contrast in args.contrast:
            row, parts[(n, contrast)] = load_path(
                n, contrast, args.load_path, args.depth, args.repeat, args.tol, args.monolithic
            )
            fits[contrast].append(row["_fit"])
            lines.append("| " + " | ".join(_cell(row.get(k)) for k in keys) + " |")
            print(lines[-1], flush=True)
            write()
    labels = list(dict.fromkeys(label for p in parts.values() for label in p))
    tail = [
        "",
        "Algorithm 1's load step (A) by part, CPU ms per step (a part called inside another counts for it):",
        "",
    ]
    tail += ["| part | " + " | ".join(f"1/{n}, {c:.0e}" for n, c in parts) + " |", "|---|" + "---|" * len(parts)]
    tail += [
        f"| {label} | " + " | ".join(f"{p.get(label, 0.0):.1f}" for p in parts.values()) + " |" for label in labels
    ]
    if len(args.h) > 1:
        tail += ["", "Fit over the sizes run (N the monolithic DOFs):", ""]
        tail += [f"* contrast {c:.0e}: {_fit(points)}" for c, points in fits.items()]
    lines += tail
    print("\n".join(tail))
    write()


if __name__ == "__main__":
    main()
