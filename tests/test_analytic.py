"""Analytic benchmarks (METHOD §9) for the primal and mixed monolithic solves and Algorithms 1, 2 (and 3 on the bar).

(a) the bar clamped at x = 0 only: pushing (full contact) and pulling (no contact);
(b) plane-strain Hertz: a rigid cylinder pressed into a wide, deep block;
(c) the layered patch test: stiff and soft layers across γ compressed by a plane moved in by d₀,
    as a force–indentation curve in load steps.
The full table (errors and rates per method) is ``benchmarks/analytic_benchmarks.py``.
"""

import numpy as np
import pytest
import ufl
from dolfinx import fem
from mpi4py import MPI

import fenics_contact  # noqa: F401
from fenics_contact.fem.mixed import solve_mixed_monolithic
from fenics_contact.fem.primal import default_penalty, solve_primal_monolithic
from fenics_contact.hybrid.iteration import IterationOptions
from fenics_contact.hybrid.mixed import solve_mixed_hybrid
from fenics_contact.hybrid.primal import solve_primal_hybrid
from fenics_contact.indentation import force_indentation
from fenics_contact.multiscale.primal import solve_primal_ms_hybrid
from fenics_contact.problem.analytic import (
    bar_model, bar_solution, hertz_errors, hertz_model, layered_displacement, layered_model, layered_pressure,
)
from fenics_contact.problem.fields import material_fields
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.meshes import hertz_block

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="mixed (Arnold–Winther) methods are serial")
TIGHT = IterationOptions(tol=1e-11)


def _l2(expr, msh):
    form = fem.form(ufl.inner(expr, expr) * ufl.dx(domain=msh, metadata={"quadrature_degree": 6}))
    return np.sqrt(msh.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM))


def _bar_exact(msh, sol):
    X = ufl.SpatialCoordinate(msh)
    return ufl.as_vector([sol.sigma_xx(X), 0.0, 0.0]), ufl.as_vector([sol.u_x(X), 0.0])


# -- (a) the bar ------------------------------------------------------------------------------


@pytest.mark.parametrize("f1", [1.0, -1.0], ids=["push", "pull"])
def test_bar_primal_monolithic_and_algorithm_1(f1):
    """P1: O(h²) in L² against the penalized bar (the P1 load at the corners of Γ_C is not 1D);
    the contact force is the penalized one; Algorithm 1 reaches the monolithic solution."""
    errors = []
    for n in (8, 16):
        cm = unit_square(n, 4, clamped=("left",))
        delta = default_penalty(cm.h, 1.0)
        sol = solve_primal_monolithic(cm.mesh, cm.facet_tags, material_fields(cm.mesh, bar_model(f1)), delta=delta)
        exact = bar_solution(f1, delta=delta)
        _, u_ex = _bar_exact(cm.mesh, exact)
        errors.append(_l2(sol.u - u_ex, cm.mesh) / _l2(u_ex, cm.mesh))
        assert abs(sol.profile.force + exact.sigma_end) < 1e-6 * abs(f1)
        assert np.all(sol.profile.active) == (f1 > 0) and np.any(sol.profile.active) == (f1 > 0)
    assert errors[1] < 1e-2 and np.log2(errors[0] / errors[1]) > 1.8, errors
    alg1 = solve_primal_hybrid(cm, bar_model(f1), delta=delta, reference=sol.u, options=TIGHT)
    assert alg1.converged and alg1.e_u < 1e-8


@pytest.mark.parametrize("f1", [1.0, -1.0], ids=["push", "pull"])
def test_bar_algorithm_3(f1):
    """Algorithm 3 on the bar (traction-free top and bottom of Ω₁, the load everywhere): the error against
    the monolithic P1 solve falls with the oversampling layers, and with m = 3 the patches cover Ω₁
    (H = 1/4), so the multiscale space holds the fine solution: equal to the monolithic solve."""
    cm = unit_square(16, 4, clamped=("left",))
    delta = default_penalty(cm.h, 1.0)
    sol = solve_primal_monolithic(cm.mesh, cm.facet_tags, material_fields(cm.mesh, bar_model(f1)), delta=delta)
    errors = [solve_primal_ms_hybrid(cm, bar_model(f1), delta=delta, layers=m, reference=sol.u, options=TIGHT)
              for m in (1, 2, 3)]
    assert all(r.converged for r in errors)
    e = [r.e_u for r in errors]
    assert e[0] < 5e-2 and e[0] / e[1] > 20 and e[2] < 1e-8, e


