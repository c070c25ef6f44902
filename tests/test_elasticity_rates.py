"""P1 linear elasticity on a manufactured solution: L² rate 2, H¹ rate 1."""

import numpy as np
import ufl
from mpi4py import MPI

from dolfinx import fem, mesh

from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.materials import lame, strain, stress
from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.problem.tags import Boundary


def _clamped_square(n: int):
    """Unit square, n×n cells, the whole boundary tagged Γ_D (u = 0)."""
    msh = mesh.create_unit_square(MPI.COMM_WORLD, n, n)
    tdim = msh.topology.dim
    msh.topology.create_connectivity(tdim - 1, tdim)
    facets = mesh.exterior_facet_indices(msh.topology)
    return msh, mesh.meshtags(msh, tdim - 1, facets, np.full(facets.size, Boundary.GAMMA_D, dtype=np.int32))


def _errors(n: int) -> tuple[float, float]:
    msh, tags = _clamped_square(n)
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


def _locking_errors(n: int, nu: float) -> float:
    """Relative L² error of P1 for u = curl ψ (divergence free), clamped, at Poisson ratio ν."""
    msh, tags = _clamped_square(n)
    x = ufl.SpatialCoordinate(msh)
    psi = (x[0] * (1 - x[0]) * x[1] * (1 - x[1])) ** 2
    u_exact = ufl.as_vector([psi.dx(1), -psi.dx(0)])
    lm, mu = (float(v) for v in lame(1.0, nu))
    f = -ufl.div(stress(strain(u_exact), lm, mu))
    fields = MaterialFields(None, None, fem.Constant(msh, lm), fem.Constant(msh, mu), f)
    problem = PrimalSubproblem(msh, tags, fields, delta=None, alpha=None, prefix=f"lock{n}_{nu}_")
    problem.solve()
    e = problem.u - u_exact
    err = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(e, e) * ufl.dx)), op=MPI.SUM)
    ref = msh.comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(u_exact, u_exact) * ufl.dx)), op=MPI.SUM)
    problem.destroy()
    return float(np.sqrt(err / ref))


def test_p1_locks_as_nu_approaches_one_half():
    """Primal P1 locks (the reason for the mixed Arnold–Winther method, which does not: test_arnold_winther)."""
    sizes = [8, 16, 32]
    compressible = np.array([_locking_errors(n, 0.3) for n in sizes])
    nearly = np.array([_locking_errors(n, 0.4999) for n in sizes])
    assert np.all(nearly > 5 * compressible), (compressible, nearly)  # far larger error at the same h
    assert np.all(nearly > 0.8), nearly  # measured 0.99, 0.97, 0.89: no useful accuracy on these meshes
    rate = np.log2(nearly[:-1] / nearly[1:])
    assert np.all(rate < 0.5), rate  # and no convergence to speak of (P1 in compressible case: rate 2)
