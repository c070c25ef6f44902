"""Interface Newton (hybrid.interface_newton) and the convergence certificate (hybrid.certificate).

* Newton lands on the fixed point of the Robin iteration (same step object, Anderson run to a
  transmission residual of 1e-10) for all four algorithms on models 1, 2 and the heterogeneous
  strip model 3 (E_high = 1e3 and 1e6), in at most 8 Newton steps; Algorithm 1 + Newton equals
  the monolithic solve (Theorem 3.1), Algorithm 2 + Newton the monolithic solve on X̃_h.
* No α, β, update or contrast ends as ``converged`` with a wrong solution (α = 1e8, 1e-12, β = 1e12).
* The certificate itself: zero exactly at a glued pair, O(1) when either condition fails, 0/0 = 0.
"""

import time

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import NewtonOptions
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.certificate import (
    FLOOR_MARGIN,
    ROUNDOFF,
    at_floor,
    mixed_certificate,
    primal_certificate,
    relative,
)
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions, IterationOptions, iterate
from fenics_contact.hybrid.mixed import MixedHybridStep, solve_mixed_hybrid
from fenics_contact.hybrid.primal import DEFAULT_ALPHA, PrimalHybridStep, solve_primal_hybrid
from fenics_contact.multiscale.cem import CEMOptions
from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep
from fenics_contact.multiscale.mixed_cem import MixedCEMOptions
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model

#: (model number, E_high): the built-in models and the heterogeneous strip at contrast 1e3 and 1e6
CASES = [(1, 1e3), (2, 1e3), (3, 1e3), (3, 1e6)]
TIGHT = 1e-10


def _l2(f) -> float:
    comm = f.function_space.mesh.comm
    return float(np.sqrt(comm.allreduce(fem.assemble_scalar(fem.form(ufl.inner(f, f) * ufl.dx)), op=MPI.SUM)))


def _distance(a: list, b: list) -> float:
    """max over the fields of ‖a − b‖_L² / ‖a‖_L²."""
    out = 0.0
    for fa, fb in zip(a, b):
        d = fem.Function(fa.function_space)
        d.x.array[:] = fa.x.array - fb.x.array
        out = max(out, _l2(d) / _l2(fa))
    return out


def _fields(step) -> list:
    if isinstance(step, (PrimalHybridStep, MultiscalePrimalHybridStep)):
        V = fem.functionspace(step.interface.V.mesh, ("Lagrange", 1, (2,)))
        return [step.glued(V)]
    return list(step.glued())


def _primal_step(method, number, E_high):
    cm = unit_square(32, 8)
    model = get_model(number, E_high=E_high)
    delta = default_penalty(cm.h, E_high if number == 3 else 1.0)  # model 3: the channels reach Γ_C
    # at contrast 1e6 the Ω₂ Newton's acceptance test ‖F‖ ≤ 1e-8‖b‖ is below the round-off of the
    # penalty and Robin stiffness (the Robin iteration stops with ConvergenceError): relax it there
    newton = NewtonOptions(rtol=1e-6) if E_high > 1e3 else NewtonOptions()
    if method == 1:
        step = PrimalHybridStep(model.on(cm), alpha=DEFAULT_ALPHA, delta=delta, newton=newton)
        step.prepare()
    else:
        step = MultiscalePrimalHybridStep(
            model.on(cm), alpha=DEFAULT_ALPHA, delta=delta, newton=newton, cem=CEMOptions(layers=2)
        )
    return cm, model, delta, step


def _mixed_step(method, number, E_high):
    cm = unit_square(16, 4)
    model = get_model(number, E_high=E_high)
    if method == 2:
        step = MixedHybridStep(model.on(cm), beta="sqrt-h")
        step.prepare()
    else:
        step = MixedMultiscaleHybridStep(model.on(cm), beta="sqrt-h", cem=MixedCEMOptions(layers=2))
    return cm, model, step


