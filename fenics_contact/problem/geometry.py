"""Meshes with the tags the hybrid method needs (Ω₁, Ω₂, Γ_D, Γ_C, γ).

``unit_square`` builds, with gmsh, the structured triangulation of (0,1)² with
fine size h = 1/n whose coarse grid of squares of side H = 1/N is resolved
exactly (every coarse square is a union of 2(n/N)² fine triangles); Ω₂ is the
last coarse column (1−H, 1)×(0,1). ``read_mesh`` loads a user's gmsh model with
the same physical-group names (``tags.PHYSICAL_NAMES``), checked on its gmsh model before the
mesh is built (``gmsh_checks``).
"""

import contextlib
import logging
import os
import signal
import threading
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path
from typing import NamedTuple, TypeVar

import dolfinx
import dolfinx.io.gmsh
import gmsh
import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem import partition, strip, validation
from fenics_contact.problem.gmsh_checks import gmsh_model_problem, needs_strip
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, is_neumann_name, neumann_tag

__all__ = [
    "ContactMesh",
    "unit_square",
    "read_mesh",
    "mesh_size",
    "mesh_extent",
    "check_memory",
    "gmsh_session",
    "query_gmsh_file",
    "build_unit_square_model",
    "contact_mesh_from_model",
]

log = logging.getLogger(__name__)
T = TypeVar("T")

#: the cell types of a ContactMesh: triangles (plane problems) and tetrahedra (3D)
_CELL_TYPES = (dmesh.CellType.triangle, dmesh.CellType.tetrahedron)


class ContactMesh(NamedTuple):
    """A tagged mesh: cell tags Ω₁/Ω₂, facet tags Γ_D/Γ_C/γ, sizes and coarse grid."""

    mesh: dmesh.Mesh
    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags
    #: fine mesh size at Γ_C: 1/n, or ``mesh_size(mesh, facet_tags)`` (√(2·largest area of a cell on Γ_C)) for a user
    #: mesh
    h: float
    H: float | None  #: coarse size / strip width (None when unknown)
    coarse_cell: np.ndarray  #: coarse-square index of every local cell (-1 if no coarse grid)
    neumann_names: dict | None = None  #: traction-group tag -> physical name (Gamma_N*)
    #: True: the coarse cells are squares (cubes) of side H (the grid over the bounding box, or its squares that hold
    #: the cells' centroids); False: a partition of any other shape (``partition.graded_coarse_cells``, the user's
    #: groups), whose H is a size, not the side of every coarse cell
    coarse_grid: bool = True

    @property
    def comm(self) -> MPI.Comm:
        """The mesh communicator."""
        return self.mesh.comm


@contextlib.contextmanager
def gmsh_session(*, verbosity: int = 0) -> Iterator[None]:
    """Initialise gmsh for the duration of a ``with`` block (no global state leaks).

    gmsh's initialisation resets the SIGTERM disposition to the default (die at once); the
    Python handlers of SIGINT and SIGTERM are put back, so a run can still end cleanly.
    """
    started = not gmsh.isInitialized()
    handlers = _signal_handlers()
    if started:
        gmsh.initialize(interruptible=False)
        _restore_signal_handlers(handlers)
    gmsh.option.setNumber("General.Terminal", verbosity)
    try:
        yield
    finally:
        if started:
            gmsh.finalize()
            _restore_signal_handlers(handlers)


def query_gmsh_file(path: Path, comm: MPI.Comm, query: Callable[[], T], default: T) -> T:
    """Collective: ``query()`` on rank 0 with the gmsh file ``path`` merged into a fresh model, broadcast to every
    rank; ``default`` when the file is missing or gmsh cannot read it (the mesh reader then says why)."""
    result = default
    if comm.rank == 0 and Path(path).is_file():
        with gmsh_session():
            gmsh.model.add("query")
            try:
                gmsh.merge(str(path))
            except Exception:  # gmsh raises a bare Exception; read_mesh reports it
                pass
            else:
                result = query()
    return comm.bcast(result, root=0)


def _signal_handlers() -> dict:
    if threading.current_thread() is not threading.main_thread():
        return {}
    return {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}


def _restore_signal_handlers(handlers: dict) -> None:
    for s, handler in handlers.items():
        if handler is not None:
            signal.signal(s, handler)


def _check_sizes(n: int, n_coarse: int) -> None:
    if not _is_integral(n) or n < 2:
        raise InputError(f"1/h must be an integer >= 2, got {n!r}")
    if not _is_integral(n_coarse) or n_coarse < 2:
        raise InputError(
            f"1/H must be an integer >= 2 (the strip Ω₂ of width H must leave room for Ω₁), got {n_coarse!r}"
        )
    if n % n_coarse != 0:
        raise InputError(
            f"H = 1/{n_coarse} is not a multiple of h = 1/{n}: the coarse grid must be a union of fine cells"
        )


