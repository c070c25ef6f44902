"""PETSc helpers: a checked direct solver, PETSc ↔ SciPy matrix copies, small norms."""

import dolfinx.fem.petsc
import scipy.sparse as sp
from dolfinx import fem
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError

__all__ = ["DirectSolver", "assemble_scipy", "petsc_to_scipy", "quadratic_form", "scipy_to_petsc"]

#: Default options of every direct solve (each solver gets its own prefix).
DIRECT_OPTIONS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}


class DirectSolver:
    """A factorized operator (MUMPS LU by default) whose every solve is checked."""

    def __init__(self, comm, *, prefix: str, options: dict | None = None) -> None:
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        for key, value in (options or DIRECT_OPTIONS).items():
            opts[f"{prefix}{key}"] = value
        self.ksp.setFromOptions()
        self.prefix = prefix
        self.factorizations = 0

    def set_operator(self, A: PETSc.Mat) -> None:
        """Use A from now on; the factorization happens at the next solve."""
        self.ksp.setOperators(A)
        self.ksp.setUp()
        reason = self.ksp.getPC().getFailedReason()
        if reason != 0:
            raise ConvergenceError(f"{self.prefix}: factorization failed (PETSc PC failed reason {reason})")
        self.factorizations += 1

    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """x = A⁻¹ b, raising ConvergenceError on any PETSc failure."""
        self.ksp.solve(b, x)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise ConvergenceError(f"{self.prefix}: linear solve failed, KSP reason {reason}")

    def destroy(self) -> None:
        self.ksp.destroy()


def quadratic_form(A: PETSc.Mat, x: PETSc.Vec, work: PETSc.Vec) -> float:
    """xᵀ A x (collective)."""
    A.mult(x, work)
    return work.dot(x)


def petsc_to_scipy(A: PETSc.Mat) -> sp.csr_matrix:
    """Copy a sequential PETSc AIJ matrix to SciPy CSR."""
    indptr, indices, data = A.getValuesCSR()
    return sp.csr_matrix((data.copy(), indices.copy(), indptr.copy()), shape=A.getSize())


def scipy_to_petsc(A: sp.spmatrix, comm=PETSc.COMM_SELF) -> PETSc.Mat:
    """A sequential PETSc AIJ copy of a SciPy sparse matrix (assembled)."""
    A = sp.csr_matrix(A)
    A.sort_indices()
    M = PETSc.Mat().createAIJ(
        size=A.shape, csr=(A.indptr.astype(PETSc.IntType), A.indices.astype(PETSc.IntType), A.data), comm=comm
    )
    M.assemble()
    return M


def assemble_scipy(form) -> sp.csr_matrix:
    """Assemble a bilinear UFL form (square or not, blocked spaces allowed) into SciPy CSR (serial)."""
    A = dolfinx.fem.petsc.assemble_matrix(fem.form(form))
    A.assemble()
    out = petsc_to_scipy(A)
    A.destroy()
    return out
