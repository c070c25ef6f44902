"""CEM-GMsFEM in Ω₁: local spectral problems (SLEPc), relaxed CEM bases, Robin and source corrections.

Notation (METHOD §3, Algorithm 3, and §9). K_i are the coarse cells of Ω₁
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
at h = 1/256). One MUMPS LU per patch serves the l_i bases, the Robin
correction of the γ vertices of K_i and the source correction (one solve with
many right-hand sides). The bases are stored per patch (the DOFs I and an
|I| × l_i block), never as fine-mesh-sized arrays. The coarse operators
ΨᵀAΨ, ΨᵀA[N N_f] are summed over coarse cells K from dense blocks of the
functions that cover K (one BLAS product per K with the cellwise matrix A_K).

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

Offline data (the aux functions, the bases, N and N_f) can be cached on disk
(npz, one entry per patch: written without a second copy) under a key hashing
everything they depend on; a cache file whose stored key or checksum does not
match is rebuilt, never used.
"""

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from slepc4py import SLEPc

import dolfinx.mesh
from dolfinx import fem, la

from fenics_contact import __version__
from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem import forms_primal
from fenics_contact.fem.linalg import assemble_scipy, scipy_to_petsc
from fenics_contact.multiscale.cache import OfflineCache, hash_array
from fenics_contact.multiscale.coarse import CoarseGrid, coarse_grid, grid_from_cells
from fenics_contact.multiscale.replica import SerialReplica
from fenics_contact.multiscale.work import run_shared
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.tags import Boundary
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.hybrid.transmission import InterfaceSpace, Part, robin_coefficient, split_mesh

__all__ = [
    "CEMOptions",
    "CoarseGrid",
    "coarse_grid",
    "FineOperators",
    "assemble_fine_operators",
    "local_spectral_problem",
    "count_eigenvalues_below",
    "AuxiliarySpace",
    "build_auxiliary_space",
    "PatchFunctions",
    "MultiscaleSpace",
    "build_multiscale_space",
    "CoarseFactor",
    "MultiscaleRobinSolver",
    "offline_key",
    "PrimalOfflineCache",
    "offline_stage",
    "local_matrices",
    "ALL_MODES",
    "require_serial",
    "Omega1Multiscale",
    "build_omega1_multiscale",
]

log = logging.getLogger(__name__)

#: ``nbasis`` value that keeps every local eigenfunction (V_aux = the broken fine space).
ALL_MODES = None

#: Bumped whenever the layout or meaning of the cached arrays changes.
CACHE_FORMAT = 3  # 3: aux_gaps (the first eigenvalue left out on each coarse cell)

_EIGENSOLVERS = ("auto", "krylovschur", "lapack")

#: Algorithm 3 warns when ν in Ω₁ exceeds this.  As ν → ½ the smallest local eigenvalue left out, Λ,
#: falls like μ/(λ+2μ) and the bases localize slowly: model 3 at E 1e6, h = 1/64, H = 1/16, l = 3, m = 4
#: (``benchmarks/multiscale_primal.py --parts j``): energy error 3.3e-3 (ν = 0.35, Λ·c = 0.78), 3.2e-3
#: (0.4, 0.59), 2.9e-2 (0.45, 0.34), 0.30 (0.48, 0.15), 0.51 (0.49, 0.08), 0.82 (0.499, 0.01).  More modes
#: help only partly: with l_k raised until Λ ≥ 0.3 (a prototype of Algorithm 4's rule, not kept) the error at
#: m = 4 was 0.29 at ν = 0.48, 0.22 at 0.49 and 0.10 at 0.499 (18 modes per cell, 5× the coarse space), far
#: from the 3e-3 of ν ≤ 0.4: the slow decay comes from λ/μ in a(·,·) itself, not only from Λ.  A small Λ alone
#: is no reason to warn: inclusions inside a coarse cell give one too (model 2 at h = 1/32, H = 1/8, ν = 0.35:
#: Λ·c = 0.34), which the CEM bases are built for.
NEARLY_INCOMPRESSIBLE = 0.42

#: fewer oversampling layers than this cut the bases short: warned about (``warn_if_few_layers``)
FEW_LAYERS = 2


def warn_if_few_layers(layers: int, method: str, comm) -> None:
    """Warn (rank 0) when m < ``FEW_LAYERS``: the bases are cut off at one coarse cell (m = 0) or two, and the
    error stays O(1) whatever the number of modes (measured below)."""
    if layers < FEW_LAYERS and comm.rank == 0:
        log.warning(
            "%s with m = %d oversampling layer(s): the multiscale bases are cut off where they have not decayed, "
            "and the Ω₁ error stays large (model 1, h = 1/32, H = 1/8: primal-ms e_u 0.72, 0.36, 5.1e-3, 3.9e-4 "
            "and mixed-ms e_σ 3.1, 0.44, 2.0e-2, 2.5e-3 for m = 0, 1, 2, 3). Use m >= 2 (default 3); check against "
            "the fine solution with --reference.", method, layers)


# ---------------------------------------------------------------------------------------
# options
# ---------------------------------------------------------------------------------------
#: default c in κ̃ = c (λ + 2μ) H⁻² (see CEMOptions)
DEFAULT_S_FACTOR = 3.0


@dataclass(frozen=True, slots=True)
class CEMOptions:
    """CEM-GMsFEM parameters: m oversampling layers, l_i eigenfunctions per coarse cell.

    ``nbasis=None`` (``ALL_MODES``) keeps every local eigenfunction. With
    ``threshold`` set, only eigenpairs with λ ≤ threshold among the ``nbasis``
    smallest are kept (at least one per coarse cell). ``eigensolver`` is
    ``"krylovschur"`` (shift-and-invert about ``target``), ``"lapack"`` (dense,
    all pairs) or ``"auto"`` (Krylov–Schur unless the local problem is too small
    for a Krylov subspace or most of its pairs are wanted).

    ``s_factor`` c scales the weight of the CEM inner product, κ̃ = c (λ + 2μ) H⁻²
    (METHOD §3 has c = 1; the CEM literature's κ Σ_j|∇χ_j|² with a bilinear
    partition of unity gives c between 2 and 4). Default 3, chosen from the sweep
    c ∈ {1, 2, 3, 10, 30, 100} recorded in benchmarks/results/multiscale_primal.md:
    at h = 1/64, H = 1/16, l = 3, m = 5 the energy error of model 1 is 1.0e-2 with
    c = 1 and 1.2e-4 with c = 3.

    ``source_correction`` (default on, METHOD §9) corrects the Ω₁ load on the
    patches as the Robin data are (N_f); off, the coarse problem sees the load
    directly, as in the paper, and the error stalls once the load acts in Ω₁.
    """

    layers: int = 3
    nbasis: int | None = 3
    threshold: float | None = None
    eigensolver: str = "auto"
    eig_tol: float = 1.0e-12
    target: float = -1.0
    s_factor: float = DEFAULT_S_FACTOR
    source_correction: bool = True

    def __post_init__(self) -> None:
        if not (np.isfinite(self.s_factor) and self.s_factor > 0):
            raise InputError(f"s_factor must be finite and > 0, got {self.s_factor!r}")
        if int(self.layers) != self.layers or self.layers < 0:
            raise InputError(f"the number of oversampling layers must be an integer >= 0, got {self.layers!r}")
        if self.nbasis is not None and (int(self.nbasis) != self.nbasis or self.nbasis < 1):
            raise InputError(f"nbasis must be an integer >= 1 (or None for all modes), got {self.nbasis!r}")
        if self.nbasis is not None:
            object.__setattr__(self, "nbasis", int(self.nbasis))  # 3.0 → 3 (an index below)
        if self.threshold is not None and not (np.isfinite(self.threshold) and self.threshold > 0):
            raise InputError(f"the eigenvalue threshold must be finite and > 0, got {self.threshold!r}")
        if self.eigensolver not in _EIGENSOLVERS:
            raise InputError(f"unknown eigensolver {self.eigensolver!r}; choose one of {_EIGENSOLVERS}")
        if not (0 < self.eig_tol < 1e-2):
            raise InputError(f"eig_tol must lie in (0, 1e-2), got {self.eig_tol}")
        if not self.target < 0:
            raise InputError(f"the shift-and-invert target must be < 0 (A is only semi-definite), got {self.target}")
        if not isinstance(self.source_correction, bool):
            raise InputError(f"source_correction must be True or False, got {self.source_correction!r}")


