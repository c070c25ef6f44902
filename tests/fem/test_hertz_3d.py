"""3D Hertz at contact cells of a/20: a rigid sphere on the quarter block of ``meshes3d.hertz_quarter_block``, by the
primal monolithic solve and by Algorithm 1 on the same block (Ω₂ the layer under the top, the symmetry planes
rollers through both parts)."""

from typing import NamedTuple

import numpy as np
import pytest
from mpi4py import MPI

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.fem.primal import PrimalSolution, solve_primal_monolithic
from fenics_contact.problem.analytic import (
    HertzSphereErrors,
    hertz_sphere_errors,
    hertz_sphere_model,
    hertz_sphere_penalty,
)
from fenics_contact.problem.geometry import mesh_size
from fenics_contact.problem.meshes3d import hertz_quarter_block
from fenics_contact.problem.problem import ContactProblem
from fenics_contact.problem.tags import Boundary

A, R, E, NU = 0.1, 1.0, 1.0, 0.3  # a/R = 0.1; the block 20a


class Hertz(NamedTuple):
    """One monolithic Hertz solve with contact cells h_c = a/``cells``."""

    problem: ContactProblem
    delta: float
    solution: PrimalSolution
    errors: HertzSphereErrors


def _errors(profile, cells: int) -> HertzSphereErrors:
    return hertz_sphere_errors(profile, radius=R, E=E, nu=NU, h_contact=A / cells)


@pytest.fixture(scope="module")
def hertz() -> dict[int, Hertz]:
    """The monolithic solves at h_c = a/10 and a/20, δ = 10⁻³ h_c/E*, CG + AMG (shared by the tests below)."""
    runs = {}
    for cells in (10, 20):
        h = A / cells
        problem = hertz_sphere_model(A, h, radius=R, E=E, nu=NU)
        delta = hertz_sphere_penalty(h, E=E, nu=NU)
        solution = solve_primal_monolithic(problem, delta=delta, solver=LinearSolverOptions(kind="amg"))
        runs[cells] = Hertz(problem, delta, solution, _errors(solution.profile, cells))
    return runs


def _assert_hertz(coarse: HertzSphereErrors, fine: HertzSphereErrors) -> None:
    """The Hertz bounds at a/20 (and a/10 for the rate): the contact radius within one contact cell, the centre
    pressure within 3 %, the L² pressure profile within 4 % and at least 1.3 times smaller than at a/10."""
    assert abs(fine.radius - fine.a) <= A / 20
    assert abs(fine.centre_error) <= 0.03
    assert fine.l2_error <= 0.04 and coarse.l2_error >= 1.3 * fine.l2_error
    assert abs(coarse.radius - coarse.a) <= A / 10


@pytest.mark.slow
def test_hertz_sphere_at_a_over_20(hertz):
    """Measured (26,901 DOFs at a/20, 7 Newton steps of 25–33 CG iterations): the area-equivalent contact radius
    −0.00 h_c from a, the centre pressure −0.6 % from p₀, the L² profile error 3.1 % (4.9 % at a/10: 1.6×)."""
    _assert_hertz(hertz[10].errors, hertz[20].errors)
    solution = hertz[20].solution
    assert max(solution.krylov_iterations) <= 80  # AMG: flat in the Newton steps and the refinement
    assert solution.profile.penetration == pytest.approx(solution.delta * solution.profile.max_pressure, rel=1e-6)


@pytest.mark.slow
def test_algorithm_1_on_the_hertz_block(hertz):
    """Algorithm 1 (``primal``, the interface Newton) on the same blocks and penalty: its fixed point is the
    monolithic solution (relative L² difference at most 1e-8, Theorem 3.1), so the Hertz bounds hold for it as
    well.  The symmetry planes x = 0 and y = 0 cross γ (the plane z = −2a): each part takes them as its own
    rollers, u_x = 0 and u_y = 0 on them in Ω₁ and Ω₂ alike.  Measured: 2 interface Newton steps at a/10 and 3 at
    a/20 (e_u 4e-12 and 5e-14)."""
    errors = {}
    for cells, run in hertz.items():
        result = fc.solve(run.problem, "primal", delta=run.delta, reference=run.solution.u, tol=1e-9)
        assert result.converged and result.history.transmission_residual < 1e-9
        assert result.e_u <= 1e-8, cells
        assert result.history.newton_steps <= 8, cells
        np.testing.assert_array_equal(result.profile.active, run.solution.profile.active)
        errors[cells] = _errors(result.profile, cells)
        assert errors[cells].force == pytest.approx(run.errors.force, rel=1e-8)
    _assert_hertz(errors[10], errors[20])
    gamma = result.step.interface.coordinates
    for axis in (0, 1):
        assert MPI.COMM_WORLD.allreduce(int(np.count_nonzero(np.isclose(gamma[:, axis], 0.0))), op=MPI.SUM) > 0
        for part in (result.u1, result.u2):
            x = part.function_space.tabulate_dof_coordinates()
            u = part.x.array.reshape(-1, 3)[: x.shape[0]]
            scale = MPI.COMM_WORLD.allreduce(float(np.abs(u).max(initial=0.0)), op=MPI.MAX)
            assert np.abs(u[np.isclose(x[:, axis], 0.0), axis]).max(initial=0.0) <= 1e-12 * scale  # (round-off)


def test_hertz_block_is_tagged_and_refined_under_the_contact():
    """The quarter block at a/4: Γ_C the top, the contact cells of size h_c at the origin, coarse far away."""
    cm = hertz_quarter_block(A, A / 4)
    assert cm.mesh.topology.dim == 3 and cm.h == A / 4
    assert cm.comm.allreduce(cm.facet_tags.find(Boundary.GAMMA_C).size, op=MPI.SUM) > 0
    x = cm.mesh.geometry.x
    assert np.isclose(cm.comm.allreduce(x[:, 0].max(), op=MPI.MAX), 20 * A)
    assert mesh_size(cm.mesh, cm.facet_tags) > 4 * cm.h  # the top face far from the contact is coarse
    with pytest.raises(InputError, match="h_contact < fine"):
        hertz_quarter_block(A, 2 * A)
