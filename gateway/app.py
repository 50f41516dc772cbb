"""The composition root: the one place a gateway is built (and its parts closed again).

Every entry point — ``printeps serve`` (and each of its ``--workers``), ``printeps demo``, the ROS
launcher ``printeps ros`` / ``python -m gateway.ros_launch``, the agile-loop harness and the tests —
calls :func:`build_gateway` with its settings; there is no second wiring. One gateway process is:

- the Information State (MongoDB: ``MONGO_URI`` or the embedded SecantusDB), with the catalog of
  everything an author changes (rule sets, workflows, knowledge, queries, mappings) and the one
  decision record;
- one rules engine, one knowledge base (ontology + SWRL, Pellet), one stream engine with its
  queries, bindings and mappings, one workflow service;
- optionally one ROS node (topics in, robot services out) and the REST app (API + workbench);
- a change follower that keeps all of them on the catalog's current versions, so a change made
  through any process is live in every process.

Imports go downward only: entry points (cli, serve, demo, worker, ros_launch) → app → api/ros →
runtime → workflow → engine/stream/ontology → store/rdf → base → config (tests/meta/test_layers.py).
Running a built gateway until a signal is the entry points' part (:func:`gateway.serve.run`).
Data flows one way: sensor → RDF → window → binding → rules → action → Information State.
"""

from __future__ import annotations

import logging
import os
import socket
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from gateway.base import jvm
from gateway.base.lifecycle import CatalogLifecycle
from gateway.base.versions import Catalog
from gateway.config import Settings
from gateway.dialogue.service import DialogueService
from gateway.engine import Engine
from gateway.ontology.knowledge import KnowledgeBase
from gateway.rdf.mapping import Mapper
from gateway.ros.robots import RobotStates
from gateway.runtime.actions import ActionRouter, workflow_handler
from gateway.runtime.follower import ChangeFollower
from gateway.runtime.jobs import JobRecords, JobService
from gateway.runtime.live import LiveFeed
from gateway.runtime.session_log import StoredSessionLog
from gateway.runtime.transfer import seed_folders
from gateway.store import open_store
from gateway.store.catalog import MongoCatalog
from gateway.store.decisions import DecisionRecord
from gateway.store.members import Membership
from gateway.store.session_records import SessionDirectory
from gateway.store.store import QUERY_RESULTS
from gateway.stream.engine import StreamEngine
from gateway.stream.services import MappingService, QueryService
from gateway.workflow.recorder import CallableRecorder, FanOutRecorder
from gateway.workflow.service import WorkflowService, build_service

log = logging.getLogger(__name__)


def process_name() -> str:
    """host:pid — how this process signs catalog changes and decisions."""
    return f"{socket.gethostname()}:{os.getpid()}"


@dataclass
class Gateway:
    """A built gateway: every service of this process. ``close()`` stops them in reverse order."""

    settings: Settings
    catalog: Catalog
    engine: Engine
    knowledge: KnowledgeBase
    mapper: Mapper
    mappings: MappingService
    streams: StreamEngine
    queries: QueryService
    robots: RobotStates
    actions: ActionRouter
    workflows: WorkflowService
    store: Any = None
    decisions: Any = None
    ros: Any = None
    follower: ChangeFollower | None = None
    live: LiveFeed = field(default_factory=LiveFeed)  # what this process sees happen (GET /api/live)
    app: Any = None
    members: Any = None  # gateway.store.members.Membership: where other processes reach this one
    jobs: Any = None  # gateway.runtime.jobs.JobService: deploys and validations in the background
    dialogue: Any = None  # gateway.dialogue.service.DialogueService: conversations at the tables

    name: str = field(default_factory=process_name)
    _closers: list[tuple[str, Callable[[], None]]] = field(default_factory=list, repr=False)

    def health(self) -> dict[str, dict[str, Any]]:
        """Per part: ``{"status": "ok" | "degraded" | "down" | "not configured", ...}``."""
        report: dict[str, dict[str, Any]] = {
            "engine": {"status": "ok", "rulesets": {i.name: i.version for i in self.engine.live_versions()},
                       "sessions": len(self.engine.session_manager.list()), "jvm_heap": jvm.heap(),
                       "jvm_non_heap": jvm.non_heap(), "jvm_aot_cache": jvm.aot_cache()},
            "store": self.store.health() if self.store is not None else {"status": "not configured"},
            "ros": self.ros.health() if self.ros is not None else {"status": "not configured"},
            "actions": {"status": "ok", "handlers": sorted(self.actions.handlers), **self.actions.stats},
            "sync": self.follower.health() if self.follower is not None else {"status": "not configured"},
            "knowledge": {"status": "ok" if not self.knowledge.error else "degraded", "error": self.knowledge.error},
        }
        return report

    def announce(self, url: str) -> None:
        """Serving at ``url`` (``sessions.advertise_url`` wins): other processes forward calls for
        the sessions this one holds there (see gateway.api.forwarding)."""
        if self.members is not None:
            advertised = self.settings.sessions.advertise_url
            self.members.register(url if not advertised or "{port}" in advertised else advertised)

    def idle(self) -> bool:
        """Nothing in hand: every received message handled, every action performed, no workflow
        run going (tests, the demo and benchmarks wait for this)."""
        return ((self.ros is None or self.ros.idle()) and self.actions.idle()
                and self.workflows.running() == 0)

    def close(self) -> None:
        """Stop everything this gateway started, last started first; each step is best effort."""
        while self._closers:
            what, closer = self._closers.pop()
            try:
                closer()
            except Exception:  # shutting down must go on: later parts (the store) must still close
                log.exception("closing %s failed", what)


