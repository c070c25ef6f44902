"""Command line: ``fenics-contact run …`` (one simulation with fields, plots and a summary)."""

import argparse
import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from fenics_contact import __version__
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.hybrid.iteration import ACCELERATIONS, IterationOptions
from fenics_contact.errors import FenicsContactError, InputError
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import ContactMesh, read_mesh, unit_square
from fenics_contact.io import cell_function_of, cell_markers, stress_field, write_fields, write_summary, write_vtx
from fenics_contact.problem.models import get_model, pixel_field
from fenics_contact.plots import (
    plot_cell_field,
    plot_contact,
    plot_displacement,
    plot_history,
    plot_stress,
    render_deformed,
)
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, solve_primal_hybrid
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.tags import Subdomain

__all__ = ["main", "build_parser"]

log = logging.getLogger("fenics_contact")

METHODS = ("primal", "primal-ms", "mixed", "mixed-ms")


class _RankZero(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return MPI.COMM_WORLD.rank == 0


def _setup_logging(verbose: bool) -> None:
    handler = logging.StreamHandler(sys.stdout)
    handler.addFilter(_RankZero())
    handler.setFormatter(logging.Formatter("%(message)s"))
    root = logging.getLogger("fenics_contact")
    root.handlers[:] = [handler]
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    root.propagate = False


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="fenics-contact", description=__doc__)
    parser.add_argument("--version", action="version", version=f"fenics-contact {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="run one contact simulation and write fields, plots and a summary")
    run.add_argument("--model", type=int, choices=(1, 2, 3), default=1,
                     help="built-in test model: 1 channels, 2 inclusions, 3 heterogeneous strip (loads in Ω₁)")
    run.add_argument("--method", choices=METHODS, default="primal", help="discretization / algorithm")
    run.add_argument("--h", type=int, default=64, help="fine mesh size given as 1/h (e.g. 64)")
    run.add_argument("--H", type=int, default=16, help="coarse size / strip width given as 1/H (e.g. 16)")
    run.add_argument("--mesh", type=Path, help="a gmsh .msh file with the physical groups "
                     "Omega1, Omega2, Gamma_D, Gamma_C, gamma (replaces the built-in unit square)")
    run.add_argument("--alpha", default=DEFAULT_ALPHA, help="Robin coefficient: a number or a product of "
                     "numbers, h^p, sqrt-h and E (E_p: mean E at the γ node), e.g. 1, h^-1/2, 2E*h^-1/2")
    run.add_argument("--accel", choices=ACCELERATIONS, default="anderson",
                     help="update of the interface data: the paper's plain update, Anderson acceleration, or "
                     "the interface Newton method")
    run.add_argument("--tol", type=float, default=1e-6,
                     help="tolerance of the transmission residual (relative jump and traction imbalance on γ)")
    run.add_argument("--max-iterations", type=int, default=2000)
    run.add_argument("--delta", type=float, help="primal penalty δ (default 1e-3·h/E on Γ_C)")
    run.add_argument("--beta", default="sqrt-h", help="mixed: transmission coefficient β (1, sqrt-h or a number)")
    run.add_argument("--epsilon", type=float, help="mixed penalty ε (default 1e-3·h·E on Γ_C)")
    run.add_argument("--E-high", type=float, default=1e3, help="E in the high-modulus pattern")
    run.add_argument("--E-low", type=float, default=1.0, help="E elsewhere")
    run.add_argument("--nu", type=float, default=0.35, help="Poisson ratio")
    run.add_argument("--E-map", type=Path, help="Young's modulus as a pixel array over the unit square "
                     "(.npy, or text/.csv readable by numpy.loadtxt; row 0 = bottom); replaces the model's E map")
    run.add_argument("--layers", type=int, default=4, help="*-ms: oversampling layers m of the multiscale bases")
    run.add_argument("--nbasis", type=int, default=3, help="*-ms: local spectral modes l per coarse cell")
    run.add_argument("--min-gap", type=float,
                     help="mixed-ms: add Stage I modes on a coarse cell until the first one left out has "
                     "eigenvalue >= this (needed for nu -> 1/2; default 0.1; 0 keeps exactly --nbasis)")
    run.add_argument("--max-nbasis", type=int, help="mixed-ms: most Stage I modes per coarse cell (default 32)")
    run.add_argument("--cache-dir", type=Path, help="*-ms: directory for the offline data (reused when valid)")
    run.add_argument("--reference", action="store_true", help="also solve the monolithic problem and report e_u")
    run.add_argument("--out", type=Path, default=Path("results"), help="output directory")
    run.add_argument("--no-plots", action="store_true", help="skip the PNG figures")
    run.add_argument("-v", "--verbose", action="store_true")
    return parser


def _load_array(path: Path) -> np.ndarray:
    if not path.is_file():
        raise InputError(f"{path} does not exist")
    try:
        return np.load(path) if path.suffix == ".npy" else np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None)
    except ValueError as err:
        raise InputError(f"cannot read a pixel array from {path}: {err}") from None


