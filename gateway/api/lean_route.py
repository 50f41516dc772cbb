"""``LeanRoute``: a FastAPI route that FastAPI documents as usual but serves without solving dependencies.

Why: the REST fire and the KIE command batch are the gateway's hot path (goal: 1,500 recorded
fires/s on 2 cores). FastAPI 0.165 spends more CPU matching a request against every route of the
included routers and solving its dependencies than the engine spends firing it (measured
in-process, warm: 0.91 ms per fire request through a plain route, 0.46 ms without; ``engine.fire``
itself 0.29 ms). A LeanRoute is an ordinary :class:`fastapi.routing.APIRoute` — its endpoint's
signature gives the OpenAPI document its parameters and security — whose ASGI app calls the
endpoint directly with the arguments ``prepare(request)`` gives (the path parameter checked against
its pattern, the principal from :mod:`gateway.api.auth`). :func:`gateway.api.main.create_app`
places these routes first in the app's router, so they are matched before any other route, inside
the app's usual middleware and exception handlers. Each endpoint is defined once.
"""

from __future__ import annotations

from typing import Any, Awaitable, Callable

from fastapi.routing import APIRoute
from starlette.requests import Request
from starlette.responses import Response

Prepare = Callable[[Request], Awaitable[dict[str, Any]]]
OnError = Callable[[Request, Exception], Response]


class LeanRoute(APIRoute):
    """An APIRoute served by calling ``endpoint(**await prepare(request))``; an error goes to
    ``on_error`` when given (the KIE ``FAILURE`` answer), else to the app's exception handlers."""

    def __init__(self, path: str, endpoint: Callable[..., Any], *, prepare: Prepare, on_error: OnError | None = None,
                 **kwargs: Any) -> None:
        super().__init__(path, endpoint, **kwargs)
        self.prepare = prepare
        self.on_error = on_error
        self.app = self._serve  # instead of FastAPI's dependency-solving handler; matching is Starlette's

    async def _serve(self, scope: dict[str, Any], receive: Any, send: Any) -> None:
        request = Request(scope, receive)
        if self.on_error is None:
            response = await self.endpoint(**await self.prepare(request))
        else:
            try:
                response = await self.endpoint(**await self.prepare(request))
            except Exception as exc:
                response = self.on_error(request, exc)
        await response(scope, receive, send)
