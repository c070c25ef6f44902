"""Mixed CEM-GMsFEM on Ω₁ (METHOD §3, Algorithm 4): local spaces, Stage I, Stage II, Robin and source correctors.

All fine quantities live in a *cell-major* discontinuous layout: a stress is an
array (n_cells, 30) of DG P3 coefficients (10 Lagrange nodes × (σ_xx, σ_xy,
σ_yy)), a displacement (n_cells, 6) of DG P1 coefficients.  Every volume
operator is block diagonal in this layout (compliance, Robin term on γ,
divergence, masses), so local problems are assembled from cell blocks.

**Local stress spaces.**  For a set of fine cells ω (a coarse cell K_i or an
oversampled patch K_{i,m}) X_h(ω) = {τ ∈ AW(ω) : τn = 0 on ∂ω ∩ Ω₁° and on the
traction-free sides of Ω₁}.  Its basis: the global AW basis functions supported in
ω (interior vertices, edges not on the inner boundary, cells) plus, at every vertex
v on the inner boundary, the restrictions to ω of the AW vertex functions with value
z, z in the null space of τ ↦ τn for the normals of the inner-boundary edges at v
(σ_tt stays free there, as in the restriction of AW to ω; at a patch corner nothing
is left).  Essential τn = 0 sides of ∂Ω₁ (``traction_free_facets``) are treated like
inner boundary, so with ω = Ω₁ the space is the constrained AW(Ω₁).  The zero
extension of such a function is H(div)-conforming but not vertex continuous, so
X_ms ⊄ AW(Ω₁); everything is computed on the DG P3 representation.

**Stage I** (per coarse cell): Ã φ + Bᵀp = 0, −Bφ = λ S p with
Ã = (A·,·) + β∫_{γ∩∂K}(·n)·(·n) and S the κ̃-weighted mass, κ̃ = c(λ+2μ)H⁻² (the
weight of the primal method, METHOD §3).  Large cells: the pencil
−[[Ã, Bᵀ], [B, 0]] x = λ [[0, 0], [0, S]] x by SLEPc Krylov–Schur with
shift-and-invert (MUMPS) for the few pairs kept, checked by Sylvester's inertia just
above the gap (a Krylov method can miss copies of a repeated eigenvalue, e.g. the
three rigid motions at λ = 0 on interior cells; missing pairs are searched again
with the found ones deflated); small cells: dense LAPACK on B Ã⁻¹ Bᵀ p = λ S p
(``eigensolver``).  The l smallest, S-orthonormal p_j^i span U_aux; π = Π Πᵀ S.
l is per cell: at least ``nbasis`` (the paper's 3), more while the first eigenvalue
left out is below ``min_gap``, and whole clusters.  The Stage II bases decay like
exp(−ρ·distance/H), and ρ falls with the number of near-divergence-free modes left
out (for ν → ½ they have Λ ∝ μ/(λ+2μ)): with l = 3 ρ drops from 2.2 (ν = 0.3) to
0.60 (ν = 0.499) at h = 1/64, H = 1/16; with the extra modes it is 1.9 again
(``DEFAULT_MIN_GAP``, ``basis_decay_profile``, benchmarks/mixed_ms_localization.py).

**Stage II** and the correctors (sparse LU per patch): with Z = S Π (patch
columns) and y = Zᵀ q the relaxed problem s(πq, πv) − (div ψ, v) = s(p, πv)
becomes the sparse symmetric system

    [Ã   Bᵀ   0 ] [ψ]   [ 0     ]      [Ã   Bᵀ   0 ] [Q]   [C_i g]      [Ã   Bᵀ   0 ] [σ_f]   [ 0      ]
    [B   0   −Z ] [q] = [−Z e_j ],     [B   0   −Z ] [N] = [ 0   ],     [B   0   −Z ] [u_f] = [ G|K_i  ]
    [0  −Zᵀ   I ] [y]   [ 0     ]      [0  −Zᵀ   I ] [y]   [ 0   ]      [0  −Zᵀ   I ] [ y ]   [ 0      ]

(C_i g = ∫_{γ∩∂K_i} g·τn₁ on the coarse cells touching γ; G|K_i = −(f χ_{K_i}, v)).

**Source correction** (METHOD §9; ``MixedCEMOptions.source_correction``, default on;
off is the paper's algorithm).  The divergence of X_ms lies in S·U_aux, so the
paper's Ω₁ step sees the load only through its moments against U_aux: an
O(H Λ^{-1/2}) error that no number of layers removes (e_σ = 0.33 at m = 3 for a load
in Ω₁, h = 1/32, H = 1/8).  For each coarse cell with f|K_i ≠ 0 the third system above
gives the localized corrector (σ_{f,i}, u_{f,i}) on K_{i,m}:

    (Aσ_{f,i}, τ) + (div τ, u_{f,i}) + β∫_γ (σ_{f,i}n₁)·(τn₁) = 0,
    s(π u_{f,i}, πv) − (div σ_{f,i}, v) = (f χ_{K_i}, v)        on X_h(K_{i,m}) × U_h(K_{i,m}),

σ_f = Σ_i σ_{f,i}, u_f = Σ_i u_{f,i}, and the coarse problem solves for the
remainder: σ₁ = r + Q g + σ_f, u₁ = w + N g + u_f.  With global correctors σ_h − σ_f − Q g
lies in the global multiscale space (its relaxed divergence equation has a right-hand
side in S·U_aux), so the error is the localization error of correctors and bases,
which decays exponentially with m for any load.  In the code σ_f is one more column
of the data: d = [g; 1] (n_g γ values, then the load).

**Boundary data** (issue 14).  Tractions on Γ_N: σ = σ̂ + s₀ with the lifting s₀ (s₀n = t) of the fine
Ω₁ subproblem and σ̂n = 0 there (``traction_free_facets``, like the traction-free sides); s₀ moves to the
right-hand side as G ← G − (div s₀, v) and the stress-side load F = −(A s₀, τ) − β∫_γ(s₀n)·(τn); a
prescribed u_D on Γ_D adds ∫_ΓD u_D·(τn) to F (``CellOperators.F``, ``.s0``).  F|K_i enters the τ rows of
the source corrector's system above (the load column), Ψᵀ F the coarse right-hand side (``CoarseOperators.Fphi``),
and the trace σ₁n₁ gets s₀'s (``_E_g``).  Without source correctors F is seen only through Ψᵀ F (a warning).

**Coarse operators.**  With Φ = [Ψ | Q | σ_f] the online problem needs only small dense
matrices, accumulated coarse cell by coarse cell from the patch functions that
reach it: the Robin/compliance Gram ΦᵀÃΦ, the compliance Gram ΦᵀKΦ (A-norms),
Πᵀ B Φ, (BΦ)ᵀ[N | u_f], ΦᵀC, the trace map E Φ (σn₁ at the γ nodes, averaged at
vertices where the multiscale trace may jump), and the displacement Gram of
[Π | N | u_f].  The online Ω₁ solve is one dense LU solve of size dim X_ms + dim U_aux,
precomputed once per interface value (``InterfaceResponse``).

**Storage.**  A patch function is kept only on its patch, per coarse cell K of the
patch: its coefficients in the AW functions touching K (≈ 11 numbers per fine cell
instead of the 30 of DG P3, ``CoarseCellDofs``) and its displacement (6 per cell).

**Implementation.**  A local basis is kept cell by cell (L_c = P_c T_c: the
AW columns of the cell, combined at inner-boundary vertices), so Lᵀ Ã L and B L
are assembled from dense cell blocks like element matrices.  Stage II is solved by
static condensation along the coarse skeleton (``_stage_two_condensed``): a patch
system is the sum of its coarse cells' blocks, coupled only through the AW vertex
and edge DOFs shared by two coarse cells, so each coarse cell's own unknowns (its
inner stress functions, displacements and aux multipliers) are eliminated once
(Schur complement S_K on its skeleton, MUMPS), each patch factorizes only
Σ_K T_Γᵀ S_K T_Γ on its skeleton (4.7·10³ instead of 1.0·10⁵ unknowns for an interior
patch at h = 1/128, H = 1/16, m = 3; symmetric positive definite: MUMPS Cholesky,
7.5·10⁸ flops against 2.8·10⁹ for the LU of the whole patch system) and the own
unknowns are recovered coarse cell by coarse cell for all the patches reaching it in
one multi-right-hand-side solve with the LU kept from the condensation (on the rank that
made it: both phases share the coarse cells out alike).  The patch skeleton matrices are not summed cell by
cell: their inner block is a principal submatrix of one global Σ_K S_K
(``_GlobalSkeleton``; an inner skeleton DOF has all its coarse cells in the patch),
and only the columns of the patch-boundary vertex functions are summed per cell.  The same
linear systems as one LU per patch (the test oracle ``tests/multiscale_oracles.stage_two_reference``).  The Stage I
cells, Stage II patches and coarse-operator cells can be shared out over an MPI communicator
(``comm``; every rank holds the whole Ω₁ mesh): each is computed once, the results are broadcast
and the coarse matrices summed.  Offline phases report progress (``fenics_contact.progress``).
The offline data can be cached (``cache_dir``): one npz file per configuration,
keyed by a hash of everything they depend on (``mixed_offline_key``), checked by
a stored checksum, written atomically and patch by patch (no second copy); the
patch functions are stored in float32 (they only rebuild the fine output fields,
relative rounding 6·10⁻⁸), U_aux and the coarse matrices in float64.
"""

import hashlib
import json
import logging
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import NamedTuple

import basix.ufl
import dolfinx.fem.petsc
import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact import __version__
from fenics_contact.fem import forms_mixed
from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.eigen import count_eigenvalues_below, generalized_eigenpairs
from fenics_contact.fem.linalg import ReusedAnalysis, SparseFactor, assemble_scipy, scipy_to_petsc
from fenics_contact.multiscale.cache import OfflineCache, hash_array
from fenics_contact.multiscale.work import run_shared
from fenics_contact.multiscale.cem.operators import kappa_tilde, require_serial
from fenics_contact.multiscale.cem.options import DEFAULT_S_FACTOR
from fenics_contact.multiscale.coarse import CoarseGrid
from fenics_contact.problem.tags import Boundary

__all__ = [
    "DEFAULT_MAX_NBASIS",
    "DEFAULT_MIN_GAP",
    "MIXED_CACHE_FORMAT",
    "SMALL_GAP",
    "CellOperators",
    "CoarseCellDofs",
    "CoarseOperators",
    "LocalSpace",
    "InterfaceResponse",
    "MixedCEMOptions",
    "MixedMultiscaleOmega1",
    "MixedOfflineCache",
    "OfflineData",
    "PatchFunctions",
    "StageI",
    "aw_map",
    "cell_rows",
    "patch_system",
    "basis_decay_profile",
    "cell_operators",
    "coarse_operators",
    "held_cells",
    "local_stress_space",
    "mixed_offline_key",
    "stage_one",
    "stage_one_cell",
    "stage_one_of",
    "stage_two",
]

log = logging.getLogger(__name__)

#: Λ·c below this triggers a warning: at h = 1/64, H = 1/16, m = 5 the paper's cases gave e_σ ≤ 1e-3 with
#: Λ·c ≥ 0.07 (ν = 0.35: 0.57; ν = 0.49: 0.07, 0.31) and 9e-3…2e-1 with Λ·c ≤ 0.03 (ν = 0.499).
SMALL_GAP = 0.05

#: Default Stage I target for Λ, the first eigenvalue left out on each coarse cell (κ̃ with c).
#: The Stage II bases decay like exp(−ρ·distance/H).  Global bases of a central cell, h = 1/64,
#: H = 1/16, c = 3 (benchmarks/mixed_ms_localization.py): ρ = 2.2 for ν = 0.3 (l = 3, Λ = 1.5) and
#: 1.8 for ν = 0.49 (l = 3, Λ = 0.10), but 0.60 for ν = 0.499 (l = 3, Λ = 0.011): near-div-free
#: modes have Λ ∝ μ/(λ+2μ).  Adding modes until Λ ≥ 0.1 gives ρ = 1.9 for ν = 0.499 (11–21 modes)
#: and, capped at 32 modes (Λ = 0.019), also for ν = 0.4999.  For ν ≤ 0.49 the paper's l = 3
#: already meets the target.
DEFAULT_MIN_GAP = 0.1
#: Default cap on the Stage I modes per coarse cell when ``min_gap`` adds modes.
DEFAULT_MAX_NBASIS = 32

#: Bumped whenever the layout or meaning of the cached mixed offline arrays changes.
MIXED_CACHE_FORMAT = 4  # 4: Fphi (issue 14: the boundary data's stress-side load)


