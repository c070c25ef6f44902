"""The local spectral problems of the primal CEM (Algorithm 3) and the auxiliary space V_aux they span.

On each coarse cell K_i: a_i(φ, v) + α ∫_{γ∩∂K_i} φ·v ds = λ s_i(φ, v), s_i(w, v) = ∫_{K_i} κ̃ w·v dx; the l_i
smallest s_i-orthonormal φ_j^i span V_aux = ⊕ span{φ_j^i} (``AuxiliarySpace``), π is the s-orthogonal
projection onto it.  The eigenpairs come from ``fem.eigen`` (Krylov–Schur with shift-and-invert, checked by
Sylvester's inertia, or LAPACK); every cell is independent and the cells are shared out over a communicator.
"""

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.eigen import count_eigenvalues_below, generalized_eigenpairs
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.multiscale.cem.operators import FineOperators
from fenics_contact.multiscale.cem.options import CEMOptions
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.work import run_shared

__all__ = [
    "DENSE_FALLBACK",
    "AuxiliarySpace",
    "build_auxiliary_space",
    "local_matrices",
    "local_spectral_problem",
    "restrict",
]

log = logging.getLogger(__name__)

#: Extra eigenpairs requested from Krylov–Schur beyond the wanted ones (a margin for multiplicities).
_EXTRA_PAIRS = 3
#: Relative gap above the last wanted eigenvalue at which the inertia count is taken.
_INERTIA_GAP = 1.0e-6
#: Largest local problem solved densely (LAPACK) when Krylov–Schur keeps missing pairs.
DENSE_FALLBACK = 3000


