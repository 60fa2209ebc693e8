"""LEADR pyramids for engines: per-MIP-level normal, roughness and anisotropy textures.

A LEADR pyramid (``microfacet bake``; :mod:`microfacet.leadr`) holds, per texel and MIP
level, the five slope moments ``E1..E5 = E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~]`` (Dupuy
2015, Eqs. 3.5-3.9). Engines take a tangent-space normal map and a roughness (glTF:
``metallicRoughness`` G channel) with, at most, an anisotropy strength and direction
(``KHR_materials_anisotropy``). Per level this module writes (:func:`level_parameters`,
:func:`encode_level`):

* **normal map** from the mean slope ``(x, y) = (E1, E2)``: ``n = (-x, -y, 1) / |.|``,
  stored ``round(255 (n + 1) / 2)`` (glTF: +X right, +Y up the image, +Z out; the same as
  :func:`microfacet.leadr.encode_normal_map`);
* **slope covariance** ``Sx = E3 - E1^2``, ``Sy = E4 - E2^2``, ``C = E5 - E1 E2`` (plus an
  optional base roughness, added as independent moments, Listing 5.1), turned into the
  Beckmann ellipse with ``alpha^2 = 2 sigma^2`` (the library's convention,
  :func:`microfacet.leadr.from_moments`): eigenvalues
  ``l1,2 = (Sx + Sy)/2 +- sqrt(((Sx - Sy)/2)^2 + C^2)``, ``alpha1,2 = sqrt(2 l1,2)``, the
  ``alpha1`` axis at ``phi = atan2(2 C, Sx - Sy) / 2`` from the tangent towards the
  bitangent (:func:`ellipse_of_covariance`; inverse :func:`covariance_of_ellipse`);
* engines' lobe is GGX: it takes the Beckmann ``alpha`` as is (both have the peak
  ``D(0) = 1 / (pi alpha1 alpha2)``; GGX's slope variance is infinite, so no moment match
  exists), then ``KHR_materials_anisotropy`` (``alpha_t = mix(r^2, 1, s^2)``, ``alpha_b = r^2``
  along the direction): **roughness** ``r = sqrt(alpha2)`` in the G channel of
  ``metallic_roughness`` (B: metalness 1, scaled by ``metallicFactor``; R: 255), **anisotropy**
  RGB ``= ((cos phi + 1)/2, (sin phi + 1)/2, s)`` with ``s = sqrt((alpha1 - alpha2) / (1 - alpha2))``
  (:func:`microfacet.export.gltf.roughness_anisotropy`, vectorised here), ``alpha1`` clipped
  to 1, ``phi`` in ``(-pi/2, pi/2]`` (``cos phi >= 0``; isotropic texels point along the tangent).

:func:`decode_level` is the inverse (what a conforming engine evaluates at a texel centre).
:func:`export_leadr` writes the PNG MIP chains (``--to textures``: lossless, one file per level,
for an application to upload as mipmaps), the KTX2 MIP chains (``--to ktx2``: one file per
texture holding every level, Basis Universal UASTC, linear; :func:`encode_ktx2`) or a ``.glb`` of
a textured plane whose three textures are those KTX2 chains (``--to gltf``; glTF holds a custom
MIP chain only as KTX2, ``KHR_texture_basisu``, so engines sample the LEADR levels instead of
building their own), and the report of what is not carried (:data:`NOT_CARRIED`) with the 8-bit
round trip's error per level and, for KTX2, the UASTC round trip's (:func:`ktx2_error`). The KTX2
encoder is ``alktx2`` (Binomial's basisu behind a Python interface; the ``export`` extra):
:func:`ktx2_writer`. :func:`ktx2_info` reads a KTX2 header from the specification alone.

Examples
--------
>>> import microfacet as mf
>>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((16, 16), 0.3, seed=1))
>>> levels = leadr_textures(pyramid, base_roughness=0.1)
>>> sorted(levels[0]), levels[0]["normal"].shape
(['anisotropy', 'metallic_roughness', 'normal'], (16, 16, 3))
"""
from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from ..errors import MicrofacetError
from ..io.png import read_png_data, write_png_data

__all__ = ["ellipse_of_covariance", "covariance_of_ellipse", "gltf_parameters", "level_parameters",
           "encode_level", "decode_level", "leadr_textures", "naive_textures", "box_downsample",
           "write_chains", "read_chains", "plane_mesh", "write_plane_glb", "export_leadr", "quantization_error",
           "ktx2_writer", "ktx2_level_sizes", "encode_ktx2", "ktx2_info", "decode_ktx2", "write_ktx2_chains",
           "ktx2_error", "run_cli", "TEXTURES", "TARGETS", "NOT_CARRIED", "KTX2_CODEC", "KTX2_EFFORT", "KTX2_ZSTD"]

#: The three textures of a level, in the order they are written.
TEXTURES = ("normal", "metallic_roughness", "anisotropy")
#: ``export_leadr``'s formats.
TARGETS = ("textures", "ktx2", "gltf")
#: What engines' textures cannot carry exactly (written into every report).
NOT_CARRIED = [
    "Beckmann lobe: engines' lobe is GGX; it takes the Beckmann alpha (same peak D(0) = 1/(pi a1 a2), "
    "heavier tails; GGX has no finite slope variance, so the moments cannot be matched)",
    "filtering in the moments: engines interpolate the encoded textures (sqrt(alpha), strength, direction, "
    "normal) bilinearly within a level and linearly between levels, which is exact only at texel centres "
    "of each level",
    "8-bit storage: roughness r = sqrt(alpha2) and strength in steps of 1/255 (per-level error below)",
    "alpha1 > 1 is clipped to 1 (glTF's alpha_t <= 1)",
    "the anisotropy direction is an axis (phi and phi + pi are one ellipse) stored as a vector with "
    "cos(phi) >= 0: filtering between texels whose axes straddle +-90 degrees shortens or turns it",
    "engines choose the MIP level from their own footprint (isotropic trilinear, or anisotropic filtering "
    "when enabled), not LEADR's anisotropic footprint lookup",
    "correlation rho: carried by the direction of the ellipse (the same distribution)",
]
#: Smallest alpha written (a single facet has zero variance; as :data:`microfacet.leadr.moments.MIN_ALPHA`).
MIN_ALPHA = 1e-3


def ellipse_of_covariance(vx, vy, cxy):
    """``(alpha1, alpha2, phi)`` of the slope covariance ``[[vx, cxy], [cxy, vy]]``
    (Beckmann: ``alpha^2 = 2 sigma^2``, Dupuy 2015 Eq. 3.5-3.9): ``alpha1 >= alpha2`` from the
    eigenvalues, ``phi = atan2(2 cxy, vx - vy) / 2`` in ``(-pi/2, pi/2]`` the ``alpha1`` axis
    from the tangent towards the bitangent. Negative eigenvalues (rounding) become 0.
    Exact to float64 rounding (:func:`covariance_of_ellipse` is the inverse).

    Parameters
    ----------
    vx, vy, cxy : array_like
        Slope variances and covariance (broadcast together).

    Returns
    -------
    alpha1, alpha2, phi : ndarray
        The Beckmann ellipses' radii and the ``alpha1`` axis's azimuth (radians).

    Examples
    --------
    >>> [round(float(v), 6) for v in ellipse_of_covariance(0.02, 0.02, 0.01)]
    [0.244949, 0.141421, 0.785398]
    """
    vx, vy, cxy = (np.asarray(v, dtype=np.float64) for v in (vx, vy, cxy))
    mean, half = 0.5 * (vx + vy), 0.5 * (vx - vy)
    r = np.hypot(half, cxy)
    l1, l2 = np.maximum(mean + r, 0.0), np.maximum(mean - r, 0.0)
    phi = 0.5 * np.arctan2(2.0 * cxy, vx - vy)
    phi = np.where(phi <= -0.5 * np.pi, phi + np.pi, phi)
    return np.sqrt(2.0 * l1), np.sqrt(2.0 * l2), phi


