"""Primal P1 elasticity subproblems and the monolithic penalized contact solve.

One class, ``PrimalSubproblem``, serves three roles: the monolithic problem on Ω
(contact, no Robin), the linear Ω₁ problem (Robin on γ, no contact) and the
nonlinear Ω₂ problem (contact and Robin). Forms come from ``forms_primal``.
"""

import logging
import time
from dataclasses import dataclass

import numpy as np
import ufl
from mpi4py import MPI
from petsc4py import PETSc

import basix.ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
import dolfinx.fem.petsc

from fenics_contact.fem import forms_primal
from fenics_contact.fem.contact import ContactProfile, NewtonHistory, NewtonOptions, semismooth_newton
from fenics_contact.errors import InputError
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.fem.linalg import DirectSolver, quadratic_form
from fenics_contact.problem.materials import strain, stress
from fenics_contact.problem.tags import Boundary

__all__ = ["PrimalSubproblem", "PrimalSolution", "solve_primal_monolithic", "default_penalty"]

log = logging.getLogger(__name__)


def default_penalty(h: float, E_contact: float, factor: float = 1.0e-3) -> float:
    """δ = factor · h / E_c: penalty stiffness 1/δ a factor 1/factor above the element stiffness E_c/h."""
    return factor * h / E_contact


class PrimalSubproblem:
    """a(u, v) [+ (1/δ)∫_ΓC (u·n)⁺ v·n] [+ α∫_γ u·v − ∫_γ g·v] = (f, v), u = 0 on Γ_D, P1."""

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
    ) -> None:
        if delta is not None and not delta > 0:
            raise InputError(f"the penalty parameter δ must be > 0, got {delta}")
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

        msh.topology.create_connectivity(tdim - 1, tdim)
        dirichlet = facet_tags.find(Boundary.GAMMA_D)
        dofs = fem.locate_dofs_topological(self.V, tdim - 1, dirichlet)
        self.bcs = [fem.dirichletbc(np.zeros(gdim, dtype=PETSc.ScalarType), dofs, self.V)]
        self._dirichlet_q = fem.locate_dofs_topological(self.Q, tdim - 1, dirichlet)

        ds = forms_primal.vertex_measure(msh, facet_tags)
        n = ufl.FacetNormal(msh)
        v, du = ufl.TestFunction(self.V), ufl.TrialFunction(self.V)
        q = ufl.TestFunction(self.Q)
        lm, mu = fields.lmbda, fields.mu
        penalty = (fem.Constant(msh, PETSc.ScalarType(1.0 / delta)), n) if self.contact else None
        robin = (alpha, self.g, ds(Boundary.INTERFACE)) if alpha is not None else None
        kw = dict(lmbda=lm, mu=mu, penalty=penalty, ds_contact=ds(Boundary.GAMMA_C), robin=robin)
        self._F = fem.form(forms_primal.contact_residual(self.u, v, f=fields.f, **kw))
        self._J = fem.form(forms_primal.contact_jacobian(self.u, du, v, **kw))
        load = ufl.inner(fields.f, v) * ufl.dx
        if robin is not None:
            load += ufl.inner(self.g, v) * ds(Boundary.INTERFACE)
        self._load = fem.form(load)
        self._a = fem.form(forms_primal.elastic_form(du, v, lm, mu))
        self._m = fem.form(forms_primal.mass_form(du, v))
        if self.contact:
            self._indicator = fem.form(forms_primal.nodal_indicator(ufl.dot(self.u, n), q, ds(Boundary.GAMMA_C)))
            self._weights = fem.form(q * ds(Boundary.GAMMA_C))
            self._normals = fem.form(ufl.dot(v, n) * ds(Boundary.GAMMA_C))
            self._reaction = fem.form(
                ufl.inner(stress(strain(self.u), lm, mu), strain(v)) * ufl.dx - ufl.inner(fields.f, v) * ufl.dx
            )

        self.A = dolfinx.fem.petsc.create_matrix(self._J)
        self.b = dolfinx.fem.petsc.create_vector(self.V)
        self.du = dolfinx.fem.petsc.create_vector(self.V)
        self.solver = DirectSolver(msh.comm, prefix=prefix)
        self._K = dolfinx.fem.petsc.assemble_matrix(self._a)
        self._K.assemble()
        self._M = dolfinx.fem.petsc.assemble_matrix(self._m)
        self._M.assemble()
        self._work = self._K.createVecLeft()
        self._linear_ready = False
        self._factorized_set: np.ndarray | None = None

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
        self._assemble_vector(self._F, self.b)
        return self.b.norm()

    def _factorize_for(self, active: np.ndarray) -> bool:
        """Factorize J unless the cached factorization has the same active set."""
        if self._factorized_set is not None and self._same_sets(active, self._factorized_set):
            return False
        self._factorize()
        self._factorized_set = active.copy()
        return True

    def _factorize(self) -> None:
        self.A.zeroEntries()
        dolfinx.fem.petsc.assemble_matrix(self.A, self._J, bcs=self.bcs)
        self.A.assemble()
        self.solver.set_operator(self.A)

    def _step(self) -> None:
        self.b.scale(-1.0)
        self.solver.solve(self.b, self.du)
        self.u.x.petsc_vec.axpy(1.0, self.du)
        self.u.x.scatter_forward()

    def _active_set(self) -> np.ndarray:
        vec = dolfinx.fem.assemble_vector(self._indicator)
        vec.scatter_reverse(dolfinx.la.InsertMode.add)
        return vec.array[: self.Q.dofmap.index_map.size_local] > 0.0

    def _same_sets(self, a: np.ndarray, b: np.ndarray) -> bool:
        return self.mesh.comm.allreduce(bool(np.array_equal(a, b)), op=MPI.LAND)

    def load_norm(self) -> float:
        """‖b‖ of the load vector (f and Robin data)."""
        return self._assemble_vector(self._load, self.b).norm()

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
        return semismooth_newton(
            residual=self._residual,
            active_set=self._active_set,
            same_sets=self._same_sets,
            factorize=self._factorize_for,
            step=self._step,
            load_norm=self.load_norm(),
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

    def contact_profile(self) -> ContactProfile:
        """u_c and the consistent nodal normal stress σ_c = (R·n_p)/w_p along Γ_C, on every rank."""
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        nloc = self.Q.dofmap.index_map.size_local
        w = dolfinx.fem.assemble_vector(self._weights)
        w.scatter_reverse(dolfinx.la.InsertMode.add)
        N = dolfinx.fem.assemble_vector(self._normals)
        N.scatter_reverse(dolfinx.la.InsertMode.add)
        R = dolfinx.fem.assemble_vector(self._reaction)
        R.scatter_reverse(dolfinx.la.InsertMode.add)
        on_contact = w.array[:nloc] > 0.0
        on_contact[self._dirichlet_q[self._dirichlet_q < nloc]] = False  # clamped corners: not contact
        on = np.flatnonzero(on_contact)
        gdim = self.mesh.geometry.dim
        Nn = N.array.reshape(-1, gdim)[on]
        normal = Nn / np.linalg.norm(Nn, axis=1)[:, None]
        u_c = np.sum(self.u.x.array.reshape(-1, gdim)[on] * normal, axis=1)
        sigma_c = np.sum(R.array.reshape(-1, gdim)[on] * normal, axis=1) / w.array[on]
        y = self.Q.tabulate_dof_coordinates()[on, 1]
        comm = self.mesh.comm
        y, u_c, sigma_c = (np.concatenate(comm.allgather(a)) for a in (y, u_c, sigma_c))
        order = np.argsort(y, kind="stable")
        return ContactProfile(y[order], u_c[order], sigma_c[order])

    # -- interface Newton support (hybrid.newton): the affine pieces of the problem ---------------
    def reset(self) -> None:
        """Forget the solution and the cached factorization (the next ``solve`` starts cold from u = 0)."""
        self.u.x.array[:] = 0.0
        self._factorized_set = None

    def residual_norm(self) -> tuple[float, float]:
        """(‖F(u)‖, ‖b‖) at the current u and data: ``solve`` accepts u when ‖F‖ ≤ rtol‖b‖ + atol."""
        return self._residual(), self.load_norm()

    def contact_free_matrix(self) -> PETSc.Mat:
        """A new matrix J₀ = a + α∫_γ (the Jacobian with no contact node active), Γ_D rows = identity."""
        keep = self.u.x.array.copy()
        self.u.x.array[:] = 0.0  # H(0) = 0: no penalty term
        A = dolfinx.fem.petsc.create_matrix(self._J)
        dolfinx.fem.petsc.assemble_matrix(A, self._J, bcs=self.bcs)
        A.assemble()
        self.u.x.array[:] = keep
        return A

    def body_load(self, out: PETSc.Vec) -> PETSc.Vec:
        """out ← −F(0) with zero Robin data: (f, v), zero on Γ_D rows (so J(u) u = body_load + data at a solution)."""
        keep_u = self.u.x.array.copy()
        keep_g = self.g.x.array.copy() if self.g is not None else None
        self.u.x.array[:] = 0.0
        if self.g is not None:
            self.g.x.array[:] = 0.0
        self._assemble_vector(self._F, out)
        out.scale(-1.0)
        self.u.x.array[:] = keep_u
        if self.g is not None:
            self.g.x.array[:] = keep_g
        return out

    def contact_nodes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Owned Γ_C nodes off Γ_D: (node = block index of u, unit normal (k, gdim), vertex weight w_p).

        The penalty term is Σ_p (w_p/δ) (u_p·n_p)⁺ (v_p·n_p) when the facets at each node share
        one normal (a straight Γ_C); n_p is the weight-averaged facet normal otherwise.
        """
        if not self.contact:
            raise InputError("this subproblem has no contact boundary")
        nloc = self.Q.dofmap.index_map.size_local
        w = dolfinx.fem.assemble_vector(self._weights)
        w.scatter_reverse(dolfinx.la.InsertMode.add)
        N = dolfinx.fem.assemble_vector(self._normals)
        N.scatter_reverse(dolfinx.la.InsertMode.add)
        on = w.array[:nloc] > 0.0
        on[self._dirichlet_q[self._dirichlet_q < nloc]] = False
        nodes = np.flatnonzero(on)
        gdim = self.mesh.geometry.dim
        Nn = N.array.reshape(-1, gdim)[nodes]
        return nodes, Nn / np.linalg.norm(Nn, axis=1)[:, None], w.array[nodes].copy()

    def destroy(self) -> None:
        """Free the PETSc objects (collective)."""
        for obj in (self.A, self.b, self.du, self._K, self._M, self._work):
            obj.destroy()
        self.solver.destroy()


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


def solve_primal_monolithic(
    msh: dmesh.Mesh,
    facet_tags: dmesh.MeshTags,
    fields: MaterialFields,
    *,
    delta: float,
    newton: NewtonOptions = NewtonOptions(),
    prefix: str = "fc_primal_mono_",
) -> PrimalSolution:
    """Penalized primal contact on the whole mesh (METHOD §2) by semismooth Newton."""
    start = time.perf_counter()
    problem = PrimalSubproblem(msh, facet_tags, fields, delta=delta, alpha=None, prefix=prefix, newton=newton)
    history = problem.solve()
    elapsed = time.perf_counter() - start
    profile = problem.contact_profile()
    log.info(
        "monolithic primal: %d Newton steps, active-set sizes %s, penetration %.3e, %.2f s",
        history.steps, history.active_sizes, profile.penetration, elapsed,
    )
    return PrimalSolution(problem.u, history, profile, delta, problem.num_dofs, elapsed, problem)
