"""A fit's directional albedo matched to the data's by a smooth table in ``theta_d`` and, where
the lobes cannot carry it, by its diffuse bases' reflectances.

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
the fits themselves). A second table is solved log first: the log error weighed by
:data:`LOG_WEIGHT_IN_BAND`, the band views (below) farther than :data:`BAND_TARGET` from the
data's albedo weighed up fourfold for up to :data:`BAND_ROUNDS` rounds; where its tables, as
clipped, hold that band, it is kept if the whole match below misses the band or holds it at
more log error (within the band, the log error decides how the energy moves). A specular
lobe's energy at view ``theta_o`` comes from ``theta_d`` near ``theta_o`` (the mirror configuration), which is
why a table in ``theta_d`` reaches the albedo at each view without changing the lobes'
shape. The product ``F s`` becomes each lobe's :class:`~microfacet.fresnel.Tabulated`
Fresnel term (clipped to ``[0, 1]``): the result is a BRDF of the same tree, which specs,
fit files and the Mitsuba plugins hold; the exports (glTF, MaterialX, USD, Blender) write
each table as its least-squares Schlick pair and report that loss. No table may ring: where
a channel's tables would have a total variation above twice their range, ``s`` is solved
again rising to one peak and falling after it (every peak node tried), and, if that fails
too, as a constant.

Where the lobes carry too little of the albedo to reach the band (every channel whose data
albedo exceeds :data:`BAND_FLOOR` within 5 % at :data:`BAND_VIEWS_DEG`; the match aims at
:data:`BAND_TARGET`), the diffuse bases' reflectances are scaled too, one factor ``b`` per
base and channel: the albedo is linear in ``b`` as in ``s``,

    a'(o) = a(o) + sum_k (s_k - 1) A_k(o) + sum_j (b_j - 1) int f_base,j cos theta_i d i,

so ``(s, b)`` solve the same bounded least squares (the log-error term linearized in ``b``
too), the band views still outside :data:`BAND_TARGET` weighed up fourfold for up to
:data:`BAND_ROUNDS` rounds. Each factor lies within ``[1 / BASE_RANGE, BASE_RANGE]`` and keeps
the reflectance at most 1; a factor above 1 is drawn back toward 1 until the total albedo
at :data:`ENERGY_VIEWS_DEG` stays below ``1 - ENERGY_MARGIN``. The scaled bases are kept only
if they bring the band error down, exceed the data's albedo at no view of the band by more
than :data:`ALBEDO_ABOVE` (or than the lobes' match alone did), and the log error grows by at most
:data:`LOG_TOLERANCE`, or by at most :data:`LOG_TOLERANCE_IN_BAND` where they bring the fit into
the band (reaching the data's energy is worth more of the shape than coming closer to it);
of the solutions for 0 to :data:`BAND_ROUNDS` weighing rounds, the one kept of least log error
in the band, else of least band error; the base keeps its class
(:class:`~microfacet.Lambertian`, :class:`~microfacet.diffuse.TransmittedLambertian` of the
same index) with the new reflectance, so the result is still the fit's tree.

Where a fit of several lobes is still outside :data:`BAND_TARGET`, each lobe gets a factor
of its own on top of ``s``, ``r_l(theta_d)`` on the same nodes (every lobe's of the same
shape, from ``r = 1``), its table ``clip(F_l s r_l, 0, 1)``: a sharp lobe's energy at a view
comes from ``theta_d`` near it, a rough lobe's from a wide range, so their own tables follow a
steep rise of the albedo toward grazing that one shared table cannot. The albedo is linear
in each ``r_l`` as in ``s``; they are solved and kept as the bases' factors are (the log
error at most :data:`LOG_TOLERANCE` above the lobes' shared match, :data:`LOG_TOLERANCE_IN_BAND`
where they reach the band).

Energy comes before the data's albedo (measured albedos can exceed 1 near grazing views, and
a table matched up to 80 deg can overshoot beyond it): where the matched fit's total albedo
at :data:`VIEWS_DEG` or :data:`ENERGY_VIEWS_DEG` exceeds ``1 - ENERGY_MARGIN`` in a channel,
that channel's factor at the nodes beyond the band views (:data:`NODES_DEG` above 75 deg) is
scaled down until it does not, or, where that makes a table ring, the channel's tables get the
largest ceiling that holds it (their grazing rise cut flat), the bases scaled down too where
they alone exceed it, or, where a capped table still rings, the whole channel is scaled
down (:class:`AlbedoFactors`).

Accuracy: the albedo is matched to a few percent at 0-75 deg wherever the lobes, or the
lobes and bases together, carry the albedo's variation with the view; a data albedo that
jumps within a degree of normal view or rises more steeply toward grazing than the lobes
can follow is left out of the band rather than matched at the cost of the shape; the fit corpus's results page (``experiments/fit_corpus.py``)
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
>>> BAND_VIEWS_DEG, BAND_TARGET                  # the band's views (deg) and the half-width aimed at
((0.0, 30.0, 60.0, 75.0), 0.04)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..metrics import AlbedoRatios, LogError, directional_albedo
from .extract import box_qp

__all__ = ["VIEWS_DEG", "NODES_DEG", "theta_d", "hats", "SMOOTHNESS", "LOG_WEIGHT", "LOG_WEIGHT_IN_BAND", "AlbedoTarget", "albedo_target", "albedo_scale",
           "AlbedoFactors", "albedo_factors", "match_albedo", "LOG_PAIRS", "BAND_VIEWS_DEG", "BAND_TARGET"]

#: Views (deg) at which the albedo is matched.
VIEWS_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0)
#: Nodes (deg) of the piecewise-linear factor ``s(theta_d)``.
NODES_DEG = (0.0, 20.0, 35.0, 45.0, 55.0, 62.0, 68.0, 74.0, 80.0, 90.0)
#: Weight of the second differences of ``s`` (per node) against the relative albedo residuals.
SMOOTHNESS = 1e-3
#: Weight of the linearized squared log error over its value before the match: doubling
#: it costs as much as a 17 % albedo residual at one view.
LOG_WEIGHT = 0.03
#: The same in the log-first table (doubling the log error costs as much as a 55 % albedo
#: residual), whose band views are held to :data:`BAND_TARGET` by weighing them up
#: (:data:`BAND_ROUNDS`; module docstring).
LOG_WEIGHT_IN_BAND = 0.3
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
#: Quadrature of the albedo: ``(n_theta, n_phi)`` of the half-vector grid per view
#: (:func:`microfacet.metrics.albedo_directions`). A sharp peak needs the nodes in ``theta``;
#: ``phi`` needs few (the integrand is smooth and periodic in it).
QUADRATURE = (128, 32)
#: Pairs of the log-error term.
LOG_PAIRS = 2**15
#: Views (deg) of the albedo band (issue 24's check: every channel whose data albedo
#: exceeds :data:`BAND_FLOOR` within ``1 +- BAND`` of it there).
BAND_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
#: Half-width of the albedo band.
BAND = 0.05
#: Half-width that the match aims at, inside :data:`BAND`, to leave room for the quadrature.
BAND_TARGET = 0.04
#: Channels whose data albedo is below this are not held to the band.
BAND_FLOOR = 0.03
#: Rounds of weighing up the band views outside :data:`BAND_TARGET` (fourfold each) in the
#: log-first table and where the bases are scaled too.
BAND_ROUNDS = 3
#: Largest factor of a base's reflectance and its inverse, the smallest.
BASE_RANGE = 2.0
#: Largest relative growth of the log error (:class:`~microfacet.metrics.LogError` on the
#: target's pairs) that the bases' factors may cost over the lobes' match alone.
LOG_TOLERANCE = 0.1
#: The same where the factors bring a fit outside the band (band error at least :data:`BAND`) into it.
LOG_TOLERANCE_IN_BAND = 0.3
#: Views (deg) beyond :data:`VIEWS_DEG` where the total albedo of a fit whose bases were
#: scaled up must stay below ``1 - ENERGY_MARGIN``.
ENERGY_VIEWS_DEG = (85.0, 89.0)
ENERGY_MARGIN = 2e-3


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


def theta_d(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The difference angle ``theta_d`` (radians) of direction pairs ``(..., 3)``: the angle
    between the light and the half vector (Rusinkiewicz 1998).

    Parameters
    ----------
    wi, wo : (..., 3) ndarray
        Unit light and view directions.

    Returns
    -------
    (...) ndarray
        ``theta_d`` in radians.

    Examples
    --------
    >>> import numpy as np
    >>> round(float(np.degrees(theta_d(np.array([1.0, 0, 0]), np.array([0, 0, 1.0])))), 6)
    45.0
    """
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(wi * h, axis=-1), -1.0, 1.0))


