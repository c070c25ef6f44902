"""The reused solution buffer of ``SparseFactor.solve_sparse`` and the retained C heap of ``fem.heap``."""

import ctypes
import resource

import numpy as np
import pytest
import scipy.sparse as sp

from fenics_contact.fem import heap
from fenics_contact.fem.linalg import SolveBuffer, SparseFactor


def _saddle(n: int, k: int, seed: int) -> sp.csr_matrix:
    """[[A, B], [Bᵀ, −I]] with A a shifted 1D Laplacian and B random: symmetric indefinite, like a CEM patch."""
    rng = np.random.default_rng(seed)
    A = sp.diags([-np.ones(n - 1), 2.5 * np.ones(n), -np.ones(n - 1)], [-1, 0, 1])
    B = sp.random(n, k, density=0.3, random_state=rng)
    return sp.bmat([[A, B], [B.T, -sp.identity(k)]], format="csr")


def test_solutions_in_a_reused_buffer_equal_the_fresh_ones():
    """MUMPS writes every entry of the solution into the buffer (filled with NaN before), the result is a view of
    it and equals the solve into a fresh matrix bit for bit; a larger solve after a smaller one grows it."""
    buffer = SolveBuffer()
    for n, k, seed in ((60, 6, 0), (200, 12, 1), (90, 4, 2)):
        lu = SparseFactor.from_csr(_saddle(n, k, seed), cholesky=True)
        try:
            rng = np.random.default_rng(seed)
            rhs_t = sp.random(5, n + k, density=0.05, format="csr", random_state=rng)
            rhs_t.sum_duplicates()
            fresh = lu.solve_sparse(rhs_t)
            out = buffer.get(rhs_t.shape[0] * rhs_t.shape[1])
            out[:] = np.nan
            x = lu.solve_sparse(rhs_t, out=out)
        finally:
            lu.destroy()
        assert np.shares_memory(x, buffer.array)
        assert x.shape == fresh.shape and np.array_equal(x, fresh)
    assert buffer.array.size == 5 * 212  # (the largest request)


def test_a_buffer_too_small_is_refused():
    lu = SparseFactor.from_csr(_saddle(30, 3, 0), cholesky=True)
    try:
        rhs_t = sp.csr_matrix(([1.0], ([0], [0])), shape=(2, 33))
        with pytest.raises(ValueError, match="output buffer"):
            lu.solve_sparse(rhs_t, out=np.empty(10))
    finally:
        lu.destroy()


def _faults_of_blocks(libc, size: int, count: int) -> int:
    """Minor page faults of ``count`` blocks of ``size`` bytes malloc'ed, written and freed one after the other."""
    libc.malloc.restype = ctypes.c_void_p
    libc.malloc.argtypes = [ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(count):
        p = libc.malloc(size)
        assert p
        ctypes.memset(p, 1, size)
        libc.free(p)
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before


def test_the_retained_heap_faults_a_large_block_in_once():
    """A 64 MiB block (above glibc's mmap threshold) allocated, written and freed 8 times: every time fresh pages
    outside ``retained_heap`` (a fault per page, unless huge pages), once inside; the thresholds set on leaving."""
    libc = heap._glibc()
    if libc is None:
        pytest.skip("not glibc")
    size, pages = 64 << 20, (64 << 20) // resource.getpagesize()
    outside = _faults_of_blocks(libc, size, 8)
    if outside < 4 * pages:
        pytest.skip("large blocks are not faulted in page by page here (transparent huge pages)")
    with heap.retained_heap() as applied:
        assert applied
        inside = _faults_of_blocks(libc, size, 8)
    assert inside <= 1.5 * pages  # the first block's pages, then reused
    assert _faults_of_blocks(libc, size, 8) >= 4 * pages  # (above ``AFTER``'s threshold again: mapped afresh)
