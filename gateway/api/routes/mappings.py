"""``/api/mappings``: how messages become RDF, as data — listed, checked, changed and versioned.

A mapping (``subject``, ``type``, ``fields``, ``timed``, ``children``; see
:mod:`gateway.rdf.mapping`) names the message type it is for (``message_type``); when the ROS
packages are installed a change is checked against that type's fields, so a mapping that names a
field the type lacks is refused with the field and the type. Changes are stored in the Information
State and followed by every gateway process; ``ontology/mappings/*.yaml`` only seed it.

    GET    /api/mappings                 names, versions and message types
    GET    /api/mappings/{name}          {"name", "version", "spec"}
    PUT    /api/mappings/{name}          {"spec": {...}, "comment", "base_version"} -> 201 {name, version}
    POST   /api/mappings/validate        {"spec": {...}} -> {"ok", "errors"}
    POST   /api/mappings/{name}/preview  {"message": {...}, "timestamp": ms} -> the triples it makes
    DELETE /api/mappings/{name}          back to the built-in of that name, if any
    GET    /api/mappings/{name}/versions
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Author, Caller, MappingsDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON
from gateway.rdf.mapping import MappingError
from gateway.versions import CatalogConflict

router = APIRouter(tags=["streams"])
MappingName = Annotated[str, PathParam(pattern=r"^[A-Za-z][A-Za-z0-9_.:-]{0,63}$")]


class SpecBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    spec: dict[str, Any]
    comment: str = Field(default="", max_length=2000)
    base_version: int | None = Field(default=None, ge=0)


class PreviewBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    message: dict[str, Any]
    timestamp: int = Field(default=0, ge=0)


@router.get("/api/mappings")
def list_mappings(mappings: MappingsDep, _: Caller) -> JSON:
    out = []
    for name in mappings.names():
        item = mappings.get(name)
        out.append({"name": name, "version": item["version"], "message_type": item["spec"].get("message_type")})
    return JSON(out)


@router.post("/api/mappings/validate")
def validate_mapping(body: SpecBody, mappings: MappingsDep, _: Caller) -> JSON:
    try:
        mappings.check("(draft)", body.spec)
    except MappingError as exc:
        return JSON({"ok": False, "errors": [{"where": exc.where, "message": exc.message}]})
    return JSON({"ok": True, "errors": []})


@router.get("/api/mappings/{name}")
def get_mapping(name: MappingName, mappings: MappingsDep, _: Caller) -> JSON:
    try:
        return JSON(mappings.get(name))
    except MappingError as exc:
        raise ApiError(404, exc.message) from None


@router.put("/api/mappings/{name}", status_code=201)
def put_mapping(name: MappingName, body: SpecBody, mappings: MappingsDep, who: Author) -> JSON:
    """Check and make live; 422 naming the key, or the field and the message type."""
    try:
        info = mappings.replace(name, body.spec, author=who.name, comment=body.comment, base_version=body.base_version)
    except CatalogConflict as exc:
        raise ApiError(409, "base version changed", current=exc.current) from None
    return JSON({"name": name, "version": info.version}, status_code=201)


@router.post("/api/mappings/{name}/preview")
def preview(name: MappingName, body: PreviewBody, mappings: MappingsDep, _: Caller) -> JSON:
    """The triples ``message`` becomes with this mapping (nothing is pushed on any stream)."""
    if name not in mappings.mapper.mappings:
        raise ApiError(404, f"no mapping named {name!r}")
    triples = mappings.mapper.map(body.message, body.timestamp, name)
    return JSON({"triples": [[str(t) for t in triple] for triple in triples]})


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
