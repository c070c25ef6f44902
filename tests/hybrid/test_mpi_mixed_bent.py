"""Algorithm 2 on a bent γ distributed over two ranks (the bends' data, the facet colours and the traces gathered
across ranks) is the serial run: the same iterations, fixed point and force (the serial run on COMM_SELF)."""

import pytest
from bent_interfaces import zigzag_problem
from mpi4py import MPI
from mpi_jobs import on_every_rank

from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid

pytestmark = pytest.mark.mpi


def _numbers(comm: MPI.Comm) -> dict:
    """Algorithm 2 (Anderson, tol 1e-10) on the zigzag γ at h = 1/16 on ``comm``: rank 0's numbers on every rank."""
    problem = zigzag_problem(16, comm=comm)
    split = solve_mixed_monolithic(problem, split_interface=True)
    result = solve_mixed_hybrid(problem, reference=split, options=IterationOptions(accel="anderson", tol=1e-10))
    return on_every_rank(
        {
            "ranks": comm.size,
            "converged": bool(result.converged),
            "iterations": result.history.iterations,
            "e_sigma": result.e_sigma,
            "e_u": result.e_u,
            "residual": float(result.history.residuals[-1]),
            "force": float(result.profile.force),
            "force_split": float(split.profile.force),
        }
    )


def test_algorithm_2_on_a_bent_interface_on_two_ranks_is_the_serial_run():
    serial, parallel = _numbers(MPI.COMM_SELF), _numbers(MPI.COMM_WORLD)
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    for run in (serial, parallel):
        assert run["converged"] and run["residual"] < 1e-10
        assert run["e_sigma"] < 1e-8 and run["e_u"] < 1e-8
        assert abs(run["force"] - run["force_split"]) < 1e-9 * abs(run["force_split"])
    assert parallel["iterations"] == serial["iterations"]
    assert abs(parallel["force"] - serial["force"]) < 1e-10 * abs(serial["force"])
