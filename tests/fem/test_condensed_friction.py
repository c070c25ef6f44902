"""The condensed frictional Newton (``fem.condensed_friction``) ends at a solution whose nodes lie on the cone's
boundary, where the stick and the slip linearization have the same solution and the state rule flips on round-off."""

from types import SimpleNamespace

import numpy as np
import pytest
from mpi4py import MPI

from fenics_contact.fem.condensed_friction import CondensedFrictionalSystem, CondensedLaw
from fenics_contact.fem.friction import NodalFriction
from fenics_contact.fem.newton import semismooth_newton_loop
from fenics_contact.problem.friction import Friction


def _cone_edge(n: int, seed: int):
    """A 2D Coulomb law (μ = ½, δ = 1, unit stick stiffness and weights, flat Γ_C with zero gap) at n nodes and a
    random SPD compliance M, with the solution U* = (−1, 2) at every node: p = 2, τ = 1 = |t_trial|, exactly on the
    cone's boundary; U_L = U* + M λ(U*)."""
    rng = np.random.default_rng(seed)
    nu, w, gap = np.tile([0.0, 1.0], (n, 1)), np.ones(n), np.zeros(n)
    friction = NodalFriction.__new__(NodalFriction)  # (the law at given nodal values: no subproblem behind it)
    friction.sub = SimpleNamespace(geometry=SimpleNamespace(nodes=lambda: (None, nu, w, gap)))
    friction.law, friction.delta, friction.k_t, friction.d = Friction("coulomb", mu=0.5), 1.0, 1.0, 2
    friction.comm, friction.nodes, friction.free = MPI.COMM_SELF, np.arange(n), np.ones((n, 2), dtype=bool)
    friction.anchor, friction.motion, friction.stiffness = np.zeros((n, 2)), np.zeros(2), np.ones(n)
    friction.forced = friction.frozen = friction.nodal = friction.linearized = friction.committed = None
    A = rng.standard_normal((2 * n, 2 * n))
    M = 0.1 * (A @ A.T / (2 * n) + np.eye(2 * n))
    U = np.tile([-1.0, 2.0], n)
    lam = np.tile([-1.0, 2.0], n)  # w p ν − w t, t = t_trial = (1, 0)
    return friction, M, U, U + M @ lam


@pytest.mark.parametrize("seed", range(5))
def test_a_solution_on_the_cone_boundary_ends_the_newton(seed):
    """Started at the solution linearized in slip, one Newton step (negligible, to an iterate solving the law to
    round-off) ends the Newton, although the state rule predicts stick there."""
    friction, M, U, U_L = _cone_edge(4, seed)
    slip = (np.full(4, 2, dtype=np.int8), np.tile([1.0, 0.0], (4, 1)))
    law = CondensedLaw(friction, M)
    system = CondensedFrictionalSystem(law, U, U_L, energy=False, state=slip)
    trace = semismooth_newton_loop(system, system.key(slip), name="condensed", max_steps=10)
    friction.forced = None
    assert trace.steps == 1
    assert np.max(np.abs(system.U - U)) <= 1e-14
    assert np.linalg.norm(law.residual(system.U, U_L)) <= 1e-14 * np.linalg.norm(U_L)
