"""glibc's malloc arenas in a gateway process: how many, set once at start.

Why: glibc gives threads that contend for malloc arenas of their own, up to 8 per core. A gateway
has ~40 threads (the JVM's, uvicorn's, the fire workers, the journal), and memory one thread frees
stays free in its arena, where only that arena's threads find it again. In the soak
(docs/benchmarks.md "Soak") that free-but-kept memory was what grew: glibc's totals went from
16 to 83 MB free in ten minutes while the memory in use stayed at ~90 MB, and the JVM's native
memory, its heap's pages and Python's allocations stayed flat. Two arenas keep that free memory
where the next allocation finds it (``MALLOC_ARENA_MAX=2``, as the JVM's vendors advise for
processes with many threads).

It has to be set before threads start allocating: ``mallopt(M_ARENA_MAX)`` takes effect for
arenas made after it, so the process entry points call :func:`limit_arenas` first. The
``MALLOC_ARENA_MAX`` environment variable, read by glibc itself at start, wins when set.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import os

log = logging.getLogger(__name__)

M_ARENA_MAX = -8  # glibc's malloc.h


def limit_arenas(arena_max: int) -> bool:
    """Limit glibc's malloc arenas to ``arena_max`` (0: glibc's default, 8 per core); True when
    set. Not set when ``$MALLOC_ARENA_MAX`` already says (glibc applied it) or without glibc."""
    if arena_max <= 0 or os.environ.get("MALLOC_ARENA_MAX"):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc (musl, macOS): nothing to limit
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    if mallopt(M_ARENA_MAX, arena_max) != 1:
        log.warning("mallopt(M_ARENA_MAX, %d) refused; glibc's default arenas stay", arena_max)
        return False
    return True
