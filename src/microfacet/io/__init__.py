"""Files in and out: atomic writers, EXR (data), PNG (previews), text and HTML reports.

Every writer writes to a temporary file in the destination folder and ``os.replace``-s
it onto the destination, so an interrupted run never leaves a half-written output.
Readers raise :class:`microfacet.MicrofacetError` naming the file and what is wrong.
"""
from .atomic import atomic_path, write_bytes, write_text
from .exr import read_exr, write_exr
from .html import html_figure, html_page, html_grid
from .npz import load_npz
from .png import srgb_encode, to_srgb8, tonemap, write_png

__all__ = ["atomic_path", "write_bytes", "write_text", "read_exr", "write_exr", "load_npz",
           "srgb_encode", "to_srgb8", "tonemap", "write_png",
           "html_figure", "html_page", "html_grid"]
