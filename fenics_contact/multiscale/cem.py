"""CEM-GMsFEM in Ω₁: coarse grid, local spectral problems (SLEPc), relaxed CEM bases, Robin correction.

Notation (METHOD §3, Algorithm 3). K_i are the coarse squares of side H inside
Ω₁, K_{i,m} the patch of K_i extended by m coarse layers, κ̃ = (λ + 2μ) H⁻²,

    s_i(w, v) = ∫_{K_i} κ̃ w·v dx,   s = Σ_i s_i,
    a_i(φ, v) + α ∫_{γ∩∂K_i} φ·v ds = λ s_i(φ, v)            (local spectral problem)
    a(ψ, v) + α ∫_γ ψ·v ds + s(πψ, πv) = s(φ_j^i, πv)        (relaxed CEM basis on K_{i,m})
    a(N_i g, v) + α ∫_γ N_i g·v ds + s(πN_i g, πv) = ∫_{γ∩∂K_i} g·v ds   (Robin correction)

where π is the s-orthogonal projection onto V_aux = ⊕ span{φ_j^i}. Interface
integrals use vertex quadrature, as everywhere in the package.

Implementation: every operator is assembled once on the Ω₁ P1 space with
DOLFINx (serially) and converted to SciPy. Cellwise matrices (a_i, s_i and the
γ-mass of K_i) come from a four-colouring of the coarse grid: coarse cells of
one colour ((i mod 2, j mod 2)) share no fine node, so the restriction of the
colour-c matrix to the nodes of K_i is exactly the matrix of K_i. Patch problems
need no extra assembly: the rows of the global Ω₁ matrix at the interior nodes
of a patch only see cells of that patch. Each local problem is therefore an
independent small sparse problem (a restricted DOF set), ready to be
distributed later; this module runs it serially and refuses communicators with
more than one rank.

The s(π·, π·) term is low rank: with B the matrix whose columns are s_k(·, φ_j^k)
(B = S_k Φ_k blockwise), s(πu, πv) = vᵀ B Bᵀ u, so each patch matrix is
A_II + B_I B_Iᵀ, a sparse matrix factorized with SuperLU.

Offline data (the aux functions, the bases Ψ and the correction N) can be cached
on disk (npz) under a key hashing everything they depend on; a cache file whose
stored key or checksum does not match is rebuilt, never used.
"""

import hashlib
import json
import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from slepc4py import SLEPc

from dolfinx import fem, la
from dolfinx import mesh as dmesh

from fenics_contact import __version__
from fenics_contact.fem import forms_primal
from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.fem.linalg import assemble_scipy, scipy_to_petsc
from fenics_contact.hybrid.transmission import InterfaceSpace, Part, robin_coefficient, split_mesh
from fenics_contact.multiscale.cache import OfflineCache, hash_array
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.models import TestModel
from fenics_contact.problem.tags import Boundary

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
CACHE_FORMAT = 1

