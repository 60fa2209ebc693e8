"""A dielectric coat over any BRDF, energy-conserving coupling (Kelemen & Szirmay-Kalos 2001;
Weidlich & Wilkie 2007 without refraction of the base's directions).

``f(i, o) = f_c(i, o) + (1 - E_c(cos theta_i)) (1 - E_c(cos theta_o)) f_b(i, o)``

with ``f_c`` an isotropic microfacet lobe whose Fresnel term is the coat's (a
:class:`microfacet.fresnel.Dielectric`), ``f_b`` any BRDF of the library (the base) and
``E_c(mu)`` the coat lobe's directional albedo (Eq. 1.8, its Fresnel term included): the
energy the coat reflects at view ``mu = cos theta``; what it does not reflect reaches the
base on the way in, and the base's light leaves through the coat on the way out, each
time weighted by the coat's transmission ``1 - E_c``. Kelemen & Szirmay-Kalos 2001
("A microfacet based coupled specular-matte BRDF model with importance sampling",
Eurographics short papers) couple a Lambertian base to a specular lobe this way;
Weidlich & Wilkie 2007 ("Arbitrarily layered micro-facet surfaces", GRAPHITE) stack lobes
with the same transmission factors, and refract the directions into the layer, which is
left out here (the base sees the outside directions).

Energy: with ``a_b(o) = int f_b(i, o) cos theta_i d i <= 1`` (the base's white furnace),
``a(o) = E_c(o) + (1 - E_c(o)) int (1 - E_c(i)) f_b(i, o) cos theta_i d i
<= E_c(o) + (1 - E_c(o)) a_b(o) <= 1``, since ``0 <= E_c <= 1``. Reciprocity: the coupling
factor is symmetric in ``i`` and ``o``, so ``f`` is reciprocal where ``f_c`` and ``f_b`` are.

``E_c`` is tabulated once per coat (:func:`albedo_table`, cached): at the 48 views
:data:`NODES` (``mu_k = t_k^3``, ``t`` uniform: dense near grazing) by a deterministic
Gauss-Legendre rule over the light direction that follows the lobe (:func:`lobe_albedo`), then
``E_c(mu) = F(mu) R(mu)`` on the 1024 views :data:`TABLE_NODES`, ``R = E_c / F`` a cubic spline
in ``mu^(1/3)`` through the nodes (``F``: the coat's Fresnel term at ``cos theta_d = mu``, which
carries most of the variation of ``E_c``), interpolated linearly in ``mu^(1/3)`` at evaluation
(:func:`lerp`). Accuracy, against the slope-space quadrature of
:func:`microfacet.validation.albedo` (GGX and Beckmann, ``eta = 1.5``, views 0-89 deg): within
3e-5 for ``alpha`` 0.005-1 (tests), ~2e-4 at 89.9 deg for ``alpha = 0.003``. Construction
costs one evaluation of the coat on 48 x 1152 pairs.

Examples
--------
>>> from microfacet.layered.coat import NODES, TABLE_NODES, QUADRATURE_ORDERS, QUADRATURE_ORDER, PROBABILITY_BOUNDS, LUMINANCE
>>> len(NODES), len(TABLE_NODES), round(float(TABLE_NODES[0]), 6), float(TABLE_NODES[-1])
(48, 1024, 0.0001, 1.0)
>>> QUADRATURE_ORDERS, QUADRATURE_ORDER, PROBABILITY_BOUNDS, LUMINANCE
((24, 48), 32, (0.05, 0.95), array([0.2126, 0.7152, 0.0722]))
"""
from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import CubicSpline

from .._colour import LUMINANCE
from .. import protocol
from ..brdf import BRDF, MicrofacetBRDF, uniforms, unit_directions
from ..distributions import GGX, Beckmann

__all__ = ["LayeredBRDF", "coat_albedo", "albedo_table", "lobe_albedo", "sampled_albedo", "lerp", "grid", "luminance",
           "NODES", "TABLE_NODES", "QUADRATURE_ORDERS", "QUADRATURE_ORDER", "PROBABILITY_BOUNDS", "LUMINANCE"]

