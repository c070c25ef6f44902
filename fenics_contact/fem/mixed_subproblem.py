"""The mixed (Arnold–Winther × DG P1) penalized contact subproblem on one mesh.

    (Aσ_h, τ) + (div τ, u_h) + (1/ε) ∫_ΓC (σ_hc)⁺ τ_c ds [+ β∫_γ (σ_h n)·(τn) ds] = [∫_γ g·(τn) ds]
    (div σ_h, v) = −(f, v)

``MixedSubproblem`` composes the pieces of the ``mixed_*`` modules: spaces and boundary data
(``mixed_spaces``), operators and loads (``mixed_assembly``), the interface γ (``mixed_interface``), the
contact nodes and penalty (``mixed_contact``), the factorization (``mixed_linear``) and the globalized
semismooth Newton (``mixed_newton``).

**Three roles**, like ``fem.primal.PrimalSubproblem``: the monolithic problem (contact, no Robin), the
linear Ω₁ problem (Robin on γ, no contact: one factorization, then one solve per call) and the Ω₂ problem
(contact and Robin: globalized semismooth Newton warm-started from the last solution, refactorized only
when the active set changes).

**Distributed data.**  The state (``c``: AW coefficients, ``u``: DG P1 coefficients) holds this rank's
owned entries; the bulk operators (K, B, M, the Robin term, P) are distributed PETSc matrices
(``fem.distributed.DistributedMatrix``).  The Γ_C node data (σ_c, weights, gap, the active set) and the γ
node coordinates are replicated: every rank holds all of them in the same order and takes the same Newton
decisions from them (active sets, cycle detection, line search), with every scalar of the iteration
(energies, norms) a global reduction.  The Robin data g and the trace σn on γ are distributed by blocks of
the canonical γ values (``interface_range``).

**Units.**  The saddle-point factorizations are equilibrated by E_ref/L_ref (``mixed_linear.stress_scale``; E_ref
``modulus``, by default the smallest Young's modulus of the cells, L_ref the mesh's extent), so the solves keep
their accuracy in any units (E = 2.1e11 in Pa as E = 1, lengths in mm as in m), and the residual checks measure
the residual with the same equilibration (``residual_norm``), both blocks in one unit.
"""

import time

import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.arnold_winther import ArnoldWintherSpace
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.contact_boundary import contact_boundary_present
from fenics_contact.fem.distributed import DistributedMatrix
from fenics_contact.fem.mixed_assembly import MixedOperators, dot, norm
from fenics_contact.fem.mixed_contact import ContactNodes, MixedContactProfile
from fenics_contact.fem.mixed_friction import MixedFriction, frictional_mixed_newton
from fenics_contact.fem.mixed_interface import InterfaceData
from fenics_contact.fem.mixed_linear import (
    SaddlePointFactorization,
    equilibrated_norm,
    equilibrated_size,
    stress_scale,
)
from fenics_contact.fem.mixed_newton import MixedNewtonHistory, globalized_newton
from fenics_contact.fem.mixed_residual import ufl_residual_norm
from fenics_contact.fem.mixed_spaces import MixedSpaces, check_triangles
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import mesh_extent
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.tags import Boundary

__all__ = ["MixedSubproblem"]


def _part(part: str, name: str, doc: str) -> property:
    """A read-only attribute ``name`` of the collaborator ``part``."""
    return property(lambda self: getattr(getattr(self, part), name), doc=doc)


