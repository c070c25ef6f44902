"""Boundary conditions and obstacles in the primal solves give the serial answer on two ranks: u_D, two traction
groups, a curved gap (the manufactured problem), Algorithm 1 (Anderson and the interface Newton), and the Hertz
cylinder with a moving obstacle (load steps); the serial answer is the same computation on COMM_SELF."""

import numpy as np
import pytest
from manufactured import manufactured_mesh, manufactured_model
from mpi4py import MPI
from mpi_jobs import on_every_rank

import fenics_contact  # noqa: F401  (imports dolfinx_solver first)
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.problem.analytic import hertz_model, layered_model
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block

pytestmark = pytest.mark.mpi


def _numbers(comm: MPI.Comm) -> dict:
    cm = manufactured_mesh(16, comm)
    model = manufactured_model()
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    alg1 = solve_primal_hybrid(
        model.on(cm), delta=delta, reference=ref.u, options=IterationOptions(tol=1e-10, accel="anderson")
    )
    newton = solve_primal_hybrid(
        model.on(cm), delta=delta, reference=ref.u, options=IterationOptions(tol=1e-10, accel="newton")
    )
    block, _ = hertz_block(0.05, refinement=0.5, comm=comm)
    curve = force_indentation(
        hertz_model(radius=5.0, depth=0.0).on(block), "primal-monolithic", [6e-4, 1.2e-3], direction=(0.0, -1.0)
    )
    return on_every_rank(
        {
            "ranks": comm.size,
            "force": ref.profile.force,
            "l2": ref.problem.l2_norm2(ref.u),
            "alg1_iterations": alg1.iterations,
            "alg1_e_u": alg1.e_u,
            "newton_converged": newton.converged,
            "newton_steps": newton.history.newton_steps,
            "newton_e_u": newton.e_u,
            "hertz_forces": curve.forces.tolist(),
            "hertz_zone": curve.steps[-1].profile.contact_zone(),
        }
    )


def test_two_ranks_match_serial_with_boundary_conditions_and_obstacles():
    serial = _numbers(MPI.COMM_SELF)
    parallel = _numbers(MPI.COMM_WORLD)
    assert serial["ranks"] == 1 and parallel["ranks"] == 2
    assert parallel["force"] == pytest.approx(serial["force"], rel=1e-10)
    assert parallel["l2"] == pytest.approx(serial["l2"], rel=1e-10)
    assert parallel["alg1_iterations"] == serial["alg1_iterations"] and parallel["alg1_e_u"] < 1e-8
    assert parallel["newton_converged"] and parallel["newton_steps"] == serial["newton_steps"] <= 8
    assert parallel["newton_e_u"] < 1e-10 and serial["newton_e_u"] < 1e-10
    assert np.allclose(parallel["hertz_forces"], serial["hertz_forces"], rtol=1e-10)
    assert np.allclose(parallel["hertz_zone"], serial["hertz_zone"], atol=1e-12)


@pytest.mark.parametrize("accel", ["newton", "anderson"])
def test_unloading_to_a_vanishing_solution_on_two_ranks(accel):
    """Load steps down to a vanishing solution on two ranks (Algorithm 1): the Ω₂ solve at nearly collapsed data
    sees the collapse before its own residual check (on two ranks that check can fail where one rank passes), so
    every step converges, the withdrawn step with zero force and the unloaded one with no force beyond round-off
    of the loaded one (exactly zero where the collapse is detected; the machine's BLAS rounding decides whether
    the iteration reaches u ≈ 0 directly instead)."""
    cm = unit_square(8, 4, clamped=("left",))
    model = layered_model([0.0, 0.5, 1.0], [1.0, 100.0], depth=0.0)
    curve = force_indentation(
        model.on(cm),
        "primal",
        [0.01, 0.0, -0.01],
        direction=(-1.0, 0.0),
        options=IterationOptions(tol=1e-9, accel=accel, max_iterations=300),
    )
    steps = on_every_rank(
        [dict(converged=s.converged, force=s.force, residual=s.transmission_residual) for s in curve.steps]
    )
    pushed, unloaded, withdrawn = steps
    assert MPI.COMM_WORLD.size == 2 and all(s["converged"] for s in steps)
    assert pushed["force"] > 0.0 and abs(unloaded["force"]) <= 1e-12 * pushed["force"] and withdrawn["force"] == 0.0
    assert unloaded["residual"] < 1e-9
