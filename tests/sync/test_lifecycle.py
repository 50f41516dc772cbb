"""The shared life cycle of catalog-backed services (:mod:`gateway.base.lifecycle`), on a stub
service over an in-memory catalog: seed from a folder, load, follow another process (deploy,
rollback, delete), the newer change winning a race, and one bad item never stopping the others.
The five real services are checked to share it (their own behaviour is in their own tests)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from gateway.base.lifecycle import CatalogLifecycle, NotAnItem
from gateway.base.versions import MemoryCatalog, Version


class Notes(CatalogLifecycle):
    """A stub service: notes named by their file, served as text; "bad" does not load."""

    kind = "note"
    failures = (ValueError, OSError)

    def __init__(self, catalog: MemoryCatalog, before_store: Any = None) -> None:
        super().__init__(catalog)
        self.texts: dict[str, str] = {}
        self.events: list[tuple[str, str, bool]] = []
        self.before_store = before_store  # a hook to let "another process" act mid-seed

    def change(self, name: str, text: str) -> None:
        """What an author's change does: store, then serve here at once."""
        info, seq = self.catalog.save(self.kind, name, {"text": text}, author="a", comment="", hash=text)
        self._apply(name, self.catalog.load(self.kind, name, info.version), seq, elsewhere=False)

    def _apply(self, name: str, stored: Version, seq: int, *, elsewhere: bool) -> None:
        if stored.payload["text"] == "bad":
            raise ValueError(f"{name} does not load")
        if self._served.set(name, stored.info.version, seq):
            self.texts[name] = stored.payload["text"]
            self.events.append(("serve", name, elsewhere))

    def _withdraw(self, name: str, seq: int) -> None:
        if self._served.set(name, None, seq) and self.texts.pop(name, None) is not None:
            self.events.append(("drop", name, True))

    def _seed_paths(self, folder: Path) -> list[Path]:
        return sorted(folder.glob("*.txt"))

    def _read_seed(self, path: Path) -> tuple[str, str]:
        text = path.read_text(encoding="utf-8")
        if not text:
            raise NotAnItem("empty file")
        if text == "unreadable":
            raise ValueError("not a note")
        return path.stem, text

    def _store_seed(self, name: str, item: str, path: Path) -> int:
        if self.before_store is not None:
            self.before_store(name)
        return self._save_seed(name, {"text": item}, item, path)


@pytest.fixture()
def folder(tmp_path: Path) -> Path:
    for name, text in {"a": "alpha", "b": "beta", "empty": "", "broken": "unreadable"}.items():
        (tmp_path / f"{name}.txt").write_text(text)
    return tmp_path


def test_seed_imports_only_what_the_catalog_never_had(folder):
    notes = Notes(MemoryCatalog())
    assert notes.seed(folder) == {"a": "seeded v1", "b": "seeded v1", "empty.txt": "skipped: empty file",
                                  "broken.txt": "failed: not a note"}
    assert notes.catalog.versions("note", "a")[0].author == "seed"
    assert notes.catalog.versions("note", "a")[0].comment == "seeded from a.txt"
    notes.change("a", "edited")
    notes.catalog.delete("note", "b", author="a")
    (folder / "a.txt").write_text("changed on disk")
    report = notes.seed(folder)
    assert report["a"] == "kept v2" and report["b"] == "kept (deleted)"  # files never overwrite the store
    assert notes.catalog.load("note", "a", 2).payload == {"text": "edited"}
    assert notes.seed(None) == {} and notes.seed(folder / "missing") == {}


def test_two_processes_seeding_at_once_store_an_item_once(folder):
    shared = MemoryCatalog("p1")
    other = Notes(shared.sharing("p2"))
    notes = Notes(shared, before_store=lambda name: other.seed(folder) if name == "a" else None)
    report = notes.seed(folder)
    assert report["a"] == "kept (seeded by another process)"
    assert [v.version for v in shared.versions("note", "a")] == [1]


