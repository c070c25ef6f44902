"""One run: inputs (E map) → output staging directory → mesh → solve (and load steps) → write → move it into
place."""

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import gmsh
import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.cli.cases import _options_echo
from fenics_contact.cli.coarse import check_case_coarse_grid, check_coarse_grid
from fenics_contact.cli.options import RunOptions
from fenics_contact.cli.outputs import (
    _contact_summary,
    _curve_row,
    _field_grid,
    _finite_or_none,
    _friction_summary,
    _render_deformed,
    _warn_open_ends,
    check_run_memory,
    output_bytes,
)
from fenics_contact.cli.pair import run_pair
from fenics_contact.cli.signals import EXIT_NOT_CONVERGED, Interrupted, _fail
from fenics_contact.errors import InputError
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.indentation import force_indentation
from fenics_contact.io import OutputDirectory, provenance, write_summary, write_vtx
from fenics_contact.methods import METHODS as CATALOGUE
from fenics_contact.methods import get_method
from fenics_contact.paraview import Series, contact_grid
from fenics_contact.plots import (
    hertz_curve_for,
    plot_cell_field,
    plot_contact,
    plot_displacement,
    plot_force_indentation,
    plot_history,
    plot_stress,
)
from fenics_contact.problem.case import Case
from fenics_contact.problem.cell_groups import bounding_box
from fenics_contact.problem.composite3d import MODEL_COMPOSITE_3D, fibre_block_3d_mesh
from fenics_contact.problem.geometry import ContactMesh, query_gmsh_file, read_mesh, unit_square
from fenics_contact.problem.models import MODELS_3D, get_model, pixel_field
from fenics_contact.problem.models3d import MODEL_3D, channels_3d_mesh
from fenics_contact.problem.pair_case import PairCase
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.strip import omega1_coarse_cells
from fenics_contact.problem.validation import contact_open_ends
from fenics_contact.sliding import slide

__all__ = ["check_pixel_modulus", "load_pixel_map", "run"]

log = logging.getLogger("fenics_contact")


def _indentation_curve(
    options: RunOptions, case: Case, problem: ContactProblem, outcome, ends: np.ndarray, out: Path, writes: bool
) -> dict:
    """The force-indentation curve of the case's load steps (the last step is the run's depth), each step's
    fields and contact written into ``out`` as ParaView series (by the ranks with ``writes``).

    primal, mixed: ``indentation.force_indentation`` (warm starts, factorizations kept) with the
    run's penalty and transmission coefficient; primal-ms, mixed-ms: the same with the run's hybrid
    step, so the Ω₁ offline phase of the run serves every step.
    """
    spec = case.obstacle
    direction = np.asarray(spec.direction, dtype=np.float64)
    direction = np.pad(direction, (0, max(problem.dim - direction.size, 0)))  # (a planar direction, z = 0 in 3D)
    if options.method in ("primal", "mixed"):
        if options.method == "primal":
            penalty = {"delta": outcome.summary["delta"], "alpha": options.value("alpha")}
        else:
            penalty = {"epsilon": outcome.summary["epsilon"], "beta": options.value("beta")}
    else:  # the run's step: its Ω₁ offline data, penalty and coefficients
        penalty = {"step": outcome.result.step}
    comm = problem.comm if writes else MPI.COMM_SELF
    fields, contact = Series(out, "fields", comm), Series(out, "contact", comm)
    primal = get_method(options.method).family == "primal"
    V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (problem.dim,))) if primal else None

    def write_step(step, solver) -> None:
        state = (solver.glued(V),) if primal else solver.glued()[::-1]  # (collective over the offline ranks)
        if not writes:
            return
        fields.add(step.depth, _field_grid(problem, *state))
        contact.add(step.depth, contact_grid(step.profile, comm))

    curve = force_indentation(
        problem.with_(obstacle=spec.base()),
        options.method,
        spec.depths,
        direction=direction,
        options=options.iteration_options(),
        on_step=write_step,
        **penalty,
    )
    rows = [
        _curve_row(s.depth, direction, s.profile, s.iterations, s.converged, s.time_s, ends)
        | {
            "transmission_residual": s.transmission_residual,
            "complementarity": s.complementarity._asdict(),
            "interface_newton_steps": s.interface_newton_steps if options.accel == "newton" else None,
            "omega1_check": s.omega1_check,
        }
        for s in curve.steps
    ]
    return {"direction": direction.tolist(), "steps": rows}


