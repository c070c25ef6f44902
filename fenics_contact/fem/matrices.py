"""Matrices between PETSc and SciPy: copies both ways, the assembly of a bilinear form into SciPy CSR, and the
products and sizes the solvers' checks use (xᵀAx, the residual's term sizes |A||x| + |b|, the vector mass
matrix applied by the block of one component).  The factorizations are in ``fem.linalg``."""

import dolfinx.fem.petsc
import dolfinx.la
import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from petsc4py import PETSc

__all__ = [
    "AbsoluteTerms",
    "ComponentBlockProduct",
    "assemble_scipy",
    "petsc_to_scipy",
    "quadratic_form",
    "scipy_to_petsc",
]


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


class ComponentBlockProduct:
    """y = A x for a sequential matrix A = A₁ ⊗ I of a blocked space (``bs`` components interleaved) whose form
    couples equal components only, with the same entries for each (the vector mass matrix): A₁, A's block of the
    first component (taken once), applied to the components side by side by SciPy reads 1/bs² of A's entries for
    the same products, in the same order (the entries A holds between different components are zeros)."""

    def __init__(self, A: PETSc.Mat, bs: int) -> None:
        if A.getComm().getSize() != 1:
            raise ValueError("ComponentBlockProduct takes a sequential matrix")
        n = A.getSize()[0]
        rows = PETSc.IS().createStride(n // bs, 0, bs, comm=PETSc.COMM_SELF)
        block = A.createSubMatrix(rows, rows)
        self.block = petsc_to_scipy(block)
        self.bs = bs
        for obj in (block, rows):
            obj.destroy()

    @classmethod
    def of_block(cls, block: sp.csr_matrix, bs: int) -> "ComponentBlockProduct":
        """The product by A = A₁ ⊗ I given its block A₁ of one component (e.g. the scalar mass matrix on the nodes,
        which the vector mass matrix repeats), without A."""
        product = cls.__new__(cls)
        product.block, product.bs = block, bs
        return product

    def mult(self, x: PETSc.Vec, y: PETSc.Vec) -> None:
        """y ← A x."""
        y.getArray()[:] = (self.block @ x.getArray(readonly=True).reshape(-1, self.bs)).ravel()


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