def test_load_serves_every_live_item_and_reports_one_that_fails(folder):
    catalog = MemoryCatalog()
    writer = Notes(catalog)
    writer.seed(folder)
    catalog.save("note", "c", {"text": "bad"}, author="a", comment="", hash="h")  # stored, does not load
    writer.change("d", "gone")
    catalog.delete("note", "d", author="a")
    notes = Notes(catalog)
    report = notes.load()
    assert report == {"a": "serving v1", "b": "serving v1", "c": "failed: c does not load"}
    assert notes.texts == {"a": "alpha", "b": "beta"}
    assert all(not elsewhere for _, _, elsewhere in notes.events)  # loading at start is not a change elsewhere
    assert notes.load() == {"a": "serving v1", "b": "serving v1", "c": "failed: c does not load"}
    assert len(notes.events) == 2  # what is served already is not served again


def test_sync_follows_deploy_rollback_and_delete_of_another_process():
    shared = MemoryCatalog("p1")
    here, there = Notes(shared), Notes(shared.sharing("p2"))
    there.change("n", "one")
    there.change("n", "two")
    here.sync("n")
    assert here.texts == {"n": "two"} and here.served("n")[0] == 2 and here.events == [("serve", "n", True)]
    here.sync("n")
    assert len(here.events) == 1  # a change seen twice changes nothing
    shared.set_current("note", "n", 1, author="b", comment="back")
    here.sync("n")
    assert here.texts == {"n": "one"} and here.served("n")[0] == 1
    shared.delete("note", "n", author="b")
    here.sync("n")
    assert here.texts == {} and here.served("n") is None


def test_an_older_change_never_replaces_a_newer_one():
    notes = Notes(MemoryCatalog())
    notes.change("n", "one")
    old = notes.catalog.load("note", "n", 1)
    notes.change("n", "two")
    notes._apply("n", old, seq=1, elsewhere=True)  # a slow sync of the first deploy arrives late
    assert notes.texts == {"n": "two"}
    notes._withdraw("n", seq=1)  # so does a stale delete
    assert notes.texts == {"n": "two"}


def test_reconcile_converges_everything_and_drops_what_the_catalog_lost():
    shared = MemoryCatalog("p1")
    here, there = Notes(shared), Notes(shared.sharing("p2"))
    there.change("x", "ex")
    shared.save("note", "y", {"text": "bad"}, author="a", comment="", hash="h")
    here.texts["ghost"] = "?"  # served here, never in the catalog (e.g. a store that was reset)
    here._served.set("ghost", 1, 1)
    report = here.reconcile()
    assert report == {"x": "serving v1", "y": "failed: y does not load"}  # one bad item: the others go on
    assert here.texts == {"x": "ex"}


def test_the_five_services_share_one_life_cycle():
    from gateway.engine.engine import Engine
    from gateway.ontology.knowledge import KnowledgeBase
    from gateway.stream.services import MappingService, QueryService
    from gateway.workflow.registry import WorkflowRegistry

    services = [Engine, WorkflowRegistry, KnowledgeBase, QueryService, MappingService]
    assert [s.kind for s in services] == ["ruleset", "workflow", "knowledge", "query", "mapping"]
    for service in services:
        assert issubclass(service, CatalogLifecycle)
        for verb in ("seed", "load", "sync", "reconcile"):  # one implementation, one signature
            assert getattr(service, verb) is getattr(CatalogLifecycle, verb), f"{service.__name__}.{verb}"


