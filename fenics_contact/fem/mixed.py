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

**MPI.**  Everything runs on a distributed mesh (``mpiexec -n N``): the AW space
numbers its DOFs globally (``fem.arnold_winther``), the operators are distributed
PETSc matrices, MUMPS factorizes the saddle-point matrix in parallel.  The Γ_C node
data are small and replicated, so every rank takes the same Newton decisions (active
set, cycle detection, line-search step) from the same numbers; every scalar of the
iteration (energy, residual, step) is a global reduction.  With N ranks the Newton
steps, active sets and solution are those of the serial run (to round-off; tested
for N = 2, 3 in ``tests/test_mpi_mixed.py``).
"""

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import ufl
from mpi4py import MPI
from petsc4py import PETSc
from scipy.spatial import cKDTree

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
from fenics_contact.problem.obstacles import Obstacle, check_obstacle_side, evaluate_obstacle
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.fem.distributed import DistributedMatrix, SaddlePointMatrix, coo_matrix, gather_rows, global_dot, layout
from fenics_contact.fem.linalg import DIRECT_OPTIONS, DirectSolver
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary, Subdomain

__all__ = [
    "MIXED_SOLVER_OPTIONS",
    "default_epsilon",
    "check_serial_triangles",
    "check_triangles",
    "MixedContactProfile",
    "MixedNewtonHistory",
    "MixedSubproblem",
    "MixedSolution",
    "solve_mixed_monolithic",
    "epsilon_for",
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
    """ε = factor·h·E_c with E_c the *smallest* E on Γ_C (``contact_modulus(..., smallest=True)``).

    Where the body separates, the wall holds it with a tensile spring of stiffness ε (σ_c = −ε u_c):
    against a material of modulus E the tensile stress left is ≈ ε/E relative, factor·h for the softest
    material on Γ_C.  With the largest E instead, a soft part of a heterogeneous Γ_C stayed glued to the
    wall: model 3 at contrast 10⁶ (stiff channels reaching Γ_C), h = 1/32, gave a contact force 20 % below
    the primal one and a tensile σ_c of 0.22; a bar pulled off the wall with one stiff stripe kept 27 % of
    its load on the wall."""
    if not (h > 0 and E_contact > 0 and factor > 0):
        raise InputError(f"default_epsilon needs h, E_c, factor > 0; got {h}, {E_contact}, {factor}")
    return factor * h * E_contact


def check_triangles(msh: dmesh.Mesh) -> None:
    """Raise InputError unless ``msh`` is a mesh of affine triangles (what the AW space supports; any number of ranks)."""
    if msh.topology.cell_type != dmesh.CellType.triangle:
        raise InputError(f"the mixed (Arnold–Winther) method needs a triangle mesh, got {msh.topology.cell_type.name}")
    if len(msh.geometry.cmaps) != 1 or msh.geometry.cmaps[0].degree != 1:
        raise InputError("the mixed (Arnold–Winther) method needs an affine (degree 1) triangle mesh")


def check_serial_triangles(msh: dmesh.Mesh) -> None:
    """Raise InputError unless ``msh`` is a serial mesh of affine triangles (for callers that run serially only)."""
    if msh.comm.size > 1:
        raise InputError(
            f"this part of the mixed (Arnold–Winther) method runs in serial only; got {msh.comm.size} MPI ranks. "
            "Run it without mpiexec."
        )
    check_triangles(msh)


def contact_modulus(msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, E: fem.Function, *, smallest: bool = False
                    ) -> float:
    """Largest (``smallest``: smallest) Young's modulus of the cells touching Γ_C (over all ranks)."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    facets = facet_tags.find(Boundary.GAMMA_C)
    cells = np.unique(np.concatenate([f2c.links(f) for f in facets] or [[]])).astype(np.int32)
    if msh.comm.allreduce(int(cells.size), op=MPI.SUM) == 0:
        raise InputError("the mesh has no Γ_C facets")
    if smallest:
        return float(msh.comm.allreduce(float(np.min(E.x.array[cells], initial=np.inf)), op=MPI.MIN))
    return float(msh.comm.allreduce(float(np.max(E.x.array[cells], initial=-np.inf)), op=MPI.MAX))


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
# Point evaluation of DG P3 stresses (numpy / scipy, on the owned cells of a rank)
# ---------------------------------------------------------------------------