#: Smallest tabulated view cosine (tables are constant below it).
MU_MIN = 1e-4
_T0 = float(MU_MIN ** (1.0 / 3.0))


def grid(n: int) -> np.ndarray:
    """``n`` views ``mu_k = t_k^3``, ``t`` uniform from ``MU_MIN^(1/3)`` to 1 (dense near
    grazing): the nodes of every table of this module (read-only).

    Parameters
    ----------
    n : int
        Number of nodes.

    Returns
    -------
    (n,) ndarray
        ``mu_k``, increasing to 1.

    Examples
    --------
    >>> grid(4).round(4)
    array([1.000e-04, 4.830e-02, 3.174e-01, 1.000e+00])
    """
    mu = np.linspace(_T0, 1.0, n) ** 3
    mu[-1] = 1.0
    mu.flags.writeable = False
    return mu


#: Views at which ``E_c`` is computed by quadrature.
NODES = grid(48)
#: Views of the albedo table that :meth:`LayeredBRDF.coat_albedo` interpolates.
TABLE_NODES = grid(1024)
#: Gauss-Legendre orders in ``cos theta_i`` and ``phi_i`` of the albedo quadrature (:func:`lobe_albedo`).
QUADRATURE_ORDERS = (24, 48)
#: Gauss-Legendre order per uniform of :func:`sampled_albedo`.
QUADRATURE_ORDER = 32
#: Order per uniform of the base's albedo estimate (sampling probabilities only).
BASE_ORDER = 8
#: The coat's sampling probability is clamped into this interval.
PROBABILITY_BOUNDS = (0.05, 0.95)
LUMINANCE.flags.writeable = False


