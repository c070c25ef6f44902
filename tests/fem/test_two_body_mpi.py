"""The monolithic two-body solve on two ranks (``fem.two_body_mpi``): the contact surfaces gathered to every rank,
the bulk solved in parallel; the solution is the serial one (``mpiexec -n 2``, against the same problem on
``COMM_SELF``) to 1e-10: the displacement at every vertex, both contact profiles and the forces on both sides,
with a partial contact whose active set changes during the iteration."""

import numpy as np
import pytest
import scipy.spatial
from mpi4py import MPI
from mpi_jobs import on_every_rank
from pair_problems import tilted_pair

import fenics_contact as fc

pytestmark = pytest.mark.mpi


def _vertex_values(u) -> np.ndarray:
    """(x, y, u_x, u_y) of the owned vertices of all ranks (rank 0's; None elsewhere)."""
    V = u.function_space
    n = V.dofmap.index_map.size_local
    rows = np.column_stack([V.tabulate_dof_coordinates()[:n, :2], u.x.array.reshape(-1, 2)[:n]])
    parts = V.mesh.comm.gather(rows, root=0)
    if parts is None:
        return None
    return np.vstack(parts)


def test_two_ranks_give_the_serial_solution():
    parallel = fc.solve(tilted_pair(MPI.COMM_WORLD, (7, 10)), "primal-monolithic")
    serial = fc.solve(tilted_pair(MPI.COMM_SELF, (7, 10)), "primal-monolithic")
    assert MPI.COMM_WORLD.size > 1 and parallel.dofs == serial.dofs
    assert 0 < np.count_nonzero(serial.slave.active) < serial.slave.active.size  # a partial contact
    for a, b in ((parallel.slave, serial.slave), (parallel.master, serial.master)):
        assert np.array_equal(a.points, b.points)
        assert np.max(np.abs(a.sigma_c - b.sigma_c)) <= 1e-10 * np.max(np.abs(b.sigma_c))
    for fp, fs in zip(parallel.forces, serial.forces, strict=True):
        assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
    assert parallel.force_balance() < 1e-12
    rows = _vertex_values(parallel.u)
    error = None
    if rows is not None:  # rank 0: every vertex of the parallel solution against the serial one at its position
        V = serial.u.function_space
        distance, match = scipy.spatial.cKDTree(V.tabulate_dof_coordinates()[:, :2]).query(rows[:, :2])
        serial_u = serial.u.x.array.reshape(-1, 2)
        assert rows.shape[0] == serial_u.shape[0] and np.max(distance) < 1e-12
        error = float(np.max(np.abs(rows[:, 2:] - serial_u[match])) / np.max(np.abs(serial_u)))
    assert on_every_rank(error) < 1e-10


def test_two_ranks_give_the_serial_solution_in_three_dimensions():
    parallel = fc.solve(tilted_pair(MPI.COMM_WORLD, (3, 4), dim=3), "primal-monolithic")
    serial = fc.solve(tilted_pair(MPI.COMM_SELF, (3, 4), dim=3), "primal-monolithic")
    assert 0 < np.count_nonzero(serial.slave.active) < serial.slave.active.size
    for a, b in ((parallel.slave, serial.slave), (parallel.master, serial.master)):
        assert np.array_equal(a.points, b.points)
        assert np.max(np.abs(a.sigma_c - b.sigma_c)) <= 1e-10 * np.max(np.abs(b.sigma_c))
    for fp, fs in zip(parallel.forces, serial.forces, strict=True):
        assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
