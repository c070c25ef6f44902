"""Coarse partitions of a fine mesh (multiscale methods) and the automatic contact strip Ω₂.

The multiscale methods need every fine cell of Ω₁ in one coarse cell K
(``ContactMesh.coarse_cell``). Two sources, on any domain:

* **A Cartesian grid over the bounding box** (``cartesian_coarse_cells``): squares (cubes on a
  tetrahedral mesh) of side H anchored at the smallest vertex coordinates; a fine cell gets the
  square that contains it, or −1 when it straddles a grid line (the fine mesh does not resolve the
  grid there). The multiscale methods refuse −1 cells in Ω₁ with an InputError.
* **Graded boxes** (``graded_coarse_cells``): the bounding box of the chosen cells halved along every axis
  longer than a size function at the box's centre, again and again (a k-d tree of boxes whose side follows
  the size function); a fine cell gets the box that holds its centroid.  Coarse cells of any size on any
  mesh, e.g. small near a contact and growing with the distance from it, where a graded mesh grows too.
* **A partition given by the user**: in a gmsh file, every 2D physical group other than
  ``Omega1``/``Omega2`` is one coarse cell (``read_mesh`` reads them, ``group_coarse_cells``).

When a mesh does not tag Ω₁, Ω₂ and γ, ``problem.strip`` builds them from these partitions.
"""

import math
from collections.abc import Callable

import basix.ufl
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from scipy.sparse import csgraph

from fenics_contact.errors import InputError

