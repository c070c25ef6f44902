"""Friction on two ranks: the monolithic solve and Algorithm 1 (the "interface" strategy under MPI) along a
press-and-drag path give the serial answer."""

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.obstacles import Plane
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.sliding import slide

pytestmark = pytest.mark.mpi

PATH = [(-0.01, 0.0), (-0.01, 0.01), (-0.01, 0.05)]


def _numbers(comm: MPI.Comm) -> dict:
    cm = unit_square(16, 4, clamped=("left",), comm=comm)
    wall = Plane((1.0, 0.0), (-1.0, 0.0))
    problem = ContactProblem(1.0, 0.3, obstacle=wall, law=Friction("coulomb", mu=0.3)).on(cm)
    out = {"ranks": comm.size}
    for method, options in (("primal-monolithic", {}), ("primal", {"tol": 1e-10})):
        path = slide(problem, method, PATH, **options)
        out[method] = [
            (s.normal_force, *map(float, s.tangential_force), s.stick_nodes, s.slip_nodes, s.dissipation)
            for s in path.steps
        ]
    return on_every_rank(out, comm)


def test_two_ranks_match_serial_with_friction():
    serial = _numbers(MPI.COMM_SELF)
    parallel = _numbers(MPI.COMM_WORLD)
    assert serial["ranks"] == 1 and parallel["ranks"] == MPI.COMM_WORLD.size
    for method in ("primal-monolithic", "primal"):
        s, p = np.array(serial[method]), np.array(parallel[method])
        assert np.array_equal(s[:, 3:5], p[:, 3:5])  # stick and slip node counts
        assert np.allclose(p, s, rtol=1e-8, atol=1e-14)
    assert np.allclose(serial["primal"], serial["primal-monolithic"], rtol=1e-8, atol=1e-14)