def _robin_then_newton(step, *, robin: bool = True, floor: float = TIGHT):
    """Anderson to 1e-10 from g = 0 (if ``robin``), then Newton on the same step (reused offline data),
    then Anderson warm-started from the Newton data: (Robin history, Robin fields, Newton history, fields)."""
    history = iterate(step, IterationOptions(tol=TIGHT, accel="anderson", max_iterations=3000)) if robin else None
    robin_fields = [f.copy() for f in _fields(step)] if robin else None
    newton = iterate(step, IterationOptions(tol=TIGHT, accel="newton"))
    newton_fields = [f.copy() for f in _fields(step)]
    assert newton.converged and newton.transmission_residual < TIGHT
    assert newton.newton_steps <= 8, newton.newton_steps
    assert newton.iterations <= 3  # applications of T: the first certifies the condensed result
    # the Newton data are a fixed point of the Robin iteration: it stops at once (``floor``: at contrast
    # 1e6 a fresh Ω₂ Newton solve reproduces the pair only to ~1e-9, the round-off of its stiff penalty)
    again = iterate(step, IterationOptions(tol=floor, accel="anderson"), initial=newton.data)
    assert again.iterations == 1 and again.converged
    return history, robin_fields, newton, newton_fields


@pytest.mark.parametrize("number, E_high", CASES)
@pytest.mark.parametrize("method", [1, 3])
def test_primal_newton_is_the_robin_fixed_point(method, number, E_high):
    """Algorithms 1, 3: same fixed point as the Robin iteration (≤ 1e-8), ≤ 8 Newton steps, certified.

    At contrast 1e6 the Robin iteration from g = 0 does not reach 1e-10 (Anderson stalls near 3e-8
    after 3000 iterations on model 3 at h = 1/32, H = 1/8): there the Newton result is shown to be its
    fixed point by the warm start, and Algorithm 1 + Newton is compared with the monolithic solve.
    """
    cm, model, delta, step = _primal_step(method, number, E_high)
    stiff = E_high > 1e3
    robin, robin_fields, newton, newton_fields = _robin_then_newton(
        step, robin=not stiff, floor=1e-8 if stiff else TIGHT
    )
    if not stiff:
        assert robin.converged and robin.iterations > 10
        assert _distance(robin_fields, newton_fields) <= 1e-8
    if method == 1:  # Theorem 3.1: the fixed point is the monolithic solution
        newton_opts = NewtonOptions(rtol=1e-6) if stiff else NewtonOptions()
        ref = solve_primal_monolithic(model.on(cm), delta=delta, newton=newton_opts)
        assert _distance([ref.u], newton_fields) <= (1e-8 if stiff else 1e-10)


@pytest.mark.parametrize("number, E_high", CASES)
@pytest.mark.parametrize("method", [2, 4])
def test_mixed_newton_is_the_robin_fixed_point(method, number, E_high):
    """Algorithms 2, 4: same fixed point as the Robin iteration (σ and u to ≤ 1e-8), ≤ 8 Newton steps."""
    cm, model, step = _mixed_step(method, number, E_high)
    robin, robin_fields, newton, newton_fields = _robin_then_newton(step)
    assert robin.converged
    assert _distance(robin_fields, newton_fields) <= 1e-8
    if method == 2 and number == 3:  # the exact fixed point: the monolithic solution on X̃_h
        split = solve_mixed_monolithic(model.on(cm), split_interface=True, epsilon=step.epsilon)
        step.set_reference(split)
        assert max(step.errors()) <= 1e-10, step.errors()


def test_strategies_agree_and_newton_matches_monolithic():
    """'interface' (Newton on g with back-solves of Ω₂'s own factorization) and 'condensed' give one answer."""
    cm = unit_square(32, 8)
    model = get_model(3)
    delta = default_penalty(cm.h, 1e3)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    for strategy in ("interface", "condensed"):
        res = solve_primal_hybrid(
            model.on(cm),
            delta=delta,
            reference=ref.u,
            options=IterationOptions(tol=TIGHT, accel="newton", newton=InterfaceNewtonOptions(strategy=strategy)),
        )
        assert res.converged and res.e_u <= 1e-10 and res.history.newton_steps <= 8, (strategy, res.e_u)
        assert res.time_interface_offline_s > 0 and res.time_offline_s >= res.time_interface_offline_s