@dataclass(frozen=True, slots=True)
class MixedCEMOptions:
    """Mixed CEM parameters: m oversampling layers, l eigenfunctions per coarse cell (None: all).

    ``nbasis`` is the least number of Stage I modes per coarse cell (the paper's l = 3).  With
    ``min_gap`` a cell keeps further modes, up to ``max_nbasis``, until the first eigenvalue left out
    is ≥ ``min_gap`` (the decay of the bases with the layers is governed by it, see
    ``DEFAULT_MIN_GAP``); ``min_gap=None`` keeps exactly ``nbasis`` (the paper's fixed l).
    """

    layers: int = 3
    nbasis: int | None = 3
    min_gap: float | None = DEFAULT_MIN_GAP
    max_nbasis: int = DEFAULT_MAX_NBASIS
    weight: str = "lambda+2mu"  #: κ̃ = c(λ+2μ)H⁻² (METHOD §3 has c = 1) or "2mu": κ̃ = c·2μ H⁻²
    #: c, as for the primal CEM (multiscale.CEMOptions.s_factor). Model 2, h = 1/32, H = 1/8, m = 3:
    #: e_σ = 4.2e-3 (c = 1), 2.3e-3 (c = 3), 2.6e-3 (c = 10).
    s_factor: float = DEFAULT_S_FACTOR
    #: Localized source correctors (METHOD §9): the Ω₁ response to f is computed on the oversampled
    #: patches and the coarse problem solves for the remainder, so that the error falls with m for any
    #: load.  False: the paper's Algorithm 4 (f seen only through U_aux: an O(H Λ^{-1/2}) floor).
    source_correction: bool = True
    #: Stage I eigensolver: "auto" (dense LAPACK for small coarse cells, else "krylovschur"), "lapack"
    #: (all pairs, dense) or "krylovschur" (SLEPc shift-and-invert for the pairs kept, inertia-checked).
    eigensolver: str = "auto"

    def __post_init__(self) -> None:
        if not (np.isfinite(self.s_factor) and self.s_factor > 0):
            raise InputError(f"s_factor must be finite and > 0, got {self.s_factor!r}")
        if self.weight not in ("lambda+2mu", "2mu"):
            raise InputError(f"weight must be 'lambda+2mu' or '2mu', got {self.weight!r}")
        if int(self.layers) != self.layers or self.layers < 0:
            raise InputError(f"the number of oversampling layers must be an integer >= 0, got {self.layers!r}")
        if self.nbasis is not None and (int(self.nbasis) != self.nbasis or self.nbasis < 1):
            raise InputError(f"nbasis must be an integer >= 1 (or None for all modes), got {self.nbasis!r}")
        if self.min_gap is not None and not (np.isfinite(self.min_gap) and self.min_gap > 0):
            raise InputError(f"min_gap must be finite and > 0 (or None for a fixed nbasis), got {self.min_gap!r}")
        if int(self.max_nbasis) != self.max_nbasis or self.max_nbasis < 1:
            raise InputError(f"max_nbasis must be an integer >= 1, got {self.max_nbasis!r}")
        if self.nbasis is not None and self.max_nbasis < self.nbasis:
            raise InputError(f"max_nbasis ({self.max_nbasis}) must be >= nbasis ({self.nbasis})")
        if self.eigensolver not in ("auto", "lapack", "krylovschur"):
            raise InputError(f"eigensolver must be 'auto', 'lapack' or 'krylovschur', got {self.eigensolver!r}")
        if not isinstance(self.source_correction, (bool, np.bool_)):
            raise InputError(f"source_correction must be True or False, got {self.source_correction!r}")


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def _csr_cell_blocks(A: sp.csr_matrix, rows: np.ndarray, b: int) -> tuple[np.ndarray, np.ndarray]:
    """(values, columns), each (n, a, b): the CSR entries of the cells' rows ``rows`` (n, a), every one of which holds
    b entries.  Where every row of A holds b entries and each cell's rows are a whole block of a consecutive rows
    (a DG form, the AW prolongation on a serial mesh), the CSR arrays are the blocks already: views when the
    cells come in row order, one gather of blocks otherwise; else one (n, a, b) index gather."""
    n, a = rows.shape
    first = rows[:, 0]
    if (A.shape[0] % a == 0 and np.all(np.diff(A.indptr) == b) and np.all(first % a == 0)
            and np.array_equal(rows - first[:, None], np.broadcast_to(np.arange(a), rows.shape))):
        data, ind = A.data.reshape(-1, a, b), A.indices.reshape(-1, a, b)
        k = first // a
        if not (k.size == data.shape[0] and np.array_equal(k, np.arange(k.size))):
            data, ind = data[k], ind[k]
        return data, ind
    at = A.indptr[rows][..., None] + np.arange(b)  # (n, a, b)
    return A.data[at], A.indices[at]


def _cell_blocks(A: sp.spmatrix, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
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


def _block_diag(blocks: np.ndarray) -> sp.csr_matrix:
    """The block-diagonal CSR matrix of dense blocks (n, a, b)."""
    n, a, b = blocks.shape
    rows = np.broadcast_to((a * np.arange(n)[:, None, None] + np.arange(a)[None, :, None]), blocks.shape)
    cols = np.broadcast_to((b * np.arange(n)[:, None, None] + np.arange(b)[None, None, :]), blocks.shape)
    return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(n * a, n * b))


def cell_rows(cells: np.ndarray, width: int) -> np.ndarray:
    """The cell-major rows of ``cells`` in a layout of ``width`` rows per cell (cell by cell, in order)."""
    return (width * np.asarray(cells, dtype=np.int64)[:, None] + np.arange(width)).ravel()


def _column_blocks(P: sp.spmatrix, ncell: int, a: int) -> tuple[np.ndarray, np.ndarray]:
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


