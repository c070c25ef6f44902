"""The contact Newton: s = s_L − M D s⁺ on the condensed Γ_C unknowns by semismooth Newton.

M (n_c × n_c) is the contact compliance of the glued problem and s_L its load term
(``hybrid.condensation``).  Each step solves the contact equations linearized on the current active set
𝒜 for the forces (``contact_equations.solve_on``); the next set is {s > 0}, or, by default, the one the
local front resolution proposes (``fronts.LocalFronts``).  Every set solved on all of Γ_C is a step, and
a set is accepted only when the solve on it reproduces it.  The Newton method takes full steps until an
active set recurs and from then on minimizes, along each Newton direction, ψ = ½ μᵀMμ + ½ Σ D (s⁺)² with
s = s_L − Mμ (exact line search on a piecewise-linear derivative, ``contact_equations.energy_line_search``):
ψ is the convex energy of the glued problem when M is symmetric (Algorithms 1, 2), so no cycle can recur.
A Newton method that does not converge in ``max_steps`` or meets a singular system raises
ConvergenceError; ``contact_solve`` then starts the plain Newton afresh.  The loop is
``fem.newton.semismooth_newton_loop``; ``contact_newton`` gives it the condensed equations.
"""

import logging
from dataclasses import dataclass, field

import numpy as np

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.newton import Advance, Direction, StepState, semismooth_newton_loop
from fenics_contact.hybrid.contact_equations import energy_line_search, solve_on
from fenics_contact.hybrid.fronts import LocalFronts
from fenics_contact.hybrid.options import InterfaceNewtonOptions

__all__ = ["ContactNewtonHistory", "contact_newton", "contact_solve"]

log = logging.getLogger(__name__)


@dataclass(slots=True)
class ContactNewtonHistory:
    """Active-set sizes, step lengths and contact-law violations ‖μ − D s⁺‖ of the contact Newton.

    ``added`` / ``removed``: the contact rows each step brought into / took out of the active set it
    solves next (indices into the Γ_C unknowns; the step that confirms the set adds and removes none).
    """

    active_sizes: list[int] = field(default_factory=list)
    step_lengths: list[float] = field(default_factory=list)
    residuals: list[float] = field(default_factory=list)
    added: list[np.ndarray] = field(default_factory=list)
    removed: list[np.ndarray] = field(default_factory=list)
    #: rows where the next set differs from the semismooth step's own set {s > 0} because the local front
    #: resolution set them, per step (empty: none); the next step solves that trial set.  A row may be one
    #: the step would have flipped and the local problem kept as it was (then it is in neither ``added``
    #: nor ``removed``)
    resolved: list[np.ndarray] = field(default_factory=list)
    #: per step: (local problems, their semismooth iterations, largest window) of the local front resolution
    #: (``LocalFronts``; (0, 0, 0) when none was solved)
    local: list[tuple[int, int, int]] = field(default_factory=list)
    #: steps of a first attempt that did not converge (``CondensedInterface.solve`` then starts the plain
    #: contact Newton afresh; the records above are the second attempt's), counted in ``steps``
    discarded: int = 0

    @property
    def steps(self) -> int:
        return len(self.step_lengths) + self.discarded

    @property
    def local_iterations(self) -> int:
        """Semismooth iterations of all the local front problems (each a solve of at most 2w unknowns for an
        isolated front)."""
        return sum(it for _, it, _ in self.local)


class _CondensedSystem:
    """s = s_L − M μ, μ = D s⁺ as a ``ContactSystem``: the iterate (s, μ), each step solved on its set for the
    forces (``solve_on``, checked for a singular system), the next set that of the local front resolution
    where it proposes one not yet solved."""

    def __init__(
        self,
        s_load: np.ndarray,
        M: np.ndarray,
        D: np.ndarray,
        *,
        name: str,
        rtol: float,
        local: LocalFronts | None,
        factors: dict | None = None,
    ) -> None:
        self.s_load, self.M, self.D, self.name, self.rtol, self.local = s_load, M, D, name, rtol, local
        self.factors = factors
        self.s, self.mu = s_load.copy(), np.zeros(s_load.size)
        self.hist = ContactNewtonHistory()
        self.active: np.ndarray | None = None

    def residual(self) -> None:
        return None  # (the contact-law violation is recorded after each step)

    def jacobian(self, active: np.ndarray) -> bool:
        return False  # (each solve factorizes its dense system on the set)

    def solve(self, active: np.ndarray) -> Direction:
        self.active = active
        A = np.flatnonzero(active)
        self.s_new, self.mu_new, residual = solve_on(self.s_load, self.M, self.D, A, self.factors)
        if self.factors:  # only the set just solved on is kept (the last step's: a warm-started next solve's first)
            kept = A.tobytes()
            for key in [k for k in self.factors if k != kept]:
                del self.factors[key]
        if residual > self.rtol:
            raise ConvergenceError(
                f"{self.name}: the condensed contact system is singular or ill-conditioned "
                f"(relative residual {residual:.1e})"
            )
        return Direction(self.s_new > 0.0)

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return np.array_equal(a, b)

    def line_search(self) -> float:
        return energy_line_search(self.mu, self.mu_new - self.mu, self.s, self.s_new - self.s, self.s_load, self.D)

    def advance(self, t: float, state: StepState) -> Advance:
        active, hist = self.active, self.hist
        self.s, self.mu = self.s + t * (self.s_new - self.s), self.mu + t * (self.mu_new - self.mu)
        s, mu = self.s, self.mu
        following = s > 0.0
        resolved = np.zeros(0, dtype=np.int64)
        local_work = (0, 0, 0)
        if self.local is not None and not state.searching and not state.settled:
            trial, local_work = self.local.trial(following, self.s_load, self.mu_new)
            if not state.seen(trial):  # (a set already solved: the plain one instead)
                resolved, following = np.flatnonzero(trial != following), trial
        hist.local.append(local_work)
        hist.added.append(np.flatnonzero(following & ~active))
        hist.removed.append(np.flatnonzero(active & ~following))
        hist.resolved.append(resolved)
        violation = float(np.linalg.norm(mu - self.D * np.maximum(s, 0.0)))  # the contact law's
        return Advance(following, int(np.count_nonzero(following)), violation)

    def check(self) -> None:
        return None  # (every solve was checked)


