"""Generalized symmetric eigenproblems A x = λ B x on one process: one SLEPc driver and Sylvester's inertia count.

``generalized_eigenpairs`` is the SLEPc driver of the local spectral problems of both multiscale methods
(the primal CEM's a_i φ = λ s_i φ, the mixed CEM's Stage I pencil): Krylov–Schur with shift-and-invert about
a target for the pairs nearest it, optionally orthogonal to known eigenvectors (deflation), or dense LAPACK
for all pairs; too few converged pairs are an error.  A Krylov method can miss copies of a multiple
eigenvalue, so its callers check the result with ``count_eigenvalues_below`` (the negative inertia of
A − σB).
"""

import numpy as np
import scipy.sparse as sp
from petsc4py import PETSc
from slepc4py import SLEPc

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.matrices import scipy_to_petsc

__all__ = ["EIGEN_METHODS", "count_eigenvalues_below", "generalized_eigenpairs"]

#: "krylovschur": SLEPc Krylov–Schur with shift-and-invert (the pairs nearest a target); "lapack": dense, all pairs
EIGEN_METHODS = ("krylovschur", "lapack")


def generalized_eigenpairs(
    A: PETSc.Mat,
    B: PETSc.Mat,
    nev: int,
    method: str = "krylovschur",
    *,
    tol: float,
    target: float | None = None,
    factor_solver: str | None = None,
    deflation: np.ndarray | None = None,
    max_it: int = 1000,
    label: str = "generalized eigenproblem",
) -> tuple[np.ndarray, np.ndarray]:
    """Every converged pair of A x = λ B x (SLEPc GHEP on COMM_SELF, B ⪰ 0): (values (real), vectors (columns)).

    ``method`` "krylovschur": the ``nev`` pairs nearest ``target`` (Krylov–Schur on the shift-and-invert
    transform (A − target·B)⁻¹B, a direct LU by ``factor_solver``: None for PETSc's own, e.g. "mumps"),
    orthogonal to the columns of ``deflation``; "lapack": all pairs, dense.  Relative tolerance ``tol``,
    at most ``max_it`` restarts.  The pairs come in SLEPc's order (not sorted).
    Raises ConvergenceError when fewer than ``nev`` pairs converge (``label`` names the problem).
    """
    if method not in EIGEN_METHODS:
        raise InputError(f"unknown eigensolver {method!r}; choose one of {EIGEN_METHODS}")
    if method == "krylovschur" and target is None:
        raise InputError("Krylov–Schur with shift-and-invert needs a target")
    n = A.getSize()[0]
    eps = SLEPc.EPS().create(PETSc.COMM_SELF)
    defl = []
    try:
        eps.setOperators(A, B)
        eps.setProblemType(SLEPc.EPS.ProblemType.GHEP)
        if method == "krylovschur":
            eps.setType(SLEPc.EPS.Type.KRYLOVSCHUR)
            eps.setDimensions(nev)
            st = eps.getST()
            st.setType(SLEPc.ST.Type.SINVERT)
            ksp = st.getKSP()
            ksp.setType(PETSc.KSP.Type.PREONLY)
            pc = ksp.getPC()
            pc.setType(PETSc.PC.Type.LU)
            if factor_solver is not None:
                pc.setFactorSolverType(factor_solver)
            eps.setTarget(target)
            eps.setWhichEigenpairs(SLEPc.EPS.Which.TARGET_REAL)
            if deflation is not None and deflation.shape[1]:
                for col in deflation.T:
                    vec = A.createVecRight()
                    vec.array[:] = col
                    defl.append(vec)
                eps.setDeflationSpace(defl)
        else:
            eps.setType(SLEPc.EPS.Type.LAPACK)
            eps.setDimensions(n)
            eps.setWhichEigenpairs(SLEPc.EPS.Which.SMALLEST_REAL)
        eps.setTolerances(tol, max_it)
        eps.solve()
        nconv = eps.getConverged()
        if nconv < nev:
            raise ConvergenceError(
                f"{label} ({method}, n = {n}): only {nconv} of {nev} eigenpairs converged "
                f"(reason {eps.getConvergedReason()})"
            )
        vr = A.createVecRight()
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
    # null-pivot detection (ICNTL(24)) is required for the inertia; the factor owns (destroys) the matrix
    factor = SparseFactor(scipy_to_petsc((A - sigma * S).tocsr()), cholesky=True, icntl={24: 1}, what="A − σS")
    try:
        nneg, _, _ = factor.inertia()
    finally:
        factor.destroy()
    return nneg
