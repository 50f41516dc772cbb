"""``make bench`` runs bench/run_all.py: every bench it names must exist (it once named a missing one)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_bench_run_all_names_exists() -> None:
    spec = importlib.util.spec_from_file_location("run_all", ROOT / "bench" / "run_all.py")
    run_all = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(run_all)
    for quick in (False, True):
        for name, cmd in run_all.benches(quick).items():
            assert (ROOT / cmd[0]).is_file(), f"make bench: {name} names missing {cmd[0]}"
