"""The dialogue on ROS: ``printeps_interfaces/msg/Utterance`` in, completed orders out.

Why its own adapter: the ROS side only carries words and orders; the conversation is the
gateway's :class:`gateway.dialogue.service.DialogueService` (the same one REST reaches). An
utterance on ``dialogue.utterance_topic`` is one turn (Pepper answers through her Speak service,
as every rule action does); every completed order is published as JSON on
``dialogue.orders_topic`` (``std_msgs/msg/String``: ``{"conversation", "table", "drink", "cups",
"at", "decision_ids"}``), where the kitchen's workflow and nodes listen. Turns are taken off the
executor's threads by one worker with a bounded queue: a full queue drops the utterance, counted
and logged, rather than stalling the node.
"""

from __future__ import annotations

import json
import logging
import queue
import threading
from typing import Any

log = logging.getLogger(__name__)


class DialogueTopics:
    """Subscribes the utterance topic and publishes orders for one dialogue service."""

    def __init__(self, node: Any, dialogue: Any, *, utterance_topic: str, orders_topic: str,
                 queue_size: int = 100) -> None:
        from std_msgs.msg import String

        self.node = node
        self.dialogue = dialogue
        self.stats = {"utterances": 0, "dropped": 0, "failed": 0, "orders": 0}
        self._queue: queue.Queue[dict[str, Any] | None] = queue.Queue(maxsize=queue_size)
        self._string = String
        self.orders = node.create_publisher(String, orders_topic, 10)
        self.subscription = None
        try:
            from printeps_interfaces.msg import Utterance
        except ImportError:  # an interface package built before Utterance existed: rebuild (ros/install.sh)
            log.warning("printeps_interfaces has no Utterance message: rebuild it (PRINTEPS_ROS_REBUILD=1 "
                        "bash ros/install.sh) to take turns from %s", utterance_topic)
        else:
            self.subscription = node.create_subscription(Utterance, utterance_topic, self._on_utterance, 100)
        dialogue.add_order_listener(self.publish_order)
        self._worker = threading.Thread(target=self._work, name="ros-dialogue", daemon=True)
        self._worker.start()

    def _on_utterance(self, msg: Any) -> None:
        turn = {"conversation": str(msg.conversation), "text": str(msg.text), "confidence": float(msg.confidence)}
        try:
            self._queue.put_nowait(turn)
        except queue.Full:
            self.stats["dropped"] += 1
            log.error("dialogue queue full: the utterance %r of %s was dropped", turn["text"], turn["conversation"])

    def _work(self) -> None:
        while True:
            turn = self._queue.get()
            try:
                if turn is None:
                    return
                self.stats["utterances"] += 1
                self.dialogue.turn(turn["conversation"], text=turn["text"], confidence=turn["confidence"])
            except Exception:  # a bad utterance is logged; the conversation and the node go on
                self.stats["failed"] += 1
                log.exception("the utterance of %s could not be taken", turn and turn.get("conversation"))
            finally:
                self._queue.task_done()

    def idle(self) -> bool:
        return self._queue.unfinished_tasks == 0

    def publish_order(self, order: dict[str, Any]) -> None:
        self.orders.publish(self._string(data=json.dumps(order, default=str)))
        self.stats["orders"] += 1

    def close(self) -> None:
        try:
            self._queue.put_nowait(None)
        except queue.Full:
            pass
        self._worker.join(timeout=5)
