"""The frictional contact law condensed onto nodal unknowns: U = U_L − M λ(U), dense, by semismooth Newton.

With a linear bulk, the contact displacements U (d components at each of N contact nodes: the Γ_C
displacements of one body, or the relative displacements of a contact pair's slave nodes) are those of the load
U_L minus a compliance M (dN × dN, symmetric positive definite) times the nodal contact forces,

    U = U_L − M λ(U),      λ_p = w_p p_p ν_p − w_p t_p      (``fem.friction``: normal penalty and friction),

λ the nodal law of a ``NodalFriction`` evaluated at given nodal values (``nodal``). ``solve_condensed`` solves it by
the loop of the monolithic frictional Newton (``fem.newton.semismooth_newton_loop`` on
``CondensedFrictionalSystem``: the state rule ``NodalFriction.next_state``, full steps until a state recurs, then a
line search, in 3D from the committed state full steps throughout; in 3D a state is settled once the step is at most
``NEGLIGIBLE`` of U as well, the slip direction varying within it; whatever the state rule predicts, a negligible
step to an iterate that solves the law to round-off ends it, ``ROUNDOFF``), linearized first at the state of the last
committed load step (``NodalFriction.predicted_state``), then at the trial state (in 3D at the first Newton's last
iterate when its residual is the lower), with, for Coulomb, the fixed point
on the thresholds should neither converge in ``LAW_STEPS``: once two of its iterates have the same contact and
stick/slip sets, the Newton on the law from there (it then converges in one or two steps), the fixed point going on
should it fail. The first press of a path (nothing committed) in 3D is the Newton on the law from U_L, the
displacement of the load alone (in ``LAW_STEPS``; in 3D a slipping node keeps a tangential stiffness across its
slip, and this Newton converges where the 2D one cycles). Its first state, the law's at U_L, holds no slip of the
path (U_L is a displacement no contact force acts on), so the state rule's reversal (a slip turning back sticks)
applies from the first iterate on (``loaded``): 8 and 7 steps on the 3D channel cube at contrast 10³ and 10⁶,
against 9 and 9 with the reversal from U_L's slip directions, where the nodes whose load-alone tangential
displacement the first step turns round are told to stick and slip again the step after. In 2D, or should it not
converge, the press goes to the fixed point at once (``fem.friction_strategy``), its frozen-threshold solves ended
once their sets settle. The energy solves (Tresca, frozen thresholds) take the full steps of the primal–dual state
rule while they lower the convex energy, else its exact line search (``CondensedFrictionalSystem``). Used by
Algorithm 1's condensed Γ_C system (``hybrid.friction``) and by the two-body solve under MPI (``fem.two_body_mpi``).
"""

from collections.abc import Callable

import numpy as np
import scipy.linalg as sla
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.friction import ENERGY_STEPS, NEGLIGIBLE, NodalFriction
from fenics_contact.fem.friction_strategy import LAW_STEPS, solve_frictional
from fenics_contact.fem.newton import (
    Advance,
    Direction,
    NewtonTrace,
    StepState,
    exact_step,
    lowers_energy,
    semismooth_newton_loop,
)

__all__ = ["nodal_forces", "CondensedLaw", "CondensedFrictionalSystem", "solve_condensed", "ROUNDOFF"]

#: a negligible step (``NEGLIGIBLE``) to an iterate whose own residual ‖U − U_L + M λ(U)‖ (the law's, in the state of
#: U itself) is at most this times the size of its terms ‖U‖ + ‖U_L‖ + ‖|M| |λ|‖ ends the Newton whatever the state rule
#: predicts: there the solution has nodes on the cone's boundary (|t_trial| = τ to round-off), where the stick and
#: the slip linearization have the same solution, and the state rule flips them on the round-off of each step
ROUNDOFF = 1.0e-12


