"""The condensed Γ_C system with friction: every displacement component of the Γ_C nodes, and the nodal law.

With friction the contact force at a Γ_C node is a vector, λ_p = w_p p_p ν_p − w_p t_p (the normal penalty and
the friction traction, ``fem.friction``), so the glued linear problem (Ω₁'s affine interface response, Ω₂ with
no contact node active, ``hybrid.condensation``) is condensed onto all d components of the Γ_C displacements:

    U = U_L − M λ(U),

M (dN × dN) the compliance of the glued problem at the N Γ_C nodes, U_L their displacement under the load with
no contact force.  ``ComponentPart`` is Ω₂ with one contact column per node and component; ``FrictionalCondensation``
solves the nodal law on U by the semismooth Newton of ``fem.friction`` (its state rule, full steps, a
backtracking line search on ‖R‖ once states recur), dense, then returns the interface data as
``CondensedInterface.solve`` does.  The corrections that follow use Ω₂'s exact Jacobian.  Serial only (the
condensation gathers the Γ_C unknowns in the order of one rank's nodes).
"""

import numpy as np
import scipy.linalg as sla

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.friction import FIXED_POINT_STEPS, FIXED_POINT_TOL
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.contact_newton import ContactNewtonHistory
from fenics_contact.hybrid.response import PrimalPart

__all__ = ["ComponentPart", "FrictionalCondensation"]


class ComponentPart(PrimalPart):
    """Ω₂ (a frictional ``PrimalSubproblem``) with the contact rows s = all components of u at the Γ_C nodes."""

    def __init__(self, sub, iface, part: int) -> None:
        super().__init__(sub, iface, part, contact=True, factorize=True)
        d = self.bs
        nodes = self.c_nodes
        self.nodes = nodes
        self.c_nodes = np.repeat(nodes, d)
        self.c_normals = np.tile(np.eye(d), (nodes.size, 1))
        self.n_c = nodes.size * d
        self.D = np.zeros(self.n_c)
        self.gap = np.zeros(self.n_c)

    def refresh(self) -> bool:
        return False  # (the rows are the coordinate directions: no obstacle motion changes them)


