"""Prescribed rigid motion of the obstacle in load steps, and the force–indentation curve.

At every step the obstacle ``model.obstacle`` is moved by depth·direction
(``Obstacle.indented``); the solver keeps everything it built (meshes, spaces,
the factorization of the linear Ω₁ problem, the Ω₂ factorizations cached by
active set) and starts from the previous solution: the Newton iterations from
the previous displacement / stress, the hybrid iteration from the previous
interface data.  The force is the contact resultant along the indentation
direction, ∫_ΓC σ_c ν·direction ds (σ_c < 0 in compression: the obstacle pushes
the body along the direction), and the total normal force −∫_ΓC σ_c ds.

Methods: ``"primal-monolithic"``, ``"mixed-monolithic"``, ``"primal"``
(Algorithm 1), ``"mixed"`` (Algorithm 2).
"""

import logging
import time
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile, NewtonOptions
from fenics_contact.hybrid.iteration import IterationOptions, iterate
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.models import TestModel
from fenics_contact.problem.obstacles import Obstacle

__all__ = ["METHODS", "IndentationStep", "IndentationCurve", "WarmStart", "force_indentation"]

log = logging.getLogger(__name__)

METHODS = ("primal-monolithic", "mixed-monolithic", "primal", "mixed")


@dataclass(slots=True)
class IndentationStep:
    """One load step: depth, forces, contact profile, solver effort."""

    depth: float
    force: float  #: resultant along the indentation direction
    normal_force: float  #: −∫_ΓC σ_c ds
    max_pressure: float
    profile: ContactProfile
    iterations: int  #: Newton steps (monolithic) or hybrid iterations
    converged: bool
    time_s: float


@dataclass(slots=True)
class IndentationCurve:
    """The force–indentation curve of a method."""

    method: str
    direction: np.ndarray
    steps: list[IndentationStep] = field(default_factory=list)

    @property
    def depths(self) -> np.ndarray:
        return np.array([s.depth for s in self.steps])

    @property
    def forces(self) -> np.ndarray:
        return np.array([s.force for s in self.steps])

    def table(self) -> str:
        """A markdown table of the curve."""
        rows = ["| depth | force | normal force | max pressure | iterations | time [s] |", "|---|---|---|---|---|---|"]
        rows += [
            f"| {s.depth:.4g} | {s.force:.6g} | {s.normal_force:.6g} | {s.max_pressure:.6g} | {s.iterations} "
            f"| {s.time_s:.2f} |"
            for s in self.steps
        ]
        return "\n".join(rows)


class WarmStart:
    """A hybrid step whose ``initial_data`` is the last interface data it was applied to (warm start)."""

    def __init__(self, step) -> None:
        self.step = step
        self.comm = step.comm
        self._last: np.ndarray | None = None

    def initial_data(self) -> np.ndarray:
        return self.step.initial_data() if self._last is None else self._last.copy()

    def apply(self, g: np.ndarray, **kwargs) -> np.ndarray:
        self._last = np.array(g, copy=True)
        return self.step.apply(g, **kwargs)

    def __getattr__(self, name: str):
        # everything else of the step (certificate, data_weights, interface_problem for --accel newton)
        return getattr(self.step, name)

    def relative_change(self) -> float:
        return self.step.relative_change()

    def record(self) -> dict:
        return self.step.record()


def force_indentation(
    method: str,
    cm: ContactMesh,
    model: TestModel,
    depths: npt.ArrayLike,
    *,
    direction: npt.ArrayLike,
    delta: float | None = None,
    epsilon: float | None = None,
    alpha: float | str | None = None,
    beta: float | str = "sqrt-h",
    options: IterationOptions = IterationOptions(),
    newton: NewtonOptions = NewtonOptions(),
) -> IndentationCurve:
    """Move ``model.obstacle`` by each depth along ``direction`` in turn; solve with warm starts.

    ``delta`` (primal) defaults to ``default_penalty(h, E_c)``, ``epsilon`` (mixed) to
    ``default_epsilon(h, E_c)``, E_c the largest E on Γ_C.
    """
    from fenics_contact.fem.mixed import MixedSubproblem, contact_modulus, default_epsilon
    from fenics_contact.fem.primal import PrimalSubproblem, default_penalty
    from fenics_contact.hybrid.mixed import MixedHybridStep
    from fenics_contact.hybrid.primal import DEFAULT_ALPHA, PrimalHybridStep
    from fenics_contact.problem.boundary import check_boundary_groups
    from fenics_contact.problem.fields import material_fields

    if method not in METHODS:
        raise InputError(f"unknown method {method!r} for force_indentation; choose one of {METHODS}")
    if not isinstance(model.obstacle, Obstacle):
        raise InputError("force_indentation needs a model with an obstacle (model.with_(obstacle=...))")
    depths = np.asarray(depths, dtype=np.float64).ravel()
    if depths.size == 0 or not np.all(np.isfinite(depths)):
        raise InputError(f"indentation depths must be finite numbers, got {depths}")
    direction = np.asarray(direction, dtype=np.float64).ravel()
    if direction.size != 2 or not np.linalg.norm(direction) > 0:
        raise InputError(f"the indentation direction must be a non-zero 2-vector, got {direction}")
    direction = direction / np.linalg.norm(direction)
    base = model.obstacle
    first = model.with_(obstacle=base.indented(depths[0], direction))
    fields = material_fields(cm.mesh, first)
    check_boundary_groups(cm.mesh, cm.facet_tags, fields.boundary, names=cm.neumann_names)
    E_c = contact_modulus(cm.mesh, cm.facet_tags, fields.E)
    if method.startswith("primal"):
        delta = default_penalty(cm.h, E_c) if delta is None else delta
    else:
        epsilon = default_epsilon(cm.h, E_c) if epsilon is None else epsilon

    if method == "primal-monolithic":
        sub = PrimalSubproblem(cm.mesh, cm.facet_tags, fields, delta=delta, alpha=None,
                               prefix="fc_indent_primal_", newton=newton)
        contact, hybrid = sub, None
    elif method == "mixed-monolithic":
        sub = MixedSubproblem(cm.mesh, cm.facet_tags, fields, epsilon=epsilon, beta=None,
                              prefix="fc_indent_mixed_", newton=newton)
        contact, hybrid = sub, None
    elif method == "primal":
        step = PrimalHybridStep(cm, first, alpha=DEFAULT_ALPHA if alpha is None else alpha, delta=delta,
                                newton=newton)
        step.prepare()
        contact, hybrid = step.sub[1], WarmStart(step)
    else:
        step = MixedHybridStep(cm, first, beta=beta, epsilon=epsilon, newton=newton)
        step.prepare()
        contact, hybrid = step.sub[1], WarmStart(step)

    curve = IndentationCurve(method, direction)
    for depth in depths:
        start = time.perf_counter()
        contact.set_obstacle(base.indented(depth, direction))
        if hybrid is None:
            history = contact.solve()
            iterations, converged = history.steps, True
        else:
            history = iterate(hybrid, options, name=f"{method} indentation")
            iterations, converged = history.iterations, history.converged
        profile = contact.contact_profile()
        force = float(profile.resultant @ direction)
        curve.steps.append(IndentationStep(
            float(depth), force, profile.force, profile.max_pressure, profile, iterations, converged,
            time.perf_counter() - start,
        ))
        log.info("%s: depth %.4g force %.6g (normal %.6g), %d iterations, %.2f s", method, depth, force,
                 profile.force, iterations, curve.steps[-1].time_s)
    return curve
