"""``/api/knowledge/{ontology|swrl}``: read, check and replace the teahouse ontology and its SWRL
rules live, with versions, history and rollback; ``/api/reason`` runs Pellet on them.

Why here: the owners' "Onto" and "SWRL" change requests (Table 2 #12-#16) are edits of these two
texts. A replacement is checked first — the Turtle must parse and Pellet must accept ontology +
rules together — and only then stored as a new version in the Information State, live at once in
this process and within a second in every other one (:mod:`gateway.ontology.knowledge`). A bad
edit changes nothing and answers 422 with the file, line and column.
"""

from __future__ import annotations

import time
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Path as PathParam, Request
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from gateway.api.deps import Author, Caller, KnowledgeDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute, read_json
from gateway.ontology.knowledge import KnowledgeConflict, KnowledgeInvalid, digest
from gateway.ontology.reasoner import ReasonerError
from gateway.base.versions import VersionMissing

router = APIRouter(tags=["knowledge"], route_class=JsonRoute)
Kind = Literal["ontology", "swrl"]
MAX_TEXT = 2_000_000


class KnowledgeBody(BaseModel):
    """The new full text, and why it changed."""

    model_config = ConfigDict(extra="forbid")
    text: str = Field(max_length=MAX_TEXT)
    comment: str = Field(default="", max_length=2000)
    base_hash: str | None = Field(default=None, description="Hash of the text the edit started from (409 if it changed).")
    base_version: int | None = Field(default=None, ge=0, description="Version the edit started from (409 if stale).")


class CheckBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    text: str = Field(max_length=MAX_TEXT)


class RollbackBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    version: int = Field(ge=1)
    comment: str = Field(default="", max_length=2000)


def _described(knowledge: Any, kind: str) -> dict[str, Any]:
    text = knowledge.text(kind)
    info = knowledge.info(kind)
    return {"kind": kind, "file": knowledge.files[kind], "text": text, "hash": digest(text),
            **({"version": info.version, "deployed_at": info.deployed_at, "author": info.author,
                "comment": info.comment} if info else {"version": None})}


@router.get("/api/knowledge/values")
def values(knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Every ``individual.property`` value of the ontology, asserted or inferred by the SWRL rules
    (what workflows' ``ontology_value`` steps and the queries' parameters read)."""
    return JSON({"version": knowledge.version, "values": knowledge.values()})


@router.get("/api/knowledge/{kind}")
def get_knowledge(kind: Kind, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """The current text of the ontology (Turtle) or the SWRL rules, with its hash and version."""
    return JSON(_described(knowledge, kind))


@router.put("/api/knowledge/{kind}")
def put_knowledge(kind: Kind, body: KnowledgeBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Check, then replace the ontology or the SWRL rules; live at once, on every gateway process."""
    started = time.perf_counter()
    try:
        info = knowledge.replace(kind, body.text, author=who.name, comment=body.comment, base_hash=body.base_hash,
                                 base_version=body.base_version)
    except KnowledgeConflict as exc:
        raise ApiError(409, "base version changed", current=exc.current_hash, version=exc.current_version) from None
    except KnowledgeInvalid as exc:
        raise ApiError(422, str(exc), errors=exc.errors) from None
    return JSON({"kind": kind, "file": knowledge.files[kind], "hash": digest(body.text), "version": info.version,
                 "duration_ms": round((time.perf_counter() - started) * 1000, 1)})


@router.post("/api/knowledge/{kind}/check")
def check_knowledge(kind: Kind, body: CheckBody, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Check a candidate text with Pellet (together with the other text as it is now); changes nothing."""
    errors = knowledge.check(kind, body.text)
    return JSON({"ok": not errors, "errors": errors})


@router.get("/api/knowledge/{kind}/versions")
def knowledge_versions(kind: Kind, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Every kept version, oldest first."""
    return JSON([i.to_dict() for i in knowledge.versions(kind)])


@router.get("/api/knowledge/{kind}/versions/{version}")
def knowledge_version(kind: Kind, version: Annotated[int, PathParam(ge=1)], knowledge: KnowledgeDep, _: Caller) -> JSON:
    try:
        info, text = knowledge.version_text(kind, version)
    except VersionMissing as exc:
        raise ApiError(404, str(exc)) from None
    return JSON({**info.to_dict(), "kind": kind, "text": text, "hash": digest(text)})


@router.get("/api/knowledge/{kind}/history")
def knowledge_history(kind: Kind, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Every change (deploy, rollback), newest first, with author and comment."""
    return JSON(list(reversed(knowledge.history(kind))))


@router.post("/api/knowledge/{kind}/rollback")
def rollback_knowledge(kind: Kind, body: RollbackBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Make an earlier version current again (checked by Pellet first, like any edit)."""
    try:
        info = knowledge.rollback(kind, body.version, author=who.name, comment=body.comment)
    except VersionMissing as exc:
        raise ApiError(404, str(exc)) from None
    except KnowledgeInvalid as exc:
        raise ApiError(422, str(exc), errors=exc.errors) from None
    return JSON({"kind": kind, "version": info.version})


@router.post("/api/reason")
async def reason(request: Request, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Pellet + SWRL over the ontology and the posted individuals (JSON or text/turtle)."""
    if "json" in request.headers.get("content-type", "application/json"):
        data: Any = await read_json(request)
    else:
        data = (await request.body()).decode("utf-8", errors="replace")
    try:
        return JSON(await run_in_threadpool(knowledge.reason, data))
    except ReasonerError as exc:
        raise ApiError(exc.status, exc.message, where=exc.where) from None
