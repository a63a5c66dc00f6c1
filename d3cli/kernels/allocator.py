"""Keep freed memory in the process (glibc's ``mallopt``) so that the next volume does
not fault in fresh pages.

Every pyramid level allocates its cost volume, integral images, weights and maps anew,
and every pair does it again.  glibc serves blocks above its mmap threshold (128 KB,
adapting up to 32 MB) with ``mmap`` and returns them with ``munmap``; the next block of
the same size then takes a page fault per 4 KB page, each clearing the page
(``clear_page_erms``: 10 % of the samples of the NCC kernel under ``perf``).  With the
threshold at 1 GiB and the trim threshold at 1 GiB, freed blocks stay in the heap and
are reused without faults (docs/performance.md has the measurement).  The cost: the
process keeps its peak heap instead of returning it between pairs.

Only glibc has ``mallopt``; elsewhere, or with ``D3STEREO_MALLOC=system``, or when the
user set ``MALLOC_MMAP_THRESHOLD_`` / ``MALLOC_TRIM_THRESHOLD_`` themselves, nothing is
changed.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: glibc's mallopt parameters (malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: Blocks up to this size come from the heap and are kept there when freed.
KEEP_BYTES = 1 << 30

_done: bool | None = None


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds to :data:`KEEP_BYTES` (once per process).

    Returns
    -------
    bool
        Whether the thresholds were set (False: not glibc, opted out with
        ``D3STEREO_MALLOC=system``, the user's own ``MALLOC_*`` variables, or mallopt
        refused).
    """
    global _done
    if _done is not None:
        return _done
    _done = False
    if os.environ.get("D3STEREO_MALLOC", "").lower() == "system":
        return False
    if "MALLOC_MMAP_THRESHOLD_" in os.environ or "MALLOC_TRIM_THRESHOLD_" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): keep the system's allocator as it is
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    _done = bool(mallopt(M_MMAP_THRESHOLD, KEEP_BYTES)) and bool(mallopt(M_TRIM_THRESHOLD, KEEP_BYTES))
    return _done
