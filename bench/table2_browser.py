"""Benchmark: Table 2's sixteen change requests made by the teahouse owner in the browser.

A fresh gateway (as ``printeps serve`` builds it, robots and humans simulated, an author token) and
a headless Chromium driven by Playwright; the owner's steps are those of the acceptance test
(``tests/workbench/table2_steps.py``): per change the clicks and fields filled, the seconds from
starting the change until the running gateway shows the new behaviour, and a screenshot
(docs/img/table2/NN.png, 1280x800).

    .venv/bin/python bench/table2_browser.py [--write FILE.md] [--shots docs/img/table2]

``--write`` replaces the table between the ``<!-- browser-table -->`` markers of the given file
(docs/agile-loop.md no longer keeps this table: a person's time is the newcomer measure's,
tests/workbench/test_newcomer_table2.py).
The seconds are those of a scripted owner (no thinking time): what the workbench and the gateway
take, the floor of what a person needs.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

from gateway.config import PROJECT_ROOT, Settings

sys.path.insert(0, str(PROJECT_ROOT / "tests" / "workbench"))
sys.path.insert(0, str(PROJECT_ROOT / "tests"))  # the agile harness (tests/agile_harness.py)

from table2_steps import Done, Setup, make_all, markdown, prepare, steps_markdown  # noqa: E402
from wb_helpers import AUTHOR_TOKEN, TOKENS, new_page  # noqa: E402

from agile_harness import OwnerClient  # noqa: E402

MARK_START, MARK_END = "<!-- browser-table -->", "<!-- /browser-table -->"
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-quic"]


@contextmanager
def fresh_gateway(workdir: Path) -> Iterator[str]:
    """A gateway built as ``printeps serve`` builds it over the repository's rules, workflows and
    knowledge (its own data directory), served on 127.0.0.1; yields its base URL."""
    from gateway.app import build_gateway
    from gateway.serve import free_port, serve_in_thread

    settings = Settings.model_validate({
        "data_dir": str(workdir / "var"),
        "engine": {"rules_dir": str(PROJECT_ROOT / "rules" / "drl")},
        "workflows": {"simulate_robots": True, "simulate_humans": True},
        "api": {"tokens": TOKENS},
    })
    gateway = build_gateway(settings, rest=True, ros=False, warm_up=False)
    try:
        gateway.engine.warm_up(background=False)  # as a gateway that has been up a while
        server, thread = serve_in_thread(gateway.app, free_port(), name="table2-gateway")
        try:
            yield f"http://127.0.0.1:{server.config.port}"
        finally:
            server.should_exit = True
            thread.join(timeout=10)
    finally:
        gateway.close()


def run(shots: Path) -> list[Done]:
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="table2-") as tmp, fresh_gateway(Path(tmp)) as base_url:
        setup = Setup(files=Path(tmp) / "from-the-engineer")
        gw = OwnerClient(base_url, token=AUTHOR_TOKEN)
        try:
            prepare(gw.http, setup)
            with sync_playwright() as playwright:
                browser = playwright.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
                try:
                    page = new_page(browser, SimpleNamespace(base_url=base_url), AUTHOR_TOKEN)
                    done = make_all(page, gw, setup, shots)
                    if page.js_errors:
                        raise SystemExit(f"script errors in the workbench: {page.js_errors}")
                finally:
                    browser.close()
        finally:
            gw.close()
    return done


def section(done: list[Done], image_dir: str) -> str:
    slowest = max(done, key=lambda d: d.seconds)
    return "\n".join([
        f"Measured {time.strftime('%Y-%m-%d')} on a fresh gateway (2 shared cores), one run, "
        "headless Chromium at 1280×800.",
        "",
        markdown(done, image_dir),
        "",
        f"Slowest: #{slowest.id}, {slowest.seconds:.1f} s; all {len(done)} verified live on the gateway, no restart.",
        "\\* #8 and #11 need DRL the owner does not write: the owner creates the `seat_info` rule set in "
        "the workbench (“+ New rule set”) and adds three small files the engineer wrote (the `Table` fact "
        "type and the two rules) with “+ Add a file…”, then deploys (nothing typed; writing the files "
        "is not counted).",
        "",
        steps_markdown(done),
    ])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--write", type=Path, default=None, help="markdown file with the browser-table markers")
    ap.add_argument("--shots", type=Path, default=PROJECT_ROOT / "docs" / "img" / "table2",
                    help="where the screenshots go (NN.png)")
    args = ap.parse_args()
    done = run(args.shots)
    for d in done:
        print(f"#{d.id:2d} {d.steps:3d} steps {d.seconds:5.1f} s  {d.how}")
    if args.write:
        image_dir = Path(os.path.relpath(args.shots.resolve(), args.write.resolve().parent)).as_posix()
        doc = args.write.read_text(encoding="utf-8")
        if MARK_START not in doc or MARK_END not in doc:
            print(f"{args.write} has no {MARK_START} … {MARK_END} markers: put them where the table goes "
                  "(docs/agile-loop.md no longer keeps it: the newcomer measure is what a person needs)", file=sys.stderr)
            return 2
        start, end = doc.index(MARK_START) + len(MARK_START), doc.index(MARK_END)
        args.write.write_text(doc[:start] + "\n" + section(done, image_dir) + "\n" + doc[end:], encoding="utf-8")
        print(f"table written to {args.write}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
