"""Matrix-free interface Newton: Newton–GMRES on F(g) = g − T(g), for an Ω₁ solved by CG + AMG.

With Ω₁ solved iteratively its interface response T₁ is not formed: it would cost n_γ Ω₁ solves and
O(n_γ²) memory, and in 3D n_γ = O(h⁻²).  Each Newton step solves its interface equation

    (I − P₁P₂) d₂₁ = −F₂₁ − P₁F₁₂,   d₁₂ = P₂d₂₁ − F₁₂,
    P₁ = a⊙T₁ + b,   P₂ = a⊙Y₂ + b   (T(g) = (a⊙y₂ + b g₂₁, a⊙y₁ + b g₁₂), primal a = 2α, b = −1)

by GMRES, each product one Ω₁ solve (its AMG set-up reused) and one back-solve with Ω₂'s factorization of
its Jacobian at its current active set (Y₂: Ω₂'s linearized trace response).  GMRES is preconditioned from the
right by I − P̃₁P₂, P̃₁ the Robin map of a cheap Ω₁ model (a band next to γ and the AMG's coarse functions,
``hybrid.krylov_band``; ``InterfaceNewtonOptions.krylov_layers``, ``krylov_coarse``): the products stay exact Ω₁
solves, their number per Newton step falls to a few.  The Newton is inexact: GMRES
stops at the relative residual η_k = min(``ETA_MAX``, r_k) (r_k the transmission residual of the current
pair), so the last steps are solved as accurately as the tolerance asks.  A backtracking line search on
‖F‖ globalizes it.  Every trial is an application of T (the Ω₂ semismooth Newton, warm-started), and the
transmission residual of the last pair certifies the result, as for the other strategies.
"""

import logging
import time

import numpy as np
import scipy.sparse.linalg as spla

from fenics_contact.fem.amg import AMGSolver, amg_coarse_space
from fenics_contact.hybrid.krylov_band import BandPreconditioner
from fenics_contact.hybrid.options import IterationOptions
from fenics_contact.hybrid.response import PrimalPart
from fenics_contact.hybrid.step import IterationHistory, evaluate

__all__ = ["KrylovInterface", "krylov_newton_iterate", "ETA_MAX", "GMRES_RESTART"]

log = logging.getLogger(__name__)

#: the largest relative GMRES tolerance of a Newton step (the first steps, far from the fixed point)
ETA_MAX = 1e-2
#: GMRES restart length (interface vectors kept); products per Newton step are capped at ``GMRES_PRODUCTS``
GMRES_RESTART = 200
GMRES_PRODUCTS = 2000
#: trial step lengths 1, ½, … of the backtracking line search (each trial one application of T)
BACKTRACKS = 6
#: the smallest GMRES tolerance (below it the inexact Ω₁ solves dominate the products' error)
ETA_MIN = 1e-13