def _is_integral(value) -> bool:
    return isinstance(value, (int, float, np.integer, np.floating)) and np.isfinite(value) and int(value) == value


#: The sides of the unit square that may be clamped or carry a traction group (x = 1 is Γ_C).
SIDES = ("left", "bottom", "top")


def _check_sides(clamped, neumann) -> tuple[tuple[str, ...], dict[str, str]]:
    clamped = tuple(clamped)
    neumann = dict(neumann or {})
    for side in (*clamped, *neumann):
        if side not in SIDES:
            raise InputError(f"unknown side {side!r}: the unit square's sides are {SIDES} (x = 1 is Gamma_C)")
    both = sorted(set(clamped) & set(neumann))
    if both:
        raise InputError(f"side(s) {both} cannot be clamped (Gamma_D) and carry a traction group (Gamma_N) at once")
    for name in neumann.values():
        neumann_tag(name)  # validates the name
    return clamped, neumann


def build_unit_square_model(
    n: int, n_coarse: int, *, diagonal: str = "Right", clamped=SIDES, neumann: dict[str, str] | None = None
) -> None:
    """Create the structured, tagged gmsh model of the unit square in the current gmsh session.

    ``clamped``: the sides in Γ_D; ``neumann``: side -> traction group name (``Gamma_N*``);
    other sides are traction free (untagged).
    """
    _check_sizes(n, n_coarse)
    clamped, neumann = _check_sides(clamped, neumann)
    n, n_coarse = int(n), int(n_coarse)
    check_memory((n + 1.0) ** 2, f"the unit square with h = 1/{n}")
    H = 1.0 / n_coarse
    xs = 1.0 - H
    geo = gmsh.model.geo
    gmsh.model.add("unit_square")
    p = [geo.addPoint(x, y, 0.0) for x, y in [(0, 0), (xs, 0), (1, 0), (1, 1), (xs, 1), (0, 1)]]
    bottom1, bottom2 = geo.addLine(p[0], p[1]), geo.addLine(p[1], p[2])
    contact = geo.addLine(p[2], p[3])
    top2, top1 = geo.addLine(p[3], p[4]), geo.addLine(p[4], p[5])
    left = geo.addLine(p[5], p[0])
    interface = geo.addLine(p[1], p[4])
    s1 = geo.addPlaneSurface([geo.addCurveLoop([bottom1, interface, top1, left])])
    s2 = geo.addPlaneSurface([geo.addCurveLoop([bottom2, contact, top2, -interface])])
    geo.synchronize()
    n1, n2 = n - n // n_coarse, n // n_coarse
    for curve, cells in [(bottom1, n1), (top1, n1), (bottom2, n2), (top2, n2), (left, n), (contact, n), (interface, n)]:
        gmsh.model.mesh.setTransfiniteCurve(curve, cells + 1)
    for s in (s1, s2):
        gmsh.model.mesh.setTransfiniteSurface(s, diagonal)
    side_curves = {"left": [left], "bottom": [bottom1, bottom2], "top": [top1, top2]}
    groups = {
        Subdomain.OMEGA1: (2, [s1]),
        Subdomain.OMEGA2: (2, [s2]),
        Boundary.GAMMA_D: (1, [c for side in clamped for c in side_curves[side]]),
        Boundary.GAMMA_C: (1, [contact]),
        Boundary.INTERFACE: (1, [interface]),
    }
    for tag, (dim, entities) in groups.items():
        if entities:
            gmsh.model.addPhysicalGroup(dim, entities, int(tag), name=PHYSICAL_NAMES[tag])
    by_name: dict[str, list[int]] = {}
    for side, name in neumann.items():
        by_name.setdefault(name, []).extend(side_curves[side])
    for name, curves in sorted(by_name.items()):
        gmsh.model.addPhysicalGroup(1, curves, neumann_tag(name), name=name)
    gmsh.model.mesh.generate(2)


#: memory per mesh vertex of a primal run (Algorithm 1 on the bar, h = 1/256: 0.82 GB peak for 66,049 vertices,
#: ``/usr/bin/time -v fenics-contact run --case cases/bar.toml --set mesh.h=256 --no-plots``); the mixed and
#: multiscale methods need more
BYTES_PER_VERTEX = 8.0e3


