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

#: Newton steps with a settled active set (and so the same factorization) allowed to bring the
#: residual to the check: iterative refinement of a solve whose pivots lost digits (tiny δ).
MAX_REFINEMENTS = 2

__all__ = ["NewtonOptions", "NewtonHistory", "ContactProfile", "semismooth_newton", "active_interval"]


@dataclass(frozen=True, slots=True)
class NewtonOptions:
    """Semismooth Newton options: step cap, and the residual check at termination.

    The check is normwise backward stability: ‖F(u)‖ ≤ rtol·(size of the terms F balances) + atol,
    the size being ‖J‖‖u‖ + ‖b‖ (stiffness, penalty and Robin terms, load and data) for the primal
    solve and the sum of the norms of the terms for the mixed one. A backward-stable direct solve
    meets it with rtol ~ 1e-16·growth whatever δ, ε or the contrast, so rtol = 1e-8 only rejects a
    solve whose linear algebra failed.
    """

    max_iterations: int = 50
    rtol: float = 1e-8
    atol: float = 1e-13

    def __post_init__(self) -> None:
        if not isinstance(self.max_iterations, (int, np.integer)) or self.max_iterations < 1:
            raise InputError(f"max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if not (np.isfinite(self.rtol) and np.isfinite(self.atol) and 0 < self.rtol < 1 and self.atol >= 0):
            raise InputError(f"Newton tolerances must be finite, 0 < rtol < 1 and atol >= 0; got {self.rtol!r}, "
                             f"{self.atol!r}")


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
    """Nodal data along Γ_C, sorted by y: position, normal displacement, normal stress."""

    y: np.ndarray
    u_c: np.ndarray
    sigma_c: np.ndarray

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
    residual_check: Callable[[], tuple[float, float]],
    options: NewtonOptions,
    name: str,
    comm,
) -> NewtonHistory:
    """Generic semismooth Newton loop over callbacks.

    ``comm`` sums the active-set sizes over ranks. ``residual()`` assembles F(u) and returns ‖F‖; ``active_set()`` returns the
    local active-set indicator of the current u; ``factorize(active)`` makes the
    factorization of J at the current u available, returning True if it had to
    refactorize (the caller caches it by active set: J depends on u only through
    the active set); ``step()`` solves J du = −F and updates u; ``residual_check()`` returns
    (‖F(u)‖, the size of the terms F balances) in one norm, e.g. (‖F‖∞, ‖J‖∞‖u‖∞ + ‖b‖∞).
    A settled step whose residual fails the check is followed by up to ``MAX_REFINEMENTS`` steps
    with the same factorization (iterative refinement). Raises ConvergenceError when the step cap is
    hit or the residual still fails the check.
    """
    history = NewtonHistory()
    current = active_set()
    refinements = 0
    for _ in range(options.max_iterations):
        history.residuals.append(residual())
        history.factorizations += bool(factorize(current))
        linearized_at = current
        step()
        current = active_set()
        history.active_sizes.append(comm.allreduce(int(np.count_nonzero(current))))
        if same_sets(current, linearized_at):
            final, scale = residual_check()
            if np.isfinite(final) and final <= options.rtol * scale + options.atol:
                history.residuals.append(residual())
                return history
            if not np.isfinite(final) or refinements == MAX_REFINEMENTS:
                raise ConvergenceError(
                    f"{name}: active set settled but the residual {final:.3e} exceeds {options.rtol:g} x the size "
                    f"of the terms it balances ({scale:.3e}) after {refinements} refinement steps: the linear "
                    "solve failed (ill-conditioned?)"
                )
            refinements += 1  # iterative refinement: one more step with the same factorization
    raise ConvergenceError(
        f"{name}: semismooth Newton did not converge in {options.max_iterations} steps "
        f"(active-set sizes {history.active_sizes[-5:]}, residuals {history.residuals[-3:]})"
    )