def require_serial(comm: MPI.Comm) -> None:
    """Raise InputError on a communicator with more than one rank (for code that needs the serial Ω₁ copy)."""
    if comm.size > 1:
        raise InputError(
            f"this CEM operation needs a serial (COMM_SELF) mesh; got a communicator with {comm.size} ranks"
        )


# ---------------------------------------------------------------------------------------
# fine-scale operators on Ω₁
# ---------------------------------------------------------------------------------------
def kappa_tilde(lmbda, mu, H, factor: float = 1.0):
    """κ̃ = factor · (λ + 2μ) H⁻² (H a number or a cellwise function)."""
    return factor * (lmbda + 2.0 * mu) / H**2


def cem_mass_form(u, v, weight):
    """s(u, v) = ∫ weight u·v dx (weight = χ κ̃ with χ a coarse-cell indicator)."""
    return weight * ufl.inner(u, v) * ufl.dx


def interface_mass_form(u, v, weight, ds_gamma):
    """∫_γ weight u·v ds (vertex quadrature through ``ds_gamma``)."""
    return weight * ufl.inner(u, v) * ds_gamma


@dataclass(slots=True)
class FineOperators:
    """SciPy matrices of the Ω₁ P1 space (no boundary conditions applied; ``free`` marks non-Γ_D DOFs).

    K: a(u, v); R: α∫_γ u·v; A = K + R; M: (u, v); G: ∫_γ u·v (vertex quadrature); F: the load ℓ(v);
    Kc/Mc/Sc/Gc: a, the mass, s and the γ-mass restricted to the cells of one colour (index = colour).
    """

    V: fem.FunctionSpace
    K: sp.csr_matrix
    R: sp.csr_matrix
    A: sp.csr_matrix
    M: sp.csr_matrix
    G: sp.csr_matrix
    Kc: list
    Mc: list
    Sc: list
    Gc: list
    F: np.ndarray
    free: np.ndarray  #: bool, scalar DOF not on Γ_D
    gamma: np.ndarray  #: scalar DOFs on γ (sorted), the columns of N
    alpha: np.ndarray  #: nodal α at every scalar DOF (zero off γ)
    node_dofs: np.ndarray  #: (num nodes, bs) scalar DOFs of each node
    cell_nodes: np.ndarray  #: (num cells, 3) nodes of each cell
    key_data: dict = field(default_factory=dict)  #: arrays the offline data depend on (for the cache key)
    #: the lifting u_g of a prescribed displacement (u_D at the Γ_D DOFs, zero elsewhere), or None
    lifting: np.ndarray | None = None
    #: the load the source correctors localize: F − A u_g with a lifting, else F (``corrector_load``)
    F_lifted: np.ndarray | None = None

    @property
    def corrector_load(self) -> np.ndarray:
        """ℓ(v) − a₁(u_g, v) − α∫_γ u_g·v: the load of the homogeneous part u₁ − u_g (F without a lifting)."""
        return self.F if self.F_lifted is None else self.F_lifted

    @property
    def size(self) -> int:
        """Number of scalar DOFs of the Ω₁ space (Γ_D included)."""
        return self.K.shape[0]

    @property
    def bs(self) -> int:
        return self.node_dofs.shape[1]


def _over(form: ufl.Form, measure: ufl.Measure) -> ufl.Form:
    """The one cell integral of ``form`` (written with ``ufl.dx``) over ``measure`` instead."""
    (integral,) = form.integrals()
    return integral.integrand() * measure


def assemble_fine_operators(
    V: fem.FunctionSpace,
    facet_tags,
    fields: MaterialFields,
    alpha: fem.Function,
    grid: CoarseGrid,
    *,
    s_factor: float = 1.0,
    load: np.ndarray | None = None,
    displacement=None,
) -> FineOperators:
    """Assemble every Ω₁ matrix the CEM construction needs (serial mesh; colour-restricted copies included).

    ``load`` (optional) replaces the body-force vector (f, v) as the Ω₁ load ℓ(v): any assembled
    functional (tractions).  ``displacement`` (optional): a prescribed u_D on Γ_D (a callable
    x(3, N) -> (2, N) or a constant 2-vector, as ``BoundaryConditions.displacement``); its lifting
    u_g (u_D at the Γ_D DOFs, zero elsewhere) is ``FineOperators.lifting`` and the source correctors
    localize ℓ − A u_g (``corrector_load``).
    """
    msh = V.mesh
    require_serial(msh.comm)
    tdim = msh.topology.dim
    bs = V.dofmap.index_map_bs
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = forms_primal.vertex_measure(msh, facet_tags)(Boundary.INTERFACE)
    Q0 = fields.E.function_space
    cell_dof0 = Q0.dofmap.list[:, 0]
    size = fem.Function(Q0, name="H_K")
    size.x.array[cell_dof0] = grid.cell_size[grid.cell_coarse]
    kap = kappa_tilde(fields.lmbda, fields.mu, size, s_factor)
    a = alpha.x.array.copy()
    fine_colour = grid.colors[grid.cell_coarse]
    Kc, Mc, Sc, Gc = [], [], [], []
    num_cells = msh.topology.index_map(tdim).size_local
    cells = np.arange(num_cells, dtype=np.int32)
    for c in range(grid.num_colors):
        # the cell integrals over the cells of colour c only (tagged 0 here: one compiled form for all colours);
        # the γ facet integral keeps the indicator χ (γ's few facets cost nothing)
        in_c = dolfinx.mesh.meshtags(msh, tdim, cells, (fine_colour[:num_cells] != c).astype(np.int32))
        dx_c = ufl.Measure("dx", domain=msh, subdomain_data=in_c)(0)
        chi = fem.Function(Q0, name=f"chi{c}")
        chi.x.array[cell_dof0] = (fine_colour == c).astype(np.float64)
        Kc.append(assemble_scipy(_over(forms_primal.elastic_form(u, v, fields.lmbda, fields.mu), dx_c)))
        Mc.append(assemble_scipy(ufl.inner(u, v) * dx_c))
        Gc.append(assemble_scipy(interface_mass_form(u, v, chi, ds)))
        Sc.append(assemble_scipy(_over(cem_mass_form(u, v, kap), dx_c)))
    K = sum(Kc[1:], Kc[0]).tocsr()
    M = sum(Mc[1:], Mc[0]).tocsr()
    G = sum(Gc[1:], Gc[0]).tocsr()
    R = (sp.diags(a) @ G).tocsr()
    A = (K + R).tocsr()
    if load is None:
        F_vec = fem.assemble_vector(fem.form(ufl.inner(fields.f, v) * ufl.dx))
        F_vec.scatter_reverse(la.InsertMode.add)
        F = F_vec.array.copy()
    else:
        F = np.asarray(load, dtype=np.float64).copy()
        if F.shape != (K.shape[0],):
            raise InputError(f"the Ω₁ load vector has shape {F.shape}, expected ({K.shape[0]},)")
    n = K.shape[0]
    msh.topology.create_connectivity(tdim - 1, tdim)
    dir_blocks = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(Boundary.GAMMA_D))
    gam_blocks = fem.locate_dofs_topological(V, tdim - 1, facet_tags.find(Boundary.INTERFACE))
    free = np.ones(n, dtype=bool)
    free[(bs * dir_blocks[:, None] + np.arange(bs)).ravel()] = False
    gamma = np.sort((bs * gam_blocks[:, None] + np.arange(bs)).ravel())
    num_nodes = n // bs
    node_dofs = bs * np.arange(num_nodes)[:, None] + np.arange(bs)
    cell_nodes = V.dofmap.list.copy()
    lam = fields.lmbda.x.array[cell_dof0]
    mu = fields.mu.x.array[cell_dof0]
    key_data = {
        "E": fields.E.x.array[cell_dof0],
        "nu": fields.nu.x.array[cell_dof0],
        "lame": np.concatenate([lam, mu]),
        "alpha": a,
        "coords": V.tabulate_dof_coordinates(),
        "cell_nodes": cell_nodes,
        "cell_coarse": grid.global_index[grid.cell_coarse],
        "cell_size": grid.cell_size,
        "free": free,
        "load": F,
    }
    lifting = F_lifted = None
    if displacement is not None and dir_blocks.size:
        u_D = fem.Function(V)
        u_D.interpolate(displacement if callable(displacement) else
                        (lambda x, c=np.asarray(displacement, dtype=np.float64): np.tile(c[:, None], (1, x.shape[1]))))
        lifting = np.zeros(n)
        lifting[~free] = u_D.x.array[~free]
        if np.any(lifting):
            F_lifted = F - A @ lifting
            key_data["lifting"] = lifting
        else:
            lifting = None
    return FineOperators(V, K, R, A, M, G, Kc, Mc, Sc, Gc, F, free, gamma, a, node_dofs, cell_nodes, key_data,
                         lifting, F_lifted)


