"""The right preconditioner of the matrix-free interface Newton's GMRES: Ω₁'s Robin response by a cheap Ω₁ model.

A Newton–GMRES step (``hybrid.krylov_newton``) solves (I − P₂P₁) z = y on the interface values, P₁ = a⊙T₁ + b
Ω₁'s Robin map (each product one Ω₁ solve), P₂ = a⊙Y₂ + b Ω₂'s at its current active set (one back-solve).  The
cheap model is Ω₁'s operator A₁ (its Robin term on γ included) on a subspace, Z: the unknowns of the band B of Ω₁
within ``layers`` couplings of γ (graph distance in A₁: about ``layers`` cells; zero displacement beyond) and,
beyond the band, the coarse functions of Ω₁'s AMG hierarchy (``fem.amg.amg_coarse_space``: the aggregates'
rigid motions), which carry the smooth far-field response the band misses (the stiff channels' rigid motions, the
soft body's bending).  Its Robin map is P̃₁ = a⊙N Z J_Z⁻¹ Zᵀ C + b, J_Z = Zᵀ A₁ Z (a Ritz approximation of
A₁⁻¹).  M = I − P₂P̃₁ is applied exactly: M z = y is the sparse system

    J_Z u_Z − Zᵀ C z = 0,    J₂ u₂ − C₂ (a⊙N Z u_Z) − b C₂ z = 0,    ((1 − b²)/a) z − b N Z u_Z − N₂u₂ = y/a

(unknowns the model's and Ω₂'s states and z; z = 0 where no data act), factorized by MUMPS LU once per Ω₂
Jacobian (its active set); M⁻¹ y is one back-solve.  With Z all of Ω₁, M is the interface operator itself.
The GMRES then solves (I − P₂P₁) M⁻¹ w = y, each product still one exact Ω₁ solve: the fixed point stays the
monolithic solution, only the products fall.  One process (the matrices are taken sequentially).
"""

import numpy as np
import scipy.sparse as sp

from fenics_contact.errors import InputError
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.matrices import petsc_to_scipy
from fenics_contact.hybrid.response import PrimalPart

__all__ = ["BandPreconditioner", "REGULARIZATION"]

#: the coarse block's diagonal is raised by this fraction: the coarse functions masked on the band can be linearly
#: dependent (an aggregate with one node outside the band), and Z u (the state) does not see such a dependence
REGULARIZATION = 1e-8


def _data_matrix(part: PrimalPart) -> sp.csr_matrix:
    """C: global interface data → the part's owned right-hand side (vertex weights at the γ DOFs)."""
    return sp.csr_matrix((part.data_w, (part.data_at, part.data_index)), shape=(part.nown, part.n_g))


def _trace_matrix(part: PrimalPart) -> sp.csr_matrix:
    """N: the part's state → its trace on γ (global interface values)."""
    ones = np.ones(part.trace_at.size)
    return sp.csr_matrix((ones, (part.trace_index, part.trace_at)), shape=(part.n_g, part.nown))


def band_of(A: sp.csr_matrix, seeds: np.ndarray, layers: int) -> np.ndarray:
    """The unknowns within ``layers`` couplings of ``seeds`` in the graph of A (sorted)."""
    G = A.astype(bool).astype(np.int8)
    reached = np.zeros(A.shape[0], dtype=bool)
    reached[seeds] = True
    for _ in range(layers):
        grown = (G @ reached.astype(np.int8)) > 0
        if np.array_equal(grown | reached, reached):
            break
        reached |= grown
    return np.flatnonzero(reached)


