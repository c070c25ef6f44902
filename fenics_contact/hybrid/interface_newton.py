"""Interface Newton: solve the hybrid fixed point g = T(g) of any algorithm by semismooth Newton.

The step provides its ``InterfaceProblem`` (``hybrid.condensation``: Ω₁'s affine interface response, Ω₂'s
affine pieces, ``hybrid.response``).  Two strategies solve g = T(g) (``InterfaceNewtonOptions.strategy``):

* ``"condensed"`` (default): offline, the glued linear problem is condensed onto the Γ_C unknowns
  (``CondensedInterface``: s = s_L − M D s⁺).  Online: s_L, then the contact Newton on the contact forces
  (``hybrid.contact_newton``: dense, size n_c; with Algorithm 1 the condensation is exact and its active
  sets are those of the monolithic semismooth Newton from its second step on; a warm-started solve, a load
  step whose ``initial`` data are the last step's, starts it from the last active set), then the data g and one
  application of T with the real subdomain solvers: Ω₁ is solved, Ω₂'s state (one more J₀ back-solve) is
  checked against its own equations with the acceptance test of its Newton solver and solved only if
  that fails.  The transmission residual of that pair certifies the result.  Should it be above the
  tolerance (round-off for extreme α, β or contrast), Newton steps on F(g) = g − T(g) follow, with Ω₂'s
  generalized Jacobian from the same offline data (Woodbury on J₀, no factorization), or, when such a step
  does not reduce the residual, exactly by back-solves with Ω₂'s own factorization.
* ``"interface"``: Newton on F(g) = g − T(g) from g⁰, each step an application of T (the Ω₂ semismooth
  Newton) and Ω₂'s generalized Jacobian from the factorization Ω₂ keeps (the entries of its inverse on the
  interface unknowns, or n_γ back-solves under MPI); a backtracking line search on ‖F‖ globalizes it.  It
  needs no J₀ but that Jacobian in every step.

A line search that rejects all its trials: a step with the condensed Jacobian is retried from the same iterate
with the exact one.  With the ``"interface"`` strategy the iterate stays where it was (a rejected trial never
becomes the next one): one more step from it with Ω₂'s Jacobian at the shortest trial's state (the other side of
a contact or stick/slip front next to the iterate), and should that fail too, Anderson acceleration goes on from
the iterate for the remaining steps, its least squares seeded with the trials (their applications of T are secant
information).  The corrections after a condensed solve start at its fixed point, where ‖F‖ is round-off and no
trial can lower it; there the next step goes on from the shortest trial, within round-off of the iterate.

Both land on the fixed point of the Robin iteration (the same equations).  A Newton method that fails (no
convergence in ``max_steps``, a singular condensed system) raises ConvergenceError; a pair whose
transmission residual stays above the tolerance ends with ``converged = False``.
"""

import logging
import time
from dataclasses import replace

import numpy as np

from fenics_contact.hybrid.anderson import AndersonUpdate
from fenics_contact.hybrid.condensation import CondensedInterface
from fenics_contact.hybrid.options import IterationOptions
from fenics_contact.hybrid.step import COLLAPSE, IterationHistory, data_norm, evaluate, zero_is_the_fixed_point

__all__ = ["newton_iterate"]

log = logging.getLogger(__name__)

#: trials of the backtracking with Ω₂'s exact Jacobian (step lengths 1, ½, …, 1/32)
TRIALS = 6


def _norm(v: np.ndarray) -> float:
    return float(np.linalg.norm(v))


