"""Interface Newton at contrast 1e6: the contact Newton's active-set record, its other starts,
the multiscale default α and the clear error when the glued problem is not positive definite.

* The contact Newton records the Γ_C rows each step adds / removes; the sizes add up, the last step
  confirms its set, and every start (the default, all active, the converged set, with or without the
  line search) ends on the same solution of s = s_L − M D s⁺ — the fixed point does not depend on how
  it is reached.
* ``alpha="Emin*h^-1/2"`` is h^-1/2 times the smallest nodal modulus on γ.
* Algorithm 3 on the heterogeneous strip at contrast 1e6 with α = E·h^-1/2: the multiscale Ω₁ response,
  amplified by α ≈ 6e6 in the stiff channels, makes the glued problem indefinite (m = 3) — a
  ConvergenceError that says so, never a wrong ``converged`` — or 0.33 off the fine solution (m = 4);
  the multiscale default α gives a positive definite glued problem and e_u ≤ 0.03 (m = 4; at m = 3 the
  multiscale space itself is 0.24 off at this h/H = 1/2, for every α).
"""

import numpy as np
import pytest

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.contact_newton import contact_newton
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions, iterate
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, DEFAULT_ALPHA_MS, PrimalHybridStep
from fenics_contact.hybrid.transmission import InterfaceSpace, robin_coefficient, split_mesh
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep, solve_primal_ms_hybrid
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

STIFF = NewtonOptions(rtol=1e-6)  # the Ω₂ acceptance test at contrast 1e6 (see test_interface_newton.py)


@pytest.fixture(scope="module")
def strip():
    """Model 3 at contrast 1e6, h = 1/32, H = 1/16, its penalty and the fine monolithic solution."""
    cm = unit_square(32, 16)
    model = get_model(3, E_high=1e6)
    delta = default_penalty(cm.h, 1e6)
    ref = solve_primal_monolithic(model.on(cm), delta=delta, newton=STIFF)
    return cm, model, delta, ref


def test_contact_newton_records_its_fronts_and_every_start_ends_on_one_solution(strip):
    cm, model, delta, ref = strip
    step = PrimalHybridStep(model.on(cm), alpha=DEFAULT_ALPHA, delta=delta, newton=STIFF)
    step.prepare()
    history = iterate(step, IterationOptions(accel="newton"))
    assert history.converged
    ch = history.contact_newton
    assert ch.steps == len(ch.added) == len(ch.removed) and ch.steps <= 8
    problem = step.interface_problem(InterfaceNewtonOptions())
    cond = problem.condensed
    s_load = cond.load_terms()[0]
    sizes = [int(np.count_nonzero(s_load > 0))] + ch.active_sizes
    assert all(b == a + add.size - rem.size for a, b, add, rem in zip(sizes, sizes[1:], ch.added, ch.removed))
    assert ch.added[-1].size == ch.removed[-1].size == 0  # the last step confirms its set
    s, mu, _ = contact_newton(s_load, cond.M, cond.D)
    # the glued problem of Algorithm 1 is the monolithic one: its compliance is symmetric positive definite
    assert cond.lowest_eigenvalue() > 0
    assert np.abs(cond.M - cond.M.T).max() <= 1e-8 * np.abs(cond.M).max()
    scale = np.abs(s).max()
    for kwargs in ({"active": np.ones(s.size, dtype=bool)}, {"line_search": True}, {"active": s > 0}):
        s2, mu2, h2 = contact_newton(s_load, cond.M, cond.D, **kwargs)
        assert np.array_equal(s2 > 0, s > 0) and np.abs(s2 - s).max() <= 1e-10 * scale, kwargs
        assert np.allclose(mu2, mu, rtol=1e-8, atol=1e-12 * np.abs(mu).max())
    assert contact_newton(s_load, cond.M, cond.D, active=s > 0)[2].steps == 1  # the solution's set: one solve
    # the monolithic semismooth Newton ends on the same number of contact nodes
    assert ch.active_sizes[-1] == ref.newton.active_sizes[-1]


def test_alpha_emin_is_the_smallest_nodal_modulus_on_gamma():
    """γ at x = 3/4 crosses the channels of model 1 (E_p ∈ {E_low, (E_high + E_low)/2})."""
    cm = unit_square(32, 4)
    space = InterfaceSpace(cm, split_mesh(cm), shape=(2,))
    for E_low in (1.0, 5.0):
        E = material_fields(cm.mesh, get_model(1, E_low=E_low)).E
        nodal = robin_coefficient("E*h^-1/2", E, space, cm.h)
        assert nodal.max() > 100 * nodal.min()
        assert np.allclose(robin_coefficient("Emin*h^-1/2", E, space, cm.h), E_low * np.sqrt(32))
        assert np.allclose(robin_coefficient("2Emin", E, space, cm.h), 2 * E_low)
    with pytest.raises(InputError):
        robin_coefficient("E*Emin", E, space, cm.h)


@pytest.mark.slow
def test_multiscale_alpha_amplifying_its_error_is_a_clear_error_and_the_default_is_accurate(strip):
    cm, model, delta, ref = strip
    # α = E·h^-1/2, m = 3: the glued problem is indefinite -> ConvergenceError naming it (CLI exit 4)
    step = MultiscalePrimalHybridStep(
        model.on(cm), alpha=DEFAULT_ALPHA, delta=delta, newton=STIFF, cem=CEMOptions(layers=3)
    )
    assert CondensedInterface(step.interface_problem(InterfaceNewtonOptions())).lowest_eigenvalue() < 0
    with pytest.raises(ConvergenceError, match="not positive definite"):
        iterate(step, IterationOptions(accel="newton"))
    # m = 4 (the CLI default): both converge, E·h^-1/2 to a solution 0.33 off the fine one, the default to 0.015
    errors = {}
    for alpha in (DEFAULT_ALPHA, DEFAULT_ALPHA_MS):
        res = solve_primal_ms_hybrid(
            model.on(cm),
            alpha=alpha,
            delta=delta,
            cem=CEMOptions(layers=4),
            newton=STIFF,
            reference=ref.u,
            options=IterationOptions(accel="newton"),
        )
        assert res.converged and res.transmission_residual < 1e-6
        errors[alpha] = res.e_u
    assert res.step.interface_problem(InterfaceNewtonOptions()).condensed.lowest_eigenvalue() > 0
    assert errors[DEFAULT_ALPHA_MS] <= 0.03 and errors[DEFAULT_ALPHA] >= 5 * errors[DEFAULT_ALPHA_MS], errors