def covariance_of_ellipse(alpha1, alpha2, phi):
    """``(vx, vy, cxy)``: the slope covariance of a Beckmann ellipse (radii ``alpha1,
    alpha2``, ``alpha1`` axis at ``phi``), ``R diag(a1^2, a2^2) R^T / 2``.

    Parameters
    ----------
    alpha1, alpha2, phi : array_like
        Radii and azimuth (radians) of the ellipses (broadcast together).

    Returns
    -------
    vx, vy, cxy : ndarray
        Slope variances and covariance.

    Examples
    --------
    >>> [round(float(v), 6) for v in covariance_of_ellipse(0.3, 0.1, 0.0)]
    [0.045, 0.005, 0.0]
    """
    a1, a2, phi = (np.asarray(v, dtype=np.float64) for v in (alpha1, alpha2, phi))
    l1, l2 = 0.5 * a1 * a1, 0.5 * a2 * a2
    c, s = np.cos(phi), np.sin(phi)
    return l1 * c * c + l2 * s * s, l1 * s * s + l2 * c * c, (l1 - l2) * c * s


def gltf_parameters(alpha1, alpha2):
    """``(roughness, strength, clipped)`` arrays of KHR_materials_anisotropy for ellipses
    ``alpha1 >= alpha2``: ``alpha_t = mix(r^2, 1, s^2) = min(alpha1, 1)``, ``alpha_b = r^2 =
    min(alpha2, 1)``; ``clipped`` marks ``alpha1 > 1`` (the vectorised
    :func:`microfacet.export.gltf.roughness_anisotropy`).

    Parameters
    ----------
    alpha1, alpha2 : array_like
        Radii of the ellipses, ``alpha1 >= alpha2``.

    Returns
    -------
    roughness, strength : ndarray
        ``sqrt(alpha2)`` and ``sqrt((alpha1 - alpha2) / (1 - alpha2))`` (alphas clipped to 1).
    clipped : ndarray of bool
        Where ``alpha1 > 1``.

    Examples
    --------
    >>> r, s, clipped = gltf_parameters([0.5, 2.0], [0.1, 0.1])
    >>> r.round(4).tolist(), s.round(4).tolist(), clipped.tolist()
    ([0.3162, 0.3162], [0.6667, 1.0], [False, True])
    """
    a1, a2 = (np.asarray(v, dtype=np.float64) for v in (alpha1, alpha2))
    clipped = a1 > 1.0
    a1, a2 = np.minimum(a1, 1.0), np.minimum(a2, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(a2 >= 1.0, 0.0, np.sqrt(np.maximum(a1 - a2, 0.0) / np.maximum(1.0 - a2, 1e-300)))
    return np.sqrt(a2), np.clip(s, 0.0, 1.0), clipped


def level_parameters(E, base_roughness=None) -> dict:
    """Engine parameters of one pyramid level ``E (H, W, 5)``: ``slopes`` (mean slope
    ``(E1, E2)``), the covariance ``vx, vy, cxy`` (with ``base_roughness`` added: ``None``,
    ``alpha``, ``(alpha_x, alpha_y)`` or a Beckmann lobe, :func:`microfacet.leadr.base_moments`),
    its ellipse ``alpha1, alpha2, phi`` (``alpha`` at least :data:`MIN_ALPHA`) and the glTF
    ``roughness, strength, clipped`` (module docstring).

    Parameters
    ----------
    E : (H, W, 5) array_like
        One level of a moment pyramid (:func:`microfacet.leadr.bake`).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every texel's moments.

    Returns
    -------
    dict
        ``slopes (H, W, 2)`` and ``(H, W)`` arrays ``vx, vy, cxy, alpha1, alpha2, phi,
        roughness, strength, clipped``.

    Raises
    ------
    ValueError
        ``E`` is not ``(H, W, 5)``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> p = level_parameters(pyramid[0], base_roughness=0.1)
    >>> p["slopes"].shape, p["alpha1"].shape, bool((p["alpha1"] >= p["alpha2"]).all())
    ((8, 8, 2), (8, 8), True)
    """
    from ..leadr import base_moments, convolve, covariance
    E = np.asarray(E, dtype=np.float64)
    if E.ndim != 3 or E.shape[2] != 5 or 0 in E.shape:
        raise ValueError(f"a pyramid level must be (H, W, 5), got shape {E.shape}")
    base = base_moments(base_roughness)
    if base is not None:
        E = convolve(E, base)
    vx, vy, cxy = covariance(E)
    a1, a2, phi = ellipse_of_covariance(vx, vy, cxy)
    a1, a2 = np.maximum(a1, MIN_ALPHA), np.maximum(a2, MIN_ALPHA)
    r, s, clipped = gltf_parameters(a1, a2)
    return {"slopes": E[..., :2], "vx": vx, "vy": vy, "cxy": cxy, "alpha1": a1, "alpha2": a2, "phi": phi,
            "roughness": r, "strength": s, "clipped": clipped}


def _u8(v) -> np.ndarray:
    return np.rint(np.clip(v, 0.0, 1.0) * 255.0).astype(np.uint8)


def encode_level(params: dict) -> dict[str, np.ndarray]:
    """The three ``(H, W, 3)`` uint8 textures (:data:`TEXTURES`) of :func:`level_parameters`'
    output (module docstring). Texels whose strength rounds to 0 point along the tangent.

    Parameters
    ----------
    params : dict
        :func:`level_parameters` of a level.

    Returns
    -------
    dict
        :data:`TEXTURES` name -> ``(H, W, 3)`` uint8 image.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> images = encode_level(level_parameters(pyramid[0], 0.1))
    >>> [(name, images[name].shape, images[name].dtype.name) for name in TEXTURES][0]
    ('normal', (8, 8, 3), 'uint8')
    """
    from ..leadr import encode_normal_map
    r, s, phi = params["roughness"], params["strength"], params["phi"]
    ones = np.ones_like(r)
    mr = np.stack([ones, r, ones], axis=-1)
    s8 = _u8(s)
    c, sn = np.where(s8 > 0, np.cos(phi), 1.0), np.where(s8 > 0, np.sin(phi), 0.0)
    aniso = np.stack([_u8(0.5 * c + 0.5), _u8(0.5 * sn + 0.5), s8], axis=-1)
    return {"normal": encode_normal_map(params["slopes"], np.uint8), "metallic_roughness": _u8(mr),
            "anisotropy": aniso}


def decode_level(images: dict) -> dict:
    """What a conforming glTF engine reads at the texel centres of :func:`encode_level`'s
    textures: ``slopes`` of the normal (``-n_xy / n_z``), ``roughness``, ``strength``, ``phi``
    (of the normalised direction, as three.js), ``alpha_t = mix(r^2, 1, s^2)``, ``alpha_b = r^2``
    and their covariance ``vx, vy, cxy`` (``alpha^2 = 2 sigma^2``).

    Parameters
    ----------
    images : dict
        The three textures of a level (:func:`encode_level`, :func:`read_chains`).

    Returns
    -------
    dict
        ``slopes (H, W, 2)`` and ``(H, W)`` arrays ``roughness, strength, phi, alpha_t,
        alpha_b, vx, vy, cxy``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> p = level_parameters(pyramid[0], 0.1)
    >>> d = decode_level(encode_level(p))
    >>> float(np.abs(d["alpha_b"] - p["alpha2"]).max() / p["alpha2"].min()) < 0.02    # 8 bits of sqrt(alpha)
    True
    """
    n = images["normal"].astype(np.float64) / 127.5 - 1.0
    r = images["metallic_roughness"][..., 1].astype(np.float64) / 255.0
    a = images["anisotropy"].astype(np.float64)
    d = a[..., :2] / 127.5 - 1.0
    s = a[..., 2] / 255.0
    phi = np.arctan2(d[..., 1], d[..., 0])
    at, ab = r * r + s * s * (1.0 - r * r), r * r
    vx, vy, cxy = covariance_of_ellipse(at, ab, phi)
    with np.errstate(divide="ignore", invalid="ignore"):
        slopes = -n[..., :2] / np.maximum(n[..., 2:], 1e-6)
    return {"slopes": slopes, "roughness": r, "strength": s, "phi": phi, "alpha_t": at, "alpha_b": ab,
            "vx": vx, "vy": vy, "cxy": cxy}


def quantization_error(params: dict, images: dict) -> dict:
    """Error of the 8-bit textures against the exact parameters of one level: ``covariance``
    (mean and max over texels of ``|S_decoded - S|_F / |S|_F``, clipped texels excluded),
    ``alpha`` (max ``|alpha - alpha_decoded| / alpha`` over both axes), ``slope`` (max abs of
    the mean slope's error) and ``clipped`` (fraction of texels with ``alpha1 > 1``).

    Parameters
    ----------
    params : dict
        :func:`level_parameters` of a level.
    images : dict
        Its textures (:func:`encode_level`).

    Returns
    -------
    dict
        ``covariance_mean``, ``covariance_max``, ``alpha_max``, ``slope_max``, ``clipped``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> p = level_parameters(pyramid[0], 0.1)
    >>> q = quantization_error(p, encode_level(p))
    >>> sorted(q), q["covariance_max"] < 0.05, q["clipped"]
    (['alpha_max', 'clipped', 'covariance_max', 'covariance_mean', 'slope_max'], True, 0.0)
    """
    d = decode_level(images)
    keep = ~params["clipped"]
    a1, a2 = np.minimum(params["alpha1"], 1.0), np.minimum(params["alpha2"], 1.0)
    vx, vy, cxy = covariance_of_ellipse(a1, a2, params["phi"])
    norm = np.sqrt(vx**2 + vy**2 + 2 * cxy**2)
    diff = np.sqrt((d["vx"] - vx) ** 2 + (d["vy"] - vy) ** 2 + 2 * (d["cxy"] - cxy) ** 2)
    rel = (diff / norm)[keep] if keep.any() else np.zeros(1)
    ea = np.maximum(np.abs(d["alpha_t"] - a1) / a1, np.abs(d["alpha_b"] - a2) / a2)
    return {"covariance_mean": float(rel.mean()), "covariance_max": float(rel.max()),
            "alpha_max": float(ea[keep].max()) if keep.any() else 0.0,
            "slope_max": float(np.abs(d["slopes"] - params["slopes"]).max()),
            "clipped": float(params["clipped"].mean())}


def _levels_of(source) -> tuple[list[np.ndarray], str]:
    """``(levels, label)`` of a pyramid file or a list of ``(H, W, 5)`` levels."""
    from ..leadr import read_pyramid
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.is_file():
            raise MicrofacetError(f"{path}: no such pyramid file (a moment pyramid EXR from 'microfacet bake')")
        return read_pyramid(path), str(path)
    levels = [np.asarray(level) for level in source]
    if not levels or any(lv.ndim != 3 or lv.shape[2] != 5 for lv in levels):
        raise ValueError("pyramid must be a non-empty list of (H, W, 5) moment levels")
    return levels, "a moment pyramid"


def leadr_textures(pyramid, base_roughness=None, with_parameters: bool = False):
    """Per level (level 0 first) the dict of three uint8 textures (:func:`encode_level`) of a
    moment pyramid (a list of ``(H, W, 5)`` or a pyramid EXR path); ``base_roughness`` is
    added to every level (leave it None when the pyramid was baked with ``--roughness``: it
    holds it already). ``with_parameters``: also return the per-level parameters.

    Parameters
    ----------
    pyramid : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR (``microfacet bake``).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level (:func:`level_parameters`).
    with_parameters : bool
        Also return the :func:`level_parameters` of each level.

    Returns
    -------
    list of dict, or (list of dict, list of dict)
        The textures per level (and the parameters).

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> levels = leadr_textures(pyramid, base_roughness=0.1)
    >>> [level["metallic_roughness"].shape[:2] for level in levels]
    [(8, 8), (4, 4), (2, 2), (1, 1)]
    """
    levels, _ = _levels_of(pyramid)
    params = [level_parameters(E, base_roughness) for E in levels]
    images = [encode_level(p) for p in params]
    return (images, params) if with_parameters else images


def box_downsample(image: np.ndarray) -> np.ndarray:
    """The next MIP level of an ``(H, W, C)`` texture by the box filter of
    :func:`microfacet.leadr.mip_pyramid` (2x2 means for even sizes), in float64.

    Parameters
    ----------
    image : (H, W, C) ndarray
        A texture level.

    Returns
    -------
    ndarray
        The next level, float64.

    Examples
    --------
    >>> box_downsample(np.arange(16.0).reshape(4, 4, 1))[..., 0].tolist()
    [[2.5, 4.5], [10.5, 12.5]]
    """
    from ..leadr import mip_pyramid
    return mip_pyramid(np.asarray(image, dtype=np.float64))[1]


def naive_textures(level0: dict) -> list[dict]:
    """The MIP chain an engine makes from level 0 alone (``generateMipmap``): each texture's
    encoded values box-filtered level by level (normals averaged, then renormalised when
    encoded; roughness, strength and direction averaged) and rounded to 8 bits. With a
    constant base roughness the roughness stays constant: the naive MIPs of Dupuy 2015,
    Fig. 5.3 (what LEADR is compared against).

    Parameters
    ----------
    level0 : dict
        The level-0 textures (:func:`encode_level`).

    Returns
    -------
    list of dict
        The chain, level 0 first, down to 1 x 1.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> naive = naive_textures(leadr_textures(pyramid, base_roughness=0.1)[0])
    >>> len(naive), naive[-1]["normal"].shape
    (4, (1, 1, 3))
    """
    from ..leadr import mip_pyramid
    chains = {}
    for name in TEXTURES:
        levels = mip_pyramid(level0[name].astype(np.float64))
        if name == "normal":
            out = []
            for lv in levels:
                n = lv / 127.5 - 1.0
                n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-9)
                out.append(_u8(0.5 * n + 0.5))
            chains[name] = out
        else:
            chains[name] = [np.rint(lv).astype(np.uint8) for lv in levels]
    return [{name: chains[name][k] for name in TEXTURES} for k in range(len(chains["normal"]))]


