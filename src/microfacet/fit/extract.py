"""Extraction of the microfacet terms of a BRDF from its values (thesis Ch. 4.2).

The slope distribution comes from backscattering (``i = o = h``, Eq. 4.1-4.3): with the
Smith GAF it is the Perron eigenvector of the discretized Fredholm equation (Eq. 4.5-4.9,
isotropic form Eq. 4.12-4.15), found by power iterations (Algorithms 1 and 3); with the
V-groove and normal-map GAFs it is explicit (Eq. 4.16-4.18).

Two Smith backscattering models are inverted (``BACKSCATTER_GAFS``):

- ``"masking"``: the thesis's Eq. 4.3, ``G(o, o) = G1(o) = cos theta_o / A(o)``, so
  ``F0 D(o) = 4 f(o, o) cos theta_o A(o)`` (the forward model of ``shadowing=False``);
- ``"height_correlated"``: the library's ``G2(o, o) = 1 / (1 + 2 Lambda(o))``
  (Eq. 2.13 at ``i = o``) with ``1 + Lambda = A / cos``, so
  ``F0 D(o) = 4 f(o, o) cos theta_o (2 A(o) - cos theta_o A(z))``, written with
  ``A(z) = int cos D dw = 1`` to stay linear and homogeneous in ``D``: the operator is
  twice the masking kernel minus a rank-one term, iterated as the same fixed point. The Fresnel term is the
average ratio of the BRDF to the fitted ideal-mirror BRDF at each ``theta_d`` (Eq. 4.11,
Algorithm 2).

The NDF is recovered at the nodes of :func:`theta_grid` (and azimuths ``2 pi k / m``).
The grazing node ``theta = pi/2``, where backscattering is not measurable (an input may
return garbage there), takes the value of its neighbour (constant extrapolation, which
keeps the eigenproblem linear and nonnegative).

Examples
--------
>>> BACKSCATTER_GAFS, MEASURED_MAX, TV_MAX
(('masking', 'height_correlated'), 1000000.0, 2.0)
"""
from __future__ import annotations

import os
import threading
import warnings
from typing import NamedTuple

import numpy as np

from .._colour import LUMINANCE
from ..distributions.tabulated import HALF_PI, azimuthal_cosine_spectrum, circular_projection, hat_weights
from ..errors import MicrofacetError
from ..geometry import hd_to_io
from ..metrics import measured_mask

__all__ = ["BACKSCATTER_GAFS", "backscattering", "luminance", "smith_kernel_isotropic",
           "smith_kernel_anisotropic", "AzimuthalKernel", "power_iteration", "rule_area_at_normal", "ndf_closed_form",
           "fresnel_samples", "solve_fresnel", "FresnelSolution", "smooth_table_qp", "table_variation", "TV_MAX", "box_qp", "chi2_residual", "albedo_rows", "extract_fresnel",
           "screen_measured", "MEASURED_MAX"]

#: Smith backscattering models ``G(o, o)``: Eq. 4.3 (``G1``) or height-correlated ``G2``
BACKSCATTER_GAFS = ("masking", "height_correlated")


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance of RGB values ``(..., 3)``.

    Parameters
    ----------
    rgb : array-like, shape (..., 3)
        Linear RGB values.

    Returns
    -------
    numpy.ndarray, shape (...)
        Their luminance (float64).

    Examples
    --------
    >>> import numpy as np
    >>> luminance(np.array([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])).round(4)
    array([1.    , 0.2126])
    """
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def _clean(values) -> np.ndarray:
    """Nonfinite or negative BRDF values (garbage at grazing angles) become 0."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(np.isfinite(v) & (v > 0), v, 0.0)


def _directions(theta, phi) -> np.ndarray:
    s = np.sin(theta)
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), np.cos(theta)), axis=-1)


def backscattering(brdf, theta, phi=0.0) -> np.ndarray:
    """Luminance of ``f_r(o, o)`` at ``o = (theta, phi)``, garbage set to 0 (Eq. 4.1).

    Parameters
    ----------
    brdf : BRDF
        The BRDF (``eval(wi, wo)`` RGB).
    theta : array-like
        Polar angles of ``o`` in radians.
    phi : float or array-like, optional
        Azimuths of ``o`` in radians (default 0), broadcast against ``theta``.

    Returns
    -------
    numpy.ndarray
        Luminance of ``f_r(o, o)`` in 1/sr, of the broadcast shape (nonfinite or negative
        values set to 0).

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.1.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> backscattering(brdf, np.radians([0.0, 30.0, 60.0])).round(4)    # f_r(o, o), luminance
    array([0.0354, 0.0037, 0.0017])
    """
    o = _directions(theta, phi)
    return _clean(luminance(_clean(brdf.eval(o, o))))


#: Largest plausible value of a measured BRDF (sr^-1): a MERL sample of a mirror-like metal
#: reaches a few 1e3 (chrome 3.9e3); above this a value is an overflow or a corrupt sample.
MEASURED_MAX = 1e6
#: Share of the measured samples above :data:`MEASURED_MAX` that :func:`screen_measured`
#: ignores (as unmeasured) rather than refuses.
IGNORED_SHARE = 1e-3


def screen_measured(brdf):
    """``brdf``, or for a MERL BRDF (:class:`~microfacet.measured.MERLBRDF`) with samples
    above :data:`MEASURED_MAX` (finite but huge: 1e300, 1.75e308, which overflow the fit's
    products into NaN), a copy in which they are unmeasured (interpolated from their
    measured neighbours, as the MERL reader treats missing samples) when they are few (at
    most :data:`IGNORED_SHARE` of the measured samples; a ``RuntimeWarning`` names the file
    and their count), or a :class:`~microfacet.errors.MicrofacetError` naming the file and
    the count when they are more. Costs one pass over the table (~5 ms) when all is well.
    Example: ``fit(screen_measured(load(path)))`` (:func:`microfacet.fit.fit` calls it).

    Parameters
    ----------
    brdf : BRDF
        Any BRDF; only a :class:`~microfacet.measured.MERLBRDF` is screened.

    Returns
    -------
    BRDF
        ``brdf`` itself, or a screened copy.

    Examples
    --------
    >>> import microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> screen_measured(brdf) is brdf                 # not a MERL table: returned as it is
    True
    """
    from ..measured import MERLBRDF
    if not isinstance(brdf, MERLBRDF):
        return brdf
    values, valid = brdf.values, brdf.valid
    top = float(np.max(values))
    if not top > MEASURED_MAX:
        return brdf
    bad = valid & np.any(values > MEASURED_MAX, axis=-1)
    n_bad, n_valid = int(np.count_nonzero(bad)), int(np.count_nonzero(valid))
    if n_bad == 0:
        return brdf
    name = os.fspath(brdf.path)
    if n_bad > IGNORED_SHARE * n_valid:
        raise MicrofacetError(f"{name}: {n_bad} of {n_valid} measured samples exceed {MEASURED_MAX:g} sr^-1 "
                              f"(largest {top:.3g}): not a physical BRDF (overflow or a corrupt file)")
    warnings.warn(f"{name}: {n_bad} sample(s) above {MEASURED_MAX:g} sr^-1 (largest {top:.3g}) ignored "
                  "as unmeasured", RuntimeWarning, stacklevel=3)
    return MERLBRDF(values, valid & ~bad, brdf.path)


# ------------------------------------------------------------------ Smith kernel
def azimuthal_cosine_integral(theta_o, theta_h) -> np.ndarray:
    """``E(theta_o, theta_h) = int_0^2pi <o, h>+ dphi_h`` in closed form (inner integral of
    the kernel K', Eq. 4.14): ``2 pi p`` if ``q <= p``, else
    ``2 p arccos(-p/q) + 2 sqrt(q^2 - p^2)``, with ``p = cos cos``, ``q = sin sin``."""
    p = np.cos(theta_o) * np.cos(theta_h)
    q = np.sin(theta_o) * np.sin(theta_h)
    with np.errstate(divide="ignore", invalid="ignore"):
        partial = 2.0 * p * np.arccos(np.clip(-p / q, -1.0, 1.0)) + 2.0 * np.sqrt(np.maximum(q * q - p * p, 0.0))
    return np.where(q <= p, 2.0 * np.pi * p, partial)


_KEPT_LOCK = threading.Lock()


def _kept(store: dict, key, make, size: int = 16):
    """``store[key]``, made by ``make()`` (never None) when missing; the oldest entry is
    dropped beyond ``size`` (what a fit computes again and again with the same inputs).
    Safe for stores shared by threads."""
    value = store.get(key)
    if value is None:
        value = make()
        with _KEPT_LOCK:
            while len(store) >= size:
                del store[next(iter(store))]
            store[key] = value
    return value


def _distribution_key(distribution) -> tuple:
    """A distribution's family and parameters (``alpha_x, alpha_y, rho, mean_slope``): the key
    of what is kept per lobe (:func:`_kept`)."""
    return (type(distribution),) + tuple(np.asarray(getattr(distribution, a), dtype=np.float64).tobytes()
                                         for a in ("alpha_x", "alpha_y", "rho", "mean_slope"))


