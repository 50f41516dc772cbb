"""The knowledge editor's REST API: the class tree, individuals with typed values (asserted and
inferred), one value changed, SWRL rules one at a time (read, check, replace, add), and "what does
this infer for …".

Why next to ``/api/knowledge/{kind}``: these are small edits of the same two texts. Each one becomes
a new whole text handed to the knowledge base, so it is checked by Pellet, versioned (history,
rollback on ``/api/knowledge/{ontology|swrl}/...``), live at once and followed by every process.
Invalid input answers 422 naming the field (``errors: [{field, message, ...}]``) and changes nothing.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Annotated, Any

from fastapi import APIRouter
from fastapi import Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Author, Caller, KnowledgeDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.ontology.editor import KnowledgeEditor
from gateway.ontology.knowledge import KnowledgeConflict, KnowledgeInvalid
from gateway.ontology.reasoner import ReasonerError
from gateway.ontology.values import ValueInvalid

router = APIRouter(tags=["knowledge editor"], route_class=JsonRoute)
Name = Annotated[str, PathParam(min_length=1, max_length=200, pattern=r"^[A-Za-z_][\w.-]*$")]
RuleNumber = Annotated[int, PathParam(ge=1, le=100_000)]


class ValueBody(BaseModel):
    """The new value of one data property of one individual (checked against its xsd type)."""

    model_config = ConfigDict(extra="forbid")
    value: str | float | int | bool | None
    comment: str = Field(default="", max_length=2000)
    base_hash: str | None = Field(default=None, description="Hash of the ontology text the edit started from (409 if it changed).")


class RuleBody(BaseModel):
    """One SWRL rule, one line: ``body atoms -> head atoms``."""

    model_config = ConfigDict(extra="forbid")
    text: str = Field(max_length=20_000)
    comment: str = Field(default="", max_length=2000)
    base_hash: str | None = Field(default=None, description="Hash of the rules text the edit started from (409 if it changed).")


class RuleCheckBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    text: str = Field(max_length=20_000)


class IndividualBody(BaseModel):
    """A new individual: ``{"name": "oolongTea", "class": "Beverage", "values": {"label": "oolong tea"}}``."""

    model_config = ConfigDict(extra="forbid", populate_by_name=True)
    name: str = Field(min_length=1, max_length=200)
    class_: str = Field(alias="class", min_length=1, max_length=200)
    values: dict[str, str | float | int | bool | None] = Field(
        default_factory=dict, description="Data property -> value (type-checked); 'label' is the rdfs:label")
    comment: str = Field(default="", max_length=2000)


class TryBody(BaseModel):
    """A new individual that is not stored: ``{"id": "kid", "types": ["Customer"], "properties": {"age": 6}}``."""

    model_config = ConfigDict(extra="forbid")
    individual: dict[str, Any]


def _conflict(exc: KnowledgeConflict) -> ApiError:
    return ApiError(409, f"{exc}: reload and edit again", current=exc.current_hash, version=exc.current_version)


@router.get("/api/knowledge/classes")
def classes(knowledge: KnowledgeDep, _: Caller) -> JSON:
    """The class tree (subclasses nested), each class with its asserted individuals."""
    return JSON(KnowledgeEditor(knowledge).classes())


@router.get("/api/knowledge/individuals")
def individuals(knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Every individual with its types and data values (``datatype`` = xsd type; ``inferred`` values
    come from the SWRL rules, with the rules that conclude them), and the properties with ranges."""
    return JSON(KnowledgeEditor(knowledge).individuals())


@contextmanager
def _edit_refusals(what: str, field: str) -> Iterator[None]:
    """An edit's refusals as the API answers them: a bad value 422 naming its field, a value Pellet
    finds inconsistent 422 on ``field`` (each reason), a stale base 409."""
    try:
        yield
    except ValueInvalid as exc:
        raise ApiError(422, exc.message, field=exc.field, errors=[exc.to_dict()]) from None
    except KnowledgeInvalid as exc:
        raise ApiError(422, f"{what}: {exc.errors[0]['message']}", field=field,
                       errors=[{"field": field, **e} for e in exc.errors]) from None
    except KnowledgeConflict as exc:
        raise _conflict(exc) from None