def write_chains(levels: list[dict], folder) -> dict[str, list[Path]]:
    """Write ``folder/<texture>/level_00.png, level_01.png, ...`` (8-bit RGB) for each of
    :data:`TEXTURES`; returns the paths per texture.

    Parameters
    ----------
    levels : list of dict
        Textures per level (:func:`leadr_textures`).
    folder : str or os.PathLike
        The folder (created).

    Returns
    -------
    dict
        Texture name -> the paths of its levels.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> paths = write_chains(leadr_textures(pyramid, 0.1), "maps")
    >>> [p.as_posix() for p in paths["anisotropy"][:2]]
    ['maps/anisotropy/level_00.png', 'maps/anisotropy/level_01.png']
    """
    folder = Path(folder)
    paths = {}
    for name in TEXTURES:
        (folder / name).mkdir(parents=True, exist_ok=True)
        paths[name] = [write_png_data(folder / name / f"level_{k:02d}.png", lv[name]) for k, lv in enumerate(levels)]
    return paths


def read_chains(folder) -> list[dict]:
    """The levels written by :func:`write_chains` (uint8 arrays).

    Parameters
    ----------
    folder : str or os.PathLike
        A folder of :func:`write_chains` (``microfacet export --to textures``).

    Returns
    -------
    list of dict
        Textures per level, level 0 first.

    Raises
    ------
    MicrofacetError
        The folder has no ``normal/level_00.png``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> levels = leadr_textures(pyramid, 0.1)
    >>> _ = write_chains(levels, "maps")
    >>> back = read_chains("maps")
    >>> len(back), all((back[k][t] == levels[k][t]).all() for k in range(4) for t in TEXTURES)
    (4, True)
    """
    folder = Path(folder)
    files = sorted((folder / "normal").glob("level_*.png"))
    if not files:
        raise MicrofacetError(f"{folder}: no normal/level_00.png "
                              "(a texture folder of 'microfacet export --to textures')")
    return [{name: read_png_data(folder / name / f.name)[..., :3] for name in TEXTURES} for f in files]


