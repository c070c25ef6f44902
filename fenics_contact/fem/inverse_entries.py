"""Entries of A⁻¹ from MUMPS' factors of A (ICNTL(30)): the block of A⁻¹ on some unknowns without back-solves.

The rows I of A⁻¹B, for a block B whose rows outside I are zero, are (A⁻¹)_II B_I.  MUMPS computes
(A⁻¹)_II from the factors it holds, pruning its forward and backward substitutions to the paths of I in the
elimination tree: the interface responses of the hybrid methods need exactly such blocks (B and the
read-out rows on γ and Γ_C).  Algorithm 1's Ω₁ response came 17× (h = 1/128) and 34× (h = 1/256) faster
than by back-solves in blocks of 128 columns, with their values to 1e-15 (the same factors): the command
and table are in benchmarks/results/interface_response.md.

MUMPS takes the requested columns in blocks of ICNTL(27) (its multi-right-hand-side blocking factor): larger blocks
run its substitutions as BLAS-3, smaller ones prune them to fewer paths.  With ``BLOCKING`` columns at a time (the
control restored after the call) Ω₁'s block on γ (514 unknowns of 123,874, model 2 with the cylinder at
h = 1/256) took 0.097–0.101 s of CPU time against 0.113–0.159 s with MUMPS' default (−32: 32 columns, chosen
automatically), J₀'s on γ and Γ_C (1,024 of 8,738) 0.10–0.13 s either way, the forces of the load path equal to
3e-15 (three alternated pairs of ``benchmarks/load_path.py --one primal --h=256 --model=2 --parts``, the child
run of the load-path table, with ``inverse_entries.BLOCKING`` set to each; a shared machine).

petsc4py has no binding of ``MatMumpsGetInverseTranspose``: it is called through ctypes, in the libpetsc
that petsc4py itself has loaded (found in the process's memory map).  Sequential factorizations only (PETSc
wants the requested entries on one process).
"""

import ctypes
import functools
import os

import numpy as np
from petsc4py import PETSc

from fenics_contact.errors import ConvergenceError

__all__ = ["BLOCKING", "available", "inverse_block"]

#: the PETSc function called through ctypes (it returns a PetscErrorCode, 0 on success)
_FUNCTION = "MatMumpsGetInverseTranspose"
#: the columns of the requested block MUMPS takes at a time (its ICNTL(27), set for the call; the module docstring)
BLOCKING = 128


@functools.cache
def _library() -> ctypes.CDLL | None:
    """The libpetsc shared library petsc4py runs on (None if it is not found or lacks the function used here)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = {line.split()[-1] for line in maps if os.path.basename(line.split()[-1]).startswith("libpetsc.so")}
    except OSError:
        return None
    for path in sorted(paths):
        lib = ctypes.CDLL(path)  # already loaded: the same instance, no second copy of PETSc
        if hasattr(lib, _FUNCTION):
            getattr(lib, _FUNCTION).restype = ctypes.c_int
            return lib
    return None


def available() -> bool:
    """Whether entries of inverses can be taken here (real double-precision PETSc, its library found)."""
    return np.dtype(PETSc.ScalarType) == np.float64 and _library() is not None


def inverse_block(
    factor: PETSc.Mat, rows: np.ndarray, *, what: str = "a matrix", sweep: np.ndarray | None = None
) -> np.ndarray:
    """(A⁻¹)[rows][:, rows], dense, in the order of ``rows`` (distinct), from the sequential MUMPS factor ``factor``
    of A (``pc.getFactorMatrix()`` of a factorized LU or Cholesky PC).  A failure raises ConvergenceError;
    ``what`` names A in messages.

    ``sweep`` (A symmetric: one value per row, e.g. the position of its node along the interface): MUMPS computes
    the entries (i, j) with sweep[i] ≥ sweep[j] only, and the block is filled by symmetry, exactly symmetric.
    Column j's backward substitution is then pruned to the paths of the rows ahead of it: about half the entries,
    a fifth of the time off Algorithm 1's responses (docs/performance.md, Algorithm 1's interface response)."""
    if not available():
        raise RuntimeError("entries of an inverse need a real double-precision PETSc whose library is found")
    if factor.getComm().getSize() != 1:
        raise ValueError("entries of an inverse are taken from a sequential factorization only")
    rows = np.asarray(rows, dtype=PETSc.IntType)
    order = np.argsort(rows)
    kept = rows[order]  # PETSc's AIJ wants sorted columns
    m, n = kept.size, factor.getSize()[0]
    if m == 0:
        return np.zeros((0, 0))
    if np.any(kept[1:] == kept[:-1]) or kept[0] < 0 or kept[-1] >= n:
        raise ValueError("the rows of an inverse block must be distinct unknowns of the matrix")
    if sweep is None:
        requested = np.ones((m, m), dtype=bool)
    else:
        rank = np.empty(m, dtype=np.int64)  # the rows' places in the sweep (ties in the order of ``kept``)
        rank[np.argsort(np.asarray(sweep)[order], kind="stable")] = np.arange(m)
        requested = rank[None, :] >= rank[:, None]  # [a, b]: A⁻¹[kept[b], kept[a]] is computed
    col, row = np.nonzero(requested)  # (row-major: the columns of each row of Bᵀ sorted)
    counts = np.zeros(n, dtype=PETSc.IntType)
    counts[kept] = requested.sum(axis=1)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(PETSc.IntType)
    indices = kept[row].astype(PETSc.IntType)
    values = np.zeros(indices.size, dtype=PETSc.ScalarType)
    # the requested entries, as the pattern of Bᵀ (n × n, row kept[a] holding the columns kept[b] requested);
    # PETSc writes (A⁻¹)ᵀ into it: Bᵀ[j, i] = A⁻¹[i, j]
    Bt = PETSc.Mat().createAIJWithArrays((n, n), (indptr, indices, values), comm=PETSc.COMM_SELF)
    Bt.assemble()
    saved = {k: factor.getMumpsIcntl(k) for k in (20, 27, 30)}  # PETSc leaves 20 and 30 set for the entries of A⁻¹
    factor.setMumpsIcntl(27, BLOCKING)
    try:
        err = getattr(_library(), _FUNCTION)(ctypes.c_void_p(factor.handle), ctypes.c_void_p(Bt.handle))
        if err != 0:
            raise ConvergenceError(f"MUMPS failed to compute entries of the inverse of {what} (PETSc error {err})")
        entries = Bt.getValuesCSR()[2]
    finally:
        for k, v in saved.items():
            factor.setMumpsIcntl(k, v)  # back to ordinary solves (and their blocking)
        Bt.destroy()
    if sweep is None:
        block = entries.reshape(m, m).T  # [a, b] = A⁻¹[kept[a], kept[b]]
    else:
        block = np.empty((m, m))
        block[row, col] = entries
        block[col, row] = entries
    if not np.all(np.isfinite(block)):
        raise ConvergenceError(f"entries of the inverse of {what} are not finite")
    back = np.argsort(order)
    return block[np.ix_(back, back)]
