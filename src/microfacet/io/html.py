"""Minimal static HTML reports: a page of sections, tables of images and figures.

Every string passed as text is escaped; ``body`` arguments are HTML fragments built by
these functions. Paths are written relative to the page, so the folder can be moved. The
page fits its window (body at most 1200 px wide): a table of images wider than the window
shrinks its images (``max-width: 100%``) instead of widening the page.
"""
from __future__ import annotations

from collections.abc import Sequence
from html import escape

__all__ = ["html_page", "html_figure", "html_grid"]

_CSS = """
body { font-family: system-ui, sans-serif; margin: 2em auto; max-width: 1200px; color: #222; }
h1 { font-size: 1.6em; } h2 { margin-top: 2em; border-bottom: 1px solid #ccc; }
figure { margin: 1em 0; } figcaption { font-size: 0.9em; color: #444; }
table.grid { border-collapse: collapse; max-width: 100%; }
table.grid td img { max-width: 100%; height: auto; }
table.grid td, table.grid th { padding: 3px; text-align: center; vertical-align: top; }
table.grid th.row { font-weight: normal; font-size: 0.85em; text-align: right; vertical-align: middle; }
table.grid small { color: #444; }
img.lobes { max-width: 100%; } img.env { width: 512px; max-width: 100%; }
code { background: #f3f3f3; padding: 0 0.2em; }
"""


def html_figure(src: str, caption: str, alt: str = "", css_class: str = "") -> str:
    """An ``<figure>`` with one image and its (escaped) caption.

    Parameters
    ----------
    src : str
        Image URL (relative path).
    caption : str
        Caption text.
    alt : str
        Alternative text; empty: the caption.
    css_class : str
        CSS class of the image; empty: none.

    Returns
    -------
    str
        HTML fragment.

    Examples
    --------
    >>> html_figure("a.png", "GGX & Beckmann")
    '<figure><img src="a.png" alt="GGX &amp; Beckmann"><figcaption>GGX &amp; Beckmann</figcaption></figure>'
    """
    cls = f' class="{escape(css_class)}"' if css_class else ""
    return (f'<figure><img src="{escape(src)}" alt="{escape(alt or caption)}"{cls}>'
            f"<figcaption>{escape(caption)}</figcaption></figure>")


def html_grid(rows: Sequence[tuple[str, Sequence[tuple[str, str]]]]) -> str:
    """A table of images: each row is ``(row_label, cells)``, each cell ``(src, caption)``.

    Parameters
    ----------
    rows : sequence of (str, sequence of (str, str))
        Row label and ``(src, caption)`` cells.

    Returns
    -------
    str
        HTML fragment.

    Examples
    --------
    >>> html = html_grid([("GGX", [("ggx_0.png", "alpha 0.1"), ("ggx_1.png", "alpha 0.3")])])
    >>> html.count("<img"), html.startswith("<table")
    (2, True)
    """
    body = "".join(
        f'<tr><th class="row">{escape(label)}</th>'
        + "".join(f'<td><img src="{escape(src)}" alt="{escape(label)}: {escape(cap)}"><br>'
                  f"<small>{escape(cap)}</small></td>" for src, cap in cells)
        + "</tr>"
        for label, cells in rows)
    return f'<table class="grid">{body}</table>'


def html_page(title: str, body: str) -> str:
    """A complete, self-contained HTML5 page (inline CSS, no scripts).

    Parameters
    ----------
    title : str
        Page title (escaped).
    body : str
        HTML fragment.

    Returns
    -------
    str
        The page.

    Examples
    --------
    >>> page = html_page("Demo", "<p>hello</p>")
    >>> page.startswith("<!DOCTYPE html>"), "<title>Demo</title>" in page
    (True, True)
    """
    return (f'<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{escape(title)}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
            f"<h1>{escape(title)}</h1>\n{body}\n</body>\n</html>\n")