# --- KTX2 (Basis Universal UASTC) MIP chains: KHR_texture_basisu ------------------------------------------

#: Basis Universal mode of the KTX2 images. KHR_texture_basisu allows ETC1S and UASTC LDR 4x4; UASTC
#: (8 bits per texel, BC7-class) is the one for normal maps and data textures (ETC1S: 1-2 bits per texel,
#: made for colour).
KTX2_CODEC = "uastc"
#: The encoder's effort (basisu 0..10: UASTC pack level; above 3 changes the error by < 1/255 RMS at many
#: times the time).
KTX2_EFFORT = 3
#: The Zstandard supercompression level of the KTX2 files (lossless).
KTX2_ZSTD = 6
_KTX2_ID = b"\xabKTX 20\xbb\r\n\x1a\n"
_SUPERCOMPRESSION = {0: "none", 1: "basislz", 2: "zstd", 3: "zlib"}
_COLOR_MODELS = {1: "rgbsda", 163: "etc1s", 166: "uastc"}


def ktx2_writer(required: bool = True):
    """The Basis Universal KTX2 encoder (the ``alktx2`` module: Binomial's basisu behind a
    Python interface, with a custom MIP chain) or, when it is not installed, ``None``
    (``required=False``) or one line saying how to install it.

    Parameters
    ----------
    required : bool
        Raise when the writer is absent.

    Returns
    -------
    module or None
        ``alktx2``.

    Raises
    ------
    MicrofacetError
        ``required`` and ``alktx2`` is not installed.

    Examples
    --------
    >>> ktx2_writer(required=False) is None or hasattr(ktx2_writer(), "encode_raw_mips_to_ktx2")
    True
    >>> KTX2_CODEC, KTX2_EFFORT, KTX2_ZSTD
    ('uastc', 3, 6)
    """
    try:
        import alktx2
    except ImportError:
        if required:
            raise MicrofacetError("KTX2 (KHR_texture_basisu) needs the Basis Universal encoder alktx2: "
                                  "pip install 'microfacet[export]' (Python >= 3.11)") from None
        return None
    return alktx2


def ktx2_level_sizes(height: int, width: int, levels: int) -> list[tuple[int, int]]:
    """``(H, W)`` of each MIP level KTX2 requires of a ``height x width`` level 0:
    ``max(1, floor(size / 2^k))`` (KTX 2.0 specification, section 4.1; the sizes of
    :func:`microfacet.leadr.mip_pyramid`).

    Parameters
    ----------
    height, width : int
        Level 0's size.
    levels : int
        How many levels.

    Returns
    -------
    list of (int, int)
        Level 0 first.

    Examples
    --------
    >>> ktx2_level_sizes(48, 32, 6)
    [(48, 32), (24, 16), (12, 8), (6, 4), (3, 2), (1, 1)]
    """
    return [(max(1, height >> k), max(1, width >> k)) for k in range(levels)]


def encode_ktx2(chain, effort: int = KTX2_EFFORT, zstd: int | None = KTX2_ZSTD) -> bytes:
    """The KTX2 file (bytes) of one texture's MIP chain ``chain`` (``(H, W, 3)`` uint8 arrays, level 0
    first, sizes :func:`ktx2_level_sizes`): Basis Universal UASTC LDR 4x4 (:data:`KTX2_CODEC`), linear
    transfer function (data, not colour: no sRGB decode), Zstandard supercompression ``zstd`` (None:
    none), every given level stored as is (the encoder makes no MIPs of its own; basisu's
    ``m_source_mipmap_images``). UASTC is lossy: :func:`decode_ktx2` gives back what an engine
    samples (a few 1/255 RMS, up to ~30/255 in 4x4 blocks whose three channels vary independently,
    e.g. anisotropy direction and strength; the export's report measures it per level).

    Parameters
    ----------
    chain : list of (H, W, 3) uint8 arrays
        The levels.
    effort : int
        basisu's effort, 0..10.
    zstd : int or None
        Zstandard level (1..22), or None.

    Returns
    -------
    bytes
        The ``.ktx2`` file.

    Raises
    ------
    ValueError
        An empty chain, a level that is not ``(H, W, 3)`` uint8 or whose size is not KTX2's.
    MicrofacetError
        The writer (:func:`ktx2_writer`) is not installed.

    Examples
    --------
    >>> import microfacet as mf
    >>> levels = leadr_textures(mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)), 0.1)
    >>> data = encode_ktx2([lv["normal"] for lv in levels])               # doctest: +SKIP
    >>> info = ktx2_info(data)                                            # doctest: +SKIP
    >>> info["levels"], info["color_model"], info["transfer"]             # doctest: +SKIP
    ([(8, 8), (4, 4), (2, 2), (1, 1)], 'uastc', 'linear')
    """
    chain = [np.asarray(a) for a in chain]
    if not chain or any(a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 for a in chain):
        raise ValueError("a KTX2 chain must be a non-empty list of (H, W, 3) uint8 levels")
    want = ktx2_level_sizes(*chain[0].shape[:2], len(chain))
    got = [a.shape[:2] for a in chain]
    if got != want:
        raise ValueError(f"KTX2 MIP levels must halve (floor, at least 1) level by level: got sizes {got}, "
                         f"KTX2 needs {want}")
    writer = ktx2_writer()
    raw = [(np.ascontiguousarray(np.concatenate([a, np.full(a.shape[:2] + (1,), 255, np.uint8)], -1)).tobytes(),
            int(a.shape[1]), int(a.shape[0])) for a in chain]
    return bytes(writer.encode_raw_mips_to_ktx2(
        raw, has_alpha=False, codec=KTX2_CODEC, quality=100, effort=int(effort), srgb=False, linear=True,
        zstd_supercompression_level=zstd, threads=0))


