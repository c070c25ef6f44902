"""Primal P1 elasticity subproblems and the monolithic penalized contact solve.

One class, ``PrimalSubproblem``, serves three roles: the monolithic problem on Ω
(contact, no Robin), the linear Ω₁ problem (Robin on γ, no contact) and the
nonlinear Ω₂ problem (contact and Robin). Forms come from ``forms_primal``, the boundary data
(u_D, tractions, rollers) and the nodal contact geometry (ν, g) from ``primal_boundary``.

The dimension is the mesh's: on triangles plane strain, on tetrahedra 3D elasticity (the same
σ = 2μ ε + λ tr ε I with gdim-vector P1 elements; the monolithic solve is the method that takes 3D).
"""

import dataclasses
import logging
import time
import weakref
from dataclasses import dataclass

import basix.ufl
import dolfinx.fem.petsc
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_primal
from fenics_contact.fem.amg import AMGSolver, LinearSolverOptions, linear_solver
from fenics_contact.fem.contact import MAX_REFINEMENTS, ContactProfile, NewtonHistory, NewtonOptions, semismooth_newton
from fenics_contact.fem.friction import NodalFriction, frictional_newton
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.matrices import AbsoluteTerms, ComponentBlockProduct, assemble_scipy, quadratic_form
from fenics_contact.fem.primal_boundary import NodalContactGeometry, PrimalBoundaryData
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.friction import Friction, friction_of
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary
from fenics_contact.problem.validation import require_facet_groups

__all__ = ["PrimalSubproblem", "PrimalSolution", "solve_primal_monolithic", "default_penalty", "penalty_for"]

log = logging.getLogger(__name__)


def default_penalty(h: float, E_contact: float, factor: float = 1.0e-3) -> float:
    """δ = factor · h / E_c: penalty stiffness 1/δ a factor 1/factor above the element stiffness E_c/h.

    Units: δ is a length per stress (1/δ multiplies a displacement into a traction), and so is h/E_c: a mesh in
    mm instead of m gets δ in mm/Pa, the same problem (no reference length needed)."""
    if not all(isinstance(v, (int, float, np.number)) and np.isfinite(v) and v > 0 for v in (h, E_contact, factor)):
        raise InputError(f"default_penalty needs finite h, E_c, factor > 0; got {h!r}, {E_contact!r}, {factor!r}")
    return factor * h / E_contact


