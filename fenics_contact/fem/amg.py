"""CG (or GMRES) preconditioned by smoothed-aggregation AMG: the iterative linear solver of the primal Newton.

``AMGSolver`` stands beside ``fem.linalg.DirectSolver``, with its interface (``set_operator``, ``solve``):
conjugate gradients (GMRES for a Jacobian that is not symmetric) preconditioned by PETSc's smoothed-aggregation
algebraic multigrid (GAMG) with the rigid-body modes as its near-nullspace (``AMG_OPTIONS``; for heterogeneous
moduli plain aggregation with SSOR smoothing, ``HETEROGENEOUS_OPTIONS``); a Newton step's solve stopped relative to
the new iterate's right-hand side (``AMGSolver.newton_tolerance``); every solve checked (the KSP reason, a
failure a ConvergenceError saying what to do), its iterations recorded.  ``LinearSolverOptions`` chooses
between the two (``"direct"``, ``"amg"``, ``"auto"``: AMG for a 3D operator of ``auto_dofs`` unknowns or
more), ``linear_solver`` builds the one chosen.
"""

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.linalg import PC_FAILED_REASONS, DirectSolver, check_entries
from fenics_contact.fem.matrices import petsc_to_scipy

__all__ = [
    "AUTO_AMG_DOFS",
    "HETEROGENEOUS_OPTIONS",
    "LINEAR_SOLVERS",
    "AMGSolver",
    "LinearSolverOptions",
    "amg_coarse_space",
    "linear_solver",
    "rigid_body_modes",
]

log = logging.getLogger(__name__)

#: the linear solvers of a Newton step: MUMPS LU, CG or GMRES + smoothed-aggregation AMG, or chosen by size
LINEAR_SOLVERS = ("direct", "amg", "auto")
#: unknowns from which ``"auto"`` takes AMG on a 3D mesh: on the well-shaped cells of ``benchmarks/solvers_3d.py``
#: the two cross between 14,000 and 27,000 unknowns and AMG is 1.3× (46,263) to 6× (159,030) faster with 2–3.6×
#: less memory; in 2D the LU's fill grows like n log n only (``"auto"``: direct)
AUTO_AMG_DOFS = 40_000
#: the AMG drop tolerance (``pc_gamg_threshold``) for heterogeneous moduli, and the contrast from which it applies
HETEROGENEOUS_THRESHOLD, HETEROGENEOUS_CONTRAST = 0.02, 10.0
_KRYLOV = ("cg", "gmres")