def ktx2_info(data) -> dict:
    """The header of a KTX2 file (bytes or a path), read here from the KTX 2.0 specification
    (Khronos, sections 3-4: identifier, index, level index, Data Format Descriptor, key/value data),
    independently of the encoder: ``vk_format`` (0 for Basis Universal), ``type_size``, ``width``,
    ``height``, ``layers``, ``faces``, ``levels`` (``(H, W)`` per level, level 0 first),
    ``level_bytes`` (stored bytes per level), ``supercompression`` (``"none"``, ``"basislz"``,
    ``"zstd"``, ``"zlib"``), the DFD's ``color_model`` (``"uastc"``, ``"etc1s"``, ``"rgbsda"`` or its
    number), ``transfer`` (``"linear"``, ``"srgb"`` or its number) and ``channels`` (its sample
    channel ids), and ``kv`` (key/value strings).

    Parameters
    ----------
    data : bytes, str or os.PathLike
        The file or its bytes.

    Returns
    -------
    dict
        The fields above.

    Raises
    ------
    MicrofacetError
        Not a KTX2 file, or one cut short.

    Examples
    --------
    >>> ktx2_info(b"not a ktx2 file")
    Traceback (most recent call last):
    ...
    microfacet.errors.MicrofacetError: not a KTX2 file (no KTX 20 identifier)
    """
    import struct
    if isinstance(data, (str, os.PathLike)):
        data = Path(data).read_bytes()
    data = bytes(data)
    if data[:12] != _KTX2_ID:
        raise MicrofacetError("not a KTX2 file (no KTX 20 identifier)")
    try:
        (vk, type_size, w, h, _depth, layers, faces, nlev, scheme) = struct.unpack_from("<9I", data, 12)
        dfd_off, _dfd_len, kvd_off, kvd_len = struct.unpack_from("<4I", data, 48)
        index = [struct.unpack_from("<3Q", data, 80 + 24 * k) for k in range(max(nlev, 1))]
        model, _primaries, transfer = struct.unpack_from("<3B", data, dfd_off + 12)
        block_size = struct.unpack_from("<H", data, dfd_off + 4 + 6)[0]
        channels = [data[dfd_off + 4 + 24 + 16 * i + 3] & 0x0F for i in range((block_size - 24) // 16)]
        kv, pos = {}, kvd_off
        while pos < kvd_off + kvd_len:
            n = struct.unpack_from("<I", data, pos)[0]
            key, _, value = data[pos + 4:pos + 4 + n].partition(b"\0")
            kv[key.decode("utf-8", "replace")] = value.rstrip(b"\0").decode("utf-8", "replace")
            pos += 4 + n + (-n % 4)
    except struct.error:
        raise MicrofacetError("KTX2 file cut short (its index points past the end)") from None
    if any(off + length > len(data) for off, length, _ in index):
        raise MicrofacetError("KTX2 file cut short (a MIP level lies past the end)")
    return {"vk_format": vk, "type_size": type_size, "width": w, "height": h, "layers": layers, "faces": faces,
            "levels": ktx2_level_sizes(h, w, max(nlev, 1)), "level_bytes": [int(length) for _, length, _ in index],
            "supercompression": _SUPERCOMPRESSION.get(scheme, scheme), "color_model": _COLOR_MODELS.get(model, model),
            "transfer": {1: "linear", 2: "srgb"}.get(transfer, transfer), "channels": channels, "kv": kv}


def decode_ktx2(data) -> list[np.ndarray]:
    """The levels of a Basis Universal KTX2 file (bytes or a path) transcoded to 8-bit RGB
    (basisu's transcoder, :func:`ktx2_writer`'s module): ``(H, W, 3)`` uint8 per level, level 0
    first: the texels an engine samples (before its own transcode to a GPU block format, which
    for UASTC -> ASTC 4x4 or BC7 is near lossless).

    Parameters
    ----------
    data : bytes, str or os.PathLike
        The ``.ktx2`` file or its bytes.

    Returns
    -------
    list of (H, W, 3) uint8 arrays

    Raises
    ------
    MicrofacetError
        Not a KTX2 file, or the transcoder is not installed.

    Examples
    --------
    >>> import microfacet as mf
    >>> levels = leadr_textures(mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)), 0.1)
    >>> back = decode_ktx2(encode_ktx2([lv["metallic_roughness"] for lv in levels]))   # doctest: +SKIP
    >>> [b.shape for b in back]                                                         # doctest: +SKIP
    [(8, 8, 3), (4, 4, 3), (2, 2, 3), (1, 1, 3)]
    """
    import imagecodecs
    if isinstance(data, (str, os.PathLike)):
        data = Path(data).read_bytes()
    info = ktx2_info(data)
    writer = ktx2_writer()
    out = []
    for k, (h, w) in enumerate(info["levels"]):
        png, _ = writer.decode_ktx2_to_bytes(bytes(data), format="png", level=k)
        img = imagecodecs.png_decode(png)
        out.append(np.ascontiguousarray(img[:h, :w, :3]))     # the transcoder pads levels below 4 x 4 to a block
    return out


def write_ktx2_chains(levels: list[dict], folder, effort: int = KTX2_EFFORT) -> dict[str, Path]:
    """Write ``folder/<texture>.ktx2`` for each of :data:`TEXTURES`: its whole MIP chain in one
    KTX2 file (:func:`encode_ktx2`, UASTC, linear); returns the paths.

    Parameters
    ----------
    levels : list of dict
        Textures per level (:func:`leadr_textures`).
    folder : str or os.PathLike
        The folder (created).
    effort : int
        basisu's effort (:func:`encode_ktx2`).

    Returns
    -------
    dict
        Texture name -> its ``.ktx2``.

    Examples
    --------
    >>> import microfacet as mf
    >>> levels = leadr_textures(mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)), 0.1)
    >>> paths = write_ktx2_chains(levels, "maps_ktx2")                        # doctest: +SKIP
    >>> sorted(p.name for p in paths.values())                                # doctest: +SKIP
    ['anisotropy.ktx2', 'metallic_roughness.ktx2', 'normal.ktx2']
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name in TEXTURES:
        paths[name] = folder / f"{name}.ktx2"
        paths[name].write_bytes(encode_ktx2([lv[name] for lv in levels], effort=effort))
    return paths


def ktx2_error(params: list[dict], levels: list[dict], blobs: dict[str, bytes]) -> list[dict]:
    """Per level, the error of the KTX2 chains ``blobs`` (texture name -> ``.ktx2`` bytes of
    ``levels``) decoded as an engine samples them (:func:`decode_ktx2`): ``quantization``
    (:func:`quantization_error` of the decoded textures against the exact ``params``), and per
    texture the largest and the RMS texel difference from the 8-bit textures (``texel_max``,
    ``texel_rms``, in 1/255).

    Parameters
    ----------
    params : list of dict
        :func:`level_parameters` per level.
    levels : list of dict
        The 8-bit textures per level (:func:`encode_level`).
    blobs : dict
        :data:`TEXTURES` name -> KTX2 bytes.

    Returns
    -------
    list of dict
        One dict per level.

    Examples
    --------
    >>> import microfacet as mf
    >>> levels, params = leadr_textures(mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)), 0.1,
    ...                                 with_parameters=True)
    >>> blobs = {t: encode_ktx2([lv[t] for lv in levels]) for t in TEXTURES}          # doctest: +SKIP
    >>> sorted(ktx2_error(params, levels, blobs)[0])                                  # doctest: +SKIP
    ['quantization', 'texel_max', 'texel_rms']
    """
    decoded = {name: decode_ktx2(blobs[name]) for name in TEXTURES}
    out = []
    for k, (p, lv) in enumerate(zip(params, levels)):
        images = {name: decoded[name][k] for name in TEXTURES}
        diff = {name: images[name].astype(np.int16) - lv[name].astype(np.int16) for name in TEXTURES}
        out.append({"quantization": quantization_error(p, images),
                    "texel_max": {n: int(np.abs(d).max()) for n, d in diff.items()},
                    "texel_rms": {n: float(np.sqrt(np.mean(d.astype(np.float64) ** 2))) for n, d in diff.items()}})
    return out


def plane_mesh(tiles: float = 1.0):
    """``(positions, normals, tangents, uvs, indices)`` of the unit square ``[-1/2, 1/2]^2`` in
    glTF's ground plane (x, z; normal +y), tangent +x (``w = 1``: bitangent ``n x t = -z``), uv
    ``(x + 1/2, z + 1/2) * tiles`` so that the image's top row (``v = 0``) lies towards ``-z``, the
    bitangent: the normal map's +Y and the anisotropy's ``phi`` turn from the tangent towards it.

    Parameters
    ----------
    tiles : float
        Repeats of the map along each axis.

    Returns
    -------
    positions, normals : (4, 3) float32
    tangents : (4, 4) float32
    uvs : (4, 2) float32
    indices : (6,) uint32
        Two counter-clockwise triangles seen from +y.

    Examples
    --------
    >>> p, n, t, uv, idx = plane_mesh(tiles=2.0)
    >>> uv.tolist(), idx.tolist()
    ([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]], [0, 3, 2, 0, 2, 1])
    """
    p = np.array([[-0.5, 0, -0.5], [0.5, 0, -0.5], [0.5, 0, 0.5], [-0.5, 0, 0.5]], np.float32)
    n = np.tile(np.array([[0, 1, 0]], np.float32), (4, 1))
    t = np.tile(np.array([[1, 0, 0, 1]], np.float32), (4, 1))
    uv = ((p[:, [0, 2]] + 0.5) * tiles).astype(np.float32)
    idx = np.array([0, 3, 2, 0, 2, 1], np.uint32)          # counter-clockwise seen from +y
    return p, n, t, uv, idx


def _glb_material(metallic: float, base_color) -> dict:
    return {"name": "leadr", "pbrMetallicRoughness": {
        "baseColorFactor": [*map(float, base_color), 1.0], "metallicFactor": float(metallic), "roughnessFactor": 1.0,
        "metallicRoughnessTexture": {"index": 1}}, "normalTexture": {"index": 0, "scale": 1.0},
        "extensions": {"KHR_materials_anisotropy": {"anisotropyStrength": 1.0, "anisotropyRotation": 0.0,
                                                    "anisotropyTexture": {"index": 2}}}}


def write_plane_glb(textures, path, tiles: float = 1.0, metallic: float = 1.0, base_color=(0.9, 0.9, 0.9),
                    ktx2: dict | None = None, png_fallback: bool = False) -> Path:
    """Write ``path`` (``.glb``): a unit plane (:func:`plane_mesh`) whose material holds the
    textures (:data:`TEXTURES`) as ``normalTexture``, ``metallicRoughnessTexture`` and
    ``KHR_materials_anisotropy.anisotropyTexture`` (strength 1, rotation 0), sampler REPEAT with
    trilinear minification.

    Without ``ktx2``: level 0 (``textures``, or ``textures[0]`` of a chain) as embedded PNG images;
    engines make their own (naive) MIPs of it. With ``ktx2`` (texture name -> the ``.ktx2`` bytes of
    its whole chain, :func:`encode_ktx2`): each texture's image is that KTX2 file
    (``mimeType image/ktx2``), referenced through ``KHR_texture_basisu`` (glTF's only way to carry a
    custom MIP chain: engines sample the LEADR levels); ``KHR_texture_basisu`` is then in
    ``extensionsRequired`` (a viewer without it cannot load the file), unless ``png_fallback``
    adds level 0 as each texture's PNG ``source`` (viewers without the extension take it, with
    naive MIPs; the extension is then only in ``extensionsUsed``).

    Parameters
    ----------
    textures : dict or list of dict
        The level-0 textures (:func:`encode_level`) or the chain (:func:`leadr_textures`).
    path : str or os.PathLike
        The ``.glb`` to write.
    tiles : float
        Repeats of the map along each axis of the plane.
    metallic : float
        ``metallicFactor`` in ``[0, 1]``.
    base_color : (3,) sequence
        Linear RGB ``baseColorFactor``.
    ktx2 : dict, optional
        :data:`TEXTURES` name -> KTX2 bytes (Basis Universal: ETC1S or UASTC, as KHR_texture_basisu
        requires).
    png_fallback : bool
        With ``ktx2``: also embed level 0 as PNG fallbacks.

    Returns
    -------
    Path
        ``path``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1))
    >>> levels = leadr_textures(pyramid, 0.1)
    >>> glb = write_plane_glb(levels[0], "plane.glb", tiles=4)
    >>> from microfacet.export.gltf import read_material
    >>> sorted(read_material(glb)["extensions"])
    ['KHR_materials_anisotropy']
    >>> blobs = {t: encode_ktx2([lv[t] for lv in levels]) for t in TEXTURES}           # doctest: +SKIP
    >>> glb = write_plane_glb(levels, "plane_ktx2.glb", ktx2=blobs)                   # doctest: +SKIP
    >>> import pygltflib; pygltflib.GLTF2.load("plane_ktx2.glb").extensionsRequired   # doctest: +SKIP
    ['KHR_texture_basisu']
    """
    import imagecodecs
    import pygltflib as g
    level0 = textures[0] if isinstance(textures, (list, tuple)) else textures
    if ktx2 is not None and sorted(ktx2) != sorted(TEXTURES):
        raise ValueError(f"ktx2 must map each of {', '.join(TEXTURES)} to its KTX2 bytes, got {sorted(ktx2)}")
    path = Path(path)
    used = ["KHR_materials_anisotropy"] + ([] if ktx2 is None else ["KHR_texture_basisu"])
    gl = g.GLTF2(asset=g.Asset(version="2.0", generator="microfacet.export.leadr_textures"), extensionsUsed=used)
    if ktx2 is not None and not png_fallback:
        gl.extensionsRequired = ["KHR_texture_basisu"]
    blob = b""
    arrays = [(a, ct, kind, tgt) for a, (ct, kind, tgt) in zip(plane_mesh(tiles), [
        (g.FLOAT, "VEC3", g.ARRAY_BUFFER), (g.FLOAT, "VEC3", g.ARRAY_BUFFER), (g.FLOAT, "VEC4", g.ARRAY_BUFFER),
        (g.FLOAT, "VEC2", g.ARRAY_BUFFER), (g.UNSIGNED_INT, "SCALAR", g.ELEMENT_ARRAY_BUFFER)])]
    for k, (arr, ctype, kind, target) in enumerate(arrays):
        data = arr.tobytes()
        gl.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data), target=target))
        acc = g.Accessor(bufferView=k, componentType=ctype, count=len(arr) if arr.ndim > 1 else arr.size, type=kind)
        if k == 0:
            acc.min, acc.max = arr.min(axis=0).tolist(), arr.max(axis=0).tolist()
        gl.accessors.append(acc)
        blob += data + b"\0" * (-len(data) % 4)

    def image(data: bytes, mime: str, name: str) -> int:
        nonlocal blob
        gl.bufferViews.append(g.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        gl.images.append(g.Image(bufferView=len(gl.bufferViews) - 1, mimeType=mime, name=name))
        blob += data + b"\0" * (-len(data) % 4)
        return len(gl.images) - 1

    gl.samplers = [g.Sampler(magFilter=9729, minFilter=9987, wrapS=10497, wrapT=10497)]
    for name in TEXTURES:
        png = (None if ktx2 is not None and not png_fallback else
               image(imagecodecs.png_encode(np.ascontiguousarray(level0[name]), level=6), "image/png", name))
        ext = None if ktx2 is None else {"KHR_texture_basisu": {"source": image(bytes(ktx2[name]), "image/ktx2",
                                                                                 name + " (KTX2 MIP chain)")}}
        gl.textures.append(g.Texture(sampler=0, source=png, extensions=ext or {}))
    mat = _glb_material(metallic, base_color)
    pbr = g.PbrMetallicRoughness(**mat["pbrMetallicRoughness"])
    gl.materials = [g.Material(name=mat["name"], pbrMetallicRoughness=pbr,
                               normalTexture=g.NormalMaterialTexture(**mat["normalTexture"]),
                               extensions=mat["extensions"])]
    gl.buffers = [g.Buffer(byteLength=len(blob))]
    gl.meshes = [g.Mesh(name="plane", primitives=[g.Primitive(
        attributes=g.Attributes(POSITION=0, NORMAL=1, TANGENT=2, TEXCOORD_0=3), indices=4, material=0)])]
    gl.nodes = [g.Node(mesh=0, name="plane")]
    gl.scenes = [g.Scene(nodes=[0])]
    gl.scene = 0
    gl.set_binary_blob(blob)
    path.parent.mkdir(parents=True, exist_ok=True)
    gl.save_binary(str(path))
    return path


def _ktx2_note(glb: bool, fallback: bool = False) -> str:
    """What the KTX2 chains lose (UASTC) and, for the ``.glb``, what a viewer needs to read them."""
    text = ("the custom MIP chains are Basis Universal UASTC LDR 4x4 KTX2 images (KHR_texture_basisu, the only "
            "Basis mode fit for normal and data textures): a lossy block codec, 8 bits per texel; where a 4x4 block's "
            "three channels vary independently (anisotropy direction and strength, noisy normals) a texel moves by up "
            "to a few tens of 1/255: the decoded chain's error per level is in the KTX2 table. Engines transcode UASTC to a GPU "
            "format (ASTC 4x4 or BC7: near lossless; ETC2, BC1/BC3 or RGBA8 where those are absent)")
    if not glb:
        return text
    return text + (". Viewers without KHR_texture_basisu fall back to level 0 (PNG) and build naive MIPs from it"
                   if fallback else ". KHR_texture_basisu is required: a viewer without it cannot load the .glb")


def _markdown(report: dict) -> str:
    lines = [f"# LEADR export of {report['source']} to {report['format']}", "", f"Files: `{report['file']}`"
             + (f" and the MIP chains in `{report['chains']}`" if report.get("chains") != report["file"] else ""), "",
             f"Base roughness added: {report['base_roughness']}. Levels: {len(report['levels'])}.", "",
             "## 8-bit round trip per level (decoded as a glTF engine reads texel centres)", "",
             "| level | size | covariance rel. error mean | max | alpha rel. error max | mean-slope error max "
             "| alpha1 > 1 (clipped) | mean alpha1 | mean alpha2 |", "|---|---|---|---|---|---|---|---|---|"]
    for k, lv in enumerate(report["levels"]):
        q = lv["quantization"]
        lines.append(f"| {k} | {lv['size'][1]}x{lv['size'][0]} | {q['covariance_mean']:.4f} "
                     f"| {q['covariance_max']:.4f} "
                     f"| {q['alpha_max']:.4f} | {q['slope_max']:.4f} | {q['clipped']:.2%} | {lv['alpha1_mean']:.4f} "
                     f"| {lv['alpha2_mean']:.4f} |")
    if all("ktx2" in lv for lv in report["levels"]):
        lines += ["", f"## KTX2 (Basis {KTX2_CODEC.upper()}) round trip per level (the chain transcoded to RGBA8)", "",
                  "| level | size | covariance rel. error mean | max | mean-slope error max | "
                  + " | ".join(f"{t} texel error max / RMS (1/255)" for t in TEXTURES) + " |",
                  "|---|---|---|---|---|" + "---|" * len(TEXTURES)]
        for k, lv in enumerate(report["levels"]):
            e = lv["ktx2"]
            q = e["quantization"]
            lines.append(f"| {k} | {lv['size'][1]}x{lv['size'][0]} | {q['covariance_mean']:.4f} "
                         f"| {q['covariance_max']:.4f} | {q['slope_max']:.4f} | "
                         + " | ".join(f"{e['texel_max'][t]} / {e['texel_rms'][t]:.2f}" for t in TEXTURES) + " |")
    lines += ["", "## Not carried", ""] + [f"- {x}" for x in report["lost"]]
    return "\n".join(lines) + "\n"


def export_leadr(source, to: str, out, base_roughness=None, tiles: float = 1.0, metallic: float = 1.0,
                 base_color=(0.9, 0.9, 0.9), png_fallback: bool = False) -> dict:
    """Export a LEADR moment pyramid (a pyramid EXR of ``microfacet bake`` or a list of
    ``(H, W, 5)`` levels) for engines (module docstring) and return the report.

    ``to="textures"``: the folder ``out`` with ``normal/``, ``metallic_roughness/``,
    ``anisotropy/`` each holding ``level_00.png ...`` (8-bit RGB, one lossless file per MIP level:
    an application uploads them as the textures' mipmaps).
    ``to="ktx2"``: the folder ``out`` with ``normal.ktx2``, ``metallic_roughness.ktx2`` and
    ``anisotropy.ktx2``, each the texture's whole MIP chain (:func:`write_ktx2_chains`: Basis UASTC,
    linear).
    ``to="gltf"``: ``out`` (``.glb`` added if missing), a textured unit plane (:func:`write_plane_glb`,
    uv ``tiles`` times the map, ``metallic``, ``base_color``) whose three textures are those KTX2
    chains (``KHR_texture_basisu``, required unless ``png_fallback``).
    Each writes the report ``<out>.export.json`` / ``.export.md``: what is not carried and, per
    level, the error of the 8-bit textures decoded as an engine reads them
    (:func:`quantization_error`) and, for ``ktx2`` and ``gltf``, of the KTX2 chains transcoded back
    (:func:`ktx2_error`).

    Parameters
    ----------
    source : list of (H, W, 5) arrays, str or os.PathLike
        A moment pyramid or its EXR.
    to : str
        One of :data:`TARGETS`.
    out : str or os.PathLike
        The folder (``"textures"``, ``"ktx2"``) or the ``.glb`` (``"gltf"``).
    base_roughness : None, float, (float, float) or Beckmann
        A base lobe added to every level.
    tiles, metallic, base_color
        The plane's (``"gltf"``; :func:`write_plane_glb`).
    png_fallback : bool
        ``"gltf"``: also embed level 0 as PNG, for viewers without KHR_texture_basisu.

    Returns
    -------
    dict
        The report: ``format``, ``file``, ``chains``, ``lost`` (:data:`NOT_CARRIED`, and for
        KTX2 the UASTC note), ``levels`` (per level its size, mean alphas,
        :func:`quantization_error` and, for KTX2, ``ktx2``: :func:`ktx2_error`), ...

    Raises
    ------
    ValueError
        ``to``, ``tiles`` or ``metallic`` out of range, or levels that are not ``(H, W, 5)``.
    MicrofacetError
        No such pyramid file, ``out`` is a file where a folder is written, or the KTX2 writer
        (:func:`ktx2_writer`) is not installed for ``"ktx2"`` or ``"gltf"``.

    Examples
    --------
    >>> import microfacet as mf
    >>> pyramid = mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=0), roughness=0.05)
    >>> TARGETS
    ('textures', 'ktx2', 'gltf')
    >>> report = export_leadr(pyramid, "textures", "bumps")
    >>> report["file"], report["chains"], len(report["levels"]), report["lost"] == NOT_CARRIED
    ('bumps', 'bumps', 4, True)
    >>> report = export_leadr(pyramid, "gltf", "bumps")                                     # doctest: +SKIP
    >>> report["file"], sorted(report["levels"][0]["ktx2"])                                  # doctest: +SKIP
    ('bumps.glb', ['quantization', 'texel_max', 'texel_rms'])
    """
    if to not in TARGETS:
        raise ValueError(f"to must be one of {', '.join(TARGETS)} for a LEADR pyramid, got {to!r}")
    for name, v in (("tiles", tiles), ("metallic", metallic)):
        if not (np.isfinite(v) and v > 0 if name == "tiles" else np.isfinite(v) and 0 <= v <= 1):
            raise ValueError(f"{name} must be {'> 0' if name == 'tiles' else 'in [0, 1]'}, got {v!r}")
    if to != "textures":
        ktx2_writer()                               # one line before any work when the encoder is absent
    levels, label = _levels_of(source)
    images, params = leadr_textures(levels, base_roughness, with_parameters=True)
    out = Path(out)
    blobs = None
    if to == "gltf":
        if out.suffix.lower() != ".glb":
            out = out.with_name(out.name + ".glb")
        blobs = {name: encode_ktx2([lv[name] for lv in images]) for name in TEXTURES}
        write_plane_glb(images, out, tiles=tiles, metallic=metallic, base_color=base_color, ktx2=blobs,
                        png_fallback=png_fallback)
        chains, files = out, {name: f"KTX2 image '{name} (KTX2 MIP chain)' (KHR_texture_basisu)" for name in TEXTURES}
        lost = NOT_CARRIED + [_ktx2_note(True, png_fallback)]
    else:
        if out.exists() and not out.is_dir():
            raise MicrofacetError(f"{out}: exists and is not a folder (--to {to} writes a folder)")
        chains = out
        if to == "ktx2":
            paths = write_ktx2_chains(images, out)
            blobs = {name: p.read_bytes() for name, p in paths.items()}
            files = {name: f"{name}.ktx2" for name in TEXTURES}
            lost = NOT_CARRIED + [_ktx2_note(False)]
        else:
            write_chains(images, out)
            files = {name: f"{name}/level_NN.png" for name in TEXTURES}
            lost = list(NOT_CARRIED)
    summary = [{"size": list(p["alpha1"].shape), "quantization": quantization_error(p, im),
                "alpha1_mean": float(p["alpha1"].mean()), "alpha2_mean": float(p["alpha2"].mean()),
                "strength_mean": float(p["strength"].mean())} for p, im in zip(params, images)]
    if blobs is not None:
        for lv, e in zip(summary, ktx2_error(params, images, blobs)):
            lv["ktx2"] = e
    report = {"format": to, "file": str(out), "chains": str(chains), "source": label, "lost": lost,
              "base_roughness": None if base_roughness is None else str(base_roughness), "levels": summary,
              "convention": "alpha^2 = 2 sigma^2 (Beckmann); GGX alpha = Beckmann alpha; r = sqrt(alpha2), "
                            "s = sqrt((alpha1 - alpha2)/(1 - alpha2)), direction (cos phi, sin phi)",
              "textures": files}
    if blobs is not None:
        report["ktx2"] = {"codec": f"Basis Universal {KTX2_CODEC.upper()} LDR 4x4", "transfer": "linear",
                          "effort": KTX2_EFFORT, "zstd": KTX2_ZSTD,
                          "bytes": {name: len(b) for name, b in blobs.items()}}
    stem = str(out).rstrip("/\\")
    Path(stem + ".export.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    Path(stem + ".export.md").write_text(_markdown(report))
    return report


def run_cli(args) -> int:
    """``microfacet export PYRAMID.exr --to textures|ktx2|gltf -o OUT [--base-roughness A]`` (called by
    :mod:`microfacet.cli.export` for a pyramid, ``--to textures`` or ``--to ktx2``): one line per error.

    Parameters
    ----------
    args : argparse.Namespace
        ``fit`` (the pyramid EXR), ``to``, ``output``, ``base_roughness``, ``model``.

    Returns
    -------
    int
        0 (errors raise): prints the summary line, and what is not carried to stderr.

    Raises
    ------
    MicrofacetError
        The source is not a pyramid EXR, or a target or option that does not apply.

    Examples
    --------
    >>> import argparse, microfacet as mf
    >>> _ = mf.leadr.write_pyramid("bumps.exr", mf.leadr.bake(mf.leadr.gaussian_heightfield((8, 8), 0.3, seed=1)))
    >>> run_cli(argparse.Namespace(fit="bumps.exr", to="textures", output="bumps_maps", base_roughness=0.1,
    ...                            model="best"))
    bumps_maps: 4 MIP levels as textures; 8-bit covariance error max ...; report bumps_maps.export.md
    0
    """
    from ..cli.common import check_output_name, output_path
    source = Path(args.fit)
    if source.suffix.lower() != ".exr":
        raise MicrofacetError(f"{source}: --to {args.to} takes a LEADR pyramid (PYRAMID.exr from 'microfacet bake'), "
                              "not a fit file")
    if args.to not in TARGETS:
        raise MicrofacetError(f"{source}: a LEADR pyramid exports --to textures, --to ktx2 or --to gltf, "
                              f"not --to {args.to}")
    if getattr(args, "model", "best") != "best":
        raise MicrofacetError("--model applies to fit files, not to a LEADR pyramid")
    base = getattr(args, "base_roughness", None)
    if base is not None and not (np.isfinite(base) and base >= 0):
        raise ValueError(f"--base-roughness must be a finite alpha >= 0, got {base}")
    if not source.is_file():
        raise MicrofacetError(f"{source}: no such file")
    out = output_path(args.output, ".glb", source=source) if args.to == "gltf" else Path(check_output_name(args.output))
    report = export_leadr(source, args.to, out, base_roughness=base)
    q = [lv["quantization"]["covariance_max"] for lv in report["levels"]]
    k = [lv["ktx2"]["quantization"]["covariance_mean"] for lv in report["levels"] if "ktx2" in lv]
    print(f"{report['file']}: {len(report['levels'])} MIP levels as {args.to}"
          + (" (KTX2 MIP chains, KHR_texture_basisu)" if args.to == "gltf" else "")
          + f"; 8-bit covariance error max {max(q):.4f}"
          + (f"; UASTC covariance error mean, worst level {max(k):.4f}" if k else "")
          + f"; report {report['file'].rstrip('/')}.export.md")
    for line in report["lost"]:
        print(f"  not carried: {line}", file=sys.stderr)
    return 0
