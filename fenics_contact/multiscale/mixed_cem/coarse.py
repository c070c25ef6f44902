"""The coarse operators of the mixed CEM (Algorithm 4): ``CoarseOperators`` and ``coarse_operators``.

With Φ = [Ψ | Q | σ_f] the online problem needs only small dense matrices, accumulated coarse cell by coarse
cell from the patch functions that reach it: ΦᵀÃΦ, ΦᵀKΦ, Πᵀ B Φ, (BΦ)ᵀ[N | u_f], ΦᵀC, the trace map E Φ, the
displacement Gram of [Π | N | u_f], Πᵀ G and Φᵀ F; the coarse cells are shared out over the ranks and the
matrices summed.
"""

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.multiscale import work
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.bases import CoarseCellDofs
from fenics_contact.multiscale.mixed_cem.blocks import cell_rows
from fenics_contact.multiscale.mixed_cem.operators import CellOperators
from fenics_contact.multiscale.mixed_cem.spectral import StageI

__all__ = ["COARSE_ARRAYS", "SYMMETRIC_ARRAYS", "CoarseOperators", "coarse_operators", "gram", "reaching"]

log = logging.getLogger(__name__)


@dataclass(slots=True)
class CoarseOperators:
    """Dense coarse matrices of Algorithm 4.

    Index spaces: [X_ms | d] for stresses and [U_aux | d] for displacements, with the data
    d = [g; 1] (n_g γ values, then the load: the source correctors, zero without them).
    """

    n_ms: int
    n_aux: int
    n_g: int
    Gt: np.ndarray  #: ΦᵀÃΦ, Φ = [Ψ | Q | σ_f]
    Gk: np.ndarray  #: ΦᵀKΦ
    Bm: np.ndarray  #: Πᵀ B Φ
    BN: np.ndarray  #: (BΦ)ᵀ [N | u_f]
    Cphi: np.ndarray  #: Φᵀ C (n_ms + n_d, n_g)
    Ephi: np.ndarray  #: E Φ
    Mu: np.ndarray  #: Gram of [Π | N | u_f] in L²
    PiG: np.ndarray  #: Πᵀ G
    Fphi: np.ndarray | None = None  #: Φᵀ F (n_ms + n_d,): the stress-side load of the boundary data (None: zero)

    @property
    def n_d(self) -> int:
        """Number of data columns: n_g γ values and the load."""
        return self.n_g + 1

    def __add__(self, other: "CoarseOperators") -> "CoarseOperators":
        names = ("Gt", "Gk", "Bm", "BN", "Cphi", "Ephi", "Mu", "PiG")
        fphi = (
            None
            if self.Fphi is None and other.Fphi is None
            else ((0.0 if self.Fphi is None else self.Fphi) + (0.0 if other.Fphi is None else other.Fphi))
        )
        return CoarseOperators(
            self.n_ms, self.n_aux, self.n_g, *(getattr(self, n) + getattr(other, n) for n in names), fphi
        )


#: The matrices of ``CoarseOperators`` (summed over the ranks, stored in the cache)
COARSE_ARRAYS = ("Gt", "Gk", "Bm", "BN", "Cphi", "Ephi", "Mu", "PiG", "Fphi")
#: The symmetric ones among them: symmetrized exactly, stored as their upper triangle
SYMMETRIC_ARRAYS = ("Gt", "Gk", "Mu")


