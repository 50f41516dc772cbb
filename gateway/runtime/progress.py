"""A build's progress (``on_progress(done, total, stage)``) drawn on the terminal.

Why: validating or deploying thousands of rules takes a minute the first time; a user at a
terminal should see how far it is rather than a silent prompt.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

import typer


class TerminalProgress:
    """One progress bar per build stage (parse, compile, load, assemble), on stderr."""

    def __init__(self, file: TextIO | None = None) -> None:
        self.file = file or sys.stderr
        self.bar: Any = None
        self.stage = ""
        self.done = 0

    def __call__(self, done: int, total: int, stage: str) -> None:
        if stage != self.stage:
            self.close()
            self.bar = typer.progressbar(length=max(total, 1), label=f"{stage:<9}", file=self.file, show_pos=True)
            self.bar.__enter__()
            self.stage, self.done = stage, 0
        self.bar.update(max(done - self.done, 0))
        self.done = done

    def close(self) -> None:
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None
