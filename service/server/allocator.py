"""Allocator settings for a process that flattens large meshes.

glibc hands blocks above its mmap threshold straight back to the kernel when they are freed,
so every large numpy temporary of the next request is faulted in again as fresh zeroed pages.
Keeping large blocks in the process lets requests reuse them; on 1M-face meshes that saves
about a fifth of the validation time (docs/benchmarks.md measures both settings).

Requests run in worker threads, and glibc gives each thread its own arena, whose heaps are
capped at 64 MiB: larger blocks (a million-face answer is 74 MB of JSON) go to fresh mmaps on
every request whatever the thresholds say, which tripled the encode time. One arena for the
whole process keeps the settings above in force for every thread.

The price is that the heap stays at its high-water mark. :func:`release_free_memory` gives the
free part back to the kernel; the service calls it once a worker has been idle for a second
(:mod:`.jobs`), so a busy worker keeps its warm heap and an idle one shrinks.
"""

from __future__ import annotations

import ctypes
import ctypes.util
from functools import cache

#: mallopt parameters (glibc's malloc.h).
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_ARENA_MAX = -8
#: Blocks up to 1 GiB come from the heap, and the heap is not trimmed below 2 GiB - 1.
MMAP_THRESHOLD = 1 << 30
TRIM_THRESHOLD = (1 << 31) - 1


@cache
def _glibc():
    """The C library with glibc's malloc tuning functions, or None."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
        libc.mallopt, libc.malloc_trim  # noqa: B018 (glibc only)
    except (OSError, AttributeError, TypeError):
        return None
    return libc


def keep_large_blocks() -> bool:
    """Apply the settings above; False where the C library is not glibc.

    Call it before any worker thread allocates: a thread keeps the arena it first used.
    """
    libc = _glibc()
    if libc is None:
        return False
    mallopt = libc.mallopt
    mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
    settings = (
        (_M_ARENA_MAX, 1),
        (_M_MMAP_THRESHOLD, MMAP_THRESHOLD),
        (_M_TRIM_THRESHOLD, TRIM_THRESHOLD),
    )
    return all([bool(mallopt(parameter, value)) for parameter, value in settings])


def release_free_memory() -> bool:
    """Return the heap's free pages to the kernel (glibc's ``malloc_trim(0)``: the free top of
    the heap and whole free pages inside it); False where the C library is not glibc."""
    libc = _glibc()
    if libc is None:
        return False
    libc.malloc_trim.argtypes = [ctypes.c_size_t]
    libc.malloc_trim(0)
    return True
