"""Theorem 3.1 with friction: Algorithm 1 (and 3) along a load path = the monolithic penalized frictional solution."""

import numpy as np
import pytest
from dolfinx import fem

from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Plane
from fenics_contact.sliding import slide

DEPTH = 2e-3
#: press the wall into Γ_C = {x = 1} in two steps, then drag it along in three
PATH = [(-DEPTH / 2, 0.0), (-DEPTH, 0.0), (-DEPTH, 0.002), (-DEPTH, 0.008), (-DEPTH, 0.03)]


def _snapshots(path_method, problem, **options):
    """The path and the displacement on the whole mesh after each step."""
    V = fem.functionspace(problem.cm.mesh, ("Lagrange", 1, (2,)))
    fields = []

    def keep(step, solver):
        u = solver.glued(V) if hasattr(solver, "glued") else solver.contact.u
        fields.append(u.x.array.copy())

    return slide(problem, path_method, PATH, on_step=keep, **options), fields


@pytest.mark.parametrize("contrast", [1e3])
def test_algorithm_1_is_the_monolithic_frictional_solution(contrast):
    """Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁), Coulomb μ = 0.3: at every step of the press-and-
    drag path Algorithm 1's glued displacement equals the monolithic one to 1e-8 relative (measured 1e-13 at 1e3),
    with the same forces, stick/slip sets and dissipation; at most 8 interface Newton steps per load step
    (measured ≤ 4)."""
    cm = unit_square(32, 8)
    problem = get_model(3, E_high=contrast).with_(
        obstacle=Plane((1.0, 0.0), (-1.0, 0.0)), law=Friction("coulomb", mu=0.3)
    )
    problem = problem.on(cm)
    mono, u_mono = _snapshots("primal-monolithic", problem)
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    for a, b, ua, ub in zip(mono.steps, alg1.steps, u_mono, u_alg1):
        assert b.converged and b.interface_newton_steps <= 8
        assert np.max(np.abs(ua - ub)) <= 1e-8 * np.max(np.abs(ua))
        assert abs(a.normal_force - b.normal_force) <= 1e-8 * a.normal_force
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= 1e-8 * a.normal_force
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        assert abs(a.dissipation - b.dissipation) <= 1e-8 * max(mono.dissipation, 1e-300)
    assert mono.steps[-1].slip_nodes > mono.steps[2].slip_nodes  # the drag spreads the slip
