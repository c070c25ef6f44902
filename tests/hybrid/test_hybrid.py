"""Algorithm 1: fixed point = monolithic solution (Theorem 3.1), updates, caps, bad input."""

import numpy as np
import pytest

from fenics_contact.errors import InputError
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model


def _setup(n, n_coarse, number):
    cm = unit_square(n, n_coarse)
    problem = get_model(number).on(cm)
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(problem, delta=delta)
    return cm, problem, delta, ref


@pytest.mark.parametrize("number", [1, 2])
def test_fixed_point_is_the_monolithic_solution(number):
    """Theorem 3.1: with vertex quadrature on γ the converged iterate equals the monolithic solve."""
    cm, problem, delta, ref = _setup(32, 8, number)
    res = solve_primal_hybrid(
        problem, alpha="E", delta=delta, reference=ref.u, options=IterationOptions(tol=1e-10, accel="anderson")
    )
    assert res.converged
    assert res.e_u <= 1e-8, res.e_u
    assert res.profile.active_interval() == ref.profile.active_interval()
    assert np.allclose(res.profile.sigma_c, ref.profile.sigma_c, atol=1e-7 * np.abs(ref.profile.sigma_c).max())
    # Ω₁ is factorized once; Ω₂ only when its active set changes (fewer times than it takes Newton steps)
    step = res.step
    assert step.sub[0].solver.factorizations == 1
    newton_steps = sum(r.info["newton"] for r in res.history.records)
    assert step.sub[1].solver.factorizations < newton_steps


def test_plain_and_anderson_updates_reach_the_same_solution():
    cm, problem, delta, ref = _setup(16, 4, 1)
    runs = {
        accel: solve_primal_hybrid(
            problem, alpha="E", delta=delta, reference=ref.u, options=IterationOptions(tol=1e-6, accel=accel)
        )
        for accel in ("none", "anderson")
    }
    for res in runs.values():
        assert res.converged and res.e_u < 1e-4
    assert runs["anderson"].iterations < runs["none"].iterations
    # the plain iteration contracts: relative changes fall by orders of magnitude
    changes = runs["none"].history.rel_changes
    assert changes[-1] < 1e-6 < changes[1]


def test_iteration_cap_reports_not_converged():
    cm, problem, delta, _ = _setup(16, 4, 2)
    res = solve_primal_hybrid(problem, delta=delta, options=IterationOptions(max_iterations=4, accel="none"))
    assert not res.converged and res.iterations == 4
    assert res.history.rel_changes[-1] > 1e-6


@pytest.mark.parametrize("alpha", [0.0, -1.0, "foo", "-2E", "0E", float("nan"), "E*h^x", "h^1/0", "E*-1"])
def test_bad_transmission_coefficient(alpha):
    cm, problem, delta, _ = _setup(8, 4, 1)
    with pytest.raises(InputError):
        solve_primal_hybrid(problem, alpha=alpha, delta=delta)


@pytest.mark.parametrize("kwargs", [{"tol": 0.0}, {"tol": 2.0}, {"max_iterations": 0}, {"accel": "magic"}])
def test_bad_iteration_options(kwargs):
    with pytest.raises(InputError):
        IterationOptions(**kwargs)


@pytest.mark.parametrize(
    "alpha, expected",
    [(2.5, 2.5), ("h^-1/2", 4.0), ("sqrt-h", 0.25), ("2*h^-1/2", 8.0), ("E*h^-1/2", 4.0), ("0.5E*h^(1/2)", 0.125)],
)
def test_alpha_spellings(alpha, expected):
    from fenics_contact.hybrid.transmission import InterfaceSpace, robin_coefficient, split_mesh

    cm = unit_square(16, 8)
    space = InterfaceSpace(cm, split_mesh(cm), shape=(2,))
    E = material_fields(cm.mesh, get_model(1)).E
    assert np.allclose(robin_coefficient(alpha, E, space, cm.h), expected)
    # γ at x = 7/8 lies in the homogeneous E = 1 region: α_p = 3·1
    assert np.allclose(robin_coefficient("3E", E, space, cm.h), 3.0)
    # lengths in a unit L times smaller (h·L, L_ref = L): a spelling with a symbol is a stiffness per length
    # (α/L: h read as h/L_ref), a number is taken as given
    L = 1e-3
    scaled = robin_coefficient(alpha, E, space, cm.h * L, L)
    assert np.allclose(scaled, expected if isinstance(alpha, float) else expected / L, rtol=1e-14)


def test_alpha_scaled_by_the_local_modulus():
    """γ at x = 3/4 crosses the channels of model 1: α_p = c · (area-weighted mean E around p)."""
    from fenics_contact.hybrid.transmission import InterfaceSpace, robin_coefficient, split_mesh

    cm = unit_square(32, 4)
    space = InterfaceSpace(cm, split_mesh(cm), shape=(2,))
    alpha = robin_coefficient("2E", material_fields(cm.mesh, get_model(1)).E, space, cm.h)
    y = space.coordinates[:, 1].repeat(2)
    # channel k occupies y in [(4k+2)/32, (4k+3)/32]: nodes strictly inside a channel's y-range do
    # not exist at h = 1/32, nodes on its edges see half high-modulus cells (6 cells, 3 of them E=1e3)
    on_channel_edge = np.isclose((y * 32) % 4, 2) | np.isclose((y * 32) % 4, 3)
    assert np.allclose(alpha[on_channel_edge], 2 * (1e3 + 1) / 2)
    assert np.allclose(alpha[~on_channel_edge], 2.0)
