"""Friction with the multiscale Ω₁ under MPI: Algorithm 3 (the mesh distributed, its patches shared out) and
Algorithm 4 (each rank holding the whole mesh, its offline phase shared out by ``offline_comm``) along a
press-and-drag Coulomb path on model 3 at contrast 1e6 give the serial path, and with patches covering Ω₁ the
method's monolithic path."""

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane
from fenics_contact.sliding import slide

pytestmark = pytest.mark.mpi

LAW = Friction("coulomb", mu=0.3)
#: press the wall into Γ_C = {x = 1}, then drag it along y twice
PATH_2D = [(-2e-3, 0.0), (-2e-3, 0.004), (-2e-3, 0.03)]
PATH_3D = [(-0.01, 0.0, 0.0), (-0.01, 0.005, 0.0), (-0.01, 0.02, 0.0)]


def _model3(comm: MPI.Comm):
    """Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁) at contrast 1e6, h = 1/16, H = 1/4 (Ω₁ is 3 × 4
    coarse cells: m = 3 patches cover it), pressed by the wall x = 1."""
    problem = get_model(3, E_high=1e6).on(unit_square(16, 4, comm=comm))
    return problem.with_(obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=LAW)


def _rows(path) -> list[tuple]:
    """Per step: normal force, tangential force (d components), stick and slip node counts, dissipation, converged."""
    return [
        (s.normal_force, *map(float, s.tangential_force), s.stick_nodes, s.slip_nodes, s.dissipation, s.converged)
        for s in path.steps
    ]


def _path(comm: MPI.Comm, method: str, dim: int = 2) -> dict:
    """``method`` along the press-and-drag path with patches covering Ω₁ (m = 3 in 2D, m = 2 on the 3D channel cube
    at h = 1/6, H = 1/3, contrast 1e3): primal-ms on a mesh distributed over ``comm``, mixed-ms on the whole mesh
    on every rank with its offline phase shared over ``comm``."""
    if method == "primal-ms" and dim == 3:
        H = 1.0 / 3.0
        problem = channels_3d(E_high=1e3).on(channels_3d_mesh(6, strip=H, H=H, comm=comm))
        problem = problem.with_(obstacle=Plane((1.0, 0.5, 0.5), (-1.0, 0.0, 0.0)), law=LAW)
        path = slide(problem, method, PATH_3D, tol=1e-11, layers=2)
        shares = comm.allgather(path.solver.omega1.space.times["patches_here"])
    elif method == "primal-ms":
        path = slide(_model3(comm), method, PATH_2D, tol=1e-11, layers=3)
        shares = comm.allgather(path.solver.omega1.space.times["patches_here"])
    else:
        path = slide(_model3(MPI.COMM_SELF), method, PATH_2D, tol=1e-11, layers=3, offline_comm=comm)
        shares = [path.solver.omega1.distributed] * comm.size
    return on_every_rank({"ranks": comm.size, "steps": _rows(path), "shares": shares}, comm)


def _monolithic(comm: MPI.Comm, method: str, dim: int = 2) -> np.ndarray:
    """On one rank the monolithic path whose solution is the method's fixed point with a fine Ω₁: the primal one
    for Algorithm 3, the mixed one on X̃_h (σ_tt split at γ's vertices, ``split_interface``) for Algorithm 4."""
    if method == "mixed-ms":
        return np.array(_rows(slide(_model3(comm), "mixed-monolithic", PATH_2D, split_interface=True)))
    return np.array(_rows(slide(_model3(comm), "primal-monolithic", PATH_2D)), dtype=float)


def _serial(function, *args):
    """``function(MPI.COMM_SELF, *args)`` computed on rank 0 alone (the other ranks wait), on every rank."""
    return on_every_rank(function(MPI.COMM_SELF, *args) if MPI.COMM_WORLD.rank == 0 else None)


def _same_path(a: np.ndarray, b: np.ndarray, dim: int, rtol: float) -> None:
    """The same stick/slip counts; forces within ``rtol`` of the normal force; dissipation within ``rtol``."""
    assert np.all(a[:, -1] == 1.0) and np.all(b[:, -1] == 1.0)  # converged
    assert np.array_equal(a[:, dim + 1 : dim + 3], b[:, dim + 1 : dim + 3])  # stick and slip node counts
    assert np.all(np.abs(a[:, : dim + 1] - b[:, : dim + 1]) <= rtol * a[:, :1])  # normal and tangential forces
    assert np.all(np.abs(a[:, dim + 3] - b[:, dim + 3]) <= rtol * np.max(np.abs(a[:, dim + 3])))  # dissipation


@pytest.mark.mpi(sizes=(2, 3))
@pytest.mark.parametrize("method", ["primal-ms", "mixed-ms"])
def test_multiscale_friction_path_matches_serial_and_monolithic(method):
    """On 2 and 3 ranks Algorithm 3 (its patches shared out, each rank some) and Algorithm 4 (its offline phase
    shared out) give the serial path per step to 2e-10 of the normal force (measured 1.0e-10 for Algorithm 3 on 2
    ranks: the rounding of the distributed solves, carried through a Jacobian of contrast 1e6; bit for bit for
    Algorithm 4), the same stick/slip counts and dissipation; with patches covering Ω₁ both
    equal their fixed point with a fine Ω₁ to 1e-8: the primal monolithic path, the mixed one on X̃_h (at contrast 1e6
    Algorithm 2's split σ_tt at γ moves the forces by 1e-5 from the mixed monolithic path on X_h)."""
    serial = _serial(_path, method)
    parallel = _path(MPI.COMM_WORLD, method)
    assert serial["ranks"] == 1 and parallel["ranks"] == MPI.COMM_WORLD.size
    if method == "primal-ms":
        assert min(parallel["shares"]) > 0 and sum(parallel["shares"]) == serial["shares"][0]
    else:
        assert all(parallel["shares"]) and not serial["shares"][0]  # Ω₁'s offline phase shared over the ranks
    s, p = np.array(serial["steps"], dtype=float), np.array(parallel["steps"], dtype=float)
    _same_path(s, p, 2, 2e-10)
    _same_path(_serial(_monolithic, method), s, 2, 1e-8)
    assert np.any(s[:, 4] > 0) and np.abs(s[-1, 2]) > 0.1 * s[-1, 0]  # the drag makes nodes slip: a real drag


def test_algorithm_3_friction_path_in_3d_matches_serial():
    """Algorithm 3 on the channel cube (h = 1/6, H = 1/3, m = 2: every patch is Ω₁) at contrast 1e3 on 2 ranks: the
    serial path per step to 1e-10 of the normal force, the same stick/slip counts and dissipation (that serial path
    is the monolithic one: ``tests/hybrid/test_friction_hybrid_3d.py``).  Contrast 1e3, not 1e6, for time: at 1e6
    the distributed path alone took 52 s on 2 ranks (this test 35 s at 1e3), Ω₂'s frictional Newton taking hundreds
    of steps along it."""
    serial = _serial(_path, "primal-ms", 3)
    parallel = _path(MPI.COMM_WORLD, "primal-ms", 3)
    assert min(parallel["shares"]) > 0 and sum(parallel["shares"]) == serial["shares"][0]
    s, p = np.array(serial["steps"], dtype=float), np.array(parallel["steps"], dtype=float)
    _same_path(s, p, 3, 1e-10)
    assert np.any(s[:, 5] > 0)  # the drag makes nodes slip
