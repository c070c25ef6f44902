"""Stage I of the mixed CEM (Algorithm 4): the local spectral problems and U_aux (``StageI``).

On each coarse cell: Ã φ + Bᵀp = 0, −Bφ = λ S p with Ã = (A·,·) + β∫_{γ∩∂K}(·n)·(·n) and S the κ̃-weighted
mass.  Large cells: the pencil −[[Ã, Bᵀ], [B, 0]] x = λ [[0, 0], [0, S]] x by ``fem.eigen`` (Krylov–Schur with
shift-and-invert, MUMPS) for the pairs kept, checked by Sylvester's inertia just above the gap (missing pairs
are searched again with the found ones deflated); small cells: dense LAPACK on B Ã⁻¹ Bᵀ p = λ S p.  Each cell
keeps at least ``nbasis`` modes, more while the first eigenvalue left out is below ``min_gap``, and whole
clusters of a repeated eigenvalue.
"""

import logging
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.eigen import count_eigenvalues_below, generalized_eigenpairs
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.multiscale import work
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.multiscale.mixed_cem.blocks import block_diag
from fenics_contact.multiscale.mixed_cem.local_space import Topology, local_operators, local_stress_space
from fenics_contact.multiscale.mixed_cem.operators import CellOperators, cell_operators, scale_to_cell_sizes
from fenics_contact.multiscale.mixed_cem.options import DEFAULT_MAX_NBASIS, MixedCEMOptions

__all__ = ["StageI", "stage_one", "stage_one_cell", "stage_one_of"]

log = logging.getLogger(__name__)


@dataclass(slots=True)
class StageI:
    """U_aux: per coarse cell K_k the eigenvalues and S-orthonormal p_j^k (cell-major (|K|, 6, l_k))."""

    values: list
    modes: list
    offsets: np.ndarray  #: first aux index of each coarse cell
    residuals: np.ndarray  #: max backward error of the kept pairs per coarse cell (``_pair_residuals``)
    gaps: np.ndarray  #: Λ_k, the first eigenvalue left out on each coarse cell (inf: all kept)

    @property
    def size(self) -> int:
        return int(self.offsets[-1])


#: Stage I eigenvalues are dimensionless (κ̃ = c(λ+2μ)H⁻²; the modes kept have λ = O(10⁻²…10)):
#: two consecutive ones belong to one cluster when they differ by at most atol + rtol·λ.
_CLUSTER_ATOL = 1.0e-8
_CLUSTER_RTOL = 1.0e-6

#: Shift of the shift-and-invert transform: below the spectrum (which starts at λ = 0, the rigid motions).
_SHIFT = -0.05

#: Pairs requested from Krylov–Schur beyond those needed (a margin for multiplicities and the gap).
_EXTRA_PAIRS = 4

#: ``eigensolver="auto"`` uses dense LAPACK up to this many displacement DOFs of a coarse cell.
_DENSE_MAX_U = 400

#: Tolerance of the Krylov–Schur solves (relative, on the transformed eigenvalue).
_EPS_TOL = 1.0e-12


def _complete_cluster(lam: np.ndarray, n: int) -> int:
    """n, raised to the end of the eigenvalue cluster that λ_n belongs to (``lam`` ascending).

    Keeping part of a repeated eigenvalue (the three rigid motions at λ = 0 on interior cells,
    symmetric pairs) would pick an arbitrary subspace; the whole cluster is kept instead.
    """
    n0 = n
    while 0 < n < lam.size and lam[n] - lam[n - 1] <= _CLUSTER_ATOL + _CLUSTER_RTOL * abs(lam[n]):
        n += 1
    if n > n0:
        log.debug("Stage I: %d modes requested, %d kept (a repeated eigenvalue %.3e)", n0, n, lam[n0 - 1])
    return n


