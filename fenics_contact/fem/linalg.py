"""The checked factorizations of the package (PETSc and MUMPS; the matrix copies and products: ``fem.matrices``).

Every factorization lives here, on one core (``_Factorization``: a KSP of type preonly whose direct PC holds
the factors of its operator; the factorization and every solve are checked, a failure is a ConvergenceError):

* ``DirectSolver``: a (distributed) operator configured through the PETSc options database under its own
  prefix (the fine subproblems, the interface Newton), refactorized by ``set_operator``; PETSc vector solves and
  solves of dense blocks (``mat_solve``), optionally of an operator given equilibrated (``scaling``); on one
  process, blocks of A⁻¹ from its MUMPS factors (``inverse_block``, ``fem.inverse_entries``).
* ``SparseFactor``: a sequential MUMPS LU or Cholesky (without pivoting for a matrix flagged SPD, else LDLᵀ
  with pivoting) of a matrix it owns, configured in code (the multiscale local problems, thousands of them: no
  options-database entries),
  with MUMPS ICNTL controls per factorization; solves of dense blocks of right-hand sides (one MatMatSolve);
  a SciPy CSR matrix wrapped without a copy (``from_csr``), a symmetric one given by its upper triangle
  (``symmetric``: Cholesky, or LU where it is not positive definite), new values refactorized on the kept
  symbolic analysis (``refactor``; ``ReusedAnalysis`` keeps one per sparsity pattern), the inertia of an LDLᵀ,
  optionally the factors of an equilibrated D A D (``scaling``).
* ``PivotedCholesky``: a dense rank-revealing Cholesky of a small symmetric positive semi-definite matrix
  (LAPACK ``dpstrf``).  It stays outside the PETSc core: MUMPS has no pivoting by size that drops the
  numerically dependent columns, and a dense MUMPS factor would round differently.

**Equilibration.**  A saddle-point matrix whose blocks have different physical units (a compliance ~1/E beside
an O(1) divergence) makes MUMPS' threshold pivoting reject the small diagonal pivots and delay them until its
workspace overflows (E ≥ 1e6 for the mixed systems).  A factorization given a positive diagonal ``scaling`` D
holds the factors of D A D and solves A x = b as x = D (D A D)⁻¹ (D b); with D a power of two per block the
scaled matrix and vectors round nothing.  A failed factorization names its cause (``factorization_failure``: the
PETSc reason, MUMPS' INFOG(1) and INFOG(2)) and what to do.
"""

import logging

import numpy as np
import scipy.linalg
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem import inverse_entries

__all__ = [
    "DirectSolver",
    "PivotedCholesky",
    "ReusedAnalysis",
    "SolveBuffer",
    "SparseFactor",
    "factorization_failure",
    "PC_FAILED_REASONS",
    "spd_factor",
    "SPD_FACTOR_OPTION",
    "SPD_FACTORS",
]

log = logging.getLogger(__name__)

#: |entries| of a matrix a factorization handles safely in double precision (squares stay finite)
SAFE_RANGE = (1e-150, 1e150)

#: Default options of every direct solve (each solver gets its own prefix).
DIRECT_OPTIONS = {"ksp_type": "preonly", "pc_type": "lu", "pc_factor_mat_solver_type": "mumps"}
#: ``DirectSolver(spd=True)``: MUMPS Cholesky without pivoting (its SYM = 1: the operator is flagged SPD), half
#: the factors of an LU: a faster numeric factorization and back-solve (benchmarks/results/snes_vi_baseline.md)
SPD_OPTIONS = {"ksp_type": "preonly", "pc_type": "cholesky", "pc_factor_mat_solver_type": "mumps"}

#: the PETSc option that chooses how ``DirectSolver(spd=True)`` factorizes: ``cholesky`` (the default, ``SPD_OPTIONS``)
#: or ``lu`` (as any operator, ``DIRECT_OPTIONS``), e.g. ``PETSC_OPTIONS="-fc_spd_factor lu"`` or
#: ``PETSc.Options()["fc_spd_factor"] = "lu"`` before the solvers are made: which of the two is faster depends on
#: the size and the machine (docs/performance.md, ``benchmarks/load_path.py --factor both``)
SPD_FACTOR_OPTION = "fc_spd_factor"
SPD_FACTORS = ("cholesky", "lu")