@pytest.mark.parametrize("alpha", [1e8, 1e-12])
@pytest.mark.parametrize("accel", ["anderson", "newton"])
def test_extreme_alpha_is_never_a_wrong_converged(alpha, accel):
    """α = 1e8 stopped after 2 iterations at e_u = 0.79 with the relative-change rule: now it either
    converges to the monolithic solution or ends not converged."""
    cm = unit_square(32, 8)
    model = get_model(1)
    delta = default_penalty(cm.h, 1.0)
    ref = solve_primal_monolithic(model.on(cm), delta=delta)
    res = solve_primal_hybrid(
        model.on(cm),
        alpha=alpha,
        delta=delta,
        reference=ref.u,
        options=IterationOptions(accel=accel, max_iterations=60),
    )
    assert res.e_u <= 1e-5 if res.converged else res.transmission_residual >= 1e-6, (res.converged, res.e_u)
    if accel == "anderson":
        assert not res.converged  # 60 iterations are far too few at either extreme


@pytest.mark.parametrize("accel", ["anderson", "newton"])
def test_extreme_beta_is_never_a_wrong_converged(accel):
    cm = unit_square(16, 4)
    model = get_model(2)
    split = solve_mixed_monolithic(model.on(cm), split_interface=True)
    res = solve_mixed_hybrid(
        model.on(cm), beta=1e12, reference=split, options=IterationOptions(accel=accel, max_iterations=60)
    )
    assert max(res.e_sigma, res.e_u) <= 1e-5 if res.converged else res.transmission_residual >= 1e-6


def test_certificate_measures_the_transmission_conditions():
    rng = np.random.default_rng(1)
    n = 10
    w, alpha = rng.uniform(0.5, 1.0, n), rng.uniform(1.0, 5.0, n)
    u, t = rng.standard_normal(n), rng.standard_normal(n)
    glued = primal_certificate(u, u, t + alpha * u, -t + alpha * u, alpha, w, MPI.COMM_SELF)
    assert glued.value < 1e-15
    jump = primal_certificate(u, 0.9 * u, t + alpha * u, -t + 0.9 * alpha * u, alpha, w, MPI.COMM_SELF)
    assert jump.jump == pytest.approx(0.1, rel=1e-12) and jump.balance < 1e-15
    unbalanced = primal_certificate(u, u, t + alpha * u, alpha * u, alpha, w, MPI.COMM_SELF)
    assert unbalanced.balance == pytest.approx(1.0) and unbalanced.jump == 0.0
    mass = np.diag(w)
    beta = 0.3
    g12 = rng.standard_normal(n)
    mixed = mixed_certificate(t, -t, g12, g12 - 2 * beta * t, beta, mass)  # u₁ = u₂ = g₁₂ − βt
    assert mixed.value < 1e-15
    assert relative(0.0, 0.0) == 0.0 and relative(1.0, 0.0) == np.inf and relative(1.0, 4.0) == 0.25


