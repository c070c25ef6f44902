"""Algorithm 2 (fenics_contact.hybrid.mixed): fixed point, tolerance 1e-6 errors, β, ν → ½, bad input.

Run from the repository root:  .venv/bin/python -m pytest tests/hybrid/test_mixed_hybrid.py -q
"""

import numpy as np
import pytest

from fenics_contact.errors import InputError
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid, transmission_coefficient
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

#: H = 1/16 (γ at x = 15/16, three cells of h = 1/32 from the heterogeneity; the loads act on x ≥ 15/16)
N_COARSE = 16


def _incompressible(ratio, nu1, nu2):
    """Model 1 with E = ratio in the channels (E₂ = 1 elsewhere), ν₁ in the channels, ν₂ elsewhere."""
    pattern = get_model(1, E_high=2.0, E_low=1.0).youngs_modulus
    return get_model(1, E_high=ratio, E_low=1.0).with_(poisson_ratio=lambda x: np.where(pattern(x) > 1.5, nu1, nu2))


@pytest.fixture(scope="module")
def mesh():
    return unit_square(32, N_COARSE)


@pytest.fixture(scope="module")
def mesh64():
    return unit_square(64, N_COARSE)


@pytest.fixture(scope="module")
def references(mesh):
    """Per model at h = 1/32: the AW monolithic solution and the one on X̃_h (σ_tt split at the γ vertices)."""
    return {
        m: (
            solve_mixed_monolithic(get_model(m).on(mesh)),
            solve_mixed_monolithic(get_model(m).on(mesh), split_interface=True),
        )
        for m in (1, 2)
    }


@pytest.fixture(scope="module")
def references64(mesh64):
    """Per model at h = 1/64: the AW monolithic solution."""
    return {m: solve_mixed_monolithic(get_model(m).on(mesh64)) for m in (1, 2)}


def _distance(step, solution):
    """(e_σ, e_u) of the step's current iterate against a monolithic solution."""
    step.set_reference(solution)
    return step.errors()


def _space_gap(cm, model, aw, split):
    """(e_σ, e_u) between the monolithic solutions on X̃_h and X_h (restricted to the parts)."""
    step = MixedHybridStep(model.on(cm), beta=1.0, epsilon=aw.epsilon)
    step.set_reference(split)
    for sub, (c, u) in zip(step.sub, step.reference):
        sub.c[:], sub.u[:] = c, u
    return _distance(step, aw)


@pytest.mark.parametrize("number", [1, 2])
@pytest.mark.slow
def test_fixed_point_is_the_split_monolithic_solution(mesh, references, number):
    """At tight tolerance the iterate is the monolithic solution on X̃_h to round-off, and its distance
    to the AW monolithic solution is exactly the X̃_h/X_h space difference."""
    aw, split = references[number]
    res = solve_mixed_hybrid(
        get_model(number).on(mesh),
        beta="sqrt-h",
        reference=split,
        options=IterationOptions(tol=1e-11, accel="anderson"),
    )
    assert res.converged
    assert res.e_sigma < 1e-8 and res.e_u < 1e-8, (res.e_sigma, res.e_u)
    gap = _space_gap(mesh, get_model(number), aw, split)
    to_aw = _distance(res.step, aw)
    assert np.allclose(to_aw, gap, rtol=1e-4), (to_aw, gap)
    # measured at h = 1/32: e_σ 9.1e-4 (model 1) and 1.09e-3 (model 2), e_u 1.7e-5 / 1.6e-5
    assert 1e-5 < gap[0] < 2e-3 and gap[1] < 5e-5, gap
    # Ω₁ is factorized once; Ω₂ only when its active set changes
    s1, s2 = res.step.sub
    assert s1.solver.factorizations == 1
    newton_steps = sum(r.info["newton"] for r in res.history.records)
    assert s2.solver.factorizations < newton_steps / 2
    assert res.profile.active_interval() == split.profile.active_interval()


@pytest.mark.slow
def test_space_difference_shrinks_with_h(mesh, mesh64, references, references64):
    """The X̃_h/X_h difference is a discretization effect: ≥ 4× smaller at h = 1/64 (measured 6.4×)."""
    model = get_model(1)
    gap32 = _space_gap(mesh, model, *references[1])
    split64 = solve_mixed_monolithic(model.on(mesh64), split_interface=True)
    gap64 = _space_gap(mesh64, model, references64[1], split64)
    assert gap64[0] < gap32[0] / 4 and gap64[1] < gap32[1] / 4, (gap32, gap64)
    assert gap64[0] < 3e-4, gap64


