"""Coarse partitions of a fine mesh (multiscale methods) and the automatic contact strip Ω₂.

The multiscale methods need every fine cell of Ω₁ in one coarse cell K
(``ContactMesh.coarse_cell``). Two sources, on any domain:

* **A Cartesian grid over the bounding box** (``cartesian_coarse_cells``): squares of side H
  anchored at the smallest vertex coordinates; a fine cell gets the square that contains it,
  or −1 when it straddles a grid line (the fine mesh does not resolve the grid there). The
  multiscale methods refuse −1 cells in Ω₁ with an InputError.
* **A partition given by the user**: in a gmsh file, every 2D physical group other than
  ``Omega1``/``Omega2`` is one coarse cell (``read_mesh`` reads them, ``group_coarse_cells``).

When a mesh does not tag Ω₁, Ω₂ and γ, ``contact_strip`` builds them: Ω₂ is the set of coarse
cells that hold a cell with a facet on Γ_C (one coarse layer along the contact boundary, as in
the paper), Ω₁ the rest, and γ the facets between the two.
"""

import numpy as np
from mpi4py import MPI

import basix.ufl
from dolfinx import fem
from dolfinx import mesh as dmesh

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = ["cartesian_coarse_cells", "centroid_coarse_cells", "group_coarse_cells", "contact_strip", "coarse_sizes", "UNRESOLVED"]

#: coarse index of a fine cell that lies in no coarse cell (straddles a line of the Cartesian grid)
UNRESOLVED = -1


def _local_cells(msh: dmesh.Mesh) -> np.ndarray:
    imap = msh.topology.index_map(msh.topology.dim)
    return np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)


def _cell_vertices(msh: dmesh.Mesh, cells: np.ndarray) -> np.ndarray:
    """(cells, 3, 2) vertex coordinates."""
    geo = dmesh.entities_to_geometry(msh, msh.topology.dim, cells)
    return msh.geometry.x[geo][:, :, :2]


def _bounding_grid(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, int, int]:
    """(lower-left corner, columns nx, rows ny) of the grid of squares of side H over the mesh's bounding box
    (collective; InputError for an H that is not a positive number)."""
    if not (isinstance(H, (int, float, np.floating)) and np.isfinite(H) and H > 0):
        raise InputError(f"the coarse size H must be a positive number, got {H!r}")
    comm = msh.comm
    x = msh.geometry.x[:, :2]
    lo, hi = np.empty(2), np.empty(2)
    comm.Allreduce(x.min(axis=0) if x.size else np.full(2, np.inf), lo, op=MPI.MIN)
    comm.Allreduce(x.max(axis=0) if x.size else np.full(2, -np.inf), hi, op=MPI.MAX)
    nx = max(1, int(np.ceil((hi[0] - lo[0]) / H - 1e-9)))
    ny = max(1, int(np.ceil((hi[1] - lo[1]) / H - 1e-9)))
    return lo, nx, ny


def cartesian_coarse_cells(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, int]:
    """(coarse index of every local cell, number of columns nx) for the grid of squares of side H over the
    bounding box; index i + nx·j, or ``UNRESOLVED`` for a cell not inside one square (collective)."""
    lo, nx, _ = _bounding_grid(msh, H)
    cells = _local_cells(msh)
    if cells.size == 0:
        return np.zeros(0, dtype=np.int64), nx
    p = (_cell_vertices(msh, cells) - lo) / H
    tol = 1e-8
    ij_lo = np.floor(p.min(axis=1) + tol).astype(np.int64)
    ij_hi = np.floor(p.max(axis=1) - tol).astype(np.int64)
    index = ij_lo[:, 0] + nx * ij_lo[:, 1]
    index[np.any(ij_lo != ij_hi, axis=1)] = UNRESOLVED
    return index, nx


def centroid_coarse_cells(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, int]:
    """(coarse index of every local cell, nx): the square of side H (grid over the bounding box, as
    ``cartesian_coarse_cells``) that holds the cell's centroid.  Every cell gets a coarse cell, also on
    an unstructured mesh that does not resolve the grid lines: the coarse cells are then unions of fine
    cells with jagged boundaries, which the multiscale methods accept as any partition (collective)."""
    lo, nx, ny = _bounding_grid(msh, H)
    cells = _local_cells(msh)
    if cells.size == 0:
        return np.zeros(0, dtype=np.int64), nx
    ij = np.floor((_cell_vertices(msh, cells).mean(axis=1) - lo) / H).astype(np.int64)
    ij = np.minimum(np.maximum(ij, 0), [nx - 1, ny - 1])
    return ij[:, 0] + nx * ij[:, 1], nx


