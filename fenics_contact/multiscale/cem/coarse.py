"""The coarse (online) step of the primal CEM (Algorithm 3): Gram and trace matrices, the Robin solver.

Online everything is done in the coordinates s = (w, g, 1) of u₁ = Z s, Z = [Ψ, N, N_f]: the coarse solve
(ΨᵀAΨ factorized once, ``fem.linalg.PivotedCholesky``), the trace Z_γ s, the norms sᵀ(ZᵀKZ)s and sᵀ(ZᵀMZ)s.
ZᵀKZ comes from the patch equations the functions solve (``equations``); ZᵀMZ is summed over the coarse cells K
from dense blocks of the functions that cover K (BLAS products with the cellwise M_K, summed per pair of patch
problems: those on and above the diagonal formed, the rest mirrored), the cells shared out over the ranks and the
sums Allreduced.
"""

import logging
import time

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.fem.linalg import PivotedCholesky
from fenics_contact.multiscale.cem.bases import Incidence, MultiscaleSpace, cell_groups
from fenics_contact.multiscale.cem.equations import resolves, stiffness_gram
from fenics_contact.multiscale.cem.operators import FineOperators
from fenics_contact.multiscale.cem.options import WHOLE_DOMAIN, CEMOptions
from fenics_contact.multiscale.cem.spectral import restrict
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.work import run_shared

__all__ = ["MultiscaleRobinSolver", "gram_matrices", "trace_matrix"]

log = logging.getLogger(__name__)


#: fine DOFs per coarse cell below which ``gram_matrices`` sums blocks of coarse cells rather than single cells
#: (2D): small cells make small products whose overhead dominates.  Model 3, H = 1/16, m = 4: at h = 1/128 (130
#: Ω₁ DOFs per coarse cell) blocks of 2 × 2 cells take a fifth less time than single cells with one patch per
#: cell, the groups of 4 × 4 (their cells covered by the same functions) two-fifths less; at h = 1/256 (520 DOFs
#: per cell) blocks gain nothing.
GRAM_BLOCK_BELOW = 400


#: mean columns per patch problem from which ``gram_matrices`` sums the products per pair of patch problems (shared
#: patches: few wide blocks); below (one cell per patch problem: many narrow ones) the products of a coarse cell go
#: straight into the Gram matrices, formed in ``GRAM_PIECES`` column pieces.  Model 3, H = 1/16, m = 4 (the Gram
#: matrices' CPU time, two builds each): h = 1/256, patch_group 4 (48 bases and up to ~130 Robin correctors per patch
#: problem) 2.0–2.1 s by pairs against 2.5–3.0 s straight; patch_group 1, h = 1/128 1.2 s straight against 1.9 s
#: by pairs, h = 1/256 3.0 s against 4.6 s.
PAIRS_FROM_WIDTH = 24

#: column pieces of a coarse cell's products ZᵀW summed straight into the Gram matrices: the pieces above the
#: diagonal formed, those below mirrored ((pieces + 1) / (2 pieces) of the work of the full product)
GRAM_PIECES = 4


def _gram_block(patch_group: int | str, dim: int, dofs_per_cell: float) -> int:
    """Coarse cells per direction in a block of ``gram_matrices``: 1 unless the cells are small (2D only), then
    the patch groups (blocks of 4 for the whole domain) or blocks of 2."""
    if dim != 2 or dofs_per_cell >= GRAM_BLOCK_BELOW:
        return 1
    if patch_group == WHOLE_DOMAIN:
        return 4
    return max(int(patch_group), 2)


def _block_matrix(ops: FineOperators, grid: CoarseGrid, cells: list, cell_dofs: list, D: np.ndarray) -> sp.csr_matrix:
    """[K_S; M_S] (2|D| × |D|): the stiffness and mass matrices of the fine cells of the coarse cells ``cells``
    (DOFs ``cell_dofs`` each) on their DOFs D, summed from the colour matrices restricted cell by cell."""
    if len(cells) == 1:
        c = int(grid.colors[cells[0]])
        return sp.vstack([restrict(ops.Kc[c], D), restrict(ops.Mc[c], D)], format="csr")
    rows, cols, vals = [], [], []
    for K, DK in zip(cells, cell_dofs):
        c = int(grid.colors[K])
        pos = np.searchsorted(D, DK)
        for shift, colour_matrix in ((0, ops.Kc[c]), (D.size, ops.Mc[c])):
            m = restrict(colour_matrix, DK).tocoo()
            rows.append(shift + pos[m.row])
            cols.append(pos[m.col])
            vals.append(m.data)
    return sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * D.size, D.size)
    )


