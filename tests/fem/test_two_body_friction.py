"""Friction between two deformable bodies (``fem.two_body_friction``): two blocks on non-matching meshes pressed
together, then sheared past sliding: the tangential force μ × the normal force (Coulomb) and s × the contact
length (Tresca), equal and opposite forces on the two bodies, the stick-to-slip transition, dissipation ≥ 0;
μ = 0 is the frictionless solve; what is refused."""

import numpy as np
import pytest
from mpi4py import MPI
from pair_problems import pressed_pair

import fenics_contact as fc
from fenics_contact.errors import InputError
from fenics_contact.fem.two_body import PairState, solve_two_body
from fenics_contact.problem.pair import Body, ContactPair, Support, TwoBodyProblem
from fenics_contact.problem.pair_meshes import PairTag as T
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body friction runs on one process")

#: press the upper block's top down by 0.01, then move it along x (the last step slides the whole face)
PATH = ((0.0, -0.005), (0.0, -0.01), (0.002, -0.01), (0.01, -0.01), (0.03, -0.01))
MU, S = 0.3, 0.002


@pytest.fixture(scope="module")
def blocks():
    return two_blocks(7, 10, heights=(0.5, 0.4))  # 7 against 10 cells across the fault: non-matching


def _problem(m, law, top, *, slave="upper", basis=None):
    """The lower block (E = 1, ν = 0.3) clamped at its bottom, the upper (E = 5, ν = 0.2) with its top moved by
    ``top``; the contact face 1 wide; ``basis`` of the pressure (None: the pair's default)."""
    lower, upper = Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)
    return pressed_pair(m, lower, upper, top, upper_slave=slave == "upper", friction=law, basis=basis)


def _path(m, law, **kw):
    state, out = None, []
    for top in PATH:
        solution = solve_two_body(_problem(m, law, top, **kw), state=state)
        state = solution.state
        out.append(solution)
    return out


@pytest.mark.parametrize("slave", ["upper", "lower"])
def test_coulomb_sliding_blocks_carry_mu_times_the_normal_force(blocks, slave):
    """Pressed, the faces stick; sheared, slip spreads from the edges; past sliding every slave node slips and
    the tangential force is μ × the normal force, opposing the upper block's motion; the two bodies' forces are
    equal and opposite; each step dissipates ≥ 0."""
    path = _path(blocks, fc.Friction("coulomb", mu=MU), slave=slave)
    upper = 0 if slave == "upper" else 1  # the upper block's resultant: forces[upper]
    for solution in path:
        assert solution.force_balance() < 1e-13
        assert solution.dissipation >= -1e-15 * np.abs(solution.forces[0]).sum() * 0.01
        assert np.all(solution.friction.stick | solution.friction.slip)  # in contact everywhere
    assert np.count_nonzero(path[2].friction.stick) > np.count_nonzero(path[2].friction.slip)
    last = path[-1]
    assert np.all(last.friction.slip)
    force = last.forces[upper]
    assert force[1] > 0.0 and force[0] < 0.0  # pushed up, dragged back against the motion +x
    assert abs(force[0]) == pytest.approx(MU * force[1], rel=1e-10)
    f = last.friction
    assert np.linalg.norm(f.tangential_force) == pytest.approx(MU * f.normal_force, rel=1e-10)
    assert last.dissipation > 0.0


def test_tresca_sliding_blocks_carry_the_threshold_times_the_contact_length(blocks):
    """Past sliding the tangential force is s × |Γ_C| (the face is 1 wide); in the last step the face slides
    rigidly by 0.02 more, dissipating s × 1 × 0.02 up to the elastic change of the slip."""
    path = _path(blocks, fc.Friction("tresca", threshold=S))
    last = path[-1]
    assert np.all(last.friction.slip)
    assert abs(last.forces[0][0]) == pytest.approx(S * 1.0, rel=1e-10)
    assert last.forces[0][0] == pytest.approx(-last.forces[1][0], rel=1e-12)
    assert last.dissipation == pytest.approx(S * 0.02, rel=1e-3)
    assert all(s.dissipation >= 0.0 for s in path)


