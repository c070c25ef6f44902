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
change of the iterates (METHOD §6, the paper's rule) is still computed and
reported, but it is not evidence of a solution: a slow iteration changes little
per step far from its fixed point (α = 10⁸ stopped after 2 iterations at
e_u = 0.79 with it).
"""

import logging
import time
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Protocol

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError, InputError
from fenics_contact.hybrid.certificate import Certificate

__all__ = [
    "HybridStep",
    "ACCELERATIONS",
    "InterfaceNewtonOptions",
    "PlainUpdate",
    "AndersonUpdate",
    "make_update",
    "IterationOptions",
    "IterationRecord",
    "IterationHistory",
    "iterate",
    "evaluate",
    "zero_is_the_fixed_point",
    "IterationResult",
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
    # ``reset()`` (cold subdomain states for the next solve, offline data kept).


class PlainUpdate:
    """g ← T(g): the paper's update."""

    name = "none"

    def __call__(self, g: np.ndarray, Tg: np.ndarray) -> np.ndarray:
        return Tg


class AndersonUpdate:
    """Anderson acceleration (type II, depth m) of g ↦ T(g) with residual r = T(g) − g.

    g⁺ = g + r − (ΔG + ΔR) θ,  θ = argmin ‖r − ΔR θ‖₂ over the last m differences;
    inner products are global (allreduce), so every rank takes the same step.
    """

    name = "anderson"

    def __init__(self, comm: MPI.Comm, depth: int = 10, regularization: float = 1e-12,
                 weights: np.ndarray | None = None) -> None:
        if depth < 1:
            raise InputError(f"Anderson depth must be >= 1, got {depth}")
        self.comm, self.depth, self.reg = comm, depth, regularization
        self.w = weights
        self._g: list[np.ndarray] = []
        self._r: list[np.ndarray] = []

    def __call__(self, g: np.ndarray, Tg: np.ndarray) -> np.ndarray:
        r = Tg - g
        self._g.append(g.copy())
        self._r.append(r.copy())
        if len(self._g) > self.depth + 1:
            self._g.pop(0)
            self._r.pop(0)
        if len(self._g) == 1:
            return Tg
        dG = np.stack([b - a for a, b in zip(self._g[:-1], self._g[1:])], axis=1)
        dR = np.stack([b - a for a, b in zip(self._r[:-1], self._r[1:])], axis=1)
        wdR = dR if self.w is None else self.w[:, None] * dR
        gram = self.comm.allreduce(wdR.T @ dR, op=MPI.SUM)
        rhs = self.comm.allreduce(wdR.T @ r, op=MPI.SUM)
        scale = np.trace(gram) / gram.shape[0] if gram.size else 1.0
        theta = np.linalg.solve(gram + self.reg * max(scale, 1e-300) * np.eye(gram.shape[0]), rhs)
        return g + r - (dG + dR) @ theta


#: The updates of the interface data: the paper's plain update, Anderson acceleration, interface Newton.
ACCELERATIONS = ("none", "anderson", "newton")


def make_update(name: str, comm: MPI.Comm, *, depth: int = 10, weights: np.ndarray | None = None):
    """'none' → PlainUpdate, 'anderson' → AndersonUpdate(depth, weights of the least-squares inner product)."""
    if name == "none":
        return PlainUpdate()
    if name == "anderson":
        return AndersonUpdate(comm, depth, weights=weights)
    raise InputError(f"unknown update {name!r}; choose 'none' or 'anderson' ('newton' is run by iterate)")


@dataclass(frozen=True, slots=True)
class InterfaceNewtonOptions:
    """Interface Newton (``hybrid.interface_newton``): strategy and step caps.

    ``strategy``: ``"condensed"`` (Ω₁'s affine interface response and the contact-free Ω₂
    condensed offline onto γ and Γ_C; online a semismooth Newton on the Γ_C unknowns, then one
    application of T to certify) or ``"interface"`` (Newton on F(g) = g − T(g), Ω₂'s generalized
    Jacobian by back-solves with its current factorization at every step).
    ``max_steps`` caps the contact Newton, ``max_corrections`` the Newton steps on F(g) that
    follow it (or, for ``"interface"``, all steps).  ``front_window`` (default 8; 0: off): the condensed
    contact Newton resolves every front of its next active set locally, on the ``front_window`` Γ_C
    unknowns on either side of it with the forces elsewhere held (``hybrid.fronts.LocalFronts``; the same
    fixed point; 3–5 steps instead of 8–11 where a near-rigid body rests on Γ_C at contrast 1e6: README,
    "Interface Newton").  ``fronts=True``: instead, the front extrapolation of an earlier version
    (``hybrid.fronts.FrontExtrapolation``; fewer steps on some cases, more on others).
    """

    strategy: str = "condensed"
    max_steps: int = 50
    max_corrections: int = 8
    chunk: int = 128  #: right-hand sides per multi-RHS back-solve of the offline condensation
    fronts: bool = False
    front_window: int = 8

    def __post_init__(self) -> None:
        if isinstance(self.front_window, bool) or not isinstance(self.front_window, (int, np.integer)) \
                or self.front_window < 0:
            raise InputError(f"interface Newton: front_window must be an integer >= 0 (0: off), got "
                             f"{self.front_window!r}")
        if self.strategy not in ("condensed", "interface"):
            raise InputError(f"unknown interface Newton strategy {self.strategy!r}; choose 'condensed' or 'interface'")
        if self.max_steps < 1 or self.max_corrections < 0 or self.chunk < 1:
            raise InputError("interface Newton: max_steps and chunk must be >= 1, max_corrections >= 0")


@dataclass(frozen=True, slots=True)
class IterationOptions:
    """Stopping rule: transmission residual < tol (``hybrid.certificate``), at most max_iterations.

    ``accel`` is the update: ``"none"`` (the paper's), ``"anderson"`` (depth ``depth``) or
    ``"newton"`` (``hybrid.interface_newton``, options ``newton``).
    """

    tol: float = 1.0e-6
    max_iterations: int = 2000
    accel: str = "anderson"
    depth: int = 10
    newton: InterfaceNewtonOptions = InterfaceNewtonOptions()

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float, np.number)) and 0 < self.tol < 1):
            raise InputError(f"the relative tolerance must lie in (0, 1), got {self.tol!r}")
        if not isinstance(self.max_iterations, (int, np.integer)) or self.max_iterations < 1:
            raise InputError(f"max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if self.accel not in ACCELERATIONS:
            raise InputError(f"unknown acceleration {self.accel!r}; choose one of {', '.join(ACCELERATIONS)}")
        if not isinstance(self.depth, (int, np.integer)) or self.depth < 1:
            raise InputError(f"the Anderson depth must be an integer >= 1, got {self.depth!r}")


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
    time_s: float = 0.0
    time_offline_s: float = 0.0
    time_monitor_s: float = 0.0
    newton_steps: int = 0  #: interface Newton steps (contact Newton + corrections); 0 for the fixed-point updates
    data: np.ndarray | None = None  #: the interface data g of the final pair (``initial`` of a warm-started solve)
    #: the condensed contact Newton's history (``hybrid.contact_newton.ContactNewtonHistory``: active-set sizes,
    #: rows added / removed per step, step lengths); None for the fixed-point updates
    contact_newton: object = None

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


def _format(info: dict) -> str:
    return "  ".join(f"{k} {v:.3e}" if isinstance(v, float) else f"{k} {v}" for k, v in info.items())


def evaluate(step: HybridStep, g: np.ndarray, history: IterationHistory, *, name: str,
             monitor: Callable[[], dict] | None = None, omega2_warm: bool = False) -> tuple[np.ndarray, IterationRecord]:
    """Apply T once at g, certify the pair and append the record (the monitor's time is booked apart)."""
    Tg = step.apply(g, omega2_warm=omega2_warm) if omega2_warm else step.apply(g)
    history.data = np.array(g, dtype=float)
    change = step.relative_change()
    cert = step.certificate()
    finite = bool(np.all(np.isfinite(Tg))) and np.isfinite(cert.value)
    if not step.comm.allreduce(finite, op=MPI.LAND):
        raise ConvergenceError(f"{name}: the iteration produced non-finite values at iteration {history.iterations + 1}")
    info = step.record()
    info["jump"], info["balance"] = cert.jump, cert.balance
    if monitor is not None:
        t0 = time.perf_counter()
        info.update(monitor())
        history.time_monitor_s += time.perf_counter() - t0
    record = IterationRecord(history.iterations + 1, change, cert.value, info)
    history.records.append(record)
    return Tg, record


#: the iterates have collapsed when the interface data fall below this fraction of the largest seen in the solve
COLLAPSE = 1.0e-6


def data_norm(g: np.ndarray, comm: MPI.Comm) -> float:
    """Euclidean norm of the interface data over the ranks (only ratios of it are used)."""
    return float(np.sqrt(comm.allreduce(float(np.dot(g, g)), op=MPI.SUM)))


def zero_is_the_fixed_point(step: HybridStep, history: IterationHistory, options: IterationOptions, *,
                            name: str, monitor: Callable[[], dict] | None = None) -> bool:
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
    log.info("%s: the interface data collapsed; the pair at g = 0 has transmission residual %.3e (%s)", name,
             rec.residual, "the fixed point is g = 0" if rec.residual < options.tol else "not a fixed point")
    history.converged = bool(rec.residual < options.tol)
    return history.converged


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
    if options.accel == "newton":
        from fenics_contact.hybrid.interface_newton import newton_iterate

        return newton_iterate(step, options, name=name, monitor=monitor, initial=g)
    weights = step.data_weights() if hasattr(step, "data_weights") else None
    update = make_update(options.accel, step.comm, depth=options.depth, weights=weights)
    history = IterationHistory()
    start = time.perf_counter()
    largest = data_norm(g, step.comm)
    zero_tried = False
    for k in range(1, options.max_iterations + 1):
        Tg, rec = evaluate(step, g, history, name=name, monitor=monitor)
        done = rec.residual < options.tol
        if k == 1 or k % 10 == 0 or done:
            log.info("%s it %4d  residual %.3e  rel. change %.3e  %s", name, k, rec.residual, rec.rel_change,
                     _format(rec.info))
        if done:
            history.converged = True
            break
        size = data_norm(Tg, step.comm)
        largest = max(largest, size)
        if not zero_tried and size <= COLLAPSE * largest and k < options.max_iterations:
            zero_tried = True
            if zero_is_the_fixed_point(step, history, options, name=name, monitor=monitor):
                break
        g = update(g, Tg)
    history.time_s = time.perf_counter() - start - history.time_monitor_s
    if not history.converged:
        log.warning("%s: NOT converged after %d iterations (transmission residual %.3e, last change %.3e)", name,
                    history.iterations, history.records[-1].residual, history.records[-1].rel_change)
    return history