class KrylovInterface:
    """The interface equation of the Newton step, matrix-free: P₁ v by one Ω₁ solve, P₂ v by one Ω₂
    back-solve with the factorization Ω₂ holds; vectors are global interface values (identical on all ranks).

    ``layers`` (None: no preconditioner) and ``coarse``: GMRES preconditioned from the right by the Robin response
    of a cheap Ω₁ model, the band of Ω₁ within ``layers`` couplings of γ and the coarse functions ``coarse`` levels
    below the finest of Ω₁'s AMG (0: none) beyond it (``hybrid.krylov_band``; on one process, else none)."""

    def __init__(
        self,
        omega1: PrimalPart,
        omega2: PrimalPart,
        a: np.ndarray,
        b: float,
        *,
        layers: int | None = None,
        coarse: int = 0,
    ) -> None:
        self.omega1, self.omega2, self.a, self.b = omega1, omega2, a, b
        self.free = np.flatnonzero(omega1.data_free() | omega2.data_free())  #: values whose data act (not γ ∩ Γ_D)
        self.products = 0  #: interface products (each one Ω₁ solve and one Ω₂ back-solve), GMRES's and the step's
        self.layers, self.coarse = layers, coarse
        self._band: BandPreconditioner | None = None
        self._band_for: tuple | None = None  # (layers, coarse) of ``_band``

    @property
    def preconditioner(self) -> BandPreconditioner | None:
        """The preconditioner of ``layers`` and ``coarse`` (built at its first use, kept while they stay; None:
        unpreconditioned GMRES)."""
        if self.layers is None or self.omega1.comm.size > 1:
            return None
        if self._band is None or self._band_for != (self.layers, self.coarse):
            if self._band is not None:
                self._band.destroy()
            solver = self.omega1.sub.solver
            P = amg_coarse_space(solver, self.coarse) if self.coarse and isinstance(solver, AMGSolver) else None
            self._band = BandPreconditioner(self.omega1, self.omega2, self.a, self.b, layers=self.layers, coarse=P)
            self._band_for = (self.layers, self.coarse)
        return self._band

    @staticmethod
    def _response(part: PrimalPart, d: np.ndarray, solver=None) -> np.ndarray:
        """N J⁻¹ C d: the trace on γ of the part's solve with Robin data d (global), no load."""
        r = np.zeros(part.nown)
        r[part.data_at] = part.data_w * d[part.data_index]
        x = part.solve(r, solver)
        return part.trace_rows(x[:, None])[:, 0]

    def P1(self, v: np.ndarray) -> np.ndarray:
        return self.a * self._response(self.omega1, v) + self.b * v

    def P2(self, v: np.ndarray) -> np.ndarray:
        return self.a * self._response(self.omega2, v, self.omega2.sub.solver) + self.b * v

    def direction(self, F12: np.ndarray, F21: np.ndarray, eta: float) -> tuple[np.ndarray, np.ndarray, int, bool]:
        """(d₁₂, d₂₁, GMRES products, whether GMRES reached η) of the Newton step at F = (F₁₂, F₂₁)."""
        f, n = self.free, self.a.size

        def full(x: np.ndarray) -> np.ndarray:
            out = np.zeros(n)
            out[f] = x
            return out

        count = [0]
        band = self.preconditioner
        right = (lambda y: y) if band is None else band.solve  # M⁻¹ (GMRES on (I − P₁P₂) M⁻¹)

        def matvec(y: np.ndarray) -> np.ndarray:
            count[0] += 1
            x = right(np.asarray(y).ravel())
            return x - self.P1(self.P2(full(x)))[f]

        rhs = (-F21 - self.P1(F12))[f]
        A = spla.LinearOperator((f.size, f.size), matvec=matvec, dtype=float)
        y, info = spla.gmres(
            A, rhs, rtol=eta, atol=0.0, restart=GMRES_RESTART, maxiter=max(GMRES_PRODUCTS // GMRES_RESTART, 1)
        )
        d21 = full(right(y))
        d12 = self.P2(d21) - F12
        self.products += count[0] + 1
        return d12, d21, count[0], info == 0


def krylov_newton_iterate(
    step, options: IterationOptions, *, name: str, monitor=None, initial: np.ndarray | None = None
) -> IterationHistory:
    """Newton–GMRES on g = T(g) (``step.krylov_interface()``: a ``KrylovInterface``); each record is one
    application of T, its ``info["gmres"]`` the GMRES products of the step that led to it."""
    nopt = options.newton
    history = IterationHistory()
    t_off = time.perf_counter()
    kry = step.krylov_interface()
    kry.layers, kry.coarse = nopt.krylov_layers, nopt.krylov_coarse
    history.time_offline_s = time.perf_counter() - t_off
    start = time.perf_counter()
    comm = step.comm
    iface = step.interface
    n = iface.size

    def halves(g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return iface.gather(g[:n]), iface.gather(g[n:])

    def fnorm(g: np.ndarray, Tg: np.ndarray) -> float:
        return float(np.linalg.norm(np.concatenate([a - b for a, b in zip(halves(g), halves(Tg))])))

    g = step.initial_data() if initial is None else np.array(initial, dtype=float)
    Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
    steps_left = nopt.max_steps
    while rec.residual >= options.tol and steps_left > 0 and history.iterations < options.max_iterations:
        F12, F21 = (a - b for a, b in zip(halves(g), halves(Tg)))
        norm0 = float(np.linalg.norm(np.concatenate([F12, F21])))
        eta = float(np.clip(min(ETA_MAX, rec.residual), ETA_MIN, ETA_MAX))
        d12, d21, products, reached = kry.direction(F12, F21, eta)
        d12, d21 = comm.bcast((d12, d21), root=0)
        steps_left -= 1
        history.newton_steps += 1
        if not reached:
            log.warning("%s: GMRES stopped at %d products above its tolerance %.1e", name, products, eta)
        g0, rec0, t = g, rec, 1.0
        while True:  # backtracking
            g = g0 + t * np.concatenate([iface.local(d12), iface.local(d21)])
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
            rec.info["gmres"] = products
            rec.info["step_length"] = t
            accepted = (
                rec.residual < options.tol
                or fnorm(g, Tg) <= (1.0 - 1e-4 * t) * norm0
                or rec.residual < 0.5 * rec0.residual
            )
            if accepted or history.iterations >= options.max_iterations or t <= 0.5 ** (BACKTRACKS - 1):
                break
            t *= 0.5
        log.info(
            "%s: Newton–GMRES step %d, %d products (η %.1e), step length %g, residual %.3e",
            name,
            history.newton_steps,
            products,
            eta,
            t,
            rec.residual,
        )
    history.converged = bool(rec.residual < options.tol)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    log.info(
        "%s: %s, %d Newton–GMRES steps, %d products, %d applications of T, transmission residual %.3e, online %.3f s",
        name,
        "converged" if history.converged else "NOT converged",
        history.newton_steps,
        kry.products,
        history.iterations,
        rec.residual,
        history.time_s,
    )
    if comm.rank == 0 and not history.converged:
        log.warning("%s: the Newton–GMRES interface iteration did not reach the tolerance %g", name, options.tol)
    return history
