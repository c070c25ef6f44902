"""Monolithic penalized primal contact: Newton termination, complementarity, active sets, penalty limit."""

import numpy as np
import pytest

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

N = 32


@pytest.fixture(scope="module")
def mesh32():
    return unit_square(N, 8)


@pytest.mark.parametrize("number, expected", [(1, (0.0, 0.5)), (2, (0.4, 0.6))])
def test_complementarity_and_active_set(mesh32, number, expected):
    cm = mesh32
    problem = get_model(number).on(cm)
    delta = default_penalty(cm.h, 1.0)
    sol = solve_primal_monolithic(problem, delta=delta)
    assert 1 <= sol.newton.steps <= 8
    p = sol.profile
    scale = np.max(np.abs(p.sigma_c))
    assert scale > 0.05, "the load must press the body onto the obstacle"
    # σ_c ≤ 0 (no tension), and the penalty law σ_c = −(u_c)⁺/δ at every Γ_C node
    assert np.max(p.sigma_c) <= 1e-9 * scale
    assert np.allclose(p.sigma_c, -np.maximum(p.u_c, 0.0) / delta, rtol=0, atol=1e-8 * scale)
    # separated nodes carry no stress; contact nodes penetrate only at the penalty level
    assert np.all(np.abs(p.sigma_c[p.u_c < 0]) <= 1e-8 * scale)
    assert p.penetration <= delta * scale * (1 + 1e-8)
    assert p.penetration < 1e-3 * np.max(np.abs(p.u_c))  # far below the P1 error at h = 1/32
    lo, hi = p.active_interval()
    assert abs(lo - expected[0]) <= 2.5 / N and abs(hi - expected[1]) <= 2.5 / N, (lo, hi)


def test_penetration_vanishes_with_the_penalty(mesh32):
    cm = mesh32
    problem = get_model(1).on(cm)
    pen = [solve_primal_monolithic(problem, delta=f * cm.h).profile.penetration for f in (1e-1, 1e-3, 1e-5)]
    ratios = np.array(pen[:-1]) / np.array(pen[1:])
    assert np.all((ratios > 50) & (ratios < 200)), pen  # penetration = O(δ)


def test_bad_penalty_and_newton_cap(mesh32):
    cm = mesh32
    problem = get_model(2).on(cm)
    with pytest.raises(InputError, match="δ"):
        solve_primal_monolithic(problem, delta=0.0)
    with pytest.raises(ConvergenceError, match="did not converge"):
        solve_primal_monolithic(
            problem, delta=default_penalty(cm.h, 1.0), newton=NewtonOptions(max_iterations=1), prefix="capped_"
        )
