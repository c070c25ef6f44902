"""Friction between two deformable bodies: the one-body nodal law (``fem.friction``) on the relative displacement.

At each slave node p of the contact pair the law acts on the mortar-weighted relative displacement

    r_p = (1/w_p) Σ_q w_q N_p(x_q) (u_s(x_q) − u_m(π(x_q))),      (``ContactQuadrature.relative``: r = G u)

the slave body's displacement minus the master's at the projection π of each slave point: its normal part
r_p·ν_p − g_p is the penetration, its tangential part P_p r_p = (I − ν_p⊗ν_p) r_p the relative slip.  The
contact force on the slave node is the one-body law's λ_p(r_p) = w_p p_p ν_p − w_p t_p (normal penalty pressure
p_p, tangential traction t_p of the return mapping with its state carried between load steps), and the
residual and Jacobian of the two bodies gain

    F += Gᵀ λ(G u),      J += Gᵀ blockdiag(∂λ_p/∂r_p) G,

so the master's nodes carry the equal and opposite force (each row of G sums to zero over the two bodies'
nodes: partitions of unity).  With a flat master ν_p·r_p − g_p is the frictionless solve's weighted gap s̃_p
(``fem.mortar.nodal_gaps``); on a curved one the normal is the slave node's averaged ν_p.  The Newton iteration is
the one-body frictional Newton's (``fem.newton.semismooth_newton_loop``, the state rule
``NodalFriction.next_state``, Tresca with the exact line search on its convex energy, Coulomb full steps until a
state recurs and then a backtracking search on ‖F‖), with the fixed point on the Coulomb thresholds should it
not converge.  The relative slip of a step is measured from the anchors the previous converged step committed.
"""

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.fem.condensed_friction import nodal_forces
from fenics_contact.fem.contact import NewtonHistory, NewtonOptions, profile_order
from fenics_contact.fem.friction import FrictionProfile, NodalFriction, _tangent_2d
from fenics_contact.fem.friction_strategy import solve_frictional
from fenics_contact.fem.linalg import SparseFactor
from fenics_contact.fem.mortar import ContactQuadrature
from fenics_contact.fem.newton import Advance, Check, Direction, StepState, exact_step, semismooth_newton_loop
from fenics_contact.fem.two_body import TwoBodySystem
from fenics_contact.problem.friction import Friction

__all__ = ["PairFriction", "FrictionalTwoBodySystem", "solve_frictional_pair"]


class PairFriction(NodalFriction):
    """``NodalFriction``'s law at the slave nodes of a contact pair (the rows of the nodal quadrature ``Q``),
    evaluated at relative displacements (``nodal``, (N, d)); ``stiffness``: the elastic stiffness against each
    node's relative displacement (the state rule's β); ``anchor``: the committed anchors (None: unstretched)."""

    def __init__(self, law: Friction, Q: ContactQuadrature, delta: float, stiffness: np.ndarray, anchor=None):
        # (no NodalFriction.__init__: no subproblem of its own, as hybrid.friction's gathered law)
        d = Q.nu.shape[1]
        self.sub, self.law, self.delta, self.d = None, law, float(delta), d
        self.k_t = law.stiffness_ratio / self.delta
        self.comm = MPI.COMM_SELF
        self._nodal_geometry = (Q.nu, Q.weights, Q.gap)
        self.points = Q.points
        self.nodes = np.arange(Q.weights.size)
        self.free = np.ones((self.nodes.size, d), dtype=bool)  # (the supports act on u, not on r)
        self.anchor = np.zeros((self.nodes.size, d)) if anchor is None else np.array(anchor, dtype=np.float64)
        if self.anchor.shape != (self.nodes.size, d):
            raise InputError(
                f"the state's friction anchors have the shape {self.anchor.shape}, this pair has {self.nodes.size} "
                f"slave nodes in {d}D: a state belongs to the load path of the same mesh and pair"
            )
        self.stiffness, self.motion = np.asarray(stiffness, dtype=np.float64), np.zeros(d)
        self.dissipation, self.forced, self.frozen, self.nodal, self.linearized = 0.0, None, None, None, None
        self.committed = None

    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._nodal_geometry

    def profile(self) -> FrictionProfile:
        """The tangential traction on the slave body, pressure and stick/slip state at the slave nodes (at
        ``nodal``), in profile order."""
        e = self.evaluate()
        order = profile_order(self.points)
        arrays = (self.points, e["w"], e["t"], e["p"], e["stick"], e["slip"], _tangent_2d(e["nu"]))
        return FrictionProfile(*(a[order] for a in arrays))