#: PETSc's PC failure reasons by number (``PETSc.PC.FailedReason``)
PC_FAILED_REASONS = {
    v: k for k, v in vars(PETSc.PC.FailedReason).items() if not k.startswith("_") and isinstance(v, int)
}

#: MUMPS error codes INFOG(1) (MUMPS users' guide, section "Error diagnostics"): what they mean, what to do
_MUMPS_ERRORS = {
    -5: "memory allocation failed in the analysis",
    -7: "memory allocation failed in the analysis",
    -6: "the matrix is structurally singular (INFOG(2): its structural rank)",
    -8: "MUMPS' integer workspace is too small",
    -9: "MUMPS' real workspace is too small",
    -10: "the matrix is numerically singular",
    -11: "MUMPS' real workspace is too small for the solve",
    -12: "MUMPS' real workspace is too small",
    -13: "a memory allocation of INFOG(2) entries failed",
    -14: "MUMPS' integer workspace is too small for the solve",
    -15: "MUMPS' integer workspace is too small",
    -17: "MUMPS' send buffer is too small",
    -19: "the memory limit ICNTL(23) is too small",
    -20: "MUMPS' reception buffer is too small",
}
_WORKSPACE = (-8, -9, -11, -12, -14, -15, -17, -20)


def factorization_failure(pc: PETSc.PC, prefix: str | None = None) -> str:
    """Why the factorization of ``pc`` failed and what to do: the PETSc reason by name and, for MUMPS, INFOG(1)
    and INFOG(2) with their meaning.  ``prefix``: the solver's options prefix (named in the advice)."""
    reason = pc.getFailedReason()
    text = f"PETSc PC failed reason {PC_FAILED_REASONS.get(reason, 'UNKNOWN')} ({reason})"
    infog1 = infog2 = None
    try:
        if pc.getFactorSolverType() == "mumps":
            F = pc.getFactorMatrix()
            infog1, infog2 = F.getMumpsInfog(1), F.getMumpsInfog(2)
    except PETSc.Error:  # no factor matrix (the set-up failed before MUMPS ran)
        pass
    option = f"-{prefix or ''}mat_mumps_icntl_14"
    if infog1 is not None:
        text += f"; MUMPS INFOG(1) = {infog1}, INFOG(2) = {infog2}"
        meaning = _MUMPS_ERRORS.get(infog1)
        if meaning:
            text += f": {meaning}"
    if infog1 in _WORKSPACE or (infog1 is None and reason == PETSc.PC.FailedReason.FACTOR_OUTMEMORY):
        return (
            f"{text}. Delayed pivots overflowed the workspace MUMPS estimated: the matrix is badly scaled (blocks "
            f"in very different units, e.g. Young's modulus or lengths far from 1, where it is not equilibrated) "
            f"or has tiny pivots. Rescale the data, or raise the workspace (PETSC_OPTIONS='{option} 200': "
            "200 % more than estimated)"
        )
    if infog1 in (-5, -7, -13) or infog1 == -19:
        return f"{text}. Out of memory: a coarser mesh, more memory, or more MPI ranks"
    if infog1 in (-6, -10) or reason in (
        PETSc.PC.FailedReason.FACTOR_STRUCT_ZEROPIVOT,
        PETSc.PC.FailedReason.FACTOR_NUMERIC_ZEROPIVOT,
    ):
        return (
            f"{text}. A singular matrix: a part of the body free to move rigidly (no Γ_D, no contact or "
            "Robin data holding it), a zero Young's modulus, or a penalty or Robin coefficient far out of range"
        )
    return f"{text}. Check the data (moduli, penalty and Robin coefficients) for values far out of range"


def spd_factor() -> str:
    """How ``DirectSolver(spd=True)`` factorizes: the PETSc option ``SPD_FACTOR_OPTION`` (``"cholesky"`` unless it is
    set); InputError for another value."""
    value = PETSc.Options().getString(SPD_FACTOR_OPTION, SPD_FACTORS[0]).strip().lower()
    if value not in SPD_FACTORS:
        raise InputError(f"-{SPD_FACTOR_OPTION} must be one of {', '.join(SPD_FACTORS)}, got {value!r}")
    return value


