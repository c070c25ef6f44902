"""PETSc helpers: a checked direct solver, PETSc ↔ SciPy matrix copies, small norms."""

import dolfinx.fem.petsc
import dolfinx.la
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError, InputError

__all__ = ["AbsoluteTerms", "DirectSolver", "assemble_scipy", "petsc_to_scipy", "quadratic_form", "scipy_to_petsc"]

#: |entries| of a matrix a factorization handles safely in double precision (squares stay finite)
SAFE_RANGE = (1e-150, 1e150)

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
        """Use A from now on and factorize it.

        Raises InputError when A has non-finite entries (overflowing data, e.g. E = 1e308) or its
        largest entry is outside the range a double-precision factorization handles (``SAFE_RANGE``:
        squares and residual norms must stay finite); ConvergenceError when the factorization fails
        (a singular matrix).
        """
        _, _, values = A.getValuesCSR()
        finite = A.getComm().tompi4py().allreduce(bool(np.all(np.isfinite(values))), op=MPI.LAND)
        largest = A.getComm().tompi4py().allreduce(float(np.max(np.abs(values), initial=0.0)), op=MPI.MAX)
        if not finite:
            raise InputError(self._range_message("non-finite values"))
        if not SAFE_RANGE[0] <= largest <= SAFE_RANGE[1]:
            raise InputError(self._range_message(f"entries up to {largest:.3g}"))
        self.ksp.setOperators(A)
        self.ksp.setUp()
        reason = self.ksp.getPC().getFailedReason()
        if reason != 0:
            raise ConvergenceError(f"{self.prefix}: factorization failed (PETSc PC failed reason {reason}; "
                                   "a singular matrix?)")
        self.factorizations += 1

    def _range_message(self, what: str) -> str:
        return (f"{self.prefix}: the matrix has {what}: the data overflow the range of a double-precision "
                f"factorization (about {SAFE_RANGE[0]:g} to {SAFE_RANGE[1]:g}): Young's modulus, 1/δ, α or 1/ε too "
                "large or too small. Rescale the units (the displacement scales as load/E).")

    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """x = A⁻¹ b, raising ConvergenceError on any PETSc failure."""
        self.ksp.solve(b, x)
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            raise ConvergenceError(f"{self.prefix}: linear solve failed, KSP reason {reason}")

    def destroy(self) -> None:
        self.ksp.destroy()


class AbsoluteTerms:
    """‖ |A||x| + |b| ‖∞: the size of the terms of the residual A x − b, row by row.

    The yardstick of a residual check: rounding leaves |A x − b| ≲ ε(|A||x| + |b|) componentwise
    (Oettli–Prager), whatever the scaling of the rows (a penalty row of 1/δ times a tiny normal
    displacement, a stiff row beside a soft one). Keeps a matrix with the pattern of A between calls.
    """

    def __init__(self) -> None:
        self._abs: PETSc.Mat | None = None

    def __call__(self, A: PETSc.Mat, x: PETSc.Vec, b: PETSc.Vec) -> float:
        if self._abs is None:
            self._abs = A.duplicate(copy=True)
        else:
            A.copy(self._abs, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        rows, cols, values = self._abs.getValuesCSR()
        self._abs.setValuesCSR(rows, cols, np.abs(values))
        self._abs.assemble()
        ax, terms = x.copy(), b.copy()
        ax.abs()
        terms.abs()
        self._abs.multAdd(ax, terms, terms)
        size = terms.norm(PETSc.NormType.NORM_INFINITY)
        ax.destroy()
        terms.destroy()
        return size

    def destroy(self) -> None:
        if self._abs is not None:
            self._abs.destroy()


def quadratic_form(A: PETSc.Mat, x: PETSc.Vec, work: PETSc.Vec) -> float:
    """xᵀ A x (collective)."""
    A.mult(x, work)
    return work.dot(x)


def petsc_to_scipy(A: PETSc.Mat) -> sp.csr_matrix:
    """Copy a sequential PETSc AIJ matrix to SciPy CSR."""
    indptr, indices, data = A.getValuesCSR()  # fresh arrays (petsc4py copies), owned by the result
    return sp.csr_matrix((data, indices, indptr), shape=A.getSize())


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
    """Assemble a bilinear UFL form (square or not, blocked spaces allowed) into SciPy CSR (serial).

    DOLFINx's own CSR matrix (expanded blocks) is used where it can be (equal block sizes of the two spaces;
    the CSR arrays are then DOLFINx's, no copy: Algorithm 4's compliance blocks at h = 1/128, 221 MB, took
    1.1 s to copy out of PETSc); else a PETSc matrix, copied.  The same entries either way (one assembly loop,
    other insertion functions)."""
    compiled = fem.form(form)
    spaces = compiled.function_spaces
    if compiled.mesh.comm.size == 1 and spaces[0].dofmap.index_map_bs == spaces[1].dofmap.index_map_bs:
        A = fem.assemble_matrix(compiled, block_mode=dolfinx.la.BlockMode.expanded)
        A.scatter_reverse()
        return A.to_scipy()  # (a view: its arrays keep DOLFINx's matrix alive)
    A = dolfinx.fem.petsc.assemble_matrix(compiled)
    A.assemble()
    out = petsc_to_scipy(A)
    A.destroy()
    return out
