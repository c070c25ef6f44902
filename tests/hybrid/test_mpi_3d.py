"""Algorithms 1 and 3 in 3D on several ranks give the serial answer (the same solves on COMM_SELF): on the channel
model's cubes and on the Hertz block's graded boxes (``partition.graded_coarse_cells``: the same partition on any
number of ranks)."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact as fc
from fenics_contact.problem.analytic import hertz_sphere_model, hertz_sphere_penalty
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.partition import coarse_sizes
from fenics_contact.problem.tags import Subdomain


def _numbers(comm: MPI.Comm, accel: str) -> dict:
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(8, comm=comm))
    ref = fc.solve(problem, "primal-monolithic")
    result = fc.solve(problem, "primal", accel=accel, tol=1e-9, reference=ref.u)

    def norm(u):
        local = fem.assemble_scalar(fem.form(ufl.inner(u, u) * ufl.dx))
        return float(np.sqrt(comm.allreduce(local, op=MPI.SUM)))

    V = result.u.function_space
    owned = V.dofmap.index_map.size_local
    x = np.concatenate(comm.allgather(V.tabulate_dof_coordinates()[:owned]))
    u = np.concatenate(comm.allgather(result.u.x.array.reshape(-1, 3)[:owned]))
    order = np.lexsort(np.round(x, 12).T)
    return on_every_rank(
        {
            "u": u[order],
            "ranks": comm.size,
            "norm": norm(result.u),
            "ref_norm": norm(ref.u),
            "e_u": result.e_u,
            "converged": result.converged,
            "residual": result.history.transmission_residual,
            "newton_steps": result.history.newton_steps,
            "active": int(np.count_nonzero(result.profile.active)),
            "force": result.profile.force,
        },
        comm=MPI.COMM_WORLD,
    )


@pytest.mark.mpi(sizes=(2, 3))
def test_algorithm_1_in_3d_on_several_ranks_is_the_serial_answer():
    serial = _numbers(MPI.COMM_SELF, "newton")
    parallel = _numbers(MPI.COMM_WORLD, "newton")
    assert serial["ranks"] == 1 and parallel["ranks"] == MPI.COMM_WORLD.size
    for run in (serial, parallel):
        assert run["converged"] and run["residual"] < 1e-9 and run["e_u"] <= 1e-8
    assert np.abs(parallel["u"] - serial["u"]).max() <= 1e-10 * np.abs(serial["u"]).max()  # node by node
    assert abs(parallel["norm"] - serial["norm"]) <= 1e-10 * serial["norm"]
    assert abs(parallel["ref_norm"] - serial["ref_norm"]) <= 1e-10 * serial["ref_norm"]
    assert parallel["active"] == serial["active"] and parallel["newton_steps"] == serial["newton_steps"]
    assert parallel["force"] == pytest.approx(serial["force"], rel=1e-10)


def _multiscale_numbers(comm: MPI.Comm, model: str = "channels") -> dict:
    """Algorithm 3 (m = 2) on the 3D channel model (h = 1/8, cubes of side ¼) or on the Hertz block (contact cells
    a/5, its graded coarse boxes): the offline phase shared over the ranks of ``comm``."""
    if model == "channels":
        problem = channels_3d(E_high=1e3).on(channels_3d_mesh(8, strip=0.25, H=0.25, comm=comm))
        delta = None
    else:
        problem = hertz_sphere_model(0.1, 0.1 / 5, radius=1.0, comm=comm)
        delta = hertz_sphere_penalty(0.1 / 5)
    ref = fc.solve(problem, "primal-monolithic", delta=delta)
    result = fc.solve(problem, "primal-ms", delta=delta, layers=2, tol=1e-9, reference=ref.u)
    cm = problem.cm
    sizes = coarse_sizes(cm.mesh, cm.coarse_cell)
    unresolved = comm.allreduce(int(np.count_nonzero(cm.coarse_cell[cm.cell_tags.find(Subdomain.OMEGA1)] < 0)))
    V = result.u.function_space
    owned = V.dofmap.index_map.size_local
    x = np.concatenate(comm.allgather(V.tabulate_dof_coordinates()[:owned]))
    u = np.concatenate(comm.allgather(result.u.x.array.reshape(-1, 3)[:owned]))
    order = np.lexsort(np.round(x, 12).T)
    omega1 = result.step.omega1
    return on_every_rank(
        {
            "u": u[order],
            "ranks": comm.size,
            "e_u": result.e_u,
            "e_energy": result.step.error_energy(),
            "converged": result.converged,
            "residual": result.history.transmission_residual,
            "newton_steps": result.history.newton_steps,
            "dim_ms": result.dofs["omega1_ms"],
            "gap": omega1.spectral_gap,
            "patches_here": omega1.space.times["patches_here"],
            "active": int(np.count_nonzero(result.profile.active)),
            "sizes": np.sort(sizes),
            "unresolved": unresolved,
        },
        comm=MPI.COMM_WORLD,
    )


@pytest.mark.mpi(sizes=(2, 3))
def test_algorithm_3_in_3d_on_several_ranks_is_the_serial_answer():
    """The local eigenproblems and patch problems shared over the ranks, the coarse solve on every rank: the
    same multiscale solution as one process, node by node to 1e-10."""
    serial = _multiscale_numbers(MPI.COMM_SELF)
    parallel = _multiscale_numbers(MPI.COMM_WORLD)
    _assert_same_multiscale_solution(serial, parallel)
    assert serial["patches_here"] == 48
    for run in (serial, parallel):
        assert run["e_energy"] < 1e-2  # (2.2e-3 measured)


@pytest.mark.mpi(sizes=(2, 3))
def test_algorithm_3_on_the_hertz_block_on_several_ranks_is_the_serial_answer():
    """The Hertz block's graded coarse boxes: the same partition (sizes of the coarse cells, every Ω₁ cell in one)
    and the same Algorithm 3 solution on several ranks as on one."""
    serial = _multiscale_numbers(MPI.COMM_SELF, "hertz")
    parallel = _multiscale_numbers(MPI.COMM_WORLD, "hertz")
    assert serial["unresolved"] == parallel["unresolved"] == 0
    np.testing.assert_allclose(parallel["sizes"], serial["sizes"], rtol=1e-12)
    _assert_same_multiscale_solution(serial, parallel)


def _assert_same_multiscale_solution(serial: dict, parallel: dict) -> None:
    assert serial["ranks"] == 1 and parallel["ranks"] == MPI.COMM_WORLD.size
    for run in (serial, parallel):
        assert run["converged"] and run["residual"] < 1e-9 and run["newton_steps"] <= 8
    assert 0 < parallel["patches_here"] < serial["patches_here"]  # the patch problems were shared
    assert np.abs(parallel["u"] - serial["u"]).max() <= 1e-10 * np.abs(serial["u"]).max()
    assert parallel["e_u"] == pytest.approx(serial["e_u"], rel=1e-8)
    assert parallel["dim_ms"] == serial["dim_ms"] and parallel["gap"] == pytest.approx(serial["gap"], rel=1e-10)
    assert parallel["active"] == serial["active"] and parallel["newton_steps"] == serial["newton_steps"]
