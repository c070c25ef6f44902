"""Pure UFL forms of the mixed (Hellinger–Reissner) penalized contact problem and its Robin subproblems.

Stresses are written on the discontinuous P3 space of the three components
s = (σ_xx, σ_xy, σ_yy) (``ArnoldWintherSpace.dg``); S = [[s0, s1], [s1, s2]].
Displacements are discontinuous vector P1.  With n the outward unit normal,
σ_c = n·Sn the normal stress on Γ_C and (s)⁺ = max(s, 0):

    a(σ, τ)        = (Aσ, τ)                                  compliance
    b(τ, v)        = (div τ, v)                               divergence
    ℓ(v)           = −(f, v)                                  load: (div σ, v) = −(f, v)
    p_ε(σ; τ)      = (1/ε) ∫_ΓC (σ_c)⁺ τ_c ds                 mixed contact penalty
    r_β(σ, τ)      = β ∫_γ (σn)·(τn) ds                        Robin term on γ
    d(g; τ)        = ∫_γ g·(τn) ds                             Robin data on γ
    f_t(σ; τ)      = ∫_ΓC [(σ_t − Π_τ σ_t)/ε_t − (m_t + a)] τ_t ds   friction (σ_t = t·σn, t = (−n_y, n_x))
    J(σ)           = ½(Aσ, σ) + (1/2ε) ∫_ΓC ((σ_c)⁺)² ds       complementary energy

Quadrature on boundaries (the normal trace of an Arnold–Winther stress is a
cubic on each edge, continuous at vertices):

* γ terms (``boundary_measure``): Gauss, degree ``BOUNDARY_QUADRATURE_DEGREE``
  = 6 (4 Gauss–Legendre points per edge), exact for the degree-6 Robin terms.
* Γ_C penalty (``contact_measure``): 4-point Gauss–Lobatto per edge (degree 5).
  Its 3 per edge + shared vertices are exactly the 3n+1 nodes of a Lagrange
  basis of the σ_c trace space (continuous P3 on Γ_C), so the penalty acts on
  nodal values of σ_c with a diagonal weight — the mixed analogue of the
  primal method's vertex quadrature.  Semismooth Newton with it behaves like
  the primal nodal one; with Gauss points (more points than trace DOFs) it
  wandered without converging.
"""

import ufl

from fenics_contact.problem.materials import compliance

__all__ = [
    "BOUNDARY_QUADRATURE_DEGREE",
    "CONTACT_QUADRATURE",
    "boundary_measure",
    "contact_measure",
    "stress_tensor",
    "normal_stress",
    "positive_part",
    "heaviside",
    "compliance_form",
    "divergence_form",
    "load_form",
    "mass_form",
    "contact_penalty",
    "contact_penalty_jacobian",
    "complementary_energy",
    "robin_form",
    "robin_data_form",
    "gap_form",
    "tangential_stress",
    "friction_term",
    "mixed_residual",
]

#: Gauss quadrature degree of the γ integrals (exact for P3·P3 traces).
BOUNDARY_QUADRATURE_DEGREE = 6
#: Form-compiler metadata of the nodal contact quadrature: 4 Gauss–Lobatto points per edge.
CONTACT_QUADRATURE = {"quadrature_rule": "GLL", "quadrature_degree": 5}


def boundary_measure(mesh, facet_tags, degree: int = BOUNDARY_QUADRATURE_DEGREE) -> ufl.Measure:
    """Exterior-facet measure over tagged facets with Gauss quadrature of the given degree."""
    return ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags, metadata={"quadrature_degree": degree})


def contact_measure(mesh, facet_tags) -> ufl.Measure:
    """Exterior-facet measure with the nodal (4-point Gauss–Lobatto) contact quadrature."""
    return ufl.Measure("ds", domain=mesh, subdomain_data=facet_tags, metadata=CONTACT_QUADRATURE)


def stress_tensor(s):
    """(s0, s1, s2) ↦ [[s0, s1], [s1, s2]]."""
    return ufl.as_matrix([[s[0], s[1]], [s[1], s[2]]])


def normal_stress(s, n):
    """σ_c = n·σn of the components s = (σ_xx, σ_xy, σ_yy)."""
    return ufl.dot(n, ufl.dot(stress_tensor(s), n))


def positive_part(x):
    """(x)⁺ = max(x, 0)."""
    return ufl.conditional(ufl.gt(x, 0.0), x, 0.0)


def heaviside(x):
    """H(x) = 1 if x > 0 else 0, the generalized derivative of (x)⁺."""
    return ufl.conditional(ufl.gt(x, 0.0), 1.0, 0.0)