def local_spectral_problem(
    A: sp.spmatrix,
    S: sp.spmatrix,
    nev: int | None,
    *,
    eigensolver: str = "auto",
    target: float = -1.0,
    tol: float = 1.0e-12,
) -> tuple[np.ndarray, np.ndarray]:
    """The ``nev`` smallest eigenpairs of A φ = λ S φ (A ⪰ 0, S ≻ 0), by SLEPc on COMM_SELF.

    GHEP; Krylov–Schur with shift-and-invert about ``target`` < 0 (A − target·S is
    SPD even when A has rigid-body modes), or LAPACK for small/complete problems.
    A Krylov method can miss copies of a multiple eigenvalue (the three rigid-body
    modes of a floating cell): the Krylov–Schur result is therefore checked by
    Sylvester's inertia of A − σS just above the last wanted eigenvalue, and missing
    pairs are searched again with the found ones deflated.
    Returns ascending eigenvalues and S-orthonormal eigenvectors (columns).
    """
    n = A.shape[0]
    if n == 0:
        return np.zeros(0), np.zeros((0, 0))
    nev = n if nev is None else min(int(nev), n)
    kind = eigensolver
    if kind == "auto":
        kind = "krylovschur" if (n >= 2 * nev + 16 and 3 * nev <= n) else "lapack"
    Ap, Sp = scipy_to_petsc(A), scipy_to_petsc(S)

    def pairs(count: int, method: str, deflation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        return generalized_eigenpairs(
            Ap, Sp, count, method, target=target, tol=tol, deflation=deflation, label="local spectral problem"
        )

    try:
        if kind == "lapack":
            values, vectors = pairs(nev, kind)
        else:
            want = min(nev + _EXTRA_PAIRS, n)
            values, vectors = pairs(want, kind)
            for _ in range(10):
                order = np.argsort(values, kind="stable")
                values, vectors = values[order], vectors[:, order]
                cut = values[nev - 1]
                sigma = cut + _INERTIA_GAP * max(1.0, abs(cut))
                below = count_eigenvalues_below(A, S, sigma)
                have = int(np.count_nonzero(values < sigma))
                if below <= have:
                    break
                log.debug(
                    "Krylov–Schur missed %d eigenpair(s) below %.3e; deflating and searching again", below - have, sigma
                )
                more_v, more_x = pairs(min(below - have + _EXTRA_PAIRS, n - have), kind, vectors[:, values < sigma])
                keep = values < sigma
                values = np.concatenate([values[keep], more_v])
                vectors = np.concatenate([vectors[:, keep], more_x], axis=1)
            else:
                # shift-and-invert about target = −1 clusters eigenvalues ≪ 1 near one (a coarse cell holding a
                # stiff inclusion in a soft matrix: λ₄ ≈ 5e-3) and Krylov–Schur can keep missing a copy of the
                # triple zero; a problem small enough is then solved densely.
                if n > DENSE_FALLBACK:
                    raise ConvergenceError(f"local spectral problem (n = {n}): could not find all {nev} smallest pairs")
                log.info("local spectral problem (n = %d): Krylov–Schur missed pairs; dense LAPACK instead", n)
                values, vectors = pairs(nev, "lapack")
    finally:
        Ap.destroy()
        Sp.destroy()
    order = np.argsort(values, kind="stable")[:nev]
    values, vectors = values[order], vectors[:, order]
    # s-orthonormalize (fixes scaling, and bases of multiple eigenvalues): Φ ← Φ L⁻ᵀ, ΦᵀSΦ = LLᵀ.
    gram = vectors.T @ (S @ vectors)
    gram = 0.5 * (gram + gram.T)
    try:
        L = np.linalg.cholesky(gram)
    except np.linalg.LinAlgError as err:
        raise ConvergenceError(f"local eigenvectors are linearly dependent in the s-inner product: {err}") from None
    vectors = np.linalg.solve(L, vectors.T).T
    return values, vectors


@dataclass(slots=True)
class AuxiliarySpace:
    """V_aux = ⊕_k span{φ_j^k}: per coarse cell the free DOFs D_k, eigenvalues and s_k-orthonormal Φ_k.

    ``B`` (n × n_aux, CSR) has the columns s_k(·, φ_j^k) = S_k Φ_k, so that πu has the
    coefficients Bᵀu and s(πu, πv) = vᵀ B Bᵀ u.
    """

    dofs: list  #: D_k
    eigenvalues: list
    vectors: list  #: Φ_k, |D_k| × l_k
    B: sp.csr_matrix
    offsets: np.ndarray  #: columns of cell k in B: offsets[k]:offsets[k+1]
    #: Λ_k, the first eigenvalue left out on each coarse cell (inf when all are kept)
    gaps: np.ndarray

    @property
    def spectral_gap(self) -> float:
        """Λ = min_k Λ_k (inf when every cell keeps all its modes)."""
        return float(self.gaps.min()) if self.gaps.size else np.inf

    @property
    def size(self) -> int:
        """dim V_aux = Σ_k l_k."""
        return int(self.offsets[-1])

    def columns(self, k: int) -> np.ndarray:
        return np.arange(self.offsets[k], self.offsets[k + 1])

    def coefficients(self, u: np.ndarray) -> np.ndarray:
        """(s_k(u, φ_j^k))_{k,j}: the coordinates of πu."""
        return self.B.T @ u

    def project(self, u: np.ndarray) -> list:
        """πu as broken local vectors (one per K_k, on D_k): Φ_k Φ_kᵀ S_k u."""
        c = self.coefficients(u)
        return [Phi @ c[self.offsets[k] : self.offsets[k + 1]] for k, Phi in enumerate(self.vectors)]

    def project_local(self, local: list, S_local: list) -> list:
        """π applied to a broken function given by local vectors (with the local s_k matrices)."""
        return [Phi @ (Phi.T @ (Sk @ w)) for Phi, Sk, w in zip(self.vectors, S_local, local)]

    @classmethod
    def from_parts(cls, n: int, dofs, values, vectors, blocks, gaps: np.ndarray) -> "AuxiliarySpace":
        """V_aux from its per-cell parts: D_k, eigenvalues, Φ_k, the blocks S_k Φ_k (the columns of B), Λ_k;
        n Ω₁ DOFs."""
        offsets = np.concatenate([[0], np.cumsum([Phi.shape[1] for Phi in vectors])]).astype(np.int64)
        rows = np.concatenate([np.repeat(D, b.shape[1]) for D, b in zip(dofs, blocks)])
        cols = np.concatenate([np.tile(np.arange(offsets[k], offsets[k + 1]), len(D)) for k, D in enumerate(dofs)])
        data = np.concatenate([b.ravel() for b in blocks])
        B = sp.csr_matrix((data, (rows, cols)), shape=(n, int(offsets[-1])))
        return cls(list(dofs), list(values), list(vectors), B, offsets, np.asarray(gaps, dtype=np.float64))


def _cell_dofs(ops: FineOperators, grid: CoarseGrid, k: int) -> np.ndarray:
    nodes = np.unique(ops.cell_nodes[grid.cells[k]])
    dofs = ops.node_dofs[nodes].ravel()
    return dofs[ops.free[dofs]]


def restrict(M: sp.csr_matrix, D: np.ndarray) -> sp.csr_matrix:
    """M[D][:, D] for sorted D: the rows at D, their entries in the columns D kept and renumbered (the same
    entries in the same order as SciPy's column indexing, without its pass over the columns)."""
    rows = M[D]
    pos = np.minimum(np.searchsorted(D, rows.indices), max(D.size - 1, 0))
    keep = D[pos] == rows.indices if D.size else np.zeros(rows.indices.size, dtype=bool)
    indptr = np.concatenate([[0], np.cumsum(keep)])[rows.indptr]
    return sp.csr_matrix((rows.data[keep], pos[keep], indptr), shape=(D.size, D.size))


def local_matrices(ops: FineOperators, grid: CoarseGrid, k: int) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """D_k and the matrices of a_k(·,·) + α∫_{γ∩∂K_k} and s_k on it (colour restriction)."""
    c = int(grid.colors[k])
    D = _cell_dofs(ops, grid, k)
    Gk = restrict(ops.Gc[c], D)
    Kk = restrict(ops.Kc[c], D)
    A = (Kk + sp.diags(ops.alpha[D]) @ Gk).tocsr() if Gk.nnz else Kk  # (the γ term on cells touching γ only)
    return D, A, restrict(ops.Sc[c], D)


def build_auxiliary_space(
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, comm: MPI.Comm = MPI.COMM_SELF
) -> AuxiliarySpace:
    """Solve every local spectral problem (shared out over ``comm``) and keep l_k s-normalized eigenfunctions."""
    sizes = np.array([c.size for c in grid.cells], dtype=np.float64)

    def eigenproblem(k: int) -> tuple:
        D, A, S = local_matrices(ops, grid, k)
        # one pair more than kept: Λ_k, the first eigenvalue left out (reported as ``spectral_gap``)
        l = options.modes(ops.bs)  # an int or None (the rigid motions resolved by the dimension)
        lam, Phi = local_spectral_problem(
            A,
            S,
            l if l is None or l >= D.size else l + 1,
            eigensolver=options.eigensolver,
            target=options.target,
            tol=options.eig_tol,
        )
        gap = np.inf
        if l is not None and lam.size > l:
            gap = float(lam[l])
            lam, Phi = lam[:l], Phi[:, :l]
        if options.threshold is not None:
            keep = max(1, int(np.count_nonzero(lam <= options.threshold)))
            gap = float(lam[keep]) if keep < lam.size else gap
            lam, Phi = lam[:keep], Phi[:, :keep]
        gap = max(gap, 0.0)  # a cut through a cluster of zeros (rigid motions) can give −1e-16
        return D, lam, Phi, gap, S @ Phi

    parts = run_shared(sizes**1.5, comm, "CEM local eigenproblems", eigenproblem, balanced=True, logger=log)
    dofs = [p[0] for p in parts]
    values = [p[1] for p in parts]
    vectors = [p[2] for p in parts]
    blocks = [p[4] for p in parts]  # S_k Φ_k
    return AuxiliarySpace.from_parts(ops.size, dofs, values, vectors, blocks, np.array([p[3] for p in parts]))
