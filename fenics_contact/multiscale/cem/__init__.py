"""Primal CEM-GMsFEM in Ω₁ (Algorithm 3): local spectral problems, relaxed CEM bases, Robin and source correctors.

Notation (the docs' theory page, Algorithm 3). K_i are the coarse cells of Ω₁
(``multiscale.coarse``), K_{i,m} the patch of K_i extended by m coarse layers,
κ̃ = c (λ + 2μ) H_i⁻² (H_i = √|K_i|),

    s_i(w, v) = ∫_{K_i} κ̃ w·v dx,   s = Σ_i s_i,
    a_i(φ, v) + α ∫_{γ∩∂K_i} φ·v ds = λ s_i(φ, v)            (local spectral problem)
    a(ψ, v) + α ∫_γ ψ·v ds + s(πψ, πv) = s(φ_j^i, πv)        (relaxed CEM basis on K_{i,m})
    a(N_i g, v) + α ∫_γ N_i g·v ds + s(πN_i g, πv) = ∫_{γ∩∂K_i} g·v ds   (Robin correction)
    a(N_f,i, v) + α ∫_γ N_f,i·v ds + s(πN_f,i, πv) = ℓ_i(v)             (source correction)

for all v ∈ V_h⁰(K_{i,m}) (zero on ∂K_{i,m} ∩ Ω₁ and on Γ_D), where π is the
s-orthogonal projection onto V_aux = ⊕ span{φ_j^i}. Interface integrals use
vertex quadrature, as everywhere in the package.

**Source correction.** With l modes per coarse cell, V_ms approximates the Ω₁
response to a load f only to O(H Λ^{-1/2}), whatever m: the error floor seen
when f acts inside Ω₁. The load functional ℓ(v) = (f, v)_Ω₁ is split into
pieces ℓ_i supported on the coarse cells (every fine vertex is given to the
first coarse cell that contains it: ℓ_i(v) = ℓ(v) for the test functions of
the vertices of K_i given to it, 0 otherwise), each piece is corrected on the
patch of its cell as N g is, N_f = Σ_i N_f,i, and the coarse problem solves for
the remainder:

    w ∈ V_ms:  a₁(w, v) + α∫_γ w·v = ℓ(v) + ∫_γ g·v − [a₁(N g + N_f, v) + α∫_γ (N g + N_f)·v],
    u₁ = w + N g + N_f.

Without localization (patches = Ω₁) u₁ is the fine Robin solution for any
load: with Â = A + BBᵀ, u − Â⁻¹ℓ = A⁻¹B (Bᵀ Â⁻¹ℓ) lies in span A⁻¹B = V_ms.
The correctors decay away from K_i like the basis functions (outside K_i their
equation is the same), so the error falls exponentially with m for any load,
as for localized orthogonal decomposition with a right-hand-side corrector.
Any load that is an assembled functional on Ω₁ is split and corrected the
same way: ``assemble_fine_operators(load=...)`` takes the vector. The Γ_N
tractions on ∂Ω₁ are such a load (``omega1_load``: ℓ(v) = (f, v) + Σ_k ∫_ΓN,k
t_k·v ds), so Algorithm 3 takes them.  A prescribed displacement u_D on Γ_D ∩ ∂Ω₁
enters through its lifting u_g (u_D at the Γ_D DOFs, zero elsewhere): u₁ = w + N g +
N_f + u_g, where N_f now localizes ℓ − A u_g (A = a₁ + the Robin term), and u_g rides
in the last column of Z = [Ψ, N, N_f + u_g], so the trace, the field and the norms
carry it (``assemble_fine_operators(displacement=...)``).
``CEMOptions(source_correction=False)`` is the paper's algorithm (N_f = 0).

**Linear algebra.** The s(π·, π·) term is low rank: with B the matrix whose
columns are s_k(·, φ_j^k) (B = S_k Φ_k blockwise), s(πu, πv) = vᵀ B Bᵀ u. Each
patch problem (A + B Bᵀ) x = r restricted to the interior DOFs I of K_{i,m} is
solved in its sparse saddle-point form

    [A_II  B_IJ] [x]   [r]
    [B_IJᵀ  −I ] [μ] = [0]        (μ = B_IJᵀ x; J = the aux columns of the patch's cells)

(A_II + B_IJ B_IJᵀ has a dense block per coarse cell: 45× the nonzeros of A_II
at h = 1/256). One MUMPS LDLᵀ per patch serves the l_i bases, the Robin
correction of the γ vertices of K_i and the source correction (one solve with
many right-hand sides, sparse: MUMPS skips the forward elimination where they vanish); with
``CEMOptions.patch_group`` the cells of a block share one patch, the union of their K_{i,m}, and one
factorization (a superset of each K_{i,m}: the decay estimate holds with at least m layers); a γ vertex shared
by cells of one group has one Robin datum there (their γ-masses summed: the sum of their correctors). The
functions of a patch problem are stored side by side (the DOFs I and an |I| × k block, of which each cell's
bases are a view), never as fine-mesh-sized arrays. ZᵀAZ comes from the patch equations (``equations``); ZᵀMZ
is summed over coarse cells K from dense blocks of the functions that cover K (BLAS products per K with the
cellwise matrix M_K, summed per pair of patch problems: those on and above the diagonal formed, the rest
mirrored).

**Cellwise matrices.** a_i, s_i and the γ-mass of K_i come from a colouring of
the coarse cells (``CoarseGrid.colors``): cells of one colour share no fine
vertex, so the restriction of the colour-c matrix to the vertices of K_i is the
matrix of K_i. Patch problems need no extra assembly: the rows of the global Ω₁
matrix at the interior DOFs of a patch only see cells of that patch.

**Parallel.** Every local problem is independent: ``build_auxiliary_space`` and
``build_multiscale_space`` take a communicator, share the items out
(``multiscale.work``) and give every rank all results; the coarse-cell blocks
of the coarse operators are summed over the ranks (Allreduce). The fine Ω₁
operators live on a serial (COMM_SELF) copy of Ω₁ on every rank.

Offline data (the aux functions, the bases, N, N_f and the Gram matrices ZᵀKZ,
ZᵀMZ) can be cached on disk (npz, one entry per patch: written without a second
copy) under a key hashing everything they depend on; a cache file whose stored
key or checksum does not match is rebuilt, never used.

**Modules.** ``options`` (``CEMOptions``, the warning thresholds), ``operators`` (the fine Ω₁ operators and
forms), ``spectral`` (the local spectral problems, V_aux), ``bases`` (the patch problems, V_ms), ``coarse``
(Gram and trace matrices, the online Robin solver), ``cache`` (offline key, npz layout, the offline stage),
``omega1`` (``Omega1Multiscale``, the Ω₁ side of Algorithm 3).  The names below are re-exported here.
"""

