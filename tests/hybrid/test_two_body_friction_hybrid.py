"""Algorithm 1 for two bodies with friction (``hybrid.two_body`` with ``fem.two_body_friction`` strips): along a
press-then-shear path on a layered pair (strata of contrast 1e3 with inclusions, non-matching meshes) the
fixed point is the monolithic frictional solution (Theorem 3.1) step by step, the interface Newton needs at most
8 evaluations of T per load step, and the friction state and dissipation are the monolithic ones."""

import numpy as np
import pytest
from mpi4py import MPI
from pair_problems import strata_pair

import fenics_contact as fc
from fenics_contact.problem.pair_meshes import two_blocks

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="two-body Algorithm 1 runs on one process")

CONTRAST = 1e3
PATH = ((0.0, -0.005), (0.0, -0.01), (0.002, -0.01), (0.005, -0.01), (0.01, -0.01), (0.02, -0.01))


@pytest.fixture(scope="module")
def blocks():
    return two_blocks(16, 21, heights=(0.5, 0.4))


@pytest.mark.parametrize(
    "law", [fc.Friction("coulomb", mu=0.3), fc.Friction("tresca", threshold=0.002)], ids=["coulomb", "tresca"]
)
def test_algorithm_1_is_the_monolithic_frictional_path(blocks, law):
    m = blocks
    states = [None, None]
    slipped = False
    for top in PATH:
        problem = strata_pair(m, law, top, contrast=CONTRAST)
        mono = fc.solve(problem, "primal-monolithic", state=states[0])
        hybrid = fc.solve(problem, "primal", state=states[1])
        states = [mono.state, hybrid.state]
        assert hybrid.converged and hybrid.iterations <= 8
        u0 = mono.u.x.array
        assert np.linalg.norm(hybrid.u.x.array - u0) <= 1e-8 * np.linalg.norm(u0)
        assert np.allclose(hybrid.forces[0], mono.forces[0], rtol=1e-8, atol=1e-12)
        assert hybrid.force_balance() < 1e-12
        assert np.array_equal(hybrid.friction.slip, mono.friction.slip)
        assert hybrid.dissipation >= 0.0
        assert hybrid.dissipation == pytest.approx(mono.dissipation, rel=1e-6, abs=1e-14)
        slipped |= bool(np.any(mono.friction.slip))
    assert np.all(mono.friction.slip) and slipped


def test_a_state_warm_starts_the_frictionless_interface_newton(blocks):
    """Without friction a state carries the displacement and the interface data only: the next step starts
    from them, in no more evaluations of T than from zero, and reaches the monolithic solution."""
    m = blocks
    state = None
    for top in ((0.0, -0.005), (0.0, -0.01)):
        problem = strata_pair(m, top=top, contrast=CONTRAST)
        warm = fc.solve(problem, "primal", state=state)
        state = warm.state
        assert state.anchor is None and warm.friction is None and warm.dissipation == 0.0
    cold = fc.solve(problem, "primal")
    mono = fc.solve(problem, "primal-monolithic")
    assert warm.converged and warm.iterations <= cold.iterations
    u0 = mono.u.x.array
    assert np.linalg.norm(warm.u.x.array - u0) <= 1e-8 * np.linalg.norm(u0)
