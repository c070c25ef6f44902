"""Meshes with the tags the hybrid method needs (Ω₁, Ω₂, Γ_D, Γ_C, γ).

``unit_square`` builds, with gmsh, the structured triangulation of (0,1)² with
fine size h = 1/n whose coarse grid of squares of side H = 1/N is resolved
exactly (every coarse square is a union of 2(n/N)² fine triangles); Ω₂ is the
last coarse column (1−H, 1)×(0,1). ``read_mesh`` loads a user's gmsh model with
the same physical-group names (``tags.PHYSICAL_NAMES``).
"""

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import gmsh
import numpy as np
from mpi4py import MPI

import dolfinx
import dolfinx.io.gmsh
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain

__all__ = ["ContactMesh", "unit_square", "read_mesh", "gmsh_session", "build_unit_square_model"]

log = logging.getLogger(__name__)


class ContactMesh(NamedTuple):
    """A tagged mesh: cell tags Ω₁/Ω₂, facet tags Γ_D/Γ_C/γ, sizes and coarse grid."""

    mesh: dmesh.Mesh
    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags
    h: float  #: fine mesh size (largest cell diameter for a user mesh)
    H: float | None  #: coarse size / strip width (None when unknown)
    coarse_cell: np.ndarray  #: coarse-square index of every local cell (-1 if no coarse grid)

    @property
    def comm(self) -> MPI.Comm:
        """The mesh communicator."""
        return self.mesh.comm


@contextlib.contextmanager
def gmsh_session(*, verbosity: int = 0) -> Iterator[None]:
    """Initialise gmsh for the duration of a ``with`` block (no global state leaks)."""
    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(interruptible=False)
    gmsh.option.setNumber("General.Terminal", verbosity)
    try:
        yield
    finally:
        if started:
            gmsh.finalize()


def _check_sizes(n: int, n_coarse: int) -> None:
    if int(n) != n or n < 2:
        raise InputError(f"1/h must be an integer >= 2, got {n!r}")
    if int(n_coarse) != n_coarse or n_coarse < 2:
        raise InputError(
            f"1/H must be an integer >= 2 (the strip Ω₂ of width H must leave room for Ω₁), got {n_coarse!r}"
        )
    if n % n_coarse != 0:
        raise InputError(
            f"H = 1/{n_coarse} is not a multiple of h = 1/{n}: the coarse grid must be a union of fine cells"
        )


def build_unit_square_model(n: int, n_coarse: int, *, diagonal: str = "Right") -> None:
    """Create the structured, tagged gmsh model of the unit square in the current gmsh session."""
    _check_sizes(n, n_coarse)
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
    groups = {
        Subdomain.OMEGA1: (2, [s1]),
        Subdomain.OMEGA2: (2, [s2]),
        Boundary.GAMMA_D: (1, [bottom1, bottom2, top1, top2, left]),
        Boundary.GAMMA_C: (1, [contact]),
        Boundary.INTERFACE: (1, [interface]),
    }
    for tag, (dim, entities) in groups.items():
        gmsh.model.addPhysicalGroup(dim, entities, int(tag), name=PHYSICAL_NAMES[tag])
    gmsh.model.mesh.generate(2)


def unit_square(n: int, n_coarse: int, *, comm: MPI.Comm = MPI.COMM_WORLD, diagonal: str = "Right") -> ContactMesh:
    """Tagged structured mesh of (0,1)², h = 1/n, strip Ω₂ of width H = 1/n_coarse."""
    _check_sizes(n, n_coarse)
    with gmsh_session():
        if comm.rank == 0:
            build_unit_square_model(n, n_coarse, diagonal=diagonal)
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    cm = _contact_mesh(data, h=1.0 / n, H=1.0 / n_coarse)
    return cm


