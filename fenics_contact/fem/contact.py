"""Semismooth Newton for penalized contact, and what it reports: history and contact profile.

The generalized derivative of s ↦ (s)⁺ is the Heaviside function, so for a
fixed active set 𝒜 (the Γ_C nodes with u_c > 0) the penalized problem is
linear; Newton stops after the first step whose new iterate has the same active
set as the one it was linearized at (finite termination), after checking the
residual.
"""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from fenics_contact.errors import ConvergenceError, InputError

__all__ = [
    "NewtonOptions", "NewtonHistory", "ContactProfile", "semismooth_newton", "active_interval", "profile_order",
]


@dataclass(frozen=True, slots=True)
class NewtonOptions:
    """Semismooth Newton options: step cap, and the residual check ‖F‖ ≤ rtol‖b‖ + atol at termination."""

    max_iterations: int = 50
    rtol: float = 1e-8
    atol: float = 1e-13

    def __post_init__(self) -> None:
        if self.max_iterations < 1:
            raise InputError("max_iterations must be >= 1")
        if not (self.rtol > 0 and self.atol >= 0):
            raise InputError("Newton tolerances must be positive")


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
    """Nodal data along Γ_C, in ``profile_order`` (by y on a vertical Γ_C): position, normal displacement, normal stress.

    ``u_c`` = u·ν − g, the normal displacement relative to the obstacle (> 0: penetration);
    ``sigma_c`` the normal stress (< 0: contact pressure). The optional fields (issue 14)
    give the node coordinates, their quadrature weights on Γ_C, the contact direction ν
    and the initial gap g, from which ``force``, ``resultant`` and ``contact_zone`` follow.
    """

    y: np.ndarray
    u_c: np.ndarray
    sigma_c: np.ndarray
    points: np.ndarray | None = None  #: (N, 2) node coordinates
    weights: np.ndarray | None = None  #: (N,) quadrature weights: ∫_ΓC w ds ≈ Σ weights·w(nodes)
    normals: np.ndarray | None = None  #: (N, 2) contact direction ν (towards the obstacle)
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

    def active_interval(self) -> tuple[float, float] | None:
        """[y_min, y_max] of the contact zone, or None when nothing touches."""
        return active_interval(self.y, self.active)


def profile_order(points: np.ndarray) -> np.ndarray:
    """Order of contact nodes along Γ_C: by the coordinate with the larger spread (y for a vertical Γ_C), then the other."""
    if points.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    spread = np.ptp(points[:, :2], axis=0)
    major = 0 if spread[0] > spread[1] else 1
    return np.lexsort((points[:, 1 - major], points[:, major]))


def active_interval(y: np.ndarray, active: np.ndarray) -> tuple[float, float] | None:
    """[min y, max y] over the active nodes, or None."""
    if not np.any(active):
        return None
    return float(np.min(y[active])), float(np.max(y[active]))


def semismooth_newton(
    *,
    residual: Callable[[], float],
    active_set: Callable[[], np.ndarray],
    same_sets: Callable[[np.ndarray, np.ndarray], bool],
    factorize: Callable[[np.ndarray], bool],
    step: Callable[[], None],
    load_norm: float,
    options: NewtonOptions,
    name: str,
    comm,
) -> NewtonHistory:
    """Generic semismooth Newton loop over callbacks.

    ``comm`` sums the active-set sizes over ranks. ``residual()`` assembles F(u) and returns ‖F‖; ``active_set()`` returns the
    local active-set indicator of the current u; ``factorize(active)`` makes the
    factorization of J at the current u available, returning True if it had to
    refactorize (the caller caches it by active set: J depends on u only through
    the active set); ``step()`` solves J du = −F and updates u.
    """
    history = NewtonHistory()
    current = active_set()
    for _ in range(options.max_iterations):
        history.residuals.append(residual())
        history.factorizations += bool(factorize(current))
        linearized_at = current
        step()
        current = active_set()
        history.active_sizes.append(comm.allreduce(int(np.count_nonzero(current))))
        if same_sets(current, linearized_at):
            final = residual()
            history.residuals.append(final)
            if final > options.rtol * load_norm + options.atol:
                raise ConvergenceError(
                    f"{name}: active set settled but residual {final:.3e} exceeds "
                    f"{options.rtol:g}·‖b‖ = {options.rtol * load_norm:.3e} (ill-conditioned solve?)"
                )
            return history
    raise ConvergenceError(
        f"{name}: semismooth Newton did not converge in {options.max_iterations} steps "
        f"(active-set sizes {history.active_sizes[-5:]}, residuals {history.residuals[-3:]})"
    )
