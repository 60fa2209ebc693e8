"""Independent numerical integration over the slope plane, for validation tests.

Integrals over the hemisphere of normals are done in slope space
(``dw_h = cos^3 theta_h ds``) with nested Gauss-Legendre rules on
``s = centre + scale * tan(t)``: the outer line is aligned with a chosen direction and
may stop at a cut ``p <= p0`` (where an integrand's clamp ``<k,h>+`` has its kink), and
each inner line is centred and scaled on the lobe's conditional centre and width, so that
sharp (alpha = 0.01), strongly correlated (|rho| = 0.9) and sheared lobes are resolved.
Nothing here uses the library's own parameter maps.
"""
from __future__ import annotations

import numpy as np

import microfacet as mf


def _gl(n: int):
    t, w = np.polynomial.legendre.leggauss(n)
    return t, w


def lobe_shape(d: mf.SlopeDistribution) -> tuple[np.ndarray, np.ndarray]:
    """Centre and shape matrix ``[[ax^2, rho ax ay], [rho ax ay, ay^2]]`` of a slope lobe."""
    ax, ay, rho = float(d.alpha_x), float(d.alpha_y), float(d.rho)
    sigma = np.array([[ax * ax, rho * ax * ay], [rho * ax * ay, ay * ay]])
    return np.array(d.mean_slope, dtype=float), sigma


def integrate_slopes(f, centre, sigma, direction=(1.0, 0.0), p0=np.inf, n=(256, 256)):
    """``int f(x, y) dx dy`` over the half plane ``p <= p0``, ``p = e . (s - 0)`` with
    ``e = direction / |direction|``; ``f`` takes and returns arrays."""
    e = np.asarray(direction, float) / np.hypot(*direction)
    q_dir = np.array([-e[1], e[0]])
    basis = np.stack([e, q_dir])                       # rows: p and q axes
    s_pq = basis @ sigma @ basis.T
    mu_p, mu_q = basis @ centre
    lp = np.sqrt(s_pq[0, 0])
    hi = np.arctan((p0 - mu_p) / lp) if np.isfinite(p0) else np.pi / 2
    tp, wp = _gl(n[0])
    th_p = -np.pi / 2 + (hi + np.pi / 2) * (tp + 1) / 2   # [-1, 1] -> [-pi/2, hi]
    wp = wp * (hi + np.pi / 2) / 2
    p = mu_p + lp * np.tan(th_p)
    jp = lp / np.cos(th_p) ** 2
    # inner lines: conditional centre and width of the lobe along q at fixed p
    cq = mu_q + s_pq[0, 1] / s_pq[0, 0] * (p - mu_p)
    lq = np.sqrt(max(s_pq[1, 1] - s_pq[0, 1] ** 2 / s_pq[0, 0], 1e-300))
    lq = lq * np.sqrt(1.0 + ((p - mu_p) / lp) ** 2)     # wider far in the tails
    tq, wq = _gl(n[1])
    th_q = np.pi / 2 * tq
    wq = wq * np.pi / 2
    q = cq[:, None] + lq[:, None] * np.tan(th_q)[None, :]
    jq = lq[:, None] / np.cos(th_q)[None, :] ** 2
    xy = p[:, None, None] * e + q[..., None] * q_dir
    vals = f(xy[..., 0], xy[..., 1])
    return float(np.sum(vals * jq * wq[None, :] * (jp * wp)[:, None]))


def integrate_hemisphere(g, d: mf.SlopeDistribution, k=None, n=(256, 256)):
    """``int g(h) dw_h`` over upper normals, for integrands concentrated like ``d``'s lobe
    and, if ``k`` is given, vanishing where ``<k, h> <= 0``."""
    centre, sigma = lobe_shape(d)
    direction, p0 = (1.0, 0.0), np.inf
    if k is not None:
        k = np.asarray(k, float)
        r = np.hypot(k[0], k[1])
        if r > 1e-12:      # <k,h> > 0  <=>  x_k x + y_k y < z_k  in slope space
            direction, p0 = (k[0], k[1]), k[2] / r

    def f(x, y):
        h = mf.geometry.slope_to_normal(x, y)
        return g(h) * h[..., 2] ** 3

    return integrate_slopes(f, centre, sigma, direction, p0, n)
