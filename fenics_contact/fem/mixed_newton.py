"""Globalized semismooth Newton for the mixed penalized contact subproblem, with its exact line search.

Every Newton step (dσ, du) satisfies (div dσ, v) = 0 once the equilibrium equation holds, so dσ is a
descent direction of the convex, piecewise quadratic complementary energy

    J(σ) = ½(Aσ, σ) [+ ½β‖σn‖²_γ − ∫_γ g·σn] + (1/2ε) ∫_ΓC ((σ_c)⁺)² ds

on the affine set {div σ = −f}.  Full steps are taken while they lead to new active sets; with full steps
the iterate depends only on the set it was linearized at, so a step into a set already visited closes a
cycle (plain semismooth Newton cycles here, METHOD §8).  From the first such step on, the step length
minimizes J exactly along the Newton direction (J is piecewise quadratic in the step, with breakpoints
where σ_c changes sign), so J decreases monotonically and no cycle can recur.  The iteration ends with the
first step whose result has the active set it was linearized at (it then solves the penalized problem
exactly) and a residual check.  A cold start is linearized at "penalty everywhere" (traction-free Γ_C):
its solution is compressive exactly where a free body would penetrate, a good first contact set.  The
Jacobian depends on the iterate only through the active set, so factorizations are cached by active set
(``mixed_linear``).

**MPI.**  The Γ_C node data are replicated, so every rank takes the same decisions (active set, cycle
detection, line-search step) from the same numbers; every scalar (energy, residual, step) is a global
reduction.
"""

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from fenics_contact.errors import ConvergenceError
from fenics_contact.fem.contact import NewtonHistory, NewtonOptions
from fenics_contact.fem.mixed_assembly import MixedOperators, dot, norm
from fenics_contact.fem.mixed_contact import ContactNodes

__all__ = ["MixedNewtonHistory", "MixedNewtonProblem", "exact_line_search", "globalized_newton"]


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


def exact_line_search(problem: MixedNewtonProblem, dc: np.ndarray, s: np.ndarray, d: np.ndarray,
                      load: np.ndarray) -> float:
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


def globalized_newton(problem: MixedNewtonProblem, load: np.ndarray, data: np.ndarray | None
                      ) -> MixedNewtonHistory:
    """Solve the penalized contact problem with stress-side load ``load`` (Robin data ``data``), warm-started
    from (problem.c, problem.u); raises ConvergenceError at the step cap or when the settled residual fails."""
    history = MixedNewtonHistory()
    comm, nodes, options = problem.comm, problem.contact_nodes, problem.newton
    B, G = problem.assembly.B, problem.assembly.G
    name = problem.prefix.rstrip("_")
    visited: set[bytes] = set()
    line_search = problem.line_search == "always"
    for _ in range(options.max_iterations):
        s = nodes.stress(problem.c)
        # cold start: linearize at "penalty everywhere" (traction-free Γ_C); its solution has
        # σ_c < 0 exactly where a free body would penetrate, a good first contact set
        active = np.ones_like(s, dtype=bool) if problem.cold else s > 0.0
        visited.add(np.packbits(active).tobytes())
        F1, F2 = problem.gradient(load)
        history.residuals.append(float(np.sqrt(dot(F1, F1, comm) + dot(F2, F2, comm))))
        history.factorizations += problem.factorize_for(active)
        feasible = norm(F2, comm) <= 1e-10 * (norm(G, comm) + norm(B @ problem.c, comm))
        dc, du = problem.linear_solve(-F1, -F2)
        d = nodes.replicate(nodes.Q @ dc)
        predicted = s + d > 0.0
        settled = np.array_equal(predicted, active)
        if not settled and feasible and not line_search:
            # with full steps the iterate depends only on the set it was linearized at, so
            # stepping into a set already linearized at closes a cycle: from then on
            # minimize J along every direction (J decreases monotonically: no cycle)
            line_search = np.packbits(predicted).tobytes() in visited
        t = exact_line_search(problem, dc, s, d, load) if line_search and feasible and not settled else 1.0
        problem.cold = False
        problem.c += t * dc
        problem.u += t * du
        history.step_lengths.append(t)
        history.energies.append(problem.complementary_energy(data))
        history.active_sizes.append(int(np.count_nonzero(nodes.stress(problem.c) <= 0.0)))
        if settled:
            final, scale = problem.residual(data)
            history.residuals.append(final)
            if final > options.rtol * scale + options.atol:
                raise ConvergenceError(
                    f"{name}: active set settled but residual {final:.3e} exceeds "
                    f"{options.rtol:g}·(size of the terms {scale:.3e})"
                )
            return history
    raise ConvergenceError(
        f"{name}: globalized semismooth Newton did not converge in {options.max_iterations} steps "
        f"(contact-set sizes {history.active_sizes[-5:]}, step lengths {history.step_lengths[-5:]}, "
        f"residuals {history.residuals[-3:]})"
    )
