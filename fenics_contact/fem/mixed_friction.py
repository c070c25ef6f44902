"""Friction on Γ_C of the mixed subproblem: the law on the tangential traction, its Newton and the load-step state.

With friction the tangential traction σ_t = t·σn (t = (−n_y, n_x), n the body's outward normal) is an unknown on
Γ_C (no essential σn·t = 0 there), and the natural boundary term −∫_ΓC u·τn ds takes the boundary displacement
from the law, normal and tangential, written on the traction:

    u_c = g − (σ_c)⁺/ε,      u_t = m_t + a − (1/ε_t)(σ_t − Π_τ σ_t),      Π_τ s = max(−τ, min(τ, s)),

m_t = m·t the obstacle's rigid tangential motion, a the node's anchor (its accumulated slip: after each converged
load step a ← a − (σ_t − Π_τ σ_t)/ε_t), τ the threshold: Tresca τ = s on all of Γ_C, Coulomb τ = μ (−σ_c)⁺.
Sticking (|σ_t| ≤ τ) the boundary moves with the obstacle exactly (u_t = m_t + a, as u_c = g exactly in
compression); slipping, the traction exceeds the threshold by ε_t times the step's slip, the tangential
analogue of the tensile stress ε|u_c| the normal penalty leaves in a gap.  ε_t = ε / ``stiffness_ratio``
(default ε_t = ε = 1e-3·h·E_c): as ε_t → 0 the law is the exact Coulomb (Tresca) law, the limit of the primal
law's stick penalty δ_t → 0 too; ``stiffness_ratio`` > 1 brings both closer to it.

At the Gauss–Lobatto contact nodes (``mixed_contact``: a nodal basis of the traces σ_c, σ_t, both continuous P3
on a straight Γ_C) the term is nodal: F_σ += Tᵀ W [(σ_t − Π_τ σ_t)/ε_t − (m_t + a)], T the nodal values of
σ_t.  Its generalized Jacobian per node is (w/ε_t)·[slip] on σ_t and, for a slipping Coulomb node in contact,
± (w μ/ε_t) on σ_c (non-symmetric; the saddle-point matrix takes 2 × 2 weights per node,
``distributed.SaddlePointMatrix``).  On a fixed state (contact, stick, slip and its sign) the equations are
affine, so the semismooth Newton terminates finitely.  Tresca, and Coulomb with the thresholds frozen, is the
gradient of the convex complementary energy J + (1/2ε_t) Σ w ((|σ_t| − τ)⁺)² − Σ w (m_t + a) σ_t, globalized by
its exact line search; Coulomb by a backtracking line search on ‖F‖, and should that fail, by the fixed point on
the thresholds (each a frozen-threshold problem), as the primal ``fem.friction``.  A step's dissipation is
Σ w σ_t (σ_t − Π_τ σ_t)/ε_t ≥ 0 (the traction times the slip).
"""

import logging

import numpy as np

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.friction import FrictionProfile
from fenics_contact.fem.friction_strategy import FIXED_POINT_STEPS, FIXED_POINT_TOL
from fenics_contact.fem.mixed_assembly import dot, norm
from fenics_contact.fem.mixed_newton import MixedNewtonHistory, run_mixed_newton
from fenics_contact.fem.mixed_traces import tangent_of
from fenics_contact.fem.newton import Advance, Check, Direction, StepState
from fenics_contact.problem.friction import Friction

__all__ = ["MixedFriction", "frictional_mixed_newton"]

log = logging.getLogger(__name__)


