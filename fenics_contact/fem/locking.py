"""P1 locking as ν → ½: the measurement behind ``fem.primal.P1_LOCKING_NU``.

u = curl ψ, ψ = (x(1−x)y(1−y))², is divergence free; on the clamped unit square with the body force
it needs, ``p1_locking_error`` is the relative L² error of P1 at Poisson ratio ν, which grows without
bound as ν → ½ at fixed h (``benchmarks/analytic_benchmarks.py --sections 6``).
"""

import numpy as np
import ufl
from dolfinx import fem, mesh
from mpi4py import MPI

from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.materials import lame, strain, stress
from fenics_contact.problem.tags import Boundary

__all__ = ["clamped_square", "p1_locking_error"]


def clamped_square(n: int, comm=None):
    """Unit square, n×n cells (``comm``, default COMM_WORLD), the whole boundary tagged Γ_D (u = 0)."""
    msh = mesh.create_unit_square(MPI.COMM_WORLD if comm is None else comm, n, n)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = mesh.exterior_facet_indices(msh.topology)
    return msh, mesh.meshtags(msh, tdim - 1, facets, np.full(facets.size, Boundary.GAMMA_D, dtype=np.int32))


def p1_locking_error(n: int, nu: float, comm=None) -> float:
    """Relative L² error of P1 for u = curl ψ (divergence free) on the clamped square, h = 1/n, E = 1, ν."""
    msh, tags = clamped_square(n, comm)
    x = ufl.SpatialCoordinate(msh)
    psi = (x[0] * (1 - x[0]) * x[1] * (1 - x[1])) ** 2
    u_exact = ufl.as_vector([psi.dx(1), -psi.dx(0)])
    lm, mu = (float(v) for v in lame(1.0, nu))
    f = -ufl.div(stress(strain(u_exact), lm, mu))
    fields = MaterialFields(None, None, fem.Constant(msh, lm), fem.Constant(msh, mu), f)
    problem = PrimalSubproblem(msh, tags, fields, delta=None, alpha=None, prefix=f"lock{n}_{nu}_")
    try:
        problem.solve()
        e = problem.u - u_exact
        err = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx)), op=MPI.SUM)
        ref = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(u_exact, u_exact) * ufl.dx)), op=MPI.SUM)
    finally:
        problem.destroy()
    return float(np.sqrt(err / ref))
