"""The strategy of every frictional contact solve: the Newton on the law, then the fixed point on the thresholds.

One body (``fem.friction``), its Γ_C system condensed onto nodal unknowns (``fem.condensed_friction``) and a contact
pair (``fem.two_body_friction``) solve the penalized friction law the same way (``solve_frictional``):

1. with ``predict``, the Newton on the law linearized first at the state of the last committed load step
   (``NodalFriction.predicted_state``; Coulomb: ``LAW_STEPS`` steps): dragged on, most nodes keep their state;
2. the Newton on the law from the trial state (Tresca: a convex energy, its failure raises);
3. for Coulomb, the fixed point on the thresholds: τ = μp frozen at the current iterate, the convex problem with
   frozen τ solved, until τ settles (``FIXED_POINT_TOL``) or, with ``handover``, until two successive iterates
   have the same contact and stick/slip sets, where the Newton on the law takes over; then the Newton on the law
   from the fixed point's iterate, and should it fail the iterate itself (``FrictionalSolve.settle``).

The first press of a path (``press``: Coulomb, no load step committed; the one-body and condensed solves) goes to
the fixed point at once, and hands over as soon as two successive iterates have the same contact set.  Pressed
from the unloaded state, the Newton on the law cycles: on 2D model 3 at contrast 10³ a slipping node's step carries
its trial traction far across to the other side (in 2D a slipping node has no tangential stiffness), the reversal
rule makes it stick, the stick sends it back, and 12 nodes change stick/slip at every step for ten steps.  The fixed
point's first problem has the thresholds of the starting iterate, which the obstacle penetrates everywhere: every
node sticks (a bonded press: the normal contact set in 3–4 steps); the next has the bonded press's thresholds, and
the Newton on the law finishes from there (``benchmarks/results/friction.md``).  The one-body and condensed solves
in 3D, where a slipping node keeps a tangential stiffness across its slip, first run the Newton on the law from the
displacement of the load alone (``fem.friction.frictional_newton``, ``fem.condensed_friction.solve_condensed``) and
come here should it not converge.

What a solve provides is a ``FrictionalSolve``: its Newton, its iterate to save and restore, the thresholds and sets
of the iterate, and what to do with the fixed point's iterate.  The condensed system predicts (on 2D model 3 and the
3D channel cube its Newton then takes 2–8 steps per drag step, 15–53 without); the one-body and the pair solves do
not: Ω₂'s solve inside Algorithm 1's interface Newton is then the same as the condensed one's to round-off, while from
the committed state it converged on the friction demo's long drag to another solution of the penalized Coulomb
equations (which need not have one), and the interface Newton took 9 applications of T to a result 7·10⁻⁶ off.
"""

from typing import Protocol

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError

__all__ = ["FrictionalSolve", "solve_frictional", "LAW_STEPS", "FIXED_POINT_STEPS", "FIXED_POINT_TOL"]

#: the steps of a Newton on the Coulomb law with another strategy to follow: on the tests' paths the Newton on the law
#: converges in at most 8 steps or cycles between slip states
LAW_STEPS = 10

#: thresholds' fixed-point iterations at most, and their relative tolerance
FIXED_POINT_STEPS = 200
FIXED_POINT_TOL = 1.0e-12


class FrictionalSolve(Protocol):
    """A frictional contact problem as ``solve_frictional`` sees it (an iterate it updates in place)."""

    friction: object  #: its ``NodalFriction``
    comm: MPI.Comm  #: the ranks sharing its law (the thresholds' change is reduced over them)

    def newton(self, *, energy: bool, state, max_steps: int | None) -> None:
        """The Newton on the law (``energy``: with frozen thresholds, a convex energy) from the current iterate,
        linearized first at ``state`` (None: the state rule's), in ``max_steps`` steps (None: the solve's own
        number); ConvergenceError when it does not converge."""

    def save(self) -> object:
        """The current iterate (a copy)."""

    def restore(self, saved: object) -> None:
        """Go back to a saved iterate."""

    def thresholds(self) -> np.ndarray:
        """τ at the current iterate (this rank's nodes)."""

    def sets(self) -> tuple[np.ndarray, ...]:
        """The contact and stick/slip sets of the current iterate."""

    def settle(self) -> None:
        """Accept the fixed point's iterate, the Newton on the law having failed from it (or raise)."""


def _same(a: tuple[np.ndarray, ...], b: tuple[np.ndarray, ...] | None) -> bool:
    return b is not None and all(np.array_equal(x, y) for x, y in zip(a, b))


def solve_frictional(
    solve: FrictionalSolve, *, predict: bool, trial_steps: int | None, handover: bool, press: bool = False
) -> None:
    """Solve ``solve`` by the strategy of the module docstring (``predict``: with its first step, from the committed
    state; ``press``: the first press of a path, nothing committed); ``trial_steps``: the Coulomb Newton's steps from
    the trial state (None: the solve's own number)."""
    friction = solve.friction
    coulomb = friction.law.law == "coulomb"
    start = solve.save()
    predicted = friction.predicted_state() if predict else None
    if predicted is not None:
        try:
            return solve.newton(energy=not coulomb, state=predicted, max_steps=LAW_STEPS if coulomb else None)
        except ConvergenceError:
            solve.restore(start)
    first = press and coulomb
    if not first:
        try:
            return solve.newton(energy=not coulomb, state=None, max_steps=trial_steps if coulomb else None)
        except ConvergenceError:
            if not coulomb:
                raise
            solve.restore(start)
    previous = None
    for _ in range(FIXED_POINT_STEPS):
        tau = solve.thresholds()
        friction.frozen, friction.settle_on_sets = tau, handover or first
        try:
            solve.newton(energy=True, state=None, max_steps=None)
        finally:
            friction.frozen, friction.settle_on_sets = None, False
        change = np.max(np.abs(solve.thresholds() - tau), initial=0.0)
        size = np.max(tau, initial=0.0)
        change, size = (solve.comm.allreduce(v, op=MPI.MAX) for v in (change, size))
        if change <= FIXED_POINT_TOL * size:
            break
        if handover or first:
            sets = solve.sets()[:1] if first else solve.sets()
            if solve.comm.allreduce(_same(sets, previous), op=MPI.LAND):
                reached = solve.save()
                try:  # the sets have settled: the Newton on the law finds the thresholds with them
                    return solve.newton(energy=False, state=None, max_steps=LAW_STEPS)
                except ConvergenceError:
                    solve.restore(reached)
            previous = sets
    reached = solve.save()
    try:  # the Newton on the law settles the state exactly (the fixed point ends at FIXED_POINT_TOL)
        return solve.newton(energy=False, state=None, max_steps=None)
    except ConvergenceError:
        solve.restore(reached)
    solve.settle()