def test_the_certificates_floor_is_its_terms_rounding_and_the_solves_errors_scale_free():
    """The floor of the primal certificate: one rounding of each term it subtracts plus the subdomain solves' errors
    (``certificate`` module docstring), the same in any units of u, g and α; ``at_floor`` counts a residual as
    round-off only within ``FLOOR_MARGIN`` of it and when the step before did not halve it (a fixed-point update's
    steps: did not reduce it)."""
    rng = np.random.default_rng(2)
    n = 12
    w, alpha = rng.uniform(0.5, 1.0, n), rng.uniform(1.0, 5.0, n) * 1e6  # (stiff: αu ≫ t)
    u, t = rng.standard_normal(n), rng.standard_normal(n)
    e1, e2 = 1e-12 * rng.standard_normal(n), 1e-13 * rng.standard_normal(n)

    def norm(v):
        return float(np.sqrt(w @ v**2))

    cert = primal_certificate(u, u, t + alpha * u, -t + alpha * u, alpha, w, MPI.COMM_SELF, (e1, e2))
    eps = ROUNDOFF * np.finfo(float).eps
    g12, g21 = t + alpha * u, -t + alpha * u
    balance = eps * (norm(g12) + norm(g21) + 2 * norm(alpha * u)) + norm(alpha * e1) + norm(alpha * e2)
    jump = 2 * eps * norm(u) + norm(e1) + norm(e2)
    assert cert.floor == pytest.approx(max(balance / max(norm(g12 - alpha * u), norm(g21 - alpha * u)), jump / norm(u)))
    assert cert.floor > 1e-7  # (αe₁ against t: 10⁶ × 10⁻¹²)
    assert primal_certificate(u, u, g12, g21, alpha, w, MPI.COMM_SELF).floor < 1e-8  # (rounding only)
    for U, S in ((0.05, 2.1e11), (1e3, 5e6)):  # u in a length unit, g and α·u in a stress unit
        scaled = primal_certificate(
            U * u, U * u, S * U * g12, S * U * g21, S * alpha, w, MPI.COMM_SELF, (U * e1, U * e2)
        )
        assert scaled.floor == pytest.approx(cert.floor, rel=1e-12)
    assert at_floor(3e-7, 2e-7, 4e-7) and not at_floor(1e-7, 2e-7, 4e-7)  # (halved: still converging)
    assert at_floor(FLOOR_MARGIN * 2e-7, 2e-7, FLOOR_MARGIN * 2e-7)
    assert not at_floor(1.01 * FLOOR_MARGIN * 2e-7, 2e-7, FLOOR_MARGIN * 2e-7)  # (above FLOOR_MARGIN × floor)
    assert at_floor(3e-7, 2e-7, 2.9e-7, reduction=1.0) and not at_floor(3e-7, 2e-7, 3.5e-7, reduction=1.0)
    assert not at_floor(3e-7, 2e-7, None) and not at_floor(1.0, np.inf, 1.0)


def test_warm_start_reuses_the_step_and_its_offline_data():
    """A second solve from the converged data needs one application of T; the Newton offline data are built once."""
    cm = unit_square(16, 4)
    model = get_model(2)
    delta = default_penalty(cm.h, 1.0)
    step = PrimalHybridStep(model.on(cm), alpha=DEFAULT_ALPHA, delta=delta)
    first = solve_primal_hybrid(model.on(cm), delta=delta, step=step, options=IterationOptions(accel="anderson"))
    again = solve_primal_hybrid(
        model.on(cm),
        delta=delta,
        step=step,
        initial_data=first.history.data,
        options=IterationOptions(accel="anderson"),
    )
    assert first.iterations > 5 and again.iterations == 1 and again.converged
    n1 = solve_primal_hybrid(model.on(cm), delta=delta, step=step, options=IterationOptions(accel="newton"))
    n2 = solve_primal_hybrid(model.on(cm), delta=delta, step=step, options=IterationOptions(accel="newton"))
    assert n1.time_interface_offline_s > 0 and n2.time_interface_offline_s < n1.time_interface_offline_s
    assert n2.converged and np.allclose(n2.u.x.array, first.u.x.array, atol=1e-5 * np.abs(first.u.x.array).max())
    with pytest.raises(InputError):
        solve_primal_hybrid(model.on(cm), delta=delta, step=step, initial_data=np.zeros(3))


def test_online_time_excludes_the_monitor():
    cm = unit_square(16, 4)
    step = PrimalHybridStep(get_model(1).on(cm), alpha=DEFAULT_ALPHA, delta=default_penalty(cm.h, 1.0))
    step.prepare()
    start = time.perf_counter()
    history = iterate(
        step, IterationOptions(accel="anderson", max_iterations=5), monitor=lambda: (time.sleep(0.05), {"slept": 1})[1]
    )
    wall = time.perf_counter() - start
    assert history.records[-1].info["slept"] == 1
    assert history.time_monitor_s >= 0.05 * history.iterations
    assert history.time_s <= wall - history.time_monitor_s + 1e-6