def check_entries(A: PETSc.Mat, prefix: str) -> None:
    """InputError when A has non-finite entries (overflowing data, e.g. E = 1e308) or its largest entry is
    outside the range a double-precision solve handles (``SAFE_RANGE``: squares and residual norms must stay
    finite).  Collective.

    The Frobenius norm F settles the common case without copying the entries: a finite F with
    ``SAFE_RANGE[0]``·√(m n) ≤ F ≤ ``SAFE_RANGE[1]`` (m × n the size) bounds the largest entry |a| by
    F/√(m n) ≤ |a| ≤ F, inside the range, and no entry is NaN or infinite (they make F so).  Otherwise the
    entries are read to say which bound fails."""
    m, n = A.getSize()
    norm = A.norm(PETSc.NormType.FROBENIUS)
    if np.isfinite(norm) and SAFE_RANGE[0] * np.sqrt(float(m) * float(n)) <= norm <= SAFE_RANGE[1]:
        return
    _, _, values = A.getValuesCSR()
    comm = A.getComm().tompi4py()
    finite = comm.allreduce(bool(np.all(np.isfinite(values))), op=MPI.LAND)
    largest = comm.allreduce(float(np.max(np.abs(values), initial=0.0)), op=MPI.MAX)
    what = None if finite else "non-finite values"
    if finite and not SAFE_RANGE[0] <= largest <= SAFE_RANGE[1]:
        what = f"entries up to {largest:.3g}"
    if what is not None:
        raise InputError(
            f"{prefix}: the matrix has {what}: the data overflow the range of a double-precision "
            f"factorization (about {SAFE_RANGE[0]:g} to {SAFE_RANGE[1]:g}): Young's modulus, 1/δ, α or 1/ε too "
            "large or too small. Rescale the units (the displacement scales as load/E)."
        )


class _Factorization:
    """The shared core: ``ksp`` (type preonly) whose direct PC holds the factors of its operator."""

    ksp: PETSc.KSP

    def _set_up(self) -> int:
        """Factorize the operator (KSP set-up); the PETSc PC failure reason, 0 on success."""
        self.ksp.setUp()
        return self.ksp.getPC().getFailedReason()

    def _solve_reason(self) -> int:
        """The KSP reason of the last solve (negative: failed; PETSc leaves the check to the caller)."""
        return self.ksp.getConvergedReason()

    def destroy(self) -> None:
        self.ksp.destroy()