def _read_only(*arrays) -> tuple:
    """``arrays``, made read-only (they are kept and shared)."""
    for array in arrays:
        array.flags.writeable = False
    return arrays


#: The last :func:`projected_area_matrix_isotropic` results (key: nodes, views, order).
_PROJECTED_AREA: dict = {}


def projected_area_matrix_isotropic(theta: np.ndarray, theta_o: np.ndarray, order: int = 8) -> np.ndarray:
    """``M[i, j]`` with ``A(o_i) = int <o_i,h>+ D(h) dw_h = sum_j M[i, j] D_j`` for ``D``
    linear in ``theta`` between the nodes ``theta`` (product integration: Gauss-Legendre of
    ``order`` points per interval of ``hat_j(theta) E(theta_o, theta) sin theta``). It
    depends on the nodes alone, not on the table: the last few are kept (read-only; a fit
    with a base solves ~17 kernels on one grid)."""
    theta, theta_o = np.asarray(theta, dtype=np.float64), np.asarray(theta_o, dtype=np.float64)
    return _kept(_PROJECTED_AREA, (theta.tobytes(), theta_o.tobytes(), int(order)),
                 lambda: _read_only(_projected_area_matrix(theta, theta_o, order))[0], size=4)


def _projected_area_matrix(theta: np.ndarray, theta_o: np.ndarray, order: int) -> np.ndarray:
    """:func:`projected_area_matrix_isotropic`, computed."""
    t, w = np.polynomial.legendre.leggauss(order)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    a, b = theta[:-1], theta[1:]
    th = a[:, None] + (b - a)[:, None] * t                            # (n-1, order)
    wq = (b - a)[:, None] * w * np.sin(th)
    e = azimuthal_cosine_integral(theta_o[:, None, None], th[None])   # (no, n-1, order)
    m = np.zeros((len(theta_o), len(theta)))
    m[:, :-1] += np.einsum("ijq,jq->ij", e, wq * (1.0 - t))
    m[:, 1:] += np.einsum("ijq,jq->ij", e, wq * t)
    return m


def smith_kernel_isotropic(f_back: np.ndarray, theta: np.ndarray, model: str = "masking"):
    """Kernel of Eq. 4.15 for the unknowns ``D(theta_0..theta_{n-2})`` (the grazing node
    folded onto its neighbour), written for ``D = P / cos^4`` (a similarity transform of
    the ``P`` form, same eigenvector): ``K' = 4 f_r(o, o) cos theta_o M`` with
    ``A(o) = M D``, so that ``F0 D = K' D`` (Eq. 4.4-4.6, ``model="masking"``).

    Returns ``(K', None)`` for ``"masking"`` and, for ``"height_correlated"``,
    ``(2 K', (u, v))`` with the rank-one term ``u = 4 f cos^2 theta_o``, ``v = M[z]``
    (the row of ``A`` at the normal): ``F0 D = 2 K' D - u (v . D)`` (module docstring).

    Parameters
    ----------
    f_back : numpy.ndarray, shape (n - 1,)
        Backscattering luminance at ``theta[:-1]``.
    theta : numpy.ndarray, shape (n,)
        Polar nodes in radians, 0 to ``pi / 2``.
    model : {"masking", "height_correlated"}, optional
        Smith masking form (default ``"masking"``).

    Returns
    -------
    K : numpy.ndarray, shape (n - 1, n - 1)
        The kernel ``K'`` (``2 K'`` for ``"height_correlated"``).
    rank_one : (numpy.ndarray, numpy.ndarray) or None
        ``(u, v)`` of the rank-one term for ``"height_correlated"``, else ``None``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.4-4.6, 4.12-4.15; Dupuy et al. 2015.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.distributions.tabulated import theta_grid
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> theta = theta_grid(16)
    >>> f_back = backscattering(brdf, theta[:-1])         # the grazing node is not measured
    >>> k, rank_one = smith_kernel_isotropic(f_back, theta, "height_correlated")
    >>> k.shape, [a.shape for a in rank_one]
    ((15, 15), [(15,), (15,)])
    """
    _check_model(model)
    m = projected_area_matrix_isotropic(theta, theta[:-1]).copy()
    m[:, -2] += m[:, -1]
    m = m[:, :-1]
    scale = 4.0 * f_back * np.cos(theta[:-1])
    k = scale[:, None] * m
    if model == "masking":
        return k, None
    return 2.0 * k, (scale * np.cos(theta[:-1]), m[0].copy())      # theta_0 = 0: the normal


def _check_model(model: str) -> None:
    if model not in BACKSCATTER_GAFS:
        raise ValueError(f"backscatter_gaf must be one of {BACKSCATTER_GAFS}, got {model!r}")


class AzimuthalKernel:
    """The anisotropic kernel of Eq. 4.8 as an operator, ``K p = s * (A p)`` with the node
    rule ``(A p)[i, a] = sum_j w_j sum_b <o_ia, h_jb>+ p[j, b]`` over ``theta`` x uniform
    ``phi``: block-circulant in azimuth, applied by the DFT
    (:func:`~microfacet.distributions.tabulated.circular_projection`) in ``O(n^2 m log m)``
    per product instead of ``O(n^2 m^2)`` for the dense ``(n m)^2`` matrix, and exact to
    rounding. ``p`` is over the rows ``i < n - 1`` (row-major, ``(n - 1) m``); the grazing
    row of ``h`` takes the values of its neighbour (folded). ``k @ p`` and ``k.dense()``
    (the explicit matrix, for tests) are provided.

    Parameters
    ----------
    theta : array-like, shape (n,)
        Polar nodes in radians, increasing from 0 to ``pi / 2``.
    m : int
        Number of uniform azimuth nodes ``2 pi k / m``.
    scale : array-like, shape ((n - 1) m,)
        The row scale ``s`` (row-major over ``(theta_i, phi_j)``, ``i < n - 1``).

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.8.

    Examples
    --------
    >>> import numpy as np
    >>> from microfacet.distributions.tabulated import theta_grid
    >>> k = AzimuthalKernel(theta_grid(6), 4, np.ones(5 * 4))
    >>> p = np.random.default_rng(0).random(5 * 4)
    >>> bool(np.allclose(k @ p, k.dense() @ p))       # the DFT product equals the dense matrix's
    True
    """

    dtype = np.float64

    def __init__(self, theta: np.ndarray, m: int, scale: np.ndarray):
        self.theta, self.m = np.asarray(theta, np.float64), int(m)
        self.w = hat_weights(self.theta, np.sin) * (2.0 * np.pi / self.m)
        self.spectrum = azimuthal_cosine_spectrum(self.theta[:-1], self.theta, self.m)
        self.scale = np.asarray(scale, np.float64).ravel()
        self.shape = (len(self.scale), len(self.scale))

    def _weighted(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, np.float64).reshape(len(self.theta) - 1, self.m)
        return self.w[:, None] * np.concatenate([p, p[-1:]], axis=0)

    def __matmul__(self, p):
        return self.scale * circular_projection(self.spectrum, self._weighted(p)).ravel()

    def dense(self) -> np.ndarray:
        """The explicit matrix (``(n - 1) m`` square) of the same operator.

        Returns
        -------
        numpy.ndarray, shape ((n - 1) m, (n - 1) m)
            The kernel as an explicit matrix.
        """
        return np.stack([self @ e for e in np.eye(self.shape[1])], axis=1)


def smith_kernel_anisotropic(f_back: np.ndarray, theta: np.ndarray, phi: np.ndarray, model: str = "masking"):
    """Kernel of Eq. 4.8 over the nodes ``(theta_i, phi_j)``, ``i < n - 1`` (row-major),
    with ``A(o) = sum_n w_n <o, h_n>+ D_n``, ``w_n = int int hat_n sin dtheta dphi`` (node
    rule), the grazing row folded onto its neighbour, as an :class:`AzimuthalKernel`
    (``phi`` must be the uniform ``2 pi k / m``). ``f_back`` is ``(n - 1, m)``.
    Returns ``(K, None)`` (``"masking"``) or ``(2 K, (u, v))`` (``"height_correlated"``),
    as :func:`smith_kernel_isotropic`, ``v`` the row of ``A`` at the normal.

    Parameters
    ----------
    f_back : numpy.ndarray, shape (n - 1, m)
        Backscattering luminance at the nodes.
    theta : numpy.ndarray, shape (n,)
        Polar nodes in radians, 0 to ``pi / 2``.
    phi : numpy.ndarray, shape (m,)
        Uniform azimuth nodes ``2 pi k / m``.
    model : {"masking", "height_correlated"}, optional
        Smith masking form (default ``"masking"``).

    Returns
    -------
    K : AzimuthalKernel
        The kernel (``2 K`` for ``"height_correlated"``).
    rank_one : (numpy.ndarray, numpy.ndarray) or None
        ``(u, v)`` of the rank-one term for ``"height_correlated"``, else ``None``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.8; Dupuy et al. 2015.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.distributions.tabulated import theta_grid
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4))
    >>> theta, phi = theta_grid(8), 2 * np.pi * np.arange(8) / 8
    >>> f_back = backscattering(brdf, theta[:-1, None], phi[None, :])
    >>> k, _ = smith_kernel_anisotropic(f_back, theta, phi)
    >>> type(k).__name__, k.dense().shape
    ('AzimuthalKernel', (56, 56))
    """
    _check_model(model)
    m = len(phi)
    if not np.allclose(phi, np.arange(m) * (2.0 * np.pi / m), atol=1e-12):
        raise ValueError("smith_kernel_anisotropic needs the uniform azimuths 2 pi k / m")
    cos_o = np.repeat(np.cos(theta[:-1]), m)
    scale = 4.0 * np.asarray(f_back, np.float64).ravel() * cos_o
    k = AzimuthalKernel(theta, m, scale * (1.0 if model == "masking" else 2.0))
    if model == "masking":
        return k, None
    wc = k.w * np.cos(theta)
    v = np.repeat(np.append(wc[:-2], wc[-2] + wc[-1]), m)             # A(z) = sum w cos p
    return k, (scale * cos_o, v)


