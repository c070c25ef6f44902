"""What a run reports and draws: the contact summary entries, the open-end warning, the ParaView grid of a
state and the figures' titles; and what it needs: the space of its results, its memory."""

import logging
import math
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fenics_contact.cli.options import RunOptions
from fenics_contact.io import cell_function_of, cell_markers, stress_field
from fenics_contact.paraview import field_grid
from fenics_contact.plots import nodal_average, render_deformed
from fenics_contact.problem.geometry import check_memory
from fenics_contact.problem.models import MODELS_3D
from fenics_contact.problem.problem import ContactProblem

log = logging.getLogger("fenics_contact")


def _at_open_ends(profile, ends: np.ndarray) -> list[list[float]]:
    """The open ends of Γ_C (``validation.open_ends``: x, y, end facet length) that ``profile``'s contact reaches:
    a contact node within one facet of the end (the mixed method's σ_c vanishes at the end node itself next to
    a traction-free side), whatever the order of the profile's nodes."""
    if not ends.size or profile.points is None or not np.any(profile.active):
        return []
    touching = profile.points[profile.active][:, :2]
    hits = []
    for x, y, length in ends:
        if np.min(np.linalg.norm(touching - [x, y], axis=1)) <= 1.01 * length:
            hits.append([float(x), float(y)])
    return hits


def _contact_summary(profile, ends: np.ndarray) -> dict:
    """Contact zone(s) of a profile for the summary: the span, each separate zone, open ends reached."""
    zone = profile.contact_zone()
    return {
        "contact_zone": [list(p) for p in zone] if zone else None,
        "contact_zones": [[list(a), list(b)] for a, b in profile.contact_zones()],
        "contact_at_open_end": _at_open_ends(profile, ends),
    }


def _curve_row(
    depth: float, direction: np.ndarray, profile, iterations: int, converged: bool, time_s: float, ends: np.ndarray
) -> dict:
    return {
        "depth": float(depth),
        "force": float(profile.resultant @ direction),
        "normal_force": profile.force,
        "max_pressure": profile.max_pressure,
        **_contact_summary(profile, ends),
        "iterations": int(iterations),
        "converged": bool(converged),
        "time_s": time_s,
    }


def _friction_summary(profile, dissipation: float | None) -> dict:
    """The tangential side of a frictional solve (``fem.friction.FrictionProfile``) for the summary; the
    dissipation of a load step (None for a solve from the unloaded body)."""
    return {
        "normal_force": profile.normal_force,
        "tangential_force": profile.tangential_force.tolist(),
        "stick_nodes": int(np.count_nonzero(profile.stick)),
        "slip_nodes": int(np.count_nonzero(profile.slip)),
        "stick_zone": profile.extent("stick"),
        "slip_zone": profile.extent("slip"),
        "dissipation": None if dissipation is None else float(dissipation),
    }


def _warn_open_ends(summary: dict, comm: MPI.Comm) -> None:
    """Warn (rank 0) when a solve's contact zone reaches an end of Γ_C where the boundary goes on straight."""
    hits = [("the run", summary["contact_at_open_end"])] if summary["contact_at_open_end"] else []
    steps = (summary.get("force_indentation") or {}).get("steps", [])
    hits += [(f"depth {s['depth']:g}", s["contact_at_open_end"]) for s in steps if s["contact_at_open_end"]]
    if hits and comm.rank == 0:
        where = "; ".join(f"{what} at {', '.join(f'({x:.6g}, {y:.6g})' for x, y in pts)}" for what, pts in hits)
        log.warning(
            "the contact zone reaches an end of Gamma_C where the boundary goes on straight (%s): the "
            "true zone is wider than Gamma_C, so the contact force and pressure are those of a contact "
            "cut short by the tags, not of the body. Extend Gamma_C along that side.",
            where,
        )


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _field_grid(problem: ContactProblem, u, sigma=None):
    """The ParaView grid of a state: the P1 displacement ``u`` (primal; the stress from it), or the mixed
    stress ``sigma`` (DG P3: xx, xy, yy) and displacement ``u`` (DG P1, averaged at the vertices)."""
    fields, cm = problem.fields, problem.cm
    if sigma is None and problem.dim == 3:  # (xx, yy, zz, xy, yz, xz) of the 3 × 3 stress, row by row
        s = _cell_array(stress_field(u, fields.lmbda, fields.mu))
        stress = s[:, [0, 4, 8, 1, 5, 2]]
    elif sigma is None:
        s = _cell_array(stress_field(u, fields.lmbda, fields.mu))
        stress = np.column_stack([s[:, 0], s[:, 3], s[:, 1]])
    else:
        s = _cell_array(cell_function_of(sigma, name="sigma"))
        stress, u = np.column_stack([s[:, 0], s[:, 2], s[:, 1]]), nodal_average(u)
    return field_grid(u, stress, {"E": fields.E, "subdomain": cell_markers(cm.cell_tags, cm.mesh)}, fields.nu)


