"""Algorithm 3 (primal CEM hybrid) on two ranks: the patches are shared out and the solution is the serial one."""

import numpy as np
import pytest
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

pytestmark = pytest.mark.mpi


def load(x):
    """Bands inside Ω₁ (x ∈ [1/2, 15/16]): push the lower half, pull the upper half."""
    f = np.zeros((2, x.shape[1]))
    inside = (x[0] > 0.5) & (x[0] < 15 / 16)
    f[0, inside & (x[1] < 0.5)] = 1.0
    f[0, inside & (x[1] > 0.5)] = -1.0
    return f


def _numbers(comm: MPI.Comm, n: int = 32, n_coarse: int = 8, patch_group: int = 1) -> dict:
    """Algorithm 3 (Anderson), then the interface Newton on the same step; the solution's values at every vertex
    of the uniform grid (h = 1/n) in coordinate order, from all ranks."""
    cm = unit_square(n, n_coarse, comm=comm)
    problem = get_model(1).with_(load=load).on(cm)
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(problem, delta=delta)
    cem = CEMOptions(layers=2, nbasis=3, patch_group=patch_group)
    res = solve_primal_ms_hybrid(
        problem,
        alpha="Emin",
        delta=delta,
        cem=cem,
        reference=ref.u,
        options=IterationOptions(tol=1e-10, accel="anderson"),
    )
    # the interface Newton on the same step (Ω₁'s response from the coarse solver, gathered over the ranks)
    newton = solve_primal_ms_hybrid(
        problem, alpha="Emin", delta=delta, cem=cem, step=res.step, options=IterationOptions(tol=1e-10, accel="newton")
    )
    scale = comm.allreduce(float(np.abs(res.u.x.array).max()), op=MPI.MAX)
    newton_vs_robin = comm.allreduce(float(np.abs(newton.u.x.array - res.u.x.array).max()), op=MPI.MAX) / scale
    V = res.u.function_space
    n_owned, bs = V.dofmap.index_map.size_local, V.dofmap.index_map_bs
    xs = np.concatenate(comm.allgather(V.tabulate_dof_coordinates()[:n_owned, :2]))
    us = np.concatenate(comm.allgather(res.u.x.array[: n_owned * bs].reshape(n_owned, bs)))
    key = np.round(xs * n).astype(np.int64)  # vertices of the uniform grid (h = 1/n)
    order = np.lexsort((key[:, 1], key[:, 0]))
    return on_every_rank(
        {
            "ranks": comm.size,
            "iterations": res.iterations,
            "converged": bool(res.converged),
            "e_u": res.e_u,
            "e_a": res.step.error_energy(),
            "rel_changes": res.history.rel_changes.tolist(),
            "dim_ms": res.dofs["omega1_ms"],
            "newton_converged": bool(newton.converged),
            "newton_steps": newton.history.newton_steps,
            "newton_vs_robin": newton_vs_robin,
            "patches_here": comm.allgather(res.step.omega1.space.times["patches_here"]),
            "x": xs[order],
            "u": us[order],
        }
    )


def test_two_ranks_match_serial():
    """mpiexec -n 2: the patches are shared out (each rank computes some, none twice) and the Algorithm 3
    solution equals the serial one DOF by DOF to 1e-10 (loads in Ω₁, source correction on)."""
    serial = _numbers(MPI.COMM_SELF)
    parallel = _numbers(MPI.COMM_WORLD)
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    assert serial["converged"] and parallel["converged"]
    assert parallel["iterations"] == serial["iterations"]
    assert parallel["dim_ms"] == serial["dim_ms"]
    shares = parallel["patches_here"]
    assert min(shares) > 0 and sum(shares) == serial["patches_here"][0] == 56
    assert np.allclose(parallel["x"], serial["x"], rtol=0, atol=1e-12)
    assert np.abs(parallel["u"] - serial["u"]).max() / np.abs(serial["u"]).max() < 1e-10
    for key in ("e_u", "e_a"):
        assert abs(parallel[key] - serial[key]) <= 1e-8 * serial[key], key
    assert np.allclose(parallel["rel_changes"], serial["rel_changes"], rtol=1e-6, atol=1e-12)
    for run in (serial, parallel):  # --accel newton: the same fixed point, the same steps on 1 and 2 ranks
        assert run["newton_converged"] and run["newton_vs_robin"] < 1e-8, run
    assert parallel["newton_steps"] == serial["newton_steps"] <= 8


def test_two_ranks_share_out_patch_groups():
    """mpiexec -n 2 with 2 × 2 cells per patch problem: the 16 group problems are shared out (each rank some,
    none twice) and the solution equals the serial one with the same groups."""
    serial = _numbers(MPI.COMM_SELF, patch_group=2)
    parallel = _numbers(MPI.COMM_WORLD, patch_group=2)
    assert serial["converged"] and parallel["converged"]
    shares = parallel["patches_here"]
    assert min(shares) > 0 and sum(shares) == serial["patches_here"][0] == 16
    assert np.abs(parallel["u"] - serial["u"]).max() / np.abs(serial["u"]).max() < 1e-10
    assert parallel["iterations"] == serial["iterations"]
