"""Who is calling and may they: bearer tokens with roles, basic auth for KIE Server clients.

Roles, each including the one before: ``caller`` may fire and read; ``author`` may also deploy, roll
back and delete — rule sets the rule policy allows (gateway.engine.policy: DRL is Java, and an
author's rules may not run arbitrary code on the server); ``developer`` may deploy and try any DRL.
Tokens come from ``settings.api.tokens`` (``PRINTEPS_TOKENS``). With no tokens configured the API
is *open* (dev mode for the embedded demo, which ``printeps serve`` keeps on a loopback address
unless ``PRINTEPS_API_OPEN=1``): every request acts as the developer ``anonymous`` — whoever can
reach a loopback port can run code on the machine anyway. Missing/unknown credentials -> 401, a
known identity without the role -> 403.
"""

from __future__ import annotations

import hmac
from dataclasses import dataclass
from typing import Callable

from fastapi import Request, Security
from fastapi.security import HTTPAuthorizationCredentials, HTTPBasic, HTTPBasicCredentials, HTTPBearer

from gateway.api.errors import ApiError
from gateway.config import ApiSettings

ROLE_RANK = {"caller": 1, "author": 2, "developer": 3}

_bearer = HTTPBearer(auto_error=False, description="A token from settings.api.tokens")
KIE_CHALLENGE = 'Basic realm="kie-server"'
_basic = HTTPBasic(auto_error=False, description="KIE Server endpoints only: settings.api.basic_users")


@dataclass(frozen=True)
class Principal:
    """The identity of a request: its name (recorded as deploy author), role and how it was proven."""

    name: str
    role: str
    via: str  # "open", "token" or "basic"

    def to_dict(self) -> dict[str, str]:
        return {"name": self.name, "role": self.role, "auth": self.via}


ANONYMOUS = Principal("anonymous", "developer", "open")


class Authenticator:
    """Checks credentials against the configured tokens/users (constant-time comparisons)."""

    def __init__(self, settings: ApiSettings) -> None:
        self.open = settings.is_open
        self._tokens = [(tok.encode(), entry.name, entry.role) for tok, entry in settings.tokens.items()]
        self._users = {user: (entry.password.encode(), entry.role) for user, entry in settings.basic_users.items()}

    def by_token(self, token: str) -> Principal | None:
        presented = token.encode()
        found = None
        for tok, name, role in self._tokens:  # no early exit: timing does not tell which matched
            if hmac.compare_digest(tok, presented):
                found = Principal(name, role, "token")
        return found

    def by_basic(self, user: str, password: str) -> Principal | None:
        entry = self._users.get(user)
        if entry is None:
            hmac.compare_digest(b"x", password.encode())
            return None
        if hmac.compare_digest(entry[0], password.encode()):
            return Principal(user, entry[1], "basic")
        return None

    def check(
        self,
        role: str,
        bearer: HTTPAuthorizationCredentials | None,
        basic: HTTPBasicCredentials | None = None,
        challenge: str = "Bearer",
    ) -> Principal:
        """The principal for these credentials, or ApiError 401/403."""
        principal: Principal | None = None
        if bearer is not None:
            principal = self.by_token(bearer.credentials)
            if principal is None:
                raise ApiError(401, "unknown token", headers={"WWW-Authenticate": challenge})
        elif basic is not None:
            if self.open and not self._users:
                # open (dev) mode with no users to check against: KIE clients always send some
                # user and password, and must reach the server as they do an unsecured KIE Server
                return ANONYMOUS
            principal = self.by_basic(basic.username, basic.password)
            if principal is None:
                raise ApiError(401, "wrong user or password", headers={"WWW-Authenticate": challenge})
        elif self.open:
            return ANONYMOUS
        else:
            wanted = ("HTTP basic credentials ('Authorization: Basic …') or a token ('Authorization: Bearer <token>')"
                      if challenge.lower().startswith("basic") else "'Authorization: Bearer <token>'")
            raise ApiError(401, f"authentication required: send {wanted}", headers={"WWW-Authenticate": challenge})
        if ROLE_RANK.get(principal.role, 0) < ROLE_RANK[role]:
            raise ApiError(403, f"{principal.name!r} has role {principal.role!r}; this needs {role!r}")
        return principal


def _auth(request: Request) -> Authenticator:
    return request.app.state.auth


def require(role: str) -> Callable[..., Principal]:
    """A FastAPI dependency: the bearer-token principal, with at least ``role``."""

    async def dependency(  # async: a sync dependency would cost a threadpool hop per request
        request: Request, bearer: HTTPAuthorizationCredentials | None = Security(_bearer)
    ) -> Principal:
        return _auth(request).check(role, bearer)

    return dependency


def require_event_stream(role: str) -> Callable[..., Principal]:
    """Like :func:`require`, also accepting the token as ``?access_token=`` (RFC 6750 §2.3): a
    browser's ``EventSource`` cannot set headers. Only for Server-Sent Events routes."""

    async def dependency(
        request: Request, bearer: HTTPAuthorizationCredentials | None = Security(_bearer)
    ) -> Principal:
        token = request.query_params.get("access_token")
        if bearer is None and token:
            bearer = HTTPAuthorizationCredentials(scheme="Bearer", credentials=token)
        return _auth(request).check(role, bearer)

    return dependency


def require_kie(role: str) -> Callable[..., Principal]:
    """Like :func:`require`, also accepting HTTP basic auth (what KIE Server clients send)."""

    async def dependency(
        request: Request,
        bearer: HTTPAuthorizationCredentials | None = Security(_bearer),
        basic: HTTPBasicCredentials | None = Security(_basic),
    ) -> Principal:
        return _auth(request).check(role, bearer, basic, challenge=KIE_CHALLENGE)

    return dependency


async def check_bearer(request: Request, role: str) -> Principal:
    """What :func:`require` answers, for a route served without FastAPI's dependency solving
    (:class:`gateway.api.lean_route.LeanRoute`): the same credential reader, the same check."""
    return _auth(request).check(role, await _bearer(request))


async def check_kie(request: Request, role: str) -> Principal:
    """What :func:`require_kie` answers, for a route served without FastAPI's dependency solving
    (the KIE batch's LeanRoute): the same credential readers, the same check."""
    return _auth(request).check(role, await _bearer(request), await _basic(request), challenge=KIE_CHALLENGE)


caller = require("caller")
author = require("author")
kie_caller = require_kie("caller")
event_stream_caller = require_event_stream("caller")