class DirectSolver(_Factorization):
    """A factorized operator (MUMPS LU by default) whose every solve is checked.

    ``scaling``: the owned entries of a positive diagonal D when the operators are given equilibrated, D A D:
    ``solve`` and ``mat_solve`` then return the solutions of A x = b, x = D (D A D)⁻¹ (D b).  ``spd``: the
    operators are symmetric positive definite (the caller's guarantee): each is flagged so and factorized by
    MUMPS' Cholesky without pivoting (``SPD_OPTIONS``, unless ``options`` are given); should that fail (a
    matrix positive definite in exact arithmetic only), by its LU from then on.  The PETSc option
    ``-fc_spd_factor lu`` (``spd_factor``) makes ``spd`` operators factorize by LU like any other.
    """

    def __init__(
        self,
        comm,
        *,
        prefix: str,
        options: dict | None = None,
        scaling: np.ndarray | None = None,
        spd: bool = False,
    ) -> None:
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(prefix)
        self.spd = spd = spd and spd_factor() == "cholesky"
        opts = PETSc.Options()
        for key, value in (options or (SPD_OPTIONS if spd else DIRECT_OPTIONS)).items():
            opts[f"{prefix}{key}"] = value
        self.ksp.setFromOptions()
        self.prefix = prefix
        self.factorizations = 0
        self.scaling = None if scaling is None else np.asarray(scaling, dtype=PETSc.ScalarType)
        self._d: PETSc.Vec | None = None  # D as a PETSc vector (made with the first operator)
        self._work: PETSc.Vec | None = None

    def set_operator(self, A: PETSc.Mat) -> None:
        """Use A from now on and factorize it (with ``scaling``: A is the equilibrated D A D).

        Raises InputError when A has non-finite entries (overflowing data, e.g. E = 1e308) or its
        largest entry is outside the range a double-precision factorization handles (``SAFE_RANGE``:
        squares and residual norms must stay finite); ConvergenceError when the factorization fails
        (``factorization_failure``: the cause and what to do).
        """
        check_entries(A, self.prefix)
        if self.spd:
            A.setOption(PETSc.Mat.Option.SPD, True)
        if self.scaling is not None and self._d is None:
            self._d = A.createVecLeft()
            self._d.array[:] = self.scaling
            self._work = self._d.duplicate()
        self.ksp.setOperators(A)
        failed = self._set_up() != 0
        if failed and self.spd:  # not positive definite in floating point (a contrast beyond double precision)
            log.debug("%s: Cholesky failed, LU from now on", self.prefix)
            self.spd = False
            A.setOption(PETSc.Mat.Option.SPD, False)
            self.ksp.getPC().setType("lu")
            self.ksp.getPC().setFactorSolverType("mumps")
            self.ksp.setOperators(A)
            failed = self._set_up() != 0
        if failed:
            cause = factorization_failure(self.ksp.getPC(), self.prefix)
            raise ConvergenceError(f"{self.prefix}: factorization failed ({cause})")
        self.factorizations += 1

    def solve(self, b: PETSc.Vec, x: PETSc.Vec) -> None:
        """x = A⁻¹ b, raising ConvergenceError on any PETSc failure (b is left as it is)."""
        if self._d is None:
            self.ksp.solve(b, x)
        else:
            self._work.pointwiseMult(b, self._d)
            self.ksp.solve(self._work, x)
            x.pointwiseMult(x, self._d)
        reason = self._solve_reason()
        if reason < 0:
            raise ConvergenceError(f"{self.prefix}: linear solve failed, KSP reason {reason}")

    def sequential_mumps(self) -> bool:
        """Whether the factors held are a sequential MUMPS factorization (``solve_sparse`` works here)."""
        pc = self.ksp.getPC()
        return (
            self.ksp.getComm().getSize() == 1
            and self.factorizations > 0
            and pc.getType() in ("lu", "cholesky")
            and pc.getFactorSolverType() == "mumps"
        )

    def has_inverse_entries(self) -> bool:
        """Whether ``inverse_block`` works here: a sequential MUMPS factorization (``fem.inverse_entries``)."""
        return inverse_entries.available() and self.sequential_mumps()

    def solve_sparse(self, rows: np.ndarray, values: np.ndarray) -> np.ndarray:
        """A⁻¹ b for the b that vanishes but at ``rows`` (distinct), where it holds ``values``: MUMPS' sparse
        right-hand side (ICNTL(20)) skips the forward elimination where b vanishes (``sequential_mumps`` only);
        ConvergenceError on a failure or non-finite values.  With ``scaling`` the solution of A x = b as ``solve``."""
        rows = np.asarray(rows, dtype=np.int64)
        values = np.asarray(values, dtype=PETSc.ScalarType)
        if self.scaling is not None:
            values = values * self.scaling[rows]
        order = np.argsort(rows)
        n = self.ksp.getOperators()[0].getSize()[0]
        rhs_t = sp.csr_matrix((values[order], rows[order], np.array([0, rows.size])), shape=(1, n))
        x = _sparse_solve(self.ksp.getPC().getFactorMatrix(), rhs_t, self.prefix)[:, 0]
        return x if self.scaling is None else self.scaling * x

    def inverse_block(self, rows: np.ndarray, *, sweep: np.ndarray | None = None) -> np.ndarray:
        """(A⁻¹)[rows][:, rows] (dense, in the order of ``rows``) from the factors held: MUMPS' entries of the
        inverse, the values of back-solves without them (``fem.inverse_entries``; ``has_inverse_entries``).  With
        ``scaling`` the factors are those of D A D and A⁻¹ = D (D A D)⁻¹ D (exact for powers of two).  ``sweep``
        (A symmetric): one triangle computed, the other by symmetry (``inverse_entries.inverse_block``)."""
        factor = self.ksp.getPC().getFactorMatrix()
        block = inverse_entries.inverse_block(factor, rows, what=self.prefix, sweep=sweep)
        if self.scaling is None:
            return block
        d = self.scaling[np.asarray(rows, dtype=np.int64)]
        return d[:, None] * block * d[None, :]

    def mat_solve(self, B: PETSc.Mat, X: PETSc.Mat) -> None:
        """X = A⁻¹ B for a dense block B (one multi-right-hand-side solve; with ``scaling`` B is overwritten)."""
        if self._d is not None:
            B.diagonalScale(L=self._d)
        self.ksp.matSolve(B, X)
        if self._d is not None:
            X.diagonalScale(L=self._d)
        reason = self._solve_reason()
        if reason < 0:
            raise ConvergenceError(f"{self.prefix}: multi-right-hand-side solve failed, KSP reason {reason}")

    def destroy(self) -> None:
        for obj in (self._d, self._work):
            if obj is not None:
                obj.destroy()
        self.ksp.destroy()