def rule_area_at_normal(dist, refine: int = 1) -> float:
    """``A(z) = int cos theta D dw`` of the normalized table ``dist`` by the kernel's rule
    (1 for an exact rule): the eigenvalue of the discrete kernel divided by it is ``F0``
    (Eq. 4.9) for the exactly normalized ``D``. ``refine``: a radial table resampled from
    the kernel's nodes (:func:`~microfacet.distributions.tabulated.refine_radial`), whose
    every ``refine``-th node is one of the kernel's.

    Parameters
    ----------
    dist : Tabulated distribution
        A normalized tabulated NDF (``theta``, ``ndf_table``).
    refine : int, optional
        Resampling factor of a radial table (default 1: the kernel's nodes).

    Returns
    -------
    float
        The rule's projected area at the normal.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.9.

    Examples
    --------
    >>> from microfacet.distributions.tabulated import TabulatedIsotropic, theta_grid
    >>> import numpy as np
    >>> d = TabulatedIsotropic(np.exp(-np.tan(theta_grid(16)) ** 2 / 0.09) / np.cos(theta_grid(16)) ** 4)
    >>> round(rule_area_at_normal(d), 3)          # 1 for an exact rule
    1.043
    """
    d = dist.ndf_table
    if d.ndim == 1:
        return float(projected_area_matrix_isotropic(dist.theta[::refine], np.zeros(1))[0] @ d[::refine])
    w = hat_weights(dist.theta, np.sin) * (2.0 * np.pi / d.shape[1])
    return float(np.sum(w[:, None] * np.cos(dist.theta)[:, None] * d))


def power_iteration(k: np.ndarray, tol: float = 1e-10, max_iter: int = 1000, rank_one=None):
    """Perron eigenvector and eigenvalue of the kernel (Eq. 4.9): ``p <- K p / |K p|`` from
    ``p = 1`` until the relative change is below ``tol`` (Algorithms 1 and 3 use four
    iterations; we iterate to convergence). With ``rank_one = (u, v)`` the operator is
    ``K p - u (v . p)`` (height-correlated backscattering), clamped at 0: it is
    nonnegative on symmetric ``p`` (``A(o) >= cos theta_o A(z)``), so the clamp only
    guards rounding and asymmetric inputs. ``k`` is a matrix or an operator with
    ``k @ p`` (:class:`AzimuthalKernel`); the iterate is kept in float64.

    Parameters
    ----------
    k : ndarray or AzimuthalKernel
        The kernel (:func:`smith_kernel_isotropic`, :func:`smith_kernel_anisotropic`).
    tol : float
        Relative change of the iterate at which the iterations stop.
    max_iter : int
        Most iterations.
    rank_one : (ndarray, ndarray), optional
        ``(u, v)`` of the height-correlated operator ``K p - u (v . p)``.

    Returns
    -------
    (ndarray, float, int)
        The eigenvector (the NDF at the nodes, unnormalized), the eigenvalue (``F0`` up to the
        rule's normalization, :func:`rule_area_at_normal`) and the iterations made.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.9, Algorithms 1 and 3; Dupuy et al. 2015.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> from microfacet.distributions.tabulated import theta_grid
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> theta = theta_grid(16)
    >>> f_back = backscattering(brdf, theta[:-1])         # the grazing node is not measured
    >>> k, rank_one = smith_kernel_isotropic(f_back, theta, "height_correlated")
    >>> d, eigenvalue, iterations = power_iteration(k, rank_one=rank_one)
    >>> d.shape, round(float(eigenvalue), 3)         # F0 = 0.04 up to the rule's normalization
    ((15,), 0.041)
    """
    p = np.full(k.shape[0], 1.0 / k.shape[0])
    lam = 0.0
    for it in range(1, max_iter + 1):
        q = np.asarray(k @ p, dtype=np.float64)
        if rank_one is not None:
            q = np.maximum(q - rank_one[0] * float(rank_one[1] @ p), 0.0)
        s = float(np.sum(q, dtype=np.float64))
        if not s > 0 or not np.isfinite(s):
            raise MicrofacetError("fit: the backscattering kernel is zero or not finite "
                                  "(does the BRDF reflect anything at i = o?)")
        lam = s / float(np.sum(p, dtype=np.float64))
        q = q / s
        change = float(np.max(np.abs(q - p / np.sum(p))) / np.max(q))
        p = q
        if change < tol:
            break
    return np.asarray(p, dtype=np.float64), lam, it


def ndf_closed_form(f_back: np.ndarray, theta: np.ndarray, gaf: str) -> np.ndarray:
    """``F0 D(h) = 4 f_r(h, h) / G(h, h) cos^2 theta_h`` in closed form: V-groove
    ``4 f max(cos^2, 1/2)`` (Eq. 4.17 divided by ``cos^4``), normal map ``4 f``
    (Eq. 4.18). ``theta`` broadcasts against ``f_back``.

    Parameters
    ----------
    f_back : numpy.ndarray
        Backscattering ``f_r(h, h)`` (luminance) at ``theta``.
    theta : numpy.ndarray
        Polar angles of ``h`` in radians.
    gaf : {"vgroove", "normal_map"}
        The geometric attenuation factor (another value raises ``ValueError``).

    Returns
    -------
    numpy.ndarray
        ``F0 D(h)`` in 1/sr, of the broadcast shape.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.16-4.18.

    Examples
    --------
    >>> import numpy as np
    >>> ndf_closed_form(np.array([1.0, 0.5]), np.radians([0.0, 60.0]), "vgroove")
    array([4., 1.])
    >>> ndf_closed_form(np.array([1.0, 0.5]), np.radians([0.0, 60.0]), "normal_map")
    array([4., 2.])
    """
    if gaf == "vgroove":
        return 4.0 * f_back * np.maximum(np.cos(theta) ** 2, 0.5)
    if gaf == "normal_map":
        return 4.0 * f_back
    raise ValueError(f"no closed form for gaf {gaf!r}")


# ---------------------------------------------------------------------- Fresnel
def _hats(cos_d, n_d: int):
    """Node ``k`` (``theta_d,k = k pi / (2 (n_d - 1))``) and weight ``t`` of the table's
    linear interpolation in ``cos theta_d`` (as :class:`~microfacet.fresnel.Tabulated`):
    ``F = (1 - t) F_k + t F_{k+1}``."""
    c = np.clip(np.asarray(cos_d, dtype=np.float64), 0.0, 1.0)
    k0 = np.minimum((np.arccos(c) / (HALF_PI / (n_d - 1))).astype(np.intp), n_d - 2)
    nodes = np.cos(np.arange(n_d) * (HALF_PI / (n_d - 1)))          # gathered, not a cos per value
    ca, cb = nodes[k0], nodes[k0 + 1]
    return k0, np.clip((ca - c) / (ca - cb), 0.0, 1.0)


