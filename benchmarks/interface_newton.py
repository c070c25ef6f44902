"""Interface Newton (``--accel newton``) against the fixed-point updates, for all four algorithms.

    OMP_NUM_THREADS=1 python benchmarks/interface_newton.py --parts steps,updates,speed \\
        --out benchmarks/results/interface_newton.md

Parts (each a table; all ratios are taken within one run, on one machine):

* ``steps``: Newton steps (contact Newton + corrections on F(g)) to a transmission residual of
  1e-6 for every algorithm, models 1, 2, 3 (E_high 1e3, 1e6), H = 1/16, h = 1/32 … 1/256 (primal)
  and 1/32 … 1/128 (mixed), α = c × the default (Algorithm 1 E·h^-1/2, Algorithm 3 Emin·h^-1/2) and
  β = c·√h for c = 1e-2, 1, 1e4 (``--h-primal``,
  ``--h-mixed``, ``--factors``; the multiscale Ω₁ of Algorithms 3/4 is rebuilt for every α, β, so
  their largest h only at c = 1: ``--big-default-only``).  Each cell also gives, in brackets, the count
  of the other contact Newton on the same condensed problem (the plain one; the default local front
  resolution when ``--front-window 0`` makes the plain one the main count);
  ``--dump DIR`` saves every condensed contact problem (s_L, M, D, coordinates) for offline study.
* ``updates``: none / anderson / newton on every model and algorithm at h = 1/64, H = 1/16:
  converged?, applications of T, online time, final transmission residual (the CLI default is the
  update that converges everywhere fastest).
* ``fronts``: the contact Newton of Algorithm 1 on model 3 at contrast 1e6 (h from ``--h-primal``): the
  Γ_C nodes each step adds / removes (plain and the default local front resolution), and the step counts
  of other starts (all active, nested Galerkin-coarsened Γ_C levels, a path in the penalty) and of the
  line search at every step.
* ``speed``: online time / monolithic semismooth Newton (Newton only, same run) for Algorithms 1 and
  3 at h = 1/256, H = 1/16, model 2 (Algorithms 2, 4: ``reproduce_mixed_ms_tables.py --tables 5.8``),
  with the offline interface response beside it.

Model 3 at contrast 1e6 uses the Ω₂ Newton acceptance test ‖F‖ ≤ 1e-6‖b‖ (the default 1e-8 is
below the round-off of its penalty and Robin stiffness there).
"""

import argparse
import logging
import time
from pathlib import Path

import numpy as np
from common import write_report

import fenics_contact  # noqa: F401  (must precede dolfinx / petsc4py)
from fenics_contact.errors import FenicsContactError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import contact_modulus, default_epsilon, solve_mixed_monolithic
from fenics_contact.fem.primal import PrimalSubproblem, default_penalty
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.contact_newton import contact_newton
from fenics_contact.hybrid.fronts import contact_chains
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions, iterate
from fenics_contact.hybrid.mixed import MixedHybridStep
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.io import machine_description
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.tags import Subdomain

#: interface Newton options of the steps part (``--chunk``: right-hand sides per multi-RHS back-solve)
NEWTON = InterfaceNewtonOptions()
#: (label, model number, E_high)
MODELS = [("1", 1, 1e3), ("2", 2, 1e3), ("3 (1e3)", 3, 1e3), ("3 (1e6)", 3, 1e6)]
LAYERS = 3
#: ``--dump DIR``: the steps part saves every condensed contact problem (s_L, M, D, coordinates) there
DUMP: Path | None = None


def _strip_modulus(cm, E) -> float:
    return float(np.max(E.x.array[cm.cell_tags.find(Subdomain.OMEGA2)]))


