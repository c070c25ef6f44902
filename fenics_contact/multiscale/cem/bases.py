"""The patch problems of the primal CEM (Algorithm 3): relaxed CEM bases, Robin and source correctors, V_ms.

On the patch K_{i,m} (K_i extended by m coarse layers), for all v ∈ V_h⁰(K_{i,m}):

    a(ψ, v) + α ∫_γ ψ·v ds + s(πψ, πv) = s(φ_j^i, πv)                      (relaxed CEM basis)
    a(N_i g, v) + α ∫_γ N_i g·v ds + s(πN_i g, πv) = ∫_{γ∩∂K_i} g·v ds      (Robin corrector)
    a(N_f,i, v) + α ∫_γ N_f,i·v ds + s(πN_f,i, πv) = ℓ_i(v)                (source corrector)

solved in the sparse saddle-point form [[A_II, B_IJ], [B_IJᵀ, −I]] (μ = B_IJᵀ x; B = the columns S_k Φ_k of
the aux functions of the patch's cells): A_II + B_IJ B_IJᵀ has a dense block per coarse cell, 45× the nonzeros
of A_II at h = 1/256.  One MUMPS LDLᵀ per patch serves the l_i bases, the Robin correctors of the γ vertices of
K_i and the source corrector (one solve with many right-hand sides, given to MUMPS as sparse: a unit vector in
the μ rows per basis, a few γ rows per Robin datum; ``SparseFactor.solve_sparse``).  With ``CEMOptions.patch_group`` the
cells of a group share one patch, the union of their K_{i,m} (``cell_groups``), and one LDLᵀ serves all their
problems (a γ vertex shared by cells of the group: one Robin datum, their γ-masses summed); ``covering`` gives the
cells whose functions reach a coarse cell.  The functions of a patch problem are stored side by side
(``MultiscaleSpace.blocks``: the DOFs and one dense row-major block, of which each cell's bases and the group's
Robin correctors are views; ``split_block``), never as fine-mesh-sized arrays.
"""

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.fem.heap import retained_heap
from fenics_contact.fem.linalg import SolveBuffer, SparseFactor
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.multiscale.cem.equations import patch_equations
from fenics_contact.multiscale.cem.operators import FineOperators
from fenics_contact.multiscale.cem.options import WHOLE_DOMAIN, CEMOptions
from fenics_contact.multiscale.cem.spectral import AuxiliarySpace, build_auxiliary_space
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.work import run_shared

__all__ = [
    "EQUATIONS_GRAM_DIMS",
    "METIS_FROM_3D",
    "PATCH_ICNTL",
    "Incidence",
    "MultiscaleSpace",
    "PatchFunctions",
    "build_multiscale_space",
    "cell_groups",
    "covering",
    "global_saddle_matrix",
    "patch_icntl",
    "split_block",
    "split_blocks",
]

log = logging.getLogger(__name__)


class Incidence:
    """Fine vertex ↔ coarse cell incidence: the DOFs of a coarse cell, the interior DOFs of a patch."""

    def __init__(self, ops: FineOperators, grid: CoarseGrid) -> None:
        num_nodes = ops.node_dofs.shape[0]
        nv = ops.cell_nodes.shape[1]
        inc = sp.csr_matrix(
            (np.ones(ops.cell_nodes.size), (ops.cell_nodes.ravel(), np.repeat(grid.cell_coarse, nv))),
            shape=(num_nodes, grid.size),
        )
        inc.sum_duplicates()
        inc.data[:] = 1.0
        inc.sort_indices()
        self.node_cells = inc  #: node × coarse cell
        self.cell_nodes = inc.T.tocsr()  #: coarse cell × node
        self.cell_nodes.sort_indices()
        self.count = np.diff(inc.indptr)  #: coarse cells at each node
        #: the coarse cell a node's load is given to (the first one containing it)
        self.load_owner = inc.indices[inc.indptr[:-1]]
        self.bs = ops.bs
        self.free = ops.free

    def nodes(self, k: int) -> np.ndarray:
        """Vertices of K_k (sorted)."""
        return self.cell_nodes.indices[self.cell_nodes.indptr[k] : self.cell_nodes.indptr[k + 1]]

    def dofs(self, k: int, *, free_only: bool = True) -> np.ndarray:
        """Scalar DOFs of the vertices of K_k (sorted)."""
        d = (self.bs * self.nodes(k)[:, None] + np.arange(self.bs)).ravel()
        return d[self.free[d]] if free_only else d

    def interior_dofs(self, patch: np.ndarray) -> np.ndarray:
        """Free DOFs of the vertices all of whose coarse cells lie in the patch (sorted)."""
        member = np.zeros(self.node_cells.shape[1])
        member[patch] = 1.0
        inside = np.flatnonzero(np.rint(self.node_cells @ member).astype(np.int64) == self.count)
        d = (self.bs * inside[:, None] + np.arange(self.bs)).ravel()
        return d[self.free[d]]


