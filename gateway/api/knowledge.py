"""``/api/knowledge/{ontology|swrl}``: read and replace the teahouse ontology and its SWRL rules live.

Why here: the owners' "Onto" and "SWRL" change requests (Table 2 #12-#16) are edits of these two
files. A replacement is checked first — the Turtle must parse and Pellet must accept ontology +
rules together — and only then written (atomically, the previous text kept under
``<data_dir>/knowledge/<kind>/``). The stream engine re-binds its ontology parameters and the
reasoner reloads on the file change, so the edit is live without a restart. A bad edit changes
nothing and answers 422 with the file, line and column.
"""

from __future__ import annotations

import hashlib
import os
import re
import shutil
import tempfile
import threading
import time
from pathlib import Path
from typing import Any, Literal

from fastapi import APIRouter, Depends, Request
from pydantic import BaseModel, ConfigDict, Field

from gateway.api.auth import Principal, author, caller
from gateway.api.errors import ApiError

router = APIRouter(tags=["knowledge"])
Kind = Literal["ontology", "swrl"]
MAX_TEXT = 2_000_000
_write_lock = threading.Lock()


class KnowledgeBody(BaseModel):
    """The new full text of the file, and why it changed."""

    model_config = ConfigDict(extra="forbid")
    text: str = Field(max_length=MAX_TEXT)
    comment: str = Field(default="", max_length=2000)
    base_hash: str | None = Field(default=None, description="Hash of the text the edit started from (409 if it changed).")


def _paths(request: Request) -> dict[str, Path]:
    cfg = request.app.state.settings.streams
    return {"ontology": Path(cfg.ontology_file), "swrl": Path(cfg.swrl_file)}


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ApiError(500, f"cannot read {path}: {exc.strerror or exc}") from None


@router.get("/api/knowledge/{kind}")
def get_knowledge(kind: Kind, request: Request, _: Principal = Depends(caller)) -> dict[str, Any]:
    """The current text of the ontology (Turtle) or the SWRL rules, with its hash."""
    path = _paths(request)[kind]
    text = _read(path)
    return {"kind": kind, "file": path.name, "text": text, "hash": _digest(text)}


@router.put("/api/knowledge/{kind}")
def put_knowledge(kind: Kind, body: KnowledgeBody, request: Request, who: Principal = Depends(author)) -> dict[str, Any]:
    """Check, then replace the ontology or the SWRL rules; live at once."""
    started = time.perf_counter()
    paths = _paths(request)
    path = paths[kind]
    with _write_lock:
        current = _read(path)
        if body.base_hash is not None and body.base_hash != _digest(current):
            raise ApiError(409, "base version changed", current=_digest(current))
        errors = check_knowledge(kind, body.text, paths)
        if errors:
            raise ApiError(422, f"{path.name} rejected: {errors[0]['message']}", errors=errors)
        backup = _keep_previous(request, kind, path, current, who.name, body.comment)
        _write_atomic(path, body.text)
    store = getattr(request.app.state, "store", None)
    if store is not None:
        store.record("knowledge_events", {"kind": kind, "file": path.name, "by": who.name, "comment": body.comment,
                                          "hash": _digest(body.text), "previous": str(backup)},
                     stored_type=f"printeps/Knowledge/{kind}", inserted_by="gateway")
    return {"kind": kind, "file": path.name, "hash": _digest(body.text),
            "duration_ms": round((time.perf_counter() - started) * 1000, 1)}


@router.get("/api/knowledge/{kind}/history")
def knowledge_history(kind: Kind, request: Request, _: Principal = Depends(caller)) -> list[dict[str, Any]]:
    """Earlier texts kept on each replacement (newest first)."""
    folder = _history_dir(request, kind)
    if not folder.is_dir():
        return []
    return [{"file": p.name, "hash": _digest(p.read_text(encoding="utf-8"))} for p in sorted(folder.iterdir(), reverse=True)]


def check_knowledge(kind: str, text: str, paths: dict[str, Path]) -> list[dict[str, Any]]:
    """Errors of a candidate text, as [{"file", "line", "column", "message"}] ([] = acceptable).

    The candidate is checked together with the other file as it is now, by the same reasoner that
    serves ``/api/reason`` (Turtle parsing with rdflib, the rules loaded into owlready2, Pellet run).
    """
    from gateway.ontology.reasoner import Reasoner, ReasonerError

    name = paths[kind].name
    if "\x00" in text:
        return [{"file": name, "line": 0, "column": 0, "message": "binary content is not an ontology or SWRL text"}]
    with tempfile.TemporaryDirectory(prefix="printeps-knowledge-") as tmp:
        onto = Path(tmp) / paths["ontology"].name
        swrl = Path(tmp) / paths["swrl"].name
        shutil.copyfile(paths["ontology"], onto)
        shutil.copyfile(paths["swrl"], swrl)
        (onto if kind == "ontology" else swrl).write_text(text, encoding="utf-8")
        try:
            Reasoner(onto, swrl).reason(None)
        except ReasonerError as exc:
            return [_position(exc, name, tmp)]
    return []


def _position(exc: Any, name: str, tmp: str) -> dict[str, Any]:
    """file/line/column from a ReasonerError (``where`` = "path:line"; rdflib says "at line N")."""
    where = str(exc.where or "")
    message = str(exc.message).replace(tmp + os.sep, "")
    line = column = 0
    match = re.search(r":(\d+)$", where)
    if match:
        line = int(match.group(1))
    else:
        match = re.search(r"line (\d+)(?:[^\d]+(?:col(?:umn)?|char) (\d+))?", message)
        if match:
            line = int(match.group(1))
            column = int(match.group(2) or 0)
    return {"file": name, "line": line, "column": column, "message": message}


def _history_dir(request: Request, kind: str) -> Path:
    return Path(request.app.state.settings.data_dir) / "knowledge" / kind


def _keep_previous(request: Request, kind: str, path: Path, text: str, who: str, comment: str) -> Path:
    folder = _history_dir(request, kind)
    folder.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%dT%H%M%S", time.gmtime()) + f"{time.time() % 1:.3f}"[1:]
    backup = folder / f"{stamp}-{re.sub(r'[^A-Za-z0-9_-]', '_', who)}{path.suffix}"
    backup.write_text(text, encoding="utf-8")
    return backup


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
