"""The gateway on generated rule sets of growing size (bench/peers/growth_rules.py), through its
public API. One measurement per process (the orchestrator, bench/growth_bench.py, starts them).

Usage (project venv): .venv/bin/python bench/peers/growth_gateway_peer.py MODE N CACHE_DIR [ARCHIVE]
  build N     cold: JVM start, first deploy of N rules (incremental, empty unit cache), then five
              one-rule redeploys (each live = compiled, assembled, warmed, swapped), the first fire
              after each, fire latency of 5-fact requests, RSS; writes the compiled set to ARCHIVE
  whole N     the same through the non-incremental path (the whole set compiled every time)
  restart N   a fresh process deploys the same N rules again: assembled from the disk unit cache
  load N      a fresh process loads ARCHIVE (export_compiled's bytes) instead of compiling
"""

from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from common import Clock, emit, rss_mb

# GROWTH_GENERATOR=business: the second, independent generator (business_rules.py, seeded by
# GROWTH_SEED) instead of growth_rules.py; everything else measures the same way.
# GROWTH_DOMAINS=fixed: its key domains do not grow with the base (the bases measured before
# 2026-11-27 14:30 UTC: 744 firings per request at 10,000 rules instead of ~74).
GENERATOR = os.environ.get("GROWTH_GENERATOR", "growth")
SEED = int(os.environ.get("GROWTH_SEED", "1"))
SCALE_DOMAINS = os.environ.get("GROWTH_DOMAINS", "scaled") != "fixed"

if GENERATOR == "business":
    from business_rules import BusinessRules

    def _base(n: int, variants: dict[int, int] | None = None) -> BusinessRules:
        return BusinessRules(SEED, n, variants=variants or {}, scale_domains=SCALE_DOMAINS)

    def drl_files(n: int, variants: dict[int, int] | None = None) -> dict[str, str]:
        return _base(n, variants).drl_files()

    def sample_facts(k: int, n: int) -> list[dict]:
        return _base(n).facts(k, applicants=2, loans=3)  # 5 facts, as the first generator's

    def expected_firings(n: int, facts: list[dict], variants: dict[int, int] | None = None) -> dict[str, int]:
        return {r: len(t) for r, t in _base(n, variants).expected(facts).items()}
else:
    from growth_rules import drl_files as _drl_files
    from growth_rules import expected_firings
    from growth_rules import sample_facts as _sample_facts

    def drl_files(n: int, variants: dict[int, int] | None = None) -> dict[str, str]:
        return _drl_files(n, variants, examples=True)  # a rule set with examples, as authors write them

    def sample_facts(k: int, n: int) -> list[dict]:
        return _sample_facts(k)  # the same facts at every size

# GROWTH_REQUEST_JOINS=auto|always|never: engine.compile_request_joins (issue 30: one-shot fires of
# all-plain sets read joined facts from the request; auto uses it where facts fan out widely, as
# they do at 10,000 business rules)
REQUEST_JOINS = os.environ.get("GROWTH_REQUEST_JOINS", "auto")

EDITS = 5
# fewer on a loaded machine (GROWTH_WARM_FIRES / GROWTH_REQUESTS): a 10,000-rule business request
# fires ~750 rules, 5,000 of them take half an hour at load 30; the results record the count
WARM_FIRES = int(os.environ.get("GROWTH_WARM_FIRES", "2000"))
REQUESTS = int(os.environ.get("GROWTH_REQUESTS", "5000"))


def percentile(samples: list[float], q: float) -> float:
    ordered = sorted(samples)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def new_engine(cache_dir: str, incremental: bool = True):
    from gateway.config import Settings
    from gateway.engine import Engine

    data = tempfile.mkdtemp(prefix="printeps-growth-")
    return Engine(Settings(data_dir=data, engine={
        "rules_dir": str(Path(data) / "none"), "compile_cache_dir": cache_dir, "compile_incremental": incremental,
        "compile_timeout_s": 3600, "compile_request_joins": REQUEST_JOINS}))


def start_jvm() -> float:
    from gateway.base import jvm

    with Clock() as clock:
        jvm.start()
    return clock.seconds


def _compiled(files):
    """The compiled set of ``files`` in the process's compile cache (None if not there)."""
    from gateway.engine import compiler
    from gateway.engine.ruleset import content_hash

    return compiler._cache.get(content_hash(files))


def deploy(engine, files) -> dict:
    with Clock() as clock:
        engine.deploy("growth", files)
    compiled = _compiled(files)
    stats = compiled.stats.to_dict() if compiled is not None and compiled.stats is not None else {}
    return {"seconds": clock.seconds, "stats": stats}


def fire_latency(engine, n: int, variants: dict[int, int] | None = None) -> dict:
    """Engine.fire of 5 facts (the default answer: actions, fired rules with their facts, facts);
    checked against the model of the live set (``variants``: the last redeploy's edit)."""
    facts = [sample_facts(k, n) for k in range(50)]
    for k in range(WARM_FIRES):
        engine.fire("growth", facts[k % 50])
    samples = []
    cpu = time.thread_time()  # the calling thread's CPU (JPype runs the Java work on it): what load does not inflate
    for k in range(REQUESTS):
        t = time.perf_counter()
        engine.fire("growth", facts[k % 50])
        samples.append((time.perf_counter() - t) * 1000)
    cpu_ms = (time.thread_time() - cpu) * 1000 / REQUESTS
    correct = all(_counts(engine.fire("growth", facts[k])) == expected_firings(n, facts[k], variants) for k in range(10))
    firings = statistics.fmean(len(engine.fire("growth", f).fired) for f in facts)
    return {"p50_ms": percentile(samples, 0.5), "p99_ms": percentile(samples, 0.99), "mean_ms": statistics.fmean(samples),
            "max_ms": max(samples), "cpu_ms_per_request": cpu_ms, "load": os.getloadavg()[0], "correct": correct, "firings_per_request": firings, "requests": REQUESTS}


