"""The iteration on the Robin data of two bodies' interfaces (Algorithm 1 for a ``TwoBodyProblem``).

g = (g₁₂, g₂₁) holds the Robin data of both parts (bulks and strips) on γ; T(g) solves both and returns the new
data 2α u|γ − g of the other side.  The interface Newton updates g by (I − T′)⁻¹(T(g) − g) with
T′ = [[0, 2α R₂ − I], [2α R₁ − I, 0]], R₁ = ∂u₁|γ/∂g₁₂ (the bulks: linear, once) and R₂ = ∂u₂|γ/∂g₂₁ at the
strips' current contact state; after ``NEWTON_STEPS`` without convergence (a cycle of active sets) the iteration
goes on with Anderson acceleration, as does ``accel="anderson"``.  Shared by the serial solve (``two_body``) and
the distributed one (``two_body_mpi``), which differ only in how T, R₁ and R₂ are computed.
"""

import logging
from collections.abc import Callable

import numpy as np
from mpi4py import MPI

from fenics_contact.hybrid.anderson import AndersonUpdate

__all__ = ["NEWTON_STEPS", "iterate_pair_interface"]

log = logging.getLogger(__name__)

#: interface Newton steps before the iteration goes on with Anderson acceleration (a cycle of active sets)
NEWTON_STEPS = 30


def iterate_pair_interface(
    T: Callable[[np.ndarray], tuple[np.ndarray, float]],
    g: np.ndarray,
    alpha: np.ndarray,
    R1: Callable[[], np.ndarray],
    R2: Callable[[], np.ndarray],
    options,
    *,
    name: str,
    warn: bool = True,
) -> tuple[np.ndarray, bool, int]:
    """(g, converged, Newton steps taken): the fixed point of T from ``g`` to the certificate ``options.tol`` (T
    returns the new data and the certificate of its argument), at most ``options.max_iterations`` applications
    of T.

    ``R1()`` is called once, ``R2()`` after each application of T (at the strips' state of that solve);
    ``options.accel`` is ``"newton"`` (then Anderson), ``"anderson"`` or ``"none"`` (the plain iteration);
    ``warn``: log the hand-over to Anderson (one rank of a parallel run).
    """
    m = alpha.size
    converged, steps = False, 0
    if options.accel == "newton":
        R1_ = R1()
        zero, one = np.zeros((m, m)), np.eye(m)
        for steps in range(1, min(NEWTON_STEPS, options.max_iterations) + 1):
            Tg, res = T(g)
            if res < options.tol:
                converged = True
                break
            dT = np.block([[zero, 2 * alpha[:, None] * R2() - one], [2 * alpha[:, None] * R1_ - one, zero]])
            g = g + np.linalg.solve(np.eye(2 * m) - dT, Tg - g)
        if not converged and steps < options.max_iterations and warn:
            log.warning("%s: no interface Newton convergence in %d steps; Anderson", name, steps)
    if not converged and steps < options.max_iterations:
        update = AndersonUpdate(MPI.COMM_SELF, options.depth) if options.accel != "none" else None
        for _ in range(options.max_iterations - steps):
            Tg, res = T(g)
            if res < options.tol:
                converged = True
                break
            g = update(g, Tg) if update is not None else Tg
    return g, converged, steps