def build_gateway(
    settings: Settings,
    *,
    rest: bool = True,
    ros: bool | None = None,
    store: Any = None,
    seed: bool = True,
    warm_up: bool = True,
    follow: bool = True,
    domain_id: int | None = None,
    on_ros_event: Callable[[str, dict[str, Any]], None] | None = None,
) -> Gateway:
    """Build one gateway process from ``settings`` (see the module docstring).

    ``ros``: run the ROS node (None: ``settings.ros.enabled``, else when rclpy is importable).
    ``store``: an open Information State to use (None: open the configured one).
    ``seed``: import ``rules/drl``, ``workflows``, ``ontology`` into a store that lacks them.
    """
    closers: list[tuple[str, Callable[[], None]]] = []
    try:
        return _build(settings, closers, rest=rest, ros=ros, store=store, seed=seed,
                      warm_up=warm_up, follow=follow, domain_id=domain_id, on_ros_event=on_ros_event)
    except BaseException:
        while closers:
            what, closer = closers.pop()
            try:
                closer()
            except Exception:
                log.exception("closing %s after a failed start failed", what)
        raise


def _build(settings: Settings, closers: list[tuple[str, Callable[[], None]]], *, rest: bool, ros: bool | None,
           store: Any, seed: bool, warm_up: bool, follow: bool, domain_id: int | None,
           on_ros_event: Callable[[str, dict[str, Any]], None] | None) -> Gateway:
    name = process_name()
    # The JVM starts in this (normally the main) thread: a JVM first started from a worker thread
    # makes the interpreter hang at exit (JPype).
    jvm.start(settings.jvm)

    if store is None:
        store = open_store(settings)
        closers.append(("the Information State", store.close))
    store.ping()
    catalog = MongoCatalog(store.db, name, change_streams=settings.sync.change_streams,
                           poll_interval_s=settings.sync.poll_interval_s)
    closers.append(("the catalog", catalog.close))
    decisions = DecisionRecord(store)
    members = Membership(store.db, name, heartbeat_s=settings.sessions.member_heartbeat_s)
    closers.append(("the member record", members.close))
    if settings.engine.compile_shared_cache:  # followers on other hosts assemble, not compile
        from gateway.engine import incremental
        from gateway.store.unit_store import SharedUnitStore

        incremental.share_units(SharedUnitStore(store.db, settings.engine.compile_shared_cache_days))
        closers.append(("the shared rule units", lambda: incremental.share_units(None)))
    start_seq = catalog.last_seq()  # follow from here: nothing changed after loading is missed

    engine = Engine(settings, catalog)
    engine.recorder.journal_to(decisions)  # the one recorder journals every decision there
    live = LiveFeed()
    engine.add_listener(live.on_engine_event)
    # sessions are recorded with their owner, so other processes can forward to it
    engine.session_manager.directory = SessionDirectory(store.db, name, members)
    closers.append(("the session records", engine.session_manager.directory.release_all))
    # durable sessions (their log; see docs/operations.md)
    engine.session_manager.attach_log(StoredSessionLog(store, catch_up_s=settings.sessions.rebuild_timeout_s))
    closers.append(("the session log", engine.session_manager.log.close))
    closers.append(("the rules engine's sessions", engine.session_manager.close_all))
    closers.append(("explaining", engine.close_explain))
    jobs = JobService(engine, JobRecords(store.db), name, alive=lambda p: members.alive(members.get(p)),
                      max_queued=settings.engine.max_queued_jobs)
    closers.append(("the build jobs", jobs.close))

    cfg = settings.streams
    seeds = seed_folders(settings) if seed else {}
    knowledge = KnowledgeBase(catalog)
    _seed_and_load(knowledge, seeds)
    _seed_and_load(engine, seeds)

    robots = RobotStates(settings.ros.robot_start)
    actions = ActionRouter(store, queue_size=settings.ros.queue_size)
    actions.add_listener(robots.on_outcome)
    actions.add_listener(live.on_outcome)
    mapper = Mapper()
    mappings = MappingService(mapper, catalog, describe=_describe_if_available())
    streams = StreamEngine(cfg, rules_engine=engine, ontology=knowledge.ontology, providers={"robots": robots.facts})
    closers.append(("the stream engine", streams.close))
    streams.add_input_listener(live.on_stream_item)
    streams.subscribe(live.on_stream_event, nonempty=True)
    queries = QueryService(streams, catalog)
    _seed_and_load(mappings, seeds)
    _seed_and_load(queries, seeds)
    streams.subscribe(_result_recorder(store), nonempty=True)

    run_ros = _want_ros(settings, ros)
    ros_gateway = None
    ros_modules = None
    if run_ros:
        from gateway.ros.bridge import RosGateway
        from gateway.workflow.ros import RosModules

        ros_gateway = RosGateway(settings, engine=engine, streams=streams, mappings=mappings, store=store,
                                 actions=actions, domain_id=domain_id, on_event=on_ros_event)
        closers.append(("the ROS node", ros_gateway.close))
        ros_modules = RosModules(ros_gateway.node, ros_gateway.caller, on_move=robots.on_outcome)

    closers.append(("the action router", actions.close))  # finishes queued actions while the robots are reachable
    dialogue = DialogueService(engine, knowledge, settings.dialogue, store=store, dispatch=actions.on_stream_event)
    closers.append(("the conversations", dialogue.close))
    dialogue.start_watching()  # every process watches the shared conversations (their process may be gone)
    if ros_gateway is not None:
        ros_gateway.attach_dialogue(dialogue)

    workflows = build_service(settings, catalog=catalog, engine=engine, store=store,
                              ontology_lookup=knowledge.value, ros_modules=ros_modules, dialogue=dialogue)
    closers.append(("the workflow executor", workflows.close))
    _seed_and_load(workflows.registry, seeds)
    workflows.executor.recorder = FanOutRecorder(workflows.executor.recorder, CallableRecorder(live.on_workflow_record))
    actions.register("workflow", workflow_handler(workflows))
    streams.subscribe(actions.on_stream_event)

    follower = None
    if follow:
        services = (engine, workflows.registry, knowledge, mappings, queries)
        follower = ChangeFollower(catalog, {service.kind: service for service in services},
                                  start_seq=start_seq, reconcile_interval_s=settings.sync.reconcile_interval_s).start()
        closers.append(("the change follower", follower.stop))

    gateway = Gateway(settings=settings, catalog=catalog, engine=engine, knowledge=knowledge, mapper=mapper,
                      mappings=mappings, streams=streams, queries=queries, robots=robots, actions=actions,
                      workflows=workflows,
                      store=store, decisions=decisions, ros=ros_gateway, follower=follower, name=name,
                      members=members, jobs=jobs, live=live, dialogue=dialogue, _closers=closers)
    if settings.sync.live_relay:  # the Live view shows every process's teahouse
        from gateway.store.live_relay import LiveRelay

        relay = LiveRelay(store.db, live, store.process, change_streams=settings.sync.change_streams,
                          poll_interval_s=max(settings.sync.poll_interval_s, 0.25))
        closers.append(("the live relay", relay.close))
    closers.append(("the live feed", live.close))  # first: open event streams end, the server can stop
    if rest:
        from gateway.api.main import create_app

        gateway.app = create_app(gateway)
    if warm_up and settings.engine.process_warm_up:
        engine.warm_up()
        closers.append(("engine warm-up", engine.stop_warm_up))  # closed first: it reads the store
    return gateway


