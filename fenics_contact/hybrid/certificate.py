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
"""

from typing import NamedTuple

import numpy as np
from mpi4py import MPI

__all__ = ["Certificate", "primal_certificate", "mixed_certificate", "relative"]


class Certificate(NamedTuple):
    """Transmission residual of a pair: the displacement jump and the traction balance, both relative."""

    jump: float  #: ‖u₁ − u₂‖_γ / max_i ‖u_i‖_γ
    balance: float  #: ‖t₁ + t₂‖_γ / max_i ‖t_i‖_γ

    @property
    def value(self) -> float:
        """max(jump, balance): the transmission residual."""
        return max(self.jump, self.balance)


def relative(num: float, den: float) -> float:
    """num / den, with 0/0 = 0 and x/0 = inf (a nonzero residual of a vanishing quantity is not small)."""
    if den > 0.0:
        return num / den
    return 0.0 if num == 0.0 else np.inf


def primal_certificate(
    u1: np.ndarray,
    u2: np.ndarray,
    g12: np.ndarray,
    g21: np.ndarray,
    alpha: np.ndarray,
    weights: np.ndarray,
    comm: MPI.Comm,
) -> Certificate:
    """Nodal certificate of Algorithms 1 and 3 from owned interface values (collective)."""
    t1 = g12 - alpha * u1
    t2 = g21 - alpha * u2
    local = np.array([weights @ v**2 for v in (u1 - u2, u1, u2, t1 + t2, t1, t2)])
    n = np.sqrt(comm.allreduce(local, op=MPI.SUM))
    return Certificate(relative(n[0], max(n[1], n[2])), relative(n[3], max(n[4], n[5])))


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
