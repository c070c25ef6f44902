"""Distributed linear algebra for the mixed (Arnold–Winther) method: layouts, PETSc operators, small replicated data.

The mixed method keeps its state as NumPy arrays of the *owned* entries on each
rank (in serial: the whole vectors) and its bulk operators as distributed PETSc
matrices; :class:`DistributedMatrix` lets ``A @ x`` and ``A.T @ y`` act on such
arrays.  Data that live on Γ_C or γ (a few hundred or thousand values) are kept
*replicated*: every rank holds the same array (``gather_rows``), so that decisions
taken from them (active sets, line-search breakpoints) are the same on every rank.

Layouts follow PETSc: each rank owns a contiguous block of the global numbering,
``offsets[r] <= i < offsets[r + 1]``; a replicated array of length n handed to a
PETSc operator is split with :func:`split_sizes` (PETSc's own ``DECIDE`` rule).
"""

from __future__ import annotations

import dolfinx.la
import numpy as np
import numpy.typing as npt
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

__all__ = [
    "DistributedMatrix",
    "SaddlePointMatrix",
    "coo_matrix",
    "gather_rows",
    "global_dot",
    "layout",
    "offsets",
    "owner_of",
    "scatter_to_ghosts",
    "split_sizes",
]


def offsets(comm: MPI.Comm, n_local: int) -> np.ndarray:
    """Start of every rank's block and the global size: array of length comm.size + 1."""
    sizes = comm.allgather(int(n_local))
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def split_sizes(n: int, size: int) -> np.ndarray:
    """PETSc's DECIDE split of n entries over ``size`` ranks: block lengths."""
    return np.array([n // size + (1 if r < n % size else 0) for r in range(size)], dtype=np.int64)


def layout(comm: MPI.Comm, n: int) -> tuple[int, int]:
    """(start, end) of this rank's block of a length-n array in the DECIDE split."""
    starts = np.concatenate([[0], np.cumsum(split_sizes(n, comm.size))])
    return int(starts[comm.rank]), int(starts[comm.rank + 1])


def owner_of(indices: npt.ArrayLike, offs: np.ndarray) -> np.ndarray:
    """Rank owning each global index, for block offsets ``offs``."""
    return (np.searchsorted(offs, np.asarray(indices, dtype=np.int64), side="right") - 1).astype(np.int32)


def global_dot(comm: MPI.Comm, a: np.ndarray, b: np.ndarray) -> float:
    """Σ aᵢbᵢ over the owned entries of all ranks (no BLAS: its threads contend with MUMPS on small machines)."""
    local = float(np.einsum("i,i->", a, b))
    return local if comm.size == 1 else float(comm.allreduce(local, op=MPI.SUM))


def scatter_to_ghosts(index_map, values: np.ndarray) -> np.ndarray:
    """Integer data (n_owned, bs) of owned entities, extended to the ghosts by their owners' values.

    Returns (n_owned + n_ghosts, bs).  Exact for |values| < 2⁵³ (sent as float64 by a DOLFINx vector).
    """
    values = np.asarray(values, dtype=np.int64)
    n_own = index_map.size_local
    bs = values.shape[1]
    vec = dolfinx.la.vector(index_map, bs, dtype=np.float64)
    vec.array[: n_own * bs] = values.ravel()
    vec.array[n_own * bs :] = -1.0
    vec.scatter_forward()
    return np.rint(vec.array).astype(np.int64).reshape(-1, bs)


def gather_rows(comm: MPI.Comm, rows: np.ndarray, values: np.ndarray, n: int) -> np.ndarray:
    """Replicated array of length n (or (n, ...)) from the rows each rank holds (every row held by one rank)."""
    values = np.asarray(values)
    if comm.size == 1:
        out = np.zeros((n,) + values.shape[1:], dtype=values.dtype)
        out[rows] = values
        return out
    all_rows = comm.allgather(np.asarray(rows, dtype=np.int64))
    all_values = comm.allgather(values)
    out = np.zeros((n,) + values.shape[1:], dtype=values.dtype)
    for r, v in zip(all_rows, all_values):
        out[r] = v
    return out


def coo_matrix(
    comm: MPI.Comm,
    rows: np.ndarray,
    cols: np.ndarray,
    values: np.ndarray,
    row_sizes: tuple[int, int],
    col_sizes: tuple[int, int],
) -> PETSc.Mat:
    """Assembled AIJ matrix from global COO triplets (any rank may hold any entry; duplicates are summed).

    ``row_sizes`` / ``col_sizes``: (local, global) sizes (local may be ``PETSc.DECIDE``).
    """
    A = PETSc.Mat().createAIJ((row_sizes, col_sizes), comm=comm)
    A.setPreallocationCOO(np.asarray(rows, dtype=PETSc.IntType), np.asarray(cols, dtype=PETSc.IntType))
    A.setValuesCOO(np.asarray(values, dtype=PETSc.ScalarType), addv=PETSc.InsertMode.INSERT_VALUES)
    A.assemble()
    return A


def local_rows_to_petsc(
    comm: MPI.Comm, A: sp.csr_matrix, col_global: np.ndarray, col_sizes: tuple[int, int]
) -> PETSc.Mat:
    """AIJ matrix whose owned rows are the rows of A (local), column j of A being global column col_global[j]."""
    A = sp.csr_matrix(A)
    col_global = np.asarray(col_global)
    if A.shape[1] == col_sizes[1] and np.array_equal(col_global, np.arange(A.shape[1])) and A.has_canonical_format:
        G = A  # (serial) the columns are the global ones already; createAIJ copies the arrays
    elif A.has_canonical_format and np.all(np.diff(col_global) > 0):  # no duplicates, order kept
        G = sp.csr_matrix((A.data, col_global[A.indices], A.indptr), shape=(A.shape[0], col_sizes[1]))
    else:
        # copies: sum_duplicates / sort_indices below reorder G's arrays in place, which must not touch A's
        G = sp.csr_matrix((A.data.copy(), col_global[A.indices], A.indptr.copy()), shape=(A.shape[0], col_sizes[1]))
        G.sum_duplicates()
        G.sort_indices()
    nrows = int(comm.allreduce(A.shape[0], op=MPI.SUM)) if comm.size > 1 else A.shape[0]
    M = PETSc.Mat().createAIJ(
        size=((A.shape[0], nrows), col_sizes),
        csr=(G.indptr.astype(PETSc.IntType, copy=False), G.indices.astype(PETSc.IntType, copy=False), G.data),
        comm=comm,
    )
    M.assemble()
    return M


class _Transposed:
    def __init__(self, parent: "DistributedMatrix") -> None:
        self._parent = parent

    def __matmul__(self, y: np.ndarray) -> np.ndarray:
        p = self._parent
        p._y.array[:] = y
        p.mat.multTranspose(p._y, p._x)
        return p._x.array.copy()


class DistributedMatrix:
    """A distributed PETSc matrix acting on NumPy arrays of owned entries: ``A @ x``, ``A.T @ y`` (collective)."""

    def __init__(self, mat: PETSc.Mat) -> None:
        self.mat = mat
        self._x, self._y = mat.createVecs()  # right (column layout), left (row layout)

    @property
    def shape(self) -> tuple[int, int]:
        """Global shape."""
        return self.mat.getSize()

    @property
    def local_shape(self) -> tuple[int, int]:
        """Owned rows × owned columns (of the column layout)."""
        return self.mat.getLocalSize()

    @property
    def T(self) -> _Transposed:
        return _Transposed(self)

    def local_csr(self) -> sp.csr_matrix:
        """The owned rows as SciPy CSR with global column indices (in serial: the whole matrix)."""
        indptr, indices, data = self.mat.getValuesCSR()
        return sp.csr_matrix((data.copy(), indices.copy(), indptr.copy()), shape=(self.local_shape[0], self.shape[1]))

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        self._x.array[:] = x
        self.mat.mult(self._x, self._y)
        return self._y.array.copy()

    def destroy(self) -> None:
        for obj in (self.mat, self._x, self._y):
            obj.destroy()


def _pair_pattern(Q: sp.csr_matrix, T: sp.csr_matrix):
    """Per node q with rows R_0 = Q_q, R_1 = T_q on the union of their columns: the node of each entry, the values
    of the 4 products R_a ⊗ R_b (4, entries; ab = 00, 01, 10, 11) and the entries' rows and columns."""
    nodes, values, rows, cols = [], [], [], []
    for q in range(Q.shape[0]):
        iq, it = Q.indices[Q.indptr[q] : Q.indptr[q + 1]], T.indices[T.indptr[q] : T.indptr[q + 1]]
        idx = np.union1d(iq, it).astype(np.int64)
        if idx.size == 0:
            continue
        R = np.zeros((2, idx.size))
        R[0, np.searchsorted(idx, iq)] = Q.data[Q.indptr[q] : Q.indptr[q + 1]]
        R[1, np.searchsorted(idx, it)] = T.data[T.indptr[q] : T.indptr[q + 1]]
        values.append(np.stack([np.outer(R[a], R[b]).ravel() for a in (0, 1) for b in (0, 1)]))
        rows.append(np.repeat(idx, idx.size))
        cols.append(np.tile(idx, idx.size))
        nodes.append(np.full(idx.size**2, q, dtype=np.int64))
    if not nodes:
        return np.zeros(0, np.int64), np.zeros((4, 0)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(nodes), np.concatenate(values, axis=1), np.concatenate(rows), np.concatenate(cols)


class SaddlePointMatrix:
    """[[K + D, Bᵀ], [B, 0]] as one AIJ matrix with a fixed pattern, D = Σ_q d_q (Q_q)ᵀQ_q changing with the weights d.

    The unknowns are (x, y) with x in the column layout of K and y in the row layout of B;
    each rank owns its x block followed by its y block (the layout of a PETSc MatNest
    turned into AIJ).  The pattern holds every penalty entry, so a change of weights
    only changes values: a direct solver redoes the numeric factorization, not the
    analysis.  ``Q_rows``: the penalty rows this rank holds, with global columns of K.
    """

    def __init__(
        self, K: PETSc.Mat, B: PETSc.Mat, Q_rows: sp.csr_matrix | None = None, T_rows: sp.csr_matrix | None = None
    ) -> None:
        comm = K.getComm().tompi4py()
        self.comm = comm
        nx, ny = K.getLocalSize()[0], B.getLocalSize()[0]
        self.nx, self.ny = nx, ny
        ox, oy = offsets(comm, nx), offsets(comm, ny)
        self._ox, self._oy = ox, oy

        self._pen_entry_node = np.zeros(0, dtype=np.int64)
        self._pen_values = np.zeros(0)
        self._pairs = T_rows is not None  #: 2 × 2 weights per node (normal and tangential rows)
        self._base = np.zeros(0)
        #: no penalty on any rank: the values are fixed (the same on every rank: set_weights is collective)
        penalized = any(R is not None and R.nnz > 0 for R in (Q_rows, T_rows))
        self._fixed = not comm.allreduce(penalized, op=MPI.LOR)
        if self._fixed:
            # no penalty on any rank: the values never change; MatNest -> AIJ (same layout) holds no COO
            # maps and no copy of the values (about 3x less memory than the COO assembly below)
            Bt = B.transpose(PETSc.Mat())  # (no argument: in place)
            nest = PETSc.Mat().createNest([[K, Bt], [B, None]], comm=K.getComm())
            self.mat = nest.convert(PETSc.Mat.Type.AIJ, PETSc.Mat())  # (no out: in place)
            self.mat.assemble()  # (the MPI conversion leaves it unassembled)
            for obj in (nest, Bt):
                obj.destroy()
            return

        def xmap(i):  # global x index -> saddle index
            return i + oy[owner_of(i, ox)]

        def ymap(i):
            return i + ox[owner_of(i, oy) + 1]

        ki, kj, kv = K.getValuesCSR()
        bi, bj, bv = B.getValuesCSR()
        krows = ox[comm.rank] + np.repeat(np.arange(nx, dtype=np.int64), np.diff(ki))
        brows = oy[comm.rank] + np.repeat(np.arange(ny, dtype=np.int64), np.diff(bi))
        kj, bj = kj.astype(np.int64), bj.astype(np.int64)
        rows = [xmap(krows), ymap(brows), xmap(bj)]
        cols = [xmap(kj), xmap(bj), ymap(brows)]
        self._base = np.concatenate([kv, bv, bv])
        if self._pairs:
            self._pen_entry_node, self._pen_values, r, c = _pair_pattern(sp.csr_matrix(Q_rows), sp.csr_matrix(T_rows))
            rows.append(xmap(r))
            cols.append(xmap(c))
        elif Q_rows is not None and Q_rows.nnz:
            Q = sp.csr_matrix(Q_rows)
            counts = np.diff(Q.indptr)
            node_parts, r_parts, c_parts, v_parts = [], [], [], []
            for q in np.flatnonzero(counts):
                idx = Q.indices[Q.indptr[q] : Q.indptr[q + 1]].astype(np.int64)
                val = Q.data[Q.indptr[q] : Q.indptr[q + 1]]
                r_parts.append(np.repeat(idx, idx.size))
                c_parts.append(np.tile(idx, idx.size))
                v_parts.append(np.outer(val, val).ravel())
                node_parts.append(np.full(idx.size**2, q, dtype=np.int64))
            self._pen_entry_node = np.concatenate(node_parts)
            self._pen_values = np.concatenate(v_parts)
            rows.append(xmap(np.concatenate(r_parts)))
            cols.append(xmap(np.concatenate(c_parts)))
        N = int(ox[-1] + oy[-1])
        self.mat = PETSc.Mat().createAIJ(((nx + ny, N), (nx + ny, N)), comm=comm)
        self.mat.setPreallocationCOO(
            np.concatenate(rows).astype(PETSc.IntType), np.concatenate(cols).astype(PETSc.IntType)
        )
        self.set_weights(None)

    def set_weights(self, weights: np.ndarray | None) -> None:
        """Values for penalty weights d (one per local row of ``Q_rows``; with ``T_rows`` a 2 × 2 matrix W_q per
        node, D = Σ_q [Q_q; T_q]ᵀ W_q [Q_q; T_q]; None: D = 0)."""
        if self._fixed:  # no penalty anywhere (MatNest conversion): the values are fixed
            return
        if self._pairs and self._pen_entry_node.size:
            values = self._base.copy()
            if weights is not None:  # Σ_ab W[q, a, b] R_a ⊗ R_b over each node's 4 products of rows
                w = np.asarray(weights, dtype=np.float64).reshape(-1, 4)[self._pen_entry_node]
                values = np.concatenate([self._base, np.einsum("ek,ke->e", w, self._pen_values)])
            else:
                values = np.concatenate([self._base, np.zeros(self._pen_entry_node.size)])
        elif self._pen_values.size:
            w = np.zeros(0) if weights is None else np.asarray(weights, dtype=np.float64)
            pen = self._pen_values * w[self._pen_entry_node] if w.size else np.zeros_like(self._pen_values)
            values = np.concatenate([self._base, pen])
        else:
            values = self._base
        self.mat.setValuesCOO(values.astype(PETSc.ScalarType), addv=PETSc.InsertMode.INSERT_VALUES)

    def create_vecs(self) -> tuple[PETSc.Vec, PETSc.Vec]:
        """(rhs, solution) vectors: the first ``nx`` local entries are x, the next ``ny`` are y."""
        return self.mat.createVecs()

    def destroy(self) -> None:
        self.mat.destroy()