@functools.lru_cache(maxsize=8)
def _gauss(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre nodes and weights on ``[0, 1]`` (read-only)."""
    t, w = np.polynomial.legendre.leggauss(order)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    t.flags.writeable = w.flags.writeable = False
    return t, w


@functools.lru_cache(maxsize=8)
def _gauss_grid(order: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre product nodes ``(order^2, 2)`` in ``[0, 1]^2`` and their weights."""
    t, w = np.polynomial.legendre.leggauss(order)
    t, w = 0.5 * (t + 1.0), 0.5 * w
    u = np.stack(np.meshgrid(t, t, indexing="ij"), axis=-1).reshape(-1, 2)
    weights = (w[:, None] * w[None, :]).ravel()
    u.flags.writeable = weights.flags.writeable = False
    return u, weights


def _views(mu) -> np.ndarray:
    mu = np.clip(np.asarray(mu, dtype=np.float64), 0.0, 1.0)
    return np.stack([np.sqrt(1.0 - mu * mu), np.zeros_like(mu), mu], axis=-1)


def sampled_albedo(brdf, mu, order: int = QUADRATURE_ORDER) -> np.ndarray:
    """``int f cos theta_i d i`` (Eq. 1.8, RGB ``(len(mu), 3)``) of any library BRDF at views
    ``cos theta_o = mu`` (azimuth 0), by the Gauss-Legendre product rule of ``order`` over the
    uniforms of ``brdf.sample``: the weighted mean of its weights ``f cos theta_i / pdf``
    (failed samples count 0). Exact change of variables; the error is the rule's on the
    sampler's warp (see the module docstring for coat lobes).

    Parameters
    ----------
    brdf : BRDF
        Any library BRDF.
    mu : (V,) array_like
        ``cos theta_o`` of the views, ``(0, 1]``.
    order : int
        Gauss-Legendre nodes per uniform.

    Returns
    -------
    (V, 3) ndarray
        The albedo per view and RGB channel.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fresnel=mf.fresnel.Dielectric(1.5))
    >>> sampled_albedo(mf.Lambertian(0.5), np.array([1.0, 0.3]))[:, 0].round(6)
    array([0.5, 0.5])
    >>> bool(abs(sampled_albedo(coat, np.array([0.5]), order=64) - lobe_albedo(coat, np.array([0.5])))[0, 0] < 1e-3)
    True
    """
    mu = np.atleast_1d(np.asarray(mu, dtype=np.float64))
    u, w = _gauss_grid(order)
    wo = np.repeat(_views(mu), len(u), axis=0)
    weight = np.asarray(brdf.sample(np.tile(u, (len(mu), 1)), wo)[1], dtype=np.float64)
    weight = np.where(np.isfinite(weight), weight, 0.0)
    return np.einsum("vsc,s->vc", weight.reshape(len(mu), len(u), 3), w)


def lerp(table: np.ndarray, mu) -> np.ndarray:
    """Piecewise-linear interpolation of ``table`` (its values at :func:`grid` ``(len(table))``)
    in ``t = mu^(1/3)``, clamped at its ends: shape ``mu.shape + table.shape[1:]``.

    Parameters
    ----------
    table : (n, ...) ndarray
        Values at :func:`grid` ``(n)``.
    mu : array_like
        ``cos theta`` of the views.

    Returns
    -------
    ndarray
        Interpolated values, ``mu.shape + table.shape[1:]``.

    Examples
    --------
    >>> import numpy as np
    >>> mu = grid(5)
    >>> bool(np.allclose(lerp(mu ** 2, mu), mu ** 2)), lerp(mu ** 2, np.array([2.0])).item()   # exact at the nodes, clamped
    (True, 1.0)
    """
    n = len(table)
    x = np.clip((np.cbrt(np.asarray(mu, dtype=np.float64)) - _T0) * ((n - 1) / (1.0 - _T0)), 0.0, n - 1.0)
    j = np.minimum(x.astype(np.intp), n - 2)
    s = x - j
    if table.ndim > 1:
        s = s[..., None]
    lo = table[j]
    return lo + s * (table[j + 1] - lo)


def _check_coat(coat) -> None:
    """``ValueError`` naming ``coat`` unless it is an isotropic GGX/Beckmann MicrofacetBRDF."""
    if not isinstance(coat, MicrofacetBRDF):
        raise ValueError(f"coat must be a MicrofacetBRDF (GGX or Beckmann, Dielectric Fresnel), "
                         f"got {type(coat).__name__}")
    d = coat.distribution
    if type(d) not in (GGX, Beckmann):
        raise ValueError(f"coat must have a GGX or Beckmann distribution, got {type(d).__name__}")
    params = (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)
    if any(np.ndim(p) for p in params) or d.alpha_x != d.alpha_y or d.rho != 0 or d.xn != 0 or d.yn != 0:
        raise ValueError(f"coat must be isotropic (alpha_x = alpha_y, rho = 0, zero mean slope, scalars), "
                         f"got {d!r}")


def _fresnel_key(fresnel):
    """A hashable key of a Fresnel term's class and parameters (``None`` if unknown)."""
    try:
        return (type(fresnel).__qualname__,) + tuple(
            (k, np.asarray(v, dtype=np.float64).tobytes()) for k, v in sorted(vars(fresnel).items()))
    except (TypeError, ValueError):
        return None


def _coat_key(coat):
    fresnel = _fresnel_key(coat.fresnel)
    if fresnel is None:
        return None
    d = coat.distribution
    return (type(d).__name__, float(d.alpha_x), coat.gaf_model, coat.shadowing, fresnel)


#: Albedo tables by coat key (:func:`_coat_key`), oldest first; at most :data:`_CACHE_SIZE`.
_TABLES: dict = {}
_CACHE_SIZE = 64


def lobe_albedo(coat, mu, orders: tuple[int, int] = QUADRATURE_ORDERS) -> np.ndarray:
    """Directional albedo ``int f_c(i, o) cos theta_i d i`` (Eq. 1.8, RGB ``(len(mu), 3)``) of
    an isotropic microfacet lobe ``coat`` at views ``cos theta_o = mu`` (1-D), by a
    Gauss-Legendre product rule over the light direction ``(cos theta_i, phi_i)`` of ``orders``
    nodes, each coordinate mapped by ``x = c + w tan(s)`` onto its interval (``cos theta_i`` in
    ``[0, 1]``, ``phi_i`` in ``[0, pi]`` from the mirror azimuth, doubled by symmetry) around the
    mirror direction ``c`` with the lobe's width ``w`` (``2 alpha sin theta_o`` in
    ``cos theta_i``, at least ``2 alpha^2``; ``2 alpha / sin theta_o`` in ``phi_i``, at most 1):
    the nodes follow the lobe from mirror-sharp to rough and its tails, and the horizon is an
    end of an interval, not a kink inside it. Against :func:`microfacet.validation.albedo`
    (slope space, 500 x 500 nodes), GGX and Beckmann, ``alpha`` 0.003-2, views 0-89 deg:
    within 3e-5 (tests).

    Parameters
    ----------
    coat : MicrofacetBRDF
        An isotropic microfacet lobe.
    mu : (V,) array_like
        ``cos theta_o`` of the views, ``(0, 1]``.
    orders : (int, int)
        Gauss-Legendre nodes in ``cos theta_i`` and ``phi_i``.

    Returns
    -------
    (V, 3) ndarray
        The albedo per view and RGB channel.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fresnel=mf.fresnel.Dielectric(1.5))
    >>> lobe_albedo(coat, np.array([1.0, 0.5]))[:, 0].round(4)
    array([0.0397, 0.0859])
    """
    mu = np.clip(np.atleast_1d(np.asarray(mu, dtype=np.float64)), 0.0, 1.0)
    alpha = float(coat.distribution.alpha_x)
    sin_o = np.sqrt(1.0 - mu * mu)
    w_mu = np.maximum(2.0 * alpha * sin_o, 2.0 * alpha * alpha)
    w_phi = 2.0 * alpha / np.maximum(sin_o, 2.0 * alpha)
    (t_mu, q_mu), (t_phi, q_phi) = (_gauss(n) for n in orders)
    lo, hi = np.arctan(-mu / w_mu), np.arctan((1.0 - mu) / w_mu)
    x = lo[:, None] + (hi - lo)[:, None] * t_mu                          # (views, n_mu)
    mu_i = np.clip(mu[:, None] + w_mu[:, None] * np.tan(x), 0.0, 1.0)
    q_x = q_mu * (hi - lo)[:, None] * w_mu[:, None] / np.cos(x) ** 2
    top = np.arctan(np.pi / w_phi)
    y = top[:, None] * t_phi                                             # (views, n_phi)
    psi = w_phi[:, None] * np.tan(y)
    q_y = 2.0 * q_phi * top[:, None] * w_phi[:, None] / np.cos(y) ** 2  # both sides of the mirror plane
    sin_i = np.sqrt(1.0 - mu_i * mu_i)[:, :, None]
    wi = np.stack(np.broadcast_arrays(-sin_i * np.cos(psi)[:, None, :], sin_i * np.sin(psi)[:, None, :],
                                      mu_i[:, :, None]), axis=-1)
    wo = np.broadcast_to(_views(mu)[:, None, None, :], wi.shape)
    f = np.asarray(coat.eval_cos(wi.reshape(-1, 3), np.ascontiguousarray(wo).reshape(-1, 3)), dtype=np.float64)
    f = f.reshape(wi.shape[:3] + (3,))
    return np.einsum("vmpc,vm,vp->vc", f, q_x, q_y)


def _table(coat) -> np.ndarray:
    ratio = lobe_albedo(coat, NODES)
    f = np.asarray(coat.fresnel(NODES), dtype=np.float64)
    ratio = np.divide(ratio, f, out=np.zeros_like(ratio), where=f > 0)
    spline = CubicSpline(np.cbrt(NODES), ratio, axis=0)
    table = np.asarray(coat.fresnel(TABLE_NODES), dtype=np.float64) * spline(np.cbrt(TABLE_NODES))
    table = np.clip(table, 0.0, 1.0)
    table.flags.writeable = False
    return table


def albedo_table(coat) -> np.ndarray:
    """The coat's directional albedo ``E_c`` at :data:`TABLE_NODES`, ``(1024, 3)`` (read-only;
    module docstring): by :func:`lobe_albedo` at :data:`NODES`, and ``F(mu) R(mu)`` in
    between (``R = E_c / F``, 0 where ``F = 0``, a cubic spline in ``mu^(1/3)`` through those
    nodes). Cached per coat (distribution, roughness, Fresnel term and GAF).

    Parameters
    ----------
    coat : MicrofacetBRDF
        An isotropic microfacet lobe.

    Returns
    -------
    (1024, 3) ndarray
        ``E_c`` at :data:`TABLE_NODES`.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fresnel=mf.fresnel.Dielectric(1.5))
    >>> table = albedo_table(coat)
    >>> table.shape, bool(np.allclose(table[-1], coat_albedo(coat, [1.0])[0]))
    ((1024, 3), True)
    """
    _check_coat(coat)
    key = _coat_key(coat)
    if key is None:
        return _table(coat)
    table = _TABLES.get(key)
    if table is None:
        table = _TABLES[key] = _table(coat)
        while len(_TABLES) > _CACHE_SIZE:
            _TABLES.pop(next(iter(_TABLES)), None)
    return table


def coat_albedo(coat, mu) -> np.ndarray:
    """Directional albedo ``E_c(mu) = int f_c(i, o) cos theta_i d i`` (Eq. 1.8, RGB
    ``(..., 3)``) of the isotropic microfacet lobe ``coat`` at views ``cos theta_o = mu``,
    interpolated in its table (:func:`albedo_table`; accuracy in the module docstring).

    Parameters
    ----------
    coat : MicrofacetBRDF
        An isotropic microfacet lobe.
    mu : array_like
        ``cos theta_o`` of the views, ``[0, 1]``.

    Returns
    -------
    (..., 3) ndarray
        ``E_c(mu)``.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fresnel=mf.fresnel.Dielectric(1.5))
    >>> coat_albedo(coat, [1.0, 0.5, 0.1])[:, 0].round(4)    # E_c grows toward grazing views
    array([0.0397, 0.0859, 0.3116])
    """
    return lerp(albedo_table(coat), mu)


def luminance(rgb) -> np.ndarray:
    """Rec. 709 luminance of linear RGB ``(..., 3)``.

    Parameters
    ----------
    rgb : (..., 3) array_like
        Linear RGB.

    Returns
    -------
    (...) ndarray
        Luminance.

    Examples
    --------
    >>> import numpy as np
    >>> luminance(np.array([[1.0, 1.0, 1.0], [1.0, 0.0, 0.0]])).round(4)
    array([1.    , 0.2126])
    """
    return np.asarray(rgb, dtype=np.float64) @ LUMINANCE


def _into(out, result: np.ndarray, inputs) -> np.ndarray:
    if out is None:
        return result
    np.copyto(protocol.output(out, result.shape, result.dtype, "out", tuple(inputs)), result)
    return out


class LayeredBRDF(BRDF):
    """A coat lobe over a base BRDF, coupled by the coat's transmission (module docstring):
    ``f(i, o) = f_c(i, o) + (1 - E_c(cos theta_i)) (1 - E_c(cos theta_o)) f_b(i, o)``.

    Parameters
    ----------
    coat : MicrofacetBRDF
        Isotropic GGX or Beckmann lobe (zero mean slope) with the coat's Fresnel term,
        normally :class:`microfacet.fresnel.Dielectric` ``(eta)``.
    base : BRDF
        Any BRDF of the library: :class:`~microfacet.Lambertian`,
        :class:`~microfacet.MicrofacetBRDF`, :class:`microfacet.fit.SumBRDF`, another
        :class:`LayeredBRDF`...

    Notes
    -----
    ``sample`` picks the coat with probability ``p(mu_o)`` (:meth:`coat_probability`), the
    base otherwise (the first uniform, rescaled, drives the chosen sampler); ``pdf`` is the
    mixture ``p pdf_c + (1 - p) pdf_b`` and the weight ``eval_cos / pdf``. Construction
    tabulates ``E_c`` (:func:`albedo_table`, cached); the base's albedo behind the sampling
    probability is estimated on first use of ``sample`` or ``pdf``. Every method takes
    ``out=`` as the other BRDFs do (float64 results). Read-only after construction.

    Examples
    --------
    >>> import numpy as np
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.1), fresnel=mf.fresnel.Dielectric(1.5))
    >>> paint = LayeredBRDF(coat, mf.Lambertian([0.8, 0.3, 0.1]))
    >>> wo = np.array([0.0, 0.0, 1.0])
    >>> wi, weight, pdf = paint.sample(np.random.default_rng(0).random((20_000, 2)), wo)
    >>> weight.mean(axis=0).round(2)                                   # directional albedo, RGB
    array([0.75, 0.31, 0.13])
    >>> bool(paint.eval(wo, wo)[0] > coat.eval(wo, wo)[0])             # the coat's highlight on top of the base
    True
    """

    def __init__(self, coat: MicrofacetBRDF, base: BRDF):
        if not isinstance(base, BRDF):
            raise ValueError(f"base must be a BRDF of microfacet (Lambertian, MicrofacetBRDF, SumBRDF, ...), "
                             f"got {type(base).__name__}")
        self.coat = coat
        self.base = base
        #: ``E_c`` at :data:`TABLE_NODES`, ``(1024, 3)`` (:func:`albedo_table`).
        self.table = albedo_table(coat)            # checks coat
        grey = bool(np.all(self.table == self.table[:, :1]))
        self._transmission = 1.0 - (self.table[:, :1] if grey else self.table)

    def __repr__(self) -> str:
        return f"LayeredBRDF(coat={self.coat!r}, base={self.base!r})"

    # ------------------------------------------------------------ coupling
    def coat_albedo(self, mu) -> np.ndarray:
        """The coat's directional albedo ``E_c(mu)``, RGB ``(..., 3)`` (:func:`coat_albedo`).

        Parameters
        ----------
        mu : array_like
            ``cos theta_o`` of the views, ``[0, 1]``.

        Returns
        -------
        (..., 3) ndarray
            ``E_c(mu)``.
        """
        return lerp(self.table, mu)

    def transmission(self, mu) -> np.ndarray:
        """``1 - E_c(mu)``: the fraction of light the coat lets through at ``mu``, RGB ``(..., 3)``
        (``(..., 1)`` where the coat is grey, which broadcasts against RGB values).

        Parameters
        ----------
        mu : array_like
            ``cos theta`` of the directions, ``[0, 1]``.

        Returns
        -------
        (..., 3) or (..., 1) ndarray
            ``1 - E_c(mu)``.
        """
        return lerp(self._transmission, mu)

    @functools.cached_property
    def probability_table(self) -> np.ndarray:
        """The coat's sampling probability at :data:`NODES`, ``(64,)`` (:meth:`coat_probability`)."""
        e = luminance(self.coat_albedo(NODES))
        a = np.maximum(luminance(sampled_albedo(self.base, NODES, BASE_ORDER)), 0.0)
        base = (1.0 - e) ** 2 * a
        with np.errstate(divide="ignore", invalid="ignore"):
            p = np.where(e + base > 0, e / (e + base), 0.5)
        p = np.clip(p, *PROBABILITY_BOUNDS)
        p.flags.writeable = False
        return p

    def coat_probability(self, mu) -> np.ndarray:
        """Probability that ``sample`` samples the coat at view ``mu``: the luminance of the
        coat's share of the albedo, ``E / (E + (1 - E)^2 a_b)`` (``E = E_c(mu)``, ``a_b`` the
        base's albedo estimated by an 8 x 8 Gauss rule over its sampler), at :data:`NODES`,
        clamped into :data:`PROBABILITY_BOUNDS` and interpolated as ``E_c``'s table. It changes
        the variance of the estimates, never their mean.

        Parameters
        ----------
        mu : array_like
            ``cos theta_o`` of the views, ``[0, 1]``.

        Returns
        -------
        ndarray
            Probability of sampling the coat.
        """
        return lerp(self.probability_table, mu)

    # ------------------------------------------------------------ protocol
    def _coupled(self, coat_value, base_value, wi, wo) -> np.ndarray:
        fc = np.asarray(coat_value, dtype=np.float64)
        fb = np.asarray(base_value, dtype=np.float64)
        wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
        return fc + self.transmission(wi[..., 2]) * self.transmission(wo[..., 2]) * fb

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f cos theta_i = f_c cos theta_i + (1 - E_c(i))(1 - E_c(o)) f_b cos theta_i``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values.
        """
        return _into(out, self._coupled(self.coat.eval_cos(wi, wo), self.base.eval_cos(wi, wo), wi, wo), (wi, wo))

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f = f_c + (1 - E_c(i))(1 - E_c(o)) f_b``; 0 below either horizon.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values, per steradian.
        """
        return _into(out, self._coupled(self.coat.eval(wi, wo), self.base.eval(wi, wo), wi, wo), (wi, wo))

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Mixture density ``p(mu_o) pdf_c + (1 - p(mu_o)) pdf_b`` of :meth:`sample`.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up).
        out : ndarray, optional
            Array ``(...)`` to write into.

        Returns
        -------
        (...) ndarray
            Density per steradian of ``wi``.
        """
        pc = np.asarray(self.coat.pdf(wi, wo), dtype=np.float64)
        pb = np.asarray(self.base.pdf(wi, wo), dtype=np.float64)
        p = self.coat_probability(np.asarray(wo, dtype=np.float64)[..., 2])
        return _into(out, p * pc + (1.0 - p) * pb, (wi, wo))

    def sample(self, u, wo, out=None):
        """The coat's sampler where ``u[..., 0] < p(mu_o)``, the base's elsewhere (``u[..., 0]``
        rescaled to ``[0, 1]``); returns ``(wi, eval_cos / pdf, pdf)`` of the mixture. Samples
        that the chosen sampler fails (pdf 0) have weight 0 and pdf 0.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1]``.
        wo : (..., 3) array_like
            Unit view directions, local frame.
        out : tuple of 3 ndarray, optional
            ``(wi, weight, pdf)`` arrays to write into.

        Returns
        -------
        wi : (..., 3) ndarray
            Sampled light directions.
        weight : (..., 3) ndarray
            ``eval_cos / pdf``, RGB.
        pdf : (...) ndarray
            Density per steradian.
        """
        wo = unit_directions(wo, "wo")
        u = uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        u = np.broadcast_to(u, shape + (2,))
        wo_b = np.broadcast_to(wo, shape + (3,))
        p = self.coat_probability(wo_b[..., 2])
        coat = u[..., 0] < p
        v0 = np.where(coat, u[..., 0] / p, (u[..., 0] - p) / (1.0 - p))
        v = np.stack([np.clip(v0, 0.0, 1.0), u[..., 1]], axis=-1)
        wi = np.zeros(shape + (3,))
        wi[..., 2] = 1.0
        chosen_pdf = np.zeros(shape)
        for mask, brdf in ((coat, self.coat), (~coat, self.base)):
            if np.any(mask):
                s_wi, _, s_pdf = brdf.sample(v[mask], wo_b[mask])
                wi[mask], chosen_pdf[mask] = s_wi, s_pdf
        pdf = self.pdf(wi, wo_b)
        fc = self.eval_cos(wi, wo_b)
        ok = (chosen_pdf > 0) & (pdf > 0) & np.all(np.isfinite(fc), axis=-1)
        weight = np.where(ok[..., None], fc / np.where(ok, pdf, 1.0)[..., None], 0.0)
        result = (wi, weight, np.where(ok, pdf, 0.0))
        if out is None:
            return result
        out = protocol.sample_outputs(out, shape, np.dtype(np.float64), (u, wo))
        for o, a in zip(out, result):
            np.copyto(o, a)
        return out