def _sliding_path(
    options: RunOptions, case: Case, problem: ContactProblem, out: Path, writes: bool, comm: MPI.Comm = MPI.COMM_SELF
) -> dict:
    """The case's sliding path (``[obstacle] motion``, ``sliding.slide``): per step the forces, the stick and
    slip zones and the dissipation; each step's fields and contact written into ``out`` as ParaView series
    (time: the step's number) by the ranks with ``writes``; ``comm``: the ranks sharing mixed-ms's offline phase
    (each holding the whole mesh)."""
    comm = problem.comm if writes else MPI.COMM_SELF
    fields, contact = Series(out, "fields", comm), Series(out, "contact", comm)
    V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (problem.dim,)))
    written = []

    mixed = get_method(options.method).family == "mixed"

    def write_step(step, solver) -> None:
        sigma = None  # (collective:)
        if mixed:  # σ (DG P3) and u (DG P1), the parts glued
            sigma, u = (
                solver.glued()
                if hasattr(solver, "glued")
                else (solver.contact.sigma_function(), solver.contact.u_function())
            )
        else:
            u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
        written.append(step)
        if writes:
            fields.add(float(len(written)), _field_grid(problem, u, sigma))
            contact.add(float(len(written)), contact_grid(step.profile, comm))

    flat = options.method_options()
    extra = {"offline_comm": comm} if mixed and get_method(options.method).multiscale else {}
    path = slide(
        problem.with_(obstacle=case.obstacle.base()),
        options.method,
        case.obstacle.motions,
        on_step=write_step,
        **flat,
        **extra,
    )
    rows = [
        {"motion": list(map(float, s.motion))}
        | (_friction_summary(s.friction, s.dissipation) if s.friction is not None else {})
        | {
            "contact_force": s.profile.force,
            "iterations": s.iterations,
            "converged": bool(s.converged),
            "transmission_residual": s.transmission_residual,
            "interface_newton_steps": s.interface_newton_steps,
            "time_s": s.time_s,
        }
        for s in path.steps
    ]
    return {"steps": rows, "dissipation": path.dissipation}


# ---------------------------------------------------------------------------------------------
# inputs
# ---------------------------------------------------------------------------------------------
def load_pixel_map(path: Path) -> np.ndarray:
    """A 2D array of pixels from .npy or text (InputError if unreadable, empty or not 2D)."""
    try:
        if path.suffix == ".npy":
            values = np.load(path, allow_pickle=False)
        else:
            values = np.loadtxt(path, delimiter="," if path.suffix == ".csv" else None, ndmin=2)
    except (OSError, ValueError, EOFError) as err:
        raise InputError(f"cannot read a pixel array from {path}: {type(err).__name__}: {err}") from None
    try:
        values = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"--E-map {path} does not hold numbers (dtype {values.dtype})") from None
    if values.ndim != 2 or values.size == 0:
        raise InputError(f"--E-map {path} must hold a non-empty 2D array, got shape {values.shape}")
    return values


def check_pixel_modulus(values: np.ndarray, box: tuple[float, float, float, float], source: str) -> None:
    """Every pixel of the unit-square map that the box (x0, x1, y0, y1) covers is a finite E > 0."""
    ny, nx = values.shape
    x0, x1, y0, y1 = box
    i0, i1 = (int(np.clip(np.floor(x * nx), 0, nx - 1)) for x in (x0, x1))
    j0, j1 = (int(np.clip(np.floor(y * ny), 0, ny - 1)) for y in (y0, y1))
    covered = values[j0 : j1 + 1, i0 : i1 + 1]
    bad = ~(np.isfinite(covered) & (covered > 0))
    if np.any(bad):
        j, i = np.argwhere(bad)[0]
        raise InputError(
            f"{source}: {np.count_nonzero(bad)} pixels the domain covers are not a finite Young's "
            f"modulus > 0 (first: row {j + j0}, column {i + i0}, value {float(covered[j, i])!r})"
        )


def _model(options: RunOptions) -> tuple[ContactProblem, np.ndarray | None]:
    model = get_model(options.model, E_high=options.value("E_high"), E_low=options.value("E_low"), nu=options.nu)
    if options.E_map is None:
        return model, None
    values = load_pixel_map(options.E_map)
    if options.mesh is None:  # the built-in mesh covers the unit square: check before building it
        check_pixel_modulus(values, (0.0, 1.0, 0.0, 1.0), f"--E-map {options.E_map}")
    model = model.with_(
        youngs_modulus=pixel_field(values), description=f"E from {options.E_map.name}, nu={options.nu:g}"
    )
    return model, values


