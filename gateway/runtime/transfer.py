"""``printeps export DIR`` / ``printeps import DIR``: the Information State ↔ a folder, for git.

The Information State is the source of truth for everything an author changes; these two keep a
git-based workflow possible. The folder has the repository's seed layout, so an exported folder
can be committed, reviewed, edited and imported again (or used as the seed of a new gateway):

    rules/drl/<rule set>/<files>         workflows/<name>.yaml
    ontology/teahouse.ttl, .swrl         ontology/queries/<query>.rq + <query>.binding.yaml
    ontology/mappings/<name>.yaml

Export writes the current version of each item. Import makes every item whose content differs
from the current version a new version (author and comment given), through the same services —
and so the same checks — as a deploy over REST: a rule set that does not compile, a workflow that
does not validate, knowledge Pellet refuses, a query that does not parse are reported with file
and position and change nothing, while the other items are imported.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from gateway.base.versions import Catalog
from gateway.config import knowledge_files
from gateway.engine.ruleset import write_file
from gateway.stream.query import ParamSpec, parse_query
from gateway.stream.rules import RuleBinding
from gateway.workflow.loader import parse

RULES = Path("rules") / "drl"
WORKFLOWS = Path("workflows")
ONTOLOGY = Path("ontology")
QUERIES = ONTOLOGY / "queries"
MAPPINGS = ONTOLOGY / "mappings"


def _current(catalog: Catalog, kind: str) -> list[tuple[str, Any]]:
    out = []
    for head in catalog.heads(kind):
        if head.live:
            out.append((head.name, catalog.load(kind, head.name, head.current).payload))  # type: ignore[arg-type]
    return out


def seed_folders(settings: Any) -> dict[str, list[Path]]:
    """The folders a gateway with ``settings`` seeds from, by catalog kind: what a start passes to
    each service's ``seed(folder)`` (:mod:`gateway.base.lifecycle`) and where :func:`export_to`
    finds the seed files' names. One folder per kind (a list: none when a setting is None)."""
    streams = settings.streams
    return {"ruleset": [Path(settings.engine.rules_dir)],
            "knowledge": [Path(streams.knowledge_dir)] if streams.knowledge_dir else [],
            "workflow": [Path(settings.workflows.source_dir)],
            "query": [Path(streams.queries_dir)] if streams.queries_dir else [],
            "mapping": [Path(streams.mappings_dir)] if streams.mappings_dir else []}


def export_to(catalog: Catalog, folder: Path, seeds: dict[str, list[Path]] | None = None) -> list[str]:
    """Write the current version of everything into ``folder``; returns the files written.

    Files get the names and the bytes of the seed layout: an item a file in ``folder`` or in a seed
    folder (``seeds``, see :func:`seed_folders`) already holds is written under that file's name
    (``workflows/1_greeting.yaml`` for workflow ``greeting``, ``queries/customer_detection.rq`` for
    query ``CustomerDetectionQuery``), and a YAML file whose content is the item's as it is
    (a binding, a mapping) is written as that file's text, comments and all. Why: so export then
    import is the identity, and exporting into a copy of the repository changes only what changed
    (issue 32) — not a second file per item under another name.
    """
    written: list[str] = []
    seeds = seeds or {}

    def write(rel: Path, text: str) -> None:
        path = folder / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(str(rel))

    for name, files in _current(catalog, "ruleset"):
        for fname, text in sorted(files.items()):  # tests/<x>.yaml in tests/, a workbook as itself
            path = folder / RULES / name / fname
            path.parent.mkdir(parents=True, exist_ok=True)
            write_file(path, text)
            written.append(str(RULES / name / fname))
    workflow_files = _files_by_item([folder / WORKFLOWS, *seeds.get("workflow", [])], "*.yaml", _workflow_name)
    for name, payload in _current(catalog, "workflow"):
        write(WORKFLOWS / workflow_files.get(name, Path(f"{name}.yaml")).name, payload["text"])
    for name, payload in _current(catalog, "knowledge"):
        write(ONTOLOGY / payload.get("file", f"teahouse.{'ttl' if name == 'ontology' else 'swrl'}"), payload["text"])
    query_files = _files_by_item([folder / QUERIES, *seeds.get("query", [])], "*.rq", _query_name)
    for name, payload in _current(catalog, "query"):
        source = query_files.get(name)
        stem = source.stem if source is not None else name
        write(QUERIES / f"{stem}.rq", payload["text"])
        if payload.get("binding"):
            sidecar = source.with_name(f"{stem}.binding.yaml") if source is not None else None
            write(QUERIES / f"{stem}.binding.yaml", _same_yaml(sidecar, payload["binding"], _binding_of) or yaml.safe_dump(
                _plain_binding(payload["binding"]), sort_keys=False, allow_unicode=True))
        if payload.get("params"):
            write(QUERIES / f"{stem}.params.json", json.dumps(payload["params"], indent=1))
    mapping_dirs = [folder / MAPPINGS, *seeds.get("mapping", [])]
    for name, spec in _current(catalog, "mapping"):
        same = next((t for d in mapping_dirs if (t := _same_yaml(d / f"{name}.yaml", spec, lambda v: v)) is not None), None)
        write(MAPPINGS / f"{name}.yaml", same or yaml.safe_dump(spec, sort_keys=False, allow_unicode=True))
    return written


