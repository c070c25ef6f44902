"""The C heap kept for reuse while a phase allocates and frees large work arrays (``retained_heap``, glibc only).

glibc serves an allocation above its mmap threshold (at most 32 MiB by default) with fresh pages from the kernel
and gives them back when it is freed, so a phase that allocates such an array again and again pays a page fault
and a zero fill per 4 KiB every time.  MUMPS does so: each factorization allocates its work array afresh (the
fronts, zeroed as they are assembled) and frees it at the next analysis or at the end, and PETSc gives no way to
hand it a reused one (MUMPS' WK_USER).  Inside ``retained_heap`` large blocks come from the heap and freed ones
stay there for the next allocation; on leaving, the thresholds are set to the values glibc's dynamic thresholds
reach (``AFTER``) and the free pages are given back (``malloc_trim``).
"""

import contextlib
import ctypes
import logging
from collections.abc import Iterator

__all__ = ["AFTER", "retained_heap"]

log = logging.getLogger(__name__)

#: mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
#: the mmap and trim thresholds set on leaving: glibc's largest dynamic mmap threshold (DEFAULT_MMAP_THRESHOLD_MAX
#: on 64-bit) and twice it, the values its dynamic thresholds settle at once such a block has been freed
AFTER = {_M_MMAP_THRESHOLD: 32 << 20, _M_TRIM_THRESHOLD: 64 << 20}
#: the thresholds inside (mallopt takes an int): no block below 2 GiB mapped, no free memory trimmed
_INSIDE = {_M_MMAP_THRESHOLD: 2**31 - 1, _M_TRIM_THRESHOLD: 2**31 - 1}


def _glibc() -> ctypes.CDLL | None:
    """The process's C library when it is glibc (mallopt and malloc_trim), else None."""
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # noqa: B018 (glibc only)
        libc.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        libc.malloc_trim.argtypes = [ctypes.c_size_t]
    except (OSError, AttributeError):
        return None
    return libc


_LIBC = _glibc()


def _set(libc: ctypes.CDLL, values: dict) -> bool:
    return all(libc.mallopt(key, value) == 1 for key, value in values.items())


@contextlib.contextmanager
def retained_heap() -> Iterator[bool]:
    """Within: large blocks from glibc's heap and freed ones kept there (yields whether it applies: glibc)."""
    if _LIBC is None:
        yield False
        return
    applied = _set(_LIBC, _INSIDE)
    try:
        yield applied
    finally:
        if applied:
            _set(_LIBC, AFTER)
            _LIBC.malloc_trim(0)
