"""The condensation per displacement component, the kept load response, the mixed responses from entries of J⁻¹.

* ``PrimalPart.component_responses``: J₀'s contact columns and rows per component E_k; ``CondensedInterface``
  recombines them with the normals ν (Yq = Σ_k Yq_k diag(ν_k), Gq = Σ_k G_k diag(ν_k), M = Σ_kl diag(ν_k) M_kl
  diag(ν_l)).  Before and after the obstacle moves, every piece equals the condensation from ``responses`` (the
  component split off) and the back-solves at the current normals, to 1e-12 relative to the largest entry.
* ``AffinePart.load_response`` keeps J⁻¹b: a second call does no solve, a changed load is solved again.
* ``MixedPart.responses``: Ω₁'s T₁ of Algorithm 2 from the block of J⁻¹ equals the back-solves;
  ``DirectSolver.inverse_block`` of equilibrated factors (D A D) gives the block of A⁻¹.
* Algorithm 3's load path with the condensation per component gives the forces of the one without, to 1e-12;
  with Ω₂'s change from the kept products, s_L's Sc g by components and the contact Newton started from the
  last step's active set, the forces of the path that forms Sc, takes four quadratic forms and starts the
  contact Newton from {s_L > 0} at every step, to 1e-12 (the relative changes to 1e-6), in no more contact
  Newton steps.
"""

import numpy as np
import pytest
import scipy.sparse as sp
from petsc4py import PETSc

import fenics_contact as fc
from fenics_contact.fem.inverse_entries import available
from fenics_contact.fem.linalg import DirectSolver
from fenics_contact.fem.matrices import scipy_to_petsc
from fenics_contact.hybrid import condensation, response
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions
from fenics_contact.hybrid.mixed import MixedHybridStep
from fenics_contact.hybrid.primal import PrimalHybridStep
from fenics_contact.hybrid.response import AffinePart, MixedPart
from fenics_contact.multiscale.cem.options import CEMOptions
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep
from fenics_contact.problem.geometry import unit_square
from fenics_contact.problem.models import get_model
from fenics_contact.problem.obstacles import Circle

pytestmark = pytest.mark.skipif(not available(), reason="no PETSc library for entries of inverses")

TOL = 1e-12
CYLINDER = Circle((3.0, 0.5), 2.0)
LEFT = (-1.0, 0.0)


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max(initial=0.0) / max(np.abs(b).max(initial=0.0), np.finfo(float).tiny))


def _pieces(c: CondensedInterface) -> tuple:
    return c.Yc, c.Sc, c.Yq, c.Sq, c.Gq, c.M


def test_condensation_per_component_equals_the_responses(monkeypatch):
    calls = []
    entries = DirectSolver.inverse_block
    monkeypatch.setattr(
        DirectSolver, "inverse_block", lambda self, rows, **kw: calls.append(rows.size) or entries(self, rows, **kw)
    )
    problem = get_model(3, E_high=1e3).with_(obstacle=CYLINDER.indented(0.01, LEFT)).on(unit_square(32, 8))
    step = PrimalHybridStep(problem)
    step.prepare()
    interface = step.interface_problem(InterfaceNewtonOptions())
    om2 = interface.omega2
    first = CondensedInterface(interface)
    assert first.components is not None and len(first.components[1]) == 2
    for moved in (False, True):
        if moved:
            made = len(calls)
            step.contact.set_obstacle(CYLINDER.indented(0.02, LEFT))
            assert om2.refresh()
        by_components = CondensedInterface(interface, previous=first if moved else None)
        om2.by_components = False
        plain = CondensedInterface(interface)  # Yq, Sq, Sc from ``responses`` at the current normals, M from them
        om2.by_components = True
        assert plain.components is None
        for new, old in zip(_pieces(by_components), _pieces(plain)):
            assert _relative(new, old) < TOL
        g = np.linspace(-1.0, 1.0, plain.Sc.shape[1])
        assert _relative(CondensedInterface(interface, previous=by_components).contact_of(g), plain.Sc @ g) < TOL
        solves = AffinePart.responses(om2, contact=True, chunk=16)  # back-solves at the current normals
        for new, old in zip(_pieces(by_components)[:4], solves):
            assert _relative(new, old) < TOL
    assert len(calls) == made  # the moved obstacle: no MUMPS call (the block of J₀⁻¹ is kept)
    assert _relative(by_components.Yq, first.Yq) > 1e-6  # the normals did move
    om2.destroy()


def test_load_response_is_kept_while_the_load_is():
    problem = get_model(3, E_high=1e3).with_(obstacle=CYLINDER.indented(0.01, LEFT)).on(unit_square(16, 4))
    step = PrimalHybridStep(problem)
    step.prepare()
    om2 = step.interface_problem(InterfaceNewtonOptions()).omega2
    solves = []
    solve = om2._solve_load
    om2._solve_load = lambda b: solves.append(1) or solve(b)
    y0, s0 = om2.load_response()
    y1, s1 = om2.load_response()
    assert len(solves) == 1 and np.array_equal(y0, y1) and np.array_equal(s0, s1)
    load = om2.body_load()
    om2._current_body_load = lambda: 2.0 * load  # another load: solved again, the response doubles (y = N J⁻¹b)
    y2, _ = om2.load_response()
    assert len(solves) == 2 and _relative(y2, 2.0 * y0) < TOL
    om2.destroy()