def _solid(path: Path, comm: MPI.Comm) -> bool:
    """Whether the gmsh file holds 3D cells (False when gmsh cannot read it: read_mesh says why). Collective."""
    return query_gmsh_file(path, comm, lambda: len(gmsh.model.mesh.getElementTypes(3)) > 0, False)


def _mesh(options: RunOptions, comm: MPI.Comm = MPI.COMM_WORLD) -> ContactMesh:
    multiscale = CATALOGUE[options.method].multiscale
    if options.mesh is not None:
        # (a 3D mesh takes 1/H for the multiscale methods only, the side of its coarse cubes: the strip of a file
        # without one is otherwise the band of ``problem.strip``)
        grid = not options.coarse_groups and (multiscale or not _solid(options.mesh, comm))
        return read_mesh(options.mesh, H=1.0 / options.H if grid else None, comm=comm)
    if options.model == MODEL_3D:  # the multiscale methods' coarse cubes: side 1/H, as the strip
        return channels_3d_mesh(options.n, strip=1.0 / options.H, H=1.0 / options.H if multiscale else None, comm=comm)
    if options.model == MODEL_COMPOSITE_3D:
        cm = fibre_block_3d_mesh(options.n, strip=1.0 / options.H, comm=comm)
        if multiscale:  # the cubes of side 1/H that hold the Ω₁ cells' centroids (the mesh follows the fibres)
            cm = cm._replace(coarse_cell=omega1_coarse_cells(cm.mesh, cm.cell_tags, 1.0 / options.H))
        return cm
    return unit_square(options.n, options.H, comm=comm)


def _replicated(options: RunOptions, comm: MPI.Comm) -> bool:
    """mixed-ms under MPI: every rank holds the whole mesh (the AW space is serial), the offline phase is shared."""
    return options.method == "mixed-ms" and comm.size > 1


def _bounding_box(cm: ContactMesh) -> tuple[float, float, float, float]:
    return bounding_box(cm.mesh)  # (an elementwise allreduce of arrays failed under MPI)


def _series_written(out: Path, comm: MPI.Comm) -> bool:
    """Whether ``out`` holds the fields series of load steps, as rank 0 (which writes it) sees it: the ranks decide
    alike whether to write the run's single state (a collective write)."""
    return comm.bcast((out / "fields.pvd").exists() if comm.rank == 0 else None, root=0)


class _Outcome(NamedTuple):
    """What a method family hands back to ``run``: its result, summary entries and output writer."""

    result: object
    reference: object | None
    summary: dict
    write: Callable[[Path], None]


def _run_primal(options: RunOptions, problem: ContactProblem) -> _Outcome:
    """Algorithms 1 (primal) and 3 (primal-ms), with the monolithic primal reference."""
    method = get_method(options.method)
    flat = options.method_options()
    reference = (
        CATALOGUE["primal-monolithic"].solve(problem, delta=options.delta, **options.reference_options())
        if options.reference
        else None
    )
    result = method.solve(problem, **flat, reference=reference.u if reference is not None else None)
    ms = method.multiscale
    summary = {
        "alpha": options.value("alpha"),
        "delta": result.step.delta,
        "e_u": result.e_u,
        "e_energy": result.step.error_energy() if reference is not None else None,
        "penetration": result.profile.penetration,
        "max_tensile_sigma_c": float(np.max(result.profile.sigma_c, initial=0.0)),
        "layers": result.step.cem.layers if ms else None,
        "nbasis": ("all" if result.step.cem.nbasis is None else result.step.cem.nbasis) if ms else None,
        "offline_cache": result.step.omega1.cache_status if ms else None,
        # Λ, the smallest local eigenvalue left out (it falls like μ/(λ+2μ) as ν → ½, and with inclusions)
        "spectral_gap": _finite_or_none(result.step.omega1.spectral_gap) if ms else None,
        # the multiscale Ω₁ against its fine solve for the run's interface data (relative, energy norm)
        "omega1_check": result.omega1_check if ms else None,
    }

    def write(out: Path) -> None:
        if not _series_written(out, problem.comm):  # (load steps write their own series)
            Series(out, "fields", problem.comm).add(0.0, _field_grid(problem, result.u))
            Series(out, "contact", problem.comm).add(0.0, contact_grid(result.profile, problem.comm))
        if options.plots and problem.dim == 2:  # (figures of the plane; a 3D run has its ParaView series)
            plot_displacement(result.u, out / "displacement.png", title=f"({options.method} hybrid)")
            _render_deformed(result.u, out / "deformed.png", options, problem, result.profile)

    return _Outcome(result, reference, summary, write)


