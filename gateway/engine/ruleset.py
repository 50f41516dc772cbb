"""A rule set: a named folder of ``.drl``, ``.dsl`` and ``.dslr`` files (plus optional ``examples.json``).

Plain Python: naming rules, size limits, content hashing and reading a folder. Nothing here needs
the JVM, so it is cheap to check input before compiling anything.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

from gateway.engine.errors import CompileError, InvalidRuleSet

RULE_SUFFIXES = (".drl", ".dsl", ".dslr")
DATA_FILES = ("examples.json",)
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
FILE_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_. -]{0,99}$")
MAX_FILE_BYTES = 1_000_000
MAX_TOTAL_BYTES = 5_000_000
MAX_FILES = 200


def check_name(name: str) -> str:
    """A rule set name is also a folder name and a URL segment: keep it plain."""
    if not isinstance(name, str) or not NAME_PATTERN.match(name) or ".." in name:
        raise InvalidRuleSet(
            f"invalid rule set name {name!r}: use 1-64 letters, digits, '_', '-' or '.', "
            "starting with a letter or digit"
        )
    return name


def is_rule_file(file_name: str) -> bool:
    return file_name.endswith(RULE_SUFFIXES)


def check_files(files: dict[str, str]) -> dict[str, str]:
    """Refuses unusable file sets with errors that name the file; returns the files unchanged."""
    if not isinstance(files, dict):
        raise InvalidRuleSet("files must be an object mapping file names to their text")
    errors: list[CompileError] = []
    total = 0
    if len(files) > MAX_FILES:
        raise InvalidRuleSet(f"too many files: {len(files)} (at most {MAX_FILES})")
    for fname, text in files.items():
        if not isinstance(fname, str) or not FILE_PATTERN.match(fname) or "/" in fname or ".." in fname:
            errors.append(CompileError(str(fname), 0, 0, "invalid file name: use letters, digits, '_', '-', '.', no folders"))
            continue
        if not (is_rule_file(fname) or fname in DATA_FILES):
            errors.append(CompileError(fname, 0, 0, f"unsupported file: rule sets hold {', '.join(RULE_SUFFIXES)} files and {', '.join(DATA_FILES)}"))
            continue
        if not isinstance(text, str):
            errors.append(CompileError(fname, 0, 0, "file content must be text"))
            continue
        size = len(text.encode("utf-8", "surrogatepass"))
        total += size
        if size > MAX_FILE_BYTES:
            errors.append(CompileError(fname, 0, 0, f"file too large: {size} bytes (at most {MAX_FILE_BYTES})"))
            continue
        bad = _first_control_char(text)
        if bad is not None:
            line, col = bad
            errors.append(CompileError(fname, line, col, "binary or control characters in the text: is this a rule file?"))
    if total > MAX_TOTAL_BYTES:
        errors.append(CompileError("", 0, 0, f"rule set too large: {total} bytes (at most {MAX_TOTAL_BYTES})"))
    if not errors and not any(is_rule_file(f) and files[f].strip() for f in files):
        errors.append(CompileError("", 0, 0, "empty rule set: it needs at least one non-empty .drl or .dslr file"))
    elif not errors and not any(f.endswith((".drl", ".dslr")) and files[f].strip() for f in files):
        errors.append(CompileError("", 0, 0, "the rule set has no .drl or .dslr file: a .dsl alone holds no rules"))
    if errors:
        raise InvalidRuleSet(f"rule set rejected: {errors[0]}", errors)
    return files


_CONTROL_CHAR = re.compile("[\x00-\x08\x0b\x0e-\x1f\x7f\ufffd\ud800-\udfff]")


def _first_control_char(text: str) -> tuple[int, int] | None:
    match = _CONTROL_CHAR.search(text)  # one regex scan: rule sets run to megabytes
    if match is None:
        return None
    line = text.count("\n", 0, match.start()) + 1
    return line, match.start() - (text.rfind("\n", 0, match.start()) + 1) + 1


def content_hash(files: dict[str, str]) -> str:
    """A stable hash of the file set (names and texts), to tell versions apart."""
    digest = hashlib.sha256()
    for fname in sorted(files):
        digest.update(fname.encode())
        digest.update(b"\0")
        digest.update(files[fname].encode("utf-8", "surrogatepass"))
        digest.update(b"\0")
    return digest.hexdigest()


def read_folder(folder: Path) -> dict[str, str]:
    """The rule set files of a folder (non-recursive)."""
    files: dict[str, str] = {}
    for path in sorted(folder.iterdir()):
        if path.is_file() and (is_rule_file(path.name) or path.name in DATA_FILES):
            files[path.name] = path.read_text(encoding="utf-8")
    return files
