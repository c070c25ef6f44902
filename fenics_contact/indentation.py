"""Prescribed rigid motion of the obstacle in load steps, and the force–indentation curve.

At every step the obstacle ``problem.obstacle`` is moved by depth·direction
(``Obstacle.indented``); the solver keeps everything it built (meshes, spaces,
the factorization of the linear Ω₁ problem, the Ω₂ factorizations cached by
active set) and starts from the previous solution: the Newton iterations from
the previous displacement / stress, the hybrid iteration from the previous
interface data.  The force is the contact resultant along the indentation
direction, ∫_ΓC σ_c ν·direction ds (σ_c < 0 in compression: the obstacle pushes
the body along the direction), and the total normal force −∫_ΓC σ_c ds.

Methods: every method of ``methods.METHODS`` (the monolithic solves and Algorithms
1–4), built once by its factory (``Method.build``).  The obstacle acts on Γ_C ⊂ Ω₂ only, so the
multiscale Ω₁ (local spectral problems, bases, Robin and source correctors, the
factorized coarse operator and, with ``accel="newton"``, its interface response)
is built once, before the first step, and every step reuses it: a step costs
what the online phase of one solve costs (``IndentationCurve.time_offline_s``
holds the one-off part, ``IndentationCurve.step`` the step, which a later curve
can take again through ``step=``).

Every step carries its evidence: the transmission residual of its final pair of
subdomain solutions (``IndentationStep.transmission_residual``, hybrid methods)
and the complementarity of its contact profile (``complementarity``: penetration,
tensile contact stress and max |σ_c u_c|, each relative to the step's scale); a
``primal-ms`` step also the distance of its multiscale Ω₁ from the fine Ω₁ solve for its
interface data (``IndentationStep.omega1_check``, as ``solve_primal_ms_hybrid``'s ``check``).
"""

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile
from fenics_contact.hybrid.iteration import HybridStep, iterate
from fenics_contact.methods import Method, get_method
from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep
from fenics_contact.problem.obstacles import Obstacle
from fenics_contact.problem.problem import ContactProblem

__all__ = [
    "Complementarity",
    "complementarity",
    "IndentationStep",
    "IndentationCurve",
    "WarmStart",
    "force_indentation",
]

log = logging.getLogger(__name__)


class Complementarity(NamedTuple):
    """How far a penalized contact profile is from u_c ≤ 0, σ_c ≤ 0, σ_c u_c = 0 (relative measures).

    ``penetration`` = max (u_c)⁺ / d, ``tension`` = max (σ_c)⁺ / p_max, ``product`` = max |σ_c u_c| / (p_max d),
    with d = max(indentation depth, max |u_c|) (the scale of the normal displacements relative to the
    obstacle) and p_max the peak pressure.  The penalty leaves O(δ) (primal: penetration) and O(ε)
    (mixed: tension); the product is the complementarity defect of both.
    """

    penetration: float
    tension: float
    product: float

    @property
    def value(self) -> float:
        """The largest of the three."""
        return max(self.penetration, self.tension, self.product)


def complementarity(profile: ContactProfile, scale: float | None = None) -> Complementarity:
    """The complementarity defects of ``profile`` (``Complementarity``); d = max(``scale``, max |u_c|)."""
    u_c, s_c = np.asarray(profile.u_c), np.asarray(profile.sigma_c)
    d = max(float(np.max(np.abs(u_c), initial=0.0)), 0.0 if scale is None else abs(float(scale)))
    p = profile.max_pressure
    if not (d > 0 and p > 0):  # no contact: only the sign conditions can be measured
        return Complementarity(
            float(np.max(np.maximum(u_c, 0.0), initial=0.0)), float(np.max(np.maximum(s_c, 0.0), initial=0.0)), 0.0
        )
    return Complementarity(
        float(np.max(np.maximum(u_c, 0.0), initial=0.0)) / d,
        float(np.max(np.maximum(s_c, 0.0), initial=0.0)) / p,
        float(np.max(np.abs(s_c * u_c), initial=0.0)) / (p * d),
    )


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
    time_s: float  #: the step alone (the curve's one-off offline work is in ``IndentationCurve.time_offline_s``)
    transmission_residual: float | None = None  #: certificate of the final pair (hybrid methods)
    complementarity: Complementarity | None = None  #: of the profile, relative to the depth and peak pressure
    time_offline_s: float = 0.0  #: offline work done inside this step (the interface Newton's Ω₁ response)
    interface_newton_steps: int = 0  #: steps of the interface Newton (``accel="newton"``), else 0
    #: primal-ms: the multiscale Ω₁ against the fine Ω₁ solve for the step's interface data (relative energy norm;
    #: ``Omega1Multiscale.fine_check``, outside ``time_s``), else None
    omega1_check: float | None = None