@pytest.mark.parametrize("basis", ["dual", "standard"])
def test_zero_friction_is_the_frictionless_solve(blocks, basis):
    """Coulomb with μ = 0 on a flat interface, either pressure basis: the frictionless solution of that basis and
    its contact force to round-off."""
    top = (0.004, -0.01)
    free = solve_two_body(_problem(blocks, None, top, basis=basis))
    coulomb = solve_two_body(_problem(blocks, fc.Friction("coulomb", mu=0.0), top, basis=basis))
    u0, u1 = free.u.x.array, coulomb.u.x.array
    assert np.linalg.norm(u1 - u0) <= 1e-10 * np.linalg.norm(u0)
    assert np.allclose(coulomb.forces[0], free.forces[0], rtol=1e-10, atol=1e-14)
    assert coulomb.dissipation == 0.0


def test_the_state_carries_the_slip_of_the_path(blocks):
    """Back at the pressed position after sliding, the faces keep a locked-in shear (the slip stays) of the
    order of the sliding force, where the pressed position solved alone has next to none; a frictionless solve
    accepts a state and returns one without anchors."""
    law = fc.Friction("coulomb", mu=MU)
    path = _path(blocks, law)
    back = solve_two_body(_problem(blocks, law, PATH[1]), state=path[-1].state)
    alone = solve_two_body(_problem(blocks, law, PATH[1]))
    sliding = abs(path[-1].forces[0][0])
    assert abs(back.forces[0][0]) > 0.5 * sliding
    assert abs(alone.forces[0][0]) < 1e-3 * sliding
    assert back.dissipation > 0.0
    assert isinstance(path[-1].state, PairState) and path[-1].state.anchor.shape == (path[-1].friction.weights.size, 2)
    free = solve_two_body(_problem(blocks, None, PATH[1]), state=path[0].state)
    assert free.state.anchor is None


def test_bad_friction_input_is_refused(blocks):
    with pytest.raises(InputError, match="Friction"):
        ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction="coulomb")
    with pytest.raises(InputError, match="PairState"):
        solve_two_body(_problem(blocks, fc.Friction("coulomb", mu=MU), PATH[0]), state=np.zeros(3))
    other = two_blocks(5, 6, heights=(0.5, 0.4))
    foreign = solve_two_body(_problem(other, fc.Friction("coulomb", mu=MU), PATH[0])).state
    with pytest.raises(InputError, match="the same mesh and pair"):
        solve_two_body(_problem(blocks, fc.Friction("coulomb", mu=MU), PATH[0]), state=foreign._replace(u=None))


@pytest.mark.parametrize(
    ("law", "bound"),
    [(fc.Friction("coulomb", mu=MU), "mu"), (fc.Friction("tresca", threshold=S), "threshold")],
    ids=["coulomb", "tresca"],
)
def test_sliding_cubes_in_3d(law, bound):
    """Two cubes (3 against 4 cells across) pressed, then sheared along (2, 1) past sliding: the tangential
    plane of the law is a plane; every slave node slips, Σ w_p|t_p| is μ Σ w_p p_p (Coulomb) or s |Γ_C| (Tresca),
    the tangential force opposes the motion, the forces balance to round-off."""
    m = two_blocks(3, 4, heights=(0.5, 0.4), dim=3)
    state = None
    for top in ((0.0, 0.0, -0.01), (0.01, 0.005, -0.01), (0.04, 0.02, -0.01)):
        problem = TwoBodyProblem(
            m.mesh,
            m.cell_tags,
            m.facet_tags,
            bodies=(Body(T.LOWER, 1.0, 0.3), Body(T.UPPER, 5.0, 0.2)),
            pair=ContactPair(T.UPPER_BOTTOM, T.LOWER_TOP, friction=law),
            supports=(Support(T.LOWER_BOTTOM), Support(T.UPPER_TOP, top)),
        )
        solution = solve_two_body(problem, state=state)
        state = solution.state
        assert solution.force_balance() < 1e-13 and solution.dissipation >= 0.0
    f = solution.friction
    assert np.all(f.slip)
    carried = np.sum(f.weights * np.linalg.norm(f.traction, axis=1))
    expected = MU * f.normal_force if bound == "mu" else S * 1.0  # the face is 1 × 1
    assert carried == pytest.approx(expected, rel=1e-10)
    direction = f.tangential_force / np.linalg.norm(f.tangential_force)
    assert direction @ np.array([2.0, 1.0, 0.0]) / np.sqrt(5.0) < -0.999
