"""Calls for a session another gateway process owns go to that process.

A stateful session lives in the JVM of the process that created it; with several processes
(``--workers``, several hosts behind a load balancer) a call may land elsewhere. The receiving
process looks the owner up (``gateway.store.session_records``), finds its member record
(``gateway.store.members``: the URL other processes reach it at) and replays the request there
— method, path, query, body and the caller's credentials — then hands the owner's answer back
unchanged. A forwarded request carries ``X-Printeps-Forwarded-By`` and is never forwarded again
(a misdirected one is answered 421). If the owner is gone (no fresh member record, or its pid is
dead on this host), the record is released and :class:`SessionGone` raised: the caller then
rebuilds a durable session here (``gateway.engine.sessions``), or answers 410 for one that was not
durable (its facts are lost); an owner that is alive but does not answer gets 503 (retry).
"""

from __future__ import annotations

import logging
from typing import Any

import httpx
from fastapi import Request
from fastapi.responses import Response

from gateway.engine.sessions import SessionElsewhere, SessionGone

log = logging.getLogger(__name__)

FORWARDED_BY = "x-printeps-forwarded-by"
_HOP_HEADERS = {"host", "content-length", "connection", "keep-alive", "transfer-encoding", "te", "upgrade",
                "proxy-authorization", "proxy-connection", "accept-encoding"}
# retry-after: the owner's 503 (the session being rebuilt there, a bulkhead full) tells when to retry
_PASS_BACK = ("content-type", "x-ruleset-version", "x-decision-id", "x-kie-conversationid", "x-session-id",
              "x-session-owner", "location", "retry-after")


class OwnerUnreachable(Exception):
    """The owner is alive (fresh heartbeat) but did not answer: retry later."""


class Misdirected(Exception):
    """A forwarded call reached a process that does not hold the session either."""


def _client(request: Request) -> httpx.AsyncClient:
    state = request.app.state
    client = getattr(state, "forward_client", None)
    if client is None:
        timeout = request.app.state.settings.sessions.forward_timeout_s
        client = httpx.AsyncClient(timeout=httpx.Timeout(timeout, connect=2.0))
        state.forward_client = client
    return client


async def forward(request: Request, elsewhere: SessionElsewhere) -> Response:
    """Replays ``request`` at the session's owner and returns its answer; :class:`SessionGone`,
    :class:`OwnerUnreachable` or :class:`Misdirected` when that cannot be done."""
    gateway = request.app.state.gateway
    owner = elsewhere.owner.get("process")
    if request.headers.get(FORWARDED_BY):
        raise Misdirected(f"session {elsewhere.session_id} of {elsewhere.ruleset} is not here either: its owner is "
                          f"{owner} (this call was forwarded by {request.headers[FORWARDED_BY]})")
    members = getattr(gateway, "members", None)
    member = members.get(owner) if members is not None else None
    if members is None or not members.alive(member):
        _release(gateway, elsewhere)
        raise SessionGone(_gone_message(elsewhere))
    url = str(member.get("url") or elsewhere.owner.get("url") or "")
    if not url:
        raise OwnerUnreachable(f"process {owner} owns session {elsewhere.session_id} but announced no address")
    target = url + request.url.path + (f"?{request.url.query}" if request.url.query else "")
    headers = {k: v for k, v in request.headers.items() if k.lower() not in _HOP_HEADERS}
    headers[FORWARDED_BY] = gateway.name
    body = await request.body()
    try:
        answer = await _client(request).request(request.method, target, content=body, headers=headers)
    except httpx.TransportError as exc:
        if not members.alive(members.get(owner)):
            _release(gateway, elsewhere)
            raise SessionGone(_gone_message(elsewhere)) from None
        raise OwnerUnreachable(f"process {owner}, which holds session {elsewhere.session_id} of {elsewhere.ruleset}, "
                               f"did not answer at {url}: {type(exc).__name__}; retry") from None
    passed = {k: v for k, v in answer.headers.items() if k.lower() in _PASS_BACK}
    passed["X-Session-Owner"] = str(owner)
    return Response(answer.content, status_code=answer.status_code, headers=passed)


def _gone_message(elsewhere: SessionElsewhere) -> str:
    return (f"session {elsewhere.session_id} of {elsewhere.ruleset} lived in gateway process "
            f"{elsewhere.owner.get('process')}, which is gone: the session and its facts are lost. "
            "Open a new session (a KIE lookup of the same ksession now starts a fresh one).")


def _release(gateway: Any, elsewhere: SessionElsewhere) -> None:
    """Forget the gone owner's record, and tell the session manager who it was: the call is run
    again here, and a durable session's rebuild waits for that process's journal."""
    manager = gateway.engine.session_manager
    directory = getattr(manager, "directory", None)
    if directory is None:
        return
    manager.owner_gone(elsewhere.ruleset, elsewhere.session_id, str(elsewhere.owner.get("process")))
    try:
        directory.release(elsewhere.ruleset, elsewhere.session_id, process=elsewhere.owner.get("process"))
    except Exception:  # the next call finds the same and tries again
        log.warning("could not release the record of gone session %s/%s", elsewhere.ruleset, elsewhere.session_id,
                    exc_info=True)