from fenics_contact.multiscale.cem.bases import (
    METIS_FROM_3D,
    PATCH_ICNTL,
    Incidence,
    MultiscaleSpace,
    PatchFunctions,
    build_multiscale_space,
    cell_groups,
    covering,
    global_saddle_matrix,
    patch_icntl,
    split_block,
)
from fenics_contact.multiscale.cem.cache import CACHE_FORMAT, PrimalOfflineCache, offline_key, offline_stage
from fenics_contact.multiscale.cem.coarse import MultiscaleRobinSolver, gram_matrices, trace_matrix
from fenics_contact.multiscale.cem.omega1 import Omega1Multiscale, build_omega1_multiscale
from fenics_contact.multiscale.cem.operators import (
    FineOperators,
    assemble_fine_operators,
    cem_mass_form,
    interface_mass_form,
    kappa_tilde,
    omega1_load,
    require_serial,
)
from fenics_contact.multiscale.cem.options import (
    ALL_MODES,
    DEFAULT_S_FACTOR,
    EIGENSOLVERS,
    FEW_LAYERS,
    NEARLY_INCOMPRESSIBLE,
    RIGID_MOTIONS,
    WHOLE_DOMAIN,
    CEMOptions,
    warn_if_few_layers,
)
from fenics_contact.multiscale.cem.spectral import (
    DENSE_FALLBACK,
    AuxiliarySpace,
    build_auxiliary_space,
    local_matrices,
    local_spectral_problem,
    restrict,
)

__all__ = [
    "ALL_MODES",
    "DEFAULT_S_FACTOR",
    "EIGENSOLVERS",
    "FEW_LAYERS",
    "NEARLY_INCOMPRESSIBLE",
    "RIGID_MOTIONS",
    "WHOLE_DOMAIN",
    "CEMOptions",
    "warn_if_few_layers",
    "FineOperators",
    "assemble_fine_operators",
    "cem_mass_form",
    "interface_mass_form",
    "kappa_tilde",
    "omega1_load",
    "require_serial",
    "DENSE_FALLBACK",
    "AuxiliarySpace",
    "build_auxiliary_space",
    "local_matrices",
    "local_spectral_problem",
    "restrict",
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
    "MultiscaleRobinSolver",
    "gram_matrices",
    "trace_matrix",
    "CACHE_FORMAT",
    "PrimalOfflineCache",
    "offline_key",
    "offline_stage",
    "Omega1Multiscale",
    "build_omega1_multiscale",
]
