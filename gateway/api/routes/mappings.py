"""``/api/mappings``: how messages become RDF, as data — listed, checked, changed and versioned.

A mapping (``subject``, ``type``, ``fields``, ``timed``, ``children``; see
:mod:`gateway.rdf.mapping`) names the message type it is for (``message_type``); when the ROS
packages are installed a change is checked against that type's fields, so a mapping that names a
field the type lacks is refused with the field and the type. Changes are stored in the Information
State and followed by every gateway process; ``ontology/mappings/*.yaml`` only seed it.

    GET    /api/mappings                 names, versions and message types
    GET    /api/mappings/{name}          {"name", "version", "spec", "text"} (text: the spec as YAML)
    PUT    /api/mappings/{name}          {"spec": {...} | "text": "<YAML>", "comment", "base_version"}
                                         -> 201 {name, version}; 409 when base_version is stale
    POST   /api/mappings/validate        {"spec": {...} | "text": "<YAML>"} -> {"ok", "errors"}
    POST   /api/mappings/{name}/preview  {"message": {...}, "timestamp": ms, "spec"|"text"?} -> the triples
                                         it makes (with the draft spec when one is given)
    DELETE /api/mappings/{name}          no longer served (messages for it are rejected); history kept
    GET    /api/mappings/{name}/versions
    GET    /api/mappings/{name}/versions/{version}  {"version", …, "spec", "text", "current"}
    POST   /api/mappings/{name}/rollback {"version"}

A spec given as YAML ``text`` gets ``line`` and ``column`` on its errors: those of the key the
error names (``where``), or of a YAML syntax error.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Author, Caller, MappingsDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.rdf.mapping import Mapper, MappingError
from gateway.rdf.spec_text import SpecSyntaxError, SpecText, read_spec_text, spec_to_text
from gateway.base.versions import CatalogConflict

router = APIRouter(tags=["streams"], route_class=JsonRoute)
MappingName = Annotated[str, PathParam(pattern=r"^[A-Za-z][A-Za-z0-9_.:-]{0,63}$")]


class DraftBody(BaseModel):
    """A mapping as data (``spec``) or as the YAML an author wrote (``text``)."""

    model_config = ConfigDict(extra="forbid")
    spec: dict[str, Any] | None = None
    text: str | None = Field(default=None, max_length=200_000)

    def draft(self) -> tuple[dict[str, Any], SpecText | None]:
        """The spec and, for text, where its keys are; 422 with line/column for text that is not YAML."""
        if (self.spec is None) == (self.text is None):
            raise ApiError(422, "give exactly one of 'spec' (an object) or 'text' (YAML)", field="spec")
        if self.text is None:
            return self.spec, None  # type: ignore[return-value]
        try:
            parsed = read_spec_text(self.text)
        except SpecSyntaxError as exc:
            raise ApiError(422, exc.message, field="text", where="mapping", line=exc.line, column=exc.column) from None
        return parsed.spec, parsed


class SpecBody(DraftBody):
    comment: str = Field(default="", max_length=2000)
    base_version: int | None = Field(default=None, ge=0)


class PreviewBody(DraftBody):
    message: dict[str, Any]
    timestamp: int = Field(default=0, ge=0)


class RollbackBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    version: int = Field(ge=1)


def _located(exc: MappingError, text: SpecText | None) -> dict[str, Any]:
    """An error's JSON fields: where, message, and the line/column of that key in the author's text."""
    out: dict[str, Any] = {"where": exc.where, "message": exc.message}
    if text is not None:
        line, column = text.locate(exc.where)
        if line:
            out.update(line=line, column=column)
    return out


def _refused(exc: MappingError, text: SpecText | None) -> ApiError:
    fields = _located(exc, text)
    return ApiError(422, fields.pop("message"), **fields)


@router.get("/api/mappings")
def list_mappings(mappings: MappingsDep, _: Caller) -> JSON:
    out = []
    for name in mappings.names():
        item = mappings.get(name)
        out.append({"name": name, "version": item["version"], "message_type": item["spec"].get("message_type")})
    return JSON(out)


@router.post("/api/mappings/validate")
def validate_mapping(body: DraftBody, mappings: MappingsDep, _: Caller) -> JSON:
    try:
        spec, text = body.draft()
    except ApiError as exc:
        return JSON({"ok": False, "errors": [{"message": exc.message, **exc.extra}]})
    try:
        mappings.check("(draft)", spec)
    except MappingError as exc:
        return JSON({"ok": False, "errors": [_located(exc, text)]})
    return JSON({"ok": True, "errors": []})


@router.get("/api/mappings/{name}")
def get_mapping(name: MappingName, mappings: MappingsDep, _: Caller) -> JSON:
    try:
        found = mappings.get(name)
    except MappingError as exc:
        raise ApiError(404, exc.message) from None
    return JSON({**found, "text": spec_to_text(found["spec"])})


@router.put("/api/mappings/{name}", status_code=201)
def put_mapping(name: MappingName, body: SpecBody, mappings: MappingsDep, who: Author) -> JSON:
    """Check and make live; 422 naming the key (with its line/column in ``text``), or the field and
    the message type; 409 when ``base_version`` is not current any more."""
    spec, text = body.draft()
    try:
        info = mappings.replace(name, spec, author=who.name, comment=body.comment, base_version=body.base_version)
    except CatalogConflict as exc:
        raise ApiError(409, "base version changed: someone saved this mapping meanwhile", current=exc.current) from None
    except MappingError as exc:
        raise _refused(exc, text) from None
    return JSON({"name": name, "version": info.version}, status_code=201)


@router.post("/api/mappings/{name}/preview")
def preview(name: MappingName, body: PreviewBody, mappings: MappingsDep, _: Caller) -> JSON:
    """The triples ``message`` becomes with this mapping, or with the draft given as ``spec``/``text``
    (nothing is stored, nothing is pushed on any stream)."""
    if body.spec is None and body.text is None:
        if name not in mappings.mapper.mappings:
            raise ApiError(404, f"no mapping named {name!r}")
        mapper, used = mappings.mapper, name
    else:
        spec, text = body.draft()
        try:
            node = mappings.check(name, spec)
        except MappingError as exc:
            raise _refused(exc, text) from None
        mapper, used = Mapper({"(draft)": node}, prefixes=mappings.mapper.prefixes), "(draft)"
    triples = mapper.map(body.message, body.timestamp, used)
    return JSON({"triples": [[str(t) for t in triple] for triple in triples]})


@router.get("/api/mappings/{name}/versions/{version}")
def mapping_version(name: MappingName, version: int, mappings: MappingsDep, _: Caller) -> JSON:
    try:
        found = mappings.version(name, version)
    except MappingError as exc:
        raise ApiError(404, exc.message) from None
    return JSON({**found, "text": spec_to_text(found["spec"])})


@router.post("/api/mappings/{name}/rollback")
def rollback_mapping(name: MappingName, body: RollbackBody, mappings: MappingsDep, who: Author) -> JSON:
    """Make a stored version current again; 404 for an unknown version, 422 if it no longer checks."""
    if not mappings.versions(name):
        raise ApiError(404, f"no stored mapping named {name!r}")
    try:
        info = mappings.rollback(name, body.version, author=who.name)
    except MappingError as exc:
        raise ApiError(404 if "has no version" in exc.message else 422, exc.message, where=exc.where) from None
    return JSON({"name": name, "version": info.version})


@router.delete("/api/mappings/{name}")
def delete_mapping(name: MappingName, mappings: MappingsDep, who: Author) -> JSON:
    try:
        mappings.delete(name, author=who.name)
    except MappingError as exc:
        raise ApiError(404, exc.message) from None
    return JSON({"name": name, "deleted": True})


@router.get("/api/mappings/{name}/versions")
def mapping_versions(name: MappingName, mappings: MappingsDep, _: Caller) -> JSON:
    infos = mappings.versions(name)
    if not infos:
        raise ApiError(404, f"no stored mapping named {name!r}")
    return JSON([i.to_dict() for i in infos])
