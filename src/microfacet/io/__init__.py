"""Files in and out: atomic writers, EXR (data), PNG (exact data images and previews), text and HTML reports.

Every writer writes to a temporary file in the destination folder and ``os.replace``-s
it onto the destination, so an interrupted run never leaves a half-written output.
Readers raise :class:`microfacet.MicrofacetError` naming the file and what is wrong.
Normal maps are decoded by :mod:`microfacet.io.normalmap`, the library's one decoder.
"""
from .atomic import atomic_path, write_bytes, write_text
from .exr import read_exr, write_exr
from .html import html_figure, html_page, html_grid
from .image import read_image
from .names import input_name, material_name
from .npz import load_npz
from .png import read_png_data, srgb_encode, to_srgb8, tonemap, write_png, write_png_data

__all__ = ["atomic_path", "write_bytes", "write_text", "read_exr", "write_exr", "load_npz",
           "input_name", "material_name",
           "srgb_encode", "to_srgb8", "tonemap", "write_png", "read_png_data", "write_png_data", "read_image",
           "html_figure", "html_page", "html_grid"]