@dataclass(frozen=True, slots=True)
class LinearSolverOptions:
    """Which linear solver a Newton step uses, and the Krylov solver's tolerance and iteration cap.

    ``kind``: ``"direct"`` (MUMPS LU, ``DirectSolver``), ``"amg"`` (``AMGSolver``: ``krylov`` = ``"cg"`` for a
    symmetric positive definite Jacobian such as the frictionless penalty's, ``"gmres"`` otherwise,
    preconditioned by smoothed-aggregation AMG) or ``"auto"`` (AMG on a 3D mesh of ``auto_dofs`` unknowns or
    more, else direct).  A Krylov solve stops at ‖b − A x‖₂ ≤ ``rtol``·‖b‖₂ (a Newton step's at
    ``rtol``·min(‖b‖₂, ‖A u + b‖₂): ``AMGSolver.newton_tolerance``).  ``threshold``: the AMG's drop tolerance of weak
    connections when it aggregates (PETSc's ``pc_gamg_threshold``); None: ``HETEROGENEOUS_THRESHOLD`` where the shear
    modulus μ varies by more than ``HETEROGENEOUS_CONTRAST`` over the mesh, else 0 (test model 1 in 2D, h = 1/32,
    contrast 1e3, rtol 1e-10, smoothed aggregation: 158–192 CG iterations per step at 0, 40–48 at 0.02; the
    homogeneous Hertz block at a/20: 0.02 doubles them).
    """

    kind: str = "auto"
    krylov: str = "cg"
    rtol: float = 1e-8
    max_iterations: int = 1000
    auto_dofs: int = AUTO_AMG_DOFS
    threshold: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in LINEAR_SOLVERS:
            raise InputError(f"the linear solver must be one of {', '.join(LINEAR_SOLVERS)}, got {self.kind!r}")
        if self.krylov not in _KRYLOV:
            raise InputError(f"the Krylov method must be one of {', '.join(_KRYLOV)}, got {self.krylov!r}")
        if not (isinstance(self.rtol, (int, float)) and 0 < self.rtol < 1):
            raise InputError(f"the Krylov rtol must be a number in (0, 1), got {self.rtol!r}")
        if self.threshold is not None and not (isinstance(self.threshold, (int, float)) and 0 <= self.threshold < 1):
            raise InputError(f"the AMG threshold must be a number in [0, 1) or None, got {self.threshold!r}")
        for name in ("max_iterations", "auto_dofs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise InputError(f"the linear solver's {name} must be an integer >= 1, got {value!r}")

    @classmethod
    def of(cls, value: "LinearSolverOptions | str") -> "LinearSolverOptions":
        """The options themselves, or the defaults with ``kind`` = ``value`` (``"direct"``, ``"amg"``, ``"auto"``)."""
        if isinstance(value, cls):
            return value
        if isinstance(value, str):
            return cls(kind=value)
        raise InputError(
            f"solver must be one of {', '.join(LINEAR_SOLVERS)} or LinearSolverOptions, got {type(value).__name__}"
        )

    def chosen(self, dofs: int, tdim: int) -> str:
        """``"direct"`` or ``"amg"`` for an operator of ``dofs`` unknowns on a mesh of dimension ``tdim``."""
        if self.kind != "auto":
            return self.kind
        return "amg" if tdim == 3 and dofs >= self.auto_dofs else "direct"


def rigid_body_modes(V: fem.FunctionSpace) -> list[PETSc.Vec]:
    """The rigid motions on V (vector P1/Pk): gdim translations and the rotations x ↦ e_k × x (1 in 2D, 3 in
    3D), as owned PETSc vectors in V's layout, orthonormalized (the near-nullspace of elasticity for AMG)."""
    gdim = V.mesh.geometry.dim
    bs = V.dofmap.index_map_bs
    if bs != gdim:
        raise InputError(f"rigid_body_modes needs a vector space with {gdim} components, got block size {bs}")
    n = V.dofmap.index_map.size_local
    x = V.tabulate_dof_coordinates()[:n, :gdim]
    x = x - V.mesh.comm.allreduce(x.sum(axis=0), op=MPI.SUM) / max(V.mesh.comm.allreduce(n, op=MPI.SUM), 1)
    modes = []
    for k in range(gdim):  # translations
        m = np.zeros((n, gdim))
        m[:, k] = 1.0
        modes.append(m)
    rotations = [(0, 1)] if gdim == 2 else [(0, 1), (1, 2), (2, 0)]
    for i, j in rotations:  # the rotation in the (i, j) plane: u_i = −x_j, u_j = x_i
        m = np.zeros((n, gdim))
        m[:, i], m[:, j] = -x[:, j], x[:, i]
        modes.append(m)
    vecs = []
    for m in modes:  # Gram–Schmidt, twice (collective dot products)
        v = PETSc.Vec().createWithArray(m.ravel().copy(), size=(n * bs, PETSc.DECIDE), bsize=bs, comm=V.mesh.comm)
        for _ in range(2):
            for w in vecs:
                v.axpy(-v.dot(w), w)
        v.scale(1.0 / v.norm())
        vecs.append(v)
    return vecs


def identity_rows(A: PETSc.Mat) -> np.ndarray:
    """The owned rows of A (local indices) that are rows of the identity: a unit diagonal and no other nonzero
    (the Dirichlet rows of an assembled operator, whose solution is the right-hand side)."""
    indptr, indices, values = A.getValuesCSR()
    n = indptr.size - 1
    rows = np.repeat(np.arange(n), np.diff(indptr))
    on_diagonal = indices == rows + A.getOwnershipRange()[0]
    off = np.bincount(rows[~on_diagonal], np.abs(values[~on_diagonal]), minlength=n)
    diagonal = np.zeros(n)
    diagonal[rows[on_diagonal]] = values[on_diagonal]
    return np.flatnonzero((off == 0.0) & (diagonal == 1.0))


#: the options of ``AMGSolver`` (each solver under its own prefix): smoothed aggregation (GAMG, one smoothing
#: step of the prolongator), Chebyshev–Jacobi smoothing, the interpolation kept when the operator changes
#: values on its pattern (a Newton step moving the active set: only the coarse operators are recomputed)
AMG_OPTIONS = {
    "ksp_norm_type": "unpreconditioned",
    "pc_type": "gamg",
    "pc_gamg_type": "agg",
    "pc_gamg_agg_nsmooths": 1,
    "pc_gamg_reuse_interpolation": True,
    "mg_levels_ksp_type": "chebyshev",
    "mg_levels_pc_type": "jacobi",
    "mg_levels_ksp_chebyshev_esteig_steps": 20,
}

#: what replaces ``AMG_OPTIONS`` for an operator whose moduli vary by more than ``HETEROGENEOUS_CONTRAST``: plain
#: (unsmoothed) aggregation, and symmetric Gauss–Seidel (SSOR) sweeps as the smoother, which need no estimate of the
#: largest eigenvalue.  Chebyshev's bound, taken from 10 Krylov steps on a spectrum spread by the contrast and the
#: penalty rows, can fall below the largest eigenvalue and make the preconditioner indefinite (the 3D channel cube,
#: contrast 10⁶, h = 1/8: CG stopped with DIVERGED_INDEFINITE_PC).  At h = 1/24 there, 30–55 CG iterations per
#: Newton step and 12 s of CPU for the solve against 200–232 and 57 s with ``AMG_OPTIONS`` (MUMPS: 21 s); test
#: model 1 in 2D, h = 1/32, contrast 10³: 49–58 against 40–48
HETEROGENEOUS_OPTIONS = {
    "pc_gamg_agg_nsmooths": 0,
    "mg_levels_ksp_type": "richardson",
    "mg_levels_pc_type": "sor",
}

#: KSP reasons by number (``PETSc.KSP.ConvergedReason``)
_REASON = PETSc.KSP.ConvergedReason
_KSP_REASONS = {v: k for k, v in vars(_REASON).items() if not k.startswith("_") and isinstance(v, int)}


class AMGSolver:
    """A Krylov solver (CG or GMRES) preconditioned by smoothed-aggregation AMG with the rigid-body
    near-nullspace of V; ``DirectSolver``'s interface (``set_operator``, ``solve``, ``mat_solve``).

    The AMG hierarchy is built at the first ``set_operator``; later operators on the same pattern (the Newton
    Jacobians of other active sets) keep its interpolation and recompute the coarse operators.  Every solve is
    checked (the KSP reason; ConvergenceError naming it and what to do); ``iterations`` holds the Krylov
    iterations of each solve.
    """

    def __init__(
        self, comm, *, prefix: str, space: fem.FunctionSpace, options: LinearSolverOptions, contrast: float = 1.0
    ) -> None:
        """``contrast``: max μ / min μ of the operator's material (the AMG threshold when ``options`` has none)."""
        self.ksp = PETSc.KSP().create(comm)
        self.ksp.setOptionsPrefix(prefix)
        opts = PETSc.Options()
        heterogeneous = contrast > HETEROGENEOUS_CONTRAST
        threshold = options.threshold
        if threshold is None:
            threshold = HETEROGENEOUS_THRESHOLD if heterogeneous else 0.0
        amg = {**AMG_OPTIONS, **HETEROGENEOUS_OPTIONS} if heterogeneous else AMG_OPTIONS
        if heterogeneous:  # no Chebyshev smoother: its options would stay unused
            amg = {k: v for k, v in amg.items() if "chebyshev" not in k}
            opts.delValue(f"{prefix}mg_levels_ksp_chebyshev_esteig_steps")
        for key, value in {
            **amg,
            "pc_gamg_threshold": threshold,
            "ksp_type": options.krylov,
            "ksp_rtol": options.rtol,
            "ksp_atol": 0.0,
            "ksp_max_it": options.max_iterations,
            # GMRES preconditioned from the right: its residual norm is the unpreconditioned one (the side is set for
            # CG too: a GMRES solver earlier under this prefix leaves its side in the options database)
            "ksp_pc_side": "right" if options.krylov == "gmres" else "left",
        }.items():
            opts[f"{prefix}{key}"] = value
        if options.krylov == "gmres":
            opts[f"{prefix}ksp_gmres_restart"] = 100
        self.ksp.setFromOptions()
        self.prefix = prefix
        self.options = options
        self.factorizations = 0  #: operators set (AMG set-ups, the first in full)
        self.iterations: list[int] = []  #: Krylov iterations of each solve
        self._identity = np.zeros(0, dtype=np.int64)  #: the owned rows of the operator that are the identity's
        self._modes = rigid_body_modes(space)
        self._nullspace = PETSc.NullSpace().create(vectors=self._modes, comm=comm)

    def set_operator(self, A: PETSc.Mat) -> None:
        """Use A from now on (symmetric positive definite for CG); the AMG set-up happens here, checked."""
        check_entries(A, self.prefix)
        self._identity = identity_rows(A)
        A.setNearNullSpace(self._nullspace)
        self.ksp.setOperators(A)
        self.ksp.setUp()
        reason = self.ksp.getPC().getFailedReason()
        if reason != 0:
            raise ConvergenceError(
                f"{self.prefix}: the AMG set-up failed "
                f"(PETSc PC failed reason {PC_FAILED_REASONS.get(reason, reason)}): "
                "check the data for values far out of range, or use the direct solver (solver='direct')"
            )
        self.factorizations += 1

    def solve(
        self,
        b: PETSc.Vec,
        x: PETSc.Vec,
        *,
        iterate: PETSc.Vec | None = None,
        rtol: float | None = None,
        guess: bool = False,
    ) -> None:
        """x = A⁻¹ b to ‖b − A x‖ ≤ rtol‖b‖, raising ConvergenceError when the Krylov solve fails.

        ``iterate``: the Newton iterate u when b = −F(u) (x the Newton step): the solve then stops at
        ‖b − A x‖ ≤ rtol·min(‖b‖, ‖A u + b‖), ‖A u + b‖ the norm of the right-hand side A u − F(u) of the new
        iterate's equation A (u + x) = A u − F(u) (its free rows; ``newton_tolerance``).  ``rtol``: this solve's
        tolerance instead of the options' (not with ``iterate``); ``guess``: start from x as it is (a warm start;
        the stop stays relative to ‖b‖), else from zero.
        """
        if iterate is not None:
            rtol = self.newton_tolerance(b, iterate)
        elif rtol is None:
            rtol = self.options.rtol
        self.ksp.setTolerances(rtol=rtol)
        self.ksp.setInitialGuessNonzero(bool(guess))
        self.ksp.solve(b, x)
        if self._identity.size:  # exact on the Dirichlet rows, as a factorization
            x.array[self._identity] = b.getArray(readonly=True)[self._identity]
        its = self.ksp.getIterationNumber()
        self.iterations.append(int(its))
        reason = self.ksp.getConvergedReason()
        if reason < 0:
            name = _KSP_REASONS.get(reason, str(reason))
            advice = (
                "the operator is not symmetric positive definite (a frictional or otherwise unsymmetric "
                "Jacobian): use krylov='gmres' or the direct solver (solver='direct')"
                if reason in (_REASON.DIVERGED_INDEFINITE_PC, _REASON.DIVERGED_INDEFINITE_MAT)
                else "raise the iteration cap (LinearSolverOptions(max_iterations=...)) or the tolerance, or use the "
                "direct solver (solver='direct'): a body held only by contact or springs, or a very large contrast "
                "in the moduli, slows AMG down"
            )
            raise ConvergenceError(
                f"{self.prefix}: {self.options.krylov.upper()} with AMG did not converge: KSP reason {name} after "
                f"{its} iterations (residual {self.ksp.getResidualNorm():.3e}, ‖b‖ {b.norm():.3e}, rtol "
                f"{rtol:g}); {advice}"
            )

    def newton_tolerance(self, b: PETSc.Vec, iterate: PETSc.Vec) -> float:
        """The relative tolerance on ‖b‖ of a Newton step's solve A x = b = −F(u) at the iterate u that stops it at
        rtol·min(‖b‖, ‖A u + b‖) (collective).

        Krylov solves of Newton steps usually stop at rtol‖F(u)‖.  In penalized contact a step that moves the
        active set leaves F(u) full of penalty forces (1/δ)(u·ν − g)⁺ far above the load (10⁹× it on the 3D
        channel cube at contrast 10⁶): rtol‖F(u)‖ then allows a residual above the load itself, the next iterate
        is wrong by more than its penetrations and the active sets cycle.  A u + b = A (u + x) is the right-hand
        side of the next iterate's own equation (the load and the gap's penalty forces, the Dirichlet columns'
        lifting); the Dirichlet rows, set exactly after the solve, are left out of its norm.
        """
        w = b.duplicate()
        try:
            self._operator().mult(iterate, w)
            w.axpy(1.0, b)
            w.array[self._identity] = 0.0
            target, norm = w.norm(), b.norm()
        finally:
            w.destroy()
        return self.options.rtol if norm == 0.0 else self.options.rtol * min(1.0, target / norm)

    def _operator(self) -> PETSc.Mat:
        return self.ksp.getOperators()[0]

    def mat_solve(self, B: PETSc.Mat, X: PETSc.Mat) -> None:
        """X = A⁻¹ B for a dense block B, one checked Krylov solve per column."""
        for j in range(B.getSize()[1]):
            b = B.getDenseColumnVec(j, "r")
            x = X.getDenseColumnVec(j, "w")
            try:
                self.solve(b, x)
            finally:
                B.restoreDenseColumnVec(j, "r")
                X.restoreDenseColumnVec(j, "w")

    def has_inverse_entries(self) -> bool:
        """False: no factors to take entries of A⁻¹ from (``DirectSolver.has_inverse_entries``)."""
        return False

    def destroy(self) -> None:
        for obj in (self.ksp, self._nullspace, *self._modes):
            obj.destroy()


def linear_solver(
    comm, *, prefix: str, space: fem.FunctionSpace, options: "LinearSolverOptions | str", contrast: float = 1.0
) -> DirectSolver | AMGSolver:
    """The solver ``options`` choose for operators on ``space`` (``LinearSolverOptions.chosen``); ``contrast``:
    max μ / min μ (``AMGSolver``)."""
    options = LinearSolverOptions.of(options)
    dofs = space.dofmap.index_map.size_global * space.dofmap.index_map_bs
    if options.chosen(dofs, space.mesh.topology.dim) == "amg":
        log.info("%s: %s + AMG for %d unknowns", prefix, options.krylov.upper(), dofs)
        return AMGSolver(comm, prefix=prefix, space=space, options=options, contrast=contrast)
    return DirectSolver(comm, prefix=prefix)


def amg_coarse_space(solver: AMGSolver, depth: int) -> sp.csr_matrix | None:
    """The interpolation P to the finest level from the AMG hierarchy's level ``depth`` below it (the product of the
    hierarchy's interpolations; the coarsest level where the hierarchy is shallower; None for a single level;
    sequential): the coarse functions of ``solver``'s operator, e.g. for a Galerkin coarse operator Pᵀ A P."""
    if isinstance(depth, bool) or not isinstance(depth, (int, np.integer)) or depth < 1:
        raise InputError(f"the coarse depth must be an integer >= 1, got {depth!r}")
    pc = solver.ksp.getPC()
    levels = pc.getMGLevels()
    P = None
    for level in range(levels - 1, max(levels - 1 - depth, 0), -1):
        step = petsc_to_scipy(pc.getMGInterpolation(level))
        P = step if P is None else (P @ step).tocsr()
    return P
