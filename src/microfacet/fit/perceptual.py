"""Fits that look like the material: analytic models fitted in log space, chosen by image error.

A measured BRDF ``f_d`` is fitted by models of the library's protocol, each by minimizing
the cosine-weighted log error of Löw et al. 2012 (their metric E2, also Bagher et al. 2016):

    E^2 = sum_pairs w sum_c (ln(1 + f_c cos th_i) - ln(1 + f_d,c cos th_i))^2 / (3 sum w)

over pairs ``(wi, wo)`` distributed uniformly in solid angle (importance-sampled at the
specular peak, :func:`microfacet.metrics.uniform_directions`, grazing pairs left out), with
the directional albedo held as a constraint rather than weighed: at views 0/30/60/75 deg
each channel's albedo stays within ``[1 - ALBEDO_BELOW, 1 + ALBEDO_ABOVE]`` of the data's
and at every view up to 89 deg the total stays below 1 (penalty residuals of weight
:data:`PENALTY`, then an exact projection of the upper bounds). The models
(:data:`MODELS`), all with GGX lobes and the height-correlated Smith GAF (Heitz 2014):

* ``"lobe"``: one lobe with Schlick's Fresnel ``F = f0 + (f90 - f0)(1 - cos th_d)^5``
  (``f0`` RGB, ``f90`` grey) plus a Lambertian base ``k_d``;
* ``"two_lobes"``: a sharp core and a wide halo, each with its own Schlick term, plus a
  base (metals and metallic paints: Cook & Torrance 1982 used two lobes for the same
  reason; Löw et al. 2012 Sec. 6);
* ``"mixture"``: a sum of GGX lobes on a fixed ladder of roughnesses
  ``ALPHA_MIN 1.5^(k + 1/2)`` (:data:`LADDER`, 16 rungs up to 1), each with its own Schlick
  term, plus a base (no nonlinear parameter: its basis is evaluated once per fit); a
  non-negative mixture of GGX distributions is a distribution whose tail can fall as slowly
  as the data's (Löw et al. 2012's ABC fits have
  ``D ~ (1 - cos th_h)^-C`` with ``C`` ~1-2 where one GGX lobe falls as ``^-2``); lobes left
  empty by the bounds are dropped;
* ``"dielectric_mixture"``: the mixture with a second base, the diffuse body seen through
  its smooth surface (:class:`microfacet.diffuse.TransmittedLambertian`, index
  :data:`BODY_ETA`): darker at grazing angles where the lobes' Fresnel terms brighten, so
  that a paint's or plastic's albedo can stay flat with the view as the data's does
  (started from the mixture's fit too, so its objective is at most the mixture's);
* ``"coat"``: a dielectric coat of index ``eta`` and its own roughness over a base (a lobe
  plus a Lambertian term) lit through the coat's transmission,
  ``f = f_coat + (1 - E_c(mu_i))(1 - E_c(mu_o)) f_base``
  (:class:`microfacet.layered.LayeredBRDF`; Kelemen & Szirmay-Kalos 2001).

Each model is linear in its reflectances given its nonlinear parameters ``q`` (log
roughnesses, the coat's index): ``f = C(q) + A(q) y``. The fit scans ``q``, solves ``y``
for each scanned ``q`` by a bounded linearized least squares (:func:`.extract.box_qp`),
then refines the best starts by a projected Levenberg-Marquardt method on ``(q, y)``
(Jacobian exact in ``y`` and, for the lobe models, in ``q``: the GGX lobe's derivative in
``log alpha``; forward differences in the coat's ``q``; the normal equations formed
through the basis's Gram matrices). :func:`fit_models` returns every
model's BRDF; :func:`select` picks the one whose rendered spheres look most like the data's
(Bieron & Peers 2020: choose by image error, not by the fitting metric).

Example
-------
>>> import microfacet as mf                                          # doctest: +SKIP
>>> data = mf.measured.load("nickel.binary.gz")                     # doctest: +SKIP
>>> fits = mf.fit.perceptual.fit_models(data)                       # doctest: +SKIP
>>> sorted(fits)                                                    # doctest: +SKIP
['lobe', 'two_lobes']
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import numpy as np

from .._colour import LUMINANCE
from ..metrics import (ALBEDO_VIEWS_DEG, GRAZING_COS, albedo_directions, measured_mask, measurement_directions,
                       uniform_directions)
from ..protocol import directions
from .analytic import SumBRDF
from .extract import box_qp

__all__ = ["MODELS", "MODEL_SPECS", "Geometry", "GGXLobes", "Target", "Model", "target", "fit_model", "fit_parameters", "iter_parameters", "fit_models", "select",
           "lobe_factor", "PENALTY"]

#: The models of :func:`fit_models`, in the order they are fitted.
MODELS = ("lobe", "two_lobes", "mixture", "dielectric_mixture", "coat")
#: Weight of the energy penalty residuals (a 1 % excess costs ~(0.01 PENALTY)^2).
PENALTY = 10.0
#: Weight of the penalty below the albedo band (data whose albedo falls faster with the
#: view than any model's cannot be held to both sides).
PENALTY_BELOW = 0.0
#: Albedo band around the data's at :data:`microfacet.metrics.ALBEDO_VIEWS_DEG`.
ALBEDO_BELOW, ALBEDO_ABOVE = 0.05, 0.01
#: Channels whose data albedo is below this are not held to the band (noise).
ALBEDO_FLOOR = 0.03
#: Views (deg) at which the total albedo must stay below ``1 - ENERGY_MARGIN``.
ENERGY_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0, 85.0, 89.0)
ENERGY_MARGIN = 2e-3
#: Roughness bounds of every lobe.
ALPHA_MIN, ALPHA_MAX = 2e-3, 1.0
#: Index bounds of the coat.
ETA_MIN, ETA_MAX = 1.2, 2.2


#: Compression of ``u = f cos th_i`` in which the fit is made: ``"log"``, ``ln(1 + u)``
#: (Löw et al. 2012), or ``"cbrt"``, ``(u + eps)^(1/3)`` (Bagher et al. 2016; the cube
#: root of the lightness curve that the image error compares).
COMPRESSION = "cbrt"
_CBRT_EPS = 1e-4


def compress(u: np.ndarray) -> np.ndarray:
    """The compression :data:`COMPRESSION` of ``u = f cos th_i >= 0``."""
    if COMPRESSION == "log":
        return np.log1p(u)
    return np.cbrt(u + _CBRT_EPS)


def compress_slope(u: np.ndarray) -> np.ndarray:
    """The derivative of :func:`compress` at ``u``."""
    if COMPRESSION == "log":
        return 1.0 / (1.0 + u)
    return 1.0 / (3.0 * np.cbrt(u + _CBRT_EPS) ** 2)


@dataclass(frozen=True)
class Geometry:
    """Cosines of a set of pairs: ``cos th_i``, ``cos th_o``, ``cos th_h``, ``cos th_d``, each ``(n,)``.

    Parameters
    ----------
    cos_i, cos_o, cos_h, cos_d : (n,) ndarray
        ``cos theta_i``, ``cos theta_o``, ``cos theta_h`` and ``cos theta_d`` of the pairs.

    Examples
    --------
    >>> import numpy as np
    >>> g = Geometry(*np.array([[1.0], [1.0], [1.0], [1.0]]))          # one pair at normal incidence
    >>> g.cos_i, g.cos_h
    (array([1.]), array([1.]))
    """
    cos_i: np.ndarray
    cos_o: np.ndarray
    cos_h: np.ndarray
    cos_d: np.ndarray

    @classmethod
    def of(cls, wi: np.ndarray, wo: np.ndarray) -> "Geometry":
        """The cosines of the pairs ``(wi, wo)``.

        Parameters
        ----------
        wi, wo : (n, 3) ndarray
            Unit light and view directions.

        Returns
        -------
        Geometry
            ``cos theta_i``, ``cos theta_o``, ``cos theta_h``, ``cos theta_d`` of each pair
            (``cos theta_h = cos theta_d = 0`` where ``wo = -wi``).
        """
        h = wi + wo
        n2 = np.einsum("ij,ij->i", h, h)
        inv = np.divide(1.0, np.sqrt(n2), out=np.zeros_like(n2), where=n2 > 0)
        return cls(wi[:, 2].copy(), wo[:, 2].copy(), h[:, 2] * inv,
                   np.clip(np.einsum("ij,ij->i", wi, h) * inv, 0.0, 1.0))

    def __len__(self) -> int:
        return len(self.cos_i)

    # the factors of every lobe that do not depend on its roughness, computed once per pair
    # set; 0 at a pair at or below the horizon, where every lobe is then 0
    @cached_property
    def tan2_i(self) -> np.ndarray:
        """``tan^2 theta_i``."""
        return _tan2(self.cos_i)

    @cached_property
    def tan2_o(self) -> np.ndarray:
        """``tan^2 theta_o``."""
        return _tan2(self.cos_o)

    @cached_property
    def cos2_h(self) -> np.ndarray:
        """``cos^2 theta_h``."""
        return self.cos_h * self.cos_h

    @cached_property
    def jacobian(self) -> np.ndarray:
        """``1 / (4 cos theta_i cos theta_o)``."""
        product = 4.0 * self.cos_i * self.cos_o
        return np.divide(1.0, product, out=np.zeros_like(product), where=(self.cos_i > 0) & (self.cos_o > 0))

    @cached_property
    def schlick(self) -> np.ndarray:
        """Schlick's weight ``(1 - cos theta_d)^5``."""
        m = 1.0 - self.cos_d
        return (m * m) * (m * m) * m