@router.post("/api/knowledge/individuals", status_code=201)
def add_individual(body: IndividualBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Add an individual of a class with its values (Pellet-checked, versioned, live at once): a new
    ``Beverage`` with its ``label`` can be ordered by talking to Pepper straight away."""
    with _edit_refusals(body.name, "values"):
        info, added = KnowledgeEditor(knowledge).add_individual(body.name, body.class_, body.values, author=who.name,
                                                                comment=body.comment)
    return JSON({**added, "version": info.version}, status_code=201)


@router.get("/api/knowledge/individuals/{name}")
def individual(name: Name, knowledge: KnowledgeDep, _: Caller) -> JSON:
    return JSON(KnowledgeEditor(knowledge).individual(name))


@router.put("/api/knowledge/individuals/{name}/values/{prop}")
def put_value(name: Name, prop: Name, body: ValueBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Change one data value: type-checked, written into the ontology text, Pellet-checked, saved as
    a new ontology version, live at once (workflows' ``ontology_value`` steps see it)."""
    with _edit_refusals(f"{name}.{prop}", "value"):
        info, value = KnowledgeEditor(knowledge).set_value(name, prop, body.value, author=who.name,
                                                           comment=body.comment, base_hash=body.base_hash)
    return JSON({**value, "version": info.version, "comment": info.comment})


@router.get("/api/knowledge/individuals/{name}/inferred")
def inferred(name: Name, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """What Pellet infers for an individual: types and values, each with the rule (or axiom) behind it."""
    return JSON(KnowledgeEditor(knowledge).explain(name))


@router.post("/api/knowledge/try")
def try_individual(body: TryBody, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """What Pellet would infer for a new individual (nothing is stored)."""
    try:
        return JSON(KnowledgeEditor(knowledge).try_individual(body.individual))
    except ReasonerError as exc:
        where = exc.where.replace("individuals[0]", "individual") if exc.where else "individual"
        raise ApiError(exc.status, exc.message, where=where, errors=[{"field": where, "message": exc.message}]) from None


@router.get("/api/knowledge/swrl/rules")
def rules(knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Every SWRL rule: number, line, text, comment, the rule in words and its atoms."""
    return JSON(KnowledgeEditor(knowledge).rules())


@router.post("/api/knowledge/swrl/rules/check")
def check_new_rule(body: RuleCheckBody, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Check a new rule (added at the end) with Pellet; changes nothing."""
    editor = KnowledgeEditor(knowledge)
    errors, _text = editor.check_rule(None, body.text)
    return JSON({"ok": not errors, "errors": errors, "changes": editor.last_changes})


@router.post("/api/knowledge/swrl/rules", status_code=201)
def add_rule(body: RuleBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Add a rule at the end of the rules (checked, versioned, live)."""
    saved = _save_rule(knowledge, None, body, who.name)
    saved.status_code = 201
    return saved


@router.get("/api/knowledge/swrl/rules/{number}")
def rule(number: RuleNumber, knowledge: KnowledgeDep, _: Caller) -> JSON:
    return JSON(KnowledgeEditor(knowledge).rule(number))


@router.post("/api/knowledge/swrl/rules/{number}/check")
def check_rule(number: RuleNumber, body: RuleCheckBody, knowledge: KnowledgeDep, _: Caller) -> JSON:
    """Check rule ``number`` replaced by ``text``, with Pellet and everything else as it is now; changes
    nothing. Errors name the rule, line, column and atom; ``changes`` lists the inferred values of the
    ontology's individuals the rule would change (``{"value", "before", "after"}``)."""
    editor = KnowledgeEditor(knowledge)
    errors, _text = editor.check_rule(number, body.text)
    return JSON({"ok": not errors, "errors": errors, "changes": editor.last_changes})


@router.put("/api/knowledge/swrl/rules/{number}")
def put_rule(number: RuleNumber, body: RuleBody, knowledge: KnowledgeDep, who: Author) -> JSON:
    """Replace rule ``number`` (checked by Pellet, saved as a new version of the rules, live at once)."""
    return _save_rule(knowledge, number, body, who.name)


def _save_rule(knowledge: Any, number: int | None, body: RuleBody, author: str) -> JSON:
    editor = KnowledgeEditor(knowledge)
    try:
        info, saved_number = editor.save_rule(number, body.text, author=author, comment=body.comment,
                                              base_hash=body.base_hash)
    except KnowledgeInvalid as exc:
        raise ApiError(422, exc.errors[0]["message"], errors=exc.errors) from None
    except KnowledgeConflict as exc:
        raise _conflict(exc) from None
    return JSON({**editor.rule(saved_number), "version": info.version})
