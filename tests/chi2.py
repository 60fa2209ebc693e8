"""Pearson chi-square goodness-of-fit of a BRDF's ``sample`` against its ``pdf``.

As Mitsuba 3's ``chi2.py`` and pbrt-v4's tests: histogram the sampled directions on a
``(cos theta, phi)`` grid of the upper hemisphere, integrate ``pdf`` over each cell
(Gauss-Legendre, ``dw = d(cos theta) dphi``), pool cells whose expected count is below 5,
and add one cell for the samples that ``sample`` reports as failed (pdf 0), whose
expected count is the mass the pdf leaves outside the hemisphere.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2 as chi2_dist


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
    """Returns ``(p_value, statistic, dof, integral_of_pdf)``."""
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
