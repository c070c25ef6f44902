"""``fenics-contact check-mesh FILE`` and ``check-mesh --case CASE.toml``: a mesh checked without a solve.

The mesh is read the way ``run`` reads it (``RunOptions`` and ``run --mesh FILE``'s reader, or the
case file's mesh and problem, ``problem.case``), with every check a run makes before its first
solve: the file's elements and physical groups, the tags against the contact problem
(``problem.validation``), the strip Ω₂, γ and the coarse cells built when the file has none of
Omega1/Omega2/gamma (``problem.strip``), the materials and loads, the coarse grid of the multiscale
methods and the dimension each method solves in. It prints what it found and which methods can run;
exit 0 when a run with the chosen method could start, 2 (the run's code for bad input) with the
refusal otherwise.
"""

import argparse
import dataclasses
from pathlib import Path
from types import SimpleNamespace

import gmsh
import numpy as np
from mpi4py import MPI

from fenics_contact.cli.cases import case_run_options
from fenics_contact.cli.coarse import check_case_coarse_grid, check_coarse_grid
from fenics_contact.cli.options import METHODS, RunOptions
from fenics_contact.cli.pair import PAIR_METHODS, check_coarse_size, pair_run_options
from fenics_contact.cli.signals import stdout_lost
from fenics_contact.cli.solve import _mesh, _model
from fenics_contact.errors import FenicsContactError, InputError
from fenics_contact.hybrid.two_body import strip_cells
from fenics_contact.methods import METHODS as CATALOGUE
from fenics_contact.multiscale.pair import bulk_meshes
from fenics_contact.multiscale.pair_replica import PairReplica
from fenics_contact.problem.case import Case, MeshFile, load_case, parse_override
from fenics_contact.problem.geometry import ContactMesh, query_gmsh_file
from fenics_contact.problem.models3d import MODEL_3D
from fenics_contact.problem.pair_case import PairCase
from fenics_contact.problem.strip import contact_cell_size
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, is_neumann_name
from fenics_contact.problem.validation import contact_open_ends, interface_bends_of, require_method_dimension

__all__ = ["check_mesh"]

#: the groups the package builds when a file has none of them (Ω₁, Ω₂, γ)
_BUILT = (PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2], PHYSICAL_NAMES[Boundary.INTERFACE])
#: what each named group is to the contact problem
_ROLES = {
    PHYSICAL_NAMES[Subdomain.OMEGA1]: "Omega1: the subdomain Ω₁ (linear; fine or multiscale)",
    PHYSICAL_NAMES[Subdomain.OMEGA2]: "Omega2: the contact strip Ω₂",
    PHYSICAL_NAMES[Boundary.INTERFACE]: "gamma: the interface γ between Ω₁ and Ω₂",
    PHYSICAL_NAMES[Boundary.GAMMA_C]: "Gamma_C: the contact boundary Γ_C",
    PHYSICAL_NAMES[Boundary.GAMMA_D]: "Gamma_D: the Dirichlet boundary Γ_D (clamped, or the case's displacement)",
}
_KINDS = {0: ("point", "points"), 1: ("curve", "segments"), 2: ("surface", "triangles"), 3: ("volume", "cells")}


