"""Algorithm 3 carries the evidence of its Ω₁ accuracy: the multiscale Ω₁ against the fine Ω₁ solve for the run's own
interface data (``Omega1Multiscale.fine_check``), without a monolithic reference."""

import logging

import pytest

import fenics_contact as fc
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import OMEGA1_CHECK_WARN


@pytest.fixture(scope="module")
def free_bottom():
    """Model 3 (stiff channels through γ, loads in Ω₁) with a traction-free bottom, and its fine solution."""
    problem = fc.models.model_3(E_high=1e3).on(fc.unit_square(32, 8, clamped=("left", "top")))
    return problem, fc.solve(problem, "primal-monolithic")


@pytest.mark.slow
def test_the_omega1_check_tracks_the_energy_error(free_bottom, caplog):
    """Measured, m = 1, 2, 3: check 0.261, 2.05e-2, 1.78e-3 against the coupled energy error 0.268, 2.14e-2, 1.85e-3;
    a warning above ``OMEGA1_CHECK_WARN`` (m = 1, 2) and none below it (m = 3)."""
    problem, reference = free_bottom
    for m in (1, 2, 3):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="fenics_contact"):
            result = fc.solve(problem, "primal-ms", cem=CEMOptions(layers=m), reference=reference.u)
        error = result.step.error_energy()
        assert result.converged and 0.8 * error < result.omega1_check < 1.2 * error, (m, result.omega1_check, error)
        warned = any("from its fine P1 solve" in r.getMessage() for r in caplog.records)
        assert warned == (result.omega1_check > OMEGA1_CHECK_WARN), (m, result.omega1_check)
    assert result.omega1_check < OMEGA1_CHECK_WARN  # m = 3


def test_the_check_can_be_left_out(free_bottom):
    problem, _ = free_bottom
    assert fc.solve(problem, "primal-ms", cem=CEMOptions(layers=2), check=False).omega1_check is None
