"""The coarse grid T_H of Ω₁ for the multiscale methods: coarse cells, adjacency, oversampled patches, colours.

A coarse cell K_k is a set of fine Ω₁ cells (the fine mesh refines the coarse
partition). Where the partition comes from is the mesh's business
(``ContactMesh.coarse_cell``: the squares (cubes on a tetrahedral mesh) of a
Cartesian grid over the bounding box, or a partition given by the user,
``problem.partition``); this module only
needs the coarse index of every fine cell, so any domain and any partition work.

* **Adjacency.** Two coarse cells are neighbours when they share a fine vertex
  (for a Cartesian grid: the eight surrounding squares, the 26 surrounding cubes).
* **Oversampling.** K_{k,m} is K_k and every coarse cell at most m adjacency
  steps away (breadth-first search); on a Cartesian grid over a convex Ω₁ this
  is |i′ − i| ≤ m and |j′ − j| ≤ m (and |k′ − k| ≤ m).
* **Colours.** A greedy colouring of the adjacency graph: two coarse cells of
  one colour share no fine vertex, so the restriction of a matrix assembled over
  the cells of one colour to the vertices of K_k is the matrix of K_k alone
  (four colours on a Cartesian grid of squares, eight of cubes).
* **Groups.** ``groups(g)`` partitions the coarse cells into blocks that share one patch problem
  (``CEMOptions.patch_group``): the g × g (× g) blocks of a Cartesian grid; on a general partition greedy
  groups (the first ungrouped cell and the ungrouped cells at most g − 1 steps from it, nearest first, at
  most g^d of them); g = None: one group of all cells.
* **Size.** ``cell_size[k]`` = |K_k|^(1/d) (H for a square or cube of side H) scales
  the CEM inner product, κ̃ = c κ H_k⁻².
"""

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from dolfinx import mesh as dmesh
from scipy.sparse import csgraph

from fenics_contact.errors import InputError
from fenics_contact.problem.partition import simplex_volumes

__all__ = ["CoarseGrid", "coarse_grid", "grid_from_cells"]


