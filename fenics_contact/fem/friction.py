"""The penalized friction law at the Γ_C vertices of a primal subproblem: residual, generalized Jacobian, state.

With vertex quadrature the friction term of the residual is nodal, F_p += −w_p t_p, w_p the vertex weight and
t_p the tangential traction of the return mapping (``problem.friction``):

    r_p = u_p − m − a_p,   t_trial = −(1/δ_t) P_p r_p,   τ_p = μ p_p (Coulomb) or s (Tresca),
    stick |t_trial| ≤ τ_p: t_p = t_trial,   slip: t_p = τ_p n̂_p,   n̂_p = t_trial/|t_trial|,

P_p = I − ν_p⊗ν_p, m the obstacle's rigid motion, a_p the node's anchor: the relative displacement at which
its tangential spring is unstretched (a_p = u_old − m_old + δ_t t_old after each converged load step, so
t_trial = t_old − (1/δ_t) P (u − u_old − Δm)).  A node with τ_p = 0 (out of contact) carries no traction.
Its generalized Jacobian block ∂(−w t_p)/∂u_p (d × d, d the dimension; the tangential plane is a line in 2D
and a plane in 3D):

    stick:  (w/δ_t) P,     slip:  (w/δ_t)(τ/|t_trial|)(P − n̂⊗n̂) − [Coulomb, p > 0] (w μ/δ) n̂⊗ν,

non-symmetric for a slipping Coulomb node (LU factorization).  In 2D P − n̂⊗n̂ = 0: on a fixed state (contact,
stick, slip and its sign) the equations are affine and the semismooth Newton terminates finitely; in 3D n̂
varies within a state, and the Newton continues until its residual check.  The dissipation of a load step is
Σ_p w_p t_p·(a_p − a_p^new) ≥ 0 (δ_t τ (|t_trial| − τ) per slipping node, 0 where it sticks).
"""

import logging
from typing import NamedTuple

import dolfinx.fem.petsc
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.contact import NewtonHistory, profile_order
from fenics_contact.fem.friction_strategy import LAW_STEPS, solve_frictional
from fenics_contact.fem.newton import (
    Advance,
    Check,
    Direction,
    StepState,
    exact_step,
    lowers_energy,
    semismooth_newton_loop,
)
from fenics_contact.problem.friction import Friction

__all__ = ["NodalFriction", "FrictionProfile", "frictional_newton", "NEGLIGIBLE", "TIE"]

#: a 3D step (max norm) at most this times u's ends the Newton on a settled set: the Newton converges quadratically
#: there, so the iterate after it is within a few times its square of the solution (at contrast 10⁶ on the 3D
#: channel cube the round-off level of u is 10⁻¹⁰ of it: a step never becomes smaller there)
NEGLIGIBLE = 1.0e-8

#: a trial traction within this many round-offs of its own computation, k_t·ε·(|u_p|_t + |m|_t + |a_p|_t) (the
#: tangential parts, |v|_t = |v − (v·ν)ν|), of the threshold is a tie, which slips (``NodalFriction.sticks``): a node
#: the last load step left slipping starts the next on the threshold (|t_trial| = τ exactly, its anchor moved by the
#: slip), and t_trial = −k_t (u − m − a)_t, a difference of displacements larger than it, holds that tie to about
#: 10⁻¹² of τ; without the margin the round-off of the units decides the node's first state and the steps of the
#: Newton (a pair at E = 1 and at E = 3: 3 and 4 steps)
TIE = 16.0

log = logging.getLogger(__name__)


