"""Rule authoring over REST: run a rule set's test scenarios, gate deploys on them, and read/write
decision tables as grids for the workbench.

Why a module of its own: these routes only call the engine's authoring modules
(:mod:`gateway.engine.scenarios`, :mod:`gateway.engine.decision_table`); the deploy gate itself is
the engine's (``Engine.deploy`` refuses a red rule set unless forced). Routes:

* ``POST /api/rulesets/{name}/test`` — run the scenarios (``tests/*.yaml``) of draft ``files``, of
  ``version`` N, or of the current version: the report (green/red per scenario with expected and
  actual, coverage). 422 with located errors when the rules do not compile or a scenario file is
  malformed.
* ``POST /api/rulesets/{name}/tests/update`` — "Update the tests too": the draft's test files with
  the expectations its changed sentences or values broke rewritten in place (comments and layout
  kept), and the changes; scenarios red for another reason are left alone. Stores nothing.
* ``POST /api/decision-tables/read`` — a table file's text (CSV, or an .xlsx ``data:`` URL) as a grid.
* ``POST /api/decision-tables/write`` — the table file with one sheet's cells replaced.
"""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path as PathParam
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.deps import Caller, EngineDep
from gateway.api.errors import ApiError
from gateway.api.jsonio import JSON, JsonRoute
from gateway.engine import decision_table
from gateway.engine.ruleset import is_table_file
from gateway.engine.errors import RuleSetNotFound
from gateway.engine.scenarios import run_scenarios
from gateway.engine.test_update import update_tests

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"
RuleSetName = Annotated[str, PathParam(pattern=NAME_PATTERN, description="Rule set name (its folder name)")]
MAX_FILES = 500

router = APIRouter(tags=["rule authoring"], route_class=JsonRoute)


class TestBody(BaseModel):
    """What to test: draft ``files`` (as for validate/try), or a stored ``version``; neither: the
    current version."""

    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] | None = Field(default=None, max_length=MAX_FILES)
    version: int | None = Field(default=None, ge=1)


class TableBody(BaseModel):
    model_config = ConfigDict(extra="forbid")
    file: str = Field(description="The table's file name (.csv or .xlsx)")
    content: str = Field(description="The file's text as in `files` (CSV text, or the .xlsx data: URL)")


class TableWriteBody(TableBody):
    sheet: str = Field(description="The sheet whose cells are replaced")
    rows: list[list[str]] = Field(description="The sheet's cells, row by row (text, '' for empty)")
    merged: list[str] | None = Field(default=None, description="Merged ranges such as 'C8:E8' (default: kept)")


@router.post("/api/rulesets/{name}/test")
def test_ruleset(name: RuleSetName, engine: EngineDep, who: Caller, body: TestBody | None = None) -> JSON:
    """Run the rule set's test scenarios: ``{"ok", "summary", "passed", "failed", "errors",
    "results": [{name, file, line, status, failures, given, expected, actual}], "coverage":
    {"rules", "fired", "not_fired"}}``. Deploys nothing. For any role but developer the rule policy
    checks draft ``files`` first (422 ``{"kind": "policy"}``: nothing compiled, no scenario ran); a
    stored version runs as it serves."""
    body = body or TestBody()
    if body.files is not None and body.version is not None:
        raise ApiError(422, "give either 'files' (a draft) or 'version', not both")
    if body.files is not None:
        files, version, role = dict(body.files), None, who.role
    else:  # a stored version: its code was deployed (and so accepted) already; it runs on every fire
        stored = engine.version(name, body.version) if body.version is not None else engine.current(name)
        files, version, role = dict(stored.files), stored.info.version, None
    return JSON(run_scenarios(engine, files, name, version, role=role).to_dict())


class UpdateTestsBody(BaseModel):
    """The draft whose tests are to follow it."""

    model_config = ConfigDict(extra="forbid")
    files: dict[str, str] = Field(min_length=1, max_length=MAX_FILES)


@router.post("/api/rulesets/{name}/tests/update")
def update_ruleset_tests(name: RuleSetName, body: UpdateTestsBody, engine: EngineDep, _: Caller) -> JSON:
    """``{"files": {test file: updated text}, "changes": [{"scenario", "file", "line", "old", "new",
    "rule"}], "kept": [names of scenarios still red for another reason]}``. Only scenarios that fail
    solely because an expected value is one the draft changed (old value gone from the rules, new
    one in them, old one in the live version) are rewritten, at their line. Stores nothing."""
    try:
        base = dict(engine.current(name).files)
    except RuleSetNotFound:
        base = None
    return JSON(update_tests(engine, dict(body.files), name, base))


@router.post("/api/decision-tables/read")
def read_table(body: TableBody, _: Caller) -> JSON:
    """A decision table as a grid: ``{"file", "table_sheet", "sheets": [{"name", "rows", "merged"}]}``."""
    _check_table_name(body.file)
    try:
        return JSON(decision_table.grid(body.file, body.content))
    except ValueError as exc:
        raise ApiError(422, str(exc), errors=[{"file": body.file, "line": 0, "column": 0, "message": str(exc)}]) from None


@router.post("/api/decision-tables/write")
def write_table(body: TableWriteBody, _: Caller) -> JSON:
    """The table file with ``sheet``'s cells replaced by ``rows``: ``{"file", "content"}`` (nothing
    is stored: the result goes into the rule set's files like any edit)."""
    _check_table_name(body.file)
    try:
        content = decision_table.write_grid(body.file, body.content, body.sheet, body.rows, body.merged)
    except ValueError as exc:
        raise ApiError(422, str(exc), errors=[{"file": body.file, "line": 0, "column": 0, "message": str(exc)}]) from None
    return JSON({"file": body.file, "content": content})


def _check_table_name(file_name: str) -> None:
    if not is_table_file(file_name):
        raise ApiError(422, f"{file_name!r} is not a decision table file (.csv or .xlsx)")