def group_coarse_cells(msh: dmesh.Mesh, cell_tags: dmesh.MeshTags, tags: list[int]) -> np.ndarray:
    """Coarse index of every local cell (owned and ghost) from cell tags: the cells of ``tags[k]`` are K_k;
    cells with another tag get ``UNRESOLVED``."""
    cells = _local_cells(msh)
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    Q = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 0))
    index = fem.Function(Q)
    index.x.array[:] = UNRESOLVED
    for k, tag in enumerate(tags):
        found = cell_tags.find(int(tag))
        index.x.array[Q.dofmap.list[found[found < n_owned], 0]] = k
    index.x.scatter_forward()  # ghost cells get the owner's value
    return np.rint(index.x.array[Q.dofmap.list[cells, 0]]).astype(np.int64)


def coarse_sizes(msh: dmesh.Mesh, coarse_cell: np.ndarray) -> np.ndarray:
    """√|K| of every coarse cell (index = coarse number; summed over the owned cells of all ranks)."""
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    cells = np.arange(n_owned, dtype=np.int32)
    p = _cell_vertices(msh, cells)
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    area = 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    idx = np.asarray(coarse_cell)[:n_owned]
    n = msh.comm.allreduce(int(idx.max()) + 1 if idx.size else 0, op=MPI.MAX)
    ok = idx >= 0
    local = np.bincount(idx[ok], weights=area[ok], minlength=n).astype(np.float64)
    total = np.empty_like(local)
    msh.comm.Allreduce(local, total, op=MPI.SUM)
    return np.sqrt(total)


def contact_strip(
    msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, coarse_cell: np.ndarray
) -> tuple[dmesh.MeshTags, dmesh.MeshTags]:
    """(cell tags Ω₁/Ω₂, facet tags + γ): Ω₂ = the coarse cells holding a cell with a facet on Γ_C.

    ``facet_tags`` must tag Γ_C (``Boundary.GAMMA_C``); the returned facet tags are those
    given plus the γ facets (between a cell of Ω₁ and a cell of Ω₂). Collective.
    """
    comm = msh.comm
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    coarse_cell = np.asarray(coarse_cell)
    contact = facet_tags.find(Boundary.GAMMA_C)
    if comm.allreduce(contact.size, op=MPI.SUM) == 0:
        raise MeshTagError("the contact strip Ω₂ is built along Γ_C, but the mesh has no Gamma_C facets")
    touching = np.unique(f2c.array[f2c.offsets[contact]])  # exterior facets: one cell each
    strip_local = coarse_cell[touching]
    if np.any(strip_local < 0):
        raise InputError(
            "cannot build the contact strip Ω₂: some cells along Γ_C lie in no coarse cell (the fine mesh does not "
            "resolve the coarse grid there); give a coarse partition, another H, or tag Omega1/Omega2/gamma"
        )
    strip = np.unique(np.concatenate(comm.allgather(np.unique(strip_local))))
    cells = _local_cells(msh)
    in_strip = np.isin(coarse_cell[cells], strip)
    n_total = comm.allreduce(msh.topology.index_map(tdim).size_local, op=MPI.SUM)
    n_strip = comm.allreduce(int(np.count_nonzero(in_strip[: msh.topology.index_map(tdim).size_local])),
                             op=MPI.SUM)
    if n_strip == n_total:
        raise InputError("the contact strip Ω₂ (the coarse cells along Γ_C) is the whole domain: use a finer "
                         "coarse grid (smaller H) or more coarse cells")
    values = np.where(in_strip, int(Subdomain.OMEGA2), int(Subdomain.OMEGA1)).astype(np.int32)
    cell_tags = dmesh.meshtags(msh, tdim, cells, values)
    # γ: facets with one cell on each side of the strip boundary
    num_facets = msh.topology.index_map(tdim - 1).size_local + msh.topology.index_map(tdim - 1).num_ghosts
    offsets = f2c.offsets
    two = np.flatnonzero(np.diff(offsets)[:num_facets] == 2)
    c0 = f2c.array[offsets[two]]
    c1 = f2c.array[offsets[two] + 1]
    gamma = two[in_strip[c0] != in_strip[c1]].astype(np.int32)
    if comm.allreduce(gamma.size, op=MPI.SUM) == 0:
        raise InputError("the contact strip Ω₂ has no interface γ with Ω₁")
    keep = ~np.isin(facet_tags.indices, gamma)
    entities = np.concatenate([facet_tags.indices[keep], gamma])
    tag_values = np.concatenate([facet_tags.values[keep], np.full(gamma.size, int(Boundary.INTERFACE), np.int32)])
    order = np.argsort(entities, kind="stable")
    return cell_tags, dmesh.meshtags(msh, tdim - 1, entities[order].astype(np.int32),
                                     tag_values[order].astype(np.int32))