def _row_blocks(P: sp.spmatrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``_column_blocks(P[rows.ravel()], ...)`` read straight from the CSR arrays when every cell's rows hold
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
    return _column_blocks(P[rows.ravel()], rows.shape[0], rows.shape[1])


# ---------------------------------------------------------------------------------------
# cellwise operators of Ω₁
# ---------------------------------------------------------------------------------------
@dataclass(slots=True)
class CellOperators:
    """Cell blocks and interface maps of the Ω₁ mixed problem in the cell-major layout."""

    K: np.ndarray  #: (n, 30, 30) compliance (Aσ, τ)
    R: np.ndarray  #: (n_γ, 30, 30) β ∫_γ (σn)·(τn) on the cells ``gamma_cells`` (zero elsewhere)
    B: np.ndarray  #: (n, 6, 30) (div σ, v)
    M: np.ndarray  #: (n, 6, 6) L² mass of DG P1
    S: np.ndarray  #: (n, 6, 6) κ̃-weighted mass, κ̃ = (λ+2μ)H⁻²
    G: np.ndarray  #: (n, 6) −(f, v)
    C: sp.csr_matrix  #: (30 n, n_g) ∫_γ g·(τn₁), g by values (x, y) at the γ nodes
    E: sp.csr_matrix  #: (n_g, 30 n) σn₁ at the γ nodes (average of the two sides at vertices)
    num_aw: int  #: dim AW(Ω₁)
    dg_rows: np.ndarray  #: (n, 30) standard DG P3 index of each cell-major stress entry
    u_rows: np.ndarray  #: (n, 6) standard DG P1 index of each cell-major displacement entry
    gamma_cells: np.ndarray  #: sorted cells with a γ facet
    P_cols: np.ndarray  #: (n, w) AW indices of the nonzero columns of P in the rows of each cell (sorted, −1 pads)
    P_blocks: np.ndarray  #: (n, 30, w) those columns of P: P[rows of c][:, P_cols[c]]
    #: (n, 30) stress-side load of the boundary data (issue 14), a functional on DG P3 stresses:
    #: −(A s₀, τ) − β∫_γ (s₀n)·(τn) + ∫_ΓD u_D·(τn); None (zero) without tractions and u_D
    F: np.ndarray | None = None
    #: (n, 30) the traction lifting s₀ (σ₁ = homogeneous part + s₀, s₀n = t on Γ_N); None without tractions
    s0: np.ndarray | None = None

    @property
    def has_boundary_data(self) -> bool:
        """Whether tractions or a prescribed displacement act on Ω₁ (a stress-side load F or a lifting s₀)."""
        return self.F is not None or self.s0 is not None

    @property
    def num_cells(self) -> int:
        return self.K.shape[0]

    def kt(self, cells: np.ndarray) -> np.ndarray:
        """Blocks (|cells|, 30, 30) of Ã = compliance + β ∫_γ (σn)·(τn) (only γ cells carry the Robin term)."""
        cells = np.asarray(cells, dtype=np.int64)
        out = self.K[cells]
        k = np.searchsorted(self.gamma_cells, cells)
        on = (k < self.gamma_cells.size) & (self.gamma_cells[np.minimum(k, self.gamma_cells.size - 1)] == cells)
        if np.any(on):
            out[on] += self.R[k[on]]
        return out

    @property
    def P(self) -> sp.csr_matrix:
        """The AW prolongation (30 n × dim AW), rows cell-major (rebuilt from the cell blocks)."""
        n, a, w = self.P_blocks.shape
        rows = np.broadcast_to((a * np.arange(n)[:, None, None] + np.arange(a)[None, :, None]), self.P_blocks.shape)
        cols = np.broadcast_to(self.P_cols[:, None, :], self.P_blocks.shape)
        keep = (cols >= 0) & (self.P_blocks != 0.0)
        return sp.csr_matrix((self.P_blocks[keep], (rows[keep], cols[keep])), shape=(a * n, self.num_aw))

    @property
    def num_gamma_values(self) -> int:
        return self.C.shape[1]


def _trace_operator(msh: dmesh.Mesh, dg: fem.FunctionSpace, gamma: np.ndarray, points: np.ndarray) -> sp.csr_matrix:
    """σn (outward normal) at ``points`` on the γ facets, cell-major columns; averaged where two facets meet."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    geo = dmesh.entities_to_geometry(msh, tdim - 1, gamma)
    x = msh.geometry.x[:, :2]
    a, b = x[geo[:, 0]], x[geo[:, 1]]
    d = b - a
    length = np.linalg.norm(d, axis=1)
    cells = f2c.array[f2c.offsets[gamma]].astype(np.int64)  # a γ facet is on ∂Ω₁: one cell
    n = np.stack([d[:, 1], -d[:, 0]], axis=1) / length[:, None]
    centre = x[msh.geometry.dofmaps[0][cells]].mean(axis=1)
    n[np.sum(n * (0.5 * (a + b) - centre), axis=1) < 0] *= -1.0
    # (point, facet) incidences
    rel = points[:, None, :] - a[None]
    s = np.einsum("pfi,fi->pf", rel, d) / length[None] ** 2
    dist = np.linalg.norm(rel - s[..., None] * d[None], axis=-1)
    on = (dist <= 1e-10 * length[None]) & (s >= -1e-10) & (s <= 1 + 1e-10)
    pi, fi = np.nonzero(on)
    if np.unique(pi).size != points.shape[0]:
        raise RuntimeError("a γ node lies on no γ facet")
    weight = 1.0 / np.bincount(pi, minlength=points.shape[0])[pi]
    c = cells[fi]
    gx = x[msh.geometry.dofmaps[0][c]]
    J = np.stack([gx[:, 1] - gx[:, 0], gx[:, 2] - gx[:, 0]], axis=-1)
    X = np.linalg.solve(J, (points[pi] - gx[:, 0])[..., None])[..., 0]
    el = dg.ufl_element().sub_elements[0].basix_element
    phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 10)
    nn = n[fi]
    rows, cols, vals = [], [], []
    base = 30 * c[:, None] + 3 * np.arange(10)[None, :]  # (N, 10)
    for comp, (j, w) in enumerate([(0, nn[:, 0]), (1, nn[:, 1]), (1, nn[:, 0]), (2, nn[:, 1])]):
        row = 2 * pi + (0 if comp < 2 else 1)
        rows.append(np.repeat(row, 10))
        cols.append((base + j).ravel())
        vals.append((phi * (w * weight)[:, None]).ravel())
    ncell = msh.topology.index_map(tdim).size_local
    E = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * points.shape[0], 30 * ncell)
    )
    E.sum_duplicates()
    return E


def cell_operators(sub, H: float, weight: str = "lambda+2mu", s_factor: float = 1.0) -> CellOperators:
    """Cell-major operators of the Ω₁ ``fem.mixed.MixedSubproblem`` ``sub`` (Robin β, no contact)."""
    msh, ft, fields = sub.mesh, sub.facet_tags, sub.fields
    if sub.beta is None:
        raise InputError("the Ω₁ subproblem needs a Robin coefficient β")
    tdim = msh.topology.dim
    ncell = msh.topology.index_map(tdim).size_local
    dg, U = sub.dg, sub.U
    dg_rows = (3 * dg.dofmap.list[:ncell].astype(np.int64)[:, :, None] + np.arange(3)).reshape(ncell, 30)
    u_rows = (2 * U.dofmap.list[:ncell].astype(np.int64)[:, :, None] + np.arange(2)).reshape(ncell, 6)
    s, t = ufl.TrialFunction(dg), ufl.TestFunction(dg)
    w, v = ufl.TrialFunction(U), ufl.TestFunction(U)
    n = ufl.FacetNormal(msh)
    ds = forms_mixed.boundary_measure(msh, ft)
    gamma = ft.find(Boundary.INTERFACE)
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    gamma_cells = np.unique(f2c.array[f2c.offsets[gamma]]).astype(np.int64)  # a γ facet is on ∂Ω₁: one cell
    K = _cell_blocks(assemble_scipy(forms_mixed.compliance_form(s, t, fields.lmbda, fields.mu)), dg_rows, dg_rows)
    R = _cell_blocks(assemble_scipy(forms_mixed.robin_form(s, t, n, 1.0, ds(Boundary.INTERFACE))),
                     dg_rows[gamma_cells], dg_rows[gamma_cells])
    B = _cell_blocks(assemble_scipy(forms_mixed.divergence_form(s, v)), u_rows, dg_rows)
    M = _cell_blocks(assemble_scipy(forms_mixed.mass_form(w, v)), u_rows, u_rows)
    kt = kappa_tilde(fields.lmbda, fields.mu, H, s_factor) if weight == "lambda+2mu" else s_factor * 2.0 * fields.mu / H**2
    S = _cell_blocks(assemble_scipy(kt * ufl.inner(w, v) * ufl.dx), u_rows, u_rows)
    Gv = fem.assemble_vector(fem.form(forms_mixed.load_form(fields.f, v)))
    Gv.scatter_reverse(dolfinx.la.InsertMode.add)
    G = Gv.array[u_rows]
    F, s0 = _boundary_loads(sub, dg_rows, t, n, ds)
    # interface data: continuous vector P3 on γ, nodes ordered as sub.gamma_points
    Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
    blocks = fem.locate_dofs_topological(Lam, tdim - 1, gamma)
    coords = Lam.tabulate_dof_coordinates()[blocks, :2]
    order = np.lexsort((coords[:, 0], coords[:, 1]))
    blocks, coords = blocks[order], coords[order]
    if coords.shape != sub.gamma_points.shape or not np.allclose(coords, sub.gamma_points, atol=1e-12):
        raise RuntimeError("the γ nodes do not match the Ω₁ subproblem's interface nodes")
    g = ufl.TrialFunction(Lam)
    Cfull = assemble_scipy(forms_mixed.robin_data_form(g, t, n, ds(Boundary.INTERFACE)))
    C = Cfull[dg_rows.ravel()][:, (2 * blocks[:, None] + np.arange(2)).ravel()].tocsr()
    E = _trace_operator(msh, dg, gamma, coords)
    # the local spaces start from the full (unconstrained) AW space, also where τn = 0 sides constrain sub.space
    space = sub.space
    num_full = 3 * msh.topology.index_map(0).size_local + 4 * msh.topology.index_map(1).size_local + 3 * ncell
    if space.num_dofs_full != num_full:
        raise RuntimeError("the full AW prolongation does not have the raw serial numbering")
    if space.dg is dg and np.array_equal(space.dg_rows, dg_rows):  # the space's own blocks (no CSR P, no copy)
        P_cols, P_blocks = space.cell_prolongation()
    else:
        P_cols, P_blocks = _row_blocks(space.full_prolongation, dg_rows)
    if s0 is not None:  # the lifting is a load: (div σ̂, v) = −(f, v) − (div s₀, v), σ = σ̂ + s₀
        G = G - np.einsum("cab,cb->ca", B, s0)
        lift = -np.einsum("cab,cb->ca", K, s0)
        lift[gamma_cells] -= sub.beta * np.einsum("cab,cb->ca", R, s0[gamma_cells])
        F = lift if F is None else F + lift
    return CellOperators(K, sub.beta * R, B, M, S, G, C, E, int(num_full), dg_rows, u_rows, gamma_cells,
                         P_cols, P_blocks, F, s0)


def _boundary_loads(sub, dg_rows: np.ndarray, t, n, ds) -> tuple:
    """(∫_ΓD u_D·(τn) as a cell-major (n, 30) functional or None, the lifting s₀ cell-major or None).

    The boundary data of the Ω₁ ``MixedSubproblem`` ``sub`` (issue 14): its traction lifting ``sub.s0``
    (DG P3; σn = t on Γ_N) and its prescribed displacement ``sub.u_D`` (P3 on Γ_D).  Traction-free
    and traction sides are essential in the local spaces (``_Topology(traction_free_facets=)``).
    """
    s0 = None
    if getattr(sub, "_lifted", False):
        s0 = np.ascontiguousarray(sub.s0[dg_rows])
    F = None
    if getattr(sub, "u_D", None) is not None:
        Fv = fem.assemble_vector(fem.form(forms_mixed.robin_data_form(sub.u_D, t, n, ds(Boundary.GAMMA_D))))
        Fv.scatter_reverse(dolfinx.la.InsertMode.add)
        F = np.ascontiguousarray(Fv.array[dg_rows])
    return F, s0


# ---------------------------------------------------------------------------------------
# local stress spaces
# ---------------------------------------------------------------------------------------
class _Topology:
    """Vertex/edge/cell incidences of Ω₁ and the raw AW numbering (3 per vertex, 4 per edge, 3 per cell).

    ``traction_free_facets``: edges of ∂Ω₁ with the essential condition τn = 0 (traction-free sides);
    every local space treats them like its inner boundary (``local_stress_space``).
    """

    def __init__(self, msh: dmesh.Mesh, num_aw: int, traction_free_facets: np.ndarray | None = None) -> None:
        top = msh.topology
        for d0, d1 in ((2, 0), (2, 1), (1, 0), (1, 2), (0, 2)):
            top.create_connectivity(d0, d1)
        self.nc = top.index_map(2).size_local
        self.nv = top.index_map(0).size_local
        self.ne = top.index_map(1).size_local
        if num_aw != 3 * self.nv + 4 * self.ne + 3 * self.nc:
            raise RuntimeError("the local spaces are built on the unconstrained AW numbering of Ω₁ (cell_operators "
                               "takes care of that); essential τn = 0 sides enter through traction_free_facets")
        self.c2v = top.connectivity(2, 0).array.reshape(-1, 3)[: self.nc].astype(np.int64)
        self.c2e = top.connectivity(2, 1).array.reshape(-1, 3)[: self.nc].astype(np.int64)
        self.e2v = top.connectivity(1, 0).array.reshape(-1, 2).astype(np.int64)
        self.v_deg = np.bincount(self.c2v.ravel(), minlength=self.nv)
        self.e_deg = np.bincount(self.c2e.ravel(), minlength=self.ne)
        x = msh.geometry.x[:, :2]
        vx = np.empty((self.nv, 2))
        vx[self.c2v.ravel()] = x[msh.geometry.dofmaps[0][: self.nc].ravel()]
        self.vx = vx
        self.tf_edge = np.zeros(self.ne, dtype=bool)
        if traction_free_facets is not None and len(traction_free_facets):
            tf = np.asarray(traction_free_facets, dtype=np.int64)
            if np.any(self.e_deg[tf] != 1):
                raise InputError("traction-free facets must lie on the boundary of Ω₁")
            self.tf_edge[tf] = True
        self.tf_vertex = np.zeros(self.nv, dtype=bool)
        self.tf_vertex[self.e2v[self.tf_edge].ravel()] = True


@dataclass(slots=True)
class LocalSpace:
    """X_h(ω) on fine cells ω (sorted), cell by cell: on cell c the basis is L_c = blocks[c] (30 × w).

    Column s of L_c is the restriction to c of local basis function cols[c, s] (−1: padding, a zero
    column); the basis L (30|ω| × size) stacks these blocks in the cell-major rows of ω.
    """

    cells: np.ndarray
    blocks: np.ndarray  #: (|ω|, 30, w)
    cols: np.ndarray  #: (|ω|, w) local column of each block column, −1 for none
    size: int  #: dim X_h(ω)
    num_extra: int  #: inner-boundary vertex functions (not in AW(Ω₁))
    aw_inner: np.ndarray  #: the AW function of each of the first size − num_extra local columns
    extra_vertex: np.ndarray  #: the vertex v of each inner-boundary vertex function (the last num_extra)
    extra_z: np.ndarray  #: (num_extra, 3): its value z, i.e. the function is Σ_i z_i (AW function 3v + i) on ω

    @property
    def L(self) -> sp.csr_matrix:
        """The basis as a sparse matrix (30|ω| × dim X_h(ω)) in the cell-major rows of ω."""
        nc, a, _ = self.blocks.shape
        rows = np.broadcast_to((a * np.arange(nc)[:, None] + np.arange(a))[:, :, None], self.blocks.shape)
        cols = np.broadcast_to(self.cols[:, None, :], self.blocks.shape)
        keep = (cols >= 0) & (self.blocks != 0.0)
        return sp.csr_matrix((self.blocks[keep], (rows[keep], cols[keep])), shape=(a * nc, self.size))

    def apply(self, x: np.ndarray) -> np.ndarray:
        """L x for coefficients x (size, k), cell-major (|ω|, 30, k)."""
        xc = np.where((self.cols >= 0)[:, :, None], x[np.maximum(self.cols, 0)], 0.0)  # (|ω|, w, k)
        return self.blocks @ xc


def _boundary_vertex_null_spaces(
    topo: _Topology, v_bnd: np.ndarray, e_bnd: np.ndarray, first: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Null spaces of τ ↦ τn at the inner-boundary vertices ``v_bnd`` (sorted) for the normals of their
    inner-boundary edges ``e_bnd``: (null (|v_bnd|, 3, 3) with null[k][:, q] = z_q, the local column of
    each z_q (−1: none) numbered from ``first``, the number of columns).

    No edge: all of R³ (z = e_x, e_y, e_z); parallel normals n: z = t⊗t (σ_tt free, t ⊥ n, unit
    norm in (xx, xy, yy)); two directions (a corner of ω): nothing.
    """
    nv = v_bnd.size
    null = np.zeros((nv, 3, 3))
    extra = np.full((nv, 3), -1, dtype=np.int64)
    if nv == 0:
        return null, extra, 0
    a, b = topo.vx[topo.e2v[e_bnd, 0]], topo.vx[topo.e2v[e_bnd, 1]]
    d = (b - a) / np.linalg.norm(b - a, axis=1)[:, None]
    normal = np.stack([d[:, 1], -d[:, 0]], axis=1)
    vert = topo.e2v[e_bnd].ravel()  # (2E,) each edge's two vertices
    nrm = np.repeat(normal, 2, axis=0)
    k = np.searchsorted(v_bnd, vert)
    inside = (k < nv) & (v_bnd[np.minimum(k, nv - 1)] == vert)
    k, nrm = k[inside], nrm[inside]
    count = np.bincount(k, minlength=nv)
    first_normal = np.zeros((nv, 2))
    first_normal[k[::-1]] = nrm[::-1]  # any one normal per vertex
    cross = np.abs(first_normal[k, 0] * nrm[:, 1] - first_normal[k, 1] * nrm[:, 0])
    bent = np.bincount(k, weights=(cross > 1e-10).astype(float), minlength=nv) > 0
    ncols = np.where(count == 0, 3, np.where(bent, 0, 1))
    free = count == 0
    null[free] = np.eye(3)
    line = (count > 0) & ~bent
    n0, n1 = first_normal[line, 0], first_normal[line, 1]
    z = np.stack([n1 * n1, -n0 * n1, n0 * n0], axis=1)
    z /= np.linalg.norm(z, axis=1)[:, None]
    null[line, :, 0] = np.where(np.abs(z) < 1e-14, 0.0, z)
    start = first + np.concatenate([[0], np.cumsum(ncols)[:-1]])
    for q in range(3):
        has = ncols > q
        extra[has, q] = start[has] + q
    return null, extra, int(ncols.sum())


def local_stress_space(
    ops: CellOperators, topo: _Topology, cells: np.ndarray, raw: tuple[np.ndarray, np.ndarray] | None = None,
) -> LocalSpace:
    """Basis of {τ ∈ AW(ω) : τn = 0 on ∂ω ∩ Ω₁° and on the traction-free sides} in the cell-major layout of ω.

    ``raw``: masks (vertices, edges) whose AW functions are kept unconstrained (restricted to ω) wherever they
    lie (the skeleton unknowns of a coarse cell, ``_cell_system``).
    """
    cells = np.sort(np.asarray(cells, dtype=np.int64))
    v_in = np.bincount(topo.c2v[cells].ravel(), minlength=topo.nv)
    e_in = np.bincount(topo.c2e[cells].ravel(), minlength=topo.ne)
    raw_v, raw_e = raw if raw is not None else (np.zeros(topo.nv, dtype=bool), np.zeros(topo.ne, dtype=bool))
    v_int = np.flatnonzero((v_in > 0) & (((v_in == topo.v_deg) & ~topo.tf_vertex) | raw_v))
    v_bnd = np.flatnonzero((v_in > 0) & ((v_in < topo.v_deg) | topo.tf_vertex) & ~raw_v)
    e_int = np.flatnonzero((e_in > 0) & (((e_in == topo.e_deg) & ~topo.tf_edge) | raw_e))
    e_bnd = np.flatnonzero((((e_in == 1) & (topo.e_deg == 2)) | ((e_in > 0) & topo.tf_edge)) & ~raw_e)
    nv, ne = topo.nv, topo.ne
    inner = np.concatenate([
        (3 * v_int[:, None] + np.arange(3)).ravel(),
        (3 * nv + 4 * e_int[:, None] + np.arange(4)).ravel(),
        (3 * nv + 4 * ne + 3 * cells[:, None] + np.arange(3)).ravel(),
    ])
    # AW functions supported in ω: columns of P, by cell
    local = np.full(ops.num_aw, -1, dtype=np.int64)
    local[inner] = np.arange(inner.size)
    pcols = ops.P_cols[cells]
    cols = np.where(pcols >= 0, local[np.maximum(pcols, 0)], -1)
    blocks = ops.P_blocks[cells].copy()
    null, extra, ncol = _boundary_vertex_null_spaces(topo, v_bnd, e_bnd, inner.size)
    if v_bnd.size:
        # the block columns of 3v, 3v+1, 3v+2 (consecutive: P_cols is sorted) become
        # L_c[:, q] = Σ_i P_c[:, 3v+i] z_q[i]
        vert = np.where((pcols >= 0) & (pcols < 3 * nv) & (pcols % 3 == 0), pcols // 3, -1)
        kpos = np.minimum(np.searchsorted(v_bnd, vert), v_bnd.size - 1)
        ci, si = np.nonzero((vert >= 0) & (v_bnd[kpos] == vert))
        ki = kpos[ci, si]
        slots = si[:, None] + np.arange(3)
        expected = 3 * v_bnd[ki][:, None] + np.arange(3)
        if np.any(slots >= pcols.shape[1]) or np.any(pcols[ci[:, None], slots] != expected):
            raise RuntimeError("an AW vertex function is missing from a cell block")
        vals = blocks[ci[:, None], :, slots]  # (m, 3 (i), 30)
        blocks[ci[:, None], :, slots] = np.einsum("mia,miq->mqa", vals, null[ki])
        cols[ci[:, None], slots] = extra[ki]
    kk, qq = np.nonzero(extra >= 0)  # row-major: in the order of the extra columns
    return LocalSpace(cells, blocks, cols, int(inner.size + ncol), ncol, inner, v_bnd[kk], null[kk, :, qq])


def _local_blocks(ops: CellOperators, space: LocalSpace) -> tuple[np.ndarray, np.ndarray]:
    """Cell blocks L_cᵀ Ã_c L_c (|ω|, w, w) and B_c L_c (|ω|, 6, w) of the local operators."""
    Lb = space.blocks
    At = np.swapaxes(Lb, 1, 2) @ (ops.kt(space.cells) @ Lb)
    Bl = ops.B[space.cells] @ Lb
    return At, Bl


def _local_triplets(ops: CellOperators, space: LocalSpace) -> tuple[tuple, tuple]:
    """COO triplets (rows, cols, values) of Ã = Lᵀ Ã L and B L on X_h(ω) × U_h(ω) (duplicates to be summed)."""
    At, Bl = _local_blocks(ops, space)
    nc = space.cols.shape[0]
    cols, valid = space.cols, space.cols >= 0
    both = valid[:, :, None] & valid[:, None, :]
    r = np.broadcast_to(cols[:, :, None], At.shape)[both]
    c = np.broadcast_to(cols[:, None, :], At.shape)[both]
    a_trip = (r, c, At[both])
    u_rows = np.broadcast_to((6 * np.arange(nc)[:, None] + np.arange(6))[:, :, None], Bl.shape)
    bv = np.broadcast_to(valid[:, None, :], Bl.shape)
    b_trip = (u_rows[bv], np.broadcast_to(cols[:, None, :], Bl.shape)[bv], Bl[bv])
    return a_trip, b_trip


def _local_operators(ops: CellOperators, space: LocalSpace) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """(Ã, B) of X_h(ω) × U_h(ω): Lᵀ Kt L and B L, assembled from the cell blocks."""
    (ar, ac, av), (br, bc, bv) = _local_triplets(ops, space)
    n = space.size
    At = sp.csr_matrix((av, (ar, ac)), shape=(n, n))
    Bl = sp.csr_matrix((bv, (br, bc)), shape=(6 * space.cells.size, n))
    for X in (At, Bl):
        X.eliminate_zeros()
    return At, Bl


# ---------------------------------------------------------------------------------------
# Stage I
# ---------------------------------------------------------------------------------------
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


def _eps_smallest(Af: PETSc.Mat, Bf: PETSc.Mat, nev: int, deflation: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Converged pairs nearest ``_SHIFT`` of Af x = λ Bf x (Bf ⪰ 0; Krylov–Schur, shift-and-invert by MUMPS)."""
    return generalized_eigenpairs(Af, Bf, nev, "krylovschur", target=_SHIFT, tol=_EPS_TOL, factor_solver="mumps",
                                  deflation=deflation, label="Stage I eigenproblem")


def _count_below(K: sp.spmatrix, n_loc: int, t: float, M: sp.spmatrix) -> int:
    """#{λ < t} of B Ã⁻¹ Bᵀ p = λ S p: neg. inertia of K − tM = −[[Ã, Bᵀ], [B, tS]] minus dim X (MUMPS LDLᵀ).

    Sylvester and Haynsworth: In([[Ã, Bᵀ], [B, tS]]) = In(Ã) + In(tS − BÃ⁻¹Bᵀ), Ã ≻ 0.
    """
    return count_eigenvalues_below(K, M, t) - n_loc  # Sylvester's inertia count (MUMPS LDLᵀ, ``fem.eigen``)


def _cell_pairs_sparse(
    At: sp.spmatrix, Bl: sp.spmatrix, S: sp.spmatrix, nbasis: int, min_gap: float | None, max_nbasis: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """The kept pairs (λ, p S-orthonormal) and Λ of one coarse cell: sparse shift-and-invert.

    The pencil −[[Ã, Bᵀ], [B, 0]] x = λ [[0, 0], [0, S]] x (x = (φ, p); the φ block of the right-hand
    matrix is zero: infinite eigenvalues, mapped to 0 by the transform) is solved by SLEPc
    Krylov–Schur about ``_SHIFT`` < 0.  Enough pairs are requested to decide ``_modes_to_keep``
    (more when the first eigenvalue left out is not yet among them); then Sylvester's inertia just
    above the gap Λ checks that no eigenvalue below it was missed (a Krylov method can miss copies
    of a repeated one, e.g. the three rigid motions), and missing ones are searched again with the
    found ones deflated.
    """
    n_loc, n_u = At.shape[0], S.shape[0]
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
            log.debug("Stage I: Krylov–Schur missed %d pair(s) below %.3e; deflating and searching again",
                      below - have, t)
            keep = lam < t
            more_v, more_x = _eps_smallest(Kp, Mp, min(below - have + _EXTRA_PAIRS, n_u - have), X[:, keep])
            lam, X = np.concatenate([lam[keep], more_v]), np.concatenate([X[:, keep], more_x], axis=1)
        else:
            raise ConvergenceError(f"Stage I (n = {n_u}): could not find the smallest eigenpairs")
    finally:
        Kp.destroy()
        Mp.destroy()
    gap = float(lam[nk]) if nk < lam.size else np.inf
    return np.maximum(lam[:nk], 0.0), X[n_loc:, :nk], gap, X[:n_loc, :nk]


def stage_one_cell(
    ops: CellOperators, topo: _Topology, cells: np.ndarray, nbasis: int | None,
    min_gap: float | None = None, max_nbasis: int = DEFAULT_MAX_NBASIS, eigensolver: str = "auto",
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Stage I on one coarse cell (fine ``cells``): (λ kept, p (|K|, 6, l) S-orthonormal, Λ, residual).

    ``eigensolver``: "lapack" (all pairs, dense), "krylovschur" (sparse, ``_cell_pairs_sparse``) or
    "auto" (dense up to ``_DENSE_MAX_U`` displacement DOFs, and for ``nbasis=None``).
    """
    cells = np.sort(np.asarray(cells, dtype=np.int64))
    space = local_stress_space(ops, topo, cells)
    At, Bl = _local_operators(ops, space)
    S = _block_diag(ops.S[cells])
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
        lam, p, gap, phi = _cell_pairs_sparse(At, Bl, S, nbasis, min_gap, max_nbasis)
        p, phi = _s_orthonormalize(p, S, phi)
    # the backward error of the pairs, from the equations (not the eigensolver's own estimate)
    res = _pair_residuals(At, Bl, S, lam, phi, p)
    return lam, np.ascontiguousarray(p).reshape(cells.size, 6, lam.size), gap, res


def stage_one(
    ops: CellOperators, topo: _Topology, grid: CoarseGrid, nbasis: int | None,
    min_gap: float | None = None, max_nbasis: int = DEFAULT_MAX_NBASIS, eigensolver: str = "auto",
    *, comm: MPI.Comm = MPI.COMM_SELF,
) -> StageI:
    """Mixed local spectral problems Ã φ + Bᵀp = 0, −Bφ = λ S p on every coarse cell (``stage_one_cell``).

    Each cell keeps ``_modes_to_keep`` modes: ``nbasis`` (all if None), raised while the first
    eigenvalue left out is below ``min_gap`` (at most ``max_nbasis``) and to whole clusters.
    Under ``comm`` the coarse cells are shared out and every rank gets all results.
    """
    out = _run_shared(np.array([len(c) for c in grid.cells], dtype=float), comm, "mixed CEM Stage I (coarse cells)",
                      lambda k: stage_one_cell(ops, topo, grid.cells[k], nbasis, min_gap, max_nbasis, eigensolver),
                      balanced=True)
    return _stage_one_from(out)


def _stage_one_from(out: list) -> StageI:
    values = [o[0] for o in out]
    modes = [o[1] for o in out]
    offsets = np.concatenate([[0], np.cumsum([m.shape[2] for m in modes])]).astype(np.int64)
    return StageI(values, modes, offsets, np.array([o[3] for o in out]), np.array([o[2] for o in out]))


# ---------------------------------------------------------------------------------------
# Stage II and the correction
# ---------------------------------------------------------------------------------------
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
        return ops.P_blocks[self.cells[k]] @ cc if c.ndim > 1 else np.einsum("cab,cb->ca", ops.P_blocks[self.cells[k]], cc)


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


def patch_system(ops: CellOperators, topo: _Topology, grid: CoarseGrid, aux: StageI, patch: np.ndarray):
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
    (ar, ac, av), (br, bc, bv) = _local_triplets(ops, space)
    eye = n_loc + n_u + np.arange(col)
    rows = np.concatenate([ar, n_loc + br, bc, n_loc + zr, n_loc + n_u + zc, eye])
    cols = np.concatenate([ac, bc, n_loc + br, n_loc + n_u + zc, n_loc + zr, eye])
    vals = np.concatenate([av, bv, bv, -zv, -zv, np.ones(col)])
    n_tot = n_loc + n_u + col
    lu = LocalFactor.from_coo(rows, cols, vals, n_tot)
    return space, lu, Z, aux_cols, n_loc, n_u


class LocalFactor(SparseFactor):
    """MUMPS factorizations of the local mixed CEM problems (Stage II patch, coarse-cell and skeleton systems;
    SuperLU was 10–100× slower on these saddle-point systems).

    AMD ordering for LU (ICNTL(7) = 0): on the Stage II systems (5·10³–6·10⁴ unknowns) it halves the
    factorization time of MUMPS' automatic choice (METIS); Cholesky (LDLᵀ) was 2–4× slower.
    """

    what = "a local mixed CEM problem"
    lu_icntl = ((7, 0),)


def _unpack(space: LocalSpace, x: np.ndarray, n_loc: int, n_u: int) -> tuple[np.ndarray, np.ndarray]:
    """Cell-major DG stresses (|ω|, 30, k) and displacements (|ω|, 6, k) of patch solutions x."""
    k = x.shape[1]
    nc = space.cells.size
    sigma = space.apply(x[:n_loc])
    u = x[n_loc : n_loc + n_u].reshape(nc, 6, k)
    return sigma, u


def aw_map(space: LocalSpace, aw: np.ndarray) -> sp.csr_matrix:
    """(|aw| × dim X_h(ω)): AW coefficients (on the sorted DOFs ``aw``) of the local basis functions.

    Inner functions are AW functions (one coefficient 1); an inner-boundary vertex function with
    value z is Σ_i z_i (AW function 3v + i) restricted to ω.
    """
    rows = [np.searchsorted(aw, space.aw_inner)]
    cols = [np.arange(space.aw_inner.size)]
    vals = [np.ones(space.aw_inner.size)]
    if space.num_extra:
        ext = space.aw_inner.size + np.arange(space.num_extra)
        for i in range(3):
            rows.append(np.searchsorted(aw, 3 * space.extra_vertex + i))
            cols.append(ext)
            vals.append(space.extra_z[:, i])
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = vals != 0.0
    return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(aw.size, space.size))


# ---------------------------------------------------------------------------------------
# Stage II by static condensation onto the coarse skeleton
# ---------------------------------------------------------------------------------------
def _skeleton_entities(topo: _Topology, grid: CoarseGrid) -> tuple[np.ndarray, np.ndarray]:
    """Masks (vertices, edges) of Ω₁ touching two or more coarse cells: the coarse skeleton."""
    cc = np.repeat(_cell_coarse(grid), 3)
    out = []
    for conn, n in ((topo.c2v, topo.nv), (topo.c2e, topo.ne)):
        lo = np.full(n, np.iinfo(np.int64).max)
        hi = np.full(n, -1, dtype=np.int64)
        np.minimum.at(lo, conn.ravel(), cc)
        np.maximum.at(hi, conn.ravel(), cc)
        out.append(hi > lo)
    return out[0], out[1]


def _skeleton_aw(topo: _Topology, skeleton: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Mask over the AW DOFs of Ω₁: the DOFs of the skeleton vertices and edges."""
    out = np.zeros(3 * topo.nv + 4 * topo.ne + 3 * topo.nc, dtype=bool)
    out[: 3 * topo.nv] = np.repeat(skeleton[0], 3)
    out[3 * topo.nv : 3 * topo.nv + 4 * topo.ne] = np.repeat(skeleton[1], 4)
    return out


@dataclass(slots=True)
class _CellSystem:
    """The Stage II equations restricted to one coarse cell K, in the unknowns [I | Γ].

    I: the stress functions owned by K (support in K; AW coefficients on K: ``WI``), the displacements
    on K and the y of K's aux functions; Γ: the skeleton DOFs of K (AW vertex and edge DOFs shared with
    other coarse cells, AW functions restricted to K).  Every patch containing K contains these
    unknowns with these equations, so a patch system is the sum of its coarse cells' blocks (coupled on Γ).
    """

    skel: np.ndarray  #: sorted global AW DOFs of Γ_K
    WI: sp.csr_matrix  #: (|aw_K| × n_s) AW coefficients on K of the owned stress functions
    gpos: np.ndarray  #: position of each skeleton DOF in dofs.aw[K]
    n_s: int  #: owned stress functions
    n_u: int  #: displacement DOFs (6|K|)
    M_II: sp.csr_matrix
    M_IG: sp.csr_matrix
    M_GG: np.ndarray
    b: np.ndarray  #: (n_I + |Γ|, k) K's own right-hand sides: l_K basis columns, Robin data columns, load

    @property
    def n_I(self) -> int:
        return self.M_II.shape[0]


def _has_load(ops: CellOperators, cells: np.ndarray, source: bool) -> bool:
    """Whether a coarse cell gets a source corrector: f or the boundary data's stress-side load F act on it."""
    return source and bool(np.any(ops.G[cells] != 0.0) or (ops.F is not None and np.any(ops.F[cells] != 0.0)))


def _cell_system(
    ops: CellOperators, topo: _Topology, dofs: CoarseCellDofs, aux: StageI, skeleton: tuple, skel_aw: np.ndarray,
    K: int, source: bool,
) -> _CellSystem:
    """The coarse cell K's block of every Stage II patch system (``_CellSystem``), assembled from cell blocks."""
    cK, awK = dofs.cells[K], dofs.aw[K]
    nK = cK.size
    space = local_stress_space(ops, topo, cK, raw=skeleton)  # owned functions + raw skeleton functions
    is_skel = np.zeros(space.size, dtype=bool)
    is_skel[: space.aw_inner.size] = skel_aw[space.aw_inner]
    skel_cols, own_cols = np.flatnonzero(is_skel), np.flatnonzero(~is_skel)
    n_s, n_G = own_cols.size, skel_cols.size
    Zk = (ops.S[cK] @ aux.modes[K]).reshape(6 * nK, -1)
    lk = Zk.shape[1]
    n_I = n_s + 6 * nK + lk
    new = np.empty(space.size, dtype=np.int64)
    new[own_cols] = np.arange(n_s)
    new[skel_cols] = n_I + np.arange(n_G)
    (ar, ac, av), (br, bc, bv) = _local_triplets(ops, space)
    zr, zc = np.nonzero(Zk)
    zv = Zk[zr, zc]
    eye = n_s + 6 * nK + np.arange(lk)
    rows = np.concatenate([new[ar], n_s + br, new[bc], n_s + zr, n_s + 6 * nK + zc, eye])
    cols = np.concatenate([new[ac], new[bc], n_s + br, n_s + 6 * nK + zc, n_s + zr, eye])
    vals = np.concatenate([av, bv, bv, -zv, -zv, np.ones(lk)])
    M = sp.csr_matrix((vals, (rows, cols)), shape=(n_I + n_G, n_I + n_G))
    T = aw_map(space, awK)
    # K's own right-hand sides (those of the patch systems): −Z e_j; Robin data C_K g; the load on K
    Ci = ops.C[cell_rows(cK, 30)]
    gcols = np.unique(Ci.indices)
    load = _has_load(ops, cK, source)
    b = np.zeros((n_I + n_G, lk + gcols.size + int(load)))
    b[n_s : n_s + 6 * nK, :lk] = -Zk
    if gcols.size:
        b[new, lk : lk + gcols.size] = (T.T @ (dofs.P(ops, K).T @ Ci[:, gcols])).toarray()
    if load:
        b[n_s : n_s + 6 * nK, -1] = ops.G[cK].ravel()
        if ops.F is not None:  # (issue 14) the boundary data's stress-side load F|K in the τ rows
            b[new, -1] = T.T @ (dofs.P(ops, K).T @ ops.F[cK].ravel())
    skel = space.aw_inner[skel_cols]
    return _CellSystem(skel, T[:, own_cols].tocsr(), np.searchsorted(awK, skel), n_s, 6 * nK,
                       M[:n_I, :n_I], M[:n_I, n_I:], M[n_I:, n_I:].toarray(), b)


#: Bytes of coarse-cell LUs (and what goes with them) a rank keeps from the condensation for the back substitution;
#: beyond it a cell is assembled and factorized again.  By this count (``_CellElimination.nbytes``, 12 bytes per
#: factor entry) h = 1/128, H = 1/16 holds 0.79 GB in all (3–4 MB per cell: all kept; the benchmark's peak RSS
#: rose by 0.08 GB), h = 1/256 about 4× that (a third kept).
KEEP_FACTORS_BYTES = 1.0e9


class _CellElimination:
    """What the back substitution on a coarse cell K needs: the LU of M_II (kept from the condensation, or a new
    one), M_IΓ, the AW coefficients of the owned stress functions and M_II⁻¹ b_I (``own``; added after the solve
    with −M_IΓ x_Γ: with b_I put into that right-hand side instead, Algorithm 4 moved 1e-10 off the per-patch LUs)."""

    def __init__(self, system: _CellSystem, lu: LocalFactor, own: np.ndarray) -> None:
        self.skel, self.WI, self.gpos = system.skel, system.WI, system.gpos
        self.n_s, self.n_u, self.M_IG = system.n_s, system.n_u, system.M_IG
        self.lu, self.own = lu, own

    @classmethod
    def factorized(cls, system: _CellSystem) -> "_CellElimination":
        """A new LU of M_II (a cell whose condensation was not kept)."""
        lu = LocalFactor.from_csr(system.M_II)
        try:
            return cls(system, lu, lu.solve(system.b[: system.n_I]))
        except Exception:
            lu.destroy()
            raise

    @property
    def nbytes(self) -> int:
        """Memory held: the LU (``SparseFactor.nbytes``) and the arrays."""
        return int(self.lu.nbytes + self.own.nbytes + self.M_IG.data.nbytes * 2 + self.WI.data.nbytes * 2)

    def destroy(self) -> None:
        self.lu.destroy()


def _condense(system: _CellSystem) -> tuple[np.ndarray, np.ndarray, np.ndarray, _CellElimination]:
    """(skeleton DOFs, Schur complement S_K = M_ΓΓ − M_ΓI M_II⁻¹ M_IΓ, condensed own data b_Γ − M_ΓI M_II⁻¹ b_I,
    the data of the back substitution: M_II's LU is kept, not factorized again)."""
    n_I, n_G = system.n_I, system.skel.size
    lu = LocalFactor.from_csr(system.M_II)
    try:
        X = lu.solve(np.hstack([system.M_IG.toarray(), system.b[:n_I]]))
    except Exception:
        lu.destroy()
        raise
    S = system.M_GG - system.M_IG.T @ X[:, :n_G]
    S = 0.5 * (S + S.T)
    c = system.b[n_I:] - system.M_IG.T @ X[:, n_G:]
    return system.skel, S, c, _CellElimination(system, lu, np.ascontiguousarray(X[:, n_G:]))


def _skeleton_columns(topo: _Topology, skeleton: tuple, cells: np.ndarray, G: np.ndarray
                      ) -> tuple[sp.csr_matrix, np.ndarray]:
    """T_Γ (|G| × n): the functions of X_h(ω) (``local_stress_space`` of the fine cells ω) on the skeleton DOFs G
    of ω: the AW functions of the skeleton vertices and edges inside ω, the inner-boundary vertex functions
    (null-space values z) of the skeleton vertices on ∂ω or on a traction-free side; edges there are dropped.
    Also returns the inner DOFs (sorted global AW DOFs; column k < |inner| of T_Γ is the unit vector of inner[k])."""
    v_in = np.bincount(topo.c2v[cells].ravel(), minlength=topo.nv)
    e_in = np.bincount(topo.c2e[cells].ravel(), minlength=topo.ne)
    skel_v, skel_e = skeleton
    v_int = np.flatnonzero(skel_v & (v_in > 0) & (v_in == topo.v_deg) & ~topo.tf_vertex)
    v_bnd = np.flatnonzero(skel_v & (v_in > 0) & ((v_in < topo.v_deg) | topo.tf_vertex))
    e_int = np.flatnonzero(skel_e & (e_in > 0) & (e_in == topo.e_deg) & ~topo.tf_edge)
    e_bnd = np.flatnonzero(((e_in == 1) & (topo.e_deg == 2)) | ((e_in > 0) & topo.tf_edge))
    inner = np.concatenate([(3 * v_int[:, None] + np.arange(3)).ravel(),
                            (3 * topo.nv + 4 * e_int[:, None] + np.arange(4)).ravel()])
    null, extra, ncol = _boundary_vertex_null_spaces(topo, v_bnd, e_bnd, inner.size)
    kk, qq = np.nonzero(extra >= 0)
    rows = [np.searchsorted(G, inner)] + [np.searchsorted(G, 3 * v_bnd[kk] + i) for i in range(3)]
    cols = [np.arange(inner.size)] + [extra[kk, qq]] * 3
    vals = [np.ones(inner.size)] + [null[kk, i, qq] for i in range(3)]
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    keep = vals != 0.0
    return sp.csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(G.size, inner.size + ncol)), inner


def _skeleton_solve(
    ops: CellOperators, topo: _Topology, grid: CoarseGrid, dofs: CoarseCellDofs, skeleton: tuple, condensed: list,
    i: int, layers: int, glob: "_GlobalSkeleton",
) -> tuple[np.ndarray, np.ndarray]:
    """The patch K_{i,m} condensed onto its skeleton: (skeleton AW DOFs G, their values (|G|, k) for coarse
    cell i's right-hand sides).  On the skeleton the patch space X_h(K_{i,m}) is T_Γ: the AW functions of
    the skeleton vertices and edges inside the patch and the inner-boundary vertex functions on its boundary
    (``local_stress_space``; the patch-boundary edge DOFs are dropped)."""
    patch = np.sort(np.asarray(grid.patch(i, layers), dtype=np.int64))
    G = np.unique(np.concatenate([condensed[j][0] for j in patch]))
    c = condensed[i][2]
    rhs = np.zeros((G.size, c.shape[1]))
    rhs[np.searchsorted(G, condensed[i][0])] = c
    TG, inner = _skeleton_columns(topo, skeleton, np.concatenate([dofs.cells[j] for j in patch]), G)
    if TG.shape[1] == 0:
        return G, np.zeros_like(rhs)
    lu, own = glob.factors.factor(glob.patch_matrix(G, TG, inner, [condensed[j][:2] for j in patch]))
    try:
        xs = lu.solve(np.asarray(TG.T @ rhs))
    finally:
        if own:
            lu.destroy()
    return G, np.asarray(TG @ xs)


def _patch_classes(grid: CoarseGrid, patches: list, condensed: list) -> np.ndarray:
    """A label per patch: patches with one label are translates of each other with the same number of skeleton
    DOFs on every coarse cell, which on a Cartesian grid gives them one skeleton sparsity pattern (h = 1/128,
    H = 1/16, m = 3: 81 patterns among 240 patches; ``ReusedAnalysis`` checks the pattern itself, a label
    only orders the work).  All labels distinct on a general partition (no ``grid.ij``)."""
    if grid.ij is None:
        return np.arange(len(patches), dtype=np.int64)
    labels: dict = {}
    out = np.empty(len(patches), dtype=np.int64)
    for i, p in enumerate(patches):
        rel = grid.ij[p] - grid.ij[i]
        key = tuple(sorted(zip(rel[:, 0].tolist(), rel[:, 1].tolist(), [condensed[j][0].size for j in p])))
        out[i] = labels.setdefault(key, len(labels))
    return out


class _GlobalSkeleton:
    """Σ_K S_K over all coarse cells of Ω₁ (upper triangle, canonical CSR, on the sorted skeleton DOFs ``dofs``).

    A patch skeleton matrix T_Γᵀ (Σ_{K in the patch} S_K) T_Γ takes its inner block from here: an inner DOF of
    a patch lies on a skeleton vertex or edge all of whose coarse cells are in the patch, so every entry in an
    inner row has all its contributions from patch cells.  Only the columns of the patch-boundary vertex
    functions (null-space combinations, a few dozen) are summed from the patch's own cells.
    """

    def __init__(self, condensed: list) -> None:
        #: the patch skeleton factorizations, reusing MUMPS' analysis per pattern: a third of MUMPS' time on a
        #: 4.7·10³ skeleton at h = 1/128 (116 ms with the analysis, 75 ms without).  The patches of one class
        #: (``_patch_classes``: translates, e.g. all interior patches of a structured mesh) share one pattern and
        #: come one after the other (serially grouped by class; in the cost order of ``work.run_balanced``, where
        #: a class's patches have one cost and classes of equal cost are kept apart).
        self.factors = ReusedAnalysis(keep=2, factor_class=LocalFactor)
        self.dofs = np.unique(np.concatenate([c[0] for c in condensed]))
        n = self.dofs.size
        rows, cols, vals = [], [], []
        for skel, S, *_ in condensed:
            pos = np.searchsorted(self.dofs, skel)  # skel sorted: the local upper triangle is the global one
            iu, ju = np.triu_indices(pos.size)
            rows.append(pos[iu])
            cols.append(pos[ju])
            vals.append(S[iu, ju])
        self.upper = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))
        self.upper.sum_duplicates()

    def patch_matrix(self, G: np.ndarray, TG: sp.csr_matrix, inner: np.ndarray, blocks: list) -> sp.csr_matrix:
        """Upper triangle (canonical CSR) of T_Γᵀ (Σ_K S_K) T_Γ for a patch with skeleton DOFs G, T_Γ and inner
        DOFs from ``_skeleton_columns`` and its cells' ``blocks`` = [(skeleton DOFs of K, S_K)]."""
        pos = np.searchsorted(self.dofs, inner)
        A = self.upper[pos][:, pos]  # the inner block (pos increasing: still upper triangular)
        A.sum_duplicates()  # canonical for PETSc (SciPy checks first: no sort when already sorted)
        n_I, n_B = inner.size, TG.shape[1] - inner.size
        if n_B == 0:
            return A
        NB = TG[:, n_I:].tocsr()  # the boundary vertex functions on G (a few hundred columns, ≤ 3 rows each)
        on_b = np.diff(NB.indptr) > 0
        rows_x, cols_x, vals_x = [], [], []
        for skel, S in blocks:  # (Σ_K S_K) N_B, from the cells touching the patch boundary
            rows = np.searchsorted(G, skel)
            b = on_b[rows]
            if b.any():
                Nk = NB[rows[b]]
                cols = np.unique(Nk.indices)
                Nk = sp.csr_matrix((Nk.data, np.searchsorted(cols, Nk.indices), Nk.indptr), shape=(Nk.shape[0], cols.size))
                rows_x.append(np.repeat(rows, cols.size))
                cols_x.append(np.tile(cols, rows.size))
                vals_x.append(np.asarray(Nk.T @ S[b]).T.ravel())  # S[:, b] N_k (S symmetric)
        X = sp.csr_matrix((np.concatenate(vals_x), (np.concatenate(rows_x), np.concatenate(cols_x))),
                          shape=(G.size, n_B))
        BB = (NB.T @ X).toarray()
        A = sp.bmat([[A, X[np.searchsorted(G, inner)]], [None, sp.csr_matrix(np.triu(0.5 * (BB + BB.T)))]], format="csr")
        A.sum_duplicates()  # sorts the indices too: canonical for PETSc
        return A


