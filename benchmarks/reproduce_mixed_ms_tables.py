"""Reproduce the paper's mixed CEM-GMsFEM tables (Algorithm 4): Table 5.3, 5.5–5.7 analogues and Table 5.8.

    OMP_NUM_THREADS=1 python benchmarks/reproduce_mixed_ms_tables.py --tables 5.3 --out results/mixed_ms.md

Table 5.3: model 2, h = 1/64, H = 1/16, β = √h, l = 3, m = 1..5: iterations, e_σ (A-norm, and
L²), e_u against the fine monolithic mixed solution.  Tables 5.5–5.7 (nearly incompressible): the
paper's §5.4 cases on test model 1 (``problem.models.paper_phase_model``): (E₁/E₂, ν₁, ν₂) = (1e−4, 0.35,
0.499), (1e4, 0.499, 0.35), (1, 0.499, 0.499), E₁, ν₁ in the channels, E₂ = 1, ν₂ elsewhere and in Ω₂.
Table 5.8: online times of the monolithic semismooth Newton solve, Algorithm 2 and Algorithm 4
with H = 1/32, 1/16, 1/8 (each H has its own strip Ω₂ = one coarse cell, hence its own reference).
The iteration is the paper's plain update unless ``--accel anderson`` or ``newton`` (Table 5.8 takes
a comma list, the offline data reused between the updates).  Tables 5.3, 5.5–5.7 stop at a transmission
residual < ``--tol`` (1e-6; the row also gives where the relative change first fell below it, the
rule of the paper), give e_σ against the monolithic and against the split fine solution (Algorithm 2's
fixed point), offline wall and CPU seconds and the peak RSS; ``--load omega1`` moves the model's load
bands into Ω₁ (x ∈ [1/2, 15/16], ``models.LOADS_IN_OMEGA1``: loads in Ω₁ as in the paper) and
``--without-source`` adds the paper's Ω₁ step (no source correctors) at the largest m:

    OMP_NUM_THREADS=1 python benchmarks/reproduce_mixed_ms_tables.py --tables 5.3 --load omega1 --without-source

Table 'source' (``--tables source``): loads inside Ω₁ (models 1 and 2 with their bands moved to
x ∈ [1/2, 15/16], model 3 with E_high = 1e3 and 1e6), h = 1/n, H = ``--n-coarse``, m = ``--layers``:
e_σ with the source correctors (default) per layer, their ratio, and without them at the largest m.

    OMP_NUM_THREADS=1 python benchmarks/reproduce_mixed_ms_tables.py --tables source --layers 1,2,3,4
"""

import argparse
import logging
import sys
import time
from pathlib import Path

import numpy as np

import fenics_contact  # noqa: F401  (must precede dolfinx / petsc4py)
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid
from fenics_contact.io import machine_description, write_report
from fenics_contact.multiscale.mixed import solve_mixed_ms_hybrid
from fenics_contact.multiscale.mixed_cem.options import DEFAULT_MIN_GAP, MixedCEMOptions
from fenics_contact.problem import geometry, models

#: the paper's Tables 5.3, 5.5–5.7 (h = 1/64, H = 1/16, β = √h, 3 bases): m -> (iterations, e_σ, e_u)
PAPER = {
    "5.3": {
        1: (96, 2.16e-1, 1.81e-1),
        2: (71, 1.23e-1, 6.37e-2),
        3: (58, 5.14e-2, 3.09e-2),
        4: (46, 7.26e-3, 6.29e-3),
        5: (43, 8.94e-4, 6.86e-4),
    },
    "5.5": {
        1: (68, 2.39e-1, 1.26e-1),
        2: (53, 1.38e-1, 8.12e-2),
        3: (44, 3.79e-2, 2.31e-2),
        4: (37, 4.35e-3, 3.15e-3),
        5: (32, 8.21e-4, 5.96e-4),
    },
    "5.6": {
        1: (79, 5.21e-1, 3.35e-1),
        2: (62, 1.96e-1, 2.81e-2),
        3: (54, 3.81e-2, 1.58e-2),
        4: (51, 4.91e-3, 3.79e-3),
        5: (46, 8.84e-4, 6.02e-4),
    },
    "5.7": {
        1: (63, 1.54e-1, 9.36e-2),
        2: (50, 8.79e-2, 5.85e-2),
        3: (44, 4.12e-2, 1.06e-2),
        4: (36, 5.31e-3, 3.22e-3),
        5: (24, 7.28e-4, 6.59e-4),
    },
}
PAPER_58 = {"monolithic": 15.29, "alg2": 6.48, 32: 4.94, 16: 2.13, 8: 1.69}
#: the paper's §5.4 cases on test model 1: (E₁/E₂, ν₁ in the pattern, ν₂ elsewhere and in Ω₂)
INCOMPRESSIBLE = {"5.5": (1.0e-4, 0.35, 0.499), "5.6": (1.0e4, 0.499, 0.35), "5.7": (1.0, 0.499, 0.499)}