def check_mesh(args: argparse.Namespace, comm: MPI.Comm = MPI.COMM_WORLD) -> int:
    """``fenics-contact check-mesh``: 0 when a run could start; raises the run's refusal (InputError,
    MeshTagError) otherwise, after printing what was found. Collective."""
    if (args.file is None) == (args.case is None):
        raise InputError("check-mesh takes a mesh FILE or --case CASE.toml (one of them)")
    if args.case is None and args.set:
        raise InputError("--set changes a key of a case file: it needs --case FILE")
    if args.case is not None and (args.H is not None or args.coarse_groups):
        raise InputError("--H and --coarse-groups apply to a mesh FILE; a case file gives them in its [mesh] table")
    if args.case is not None:
        found = load_case(args.case, [parse_override(text) for text in args.set or ()])
        if isinstance(found, PairCase):
            return _check_pair(found, args, comm)
    case, options = _options(args)
    path = options.mesh if case is None else case.mesh.path if isinstance(case.mesh, MeshFile) else None
    say = _printer(comm)
    say(
        f"{'mesh ' + str(path) if case is None else 'case ' + str(case.path)}"
        + (
            f" (mesh {path})"
            if case is not None and path is not None
            else f" (built-in {case.mesh.kind} mesh)"
            if case is not None
            else ""
        )
    )
    groups = _file_groups(path, comm) if path is not None else None
    if groups is not None:
        materials = case.material.groups() if case is not None else set()
        tdim = 3 if any(dim == 3 for _, dim, _ in groups) else 2  # (the cells' dimension: 3 for tetrahedra)
        built = not any(name in _BUILT for name, _, _ in groups) and any(dim == tdim for _, dim, _ in groups)
        say("  physical groups of the file:")
        for name, dim, count in groups:
            kind, unit = _KINDS.get(dim, (f"dimension {dim}", "elements"))
            role = _role(name, dim, materials, built, options, tdim)
            say(f"    {name:<16} {kind:<8} {count:>8} {unit:<10} {role}")
    cm, problem = _build(options, case, comm)
    _describe(cm, say, groups)
    refusals = {m: _refusal(m, cm, options, case) for m in METHODS}
    say("  methods: " + "; ".join(f"{m} {'can run' if why is None else 'refused'}" for m, why in refusals.items()))
    for m, why in refusals.items():
        if why is not None and m != options.method:  # (the chosen method's refusal ends the command)
            say(f"    {m}: {' '.join(str(why).split())}")
    if refusals[options.method] is not None:
        raise refusals[options.method]
    say(f"ok: a run with --method {options.method} can start ({problem.description})")
    return 0


def _options(args: argparse.Namespace) -> tuple[Case | None, RunOptions]:
    """The case (or None) and the run options a run would have: validated as ``run`` validates them."""
    given = {"method": args.method} if args.method is not None else {}
    if args.case is not None:
        case = load_case(args.case, [parse_override(text) for text in args.set or ()])
        return case, case_run_options(case, given)
    H = {"H": args.H} if args.H is not None else {}
    return None, RunOptions(mesh=args.file, coarse_groups=args.coarse_groups, **given, **H)


def _build(options: RunOptions, case: Case | None, comm: MPI.Comm):
    """The mesh and the problem on it, as ``run`` builds them before its solve (collective)."""
    if case is None:
        cm = _mesh(options, comm)
        if cm.mesh.topology.dim == 3:  # (the planar models' loads are 2-vectors: the 3D model's physics)
            options = dataclasses.replace(options, model=MODEL_3D)
        model, _ = _model(options)
    else:
        case_mesh = case.build_mesh(comm)
        cm = case_mesh.cm
        model = case.problem(case_mesh)
    problem = model.on(cm)
    problem.check_loaded()
    return cm, problem


def _refusal(method: str, cm: ContactMesh, options: RunOptions, case: Case | None) -> FenicsContactError | None:
    """Why ``method`` would refuse this mesh before its first solve (None: it would start)."""
    entry = CATALOGUE[method]
    try:
        require_method_dimension(method, cm.mesh)
        if entry.multiscale:
            as_run = SimpleNamespace(method=method, mesh=options.mesh, H=options.H)
            if case is None:
                check_coarse_grid(cm, as_run)
            else:
                check_case_coarse_grid(cm, as_run, case)
    except FenicsContactError as err:
        return err
    return None


