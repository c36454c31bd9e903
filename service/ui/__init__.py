"""The operator's web page ``/ui``: static HTML, CSS and one script of our own, plus the
plotly.js bundle of the ``plotly`` Python package (served from this machine, no CDN).

The page holds no data: after the operator enters an API token (kept in the tab's
``sessionStorage``) its script reads the REST API with ``Authorization: Bearer`` — the
buildings, history, forecast, internal-gains, health and diagnosis resources — and plots
them with plotly.js. Nothing here is loaded before a request: the plotly bundle is located
on the first request for it, without importing the ``plotly`` package.
"""

from __future__ import annotations

import functools
import importlib.util
from pathlib import Path

from fastapi import APIRouter, HTTPException
from fastapi.responses import FileResponse

__all__ = ["STATIC", "plotly_js", "router"]

STATIC = Path(__file__).resolve().parent / "static"

#: the page's own files: name -> media type
_FILES = {"ui.js": "text/javascript", "ui.css": "text/css"}

#: no inline scripts, nothing from other origins; plotly.js adds <style> elements and style
#: attributes ('unsafe-inline' for styles only); the favicon is an empty data: URL
CSP = ("default-src 'self'; script-src 'self'; style-src 'self' 'unsafe-inline'; "
       "img-src 'self' data:; connect-src 'self'; base-uri 'none'; form-action 'self'; "
       "frame-ancestors 'none'")
_HEADERS = {"Content-Security-Policy": CSP, "X-Content-Type-Options": "nosniff",
            "Referrer-Policy": "no-referrer", "Cache-Control": "no-cache"}

router = APIRouter(tags=["ui"], include_in_schema=False)


@functools.cache
def plotly_js() -> Path | None:
    """``plotly.min.js`` of the installed ``plotly`` package (found without importing it),
    or None when the package is not installed."""
    spec = importlib.util.find_spec("plotly")
    if spec is None or not spec.submodule_search_locations:
        return None
    for folder in spec.submodule_search_locations:
        path = Path(folder) / "package_data" / "plotly.min.js"
        if path.is_file():
            return path
    return None


@router.get("/ui", response_class=FileResponse)
async def page():
    return FileResponse(STATIC / "index.html", media_type="text/html", headers=_HEADERS)


@router.get("/ui/plotly.min.js", response_class=FileResponse)
async def plotly_bundle():
    path = plotly_js()
    if path is None:
        raise HTTPException(404, "the charting library is missing: install the Python "
                                 "package plotly (pip install 'zonecast[service]')")
    return FileResponse(path, media_type="text/javascript",
                        headers={**_HEADERS, "Cache-Control": "max-age=86400"})


@router.get("/ui/{name}", response_class=FileResponse)
async def asset(name: str):
    media = _FILES.get(name)
    if media is None:  # only the page's own files, never a path
        raise HTTPException(404, f"no such file of the operator page: {name[:64]!r}")
    return FileResponse(STATIC / name, media_type=media, headers=_HEADERS)
