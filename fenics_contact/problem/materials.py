"""Isotropic plane-strain linear elasticity: Lamé parameters, stress, compliance.

σ(u) = 2μ ε(u) + λ tr ε(u) I,  A σ = (σ − λ/(2λ+2μ) tr σ I)/(2μ),
λ = Eν/((1+ν)(1−2ν)),  μ = E/(2(1+ν)).
"""

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import ufl

from fenics_contact.errors import InputError

__all__ = [
    "Material",
    "lame",
    "check_youngs_modulus",
    "check_poisson_ratio",
    "strain",
    "stress",
    "compliance",
]


def check_youngs_modulus(E: npt.ArrayLike) -> np.ndarray:
    """Return E as an array, raising InputError unless every value is finite and > 0."""
    E = np.asarray(E, dtype=np.float64)
    if not np.all(np.isfinite(E)) or np.any(E <= 0.0):
        bad = E[~(np.isfinite(E) & (E > 0.0))]
        raise InputError(f"Young's modulus must be finite and > 0; got {bad.ravel()[:5]}")
    return E


def check_poisson_ratio(nu: npt.ArrayLike) -> np.ndarray:
    """Return ν as an array, raising InputError unless every value lies in (−1, 1/2)."""
    nu = np.asarray(nu, dtype=np.float64)
    ok = np.isfinite(nu) & (nu > -1.0) & (nu < 0.5)
    if not np.all(ok):
        raise InputError(f"Poisson ratio must lie in the open interval (-1, 0.5); got {nu[~ok].ravel()[:5]}")
    return nu


def lame(E: npt.ArrayLike, nu: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Lamé parameters (λ, μ) from Young's modulus E and Poisson ratio ν (validated)."""
    E = check_youngs_modulus(E)
    nu = check_poisson_ratio(nu)
    return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


@dataclass(frozen=True, slots=True)
class Material:
    """A homogeneous isotropic material (E, ν), validated on construction."""

    E: float
    nu: float

    def __post_init__(self) -> None:
        check_youngs_modulus(self.E)
        check_poisson_ratio(self.nu)

    @property
    def lame(self) -> tuple[float, float]:
        """(λ, μ)."""
        lmbda, mu = lame(self.E, self.nu)
        return float(lmbda), float(mu)


def strain(u: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """ε(u) = sym ∇u."""
    return ufl.sym(ufl.grad(u))


def stress(eps: ufl.core.expr.Expr, lmbda, mu) -> ufl.core.expr.Expr:
    """σ = 2μ ε + λ tr(ε) I."""
    return 2.0 * mu * eps + lmbda * ufl.tr(eps) * ufl.Identity(eps.ufl_shape[0])


def compliance(sigma: ufl.core.expr.Expr, lmbda, mu) -> ufl.core.expr.Expr:
    """A σ = (σ − λ/(2λ+2μ) tr(σ) I)/(2μ) (plane strain)."""
    d = sigma.ufl_shape[0]
    return (sigma - lmbda / (2.0 * lmbda + 2.0 * mu) * ufl.tr(sigma) * ufl.Identity(d)) / (2.0 * mu)