@dataclass(slots=True)
class PatchFunctions:
    """Functions supported on one patch: values (|dofs| × k) at the sorted Ω₁ DOFs ``dofs``; global ``columns``."""

    dofs: np.ndarray
    values: np.ndarray
    columns: np.ndarray

    def add_to(self, u: np.ndarray, coefficients: np.ndarray) -> None:
        """u += Σ_j coefficients[columns[j]] · function j."""
        u[self.dofs] += self.values @ coefficients[self.columns]


@dataclass(slots=True)
class MultiscaleSpace:
    """V_ms = span{ψ_j^i} (``basis``, one PatchFunctions per coarse cell, columns = aux indices), the
    Robin correction N (``correction``: γ DOF positions → Ω₁ fields, one per patch problem whose cells touch γ)
    and the source correction N_f (an Ω₁ vector, None when switched off)."""

    aux: AuxiliarySpace
    basis: list
    correction: list
    Nf: np.ndarray | None
    layers: int
    n: int  #: Ω₁ DOFs
    n_gamma: int  #: γ DOFs
    correction_cells: np.ndarray  #: the first coarse cell of the group whose patch problem gave each ``correction``
    times: dict = field(default_factory=dict)
    #: (ZᵀKZ, ZᵀMZ) for Z = [Ψ, N, N_f] (``coarse.gram_matrices``) when stored with the space (the offline
    #: cache), else None (``coarse.MultiscaleRobinSolver`` forms them)
    grams: tuple | None = None
    #: ``CEMOptions.patch_group`` the bases were built with (their supports: ``covering``)
    patch_group: int | str = 1
    #: the ``equations.PatchEquations`` of the patch problems (ZᵀKZ from them, ``coarse.gram_matrices``) until the
    #: Gram matrices are formed; None on a space loaded from the cache
    equations: list | None = None
    #: the functions of each patch problem side by side (``PatchFunctions``; their Z columns: the bases of the
    #: group's cells, then its Robin correctors; ``split_block``), of which the ``basis`` and ``correction`` entries
    #: are views
    blocks: list = field(default_factory=list)
    #: the coarse cells of each patch problem (``cell_groups``), whose bases ``blocks`` holds
    groups: list = field(default_factory=list)

    @property
    def size(self) -> int:
        """dim V_ms."""
        return self.aux.size

    def apply(self, w: np.ndarray, g: np.ndarray, *, with_source: bool = True) -> np.ndarray:
        """Ψ w + N g (+ N_f) on every Ω₁ DOF."""
        u = self.Nf.copy() if (with_source and self.Nf is not None) else np.zeros(self.n)
        for pf in self.basis:
            pf.add_to(u, w)
        for pf in self.correction:
            pf.add_to(u, g)
        return u

    @staticmethod
    def _sparse(parts: list, shape: tuple) -> sp.csc_matrix:
        if not parts:
            return sp.csc_matrix(shape)
        rows = np.concatenate([np.repeat(p.dofs, p.columns.size) for p in parts])
        cols = np.concatenate([np.tile(p.columns, p.dofs.size) for p in parts])
        vals = np.concatenate([p.values.ravel() for p in parts])
        return sp.csc_matrix((vals, (rows, cols)), shape=shape)

    @property
    def Psi(self) -> sp.csc_matrix:
        """The bases as one sparse n × dim V_ms matrix (built on demand; diagnostics and tests)."""
        return self._sparse(self.basis, (self.n, self.size))

    @property
    def N(self) -> sp.csc_matrix:
        """N as one sparse n × |γ DOFs| matrix (built on demand)."""
        return self._sparse(self.correction, (self.n, self.n_gamma))

    @property
    def nbytes(self) -> int:
        """Memory held by the bases and corrections."""
        parts = self.basis + self.correction
        total = sum(p.values.nbytes + p.dofs.nbytes + p.columns.nbytes for p in parts)
        return total + (self.Nf.nbytes if self.Nf is not None else 0)


