"""A rule set: a named folder of ``.drl``, ``.dsl``, ``.dslr`` files and decision tables (``.csv``,
``.xlsx``), plus optional ``examples.json`` and test scenarios ``tests/*.yaml``.

Plain Python: naming rules, size limits, content hashing and reading a folder. Nothing here needs
the JVM, so it is cheap to check input before compiling anything.

Everywhere a rule set travels as ``files`` (REST JSON, versions, drafts) it is a map of file name to
*text*. A binary ``.xlsx`` workbook travels as a ``data:`` URL (RFC 2397) —
``data:application/vnd.openxmlformats-officedocument.spreadsheetml.sheet;base64,UEsDB…`` — which is
what a browser's ``FileReader.readAsDataURL`` produces, says what it is, and can never be mistaken
for rule text. On disk (rule folders, the version store) it is the plain workbook.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import re
from pathlib import Path

from gateway.engine.errors import CompileError, InvalidRuleSet

RULE_SUFFIXES = (".drl", ".dsl", ".dslr", ".csv", ".xlsx")
TABLE_SUFFIXES = (".csv", ".xlsx")  # decision tables, converted to DRL (gateway.engine.decision_table)
BINARY_SUFFIXES = (".xlsx",)
XLSX_DATA_URL = "data:application/vnd.openxmlformats-officedocument.spreadsheetml.sheet;base64,"
DATA_FILES = ("examples.json", "kmodule.xml")  # kmodule.xml: the sessions it declares (gateway.engine.kmodule)
TESTS_FOLDER = "tests/"  # test scenarios live in the rule set's tests/ folder: tests/<name>.yaml
TEST_SUFFIXES = (".yaml", ".yml")
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
    return "/" not in file_name and file_name.endswith(RULE_SUFFIXES)


def is_table_file(file_name: str) -> bool:
    """A decision table (compiled to DRL by gateway.engine.decision_table)."""
    return "/" not in file_name and file_name.endswith(TABLE_SUFFIXES)


def is_binary_file(file_name: str) -> bool:
    """Kept as a ``data:`` URL in ``files`` (see the module docstring)."""
    return file_name.endswith(BINARY_SUFFIXES)


def is_test_file(file_name: str) -> bool:
    """A test scenario file: ``tests/<name>.yaml``."""
    return (
        file_name.startswith(TESTS_FOLDER)
        and file_name.endswith(TEST_SUFFIXES)
        and bool(FILE_PATTERN.match(file_name[len(TESTS_FOLDER):]))
    )


def encode_binary(data: bytes) -> str:
    """A workbook's bytes as the ``data:`` URL text that ``files`` carries."""
    return XLSX_DATA_URL + base64.b64encode(data).decode("ascii")


def decode_binary(file_name: str, text: str) -> bytes:
    """The bytes of a binary file's ``data:`` URL; ValueError saying what is wrong."""
    if not isinstance(text, str) or not text.startswith(XLSX_DATA_URL):
        start = text[:40] + "…" if isinstance(text, str) and len(text) > 40 else text
        raise ValueError(
            f"a {Path(file_name).suffix} file travels as a data: URL starting with '{XLSX_DATA_URL}', "
            f"not {start!r}"
        )
    try:
        return base64.b64decode(text[len(XLSX_DATA_URL):], validate=True)
    except (binascii.Error, ValueError) as exc:
        raise ValueError(f"the base64 data of the data: URL is broken: {exc}") from None


def check_files(files: dict[str, str]) -> dict[str, str]:
    """Refuses unusable file sets with errors that name the file; returns the files unchanged."""
    if not isinstance(files, dict):
        raise InvalidRuleSet("files must be an object mapping file names to their text")
    errors: list[CompileError] = []
    total = 0
    if len(files) > MAX_FILES:
        raise InvalidRuleSet(f"too many files: {len(files)} (at most {MAX_FILES})")
    for fname, text in files.items():
        if isinstance(fname, str) and is_test_file(fname) and ".." not in fname:
            pass
        elif not isinstance(fname, str) or not FILE_PATTERN.match(fname) or "/" in fname or ".." in fname:
            errors.append(CompileError(str(fname), 0, 0, "invalid file name: use letters, digits, '_', '-', '.', "
                                                         "no folders but tests/ (for tests/<name>.yaml)"))
            continue
        if not (is_rule_file(fname) or fname in DATA_FILES or is_test_file(fname)):
            errors.append(CompileError(fname, 0, 0, f"unsupported file: rule sets hold {', '.join(RULE_SUFFIXES)} files, "
                                                    f"{', '.join(DATA_FILES)} and tests/*.yaml"))
            continue
        if not isinstance(text, str):
            errors.append(CompileError(fname, 0, 0, "file content must be text"))
            continue
        size = len(text.encode("utf-8", "surrogatepass"))
        total += size
        if size > MAX_FILE_BYTES:
            errors.append(CompileError(fname, 0, 0, f"file too large: {size} bytes (at most {MAX_FILE_BYTES})"))
            continue
        if is_binary_file(fname):
            try:
                decode_binary(fname, text)
            except ValueError as exc:
                errors.append(CompileError(fname, 0, 0, str(exc)))
            continue
        bad = _first_control_char(text)
        if bad is not None:
            line, col = bad
            errors.append(CompileError(fname, line, col, "binary or control characters in the text: is this a rule file?"))
    if total > MAX_TOTAL_BYTES:
        errors.append(CompileError("", 0, 0, f"rule set too large: {total} bytes (at most {MAX_TOTAL_BYTES})"))
    if not errors and not any(is_rule_file(f) and files[f].strip() for f in files):
        errors.append(CompileError("", 0, 0, "empty rule set: it needs at least one non-empty .drl, .dslr or decision table file"))
    elif not errors and not any((f.endswith((".drl", ".dslr")) or is_table_file(f)) and files[f].strip() for f in files):
        errors.append(CompileError("", 0, 0, "the rule set has no .drl or .dslr file (nor a decision table): a .dsl alone holds no rules"))
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
    """The rule set files of a folder: its rule files, tables and data files, and tests/*.yaml.

    Workbooks (``.xlsx``) become ``data:`` URLs; lock files spreadsheet programs leave beside an
    open workbook (``~$greetings.xlsx``, ``.~lock.greetings.xlsx#``) are not rule files and are skipped.
    """
    files: dict[str, str] = {}
    for path in sorted(folder.iterdir()):
        if path.is_file() and (is_rule_file(path.name) or path.name in DATA_FILES) and FILE_PATTERN.match(path.name):
            files[path.name] = read_file(path)
    tests = folder / TESTS_FOLDER.rstrip("/")
    if tests.is_dir():
        for path in sorted(tests.iterdir()):
            name = TESTS_FOLDER + path.name
            if path.is_file() and is_test_file(name):
                files[name] = path.read_text(encoding="utf-8")
    return files


def read_file(path: Path) -> str:
    """One file of a rule set as ``files`` carries it (text, or a data: URL for a workbook)."""
    if is_binary_file(path.name):
        return encode_binary(path.read_bytes())
    return path.read_text(encoding="utf-8")


def write_file(path: Path, text: str) -> None:
    """The inverse of :func:`read_file`: a workbook is written as the workbook itself."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if is_binary_file(path.name):
        path.write_bytes(decode_binary(path.name, text))
    else:
        path.write_text(text, encoding="utf-8")