def _split_interface_errors(problem: ContactProblem, result, standard) -> tuple[float, float]:
    """(e_σ, e_u) of a mixed hybrid result against the monolithic mixed solution on the stress space whose normal
    traction is continuous across γ (σ_tt doubled at γ's straight vertices): the fixed point of Algorithm 2, so
    that a summary tells the hybrid iteration's own error (this one) from the split-γ discretization's (the
    difference to e_σ, e_u against the Arnold–Winther solution ``standard``), which is put back as the step's
    reference."""
    split = solve_mixed_monolithic(problem, epsilon=result.epsilon, split_interface=True)
    split.free()
    try:
        result.step.set_reference(split)
        return result.step.errors()
    finally:
        result.step.set_reference(standard)


def _run_mixed(options: RunOptions, problem: ContactProblem, comm: MPI.Comm = MPI.COMM_SELF) -> _Outcome:
    """Algorithms 2 (mixed) and 4 (mixed-ms), with the monolithic mixed reference (serial).

    ``comm``: the ranks sharing the mixed-ms offline phase (each holds the whole mesh); the
    reference is then solved on rank 0 only, which alone reports the errors and writes.
    """
    method = get_method(options.method)
    ms = method.multiscale
    flat = options.method_options()
    reference = (
        CATALOGUE["mixed-monolithic"].solve(problem, epsilon=options.epsilon)
        if options.reference and comm.rank == 0
        else None
    )
    if reference is not None:
        reference.free()  # only its solution is used: the factors of the whole problem go now
    extra = {"offline_comm": comm} if ms else {}
    result = method.solve(problem, **flat, reference=reference, **extra)
    e_split = _split_interface_errors(problem, result, reference) if reference is not None else (None, None)
    summary = {
        "beta": options.value("beta"),
        "beta_value": result.beta,
        "epsilon": result.epsilon,
        "e_sigma": result.e_sigma,
        "e_u": result.e_u,
        # against the hybrid method's own fixed point: the mixed solution with σn continuous across γ
        "e_sigma_split": e_split[0],
        "e_u_split": e_split[1],
        # mixed-ms: e_u is that of a coarse displacement (U_aux); e_u_post that of the fine one (README)
        "e_u_post": getattr(result, "e_u_post", None) if ms else None,
        "max_tensile_sigma_c": result.profile.max_tensile,
        "layers": result.step.cem.layers if ms else None,
        "nbasis": result.step.cem.nbasis if ms else None,
        "offline_cache": result.step.omega1.cache_status if ms else None,
        "stage_one_gap": result.step.omega1.spectral_gap if ms else None,
        "nbasis_per_cell": list(result.step.omega1.nbasis_range) if ms else None,
        "dim_X_ms": result.step.omega1.co.n_ms if ms else None,
    }

    def write(out: Path) -> None:
        if not _series_written(out, problem.comm):  # (load steps write their own series)
            Series(out, "fields", problem.comm).add(0.0, _field_grid(problem, result.u, result.sigma))
            Series(out, "contact", problem.comm).add(0.0, contact_grid(result.profile, problem.comm))
        write_vtx(out / "sigma.bp", result.sigma)
        write_vtx(out / "u.bp", result.u)
        if options.plots:
            plot_stress(result.sigma, out / "stress.png", title=f"({options.method} hybrid)")
            plot_displacement(result.u, out / "displacement.png", title=f"({options.method} hybrid)")
            _render_deformed(result.u, out / "deformed.png", options, problem, result.profile)

    return _Outcome(result, reference, summary, write)