def build_step(method: int, cm, number: int, E_high: float, factor: float = 1.0):
    """The step of Algorithm ``method`` with α = factor × its default (Algorithm 1: E·h^-1/2, 3: Emin·h^-1/2)
    or β = factor·√h (penalties as the CLI)."""
    problem = get_model(number, E_high=E_high).on(cm)
    newton = NewtonOptions(rtol=1e-6) if E_high > 1e3 else NewtonOptions()
    if method in (1, 3):
        fields = problem.fields
        delta = default_penalty(cm.h, _strip_modulus(cm, fields.E))
        alpha = f"{factor:g}*E*h^-1/2" if method == 1 else f"{factor:g}*Emin*h^-1/2"  # each method's default × c
        if method == 1:
            step = PrimalHybridStep(problem, alpha=alpha, delta=delta, newton=newton)
            step.prepare()
            return step
        return MultiscalePrimalHybridStep(
            problem, alpha=alpha, delta=delta, newton=newton, cem=CEMOptions(layers=LAYERS)
        )
    fields = problem.fields
    epsilon = default_epsilon(cm.h, contact_modulus(cm.mesh, cm.facet_tags, fields.E, smallest=True))
    beta = factor * np.sqrt(cm.h)
    if method == 2:
        step = MixedHybridStep(problem, beta=beta, epsilon=epsilon, newton=newton)
        step.prepare()
        return step
    return MixedMultiscaleHybridStep(
        problem, beta=beta, epsilon=epsilon, newton=newton, cem=MixedCEMOptions(layers=LAYERS)
    )


def monolithic_steps(method: int, cm, number: int, E_high: float) -> str:
    """Steps of the monolithic semismooth Newton (Algorithm 1 / 2 discretization; '—' for 3, 4)."""
    if method in (3, 4):
        return "—"
    model = get_model(number, E_high=E_high)
    newton = NewtonOptions(rtol=1e-6) if E_high > 1e3 else NewtonOptions()
    fields = material_fields(cm.mesh, model)
    try:
        if method == 1:
            delta = default_penalty(cm.h, _strip_modulus(cm, fields.E))
            mono = PrimalSubproblem(
                cm.mesh, cm.facet_tags, fields, delta=delta, alpha=None, prefix="fc_bench_mono_", newton=newton
            )
            steps = mono.solve().steps
            mono.destroy()
            return str(steps)
        return str(solve_mixed_monolithic(model.on(cm), newton=newton, split_interface=True, verify=False).newton.steps)
    except FenicsContactError as err:
        return f"error: {type(err).__name__}"


def _main_kind() -> str:
    """The contact Newton of the main count: 'local' (the default front windows) or 'plain'."""
    return "local" if NEWTON.front_window else "plain"


def other_steps(step, hist) -> str:
    """Steps the solve takes with the plain contact Newton (no front windows), or with the
    default local front resolution when the main count is the plain one: the same condensed problem, its
    contact Newton steps + the corrections on F(g) that followed; '=' when it ends on the same active set and s
    to 1e-10 (then the corrections are the same)."""
    ch = hist.contact_newton
    if ch is None:
        return "—"
    cond = step.interface_problem(NEWTON).condensed
    s_load = cond.load_terms()[0]
    if DUMP is not None:  # --dump: the condensed contact problem, to study the contact Newton offline
        DUMP.mkdir(parents=True, exist_ok=True)
        name = f"{type(step).__name__}_{len(s_load)}_{abs(hash(s_load.tobytes())) % 10**6}.npz"
        np.savez(
            DUMP / name,
            s_load=s_load,
            M=cond.M,
            D=cond.D,
            points=step.interface_problem(NEWTON).omega2.contact_points(),
        )
    kind = _main_kind()
    s_d, _, _ = contact_newton(
        s_load,
        cond.M,
        cond.D,
        max_steps=NEWTON.max_steps,
        chains=None if kind == "plain" else cond.chains,
        window=NEWTON.front_window,
    )
    try:
        if kind == "plain":
            s_o, _, h_o = contact_newton(
                s_load,
                cond.M,
                cond.D,
                max_steps=NEWTON.max_steps,
                chains=cond.chains,
                window=InterfaceNewtonOptions().front_window,
            )
        else:
            s_o, _, h_o = contact_newton(s_load, cond.M, cond.D, max_steps=NEWTON.max_steps)
    except FenicsContactError as err:
        return f"error: {type(err).__name__}"
    same = np.array_equal(s_o > 0, s_d > 0) and np.abs(s_o - s_d).max() <= 1e-10 * np.abs(s_d).max()
    return f"{h_o.steps + hist.newton_steps - ch.steps}{'=' if same else ' (other solution)'}"