def _files_by_item(folders: list[Path], pattern: str, item_name: Any) -> dict[str, Path]:
    """Item name -> the first file (folders in order) that defines it; unreadable files are skipped."""
    out: dict[str, Path] = {}
    for folder in folders:
        if not folder.is_dir():
            continue
        for path in sorted(folder.glob(pattern)):
            try:
                name = item_name(path.read_text(encoding="utf-8"))
            except Exception:  # a file that does not parse names no item: it keeps its name, is not reused
                continue
            if name and name not in out:
                out[name] = path
    return out


def _workflow_name(text: str) -> str | None:
    document = yaml.safe_load(text)
    return document.get("workflow") if isinstance(document, dict) else None


def _query_name(text: str) -> str:
    return parse_query(text).name


def _binding_of(raw: Any) -> Any:
    return RuleBinding.from_dict(raw).to_dict()


def _same_yaml(path: Path | None, value: Any, normal: Any) -> str | None:
    """The text of YAML file ``path`` when it holds ``value`` (after ``normal``), else None."""
    if path is None or not path.is_file():
        return None
    try:
        text = path.read_text(encoding="utf-8")
        return text if normal(yaml.safe_load(text)) == value else None
    except Exception:  # unreadable or not that item's shape: written afresh
        return None


def _plain_binding(binding: dict[str, Any]) -> dict[str, Any]:
    """A binding without its defaults (what an author would write)."""
    defaults = {"mode": "stateless", "local_names": True, "constants": {}, "attributes": {}, "subject": None,
                "window_facts": [], "context": [], "suppress_repeats": None, "dispatch": True, "fields": None}
    return {k: v for k, v in binding.items() if k not in defaults or defaults[k] != v}


