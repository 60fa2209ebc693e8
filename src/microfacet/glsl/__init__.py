"""Real-time runtime stage: GLSL shaders (GLSL 3.30 and ES 3.00 from one source), the
textures they read, and a WebGL2 viewer (``microfacet view``).

* :func:`source` — a shader's text for ``"330"`` or ``"es300"`` (:mod:`.sources`).
* :func:`export_textures` — float32 arrays (layout documented there) from a LEADR
  pyramid EXR or a fit ``.npz`` (:mod:`.textures`).
* :func:`evaluate` — run a GLSL expression over arrays on a real GL (moderngl, EGL)
  (:mod:`.harness`).
* :func:`demo_section` — viewer screenshots beside the Python renders for ``make demo``
  (:mod:`.demo`).
"""
from .sources import SHADERS, VERSIONS, source
from .textures import export_textures

__all__ = ["source", "SHADERS", "VERSIONS", "export_textures", "evaluate", "demo_section"]


def evaluate(*args, **kwargs):
    """:func:`microfacet.glsl.harness.evaluate` (imports moderngl on first use)."""
    from .harness import evaluate as _evaluate
    return _evaluate(*args, **kwargs)


def demo_section(*args, **kwargs):
    """:func:`microfacet.glsl.demo.demo_section` (imports Playwright on first use)."""
    from .demo import demo_section as _demo_section
    return _demo_section(*args, **kwargs)
