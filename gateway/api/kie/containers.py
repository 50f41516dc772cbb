"""KIE Server's server and container resources, for rule sets.

A rule set is a container: container id = rule set name, release id
``org.printeps.rules:<name>:<version>``. ``PUT /containers/{id}`` with a release id and
``POST /containers/{id}/release-id`` choose which stored version serves (a number, or ``LATEST``:
the newest stored); ``DELETE`` stops serving it (its versions and history stay).
"""

from __future__ import annotations

import time
import urllib.parse
import uuid
from datetime import datetime
from typing import Any

KIE_VERSION = "7.74.1.Final"  # the KIE Server API level these answers follow
CAPABILITIES = ["KieServer", "BRM"]
GROUP_ID = "org.printeps.rules"
LATEST = "LATEST"


class ReleaseIdError(ValueError):
    """A release id that does not name a rule set version of this gateway."""


def service_response(ok: bool, msg: str, result: Any = None) -> dict[str, Any]:
    return {"type": "SUCCESS" if ok else "FAILURE", "msg": msg, "result": result}


def release_id(name: str, version: int | str) -> dict[str, str]:
    return {"group-id": GROUP_ID, "artifact-id": name, "version": str(version)}


def external_release_id(name: str, version: int | str) -> str:
    return f"{GROUP_ID}:{name}:{version}"


def parse_release_id(body: Any, container_id: str) -> str | int:
    """The version a ``release-id`` (or a ``kie-container`` with one) asks for: an int or LATEST."""
    if isinstance(body, dict) and "release-id" in body:
        body = body["release-id"]
    if not isinstance(body, dict):
        raise ReleaseIdError("a release-id is required: {\"group-id\", \"artifact-id\", \"version\"}")
    group, artifact, version = body.get("group-id"), body.get("artifact-id"), body.get("version")
    if group not in (None, GROUP_ID):
        raise ReleaseIdError(f"group-id must be {GROUP_ID} (rule sets of this gateway), got {group!r}")
    if artifact != container_id:
        raise ReleaseIdError(f"artifact-id must be the rule set's name, which is the container id {container_id!r}, "
                             f"got {artifact!r}")
    if isinstance(version, str) and version.upper() == LATEST:
        return LATEST
    try:
        number = int(str(version))
    except ValueError:
        raise ReleaseIdError(f"version must be a rule set version number or LATEST, got {version!r}") from None
    if number < 1:
        raise ReleaseIdError(f"version must be 1 or more, got {number}")
    return number


def container_resource(info: Any, status: str = "STARTED", sessions: list[dict[str, Any]] | None = None) -> dict[str, Any]:
    """A rule set version as a ``kie-container`` resource."""
    rid = release_id(info.name, info.version)
    items = [{"itemName": "KBase", "itemValue": "", "itemType": "BRM"},
             {"itemName": "KSession", "itemValue": "", "itemType": "BRM"}]
    out = {
        "container-id": info.name,
        "release-id": rid,
        "resolved-release-id": dict(rid),
        "status": status,
        "scanner": {"status": "DISPOSED", "poll-interval": None},
        "config-items": items,
        "messages": [{
            "severity": "INFO",
            "timestamp": {"java.util.Date": epoch_ms(info.deployed_at)},
            "content": [f"Container {info.name} successfully created with module {external_release_id(info.name, info.version)}."
                        f" (deployed by {info.author or 'unknown'})"],
        }],
        "container-alias": info.name,
    }
    if sessions is not None:
        out["ksessions"] = sessions  # the gateway's addition: the ksessions it declares
    return out


def epoch_ms(iso: str) -> int:
    try:
        return int(datetime.fromisoformat(iso.replace("Z", "+00:00")).timestamp() * 1000)
    except (ValueError, AttributeError):
        return 0


def server_info(server_id: str, location: str) -> dict[str, Any]:
    return {
        "id": server_id,
        "name": server_id,
        "version": KIE_VERSION,
        "location": location,
        "capabilities": list(CAPABILITIES),
        "messages": [{
            "severity": "INFO",
            "timestamp": {"java.util.Date": int(time.time() * 1000)},
            "content": [f"Server {server_id} (PRINTEPS gateway, KIE Server compatible) is running"],
        }],
        "mode": "PRODUCTION",
    }


def conversation_id(server_id: str, container_id: str, version: int | str) -> str:
    """KIE's ``X-KIE-ConversationId``: 'server':'container':'group:artifact:version':'uuid', URL-encoded."""
    text = f"'{server_id}':'{container_id}':'{external_release_id(container_id, version)}':'{uuid.uuid4()}'"
    return urllib.parse.quote_plus(text)
