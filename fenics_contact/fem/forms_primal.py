"""Pure UFL forms of the penalized primal contact problem and its Robin subproblems.

    a(u, v) = ∫ σ(u) : ε(v) dx
    F(u; v) = a(u, v) + (1/δ) ∫_ΓC (u·ν − g_c)⁺ v·ν ds + α ∫_γ u·v ds − (f, v) − Σ_k ∫_ΓN,k t_k·v ds − ∫_γ g·v ds

ν is the contact direction (the obstacle's, or the body's nodal normal for a
wall flush with Γ_C) and g_c the initial gap, both nodal P1 functions on Γ_C.

Boundary integrals use nodal ("vertex") quadrature: ∫ w·v ds ≈ Σ_p w_p w(p)·v(p),
which makes the contact nonlinearity and the Robin transmission nodal (the docs' theory page).
"""

import ufl

from fenics_contact.problem.materials import strain, stress

__all__ = [
    "vertex_measure",
    "positive_part",
    "heaviside",
    "elastic_form",
    "mass_form",
    "contact_residual",
    "contact_jacobian",
    "nodal_indicator",
    "gap_function",
    "traction_form",
]

#: Form-compiler metadata for nodal (vertex) quadrature.
VERTEX_QUADRATURE = {"quadrature_rule": "vertex", "quadrature_degree": 1}


def vertex_measure(mesh, facet_tags) -> ufl.Measure:
    """Exterior-facet measure with vertex quadrature over tagged facets."""
    return ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags, metadata=VERTEX_QUADRATURE)


def positive_part(s):
    """(s)⁺ = max(s, 0)."""
    return ufl.conditional(ufl.gt(s, 0.0), s, 0.0)


def heaviside(s):
    """H(s) = 1 if s > 0 else 0: the generalized derivative of s ↦ (s)⁺ used by semismooth Newton."""
    return ufl.conditional(ufl.gt(s, 0.0), 1.0, 0.0)


def elastic_form(u, v, lmbda, mu):
    """a(u, v) = ∫ σ(u) : ε(v) dx."""
    return ufl.inner(stress(strain(u), lmbda, mu), strain(v)) * ufl.dx


def mass_form(u, v):
    """(u, v) over the whole mesh."""
    return ufl.inner(u, v) * ufl.dx


def _scaled(alpha, u):
    """α u for a scalar α, or componentwise for a vector of nodal coefficients."""
    return ufl.elem_mult(alpha, u) if alpha.ufl_shape else alpha * u


def gap_function(u, nu, gap=None):
    """u·ν − g: the normal displacement relative to the obstacle (> 0: penetration)."""
    s = ufl.dot(u, nu)
    return s if gap is None else s - gap


def _penalty_parts(penalty):
    """(1/δ, ν, g) from a penalty tuple (1/δ, ν) or (1/δ, ν, g)."""
    inv_delta, nu, *rest = penalty
    return inv_delta, nu, (rest[0] if rest else None)


def traction_form(tractions, v):
    """Σ_k ∫_ΓN,k t_k·v ds for pairs (t_k, ds_k)."""
    forms = [ufl.inner(t, v) * ds_k for t, ds_k in tractions]
    return sum(forms[1:], forms[0]) if forms else None


def contact_residual(u, v, *, lmbda, mu, f, penalty=None, ds_contact=None, robin=None, tractions=()):
    """F(u; v) with optional penalty contact ((1/δ), ν[, g]), Robin ((α, g, ds)) and traction ((t, ds), ...) terms."""
    F = elastic_form(u, v, lmbda, mu) - ufl.inner(f, v) * ufl.dx
    if penalty is not None:
        inv_delta, nu, gap = _penalty_parts(penalty)
        F += inv_delta * positive_part(gap_function(u, nu, gap)) * ufl.dot(v, nu) * ds_contact
    if robin is not None:
        alpha, g, ds_gamma = robin
        F += ufl.inner(_scaled(alpha, u), v) * ds_gamma - ufl.inner(g, v) * ds_gamma
    if tractions:
        F -= traction_form(tractions, v)
    return F


def contact_jacobian(u, du, v, *, lmbda, mu, penalty=None, ds_contact=None, robin=None):
    """The exact generalized Jacobian of ``contact_residual`` (Heaviside for (·)⁺)."""
    J = elastic_form(du, v, lmbda, mu)
    if penalty is not None:
        inv_delta, nu, gap = _penalty_parts(penalty)
        J += inv_delta * heaviside(gap_function(u, nu, gap)) * ufl.dot(du, nu) * ufl.dot(v, nu) * ds_contact
    if robin is not None:
        alpha, _, ds_gamma = robin
        J += ufl.inner(_scaled(alpha, du), v) * ds_gamma
    return J


def nodal_indicator(s, q, ds):
    """∫ H(s) q ds with vertex quadrature: positive exactly at the nodes where s > 0."""
    return heaviside(s) * q * ds
