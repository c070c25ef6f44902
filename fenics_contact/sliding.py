"""Quasi-static load paths with friction: the obstacle moved rigidly step by step, the friction state carried.

At every step the obstacle ``problem.obstacle`` is translated by that step's motion m_k (a rigid displacement
from its position in the problem: pressing it in, dragging it along), the contact subproblem (the whole body,
or Ω₂ of Algorithms 1–4) is solved from the previous step's solution, and the friction state is committed
(``fem.friction.NodalFriction.commit``; the mixed methods' ``fem.mixed_friction.MixedFriction.commit``): the
slip of the next step is measured from this one's converged state, so a path's answer depends on the path and the
slip dissipates energy.

Each step reports the normal force Σ w_p p_p, the tangential force Σ w_p t_p (a vector: the force the obstacle
exerts on the body along Γ_C), the stick and slip nodes (counts and extents along Γ_C), the step's dissipation
Σ w_p t_p·(a_p − a_p^new) ≥ 0, the solver's effort and, for the hybrid methods, the transmission residual of
the final pair.  Methods: all six (the mixed ones in 2D; ``mixed-monolithic`` with ``split_interface=True``: on
X̃_h, Algorithm 2's fixed point); by default Algorithm 1 runs the interface Newton on the condensed frictional
system (``hybrid.friction``, on one or several ranks), Algorithms 2–4 with the ``"interface"`` strategy
(``hybrid.options.interface_options``); or the iteration asked for.
"""

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile
from fenics_contact.fem.friction import FrictionProfile
from fenics_contact.hybrid.iteration import iterate
from fenics_contact.indentation import WarmStart
from fenics_contact.methods import get_method
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.problem import ContactProblem

__all__ = ["SlidingStep", "SlidingPath", "slide", "check_motions"]

log = logging.getLogger(__name__)


@dataclass(slots=True)
class SlidingStep:
    """One load step of a frictional path: the obstacle's motion, forces, stick/slip state, dissipation, effort."""

    motion: np.ndarray  #: the obstacle's rigid displacement from its position in the problem
    normal_force: float  #: Σ w_p p_p (−∫_ΓC σ_c ds)
    tangential_force: np.ndarray  #: Σ w_p t_p: the tangential force on the body (a vector)
    stick_nodes: int
    slip_nodes: int
    stick_extent: tuple[float, float] | None  #: [min, max] along Γ_C of the sticking nodes
    slip_extent: tuple[float, float] | None
    dissipation: float  #: of this step (≥ 0)
    profile: ContactProfile
    friction: FrictionProfile | None
    iterations: int  #: Newton steps (monolithic) or applications of T (hybrid)
    converged: bool
    time_s: float
    transmission_residual: float | None = None
    interface_newton_steps: int = 0  #: the interface Newton's steps (with the condensed strategy: contact Newton's too)
    contact_newton_steps: int = 0  #: of those, the steps of the contact Newton on the condensed Γ_C system


@dataclass(slots=True)
class SlidingPath:
    """The steps of a frictional load path and the solver that ran it."""

    method: str
    steps: list[SlidingStep] = field(default_factory=list)
    time_offline_s: float = 0.0
    solver: object | None = None  #: the hybrid step or ``methods.MonolithicSolver``
    contact: object | None = None  #: the subproblem holding Γ_C

    @property
    def normal_forces(self) -> np.ndarray:
        return np.array([s.normal_force for s in self.steps])

    @property
    def tangential_forces(self) -> np.ndarray:
        """(steps, d): the tangential force vectors."""
        return np.array([s.tangential_force for s in self.steps])

    @property
    def dissipation(self) -> float:
        """The energy the path dissipated (the sum of its steps')."""
        return float(sum(s.dissipation for s in self.steps))

    def table(self) -> str:
        """A markdown table of the path."""
        rows = [
            "| motion | normal force | tangential force | stick nodes | slip nodes | dissipation | iterations |",
            "|---|---|---|---|---|---|---|",
        ]
        rows += [
            f"| {np.array2string(s.motion, precision=4)} | {s.normal_force:.6g} "
            f"| {np.array2string(s.tangential_force, precision=6)} | {s.stick_nodes} | {s.slip_nodes} "
            f"| {s.dissipation:.3e} | {s.iterations} |"
            for s in self.steps
        ]
        return "\n".join(rows)