_EIGENSOLVERS = ("auto", "krylovschur", "lapack")


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
    """

    layers: int = 3
    nbasis: int | None = 3
    threshold: float | None = None
    eigensolver: str = "auto"
    eig_tol: float = 1.0e-12
    target: float = -1.0
    s_factor: float = DEFAULT_S_FACTOR

    def __post_init__(self) -> None:
        if not (np.isfinite(self.s_factor) and self.s_factor > 0):
            raise InputError(f"s_factor must be finite and > 0, got {self.s_factor!r}")
        if int(self.layers) != self.layers or self.layers < 0:
            raise InputError(f"the number of oversampling layers must be an integer >= 0, got {self.layers!r}")
        if self.nbasis is not None and (int(self.nbasis) != self.nbasis or self.nbasis < 1):
            raise InputError(f"nbasis must be an integer >= 1 (or None for all modes), got {self.nbasis!r}")
        if self.threshold is not None and not (np.isfinite(self.threshold) and self.threshold > 0):
            raise InputError(f"the eigenvalue threshold must be finite and > 0, got {self.threshold!r}")
        if self.eigensolver not in _EIGENSOLVERS:
            raise InputError(f"unknown eigensolver {self.eigensolver!r}; choose one of {_EIGENSOLVERS}")
        if not (0 < self.eig_tol < 1e-2):
            raise InputError(f"eig_tol must lie in (0, 1e-2), got {self.eig_tol}")
        if not self.target < 0:
            raise InputError(f"the shift-and-invert target must be < 0 (A is only semi-definite), got {self.target}")


def require_serial(comm: MPI.Comm) -> None:
    """Raise InputError on a communicator with more than one rank (the offline stage is serial)."""
    if comm.size > 1:
        raise InputError(
            f"the CEM-GMsFEM offline stage runs serially on the Ω₁ mesh; got a communicator with {comm.size} "
            "ranks. Run Algorithm 3 with one MPI process (the local problems are independent and could be "
            "distributed, but that is not implemented)."
        )


# ---------------------------------------------------------------------------------------
# coarse grid
# ---------------------------------------------------------------------------------------
class CoarseGrid(NamedTuple):
    """The coarse squares K_k of Ω₁: grid position (i, j), fine cells, colour (i mod 2) + 2 (j mod 2)."""

    n_coarse: int  #: 1/H
    H: float
    ij: np.ndarray  #: (n_K, 2) grid position of each coarse cell of Ω₁ (local numbering k)
    global_index: np.ndarray  #: (n_K,) index i + n_coarse·j in ContactMesh.coarse_cell
    cell_coarse: np.ndarray  #: (num fine cells,) local coarse number k of each fine Ω₁ cell
    cells: tuple  #: fine cells of each K_k (Ω₁ submesh numbering)

    @property
    def size(self) -> int:
        """Number of coarse cells in Ω₁."""
        return self.ij.shape[0]

    @property
    def colors(self) -> np.ndarray:
        """Colour of each coarse cell: no two cells of one colour share a fine node."""
        return (self.ij[:, 0] % 2) + 2 * (self.ij[:, 1] % 2)

    def patch(self, k: int, layers: int) -> np.ndarray:
        """Coarse cells of K_{k,m}: |i' − i| ≤ m and |j' − j| ≤ m (inside Ω₁)."""
        d = np.abs(self.ij - self.ij[k])
        return np.flatnonzero((d[:, 0] <= layers) & (d[:, 1] <= layers))


def coarse_grid(msh: dmesh.Mesh, cell_map: dmesh.EntityMap, coarse_cell: np.ndarray, H: float | None) -> CoarseGrid:
    """Coarse grid of a submesh from the parent's ``coarse_cell`` (ContactMesh) via the submesh cell map."""
    if H is None:
        raise InputError("the mesh has no coarse grid (ContactMesh.H is None); build it with geometry.unit_square")
    tdim = msh.topology.dim
    imap = msh.topology.index_map(tdim)
    sub_cells = np.arange(imap.size_local + imap.num_ghosts, dtype=np.int32)
    parent = np.asarray(cell_map.sub_topology_to_topology(sub_cells, False), dtype=np.int64)
    index = np.asarray(coarse_cell)[parent]
    if np.any(index < 0):
        raise InputError("some Ω₁ cells lie in no coarse cell (coarse_cell = -1)")
    n_coarse = round(1.0 / H)
    global_index, cell_coarse = np.unique(index, return_inverse=True)
    ij = np.stack([global_index % n_coarse, global_index // n_coarse], axis=1)
    order = np.argsort(cell_coarse, kind="stable")
    splits = np.cumsum(np.bincount(cell_coarse, minlength=global_index.size))[:-1]
    cells = tuple(np.split(order.astype(np.int32), splits))
    return CoarseGrid(n_coarse, float(H), ij, global_index, cell_coarse.astype(np.int32), cells)


# ---------------------------------------------------------------------------------------
# fine-scale operators on Ω₁
# ---------------------------------------------------------------------------------------
def kappa_tilde(lmbda, mu, H: float, factor: float = 1.0):
    """κ̃ = factor · (λ + 2μ) H⁻²."""
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

    K: a(u, v); R: α∫_γ u·v; A = K + R; M: (u, v); S: s(u, v); G: ∫_γ u·v (vertex quadrature);
    Kc/Sc/Gc: the same restricted to the cells of one colour (index = colour), Ac = Kc + α Gc; F: (f, v).
    """

    V: fem.FunctionSpace
    K: sp.csr_matrix
    R: sp.csr_matrix
    A: sp.csr_matrix
    M: sp.csr_matrix
    S: sp.csr_matrix
    G: sp.csr_matrix
    Kc: list
    Sc: list
    Gc: list
    Ac: list
    F: np.ndarray
    free: np.ndarray  #: bool, scalar DOF not on Γ_D
    gamma: np.ndarray  #: scalar DOFs on γ (sorted), the columns of N
    alpha: np.ndarray  #: nodal α at every scalar DOF (zero off γ)
    node_dofs: np.ndarray  #: (num nodes, bs) scalar DOFs of each node
    cell_nodes: np.ndarray  #: (num cells, 3) nodes of each cell
    key_data: dict = field(default_factory=dict)  #: arrays the offline data depend on (for the cache key)

    @property
    def size(self) -> int:
        """Number of scalar DOFs of the Ω₁ space (Γ_D included)."""
        return self.K.shape[0]


def assemble_fine_operators(
    V: fem.FunctionSpace,
    facet_tags: dmesh.MeshTags,
    fields: MaterialFields,
    alpha: fem.Function,
    grid: CoarseGrid,
    *,
    s_factor: float = 1.0,
) -> FineOperators:
    """Assemble every Ω₁ matrix the CEM construction needs (serial; colour-restricted copies included)."""
    msh = V.mesh
    require_serial(msh.comm)
    tdim = msh.topology.dim
    bs = V.dofmap.index_map_bs
    u, v = ufl.TrialFunction(V), ufl.TestFunction(V)
    ds = forms_primal.vertex_measure(msh, facet_tags)(Boundary.INTERFACE)
    Q0 = fields.E.function_space
    kap = kappa_tilde(fields.lmbda, fields.mu, grid.H, s_factor)
    cell_dof0 = Q0.dofmap.list[:, 0]
    Kc, Sc, Gc = [], [], []
    for c in range(4):
        chi = fem.Function(Q0, name=f"chi{c}")
        chi.x.array[cell_dof0] = (grid.colors[grid.cell_coarse] == c).astype(np.float64)
        Kc.append(assemble_scipy(forms_primal.elastic_form(u, v, chi * fields.lmbda, chi * fields.mu)))
        Sc.append(assemble_scipy(cem_mass_form(u, v, chi * kap)))
        Gc.append(assemble_scipy(interface_mass_form(u, v, chi, ds)))
    K = sum(Kc[1:], Kc[0]).tocsr()
    S = sum(Sc[1:], Sc[0]).tocsr()
    G = sum(Gc[1:], Gc[0]).tocsr()
    a = alpha.x.array.copy()
    R = (sp.diags(a) @ G).tocsr()
    M = assemble_scipy(forms_primal.mass_form(u, v))
    F_vec = fem.assemble_vector(fem.form(ufl.inner(fields.f, v) * ufl.dx))
    F_vec.scatter_reverse(la.InsertMode.add)
    F = F_vec.array.copy()

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
        "free": free,
    }
    Ac = [(Kc[c] + sp.diags(a) @ Gc[c]).tocsr() for c in range(4)]
    return FineOperators(V, K, R, (K + R).tocsr(), M, S, G, Kc, Sc, Gc, Ac, F, free, gamma, a, node_dofs,
                         cell_nodes, key_data)


# ---------------------------------------------------------------------------------------
# local spectral problems
# ---------------------------------------------------------------------------------------
#: Extra eigenpairs requested from Krylov–Schur beyond the wanted ones (a margin for multiplicities).
_EXTRA_PAIRS = 3
#: Relative gap above the last wanted eigenvalue at which the inertia count is taken.
_INERTIA_GAP = 1.0e-6


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
                raise ConvergenceError(f"local spectral problem (n = {n}): could not find all {nev} smallest pairs")
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


def _cell_dofs(ops: FineOperators, grid: CoarseGrid, k: int) -> np.ndarray:
    nodes = np.unique(ops.cell_nodes[grid.cells[k]])
    dofs = ops.node_dofs[nodes].ravel()
    return dofs[ops.free[dofs]]


def local_matrices(ops: FineOperators, grid: CoarseGrid, k: int) -> tuple[np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """D_k and the matrices of a_k(·,·) + α∫_{γ∩∂K_k} and s_k on it (colour restriction)."""
    c = int(grid.colors[k])
    D = _cell_dofs(ops, grid, k)
    return D, ops.Ac[c][D][:, D].tocsr(), ops.Sc[c][D][:, D].tocsr()


def build_auxiliary_space(ops: FineOperators, grid: CoarseGrid, options: CEMOptions) -> AuxiliarySpace:
    """Solve every local spectral problem and keep l_k s-normalized eigenfunctions per coarse cell."""
    dofs, values, vectors, blocks = [], [], [], []
    for k in range(grid.size):
        D, A, S = local_matrices(ops, grid, k)
        lam, Phi = local_spectral_problem(
            A, S, options.nbasis, eigensolver=options.eigensolver, target=options.target, tol=options.eig_tol
        )
        if options.threshold is not None:
            keep = max(1, int(np.count_nonzero(lam <= options.threshold)))
            lam, Phi = lam[:keep], Phi[:, :keep]
        dofs.append(D)
        values.append(lam)
        vectors.append(Phi)
        blocks.append(S @ Phi)
    return _aux_from_parts(ops.size, dofs, values, vectors, blocks)


def _aux_from_parts(n: int, dofs, values, vectors, blocks) -> AuxiliarySpace:
    offsets = np.concatenate([[0], np.cumsum([Phi.shape[1] for Phi in vectors])]).astype(np.int64)
    rows = np.concatenate([np.repeat(D, b.shape[1]) for D, b in zip(dofs, blocks)])
    cols = np.concatenate(
        [np.tile(np.arange(offsets[k], offsets[k + 1]), len(D)) for k, D in enumerate(dofs)]
    )
    data = np.concatenate([b.ravel() for b in blocks])
    B = sp.csr_matrix((data, (rows, cols)), shape=(n, int(offsets[-1])))
    return AuxiliarySpace(list(dofs), list(values), list(vectors), B, offsets)


# ---------------------------------------------------------------------------------------
# relaxed CEM bases and Robin correction
# ---------------------------------------------------------------------------------------
@dataclass(slots=True)
class MultiscaleSpace:
    """V_ms = span{ψ_j^i} (columns of Psi) and the Robin-data correction N (γ DOF values → Ω₁ field)."""

    aux: AuxiliarySpace
    Psi: sp.csc_matrix  #: n × n_ms
    N: sp.csc_matrix  #: n × |gamma|
    layers: int
    times: dict = field(default_factory=dict)

    @property
    def size(self) -> int:
        """dim V_ms."""
        return self.Psi.shape[1]


class _NodeCoarse:
    """For every fine node, the coarse cells containing it (padded with −1)."""

    def __init__(self, ops: FineOperators, grid: CoarseGrid) -> None:
        num_nodes = ops.node_dofs.shape[0]
        pairs = np.unique(
            np.stack([ops.cell_nodes.ravel(), np.repeat(grid.cell_coarse, ops.cell_nodes.shape[1])], axis=1), axis=0
        )
        counts = np.bincount(pairs[:, 0], minlength=num_nodes)
        width = int(counts.max())
        table = np.full((num_nodes, width), -1, dtype=np.int64)
        start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        slot = np.arange(pairs.shape[0]) - start[pairs[:, 0]]
        table[pairs[:, 0], slot] = pairs[:, 1]
        self.table = table
        self.nodes_of = [np.unique(ops.cell_nodes[c]) for c in grid.cells]

    def interior_nodes(self, patch: np.ndarray, num_coarse: int) -> np.ndarray:
        """Nodes all of whose coarse cells are in the patch (so every cell touching them is)."""
        member = np.zeros(num_coarse + 1, dtype=bool)
        member[patch] = True
        member[-1] = True  # padding (−1 indexes the last entry)
        nodes = np.unique(np.concatenate([self.nodes_of[k] for k in patch]))
        inside = np.all(member[self.table[nodes]], axis=1)
        return nodes[inside]


def build_multiscale_space(
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, aux: AuxiliarySpace | None = None
) -> MultiscaleSpace:
    """Offline stage: aux space, relaxed CEM bases on K_{i,m} and the correction N (sparse, exact zeros outside)."""
    times = {}
    t0 = time.perf_counter()
    if aux is None:
        aux = build_auxiliary_space(ops, grid, options)
    times["eigen"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    node_coarse = _NodeCoarse(ops, grid)
    A = ops.A.tocsr()
    B = aux.B.tocsr()
    gamma_pos = np.full(ops.size, -1, dtype=np.int64)
    gamma_pos[ops.gamma] = np.arange(ops.gamma.size)
    psi_rows, psi_cols, psi_vals = [], [], []
    n_rows, n_cols, n_vals = [], [], []
    t_basis = t_corr = 0.0
    for i in range(grid.size):
        ts = time.perf_counter()
        patch = grid.patch(i, options.layers)
        nodes = node_coarse.interior_nodes(patch, grid.size)
        inner = ops.node_dofs[nodes].ravel()
        inner = inner[ops.free[inner]]
        cols = np.concatenate([aux.columns(k) for k in patch])
        BI = B[inner][:, cols]
        lu = spla.splu((A[inner][:, inner] + BI @ BI.T).tocsc(), permc_spec="MMD_AT_PLUS_A")  # SPD: symmetric ordering
        rhs = B[inner][:, aux.columns(i)].toarray()
        psi = lu.solve(rhs)
        psi_rows.append(np.repeat(inner, psi.shape[1]))
        psi_cols.append(np.tile(aux.columns(i), inner.size))
        psi_vals.append(psi.ravel())
        t_basis += time.perf_counter() - ts
        # Robin correction: only coarse cells whose boundary meets γ contribute.
        ts = time.perf_counter()
        c = int(grid.colors[i])
        D_all = ops.node_dofs[node_coarse.nodes_of[i]].ravel()
        Gi = ops.Gc[c][D_all][:, D_all]
        on_gamma = D_all[np.flatnonzero(Gi.diagonal() > 0)]
        if on_gamma.size:
            rhs_g = ops.Gc[c][inner][:, on_gamma].toarray()
            used = np.flatnonzero(np.any(rhs_g != 0.0, axis=0))
            if used.size:
                corr = lu.solve(rhs_g[:, used])
                n_rows.append(np.repeat(inner, used.size))
                n_cols.append(np.tile(gamma_pos[on_gamma[used]], inner.size))
                n_vals.append(corr.ravel())
        t_corr += time.perf_counter() - ts
    n_ms = aux.size
    Psi = sp.csc_matrix(
        (np.concatenate(psi_vals), (np.concatenate(psi_rows), np.concatenate(psi_cols))), shape=(ops.size, n_ms)
    )
    if n_rows:
        N = sp.csc_matrix(
            (np.concatenate(n_vals), (np.concatenate(n_rows), np.concatenate(n_cols))),
            shape=(ops.size, ops.gamma.size),
        )
    else:
        N = sp.csc_matrix((ops.size, ops.gamma.size))
    times["basis"] = t_basis
    times["correction"] = t_corr
    times["total"] = times["eigen"] + time.perf_counter() - t0
    log.info(
        "CEM offline: %d coarse cells, m = %d, dim V_aux = %d, dim V_ms = %d; eigen %.2f s, bases %.2f s, "
        "correction %.2f s", grid.size, options.layers, aux.size, n_ms, times["eigen"], t_basis, t_corr,
    )
    return MultiscaleSpace(aux, Psi, N, int(options.layers), times)


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


class MultiscaleRobinSolver:
    """The Ω₁ step of Algorithm 3: w ∈ V_ms with a₁(w,v) + α∫_γ w·v = (f,v) + ∫_γ g·v − [a₁(Ng,v) + α∫_γ Ng·v],
    then u₁ = w + N g; the coarse matrix ΨᵀAΨ is factorized once (offline)."""

    def __init__(self, ops: FineOperators, space: MultiscaleSpace) -> None:
        t0 = time.perf_counter()
        self.ops = ops
        self.space = space
        Psi = space.Psi.tocsc()
        APsi = (ops.A @ Psi).tocsc()
        self.A_ms = (Psi.T @ APsi).toarray()
        self.factor = CoarseFactor(self.A_ms)
        self.b_f = Psi.T @ ops.F
        # Ψᵀ (G[:, γ] − A N): the action of the interface data on the coarse right-hand side
        self.C = (Psi.T @ (ops.G[:, ops.gamma] - ops.A @ space.N)).toarray() if ops.gamma.size else None
        self.time_s = time.perf_counter() - t0

    @property
    def size(self) -> int:
        return self.space.size

    def solve(self, g: np.ndarray) -> np.ndarray:
        """u₁ (all scalar Ω₁ DOFs) for nodal Robin data g on ``ops.gamma``."""
        rhs = self.b_f + self.C @ g
        w = self.factor.solve(rhs)
        return self.space.Psi @ w + self.space.N @ g


# ---------------------------------------------------------------------------------------
# offline cache
# ---------------------------------------------------------------------------------------
def offline_key(ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, h: float) -> str:
    """sha256 of everything the offline data depend on: mesh, coarse grid, E, ν, α, options, package version."""
    hasher = hashlib.sha256()
    meta = {
        "format": CACHE_FORMAT,
        "version": __version__,
        "h": repr(float(h)),
        "n_coarse": grid.n_coarse,
        "H": repr(float(grid.H)),
        "options": {
            "layers": options.layers,
            "nbasis": options.nbasis,
            "threshold": options.threshold,
            "eigensolver": options.eigensolver,
            "eig_tol": options.eig_tol,
            "target": options.target,
            "s_factor": options.s_factor,
        },
    }
    hasher.update(json.dumps(meta, sort_keys=True).encode())
    for name in sorted(ops.key_data):
        hasher.update(name.encode())
        hash_array(hasher, ops.key_data[name])
    return hasher.hexdigest()


def _pack(space: MultiscaleSpace) -> dict:
    aux = space.aux
    out = {
        "aux_offsets": aux.offsets,
        "aux_dof_offsets": np.concatenate([[0], np.cumsum([d.size for d in aux.dofs])]).astype(np.int64),
        "aux_dofs": np.concatenate(aux.dofs).astype(np.int64),
        "aux_values": np.concatenate(aux.eigenvalues),
        "aux_vectors": np.concatenate([Phi.ravel() for Phi in aux.vectors]),
        "layers": np.array(space.layers),
    }
    for name, M in (("Psi", space.Psi.tocsc()), ("N", space.N.tocsc())):
        out[f"{name}_data"], out[f"{name}_indices"], out[f"{name}_indptr"] = M.data, M.indices, M.indptr
        out[f"{name}_shape"] = np.array(M.shape)
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
        c = int(grid.colors[k])
        S = ops.Sc[c][D][:, D]
        dofs.append(D)
        values.append(arrays["aux_values"][offs[k]:offs[k + 1]])
        vectors.append(Phi)
        blocks.append(S @ Phi)
    aux = _aux_from_parts(ops.size, dofs, values, vectors, blocks)
    mats = {}
    for name in ("Psi", "N"):
        mats[name] = sp.csc_matrix(
            (arrays[f"{name}_data"], arrays[f"{name}_indices"], arrays[f"{name}_indptr"]),
            shape=tuple(int(s) for s in arrays[f"{name}_shape"]),
        )
    return MultiscaleSpace(aux, mats["Psi"], mats["N"], int(arrays["layers"]), {"eigen": 0.0, "basis": 0.0,
                                                                              "correction": 0.0, "total": 0.0})


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
    ops: FineOperators, grid: CoarseGrid, options: CEMOptions, *, h: float, cache_dir: str | Path | None = None
) -> tuple[MultiscaleSpace, str]:
    """Build (or load from the cache) the multiscale space; returns (space, cache status)."""
    if cache_dir is None:
        return build_multiscale_space(ops, grid, options), "disabled"
    cache = PrimalOfflineCache(cache_dir)
    key = offline_key(ops, grid, options, h=h)
    t0 = time.perf_counter()
    space, status = cache.load(key, ops, grid)
    if space is not None:
        space.times["load"] = time.perf_counter() - t0
        log.info("CEM offline data loaded from %s", cache.path(key))
        return space, status
    if status != "missing":
        log.warning("CEM offline cache %s rejected (%s); rebuilding", cache.path(key), status)
    cache.check_writable()  # before the expensive build, not after it
    space = build_multiscale_space(ops, grid, options)
    try:
        cache.save(key, space)
    except OSError as err:  # the directory went away or filled up meanwhile: keep the built data
        log.warning("CEM offline data could not be saved to %s: %s", cache.path(key), err)
    return space, "built" if status == "missing" else "rebuilt"


# ---------------------------------------------------------------------------------------
# the Ω₁ side of Algorithm 3
# ---------------------------------------------------------------------------------------
class Omega1Multiscale:
    """The Ω₁ side of Algorithm 3: fine operators, coarse grid, multiscale space and the online solver."""

    def __init__(
        self,
        cm: ContactMesh,
        model: TestModel,
        parts: tuple[Part, Part],
        interface: InterfaceSpace,
        alpha: np.ndarray,
        *,
        cem: CEMOptions,
        cache_dir: str | Path | None = None,
    ) -> None:
        require_serial(cm.comm)
        t0 = time.perf_counter()
        part_index = 0
        part = parts[part_index]
        self.mesh = part.mesh
        self.facet_tags = part.facet_tags
        self.V = interface.spaces[part_index]
        self.alpha_fn = fem.Function(self.V, name="alpha")
        interface.to_part(alpha, part_index, self.alpha_fn)
        self.fields = material_fields(part.mesh, model)
        self.grid = coarse_grid(part.mesh, part.cell_map, cm.coarse_cell, cm.H)
        self.ops = assemble_fine_operators(
            self.V, part.facet_tags, self.fields, self.alpha_fn, self.grid, s_factor=cem.s_factor
        )
        t_assembly = time.perf_counter() - t0
        self.space, self.cache_status = offline_stage(
            self.ops, self.grid, cem, h=cm.h, cache_dir=cache_dir
        )
        self.solver = MultiscaleRobinSolver(self.ops, self.space)
        # interface value index (InterfaceSpace ordering) → position in ops.gamma
        probe = fem.Function(self.V)
        interface.to_part(np.arange(1, interface.size + 1, dtype=np.float64), part_index, probe)
        value_of_dof = np.rint(probe.x.array[self.ops.gamma]).astype(np.int64) - 1
        if np.any(value_of_dof < 0) or np.unique(value_of_dof).size != interface.size:
            raise InputError("the Ω₁ γ DOFs do not match the interface DOFs one to one")
        self.gamma_of_value = np.empty(interface.size, dtype=np.int64)
        self.gamma_of_value[value_of_dof] = np.arange(self.ops.gamma.size)
        self.times = {
            "assembly": t_assembly,
            "eigen": self.space.times.get("eigen", 0.0),
            "basis": self.space.times.get("basis", 0.0),
            "correction": self.space.times.get("correction", 0.0),
            "cache_load": self.space.times.get("load", 0.0),
            "coarse": self.solver.time_s,
        }

    @property
    def num_coarse_dofs(self) -> int:
        """dim V_ms."""
        return self.space.size

    @property
    def num_fine_dofs(self) -> int:
        """Scalar DOFs of the fine Ω₁ P1 space (Γ_D included, as PrimalSubproblem.num_dofs counts them)."""
        return self.ops.size

    def solve(self, g12: np.ndarray) -> np.ndarray:
        """u₁ on every Ω₁ DOF for Robin data g₁₂ (InterfaceSpace ordering)."""
        g = np.zeros(self.ops.gamma.size)
        g[self.gamma_of_value] = g12
        return self.solver.solve(g)

    def interface_values(self, u1: np.ndarray) -> np.ndarray:
        """u₁ at the interface DOFs, in InterfaceSpace ordering."""
        return u1[self.ops.gamma[self.gamma_of_value]]


def build_omega1_multiscale(
    cm: ContactMesh,
    model: TestModel,
    *,
    alpha: float | str = "E",
    cem: CEMOptions = CEMOptions(),
    cache_dir: str | Path | None = None,
) -> tuple[Omega1Multiscale, InterfaceSpace, np.ndarray]:
    """The Ω₁ multiscale solver on its own (for linear Robin problems and tests): (Ω₁ solver, interface, α)."""
    require_serial(cm.comm)
    parts = split_mesh(cm)
    interface = InterfaceSpace(cm, parts, shape=(cm.mesh.geometry.dim,))
    alpha_values = robin_coefficient(alpha, material_fields(cm.mesh, model).E, interface, cm.h)
    omega1 = Omega1Multiscale(cm, model, parts, interface, alpha_values, cem=cem, cache_dir=cache_dir)
    return omega1, interface, alpha_values
