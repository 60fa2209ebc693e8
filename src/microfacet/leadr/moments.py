"""Linear representation of Beckmann slope distributions (LEAN/LEADR, thesis Sec. 3.3-3.4).

A Beckmann slope PDF is fully described by its five linear slope moments
``E = (E1, E2, E3, E4, E5) = (E[x~], E[y~], E[x~^2], E[y~^2], E[x~ y~])`` (Eq. 3.5-3.9),
stored in the last axis of an ``(..., 5)`` array. Because the moments are expectations,
they average linearly (MIP maps, Eq. 3.10-3.14), add under convolution of independent
lobes (Listing 5.1) and transform exactly under linear maps of the slopes (height
scaling and the uv Jacobian, Sec. 3.4). Beckmann convention: the slope standard
deviation per axis is ``alpha / sqrt(2)``, so ``E3 = alpha_x^2 / 2 + x~n^2``.

Examples
--------
>>> MIN_ALPHA, MAX_RHO
(0.001, 0.99)
"""
from __future__ import annotations

import numpy as np

from ..distributions import Beckmann

__all__ = ["to_moments", "from_moments", "convolve", "scale_height", "transform",
           "covariance", "clean_moments", "clean_to_moments", "MIN_ALPHA", "MAX_RHO"]

#: Smallest roughness :func:`from_moments` returns (a texel of a single normal has
#: zero variance; Listing 3.5 clamps to 1e-5, we keep 1e-3 so that lobes stay samplable).
MIN_ALPHA = 1e-3
#: Largest ``|rho|`` :func:`from_moments` returns (Listing 3.5).
MAX_RHO = 0.99


def _moments(E) -> np.ndarray:
    E = np.asarray(E, dtype=np.float64)
    if E.shape[-1:] != (5,):
        raise ValueError(f"moments must have a last axis of size 5 (E1..E5), got shape {E.shape}")
    return E


def to_moments(alpha_x, alpha_y, rho=0.0, mean_slope=(0.0, 0.0)) -> np.ndarray:
    """Moments ``(..., 5)`` of Beckmann surfaces (Eq. 3.5-3.9, Listing 3.5 ``params_to_lrep``).

    ``E1 = x~n``, ``E2 = y~n``, ``E3 = alpha_x^2/2 + x~n^2``, ``E4 = alpha_y^2/2 + y~n^2``,
    ``E5 = rho alpha_x alpha_y / 2 + x~n y~n``. Parameters broadcast; ``mean_slope`` has
    a last axis of size 2. ``alpha = 0`` (a single facet) is allowed here.

    Parameters
    ----------
    alpha_x, alpha_y : float or ndarray
        Beckmann roughness along x and y (``alpha = 0``: a single facet).
    rho : float or ndarray
        Slope correlation.
    mean_slope : (float, float) or ndarray (..., 2)
        Mean slope ``(x~n, y~n)``.

    Returns
    -------
    ndarray, (..., 5)
        The moments ``E1..E5`` (the parameters broadcast).

    References
    ----------
    Dupuy 2015, thesis, Eq. 3.5-3.9, Listing 3.5.

    Examples
    --------
    >>> to_moments(0.2, 0.4, rho=0.5, mean_slope=(0.1, 0.0)).round(4)   # E1, E2, E3, E4, E5
    array([0.1 , 0.  , 0.03, 0.08, 0.02])
    """
    ax, ay, rho = (np.asarray(v, dtype=np.float64) for v in (alpha_x, alpha_y, rho))
    ms = np.asarray(mean_slope, dtype=np.float64)
    if ms.shape[-1:] != (2,):
        raise ValueError(f"mean_slope must have a last axis of size 2, got shape {ms.shape}")
    if np.any(ax < 0) or np.any(ay < 0) or not np.all(np.isfinite(ax) & np.isfinite(ay)):
        raise ValueError("alpha_x and alpha_y must be finite and >= 0")
    if np.any(np.abs(rho) > 1) or not np.all(np.isfinite(rho)):
        raise ValueError(f"rho must lie in [-1, 1], got {rho!r}")
    xn, yn = ms[..., 0], ms[..., 1]
    parts = np.broadcast_arrays(xn, yn, 0.5 * ax * ax + xn * xn, 0.5 * ay * ay + yn * yn,
                                0.5 * rho * ax * ay + xn * yn)
    return np.stack(parts, axis=-1)