def _tan2(mu: np.ndarray) -> np.ndarray:
    """``tan^2 theta = (1 - mu^2) / mu^2``, 0 where ``mu <= 0``."""
    mu2 = mu * mu
    return np.divide(1.0 - mu2, mu2, out=np.zeros_like(mu2), where=mu > 0)


def _lobe_factors(log_alpha, g: Geometry, slopes: bool = False):
    """:func:`lobe_factor` of every roughness ``exp(log_alpha)`` (``(L,)``) at ``g``: ``(L, n)``;
    with ``slopes``, also its derivative in ``log alpha``,
    ``s (2 - 4 a^2 c^2 / (c^2 (a^2 - 1) + 1) - G2 sum_{i,o} t / (2 sqrt(1 + t)))``,
    ``t = a^2 tan^2`` (differentiating ``D``, and ``Lambda = (sqrt(1 + t) - 1) / 2`` of
    Heitz 2014, Eq. 72, so that ``G2 = 2 / (sqrt(1 + t_i) + sqrt(1 + t_o))``)."""
    log_alpha = np.atleast_1d(np.asarray(log_alpha, dtype=np.float64))
    out = np.empty((len(log_alpha), len(g)))
    slope = np.empty_like(out) if slopes else None
    c2 = g.cos2_h
    for j, a2 in enumerate(np.exp(2.0 * log_alpha)):    # a lobe at a time: its arrays stay in cache
        den = c2 * (a2 - 1.0) + 1.0
        ti, to = a2 * g.tan2_i, a2 * g.tan2_o
        si, so = np.sqrt(1.0 + ti), np.sqrt(1.0 + to)
        g2 = 2.0 / (si + so)                        # 1 + Lambda_i + Lambda_o = (s_i + s_o) / 2
        out[j] = (a2 / np.pi) * g2 * g.jacobian / (den * den)
        if slopes:
            slope[j] = out[j] * (2.0 - 4.0 * a2 * c2 / den - g2 * (ti / (2.0 * si) + to / (2.0 * so)))
    return (out, slope) if slopes else out


def lobe_factor(alpha: float, g: Geometry) -> np.ndarray:
    """``D G2 / (4 cos th_i cos th_o)`` of an isotropic GGX lobe (Eq. 2.1 without ``F``;
    Walter et al. 2007's ``D``, the height-correlated Smith ``G2 = 1 / (1 + Lambda_i +
    Lambda_o)``, Heitz 2014 Eq. 99): equal to ``MicrofacetBRDF(GGX(alpha)).eval`` with
    ``F = 1`` to rounding (tested).

    Parameters
    ----------
    alpha : float
        GGX roughness.
    g : Geometry
        The pairs.

    Returns
    -------
    (n,) ndarray
        ``D G2 / (4 cos theta_i cos theta_o)`` at the pairs.

    References
    ----------
    Walter et al. 2007 (GGX); Heitz 2014, Eq. 99 (height-correlated Smith G2); Dupuy 2015, thesis, Eq. 2.1.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> g = Geometry(*np.array([[0.8], [0.8], [1.0], [0.8]]))      # a mirror pair at 37 degrees
    >>> lobe_factor(0.3, g).round(4)
    array([1.3479])
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.6, 0.0, 0.8])
    >>> float(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)).eval(wi, wo)[0].round(4))     # the same
    1.3479
    """
    return _lobe_factors(np.log(alpha), g)[0]


def dielectric(eta: float, c: np.ndarray) -> np.ndarray:
    """Unpolarized Fresnel reflectance of a dielectric of index ``eta`` (as :class:`microfacet.fresnel.Dielectric`)."""
    g = np.sqrt(np.maximum(eta * eta + c * c - 1.0, 0.0))
    a = (g - c) / (g + c)
    b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
    return 0.5 * a * a * (1.0 + b * b)


@dataclass(frozen=True)
class _AlbedoQuadrature:
    """Half-vector quadrature of the directional albedo at ``n`` views spaced in ``mu``."""
    mu: np.ndarray
    geometry: Geometry
    w: np.ndarray
    view: np.ndarray


def _coat_quadrature(n_mu: int = 24, n_theta: int = 40, n_phi: int = 16) -> _AlbedoQuadrature:
    mu = np.concatenate([[1e-3], np.linspace(0.02, 1.0, n_mu - 1) ** 1.5])
    views = np.degrees(np.arccos(mu))
    wi, wo, w, view = albedo_directions(views, 0.0, n_theta, n_phi)
    return _AlbedoQuadrature(mu, Geometry.of(wi, wo), w, view)


_COAT_NODES: list = []


def coat_albedo(alpha: float, eta: float) -> tuple[np.ndarray, np.ndarray]:
    """``(mu, E_c(mu))``: directional albedo of a GGX lobe of roughness ``alpha`` with the
    dielectric Fresnel of index ``eta`` (single scattering), at 24 views by a half-vector
    quadrature (within ~1e-3 of :func:`microfacet.metrics.directional_albedo`)."""
    if not _COAT_NODES:
        _COAT_NODES.append(_coat_quadrature())
    q = _COAT_NODES[0]
    f = lobe_factor(alpha, q.geometry) * dielectric(eta, q.geometry.cos_d) * q.geometry.cos_i
    e = np.bincount(q.view, q.w * np.where(np.isfinite(f), f, 0.0), minlength=len(q.mu))
    return q.mu, np.minimum(e, 1.0)


