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
from fenics_contact.problem.tags import PHYSICAL_NAMES, Boundary, Subdomain, is_neumann_name, neumann_tag

__all__ = [
    "ContactMesh", "unit_square", "read_mesh", "gmsh_session", "build_unit_square_model", "contact_mesh_from_model",
    "boundary_group_overlaps",
]

log = logging.getLogger(__name__)


class ContactMesh(NamedTuple):
    """A tagged mesh: cell tags Ω₁/Ω₂, facet tags Γ_D/Γ_C/γ, sizes and coarse grid."""

    mesh: dmesh.Mesh
    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags
    h: float  #: fine mesh size (largest cell diameter for a user mesh)
    H: float | None  #: coarse size / strip width (None when unknown)
    coarse_cell: np.ndarray  #: coarse-square index of every local cell (-1 if no coarse grid)
    neumann_names: dict | None = None  #: traction-group tag -> physical name (Gamma_N*)

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
    with gmsh_session():
        if comm.rank == 0:
            build_unit_square_model(n, n_coarse, diagonal=diagonal, clamped=clamped, neumann=neumann)
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    cm = _contact_mesh(data, h=1.0 / n, H=1.0 / n_coarse)
    return cm


def contact_mesh_from_model(comm: MPI.Comm, *, h: float, H: float | None = None) -> ContactMesh:
    """The ContactMesh of the gmsh model built (on rank 0) in the current gmsh session (collective)."""
    data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    return _contact_mesh(data, h=h, H=H)


def read_mesh(path: str | Path, *, comm: MPI.Comm = MPI.COMM_WORLD, H: float | None = None) -> ContactMesh:
    """Load a gmsh ``.msh`` file whose physical groups carry the names of ``tags.PHYSICAL_NAMES``.

    Tags are matched by physical *name*, so any integers may be used in the file.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"mesh file {path} does not exist")
    with gmsh_session():
        names = None
        if comm.rank == 0:
            gmsh.model.add("user mesh")
            gmsh.merge(str(path))
            names = {gmsh.model.getPhysicalName(d, t) for d, t in gmsh.model.getPhysicalGroups()}
            overlap = boundary_group_overlaps()
        else:
            overlap = None
        names, overlap = comm.bcast((names, overlap), root=0)
        if overlap:
            raise MeshTagError(f"{path}: {overlap}")
        # validate before the collective mesh construction (which aborts on inconsistent tags)
        missing = [name for name in PHYSICAL_NAMES.values() if name not in names]
        if missing:
            raise MeshTagError(
                f"{path} lacks the physical group(s) {missing}; it has {sorted(names)}. "
                f"Required names: {list(PHYSICAL_NAMES.values())}"
            )
        data = dolfinx.io.gmsh.model_to_mesh(gmsh.model, comm, 0, gdim=2)
    msh = data.mesh
    tdim = msh.topology.dim
    cells = np.arange(msh.topology.index_map(tdim).size_local, dtype=np.int32)
    h = msh.comm.allreduce(float(np.max(msh.h(tdim, cells))) if cells.size else 0.0, op=MPI.MAX)
    return _contact_mesh(data, h=h, H=H)


def boundary_group_overlaps() -> str | None:
    """In the current gmsh model: a message if two boundary groups (Gamma_D, Gamma_C, gamma, Gamma_N*) share a curve."""
    standard = {PHYSICAL_NAMES[t] for t in Boundary}
    curves: dict[str, set[int]] = {}
    for dim, tag in gmsh.model.getPhysicalGroups(1):
        name = gmsh.model.getPhysicalName(dim, tag)
        if name in standard or is_neumann_name(name):
            curves.setdefault(name, set()).update(int(c) for c in gmsh.model.getEntitiesForPhysicalGroup(dim, tag))
    names = sorted(curves)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            shared = curves[a] & curves[b]
            if shared:
                return (
                    f"the physical groups {a!r} and {b!r} overlap (curves {sorted(shared)}): a boundary facet "
                    "belongs to one group only"
                )
    return None


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
    if H is not None:
        n_coarse = int(round(1.0 / H))
        mid = dmesh.compute_midpoints(msh, tdim, np.arange(num_cells, dtype=np.int32))
        i = np.clip(np.floor(mid[:, 0] / H).astype(np.int32), 0, n_coarse - 1)
        j = np.clip(np.floor(mid[:, 1] / H).astype(np.int32), 0, n_coarse - 1)
        coarse = i + n_coarse * j
    neumann = {neumann_tag(name): name for name, g in data.physical_groups.items()
               if g.dim == tdim - 1 and is_neumann_name(name)}
    return ContactMesh(msh, cell_tags, facet_tags, float(h), H, coarse, neumann)
