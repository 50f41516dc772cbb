"""The training run that makes the JVM's AOT class cache (see :mod:`gateway.base.jvm_cache`).

Why a run of its own: the cache holds the classes a JVM loaded and linked, and how its methods ran,
up to its exit. A gateway process rarely exits cleanly at a good moment (workers are killed, tests
end processes), and a cache made at start-up would miss the compiler and the firing paths. So
``printeps build-java`` starts this module in a child process, whose JVM records while it does what
a gateway's JVM does, then exits and writes the cache:

- compiles the shipped rule sets (``engine.rules_dir``: DRL, DSL, decision tables) from scratch
  (a private compile cache) and Drools' builder twice more (the process warm-up);
- fires each with its ``examples.json`` facts, stateless and on the JVM lane
  (:class:`gateway.engine.bulkhead.Bulkhead`), and in a stateful session on the pseudo clock
  (pushes, clock advances, a KIE-style batch);
- reasons with Pellet over the shipped ontology (``streams.knowledge_dir``).

Classes it does not reach load as they always did; the cache only saves work, it never decides what
runs.
"""

from __future__ import annotations

import asyncio
import logging
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from gateway.base import jvm, jvm_cache
from gateway.config import Settings
from gateway.engine.bulkhead import Bulkhead
from gateway.engine.engine import Engine
from gateway.engine.warmup import example_fact_sets

log = logging.getLogger(__name__)

#: Seconds the training child may take (it compiles every shipped rule set cold: 30-45 s on 2 cores).
TIMEOUT_S = 600.0


class TrainingError(RuntimeError):
    """The training run failed or did not finish; the message ends with its output's end."""


def build(settings: Settings, *, timeout_s: float = TIMEOUT_S) -> Path | None:
    """Make the AOT cache for this checkout's JVM and classpath unless it exists; returns it.

    None when this JVM takes no cache (older than Java 25, ``jvm.aot_cache`` off) or the helpers'
    jar is not there yet (start the JVM once first: ``printeps build-java`` does)."""
    jvm_lib = jvm.find_jvm_library(settings.jvm)
    classpath = jvm.planned_classpath()
    if not jvm_cache.usable(classpath, jvm.java_major(jvm_lib), enabled=settings.jvm.aot_cache):
        return None
    target = jvm_cache.cache_file(jvm_lib, classpath)
    if target.is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    partial = target.with_name(f"{target.stem}.tmp{os.getpid()}")
    env = {**os.environ, jvm_cache.TRAINING_OUTPUT_ENV: str(partial)}
    try:
        try:
            done = subprocess.run([sys.executable, "-m", "gateway.engine.jvm_training"], env=env, capture_output=True,
                                  input=settings.model_dump_json(), text=True, timeout=timeout_s)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise TrainingError(f"the JVM cache's training run did not finish: {exc}") from exc
        if done.returncode != 0 or not partial.is_file():
            raise TrainingError(f"the JVM cache's training run failed (exit {done.returncode}): "
                                f"{(done.stderr or done.stdout)[-2000:]}")
        os.replace(partial, target)
    finally:
        partial.unlink(missing_ok=True)
        Path(f"{partial}.config").unlink(missing_ok=True)
    jvm_cache.prune(target)
    return target


def train(settings: Settings) -> None:
    """What the child does (its JVM records all of it)."""
    with tempfile.TemporaryDirectory(prefix="printeps-jvm-training-") as scratch:
        settings = settings.model_copy(deep=True)
        settings.data_dir = scratch
        settings.engine.compile_cache_dir = str(Path(scratch) / "rule-units")
        jvm.start(settings.jvm)
        engine = Engine(settings)
        try:
            engine.seed(settings.engine.rules_dir)
            engine.load()
            engine.warm_up(rounds=2, fires=20, background=False)
            for name in engine.served_names():
                samples = example_fact_sets(engine.current(name).files) or [[]]
                _fire_in_a_session(engine, name, samples)
                asyncio.run(_fire_on_the_lane(engine, name, samples))
        finally:
            engine.session_manager.close_all()
        _reason(settings)


def _fire_in_a_session(engine: Engine, name: str, samples: list[list[dict]]) -> None:
    for facts in samples:  # a session each: the samples may reuse fact ids
        session = engine.session_manager.open(name, clock="pseudo", record_facts=False)
        try:
            session.push(facts)
            session.advance_clock(1_000)
            session.fire(return_facts=True)
            session.execute([{"op": "fire", "max": -1}, {"op": "get_objects"}, {"op": "advance", "ms": 500},
                             {"op": "fact_count"}])  # a KIE batch's path
        except Exception:  # a rule set's examples may not suit a session; training is best effort
            log.debug("training: the session of %s failed", name, exc_info=True)
        finally:
            session.close()


async def _fire_on_the_lane(engine: Engine, name: str, samples: list[list[dict]]) -> None:
    lane = Bulkhead(name, workers=1, max_queue=64, max_wait_s=10.0)
    for facts in samples * 5:
        try:
            await lane.fire(engine.prepare_fire(name, facts), engine.fire_timeout_ms)
        except Exception:
            log.debug("training: a lane fire of %s failed", name, exc_info=True)


def _reason(settings: Settings) -> None:
    """Pellet over the shipped ontology, with an empty data graph: ``""``, not None, which would be
    answered from the disk copy of the ontology's own inferences and never reach Pellet."""
    from gateway.ontology.knowledge import KnowledgeBase

    if not settings.streams.knowledge_dir:
        return
    knowledge = KnowledgeBase()
    knowledge.seed(settings.streams.knowledge_dir)
    knowledge.load()
    try:
        knowledge.reason("")
    except Exception:
        log.debug("training: reasoning failed", exc_info=True)


def main() -> None:  # pragma: no cover - run as a child process by build()
    logging.basicConfig(level=logging.WARNING)
    train(Settings.model_validate_json(sys.stdin.read()))  # the parent's settings, as build() was given them


if __name__ == "__main__":  # pragma: no cover
    main()