def _cell_values(elim: _CellElimination, K: int, reach: list, values: list) -> dict:
    """Back substitution on coarse cell K for every patch i reaching it: {i: (AW coefficients on K (|aw_K|, k_i),
    displacements (6|K|, k_i))}, x_I = M_II⁻¹(b_I δ_{iK} − M_IΓ x_Γ) with K's kept LU."""
    xg = [values[i][1][np.searchsorted(values[i][0], elim.skel)] for i in reach]
    widths = np.array([x.shape[1] for x in xg])
    XG = np.hstack(xg)
    rhs = -np.asarray(elim.M_IG @ XG)
    start = np.concatenate([[0], np.cumsum(widths)])
    XI = elim.lu.solve(rhs)
    if K in reach:  # K's own right-hand sides
        q = reach.index(K)
        XI[:, start[q] : start[q + 1]] += elim.own
    A = np.asarray(elim.WI @ XI[: elim.n_s])  # AW coefficients on K, all patches in one product
    A[elim.gpos] += XG
    U = XI[elim.n_s : elim.n_s + elim.n_u]
    cols = [slice(start[q], start[q + 1]) for q in range(len(reach))]  # contiguous pieces: sent out of band by MPI
    return {int(i): (np.ascontiguousarray(A[:, c]), np.ascontiguousarray(U[:, c])) for i, c in zip(reach, cols)}


