"""``solve_two_body(initial=…)``: a warm start (a load step started from the last) reaches the cold solve's
solution, the unique minimizer of the convex penalized energy, and from that solution itself Newton has
nothing left to do."""

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.two_body import solve_two_body
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body contact runs on one process")

GAP = 0.004


def _pushed(mesh, d: float) -> TwoBodyProblem:
    """The upper block pushed down by d onto the lower one across the gap GAP (clamped bottom, moved top)."""
    return TwoBodyProblem(
        mesh.mesh,
        mesh.cell_tags,
        mesh.facet_tags,
        bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
        pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP),
        supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, (0.0, -d))),
    )


def test_a_warm_start_reaches_the_cold_solution():
    mesh = two_blocks(7, 10, heights=(0.5, 0.4), gap=GAP)
    apart = solve_two_body(_pushed(mesh, 0.5 * GAP))  # no contact yet: the upper block moved down rigidly
    assert apart.slave.force == 0.0
    cold = solve_two_body(_pushed(mesh, 3 * GAP))
    warm = solve_two_body(_pushed(mesh, 3 * GAP), initial=apart.u.x.array)
    assert cold.slave.force > 0.0
    scale = np.max(np.abs(cold.u.x.array))
    assert np.max(np.abs(warm.u.x.array - cold.u.x.array)) < 1e-10 * scale
    again = solve_two_body(_pushed(mesh, 3 * GAP), initial=cold.u.x.array)
    assert again.newton.steps <= 1 < cold.newton.steps
    assert np.max(np.abs(again.u.x.array - cold.u.x.array)) < 1e-10 * scale


def test_a_bad_initial_state_is_refused():
    problem = _pushed(two_blocks(3, 4, heights=(0.5, 0.4)), 0.01)
    with pytest.raises(InputError, match="initial must hold"):
        solve_two_body(problem, initial=np.zeros(5))
    with pytest.raises(InputError, match="finite"):
        solve_two_body(problem, initial=np.full(10**4, np.nan))