@dataclass(frozen=True)
class Model:
    """A model ``f = c(q) + B(q) Y(y)`` of nonlinear parameters ``q`` and reflectances ``y``.

    ``basis(q, g) -> (c (n,) grey or None, B (n, K))``: the model's basis functions at the
    pairs ``g``; ``mix (3, K, len(y))``: the reflectance of basis ``k`` in channel ``c`` is
    ``mix[c, k] @ y``; ``brdf(q, y)`` the library BRDF; ``starts(previous)`` the scanned
    ``q``'s (``previous``: the fitted ``(q, y)`` of earlier models by name).

    Parameters
    ----------
    name : str
        The model's name (:data:`MODELS`).
    q_bounds : (lo, hi) tuple of ndarray
        Bounds of the nonlinear parameters ``q``.
    mix : (3, K, len(y)) ndarray
        Reflectance of basis ``k`` in channel ``c``: ``mix[c, k] @ y``.
    basis : callable
        ``basis(q, g) -> (c, B)``.
    brdf : callable
        ``brdf(q, y)``: the library BRDF.
    starts : callable
        ``starts(previous)``: the scanned ``q``'s.
    slopes : callable, optional
        ``slopes(q, g) -> (c, B, dc, dB)``: the basis and its derivatives in each ``q``,
        ``dc (len(q), n)`` or None and ``dB (len(q), n, K)`` (None: forward differences).

    Examples
    --------
    >>> MODELS, PENALTY
    (('lobe', 'two_lobes', 'mixture', 'dielectric_mixture', 'coat'), 10.0)
    >>> spec = MODEL_SPECS["lobe"]
    >>> isinstance(spec, Model), spec.name, spec.mix.shape
    (True, 'lobe', (3, 3, 7))
    """
    name: str
    q_bounds: tuple[np.ndarray, np.ndarray]
    mix: np.ndarray
    basis: Callable
    brdf: Callable
    starts: Callable
    slopes: Callable | None = None

    @property
    def n_y(self) -> int:
        return self.mix.shape[-1]


def _basis_rows(s: np.ndarray, g: Geometry, extra: tuple = ()) -> np.ndarray:
    """The basis ``(2L + 1 + len(extra), n)`` of lobe factors ``s (L, n)``: each lobe weighted by
    Schlick's ``f0`` and ``f90`` terms, ``s (1 - m^5)`` and ``s m^5`` (``m = 1 - cos th_d``),
    then the Lambertian base ``1 / pi``, then the rows ``extra``; its transpose is the
    ``(n, K)`` basis of :class:`Model` (rows, so that each is written contiguously)."""
    n_lobes = len(s)
    out = np.empty((2 * n_lobes + 1 + len(extra), s.shape[1]))
    np.multiply(s, g.schlick, out=out[1:2 * n_lobes:2])
    np.subtract(s, out[1:2 * n_lobes:2], out=out[0:2 * n_lobes:2])
    out[2 * n_lobes] = 1.0 / np.pi
    for k, row in enumerate(extra):
        out[2 * n_lobes + 1 + k] = row
    return out


def _finite(a: np.ndarray) -> np.ndarray:
    """``a`` with its non-finite entries set to 0."""
    return np.where(np.isfinite(a), a, 0.0)


def _lobes_mix(n_lobes: int) -> np.ndarray:
    """``mix`` of ``n_lobes`` Schlick lobes (``f0`` RGB, grey ``f90`` each) and a Lambertian base (RGB)."""
    k, n = 2 * n_lobes + 1, 4 * n_lobes + 3
    mix = np.zeros((3, k, n))
    for c in range(3):
        for j in range(n_lobes):
            mix[c, 2 * j, 4 * j + c] = 1.0
            mix[c, 2 * j + 1, 4 * j + 3] = 1.0
        mix[c, 2 * n_lobes, 4 * n_lobes + c] = 1.0
    return mix


def _lobes_basis(q, g):
    return None, _basis_rows(_lobe_factors(q, g), g).T


def _lobes_slopes(q, g):
    """``(c, B, dc, dB)``: :func:`_lobes_basis` and its derivatives in each ``q`` (lobe ``j``'s
    log roughness moves lobe ``j``'s two columns only)."""
    s, ds = _lobe_factors(q, g, slopes=True)
    db = np.zeros((len(q), 2 * len(q) + 1, len(g)))
    for j in range(len(q)):
        db[j, 2 * j:2 * j + 2] = _basis_rows(ds[j:j + 1], g)[:2]
    return None, _basis_rows(s, g).T, None, db.transpose(0, 2, 1)


def _ggx_lobe(alpha, f0, f90):
    from ..brdf import MicrofacetBRDF
    from ..distributions import GGX
    from ..fresnel import Schlick
    return MicrofacetBRDF(GGX(alpha=float(alpha)), fresnel=Schlick(np.clip(f0, 0, 1), float(np.clip(f90, 0, 1))))


def _luminance(rgb) -> float:
    return float(np.dot(LUMINANCE, rgb))


def _sum(parts, weights):
    return parts[0] if len(parts) == 1 else GGXLobes(*parts, weights=np.maximum(weights, 0.02))


def _isotropic_ggx(part) -> bool:
    """Whether ``part`` is a lobe of :func:`lobe_factor`: a float64 Smith (height-correlated,
    shadowing) :class:`~microfacet.brdf.MicrofacetBRDF` of a central isotropic GGX."""
    from ..brdf import MicrofacetBRDF
    from ..distributions import GGX
    if not (isinstance(part, MicrofacetBRDF) and isinstance(part.distribution, GGX)):
        return False
    d = part.distribution
    return (part.gaf_model == "smith" and part.shadowing and part.dtype == np.float64 and d.alpha_x == d.alpha_y
            and d.rho == 0.0 and not np.any(d.mean_slope))


class GGXLobes(SumBRDF):
    """The :class:`~microfacet.fit.SumBRDF` of the perceptual fits, whose isotropic GGX lobes
    are evaluated together: the pairs' :class:`Geometry` once per call, then each lobe's
    :func:`lobe_factor` (the closed form of ``D G2 / (4 cos th_i cos th_o)``) times its own
    Fresnel term at ``cos th_d``; the other parts (bases, other lobes) by their own ``eval``.
    Equal to the :class:`~microfacet.fit.SumBRDF` of the same parts to rounding (tested);
    sampling, ``pdf`` and the fit file's spec are the sum's.

    Parameters
    ----------
    *brdfs : BRDF
        The terms.
    weights : sequence of float, optional
        Probabilities of sampling each term (:class:`~microfacet.fit.SumBRDF`).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> parts = (mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.9)),
    ...          mf.MicrofacetBRDF(mf.GGX(alpha=0.4), mf.fresnel.Schlick(0.2)), mf.Lambertian(0.1))
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.5, 0.1, np.sqrt(0.74)])
    >>> bool(np.allclose(GGXLobes(*parts).eval(wi, wo), mf.fit.SumBRDF(*parts).eval(wi, wo), rtol=1e-12))
    True
    """

    def __init__(self, *brdfs, weights=None):
        super().__init__(*brdfs, weights=weights)
        self._lobes = [b for b in self.brdfs if _isotropic_ggx(b)]
        self._others = [b for b in self.brdfs if not _isotropic_ggx(b)]
        self._log_alpha = np.log([b.distribution.alpha_x for b in self._lobes])

    def _factors(self, wi, wo, cos: bool):
        """The broadcast pairs ``(wi, wo)``, their :class:`Geometry` (flattened) and the lobes'
        :func:`_lobe_factors`, times ``cos theta_i`` with ``cos`` (0 below either horizon)."""
        wi, wo = np.broadcast_arrays(directions(wi, "wi"), directions(wo, "wo"))
        g = Geometry.of(wi.reshape(-1, 3), wo.reshape(-1, 3))
        return wi, wo, g, _lobe_factors(self._log_alpha, g) * (g.cos_i if cos else 1.0)

    def _sum(self, wi, wo, cos: bool) -> np.ndarray:
        wi, wo, g, s = self._factors(wi, wo, cos)
        total = np.zeros(wi.shape)
        for b in self._others:
            total += b.eval_cos(wi, wo) if cos else b.eval(wi, wo)
        if self._lobes:
            total += _fresnel_sum([lobe.fresnel for lobe in self._lobes], s, g.cos_d).reshape(wi.shape)
        return total

    def terms_cos(self, wi, wo) -> list:
        """:meth:`microfacet.fit.SumBRDF.terms_cos`, the lobes' from one :class:`Geometry` and
        their closed form, each times its own Fresnel term.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.

        Returns
        -------
        list of (..., 3) ndarray
            The terms' ``eval_cos``, equal to their own to rounding (tested).
        """
        wi, wo, g, s = self._factors(wi, wo, True)
        lobes = iter(s[k][:, None] * lobe.fresnel(g.cos_d) for k, lobe in enumerate(self._lobes))
        return [next(lobes).reshape(wi.shape) if _isotropic_ggx(b) else b.eval_cos(wi, wo) for b in self.brdfs]


