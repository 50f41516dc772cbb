"""The JVM's ahead-of-time class cache: which file, when a JVM uses it, and how a training run asks for one.

Why: every gateway process starts a JVM that loads ~9,000 classes (Drools' compiler and engine, the
Eclipse compiler, Pellet and the OWL API) from jars, verifies and links each one, and runs them
interpreted until the JIT catches up. JDK 25's AOT cache (JEPs 483, 514, 515) keeps all of that from a
training run in one file that the next JVMs map instead. Measured on the 2-core target, a process that
starts the JVM, compiles one rule and fires it: 6.4 CPU-s without the cache, 4.2-4.6 with it. What
it saves is loading and compiling: a process that deploys (every test process, an author's first
edit after a restart) gains; one whose rule units are all cached starts about as before.

Safety: a cache is valid only for the JVM that wrote it and the exact classpath (the JVM checks each
jar's size and time and quietly starts without the cache on any difference). Its file name is a
digest of both, so a new Java, a changed jar or new Java helpers mean another name: no cache (a start
as before), never a wrong one. Classes in a directory cannot be cached, which is why the Java helpers
go on the classpath as a jar once compiled (:mod:`gateway.base.jvm`).

Who makes it: ``printeps build-java`` (``make install`` runs it) starts a training process that
compiles and fires the shipped rule sets and reasons with Pellet (:mod:`gateway.engine.jvm_training`);
its JVM writes the cache as it exits (``-XX:AOTCacheOutput``, which starts ``java`` once more to
assemble it).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

#: The first JDK with ``-XX:AOTCacheOutput`` (JEP 514). Older JVMs (a system JDK 17) start without.
MIN_JAVA = 25
#: Set by the training run for its child: the JVM records into this file instead of using a cache.
TRAINING_OUTPUT_ENV = "PRINTEPS_JVM_AOT_OUTPUT"
#: Caches kept in the folder (newest first): other checkouts and virtualenvs on the host have their
#: own classpaths, hence their own caches; older ones are left from earlier installs.
KEEP = 4
#: Part of the name: a change in what the training run does makes a new cache.
FORMAT = "1"


def cache_dir() -> Path:
    """Where the caches live: ``$PRINTEPS_CACHE_DIR/jvm-aot`` (default ``~/.cache/printeps``)."""
    return Path(os.environ.get("PRINTEPS_CACHE_DIR", Path.home() / ".cache" / "printeps")) / "jvm-aot"


def cache_file(jvm_lib: str, classpath: list[str]) -> Path:
    """The cache for this JVM and classpath (it may not exist)."""
    digest = hashlib.sha256(FORMAT.encode())
    for part in (jvm_lib, _release(jvm_lib), _jpype_version(), *map(_entry, classpath)):
        digest.update(part.encode("utf-8"))
        digest.update(b"\0")
    return cache_dir() / f"{digest.hexdigest()[:24]}.aot"


def options(jvm_lib: str, classpath: list[str], java_major: int, *, enabled: bool) -> tuple[list[str], Path | None]:
    """The JVM options for the cache, and the cache used (None: none).

    A training run (``$PRINTEPS_JVM_AOT_OUTPUT``) records into that file; otherwise the JVM uses the
    cache that matches, if one was made. Nothing when disabled (``jvm.aot_cache``), on a JVM older
    than :data:`MIN_JAVA`, or with a directory on the classpath (the first start, before the Java
    helpers' jar exists: a cache made then would never match again)."""
    if not usable(classpath, java_major, enabled=enabled):
        return [], None
    output = os.environ.get(TRAINING_OUTPUT_ENV)
    if output:
        return [f"-XX:AOTCacheOutput={output}"], None
    cache = cache_file(jvm_lib, classpath)
    if not cache.is_file():
        return [], None
    return [f"-XX:AOTCache={cache}"], cache


def usable(classpath: list[str], java_major: int, *, enabled: bool) -> bool:
    """Whether a JVM of ``java_major`` with ``classpath`` can take (or make) a cache."""
    return enabled and java_major >= MIN_JAVA and not any(os.path.isdir(entry) for entry in classpath)


def prune(keep: Path) -> None:
    """Remove all but the :data:`KEEP` newest caches (``keep`` always stays)."""
    caches = sorted(cache_dir().glob("*.aot"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in [p for p in caches if p != keep][KEEP - 1:]:
        old.unlink(missing_ok=True)


def _entry(path: str) -> str:
    try:
        stat = os.stat(path)
    except OSError:
        return f"{path}|missing"
    return f"{path}|{stat.st_size}|{stat.st_mtime_ns}"


def _release(jvm_lib: str) -> str:
    """The Java home's ``release`` file (the exact build), or '' if there is none."""
    try:
        return (Path(jvm_lib).parents[2] / "release").read_text(encoding="utf-8", errors="replace")
    except (OSError, IndexError):
        return ""


def _jpype_version() -> str:
    """JPype puts its own jar at the end of the classpath: another JPype, another cache."""
    import jpype

    return str(getattr(jpype, "__version__", ""))