__all__ = [
    "cartesian_coarse_cells",
    "coarse_to_fine",
    "centroid_coarse_cells",
    "graded_coarse_cells",
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


def coarse_to_fine(volumes: np.ndarray, coarse: np.ndarray, d: int, comm: MPI.Comm = MPI.COMM_SELF) -> float:
    """The median over the coarse cells K of |K|^(1/d) / mean (d!|T|)^(1/d) of the fine cells T it holds
    (``volumes``: |T| of the fine simplices of dimension d, ``coarse``: their coarse cells' indices; summed over
    the ranks of ``comm`` when each holds some of the cells).  (d!|T|)^(1/d) is the side of the square (cube) a
    triangle (tetrahedron) of area (volume) |T| is one d!-th of: a square (cube) of side H over a mesh of squares
    (cubes) of side h, each cut into d! simplices, has the ratio H/h."""
    root = np.sqrt if d == 2 else np.cbrt
    n = comm.allreduce(int(np.max(coarse, initial=-1)) + 1, op=MPI.MAX)
    total = comm.allreduce(np.bincount(coarse, weights=volumes, minlength=n), op=MPI.SUM)
    fine = comm.allreduce(np.bincount(coarse, weights=root(math.factorial(d) * volumes), minlength=n), op=MPI.SUM)
    count = comm.allreduce(np.bincount(coarse, minlength=n).astype(float), op=MPI.SUM)
    held = count > 0
    return float(np.median(root(total[held]) / (fine[held] / count[held])))


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


#: ``graded_coarse_cells`` refuses a size function that asks for more boxes than this
MAX_BOXES = 200_000


def graded_coarse_cells(
    msh: dmesh.Mesh, size: Callable[[np.ndarray], np.ndarray], *, cells: np.ndarray | None = None
) -> np.ndarray:
    """Coarse index of every local cell (owned and ghost): boxes no longer than ``size`` at centre and corners.

    The bounding box of ``cells`` (local cell numbers, owned and ghost; default all) is halved along every
    axis longer than the smallest ``size`` at its centre and its corners (x of shape (3, k) -> (k,) positive
    sizes, as a DOLFINx expression takes points), and so are its halves, until no box is longer than that.  A fine cell
    of ``cells`` gets the box holding its centroid, numbered 0, 1, … over the boxes that hold a cell on some
    rank; the other cells get ``UNRESOLVED``.  The coarse cells are unions of fine cells with jagged
    boundaries where the mesh does not follow the box faces, which the multiscale methods accept as any
    partition; a piece of a box's cells joined to the rest at a vertex or an edge only (a hinge: a zero-energy
    mode more in its local spectral problem) joins the neighbouring coarse cell it shares the most faces with,
    so that every coarse cell is face-connected.  The boxes depend only on the global bounding box and
    ``size``, and the repair is made on the chosen cells of all ranks (gathered on every rank) in the order of
    their centroids: the same partition on any number of ranks (collective).  InputError for a size that is
    not positive and finite or asks for over ``MAX_BOXES`` boxes.
    """
    d = msh.topology.dim
    local = _local_cells(msh)
    chosen = local if cells is None else np.asarray(cells, dtype=np.int32)
    p = _cell_vertices(msh, chosen) if chosen.size else np.zeros((0, d + 1, d))
    comm = msh.comm
    lo, hi = np.empty(d), np.empty(d)
    flat = p.reshape(-1, d)
    comm.Allreduce(flat.min(axis=0) if flat.size else np.full(d, np.inf), lo, op=MPI.MIN)
    comm.Allreduce(flat.max(axis=0) if flat.size else np.full(d, -np.inf), hi, op=MPI.MAX)
    if not np.all(hi > lo):
        raise InputError("graded_coarse_cells: the chosen cells span no box (no cells, or a flat set)")
    centroids = p.mean(axis=1)
    leaf, _ = _box_tree_leaves(lo, hi, size, centroids)
    # every rank gathers the chosen owned cells (global numbers, global vertices, box, centroid) and repairs them
    # alike, in the order of their centroids (the same partition on any number of ranks)
    n_owned = msh.topology.index_map(d).size_local
    owned = chosen < n_owned
    cell_map, vertex_map = msh.topology.index_map(d), msh.topology.index_map(0)
    c2v = msh.topology.connectivity(d, 0)
    vertices = c2v.array.reshape(-1, d + 1)[chosen[owned]] if chosen.size else np.zeros((0, d + 1), np.int32)
    gathered = comm.allgather(
        (
            cell_map.local_to_global(chosen[owned].astype(np.int32)),
            vertex_map.local_to_global(vertices.ravel().astype(np.int32)).reshape(-1, d + 1),
            leaf[owned],
            centroids[owned],
        )
    )
    global_cells, global_vertices, boxes, points = (np.concatenate([g[i] for g in gathered]) for i in range(4))
    along = np.lexsort(np.round((points - lo) / np.max(hi - lo), 9).T[::-1])
    repaired = np.empty(global_cells.size, dtype=np.int64)
    repaired[along] = _face_connected(global_vertices[along], boxes[along])
    order = np.argsort(global_cells)
    mine = cell_map.local_to_global(chosen.astype(np.int32))
    at = np.minimum(np.searchsorted(global_cells, mine, sorter=order), max(order.size - 1, 0))
    found = order.size > 0 and global_cells[order[at]] == mine
    index = np.full(local.size, UNRESOLVED, dtype=np.int64)
    index[chosen[found]] = repaired[order[at[found]]]
    return index


def _face_connected(vertices: np.ndarray, index: np.ndarray, *, rounds: int = 50) -> np.ndarray:
    """Coarse cells joined through faces, numbered 0, 1, …: the cells (rows of global ``vertices``) of a coarse
    ``index`` that are not in its largest face-connected piece (pieces joined to it only at a vertex or an edge,
    which would add hinge modes to its local spectral problem) join the neighbouring coarse cell with which
    they share the most faces; a piece with no other neighbour becomes a coarse cell of its own."""
    index = np.unique(index, return_inverse=True)[1].astype(np.int64)
    n, d1 = vertices.shape
    if n == 0:
        return index
    # the pairs of cells that share a face (the d vertices left when one is dropped)
    faces = np.sort(np.concatenate([np.delete(vertices, k, axis=1) for k in range(d1)]), axis=1)
    owner = np.tile(np.arange(n), d1)
    order = np.lexsort(faces.T[::-1])
    same = np.all(faces[order[1:]] == faces[order[:-1]], axis=1)
    first, second = owner[order[:-1][same]], owner[order[1:][same]]
    for _ in range(rounds):
        inside = index[first] == index[second]
        graph = sp.coo_matrix((np.ones(int(inside.sum())), (first[inside], second[inside])), shape=(n, n))
        _, piece = csgraph.connected_components(graph, directed=False)
        cells_of_piece = np.bincount(piece)
        largest = np.zeros(index.max() + 1, dtype=np.int64)  # the largest piece of each coarse cell (the first)
        by_size = np.lexsort((-cells_of_piece[piece], index))
        heads = np.concatenate([[True], index[by_size[1:]] != index[by_size[:-1]]])
        largest[index[by_size[heads]]] = piece[by_size[heads]]
        stray = piece != largest[index]
        if not stray.any():
            break
        # votes of the stray pieces for the coarse index across their faces
        a, b = np.concatenate([first, second]), np.concatenate([second, first])
        vote = stray[a] & (piece[a] != piece[b])
        pairs, counts = np.unique(np.stack([piece[a[vote]], index[b[vote]]]), axis=1, return_counts=True)
        best = np.lexsort((pairs[1], -counts, pairs[0]))
        keep = np.concatenate([[True], pairs[0, best[1:]] != pairs[0, best[:-1]]]) if best.size else best
        target = dict(zip(pairs[0, best[keep]].tolist(), pairs[1, best[keep]].tolist()))
        moved = np.array([target.get(int(q), -1) for q in piece[stray]], dtype=np.int64)
        alone = moved < 0
        moved[alone] = index.max() + 1 + np.unique(piece[stray][alone], return_inverse=True)[1]
        index[stray] = moved
    return np.unique(index, return_inverse=True)[1].astype(np.int64)


def _box_tree_leaves(
    lo: np.ndarray, hi: np.ndarray, size: Callable[[np.ndarray], np.ndarray], points: np.ndarray
) -> tuple[np.ndarray, int]:
    """(the leaf box of every point (k, d), the number of leaves) of the k-d tree of ``graded_coarse_cells``:
    level by level, every box longer than ``size`` at its centre or a corner along some axes is halved along
    those axes."""
    d = lo.size
    box_lo, box_hi = lo[None, :].copy(), hi[None, :].copy()
    where = np.zeros(points.shape[0], dtype=np.int64)  # the box of every point at the current level
    leaf_of = np.full(points.shape[0], -1, dtype=np.int64)
    n_leaves, total = 0, 1
    codes = np.arange(2**d)
    bits = (codes[:, None] >> np.arange(d)[None, :]) & 1  # (2^d, d): the upper half along each axis?
    while box_lo.shape[0]:
        centre = 0.5 * (box_lo + box_hi)
        n = centre.shape[0]
        corners = np.where(bits[None, :, :].astype(bool), box_hi[:, None, :], box_lo[:, None, :])  # (n, 2^d, d)
        x = np.zeros((3, n * (2**d + 1)))
        x[:d] = np.concatenate([centre[:, None, :], corners], axis=1).reshape(-1, d).T
        values = np.broadcast_to(np.asarray(size(x), dtype=np.float64), (x.shape[1],))
        if not np.all(np.isfinite(values) & (values > 0)):
            raise InputError("graded_coarse_cells: the size function must be positive and finite everywhere")
        s = values.reshape(n, 2**d + 1).min(axis=1)
        split = (box_hi - box_lo) > s[:, None] * (1.0 + 1e-12)
        is_leaf = ~split.any(axis=1)
        leaf_id = np.full(box_lo.shape[0], -1, dtype=np.int64)
        leaf_id[is_leaf] = n_leaves + np.arange(np.count_nonzero(is_leaf))
        n_leaves += int(np.count_nonzero(is_leaf))
        done = is_leaf[where]
        leaf_of[np.flatnonzero(leaf_of < 0)[done]] = leaf_id[where[done]]
        points, where = points[~done], where[~done]
        # the children: the codes whose upper-half bits lie on split axes only, in (box, code) order
        valid = ~np.any(bits[None, :, :] & ~split[:, None, :], axis=2)  # (boxes, 2^d)
        valid[is_leaf] = False
        child = np.full(valid.shape, -1, dtype=np.int64)
        child[valid] = np.arange(np.count_nonzero(valid))
        total += int(np.count_nonzero(valid))
        if total > MAX_BOXES:
            raise InputError(
                f"graded_coarse_cells: the size function asks for more than {MAX_BOXES} boxes (too small a size)"
            )
        parent, code = np.nonzero(valid)
        mid = centre[parent]
        upper = bits[code].astype(bool)
        new_lo = np.where(upper, mid, box_lo[parent])
        new_hi = np.where(upper, box_hi[parent], mid)
        point_code = np.sum(((points >= centre[where]) & split[where]) << np.arange(d), axis=1)
        where = child[where, point_code]
        box_lo, box_hi = new_lo, new_hi
    return leaf_of, n_leaves


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
