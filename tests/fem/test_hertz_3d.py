"""3D Hertz at contact cells of a/20: a rigid sphere on the quarter block of ``meshes3d.hertz_quarter_block``."""

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.amg import LinearSolverOptions
from fenics_contact.fem.primal import solve_primal_monolithic
from fenics_contact.problem.analytic import hertz_sphere_errors, hertz_sphere_model, hertz_sphere_penalty
from fenics_contact.problem.geometry import mesh_size
from fenics_contact.problem.meshes3d import hertz_quarter_block
from fenics_contact.problem.tags import Boundary

A, R, E, NU = 0.1, 1.0, 1.0, 0.3  # a/R = 0.1; the block 20a


def _errors(cells: int):
    """The Hertz errors with contact cells h_c = a/``cells``, δ = 10⁻³ h_c/E*, CG + AMG."""
    h = A / cells
    problem = hertz_sphere_model(A, h, radius=R, E=E, nu=NU)
    solution = solve_primal_monolithic(
        problem, delta=hertz_sphere_penalty(h, E=E, nu=NU), solver=LinearSolverOptions(kind="amg")
    )
    return solution, hertz_sphere_errors(solution.profile, radius=R, E=E, nu=NU, h_contact=h)


@pytest.mark.slow
def test_hertz_sphere_at_a_over_20():
    """Measured (26,901 DOFs at a/20, 7 Newton steps of 25–33 CG iterations): the area-equivalent contact radius
    −0.00 h_c from a, the centre pressure −0.6 % from p₀, the L² profile error 3.1 % (4.9 % at a/10: 1.6×)."""
    coarse_solution, coarse = _errors(10)
    solution, fine = _errors(20)
    h = A / 20
    assert abs(fine.radius - fine.a) <= h
    assert abs(fine.centre_error) <= 0.03
    assert fine.l2_error <= 0.04 and coarse.l2_error >= 1.3 * fine.l2_error
    assert abs(coarse.radius - coarse.a) <= A / 10
    assert max(solution.krylov_iterations) <= 80  # AMG: flat in the Newton steps and the refinement
    assert solution.profile.penetration == pytest.approx(solution.delta * solution.profile.max_pressure, rel=1e-6)


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
