"""Error metrics between a reference BRDF (usually measured) and a fit.

* :func:`fit_error` — relative RMS of ``f_r cos theta_i`` over a fixed set of direction
  pairs (:func:`measurement_directions`), the error table of fitting reports;
* :func:`ndf_error` — relative L2 difference of ``D cos theta_h`` over the hemisphere
  between two NDFs (e.g. a fit's and the ``ndf`` field of an RGL file).

Direction pairs lie on a grid of the MERL (Rusinkiewicz) parameterization
``(theta_h, theta_d, phi_d)``, ``theta_h = (i / n)^2 pi / 2`` dense near the normal where
specular lobes live, so every sample weighs as one measured MERL sample does (the RMS
of Ngan et al. 2005, weighted by ``cos theta_i``). Samples where either direction grazes
the horizon (``cos theta_i`` or ``cos theta_o < 0.1``, i.e. beyond 84.3 deg) are
excluded: measured data are unreliable there (and huge in the neural-fit MERL files of
``../shared/data``). For a reference with a ``coverage(wi, wo)`` method (MERL), pairs
whose interpolation touches unmeasured samples (coverage < 1) are excluded too.
"""
from __future__ import annotations

import numpy as np

from .geometry import hd_to_io, spherical_to_cartesian

__all__ = ["GRAZING_COS", "measurement_directions", "fit_error", "ndf_error", "hemisphere_grid",
           "describe_fit_error"]

#: Pairs with ``cos theta_i`` or ``cos theta_o`` below this are excluded (grazing).
GRAZING_COS = 0.1
_GOLDEN = 0.5 * (np.sqrt(5.0) - 1.0)


def describe_fit_error(n: int = 32) -> str:
    """One sentence saying what :func:`fit_error` measures (for reports and JSON)."""
    return (f"relative RMS of f_r cos(theta_i) (RGB) over a {n}^3 grid of MERL coordinates "
            f"(theta_h, theta_d, phi_d), theta_h quadratic; pairs with cos(theta_i) or cos(theta_o) "
            f"< {GRAZING_COS:g} (grazing) and, for MERL, pairs touching unmeasured samples excluded")


def measurement_directions(n: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """Light/view pairs ``(wi, wo)``, each ``(M, 3)``, on an ``n^3`` grid of MERL coordinates.

    ``theta_h = ((i + 1/2) / n)^2 pi / 2``, ``theta_d = (j + 1/2) / n pi / 2`` and
    ``phi_d = (k + 1/2) / n pi`` (cell centres of the MERL parameterization), with the
    half-vector azimuth ``phi_h`` following the golden-ratio sequence so that anisotropic
    materials are probed at all azimuths. Pairs with either cosine below
    :data:`GRAZING_COS` are dropped. Deterministic.
    """
    c = (np.arange(n) + 0.5) / n
    th, td, pd = np.meshgrid(c * c * (np.pi / 2), c * (np.pi / 2), c * np.pi, indexing="ij")
    ph = 2.0 * np.pi * np.mod(np.arange(th.size) * _GOLDEN, 1.0).reshape(th.shape)
    wi, wo = hd_to_io(spherical_to_cartesian(th, ph), spherical_to_cartesian(td, pd))
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    keep = (wi[:, 2] >= GRAZING_COS) & (wo[:, 2] >= GRAZING_COS)
    return wi[keep], wo[keep]


def _measured(reference, wi, wo) -> np.ndarray:
    """Mask of pairs where ``reference`` rests on measured data only (MERL coverage)."""
    coverage = getattr(reference, "coverage", None)
    if coverage is None:
        return np.ones(len(wi), dtype=bool)
    return np.asarray(coverage(wi, wo)) >= 1.0 - 1e-9


def fit_error(reference, fits, n: int = 32, directions=None) -> dict[str, float]:
    """Relative RMS error of ``f_r cos theta_i`` of each fit against ``reference``.

    ``e = sqrt(sum |f_fit cos - f_ref cos|^2 / sum |f_ref cos|^2)`` over the RGB channels
    and the pairs of :func:`measurement_directions` (grazing pairs excluded, and for a
    MERL reference the pairs touching unmeasured samples).

    Parameters
    ----------
    reference : BRDF
        The data (measured or analytic).
    fits : BRDF or dict of str -> BRDF
        One fit, or several by name.
    n : int
        Grid size per MERL coordinate (``n^3`` pairs before exclusions).
    directions : (wi, wo), optional
        Use these pairs instead of the grid (still filtered by grazing and coverage).

    Returns
    -------
    dict of str -> float
        Error per fit name (``"fit"`` for a single BRDF), plus ``"n_pairs"``, the number
        of pairs used.
    """
    wi, wo = measurement_directions(n) if directions is None else directions
    wi, wo = np.broadcast_arrays(np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64))
    wi, wo = wi.reshape(-1, 3), wo.reshape(-1, 3)
    keep = (wi[:, 2] >= GRAZING_COS) & (wo[:, 2] >= GRAZING_COS)
    keep[keep] = _measured(reference, wi[keep], wo[keep])
    wi, wo = wi[keep], wo[keep]
    if len(wi) == 0:
        raise ValueError("no measured, non-grazing direction pairs to compare")
    ref = reference.eval_cos(wi, wo)
    norm = float(np.sqrt(np.sum(ref * ref)))
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError("the reference BRDF is zero or not finite on the compared directions")
    named = fits if isinstance(fits, dict) else {"fit": fits}
    out = {name: float(np.sqrt(np.sum((brdf.eval_cos(wi, wo) - ref) ** 2)) / norm)
           for name, brdf in named.items()}
    out["n_pairs"] = int(len(wi))
    return out


