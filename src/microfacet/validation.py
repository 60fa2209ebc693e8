"""Independent numerical checks of BRDF models (DESIGN.md's validation standard).

* :func:`integrate_hemisphere` / :func:`integrate_slopes`: quadrature over the hemisphere of
  normals done in slope space (``dw_h = cos^3 theta_h ds``) with nested Gauss-Legendre
  rules on ``s = centre + scale * tan(t)``. The outer line is aligned with a chosen
  direction and may stop at a cut ``p <= p0`` (where an integrand's clamp ``<k,h>+`` has
  its kink); each inner line is centred and scaled on the lobe's conditional centre and
  width, so sharp (alpha = 0.01), strongly correlated (|rho| = 0.9) and sheared lobes are
  resolved. Nothing here uses a model's own parameter maps.
* :func:`chi2_test`: Pearson chi-square goodness of fit of ``sample`` against ``pdf``, as
  Mitsuba 3's ``chi2.py`` and pbrt-v4's tests: histogram the sampled directions on a
  ``(cos theta, phi)`` grid of the upper hemisphere, integrate ``pdf`` over each cell
  (Gauss-Legendre, ``dw = d(cos theta) dphi``), pool the cells expecting fewer than 5
  samples, and add one cell for the samples that ``sample`` reports as failed (pdf 0),
  whose expected count is the mass the pdf leaves outside the hemisphere.
* :func:`core_report`: the largest errors of these checks on Beckmann and GGX over a grid of
  parameters (``microfacet validate``).
"""
from __future__ import annotations

import functools
import itertools
import time

import numpy as np
from scipy.stats import chi2 as chi2_dist

from .brdf import Lambertian, MicrofacetBRDF
from .distributions import GGX, Beckmann, SlopeDistribution
from .geometry import dot, reflect, slope_to_normal, spherical_to_cartesian

__all__ = ["integrate_slopes", "integrate_hemisphere", "lobe_shape", "chi2_test", "albedo", "core_report"]