def check_motions(motions: npt.ArrayLike, dim: int) -> np.ndarray:
    """The obstacle motions as an array (steps, dim); InputError unless a non-empty list of finite d-vectors."""
    try:
        m = np.asarray(motions, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"obstacle motions must be a list of {dim}-vectors, got {motions!r}") from None
    if m.ndim != 2 or m.shape[0] == 0 or m.shape[1] != dim or not np.all(np.isfinite(m)):
        raise InputError(f"obstacle motions must be a non-empty list of finite {dim}-vectors, got {motions!r}")
    return m


def slide(
    problem: ContactProblem,
    method: str,
    motions: npt.ArrayLike,
    *,
    on_step: Callable[[SlidingStep, object], None] | None = None,
    **options,
) -> SlidingPath:
    """Move ``problem.obstacle`` by each motion in turn (rigid displacements from its position in the problem),
    solve each load step from the previous one and carry the friction state (``problem.law``).

    ``method``: any of ``methods.METHODS`` (``primal-monolithic``, ``primal``, ``primal-ms``, ``mixed-monolithic``,
    ``mixed``, ``mixed-ms``); ``options``: its options (``methods.Method.options``) and the build's own keywords
    (``offline_comm=MPI.COMM_WORLD`` shares ``mixed-ms``'s offline phase over the ranks, each holding the whole
    mesh; ``split_interface=True`` for ``mixed-monolithic`` on X̃_h, Algorithm 2's fixed point);
    ``on_step(step, solver)`` after every load step.  A frictionless problem runs the same path (no tangential force,
    no dissipation).

    Raises:
        InputError: no obstacle, motions that are not finite d-vectors, a mixed method in 3D.
        ConvergenceError: a Newton solve of a load step failed (a hybrid step that reaches its iteration cap is
            recorded with ``converged`` False).
    """
    spec = get_method(method)
    if not isinstance(problem, ContactProblem) or not isinstance(problem.obstacle, Obstacle):
        raise InputError("slide needs a ContactProblem with an obstacle (problem.with_(obstacle=...))")
    motions = check_motions(motions, problem.dim)
    base = problem.obstacle
    start = time.perf_counter()
    iteration = spec.iteration(options, comm=problem.comm) if spec.hybrid else None
    solver = spec.build(problem.with_(obstacle=base.translated(motions[0])), comm=problem.comm, **options)
    contact = solver.contact
    hybrid = WarmStart(solver) if spec.hybrid else None
    path = SlidingPath(method, time_offline_s=time.perf_counter() - start, solver=solver, contact=contact)
    friction = getattr(contact, "friction", None)
    for motion in motions:
        start = time.perf_counter()
        contact.set_obstacle(base.translated(motion))
        if friction is not None:
            friction.set_motion(motion)
        residual, newton_steps, contact_steps = None, 0, 0
        if hybrid is None:
            history = solver.solve()
            iterations, converged = history.steps, True
        else:
            history = iterate(hybrid, iteration, name=f"{method} sliding")
            iterations, converged = history.iterations, history.converged
            residual, newton_steps = history.transmission_residual, history.newton_steps
            contact_steps = history.contact_newton.steps if history.contact_newton is not None else 0
        profile = contact.contact_profile()
        tangential = friction.profile() if friction is not None else None
        dissipated = friction.commit() if friction is not None else 0.0
        record = SlidingStep(
            motion.copy(),
            profile.force,
            tangential.tangential_force if tangential is not None else np.zeros(problem.dim),
            int(np.count_nonzero(tangential.stick)) if tangential is not None else 0,
            int(np.count_nonzero(tangential.slip)) if tangential is not None else 0,
            tangential.extent("stick") if tangential is not None else None,
            tangential.extent("slip") if tangential is not None else None,
            dissipated,
            profile,
            tangential,
            iterations,
            converged,
            time.perf_counter() - start,
            residual,
            newton_steps,
            contact_steps,
        )
        path.steps.append(record)
        log.info(
            "%s: motion %s normal force %.6g tangential force %s, %d stick / %d slip nodes, dissipation %.3e, "
            "%d iterations",
            method,
            motion,
            record.normal_force,
            record.tangential_force,
            record.stick_nodes,
            record.slip_nodes,
            dissipated,
            iterations,
        )
        if on_step is not None:
            on_step(record, solver)
    return path
