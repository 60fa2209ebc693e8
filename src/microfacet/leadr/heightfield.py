"""Gaussian random height fields with a prescribed slope covariance (for tests and
experiments; thesis Sec. 3.3 validation uses Beckmann microgeometries).

A periodic field is synthesised by FFT from a Gaussian power spectrum. Its slopes
(central differences in uv-square units, :func:`microfacet.leadr.height_to_slopes`
with ``border="wrap"``) have, in expectation over the random phases and amplitudes,
exactly the prescribed covariance ``[[alpha_x^2/2, rho alpha_x alpha_y/2], [., alpha_y^2/2]]``:
the spectrum's shape is adjusted by fixed-point iteration against the *discrete*
derivative operator. The mean slope is a plane ``x~n u + y~n (1 - v)`` added on top; a
plane is not periodic, so bake such a field with ``border="clamp"`` (its outer texels
then carry half the plane's slope).
"""
from __future__ import annotations

import numpy as np

__all__ = ["gaussian_heightfield", "slope_spectrum"]


def _operators(shape):
    """Discrete central-difference slope operators in Fourier space, per frequency."""
    h, w = shape
    kx = np.fft.fftfreq(w)[None, :]
    ky = np.fft.fftfreq(h)[:, None]
    # x~ = W (xi(i+1) - xi(i-1)) / 2 -> i W sin(2 pi kx); y~ = H (xi(j-1) - xi(j+1)) / 2 -> -i H sin(2 pi ky)
    dx = 1j * w * np.sin(2 * np.pi * kx) * np.ones((h, 1))
    dy = -1j * h * np.sin(2 * np.pi * ky) * np.ones((1, w))
    return kx * np.ones((h, 1)), ky * np.ones((1, w)), dx, dy


def slope_spectrum(shape, alpha_x, alpha_y, rho=0.0, correlation: float = 8.0, iterations: int = 50):
    """Height power spectrum ``S (H, W)`` (per FFT coefficient, variance of ``xi_hat / sqrt(HW)``)
    whose central-difference slopes have covariance exactly ``alpha^2 / 2`` (Beckmann),
    and the per-frequency slope contributions ``(dx, dy)`` (used to compute estimator
    variances). ``correlation`` is the correlation length in texels.

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)`` of the height field in texels.
    alpha_x, alpha_y : float
        Beckmann roughness of the slopes along x and y (slope variances ``alpha^2 / 2``).
    rho : float, optional
        Correlation coefficient of the x and y slopes, in (-1, 1) (default 0).
    correlation : float, optional
        Correlation length of the heights in texels (default 8).
    iterations : int, optional
        Most fixed-point iterations fitting the spectrum's shape to the slope covariance
        (default 50; it stops earlier at 1e-14).

    Returns
    -------
    S : numpy.ndarray, shape (H, W)
        Height power per FFT coefficient (``S[0, 0] = 0``: zero mean height).
    dx, dy : numpy.ndarray, shape (H, W)
        Complex per-frequency factors of the central-difference slope operators along x
        and y.

    Examples
    --------
    >>> S, dx, dy = slope_spectrum((16, 16), 0.3, 0.3)
    >>> S.shape, float(S[0, 0])          # no energy in the mean height
    ((16, 16), 0.0)
    """
    h, w = shape
    target = 0.5 * np.array([[alpha_x**2, rho * alpha_x * alpha_y], [rho * alpha_x * alpha_y, alpha_y**2]])
    kx, ky, dx, dy = _operators(shape)
    fx, fy = kx * w, -ky * h                                  # cycles per unit uv (y to the top)
    T = target / np.trace(target)
    K = T.copy()                                              # frequency covariance shape, trace 1
    for _ in range(iterations):
        Ki = np.linalg.inv(K)
        q = Ki[0, 0] * fx * fx + 2 * Ki[0, 1] * fx * fy + Ki[1, 1] * fy * fy
        S = np.exp(-0.25 * q * (2 * np.pi * correlation / max(h, w)) ** 2)
        S[0, 0] = 0.0
        cxy = np.sum(S * (dx * np.conj(dy)).real)
        M = np.array([[np.sum(S * np.abs(dx) ** 2), cxy], [cxy, np.sum(S * np.abs(dy) ** 2)]])
        S = S * (np.trace(target) / np.trace(M))
        err = M / np.trace(M) - T
        if np.max(np.abs(err)) <= 1e-14:
            break
        # slope covariance ~ proportional to K (continuous limit): fixed-point on the shape
        K = K - err
    return S, dx, dy


def gaussian_heightfield(shape, alpha_x: float, alpha_y: float | None = None, rho: float = 0.0,
                         mean_slope=(0.0, 0.0), correlation: float = 8.0, seed=None) -> np.ndarray:
    """A Gaussian random height field ``(H, W)`` whose central-difference slopes are
    Beckmann(``alpha_x, alpha_y, rho``) distributed around ``mean_slope`` (module docstring).

    ``correlation`` (texels) sets the spectrum's width: larger is smoother but gives
    fewer independent slope samples (more statistical error in the map's moments).

    Parameters
    ----------
    shape : (int, int)
        ``(H, W)`` texels.
    alpha_x, alpha_y : float
        Beckmann roughness of the slopes along x and y (``alpha_y`` defaults to ``alpha_x``).
    rho : float
        Correlation of the slopes, in ``(-1, 1)``.
    mean_slope : (float, float)
        Mean slope ``(x~n, y~n)``: a linear ramp added to the field.
    correlation : float
        Correlation length in texels.
    seed : int or numpy.random.Generator, optional
        Random seed.

    Returns
    -------
    ndarray, (H, W) float64
        Heights whose central-difference slopes (:func:`microfacet.leadr.height_to_slopes`) have
        the requested statistics, up to the sampling error of a finite map.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.leadr import height_to_slopes
    >>> h = gaussian_heightfield((64, 64), 0.3, seed=0)
    >>> s = height_to_slopes(h)
    >>> h.shape, round(float(np.sqrt(2 * s[..., 0].var())), 2)    # alpha_x of the slopes
    ((64, 64), 0.33)
    """
    alpha_y = alpha_x if alpha_y is None else alpha_y
    h, w = int(shape[0]), int(shape[1])
    S, _, _ = slope_spectrum((h, w), alpha_x, alpha_y, rho, correlation)
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((h, w))                       # real white noise: Hermitian spectrum
    xi = np.fft.ifft2(np.fft.fft2(white) * np.sqrt(S)).real * np.sqrt(h * w)
    u = (np.arange(w) + 0.5) / w
    v = (np.arange(h) + 0.5) / h
    return xi + mean_slope[0] * u[None, :] + mean_slope[1] * (1.0 - v)[:, None]
