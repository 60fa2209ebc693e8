"""Brute-force references for the P-NDF (Chermain et al. 2019, Sec. 5.1.1, Fig. 5): the
histogram of the interpolated normal map's slopes over a Gaussian footprint, and the
comparison of a microsurface's P-NDF against it (binned total-variation distance).

Independent of the lobe mixture: it only samples the footprint ``k_P`` and looks up the
bilinearly interpolated slopes (:func:`microfacet.glints.interpolate_slopes`).
"""
from __future__ import annotations

import numpy as np

from .microsurface import interpolate_slopes

__all__ = ["footprint_slopes", "slope_histogram", "compare_histogram"]


def footprint_slopes(slopes, center, cov, n: int = 1_000_000, seed: int = 0,
                     sigma_eps: float = 0.0) -> np.ndarray:
    """Slopes ``(n, 2)`` of the interpolated map at ``n`` points drawn from ``k_P``, plus
    isotropic Gaussian slope noise of std ``sigma_eps`` (the near-specular material of the
    paper's reference renderings, Sec. 5.2.2).

    Parameters
    ----------
    slopes : (H, W, 2) array_like
        Texel slopes.
    center : (2,) array_like
        Footprint centre in uv.
    cov : (2, 2) array_like
        Footprint covariance in uv^2.
    n : int
        Number of samples.
    seed : int
        Random seed.
    sigma_eps : float
        Slope noise added to each sample.

    Returns
    -------
    (n, 2) ndarray
        Slope samples.

    Examples
    --------
    A constant map gives its slope everywhere:

    >>> s = footprint_slopes(np.broadcast_to([0.1, 0.2], (4, 4, 2)), [0.5, 0.5], np.eye(2) * 1e-3, n=100)
    >>> s.shape, bool(np.allclose(s, [0.1, 0.2]))
    ((100, 2), True)
    """
    rng = np.random.default_rng(seed)
    L = np.linalg.cholesky(np.asarray(cov, dtype=np.float64) + 1e-300 * np.eye(2))
    uv = np.asarray(center, dtype=np.float64) + rng.standard_normal((n, 2)) @ L.T
    s = interpolate_slopes(slopes, uv)
    return s + sigma_eps * rng.standard_normal(s.shape) if sigma_eps > 0 else s


def slope_histogram(samples, edges_x, edges_y) -> np.ndarray:
    """Bin probabilities ``(bx, by)`` of slope samples (fraction of all samples).

    Parameters
    ----------
    samples : (n, 2) ndarray
        Slope samples.
    edges_x, edges_y : array_like
        Bin edges per axis.

    Returns
    -------
    (bx, by) ndarray
        The fraction of the samples in each bin (those outside every bin are left out).

    Examples
    --------
    >>> p = slope_histogram(np.array([[0.1, 0.1], [-0.1, 0.1], [2.0, 0.0]]), [-1, 0, 1], [-1, 0, 1])
    >>> p.round(3).tolist()
    [[0.0, 0.333], [0.0, 0.333]]
    """
    H, _, _ = np.histogram2d(samples[:, 0], samples[:, 1], bins=(edges_x, edges_y))
    return H / samples.shape[0]


def _bin_masses_sampled(ms, edges_x, edges_y, center, cov, n: int, seed: int) -> np.ndarray:
    """Bin probabilities of the P-NDF in slope space by sampling the lobe mixture."""
    u = np.random.default_rng(seed + 1).random((n, 3))
    return slope_histogram(ms.sample_slopes(u, center, cov), edges_x, edges_y)


def _bin_masses(ms, edges_x, edges_y, center, cov, sub: int, **kwargs) -> np.ndarray:
    """Bin probabilities of the P-NDF in slope space (midpoint rule, ``sub^2`` per bin)."""
    def fine(e):
        t = (np.arange(sub) + 0.5) / sub
        return (e[:-1, None] + np.diff(e)[:, None] * t).ravel()
    fx, fy = fine(edges_x), fine(edges_y)
    X, Y = np.meshgrid(fx, fy, indexing="ij")
    p = ms.slope_pdf(np.stack([X, Y], -1), center, cov, **kwargs)
    area = np.diff(edges_x)[:, None].repeat(sub, 0) / sub * (np.diff(edges_y)[None, :].repeat(sub, 1) / sub)
    m = p * area
    bx, by = len(edges_x) - 1, len(edges_y) - 1
    return m.reshape(bx, sub, by, sub).sum(axis=(1, 3))