def _cell_array(fn) -> np.ndarray:
    """(local cells, components) of a DG0 function."""
    V = fn.function_space
    bs = V.dofmap.index_map_bs
    n = V.mesh.topology.index_map(V.mesh.topology.dim).size_local
    return fn.x.array.reshape(-1, bs)[V.dofmap.list[:n, 0]]


def _title(options: RunOptions, problem: ContactProblem) -> str:
    """The figures' name of the run: the case or mesh file, else the built-in model, and the method."""
    name = (
        f"case {Path(options.case).name}"
        if options.case is not None
        else f"mesh {Path(options.mesh).name}"
        if options.mesh is not None
        else f"model {options.model}"
    )
    return f"{name}, {options.method}"


def _render_deformed(u, path: Path, options: RunOptions, problem: ContactProblem, profile) -> None:
    """The deformed body with the problem's own obstacle (a wall flush with Γ_C when it has none)."""
    wall = profile.points if problem.obstacle is None else None
    render_deformed(u, path, title=_title(options, problem), obstacle=problem.obstacle, wall=wall)


#: bytes of the results per cell of the mesh and per state written (ParaView fields and contact, the mixed
#: methods' VTX files), of the figures and of the rest (summaries, file-system blocks), each twice what a run
#: writes (66, 950 bytes per cell; 0.32 to 0.48 MB of figures: ``fenics-contact run --h 32 --H 4 --method M``,
#: ``du -sb`` of --out and of its .png files, h = 1/16 and 1/32, each method)
BYTES_PER_CELL = {"primal": 150.0, "mixed": 2000.0}
BYTES_OF_PLOTS = 1.0e6
BYTES_FIXED = 1.0e5


def output_bytes(cm, options: RunOptions, case=None) -> float:
    """About how many bytes a run writes into ``--out`` (``OutputDirectory.check_space`` before the solve)."""
    cells = cm.mesh.topology.index_map(cm.mesh.topology.dim).size_global
    family = "primal" if options.method.startswith("primal") else "mixed"
    states = 1 + (len(case.obstacle.depths) if case is not None and case.obstacle.steps else 0)
    return BYTES_PER_CELL[family] * cells * states + (BYTES_OF_PLOTS if options.plots else 0.0) + BYTES_FIXED


#: peak memory of a run per mesh vertex, by method family (bytes): 6.9 kB (primal) and 235 kB (mixed: the
#: Arnold–Winther spaces and their factorizations) from h = 1/64 to 1/128 (``/usr/bin/time -f %M fenics-contact
#: run --h 128 --H 8 --method M --no-plots``), with a margin
RUN_BYTES_PER_VERTEX = {"primal": 1.0e4, "mixed": 2.5e5}
#: the same on a mesh of tetrahedra (the primal methods: three unknowns and about 15 neighbours a vertex, and the
#: fill of a direct factorization growing faster in 3D): 109 kB at h = 1/16 (4,913 vertices, 0.54 GB) and 88 kB at
#: h = 1/24 (15,625 vertices, 1.38 GB) of the cube of model 4 (``/usr/bin/time -f %M fenics-contact run --model 4
#: --h 24 --H 4 --method primal --no-plots``), with a margin
RUN_BYTES_PER_VERTEX_3D = 1.2e5


def run_vertices(options: RunOptions, cm=None) -> float:
    """The vertices of the run's mesh: of ``cm``, or without it of the built-in mesh of ``options`` before it is
    made, (n + 1)² on the unit square and (n + 1)³ on the cube of the 3D models (their gmsh block: about as many)."""
    if cm is not None:
        return float(cm.mesh.topology.index_map(0).size_global)
    return (options.n + 1.0) ** (3 if options.model in MODELS_3D else 2)


def check_run_memory(options: RunOptions, cm=None) -> None:
    """InputError before the solve when the run would need more memory than this machine has: on the mesh ``cm``,
    or without it on the built-in mesh of ``options`` (before it is made), by the bytes per vertex of the method's
    family and the mesh's dimension."""
    solid = options.model in MODELS_3D if cm is None else cm.mesh.topology.dim == 3
    family = "primal" if options.method.startswith("primal") else "mixed"
    per_vertex = RUN_BYTES_PER_VERTEX_3D if solid else RUN_BYTES_PER_VERTEX[family]
    check_memory(run_vertices(options, cm), f"the mesh of --method {options.method}", per_vertex)
