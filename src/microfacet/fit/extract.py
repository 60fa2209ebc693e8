"""Extraction of the microfacet terms of a BRDF from its values (thesis Ch. 4.2).

The slope distribution comes from backscattering (``i = o = h``, Eq. 4.1-4.3): with the
Smith GAF it is the Perron eigenvector of the discretized Fredholm equation (Eq. 4.5-4.9,
isotropic form Eq. 4.12-4.15), found by power iterations (Algorithms 1 and 3); with the
V-groove and normal-map GAFs it is explicit (Eq. 4.16-4.18). The Fresnel term is the
average ratio of the BRDF to the fitted ideal-mirror BRDF at each ``theta_d`` (Eq. 4.11,
Algorithm 2).

The NDF is recovered at the nodes of :func:`theta_grid` (and azimuths ``2 pi k / m``).
The grazing node ``theta = pi/2``, where backscattering is not measurable (an input may
return garbage there), takes the value of its neighbour (constant extrapolation, which
keeps the eigenproblem linear and nonnegative).
"""
from __future__ import annotations

import numpy as np

from ..distributions.tabulated import HALF_PI, hat_weights
from ..errors import MicrofacetError
from ..geometry import hd_to_io

__all__ = ["backscattering", "luminance", "smith_kernel_isotropic", "smith_kernel_anisotropic",
           "power_iteration", "rule_area_at_normal", "ndf_closed_form", "extract_fresnel"]

#: Rec. 709 luminance weights
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance of RGB values ``(..., 3)``."""
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def _clean(values) -> np.ndarray:
    """Nonfinite or negative BRDF values (garbage at grazing angles) become 0."""
    v = np.asarray(values, dtype=np.float64)
    return np.where(np.isfinite(v) & (v > 0), v, 0.0)


def _directions(theta, phi) -> np.ndarray:
    s = np.sin(theta)
    return np.stack(np.broadcast_arrays(s * np.cos(phi), s * np.sin(phi), np.cos(theta)), axis=-1)


def backscattering(brdf, theta, phi=0.0) -> np.ndarray:
    """Luminance of ``f_r(o, o)`` at ``o = (theta, phi)``, garbage set to 0 (Eq. 4.1)."""
    o = _directions(theta, phi)
    return _clean(luminance(_clean(brdf.eval(o, o))))


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


def projected_area_matrix_isotropic(theta: np.ndarray, theta_o: np.ndarray, order: int = 8) -> np.ndarray:
    """``M[i, j]`` with ``A(o_i) = int <o_i,h>+ D(h) dw_h = sum_j M[i, j] D_j`` for ``D``
    linear in ``theta`` between the nodes ``theta`` (product integration: Gauss-Legendre of
    ``order`` points per interval of ``hat_j(theta) E(theta_o, theta) sin theta``)."""
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


def smith_kernel_isotropic(f_back: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Matrix ``K'`` of Eq. 4.15 for the unknowns ``D(theta_0..theta_{n-2})``:
    ``F0 D(o) = 4 f_r(o, o) cos theta_o A(o)`` (Eq. 4.4-4.6 written for ``D = P / cos^4``;
    a similarity transform of the ``P`` form, same eigenvector), the grazing node folded
    onto its neighbour."""
    m = projected_area_matrix_isotropic(theta, theta[:-1])
    m[:, -2] += m[:, -1]
    return (4.0 * f_back * np.cos(theta[:-1]))[:, None] * m[:, :-1]


def smith_kernel_anisotropic(f_back: np.ndarray, theta: np.ndarray, phi: np.ndarray,
                             dtype=np.float32) -> np.ndarray:
    """Matrix ``K`` of Eq. 4.8 over the nodes ``(theta_i, phi_j)``, ``i < n - 1``
    (row-major), with ``A(o) = sum_n w_n <o, h_n>+ D_n``, ``w_n = int int hat_n sin dtheta
    dphi`` (node rule), the grazing row folded onto its neighbour. ``f_back`` is
    ``(n - 1, m)``."""
    n, m = len(theta), len(phi)
    dirs = _directions(theta[:, None], phi[None, :])                  # (n, m, 3)
    o = dirs[:-1].reshape(-1, 3).astype(dtype)
    w = hat_weights(theta, np.sin) * (2.0 * np.pi / m)
    k = o @ o.T                                                       # h nodes = o nodes (folded)
    np.maximum(k, 0.0, out=k)
    last = np.maximum(o @ dirs[-1].reshape(-1, 3).astype(dtype).T, 0.0)   # (rows, m) grazing column
    wcol = np.repeat(w[:-1], m).astype(dtype)
    k *= wcol[None, :]
    k[:, -m:] += last * dtype(w[-1])
    k *= (4.0 * f_back.ravel() * np.repeat(np.cos(theta[:-1]), m)).astype(dtype)[:, None]
    return k