def check_memory(vertices: float, what: str, bytes_per_vertex: float = BYTES_PER_VERTEX) -> None:
    """InputError when a mesh of about ``vertices`` vertices would need more memory than this machine has (by
    ``bytes_per_vertex``, a primal run's by default), before gmsh runs out of memory making it."""
    try:
        available = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return
    need = vertices * bytes_per_vertex
    if need > available:
        raise InputError(
            f"{what} has about {vertices:.3g} vertices and would need about {need / 1e9:.3g} GB of "
            f"memory; this machine has {available / 1e9:.3g} GB: choose a coarser mesh"
        )


def unit_square(
    n: int,
    n_coarse: int,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    diagonal: str = "Right",
    clamped=SIDES,
    neumann: dict[str, str] | None = None,
) -> ContactMesh:
    """Tagged structured mesh of (0,1)², h = 1/n, strip Ω₂ of width H = 1/n_coarse.

    Γ_C is the side x = 1; ``clamped`` lists the sides in Γ_D (default all three others),
    ``neumann`` maps sides to traction group names (e.g. ``{"top": "Gamma_N_top"}``);
    the remaining sides are traction free.
    """
    _check_sizes(n, n_coarse)
    clamped, neumann = _check_sides(clamped, neumann)
    n, n_coarse = int(n), int(n_coarse)
    check_memory((n + 1.0) ** 2, f"the unit square with h = 1/{n}")
    with gmsh_session():
        if comm.rank == 0:
            build_unit_square_model(n, n_coarse, diagonal=diagonal, clamped=clamped, neumann=neumann)
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    cm = _contact_mesh(data, h=1.0 / n, H=1.0 / n_coarse)
    return cm


def contact_mesh_from_model(comm: MPI.Comm, *, h: float, H: float | None = None, gdim: int = 2) -> ContactMesh:
    """The ContactMesh of the gmsh model built (on rank 0) in the current gmsh session (collective); ``gdim`` 3
    for a model of tetrahedra."""
    data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=gdim)
    return _contact_mesh(data, h=h, H=H)


def read_mesh(
    path: str | Path,
    *,
    comm: MPI.Comm = MPI.COMM_WORLD,
    H: float | None = None,
    validate: bool = True,
    rules: Iterable[validation.BoundaryRule] = validation.BOUNDARY_RULES,
    overlay_groups: Iterable[str] = (),
) -> ContactMesh:
    """Load a gmsh ``.msh`` file whose physical groups carry the names of ``tags.PHYSICAL_NAMES``.

    Tags are matched by physical *name*, so any integers may be used in the file. The file
    must hold a planar (z = 0) mesh of 3-node triangles, or a 3D mesh of 4-node tetrahedra (then Omega1
    and Omega2 are volume groups and the boundary groups surfaces); anything else is an InputError, raised
    before the mesh is built. With ``validate`` the tags are then checked against the contact
    problem (``validation.validate_contact_mesh`` with ``rules``: γ the common boundary of Ω₁
    and Ω₂, Γ_C on ∂Ω₂ away from γ, Γ_D and Γ_C disjoint, a conforming mesh), a MeshTagError
    naming the group otherwise. ``h`` of the result is the mesh size ``mesh_size`` (1/n on the
    built-in meshes), ``H`` the side of the coarse grid of squares over the bounding box (multiscale
    methods; a fine cell that straddles a grid line lies in no coarse cell); on a mesh of tetrahedra the coarse
    cells are the cubes of side H that hold the Ω₁ cells' centroids (``strip.omega1_coarse_cells``: the cubes
    themselves where the mesh resolves them, unions of whole tetrahedra with jagged faces elsewhere).
    ``overlay_groups``: surface groups that overlay Omega1/Omega2 (materials by group, read with
    ``problem.cell_groups.read_cell_groups``); they are left out of the mesh and its checks.

    A file that tags none of Omega1, Omega2 and gamma (only Gamma_D, Gamma_C, Gamma_N* and surface
    groups of any names) gets them built (``problem.strip``, rules in ``_strip_contact_mesh``): Ω₂ = a strip
    along Γ_C of width ``H`` (on any mesh), or, with ``H=None``, the coarse cells along Γ_C of the surface
    groups that are not ``overlay_groups`` (the user's coarse partition), or a band of a few cells. The
    overlay (material) groups are then the cells' groups of the file and stay in the mesh.
    """
    path = Path(path)
    overlay_groups = set(overlay_groups)
    if H is not None and not (isinstance(H, (int, float)) and np.isfinite(H) and H > 0):
        raise InputError(
            f"the coarse size H must be a positive number (the side of the coarse squares over the "
            f"bounding box), got {H!r}"
        )
    if not path.is_file():
        raise InputError(f"mesh file {path} does not exist" if not path.exists() else f"mesh file {path} is not a file")
    with gmsh_session():
        problem, auto_strip, tdim = None, False, 2
        if comm.rank == 0:
            gmsh.model.add("user mesh")
            try:
                gmsh.merge(str(path))
            except Exception as err:  # gmsh raises a bare Exception with its parser's message
                problem = (InputError, f"cannot read {path} as a gmsh mesh: {err}")
            else:
                tdim = 3 if len(gmsh.model.mesh.getElementTypes(3)) else 2
                auto_strip = needs_strip(tdim)
                if not auto_strip:  # overlays: read separately, not cell tags (with the automatic strip they are
                    for dim, tag in gmsh.model.getPhysicalGroups(tdim):  # the cells' groups: kept)
                        if gmsh.model.getPhysicalName(dim, tag) in overlay_groups:
                            gmsh.model.removePhysicalGroups([(dim, tag)])
                problem = gmsh_model_problem(path, auto_strip=auto_strip)
        problem, auto_strip, tdim = comm.bcast((problem, auto_strip, tdim), root=0)
        # validate before the collective mesh construction (which aborts on inconsistent tags)
        if problem is not None:
            error, message = problem
            raise error(message)
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=tdim)
    if auto_strip:
        cm = _strip_contact_mesh(data, h=mesh_size(data.mesh), H=H, materials=overlay_groups)
    else:
        cm = _contact_mesh(data, h=mesh_size(data.mesh), H=H)
        if H is not None and tdim == 3:  # the cubes of side H that hold the Ω₁ cells' centroids (any tetrahedra)
            cm = cm._replace(coarse_cell=strip.omega1_coarse_cells(cm.mesh, cm.cell_tags, H))
    if cm.comm.allreduce(int(np.count_nonzero(cm.facet_tags.values == Boundary.GAMMA_C)), op=MPI.SUM):
        cm = cm._replace(h=mesh_size(cm.mesh, cm.facet_tags))
    if validate:
        validation.validate_contact_mesh(cm, rules, source=str(path))
    return cm


