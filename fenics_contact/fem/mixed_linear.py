"""The saddle-point Jacobian of the mixed subproblem and its MUMPS factorization, cached by active set.

    J = [[K̃ + (1/ε) Qᵀ W H Q, Bᵀ], [B, 0]]

depends on the iterate only through the active set H, so a factorization is reused until the set
changes.  The sparsity pattern holds every Γ_C node's penalty entries (``SaddlePointMatrix``): when the
set changes only values change, and MUMPS redoes the numeric factorization, not the analysis.

**Units.**  On a mesh of size h the stress block K̃ + (1/ε) Qᵀ W H Q scales like h²/E (compliance, and ε ∝ E),
the divergence block B like h: a stress pivot is h/E times the divergence entries of its column, so with
E = 2.1e11 (steel in Pa) or lengths in μm MUMPS' threshold pivoting delays every stress pivot and its workspace
overflows.  The matrix factorized is the equilibrated D J D, D = diag(s I_σ, I_u/s), s² ≈ E_ref/L_ref
(``stress_scale``: the power of two nearest, so D J D and the scaled vectors round nothing; E_ref a reference
Young's modulus, L_ref a reference length): the stress pivots are h/L_ref times the divergence entries whatever
the units, B is unchanged, and J⁻¹ r = D (D J D)⁻¹ D r.  With E_ref/L_ref in (1/2, 2) (every built-in model on
the unit square: E_ref = L_ref = 1) s = 1 and the factorization is J's own.

The residual F = (F_σ, F_u) has the same two units: F_σ (compliance × stress × area) a length², F_u (stress ×
length) E/L_ref times that, so ‖F‖ and the sums of the norms of its terms are measured equilibrated,
‖D F‖ = (s²‖F_σ‖² + ‖F_u‖²/s²)^½ (``equilibrated_norm``): both blocks in one unit, the same relative numbers in
any units (without it, the round-off of the divergence block, E times that of E = 1, swamps a yardstick made of
the stress block's terms at E = 2.1e11).
"""

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.distributed import SaddlePointMatrix
from fenics_contact.fem.linalg import DIRECT_OPTIONS, DirectSolver
from fenics_contact.fem.mixed_assembly import MixedOperators, dot
from fenics_contact.fem.mixed_contact import ContactNodes

__all__ = [
    "MIXED_SOLVER_OPTIONS",
    "SaddlePointFactorization",
    "equilibrated_norm",
    "equilibrated_size",
    "saddle_point_scaling",
    "stress_scale",
]

#: MUMPS LU with the AMF ordering: half the factorization time of the default ordering on the
#: AW saddle-point matrices (3.8 s instead of 7.5 s at h = 1/128, 0.7 s instead of 1.3 s at 1/64).
MIXED_SOLVER_OPTIONS = {**DIRECT_OPTIONS, "mat_mumps_icntl_7": "2"}


def stress_scale(stiffness: float) -> float:
    """s = 2^k with s² nearest ``stiffness`` = E_ref/L_ref (1 for values in (1/2, 2)); exponents are kept within
    ±500 (s² finite for any finite value)."""
    if not (np.isfinite(stiffness) and stiffness > 0):
        raise InputError(f"the reference stiffness E_ref/L_ref must be finite and > 0, got {stiffness!r}")
    return float(2.0 ** int(np.clip(np.round(0.5 * np.log2(stiffness)), -500, 500)))


def saddle_point_scaling(scale: float, n_sigma: int, n_u: int, n_extra: int = 0) -> np.ndarray | None:
    """The diagonal D = (s, …, s, 1/s, …, 1/s, 1, …, 1) of n_sigma stress, n_u displacement and n_extra
    dimensionless unknowns (None for s = 1: no equilibration)."""
    if scale == 1.0:
        return None
    return np.concatenate([np.full(n_sigma, scale), np.full(n_u, 1.0 / scale), np.ones(n_extra)])


def equilibrated_norm(scale: float, r1: np.ndarray, r2: np.ndarray, comm: MPI.Comm) -> float:
    """‖D r‖ = (s²‖r1‖² + ‖r2‖²/s²)^½ of the stress part r1 and displacement part r2 (owned entries) of a residual,
    s = ``scale`` (a power of two: the scaling rounds nothing; s = 1: the plain norm)."""
    s2 = scale * scale
    return float(np.sqrt(s2 * dot(r1, r1, comm) + dot(r2, r2, comm) / s2))