def test_every_kind_is_seeded_from_one_folder_setting_by_the_composition_root(tmp_path):
    """Each kind has one folder setting, and ``seed_folders`` (what ``build_gateway`` passes to
    each service's ``seed``) is the one place that reads them: building the workflow service seeds
    nothing by itself any more (it did, from ``workflows.source_dir``)."""
    from gateway.config import Settings
    from gateway.runtime.transfer import seed_folders
    from gateway.workflow.service import build_service

    root = Path(__file__).resolve().parents[2]
    folders = {kind: tmp_path / kind for kind in ("rules", "workflows", "knowledge", "queries", "mappings")}
    settings = Settings.model_validate({
        "data_dir": str(tmp_path / "var"), "engine": {"rules_dir": str(folders["rules"])},
        "workflows": {"source_dir": str(root / "workflows"), "simulate_robots": True},
        "streams": {"knowledge_dir": str(folders["knowledge"]), "queries_dir": str(folders["queries"]),
                    "mappings_dir": str(folders["mappings"])}})
    assert seed_folders(settings) == {"ruleset": [folders["rules"]], "workflow": [root / "workflows"],
                                      "knowledge": [folders["knowledge"]], "query": [folders["queries"]],
                                      "mapping": [folders["mappings"]]}
    service = build_service(settings)
    try:
        assert service.registry.names() == []  # the root seeds and loads it, like the other four kinds
        report = service.registry.seed(seed_folders(settings)["workflow"][0])
        assert report["thanking"] == "seeded v1"
    finally:
        service.close()


def test_the_knowledge_seeds_from_its_folder_whatever_the_files_are_named(tmp_path):
    from gateway.ontology.knowledge import KnowledgeBase

    root = Path(__file__).resolve().parents[2]
    (tmp_path / "cafe.ttl").write_bytes((root / "ontology" / "teahouse.ttl").read_bytes())
    (tmp_path / "cafe.swrl").write_bytes((root / "ontology" / "teahouse.swrl").read_bytes())
    (tmp_path / "notes.txt").write_text("not knowledge")
    knowledge = KnowledgeBase(MemoryCatalog(), infer=False)
    assert knowledge.seed(tmp_path) == {"ontology": "seeded v1", "swrl": "seeded v1"}
    stored = {kind: knowledge.catalog.load("knowledge", kind, 1).payload["file"] for kind in ("ontology", "swrl")}
    assert stored == {"ontology": "cafe.ttl", "swrl": "cafe.swrl"}


def test_a_knowledge_folder_with_two_ontologies_is_refused_naming_both(tmp_path):
    from gateway.ontology.knowledge import KnowledgeBase

    (tmp_path / "a.ttl").write_text("@prefix p: <http://x/> .\n")
    (tmp_path / "b.owl").write_text("<rdf:RDF/>")
    knowledge = KnowledgeBase(MemoryCatalog(), infer=False)
    report = knowledge.seed(tmp_path)
    assert set(report) == {"a.ttl", "b.owl"}
    assert all(status.startswith("failed:") and "a.ttl" in status and "b.owl" in status for status in report.values())
    assert knowledge.catalog.head("knowledge", "ontology") is None  # nothing guessed, nothing stored


def test_the_old_knowledge_file_settings_name_their_folder(tmp_path, caplog):
    """Back-compat: ``streams.ontology_file``/``swrl_file`` (public, in docs/operations.md) still
    load, as ``knowledge_dir`` = their folder, with a warning; what cannot be one folder is refused."""
    from pydantic import ValidationError

    from gateway.config import Settings

    old = {"ontology_file": str(tmp_path / "k" / "a.ttl"), "swrl_file": str(tmp_path / "k" / "a.swrl")}
    with caplog.at_level("WARNING", logger="gateway.config"):
        settings = Settings.model_validate({"streams": old})
    assert settings.streams.knowledge_dir == str(tmp_path / "k")
    assert "knowledge_dir" in caplog.text and "deprecated" in caplog.text
    with pytest.raises(ValidationError, match="different folders.*knowledge_dir"):
        Settings.model_validate({"streams": {**old, "swrl_file": str(tmp_path / "elsewhere" / "a.swrl")}})
    with pytest.raises(ValidationError, match="set knowledge_dir only"):
        Settings.model_validate({"streams": {**old, "knowledge_dir": str(tmp_path)}})
