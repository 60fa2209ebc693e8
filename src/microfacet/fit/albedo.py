"""A fit's directional albedo matched to the data's by a smooth table in ``theta_d``.

A fit made in a compressed space (:mod:`microfacet.fit.perceptual`) weighs the specular
peak little: its shape can be right while the energy it reflects at grazing views falls
short of the data's (a plastic's or paint's albedo stays flat or rises with the view, the
fit's falls with its body's transmission). :func:`match_albedo` multiplies the Fresnel term
of every microfacet lobe by one smooth non-negative factor per channel ``s(theta_d)``,

    f'(i, o) = f(i, o) + (s(theta_d) - 1) f_spec(i, o),

chosen so that the directional albedo ``a(o) = int f' cos theta_i d i`` (Eq. 1.8) of the
fit equals the data's at views :data:`VIEWS_DEG`. The albedo is linear in ``s``: with
``s`` piecewise linear on :data:`NODES_DEG` (hat functions ``h_k``),

    a'(o) = a(o) + sum_k (s_k - 1) int h_k(theta_d) f_spec cos theta_i d i,

so ``s`` is the bounded linear least squares (:func:`~microfacet.fit.extract.box_qp`) of the
relative albedo residuals, with a second-difference smoothness penalty
(:data:`SMOOTHNESS`) and a weak pull toward 1. A specular lobe's energy at view
``theta_o`` comes from ``theta_d`` near ``theta_o`` (the mirror configuration), which is
why a table in ``theta_d`` reaches the albedo at each view without changing the lobes'
shape. The product ``F s`` becomes each lobe's :class:`~microfacet.fresnel.Tabulated`
Fresnel term (clipped to ``[0, 1]``): the result is a BRDF of the same tree, which specs,
fit files, the Mitsuba plugins and the exports read as any other.

Accuracy: on the fit corpus the albedo is matched to a few percent at 0-75 deg wherever the
lobes carry enough energy at the view (a lobe-free Lambertian fit is returned unchanged).

Example
-------
>>> import microfacet as mf
>>> data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.08)), mf.Lambertian(0.3))
>>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
>>> matched = match_albedo(data, fit)
>>> ratios = mf.metrics.albedo_ratios(data, matched, views_deg=(0.0, 60.0))
>>> bool(abs(ratios - 1.0).max() < 0.01)
True
"""
from __future__ import annotations

import numpy as np

from ..metrics import AlbedoRatios
from .extract import box_qp

__all__ = ["VIEWS_DEG", "NODES_DEG", "SMOOTHNESS", "albedo_target", "albedo_scale", "match_albedo"]

#: Views (deg) at which the albedo is matched.
VIEWS_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0)
#: Nodes (deg) of the piecewise-linear factor ``s(theta_d)``.
NODES_DEG = (0.0, 20.0, 35.0, 45.0, 55.0, 62.0, 68.0, 74.0, 80.0, 90.0)
#: Weight of the second differences of ``s`` (per node) against the relative albedo residuals.
SMOOTHNESS = 1e-3
#: Weight of ``s - 1`` (keeps nodes that no view constrains near 1).
PULL = 1e-3
#: Largest factor.
S_MAX = 20.0
#: Nodes of the tabulated Fresnel terms, uniform in ``theta_d``.
TABLE_SIZE = 46
#: Quadrature of the albedo (half-vector grid per view, :func:`microfacet.metrics.albedo_directions`).
QUADRATURE = 64


def _theta_d(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(wi * h, axis=-1), -1.0, 1.0))


def _hats(theta_d: np.ndarray) -> np.ndarray:
    """Hat functions of :data:`NODES_DEG` at ``theta_d`` (radians): ``(..., K)``."""
    nodes = np.radians(NODES_DEG)
    eye = np.eye(len(nodes))
    return np.stack([np.interp(theta_d, nodes, eye[k]) for k in range(len(nodes))], axis=-1)


def _lobes(brdf) -> list:
    from ..brdf import MicrofacetBRDF
    return [b for b in getattr(brdf, "brdfs", [brdf]) if isinstance(b, MicrofacetBRDF)]


def albedo_target(reference) -> AlbedoRatios:
    """The data's side of :func:`match_albedo`: ``reference``'s directional albedo at
    :data:`VIEWS_DEG` on a :data:`QUADRATURE` grid, light directions as the metrics compare
    them (:class:`~microfacet.metrics.AlbedoRatios`).

    Examples
    --------
    >>> import microfacet as mf
    >>> albedo_target(mf.Lambertian(0.5)).ref.shape
    (12, 3)
    """
    return AlbedoRatios(reference, VIEWS_DEG, n_theta=QUADRATURE, n_phi=QUADRATURE)