def import_from(gateway: Any, folder: Path, *, author: str, comment: str,
                role: str | None = None) -> list[tuple[str, str]]:
    """Import ``folder`` into the gateway's catalog; returns ``(item, outcome)`` lines, outcome
    "unchanged vN", "deployed vN" or "failed: <what and where>". Each rule set is deployed with
    ``role`` (an author's: the rule policy applies; None: the machine's own rights)."""
    report: list[tuple[str, str]] = []

    def attempt(item: str, action: Any) -> None:
        try:
            report.append((item, action()))
        except Exception as exc:  # every failure is reported with its item; the others go on
            report.append((item, f"failed: {_describe(exc)}"))

    rules = folder / RULES
    if rules.is_dir():
        for sub in sorted(p for p in rules.iterdir() if p.is_dir()):
            attempt(f"rule set {sub.name}",
                    lambda sub=sub: gateway.engine.import_folder(sub, author, comment, role=role))
    knowledge = gateway.knowledge
    for kind, files in knowledge_files(folder / ONTOLOGY).items():  # the seed folder's layout (streams.knowledge_dir)
        if len(files) > 1:
            report.append((f"{kind} {', '.join(p.name for p in files)}",
                           f"failed: {folder / ONTOLOGY} holds {len(files)} {kind} files: keep one"))
            continue
        for path in files:
            attempt(f"{kind} {path.name}", lambda kind=kind, path=path: _import_knowledge(knowledge, kind, path, author, comment))
    workflows = folder / WORKFLOWS
    if workflows.is_dir():
        for path in sorted(workflows.glob("*.yaml")):
            attempt(f"workflow {path.name}", lambda path=path: _import_workflow(gateway.workflows.registry, path, author, comment))
    mappings = folder / MAPPINGS
    if mappings.is_dir():
        for path in sorted(mappings.glob("*.yaml")):
            attempt(f"mapping {path.stem}", lambda path=path: _import_mapping(gateway.mappings, path, author, comment))
    queries = folder / QUERIES
    if queries.is_dir():
        for path in sorted(queries.glob("*.rq")):
            attempt(f"query {path.name}", lambda path=path: _import_query(gateway, path, author, comment))
    return report


def _import_knowledge(knowledge: Any, kind: str, path: Path, author: str, comment: str) -> str:
    text = path.read_text(encoding="utf-8")
    info = knowledge.info(kind)
    if info is not None and knowledge.text(kind) == text:
        return f"unchanged v{info.version}"
    return f"deployed v{knowledge.replace(kind, text, author=author, comment=comment).version}"


def _import_workflow(registry: Any, path: Path, author: str, comment: str) -> str:
    text = path.read_text(encoding="utf-8")
    name = parse(text, file=str(path)).name
    if name in registry.names():
        entry = registry.current(name)
        if entry.workflow.source == text:
            return f"unchanged v{entry.info.version}"
    return f"deployed v{registry.replace(name, text, author=author, comment=comment).version}"


def _import_mapping(mappings: Any, path: Path, author: str, comment: str) -> str:
    spec = yaml.safe_load(path.read_text(encoding="utf-8"))
    current = mappings.get(path.stem) if path.stem in mappings.names() else None
    if current is not None and current["version"] is not None and current["spec"] == spec:
        return f"unchanged v{current['version']}"
    return f"deployed v{mappings.replace(path.stem, spec, author=author, comment=comment).version}"


def _import_query(gateway: Any, path: Path, author: str, comment: str) -> str:
    text = path.read_text(encoding="utf-8")
    sidecar = path.with_name(path.stem + ".binding.yaml")
    binding = RuleBinding.from_dict(yaml.safe_load(sidecar.read_text(encoding="utf-8")), sidecar.name) \
        if sidecar.exists() else None
    params_file = path.with_name(path.stem + ".params.json")
    params = [ParamSpec(**p) for p in json.loads(params_file.read_text(encoding="utf-8"))] if params_file.exists() else None
    name = parse_query(text, params).name
    head = gateway.catalog.head("query", name)
    if head is not None and head.live:
        payload = gateway.catalog.load("query", name, head.current).payload
        if payload["text"] == text and payload.get("binding") == (binding.to_dict() if binding else None):
            return f"unchanged v{head.current}"
    info = gateway.queries.register(text, params, replace=True, binding=binding, author=author, comment=comment)
    return f"deployed v{info['version']}"


def _describe(exc: Exception) -> str:
    errors = getattr(exc, "errors", None)
    if isinstance(errors, list) and errors:
        first = errors[0]
        if hasattr(first, "to_dict"):
            first = first.to_dict()
        if isinstance(first, dict):
            where = ":".join(str(first.get(k)) for k in ("file", "line", "column") if first.get(k) not in (None, ""))
            return f"{where}: {first.get('message', exc)}" if where else str(first.get("message", exc))
    problems = getattr(exc, "problems", None)
    if isinstance(problems, list) and problems:
        return str(problems[0])
    return str(exc)