def contact_newton(
    s_load: np.ndarray,
    M: np.ndarray,
    D: np.ndarray,
    *,
    max_steps: int = 50,
    name: str = "contact Newton",
    rtol: float = 1e-10,
    active: np.ndarray | None = None,
    line_search: bool = False,
    chains=None,
    window: int = 0,
    factors: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, ContactNewtonHistory]:
    """Solve s = s_L − M μ, μ = D s⁺ by semismooth Newton (finite termination, globalized): (s, μ).

    Starts from μ = 0 (no contact force) with the active set 𝒜 = {s_L > 0} (the contact-free
    solution's penetration pattern), or from the set ``active`` (a guess, e.g. a coarser solve's);
    ``line_search``: the exact line search at every step (by default only once an active set
    recurs).  A full step solves the problem linearized at the
    current active set 𝒜 = {s > 0} for the forces: (D_𝒜⁻¹ + M_𝒜𝒜) μ_𝒜 = s_L,𝒜, s = s_L − M_:𝒜 μ_𝒜
    (on 𝒜, s = μ/D: no cancellation with a stiff penalty).  It stops at the first step whose result
    has the set it was computed for (then both equations hold exactly) and checks that solve.
    ``chains`` (``contact_chains`` of the Γ_C unknowns' coordinates) and ``window`` > 0: the next set
    is that of the local front resolution (``LocalFronts``, ``window`` unknowns on either side of every
    front) until the line search starts; every set solved, proposed or not, is one step.  Without
    them (``window`` = 0): the plain semismooth Newton.  ``factors``: the LU factors of the systems on the sets
    solved, by set (``contact_equations.solve_on``; a dict kept by the caller: a load step that solves on the last
    step's set again back-solves).  The loop is ``fem.newton.semismooth_newton_loop``; its ConvergenceError carries
    ``steps``.
    """
    if window < 0:
        raise ValueError(f"contact_newton: window must be >= 0, got {window}")
    local = LocalFronts(chains, M, D, window) if chains and window > 0 else None
    system = _CondensedSystem(s_load, M, D, name=name, rtol=rtol, local=local, factors=factors)
    start = s_load > 0.0 if active is None else np.asarray(active, dtype=bool).copy()
    trace = semismooth_newton_loop(
        system, start, name=name, max_steps=max_steps, line_search="always" if line_search else "on-cycle"
    )
    hist = system.hist
    hist.active_sizes, hist.step_lengths, hist.residuals = trace.active_sizes, trace.step_lengths, trace.residuals
    return system.s, system.mu, hist


def contact_solve(
    s_load: np.ndarray,
    M: np.ndarray,
    D: np.ndarray,
    options: InterfaceNewtonOptions,
    name: str,
    chains,
    active: np.ndarray | None = None,
    factors: dict | None = None,
) -> tuple[np.ndarray, np.ndarray, "ContactNewtonHistory"]:
    """``contact_newton`` with the options' local front resolution (``chains`` given, ``options.front_window``
    unknowns on either side of every front), and the plain contact Newton afresh should that not converge:
    with a non-symmetric M (a multiscale Ω₁) the energy line search that stops cycles is no merit function,
    and a set the local problems chose can lead into a cycle the plain Newton avoids.  The failed attempt's steps
    stay counted (``ContactNewtonHistory.discarded``).  ``active``: the first set (e.g. the last load step's),
    else {s_L > 0}; ``factors``: ``contact_newton``'s."""
    try:
        return contact_newton(
            s_load,
            M,
            D,
            max_steps=options.max_steps,
            name=name,
            chains=chains,
            window=options.front_window,
            active=active,
            factors=factors,
        )
    except ConvergenceError as first:
        if not chains:
            raise
        log.warning(
            "%s: the contact Newton with the local front resolution did not converge (%s); the plain "
            "contact Newton instead",
            name,
            first,
        )
        s, mu, hist = contact_newton(s_load, M, D, max_steps=options.max_steps, name=name, factors=factors)
        hist.discarded = first.steps
        return s, mu, hist
