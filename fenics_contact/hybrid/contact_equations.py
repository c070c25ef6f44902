"""The contact equations on the condensed Γ_C unknowns, s = s_L − M μ, μ = D s⁺ (``hybrid.condensation``).

``solve_on`` solves them linearized on a given active set; ``energy_line_search`` is the exact line
search along a step on the energy ψ = ½ μᵀMμ + ½ Σ D (s⁺)² (the convex energy of the glued problem when
M is symmetric).  The contact Newton (``hybrid.contact_newton``) and the local front problems
(``hybrid.fronts``) take their steps with them.
"""

import numpy as np
import scipy.linalg as sla

__all__ = ["solve_on", "energy_line_search"]


def solve_on(
    s_load: np.ndarray, M: np.ndarray, D: np.ndarray, A: np.ndarray, factors: dict | None = None
) -> tuple[np.ndarray, np.ndarray, float]:
    """The contact equations s = s_L − M μ, μ = D s⁺ linearized on the set A (indices): (s, μ, the relative residual
    of the solve).  (D_A⁻¹ + M_AA) μ_A = s_L,A, μ = 0 off A, s = s_L − M_:A μ_A and on A s = μ_A / D_A (no
    cancellation with a stiff penalty); the residual is 0 for an empty A and infinite when not finite.
    ``factors``: LU factors of the systems by set (``A.tobytes()``), taken from it and added to it."""
    s, mu = s_load.copy(), np.zeros(s_load.size)
    if not A.size:
        return s, mu, 0.0
    K = M[np.ix_(A, A)] + np.diag(1.0 / D[A])
    if factors is None:
        mu[A] = np.linalg.solve(K, s_load[A])
    else:
        lu = factors.get(A.tobytes())
        if lu is None:
            lu = factors[A.tobytes()] = sla.lu_factor(K, check_finite=False)
        mu[A] = sla.lu_solve(lu, s_load[A], check_finite=False)
    r = K @ mu[A] - s_load[A]
    s = s_load - M[:, A] @ mu[A]
    s[A] = mu[A] / D[A]
    size = np.linalg.norm(s_load[A]) + np.linalg.norm(M[np.ix_(A, A)] @ mu[A]) + 1e-300
    return s, mu, float(np.linalg.norm(r) / size) if np.isfinite(r).all() else np.inf


def energy_line_search(
    mu: np.ndarray, dmu: np.ndarray, s: np.ndarray, ds: np.ndarray, s_load: np.ndarray, D: np.ndarray
) -> float:
    """argmin over t ∈ (0, 1] of ψ(s + t ds): root of the increasing piecewise-linear φ'(t).

    φ'(t) = dμᵀ(s_L − s − t ds) + Σ D (s + t ds)⁺ ds  (ψ = ½μᵀMμ + ½ΣD(s⁺)², s = s_L − Mμ).
    """
    c0, c1 = dmu @ (s_load - s), -(dmu @ ds)

    def dphi(t: np.ndarray) -> np.ndarray:
        return c0 + c1 * t + (D * ds * np.maximum(s[None, :] + t[:, None] * ds[None, :], 0.0)).sum(axis=1)

    ends = dphi(np.array([0.0, 1.0]))
    if ends[0] >= 0.0 or ends[1] <= 0.0:
        return 1.0
    nz = ds != 0.0
    bp = -s[nz] / ds[nz]
    bp = np.unique(np.concatenate([[0.0, 1.0], bp[(bp > 0.0) & (bp < 1.0)]]))
    vals = dphi(bp)
    k = int(np.argmax(vals > 0.0))
    t0, t1, v0, v1 = bp[k - 1], bp[k], vals[k - 1], vals[k]
    return float(t0 - v0 * (t1 - t0) / (v1 - v0))
