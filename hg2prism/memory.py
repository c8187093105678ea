"""The process's memory: large arrays given back to the system when they are freed.

glibc serves an allocation above its mmap threshold by a mapping of its own, unmapped on free;
below it, from the heap, which keeps freed memory. The threshold starts at 128 KB and grows
to the largest block freed (up to 32 MB), so after the first large numpy temporaries the
pipeline's arrays of a few MB stay in the heap when freed, and the heap's free holes add up
over the stages (Storm's model, its arrays in Python, the canonical MDP, the exports). A fixed
threshold of LARGE keeps every array of LARGE or more in its own mapping (measured on the
benchmark's s16 w3 world, 265k states: peak 1039 -> 779 MB), and `trim` gives the heap's free
memory back between stages. Elsewhere than glibc both do nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

LARGE = 4 << 20            # bytes: allocations of this size or more get their own mapping
M_MMAP_THRESHOLD = -3      # mallopt's parameter (malloc.h)


@functools.cache
def _libc() -> ctypes.CDLL | None:
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        libc.mallopt, libc.malloc_trim     # glibc only
    except (OSError, AttributeError):
        return None
    return libc


def release_large_arrays() -> None:
    """Fix the mmap threshold at LARGE (module docstring): for a process about to run the
    pipeline on a large world (the command line, each benchmark world)."""
    libc = _libc()
    if libc is not None:
        libc.mallopt(M_MMAP_THRESHOLD, LARGE)


def trim() -> None:
    """Give the heap's free memory back to the system (between stages that free a lot)."""
    libc = _libc()
    if libc is not None:
        libc.malloc_trim(0)
