"""hg2prism.memory: glibc's mmap threshold and trimming, which change no result."""

from __future__ import annotations

import numpy as np

from hg2prism import memory


def test_release_and_trim_keep_arrays_intact() -> None:
    """Both are safe to call any time (no-ops without glibc); large arrays allocated and freed
    around them keep their contents."""
    memory.release_large_arrays()
    kept = np.arange(2 * memory.LARGE // 8, dtype=np.int64)      # above the threshold
    freed = np.ones(3 * memory.LARGE // 8)
    del freed
    memory.trim()
    assert kept[-1] == len(kept) - 1 and int(kept.sum()) == len(kept) * (len(kept) - 1) // 2