def compare_histogram(ms, center, cov, *, bins: int = 24, n: int = 1_000_000, sub: int = 4,
                      seed: int = 0, method: str = "sample", rough: bool = True, **kwargs) -> dict:
    """Binned comparison of ``ms``'s P-NDF with the footprint histogram of the interpolated
    map. ``method``: ``"sample"`` bins ``n`` samples of the lobe mixture
    (:meth:`~microfacet.glints.Microsurface.sample_slopes`, exact for any lobe width);
    ``"quadrature"`` integrates :meth:`~microfacet.glints.Microsurface.slope_pdf` over
    each bin by the midpoint rule with ``sub^2`` points (only where the lobes are wider
    than ``bin width / sub``). ``rough``: the reference map carries the microsurface's
    ``sigma_eps`` roughness (default; the paper's ground truth) or is perfectly specular.
    Bins span the 0.1-99.9 % slope quantiles of the samples plus 10 % (so that the
    bins stay wider than the histogram's noise allows and the tails are counted outside).

    Returns a dict: ``tv`` (total-variation distance ``1/2 sum |p_ref - p_ndf|`` over the
    bins plus the mass outside them), ``mass_in`` (P-NDF mass inside the bins),
    ``ref_in`` (reference mass inside), ``peak_rel`` (relative error of the largest bin).

    Parameters
    ----------
    ms : Microsurface
        The lobe mixture (its ``slopes`` are the reference's map).
    center, cov : array_like
        The footprint.
    bins : int
        Bins per axis.
    n : int
        Samples of the reference (and of the mixture, ``"sample"``).
    sub : int
        Midpoint-rule points per bin and axis (``"quadrature"``).
    seed : int
        Random seed.
    method : str
        ``"sample"`` or ``"quadrature"``.
    rough : bool
        Add ``ms.sigma_eps`` slope noise to the reference.
    **kwargs
        Passed to :meth:`~microfacet.glints.Microsurface.slope_pdf` (``"quadrature"``).

    Returns
    -------
    dict
        ``tv``, ``mass_in``, ``ref_in``, ``peak_rel``.

    Examples
    --------
    >>> import microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((8, 8, 2)))
    >>> r = compare_histogram(ms, [0.5, 0.5], np.eye(2) * 1e-2, bins=8, n=20000)
    >>> sorted(r), 0 <= r["tv"] <= 1
    (['mass_in', 'peak_rel', 'ref_in', 'tv'], True)
    """
    s = footprint_slopes(ms.slopes, center, cov, n, seed, ms.sigma_eps if rough else 0.0)
    lo, hi = np.percentile(s, 0.1, axis=0), np.percentile(s, 99.9, axis=0)
    pad = 0.1 * (hi - lo) + 4 * ms.sigma_eps
    ex = np.linspace(lo[0] - pad[0], hi[0] + pad[0], bins + 1)
    ey = np.linspace(lo[1] - pad[1], hi[1] + pad[1], bins + 1)
    ref = slope_histogram(s, ex, ey)
    if method == "sample":
        mix = _bin_masses_sampled(ms, ex, ey, center, cov, n, seed)
    elif method == "quadrature":
        mix = _bin_masses(ms, ex, ey, center, cov, sub, **kwargs)
    else:
        raise ValueError(f"method must be 'sample' or 'quadrature', got {method!r}")
    out_ref, out_mix = 1.0 - ref.sum(), 1.0 - mix.sum()
    tv = 0.5 * (np.abs(ref - mix).sum() + abs(out_ref - out_mix))
    k = np.unravel_index(np.argmax(ref), ref.shape)
    return {"tv": float(tv), "mass_in": float(mix.sum()), "ref_in": float(ref.sum()),
            "peak_rel": float(abs(mix[k] - ref[k]) / ref[k])}
