"""The hybrid iteration shared by all four algorithms: a fixed-point loop g ↦ T(g).

The interface data g (Robin data g₁₂, g₂₁ on γ, stacked as one local array of
owned interface values) is the only state carried between iterations. One
application of T solves both subproblems with the current data and returns the
updated data; an *update* (plain, or Anderson acceleration) combines the
history into the next input, or the interface Newton method
(``hybrid.interface_newton``) solves g = T(g) directly.

**Stopping rule.**  The loop stops when the *transmission residual* of the
current pair of subdomain solutions (``hybrid.certificate``: the relative
displacement jump and traction imbalance on γ) is below ``tol``.  The relative
change of the iterates (the paper's rule) is still computed and
reported, but it is not evidence of a solution: a slow iteration changes little
per step far from its fixed point (α = 10⁸ stopped after 2 iterations at
e_u = 0.79 with it).
"""

import logging
import time
from collections.abc import Callable

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError
from fenics_contact.hybrid.anderson import AndersonUpdate
from fenics_contact.hybrid.interface_newton import newton_iterate
from fenics_contact.hybrid.krylov_newton import krylov_newton_iterate
from fenics_contact.hybrid.options import ACCELERATIONS, InterfaceNewtonOptions, IterationOptions, default_accel
from fenics_contact.hybrid.step import (
    COLLAPSE,
    SHRINKING_ITERATIONS,
    STALLED_RESIDUAL,
    HybridStep,
    IterationHistory,
    IterationRecord,
    IterationResult,
    data_norm,
    evaluate,
    zero_is_the_fixed_point,
)

__all__ = [
    "PlainUpdate",
    "AndersonUpdate",
    "make_update",
    "iterate",
    # iterate's options, protocol and results, defined in hybrid.options and hybrid.step (imported from here too)
    "ACCELERATIONS",
    "InterfaceNewtonOptions",
    "IterationOptions",
    "HybridStep",
    "IterationRecord",
    "IterationHistory",
    "IterationResult",
]

log = logging.getLogger(__name__)


class PlainUpdate:
    """g ← T(g): the paper's update."""

    name = "none"

    def __call__(self, g: np.ndarray, Tg: np.ndarray) -> np.ndarray:
        return Tg


def make_update(name: str, comm: MPI.Comm, *, depth: int = 10, weights: np.ndarray | None = None):
    """'none' → PlainUpdate, 'anderson' → AndersonUpdate(depth, weights of the least-squares inner product)."""
    if name == "none":
        return PlainUpdate()
    if name == "anderson":
        return AndersonUpdate(comm, depth, weights=weights)
    raise InputError(f"unknown update {name!r}; choose 'none' or 'anderson' ('newton' is run by iterate)")


def _format(info: dict) -> str:
    return "  ".join(f"{k} {v:.3e}" if isinstance(v, float) else f"{k} {v}" for k, v in info.items())


def iterate(
    step: HybridStep,
    options: IterationOptions,
    *,
    name: str = "hybrid",
    monitor: Callable[[], dict] | None = None,
    initial: np.ndarray | None = None,
) -> IterationHistory:
    """Solve g = T(g) until the transmission residual is below ``options.tol``.

    ``monitor()`` (e.g. errors against a reference) is called after every iteration, its
    entries are added to the record and its time is excluded from ``time_s``.  ``initial``
    is the first interface data (default ``step.initial_data()``, zero; a warm start for a
    sequence of solves, e.g. load steps, reusing the step and its offline data).
    """
    g = step.initial_data() if initial is None else np.array(initial, dtype=float)
    if g.shape != step.initial_data().shape:
        raise InputError(f"initial interface data have shape {g.shape}, expected {step.initial_data().shape}")
    accel = options.accel if options.accel is not None else default_accel(step, step.comm)
    if accel == "newton":
        # an Ω₁ solved iteratively (AMG) has no interface response to condense: Newton–GMRES, matrix-free
        solve = krylov_newton_iterate if getattr(step, "omega1_iterative", False) else newton_iterate
        history = solve(step, options, name=name, monitor=monitor, initial=g)
        history.accel = accel
        return history
    weights = step.data_weights() if hasattr(step, "data_weights") else None
    update = make_update(accel, step.comm, depth=options.depth, weights=weights)
    history = IterationHistory(accel=accel)
    start = time.perf_counter()
    largest = previous = data_norm(g, step.comm)
    zero_tried, shrinking = False, 0
    for k in range(1, options.max_iterations + 1):
        Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
        done = rec.residual < options.tol
        if k == 1 or k % 10 == 0 or done:
            log.info(
                "%s it %4d  residual %.3e  rel. change %.3e  %s",
                name,
                k,
                rec.residual,
                rec.rel_change,
                _format(rec.info),
            )
        if done:
            history.converged = True
            break
        size = data_norm(Tg, step.comm)
        shrinking = shrinking + 1 if size < previous and rec.residual > STALLED_RESIDUAL else 0
        previous, largest = size, max(largest, size)
        collapsed = size <= COLLAPSE * largest or shrinking >= SHRINKING_ITERATIONS
        if not zero_tried and collapsed and k < options.max_iterations:
            zero_tried = True
            if zero_is_the_fixed_point(step, history, options, name=name, monitor=monitor):
                break
        g = update(g, Tg)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    if not history.converged:
        log.warning(
            "%s: NOT converged after %d iterations (transmission residual %.3e, last change %.3e)",
            name,
            history.iterations,
            history.records[-1].residual,
            history.records[-1].rel_change,
        )
    return history
