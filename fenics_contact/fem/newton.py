"""The semismooth Newton method of penalized contact: one loop for the primal, mixed and condensed solves.

The generalized derivative of s ↦ s⁺ is the Heaviside function, so on a fixed active set 𝒜 the penalized
contact equations are linear: each step solves them linearized on the set of the current iterate.  The
iteration ends with the first step whose result has the set it was linearized at (finite termination) and
the system's residual check; a settled step that misses the check may be followed by ``refinements`` more
steps with the same Jacobian (iterative refinement of a solve that lost digits).

Globalization (``line_search``): with full steps the iterate depends only on the set it was linearized
at, so a step into a set already linearized at closes a cycle.  ``"on-cycle"`` takes full steps until such
a step, and from it on the step length of the system's exact line search on its convex energy (which then
decreases monotonically: no cycle can recur); ``"always"`` searches at every step; ``"never"`` takes full
steps only.  A step the system marks as not searchable (``Direction.searchable``) is a full step and does
not count for cycles.

What a contact solve provides is a ``ContactSystem``: its residual, Jacobian, linear solve, line search,
update and check, on active sets given as boolean arrays.  ``semismooth_newton_loop`` drives it and returns
a ``NewtonTrace``; every failure is a ConvergenceError carrying ``steps``, the steps taken with the failed one.
"""

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

import numpy as np

from fenics_contact.errors import ConvergenceError, InputError

__all__ = [
    "LINE_SEARCHES",
    "Direction",
    "StepState",
    "Advance",
    "Check",
    "ContactSystem",
    "NewtonTrace",
    "semismooth_newton_loop",
    "exact_step",
    "lowers_energy",
]

#: when the exact line search runs (module docstring)
LINE_SEARCHES = ("never", "on-cycle", "always")


class Direction(NamedTuple):
    """A Newton direction: the active set of the iterate a full step leads to, and whether the line search
    applies to it."""

    predicted: np.ndarray
    searchable: bool = True


class StepState(NamedTuple):
    """What the loop knows when the system takes its step: the step settles the active set, the line search
    is on, and ``seen(active)``: the loop has linearized at that set already."""

    settled: bool
    searching: bool
    seen: Callable[[np.ndarray], bool]


class Advance(NamedTuple):
    """The result of a step: the set the next step is linearized at, the size the history records for it, and
    a residual norm after the step to record (None: the system records its residuals before each step)."""

    active: np.ndarray
    size: int
    residual: float | None = None


class Check(NamedTuple):
    """The residual check of a settled iterate: ‖F‖ and the size of the terms F balances (in one norm), and the
    residual norm the history records for the accepted iterate."""

    residual: float
    scale: float
    recorded: float


class ContactSystem(Protocol):
    """A penalized contact problem as the semismooth Newton loop sees it (an iterate it updates in place)."""

    def residual(self) -> float | None:
        """Assemble F at the current iterate; its norm for the history (None: nothing recorded before a step)."""

    def jacobian(self, active: np.ndarray) -> bool:
        """Make J linearized on ``active`` ready to solve with; True when it was factorized anew."""

    def solve(self, active: np.ndarray) -> Direction:
        """Solve J d = −F for the Newton direction d."""

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        """The active sets a and b are equal (on every rank)."""

    def line_search(self) -> float:
        """argmin over t ∈ (0, 1] of the system's energy along the last direction."""

    def advance(self, t: float, state: StepState) -> Advance:
        """Move the iterate by t times the last direction."""

    def check(self) -> Check | None:
        """The residual check of the current (settled) iterate (None: the solve was checked already)."""


@dataclass(slots=True)
class NewtonTrace:
    """Per step: step length and active-set size after it; the residual norms the system reports (before each
    step and at the end, or after each step); the factorizations made."""

    residuals: list[float] = field(default_factory=list)
    active_sizes: list[int] = field(default_factory=list)
    step_lengths: list[float] = field(default_factory=list)
    factorizations: int = 0

    @property
    def steps(self) -> int:
        """Number of Newton steps (linear solves)."""
        return len(self.step_lengths)


def _key(active: np.ndarray) -> bytes:
    return np.packbits(active).tobytes()