@serial
@pytest.mark.parametrize("f1", [1.0, -1.0], ids=["push", "pull"])
def test_bar_mixed_exact_and_algorithm_2(f1):
    """Arnold–Winther with traction-free top and bottom: the stress is the penalized bar's to round-off
    (it was 65 %/83 % off when every side but Γ_C was silently clamped); Algorithm 2 reaches it."""
    cm = unit_square(16, 4, clamped=("left",))
    sol = solve_mixed_monolithic(cm, bar_model(f1))
    exact = bar_solution(f1, epsilon=sol.epsilon)
    s_ex, u_ex = _bar_exact(cm.mesh, exact)
    assert _l2(sol.sigma - s_ex, cm.mesh) < 1e-12 * _l2(s_ex, cm.mesh)
    assert _l2(sol.u - u_ex, cm.mesh) < 2e-3 * _l2(u_ex, cm.mesh)  # DG P1 of a quadratic: O(h²)
    assert abs(sol.profile.force + exact.sigma_end) < 1e-12
    # pushing: no penalty error (σ_c < 0 everywhere); pulling: the tensile stress ε|u(1)| = O(ε)
    assert sol.profile.max_tensile == pytest.approx(max(exact.sigma_end, 0.0), abs=1e-14)
    alg2 = solve_mixed_hybrid(cm, bar_model(f1), options=TIGHT)
    assert alg2.converged
    assert _l2(alg2.sigma - s_ex, cm.mesh) < 1e-9 * _l2(s_ex, cm.mesh)


# -- (c) the layered patch test, as a force–indentation curve ----------------------------------

BOUNDS, MODULI = [0.0, 6 / 16, 13 / 16, 1.0], [1.0, 1e3, 10.0]  # layers across γ (x = 3/4)


@pytest.mark.parametrize("method", [
    "primal-monolithic", "primal", pytest.param("mixed-monolithic", marks=serial), pytest.param("mixed", marks=serial),
])
def test_layered_patch_force_indentation(method):
    """Exact to round-off up to the penalty: F(d) = d/(C + δ) (primal) or d/C (mixed) at every load step,
    σ_xx uniform, u_x piecewise linear; the steps reuse the factorizations and warm-start."""
    cm = unit_square(16, 4, clamped=("left",))
    depths = [0.01, 0.02, 0.015]
    model = layered_model(BOUNDS, MODULI, depth=0.0)
    curve = force_indentation(method, cm, model, depths, direction=(-1.0, 0.0), options=TIGHT)
    delta = default_penalty(cm.h, MODULI[-1]) if method.startswith("primal") else 0.0
    expected = [layered_pressure(BOUNDS, MODULI, d, delta=delta) for d in depths]
    assert np.allclose(curve.forces, expected, rtol=1e-10, atol=0)
    assert all(s.converged for s in curve.steps)
    last = curve.steps[-1].profile
    assert np.allclose(-last.sigma_c, expected[-1], rtol=1e-9)  # uniform pressure at every contact node


def test_layered_patch_primal_fields_exact():
    cm = unit_square(16, 4, clamped=("left",))
    d0 = 0.02
    model = layered_model(BOUNDS, MODULI, depth=d0)
    delta = default_penalty(cm.h, MODULI[-1])
    sol = solve_primal_monolithic(cm.mesh, cm.facet_tags, material_fields(cm.mesh, model), delta=delta)
    p = layered_pressure(BOUNDS, MODULI, d0, delta=delta)
    x = sol.u.function_space.tabulate_dof_coordinates().T
    u = sol.u.x.array.reshape(-1, 2)
    assert np.max(np.abs(u[:, 0] - layered_displacement(BOUNDS, MODULI, p)(x))) < 1e-12
    assert np.max(np.abs(u[:, 1])) < 1e-12