def _mass_matrix(ops: FineOperators, grid: CoarseGrid, cells: list, cell_dofs: list, D: np.ndarray) -> sp.csr_matrix:
    """M_S (|D| × |D|): the mass matrix of the fine cells of the coarse cells ``cells`` on their DOFs D."""
    if len(cells) == 1:
        return restrict(ops.Mc[int(grid.colors[cells[0]])], D)
    return _block_matrix(ops, grid, cells, cell_dofs, D)[D.size :]


def _gather(Z: np.ndarray, parts: list, at: np.ndarray, D: np.ndarray) -> None:
    """Z[:, at[j]:at[j + 1]] = the values of the patch blocks parts[j] at the DOFs D (zero where D is outside
    their DOFs): one pass over the rows of each block."""
    for p, a, z in zip(parts, at[:-1], at[1:]):
        pos = np.searchsorted(p.dofs, D)
        np.minimum(pos, p.dofs.size - 1, out=pos)
        hit = p.dofs[pos] == D
        if hit.all():  # gathered straight into Z ("clip": NumPy's unbuffered mode, the rows are in range)
            np.take(p.values, pos, axis=0, out=Z[:, a:z], mode="clip")
        else:
            index = np.flatnonzero(hit)
            Z[index, a:z] = p.values[pos[index]]


def _add_pairs(acc: dict, ids: list, at: np.ndarray, Z: np.ndarray, W: np.ndarray) -> None:
    """acc[(ids[i], ids[j])] += Z_iᵀ W_j for j ≥ i (Z_i the columns at[i]:at[i + 1]): the blocks of ZᵀW on and
    above the diagonal, one product per block row."""
    for i in range(len(ids)):
        row = Z[:, at[i] : at[i + 1]].T @ W[:, at[i] :]
        for j in range(i, len(ids)):
            block = row[:, at[j] - at[i] : at[j + 1] - at[i]]
            key = (ids[i], ids[j])
            if key in acc:
                acc[key] += block
            else:
                acc[key] = block.copy()