def _strip_contact_mesh(
    data: dolfinx.io.gmsh.MeshData, *, h: float, H: float | None, materials: Iterable[str] = ()
) -> ContactMesh:
    """A mesh without Ω₁/Ω₂/γ gets them built (``strip.automatic_split``): with ``H``, a strip of width H
    along Γ_C; without, the surface groups that are not ``materials`` as the coarse cells (two or more: the
    user's partition) or a band of a few cells."""
    msh = data.mesh
    tdim = msh.topology.dim
    if msh.topology.cell_type not in _CELL_TYPES:
        raise InputError(f"fenics-contact needs a mesh of triangles or tetrahedra, got {msh.topology.cell_type.name}")
    msh.topology.create_connectivity(tdim - 1, tdim)
    facet_tags = _retag(data.facet_tags, data.physical_groups, [Boundary.GAMMA_D, Boundary.GAMMA_C], msh, tdim - 1)
    skip = {PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2], *materials}
    groups = sorted(g.tag for name, g in data.physical_groups.items() if g.dim == tdim and name not in skip)
    user_partition = (
        partition.group_coarse_cells(msh, data.cell_tags, groups) if H is None and len(groups) >= 2 else None
    )
    split = strip.automatic_split(msh, facet_tags, H=H, partition=user_partition)
    return ContactMesh(
        msh,
        split.cell_tags,
        split.facet_tags,
        float(h),
        split.H,
        split.coarse_cell,
        _neumann_names(data),
        split.coarse_grid,
    )


def mesh_size(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags | None = None) -> float:
    """h = max over the cells of √(2|T|): the leg of the right isosceles triangle of the largest cell's area (in 3D
    (6|T|)^(1/3), the edge of the cube of which the largest tetrahedron is a sixth); with
    ``facet_tags``, over the cells with a facet on Γ_C only (the contact cell size, which sets the default
    penalties δ, ε and the Robin coefficient α, so a mesh graded towards Γ_C gets the penalties of its contact
    cells, not of its largest cell far away).

    On the built-in meshes (squares of side 1/n cut in two) this is 1/n, so a user mesh of the same
    grid gets the same h, and with it the same default penalty δ and Robin coefficient α.
    """
    tdim = msh.topology.dim
    cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int32)
    if facet_tags is not None:
        touching = strip.contact_cells(msh, facet_tags)
        cells = touching[touching < cells.size]
    geo = dmesh.entities_to_geometry(msh, tdim, cells)
    if tdim == 3:  # (6|T|)^(1/3): the edge of the cube of which the largest tetrahedron is a sixth
        x = msh.geometry.x[geo]
        volume = np.abs(np.linalg.det(x[:, 1:] - x[:, :1])) / 6.0
        return msh.comm.allreduce(float(np.cbrt(6.0 * volume.max())) if volume.size else 0.0, op=MPI.MAX)
    x = msh.geometry.x[geo][:, :, :2]
    d1, d2 = x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]
    area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    return msh.comm.allreduce(float(np.sqrt(2.0 * area.max())) if area.size else 0.0, op=MPI.MAX)