def hats(theta: np.ndarray) -> np.ndarray:
    """The hat functions of :data:`NODES_DEG` (the piecewise-linear basis of the factor
    ``s(theta_d)``) at ``theta`` (radians): ``(..., K)``, summing to 1.

    Parameters
    ----------
    theta : ndarray
        Angles ``theta_d`` in radians, in ``[0, pi / 2]``.

    Returns
    -------
    (..., K) ndarray
        ``h_k(theta)`` for the ``K`` nodes.

    Examples
    --------
    >>> hats(np.radians([0.0, 10.0])).round(2)[:, :3]
    array([[1. , 0. , 0. ],
           [0.5, 0.5, 0. ]])
    """
    nodes = np.radians(NODES_DEG)
    eye = np.eye(len(nodes))
    return np.stack([np.interp(theta, nodes, eye[k]) for k in range(len(nodes))], axis=-1)


def _is_lobe(part) -> bool:
    from ..brdf import MicrofacetBRDF
    return isinstance(part, MicrofacetBRDF)


def _is_base(part) -> bool:
    from ..brdf import Lambertian
    from ..diffuse import TransmittedLambertian
    return isinstance(part, (Lambertian, TransmittedLambertian))


def _lobes(brdf) -> list:
    return [b for b in getattr(brdf, "brdfs", [brdf]) if _is_lobe(b)]


