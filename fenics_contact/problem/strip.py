"""The contact strip Ω₂, the interface γ and the coarse cells of Ω₁, built from the physics tags alone.

A user describes the body (its mesh, Γ_C, Γ_D, tractions); the hybrid method needs more: the
thin strip Ω₂ along Γ_C where the contact nonlinearity lives, the rest Ω₁, the interface γ
between them and, for the multiscale methods, a partition of Ω₁ into coarse cells. On any
mesh (structured or not, any materials, any shape of Γ_C):

* **Ω₂** (``band_cells``) is the band of cells whose centroid lies within ``width`` of Γ_C
  (and every cell with a facet on Γ_C). With ``width`` at least a cell and a half, no node of
  Γ_C lies on γ, and the band reaches past the ends of Γ_C by about ``width``.
* **γ** is the set of facets between a cell of Ω₁ and a cell of Ω₂ (``strip_tags``).
* **coarse cells** (``coarse_partition``): the squares of side H over the bounding box that hold
  the cells' centroids (``partition.centroid_coarse_cells``: jagged coarse cells on an unstructured
  mesh), restricted to Ω₁; a piece that γ cuts down to less than ``SLIVER`` of a full coarse
  cell is merged into the neighbour it shares most facets with, so that no local problem of the
  multiscale methods is built on a sliver.

The distance to Γ_C is measured to points sampled on its facets (vertices, midpoints and a
lattice of interior points), within an eighth of the facet size: the band is a band of cells,
so that is exact enough. Everything is collective and rank-independent: every rank holds the
sampled Γ_C points and decides its own and its ghost cells the same way.
"""

from typing import NamedTuple

import numpy as np
from dolfinx import mesh as dmesh
from mpi4py import MPI
from scipy.spatial import cKDTree

from fenics_contact.errors import InputError, MeshTagError
from fenics_contact.problem.partition import UNRESOLVED, cartesian_coarse_cells, centroid_coarse_cells, coarse_sizes
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = [
    "Split",
    "automatic_split",
    "SLIVER",
    "DEFAULT_WIDTH_CELLS",
    "band_cells",
    "coarse_strip",
    "strip_tags",
    "coarse_partition",
    "omega1_coarse_cells",
    "contact_cell_size",
    "contact_cells",
]

#: a coarse piece of Ω₁ with fewer cells than this fraction of the median coarse cell is merged into a neighbour
SLIVER = 0.3
#: the default width of Ω₂ without a coarse size: this many times the largest cell touching Γ_C
DEFAULT_WIDTH_CELLS = 4.0
#: points sampled per facet edge (a lattice of the facet: vertices, midpoints, interior points)
_SAMPLES = 4


def _local_cells(msh: dmesh.Mesh) -> np.ndarray:
    imap = msh.topology.index_map(msh.topology.dim)
    return np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)


def _entity_points(msh: dmesh.Mesh, dim: int, entities: np.ndarray) -> np.ndarray:
    """(n, vertices, gdim) coordinates of the vertices of ``entities`` of dimension ``dim``."""
    geo = dmesh.entities_to_geometry(msh, dim, entities)
    return msh.geometry.x[geo][:, :, : msh.geometry.dim]


def _contact_facets(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags) -> np.ndarray:
    facets = facet_tags.find(Boundary.GAMMA_C)
    if msh.comm.allreduce(facets.size, op=MPI.SUM) == 0:
        raise MeshTagError("the contact strip Ω₂ is built along Γ_C, but the mesh has no Gamma_C facets")
    return facets