@dataclass(slots=True)
class IndentationCurve:
    """The force–indentation curve of a method."""

    method: str
    direction: np.ndarray
    steps: list[IndentationStep] = field(default_factory=list)
    time_offline_s: float = 0.0  #: building the solver before the first step (multiscale: Ω₁'s offline phase)
    step: object | None = None  #: the hybrid step (HybridStep; ``force_indentation(step=...)`` reuses it)
    contact: object | None = None  #: the subproblem holding Γ_C (monolithic: the whole problem; hybrid: Ω₂)

    @property
    def depths(self) -> np.ndarray:
        return np.array([s.depth for s in self.steps])

    @property
    def forces(self) -> np.ndarray:
        return np.array([s.force for s in self.steps])

    @property
    def transmission_residuals(self) -> np.ndarray:
        """Certificate of every step (NaN for the monolithic methods)."""
        return np.array([np.nan if s.transmission_residual is None else s.transmission_residual for s in self.steps])

    def table(self) -> str:
        """A markdown table of the curve."""
        rows = [
            "| depth | force | normal force | max pressure | iterations | transmission residual "
            "| complementarity | time [s] |",
            "|---|---|---|---|---|---|---|---|",
        ]
        rows += [
            f"| {s.depth:.4g} | {s.force:.6g} | {s.normal_force:.6g} | {s.max_pressure:.6g} | {s.iterations} "
            f"| {'—' if s.transmission_residual is None else f'{s.transmission_residual:.1e}'} "
            f"| {'—' if s.complementarity is None else f'{s.complementarity.value:.1e}'} | {s.time_s:.2f} |"
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
    problem: ContactProblem,
    method: str,
    depths: npt.ArrayLike,
    *,
    direction: npt.ArrayLike,
    step: HybridStep | None = None,
    on_step: Callable[[IndentationStep, object], None] | None = None,
    **options,
) -> IndentationCurve:
    """Move ``problem.obstacle`` by each depth along ``direction`` in turn; solve with warm starts.

    ``method``: a name of ``methods.METHODS``; ``options``: its options (``methods.Method.options``:
    δ or ε, α or β, ``cem``/``layers``/``nbasis``, ``cache_dir``, the iteration's ``tol``, ``accel``…),
    its defaults otherwise.  The multiscale methods' Ω₁ offline phase runs once, before the first step.
    ``step``: a hybrid step of this method built earlier (e.g. ``curve.step`` of another curve, or a
    solve's ``result.step``) to reuse with everything it holds; it carries its own α or β, δ or ε and
    multiscale space, so only the iteration's options may be given with it.  ``on_step(step, solver)`` is
    called after every load step with its record and the solver in that state (e.g. to write its fields).

    Args:
        problem: a ``ContactProblem`` with an obstacle, on its mesh.
        method: a name of ``methods.METHODS``.
        depths: the obstacle's displacement along ``direction`` at each load step (any length unit of the mesh).
        direction: the direction of the motion (a ``problem.dim``-vector, normalized here).
        step: a hybrid step of this method to reuse (see above), or None.
        on_step: called as ``on_step(record, solver)`` after every load step, or None.
        **options: the method's options (``methods.Method.options``).

    Returns:
        The ``IndentationCurve``: ``depths``, ``forces`` (the contact resultant per unit thickness), one
        ``IndentationStep`` record per load step (converged, iterations, certificate, time), the offline time
        and the step object that can be reused.

    Raises:
        InputError: no obstacle, depths not finite, a zero direction, options the method does not take.
        ConvergenceError: a Newton solve of a load step failed (a hybrid step that reaches its iteration cap is
            recorded with ``converged`` False).
    """
    spec = get_method(method)
    if not isinstance(problem, ContactProblem) or not isinstance(problem.obstacle, Obstacle):
        raise InputError("force_indentation needs a ContactProblem with an obstacle (problem.with_(obstacle=...))")
    depths = np.asarray(depths, dtype=np.float64).ravel()
    if depths.size == 0 or not np.all(np.isfinite(depths)):
        raise InputError(f"indentation depths must be finite numbers, got {depths}")
    direction = np.asarray(direction, dtype=np.float64).ravel()
    if direction.size != problem.dim or not np.linalg.norm(direction) > 0:
        raise InputError(f"the indentation direction must be a non-zero {problem.dim}-vector, got {direction}")
    direction = direction / np.linalg.norm(direction)
    iteration = spec.iteration(options, comm=problem.comm) if spec.hybrid else None
    if step is not None:
        step = step.step if isinstance(step, WarmStart) else step
        _check_step(spec, step)
        own = sorted(k for k in spec.options(options, comm=problem.comm) if k != "options")
        if own:
            raise InputError(f"step= carries its own options; give only the iteration's with it, not {own}")
    base = problem.obstacle
    first = problem.with_(obstacle=base.indented(depths[0], direction))
    start = time.perf_counter()
    solver = spec.build(first, comm=problem.comm, **options) if step is None else step
    solver_step = solver if spec.hybrid else None
    contact = solver.contact
    hybrid = WarmStart(solver) if spec.hybrid else None
    verify = isinstance(solver, MultiscalePrimalHybridStep) and options.get("check", True)
    curve = IndentationCurve(
        method, direction, time_offline_s=time.perf_counter() - start, step=solver_step, contact=contact
    )
    for depth in depths:
        start = time.perf_counter()
        contact.set_obstacle(base.indented(depth, direction))
        residual, offline, newton_steps = None, 0.0, 0
        if hybrid is None:
            history = solver.solve()
            iterations, converged = history.steps, True
        else:
            history = iterate(hybrid, iteration, name=f"{method} indentation")
            iterations, converged = history.iterations, history.converged
            residual, offline = history.transmission_residual, history.time_offline_s
            newton_steps = history.newton_steps
        profile = contact.contact_profile()
        force = float(profile.resultant @ direction)
        scale = abs(float(depth)) if depth != 0 else None
        curve.steps.append(
            IndentationStep(
                float(depth),
                force,
                profile.force,
                profile.max_pressure,
                profile,
                iterations,
                converged,
                time.perf_counter() - start - offline,
                residual,
                complementarity(profile, scale),
                offline,
                newton_steps,
            )
        )
        if verify and history.data is not None:  # (one factorization of the fine Ω₁ operator, outside time_s)
            curve.steps[-1].omega1_check = solver.omega1.fine_check(history.data[: solver.interface.size])
        log.info(
            "%s: depth %.4g force %.6g (normal %.6g), %d iterations, transmission residual %s, %.2f s",
            method,
            depth,
            force,
            profile.force,
            iterations,
            residual,
            curve.steps[-1].time_s,
        )
        if on_step is not None:
            on_step(curve.steps[-1], solver)
    return curve


def _check_step(method: Method, step) -> None:
    """``step`` must be a hybrid step of ``method`` (monolithic methods take none)."""
    kind = getattr(method.factory, "__wrapped__", None)
    if not method.hybrid or type(step) is not kind:
        name = kind.__name__ if method.hybrid else "hybrid step (none: the method is monolithic)"
        raise InputError(f"step= takes a {name} for method {method.name!r}, got {type(step).__name__}")
