"""P1 linear elasticity on a manufactured solution: L² rate 2, H¹ rate 1."""

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.fem.locking import clamped_square, p1_locking_error
from fenics_contact.fem.primal import PrimalSubproblem
from fenics_contact.problem.fields import MaterialFields
from fenics_contact.problem.materials import lame, strain, stress


def _errors(n: int) -> tuple[float, float]:
    msh, tags = clamped_square(n)
    x = ufl.SpatialCoordinate(msh)
    u_exact = ufl.as_vector(
        [ufl.sin(ufl.pi * x[0]) * ufl.sin(ufl.pi * x[1]), 4 * x[0] * (1 - x[0]) * x[1] * (1 - x[1])]
    )
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


def test_p1_locks_as_nu_approaches_one_half():
    """Primal P1 locks (the reason for the mixed Arnold–Winther method, which does not: test_arnold_winther)."""
    sizes = [8, 16, 32]
    compressible = np.array([p1_locking_error(n, 0.3) for n in sizes])
    nearly = np.array([p1_locking_error(n, 0.4999) for n in sizes])
    assert np.all(nearly > 5 * compressible), (compressible, nearly)  # far larger error at the same h
    assert np.all(nearly > 0.8), nearly  # measured 0.99, 0.97, 0.89: no useful accuracy on these meshes
    rate = np.log2(nearly[:-1] / nearly[1:])
    assert np.all(rate < 0.5), rate  # and no convergence to speak of (P1 in compressible case: rate 2)


def test_primal_methods_warn_when_p1_locks(caplog):
    """ν ≥ P1_LOCKING_NU: the monolithic primal solve and Algorithm 1 warn (once per mesh); the test above
    shows why."""
    from fenics_contact.fem.primal import P1_LOCKING_NU, default_penalty, solve_primal_monolithic
    from fenics_contact.hybrid.iteration import IterationOptions
    from fenics_contact.hybrid.primal import solve_primal_hybrid
    from fenics_contact.problem import geometry, models

    assert p1_locking_error(16, P1_LOCKING_NU) > 5 * p1_locking_error(16, 0.3)  # 0.31 against 0.051
    for nu, warned in ((0.35, False), (P1_LOCKING_NU, True)):
        cm = geometry.unit_square(16, 4)
        caplog.clear()
        problem = models.get_model(1, nu=nu).on(cm)
        solve_primal_monolithic(problem, delta=default_penalty(cm.h, 1.0)).problem.destroy()
        assert caplog.text.count("P1 displacement elements lock") == int(warned), nu
        # Algorithm 1 on the same mesh: not warned twice; on a new mesh it warns itself
        solve_primal_hybrid(problem, delta=default_penalty(cm.h, 1.0), options=IterationOptions(tol=1e-3))
        assert caplog.text.count("P1 displacement elements lock") == int(warned), nu
        caplog.clear()
        other = geometry.unit_square(16, 4)
        solve_primal_hybrid(
            models.get_model(1, nu=nu).on(other),
            delta=default_penalty(other.h, 1.0),
            options=IterationOptions(tol=1e-3),
        )
        assert caplog.text.count("P1 displacement elements lock") == int(warned), nu