class FrictionalCondensation(CondensedInterface):
    """The offline condensation onto all Γ_C displacement components, and the frictional contact solve on it."""

    exact_corrections = True  #: the corrections after the solve take Ω₂'s exact Jacobian

    def __init__(self, problem) -> None:
        super().__init__(problem)
        self.friction = problem.omega2.sub.friction
        self._lu = None
        self._warm: np.ndarray | None = None  #: the last solve's U (the next one starts there)

    def _forces(self, U: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """λ(U) (dN) and its block-diagonal Jacobian (N, d, d) at the nodal displacements U, in the law's state."""
        friction, d = self.friction, self.friction.d
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

    def _state(self, U: np.ndarray, plain: bool = False):
        friction = self.friction
        friction.nodal = U.reshape(-1, friction.d)
        try:
            return friction.next_state(plain=plain), friction.evaluate()["active"]
        finally:
            friction.nodal = None

    def _residual(self, U: np.ndarray, U_L: np.ndarray) -> np.ndarray:
        return U - U_L + self.M @ self._forces(U)[0]

    def _newton(self, U: np.ndarray, U_L: np.ndarray, hist, max_steps: int, *, energy: bool) -> np.ndarray:
        """The semismooth Newton on U = U_L − M λ(U) from U (``fem.friction``'s state rule; with ``energy`` the
        plain states and the exact line search on ψ = ½(U − U_L)ᵀM⁻¹(U − U_L) + Φ(U), whose gradient
        M⁻¹(U − U_L) + λ(U) it is for frozen thresholds).  Returns the converged U; ConvergenceError otherwise."""
        friction = self.friction
        friction.forced = None
        state, active = self._state(U, energy)
        seen, searching = set(), False
        for _ in range(max_steps):
            friction.forced = state
            key = np.concatenate([active, friction.key(state)])
            seen.add(key.tobytes())
            lam, blocks, _ = self._forces(U)
            R = U - U_L + self.M @ lam
            dU = sla.solve(np.eye(U.size) + self.M @ sla.block_diag(*blocks), -R)
            friction.forced = None
            t = self._search(U, dU, U_L, energy) if searching else 1.0
            U = U + t * dU
            friction.forced = state
            new_state, new_active = self._state(U, energy)
            new_key = np.concatenate([new_active, friction.key(new_state)])
            hist.step_lengths.append(t)
            hist.active_sizes.append(int(np.count_nonzero(new_key)))
            for record in (hist.added, hist.removed, hist.resolved):
                record.append(np.zeros(0, dtype=np.int64))
            hist.local.append((0, 0, 0))
            if t == 1.0 and np.array_equal(new_key, key):
                friction.forced = None
                return U
            searching = searching or new_key.tobytes() in seen
            state, active = new_state, new_active
        raise ConvergenceError(f"the condensed frictional contact Newton did not converge in {max_steps} steps")

    def _search(self, U: np.ndarray, dU: np.ndarray, U_L: np.ndarray, energy: bool) -> float:
        """The step length: the exact line search on ψ (``energy``), else backtracking on ‖R‖ (Armijo)."""
        if not energy:
            norm0, t = np.linalg.norm(self._residual(U, U_L)), 1.0
            while t > 1e-9 and np.linalg.norm(self._residual(U + t * dU, U_L)) > (1.0 - 1e-4 * t) * norm0:
                t *= 0.5
            return t
        lu = self._lu if self._lu is not None else sla.lu_factor(self.M)
        self._lu = lu
        base, step = sla.lu_solve(lu, U - U_L), sla.lu_solve(lu, dU)

        def slope(t: float) -> float:
            return float(dU @ (base + t * step + self._forces(U + t * dU)[0]))

        t0, t1, f0, f1 = 0.0, 1.0, slope(0.0), slope(1.0)
        if f0 >= 0.0 or f1 <= 0.0:
            return 1.0
        t = 1.0
        for _ in range(60):
            t = t1 - f1 * (t1 - t0) / (f1 - f0)
            f = slope(t)
            if abs(f) <= 1e-12 * abs(f0) or t1 - t0 <= 1e-12:
                break
            if f > 0.0:
                t1, f1, f0 = t, f, 0.5 * f0
            else:
                t0, f0, f1 = t, f, 0.5 * f1
        return t

    def contact_solve(self, U_L: np.ndarray, name: str, max_steps: int) -> tuple[np.ndarray, ContactNewtonHistory]:
        """U = U_L − M λ(U): the Newton on the law (Tresca: with the exact line search on its convex energy), and
        for Coulomb, should it not converge, the fixed point on the thresholds (each a convex problem) and the
        Newton on the law from there: (λ, history)."""
        friction, hist = self.friction, ContactNewtonHistory()
        tresca = friction.law.law == "tresca"
        start = U_L.copy() if self._warm is None else self._warm.copy()  # (the last solve's: the previous step)
        try:
            U = self._newton(start, U_L, hist, max_steps, energy=tresca)
        except ConvergenceError:
            if tresca:
                raise
            U = start
            for _ in range(FIXED_POINT_STEPS):
                friction.nodal = U.reshape(-1, friction.d)
                tau = friction.evaluate()["tau"]
                friction.nodal, friction.frozen = None, tau
                try:
                    U = self._newton(U, U_L, hist, max_steps, energy=True)
                finally:
                    friction.frozen = None
                friction.nodal = U.reshape(-1, friction.d)
                change = np.max(np.abs(friction.evaluate()["tau"] - tau), initial=0.0)
                friction.nodal = None
                if change <= FIXED_POINT_TOL * np.max(tau, initial=0.0):
                    break
            try:  # the law's own Newton settles the state exactly
                U = self._newton(U, U_L, hist, max_steps, energy=False)
            except ConvergenceError:
                pass
        self._warm = U
        forces = self._forces(U)[0]
        hist.residuals.append(float(np.linalg.norm(U - U_L + self.M @ forces)))
        return forces, hist

    def solve(self, options, name: str):
        """The frictional contact solve on the condensed unknowns, then (g₁₂, g₂₁, λ) global."""
        p = self.problem
        U_L, g21_0, y20 = self.load_terms()
        lam, hist = self.contact_solve(U_L, name, options.max_steps)
        g21 = g21_0 - self.Gq @ lam
        y2 = y20 + self.Yc @ g21 - self.Yq @ lam
        g12 = np.where(p.free, p.a * y2 + p.b * g21, 0.0)
        return g12, g21, lam, hist
