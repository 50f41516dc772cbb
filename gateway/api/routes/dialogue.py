"""``/api/dialogue``: Pepper takes the order by talking — turns by text or WAV audio, the
conversations going on, the completed orders, the menu and grammar the recogniser listens with,
and the simulated Pepper's voice.

Why a thin route: the conversation lives in :class:`gateway.dialogue.service.DialogueService`
(one stateful session of the dialogue rules per conversation, its state in the Information State);
this only checks the body, decodes the audio and maps refusals: bad input -> 422 naming the field,
too many turns at once or the Information State away -> 503 with ``Retry-After``, too many
conversations -> 429.
"""

from __future__ import annotations

import base64
import binascii
from typing import Annotated, Any

from fastapi import APIRouter, Query
from fastapi.responses import Response
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, GatewayDep, StoreDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute, run_blocking
from gateway.dialogue.records import RecordsUnavailable
from gateway.dialogue.service import ORDERS, DialogueBusy, DialogueRefused
from gateway.dialogue.speech import SpeechUnavailable, VoiceUnknown, synthesise

router = APIRouter(tags=["dialogue"], route_class=JsonRoute)


class TurnBody(BaseModel):
    """What a customer said at a table: ``text``, or ``audio`` (base64 of a 16-bit PCM WAV file)."""

    model_config = ConfigDict(extra="forbid")
    conversation: str = Field(min_length=1, max_length=100, description="The conversation (one per table), e.g. table1")
    text: str | None = Field(default=None, description="What the customer said, as text")
    audio: str | None = Field(default=None, description="What the customer said, as base64 WAV (16-bit PCM)")
    table: str | None = Field(default=None, max_length=128, description="Where the customer sits (default: the conversation)")


class SpeechBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    text: str = Field(min_length=1, max_length=500)
    voice: str | None = Field(default=None, max_length=40, pattern=r"^[A-Za-z0-9_+-]+$")
    speed: int = Field(default=160, ge=80, le=400, description="Words per minute")


def _service(gateway: Any) -> Any:
    if gateway.dialogue is None:
        raise ApiError(503, "the dialogue is not running on this gateway")
    return gateway.dialogue


def _audio(body: TurnBody, limit: int) -> bytes | None:
    if body.audio is None:
        return None
    if len(body.audio) > limit:
        raise ApiError(422, f"audio: {len(body.audio)} bytes of base64, at most {limit} (dialogue.max_audio_bytes)",
                       field="audio")
    try:
        return base64.b64decode(body.audio, validate=True)
    except (binascii.Error, ValueError):
        raise ApiError(422, "audio: not base64 (send the WAV file's bytes in base64)", field="audio") from None


@router.post("/api/dialogue/turns")
async def turn(body: TurnBody, gateway: GatewayDep, _: Caller) -> JSON:
    """One turn of a conversation: what was heard, the intent, the order's slots, Pepper's actions,
    the conversation's state and the decision that recorded the turn."""
    service = _service(gateway)
    audio = _audio(body, service.settings.max_audio_bytes)
    try:
        answer = await run_blocking(lambda: service.turn(body.conversation, text=body.text, audio=audio, table=body.table))
    except DialogueRefused as exc:
        raise ApiError(422, exc.message, field=exc.field) from None
    except DialogueBusy as exc:
        raise ApiError(exc.status, str(exc), headers={"Retry-After": "1"}) from None
    except SpeechUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    return JSON(answer)


@router.get("/api/dialogue/conversations")
def conversations(gateway: GatewayDep, _: Caller) -> JSON:
    """The conversations going on (state, turns, idle time) and the last state of finished ones."""
    service = _service(gateway)
    try:
        return JSON({"going_on": service.conversations(), "finished": list(service.finished.values())})
    except RecordsUnavailable as exc:
        raise ApiError(503, str(exc), headers={"Retry-After": "1"}) from None


@router.get("/api/dialogue/orders")
def orders(store: StoreDep, _: Caller, limit: Annotated[int, Query(ge=1, le=1000)] = 50) -> JSON:
    """The completed orders, newest first (``orders`` in the Information State)."""
    docs = store.query(ORDERS, limit=limit)
    return JSON({"orders": [{k: v for k, v in d.items() if k not in ("_id", "_meta")} for d in docs]})


@router.get("/api/dialogue/menu")
def menu(gateway: GatewayDep, _: Caller) -> JSON:
    """The drinks customers can order: the ontology's Beverage individuals, with their words."""
    drinks = _service(gateway).menu().drinks
    return JSON({"drinks": [{"individual": d.individual, "label": d.label, "plural": d.plural,
                             "pronunciations": dict(d.pronunciations)} for d in drinks]})


@router.get("/api/dialogue/grammar")
def grammar(gateway: GatewayDep, _: Caller) -> JSON:
    """The JSGF grammar the recogniser listens with (from the understanding rules and the menu),
    and the words given a pronunciation from their letters."""
    service = _service(gateway)
    built = service.grammar()
    return JSON({"jsgf": built.jsgf, "words": sorted(built.words), "spelled": dict(service.recogniser.spelled)})


@router.post("/api/dialogue/speech", response_class=Response,
             responses={200: {"content": {"audio/wav": {}}, "description": "WAV audio"}})
async def speech(body: SpeechBody, gateway: GatewayDep, _: Caller) -> Response:
    """``text`` in the simulated Pepper's voice (espeak-ng), as a WAV file the workbench can play."""
    voice = body.voice or _service(gateway).settings.voice
    try:
        wav = await run_blocking(lambda: synthesise(body.text, voice, body.speed))
    except VoiceUnknown as exc:
        raise ApiError(422, str(exc), field="voice") from None
    except SpeechUnavailable as exc:
        raise ApiError(503, str(exc)) from None
    return Response(wav, media_type="audio/wav")