def _petsc_csr(A: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A's CSR arrays in PETSc's integer and scalar types (the same arrays where they already are: a matrix made
    on them shares them, so the caller keeps them alive)."""
    return (
        A.indptr.astype(PETSc.IntType, copy=False),
        A.indices.astype(PETSc.IntType, copy=False),
        A.data.astype(PETSc.ScalarType, copy=False),
    )


class SparseFactor(_Factorization):
    """MUMPS LU or Cholesky of a sequential sparse matrix it owns; solves of dense blocks of right-hand sides.

    Subclasses name their matrices (``what``, in the messages) and choose the ICNTL controls of their LU
    factorizations (``lu_icntl``, e.g. the ordering ICNTL(7)), also for the LU that ``symmetric`` falls
    back to.
    """

    #: the matrices, in messages
    what: str = "a sparse matrix"
    #: MUMPS ICNTL controls (index, value) of an LU when the constructor gets none
    lu_icntl: tuple[tuple[int, int], ...] = ()

    def __init__(
        self,
        mat: PETSc.Mat,
        *,
        cholesky: bool = False,
        icntl: dict[int, int] | None = None,
        trial: bool = False,
        what: str | None = None,
        scaling: np.ndarray | None = None,
    ) -> None:
        """Factorize ``mat`` (destroyed with this factor): LU, or with ``cholesky`` MUMPS' Cholesky (no pivoting
        when ``mat`` is flagged SPD, else LDLᵀ with pivoting); ``icntl`` MUMPS controls (default: ``lu_icntl``
        for an LU, none for Cholesky).  A failed factorization raises ConvergenceError, unless ``trial``
        (a Cholesky of a matrix flagged SPD): then a failure or a non-positive pivot only sets ``positive``
        False (the caller factorizes otherwise, as ``symmetric`` does).  ``what`` overrides the class's name of
        the matrix in messages.  ``scaling``: the diagonal D when ``mat`` is given equilibrated, D A D (``from_csr``
        scales): ``solve`` then returns A⁻¹ rhs = D (D A D)⁻¹ (D rhs)."""
        if what is not None:
            self.what = what
        self.mat = mat
        self.scaling = None if scaling is None else np.asarray(scaling, dtype=PETSc.ScalarType)
        self.trial = trial
        self._arrays = None  # the CSR arrays a matrix made by from_csr shares
        self.ksp = PETSc.KSP().create(PETSc.COMM_SELF)
        self.ksp.setOperators(self.mat)
        self.ksp.setType("preonly")
        pc = self.ksp.getPC()
        pc.setType("cholesky" if cholesky else "lu")
        pc.setFactorSolverType("mumps")
        pc.setFactorSetUpSolverType()
        controls = icntl if icntl is not None else ({} if cholesky else dict(self.lu_icntl))
        for key, value in controls.items():
            pc.getFactorMatrix().setMumpsIcntl(key, value)
        if not self._factorize() and not trial:
            cause = factorization_failure(pc)
            self.destroy()
            raise ConvergenceError(f"MUMPS failed to factorize {self.what} ({cause})")

    @classmethod
    def from_csr(cls, A: sp.csr_matrix, *, scaling: np.ndarray | None = None, **kwargs) -> "SparseFactor":
        """Factorize a square SciPy CSR matrix (put into canonical form: sorted indices, no duplicates, no
        explicit zeros); the PETSc matrix shares its arrays (no copy).  ``scaling``: a positive diagonal D (one
        entry per row): the factors are those of D A D, the solves those of A."""
        A = sp.csr_matrix(A)
        A.sum_duplicates()
        A.eliminate_zeros()
        if scaling is not None:
            A = _equilibrated(A, scaling)
        csr = _petsc_csr(A)
        mat = PETSc.Mat().createAIJWithArrays(A.shape, csr, comm=PETSc.COMM_SELF)  # no copy: keep csr alive
        mat.assemble()
        lu = cls(mat, scaling=scaling, **kwargs)
        lu._arrays = csr
        return lu

    @classmethod
    def from_coo(cls, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n: int, **kwargs) -> "SparseFactor":
        """Factorize the n × n matrix of COO triplets (duplicates summed; SciPy's conversion was 2–4× faster
        than PETSc's COO assembly on the multiscale patch systems)."""
        return cls.from_csr(sp.csr_matrix((vals, (rows, cols)), shape=(n, n)), **kwargs)  # canonical: sorted, summed

    @classmethod
    def symmetric(cls, upper: sp.csr_matrix) -> "SparseFactor":
        """Factorize the symmetric matrix whose upper triangle (canonical CSR) is ``upper``: MUMPS Cholesky
        (positive definite, no pivoting; 1.5× faster than LU on the mixed CEM skeleton systems), or, when a
        pivot is not positive (a matrix that is not positive definite after all), the LU of the full matrix."""
        csr = _petsc_csr(upper)
        # an AIJ matrix holding the upper triangle only, on the CSR arrays (no copy): PETSc hands MUMPS' Cholesky
        # the entries from the diagonal on of every row (MatConvertToTriples_seqaij_seqsbaij), i.e. exactly
        # these (an SBAIJ matrix would be built by copying row by row: 20 ms of 0.17 s at h = 1/128)
        mat = PETSc.Mat().createAIJWithArrays(upper.shape, csr, comm=PETSc.COMM_SELF)
        mat.setOption(PETSc.Mat.Option.SPD, True)
        mat.assemble()
        chol = cls(mat, cholesky=True, trial=True)
        chol._arrays = csr
        if chol.positive:
            return chol
        chol.destroy()
        log.debug("%s: not positive definite, LU instead of Cholesky", cls.what)
        return cls.from_csr(upper + sp.triu(upper, 1).T)

    def _factorize(self) -> bool:
        """Set up the factorization of ``mat`` (MUMPS keeps its analysis for a matrix of the same pattern);
        sets ``positive`` (Cholesky without failure and without a non-positive pivot) and returns whether it
        succeeded (for a ``trial`` Cholesky: ``positive``)."""
        failed = self._set_up() != 0 or self.ksp.getConvergedReason() < 0
        pc = self.ksp.getPC()
        cholesky = pc.getType() == "cholesky"
        self.positive = cholesky and not failed and pc.getFactorMatrix().getMumpsInfog(12) == 0
        return self.positive if self.trial else not failed

    def refactor(self, data: np.ndarray) -> bool:
        """New values ``data`` on the pattern this factorization was made for (a matrix from ``from_csr`` or
        ``symmetric``): the numeric factorization only, on MUMPS' kept ordering and symbolic analysis.  Returns
        whether it succeeded (for a Cholesky factorization: with positive pivots only)."""
        if self.scaling is not None:
            indptr, indices = self._arrays[0], self._arrays[1]
            data = data * np.repeat(self.scaling, np.diff(indptr)) * self.scaling[indices]
        self._arrays[2][:] = data
        self.mat.assemble()
        self.ksp.setOperators(self.mat)
        return self._factorize()

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A⁻¹ rhs for all columns at once (one MatMatSolve); ConvergenceError on a failure or non-finite values."""
        n, k = rhs.shape
        if self.scaling is not None:
            rhs = self.scaling[:, None] * rhs
        data = np.asfortranarray(rhs, dtype=PETSc.ScalarType)  # PETSc dense storage is column-major
        B = PETSc.Mat().createDense((n, k), array=data, comm=PETSc.COMM_SELF)
        X = PETSc.Mat().createDense((n, k), comm=PETSc.COMM_SELF)
        X.setUp()
        try:
            self.ksp.matSolve(B, X)
            reason = self._solve_reason()
            if reason < 0:
                raise ConvergenceError(f"MUMPS failed on {self.what} (reason {reason})")
            out = X.getDenseArray().copy()
        finally:
            B.destroy()
            X.destroy()
        if not np.all(np.isfinite(out)):
            raise ConvergenceError(f"a solve of {self.what} produced non-finite values")
        return out if self.scaling is None else self.scaling[:, None] * out

    def solve_sparse(self, rhs_t: sp.csr_matrix, *, out: np.ndarray | None = None) -> np.ndarray:
        """A⁻¹ B for sparse right-hand sides B given by their transpose ``rhs_t`` (one row per right-hand side,
        canonical CSR): MUMPS' sparse right-hand sides (ICNTL(20), which PETSc selects for the transpose of an AIJ
        matrix) skip the forward elimination where they vanish; a dense (n × k) column-major result;
        ConvergenceError on a failure or non-finite values.  ``out``: a contiguous float64 buffer of at least n k
        entries that MUMPS writes the solution into (``SolveBuffer``), the result a view of it (valid until the
        buffer is used again; no ``scaling`` then)."""
        if self.scaling is not None:
            if out is not None:
                raise ValueError("solve_sparse: an output buffer with an equilibrated factorization")
            rhs_t = (rhs_t @ sp.diags(self.scaling)).tocsr()  # (D B, by its transpose's columns)
        result = _sparse_solve(self.ksp.getPC().getFactorMatrix(), rhs_t, self.what, out=out)
        return result if self.scaling is None else self.scaling[:, None] * result

    def inertia(self) -> tuple[int, int, int]:
        """(negative, zero, positive) pivots of a Cholesky (LDLᵀ) factorization made with null-pivot detection
        (``icntl={24: 1}``): by Sylvester's law of inertia, the signs of the eigenvalues of the matrix."""
        nneg, nzero, npos = self.ksp.getPC().getFactorMatrix().getInertia()
        return int(nneg), int(nzero), int(npos)

    @property
    def nbytes(self) -> int:
        """Memory held: the factors (MUMPS' INFOG(9) reals, ×10⁶ when negative, at 12 bytes per entry: value and
        index) and the CSR arrays shared with the matrix."""
        entries = self.ksp.getPC().getFactorMatrix().getMumpsInfog(9)
        entries = -entries * 10**6 if entries < 0 else entries
        return int(12 * entries + sum(a.nbytes for a in (self._arrays or ())))

    def destroy(self) -> None:
        for obj in (self.ksp, self.mat):
            obj.destroy()
        self._arrays = None


