"""MUMPS' Cholesky for symmetric positive definite operators (``DirectSolver(spd=True)``), as the frictionless
primal subproblems factorize their Jacobians: the same solutions as an LU, on half its factors."""

import numpy as np
import pytest
import scipy.sparse as sp
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.fem.linalg import DirectSolver, scipy_to_petsc
from fenics_contact.problem.models import get_model


def _factor_entries(solver: DirectSolver) -> int:
    return solver.ksp.getPC().getFactorMatrix().getMumpsInfog(29)  # INFOG(29): entries in the factors


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a sequential matrix")
def test_spd_solver_is_a_cholesky_with_the_lu_solution():
    rng = np.random.default_rng(3)
    n = 60
    lap = sp.diags([-np.ones(n - 1), 4.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    extra = sp.random(n, n, density=0.05, random_state=rng)
    J = sp.csr_matrix(lap + 0.1 * (extra @ extra.T))  # symmetric, diagonally dominant: SPD
    b = rng.standard_normal(n)
    x_ref = np.linalg.solve(J.toarray(), b)
    solutions, entries = {}, {}
    for spd in (False, True):
        solver = DirectSolver(MPI.COMM_SELF, prefix=f"test_spd_{spd}_", spd=spd)
        A = scipy_to_petsc(J)
        rhs, x = A.createVecs()
        try:
            solver.set_operator(A)
            assert solver.ksp.getPC().getType() == ("cholesky" if spd else "lu")
            rhs.array[:] = b
            solver.solve(rhs, x)
            solutions[spd], entries[spd] = x.array.copy(), _factor_entries(solver)
        finally:
            for obj in (solver, A, rhs, x):
                obj.destroy()
    for x in solutions.values():
        assert np.allclose(x, x_ref, rtol=1e-12, atol=1e-12 * np.abs(x_ref).max())
    assert entries[True] < entries[False]  # one triangle of factors against two


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a sequential matrix")
def test_spd_solver_falls_back_to_lu_where_the_cholesky_fails():
    """A zero pivot (a matrix not positive definite in floating point): the LU takes over, with its solution."""
    J = sp.csr_matrix(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 2.0]]))
    solver = DirectSolver(MPI.COMM_SELF, prefix="test_spd_fallback_", spd=True)
    A = scipy_to_petsc(J)
    rhs, x = A.createVecs()
    try:
        solver.set_operator(A)
        assert not solver.spd and solver.ksp.getPC().getType() == "lu"
        rhs.array[:] = [1.0, 2.0, 4.0]
        solver.solve(rhs, x)
        assert np.allclose(x.array, [2.0, 1.0, 2.0], rtol=1e-14)
    finally:
        for obj in (solver, A, rhs, x):
            obj.destroy()


def test_frictionless_monolithic_newton_factorizes_by_cholesky_with_the_lu_answer():
    """The monolithic Newton's Jacobian (stiffness + penalty on the active set, identity on Γ_D) is SPD: its
    Cholesky gives the LU's solution, active set and Newton steps."""
    problem = get_model(3, E_high=1e3).with_(obstacle=fc.Circle((3.0, 0.5), 2.0).indented(0.01, (-1.0, 0.0)))
    problem = problem.on(fc.unit_square(16, 4))
    chol = fc.solve(problem, "primal-monolithic")
    sub = chol.problem
    assert sub.solver.spd and sub.solver.ksp.getPC().getType() == "cholesky"
    u_chol = sub.u.x.array.copy()
    sub.solver.destroy()
    sub.solver = DirectSolver(problem.comm, prefix="test_spd_monolithic_lu_")
    sub.reset()
    history = sub.solve()
    assert history.steps == chol.newton.steps
    assert np.array_equal(sub.contact_profile().active, chol.profile.active)
    scale = problem.comm.allreduce(np.abs(u_chol).max(), op=MPI.MAX)
    assert problem.comm.allreduce(np.abs(sub.u.x.array - u_chol).max(), op=MPI.MAX) <= 1e-10 * scale