@serial
def test_layered_patch_mixed_fields_exact():
    cm = unit_square(16, 4, clamped=("left",))
    d0 = 0.02
    sol = solve_mixed_monolithic(cm, layered_model(BOUNDS, MODULI, depth=d0))
    p = layered_pressure(BOUNDS, MODULI, d0)
    s = sol.sigma.x.array.reshape(-1, 3)
    assert np.max(np.abs(s - [-p, 0.0, 0.0])) < 1e-9 * p  # contrast 10³: round-off ~1e-10
    u_ex = layered_displacement(BOUNDS, MODULI, p)
    X = ufl.SpatialCoordinate(cm.mesh)
    u_ufl = ufl.as_vector([-p * ufl.conditional(ufl.lt(X[0], 6 / 16), X[0], ufl.conditional(
        ufl.lt(X[0], 13 / 16), 6 / 16 + (X[0] - 6 / 16) / 1e3, 6 / 16 + 7 / 16e3 + (X[0] - 13 / 16) / 10.0)), 0.0])
    assert abs(u_ex(np.array([[0.9], [0.0]]))[0] - (-p * (6 / 16 + 7 / 16e3 + 0.0875 / 10))) < 1e-15
    assert _l2(sol.u - u_ufl, cm.mesh) < 1e-9 * _l2(u_ufl, cm.mesh)  # DG P1 holds the piecewise-linear u


# -- (b) Hertz ----------------------------------------------------------------------------------

A, R, E, NU, DEPTH = 0.05, 5.0, 1.0, 0.3, 1.2e-3  # a ≈ 0.053, a/R ≈ 0.01: the linear (Hertz) theory applies


def _hertz(refinement):
    cm, spec = hertz_block(A, refinement=refinement)
    return cm, spec, hertz_model(radius=R, E=E, nu=NU, depth=DEPTH)


def _check_hertz(errors, spec):
    assert abs(errors.half_width_cells) <= 2.0, errors
    assert abs(errors.peak_error) <= 0.01, errors
    assert errors.l2_error <= 0.015, errors
    assert errors.a / spec.h_contact >= 20.0  # the contact mesh resolves a with >= 20 cells


def test_hertz_primal_monolithic_and_algorithm_1():
    """Contact half-width within two cells, peak pressure within 1 %, L² profile error within 1.5 % at
    a/21 (measured 0.65 %, 1.22 %); the errors fall as the whole mesh is refined; Algorithm 1 too."""
    results = []
    for r in (0.5, 1.0):
        cm, spec, model = _hertz(r)
        delta = default_penalty(cm.h, E)
        sol = solve_primal_monolithic(cm.mesh, cm.facet_tags, material_fields(cm.mesh, model), delta=delta)
        results.append(hertz_errors(sol.profile, radius=R, E=E, nu=NU, h_contact=spec.h_contact))
    coarse, fine = results
    _check_hertz(fine, spec)
    assert fine.l2_error < coarse.l2_error and abs(fine.peak_error) < abs(coarse.peak_error)
    alg1 = solve_primal_hybrid(cm, model, delta=delta, reference=sol.u)
    assert alg1.converged and alg1.e_u < 1e-4
    _check_hertz(hertz_errors(alg1.profile, radius=R, E=E, nu=NU, h_contact=spec.h_contact), spec)


@serial
def test_hertz_mixed_monolithic_and_algorithm_2():
    """The same bounds for the mixed solutions, which are far inside them from a/10 on (measured
    0.2–0.4 % in L², 0.02–0.04 % in the peak, set by where the contact edge falls between nodes)."""
    cm, spec, model = _hertz(1.0)
    sol = solve_mixed_monolithic(cm, model)
    errors = hertz_errors(sol.profile, radius=R, E=E, nu=NU, h_contact=spec.h_contact)
    _check_hertz(errors, spec)
    assert errors.l2_error < 0.005 and abs(errors.peak_error) < 0.003
    assert sol.profile.max_tensile < 1e-6 * errors.p0  # the penalty error: tensile stress ε·gap
    alg2 = solve_mixed_hybrid(cm, model, reference=sol)
    assert alg2.converged and alg2.e_sigma < 1e-3
    _check_hertz(hertz_errors(alg2.profile, radius=R, E=E, nu=NU, h_contact=spec.h_contact), spec)