def covariance(E) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Central second moments ``(Var[x~], Var[y~], Cov[x~, y~])`` of moments ``E``.

    Parameters
    ----------
    E : array-like, shape (..., 5)
        Moments ``E1..E5``.

    Returns
    -------
    var_x, var_y, cov_xy : numpy.ndarray, shape (...)
        The slopes' variances and covariance.

    Examples
    --------
    >>> [round(float(v), 6) for v in covariance(to_moments(0.2, 0.4, rho=0.5))]   # alpha^2 / 2 ...
    [0.02, 0.08, 0.02]
    """
    E = _moments(E)
    e1, e2 = E[..., 0], E[..., 1]
    return E[..., 2] - e1 * e1, E[..., 3] - e2 * e2, E[..., 4] - e1 * e2


def from_moments(E, min_alpha: float = MIN_ALPHA, max_rho: float = MAX_RHO) -> Beckmann:
    """Beckmann surface(s) of moments ``E (..., 5)`` (Listing 3.5 ``lrep_to_params``).

    ``alpha_x^2 = 2 (E3 - E1^2)``, ``alpha_y^2 = 2 (E4 - E2^2)``,
    ``rho = 2 (E5 - E1 E2) / (alpha_x alpha_y)``, mean slope ``(E1, E2)``. Degenerate
    texels are clamped as in Listing 3.5: variances below ``min_alpha^2 / 2`` (a single
    facet, or negative by rounding) are raised to it, and ``|rho| <= max_rho``.
    Non-finite moments raise ``ValueError``.

    Parameters
    ----------
    E : ndarray, (..., 5)
        Moments ``E1..E5``.
    min_alpha : float
        Smallest roughness returned (degenerate texels are raised to it).
    max_rho : float
        Largest ``|rho|`` returned.

    Returns
    -------
    Beckmann
        The surface(s), their parameters of shape ``E.shape[:-1]``.

    Raises
    ------
    ValueError
        Non-finite moments, or a last axis other than 5.

    References
    ----------
    Dupuy 2015, thesis, Listing 3.5.

    Examples
    --------
    >>> d = from_moments(to_moments(0.2, 0.4, rho=0.5))
    >>> round(float(d.alpha_x), 6), round(float(d.alpha_y), 6), round(float(d.rho), 6)
    (0.2, 0.4, 0.5)
    """
    E = _moments(E)
    if not np.all(np.isfinite(E)):
        raise ValueError("moments must be finite")
    if not (min_alpha > 0 and 0 <= max_rho < 1):
        raise ValueError(f"need min_alpha > 0 and 0 <= max_rho < 1, got {min_alpha}, {max_rho}")
    vx, vy, cxy = covariance(E)
    floor = 0.5 * min_alpha * min_alpha
    ax, ay = np.sqrt(2.0 * np.maximum(vx, floor)), np.sqrt(2.0 * np.maximum(vy, floor))
    rho = np.clip(2.0 * cxy / (ax * ay), -max_rho, max_rho)
    return Beckmann(alpha_x=ax, alpha_y=ay, rho=rho, mean_slope=E[..., :2])


def convolve(Ea, Eb) -> np.ndarray:
    """Moments of the sum of two independent slopes (convolution of their PDFs), Listing 5.1.

    ``E1 = Ea1 + Eb1``, ``E3 = Ea3 + Eb3 + 2 Ea1 Eb1``,
    ``E5 = Ea5 + Eb5 + Ea1 Eb2 + Ea2 Eb1``: means and covariances add.

    Parameters
    ----------
    Ea, Eb : array-like, shape (..., 5)
        Moments of the two slope distributions (broadcast).

    Returns
    -------
    numpy.ndarray, shape (..., 5)
        Moments of their sum.

    References
    ----------
    Dupuy 2015, thesis, Listing 5.1.

    Examples
    --------
    >>> E = convolve(to_moments(0.3, 0.3), to_moments(0.4, 0.4))
    >>> round(float(from_moments(E).alpha_x), 6)          # variances add: sqrt(0.3^2 + 0.4^2)
    0.5
    """
    Ea, Eb = np.broadcast_arrays(_moments(Ea), _moments(Eb))
    a1, a2, b1, b2 = Ea[..., 0], Ea[..., 1], Eb[..., 0], Eb[..., 1]
    cross = np.stack([np.zeros_like(a1), np.zeros_like(a1), 2 * a1 * b1, 2 * a2 * b2,
                      a1 * b2 + a2 * b1], axis=-1)
    return Ea + Eb + cross


def scale_height(E, beta) -> np.ndarray:
    """Moments of the surface whose heights are scaled by ``beta`` (Sec. 3.4): ``E1, E2``
    scale by ``beta`` and ``E3, E4, E5`` by ``beta^2``.

    Parameters
    ----------
    E : array-like, shape (..., 5)
        Moments ``E1..E5``.
    beta : float or array-like, shape (...)
        Height scale factor (broadcast against ``E[..., 0]``).

    Returns
    -------
    numpy.ndarray, shape (..., 5)
        The scaled moments.

    References
    ----------
    Dupuy 2015, thesis, Sec. 3.4.

    Examples
    --------
    >>> round(float(from_moments(scale_height(to_moments(0.2, 0.2), 2.0)).alpha_x), 6)   # slopes x 2
    0.4
    """
    E = _moments(E)
    beta = np.asarray(beta, dtype=np.float64)[..., None]
    return E * np.concatenate(np.broadcast_arrays(beta, beta, beta**2, beta**2, beta**2), axis=-1)


def transform(E, jacobian) -> np.ndarray:
    """Moments of world-space slopes from moments ``E'`` of uv slopes (Sec. 3.4, stretching
    and shearing).

    ``jacobian`` is ``(..., 2, 2)`` = ``[[du/dx, dv/dx], [du/dy, dv/dy]]`` (the uv
    parameterization's derivatives, locally constant), so that world slopes are
    ``(d xi/dx, d xi/dy) = J (d xi/du, d xi/dv)``; ``E1 = du/dx E1' + dv/dx E2'``,
    ``E3 = (du/dx)^2 E3' + (dv/dx)^2 E4' + 2 du/dx dv/dx E5'``,
    ``E5 = du/dx du/dy E3' + dv/dx dv/dy E4' + (du/dx dv/dy + dv/dx du/dy) E5'``.

    Parameters
    ----------
    E : array-like, shape (..., 5)
        Moments ``E'`` of uv slopes.
    jacobian : array-like, shape (..., 2, 2)
        ``[[du/dx, dv/dx], [du/dy, dv/dy]]``.

    Returns
    -------
    numpy.ndarray, shape (..., 5)
        Moments of world-space slopes.

    References
    ----------
    Dupuy 2015, thesis, Sec. 3.4.

    Examples
    --------
    >>> import numpy as np
    >>> E = transform(to_moments(0.2, 0.2), np.diag([2.0, 1.0]))     # uv stretched along x
    >>> d = from_moments(E)
    >>> round(float(d.alpha_x), 6), round(float(d.alpha_y), 6)
    (0.4, 0.2)
    """
    E = _moments(E)
    J = np.asarray(jacobian, dtype=np.float64)
    if J.shape[-2:] != (2, 2):
        raise ValueError(f"jacobian must be (..., 2, 2), got shape {J.shape}")
    ux, vx, uy, vy = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    e1, e2, e3, e4, e5 = (E[..., i] for i in range(5))
    out = [ux * e1 + vx * e2, uy * e1 + vy * e2,
           ux * ux * e3 + vx * vx * e4 + 2 * ux * vx * e5,
           uy * uy * e3 + vy * vy * e4 + 2 * uy * vy * e5,
           ux * uy * e3 + vx * vy * e4 + (ux * vy + vx * uy) * e5]
    return np.stack(np.broadcast_arrays(*out), axis=-1)


def clean_moments(E, mode: str = "lean") -> np.ndarray:
    """CLEAN map texels ``(..., 3)`` = ``(E1, E2, E3 + E4)`` from LEAN moments (Baker 2011,
    thesis Eq. 3.18), or with ``mode="max"`` a third component that yields the isotropic
    roughness ``max(alpha1, alpha2)`` of the LEAN ellipse (the thesis's anti-aliasing
    conjecture): ``E1^2 + E2^2 + max(alpha1, alpha2)^2``.

    Unlike the five LEAN moments, ``mode="max"`` texels are not linear in the slopes:
    filter the ``"lean"`` form and convert after filtering.

    Parameters
    ----------
    E : array-like, shape (..., 5)
        LEAN moments ``E1..E5``.
    mode : {"lean", "max"}, optional
        Third component: ``E3 + E4`` (default) or the ``max(alpha1, alpha2)`` form.

    Returns
    -------
    numpy.ndarray, shape (..., 3)
        The CLEAN texels.

    References
    ----------
    Baker 2011; Dupuy 2015, thesis, Eq. 3.18.

    Examples
    --------
    >>> clean_moments(to_moments(0.2, 0.4)).round(4)        # E1, E2, E3 + E4
    array([0. , 0. , 0.1])
    """
    E = _moments(E)
    e1, e2 = E[..., 0], E[..., 1]
    if mode == "lean":
        third = E[..., 2] + E[..., 3]
    elif mode == "max":
        vx, vy, cxy = covariance(E)
        lam1 = 0.5 * (vx + vy) + np.sqrt(0.25 * (vx - vy) ** 2 + cxy * cxy)   # = alpha1^2 / 2
        third = e1 * e1 + e2 * e2 + 2.0 * lam1
    else:
        raise ValueError(f"mode must be 'lean' or 'max', got {mode!r}")
    return np.stack([e1, e2, third], axis=-1)


def clean_to_moments(C) -> np.ndarray:
    """Isotropic LEAN moments ``(..., 5)`` of CLEAN texels ``(E1, E2, E3 + E4)``:
    ``alpha^2 = third - E1^2 - E2^2`` (Eq. 3.18), ``rho = 0``.

    Parameters
    ----------
    C : array-like, shape (..., 3)
        CLEAN texels ``(E1, E2, E3 + E4)``.

    Returns
    -------
    numpy.ndarray, shape (..., 5)
        Isotropic LEAN moments.

    References
    ----------
    Baker 2011; Dupuy 2015, thesis, Eq. 3.18.

    Examples
    --------
    >>> clean_to_moments(clean_moments(to_moments(0.2, 0.4))).round(4)     # isotropic: (E3 + E4) / 2 each
    array([0.  , 0.  , 0.05, 0.05, 0.  ])
    """
    C = np.asarray(C, dtype=np.float64)
    if C.shape[-1:] != (3,):
        raise ValueError(f"CLEAN texels must have a last axis of size 3, got shape {C.shape}")
    e1, e2 = C[..., 0], C[..., 1]
    half_a2 = 0.5 * np.maximum(C[..., 2] - e1 * e1 - e2 * e2, 0.0)   # alpha^2 / 2 per axis
    return np.stack([e1, e2, half_a2 + e1 * e1, half_a2 + e2 * e2, e1 * e2], axis=-1)
