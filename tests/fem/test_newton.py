"""The semismooth Newton loop (``fem.newton``) on contact systems small enough to check by hand.

* The one-node penalized obstacle problem k u + (1/δ)(u − g)⁺ = f: the loop ends with the first step that
  keeps its set, on the closed-form solution, and records one residual before each step and one at the end.
* A system whose full steps alternate between two sets: ``"never"`` runs into the step cap (the error counts
  the steps), ``"on-cycle"`` starts the line search with the first step into a set already linearized at.
* The settled residual check: iterative refinement steps up to ``refinements``, then ConvergenceError (a warm
  start far above a collapsing solution needs one); a failure inside a step carries the steps taken with it.
"""

import numpy as np
import pytest

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.newton import Advance, Check, Direction, semismooth_newton_loop


class Obstacle:
    """k u + (1/δ)(u − g)⁺ = f for one node: F(u) = k u + (u − g)⁺/δ − f, active set {u > g}."""

    def __init__(self, k=1.0, delta=1e-6, g=0.5, f=2.0):
        self.k, self.delta, self.g, self.f, self.u = k, delta, g, f, 0.0
        self.exact = (f + g / delta) / (k + 1.0 / delta)  # in contact: u > g
        self.checks = []  # (residual, scale) per check, scripted by a test when not empty

    def F(self):
        return self.k * self.u + max(self.u - self.g, 0.0) / self.delta - self.f

    def residual(self):
        return abs(self.F())

    def jacobian(self, active):
        self.slope = self.k + bool(active[0]) / self.delta
        return True

    def solve(self, active):
        self.du = -self.F() / self.slope
        return Direction(np.array([self.u + self.du > self.g]))

    def same(self, a, b):
        return np.array_equal(a, b)

    def line_search(self):
        raise AssertionError("full steps only")

    def advance(self, t, state):
        self.u += t * self.du
        active = np.array([self.u > self.g])
        return Advance(active, int(active.sum()))

    def check(self):
        if self.checks:
            residual, scale = self.checks.pop(0)
            return Check(residual, scale, residual)
        scale = (self.k + 1.0 / self.delta) * abs(self.u) + self.g / self.delta + self.f  # the terms F balances
        return Check(self.residual(), scale, self.residual())


def test_the_obstacle_node_ends_on_the_closed_form_solution():
    system = Obstacle()
    trace = semismooth_newton_loop(
        system, np.array([False]), name="node", max_steps=10, line_search="never", rtol=1e-12
    )
    assert system.u == pytest.approx(system.exact, rel=1e-14) and system.u > system.g
    assert trace.steps == 2 and trace.active_sizes == [1, 1] and trace.step_lengths == [1.0, 1.0]
    assert len(trace.residuals) == trace.steps + 1 and trace.residuals[-1] <= 1e-12 * system.g / system.delta
    assert trace.factorizations == 2


class Alternating:
    """Full steps that alternate between the sets {0} and {1} of two nodes; the line search breaks the cycle."""

    def __init__(self):
        self.searched_at = []
        self.step = 0
        self.t = 1.0

    def residual(self):
        return 1.0

    def jacobian(self, active):
        return False

    def solve(self, active):
        self.next = active if self.t < 1.0 else active[::-1].copy()
        return Direction(self.next)

    def same(self, a, b):
        return np.array_equal(a, b)

    def line_search(self):
        self.searched_at.append(self.step)
        return 0.5

    def advance(self, t, state):
        self.step += 1
        self.t = t
        return Advance(self.next, int(self.next.sum()))

    def check(self):
        return None


def test_a_cycle_starts_the_line_search_and_full_steps_hit_the_cap():
    start = np.array([True, False])
    with pytest.raises(ConvergenceError, match="did not converge in 7 steps") as failed:
        semismooth_newton_loop(Alternating(), start, name="cycle", max_steps=7, line_search="never")
    assert failed.value.steps == 7
    system = Alternating()
    trace = semismooth_newton_loop(system, start, name="cycle", max_steps=7, line_search="on-cycle")
    # steps 0 and 1 linearize at {0} and {1}; step 1's full step returns to {0}: the search starts there
    assert system.searched_at == [1] and trace.step_lengths == [1.0, 0.5, 1.0]
    system = Alternating()
    trace = semismooth_newton_loop(system, start, name="cycle", max_steps=7, line_search="always")
    assert system.searched_at == [0] and trace.step_lengths == [0.5, 1.0]
    with pytest.raises(InputError, match="line_search"):
        semismooth_newton_loop(Alternating(), start, name="cycle", max_steps=7, line_search="sometimes")


def _at_the_solution() -> Obstacle:
    system = Obstacle()
    system.u = system.exact  # every step keeps the set {u > g}
    return system


def test_a_settled_step_that_misses_the_check_is_refined_then_refused():
    system = _at_the_solution()
    system.checks = [(1.0, 1.0), (1e-20, 1.0)]  # the first check fails, the refinement step passes
    trace = semismooth_newton_loop(
        system, np.array([True]), name="node", max_steps=10, line_search="never", rtol=1e-12, refinements=2
    )
    assert trace.steps == 2 and trace.residuals[-1] == 1e-20
    system = _at_the_solution()
    system.checks = [(1.0, 1.0)] * 3
    with pytest.raises(ConvergenceError, match="after 2 refinement steps") as failed:
        semismooth_newton_loop(
            system, np.array([True]), name="node", max_steps=10, line_search="never", rtol=1e-12, refinements=2
        )
    assert failed.value.steps == 3
    system = _at_the_solution()
    system.checks = [(np.nan, 1.0)]
    with pytest.raises(ConvergenceError, match="after 0 refinement steps"):
        semismooth_newton_loop(
            system, np.array([True]), name="node", max_steps=10, line_search="never", rtol=1e-12, refinements=2
        )


def test_a_warm_start_far_above_a_collapsing_solution_is_refined_to_the_check():
    """From u = 1 to the solution u* ≈ 1e-12 (depth 0, load 1e-6): the step Δu ≈ −1 is exact to rounding of 1,
    so the settled iterate misses the check measured at u* by far (‖F‖/scale ≈ 1e-5), and one step of
    iterative refinement (the correction is of the size of u*) meets it; without refinement it is refused."""
    for refinements in (2, 0):
        system = Obstacle(k=1.0, delta=1e-6, g=0.0, f=1e-6)
        system.u = 1.0
        checks, measure = [], system.check

        def check(measure=measure, checks=checks):
            checks.append(measure())
            return checks[-1]

        system.check = check
        if refinements == 0:
            with pytest.raises(ConvergenceError, match="after 0 refinement steps"):
                semismooth_newton_loop(
                    system, np.array([True]), name="node", max_steps=10, line_search="never", rtol=1e-8
                )
            continue
        trace = semismooth_newton_loop(
            system, np.array([True]), name="node", max_steps=10, line_search="never", rtol=1e-8, refinements=2
        )
        assert trace.steps == 2 and checks[0].residual > 1e-8 * checks[0].scale
        assert checks[1].residual <= 1e-15 * checks[1].scale and system.u == pytest.approx(system.exact, rel=1e-14)


def test_a_failure_inside_a_step_counts_that_step():
    class Singular(Obstacle):
        def solve(self, active):
            if self.calls == 1:
                raise ConvergenceError("singular")
            self.calls += 1
            return super().solve(active)

    system = Singular()
    system.calls = 0
    with pytest.raises(ConvergenceError, match="singular") as failed:
        semismooth_newton_loop(system, np.array([False]), name="node", max_steps=10, line_search="never")
    assert failed.value.steps == 2