#: Pairs per block of :func:`_fresnel_sum`'s table lookups (their ``(pairs, lobes x RGB)``
#: arrays stay in cache).
TABLE_BLOCK = 4096


def _fresnel_sum(fresnels: list, s: np.ndarray, cos_d: np.ndarray) -> np.ndarray:
    """``sum_k s_k F_k(cos_d)``, ``(n, 3)``, of the Fresnel terms ``fresnels`` and factors ``s``
    ``(L, n)``: Schlick terms through two matrix products, tables on one grid through one
    lookup of the grid (the tables of :func:`microfacet.fit.albedo.match_albedo`), any other
    term by its own call."""
    from ..fresnel import Schlick, Tabulated
    out = np.zeros((len(cos_d), 3))
    kinds = [Schlick if type(f) is Schlick else Tabulated if type(f) is Tabulated else None for f in fresnels]
    schlick = [k for k, kind in enumerate(kinds) if kind is Schlick]
    if schlick:
        f0 = np.array([np.broadcast_to(fresnels[k].f0, 3) for k in schlick])
        f90 = np.array([np.broadcast_to(fresnels[k].f90, 3) for k in schlick])
        m = 1.0 - np.clip(cos_d, 0.0, 1.0)
        out += s[schlick].T @ f0 + ((m * m) * (m * m) * m)[:, None] * (s[schlick].T @ (f90 - f0))
    grid = next((fresnels[k].cos_theta_d for k, kind in enumerate(kinds) if kind is Tabulated), None)
    tables = [k for k, kind in enumerate(kinds) if kind is Tabulated and np.array_equal(fresnels[k].cos_theta_d, grid)]
    if tables:
        rows = np.stack([fresnels[k].values for k in tables], axis=1).reshape(len(grid), -1)   # (J, L 3)
        i = np.clip(np.searchsorted(grid, cos_d, side="right") - 1, 0, len(grid) - 2)
        t = np.clip((cos_d - grid[i]) / (grid[i + 1] - grid[i]), 0.0, 1.0)    # np.interp's, clamped at the ends
        s_tables = s[tables]
        for a in range(0, len(cos_d), TABLE_BLOCK):      # every lobe's RGB at a pair's nodes, a block at a time
            b = slice(a, a + TABLE_BLOCK)
            lo, v = np.take(rows, i[b], axis=0), np.take(rows, i[b] + 1, axis=0)
            v -= lo
            v *= t[b, None]
            v += lo
            out[b] += np.einsum("kn,nkc->nc", s_tables[:, b], v.reshape(len(lo), len(tables), 3))
    for k in set(range(len(fresnels))) - set(schlick) - set(tables):
        out += s[k][:, None] * fresnels[k](cos_d)
    return out


def _lobes_brdf(q, y):
    """Lobes (each ``f0`` RGB, ``f90``) and a Lambertian base, as a SumBRDF (base dropped when negligible)."""
    from ..brdf import Lambertian
    parts, weights = [], []
    for j, lq in enumerate(q):
        f0, f90 = y[4 * j:4 * j + 3], y[4 * j + 3]
        if max(np.max(f0), f90) < EMPTY_LOBE:    # an empty lobe (most of the mixture's)
            continue
        parts.append(_ggx_lobe(np.exp(lq), f0, f90))
        weights.append(_luminance(f0) + 0.05 * f90)
    kd = np.clip(y[-3:], 0.0, 1.0)
    if np.max(kd) >= 2e-3:
        parts.append(Lambertian(kd))
        weights.append(_luminance(kd))
    return _sum(parts, weights)


#: Reflectances below this are set to 0 after the fit: Levenberg-Marquardt approaches the
#: bound 0 without reaching it (1e-22 - 1e-8 left), and such dust makes a channel's Fresnel
#: table a rescaled copy of the albedo match's factor, ringing where the factor does.
DUST = 1e-6
#: A lobe whose ``f0`` and ``f90`` are all below this is left out of the BRDF (its
#: albedo is below ~1e-3 at every view).
EMPTY_LOBE = 1e-3
#: Roughness ratio between the lobes of the ``"mixture"`` model, and their number.
MIXTURE_RATIO, MIXTURE_LOBES = 1.5, 16
#: Log roughnesses of the mixture's lobes: ``ALPHA_MIN sqrt(RATIO) RATIO^k``, capped at
#: :data:`ALPHA_MAX`. Fixed: an offset fitted within one rung stays near this one, and would
#: cost the basis anew at every step.
LADDER = np.minimum(np.log(ALPHA_MIN) + np.log(MIXTURE_RATIO) * (np.arange(MIXTURE_LOBES) + 0.5), np.log(ALPHA_MAX))
#: Bounds of the nonlinear parameters of a model that has none.
NO_Q = (np.zeros(0), np.zeros(0))


def _mixture_basis(q, g):
    return _lobes_basis(LADDER, g)


def _mixture_brdf(q, y):
    return _lobes_brdf(LADDER, y)


#: Index of the surface that the ``"dielectric_mixture"`` model's second base is seen through.
BODY_ETA = 1.5


def _transmittance(mu: np.ndarray) -> np.ndarray:
    """``t(mu) / t(1)`` of :class:`microfacet.diffuse.TransmittedLambertian` at :data:`BODY_ETA`."""
    return (1.0 - dielectric(BODY_ETA, mu)) / (1.0 - dielectric(BODY_ETA, np.ones(1)))


def _dielectric_mix() -> np.ndarray:
    """The mixture's ``mix`` with a third base (RGB): the diffuse seen through the surface."""
    base = _lobes_mix(MIXTURE_LOBES)
    k, n = base.shape[1:]
    mix = np.zeros((3, k + 1, n + 3))
    mix[:, :k, :n] = base
    for c in range(3):
        mix[c, k, n + c] = 1.0
    return mix


def _body(g) -> np.ndarray:
    """The second base: the diffuse body seen through the surface, ``t(mu_i) t(mu_o) / pi``."""
    return _transmittance(g.cos_i) * _transmittance(g.cos_o) / np.pi


def _dielectric_basis(q, g):
    return None, _basis_rows(_lobe_factors(LADDER, g), g, (_body(g),)).T


def _dielectric_brdf(q, y):
    from ..diffuse import TransmittedLambertian
    mixture = _mixture_brdf(q, y[:-3])
    parts = list(getattr(mixture, "brdfs", [mixture]))
    weights = list(getattr(mixture, "weights", [1.0]))
    body = np.clip(y[-3:], 0.0, 1.0)
    if np.max(body) >= 2e-3:
        parts.append(TransmittedLambertian(body, BODY_ETA))
        weights.append(_luminance(body))
    return _sum(parts, weights)


def _mixture_starts(previous):
    return [np.zeros(0)]


