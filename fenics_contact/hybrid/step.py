"""The hybrid step T and what one application of it leaves: its record, the history of a solve.

A ``HybridStep`` applies the transmission map T once (both subdomain solves and the data update) and
certifies the pair it computed (``hybrid.certificate``).  ``evaluate`` applies it at g, checks that the
result is finite on every rank and appends an ``IterationRecord`` to the solve's ``IterationHistory``;
``zero_is_the_fixed_point`` tests the pair at g = 0 when the iterates collapse.  The fixed-point loop
(``hybrid.iteration``) and the interface Newton (``hybrid.interface_newton``) are both made of these.
"""

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError
from fenics_contact.hybrid.certificate import Certificate, status
from fenics_contact.hybrid.options import IterationOptions

__all__ = [
    "HybridStep",
    "IterationRecord",
    "IterationHistory",
    "IterationResult",
    "evaluate",
    "COLLAPSE",
    "data_norm",
    "zero_is_the_fixed_point",
]

log = logging.getLogger(__name__)


class HybridStep(Protocol):
    """One application of the transmission map T (both subdomain solves + data update)."""

    comm: MPI.Comm

    def initial_data(self) -> np.ndarray:
        """g⁰ (zeros), as a local array of owned interface values."""

    def apply(self, g: np.ndarray, *, omega2_warm: bool = False) -> np.ndarray:
        """Solve both subproblems with data g and return T(g).

        ``omega2_warm``: Ω₂'s state was set to a candidate solution for this g (interface Newton):
        verify its residual, and run Ω₂'s Newton only if the check fails.
        """

    def relative_change(self) -> float:
        """max of the relative energy and L² changes of the last two solutions."""

    def certificate(self) -> Certificate:
        """Transmission residual of the last pair of subdomain solutions (``hybrid.certificate``)."""

    def record(self) -> dict:
        """Diagnostics of the last application (Newton steps, active set, errors...)."""

    # Optional: ``interface_problem(options)`` (the affine pieces for ``accel="newton"``, see
    # ``hybrid.condensation.InterfaceProblem``), ``data_weights()`` (weights of Anderson's least squares),
    # ``reset()`` (cold subdomain states for the next solve, offline data kept), ``omega1_iterative`` and
    # ``krylov_interface()`` (an Ω₁ solved by AMG: the matrix-free Newton–GMRES of ``hybrid.krylov_newton``).


@dataclass(slots=True)
class IterationRecord:
    """One application of T: relative change, transmission residual and the step's diagnostics."""

    iteration: int
    rel_change: float
    residual: float  #: transmission residual (``Certificate.value``) of the pair computed in this iteration
    info: dict


@dataclass(slots=True)
class IterationHistory:
    """What the loop did: records, convergence flag and times.

    ``time_s`` is the online time (excluding the reference-error monitor, ``time_monitor_s``);
    ``time_offline_s`` is the offline work done by the loop itself (the interface response of
    the Newton method), reported beside it.
    """

    records: list[IterationRecord] = field(default_factory=list)
    converged: bool = False
    accel: str = ""  #: the update that ran ("none", "anderson", "newton")
    time_s: float = 0.0
    time_offline_s: float = 0.0
    time_monitor_s: float = 0.0
    newton_steps: int = 0  #: interface Newton steps (contact Newton + corrections); 0 for the fixed-point updates
    data: np.ndarray | None = None  #: the interface data g of the final pair (``initial`` of a warm-started solve)
    #: the condensed contact Newton's history (``hybrid.contact_newton.ContactNewtonHistory``: active-set sizes,
    #: rows added / removed per step, step lengths); None for the fixed-point updates
    contact_newton: object = None
    #: the last pair's residual is above tol but at its round-off floor (``certificate.at_floor``; converged)
    at_floor: bool = False

    @property
    def floor(self) -> float:
        """The round-off floor of the final pair's transmission residual (``hybrid.certificate``; 0 before the first
        iteration)."""
        return float(self.records[-1].info.get("floor", 0.0)) if self.records else 0.0

    @property
    def status(self) -> str:
        """``certificate.status``: ``"converged"``, ``"floor"`` (at the round-off floor ``floor``) or
        ``"not converged"``."""
        return status(self.converged, self.at_floor)

    @property
    def iterations(self) -> int:
        return len(self.records)

    @property
    def rel_changes(self) -> np.ndarray:
        return np.array([r.rel_change for r in self.records])

    @property
    def residuals(self) -> np.ndarray:
        """Transmission residual per iteration."""
        return np.array([r.residual for r in self.records])

    @property
    def transmission_residual(self) -> float:
        """Transmission residual of the final pair (inf before the first iteration)."""
        return float(self.records[-1].residual) if self.records else np.inf


