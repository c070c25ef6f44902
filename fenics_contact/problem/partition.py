"""Coarse partitions of a fine mesh (multiscale methods) and the automatic contact strip Ω₂.

The multiscale methods need every fine cell of Ω₁ in one coarse cell K
(``ContactMesh.coarse_cell``). Two sources, on any domain:

* **A Cartesian grid over the bounding box** (``cartesian_coarse_cells``): squares (cubes on a
  tetrahedral mesh) of side H anchored at the smallest vertex coordinates; a fine cell gets the
  square that contains it, or −1 when it straddles a grid line (the fine mesh does not resolve the
  grid there). The multiscale methods refuse −1 cells in Ω₁ with an InputError.
* **A partition given by the user**: in a gmsh file, every 2D physical group other than
  ``Omega1``/``Omega2`` is one coarse cell (``read_mesh`` reads them, ``group_coarse_cells``).

When a mesh does not tag Ω₁, Ω₂ and γ, ``problem.strip`` builds them from these partitions.
"""

import basix.ufl
import numpy as np
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError

__all__ = [
    "cartesian_coarse_cells",
    "centroid_coarse_cells",
    "group_coarse_cells",
    "coarse_sizes",
    "simplex_volumes",
    "UNRESOLVED",
]

#: coarse index of a fine cell that lies in no coarse cell (straddles a line of the Cartesian grid)
UNRESOLVED = -1


def _local_cells(msh: dmesh.Mesh) -> np.ndarray:
    imap = msh.topology.index_map(msh.topology.dim)
    return np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)


def _cell_vertices(msh: dmesh.Mesh, cells: np.ndarray) -> np.ndarray:
    """(cells, d + 1, d) vertex coordinates (d = the topological dimension: triangles in the plane, tetrahedra)."""
    d = msh.topology.dim
    geo = dmesh.entities_to_geometry(msh, d, cells)
    return msh.geometry.x[geo][:, :, :d]


def simplex_volumes(p: np.ndarray) -> np.ndarray:
    """|T| of every simplex of ``p`` ((cells, d + 1, d) vertex coordinates, d = 2 or 3): areas or volumes."""
    d1, d2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    if p.shape[2] == 2:
        return 0.5 * np.abs(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0])
    return np.abs(np.einsum("ij,ij->i", np.cross(d1, d2), p[:, 3] - p[:, 0])) / 6.0


def _bounding_grid(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, np.ndarray]:
    """(lowest corner, the number of grid cells along each axis) of the grid of squares (cubes in 3D) of side H
    over the mesh's bounding box (collective; InputError for an H that is not a positive number)."""
    if not (isinstance(H, (int, float, np.floating)) and np.isfinite(H) and H > 0):
        raise InputError(f"the coarse size H must be a positive number, got {H!r}")
    comm = msh.comm
    d = msh.topology.dim
    x = msh.geometry.x[:, :d]
    lo, hi = np.empty(d), np.empty(d)
    comm.Allreduce(x.min(axis=0) if x.size else np.full(d, np.inf), lo, op=MPI.MIN)
    comm.Allreduce(x.max(axis=0) if x.size else np.full(d, -np.inf), hi, op=MPI.MAX)
    counts = np.array([max(1, int(np.ceil((hi[a] - lo[a]) / H - 1e-9))) for a in range(d)], dtype=np.int64)
    return lo, counts


def _flat_index(ij: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """i + nx·j (+ nx·ny·k in 3D) of the grid positions ``ij`` (cells, d)."""
    index = ij[:, 0] + counts[0] * ij[:, 1]
    if ij.shape[1] == 3:
        index = index + counts[0] * counts[1] * ij[:, 2]
    return index


def cartesian_coarse_cells(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, int]:
    """(coarse index of every local cell, number of columns nx) for the grid of squares (cubes on a 3D mesh) of
    side H over the bounding box; index i + nx·j (+ nx·ny·k), or ``UNRESOLVED`` for a cell not inside one square
    (collective)."""
    lo, counts = _bounding_grid(msh, H)
    nx = int(counts[0])
    cells = _local_cells(msh)
    if cells.size == 0:
        return np.zeros(0, dtype=np.int64), nx
    p = (_cell_vertices(msh, cells) - lo) / H
    tol = 1e-8
    ij_lo = np.floor(p.min(axis=1) + tol).astype(np.int64)
    ij_hi = np.floor(p.max(axis=1) - tol).astype(np.int64)
    index = _flat_index(ij_lo, counts)
    index[np.any(ij_lo != ij_hi, axis=1)] = UNRESOLVED
    return index, nx


def centroid_coarse_cells(msh: dmesh.Mesh, H: float) -> tuple[np.ndarray, int]:
    """(coarse index of every local cell, nx): the square (cube) of side H (grid over the bounding box, as
    ``cartesian_coarse_cells``) that holds the cell's centroid.  Every cell gets a coarse cell, also on
    an unstructured mesh that does not resolve the grid lines: the coarse cells are then unions of fine
    cells with jagged boundaries, which the multiscale methods accept as any partition (collective)."""
    lo, counts = _bounding_grid(msh, H)
    nx = int(counts[0])
    cells = _local_cells(msh)
    if cells.size == 0:
        return np.zeros(0, dtype=np.int64), nx
    ij = np.floor((_cell_vertices(msh, cells).mean(axis=1) - lo) / H).astype(np.int64)
    ij = np.minimum(np.maximum(ij, 0), counts - 1)
    return _flat_index(ij, counts), nx


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
    """|K|^(1/d) of every coarse cell (√|K| in the plane; index = coarse number; summed over the owned cells of
    all ranks)."""
    n_owned = msh.topology.index_map(msh.topology.dim).size_local
    cells = np.arange(n_owned, dtype=np.int32)
    area = simplex_volumes(_cell_vertices(msh, cells))
    idx = np.asarray(coarse_cell)[:n_owned]
    n = msh.comm.allreduce(int(idx.max()) + 1 if idx.size else 0, op=MPI.MAX)
    ok = idx >= 0
    local = np.bincount(idx[ok], weights=area[ok], minlength=n).astype(np.float64)
    total = np.empty_like(local)
    msh.comm.Allreduce(local, total, op=MPI.SUM)
    return np.sqrt(total) if msh.topology.dim == 2 else np.cbrt(total)