class FrictionProfile(NamedTuple):
    """The tangential side of a frictional contact profile, at the Γ_C nodes of all ranks (``profile_order``).

    ``traction``: t (N, d) on the body; ``pressure``: the normal penalty pressure p; ``stick`` / ``slip``:
    the nodes' state (neither: out of contact, no traction); ``tangent``: in 2D the unit tangent (−ν_y, ν_x)
    the signed ``shear`` t·tangent refers to (zero rows in 3D).
    """

    points: np.ndarray
    weights: np.ndarray
    traction: np.ndarray
    pressure: np.ndarray
    stick: np.ndarray
    slip: np.ndarray
    tangent: np.ndarray

    @property
    def shear(self) -> np.ndarray:
        """t·tangent (2D: the signed tangential traction; 3D: zero, use ``traction``)."""
        return np.einsum("ij,ij->i", self.traction, self.tangent)

    @property
    def tangential_force(self) -> np.ndarray:
        """Σ w_p t_p: the tangential force (vector, per unit thickness in 2D) the obstacle exerts on the body."""
        return np.sum(self.weights[:, None] * self.traction, axis=0)

    @property
    def normal_force(self) -> float:
        """Σ w_p p_p: the normal penalty force."""
        return float(np.sum(self.weights * self.pressure))

    @property
    def along(self) -> np.ndarray:
        """Each node's coordinate along Γ_C (the coordinate of larger spread)."""
        if self.points.shape[0] == 0:
            return np.zeros(0)
        return self.points[:, int(np.argmax(np.ptp(self.points[:, :2], axis=0)))]

    def extent(self, which: str) -> tuple[float, float] | None:
        """[min, max] along Γ_C of the ``"stick"`` or ``"slip"`` nodes, or None when there are none."""
        mask = self.stick if which == "stick" else self.slip
        if not np.any(mask):
            return None
        return float(np.min(self.along[mask])), float(np.max(self.along[mask]))


def _tangent_2d(nu: np.ndarray) -> np.ndarray:
    """(−ν_y, ν_x) per row in 2D; zero rows in 3D (no preferred tangent)."""
    if nu.shape[1] != 2:
        return np.zeros_like(nu)
    return np.column_stack([-nu[:, 1], nu[:, 0]])


def _tangential(v: np.ndarray, nu: np.ndarray) -> np.ndarray:
    """|v − (v·ν)ν| per node (v: (N, d) or one d-vector)."""
    v = np.broadcast_to(v, nu.shape)
    return np.linalg.norm(v - np.einsum("ij,ij->i", v, nu)[:, None] * nu, axis=1)


