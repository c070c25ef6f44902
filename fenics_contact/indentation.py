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
(Algorithm 1), ``"mixed"`` (Algorithm 2), ``"primal-ms"`` (Algorithm 3) and
``"mixed-ms"`` (Algorithm 4).  The obstacle acts on Γ_C ⊂ Ω₂ only, so the
multiscale Ω₁ (local spectral problems, bases, Robin and source correctors, the
factorized coarse operator and, with ``accel="newton"``, its interface response)
is built once, before the first step, and every step reuses it: a step costs
what the online phase of one solve costs (``IndentationCurve.time_offline_s``
holds the one-off part, ``IndentationCurve.step`` the step, which a later curve
can take again through ``step=``).

Every step carries its evidence: the transmission residual of its final pair of
subdomain solutions (``IndentationStep.transmission_residual``, hybrid methods)
and the complementarity of its contact profile (``complementarity``: penetration,
tensile contact stress and max |σ_c u_c|, each relative to the step's scale).
"""

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import numpy.typing as npt

from fenics_contact.errors import InputError
from fenics_contact.fem.contact import ContactProfile, NewtonOptions
from fenics_contact.hybrid.iteration import IterationOptions, iterate
from fenics_contact.problem.geometry import ContactMesh
from fenics_contact.problem.models import TestModel
from fenics_contact.problem.obstacles import Obstacle

if TYPE_CHECKING:  # the multiscale modules are imported when a multiscale method runs
    from fenics_contact.hybrid.iteration import HybridStep
    from fenics_contact.multiscale.cem import CEMOptions
    from fenics_contact.multiscale.mixed_cem import MixedCEMOptions

__all__ = [
    "METHODS", "MULTISCALE_METHODS", "Complementarity", "complementarity", "IndentationStep", "IndentationCurve",
    "WarmStart", "force_indentation",
]

log = logging.getLogger(__name__)

METHODS = ("primal-monolithic", "mixed-monolithic", "primal", "mixed", "primal-ms", "mixed-ms")
#: the methods whose Ω₁ is a multiscale space built offline (once per curve)
MULTISCALE_METHODS = ("primal-ms", "mixed-ms")


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
        return Complementarity(float(np.max(np.maximum(u_c, 0.0), initial=0.0)),
                               float(np.max(np.maximum(s_c, 0.0), initial=0.0)), 0.0)
    return Complementarity(float(np.max(np.maximum(u_c, 0.0), initial=0.0)) / d,
                           float(np.max(np.maximum(s_c, 0.0), initial=0.0)) / p,
                           float(np.max(np.abs(s_c * u_c), initial=0.0)) / (p * d))


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
        rows = ["| depth | force | normal force | max pressure | iterations | transmission residual "
                "| complementarity | time [s] |", "|---|---|---|---|---|---|---|---|"]
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
    cem: "CEMOptions | MixedCEMOptions | None" = None,
    cache_dir: str | Path | None = None,
    step: "HybridStep | None" = None,
) -> IndentationCurve:
    """Move ``model.obstacle`` by each depth along ``direction`` in turn; solve with warm starts.

    ``delta`` (primal) defaults to ``default_penalty(h, E_c)``, ``epsilon`` (mixed) to
    ``default_epsilon(h, E_c)``, E_c the largest (primal) or smallest (mixed) E on Γ_C.  The multiscale methods take ``cem``
    (``multiscale.cem.CEMOptions`` for ``primal-ms``, ``multiscale.mixed_cem.MixedCEMOptions`` for
    ``mixed-ms``; default: their defaults) and ``cache_dir`` (the offline cache); their Ω₁ offline
    phase runs once, before the first step.  ``step``: a hybrid step of this method built earlier
    (e.g. ``curve.step`` of another curve, or a solve's ``result.step``) to reuse with everything it holds;
    ``alpha``, ``beta``, ``delta``, ``epsilon`` and ``cem`` are then the step's.
    """
    from fenics_contact.fem.mixed import contact_modulus, default_epsilon
    from fenics_contact.fem.mixed_subproblem import MixedSubproblem
    from fenics_contact.fem.primal import PrimalSubproblem, default_penalty, warn_if_locking
    from fenics_contact.hybrid.mixed import MixedHybridStep
    from fenics_contact.hybrid.primal import DEFAULT_ALPHA, DEFAULT_ALPHA_MS, PrimalHybridStep
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
    if cem is not None and method not in MULTISCALE_METHODS:
        raise InputError(f"cem options are for the multiscale methods {MULTISCALE_METHODS}, not {method!r}")
    if step is not None:
        step = step.step if isinstance(step, WarmStart) else step
        _check_step(method, step)
    base = model.obstacle
    first = model.with_(obstacle=base.indented(depths[0], direction))
    start = time.perf_counter()
    if step is None:
        fields = material_fields(cm.mesh, first)
        check_boundary_groups(cm.mesh, cm.facet_tags, fields.boundary, names=cm.neumann_names)
        if method.startswith("primal"):
            E_c = contact_modulus(cm.mesh, cm.facet_tags, fields.E)
            delta = default_penalty(cm.h, E_c) if delta is None else delta
        else:
            E_c = contact_modulus(cm.mesh, cm.facet_tags, fields.E, smallest=True)
            epsilon = default_epsilon(cm.h, E_c) if epsilon is None else epsilon

    if method == "primal-monolithic":
        warn_if_locking(fields.nu, cm.comm)
        sub = PrimalSubproblem(cm.mesh, cm.facet_tags, fields, delta=delta, alpha=None,
                               prefix="fc_indent_primal_", newton=newton)
        contact, hybrid = sub, None
    elif method == "mixed-monolithic":
        sub = MixedSubproblem(cm.mesh, cm.facet_tags, fields, epsilon=epsilon, beta=None,
                              prefix="fc_indent_mixed_", newton=newton)
        contact, hybrid = sub, None
    elif method == "primal":
        if step is None:
            step = PrimalHybridStep(cm, first, alpha=DEFAULT_ALPHA if alpha is None else alpha, delta=delta,
                                    newton=newton)
        step.prepare()
        contact, hybrid = step.sub[1], WarmStart(step)
    elif method == "mixed":
        if step is None:
            step = MixedHybridStep(cm, first, beta=beta, epsilon=epsilon, newton=newton)
        step.prepare()
        contact, hybrid = step.sub[1], WarmStart(step)
    elif method == "primal-ms":
        from fenics_contact.multiscale.cem import CEMOptions
        from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep

        if step is None:
            cem = CEMOptions() if cem is None else cem
            if not isinstance(cem, CEMOptions):
                raise InputError(f"primal-ms takes multiscale.cem.CEMOptions, got {type(cem).__name__}")
            step = MultiscalePrimalHybridStep(cm, first, alpha=DEFAULT_ALPHA_MS if alpha is None else alpha,
                                              delta=delta, cem=cem, newton=newton, cache_dir=cache_dir)
        contact, hybrid = step.omega2, WarmStart(step)
    else:  # mixed-ms
        from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep
        from fenics_contact.multiscale.mixed_cem import MixedCEMOptions

        if step is None:
            cem = MixedCEMOptions() if cem is None else cem
            if not isinstance(cem, MixedCEMOptions):
                raise InputError(f"mixed-ms takes multiscale.mixed_cem.MixedCEMOptions, got {type(cem).__name__}")
            step = MixedMultiscaleHybridStep(cm, first, beta=beta, epsilon=epsilon, cem=cem, newton=newton,
                                             cache_dir=cache_dir)
        step.prepare()
        contact, hybrid = step.sub[1], WarmStart(step)

    curve = IndentationCurve(method, direction, time_offline_s=time.perf_counter() - start, step=step,
                             contact=contact)
    for depth in depths:
        start = time.perf_counter()
        contact.set_obstacle(base.indented(depth, direction))
        residual, offline, newton_steps = None, 0.0, 0
        if hybrid is None:
            history = contact.solve()
            iterations, converged = history.steps, True
        else:
            history = iterate(hybrid, options, name=f"{method} indentation")
            iterations, converged = history.iterations, history.converged
            residual, offline = history.transmission_residual, history.time_offline_s
            newton_steps = history.newton_steps
        profile = contact.contact_profile()
        force = float(profile.resultant @ direction)
        scale = abs(float(depth)) if depth != 0 else None
        curve.steps.append(IndentationStep(
            float(depth), force, profile.force, profile.max_pressure, profile, iterations, converged,
            time.perf_counter() - start - offline, residual, complementarity(profile, scale), offline, newton_steps,
        ))
        log.info("%s: depth %.4g force %.6g (normal %.6g), %d iterations, transmission residual %s, %.2f s", method,
                 depth, force, profile.force, iterations, residual, curve.steps[-1].time_s)
    return curve


def _check_step(method: str, step) -> None:
    """``step`` must be a hybrid step of ``method`` (monolithic methods take none)."""
    from fenics_contact.hybrid.mixed import MixedHybridStep
    from fenics_contact.hybrid.primal import PrimalHybridStep
    from fenics_contact.multiscale.mixed import MixedMultiscaleHybridStep
    from fenics_contact.multiscale.primal import MultiscalePrimalHybridStep

    kinds = {"primal": PrimalHybridStep, "mixed": MixedHybridStep, "primal-ms": MultiscalePrimalHybridStep,
             "mixed-ms": MixedMultiscaleHybridStep}
    step = step.step if isinstance(step, WarmStart) else step
    kind = kinds.get(method)
    exact = kind is not None and type(step) is kind  # (MixedMultiscaleHybridStep is a MixedHybridStep)
    if not exact:
        raise InputError(f"step= takes a {kind.__name__ if kind else 'hybrid step'} for method {method!r}, "
                         f"got {type(step).__name__}")
