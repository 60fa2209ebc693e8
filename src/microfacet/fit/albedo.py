"""A fit's directional albedo matched to the data's by a smooth table in ``theta_d``.

A fit made in a compressed space (:mod:`microfacet.fit.perceptual`) weighs the specular
peak little: its shape can be right while the energy it reflects at grazing views falls
short of the data's (a plastic's or paint's albedo stays flat or rises with the view, the
fit's falls with its body's transmission). :func:`match_albedo` multiplies the Fresnel term
of every microfacet lobe by one smooth non-negative factor per channel ``s(theta_d)``,

    f'(i, o) = f(i, o) + (s(theta_d) - 1) f_spec(i, o),

chosen so that the directional albedo ``a(o) = int f' cos theta_i d i`` (Dupuy 2015, Eq. 1.8) of the
fit equals the data's at views :data:`VIEWS_DEG`. The albedo is linear in ``s``: with
``s`` piecewise linear on :data:`NODES_DEG` (hat functions ``h_k``),

    a'(o) = a(o) + sum_k (s_k - 1) int h_k(theta_d) f_spec cos theta_i d i,

so ``s`` solves a bounded linear least squares (:func:`~microfacet.fit.extract.box_qp`):
the relative albedo residuals, plus the fit's cosine-weighted log error
(:class:`~microfacet.metrics.LogError`, Löw et al. 2012) linearized in ``s`` and weighed by
:data:`LOG_WEIGHT` relative to its value before the match (so that the lobes' energy moves
where it changes the shape least), a second-difference smoothness penalty
(:data:`SMOOTHNESS`) and a weak pull toward 1; views where the albedo would exceed the
data's by more than 1 % are weighed up until it does not (energy stays a constraint, as in
the fits themselves). A specular lobe's energy at view
``theta_o`` comes from ``theta_d`` near ``theta_o`` (the mirror configuration), which is
why a table in ``theta_d`` reaches the albedo at each view without changing the lobes'
shape. The product ``F s`` becomes each lobe's :class:`~microfacet.fresnel.Tabulated`
Fresnel term (clipped to ``[0, 1]``): the result is a BRDF of the same tree, which specs,
fit files and the Mitsuba plugins hold; the exports (glTF, MaterialX, USD, Blender) write
each table as its least-squares Schlick pair and report that loss. No table may ring: where
a channel's tables would have a total variation above twice their range, ``s`` is solved
again rising to one peak and falling after it (every peak node tried), and, if that fails
too, as a constant.

Accuracy: the albedo is matched to a few percent at 0-75 deg wherever the lobes carry
enough energy at the view; the fit corpus's results page (``experiments/fit_corpus.py``)
reports it for every material. A fit without microfacet lobes is returned unchanged.
A Schlick form of the match (new ``f0``, ``f90`` and base colours, which every export holds
exactly) was measured on the fit corpus and not adopted: ``(1 - cos theta_d)^5`` moves only
the grazing views, so it reaches the albedo on far fewer materials than the table, at a larger
image error (``experiments/results/albedo_schlick.md``).

Examples
--------
>>> import microfacet as mf
>>> data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.08)), mf.Lambertian(0.3))
>>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
>>> matched = match_albedo(data, fit)
>>> ratios = mf.metrics.albedo_ratios(data, matched, views_deg=(0.0, 60.0))
>>> bool(abs(ratios - 1.0).max() < 0.01)
True
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..metrics import AlbedoRatios, LogError
from .extract import box_qp

__all__ = ["VIEWS_DEG", "NODES_DEG", "SMOOTHNESS", "LOG_WEIGHT", "AlbedoTarget", "albedo_target", "albedo_scale",
           "match_albedo", "LOG_PAIRS"]

#: Views (deg) at which the albedo is matched.
VIEWS_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0)
#: Nodes (deg) of the piecewise-linear factor ``s(theta_d)``.
NODES_DEG = (0.0, 20.0, 35.0, 45.0, 55.0, 62.0, 68.0, 74.0, 80.0, 90.0)
#: Weight of the second differences of ``s`` (per node) against the relative albedo residuals.
SMOOTHNESS = 1e-3
#: Weight of the linearized squared log error over its value before the match: doubling
#: it costs as much as a 17 % albedo residual at one view.
LOG_WEIGHT = 0.03
#: Weight of ``s - 1`` (keeps nodes that no view constrains near 1).
PULL = 1e-3
#: Largest factor.
S_MAX = 20.0
#: Relative excess of the albedo over the data's beyond which a view is weighed up, and the
#: number of rounds of that (the issue's energy constraint: albedo <= data + 1 %).
ALBEDO_ABOVE = 0.01
OVERSHOOT_ROUNDS = 4
#: Largest total variation of a table over its range (a larger one rings).
TV_LIMIT = 2.0
#: Nodes of the tabulated Fresnel terms, uniform in ``theta_d``.
TABLE_SIZE = 46
#: Quadrature of the albedo (half-vector grid per view, :func:`microfacet.metrics.albedo_directions`).
QUADRATURE = 64
#: Pairs of the log-error term.
LOG_PAIRS = 2**15


class AlbedoTarget(NamedTuple):
    """The data's side of :func:`match_albedo`: its albedo at :data:`VIEWS_DEG` and its log
    error's pairs (made by :func:`albedo_target`).

    Attributes
    ----------
    ratios : microfacet.metrics.AlbedoRatios
        The data's albedo at :data:`VIEWS_DEG`.
    log : microfacet.metrics.LogError
        The data's side of the log error.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = albedo_target(mf.Lambertian(0.5))
    >>> isinstance(t, AlbedoTarget), t.ratios.ref.shape == (len(VIEWS_DEG), 3), t.log.n == LOG_PAIRS
    (True, True, True)
    """
    ratios: AlbedoRatios
    log: LogError


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


def albedo_target(reference, log: LogError | None = None) -> AlbedoTarget:
    """The data's side of :func:`match_albedo`: ``reference``'s directional albedo at
    :data:`VIEWS_DEG` on a :data:`QUADRATURE` grid, light directions as the metrics compare
    them (:class:`~microfacet.metrics.AlbedoRatios`), and its log error ``log`` (default
    :class:`~microfacet.metrics.LogError` on :data:`LOG_PAIRS` pairs).

    Parameters
    ----------
    reference : BRDF
        The data.
    log : microfacet.metrics.LogError, optional
        Its log error, if already made (e.g. the fit's judge).

    Returns
    -------
    AlbedoTarget

    Examples
    --------
    >>> import microfacet as mf
    >>> albedo_target(mf.Lambertian(0.5)).ratios.ref.shape
    (12, 3)
    """
    return AlbedoTarget(AlbedoRatios(reference, VIEWS_DEG, n_theta=QUADRATURE, n_phi=QUADRATURE),
                        LogError(reference, n=LOG_PAIRS) if log is None else log)


class _System(NamedTuple):
    """One channel's least squares: relative albedo residuals ``m s - rhs`` (``a'/a_data - 1``
    per view) and the other terms' quadratic ``1/2 s^T h s - g^T s``."""
    m: np.ndarray
    rhs: np.ndarray
    h: np.ndarray
    g: np.ndarray

    def solve(self, t: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, float]:
        """``s = t z`` of least objective over ``0 <= z <= upper``, views whose albedo would
        exceed the data's by more than ``ALBEDO_ABOVE`` weighed up tenfold until none does
        (:data:`OVERSHOOT_ROUNDS`); and its objective with unit weights."""
        w = np.ones(len(self.rhs))
        for _ in range(OVERSHOOT_ROUNDS):
            h = self.m.T @ (w[:, None] * self.m) + self.h
            g = self.m.T @ (w * self.rhs) + self.g
            s = t @ box_qp(t.T @ h @ t, t.T @ g, np.zeros(len(upper)), upper)
            over = self.m @ s - self.rhs > ALBEDO_ABOVE
            if not np.any(over):
                break
            w = np.where(over, 10.0 * w, w)
        h, g = self.m.T @ self.m + self.h, self.m.T @ self.rhs + self.g
        return s, float(0.5 * s @ h @ s - g @ s)


