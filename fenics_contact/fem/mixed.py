"""Mixed (Arnold–Winther × DG P1) penalized contact: subproblems and the monolithic solve (METHOD §2).

Find (σ_h, u_h) ∈ X_h × U_h with

    (Aσ_h, τ) + (div τ, u_h) + (1/ε) ∫_ΓC (σ_hc)⁺ τ_c ds [+ β∫_γ (σ_h n)·(τn) ds] = [∫_γ g·(τn) ds]
    (div σ_h, v) = −(f, v)

X_h: lowest-order Arnold–Winther stresses with σ_t = t·σn = 0 on Γ_C built in
(essential); U_h: discontinuous vector P1.  u = 0 on Γ_D is natural.

**Penalty.**  The natural boundary term says u_c = −(σ_c)⁺/ε on Γ_C: where the
body presses on the obstacle (σ_c ≤ 0) u_c = 0 exactly; where it separates, a
small tensile stress σ_c = ε|u_c| remains.  So the mixed penalty never lets
the body penetrate; its error is the tensile stress left in the gap.  The
default ε = 1e−3·h·E_c (E_c the largest Young's modulus on Γ_C) mirrors the
primal default δ = 1e−3·h/E_c: the tensile stress relative to the stress
scale is ε|u_c|/σ ≈ ε/E_c = 1e−3·h, far below the stress discretization error
(≥ h^{3/2} with the contact singularity).  ``MixedContactProfile.max_tensile``
reports what is left.

**Contact quadrature.**  The penalty is integrated with the 4-point
Gauss–Lobatto rule per Γ_C edge (``forms_mixed.contact_measure``).  Its nodes
(3 per edge, vertices shared) are a Lagrange basis of the σ_c trace space
(continuous P3 on Γ_C), so the penalty acts on nodal values of σ_c with a
diagonal weight, as the primal method's vertex quadrature does for u_c.  Newton
works with the sparse matrix Q of nodal values σ_c(x_q) (a DG P3 evaluation
times the prolongation P): it gives the active set, the penalty residual
(1/ε) Qᵀ W (Qσ)⁺, its generalized Jacobian (1/ε) Qᵀ W H(Qσ) Q and the energy.
The same term assembled from the UFL form ``forms_mixed.contact_penalty``
agrees to round-off (tested), and the monolithic solve ends with a check of
the residual assembled from the UFL forms.  (With 4 Gauss–Legendre points per
edge — more points than trace DOFs — full semismooth Newton steps wandered for
50+ steps at h = 1/64 and the line search crept one point per step; with the
nodal rule full steps converge in about 5.)

**Globalized semismooth Newton.**  Every Newton step (dσ, du) satisfies
(div dσ, v) = 0 once the equilibrium equation holds, so dσ is a descent
direction of the convex, piecewise quadratic complementary energy

    J(σ) = ½(Aσ, σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε) ∫_ΓC ((σ_c)⁺)² ds

on the affine set {div σ = −f}.  Full steps are taken while they lead to new
active sets; with full steps the iterate depends only on the set it was
linearized at, so a step into a set already visited closes a cycle (plain
semismooth Newton cycles here, METHOD §8).  From the first such step on, the
step length minimizes J exactly along the Newton direction (J is piecewise
quadratic in the step, with breakpoints where σ_c changes sign), so J
decreases monotonically and no cycle can recur.  The iteration ends with the
first step whose result has the active set it was linearized at (it then
solves the penalized problem exactly) and a residual check.  A cold start is
linearized at "penalty everywhere" (traction-free Γ_C): its solution is
compressive exactly where a free body would penetrate, a good first contact
set.  The Jacobian depends on the iterate only through the active set, so
factorizations (MUMPS LU of the saddle-point matrix) are cached by active set.

**Interface split.**  ``split_interface=True`` enlarges X_h by doubling σ_tt at
the vertices of γ (Ω₁ and Ω₂ keep their own tangential-tangential
stress there; the normal traction σn stays continuous).  That space X̃_h is
exactly the space of the converged iterate of Algorithm 2 (see
``hybrid.mixed``), so this monolithic solve is its exact fixed point.

Serial only (one MPI rank), like ``fem.arnold_winther``.
"""

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import ufl
from petsc4py import PETSc

import basix
import basix.ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
import dolfinx.fem.petsc

from fenics_contact.fem import forms_mixed
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace
from fenics_contact.fem.contact import ContactProfile, NewtonHistory, NewtonOptions, profile_order
from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.problem.boundary import BoundaryConditions, check_boundary_groups, neumann_groups
from fenics_contact.problem.fields import MaterialFields, material_fields
from fenics_contact.problem.obstacles import Obstacle, evaluate_obstacle
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.fem.linalg import DIRECT_OPTIONS, DirectSolver, assemble_scipy, petsc_to_scipy, scipy_to_petsc
from fenics_contact.problem.models import TestModel
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = [
    "MIXED_SOLVER_OPTIONS",
    "default_epsilon",
    "check_serial_triangles",
    "MixedContactProfile",
    "MixedNewtonHistory",
    "MixedSubproblem",
    "MixedSolution",
    "solve_mixed_monolithic",
    "contact_modulus",
    "interpolate_stress",
    "boundary_stress_space",
    "displacement_trace_function",
]

log = logging.getLogger(__name__)

#: 4-point Gauss–Lobatto rule on [0, 1] (``forms_mixed.CONTACT_QUADRATURE``).
_LOBATTO_S = np.array([0.0, 0.5 - 0.5 / np.sqrt(5.0), 0.5 + 0.5 / np.sqrt(5.0), 1.0])
_LOBATTO_W = np.array([1.0, 5.0, 5.0, 1.0]) / 12.0


#: MUMPS LU with the AMF ordering: half the factorization time of the default ordering on the
#: AW saddle-point matrices (3.8 s instead of 7.5 s at h = 1/128, 0.7 s instead of 1.3 s at 1/64).
MIXED_SOLVER_OPTIONS = {**DIRECT_OPTIONS, "mat_mumps_icntl_7": "2"}


def default_epsilon(h: float, E_contact: float, factor: float = 1.0e-3) -> float:
    """ε = factor·h·E_c: tensile stress left in the gap ≈ factor·h relative to the stress scale."""
    if not (h > 0 and E_contact > 0 and factor > 0):
        raise InputError(f"default_epsilon needs h, E_c, factor > 0; got {h}, {E_contact}, {factor}")
    return factor * h * E_contact


