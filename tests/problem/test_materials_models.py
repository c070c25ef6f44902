"""Materials and models: Lamé parameters, validation, the two built-in maps."""

import numpy as np
import pytest

from fenics_contact.errors import InputError
from fenics_contact.problem.materials import Material, lame
from fenics_contact.problem.models import get_model, model_1, model_2, model_3, paper_phase_model, pixel_field


def test_lame_matches_closed_form():
    lmbda, mu = lame(1.0, 0.25)
    assert np.isclose(lmbda, 0.4) and np.isclose(mu, 0.4)
    E, nu = 1.0e3, 0.35
    lmbda, mu = lame(E, nu)
    # back to (E, ν) by the inverse formulas
    assert np.isclose(mu * (3 * lmbda + 2 * mu) / (lmbda + mu), E)
    assert np.isclose(lmbda / (2 * (lmbda + mu)), nu)


@pytest.mark.parametrize("nu", [0.5, 0.7, -1.0, -1.5, np.nan])
def test_bad_poisson_ratio_rejected(nu):
    with pytest.raises(InputError, match="Poisson"):
        Material(E=1.0, nu=nu)


@pytest.mark.parametrize("E", [0.0, -1.0, np.inf])
def test_bad_youngs_modulus_rejected(E):
    with pytest.raises(InputError, match="Young"):
        Material(E=E, nu=0.3)


def test_models_keep_the_strip_homogeneous_and_high_contrast():
    x = np.random.default_rng(0).random((3, 20000))
    for model in (model_1(), model_2()):
        E = model.youngs_modulus(x)
        assert set(np.unique(E)) == {1.0, 1.0e3}
        assert np.all(E[x[0] > 27 / 32] == 1.0), "pattern must stay in x <= 27/32 < 7/8"
        assert np.all(model.poisson_ratio(x) == 0.35)
        f = model.load(x)
        assert f.shape == (2, x.shape[1]) and np.all(f[1] == 0.0) and np.all(f[0][x[0] < 15 / 16] == 0.0)


def test_model_3_is_hard_where_models_1_and_2_are_easy():
    """Heterogeneous strip: stiff channels reach Γ_C, γ cuts an inclusion for H = 1/4, 1/8, 1/16, load in Ω₁."""
    model = model_3(E_high=1e6)
    s = 1.0 / 32.0
    y = (np.arange(32) + 0.5) * s
    for H in (1 / 4, 1 / 8, 1 / 16):
        xg = 1.0 - H
        left = model.youngs_modulus(np.array([np.full(32, xg - s / 2), y, np.zeros(32)]))
        right = model.youngs_modulus(np.array([np.full(32, xg + s / 2), y, np.zeros(32)]))
        # more stiff cells on γ than the three channels: an inclusion is cut by γ
        assert np.count_nonzero((left == 1e6) & (right == 1e6)) >= 4, H
    at_contact = model.youngs_modulus(np.array([np.full(32, 1.0 - s / 2), y, np.zeros(32)]))
    assert np.count_nonzero(at_contact == 1e6) == 3 and np.count_nonzero(at_contact == 1.0) == 29
    x = np.random.default_rng(2).random((3, 20000))
    f = model.load(x)
    in_omega1 = x[0] < 15 / 16
    assert np.any(f[0][in_omega1] > 0) and np.any(f[0][in_omega1] < 0) and np.all(f[1] == 0.0)


def test_unknown_model_and_pixel_field():
    with pytest.raises(InputError):
        get_model(6)
    field = pixel_field([[1.0, 2.0], [3.0, 4.0]])
    pts = np.array([[0.25, 0.75, 0.25, 0.75], [0.25, 0.25, 0.75, 0.75], [0, 0, 0, 0]])
    assert np.array_equal(field(pts), [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(InputError):
        pixel_field(np.ones(3))


@pytest.mark.parametrize("number", [1, 2])
def test_paper_phase_model_sets_both_phases(number):
    """The paper's §5.4 form: E₁, ν₁ in the pattern, E₂ = 1, ν₂ elsewhere (and in the strip)."""
    model = paper_phase_model(number, E_ratio=1e-4, nu_pattern=0.35, nu_rest=0.499)
    x = np.random.default_rng(1).random((3, 4000))
    E, nu = model.youngs_modulus(x), model.poisson_ratio(x)
    pattern = get_model(number).youngs_modulus(x) > 1.0
    assert pattern.any() and (~pattern).any()
    assert np.all(E[pattern] == 1e-4) and np.all(E[~pattern] == 1.0)
    assert np.all(nu[pattern] == 0.35) and np.all(nu[~pattern] == 0.499)
    assert np.all(nu[x[0] > 7 / 8] == 0.499)
    assert np.array_equal(model.load(x), get_model(number).load(x))
