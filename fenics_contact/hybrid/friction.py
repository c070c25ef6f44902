"""The condensed Γ_C system with friction: every displacement component of the Γ_C nodes, and the nodal law.

With friction the contact force at a Γ_C node is a vector, λ_p = w_p p_p ν_p − w_p t_p (the normal penalty and
the friction traction, ``fem.friction``), so the glued linear problem (Ω₁'s affine interface response, Ω₂ with
no contact node active, ``hybrid.condensation``) is condensed onto all d components of the Γ_C displacements:

    U = U_L − M λ(U),

M (dN × dN) the compliance of the glued problem at the N Γ_C nodes, U_L their displacement under the load with
no contact force.  ``ComponentPart`` is Ω₂ with one contact column per node and component; ``FrictionalCondensation``
solves the nodal law on U by the semismooth Newton loop of the monolithic frictional solve
(``fem.newton.semismooth_newton_loop`` on ``_CondensedSystem``: ``fem.friction``'s state rule, full steps until a
state recurs, then a line search; in 3D a state is settled once the step is negligible, the slip direction varying
within it), dense, with the fixed point on the Coulomb thresholds should it not converge, then returns the
interface data as ``CondensedInterface.solve`` does.  With Algorithm 1 the condensation is exact and the dense
Newton takes the monolithic Newton's steps; the corrections that follow use Ω₂'s exact Jacobian.  Under MPI the
unknowns are the ranks' Γ_C nodes in turn, the law's data are gathered to every rank (``_Gathered``), every rank
solves the same dense system, and the interface Newton continues from rank 0's result.
"""

import numpy as np
import scipy.linalg as sla
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.friction import FIXED_POINT_STEPS, FIXED_POINT_TOL, NodalFriction
from fenics_contact.fem.newton import Advance, Direction, StepState, semismooth_newton_loop
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
        self.c_offset = self.comm.exscan(self.c_nodes.size) or 0  # (global order: the ranks' nodes in turn)
        self.n_c = self.comm.allreduce(self.c_nodes.size, op=MPI.SUM)
        self.D = np.zeros(self.n_c)
        self.gap = np.zeros(self.n_c)
        self.by_components = False  # its contact rows are the components already (and never move)

    def refresh(self) -> bool:
        return False  # (the rows are the coordinate directions: no obstacle motion changes them)


class FrictionalCondensation(CondensedInterface):
    """The offline condensation onto all Γ_C displacement components, and the frictional contact solve on it."""

    exact_corrections = True  #: the corrections after the solve take Ω₂'s exact Jacobian

    def __init__(self, problem) -> None:
        super().__init__(problem)
        self.law = problem.omega2.sub.friction  #: Ω₂'s ``NodalFriction`` (its rank's nodes)
        self.friction = _Gathered(self.law)  #: the law at the Γ_C nodes of all ranks (gathered for each solve)
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

    def _residual(self, U: np.ndarray, U_L: np.ndarray) -> np.ndarray:
        return U - U_L + self.M @ self._forces(U)[0]

    def _newton(self, U: np.ndarray, U_L: np.ndarray, hist, max_steps: int, *, energy: bool) -> np.ndarray:
        """The semismooth Newton on U = U_L − M λ(U) from U: ``fem.newton.semismooth_newton_loop`` on
        ``_CondensedSystem`` (the loop and state rule of the monolithic frictional Newton).  Returns the converged
        U; ConvergenceError otherwise."""
        system = _CondensedSystem(self, U, U_L, energy=energy)
        try:
            trace = semismooth_newton_loop(
                system,
                system.key(self.friction.forced),
                name="condensed frictional contact Newton",
                max_steps=max_steps,
                line_search="on-cycle",
                sizes="contact and friction state sizes",
            )
        except ConvergenceError as error:
            hist.discarded += getattr(error, "steps", 0)  # (counted in the steps)
            raise
        finally:
            self.friction.forced = None
        hist.step_lengths += trace.step_lengths
        hist.active_sizes += trace.active_sizes
        for record in (hist.added, hist.removed, hist.resolved):
            record += [np.zeros(0, dtype=np.int64)] * trace.steps
        hist.local += [(0, 0, 0)] * trace.steps
        return system.U

    def contact_solve(self, U_L: np.ndarray, name: str, max_steps: int) -> tuple[np.ndarray, ContactNewtonHistory]:
        """U = U_L − M λ(U): the Newton on the law (Tresca: with the exact line search on its convex energy), and
        for Coulomb, should it not converge, the fixed point on the thresholds (each a convex problem) and the
        Newton on the law from there: (λ, history)."""
        self.friction = friction = _Gathered(self.law)  # (this step's geometry, anchors and motion)
        hist = ContactNewtonHistory()
        tresca = friction.law.law == "tresca"
        start = np.zeros_like(U_L) if self._warm is None else self._warm.copy()  # (the previous step's U)
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
        g21 = g21_0 - self.times("Gq", lam)
        y2 = y20 + self.Yc @ g21 - self.times("Yq", lam)
        g12 = np.where(p.free, p.a * y2 + p.b * g21, 0.0)
        return g12, g21, lam, hist