def check_serial_triangles(msh: dmesh.Mesh) -> None:
    """Raise InputError unless ``msh`` is a serial mesh of affine triangles (what the AW space supports)."""
    if msh.comm.size > 1:
        raise InputError(
            f"the mixed (Arnold–Winther) method runs in serial only; got {msh.comm.size} MPI ranks. "
            "Run it without mpiexec (the primal method runs in parallel)."
        )
    if msh.topology.cell_type != dmesh.CellType.triangle:
        raise InputError(f"the mixed (Arnold–Winther) method needs a triangle mesh, got {msh.topology.cell_type.name}")
    if len(msh.geometry.cmaps) != 1 or msh.geometry.cmaps[0].degree != 1:
        raise InputError("the mixed (Arnold–Winther) method needs an affine (degree 1) triangle mesh")


def contact_modulus(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, E: fem.Function) -> float:
    """Largest Young's modulus of the cells touching Γ_C."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    cells = np.unique(np.concatenate([f2c.links(f) for f in facet_tags.find(Boundary.GAMMA_C)] or [[]])).astype(
        np.int32
    )
    if cells.size == 0:
        raise InputError("the mesh has no Γ_C facets")
    return float(np.max(E.x.array[cells]))


# ---------------------------------------------------------------------------
# Contact profile and Newton history
# ---------------------------------------------------------------------------


class MixedContactProfile(ContactProfile):
    """σ_c and u_c = −(σ_c)⁺/ε along Γ_C (sorted by y) for the mixed penalty.

    The mixed penalty allows no penetration (u_c ≤ 0 everywhere); a point is in
    contact where the normal stress is compressive, σ_c < 0 (there u_c = 0).  ``max_tensile`` is the penalty error: the tensile stress left
    where the body separates (= ε·max|u_c|).
    """

    __slots__ = ()

    @property
    def active(self) -> np.ndarray:
        """Points in contact: σ_c < 0 (compressive: the penalty is inactive and u_c = g).

        (σ_c = 0 up to round-off, 1e−12 of max |σ_c|, only where an essential condition
        forces it, e.g. a Γ_C end next to a traction-free side: not contact.)
        """
        scale = float(np.max(np.abs(self.sigma_c), initial=0.0))
        return self.sigma_c < -1e-12 * scale

    @property
    def max_tensile(self) -> float:
        """max (σ_c)⁺: the tensile contact stress the penalty leaves."""
        return float(np.max(np.maximum(self.sigma_c, 0.0), initial=0.0))


@dataclass(slots=True)
class MixedNewtonHistory(NewtonHistory):
    """NewtonHistory plus the step length and complementary energy J after every Newton step.

    ``active_sizes`` counts the Γ_C contact nodes in contact (σ_c ≤ 0) after each step.
    """

    step_lengths: list[float] = field(default_factory=list)
    energies: list[float] = field(default_factory=list)


# ---------------------------------------------------------------------------
# Point evaluation of DG P3 stresses (numpy / scipy)
# ---------------------------------------------------------------------------


def _reference_coordinates(msh: dmesh.Mesh, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Reference coordinates (N, 2) of physical points x (N, 2) in affine triangles ``cells`` (N,)."""
    gx = msh.geometry.x[msh.geometry.dofmaps[0][cells]][:, :, :2]
    v0 = gx[:, 0]
    J = np.stack([gx[:, 1] - v0, gx[:, 2] - v0], axis=-1)
    return np.linalg.solve(J, (x - v0)[..., None])[..., 0]


def _csr_keys(A: sp.csr_matrix) -> np.ndarray:
    """row · ncols + column of every stored entry (ascending for a CSR matrix with sorted indices)."""
    rows = np.repeat(np.arange(A.shape[0], dtype=np.int64), np.diff(A.indptr))
    return rows * A.shape[1] + A.indices.astype(np.int64)


