"""The monolithic solve and Algorithm 1 (one solve, a load path) on two ranks give the serial answer (the same solves
on COMM_SELF)."""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle

pytestmark = pytest.mark.mpi


def _numbers(comm: MPI.Comm, n: int, n_coarse: int, model_number: int, accel: str = "anderson") -> dict:
    """The monolithic solve and Algorithm 1 (``accel``) on ``comm``: rank 0's numbers on every rank."""
    cm = unit_square(n, n_coarse, comm=comm)
    problem = get_model(model_number).on(cm)
    delta = default_penalty(cm.h, 1e3 if model_number == 3 else 1.0)  # model 3: stiff channels reach Γ_C
    ref = solve_primal_monolithic(problem, delta=delta)
    res = solve_primal_hybrid(
        problem,
        alpha="E",
        delta=delta,
        reference=ref.u,
        options=IterationOptions(tol=1e-8 if accel == "anderson" else 1e-10, accel=accel),
    )

    def norm(u):
        local = fem.assemble_scalar(fem.form(ufl.inner(u, u) * ufl.dx))
        return float(np.sqrt(comm.allreduce(local, op=MPI.SUM)))

    return on_every_rank(
        {
            "ranks": comm.size,
            "newton_steps": ref.newton.steps,
            "active_sizes": ref.newton.active_sizes,
            "ref_norm": norm(ref.u),
            "hybrid_norm": norm(res.u),
            "iterations": res.iterations,
            "rel_changes": res.history.rel_changes.tolist(),
            "residuals": res.history.residuals.tolist(),
            "converged": res.converged,
            "interface_newton_steps": res.history.newton_steps,
            "e_u": res.e_u,
            "active_set": res.profile.active_interval(),
            "ref_active_set": ref.profile.active_interval(),
            "sigma_c": ref.profile.sigma_c.tolist(),
        }
    )


@pytest.mark.parametrize("model", [1, 2])
def test_two_ranks_match_serial(model):
    serial = _numbers(MPI.COMM_SELF, 32, 8, model)
    parallel = _numbers(MPI.COMM_WORLD, 32, 8, model)
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    assert parallel["newton_steps"] == serial["newton_steps"]
    assert parallel["active_sizes"] == serial["active_sizes"]
    assert parallel["iterations"] == serial["iterations"]
    assert np.allclose(parallel["active_set"], serial["active_set"], rtol=0, atol=1e-12)
    assert np.allclose(serial["active_set"], serial["ref_active_set"], rtol=0, atol=1e-12)
    for key in ("ref_norm", "hybrid_norm"):
        assert abs(parallel[key] - serial[key]) <= 1e-10 * serial[key], key
    assert np.allclose(parallel["rel_changes"], serial["rel_changes"], rtol=1e-6, atol=1e-12)
    assert np.allclose(parallel["sigma_c"], serial["sigma_c"], rtol=0, atol=1e-10 * np.abs(serial["sigma_c"]).max())
    assert serial["e_u"] < 1e-6 and parallel["e_u"] < 1e-6


def test_two_ranks_match_serial_with_interface_newton():
    """Algorithm 1 + interface Newton on the heterogeneous strip (model 3): 2 ranks give the serial answer,
    which is the monolithic solution (Theorem 3.1), in the same number of Newton steps."""
    serial = _numbers(MPI.COMM_SELF, 32, 8, 3, "newton")
    parallel = _numbers(MPI.COMM_WORLD, 32, 8, 3, "newton")
    assert parallel["ranks"] == 2
    for run in (serial, parallel):
        assert run["converged"] and run["residuals"][-1] < 1e-10 and run["e_u"] < 1e-10, run
    assert parallel["interface_newton_steps"] == serial["interface_newton_steps"] <= 8
    assert parallel["iterations"] == serial["iterations"]
    assert abs(parallel["hybrid_norm"] - serial["hybrid_norm"]) <= 1e-10 * serial["hybrid_norm"]
    assert np.allclose(parallel["active_set"], serial["active_set"], rtol=0, atol=1e-12)


def _curve_numbers(comm: MPI.Comm) -> dict:
    """Algorithm 1's load path (condensed interface Newton) on ``comm``: rank 0's forces, relative changes and
    certificates on every rank."""
    problem = get_model(3, E_high=1e3).with_(obstacle=Circle((3.0, 0.5), 2.0)).on(unit_square(32, 8, comm=comm))
    changes = []
    curve = force_indentation(
        problem,
        "primal",
        np.linspace(0.004, 0.02, 3),
        direction=(-1.0, 0.0),
        on_step=lambda _, solver: changes.append(solver.relative_change()),
        tol=1e-10,
        accel="newton",
    )
    return on_every_rank(
        {"forces": curve.forces.tolist(), "changes": changes, "residuals": curve.transmission_residuals.tolist()}
    )


def test_two_ranks_load_path_matches_serial():
    """A load path of Algorithm 1 on two ranks (Ω₁ by one back-solve of b + C g, its K u₁ from those equations in
    the relative change): the serial forces, relative changes and certified steps."""
    serial = _curve_numbers(MPI.COMM_SELF)
    parallel = _curve_numbers(MPI.COMM_WORLD)
    assert np.allclose(parallel["forces"], serial["forces"], rtol=1e-10, atol=0.0)
    assert np.allclose(parallel["changes"], serial["changes"], rtol=1e-6, atol=0.0)
    assert max(serial["residuals"] + parallel["residuals"]) < 1e-10