# ---------------------------------------------------------------------------------------------
# one run
# ---------------------------------------------------------------------------------------------
def run(options: RunOptions, comm: MPI.Comm = MPI.COMM_WORLD, *, case: Case | None = None) -> int:
    """Run one simulation into ``options.out``; returns 0 (converged) or 3 (not converged), raises otherwise.

    ``case``: the problem from a case file (``options_from_arguments``); else the built-in model of
    the options. An ``Interrupted`` raised meanwhile carries ``output_complete``: whether ``--out``
    already holds the run.
    """
    if isinstance(case, PairCase):  # two deformable bodies (cli.pair)
        return run_pair(options, comm, case)
    model, pixels = _model(options) if case is None else (None, None)
    if case is None and options.mesh is None:
        check_run_memory(options)  # (before the unit square is made)
    output = OutputDirectory(options.out, comm)
    try:
        with output, output.writing():  # (a failed write: OutputError)
            result, summary = _solve_and_write(options, comm, model, pixels, output, case)
    except Interrupted as stop:
        stop.output_complete = output.committed
        raise
    if not result.converged:
        capped = result.iterations >= options.max_iterations
        why = (
            f"the iteration hit --max-iterations {options.max_iterations}"
            if capped
            else f"stopped after {result.iterations} iterations (the Newton corrections ran out)"
        )
        _fail(
            f"not converged: {why} (transmission residual {summary['transmission_residual']:.3e} > --tol "
            f'{options.tol:g}); results in {options.out} with "converged": false',
            comm,
        )
        return EXIT_NOT_CONVERGED
    if not summary["converged"]:  # a load step of the force-indentation curve
        bad = [s for s in summary["force_indentation"]["steps"] if not s["converged"]]
        steps = ", ".join(f"depth {s['depth']:g} after {s['iterations']} iterations" for s in bad)
        _fail(
            f"not converged: the load step(s) at {steps} (--max-iterations {options.max_iterations}, --tol "
            f'{options.tol:g}); results in {options.out} with "converged": false',
            comm,
        )
        return EXIT_NOT_CONVERGED
    log.info(
        "converged after %d iterations; e_u = %s; active set %s; summary in %s",
        result.iterations,
        result.e_u,
        result.profile.active_interval(),
        options.out / "summary.json",
    )
    return 0


