"""glibc malloc arenas limited at process start (gateway.base.malloc), in fresh processes: the
limit only holds for arenas made after it, so it is checked where the gateway sets it, before
any thread allocates."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

from gateway.base.malloc import limit_arenas

# A fresh interpreter: limit (or not), then 12 threads each make their first allocation, which in
# glibc takes a new arena per thread until the limit; malloc_info's XML lists one <heap> per arena.
PROBE = textwrap.dedent("""
    import ctypes, re, sys, threading
    from gateway.base.malloc import limit_arenas
    print(limit_arenas(int(sys.argv[1])))
    libc = ctypes.CDLL("libc.so.6")
    libc.malloc.restype = ctypes.c_void_p
    libc.free.argtypes = [ctypes.c_void_p]
    start = threading.Barrier(12)
    held = []
    def first_allocation():
        start.wait()
        held.append(libc.malloc(4096))
    threads = [threading.Thread(target=first_allocation) for _ in range(12)]
    for t in threads: t.start()
    for t in threads: t.join()
    buf, size = ctypes.c_char_p(), ctypes.c_size_t()
    libc.open_memstream.restype = ctypes.c_void_p
    stream = libc.open_memstream(ctypes.byref(buf), ctypes.byref(size))
    libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
    libc.fclose.argtypes = [ctypes.c_void_p]
    libc.malloc_info(0, stream)
    libc.fclose(stream)
    print(len(re.findall(r'<heap nr="', buf.value.decode())))
""")


def arenas_after_threads(limit: int) -> tuple[str, int]:
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    done = subprocess.run([sys.executable, "-c", PROBE, str(limit)], capture_output=True, text=True, env=env,
                          timeout=60, check=True)
    said, arenas = done.stdout.split()
    return said, int(arenas)


def test_two_arenas_when_limited_more_without():
    assert arenas_after_threads(2) == ("True", 2)
    said, arenas = arenas_after_threads(0)  # glibc's default: a new arena per thread, up to 8 per core
    assert said == "False" and arenas > 2


def test_the_environment_wins(monkeypatch):
    """MALLOC_ARENA_MAX is applied by glibc itself at start; the setting does not override it."""
    monkeypatch.setenv("MALLOC_ARENA_MAX", "4")
    assert limit_arenas(2) is False