def _mesh(args) -> ContactMesh:
    if args.mesh is not None:
        return read_mesh(args.mesh, H=1.0 / args.H)
    return unit_square(args.h, args.H)


def _contact_modulus(cm: ContactMesh, E) -> float:
    """Largest E in the contact strip Ω₂."""
    cells = cm.cell_tags.find(Subdomain.OMEGA2)
    local = float(np.max(E.x.array[cells])) if cells.size else 0.0
    return cm.comm.allreduce(local, op=MPI.MAX)


class _Outcome(NamedTuple):
    """What a method family hands back to ``run``: its result, summary entries and output writer."""

    result: object
    reference: object | None
    summary: dict
    write: Callable[[Path], None]


def _run_primal(args, cm: ContactMesh, model, fields, options: IterationOptions) -> _Outcome:
    """Algorithms 1 (primal) and 3 (primal-ms), with the monolithic primal reference."""
    delta = args.delta if args.delta is not None else default_penalty(cm.h, _contact_modulus(cm, fields.E))
    reference = solve_primal_monolithic(cm.mesh, cm.facet_tags, fields, delta=delta) if args.reference else None
    ref_u = reference.u if reference is not None else None
    if args.method == "primal":
        result = solve_primal_hybrid(cm, model, alpha=args.alpha, delta=delta, options=options,
                                     newton=NewtonOptions(), reference=ref_u)
    else:
        result = solve_primal_ms_hybrid(cm, model, alpha=args.alpha, delta=delta, options=options,
                                        layers=args.layers, nbasis=args.nbasis, reference=ref_u,
                                        cache_dir=args.cache_dir)
    summary = {
        "alpha": args.alpha,
        "delta": delta,
        "e_u": result.e_u,
        "e_energy": result.step.error_energy() if reference is not None else None,
        "penetration": result.profile.penetration,
        "max_tensile_sigma_c": float(np.max(result.profile.sigma_c, initial=0.0)),
        "layers": args.layers if args.method == "primal-ms" else None,
        "nbasis": args.nbasis if args.method == "primal-ms" else None,
        "offline_cache": result.step.omega1.cache_status if args.method == "primal-ms" else None,
    }

    def write(out: Path) -> None:
        sigma = stress_field(result.u, fields.lmbda, fields.mu)
        markers = cell_markers(cm.cell_tags, cm.mesh)
        write_fields(out / "fields.xdmf", cm.mesh, [result.u, sigma, fields.E, markers])
        if not args.no_plots:
            plot_displacement(result.u, out / "displacement.png", title=f"({args.method} hybrid)")
            render_deformed(result.u, out / "deformed.png", title=f"model {args.model}, {args.method} hybrid")

    return _Outcome(result, reference, summary, write)


def _run_mixed(args, cm: ContactMesh, model, fields, options: IterationOptions) -> _Outcome:
    """Algorithms 2 (mixed) and 4 (mixed-ms), with the monolithic mixed reference (serial)."""
    from fenics_contact.fem import mixed
    from fenics_contact.hybrid import mixed as mixed_hybrid
    from fenics_contact.multiscale import mixed as mixed_ms
    from fenics_contact.multiscale import mixed_cem as mixed_multiscale

    epsilon = args.epsilon
    min_gap = mixed_multiscale.DEFAULT_MIN_GAP if args.min_gap is None else (args.min_gap or None)
    max_nbasis = mixed_multiscale.DEFAULT_MAX_NBASIS if args.max_nbasis is None else args.max_nbasis
    reference = mixed.solve_mixed_monolithic(cm, model, epsilon=epsilon) if args.reference else None
    if args.method == "mixed":
        result = mixed_hybrid.solve_mixed_hybrid(cm, model, beta=args.beta, epsilon=epsilon, options=options,
                                                 reference=reference)
    else:
        result = mixed_ms.solve_mixed_ms_hybrid(cm, model, beta=args.beta, epsilon=epsilon, options=options,
                                                layers=args.layers, nbasis=args.nbasis, reference=reference,
                                                min_gap=min_gap, max_nbasis=max_nbasis,
                                                cache_dir=args.cache_dir)
    summary = {
        "beta": args.beta,
        "beta_value": result.beta,
        "epsilon": result.epsilon,
        "e_sigma": result.e_sigma,
        "e_u": result.e_u,
        "max_tensile_sigma_c": result.profile.max_tensile,
        "layers": args.layers if args.method == "mixed-ms" else None,
        "nbasis": args.nbasis if args.method == "mixed-ms" else None,
        "offline_cache": result.step.omega1.cache_status if args.method == "mixed-ms" else None,
        "stage_one_gap": result.step.omega1.spectral_gap if args.method == "mixed-ms" else None,
        "nbasis_per_cell": list(result.step.omega1.nbasis_range) if args.method == "mixed-ms" else None,
        "dim_X_ms": result.step.omega1.co.n_ms if args.method == "mixed-ms" else None,
    }

    def write(out: Path) -> None:
        sigma_cells = cell_function_of(result.sigma, name="sigma_cell_mean")
        u_cells = cell_function_of(result.u, name="u_cell_mean")
        markers = cell_markers(cm.cell_tags, cm.mesh)
        write_fields(out / "fields.xdmf", cm.mesh, [sigma_cells, u_cells, fields.E, markers])
        write_vtx(out / "sigma.bp", result.sigma)
        write_vtx(out / "u.bp", result.u)
        if not args.no_plots:
            plot_stress(result.sigma, out / "stress.png", title=f"({args.method} hybrid)")
            plot_displacement(result.u, out / "displacement.png", title=f"({args.method} hybrid)")

    return _Outcome(result, reference, summary, write)