def newton_iterate(
    step, options: IterationOptions, *, name: str, monitor=None, initial: np.ndarray | None = None
) -> IterationHistory:
    """Interface Newton on g = T(g) (``accel="newton"``); each record is one application of T.

    The step provides ``interface_problem(options.newton)`` (an ``InterfaceProblem``, built once
    and cached by the step: its time is the offline ``history.time_offline_s``).
    """
    nopt = options.newton
    history = IterationHistory()
    t_off = time.perf_counter()
    problem = step.interface_problem(nopt)
    if problem.options.strategy != nopt.strategy:  # (the step's: ``options.interface_options`` with friction)
        nopt = replace(nopt, strategy=problem.options.strategy)
    stale = problem.condensed
    if problem.omega2.refresh():  # the normals moved: condense again (keeping what does not depend on them)
        problem.condensed = None
    if nopt.strategy == "condensed" and problem.condensed is None:
        problem.condensed = CondensedInterface(problem, previous=stale)
    history.time_offline_s = time.perf_counter() - t_off
    start = time.perf_counter()
    comm = step.comm
    om2 = problem.omega2
    if nopt.strategy == "condensed":
        # a warm start (a load step after another, ``initial`` its data): the contact Newton from the last active set
        warm = initial is not None and data_norm(np.asarray(initial, dtype=float), comm) > 0.0
        g12, g21, lam, ch = problem.condensed.solve(nopt, name, warm=warm)
        # broadcast: every rank continues from rank 0's (identical) dense result
        g12, g21, lam = comm.bcast((g12, g21, lam), root=0)
        om2.set_state(om2.solve(om2.rhs(g21, lam)))  # warm start of Ω₂: one J₀ back-solve
        history.newton_steps = ch.steps
        resolved = [e.size for e in ch.resolved]
        log.info(
            "%s: contact Newton %d steps, active-set sizes %s, step lengths %s, rows added/removed per step %s%s%s",
            name,
            ch.steps,
            ch.active_sizes,
            [round(t, 3) for t in ch.step_lengths],
            [f"+{a.size}/-{r.size}" for a, r in zip(ch.added, ch.removed)],
            f" (rows the local front resolution set otherwise than the plain step: {resolved})"
            if any(resolved)
            else "",
            f"; local front problems {sum(w for w, _, _ in ch.local)}, {ch.local_iterations} iterations, "
            f"largest window {max(m for _, _, m in ch.local)}"
            if any(w for w, _, _ in ch.local)
            else "",
        )
        history.contact_newton = ch
        g = problem.data(g12, g21)
    else:
        g = step.initial_data() if initial is None else initial
    steps_left = nopt.max_corrections if nopt.strategy == "condensed" else nopt.max_steps
    # Jacobian of Ω₂: from the offline condensation (Woodbury, no factorization), or exact from its factorization
    # with Ω₂'s own factorization (the "interface" strategy, and the fallback when a condensed step fails:
    # with a stiff penalty the Woodbury update loses digits)
    exact = nopt.strategy == "interface" or getattr(problem.condensed, "exact_corrections", False)
    # certify: Ω₁ is solved, Ω₂'s warm state is checked against its own equations (solved only if that fails)
    Tg, rec = evaluate(step, g, history, name=name, monitor=monitor, omega2_warm=nopt.strategy == "condensed")
    rec.info["newton_steps"] = history.newton_steps
    # iterates that collapse towards a vanishing solution never certify (a relative residual): try g = 0 once,
    # before corrections would iterate on noise (on two ranks an Ω₂ solve there failed its own residual check),
    # else after them
    initial_size = data_norm(np.asarray(initial, dtype=float), comm) if initial is not None else 0.0
    first_size = data_norm(g, comm)

    def zero_or_back(g: np.ndarray):
        """The pair at g = 0 if it glues, else the pair at g again: (T(g) or None, the last record)."""
        if zero_is_the_fixed_point(step, history, options, name=name, monitor=monitor):
            return None, history.records[-1]
        return evaluate(step, g, history, name=name, monitor=monitor)

    zero_tried = (
        rec.residual >= options.tol
        and first_size <= COLLAPSE * initial_size
        and history.iterations < options.max_iterations
    )
    if zero_tried:
        Tg, rec = zero_or_back(g)  # (glued: rec.residual < tol ends the corrections before they start)

    def residual_norm(g: np.ndarray, Tg: np.ndarray) -> float:
        return _norm(np.concatenate([a - b for a, b in zip(problem.halves(g), problem.halves(Tg))]))

    retried = False
    anderson = None  # the fallback once a line search rejects all its trials (then the rest of the solve)
    while rec.residual >= options.tol and steps_left > 0 and history.iterations < options.max_iterations:
        if anderson is not None:  # unconditional steps from the last accepted iterate on
            g = anderson(g, Tg)
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
            rec.info["update"] = "anderson"
            steps_left -= 1
            continue
        F12, F21 = (a - b for a, b in zip(problem.halves(g), problem.halves(Tg)))
        fnorm = _norm(np.concatenate([F12, F21]))
        if exact:
            D2 = om2.responses(contact=False, chunk=nopt.chunk, solver=om2.sub.solver)[0]
        else:
            D2 = problem.condensed.jacobian(om2.contact_values() > 0.0)
        d12, d21 = problem.step_direction(F12, F21, D2)
        d12, d21 = comm.bcast((d12, d21), root=0)
        steps_left -= 1
        history.newton_steps += 1
        g0, Tg0, rec0, t = g, Tg, rec, 1.0
        trials = []
        for _ in range(TRIALS if exact else 1):  # backtracking (each trial is one application of T)
            g = g0 + t * problem.data(d12, d21)
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
            trials.append((g, Tg))
            accepted = (
                rec.residual < options.tol
                or residual_norm(g, Tg) <= (1.0 - 1e-4 * t) * fnorm
                or rec.residual < 0.5 * rec0.residual
            )
            rec.info["newton_steps"] = history.newton_steps
            rec.info["step_length"] = t
            rec.info["accepted"] = accepted
            rec.info["base_residual"] = rec0.residual  # (the iterate the step starts from)
            if accepted or history.iterations >= options.max_iterations:
                break
            t *= 0.5
        log.info(
            "%s: Newton step %d (%s Jacobian), step length %g, residual %.3e%s",
            name,
            history.newton_steps,
            "exact" if exact else "condensed",
            t,
            rec.residual,
            "" if accepted else " (no trial accepted)",
        )
        if accepted or history.iterations >= options.max_iterations:
            retried = False
            continue
        if not exact:
            exact = True  # back to g0 and retry with the exact Jacobian of Ω₂ (its state back at g0)
            g = g0
            Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
            continue
        if nopt.strategy != "interface":
            # corrections after the condensed solve start at its fixed point, where ‖F‖ is round-off and no trial
            # can lower it: the next step goes on from the shortest trial (within round-off of g0; from g0 itself
            # the same step fails again on model 3 at contrast 1e6, tests/hybrid/test_friction_mpi.py)
            continue
        # the iterate stays g0: a rejected trial never becomes the next one
        g, Tg, rec = g0, Tg0, rec0
        if not retried:
            retried = True  # Ω₂'s Jacobian at the shortest trial's state (its factorization now), from g0
            continue
        # the exact Jacobian fails too: its model does not hold over any tried step (a front of the contact or
        # stick/slip state next to g0), so the same direction would fail again; Anderson from g0 instead, its
        # least squares seeded with the trials (their applications of T are secant information)
        log.info("%s: Anderson acceleration from the last accepted iterate on", name)
        anderson = AndersonUpdate(
            comm, options.depth, weights=step.data_weights() if hasattr(step, "data_weights") else None
        )
        for pair in trials:
            anderson(*pair)
    if rec is not history.records[-1] and history.iterations < options.max_iterations:
        Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)  # the subdomains' state back at g
    history.converged = bool(rec.residual < options.tol)
    if (
        not history.converged
        and not zero_tried
        and history.iterations < options.max_iterations
        and data_norm(g, comm) <= COLLAPSE * max(initial_size, first_size)
    ):
        Tg, rec = zero_or_back(g)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    log.info(
        "%s: %s, %d Newton steps, %d applications of T, transmission residual %.3e, online %.3f s "
        "(interface response offline %.3f s)",
        name,
        "converged" if history.converged else "NOT converged",
        history.newton_steps,
        history.iterations,
        rec.residual,
        history.time_s,
        history.time_offline_s,
    )
    return history