#: MUMPS controls of the patch LDLᵀ: the approximate minimum fill ordering (ICNTL(7) = 2).  Measured (CPU time, on a
#: shared machine) on model 3 at h = 1/256, H = 1/16, m = 4: the 16 patches of patch_group 4 (28k–73k DOFs) factorize
#: in 2.3–2.5 s and solve in 1.8–2.1 s with AMF against 2.8–2.9 s and 2.3–2.6 s with QAMD (ICNTL(7) = 6); on patches
#: of one cell (patch_group 1) AMF and QAMD take the same time, AMD more.  Both cope with the μ rows (one per aux
#: function, dense over its coarse cell); SuperLU and LU take several times longer.
PATCH_ICNTL = {7: 2}

#: 3D patch problems of at least this many unknowns (interior DOFs and aux functions) are ordered by METIS' nested
#: dissection (ICNTL(7) = 5, ``patch_icntl``), where AMF's fill grows with the fronts.  Measured on the channel cube
#: (H = 1/8, m = 2, one patch per cell; CPU time of a factorization, METIS against AMF, on a shared machine): METIS
#: makes 2.6–3.6× fewer flops, but its ordering costs more than that saves below ~5,500 unknowns (h = 1/16, 600–3,700
#: unknowns: the 448 patch problems 11.7 s against 9.2 s); 0.26 s against 0.37 s at 10,000 (h = 1/24: the 448 patch
#: problems 59 s against 70 s), 0.61 s against 1.21 s at 17,000 and 1.08 s against 2.79 s at 23,000 (h = 1/32).  In
#: 2D nested dissection does not pay (h = 1/256, patch_group 4, 28k–73k DOFs: 5.0–5.3 s against 1.9 s).
METIS_FROM_3D = 6000


def patch_icntl(dim: int, size: int) -> dict[int, int]:
    """The MUMPS controls of a patch LDLᵀ with ``size`` unknowns in dimension ``dim``: ``PATCH_ICNTL``, METIS'
    ordering for large 3D patches (``METIS_FROM_3D``)."""
    return {7: 5} if dim == 3 and size >= METIS_FROM_3D else PATCH_ICNTL


#: the dimensions in which ZᵀKZ comes from the patch equations (``equations.stiffness_gram``), else from products
#: with the fine stiffness: in 2D the ring terms are a small part of the products' work (model 3, h = 1/256, H =
#: 1/16, m = 4, patch_group 4: the Gram matrices take 3.7 s of CPU time against 5.2 s), in 3D a patch's ring is a
#: surface holding a large share of its DOFs and they cost more (the 16³ cube of ``channels_3d``, H = 1/8, m = 1:
#: 3.8 s of CPU time against 1.5 s)
EQUATIONS_GRAM_DIMS = (2,)


def global_saddle_matrix(ops: FineOperators, aux: AuxiliarySpace) -> PETSc.Mat:
    """[[A, B], [Bᵀ, −I]] on all Ω₁ DOFs and aux functions: every patch matrix is a principal submatrix."""
    M = sp.bmat([[ops.A, aux.B], [aux.B.T, -sp.identity(aux.size, format="csr")]], format="csr")
    return scipy_to_petsc(M)