def _describe(cm: ContactMesh, say, groups) -> None:
    """What the built mesh holds: sizes, the tagged cells and facets, the contact cell size, γ and Γ_C's ends."""
    msh = cm.mesh
    tdim = msh.topology.dim
    msh.topology.create_entities(tdim - 1)
    cells, facets = msh.topology.index_map(tdim), msh.topology.index_map(tdim - 1)
    say(
        f"  dimension {msh.geometry.dim}, {cells.size_global} {'tetrahedra' if tdim == 3 else 'triangles'}, "
        f"{msh.topology.index_map(0).size_global} "
        "vertices"
    )
    counts = {PHYSICAL_NAMES[t]: _owned(cm.cell_tags.find(t), cells.size_local, cm.comm) for t in Subdomain}
    counts |= {PHYSICAL_NAMES[t]: _owned(cm.facet_tags.find(t), facets.size_local, cm.comm) for t in Boundary}
    counts |= {
        name: _owned(cm.facet_tags.find(tag), facets.size_local, cm.comm)
        for tag, name in sorted((cm.neumann_names or {}).items(), key=lambda item: item[1])
    }
    given = (
        "tagged by the built-in mesh"
        if groups is None
        else "given in the file"
        if any(name in _BUILT for name, _, _ in groups)
        else "built automatically along Gamma_C (problem.strip)"
    )
    say(f"  Omega1, Omega2, gamma: {given}")
    say(
        "  tagged: "
        + ", ".join(f"{name} {n} {'cells' if name in _BUILT[:2] else 'facets'}" for name, n in counts.items())
    )
    coarse = "none" if cm.H is None else f"{cm.H:.6g}"
    contact = contact_cell_size(msh, cm.facet_tags)
    say(
        f"  h = {cm.h:.6g} (the run's mesh size), contact cell size {contact:.6g} (the largest diameter of a "
        f"cell on Gamma_C), H = {coarse}"
    )
    bends = interface_bends_of(cm)
    say(
        "  gamma: straight"
        if not bends.size
        else f"  gamma: bends at {len(bends)} vertices (first at ({bends[0][0]:.6g}, {bends[0][1]:.6g})); the mixed "
        "methods take the traction of one stress tensor there"
    )
    ends = contact_open_ends(cm)
    if ends.size:
        say(
            f"  Gamma_C ends where the boundary goes on straight at {len(ends)} points (first at "
            f"({ends[0][0]:.6g}, {ends[0][1]:.6g})): a contact zone reaching them is cut short by the tags"
        )


def _check_pair(case: PairCase, args: argparse.Namespace, comm: MPI.Comm) -> int:
    """check-mesh of a two-body case: the file's groups and their roles, the bodies and the pair as the run
    builds them (``PairCase.problem``: every group, support and the pair validated), the methods."""
    options = pair_run_options(case, {"method": args.method} if args.method is not None else {})
    say = _printer(comm)
    say(f"case {case.path} (mesh {case.mesh_file}): two deformable bodies")
    roles = {}
    for body in case.bodies:
        roles |= {name: f"cells of the body {body.name}" for name in body.cells}
        for s in body.supports:
            what = "u = 0" if s.displacement is None else f"u = {s.displacement.echo()}"
            comps = "" if s.components is None else f" on components {list(s.components)}"
            roles[s.facets] = f"a support of the body {body.name} ({what}{comps})"
        roles |= {name: f"a traction on the body {body.name}" for name, _ in body.tractions}
    if case.load is not None:
        roles[case.load.group] += f", stepped in {len(case.load.steps)} load steps"
    roles[case.pair.slave] = "the slave contact surface (the contact integral lives on it)"
    roles[case.pair.master] = "the master contact surface (the slave points are projected onto it)"
    groups = _file_groups(case.mesh_file, comm) or []
    say("  physical groups of the file:")
    facet_dim = 2 if any(dim == 3 for _, dim, _ in groups) else 1
    for name, dim, count in groups:
        kind, unit = _KINDS.get(dim, (f"dimension {dim}", "elements"))
        role = roles.get(name, "no role (traction free)" if dim == facet_dim else "no role")
        say(f"    {name:<16} {kind:<8} {count:>8} {unit:<10} {role}")
    built = case.build_mesh(comm)
    problem = case.problem(built)
    msh = problem.mesh
    tdim = msh.topology.dim
    say(
        f"  dimension {msh.geometry.dim}, {msh.topology.index_map(tdim).size_global} "
        f"{'tetrahedra' if tdim == 3 else 'triangles'}, "
        f"{msh.topology.index_map(0).size_global} vertices"
    )
    n_cells = msh.topology.index_map(tdim).size_local
    n_facets = msh.topology.index_map(tdim - 1).size_local
    for k, body in enumerate(case.bodies):
        cells = problem.body_cells(k)
        E = problem.fields.E.x.array[cells[cells < n_cells]]
        lo = comm.allreduce(float(np.min(E, initial=np.inf)), op=MPI.MIN)
        hi = comm.allreduce(float(np.max(E, initial=-np.inf)), op=MPI.MAX)
        say(f"  body {body.name}: {_owned(cells, n_cells, comm)} cells, E in [{lo:.6g}, {hi:.6g}]")
    slave_body = case.bodies[problem._slave_body].name
    say(
        f"  pair: slave {case.pair.slave} ({_owned(problem.facet_tags.find(problem.pair.slave), n_facets, comm)} "
        f"facets, body {slave_body}), master {case.pair.master} "
        f"({_owned(problem.facet_tags.find(problem.pair.master), n_facets, comm)} facets), "
        f"{case.pair.rule} rule of degree {case.pair.quadrature_degree}, {problem.pair.basis} pressure basis"
        + (f", {case.friction.describe()} on the relative slip" if case.friction is not None else ", frictionless")
    )
    refusal = _pair_ms_refusal(case, problem, options.hybrid.layers)
    if options.method == "primal-ms" and refusal is not None:
        raise refusal
    notes = [f"{m} can run" if m != "primal-ms" or refusal is None else f"{m} cannot ({refusal})" for m in PAIR_METHODS]
    say("  methods: " + "; ".join(notes))
    if case.coarse_size is not None and refusal is None:
        say(f"  primal-ms: coarse squares of side {case.coarse_size:g} in each bulk")
    say(f"ok: a run with --method {options.method} can start ({case.description_or_name})")
    return 0


