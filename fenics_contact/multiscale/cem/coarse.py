"""The coarse (online) step of the primal CEM (Algorithm 3): Gram and trace matrices, the Robin solver.

Online everything is done in the coordinates s = (w, g, 1) of u₁ = Z s, Z = [Ψ, N, N_f]: the coarse solve
(ΨᵀAΨ factorized once, ``fem.linalg.PivotedCholesky``), the trace Z_γ s, the norms sᵀ(ZᵀKZ)s and sᵀ(ZᵀMZ)s.
ZᵀKZ comes from the patch equations the functions solve (``equations``); ZᵀMZ is summed over the coarse cells K
from dense blocks of the functions that cover K (BLAS products with the cellwise M_K, the column blocks on and
above the diagonal formed and the rest mirrored), the cells shared out over the ranks and the sums Allreduced.
"""

import logging
import time

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.fem.linalg import PivotedCholesky
from fenics_contact.multiscale.cem.bases import Incidence, MultiscaleSpace, covering
from fenics_contact.multiscale.cem.equations import resolves, stiffness_gram
from fenics_contact.multiscale.cem.operators import FineOperators
from fenics_contact.multiscale.cem.options import WHOLE_DOMAIN
from fenics_contact.multiscale.cem.spectral import restrict
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.work import run_shared

__all__ = ["MultiscaleRobinSolver", "gram_matrices", "trace_matrix"]

log = logging.getLogger(__name__)


def _fill_rows(Z: np.ndarray, parts: list, targets: list, D: np.ndarray) -> None:
    """Z[:, targets[j]] += the values of the patch functions parts[j] at the DOFs D (zero where D is outside
    their DOFs; each target list without repeats, a slice target a function's own columns, not shared)."""
    found = {}  # the functions of one patch problem share their DOF array: look D up in it once
    for p, target in zip(parts, targets):
        if id(p.dofs) not in found:
            pos = np.searchsorted(p.dofs, D)
            np.minimum(pos, p.dofs.size - 1, out=pos)
            hit = p.dofs[pos] == D
            index = np.flatnonzero(hit)
            # (a cell inside the patch: all of D, no row index; an index array paired with column indices as a
            # column vector)
            found[id(p.dofs)] = (slice(None), slice(None), pos) if hit.all() else (index, index[:, None], pos[hit])
        hit, hit_column, rows = found[id(p.dofs)]
        if isinstance(target, slice) and isinstance(hit, slice):
            # a function's own columns (still zero), all of D: gathered straight into Z (no temporary; "clip" is
            # NumPy's unbuffered mode, the rows are in range)
            np.take(p.values, rows, axis=0, out=Z[:, target], mode="clip")
        else:
            Z[hit if isinstance(target, slice) else hit_column, target] += p.values[rows]


#: column pieces of the symmetric products ZᵀW of ``gram_matrices``: the blocks above the diagonal are formed,
#: those below mirrored ((pieces + 1) / (2 pieces) of the work of the full product)
GRAM_PIECES = 4


#: fine DOFs per coarse cell below which ``gram_matrices`` sums blocks of coarse cells rather than single cells
#: (2D): small cells make small products whose overhead dominates.  Model 3, H = 1/16, m = 4: at h = 1/128 (130
#: Ω₁ DOFs per coarse cell) blocks of 2 × 2 cells take a fifth less time than single cells with one patch per
#: cell, the groups of 4 × 4 (their cells covered by the same functions) two-fifths less; at h = 1/256 (520 DOFs
#: per cell) blocks gain nothing.
GRAM_BLOCK_BELOW = 400


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


def _symmetric_products(Z: np.ndarray, W: np.ndarray) -> np.ndarray:
    """ZᵀW for a symmetric result (W = S Z, S symmetric): the column blocks on and above the diagonal formed
    (``GRAM_PIECES`` of them), the rest mirrored."""
    k = Z.shape[1]
    cuts = np.linspace(0, k, min(GRAM_PIECES, k) + 1).astype(np.int64)
    G = np.empty((k, k))
    for a, b in zip(cuts[:-1], cuts[1:]):
        G[a:b, a:] = Z[:, a:b].T @ W[:, a:]
        G[b:, a:b] = G[a:b, b:].T
    return G


