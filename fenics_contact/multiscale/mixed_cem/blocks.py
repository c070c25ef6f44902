"""The cell-major layout of the mixed CEM (Algorithm 4): dense cell blocks of sparse operators and back.

A stress is an array (n_cells, 30) of DG P3 coefficients, a displacement (n_cells, 6) of DG P1 coefficients;
every volume operator is block diagonal in this layout.  ``cell_blocks`` reads the diagonal blocks of such an
operator (off the CSR arrays where the pattern allows, without a copy), ``row_blocks`` / ``column_blocks`` the
nonzero columns of a cell's rows (the AW prolongation), ``block_diag`` assembles blocks back, ``cell_rows``
numbers the rows of a set of cells.
"""

import numpy as np
import scipy.sparse as sp

__all__ = ["block_diag", "cell_blocks", "cell_rows", "column_blocks", "row_blocks"]


def _csr_cell_blocks(A: sp.csr_matrix, rows: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """(values, columns), each (n, a, b): the CSR entries of the cells' rows ``rows`` (n, a), every one of which holds
    b entries.  Where every row of A holds b entries and each cell's rows are a whole block of a consecutive rows
    (a DG form, the AW prolongation on a serial mesh), the CSR arrays are the blocks already: views when the
    cells come in row order, one gather of blocks otherwise; else one (n, a, b) index gather."""
    n, a = rows.shape
    first = rows[:, 0]
    if (
        A.shape[0] % a == 0
        and np.all(np.diff(A.indptr) == b)
        and np.all(first % a == 0)
        and np.array_equal(rows - first[:, None], np.broadcast_to(np.arange(a), rows.shape))
    ):
        data, ind = A.data.reshape(-1, a, b), A.indices.reshape(-1, a, b)
        k = first // a
        if not (k.size == data.shape[0] and np.array_equal(k, np.arange(k.size))):
            data, ind = data[k], ind[k]
        return data, ind
    at = A.indptr[rows][..., None] + np.arange(b)  # (n, a, b)
    return A.data[at], A.indices[at]


def cell_blocks(A: sp.spmatrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Diagonal blocks (n, a, b) of a cellwise operator: A[rows[c]][:, cols[c]] (zero blocks allowed).

    Where every row of A holds b entries and the cells' rows are the consecutive blocks of A's rows in order
    (a DG form on a serial mesh), the result is a view of ``A.data`` (no copy).
    """
    n, a = rows.shape
    b = cols.shape[1]
    A = sp.csr_matrix(A)
    if n and A.has_sorted_indices and np.all(np.diff(A.indptr)[rows] == b):
        # each row holds exactly its cell's columns (a DG form's pattern): read the blocks off the CSR arrays
        order = np.argsort(cols, axis=1)
        data, ind = _csr_cell_blocks(A, rows, b)
        if np.array_equal(ind, np.broadcast_to(np.take_along_axis(cols, order, axis=1)[:, None, :], ind.shape)):
            if np.all(np.diff(cols, axis=1) > 0):  # the cells' columns in increasing order: no permutation
                return data
            inverse = np.argsort(order, axis=1)
            return np.take_along_axis(data, inverse[:, None, :], axis=2)
    Ap = A[rows.ravel()][:, cols.ravel()].tobsr(blocksize=(a, b))
    out = np.zeros((n, a, b))
    brow = np.repeat(np.arange(n), np.diff(Ap.indptr))
    if not np.array_equal(brow, Ap.indices):
        raise RuntimeError("the operator is not block diagonal in the cell-major layout")
    out[brow] = Ap.data
    return out


def block_diag(blocks: np.ndarray) -> sp.csr_matrix:
    """The block-diagonal CSR matrix of dense blocks (n, a, b)."""
    n, a, b = blocks.shape
    rows = np.broadcast_to((a * np.arange(n)[:, None, None] + np.arange(a)[None, :, None]), blocks.shape)
    cols = np.broadcast_to((b * np.arange(n)[:, None, None] + np.arange(b)[None, None, :]), blocks.shape)
    return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n * a, n * b))


def cell_rows(cells: np.ndarray, width: int) -> np.ndarray:
    """The cell-major rows of ``cells`` in a layout of ``width`` rows per cell (cell by cell, in order)."""
    return (width * np.asarray(cells, dtype=np.int64)[:, None] + np.arange(width)).ravel()


def column_blocks(P: sp.spmatrix, ncell: int, a: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell blocks of a matrix with ``a`` cell-major rows per cell: nonzero columns (n, w), −1 padded, and values."""
    P = sp.csr_matrix(P, copy=True)
    P.sum_duplicates()
    P.eliminate_zeros()
    ncol = P.shape[1]
    # the columns met by each cell's rows, sorted: the pattern of (row sums per cell) · P
    R = sp.csr_matrix(
        (np.ones(a * ncell), (np.repeat(np.arange(ncell), a), np.arange(a * ncell))), shape=(ncell, a * ncell)
    )
    pattern = R @ sp.csr_matrix((np.ones(P.nnz), P.indices, P.indptr), shape=P.shape)
    pattern.sort_indices()
    counts = np.diff(pattern.indptr)
    ucell = np.repeat(np.arange(ncell), counts)
    cols = np.full((ncell, int(counts.max(initial=0))), -1, dtype=np.int64)
    cols[ucell, np.arange(pattern.nnz) - pattern.indptr[ucell]] = pattern.indices
    row = np.repeat(np.arange(P.shape[0]), np.diff(P.indptr))
    cell = row // a
    slot = np.searchsorted(ucell * ncol + pattern.indices, cell * ncol + P.indices) - pattern.indptr[cell]
    blocks = np.zeros((ncell, a, cols.shape[1]))
    blocks[cell, row % a, slot] = P.data
    return cols, blocks


def row_blocks(P: sp.spmatrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``column_blocks(P[rows.ravel()], ...)`` read straight from the CSR arrays when every cell's rows hold
    the same sorted columns (as the AW prolongation's rows do: each DG row lives in one cell); else that."""
    P = sp.csr_matrix(P)
    counts = np.diff(P.indptr)[rows]  # (n, a)
    w = int(counts[0, 0]) if counts.size else 0
    if P.has_sorted_indices and counts.size and np.all(counts == w):
        # (views of the CSR arrays for Ω₁'s serial DG numbering: no (n, a, w) index array, 173 MB at h = 1/128)
        data, ind = _csr_cell_blocks(P, rows, w)
        cols = ind[:, 0].astype(np.int64)
        if np.array_equal(ind, np.broadcast_to(cols[:, None, :], ind.shape)):
            return cols, data
    return column_blocks(P[rows.ravel()], rows.shape[0], rows.shape[1])
