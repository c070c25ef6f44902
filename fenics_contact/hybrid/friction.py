"""The condensed Γ_C system with friction: every displacement component of the Γ_C nodes, and the nodal law.

With friction the contact force at a Γ_C node is a vector, λ_p = w_p p_p ν_p − w_p t_p (the normal penalty and
the friction traction, ``fem.friction``), so the glued linear problem (Ω₁'s affine interface response, Ω₂ with
no contact node active, ``hybrid.condensation``) is condensed onto all d components of the Γ_C displacements:

    U = U_L − M λ(U),

M (dN × dN) the compliance of the glued problem at the N Γ_C nodes, U_L their displacement under the load with
no contact force.  ``ComponentPart`` is Ω₂ with one contact column per node and component; ``FrictionalCondensation``
solves the nodal law on U by the semismooth Newton loop of the monolithic frictional solve
(``fem.condensed_friction.solve_condensed``: ``fem.friction``'s state rule from the committed state, full steps
until a state recurs, then a line search; in 3D a state is settled once the step is negligible, the slip direction
varying within it),
dense, with the fixed point on the Coulomb thresholds should it not converge, then returns the
interface data as ``CondensedInterface.solve`` does.  With Algorithm 1 the condensation is exact and the dense
Newton solves the monolithic frictional equations (the monolithic Newton runs its fixed point on the thresholds
to the end, the dense one hands over to the Newton on the law once the sets repeat); the corrections that follow
use Ω₂'s exact Jacobian.  Under MPI the
unknowns are the ranks' Γ_C nodes in turn, the law's data are gathered to every rank (``_Gathered``), every rank
solves the same dense system, and the interface Newton continues from rank 0's result.
"""

import numpy as np
from mpi4py import MPI

from fenics_contact.fem.condensed_friction import CondensedLaw, solve_condensed
from fenics_contact.fem.friction import NodalFriction
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

    def contact_solve(self, U_L: np.ndarray, name: str, max_steps: int) -> tuple[np.ndarray, ContactNewtonHistory]:
        """U = U_L − M λ(U) (``fem.condensed_friction.solve_condensed``: the Newton on the law, for Coulomb the
        fixed point on the thresholds should it not converge), from the previous load step's U: (λ, history)."""
        self.friction = friction = _Gathered(self.law)  # (this step's geometry, anchors and motion)
        hist = ContactNewtonHistory()
        start = np.zeros_like(U_L) if self._warm is None else self._warm.copy()  # (the previous step's U)
        law = CondensedLaw(friction, self.M, self._lu)

        def record(trace) -> None:
            hist.step_lengths += trace.step_lengths
            hist.active_sizes += trace.active_sizes
            for kept in (hist.added, hist.removed, hist.resolved):
                kept += [np.zeros(0, dtype=np.int64)] * trace.steps
            hist.local += [(0, 0, 0)] * trace.steps

        def discard(steps: int) -> None:
            hist.discarded += steps  # (counted in the steps)

        try:
            press = friction.committed is None  # (the first press of the path)
            U = solve_condensed(law, U_L, start, max_steps, record=record, discard=discard, press=press)
        finally:
            self._lu = law.lu
        self._warm = U
        forces = law.forces(U)[0]
        hist.residuals.append(float(np.linalg.norm(U - U_L + self.M @ forces)))
        return forces, hist

    def solve(self, options, name: str, *, warm: bool = False):
        """The frictional contact solve on the condensed unknowns, then (g₁₂, g₂₁, λ) global (``warm`` is
        ``CondensedInterface.solve``'s: this solve starts from the previous step's U in any case)."""
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
        self.dissipation, self.forced, self.frozen, self.nodal, self.linearized = 0.0, None, None, None, None
        committed = comm.allreduce(friction.committed is not None, op=MPI.LAND)
        self.committed = (
            (gather(friction.committed[0]).astype(np.int8), gather(friction.committed[1], d)) if committed else None
        )

    def _geometry(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self._nodal_geometry