def _terms_cos(brdf, wi, wo) -> list[tuple[object, np.ndarray]]:
    """``(term, f cos theta_i)`` of each term of ``brdf`` (itself where it is not a sum),
    non-finite values as 0 (:meth:`microfacet.fit.SumBRDF.terms_cos`)."""
    terms = getattr(brdf, "brdfs", (brdf,))
    values = brdf.terms_cos(wi, wo) if hasattr(brdf, "terms_cos") else [b.eval_cos(wi, wo) for b in terms]
    return [(b, np.nan_to_num(np.asarray(v, float))) for b, v in zip(terms, values)]


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
    return AlbedoTarget(AlbedoRatios(reference, VIEWS_DEG, n_theta=QUADRATURE[0], n_phi=QUADRATURE[1]),
                        LogError(reference, n=LOG_PAIRS) if log is None else log)


class _System(NamedTuple):
    """One channel's least squares: relative albedo residuals ``m x - rhs`` (``a'/a_data - 1``
    per view) and the other terms' quadratic ``1/2 x^T h x - g^T x``, of which the log error's
    is ``log_weight`` times ``1/2 x^T log_h x - log_g^T x``; ``band``: the views held to the
    band (:data:`BAND_VIEWS_DEG`, data albedo above :data:`BAND_FLOOR`)."""
    m: np.ndarray
    rhs: np.ndarray
    h: np.ndarray
    g: np.ndarray
    band: np.ndarray
    log_h: np.ndarray
    log_g: np.ndarray
    log_weight: float

    def reweighed(self, log_weight: float) -> "_System":
        """The same least squares with the log error weighed by ``log_weight``."""
        d = log_weight - self.log_weight
        return self._replace(h=self.h + d * self.log_h, g=self.g + d * self.log_g, log_weight=log_weight)

    def solve(self, t: np.ndarray, upper: np.ndarray, band_rounds: int = 0,
              offset: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """``x = offset + t z`` of least objective over ``0 <= z <= upper``, views whose albedo would
        exceed the data's by more than ``ALBEDO_ABOVE`` weighed up tenfold until none does
        (:data:`OVERSHOOT_ROUNDS`), then, ``band_rounds`` times, the band views outside
        :data:`BAND_TARGET` fourfold; and its objective with unit weights."""
        w = np.ones(len(self.rhs))
        x0 = np.zeros(t.shape[0]) if offset is None else offset
        overshoot = 1
        while True:
            h = self.m.T @ (w[:, None] * self.m) + self.h
            g = self.m.T @ (w * self.rhs) + self.g
            x = x0 + t @ box_qp(t.T @ h @ t, t.T @ (g - h @ x0), np.zeros(len(upper)), upper)
            r = self.m @ x - self.rhs
            if np.any(over := r > ALBEDO_ABOVE) and overshoot < OVERSHOOT_ROUNDS:
                w, overshoot = np.where(over, 10.0 * w, w), overshoot + 1
            elif band_rounds > 0 and np.any(out := self.band & (np.abs(r) > BAND_TARGET)):
                w, band_rounds = np.where(out, 4.0 * w, w), band_rounds - 1
            else:
                break
        h, g = self.m.T @ self.m + self.h, self.m.T @ self.rhs + self.g
        return x, float(0.5 * x @ h @ x - g @ x)

    def band_error(self, x: np.ndarray) -> float:
        """The largest ``|a'/a_data - 1|`` over the band views (0 where none is held)."""
        r = np.abs(self.m @ x - self.rhs)[self.band]
        return float(r.max()) if len(r) else 0.0


def _systems(target: AlbedoTarget, brdf, bases: bool = False, each: bool = False) -> list[_System]:
    """The least squares of :func:`albedo_factors` per channel (module docstring): unknowns
    the table's nodes ``s`` (with ``each``, one table per lobe, in the lobes' order) and, with
    ``bases``, each diffuse base's reflectance factor ``b``; the log error weighed by :data:`LOG_WEIGHT`."""
    ratios, log = target
    k = len(NODES_DEG)
    wi, wo, w, view = ratios.nodes
    fitted = ratios.albedo(brdf)
    terms = _terms_cos(brdf, wi, wo)
    lobe_values = [v for b, v in terms if _is_lobe(b)]
    spec = [w[:, None] * v for v in lobe_values] if each else [w[:, None] * sum(lobe_values)]
    diffuse = [w[:, None] * v for b, v in terms if bases and _is_base(b)]
    basis = hats(theta_d(wi, wo))
    f = np.maximum(np.nan_to_num(np.asarray(brdf.eval_cos(log.wi, log.wo), float)), 0.0)
    terms = _terms_cos(brdf, log.wi, log.wo)
    lobe_values = [v for b, v in terms if _is_lobe(b)]
    f_spec = lobe_values if each else [sum(lobe_values)]
    f_bases = [v for b, v in terms if bases and _is_base(b)]
    log_hats = hats(theta_d(log.wi, log.wo))
    d0 = np.log1p(f) - log.ref                                      # log residual before the match
    pair_w = log.w / max(float(np.sum(log.w * np.sum(d0 * d0, axis=-1))), 1e-12)
    second = np.diff(np.eye(k), 2, axis=0)
    n = k * len(spec) + len(diffuse)
    regular = PULL * np.eye(n)
    for i in range(len(spec)):
        regular[i * k:(i + 1) * k, i * k:(i + 1) * k] += SMOOTHNESS * second.T @ second
    in_band = np.isin(np.asarray(VIEWS_DEG), BAND_VIEWS_DEG)
    out = []
    for c in range(3):
        a = np.stack([np.bincount(view, sp[:, c] * basis[:, j], minlength=ratios.n_views) for sp in spec
                      for j in range(k)]
                     + [np.bincount(view, d[:, c], minlength=ratios.n_views) for d in diffuse], axis=-1)
        ref = np.maximum(ratios.ref[:, c], 1e-4)
        m = a / ref[:, None]                                        # a' = fitted + a (x - 1)
        j = np.concatenate([(fs[:, c] / (1.0 + f[:, c]))[:, None] * log_hats for fs in f_spec]   # d ln(1 + f') / d x
                           + [(fb[:, c] / (1.0 + f[:, c]))[:, None] for fb in f_bases], axis=-1)
        log_h, log_g = (j.T * pair_w) @ j, (j.T * pair_w) @ (j.sum(axis=1) - d0[:, c])
        out.append(_System(m, (ref - fitted[:, c]) / ref + m.sum(axis=1), LOG_WEIGHT * log_h + regular,
                           LOG_WEIGHT * log_g + PULL, in_band & (ratios.ref[:, c] > BAND_FLOOR), log_h, log_g,
                           LOG_WEIGHT))
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


def _tables(brdf, s: np.ndarray, ceiling=1.0, each=None) -> tuple[np.ndarray, list[np.ndarray]]:
    """The cosines of the tables and each lobe's ``clip(F s r_l, 0, ceiling)`` for factors ``s``
    ``(K, 3)`` and the lobes' own ``r = each`` ``(L, K, 3)`` (none: 1; ``ceiling``: per
    channel, at most 1)."""
    theta = np.linspace(np.pi / 2, 0.0, TABLE_SIZE)
    cos_d, basis = np.cos(theta), hats(theta)
    factor = basis @ s
    lobes = _lobes(brdf)
    own = [factor] * len(lobes) if each is None else [factor * (basis @ r) for r in each]
    return cos_d, [np.clip(np.asarray(b.fresnel(cos_d), float) * f, 0.0, ceiling) for b, f in zip(lobes, own)]


def _rings(values: np.ndarray) -> np.ndarray:
    """Per channel: whether a table's total variation exceeds :data:`TV_LIMIT` times its range."""
    tv = np.sum(np.abs(np.diff(values, axis=0)), axis=0)
    return tv > TV_LIMIT * np.ptp(values, axis=0) + 1e-9


class AlbedoFactors(NamedTuple):
    """The factors of :func:`match_albedo` (made by :func:`albedo_factors`).

    Attributes
    ----------
    s : (K, 3) ndarray
        The factor of the lobes' Fresnel terms per node of :data:`NODES_DEG` and RGB channel.
    bases : (B, 3) ndarray
        The factor of each diffuse base's reflectance (in the fit's order) per RGB channel;
        ones where the lobes reach the band alone.
    ceiling : (3,) ndarray
        The largest value of the lobes' tables per RGB channel (1: none; below 1 where the
        fit would otherwise reflect more than 1 at some view).
    each : (L, K, 3) ndarray
        Each microfacet lobe's own factor on top of ``s`` (in the fit's order) per node and
        RGB channel; ones where ``s`` and the bases reach the band.

    Examples
    --------
    >>> import microfacet as mf
    >>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
    >>> f = albedo_factors(albedo_target(fit), fit)
    >>> f.s.shape, f.bases.shape, f.ceiling, f.each.shape
    ((10, 3), (1, 3), array([1., 1., 1.]), (1, 10, 3))
    """
    s: np.ndarray
    bases: np.ndarray
    ceiling: np.ndarray
    each: np.ndarray


def _bases(brdf) -> list:
    """The diffuse bases of a fit (:class:`~microfacet.Lambertian`,
    :class:`~microfacet.diffuse.TransmittedLambertian`), in its order."""
    return [b for b in getattr(brdf, "brdfs", [brdf]) if _is_base(b)]


def _pick(system: _System, c: int, brdf, s: np.ndarray, base_lower: np.ndarray, base_upper: np.ndarray,
          band_rounds: int, each: np.ndarray | None = None) -> np.ndarray:
    """Channel ``c``'s unknowns ``(s_c, b_c)``: the least objective among the shapes of ``s``
    (:func:`_shapes`) whose tables do not ring (with ``band_rounds``: the least excess of the
    band error over :data:`BAND_TARGET` first), a constant ``s`` if every shape rings;
    ``base_lower``, ``base_upper``: the bounds of the bases' factors (none: the lobes alone).
    With ``each`` (the lobes' own factors, ``(L, K, 3)``): the unknowns are the lobes' own
    factors ``r_l,c`` on top of ``s`` instead of ``s_c``, every lobe's of the same shape."""
    k, nb = len(NODES_DEG), len(base_upper)
    copies = 1 if each is None else len(each)
    n = k * copies

    def joint(t, upper):
        t, upper = np.kron(np.eye(copies), t), np.tile(upper, copies)
        tj = np.zeros((n + nb, t.shape[1] + nb))
        tj[:n, :t.shape[1]], tj[n:, t.shape[1]:] = t, np.eye(nb)
        return system.solve(tj, np.concatenate([upper, base_upper - base_lower]), band_rounds,
                            np.concatenate([np.zeros(n), base_lower]))

    best, chosen = (np.inf, np.inf), None
    for t, upper in _shapes(k):
        x, objective = joint(t, upper)
        trial, own = s.copy(), None if each is None else each.copy()
        if each is None:
            trial[:, c] = x[:k]
        else:
            own[:, :, c] = x[:n].reshape(copies, k)
        key = (max(system.band_error(x) - BAND_TARGET, 0.0) if band_rounds else 0.0, objective)
        if key < best and not any(_rings(v)[c] for v in _tables(brdf, trial, each=own)[1]):
            best, chosen = key, x
    if chosen is None:                                # a constant factor keeps each table's shape
        chosen = joint(np.ones((k, 1)), np.full(1, S_MAX))[0]
    return chosen


def _albedo(brdf, views_deg) -> np.ndarray:
    """:func:`~microfacet.metrics.directional_albedo` of ``brdf`` on the match's :data:`QUADRATURE`."""
    return directional_albedo(brdf, views_deg, n_theta=QUADRATURE[0], n_phi=QUADRATURE[1])


def _energy_limited(matched, bases: list, factors: np.ndarray) -> np.ndarray:
    """``factors`` of the ``bases`` drawn toward 1 (per channel, along the line to 1) as far
    as needed for the total albedo at :data:`ENERGY_VIEWS_DEG` of the fit (``matched``: its
    lobes' tables made, its bases as they were) to stay below ``1 - ENERGY_MARGIN`` (at
    :data:`VIEWS_DEG` the match holds it below the data's + 1 %)."""
    if not np.any(factors > 1.0):
        return factors
    a0 = _albedo(matched, ENERGY_VIEWS_DEG)
    rise = sum((f - 1.0) * _albedo(base, ENERGY_VIEWS_DEG) for base, f in zip(bases, factors))
    limit = 1.0 - ENERGY_MARGIN
    with np.errstate(divide="ignore", invalid="ignore"):
        room = np.where((a0 + rise > limit) & (rise > 0), np.maximum(limit - a0, 0.0) / rise, 1.0)
    return 1.0 + (factors - 1.0) * np.clip(room.min(axis=0), 0.0, 1.0)


def _band(target: AlbedoTarget, brdf) -> tuple[float, float]:
    """``(error, overshoot)`` of ``brdf``'s albedo ratios ``a/a_data`` at :data:`BAND_VIEWS_DEG`
    over the channels whose data albedo exceeds :data:`BAND_FLOOR` (the match's quadrature,
    integrated once): the largest ``|a/a_data - 1|`` and the largest ``a/a_data - 1``."""
    held = np.isin(np.asarray(VIEWS_DEG), BAND_VIEWS_DEG)[:, None] & (target.ratios.ref > BAND_FLOOR)
    r = np.asarray(target.ratios(brdf), float)[held] - 1.0
    return (float(np.nanmax(np.abs(r))), float(np.nanmax(r))) if len(r) else (0.0, 0.0)


def albedo_factors(target: AlbedoTarget, brdf) -> AlbedoFactors:
    """The factors of :func:`match_albedo` for the data's :func:`albedo_target` and the fit
    ``brdf`` (module docstring): per channel, the table ``s`` of least quadratic among the
    shapes whose tables do not ring (free, one peak, constant); where that leaves a view of
    the band farther than :data:`BAND_TARGET` from the data's albedo, ``s`` and the bases'
    factors solved together (the band views outside it weighed up), kept if they come
    closer to the band; where that still does, each lobe's own factor. All ones where the
    fit has no microfacet lobe.

    Parameters
    ----------
    target : AlbedoTarget
        The data's side (:func:`albedo_target`).
    brdf : MicrofacetBRDF or SumBRDF
        The fit.

    Returns
    -------
    AlbedoFactors

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.5))
    >>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
    >>> f = albedo_factors(albedo_target(data), fit)     # the lobe cannot carry 0.2 more at every view
    >>> (0.3 * f.bases[0]).round(2)
    array([0.5, 0.5, 0.5])
    """
    lobes, bases = _lobes(brdf), _bases(brdf)
    k = len(NODES_DEG)
    ones = AlbedoFactors(np.ones((k, 3)), np.ones((len(bases), 3)), np.ones(3), np.ones((len(lobes), k, 3)))
    if not lobes:
        return ones
    systems = _systems(target, brdf)
    factors = _albedo_first(target, brdf, ones, systems)
    log_first = _log_first(brdf, ones, [system.reweighed(LOG_WEIGHT_IN_BAND) for system in systems])
    held, other = _rebuilt(brdf, *log_first), _rebuilt(brdf, *factors)
    if _band(target, held)[0] <= BAND_TARGET and (      # its tables, as clipped, hold the band: kept unless
            _band(target, other)[0] > BAND_TARGET or target.log(held) < target.log(other)):   # the other does at less log error
        factors = log_first
    return _energy_bounded(brdf, factors)


def _log_first(brdf, ones: AlbedoFactors, systems: list[_System]) -> AlbedoFactors:
    """``ones`` with the shared table ``s`` solved with the log error weighed by
    :data:`LOG_WEIGHT_IN_BAND` (``systems``) and the band views held to :data:`BAND_TARGET`
    by weighing them up."""
    s = ones.s.copy()
    for c, system in enumerate(systems):
        s[:, c] = _pick(system, c, brdf, s, np.zeros(0), np.zeros(0), BAND_ROUNDS)
    return ones._replace(s=s)


def _albedo_first(target: AlbedoTarget, brdf, ones: AlbedoFactors, systems: list[_System]) -> AlbedoFactors:
    """``ones`` with the shared table ``s`` of least albedo residuals (``systems``, of
    :data:`LOG_WEIGHT`); where it misses the band, with the bases' factors and then each
    lobe's own (module docstring)."""
    s = ones.s.copy()
    for c, system in enumerate(systems):
        s[:, c] = _pick(system, c, brdf, s, np.zeros(0), np.zeros(0), 0)
    errors = [system.band_error(s[:, c]) for c, system in enumerate(systems)]
    factors = ones._replace(s=s)
    if max(errors) <= BAND_TARGET:
        return factors
    matched = _rebuilt(brdf, *factors)
    error, overshoot = _band(target, matched)
    before = target.log(matched), error, max(overshoot, ALBEDO_ABOVE)
    if _bases(brdf):
        factors = _with_bases(target, brdf, factors, errors, before) or factors
    if len(_lobes(brdf)) > 1:
        factors = _each_lobe(target, brdf, factors, before) or factors
    return factors


def _chosen(target: AlbedoTarget, brdf, candidates, before: tuple, band: float):
    """The kept match among ``candidates`` (:class:`AlbedoFactors` of ``brdf``): of those in the
    band (band error below :data:`BAND`) the one of least log error, else the one of least band
    error, or None. Kept: its band error below ``band`` (the match's so far), its overshoot at
    most that of ``before = (log, band, overshoot)`` (the lobes' match alone) and its log error
    at most :data:`LOG_TOLERANCE` above ``before``'s, or :data:`LOG_TOLERANCE_IN_BAND` where it
    brings a match outside the band (``band >= BAND``) into it."""
    log_before, _, over_before = before
    best, best_key = None, None
    for factors in candidates:
        matched = _rebuilt(brdf, *factors)
        error, overshoot = _band(target, matched)
        if not (error < band and overshoot <= over_before):
            continue
        log = target.log(matched)
        reaches = error < BAND <= band
        if log <= (1.0 + (LOG_TOLERANCE_IN_BAND if reaches else LOG_TOLERANCE)) * log_before:
            key = (error >= BAND, log if error < BAND else error)
            if best_key is None or key < best_key:
                best, best_key = factors, key
    return best


def _with_bases(target: AlbedoTarget, brdf, factors: AlbedoFactors, errors: list, before: tuple):
    """``factors`` (the lobes' match) with ``s`` and the bases' factors solved together in the
    channels whose band ``errors`` exceed :data:`BAND_TARGET`, the band views outside it
    weighed up for :data:`BAND_ROUNDS` rounds, then fewer: the one :func:`_chosen`, or None."""
    bases, k = _bases(brdf), len(NODES_DEG)
    joint = _systems(target, brdf, bases=True)
    reflectance = np.array([base.reflectance for base in bases])
    with np.errstate(divide="ignore"):
        upper = np.minimum(1.0 / reflectance, BASE_RANGE)    # reflectance <= 1
    lower = np.minimum(1.0 / BASE_RANGE, upper)
    candidates = []
    for rounds in range(BAND_ROUNDS, -1, -1):
        s, b = factors.s.copy(), factors.bases.copy()
        for c, system in enumerate(joint):
            if errors[c] <= BAND_TARGET:
                continue
            x = _pick(system, c, brdf, s, lower[:, c], upper[:, c], rounds)
            if system.band_error(x) < errors[c]:
                s[:, c], b[:, c] = x[:k], x[k:]
        b = _energy_limited(_rebuilt(brdf, s, np.ones_like(b)), bases, b)
        if not np.all(b == 1.0):
            candidates.append(factors._replace(s=s, bases=b))
    return _chosen(target, brdf, candidates, before, before[1])


def _each_lobe(target: AlbedoTarget, brdf, factors: AlbedoFactors, before: tuple):
    """``factors`` with each lobe's own factor ``r_l`` on top of ``s``, solved in the channels
    still outside :data:`BAND_TARGET` (the band views weighed up for :data:`BAND_ROUNDS`
    rounds, then fewer): the one :func:`_chosen` that comes closer to the band, or
    None (also where ``factors`` already reach :data:`BAND_TARGET`). A sharp lobe's energy at
    a view comes from ``theta_d`` near it, a rough one's from a wide range: their own tables
    follow a steep rise of the albedo that one shared table cannot."""
    current = _rebuilt(brdf, *factors)
    band = _band(target, current)[0]
    if band <= BAND_TARGET:
        return None
    systems = _systems(target, current, each=True)
    n_lobes, k = len(factors.each), len(NODES_DEG)
    errors = [system.band_error(np.ones(n_lobes * k)) for system in systems]
    candidates = []
    for rounds in range(BAND_ROUNDS, -1, -1):
        each = factors.each.copy()
        for c, system in enumerate(systems):
            if errors[c] <= BAND_TARGET:
                continue
            x = _pick(system, c, brdf, factors.s, np.zeros(0), np.zeros(0), rounds, each)
            if system.band_error(x) < errors[c]:
                each[:, :, c] = x.reshape(n_lobes, k)
        if not np.array_equal(each, factors.each):
            candidates.append(factors._replace(each=each))
    return _chosen(target, brdf, candidates, before, band)


def _energy_bounded(brdf, factors: AlbedoFactors, steps: int = 7) -> AlbedoFactors:
    """``factors`` with the total albedo of the matched fit below ``1 - ENERGY_MARGIN`` at
    :data:`VIEWS_DEG` and :data:`ENERGY_VIEWS_DEG` (module docstring). Per channel over it:
    first the factor at the nodes above the band views scaled by the ``mu`` at which the
    albedo they carry, taken as linear in ``mu``, meets the bound (2 rounds: the tables are
    clipped), kept if it holds the bound and no table rings; else the largest ceiling of the
    lobes' tables that holds it (bisection, ``steps`` halvings: a ceiling keeps a table's
    single peak or monotone rise), the bases scaled by ``limit / albedo`` where even a
    ceiling of 0 does not; where a capped table rings (a valley), the channel's factors,
    bases and ceiling all scaled by ``limit / albedo`` (``clip(F l s, 0, l c) = l clip(F s, 0,
    c)``: the tables keep their shape, the albedo scales exactly)."""
    views, limit = VIEWS_DEG + ENERGY_VIEWS_DEG, 1.0 - ENERGY_MARGIN
    grazing = np.asarray(NODES_DEG) > max(BAND_VIEWS_DEG)
    s, b, ceiling, each = factors.s.copy(), factors.bases.copy(), factors.ceiling.copy(), factors.each

    def albedo(s, b, c):
        return _albedo(_rebuilt(brdf, s, b, c, each), views)

    a = albedo(s, b, ceiling)
    over = np.any(a > limit, axis=0)
    if not np.any(over):
        return factors
    s_mu, a_mu = s.copy(), a
    for _ in range(2):                               # the grazing nodes scaled down
        low = s_mu.copy()
        low[np.ix_(grazing, over)] = 0.0
        carried = a_mu - albedo(low, b, ceiling)
        with np.errstate(divide="ignore", invalid="ignore"):
            mu = np.where((a_mu > limit) & (carried > 0), 1.0 - (a_mu - limit) / carried, 1.0)
        s_mu[np.ix_(grazing, over)] *= np.clip(mu.min(axis=0), 0.0, 1.0)[over]
        a_mu = albedo(s_mu, b, ceiling)
    rings = np.any([_rings(v) for v in _tables(brdf, s_mu, ceiling, each)[1]], axis=0)
    if np.all(a_mu[:, over] <= limit) and not np.any(rings & over):
        return AlbedoFactors(s_mu, b, ceiling, each)
    b0 = b.copy()
    top = np.max(albedo(s, b, np.where(over, 0.0, ceiling)), axis=0)     # a ceiling of 0: the bases alone
    b *= np.where(over & (top > limit), limit / np.maximum(top, 1e-300) * (1.0 - 1e-9), 1.0)
    low, high = np.zeros(3), ceiling.copy()
    for _ in range(steps):                           # the largest ceiling that holds the bound
        mid = np.where(over, 0.5 * (low + high), ceiling)
        good = np.all(albedo(s, b, mid) <= limit, axis=0)
        low, high = np.where(over & good, mid, low), np.where(over & ~good, mid, high)
    ceiling = np.where(over, low, ceiling)
    rings = over & np.any([_rings(v) for v in _tables(brdf, s, ceiling, each)[1]], axis=0)
    if np.any(rings):          # a capped valley can ring: the channel scaled as a whole, exactly
        scale = np.where(rings, limit / np.max(a, axis=0) * (1.0 - 1e-9), 1.0)
        s, b = s * scale, np.where(rings, b0 * scale, b)
        ceiling = np.where(rings, factors.ceiling * scale, ceiling)
    return AlbedoFactors(s, b, ceiling, each)


def albedo_scale(target: AlbedoTarget, brdf) -> np.ndarray:
    """The factor ``s`` of :func:`albedo_factors` on :data:`NODES_DEG`, ``(K, 3)``: ones
    where ``brdf`` has no microfacet lobe.

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
    >>> s.shape == (len(NODES_DEG), 3), bool(s[0, 0] > 1.5)      # SMOOTHNESS, LOG_WEIGHT, LOG_WEIGHT_IN_BAND: module docstring
    (True, True)
    """
    return albedo_factors(target, brdf).s


def _rebuilt(brdf, s: np.ndarray, b: np.ndarray, ceiling=1.0, each=None):
    """``brdf``'s tree with each lobe's Fresnel term the table ``clip(F s r_l, 0, ceiling)``
    (``r = each``, :func:`_tables`) and each base's reflectance times ``b`` (clipped to 1)."""
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from .analytic import SumBRDF
    cos_d, tables = _tables(brdf, s, ceiling, each)
    tables, factors = iter(tables), iter(b)

    def scaled(part):
        if isinstance(part, MicrofacetBRDF):
            return MicrofacetBRDF(part.distribution, fresnel=fr.Tabulated(cos_d, next(tables)), gaf=part.gaf_model,
                                  shadowing=part.shadowing, dtype=part.dtype)
        if isinstance(part, TransmittedLambertian):
            return TransmittedLambertian(np.clip(part.reflectance * next(factors), 0.0, 1.0), part.eta)
        if isinstance(part, Lambertian):
            factor = next(factors)
            return part if np.all(factor == 1.0) else Lambertian(np.clip(part.reflectance * factor, 0.0, 1.0))
        return part

    if isinstance(brdf, SumBRDF):
        return type(brdf)(*map(scaled, brdf.brdfs), weights=brdf.weights)     # a GGXLobes stays one
    return scaled(brdf)


def match_albedo(reference, brdf, target: AlbedoTarget | None = None):
    """``brdf`` with each microfacet lobe's Fresnel term ``F`` replaced by the table
    ``clip(F s, 0, 1)`` and, where the lobes alone cannot reach the albedo band, each diffuse
    base's reflectance scaled (:func:`albedo_factors`; module docstring), so that its
    directional albedo matches ``reference``'s at :data:`VIEWS_DEG`. ``target``: the
    reference's :func:`albedo_target`, to share among fits. A BRDF without microfacet lobes
    is returned as is.

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
        The same tree with tabulated Fresnel terms (``TABLE_SIZE`` nodes uniform in
        ``theta_d``) and bases of the same classes.

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = match_albedo(data, mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25)))
    >>> type(fit.fresnel).__name__, bool(abs(fit.fresnel(1.0)[0] - 0.5) < 0.02)
    ('Tabulated', True)
    """
    if not _lobes(brdf):
        return brdf
    return _rebuilt(brdf, *albedo_factors(albedo_target(reference) if target is None else target, brdf))