def _columns(x: np.ndarray | None, cols: slice) -> np.ndarray | None:
    """A contiguous copy of the columns ``cols`` of a patch-function piece (None: held by another rank)."""
    return None if x is None else np.ascontiguousarray(x[:, cols])


def _stage_two_condensed(
    ops: CellOperators, topo: _Topology, grid: CoarseGrid, dofs: CoarseCellDofs, aux: StageI, layers: int,
    source: bool, comm: MPI.Comm, distributed: bool = False,
) -> tuple[list[PatchFunctions], list[PatchFunctions]]:
    """Stage II by static condensation (a substructuring of every patch along the coarse skeleton).

    A patch system is the sum of its coarse cells' blocks (``_cell_system``), coupled only through the
    skeleton DOFs.  1. Each coarse cell's owned unknowns are eliminated once (Schur complement S_K on its
    skeleton, and its own right-hand sides condensed); 2. each patch factorizes only its skeleton system
    Σ_K T_Γᵀ S_K T_Γ (a few thousand unknowns instead of 10⁵ at h = 1/128); 3. the owned unknowns are
    recovered coarse cell by coarse cell, for all patches reaching it in one multi-right-hand-side solve.
    Exact (the same linear systems as one LU per patch, up to rounding).
    """
    skeleton = _skeleton_entities(topo, grid)
    skel_aw = _skeleton_aw(topo, skeleton)
    size = _cell_cost(dofs)
    patches = [np.sort(np.asarray(grid.patch(i, layers), dtype=np.int64)) for i in range(grid.size)]
    kept: dict[int, _CellElimination] = {}  # this rank's coarse cells: condensed here, recovered here (cell_owner)
    held = 0  # bytes in ``kept``

    def condense(K: int) -> tuple:
        nonlocal held
        skel, S, c, elim = _condense(_cell_system(ops, topo, dofs, aux, skeleton, skel_aw, K, source))
        nbytes = elim.nbytes
        if held + nbytes <= KEEP_FACTORS_BYTES:
            kept[K] = elim
            held += nbytes
        else:
            elim.destroy()
        return skel, S, c

    def recover(K: int) -> dict:
        elim = kept.pop(K, None)
        if elim is None:  # not kept (KEEP_FACTORS_BYTES): assembled and factorized again
            elim = _CellElimination.factorized(_cell_system(ops, topo, dofs, aux, skeleton, skel_aw, K, source))
        try:
            return _cell_values(elim, K, reach[K], values)
        finally:
            elim.destroy()

    try:
        cell_owner = np.empty(grid.size, dtype=np.int64)  # who condensed K keeps its LU: it back-substitutes K
        condensed = _run_shared(size, comm, "mixed CEM Stage II (coarse cells)", condense, balanced=True,
                                owner=cell_owner)
        cost = np.array([sum(condensed[j][0].size for j in p) for p in patches], dtype=float)
        # patches of one class one after the other (MUMPS' analysis reused: ``ReusedAnalysis``); a class's
        # patches have one cost, so a relative 1e-9 per class label groups them in the cost order of MPI too
        label = _patch_classes(grid, patches, condensed)
        glob = _GlobalSkeleton(condensed)
        try:
            values = _run_shared(cost ** 1.5 * (1.0 + 1e-9 * label / max(len(patches), 1)), comm,
                                 "mixed CEM Stage II (patch skeletons)",
                                 lambda i: _skeleton_solve(ops, topo, grid, dofs, skeleton, condensed, i, layers,
                                                           glob),
                                 balanced=True, items=np.lexsort((np.arange(label.size), label))
                                 if comm.size == 1 else None)
        finally:
            glob.factors.release()
        del glob, condensed
        reach = [[] for _ in range(grid.size)]
        for i, p in enumerate(patches):
            for K in p:
                reach[int(K)].append(i)
        parts = _run_shared(size, comm, "mixed CEM Stage II (back substitution)", recover, gather=not distributed,
                            items=np.flatnonzero(cell_owner == comm.rank))
        if distributed and comm.size > 1:  # pieces for the coarse cells this rank recovered (``held_cells``) only
            parts = [parts.get(K) for K in range(grid.size)]
    finally:
        for elim in kept.values():  # left over only after a failure
            elim.destroy()
    del values
    n_g = ops.num_gamma_values
    basis, corr = [], []
    for i, p in enumerate(patches):
        li = aux.modes[i].shape[2]
        pieces = [(None, None) if parts[int(K)] is None else parts[int(K)].pop(i) for K in p]
        held_here = next((a for a, _ in pieces if a is not None), None)  # (distributed: some pieces are elsewhere)
        width = None if held_here is None else held_here.shape[1]
        first, rest = slice(0, li), slice(li, None)
        basis.append(PatchFunctions(p, aux.offsets[i] + np.arange(li), [_columns(a, first) for a, _ in pieces],
                                    [_columns(u, first) for _, u in pieces]))
        cK = dofs.cells[i]
        gcols = np.unique(ops.C[cell_rows(cK, 30)].indices)
        load = _has_load(ops, cK, source)
        n_corr = gcols.size + int(load)
        if width is not None and width != li + n_corr:
            raise RuntimeError(f"patch {i}: {width} back-substituted columns, expected {li} + {n_corr}")
        if n_corr == 0:
            corr.append(None)
            continue
        corr.append(PatchFunctions(p, np.concatenate([gcols, [n_g]]) if load else gcols,
                                   [_columns(a, rest) for a, _ in pieces], [_columns(u, rest) for _, u in pieces]))
    return basis, corr


