"""A load step of Algorithm 1's condensed interface Newton reuses what the last step leaves, with its answers.

On the 3D channel model pressed by a plane moved along −x (its normals fixed, the condensation kept):

* the contact Newton of a warm-started step starts from the last step's active set: a step whose set is the last
  one's takes exactly one contact Newton step, and the path fewer in all than from {s_L > 0};
* the load term's dense solve (g₂₁ at λ = 0) is made once for the path (the load responses stay), and Gq, Yq are
  formed once the condensation serves a second step;
* the forces are those of the path without these savings to 1e-10 and the monolithic ones to 1e-8, every step
  certified;
* the contact Newton keeps the LU factors of the set it ended on, and a solve starting on that set back-solves.
"""

import numpy as np
import pytest

import fenics_contact as fc
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.contact_newton import contact_newton
from fenics_contact.hybrid.iteration import InterfaceNewtonOptions
from fenics_contact.problem.models3d import channels_3d, channels_3d_mesh
from fenics_contact.problem.obstacles import Plane

DEPTHS = np.linspace(0.0, 0.02, 11)
PUSH = (-1.0, 0.0, 0.0)


def _problem():
    plane = Plane((1.0, 0.0, 0.0), (-1.0, 0.0, 0.0))
    return channels_3d(E_high=1e3).with_(obstacle=plane).on(channels_3d_mesh(8))


def _curve(problem, on_step=None):
    curve = fc.force_indentation(problem, "primal", DEPTHS, direction=PUSH, accel="newton", tol=1e-9, on_step=on_step)
    assert all(s.converged and s.transmission_residual < 1e-9 for s in curve.steps)
    return curve


def test_load_steps_start_from_the_last_active_set_and_keep_the_load_term(monkeypatch):
    problem = _problem()
    kept = []

    def on_step(record, solver):
        cond = solver.interface_problem(InterfaceNewtonOptions()).condensed
        kept.append((cond, cond._load[2], cond._Gq is not None))

    fast = _curve(problem, on_step)
    assert all(c is kept[0][0] and g is kept[0][1] for c, g, _ in kept)  # one condensation, one load term
    if kept[0][0]._nu is not None:  # (per-component pieces: Gq formed from the second step on)
        assert [formed for _, _, formed in kept] == [False] + [True] * (len(DEPTHS) - 1)
        cond = kept[0][0]
        lam = np.linspace(0.0, 1.0, cond.D.size)
        pieces = sum(cond._G[k] @ (cond._nu[:, k] * lam) for k in range(cond._nu.shape[1]))
        np.testing.assert_allclose(cond.times("Gq", lam), pieces, rtol=1e-12, atol=1e-12 * np.abs(pieces).max())
    sets = [s.profile.active for s in fast.steps]
    steps = [s.interface_newton_steps for s in fast.steps]
    same = [k for k in range(1, len(sets)) if np.array_equal(sets[k], sets[k - 1])]
    assert same and all(steps[k] == 1 for k in same), (steps, same)

    solve = CondensedInterface.solve
    monkeypatch.setattr(CondensedInterface, "solve", lambda self, options, name, warm=False: solve(self, options, name))
    plain = _curve(problem)
    assert sum(steps) < sum(s.interface_newton_steps for s in plain.steps)
    assert np.all(fast.forces > 0.0)
    np.testing.assert_allclose(fast.forces, plain.forces, rtol=1e-10)
    mono = fc.force_indentation(problem, "primal-monolithic", DEPTHS, direction=PUSH)
    np.testing.assert_allclose(fast.forces, mono.forces, rtol=1e-8)
    assert all(np.array_equal(a.profile.active, b.profile.active) for a, b in zip(fast.steps, mono.steps))


@pytest.mark.parametrize("warm", [False, True])
def test_a_cold_solve_on_a_kept_step_starts_from_the_load_term(warm):
    """A solve with zero initial data (a fresh solve reusing the step, e.g. another option) is not warm: its contact
    Newton starts from {s_L > 0} and takes the steps of the first solve; with the last data it starts from the last
    set (one step, the set reproduces itself)."""
    problem = channels_3d(E_high=1e3).on(channels_3d_mesh(8))
    first = fc.solve(problem, "primal", accel="newton", tol=1e-9)
    first.step.reset()
    again = fc.solve(
        problem, "primal", accel="newton", tol=1e-9, step=first.step, initial_data=first.history.data if warm else None
    )
    assert again.converged and again.transmission_residual < 1e-9
    assert again.history.newton_steps == (1 if warm else first.history.newton_steps) and first.history.newton_steps > 1
    np.testing.assert_array_equal(again.profile.active, first.profile.active)
    assert again.profile.force == pytest.approx(first.profile.force, rel=1e-10)


def test_the_contact_newton_keeps_the_factors_of_its_last_set():
    """``contact_newton(factors=...)`` keeps the LU factors of the set it ended on; a solve that starts on that set
    again (a warm-started load step) back-solves with them, and gives what a solve without kept factors gives."""
    rng = np.random.default_rng(3)
    n = 60
    B = rng.standard_normal((n, n))
    M = B @ B.T / n + np.eye(n)  # a compliance: symmetric positive definite
    D = np.full(n, 1e3)
    s_load = rng.standard_normal(n)
    factors = {}
    _, mu, hist = contact_newton(s_load, M, D, factors=factors)
    last = np.flatnonzero(mu > 0.0)
    assert hist.steps > 1 and list(factors) == [last.tobytes()]
    lu = factors[last.tobytes()]
    again = s_load * (1.0 + 1e-6)  # the same set
    s, mu2, hist2 = contact_newton(again, M, D, active=mu > 0.0, factors=factors)
    assert hist2.steps == 1 and factors[last.tobytes()] is lu  # one step, no new factorization
    s_ref, mu_ref, _ = contact_newton(again, M, D, active=mu > 0.0)
    np.testing.assert_array_equal(mu2 > 0.0, mu > 0.0)
    np.testing.assert_allclose(mu2, mu_ref, rtol=1e-12, atol=1e-12 * np.abs(mu_ref).max())
    np.testing.assert_allclose(s, s_ref, rtol=1e-12, atol=1e-12 * np.abs(s_ref).max())