def equilibrated_size(scale: float, sizes1: float, sizes2: float) -> float:
    """The yardstick s·Σ₁ + Σ₂/s of ``equilibrated_norm``: Σ₁, Σ₂ the sums of the norms of the terms of the stress
    and displacement parts."""
    return scale * sizes1 + sizes2 / scale


class SaddlePointFactorization:
    """J for a given active set (None: no penalty), factorized once per set, and solves with it.

    ``n_sigma``: owned AW coefficients (the first block); ``contact``: whether J has a penalty block (ε
    given); ``nodes``: the Γ_C nodes (None without Γ_C facets); ``scale``: s of the equilibration
    D = diag(s I_σ, I_u/s) (``stress_scale`` of the reference modulus; 1: none).
    """

    def __init__(
        self,
        comm: MPI.Comm,
        prefix: str,
        n_sigma: int,
        operators: MixedOperators,
        nodes: ContactNodes | None,
        *,
        contact: bool,
        has_operators: bool,
        scale: float = 1.0,
    ) -> None:
        self.comm, self.prefix, self.n_sigma = comm, prefix, n_sigma
        self.scale = scale
        self.operators, self.nodes = operators, nodes
        self.contact, self.has_operators = contact, has_operators
        self._solver: DirectSolver | None = None
        self._saddle: SaddlePointMatrix | None = None
        self.factorized_set: np.ndarray | None = None  #: the active set of the current factorization
        self._rhs = self._sol = None

    @property
    def solver(self) -> DirectSolver:
        """The direct solver (created at the first factorization: its PETSc options are set then)."""
        if self._solver is None:
            n_u = self.operators.B.mat.getLocalSize()[0]
            self._solver = DirectSolver(
                self.comm,
                prefix=self.prefix,
                options=MIXED_SOLVER_OPTIONS,
                scaling=saddle_point_scaling(self.scale, self.n_sigma, n_u),
            )
        return self._solver

    def factorize_for(self, active: np.ndarray | None, weights: np.ndarray | None = None) -> bool:
        """Factorize the saddle-point Jacobian unless the cached one has the same active set (with friction: the
        key of the friction state, and ``weights`` the 2 × 2 weights per node, ``fem.mixed_friction``)."""
        if not self.has_operators:
            raise InputError("this subproblem was built without its matrices (operators=False): it cannot be solved")
        key = np.zeros(0, dtype=bool) if active is None else active
        if self.factorized_set is not None and np.array_equal(key, self.factorized_set):
            return False
        if self._saddle is None:
            # one sparsity pattern for every active set (all Γ_C nodes): when the active set changes
            # only the penalty values change and MUMPS redoes the numeric factorization, not the analysis
            Q_rows = self.nodes.Q_rows_global if (self.contact and self.nodes is not None) else None
            T_rows = self.nodes.T_rows_global if Q_rows is not None else None
            self._saddle = self._equilibrated_matrix(Q_rows, T_rows)
            self._rhs, self._sol = self._saddle.create_vecs()
        if active is None or not self.contact:
            self._saddle.set_weights(None)
        else:
            weights = self.nodes.penalty_weights(active) if weights is None else weights
            self._saddle.set_weights(weights if self.scale == 1.0 else self.scale**2 * weights)
        self.solver.set_operator(self._saddle.mat)
        self.factorized_set = key.copy()
        return True

    def _equilibrated_matrix(self, Q_rows, T_rows=None) -> SaddlePointMatrix:
        """D J D without penalty weights: [[s² K̃, Bᵀ], [B, 0]] (the weights get s² in ``factorize_for``)."""
        Kt = self.operators.Kt.mat
        if self.scale == 1.0:
            return SaddlePointMatrix(Kt, self.operators.B.mat, Q_rows, T_rows)
        Ks = Kt.duplicate(copy=True)
        Ks.scale(self.scale**2)
        try:
            return SaddlePointMatrix(Ks, self.operators.B.mat, Q_rows, T_rows)
        finally:
            Ks.destroy()

    def solve(self, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(x1, x2) with J [x1; x2] = [r1; r2] (owned entries) by the current factorization."""
        n_sigma = self.n_sigma
        self._rhs.array[:n_sigma] = r1
        self._rhs.array[n_sigma:] = r2
        self.solver.solve(self._rhs, self._sol)
        x = self._sol.array
        return x[:n_sigma].copy(), x[n_sigma:].copy()

    def destroy(self) -> None:
        """Free the PETSc objects (collective)."""
        if self._saddle is not None:
            self._saddle.destroy()
        for obj in (self._rhs, self._sol):
            if obj is not None:
                obj.destroy()
        if self._solver is not None:
            self._solver.destroy()
