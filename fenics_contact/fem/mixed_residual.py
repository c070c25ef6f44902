"""The residual of the mixed equations assembled from the UFL forms: a check independent of Q.

The Newton iteration works with the nodal matrix Q of σ_c (``mixed_contact``); this residual comes
from ``forms_mixed.mixed_residual`` with the Gauss–Lobatto contact measure instead, so a solution that
passes both checks satisfies the equations as the forms state them (the monolithic solve ends with it).  With
friction the law's term is ``forms_mixed.friction_term`` with the sticking target m_t + a as a DG P3 function
with its nodes at the Gauss–Lobatto points (``friction_target``).
"""

import basix
import basix.ufl
import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc
from scipy.spatial import cKDTree

from fenics_contact.fem import forms_mixed
from fenics_contact.fem.mixed_assembly import assemble_array
from fenics_contact.fem.mixed_traces import BoundaryFacets, gll_function
from fenics_contact.problem.tags import Boundary

__all__ = ["friction_target", "ufl_residual_norm"]


def friction_target(sub) -> fem.Function | None:
    """m_t + a of the friction law (``fem.mixed_friction``) as a DG P3 function with its nodes at the Gauss–Lobatto
    points: each Γ_C facet's cell takes the values of its contact nodes (a vertex node of two facets with different
    normals, one per cell).  None when one cell holds two such nodes at one vertex (no single value there)."""
    fr, nodes = sub.friction, sub.contact_nodes
    msh = sub.mesh
    el = basix.ufl.element("DG", msh.basix_cell(), 3, lagrange_variant=basix.LagrangeVariant.gll_warped)
    V = fem.functionspace(msh, el)
    target = fem.Function(V)
    values = fr.target()
    bf = BoundaryFacets(msh, sub.facet_tags.find(Boundary.GAMMA_C))
    pts, _, cells, normals, _ = bf.lobatto_nodes(sub.space.global_vertex_indices)
    scale = max(float(np.max(bf.length, initial=0.0)), 1e-300)
    # the canonical node of each facet's node: the same point and normal (the merge of ``merge_contact_nodes``)
    tree = cKDTree(np.hstack([nodes.q_points, scale * nodes.q_normals]))
    dist, node = tree.query(np.hstack([pts, scale * normals]))
    if np.any(dist > 1e-8 * scale):
        raise RuntimeError("a Gauss–Lobatto node of Γ_C is not a contact node")
    coords = V.tabulate_dof_coordinates()[:, :2]
    dofs = V.dofmap.list[cells]  # (N, 10)
    nearest = np.argmin(np.linalg.norm(coords[dofs] - pts[:, None, :], axis=2), axis=1)
    dof = dofs[np.arange(dofs.shape[0]), nearest]
    seen: dict[int, float] = {}
    for d, v in zip(dof.tolist(), values[node].tolist()):
        if seen.setdefault(d, v) != v:
            return None
    target.x.array[dof] = values[node]
    return target


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
    nodal_friction = False
    if sub.friction is not None:
        target = friction_target(sub)
        if target is None:  # a cell with two Γ_C edges meeting at an angle: the nodal term of the friction law
            nodal_friction = True
        else:
            fr = sub.friction
            law = (fr.law.law, fr.law.mu if fr.law.law == "coulomb" else fr.law.threshold)
            Ft += forms_mixed.friction_term(sig, t, n, target, law, 1.0 / fr.epsilon_t, ds_c(Boundary.GAMMA_C))
    r1 = sub.spaces.Pd.T @ assemble_array(Ft)[: sub.spaces.n_dg]
    if nodal_friction:
        r1 += sub.friction.force(sub.c) - sub.friction.load()
    if data is not None:
        r1 -= sub.interface.C @ data
    r2 = assemble_array(Fv)[: sub.n_u]
    _, scale = sub.residual(data)
    return sub.residual_norm(r1, r2), scale