def _dielectric_starts(previous):
    """The linearized start, and the mixture's fit with an empty body: no worse than it."""
    starts = _mixture_starts(previous)
    if "mixture" in previous:
        starts.append((np.zeros(0), np.concatenate([previous["mixture"][1], np.zeros(3)])))
    return starts


def _lobe_starts(previous):
    return [np.array([np.log(a)]) for a in (0.002, 0.006, 0.02, 0.06, 0.15, 0.35, 0.8)]


def _two_lobe_starts(previous):
    starts = [np.log([core, min(core * ratio, 0.9)]) for core in (0.002, 0.008, 0.03, 0.1) for ratio in (4.0, 15.0)]
    if "lobe" in previous:                       # the one-lobe fit plus an empty halo: no worse than it
        q, y = previous["lobe"]
        starts.append((np.append(q, np.log(0.5)), np.concatenate([y[:4], np.zeros(4), y[4:]])))
    return starts


def _coat_basis(q, g):
    alpha_c, eta, alpha_b = np.exp(q[0]), q[1], np.exp(q[2])
    mu, e = coat_albedo(alpha_c, eta)
    t = (1.0 - np.interp(g.cos_i, mu, e)) * (1.0 - np.interp(g.cos_o, mu, e))
    coat = lobe_factor(alpha_c, g) * dielectric(eta, g.cos_d)
    _, base = _lobes_basis(q[2:], g)
    return coat, base * t[:, None]


def _coat_brdf(q, y):
    from ..brdf import MicrofacetBRDF
    from ..distributions import GGX
    from ..fresnel import Dielectric
    from ..layered import LayeredBRDF
    coat = MicrofacetBRDF(GGX(alpha=float(np.exp(q[0]))), fresnel=Dielectric(float(q[1])))
    return LayeredBRDF(coat, _lobes_brdf(q[2:], y))


def _coat_starts(previous):
    starts = [np.array([np.log(ac), 1.5, np.log(ab)]) for ac in (0.004, 0.02, 0.08) for ab in (0.1, 0.4)]
    if "lobe" in previous:                   # the one lobe's highlight as the coat's, over a rough base
        alpha = previous["lobe"][0][0]
        starts += [np.array([alpha, eta, np.log(ab)]) for eta in (1.25, 1.5) for ab in (0.1, 0.4)]
    return starts