class SolveBuffer:
    """One output buffer for a sequence of ``SparseFactor.solve_sparse`` calls (``out``): MUMPS writes each solution
    into pages already touched, where a fresh dense matrix per solve costs its zero fill and a page fault per 4 KiB
    (the solutions of the CEM patch problems run to 10⁸ bytes).  It grows to the largest request."""

    def __init__(self) -> None:
        self.array = np.empty(0, dtype=PETSc.ScalarType)

    def get(self, size: int) -> np.ndarray:
        """The buffer, at least ``size`` entries (its contents undefined)."""
        if self.array.size < size:
            self.array = np.empty(0, dtype=PETSc.ScalarType)  # (the old one freed before the new one is made)
            self.array = np.empty(size, dtype=PETSc.ScalarType)
        return self.array

    def release(self) -> None:
        """Free the buffer (a later ``get`` makes a new one)."""
        self.array = np.empty(0, dtype=PETSc.ScalarType)


def _sparse_solve(factor: PETSc.Mat, rhs_t: sp.csr_matrix, what: str, *, out: np.ndarray | None = None) -> np.ndarray:
    """A⁻¹ B with the sequential MUMPS factor ``factor`` of A for sparse right-hand sides B given by their transpose
    ``rhs_t`` (one row per right-hand side, canonical CSR; PETSc hands MUMPS the transpose of an AIJ matrix as sparse
    right-hand sides, ICNTL(20)): a dense (n × k) column-major result (in the buffer ``out`` when given: MUMPS
    writes the solution into the dense matrix's array); ConvergenceError on a failure or non-finite values (``what``
    names A)."""
    k, n = rhs_t.shape
    csr = _petsc_csr(rhs_t)
    Bt = PETSc.Mat().createAIJWithArrays((k, n), csr, comm=PETSc.COMM_SELF)
    Bt.assemble()
    B = PETSc.Mat().createTranspose(Bt)
    if out is None:
        X = PETSc.Mat().createDense((n, k), comm=PETSc.COMM_SELF)
        X.setUp()
    else:
        if out.dtype != PETSc.ScalarType or not out.flags.c_contiguous or out.size < n * k:
            raise ValueError(f"solve_sparse: the output buffer needs {n * k} contiguous {PETSc.ScalarType} entries")
        view = out.reshape(-1)[: n * k]
        X = PETSc.Mat().createDense((n, k), array=view, comm=PETSc.COMM_SELF)
    try:
        try:
            factor.matSolve(B, X)
        except PETSc.Error as err:
            raise ConvergenceError(f"MUMPS failed on {what} ({err})") from None
        result = X.getDenseArray().copy(order="F") if out is None else view.reshape((n, k), order="F")
    finally:
        for obj in (B, Bt, X):
            obj.destroy()
    if not np.all(np.isfinite(result)):
        raise ConvergenceError(f"a solve of {what} produced non-finite values")
    return result