def _solve_and_write(
    options: RunOptions,
    comm: MPI.Comm,
    model: ContactProblem | None,
    pixels: np.ndarray | None,
    output: OutputDirectory,
    case: Case | None = None,
) -> tuple[object, dict]:
    """Mesh, solve, write everything into the staging directory and move it into place."""
    t0 = time.perf_counter()
    replicated = _replicated(options, comm)
    mesh_comm = MPI.COMM_SELF if replicated else comm  # replicated: every rank holds the whole mesh (mixed-ms)
    if case is None:
        cm = _mesh(options, mesh_comm)
        if pixels is not None and options.mesh is not None:
            check_pixel_modulus(pixels, _bounding_box(cm), f"--E-map {options.E_map}")
        if (options.mesh is not None or options.model == MODEL_COMPOSITE_3D) and options.method.endswith("-ms"):
            check_coarse_grid(cm, options)
    else:
        case_mesh = case.build_mesh(mesh_comm)
        cm = case_mesh.cm
        model = case.problem(case_mesh)
        if options.method.endswith("-ms"):
            check_case_coarse_grid(cm, options, case)
    if case is None and cm.mesh.topology.dim == 3 and options.model not in MODELS_3D:
        raise InputError(
            f"--mesh {options.mesh} is a tetrahedral (3D) mesh and the built-in model {options.model} is planar: "
            f"run it with --model {MODEL_3D} (the 3D channel model's materials and load), --model "
            f"{MODEL_COMPOSITE_3D} (the fibre composite's) or a case file"
        )
    problem = model.on(cm)
    problem.check_loaded()
    check_run_memory(options, cm)
    output.check_space(output_bytes(cm, options, case))
    fields = problem.fields
    t_mesh = time.perf_counter() - t0
    name = f"model {options.model}" if case is None else f"case {case.path.name}"
    log.info(
        "%s (%s), h = %.4g, H = %s, method %s, accel %s",
        name,
        model.description,
        cm.h,
        cm.H,
        options.method,
        options.accel,
    )
    if get_method(options.method).family == "primal":
        outcome = _run_primal(options, problem)
    else:
        outcome = _run_mixed(options, problem, comm if replicated else MPI.COMM_SELF)
    result, reference = outcome.result, outcome.reference
    profile = result.profile
    ends = contact_open_ends(cm)  # (the open ends of Γ_C, for every solve's contact summary)
    writes = not replicated or comm.rank == 0  # replicated: rank 0 holds the whole run and writes it
    curve = (
        _indentation_curve(options, case, problem, outcome, ends, output.path, writes)
        if case and case.obstacle.steps
        else None
    )
    sliding = (
        _sliding_path(options, case, problem, output.path, writes, comm if replicated else MPI.COMM_SELF)
        if case and case.obstacle.motions
        else None
    )
    contact_sub = getattr(getattr(result, "step", None), "contact", None)
    friction = getattr(contact_sub, "friction", None)
    summary = {
        "method": options.method,
        "model": options.model if case is None else None,
        "mesh": str(options.mesh) if options.mesh is not None else None,
        "h": cm.h,
        "H": cm.H,
        "accel": options.accel,
        "front_window": options.newton_options().front_window if options.accel == "newton" else None,
        "iterations": result.iterations,
        "converged": result.converged
        and (curve is None or all(s["converged"] for s in curve["steps"]))
        and (sliding is None or all(s["converged"] for s in sliding["steps"])),
        "rel_tolerance": options.tol,
        # the relative change of the last two iterates (the paper's rule): not defined for the interface Newton,
        # which applies T once, to certify its solution
        "final_rel_change": float(result.history.rel_changes[-1]) if options.accel != "newton" else None,
        "transmission_residual": result.history.transmission_residual,
        "transmission_floor": result.history.floor,
        "status": result.history.status,
        "interface_newton_steps": result.history.newton_steps if options.accel == "newton" else None,
        **outcome.summary,
        "active_set": profile.active_interval(),
        "contact_force": profile.force,
        **_contact_summary(profile, ends),
        "max_contact_pressure": profile.max_pressure,
        # Ω₂'s semismooth Newton steps over the iteration (the interface Newton solves Ω₂ within its own steps)
        "newton_steps_total": (
            int(sum(r.info.get("newton", 0) for r in result.history.records)) if options.accel != "newton" else None
        ),
        "dofs": result.dofs,
        "time_mesh_s": t_mesh,
        "time_offline_s": result.time_offline_s,
        "time_online_s": result.time_online_s,
        "time_interface_offline_s": result.history.time_offline_s,
        "time_error_evaluation_s": result.history.time_monitor_s,
        "time_reference_s": reference.time_s if reference is not None else None,
        "reference_newton_steps": reference.newton.steps if reference is not None else None,
        # the primal reference's linear solver ("direct" or "amg") and its Krylov iterations per Newton step
        "reference_linear_solver": getattr(reference, "linear_solver", "direct") if reference is not None else None,
        "reference_krylov_iterations": getattr(reference, "krylov_iterations", None) or None,
        "reference_active_set": reference.profile.active_interval() if reference is not None else None,
        "mpi_ranks": comm.size,
        "provenance": provenance(),
        "force_indentation": curve,
        # with a friction law: the run's own solve (one load step from the unloaded body) and the sliding path
        # (with a sliding path: its last step)
        "friction": (sliding["steps"][-1] if sliding else _friction_summary(friction.profile(), None))
        | {"law": friction.law.describe()}
        if friction is not None
        else None,
        "sliding": sliding,
        "case": case.to_dict(problem.dim) | {"run": _options_echo(options)} if case is not None else None,
    }
    _warn_open_ends(summary, comm)
    out = output.path
    writer = MPI.COMM_SELF if replicated else comm  # replicated: rank 0 holds the whole run and writes it
    if not replicated or comm.rank == 0:
        outcome.write(out)
        if options.plots and problem.dim == 3:  # (the plane figures do not apply: the ParaView series do)
            if curve is not None:
                plot_force_indentation({options.method: curve}, out / "force_indentation.png", comm=writer)
            plot_history(
                {f"{options.method}, {options.accel}": result.history},
                out / "history.png",
                comm=writer,
                tol=options.tol,
            )
        elif options.plots:
            plot_cell_field(fields.E, out / "E.png", title=f"Young's modulus, {name}", log=True)
            if curve is not None:
                plot_force_indentation({options.method: curve}, out / "force_indentation.png", comm=writer)
            profiles = {f"{options.method} hybrid": profile}
            if reference is not None:
                profiles["monolithic"] = reference.profile
            (E_lo, E_hi), (nu_lo, nu_hi) = problem.contact_range("E"), problem.contact_range("nu")
            hertz = (
                hertz_curve_for(problem.obstacle, profile.points, E_hi, nu_hi)
                if (E_lo, nu_lo) == (E_hi, nu_hi)
                else None
            )  # (Hertz: a homogeneous body at the contact)
            plot_contact(profiles, out / "contact.png", comm=writer, hertz=hertz)
            plot_history(
                {f"{options.method}, {options.accel}": result.history},
                out / "history.png",
                comm=writer,
                tol=options.tol,
            )
        write_summary(out, summary, writer)
    output.commit()
    return result, summary