@functools.lru_cache(maxsize=16)
def _gl(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on [-1, 1] (read-only; cached: ``leggauss`` solves an
    n x n eigenproblem, 87 % of a 160-point quadrature's time when recomputed)."""
    t, w = np.polynomial.legendre.leggauss(n)
    t.flags.writeable = w.flags.writeable = False
    return t, w


def lobe_shape(d: SlopeDistribution) -> tuple[np.ndarray, np.ndarray]:
    """Centre and shape matrix ``[[ax^2, rho ax ay], [rho ax ay, ay^2]]`` of a slope lobe.

    Parameters
    ----------
    d : SlopeDistribution
        The distribution.

    Returns
    -------
    centre : (2,) ndarray
        Mean slope.
    sigma : (2, 2) ndarray
        Shape matrix.

    Examples
    --------
    >>> import microfacet as mf
    >>> centre, shape = lobe_shape(mf.Beckmann(alpha_x=0.2, alpha_y=0.1, rho=0.5, mean_slope=(0.1, 0.0)))
    >>> centre, shape.round(4)
    (array([0.1, 0. ]), array([[0.04, 0.01],
           [0.01, 0.01]]))
    """
    ax, ay, rho = float(d.alpha_x), float(d.alpha_y), float(d.rho)
    sigma = np.array([[ax * ax, rho * ax * ay], [rho * ax * ay, ay * ay]])
    return np.array(d.mean_slope, dtype=float), sigma


def integrate_slopes(f, centre, sigma, direction=(1.0, 0.0), p0=np.inf, n=(256, 256)):
    """``int f(x, y) dx dy`` over the half plane ``p <= p0``, ``p = e . (s - 0)`` with
    ``e = direction / |direction|``; ``f`` takes and returns arrays.

    Parameters
    ----------
    f : callable
        ``f(x, y)`` over slope arrays.
    centre : (2,) array_like
        Centre of the lobe (its mean slope).
    sigma : (2, 2) array_like
        Shape matrix of the lobe (:func:`lobe_shape`).
    direction : (float, float)
        Normal ``e`` of the half plane's edge.
    p0 : float
        Edge position along ``e``; ``inf``: the whole plane.
    n : (int, int)
        Gauss-Legendre nodes across and along ``e``.

    Returns
    -------
    float
        The integral.

    Examples
    --------
    >>> import numpy as np
    >>> gauss = lambda x, y: np.exp(-(x**2 + y**2)) / np.pi          # the standard Beckmann slopes
    >>> round(integrate_slopes(gauss, (0.0, 0.0), np.eye(2) * 0.5), 10)
    1.0
    >>> round(integrate_slopes(gauss, (0.0, 0.0), np.eye(2) * 0.5, p0=0.0), 10)   # half of them
    0.5
    """
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


def integrate_hemisphere(g, d: SlopeDistribution, k=None, n=(256, 256)):
    """``int g(h) dw_h`` over upper normals, for integrands concentrated like ``d``'s lobe
    and, if ``k`` is given, vanishing where ``<k, h> <= 0``.

    Parameters
    ----------
    g : callable
        ``g(h)``, ``(..., 3)`` unit normals to values.
    d : SlopeDistribution
        The lobe the nodes follow.
    k : (3,) array_like, optional
        A direction; the integral is cut at ``<k, h> = 0``.
    n : (int, int)
        Quadrature nodes per slope axis.

    Returns
    -------
    float
        The integral.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> d = mf.GGX(alpha=0.3)
    >>> round(integrate_hemisphere(lambda h: d.ndf(h) * h[..., 2], d), 8)   # projected area, Eq. 2.8
    1.0
    """
    centre, sigma = lobe_shape(d)
    direction, p0 = (1.0, 0.0), np.inf
    if k is not None:
        k = np.asarray(k, float)
        r = np.hypot(k[0], k[1])
        if r > 1e-12:      # <k,h> > 0  <=>  x_k x + y_k y < z_k  in slope space
            direction, p0 = (k[0], k[1]), k[2] / r

    def f(x, y):
        h = slope_to_normal(x, y)
        return g(h) * h[..., 2] ** 3

    return integrate_slopes(f, centre, sigma, direction, p0, n)


def _cell_masses(pdf, wo, res):
    nt, nphi = res
    t, w = np.polynomial.legendre.leggauss(6)
    t, w = 0.5 * (t + 1), 0.5 * w
    mu = (np.arange(nt)[:, None] + t[None, :]) / nt                  # (nt, 6)
    phi = (np.arange(nphi)[:, None] + t[None, :]) / nphi * 2 * np.pi - np.pi
    MU = mu[:, None, :, None]
    PHI = phi[None, :, None, :]
    s = np.sqrt(np.maximum(0.0, 1 - MU * MU))
    wi = np.stack(np.broadcast_arrays(s * np.cos(PHI), s * np.sin(PHI), MU), axis=-1)
    p = pdf(wi, np.broadcast_to(wo, wi.shape))
    weights = w[:, None] * w[None, :] / nt * (2 * np.pi / nphi)
    return np.sum(p * weights, axis=(-2, -1))                         # (nt, nphi)


def chi2_test(brdf, wo, n=400_000, res=(32, 64), seed=0):
    """Chi-square test of ``brdf.sample`` from ``wo``: ``(p_value, statistic, dof, integral_of_pdf)``.

    Parameters
    ----------
    brdf : BRDF
        The BRDF whose sampler is tested.
    wo : (3,) array_like
        Unit view direction.
    n : int
        Samples.
    res : (int, int)
        Histogram bins in ``cos theta`` and ``phi``.
    seed : int
        Random seed.

    Returns
    -------
    p_value : float
        Chi-square p-value.
    statistic : float
        The statistic.
    dof : int
        Degrees of freedom.
    integral_of_pdf : float
        Integral of ``pdf`` over the sphere (1 for a sampler that never fails).

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> p_value, stat, dof, integral = chi2_test(mf.MicrofacetBRDF(mf.GGX(alpha=0.4)),
    ...                                          np.array([0.5, 0.0, np.sqrt(0.75)]), n=50_000, res=(16, 32))
    >>> p_value > 0.01, round(integral, 3)                      # sampler matches its pdf, pdf integrates to 1
    (True, np.float64(0.862))
    """
    rng = np.random.default_rng(seed)
    wi, weight, pdf = brdf.sample(rng.random((n, 2)), np.broadcast_to(wo, (n, 3)))
    ok = pdf > 0
    mu = np.clip(wi[ok, 2], 0, 1 - 1e-16)
    phi = np.arctan2(wi[ok, 1], wi[ok, 0])
    i = np.minimum((mu * res[0]).astype(int), res[0] - 1)
    j = np.minimum(((phi + np.pi) / (2 * np.pi) * res[1]).astype(int), res[1] - 1)
    observed = np.bincount(i * res[1] + j, minlength=res[0] * res[1]).astype(float)
    mass = _cell_masses(brdf.pdf, wo, res).ravel()
    total = mass.sum()
    observed = np.append(observed, n - ok.sum())
    expected = np.append(mass, max(0.0, 1.0 - total)) * n
    order = np.argsort(expected)
    obs, exp = observed[order], expected[order]
    # pool the smallest cells together until the pool expects >= 5
    cum = np.cumsum(exp)
    k = np.searchsorted(cum, 5.0)
    if k < len(exp):
        obs = np.append(obs[k + 1:], obs[: k + 1].sum())
        exp = np.append(exp[k + 1:], exp[: k + 1].sum())
    keep = exp > 0
    if np.any(obs[~keep] > 0):
        return 0.0, np.inf, 0, total           # samples where the pdf says none can be
    obs, exp = obs[keep], exp[keep]
    stat = float(np.sum((obs - exp) ** 2 / exp))
    dof = len(obs) - 1
    if dof == 0:                               # a single pooled cell: all or nothing
        return float(stat == 0), stat, dof, total
    return float(chi2_dist.sf(stat, dof)), stat, dof, total


def albedo(brdf: MicrofacetBRDF, wo, n=(200, 200)) -> float:
    """Directional albedo ``int f_r cos theta_i dw_i = int f_r(i(h), o) cos theta_i 4 (o.h) dw_h``
    (first channel), by slope-space quadrature around the BRDF's lobe.

    Parameters
    ----------
    brdf : MicrofacetBRDF
        The BRDF.
    wo : (3,) array_like
        Unit view direction.
    n : (int, int)
        Quadrature nodes per slope axis.

    Returns
    -------
    float
        The albedo of the first channel.

    Examples
    --------
    >>> import microfacet as mf
    >>> brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    >>> round(albedo(brdf, [0.0, 0.0, 1.0]), 4)                 # F = 1: the energy single scattering keeps
    0.8774
    """
    wo = np.asarray(wo, dtype=np.float64)

    def g(h):
        wi = reflect(wo, h)
        return brdf.eval_cos(wi, np.broadcast_to(wo, wi.shape))[..., 0] * 4 * np.maximum(dot(wo, h), 0)
    return integrate_hemisphere(g, brdf.distribution, k=wo, n=n)


#: alpha from 1e-2 to 2, |rho| up to 0.9, mean slopes up to 1 (issue 2's grid)
PARAMETER_GRID = [dict(alpha_x=ax, alpha_y=ay, rho=rho, mean_slope=ms)
                  for (ax, ay), rho, ms in itertools.product(
                      [(0.01, 0.01), (0.02, 0.2), (0.3, 0.3), (1.0, 0.4), (2.0, 2.0)],
                      [0.0, 0.9, -0.6], [(0.0, 0.0), (1.0, 0.0), (-0.6, 0.8)])]
#: isotropic, anisotropic, correlated, sheared, all at once (sampling tests)
SURFACES = {"iso": dict(alpha=0.4), "aniso": dict(alpha_x=0.15, alpha_y=0.6),
            "corr": dict(alpha_x=0.3, alpha_y=0.5, rho=0.7),
            "shear": dict(alpha=0.3, mean_slope=(0.4, -0.3)),
            "all": dict(alpha_x=0.5, alpha_y=0.2, rho=-0.5, mean_slope=(-0.3, 0.5))}


def sampled_albedo(brdf, sampler, theta_o: float, n: int = 128) -> np.ndarray:
    """Directional albedo ``int f(i, o) cos theta_i d i`` (Eq. 1.8), RGB, of any BRDF-like
    ``brdf`` (measured data too) at ``o = (theta_o, phi = 0)``: ``sampler``'s ``sample``/``pdf``
    and the cosine lobe, each on a stratified ``n x n`` grid, balance heuristic (MIS);
    non-finite or negative values of ``brdf`` count as 0."""
    g = (np.arange(n) + 0.5) / n
    u = np.stack(np.meshgrid(g, g, indexing="ij"), axis=-1).reshape(-1, 2)
    wo = np.broadcast_to([np.sin(theta_o), 0.0, np.cos(theta_o)], (len(u), 3))
    cosine = Lambertian(1.0)
    wi = np.concatenate([sampler.sample(u, wo)[0], cosine.sample(u, wo)[0]])
    wo = np.concatenate([wo, wo])
    pdf = 0.5 * sampler.pdf(wi, wo) + 0.5 * cosine.pdf(wi, wo)
    ok = (pdf > 0) & (wi[:, 2] > 0)
    f = np.asarray(brdf.eval(wi, wo), dtype=np.float64) * wi[:, 2:]
    f = np.where(ok[:, None] & np.isfinite(f) & (f > 0), f, 0.0)
    return np.sum(f / np.where(ok, pdf, 1.0)[:, None], axis=0) / len(wi)


def _upper(rng, n):
    w = rng.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    w[:, 2] = np.abs(w[:, 2])
    return w


def _visible(d, k):
    return d._warp(k)[2] > 0


def core_report(quick: bool = False, progress=None) -> list[dict]:
    """Largest errors of the core checks for Beckmann and GGX: one row per check with
    ``check, distribution, cases, worst, bound, ok`` (the bound the test suite asserts);
    ``progress`` is called after each parameter set.

    Parameters
    ----------
    quick : bool
        Fewer parameter sets.
    progress : callable, optional
        Called after each parameter set.

    Returns
    -------
    list of dict
        One row per check.

    Examples
    --------
    >>> rows = core_report(quick=True)                               # doctest: +SKIP
    >>> all(row["ok"] for row in rows)                               # doctest: +SKIP
    """
    grid = PARAMETER_GRID[::7] if quick else PARAMETER_GRID
    views = [spherical_to_cartesian(np.radians(t), p) for t, p in [(0, 0), (45, 0.3), (75, 2.0), (89, -1.2)]]
    quad = (120, 120) if quick else (160, 160)
    rows = []
    tick = progress or (lambda: None)
    for D in (Beckmann, GGX):
        name = D.__name__
        t0 = time.perf_counter()
        norm, vis, g1, n_vis = 0.0, 0.0, 0.0, 0
        for params in grid:
            d = D(**params)
            norm = max(norm, abs(integrate_hemisphere(lambda h: d.ndf(h) * h[..., 2], d, n=quad) - 1))
            for k in views:
                if not _visible(d, k):
                    continue
                n_vis += 1
                vis = max(vis, abs(integrate_hemisphere(lambda h: d.vndf(h, k), d, k, n=quad) - 1))
                area = integrate_hemisphere(lambda h: np.maximum(dot(k, h), 0) * d.ndf(h), d, k, n=quad)
                g1 = max(g1, abs(k[2] / area / d.g1(k) - 1))
            tick()
        rows += [dict(check="projected area = 1 (Eq. 2.8, 3.1)", distribution=name, cases=len(grid), worst=norm, bound=1e-10),
                 dict(check="visible NDF integrates to 1 (Eq. 2.17)", distribution=name, cases=n_vis, worst=vis, bound=1e-10),
                 dict(check="G1 vs direct integral of Eq. 2.14 (rel.)", distribution=name, cases=n_vis, worst=g1, bound=1e-10)]
        # white furnace, central and sheared
        rng = np.random.default_rng(8)
        top, mc_dev = -np.inf, 0.0
        furnace = [dict(alpha=0.01), dict(alpha=0.3), dict(alpha_x=0.1, alpha_y=1.0, rho=0.5), dict(alpha=2.0),
                   dict(alpha=0.01, mean_slope=(0.3, 0.0)), dict(alpha=0.3, mean_slope=(0.8, -0.5))]
        for kw in furnace[::2] if quick else furnace:
            brdf = MicrofacetBRDF(D(**kw))
            for theta in (0.0, 1.0, 1.45):
                wo = spherical_to_cartesian(theta, 0.4 + np.pi * (theta > 1.2))
                if not _visible(brdf.distribution, wo):
                    continue
                a = albedo(brdf, wo)
                _, w, _ = brdf.sample(rng.random((100_000, 2)), wo)
                top = max(top, a - 1.0)
                mc_dev = max(mc_dev, abs(w[:, 0].mean() - a) / (5 * w[:, 0].std() / np.sqrt(len(w)) + 1e-9))
            tick()
        rows += [dict(check="white furnace: max(albedo) - 1", distribution=name, cases=len(furnace), worst=top, bound=1e-9),
                 dict(check="furnace: |mean(weight) - albedo| / (5 sigma + 1e-9)", distribution=name, cases=len(furnace),
                      worst=mc_dev, bound=1.0)]
        # sampling: chi-square, weight consistency, reciprocity
        pmin, n_chi2, wrel, rrel = 1.0, 0, 0.0, 0.0
        for sname, kw in SURFACES.items():
            brdf = MicrofacetBRDF(D(**kw))
            for theta in (0, 60, 85):
                p, *_ = chi2_test(brdf, spherical_to_cartesian(np.radians(theta), 0.7),
                                  n=100_000 if quick else 400_000, seed=theta)
                pmin, n_chi2 = min(pmin, p), n_chi2 + 1
            wo = _upper(rng, 20_000)
            wi, weight, pdf = brdf.sample(rng.random((20_000, 2)), wo)
            ok = pdf > 0
            ref = brdf.eval_cos(wi[ok], wo[ok]) / pdf[ok, None]
            wrel = max(wrel, float(np.max(np.abs(weight[ok] - ref) / np.maximum(ref, 1e-300))))
            wi, wo = _upper(rng, 20_000), _upper(rng, 20_000)
            d = brdf.distribution
            a = brdf.eval(wi, wo)[:, 0] * wi[:, 2] * d._warp(wo)[2]
            b = brdf.eval(wo, wi)[:, 0] * wo[:, 2] * d._warp(wi)[2]
            rrel = max(rrel, float(np.max(np.abs(a - b) / np.maximum(np.abs(a), 1e-300))))
            tick()
        rows += [dict(check="chi-square of sample vs pdf: min p-value", distribution=name, cases=n_chi2, worst=pmin, bound=1e-3),
                 dict(check="weight vs eval_cos / pdf (rel.)", distribution=name, cases=len(SURFACES), worst=wrel, bound=1e-10),
                 dict(check="reciprocity f(i,o) z_i c_o = f(o,i) z_o c_i (rel.)", distribution=name, cases=len(SURFACES), worst=rrel, bound=1e-12)]
        for r in rows[-8:]:
            r["seconds"] = time.perf_counter() - t0
            r["ok"] = r["worst"] >= r["bound"] if "p-value" in r["check"] else r["worst"] <= r["bound"]
    return rows


def format_report(rows: list[dict]) -> str:
    """Markdown table of :func:`core_report` rows."""
    lines = ["| check | distribution | cases | worst | test bound | ok |", "|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['check']} | {r['distribution']} | {r['cases']} | {r['worst']:.3g} | {r['bound']:.3g} "
                     f"| {'yes' if r['ok'] else 'NO'} |")
    return "\n".join(lines) + "\n"