def _equilibrated(A: sp.csr_matrix, d: np.ndarray) -> sp.csr_matrix:
    """D A D for a canonical CSR matrix A and the diagonal d (same pattern)."""
    d = np.asarray(d, dtype=np.float64)
    out = A.copy()
    out.data = A.data * np.repeat(d, np.diff(A.indptr)) * d[A.indices]
    return out


class ReusedAnalysis:
    """Cholesky factorizations (``SparseFactor.symmetric`` of ``factor_class``) kept for the last ``keep``
    sparsity patterns: a matrix with one of their patterns is factorized numerically on the kept ordering and
    symbolic analysis (``SparseFactor.refactor``).  Worth it when matrices of one pattern come one after
    the other."""

    def __init__(self, keep: int = 2, factor_class: type[SparseFactor] = SparseFactor) -> None:
        self.keep = keep
        self.factor_class = factor_class
        self.entries: list[tuple[np.ndarray, np.ndarray, SparseFactor]] = []  # most recent first

    def factor(self, upper: sp.csr_matrix) -> tuple[SparseFactor, bool]:
        """(factorization of the symmetric matrix with upper triangle ``upper``, whether the caller destroys it).

        A kept factorization takes over ``upper``'s arrays (its later values are written into them): the
        caller must not use ``upper`` afterwards."""
        for k, (indptr, indices, lu) in enumerate(self.entries):
            if np.array_equal(indptr, upper.indptr) and np.array_equal(indices, upper.indices):
                self.entries.pop(k)
                if lu.refactor(upper.data):
                    self.entries.insert(0, (indptr, indices, lu))
                    return lu, False
                lu.destroy()  # a pivot that is not positive: factorize afresh (LU) below
                break
        lu = self.factor_class.symmetric(upper)
        if not lu.positive:
            return lu, True
        self.entries.insert(0, (upper.indptr, upper.indices, lu))
        while len(self.entries) > self.keep:
            self.entries.pop()[2].destroy()
        return lu, False

    def release(self) -> None:
        for *_, lu in self.entries:
            lu.destroy()
        self.entries = []


