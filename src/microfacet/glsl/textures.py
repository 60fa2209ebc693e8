"""Textures of the GLSL shaders as float32 arrays (the layouts the shaders read).

LEADR pyramid (``leadr.glsl``), from :func:`pyramid_textures` or a pyramid EXR:

* ``e1234``: list of ``(H_k, W_k, 4)`` float32, MIP level ``k`` of an RGBA32F texture
  holding ``(E1, E2, E3, E4)``; row 0 is ``v = 0`` (upload rows in order);
* ``e5``: list of ``(H_k, W_k, 1)`` float32, the R32F texture of ``E5``.

Sampler state: wrap ``REPEAT``, ``LINEAR_MIPMAP_NEAREST`` min filter, ``LINEAR`` mag filter,
``TEXTURE_MAX_LEVEL = len(levels) - 1`` (the shader blends levels itself).

Fitted BRDF (``tabulated.glsl``), from :func:`fit_textures` or a fit .npz; ``fit_table`` is
RGBA32F, ``NEAREST``, read by ``texelFetch``. Isotropic fits:

* ``fit_table``: ``(3, W, 4)`` float32, ``W = max(N, M, K)``;
  row 0 ``x``: ``ln D`` at the ``N`` elevation nodes; row 1 ``xy``: ``L1`` and ``dL1/ds h``
  on the ``M`` fine nodes; row 2 ``rgba``: Fresnel RGB and its ``cos theta_d``, ``K`` nodes;
* ``fit_sizes``: ``(3,)`` int32 ``(N, M, K)`` (uniform ``mf_fit_sizes``);
* ``fit_azimuths``: ``(2,)`` int32 ``(0, 0)`` (uniform ``mf_fit_azimuths``: isotropic).

Anisotropic fits (:class:`~microfacet.distributions.tabulated.TabulatedAnisotropic`):

* ``fit_table``: ``(N + L + 1, W, 4)`` float32, ``W = max(Nf, Na, K)``; rows ``0 .. N - 1``
  ``x``: the *refined* ``ln D`` (Catmull-Rom, ``log_ndf``) at ``theta_i = (i / (N - 1))^2 pi/2``
  and ``phi_j = 2 pi j / Nf`` (texel ``(j, i)``; the shader only interpolates it
  log-bilinearly); rows ``N .. N + L - 1`` ``xy``: the projected area ``A`` (``area_table``)
  at ``theta_l`` (``theta_k``), ``phi_j = 2 pi j / Na``, and ``theta_l`` itself; row
  ``N + L`` ``rgba``: the Fresnel table as above;
* ``fit_sizes``: ``(N, L, K)``; ``fit_azimuths``: ``(Nf, Na)``.

Both: ``alpha`` ``(2,)``, ``rho`` ``()``, ``mean_slope`` ``(2,)``, ``diffuse`` ``(3,)``,
``shadowing``: the uniforms of the ``MfSurface`` and of ``mf_fit_eval_cos``.
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
    """``{"e1234": [...], "e5": [...]}`` of a moment pyramid (list of ``(H_k, W_k, 5)``).

    Parameters
    ----------
    levels : list of (H_k, W_k, 5) array_like
        The moment pyramid, level 0 first.

    Returns
    -------
    dict
        ``e1234``: ``(H_k, W_k, 4)`` float32 levels; ``e5``: ``(H_k, W_k, 1)`` float32 levels.

    Raises
    ------
    ValueError
        A level that is not ``(H, W, 5)``.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = pyramid_textures(mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> [a.shape for a in t["e1234"]], t["e5"][0].dtype.name
    ([(8, 8, 4), (4, 4, 4), (2, 2, 4), (1, 1, 4)], 'float32')
    """
    levels = [np.asarray(level, dtype=np.float32) for level in levels]
    for k, level in enumerate(levels):
        if level.ndim != 3 or level.shape[2] != 5:
            raise ValueError(f"pyramid level {k} must be (H, W, 5), got shape {level.shape}")
    return {"e1234": [np.ascontiguousarray(level[..., :4]) for level in levels],
            "e5": [np.ascontiguousarray(level[..., 4:]) for level in levels]}


def fit_textures(fit) -> dict:
    """Textures and uniforms of a :class:`~microfacet.fit.FittedBRDF` (module docstring).

    Parameters
    ----------
    fit : FittedBRDF
        A tabulated fit (:func:`microfacet.fit.fit`) with Smith masking and scalar parameters.

    Returns
    -------
    dict
        ``fit_table``, ``fit_sizes``, ``fit_azimuths``, ``alpha``, ``rho``, ``mean_slope``,
        ``diffuse``, ``shadowing``.

    Raises
    ------
    MicrofacetError
        A fit the shader cannot evaluate.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = fit_textures(mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), resolution=8))
    >>> t["fit_table"].shape[0], t["fit_azimuths"].tolist(), t["fit_table"].dtype.name
    (3, [0, 0], 'float32')
    """
    from ..distributions.tabulated import TabulatedAnisotropic, TabulatedIsotropic
    from ..fresnel import Tabulated
    d = fit.distribution
    if not isinstance(d, (TabulatedIsotropic, TabulatedAnisotropic)):
        raise MicrofacetError(f"the GLSL fitted BRDF takes tabulated fits, got {type(d).__name__}")
    if fit.gaf_model != "smith":
        raise MicrofacetError(f"the GLSL fitted BRDF uses Smith masking; this fit's GAF is {fit.gaf_model!r}")
    if any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
        raise MicrofacetError("the GLSL fitted BRDF needs scalar alpha, rho and mean slope")
    f = fit.fresnel
    if not isinstance(f, Tabulated):
        c = np.linspace(0.0, 1.0, 91)
        f = Tabulated(c, f(c))
    fresnel = np.concatenate([f.values, f.cos_theta_d[:, None]], -1)
    if isinstance(d, TabulatedIsotropic):
        h = d.s_fine[1] - d.s_fine[0]
        rows = [d.log_ndf[:, None], np.stack([d.L1, -d.L0 * d.dxi_ds * h], -1), fresnel]
        sizes, azimuths = [len(r) for r in rows], (0, 0)
    else:
        theta_k = np.broadcast_to(d.theta_k[:, None], d.area_table.shape)
        rows = [*d.log_ndf[..., None], *np.stack([d.area_table, theta_k], -1), fresnel]
        sizes = (len(d.log_ndf), len(d.area_table), len(fresnel))
        azimuths = (d.log_ndf.shape[1], d.area_table.shape[1])
    table = np.zeros((len(rows), max(len(r) for r in rows), 4), dtype=np.float32)
    for i, r in enumerate(rows):
        table[i, :len(r), :r.shape[1]] = r
    return {"fit_table": table, "fit_sizes": np.array(sizes, dtype=np.int32),
            "fit_azimuths": np.array(azimuths, dtype=np.int32),
            "alpha": np.array([d.alpha_x, d.alpha_y], dtype=np.float32),
            "rho": np.float32(d.rho), "mean_slope": np.asarray(d.mean_slope, dtype=np.float32),
            "diffuse": np.asarray(fit.diffuse, dtype=np.float32), "shadowing": bool(fit.shadowing)}


def export_textures(path: str | os.PathLike, base=None) -> dict:
    """Textures (float32 arrays, layout in the module docstring) of a pyramid EXR written by
    ``microfacet bake`` (merged with the ``base`` material when given:
    :func:`microfacet.leadr.downsample_operator`) or of a fit ``.npz`` of ``microfacet fit``.
    Raises :class:`MicrofacetError` naming the file when it is neither.

    Parameters
    ----------
    path : str or os.PathLike
        A pyramid EXR or a fit ``.npz``.
    base : optional
        A base material merged into a pyramid's levels (a Beckmann alpha, a lobe or a fit).

    Returns
    -------
    dict
        :func:`pyramid_textures` or :func:`fit_textures`.

    Examples
    --------
    >>> import microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> sorted(export_textures("bumps.exr"))
    ['e1234', 'e5']
    >>> _ = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), resolution=8).save("ggx.npz")
    >>> export_textures("ggx.npz")["fit_sizes"].shape
    (3,)
    """
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