class _Gathered(NodalFriction):
    """A ``NodalFriction``'s law at the Γ_C nodes of all ranks (in rank order, the order of the condensed
    unknowns): its geometry, anchors, motion and stiffness gathered, evaluated at given nodal displacements only
    (``nodal``).  Every rank holds the same data, so the dense solve is the same on every rank."""

    def __init__(self, friction: NodalFriction) -> None:  # (no NodalFriction.__init__: no subproblem of its own)
        comm, d = friction.comm, friction.d

        def gather(a: np.ndarray, width: int = 0) -> np.ndarray:
            parts = comm.allgather(np.asarray(a))
            return np.concatenate(parts).reshape((-1, width) if width else -1)

        nu, w, gap = friction._geometry()
        self._nodal_geometry = (gather(nu, d), gather(w), gather(gap))
        self.sub, self.law, self.delta, self.k_t, self.d = None, friction.law, friction.delta, friction.k_t, d
        self.comm = MPI.COMM_SELF
        self.anchor, self.free = gather(friction.anchor, d), gather(friction.free, d)
        self.stiffness, self.motion = gather(friction.stiffness), friction.motion.copy()
        self.nodes = np.arange(self.anchor.shape[0])
        self.dissipation, self.forced, self.frozen, self.nodal = 0.0, None, None, None

    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._nodal_geometry


class _CondensedSystem:
    """U = U_L − M λ(U) as a ``fem.newton.ContactSystem`` (dense): its set is the contact set with the friction
    state (``NodalFriction.next_state``) the law is linearized on, as in ``fem.friction``'s Newton; in 3D a set
    is settled once the step is negligible too (the slip direction varies within it).  The line search: the exact
    one on ψ = ½(U − U_L)ᵀM⁻¹(U − U_L) + Φ(U) (``energy``: frozen thresholds, Tresca), whose gradient
    M⁻¹(U − U_L) + λ(U) the residual is, else backtracking on ‖R‖ (Armijo)."""

    def __init__(self, cond: FrictionalCondensation, U: np.ndarray, U_L: np.ndarray, *, energy: bool) -> None:
        self.cond, self.friction, self.energy = cond, cond.friction, energy
        self.U, self.U_L = U.copy(), U_L
        self.friction.forced = None
        self.friction.forced = self._next_state(self.U)

    def _next_state(self, U: np.ndarray):
        self.friction.nodal = U.reshape(-1, self.friction.d)
        try:
            return self.friction.next_state(plain=self.energy)
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
        lam, self._blocks, _ = self.cond._forces(self.U)
        self._R = self.U - self.U_L + self.cond.M @ lam
        return float(np.linalg.norm(self._R))

    def jacobian(self, active: np.ndarray) -> bool:
        self._J = np.eye(self.U.size) + self.cond.M @ sla.block_diag(*self._blocks)
        return True

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return bool(np.array_equal(a, b)) and (self.friction.d == 2 or self._negligible)

    def solve(self, active: np.ndarray) -> Direction:
        self.dU = sla.solve(self._J, -self._R)
        self._negligible = np.max(np.abs(self.dU), initial=0.0) <= 1e-12 * np.max(np.abs(self.U), initial=0.0)
        self.U += self.dU
        self._next = self._next_state(self.U)
        predicted = self.key(self._next)
        self.U -= self.dU
        return Direction(predicted)

    def line_search(self) -> float:
        keep, self.friction.forced = self.friction.forced, None  # the merit: the residual of the law itself
        try:
            return self._search()
        finally:
            self.friction.forced = keep

    def _search(self) -> float:
        cond, U, dU, U_L = self.cond, self.U, self.dU, self.U_L
        if not self.energy:
            norm0, t = np.linalg.norm(cond._residual(U, U_L)), 1.0
            while t > 1e-9 and np.linalg.norm(cond._residual(U + t * dU, U_L)) > (1.0 - 1e-4 * t) * norm0:
                t *= 0.5
            return t
        if cond._lu is None:
            cond._lu = sla.lu_factor(cond.M)
        base, step = sla.lu_solve(cond._lu, U - U_L), sla.lu_solve(cond._lu, dU)

        def slope(t: float) -> float:
            return float(dU @ (base + t * step + cond._forces(U + t * dU)[0]))

        t0, t1, f0, f1 = 0.0, 1.0, slope(0.0), slope(1.0)
        if f0 >= 0.0 or f1 <= 0.0:
            return 1.0
        t = 1.0
        for _ in range(60):  # the root of the increasing slope (regula falsi, Illinois)
            t = t1 - f1 * (t1 - t0) / (f1 - f0)
            f = slope(t)
            if abs(f) <= 1e-12 * abs(f0) or t1 - t0 <= 1e-12:
                break
            if f > 0.0:
                t1, f1, f0 = t, f, 0.5 * f0
            else:
                t0, f0, f1 = t, f, 0.5 * f1
        return t

    def advance(self, t: float, state: StepState) -> Advance:
        self.U += t * self.dU
        self.friction.forced = self._next if t == 1.0 else self._next_state(self.U)
        active = self.key(self.friction.forced)
        return Advance(active, int(np.count_nonzero(active)))

    def check(self) -> None:
        """None: a settled iterate is accepted (the transmission residual of the pair that follows certifies it;
        the Newton steps on g that follow take off the round-off a solve with a stiff penalty leaves)."""
        return None