def _facet_samples(msh: dmesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """Points on every Γ_C facet of every rank (gathered): a lattice of ``_SAMPLES`` + 1 points per edge."""
    tdim = msh.topology.dim
    local = _entity_points(msh, tdim - 1, facets) if facets.size else np.zeros((0, tdim, msh.geometry.dim))
    k = _SAMPLES
    if tdim == 2:
        bary = np.array([[1 - t, t] for t in np.linspace(0.0, 1.0, k + 1)])
    else:
        bary = np.array([[1 - (i + j) / k, i / k, j / k] for i in range(k + 1) for j in range(k + 1 - i)])
    points = np.einsum("sv,nvd->nsd", bary, local).reshape(-1, msh.geometry.dim)
    return np.concatenate(msh.comm.allgather(points))


def contact_cells(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags) -> np.ndarray:
    """The local cells (owned and ghost) with a facet on Γ_C, sorted; MeshTagError when no rank has Γ_C."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    facets = _contact_facets(msh, facet_tags)
    return np.unique(f2c.array[f2c.offsets[facets]]).astype(np.int32)  # a boundary facet has one cell


def contact_cell_size(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags) -> float:
    """The largest diameter of a cell with a facet on Γ_C (over all ranks)."""
    tdim = msh.topology.dim
    cells = contact_cells(msh, facet_tags)
    size = 0.0
    if cells.size:
        x = _entity_points(msh, tdim, cells)
        size = float(np.max(np.linalg.norm(x[:, :, None, :] - x[:, None, :, :], axis=-1)))
    return msh.comm.allreduce(size, op=MPI.MAX)


def band_cells(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, width: float) -> np.ndarray:
    """Mask over the local cells (owned and ghost): centroid within ``width`` of Γ_C, or a facet on Γ_C."""
    if not (isinstance(width, (int, float, np.floating)) and np.isfinite(width) and width > 0):
        raise InputError(f"the width of the contact strip must be a number > 0, got {width!r}")
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = _contact_facets(msh, facet_tags)
    tree = cKDTree(_facet_samples(msh, facets))
    cells = _local_cells(msh)
    centroids = _entity_points(msh, tdim, cells).mean(axis=1)
    distance, _ = tree.query(centroids)
    inside = distance <= width
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    inside[f2c.array[f2c.offsets[facets]]] = True  # (exterior facets: one cell each)
    return inside


def strip_tags(
    msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, in_strip: np.ndarray
) -> tuple[dmesh.MeshTags, dmesh.MeshTags]:
    """(cell tags Ω₁/Ω₂, the facet tags plus γ) from the strip mask over the local cells. Collective."""
    comm = msh.comm
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    n_owned = msh.topology.index_map(tdim).size_local
    n_total = comm.allreduce(n_owned, op=MPI.SUM)
    n_strip = comm.allreduce(int(np.count_nonzero(in_strip[:n_owned])), op=MPI.SUM)
    if n_strip == n_total:
        raise InputError(
            "the contact strip Ω₂ is the whole domain: make it narrower (a smaller strip width or coarse size H)"
        )
    cells = _local_cells(msh)
    values = np.where(in_strip, int(Subdomain.OMEGA2), int(Subdomain.OMEGA1)).astype(np.int32)
    cell_tags = dmesh.meshtags(msh, tdim, cells, values)
    imap = msh.topology.index_map(tdim - 1)
    num_facets = imap.size_local + imap.num_ghosts
    offsets = f2c.offsets
    two = np.flatnonzero(np.diff(offsets)[:num_facets] == 2)
    c0, c1 = f2c.array[offsets[two]], f2c.array[offsets[two] + 1]
    gamma = two[in_strip[c0] != in_strip[c1]].astype(np.int32)
    if comm.allreduce(gamma.size, op=MPI.SUM) == 0:
        raise InputError("the contact strip Ω₂ has no interface γ with Ω₁")
    keep = ~np.isin(facet_tags.indices, gamma)
    entities = np.concatenate([facet_tags.indices[keep], gamma])
    tag_values = np.concatenate([facet_tags.values[keep], np.full(gamma.size, int(Boundary.INTERFACE), np.int32)])
    order = np.argsort(entities, kind="stable")
    return cell_tags, dmesh.meshtags(
        msh, tdim - 1, entities[order].astype(np.int32), tag_values[order].astype(np.int32)
    )


def coarse_strip(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, coarse_cell: np.ndarray) -> np.ndarray:
    """Mask over the local cells: the coarse cells that hold a cell with a facet on Γ_C (one coarse layer along
    the contact boundary, as in the paper). Collective."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    coarse_cell = np.asarray(coarse_cell)
    touching = np.unique(f2c.array[f2c.offsets[_contact_facets(msh, facet_tags)]])  # exterior facets: one cell each
    strip_local = coarse_cell[touching]
    if np.any(strip_local < 0):
        raise InputError(
            "cannot build the contact strip Ω₂: some cells along Γ_C lie in no coarse cell (the fine mesh does not "
            "resolve the coarse grid there); give a coarse partition, another H, or tag Omega1/Omega2/gamma"
        )
    strip = np.unique(np.concatenate(msh.comm.allgather(np.unique(strip_local))))
    return np.isin(coarse_cell[_local_cells(msh)], strip)


def _coarse_adjacency(msh: dmesh.Mesh, coarse: np.ndarray) -> dict[tuple[int, int], int]:
    """Number of facets shared by every pair of coarse cells (owned facets, summed over the ranks)."""
    tdim = msh.topology.dim
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    n_owned = msh.topology.index_map(tdim - 1).size_local
    offsets = f2c.offsets
    two = np.flatnonzero(np.diff(offsets)[:n_owned] == 2)
    a, b = coarse[f2c.array[offsets[two]]], coarse[f2c.array[offsets[two] + 1]]
    keep = (a != b) & (a >= 0) & (b >= 0)
    pairs = np.sort(np.stack([a[keep], b[keep]], axis=1), axis=1)
    found = np.unique(pairs, axis=0, return_counts=True) if pairs.size else (np.zeros((0, 2), int), np.zeros(0, int))
    counts: dict[tuple[int, int], int] = {}
    for chunk in msh.comm.allgather((found[0].tolist(), found[1].tolist())):
        for (i, j), n in zip(*chunk):
            counts[(i, j)] = counts.get((i, j), 0) + n
    return counts


def coarse_partition(msh: dmesh.Mesh, omega1: np.ndarray, H: float) -> np.ndarray:
    """Coarse index of every local cell: the centroid squares of side H, restricted to the cells where
    ``omega1`` holds (``UNRESOLVED`` elsewhere), slivers merged, numbered 0, 1, … (collective)."""
    coarse, _ = centroid_coarse_cells(msh, H)
    coarse = np.where(omega1, coarse, UNRESOLVED).astype(np.int64)
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    while True:
        size = int(msh.comm.allreduce(int(coarse.max(initial=-1)), op=MPI.MAX)) + 1
        local = np.bincount(coarse[:n_owned][coarse[:n_owned] >= 0], minlength=size)
        counts = np.empty_like(local)
        msh.comm.Allreduce(local, counts, op=MPI.SUM)
        present = np.flatnonzero(counts)
        small = present[counts[present] < SLIVER * np.median(counts[present])]
        if small.size == 0 or present.size < 2:
            break
        adjacency = _coarse_adjacency(msh, coarse)
        merge = {}
        for k in small[np.argsort(counts[small], kind="stable")]:
            best = max(
                (
                    (n, j if i == k else i)
                    for (i, j), n in adjacency.items()
                    if k in (i, j) and (j if i == k else i) not in merge
                ),
                default=None,
            )
            if best is not None and best[1] not in small:
                merge[int(k)] = int(best[1])
        if not merge:
            break
        for k, into in merge.items():
            coarse[coarse == k] = into
    numbers = np.unique(np.concatenate(msh.comm.allgather(np.unique(coarse[coarse >= 0]))))
    renumbered = np.full_like(coarse, UNRESOLVED)
    ok = coarse >= 0
    renumbered[ok] = np.searchsorted(numbers, coarse[ok])
    return renumbered.astype(np.int32)


def omega1_coarse_cells(msh: dmesh.Mesh, cell_tags: dmesh.MeshTags, H: float) -> np.ndarray:
    """Coarse index of every local cell of a mesh whose Ω₁ is tagged: the squares (cubes) of side H over the
    bounding box that hold the centroids of the Ω₁ cells, slivers merged (``coarse_partition``; on a mesh that
    resolves the grid, the grid itself), ``UNRESOLVED`` outside Ω₁ (collective)."""
    return coarse_partition(msh, np.isin(_local_cells(msh), cell_tags.find(Subdomain.OMEGA1)), H)


class Split(NamedTuple):
    """Ω₁/Ω₂ cell tags, the facet tags with γ, the coarse cell of every local cell, the coarse size, and whether the
    coarse cells are squares (cubes) of side H (False: the user's partition, H its largest |K|^(1/d))."""

    cell_tags: dmesh.MeshTags
    facet_tags: dmesh.MeshTags
    coarse_cell: np.ndarray
    H: float | None
    coarse_grid: bool = True


def automatic_split(
    msh: dmesh.Mesh,
    facet_tags: dmesh.MeshTags,
    *,
    H: float | None = None,
    width: float | None = None,
    partition: np.ndarray | None = None,
) -> Split:
    """Ω₂, γ and the coarse cells of a mesh that tags only Γ_C (and Γ_D, Γ_N): collective.

    * ``partition`` (a coarse index per local cell: the user's coarse cells): Ω₂ = the coarse cells along Γ_C;
    * ``H`` without ``width``, on a mesh that resolves the squares of side H over the bounding box: Ω₂ = the
      squares along Γ_C (the paper's strip, one coarse cell wide), the other squares the coarse cells of Ω₁;
    * ``H`` otherwise: Ω₂ = the band of width ``width`` (default H) along Γ_C, the coarse cells of Ω₁ the
      squares that hold the centroids (``coarse_partition``: slivers merged);
    * neither: Ω₂ = the band of ``width`` (default ``DEFAULT_WIDTH_CELLS`` contact cells), no coarse cells.
    """
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    if partition is not None:
        coarse = np.asarray(partition)
        cell_tags, tags = strip_tags(msh, facet_tags, coarse_strip(msh, facet_tags, coarse))
        return Split(cell_tags, tags, coarse.astype(np.int32), float(coarse_sizes(msh, coarse).max()), False)
    if H is not None:
        coarse, _ = cartesian_coarse_cells(msh, H)
        if width is None and msh.comm.allreduce(int(np.all(coarse >= 0)), op=MPI.MIN):
            cell_tags, tags = strip_tags(msh, facet_tags, coarse_strip(msh, facet_tags, coarse))
            return Split(cell_tags, tags, coarse.astype(np.int32), float(H))
        in_strip = band_cells(msh, facet_tags, H if width is None else width)
        cell_tags, tags = strip_tags(msh, facet_tags, in_strip)
        return Split(cell_tags, tags, coarse_partition(msh, ~in_strip, H), float(H))
    width = DEFAULT_WIDTH_CELLS * contact_cell_size(msh, facet_tags) if width is None else width
    cell_tags, tags = strip_tags(msh, facet_tags, band_cells(msh, facet_tags, width))
    imap = msh.topology.index_map(tdim)
    return Split(cell_tags, tags, np.full(imap.size_local + imap.num_ghosts, UNRESOLVED, dtype=np.int32), None)