@dataclass(frozen=True, eq=False)
class CoarseGrid:
    """The coarse cells K_k of Ω₁ (local numbering k = 0..size−1) and their adjacency."""

    H: float  #: coarse size: the Cartesian H, or the largest |K_k|^(1/d) of a user partition
    global_index: np.ndarray  #: (n_K,) index of each K_k in ContactMesh.coarse_cell
    cell_coarse: np.ndarray  #: (num fine cells,) local coarse number k of each fine Ω₁ cell
    cells: tuple  #: fine cells of each K_k (Ω₁ submesh numbering, sorted)
    adjacency: sp.csr_matrix  #: (n_K, n_K) boolean, K_k and K_l share a fine vertex (diagonal included)
    cell_size: np.ndarray  #: (n_K,) |K_k|^(1/d): √|K_k| in the plane, ∛|K_k| in 3D
    ij: np.ndarray | None  #: (n_K, d) Cartesian position of each K_k, None for a general partition
    n_coarse: int | None  #: 1/H for a Cartesian grid over the unit square (cube), else None
    _patches: dict = field(default_factory=dict, repr=False)

    @property
    def size(self) -> int:
        """Number of coarse cells in Ω₁."""
        return len(self.cells)

    @property
    def colors(self) -> np.ndarray:
        """Colour of each coarse cell: no two cells of one colour share a fine vertex."""
        if "colors" not in self._patches:
            self._patches["colors"] = _greedy_colouring(self.adjacency)
        return self._patches["colors"]

    @property
    def num_colors(self) -> int:
        return int(self.colors.max()) + 1 if self.size else 0

    def distance(self, k: int) -> np.ndarray:
        """Adjacency distance (number of coarse layers) from K_k to every coarse cell (−1: unreachable)."""
        key = ("distance", int(k))
        if key not in self._patches:
            d = csgraph.shortest_path(self.adjacency, method="D", unweighted=True, indices=int(k))
            self._patches[key] = np.where(np.isfinite(d), d, -1).astype(np.int64)
        return self._patches[key]

    def patch(self, k: int, layers: int) -> np.ndarray:
        """Coarse cells of K_{k,m}: at most m = ``layers`` adjacency steps from K_k (sorted)."""
        dist = self.distance(k)
        return np.flatnonzero((dist >= 0) & (dist <= layers))

    def groups(self, g: int | None, dim: int) -> list[np.ndarray]:
        """The coarse cells in groups of about g per direction (each sorted; groups by their first cell) in
        dimension ``dim``; g = None: one group of all cells."""
        if g is None:
            return [np.arange(self.size)]
        if g == 1:
            return [np.array([k]) for k in range(self.size)]
        if self.ij is not None:
            _, label = np.unique(self.ij // g, axis=0, return_inverse=True)
        else:
            label = np.full(self.size, -1, dtype=np.int64)
            for seed in range(self.size):
                if label[seed] >= 0:
                    continue
                dist = self.distance(seed)
                near = np.flatnonzero((dist >= 0) & (dist <= g - 1) & (label < 0))
                near = near[np.argsort(dist[near], kind="stable")][: g**dim]
                label[near] = seed
        label = np.asarray(label).ravel()
        groups = [np.flatnonzero(label == v) for v in np.unique(label)]
        return sorted(groups, key=lambda c: int(c[0]))

    def group_patch(self, cells: np.ndarray, layers: int) -> np.ndarray:
        """The union of the K_{k,m} of ``cells`` (sorted): the patch a group's problems are solved on."""
        if cells.size == 1:
            return self.patch(int(cells[0]), layers)
        reach = np.zeros(self.size, dtype=bool)
        reach[cells] = True
        for _ in range(layers):
            reach = reach | (self.adjacency @ reach.astype(np.int64) > 0)
        return np.flatnonzero(reach)


def _greedy_colouring(adjacency: sp.csr_matrix) -> np.ndarray:
    """Smallest colour not used by an already coloured neighbour, cells in index order."""
    n = adjacency.shape[0]
    colors = np.full(n, -1, dtype=np.int64)
    A = adjacency.tocsr()
    for k in range(n):
        used = colors[A.indices[A.indptr[k] : A.indptr[k + 1]]]
        used = used[used >= 0]
        c = 0
        if used.size:
            free = np.setdiff1d(np.arange(used.max() + 2), used)
            c = int(free[0])
        colors[k] = c
    return colors


def grid_from_cells(
    cell_nodes: np.ndarray, coords: np.ndarray, coarse_index: np.ndarray, H: float | None
) -> CoarseGrid:
    """The coarse grid from the coarse index of every fine cell (``cell_nodes``: (cells, d + 1) vertex numbers of
    triangles, d = 2, or tetrahedra, d = 3).

    ``coords`` are the vertex coordinates (x, y (, z) in the first d columns). A grid is recognised as Cartesian
    (``ij`` set) when every coarse cell lies in one square (cube) of side H of the grid anchored at the smallest
    vertex coordinates.
    """
    coarse_index = np.asarray(coarse_index, dtype=np.int64)
    d = cell_nodes.shape[1] - 1
    shape = "squares" if d == 2 else "cubes"
    if coarse_index.size == 0:
        raise InputError("Ω₁ has no cells")
    if np.any(coarse_index < 0):
        bad = int(np.count_nonzero(coarse_index < 0))
        raise InputError(
            f"{bad} of the {coarse_index.size} fine cells of Ω₁ lie in no coarse cell: the fine mesh does not "
            f"resolve the coarse grid ({shape} of side H = {H} over the bounding box; every fine cell must lie "
            f"inside one of them). Use a mesh whose edges follow the grid lines, another H, or give the coarse "
            f"partition as {d}D physical groups (one per coarse cell)"
        )
    global_index, cell_coarse = np.unique(coarse_index, return_inverse=True)
    n_k = global_index.size
    order = np.argsort(cell_coarse, kind="stable")
    splits = np.cumsum(np.bincount(cell_coarse, minlength=n_k))[:-1]
    cells = tuple(np.split(order.astype(np.int32), splits))
    # vertex–coarse-cell incidence → adjacency (shared fine vertex)
    nv = int(cell_nodes.max()) + 1
    inc = sp.csr_matrix(
        (np.ones(cell_nodes.size, dtype=np.int8), (cell_nodes.ravel(), np.repeat(cell_coarse, cell_nodes.shape[1]))),
        shape=(nv, n_k),
    )
    inc.data[:] = 1
    adjacency = (inc.T @ inc).tocsr()
    adjacency.data[:] = 1
    adjacency = adjacency.astype(bool)
    # measures (areas, volumes) and bounding boxes of the coarse cells
    p = coords[cell_nodes][:, :, :d]
    measure = np.bincount(cell_coarse, weights=simplex_volumes(p), minlength=n_k)
    cell_size = np.sqrt(measure) if d == 2 else np.cbrt(measure)
    lo = np.full((n_k, d), np.inf)
    hi = np.full((n_k, d), -np.inf)
    np.minimum.at(lo, cell_coarse, p.min(axis=1))
    np.maximum.at(hi, cell_coarse, p.max(axis=1))
    ij, n_coarse = None, None
    if H is not None:
        origin = coords[:, :d].min(axis=0)
        tol = 1e-8 * H
        ij_lo = np.floor((lo - origin + tol) / H).astype(np.int64)
        ij_hi = np.floor((hi - origin - tol) / H).astype(np.int64)
        if np.all(ij_lo == ij_hi):
            ij = ij_lo
            if np.unique(ij, axis=0).shape[0] != n_k:
                ij = None
        in_unit_box = np.allclose(coords[:, :d].min(axis=0), 0.0) and np.all(coords[:, :d].max(axis=0) <= 1 + 1e-12)
        if ij is not None and in_unit_box and abs(1.0 / H - round(1.0 / H)) < 1e-9:
            n_coarse = int(round(1.0 / H))
    H_out = float(H) if H is not None else float(cell_size.max())
    return CoarseGrid(H_out, global_index, cell_coarse.astype(np.int32), cells, adjacency, cell_size, ij, n_coarse)


def coarse_grid(msh: dmesh.Mesh, cell_map: dmesh.EntityMap, coarse_cell: np.ndarray, H: float | None) -> CoarseGrid:
    """Coarse grid of a serial submesh (Ω₁) from the parent's ``coarse_cell`` via the submesh cell map."""
    if msh.comm.size > 1:
        raise InputError("coarse_grid needs a serial (COMM_SELF) copy of Ω₁")
    if H is None and not np.any(np.asarray(coarse_cell) >= 0):
        raise InputError(
            "the mesh has no coarse grid (ContactMesh.H is None and no coarse partition): build it with "
            "geometry.unit_square(n, n_coarse), or give read_mesh H or a mesh with a coarse partition"
        )
    tdim = msh.topology.dim
    imap = msh.topology.index_map(tdim)
    sub_cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    parent = np.asarray(cell_map.sub_topology_to_topology(sub_cells, False), dtype=np.int64)
    index = np.asarray(coarse_cell)[parent]
    cell_nodes = msh.geometry.dofmaps[0]
    return grid_from_cells(cell_nodes, msh.geometry.x, index, H)