def stage_two(
    ops: CellOperators, topo: _Topology, grid: CoarseGrid, aux: StageI, layers: int, source: bool = True,
    *, dofs: CoarseCellDofs | None = None, comm: MPI.Comm = MPI.COMM_SELF, distributed: bool = False,
) -> tuple[list[PatchFunctions], list[PatchFunctions]]:
    """Basis functions ψ_j^i (index = aux index) and data correctors (index = data index), per coarse cell.

    The data are d = [g; 1]: the γ values g (index 0..n_g−1; Robin correctors Q_i, N_i on the
    patches of the coarse cells touching γ) and, with ``source``, the load (index n_g; the source
    correctors of the coarse cells where f ≠ 0).  ``corr[i]`` is None for a cell with neither.
    Under ``comm`` the patches are shared out (``work.run_shared``) and every rank gets all results; with
    ``distributed`` each rank keeps only the pieces on its ``held_cells`` (no gather of the functions).
    """
    dofs = dofs or CoarseCellDofs.of(ops, grid)
    return _stage_two_condensed(ops, topo, grid, dofs, aux, layers, source, comm, distributed)


def _cell_cost(dofs: CoarseCellDofs) -> np.ndarray:
    """The estimated cost of a coarse cell's condensation and back substitution: |K|^1.5."""
    return np.array([len(c) for c in dofs.cells], dtype=float) ** 1.5


def held_cells(basis: list[PatchFunctions]) -> np.ndarray:
    """The coarse cells K whose pieces this rank holds (all, unless ``stage_two(distributed=True)`` under MPI):
    those where the basis of K's own patch has its piece on K."""
    return np.array([i for i, f in enumerate(basis) if f.sigma[int(np.searchsorted(f.coarse, i))] is not None],
                    dtype=np.int64)


def _run_shared(cost: np.ndarray, comm: MPI.Comm, desc: str, work, **kwargs) -> list | dict:
    """``work.run_shared`` with this module's logger for the progress lines."""
    return run_shared(cost, comm, desc, work, logger=log, **kwargs)


def _scale_to_cell_sizes(ops: CellOperators, grid: CoarseGrid, H: float) -> None:
    """κ̃ = c κ H_k⁻² with the size H_k of each coarse cell when the grid gives one (``cell_size``: √|K_k|,
    a user partition); a Cartesian grid has H_k = H and nothing changes."""
    sizes = getattr(grid, "cell_size", None)
    if sizes is None:
        return
    for k, Hk in enumerate(np.asarray(sizes, dtype=float)):
        factor = (H / Hk) ** 2
        if abs(factor - 1.0) > 1e-10:
            ops.S[np.asarray(grid.cells[k], dtype=np.int64)] *= factor


def stage_one_of(
    sub, grid: CoarseGrid, options: MixedCEMOptions, *, H: float, traction_free_facets: np.ndarray | None = None,
) -> tuple[CellOperators, "_Topology", StageI]:
    """Stage I alone for an Ω₁ ``MixedSubproblem``: (cell operators, local-space topology, U_aux)."""
    ops = cell_operators(sub, H, options.weight, options.s_factor)
    _scale_to_cell_sizes(ops, grid, H)
    topo = _Topology(sub.mesh, ops.num_aw, traction_free_facets)
    return ops, topo, stage_one(ops, topo, grid, options.nbasis, options.min_gap, options.max_nbasis,
                                options.eigensolver)


def _cell_coarse(grid: CoarseGrid) -> np.ndarray:
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


def basis_decay_profile(ops: CellOperators, topo: _Topology, grid: CoarseGrid, aux: StageI, k: int) -> np.ndarray:
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
    dist = _coarse_distance(grid, k)[_cell_coarse(grid)[space.cells]]
    total = energy.sum(axis=0)
    return np.array([np.sqrt(energy[dist >= d].sum(axis=0) / total).max() for d in range(1, int(dist.max()) + 1)])


# ---------------------------------------------------------------------------------------
# coarse operators
# ---------------------------------------------------------------------------------------
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
        fphi = None if self.Fphi is None and other.Fphi is None else (
            (0.0 if self.Fphi is None else self.Fphi) + (0.0 if other.Fphi is None else other.Fphi))
        return CoarseOperators(self.n_ms, self.n_aux, self.n_g, *(getattr(self, n) + getattr(other, n) for n in names),
                               fphi)