def _stress_evaluation(dg: fem.FunctionSpace, cells: np.ndarray, X: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Sparse E with (E s)_p = Σ_j weights[p, j] s_j(x_p) for DG P3 stress coefficients s.

    ``cells`` (N,), reference points ``X`` (N, 2), component weights (N, 3) on (σ_xx, σ_xy, σ_yy).
    """
    el = dg.ufl_element().sub_elements[0].basix_element
    phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 10): basis function k at point p
    dofs = dg.dofmap.list[cells].astype(np.int64)  # (N, 10) block indices
    npts = phi.shape[0]
    cols = 3 * dofs[:, :, None] + np.arange(3)  # (N, 10, 3)
    vals = phi[:, :, None] * weights[:, None, :]
    rows = np.broadcast_to(np.arange(npts)[:, None, None], cols.shape)
    n_dg = 3 * dg.dofmap.index_map.size_local
    E = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(npts, n_dg))
    E.eliminate_zeros()
    return E


def _normal_weights(n: np.ndarray) -> np.ndarray:
    """Weights (N, 3) giving n·σn from (σ_xx, σ_xy, σ_yy)."""
    return np.stack([n[:, 0] ** 2, 2.0 * n[:, 0] * n[:, 1], n[:, 1] ** 2], axis=1)


def _traction_weights(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights (N, 3) giving the x and y components of σn."""
    zero = np.zeros(n.shape[0])
    return np.stack([n[:, 0], n[:, 1], zero], axis=1), np.stack([zero, n[:, 0], n[:, 1]], axis=1)


class _BoundaryFacets:
    """Exterior facets of one tag: cells, end points, outward unit normals."""

    def __init__(self, msh: dmesh.Mesh, facets: np.ndarray) -> None:
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        self.facets = np.asarray(facets, dtype=np.int32)
        self.cells = np.array([f2c.links(f)[0] for f in self.facets], dtype=np.int32)
        if any(len(f2c.links(f)) != 1 for f in self.facets):
            raise InputError("a boundary-tagged facet is not on the boundary of the (sub)mesh")
        geo = dmesh.entities_to_geometry(msh, tdim - 1, self.facets)
        x = msh.geometry.x[:, :2]
        self.a, self.b = x[geo[:, 0]], x[geo[:, 1]]
        d = self.b - self.a
        self.length = np.linalg.norm(d, axis=1)
        n = np.stack([d[:, 1], -d[:, 0]], axis=1) / self.length[:, None]
        centre = x[msh.geometry.dofmaps[0][self.cells]][:, :, :2].mean(axis=1)
        flip = np.sum(n * (0.5 * (self.a + self.b) - centre), axis=1) < 0
        n[flip] *= -1.0
        self.normal = n

    def lobatto_nodes(self, msh: dmesh.Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Nodes of the per-edge 4-point Gauss–Lobatto rule, shared vertices merged.

        Returns points (N, 2), weights (N,), a cell containing each node, the
        outward normal there, and the geometry node index of vertex nodes (−1 inside edges).
        """
        tdim = msh.topology.dim
        geo = dmesh.entities_to_geometry(msh, tdim - 1, self.facets)  # (F, 2) end points a, b
        pts = self.a[:, None, :] + _LOBATTO_S[None, :, None] * (self.b - self.a)[:, None, :]  # (F, 4, 2)
        wts = self.length[:, None] * _LOBATTO_W[None, :]
        F = self.facets.size
        vertex = np.full((F, 4), -1, dtype=np.int64)
        vertex[:, 0], vertex[:, 3] = geo[:, 0], geo[:, 1]
        cells = np.repeat(self.cells, 4)
        normals = np.repeat(self.normal, 4, axis=0)
        pts, wts, vertex = pts.reshape(-1, 2), wts.ravel(), vertex.ravel()
        # merge the copies of a vertex shared by two edges with the same normal
        key = np.where(vertex >= 0, vertex, -1 - np.arange(vertex.size))
        nkey = np.round(normals * 1e8).astype(np.int64)
        _, first, inverse = np.unique(
            np.stack([key, nkey[:, 0], nkey[:, 1]], axis=1), axis=0, return_index=True, return_inverse=True
        )
        merged_w = np.zeros(first.size)
        np.add.at(merged_w, inverse.ravel(), wts)
        return pts[first], merged_w, cells[first], normals[first], vertex[first]

    def locate(self, points: np.ndarray, tol: float = 1e-10) -> np.ndarray:
        """Index of a facet (into ``self.facets``) containing each point; raises if one is off the facets."""
        d = self.b - self.a
        rel = points[:, None, :] - self.a[None, :, :]  # (P, F, 2)
        s = np.einsum("pfi,fi->pf", rel, d) / self.length[None, :] ** 2
        dist = np.linalg.norm(rel - s[..., None] * d[None], axis=-1)
        ok = (dist <= tol * self.length[None, :]) & (s >= -tol) & (s <= 1 + tol)
        if not np.all(ok.any(axis=1)):
            raise RuntimeError("a point does not lie on the boundary facets")
        return np.argmax(ok, axis=1)


# ---------------------------------------------------------------------------
# Assembly helpers
# ---------------------------------------------------------------------------


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """a·b without BLAS (OpenBLAS threads contend with the MUMPS/OpenMP threads on small machines)."""
    return float(np.einsum("i,i->", a, b))


def _norm(a: np.ndarray) -> float:
    return float(np.sqrt(_dot(a, a)))


def _assemble_vector(form) -> np.ndarray:
    b = fem.assemble_vector(fem.form(form))
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    return b.array.copy()


def _pt_a_p(form, P_petsc: PETSc.Mat) -> sp.csr_matrix:
    """Pᵀ A P of a bilinear form on the DG stress space (PETSc PtAP)."""
    A = dolfinx.fem.petsc.assemble_matrix(fem.form(form))
    A.assemble()
    R = A.PtAP(P_petsc)
    A.destroy()
    out = petsc_to_scipy(R)
    R.destroy()
    return out


def _split_interface_columns(
    space: ArnoldWintherSpace, msh: dmesh.Mesh, cell_tags: dmesh.MeshTags, facet_tags: dmesh.MeshTags
) -> sp.csr_matrix:
    """Extra stress basis functions doubling σ_tt at the vertices of γ on the Ω₂ side.

    At a γ vertex v with γ normals n, the Ω₂-side function equals the AW vertex
    basis function with value z (z spanning the null space of σ ↦ σn) in the
    Ω₂ cells and 0 elsewhere; its normal trace on γ vanishes, so it stays in
    H(div).  Returns the new columns of P (n_dg × n_new).
    """
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, 0)
    f2v = msh.topology.connectivity(tdim - 1, 0)
    gamma = facet_tags.find(Boundary.INTERFACE)
    geo = dmesh.entities_to_geometry(msh, tdim - 1, gamma)
    x = msh.geometry.x[:, :2]
    rows_at: dict[int, list[np.ndarray]] = {}
    for f, g in zip(gamma, geo):
        d = x[g[1]] - x[g[0]]
        n = np.array([d[1], -d[0]]) / np.linalg.norm(d)
        for v in f2v.links(f):
            rows_at.setdefault(int(v), []).append(np.array([[n[0], n[1], 0.0], [0.0, n[0], n[1]]]))
    P = space.full_prolongation.tocsc()
    omega2 = cell_tags.find(Subdomain.OMEGA2)
    dg_rows = (3 * space.dg.dofmap.list[omega2].astype(np.int64)[:, :, None] + np.arange(3)).ravel()
    mask = np.zeros(P.shape[0])
    mask[dg_rows] = 1.0
    columns = []
    for v, rows in rows_at.items():
        # the Ω₂-side value z must also satisfy the essential conditions at v (a γ end on a
        # traction-free, traction or contact side): z in the null space of all rows
        stacked = np.vstack(rows + [space.vertex_constraints[v]] if v in space.vertex_constraints else rows)
        _, sv, vt = np.linalg.svd(stacked)
        null = vt[int(np.sum(sv > 1e-10 * sv.max())) :]
        for z in null:
            col = sum(z[j] * P[:, 3 * v + j] for j in range(3) if z[j] != 0.0)
            columns.append(col.multiply(mask[:, None]).tocsc())
    if not columns:
        return sp.csr_matrix((P.shape[0], 0))
    return sp.hstack(columns, format="csr")


# ---------------------------------------------------------------------------
# The subproblem
# ---------------------------------------------------------------------------


class MixedSubproblem:
    """(Aσ, τ) + (div τ, u) [+ p_ε(σ; τ)] [+ r_β(σ, τ)] = [d(g; τ)],  (div σ, v) = −(f, v) on one mesh.

    Three roles, like ``fem.primal.PrimalSubproblem``: the monolithic problem
    (contact, no Robin), the linear Ω₁ problem (Robin on γ, no contact: one
    factorization, then one solve per call) and the Ω₂ problem (contact and
    Robin: globalized semismooth Newton warm-started from the last solution,
    refactorized only when the active set changes).

    Args:
        msh, facet_tags, fields: the (sub)mesh, its Γ_C / γ tags and DG0 materials.
        epsilon: mixed penalty ε (None: no contact term; Γ_C facets still get σ_t = 0).
        beta: Robin coefficient β on γ (None: no Robin term).
        prefix: PETSc options prefix of the direct solver.
        newton: step cap and residual tolerances.
        extra_columns: additional stress basis functions (columns of P), e.g. the
            interface split of the monolithic reference.
        space: a prebuilt AW space on ``msh`` (with σ_t = 0 on Γ_C).
        line_search: ``"on-cycle"`` (full semismooth Newton steps until a cycle
            is detected, then exact line search on J) or ``"always"``.
        operators: False builds the spaces, the interface data and the load only, without
            the global matrices (no solve then; Algorithm 4's Ω₁ assembles its own cell blocks).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        fields: MaterialFields,
        *,
        epsilon: float | None,
        beta: float | None,
        prefix: str,
        newton: NewtonOptions = NewtonOptions(),
        extra_columns: sp.csr_matrix | None = None,
        space: ArnoldWintherSpace | None = None,
        line_search: str = "on-cycle",
        operators: bool = True,
    ) -> None:
        t0 = time.perf_counter()
        if line_search not in ("on-cycle", "always"):
            raise InputError(f"line_search must be 'on-cycle' or 'always', got {line_search!r}")
        self.line_search = line_search
        check_serial_triangles(msh)
        if epsilon is not None and not (np.isfinite(epsilon) and epsilon > 0):
            raise InputError(f"the mixed penalty parameter ε must be > 0, got {epsilon}")
        if beta is not None and not (np.isfinite(beta) and beta > 0):
            raise InputError(f"the transmission coefficient β must be > 0, got {beta}")
        self.mesh, self.facet_tags, self.prefix, self.newton = msh, facet_tags, prefix, newton
        self.epsilon, self.beta = epsilon, beta
        self.contact = epsilon is not None
        self.fields = fields
        contact_facets = facet_tags.find(Boundary.GAMMA_C)
        if self.contact and contact_facets.size == 0:
            if fields.obstacle is not None:
                raise InputError(
                    "an obstacle is given but the mesh has no contact boundary: the physical group 'Gamma_C' "
                    "has no facets (tag the facets that may touch the obstacle as Gamma_C)"
                )
            raise InputError("a contact subproblem needs Γ_C facets")
        self.space = space or boundary_stress_space(msh, facet_tags, fields.boundary)
        P = self.space.prolongation
        if extra_columns is not None and extra_columns.shape[1] > 0:
            P = sp.hstack([P, extra_columns], format="csr")
        self.P = P.tocsr()
        self.P.sort_indices()
        self.dg = self.space.dg
        self.U = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 1, shape=(2,)))
        self.n_sigma = self.P.shape[1]
        self.n_u = 2 * self.U.dofmap.index_map.size_local

        # -- bulk operators ------------------------------------------------------------
        self.has_operators = operators
        s, t = ufl.TrialFunction(self.dg), ufl.TestFunction(self.dg)
        w, v = ufl.TrialFunction(self.U), ufl.TestFunction(self.U)
        n = ufl.FacetNormal(msh)
        if operators:
            P_petsc = scipy_to_petsc(self.P, msh.comm)
            self.K = _pt_a_p(forms_mixed.compliance_form(s, t, fields.lmbda, fields.mu), P_petsc)
            self.B = (assemble_scipy(forms_mixed.divergence_form(s, v)) @ self.P).tocsr()
            P_petsc.destroy()
        else:  # the spaces and the interface data only (Algorithm 4's Ω₁ assembles its own cell blocks)
            self.K = self.B = None
        self.M = assemble_scipy(forms_mixed.mass_form(w, v))
        self.G = _assemble_vector(forms_mixed.load_form(fields.f, v))[: self.n_u]

        # -- boundary data: traction lifting σ_t (σ = P c + σ_t) and the natural Γ_D term ------
        n_dg = self.P.shape[0]
        self.s0 = np.zeros(n_dg) if self.space.lifting_dg is None else self.space.lifting_dg[:n_dg].copy()
        self._lifted = bool(np.any(self.s0))
        self._F_boundary = np.zeros(self.n_sigma)  # constant stress-side load of the lifting and of u_D
        if self._lifted:
            s0 = fem.Function(self.dg)
            s0.x.array[:n_dg] = self.s0
            self.G -= _assemble_vector(forms_mixed.divergence_form(s0, v))[: self.n_u]
            self._F_boundary -= self.P.T @ _assemble_vector(forms_mixed.compliance_form(s0, t, fields.lmbda, fields.mu))[:n_dg]
            self._s0_function = s0
        self.u_D: fem.Function | None = None
        if fields.boundary.displacement is not None and facet_tags.find(Boundary.GAMMA_D).size:
            self.u_D = displacement_trace_function(msh, fields.boundary.displacement)
            dsD = forms_mixed.boundary_measure(msh, facet_tags)(Boundary.GAMMA_D)
            self._F_boundary += self.P.T @ _assemble_vector(forms_mixed.robin_data_form(self.u_D, t, n, dsD))[:n_dg]

        # -- Robin term and data on γ -------------------------------------------------
        ds = forms_mixed.boundary_measure(msh, facet_tags)
        self.Kt = self.K
        self.gamma_points = np.zeros((0, 2))
        if beta is not None:
            gamma = facet_tags.find(Boundary.INTERFACE)
            if gamma.size == 0:
                raise InputError("a Robin subproblem needs interface (γ) facets")
            if operators:
                R = assemble_scipy(forms_mixed.robin_form(s, t, n, 1.0, ds(Boundary.INTERFACE)))
                self.R = (self.P.T @ R @ self.P).tocsr()
                self.Kt = (self.K + beta * self.R).tocsr()
                if self._lifted:
                    self._F_boundary -= beta * (self.P.T @ (R @ self.s0))
            elif self._lifted:
                raise InputError("a subproblem without its global operators (Algorithm 4's Ω₁) takes no traction data")
            self._setup_interface(gamma, ds, t, n)

        # -- contact quadrature and obstacle ----------------------------------------------
        self._F_gap = np.zeros(self.n_sigma)
        self.obstacle = None
        if contact_facets.size:
            self._setup_contact(msh, facet_tags, contact_facets)
            self.set_obstacle(fields.obstacle)

        self.c = np.zeros(self.n_sigma)
        self.u = np.zeros(self.n_u)
        self._cold = True
        self._solver: DirectSolver | None = None
        self._matrix: PETSc.Mat | None = None
        self._saddle: sp.csr_matrix | None = None
        self._factorized_set: np.ndarray | None = None
        self._rhs = PETSc.Vec().createSeq(self.n_sigma + self.n_u, comm=msh.comm)
        self._sol = self._rhs.duplicate()
        self.build_time = time.perf_counter() - t0

    # -- setup pieces -----------------------------------------------------------------
    def _setup_interface(self, gamma: np.ndarray, ds, t, n) -> None:
        """Robin data space on γ: continuous vector P3 on γ (the normal-trace space of AW)."""
        msh = self.mesh
        Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        blocks = fem.locate_dofs_topological(Lam, tdim - 1, gamma)
        coords = Lam.tabulate_dof_coordinates()[blocks, :2]
        order = np.lexsort((coords[:, 0], coords[:, 1]))
        blocks, coords = blocks[order], coords[order]
        self.gamma_points = coords
        g = ufl.TrialFunction(Lam)
        C = assemble_scipy(forms_mixed.robin_data_form(g, t, n, ds(Boundary.INTERFACE)))
        cols = (2 * blocks[:, None] + np.arange(2)).ravel()
        #: d(g; τ) = C g for interface data g = values (x, y) at ``gamma_points`` (flattened)
        self.C = (self.P.T @ C[:, cols]).tocsr()
        # trace σn at the γ nodes (exact: σn is a P3 polynomial on each γ edge, continuous at vertices)
        bf = _BoundaryFacets(msh, gamma)
        idx = bf.locate(coords)
        cells, normals = bf.cells[idx], bf.normal[idx]
        X = _reference_coordinates(msh, cells, coords)
        wx, wy = _traction_weights(normals)
        Ex = _stress_evaluation(self.dg, cells, X, wx)
        Ey = _stress_evaluation(self.dg, cells, X, wy)
        E = sp.vstack([Ex, Ey]).tocsr()
        perm = np.arange(2 * coords.shape[0]).reshape(2, -1).T.ravel()  # interleave (x, y) per node
        #: σn (outward n of this mesh) at ``gamma_points``, flattened (x, y) per node: N c (+ ``n0``)
        self.N = (E[perm] @ self.P).tocsr()
        #: σ_t n at ``gamma_points`` (the traction lifting's trace; zero without tractions)
        self.n0 = E[perm] @ self.s0
        self.gamma_normal = normals

    def _setup_contact(self, msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, facets: np.ndarray) -> None:
        """Q: σ_c at the Gauss–Lobatto nodes of Γ_C (a Lagrange basis of the σ_c trace space)."""
        bf = _BoundaryFacets(msh, facets)
        pts, wq, cells, normals, vertex = bf.lobatto_nodes(msh)
        order = profile_order(pts)
        pts, wq, cells, normals, vertex = pts[order], wq[order], cells[order], normals[order], vertex[order]
        X = _reference_coordinates(msh, cells, pts)
        Q_dg = _stress_evaluation(self.dg, cells, X, _normal_weights(normals))
        self.Q = (Q_dg @ self.P).tocsr()
        self.Q.eliminate_zeros()
        #: σ_t,c at the contact nodes (the traction lifting's normal stress; zero without tractions)
        self.q0 = Q_dg @ self.s0
        self.q_weights = wq
        self.q_points = pts
        self.q_normals = normals
        # u_h·n at the nodes from the DG P1 displacement (one adjacent cell per node)
        el = self.U.ufl_element().sub_elements[0].basix_element
        phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 3)
        dofs = self.U.dofmap.list[cells].astype(np.int64)
        cols = 2 * dofs[:, :, None] + np.arange(2)
        vals = phi[:, :, None] * normals[:, None, :]
        rows = np.broadcast_to(np.arange(pts.shape[0])[:, None, None], cols.shape)
        self._Un = sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(pts.shape[0], self.n_u))
        # nodes on Γ_D (the clamped corners) are left out of the profile, as in the primal one
        tdim = msh.topology.dim
        dirichlet = facet_tags.find(Boundary.GAMMA_D)
        clamped = np.unique(dmesh.entities_to_geometry(msh, tdim - 1, dirichlet)) if dirichlet.size else []
        self._profile_nodes = ~np.isin(vertex, clamped)

    def set_obstacle(self, obstacle: Obstacle | None) -> None:
        """Set (or move) the obstacle: the gap g at the contact nodes and the load −∫_ΓC g τ_c (Gauss–Lobatto).

        The mixed law is u·n = g − (σ_c)⁺/ε with the body's normal n; the Jacobian does not
        change, so the factorizations stay valid and the next solve warm-starts.
        """
        if not hasattr(self, "q_points"):
            raise InputError("this subproblem has no contact boundary")
        if obstacle is None:
            self.q_gap = np.zeros(self.q_points.shape[0])
        else:
            self.q_gap, _ = evaluate_obstacle(obstacle, self.q_points)
        self._F_gap = self.Q.T @ (self.q_weights * self.q_gap)
        self.obstacle = obstacle

    def _stress_load(self, data: np.ndarray | None) -> np.ndarray:
        """The σ-row right-hand side: Robin data C g, traction lifting, ∫_ΓD u_D·τn and ∫_ΓC g τ_c."""
        load = self._F_boundary + self._F_gap
        return load if data is None else load + self.C @ data

    def _contact_stress(self, c: np.ndarray) -> np.ndarray:
        """σ_c at the contact nodes of the stress P c + σ_t."""
        return self.Q @ c + self.q0

    def gamma_traction(self) -> np.ndarray:
        """σn on γ (outward n of this mesh) at ``gamma_points``, flattened (x, y) per node."""
        return self.N @ self.c + self.n0

    # -- sizes ------------------------------------------------------------------------
    @property
    def num_dofs(self) -> dict[str, int]:
        """Stress (AW), displacement and total DOF counts."""
        return {"sigma": self.n_sigma, "u": self.n_u, "total": self.n_sigma + self.n_u}

    # -- linear algebra -----------------------------------------------------------------
    @property
    def solver(self) -> DirectSolver:
        """The direct solver (created at the first factorization: its PETSc options are set then)."""
        if self._solver is None:
            self._solver = DirectSolver(self.mesh.comm, prefix=self.prefix, options=MIXED_SOLVER_OPTIONS)
        return self._solver

    def _penalty_matrix(self, active: np.ndarray, *, padded: bool = False) -> sp.csr_matrix:
        """(1/ε) Qᵀ W H Q for the penalty-active nodes (``padded``: as a block of the saddle-point matrix)."""
        Q = self._Q_padded if padded else self.Q
        Qa = Q[np.flatnonzero(active)]
        return (Qa.T @ sp.diags(self.q_weights[active] / self.epsilon) @ Qa).tocsr()

    def _factorize_for(self, active: np.ndarray | None) -> bool:
        """Factorize the saddle-point Jacobian unless the cached one has the same active set."""
        if not self.has_operators:
            raise InputError("this subproblem was built without its matrices (operators=False): it cannot be solved")
        key = np.zeros(0, dtype=bool) if active is None else active
        if self._factorized_set is not None and np.array_equal(key, self._factorized_set):
            return False
        if self._saddle is None:
            self._saddle = sp.bmat([[self.Kt, self.B.T], [self.B, None]], format="csr")
            self._saddle.sum_duplicates()  # canonical: sorted indices, no duplicates, no stored zeros
            self._saddle.eliminate_zeros()
            if self.contact:
                self._Q_padded = sp.hstack([self.Q, sp.csr_matrix((self.Q.shape[0], self.n_u))], format="csr")
        if not self.contact:
            if self._matrix is not None:
                self._matrix.destroy()
            self._matrix = scipy_to_petsc(self._saddle, self.mesh.comm)
        else:
            # one sparsity pattern for every active set (all Γ_C nodes): when the active set changes
            # only the penalty values change and MUMPS redoes the numeric factorization, not the analysis
            if self._matrix is None:
                Qabs = abs(self._Q_padded)
                pattern = (abs(self._saddle) + Qabs.T @ Qabs).tocsr()  # structural: no cancellation
                pattern.sum_duplicates()
                self._pattern = pattern
                self._pattern_keys = _csr_keys(pattern)
                self._saddle_data = np.zeros_like(pattern.data)
                self._saddle_data[self._pattern_positions(self._saddle)] = self._saddle.data
                self._matrix = scipy_to_petsc(pattern, self.mesh.comm)
                self._matrix.setOption(PETSc.Mat.Option.NEW_NONZERO_LOCATION_ERR, True)
            data = self._saddle_data.copy()
            if active is not None and active.any():
                pen = self._penalty_matrix(active, padded=True)
                pen.sum_duplicates()
                pen.eliminate_zeros()
                data[self._pattern_positions(pen)] += pen.data
            self._matrix.zeroEntries()
            self._matrix.setValuesCSR(self._pattern.indptr, self._pattern.indices, data)
            self._matrix.assemble()
        self.solver.set_operator(self._matrix)
        self._factorized_set = key.copy()
        return True

    def _pattern_positions(self, A: sp.csr_matrix) -> np.ndarray:
        """Where the stored entries of A sit in the data array of the all-active pattern."""
        keys = _csr_keys(A)
        pos = np.minimum(np.searchsorted(self._pattern_keys, keys), self._pattern_keys.size - 1)
        if not np.array_equal(self._pattern_keys[pos], keys):
            raise RuntimeError("the mixed Jacobian has an entry outside the all-active sparsity pattern")
        return pos

    def _solve(self, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._rhs.array[: self.n_sigma] = r1
        self._rhs.array[self.n_sigma :] = r2
        self.solver.solve(self._rhs, self._sol)
        x = self._sol.array
        return x[: self.n_sigma].copy(), x[self.n_sigma :].copy()

    # -- residual, energy ---------------------------------------------------------------
    def _penalty_force(self, s: np.ndarray) -> np.ndarray:
        return self.Q.T @ (self.q_weights * np.maximum(s, 0.0)) / self.epsilon

    def _gradient(self, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(F_σ, F_u) at the current (σ, u) for the stress-side load (C g)."""
        F1 = self.Kt @ self.c + self.B.T @ self.u - load
        if self.contact:
            F1 += self._penalty_force(self._contact_stress(self.c))
        return F1, self.B @ self.c - self.G

    def _scale(self, load: np.ndarray) -> float:
        """Sum of the norms of the terms of the residual (the yardstick of the residual check)."""
        scale = _norm(self.Kt @ self.c) + _norm(self.B.T @ self.u) + _norm(load)
        scale += _norm(self.B @ self.c) + _norm(self.G)
        if self.contact:
            scale += _norm(self._penalty_force(self._contact_stress(self.c)))
        return scale

    def residual(self, data: np.ndarray | None = None) -> tuple[float, float]:
        """(‖F‖, scale) at the current (σ, u) with Robin data g; scale = sum of the norms of the terms."""
        load = self._stress_load(data)
        F1, F2 = self._gradient(load)
        return float(np.sqrt(_dot(F1, F1) + _dot(F2, F2))), self._scale(load)

    def _line_search(self, dc: np.ndarray, s: np.ndarray, d: np.ndarray, load: np.ndarray) -> float:
        """argmin_{t ∈ (0, 1]} J(σ + t dσ): root of the increasing piecewise-linear φ'(t)."""
        a = _dot(dc, self.Kt @ dc)
        b0 = _dot(self.Kt @ self.c - load, dc)
        w = self.q_weights / self.epsilon

        def dphi(t: np.ndarray) -> np.ndarray:
            return a * t + b0 + (w * d * np.maximum(s[None, :] + t[:, None] * d[None, :], 0.0)).sum(axis=1)

        ends = dphi(np.array([0.0, 1.0]))
        if ends[0] >= 0.0 or ends[1] <= 0.0:
            return 1.0
        nz = d != 0.0
        bp = -s[nz] / d[nz]
        bp = np.unique(np.concatenate([[0.0, 1.0], bp[(bp > 0.0) & (bp < 1.0)]]))
        vals = dphi(bp)
        k = int(np.argmax(vals > 0.0))  # first breakpoint with φ' > 0 (k ≥ 1)
        t0, t1, v0, v1 = bp[k - 1], bp[k], vals[k - 1], vals[k]
        return float(t0 - v0 * (t1 - t0) / (v1 - v0))

    # -- solve --------------------------------------------------------------------------
    def solve(self, data: np.ndarray | None = None) -> MixedNewtonHistory:
        """Solve with Robin data g (values at ``gamma_points``), warm-started from the current (σ, u)."""
        load = self._stress_load(data)
        history = MixedNewtonHistory()
        if not self.contact:  # linear: one solve with the cached factorization
            history.factorizations += self._factorize_for(None)
            self.c, self.u = self._solve(load, self.G)
            history.active_sizes.append(0)
            history.step_lengths.append(1.0)
            return history
        name = self.prefix.rstrip("_")
        visited: set[bytes] = set()
        line_search = self.line_search == "always"
        for _ in range(self.newton.max_iterations):
            s = self._contact_stress(self.c)
            # cold start: linearize at "penalty everywhere" (traction-free Γ_C); its solution has
            # σ_c < 0 exactly where a free body would penetrate, a good first contact set
            active = np.ones_like(s, dtype=bool) if self._cold else s > 0.0
            visited.add(np.packbits(active).tobytes())
            F1, F2 = self._gradient(load)
            history.residuals.append(float(np.sqrt(_dot(F1, F1) + _dot(F2, F2))))
            history.factorizations += self._factorize_for(active)
            feasible = _norm(F2) <= 1e-10 * (_norm(self.G) + _norm(self.B @ self.c))
            dc, du = self._solve(-F1, -F2)
            d = self.Q @ dc
            predicted = s + d > 0.0
            settled = np.array_equal(predicted, active)
            if not settled and feasible and not line_search:
                # with full steps the iterate depends only on the set it was linearized at, so
                # stepping into a set already linearized at closes a cycle: from then on
                # minimize J along every direction (J decreases monotonically: no cycle)
                line_search = np.packbits(predicted).tobytes() in visited
            t = self._line_search(dc, s, d, load) if line_search and feasible and not settled else 1.0
            self._cold = False
            self.c += t * dc
            self.u += t * du
            history.step_lengths.append(t)
            history.energies.append(self.complementary_energy(data))
            history.active_sizes.append(int(np.count_nonzero(self._contact_stress(self.c) <= 0.0)))
            if settled:
                final, scale = self.residual(data)
                history.residuals.append(final)
                if final > self.newton.rtol * scale + self.newton.atol:
                    raise ConvergenceError(
                        f"{name}: active set settled but residual {final:.3e} exceeds "
                        f"{self.newton.rtol:g}·(size of the terms {scale:.3e})"
                    )
                return history
        raise ConvergenceError(
            f"{name}: globalized semismooth Newton did not converge in {self.newton.max_iterations} steps "
            f"(contact-set sizes {history.active_sizes[-5:]}, step lengths {history.step_lengths[-5:]}, "
            f"residuals {history.residuals[-3:]})"
        )

    # -- output -------------------------------------------------------------------------
    def sigma_function(self, out: fem.Function | None = None, name: str = "sigma") -> fem.Function:
        """σ_h as a DG P3 function of (σ_xx, σ_xy, σ_yy)."""
        out = fem.Function(self.dg, name=name) if out is None else out
        out.x.array[: self.P.shape[0]] = self.P @ self.c + self.s0
        out.x.scatter_forward()
        return out

    def u_function(self, out: fem.Function | None = None, name: str = "u") -> fem.Function:
        """u_h as a DG P1 vector function."""
        out = fem.Function(self.U, name=name) if out is None else out
        out.x.array[: self.n_u] = self.u
        out.x.scatter_forward()
        return out

    def stress_norm2(self, c: np.ndarray) -> float:
        """‖σ‖²_A = (Aσ, σ) of AW coefficients c."""
        return _dot(c, self.K @ c)

    def l2_norm2(self, u: np.ndarray) -> float:
        """‖u‖²_L² of DG P1 coefficients u."""
        return _dot(u, self.M @ u)

    def complementary_energy(self, data: np.ndarray | None = None) -> float:
        """J(σ) = ½(Aσ,σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε)∫_ΓC ((σ_c)⁺)² at the current σ."""
        J = 0.5 * _dot(self.c, self.Kt @ self.c) - _dot(self._stress_load(data), self.c)
        if self.contact:
            J += 0.5 * np.sum(self.q_weights * np.maximum(self._contact_stress(self.c), 0.0) ** 2) / self.epsilon
        return float(J)

    def contact_profile(self) -> MixedContactProfile:
        """σ_c and u_c = −(σ_c)⁺/ε at the Γ_C contact nodes (clamped corners excluded), sorted by y."""
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        keep = self._profile_nodes
        sigma_c = self._contact_stress(self.c)[keep]
        return MixedContactProfile(
            self.q_points[keep, 1], -np.maximum(sigma_c, 0.0) / self.epsilon, sigma_c, self.q_points[keep],
            self.q_weights[keep], self.q_normals[keep], self.q_gap[keep],
        )

    def displacement_normal_trace(self) -> tuple[np.ndarray, np.ndarray]:
        """(y, u_h·n) of the DG P1 displacement at the profile's contact nodes (a diagnostic of u_c)."""
        keep = self._profile_nodes
        return self.q_points[keep, 1], (self._Un @ self.u)[keep]

    def ufl_residual_norm(self, data: np.ndarray | None = None) -> tuple[float, float]:
        """‖F‖ of the residual assembled from ``forms_mixed.mixed_residual`` (independent of Q), and its scale."""
        msh = self.mesh
        sig, uh = self.sigma_function(), self.u_function()
        t, v = ufl.TestFunction(self.dg), ufl.TestFunction(self.U)
        n = ufl.FacetNormal(msh)
        ds = forms_mixed.boundary_measure(msh, self.facet_tags)
        contact = robin = None
        if self.contact:
            ds_c = forms_mixed.contact_measure(msh, self.facet_tags)
            contact = (fem.Constant(msh, PETSc.ScalarType(1.0 / self.epsilon)), ds_c(Boundary.GAMMA_C))
        if self.beta is not None:  # the data term is applied below as C g
            robin = (fem.Constant(msh, PETSc.ScalarType(self.beta)), None, ds(Boundary.INTERFACE))
        Ft, Fv = forms_mixed.mixed_residual(sig, uh, t, v, lmbda=self.fields.lmbda, mu=self.fields.mu,
                                            f=self.fields.f, n=n, contact=contact, robin=robin)
        natural = []  # ∫_ΓD u_D·τn and ∫_ΓC g τ_c (g as a P3 function with its nodes at the Gauss–Lobatto points)
        if self.u_D is not None:
            natural.append(forms_mixed.robin_data_form(self.u_D, t, n, ds(Boundary.GAMMA_D)))
        if self.contact and self.obstacle is not None:
            gap = _gll_function(msh, self.obstacle.gap)
            natural.append(forms_mixed.gap_form(gap, t, n, ds_c(Boundary.GAMMA_C)))
        for form in natural:
            Ft -= form
        r1 = self.P.T @ _assemble_vector(Ft)[: self.P.shape[0]]
        if data is not None:
            r1 -= self.C @ data
        r2 = _assemble_vector(Fv)[: self.n_u]
        _, scale = self.residual(data)
        return float(np.sqrt(_dot(r1, r1) + _dot(r2, r2))), scale

    # -- interface Newton support (hybrid.newton) -------------------------------------------------
    def reset(self) -> None:
        """Forget the solution and the cached factorization (the next ``solve`` starts cold)."""
        self.c = np.zeros(self.n_sigma)
        self.u = np.zeros(self.n_u)
        self._cold = True
        if self.contact:
            self._factorized_set = None

    def set_state(self, c: np.ndarray, u: np.ndarray) -> None:
        """Set (σ, u) (AW and DG P1 coefficients): the warm start of the next ``solve``."""
        self.c = np.array(c, dtype=float).reshape(self.n_sigma)
        self.u = np.array(u, dtype=float).reshape(self.n_u)
        self._cold = False

    def gamma_mass(self) -> sp.csr_matrix:
        """The L²(γ) mass matrix of the continuous P3 vector data at ``gamma_points`` (flattened (x, y))."""
        if self.beta is None:
            raise InputError("this subproblem has no interface γ")
        msh = self.mesh
        Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
        gamma = self.facet_tags.find(Boundary.INTERFACE)
        blocks = fem.locate_dofs_topological(Lam, msh.topology.dim - 1, gamma)
        coords = Lam.tabulate_dof_coordinates()[blocks, :2]
        blocks = blocks[np.lexsort((coords[:, 0], coords[:, 1]))]  # the order of ``gamma_points``
        g, w = ufl.TrialFunction(Lam), ufl.TestFunction(Lam)
        ds = forms_mixed.boundary_measure(msh, self.facet_tags)
        M = assemble_scipy(ufl.inner(g, w) * ds(Boundary.INTERFACE))
        cols = (2 * blocks[:, None] + np.arange(2)).ravel()
        return M[cols][:, cols].tocsr()

    def destroy(self) -> None:
        """Free the PETSc objects."""
        if self._matrix is not None:
            self._matrix.destroy()
        for obj in (self._rhs, self._sol):
            obj.destroy()
        if self._solver is not None:
            self._solver.destroy()


def _gll_function(msh: dmesh.Mesh, field) -> fem.Function:
    """A scalar P3 function with its edge nodes at the 4-point Gauss–Lobatto points, interpolating ``field``.

    Non-finite values (a signed distance undefined away from Γ_C) are set to 0.
    """
    el = basix.ufl.element("Lagrange", msh.basix_cell(), 3, lagrange_variant=basix.LagrangeVariant.gll_warped)
    fn = fem.Function(fem.functionspace(msh, el))
    with np.errstate(invalid="ignore"):
        fn.interpolate(lambda x: np.asarray(field(x), dtype=np.float64).reshape(-1))
    fn.x.array[~np.isfinite(fn.x.array)] = 0.0
    return fn


def displacement_trace_function(msh: dmesh.Mesh, field) -> fem.Function:
    """u_D interpolated into continuous vector P3 (for the natural term ∫_ΓD u_D·τn ds)."""
    fn = fem.Function(fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,))))
    fn.interpolate(field)
    return fn