class IterationResult:
    """Mixin for result dataclasses that hold an ``IterationHistory`` as ``history``."""

    __slots__ = ()

    @property
    def converged(self) -> bool:
        return self.history.converged

    @property
    def iterations(self) -> int:
        return self.history.iterations

    @property
    def transmission_residual(self) -> float:
        return self.history.transmission_residual

    @property
    def floor(self) -> float:
        """The round-off floor of the final pair's transmission residual."""
        return self.history.floor

    @property
    def status(self) -> str:
        """``"converged"``, ``"floor"`` (converged at the round-off floor) or ``"not converged"``."""
        return self.history.status


def evaluate(
    step: HybridStep,
    g: np.ndarray,
    history: IterationHistory,
    *,
    name: str,
    monitor: Callable[[], dict] | None = None,
    omega2_warm: bool = False,
) -> tuple[np.ndarray, IterationRecord]:
    """Apply T once at g, certify the pair and append the record (the monitor's time is booked apart)."""
    Tg = step.apply(g, omega2_warm=omega2_warm) if omega2_warm else step.apply(g)
    history.data = np.array(g, dtype=float)
    change = step.relative_change()
    cert = step.certificate()
    finite = bool(np.all(np.isfinite(Tg))) and np.isfinite(cert.value)
    if not step.comm.allreduce(finite, op=MPI.LAND):
        raise ConvergenceError(
            f"{name}: the iteration produced non-finite values at iteration {history.iterations + 1}"
        )
    info = step.record()
    info["jump"], info["balance"], info["floor"] = cert.jump, cert.balance, cert.floor
    if monitor is not None:
        t0 = time.perf_counter()
        info.update(monitor())
        history.time_monitor_s += time.perf_counter() - t0
    record = IterationRecord(history.iterations + 1, change, cert.value, info)
    history.records.append(record)
    return Tg, record


#: the iterates have collapsed when the interface data fall below this fraction of the largest seen in the solve
COLLAPSE = 1.0e-6
#: ... or when they have shrunk at every one of this many iterations in a row while the relative transmission
#: residual stayed above ``STALLED_RESIDUAL``: the power-iteration decay towards a vanishing solution, which a
#: slow update (the plain Robin update with a small β) takes thousands of iterations to bring below ``COLLAPSE``
#: (the mixed unloading test of tests/problem/test_obstacles.py: 0.7 % per iteration)
SHRINKING_ITERATIONS = 20
STALLED_RESIDUAL = 0.5


def data_norm(g: np.ndarray, comm: MPI.Comm) -> float:
    """Euclidean norm of the interface data over the ranks (only ratios of it are used)."""
    return float(np.sqrt(comm.allreduce(float(np.dot(g, g)), op=MPI.SUM)))


def zero_is_the_fixed_point(
    step: HybridStep,
    history: IterationHistory,
    options: IterationOptions,
    *,
    name: str,
    monitor: Callable[[], dict] | None = None,
) -> bool:
    """Apply T at g = 0 and certify that pair: True (history converged) if it glues.

    The certificate is relative (``hybrid.certificate``), so iterates that decay towards a vanishing solution
    (unloading to zero data, an obstacle the body leaves) never certify: their relative jump stays O(1) while
    their size falls like a power iteration.  A zero solution is recognised instead by its own evidence: with
    g = 0 both subproblems see only the problem's data, and if they return a pair that glues (both exactly
    zero: 0/0 counts as 0, or any pair below ``tol``), g = 0 is a fixed point of T, the unique one.  The
    subproblems start cold (``reset``): warm-started from the collapsed state, Ω₂'s Newton would shrink it by
    a factor of rounding per step into subnormal numbers, whose rounding flips its active set.  Costs one
    application of T (and Ω₂'s factorization); the step's state is then that pair, the last record of ``history``.
    """
    zero = np.zeros_like(step.initial_data())
    if hasattr(step, "reset"):
        step.reset()
    _, rec = evaluate(step, zero, history, name=name, monitor=monitor)
    log.info(
        "%s: the interface data collapsed; the pair at g = 0 has transmission residual %.3e (%s)",
        name,
        rec.residual,
        "the fixed point is g = 0" if rec.residual < options.tol else "not a fixed point",
    )
    history.converged = bool(rec.residual < options.tol)
    return history.converged