def _systems(target: AlbedoTarget, brdf, lobes) -> list[_System]:
    """The least squares of :func:`albedo_scale` per channel (module docstring)."""
    ratios, log = target
    k = len(NODES_DEG)
    wi, wo, w, view = ratios.nodes
    fitted = ratios.albedo(brdf)
    spec = w[:, None] * sum(np.nan_to_num(np.asarray(b.eval_cos(wi, wo), float)) for b in lobes)
    hats = _hats(_theta_d(wi, wo))
    f = np.maximum(np.nan_to_num(np.asarray(brdf.eval_cos(log.wi, log.wo), float)), 0.0)
    f_spec = sum(np.nan_to_num(np.asarray(b.eval_cos(log.wi, log.wo), float)) for b in lobes)
    log_hats = _hats(_theta_d(log.wi, log.wo))
    d0 = np.log1p(f) - log.ref                                      # log residual before the match
    pair_w = LOG_WEIGHT * log.w / max(float(np.sum(log.w * np.sum(d0 * d0, axis=-1))), 1e-12)
    second = np.diff(np.eye(k), 2, axis=0)
    regular = SMOOTHNESS * second.T @ second + PULL * np.eye(k)
    out = []
    for c in range(3):
        a = np.stack([np.bincount(view, spec[:, c] * hats[:, j], minlength=ratios.n_views) for j in range(k)], axis=-1)
        ref = np.maximum(ratios.ref[:, c], 1e-4)
        m = a / ref[:, None]                                        # a' = fitted + a (s - 1)
        j = (f_spec[:, c] / (1.0 + f[:, c]))[:, None] * log_hats    # d ln(1 + f') / d s
        out.append(_System(m, (ref - fitted[:, c]) / ref + m.sum(axis=1), (j.T * pair_w) @ j + regular,
                           (j.T * pair_w) @ (j.sum(axis=1) - d0[:, c]) + PULL))
    return out