def semismooth_newton_loop(
    system: ContactSystem,
    active: np.ndarray,
    *,
    name: str,
    max_steps: int,
    line_search: str = "on-cycle",
    rtol: float = 0.0,
    atol: float = 0.0,
    refinements: int = 0,
    sizes: str = "active-set sizes",
) -> NewtonTrace:
    """Semismooth Newton on ``system`` from its current iterate, linearized first at ``active``.

    A settled step is accepted when the system has no check or ‖F‖ ≤ rtol·(size of its terms) + atol with ‖F‖
    finite; otherwise up to ``refinements`` further steps follow before ConvergenceError.  ConvergenceError
    too at ``max_steps`` steps, and for a failure inside a step (``steps`` counts that step).  ``sizes`` names
    what ``Advance.size`` counts, for the messages.
    """
    if line_search not in LINE_SEARCHES:
        raise InputError(f"{name}: line_search must be one of {', '.join(LINE_SEARCHES)}, got {line_search!r}")
    trace = NewtonTrace()
    visited: set[bytes] = set()
    cycles = line_search != "never"
    searching = line_search == "always"
    refined = 0

    def seen(candidate: np.ndarray) -> bool:
        return _key(candidate) in visited

    for k in range(max_steps):
        try:
            if cycles:
                visited.add(_key(active))
            norm = system.residual()
            if norm is not None:
                trace.residuals.append(norm)
            trace.factorizations += bool(system.jacobian(active))
            direction = system.solve(active)
            settled = system.same(direction.predicted, active)
            if cycles and not settled and direction.searchable and not searching:
                searching = seen(direction.predicted)  # the full step would close a cycle
            t = system.line_search() if searching and direction.searchable and not settled else 1.0
            after = system.advance(t, StepState(settled, searching, seen))
            trace.step_lengths.append(t)
            trace.active_sizes.append(after.size)
            if after.residual is not None:
                trace.residuals.append(after.residual)
            if settled:
                check = system.check()
                if check is None:
                    return trace
                if np.isfinite(check.residual) and check.residual <= rtol * check.scale + atol:
                    trace.residuals.append(check.recorded)
                    return trace
                if not np.isfinite(check.residual) or refined == refinements:
                    raise ConvergenceError(
                        f"{name}: active set settled but the residual {check.residual:.3e} exceeds {rtol:g} x the "
                        f"size of the terms it balances ({check.scale:.3e}) after {refined} refinement steps: the "
                        "linear solve failed (ill-conditioned?)"
                    )
                refined += 1  # iterative refinement: one more step with the same Jacobian
            active = after.active
        except ConvergenceError as error:
            error.steps = k + 1
            raise
    lengths = f", step lengths {trace.step_lengths[-5:]}" if cycles else ""
    error = ConvergenceError(
        f"{name}: semismooth Newton did not converge in {max_steps} steps ({sizes} {trace.active_sizes[-5:]}"
        f"{lengths}, residuals {trace.residuals[-3:]})"
    )
    error.steps = max_steps
    raise error


def exact_step(slope: Callable[[float], float]) -> float:
    """The root in (0, 1] of the increasing slope t ↦ d·∇ψ(u + t d) of a convex energy ψ along d: the exact line
    search, by regula falsi with the Illinois modification (1 when the slope does not change sign on [0, 1])."""
    t0, t1 = 0.0, 1.0
    f0, f1 = slope(0.0), slope(1.0)
    if f0 >= 0.0 or f1 <= 0.0:
        return 1.0
    t = 1.0
    for _ in range(60):
        t = t1 - f1 * (t1 - t0) / (f1 - f0)
        f = slope(t)
        if abs(f) <= 1e-12 * abs(f0) or t1 - t0 <= 1e-12:
            return t
        if f > 0.0:
            t1, f1 = t, f
            f0 *= 0.5
        else:
            t0, f0 = t, f
            f1 *= 0.5
    return t


#: ``lowers_energy``: the energy's change along [0, 1] by composite 3-point Gauss–Legendre on this many pieces
ENERGY_PIECES = 8
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(3)


def lowers_energy(slope: Callable[[float], float], start: float) -> bool:
    """Whether the full step lowers the convex energy ψ whose slope along the direction is t ↦ d·∇ψ(u + t d)
    (``start`` = slope(0) < 0): ψ(u + d) − ψ(u) = ∫₀¹ slope ≤ 10⁻⁴ slope(0), the integral by composite Gauss–Legendre
    (the slope is piecewise smooth: exact on its smooth pieces up to the quadrature error of the kinks)."""
    edges = np.linspace(0.0, 1.0, ENERGY_PIECES + 1)
    change = sum(
        0.5 * (b - a) * w * slope(a + 0.5 * (b - a) * (x + 1.0))
        for a, b in zip(edges[:-1], edges[1:])
        for x, w in zip(_NODES, _WEIGHTS)
    )
    return change <= 1e-4 * start