def _seed_and_load(service: CatalogLifecycle, seeds: dict[str, list[Path]]) -> None:
    """Seed a catalog-backed service from its folders (none: ``seed=False``), then serve what the
    catalog holds. One log line per item; failures as errors, so a start that serves less than
    the store holds says so."""
    for folder in seeds.get(service.kind, []):
        _log_report(service.kind, service.seed(folder))
    _log_report(service.kind, service.load())


def _log_report(kind: str, report: dict[str, str]) -> None:
    for item, status in report.items():
        (log.error if status.startswith("failed") else log.info)("%s %s: %s", kind, item, status)


def _want_ros(settings: Settings, ros: bool | None) -> bool:
    if ros is not None:
        return ros
    if settings.ros.enabled is not None:
        return settings.ros.enabled
    from gateway.ros.bridge import ros_available

    return ros_available()


def _describe_if_available() -> Callable[[str], dict[str, str]] | None:
    """Message types' fields from rosidl when the ROS packages are installed (mapping checks)."""
    try:
        import rclpy  # noqa: F401
    except ImportError:
        return None
    from gateway.ros.convert import describe

    return describe


def _result_recorder(store: Any) -> Callable[[dict[str, Any]], None]:
    """Keep every non-empty query result in the Information State (what was detected, when)."""

    def record(event: dict[str, Any]) -> None:
        if event.get("kind") == "result" and event.get("rows"):
            store.record(QUERY_RESULTS, {k: v for k, v in event.items() if k != "kind"},
                         stored_type=f"printeps/QueryResult/{event.get('query', 'query')}", inserted_by="stream_engine")

    return record
