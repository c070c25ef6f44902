"""Assembly of the mixed subproblem's bulk operators and boundary loads on the AW × DG P1 spaces.

K = Pᵀ A P (compliance), B = B_dg P (divergence), M (DG P1 mass), R = Pᵀ R_γ P (the Robin form with
β = 1) and K̃ = K + β R, the stress block of the Jacobian; the displacement load G = −(f, v) − (div σ_t, v)
and the constant stress-side load F_∂ of the traction lifting σ_t and of u_D:
F_∂ = −Pᵀ(Aσ_t, τ) + Pᵀ∫_ΓD u_D·τn − β Pᵀ R_γ σ_t.  Forms come from ``forms_mixed``.
"""

import dolfinx.fem.petsc
import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import InputError
from fenics_contact.fem import forms_mixed
from fenics_contact.fem.distributed import DistributedMatrix, global_dot
from fenics_contact.fem.mixed_spaces import MixedSpaces, displacement_trace_function
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.tags import Boundary

__all__ = ["MixedOperators", "assemble_array", "assemble_petsc", "dot", "norm", "without_product_data"]


def norm(a: np.ndarray, comm=None) -> float:
    """‖a‖ over all ranks (owned entries)."""
    return float(np.sqrt(dot(a, a, comm)))


def dot(a: np.ndarray, b: np.ndarray, comm=None) -> float:
    """a·b over all ranks (owned entries; no BLAS: OpenBLAS threads contend with MUMPS on small machines)."""
    return global_dot(comm, a, b) if comm is not None else float(np.einsum("i,i->", a, b))


def assemble_array(form) -> np.ndarray:
    """A linear form assembled (ghost contributions added) as a NumPy array of the local entries."""
    b = fem.assemble_vector(fem.form(form))
    b.scatter_reverse(dolfinx.la.InsertMode.add)
    return b.array.copy()


def without_product_data(C: PETSc.Mat) -> PETSc.Mat:
    """A copy of a product C = PᵀAP (or A P) without the intermediate data PETSc keeps in C for a reuse
    (the size of A P: as much again as P), which is never needed here."""
    out = C.duplicate(copy=True)
    C.destroy()
    return out


def assemble_petsc(form) -> PETSc.Mat:
    """A bilinear form assembled as a PETSc matrix."""
    A = dolfinx.fem.petsc.assemble_matrix(fem.form(form))
    A.assemble()
    return A


class MixedOperators:
    """K, B, M, R, K̃ = K + βR (distributed), the loads G and F_∂, and u_D on Γ_D of one mixed subproblem.

    ``operators=False`` assembles only M, G and F_∂ (no K, B, R: Algorithm 4's Ω₁ assembles its own cell
    blocks); ``beta`` None: no Robin term (K̃ = K).
    """

    def __init__(
        self,
        msh: dmesh.Mesh,
        facet_tags: dmesh.MeshTags,
        fields: MaterialFields,
        spaces: MixedSpaces,
        *,
        beta: float | None,
        operators: bool,
    ) -> None:
        comm = msh.comm
        n_dg = spaces.n_dg
        s, t = ufl.TrialFunction(spaces.dg), ufl.TestFunction(spaces.dg)
        w, v = ufl.TrialFunction(spaces.U), ufl.TestFunction(spaces.U)
        n = ufl.FacetNormal(msh)
        self.K = self.B = self.R = None
        if operators:
            P_petsc = spaces.space.prolongation_petsc
            A = assemble_petsc(forms_mixed.compliance_form(s, t, fields.lmbda, fields.mu))
            self.K = DistributedMatrix(without_product_data(A.PtAP(P_petsc)))
            A.destroy()
            D = assemble_petsc(forms_mixed.divergence_form(s, v))
            self.B = DistributedMatrix(without_product_data(D.matMult(P_petsc)))
            D.destroy()
        self.M = DistributedMatrix(assemble_petsc(forms_mixed.mass_form(w, v)))
        self.G = assemble_array(forms_mixed.load_form(fields.f, v))[: spaces.n_u]

        # -- boundary data: traction lifting σ_t (σ = P c + σ_t) and the natural Γ_D term ------
        self.F_boundary = np.zeros(spaces.n_sigma)  # constant stress-side load of the lifting and of u_D
        self.s0_function: fem.Function | None = None
        if spaces.lifted:
            s0 = fem.Function(spaces.dg)
            s0.x.array[:n_dg] = spaces.s0
            s0.x.scatter_forward()
            self.G -= assemble_array(forms_mixed.divergence_form(s0, v))[: spaces.n_u]
            self.F_boundary -= (
                spaces.Pd.T @ assemble_array(forms_mixed.compliance_form(s0, t, fields.lmbda, fields.mu))[:n_dg]
            )
            self.s0_function = s0
        self.u_D: fem.Function | None = None
        has_dirichlet = comm.allreduce(int(facet_tags.find(Boundary.GAMMA_D).size), op=MPI.SUM) > 0
        if fields.boundary.displacement is not None and has_dirichlet:
            self.u_D = displacement_trace_function(msh, fields.boundary.displacement)
            dsD = forms_mixed.boundary_measure(msh, facet_tags)(Boundary.GAMMA_D)
            self.F_boundary += spaces.Pd.T @ assemble_array(forms_mixed.robin_data_form(self.u_D, t, n, dsD))[:n_dg]

        # -- Robin term on γ ------------------------------------------------------------
        ds = forms_mixed.boundary_measure(msh, facet_tags)
        self.Kt = self.K
        if beta is not None:
            gamma = facet_tags.find(Boundary.INTERFACE)
            if comm.allreduce(int(gamma.size), op=MPI.SUM) == 0:
                raise InputError("a Robin subproblem needs interface (γ) facets")
            if operators or spaces.lifted:
                R_dg = assemble_petsc(forms_mixed.robin_form(s, t, n, 1.0, ds(Boundary.INTERFACE)))
                if operators:
                    self.R = DistributedMatrix(without_product_data(R_dg.PtAP(P_petsc)))
                    Kt = self.K.mat.duplicate(copy=True)
                    Kt.axpy(beta, self.R.mat, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
                    self.Kt = DistributedMatrix(Kt)
                if spaces.lifted:  # (also without operators: Algorithm 4's Ω₁ reads s0, G and n0)
                    y = R_dg.createVecLeft()
                    x = R_dg.createVecRight()
                    x.array[:] = spaces.s0
                    R_dg.mult(x, y)
                    self.F_boundary -= beta * (spaces.Pd.T @ y.array)
                    x.destroy()
                    y.destroy()
                R_dg.destroy()

    def destroy(self) -> None:
        """Free the PETSc matrices (collective)."""
        for op in (self.K, self.B, self.M, self.R):
            if op is not None:
                op.destroy()
        if self.Kt is not None and self.Kt is not self.K:
            self.Kt.destroy()