def rule_area_at_normal(dist) -> float:
    """``A(z) = int cos theta D dw`` of the normalized table ``dist`` by the kernel's rule
    (1 for an exact rule): the eigenvalue of the discrete kernel divided by it is ``F0``
    (Eq. 4.9) for the exactly normalized ``D``."""
    d = dist.ndf_table
    if d.ndim == 1:
        return float(projected_area_matrix_isotropic(dist.theta, np.zeros(1))[0] @ d)
    w = hat_weights(dist.theta, np.sin) * (2.0 * np.pi / d.shape[1])
    return float(np.sum(w[:, None] * np.cos(dist.theta)[:, None] * d))


def power_iteration(k: np.ndarray, tol: float = 1e-10, max_iter: int = 1000):
    """Perron eigenvector and eigenvalue of the nonnegative matrix ``k`` (Eq. 4.9):
    ``p <- K p / |K p|`` from ``p = 1`` until the relative change is below ``tol``
    (Algorithms 1 and 3 use four iterations; we iterate to convergence). The matrix may
    be float32 (anisotropic kernels); the iterate is kept in float64."""
    p = np.full(k.shape[0], 1.0 / k.shape[0])
    lam = 0.0
    for it in range(1, max_iter + 1):
        q = np.asarray(k @ p.astype(k.dtype), dtype=np.float64)
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
    (Eq. 4.18). ``theta`` broadcasts against ``f_back``."""
    if gaf == "vgroove":
        return 4.0 * f_back * np.maximum(np.cos(theta) ** 2, 0.5)
    if gaf == "normal_map":
        return 4.0 * f_back
    raise ValueError(f"no closed form for gaf {gaf!r}")


# ---------------------------------------------------------------------- Fresnel
def extract_fresnel(brdf, ideal, n_d: int, n_h: int = 32, n_phi_d: int = 16, n_phi_h: int = 1):
    """Fresnel table ``F(theta_d)`` per RGB channel (Eq. 4.11, Algorithm 2).

    For each ``theta_d`` of a uniform grid of ``n_d`` nodes on ``[0, pi/2]``, the ratio of
    the input BRDF to the fitted ideal-mirror BRDF ``ideal`` (Eq. 4.10) is averaged over
    ``theta_h`` (nodes ``((k + 1/2) / n_h)^2 pi/2``, dense where lobes are), ``phi_d`` and
    ``phi_h`` (uniform), weighted by ``f_id``: ``F = sum f / sum f_id``, the ``f_id``-weighted
    mean of ``f / f_id``. This equals Eq. 4.11 when the ratio is constant in the average,
    and keeps near-zero ``f_id`` (tails, grazing garbage) from dominating it. Nodes without
    any valid configuration take the value of the nearest valid one.

    Returns ``(cos_theta_d, rgb)`` with increasing ``cos_theta_d``.
    """
    theta_d = np.linspace(0.0, HALF_PI, n_d)
    theta_h = ((np.arange(n_h) + 0.5) / n_h) ** 2 * HALF_PI
    phi_d = (np.arange(n_phi_d) + 0.5) * (2.0 * np.pi / n_phi_d)
    phi_h = np.arange(n_phi_h) * (2.0 * np.pi / n_phi_h)
    TD, TH, PH, PD = np.meshgrid(theta_d, theta_h, phi_h, phi_d, indexing="ij")
    h = _directions(TH, PH)
    d = _directions(TD, PD)
    wi, wo = hd_to_io(h, d)
    f = np.asarray(brdf.eval(wi, wo), dtype=np.float64)
    f_id = np.asarray(ideal.eval(wi, wo), dtype=np.float64)[..., 0]
    ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (f_id > 0) & np.all(np.isfinite(f), axis=-1)
    f = np.where(ok[..., None], np.maximum(np.nan_to_num(f), 0.0), 0.0)
    num = f.reshape(n_d, -1, 3).sum(axis=1)
    den = np.where(ok, f_id, 0.0).reshape(n_d, -1).sum(axis=1)
    valid = den > 0
    if not np.any(valid):
        raise MicrofacetError("fit: no configuration to extract the Fresnel term from")
    rgb = np.empty((n_d, 3))
    for c in range(3):
        rgb[:, c] = np.interp(theta_d, theta_d[valid], num[valid, c] / den[valid])
    return np.cos(theta_d)[::-1].copy(), rgb[::-1].copy()
