"""Materials and models: Lamé parameters, validation, the two built-in maps."""

import numpy as np
import pytest

from fenics_contact.errors import InputError
from fenics_contact.materials import Material, lame
from fenics_contact.models import get_model, model_1, model_2, pixel_field


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


def test_unknown_model_and_pixel_field():
    with pytest.raises(InputError):
        get_model(3)
    field = pixel_field([[1.0, 2.0], [3.0, 4.0]])
    pts = np.array([[0.25, 0.75, 0.25, 0.75], [0.25, 0.25, 0.75, 0.75], [0, 0, 0, 0]])
    assert np.array_equal(field(pts), [1.0, 2.0, 3.0, 4.0])
    with pytest.raises(InputError):
        pixel_field(np.ones(3))
