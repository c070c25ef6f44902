"""UFL helpers of the AW forms: the symmetric tensor of (σ_xx, σ_xy, σ_yy), plane-strain Lamé parameters, compliance."""

from __future__ import annotations

import ufl

__all__ = ["compliance", "lame_parameters", "symmetric_tensor"]


def symmetric_tensor(s: ufl.core.expr.Expr) -> ufl.core.expr.Expr:
    """(s0, s1, s2) ↦ [[s0, s1], [s1, s2]]."""
    return ufl.as_matrix([[s[0], s[1]], [s[1], s[2]]])


def lame_parameters(E: float | ufl.core.expr.Expr, nu: float | ufl.core.expr.Expr):
    """Plane-strain Lamé parameters λ = Eν/((1+ν)(1-2ν)), μ = E/(2(1+ν))."""
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


def compliance(sigma: ufl.core.expr.Expr, lmbda, mu) -> ufl.core.expr.Expr:
    """Plane-strain compliance Aσ = (σ - λ/(2λ+2μ) tr(σ) I) / (2μ)."""
    return (sigma - lmbda / (2 * lmbda + 2 * mu) * ufl.tr(sigma) * ufl.Identity(2)) / (2 * mu)
