"""The demo page at ``/`` and its files under ``/static`` (three.js bundled in; nothing is
fetched from elsewhere at run time, which the page's Content-Security-Policy enforces)."""

from __future__ import annotations

from functools import cache
from pathlib import Path

from fastapi import APIRouter
from starlette.responses import HTMLResponse
from starlette.staticfiles import StaticFiles

STATIC = Path(__file__).parent / "static"

#: Only this origin: the page, its script, the API; blob: and data: for the map and the
#: GLB's embedded texture.
CONTENT_SECURITY_POLICY = (
    "default-src 'self'; img-src 'self' blob: data:; connect-src 'self' blob: data:; "
    "style-src 'self'; script-src 'self'; object-src 'none'; base-uri 'none'; "
    "frame-ancestors 'none'"
)

router = APIRouter(include_in_schema=False)


@router.get("/")
def page() -> HTMLResponse:
    """The demo page."""
    return HTMLResponse(_page_html(), headers={"Content-Security-Policy": CONTENT_SECURITY_POLICY})


@cache
def _page_html() -> str:
    # Read once: the page is a file of the package and does not change while serving.
    return (STATIC / "index.html").read_text()


def static_files() -> StaticFiles:
    return StaticFiles(directory=STATIC)
