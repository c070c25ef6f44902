"""The iteration on the Robin data of two bodies' interfaces (Algorithm 1 for a ``TwoBodyProblem``).

g = (g₁₂, g₂₁) holds the Robin data of both parts (bulks and strips) on γ; T(g) solves both and returns the new
data 2α u|γ − g of the other side.  The interface Newton updates g by (I − T′)⁻¹(T(g) − g) with
T′ = [[0, 2α R₂ − I], [2α R₁ − I, 0]], R₁ = ∂u₁|γ/∂g₁₂ (the bulks: linear, once) and R₂ = ∂u₂|γ/∂g₂₁ at the
strips' current contact state; after ``NEWTON_STEPS`` without convergence (a cycle of active sets) the iteration
goes on with Anderson acceleration, as does ``accel="anderson"``.  Shared by the serial solve (``two_body``) and
the distributed one (``two_body_mpi``), which differ only in how T, R₁ and R₂ are computed.

The iteration stops on the certificate (``hybrid.certificate``): below ``tol``, or at its round-off floor
(``certificate.at_floor``: within ``FLOOR_MARGIN`` of the floor of the pair, and above half the best residual before
it; with a fixed-point update, which may converge slowly there, its last ``STALLED`` evaluations no lower than the
best before them), then
converged with the floor reported (a stiff body on a soft one: on the stiff side of γ the Robin data are 10⁶ times
the traction they carry, and the balance of the tractions is resolved only to 10⁶ times the solves' relative error).
"""

import logging
from collections.abc import Callable
from typing import NamedTuple

import numpy as np
from mpi4py import MPI

from fenics_contact.hybrid.anderson import AndersonUpdate
from fenics_contact.hybrid.certificate import FLOOR_MARGIN, Certificate, at_floor

__all__ = ["NEWTON_STEPS", "PairOutcome", "iterate_pair_interface"]

log = logging.getLogger(__name__)

#: interface Newton steps before the iteration goes on with Anderson acceleration (a cycle of active sets)
NEWTON_STEPS = 30
#: a fixed-point update (Anderson, the plain one) is at the floor when this many evaluations of T brought no residual
#: below the best before them
STALLED = 5


class PairOutcome(NamedTuple):
    """What the iteration on a pair's interface data ended with."""

    g: np.ndarray  #: the data of the last pair
    converged: bool  #: the last pair's residual below ``tol`` or at its floor
    steps: int  #: interface Newton steps taken
    floor: float  #: the round-off floor of the last pair's certificate
    status: str  #: ``"converged"``, ``"floor"`` or ``"not converged"``


def iterate_pair_interface(
    T: Callable[[np.ndarray], tuple[np.ndarray, Certificate]],
    g: np.ndarray,
    alpha: np.ndarray,
    R1: Callable[[], np.ndarray],
    R2: Callable[[], np.ndarray],
    options,
    *,
    name: str,
    warn: bool = True,
) -> PairOutcome:
    """The fixed point of T from ``g`` to the certificate ``options.tol`` or its floor (T returns the new data and
    the certificate of its argument), at most ``options.max_iterations`` applications of T.

    ``R1()`` is called once, ``R2()`` after each application of T (at the strips' state of that solve);
    ``options.accel`` is ``"newton"`` (then Anderson), ``"anderson"`` or ``"none"`` (the plain iteration);
    ``warn``: log the hand-over to Anderson and the end at the floor (one rank of a parallel run).
    """
    m = alpha.size
    status, steps, seen = "not converged", 0, []
    cert = Certificate(np.inf, np.inf)

    def done(cert: Certificate, back: int) -> str | None:
        """Below tol, at the floor, or None: a Newton step (``back`` 1) at the floor did not halve the best residual
        before it; a fixed-point update's last ``back`` evaluations, the last within the floor's margin, brought no
        residual below the best before them."""
        res = cert.value
        seen.append(res)
        if res < options.tol:
            return "converged"
        if back == 1:
            return "floor" if at_floor(res, cert.floor, min(seen[:-1], default=None)) else None
        if len(seen) <= back or res > FLOOR_MARGIN * cert.floor:
            return None
        return "floor" if at_floor(min(seen[-back:]), cert.floor, min(seen[:-back]), reduction=1.0) else None

    if options.accel == "newton":
        R1_ = R1()
        zero, one = np.zeros((m, m)), np.eye(m)
        for steps in range(1, min(NEWTON_STEPS, options.max_iterations) + 1):
            Tg, cert = T(g)
            if (end := done(cert, 1)) is not None:
                status = end
                break
            dT = np.block([[zero, 2 * alpha[:, None] * R2() - one], [2 * alpha[:, None] * R1_ - one, zero]])
            g = g + np.linalg.solve(np.eye(2 * m) - dT, Tg - g)
        if status == "not converged" and steps < options.max_iterations and warn:
            log.warning("%s: no interface Newton convergence in %d steps; Anderson", name, steps)
    if status == "not converged" and steps < options.max_iterations:
        update = AndersonUpdate(MPI.COMM_SELF, options.depth) if options.accel != "none" else None
        for _ in range(options.max_iterations - steps):
            Tg, cert = T(g)
            if (end := done(cert, STALLED)) is not None:
                status = end
                break
            g = update(g, Tg) if update is not None else Tg
    if status == "floor" and warn:
        log.warning(
            "%s: converged at the round-off floor %.1e of the transmission residual (residual %.1e above tol %.1e): "
            "the pair glues as far as its subdomain solves resolve it (status 'floor'); a tol of %.0e or more ends "
            "below tol",
            name,
            cert.floor,
            cert.value,
            options.tol,
            FLOOR_MARGIN * cert.floor,
        )
    return PairOutcome(g, status != "not converged", steps, float(cert.floor), status)
