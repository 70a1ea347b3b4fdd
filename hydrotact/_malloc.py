"""Keep freed memory in the process's heap (glibc), so that XLA's per-call working
memory is not page-faulted in again on every call.

XLA's CPU runtime allocates each call's temporaries with malloc. glibc serves blocks
above its mmap threshold (at most 32 MB) as fresh pages and returns them to the system
when freed, so every call of a jitted kernel touches its working memory for the first
time: the contact kernel's 16-pose groups ran 1.7x slower for it, 64-pose batches
1.2-1.3x (benchmarks/RESULTS.md, issue 48). With mmap off for allocations and the heap
never trimmed, freed blocks are reused warm. The cost: the process keeps its peak
memory until it exits, as a GPU client keeps its preallocated pool.

Set HYDROTACT_MALLOC=system in the environment to leave the C library as it is. A no-op
outside glibc (macOS, musl) and where malloc was already replaced.
"""

import ctypes
import ctypes.util
import os

# mallopt's parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
_NEVER = 2**31 - 1  # mallopt takes an int


def keep_freed_memory() -> bool:
    """Tell glibc's malloc to serve every block from the heap and never shrink it
    (idempotent). **Returns:** whether glibc's mallopt accepted both settings (it also
    does where another malloc was preloaded, which then ignores them)."""
    if os.environ.get("HYDROTACT_MALLOC", "").lower() == "system":
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return False
    if not (hasattr(libc, "gnu_get_libc_version") and hasattr(libc, "mallopt")):  # glibc only
        return False
    mallopt = libc.mallopt
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, _NEVER))
