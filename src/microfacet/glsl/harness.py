"""Evaluate GLSL over arrays on a real OpenGL (moderngl; headless EGL, e.g. Mesa llvmpipe).

One fragment per element: the inputs are RGBA32F textures read with ``texelFetch``, the
result a ``vec4`` per element written to an RGBA32F framebuffer and read back. Used by the
tests to compare every shader function with the NumPy library, and usable to check a
shader edit the same way.
"""
from __future__ import annotations

import numpy as np

from .sources import source

__all__ = ["context", "evaluate", "upload_levels"]

_CTX = None
_WIDTH = 256
_VERTEX = """
in vec2 in_pos;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); }
"""


def context():
    """A shared standalone OpenGL >= 3.3 context on EGL (raises if none can be made).

    Returns
    -------
    moderngl.Context
        The context, made on first use.

    Examples
    --------
    >>> context().version_code >= 330
    True
    """
    global _CTX
    if _CTX is None:
        import moderngl
        _CTX = moderngl.create_standalone_context(backend="egl", require=330)
    return _CTX


def upload_levels(ctx, levels, wrap=(True, True), nearest: bool = False):
    """A float32 texture whose MIP level ``k`` is ``levels[k]`` (``(H_k, W_k, C)``, C <= 4;
    row 0 is texture coordinate ``t = 0``).

    Parameters
    ----------
    ctx : moderngl.Context
        The context (:func:`context`).
    levels : list of (H_k, W_k, C) array_like
        The MIP levels, level 0 first.
    wrap : (bool, bool)
        Repeat along s and t (else clamp).
    nearest : bool
        Nearest filtering (else linear, ``LINEAR_MIPMAP_NEAREST`` with levels).

    Returns
    -------
    moderngl.Texture
        The texture (release it when done).

    Examples
    --------
    >>> tex = upload_levels(context(), [np.ones((4, 4, 4)), np.ones((2, 2, 4))])
    >>> tex.size, tex.components, tex.dtype
    ((4, 4), 4, 'f4')
    >>> tex.release()
    """
    import moderngl
    levels = [np.ascontiguousarray(level, dtype=np.float32) for level in levels]
    h, w, c = levels[0].shape
    tex = ctx.texture((w, h), c, levels[0].tobytes(), dtype="f4")
    if len(levels) > 1:
        tex.build_mipmaps(0, len(levels) - 1)
        for k, level in enumerate(levels[1:], 1):
            tex.write(level.tobytes(), level=k)
        tex.filter = (moderngl.NEAREST_MIPMAP_NEAREST if nearest else moderngl.LINEAR_MIPMAP_NEAREST,
                      moderngl.NEAREST if nearest else moderngl.LINEAR)
    else:
        tex.filter = (moderngl.NEAREST, moderngl.NEAREST) if nearest else (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x, tex.repeat_y = bool(wrap[0]), bool(wrap[1])
    return tex


def evaluate(library: str, body: str, inputs: dict, *, uniforms: dict | None = None,
             textures: dict | None = None, version: str = "330", defines: dict | None = None,
             declarations: str = "") -> np.ndarray:
    """``(N, 4)`` float32: ``body`` run once per element on the GPU.

    Parameters
    ----------
    library : str
        Shader library prepended (:func:`microfacet.glsl.source` name), e.g. ``"leadr"``.
    body : str
        GLSL statements assigning ``vec4 result``; input ``x`` is the ``vec4 x`` (missing
        components 0).
    inputs : dict of name -> (N, C) array, C <= 4
        Per-element inputs (same N).
    uniforms : dict of name -> value
        Uniforms declared in ``declarations`` (or the library), set with moderngl.
    textures : dict of name -> (levels, wrap) or (levels, wrap, nearest)
        Samplers (``uniform highp sampler2D name;`` in ``declarations`` or the library).
    version : str
        GLSL version (:data:`microfacet.glsl.VERSIONS`).
    defines : dict, optional
        Macros (:func:`microfacet.glsl.source`).
    declarations : str
        GLSL placed after the library (uniforms, helper functions).

    Returns
    -------
    (N, 4) float32 ndarray
        ``result`` per element.

    Raises
    ------
    ValueError
        Inputs of different lengths or more than 4 components.

    Examples
    --------
    The shader's Schlick term against the library's:

    >>> import numpy as np, microfacet as mf
    >>> c = np.array([[1.0], [0.5], [0.1]])                                  # cos theta_d
    >>> gl = evaluate("common", "result = vec4(mf_fresnel_schlick(vec3(0.04), vec3(1.0), x.x), 1.0);", {"x": c})
    >>> bool(np.allclose(gl[:, :3], mf.fresnel.Schlick(0.04)(c[:, 0]), atol=1e-6))
    True
    """
    import moderngl
    ctx = context()
    arrays = {k: np.asarray(v, dtype=np.float32).reshape(len(v), -1) for k, v in inputs.items()}
    n = len(next(iter(arrays.values())))
    if any(len(a) != n or a.shape[1] > 4 for a in arrays.values()):
        raise ValueError("inputs must be (N, C) arrays of the same N with C <= 4")
    w = min(n, _WIDTH)
    h = -(-n // w)
    fetch = "\n".join(f"    vec4 {k} = texelFetch(mf_in_{k}, p, 0);" for k in arrays)
    decl = "\n".join(f"uniform highp sampler2D mf_in_{k};" for k in arrays)
    frag = (source(library, version, defines) + declarations + "\n" + decl
            + "\nout vec4 mf_out;\nvoid main() {\n    ivec2 p = ivec2(gl_FragCoord.xy);\n"
            + fetch + "\n    vec4 result = vec4(0.0);\n" + body + "\n    mf_out = result;\n}\n")
    vert = source("common", version).split("\n")[0] + "\n" + _VERTEX   # version line only
    prog = ctx.program(vertex_shader=vert, fragment_shader=frag)
    owned, unit = [], 0
    for k, a in arrays.items():
        pad = np.zeros((w * h, 4), np.float32)
        pad[:n, :a.shape[1]] = a
        tex = upload_levels(ctx, [pad.reshape(h, w, 4)], nearest=True)
        owned.append(tex)
        if f"mf_in_{k}" in prog:
            tex.use(unit)
            prog[f"mf_in_{k}"].value = unit
            unit += 1
    for name, spec in (textures or {}).items():
        tex = upload_levels(ctx, *spec)
        owned.append(tex)
        if name in prog:
            tex.use(unit)
            prog[name].value = unit
            unit += 1
    for name, value in (uniforms or {}).items():
        if name in prog:
            v = np.asarray(value)
            prog[name].value = (tuple(map(tuple, v)) if v.ndim == 2 else tuple(v.tolist()) if v.ndim == 1
                                else v.item())
    out = ctx.texture((w, h), 4, dtype="f4")
    fbo = ctx.framebuffer(color_attachments=[out])
    quad = ctx.buffer(np.array([-1, -1, 3, -1, -1, 3], dtype=np.float32).tobytes())
    vao = ctx.vertex_array(prog, [(quad, "2f", "in_pos")])
    fbo.use()
    ctx.viewport = (0, 0, w, h)
    vao.render(moderngl.TRIANGLES)
    data = np.frombuffer(fbo.read(components=4, dtype="f4"), dtype=np.float32).reshape(h * w, 4)[:n].copy()
    for obj in (vao, quad, fbo, out, prog, *owned):
        obj.release()
    return data