def nodal_forces(friction: NodalFriction, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """λ(U) (dN) and its block-diagonal Jacobian ∂λ_p/∂U_p (N, d, d) at the nodal values U, in the law's state,
    with the evaluated law (free components only; ``friction.nodal`` is left unset)."""
    d = friction.d
    friction.nodal = U.reshape(-1, d)
    try:
        e = friction.evaluate()
        blocks = friction.blocks(e)
    finally:
        friction.nodal = None
    nu, w = e["nu"], e["w"]
    normal = (w * e["p"])[:, None] * nu
    on = e["active"]
    blocks[on] += (w[on] / friction.delta)[:, None, None] * nu[on][:, :, None] * nu[on][:, None, :]
    lam = (normal - w[:, None] * e["t"]) * friction.free
    blocks *= friction.free[:, :, None] * friction.free[:, None, :]
    return lam.ravel(), blocks, e


class CondensedLaw:
    """The nodal law ``friction`` with the compliance ``M``: λ(U), the residual U − U_L + M λ(U), and M's LU
    (for the exact line search; ``lu`` a factorization to reuse, e.g. of an earlier load step's M)."""

    def __init__(self, friction: NodalFriction, M: np.ndarray, lu=None) -> None:
        self.friction, self.M, self.lu = friction, M, lu

    def forces(self, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        return nodal_forces(self.friction, U)

    def residual(self, U: np.ndarray, U_L: np.ndarray) -> np.ndarray:
        return U - U_L + self.M @ self.forces(U)[0]

    def factor(self):
        """M's LU (made once)."""
        if self.lu is None:
            self.lu = sla.lu_factor(self.M)
        return self.lu


class CondensedFrictionalSystem:
    """U = U_L − M λ(U) as a ``fem.newton.ContactSystem`` (dense): its set is the contact set with the friction
    state (``NodalFriction.next_state``) the law is linearized on, as in ``fem.friction``'s Newton; in 3D a set
    is settled once the step is negligible too (the slip direction varies within it).

    With ``energy`` (frozen thresholds, Tresca) the residual is the gradient M⁻¹(U − U_L) + λ(U) (times M) of the
    convex ψ = ½(U − U_L)ᵀM⁻¹(U − U_L) + Φ(U), and every step is checked on it: the full step of the primal–dual
    state rule is taken when it lowers ψ (its change integrated along the step from the slope), else the exact line
    search along it when it descends, else along the Newton direction of the plain state of U (a generalized
    Hessian of ψ: it descends).  ψ falls at every step, so no state recurs.  Without it (Coulomb) full steps until a
    state recurs, then backtracking on ‖R‖ (Armijo); in 3D from a given ``state`` (the committed one) full steps
    throughout (no line search: see ``_searchable``).  ``loaded``: U is the load's displacement U_L, whose state holds
    no slip of the path: the next state after the first step is the state rule's without the reversal."""

    def __init__(
        self, law: CondensedLaw, U: np.ndarray, U_L: np.ndarray, *, energy: bool, state=None, loaded: bool = False
    ) -> None:
        self.law, self.friction, self.energy = law, law.friction, energy
        self.U, self.U_L = U.copy(), U_L
        self._full = True  #: the last step was the full step of the state rule (its next state is ``_next``)
        #: the state rule's reversal applies (not to the first state of a start at the load's displacement: ``loaded``)
        self._reverse = not loaded
        #: the line search on a recurring set; in 3D from a given state (the committed one) full steps throughout: a
        #: slipping node's direction varies within a set, so a set recurs without a cycle, and a node on the contact
        #: boundary leaves and re-enters contact on the way to the solution; the backtracking on ‖R‖ there accepts
        #: only steps of 10⁻⁵–10⁻⁷ (the normal penalty's kink lies within them) and stalls to the end of its steps
        #: (``LAW_STEPS``: the strategy goes on should it not converge)
        self._searchable = energy or state is None or self.friction.d == 2
        self.friction.forced = None
        self.friction.forced = self._next_state(self.U) if state is None else state

    def _next_state(self, U: np.ndarray, *, plain: bool = False):
        self.friction.nodal = U.reshape(-1, self.friction.d)
        try:
            return self.friction.next_state(plain=plain, reverse=self._reverse)
        finally:
            self.friction.nodal = None

    def key(self, state) -> np.ndarray:
        friction = self.friction
        friction.nodal = self.U.reshape(-1, friction.d)
        try:
            active = friction.evaluate()["active"]
        finally:
            friction.nodal = None
        return np.concatenate([active, friction.key(state)])

    def residual(self) -> float:
        lam, self._blocks, e = self.law.forces(self.U)
        self.friction.linearize(e)
        self._R = self.U - self.U_L + self.law.M @ lam
        return float(np.linalg.norm(self._R))

    def jacobian(self, active: np.ndarray) -> bool:
        self._J = np.eye(self.U.size) + self.law.M @ sla.block_diag(*self._blocks)
        return True

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The sets are equal and, in 3D, the step is negligible (``NEGLIGIBLE``) or the thresholds are frozen
        inside the fixed point before its hand-over (``NodalFriction.settle_on_sets``); or, whatever the sets, the
        step is negligible to an iterate that solves the law to round-off (``ROUNDOFF``)."""
        if not np.array_equal(a, b):
            return self._solved
        friction = self.friction
        return friction.d == 2 or self._negligible or (friction.frozen is not None and friction.settle_on_sets)

    def solve(self, active: np.ndarray) -> Direction:
        self.dU = sla.solve(self._J, -self._R)
        self._negligible = np.max(np.abs(self.dU), initial=0.0) <= NEGLIGIBLE * np.max(np.abs(self.U), initial=0.0)
        self.U += self.dU
        self._next = self._next_state(self.U)
        predicted = self.key(self._next)
        self._solved = self._negligible and self._at_roundoff()
        self.U -= self.dU
        return Direction(predicted, searchable=self._searchable)

    def _at_roundoff(self) -> bool:
        """The law's own residual at U (in the state of U) is at round-off (``ROUNDOFF``)."""
        keep, self.friction.forced = self.friction.forced, None
        try:
            lam = self.law.forces(self.U)[0]
        finally:
            self.friction.forced = keep
        forces = self.law.M @ lam
        scale = np.linalg.norm(self.U) + np.linalg.norm(self.U_L) + np.linalg.norm(np.abs(self.law.M) @ np.abs(lam))
        return bool(np.linalg.norm(self.U - self.U_L + forces) <= ROUNDOFF * scale)

    def line_search(self) -> float:
        keep, self.friction.forced = self.friction.forced, None  # the merit: the residual of the law itself
        try:
            return self._search() if self.energy else self._backtrack()
        finally:
            self.friction.forced = keep

    def _backtrack(self) -> float:
        law, U, dU, U_L = self.law, self.U, self.dU, self.U_L
        norm0, t = np.linalg.norm(law.residual(U, U_L)), 1.0
        while t > 1e-9 and np.linalg.norm(law.residual(U + t * dU, U_L)) > (1.0 - 1e-4 * t) * norm0:
            t *= 0.5
        return t

    def _slope(self, dU: np.ndarray):
        """t ↦ dU·∇ψ(U + t dU)."""
        law, U = self.law, self.U
        lu = law.factor()
        base, step = sla.lu_solve(lu, U - self.U_L), sla.lu_solve(lu, dU)
        return lambda t: float(dU @ (base + t * step + law.forces(U + t * dU)[0]))

    def _search(self) -> float:
        slope = self._slope(self.dU)
        start = slope(0.0)
        if start < 0.0:
            if lowers_energy(slope, start):
                return 1.0
            self._full = False
            return exact_step(slope)
        self._full = False  # no descent: the Newton direction of the plain state of U
        self.friction.forced = self._next_state(self.U, plain=True)
        self.residual()
        self.jacobian(None)
        self.dU = sla.solve(self._J, -self._R)
        return exact_step(self._slope(self.dU))

    def advance(self, t: float, state: StepState) -> Advance:
        self.U += t * self.dU
        self.friction.forced = self._next if t == 1.0 and self._full else self._next_state(self.U)
        self._full = self._reverse = True
        active = self.key(self.friction.forced)
        return Advance(active, int(np.count_nonzero(active)))

    def check(self) -> None:
        """None: a settled iterate is accepted (in 2D the equations are affine on a settled state, solved
        exactly; the caller measures the residual of what it uses)."""
        return None


def _newton(
    law: CondensedLaw, U, U_L, max_steps: int, energy: bool, record, discard, state=None, loaded: bool = False
) -> np.ndarray:
    """The Newton loop on ``CondensedFrictionalSystem`` (an energy's with ``ENERGY_STEPS`` steps at least), linearized
    first at ``state`` (None: the state rule's at U; ``loaded``: U is the load's displacement U_L, whose state holds
    no slip to reverse)."""
    max_steps = max(max_steps, ENERGY_STEPS) if energy else max_steps
    system = CondensedFrictionalSystem(law, U, U_L, energy=energy, state=state, loaded=loaded)
    try:
        trace = semismooth_newton_loop(
            system,
            system.key(law.friction.forced),
            name="condensed frictional contact Newton",
            max_steps=max_steps,
            line_search="always" if energy else "on-cycle",
            sizes="contact and friction state sizes",
        )
    except ConvergenceError as error:
        discard(getattr(error, "steps", 0))
        error.iterate = system.U.copy()
        raise
    finally:
        law.friction.forced = None
    record(trace)
    return system.U


def _plain_state(friction: NodalFriction, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contact and stick/slip sets of U itself (the law's, with the thresholds of U)."""
    friction.nodal = U.reshape(-1, friction.d)
    try:
        e = friction.evaluate()
    finally:
        friction.nodal = None
    return e["active"], friction.key(friction.state_of(e))


class _CondensedSolve:
    """U = U_L − M λ(U) as a ``fem.friction_strategy.FrictionalSolve`` (every rank holds the same data); the fixed
    point's iterate is accepted as it is (the caller measures the residual of what it uses)."""

    comm = MPI.COMM_SELF

    def __init__(self, law: CondensedLaw, U_L: np.ndarray, start: np.ndarray, max_steps: int, record, discard):
        self.law, self.friction = law, law.friction
        self.U_L, self.U, self.max_steps, self.record, self.discard = U_L, start, max_steps, record, discard

    def newton(self, *, energy: bool, state, max_steps: int | None) -> None:
        """The Newton on the law from U; in 3D, should it fail from a given state (the committed one), the Newton
        from the trial state at its last iterate when that iterate's residual is below U's (ConvergenceError
        should that fail too, the caller going on from U)."""
        steps = self.max_steps if max_steps is None else min(self.max_steps, max_steps)
        try:
            self.U = _newton(self.law, self.U, self.U_L, steps, energy, self.record, self.discard, state=state)
        except ConvergenceError as error:
            last = error.iterate
            if state is None or energy or self.friction.d == 2 or not self._closer(last):
                raise
            self.U = _newton(self.law, last, self.U_L, steps, False, self.record, self.discard)

    def _closer(self, U: np.ndarray) -> bool:
        """‖U − U_L + M λ(U)‖ (the law's residual) is below the current iterate's."""
        law, U_L = self.law, self.U_L
        return bool(np.linalg.norm(law.residual(U, U_L)) < np.linalg.norm(law.residual(self.U, U_L)))

    def save(self) -> np.ndarray:
        return self.U

    def restore(self, saved: np.ndarray) -> None:
        self.U = saved

    def thresholds(self) -> np.ndarray:
        self.friction.nodal = self.U.reshape(-1, self.friction.d)
        try:
            return self.friction.evaluate()["tau"]
        finally:
            self.friction.nodal = None

    def sets(self) -> tuple[np.ndarray, ...]:
        return _plain_state(self.friction, self.U)

    def settle(self) -> None:
        return None


def solve_condensed(
    law: CondensedLaw,
    U_L: np.ndarray,
    start: np.ndarray,
    max_steps: int,
    *,
    record: Callable[[NewtonTrace], None] = lambda trace: None,
    discard: Callable[[int], None] = lambda steps: None,
    press: bool = False,
) -> np.ndarray:
    """U = U_L − M λ(U) from ``start`` (``fem.friction_strategy.solve_frictional``): the Newton on the law (Tresca:
    with the exact line search on its convex energy; a failure raises ConvergenceError) linearized first at the
    committed state (``NodalFriction.predicted_state``, when there is one) and, should that not converge, at the
    trial state (in 3D first at its last iterate when that one's residual is below the start's: on the 3D channel
    cube at ν = 0.49 and contrast 10⁶ the last drag's tenth iterate is 4·10⁻¹⁰ from the solution); for Coulomb,
    should neither converge in ``LAW_STEPS``, the fixed point on the thresholds (each a convex problem): as soon as
    two successive iterates of it have the same contact and stick/slip sets, the Newton on the law from there
    (``LAW_STEPS``; the fixed point goes on should it fail), else until the thresholds settle, and the Newton on
    the law from there.  ``press``: the first press of a path (nothing committed): in 3D
    the Newton on the law from U_L first (``LAW_STEPS``; the state rule's reversal from its first iterate on), then
    (and in 2D at once) the fixed point.  ``record`` gets each converged Newton's trace, ``discard`` the steps of
    each that did not converge."""
    if press and law.friction.d == 3 and law.friction.law.law == "coulomb":
        try:  # (from the load's displacement: the contact set of the load alone)
            return _newton(law, U_L, U_L, min(max_steps, LAW_STEPS), False, record, discard, loaded=True)
        except ConvergenceError:
            pass  # (the fixed point)
    solve = _CondensedSolve(law, U_L, start, max_steps, record, discard)
    solve_frictional(solve, predict=True, trial_steps=LAW_STEPS, handover=True, press=press)
    return solve.U