def _merge_columns(X: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum the columns of the matrix X with equal index: (sorted unique indices, merged X)."""
    uniq, inv = np.unique(idx, return_inverse=True)
    if uniq.size == idx.size:
        return uniq, X[:, np.argsort(inv)] if np.any(np.diff(idx) < 0) else X
    sel = sp.csr_matrix((np.ones(idx.size), (np.arange(idx.size), inv)), shape=(idx.size, uniq.size))
    return uniq, np.asarray((sel.T @ X.T).T)


def _gram(A: np.ndarray, F: np.ndarray) -> np.ndarray:
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


def _reaching(funcs: list, n: int) -> list:
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
    ops: CellOperators, grid: CoarseGrid, aux: StageI, basis: list, corr: list, *,
    dofs: CoarseCellDofs | None = None, comm: MPI.Comm = MPI.COMM_SELF, cells: np.ndarray | None = None,
) -> CoarseOperators:
    """Accumulate the coarse matrices coarse cell by coarse cell from the patch functions reaching it.

    On K the stresses are P_K F (F: their AW coefficients on K), so ΦᵀÃΦ|_K = Fᵀ (P_Kᵀ Ã_K P_K) F etc., formed fine
    cell by fine cell (Σ_c F_cᵀ (P_cᵀ Ã_c P_c) F_c: batched 24 × 24 blocks, their Cholesky factors and one symmetric
    BLAS product, ``_gram``; at h = 1/128 the sparse products with P_K took 30 % longer, the general product 15 %).
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
    reach_b, reach_c = _reaching(basis, grid.size), _reaching(corr, grid.size)

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
        Gt[ix] += _gram(PBt @ (ops.kt(cK) @ PB), Fc)
        Gk[ix] += _gram(PBt @ (ops.K[cK] @ PB), Fc)
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
            gu, Nu = _merge_columns(np.concatenate([q.u[p] for q, p in reach_c[K]], axis=1),
                                    np.concatenate([q.index for q, _ in reach_c[K]]))
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
    _run_shared(cost ** 2, comm, "mixed CEM coarse operators", accumulate, gather=False, items=cells)
    co = CoarseOperators(n_ms, aux.size, n_g, Gt, Gk, Bm, BN, Cphi, Ephi, Mu, PiG, Fphi)
    if comm.size > 1:
        for name in _COARSE_ARRAYS:
            arr = getattr(co, name)
            comm.Allreduce(MPI.IN_PLACE, arr, op=MPI.SUM)
    for name in _SYMMETRIC:  # Gram matrices: exactly symmetric (the cache stores one triangle)
        X = getattr(co, name)
        X += X.T
        X *= 0.5
    return co


# ---------------------------------------------------------------------------------------
# offline cache
# ---------------------------------------------------------------------------------------
class OfflineData(NamedTuple):
    """What the online phase and the output need: U_aux, the patch functions and the coarse matrices."""

    aux: StageI
    basis: list  #: PatchFunctions ψ_j^i per coarse cell i
    corr: list  #: PatchFunctions of the data correctors per coarse cell (None: no γ facet, no load)
    co: CoarseOperators


_COARSE_ARRAYS = ("Gt", "Gk", "Bm", "BN", "Cphi", "Ephi", "Mu", "PiG", "Fphi")
_SYMMETRIC = ("Gt", "Gk", "Mu")  #: stored as their upper triangle
#: Stored precision of the patch functions (AW coefficients, displacements) in the cache: they serve
#: only the fine output fields (relative rounding 6e-8); U_aux and the coarse matrices are float64.
_FUNCTION_DTYPE = np.float32


def mixed_offline_key(
    sub, ops: CellOperators, grid: CoarseGrid, options: MixedCEMOptions, *, H: float,
    traction_free: np.ndarray | None = None,
) -> str:
    """sha256 of everything the mixed offline data depend on.

    Mesh geometry and cells of Ω₁, facet tags, λ, μ, f, β, H, the coarse cells and their patches,
    every ``MixedCEMOptions`` field, the cache format and the package version, and (catching
    what these miss, e.g. a changed form) the cell operators assembled from them.
    """
    hasher = hashlib.sha256()
    meta = {
        "format": MIXED_CACHE_FORMAT,
        "version": __version__,
        "H": repr(float(H)),
        "beta": repr(float(sub.beta)),
        "num_coarse": int(grid.size),
        "options": {name: getattr(options, name) for name in sorted(f.name for f in fields(options))},
    }
    hasher.update(json.dumps(meta, sort_keys=True).encode())
    msh, ft, fld = sub.mesh, sub.facet_tags, sub.fields
    patches = [np.sort(np.asarray(grid.patch(k, options.layers), dtype=np.int64)) for k in range(grid.size)]
    arrays = {
        "x": msh.geometry.x,
        "cells": msh.geometry.dofmaps[0],
        "facet_indices": ft.indices,
        "facet_values": ft.values,
        "lambda": fld.lmbda.x.array,
        "mu": fld.mu.x.array,
        "f": fld.f.x.array,
        "gamma_points": sub.gamma_points,
        "coarse_cells": np.concatenate([np.sort(np.asarray(c, dtype=np.int64)) for c in grid.cells]),
        "coarse_sizes": np.array([len(c) for c in grid.cells], dtype=np.int64),
        "patches": np.concatenate(patches),
        "patch_sizes": np.array([p.size for p in patches], dtype=np.int64),
        "traction_free_edges": np.flatnonzero(traction_free) if traction_free is not None else np.zeros(0, np.int64),
    }
    for name in ("K", "R", "B", "M", "S", "G", "dg_rows", "u_rows", "gamma_cells", "P_cols", "P_blocks"):
        arrays[f"ops_{name}"] = getattr(ops, name)
    for name in ("F", "s0"):  # (issue 14) boundary data: tractions (lifting) and u_D
        if getattr(ops, name) is not None:
            arrays[f"ops_{name}"] = getattr(ops, name)
    for name in ("C", "E"):
        X = sp.csr_matrix(getattr(ops, name))
        arrays[f"ops_{name}_data"], arrays[f"ops_{name}_indices"] = X.data, X.indices
        arrays[f"ops_{name}_indptr"], arrays[f"ops_{name}_shape"] = X.indptr, np.array(X.shape)
    for name in sorted(arrays):
        hasher.update(name.encode())
        hash_array(hasher, arrays[name])
    return hasher.hexdigest()


def _concat(parts: list, dtype) -> np.ndarray:
    return np.concatenate([np.asarray(p, dtype=dtype).ravel() for p in parts]) if parts else np.zeros(0, dtype)


def _pack_offline(data: OfflineData):
    """(name, array) pairs in sorted name order, one patch at a time (no second copy of the functions)."""
    aux, co = data.aux, data.co
    yield "aux_gaps", np.asarray(aux.gaps, dtype=np.float64)
    yield "aux_modes", _concat(aux.modes, np.float64)
    yield "aux_offsets", np.asarray(aux.offsets, dtype=np.int64)
    yield "aux_residuals", np.asarray(aux.residuals, dtype=np.float64)
    yield "aux_values", _concat(aux.values, np.float64)
    for name in sorted(_COARSE_ARRAYS):
        X = getattr(co, name)
        yield f"co_{name}", X[np.triu_indices(X.shape[0])] if name in _SYMMETRIC else X
    yield "co_sizes", np.array([co.n_ms, co.n_aux, co.n_g], dtype=np.int64)
    for kind, funcs in (("b", data.basis), ("c", data.corr)):
        for i, f in enumerate(funcs):
            if f is None:
                continue
            yield f"fn_{kind}_{i:07d}_coarse", np.asarray(f.coarse, dtype=np.int64)
            yield f"fn_{kind}_{i:07d}_index", np.asarray(f.index, dtype=np.int64)
            yield f"fn_{kind}_{i:07d}_sigma", _concat(f.sigma, _FUNCTION_DTYPE)
            yield f"fn_{kind}_{i:07d}_u", _concat(f.u, _FUNCTION_DTYPE)


def _split(flat: np.ndarray, sizes: np.ndarray, what: str) -> list:
    if int(np.sum(sizes)) != flat.size:
        raise ValueError(f"cached {what} have {flat.size} entries, expected {int(np.sum(sizes))}")
    return np.split(flat, np.cumsum(sizes)[:-1]) if sizes.size else []


def _unpack_functions(arrays: dict, prefix: str, dofs: CoarseCellDofs, n_index: int) -> PatchFunctions:
    coarse, index = arrays.pop(f"{prefix}_coarse"), arrays.pop(f"{prefix}_index")
    if coarse.size == 0 or coarse.min() < 0 or coarse.max() >= len(dofs.cells) or np.any(np.diff(coarse) <= 0):
        raise ValueError(f"cached {prefix}: invalid coarse cells")
    if index.size == 0 or index.min() < 0 or index.max() >= n_index:
        raise ValueError(f"cached {prefix}: invalid function indices")
    k = index.size
    na = np.array([dofs.aw[K].size for K in coarse])
    nu = np.array([6 * dofs.cells[K].size for K in coarse])
    sig = _split(arrays.pop(f"{prefix}_sigma"), na * k, f"{prefix} stresses")
    dis = _split(arrays.pop(f"{prefix}_u"), nu * k, f"{prefix} displacements")
    return PatchFunctions(coarse, index, [s.astype(np.float64).reshape(-1, k) for s in sig],
                          [d.astype(np.float64).reshape(-1, k) for d in dis])


def _unpack_offline(arrays: dict, ops: CellOperators, grid: CoarseGrid) -> OfflineData:
    offsets = arrays["aux_offsets"]
    if offsets.shape != (grid.size + 1,) or offsets[0] != 0 or np.any(np.diff(offsets) < 0):
        raise ValueError("cached U_aux does not match the coarse grid")
    nk = np.diff(offsets)
    ncell = np.array([len(c) for c in grid.cells], dtype=np.int64)
    values = _split(arrays["aux_values"], nk, "eigenvalues")
    modes = [m.reshape(nc, 6, k) for m, nc, k in zip(_split(arrays["aux_modes"], 6 * ncell * nk, "modes"), ncell, nk)]
    aux = StageI(values, modes, offsets, arrays["aux_residuals"], arrays["aux_gaps"])
    n_ms, n_aux, n_g = (int(s) for s in arrays["co_sizes"])
    if n_ms != aux.size or n_aux != aux.size or n_g != ops.num_gamma_values:
        raise ValueError("cached coarse operators do not match U_aux or the interface")
    dofs = CoarseCellDofs.of(ops, grid)
    basis = [_unpack_functions(arrays, f"fn_b_{i:07d}", dofs, n_ms) for i in range(grid.size)]
    corr = [_unpack_functions(arrays, f"fn_c_{i:07d}", dofs, n_g + 1) if f"fn_c_{i:07d}_index" in arrays else None
            for i in range(grid.size)]
    n_d = n_g + 1
    n = n_ms + n_d
    mats = {name: arrays[f"co_{name}"] for name in _COARSE_ARRAYS}
    for name, size in (("Gt", n), ("Gk", n), ("Mu", n_aux + n_d)):
        tri = mats[name]
        if tri.shape != (size * (size + 1) // 2,):
            raise ValueError(f"cached coarse matrix {name} has {tri.size} entries, expected a triangle of {size}")
        X = np.zeros((size, size))
        X[np.triu_indices(size)] = tri
        mats[name] = X + np.triu(X, 1).T
    shapes = {"Gt": (n, n), "Gk": (n, n), "Bm": (n_aux, n), "BN": (n, n_d), "Cphi": (n, n_g), "Ephi": (n_g, n),
              "Mu": (n_aux + n_d, n_aux + n_d), "PiG": (n_aux,), "Fphi": (n,)}
    for name, shape in shapes.items():
        if mats[name].shape != shape:
            raise ValueError(f"cached coarse matrix {name} has shape {mats[name].shape}, expected {shape}")
    return OfflineData(aux, basis, corr, CoarseOperators(n_ms, n_aux, n_g, **mats))


class MixedOfflineCache(OfflineCache):
    """npz files ``mixed_cem_<key>.npz``: ``cache.OfflineCache`` holding ``OfflineData``, written patch by patch."""

    prefix = "mixed_cem"

    @staticmethod
    def pack(obj: OfflineData):
        return _pack_offline(obj)

    @staticmethod
    def unpack(arrays: dict[str, np.ndarray], *context) -> OfflineData:
        return _unpack_offline(arrays, *context)


# ---------------------------------------------------------------------------------------
# the Ω₁ multiscale solver
# ---------------------------------------------------------------------------------------
@dataclass(slots=True)
class InterfaceResponse:
    """The Ω₁ multiscale solution as an affine map of the Robin data g (n_g values on γ).

    The coarse problem is linear, so r = R g + r₀, w = W g + w₀ (n_g coarse solves, offline),
    and everything the iteration needs is a small matrix in g: the trace σ₁n₁ = T g + t₀ and
    the quadratic forms ‖σ₁‖²_A, ‖u₁‖²_L² (for the stopping rule).  Online, the Ω₁ step of
    Algorithm 4 then costs O(n_g²) instead of a coarse solve of size dim X_ms + dim U_aux.
    """

    R: np.ndarray  #: (n_ms, n_g)
    r0: np.ndarray
    W: np.ndarray  #: (n_aux, n_g)
    w0: np.ndarray
    T: np.ndarray  #: (n_g, n_g) trace map
    t0: np.ndarray
    KA: np.ndarray  #: (n_g, n_g): ‖σ₁(g) − σ₁(g')‖²_A = (g − g')ᵀ KA (g − g')
    kA: np.ndarray  #: ‖σ₁(g)‖²_A = gᵀKA g + 2 kAᵀg + cA
    cA: float
    KM: np.ndarray  #: the same for ‖u₁‖²_L²
    kM: np.ndarray
    cM: float

    @classmethod
    def of(cls, om: "MixedMultiscaleOmega1") -> "InterfaceResponse":
        co = om.co
        n, n_g = co.n_ms, co.n_g
        X = sla.lu_solve(om._lu, np.vstack([om._F1[:, :n_g], -om._F2[:, :n_g]]))  # a column per γ value
        x0 = sla.lu_solve(om._lu, np.concatenate([om._F1[:, n_g], co.PiG - om._F2[:, n_g]]))  # g = 0
        R, W, r0, w0 = X[:n], X[n:], x0[:n], x0[n:]
        lift_d = np.vstack([np.eye(n_g), np.zeros((1, n_g))])  # g ↦ d − e_load
        e_load = np.zeros(n_g + 1)
        e_load[n_g] = 1.0
        forms = []
        for lift, shift, gram in ((R, r0, co.Gk), (W, w0, co.Mu)):
            L = np.vstack([lift, lift_d])
            s0 = np.concatenate([shift, e_load])
            GL, Gs = gram @ L, gram @ s0
            forms += [0.5 * (L.T @ GL + (L.T @ GL).T), L.T @ Gs, float(s0 @ Gs)]
        T = om._E_r @ R + om._E_g[:, :n_g]
        return cls(R, r0, W, w0, T, om._E_r @ r0 + om._E_g[:, n_g], *forms)

    def trace(self, g: np.ndarray) -> np.ndarray:
        """σ₁n₁ at the γ nodes for data g."""
        return self.T @ g + self.t0

    def stress_norm2(self, g: np.ndarray) -> float:
        """‖σ₁(g)‖²_A."""
        return float(g @ self.KA @ g + 2.0 * self.kA @ g + self.cA)

    def stress_change2(self, g: np.ndarray, g_old: np.ndarray) -> float:
        """‖σ₁(g) − σ₁(g_old)‖²_A."""
        d = g - g_old
        return float(d @ self.KA @ d)

    def l2_norm2(self, g: np.ndarray) -> float:
        """‖u₁(g)‖²_L²."""
        return float(g @ self.KM @ g + 2.0 * self.kM @ g + self.cM)

    def l2_change2(self, g: np.ndarray, g_old: np.ndarray) -> float:
        """‖u₁(g) − u₁(g_old)‖²_L²."""
        d = g - g_old
        return float(d @ self.KM @ d)


class MixedMultiscaleOmega1:
    """Ω₁ of Algorithm 4: offline stages on an Ω₁ ``MixedSubproblem`` and the online coarse solve.

    ``solve(g)`` returns the coarse state (r, w) for Robin data g (values at the γ
    nodes); σ₁ = Ψ r + Q g and u₁ = Π w + N g are never formed online: norms and
    traces use the dense coarse operators (``stress_state``, ``trace``, ...).

    With ``cache_dir`` the offline data (U_aux, the patch functions, the coarse
    matrices) are read from / written to ``cache_dir/mixed_cem_<key>.npz``
    (``mixed_offline_key``); ``cache_status`` is 'disabled', 'loaded', 'built' (no file yet) or
    'rebuilt (invalid: <why>)', as for the primal CEM.  A valid file is used even in a read-only directory;
    when the data must be built and the directory cannot be written, an InputError
    is raised before the (expensive) build.  A failure of the final write itself
    only logs a warning: the built data are kept.
    """

    def __init__(
        self, sub, grid: CoarseGrid, options: MixedCEMOptions, *, H: float, cache_dir: str | Path | None = None,
        comm: MPI.Comm = MPI.COMM_SELF, traction_free_facets: np.ndarray | None = None,
    ) -> None:
        require_serial(sub.mesh.comm)
        self.options = options
        self.grid = grid
        self.comm = comm
        self.times: dict[str, float] = {}  #: wall seconds of the offline parts
        self.cpu_times: dict[str, float] = {}  #: CPU seconds of this process in the same parts
        t, c = time.perf_counter(), time.process_time()
        self.ops = cell_operators(sub, H, options.weight, options.s_factor)
        _scale_to_cell_sizes(self.ops, grid, H)
        self.topo = _Topology(sub.mesh, self.ops.num_aw, traction_free_facets)
        self.times["assembly"] = time.perf_counter() - t
        self.cpu_times["assembly"] = time.process_time() - c
        self.cache_status = "disabled"
        self.cache_path: Path | None = None
        #: the coarse cells whose patch-function pieces this rank holds (None: all).  Under MPI without a cache
        #: the pieces are not gathered: the coarse operators and the fine fields are formed where they lie.
        self._held: np.ndarray | None = None
        data = None
        if cache_dir is not None:
            t, c = time.perf_counter(), time.process_time()
            cache = MixedOfflineCache(cache_dir)
            key = mixed_offline_key(sub, self.ops, grid, options, H=H, traction_free=self.topo.tf_edge)
            self.cache_path = cache.path(key)
            data, self.cache_status = cache.load(key, self.ops, grid)
            statuses = comm.allgather(self.cache_status)  # every rank builds, or none
            if any(st != "loaded" for st in statuses) and data is not None:
                data, self.cache_status = None, next(st for st in statuses if st != "loaded")
            if data is not None:
                self._setup_online(data)
                self.times["load"] = time.perf_counter() - t
                self.cpu_times["load"] = time.process_time() - c
                log.info("mixed CEM offline data loaded from %s", self.cache_path)
            else:
                if self.cache_status != "missing":
                    log.warning(
                        "mixed CEM offline cache %s rejected (%s); rebuilding", self.cache_path, self.cache_status
                    )
                problem = None
                if comm.rank == 0:
                    try:
                        cache.check_writable()
                    except InputError as err:
                        problem = str(err)
                problem = comm.bcast(problem, root=0)
                if problem is not None:
                    raise InputError(problem)
                self.cache_status = "built" if self.cache_status == "missing" else f"rebuilt ({self.cache_status})"
        if data is None:
            t, c = time.perf_counter(), time.process_time()
            aux = stage_one(self.ops, self.topo, grid, options.nbasis, options.min_gap, options.max_nbasis,
                            options.eigensolver, comm=comm)
            self.times["eigen"] = time.perf_counter() - t
            self.cpu_times["eigen"] = time.process_time() - c
            t, c = time.perf_counter(), time.process_time()
            self.dofs = CoarseCellDofs.of(self.ops, grid)
            distributed = comm.size > 1 and cache_dir is None  # (the cache file needs every function on rank 0)
            basis, corr = stage_two(self.ops, self.topo, grid, aux, options.layers, options.source_correction,
                                    dofs=self.dofs, comm=comm, distributed=distributed)
            if distributed and comm.allreduce(any(a is None for f in basis for a in f.sigma), op=MPI.LOR):
                self._held = held_cells(basis)
            self.times["basis"] = time.perf_counter() - t
            self.cpu_times["basis"] = time.process_time() - c
            t, c = time.perf_counter(), time.process_time()
            data = OfflineData(aux, basis, corr, coarse_operators(self.ops, grid, aux, basis, corr, dofs=self.dofs,
                                                                  comm=comm, cells=self._held))
            self._setup_online(data)
            self.times["coarse"] = time.perf_counter() - t
            self.cpu_times["coarse"] = time.process_time() - c
            if cache_dir is not None:
                t, c = time.perf_counter(), time.process_time()
                if comm.rank == 0:
                    try:
                        cache.save(key, data)
                        log.info("mixed CEM offline data written to %s", self.cache_path)
                    except OSError as err:
                        log.warning("could not write the mixed CEM offline cache %s (%s)", self.cache_path, err)
                comm.Barrier()
                self.times["save"] = time.perf_counter() - t
                self.cpu_times["save"] = time.process_time() - c
        co = self.co
        lo, hi = self.nbasis_range
        log.info(
            "mixed CEM Ω₁ (m=%d, l=%d..%d per cell): dim X_ms %d, dim U_aux %d, max Stage I residual %.1e, Λ %.2e, "
            "cache %s, times %s", options.layers, lo, hi, co.n_ms, co.n_aux, float(self.aux.residuals.max()),
            self.spectral_gap, self.cache_status, {k: round(v, 2) for k, v in self.times.items()},
        )
        if not options.source_correction and self.ops.F is not None:
            log.warning(
                "mixed CEM without source correctors: the Ω₁ boundary data (a prescribed displacement on Gamma_D or "
                "the traction lifting) act on the stresses, which X_ms sees only through Ψᵀ F, an error no number of "
                "layers removes (e_σ = 0.13 with all modes and patches covering Ω₁, h = 1/16, H = 1/4); keep "
                "source_correction=True (the default)"
            )
        if options.min_gap is not None and self.spectral_gap < options.min_gap:
            log.warning(
                "mixed CEM: the Stage I target Λ ≥ %g was not reached with at most max_nbasis = %d modes per cell "
                "(Λ = %.2e, ν → ½ in Ω₁): the basis functions may decay more slowly with the oversampling layers "
                "(for ν = 0.4999, h = 1/64, H = 1/16, 32 modes still gave the decay of ν = 0.3). Check the error "
                "with one layer more, raise max_nbasis, or use Algorithm 2.", options.min_gap, options.max_nbasis,
                self.spectral_gap,
            )
        elif options.min_gap is None and self.spectral_gap * options.s_factor < SMALL_GAP:
            log.warning(
                "mixed CEM: the smallest left-out Stage I eigenvalue is Λ = %.2e (Λ·c < %g): the basis functions "
                "decay slowly with the oversampling layers (expected for ν → ½ in Ω₁ with a fixed l); at m = 5 "
                "errors of 1e-2 and more were measured in such cases. Set min_gap (e.g. %g) to add modes where "
                "Λ is small, add layers, or use Algorithm 2.", self.spectral_gap, SMALL_GAP, DEFAULT_MIN_GAP,
            )

    @property
    def nbasis_range(self) -> tuple[int, int]:
        """(least, most) Stage I modes kept on a coarse cell."""
        counts = np.diff(self.aux.offsets)
        return int(counts.min()), int(counts.max())

    @property
    def spectral_gap(self) -> float:
        """Λ = min over coarse cells of the first Stage I eigenvalue left out (inf when all are kept)."""
        return float(np.min(self.aux.gaps, initial=np.inf))

    def _setup_online(self, data: OfflineData) -> None:
        """Keep the offline data; factorize the coarse matrix [[ΨᵀÃΨ, (ΠᵀBΨ)ᵀ], [ΠᵀBΨ, 0]]."""
        self.aux, self.basis, self.corr, self.co = data
        if getattr(self, "dofs", None) is None:
            self.dofs = CoarseCellDofs.of(self.ops, self.grid)
        self._reach_b = _reaching(self.basis, self.grid.size)
        self._reach_c = _reaching(self.corr, self.grid.size)
        co = self.co
        ms = slice(0, co.n_ms)
        qd = slice(co.n_ms, co.n_ms + co.n_d)
        A = np.block([[co.Gt[ms, ms], co.Bm[:, ms].T], [co.Bm[:, ms], np.zeros((co.n_aux, co.n_aux))]])
        self._lu = sla.lu_factor(A)
        # right-hand sides for the data d = [g; 1]: τ rows F1 d, v rows Πᵀ G − F2 d
        load = np.zeros((co.n_ms, 1)) if co.Fphi is None else co.Fphi[ms, None]  # Ψᵀ F: boundary data
        self._F1 = np.hstack([co.Cphi[ms], load]) - co.Gt[ms, qd] - co.BN[ms]
        self._F2 = co.Bm[:, qd]
        self._E_r, self._E_g = co.Ephi[:, ms], co.Ephi[:, qd].copy()
        if self.ops.s0 is not None:  # σ₁n₁ of the traction lifting s₀ (σ₁ = Ψ r + Q g + σ_f + s₀)
            self._E_g[:, co.n_g] += self.ops.E @ self.ops.s0.ravel()
        self.response = InterfaceResponse.of(self)

    @staticmethod
    def data(g: np.ndarray) -> np.ndarray:
        """The data vector d = [g; 1] (γ values, then the load's weight)."""
        return np.append(np.asarray(g, dtype=float), 1.0)

    def solve_lu(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coarse (r, w) for Robin data g by the coarse LU (``solve`` uses the precomputed response)."""
        n, d = self.co.n_ms, self.data(g)
        x = sla.lu_solve(self._lu, np.concatenate([self._F1 @ d, self.co.PiG - self._F2 @ d]))
        return x[:n], x[n:]

    @property
    def num_coarse_dofs(self) -> int:
        """dim X_ms + dim U_aux."""
        return self.co.n_ms + self.co.n_aux

    def solve(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coarse (r, w) for Robin data g: r = R g + r₀, w = W g + w₀ (``InterfaceResponse``)."""
        rs = self.response
        return rs.R @ g + rs.r0, rs.W @ g + rs.w0

    def trace(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """σ₁n₁ at the γ nodes."""
        return self._E_r @ r + self._E_g @ self.data(g)

    def stress_norm2(self, r: np.ndarray, g: np.ndarray) -> float:
        """‖Ψ r + Q g + σ_f‖²_A."""
        x = np.concatenate([r, self.data(g)])
        return float(x @ self.co.Gk @ x)

    def l2_norm2(self, w: np.ndarray, g: np.ndarray) -> float:
        """‖Π w + N g + u_f‖²_L²."""
        x = np.concatenate([w, self.data(g)])
        return float(x @ self.co.Mu @ x)

    # -- fine reconstruction (output, errors, tests) ----------------------------------
    def _combine(self, K: int, r: np.ndarray | None, d: np.ndarray, part: str) -> np.ndarray:
        """Σ over the functions reaching K of their ``part`` ('sigma' or 'u') on K times their coefficient."""
        out = None
        terms = ([] if r is None else [(f, p, r) for f, p in self._reach_b[K]]) + [(q, p, d) for q, p in self._reach_c[K]]
        for f, p, coef in terms:
            x = getattr(f, part)[p] @ coef[f.index]
            out = x if out is None else out + x
        return out

    @property
    def distributed(self) -> bool:
        """Whether the patch functions are spread over the ranks of ``comm`` (each coarse cell's pieces on one):
        then ``fine_stress`` and the other fine fields are collective over ``comm``."""
        return self._held is not None

    def _here(self) -> np.ndarray:
        """The coarse cells whose fine fields this rank forms (``_held``; all without MPI or with a cache)."""
        return np.arange(self.grid.size) if self._held is None else self._held

    def _summed(self, out: np.ndarray) -> np.ndarray:
        """A fine field formed on the held coarse cells, completed by the other ranks' (each cell from one rank)."""
        if self._held is not None:
            self.comm.Allreduce(MPI.IN_PLACE, out, op=MPI.SUM)
        return out

    def fine_stress(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """σ₁ = Ψ r + Q g + σ_f, cell-major (n_cells, 30): without the traction lifting ``lifting`` (collective
        over ``comm`` when the patch functions are distributed)."""
        out = np.zeros((self.ops.num_cells, 30))
        d = self.data(g)
        for K in self._here():
            out[self.dofs.cells[K]] = self.dofs.dg(self.ops, K, self._combine(K, r, d, "sigma"))
        return self._summed(out)

    def fine_displacement(self, w: np.ndarray, g: np.ndarray) -> np.ndarray:
        """u₁ = Π w + N g + u_f, cell-major (n_cells, 6)."""
        out = np.zeros((self.ops.num_cells, 6))
        d = self.data(g)
        for K in self._here():
            cells = self.dofs.cells[K]
            out[cells] = self.aux.modes[K] @ w[self.aux.offsets[K] : self.aux.offsets[K + 1]]
            if self._reach_c[K]:
                out[cells] += self._combine(K, None, d, "u").reshape(-1, 6)
        return self._summed(out)

    def fine_displacement_post(self, r: np.ndarray, g: np.ndarray) -> np.ndarray:
        """Post-processed fine displacement Σ r_j q_j + N g + u_f (cell-major (n_cells, 6)).

        q_j is the displacement part of the Stage II problem of ψ_j (Ãψ_j + Bᵀq_j = 0), so
        σ₁ = Ψ r + Q g + σ_f and this u satisfy the discrete constitutive law (Aσ₁, τ) + (div τ, u) +
        β∫_γ(σ₁n₁)·(τn₁) = ∫_{γ}g·(τn₁) for τ in every local space; unlike u₁ = Π w + N g + u_f
        (coarse, in U_aux) it resolves the fine scales.
        """
        out = np.zeros((self.ops.num_cells, 6))
        d = self.data(g)
        for K in self._here():
            out[self.dofs.cells[K]] = self._combine(K, r, d, "u").reshape(-1, 6)
        return self._summed(out)

    @property
    def lifting(self) -> np.ndarray | None:
        """The traction lifting s₀ (n_cells, 30), cell-major: the stress is ``fine_stress`` + s₀ (None: no tractions)."""
        return self.ops.s0

    def a_norm2(self, sigma: np.ndarray) -> float:
        """(Aσ, σ) of a cell-major stress."""
        return float(np.einsum("ca,cab,cb->", sigma, self.ops.K, sigma))

    def m_norm2(self, u: np.ndarray) -> float:
        """‖u‖²_L² of a cell-major displacement."""
        return float(np.einsum("ca,cab,cb->", u, self.ops.M, u))

    def project(self, u: np.ndarray) -> np.ndarray:
        """π u = Π Πᵀ S u (cell-major)."""
        out = np.zeros_like(u)
        for k in range(self.grid.size):
            cells = np.sort(self.grid.cells[k].astype(np.int64))
            p = self.aux.modes[k]
            Su = np.einsum("cab,cb->ca", self.ops.S[cells], u[cells])
            out[cells] = p @ np.einsum("cak,ca->k", p, Su)
        return out
