"""Friction on two ranks: the monolithic solves, Algorithm 1 (the condensed frictional system, its law gathered to
every rank) and Algorithm 2 along a press-and-drag path give the serial answer."""

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.hybrid.friction import FrictionalCondensation
from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.sliding import slide

pytestmark = pytest.mark.mpi

PATH = [(-0.01, 0.0), (-0.01, 0.01), (-0.01, 0.05)]


def _numbers(comm: MPI.Comm, family: str = "primal") -> dict:
    cm = unit_square(16, 4, clamped=("left",), comm=comm)
    wall = Plane((1.0, 0.0), (-1.0, 0.0))
    problem = ContactProblem(1.0, 0.3, obstacle=wall, law=Friction("coulomb", mu=0.3)).on(cm)
    out = {"ranks": comm.size}
    for method, options in ((f"{family}-monolithic", {}), (family, {"tol": 1e-10})):
        path = slide(problem, method, PATH, **options)
        out[method] = [
            (s.normal_force, *map(float, s.tangential_force), s.stick_nodes, s.slip_nodes, s.dissipation)
            for s in path.steps
        ]
    return on_every_rank(out, comm)


@pytest.mark.parametrize("family", ["primal", "mixed"])
def test_two_ranks_match_serial_with_friction(family):
    """The monolithic solve and Algorithm 1 (primal) or 2 (mixed: the law on σ_t at replicated contact nodes, the
    interface Newton with Ω₂'s frictional Jacobian; its forces of 1e-2 agree to 3e-14: atol 1e-12)."""
    atol = 1e-14 if family == "primal" else 1e-12
    serial = _numbers(MPI.COMM_SELF, family)
    parallel = _numbers(MPI.COMM_WORLD, family)
    assert serial["ranks"] == 1 and parallel["ranks"] == MPI.COMM_WORLD.size
    for method in (f"{family}-monolithic", family):
        s, p = np.array(serial[method]), np.array(parallel[method])
        assert np.array_equal(s[:, 3:5], p[:, 3:5])  # stick and slip node counts
        assert np.allclose(p, s, rtol=1e-8, atol=atol)
    assert np.allclose(serial[family], serial[f"{family}-monolithic"], rtol=1e-8, atol=atol)


def _channels(comm: MPI.Comm, dim: int) -> dict:
    """Algorithm 1 along press-and-drag on the channel models at contrast 1e6 (2D model 3, h = 1/16; the 3D channel
    cube, h = 1/4), Coulomb μ = 0.3: per step the forces, stick/slip counts, dissipation and convergence."""
    law = Friction("coulomb", mu=0.3)
    if dim == 2:
        problem = get_model(3, E_high=1e6).on(unit_square(16, 4, comm=comm))
        problem = problem.with_(obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=law)
        path = [(-2e-3, 0.0), (-2e-3, 0.004), (-2e-3, 0.03)]
    else:
        problem = channels_3d(E_high=1e6).on(channels_3d_mesh(4, comm=comm))
        problem = problem.with_(obstacle=Plane((1.0, 0.5, 0.5), (-1.0, 0.0, 0.0)), law=law)
        path = [(-0.01, 0.0, 0.0), (-0.01, 0.005, 0.0), (-0.01, 0.02, 0.0)]
    result = slide(problem, "primal", path, tol=1e-11)
    steps = [
        (s.normal_force, *map(float, s.tangential_force), s.stick_nodes, s.slip_nodes, s.dissipation, s.converged)
        for s in result.steps
    ]
    condensed = isinstance(result.solver._newton.condensed, FrictionalCondensation)
    return on_every_rank({"ranks": comm.size, "steps": steps, "condensed": condensed}, comm)


@pytest.mark.parametrize("dim", [2, 3])
def test_two_ranks_run_the_condensed_frictional_system_as_serial(dim):
    """At contrast 1e6 the frictional condensed system runs on two ranks (not the "interface" strategy) and gives
    the serial path to 1e-10: forces, stick/slip counts, dissipation, every step converged."""
    serial = _channels(MPI.COMM_SELF, dim)
    parallel = _channels(MPI.COMM_WORLD, dim)
    assert parallel["ranks"] == MPI.COMM_WORLD.size and serial["condensed"] and parallel["condensed"]
    s, p = np.array(serial["steps"], dtype=float), np.array(parallel["steps"], dtype=float)
    assert np.all(s[:, -1] == 1.0) and np.all(p[:, -1] == 1.0)  # converged
    assert np.array_equal(s[:, dim + 1 : dim + 3], p[:, dim + 1 : dim + 3])  # stick and slip node counts
    normal = s[:, :1]
    assert np.all(np.abs(p[:, : dim + 1] - s[:, : dim + 1]) <= 1e-10 * normal)  # normal and tangential forces
    assert np.allclose(p[:, dim + 3], s[:, dim + 3], rtol=1e-10, atol=1e-10 * np.max(np.abs(s[:, dim + 3])))
    assert np.any(s[:, dim + 2] > 0)  # the drag makes nodes slip
