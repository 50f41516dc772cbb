"""Shared test set-up: every test process gets one real JVM (started on first use)."""

from __future__ import annotations

import os

# Keep the test runs' caches (compiled Java helpers) in one place across runs.
os.environ.setdefault("PRINTEPS_CACHE_DIR", os.path.expanduser("~/.cache/printeps"))
