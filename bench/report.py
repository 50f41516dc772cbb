"""Writing a bench's section into docs/benchmarks.md (only that section is replaced)."""

from __future__ import annotations

import os
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "benchmarks.md"


def write_section(section: str, text: str, doc: Path = DOC) -> None:
    """Replace the ``section`` heading's text (up to the next ``## `` heading), or append it."""
    doc.parent.mkdir(parents=True, exist_ok=True)
    current = doc.read_text() if doc.exists() else "# Benchmarks\n"
    if section in current:
        before, rest = current.split(section, 1)
        after = rest[rest.find("\n## "):] if "\n## " in rest else ""
        current = before.rstrip() + "\n\n" + text.rstrip() + "\n" + after
    else:
        current = current.rstrip() + "\n\n" + text.rstrip() + "\n"
    doc.write_text(current)


def machine_note() -> str:
    """The load the bench ran under (the machine is shared: read the ratios)."""
    load1, load5, _ = os.getloadavg()
    return f"{os.cpu_count()} cores, load average {load1:.1f} (5 min: {load5:.1f}) at the start"