def part_steps(
    lines, h_primal, h_mixed, factors, big_default_only, methods, h_ms_max, models=MODELS, monolithic=True
) -> None:
    lines += [
        "## Newton steps to a transmission residual of 1e-6 (H = 1/16)",
        "",
        f"Cell: Newton steps (contact Newton + corrections) with the {_main_kind()} contact Newton "
        f"(InterfaceNewtonOptions(front_window={NEWTON.front_window})), "
        "{the semismooth iterations of its local front problems, each a dense solve of at most the largest window "
        "(/ that size)}, "
        f"[the same with the {'default local' if _main_kind() == 'plain' else 'plain'} contact Newton on "
        "the same condensed problem; '=' marks that it ends on the same active set and s to 1e-10], and the final "
        "transmission residual; "
        "α = c·E·h^-1/2 (Algorithm 1), c·Emin·h^-1/2 (Algorithm 3), β = c·√h (Algorithms 2, 4); '—' not run.",
        "",
        "| algorithm | model | 1/h | " + " | ".join(f"c = {c:g}" for c in factors) + " | monolithic Newton |",
        "|---|---|---|" + "---|" * len(factors) + "---|",
    ]
    worst = 0
    for method in methods:
        sizes = h_primal if method in (1, 3) else h_mixed
        if method in (3, 4):  # the multiscale offline phase grows fast with 1/h (877 s of bases at 1/256)
            sizes = [n for n in sizes if n <= h_ms_max]
        for label, number, E_high in models:
            for n in sizes:
                cm = unit_square(n, 16)
                cells = []
                for c in factors:
                    if method in (3, 4) and n == max(sizes) and big_default_only and c != 1.0:
                        cells.append("—")
                        continue
                    try:
                        step = build_step(method, cm, number, E_high, c)
                        hist = iterate(step, IterationOptions(accel="newton", newton=NEWTON))
                        worst = max(worst, hist.newton_steps)
                        mark = "" if hist.converged else " (not conv.)"
                        other = other_steps(step, hist)
                        ch = hist.contact_newton
                        local = (
                            ""
                            if ch is None or not any(w for w, _, _ in ch.local)
                            else f" {{{ch.local_iterations}/{max(m for _, _, m in ch.local)}}}"
                        )
                        cells.append(f"{hist.newton_steps}{local} [{other}] ({hist.transmission_residual:.0e}){mark}")
                        del step
                    except FenicsContactError as err:
                        cells.append(f"error: {type(err).__name__}")
                        logging.warning("Algorithm %d, model %s, h = 1/%d, c = %g: %s", method, label, n, c, err)
                mono = monolithic_steps(method, cm, number, E_high) if monolithic else "not run"
                row = f"| {method} | {label} | {n} | " + " | ".join(cells) + f" | {mono} |"
                print(row, flush=True)
                lines.append(row)
    lines += [
        "",
        f"Largest Newton step count: {worst}. 'monolithic Newton': steps of the monolithic semismooth "
        "Newton on the same mesh (Algorithms 1, 2: the same discrete problem, cold start).",
        "",
    ]


def part_updates(lines, n: int, cap: int, methods) -> None:
    lines += [
        f"## Updates compared: h = 1/{n}, H = 1/16, default α, β, tolerance 1e-6 on the transmission residual",
        "",
        "Cell: converged?, applications of T (Newton: + Newton steps), online s (Newton: + offline interface "
        f"response s), final transmission residual; cap {cap} iterations.",
        "",
        "| algorithm | model | none (paper) | anderson | newton |",
        "|---|---|---|---|---|",
    ]
    cm = unit_square(n, 16)
    for method in methods:
        for label, number, E_high in MODELS:
            step = build_step(method, cm, number, E_high)
            cells = []
            for accel in ("none", "anderson", "newton"):
                try:
                    step.reset()  # a cold start each time: the step keeps only its offline data
                    hist = iterate(
                        step,
                        IterationOptions(accel=accel, max_iterations=cap),
                        initial=np.zeros_like(step.initial_data()),
                    )
                    extra = f" + {hist.newton_steps} Newton" if accel == "newton" else ""
                    off = f" + {hist.time_offline_s:.2f} offline" if accel == "newton" else ""
                    cells.append(
                        f"{'yes' if hist.converged else '**no**'}, {hist.iterations}{extra}, "
                        f"{hist.time_s:.2f}{off} s, {hist.transmission_residual:.0e}"
                    )
                except FenicsContactError as err:
                    cells.append(f"**{type(err).__name__}**")
                    logging.warning("Algorithm %d, model %s, %s: %s", method, label, accel, err)
            row = f"| {method} | {label} | " + " | ".join(cells) + " |"
            print(row, flush=True)
            lines.append(row)
            del step
    lines.append("")


