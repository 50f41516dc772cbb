"""A compiled rule set as bytes, loaded again in another process without compiling.

Why: compiling is the expensive part of a deploy (~5-10 ms of CPU a rule), loading compiled classes
is not. Gateway processes that serve the same rule sets (several workers on a host, a restart, a
standby) can share one build: the process that compiled exports it, the others load it. On one host
the disk unit cache already does this by itself; these bytes are for moving a build anywhere else
(a database, another host).

The archive is a zip: ``manifest.json`` (format, the Drools/helper environment it was built for,
the rule set's content hash, the assembly plan) and ``units/<id>.zip`` + ``units/<id>.json`` for
every unit the plan uses (the executable-model classes Drools generated, as in the disk cache).
It is keyed by content: :func:`load_compiled` refuses bytes made for other files, another Drools or
other Java helpers, so a stale build can never run in place of the text it claims to be.
"""

from __future__ import annotations

import io
import json
import zipfile

from gateway.engine import compiler, incremental
from gateway.engine.build import DEFAULT_OPTIONS, CompiledRuleSet, CompileOptions
from gateway.engine.errors import EngineError
from gateway.engine.ruleset import content_hash
from gateway.engine.unit_cache import FORMAT, UnitArtifact

ARCHIVE_FORMAT = "printeps-compiled-ruleset-1"


class IncompatibleArtifact(EngineError):
    """The bytes are not a compiled form of these files for this gateway (compile the files instead)."""

    kind = "incompatible"


def export_compiled(compiled: CompiledRuleSet, options: CompileOptions | None = None) -> bytes:
    """``compiled`` as one archive (see the module docstring); its units come from the unit cache
    that built it (or the one of ``options``)."""
    plan = compiled.plan
    if not plan:
        raise IncompatibleArtifact("this compiled rule set has no assembly plan to export")
    cache = compiled.unit_cache if options is None and compiled.unit_cache is not None else \
        incremental.unit_cache(options or DEFAULT_OPTIONS)
    unit_ids = [plan["declarations"]] + [u for u in dict.fromkeys(r[0] for r in plan["rules"]) if u != plan["declarations"]]
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression=zipfile.ZIP_STORED) as archive:  # unit zips are compressed already
        manifest = {"format": ARCHIVE_FORMAT, "unit_format": FORMAT, "env": incremental.env_key(),
                    "hash": compiled.hash, "plan": plan}
        archive.writestr("manifest.json", json.dumps(manifest))
        for unit_id in unit_ids:
            unit = cache.get(unit_id)
            if unit is None:
                raise IncompatibleArtifact(f"unit {unit_id} of this rule set is no longer cached: compile it again to export it")
            archive.writestr(f"units/{unit_id}.json", json.dumps(unit.manifest()))
            archive.writestr(f"units/{unit_id}.zip", unit.data)
    return buffer.getvalue()


def load_compiled(data: bytes, files: dict[str, str], options: CompileOptions | None = None) -> CompiledRuleSet:
    """The rule set ``files`` from an archive :func:`export_compiled` made, without compiling.

    Raises :class:`IncompatibleArtifact` when the archive is not a build of exactly ``files`` for
    this Drools and these Java helpers. Its units join the unit cache (and the disk cache), so
    later edits of the set compile only what changed.
    """
    options = options or DEFAULT_OPTIONS
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        manifest = json.loads(archive.read("manifest.json"))
    except (zipfile.BadZipFile, KeyError, ValueError) as exc:
        raise IncompatibleArtifact(f"not a compiled rule set archive: {exc}") from None
    if manifest.get("format") != ARCHIVE_FORMAT or manifest.get("unit_format") != FORMAT:
        raise IncompatibleArtifact(f"archive format {manifest.get('format')!r} is not {ARCHIVE_FORMAT!r}")
    env = incremental.env_key()
    if manifest.get("env") != env:
        raise IncompatibleArtifact(f"compiled for {manifest.get('env')}, this gateway runs {env}: compile the files")
    digest = content_hash(files)
    if manifest.get("hash") != digest:
        raise IncompatibleArtifact("the archive is the build of other files (content hash differs)")
    cache = incremental.unit_cache(options)
    with compiler._compile_lock:
        for name in archive.namelist():
            if name.startswith("units/") and name.endswith(".json"):
                unit_manifest = json.loads(archive.read(name))
                unit_data = archive.read(name[:-5] + ".zip")
                cache.put(UnitArtifact.from_manifest(unit_manifest, unit_data), persist=options.disk_cache)
        plan = incremental._plan_from_json(manifest["plan"])
        stats = incremental.BuildStats(mode="loaded", rules=len(plan.rules))
        try:
            compiled = incremental.assemble(plan, files, dict(manifest["plan"].get("expanded", {})), cache, stats,
                                            request_joins=options.request_joins)
        except incremental._MissingUnit as exc:
            raise IncompatibleArtifact(f"unit {exc} of the archive does not load here: compile the files") from None
        if options.incremental and options.disk_cache:
            cache.put_plan(digest, manifest["plan"])
    return compiled
