"""The Ω₁ side of Algorithm 4 as an affine map of the Robin data g: ``InterfaceResponse`` (precomputed offline)."""

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from fenics_contact.multiscale.mixed_cem.coarse import CoarseOperators

__all__ = ["InterfaceResponse"]


@dataclass(slots=True)
class InterfaceResponse:
    """The Ω₁ multiscale solution as an affine map of the Robin data g (n_g values on γ).

    The coarse problem is linear, so r = R g + r₀, w = W g + w₀ (n_g coarse solves, offline),
    and everything the iteration needs is a small matrix in g: the trace σ₁n₁ = T g + t₀ and
    the quadratic forms ‖σ₁‖²_A, ‖u₁‖²_L² (for the stopping rule).  Online, the Ω₁ step of
    Algorithm 4 then costs O(n_g²) instead of a coarse solve of size dim X_ms + dim U_aux.
    """

    R: np.ndarray  #: (n_ms, n_g)
    r0: np.ndarray
    W: np.ndarray  #: (n_aux, n_g)
    w0: np.ndarray
    T: np.ndarray  #: (n_g, n_g) trace map
    t0: np.ndarray
    KA: np.ndarray  #: (n_g, n_g): ‖σ₁(g) − σ₁(g')‖²_A = (g − g')ᵀ KA (g − g')
    kA: np.ndarray  #: ‖σ₁(g)‖²_A = gᵀKA g + 2 kAᵀg + cA
    cA: float
    KM: np.ndarray  #: the same for ‖u₁‖²_L²
    kM: np.ndarray
    cM: float

    @classmethod
    def of(
        cls, co: CoarseOperators, lu: tuple, F1: np.ndarray, F2: np.ndarray, E_r: np.ndarray, E_g: np.ndarray
    ) -> "InterfaceResponse":
        """The response of the coarse problem with operators ``co``: ``lu`` the ``scipy.linalg.lu_factor`` of its
        matrix [[ΨᵀÃΨ, (ΠᵀBΨ)ᵀ], [ΠᵀBΨ, 0]], right-hand sides F1 d (τ rows) and Πᵀ G − F2 d (v rows) for the data
        d = [g; 1], trace σ₁n₁ = E_r r + E_g d."""
        n, n_g = co.n_ms, co.n_g
        X = sla.lu_solve(lu, np.vstack([F1[:, :n_g], -F2[:, :n_g]]))  # a column per γ value
        x0 = sla.lu_solve(lu, np.concatenate([F1[:, n_g], co.PiG - F2[:, n_g]]))  # g = 0
        R, W, r0, w0 = X[:n], X[n:], x0[:n], x0[n:]
        lift_d = np.vstack([np.eye(n_g), np.zeros((1, n_g))])  # g ↦ d − e_load
        e_load = np.zeros(n_g + 1)
        e_load[n_g] = 1.0
        forms = []
        for lift, shift, gram in ((R, r0, co.Gk), (W, w0, co.Mu)):
            L = np.vstack([lift, lift_d])
            s0 = np.concatenate([shift, e_load])
            GL, Gs = gram @ L, gram @ s0
            forms += [0.5 * (L.T @ GL + (L.T @ GL).T), L.T @ Gs, float(s0 @ Gs)]
        T = E_r @ R + E_g[:, :n_g]
        return cls(R, r0, W, w0, T, E_r @ r0 + E_g[:, n_g], *forms)

    def trace(self, g: np.ndarray) -> np.ndarray:
        """σ₁n₁ at the γ nodes for data g."""
        return self.T @ g + self.t0

    def stress_norm2(self, g: np.ndarray) -> float:
        """‖σ₁(g)‖²_A."""
        return float(g @ self.KA @ g + 2.0 * self.kA @ g + self.cA)

    def stress_change2(self, g: np.ndarray, g_old: np.ndarray) -> float:
        """‖σ₁(g) − σ₁(g_old)‖²_A."""
        d = g - g_old
        return float(d @ self.KA @ d)

    def l2_norm2(self, g: np.ndarray) -> float:
        """‖u₁(g)‖²_L²."""
        return float(g @ self.KM @ g + 2.0 * self.kM @ g + self.cM)

    def l2_change2(self, g: np.ndarray, g_old: np.ndarray) -> float:
        """‖u₁(g) − u₁(g_old)‖²_L²."""
        d = g - g_old
        return float(d @ self.KM @ d)