def part_speed(lines, n: int, number: int) -> None:
    cm = unit_square(n, 16)
    model = get_model(number)
    fields = material_fields(cm.mesh, model)
    delta = default_penalty(cm.h, _strip_modulus(cm, fields.E))
    mono = PrimalSubproblem(cm.mesh, cm.facet_tags, fields, delta=delta, alpha=None, prefix="fc_bench_mono_")
    t0, c0 = time.perf_counter(), time.process_time()
    mh = mono.solve()
    t_mono, c_mono = time.perf_counter() - t0, time.process_time() - c0
    lines += [
        f"## Online time / monolithic: primal, model {number}, h = 1/{n}, H = 1/16",
        "",
        f"Monolithic semismooth Newton: {mono.num_dofs} DOFs, {mh.steps} steps, {t_mono:.2f} s wall, {c_mono:.2f} s "
        "CPU (Newton only). CPU = this process's CPU time around the solve (less skewed by other jobs than the "
        "wall time; it includes the error-free iteration only).",
        "",
        "| algorithm | update | converged | applications of T (Newton steps) | online s (wall) | online / monolithic "
        "(wall) | online CPU s | online / monolithic (CPU) | offline s (of which interface response) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for method in (1, 3):
        t0 = time.perf_counter()
        step = build_step(method, cm, number, 1e3)
        build = time.perf_counter() - t0
        for accel in ("newton", "anderson"):
            step.reset()
            if accel == "newton":  # the offline interface response, outside the CPU clock of the online phase
                t_off = time.perf_counter()
                problem = step.interface_problem(InterfaceNewtonOptions())
                problem.condensed = problem.condensed or CondensedInterface(problem)
                pre = time.perf_counter() - t_off
            else:
                pre = 0.0
            c0 = time.process_time()
            hist = iterate(step, IterationOptions(accel=accel), initial=np.zeros_like(step.initial_data()))
            cpu = time.process_time() - c0
            row = (
                f"| {method} | {accel} | {hist.converged} | {hist.iterations} ({hist.newton_steps}) | "
                f"{hist.time_s:.3f} | **{hist.time_s / t_mono:.3f}** | {cpu:.3f} | **{cpu / c_mono:.3f}** | "
                f"{build + pre + hist.time_offline_s:.1f} ({pre + hist.time_offline_s:.2f}) |"
            )
            print(row, flush=True)
            lines.append(row)
        del step
    lines.append("")


# ---------------------------------------------------------------------------------------------
# fronts: why the contact Newton needs more steps at contrast 1e6, and what does not help
# ---------------------------------------------------------------------------------------------
def _galerkin_coarse(s_load, M, D, y):
    """The condensed problem on every other Γ_C node (gaps interpolated linearly, Galerkin on M⁻¹): (s_L, M, D, y, P)."""
    n = s_load.size
    keep = np.unique(np.r_[np.arange(0, n, 2), n - 1])
    P = np.zeros((n, keep.size))
    P[keep, np.arange(keep.size)] = 1.0
    for i in np.setdiff1d(np.arange(n), keep):
        j = np.searchsorted(keep, i)
        t = (y[i] - y[keep[j - 1]]) / (y[keep[j]] - y[keep[j - 1]])
        P[i, j - 1], P[i, j] = 1.0 - t, t
    Minv = np.linalg.inv(M)
    Mc = np.linalg.inv(P.T @ Minv @ P)
    return Mc @ (P.T @ Minv @ s_load), Mc, P.T @ D, y[keep], P


def _nested(s_load, M, D, y, smallest=16):
    """Nested iteration over Γ_C: solve the Galerkin-coarsened problem, start from its prolonged active set."""
    if s_load.size <= smallest:
        s, _, hist = contact_newton(s_load, M, D, max_steps=200)
        return [hist.steps], s
    sc_load, Mc, Dc, yc, P = _galerkin_coarse(s_load, M, D, y)
    counts, sc = _nested(sc_load, Mc, Dc, yc, smallest)
    s, _, hist = contact_newton(s_load, M, D, max_steps=200, active=P @ sc > 0.0)
    return counts + [hist.steps], s


def _continuation(s_load, M, D, factor=1e3, start=1e-9):
    """Path in the penalty: D·start, ·factor, ... up to D, each solve started from the last active set."""
    counts, scale, active = [], start, s_load > 0.0
    while True:
        s, _, hist = contact_newton(s_load, M, D * scale, max_steps=200, active=active)
        counts.append(hist.steps)
        active = s > 0.0
        if scale >= 1.0:
            return counts, s
        scale = min(scale * factor, 1.0)


def part_fronts(lines, sizes, E_high: float) -> None:
    """Contact Newton of Algorithm 1 (= the monolithic semismooth Newton from its 2nd step): active-set changes
    per step on model 3, and the step counts of other starts / globalizations on the same condensed problem."""
    lines += [
        f"## Contact Newton on model 3, E_high {E_high:g}: active-set fronts and alternatives (Algorithm 1, c = 1)",
        "",
        "Same condensed problem s = s_L − M D s⁺ on Γ_C for every column (the fixed point does not change: "
        "'same' = all variants end on the plain Newton's active set and its s to 1e-10). local (the default, "
        "InterfaceNewtonOptions(front_window=8)): the next set takes, around every front of the semismooth step's set, "
        "the solution of the contact equations on the 8 Γ_C unknowns on either side of it with the forces elsewhere "
        "held (`hybrid.fronts.LocalFronts`; in braces the semismooth iterations of those local problems / the largest "
        "window). Plain (front_window=0): start from the "
        "contact-free penetration pattern {s_L > 0}, full steps, exact line search once a set recurs. "
        "all active: start from 𝒜 = Γ_C. nested: Galerkin-coarsened Γ_C problems (every other node, down to "
        "≤ 16 nodes), each level started from the prolonged coarser solution (steps per level, coarse → fine). "
        "penalty path: D·1e-9, ·1e3 … D, each started from the last set. line search: exact line search on "
        "the energy at every step.",
        "",
        "| 1/h | Γ_C rows | local {iterations/window} | plain | all active | nested (per level) | penalty path "
        "(per level) | line search | monolithic Newton | same |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    traces = []
    for n in sizes:
        cm = unit_square(n, 16)
        step = build_step(1, cm, 3, E_high)
        problem = step.interface_problem(InterfaceNewtonOptions())
        cond = CondensedInterface(problem)
        s_load = cond.load_terms()[0]
        M, D = cond.M, problem.omega2.D
        om2 = problem.omega2
        points = om2.contact_points()
        y = points[:, 1]
        order = np.argsort(y)
        s_load, M, D, y = s_load[order], M[np.ix_(order, order)], D[order], y[order]
        s0, _, h0 = contact_newton(s_load, M, D, max_steps=200)
        s_w, _, h_w = contact_newton(
            s_load,
            M,
            D,
            max_steps=200,
            chains=contact_chains(points[order]),
            window=InterfaceNewtonOptions().front_window,
        )
        _, _, h_all = contact_newton(s_load, M, D, max_steps=200, active=np.ones(s_load.size, dtype=bool))
        nest, s_nest = _nested(s_load, M, D, y)
        path, s_path = _continuation(s_load, M, D)
        s_ls, _, h_ls = contact_newton(s_load, M, D, max_steps=200, line_search=True)
        scale = np.abs(s0).max()
        same = all(
            np.array_equal(s > 0, s0 > 0) and np.abs(s - s0).max() <= 1e-10 * scale for s in (s_nest, s_path, s_ls, s_w)
        )
        row = (
            f"| {n} | {s_load.size} | **{h_w.steps}** {{{h_w.local_iterations}/{max(m for _, _, m in h_w.local)}}} | "
            f"{h0.steps} | {h_all.steps} | {sum(nest)} ({', '.join(map(str, nest))}) | "
            f"{sum(path)} ({', '.join(map(str, path))}) | {h_ls.steps} | {monolithic_steps(1, cm, 3, E_high)} | "
            f"{same} |"
        )
        print(row, flush=True)
        lines.append(row)
        at = lambda idx: ", ".join(f"{32 * y[i]:g}" for i in idx) or "—"  # noqa: E731
        traces.append(
            (
                n,
                "Plain",
                [(k + 1, h0.active_sizes[k], at(a), at(r), "") for k, (a, r) in enumerate(zip(h0.added, h0.removed))],
            )
        )
        traces.append(
            (
                n,
                "Local front resolution (the default, front_window=8)",
                [
                    (k + 1, h_w.active_sizes[k], at(a), at(r), at(x))
                    for k, (a, r, x) in enumerate(zip(h_w.added, h_w.removed, h_w.resolved))
                ],
            )
        )
        del step
    for n, label, rows in traces:
        lines += [
            "",
            f"{label} contact Newton at h = 1/{n}: Γ_C nodes (y in units of 1/32; the stiff channels touch "
            "Γ_C on y ∈ [5, 6], [13, 14], [21, 22]) that each step adds to / removes from the active set it "
            "solves next (of them, set by the local front resolution):",
            "",
            "| step | active nodes after it | added | removed | of them set locally |",
            "|---|---|---|---|---|",
        ]
        lines += [f"| {k} | {size} | {a} | {r} | {x or '—'} |" for k, size, a, r, x in rows]
    lines.append("")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parts", default="steps,updates,speed")
    parser.add_argument("--methods", default="1,3,2,4", help="algorithms of the steps and updates parts")
    parser.add_argument("--h-primal", default="32,64,128,256")
    parser.add_argument("--h-mixed", default="32,64,128")
    parser.add_argument("--factors", default="0.01,1,1e4")
    parser.add_argument(
        "--big-default-only",
        action="store_true",
        default=True,
        help="Algorithms 3, 4 at their largest h only with the default α, β",
    )
    parser.add_argument("--h-ms-max", type=int, default=128, help="largest 1/h for Algorithms 3, 4 in the steps part")
    parser.add_argument("--updates-h", type=int, default=64)
    parser.add_argument("--cap", type=int, default=2000, help="iteration cap of the fixed-point updates")
    parser.add_argument("--speed-h", type=int, default=256)
    parser.add_argument("--speed-model", type=int, default=2)
    parser.add_argument("--models", default="1,2,3,3e6", help="models of the steps part: 1, 2, 3 (E_high 1e3), 3e6")
    parser.add_argument(
        "--chunk",
        type=int,
        default=InterfaceNewtonOptions().chunk,
        help="steps part: right-hand sides per multi-RHS back-solve of the interface responses "
        "(smaller: less memory for the mixed h = 1/128)",
    )
    parser.add_argument(
        "--no-monolithic",
        action="store_true",
        help="steps part: skip the monolithic Newton column (the mixed one needs ~10 GB at h = 1/128)",
    )
    parser.add_argument(
        "--front-window",
        type=int,
        default=InterfaceNewtonOptions().front_window,
        help="steps part: the local front resolution's window (0: the plain contact Newton as the "
        "main count, the default window in brackets)",
    )
    parser.add_argument(
        "--dump",
        type=Path,
        default=None,
        help="steps part: save each condensed contact problem (s_L, M, D, coordinates) as .npz here",
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/interface_newton.md"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    lines = [
        "# Interface Newton",
        "",
        f"Machine: {machine_description()}.",
        "",
        "Command: `OMP_NUM_THREADS=1 python benchmarks/interface_newton.py "
        f"--parts {args.parts} --methods {args.methods} --h-primal {args.h_primal} --h-mixed {args.h_mixed} "
        f"--factors {args.factors} --h-ms-max {args.h_ms_max} --updates-h {args.updates_h} --cap {args.cap} "
        f"--speed-h {args.speed_h} --speed-model {args.speed_model} --models {args.models}"
        f"{' --no-monolithic' if args.no_monolithic else ''} --front-window {args.front_window} --chunk {args.chunk} "
        f"--out {args.out}`",
        "",
    ]
    chosen = {"1": MODELS[0], "2": MODELS[1], "3": MODELS[2], "3e6": MODELS[3]}
    try:
        models = [chosen[m] for m in args.models.split(",")]
    except KeyError as err:
        raise SystemExit(f"unknown model {err}; choose from {', '.join(chosen)}") from None
    global NEWTON, DUMP
    NEWTON = InterfaceNewtonOptions(chunk=args.chunk, front_window=args.front_window)
    DUMP = args.dump
    start = time.perf_counter()
    ints = lambda text: [int(x) for x in text.split(",")]  # noqa: E731
    for part in args.parts.split(","):
        if part == "steps":
            part_steps(
                lines,
                ints(args.h_primal),
                ints(args.h_mixed),
                [float(x) for x in args.factors.split(",")],
                args.big_default_only,
                ints(args.methods),
                args.h_ms_max,
                models,
                monolithic=not args.no_monolithic,
            )
        elif part == "updates":
            part_updates(lines, args.updates_h, args.cap, ints(args.methods))
        elif part == "fronts":
            part_fronts(lines, ints(args.h_primal), 1e6)
        elif part == "speed":
            part_speed(lines, args.speed_h, args.speed_model)
        else:
            raise SystemExit(f"unknown part {part!r}")
    lines.append(f"Total wall time {time.perf_counter() - start:.0f} s.")
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