class PrimalSubproblem:
    """a(u, v) [+ (1/δ)∫_ΓC (u·ν − g)⁺ v·ν] [+ α∫_γ u·v − ∫_γ g·v] = (f, v) + Σ∫_ΓN t·v, u = u_D on Γ_D, P1.

    Boundary conditions and obstacle come with ``fields`` (``fields.boundary``,
    ``fields.obstacle``): u_D is imposed strongly (Newton works with homogeneous
    increments), tractions enter the load, other facets are traction free.  The
    contact direction ν and the gap g are nodal (P1) on Γ_C: the obstacle's at
    the Γ_C vertices, or for a wall flush with Γ_C (``obstacle=None``) the body's
    nodal normal (facet normals averaged with the vertex weights) and g = 0.  One
    ν per node keeps the active set a set of nodes on a curved Γ_C too.  ``friction`` (a
    ``problem.friction.Friction``, with contact only) adds the nodal friction term of ``fem.friction``.

    ``solver``: the linear solver of every solve (``fem.amg.LinearSolverOptions`` or its kind: ``"direct"``,
    MUMPS: Cholesky when frictionless, J being symmetric positive definite, else LU; ``"amg"``, CG +
    smoothed-aggregation AMG, its set-up kept across Newton steps; ``"auto"``).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        fields: MaterialFields,
        *,
        delta: float | None,
        alpha: fem.Function | None,
        prefix: str,
        newton: NewtonOptions = NewtonOptions(),
        V: fem.FunctionSpace | None = None,
        friction: Friction | None = None,
        solver: LinearSolverOptions | str = "direct",
    ) -> None:
        if delta is not None and not (isinstance(delta, (int, float, np.number)) and np.isfinite(delta) and delta > 0):
            raise InputError(f"the penalty parameter δ must be a finite number > 0, got {delta!r}")
        self.mesh = msh
        self.prefix = prefix
        self.newton = newton
        self.contact = delta is not None
        self.delta = delta
        tdim = msh.topology.dim
        gdim = msh.geometry.dim
        self.V = V or fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1, shape=(gdim,)))
        self.Q = fem.functionspace(msh, basix.ufl.element("Lagrange", msh.basix_cell(), 1))
        self.u = fem.Function(self.V, name="u")
        self.g = fem.Function(self.V, name="g") if alpha is not None else None
        self.fields = fields
        self.facet_tags = facet_tags

        msh.topology.create_connectivity(tdim - 1, tdim)
        self.boundary = PrimalBoundaryData(self.V, self.Q, facet_tags, fields.boundary)
        self.bcs, self.u_D, self.tractions = self.boundary.bcs, self.boundary.u_D, self.boundary.tractions
        self.boundary.set_lifting(self.u)  # u_D on the Γ_D DOFs, kept through warm starts
        ds = forms_primal.vertex_measure(msh, facet_tags)
        ds_c = ds(Boundary.GAMMA_C)
        self.geometry: NodalContactGeometry | None = None
        if self.contact:
            self.geometry = NodalContactGeometry(
                self.V, self.Q, facet_tags, ds_c, self.boundary.dirichlet_q, fields.obstacle
            )
        tractions = self.boundary.traction_terms

        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        q = ufl.TestFunction(self.Q)
        lm, mu = fields.lmbda, fields.mu
        geo = self.geometry
        penalty = (fem.Constant(msh, PETSc.ScalarType(1.0 / delta)), geo.nu, geo.gap) if self.contact else None
        robin = (alpha, self.g, ds(Boundary.INTERFACE)) if alpha is not None else None
        kw = dict(lmbda=lm, mu=mu, penalty=penalty, ds_contact=ds_c, robin=robin)
        residual = forms_primal.contact_residual(self.u, v, f=fields.f, tractions=tractions, **kw)
        self._F = fem.form(residual)
        # what ``body_load`` depends on: the residual's coefficients and constants but the state u, the Robin data
        # g and the contact geometry (ν, gap: the contact term vanishes there), and u_D
        state = {id(c) for c in (self.u, self.g, *((geo.nu, geo.gap) if self.contact else ()))}
        inputs = [c for c in residual.coefficients() if id(c) not in state]
        inputs += [] if self.u_D is None else [self.u_D]
        self._load_inputs = inputs, ufl.algorithms.analysis.extract_constants(residual)
        self._J = fem.form(forms_primal.contact_jacobian(self.u, du, v, **kw))
        load = ufl.inner(fields.f, v) * ufl.dx
        if tractions:
            load += forms_primal.traction_form(tractions, v)
        if robin is not None:
            load += ufl.inner(self.g, v) * ds(Boundary.INTERFACE)
        # the forms of the other uses, compiled on first use (``_form``): a solve that never asks for one (e.g.
        # Algorithm 1's linear Ω₁ along a load path: no K, no load norm) does not pay for its compilation
        p, r = ufl.TrialFunction(self.Q), ufl.TestFunction(self.Q)
        self._forms: dict = {
            "load": load,
            "a": forms_primal.elastic_form(du, v, lm, mu),
            "m": forms_primal.mass_form(du, v),
            "m1": forms_primal.mass_form(p, r),  # the block of one component of "m" (``norm_products``)
        }
        if self.contact:
            s = forms_primal.gap_function(self.u, geo.nu, geo.gap)
            reaction = ufl.inner(stress(strain(self.u), lm, mu), strain(v)) * ufl.dx - ufl.inner(fields.f, v) * ufl.dx
            if tractions:
                reaction -= forms_primal.traction_form(tractions, v)
            self._forms |= {
                "indicator": forms_primal.nodal_indicator(s, q, ds_c),
                "gap_terms": penalty[0] * forms_primal.heaviside(s) * geo.gap * ufl.dot(v, geo.nu) * ds_c,
                "reaction": reaction,
            }

        self.A = dolfinx.fem.petsc.create_matrix(self._J)
        self.b = dolfinx.fem.petsc.create_vector(self.V)
        self.du = dolfinx.fem.petsc.create_vector(self.V)
        self._gap_vec = dolfinx.fem.petsc.create_vector(self.V)  # ghosted, like b (assembly target)
        solver = LinearSolverOptions.of(solver)
        if friction is not None and solver.krylov == "cg":  # Coulomb's Jacobian is not symmetric: GMRES
            solver = dataclasses.replace(solver, krylov="gmres")
        if friction is None and solver.chosen(self.num_dofs, tdim) == "direct":
            # frictionless, J (stiffness + penalty on the active set + Robin, identity on Γ_D) is symmetric
            # positive definite: MUMPS' Cholesky, half an LU's factors
            self.solver = DirectSolver(msh.comm, prefix=prefix, spd=True)
        else:
            self.solver = linear_solver(
                msh.comm, prefix=prefix, space=self.V, options=solver, contrast=_contrast(fields.mu, msh.comm)
            )
        # K and M on J's sparsity (its cell couplings are theirs; its facet terms couple no other unknowns): the
        # pattern is computed once, not three times; both on first use (``_K``, ``_M``)
        self._stiffness: PETSc.Mat | None = None
        self._mass_matrix: PETSc.Mat | None = None
        self._work = self.A.createVecLeft()
        self._linear_ready = False
        self._factorized_set: np.ndarray | None = None
        self._terms = AbsoluteTerms()
        self._mass = None  # M's block of one component (``norm_products``, one process)
        self.friction = NodalFriction(self, friction, delta) if friction is not None and self.contact else None

    def _form(self, name: str) -> fem.Form:
        """The compiled form ``name`` of ``_forms``, compiled on first use (collective, like every use of it)."""
        form = self._forms[name]
        if not isinstance(form, fem.Form):
            form = self._forms[name] = fem.form(form)
        return form

    @property
    def _load(self) -> fem.Form:
        """(f, v) + Σ∫_ΓN t·v [+ ∫_γ g·v]: the load of ``load_norm``."""
        return self._form("load")

    @property
    def _indicator(self) -> fem.Form:
        """∫_ΓC H(u·ν − g) q: the nodal active set (contact only)."""
        return self._form("indicator")

    @property
    def _gap_terms(self) -> fem.Form:
        """(1/δ)∫_ΓC H(u·ν − g) g v·ν: the gap's share of the penalty (contact only)."""
        return self._form("gap_terms")

    @property
    def _reaction(self) -> fem.Form:
        """a(u, v) − (f, v) − Σ∫_ΓN t·v: the obstacle's reaction (contact only)."""
        return self._form("reaction")

    @property
    def _M(self) -> PETSc.Mat:
        """M, the matrix of the mass form (u, v), assembled on first use (collective): on one process the relative
        change takes its products from M's block of one component (``norm_products``) and never needs it."""
        if self._mass_matrix is None:
            self._mass_matrix = self._on_pattern("m")
        return self._mass_matrix

    @property
    def _K(self) -> PETSc.Mat:
        """K, the matrix of the elastic form a (no boundary conditions), assembled on first use (collective):
        Algorithm 1's linear Ω₁ along a load path takes its products from its equations and never needs it."""
        if self._stiffness is None:
            self._stiffness = self._on_pattern("a")
        return self._stiffness

    def _on_pattern(self, name: str) -> PETSc.Mat:
        """The matrix of the form ``name`` assembled on J's sparsity (collective)."""
        mat = self.A.duplicate()
        dolfinx.fem.petsc.assemble_matrix(mat, self._form(name))
        mat.assemble()
        return mat

    # -- contact geometry ------------------------------------------------------------------
    @property
    def obstacle(self) -> Obstacle | None:
        """The obstacle (None: a wall flush with Γ_C)."""
        return None if self.geometry is None else self.geometry.obstacle

    def set_obstacle(self, obstacle: Obstacle | None) -> None:
        """Set (or move) the obstacle: ν and g at the Γ_C vertices (collective); the next solve warm-starts."""
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        if self.geometry.set_obstacle(obstacle):
            self._factorized_set = None  # ν enters the Jacobian

    @property
    def symmetric(self) -> bool:
        """Whether the Jacobian is symmetric (not with Coulomb friction)."""
        return self.friction is None or self.friction.law.symmetric

    # -- sizes ---------------------------------------------------------------------------
    @property
    def num_dofs(self) -> int:
        """Global number of displacement DOFs."""
        return self.V.dofmap.index_map.size_global * self.V.dofmap.index_map_bs

    # -- assembly ------------------------------------------------------------------------
    def _assemble_vector(self, form, out: PETSc.Vec) -> PETSc.Vec:
        with out.localForm() as loc:
            loc.set(0.0)
        dolfinx.fem.petsc.assemble_vector(out, form)
        out.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        dolfinx.fem.petsc.set_bc(out, self.bcs)
        return out

    def _residual(self) -> float:
        self._assemble_F()
        return self.b.norm()

    def _assemble_F(self) -> PETSc.Vec:
        """b ← F(u), with the friction term when there is one."""
        self._assemble_vector(self._F, self.b)
        if self.friction is not None:
            self.friction.add_residual(self.b)
        return self.b

    def _factorize_for(self, active: np.ndarray) -> bool:
        """Factorize J unless the cached factorization has the same active set."""
        varies = self.friction is not None and self.friction.varies()  # 3D slip: J changes within a state
        if not varies and self._factorized_set is not None and self._same_sets(active, self._factorized_set):
            return False
        self._factorize()
        self._factorized_set = active.copy()
        return True

    def _factorize(self) -> None:
        self.A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.A, self._J, bcs=self.bcs)
        self.A.assemble()
        if self.friction is not None:
            self.friction.add_jacobian(self.A)
        self.solver.set_operator(self.A)

    def _direction(self) -> None:
        """du ← −J⁻¹F(u), b holding F(u) (left holding −F(u)); an AMG solve to its Newton tolerance
        (``AMGSolver.newton_tolerance``: relative to the right-hand side of the new iterate's equation)."""
        self.b.scale(-1.0)
        if isinstance(self.solver, AMGSolver):
            self.solver.solve(self.b, self.du, iterate=self.u.x.petsc_vec)
        else:
            self.solver.solve(self.b, self.du)

    def _step(self) -> None:
        self._direction()
        self.u.x.petsc_vec.axpy(1.0, self.du)
        self.u.x.scatter_forward()

    def _active_set(self) -> np.ndarray:
        vec = dolfinx.fem.assemble_vector(self._indicator)
        vec.scatter_reverse(dolfinx.la.InsertMode.add)
        return vec.array[: self.Q.dofmap.index_map.size_local] > 0.0

    def _same_sets(self, a: np.ndarray, b: np.ndarray) -> bool:
        return self.mesh.comm.allreduce(bool(np.array_equal(a, b)), op=MPI.LAND)

    def load_norm(self) -> float:
        """‖b‖ of the load vector (f, tractions and Robin data)."""
        return self._assemble_vector(self._load, self.b).norm()

    def residual_check(self) -> tuple[float, float]:
        """(‖F(u)‖∞, ‖ |J||u| + |b| + |p_g| ‖∞): the residual and the size of the terms it balances.

        J (the factorized Jacobian: stiffness, penalty on the active set, Robin) applied to u gives
        the stiffness, penalty and Robin terms (u carries u_D on Γ_D), b the load, tractions and the
        Robin data, p_g = (1/δ)∫ H(u·ν − g) g v·ν the gap's share of the penalty; a backward-stable
        solve leaves a residual of about 1e-16 of their size row by row, whatever δ, α or the contrast.
        """
        final = self._assemble_F().norm(PETSc.NormType.NORM_INFINITY)
        load = self._assemble_vector(self._load, self.du)
        if self.contact:
            load.abs()
            gap = self._assemble_vector(self._gap_terms, self._gap_vec)
            gap.abs()
            load.axpy(1.0, gap)
            if self.friction is not None:
                self.friction.add_sizes(load)
        return final, self._terms(self.A, self.u.x.petsc_vec, load)

    # -- solve ---------------------------------------------------------------------------
    def factorize(self) -> None:
        """Factorize the operator now (offline work for a linear problem; a no-op once done)."""
        if not self._linear_ready:
            self._factorize()
            self._linear_ready = not self.contact

    def solve(self) -> NewtonHistory:
        """Solve for u (warm-started from the current u); Newton when there is contact."""
        if not self.contact:
            self.factorize()
            self._residual()
            self._step()
            h = NewtonHistory()
            h.active_sizes.append(0)
            return h
        if self.friction is not None:
            return frictional_newton(
                self, refinements=self.newton.max_iterations if self.mesh.geometry.dim == 3 else MAX_REFINEMENTS
            )
        return semismooth_newton(
            residual=self._residual,
            active_set=self._active_set,
            same_sets=self._same_sets,
            factorize=self._factorize_for,
            step=self._step,
            residual_check=self.residual_check,
            options=self.newton,
            name=self.prefix.rstrip("_"),
            comm=self.mesh.comm,
        )

    # -- measures ------------------------------------------------------------------------
    def energy_norm2(self, w: fem.Function) -> float:
        """a(w, w) on this (sub)mesh."""
        return quadratic_form(self._K, w.x.petsc_vec, self._work)

    def l2_norm2(self, w: fem.Function) -> float:
        """(w, w) on this (sub)mesh."""
        return quadratic_form(self._M, w.x.petsc_vec, self._work)

    def norm_products(self, w: fem.Function, Kw: PETSc.Vec | None, Mw: PETSc.Vec) -> None:
        """Kw ← K w (unless Kw is None), Mw ← M w: a(w, w) = wᵀK w and (w, w) = wᵀM w (K, M the matrices of
        ``energy_norm2``, ``l2_norm2``).  On one process M w by M's block of one component
        (``matrices.ComponentBlockProduct``: the mass form couples equal components only), the same products."""
        if Kw is not None:
            self._K.mult(w.x.petsc_vec, Kw)
        if self.mesh.comm.size > 1:
            self._M.mult(w.x.petsc_vec, Mw)
            return
        if self._mass is None:
            self._mass = self._component_mass()
        self._mass.mult(w.x.petsc_vec, Mw)

    def _component_mass(self) -> ComponentBlockProduct:
        """The product with M by its block of one component (one process): the scalar mass matrix of Q, assembled
        alone (a quarter of M's entries in 2D, the same values) when Q numbers the nodes as V its blocks, else M's
        block taken from M."""
        bs = self.V.dofmap.index_map_bs
        same = self.V.dofmap.index_map.size_local == self.Q.dofmap.index_map.size_local and np.array_equal(
            self.V.dofmap.list, self.Q.dofmap.list
        )
        if same and self._mass_matrix is None:
            return ComponentBlockProduct.of_block(assemble_scipy(self._form("m1")), bs)
        return ComponentBlockProduct(self._M, bs)

    def contact_profile(self) -> ContactProfile:
        """u_c = u·ν − g and the consistent nodal normal stress σ_c = (R·ν_p)/w_p along Γ_C, on every rank.

        R is the residual of the equations without the contact term (the reaction of the
        obstacle), w_p the vertex weights; clamped (Γ_D) nodes are left out.
        """
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        R = dolfinx.fem.assemble_vector(self._reaction)
        R.scatter_reverse(dolfinx.la.InsertMode.add)
        return self.geometry.profile(self.u, R.array)

    # -- interface Newton support (hybrid.newton): the affine pieces of the problem ---------------
    def _with_lifting_no_contact(self, action):
        """Run ``action()`` at u = lifting of u_D, zero Robin data and every contact node inactive
        (the gap raised above u·ν), then restore u, g and the gap."""
        keep_u = self.u.x.array.copy()
        keep_g = self.g.x.array.copy() if self.g is not None else None
        gap = self.geometry.gap if self.contact else None
        keep_gap = gap.x.array.copy() if self.contact else None
        try:
            self.boundary.set_lifting(self.u)
            if self.g is not None:
                self.g.x.array[:] = 0.0
            if self.contact:
                gap.x.array[:] = 1.0 + float(np.max(np.abs(self.u.x.array), initial=0.0))
            return action()
        finally:
            self.u.x.array[:] = keep_u
            if self.g is not None:
                self.g.x.array[:] = keep_g
            if self.contact:
                gap.x.array[:] = keep_gap

    def reset(self) -> None:
        """Forget the solution and the cached factorization (the next ``solve`` starts cold from u_D's lifting)."""
        self.boundary.set_lifting(self.u)
        self._factorized_set = None

    def residual_norm(self) -> tuple[float, float]:
        """(‖F(u)‖, ‖b‖) at the current u and data: ``solve`` accepts u when ‖F‖ ≤ rtol‖b‖ + atol."""
        return self._residual(), self.load_norm()

    def contact_free_matrix(self) -> PETSc.Mat:
        """A new matrix J₀ = a + α∫_γ (the Jacobian with no contact node active), identity on Γ_D."""
        A = dolfinx.fem.petsc.create_matrix(self._J)

        def assemble():
            dolfinx.fem.petsc.assemble_matrix(A, self._J, bcs=self.bcs)
            A.assemble()

        self._with_lifting_no_contact(assemble)
        return A

    def body_load(self, out: PETSc.Vec) -> PETSc.Vec:
        """out ← the right-hand side of J₀ x = out + data − contact forces at zero Robin data and no contact:
        (f, v) + Σ∫_ΓN t·v − a(u_D lifting, v) on the free rows, u_D on the Γ_D rows."""

        def assemble():
            self._assemble_vector(self._F, out)  # Γ_D rows 0
            out.scale(-1.0)
            if self.u_D is not None:
                dolfinx.fem.petsc.set_bc(out, [fem.dirichletbc(self.u_D, self.boundary.dirichlet_dofs)])
            return out

        return self._with_lifting_no_contact(assemble)

    def body_load_inputs(self) -> list[np.ndarray]:
        """The values ``body_load`` is a function of (local arrays, views): the coefficients and constants of the
        residual but the state, the Robin data and the contact geometry, and u_D.  Equal inputs assemble the
        same body load."""
        functions, constants = self._load_inputs
        return [c.x.array for c in functions] + [np.asarray(k.value) for k in constants]

    def contact_nodes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Owned Γ_C nodes off Γ_D: (node = block index of u, contact direction ν_p (k, gdim), vertex weight w_p,
        gap g_p): the penalty term is Σ_p (w_p/δ) (u_p·ν_p − g_p)⁺ (v_p·ν_p)."""
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        return self.geometry.nodes()

    def destroy(self) -> None:
        """Free the PETSc objects (collective)."""
        for obj in (self.A, self.b, self.du, self._gap_vec, self._stiffness, self._mass_matrix, self._work):
            if obj is not None:
                obj.destroy()
        self.solver.destroy()
        self._terms.destroy()


def _contrast(mu: fem.Function, comm: MPI.Comm) -> float:
    """max μ / min μ over the mesh (μ = E/(2(1 + ν)): the contrast of the moduli; 1 for a constant μ)."""
    values = getattr(getattr(mu, "x", None), "array", None)
    if values is None:
        return 1.0
    low = comm.allreduce(float(np.min(values, initial=np.inf)), op=MPI.MIN)
    high = comm.allreduce(float(np.max(values, initial=0.0)), op=MPI.MAX)
    return high / low if low > 0 else np.inf


@dataclass(slots=True)
class PrimalSolution:
    """The monolithic penalized solution with its Newton history and contact profile."""

    u: fem.Function
    newton: NewtonHistory
    profile: ContactProfile
    delta: float
    dofs: int
    time_s: float
    problem: PrimalSubproblem

    @property
    def linear_solver(self) -> str:
        """The linear solver the Newton steps used: ``"direct"`` (MUMPS Cholesky or LU) or ``"amg"``."""
        return "amg" if isinstance(self.problem.solver, AMGSolver) else "direct"

    @property
    def krylov_iterations(self) -> list[int]:
        """The Krylov iterations of each linear solve (empty for the direct solver)."""
        return list(getattr(self.problem.solver, "iterations", []))


#: The primal (P1) methods warn when ν reaches this.  P1 locks as ν → ½: on u = curl ψ, the clamped unit
#: square (``problem.analytic.p1_locking_error``; ``benchmarks/analytic_benchmarks.py --sections 6``), the
#: relative L² error at h = 1/64 is 3.4e-3 at ν = 0.3, 1.7e-2 at 0.48, 3.2e-2 at 0.49, 0.21 at 0.499 and
#: 0.68 at 0.4999 (0.89 at h = 1/32): about 10× the compressible error at ν = 0.49, 60× at 0.499.
P1_LOCKING_NU = 0.49
_locking_warned = weakref.WeakSet()  #: meshes already warned about (one warning per mesh, not per solve)


def warn_if_locking(nu: fem.Function | None, comm) -> None:
    """Log a warning when ν reaches ``P1_LOCKING_NU``: P1 locks as ν → ½ (once per mesh: a run with its
    monolithic reference warns once).  Collective on ``comm``."""
    if nu is None:
        return
    local = float(np.max(nu.x.array, initial=0.0))
    nu_max = comm.allreduce(local, op=MPI.MAX)
    msh = nu.function_space.mesh
    if nu_max < P1_LOCKING_NU or msh in _locking_warned:
        return
    _locking_warned.add(msh)
    if comm.rank == 0:
        log.warning(
            "ν reaches %.6g: P1 displacement elements lock as ν → ½ (a divergence-free test solution on the "
            "clamped square, h = 1/64: L² error 3.4e-3 at ν = 0.3, 3.2e-2 at 0.49, 0.21 at 0.499, 0.68 at 0.4999), "
            "so the primal methods (monolithic, Algorithms 1 and 3) may be far from the elastic solution; "
            "--method mixed or mixed-ms (Arnold–Winther stress) is robust in ν.",
            nu_max,
        )


def penalty_for(problem: ContactProblem, delta: float | None = None) -> float:
    """δ, or when None the default ``default_penalty(h, E_c)`` with E_c the largest E on Γ_C."""
    if delta is None:
        return default_penalty(problem.h, problem.contact_modulus())
    if (
        isinstance(delta, bool)
        or not isinstance(delta, (int, float, np.number))
        or not (np.isfinite(delta) and delta > 0)
    ):
        raise InputError(f"the primal penalty δ must be a finite number > 0 (or None: the default), got {delta!r}")
    return float(delta)


def solve_primal_monolithic(
    problem: ContactProblem,
    *,
    delta: float | None = None,
    newton: NewtonOptions = NewtonOptions(),
    solver: LinearSolverOptions | str = "auto",
    prefix: str = "fc_primal_mono_",
) -> PrimalSolution:
    """Penalized primal contact on the whole mesh by semismooth Newton, on triangles or tetrahedra.

    ``delta`` defaults to ``default_penalty(h, E_c)``, E_c the largest E on Γ_C (``penalty_for``).  With a
    friction law (``problem.law``) it is one load step from the unloaded state (``fenics_contact.sliding`` for
    load paths). ``solver``: the linear solver of the Newton steps (``fem.amg.LinearSolverOptions`` or its
    kind): ``"direct"`` (MUMPS: Cholesky frictionless, else LU), ``"amg"`` (CG + smoothed-aggregation AMG with
    the rigid-body near-nullspace) or ``"auto"`` (AMG on a 3D mesh of ``fem.amg.AUTO_AMG_DOFS`` unknowns or
    more, else direct).
    """
    cm = problem.cm
    msh, facet_tags = cm.mesh, cm.facet_tags
    require_facet_groups(msh, facet_tags, (Boundary.GAMMA_D, Boundary.GAMMA_C))
    start = time.perf_counter()
    fields = problem.fields
    delta = penalty_for(problem, delta)
    warn_if_locking(fields.nu, msh.comm)
    sub = PrimalSubproblem(
        msh,
        facet_tags,
        fields,
        delta=delta,
        alpha=None,
        prefix=prefix,
        newton=newton,
        friction=friction_of(problem.law),
        solver=solver,
    )
    history = sub.solve()
    elapsed = time.perf_counter() - start
    profile = sub.contact_profile()
    solution = PrimalSolution(sub.u, history, profile, delta, sub.num_dofs, elapsed, sub)
    log.info(
        "monolithic primal: %d Newton steps (%s%s), active-set sizes %s, penetration %.3e, %.2f s",
        history.steps,
        solution.linear_solver,
        f", Krylov iterations {solution.krylov_iterations}" if solution.krylov_iterations else "",
        history.active_sizes,
        profile.penetration,
        elapsed,
    )
    return solution