def boundary_stress_space(
    msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, boundary: BoundaryConditions
) -> ArnoldWintherSpace:
    """The AW space of a (sub)mesh with the essential stress conditions of its boundary.

    σn·t = 0 on Γ_C; σn = t on the Γ_N groups (a lifting); σn = 0 on every other
    exterior facet that is not Γ_D or γ (traction free).  Γ_D (u = u_D) and γ (Robin)
    are natural.
    """
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    exterior = dmesh.exterior_facet_indices(msh.topology)
    tagged = np.concatenate(
        [facet_tags.find(t) for t in (Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE)]
    )
    prescribed = []
    for tag, _, traction in boundary.traction_tags():
        facets = facet_tags.find(tag)
        if facets.size:
            prescribed.append((facets, traction))
    all_neumann = set(neumann_groups(facet_tags))
    neumann = np.concatenate([facet_tags.find(t) for t in sorted(all_neumann)] or [np.zeros(0, np.int32)])
    free = np.setdiff1d(exterior, np.concatenate([tagged, neumann]))
    return ArnoldWintherSpace(
        msh,
        zero_tangential_facets=facet_tags.find(Boundary.GAMMA_C),
        zero_traction_facets=np.union1d(free, neumann),
        prescribed_tractions=prescribed,
    )


def interpolate_stress(sigma: fem.Function, degree: int = 1, name: str = "sigma") -> fem.Function:
    """(σ_xx, σ_xy, σ_yy) of a DG P3 stress interpolated into DG ``degree`` (0: cell midpoints).

    For output: XDMF writes DG0 (and P1-like) fields, plots take DG0 / DG1.
    """
    msh = sigma.function_space.mesh
    el = basix.ufl.element("DG", msh.basix_cell(), degree, shape=(3,))
    V = fem.functionspace(msh, el)
    out = fem.Function(V, name=name)
    out.interpolate(fem.Expression(sigma, V.element.interpolation_points))
    return out