class NodalFriction:
    """The friction law of a ``PrimalSubproblem`` at its owned Γ_C nodes off Γ_D, with its load-step state.

    ``delta``: the normal penalty δ (p = (u·ν − g)⁺/δ); the stick stiffness is ``law.stiffness_ratio``/δ.
    The state is the anchor a_p per node and the obstacle motion m; ``commit`` ends a load step.
    """

    #: a dense Newton with frozen thresholds ends once its sets settle, in 3D too (``fem.friction_strategy``: the
    #: thresholds' fixed point before the hand-over, whose iterates need only their sets)
    settle_on_sets = False

    def __init__(self, sub, law: Friction, delta: float) -> None:
        self.sub, self.law, self.delta = sub, law, float(delta)
        self.k_t = law.stiffness_ratio / self.delta
        self.d = sub.mesh.geometry.dim
        self.comm = sub.mesh.comm
        nodes = sub.geometry.owned_nodes()
        mask = dolfinx.fem.petsc.create_vector(sub.V)
        mask.set(1.0)
        dolfinx.fem.petsc.set_bc(mask, sub.bcs)
        free = mask.getArray(readonly=True).reshape(-1, self.d)[nodes].copy()
        mask.destroy()
        self.nodes, self.free = nodes, free != 0.0  #: (N,), (N, d): components not held by Γ_D / rollers
        self.anchor = np.zeros((nodes.size, self.d))
        self.motion = np.zeros(self.d)
        self.dissipation = 0.0  #: accumulated over the committed load steps (all ranks)
        diagonal = sub._K.getDiagonal()
        #: the elastic stiffness at each node (the mean diagonal entry of its block of K)
        self.stiffness = diagonal.getArray(readonly=True).reshape(-1, self.d)[nodes].mean(axis=1)
        diagonal.destroy()
        #: the Newton's linearization state: codes per node (0 no traction, 1 stick, 2 slip) and the slip
        #: directions, or None (the state of the current u)
        self.forced: tuple[np.ndarray, np.ndarray] | None = None
        #: thresholds τ held fixed (the fixed-point iteration of ``frictional_newton``), or None: the law's
        self.frozen: np.ndarray | None = None
        #: nodal displacements (N, d) to evaluate the law at instead of u's (the condensed system's unknowns)
        self.nodal: np.ndarray | None = None
        #: the law evaluated where the Newton last linearized (``linearize``), or None
        self.linearized: dict | None = None
        #: the state (codes, slip directions) at the last committed load step, or None (``commit``): the state the
        #: condensed Newton of the next load step linearizes at first (``predicted_state``)
        self.committed: tuple[np.ndarray, np.ndarray] | None = None

    # -- the law at the current iterate ------------------------------------------------------------------
    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        _, nu, w, gap = self.sub.geometry.nodes()
        return nu, w, gap

    def evaluate(self) -> dict:
        """The return mapping at the current u: ν, w, p, τ, t_trial, t, stick, slip (owned nodes)."""
        nu, w, gap = self._geometry()
        u = self.sub.u.x.array.reshape(-1, self.d)[self.nodes] if self.nodal is None else self.nodal
        gn = np.einsum("ij,ij->i", u, nu) - gap
        p = np.maximum(gn, 0.0) / self.delta
        r = u - self.motion[None, :] - self.anchor
        r_t = r - np.einsum("ij,ij->i", r, nu)[:, None] * nu
        t_trial = -self.k_t * r_t
        norm = np.linalg.norm(t_trial, axis=1)
        slack = TIE * np.finfo(float).eps * self.k_t * sum(_tangential(v, nu) for v in (u, self.motion, self.anchor))
        if self.frozen is not None:
            tau = self.frozen
        elif self.law.law == "coulomb":
            tau = self.law.mu * p
        else:
            tau = np.full(gn.size, self.law.threshold)
        raw = t_trial / np.where(norm > 0.0, norm, 1.0)[:, None]
        if self.forced is None:
            stick = (tau > 0.0) & self.sticks(norm, tau, slack)
            slip = (tau > 0.0) & ~stick
            direction = np.where(slip[:, None], raw, 0.0)
        else:
            codes, forced_direction = self.forced
            stick, slip = (tau > 0.0) & (codes == 1), (tau > 0.0) & (codes == 2)
            keep = (self.d == 2) | (norm == 0.0)  # 2D: the slip direction of the state (affine on it)
            direction = np.where(slip[:, None], np.where(keep[:, None], forced_direction, raw), 0.0)
        t = np.where(stick[:, None], t_trial, tau[:, None] * direction)
        return dict(nu=nu, w=w, p=p, tau=tau, active=gn > 0.0, t_trial=t_trial, norm=norm, t=t, stick=stick,
                    slip=slip, direction=direction, slack=slack)  # fmt: skip

    def next_state(self, *, plain: bool = False, reverse: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """The state the Newton linearizes at next: (codes, slip directions) from z = (1 − β) t + β t_trial.

        t is the traction of the state linearized at (``forced``; the law's own without one) and t_trial the trial
        traction at the current u: a node sticks where |z| < τ (a tie to the round-off of t_trial slips: ``sticks``) and
        slips along z/|z| otherwise.  The primal–dual active-set rule with the constant c = β/δ_t, β = min(1, δ_t
        K_pp/w_p) (K_pp the node's elastic stiffness): β = 1 would be the trial state alone, whose stick band |P r| ≤
        τδ_t is too narrow for a Newton iterate to land in.  A node that carried no traction in the state linearized at
        (out of contact there) takes β = 1, its trial state: with t = 0 a node entering contact would stick whatever its
        trial traction (on model 3 at contrast 10⁶ nodes re-entered contact sticking at 25–76 times their threshold, and
        the Newton cycled them in and out of contact).  A node that slipped in the state linearized at and whose z turns
        against that slip direction (z·n̂ < 0) sticks instead: its traction passes through the stick disc on the way,
        and the slip state, whose tangential stiffness is zero in 2D, would carry it across to the other side in one
        full step (the Coulomb Newton then cycles between slip directions).  A state that reproduces itself satisfies
        the law, with the reversal rule as without it (it only changes a node that slipped into one that sticks).
        ``plain``: the state of u itself (β = 1), the generalized Hessian of a frozen-threshold energy. ``reverse``:
        with the reversal rule; without it where the state linearized at holds no slip of the path (the law's at the
        displacement of the load alone, ``fem.condensed_friction``: its slip directions are those of a displacement no
        contact force acts on, and its tractions pass through no stick disc)."""
        if plain:
            keep, self.forced = self.forced, None
            try:
                e = self.evaluate()
            finally:
                self.forced = keep
            beta = np.ones((e["w"].size, 1))
        else:
            e = self.evaluate()
            beta = np.minimum(1.0, self.stiffness / e["w"] / self.k_t)
            beta = np.where(e["stick"] | e["slip"], beta, 1.0)[:, None]  # (no traction linearized: the trial state)
        z = (1.0 - beta) * self._linearized_traction(e) + beta * e["t_trial"]
        size = np.linalg.norm(z, axis=1)
        tau = e["tau"]
        codes = np.where(tau > 0.0, np.where(self.sticks(size, tau, e["slack"]), 1, 2), 0).astype(np.int8)
        direction = z / np.where(size > 0.0, size, 1.0)[:, None]
        if not plain and reverse and self.forced is not None and self.forced[0].shape == codes.shape:
            was, along = self.forced
            codes[(codes == 2) & (was == 2) & (np.einsum("ij,ij->i", direction, along) < 0.0)] = 1
        return codes, direction

    @staticmethod
    def sticks(size: np.ndarray, tau: np.ndarray, slack: np.ndarray) -> np.ndarray:
        """|z| < τ, a tie (|z| within ``slack``, the round-off of t_trial, of τ: ``TIE``) slipping: on the threshold
        both states give the traction τ z/|z|, and a node the last load step left slipping slips on; |z| within the
        round-off of zero sticks (no direction to slip along)."""
        return (size < tau - slack) | (size <= slack)

    @staticmethod
    def state_of(e: dict) -> tuple[np.ndarray, np.ndarray]:
        """The state (codes: 0 no traction, 1 stick, 2 slip; slip directions) of the evaluated law ``e``."""
        return np.where(e["stick"], 1, np.where(e["slip"], 2, 0)).astype(np.int8), e["direction"].copy()

    def predicted_state(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The state the condensed Newton of a load step linearizes at first (``fem.condensed_friction``): the last
        committed step's, or None (none committed yet).  Dragged on, most nodes keep their state; the trial state of
        the new motion would have them all slip along it, and the Newton from there wanders through the slip states
        of the heterogeneous Γ_C."""
        if self.committed is None or self.committed[0].shape != (self.nodes.size,):
            return None
        return self.committed[0].copy(), self.committed[1].copy()

    def linearize(self, e: dict) -> None:
        """Keep the law ``e`` evaluated at the point the Newton linearizes at (its Jacobian's): in 3D the next
        state rule takes a slipping node's traction from that linearization (``_linearized_traction``)."""
        self.linearized = {k: e[k] for k in ("t", "t_trial", "norm", "tau", "direction", "slip")}

    def _linearized_traction(self, e: dict) -> np.ndarray:
        """The traction of the state linearized at: the law's own (``e["t"]``), except, in 3D, at the nodes that
        slipped at the linearization point: there its first-order expansion t_k + (τ/|t_trial|)(P − n̂⊗n̂)Δt_trial
        (with the threshold τ of the current iterate), whose component along the old slip direction n̂ is τ: a
        node whose trial traction turns back is then told to stick, as the 2D state rule does with the sign kept.
        The traction τ·t_trial/|t_trial| of the current direction would always be τ in size, and the state rule
        would reduce to the trial state alone."""
        if self.d == 2 or self.forced is None or self.linearized is None:
            return e["t"]
        lin = self.linearized
        if lin["t"].shape != e["t"].shape:
            return e["t"]
        slip = e["slip"] & lin["slip"]
        if not np.any(slip):
            return e["t"]
        n_hat, nu = lin["direction"][slip], e["nu"][slip]
        change = e["t_trial"][slip] - lin["t_trial"][slip]
        change -= np.einsum("ij,ij->i", change, n_hat)[:, None] * n_hat  # (P − n̂⊗n̂): t_trial is tangential
        change -= np.einsum("ij,ij->i", change, nu)[:, None] * nu
        t = e["t"].copy()
        t[slip] = e["tau"][slip, None] * n_hat + (lin["tau"][slip] / lin["norm"][slip])[:, None] * change
        return t

    @staticmethod
    def key(state: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        """The state as a boolean array (the Newton's active set): stick, slip, and the 2D slip's sign."""
        codes, direction = state
        parts = [codes == 1, codes == 2]
        if direction.shape[1] == 2:
            parts.append((codes == 2) & (direction[:, 0] + 1e-3 * direction[:, 1] > 0.0))
        return np.concatenate(parts)

    def varies(self) -> bool:
        """Whether the Jacobian varies within a state: a slipping node in 3D (collective)."""
        local = self.d == 3 and bool(np.any(self.evaluate()["slip"]))
        return self.comm.allreduce(local, op=MPI.LOR)

    # -- assembly hooks ------------------------------------------------------------------------------------
    def _dofs(self) -> np.ndarray:
        return (self.d * self.nodes[:, None] + np.arange(self.d)).ravel()

    def add_residual(self, b: PETSc.Vec) -> None:
        """b ← b − Σ_p w_p t_p·v_p on the free components (b: the assembled residual, owned entries)."""
        e = self.evaluate()
        force = -(e["w"][:, None] * e["t"]) * self.free
        arr = b.getArray()
        arr[self._dofs()] += force.ravel()

    def add_sizes(self, sizes: PETSc.Vec) -> None:
        """sizes ← sizes + |w_p t_p| (the friction forces' share of the terms the residual balances)."""
        e = self.evaluate()
        arr = sizes.getArray()
        arr[self._dofs()] += (np.abs(e["w"][:, None] * e["t"]) * self.free).ravel()

    def add_jacobian(self, A: PETSc.Mat) -> None:
        """A ← A + the friction blocks (assembled A; it is assembled again)."""
        e = self.evaluate()
        self.linearize(e)
        blocks = self.blocks(e)
        rows = self._dofs().reshape(-1, self.d).astype(PETSc.IntType)
        for k in np.flatnonzero(e["stick"] | e["slip"]):
            A.setValuesLocal(rows[k], rows[k], blocks[k], addv=PETSc.InsertMode.ADD_VALUES)
        A.assemble()

    def blocks(self, e: dict) -> np.ndarray:
        """The generalized Jacobian blocks ∂(−w t_p)/∂u_p (N, d, d) of the evaluated law ``e`` (free components)."""
        nu, w, n_hat = e["nu"], e["w"], e["direction"]
        eye = np.eye(self.d)
        P = eye[None] - nu[:, :, None] * nu[:, None, :]
        blocks = np.zeros((self.nodes.size, self.d, self.d))
        stick, slip = e["stick"], e["slip"]
        blocks[stick] = (w[stick] * self.k_t)[:, None, None] * P[stick]
        if np.any(slip):
            ratio = e["tau"][slip] / e["norm"][slip]
            nn = n_hat[slip][:, :, None] * n_hat[slip][:, None, :]
            blocks[slip] = (w[slip] * self.k_t * ratio)[:, None, None] * (P[slip] - nn)
            if self.law.law == "coulomb" and self.frozen is None:
                on = e["active"][slip]
                coupling = n_hat[slip][:, :, None] * nu[slip][:, None, :]
                blocks[slip] -= (w[slip] * self.law.mu / self.delta * on)[:, None, None] * coupling
        return blocks * self.free[:, :, None] * self.free[:, None, :]

    # -- load steps ----------------------------------------------------------------------------------------
    def set_motion(self, motion) -> None:
        """The obstacle's rigid motion m (a d-vector) from the reference position of the anchors."""
        m = np.zeros(self.d)
        v = np.asarray(motion, dtype=np.float64).ravel()
        m[: min(v.size, self.d)] = v[: self.d]
        self.motion = m

    def commit(self) -> float:
        """End the load step at the current (converged) u: move the anchors by the slip, add its dissipation
        Σ w_p t_p·(a_p − a_p^new) to ``dissipation``; returns the step's (collective)."""
        e = self.evaluate()
        self.committed = self.state_of(e)
        change = (e["t"] - e["t_trial"]) / self.k_t  # a_new − a: zero where the node sticks
        local = float(np.sum(e["w"] * np.einsum("ij,ij->i", e["t"], -change)))
        self.anchor += change
        step = self.comm.allreduce(local, op=MPI.SUM)
        self.dissipation += step
        return step

    def profile(self) -> FrictionProfile:
        """The tangential traction, pressure and stick/slip state at the Γ_C nodes of all ranks (profile order)."""
        e = self.evaluate()
        points = self.sub.Q.tabulate_dof_coordinates()[self.nodes, : self.d]
        arrays = (points, e["w"], e["t"], e["p"], e["stick"], e["slip"], _tangent_2d(e["nu"]))
        gathered = [np.concatenate(self.comm.allgather(a)) for a in arrays]
        order = profile_order(gathered[0])
        return FrictionProfile(*(a[order] for a in gathered))


class _FrictionalSystem:
    """A frictional ``PrimalSubproblem`` as a ``ContactSystem``: its set is the contact set with the friction
    state (``NodalFriction.next_state``), on which the friction term is linearized (``NodalFriction.forced``).

    With ``energy`` (frozen thresholds, Tresca) F is the gradient of a convex energy ψ and every step is checked on
    it: the full step of the state rule is taken when it lowers ψ (``fem.newton.lowers_energy``), else the exact
    line search along it when it descends, else along the Newton direction of the plain state of u (a generalized
    Hessian of ψ: it descends); ψ falls at every step, so no state recurs.  Without it (Coulomb) full steps until a
    state recurs, then a backtracking line search on ‖F‖ (Armijo); in 3D full steps throughout."""

    def __init__(self, sub, *, energy: bool = False, state=None, loaded: bool = False) -> None:
        self.sub, self.friction, self.energy = sub, sub.friction, energy
        self._norm = np.inf
        self._negligible = False
        self._full = True  #: the last step was the full step of the state rule (its next state is ``_next``)
        #: the state rule's reversal applies (not to the first state of a start at the load's displacement: ``loaded``)
        self._reverse = not loaded
        #: the line search on a recurring set; in 3D (Coulomb) full steps throughout, as the condensed Newton from the
        #: committed state (``fem.condensed_friction``): a slipping node's direction varies within a set, so a set
        #: recurs without a cycle, and the backtracking on ‖F‖ there accepts steps down to 10⁻⁹ (the normal
        #: penalty's kink lies within them): 47 steps on a drag of the 3D channel cube at ν = 0.49 and contrast
        #: 10⁶, 8 with full steps
        self._searchable = energy or self.friction.d == 2
        self.friction.forced = None
        self.friction.forced = self.friction.next_state() if state is None else state

    def key(self, state) -> np.ndarray:
        """The set of all ranks (so that every rank sees the same sets recur)."""
        local = np.concatenate([self.sub._active_set(), self.friction.key(state)])
        return np.concatenate(self.sub.mesh.comm.allgather(local))

    def residual(self) -> float:
        self._norm = self.sub._residual()
        return self._norm

    def jacobian(self, active: np.ndarray) -> bool:
        return self.sub._factorize_for(active)

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The sets are equal and, where the Jacobian varies within a set (3D slip), the step is negligible or the
        thresholds are frozen inside the fixed point before its hand-over (``NodalFriction.settle_on_sets``)."""
        friction = self.friction
        rough = friction.frozen is not None and friction.settle_on_sets
        return self.sub._same_sets(a, b) and (friction.d == 2 or self._negligible or rough)

    def _move(self, t: float) -> None:
        self.sub.u.x.petsc_vec.axpy(t, self.sub.du)
        self.sub.u.x.scatter_forward()

    def _direction(self) -> None:
        self.sub._direction()

    def solve(self, active: np.ndarray) -> Direction:
        sub = self.sub
        self._direction()
        size = sub.u.x.petsc_vec.norm(PETSc.NormType.NORM_INFINITY)
        self._negligible = sub.du.norm(PETSc.NormType.NORM_INFINITY) <= NEGLIGIBLE * size
        self._move(1.0)
        self._next = self.friction.next_state(reverse=self._reverse)
        predicted = self.key(self._next)
        self._move(-1.0)
        return Direction(predicted, searchable=self._searchable)

    def _slope(self, t: float) -> float:
        """d·F(u + t d): the derivative of the energy along the direction (F its gradient with frozen τ)."""
        self._move(t)
        self.sub._residual()
        self._move(-t)
        return self.sub.b.dot(self.sub.du)

    def _energy_search(self) -> float:
        """The full step when it lowers the energy, else the exact line search (``fem.newton.exact_step``) along
        it or, when it does not descend, along the plain state's Newton direction."""
        start = self._slope(0.0)
        if start < 0.0:
            if lowers_energy(self._slope, start):
                return 1.0
            self._full = False
            return exact_step(self._slope)
        self._full = False
        self.friction.forced = self.friction.next_state(plain=True)
        self.sub._factorize()
        self.sub._factorized_set = None
        self.sub._residual()
        self._direction()
        self.friction.forced = None
        return exact_step(self._slope)

    def line_search(self) -> float:
        keep, self.friction.forced = self.friction.forced, None  # the merit: the residual of the law itself
        try:
            if self.energy:
                return self._energy_search()
            norm0 = self.sub._residual()
            t = 1.0
            for _ in range(30):
                self._move(t)
                trial = self.sub._residual()
                self._move(-t)
                if trial <= (1.0 - 1e-4 * t) * norm0:
                    break
                t *= 0.5
        finally:
            self.friction.forced = keep
        return t

    def advance(self, t: float, state: StepState) -> Advance:
        self._move(t)
        self.friction.forced = (
            self._next if t == 1.0 and self._full else self.friction.next_state(reverse=self._reverse)
        )
        self._full = self._reverse = True
        active = self.key(self.friction.forced)
        return Advance(active, self.sub.mesh.comm.allreduce(int(np.count_nonzero(active))))

    def check(self) -> Check:
        final, scale = self.sub.residual_check()
        return Check(final, scale, self.sub._residual())


#: steps of a convex energy's Newton (Tresca, frozen thresholds) at least: the energy falls at every step, so it
#: converges, but in 3D slowly (73 steps on the channel cube dragged with Tresca, ``docs/limits.md``)
ENERGY_STEPS = 200


def _newton(
    sub, *, refinements: int, energy: bool = False, state=None, max_steps: int | None = None, loaded: bool = False
):
    system = _FrictionalSystem(sub, energy=energy, state=state, loaded=loaded)
    steps = sub.newton.max_iterations if max_steps is None else max_steps
    return semismooth_newton_loop(
        system,
        system.key(sub.friction.forced),
        name=sub.prefix.rstrip("_"),
        max_steps=max(steps, ENERGY_STEPS) if energy else steps,
        line_search="always" if energy else "on-cycle",
        rtol=sub.newton.rtol,
        atol=sub.newton.atol,
        refinements=refinements,
        sizes="contact and friction state sizes",
    )


class _SubproblemSolve:
    """A frictional ``PrimalSubproblem`` as a ``fem.friction_strategy.FrictionalSolve``: the converged Newtons'
    traces in ``history``, and the steps of every Newton that did not converge (a step each); the fixed point's
    iterate is accepted when it passes the subproblem's residual check."""

    def __init__(self, sub, refinements: int) -> None:
        self.sub, self.refinements = sub, refinements
        self.friction, self.comm = sub.friction, sub.mesh.comm
        self.history = NewtonHistory()

    def newton(self, *, energy: bool, state, max_steps: int | None, loaded: bool = False) -> None:
        sub = self.sub
        steps = sub.newton.max_iterations if max_steps is None else min(sub.newton.max_iterations, max_steps)
        sub._factorized_set = None  # (a factorization of the same sets with other thresholds is not this one's)
        try:
            trace = _newton(
                sub, refinements=self.refinements, energy=energy, state=state, max_steps=steps, loaded=loaded
            )
        except ConvergenceError as error:
            log.info("%s: %s", sub.prefix.rstrip("_"), error)
            steps = getattr(error, "steps", 0)  # (its linear solves counted)
            self.history.active_sizes += [0] * steps
            self.history.factorizations += steps
            raise
        finally:
            sub.friction.forced = None
        self.history.residuals += trace.residuals
        self.history.active_sizes += trace.active_sizes
        self.history.factorizations += trace.factorizations

    def load_alone(self) -> None:
        """u ← the displacement of the load alone (no contact force): one step of the Newton with every Γ_C node
        out of contact (the gap raised above u·ν), a linear solve."""
        sub = self.sub
        gap = sub.geometry.gap
        keep = gap.x.array.copy()
        gap.x.array[:] = 1.0 + float(np.max(np.abs(sub.u.x.array), initial=0.0))
        try:
            sub._factorized_set = None
            self.history.residuals.append(sub._residual())
            sub._factorize()
            sub._step()
        finally:
            gap.x.array[:] = keep
        sub._factorized_set = None
        self.history.active_sizes.append(0)
        self.history.factorizations += 1

    def save(self) -> np.ndarray:
        return self.sub.u.x.array.copy()

    def restore(self, saved: np.ndarray) -> None:
        self.sub.u.x.array[:] = saved
        self.sub._factorized_set = None

    def thresholds(self) -> np.ndarray:
        return self.friction.evaluate()["tau"]

    def sets(self) -> tuple[np.ndarray, ...]:
        e = self.friction.evaluate()
        return self.sub._active_set(), self.friction.key(self.friction.state_of(e))

    def settle(self) -> None:
        sub = self.sub
        sub._factorize()  # the law's own Jacobian at the solution (the interface Newton's Ω₂ response reads it)
        sub._factorized_set = None
        final, scale = sub.residual_check()
        if not (np.isfinite(final) and final <= sub.newton.rtol * scale + sub.newton.atol):
            raise ConvergenceError(
                f"{sub.prefix.rstrip('_')}: the friction thresholds' fixed point ended with the residual {final:.3e} "
                f"above {sub.newton.rtol:g} x the size of its terms ({scale:.3e})"
            )
        self.history.residuals.append(final)


def frictional_newton(sub, *, refinements: int) -> NewtonHistory:
    """Solve a frictional ``PrimalSubproblem`` (``fem.friction_strategy.solve_frictional``): the semismooth Newton
    on the law itself (``fem.newton.semismooth_newton_loop``; full steps until a state recurs, then a backtracking
    line search on ‖F‖, in 3D full steps throughout; ``refinements`` steps after a settled state whose residual
    misses the check: iterative refinement, or the Newton steps of a 3D slip) from the trial state, and should it
    not converge (slip fronts cycling at high contrast), the fixed point on the thresholds (each step a convex
    problem) until they settle, then the Newton on the law from there.  The first press of a path in 3D (Coulomb,
    nothing committed) is the displacement of the load alone (``_SubproblemSolve.load_alone``: one linear solve) and
    the Newton on the law from it (``LAW_STEPS``; the state rule's reversal from its first iterate on, as in
    ``fem.condensed_friction``): 9 and 8 steps on the 3D channel cube at contrast 10³ and 10⁶, 13 and 13 by the
    fixed point; should it not converge, the fixed point from the starting u."""
    solve = _SubproblemSolve(sub, refinements)
    press = sub.friction.committed is None
    if press and sub.friction.d == 3 and sub.friction.law.law == "coulomb":
        start = solve.save()
        solve.load_alone()
        try:  # (from the load's displacement, as the condensed press: ``fem.condensed_friction``)
            solve.newton(energy=False, state=None, max_steps=LAW_STEPS, loaded=True)
            return solve.history
        except ConvergenceError:
            solve.restore(start)  # (its steps counted by ``newton``)
    solve_frictional(solve, predict=False, trial_steps=None, handover=False, press=press)
    return solve.history
