"""Textures of the GLSL shaders as float32 arrays (the layouts the shaders read).

LEADR pyramid (``leadr.glsl``), from :func:`pyramid_textures` or a pyramid EXR:

* ``e1234``: list of ``(H_k, W_k, 4)`` float32, MIP level ``k`` of an RGBA32F texture
  holding ``(E1, E2, E3, E4)``; row 0 is ``v = 0`` (upload rows in order);
* ``e5``: list of ``(H_k, W_k, 1)`` float32, the R32F texture of ``E5``.

Sampler state: wrap ``REPEAT``, ``LINEAR_MIPMAP_NEAREST`` min filter, ``LINEAR`` mag filter,
``TEXTURE_MAX_LEVEL = len(levels) - 1`` (the shader blends levels itself).

Fitted BRDF (``tabulated.glsl``, isotropic fits), from :func:`fit_textures` or a fit .npz:

* ``fit_table``: ``(3, W, 4)`` float32, RGBA32F, ``NEAREST``, read by ``texelFetch``;
  row 0 ``x``: ``ln D`` at the ``N`` elevation nodes; row 1 ``xy``: ``L1`` and ``dL1/ds h``
  on the ``M`` fine nodes; row 2 ``rgba``: Fresnel RGB and its ``cos theta_d``, ``K`` nodes;
* ``fit_sizes``: ``(3,)`` int32 ``(N, M, K)`` (uniform ``mf_fit_sizes``);
* ``alpha`` ``(2,)``, ``rho`` ``()``, ``mean_slope`` ``(2,)``, ``diffuse`` ``(3,)``, ``shadowing``:
  the uniforms of the ``MfSurface`` and of ``mf_fit_eval_cos``.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from ..io.exr import EXR_MAGIC
from ..io.read import read_bytes

__all__ = ["export_textures", "pyramid_textures", "fit_textures"]


def pyramid_textures(levels) -> dict:
    """``{"e1234": [...], "e5": [...]}`` of a moment pyramid (list of ``(H_k, W_k, 5)``)."""
    levels = [np.asarray(level, dtype=np.float32) for level in levels]
    for k, level in enumerate(levels):
        if level.ndim != 3 or level.shape[2] != 5:
            raise ValueError(f"pyramid level {k} must be (H, W, 5), got shape {level.shape}")
    return {"e1234": [np.ascontiguousarray(level[..., :4]) for level in levels],
            "e5": [np.ascontiguousarray(level[..., 4:]) for level in levels]}


def fit_textures(fit) -> dict:
    """Textures and uniforms of an isotropic :class:`~microfacet.fit.FittedBRDF` (module docstring)."""
    from ..distributions.tabulated import TabulatedIsotropic
    from ..fresnel import Tabulated
    d = fit.distribution
    if not isinstance(d, TabulatedIsotropic):
        raise MicrofacetError("the GLSL fitted BRDF takes isotropic fits only (this fit is anisotropic)")
    if fit.gaf_model != "smith":
        raise MicrofacetError(f"the GLSL fitted BRDF uses Smith masking; this fit's GAF is {fit.gaf_model!r}")
    if any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        raise MicrofacetError("the GLSL fitted BRDF needs scalar alpha, rho and mean slope")
    f = fit.fresnel
    if not isinstance(f, Tabulated):
        c = np.linspace(0.0, 1.0, 91)
        f = Tabulated(c, f(c))
    h = d.s_fine[1] - d.s_fine[0]
    rows = [np.stack([d.log_ndf], -1),
            np.stack([d.L1, -d.L0 * d.dxi_ds * h], -1),
            np.concatenate([f.values, f.cos_theta_d[:, None]], -1)]
    width = max(len(r) for r in rows)
    table = np.zeros((3, width, 4), dtype=np.float32)
    for i, r in enumerate(rows):
        table[i, :len(r), :r.shape[1]] = r
    return {"fit_table": table,
            "fit_sizes": np.array([len(r) for r in rows], dtype=np.int32),
            "alpha": np.array([d.alpha_x, d.alpha_y], dtype=np.float32),
            "rho": np.float32(d.rho), "mean_slope": np.asarray(d.mean_slope, dtype=np.float32),
            "diffuse": np.asarray(fit.diffuse, dtype=np.float32), "shadowing": bool(fit.shadowing)}


def export_textures(path: str | os.PathLike, base=None) -> dict:
    """Textures (float32 arrays, layout in the module docstring) of a pyramid EXR written by
    ``microfacet bake`` (merged with the ``base`` material when given:
    :func:`microfacet.leadr.downsample_operator`) or of a fit ``.npz`` of ``microfacet fit``.
    Raises :class:`MicrofacetError` naming the file when it is neither."""
    path = Path(path)
    head = read_bytes(path, "a pyramid EXR or a fit .npz", 4)
    if head == EXR_MAGIC[:4]:
        from ..leadr import downsample_operator, read_pyramid
        levels = read_pyramid(path)
        return pyramid_textures(levels if base is None else downsample_operator(levels, base))
    if head.startswith(b"PK"):
        from ..fit import load
        return fit_textures(load(path))
    raise MicrofacetError(f"{path}: neither an OpenEXR pyramid nor a .npz fit (starts with {head.hex() or 'nothing'})")
