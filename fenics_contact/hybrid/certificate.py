"""The convergence certificate of the hybrid iteration: how far a pair (Ω₁, Ω₂ solutions) is from gluing.

At a fixed point of any of the four algorithms the transmission conditions hold
on γ: the displacements agree (u₁ = u₂) and the tractions balance
(σ₁n₁ + σ₂n₂ = 0).  Both are measured directly on the current pair, each
relative to the size of the quantity it compares:

    transmission residual = max( ‖u₁ − u₂‖_γ / max_i ‖u_i‖_γ ,  ‖t₁ + t₂‖_γ / max_i ‖t_i‖_γ ).

* Primal (Algorithms 1, 3), nodal on γ with the vertex weights w_p: the weak
  traction of subdomain i is t_i(p) = g_i(p) − α_p u_i(p) (the Robin condition
  solved for the flux), ‖v‖²_γ = Σ_p w_p |v(p)|².
* Mixed (Algorithms 2, 4): t_i = σ_i n_i (the P3 trace; for Algorithm 4 the
  multiscale trace averaged at the coarse nodes, as its update uses it), the
  displacement trace u_i = g_i − β t_i, ‖·‖_γ the L²(γ) norm of the continuous P3
  trace functions (the γ mass matrix).

Unlike the relative change of the iterates or ‖g − T(g)‖/‖g‖, this does not
degenerate for α, β → 0 or ∞: in either limit one of the two conditions is
violated by an O(1) relative amount until the pair is glued.  It vanishes
exactly at the fixed point (both conditions together are equivalent to
g = T(g)).

**Its floor.**  The terms the certificate subtracts are computed: each carries its rounding (about ε of its size,
ε the machine epsilon) and the error of the subdomain solve that produced it (``errors``: an estimate of each
u_i's error on γ, e.g. one step of iterative refinement, δu_i = A_i⁻¹(b_i − A_i u_i)).  The transmission residual
of a computed pair cannot be resolved below

    floor = max( (c ε (‖u₁‖ + ‖u₂‖) + ‖δu₁‖ + ‖δu₂‖) / max_i ‖u_i‖ ,
                 (c ε (‖g₁₂‖ + ‖α u₁‖ + ‖g₂₁‖ + ‖α u₂‖) + ‖α δu₁‖ + ‖α δu₂‖) / max_i ‖t_i‖ )   (c = ``ROUNDOFF``),

scale-free like the residual.  Where a stiff side's Robin data are 10⁶ times the traction they carry, the
balance's floor is 10⁶ times the relative error of αu there.  A residual within ``FLOOR_MARGIN`` of it that an
iteration step no longer halves is round-off (``at_floor``): the iterations end there, converged *at the floor*,
the floor reported beside the residual.
"""

from typing import NamedTuple

import numpy as np
from mpi4py import MPI

__all__ = [
    "Certificate",
    "FLOOR_MARGIN",
    "ROUNDOFF",
    "at_floor",
    "primal_certificate",
    "mixed_certificate",
    "relative",
    "status",
]

#: c of the floor: one rounding per term (on a stiff inclusion cut by γ at contrast 10⁶ the residual of pairs whose
#: Ω₁ is solved to 10⁻¹² scatters over 1–5·10⁻¹⁰, this term 2·10⁻¹⁰ and Ω₁'s error 2·10⁻¹⁰ of it)
ROUNDOFF = 1.0
#: a residual at most this many times its floor is round-off when a step no longer reduces it (the residuals of pairs
#: at their floor measured 0.3–1.0 times it; a slowly converging Anderson at 8 times it was 5 floors from the solution)
FLOOR_MARGIN = 2.0
#: a floor at or above this is no floor (a vanishing traction on both sides: no scale to measure round-off by)
FLOOR_LIMIT = 1e-2