@pytest.mark.parametrize("number", [1, 2])
@pytest.mark.slow
def test_paper_tolerance_and_beta(mesh, references, number):
    """Plain update (the paper's), tolerance 1e-6, β = 1 and √h at h = 1/32: errors ≤ 1e-4 against the
    exact fixed point (X̃_h), within the measured space gap + 1e-4 of the AW solution; √h needs fewer
    iterations; the recorded errors fall."""
    aw, split = references[number]
    gap = _space_gap(mesh, get_model(number), aw, split)
    runs = {
        beta: solve_mixed_hybrid(
            get_model(number).on(mesh), beta=beta, reference=split, options=IterationOptions(tol=1e-6, accel="none")
        )
        for beta in (1.0, "sqrt-h")
    }
    for res in runs.values():
        assert res.converged
        assert res.history.rel_changes[-1] < 1e-6
        assert res.e_sigma <= 1e-4 and res.e_u <= 1e-4, (res.e_sigma, res.e_u)
        to_aw = _distance(res.step, aw)
        assert to_aw[0] <= gap[0] + 1e-4 and to_aw[1] <= gap[1] + 1e-4, (to_aw, gap)
        assert set(res.dofs) == {"omega1", "omega2", "interface"}
        assert res.time_online_s > 0 and res.time_offline_s > 0
    assert runs["sqrt-h"].iterations < runs[1.0].iterations
    e = [r.info["e_sigma"] for r in runs["sqrt-h"].history.records]
    assert e[-1] < 1e-2 * e[0]


@pytest.mark.parametrize("number", [1, 2])
@pytest.mark.slow
def test_paper_tolerance_against_the_aw_solution(mesh64, references64, number):
    """h = 1/64, β = √h, plain update, tolerance 1e-6: e_σ, e_u ≤ 1e-3 against the monolithic AW solution."""
    res = solve_mixed_hybrid(
        get_model(number).on(mesh64),
        beta="sqrt-h",
        reference=references64[number],
        options=IterationOptions(tol=1e-6, accel="none"),
    )
    assert res.converged
    assert res.e_sigma <= 1e-3 and res.e_u <= 1e-3, (res.e_sigma, res.e_u)


@pytest.mark.slow
def test_anderson_acceleration(mesh, references):
    """Anderson on the interface data: same fixed point, fewer iterations than the plain update."""
    _, split = references[2]
    plain = solve_mixed_hybrid(
        get_model(2).on(mesh), beta="sqrt-h", reference=split, options=IterationOptions(tol=1e-6, accel="none")
    )
    anderson = solve_mixed_hybrid(
        get_model(2).on(mesh), beta="sqrt-h", reference=split, options=IterationOptions(tol=1e-6, accel="anderson")
    )
    assert anderson.converged and anderson.iterations < plain.iterations
    assert anderson.e_sigma < 1e-4 and anderson.e_u < 1e-4


@pytest.mark.parametrize("nu1, nu2, ratio", [(0.4999, 0.35, 1e4), (0.35, 0.4999, 1e-4), (0.4999, 0.4999, 1.0)])
@pytest.mark.slow
def test_nearly_incompressible(mesh, nu1, nu2, ratio):
    """Table 5.4 cases at ν = 0.4999, h = 1/32, plain update, β = √h: converged at 1e-6 with
    e_σ, e_u ≤ 1e-4 against the exact fixed point (X̃_h)."""
    model = _incompressible(ratio, nu1, nu2)
    split = solve_mixed_monolithic(model.on(mesh), split_interface=True)
    res = solve_mixed_hybrid(
        model.on(mesh), beta="sqrt-h", reference=split, options=IterationOptions(tol=1e-6, accel="none")
    )
    assert res.converged
    assert res.e_sigma <= 1e-4 and res.e_u <= 1e-4, (res.e_sigma, res.e_u)


@pytest.mark.slow
def test_nearly_incompressible_against_the_aw_solution(mesh64):
    """ν₁ = ν₂ = 0.4999 at h = 1/64: e_σ, e_u ≤ 1e-3 against the monolithic AW solution."""
    model = _incompressible(1.0, 0.4999, 0.4999)
    aw = solve_mixed_monolithic(model.on(mesh64))
    res = solve_mixed_hybrid(
        model.on(mesh64), beta="sqrt-h", reference=aw, options=IterationOptions(tol=1e-6, accel="none")
    )
    assert res.converged
    assert res.e_sigma <= 1e-3 and res.e_u <= 1e-3, (res.e_sigma, res.e_u)


def test_iteration_cap_reports_not_converged(mesh):
    res = solve_mixed_hybrid(get_model(1).on(mesh), beta=1.0, options=IterationOptions(max_iterations=3, accel="none"))
    assert not res.converged and res.iterations == 3 and res.e_sigma is None


@pytest.mark.parametrize("beta, expected", [(2.5, 2.5), ("1", 1.0), ("sqrt-h", 0.125), (" h^1/2 ", 0.125)])
def test_beta_spellings(beta, expected):
    assert transmission_coefficient(beta, 1 / 64) == pytest.approx(expected)


@pytest.mark.parametrize("beta", [0.0, -1.0, "foo", "-2", float("nan"), float("inf")])
def test_rejects_bad_beta(beta):
    with pytest.raises(InputError, match="β|beta"):
        transmission_coefficient(beta, 1 / 16)
    cm = unit_square(8, 4)
    with pytest.raises(InputError):
        solve_mixed_hybrid(get_model(1).on(cm), beta=beta)


def test_rejects_poisson_ratio_out_of_range():
    cm = unit_square(8, 4)
    with pytest.raises(InputError, match="Poisson"):
        solve_mixed_hybrid(get_model(2, nu=0.5).on(cm))