def test_mixed_omega1_response_from_entries_equals_back_solves(monkeypatch):
    monkeypatch.setattr(response, "ENTRIES_FRACTION", 1.0)  # entries at any size (h = 1/16: 10 % of Ω₁'s unknowns)
    problem = get_model(3, E_high=1e3).with_(obstacle=CYLINDER.indented(0.01, LEFT)).on(unit_square(16, 4))
    step = MixedHybridStep(problem, beta="sqrt-h")
    step.prepare()
    omega1 = MixedPart(step.sub[0], perm=None, contact=False)
    assert omega1.solver.has_inverse_entries()
    calls = []
    entries = omega1.solver.inverse_block
    omega1.solver.inverse_block = lambda rows: calls.append(rows.size) or entries(rows)
    T = omega1.responses(contact=False, chunk=16)[0]
    assert calls
    T_solves = AffinePart.responses(omega1, contact=False, chunk=16)[0]
    assert np.abs(T_solves).max() > 0.0 and _relative(T, T_solves) < TOL


def test_inverse_block_of_equilibrated_factors():
    rng = np.random.default_rng(5)
    n = 40
    R = sp.random(n, n, density=0.1, random_state=rng)
    A = R + R.T + 10.0 * sp.eye(n)
    d = 2.0 ** rng.integers(-4, 5, n)  # D A D is what is factorized
    solver = DirectSolver(PETSc.COMM_SELF, prefix="test_inverse_entries_scaled_", scaling=d)
    Am = scipy_to_petsc(sp.diags(d) @ A @ sp.diags(d))
    solver.set_operator(Am)
    assert solver.has_inverse_entries()
    rows = rng.permutation(n)[:11]
    assert _relative(solver.inverse_block(rows), np.linalg.inv(A.toarray())[np.ix_(rows, rows)]) < TOL
    for obj in (solver, Am):
        obj.destroy()


def test_multiscale_load_path_per_component_equals_plain():
    problem = get_model(3, E_high=1e3).with_(obstacle=CYLINDER).on(unit_square(32, 8))
    depths = np.linspace(0.005, 0.02, 4)
    forces = []
    for by_components in (True, False):
        step = MultiscalePrimalHybridStep(
            problem.with_(obstacle=CYLINDER.indented(depths[0], LEFT)), cem=CEMOptions(layers=2, nbasis=3)
        )
        step.interface_problem(InterfaceNewtonOptions()).omega2.by_components = by_components
        curve = fc.force_indentation(problem, "primal-ms", depths, direction=LEFT, step=step, accel="newton", tol=1e-8)
        assert all(s.converged for s in curve.steps)
        forces.append(curve.forces)
    assert np.all(forces[0] > 0.0)
    assert _relative(forces[0], forces[1]) < TOL


def test_multiscale_load_path_kept_products_equal_plain(monkeypatch):
    problem = get_model(3, E_high=1e3).with_(obstacle=CYLINDER).on(unit_square(32, 8))
    depths = np.linspace(0.005, 0.02, 4)

    def curve() -> tuple:
        step = MultiscalePrimalHybridStep(
            problem.with_(obstacle=CYLINDER.indented(depths[0], LEFT)), cem=CEMOptions(layers=2, nbasis=3)
        )
        changes = []
        out = fc.force_indentation(
            problem,
            "primal-ms",
            depths,
            direction=LEFT,
            step=step,
            accel="newton",
            tol=1e-8,
            on_step=lambda _, solver: changes.append(solver.relative_change()),
        )
        assert all(s.converged for s in out.steps)
        return out.forces, np.array(changes), step, sum(s.interface_newton_steps for s in out.steps)

    fast, fast_changes, step, fast_steps = curve()
    assert step._products is not None  # the load steps took Ω₂'s change from the kept products
    measure = MultiscalePrimalHybridStep._measure
    monkeypatch.setattr(MultiscalePrimalHybridStep, "_measure", lambda self, kept=False: measure(self))
    monkeypatch.setattr(CondensedInterface, "contact_of", lambda self, g: self.Sc @ g)
    solve = condensation.contact_solve
    monkeypatch.setattr(condensation, "contact_solve", lambda *args: solve(*args[:6]))  # from {s_L > 0}
    plain, plain_changes, _, plain_steps = curve()
    assert fast_steps <= plain_steps
    assert np.all(fast > 0.0) and _relative(fast, plain) < TOL
    assert np.all(np.isfinite(fast_changes)) and np.allclose(fast_changes, plain_changes, rtol=1e-6, atol=0.0)
