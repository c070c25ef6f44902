"""Globalized semismooth Newton for the mixed penalized contact subproblem, with its exact line search.

Every Newton step (dσ, du) satisfies (div dσ, v) = 0 once the equilibrium equation holds, so dσ is a
descent direction of the convex, piecewise quadratic complementary energy

    J(σ) = ½(Aσ, σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε) ∫_ΓC ((σ_c)⁺)² ds

on the affine set {div σ = −f}.  Full steps are taken while they lead to new active sets; with full steps
the iterate depends only on the set it was linearized at, so a step into a set already visited closes a
cycle (plain semismooth Newton cycles here).  From the first such step on, the step length
minimizes J exactly along the Newton direction (J is piecewise quadratic in the step, with breakpoints
where σ_c changes sign), so J decreases monotonically and no cycle can recur.  The iteration ends with the
first step whose result has the active set it was linearized at (it then solves the penalized problem
exactly) and a residual check.  A cold start is linearized at "penalty everywhere" (traction-free Γ_C):
its solution is compressive exactly where a free body would penetrate, a good first contact set.  The
Jacobian depends on the iterate only through the active set, so factorizations are cached by active set
(``mixed_linear``).  The loop is ``fem.newton.semismooth_newton_loop``; ``globalized_newton`` gives it the
mixed subproblem's residual, solve and line search.

**MPI.**  The Γ_C node data are replicated, so every rank takes the same decisions (active set, cycle
detection, line-search step) from the same numbers; every scalar (energy, residual, step) is a global
reduction.
"""

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from fenics_contact.fem.contact import NewtonHistory, NewtonOptions
from fenics_contact.fem.mixed_assembly import MixedOperators, dot, norm
from fenics_contact.fem.mixed_contact import ContactNodes
from fenics_contact.fem.newton import Advance, Check, Direction, StepState, semismooth_newton_loop

__all__ = ["MixedNewtonHistory", "MixedNewtonProblem", "exact_line_search", "globalized_newton", "run_mixed_newton"]


@dataclass(slots=True)
class MixedNewtonHistory(NewtonHistory):
    """NewtonHistory plus the step length and complementary energy J after every Newton step.

    ``active_sizes`` counts the Γ_C contact nodes in contact (σ_c ≤ 0) after each step.
    """

    step_lengths: list[float] = field(default_factory=list)
    energies: list[float] = field(default_factory=list)