def gram_matrices(
    ops: FineOperators, grid: CoarseGrid, space: MultiscaleSpace, *, comm: MPI.Comm = MPI.COMM_SELF
) -> tuple[np.ndarray, np.ndarray]:
    """(ZᵀKZ, ZᵀMZ) for Z = [Ψ, N, N_f] (columns: the dim V_ms bases, the γ DOFs, the source correction).

    ZᵀKZ from the patch equations when the space holds them (``equations.stiffness_gram``, unless ΨᵀAΨ is nearly
    singular: ``equations.resolves``), else as ZᵀMZ: summed over coarse cells (or blocks of small ones,
    ``GRAM_BLOCK_BELOW``) S of Z_Sᵀ K_S Z_S (K_S the matrix of the block's fine cells, Z_S the dense block of the
    functions covering its cells;
    ``_symmetric_products``: (GRAM_PIECES + 1) / (2 GRAM_PIECES) of a full product); blocks shared out over
    ``comm`` (a static share: a fixed summation order) and the sums Allreduced.
    """
    inc = Incidence(ops, grid)
    n_ms, ng = space.size, space.n_gamma
    nz = n_ms + ng + 1
    stiffness = True  # ZᵀKZ as products too, unless the patch equations give it (``equations.stiffness_gram``)
    if space.equations is not None:
        Zg = trace_matrix(ops, space)
        GK = stiffness_gram(ops, space, space.equations, Zg, comm=comm)
        stiffness = not resolves(ops, GK, Zg, n_ms)
    corr_at = {int(k): p for k, p in zip(space.correction_cells, space.correction)}
    if stiffness:
        GK = np.zeros((nz, nz))
    GM = np.zeros((nz, nz))
    covers = covering(grid, space.layers, space.patch_group, ops.bs)
    blocks = grid.groups(_gram_block(space.patch_group, ops.bs, ops.size / grid.size), ops.bs)
    sizes = np.array([sum(grid.cells[int(K)].size for K in b) for b in blocks], dtype=np.float64)

    def add_block(q: int) -> None:
        cells = [int(K) for K in blocks[q]]
        cell_dofs = [inc.dofs(K, free_only=False) for K in cells]
        D = cell_dofs[0] if len(cells) == 1 else np.unique(np.concatenate(cell_dofs))
        cover = covers[cells[0]] if len(cells) == 1 else np.unique(np.concatenate([covers[K] for K in cells]))
        bases = [space.basis[i] for i in cover]
        corrections = [corr_at[int(i)] for i in cover if int(i) in corr_at]
        # columns: the covering bases, the γ vertices of their Robin corrections (a γ vertex shared by two coarse
        # cells has a column in both corrections: summed into one), N_f
        cols = [p.columns for p in bases]
        at = np.cumsum([0] + [c.size for c in cols])
        targets = [slice(a, z) for a, z in zip(at[:-1], at[1:])]
        if corrections:
            uniq = np.unique(np.concatenate([p.columns for p in corrections]))
            targets += [at[-1] + np.searchsorted(uniq, p.columns) for p in corrections]
            cols.append(n_ms + uniq)
        if space.Nf is not None:
            cols.append(np.array([nz - 1]))
        cols = np.concatenate(cols)
        Z = np.zeros((D.size, cols.size))
        _fill_rows(Z, bases + corrections, targets, D)
        if space.Nf is not None:
            Z[:, -1] = space.Nf[D]
        if stiffness:
            W = _block_matrix(ops, grid, cells, cell_dofs, D) @ Z  # [K_S Z; M_S Z]
            gk, gm = _symmetric_products(Z, W[: D.size]), _symmetric_products(Z, W[D.size :])
        else:
            gm = _symmetric_products(Z, _mass_matrix(ops, grid, cells, cell_dofs, D) @ Z)
        # cols runs through few contiguous ranges (the modes of consecutive cells): added range by range
        cut = np.concatenate([[0], np.flatnonzero(np.diff(cols) != 1) + 1, [cols.size]])
        for a0, a1 in zip(cut[:-1], cut[1:]):
            ra = slice(cols[a0], cols[a0] + a1 - a0)
            for b0, b1 in zip(cut[:-1], cut[1:]):
                rb = slice(cols[b0], cols[b0] + b1 - b0)
                if stiffness:
                    GK[ra, rb] += gk[a0:a1, b0:b1]
                GM[ra, rb] += gm[a0:a1, b0:b1]

    # a static share (not handed out on request): the same cells on the same rank in every run, so the sums
    # and the Allreduce below round the same way every time
    run_shared(sizes, comm, "CEM Gram matrices", add_block, gather=False, logger=log)
    if comm.size > 1:
        for arr in (GK, GM) if stiffness else (GM,):
            comm.Allreduce(MPI.IN_PLACE, arr, op=MPI.SUM)
    return GK, GM


def trace_matrix(ops: FineOperators, space: MultiscaleSpace) -> np.ndarray:
    """Z_γ: the values of Z = [Ψ, N, N_f] at the γ DOFs (``ops.gamma`` ordering), dense n_γ × (dim V_ms + n_γ + 1)."""
    ng = space.n_gamma
    gamma = ops.gamma
    Zg = np.zeros((ng, space.size + ng + 1))
    for parts, shift in ((space.basis, 0), (space.correction, space.size)):
        for p in parts:
            pos = np.minimum(np.searchsorted(p.dofs, gamma), p.dofs.size - 1)
            hit = np.flatnonzero(p.dofs[pos] == gamma)
            if hit.size:
                Zg[np.ix_(hit, shift + p.columns)] += p.values[pos[hit]]
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
        # ZᵀAZ = ZᵀKZ + Z_γᵀ R_γγ Z_γ (R is α times the γ vertex mass: diagonal on γ)
        Rg = ops.R[ops.gamma][:, ops.gamma]
        ZAZ = self.GK + self.Zg.T @ (Rg @ self.Zg)
        self.A_ms = ZAZ[:n_ms, :n_ms]
        self.factor = PivotedCholesky(self.A_ms, what="the coarse matrix")
        # Ψᵀℓ and Ψᵀ G[:, γ], patch by patch
        PsiF = np.zeros(n_ms)
        Gg = ops.G[:, ops.gamma].tocsr()
        PsiG = np.zeros((n_ms, ng))
        for p in space.basis:
            PsiF[p.columns] += p.values.T @ ops.F[p.dofs]
            Gp = Gg[p.dofs]
            if Gp.nnz:
                PsiG[p.columns] += (Gp.T @ p.values).T
        self.b_f = PsiF - ZAZ[:n_ms, -1]
        # Ψᵀ (G[:, γ] − A N): the action of the interface data on the coarse right-hand side
        self.C = PsiG - ZAZ[:n_ms, n_ms : n_ms + ng]
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