def _pair_ms_refusal(case: PairCase, problem, layers: int) -> InputError | None:
    """Why ``primal-ms`` cannot run the two-body case (as ``cli.pair`` would say, then the run's bulk checks of
    ``multiscale.pair.bulk_meshes`` on the strips of ``layers`` cell layers), or None (collective)."""
    if case.coarse_size is None:
        return InputError("--method primal-ms needs the coarse size: give mesh.coarse-size or mesh.H")
    try:
        check_coarse_size(problem, case.coarse_size)
        serial = problem if problem.comm.size == 1 else PairReplica(problem).problem  # as the run: serial bulks
        bulk_meshes(serial, strip_cells(serial, layers), case.coarse_size, layers)
    except InputError as error:
        return error
    return None


def _owned(found: np.ndarray, n_owned: int, comm: MPI.Comm) -> int:
    return comm.allreduce(int(np.count_nonzero(found < n_owned)), op=MPI.SUM)


def _role(name: str, dim: int, materials: set[str], built: bool, options: RunOptions, tdim: int = 2) -> str:
    """What the physical group ``name`` of dimension ``dim`` is to the run on cells of dimension ``tdim``."""
    if name in _ROLES:
        return _ROLES[name]
    if dim == tdim - 1 and is_neumann_name(name):
        return f"{name}: a traction boundary Γ_N"
    if dim == tdim and name in materials:
        return "a material group of the case"
    if dim == tdim and built and options.coarse_groups:
        return "a coarse cell (--coarse-groups)"
    if dim == tdim:
        return "cells (no role)"
    return "no role (ignored)"


def _file_groups(path: Path, comm: MPI.Comm) -> list[tuple[str, int, int]] | None:
    """(name, dimension, elements) of every physical group of a gmsh file (None when gmsh cannot read it: the
    run's reader says why). Collective."""

    def groups() -> list[tuple[str, int, int]]:
        found = []
        for dim, tag in gmsh.model.getPhysicalGroups():
            count = sum(
                len(elements)
                for entity in gmsh.model.getEntitiesForPhysicalGroup(dim, tag)
                for elements in gmsh.model.mesh.getElements(dim, entity)[1]
            )
            found.append((gmsh.model.getPhysicalName(dim, tag) or f"(unnamed {tag})", dim, count))
        return sorted(found, key=lambda g: (-g[1], g[0]))

    return query_gmsh_file(path, comm, groups, None)


def _printer(comm: MPI.Comm):
    lost = []

    def say(line: str) -> None:
        if comm.rank == 0 and not lost:
            try:
                print(line, flush=True)
            except OSError as error:  # a closed pipe (| head), a full device: the report stops there
                lost.append(error)
                stdout_lost(error)

    return say