class MixedNewtonProblem(Protocol):
    """What the Newton iteration needs of a mixed contact subproblem (``MixedSubproblem``)."""

    c: np.ndarray  #: owned AW coefficients of σ (updated in place)
    u: np.ndarray  #: owned DG P1 coefficients of u (updated in place)
    cold: bool  #: no solution yet: linearize at "penalty everywhere"
    comm: object
    prefix: str
    newton: NewtonOptions
    line_search: str  #: "on-cycle" or "always"
    assembly: MixedOperators
    contact_nodes: ContactNodes

    def gradient(self, load: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def factorize_for(self, active: np.ndarray | None) -> bool: ...

    def linear_solve(self, r1: np.ndarray, r2: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...

    def complementary_energy(self, data: np.ndarray | None = None) -> float: ...

    def residual(self, data: np.ndarray | None = None) -> tuple[float, float]: ...

    def residual_norm(self, F1: np.ndarray, F2: np.ndarray) -> float: ...


def exact_line_search(
    problem: MixedNewtonProblem, dc: np.ndarray, s: np.ndarray, d: np.ndarray, load: np.ndarray
) -> float:
    """argmin_{t ∈ (0, 1]} J(σ + t dσ): root of the increasing piecewise-linear φ'(t) (s = σ_c, d = Q dσ replicated)."""
    Kt, comm = problem.assembly.Kt, problem.comm
    a = dot(dc, Kt @ dc, comm)
    b0 = dot(Kt @ problem.c - load, dc, comm)
    w = problem.contact_nodes.q_weights / problem.contact_nodes.epsilon

    def dphi(t: np.ndarray) -> np.ndarray:
        return a * t + b0 + (w * d * np.maximum(s[None, :] + t[:, None] * d[None, :], 0.0)).sum(axis=1)

    ends = dphi(np.array([0.0, 1.0]))
    if ends[0] >= 0.0 or ends[1] <= 0.0:
        return 1.0
    nz = d != 0.0
    bp = -s[nz] / d[nz]
    bp = np.unique(np.concatenate([[0.0, 1.0], bp[(bp > 0.0) & (bp < 1.0)]]))
    vals = dphi(bp)
    k = int(np.argmax(vals > 0.0))  # first breakpoint with φ' > 0 (k ≥ 1)
    t0, t1, v0, v1 = bp[k - 1], bp[k], vals[k - 1], vals[k]
    return float(t0 - v0 * (t1 - t0) / (v1 - v0))


class _MixedSystem:
    """A ``MixedNewtonProblem`` as a ``ContactSystem``: the set {σ_c > 0} (all of Γ_C at a cold start), Newton
    directions (dσ, du), the exact line search on J once the equilibrium equation holds."""

    def __init__(self, problem: MixedNewtonProblem, load: np.ndarray, data: np.ndarray | None) -> None:
        self.problem, self.load, self.data = problem, load, data
        self.energies: list[float] = []
        self.s = problem.contact_nodes.stress(problem.c)

    def start(self) -> np.ndarray:
        """The first set: "penalty everywhere" at a cold start (traction-free Γ_C: its solution has σ_c < 0
        exactly where a free body would penetrate, a good first contact set), else {σ_c > 0}."""
        return np.ones_like(self.s, dtype=bool) if self.problem.cold else self.s > 0.0

    def residual(self) -> float:
        self.F1, self.F2 = self.problem.gradient(self.load)
        return self.problem.residual_norm(self.F1, self.F2)

    def jacobian(self, active: np.ndarray) -> bool:
        return self.problem.factorize_for(active)

    def solve(self, active: np.ndarray) -> Direction:
        problem, comm, nodes = self.problem, self.problem.comm, self.problem.contact_nodes
        B, G = problem.assembly.B, problem.assembly.G
        # dσ descends J on {div σ = −f} only once the equilibrium equation holds
        feasible = norm(self.F2, comm) <= 1e-10 * (norm(G, comm) + norm(B @ problem.c, comm))
        self.dc, self.du = problem.linear_solve(-self.F1, -self.F2)
        self.d = nodes.replicate(nodes.Q @ self.dc)
        return Direction(self.s + self.d > 0.0, searchable=feasible)

    def same(self, a: np.ndarray, b: np.ndarray) -> bool:
        return np.array_equal(a, b)  # (replicated Γ_C data)

    def line_search(self) -> float:
        return exact_line_search(self.problem, self.dc, self.s, self.d, self.load)

    def advance(self, t: float, state: StepState) -> Advance:
        problem = self.problem
        problem.cold = False
        problem.c += t * self.dc
        problem.u += t * self.du
        self.energies.append(problem.complementary_energy(self.data))
        self.s = problem.contact_nodes.stress(problem.c)
        return Advance(self.s > 0.0, int(np.count_nonzero(self.s <= 0.0)))

    def check(self) -> Check:
        final, scale = self.problem.residual(self.data)
        return Check(final, scale, final)


def globalized_newton(problem: MixedNewtonProblem, load: np.ndarray, data: np.ndarray | None) -> MixedNewtonHistory:
    """Solve the penalized contact problem with stress-side load ``load`` (Robin data ``data``), warm-started
    from (problem.c, problem.u) (``fem.newton.semismooth_newton_loop``); raises ConvergenceError at the step cap
    or when the settled residual fails its check."""
    return run_mixed_newton(_MixedSystem(problem, load, data), problem)


def run_mixed_newton(system, problem: MixedNewtonProblem) -> MixedNewtonHistory:
    """``fem.newton.semismooth_newton_loop`` on a mixed contact ``system`` (frictionless or frictional) with the
    Newton options, line search and prefix of ``problem``, its trace as a ``MixedNewtonHistory``."""
    options = problem.newton
    trace = semismooth_newton_loop(
        system,
        system.start(),
        name=problem.prefix.rstrip("_"),
        max_steps=options.max_iterations,
        line_search=problem.line_search,
        rtol=options.rtol,
        atol=options.atol,
        sizes="contact-set sizes",
    )
    return MixedNewtonHistory(
        residuals=trace.residuals,
        active_sizes=trace.active_sizes,
        factorizations=trace.factorizations,
        step_lengths=trace.step_lengths,
        energies=system.energies,
    )
