"""Stage II of the mixed CEM (Algorithm 4) on one patch: the patch system, the storage of patch functions.

With Z = S Π (the aux columns of the patch) and y = Zᵀ q, the relaxed problem of a basis function (and of the
Robin and source correctors) on K_{i,m} is the sparse symmetric saddle-point system
[[Ã, Bᵀ, 0], [B, 0, −Z], [0, −Zᵀ, I]] (``patch_system``, one MUMPS LU: ``LocalFactor``).  A patch function is
kept only on its patch, per coarse cell K of the patch: its coefficients in the AW functions touching K
(``CoarseCellDofs``, about 11 numbers per fine cell instead of the 30 of DG P3) and its displacement
(``PatchFunctions``).  ``basis_decay_profile`` measures how fast the global bases decay.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.mixed_linear import saddle_point_scaling
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.blocks import cell_rows
from fenics_contact.multiscale.mixed_cem.local_space import LocalSpace, Topology, local_stress_space, local_triplets
from fenics_contact.multiscale.mixed_cem.operators import CellOperators
from fenics_contact.multiscale.mixed_cem.spectral import StageI

__all__ = ["CoarseCellDofs", "LocalFactor", "PatchFunctions", "basis_decay_profile", "cell_coarse", "patch_system"]


@dataclass(slots=True)
class CoarseCellDofs:
    """Per coarse cell K: its fine cells (sorted) and the AW DOFs touching them (sorted).

    A stress supported on a patch is stored, on each coarse cell K of the patch, by its coefficients
    in the AW functions touching K (restricted to K): on K it is P_K c_K with P_K = P[rows of K][:, aw_K]
    (``p_blocks``).  These are about 11 numbers per fine cell instead of the 30 of DG P3.
    """

    cells: list  #: sorted fine cells of each K
    aw: list  #: sorted AW DOFs touching K
    slots: list  #: (|K|, w): position in aw of each column of ops.P_cols[cells] (−1 for padding)

    @classmethod
    def of(cls, ops: CellOperators, grid: CoarseGrid) -> "CoarseCellDofs":
        cells, aw, slots = [], [], []
        for k in range(grid.size):
            ck = np.sort(np.asarray(grid.cells[k], dtype=np.int64))
            pc = ops.P_cols[ck]
            awk = np.unique(pc[pc >= 0])
            cells.append(ck)
            aw.append(awk)
            slots.append(np.where(pc >= 0, np.searchsorted(awk, np.maximum(pc, 0)), -1))
        return cls(cells, aw, slots)

    def P(self, ops: CellOperators, k: int) -> sp.csr_matrix:
        """P_K (30|K| × |aw_K|): the AW functions touching K, restricted to K, cell-major."""
        blocks, slots = ops.P_blocks[self.cells[k]], self.slots[k]
        nc, a, w = blocks.shape
        rows = np.broadcast_to((a * np.arange(nc)[:, None, None] + np.arange(a)[None, :, None]), blocks.shape)
        cols = np.broadcast_to(slots[:, None, :], blocks.shape)
        keep = (cols >= 0) & (blocks != 0.0)
        return sp.csr_matrix((blocks[keep], (rows[keep], cols[keep])), shape=(a * nc, self.aw[k].size))

    def per_cell(self, k: int, c: np.ndarray) -> np.ndarray:
        """AW coefficients c (|aw_K|, ...) on K by fine cell: (|K|, w, ...), the columns ops.P_cols of each cell."""
        slots = self.slots[k]
        return np.where((slots >= 0).reshape(slots.shape + (1,) * (c.ndim - 1)), c[np.maximum(slots, 0)], 0.0)

    def dg(self, ops: CellOperators, k: int, c: np.ndarray) -> np.ndarray:
        """The cell-major DG P3 values (|K|, 30, ...) of AW coefficients c (|aw_K|, ...) on K."""
        cc = self.per_cell(k, c)
        return (
            ops.P_blocks[self.cells[k]] @ cc if c.ndim > 1 else np.einsum("cab,cb->ca", ops.P_blocks[self.cells[k]], cc)
        )


@dataclass(slots=True)
class PatchFunctions:
    """Functions on one patch, stored per coarse cell of the patch (``CoarseCellDofs``).

    sigma[j]: AW coefficients (|aw_K|, k) on coarse cell K = coarse[j]; u[j]: displacements
    (6|K|, k), cell-major on K's sorted cells; index: the global function indices (aux index for
    basis functions, data index for correctors).  Under MPI without a cache the pieces stay on the
    rank that computed them (``held_cells``): sigma[j] and u[j] are None for the other coarse cells.
    """

    coarse: np.ndarray
    index: np.ndarray
    sigma: list
    u: list

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.sigma if a is not None) + sum(a.nbytes for a in self.u if a is not None)


class LocalFactor(SparseFactor):
    """MUMPS factorizations of the local mixed CEM problems (Stage II patch, coarse-cell and skeleton systems;
    SuperLU is 10–100× slower on these saddle-point systems).

    AMD ordering for LU (ICNTL(7) = 0): on the Stage II systems (5·10³–6·10⁴ unknowns) it halves the
    factorization time of MUMPS' automatic choice (METIS); Cholesky (LDLᵀ) is 2–4× slower.  The saddle-point
    systems are factorized equilibrated (``CellOperators.scale``: ``scaling`` of ``SparseFactor.from_csr``).
    """

    what = "a local mixed CEM problem"
    lu_icntl = ((7, 0),)


def patch_system(ops: CellOperators, topo: Topology, grid: CoarseGrid, aux: StageI, patch: np.ndarray):
    """(space, LU of the Stage II matrix, Z, aux column offsets of the patch's coarse cells, n_loc, n_u)."""
    cells = np.sort(np.concatenate([grid.cells[j] for j in patch]).astype(np.int64))
    space = local_stress_space(ops, topo, cells)
    # Z = S Π on the patch: the aux functions of its coarse cells
    zr, zc, zv = [], [], []
    col = 0
    aux_cols = {}
    for j in patch:
        cj = np.sort(grid.cells[j].astype(np.int64))
        pos = np.searchsorted(cells, cj)
        Zj = ops.S[cj] @ aux.modes[j]  # (|K_j|, 6, l_j)
        lj = Zj.shape[2]
        r = np.broadcast_to(cell_rows(pos, 6).reshape(cj.size, 6)[:, :, None], Zj.shape)
        c = np.broadcast_to(col + np.arange(lj)[None, None, :], Zj.shape)
        zr.append(r.ravel())
        zc.append(c.ravel())
        zv.append(Zj.ravel())
        aux_cols[int(j)] = col
        col += lj
    n_u = 6 * cells.size
    zr, zc, zv = np.concatenate(zr), np.concatenate(zc), np.concatenate(zv)
    Z = sp.csr_matrix((zv, (zr, zc)), shape=(n_u, col))
    # the symmetric saddle-point matrix [[Ã, Bᵀ, 0], [B, 0, −Z], [0, −Zᵀ, I]], assembled in one pass
    n_loc = space.size
    (ar, ac, av), (br, bc, bv) = local_triplets(ops, space)
    eye = n_loc + n_u + np.arange(col)
    rows = np.concatenate([ar, n_loc + br, bc, n_loc + zr, n_loc + n_u + zc, eye])
    cols = np.concatenate([ac, bc, n_loc + br, n_loc + n_u + zc, n_loc + zr, eye])
    vals = np.concatenate([av, bv, bv, -zv, -zv, np.ones(col)])
    n_tot = n_loc + n_u + col
    lu = LocalFactor.from_coo(rows, cols, vals, n_tot, scaling=saddle_point_scaling(ops.scale, n_loc, n_u, col))
    return space, lu, Z, aux_cols, n_loc, n_u


def _unpack(space: LocalSpace, x: np.ndarray, n_loc: int, n_u: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell-major DG stresses (|ω|, 30, k) and displacements (|ω|, 6, k) of patch solutions x."""
    k = x.shape[1]
    nc = space.cells.size
    sigma = space.apply(x[:n_loc])
    u = x[n_loc : n_loc + n_u].reshape(nc, 6, k)
    return sigma, u


def cell_coarse(grid: CoarseGrid) -> np.ndarray:
    """The coarse cell of each fine Ω₁ cell."""
    out = np.full(sum(len(c) for c in grid.cells), -1, dtype=np.int64)
    for k in range(grid.size):
        out[np.asarray(grid.cells[k], dtype=np.int64)] = k
    return out


def _coarse_distance(grid: CoarseGrid, k: int) -> np.ndarray:
    """Layers from coarse cell k: the least m with K_j in K_{k,m}, for every coarse cell j."""
    dist = np.full(grid.size, -1, dtype=np.int64)
    m = 0
    while np.any(dist < 0):
        reached = np.asarray(grid.patch(k, m), dtype=np.int64)
        dist[reached[dist[reached] < 0]] = m
        m += 1
        if m > grid.size:
            raise RuntimeError("the coarse patches do not reach every coarse cell")
    return dist


def basis_decay_profile(ops: CellOperators, topo: Topology, grid: CoarseGrid, aux: StageI, k: int) -> np.ndarray:
    """How fast the Stage II bases of coarse cell ``k`` decay: entry d−1 is √(A-energy at coarse distance ≥ d
    / total A-energy), maximized over the cell's bases, for the *global* bases (the patch is all of Ω₁).

    A diagnostic (it factorizes the whole Ω₁ saddle-point system): the localization error of m
    layers follows the profile at d ≈ m (benchmarks/mixed_ms_localization.py).
    """
    space, lu, Z, aux_cols, n_loc, n_u = patch_system(ops, topo, grid, aux, np.arange(grid.size))
    try:
        lk = aux.modes[k].shape[2]
        rhs = np.zeros((n_loc + n_u + Z.shape[1], lk))
        rhs[n_loc : n_loc + n_u] = -Z[:, aux_cols[int(k)] : aux_cols[int(k)] + lk].toarray()
        sigma, _ = _unpack(space, lu.solve(rhs), n_loc, n_u)
    finally:
        lu.destroy()
    energy = np.einsum("cak,cab,cbk->ck", sigma, ops.K[space.cells], sigma)
    dist = _coarse_distance(grid, k)[cell_coarse(grid)[space.cells]]
    total = energy.sum(axis=0)
    return np.array([np.sqrt(energy[dist >= d].sum(axis=0) / total).max() for d in range(1, int(dist.max()) + 1)])