def _reference_coordinates(msh: dmesh.Mesh, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Reference coordinates (N, 2) of physical points x (N, 2) in affine triangles ``cells`` (N,)."""
    gx = msh.geometry.x[msh.geometry.dofmaps[0][cells]][:, :, :2]
    v0 = gx[:, 0]
    J = np.stack([gx[:, 1] - v0, gx[:, 2] - v0], axis=-1)
    return np.linalg.solve(J, (x - v0)[..., None])[..., 0]


def _stress_evaluation(dg: fem.FunctionSpace, cells: np.ndarray, X: np.ndarray, weights: np.ndarray) -> sp.csr_matrix:
    """Sparse E with (E s)_p = Σ_j weights[p, j] s_j(x_p) for owned DG P3 stress coefficients s.

    ``cells`` (N,) owned cells, reference points ``X`` (N, 2), component weights (N, 3) on (σ_xx, σ_xy, σ_yy).
    """
    el = dg.ufl_element().sub_elements[0].basix_element
    npts = np.asarray(cells).size
    n_dg = 3 * dg.dofmap.index_map.size_local
    if npts == 0:
        return sp.csr_matrix((0, n_dg))
    phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 10): basis function k at point p
    dofs = dg.dofmap.list[cells].astype(np.int64)  # (N, 10) block indices
    cols = 3 * dofs[:, :, None] + np.arange(3)  # (N, 10, 3)
    vals = phi[:, :, None] * weights[:, None, :]
    rows = np.broadcast_to(np.arange(npts)[:, None, None], cols.shape)
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


def _owned_cell_facets(msh: dmesh.Mesh, facets: np.ndarray) -> np.ndarray:
    """The facets (of a tag) whose first cell is owned by this rank: every exterior facet on exactly one rank."""
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    f2c = msh.topology.connectivity(tdim - 1, tdim)
    facets = np.asarray(facets, dtype=np.int32)
    if facets.size == 0:
        return facets
    first = f2c.array[f2c.offsets[facets]]
    return facets[first < msh.topology.index_map(tdim).size_local]


class _BoundaryFacets:
    """Exterior facets of one tag whose cell this rank owns: cells, end points, outward unit normals."""

    def __init__(self, msh: dmesh.Mesh, facets: np.ndarray) -> None:
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        msh.topology.create_connectivity(tdim - 1, 0)
        msh.topology.create_connectivity(0, tdim)
        f2c = msh.topology.connectivity(tdim - 1, tdim)
        self.facets = _owned_cell_facets(msh, facets)
        counts = np.diff(f2c.offsets)[self.facets]
        if msh.comm.size == 1 and np.any(counts != 1):
            raise InputError("a boundary-tagged facet is not on the boundary of the (sub)mesh")
        self.cells = f2c.array[f2c.offsets[self.facets]].astype(np.int32)
        f2v = msh.topology.connectivity(tdim - 1, 0).array.reshape(-1, 2)
        self.vertices = f2v[self.facets].astype(np.int32)  # topology vertices of the end points a, b
        x = msh.geometry.x[:, :2]
        if self.facets.size:
            geo = dmesh.entities_to_geometry(msh, 0, self.vertices.ravel().astype(np.int32)).reshape(-1, 2)
        else:
            geo = np.zeros((0, 2), dtype=np.int32)
        self.a, self.b = x[geo[:, 0]], x[geo[:, 1]]
        d = self.b - self.a
        self.length = np.linalg.norm(d, axis=1)
        n = np.stack([d[:, 1], -d[:, 0]], axis=1) / np.maximum(self.length[:, None], 1e-300)
        centre = x[msh.geometry.dofmaps[0][self.cells]][:, :, :2].mean(axis=1)
        flip = np.sum(n * (0.5 * (self.a + self.b) - centre), axis=1) < 0
        n[flip] *= -1.0
        self.normal = n

    def lobatto_nodes(self, vertex_gid: np.ndarray) -> tuple[np.ndarray, ...]:
        """Nodes of the per-edge 4-point Gauss–Lobatto rule, per facet (not merged).

        Returns points (4F, 2), weights (4F,), the facet's cell, the outward normal, and the
        global number of vertex nodes (−1 inside edges).
        """
        pts = self.a[:, None, :] + _LOBATTO_S[None, :, None] * (self.b - self.a)[:, None, :]  # (F, 4, 2)
        wts = self.length[:, None] * _LOBATTO_W[None, :]
        F = self.facets.size
        vertex = np.full((F, 4), -1, dtype=np.int64)
        if F:
            vertex[:, 0], vertex[:, 3] = vertex_gid[self.vertices[:, 0]], vertex_gid[self.vertices[:, 1]]
        cells = np.repeat(self.cells, 4)
        normals = np.repeat(self.normal, 4, axis=0)
        return pts.reshape(-1, 2), wts.ravel(), cells, normals, vertex.ravel()

    def locate(self, points: np.ndarray, tol: float = 1e-10) -> tuple[np.ndarray, np.ndarray]:
        """(found, facet): whether each point lies on one of these facets, and the index (into ``facets``) of one."""
        if self.facets.size == 0 or points.shape[0] == 0:
            return np.zeros(points.shape[0], dtype=bool), np.zeros(points.shape[0], dtype=np.int64)
        d = self.b - self.a
        rel = points[:, None, :] - self.a[None, :, :]  # (P, F, 2)
        s = np.einsum("pfi,fi->pf", rel, d) / self.length[None, :] ** 2
        dist = np.linalg.norm(rel - s[..., None] * d[None], axis=-1)
        ok = (dist <= tol * self.length[None, :]) & (s >= -tol) & (s <= 1 + tol)
        return ok.any(axis=1), np.argmax(ok, axis=1)


def _merge_contact_nodes(comm, pts, wts, normals, vertex):
    """Gauss–Lobatto nodes of all ranks, copies of a vertex shared by two edges with the same normal merged.

    Returns the replicated, canonically ordered (``profile_order``) points, weights, normals and vertex
    numbers, and for this rank (local node index, canonical index) of the copies it evaluates
    (the first copy of each merged node in rank order).
    """
    local_n = pts.shape[0]
    if comm.size > 1:
        parts = comm.allgather((pts, wts, normals, vertex))
        start = int(sum(p[0].shape[0] for p in parts[: comm.rank]))
        pts, wts, normals, vertex = (np.concatenate([p[i] for p in parts]) for i in range(4))
    else:
        start = 0
    key = np.where(vertex >= 0, vertex, -1 - np.arange(vertex.size))
    nkey = np.round(normals * 1e8).astype(np.int64)
    _, first, inverse = np.unique(
        np.stack([key, nkey[:, 0], nkey[:, 1]], axis=1), axis=0, return_index=True, return_inverse=True
    )
    merged_w = np.zeros(first.size)
    np.add.at(merged_w, inverse.ravel(), wts)
    order = profile_order(pts[first])
    first = first[order]
    mine = (first >= start) & (first < start + local_n)
    mine_rows = np.flatnonzero(mine)
    return (pts[first], merged_w[order], normals[first], vertex[first], first[mine] - start, mine_rows)


# ---------------------------------------------------------------------------
# Assembly helpers
# ---------------------------------------------------------------------------


def _norm(a: np.ndarray, comm=None) -> float:
    return float(np.sqrt(_dot(a, a, comm)))


def _dot(a: np.ndarray, b: np.ndarray, comm=None) -> float:
    """a·b over all ranks (owned entries; no BLAS: OpenBLAS threads contend with MUMPS on small machines)."""
    return global_dot(comm, a, b) if comm is not None else float(np.einsum("i,i->", a, b))


def _assemble_vector(form) -> np.ndarray:
    b = fem.assemble_vector(fem.form(form))
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    return b.array.copy()


def _without_product_data(C: PETSc.Mat) -> PETSc.Mat:
    """A copy of a product C = PᵀAP (or A P) without the intermediate data PETSc keeps in C for a reuse
    (the size of A P: as much again as P), which is never needed here."""
    out = C.duplicate(copy=True)
    C.destroy()
    return out


def _assemble_petsc(form) -> PETSc.Mat:
    A = dolfinx.fem.petsc.assemble_matrix(fem.form(form))
    A.assemble()
    return A


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

    **Distributed data.**  The state (``c``: AW coefficients, ``u``: DG P1 coefficients)
    holds this rank's owned entries; the bulk operators (K, B, M, the Robin term, P) are
    distributed PETSc matrices (``fem.distributed.DistributedMatrix``).  The Γ_C node data
    (σ_c, weights, gap, the active set) and the γ node coordinates are replicated: every
    rank holds all of them in the same order and takes the same Newton decisions from
    them (active sets, cycle detection, line search), with every scalar of the
    iteration (energies, norms) a global reduction.  The Robin data g and the trace σn
    on γ are distributed by blocks of the canonical γ values (``interface_range``).

    Args:
        msh, facet_tags, fields: the (sub)mesh, its Γ_C / γ tags and DG0 materials.
        epsilon: mixed penalty ε (None: no contact term; Γ_C facets still get σ_t = 0).
        beta: Robin coefficient β on γ (None: no Robin term).
        prefix: PETSc options prefix of the direct solver.
        newton: step cap and residual tolerances.
        space: a prebuilt AW space on ``msh`` (with σ_t = 0 on Γ_C), e.g. with the
            interface split of the monolithic reference (``boundary_stress_space``).
        line_search: ``"on-cycle"`` (full semismooth Newton steps until a cycle
            is detected, then exact line search on J) or ``"always"``.
        interface_points: the γ nodes in the order to use for the Robin data
            (replicated; default: this mesh's γ nodes sorted by (y, x)).
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
        space: ArnoldWintherSpace | None = None,
        line_search: str = "on-cycle",
        interface_points: np.ndarray | None = None,
        operators: bool = True,
    ) -> None:
        t0 = time.perf_counter()
        if line_search not in ("on-cycle", "always"):
            raise InputError(f"line_search must be 'on-cycle' or 'always', got {line_search!r}")
        self.line_search = line_search
        check_triangles(msh)
        if epsilon is not None and not (np.isfinite(epsilon) and epsilon > 0):
            raise InputError(f"the mixed penalty parameter ε must be > 0, got {epsilon}")
        if beta is not None and not (np.isfinite(beta) and beta > 0):
            raise InputError(f"the transmission coefficient β must be > 0, got {beta}")
        self.mesh, self.facet_tags, self.prefix, self.newton = msh, facet_tags, prefix, newton
        self.comm = msh.comm
        self.epsilon, self.beta = epsilon, beta
        self.contact = epsilon is not None
        self.fields = fields
        contact_facets = facet_tags.find(Boundary.GAMMA_C)
        has_contact = self.comm.allreduce(int(contact_facets.size), op=MPI.SUM) > 0
        if self.contact and not has_contact:
            if fields.obstacle is not None:
                raise InputError(
                    "an obstacle is given but the mesh has no contact boundary: the physical group 'Gamma_C' "
                    "has no facets (tag the facets that may touch the obstacle as Gamma_C)"
                )
            raise InputError("a contact subproblem needs Γ_C facets")
        self.space = space or boundary_stress_space(msh, facet_tags, fields.boundary)
        # P as a PETSc matrix (0.34 s and 270 MB for Ω₁ at h = 1/128): made when first used, unless the operators
        # need it now or the mesh is distributed (its creation is collective)
        self._Pd_matrix: DistributedMatrix | None = None
        if operators or self.comm.size > 1:
            self._Pd_matrix = DistributedMatrix(self.space.prolongation_petsc)
        self.dg = self.space.dg
        self.U = fem.functionspace(msh, basix.ufl.element("DG", msh.basix_cell(), 1, shape=(2,)))
        self.n_sigma = self.space.num_owned
        self.n_u = 2 * self.U.dofmap.index_map.size_local
        n_dg = 3 * self.dg.dofmap.index_map.size_local
        self._n_dg = n_dg

        # -- bulk operators ------------------------------------------------------------
        s, t = ufl.TrialFunction(self.dg), ufl.TestFunction(self.dg)
        w, v = ufl.TrialFunction(self.U), ufl.TestFunction(self.U)
        n = ufl.FacetNormal(msh)
        self.has_operators = operators
        self._K = self._B = self._R = None
        if operators:
            P_petsc = self.space.prolongation_petsc
            A = _assemble_petsc(forms_mixed.compliance_form(s, t, fields.lmbda, fields.mu))
            self._K = DistributedMatrix(_without_product_data(A.PtAP(P_petsc)))
            A.destroy()
            D = _assemble_petsc(forms_mixed.divergence_form(s, v))
            self._B = DistributedMatrix(_without_product_data(D.matMult(P_petsc)))
            D.destroy()
        self._M = DistributedMatrix(_assemble_petsc(forms_mixed.mass_form(w, v)))
        self.G = _assemble_vector(forms_mixed.load_form(fields.f, v))[: self.n_u]

        # -- boundary data: traction lifting σ_t (σ = P c + σ_t) and the natural Γ_D term ------
        lifting = self.space.lifting_dg
        self.s0 = np.zeros(n_dg) if lifting is None else lifting[:n_dg].copy()
        self._lifted = bool(self.comm.allreduce(bool(np.any(self.s0)), op=MPI.LOR))
        self._F_boundary = np.zeros(self.n_sigma)  # constant stress-side load of the lifting and of u_D
        if self._lifted:
            s0 = fem.Function(self.dg)
            s0.x.array[:n_dg] = self.s0
            s0.x.scatter_forward()
            self.G -= _assemble_vector(forms_mixed.divergence_form(s0, v))[: self.n_u]
            self._F_boundary -= self._Pd.T @ _assemble_vector(
                forms_mixed.compliance_form(s0, t, fields.lmbda, fields.mu))[:n_dg]
            self._s0_function = s0
        self.u_D: fem.Function | None = None
        has_dirichlet = self.comm.allreduce(int(facet_tags.find(Boundary.GAMMA_D).size), op=MPI.SUM) > 0
        if fields.boundary.displacement is not None and has_dirichlet:
            self.u_D = displacement_trace_function(msh, fields.boundary.displacement)
            dsD = forms_mixed.boundary_measure(msh, facet_tags)(Boundary.GAMMA_D)
            self._F_boundary += self._Pd.T @ _assemble_vector(forms_mixed.robin_data_form(self.u_D, t, n, dsD))[:n_dg]

        # -- Robin term and data on γ -------------------------------------------------
        ds = forms_mixed.boundary_measure(msh, facet_tags)
        self._Kt = self._K
        self.gamma_points = np.zeros((0, 2))
        self.interface_range = (0, 0)
        if beta is not None:
            gamma = facet_tags.find(Boundary.INTERFACE)
            if self.comm.allreduce(int(gamma.size), op=MPI.SUM) == 0:
                raise InputError("a Robin subproblem needs interface (γ) facets")
            if operators or self._lifted:
                R_dg = _assemble_petsc(forms_mixed.robin_form(s, t, n, 1.0, ds(Boundary.INTERFACE)))
                if operators:
                    self._R = DistributedMatrix(_without_product_data(R_dg.PtAP(P_petsc)))
                    Kt = self._K.mat.duplicate(copy=True)
                    Kt.axpy(beta, self._R.mat, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                    self._Kt = DistributedMatrix(Kt)
                if self._lifted:  # (also without operators: Algorithm 4's Ω₁ reads s0, G and n0)
                    y = R_dg.createVecLeft()
                    x = R_dg.createVecRight()
                    x.array[:] = self.s0
                    R_dg.mult(x, y)
                    self._F_boundary -= beta * (self._Pd.T @ y.array)
                    x.destroy()
                    y.destroy()
                R_dg.destroy()
            self._setup_interface(gamma, ds, t, n, interface_points)

        # -- contact quadrature and obstacle ----------------------------------------------
        self._F_gap = np.zeros(self.n_sigma)
        self.obstacle = None
        self._has_contact_nodes = has_contact
        if has_contact:
            self._setup_contact(msh, facet_tags, contact_facets)
            self.set_obstacle(fields.obstacle)

        self.c = np.zeros(self.n_sigma)
        self.u = np.zeros(self.n_u)
        self._cold = True
        self._solver: DirectSolver | None = None
        self._saddle: SaddlePointMatrix | None = None
        self._factorized_set: np.ndarray | None = None
        self._rhs = self._sol = None
        self.build_time = time.perf_counter() - t0

    @property
    def P(self) -> sp.csr_matrix:
        """Local P (SciPy): owned DG rows × local AW columns (owned, then ghosts); in serial the whole P (made
        when first asked for: ``ArnoldWintherSpace.prolongation``)."""
        return self.space.prolongation

    @property
    def _Pd(self) -> DistributedMatrix:
        """P (owned DG rows × AW DOFs) as a ``DistributedMatrix``."""
        if self._Pd_matrix is None:
            self._Pd_matrix = DistributedMatrix(self.space.prolongation_petsc)
        return self._Pd_matrix

    # -- the operators as SciPy matrices (serial consumers: interface Newton, multiscale, tests) ----
    def _scipy(self, name: str) -> sp.csr_matrix:
        cache = self.__dict__.setdefault("_scipy_cache", {})
        if name not in cache:
            op = self.__dict__.get(f"_{name}")
            if op is None:
                raise AttributeError(f"this subproblem has no operator {name}")
            cache[name] = op.local_csr()
        return cache[name]

    K = property(lambda self: self._scipy("K"), doc="Pᵀ A P (compliance) as SciPy CSR: owned rows, global columns.")
    Kt = property(lambda self: self._scipy("Kt"), doc="K + β R (the stress block of the Jacobian), SciPy CSR.")
    B = property(lambda self: self._scipy("B"), doc="B P (divergence), SciPy CSR: owned DG P1 rows, global AW columns.")
    M = property(lambda self: self._scipy("M"), doc="DG P1 mass matrix, SciPy CSR.")
    R = property(lambda self: self._scipy("R"), doc="Pᵀ R_γ P (the Robin form with β = 1), SciPy CSR.")
    Q = property(lambda self: self._scipy("Q"), doc="σ_c at the contact nodes, SciPy CSR: this rank's rows, global columns.")
    C = property(lambda self: self._scipy("C"), doc="Robin data → stress load, SciPy CSR: owned rows, canonical γ columns.")
    N = property(lambda self: self._scipy("N"), doc="σn at the γ nodes, SciPy CSR: this rank's block of rows, global columns.")


    # -- setup pieces -----------------------------------------------------------------
    def _setup_interface(self, gamma: np.ndarray, ds, t, n, points: np.ndarray | None) -> None:
        """Robin data space on γ: continuous vector P3 on γ (the normal-trace space of AW)."""
        msh, comm = self.mesh, self.comm
        Lam = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 3, shape=(2,)))
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, tdim)
        blocks = fem.locate_dofs_topological(Lam, tdim - 1, gamma)
        coords = Lam.tabulate_dof_coordinates()[blocks, :2]
        gblocks = Lam.dofmap.index_map.local_to_global(blocks.astype(np.int32)).astype(np.int64)
        if comm.size > 1:
            parts = comm.allgather((gblocks, coords))
            all_g = np.concatenate([p[0] for p in parts])
            all_x = np.concatenate([p[1] for p in parts])
            all_g, first = np.unique(all_g, return_index=True)
            all_x = all_x[first]
        else:
            all_g, all_x = gblocks, coords
        order = np.lexsort((all_x[:, 0], all_x[:, 1]))
        all_g, all_x = all_g[order], all_x[order]
        if points is not None:  # use the given order (the other subdomain's γ nodes)
            points = np.asarray(points, dtype=np.float64)[:, :2]
            dist, perm = cKDTree(all_x).query(points)
            if points.shape != all_x.shape or np.max(dist, initial=0.0) > 1e-10 or np.unique(perm).size != perm.size:
                raise InputError("the interface nodes of Ω₁ and Ω₂ do not match (γ must be conforming)")
            all_g, all_x = all_g[perm], all_x[perm]
        self.gamma_points = all_x
        n_nodes = all_x.shape[0]
        n_g = 2 * n_nodes
        g0, g1 = layout(comm, n_g)
        #: (start, end) of this rank's block of the γ values (x, y per node, canonical order)
        self.interface_range = (g0, g1)
        sort = np.argsort(all_g)
        g_sorted = all_g[sort]

        def canonical_value(global_dof: np.ndarray) -> np.ndarray:
            blk, comp = global_dof // 2, global_dof % 2
            pos = np.minimum(np.searchsorted(g_sorted, blk), max(g_sorted.size - 1, 0))
            hit = g_sorted[pos] == blk if g_sorted.size else np.zeros(blk.size, dtype=bool)
            return np.where(hit, 2 * sort[pos] + comp, -1)

        # d(g; τ) = C g:  Pᵀ C_dg S, S the canonical γ values -> P3 functions on γ
        g = ufl.TrialFunction(Lam)
        Cdg = _assemble_petsc(forms_mixed.robin_data_form(g, t, n, ds(Boundary.INTERFACE)))
        ci, cj, cv = Cdg.getValuesCSR()
        Cdg.destroy()
        rows = np.repeat(np.arange(ci.size - 1), np.diff(ci))
        cols = canonical_value(cj.astype(np.int64))
        keep = cols >= 0
        C_local = sp.csr_matrix((cv[keep], (rows[keep], cols[keep])), shape=(self._n_dg, n_g))
        P_gamma = self.space.prolongation_for_rows(np.flatnonzero(np.diff(C_local.indptr)))
        C_red = (P_gamma.T @ C_local).tocoo()  # local AW rows (owned, ghosts) × canonical γ values
        gi = self.space.global_indices
        #: d(g; τ) = C g for interface data g = values (x, y) at ``gamma_points`` (this rank's block)
        self._C = DistributedMatrix(coo_matrix(comm, gi[C_red.row], C_red.col, C_red.data,
                                              (self.n_sigma, self.space.num_dofs), (g1 - g0, n_g)))
        # L²(γ) mass matrix of the continuous P3 data, canonical values × canonical values (the γ norm of the
        # convergence certificate); the owned Lagrange rows of every rank, mapped like the columns
        w = ufl.TestFunction(Lam)
        Mg = _assemble_petsc(ufl.inner(g, w) * ds(Boundary.INTERFACE))
        mi, mj, mv = Mg.getValuesCSR()
        m_rows = canonical_value(Mg.getOwnershipRange()[0] + np.repeat(np.arange(mi.size - 1), np.diff(mi)))
        Mg.destroy()
        m_cols = canonical_value(mj.astype(np.int64))
        keep = (m_rows >= 0) & (m_cols >= 0)
        self._gamma_mass = DistributedMatrix(coo_matrix(comm, m_rows[keep], m_cols[keep], mv[keep],
                                                        (g1 - g0, n_g), (g1 - g0, n_g)))
        # trace σn at the γ nodes (exact: σn is a P3 polynomial on each γ edge, continuous at vertices),
        # each node evaluated by the lowest rank holding one of its facets with an owned cell
        bf = _BoundaryFacets(msh, gamma)
        found, idx = bf.locate(all_x)
        mine = np.where(found, comm.rank, comm.size).astype(np.int32)
        owner = np.empty_like(mine)
        comm.Allreduce(mine, owner, op=MPI.MIN)
        if np.any(owner >= comm.size):
            raise RuntimeError("a γ node does not lie on the γ facets")
        nodes = np.flatnonzero(owner == comm.rank)
        cells, normals = bf.cells[idx[nodes]], bf.normal[idx[nodes]]
        X = _reference_coordinates(msh, cells, all_x[nodes])
        wx, wy = _traction_weights(normals)
        E = sp.vstack([_stress_evaluation(self.dg, cells, X, wx), _stress_evaluation(self.dg, cells, X, wy)]).tocsr()
        value_rows = np.concatenate([2 * nodes, 2 * nodes + 1])  # canonical value of each row of E
        N_loc = (E @ self.space.prolongation_for_rows(np.unique(E.indices))).tocoo()
        #: σn (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block: N c (+ ``n0``)
        self._N = DistributedMatrix(coo_matrix(comm, value_rows[N_loc.row], gi[N_loc.col], N_loc.data,
                                              (g1 - g0, n_g), (self.n_sigma, self.space.num_dofs)))
        #: σ_t n on γ (the traction lifting's trace; zero without tractions), this rank's block
        self.n0 = gather_rows(comm, value_rows, E @ self.s0, n_g)[g0:g1]
        self.gamma_normal = gather_rows(comm, nodes, normals, n_nodes)

    def _setup_contact(self, msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, facets: np.ndarray) -> None:
        """Q: σ_c at the Gauss–Lobatto nodes of Γ_C (a Lagrange basis of the σ_c trace space)."""
        comm = self.comm
        bf = _BoundaryFacets(msh, facets)
        vertex_gid = self.space.global_vertex_indices
        pts, wq, cells, normals, vertex = bf.lobatto_nodes(vertex_gid)
        (self.q_points, self.q_weights, self.q_normals, q_vertex, local_nodes,
         rows) = _merge_contact_nodes(comm, pts, wq, normals, vertex)
        nq = self.q_points.shape[0]
        self._q_rows = rows  #: canonical index of the contact nodes this rank evaluates
        self._q_range = layout(comm, nq)
        cells, normals = cells[local_nodes], normals[local_nodes]
        X = _reference_coordinates(msh, cells, pts[local_nodes])
        Q_dg = _stress_evaluation(self.dg, cells, X, _normal_weights(normals))
        Q_loc = (Q_dg @ self.space.prolongation_for_rows(np.unique(Q_dg.tocsr().indices))).tocsr()
        Q_loc.eliminate_zeros()
        gi = self.space.global_indices
        #: this rank's rows of Q with global AW columns (the penalty pattern of the saddle-point matrix)
        self._Q_rows_global = sp.csr_matrix((Q_loc.data, gi[Q_loc.indices], Q_loc.indptr),
                                            shape=(Q_loc.shape[0], self.space.num_dofs))
        self._Q_local = Q_loc
        Qc = Q_loc.tocoo()
        #: σ_c at the contact nodes (canonical order), this rank's block of rows: Q c (+ ``q0``)
        self._Q = DistributedMatrix(coo_matrix(comm, rows[Qc.row], gi[Qc.col], Qc.data,
                                              (self._q_range[1] - self._q_range[0], nq),
                                              (self.n_sigma, self.space.num_dofs)))
        #: σ_t,c at the contact nodes (the traction lifting's normal stress; zero without tractions), replicated
        self.q0 = gather_rows(comm, rows, Q_dg @ self.s0, nq)
        # u_h·n at the nodes from the DG P1 displacement (one adjacent cell per node)
        el = self.U.ufl_element().sub_elements[0].basix_element
        if cells.size:
            phi = el.tabulate(0, X)[0, :, :, 0]  # (N, 3)
            dofs = self.U.dofmap.list[cells].astype(np.int64)
            ucols = 2 * dofs[:, :, None] + np.arange(2)
            vals = phi[:, :, None] * normals[:, None, :]
            urows = np.broadcast_to(np.arange(cells.size)[:, None, None], ucols.shape)
            self._Un = sp.csr_matrix((vals.ravel(), (urows.ravel(), ucols.ravel())), shape=(cells.size, self.n_u))
        else:
            self._Un = sp.csr_matrix((0, self.n_u))
        # nodes on Γ_D (the clamped corners) are left out of the profile, as in the primal one
        tdim = msh.topology.dim
        msh.topology.create_connectivity(tdim - 1, 0)
        f2v = msh.topology.connectivity(tdim - 1, 0).array.reshape(-1, 2)
        dirichlet = facet_tags.find(Boundary.GAMMA_D)
        clamped = vertex_gid[f2v[dirichlet].ravel()] if dirichlet.size else np.zeros(0, np.int64)
        if comm.size > 1:
            clamped = np.concatenate(comm.allgather(clamped))
        self._profile_nodes = ~np.isin(q_vertex, clamped) | (q_vertex < 0)

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
            self.q_gap, nu = evaluate_obstacle(obstacle, self.q_points)
            check_obstacle_side(obstacle, nu, self.q_normals, self.q_gap)  # (replicated contact nodes: no comm)
        self._F_gap = self._Q.T @ self._q_block(self.q_weights * self.q_gap)
        self.obstacle = obstacle

    def _q_block(self, values: np.ndarray) -> np.ndarray:
        """This rank's block (rows of ``Q``) of a replicated array over the contact nodes."""
        return values[self._q_range[0] : self._q_range[1]]

    def _replicate_q(self, block: np.ndarray) -> np.ndarray:
        """The replicated array over the contact nodes from every rank's block (canonical order)."""
        return block if self.comm.size == 1 else np.concatenate(self.comm.allgather(block))

    def _stress_load(self, data: np.ndarray | None) -> np.ndarray:
        """The σ-row right-hand side: Robin data C g, traction lifting, ∫_ΓD u_D·τn and ∫_ΓC g τ_c."""
        load = self._F_boundary + self._F_gap
        return load if data is None else load + self._C @ data

    def _contact_stress(self, c: np.ndarray) -> np.ndarray:
        """σ_c at the contact nodes of the stress P c + σ_t (replicated)."""
        return self._replicate_q(self._Q @ c) + self.q0

    def contact_stress(self) -> np.ndarray:
        """σ_c at the contact nodes (``q_points``) of the current stress, replicated on every rank."""
        return self._contact_stress(self.c)

    def gamma_mass_matrix(self) -> DistributedMatrix:
        """L²(γ) mass matrix M of the Robin data (canonical γ values, this rank's block): ‖g‖²_γ = Σ_ranks g·(M g)."""
        if self.beta is None:
            raise InputError("this subproblem has no interface γ")
        return self._gamma_mass

    def gamma_traction(self) -> np.ndarray:
        """σn on γ (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block."""
        return self._N @ self.c + self.n0

    # -- sizes ------------------------------------------------------------------------
    @property
    def num_dofs(self) -> dict[str, int]:
        """Global stress (AW), displacement and total DOF counts."""
        n_u = self.U.dofmap.index_map.size_global * 2
        return {"sigma": self.space.num_dofs, "u": n_u, "total": self.space.num_dofs + n_u}

    # -- linear algebra -----------------------------------------------------------------
    @property
    def solver(self) -> DirectSolver:
        """The direct solver (created at the first factorization: its PETSc options are set then)."""
        if self._solver is None:
            self._solver = DirectSolver(self.comm, prefix=self.prefix, options=MIXED_SOLVER_OPTIONS)
        return self._solver

    def _penalty_matrix(self, active: np.ndarray) -> sp.csr_matrix:
        """(1/ε) Qᵀ W H Q for the penalty-active nodes, this rank's rows of Q (local AW columns; serial: all)."""
        act = active[self._q_rows]
        Qa = self._Q_local[np.flatnonzero(act)]
        return (Qa.T @ sp.diags(self.q_weights[self._q_rows][act] / self.epsilon) @ Qa).tocsr()

    def _factorize_for(self, active: np.ndarray | None) -> bool:
        """Factorize the saddle-point Jacobian unless the cached one has the same active set."""
        if not self.has_operators:
            raise InputError("this subproblem was built without its matrices (operators=False): it cannot be solved")
        key = np.zeros(0, dtype=bool) if active is None else active
        if self._factorized_set is not None and np.array_equal(key, self._factorized_set):
            return False
        if self._saddle is None:
            # one sparsity pattern for every active set (all Γ_C nodes): when the active set changes
            # only the penalty values change and MUMPS redoes the numeric factorization, not the analysis
            Q_rows = self._Q_rows_global if (self.contact and self._has_contact_nodes) else None
            self._saddle = SaddlePointMatrix(self._Kt.mat, self._B.mat, Q_rows)
            self._rhs, self._sol = self._saddle.create_vecs()
        if active is None or not self.contact:
            self._saddle.set_weights(None)
        else:
            rows = self._q_rows
            self._saddle.set_weights(np.where(active[rows], self.q_weights[rows] / self.epsilon, 0.0))
        self.solver.set_operator(self._saddle.mat)
        self._factorized_set = key.copy()
        return True

    def _solve(self, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._rhs.array[: self.n_sigma] = r1
        self._rhs.array[self.n_sigma :] = r2
        self.solver.solve(self._rhs, self._sol)
        x = self._sol.array
        return x[: self.n_sigma].copy(), x[self.n_sigma :].copy()

    # -- residual, energy ---------------------------------------------------------------
    def _penalty_force(self, s: np.ndarray) -> np.ndarray:
        """(1/ε) Qᵀ W (σ_c)⁺ for replicated σ_c (owned AW entries)."""
        return self._Q.T @ self._q_block(self.q_weights * np.maximum(s, 0.0) / self.epsilon)

    def _gradient(self, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(F_σ, F_u) at the current (σ, u) for the stress-side load (C g)."""
        F1 = self._Kt @ self.c + self._B.T @ self.u - load
        if self.contact:
            F1 += self._penalty_force(self._contact_stress(self.c))
        return F1, self._B @ self.c - self.G

    def _scale(self, load: np.ndarray) -> float:
        """Sum of the norms of the terms of the residual (the yardstick of the residual check)."""
        comm = self.comm
        scale = _norm(self._Kt @ self.c, comm) + _norm(self._B.T @ self.u, comm) + _norm(load, comm)
        scale += _norm(self._B @ self.c, comm) + _norm(self.G, comm)
        if self.contact:
            scale += _norm(self._penalty_force(self._contact_stress(self.c)), comm)
        return scale

    def residual(self, data: np.ndarray | None = None) -> tuple[float, float]:
        """(‖F‖, scale) at the current (σ, u) with Robin data g; scale = sum of the norms of the terms."""
        load = self._stress_load(data)
        F1, F2 = self._gradient(load)
        return float(np.sqrt(_dot(F1, F1, self.comm) + _dot(F2, F2, self.comm))), self._scale(load)

    def _line_search(self, dc: np.ndarray, s: np.ndarray, d: np.ndarray, load: np.ndarray) -> float:
        """argmin_{t ∈ (0, 1]} J(σ + t dσ): root of the increasing piecewise-linear φ'(t) (s, d replicated)."""
        a = _dot(dc, self._Kt @ dc, self.comm)
        b0 = _dot(self._Kt @ self.c - load, dc, self.comm)
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
        """Solve with Robin data g (this rank's block of the γ values), warm-started from the current (σ, u)."""
        load = self._stress_load(data)
        history = MixedNewtonHistory()
        comm = self.comm
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
            history.residuals.append(float(np.sqrt(_dot(F1, F1, comm) + _dot(F2, F2, comm))))
            history.factorizations += self._factorize_for(active)
            feasible = _norm(F2, comm) <= 1e-10 * (_norm(self.G, comm) + _norm(self._B @ self.c, comm))
            dc, du = self._solve(-F1, -F2)
            d = self._replicate_q(self._Q @ dc)
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
        """σ_h as a DG P3 function of (σ_xx, σ_xy, σ_yy) (collective)."""
        out = fem.Function(self.dg, name=name) if out is None else out
        out.x.array[: self._n_dg] = self._Pd @ self.c + self.s0
        out.x.scatter_forward()
        return out

    def u_function(self, out: fem.Function | None = None, name: str = "u") -> fem.Function:
        """u_h as a DG P1 vector function."""
        out = fem.Function(self.U, name=name) if out is None else out
        out.x.array[: self.n_u] = self.u
        out.x.scatter_forward()
        return out

    def stress_norm2(self, c: np.ndarray) -> float:
        """‖σ‖²_A = (Aσ, σ) of (owned) AW coefficients c (collective)."""
        return _dot(c, self._K @ c, self.comm)

    def l2_norm2(self, u: np.ndarray) -> float:
        """‖u‖²_L² of (owned) DG P1 coefficients u (collective)."""
        return _dot(u, self._M @ u, self.comm)

    def complementary_energy(self, data: np.ndarray | None = None) -> float:
        """J(σ) = ½(Aσ,σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε)∫_ΓC ((σ_c)⁺)² at the current σ."""
        J = 0.5 * _dot(self.c, self._Kt @ self.c, self.comm) - _dot(self._stress_load(data), self.c, self.comm)
        if self.contact:
            J += 0.5 * np.sum(self.q_weights * np.maximum(self._contact_stress(self.c), 0.0) ** 2) / self.epsilon
        return float(J)

    def contact_profile(self) -> MixedContactProfile:
        """σ_c and u_c = −(σ_c)⁺/ε at the Γ_C contact nodes (clamped corners excluded), sorted; on every rank."""
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
        un = gather_rows(self.comm, self._q_rows, self._Un @ self.u, self.q_points.shape[0])
        return self.q_points[keep, 1], un[keep]

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
        r1 = self._Pd.T @ _assemble_vector(Ft)[: self._n_dg]
        if data is not None:
            r1 -= self._C @ data
        r2 = _assemble_vector(Fv)[: self.n_u]
        _, scale = self.residual(data)
        return float(np.sqrt(_dot(r1, r1, self.comm) + _dot(r2, r2, self.comm))), scale

    def fit_stress(self, values: np.ndarray) -> tuple[np.ndarray, float]:
        """Owned AW coefficients c with P c + σ_t closest to a DG P3 stress (owned ``dg`` entries) in ℓ².

        Returns c and the relative misfit ‖P c + σ_t − values‖ / ‖values − σ_t‖ (0 when the stress is in
        the space); PᵀP c = Pᵀ(values − σ_t) is solved with MUMPS (collective).
        """
        comm = self.comm
        P = self.space.prolongation_petsc
        d = np.asarray(values, dtype=np.float64) - self.s0
        PtP = P.transposeMatMult(P)
        solver = DirectSolver(comm, prefix=f"{self.prefix}fit_")
        try:
            solver.set_operator(PtP)
            rhs, x = PtP.createVecs()
            rhs.array[:] = self._Pd.T @ d
            solver.solve(rhs, x)
            c = x.array.copy()
            for obj in (rhs, x):
                obj.destroy()
        finally:
            solver.destroy()
            PtP.destroy()
        r = self._Pd @ c - d
        misfit = np.sqrt(_dot(r, r, comm)) / max(np.sqrt(_dot(d, d, comm)), 1e-300)
        return c, float(misfit)

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

    def gamma_mass(self) -> DistributedMatrix:
        """The L²(γ) mass matrix of the continuous P3 vector data at ``gamma_points`` (flattened (x, y)), acting
        on this rank's block of the canonical γ values (``interface_range``; serial: all): ``gamma_mass_matrix``."""
        return self.gamma_mass_matrix()

    def destroy(self) -> None:
        """Free the PETSc objects (collective)."""
        if self._saddle is not None:
            self._saddle.destroy()
        for obj in (self._rhs, self._sol):
            if obj is not None:
                obj.destroy()
        if self._solver is not None:
            self._solver.destroy()
        for name in ("_K", "_B", "_M", "_R", "_Q", "_C", "_N", "_gamma_mass"):
            op = self.__dict__.get(name)
            if op is not None:
                op.destroy()
        if self._Kt is not None and self._Kt is not self._K:
            self._Kt.destroy()


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
    msh: dmesh.Mesh, facet_tags: dmesh.MeshTags, boundary: BoundaryConditions, *, split_interface=None,
    basis_comm: MPI.Comm | None = None,
) -> ArnoldWintherSpace:
    """The AW space of a (sub)mesh with the essential stress conditions of its boundary.

    σn·t = 0 on Γ_C; σn = t on the Γ_N groups (a lifting); σn = 0 on every other
    exterior facet that is not Γ_D or γ (traction free).  Γ_D (u = u_D) and γ (Robin)
    are natural.  ``split_interface`` = (γ facets, cells of one side), ``basis_comm`` (ranks holding this same
    serial mesh, which share out its cells' nodal bases): see ``ArnoldWintherSpace``.
    """
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    exterior = dmesh.exterior_facet_indices(msh.topology)
    tagged = np.concatenate(
        [facet_tags.find(t) for t in (Boundary.GAMMA_D, Boundary.GAMMA_C, Boundary.INTERFACE)]
    )
    prescribed = []
    for tag, _, traction in boundary.traction_tags():  # every group on every rank (same list everywhere)
        prescribed.append((facet_tags.find(tag), traction))
    all_neumann = set(neumann_groups(facet_tags))
    neumann = np.concatenate([facet_tags.find(t) for t in sorted(all_neumann)] or [np.zeros(0, np.int32)])
    free = np.setdiff1d(exterior, np.concatenate([tagged, neumann]))
    return ArnoldWintherSpace(
        msh,
        zero_tangential_facets=facet_tags.find(Boundary.GAMMA_C),
        zero_traction_facets=np.union1d(free, neumann),
        prescribed_tractions=prescribed,
        split_interface=split_interface,
        basis_comm=basis_comm,
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


def epsilon_for(problem: ContactProblem, epsilon: float | None = None) -> float:
    """ε, or when None the default ``default_epsilon(h, E_c)`` with E_c the smallest E on Γ_C."""
    if epsilon is None:
        return default_epsilon(problem.h, problem.contact_modulus(smallest=True))
    if isinstance(epsilon, bool) or not isinstance(epsilon, (int, float, np.number)) \
            or not (np.isfinite(epsilon) and epsilon > 0):
        raise InputError(f"the mixed penalty ε must be a finite number > 0 (or None: the default), got {epsilon!r}")
    return float(epsilon)


def solve_mixed_monolithic(
    problem: ContactProblem,
    *,
    epsilon: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    split_interface: bool = False,
    prefix: str = "fc_mixed_mono_",
    verify: bool = True,
) -> MixedSolution:
    """Mixed penalized contact on the whole mesh (METHOD §2), globalized semismooth Newton (serial or MPI).

    ``epsilon`` defaults to ``default_epsilon(h, E_c)``; ``split_interface`` solves on X̃_h
    (σ_tt doubled at the γ vertices: the exact fixed point of Algorithm 2); ``verify``
    re-checks the final residual with the UFL forms.
    """
    start = time.perf_counter()
    cm = problem.cm
    check_triangles(cm.mesh)
    fields = problem.fields
    usual = epsilon_for(problem)
    epsilon = epsilon_for(problem, epsilon)
    space = None
    if split_interface:
        split = (cm.facet_tags.find(Boundary.INTERFACE), cm.cell_tags.find(Subdomain.OMEGA2))
        space = boundary_stress_space(cm.mesh, cm.facet_tags, fields.boundary, split_interface=split)
    problem = MixedSubproblem(
        cm.mesh, cm.facet_tags, fields, epsilon=epsilon, beta=None, prefix=prefix, newton=newton, space=space,
    )
    t0 = time.perf_counter()
    history = problem.solve()
    t_newton = time.perf_counter() - t0
    if verify:
        norm, scale = problem.ufl_residual_norm()
        if norm > newton.rtol * scale + newton.atol:
            hint = (f"; ε = {epsilon:g} is {usual / epsilon:.0e} times below the default 1e-3·h·E_min = {usual:.3g} "
                    "on Gamma_C, which makes the contact block ill-conditioned: use a larger --epsilon"
                    if epsilon < 1e-3 * usual else "")
            raise ConvergenceError(f"mixed monolithic: the solution misses its own equations (UFL residual "
                                   f"{norm:.3e} > {newton.rtol:g}·{scale:.3e}, the size of their terms): the linear "
                                   f"solves lost accuracy{hint}")
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