def omega1_load(V: fem.FunctionSpace, facet_tags, fields: MaterialFields) -> np.ndarray | None:
    """The Ω₁ load vector ℓ(v) = (f, v) + Σ_k ∫_ΓN,k t_k·v ds on a serial Ω₁ mesh, or None without tractions.

    The tractions of ``fields.boundary`` whose Γ_N groups have facets in ``facet_tags`` enter
    as in the fine methods (``fem.primal``: t_k interpolated in P1, the boundary integral
    assembled); the source correction then treats them as it treats f (module docstring).
    """
    require_serial(V.mesh.comm)
    present = set(np.unique(facet_tags.values).tolist())
    tractions = [(tag, field_) for tag, _, field_ in fields.boundary.traction_tags() if tag in present]
    if not tractions:
        return None
    v = ufl.TestFunction(V)
    ds = ufl.Measure("ds", domain=V.mesh, subdomain_data=facet_tags)
    pairs = []
    for tag, field_ in tractions:
        t = fem.Function(V)
        t.interpolate(field_)
        pairs.append((t, ds(tag)))
    form = ufl.inner(fields.f, v) * ufl.dx + forms_primal.traction_form(pairs, v)
    vec = fem.assemble_vector(fem.form(form))
    vec.scatter_reverse(la.InsertMode.add)
    return vec.array.copy()


# ---------------------------------------------------------------------------------------
# local spectral problems
# ---------------------------------------------------------------------------------------
#: Extra eigenpairs requested from Krylov–Schur beyond the wanted ones (a margin for multiplicities).
_EXTRA_PAIRS = 3
#: Relative gap above the last wanted eigenvalue at which the inertia count is taken.
_INERTIA_GAP = 1.0e-6
#: Largest local problem solved densely (LAPACK) when Krylov–Schur keeps missing pairs.
_DENSE_FALLBACK = 3000


