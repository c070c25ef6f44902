"""The hybrid iteration shared by all four algorithms: a fixed-point loop g ↦ T(g).

The interface data g (Robin data g₁₂, g₂₁ on γ, stacked as one local array of
owned interface values) is the only state carried between iterations. One
application of T solves both subproblems with the current data and returns the
updated data; an *update* (plain, or Anderson acceleration) combines the
history into the next input. The loop stops by the relative-change rule of
METHOD §6 (evaluated by the step, on the subdomain solutions).
"""

import logging
import time
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import ConvergenceError, InputError

__all__ = [
    "HybridStep",
    "PlainUpdate",
    "AndersonUpdate",
    "make_update",
    "IterationOptions",
    "IterationRecord",
    "IterationHistory",
    "iterate",
    "IterationResult",
]

log = logging.getLogger(__name__)


class HybridStep(Protocol):
    """One application of the transmission map T (both subdomain solves + data update)."""

    comm: MPI.Comm

    def initial_data(self) -> np.ndarray:
        """g⁰ (zeros), as a local array of owned interface values."""

    def apply(self, g: np.ndarray) -> np.ndarray:
        """Solve both subproblems with data g and return T(g)."""

    def relative_change(self) -> float:
        """max of the relative energy and L² changes of the last two solutions."""

    def record(self) -> dict:
        """Diagnostics of the last application (Newton steps, active set, errors...)."""


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

    def __init__(self, comm: MPI.Comm, depth: int = 10, regularization: float = 1e-12) -> None:
        if depth < 1:
            raise InputError(f"Anderson depth must be >= 1, got {depth}")
        self.comm, self.depth, self.reg = comm, depth, regularization
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
        gram = self.comm.allreduce(dR.T @ dR, op=MPI.SUM)
        rhs = self.comm.allreduce(dR.T @ r, op=MPI.SUM)
        scale = np.trace(gram) / gram.shape[0] if gram.size else 1.0
        theta = np.linalg.solve(gram + self.reg * max(scale, 1e-300) * np.eye(gram.shape[0]), rhs)
        return g + r - (dG + dR) @ theta


def make_update(name: str, comm: MPI.Comm, *, depth: int = 10):
    """'none' → PlainUpdate, 'anderson' → AndersonUpdate(depth)."""
    if name == "none":
        return PlainUpdate()
    if name == "anderson":
        return AndersonUpdate(comm, depth)
    raise InputError(f"unknown update {name!r}; choose 'none' or 'anderson'")


@dataclass(frozen=True, slots=True)
class IterationOptions:
    """Stopping rule: relative change < tol (METHOD §6), at most max_iterations."""

    tol: float = 1.0e-6
    max_iterations: int = 2000
    accel: str = "anderson"
    depth: int = 10

    def __post_init__(self) -> None:
        if not (isinstance(self.tol, (int, float, np.number)) and 0 < self.tol < 1):
            raise InputError(f"the relative tolerance must lie in (0, 1), got {self.tol!r}")
        if not isinstance(self.max_iterations, (int, np.integer)) or self.max_iterations < 1:
            raise InputError(f"max_iterations must be an integer >= 1, got {self.max_iterations!r}")
        if self.accel not in ("none", "anderson"):
            raise InputError(f"unknown acceleration {self.accel!r}; choose 'none' or 'anderson'")


@dataclass(slots=True)
class IterationRecord:
    """One iteration: relative change and the step's diagnostics."""

    iteration: int
    rel_change: float
    info: dict


@dataclass(slots=True)
class IterationHistory:
    """What the loop did: records, convergence flag, and the online time."""

    records: list[IterationRecord] = field(default_factory=list)
    converged: bool = False
    time_s: float = 0.0

    @property
    def iterations(self) -> int:
        return len(self.records)

    @property
    def rel_changes(self) -> np.ndarray:
        return np.array([r.rel_change for r in self.records])


class IterationResult:
    """Mixin for result dataclasses that hold an ``IterationHistory`` as ``history``."""

    __slots__ = ()

    @property
    def converged(self) -> bool:
        return self.history.converged

    @property
    def iterations(self) -> int:
        return self.history.iterations


def _format(info: dict) -> str:
    return "  ".join(f"{k} {v:.3e}" if isinstance(v, float) else f"{k} {v}" for k, v in info.items())


def iterate(step: HybridStep, options: IterationOptions, *, name: str = "hybrid") -> IterationHistory:
    """Run g ← update(g, T(g)) until the relative change drops below ``options.tol``."""
    update = make_update(options.accel, step.comm, depth=options.depth)
    history = IterationHistory()
    g = step.initial_data()
    start = time.perf_counter()
    for k in range(1, options.max_iterations + 1):
        Tg = step.apply(g)
        change = step.relative_change()
        if not np.isfinite(change) or not step.comm.allreduce(bool(np.all(np.isfinite(Tg))), op=MPI.LAND):
            raise ConvergenceError(f"{name}: the iteration produced non-finite values at iteration {k}")
        history.records.append(IterationRecord(k, change, step.record()))
        if k == 1 or k % 10 == 0 or change < options.tol:
            log.info("%s it %4d  rel. change %.3e  %s", name, k, change, _format(history.records[-1].info))
        if change < options.tol:
            history.converged = True
            break
        g = update(g, Tg)
    history.time_s = time.perf_counter() - start
    if not history.converged:
        log.warning("%s: NOT converged after %d iterations (last change %.3e)", name, options.max_iterations,
                    history.records[-1].rel_change)
    return history
