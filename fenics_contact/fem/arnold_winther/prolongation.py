"""The prolongation P: AW coefficients -> coefficients of the DG P3 stress space, built from per-cell blocks.

Each owned cell's block of the *full* P (its nodal basis at the DG nodes, ``local_nodal_basis``) is
kept; the CSR matrices P_full and P = P_full T (+ the split-interface functions on their side) are made
when first asked for, row by row from the blocks, so that a caller needing a few rows (the interface maps
of Algorithm 4's Ω₁) never pays for the whole matrix.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.fem.arnold_winther.numbering import DofNumbering
from fenics_contact.fem.distributed import local_rows_to_petsc

__all__ = ["Prolongation", "cell_rows_csr"]


def cell_rows_csr(sblocks: np.ndarray, rows: np.ndarray, scols: np.ndarray, shape: tuple[int, int]) -> sp.csr_matrix:
    """CSR matrix with rows[c, i] holding sblocks[c, i, :] at columns scols[c] (each row in one cell), sorted.

    Each cell's columns ``scols[c]`` increasing.  Built straight from the cell blocks (no COO
    conversion) when the cells' rows cover 0..shape[0]-1 once; when they are 0, 1, 2, … in cell-major order
    (a serial DG numbering) the matrix's data is a view of ``sblocks`` (no copy).
    """
    nc, a, b = sblocks.shape
    flat = rows.ravel()
    if flat.size != shape[0] or not np.array_equal(np.bincount(flat, minlength=shape[0]), np.ones(shape[0], np.int64)):
        P = sp.csr_matrix(
            (sblocks.ravel(), (np.repeat(rows, b, axis=1).ravel(), np.tile(scols, (1, a)).ravel())), shape=shape
        )
        P.sort_indices()
        return P
    if np.array_equal(flat, np.arange(shape[0])):
        data = sblocks.reshape(-1)
        indices = np.repeat(scols, a, axis=0).ravel()
    else:
        where = np.empty(shape[0], dtype=np.int64)
        where[flat] = np.arange(flat.size)  # row -> (cell, i) position
        data = sblocks.reshape(-1, b)[where].ravel()
        indices = scols[where // a].ravel()
    return sp.csr_matrix((data, indices, b * np.arange(shape[0] + 1, dtype=np.int64)), shape=shape)


class Prolongation:
    """P_full (full local AW -> owned DG) and P = P_full T (+ split functions), made when first asked for.

    ``cell_blocks`` (n_c, 30, 24) and ``cell_cols`` (n_c, 24): each owned cell's rows of P_full at its
    (increasing) full AW columns; ``dg_rows`` (n_c, 30) the DG coefficient of each row.  ``full_csr``,
    ``csr`` and ``petsc`` are None until made (``release`` drops them; the cell blocks stay).
    """

    def __init__(
        self,
        comm: MPI.Comm,
        cell_blocks: np.ndarray,
        cell_cols: np.ndarray,
        dg_rows: np.ndarray,
        n_dg: int,
        num_dofs_full: int,
        numbering: DofNumbering,
        split_cells: np.ndarray | None,
    ) -> None:
        self.comm = comm
        self.cell_blocks, self.cell_cols, self.dg_rows = cell_blocks, cell_cols, dg_rows
        self.n_dg, self.num_dofs_full = n_dg, num_dofs_full
        self.numbering = numbering
        self.split_cells = split_cells  #: owned cells on the split side of γ (None without a split)
        self.full_csr: sp.csr_matrix | None = None
        self.csr: sp.csr_matrix | None = None
        self.petsc: PETSc.Mat | None = None

    @property
    def full(self) -> sp.csr_matrix:
        """P_full (SciPy CSR), made once."""
        if self.full_csr is None:
            self.full_csr = cell_rows_csr(
                self.cell_blocks, self.dg_rows, self.cell_cols, (self.n_dg, self.num_dofs_full)
            )
        return self.full_csr

    def _constrain_rows(self, P_full: sp.csr_matrix, split_cells: np.ndarray | None) -> sp.csr_matrix:
        """P = P_full T (+ the split-interface functions on ``split_cells``), row by row from ``P_full``."""
        T = self.numbering.T_local
        P = P_full if T is None else (P_full @ T).tocsr()
        if split_cells is not None:
            mask = np.zeros(self.n_dg)
            mask[self.dg_rows[split_cells].ravel()] = 1.0
            P = (P + sp.diags(mask) @ P_full @ self.numbering.X_local).tocsr()
        P.sort_indices()
        return P

    @property
    def matrix(self) -> sp.csr_matrix:
        """P (SciPy CSR): owned DG coefficients × local AW coefficients (owned, then ghosts), made once."""
        if self.csr is None:
            self.csr = self._constrain_rows(self.full, self.split_cells)
        return self.csr

    def for_rows(self, rows: npt.ArrayLike) -> sp.csr_matrix:
        """P where it has been made; else P's rows in the cells holding the given DG rows, the other rows empty."""
        if self.csr is not None:
            return self.csr
        num_cells = self.dg_rows.shape[0]
        cell_of = np.empty(self.n_dg, dtype=np.int64)
        cell_of[self.dg_rows.ravel()] = np.repeat(np.arange(num_cells), self.dg_rows.shape[1])
        cells = np.unique(cell_of[np.asarray(rows, dtype=np.int64)])
        P_full = cell_rows_csr(
            self.cell_blocks[cells], self.dg_rows[cells], self.cell_cols[cells], (self.n_dg, self.num_dofs_full)
        )
        split = None if self.split_cells is None else np.intersect1d(self.split_cells, cells)
        return self._constrain_rows(P_full, split)

    def petsc_matrix(self) -> PETSc.Mat:
        """P as a distributed PETSc AIJ matrix (global AW numbering; created once)."""
        if self.petsc is None:
            num = self.numbering
            self.petsc = local_rows_to_petsc(
                self.comm, self.matrix, num.global_indices, (num.num_owned, int(num.offsets[-1]))
            )
        return self.petsc

    def release(self) -> None:
        """Drop the CSR (and PETSc) P and P_full (made again when asked for); the cell blocks stay."""
        self.full_csr = self.csr = None
        if self.petsc is not None:
            self.petsc.destroy()
            self.petsc = None