def hemisphere_grid(n_theta: int = 128, n_phi: int = 128) -> tuple[np.ndarray, np.ndarray]:
    """Midpoint quadrature over the upper hemisphere: directions ``(n_theta * n_phi, 3)``
    and solid-angle weights, ``theta = u^2 pi / 2`` (dense near the normal), so that
    ``sum w g(h) ~= int g dw`` for smooth or sharp-at-the-pole ``g``."""
    u = (np.arange(n_theta) + 0.5) / n_theta
    theta = u * u * (np.pi / 2)
    dtheta = u * np.pi / n_theta                    # d theta / du * du
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    w = (np.sin(theta) * dtheta)[:, None] * np.full(n_phi, 2.0 * np.pi / n_phi)
    return spherical_to_cartesian(t, p).reshape(-1, 3), w.reshape(-1)


def ndf_error(ndf_ref, ndf_fit, n_theta: int = 128, n_phi: int = 128) -> dict[str, float]:
    """Relative L2 difference of ``D cos theta_h`` over the hemisphere.

    Both NDFs (callables ``h (N, 3) -> (N,)``) are first normalized to projected area 1
    (``int D cos theta_h dw_h = 1``, Eq. 2.8), so only their shapes are compared:
    ``e = ||D_fit cos - D_ref cos||_2 / ||D_ref cos||_2`` (solid-angle measure).

    Returns ``{"l2": e, "area_ref": ..., "area_fit": ...}`` where the areas are the
    projected areas before normalization (1 for a normalized NDF).
    """
    h, w = hemisphere_grid(n_theta, n_phi)
    cos = h[:, 2]
    dr = np.asarray(ndf_ref(h), dtype=np.float64) * cos
    df = np.asarray(ndf_fit(h), dtype=np.float64) * cos
    area_ref, area_fit = float(np.sum(w * dr)), float(np.sum(w * df))
    if not (area_ref > 0 and area_fit > 0 and np.isfinite(area_ref) and np.isfinite(area_fit)):
        raise ValueError(f"NDFs must have a positive finite projected area, got {area_ref}, {area_fit}")
    dr, df = dr / area_ref, df / area_fit
    e = float(np.sqrt(np.sum(w * (df - dr) ** 2) / np.sum(w * dr * dr)))
    return {"l2": e, "area_ref": area_ref, "area_fit": area_fit}
