"""The queue of explainers built in advance (no JVM: the build itself is replaced by a recorder
that can be held, so the test controls when each build ends): one pending build per rule set,
the newest text wins, at most the cache's size pending, and closing drops what waits."""

from __future__ import annotations

import threading

from gateway.engine import explain
from gw_testing import wait_for


class HeldBuilds:
    """Stands in for :func:`explain.build`: records the texts built and holds each until released."""

    def __init__(self) -> None:
        self.built: list[str] = []
        self.started = threading.Event()
        self.release = threading.Event()

    def __call__(self, _engine, files):
        self.started.set()
        self.release.wait(30)
        self.built.append(files["r.drl"])
        return explain.Explainer([], None, None)


def test_the_newest_text_of_each_rule_set_is_built_and_the_queue_is_bounded(monkeypatch):
    builds = HeldBuilds()
    monkeypatch.setattr(explain, "build", builds)
    monkeypatch.setattr(explain, "explain", lambda *_args: {})
    cache = explain.ExplainCache(size=2)
    try:
        cache.prebuild(None, "a", {"r.drl": "a1"})
        assert builds.started.wait(30)  # a1 is being built: what comes now waits
        cache.prebuild(None, "b", {"r.drl": "b1"})
        cache.prebuild(None, "b", {"r.drl": "b2"})  # replaces b1, not yet started
        cache.prebuild(None, "c", {"r.drl": "c1"})
        cache.prebuild(None, "d", {"r.drl": "d1"})  # three rule sets pending, two kept: b (oldest) dropped
        builds.release.set()
        assert wait_for(lambda: builds.built == ["a1", "c1", "d1"], timeout_s=30), builds.built
        assert cache.has({"r.drl": "d1"}) and not cache.has({"r.drl": "b2"}) and cache.builds == 3
        cache.prebuild(None, "d", {"r.drl": "d1"})  # built already: nothing to do
        assert cache.builds == 3
    finally:
        builds.release.set()
        cache.close()


def test_closing_drops_the_builds_that_wait(monkeypatch):
    builds = HeldBuilds()
    monkeypatch.setattr(explain, "build", builds)
    monkeypatch.setattr(explain, "explain", lambda *_args: {})
    cache = explain.ExplainCache(size=4)
    cache.prebuild(None, "a", {"r.drl": "a1"})
    assert builds.started.wait(30)
    cache.prebuild(None, "b", {"r.drl": "b1"})
    closer = threading.Thread(target=cache.close)
    closer.start()
    assert wait_for(lambda: not cache._prebuild, timeout_s=30)  # dropped before the build in progress ends
    builds.release.set()
    closer.join(30)
    assert builds.built == ["a1"]