def _modes_to_keep(
    lam: np.ndarray, nbasis: int | None, min_gap: float | None, max_nbasis: int, complete: bool = True
) -> int | None:
    """l_k: ``nbasis`` modes, more (up to ``max_nbasis``) while λ_{l+1} < ``min_gap``, whole clusters.

    ``lam``: the smallest eigenvalues, ascending; all of them when ``complete``.  Otherwise None
    when they do not suffice to decide (the first eigenvalue left out must be among them).
    """
    if nbasis is None:
        return lam.size if complete else None
    n = min(nbasis, lam.size)
    if min_gap is not None:
        cap = min(max(max_nbasis, n), lam.size)
        while n < cap and lam[n] < min_gap:
            n += 1
    n = _complete_cluster(lam, n)
    if not complete and n >= lam.size:
        return None
    return n


def _pair_residuals(At, Bl, S, lam: np.ndarray, phi: np.ndarray, p: np.ndarray) -> float:
    """Largest normwise backward error of the pairs: ‖(Ãφ + Bᵀp, −Bφ − λSp)‖ / ((‖Ã‖+2‖B‖+λ‖S‖)‖(φ, p)‖)."""
    if lam.size == 0:
        return 0.0
    nA, nB, nS = (float(sp.linalg.norm(X)) if sp.issparse(X) else float(np.linalg.norm(X)) for X in (At, Bl, S))
    r1 = At @ phi + Bl.T @ p
    r2 = -(Bl @ phi) - (S @ p) * lam
    res = np.sqrt(np.sum(r1 * r1, axis=0) + np.sum(r2 * r2, axis=0))
    scale = (nA + 2.0 * nB + np.abs(lam) * nS) * np.sqrt(np.sum(phi * phi, axis=0) + np.sum(p * p, axis=0))
    return float(np.max(res / scale))