def _peak_rss_gb() -> float:
    """Peak resident memory of this process so far, GB = 10⁹ bytes."""
    from fenics_contact.io import peak_rss_bytes

    return peak_rss_bytes() / 1e9


def table_53(
    n: int,
    layers: list[int],
    accel: str,
    lines: list[str],
    title: str = "5.3",
    nu_high: float = 0.499,
    min_gap: float | None = DEFAULT_MIN_GAP,
    load: str = "builtin",
    tol: float = 1.0e-6,
    without_source: bool = False,
) -> None:
    """One Table 5.3 / 5.5–5.7 analogue, m = ``layers``.

    ``load="omega1"`` moves the model's load bands into Ω₁ (``models.LOADS_IN_OMEGA1``: x ∈ [1/2, 15/16],
    pushing and pulling), loads in Ω₁ as in the paper; ``without_source`` adds, at the largest m, the
    paper's Ω₁ step (no source correctors).  Per row: the iterations of the stopping rule (transmission
    residual < ``tol``) and, in brackets, where the relative change of the iterates first fell below
    ``tol`` (the rule of the paper and of the runs before the certificate); offline wall and CPU
    seconds (process time of the Ω₁ offline parts); the process's peak RSS so far.
    """
    cm = geometry.unit_square(n, 16)
    if title == "5.3":
        number = 2
        model = models.get_model(2)
        desc = "model 2 (E 1000/1, ν = 0.35)"
    else:
        number = 1
        ratio, nu1, nu2 = INCOMPRESSIBLE[title]
        nu1, nu2 = (nu_high if nu == 0.499 else nu for nu in (nu1, nu2))
        model = models.paper_phase_model(1, E_ratio=ratio, nu_pattern=nu1, nu_rest=nu2)
        desc = f"model 1, E₁/E₂ = {ratio:g}, ν₁ = {nu1:g} (channels), ν₂ = {nu2:g} (rest, Ω₂)"
    if load == "omega1":
        bands = models.LOADS_IN_OMEGA1[number]
        model = model.with_(load=models.band_load(bands))
        desc += (
            ", load in Ω₁ (bands x ∈ [1/2, 15/16]: "
            + ", ".join(f"f₁ = {b[4]:+g} on y ∈ [{b[2]:g}, {b[3]:g}]" for b in bands)
            + ")"
        )
    elif load != "builtin":
        raise SystemExit(f"unknown load {load!r} (builtin or omega1)")
    ref = solve_mixed_monolithic(model.on(cm))
    ref.free()
    split = solve_mixed_monolithic(model.on(cm), split_interface=True, epsilon=ref.epsilon)
    split.free()
    floor = _reference_distance(cm, model, ref, split)
    paper_cols = load == "builtin" and nu_high == 0.499
    lines += [
        f"### Table {title} analogue: {desc}, h = 1/{n}, H = 1/16, β = √h, "
        + (f"l ≥ 3 per cell, more where Λ < {min_gap:g} (min_gap)" if min_gap else "l = 3 (fixed)")
        + f", update '{accel}', tol {tol:g}",
        "",
        "its: to a transmission residual < tol (in brackets: first iteration with a relative change < tol). "
        "ratio: e_σ(m−1)/e_σ(m). e_σ (split): against the split fine solution (Algorithm 2's fixed point, what the "
        f"multiscale method approximates); the two fine solutions differ by {floor:.2e} (A-norm, relative: the floor "
        "of e_σ against the monolithic one). offline: wall s [CPU s of the Ω₁ offline parts]. RSS: peak of the "
        "process so far.",
        "",
        "| m | its | e_σ | ratio | e_σ (split) | ratio (split) | e_σ (L²) | e_u | e_u (π on Ω₁) | e_u (post-proc.) "
        "| converged | l per cell | Λ "
        "| dim X_ms + U_aux | offline s [CPU] | CPU s: assembly, Stage I, Stage II, coarse | online s | peak RSS GB "
        "| paper its | paper e_σ | paper e_u |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    prev = prev_split = None
    for m in layers:
        res = solve_mixed_ms_hybrid(
            model.on(cm),
            cem=MixedCEMOptions(layers=m, nbasis=3, min_gap=min_gap),
            reference=ref,
            options=IterationOptions(accel=accel, max_iterations=1000, tol=tol),
        )
        om = res.step.omega1
        lo, hi = om.nbasis_range
        below = np.flatnonzero(res.history.rel_changes < tol)
        its_rel = f"{below[0] + 1}" if below.size else "—"
        p = PAPER[title].get(m) if paper_cols else None
        paper = f" {p[0]} | {p[1]:.2e} | {p[2]:.2e} |" if p else " — | — | — |"
        ratio = f"{prev / res.e_sigma:.1f}" if prev else "—"
        res.step.set_reference(split)
        e_split = res.step.errors()[0]
        ratio_s = f"{prev_split / e_split:.1f}" if prev_split else "—"
        row = (
            f"| {m} | {res.iterations} ({its_rel}) | {res.e_sigma:.2e} | {ratio} | {e_split:.2e} | {ratio_s} | "
            f"{res.e_sigma_l2:.2e} | "
            f"{res.e_u:.2e} | {res.e_u_projected:.2e} | {res.e_u_post:.2e} | {res.converged} | {lo}–{hi} | "
            f"{om.spectral_gap:.2g} | {res.dofs['omega1_ms']} | "
            f"{res.time_offline_s:.1f} [{sum(om.cpu_times.values()):.1f}] | "
            + ", ".join(f"{om.cpu_times.get(k, 0.0):.1f}" for k in ("assembly", "eigen", "basis", "coarse"))
            + f" | {res.time_online_s:.2f} | {_peak_rss_gb():.2f} |"
            + paper
        )
        lines.append(row)
        print(row, flush=True)
        prev, prev_split = res.e_sigma, e_split
        del res, om  # the offline data of one m (GBs with many modes) is freed before the next is built
    if without_source:
        m = max(layers)
        res = solve_mixed_ms_hybrid(
            model.on(cm),
            cem=MixedCEMOptions(layers=m, nbasis=3, min_gap=min_gap, source_correction=False),
            reference=ref,
            options=IterationOptions(accel=accel, max_iterations=1000, tol=tol),
        )
        res.step.set_reference(split)
        e_split = res.step.errors()[0]
        row = (
            f"| {m}, without source correctors (the paper's Ω₁ step) | {res.iterations} | {res.e_sigma:.2e} | — | "
            f"{e_split:.2e} | — | {res.e_sigma_l2:.2e} | {res.e_u:.2e} | {res.e_u_projected:.2e} | "
            f"{res.e_u_post:.2e} | "
            f"{res.converged} | | | {res.dofs['omega1_ms']} | {res.time_offline_s:.1f} | | "
            f"{res.time_online_s:.2f} | {_peak_rss_gb():.2f} | — | — | — |"
        )
        lines.append(row)
        print(row, flush=True)
        del res
    lines.append("")


def table_58(n: int, layers: int, accels: list[str], lines: list[str], coarse: tuple[int, ...] = (32, 16, 8)) -> None:
    lines += [
        f"### Table 5.8 analogue: online times, model 2, h = 1/{n}, β = √h, l ≥ 3 (default Stage I rule), m = {layers}, "
        f"updates {', '.join(accels)}",
        "",
        "Online: to a transmission residual of 1e-6, error evaluation excluded; reference: the monolithic "
        "semismooth Newton alone.  Newton: 'its' = applications of T (Newton steps); its offline column "
        "includes the interface response (in brackets).  Each H builds one step per algorithm and reuses it "
        "for every update (cold states, ``step.reset``); offline = its build + the interface response.",
        "",
        "| H | method | update | DOFs | its | online s | ratio to monolithic | offline s | e_σ | paper online s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    model = models.get_model(2)
    for nc in coarse:
        cm = geometry.unit_square(n, nc)
        ref = solve_mixed_monolithic(model.on(cm))
        ref.free()
        t_ref = ref.time_newton_s
        rows = [
            f"| 1/{nc} | monolithic (semismooth Newton) | — | {ref.dofs['total']} | {ref.newton.steps} | "
            f"{t_ref:.2f} | 1 | {ref.time_s - t_ref:.1f} | 0 | {PAPER_58['monolithic']} |"
        ]
        step2 = step4 = None
        build = {}  # offline time of each step's first solve (later updates reuse the step)
        for accel in accels:
            for step in (step2, step4):
                if step is not None:
                    step.reset()  # cold subdomain states and factorizations; the offline data are kept
            opts = IterationOptions(accel=accel, max_iterations=1000)
            a2 = solve_mixed_hybrid(model.on(cm), reference=ref, options=opts, step=step2)
            a4 = solve_mixed_ms_hybrid(
                model.on(cm), cem=MixedCEMOptions(layers=layers, nbasis=3), reference=ref, options=opts, step=step4
            )
            step2, step4 = a2.step, a4.step  # the offline data are reused by the next update
            for name, res, dofs, paper in (
                ("Algorithm 2", a2, a2.dofs["omega1"] + a2.dofs["omega2"], PAPER_58["alg2"]),
                ("Algorithm 4", a4, a4.dofs["omega1_ms"] + a4.dofs["omega2"], PAPER_58[nc]),
            ):
                its = f"{res.iterations} ({res.history.newton_steps})" if accel == "newton" else f"{res.iterations}"
                build.setdefault(name, res.time_offline_s - res.time_interface_offline_s)
                off = f"{build[name] + res.time_interface_offline_s:.1f}"
                off += f" ({res.time_interface_offline_s:.2f})" if accel == "newton" else ""
                rows.append(
                    f"| 1/{nc} | {name} | {accel} | {dofs} | {its} | {res.time_online_s:.3f} | "
                    f"**{res.time_online_s / t_ref:.3f}** | {off} | {res.e_sigma:.1e} | {paper} |"
                )
        for r in rows:
            print(r, flush=True)
        lines += rows
    lines.append("")


#: the loads-in-Ω₁ cases: name -> (model number, E_high, bands or None for the model's own loads)
SOURCE_CASES = {
    "1L": (1, 1.0e3, models.LOADS_IN_OMEGA1[1]),
    "2L": (2, 1.0e3, models.LOADS_IN_OMEGA1[2]),
    "3": (3, 1.0e3, None),
    "3 (E 1e6)": (3, 1.0e6, None),
}


def table_source(n: int, layers: list[int], n_coarse: list[int], cases: list[str], lines: list[str]) -> None:
    """Loads inside Ω₁: e_σ of Algorithm 4 with the source correctors (default) and without (the paper's).

    Iterated to tol 1e-9 (Anderson) so that e_σ is the multiscale error, not the stopping rule's; e_σ
    against the monolithic AW solution and against the split one (σ_tt doubled at the γ
    vertices, the exact fixed point of the fine splitting, Algorithm 2): the latter is what the
    multiscale method approximates, the former adds Algorithm 2's O(h²) γ term.
    """
    opts = IterationOptions(tol=1e-9, accel="anderson", max_iterations=2000)
    lines += [
        f"### Loads inside Ω₁, h = 1/{n}, β = √h, l ≥ 3 (default Stage I rule), tol 1e-9 (Anderson)",
        "",
        "e_σ: A-norm error against the monolithic AW solution; e_σ (split): against the split fine solution "
        "(Algorithm 2's fixed point; the difference of the two references is given as 'floor'). ratio: e_σ(m−1)/e_σ(m).",
        "",
        "| model | H | m | its | e_σ | ratio | e_σ (split) | ratio (split) | e_σ without source correctors "
        "| e_u (post-proc.) | offline s | online s |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in cases:
        number, contrast, bands = SOURCE_CASES[name]
        model = models.get_model(number, E_high=contrast)
        if bands is not None:
            model = model.with_(load=models.band_load(bands))
        for nc in n_coarse:
            cm = geometry.unit_square(n, nc)
            ref = solve_mixed_monolithic(model.on(cm))
            ref.free()
            split = solve_mixed_monolithic(model.on(cm), split_interface=True, epsilon=ref.epsilon)
            split.free()
            floor = _reference_distance(cm, model, ref, split)
            prev = prev_split = None
            for m in layers:
                row = {}
                for sc in (True, False):
                    if not sc and m != max(layers):
                        continue
                    res = solve_mixed_ms_hybrid(
                        model.on(cm), cem=MixedCEMOptions(layers=m, source_correction=sc), reference=ref, options=opts
                    )
                    res.step.set_reference(split)
                    row[sc] = (res, res.step.errors()[0])
                res, e_split = row[True]
                without = f"{row[False][0].e_sigma:.2e}" if False in row else "—"
                ratio = f"{prev / res.e_sigma:.1f}" if prev else "—"
                ratio_s = f"{prev_split / e_split:.1f}" if prev_split else "—"
                out = (
                    f"| {name} | 1/{nc} | {m} | {res.iterations} | {res.e_sigma:.2e} | {ratio} | {e_split:.2e} | "
                    f"{ratio_s} | {without} | {res.e_u_post:.2e} | {res.time_offline_s:.1f} | "
                    f"{res.time_online_s:.2f} |"
                )
                lines.append(out)
                print(out, flush=True)
                prev, prev_split = res.e_sigma, e_split
                del res, row
            lines.append(f"| {name} | 1/{nc} | floor | | {floor:.2e} | | | | | | | |")
    lines.append("")


def _reference_distance(cm, model, ref, split) -> float:
    """‖σ_h − σ̃_h‖_A / ‖σ_h‖_A of the monolithic and the split fine solutions (the 'floor' of e_σ)."""
    step = MixedHybridStep(model.on(cm), beta="sqrt-h")
    step.set_reference(split)
    c_split = [c for c, _ in step.reference]
    step.set_reference(ref)
    num = sum(s.stress_norm2(c - cs) for s, (c, _), cs in zip(step.sub, step.reference, c_split))
    return float(np.sqrt(num / step._ref_norm2[0]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tables", default="5.3", help="comma list of 5.3, 5.5, 5.6, 5.7, 5.8, source")
    parser.add_argument("--n", type=int, default=64, help="fine cells per side (h = 1/n)")
    parser.add_argument("--layers", default="1,2,3,4,5", help="oversampling layers for Tables 5.3, 5.5-5.7")
    parser.add_argument("--layers-58", type=int, default=3, help="oversampling layers for Table 5.8")
    parser.add_argument("--coarse-58", default="32,16,8", help="Table 5.8: 1/H values (comma list)")
    parser.add_argument(
        "--accel",
        default="none",
        help="update: none, anderson or newton (Table 5.8: a comma list, e.g. none,anderson,newton)",
    )
    parser.add_argument(
        "--nu-high",
        type=float,
        default=0.499,
        help="the nearly incompressible ν of Tables 5.5-5.7 (the paper's is 0.499)",
    )
    parser.add_argument(
        "--min-gap",
        type=float,
        default=DEFAULT_MIN_GAP,
        help="Stage I: more modes where the first eigenvalue left out is below this (0: the paper's fixed l = 3)",
    )
    parser.add_argument(
        "--load",
        default="builtin",
        choices=("builtin", "omega1"),
        help="Tables 5.3, 5.5-5.7: the model's own load bands (in Ω₂) or the same bands moved into "
        "Ω₁ (x ∈ [1/2, 15/16], models.LOADS_IN_OMEGA1)",
    )
    parser.add_argument(
        "--tol",
        type=float,
        default=1.0e-6,
        help="Tables 5.3, 5.5-5.7: stopping rule, transmission residual < tol (the paper's 1e-6)",
    )
    parser.add_argument(
        "--without-source",
        action="store_true",
        help="Tables 5.3, 5.5-5.7: also the paper's Ω₁ step (no source correctors) at the largest m",
    )
    parser.add_argument("--n-coarse", default="16,8", help="table 'source': 1/H values")
    parser.add_argument(
        "--cases",
        default=";".join(SOURCE_CASES),
        help="table 'source': ';'-separated cases among " + ", ".join(SOURCE_CASES),
    )
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/mixed_ms_tables.md"))
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING)
    layers = [int(x) for x in args.layers.split(",")]
    lines = [
        "# Mixed CEM-GMsFEM (Algorithm 4): measured vs paper",
        "",
        f"Machine: {machine_description()}; MUMPS LU. Paper: MATLAB on a 24-core desktop.",
        "",
        "Command: `OMP_NUM_THREADS=1 python " + " ".join(sys.argv) + "`",
        "",
    ]
    start, cpu = time.perf_counter(), time.process_time()
    for t in args.tables.split(","):
        t = t.strip()
        if t == "5.3" or t in INCOMPRESSIBLE:
            table_53(
                args.n,
                layers,
                args.accel,
                lines,
                title=t,
                nu_high=args.nu_high,
                min_gap=args.min_gap or None,
                load=args.load,
                tol=args.tol,
                without_source=args.without_source,
            )
        elif t == "5.8":
            table_58(
                args.n, args.layers_58, args.accel.split(","), lines, tuple(int(c) for c in args.coarse_58.split(","))
            )
        elif t == "source":
            table_source(
                args.n,
                layers,
                [int(c) for c in args.n_coarse.split(",")],
                [c.strip() for c in args.cases.split(";")],
                lines,
            )
        else:
            raise SystemExit(f"unknown table {t!r}")
    lines.append(
        f"Total wall time {time.perf_counter() - start:.0f} s, CPU time {time.process_time() - cpu:.0f} s, "
        f"peak RSS {_peak_rss_gb():.2f} GB."
    )
    write_report(args.out, lines)


if __name__ == "__main__":
    main()