def _warm_stats(files) -> dict:
    """How the live version was warmed before the swap (fires, seconds, first and last ms)."""
    stats = getattr(_compiled(files), "warm_stats", None)
    return dict(stats.__dict__) if stats is not None else {}


def _reads_joins(files) -> bool:
    """Whether the live version's one-shot fires use a request-join network (GROWTH_REQUEST_JOINS)."""
    return bool(_compiled(files).runner.readsJoinsFromRequest())


def _counts(result) -> dict[str, int]:
    out: dict[str, int] = {}
    for fired in result.fired:
        out[fired["rule"]] = out.get(fired["rule"], 0) + 1
    return out


def redeploys(engine, n: int, edits: int = EDITS) -> dict:
    """One-rule edits, each deployed and then fired once (the first request after the swap)."""
    out = {"seconds": [], "first_fire_ms": [], "first_fire_wall_ms": [], "rules_compiled": [], "stats": []}
    for k in range(edits):
        rule = (n * (2 * k + 1)) // (2 * edits)  # spread over the files
        files = drl_files(n, {rule: k + 1})
        done = deploy(engine, files)
        cpu = time.thread_time()
        with Clock() as wall:
            result = engine.fire("growth", sample_facts(k, n))
        out.setdefault("first_fire_cpu_ms", []).append((time.thread_time() - cpu) * 1000)
        out.setdefault("warm", []).append(_warm_stats(files))
        out["seconds"].append(done["seconds"])
        out["rules_compiled"].append(done["stats"].get("rules_compiled"))
        out["stats"].append(done["stats"])
        out["first_fire_ms"].append(result.duration_ms)
        out["first_fire_wall_ms"].append(wall.seconds * 1000)
    out["live_variants"] = {rule: edits} if edits else {}  # the set now live: the last edit only
    out["median_s"] = statistics.median(out["seconds"])
    out["first_fire_median_ms"] = statistics.median(out["first_fire_ms"])
    return out


def build(n: int, cache_dir: str, archive: str | None, incremental: bool = True) -> None:
    jvm_s = start_jvm()
    engine = new_engine(cache_dir, incremental)
    files = drl_files(n)
    first = deploy(engine, files)
    with Clock() as wall:
        result = engine.fire("growth", sample_facts(0, n))
    first_fire = {"engine_ms": result.duration_ms, "wall_ms": wall.seconds * 1000, "warm": _warm_stats(files),
                  "reads_joins_from_request": _reads_joins(files),
                  "routed_patterns": int(_compiled(files).runner.routedPatterns())}
    out = {"peer": "gateway", "generator": GENERATOR, "mode": "incremental" if incremental else "whole", "rules": n,
           "request_joins": REQUEST_JOINS,
           "jvm_start_s": jvm_s,
           "cold_deploy": first, "first_fire_after_cold_deploy": first_fire}
    if archive and incremental:
        from gateway.engine.artifacts import export_compiled

        with Clock() as exported:
            data = export_compiled(_compiled(files))
        Path(archive).write_bytes(data)
        out["export"] = {"seconds": exported.seconds, "bytes": len(data)}
    # the whole path recompiles everything per edit: at 10,000 rules one edit tells enough
    out["redeploy"] = redeploys(engine, n, EDITS if incremental or n < 10_000 else 1)
    out["fire"] = fire_latency(engine, n, out["redeploy"]["live_variants"])
    from gateway.base import jvm

    runtime = jvm.jclass("java.lang.Runtime").getRuntime()
    jvm.jclass("java.lang.System").gc()
    out["heap_used_mb"] = (int(runtime.totalMemory()) - int(runtime.freeMemory())) / 2**20
    out["heap_max_mb"] = int(runtime.maxMemory()) / 2**20
    peak = rss_mb()  # before the split below parses the set once more
    from gateway.engine import compiler

    out["plain_split"] = dict(compiler.plain_split(files))  # why the rules not built plain are compiled
    emit({**out, **peak})


def restart(n: int, cache_dir: str) -> None:
    """A gateway restarting with the set in the disk cache: deploy = assemble from cached units."""
    jvm_s = start_jvm()
    engine = new_engine(cache_dir)
    done = deploy(engine, drl_files(n))
    result = engine.fire("growth", sample_facts(0, n))
    emit({"peer": "gateway", "mode": "restart", "rules": n, "jvm_start_s": jvm_s, "deploy": done,
          "first_fire_ms": result.duration_ms, **rss_mb()})


def load(n: int, cache_dir: str, archive: str) -> None:
    """Another process given the exported bytes: load_compiled, no compiling."""
    from gateway.engine.artifacts import load_compiled
    from gateway.engine.build import CompileOptions

    jvm_s = start_jvm()
    data = Path(archive).read_bytes()
    with Clock() as clock:
        compiled = load_compiled(data, drl_files(n), CompileOptions(cache_dir=cache_dir))
    ok = compiled.rule_count == n
    emit({"peer": "gateway", "mode": "load", "rules": n, "jvm_start_s": jvm_s, "load_s": clock.seconds,
          "stats": compiled.stats.to_dict(), "correct": ok, **rss_mb()})


if __name__ == "__main__":
    mode, n, cache = sys.argv[1], int(sys.argv[2]), sys.argv[3]
    arg = sys.argv[4] if len(sys.argv) > 4 else None
    if mode == "build":
        build(n, cache, arg)
    elif mode == "whole":
        build(n, cache, None, incremental=False)
    elif mode == "restart":
        restart(n, cache)
    elif mode == "load":
        load(n, cache, arg)
    else:
        raise SystemExit(__doc__)