def compliance_form(s, t, lmbda, mu):
    """a(σ, τ) = (Aσ, τ), A the plane-strain compliance."""
    return ufl.inner(compliance(stress_tensor(s), lmbda, mu), stress_tensor(t)) * ufl.dx


def divergence_form(s, v):
    """b(σ, v) = (div σ, v)."""
    return ufl.inner(ufl.div(stress_tensor(s)), v) * ufl.dx


def load_form(f, v):
    """ℓ(v) = −(f, v): the right-hand side of (div σ, v) = −(f, v)."""
    return -ufl.inner(f, v) * ufl.dx


def mass_form(u, v):
    """(u, v): the L² inner product of displacements."""
    return ufl.inner(u, v) * ufl.dx


def contact_penalty(s, t, n, inv_epsilon, ds_contact):
    """p_ε(σ; τ) = (1/ε) ∫_ΓC (σ_c)⁺ τ_c ds (penalizes tensile contact stress)."""
    return inv_epsilon * positive_part(normal_stress(s, n)) * normal_stress(t, n) * ds_contact


def contact_penalty_jacobian(s, ds_, t, n, inv_epsilon, ds_contact):
    """Generalized derivative of ``contact_penalty`` at σ in direction dσ: (1/ε) ∫ H(σ_c) dσ_c τ_c ds."""
    return inv_epsilon * heaviside(normal_stress(s, n)) * normal_stress(ds_, n) * normal_stress(t, n) * ds_contact


def complementary_energy(s, lmbda, mu, n, inv_epsilon, ds_contact):
    """J(σ) = ½(Aσ, σ) + (1/2ε) ∫_ΓC ((σ_c)⁺)² ds."""
    S = stress_tensor(s)
    return (
        0.5 * ufl.inner(compliance(S, lmbda, mu), S) * ufl.dx
        + 0.5 * inv_epsilon * positive_part(normal_stress(s, n)) ** 2 * ds_contact
    )


def robin_form(s, t, n, beta, ds_gamma):
    """r_β(σ, τ) = β ∫_γ (σn)·(τn) ds."""
    return beta * ufl.inner(ufl.dot(stress_tensor(s), n), ufl.dot(stress_tensor(t), n)) * ds_gamma


def robin_data_form(g, t, n, ds_gamma):
    """d(g; τ) = ∫_γ g·(τn) ds (g a vector function on γ, or a trial function)."""
    return ufl.inner(g, ufl.dot(stress_tensor(t), n)) * ds_gamma


def gap_form(g, t, n, ds_contact):
    """∫_ΓC g τ_c ds: the obstacle's gap in the natural boundary term (F_τ gets −∫ g τ_c)."""
    return g * normal_stress(t, n) * ds_contact


def tangential_stress(s, n):
    """σ_t = t·σn, t = (−n_y, n_x)."""
    return ufl.dot(ufl.as_vector((-n[1], n[0])), ufl.dot(stress_tensor(s), n))


def friction_term(s, t, n, target, law, inv_epsilon_t, ds_contact):
    """The friction law's natural term ∫_ΓC [(σ_t − Π_τ σ_t)/ε_t − (m_t + a)] τ_t ds (``fem.mixed_friction``):
    ``target`` = m_t + a, ``law`` = ("coulomb", μ) (τ = μ(−σ_c)⁺) or ("tresca", s) (τ = s)."""
    name, value = law
    tau = value * positive_part(-normal_stress(s, n)) if name == "coulomb" else value
    s_t = tangential_stress(s, n)
    excess = s_t - ufl.max_value(-tau, ufl.min_value(tau, s_t))
    return (inv_epsilon_t * excess - target) * tangential_stress(t, n) * ds_contact


def mixed_residual(s, u, t, v, *, lmbda, mu, f, n, contact=None, robin=None):
    """Residual of the mixed problem as the pair of forms (F_τ, F_v) in the test functions τ and v.

        F_τ = (Aσ, τ) + (div τ, u) [+ p_ε(σ; τ)] [+ r_β(σ, τ) − d(g; τ)],   F_v = (div σ, v) + (f, v)

    ``fem.contact`` = (1/ε, ds_C), ``robin`` = (β, g, ds_γ) with g possibly None; both optional.
    """
    F = compliance_form(s, t, lmbda, mu) + ufl.inner(ufl.div(stress_tensor(t)), u) * ufl.dx
    if contact is not None:
        inv_epsilon, ds_contact = contact
        F += contact_penalty(s, t, n, inv_epsilon, ds_contact)
    if robin is not None:
        beta, g, ds_gamma = robin
        F += robin_form(s, t, n, beta, ds_gamma)
        if g is not None:
            F -= robin_data_form(g, t, n, ds_gamma)
    return F, divergence_form(s, v) - load_form(f, v)
