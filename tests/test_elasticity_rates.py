"""P1 linear elasticity on a manufactured solution: L² rate 2, H¹ rate 1."""

import numpy as np
import ufl
from mpi4py import MPI

from dolfinx import fem, mesh

from fenics_contact.fields import MaterialFields
from fenics_contact.materials import lame, strain, stress
from fenics_contact.primal import PrimalSubproblem
from fenics_contact.tags import Boundary


def _errors(n: int) -> tuple[float, float]:
    msh = mesh.create_unit_square(MPI.COMM_WORLD, n, n)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = mesh.exterior_facet_indices(msh.topology)
    tags = mesh.meshtags(msh, tdim - 1, facets, np.full(facets.size, Boundary.GAMMA_D, dtype=np.int32))
    x = ufl.SpatialCoordinate(msh)
    u_exact = ufl.as_vector([ufl.sin(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]), 4 * x[0] * (1 - x[0]) * x[1] * (1 - x[1])])
    lm, mu = (float(v) for v in lame(1.0, 0.3))
    f = -ufl.div(stress(strain(u_exact), lm, mu))
    fields = MaterialFields(None, None, fem.Constant(msh, lm), fem.Constant(msh, mu), f)
    problem = PrimalSubproblem(msh, tags, fields, delta=None, alpha=None, prefix=f"mms{n}_")
    problem.solve()
    e = problem.u - u_exact
    l2 = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx)), op=MPI.SUM)
    h1 = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(ufl.grad(e), ufl.grad(e)) * ufl.dx)), op=MPI.SUM)
    problem.destroy()
    return np.sqrt(l2), np.sqrt(h1)


def test_p1_convergence_rates():
    sizes = [8, 16, 32]
    errors = np.array([_errors(n) for n in sizes])
    rates = np.log2(errors[:-1] / errors[1:])
    rate_l2, rate_h1 = 2.0, 1.0
    assert np.all(rates[:, 0] > 0.95 * rate_l2), rates
    assert np.all(rates[:, 1] > 0.95 * rate_h1), rates
    assert np.all(rates[:, 0] < 1.1 * rate_l2) and np.all(rates[:, 1] < 1.15 * rate_h1), rates
