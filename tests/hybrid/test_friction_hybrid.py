"""Theorem 3.1 with friction: Algorithm 1 along a load path = the monolithic penalized frictional solution;
Algorithm 3 within its multiscale error of it."""

import numpy as np
import pytest
from friction_paths import snapshots

from fenics_contact.problem.friction import Friction
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Plane

DEPTH = 2e-3
#: press the wall into Γ_C = {x = 1} in two steps, then drag it along in three
PATH = [(-DEPTH / 2, 0.0), (-DEPTH, 0.0), (-DEPTH, 0.002), (-DEPTH, 0.008), (-DEPTH, 0.03)]


def _snapshots(method, problem, **options):
    return snapshots(method, problem, PATH, **options)


@pytest.fixture(scope="module", params=[1e3, 1e6], ids=["contrast1e3", "contrast1e6"])
def model3(request):
    """Model 3 (stiff channels through γ up to Γ_C, loads in Ω₁) at contrast 1e3 and 1e6, Coulomb μ = 0.3,
    h = 1/32, H = 1/8, with its monolithic path."""
    wall = Plane((1.0, 0.0), (-1.0, 0.0))
    model = get_model(3, E_high=request.param).with_(obstacle=wall, law=Friction("coulomb", mu=0.3))
    problem = model.on(unit_square(32, 8))
    return problem, *_snapshots("primal-monolithic", problem)


def _same_paths(mono, u_mono, alg1, u_alg1):
    for a, b, ua, ub in zip(mono.steps, alg1.steps, u_mono, u_alg1):
        assert b.converged
        assert np.max(np.abs(ua - ub)) <= 1e-8 * np.max(np.abs(ua))
        assert abs(a.normal_force - b.normal_force) <= 1e-8 * a.normal_force
        # the sticking nodes' shear is the stick penalty times their displacement: at contrast 1e6 a displacement
        # equal to 1e-12 gives a tangential force equal to 1e-8 (measured 1.2e-8 of the normal force)
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= 5e-8 * a.normal_force
        assert np.array_equal(a.friction.stick, b.friction.stick) and np.array_equal(a.friction.slip, b.friction.slip)
        assert abs(a.dissipation - b.dissipation) <= 1e-8 * mono.dissipation
    assert mono.steps[-1].slip_nodes > mono.steps[2].slip_nodes  # the drag spreads the slip


def test_algorithm_1_is_the_monolithic_frictional_solution(model3):
    """At every step of the press-and-drag path Algorithm 1's glued displacement equals the monolithic one to 1e-8
    relative, with the same forces, stick/slip sets and dissipation.  The interface Newton (the default condensed
    strategy: the frictional contact solved on all Γ_C displacement components, ``hybrid.friction``) applies T at
    most 4 times per load step and takes at most 3 Newton steps on the interface data after the condensed solve
    (measured).  Its dense contact Newton on the Γ_C unknowns (``fem.condensed_friction.solve_condensed``) and the
    monolithic frictional Newton take at most 8 steps at every load step, the first press from the unloaded state
    included (measured 8 there at both contrasts: the thresholds' fixed point from a bonded press, then the Newton
    on the law; 2–5 on the later steps from the committed state), every Newton that did not converge counted."""
    problem, mono, u_mono = model3
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11)
    _same_paths(mono, u_mono, alg1, u_alg1)
    for a, b in zip(mono.steps, alg1.steps, strict=True):
        assert b.iterations <= 8 and b.interface_newton_steps - b.contact_newton_steps <= 8
        assert b.contact_newton_steps <= 8 and a.iterations <= 8


@pytest.mark.slow
def test_algorithm_1_interface_strategy(model3):
    """The same with the ``"interface"`` strategy (Newton on g = T(g), Ω₂'s frictional Jacobian): at most 8
    interface Newton steps per load step at contrast 1e3 (measured ≤ 4; at 1e6 a drag step ends unconverged,
    docs/limits.md and tests/hybrid/test_interface_newton_globalization.py)."""
    problem, mono, u_mono = model3
    if problem.contact_modulus() > 1e3:
        pytest.skip("the interface strategy leaves a drag step unconverged at contrast 1e6 (docs/limits.md)")
    alg1, u_alg1 = _snapshots("primal", problem, tol=1e-11, strategy="interface")
    _same_paths(mono, u_mono, alg1, u_alg1)
    assert all(step.interface_newton_steps <= 8 for step in alg1.steps)


def test_algorithm_3_along_the_frictional_path(model3):
    """Algorithm 3 (multiscale Ω₁, the same Ω₂ and friction): within its multiscale error of the monolithic path at
    every step (measured 1.8e-4 in the displacement, 5e-7 in the forces relative to the normal force, at 1e3), at
    most 8 interface Newton steps per load step (measured ≤ 2)."""
    problem, mono, u_mono = model3
    if problem.contact_modulus() > 1e3:
        pytest.skip("Algorithm 3 at contrast 1e3 only (its multiscale error grows with the contrast)")
    alg3, u_alg3 = _snapshots("primal-ms", problem, tol=1e-10)
    for a, b, ua, ub in zip(mono.steps, alg3.steps, u_mono, u_alg3):
        assert b.converged and b.interface_newton_steps <= 8
        assert np.max(np.abs(ua - ub)) <= 1e-3 * np.max(np.abs(ua))
        assert abs(a.normal_force - b.normal_force) <= 1e-5 * a.normal_force
        assert np.max(np.abs(a.tangential_force - b.tangential_force)) <= 1e-5 * a.normal_force
        assert b.dissipation >= 0.0