# ---------------------------------------------------------------------------
# The monolithic solve
# ---------------------------------------------------------------------------


@dataclass(slots=True)
class MixedSolution:
    """The monolithic mixed penalized solution with its Newton history and contact profile."""

    sigma: fem.Function  #: DG P3 (σ_xx, σ_xy, σ_yy)
    u: fem.Function  #: DG P1 vector
    newton: MixedNewtonHistory
    profile: MixedContactProfile
    epsilon: float
    dofs: dict
    time_s: float  #: setup + Newton
    time_newton_s: float  #: Newton only (the online part)
    problem: MixedSubproblem | None  #: None once ``free()`` has been called
    split_interface: bool

    def free(self) -> None:
        """Release the monolithic problem (its matrices and MUMPS factors); the solution, history and profile stay.

        A reference solve keeps GBs at h = 1/128 otherwise (the factors of the whole mixed problem).
        """
        if self.problem is not None:
            self.problem.destroy()
            self.problem = None


def solve_mixed_monolithic(
    cm: ContactMesh,
    model: TestModel,
    *,
    epsilon: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    split_interface: bool = False,
    prefix: str = "fc_mixed_mono_",
    verify: bool = True,
) -> MixedSolution:
    """Mixed penalized contact on the whole mesh (METHOD §2), globalized semismooth Newton.

    ``epsilon`` defaults to ``default_epsilon(h, E_c)``; ``split_interface`` solves on X̃_h
    (σ_tt doubled at the γ vertices: the exact fixed point of Algorithm 2); ``verify``
    re-checks the final residual with the UFL forms.
    """
    start = time.perf_counter()
    check_serial_triangles(cm.mesh)
    fields = material_fields(cm.mesh, model)
    if epsilon is None:
        epsilon = default_epsilon(cm.h, contact_modulus(cm.mesh, cm.facet_tags, fields.E))
    extra = None
    space = None
    check_boundary_groups(cm.mesh, cm.facet_tags, fields.boundary, names=cm.neumann_names)
    if split_interface:
        space = boundary_stress_space(cm.mesh, cm.facet_tags, fields.boundary)
        extra = _split_interface_columns(space, cm.mesh, cm.cell_tags, cm.facet_tags)
    problem = MixedSubproblem(
        cm.mesh, cm.facet_tags, fields, epsilon=epsilon, beta=None, prefix=prefix, newton=newton,
        extra_columns=extra, space=space,
    )
    t0 = time.perf_counter()
    history = problem.solve()
    t_newton = time.perf_counter() - t0
    if verify:
        norm, scale = problem.ufl_residual_norm()
        if norm > newton.rtol * scale + newton.atol:
            raise ConvergenceError(f"mixed monolithic: UFL residual {norm:.3e} exceeds {newton.rtol:g}·{scale:.3e}")
    elapsed = time.perf_counter() - start
    profile = problem.contact_profile()
    log.info(
        "monolithic mixed (ε = %.3g%s): %d Newton steps, step lengths %s, contact points %s, "
        "max tensile σ_c %.3e, %.2f s",
        epsilon, ", split γ" if split_interface else "", history.steps,
        [round(t, 3) for t in history.step_lengths], history.active_sizes, profile.max_tensile, elapsed,
    )
    return MixedSolution(
        problem.sigma_function(), problem.u_function(), history, profile, epsilon, problem.num_dofs,
        elapsed, t_newton, problem, split_interface,
    )