class BandPreconditioner:
    """M⁻¹ for the interface operator I − P₂P₁ of ``KrylovInterface``: P₁ by the band of ``layers`` couplings and
    the coarse functions ``coarse`` (an interpolation to Ω₁'s unknowns, or None)."""

    def __init__(
        self,
        omega1: PrimalPart,
        omega2: PrimalPart,
        a: np.ndarray,
        b: float,
        *,
        layers: int,
        coarse: sp.csr_matrix | None = None,
    ) -> None:
        if isinstance(layers, bool) or not isinstance(layers, (int, np.integer)) or layers < 0:
            raise InputError(f"the band preconditioner's layers must be an integer >= 0, got {layers!r}")
        self.omega2, self.a, self.b, self.layers = omega2, a, b, int(layers)
        A1 = petsc_to_scipy(omega1.sub.A)
        C1, N1 = _data_matrix(omega1), _trace_matrix(omega1)
        self.band = band_of(A1, omega1.trace_at, int(layers)) if layers else np.zeros(0, dtype=np.int64)
        n1 = A1.shape[0]
        Z = sp.csr_matrix((np.ones(self.band.size), (self.band, np.arange(self.band.size))), shape=(n1, self.band.size))
        if coarse is not None:  # the coarse functions, zero on the band (a Ritz space: band ⊕ coarse far field)
            outside = np.ones(n1)
            outside[self.band] = 0.0
            P = (sp.diags(outside) @ sp.csr_matrix(coarse)).tocsc()
            P = P[:, np.flatnonzero(np.diff(P.indptr) > 0)]
            Z = sp.hstack([Z, P]).tocsr()
        J = (Z.T @ A1 @ Z).tocsr()
        if coarse is not None:  # masked coarse functions may depend on each other: a relative shift of their pivots
            shift = np.zeros(J.shape[0])
            shift[self.band.size :] = REGULARIZATION * J.diagonal()[self.band.size :]
            J = (J + sp.diags(shift)).tocsr()
        self.J_B = J
        self.C_B = (Z.T @ C1).tocsr()
        self.N_B = (N1 @ Z).tocsr()
        self.C_2, self.N_2 = _data_matrix(omega2), _trace_matrix(omega2)
        self.free = np.flatnonzero(omega1.data_free() | omega2.data_free())
        self.factorizations = 0  #: the block systems factorized (one per Ω₂ Jacobian)
        self._key = None
        self._lu: SparseFactor | None = None

    @property
    def size(self) -> int:
        """Unknowns of the cheap Ω₁ model (the band's and the coarse functions')."""
        return int(self.J_B.shape[0])

    def _factorize(self) -> None:
        """The block system for Ω₂'s current Jacobian (the matrix its factorization holds)."""
        solver = self.omega2.sub.solver
        key = (id(solver), solver.factorizations)
        if key == self._key:
            return
        n_g, a, b = self.a.size, self.a, self.b
        J_2 = petsc_to_scipy(self.omega2.sub.A)
        free = np.zeros(n_g, dtype=bool)
        free[self.free] = True
        inv_a = np.where(free, 1.0 / np.where(free, a, 1.0), 0.0)
        R = sp.diags(free.astype(float))  # the free rows of the last block (the others: z = 0)
        diag_z = np.where(free, (1.0 - b * b) * inv_a, 1.0)
        K = sp.bmat(
            [
                [self.J_B, None, -self.C_B],
                [-self.C_2 @ sp.diags(a) @ self.N_B, J_2, -b * self.C_2],
                [-b * (R @ self.N_B), -R @ self.N_2, sp.diags(diag_z)],
            ],
            format="csr",
        )
        if self._lu is not None:
            self._lu.destroy()
        self._lu = SparseFactor.from_csr(K, what="the band preconditioner's block system", icntl={14: 200})
        self._key = key
        self.factorizations += 1

    def solve(self, y: np.ndarray) -> np.ndarray:
        """z = M⁻¹ y on the free interface values (y, z: values at ``free``)."""
        self._factorize()
        n_g = self.a.size
        rhs = np.zeros(self.J_B.shape[0] + self.omega2.nown + n_g)
        rhs[rhs.size - n_g + self.free] = y / self.a[self.free]
        x = self._lu.solve(rhs[:, None])[:, 0]
        return x[rhs.size - n_g + self.free]

    def destroy(self) -> None:
        if self._lu is not None:
            self._lu.destroy()
            self._lu = None
