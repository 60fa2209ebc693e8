"""Headless Chromium (Playwright) on the viewer: used by the demo section, the tests'
fixtures and the benchmark. Playwright is imported on use (the ``view``/``test`` extras)."""
from __future__ import annotations

import shutil
import threading
from contextlib import contextmanager
from pathlib import Path

from ..errors import MicrofacetError
from .server import ViewerData, make_server

__all__ = ["chromium_path", "open_viewer", "CHROMIUM_PATHS"]

#: Where the system Chromium is looked for, in order (then ``chromium`` on the ``PATH``).
CHROMIUM_PATHS = ("/usr/lib/chromium/chromium", "/usr/bin/chromium", "/usr/bin/chromium-browser")


def chromium_path() -> str:
    """The system Chromium (Debian's ``chromium``); raises :class:`MicrofacetError` if none.

    Returns
    -------
    str
        The executable: the first of :data:`CHROMIUM_PATHS` that exists, else ``chromium``
        on the ``PATH``.

    Raises
    ------
    MicrofacetError
        No Chromium (one line: what to install).

    Examples
    --------
    >>> try:
    ...     exe = chromium_path()
    ... except MicrofacetError:
    ...     exe = None
    >>> exe is None or exe in CHROMIUM_PATHS or Path(exe).exists()
    True
    """
    exe = next((c for c in CHROMIUM_PATHS if Path(c).exists()), None) or shutil.which("chromium")
    if exe is None:
        raise MicrofacetError("no system Chromium found (apt-get install chromium)")
    return exe


@contextmanager
def open_viewer(data: ViewerData, width: int = 960, height: int = 540, timeout_ms: int = 120000):
    """Serve ``data`` on a free 127.0.0.1 port (in a thread) and yield a Playwright page with
    the viewer loaded and its first frame drawn; ``page.errors`` collects console errors.

    Parameters
    ----------
    data : ViewerData
        What to serve (:func:`~microfacet.glsl.server.load_viewer_data`).
    width, height : int
        The page's viewport.
    timeout_ms : int
        Milliseconds the first frame may take.

    Yields
    ------
    playwright.sync_api.Page
        The page (``window.mfViewer`` is the viewer).

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.glsl.server import load_viewer_data
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> data = load_viewer_data("bumps.exr")
    >>> with open_viewer(data, 320, 200) as page:                         # doctest: +SKIP
    ...     _ = page.screenshot(path="viewer.png")
    ...     page.errors
    []
    """
    from playwright.sync_api import sync_playwright
    server = make_server(data, 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium_path(), headless=True)
            try:
                page = browser.new_page(viewport={"width": width, "height": height})
                page.errors = []
                page.on("console", lambda m: page.errors.append(m.text) if m.type == "error" else None)
                page.on("pageerror", lambda e: page.errors.append(str(e)))
                page.goto(f"http://127.0.0.1:{server.server_address[1]}/")
                page.wait_for_function("window.mfViewer && window.mfViewer.frames > 0", timeout=timeout_ms)
                yield page
            finally:
                browser.close()
    finally:
        server.shutdown()
        server.server_close()