def _s_orthonormalize(p: np.ndarray, S, phi: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """(P L⁻ᵀ, Φ L⁻ᵀ) with PᵀSP = LLᵀ (fixes scaling, and the bases of repeated eigenvalues); Φ (the stress
    parts of the pairs, optional) gets the same combination."""
    gram = p.T @ (S @ p)
    try:
        L = np.linalg.cholesky(0.5 * (gram + gram.T))
    except np.linalg.LinAlgError as err:
        raise ConvergenceError(f"Stage I eigenvectors are dependent in the s-inner product: {err}") from None
    return np.linalg.solve(L, p.T).T, None if phi is None else np.linalg.solve(L, phi.T).T


def _cell_pairs_dense(At: sp.spmatrix, Bl: sp.spmatrix, S: sp.spmatrix) -> tuple[np.ndarray, np.ndarray]:
    """All pairs (λ ascending, p S-orthonormal) of B Ã⁻¹ Bᵀ p = λ S p by dense LAPACK."""
    Ad, Bd, Sd = At.toarray(), Bl.toarray(), S.toarray()
    X = sla.cho_solve(sla.cho_factor(Ad), Bd.T)
    schur = Bd @ X
    lam, vec = sla.eigh(0.5 * (schur + schur.T), Sd)
    return np.maximum(lam, 0.0), vec


def _eps_smallest(
    Af: PETSc.Mat, Bf: PETSc.Mat, nev: int, deflation: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Converged pairs nearest ``_SHIFT`` of Af x = λ Bf x (Bf ⪰ 0; Krylov–Schur, shift-and-invert by MUMPS)."""
    return generalized_eigenpairs(
        Af,
        Bf,
        nev,
        "krylovschur",
        target=_SHIFT,
        tol=_EPS_TOL,
        factor_solver="mumps",
        deflation=deflation,
        label="Stage I eigenproblem",
    )


def _count_below(K: sp.spmatrix, n_loc: int, t: float, M: sp.spmatrix) -> int:
    """#{λ < t} of B Ã⁻¹ Bᵀ p = λ S p: neg. inertia of K − tM = −[[Ã, Bᵀ], [B, tS]] minus dim X (MUMPS LDLᵀ).

    Sylvester and Haynsworth: In([[Ã, Bᵀ], [B, tS]]) = In(Ã) + In(tS − BÃ⁻¹Bᵀ), Ã ≻ 0.
    """
    return count_eigenvalues_below(K, M, t) - n_loc  # Sylvester's inertia count (MUMPS LDLᵀ, ``fem.eigen``)


def _cell_pairs_sparse(
    At: sp.spmatrix,
    Bl: sp.spmatrix,
    S: sp.spmatrix,
    nbasis: int,
    min_gap: float | None,
    max_nbasis: int,
    scale: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, float]:
    """The kept pairs (λ, p S-orthonormal) and Λ of one coarse cell: sparse shift-and-invert.

    The pencil −[[Ã, Bᵀ], [B, 0]] x = λ [[0, 0], [0, S]] x (x = (φ, p); the φ block of the right-hand
    matrix is zero: infinite eigenvalues, mapped to 0 by the transform) is solved by SLEPc
    Krylov–Schur about ``_SHIFT`` < 0.  Enough pairs are requested to decide ``_modes_to_keep``
    (more when the first eigenvalue left out is not yet among them); then Sylvester's inertia just
    above the gap Λ checks that no eigenvalue below it was missed (a Krylov method can miss copies
    of a repeated one, e.g. the three rigid motions), and missing ones are searched again with the
    found ones deflated.  The pencil is equilibrated by D = diag(s I, I/s) (``scale``: ``CellOperators.scale``):
    D K D x̃ = λ D M D x̃ has the same eigenvalues and inertias, x = D x̃.
    """
    n_loc, n_u = At.shape[0], S.shape[0]
    if scale != 1.0:
        At, S = scale**2 * At, S / scale**2
    K = -sp.bmat([[At, Bl.T], [Bl, None]], format="csr")
    M = sp.block_diag([sp.csr_matrix((n_loc, n_loc)), S], format="csr")
    Kp, Mp = scipy_to_petsc(K), scipy_to_petsc(M)
    try:
        want = min(nbasis + _EXTRA_PAIRS, n_u)
        lam, X = _eps_smallest(Kp, Mp, want, None)
        for _ in range(50):
            order = np.argsort(lam, kind="stable")
            lam, X = lam[order], X[:, order]
            nk = _modes_to_keep(lam, nbasis, min_gap, max_nbasis, complete=lam.size >= n_u)
            if nk is None:  # the first eigenvalue left out is not among them yet
                want = min(max(2 * want, lam.size + _EXTRA_PAIRS), n_u)
                more_v, more_x = _eps_smallest(Kp, Mp, min(want - lam.size + _EXTRA_PAIRS, n_u - lam.size), X)
                lam, X = np.concatenate([lam, more_v]), np.concatenate([X, more_x], axis=1)
                continue
            cut = lam[nk] if nk < lam.size else lam[-1]
            t = cut + _CLUSTER_ATOL + _CLUSTER_RTOL * abs(cut)
            below, have = _count_below(K, n_loc, t, M), int(np.count_nonzero(lam < t))
            if below <= have:
                break
            log.debug(
                "Stage I: Krylov–Schur missed %d pair(s) below %.3e; deflating and searching again", below - have, t
            )
            keep = lam < t
            more_v, more_x = _eps_smallest(Kp, Mp, min(below - have + _EXTRA_PAIRS, n_u - have), X[:, keep])
            lam, X = np.concatenate([lam[keep], more_v]), np.concatenate([X[:, keep], more_x], axis=1)
        else:
            raise ConvergenceError(f"Stage I (n = {n_u}): could not find the smallest eigenpairs")
    finally:
        Kp.destroy()
        Mp.destroy()
    gap = float(lam[nk]) if nk < lam.size else np.inf
    if scale != 1.0:
        return np.maximum(lam[:nk], 0.0), X[n_loc:, :nk] / scale, gap, scale * X[:n_loc, :nk]
    return np.maximum(lam[:nk], 0.0), X[n_loc:, :nk], gap, X[:n_loc, :nk]


def stage_one_cell(
    ops: CellOperators,
    topo: Topology,
    cells: np.ndarray,
    nbasis: int | None,
    min_gap: float | None = None,
    max_nbasis: int = DEFAULT_MAX_NBASIS,
    eigensolver: str = "auto",
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Stage I on one coarse cell (fine ``cells``): (λ kept, p (|K|, 6, l) S-orthonormal, Λ, residual).

    ``eigensolver``: "lapack" (all pairs, dense), "krylovschur" (sparse, ``_cell_pairs_sparse``) or
    "auto" (dense up to ``_DENSE_MAX_U`` displacement DOFs, and for ``nbasis=None``).
    """
    cells = np.sort(np.asarray(cells, dtype=np.int64))
    space = local_stress_space(ops, topo, cells)
    At, Bl = local_operators(ops, space)
    S = block_diag(ops.S[cells])
    n_u = S.shape[0]
    dense = eigensolver == "lapack" or nbasis is None or (eigensolver == "auto" and n_u <= _DENSE_MAX_U)
    if dense:
        lam, vec = _cell_pairs_dense(At, Bl, S)
        nk = _modes_to_keep(lam, nbasis, min_gap, max_nbasis)
        gap = float(lam[nk]) if nk < lam.size else np.inf
        lam, p = lam[:nk], vec[:, :nk]
        p, _ = _s_orthonormalize(p, S)
        phi = -spla.splu(At.tocsc()).solve(np.asarray(Bl.T @ p))  # φ = −Ã⁻¹Bᵀp (sparse LU of the local Ã)
    else:  # the pencil's eigenvectors carry φ
        lam, p, gap, phi = _cell_pairs_sparse(At, Bl, S, nbasis, min_gap, max_nbasis, ops.scale)
        p, phi = _s_orthonormalize(p, S, phi)
    # the backward error of the pairs, from the equations (not the eigensolver's own estimate)
    res = _pair_residuals(At, Bl, S, lam, phi, p)
    return lam, np.ascontiguousarray(p).reshape(cells.size, 6, lam.size), gap, res


def stage_one(
    ops: CellOperators,
    topo: Topology,
    grid: CoarseGrid,
    nbasis: int | None,
    min_gap: float | None = None,
    max_nbasis: int = DEFAULT_MAX_NBASIS,
    eigensolver: str = "auto",
    *,
    comm: MPI.Comm = MPI.COMM_SELF,
) -> StageI:
    """Mixed local spectral problems Ã φ + Bᵀp = 0, −Bφ = λ S p on every coarse cell (``stage_one_cell``).

    Each cell keeps ``_modes_to_keep`` modes: ``nbasis`` (all if None), raised while the first
    eigenvalue left out is below ``min_gap`` (at most ``max_nbasis``) and to whole clusters.
    Under ``comm`` the coarse cells are shared out and every rank gets all results.
    """
    out = work.run_shared(
        np.array([len(c) for c in grid.cells], dtype=float),
        comm,
        "mixed CEM Stage I (coarse cells)",
        lambda k: stage_one_cell(ops, topo, grid.cells[k], nbasis, min_gap, max_nbasis, eigensolver),
        balanced=True,
        logger=log,
    )
    return _stage_one_from(out)


def _stage_one_from(out: list) -> StageI:
    values = [o[0] for o in out]
    modes = [o[1] for o in out]
    offsets = np.concatenate([[0], np.cumsum([m.shape[2] for m in modes])]).astype(np.int64)
    return StageI(values, modes, offsets, np.array([o[3] for o in out]), np.array([o[2] for o in out]))


def stage_one_of(
    sub,
    grid: CoarseGrid,
    options: MixedCEMOptions,
    *,
    H: float,
    traction_free_facets: np.ndarray | None = None,
) -> tuple[CellOperators, "Topology", StageI]:
    """Stage I alone for an Ω₁ ``MixedSubproblem``: (cell operators, local-space topology, U_aux)."""
    ops = cell_operators(sub, H, options.weight, options.s_factor)
    scale_to_cell_sizes(ops, grid, H)
    topo = Topology(sub.mesh, ops.num_aw, traction_free_facets)
    return (
        ops,
        topo,
        stage_one(ops, topo, grid, options.nbasis, options.min_gap, options.max_nbasis, options.eigensolver),
    )
