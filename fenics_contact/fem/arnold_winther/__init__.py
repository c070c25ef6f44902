"""Lowest-order conforming Arnold–Winther stress space on triangles for DOLFINx.

The Arnold–Winther (AW) element [Arnold & Winther 2002] is the space of symmetric
2x2 tensors that are cubic on each triangle and whose divergence is linear,

    X_T = {σ ∈ P3(T; S) : div σ ∈ P1(T; R²)},   dim X_T = 24,

glued together so that the normal traction σn is continuous across edges
(H(div)-conforming, strongly symmetric).  Its 24 local degrees of freedom are

* at each vertex the three Cartesian components σ_xx, σ_xy, σ_yy (9),
* on each edge e the averages (1/|e|)∫_e σn·n q ds and (1/|e|)∫_e σn·t q ds
  for q ∈ {1, 2s-1}, s ∈ [0, 1] the arc-length parameter of e from its lower to
  its higher *global* vertex number, t the unit tangent in that direction and
  n = (t_y, -t_x) (12),
* the three cell averages (1/|T|)∫_T σ_ij dx (3).

Edge moments are normalised by |e| (they are averages) so that every DOF has
the size of a stress value; this keeps the local 24x24 systems well conditioned.

basix does not ship the element (it is not affine-equivalent), so forms are
written on a discontinuous vector P3 space ``dg`` holding (σ_xx, σ_xy, σ_yy),
and a sparse *prolongation* matrix ``P`` maps AW coefficients to DG
coefficients.  For every cell the local nodal basis is computed in physical
coordinates from a spanning set in scaled coordinates ξ = (x - x_T)/h_T:
18 symmetric P2 tensors plus the 6 Airy stresses curl curl(ξ^a η^b), a+b = 5
(homogeneous cubic, divergence-free), which together span exactly X_T.  The
AW matrices are then Pᵀ A P, B P, Pᵀ b.

Essential conditions σn·t = 0 and σn = 0 on straight facets are imposed by
removing columns of ``P`` (edge moments dropped; vertex values restricted to
the null space of the vertex constraints, which also handles corners).  A
prescribed traction σn = t on some of the σn = 0 facets is a *lifting*: a
fixed stress σ_t (``lifting_dg``) whose edge moments are those of t and whose
vertex values solve the stacked vertex constraints with right-hand side t
(least squares where the data of two edges meeting at a corner disagree), so
that the stress is σ = P c + σ_t with c free.

Serial and distributed meshes (any number of MPI ranks) of affine triangles are
supported: the numbering, constraints and P are built as described in
:class:`ArnoldWintherSpace`; the operators are distributed PETSc matrices.

Modules: ``functionals`` (the DOFs, their quadrature, the interpolant), ``local_basis`` (the nodal basis
per cell), ``shared_basis`` (the nodal bases of a replicated mesh shared out over MPI), ``topology`` (the
mesh entities and their orientation), ``constraints`` (essential conditions, traction lifting, split
interface), ``numbering`` (global DOF numbers), ``prolongation`` (P from the cell blocks), ``space`` (the
space), ``tensors`` (UFL helpers), ``solve`` (Hellinger–Reissner elasticity without contact).
"""

from fenics_contact.fem.arnold_winther.local_basis import NODAL_BASIS_BATCH, local_nodal_basis
from fenics_contact.fem.arnold_winther.shared_basis import shared_nodal_basis
from fenics_contact.fem.arnold_winther.solve import (
    MixedElasticitySolution,
    solve_mixed_elasticity,
    solve_saddle_point,
)
from fenics_contact.fem.arnold_winther.space import ArnoldWintherSpace
from fenics_contact.fem.arnold_winther.tensors import compliance, lame_parameters, symmetric_tensor

__all__ = [
    "ArnoldWintherSpace",
    "MixedElasticitySolution",
    "NODAL_BASIS_BATCH",
    "compliance",
    "lame_parameters",
    "local_nodal_basis",
    "shared_nodal_basis",
    "solve_mixed_elasticity",
    "solve_saddle_point",
    "symmetric_tensor",
]