class MixedFriction:
    """The friction law at the Γ_C contact nodes of a ``MixedSubproblem`` (replicated node data) and its state.

    ``epsilon``: the normal penalty ε; ε_t = ε / ``law.stiffness_ratio``.  The state is the anchor a per node
    and the obstacle motion m; ``commit`` ends a load step.  ``frozen``: thresholds held fixed (the fixed point
    of ``frictional_mixed_newton``), or None: the law's.
    """

    def __init__(self, sub, law: Friction, epsilon: float) -> None:
        self.sub, self.law, self.nodes = sub, law, sub.contact_nodes
        self.epsilon, self.epsilon_t = float(epsilon), float(epsilon) / law.stiffness_ratio
        self.d, self.comm = 2, sub.comm
        self.tangent = tangent_of(self.nodes.q_normals)  #: t per node (replicated)
        self.anchor = np.zeros(self.tangent.shape[0])
        self.motion = np.zeros(2)
        self.dissipation = 0.0  #: accumulated over the committed load steps
        self.frozen: np.ndarray | None = None

    # -- the law ---------------------------------------------------------------------------------------------
    def stresses(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(σ_c, σ_t) at the nodes (replicated) of the AW coefficients c."""
        return self.nodes.stress(c), self.nodes.tangential_stress(c)

    def threshold(self, s_c: np.ndarray) -> np.ndarray:
        """τ per node: the frozen thresholds, μ(−σ_c)⁺ (Coulomb) or s (Tresca)."""
        if self.frozen is not None:
            return self.frozen
        if self.law.law == "coulomb":
            return self.law.mu * np.maximum(-s_c, 0.0)
        return np.full(s_c.size, self.law.threshold)

    @property
    def coupled(self) -> bool:
        """Whether σ_t's equation depends on σ_c (Coulomb with the law's thresholds): a non-symmetric Jacobian."""
        return self.law.law == "coulomb" and self.frozen is None

    @property
    def convex(self) -> bool:
        """Whether the equations are the gradient of a convex energy (Tresca, or frozen thresholds)."""
        return not self.coupled

    def excess(self, s_c: np.ndarray, s_t: np.ndarray) -> np.ndarray:
        """σ_t − Π_τ σ_t: ε_t times the slip of the step (zero where the node sticks)."""
        tau = self.threshold(s_c)
        return s_t - np.clip(s_t, -tau, tau)

    def target(self) -> np.ndarray:
        """m_t + a per node: where the boundary sticks."""
        return self.tangent @ self.motion + self.anchor

    def load(self) -> np.ndarray:
        """Tᵀ W (m_t + a) (owned AW entries): the sticking target moved to the right-hand side."""
        nodes = self.nodes
        return nodes.T.T @ nodes.block(nodes.q_weights * self.target())

    def force(self, c: np.ndarray) -> np.ndarray:
        """Tᵀ W (σ_t − Π_τ σ_t)/ε_t (owned AW entries)."""
        nodes = self.nodes
        return nodes.T.T @ nodes.block(nodes.q_weights * self.excess(*self.stresses(c)) / self.epsilon_t)

    def energy(self, c: np.ndarray) -> float:
        """(1/2ε_t) Σ w ((|σ_t| − τ)⁺)² (the thresholds of ``threshold``; the target's share is in the load)."""
        return 0.5 * float(np.sum(self.nodes.q_weights * self.excess(*self.stresses(c)) ** 2)) / self.epsilon_t

    def key(self, s_c: np.ndarray, s_t: np.ndarray) -> np.ndarray:
        """The state as a boolean array: penalty active (σ_c > 0), slip forward (σ_t > τ), slip back (σ_t < −τ)."""
        tau = self.threshold(s_c)
        return np.concatenate([s_c > 0.0, s_t > tau, s_t < -tau])

    def cold_key(self) -> np.ndarray:
        """The first state of a cold start: penalty and (forward) slip everywhere, a traction-free Γ_C."""
        n = self.anchor.size
        return np.concatenate([np.ones(n, bool), np.ones(n, bool), np.zeros(n, bool)])

    def weights(self, key: np.ndarray) -> np.ndarray:
        """The 2 × 2 Jacobian weights (rows: test σ_c, σ_t; columns: σ_c, σ_t) of the nodes this rank evaluates."""
        n, rows = self.anchor.size, self.nodes.rows
        pen, up, down = key[:n][rows], key[n : 2 * n][rows], key[2 * n :][rows]
        w = self.nodes.q_weights[rows]
        W = np.zeros((rows.size, 2, 2))
        W[:, 0, 0] = np.where(pen, w / self.epsilon, 0.0)
        W[:, 1, 1] = np.where(up | down, w / self.epsilon_t, 0.0)
        if self.coupled:  # slip: σ_t ∓ μσ_c in contact
            sign = up.astype(float) - down.astype(float)
            W[:, 1, 0] = np.where(~pen, sign * w * self.law.mu / self.epsilon_t, 0.0)
        return W

    def cache_key(self, key: np.ndarray) -> np.ndarray:
        """The factorization's key: the state and whether the Jacobian is coupled."""
        return np.concatenate([key, [self.coupled]])

    # -- load steps --------------------------------------------------------------------------------------------
    def set_motion(self, motion) -> None:
        """The obstacle's rigid motion m (a 2-vector) from the reference position of the anchors."""
        m = np.zeros(2)
        v = np.asarray(motion, dtype=np.float64).ravel()
        m[: min(v.size, 2)] = v[:2]
        self.motion = m

    def commit(self) -> float:
        """End the load step at the current (converged) σ: move the anchors by the slip −(σ_t − Π_τ σ_t)/ε_t and
        add the step's dissipation Σ w σ_t (σ_t − Π_τ σ_t)/ε_t to ``dissipation``; returns the step's."""
        s_c, s_t = self.stresses(self.sub.c)
        slip = self.excess(s_c, s_t) / self.epsilon_t
        step = float(np.sum(self.nodes.q_weights * s_t * slip))
        self.anchor -= slip
        self.dissipation += step
        return step

    def profile(self) -> FrictionProfile:
        """The tangential traction σ_t t, the pressure (−σ_c)⁺ and the stick/slip state at the contact nodes
        (clamped corners excluded; profile order), on every rank."""
        keep = self.nodes.profile_nodes
        s_c, s_t = self.stresses(self.sub.c)
        tau = self.threshold(s_c)
        stick = (tau > 0.0) & (np.abs(s_t) <= tau)
        slip = (tau > 0.0) & ~stick
        return FrictionProfile(
            self.nodes.q_points[keep],
            self.nodes.q_weights[keep],
            (s_t[:, None] * self.tangent)[keep],
            np.maximum(-s_c, 0.0)[keep],
            stick[keep],
            slip[keep],
            self.tangent[keep],
        )


class _FrictionalMixedSystem:
    """A frictional ``MixedSubproblem`` as a ``fem.newton.ContactSystem``: its set is ``MixedFriction.key``;
    with a convex law (Tresca, frozen thresholds) the exact line search on the energy once the equilibrium
    equation holds, else (Coulomb) a backtracking line search on ‖F‖."""

    def __init__(self, problem, load: np.ndarray, data: np.ndarray | None) -> None:
        self.problem, self.load, self.data = problem, load, data
        self.friction = problem.friction
        self.nodes = problem.contact_nodes
        self.energies: list[float] = []
        self.s_c, self.s_t = self.friction.stresses(problem.c)

    def start(self) -> np.ndarray:
        return self.friction.cold_key() if self.problem.cold else self.friction.key(self.s_c, self.s_t)

    def residual(self) -> float:
        self.F1, self.F2 = self.problem.gradient(self.load)
        return self.problem.residual_norm(self.F1, self.F2)

    def jacobian(self, active: np.ndarray) -> bool:
        return self.problem.factorize_for(active)

    def solve(self, active: np.ndarray) -> Direction:
        problem, comm, nodes = self.problem, self.problem.comm, self.nodes
        B, G = problem.assembly.B, problem.assembly.G
        feasible = norm(self.F2, comm) <= 1e-10 * (norm(G, comm) + norm(B @ problem.c, comm))
        self.dc, self.du = problem.linear_solve(-self.F1, -self.F2)
        self.d_c = nodes.replicate(nodes.Q @ self.dc)
        self.d_t = nodes.replicate(nodes.T @ self.dc)
        predicted = self.friction.key(self.s_c + self.d_c, self.s_t + self.d_t)
        return Direction(predicted, searchable=feasible or not self.friction.convex)

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return np.array_equal(a, b)  # (replicated Γ_C data)

    def line_search(self) -> float:
        return self._exact_search() if self.friction.convex else self._backtracking()

    def _exact_search(self) -> float:
        """argmin_{t ∈ (0, 1]} of the convex, piecewise quadratic energy along the direction: the root of its
        increasing, piecewise linear derivative (breakpoints where σ_c changes sign or |σ_t| crosses τ)."""
        problem, comm = self.problem, self.problem.comm
        Kt, dc = problem.assembly.Kt, self.dc
        a = dot(dc, Kt @ dc, comm)
        b0 = dot(Kt @ problem.c - self.load, dc, comm)
        w = self.nodes.q_weights
        tau = self.friction.threshold(self.s_c)
        s_c, d_c, s_t, d_t = self.s_c, self.d_c, self.s_t, self.d_t
        eps, eps_t = self.friction.epsilon, self.friction.epsilon_t

        def dphi(t: np.ndarray) -> np.ndarray:
            x_c = s_c[None, :] + t[:, None] * d_c[None, :]
            x_t = s_t[None, :] + t[:, None] * d_t[None, :]
            excess = x_t - np.clip(x_t, -tau[None, :], tau[None, :])
            return (
                a * t + b0 + (w * d_c * np.maximum(x_c, 0.0)).sum(axis=1) / eps + (w * d_t * excess).sum(axis=1) / eps_t
            )

        ends = dphi(np.array([0.0, 1.0]))
        if ends[0] >= 0.0 or ends[1] <= 0.0:
            return 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            bp = np.concatenate([-s_c / d_c, (tau - s_t) / d_t, (-tau - s_t) / d_t])
        bp = np.unique(np.concatenate([[0.0, 1.0], bp[np.isfinite(bp) & (bp > 0.0) & (bp < 1.0)]]))
        vals = dphi(bp)
        k = int(np.argmax(vals > 0.0))
        t0, t1, v0, v1 = bp[k - 1], bp[k], vals[k - 1], vals[k]
        return float(t0 - v0 * (t1 - t0) / (v1 - v0))

    def _backtracking(self) -> float:
        """The longest t = 2⁻ᵏ with ‖F(x + t d)‖ ≤ (1 − 1e-4 t)‖F(x)‖ (Armijo on the residual)."""
        problem = self.problem
        norm0 = problem.residual_norm(self.F1, self.F2)
        c0, u0 = problem.c, problem.u
        t = 1.0
        try:
            for _ in range(30):
                problem.c, problem.u = c0 + t * self.dc, u0 + t * self.du
                if problem.residual_norm(*problem.gradient(self.load)) <= (1.0 - 1e-4 * t) * norm0:
                    break
                t *= 0.5
        finally:
            problem.c, problem.u = c0, u0
        return t

    def advance(self, t: float, state: StepState) -> Advance:
        problem = self.problem
        problem.cold = False
        problem.c = problem.c + t * self.dc
        problem.u = problem.u + t * self.du
        self.energies.append(problem.complementary_energy(self.data))
        self.s_c, self.s_t = self.friction.stresses(problem.c)
        return Advance(self.friction.key(self.s_c, self.s_t), int(np.count_nonzero(self.s_c <= 0.0)))

    def check(self) -> Check:
        final, scale = self.problem.residual(self.data)
        return Check(final, scale, final)


def _newton(problem, load: np.ndarray, data: np.ndarray | None) -> MixedNewtonHistory:
    return run_mixed_newton(_FrictionalMixedSystem(problem, load, data), problem)


def _append(history: MixedNewtonHistory, more: MixedNewtonHistory) -> None:
    history.residuals += more.residuals
    history.active_sizes += more.active_sizes
    history.factorizations += more.factorizations
    history.step_lengths += more.step_lengths
    history.energies += more.energies


def _fixed_point(problem, load: np.ndarray, data: np.ndarray | None) -> MixedNewtonHistory:
    """Coulomb's thresholds by fixed point: τ frozen at μ(−σ_c)⁺ of the current σ, the frozen (convex) problem
    solved, until τ stops changing; then the Newton on the law itself from there."""
    friction, history = problem.friction, MixedNewtonHistory()
    for _ in range(FIXED_POINT_STEPS):
        tau = friction.threshold(friction.stresses(problem.c)[0])
        friction.frozen = tau
        try:
            _append(history, _newton(problem, load, data))
        finally:
            friction.frozen = None
        change = np.max(np.abs(friction.threshold(friction.stresses(problem.c)[0]) - tau), initial=0.0)
        if change <= FIXED_POINT_TOL * np.max(tau, initial=0.0):
            break
    _append(history, _newton(problem, load, data))
    return history


def frictional_mixed_newton(problem, load: np.ndarray, data: np.ndarray | None) -> MixedNewtonHistory:
    """Solve a frictional ``MixedSubproblem`` with stress-side load ``load`` (Robin data ``data``) from its current
    state: the semismooth Newton on the law (``fem.newton.semismooth_newton_loop``), and for Coulomb, should it
    not converge, the fixed point on the thresholds from the same start (``_fixed_point``)."""
    start = (problem.c.copy(), problem.u.copy(), problem.cold)
    try:
        return _newton(problem, load, data)
    except ConvergenceError as error:
        if problem.friction.law.law != "coulomb":
            raise
        log.info("%s: %s; the fixed point on the friction thresholds instead", problem.prefix.rstrip("_"), error)
        problem.c, problem.u, problem.cold = start[0].copy(), start[1].copy(), start[2]
        return _fixed_point(problem, load, data)