def albedo_scale(ratios: AlbedoRatios, brdf) -> np.ndarray:
    """The factor ``s`` of :func:`match_albedo` on :data:`NODES_DEG`, ``(K, 3)``, for the
    data's albedo ``ratios`` (an :class:`~microfacet.metrics.AlbedoRatios` at
    :data:`VIEWS_DEG`) and the fit ``brdf``; ones where it has no microfacet lobe.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.metrics import AlbedoRatios
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25))
    >>> s = albedo_scale(AlbedoRatios(data, VIEWS_DEG, n_theta=32, n_phi=32), fit)
    >>> s.shape, bool(s[0, 0] > 1.5)
    ((10, 3), True)
    """
    lobes = _lobes(brdf)
    k = len(NODES_DEG)
    if not lobes:
        return np.ones((k, 3))
    wi, wo, w, view = ratios.nodes
    n_views = ratios.n_views
    fitted = ratios.albedo(brdf)
    spec = w[:, None] * sum(np.nan_to_num(np.asarray(b.eval_cos(wi, wo), float)) for b in lobes)
    hats = _hats(_theta_d(wi, wo))
    second = np.diff(np.eye(k), 2, axis=0)
    s = np.ones((k, 3))
    for c in range(3):
        a = np.stack([np.bincount(view, spec[:, c] * hats[:, j], minlength=n_views) for j in range(k)], axis=-1)
        if not np.any(a > 0):
            continue
        ref = np.maximum(ratios.ref[:, c], 1e-4)
        rhs = (ref - fitted[:, c] + a.sum(axis=1)) / ref          # a' = fitted + a (s - 1)
        m = np.vstack([a / ref[:, None], np.sqrt(SMOOTHNESS) * second, np.sqrt(PULL) * np.eye(k)])
        v = np.concatenate([rhs, np.zeros(len(second)), np.sqrt(PULL) * np.ones(k)])
        s[:, c] = box_qp(m.T @ m, m.T @ v, np.zeros(k), np.full(k, S_MAX))
    return s


def match_albedo(reference, brdf, ratios: AlbedoRatios | None = None):
    """``brdf`` with each microfacet lobe's Fresnel term ``F`` replaced by the table
    ``clip(F s, 0, 1)`` (:func:`albedo_scale`; module docstring), so that its directional
    albedo matches ``reference``'s at :data:`VIEWS_DEG`. ``ratios``: the reference's
    :class:`~microfacet.metrics.AlbedoRatios` at those views, to share among fits.
    A BRDF without microfacet lobes is returned as is.

    Parameters
    ----------
    reference : BRDF
        The data (measured or any BRDF).
    brdf : MicrofacetBRDF or SumBRDF
        The fit: a lobe, or a sum of lobes and diffuse terms.
    ratios : AlbedoRatios, optional
        :func:`albedo_target` of ``reference`` (which is then not read).

    Returns
    -------
    BRDF
        The same tree with tabulated Fresnel terms (``TABLE_SIZE`` nodes uniform in ``theta_d``).

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = match_albedo(data, mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25)))
    >>> type(fit.fresnel).__name__, bool(abs(fit.fresnel(1.0)[0] - 0.5) < 0.02)
    ('Tabulated', True)
    """
    from .. import fresnel as fr
    from ..brdf import MicrofacetBRDF
    from .analytic import SumBRDF
    if not _lobes(brdf):
        return brdf
    s = albedo_scale(albedo_target(reference) if ratios is None else ratios, brdf)
    theta = np.linspace(np.pi / 2, 0.0, TABLE_SIZE)
    cos_d, factor = np.cos(theta), _hats(theta) @ s

    def scaled(b):
        if not isinstance(b, MicrofacetBRDF):
            return b
        table = fr.Tabulated(cos_d, np.clip(np.asarray(b.fresnel(cos_d), float) * factor, 0.0, 1.0))
        return MicrofacetBRDF(b.distribution, fresnel=table, gaf=b.gaf_model, shadowing=b.shadowing)

    if isinstance(brdf, SumBRDF):
        return SumBRDF(*map(scaled, brdf.brdfs), weights=brdf.weights)
    return scaled(brdf)
