"""The residual of the mixed equations assembled from the UFL forms: a check independent of Q.

The Newton iteration works with the nodal matrix Q of σ_c (``mixed_contact``); this residual comes
from ``forms_mixed.mixed_residual`` with the Gauss–Lobatto contact measure instead, so a solution that
passes both checks satisfies the equations as the forms state them (the monolithic solve ends with it).
"""

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from fenics_contact.fem import forms_mixed
from fenics_contact.fem.mixed_assembly import assemble_array
from fenics_contact.fem.mixed_traces import gll_function
from fenics_contact.problem.tags import Boundary

__all__ = ["ufl_residual_norm"]


def ufl_residual_norm(sub, data: np.ndarray | None = None) -> tuple[float, float]:
    """‖D F‖ of the residual of the ``MixedSubproblem`` ``sub`` at its current (σ, u) with Robin data g, assembled
    from ``forms_mixed.mixed_residual`` (independent of Q) and equilibrated like ``sub.residual``
    (``sub.residual_norm``), and the scale of ``sub.residual``."""
    msh = sub.mesh
    sig, uh = sub.sigma_function(), sub.u_function()
    t, v = ufl.TestFunction(sub.dg), ufl.TestFunction(sub.U)
    n = ufl.FacetNormal(msh)
    ds = forms_mixed.boundary_measure(msh, sub.facet_tags)
    contact = robin = None
    if sub.contact:
        ds_c = forms_mixed.contact_measure(msh, sub.facet_tags)
        contact = (fem.Constant(msh, PETSc.ScalarType(1.0 / sub.epsilon)), ds_c(Boundary.GAMMA_C))
    if sub.beta is not None:  # the data term is applied below as C g
        robin = (fem.Constant(msh, PETSc.ScalarType(sub.beta)), None, ds(Boundary.INTERFACE))
    Ft, Fv = forms_mixed.mixed_residual(
        sig, uh, t, v, lmbda=sub.fields.lmbda, mu=sub.fields.mu, f=sub.fields.f, n=n, contact=contact, robin=robin
    )
    natural = []  # ∫_ΓD u_D·τn and ∫_ΓC g τ_c (g as a P3 function with its nodes at the Gauss–Lobatto points)
    if sub.u_D is not None:
        natural.append(forms_mixed.robin_data_form(sub.u_D, t, n, ds(Boundary.GAMMA_D)))
    if sub.contact and sub.obstacle is not None:
        gap = gll_function(msh, sub.obstacle.gap)
        natural.append(forms_mixed.gap_form(gap, t, n, ds_c(Boundary.GAMMA_C)))
    for form in natural:
        Ft -= form
    r1 = sub.spaces.Pd.T @ assemble_array(Ft)[: sub.spaces.n_dg]
    if sub.friction is not None:  # the friction law's term, nodal at the same Gauss–Lobatto points
        r1 += sub.friction.force(sub.c) - sub.friction.load()
    if data is not None:
        r1 -= sub.interface.C @ data
    r2 = assemble_array(Fv)[: sub.n_u]
    _, scale = sub.residual(data)
    return sub.residual_norm(r1, r2), scale