def _log_bounds(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.full(n, np.log(ALPHA_MIN)), np.full(n, np.log(ALPHA_MAX))


#: The models by name.
MODEL_SPECS = {
    "lobe": Model("lobe", _log_bounds(1), _lobes_mix(1), _lobes_basis, _lobes_brdf, _lobe_starts, _lobes_slopes),
    "two_lobes": Model("two_lobes", _log_bounds(2), _lobes_mix(2), _lobes_basis, _lobes_brdf, _two_lobe_starts,
                       _lobes_slopes),
    "mixture": Model("mixture", NO_Q, _lobes_mix(MIXTURE_LOBES), _mixture_basis, _mixture_brdf, _mixture_starts),
    "dielectric_mixture": Model("dielectric_mixture", NO_Q, _dielectric_mix(), _dielectric_basis, _dielectric_brdf,
                                _dielectric_starts),
    "coat": Model("coat", (np.array([np.log(ALPHA_MIN), ETA_MIN, np.log(ALPHA_MIN)]),
                           np.array([np.log(ALPHA_MAX), ETA_MAX, np.log(ALPHA_MAX)])), _lobes_mix(1),
                  _coat_basis, _coat_brdf, _coat_starts),
}


@dataclass(frozen=True)
class Target:
    """The data's side of the objective.

    ``geometry`` holds the fitted pairs (first ``n_pairs``) then the albedo nodes;
    ``sqrt_w`` the pairs' normalized weights' roots, ``scale`` the factor of each pair's
    ``u = f cos th_i`` before compression, ``log_data`` ``compress(scale u_d)``;
    ``albedo_w``/``albedo_view`` the nodes' weights (times ``cos th_i``) and views
    (:data:`ENERGY_VIEWS_DEG`), ``ratio_mask`` the nodes counted in the albedo ratios,
    ``albedo_data`` the data's albedo at :data:`microfacet.metrics.ALBEDO_VIEWS_DEG`.

    Parameters
    ----------
    geometry : Geometry
        The fitted pairs, then the albedo nodes.
    n_pairs : int
        Number of fitted pairs.
    sqrt_w : ndarray
        Square roots of the pairs' normalized weights.
    scale : ndarray
        Factor of each pair's ``u = f cos theta_i`` before compression.
    log_data : ndarray
        ``compress(scale u_d)`` of the data.
    f_data : ndarray
        The data's ``f_r`` at the pairs.
    albedo_w, albedo_view : ndarray
        Albedo nodes' weights (times ``cos theta_i``) and views.
    ratio_mask : ndarray
        Nodes counted in the albedo ratios.
    albedo_data : ndarray
        The data's albedo at :data:`microfacet.metrics.ALBEDO_VIEWS_DEG`.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = target(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), n=64, grid=4, image_size=0, albedo_grid=(8, 4))
    >>> isinstance(t, Target), isinstance(t.geometry, Geometry), t.n_pairs
    (True, True, 81)
    """
    geometry: Geometry
    n_pairs: int
    sqrt_w: np.ndarray
    scale: np.ndarray
    log_data: np.ndarray   # compress(f_d cos th_i)
    f_data: np.ndarray
    albedo_w: np.ndarray
    albedo_view: np.ndarray
    ratio_mask: np.ndarray
    albedo_data: np.ndarray

    @property
    def view_starts(self) -> np.ndarray:
        """Index of each view's first albedo node (nodes are grouped by view, in order)."""
        return np.searchsorted(self.albedo_view, np.arange(self.albedo_view.max() + 1))


def _image_pairs(size: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wi, wo, image)``: the lit pixels of ``size``-px orthographic spheres under the
    directional lights of :data:`microfacet.metrics.IMAGE_LIGHTS_DEG` (both cosines at
    least :data:`~microfacet.metrics.GRAZING_COS`), each pixel one pair, and its image index."""
    from ..metrics import IMAGE_LIGHTS_DEG
    from ..render.sphere import Sphere
    sphere = Sphere(size)
    wis, wos, index = [], [], []
    for j, (angle, azimuth) in enumerate(IMAGE_LIGHTS_DEG):
        a, b = np.radians(angle), np.radians(azimuth)
        wi = sphere.to_local(np.array([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)]))
        lit = (wi[:, 2] >= GRAZING_COS) & (sphere.wo[:, 2] >= GRAZING_COS)
        wis.append(wi[lit]), wos.append(sphere.wo[lit]), index.append(np.full(int(lit.sum()), j))
    return np.concatenate(wis), np.concatenate(wos), np.concatenate(index)


def target(reference, n: int = 2**12, seed: int = 7, grid: int = 16, image_size: int = 24,
           albedo_grid: tuple[int, int] = (64, 16)) -> Target:
    """The data's side of the objective for ``reference`` (any BRDF; MERL samples not
    measured are left out). Up to three sets of pairs, each with an equal share of the weight:

    * ``n`` Sobol pairs uniform in solid angle (seed ``seed``: not the seed-0 pairs of
      :class:`microfacet.metrics.LogError`, so that the reported error is held out);
    * a ``grid^3`` grid of MERL coordinates (:func:`microfacet.metrics.measurement_directions`,
      dense at the specular peak, as the MERL samples Löw et al. 2012 fitted), so that the
      peak, which carries a glossy material's energy, is not left to ~2 % of the weight;
    * the pixels of ``image_size``-px spheres (0: none) under the image error's three
      directional lights (:func:`_image_pairs`), each compared relative to its image's
      99th-percentile value as the image error's lightness does (Bieron & Peers 2020 fit
      in image space);

    and ``albedo_grid``: the albedo quadrature (half-vector ``theta x phi`` nodes per view).

    Parameters
    ----------
    reference : BRDF
        The material.
    n : int
        Sobol pairs uniform in solid angle.
    seed : int
        Their scramble seed.
    grid : int
        Nodes per MERL coordinate of the grid pairs.
    image_size : int
        Side of the spheres whose pixels are pairs (0: none).
    albedo_grid : (int, int)
        Half-vector ``theta x phi`` nodes of the albedo quadrature, per view.

    Returns
    -------
    Target

    Examples
    --------
    >>> import microfacet as mf
    >>> t = target(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), n=64, grid=4, image_size=0, albedo_grid=(8, 4))
    >>> t.n_pairs, t.albedo_data.shape
    (81, (4, 3))
    """
    wi, wo, w = uniform_directions(n, seed)
    gi, go = measurement_directions(grid)
    ii, io, image = _image_pairs(image_size) if image_size else (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))
    sets = [np.zeros(len(w)), np.ones(len(gi)), 2.0 + image]       # 0 uniform, 1 grid, 2 + j image j
    w = np.concatenate([w / w.sum(), np.full(len(gi), 1.0 / len(gi)), np.full(len(ii), 1.0 / max(len(ii), 1))])
    wi, wo, group = np.concatenate([wi, gi, ii]), np.concatenate([wo, go, io]), np.concatenate(sets)
    keep = measured_mask(reference, wi, wo)
    wi, wo, w, group = wi[keep], wo[keep], w[keep], group[keep]
    f = np.asarray(reference.eval(wi, wo), dtype=np.float64)
    ok = np.all(np.isfinite(f), axis=-1) & np.all(f >= 0, axis=-1)
    wi, wo, w, f, group = wi[ok], wo[ok], w[ok], f[ok], group[ok]
    if len(w) < 64:
        raise ValueError("the reference has too few measured pairs to fit")
    # robust to isolated outliers (e.g. a corrupt sample): clamp to 50x the 99.9th percentile
    f = np.minimum(f, 50.0 * max(float(np.quantile(f, 0.999)), 1e-6))
    u = f * wi[:, 2:3]
    scale = np.ones(len(w))
    for j in np.unique(group[group >= 2]):                     # each image relative to its white
        pixels = group == j
        white = float(np.percentile(u[pixels] @ LUMINANCE, 99.0))
        scale[pixels] = 1.0 / white if white > 0 else 1.0
    views = tuple(ALBEDO_VIEWS_DEG) + tuple(v for v in ENERGY_VIEWS_DEG if v not in ALBEDO_VIEWS_DEG)
    ai, ao, aw, av = albedo_directions(views, 0.0, *albedo_grid)
    ratio = (ai[:, 2] >= GRAZING_COS) & (av < len(ALBEDO_VIEWS_DEG)) & measured_mask(reference, ai, ao)
    fa = np.zeros((len(aw), 3))
    fa[ratio] = np.asarray(reference.eval(ai[ratio], ao[ratio]), dtype=np.float64)
    fa = np.where(np.isfinite(fa) & (fa >= 0), fa, 0.0)
    aw = aw * ai[:, 2]
    data_albedo = np.stack([np.bincount(av[ratio], aw[ratio] * fa[ratio, c], minlength=len(ALBEDO_VIEWS_DEG))
                            for c in range(3)], -1)
    geometry = Geometry.of(np.concatenate([wi, ai]), np.concatenate([wo, ao]))
    w = w / (3.0 * w.sum())
    return Target(geometry, len(w), np.sqrt(w), scale, compress(u * scale[:, None]), f, aw, av, ratio, data_albedo)


class _Problem:
    """The residuals of one model against a :class:`Target`, and their normal equations."""

    def __init__(self, model: Model, t: Target):
        self.model, self.t = model, t
        self.lo = np.concatenate([model.q_bounds[0], np.zeros(model.n_y)])
        self.hi = np.concatenate([model.q_bounds[1], np.ones(model.n_y)])
        self.nq = len(model.q_bounds[0])
        self.band_mask = t.albedo_data > ALBEDO_FLOOR
        self._last_basis = (None, None)

    def basis(self, q):
        """``model.basis(q, geometry)``, remembered for the last ``q`` (a model without
        ``q``, or a step that leaves it at a bound, keeps its basis)."""
        key = np.asarray(q, dtype=np.float64).tobytes()
        if self._last_basis[0] != key:
            self._last_basis = (key, self.model.basis(q, self.t.geometry))
        return self._last_basis[1]

    def values(self, q, y):
        """``(f (n, 3), c, B)`` at all pairs and albedo nodes."""
        c, basis = self.basis(q)
        return self._combine(c, basis, y), c, basis

    def _combine(self, c, basis, y):
        f = basis @ (self.model.mix @ y).T
        if c is not None:
            f += c[:, None]
        return _finite(f)

    def albedo(self, f, mask=None):
        """Albedo ``(views, 3)`` of values ``f`` at the albedo nodes (``mask``: the ratio nodes)."""
        t = self.t
        return self._albedo_sums(f, t.albedo_w if mask is None else t.albedo_w * mask)

    def _fit_residuals(self, f):
        """``(r (n, 3), u)``: the weighted compressed differences at the pairs and ``u = f cos th_i`` scaled."""
        t, n = self.t, self.t.n_pairs
        u = np.maximum(f[:n], 0.0) * t.geometry.cos_i[:n, None] * t.scale[:, None]
        return t.sqrt_w[:, None] * (compress(u) - t.log_data), u

    def residuals(self, x):
        """The residuals at ``x = (q, y)``: the weighted log differences (pairs x RGB), the
        albedo band's and the energy bound's penalties."""
        f = self.values(x[:self.nq], x[self.nq:])[0]
        r_band, r_energy, _, _ = self._energy(f)
        return np.concatenate([self._fit_residuals(f)[0].ravel(), r_band.ravel(), r_energy.ravel()])

    def normal_equations(self, x):
        """``(cost, J^T J, J^T r)`` at ``x = (q, y)``, ``cost = r^T r``: the Jacobian exact in
        ``y``, and in ``q`` where the model has :attr:`Model.slopes` (forward differences
        otherwise); the pairs' rows are summed per channel through the basis's Gram matrix
        (``B^T diag(d_c^2) B``, ``K x K``), never formed."""
        t, nq, mix = self.t, self.nq, self.model.mix
        q, y = x[:nq], x[nq:]
        c, basis, df = self._basis_slopes(q, y)
        f = self._combine(c, basis, y)
        r_fit, u = self._fit_residuals(f)
        r_band, r_energy, band_scale, energy_active = self._energy(f)
        n = t.n_pairs
        d = t.sqrt_w[:, None] * t.geometry.cos_i[:n, None] * t.scale[:, None] * compress_slope(u)
        jtj, jtr = self.gram(basis[:n], d, r_fit)
        jtj = np.pad(jtj, ((nq, 0), (nq, 0)))
        jtr = np.concatenate([np.zeros(nq), jtr])
        for ch in range(3):                          # the q columns of the pairs' rows
            dq = df[:n, ch] * d[:, ch, None]          # (n, nq)
            cross = mix[ch].T @ (basis[:n].T @ (dq * d[:, ch, None]))     # (n_y, nq)
            jtj[:nq, :nq] += dq.T @ dq
            jtj[nq:, :nq] += cross
            jtj[:nq, nq:] += cross.T
            jtr[:nq] += dq.T @ r_fit[:, ch]
        # the penalties' few rows, formed
        j_ratio = self._albedo_jacobian(basis, df, t.albedo_w * t.ratio_mask)[:len(ALBEDO_VIEWS_DEG)]
        j_all = self._albedo_jacobian(basis, df, t.albedo_w)
        rows = np.concatenate([(band_scale[..., None] * j_ratio).reshape(-1, len(x)),
                               (energy_active[..., None] * PENALTY * j_all).reshape(-1, len(x))])
        r_rows = np.concatenate([r_band.ravel(), r_energy.ravel()])
        cost = float(np.sum(r_fit * r_fit) + r_rows @ r_rows)
        return cost, jtj + rows.T @ rows, jtr + rows.T @ r_rows

    def gram(self, basis, w, v):
        """``(sum_c M_c^T A_c^T A_c M_c, sum_c M_c^T A_c^T v_c)``, ``A_c = diag(w_c) B``,
        ``M_c = mix[c]``: the normal equations in ``y`` of rows ``w_c B M_c y ~ v_c``
        (``basis`` ``(n, K)``, ``w``, ``v`` ``(n, 3)``)."""
        mix = self.model.mix
        h, b = np.zeros((mix.shape[2],) * 2), np.zeros(mix.shape[2])
        for ch in range(3):
            a = basis * w[:, ch, None]
            h += mix[ch].T @ (a.T @ a) @ mix[ch]
            b += mix[ch].T @ (a.T @ v[:, ch])
        return h, b

    def _basis_slopes(self, q, y):
        """``(c, B, df)``: the basis at ``q`` and ``d f / d q`` ``(N, 3, nq)`` at all rows."""
        g, model = self.t.geometry, self.model
        if model.slopes is not None:
            c, basis, dc, db = model.slopes(q, g)
            yc = (model.mix @ y).T                                   # (K, 3)
            df = np.stack([db[k] @ yc + (0.0 if dc is None else dc[k][:, None]) for k in range(len(q))], -1)
            return c, basis, df
        c, basis = self.basis(q)
        f = self._combine(c, basis, y)
        df = np.empty(f.shape + (len(q),))
        for k in range(len(q)):
            h = 1e-5 * max(1.0, abs(q[k]))
            qk = q.copy()
            qk[k] += h
            df[..., k] = (self.values(qk, y)[0] - f) / h
        return c, basis, df

    def _albedo_jacobian(self, basis, df, w):
        """``d albedo / d x`` ``(views, 3, nq + n_y)`` with the albedo weights ``w``."""
        sums = self._albedo_sums(basis, w)                          # (views, K)
        nq = df.shape[-1]
        return np.concatenate([self._albedo_sums(df.reshape(len(df), -1), w).reshape(len(sums), 3, nq),
                               np.einsum("vk,cky->vcy", sums, self.model.mix)], axis=2)

    def _albedo_sums(self, values, w):
        """Per view, the sums of ``values`` (rows: all pairs then the albedo nodes) at the
        albedo nodes weighted by ``w``: albedos, or their basis functions' (linear in ``y``)."""
        t = self.t
        return np.add.reduceat(values[t.n_pairs:] * w[:, None], t.view_starts, axis=0)

    def _energy(self, f):
        """Penalty residuals of the albedo band (:data:`PENALTY` above it, :data:`PENALTY_BELOW`
        below: the bound above is the constraint) and of the energy bound, and the derivative
        factors of their active entries."""
        ratio_albedo = self.albedo(f, self.t.ratio_mask)[:len(ALBEDO_VIEWS_DEG)]
        ad = np.where(self.band_mask, self.t.albedo_data, 1.0)
        ratio = ratio_albedo / ad
        excess = np.where(self.band_mask, ratio - np.clip(ratio, 1.0 - ALBEDO_BELOW, 1.0 + ALBEDO_ABOVE), 0.0)
        weight = np.where(excess > 0, PENALTY, PENALTY_BELOW)
        band_scale = np.where(excess != 0.0, weight / ad, 0.0)
        total = self.albedo(f)
        over = np.maximum(total - (1.0 - ENERGY_MARGIN), 0.0)
        return weight * excess, PENALTY * over, band_scale, (over > 0).astype(float)

    def linear_start(self, q) -> np.ndarray:
        """``y`` minimizing, in the box, the log error linearized about the data
        (``ln(1 + u) ~ ln(1 + u_d) + (u - u_d) / (1 + u_d)``) plus the albedo band's
        residuals taken as equalities (the data's albedo at the ratio views)."""
        t, mix = self.t, self.model.mix
        c, basis = self.basis(q)
        c = np.zeros(len(basis)) if c is None else _finite(c)
        n = t.n_pairs
        ci = t.geometry.cos_i[:n, None]
        k = t.scale[:, None]
        wt = t.sqrt_w[:, None] * ci * k * compress_slope(t.f_data * ci * k)
        h, b = self.gram(basis[:n], wt, (t.f_data - c[:n, None]) * wt)
        ad = np.where(self.band_mask, t.albedo_data, 1.0)
        scale = np.where(self.band_mask, PENALTY_BELOW / ad, 0.0)
        sums = self._albedo_sums(basis, t.albedo_w * t.ratio_mask)[:len(ALBEDO_VIEWS_DEG)]
        rows = (np.einsum("vk,cky->vcy", sums, mix) * scale[..., None]).reshape(-1, mix.shape[2])
        c_albedo = self.albedo(np.repeat(c[:, None], 3, axis=1), t.ratio_mask)[:len(ALBEDO_VIEWS_DEG)]
        rhs = ((t.albedo_data - c_albedo) * scale).ravel()
        h = h + rows.T @ rows
        h += np.eye(len(h)) * (1e-10 * np.trace(h) / len(h) + 1e-30)
        return box_qp(h, b + rows.T @ rhs, np.zeros(len(h)), np.ones(len(h)))