def _distinct_columns(Z: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Z with the columns of a repeated Z column summed into its first, their distinct Z columns)."""
    uniq, first, inverse = np.unique(cols, return_index=True, return_inverse=True)
    if uniq.size == cols.size:
        return Z, cols
    for j in np.flatnonzero(first[inverse] != np.arange(cols.size)):
        Z[:, first[inverse[j]]] += Z[:, j]
    keep = np.sort(first)
    return Z[:, keep], cols[keep]


def _add_direct(G: np.ndarray, cols: np.ndarray, Z: np.ndarray, W: np.ndarray) -> None:
    """G[cols, cols] += ZᵀW (distinct ``cols``, a symmetric product): the column pieces on and above the diagonal
    formed (``GRAM_PIECES``), the rest mirrored."""
    k = cols.size
    cuts = np.linspace(0, k, min(GRAM_PIECES, k) + 1).astype(np.int64)
    for a, b in zip(cuts[:-1], cuts[1:]):
        row = Z[:, a:b].T @ W[:, a:]
        G[np.ix_(cols[a:b], cols[a:])] += row
        if b < k:
            G[np.ix_(cols[b:], cols[a:b])] += row[:, b - a :].T


def _scatter_pairs(G: np.ndarray, acc: dict, columns: list) -> None:
    """G += the pair blocks ``acc`` at the Z columns of their patch blocks, those below the diagonal mirrored (the
    columns of one block are distinct; a column in two blocks sums their functions)."""
    for (a, b), block in sorted(acc.items()):
        G[np.ix_(columns[a], columns[b])] += block
        if a != b:
            G[np.ix_(columns[b], columns[a])] += block.T


def gram_matrices(
    ops: FineOperators, grid: CoarseGrid, space: MultiscaleSpace, *, comm: MPI.Comm = MPI.COMM_SELF
) -> tuple[np.ndarray, np.ndarray]:
    """(ZᵀKZ, ZᵀMZ) for Z = [Ψ, N, N_f] (columns: the dim V_ms bases, the γ DOFs, the source correction).

    ZᵀKZ from the patch equations when the space holds them (``equations.stiffness_gram``, unless ΨᵀAΨ is nearly
    singular: ``equations.resolves``), else as ZᵀMZ: summed over coarse cells (or blocks of small ones,
    ``GRAM_BLOCK_BELOW``) S of Z_Sᵀ K_S Z_S (K_S the matrix of the block's fine cells, Z_S the dense block of the
    patch problems' functions covering its cells, ``MultiscaleSpace.blocks``, gathered one patch problem at a time).
    The products are summed per pair of patch problems, those on and above the diagonal formed (one product per
    patch problem covering S) and the rest mirrored, and put into the Gram matrices at the end; the blocks are
    shared out over ``comm`` (a static share: a fixed summation order) and the sums Allreduced.
    """
    inc = Incidence(ops, grid)
    n_ms, ng = space.size, space.n_gamma
    nz = n_ms + ng + 1
    stiffness = True  # ZᵀKZ as products too, unless the patch equations give it (``equations.stiffness_gram``)
    if space.equations is not None:
        Zg = trace_matrix(ops, space)
        GK = stiffness_gram(ops, space, space.equations, Zg, comm=comm)
        stiffness = not resolves(ops, GK, Zg, n_ms)
    blocks = space.blocks
    columns = [p.columns for p in blocks] + [np.array([nz - 1])]  # (the last: N_f's)
    # the patch blocks holding each coarse cell (those whose functions may be nonzero on it)
    _, patches = cell_groups(grid, CEMOptions(layers=space.layers, patch_group=space.patch_group), ops.bs)
    held = sp.csr_matrix(
        (
            np.ones(sum(p.size for p in patches)),
            (np.concatenate(patches), np.repeat(np.arange(len(patches)), [p.size for p in patches])),
        ),
        shape=(grid.size, len(patches)),
    )
    held.sort_indices()
    units = grid.groups(_gram_block(space.patch_group, ops.bs, ops.size / grid.size), ops.bs)
    sizes = np.array([sum(grid.cells[int(K)].size for K in b) for b in units], dtype=np.float64)
    acc_K, acc_M = {}, {}  # (block, block) → the sum of its products over the units
    # wide patch problems (shared patches): products per pair of them; one cell each: straight into the matrices
    pairs = np.mean([p.columns.size for p in blocks]) >= PAIRS_FROM_WIDTH
    if stiffness:
        GK = np.zeros((nz, nz))
    GM = np.zeros((nz, nz))

    def add_unit(q: int) -> None:
        cells = [int(K) for K in units[q]]
        cell_dofs = [inc.dofs(K, free_only=False) for K in cells]
        D = cell_dofs[0] if len(cells) == 1 else np.unique(np.concatenate(cell_dofs))
        cover = np.unique(np.concatenate([held.indices[held.indptr[K] : held.indptr[K + 1]] for K in cells]))
        parts = [blocks[b] for b in cover]
        ids = [int(b) for b in cover]
        widths = [p.columns.size for p in parts]
        if space.Nf is not None:
            ids.append(len(blocks))
            widths.append(1)
        at = np.concatenate([[0], np.cumsum(widths)]).astype(np.int64)
        Z = np.zeros((D.size, int(at[-1])))
        _gather(Z, parts, at, D)
        if space.Nf is not None:
            Z[:, -1] = space.Nf[D]
        if not pairs:
            Z, cols = _distinct_columns(Z, np.concatenate([columns[i] for i in ids]))
        if stiffness:
            W = _block_matrix(ops, grid, cells, cell_dofs, D) @ Z  # [K_S Z; M_S Z]
            targets = ((acc_K, GK, W[: D.size]), (acc_M, GM, W[D.size :]))
        else:
            targets = ((acc_M, GM, _mass_matrix(ops, grid, cells, cell_dofs, D) @ Z),)
        for acc, G, product in targets:
            if pairs:
                _add_pairs(acc, ids, at, Z, product)
            else:
                _add_direct(G, cols, Z, product)

    # a static share (not handed out on request): the same cells on the same rank in every run, so the sums
    # and the Allreduce below round the same way every time
    run_shared(sizes, comm, "CEM Gram matrices", add_unit, gather=False, logger=log)
    if stiffness:
        _scatter_pairs(GK, acc_K, columns)
    _scatter_pairs(GM, acc_M, columns)
    if comm.size > 1:
        for arr in (GK, GM) if stiffness else (GM,):
            comm.Allreduce(MPI.IN_PLACE, arr, op=MPI.SUM)
    return GK, GM


def trace_matrix(ops: FineOperators, space: MultiscaleSpace) -> np.ndarray:
    """Z_γ: the values of Z = [Ψ, N, N_f] at the γ DOFs (``ops.gamma`` ordering), dense n_γ × (dim V_ms + n_γ + 1)."""
    ng = space.n_gamma
    gamma = ops.gamma
    Zg = np.zeros((ng, space.size + ng + 1))
    for p in space.blocks:  # (the columns of a block are distinct)
        pos = np.minimum(np.searchsorted(p.dofs, gamma), p.dofs.size - 1)
        hit = np.flatnonzero(p.dofs[pos] == gamma)
        if hit.size:
            Zg[np.ix_(hit, p.columns)] += p.values[pos[hit]]
    if space.Nf is not None:
        Zg[:, -1] = space.Nf[gamma]
    return Zg


class MultiscaleRobinSolver:
    """The Ω₁ step of Algorithm 3 with source correction: w ∈ V_ms with
    a₁(w,v) + α∫_γ w·v = ℓ(v) + ∫_γ g·v − [a₁(Ng + N_f,v) + α∫_γ (Ng + N_f)·v], then u₁ = w + N g + N_f.

    Online everything is done in the coordinates s = (w, g, 1) of u₁ = Z s, Z = [Ψ, N, N_f]: the
    coarse solve w = A_ms⁻¹(b + C g) (A_ms = ΨᵀAΨ factorized offline), the trace u₁|γ = Z_γ s and
    the norms a₁(u₁, u₁) = sᵀ(ZᵀKZ)s, ‖u₁‖² = sᵀ(ZᵀMZ)s; the fine field Z s only when asked.
    """

    def __init__(
        self, ops: FineOperators, space: MultiscaleSpace, grid: CoarseGrid, *, comm: MPI.Comm = MPI.COMM_SELF
    ) -> None:
        t0 = time.perf_counter()
        self.ops = ops
        self.space = space
        n_ms, ng = space.size, space.n_gamma
        self.GK, self.GM = space.grams if space.grams is not None else gram_matrices(ops, grid, space, comm=comm)
        space.equations = None  # (used by the Gram matrices only)
        self.time_gram = time.perf_counter() - t0  #: forming the Gram matrices (0 when the space holds them)
        self.Zg = trace_matrix(ops, space)
        # ΨᵀAZ = ΨᵀKZ + Ψ_γᵀ R_γγ Z_γ (R is α times the γ vertex mass: diagonal on γ; the rows of ZᵀAZ the coarse
        # problem reads)
        Rg = ops.R[ops.gamma][:, ops.gamma]
        ZAZ = self.GK[:n_ms] + self.Zg[:, :n_ms].T @ (Rg @ self.Zg)
        self.A_ms = ZAZ[:, :n_ms]
        self.factor = PivotedCholesky(self.A_ms, what="the coarse matrix")
        # Zᵀℓ and Zᵀ G[:, γ] (of which the rows of Ψ), patch problem by patch problem
        ZF = np.zeros(n_ms + ng + 1)
        Gg = ops.G[:, ops.gamma].tocsr()
        ZG = np.zeros((n_ms + ng + 1, ng))
        for p in space.blocks:  # (the columns of a block are distinct)
            ZF[p.columns] += p.values.T @ ops.F[p.dofs]
            Gp = Gg[p.dofs]
            if Gp.nnz:
                ZG[p.columns] += (Gp.T @ p.values).T
        PsiF, PsiG = ZF[:n_ms], ZG[:n_ms]
        self.b_f = PsiF - ZAZ[:, -1]
        # Ψᵀ (G[:, γ] − A N): the action of the interface data on the coarse right-hand side
        self.C = PsiG - ZAZ[:, n_ms : n_ms + ng]
        self._response = None
        self._reduced = None
        self.time_s = time.perf_counter() - t0

    @property
    def size(self) -> int:
        return self.space.size

    def coordinates(self, g: np.ndarray) -> np.ndarray:
        """s = (w, g, 1): u₁ = Z s for nodal Robin data g on ``ops.gamma``."""
        w = self.factor.solve(self.b_f + self.C @ g)
        return np.concatenate([w, g, [1.0]])

    def coarse_solution(self, g: np.ndarray) -> np.ndarray:
        """w (coordinates in V_ms) for nodal Robin data g on ``ops.gamma``."""
        return self.factor.solve(self.b_f + self.C @ g)

    def field(self, s: np.ndarray) -> np.ndarray:
        """u₁ = Z s = Ψ w + N g + s_last N_f on every Ω₁ DOF."""
        n_ms, ng = self.space.size, self.space.n_gamma
        u = self.space.apply(s[:n_ms], s[n_ms : n_ms + ng], with_source=False)
        if self.space.Nf is not None and s[-1] != 0.0:
            u += s[-1] * self.space.Nf
        return u

    def solve(self, g: np.ndarray) -> np.ndarray:
        """u₁ (all scalar Ω₁ DOFs) for nodal Robin data g on ``ops.gamma``."""
        return self.field(self.coordinates(g))

    def trace(self, s: np.ndarray) -> np.ndarray:
        """u₁ at ``ops.gamma`` for coordinates s."""
        return self.Zg @ s

    def _solution_map(self) -> np.ndarray:
        """X with w = X t for t = (g, 1): the coarse solution as an affine map of the Robin data (one dense
        coarse solve with n_γ + 1 right-hand sides, made once)."""
        if self._response is None:
            self._response = self.factor.solve(np.column_stack([self.C, self.b_f]))
        return self._response

    def response(self) -> tuple[np.ndarray, np.ndarray]:
        """The affine interface map u₁|γ = R g + r₀ (``ops.gamma`` ordering, dense R)."""
        n_ms, ng = self.space.size, self.space.n_gamma
        X = self._solution_map()
        R = self.Zg[:, :n_ms] @ X[:, :ng] + self.Zg[:, n_ms : n_ms + ng]
        r0 = self.Zg[:, :n_ms] @ X[:, ng] + self.Zg[:, -1]
        return R, r0

    def reduced(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(T, Ĝ_K, Ĝ_M) in the interface coordinates t = (g, 1): u₁|γ = T t and the Gram matrices QᵀGQ of
        s = Q t (Q = [X; I]), so a₁(Zs, Zs) = tᵀĜ_K t and ‖Zs‖² = tᵀĜ_M t.  Order n_γ + 1 instead of
        dim V_ms + n_γ + 1: a step reads these instead of the coarse factor, Z_γ and the Gram matrices (made
        once, with the response)."""
        if self._reduced is None:
            n_ms = self.space.size
            X = self._solution_map()
            R, r0 = self.response()

            def reduce(G: np.ndarray) -> np.ndarray:
                GQ = G[:, :n_ms] @ X + G[:, n_ms:]
                out = X.T @ GQ[:n_ms] + GQ[n_ms:]
                return 0.5 * (out + out.T)

            self._reduced = (np.column_stack([R, r0]), reduce(self.GK), reduce(self.GM))
        return self._reduced

    def expand(self, t: np.ndarray) -> np.ndarray:
        """s = (X t, t): the coordinates of u₁ = Z s from the interface coordinates t = (g, 1)."""
        return np.concatenate([self._solution_map() @ t, t])
