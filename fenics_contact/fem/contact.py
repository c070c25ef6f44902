"""The primal semismooth Newton for penalized contact, and what the contact solves report: options, history,
contact profile.

The generalized derivative of s ↦ (s)⁺ is the Heaviside function, so for a
fixed active set 𝒜 (the Γ_C nodes with u_c > 0) the penalized problem is
linear; Newton stops after the first step whose new iterate has the same active
set as the one it was linearized at (finite termination), after checking the
residual.  The loop is ``fem.newton.semismooth_newton_loop``; ``semismooth_newton``
gives it the primal solve's callbacks (full steps, iterative refinement).
"""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from fenics_contact.errors import InputError
from fenics_contact.fem.newton import Advance, Check, Direction, StepState, semismooth_newton_loop

#: Newton steps with a settled active set (and so the same factorization) allowed to bring the
#: residual to the check: iterative refinement of a solve whose pivots lost digits (tiny δ).
MAX_REFINEMENTS = 2

__all__ = [
    "NewtonOptions",
    "NewtonHistory",
    "ContactProfile",
    "semismooth_newton",
    "active_interval",
    "profile_order",
]


@dataclass(frozen=True, slots=True)
class NewtonOptions:
    """Semismooth Newton options: step cap, and the residual check at termination.

    The check is normwise backward stability: ‖F(u)‖ ≤ rtol·(size of the terms F balances) + atol,
    the size being ‖J‖‖u‖ + ‖b‖ (stiffness, penalty and Robin terms, load and data) for the primal
    solve and the sum of the norms of the terms for the mixed one. A backward-stable direct solve
    meets it with rtol ~ 1e-16·growth whatever δ, ε or the contrast, so rtol = 1e-8 only rejects a
    solve whose linear algebra failed. ``atol`` is a residual (a force) in the units of the data: the floor of
    a problem whose terms all vanish (u = 0, nothing loaded), where ‖F‖ is round-off of nothing; with terms of
    any size above 1e-5 in those units the relative part decides.
    """

    max_iterations: int = 50
    rtol: float = 1e-8
    atol: float = 1e-13

    def __post_init__(self) -> None:
        if not isinstance(self.max_iterations, (int, np.integer)) or self.max_iterations < 1:
            raise InputError(f"max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if not (np.isfinite(self.rtol) and np.isfinite(self.atol) and 0 < self.rtol < 1 and self.atol >= 0):
            raise InputError(
                f"Newton tolerances must be finite, 0 < rtol < 1 and atol >= 0; got {self.rtol!r}, {self.atol!r}"
            )


@dataclass(slots=True)
class NewtonHistory:
    """Per-step residual norms (before each step) and active-set sizes (after each step)."""

    residuals: list[float] = field(default_factory=list)
    active_sizes: list[int] = field(default_factory=list)
    factorizations: int = 0

    @property
    def steps(self) -> int:
        """Number of Newton steps (linear solves)."""
        return len(self.active_sizes)


class ContactProfile(NamedTuple):
    """Nodal data along Γ_C, in ``profile_order`` (by y on a vertical Γ_C): position, normal displacement, normal
    stress.

    ``u_c`` = u·ν − g, the normal displacement relative to the obstacle (> 0: penetration);
    ``sigma_c`` the normal stress (< 0: contact pressure). The optional fields give the node coordinates, their
    quadrature weights on Γ_C, the contact direction ν
    and the initial gap g, from which ``force``, ``resultant`` and ``contact_zone`` follow.
    """

    y: np.ndarray
    u_c: np.ndarray
    sigma_c: np.ndarray
    points: np.ndarray | None = None  #: (N, d) node coordinates (d the dimension)
    weights: np.ndarray | None = None  #: (N,) quadrature weights: ∫_ΓC w ds ≈ Σ weights·w(nodes)
    normals: np.ndarray | None = None  #: (N, d) contact direction ν (towards the obstacle)
    gap: np.ndarray | None = None  #: (N,) initial gap g

    @property
    def force(self) -> float:
        """Total normal contact force −∫_ΓC σ_c ds (> 0 in compression; needs ``weights``)."""
        return float(-np.sum(self.weights * self.sigma_c))

    @property
    def resultant(self) -> np.ndarray:
        """∫_ΓC σ_c ν ds: the force the obstacle exerts on the body (needs ``weights``, ``normals``)."""
        return np.sum((self.weights * self.sigma_c)[:, None] * self.normals, axis=0)

    @property
    def max_pressure(self) -> float:
        """max −σ_c (0 without contact)."""
        return float(np.max(-self.sigma_c, initial=0.0))

    def contact_zone(self) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """End points (first and last node in the profile's order) of the contact zone, or None."""
        active = np.flatnonzero(self.active)
        if active.size == 0 or self.points is None:
            return None
        return tuple(map(float, self.points[active[0]])), tuple(map(float, self.points[active[-1]]))

    @property
    def active(self) -> np.ndarray:
        """Nodes in contact (u_c > 0: the penalty is active)."""
        return self.u_c > 0.0

    @property
    def penetration(self) -> float:
        """max (u_c)⁺: the penetration the penalty leaves."""
        return float(np.max(np.maximum(self.u_c, 0.0), initial=0.0))

    @property
    def along(self) -> np.ndarray:
        """Each node's coordinate along Γ_C: the one of larger spread (y on a vertical Γ_C, x on a horizontal
        one; ``y`` when the profile has no ``points``)."""
        if self.points is None or self.points.shape[0] == 0:
            return self.y
        return self.points[:, int(np.argmax(np.ptp(self.points[:, :2], axis=0)))]

    def active_interval(self) -> tuple[float, float] | None:
        """[min, max] of the contact nodes' coordinate along Γ_C (``along``: y on a vertical Γ_C, x on a
        horizontal one), or None when nothing touches; the span of all zones (``contact_zones``)."""
        return active_interval(self.along, self.active)

    def contact_zones(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """End points of each separate contact zone: maximal runs of consecutive contact nodes in profile order
        (``profile_order``: right for a Γ_C that is one curve monotone in its major coordinate, as every built-in
        one; on a Γ_C of several sides or pieces the runs interleave and the count is not meaningful)."""
        if self.points is None:
            return []
        active = self.active.astype(np.int8)
        edges = np.diff(np.concatenate([[0], active, [0]]))
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
        return [(tuple(map(float, self.points[a])), tuple(map(float, self.points[b]))) for a, b in zip(starts, stops)]


def profile_order(points: np.ndarray) -> np.ndarray:
    """Order of contact nodes along Γ_C: by the coordinate with the larger spread (y for a vertical Γ_C), then the
    other, then z (3D).  The coordinates are compared to 10⁻⁹ of the nodes' extent: nodes level in the unit-free
    mesh stay level when a file scales it (its coordinates then carry the round-off of the new units), so the
    order is the same in any unit."""
    if points.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    extent = max(float(np.max(np.ptp(points, axis=0))), np.finfo(float).tiny)
    q = np.round((points - points.min(axis=0)) / extent * 1e9)
    spread = np.ptp(q[:, :2], axis=0)
    major = 0 if spread[0] > spread[1] else 1
    keys = (q[:, 1 - major], q[:, major]) if q.shape[1] < 3 else (q[:, 2], q[:, 1 - major], q[:, major])
    return np.lexsort(keys)


def active_interval(y: np.ndarray, active: np.ndarray) -> tuple[float, float] | None:
    """[min y, max y] over the active nodes, or None."""
    if not np.any(active):
        return None
    return float(np.min(y[active])), float(np.max(y[active]))


class _PrimalSystem:
    """The primal solve's callbacks as a ``ContactSystem``: full steps only, the step taken by ``solve``."""

    def __init__(self, residual, active_set, same_sets, factorize, step, residual_check, comm) -> None:
        self._residual, self._active_set, self.same = residual, active_set, same_sets
        self._factorize, self._step, self._residual_check, self._comm = factorize, step, residual_check, comm
        self._landed: np.ndarray | None = None

    def residual(self) -> float:
        return self._residual()

    def jacobian(self, active: np.ndarray) -> bool:
        return self._factorize(active)

    def solve(self, active: np.ndarray) -> Direction:
        self._step()
        self._landed = self._active_set()
        return Direction(self._landed, searchable=False)

    def line_search(self) -> float:
        raise AssertionError("the primal semismooth Newton takes full steps")

    def advance(self, t: float, state: StepState) -> Advance:
        return Advance(self._landed, self._comm.allreduce(int(np.count_nonzero(self._landed))))

    def check(self) -> Check:
        final, scale = self._residual_check()
        return Check(final, scale, self._residual())


def semismooth_newton(
    *,
    residual: Callable[[], float],
    active_set: Callable[[], np.ndarray],
    same_sets: Callable[[np.ndarray, np.ndarray], bool],
    factorize: Callable[[np.ndarray], bool],
    step: Callable[[], None],
    residual_check: Callable[[], tuple[float, float]],
    options: NewtonOptions,
    name: str,
    comm,
) -> NewtonHistory:
    """The primal semismooth Newton over callbacks (``fem.newton.semismooth_newton_loop``, full steps).

    ``comm`` sums the active-set sizes over ranks. ``residual()`` assembles F(u) and returns ‖F‖; ``active_set()``
    returns the
    local active-set indicator of the current u; ``factorize(active)`` makes the
    factorization of J at the current u available, returning True if it had to
    refactorize (the caller caches it by active set: J depends on u only through
    the active set); ``step()`` solves J du = −F and updates u; ``residual_check()`` returns
    (‖F(u)‖, the size of the terms F balances) in one norm, e.g. (‖F‖∞, ‖J‖∞‖u‖∞ + ‖b‖∞).
    A settled step whose residual fails the check is followed by up to ``MAX_REFINEMENTS`` steps
    with the same factorization (iterative refinement). Raises ConvergenceError when the step cap is
    hit or the residual still fails the check.
    """
    system = _PrimalSystem(residual, active_set, same_sets, factorize, step, residual_check, comm)
    trace = semismooth_newton_loop(
        system,
        active_set(),
        name=name,
        max_steps=options.max_iterations,
        line_search="never",
        rtol=options.rtol,
        atol=options.atol,
        refinements=MAX_REFINEMENTS,
    )
    return NewtonHistory(trace.residuals, trace.active_sizes, trace.factorizations)
