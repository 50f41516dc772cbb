"""The ROS side of one gateway process: one ROS context and executor, the gateway node, the ingress
of sensor messages and the dispatch of the rules' actions to the robots.

It is built by the composition root (:func:`gateway.app.build_gateway`) from the gateway's own
services — the one rules engine, the one stream engine, the mappings, the Information State — and
builds none of them itself (cf. ros2/examples ``composed.py``: several nodes, one executor, one
main). Workflows reach robot services through the same node (:attr:`caller`).

The data path: topic → message dict → mapping → RDF on the subscription's stream → windows →
rule binding → decision → ``actions`` event → the action router (:mod:`gateway.runtime.actions`) → for
robot modules this side's :class:`ActionDispatcher` → robot services → outcome recorded with its
decision. The bridge also moves the clock of the streams named in ``ros.heartbeats`` once a
second, so windows close (and, e.g., an empty table is noticed) while every sensor is silent.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any, Callable

from gateway.config import RosSubscription, Settings
from gateway.rdf.mapping import MappingError, check_against, element_type, introspected_spec, node_map_from_spec
from gateway.ros.convert import describe
from gateway.ros.dialogue import DialogueTopics
from gateway.ros.dispatcher import ActionDispatcher
from gateway.ros.ingress import Ingress, checks, topic_mapping
from gateway.ros.node import GatewayNode
from gateway.ros.runtime import RosRuntime

log = logging.getLogger(__name__)


def ros_available() -> bool:
    """True when rclpy and the gateway's interface package can be imported."""
    try:
        import printeps_interfaces.srv  # noqa: F401
        import rclpy  # noqa: F401
    except ImportError:
        return False
    return True


class RosGateway:
    """Runs the gateway node until :meth:`close`; see the module docstring."""

    def __init__(self, settings: Settings, *, engine: Any, streams: Any, mappings: Any, store: Any,
                 actions: Any, domain_id: int | None = None,
                 on_event: Callable[[str, dict[str, Any]], None] | None = None) -> None:
        cfg = settings.ros
        self.settings = settings
        self.streams = streams
        self.runtime = RosRuntime(args=list(cfg.args) or None,
                                  domain_id=cfg.domain_id if cfg.domain_id is not None else domain_id)
        self.problems = register_topic_mappings(cfg.subscriptions, mappings)
        self.ingress = Ingress(cfg.subscriptions, mappings.mapper, streams, store, named_checks=checks(cfg),
                               queue_size=cfg.queue_size, on_event=on_event)

        def fire(ruleset: str, facts: list[dict[str, Any]], request_id: str | None) -> Any:
            return engine.fire(ruleset, facts, origin="ros", correlation_id=request_id,
                               context={"service": "fire_business_rules"})

        self.node = self.runtime.make(GatewayNode, cfg, enqueue=self.ingress.enqueue, fire=fire)
        self.caller = self.node.caller
        self.dispatcher = ActionDispatcher(self.caller, dict(cfg.robots), timeout_s=cfg.call_timeout_s,
                                           retries=cfg.call_retries)
        try:
            self.node.attach_dispatcher(self.dispatcher)
        except ValueError:  # a bad start-up parameter: leave no context or shared memory behind
            self.runtime.shutdown()
            raise
        for module in self.dispatcher.modules:
            actions.register(module, self.dispatcher.dispatch)
        self.ingress.start()
        self.dialogue: Any = None  # gateway.ros.dialogue.DialogueTopics, once attached
        self._stop = threading.Event()
        self._heartbeat = threading.Thread(target=self._beat, args=(list(cfg.heartbeats),), name="ros-heartbeat",
                                           daemon=True)
        self._heartbeat.start()

    def _beat(self, streams: list[str]) -> None:
        """Move the clock of ``streams`` to now, once a second (sensors stamp readings with the wall
        clock): a window closes even when no reading comes."""
        while streams and not self._stop.wait(1.0):
            now_ms = int(time.time() * 1000)
            for stream in streams:
                try:
                    self.streams.advance(now_ms, stream)
                except Exception:  # a heartbeat must never stop: the next one tries again
                    log.exception("heartbeat of %s failed", stream)

    def attach_dialogue(self, dialogue: Any) -> None:
        """Take turns from the ``Utterance`` topic and publish completed orders (see
        :mod:`gateway.ros.dialogue`)."""
        cfg = self.settings.dialogue
        self.dialogue = DialogueTopics(self.node, dialogue, utterance_topic=cfg.utterance_topic,
                                       orders_topic=cfg.orders_topic)

    @property
    def stats(self) -> dict[str, int]:
        return dict(self.ingress.stats)

    def idle(self) -> bool:
        """Nothing queued: every received message (sensor readings, utterances) was handled."""
        return self.ingress.idle() and (self.dialogue is None or self.dialogue.idle())

    def health(self) -> dict[str, Any]:
        return {"status": "ok", "node": self.node.get_name(), "domain_id": self.runtime.context.get_domain_id(),
                "topics": [s.topic for s in self.settings.ros.subscriptions], "problems": self.problems,
                **self.stats}

    def close(self) -> None:
        """Stop taking messages, finish the one in hand, stop the executor, destroy the node."""
        self._stop.set()
        self.ingress.stop()
        if self.dialogue is not None:
            self.dialogue.close()
        self.runtime.shutdown()


def register_topic_mappings(subscriptions: list[RosSubscription], mappings: Any) -> list[str]:
    """Give each subscription without a named mapping one under ``topic:<topic>`` (its inline
    mapping, or one introspected from the message type), and check named ones against the type.
    Returns the problems found (also logged): a subscription with a problem rejects its messages."""
    problems = []
    for sub in subscriptions:
        try:
            type_name = _mapped_type(sub)
            if isinstance(sub.mapping, str):
                node = mappings.mapper.mappings.get(sub.mapping)
                if node is None:
                    raise MappingError("mapping", f"no mapping named {sub.mapping!r}")
                check_against(node, type_name, describe)
                continue
            spec = sub.mapping if isinstance(sub.mapping, dict) else introspected_spec(type_name, describe)
            node = node_map_from_spec(spec, f"ros.subscriptions[{sub.topic}].mapping", resolve=mappings.mapper.mappings)
            check_against(node, type_name, describe)
            mappings.mapper.mappings[topic_mapping(sub.topic)] = node
        except (MappingError, ValueError) as exc:
            problems.append(f"topic {sub.topic}: {exc}")
            log.error("topic %s (%s): %s", sub.topic, sub.type, exc)
    return problems


def _mapped_type(sub: RosSubscription) -> str:
    """The type the mapping applies to: the message's, or the selected nested field's."""
    if not sub.select:
        return sub.type
    fields = describe(sub.type)
    if sub.select not in fields:
        raise MappingError("select", f"message type {sub.type} has no field {sub.select!r} (fields: {', '.join(fields)})")
    base, _ = element_type(fields[sub.select])
    parts = base.split("/")
    return f"{parts[0]}/msg/{parts[-1]}" if len(parts) >= 2 else sub.type.rsplit("/", 1)[0] + "/" + base