def run(args) -> int:
    """Run one simulation; returns the exit code (0 converged, 3 not converged)."""
    comm = MPI.COMM_WORLD
    out: Path = args.out
    model = get_model(args.model, E_high=args.E_high, E_low=args.E_low, nu=args.nu)
    if args.E_map is not None:
        model = model.with_(youngs_modulus=pixel_field(_load_array(args.E_map)),
                            description=f"E from {args.E_map.name}, nu={args.nu:g}")
    options = IterationOptions(tol=args.tol, max_iterations=args.max_iterations, accel=args.accel)
    t0 = time.perf_counter()
    cm = _mesh(args)
    fields = material_fields(cm.mesh, model, require_load=True)
    t_mesh = time.perf_counter() - t0
    log.info("model %d (%s), h = %.4g, H = %s, method %s, accel %s",
             args.model, model.description, cm.h, cm.H, args.method, args.accel)
    family = _run_primal if args.method.startswith("primal") else _run_mixed
    outcome = family(args, cm, model, fields, options)
    result, reference = outcome.result, outcome.reference
    profile = result.profile
    summary = {
        "method": args.method,
        "model": args.model,
        "h": cm.h,
        "H": cm.H,
        "accel": args.accel,
        "iterations": result.iterations,
        "converged": result.converged,
        "rel_tolerance": args.tol,
        "final_rel_change": float(result.history.rel_changes[-1]),
        "transmission_residual": result.history.transmission_residual,
        "interface_newton_steps": result.history.newton_steps if args.accel == "newton" else None,
        **outcome.summary,
        "active_set": profile.active_interval(),
        "newton_steps_total": int(sum(r.info.get("newton", 0) for r in result.history.records)),
        "dofs": result.dofs,
        "time_mesh_s": t_mesh,
        "time_offline_s": result.time_offline_s,
        "time_online_s": result.time_online_s,
        "time_interface_offline_s": result.history.time_offline_s,
        "time_error_evaluation_s": result.history.time_monitor_s,
        "time_reference_s": reference.time_s if reference is not None else None,
        "reference_newton_steps": reference.newton.steps if reference is not None else None,
        "reference_active_set": reference.profile.active_interval() if reference is not None else None,
        "mpi_ranks": comm.size,
    }
    if comm.rank == 0:
        out.mkdir(parents=True, exist_ok=True)
    comm.Barrier()
    outcome.write(out)
    if not args.no_plots:
        plot_cell_field(fields.E, out / "E.png", title=f"Young's modulus, model {args.model}", log=True)
        profiles = {f"{args.method} hybrid": profile}
        if reference is not None:
            profiles["monolithic"] = reference.profile
        plot_contact(profiles, out / "contact.png", comm=comm)
        plot_history({f"{args.method}, {args.accel}": result.history}, out / "history.png", comm=comm, tol=args.tol)
    write_summary(out, summary, comm)
    status = "converged" if result.converged else "NOT CONVERGED"
    log.info("%s after %d iterations; e_u = %s; active set %s; summary in %s",
             status, result.iterations, result.e_u, profile.active_interval(), out / "summary.json")
    return 0 if result.converged else 3


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    _setup_logging(getattr(args, "verbose", False))
    try:
        return run(args)
    except FenicsContactError as err:
        log.error("error: %s", err)
        return 2


if __name__ == "__main__":
    sys.exit(main())