def read_mesh(path: str | Path, *, comm: MPI.Comm = MPI.COMM_WORLD, H: float | None = None) -> ContactMesh:
    """Load a gmsh ``.msh`` file whose physical groups carry the names of ``tags.PHYSICAL_NAMES``.

    Tags are matched by physical *name*, so any integers may be used in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"mesh file {path} does not exist")
    with gmsh_session():
        names, surfaces = None, 0
        if comm.rank == 0:
            gmsh.model.add("user mesh")
            gmsh.merge(str(path))
            names = {gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups()}
            surfaces = len(gmsh.model.getPhysicalGroups(2))
        names, surfaces = comm.bcast((names, surfaces), root=0)
        # validate before the collective mesh construction (which aborts on inconsistent tags)
        missing = [name for name in PHYSICAL_NAMES.values() if name not in names]
        strip = {PHYSICAL_NAMES[t] for t in (Subdomain.OMEGA1, Subdomain.OMEGA2, Boundary.INTERFACE)}
        # none of Ω₁/Ω₂/γ tagged: they are built along Γ_C from the coarse cells (problem.partition)
        auto_strip = set(missing) == strip and surfaces > 0
        if missing and not auto_strip:
            raise MeshTagError(
                f"{path} lacks the physical group(s) {missing}; it has {sorted(names)}. "
                f"Required names: {list(PHYSICAL_NAMES.values())}"
            )
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    msh = data.mesh
    tdim = msh.topology.dim
    cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int32)
    h = msh.comm.allreduce(float(np.max(msh.h(tdim, cells))) if cells.size else 0.0, op=MPI.MAX)
    if auto_strip:
        return _strip_contact_mesh(data, h=h, H=H, source=str(path))
    return _contact_mesh(data, h=h, H=H)


def _strip_contact_mesh(data: dolfinx.io.gmsh.MeshData, *, h: float, H: float | None, source: str) -> ContactMesh:
    """A mesh without Ω₁/Ω₂/γ: coarse cells from H (Cartesian grid over the bounding box) or from the 2D
    physical groups (the user's coarse partition), then Ω₂ = the coarse cells along Γ_C (problem.partition)."""
    from fenics_contact.problem import partition

    msh = data.mesh
    tdim = msh.topology.dim
    if msh.topology.cell_type != dmesh.CellType.triangle:
        raise InputError(f"fenics-contact needs a triangular mesh, got {msh.topology.cell_type.name}")
    msh.topology.create_connectivity(tdim - 1, tdim)
    facet_tags = _retag(data.facet_tags, data.physical_groups, [Boundary.GAMMA_D, Boundary.GAMMA_C], msh, tdim - 1)
    skip = {PHYSICAL_NAMES[Subdomain.OMEGA1], PHYSICAL_NAMES[Subdomain.OMEGA2]}
    groups = sorted(g.tag for name, g in data.physical_groups.items() if g.dim == tdim and name not in skip)
    if H is not None:
        coarse, _ = partition.cartesian_coarse_cells(msh, H)
    elif len(groups) >= 2:
        coarse = partition.group_coarse_cells(msh, data.cell_tags, groups)
        H = float(partition.coarse_sizes(msh, coarse).max())
    else:
        raise InputError(
            f"{source} tags neither Omega1/Omega2/gamma nor a coarse partition: give the coarse size H (the "
            "strip Ω₂ is then the squares of side H along Gamma_C) or split the domain into 2D physical groups "
            "(one per coarse cell)"
        )
    cell_tags, facet_tags = partition.contact_strip(msh, facet_tags, coarse)
    return ContactMesh(msh, cell_tags, facet_tags, float(h), H, coarse.astype(np.int32))


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
    entities = np.concatenate(entities)
    values = np.concatenate(values)
    order = np.argsort(entities, kind="stable")
    return dmesh.meshtags(msh, dim, entities[order], values[order])


def _contact_mesh(data: dolfinx.io.gmsh.MeshData, *, h: float, H: float | None) -> ContactMesh:
    msh = data.mesh
    tdim = msh.topology.dim
    if msh.topology.cell_type != dmesh.CellType.triangle:
        raise InputError(f"fenics-contact needs a triangular mesh, got {msh.topology.cell_type.name}")
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
        from fenics_contact.problem.partition import cartesian_coarse_cells

        coarse = cartesian_coarse_cells(msh, H)[0].astype(np.int32)
    return ContactMesh(msh, cell_tags, facet_tags, float(h), H, coarse)