class Certificate(NamedTuple):
    """Transmission residual of a pair: the displacement jump and the traction balance, both relative."""

    jump: float  #: ‖u₁ − u₂‖_γ / max_i ‖u_i‖_γ
    balance: float  #: ‖t₁ + t₂‖_γ / max_i ‖t_i‖_γ
    floor: float = 0.0  #: the round-off of the measure itself (module docstring; 0: not estimated)

    @property
    def value(self) -> float:
        """max(jump, balance): the transmission residual."""
        return max(self.jump, self.balance)


def relative(num: float, den: float) -> float:
    """num / den, with 0/0 = 0 and x/0 = inf (a nonzero residual of a vanishing quantity is not small)."""
    if den > 0.0:
        return num / den
    return 0.0 if num == 0.0 else np.inf


def status(converged: bool, at_floor: bool) -> str:
    """``"converged"`` (below tol), ``"floor"`` (converged at the round-off floor, above tol) or ``"not converged"``."""
    return "not converged" if not converged else ("floor" if at_floor else "converged")


def at_floor(residual: float, floor: float, previous: float | None, *, reduction: float = 0.5) -> bool:
    """The residual is round-off: at most ``FLOOR_MARGIN`` × its floor (a floor below ``FLOOR_LIMIT``), and the
    step from the ``previous`` residual (None: no step yet) did not bring it below ``reduction`` × that (a Newton
    step: ½; steps of a fixed-point update, which may converge slowly: 1, no progress at all)."""
    if previous is None or not (0.0 < floor < FLOOR_LIMIT):
        return False
    return bool(residual <= FLOOR_MARGIN * floor and residual >= reduction * previous)


def primal_certificate(
    u1: np.ndarray,
    u2: np.ndarray,
    g12: np.ndarray,
    g21: np.ndarray,
    alpha: np.ndarray,
    weights: np.ndarray,
    comm: MPI.Comm,
    errors: tuple[np.ndarray, np.ndarray] | None = None,
) -> Certificate:
    """Nodal certificate of Algorithms 1 and 3 from owned interface values (collective); ``errors``: estimates of
    the errors of u₁ and u₂ (None: rounding only) for its floor."""
    t1 = g12 - alpha * u1
    t2 = g21 - alpha * u2
    e1, e2 = (np.zeros_like(u1), np.zeros_like(u2)) if errors is None else errors
    terms = (u1 - u2, u1, u2, t1 + t2, t1, t2, e1, e2, alpha * e1, alpha * e2, g12, alpha * u1, g21, alpha * u2)
    n = np.sqrt(comm.allreduce(np.array([weights @ v**2 for v in terms]), op=MPI.SUM))
    eps = ROUNDOFF * np.finfo(float).eps
    size_u, size_t = max(n[1], n[2]), max(n[4], n[5])
    floor = max(
        relative(eps * (n[1] + n[2]) + n[6] + n[7], size_u),
        relative(eps * (n[10] + n[11] + n[12] + n[13]) + n[8] + n[9], size_t),
    )
    return Certificate(relative(n[0], size_u), relative(n[3], size_t), floor)


def mixed_certificate(
    t1: np.ndarray, t2: np.ndarray, g12: np.ndarray, g21: np.ndarray, beta: float, mass, comm: MPI.Comm | None = None
) -> Certificate:
    """Certificate of Algorithms 2 and 4 from the traces σ_in_i at the γ nodes.

    ``mass``: the γ mass matrix acting on the given values (serial: all of them; with ``comm``: this rank's
    block of a distributed vector, ``fem.mixed.MixedSubproblem.gamma_mass``), norms summed over ``comm``.
    """
    u1 = g12 - beta * t1
    u2 = g21 - beta * t2

    def norm(v: np.ndarray) -> float:
        local = float(v @ (mass @ v))
        total = comm.allreduce(local, op=MPI.SUM) if comm is not None and comm.size > 1 else local
        return float(np.sqrt(max(total, 0.0)))

    return Certificate(
        relative(norm(u1 - u2), max(norm(u1), norm(u2))), relative(norm(t1 + t2), max(norm(t1), norm(t2)))
    )
