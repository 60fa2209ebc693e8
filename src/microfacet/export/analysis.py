"""A library BRDF tree read as the parts that material formats have: specular lobes, a
diffuse base and a coat (what every exporter of :mod:`microfacet.export` starts from).

:func:`analyse` splits a :class:`~microfacet.MicrofacetBRDF`, a
:class:`~microfacet.fit.SumBRDF` of lobes and an optional :class:`~microfacet.Lambertian`,
or a :class:`~microfacet.layered.LayeredBRDF` (coat over such a base) into
:class:`Lobe` records (the ellipse ``alpha1 >= alpha2`` at azimuth ``phi`` of the slope
covariance, thesis Eq. 2.29-2.34, and the Fresnel term) and a base reflectance, ordered by
albedo (the lobe of largest directional albedo at normal incidence first).
:func:`schlick_of` reads any Fresnel term as the Schlick ``(f0, f90)`` pair of least squares
on ``cos theta_d`` (exact for :class:`~microfacet.fresnel.Schlick`).

Examples
--------
>>> import microfacet as mf
>>> a = analyse(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.1)))
>>> round(a.lobes[0].alpha1, 3), round(a.lobes[0].alpha2, 3), a.base is None
(0.2, 0.1, True)
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._colour import LUMINANCE
from ..errors import MicrofacetError

__all__ = ["Lobe", "Analysis", "analyse", "schlick_of", "lobe_albedo", "LUMINANCE"]



@dataclass
class Lobe:
    """One specular lobe: ``brdf`` (the library's MicrofacetBRDF), the family
    (``"ggx"``/``"beckmann"``), the slope ellipse ``alpha1 >= alpha2`` with ``alpha1``'s axis
    at azimuth ``phi`` (radians, from the tangent towards the bitangent; Eq. 2.29-2.34), the
    mean slope and the Fresnel term.

    Attributes
    ----------
    brdf : MicrofacetBRDF
        The lobe as the library holds it.
    family : str
        ``"ggx"`` or ``"beckmann"``.
    alpha1, alpha2 : float
        Radii of the slope ellipse, ``alpha1 >= alpha2``.
    phi : float
        Azimuth of the ``alpha1`` axis (radians).
    mean_slope : tuple
        ``(x~, y~)`` of the lobe's mean normal.
    fresnel : Fresnel
        The lobe's Fresnel term.
    albedo : float
        Luminance of its directional albedo at normal incidence (:func:`lobe_albedo`).

    Examples
    --------
    >>> import microfacet as mf
    >>> lobe = analyse(mf.MicrofacetBRDF(mf.Beckmann(alpha_x=0.1, alpha_y=0.3))).lobes[0]
    >>> lobe.family, round(lobe.alpha1, 3), round(lobe.alpha2, 3), round(lobe.phi, 4), lobe.isotropic
    ('beckmann', 0.3, 0.1, 1.5708, False)
    """
    brdf: object
    family: str
    alpha1: float
    alpha2: float
    phi: float
    mean_slope: tuple
    fresnel: object
    albedo: float = 0.0

    @property
    def isotropic(self) -> bool:
        return abs(self.alpha1 - self.alpha2) <= 1e-9 * max(self.alpha1, 1e-300)


@dataclass
class Analysis:
    """``lobes`` (largest albedo first), ``base`` (Lambertian reflectance RGB or None) and
    ``coat`` (a :class:`Lobe` with a Dielectric Fresnel, or None) of a BRDF tree; ``notes``:
    one line per approximation made (e.g. a TransmittedLambertian read as a Lambertian).

    Attributes
    ----------
    lobes : list of Lobe
        The specular lobes, largest albedo first.
    base : (3,) ndarray or None
        The Lambertian base's reflectance, clipped to ``[0, 1]``.
    coat : Lobe or None
        The coat lobe of a :class:`~microfacet.layered.LayeredBRDF`.
    notes : list of str
        The approximations made.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.fit import SumBRDF
    >>> a = analyse(SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), mf.Lambertian([0.5, 0.2, 0.1])))
    >>> len(a.lobes), a.base.tolist(), a.coat is None
    (1, [0.5, 0.2, 0.1], True)
    """
    lobes: list
    base: np.ndarray | None = None
    coat: Lobe | None = None
    notes: list = field(default_factory=list)


def lobe_albedo(brdf, n: int = 64) -> float:
    """Luminance of the directional albedo at normal incidence, ``int f cos dwi`` (a
    midpoint rule in ``(cos theta, phi)``, 64 x 64 nodes: a few 1e-3 for alpha >= 0.02).

    Parameters
    ----------
    brdf : BRDF
        Any library BRDF (its ``eval_cos``).
    n : int
        Nodes per axis of the midpoint rule.

    Returns
    -------
    float
        ``int f(wi, n) cos theta_i dwi`` weighted by the Rec. 709 :data:`LUMINANCE`.

    Examples
    --------
    A white Lambertian reflects everything; a GGX lobe of ideal mirrors less (single
    scattering: what its masking-shadowing term blocks is lost):

    >>> import microfacet as mf
    >>> round(lobe_albedo(mf.Lambertian([1.0, 1.0, 1.0])), 3), round(lobe_albedo(mf.MicrofacetBRDF(mf.GGX(alpha=0.3))), 2)
    (1.0, 0.88)
    """
    u = (np.arange(n) + 0.5) / n
    mu, ph = np.meshgrid(u, 2 * np.pi * u, indexing="ij")
    # nodes dense near the mirror direction: cos theta = 1 - (1 - u)^... use u^(1/4) warp
    c = 1.0 - (1.0 - mu) ** 4
    jac = 4.0 * (1.0 - mu) ** 3
    s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
    wi = np.stack([s * np.cos(ph), s * np.sin(ph), c], -1).reshape(-1, 3)
    wo = np.broadcast_to([0.0, 0.0, 1.0], wi.shape)
    f = np.nan_to_num(brdf.eval_cos(wi, wo)) * (jac.reshape(-1, 1) * 2 * np.pi / (n * n))
    return float(f.sum(axis=0) @ LUMINANCE)


def schlick_of(fresnel, n: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """``(f0, f90)``, RGB: Schlick's ``F = f0 + (f90 - f0)(1 - c)^5`` (Schlick 1994) of least
    squares to ``fresnel`` on ``n`` cosines uniform in ``theta_d``, clipped to ``[0, 1]``;
    exact for :class:`~microfacet.fresnel.Schlick`.

    Parameters
    ----------
    fresnel : Fresnel
        Any library Fresnel term (called on cosines).
    n : int
        Number of ``theta_d`` samples of the least-squares fit.

    Returns
    -------
    f0, f90 : ndarray
        RGB reflectances at normal and grazing incidence.

    Examples
    --------
    >>> import microfacet as mf
    >>> f0, f90 = schlick_of(mf.fresnel.Schlick([0.9, 0.6, 0.5]))      # exact
    >>> f0.tolist(), f90.tolist()
    ([0.9, 0.6, 0.5], [1.0, 1.0, 1.0])
    >>> f0, f90 = schlick_of(mf.fresnel.Dielectric(1.5))               # least squares
    >>> f0.round(3).tolist(), f90.round(2).tolist()
    ([0.046, 0.046, 0.046], [0.97, 0.97, 0.97])
    """
    from .. import fresnel as fr
    if isinstance(fresnel, fr.Schlick):
        return np.array(fresnel.f0, float), np.array(fresnel.f90, float)
    c = np.cos(np.linspace(0.0, np.pi / 2, n))
    y = np.asarray(fresnel(c), float)
    m = (1.0 - c) ** 5
    a = np.stack([1.0 - m, m], -1)
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    return np.clip(coef[0], 0.0, 1.0), np.clip(coef[1], 0.0, 1.0)


def _lobe(brdf, what: str) -> Lobe:
    from ..distributions import GGX, Beckmann
    d = brdf.distribution
    if not isinstance(d, (GGX, Beckmann)):
        raise MicrofacetError(f"{what}: only GGX and Beckmann lobes export, got {type(d).__name__} "
                              "(a tabulated fit: export one of the file's analytic fits, --model NAME)")
    if d.alpha_x.ndim or d.alpha_y.ndim or d.rho.ndim:
        raise MicrofacetError(f"{what}: spatially varying parameters do not export (one material only)")
    a1, a2, phi = (float(v) for v in d.ellipse)
    return Lobe(brdf, type(d).__name__.lower(), a1, a2, phi, tuple(float(v) for v in d.mean_slope), brdf.fresnel,
                lobe_albedo(brdf))


def analyse(brdf) -> Analysis:
    """The :class:`Analysis` of a BRDF tree (module docstring); :class:`MicrofacetError`
    naming the part that has no counterpart (a tabulated NDF, a sum holding a coat).

    Parameters
    ----------
    brdf : BRDF
        A :class:`~microfacet.MicrofacetBRDF` (GGX or Beckmann, scalar parameters), a
        :class:`~microfacet.Lambertian` or
        :class:`~microfacet.diffuse.TransmittedLambertian`, a
        :class:`~microfacet.fit.SumBRDF` of those, or a
        :class:`~microfacet.layered.LayeredBRDF` (one coat over such a base).

    Returns
    -------
    Analysis
        Lobes (largest albedo first), base and coat.

    Raises
    ------
    MicrofacetError
        A part no material format holds.

    Examples
    --------
    >>> import microfacet as mf
    >>> coat = mf.MicrofacetBRDF(mf.GGX(alpha=0.05), mf.fresnel.Dielectric(1.5))
    >>> a = analyse(mf.layered.LayeredBRDF(coat, mf.Lambertian([0.8, 0.1, 0.1])))
    >>> a.coat.family, round(a.coat.alpha1, 3), a.lobes
    ('ggx', 0.05, [])
    """
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from ..fit.analytic import SumBRDF
    if type(brdf).__name__ == "LayeredBRDF":
        inner = analyse(brdf.base)
        if inner.coat is not None:
            raise MicrofacetError("a coat over a coated base does not export (one coat only)")
        inner.coat = _lobe(brdf.coat, "coat")
        return inner
    parts = list(brdf.brdfs) if isinstance(brdf, SumBRDF) else [brdf]
    lobes, base, notes = [], None, []
    for p in parts:
        if isinstance(p, MicrofacetBRDF):
            lobes.append(_lobe(p, "lobe"))
        elif isinstance(p, (Lambertian, TransmittedLambertian)):
            r = p.reflectance if isinstance(p, Lambertian) else equivalent_lambertian(p)
            base = r.copy() if base is None else base + r
            if isinstance(p, TransmittedLambertian):
                notes.append(f"diffuse seen through its surface (eta {p.eta:g}: darker at grazing angles) exported as "
                             "a Lambertian of the same mean albedo")
        else:
            raise MicrofacetError(f"{type(p).__name__} does not export (MicrofacetBRDF, Lambertian, "
                                  "TransmittedLambertian, SumBRDF, LayeredBRDF only)")
    if not lobes and base is None:
        raise MicrofacetError("nothing to export")
    lobes.sort(key=lambda lobe: -lobe.albedo)
    return Analysis(lobes, None if base is None else np.clip(base, 0.0, 1.0), notes=notes)


def equivalent_lambertian(brdf, n: int = 256) -> np.ndarray:
    """The reflectance of the Lambertian whose albedo, averaged over views (cosine-weighted),
    equals that of a :class:`~microfacet.diffuse.TransmittedLambertian`:
    ``R (2 int_0^1 mu t(mu) dmu / t(1))^2`` (midpoint rule, ``n`` nodes: ~1e-5)."""
    mu = (np.arange(n) + 0.5) / n
    a = 2.0 * np.mean(mu * brdf.transmittance(mu)) / float(brdf.transmittance(np.ones(1))[0])
    return brdf.reflectance * a * a