def _levenberg_marquardt(problem: _Problem, x0: np.ndarray, max_iter: int = 40, tol: float = 1e-6) -> tuple:
    """Projected Levenberg-Marquardt on the box ``[lo, hi]``: ``(x, cost)``. Variables held
    at a bound by the gradient are frozen for the step (Bertsekas 1982's projection idea);
    the damping adapts by Nielsen's rule."""
    lo, hi = problem.lo, problem.hi
    x = np.clip(x0, lo, hi)
    cost, jtj, g = problem.normal_equations(x)
    lam, nu = 1e-3, 2.0
    for _ in range(max_iter):
        held = ((x <= lo + 1e-12) & (g > 0)) | ((x >= hi - 1e-12) & (g < 0))
        free = ~held
        if not np.any(free):
            break
        h = jtj[np.ix_(free, free)]
        diag = np.maximum(np.diag(h), 1e-12 * max(np.max(np.diag(h)), 1e-300))
        improved = False
        for _ in range(12):
            step = np.zeros_like(x)
            try:
                step[free] = -np.linalg.solve(h + lam * np.diag(diag), g[free])
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            xn = np.clip(x + step, lo, hi)
            rn = problem.residuals(xn)
            cn = float(rn @ rn)
            if np.isfinite(cn) and cn < cost:
                improved = True
                break
            lam *= nu
            nu *= 2.0
        if not improved:
            break
        done = cost - cn <= tol * cost
        x, cost = xn, cn
        lam, nu = max(lam / 3.0, 1e-12), 2.0
        if done:
            break
        cost, jtj, g = problem.normal_equations(x)
    return x, cost