def _shapes(k: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(T, upper)``: ``s = T z`` over ``0 <= z <= upper``: free (``T = I``), then rising to
    a peak at node ``p`` and falling after it, for every ``p``."""
    out = [(np.eye(k), np.full(k, S_MAX))]
    for p in range(k):
        t = np.zeros((k, k))
        for j in range(k):
            t[j, :min(j, p) + 1] = 1.0
            t[j, p + 1:j + 1] = -1.0
        out.append((t, np.full(k, np.inf)))
    return out


def _tables(brdf, s: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The cosines of the tables and each lobe's ``clip(F s, 0, 1)`` for factors ``s`` ``(K, 3)``."""
    theta = np.linspace(np.pi / 2, 0.0, TABLE_SIZE)
    cos_d, factor = np.cos(theta), _hats(theta) @ s
    return cos_d, [np.clip(np.asarray(b.fresnel(cos_d), float) * factor, 0.0, 1.0) for b in _lobes(brdf)]


def _rings(values: np.ndarray) -> np.ndarray:
    """Per channel: whether a table's total variation exceeds :data:`TV_LIMIT` times its range."""
    tv = np.sum(np.abs(np.diff(values, axis=0)), axis=0)
    return tv > TV_LIMIT * np.ptp(values, axis=0) + 1e-9


def albedo_scale(target: AlbedoTarget, brdf) -> np.ndarray:
    """The factor ``s`` of :func:`match_albedo` on :data:`NODES_DEG`, ``(K, 3)``, for the
    data's :func:`albedo_target` and the fit ``brdf``; ones where it has no microfacet lobe.
    Per channel, the least of the module's quadratic among the shapes whose tables do not
    ring (free, one peak, constant: module docstring).

    Parameters
    ----------
    target : AlbedoTarget
        The data's side (:func:`albedo_target`).
    brdf : MicrofacetBRDF or SumBRDF
        The fit.

    Returns
    -------
    (K, 3) ndarray
        ``s`` per node of :data:`NODES_DEG` and RGB channel.

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25))
    >>> s = albedo_scale(albedo_target(data), fit)
    >>> s.shape == (len(NODES_DEG), 3), bool(s[0, 0] > 1.5)      # SMOOTHNESS, LOG_WEIGHT: module docstring
    (True, True)
    """
    lobes = _lobes(brdf)
    k = len(NODES_DEG)
    s = np.ones((k, 3))
    if not lobes:
        return s
    systems = _systems(target, brdf, lobes)
    solved = [[system.solve(t, upper) for system in systems] for t, upper in _shapes(k)]
    for c, system in enumerate(systems):
        best = np.inf
        for shape in solved:
            s_c, objective = shape[c]
            trial = s.copy()
            trial[:, c] = s_c
            if objective < best and not any(_rings(v)[c] for v in _tables(brdf, trial)[1]):
                s[:, c], best = s_c, objective
        if not np.isfinite(best):                     # a constant factor keeps each table's shape
            s[:, c] = system.solve(np.ones((k, 1)), np.full(1, S_MAX))[0]
    return s


def match_albedo(reference, brdf, target: AlbedoTarget | None = None):
    """``brdf`` with each microfacet lobe's Fresnel term ``F`` replaced by the table
    ``clip(F s, 0, 1)`` (:func:`albedo_scale`; module docstring), so that its directional
    albedo matches ``reference``'s at :data:`VIEWS_DEG`. ``target``: the reference's
    :func:`albedo_target`, to share among fits. A BRDF without microfacet lobes is
    returned as is.

    Parameters
    ----------
    reference : BRDF
        The data (measured or any BRDF).
    brdf : MicrofacetBRDF or SumBRDF
        The fit: a lobe, or a sum of lobes and diffuse terms.
    target : AlbedoTarget, optional
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
    cos_d, tables = _tables(brdf, albedo_scale(albedo_target(reference) if target is None else target, brdf))
    tables = iter(tables)

    def scaled(b):
        if not isinstance(b, MicrofacetBRDF):
            return b
        return MicrofacetBRDF(b.distribution, fresnel=fr.Tabulated(cos_d, next(tables)), gaf=b.gaf_model,
                              shadowing=b.shadowing, dtype=b.dtype)

    if isinstance(brdf, SumBRDF):
        return SumBRDF(*map(scaled, brdf.brdfs), weights=brdf.weights)
    return scaled(brdf)
