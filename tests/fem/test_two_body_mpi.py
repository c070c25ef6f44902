"""The monolithic two-body solve on two ranks (``fem.two_body_mpi``): the contact surfaces gathered to every rank,
the bulk solved in parallel; the solution is the serial one (``mpiexec -n 2``, against the same problem on
``COMM_SELF``) to 1e-10: the displacement at every vertex, both contact profiles and the forces on both sides,
with a partial contact whose active set changes during the iteration."""

import numpy as np
import pytest
import scipy.spatial
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact as fc
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.mpi


def _tilted(comm: MPI.Comm) -> TwoBodyProblem:
    """The upper block pushed down on the left and lifted on the right across a gap: a partial contact."""
    m = two_blocks(7, 10, heights=(0.5, 0.4), gap=0.004, comm=comm)
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(
            Support(T.LOWER_BOTTOM),
            Support(T.UPPER_TOP, lambda x: np.vstack([0.0 * x[0], 0.01 - 0.03 * x[0]])),
        ),
    )


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
    parallel = fc.solve(_tilted(MPI.COMM_WORLD), "primal-monolithic")
    serial = fc.solve(_tilted(MPI.COMM_SELF), "primal-monolithic")
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


def _tilted_3d(comm: MPI.Comm) -> TwoBodyProblem:
    m = two_blocks(3, 4, heights=(0.5, 0.4), dim=3, comm=comm)
    return TwoBodyProblem(
        m.mesh,
        m.cell_tags,
        m.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(
            Support(T.LOWER_BOTTOM),
            Support(T.UPPER_TOP, lambda x: np.vstack([0.0 * x[0], 0.0 * x[0], 0.005 - 0.02 * x[0]])),
        ),
    )


def test_two_ranks_give_the_serial_solution_in_three_dimensions():
    parallel = fc.solve(_tilted_3d(MPI.COMM_WORLD), "primal-monolithic")
    serial = fc.solve(_tilted_3d(MPI.COMM_SELF), "primal-monolithic")
    assert 0 < np.count_nonzero(serial.slave.active) < serial.slave.active.size
    for a, b in ((parallel.slave, serial.slave), (parallel.master, serial.master)):
        assert np.array_equal(a.points, b.points)
        assert np.max(np.abs(a.sigma_c - b.sigma_c)) <= 1e-10 * np.max(np.abs(b.sigma_c))
    for fp, fs in zip(parallel.forces, serial.forces, strict=True):
        assert np.linalg.norm(fp - fs) <= 1e-10 * np.linalg.norm(fs)
