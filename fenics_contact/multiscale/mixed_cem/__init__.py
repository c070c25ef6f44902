"""Mixed CEM-GMsFEM in Ω₁ (Algorithm 4): local spaces, Stage I, Stage II, Robin and source correctors.

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
weight of the primal method).  Large cells: the pencil
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

**Source correction** (``MixedCEMOptions.source_correction``, default on;
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

**Boundary data.**  Tractions on Γ_N: σ = σ̂ + s₀ with the lifting s₀ (s₀n = t) of the fine
Ω₁ subproblem and σ̂n = 0 there (``traction_free_facets``, like the traction-free sides); s₀ moves to the
right-hand side as G ← G − (div s₀, v) and the stress-side load F = −(A s₀, τ) − β∫_γ(s₀n)·(τn); a
prescribed u_D on Γ_D adds ∫_ΓD u_D·(τn) to F (``CellOperators.F``, ``.s0``).  F|K_i enters the τ rows of
the source corrector's system above (the load column), Ψᵀ F the coarse right-hand side (``CoarseOperators.Fphi``),
and the trace σ₁n₁ gets s₀'s (``MixedMultiscaleOmega1.trace``).  Without source correctors F is seen only through Ψᵀ
F (a warning).

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
static condensation along the coarse skeleton (``skeleton.stage_two``): a patch
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
(an inner skeleton DOF has all its coarse cells in the patch),
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

**Modules.** ``options`` (``MixedCEMOptions``, the Stage I targets), ``blocks`` (the cell-major layout),
``operators`` (``CellOperators`` of Ω₁), ``local_space`` (X_h(ω), ``Topology``), ``spectral`` (Stage I,
``StageI``), ``bases`` (the patch systems and the storage of patch functions), ``skeleton`` (Stage II by static
condensation, ``stage_two``), ``coarse`` (``CoarseOperators``), ``cache`` (``OfflineData`` on disk),
``response`` (``InterfaceResponse``), ``omega1`` (``MixedMultiscaleOmega1``).  The names below are re-exported
here.
"""

from fenics_contact.multiscale.mixed_cem.bases import (
    CoarseCellDofs,
    LocalFactor,
    PatchFunctions,
    basis_decay_profile,
    cell_coarse,
    patch_system,
)
from fenics_contact.multiscale.mixed_cem.blocks import block_diag, cell_blocks, cell_rows, column_blocks, row_blocks
from fenics_contact.multiscale.mixed_cem.cache import (
    MIXED_CACHE_FORMAT,
    MixedOfflineCache,
    OfflineData,
    mixed_offline_key,
)
from fenics_contact.multiscale.mixed_cem.coarse import (
    COARSE_ARRAYS,
    SYMMETRIC_ARRAYS,
    CoarseOperators,
    coarse_operators,
    gram,
    reaching,
)
from fenics_contact.multiscale.mixed_cem.local_space import (
    LocalSpace,
    Topology,
    aw_map,
    boundary_vertex_null_spaces,
    local_operators,
    local_stress_space,
    local_triplets,
)
from fenics_contact.multiscale.mixed_cem.omega1 import MixedMultiscaleOmega1
from fenics_contact.multiscale.mixed_cem.operators import CellOperators, cell_operators, scale_to_cell_sizes
from fenics_contact.multiscale.mixed_cem.options import DEFAULT_MAX_NBASIS, DEFAULT_MIN_GAP, SMALL_GAP, MixedCEMOptions
from fenics_contact.multiscale.mixed_cem.response import InterfaceResponse
from fenics_contact.multiscale.mixed_cem.skeleton import KEEP_FACTORS_BYTES, held_cells, stage_two
from fenics_contact.multiscale.mixed_cem.spectral import StageI, stage_one, stage_one_cell, stage_one_of

__all__ = [
    "DEFAULT_MAX_NBASIS",
    "DEFAULT_MIN_GAP",
    "SMALL_GAP",
    "MixedCEMOptions",
    "block_diag",
    "cell_blocks",
    "cell_rows",
    "column_blocks",
    "row_blocks",
    "CellOperators",
    "cell_operators",
    "scale_to_cell_sizes",
    "LocalSpace",
    "Topology",
    "aw_map",
    "boundary_vertex_null_spaces",
    "local_operators",
    "local_stress_space",
    "local_triplets",
    "StageI",
    "stage_one",
    "stage_one_cell",
    "stage_one_of",
    "CoarseCellDofs",
    "LocalFactor",
    "PatchFunctions",
    "basis_decay_profile",
    "cell_coarse",
    "patch_system",
    "KEEP_FACTORS_BYTES",
    "held_cells",
    "stage_two",
    "COARSE_ARRAYS",
    "SYMMETRIC_ARRAYS",
    "CoarseOperators",
    "coarse_operators",
    "gram",
    "reaching",
    "MIXED_CACHE_FORMAT",
    "MixedOfflineCache",
    "OfflineData",
    "mixed_offline_key",
    "InterfaceResponse",
    "MixedMultiscaleOmega1",
]