class PivotedCholesky:
    """Pivoted Cholesky of a dense SPSD matrix, Jacobi-scaled; columns that are numerically dependent are dropped.

    Solves A x = b for consistent b; x is zero on the dropped (pivot < tolerance) coordinates.
    ``what`` names the matrix in messages.
    """

    def __init__(self, A: np.ndarray, *, what: str = "the matrix") -> None:
        self.what = what
        A = 0.5 * (A + A.T)
        d = np.diag(A).copy()
        if np.any(d <= 0):
            raise ConvergenceError(f"{what} has a non-positive diagonal entry (empty basis function?)")
        self.scale = 1.0 / np.sqrt(d)
        As = A * self.scale[:, None] * self.scale[None, :]
        c, piv, rank, info = scipy.linalg.lapack.dpstrf(As, lower=1)
        if info < 0:
            raise ConvergenceError(f"pivoted Cholesky failed (LAPACK info {info})")
        self.n = A.shape[0]
        self.rank = int(rank)
        self.keep = piv[: self.rank] - 1
        self.L = np.asfortranarray(np.tril(c[: self.rank, : self.rank]))
        if self.rank < self.n:
            log.info("%s: rank %d of %d, dependent basis functions dropped", what, self.rank, self.n)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """x with A x = b (b a vector or columns), zero on the dropped coordinates."""
        bs = (b * self.scale[:, None]) if b.ndim == 2 else b * self.scale
        z, info = scipy.linalg.lapack.dpotrs(self.L, bs[self.keep], lower=1)
        if info != 0:
            raise ConvergenceError(f"solve with {self.what} failed (LAPACK dpotrs info {info})")
        x = np.zeros_like(bs)
        x[self.keep] = z
        return (x * self.scale[:, None]) if b.ndim == 2 else x * self.scale