def fresnel_samples(brdf, n_d: int, n_h: int = 32, n_phi_d: int = 16, n_phi_h: int = 1,
                    isotropic: bool = False) -> dict:
    """Configurations of Algorithm 2 and the input's values there, evaluated once.

    ``theta_d`` runs over the nodes of the Fresnel table (``n_d`` uniform on
    ``[0, pi/2]``) and the midpoints between them (even / odd ``phi_d`` indices), so that
    the solve sees the table between its nodes; ``theta_h`` over
    ``((k + 1/2) / n_h)^2 pi/2`` (dense where lobes are), ``phi_d`` and ``phi_h`` uniform
    on ``[0, 2 pi)``, or, with ``isotropic``, ``phi_d`` on ``[0, pi)`` with half the
    samples: an isotropic reciprocal BRDF is even in ``phi_d`` and ``pi``-periodic
    (``f(theta_h, theta_d, phi_d) = f(theta_h, theta_d, pi - phi_d)``), so the full
    circle only repeats these configurations.
    Returns ``wi, wo`` ``(K, 3)``, ``cos_d`` ``(K,)``, ``f`` ``(K, 3)`` (nonfinite or
    negative values set to 0) and ``finite`` ``(K,)`` (configurations to use).

    Parameters
    ----------
    brdf : BRDF
        The input (data) BRDF.
    n_d : int
        Nodes of the Fresnel table.
    n_h : int, optional
        ``theta_h`` samples (default 32).
    n_phi_d : int, optional
        ``phi_d`` samples (default 16).
    n_phi_h : int, optional
        ``phi_h`` samples (default 1).
    isotropic : bool, optional
        Sample ``phi_d`` on ``[0, pi)`` only (default ``False``).

    Returns
    -------
    dict
        ``wi``, ``wo`` ``(K, 3)``, ``cos_d`` ``(K,)``, ``f`` ``(K, 3)`` and ``finite``
        ``(K,)``.

    References
    ----------
    Dupuy 2015, thesis, Algorithm 2.

    Examples
    --------
    >>> import microfacet as mf
    >>> s = fresnel_samples(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), n_d=4, n_h=4, n_phi_d=4)
    >>> sorted(s), s["wi"].shape
    (['cos_d', 'f', 'finite', 'n_d', 'wi', 'wo'], (64, 3))
    """
    step = HALF_PI / (n_d - 1)
    theta_d = np.linspace(0.0, HALF_PI, n_d)
    theta_h = ((np.arange(n_h) + 0.5) / n_h) ** 2 * HALF_PI
    if isotropic:
        n_phi_d = max(n_phi_d // 2, 2)
    phi_d = (np.arange(n_phi_d) + 0.5) * ((np.pi if isotropic else 2.0 * np.pi) / n_phi_d)
    phi_h = np.arange(n_phi_h) * (2.0 * np.pi / n_phi_h)
    TD, TH, PH, PD = np.meshgrid(theta_d, theta_h, phi_h, phi_d, indexing="ij")
    TD = np.minimum(TD + 0.5 * step * (np.arange(n_phi_d) % 2), HALF_PI)
    wi, wo = hd_to_io(_directions(TH, PH), _directions(TD, PD))
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    f = np.asarray(brdf.eval(wi, wo), dtype=np.float64)
    finite = (wi[:, 2] > 0) & (wo[:, 2] > 0) & np.all(np.isfinite(f), axis=-1) & measured_mask(brdf, wi, wo)
    return dict(wi=wi, wo=wo, cos_d=np.cos(TD).ravel(), f=np.where(finite[:, None], np.maximum(np.nan_to_num(f), 0.0), 0.0),
                finite=finite, n_d=n_d)


class FresnelSolution(NamedTuple):
    """A solved Fresnel table (:func:`solve_fresnel`): increasing ``cos_theta_d`` of the
    ``n_d`` nodes, their ``(n_d, 3)`` values ``rgb``, the ``(3,)`` diffuse reflectance
    ``k_d`` (zeros without a base), and ``misfit``: the model's :func:`chi2_residual` over
    the usable configurations (a weighting that does not depend on the NDF, so that fits
    with different NDFs compare), plus, with an albedo weight ``lambda``, the albedo term
    ``lambda^2 mean_{v, c} (a_fit / a_data - 1)^2`` at the solution.

    Attributes
    ----------
    cos_theta_d : numpy.ndarray, shape (n_d,)
        Increasing node cosines.
    rgb : numpy.ndarray, shape (n_d, 3)
        The table's values at the nodes, in ``[0, 1]``.
    k_d : numpy.ndarray, shape (3,)
        Diffuse reflectance of the Lambertian base (zeros without one).
    misfit : float
        :func:`chi2_residual` of the model, plus the albedo term with an albedo weight.

    Examples
    --------
    >>> import microfacet as mf
    >>> sol = extract_fresnel(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), n_d=4)
    >>> isinstance(sol, FresnelSolution), sol.rgb.shape, round(sol.misfit, 6)
    (True, (4, 3), 0.0)
    """
    cos_theta_d: np.ndarray
    rgb: np.ndarray
    k_d: np.ndarray
    misfit: float


class _FresnelSystem(NamedTuple):
    """The normal equations ``h x = b`` (``b`` per channel) of :func:`solve_fresnel` over
    the usable configurations: their data ``f``, mirror values ``f_id``, weights ``w``, the
    hat nodes ``k0`` and fractions ``t`` of their ``cos theta_d``."""
    h: np.ndarray
    b: np.ndarray
    f: np.ndarray
    f_id: np.ndarray
    w: np.ndarray
    k0: np.ndarray
    t: np.ndarray
    n_d: int
    diffuse: bool


def solve_fresnel(samples: dict, ideal, diffuse: bool = False, smoothing: float = 1e-6, albedo=None,
                  kd_max=None, albedo_weight: float = 0.0, energy_margin: float = 0.01) -> FresnelSolution:
    """Fresnel table ``F(theta_d)`` per RGB channel (Eq. 4.11, Algorithm 2) bounded to
    ``[0, 1]``, and optionally a Lambertian base ``k_d``, by a box-constrained linear
    least-squares solve over the configurations ``samples`` (:func:`fresnel_samples`):

    ``min sum_j w_j (f_j - f_id,j sum_k F_k hat_k(cos theta_d,j) - k_d / pi)^2
    + smoothing tr(H) / n |Delta^2 F|^2``,  ``0 <= F_k <= 1``, ``0 <= k_d <= 1``

    with ``f_id`` the fitted ideal-mirror BRDF ``ideal`` (Eq. 4.10), ``hat_k`` the linear
    interpolation of the table in ``cos theta_d`` and ``w_j = 1 / (f_id,j + k_d0 / pi)``.
    Without the diffuse term (``k_d0 = 0``, configurations where ``f_id`` is negligible
    dropped: :data:`NEGLIGIBLE_LOBE`) and
    without the bounds and the smoothing, the solution at nodes sampled only there is
    ``sum f / sum f_id``, the ``f_id``-weighted mean of ``f / f_id`` (Eq. 4.11). The second-
    difference penalty (weight ``smoothing`` times the mean diagonal of the normal
    equations) only fills nodes that no configuration sees, unless the table would vary by
    more than :data:`TV_MAX` times its range: then it is raised until it does not
    (:func:`smooth_table_qp`; without it, measured materials gave tables flipping between 0
    and 1 across ``theta_d`` under the albedo term and constraint).
    Each channel's problem is solved on its normal equations (``n x n``) by :func:`box_qp`. ``kd_max`` ``(3,)`` bounds ``k_d`` per channel (e.g. by the
    backscattering, which the base may not exceed).

    ``albedo = (a, a_data)`` (:func:`albedo_rows`) adds the energy constraints
    ``sum_k F_k a[v, k] + k_d a[v, n_d] <= a_data[v] + energy_margin`` at each view ``v`` (the fit
    reflects no more than the data); when the bounded solution violates them, the linearly
    constrained problem is solved by :func:`_energy_constrained`. With ``albedo_weight =
    lambda > 0`` the albedo also enters the objective, as in
    :func:`~microfacet.fit.analytic.fit_analytic`: per channel ``c`` the objective above,
    divided by the data's own weighted energy ``S_c = sum_j w_j f_jc^2`` (so that it is a
    relative squared error), plus

    ``lambda^2 / V sum_v ((sum_k F_k a[v, k] + k_d a[v, n_d]) / a_data[v, c] - 1)^2``

    (:func:`_albedo_objective`): the fit's albedo is pulled towards the data's, from below
    as well, while the constraint still bounds it from above.

    Returns a :class:`FresnelSolution` ``(cos_theta_d, rgb, k_d, misfit)``.

    Parameters
    ----------
    samples : dict
        Configurations and data values (:func:`fresnel_samples`).
    ideal : BRDF
        The fitted ideal-mirror BRDF ``f_id``.
    diffuse : bool, optional
        Also fit a Lambertian base ``k_d`` (default ``False``).
    smoothing : float, optional
        Smallest second-difference penalty weight (default 1e-6).
    albedo : (a, a_data), optional
        Albedo rows (:func:`albedo_rows`) for the energy constraints (default none).
    kd_max : array-like, shape (3,), optional
        Upper bounds of ``k_d`` per channel (default 1).
    albedo_weight : float, optional
        ``lambda`` of the albedo objective term (default 0: none).
    energy_margin : float, optional
        Slack of the energy constraints (default 0.01).

    Returns
    -------
    FresnelSolution
        ``(cos_theta_d, rgb, k_d, misfit)``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.10, 4.11, Algorithm 2; Twomey 1963; Tikhonov & Arsenin 1977 (the smoothness penalty).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ideal = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))                 # the fitted ideal-mirror BRDF
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> sol = solve_fresnel(fresnel_samples(brdf, n_d=8, n_h=8, n_phi_d=8), ideal)
    >>> sol.rgb[:, 0].round(3), sol.k_d
    (array([0.837, 0.306, 0.079, 0.046, 0.04 , 0.04 , 0.04 , 0.04 ]), array([0., 0., 0.]))
    >>> mf.fresnel.Schlick(0.04)(sol.cos_theta_d)[:, 0].round(3)     # the truth at the nodes
    array([1.   , 0.313, 0.096, 0.047, 0.04 , 0.04 , 0.04 , 0.04 ])
    """
    if not (np.isfinite(albedo_weight) and albedo_weight >= 0):
        raise ValueError(f"albedo_weight must be a finite number >= 0, got {albedo_weight!r}")
    if not (np.isfinite(energy_margin) and energy_margin >= 0):
        raise ValueError(f"energy_margin must be a finite number >= 0, got {energy_margin!r}")
    system = _fresnel_system(samples, ideal, diffuse)
    x = np.empty((len(system.h), 3))
    energy = None if albedo is None else (albedo[0], np.asarray(albedo[1], np.float64) + energy_margin)
    mu = None
    for c in (1, 0, 2):                    # green first: its smoothing starts the others' search
        hi = np.ones(len(x))
        if diffuse and kd_max is not None:
            hi[system.n_d] = max(min(1.0, float(kd_max[c])), 1e-12)
        hc, bc = system.h, system.b[:, c]
        if albedo is not None and albedo_weight > 0:
            # the data term divided by the data's energy (a relative misfit), plus the albedo term
            energy_c = max(float(np.sum(system.w * system.f[:, c] ** 2)), 1e-300)
            ha, ba = _albedo_objective(albedo, c, diffuse, albedo_weight)
            hc, bc = hc / energy_c + ha, bc / energy_c + ba
        x[:, c], mu = smooth_table_qp(hc, bc, (np.zeros(len(x)), hi), system.n_d, smoothing,
                                      None if energy is None else (energy, c, diffuse), hint=mu)
    return _fresnel_solution(system, x, albedo, albedo_weight)


#: Configurations where the mirror lobe of a Fresnel solve without a base is below this times
#: its peak are left out (:func:`_fresnel_system`).
NEGLIGIBLE_LOBE = 1e-12


def _fresnel_system(samples: dict, ideal, diffuse: bool) -> _FresnelSystem:
    """The normal equations of :func:`solve_fresnel`: weights ``1 / (f_id + k_d0 / pi)``,
    with ``k_d0`` the data's floor where the mirror lobe is negligible (0 without a base,
    and configurations with ``f_id`` below :data:`NEGLIGIBLE_LOBE` times its peak dropped:
    they carry no information on ``F``, and in the far tail ``f_id`` is 0, subnormal or
    tiny depending on how the lobe's exponential underflows, so ``1 / f_id`` may overflow)."""
    n_d = samples["n_d"]
    f = samples["f"]
    f_id = np.asarray(ideal.eval(samples["wi"], samples["wo"]), dtype=np.float64)[..., 0]
    ok = samples["finite"] & np.isfinite(f_id) & (f_id >= 0)
    if diffuse:
        low = ok & (f_id <= 1e-3 * np.max(np.where(ok, f_id, 0.0)))
        floor = np.median(luminance(f[low])) if np.any(low) else 0.0
        delta = max(float(floor), 1e-6 * float(np.max(luminance(f[ok])))) if np.any(ok) else 0.0
    else:
        ok &= f_id > NEGLIGIBLE_LOBE * np.max(np.where(ok, f_id, 0.0))
        delta = 0.0
    if not np.any(ok & (f_id > 0)):
        raise MicrofacetError("fit: no configuration to extract the Fresnel term from")
    f, f_id = f[ok], f_id[ok]
    w = 1.0 / (f_id + delta)
    k0, t = _hats(samples["cos_d"][ok], n_d)
    cols, vals = [k0, k0 + 1], [f_id * (1.0 - t), f_id * t]
    n_var = n_d + (1 if diffuse else 0)
    if diffuse:
        cols.append(np.full(len(f), n_d))
        vals.append(np.full(len(f), 1.0 / np.pi))
    h = np.zeros(n_var * n_var)
    b = np.zeros((n_var, 3))
    for ca, va in zip(cols, vals):
        wva = w * va
        for cb, vb in zip(cols, vals):
            h += np.bincount(ca * n_var + cb, weights=wva * vb, minlength=n_var * n_var)
        b += np.stack([np.bincount(ca, weights=wva * f[:, c], minlength=n_var) for c in range(3)], axis=1)
    h = h.reshape(n_var, n_var)
    if not np.all(np.isfinite(h)) or not np.all(np.isfinite(b)):
        raise MicrofacetError("fit: the Fresnel system is not finite (the BRDF's values overflow float64 "
                              "products: are they physical?)")
    return _FresnelSystem(h, b, f, f_id, w, k0, t, n_d, diffuse)


def _fresnel_solution(system: _FresnelSystem, x: np.ndarray, albedo, albedo_weight: float) -> FresnelSolution:
    """The table and base ``x`` (nodes increasing in ``theta_d``, then ``k_d``) as a
    :class:`FresnelSolution`, with the misfit of the whole model."""
    n_d, k0, t = system.n_d, system.k0, system.t
    rgb = x[:n_d]
    kd = x[n_d] if system.diffuse else np.zeros(3)
    model = system.f_id[:, None] * ((1.0 - t)[:, None] * rgb[k0] + t[:, None] * rgb[k0 + 1]) + kd / np.pi
    misfit = chi2_residual(model, system.f)
    if albedo is not None and albedo_weight > 0:
        a_fit, a_data = _albedo_rows_of(albedo[0], system.diffuse) @ x, np.asarray(albedo[1], np.float64)
        seen = a_data > 0
        misfit += albedo_weight**2 * float(np.mean((a_fit[seen] / a_data[seen] - 1.0) ** 2))
    theta_d = np.linspace(0.0, HALF_PI, n_d)
    return FresnelSolution(np.cos(theta_d)[::-1].copy(), rgb[::-1].copy(), kd, float(misfit))


#: Largest total variation of a fitted Fresnel table over its range, per channel
#: (:func:`smooth_table_qp`; issue: tables alternating between 0 and 1 across ``theta_d``).
TV_MAX = 2.0
#: Relative slack of that bound for rounding: a table with one bump between equal ends has
#: a variation of exactly twice its range, which rounding would otherwise pass or fail at
#: random (and two evaluation paths of the same fit choose different smoothings).
TV_ROUNDING = 1e-6
#: Smoothing weights ``mu`` tried by :func:`smooth_table_qp` past the default (a factor 10
#: apart: the penalty's smoothing length, ~``mu^(1/4)`` nodes, grows 1.8x a step; at the
#: top, ~18 nodes, the energy-constrained solve is still well conditioned), and the first
#: one tried (the smallest that meets the bound on most measured materials).
SMOOTHING_STEPS = tuple(10.0**e for e in range(-5, 6))
SMOOTHING_START = 100.0


def table_variation(values) -> np.ndarray:
    """Total variation of a table over its range, per column: ``sum_k |F_{k+1} - F_k| /
    (max F - min F)`` (1 for a monotone table, 1 for a constant one; ``values`` ``(n,)`` or
    ``(n, C)``). Fresnel tables of the fits keep it at most :data:`TV_MAX`. Example:
    ``table_variation([0, 1, 0, 1]) == 3.0``.

    Parameters
    ----------
    values : array-like, shape (n,) or (n, C)
        A table, one column per channel.

    Returns
    -------
    float or numpy.ndarray, shape (C,)
        The variation over the range (a float for a 1-D table).

    Examples
    --------
    >>> table_variation([0.0, 1.0, 0.0, 1.0]), table_variation([0.1, 0.5, 0.9])
    (3.0, 1.0)
    """
    v = np.asarray(values, dtype=np.float64)
    v = v.reshape(len(v), -1)
    tv = np.sum(np.abs(np.diff(v, axis=0)), axis=0)
    span = np.max(v, axis=0) - np.min(v, axis=0)
    flat = span <= 1e-12 * np.maximum(np.max(np.abs(v), axis=0), 1e-300)
    out = np.where(flat, 1.0, tv / np.where(flat, 1.0, span))
    return out if np.ndim(values) > 1 else float(out[0])


def smooth_table_qp(h: np.ndarray, g: np.ndarray, bounds, n_d: int, smoothing: float = 1e-6, energy=None,
                    tv_max: float = TV_MAX, hint=None):
    """``argmin 1/2 x^T h x - g^T x + mu s / 2 |Delta^2 x[:n_d]|^2`` under ``bounds`` (and,
    with ``energy = ((a, a_data), c, diffuse)``, the albedo rows of :func:`_energy_constrained`)
    whose table ``x[:n_d]`` varies by at most ``tv_max`` times its range
    (:func:`table_variation`, to :data:`TV_ROUNDING`): a second-difference Tikhonov penalty (Tikhonov & Arsenin
    1977; Twomey 1963) scaled to the data, ``s`` the mean diagonal of ``h`` over the table's
    nodes, with the smallest ``mu`` among ``smoothing`` and :data:`SMOOTHING_STEPS` above it
    for which the bound holds (a walk from ``hint``, e.g. another channel's, or
    :data:`SMOOTHING_START`, down while it holds or up until it holds; each solve started
    from the nearest one's solution). Each problem is solved by :func:`box_qp` (then :func:`_energy_constrained`).
    ``mu = smoothing`` (1e-6: it only fills nodes no configuration sees) when the bound
    holds there, as for every smooth Fresnel term of an analytic BRDF (round trips
    unchanged). If no ``mu`` meets it, the table is the weighted monotone (isotonic,
    pool-adjacent-violators; Ayer et al. 1955) projection of the smoothest solution,
    nondecreasing or nonincreasing whichever is nearer, scaled down to meet the albedo
    rows: its variation is then its range. ``x[n_d:]`` (a diffuse base) is not penalized.
    Returns ``(x, mu)`` (``mu`` inf for the monotone projection).

    Parameters
    ----------
    h : numpy.ndarray, shape (n, n)
        Normal-equation matrix (symmetric positive definite).
    g : numpy.ndarray, shape (n,)
        Linear term.
    bounds : (numpy.ndarray, numpy.ndarray)
        Lower and upper bounds of ``x``.
    n_d : int
        Table nodes: the first ``n_d`` unknowns.
    smoothing : float, optional
        Smallest penalty weight ``mu`` (default 1e-6).
    energy : ((a, a_data), int, bool), optional
        Albedo rows (:func:`albedo_rows`), the channel and whether ``x`` has a diffuse
        base (default ``None``: no albedo constraint).
    tv_max : float, optional
        Largest table variation over its range (default 2).
    hint : float, optional
        The ``mu`` to start the walk from (default :data:`SMOOTHING_START`).

    Returns
    -------
    x : numpy.ndarray, shape (n,)
        The solution.
    mu : float
        The penalty weight used (``inf`` for the monotone projection).

    Examples
    --------
    >>> import numpy as np
    >>> h, g = np.eye(4), np.array([0.2, 0.9, 0.1, 0.8])       # an oscillating least-squares table
    >>> x, mu = smooth_table_qp(h, g, (np.zeros(4), np.ones(4)), n_d=4, tv_max=1.5)
    >>> x.round(3), float(table_variation(x)) <= 1.5
    (array([0.336, 0.491, 0.509, 0.664]), True)
    """
    lo, hi = bounds
    lap = np.diff(np.eye(n_d), 2, axis=0)
    penalty = lap.T @ lap
    scale = max(float(np.trace(h[:n_d, :n_d])) / n_d, 1e-300)
    ridge = 1e-14 * max(float(np.trace(h)), 1e-300)
    solved = {}

    def solve(i):
        """``(x, h + penalty, bound holds)`` at ``mus[i]``, started from the nearest solved one.
        Solved for ``z = sqrt(diag) x`` (Jacobi scaling: a stiff penalty otherwise leaves the
        projected Newton steps of :func:`box_qp` on the variables held at a bound tiny)."""
        if i not in solved:
            hm = h.copy()
            hm[:n_d, :n_d] += mus[i] * scale * penalty
            hm[np.diag_indices_from(hm)] += ridge
            d = np.sqrt(np.diag(hm))
            hs, gs = hm / d[:, None] / d[None, :], g / d
            near = min(solved, key=lambda j: abs(j - i), default=None)
            z = box_qp(hs, gs, lo * d, hi * d, x0=None if near is None else solved[near][0] * d)
            if energy is not None:
                (a, a_data), c, diffuse = energy
                a = np.array(a, dtype=np.float64)
                a[:, :len(d)] /= d
                z = _energy_constrained(hs, gs, z, (lo * d, hi * d), (a, a_data), c, diffuse)
            x = z / d
            solved[i] = (x, hm, table_variation(x[:n_d]) <= tv_max * (1.0 + TV_ROUNDING))
        return solved[i]

    mus = [smoothing] + [m for m in SMOOTHING_STEPS if m > smoothing]
    if solve(0)[2]:
        return solve(0)[0], mus[0]
    start = hint if hint in mus[1:] else min((m for m in mus[1:] if m >= SMOOTHING_START), default=mus[-1])
    i = mus.index(start)
    if solve(i)[2]:                              # down while the bound holds
        while i > 1 and solve(i - 1)[2]:
            i -= 1
        return solve(i)[0], mus[i]
    while i + 1 < len(mus):                      # up until it holds
        i += 1
        if solve(i)[2]:
            return solve(i)[0], mus[i]
    x, hm, _ = solve(i)
    return _monotone_table(x, hm, n_d, energy), np.inf


def _monotone_table(x, h, n_d: int, energy) -> np.ndarray:
    """``x`` with its table ``x[:n_d]`` replaced by its isotonic regression (weights the
    diagonal of ``h``), in the direction of least weighted change, then scaled down so that
    the albedo rows of ``energy`` hold (all rows are nonnegative)."""
    w = np.maximum(np.diag(h)[:n_d], 1e-300)
    t = x[:n_d]
    up, down = _isotonic(t, w), _isotonic(t[::-1], w[::-1])[::-1]
    x = x.copy()
    x[:n_d] = up if np.sum(w * (up - t) ** 2) <= np.sum(w * (down - t) ** 2) else down
    if energy is not None:
        (a, a_data), c, diffuse = energy
        rows = _albedo_rows_of(a, diffuse)
        excess = np.max((rows @ x) / np.maximum(a_data[:, c], 1e-300))
        if excess > 1.0:
            x = x / excess
    return x


def _isotonic(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted nondecreasing least-squares fit of ``y`` (pool adjacent violators)."""
    means, weights, counts = [], [], []
    for yi, wi in zip(y, w):
        means.append(float(yi)), weights.append(float(wi)), counts.append(1)
        while len(means) > 1 and means[-2] > means[-1]:
            m2, w2, c2 = means.pop(), weights.pop(), counts.pop()
            w1 = weights[-1]
            means[-1] = (means[-1] * w1 + m2 * w2) / (w1 + w2)
            weights[-1], counts[-1] = w1 + w2, counts[-1] + c2
    return np.repeat(means, counts)


def _albedo_rows_of(a, diffuse: bool) -> np.ndarray:
    """The albedo rows over the unknowns of :func:`solve_fresnel` from the ``(V, n_d + 1)``
    rows of :func:`albedo_rows` (the last column: the base's albedo per unit ``k_d``),
    without that column when there is no base."""
    return a if diffuse else a[:, :-1]


def _albedo_objective(albedo, c: int, diffuse: bool, weight: float):
    """Normal equations ``(H, g)`` of the albedo term of :func:`solve_fresnel` for channel
    ``c``, ``weight^2 / V sum_v (r_v x / a_data[v, c] - 1)^2 = x^T H x - 2 g^T x + const``
    (``r_v`` the albedo rows, :func:`_albedo_rows_of`); views where the data reflect
    nothing are left out."""
    a, a_data = albedo
    rows = _albedo_rows_of(a, diffuse)
    target = np.asarray(a_data, np.float64)[:, c]
    seen = target > 0
    scaled = rows[seen] / target[seen, None]
    c2 = weight**2 / max(len(rows), 1)
    return c2 * scaled.T @ scaled, c2 * scaled.sum(axis=0)


def chi2_residual(model: np.ndarray, f: np.ndarray) -> float:
    """``sum_j sum_c (model_jc - f_jc)^2 / (Y(f_j) + eps) / sum_j Y(f_j)`` (a Pearson
    chi-square, ``Y`` the luminance, ``eps`` 1e-3 of its mean): relative to the data
    everywhere, lobe and floor alike, whatever the model.

    Parameters
    ----------
    model : numpy.ndarray, shape (..., 3)
        Model values, RGB.
    f : numpy.ndarray, shape (..., 3)
        Data values, RGB, at the same configurations.

    Returns
    -------
    float
        The normalized chi-square (0: a perfect model).

    References
    ----------
    Rec. ITU-R BT.709 (the luminance weights).

    Examples
    --------
    >>> import numpy as np
    >>> f = np.array([[1.0, 1.0, 1.0], [0.1, 0.1, 0.1]])
    >>> chi2_residual(f, f), round(chi2_residual(1.1 * f, f), 6)
    (0.0, 0.02997)
    """
    y = luminance(f)
    eps = 1e-3 * max(float(np.mean(y)), 1e-300)
    return float(np.sum(np.sum((model - f) ** 2, axis=-1) / (y + eps)) / max(float(np.sum(y)), 1e-300))


def golden_section(f, a: float, b: float, xatol: float, lower=None) -> tuple[float, float]:
    """``(x, f(x))`` minimizing a unimodal ``f`` on ``[a, b]`` by golden-section search
    (Kiefer 1953) to ``|b - a| <= xatol`` (the ends are not evaluated): SciPy-free, so a
    fit imports no optimizer it does not need. ``lower``: a cheaper lower bound of ``f``;
    ``f`` is then evaluated only where the bound does not decide a comparison (the same
    steps and result as without it)."""
    r = (np.sqrt(5.0) - 1.0) / 2.0

    def point(x):                                  # [x, f(x) or a bound of it, exact]
        return [x, f(x), True] if lower is None else [x, lower(x), False]

    def exact(p):
        if not p[2]:
            p[1], p[2] = f(p[0]), True
        return p[1]

    def le(pc, pd) -> bool:
        """``f(c) <= f(d)``."""
        while not (pc[2] and pd[2]):
            if pd[2] and pc[1] > pd[1]:
                return False
            if pc[2] and pd[1] > pc[1]:
                return True
            exact(min((p for p in (pc, pd) if not p[2]), key=lambda p: p[1]))
        return pc[1] <= pd[1]

    pc, pd = point(b - r * (b - a)), point(a + r * (b - a))
    while b - a > xatol:
        if le(pc, pd):
            b, pd = pd[0], pc
            pc = point(b - r * (b - a))
        else:
            a, pc = pc[0], pd
            pd = point(a + r * (b - a))
    return (pc[0], exact(pc)) if le(pc, pd) else (pd[0], exact(pd))


def spd_solve(h: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``h^-1 b`` for a symmetric positive definite ``h`` by its Cholesky factor
    ``h = L L^T`` (``L^T x = L^-1 b``; NumPy only, so a fit does not import
    ``scipy.linalg``, ~0.03 s). A matrix that is positive semidefinite but not numerically
    definite (rounding in a sum of terms of very different scales, e.g. a sharp lobe's data
    term with a low-rank albedo term; unseen nodes) is solved with its diagonal scaled to 1
    (Jacobi) and a ridge of 1e-12, then 1e-9 and 1e-6 of that unit diagonal (Tikhonov), and
    by least squares (``numpy.linalg.lstsq``, minimum norm) if even that fails."""
    try:
        el = np.linalg.cholesky(h)
        return np.linalg.solve(el.T, np.linalg.solve(el, b))
    except np.linalg.LinAlgError:
        pass
    d = np.sqrt(np.maximum(np.abs(np.diag(h)), 1e-300))
    hs = h / d[:, None] / d[None, :]
    bs = b / (d[:, None] if np.ndim(b) > 1 else d)
    for ridge in (1e-12, 1e-9, 1e-6):
        try:
            el = np.linalg.cholesky(hs + ridge * np.eye(len(hs)))
        except np.linalg.LinAlgError:
            continue
        y = np.linalg.solve(el.T, np.linalg.solve(el, bs))
        return y / (d[:, None] if np.ndim(b) > 1 else d)
    y = np.linalg.lstsq(hs, bs, rcond=None)[0]
    return y / (d[:, None] if np.ndim(b) > 1 else d)


def box_qp(h: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, tol: float = 1e-12,
           max_iter: int = 200, x0=None) -> np.ndarray:
    """``argmin 1/2 x^T h x - g^T x`` over the box ``lo <= x <= hi`` (``h`` symmetric
    positive definite; ``hi`` may be ``inf``): Goldfarb & Idnani's dual active-set method
    (1983; the ``quadprog`` package), exact for a strictly convex ``h``, the same optimum
    as BVLS on ``|r x - y|`` with ``h = r^T r``, ``g = r^T y``. Where ``h`` is numerically
    only semidefinite (quadprog refuses it): Bertsekas' projected Newton method (1982) --
    the Newton step on the variables not held at a bound by the gradient, an Armijo
    search along the projection arc -- until the projected gradient vanishes
    (``|x - P(x - grad)| <= tol |g|``), from ``x0`` (projected on the box; default the
    unconstrained minimizer projected), e.g. the solution of a nearby problem, whose active
    set it guesses. The result lies in the box.

    Parameters
    ----------
    h : numpy.ndarray, shape (n, n)
        Symmetric positive definite matrix.
    g : numpy.ndarray, shape (n,)
        Linear term.
    lo, hi : numpy.ndarray, shape (n,)
        Lower and upper bounds (``hi`` may be ``inf``).
    tol : float, optional
        Stopping tolerance on the projected gradient, relative to ``|g|`` (default 1e-12).
    max_iter : int, optional
        Most Newton iterations (default 200).
    x0 : array-like, shape (n,), optional
        Start point (default: the projected unconstrained minimizer).

    Returns
    -------
    numpy.ndarray, shape (n,)
        The minimizer.

    References
    ----------
    Bertsekas 1982 (projected Newton).

    Examples
    --------
    >>> import numpy as np
    >>> box_qp(np.eye(2), np.array([2.0, -1.0]), np.zeros(2), np.ones(2))    # clipped to the box
    array([1., 0.])
    """
    scale = max(float(np.max(np.abs(g))), 1e-300)
    if not np.isfinite(scale + float(np.sum(h))):
        raise MicrofacetError("fit: a least-squares system is not finite (do the BRDF's values overflow?)")
    lo, hi = np.broadcast_to(lo, np.shape(g)), np.broadcast_to(hi, np.shape(g))
    x = _dual_active_set(h, g, lo, hi)
    if x is not None:
        return np.minimum(np.maximum(x, lo), hi)
    # np.clip, np.ix_, np.linalg.norm and np.array_equal spelled with ufuncs and masks (the
    # same values)
    x = np.minimum(np.maximum(spd_solve(h, g) if x0 is None else x0, lo), hi)
    # the gradient's rounding error (~eps |h| |x|): a stiff h (a strong smoothing penalty)
    # cannot bring it below tol |g|
    floor = max(tol * scale, 4e-16 * float(np.max(np.abs(h).sum(axis=1))) * float(np.max(np.abs(x))))
    for _ in range(max_iter):
        grad = h @ x - g
        step = x - np.minimum(np.maximum(x - grad, lo), hi)
        if np.max(np.abs(step)) <= floor:
            break
        eps = min(float(np.sqrt(step.dot(step))), 1e-3)
        held = ((x <= lo + eps) & (grad > 0)) | ((x >= hi - eps) & (grad < 0))
        free = ~held
        d = np.where(held, -grad, 0.0)
        if np.any(free):
            d[free] = -spd_solve(h[free][:, free], grad[free])
        s = 1.0
        for _ in range(60):
            xn = np.minimum(np.maximum(x + s * d, lo), hi)
            dx = xn - x                            # q(xn) - q(x) without cancellation
            if grad @ dx + 0.5 * dx @ h @ dx <= 1e-4 * grad @ dx:
                break
            s *= 0.5
        if (xn == x).all():
            break
        x = xn
    return x


def _box_rows(lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The box ``lo <= x <= hi`` as quadprog's rows ``C x >= b``: ``x >= lo``, ``-x >= -hi``,
    each where finite."""
    eye = np.eye(len(lo))
    low, high = np.isfinite(lo), np.isfinite(hi)
    return np.concatenate([eye[low], -eye[high]]), np.concatenate([lo[low], -hi[high]]).astype(np.float64)


def _dual_active_set(h, g, lo, hi):
    """:func:`box_qp` by ``quadprog.solve_qp``, or None where it finds ``h`` not positive definite."""
    import quadprog
    rows, b = _box_rows(lo, hi)
    try:
        return quadprog.solve_qp(np.asarray(h, dtype=np.float64), np.asarray(g, dtype=np.float64), rows.T, b)[0]
    except ValueError:
        return None


def _energy_constrained(h, g, x0, bounds, albedo, c, diffuse):
    """``min 1/2 x^T h x - g^T x`` under ``bounds`` and ``a x <= a_data`` (the albedo
    rows of channel ``c``), from the box-constrained solution ``x0`` (returned when
    feasible): Goldfarb & Idnani's dual active-set method (1983; the ``quadprog``
    package), exact for a strictly convex ``h``. A matrix that is numerically only
    semidefinite is retried with a ridge of 1e-12, then 1e-9 of its mean diagonal; should
    that fail too, ``x0`` is kept. A remaining violation (rounding) is removed by scaling
    ``x`` down (all rows are nonnegative), so the result is feasible."""
    import quadprog
    a, a_data = albedo
    rows = _albedo_rows_of(a, diffuse)
    limit = a_data[:, c]
    if np.all(rows @ x0 <= limit + 1e-9):
        return x0
    lo, hi = bounds
    eye = np.eye(len(g))
    box, b = _box_rows(lo, hi)
    constraints = np.concatenate([box, -rows]).T                        # C^T x >= b
    b = np.concatenate([b, -limit])
    h = 0.5 * (h + h.T)
    x, mean = x0, float(np.trace(h)) / len(h)
    for ridge in (0.0, 1e-12, 1e-9):
        try:
            x = quadprog.solve_qp(h + ridge * mean * eye, np.asarray(g, dtype=np.float64), constraints, b)[0]
            break
        except ValueError:
            continue
    x = np.minimum(np.maximum(x, lo), hi)
    excess = np.max((rows @ x) / np.maximum(limit, 1e-300))
    return x / excess if excess > 1.0 else x


def albedo_rows(brdf, ideal, n_d: int, views, n_u: int = 48):
    """Linear directional-albedo model of the fit and the data's albedo at ``views``
    (``(V, 3)`` view directions): ``a[v, k] = int f_id(i, o_v) hat_k(cos theta_d) cos
    theta_i dw_i`` for the ``n_d`` Fresnel nodes ``k`` and ``a[v, n_d] = int cos theta_i /
    pi dw_i`` (the fit's albedo is ``sum_k F_k a[v, k] + k_d a[v, n_d]``, Eq. 2.1 with the
    table's hats and a Lambertian base) and ``a_data[v] = int f(i, o_v) cos theta_i dw_i``,
    all by the same stratified ``n_u x n_u`` importance sampling of the defensive mixture
    ``1/2`` visible normals of ``ideal`` + ``1/2`` cosine lobe (each on the whole grid,
    weights of the balance heuristic), so that a model equal to the data has exactly the
    data's estimate (the base's column is the estimate of 1, not 1). Directions where the
    data are not finite or negative (garbage at grazing angles) are left out of both the
    rows and the data's albedo, so that they compare over the same directions. Returns ``(a,
    a_data)``, ``(V, n_d + 1)`` and ``(V, 3)``; ``brdf=None``: the model's rows alone
    (``a_data`` None), e.g. to bound a fit's own albedo.

    Parameters
    ----------
    brdf : BRDF or None
        The data (e.g. a measured BRDF); ``None``: the model's rows only.
    ideal : BRDF
        The fitted ideal-mirror BRDF ``f_id``.
    n_d : int
        Nodes of the Fresnel table.
    views : array-like, shape (V, 3)
        Unit view directions.
    n_u : int, optional
        Stratified samples per axis (``n_u x n_u`` per view and strategy; default 48).

    Returns
    -------
    a : numpy.ndarray, shape (V, n_d + 1)
        The model's albedo rows (Fresnel nodes, then the Lambertian base).
    a_data : numpy.ndarray, shape (V, 3), or None
        The data's directional albedo (``None`` when ``brdf`` is ``None``).

    References
    ----------
    Dupuy 2015, thesis, Eq. 2.1.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ideal = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> a, a_data = albedo_rows(brdf, ideal, 4, np.array([[0.0, 0.0, 1.0]]), n_u=8)
    >>> a.shape, a_data.shape
    ((1, 5), (1, 3))
    """
    from ..brdf import Lambertian
    from ..geometry import dot

    u, wo_v, wi_c, pdf_c, k0_c, t_c = _cosine_strategy(n_u, views, n_d)     # the cosine lobe's, kept
    v_count = len(wo_v)
    wi_s = ideal.sample(u, wo_v)[0]
    # both strategies on the whole stratified grid (a split of the grid would sample
    # each from half its domain), balance-heuristic weights
    wi = np.concatenate([wi_s, wi_c], axis=1)
    wo = np.concatenate([wo_v, wo_v], axis=1)
    pdf = 0.5 * ideal.pdf(wi, wo) + 0.5 * np.concatenate([Lambertian(1.0).pdf(wi_s, wo_v), pdf_c], axis=1)
    ok = (pdf > 0) & (wi[..., 2] > 0)
    inv = np.where(ok, 1.0 / np.where(ok, pdf, 1.0), 0.0) / (2 * len(u))
    f = None
    if brdf is not None:
        # per strategy: the data's values on the cosine samples repeat from fit to fit (a
        # measured BRDF remembers its last direction sets)
        f = np.concatenate([np.asarray(brdf.eval(w, wo_v), dtype=np.float64) for w in (wi_s, wi_c)], axis=1)
        # directions where the data are garbage (NaN, infinite, negative) or unmeasured leave
        # both sides of the comparison, not only the data's (which would read them as black);
        # the mask on the same pairs as the values (a measured BRDF gives both from one lookup)
        measured = np.concatenate([measured_mask(brdf, w, wo_v) for w in (wi_s, wi_c)], axis=1)
        seen = np.all(np.isfinite(f) & (f >= 0), axis=-1) & measured
        if not np.all(seen):
            inv = np.where(seen, inv, 0.0)
    fid = np.asarray(ideal.eval_cos(wi, wo), dtype=np.float64)[..., 0] * inv
    # cos theta_d = o . h = sqrt((1 + i . o) / 2) for unit i, o (no half vector per sample)
    k0_s, t_s = _hats(np.sqrt(np.maximum(0.5 * (1.0 + dot(wi_s, wo_v)), 0.0)), n_d)
    k0, t = np.concatenate([k0_s, k0_c], axis=1), np.concatenate([t_s, t_c], axis=1)
    key = (k0 + n_d * np.arange(v_count)[:, None]).ravel()           # node k of view v: v n_d + k
    size = v_count * n_d
    a = np.zeros((v_count, n_d + 1))
    a[:, :n_d] = (np.bincount(key, weights=(fid * (1.0 - t)).ravel(), minlength=size)
                  + np.bincount(key + 1, weights=(fid * t).ravel(), minlength=size)).reshape(v_count, n_d)
    a[:, n_d] = np.sum(np.maximum(wi[..., 2], 0.0) / np.pi * inv, axis=1)
    if f is None:
        return a, None
    f = np.where(np.isfinite(f) & (f > 0), f * wi[..., 2:], 0.0) * inv[..., None]
    return a, f.sum(axis=1)


#: The cosine strategy of :func:`albedo_rows` per ``(n_u, views, n_d)``, which no fit changes.
_COSINE_STRATEGY: dict = {}


def _cosine_strategy(n_u: int, views, n_d: int):
    """``(u, wo, wi, pdf, k0, t)`` of :func:`albedo_rows`'s cosine-lobe strategy at ``views``,
    none of which depends on the fitted lobe: the stratified uniforms ``(n_u^2, 2)``, the
    views broadcast ``(V, n_u^2, 3)``, the sampled directions, their cosine density and the
    hats of their half vectors in the ``n_d`` nodes (computed once, then kept)."""
    from ..brdf import Lambertian
    from ..geometry import dot, half_vector
    views = np.asarray(views, dtype=np.float64)

    def make():
        g = (np.arange(n_u) + 0.5) / n_u
        u = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
        wo = np.broadcast_to(views[:, None, :], (len(views), len(u), 3))
        cosine = Lambertian(1.0)
        wi = cosine.sample(u, wo)[0]
        return _read_only(u, wo, wi, cosine.pdf(wi, wo), *_hats(dot(wo, half_vector(wi, wo)), n_d))
    return _kept(_COSINE_STRATEGY, (int(n_u), views.tobytes(), int(n_d)), make, size=8)


def extract_fresnel(brdf, ideal, n_d: int, n_h: int = 32, n_phi_d: int = 16, n_phi_h: int = 1,
                    diffuse: bool = False, isotropic: bool = False):
    """:func:`solve_fresnel` on :func:`fresnel_samples` of ``brdf`` (Eq. 4.11,
    Algorithm 2): a :class:`FresnelSolution`.

    Parameters
    ----------
    brdf : BRDF
        The material.
    ideal : BRDF
        The fitted microfacet BRDF with an ideal (``F = 1``) Fresnel term.
    n_d : int
        Nodes of the Fresnel table, uniform in ``theta_d``.
    n_h, n_phi_d, n_phi_h, isotropic
        The configurations (:func:`fresnel_samples`).
    diffuse : bool
        Solve a Lambertian base ``k_d`` too.

    Returns
    -------
    FresnelSolution

    References
    ----------
    Dupuy 2015, thesis, Eq. 4.11, Algorithm 2.

    Examples
    --------
    >>> import microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> sol = extract_fresnel(brdf, mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), n_d=6, n_h=8, n_phi_d=8)
    >>> sol.cos_theta_d.round(3), sol.rgb[:, 1].round(3)
    (array([0.   , 0.309, 0.588, 0.809, 0.951, 1.   ]), array([0.721, 0.186, 0.035, 0.042, 0.04 , 0.04 ]))
    """
    return solve_fresnel(fresnel_samples(brdf, n_d, n_h, n_phi_d, n_phi_h, isotropic), ideal, diffuse=diffuse)


#: Public names of the helpers that :mod:`microfacet.fit.analytic` and :mod:`microfacet.fit.fitted`
#: share (issue 27: no module imports another's private names).
kept, distribution_key, energy_constrained = _kept, _distribution_key, _energy_constrained