class MixedSubproblem:
    """(Aσ, τ) + (div τ, u) [+ p_ε(σ; τ)] [+ r_β(σ, τ)] = [d(g; τ)],  (div σ, v) = −(f, v) on one mesh.

    Three roles (monolithic, linear Ω₁, nonlinear Ω₂) and the distributed data: see the module docstring.
    The attributes below forward to the collaborators ``spaces``, ``assembly``, ``interface`` (with β),
    ``contact_nodes`` (with Γ_C facets) and ``factorization``.

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
        friction: a friction law on Γ_C (``problem.friction.Friction``; with ε only): σn·t is free there and
            governed by the law on the traction (``fem.mixed_friction``).
        modulus: the reference Young's modulus E_ref of the equilibration of the factorizations
            (``stress_scale`` of E_ref/L_ref, L_ref the mesh's extent; default: the smallest E of its cells).
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
        modulus: float | None = None,
        friction: Friction | None = None,
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
        has_contact = contact_boundary_present(self.comm, contact_facets, fields.obstacle if self.contact else None)
        if self.contact and not has_contact:
            raise InputError("a contact subproblem needs Γ_C facets")
        frictional = friction is not None and self.contact
        self.spaces = MixedSpaces(
            msh,
            facet_tags,
            fields.boundary,
            space=space,
            distribute_P=operators or self.comm.size > 1,
            friction=frictional,
        )
        self.has_operators = operators
        self.assembly = MixedOperators(msh, facet_tags, fields, self.spaces, beta=beta, operators=operators)
        self.interface: InterfaceData | None = None
        if beta is not None:
            gamma = facet_tags.find(Boundary.INTERFACE)
            self.interface = InterfaceData(msh, facet_tags, self.spaces, gamma, interface_points)
        self.contact_nodes: ContactNodes | None = None
        if has_contact:
            self.contact_nodes = ContactNodes(
                msh, facet_tags, contact_facets, self.spaces, epsilon, tangential=frictional
            )
            self.contact_nodes.set_obstacle(fields.obstacle)
        #: the friction law on Γ_C and its state (``fem.mixed_friction``), or None: frictionless (σn·t = 0 there)
        self.friction = MixedFriction(self, friction, epsilon) if frictional else None
        if modulus is None:
            modulus = self.comm.allreduce(float(np.min(fields.E.x.array, initial=np.inf)), op=MPI.MIN)
        #: s of the equilibration D = diag(s I_σ, I_u/s) of every saddle-point factorization of this subproblem
        self.stress_scale = stress_scale(modulus / mesh_extent(msh))
        self.factorization = SaddlePointFactorization(
            self.comm,
            prefix,
            self.spaces.n_sigma,
            self.assembly,
            self.contact_nodes,
            contact=self.contact,
            has_operators=operators,
            scale=self.stress_scale,
        )
        self.c = np.zeros(self.n_sigma)
        self.u = np.zeros(self.n_u)
        self.cold = True  #: no solution yet: the next Newton solve linearizes at "penalty everywhere"
        self._scipy_cache: dict[str, sp.csr_matrix] = {}
        self.build_time = time.perf_counter() - t0

    # -- the collaborators' data ---------------------------------------------------------
    space = _part("spaces", "space", "The AW space X_h (with the essential conditions of the boundary).")
    dg = _part("spaces", "dg", "DG P3 space of (σ_xx, σ_xy, σ_yy): where the forms are written.")
    U = _part("spaces", "U", "DG P1 vector space of the displacement.")
    n_sigma = _part("spaces", "n_sigma", "Owned AW coefficients.")
    n_u = _part("spaces", "n_u", "Owned DG P1 coefficients.")
    s0 = _part("spaces", "s0", "σ_t, the traction lifting (owned DG P3 coefficients; σ = P c + σ_t).")
    _lifted = _part("spaces", "lifted", "Whether σ_t is nonzero (read by ``multiscale.mixed_cem``).")
    num_dofs = _part("spaces", "num_dofs", "Global stress (AW), displacement and total DOF counts.")
    G = _part("assembly", "G", "Displacement-row load −(f, v) − (div σ_t, v) (owned DG P1 entries).")
    u_D = _part("assembly", "u_D", "u_D in continuous vector P3 (None without a prescribed displacement).")
    n0 = _part("interface", "n0", "σ_t n at the γ nodes, this rank's block.")
    gamma_normal = _part("interface", "gamma_normal", "Outward unit normal at each γ node (replicated).")
    q_points = _part("contact_nodes", "q_points", "The Γ_C contact nodes (replicated, canonical order).")
    q_weights = _part("contact_nodes", "q_weights", "Their Gauss–Lobatto weights.")
    q_normals = _part("contact_nodes", "q_normals", "Their outward unit normals.")
    q_gap = _part("contact_nodes", "q_gap", "The obstacle's gap g at them.")
    q0 = _part("contact_nodes", "q0", "σ_t,c at them (the traction lifting's normal stress).")
    solver = _part("factorization", "solver", "The direct solver (made at the first factorization).")

    @property
    def gamma_points(self) -> np.ndarray:
        """The γ nodes (replicated, in the order of the Robin data); none without β."""
        return np.zeros((0, 2)) if self.interface is None else self.interface.gamma_points

    @property
    def interface_range(self) -> tuple[int, int]:
        """(start, end) of this rank's block of the γ values (x, y per node); (0, 0) without β."""
        return (0, 0) if self.interface is None else self.interface.interface_range

    @property
    def obstacle(self) -> Obstacle | None:
        """The obstacle (None: a wall flush with Γ_C, or no Γ_C)."""
        return None if self.contact_nodes is None else self.contact_nodes.obstacle

    @property
    def P(self) -> sp.csr_matrix:
        """Local P (SciPy): owned DG rows × local AW columns (owned, then ghosts); in serial the whole P (made
        when first asked for: ``ArnoldWintherSpace.prolongation``)."""
        return self.space.prolongation

    # -- the operators as SciPy matrices (serial consumers: interface Newton, multiscale, tests) ----
    def _scipy(self, name: str) -> sp.csr_matrix:
        if name not in self._scipy_cache:
            asm, iface, nodes = self.assembly, self.interface, self.contact_nodes
            op: DistributedMatrix | None = {
                "K": asm.K,
                "Kt": asm.Kt,
                "B": asm.B,
                "M": asm.M,
                "R": asm.R,
                "Q": nodes and nodes.Q,
                "C": iface and iface.C,
                "N": iface and iface.N,
            }[name]
            if op is None:
                raise AttributeError(f"this subproblem has no operator {name}")
            self._scipy_cache[name] = op.local_csr()
        return self._scipy_cache[name]

    K = property(lambda self: self._scipy("K"), doc="Pᵀ A P (compliance) as SciPy CSR: owned rows, global columns.")
    Kt = property(lambda self: self._scipy("Kt"), doc="K + β R (the stress block of the Jacobian), SciPy CSR.")
    B = property(lambda self: self._scipy("B"), doc="B P (divergence), SciPy CSR: owned DG P1 rows, global AW columns.")
    M = property(lambda self: self._scipy("M"), doc="DG P1 mass matrix, SciPy CSR.")
    R = property(lambda self: self._scipy("R"), doc="Pᵀ R_γ P (the Robin form with β = 1), SciPy CSR.")
    Q = property(
        lambda self: self._scipy("Q"), doc="σ_c at the contact nodes, SciPy CSR: this rank's rows, global columns."
    )
    C = property(
        lambda self: self._scipy("C"), doc="Robin data → stress load, SciPy CSR: owned rows, canonical γ columns."
    )
    N = property(
        lambda self: self._scipy("N"), doc="σn at the γ nodes, SciPy CSR: this rank's block of rows, global columns."
    )

    # -- data ---------------------------------------------------------------------------
    def set_obstacle(self, obstacle: Obstacle | None) -> None:
        """Set (or move) the obstacle: the gap g at the contact nodes and the load −∫_ΓC g τ_c (Gauss–Lobatto).

        The mixed law is u·n = g − (σ_c)⁺/ε with the body's normal n; the Jacobian does not
        change, so the factorizations stay valid and the next solve warm-starts.
        """
        if self.contact_nodes is None:
            raise InputError("this subproblem has no contact boundary")
        self.contact_nodes.set_obstacle(obstacle)

    def stress_load(self, data: np.ndarray | None) -> np.ndarray:
        """The σ-row right-hand side: Robin data C g, traction lifting, ∫_ΓD u_D·τn and ∫_ΓC g τ_c."""
        F_gap = np.zeros(self.n_sigma) if self.contact_nodes is None else self.contact_nodes.F_gap
        load = self.assembly.F_boundary + F_gap
        if self.friction is not None:
            load = load + self.friction.load()
        return load if data is None else load + self.interface.C @ data

    _stress_load = stress_load  # the name hybrid.newton calls

    def contact_stress(self) -> np.ndarray:
        """σ_c at the contact nodes (``q_points``) of the current stress, replicated on every rank."""
        return self.contact_nodes.stress(self.c)

    def gamma_mass_matrix(self) -> DistributedMatrix:
        """L²(γ) mass matrix M of the Robin data (canonical γ values, this rank's block): ‖g‖²_γ = Σ_ranks g·(M g)."""
        if self.beta is None:
            raise InputError("this subproblem has no interface γ")
        return self.interface.mass

    def gamma_mass(self) -> DistributedMatrix:
        """The L²(γ) mass matrix of the continuous P3 vector data at ``gamma_points`` (flattened (x, y)), acting
        on this rank's block of the canonical γ values (``interface_range``; serial: all): ``gamma_mass_matrix``."""
        return self.gamma_mass_matrix()

    def gamma_traction(self) -> np.ndarray:
        """σn on γ (outward n of this mesh) at ``gamma_points``, (x, y) per node, this rank's block."""
        return self.interface.traction(self.c)

    # -- residual, energy, solve ----------------------------------------------------------
    def factorize_for(self, active: np.ndarray | None) -> bool:
        """Factorize the saddle-point Jacobian for the active set (None: no penalty; with friction the friction
        state, ``MixedFriction.key``) unless cached."""
        if self.friction is None or active is None:
            return self.factorization.factorize_for(active)
        friction = self.friction
        return self.factorization.factorize_for(friction.cache_key(active), friction.weights(active))

    _factorize_for = factorize_for  # the name hybrid.mixed and hybrid.newton call

    def linear_solve(self, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dσ, du) = J⁻¹ (r1, r2) with the current factorization."""
        return self.factorization.solve(r1, r2)

    def gradient(self, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(F_σ, F_u) at the current (σ, u) for the stress-side load (C g)."""
        asm = self.assembly
        F1 = asm.Kt @ self.c + asm.B.T @ self.u - load
        if self.contact:
            F1 += self.contact_nodes.penalty_force(self.contact_nodes.stress(self.c))
        if self.friction is not None:
            F1 += self.friction.force(self.c)
        return F1, asm.B @ self.c - asm.G

    def _scale(self, load: np.ndarray) -> float:
        """Sum of the norms of the terms of the residual, equilibrated like the residual (the yardstick of the
        residual check: ``mixed_linear.equilibrated_size``)."""
        comm, asm = self.comm, self.assembly
        sizes1 = norm(asm.Kt @ self.c, comm) + norm(asm.B.T @ self.u, comm) + norm(load, comm)
        if self.contact:
            sizes1 += norm(self.contact_nodes.penalty_force(self.contact_nodes.stress(self.c)), comm)
        if self.friction is not None:
            sizes1 += norm(self.friction.force(self.c), comm)
        return equilibrated_size(self.stress_scale, sizes1, norm(asm.B @ self.c, comm) + norm(asm.G, comm))

    def residual_norm(self, F1: np.ndarray, F2: np.ndarray) -> float:
        """‖D F‖ of a residual (F_σ, F_u), D the equilibration of the factorizations (``equilibrated_norm``):
        both blocks in one unit."""
        return equilibrated_norm(self.stress_scale, F1, F2, self.comm)

    def residual(self, data: np.ndarray | None = None) -> tuple[float, float]:
        """(‖D F‖, scale) at the current (σ, u) with Robin data g; scale = sum of the norms of the terms, both
        equilibrated by D = diag(s I_σ, I_u/s) (``residual_norm``)."""
        load = self.stress_load(data)
        F1, F2 = self.gradient(load)
        return self.residual_norm(F1, F2), self._scale(load)

    def complementary_energy(self, data: np.ndarray | None = None) -> float:
        """J(σ) = ½(Aσ,σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε)∫_ΓC ((σ_c)⁺)² at the current σ."""
        J = 0.5 * dot(self.c, self.assembly.Kt @ self.c, self.comm) - dot(self.stress_load(data), self.c, self.comm)
        if self.contact:
            J += self.contact_nodes.penalty_energy(self.contact_nodes.stress(self.c))
        if self.friction is not None:
            J += self.friction.energy(self.c)
        return float(J)

    def solve(self, data: np.ndarray | None = None) -> MixedNewtonHistory:
        """Solve with Robin data g (this rank's block of the γ values), warm-started from the current (σ, u)."""
        load = self.stress_load(data)
        if not self.contact:  # linear: one solve with the cached factorization
            history = MixedNewtonHistory()
            history.factorizations += self.factorize_for(None)
            self.c, self.u = self.linear_solve(load, self.G)
            history.active_sizes.append(0)
            history.step_lengths.append(1.0)
            return history
        if self.friction is not None:
            return frictional_mixed_newton(self, load, data)
        return globalized_newton(self, load, data)

    # -- output -------------------------------------------------------------------------
    def sigma_function(self, out: fem.Function | None = None, name: str = "sigma") -> fem.Function:
        """σ_h as a DG P3 function of (σ_xx, σ_xy, σ_yy) (collective)."""
        out = fem.Function(self.dg, name=name) if out is None else out
        out.x.array[: self.spaces.n_dg] = self.spaces.Pd @ self.c + self.s0
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
        return dot(c, self.assembly.K @ c, self.comm)

    def l2_norm2(self, u: np.ndarray) -> float:
        """‖u‖²_L² of (owned) DG P1 coefficients u (collective)."""
        return dot(u, self.assembly.M @ u, self.comm)

    def contact_profile(self) -> MixedContactProfile:
        """σ_c and u_c = −(σ_c)⁺/ε at the Γ_C contact nodes (clamped corners excluded), sorted; on every rank."""
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        return self.contact_nodes.profile(self.c)

    def displacement_normal_trace(self) -> tuple[np.ndarray, np.ndarray]:
        """(y, u_h·n) of the DG P1 displacement at the profile's contact nodes (a diagnostic of u_c)."""
        return self.contact_nodes.normal_trace(self.u)

    def ufl_residual_norm(self, data: np.ndarray | None = None) -> tuple[float, float]:
        """‖F‖ of the residual assembled from ``forms_mixed.mixed_residual`` (independent of Q), and its scale."""
        return ufl_residual_norm(self, data)

    def fit_stress(self, values: np.ndarray) -> tuple[np.ndarray, float]:
        """Owned AW coefficients c with P c + σ_t closest to a DG P3 stress in ℓ², and the relative misfit
        (``MixedSpaces.fit_stress``; collective)."""
        return self.spaces.fit_stress(values, f"{self.prefix}fit_")

    # -- interface Newton support (hybrid.newton) -------------------------------------------------
    def reset(self) -> None:
        """Forget the solution and the cached factorization (the next ``solve`` starts cold)."""
        self.c = np.zeros(self.n_sigma)
        self.u = np.zeros(self.n_u)
        self.cold = True
        if self.contact:
            self.factorization.factorized_set = None

    def set_state(self, c: np.ndarray, u: np.ndarray) -> None:
        """Set (σ, u) (AW and DG P1 coefficients): the warm start of the next ``solve``."""
        self.c = np.array(c, dtype=float).reshape(self.n_sigma)
        self.u = np.array(u, dtype=float).reshape(self.n_u)
        self.cold = False

    def destroy(self) -> None:
        """Free the PETSc objects (collective)."""
        self.factorization.destroy()
        self.assembly.destroy()
        for part in (self.contact_nodes, self.interface):
            if part is not None:
                part.destroy()