def mesh_extent(msh: dmesh.Mesh) -> float:
    """L_ref = the largest side of the mesh's bounding box (over all ranks; collective): the body's size.

    The reference length of the length-dependent defaults (ε, α, β, the equilibration of the mixed solves):
    1 on the unit square, and a mesh scaled by s has s·L_ref, so the defaults give the same relative answers
    whatever the unit of length.
    """
    x = msh.geometry.x
    lo, hi = np.min(x, axis=0, initial=np.inf), np.max(x, axis=0, initial=-np.inf)
    msh.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
    msh.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
    return float(np.max(hi - lo))


def _retag(tags: dmesh.MeshTags | None, groups: dict, wanted: list, msh: dmesh.Mesh, dim: int) -> dmesh.MeshTags:
    """Re-number the tags named in ``wanted`` to this package's integers (matched by name)."""
    missing = [PHYSICAL_NAMES[t] for t in wanted if PHYSICAL_NAMES[t] not in groups]
    if tags is None or missing:
        present = sorted(groups)
        raise MeshTagError(
            f"the mesh lacks the physical group(s) {missing or [PHYSICAL_NAMES[t] for t in wanted]} "
            f"(dimension {dim}); it has {present}. Required names: {[PHYSICAL_NAMES[t] for t in wanted]}"
        )
    entities, values = [], []
    for t in wanted:
        file_tag = groups[PHYSICAL_NAMES[t]].tag
        found = tags.find(file_tag)
        entities.append(found)
        values.append(np.full(found.size, int(t), dtype=np.int32))
    for name, group in groups.items():  # traction groups Gamma_N*: tag = neumann_tag(name)
        if dim == msh.topology.dim - 1 and group.dim == dim and is_neumann_name(name):
            found = tags.find(group.tag)
            entities.append(found)
            values.append(np.full(found.size, neumann_tag(name), dtype=np.int32))
    entities = np.concatenate(entities)
    values = np.concatenate(values)
    order = np.argsort(entities, kind="stable")
    return dmesh.meshtags(msh, dim, entities[order], values[order])


def _contact_mesh(data: dolfinx.io.gmsh.MeshData, *, h: float, H: float | None) -> ContactMesh:
    msh = data.mesh
    tdim = msh.topology.dim
    if msh.topology.cell_type not in _CELL_TYPES:
        raise InputError(f"fenics-contact needs a mesh of triangles or tetrahedra, got {msh.topology.cell_type.name}")
    msh.topology.create_connectivity(tdim - 1, tdim)
    cell_tags = _retag(data.cell_tags, data.physical_groups, [Subdomain.OMEGA1, Subdomain.OMEGA2], msh, tdim)
    facet_tags = _retag(
        data.facet_tags, data.physical_groups, [Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE], msh, tdim - 1
    )
    for tags, members in [(cell_tags, list(Subdomain)), (facet_tags, list(Boundary))]:
        for t in members:
            if msh.comm.allreduce(tags.find(t).size, op=MPI.SUM) == 0:
                raise MeshTagError(f"the physical group {PHYSICAL_NAMES[t]!r} is empty")
    num_cells = msh.topology.index_map(tdim).size_local + msh.topology.index_map(tdim).num_ghosts
    coarse = np.full(num_cells, -1, dtype=np.int32)
    if H is not None:  # squares of side H over the bounding box; -1 where a cell straddles a grid line
        coarse = partition.cartesian_coarse_cells(msh, H)[0].astype(np.int32)
    return ContactMesh(msh, cell_tags, facet_tags, float(h), H, coarse, _neumann_names(data))


def _neumann_names(data: dolfinx.io.gmsh.MeshData) -> dict[int, str]:
    """Traction-group tag -> physical name (Gamma_N*) of the mesh data."""
    tdim = data.mesh.topology.dim
    return {
        neumann_tag(name): name
        for name, g in data.physical_groups.items()
        if g.dim == tdim - 1 and is_neumann_name(name)
    }
