"""Serves the rule authors' workbench: one HTML page at ``/workbench`` and its bundled assets.

Why a router of its own: the workbench is plain static files (built from ``web/`` by
``web/build.sh`` and committed under ``static/``), so the gateway needs no separate web server and
no CDN or npm at run time. All data comes from the REST API (``/api/...``) the page calls with the
user's Bearer token; this router holds no state and needs no token itself.

Deep links are limited to the shell's sections (``/workbench/<section>[/<item>]``); anything else
under ``/workbench/`` is a 404 that names the sections.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse, RedirectResponse

STATIC_DIR = Path(__file__).resolve().parent / "static"

# Browsers must revalidate (cheap, thanks to ETag) so a new gateway release is never mixed with
# an old cached bundle.
_NO_CACHE = {"Cache-Control": "no-cache"}

router = APIRouter(tags=["workbench"])


def static_file(relative: str) -> Path:
    """The asset at ``relative`` inside the static folder, refusing anything that escapes it."""
    if not relative or "\x00" in relative:
        raise HTTPException(status_code=404, detail=f"no workbench asset {relative!r}")
    root = STATIC_DIR.resolve()
    candidate = (root / relative).resolve()
    if not candidate.is_relative_to(root) or not candidate.is_file():
        raise HTTPException(status_code=404, detail=f"no workbench asset {relative!r}")
    return candidate


@router.get("/workbench", include_in_schema=False)
def workbench_page() -> FileResponse:
    """The single page; the front end routes between its views with the URL fragment (#/...)."""
    page = STATIC_DIR / "index.html"
    if not page.is_file():
        raise HTTPException(
            status_code=503,
            detail="the workbench is not built: run web/build.sh (writes gateway/workbench/static/)",
        )
    return FileResponse(page, media_type="text/html; charset=utf-8", headers=_NO_CACHE)


@router.get("/workbench/", include_in_schema=False)
def workbench_slash() -> RedirectResponse:
    """``/workbench/`` would break the page's asset paths; send it to the canonical address."""
    return RedirectResponse("/workbench", status_code=308)


@router.get("/workbench/static/{relative:path}", include_in_schema=False)
def workbench_asset(relative: str) -> FileResponse:
    """A bundled asset (JavaScript, CSS, fonts) of the workbench page."""
    return FileResponse(static_file(relative), headers=_NO_CACHE)


#: The shell's sections; ``/workbench/<section>[/<item>]`` is a deep link the page turns into its
#: fragment (``#/<section>/<item>``), so every item has an address that can be shared.
SECTIONS = ("rules", "workflows", "knowledge", "streams", "live", "dialogue", "decisions", "history")


@router.get("/workbench/{section}", include_in_schema=False)
@router.get("/workbench/{section}/{item:path}", include_in_schema=False)
def workbench_deep_link(section: str, item: str = "") -> FileResponse:
    """The page itself at a section's or an item's address (``/workbench/workflows/show_to_seat``)."""
    if section not in SECTIONS:
        raise HTTPException(status_code=404, detail=f"the workbench has no section {section!r}; "
                                                    f"sections: {', '.join(SECTIONS)}")
    return workbench_page()
