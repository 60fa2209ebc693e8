"""Estimators of reflected radiance ``L_o(wo) = int L_i(wi) f_r(wi, wo) cos theta_i dwi``.

Directional light: the integral collapses to ``E f_r(wi, wo) cos theta_i``. Environment
light: Monte Carlo with the BRDF's own importance sampling (``brdf.sample``),

    L_o ~= 1/n sum_k weight_k L_env(wi_k),   weight_k = f_r(wi_k, wo) cos theta_ik / pdf(wi_k),

i.e. ``evalp_is`` of the thesis (Listing 1.2). The uniforms fed to ``sample`` are
randomized quasi-Monte Carlo points: the 2-D Sobol' sequence (a (0, 2)-sequence in base 2,
so any ``2^m`` consecutive points stratify every dyadic box of area ``2^-m``) with an
independent random digital shift per pixel (XOR of random bits), which keeps the
stratification and makes every point uniform, so the estimator stays unbiased.
"""
from __future__ import annotations

import numpy as np

from ..geometry import to_world

__all__ = ["shade_directional", "shade_environment", "sobol_02", "shifted_sobol"]

#: Upper bound on BRDF samples per vectorized batch (bounds memory, ~100 MB).
BATCH_SAMPLES = 1 << 18


def shade_directional(brdf, wo, wi, irradiance) -> np.ndarray:
    """Radiance ``E f_r(wi, wo) cos theta_i`` ``(N, 3)`` reflected toward local ``wo``
    ``(N, 3)`` from a directional light of local direction ``wi`` ``(N, 3)``.

    Parameters
    ----------
    brdf : BRDF
        The BRDF.
    wo : (N, 3) ndarray
        Local view directions.
    wi : (N, 3) ndarray
        Local light directions.
    irradiance : float or (3,) array_like
        ``E`` of the light.

    Returns
    -------
    (N, 3) ndarray
        Reflected radiance.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> wo = np.array([[0.0, 0.0, 1.0]])
    >>> wi = np.array([[0.0, 0.0, 1.0]])
    >>> (shade_directional(mf.Lambertian(0.5), wo, wi, np.ones(3)) * np.pi).round(6)    # E R cos / pi
    array([[0.5, 0.5, 0.5]])
    """
    return np.asarray(irradiance, dtype=np.float64) * brdf.eval_cos(wi, wo)


def sobol_02(n: int) -> np.ndarray:
    """First ``n`` points of the 2-D Sobol' sequence, ``(n, 2)`` uint32 fixed point
    (value ``* 2^-32``). Dimension 0 is the van der Corput sequence (bit reversal of the
    index), dimension 1 has direction numbers ``v_1 = 1/2``, ``v_j = v_(j-1) xor v_(j-1)/2``
    (Sobol' 1967), in natural order: for ``n = 2^m`` the same point set as
    ``scipy.stats.qmc.Sobol(2, scramble=False)``, a (0, m, 2)-net.

    Parameters
    ----------
    n : int
        Number of points.

    Returns
    -------
    (n, 2) ndarray of uint32
        The points, fixed point.

    Examples
    --------
    >>> sobol_02(4) / 2.0**32
    array([[0.  , 0.  ],
           [0.5 , 0.5 ],
           [0.25, 0.75],
           [0.75, 0.25]])
    """
    k = np.arange(n, dtype=np.uint32)
    out = np.zeros((n, 2), dtype=np.uint32)
    v = np.uint32(1 << 31)
    for j in range(max(1, (n - 1).bit_length())):      # loop over index bits
        bit = ((k >> j) & 1).astype(bool)
        out[bit, 0] ^= np.uint32(1 << (31 - j))
        out[bit, 1] ^= v
        v ^= v >> np.uint32(1)
    return out


def shifted_sobol(rng: np.random.Generator, n: int, spp: int) -> np.ndarray:
    """``(n, spp, 2)`` uniforms in ``[0, 1)``: the first ``spp`` Sobol' points
    (:func:`sobol_02`), XOR-ed with an independent random 32-bit digital shift per pixel
    and dimension (module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the shifts.
    n : int
        Pixels.
    spp : int
        Points per pixel.

    Returns
    -------
    (n, spp, 2) ndarray
        Uniforms.

    Examples
    --------
    >>> import numpy as np
    >>> u = shifted_sobol(np.random.default_rng(0), 3, 4)
    >>> u.shape, bool(((u >= 0) & (u < 1)).all())
    ((3, 4, 2), True)
    """
    shift = rng.integers(0, 1 << 32, size=(n, 1, 2), dtype=np.uint32)
    return (sobol_02(spp)[None] ^ shift) * 2.0**-32


def shade_environment(brdf, wo, frame, environment, spp: int, rng: np.random.Generator) -> np.ndarray:
    """Monte Carlo radiance ``(N, 3)`` reflected toward local ``wo`` ``(N, 3)`` under an
    environment, by importance sampling the BRDF (module docstring).

    Parameters
    ----------
    brdf : BRDF
        Any object of the BRDF protocol (``sample(u, wo) -> (wi, weight, pdf)``).
    wo : (N, 3)
        View directions in the local frames.
    frame : (s, t, n), each (N, 3)
        World tangents and normals, to bring sampled ``wi`` to the world.
    environment
        Anything with ``radiance(w_world) -> (..., 3)``, e.g. :class:`Environment`.
    spp : int
        Samples per pixel (randomized Sobol' points, :func:`shifted_sobol`); powers of
        two stratify best.
    rng : numpy.random.Generator
        Source of the uniforms; a fixed seed gives a deterministic image.

    Returns
    -------
    (N, 3) ndarray
        Reflected radiance, the mean of ``spp`` samples.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> from microfacet.render import Environment, Sphere
    >>> sphere = Sphere(16)
    >>> white = Environment(np.ones((8, 16, 3)))                   # a white furnace
    >>> radiance = shade_environment(mf.Lambertian(0.5), sphere.wo, sphere.frame, white, 16, np.random.default_rng(0))
    >>> bool(np.allclose(radiance, 0.5))                            # a Lambertian reflects its albedo
    True
    """
    if int(spp) != spp or spp < 1:
        raise ValueError(f"spp must be a positive integer, got {spp!r}")
    wo = np.asarray(wo, dtype=np.float64)
    s, t, n = (np.asarray(v, dtype=np.float64) for v in frame)
    n_px = wo.shape[0]
    u = shifted_sobol(rng, n_px, int(spp))
    total = np.zeros((n_px, 3))
    step = max(1, BATCH_SAMPLES // max(n_px, 1))
    for k in range(0, int(spp), step):      # loop over sample batches, not pixels
        uk = u[:, k:k + step]
        m = uk.shape[1]
        wi, weight, pdf = brdf.sample(uk, np.broadcast_to(wo[:, None], (n_px, m, 3)))
        ok = (pdf > 0)[..., None]             # failed samples: pdf 0, weight 0
        wi_world = to_world(np.where(ok, wi, 0.0), s[:, None], t[:, None], n[:, None])
        total += np.where(ok, weight * environment.radiance(wi_world), 0.0).sum(axis=1)
    return total / spp
