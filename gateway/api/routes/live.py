"""``GET /api/live``: the live feed of this gateway process as Server-Sent Events.

What the workbench's Live view draws (:mod:`gateway.runtime.live`): one SSE event type per kind —
``reading`` (people's distances to the entrance), ``detection`` (a stream query found something),
``decision`` (rules fired; open it at ``/api/decisions/{decision_id}``), ``action`` (what a robot
was asked to do and how it went) — each with JSON data and ``id: <feed>-<seq>``. On connect the
kept events are replayed (``replay=false``: only new ones; a reconnecting ``EventSource`` sends
``Last-Event-ID`` and gets only what it missed from the same process). ``hello`` opens the stream,
``heartbeat`` comes every ``heartbeat_s`` seconds of quiet, ``dropped`` says how many events a slow
reader lost (its queue is bounded: the gateway never waits for a browser). The stream ends when
the server stops (:meth:`gateway.runtime.live.LiveFeed.close`), so an open Live view never holds up a
shutdown.

Auth: the caller role, by ``Authorization: Bearer`` or ``?access_token=`` (``EventSource`` cannot
set headers).

    GET /api/live?replay=&max_events=&heartbeat_s=
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Annotated, Any, AsyncIterator

from fastapi import APIRouter, Depends, Query, Request
from fastapi.responses import StreamingResponse

from gateway.api.auth import Principal, event_stream_caller
from gateway.api.deps import GatewayDep
from gateway.api.jsonio import JsonRoute
from gateway.runtime.live import KINDS

router = APIRouter(tags=["live"], route_class=JsonRoute)

EventStreamCaller = Annotated[Principal, Depends(event_stream_caller)]


def sse(kind: str, data: Any, event_id: str | None = None) -> bytes:
    """One Server-Sent Event (JSON data on one line)."""
    head = f"event: {kind}\n" + (f"id: {event_id}\n" if event_id else "")
    return f"{head}data: {json.dumps(data, default=str, separators=(',', ':'))}\n\n".encode()


def resume_after(last_event_id: str | None, feed_id: str) -> int | None:
    """The seq a reconnecting browser saw last, if it saw it from this very feed (else replay all)."""
    if not last_event_id or "-" not in last_event_id:
        return None
    feed, _, seq = last_event_id.rpartition("-")
    return int(seq) if feed == feed_id and seq.isdigit() else None


@router.get("/api/live")
async def live(request: Request, gateway: GatewayDep, who: EventStreamCaller,
               replay: bool = True, max_events: int | None = Query(None, ge=1),
               heartbeat_s: float = Query(15.0, ge=0.2, le=300)) -> StreamingResponse:
    """Readings, detections, decisions and robot actions of this process, as they happen (and the
    windows a rule binding skipped because its rules were still firing an earlier one)."""
    feed = gateway.live
    loop = asyncio.get_running_loop()
    wake = asyncio.Event()
    after = resume_after(request.headers.get("last-event-id"), feed.id)
    subscription = feed.subscribe(lambda: loop.call_soon_threadsafe(wake.set), after=after, replay=replay)

    async def events() -> AsyncIterator[bytes]:
        sent = 0
        try:
            yield sse("hello", {"feed": feed.id, "process": gateway.name, "user": who.name,
                                "resumed_after": after, "kinds": list(KINDS)})
            while max_events is None or sent < max_events:
                batch, dropped = subscription.take()
                if not batch and not dropped and subscription.closed:
                    return  # the server is stopping
                if not batch and not dropped:
                    wake.clear()
                    batch, dropped = subscription.take()  # queued between the take and the clear
                if not batch and not dropped:
                    try:
                        await asyncio.wait_for(wake.wait(), timeout=heartbeat_s)
                    except TimeoutError:
                        if await request.is_disconnected():
                            return
                        yield sse("heartbeat", {"at": int(time.time() * 1000), "feed": feed.id})
                    continue
                chunk = [sse("dropped", {"dropped": dropped})] if dropped else []
                for event in batch[: None if max_events is None else max_events - sent]:
                    chunk.append(sse(event["kind"], event, f"{feed.id}-{event['seq']}"))
                    sent += 1
                yield b"".join(chunk)
        finally:
            subscription.close()

    return StreamingResponse(events(), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