class FrictionalTwoBodySystem(TwoBodySystem):
    """The two-body equations with friction as a ``fem.newton.ContactSystem``: F(u) = K u − b + Gᵀ λ(G u) on
    the free rows (module docstring); its set is the contact set with the friction state the law is linearized
    on (``NodalFriction.forced``).  ``energy``: frozen thresholds (a convex energy; the exact line search)."""

    def __init__(self, K, b, fixed, values, Q: ContactQuadrature, delta: float, law: Friction, anchor=None) -> None:
        super().__init__(K, b, fixed, values, Q, delta)
        keep = sp.diags(self.free.astype(np.float64))
        self.G = (Q.relative @ keep).tocsr()
        d = Q.nu.shape[1]
        # the stiffness against r_p: 1 / Σ_j G_pj² / K_jj over the free DOFs j (component 0; nodes uncoupled)
        diagonal = np.where(self.free, self.K.diagonal(), np.inf)
        G0 = self.G[0::d]
        compliance = G0.multiply(G0) @ (1.0 / diagonal)
        stiffness = 1.0 / np.maximum(compliance, np.finfo(float).tiny)
        self.friction = PairFriction(law, Q, delta, stiffness, anchor)
        self.energy = False
        self._key_factorized: np.ndarray | None = None

    # -- the law at u -------------------------------------------------------------------------------
    def at(self, u: np.ndarray) -> None:
        """Evaluate the law at the relative displacements of u from now on."""
        self.friction.nodal = (self.Q.relative @ u).reshape(-1, self.friction.d)

    def forces(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """λ(G u) (dN), its blocks ∂λ_p/∂r_p (N, d, d) and the evaluated law, in the law's current state
        (``fem.condensed_friction.nodal_forces``)."""
        return nodal_forces(self.friction, self.Q.relative @ u)

    def profile(self) -> FrictionProfile:
        """The slave side's ``FrictionProfile`` at the current u."""
        self.at(self.u)
        return self.friction.profile()

    def contact_force(self, u: np.ndarray | None = None) -> np.ndarray:
        """Gᵀ λ on the free DOFs: the contact term of F."""
        return self.G.T @ self.forces(self.u if u is None else u)[0]

    def contact_force_vector(self) -> np.ndarray:
        """−Gᵀ λ: the contact forces (normal and tangential) on every DOF."""
        return -(self.Q.relative.T @ self.forces(self.u)[0])

    def _assemble_residual(self) -> np.ndarray:
        lam, self._blocks, _ = self.forces(self.u)
        self._lam = lam
        self.F = (self.K @ self.u - self.b) * self.free + self.G.T @ lam
        return self.F

    def state(self, u: np.ndarray):
        """The friction state the Newton linearizes at next from u (``NodalFriction.next_state``)."""
        self.at(u)
        return self.friction.next_state(plain=self.energy)

    def start(self, state=None) -> np.ndarray:
        """Linearize at ``state`` (None: the state rule's at the current u); the set to start the Newton loop with."""
        self.friction.forced = None
        self.friction.forced = self.state(self.u) if state is None else state
        self._key_factorized = None
        return self.key(self.friction.forced)

    def key(self, state) -> np.ndarray:
        """The contact set with the friction state (``NodalFriction.key``)."""
        self.at(self.u)
        return np.concatenate([self.friction.evaluate()["active"], self.friction.key(state)])

    # -- ContactSystem ------------------------------------------------------------------------------
    def jacobian(self, active: np.ndarray) -> bool:
        """K + Gᵀ blockdiag(∂λ/∂r) G on the free rows and columns (the blocks of the last residual); refactorized
        unless the set is the factorized one in 2D (there the blocks depend on the set only)."""
        if self.friction.d == 2 and self._key_factorized is not None and np.array_equal(active, self._key_factorized):
            return False
        N, d = self._blocks.shape[:2]
        blocks = sp.bsr_matrix((self._blocks, np.arange(N), np.arange(N + 1)), shape=(N * d, N * d)).tocsr()
        self._J = (self._K_free + self.G.T @ blocks @ self.G).tocsr()
        if self._factor is not None:
            self._factor.destroy()
        self._factor = SparseFactor.from_csr(self._J, what="the frictional two-body contact Jacobian")
        self._key_factorized = active.copy()
        return True

    def solve(self, active: np.ndarray) -> Direction:
        self.d = self._factor.solve(-self.F[:, None])[:, 0]
        size = np.max(np.abs(self.u), initial=0.0)
        self._negligible = np.max(np.abs(self.d), initial=0.0) <= 1e-12 * size
        self._next = self.state(self.u + self.d)
        return Direction(self._key_at(self.u + self.d, self._next))

    def _key_at(self, u: np.ndarray, state) -> np.ndarray:
        keep, self.u = self.u, u
        try:
            return self.key(state)
        finally:
            self.u = keep

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Equal sets and, where the Jacobian varies within a set (3D slip), a negligible step; or a negligible
        step alone (a node on the stick/slip threshold to round-off predicts the other state; ``check`` then
        measures the law's own residual)."""
        return (bool(np.array_equal(a, b)) and self.friction.d == 2) or self._negligible

    def _gradient(self, u: np.ndarray) -> np.ndarray:
        return (self.K @ u - self.b) * self.free + self.G.T @ self.forces(u)[0]

    def line_search(self) -> float:
        """With the law's own residual (not the linearized state): ``energy``, the root in (0, 1] of the
        increasing slope d·F(u + t d) of the convex energy (regula falsi, Illinois); otherwise backtracking on
        ‖F‖ (Armijo)."""
        keep, self.friction.forced = self.friction.forced, None
        try:
            u, d = self.u, self.d * self.free
            if not self.energy:
                norm0, t = np.linalg.norm(self._gradient(u)), 1.0
                while t > 1e-9 and np.linalg.norm(self._gradient(u + t * d)) > (1.0 - 1e-4 * t) * norm0:
                    t *= 0.5
                return t

            def slope(t: float) -> float:
                return float(d @ self._gradient(u + t * d))

            return exact_step(slope)
        finally:
            self.friction.forced = keep

    def advance(self, t: float, state: StepState) -> Advance:
        self.u += t * self.d
        self.friction.forced = self._next if t == 1.0 else self.state(self.u)
        active = self.key(self.friction.forced)
        return Advance(active, int(np.count_nonzero(active)))

    def check(self) -> Check:
        """‖F‖∞ of the law itself against ‖ |J||u| + |b| + |G|ᵀ|λ| ‖∞ (the size of the terms F balances)."""
        keep, self.friction.forced = self.friction.forced, None
        try:
            F = self._assemble_residual()
        finally:
            self.friction.forced = keep
        J = self._J if self._J is not None else self._K_free
        scale = abs(J) @ np.abs(self.u) + np.abs(self.b) * self.free + abs(self.G).T @ np.abs(self._lam)
        return Check(float(np.max(np.abs(F), initial=0.0)), float(np.max(scale, initial=0.0)), float(np.linalg.norm(F)))

    def commit(self) -> float:
        """End the load step at the converged u (``NodalFriction.commit``): the step's dissipation."""
        self.friction.forced = None
        self.at(self.u)
        return self.friction.commit()


def _newton(system: FrictionalTwoBodySystem, newton: NewtonOptions, refinements: int, *, energy: bool, state, steps):
    system.energy = energy
    try:
        return semismooth_newton_loop(
            system,
            system.start(state),
            name="frictional two-body contact",
            max_steps=steps,
            line_search="on-cycle",
            rtol=newton.rtol,
            atol=newton.atol,
            refinements=refinements,
            sizes="contact and friction state sizes",
        )
    finally:
        system.friction.forced = None


class _PairSolve:
    """A ``FrictionalTwoBodySystem`` as a ``fem.friction_strategy.FrictionalSolve``: the converged Newtons' traces
    in ``history``; the fixed point's iterate is accepted when it passes the system's residual check."""

    comm = MPI.COMM_SELF

    def __init__(self, system: FrictionalTwoBodySystem, newton: NewtonOptions, refinements: int) -> None:
        self.system, self.options, self.refinements = system, newton, refinements
        self.friction, self.history = system.friction, NewtonHistory()

    def newton(self, *, energy: bool, state, max_steps: int | None) -> None:
        limit = self.options.max_iterations
        steps = limit if max_steps is None else min(limit, max_steps)
        trace = _newton(self.system, self.options, self.refinements, energy=energy, state=state, steps=steps)
        self.history.residuals += trace.residuals
        self.history.active_sizes += trace.active_sizes
        self.history.factorizations += trace.factorizations

    def save(self) -> np.ndarray:
        return self.system.u.copy()

    def restore(self, saved: np.ndarray) -> None:
        self.system.u[:] = saved

    def thresholds(self) -> np.ndarray:
        self.system.at(self.system.u)
        return self.friction.evaluate()["tau"]

    def sets(self) -> tuple[np.ndarray, ...]:
        self.system.at(self.system.u)
        e = self.friction.evaluate()
        return e["active"], self.friction.key(self.friction.state_of(e))

    def settle(self) -> None:
        check = self.system.check()
        newton = self.options
        if not (np.isfinite(check.residual) and check.residual <= newton.rtol * check.scale + newton.atol):
            raise ConvergenceError(
                f"frictional two-body contact: the thresholds' fixed point ended with the residual "
                f"{check.residual:.3e} above {newton.rtol:g} x the size of its terms ({check.scale:.3e})"
            )
        self.history.residuals.append(check.recorded)


def solve_frictional_pair(system: FrictionalTwoBodySystem, newton: NewtonOptions, refinements: int) -> NewtonHistory:
    """Solve the frictional two-body system from its current u (``fem.friction_strategy.solve_frictional``, as
    ``fem.friction.frictional_newton``): the Newton on the law (Tresca: with the exact line search on its convex
    energy) from the trial state; should it not converge, the fixed point on the
    thresholds (each step a convex problem, τ frozen) until they settle, then the Newton on the law from there (or
    the fixed point's result when its residual passes the check)."""
    solve = _PairSolve(system, newton, refinements)
    solve_frictional(solve, predict=False, trial_steps=None, handover=False)
    return solve.history