def _merge_columns(X: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum the columns of the matrix X with equal index: (sorted unique indices, merged X)."""
    uniq, inv = np.unique(idx, return_inverse=True)
    if uniq.size == idx.size:
        return uniq, X[:, np.argsort(inv)] if np.any(np.diff(idx) < 0) else X
    sel = sp.csr_matrix((np.ones(idx.size), (np.arange(idx.size), inv)), shape=(idx.size, uniq.size))
    return uniq, np.asarray((sel.T @ X.T).T)


def gram(A: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Σ_c F_cᵀ A_c F_c for cell blocks A (n, w, w), symmetric positive definite, and F (n, w, k): W = L_cᵀ F_c with
    A_c = L_c L_cᵀ (batched Cholesky), then WᵀW (NumPy's symmetric rank-k product: half a general product); a block
    that is not positive definite (it should not happen: compliance and Robin term are, P_c is injective) takes
    the general product."""
    try:
        W = np.swapaxes(np.linalg.cholesky(A), 1, 2) @ F
    except np.linalg.LinAlgError:
        return F.reshape(-1, F.shape[2]).T @ (A @ F).reshape(-1, F.shape[2])
    W = W.reshape(-1, F.shape[2])
    return W.T @ W


def reaching(funcs: list, n: int) -> list:
    """For each coarse cell K: the (PatchFunctions, position of K in it) of the functions reaching K."""
    out = [[] for _ in range(n)]
    for f in funcs:
        if f is None:
            continue
        for pos, K in enumerate(f.coarse):
            if f.sigma[pos] is not None:  # (held by another rank otherwise)
                out[int(K)].append((f, pos))
    return out


def coarse_operators(
    ops: CellOperators,
    grid: CoarseGrid,
    aux: StageI,
    basis: list,
    corr: list,
    *,
    dofs: CoarseCellDofs | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
    cells: np.ndarray | None = None,
) -> CoarseOperators:
    """Accumulate the coarse matrices coarse cell by coarse cell from the patch functions reaching it.

    On K the stresses are P_K F (F: their AW coefficients on K), so ΦᵀÃΦ|_K = Fᵀ (P_Kᵀ Ã_K P_K) F etc., formed fine
    cell by fine cell (Σ_c F_cᵀ (P_cᵀ Ã_c P_c) F_c: batched 24 × 24 blocks, their Cholesky factors and one symmetric
    BLAS product, ``gram``; at h = 1/128 the sparse products with P_K take 30 % longer, the general product 15 %).
    Under ``comm`` the coarse cells are shared out (or this rank takes ``cells``, those whose pieces it holds)
    and the matrices summed.
    """
    dofs = dofs or CoarseCellDofs.of(ops, grid)
    n_ms, n_g = aux.size, ops.num_gamma_values
    n_d = n_g + 1
    n_tot = n_ms + n_d
    Gt = np.zeros((n_tot, n_tot))
    Gk = np.zeros((n_tot, n_tot))
    Bm = np.zeros((aux.size, n_tot))
    BN = np.zeros((n_tot, n_d))
    Cphi = np.zeros((n_tot, n_g))
    Ephi = np.zeros((n_g, n_tot))
    Mu = np.zeros((aux.size + n_d, aux.size + n_d))
    PiG = np.zeros(aux.size)
    Fphi = np.zeros(n_tot)
    gamma = np.zeros(ops.num_cells, dtype=bool)
    gamma[ops.gamma_cells] = True
    reach_b, reach_c = reaching(basis, grid.size), reaching(corr, grid.size)

    def accumulate(K: int) -> None:
        cK = dofs.cells[K]
        sig = [f.sigma[p] for f, p in reach_b[K]] + [q.sigma[p] for q, p in reach_c[K]]
        idx = [f.index for f, _ in reach_b[K]] + [n_ms + q.index for q, _ in reach_c[K]]
        uniq, F = _merge_columns(np.concatenate(sig, axis=1), np.concatenate(idx))
        ix = np.ix_(uniq, uniq)
        # per fine cell c of K: its AW coefficients F_c (w × n_f) and P_c (30 × w), so that the Grams are
        # Σ_c F_cᵀ (P_cᵀ Ã_c P_c) F_c: batched cell products and one BLAS product each, no sparse P_K products
        PB = ops.P_blocks[cK]
        Fc = dofs.per_cell(K, F)  # (|K|, w, n_f)
        PBt = np.swapaxes(PB, 1, 2)
        Fcf = Fc.reshape(-1, Fc.shape[2])
        Gt[ix] += gram(PBt @ (ops.kt(cK) @ PB), Fc)
        Gk[ix] += gram(PBt @ (ops.K[cK] @ PB), Fc)
        BP = ((ops.B[cK] @ PB) @ Fc).reshape(6 * cK.size, -1)
        a0, a1 = aux.offsets[K], aux.offsets[K + 1]
        Pi = aux.modes[K].reshape(-1, a1 - a0)
        MPi = (ops.M[cK] @ aux.modes[K]).reshape(-1, a1 - a0)
        Bm[a0:a1, uniq] += Pi.T @ BP
        Mu[a0:a1, a0:a1] += Pi.T @ MPi
        PiG[a0:a1] += Pi.T @ ops.G[cK].ravel()
        if ops.F is not None:
            Fphi[uniq] += Fcf.T @ (PBt @ ops.F[cK][:, :, None]).ravel()
        if reach_c[K]:
            gu, Nu = _merge_columns(
                np.concatenate([q.u[p] for q, p in reach_c[K]], axis=1),
                np.concatenate([q.index for q, _ in reach_c[K]]),
            )
            MNu = (ops.M[cK] @ Nu.reshape(cK.size, 6, -1)).reshape(6 * cK.size, -1)
            BN[np.ix_(uniq, gu)] += BP.T @ Nu
            PMN = MPi.T @ Nu
            du = aux.size + gu
            Mu[np.ix_(np.arange(a0, a1), du)] += PMN
            Mu[np.ix_(du, np.arange(a0, a1))] += PMN.T
            Mu[np.ix_(du, du)] += Nu.T @ MNu
        if gamma[cK].any():
            rows = cell_rows(cK, 30)
            PFf = (PB @ Fc).reshape(30 * cK.size, -1)  # cell-major DG values on K
            Cphi[uniq] += (ops.C[rows].T @ PFf).T
            Ephi[:, uniq] += ops.E[:, rows] @ PFf

    cost = np.array([sum(f.index.size for f, _ in reach_b[K] + reach_c[K]) for K in range(grid.size)], dtype=float)
    work.run_shared(cost**2, comm, "mixed CEM coarse operators", accumulate, gather=False, items=cells, logger=log)
    co = CoarseOperators(n_ms, aux.size, n_g, Gt, Gk, Bm, BN, Cphi, Ephi, Mu, PiG, Fphi)
    if comm.size > 1:
        for name in COARSE_ARRAYS:
            arr = getattr(co, name)
            comm.Allreduce(MPI.IN_PLACE, arr, op=MPI.SUM)
    for name in SYMMETRIC_ARRAYS:  # Gram matrices: exactly symmetric (the cache stores one triangle)
        X = getattr(co, name)
        X += X.T
        X *= 0.5
    return co
