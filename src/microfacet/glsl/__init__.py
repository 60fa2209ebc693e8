"""Real-time runtime stage: GLSL shaders (GLSL 3.30 and ES 3.00 from one source), the
textures they read, and a WebGL2 viewer (``microfacet view``).

* :func:`source` — a shader's text for ``"330"`` or ``"es300"`` (:mod:`.sources`).
* :func:`export_textures` — float32 arrays (layout documented there) from a LEADR
  pyramid EXR or a fit ``.npz`` (:mod:`.textures`).
* :func:`evaluate` — run a GLSL expression over arrays on a real GL (moderngl, EGL)
  (:mod:`.harness`).
* :func:`demo_section` — viewer screenshots beside the Python renders for ``make demo``
  (:mod:`.demo`).

Examples
--------
>>> SHADERS[:3], sorted(VERSIONS)
(('common', 'glints', 'leadr'), ['330', 'es300'])
>>> source("microfacet", "es300").splitlines()[0]
'#version 300 es'
"""
from .sources import SHADERS, VERSIONS, source
from .textures import export_textures

__all__ = ["source", "SHADERS", "VERSIONS", "export_textures", "evaluate", "demo_section"]


def evaluate(*args, **kwargs):
    """:func:`microfacet.glsl.harness.evaluate` (imports moderngl on first use); the parameters
    and the result are that function's.

    Parameters
    ----------
    *args, **kwargs
        Those of :func:`microfacet.glsl.harness.evaluate`.

    Returns
    -------
    object
        What :func:`microfacet.glsl.harness.evaluate` returns.

    Examples
    --------
    The shader's Schlick term against the library's (on a real OpenGL 3.3, headless EGL):

    >>> import numpy as np, microfacet as mf
    >>> c = np.array([[1.0], [0.5], [0.1]])                                  # cos theta_d
    >>> gl = evaluate("common", "result = vec4(mf_fresnel_schlick(vec3(0.04), vec3(1.0), x.x), 1.0);", {"x": c})
    >>> bool(np.allclose(gl[:, :3], mf.fresnel.Schlick(0.04)(c[:, 0]), atol=1e-6))
    True
    """
    from .harness import evaluate as _evaluate
    return _evaluate(*args, **kwargs)


def demo_section(*args, **kwargs):
    """:func:`microfacet.glsl.demo.demo_section` (imports Playwright on first use); the parameters
    and the result are that function's.

    Parameters
    ----------
    *args, **kwargs
        Those of :func:`microfacet.glsl.demo.demo_section`.

    Returns
    -------
    object
        What :func:`microfacet.glsl.demo.demo_section` returns.

    Examples
    --------
    It needs the system Chromium (:func:`microfacet.glsl.browser.chromium_path`):

    >>> html = demo_section("demo", size=16, levels=(2,), display=64, scene_size=(160, 100))  # doctest: +SKIP
    >>> html.startswith("<section")                                                          # doctest: +SKIP
    True
    """
    from .demo import demo_section as _demo_section
    return _demo_section(*args, **kwargs)
