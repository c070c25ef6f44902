"""Anderson acceleration of a fixed-point map g ↦ T(g) on the interface data (the hybrid iteration's update, and
the interface Newton's fallback)."""

import numpy as np
from mpi4py import MPI

from fenics_contact.errors import InputError

__all__ = ["AndersonUpdate"]


class AndersonUpdate:
    """Anderson acceleration (type II, depth m) of g ↦ T(g) with residual r = T(g) − g.

    g⁺ = g + r − (ΔG + ΔR) θ,  θ = argmin ‖r − ΔR θ‖₂ over the last m differences;
    inner products are global (allreduce), so every rank takes the same step.
    """

    name = "anderson"

    def __init__(
        self, comm: MPI.Comm, depth: int = 10, regularization: float = 1e-12, weights: np.ndarray | None = None
    ) -> None:
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