def _eps_pairs(
    Ap: PETSc.Mat, Sp: PETSc.Mat, nev: int, kind: str, *, target: float, tol: float, deflation: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """All converged eigenpairs of one SLEPc GHEP solve (Krylov–Schur + shift-and-invert, or LAPACK)."""
    n = Ap.getSize()[0]
    eps = SLEPc.EPS().create(PETSc.COMM_SELF)
    defl = []
    try:
        eps.setOperators(Ap, Sp)
        eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
        if kind == "krylovschur":
            eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
            eps.setDimensions(nev)
            st = eps.getST()
            st.setType(SLEPc.ST.Type.SINVERT)
            ksp = st.getKSP()
            ksp.setType(PETSc.KSP.Type.PREONLY)
            ksp.getPC().setType(PETSc.PC.Type.LU)
            eps.setTarget(target)
            eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
            if deflation is not None and deflation.shape[1]:
                for col in deflation.T:
                    vec = Ap.createVecRight()
                    vec.array[:] = col
                    defl.append(vec)
                eps.setDeflationSpace(defl)
        else:
            eps.setType(SLEPc.EPS.Type.LAPACK)
            eps.setDimensions(n)
            eps.setWhichEigenpairs(SLEPc.EPS.Which.SMALLEST_REAL)
        eps.setTolerances(tol, 1000)
        eps.solve()
        nconv = eps.getConverged()
        if nconv < nev:
            raise ConvergenceError(
                f"local spectral problem ({kind}, n = {n}): only {nconv} of {nev} eigenpairs converged "
                f"(reason {eps.getConvergedReason()})"
            )
        vr = Ap.createVecRight()
        values = np.empty(nconv)
        vectors = np.empty((n, nconv))
        for j in range(nconv):
            values[j] = eps.getEigenpair(j, vr).real
            vectors[:, j] = vr.array
        vr.destroy()
    finally:
        eps.destroy()
        for vec in defl:
            vec.destroy()
    return values, vectors


def count_eigenvalues_below(A: sp.spmatrix, S: sp.spmatrix, sigma: float) -> int:
    """#{λ < σ} for A φ = λ S φ (S ≻ 0): the negative inertia of A − σS (MUMPS LDLᵀ, Sylvester's law)."""
    X = scipy_to_petsc((A - sigma * S).tocsr())
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    try:
        ksp.setOperators(X)
        ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(24, 1)  # null-pivot detection: required for the inertia
        ksp.setUp()
        if pc.getFailedReason() != 0:
            raise ConvergenceError(f"LDLᵀ of A − σS failed (PETSc reason {pc.getFailedReason()})")
        nneg, _, _ = pc.getFactorMatrix().getInertia()
    finally:
        ksp.destroy()
        X.destroy()
    return int(nneg)


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
    try:
        if kind == "lapack":
            values, vectors = _eps_pairs(Ap, Sp, nev, kind, target=target, tol=tol, deflation=None)
        else:
            want = min(nev + _EXTRA_PAIRS, n)
            values, vectors = _eps_pairs(Ap, Sp, want, kind, target=target, tol=tol, deflation=None)
            for _ in range(10):
                order = np.argsort(values, kind="stable")
                values, vectors = values[order], vectors[:, order]
                cut = values[nev - 1]
                sigma = cut + _INERTIA_GAP * max(1.0, abs(cut))
                below = count_eigenvalues_below(A, S, sigma)
                have = int(np.count_nonzero(values < sigma))
                if below <= have:
                    break
                log.debug("Krylov–Schur missed %d eigenpair(s) below %.3e; deflating and searching again",
                          below - have, sigma)
                more_v, more_x = _eps_pairs(
                    Ap, Sp, min(below - have + _EXTRA_PAIRS, n - have), kind, target=target, tol=tol,
                    deflation=vectors[:, values < sigma],
                )
                keep = values < sigma
                values = np.concatenate([values[keep], more_v])
                vectors = np.concatenate([vectors[:, keep], more_x], axis=1)
            else:
                # (showcase stream) shift-and-invert about target = −1 clusters eigenvalues ≪ 1 near one
                # (a coarse cell holding a stiff inclusion in a soft matrix: λ₄ ≈ 5e-3) and Krylov–Schur keeps
                # missing a copy of the triple zero; a problem small enough is then solved densely.
                if n > _DENSE_FALLBACK:
                    raise ConvergenceError(f"local spectral problem (n = {n}): could not find all {nev} smallest "
                                           "pairs")
                log.info("local spectral problem (n = %d): Krylov–Schur missed pairs; dense LAPACK instead", n)
                values, vectors = _eps_pairs(Ap, Sp, nev, "lapack", target=target, tol=tol, deflation=None)
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
        return [Phi @ c[self.offsets[k]:self.offsets[k + 1]] for k, Phi in enumerate(self.vectors)]

    def project_local(self, local: list, S_local: list) -> list:
        """π applied to a broken function given by local vectors (with the local s_k matrices)."""
        return [Phi @ (Phi.T @ (Sk @ w)) for Phi, Sk, w in zip(self.vectors, S_local, local)]


class _Incidence:
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
        return self.cell_nodes.indices[self.cell_nodes.indptr[k]:self.cell_nodes.indptr[k + 1]]

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


def _cell_dofs(ops: FineOperators, grid: CoarseGrid, k: int) -> np.ndarray:
    nodes = np.unique(ops.cell_nodes[grid.cells[k]])
    dofs = ops.node_dofs[nodes].ravel()
    return dofs[ops.free[dofs]]


def local_matrices(ops: FineOperators, grid: CoarseGrid, k: int) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """D_k and the matrices of a_k(·,·) + α∫_{γ∩∂K_k} and s_k on it (colour restriction)."""
    c = int(grid.colors[k])
    D = _cell_dofs(ops, grid, k)
    Gk = ops.Gc[c][D][:, D]
    return D, (ops.Kc[c][D][:, D] + sp.diags(ops.alpha[D]) @ Gk).tocsr(), ops.Sc[c][D][:, D].tocsr()


def build_auxiliary_space(
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, comm: MPI.Comm = MPI.COMM_SELF
) -> AuxiliarySpace:
    """Solve every local spectral problem (shared out over ``comm``) and keep l_k s-normalized eigenfunctions."""
    sizes = np.array([c.size for c in grid.cells], dtype=np.float64)

    def eigenproblem(k: int) -> tuple:
        D, A, S = local_matrices(ops, grid, k)
        # one pair more than kept: Λ_k, the first eigenvalue left out (reported as ``spectral_gap``)
        l = options.nbasis  # an int (CEMOptions) or None
        lam, Phi = local_spectral_problem(
            A, S, l if l is None or l >= D.size else l + 1, eigensolver=options.eigensolver,
            target=options.target, tol=options.eig_tol,
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
        return D, lam, Phi, gap

    parts = run_shared(sizes**1.5, comm, "CEM local eigenproblems", eigenproblem, balanced=True, logger=log)
    dofs = [p[0] for p in parts]
    values = [p[1] for p in parts]
    vectors = [p[2] for p in parts]
    blocks = [ops.Sc[int(grid.colors[k])][D][:, D] @ Phi for k, (D, Phi) in enumerate(zip(dofs, vectors))]
    return _aux_from_parts(ops.size, dofs, values, vectors, blocks, np.array([p[3] for p in parts]))


def _aux_from_parts(n: int, dofs, values, vectors, blocks, gaps: np.ndarray) -> AuxiliarySpace:
    offsets = np.concatenate([[0], np.cumsum([Phi.shape[1] for Phi in vectors])]).astype(np.int64)
    rows = np.concatenate([np.repeat(D, b.shape[1]) for D, b in zip(dofs, blocks)])
    cols = np.concatenate(
        [np.tile(np.arange(offsets[k], offsets[k + 1]), len(D)) for k, D in enumerate(dofs)]
    )
    data = np.concatenate([b.ravel() for b in blocks])
    B = sp.csr_matrix((data, (rows, cols)), shape=(n, int(offsets[-1])))
    return AuxiliarySpace(list(dofs), list(values), list(vectors), B, offsets, np.asarray(gaps, dtype=np.float64))


# ---------------------------------------------------------------------------------------
# patch problems: relaxed CEM bases, Robin and source corrections
# ---------------------------------------------------------------------------------------
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
    Robin correction N (``correction``: γ DOF positions → Ω₁ fields, one per coarse cell touching γ)
    and the source correction N_f (an Ω₁ vector, None when switched off)."""

    aux: AuxiliarySpace
    basis: list
    correction: list
    Nf: np.ndarray | None
    layers: int
    n: int  #: Ω₁ DOFs
    n_gamma: int  #: γ DOFs
    correction_cells: np.ndarray  #: coarse cell of each ``correction`` entry
    times: dict = field(default_factory=dict)

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


class _SaddleFactor:
    """MUMPS LDLᵀ (symmetric indefinite, QAMD ordering) of a sparse saddle-point patch matrix; multi-RHS solves.

    Measured on a 7×7-cell patch at h = 1/256 (24.6k DOFs): LDLᵀ with QAMD 0.13 s, LDLᵀ with AMD
    0.21 s, LU with AMD 0.39 s, SuperLU 1.8 s; QAMD copes with the μ rows (one per aux function,
    dense over its coarse cell).
    """

    def __init__(self, A: PETSc.Mat) -> None:
        self.mat = A
        self.mat.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        self.ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        self.ksp.setOperators(self.mat)
        self.ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = self.ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        pc.getFactorMatrix().setMumpsIcntl(7, 6)  # QAMD
        self.ksp.setUp()
        if pc.getFailedReason() != 0:
            self.destroy()
            raise ConvergenceError(f"MUMPS failed to factorize a CEM patch problem (reason {pc.getFailedReason()})")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A⁻¹ rhs for all columns at once (one MatMatSolve)."""
        n, k = rhs.shape
        B = PETSc.Mat().createDense((n, k), array=np.asfortranarray(rhs, dtype=PETSc.ScalarType), comm=PETSc.COMM_SELF)
        X = PETSc.Mat().createDense((n, k), comm=PETSc.COMM_SELF)
        X.setUp()
        try:
            self.ksp.matSolve(B, X)
            if self.ksp.getConvergedReason() < 0:
                raise ConvergenceError(f"MUMPS failed on a CEM patch problem (reason {self.ksp.getConvergedReason()})")
            return X.getDenseArray().copy()
        finally:
            B.destroy()
            X.destroy()

    def destroy(self) -> None:
        self.ksp.destroy()
        self.mat.destroy()


def global_saddle_matrix(ops: FineOperators, aux: AuxiliarySpace) -> PETSc.Mat:
    """[[A, B], [Bᵀ, −I]] on all Ω₁ DOFs and aux functions: every patch matrix is a principal submatrix."""
    M = sp.bmat([[ops.A, aux.B], [aux.B.T, -sp.identity(aux.size, format="csr")]], format="csr")
    return scipy_to_petsc(M)


def _patch_problem(
    ops: FineOperators, grid: CoarseGrid, aux: AuxiliarySpace, inc: _Incidence, saddle: PETSc.Mat, i: int,
    patch: np.ndarray, inner: np.ndarray, *, source: bool,
) -> tuple:
    """Bases, Robin correction and source correction of coarse cell i on its patch (one LDLᵀ)."""
    J = np.concatenate([aux.columns(k) for k in patch])
    nI, nJ = inner.size, J.size
    index = PETSc.IS().createGeneral(np.concatenate([inner, ops.size + J]).astype(PETSc.IntType), comm=PETSc.COMM_SELF)
    try:
        M = saddle.createSubMatrix(index, index)
    finally:
        index.destroy()
    li = int(aux.offsets[i + 1] - aux.offsets[i])
    # Robin data on the γ vertices of K_i (γ-mass of the cells of K_i)
    c = int(grid.colors[i])
    D_all = inc.dofs(i, free_only=False)
    on_gamma = np.intersect1d(D_all, ops.gamma, assume_unique=True)
    if on_gamma.size:
        G_I = ops.Gc[c][on_gamma][:, inner].T.tocsc()  # (|I| × γ vertices of K_i), symmetric γ-mass
        used = np.flatnonzero(np.diff(G_I.indptr) > 0)
    else:
        used = np.zeros(0, dtype=np.int64)
    ng = used.size
    F_i = None
    if source:
        F_i = ops.corrector_load[inner] * (inc.load_owner[inner // ops.bs] == i)
        if not np.any(F_i):
            F_i = None
    ncols = li + ng + (F_i is not None)
    rhs = np.zeros((nI + nJ, ncols))
    rhs[nI + np.searchsorted(J, aux.columns(i)), np.arange(li)] = 1.0  # s(φ_j^i, πv): the μ-row unit vectors
    if ng:
        rhs[:nI, li:li + ng] = G_I[:, used].toarray()
    if F_i is not None:
        rhs[:nI, -1] = F_i
    try:
        lu = _SaddleFactor(M)
    except BaseException:
        M.destroy()
        raise
    try:
        x = lu.solve(rhs)[:nI]
    finally:
        lu.destroy()
    dofs = inner.astype(np.int32)
    basis = PatchFunctions(dofs, np.ascontiguousarray(x[:, :li]), aux.columns(i))
    gamma_pos = np.searchsorted(ops.gamma, on_gamma[used])
    corr = PatchFunctions(dofs, np.ascontiguousarray(x[:, li:li + ng]), gamma_pos) if ng else None
    nf = x[:, -1].copy() if F_i is not None else None
    return basis, corr, nf


def build_multiscale_space(
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, aux: AuxiliarySpace | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
) -> MultiscaleSpace:
    """Offline stage: aux space, relaxed CEM bases on K_{i,m}, the corrections N and N_f (shared out over comm)."""
    times = {}
    t0 = time.perf_counter()
    if aux is None:
        aux = build_auxiliary_space(ops, grid, options, comm=comm)
    times["eigen"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    inc = _Incidence(ops, grid)
    patches = [grid.patch(i, options.layers) for i in range(grid.size)]
    inner = [inc.interior_dofs(p) for p in patches]
    saddle = global_saddle_matrix(ops, aux)
    try:
        owner = np.empty(grid.size, dtype=np.int64)
        results = run_shared(np.array([d.size for d in inner], dtype=np.float64) ** 1.5, comm, "CEM patch problems",
                             lambda i: _patch_problem(ops, grid, aux, inc, saddle, i, patches[i], inner[i],
                                                      source=options.source_correction),
                             balanced=True, owner=owner, logger=log)
    finally:
        saddle.destroy()
    basis = [r[0] for r in results]
    correction = [r[1] for r in results if r[1] is not None]
    correction_cells = np.array([i for i, r in enumerate(results) if r[1] is not None], dtype=np.int64)
    Nf = None
    if options.source_correction:
        Nf = np.zeros(ops.size)
        for r in results:
            if r[2] is not None:
                Nf[r[0].dofs] += r[2]
    if ops.lifting is not None:  # u₁ = Ψ w + N g + (N_f + u_g): the lifting rides in the last column of Z
        Nf = ops.lifting.copy() if Nf is None else Nf + ops.lifting
    times["patches"] = time.perf_counter() - t0
    times["total"] = times["eigen"] + times["patches"]
    times["patches_here"] = int(np.count_nonzero(owner == comm.rank))  # this rank's share
    space = MultiscaleSpace(aux, basis, correction, Nf, int(options.layers), ops.size, ops.gamma.size,
                            correction_cells, times)
    log.info(
        "CEM offline: %d coarse cells, m = %d, dim V_ms = %d, %.1f MB of bases; eigen %.2f s, patches %.2f s",
        grid.size, options.layers, aux.size, space.nbytes / 1e6, times["eigen"], times["patches"],
    )
    return space


# ---------------------------------------------------------------------------------------
# the coarse (online) solve
# ---------------------------------------------------------------------------------------
class CoarseFactor:
    """Pivoted Cholesky of an SPSD matrix, Jacobi-scaled; columns that are numerically dependent are dropped.

    Solves A x = b for consistent b; x is zero on the dropped (pivot < tolerance) coordinates.
    """

    def __init__(self, A: np.ndarray) -> None:
        A = 0.5 * (A + A.T)
        d = np.diag(A).copy()
        if np.any(d <= 0):
            raise ConvergenceError("the coarse matrix has a non-positive diagonal entry (empty basis function?)")
        self.scale = 1.0 / np.sqrt(d)
        As = A * self.scale[:, None] * self.scale[None, :]
        c, piv, rank, info = scipy.linalg.lapack.dpstrf(As, lower=1)
        if info < 0:
            raise ConvergenceError(f"pivoted Cholesky failed (LAPACK info {info})")
        self.n = A.shape[0]
        self.rank = int(rank)
        self.keep = piv[: self.rank] - 1
        self.L = np.asfortranarray(np.tril(c[: self.rank, : self.rank]))
        if self.rank < self.n:
            log.info("coarse matrix: rank %d of %d, dependent basis functions dropped", self.rank, self.n)

    def solve(self, b: np.ndarray) -> np.ndarray:
        bs = (b * self.scale[:, None]) if b.ndim == 2 else b * self.scale
        z, info = scipy.linalg.lapack.dpotrs(self.L, bs[self.keep], lower=1)
        if info != 0:
            raise ConvergenceError(f"coarse solve failed (LAPACK dpotrs info {info})")
        x = np.zeros_like(bs)
        x[self.keep] = z
        return (x * self.scale[:, None]) if b.ndim == 2 else x * self.scale




def _rows_on(parts: list, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dense block (|D| × Σ k) of the patch functions ``parts`` at the DOFs D, and their global columns."""
    ncols = sum(p.columns.size for p in parts)
    Z = np.zeros((D.size, ncols))
    cols = np.empty(ncols, dtype=np.int64)
    at = 0
    for p in parts:
        k = p.columns.size
        pos = np.searchsorted(p.dofs, D)
        np.minimum(pos, p.dofs.size - 1, out=pos)
        hit = p.dofs[pos] == D
        Z[hit, at:at + k] = p.values[pos[hit]]
        cols[at:at + k] = p.columns
        at += k
    return Z, cols


def gram_matrices(
    ops: FineOperators, grid: CoarseGrid, space: MultiscaleSpace, *, comm: MPI.Comm = MPI.COMM_SELF
) -> tuple[np.ndarray, np.ndarray]:
    """(ZᵀKZ, ZᵀMZ) for Z = [Ψ, N, N_f] (columns: the dim V_ms bases, the γ DOFs, the source correction).

    Summed over coarse cells K of Z_Kᵀ K_K Z_K (K_K the cellwise matrix, Z_K the dense block of the
    functions covering K); cells shared out over ``comm`` (a static share: a fixed summation order) and the
    sums Allreduced.
    """
    inc = _Incidence(ops, grid)
    n_ms, ng = space.size, space.n_gamma
    nz = n_ms + ng + 1
    corr_at = {int(k): p for k, p in zip(space.correction_cells, space.correction)}
    GK = np.zeros((nz, nz))
    GM = np.zeros((nz, nz))
    sizes = np.array([c.size for c in grid.cells], dtype=np.float64)

    def add_cell(K: int) -> None:
        c = int(grid.colors[K])
        D = inc.dofs(K, free_only=False)
        cover = grid.patch(K, space.layers)
        Zb, cols = _rows_on([space.basis[i] for i in cover], D)
        blocks = [Zb]
        cn = [corr_at[int(i)] for i in cover if int(i) in corr_at]
        if cn:
            Zn, cols_n = _rows_on(cn, D)
            # a γ vertex shared by two coarse cells has a column in both corrections: sum them first
            uniq, inv = np.unique(cols_n, return_inverse=True)
            merge = sp.csr_matrix((np.ones(inv.size), (np.arange(inv.size), inv)), shape=(inv.size, uniq.size))
            blocks.append((merge.T @ Zn.T).T)
            cols = np.concatenate([cols, n_ms + uniq])
        if space.Nf is not None:
            blocks.append(space.Nf[D][:, None])
            cols = np.concatenate([cols, [nz - 1]])
        Z = np.hstack(blocks) if len(blocks) > 1 else Zb
        idx = np.ix_(cols, cols)
        GK[idx] += Z.T @ (ops.Kc[c][D][:, D] @ Z)
        GM[idx] += Z.T @ (ops.Mc[c][D][:, D] @ Z)

    # a static share (not handed out on request): the same cells on the same rank in every run, so the sums
    # and the Allreduce below round the same way every time
    run_shared(sizes, comm, "CEM Gram matrices", add_cell, gather=False, logger=log)
    if comm.size > 1:
        for arr in (GK, GM):
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

    def __init__(self, ops: FineOperators, space: MultiscaleSpace, grid: CoarseGrid, *,
                 comm: MPI.Comm = MPI.COMM_SELF) -> None:
        t0 = time.perf_counter()
        self.ops = ops
        self.space = space
        n_ms, ng = space.size, space.n_gamma
        self.GK, self.GM = gram_matrices(ops, grid, space, comm=comm)
        self.Zg = trace_matrix(ops, space)
        # ZᵀAZ = ZᵀKZ + Z_γᵀ R_γγ Z_γ (R is α times the γ vertex mass: diagonal on γ)
        Rg = ops.R[ops.gamma][:, ops.gamma]
        ZAZ = self.GK + self.Zg.T @ (Rg @ self.Zg)
        self.A_ms = ZAZ[:n_ms, :n_ms]
        self.factor = CoarseFactor(self.A_ms)
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
        self.C = PsiG - ZAZ[:n_ms, n_ms:n_ms + ng]
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
        u = self.space.apply(s[:n_ms], s[n_ms:n_ms + ng], with_source=False)
        if self.space.Nf is not None and s[-1] != 0.0:
            u += s[-1] * self.space.Nf
        return u

    def solve(self, g: np.ndarray) -> np.ndarray:
        """u₁ (all scalar Ω₁ DOFs) for nodal Robin data g on ``ops.gamma``."""
        return self.field(self.coordinates(g))

    def trace(self, s: np.ndarray) -> np.ndarray:
        """u₁ at ``ops.gamma`` for coordinates s."""
        return self.Zg @ s

    def response(self) -> tuple[np.ndarray, np.ndarray]:
        """The affine interface map u₁|γ = R g + r₀ (``ops.gamma`` ordering, dense R)."""
        n_ms, ng = self.space.size, self.space.n_gamma
        X = self.factor.solve(np.column_stack([self.C, self.b_f]))
        R = self.Zg[:, :n_ms] @ X[:, :ng] + self.Zg[:, n_ms:n_ms + ng]
        r0 = self.Zg[:, :n_ms] @ X[:, ng] + self.Zg[:, -1]
        return R, r0


# ---------------------------------------------------------------------------------------
# offline cache
# ---------------------------------------------------------------------------------------
def offline_key(ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, h: float) -> str:
    """sha256 of everything the offline data depend on: mesh, coarse grid, E, ν, α, load, options, version."""
    hasher = hashlib.sha256()
    meta = {
        "format": CACHE_FORMAT,
        "version": __version__,
        "h": repr(float(h)),
        "H": repr(float(grid.H)),
        "options": {
            "layers": options.layers,
            "nbasis": options.nbasis,
            "threshold": options.threshold,
            "eigensolver": options.eigensolver,
            "eig_tol": options.eig_tol,
            "target": options.target,
            "s_factor": options.s_factor,
            "source_correction": options.source_correction,
        },
    }
    hasher.update(json.dumps(meta, sort_keys=True).encode())
    for name in sorted(ops.key_data):
        if name == "load" and not options.source_correction:
            continue
        hasher.update(name.encode())
        hash_array(hasher, ops.key_data[name])
    return hasher.hexdigest()


def _pack(space: MultiscaleSpace) -> dict:
    """Arrays to store: the aux space (small, concatenated) and one entry per patch block (no copies)."""
    aux = space.aux
    out = {
        "aux_offsets": aux.offsets,
        "aux_dof_offsets": np.concatenate([[0], np.cumsum([d.size for d in aux.dofs])]).astype(np.int64),
        "aux_dofs": np.concatenate(aux.dofs).astype(np.int64),
        "aux_values": np.concatenate(aux.eigenvalues),
        "aux_gaps": aux.gaps,
        "aux_vectors": np.concatenate([Phi.ravel() for Phi in aux.vectors]),
        "meta": np.array([space.layers, space.n, space.n_gamma, len(space.basis), len(space.correction)]),
        "correction_cells": np.asarray(space.correction_cells, dtype=np.int64),
    }
    for name, parts in (("basis", space.basis), ("corr", space.correction)):
        for k, p in enumerate(parts):
            out[f"{name}{k}_dofs"] = p.dofs
            out[f"{name}{k}_values"] = p.values
            out[f"{name}{k}_columns"] = p.columns
    if space.Nf is not None:
        out["Nf"] = space.Nf
    return out


def _unpack(arrays: dict, ops: FineOperators, grid: CoarseGrid) -> MultiscaleSpace:
    offs, doffs = arrays["aux_offsets"], arrays["aux_dof_offsets"]
    if offs.size != grid.size + 1 or doffs.size != grid.size + 1:
        raise ValueError("cached auxiliary space does not match the coarse grid")
    dofs, values, vectors, blocks = [], [], [], []
    pos = 0
    for k in range(grid.size):
        D = arrays["aux_dofs"][doffs[k]:doffs[k + 1]]
        lk = int(offs[k + 1] - offs[k])
        Phi = arrays["aux_vectors"][pos:pos + D.size * lk].reshape(D.size, lk)
        pos += D.size * lk
        S = ops.Sc[int(grid.colors[k])][D][:, D]
        dofs.append(D)
        values.append(arrays["aux_values"][offs[k]:offs[k + 1]])
        vectors.append(Phi)
        blocks.append(S @ Phi)
    aux = _aux_from_parts(ops.size, dofs, values, vectors, blocks, arrays["aux_gaps"])
    layers, n, ng, nb, nc = (int(x) for x in arrays["meta"])
    if n != ops.size or ng != ops.gamma.size or nb != grid.size:
        raise ValueError("cached multiscale space does not match the Ω₁ operators")
    parts = {}
    for name, count in (("basis", nb), ("corr", nc)):
        parts[name] = [
            PatchFunctions(arrays[f"{name}{k}_dofs"], arrays[f"{name}{k}_values"], arrays[f"{name}{k}_columns"])
            for k in range(count)
        ]
    times = {"eigen": 0.0, "patches": 0.0, "total": 0.0}
    return MultiscaleSpace(aux, parts["basis"], parts["corr"], arrays.get("Nf"), layers, n, ng,
                           arrays["correction_cells"], times)


class PrimalOfflineCache(OfflineCache):
    """npz files ``cem_<key>.npz`` holding the primal ``MultiscaleSpace`` (``cache.OfflineCache``)."""

    prefix = "cem"

    @staticmethod
    def pack(obj: "MultiscaleSpace") -> dict[str, np.ndarray]:
        return _pack(obj)

    @staticmethod
    def unpack(arrays: dict[str, np.ndarray], *context) -> "MultiscaleSpace":
        return _unpack(arrays, *context)


def offline_stage(
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, h: float, cache_dir: str | Path | None = None,
    comm: MPI.Comm = MPI.COMM_SELF,
) -> tuple[MultiscaleSpace, str]:
    """Build (or load from the cache) the multiscale space; returns (space, cache status).

    Under MPI every rank reads the cache file; rank 0 alone writes it.
    """
    if cache_dir is None:
        return build_multiscale_space(ops, grid, options, comm=comm), "disabled"
    cache = PrimalOfflineCache(cache_dir)
    key = offline_key(ops, grid, options, h=h)
    t0 = time.perf_counter()
    space, status = cache.load(key, ops, grid)
    # every rank must agree on the cache status before the collective build
    if comm.size > 1 and comm.allreduce(int(space is None), op=MPI.MAX):
        space, status = None, comm.bcast(status if space is None else "missing", root=0)
    if space is not None:
        space.times["load"] = time.perf_counter() - t0
        log.info("CEM offline data loaded from %s", cache.path(key))
        return space, status
    if status != "missing":
        log.warning("CEM offline cache %s rejected (%s); rebuilding", cache.path(key), status)
    error = None
    if comm.rank == 0:
        try:
            cache.check_writable()  # before the expensive build, not after it
        except InputError as err:
            error = str(err)
    error = comm.bcast(error, root=0)  # every rank raises, none waits in the collective build
    if error is not None:
        raise InputError(error)
    space = build_multiscale_space(ops, grid, options, comm=comm)
    if comm.rank == 0:
        try:
            cache.save(key, space)
        except OSError as err:  # the directory went away or filled up meanwhile: keep the built data
            log.warning("CEM offline data could not be saved to %s: %s", cache.path(key), err)
    comm.Barrier()
    return space, "built" if status == "missing" else "rebuilt"


# ---------------------------------------------------------------------------------------
# the Ω₁ side of Algorithm 3
# ---------------------------------------------------------------------------------------
def _allgather_values(comm: MPI.Comm, local: np.ndarray) -> np.ndarray:
    """The owned interface values of every rank, concatenated in rank order (= global interface order)."""
    local = np.ascontiguousarray(local, dtype=np.float64)
    if comm.size == 1:
        return local
    counts = np.array(comm.allgather(local.size), dtype=np.int64)
    out = np.empty(int(counts.sum()))
    comm.Allgatherv(local, [out, (counts, np.concatenate([[0], np.cumsum(counts)[:-1]]))])
    return out


class Omega1Multiscale:
    """The Ω₁ side of Algorithm 3: fine operators, coarse grid, multiscale space and the online solver.

    Everything lives on a serial copy of Ω₁ (``replica.SerialReplica``), the same on every rank;
    the offline local problems are shared out across the ranks of ``cm.comm``. Online, every rank
    solves the (small, dense) coarse problem itself: ``solve`` gathers the owned Robin data of all
    ranks (one Allgather of the γ values) and returns u₁ on every DOF of the copy;
    ``interface_values`` gives back this rank's owned γ values.
    """

    def __init__(
        self,
        cm: ContactMesh,
        model: ContactProblem,
        parts: tuple[Part, Part],
        interface: InterfaceSpace,
        alpha: np.ndarray,
        *,
        cem: CEMOptions,
        cache_dir: str | Path | None = None,
    ) -> None:
        t0 = time.perf_counter()
        comm = cm.comm
        self.comm = comm
        part = parts[0]
        self.interface = interface
        tdim = part.mesh.topology.dim
        imap = part.mesh.topology.index_map(tdim)
        sub_cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
        parent_cells = np.asarray(part.cell_map.sub_topology_to_topology(sub_cells, False), dtype=np.int64)
        coarse = np.asarray(cm.coarse_cell)[parent_cells]
        if cm.H is None and comm.allreduce(int(np.any(coarse >= 0)), op=MPI.MAX) == 0:
            raise InputError(
                "the mesh has no coarse grid (ContactMesh.H is None and no coarse partition): build it with "
                "geometry.unit_square(n, n_coarse), or give read_mesh H or a mesh with a coarse partition"
            )
        self.replica = SerialReplica(part.mesh, part.facet_tags, interface.spaces[0], {"coarse": coarse})
        self.mesh = self.replica.mesh
        self.facet_tags = self.replica.facet_tags
        self.V = self.replica.V
        self.fields = material_fields(self.mesh, model)
        self.grid = grid_from_cells(self.mesh.geometry.dofmaps[0], self.mesh.geometry.x,
                                    self.replica.cell_data["coarse"], cm.H)
        # global interface value index (rank order) of every γ DOF of the copy
        self._n_local = interface.size
        self._offset = comm.exscan(self._n_local) or 0
        self._n_total = comm.allreduce(self._n_local, op=MPI.SUM)
        probe = fem.Function(interface.spaces[0])
        interface.to_part(self._offset + np.arange(1, self._n_local + 1, dtype=np.float64), 0, probe)
        index = np.rint(self.replica.gather(probe)).astype(np.int64) - 1
        self.alpha_fn = fem.Function(self.V, name="alpha")
        on = np.flatnonzero(index >= 0)
        self.alpha_fn.x.array[on] = _allgather_values(comm, alpha)[index[on]]
        self.ops = assemble_fine_operators(
            self.V, self.facet_tags, self.fields, self.alpha_fn, self.grid, s_factor=cem.s_factor,
            load=omega1_load(self.V, self.facet_tags, self.fields), displacement=self.fields.boundary.displacement,
        )
        value_of_dof = index[self.ops.gamma]
        if np.any(value_of_dof < 0) or np.unique(value_of_dof).size != self._n_total or \
                self.ops.gamma.size != self._n_total:
            raise InputError("the Ω₁ γ DOFs do not match the interface DOFs one to one")
        self.value_of_dof = value_of_dof  #: global interface index of each ops.gamma DOF
        self.gamma_of_value = np.empty(self._n_total, dtype=np.int64)  #: position in ops.gamma of each value
        self.gamma_of_value[value_of_dof] = np.arange(self.ops.gamma.size)
        self._mine = self.gamma_of_value[self._offset:self._offset + self._n_local]
        t_assembly = time.perf_counter() - t0
        self.space, self.cache_status = offline_stage(
            self.ops, self.grid, cem, h=cm.h, cache_dir=cache_dir, comm=comm
        )
        self.solver = MultiscaleRobinSolver(self.ops, self.space, self.grid, comm=comm)
        self.nu_max = float(np.max(self.fields.nu.x.array, initial=0.0))  #: largest ν in Ω₁
        warn_if_few_layers(cem.layers, "primal CEM (Algorithm 3)", comm)
        if self.nu_max > NEARLY_INCOMPRESSIBLE and comm.rank == 0:
            log.warning(
                "primal CEM with ν up to %.4g in Ω₁ (Λ·c = %.2f, Λ the smallest local eigenvalue left out): the "
                "bases localize slowly as ν → ½ and the Ω₁ error at m = %d layers may be large (model 3 at E 1e6, "
                "h = 1/64, H = 1/16, m = 4: energy error 3.2e-3 at ν = 0.4, 2.9e-2 at 0.45, 0.30 at 0.48, 0.51 at "
                "0.49; P1 itself locks as ν → ½). Check against the fine solution (CLI: --reference); more layers "
                "help up to ν ≈ 0.48 (8.9e-2 "
                "at m = 5, 1.7e-2 at m = 6), not at ν = 0.499 (0.79 at m = 6); --method mixed-ms is robust in ν.",
                self.nu_max, self.spectral_gap * cem.s_factor, cem.layers,
            )
        self.times = {
            "assembly": t_assembly,
            "eigen": self.space.times.get("eigen", 0.0),
            "patches": self.space.times.get("patches", 0.0),
            "cache_load": self.space.times.get("load", 0.0),
            "coarse": self.solver.time_s,
        }

    @property
    def spectral_gap(self) -> float:
        """Λ = min over the coarse cells of the first local eigenvalue left out (inf when all are kept)."""
        return self.space.aux.spectral_gap

    @property
    def nbasis_range(self) -> tuple[int, int]:
        """(least, most) local modes kept on a coarse cell."""
        counts = np.diff(self.space.aux.offsets)
        return int(counts.min()), int(counts.max())

    @property
    def num_coarse_dofs(self) -> int:
        """dim V_ms."""
        return self.space.size

    @property
    def num_fine_dofs(self) -> int:
        """Scalar DOFs of the fine Ω₁ P1 space (Γ_D included, as PrimalSubproblem.num_dofs counts them)."""
        return self.ops.size

    def solve(self, g12: np.ndarray) -> np.ndarray:
        """u₁ on every DOF of the Ω₁ copy for Robin data g₁₂ (this rank's owned values, InterfaceSpace
        ordering; collective)."""
        return self.solver.field(self.coordinates(g12))

    def interface_values(self, u1: np.ndarray) -> np.ndarray:
        """u₁ at this rank's owned interface DOFs, in InterfaceSpace ordering."""
        return u1[self.ops.gamma[self._mine]]

    # -- online in coarse coordinates: u₁ = Z s, Z = [Ψ, N, N_f], s = (w, g, 1) ----------------------
    def coordinates(self, g12: np.ndarray) -> np.ndarray:
        """s with u₁ = Z s for Robin data g₁₂ (owned values; collective: one Allgather of the γ values).

        Costs one dense coarse solve; nothing of fine-mesh size.
        """
        g = _allgather_values(self.comm, g12)[self.value_of_dof]
        return self.solver.coordinates(g)

    def field(self, s: np.ndarray) -> np.ndarray:
        """u₁ = Z s on every DOF of the Ω₁ copy."""
        return self.solver.field(s)

    def trace(self, s: np.ndarray) -> np.ndarray:
        """u₁ = Z s at this rank's owned interface DOFs (InterfaceSpace ordering)."""
        return self.solver.Zg[self._mine] @ s

    def coordinate_norms2(self, s: np.ndarray) -> tuple[float, float]:
        """(a₁(Zs, Zs), ‖Zs‖²_L²) from the Gram matrices (s may be a difference of coordinates)."""
        return float(s @ (self.solver.GK @ s)), float(s @ (self.solver.GM @ s))

    def reference_terms(self, r1: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(ZᵀK r, ZᵀM r, a₁(r, r), ‖r‖²) of a fine Ω₁ field r, for ``error_norms2``."""
        Kr, Mr = self.ops.K @ r1, self.ops.M @ r1
        space = self.space
        n_ms, ng = space.size, space.n_gamma
        zk, zm = np.zeros(n_ms + ng + 1), np.zeros(n_ms + ng + 1)
        for parts, shift in ((space.basis, 0), (space.correction, n_ms)):
            for p in parts:
                zk[shift + p.columns] += p.values.T @ Kr[p.dofs]
                zm[shift + p.columns] += p.values.T @ Mr[p.dofs]
        if space.Nf is not None:
            zk[-1], zm[-1] = space.Nf @ Kr, space.Nf @ Mr
        return zk, zm, float(Kr @ r1), float(Mr @ r1)

    def error_norms2(self, s: np.ndarray, terms: tuple) -> tuple[float, float]:
        """(a₁(Zs − r, Zs − r), ‖Zs − r‖²) for ``terms = reference_terms(r)``."""
        zk, zm, rk, rm = terms
        ek, em = self.coordinate_norms2(s)
        return max(ek - 2.0 * (s @ zk) + rk, 0.0), max(em - 2.0 * (s @ zm) + rm, 0.0)

    def response(self) -> tuple[np.ndarray, np.ndarray]:
        """The affine interface map of Ω₁, u₁|γ = R g₁₂ + r₀.

        Rows: this rank's owned interface values (InterfaceSpace ordering); columns: the interface
        values of all ranks in rank order (serially: R is square, n_γ × n_γ, dense).
        ``interface_values(solve(g))`` equals ``R @ g_all + r0`` to round-off.
        """
        R, r0 = self.solver.response()
        return R[np.ix_(self._mine, self.gamma_of_value)], r0[self._mine]

    def from_parent(self, u: fem.Function) -> np.ndarray:
        """A parent-mesh P1 function restricted to Ω₁, as values on the copy (collective)."""
        sub = fem.Function(self.interface.spaces[0])
        self.interface.transfers[0].to_sub(u, sub)
        return self.replica.gather(sub)

    def to_part(self, u1: np.ndarray, out: fem.Function) -> None:
        """out (P1 on the distributed Ω₁ submesh) ← u₁ given on the copy."""
        self.replica.scatter(u1, out)

    def energy_norm2(self, w: np.ndarray) -> float:
        """a₁(w, w) (the same on every rank)."""
        return float(self.ops.K.dot(w).dot(w))

    def l2_norm2(self, w: np.ndarray) -> float:
        """‖w‖²_L²(Ω₁) (the same on every rank)."""
        return float(self.ops.M.dot(w).dot(w))


def build_omega1_multiscale(
    cm: ContactMesh,
    model: ContactProblem,
    *,
    alpha: float | str = "E",
    cem: CEMOptions = CEMOptions(),
    cache_dir: str | Path | None = None,
) -> tuple[Omega1Multiscale, InterfaceSpace, np.ndarray]:
    """The Ω₁ multiscale solver on its own (for linear Robin problems and tests): (Ω₁ solver, interface, α)."""
    parts = split_mesh(cm)
    interface = InterfaceSpace(cm, parts, shape=(cm.mesh.geometry.dim,))
    alpha_values = robin_coefficient(alpha, material_fields(cm.mesh, model).E, interface, cm.h)
    omega1 = Omega1Multiscale(cm, model, parts, interface, alpha_values, cem=cem, cache_dir=cache_dir)
    return omega1, interface, alpha_values