def fit_model(t: Target, model: Model, previous: dict | None = None, refine: int = 2) -> tuple[np.ndarray, float]:
    """``(x, cost)`` of ``model`` fitted to ``t``: every start of ``model.starts(previous)``
    with its linearized ``y`` (:meth:`_Problem.linear_start`), the ``refine`` best by
    :func:`_levenberg_marquardt`; ``x = (q, y)``.

    Parameters
    ----------
    t : Target
        The data's side of the objective (:func:`target`).
    model : Model
        The model (:data:`MODEL_SPECS`).
    previous : dict, optional
        Fitted ``(q, y)`` of earlier models by name (some models start from them).
    refine : int
        Number of best starts refined by Levenberg-Marquardt.

    Returns
    -------
    x : ndarray
        ``(q, y)`` concatenated.
    cost : float
        Its objective.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> t = target(reference, n=256, grid=8, image_size=0, albedo_grid=(16, 8))
    >>> x, cost = fit_model(t, MODEL_SPECS["lobe"])
    >>> round(float(np.exp(x[0])), 3), bool(cost < 1e-6)        # alpha = exp(q): the lobe is found
    (0.3, True)
    """
    problem = _Problem(model, t)
    scored = []
    for start in model.starts(previous or {}):
        q, y = start if isinstance(start, tuple) else (start, None)
        q = np.clip(q, *model.q_bounds)
        x = np.concatenate([q, problem.linear_start(q) if y is None else y])
        r = problem.residuals(x)
        scored.append((float(r @ r), x))
    scored.sort(key=lambda s: s[0])
    best = min((_levenberg_marquardt(problem, x) for _, x in scored[:refine]), key=lambda s: s[1])
    x = _project(problem, best[0])
    x[problem.nq:][x[problem.nq:] < DUST] = 0.0     # the solver's approach to the bound, not a reflectance
    return x, best[1]


def _project(problem: _Problem, x: np.ndarray) -> np.ndarray:
    """Scale each channel's reflectances so that the albedo upper bounds hold exactly
    (band top at the ratio views, ``1 - ENERGY_MARGIN`` at every energy view)."""
    nq, t = problem.nq, problem.t
    q, y = x[:nq], x[nq:].copy()
    for _ in range(3):
        f, c, a = problem.values(q, y)
        ratio_albedo = problem.albedo(f, t.ratio_mask)[:len(ALBEDO_VIEWS_DEG)]
        limit = np.where(problem.band_mask, (1.0 + ALBEDO_ABOVE) * t.albedo_data, np.inf)
        total = problem.albedo(f)
        s = np.minimum(np.min(np.where(ratio_albedo > limit, limit / np.maximum(ratio_albedo, 1e-300), 1.0), 0),
                       np.min(np.where(total > 1.0 - ENERGY_MARGIN,
                                       (1.0 - ENERGY_MARGIN) / np.maximum(total, 1e-300), 1.0), 0))
        if np.all(s >= 1.0):
            break
        # per channel: the reflectances that feed channel c only, or all channels (grey f90)
        feeds = np.any(problem.model.mix != 0, axis=1)                     # (3, n_y)
        for k in range(len(y)):
            channels = np.flatnonzero(feeds[:, k])
            y[k] *= float(np.min(s[channels])) * (1.0 - 1e-9) if len(channels) else 1.0
    return np.concatenate([q, y])


def fit_parameters(reference, models=("lobe", "two_lobes"), t: Target | None = None) -> dict:
    """Every model of ``models`` (names of :data:`MODELS`) fitted to ``reference`` (or to its
    :func:`target` ``t``, which then is all that is read): ``{name: (q, y)}``, its nonlinear
    parameters and reflectances (``MODEL_SPECS[name].brdf(q, y)`` is the BRDF; plain arrays,
    so that they cross processes); :func:`iter_parameters` collected.

    Parameters
    ----------
    reference : BRDF
        The material (read only to make ``t`` when it is not given).
    models : sequence of str
        Names of :data:`MODELS`, fitted in order (a later model may start from an earlier one).
    t : Target, optional
        The data's side of the objective (:func:`target`).

    Returns
    -------
    dict
        ``{name: (q, y)}``: nonlinear parameters and reflectances of each model.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> t = target(reference, n=256, grid=8, image_size=0, albedo_grid=(16, 8))
    >>> q, y = fit_parameters(reference, models=("lobe",), t=t)["lobe"]
    >>> np.exp(q).round(3), y[:3].round(3)         # alpha, then the Schlick F0 per channel
    (array([0.3]), array([0.04, 0.04, 0.04]))
    """
    return dict(iter_parameters(reference, models, t))


def iter_parameters(reference, models=("lobe", "two_lobes"), t: Target | None = None):
    """``(name, (q, y))`` of every model of ``models`` in the order of :data:`MODELS`, each
    as soon as it is fitted (:func:`fit_model`; a later model may start from an earlier
    one), e.g. for a caller that judges early models while later ones are fitted
    (:func:`microfacet._background.in_process_items`). NumPy only once ``t`` is made. Linear
    algebra runs on one BLAS thread (the matrices are small; idle BLAS threads spin).

    Parameters
    ----------
    reference : BRDF
        The material (read only to make ``t`` when it is not given).
    models : sequence of str
        Names of :data:`MODELS`.
    t : Target, optional
        The data's side of the objective (:func:`target`).

    Yields
    ------
    name : str
        The model's name.
    (q, y) : tuple of ndarray
        Its nonlinear parameters and reflectances.

    Examples
    --------
    >>> import microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> t = target(reference, n=256, grid=8, image_size=0, albedo_grid=(16, 8))
    >>> [name for name, _ in iter_parameters(reference, models=("two_lobes", "lobe"), t=t)]
    ['lobe', 'two_lobes']
    """
    from threadpoolctl import threadpool_limits
    unknown = set(models) - set(MODELS)
    if unknown:
        raise ValueError(f"models must be among {MODELS}, got {sorted(unknown)}")
    with threadpool_limits(1, user_api="blas"):     # BLAS only: OpenMP is not to be touched in a forked child
        t = target(reference) if t is None else t
        fitted = {}
        for name in (m for m in MODELS if m in models):
            model = MODEL_SPECS[name]
            x, _ = fit_model(t, model, fitted)
            nq = len(model.q_bounds[0])
            fitted[name] = (x[:nq], x[nq:])
            yield name, fitted[name]


def fit_models(reference, models=("lobe", "two_lobes"), t: Target | None = None) -> dict:
    """Every model of ``models`` (names of :data:`MODELS`) fitted to ``reference``:
    ``{name: BRDF}``, each a BRDF of the library (``eval``, ``pdf``, ``sample``);
    :func:`fit_parameters` with each model's BRDF built.

    Parameters
    ----------
    reference : BRDF
        The material.
    models : sequence of str
        Names of :data:`MODELS`.
    t : Target, optional
        The data's side of the objective (:func:`target`).

    Returns
    -------
    dict
        ``{name: BRDF}``.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> t = target(reference, n=256, grid=8, image_size=0, albedo_grid=(16, 8))
    >>> brdf = fit_models(reference, models=("lobe",), t=t)["lobe"]
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> brdf.eval(n, n).round(4), reference.eval(n, n).round(4)
    (array([0.0354, 0.0354, 0.0354]), array([0.0354, 0.0354, 0.0354]))
    """
    return {name: MODEL_SPECS[name].brdf(q, y) for name, (q, y) in fit_parameters(reference, models, t).items()}


def select(scores: dict) -> str:
    """The name of least score (e.g. :class:`microfacet.metrics.ImageError` values);
    ties go to the earlier (simpler) model.

    Parameters
    ----------
    scores : dict
        ``{name: score}``, in the order of preference on ties.

    Returns
    -------
    str
        The name of least finite score.

    Examples
    --------
    >>> select({"lobe": 0.031, "two_lobes": 0.012, "mixture": 0.012})     # ties: the simpler model
    'two_lobes'
    """
    finite = {k: v for k, v in scores.items() if np.isfinite(v)}
    if not finite:
        raise ValueError("no candidate fit has a finite score")
    return min(finite, key=lambda k: (finite[k], list(scores).index(k)))
