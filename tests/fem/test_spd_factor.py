"""MUMPS' Cholesky for symmetric positive definite operators (``DirectSolver(spd=True)``), as the frictionless
primal subproblems factorize their Jacobians: the same solutions as an LU, on half its factors; the option that
makes them factorize by LU (``-fc_spd_factor lu``); the sparse right-hand-side solve (``DirectSolver.solve_sparse``)
and the range check of a matrix's entries (``check_entries``)."""

import numpy as np
import pytest
import scipy.sparse as sp
from mpi4py import MPI
from petsc4py import PETSc

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.linalg import (
    SPD_FACTOR_OPTION,
    SPD_FACTORS,
    DirectSolver,
    check_entries,
    spd_factor,
)
from fenics_contact.fem.matrices import scipy_to_petsc
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


def _spd_matrix(n: int, seed: int) -> sp.csr_matrix:
    rng = np.random.default_rng(seed)
    lap = sp.diags([-np.ones(n - 1), 4.0 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    extra = sp.random(n, n, density=0.05, random_state=rng)
    return sp.csr_matrix(lap + 0.1 * (extra @ extra.T))


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a sequential factorization")
@pytest.mark.parametrize("spd", [True, False])
@pytest.mark.parametrize("scaled", [False, True])
def test_sparse_right_hand_side_solve_is_the_dense_solve(spd, scaled):
    """``DirectSolver.solve_sparse``: A⁻¹ b for a b that vanishes but at some rows (given unsorted) is the dense
    solve's, for Cholesky and LU and with an equilibrated operator (D A D given, the solution of A x = b)."""
    n = 80
    J = _spd_matrix(n, 7)
    d = 2.0 ** np.random.default_rng(1).integers(-3, 4, n) if scaled else None
    rows = np.array([57, 3, 41, 12])
    values = np.array([1.5, -2.0, 0.25, 3.0])
    b = np.zeros(n)
    b[rows] = values
    x_ref = np.linalg.solve(J.toarray(), b)
    solver = DirectSolver(MPI.COMM_SELF, prefix=f"test_sparse_rhs_{spd}_{scaled}_", spd=spd, scaling=d)
    A = scipy_to_petsc(J if d is None else sp.diags(d) @ J @ sp.diags(d))
    try:
        solver.set_operator(A)
        assert solver.sequential_mumps()
        x = solver.solve_sparse(rows, values)
    finally:
        for obj in (solver, A):
            obj.destroy()
    assert np.allclose(x, x_ref, rtol=1e-12, atol=1e-13 * np.abs(x_ref).max())


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a sequential matrix")
def test_spd_factor_option_factorizes_by_lu():
    """``-fc_spd_factor lu``: an operator given as SPD is factorized by LU, with the Cholesky's solution; another value
    is refused."""
    J = _spd_matrix(50, 5)
    b = np.arange(50.0)
    options = PETSc.Options()
    solutions = {}
    try:
        for factor in SPD_FACTORS:
            options[SPD_FACTOR_OPTION] = factor
            assert spd_factor() == factor
            solver = DirectSolver(MPI.COMM_SELF, prefix=f"test_spd_option_{factor}_", spd=True)
            A = scipy_to_petsc(J)
            rhs, x = A.createVecs()
            try:
                solver.set_operator(A)
                assert solver.ksp.getPC().getType() == factor and solver.spd == (factor == "cholesky")
                rhs.array[:] = b
                solver.solve(rhs, x)
                solutions[factor] = x.array.copy()
            finally:
                for obj in (solver, A, rhs, x):
                    obj.destroy()
        options[SPD_FACTOR_OPTION] = "qr"
        with pytest.raises(InputError, match="fc_spd_factor"):
            DirectSolver(MPI.COMM_SELF, prefix="test_spd_option_bad_", spd=True)
    finally:
        options.delValue(SPD_FACTOR_OPTION)
    assert spd_factor() == "cholesky"
    assert np.allclose(solutions["lu"], solutions["cholesky"], rtol=1e-12, atol=1e-14 * np.abs(solutions["lu"]).max())


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="a sequential matrix")
@pytest.mark.parametrize(
    "entries, words",
    [
        ([1.0, 2.0, 3.0, 4.0], None),
        ([1e150] * 4, None),  # Frobenius norm 2e150 above the range, every entry in it
        ([1e-149] * 4, None),
        ([1.0, np.nan, 3.0, 4.0], "non-finite values"),
        ([1.0, np.inf, 3.0, 4.0], "non-finite values"),
        ([1.0, 1e160, 3.0, 4.0], "entries up to 1e\\+160"),
        ([1e-160] * 4, "entries up to 1e-160"),
    ],
)
def test_check_entries_takes_the_entries_in_range_only(entries, words):
    """``check_entries``: a matrix passes when its entries are finite and the largest lies in ``SAFE_RANGE``, whatever
    its Frobenius norm (the quick test); otherwise the error names what is wrong."""
    A = scipy_to_petsc(sp.diags(entries).tocsr())
    try:
        if words is None:
            check_entries(A, "test")
        else:
            with pytest.raises(InputError, match=words):
                check_entries(A, "test")
    finally:
        A.destroy()
