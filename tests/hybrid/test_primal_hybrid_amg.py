"""Algorithm 1 with Ω₁ solved by CG + AMG: the matrix-free interface Newton (Newton–GMRES) lands on the monolithic
solution to the Krylov tolerance, with one AMG set-up for every iteration and load step, and a Krylov solve that
fails says so."""

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact as fc
from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.amg import AUTO_AMG_DOFS, AMGSolver, LinearSolverOptions
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.hybrid.primal import OMEGA1_AUTO_AMG_DOFS, omega1_solver
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh

#: the CG tolerance of the AMG Ω₁ here, and the distance to the monolithic solution it allows (measured 2e-11)
RTOL, AGREEMENT = 1e-10, 1e-7
AMG = LinearSolverOptions(kind="amg", rtol=RTOL)


@pytest.mark.parametrize("contrast", [1e3, pytest.param(1e6, marks=pytest.mark.slow)])
def test_algorithm_1_with_an_amg_omega1_is_the_monolithic_and_the_direct_solution(contrast):
    """The 3D channel cube (h = 1/8): the AMG path's pair is glued (certificate below tol), its displacement is the
    monolithic one and the direct Algorithm 1's to AGREEMENT, with the same active set; one AMG set-up."""
    problem = channels_3d(E_high=contrast).on(channels_3d_mesh(8))
    ref = fc.solve(problem, "primal-monolithic", solver="direct")
    amg = fc.solve(problem, "primal", reference=ref.u, tol=1e-9, solver=AMG)
    direct = fc.solve(problem, "primal", reference=ref.u, tol=1e-9, solver="direct")
    assert isinstance(amg.step.sub[0].solver, AMGSolver) and isinstance(direct.step.sub[0].solver, DirectSolver)
    assert amg.converged and amg.history.transmission_residual < 1e-9
    assert amg.history.newton_steps <= 8
    assert amg.e_u <= AGREEMENT
    gap = amg.u.x.array - direct.u.x.array
    assert np.linalg.norm(gap) <= AGREEMENT * np.linalg.norm(direct.u.x.array)
    np.testing.assert_array_equal(amg.profile.active, ref.profile.active)
    assert amg.profile.force == pytest.approx(ref.profile.force, rel=AGREEMENT)
    solver = amg.step.sub[0].solver
    assert solver.factorizations == 1 and len(solver.iterations) > amg.iterations  # set up once, many solves


def test_one_amg_set_up_serves_every_solve_of_a_step_and_anderson_too():
    """One step solved again (a load step reusing its offline data) by the Newton–GMRES interface Newton and by
    Anderson: each lands on the monolithic solution, and Ω₁'s AMG is set up once for all of them."""
    problem = channels_3d(E_high=1e2).on(channels_3d_mesh(6))
    ref = fc.solve(problem, "primal-monolithic", solver="direct")
    step = None
    for accel in ("newton", "newton", "anderson"):
        result = fc.solve(problem, "primal", reference=ref.u, tol=1e-8, solver=AMG, accel=accel, step=step)
        assert result.converged and result.e_u <= AGREEMENT, (accel, result.e_u)
        step = result.step
        step.reset()
    assert step.sub[0].solver.factorizations == 1


def test_an_amg_omega1_that_does_not_converge_raises_a_clear_error():
    """A CG iteration cap far too small for Ω₁: ConvergenceError naming the solver, the reason and what to do."""
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(6))
    capped = LinearSolverOptions(kind="amg", rtol=1e-12, max_iterations=2)
    with pytest.raises(ConvergenceError, match="fc_primal_omega1_.*did not converge.*solver='direct'"):
        fc.solve(problem, "primal", solver=capped)


def _amg_numbers(comm) -> dict:
    """Algorithm 1 with an AMG Ω₁ on ``comm``: u ordered by its node coordinates, and the run's numbers."""
    problem = channels_3d(E_high=1e2).on(channels_3d_mesh(6, comm=comm))
    ref = fc.solve(problem, "primal-monolithic", solver="direct")
    result = fc.solve(problem, "primal", reference=ref.u, tol=1e-9, solver=AMG)
    V = result.u.function_space
    owned = V.dofmap.index_map.size_local
    x = np.concatenate(comm.allgather(V.tabulate_dof_coordinates()[:owned]))
    u = np.concatenate(comm.allgather(result.u.x.array.reshape(-1, 3)[:owned]))
    preconditioned = result.step.krylov_interface().preconditioner is not None
    numbers = {"u": u[np.lexsort(np.round(x, 12).T)], "converged": result.converged, "e_u": result.e_u}
    numbers["preconditioned"] = preconditioned
    return on_every_rank(numbers, comm=MPI.COMM_WORLD)


@pytest.mark.mpi(sizes=(2,))
def test_algorithm_1_with_an_amg_omega1_on_two_ranks_is_the_serial_answer():
    """The same solve on COMM_SELF and on two ranks (the AMG aggregates differ with the partition): both glued and
    on the monolithic solution, node by node equal to the Krylov tolerance's AGREEMENT; the GMRES preconditioned on
    one process (``hybrid.krylov_band``), unpreconditioned on two."""
    serial, parallel = _amg_numbers(MPI.COMM_SELF), _amg_numbers(MPI.COMM_WORLD)
    assert serial["preconditioned"] and not parallel["preconditioned"]
    for run in (serial, parallel):
        assert run["converged"] and run["e_u"] <= AGREEMENT
    assert np.abs(parallel["u"] - serial["u"]).max() <= AGREEMENT * np.abs(serial["u"]).max()


def test_auto_takes_amg_in_omega1_only_where_mumps_runs_out_of_memory():
    """``solver="auto"`` in Algorithm 1: MUMPS up to ``OMEGA1_AUTO_AMG_DOFS`` Ω₁ unknowns in 3D (above the
    monolithic threshold), AMG from there; given options keep their own threshold; the plane stays direct."""
    auto = omega1_solver("auto")
    assert OMEGA1_AUTO_AMG_DOFS > AUTO_AMG_DOFS
    assert auto.chosen(OMEGA1_AUTO_AMG_DOFS - 1, 3) == "direct" and auto.chosen(OMEGA1_AUTO_AMG_DOFS, 3) == "amg"
    assert auto.chosen(10 * OMEGA1_AUTO_AMG_DOFS, 2) == "direct"
    assert omega1_solver(LinearSolverOptions(kind="auto")).chosen(AUTO_AMG_DOFS, 3) == "amg"
    step = fc.solve(channels_3d().on(channels_3d_mesh(4)), "primal").step  # default: auto, a small Ω₁
    assert not step.omega1_iterative and isinstance(step.sub[0].solver, DirectSolver)