def _patch_problem(
    ops: FineOperators,
    grid: CoarseGrid,
    aux: AuxiliarySpace,
    inc: Incidence,
    saddle: PETSc.Mat,
    group: np.ndarray,
    patch: np.ndarray,
    inner: np.ndarray,
    *,
    source: bool,
    equations: bool,
    buffer: SolveBuffer | None = None,
) -> tuple:
    """Bases and Robin corrections of the coarse cells ``group`` and their source correction, all on ``patch``
    (one LDLᵀ); returns ((the bases and Robin correctors side by side, |I| × k row-major; the first column of each
    cell's bases; the ``ops.gamma`` positions of the correctors, after the bases), the summed source correction
    or None, (factorization time, solve time), the ``PatchEquations`` or None).  ``buffer`` takes the solutions of the
    LDLᵀ (reused from one patch problem to the next)."""
    J = np.concatenate([aux.columns(k) for k in patch])
    nI, nJ = inner.size, J.size
    index = PETSc.IS().createGeneral(np.concatenate([inner, ops.size + J]).astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    try:
        M = saddle.createSubMatrix(index, index)
    finally:
        index.destroy()
    rows, cols, vals = [], [], []  # the right-hand sides' nonzeros (column, row, value: the transpose)
    starts = []  # the first column of each cell's bases
    ncols = 0
    for i in group:  # s(φ_j^i, πv): unit vectors in the μ rows
        li = int(aux.offsets[i + 1] - aux.offsets[i])
        rows.append(ncols + np.arange(li))
        cols.append(nI + np.searchsorted(J, aux.columns(i)))
        vals.append(np.ones(li))
        starts.append(ncols)
        ncols += li
    # Robin data on the γ vertices of the group's cells (γ-mass of their cells): one datum per γ DOF, the masses
    # of the cells of the group that share its vertex summed (one operator: the sum of their correctors)
    gamma_pos = np.zeros(0, dtype=np.int64)
    pieces = []
    for i in group:
        on_gamma = np.intersect1d(inc.dofs(int(i), free_only=False), ops.gamma, assume_unique=True)
        if on_gamma.size:
            pieces.append((on_gamma, ops.Gc[int(grid.colors[i])][on_gamma][:, inner].tocoo()))
    if pieces:
        on = np.unique(np.concatenate([d for d, _ in pieces]))
        G_I = sp.csr_matrix(
            (
                np.concatenate([m.data for _, m in pieces]),
                (
                    np.concatenate([np.searchsorted(on, d[m.row]) for d, m in pieces]),
                    np.concatenate([m.col for _, m in pieces]),
                ),
            ),
            shape=(on.size, nI),
        )  # (duplicates summed)
        used = np.flatnonzero(np.diff(G_I.indptr) > 0)
        G_I = G_I[used].tocoo()
        rows.append(ncols + G_I.row)
        cols.append(G_I.col)
        vals.append(G_I.data)
        gamma_pos = np.searchsorted(ops.gamma, on[used])
        ncols += used.size
    F = None
    if source:
        F = ops.corrector_load[inner] * np.isin(inc.load_owner[inner // ops.bs], group)
        if not np.any(F):
            F = None
        else:
            at = np.flatnonzero(F)
            rows.append(np.full(at.size, ncols))
            cols.append(at)
            vals.append(F[at])
    # the right-hand sides are sparse (one nonzero per basis, a few γ rows per Robin datum): MUMPS' sparse
    # right-hand sides (ICNTL(20)) skip the forward elimination where they vanish (2.5× faster solves)
    rhs_t = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(ncols + (F is not None), nI + nJ)
    )
    rhs_t.sum_duplicates()  # (canonical: sorted indices)
    M.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    t0 = time.perf_counter()
    try:  # symmetric indefinite: MUMPS LDLᵀ
        lu = SparseFactor(M, cholesky=True, icntl=patch_icntl(ops.bs, nI + nJ), what="a CEM patch problem")
    except BaseException:
        M.destroy()
        raise
    t1 = time.perf_counter()
    try:
        out = None if buffer is None else buffer.get(rhs_t.shape[0] * rhs_t.shape[1])
        solution = lu.solve_sparse(rhs_t, out=out)
    finally:
        lu.destroy()
    timing = (t1 - t0, time.perf_counter() - t1)
    # the functions side by side (row-major: a coarse cell's rows are gathered in one pass), N_f's column apart
    values = np.ascontiguousarray(solution[:nI, :ncols])
    columns = [aux.columns(i) for i in group] + [aux.size + gamma_pos]
    if F is not None:
        columns.append(np.array([aux.size + ops.gamma.size]))
    eq = None
    if equations:  # the ring: the DOFs of the patch's cells that are not interior (where A x and B μ reach outside I)
        nodes = np.unique(np.concatenate([inc.nodes(int(k)) for k in patch]))
        ring = np.setdiff1d((ops.bs * nodes[:, None] + np.arange(ops.bs)).ravel(), inner, assume_unique=True)
        eq = patch_equations(ops.A, aux.B, ring, inner, J, solution, rhs_t, np.concatenate(columns))
    source_corrector = solution[:nI, -1].copy() if F is not None else None
    return (values, np.array(starts), gamma_pos), source_corrector, timing, eq


def cell_groups(grid: CoarseGrid, options: CEMOptions, dim: int) -> tuple[list, list]:
    """(groups, patches): the coarse cells that share a patch problem (``CEMOptions.patch_group``) and the
    coarse cells of each group's patch, the union of its cells' K_{k,m}."""
    g = None if options.patch_group == WHOLE_DOMAIN else int(options.patch_group)
    groups = grid.groups(g, dim)
    return groups, [grid.group_patch(c, options.layers) for c in groups]


def covering(grid: CoarseGrid, layers: int, patch_group: int | str, dim: int) -> list:
    """For every coarse cell K the (sorted) cells whose bases may be nonzero on K: those whose patch holds K."""
    if patch_group == 1:
        return [grid.patch(K, layers) for K in range(grid.size)]
    groups, patches = cell_groups(grid, CEMOptions(layers=layers, patch_group=patch_group), dim)
    rows = np.concatenate([np.repeat(c, p.size) for c, p in zip(groups, patches)])
    cols = np.concatenate([np.tile(p, c.size) for c, p in zip(groups, patches)])
    held = sp.csc_matrix((np.ones(rows.size), (rows, cols)), shape=(grid.size, grid.size))
    held.sort_indices()
    return [held.indices[held.indptr[K] : held.indptr[K + 1]] for K in range(grid.size)]


def split_block(
    aux: AuxiliarySpace, cells: np.ndarray, dofs: np.ndarray, values: np.ndarray, gamma_pos: np.ndarray
) -> tuple:
    """(the block, the bases of each cell, the Robin correctors or None) of the functions ``values`` of one patch
    problem (|dofs| × k: the bases of ``cells`` in order, then the correctors of the γ DOFs ``gamma_pos``): the
    per-cell entries are views of the block."""
    columns = [aux.columns(int(i)) for i in cells]
    at = np.concatenate([[0], np.cumsum([c.size for c in columns])]).astype(np.int64)
    bases = [PatchFunctions(dofs, values[:, a:z], c) for a, z, c in zip(at[:-1], at[1:], columns)]
    correction = PatchFunctions(dofs, values[:, at[-1] :], gamma_pos) if gamma_pos.size else None
    return PatchFunctions(dofs, values, np.concatenate(columns + [aux.size + gamma_pos])), bases, correction


def split_blocks(aux: AuxiliarySpace, ncells: int, parts) -> tuple[list, list, list, np.ndarray]:
    """(the bases of each of the ``ncells`` coarse cells, the blocks, the Robin corrections, the first cell of the
    group of each correction) of the patch problems ``parts``, each (its cells, its DOFs, its functions, the γ
    positions of its correctors): ``split_block`` of each (a cell no part covers keeps None)."""
    basis: list = [None] * ncells
    blocks, correction, correction_cells = [], [], []
    for cells, dofs, values, gamma_pos in parts:
        block, bases, corr = split_block(aux, cells, dofs, values, gamma_pos)
        for i, pf in zip(cells, bases):
            basis[int(i)] = pf
        if corr is not None:
            correction.append(corr)
            correction_cells.append(int(cells[0]))
        blocks.append(block)
    return basis, blocks, correction, np.array(correction_cells, dtype=np.int64)


def build_multiscale_space(
    ops: FineOperators,
    grid: CoarseGrid,
    options: CEMOptions,
    *,
    aux: AuxiliarySpace | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
) -> MultiscaleSpace:
    """Offline stage: aux space, relaxed CEM bases on K_{i,m}, the corrections N and N_f (shared out over comm)."""
    times = {}
    t0 = time.perf_counter()
    if aux is None:
        aux = build_auxiliary_space(ops, grid, options, comm=comm)
    times["eigen"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    inc = Incidence(ops, grid)
    groups, patches = cell_groups(grid, options, ops.bs)
    inner = [inc.interior_dofs(p) for p in patches]
    saddle = global_saddle_matrix(ops, aux)
    equations = ops.bs in EQUATIONS_GRAM_DIMS
    # MUMPS allocates each factorization's work array afresh: kept on the heap, its pages are faulted in once
    # (``fem.heap.retained_heap``)
    with retained_heap():
        buffer = SolveBuffer()  # (one per rank: its patch problems come one after the other)
        try:
            owner = np.empty(len(groups), dtype=np.int64)
            results = run_shared(
                np.array([d.size for d in inner], dtype=np.float64) ** 1.5,
                comm,
                "CEM patch problems",
                lambda q: _patch_problem(
                    ops,
                    grid,
                    aux,
                    inc,
                    saddle,
                    groups[q],
                    patches[q],
                    inner[q],
                    source=options.source_correction,
                    equations=equations,
                    buffer=buffer,
                ),
                balanced=True,
                owner=owner,
                logger=log,
            )
        finally:
            saddle.destroy()
            buffer.release()  # (before the heap is trimmed)
    basis, blocks, correction, correction_cells = split_blocks(
        aux,
        grid.size,
        ((cells, q_inner.astype(np.int32), r[0][0], r[0][2]) for cells, q_inner, r in zip(groups, inner, results)),
    )
    Nf = None
    if options.source_correction:
        Nf = np.zeros(ops.size)
        for q, r in enumerate(results):
            if r[1] is not None:
                Nf[inner[q]] += r[1]
    if ops.lifting is not None:  # u₁ = Ψ w + N g + (N_f + u_g): the lifting rides in the last column of Z
        Nf = ops.lifting.copy() if Nf is None else Nf + ops.lifting
    times["patches"] = time.perf_counter() - t0
    # of which (summed over the ranks): the LDLᵀ factorizations and the solves with their right-hand sides
    times["patch_factor"] = float(sum(r[2][0] for r in results))
    times["patch_solve"] = float(sum(r[2][1] for r in results))
    times["total"] = times["eigen"] + times["patches"]
    times["patches_here"] = int(np.count_nonzero(owner == comm.rank))  # this rank's share
    times["patch_problems"] = len(groups)
    space = MultiscaleSpace(
        aux,
        basis,
        correction,
        Nf,
        int(options.layers),
        ops.size,
        ops.gamma.size,
        correction_cells,
        times,
        patch_group=options.patch_group,
        equations=[r[3] for r in results] if equations else None,
        blocks=blocks,
        groups=[np.asarray(c, dtype=np.int64) for c in groups],
    )
    log.info(
        "CEM offline: %d coarse cells, m = %d, dim V_ms = %d, %.1f MB of bases; eigen %.2f s, patches %.2f s",
        grid.size,
        options.layers,
        aux.size,
        space.nbytes / 1e6,
        times["eigen"],
        times["patches"],
    )
    return space
