"""Fitting an arbitrary BRDF with a tabulated microfacet BRDF (thesis Ch. 4; Dupuy et al.
2015), its conversion to Beckmann / GGX (App. C) and its file format.

Examples
--------
>>> FORMAT, VERSION, READABLE_VERSIONS
('microfacet.fit', 2, (1, 2))
"""
from __future__ import annotations

import io
import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import fresnel as _fresnel
from ..brdf import GAFS, Lambertian, MicrofacetBRDF
from ..distributions import GGX, Beckmann
from ..distributions.tabulated import THETA_REFINE, TabulatedAnisotropic, TabulatedIsotropic, refine_radial, theta_grid
from ..errors import MicrofacetError
from ..protocol import into, into_sample
from ..io.atomic import write_bytes
from ..io.npz import load_npz
from . import extract
from .analytic import fit_analytic

#: Conversions of :meth:`FittedBRDF.to_ggx` / :meth:`FittedBRDF.to_beckmann`.
CONVERSIONS = ("moments", "least_squares")

__all__ = ["FittedBRDF", "fit", "load", "fit_names", "FORMAT", "VERSION", "READABLE_VERSIONS"]

#: slack of the energy constraint: fit albedo <= data albedo + ENERGY_MARGIN at each view
ENERGY_MARGIN = 0.01
#: default weight of the directional-albedo term of the Fresnel solve (:func:`fit`)
ALBEDO_WEIGHT = 4.0
FORMAT = "microfacet.fit"
VERSION = 2
#: versions :func:`load` reads (version 1: no diffuse base, Eq. 4.3 backscattering)
READABLE_VERSIONS = (1, 2)


class FittedBRDF(MicrofacetBRDF):
    """A microfacet BRDF over a tabulated slope distribution with a tabulated Fresnel term,
    plus an optional Lambertian base, as returned by :func:`fit` (Ch. 4):
    ``f_r = F D G / (4 cos theta_i cos theta_o) + k_d / pi`` (Eq. 2.1 and 1.9).

    It answers the BRDF protocol of :class:`MicrofacetBRDF`; ``f0`` is the Perron
    eigenvalue (luminance of ``F(0)`` estimated from backscattering, Eq. 4.9),
    ``iterations`` the power iterations used, ``backscatter_gaf`` the Smith
    backscattering model the NDF was extracted with (``"height_correlated"`` or
    ``"masking"``, Eq. 4.3) and ``diffuse`` the RGB reflectance ``k_d`` of the base.
    With a base, ``sample`` picks the microfacet lobe or the cosine lobe with probability
    proportional to their albedo estimates (``luminance(F(1))`` and ``luminance(k_d)``)
    and ``pdf`` is the mixture's, so that ``weight = eval_cos / pdf`` exactly.

    Parameters
    ----------
    distribution : TabulatedDistribution
        The fitted slope distribution (Ch. 4).
    fresnel : microfacet.fresnel.Fresnel
        The fitted Fresnel term (a table in ``cos theta_d``, Eq. 4.11).
    gaf : {"smith", "vgroove", "normal_map"}
        Geometric attenuation model (Table 2.IV).
    shadowing : bool
        Include shadowing (``G2``) or masking only.
    f0 : float
        Perron eigenvalue of the fit (luminance of ``F(0)``, Eq. 4.9); NaN if unknown.
    iterations : int
        Power iterations the fit used.
    backscatter_gaf : {None, "height_correlated", "masking"}
        Smith backscattering model the NDF was extracted with (Eq. 4.3).
    diffuse : float or (3,) array_like
        RGB reflectance ``k_d`` of the Lambertian base (0: none).

    References
    ----------
    Dupuy 2015, thesis, Ch. 4, Eq. 2.1, 4.3, 4.9; Dupuy et al. 2015.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> fitted = fit(reference, resolution=16)                # a 16-node fit
    >>> isinstance(fitted, FittedBRDF), round(float(fitted.f0), 3), fitted.backscatter_gaf
    (True, 0.04, 'height_correlated')
    >>> wi, wo = np.array([0.6, 0.0, 0.8]), np.array([-0.6, 0.0, 0.8])
    >>> fitted.eval(wi, wo).round(3), reference.eval(wi, wo).round(3)
    (array([0.055, 0.055, 0.055]), array([0.054, 0.054, 0.054]))
    """

    def __init__(self, distribution, fresnel, gaf="smith", shadowing=True, f0=np.nan, iterations=0, *,
                 backscatter_gaf=None, diffuse=0.0):
        if not isinstance(distribution, (TabulatedIsotropic, TabulatedAnisotropic)):
            raise ValueError("FittedBRDF needs a TabulatedIsotropic or TabulatedAnisotropic distribution")
        super().__init__(distribution, fresnel=fresnel, gaf=gaf, shadowing=shadowing)
        self.f0 = float(f0)
        self.iterations = int(iterations)
        self.backscatter_gaf = _backscatter_model(backscatter_gaf, shadowing)
        self.base = Lambertian(diffuse)
        self.diffuse = self.base.reflectance

    @property
    def anisotropic(self) -> bool:
        return isinstance(self.distribution, TabulatedAnisotropic)

    @property
    def has_diffuse(self) -> bool:
        return bool(np.any(self.diffuse > 0))

    def __repr__(self) -> str:
        extra = f", diffuse={self.diffuse.round(4).tolist()}" if self.has_diffuse else ""
        return f"FittedBRDF({self.distribution!r}, gaf={self.gaf_model!r}, f0={self.f0:.4g}{extra})"

    # ------------------------------------------------------------ the protocol
    def specular(self) -> MicrofacetBRDF:
        """The microfacet lobe alone (Eq. 2.1), without the diffuse base.

        Returns
        -------
        MicrofacetBRDF
            The lobe with this fit's distribution, Fresnel term, GAF and shadowing.
        """
        return MicrofacetBRDF(self.distribution, fresnel=self.fresnel, gaf=self.gaf_model,
                              shadowing=self.shadowing)

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_r cos theta_i``: the microfacet lobe (Listing 2.2) plus ``k_d cos theta_i / pi``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Output array.

        Returns
        -------
        (..., 3) ndarray
            ``f_r cos theta_i`` per RGB channel.
        """
        if not self.has_diffuse:
            return super().eval_cos(wi, wo, out)
        return into(out, super().eval_cos(wi, wo) + self.base.eval_cos(wi, wo), (wi, wo))

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f_r = F D G / (4 cos theta_i cos theta_o) + k_d / pi`` (Eq. 2.1, 1.9).

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame (``z`` the normal).
        out : ndarray, optional
            Output array (:func:`microfacet.protocol.output`).

        Returns
        -------
        (..., 3) ndarray
            ``f_r`` per RGB channel (sr^-1); 0 below the horizon.
        """
        if not self.has_diffuse:
            return super().eval(wi, wo, out)
        return into(out, super().eval(wi, wo) + self.base.eval(wi, wo), (wi, wo))

    @property
    def lobe_probability(self) -> float:
        """Probability of sampling the microfacet lobe: its albedo estimate
        ``luminance(F(1))`` over the sum with ``luminance(k_d)``."""
        a_s = float(extract.luminance(self.fresnel(np.ones(1))[0]))
        a_d = float(extract.luminance(self.diffuse))
        return a_s / (a_s + a_d) if a_s + a_d > 0 else 1.0

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of :meth:`sample`: ``p_s pdf_lobe + (1 - p_s) cos theta_i / pi``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Output array.

        Returns
        -------
        (...) ndarray
            Solid-angle density of ``wi`` given ``wo`` (sr^-1).
        """
        if not self.has_diffuse:
            return super().pdf(wi, wo, out)
        p = self.lobe_probability
        return into(out, p * super().pdf(wi, wo) + (1.0 - p) * self.base.pdf(wi, wo), (wi, wo))

    def sample(self, u, wo, out=None):
        """Sample the lobe (:meth:`MicrofacetBRDF.sample`) or the base (cosine warp),
        chosen by ``u[..., 0]`` against :attr:`lobe_probability` (rescaled to reuse it);
        returns ``(wi, eval_cos / pdf, pdf)`` of the mixture.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1]``.
        wo : (..., 3) array_like
            Unit view directions in the local frame.
        out : tuple of ndarray, optional
            Output arrays ``(wi, weight, pdf)``.

        Returns
        -------
        wi : (..., 3) ndarray
            Sampled light directions.
        weight : (..., 3) ndarray
            ``eval_cos / pdf`` per RGB channel (0 for a direction below the horizon).
        pdf : (...) ndarray
            Their density (:meth:`pdf`).
        """
        if not self.has_diffuse:
            return super().sample(u, wo, out)
        u = np.asarray(u, dtype=np.float64)
        wo = np.asarray(wo, dtype=np.float64)
        p = self.lobe_probability
        lobe = u[..., 0] < p
        u0 = np.where(lobe, u[..., 0] / max(p, 1e-300), (u[..., 0] - p) / max(1.0 - p, 1e-300))
        uu = np.stack([np.clip(u0, 0.0, np.nextafter(1.0, 0.0)), u[..., 1]], axis=-1)
        wi_s = super().sample(uu, wo)[0]
        wi_d = self.base.sample(uu, wo)[0]
        wi = np.where(lobe[..., None], wi_s, wi_d)
        wo_b = np.broadcast_to(wo, wi.shape)
        pdf = self.pdf(wi, wo_b)
        fc = self.eval_cos(wi, wo_b)
        ok = pdf > 0
        weight = np.where(ok[..., None], fc / np.where(ok, pdf, 1.0)[..., None], 0.0)
        return into_sample(out, (wi, weight, np.where(ok, pdf, 0.0)), (u, wo))

    # ------------------------------------------------------------ backscattering
    def backscatter(self, k) -> np.ndarray:
        """The model of the fit, ``F(1) D(k) G(k, k) / (4 cos^2 theta_k) + k_d / pi`` with
        the monostatic ``G(k, k)``: Smith ``1 / (1 + 2 Lambda(k))`` (height-correlated) or
        ``G1(k)`` (Eq. 4.2-4.3, ``backscatter_gaf="masking"``), ``min(1, 2 cos^2)`` for
        V-grooves and ``cos^2`` for normal maps; RGB ``(..., 3)``.

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions (light = view) in the local frame.

        Returns
        -------
        (..., 3) ndarray
            The model's backscattering ``f_r(k, k)`` per RGB channel.
        """
        k = np.asarray(k, dtype=np.float64)
        z = k[..., 2]
        zs = np.where(z > 0, z, 1.0)
        if self.gaf_model == "smith":
            g1 = self.distribution.g1(k)
            if self.backscatter_gaf == "height_correlated":   # 1 + 2 Lambda = 2 / G1 - 1
                g = np.where(g1 > 0, g1 / np.maximum(2.0 - g1, 1e-300), 0.0)
            else:
                g = g1
        elif self.gaf_model == "vgroove":
            g = np.minimum(1.0, 2.0 * z * z)
        else:
            g = z * z
        val = np.where(z > 0, self.distribution.ndf(k) * g / (4.0 * zs * zs), 0.0)
        return val[..., None] * self.fresnel(np.ones_like(z)) + np.where(z > 0, 1.0, 0.0)[..., None] * self.diffuse / np.pi

    # --------------------------------------------------------------- conversion
    def slope_moments(self) -> dict:
        """Slope moments of the fitted distribution (with its alpha, rho, mean slope):
        ``E[x~], E[y~], E[x~^2], E[y~^2], E[x~y~]`` and, about the mean, ``E|x~|, E|y~|``,
        ``beta1 = E[x~y~/(x~^2+y~^2)]``, ``beta2 = E[y~^2/(x~^2+y~^2)]`` (App. C). Kept for
        the distribution and roughness they were computed for (the moment conversions and
        the least-squares fits started from them ask ~4 times).

        Returns
        -------
        dict
            The moments ``e1 .. e5`` (mean, second moments), ``abs_x``, ``abs_y`` (first absolute
            moments about the mean), the angular moments ``beta1``, ``beta2`` and the fitted
            ``alpha_x``, ``alpha_y``, ``rho``.
        """
        d = self.distribution
        key = extract.distribution_key(d)
        kept = getattr(self, "_kept_moments", None)
        if kept is None or kept[0] is not d or kept[1] != key:
            self._kept_moments = kept = (d, key, self._slope_moments())
        return dict(kept[2])

    def _slope_moments(self) -> dict:
        """:meth:`slope_moments`, computed."""
        d = self.distribution
        x, y, w = d.standard_quadrature()
        if any(np.ndim(p) for p in (d.alpha_x, d.alpha_y, d.rho, d.xn, d.yn)):
            raise ValueError("slope moments need scalar alpha_x, alpha_y, rho and mean_slope")
        X, Y = d.from_standard(x, y)
        e1, e2 = np.sum(w * X), np.sum(w * Y)
        dx, dy = X - e1, Y - e2
        r2 = dx * dx + dy * dy
        inv = np.divide(1.0, r2, out=np.zeros_like(r2), where=r2 > 0)
        return dict(e1=e1, e2=e2, e3=np.sum(w * X * X), e4=np.sum(w * Y * Y), e5=np.sum(w * X * Y),
                    abs_x=np.sum(w * np.abs(dx)), abs_y=np.sum(w * np.abs(dy)),
                    beta1=np.sum(w * dx * dy * inv), beta2=np.sum(w * dy * dy * inv))

    def _analytic(self, distribution, reference, resolve_fresnel: bool) -> MicrofacetBRDF:
        """The analytic lobe of a moment conversion (the diffuse base is not carried), with
        its own Fresnel table (``resolve_fresnel``) or the fitted one.

        Its own: the bounded least squares of :func:`fit` (Eq. 4.11, Algorithm 2,
        :func:`extract.solve_fresnel`; table of as many nodes as the fit's) of
        ``reference`` (default: this fit's lobe, :meth:`specular`) against the converted
        NDF, under the energy constraint of :func:`fit` (the reference's albedo +
        :data:`ENERGY_MARGIN`) and without its albedo term. The fitted table was solved
        for the tabulated NDF (and, with ``albedo_weight > 0``, tuned for its albedo):
        with weights ``1 / f_id`` the solution at a node is ``sum f / sum f_id``, so against
        the fit itself it is the fitted table rescaled by the ratio of the two lobes'
        masses at that ``theta_d``, and against the fit's own data (``reference``) it does
        not depend on the fit's albedo weight."""
        if not resolve_fresnel:
            return MicrofacetBRDF(distribution, fresnel=self.fresnel, gaf=self.gaf_model, shadowing=self.shadowing)
        ideal = MicrofacetBRDF(distribution, gaf=self.gaf_model, shadowing=self.shadowing)
        reference = self.specular() if reference is None else reference
        n_d = len(getattr(self.fresnel, "cos_theta_d", ())) or 91
        samples = extract.fresnel_samples(reference, n_d, n_phi_h=(8 if self.anisotropic else 1),
                                          isotropic=not self.anisotropic)
        energy = extract.albedo_rows(reference, ideal, n_d, _energy_views(self.anisotropic), n_u=20)
        cos_d, rgb, _, _ = extract.solve_fresnel(samples, ideal, albedo=energy, energy_margin=ENERGY_MARGIN)
        return MicrofacetBRDF(distribution, fresnel=_fresnel.Tabulated(cos_d, rgb), gaf=self.gaf_model,
                              shadowing=self.shadowing)

    def _least_squares(self, model: str, options: dict):
        """:func:`~microfacet.fit.analytic.fit_analytic` of this fit itself (it is a BRDF:
        no data needed), started from its moment conversion, with a Lambertian base when
        the fit has one and its anisotropy."""
        options = {"diffuse": self.has_diffuse, "anisotropic": self.anisotropic, **options}
        return fit_analytic(self, model, start=self, gaf=self.gaf_model, shadowing=self.shadowing, **options)

    def to_beckmann(self, method: str = "moments", *, reference=None, resolve_fresnel: bool = True, **options):
        """Beckmann BRDF converted from the fit.

        ``method="moments"``: the same second slope moments (App. C, as LEAN/LEADR:
        ``alpha_x^2 = 2 Var[x~]``, ``alpha_y^2 = 2 Var[y~]``, ``rho alpha_x alpha_y =
        2 Cov[x~, y~]``, mean slope kept); exact (up to the fit's quadrature) when the
        fitted BRDF is a Beckmann one. Its Fresnel table is solved for the converted NDF
        against ``reference`` (default: the fit's lobe; or the data it was fitted to), or, with
        ``resolve_fresnel=False``, the fit's own table (:meth:`_analytic`).
        ``method="least_squares"``: the least-squares fit
        of this BRDF (:func:`~microfacet.fit.analytic.fit_analytic`, ``options`` passed
        on; a :class:`~microfacet.fit.analytic.SumBRDF` with a Lambertian base when the
        fit has one).

        Parameters
        ----------
        method : {"moments", "least_squares"}
            Conversion by slope moments (App. C) or by least squares on the data.
        reference : BRDF, optional
            The data the Fresnel table is solved against (default: the fit's own lobe).
        resolve_fresnel : bool
            Solve the Fresnel table for the converted NDF (else keep the fit's).
        **options
            Passed to :func:`~microfacet.fit.analytic.fit_analytic` (``method="least_squares"``).

        Returns
        -------
        MicrofacetBRDF or SumBRDF
            The Beckmann BRDF (with the fit's Lambertian base, if any, as a SumBRDF).
        """
        if _conversion(method, reference, resolve_fresnel) == "least_squares":
            return self._least_squares("beckmann", options)
        m = self.slope_moments()
        return self._analytic(Beckmann.from_moments(m["e1"], m["e2"], m["e3"], m["e4"], m["e5"]), reference,
                              resolve_fresnel)

    def to_ggx(self, method: str = "moments", *, reference=None, resolve_fresnel: bool = True, **options):
        """GGX BRDF converted from the fit.

        ``method="moments"``: first absolute moments (App. C): ``alpha_x = E|x~|``,
        ``alpha_y = E|y~|`` (about the mean, which is kept) and ``rho`` from the angular
        moments ``beta1, beta2``. Since ``[[1 - beta2, beta1], [beta1, beta2]] =
        S / tr S`` with ``S = Sigma^(1/2)`` for any elliptic distribution,
        ``rho = beta1 / sqrt(((1 - beta2)^2 + beta1^2) (beta1^2 + beta2^2))`` (the paper's
        ``(alpha_y / alpha_x) beta1 / (beta1^2 + beta2^2)`` when both hold exactly).
        Exact (up to the fit's quadrature) when the fitted BRDF is a GGX one. Fresnel
        term, ``reference``, ``resolve_fresnel`` and ``method="least_squares"``: as in
        :meth:`to_beckmann`.

        Parameters
        ----------
        method : {"moments", "least_squares"}
            Conversion by first absolute moments (App. C) or by least squares on the data.
        reference : BRDF, optional
            The data the Fresnel table is solved against (default: the fit's own lobe).
        resolve_fresnel : bool
            Solve the Fresnel table for the converted NDF (else keep the fit's).
        **options
            Passed to :func:`~microfacet.fit.analytic.fit_analytic` (``method="least_squares"``).

        Returns
        -------
        MicrofacetBRDF or SumBRDF
            The GGX BRDF (with the fit's Lambertian base, if any, as a SumBRDF).
        """
        if _conversion(method, reference, resolve_fresnel) == "least_squares":
            return self._least_squares("ggx", options)
        m = self.slope_moments()
        b1, b2 = m["beta1"], m["beta2"]
        rho = b1 / np.sqrt(((1.0 - b2) ** 2 + b1 * b1) * (b1 * b1 + b2 * b2))
        rho = float(np.clip(rho, -1.0 + 1e-9, 1.0 - 1e-9))
        return self._analytic(GGX(alpha_x=m["abs_x"], alpha_y=m["abs_y"], rho=rho, mean_slope=(m["e1"], m["e2"])),
                              reference, resolve_fresnel)

    # ------------------------------------------------------------------- files
    def save(self, path: str | os.PathLike) -> Path:
        """Write the fit to ``path`` (the ``.npz`` of :meth:`to_bytes`) atomically
        (:mod:`microfacet.io.atomic`); returns ``path``.

        Parameters
        ----------
        path : str or os.PathLike
            The ``.npz`` file to write (replaced atomically).

        Returns
        -------
        Path
            ``path``.
        """
        return write_bytes(path, self.to_bytes())

    def to_bytes(self, fits: dict | None = None, best: str | None = None) -> bytes:
        """The fit as the bytes of an ``.npz`` file, format :data:`FORMAT` version
        :data:`VERSION` (:meth:`save` writes them, :func:`load` reads them).
        ``fits``: other fits of the same material to keep beside it, ``{name: spec}``
        (:func:`microfacet.fit.spec.to_spec`), stored as the JSON string ``fits``, and
        ``best`` the name :func:`load` returns for ``model="best"``.

        Fields: ``format``, ``version``, ``kind`` (``isotropic`` | ``anisotropic``), ``gaf``,
        ``shadowing``, ``ndf`` (the normalized standard ``D`` at the nodes), ``fresnel_cos``
        and ``fresnel_rgb`` (a non-tabulated Fresnel term is sampled at 91 points), ``f0``,
        ``iterations``, ``alpha_x``, ``alpha_y``, ``rho``, ``mean_slope``, ``backscatter_gaf``,
        ``diffuse`` (RGB ``k_d``; both new in version 2) and, anisotropic,
        ``projected_area`` (the Lambda table).

        Parameters
        ----------
        fits : dict, optional
            Analytic fits to store beside the tabulated one, ``{name: spec}``
            (:func:`microfacet.fit.spec.to_spec`).
        best : str, optional
            The name of the best fit (``"tabulated"`` or a key of ``fits``).

        Returns
        -------
        bytes
            The ``.npz`` file's bytes.
        """
        d = self.distribution
        fresnel = self.fresnel
        if not isinstance(fresnel, _fresnel.Tabulated):          # e.g. a user-set analytic term
            c = np.linspace(0.0, 1.0, 91)
            fresnel = _fresnel.Tabulated(c, fresnel(c))
        arrays = dict(format=np.array(FORMAT), version=np.array(VERSION),
                      kind=np.array("anisotropic" if self.anisotropic else "isotropic"),
                      gaf=np.array(self.gaf_model), shadowing=np.array(self.shadowing),
                      ndf=d.ndf_table, fresnel_cos=fresnel.cos_theta_d, fresnel_rgb=fresnel.values,
                      f0=np.array(self.f0), iterations=np.array(self.iterations),
                      alpha_x=np.asarray(d.alpha_x), alpha_y=np.asarray(d.alpha_y), rho=np.asarray(d.rho),
                      mean_slope=np.asarray(d.mean_slope), backscatter_gaf=np.array(self.backscatter_gaf),
                      diffuse=self.diffuse)
        if self.anisotropic:
            arrays["projected_area"] = d.area_table
        if fits:
            if best is not None and best not in fits and best != "tabulated":
                raise ValueError(f"best fit {best!r} is not among the fits {sorted(fits)}")
            arrays["fits"] = np.array(json.dumps(fits))
            arrays["best"] = np.array(best or "tabulated")
        buf = io.BytesIO()
        np.savez(buf, **arrays)
        return buf.getvalue()


# ------------------------------------------------------------------------ fitting
def _conversion(method: str, reference=None, resolve_fresnel: bool = True) -> str:
    if method not in CONVERSIONS:
        raise ValueError(f"method must be one of {CONVERSIONS}, got {method!r}")
    if method == "least_squares" and (reference is not None or not resolve_fresnel):
        raise ValueError("reference and resolve_fresnel are options of method='moments'")
    return method


def _backscatter_model(backscatter_gaf, shadowing) -> str:
    """``backscatter_gaf`` or, when None, the model of the library's forward BRDF with
    ``shadowing``: height-correlated ``G2(o, o)`` with shadowing, ``G1(o)`` without."""
    if backscatter_gaf is None:
        return "height_correlated" if shadowing else "masking"
    if backscatter_gaf not in extract.BACKSCATTER_GAFS:
        raise ValueError(f"backscatter_gaf must be one of {extract.BACKSCATTER_GAFS} or None, "
                         f"got {backscatter_gaf!r}")
    return str(backscatter_gaf)


def _energy_views(anisotropic: bool) -> np.ndarray:
    """Views of the energy constraint: ``theta_o`` 0-80 degrees (beyond, ``cos theta_o <
    0.1``, measured data are unreliable), at ``phi_o = 0`` and, for anisotropic fits, also
    45, 90 and 135 degrees."""
    th = np.radians([0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0])
    ph = np.radians([0.0, 45.0, 90.0, 135.0] if anisotropic else [0.0])
    T, P = np.meshgrid(th, ph, indexing="ij")
    return np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)


#: Largest isotropic table that :func:`fit` refines to: above ``N = 257`` the grid itself
#: resolves sharp lobes (Beckmann 0.01: 0.02 % pair error at ``N = 180``), while the
#: sampling tables of :class:`TabulatedIsotropic` grow as the square of its nodes.
MAX_REFINED_NODES = 513


def radial_refinement(n: int) -> int:
    """Factor by which an isotropic fit on ``n`` nodes resamples its table
    (:func:`refine_radial`): ``THETA_REFINE`` up to :data:`MAX_REFINED_NODES`, else 1."""
    return THETA_REFINE if THETA_REFINE * (n - 1) + 1 <= MAX_REFINED_NODES else 1


def _fit_ndf(f_back, theta, phi, gaf, model, tol, max_iter):
    """Normalized table of ``D`` and its ``F0`` from backscattering ``f_back``: power
    iterations for Smith (Eq. 4.9, 4.15; :mod:`.extract`), closed forms otherwise
    (Eq. 4.16-4.18). ``phi`` is None for an isotropic fit, whose table is the solution at
    the ``N`` nodes ``theta`` resampled by :func:`refine_radial` at the
    ``r (N - 1) + 1`` nodes of the same grid, ``r`` = :func:`radial_refinement` (an
    anisotropic table is refined so inside :class:`TabulatedAnisotropic`)."""
    n = len(theta)
    if phi is None:
        if gaf == "smith":
            k, rank_one = extract.smith_kernel_isotropic(f_back, theta, model)
            d, f0, its = extract.power_iteration(k, tol=tol, max_iter=max_iter, rank_one=rank_one)
        else:
            d, f0, its = extract.ndf_closed_form(f_back, theta[:-1], gaf), np.nan, 0
        if not np.any(d > 0):
            raise MicrofacetError("fit: the backscattering of the BRDF is zero")
        # the N-node solution resampled at theta_grid(r (N - 1) + 1): third-order between
        # its nodes, where log-linear D errs by 3 % in a lobe ~8 nodes wide (Beckmann 0.01)
        d, r = np.append(d, d[-1]), radial_refinement(n)
        dist = TabulatedIsotropic(refine_radial(d, r) if r > 1 else d)
    else:
        m = len(phi)
        if gaf == "smith":
            k, rank_one = extract.smith_kernel_anisotropic(f_back, theta, phi, model)
            d, f0, its = extract.power_iteration(k, tol=tol, max_iter=max_iter, rank_one=rank_one)
            d = d.reshape(n - 1, m)
        else:
            d, f0, its = extract.ndf_closed_form(f_back, theta[:-1, None], gaf), np.nan, 0
        if not np.any(d > 0):
            raise MicrofacetError("fit: the backscattering of the BRDF is zero")
        d = np.concatenate([d, d[-1:]], axis=0)
        d[0] = d[0].mean()                                   # the pole is one direction
        dist = TabulatedAnisotropic(d)
    if gaf == "smith":     # eigenvalue of the discrete rule -> F0 of the exactly normalized D
        f0 /= extract.rule_area_at_normal(dist, 1 if phi is not None else radial_refinement(n))
    return dist, f0, its


def fit(brdf, resolution: int = 90, anisotropic: bool = False, gaf: str = "smith", *,
        resolution_phi: int | None = None, shadowing: bool = True, tol: float = 1e-10,
        max_iter: int = 1000, backscatter_gaf: str | None = None, diffuse: bool = False,
        diffuse_iterations: int = 16, energy_constraint: bool = True,
        albedo_weight: float | None = None) -> FittedBRDF:
    """Fit ``brdf`` (anything with ``eval(wi, wo) -> RGB``) with a tabulated microfacet BRDF.

    Parameters
    ----------
    brdf : BRDF
        Input material; evaluated at backscattering ``f(o, o)`` for the NDF (luminance, as
        the paper's ``intensity()``), then everywhere for the Fresnel term.
    resolution : int
        Elevation nodes ``N`` (Listing 4.1's ``theta = u^2 pi/2``), ``>= 4``: the
        backscattering directions and unknowns of the NDF. An isotropic fit's table is
        that solution resampled at the ``2 N - 1`` nodes of the same grid (ln D by
        Catmull-Rom, :func:`refine_radial`) for ``N <= 257`` (:func:`radial_refinement`).
    anisotropic : bool
        Fit ``D(theta, phi)`` (Algorithm 1, ``resolution x resolution_phi`` backscattering
        samples) instead of a radial ``D(theta)`` (Algorithm 3).
    resolution_phi : int, optional
        Azimuth nodes of an anisotropic fit (default ``resolution``).
    gaf : {"smith", "vgroove", "normal_map"}
        GAF of the fitted model: power iterations for Smith (Eq. 4.9, 4.15), closed forms
        otherwise (Eq. 4.16-4.18, their exact ``G(o, o)``).
    shadowing : bool
        Shadowing of the returned BRDF (the Fresnel term is extracted against it).
    backscatter_gaf : {None, "height_correlated", "masking"}
        Smith backscattering model inverted: ``G2(o, o) = 1 / (1 + 2 Lambda(o))`` of the
        library's height-correlated BRDF, or the thesis's ``G1(o)`` (Eq. 4.3). None (the
        default) takes the one the returned BRDF renders with: height-correlated with
        ``shadowing``, masking without; so a fit of the library's own BRDF inverts it.
    diffuse : bool
        Also fit a Lambertian base ``k_d / pi``: for a base luminance ``b`` the NDF is
        extracted from the backscattering minus ``b / pi`` and ``k_d`` (RGB) is solved
        jointly with the Fresnel table (:func:`extract.solve_fresnel`, ``k_d`` bounded by
        the backscattering); ``b`` minimizes the misfit of the whole model to the data
        (:func:`extract.chi2_residual`, a bounded scalar search of at most
        ``diffuse_iterations`` steps, compared with ``b = 0``). Alternating NDF and base
        instead converges to a biased fixed point (part of the base stays in the NDF's
        tail).
    diffuse_iterations : int
        Most steps of that scalar search of ``b``.
    energy_constraint : bool
        Bound the fit's directional albedo by the data's plus :data:`ENERGY_MARGIN` at
        the views of :func:`_energy_views` (0-80 degrees; :func:`extract.albedo_rows`,
        linear inequalities on the Fresnel table solved with it). On by default: a
        microfacet lobe whose NDF comes from backscattering can be wider than the data's
        lobe away from backscattering (measured metals), and the unconstrained Fresnel
        term then reflects more than the data. Inactive (no cost but the albedo rows)
        when the fit already conserves the data's energy. The Fresnel table is always
        bounded to ``[0, 1]`` (white furnace <= 1).
    albedo_weight : float or None
        Weight ``lambda`` of the data's directional albedo at the same views in the
        Fresnel (and ``k_d``) solve, ``lambda^2 / V sum_v (a_fit / a_data - 1)^2`` added
        to the relative misfit (:func:`extract.solve_fresnel`): with the constraint alone
        the albedo is only bounded from above and falls short of the data's where the
        lobe's shape misses it; the term makes the fit carry the data's energy (as
        :func:`~microfacet.fit.analytic.fit_analytic`'s albedo term). 0: shape only.
        Needs ``energy_constraint`` (ignored without it). None (the default):
        :data:`ALBEDO_WEIGHT` for isotropic fits, 0 for anisotropic ones, where the
        term (32 views) drives the table into oscillation on the sampling noise of the
        albedo rows and misses the data's albedo anyway.
    tol, max_iter
        Stopping rule of the power iterations (relative change of the eigenvector).

    Returns
    -------
    FittedBRDF

    References
    ----------
    Dupuy 2015, thesis, Ch. 4: Eq. 4.3, 4.9, 4.16-4.18, Algorithms 1-3; Dupuy et al. 2015.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2), mf.fresnel.Schlick(0.9))
    >>> fitted = fit(reference, resolution=8)
    >>> h = np.array([0.0, 0.0, 1.0])
    >>> round(float(fitted.ndf(h)), 2), round(float(reference.ndf(h)), 2)     # D at the normal
    (7.92, 7.96)
    >>> fitted.save("beckmann.npz").name
    'beckmann.npz'
    >>> load("beckmann.npz")
    FittedBRDF(TabulatedIsotropic(n=15, alpha_x=1.0, alpha_y=1.0, rho=0.0, mean_slope=[0.0, 0.0]), gaf='smith', f0=0.9042)
    """
    n, m, albedo_weight = _checked_options(resolution, resolution_phi, anisotropic, gaf, tol, max_iter,
                                           diffuse_iterations, albedo_weight)
    brdf = extract.screen_measured(brdf)         # huge samples: ignored if few, refused if many
    theta, phi, f_back = _backscattering_table(brdf, n, m if anisotropic else None)
    problem = _TableProblem(
        brdf, theta, phi, f_back, gaf, _backscatter_model(backscatter_gaf, shadowing), shadowing, tol, max_iter,
        extract.fresnel_samples(brdf, n, n_phi_h=(8 if anisotropic else 1), isotropic=not anisotropic),
        _energy_views(anisotropic) if energy_constraint else None, albedo_weight,
        _diffuse_bound(brdf) if diffuse else None)
    dist, f0, its, (cos_d, rgb, kd, _) = (_fit_with_base(problem, diffuse_iterations) if diffuse
                                          else _solve_table(problem, 0.0))
    if gaf != "smith":
        f0 = float(extract.luminance(rgb[-1]))
    return FittedBRDF(dist, _fresnel.Tabulated(cos_d, rgb), gaf=gaf, shadowing=shadowing, f0=f0,
                      iterations=its, backscatter_gaf=problem.model, diffuse=kd)


def _checked_options(resolution, resolution_phi, anisotropic, gaf, tol, max_iter, diffuse_iterations,
                     albedo_weight) -> tuple[int, int, float]:
    """``(N, M, albedo weight)`` of :func:`fit`'s options, or a ``ValueError`` naming the bad one."""
    if gaf not in GAFS:
        raise ValueError(f"gaf must be one of {GAFS}, got {gaf!r}")
    for name, v, low in (("max_iter", max_iter, 1), ("diffuse_iterations", diffuse_iterations, 1),
                         ("resolution_phi", 4 if resolution_phi is None else resolution_phi, 4)):
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= low):
            raise ValueError(f"{name} must be an integer >= {low}, got {v!r}")
    if not (isinstance(tol, (int, float, np.integer, np.floating)) and np.isfinite(tol) and tol > 0):
        raise ValueError(f"tol must be a finite number > 0, got {tol!r}")
    if albedo_weight is None:
        albedo_weight = 0.0 if anisotropic else ALBEDO_WEIGHT
    if not (np.isfinite(albedo_weight) and albedo_weight >= 0):
        raise ValueError(f"albedo_weight must be a finite number >= 0, got {albedo_weight!r}")
    n = int(resolution)
    if n < 4:
        raise ValueError(f"resolution must be >= 4, got {resolution!r}")
    return n, n if resolution_phi is None else int(resolution_phi), float(albedo_weight)


def _backscattering_table(brdf, n: int, m: int | None) -> tuple:
    """``(theta, phi, f(o, o))``: the backscattering of ``brdf`` (luminance) at the ``N``
    nodes of :func:`theta_grid` (the pole excluded), and ``M`` azimuths for an anisotropic
    fit (``phi`` None for an isotropic one)."""
    theta = theta_grid(n)
    phi = None if m is None else np.arange(m) * (2.0 * np.pi / m)
    f_back = (extract.backscattering(brdf, theta[:-1]) if phi is None
              else extract.backscattering(brdf, theta[:-1, None], phi[None, :]))
    f_back = _holes_filled(f_back, theta[:-1])
    if not float(np.max(f_back)) <= 1e100:       # the normal equations square the values
        raise MicrofacetError(f"fit: {brdf!r}: backscattering reaches {float(np.max(f_back)):.3g}, beyond what "
                              "a fit's float64 arithmetic holds (are the values physical?)")
    return theta, phi, f_back


def _holes_filled(f_back: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """``f_back`` (backscattering at the elevations ``theta``, axis 0; one column per
    azimuth) with its holes filled: a zero (unmeasured, or garbage set to 0 by
    :func:`extract.backscattering`) between measured values is interpolated linearly in
    ``ln f`` over ``theta`` from its measured neighbours, and zeros before the first
    measured elevation take its value. A measured table misses directions near
    retro-reflection (RGL's gonio-photometer cannot place sensor and light together; the
    MERL-format corpus marks them unmeasured), and a zero there becomes ``D = 0`` on a
    ring of normals: a black ring on the fit's spheres. Zeros after the last measured
    elevation (grazing) are kept.

    Examples
    --------
    >>> _holes_filled(np.array([0.0, 4.0, 0.0, 1.0, 0.0]), np.arange(5.0))
    array([4., 4., 2., 1., 0.])
    """
    columns = f_back.reshape(len(theta), -1)
    out = columns.copy()
    for j in range(columns.shape[1]):
        measured = np.flatnonzero(columns[:, j] > 0)
        if len(measured) == 0:
            continue
        holes = np.flatnonzero(columns[: measured[-1], j] <= 0)
        if len(holes):
            out[holes, j] = np.exp(np.interp(theta[holes], theta[measured], np.log(columns[measured, j])))
    return out.reshape(f_back.shape)


def _diffuse_bound(brdf) -> np.ndarray:
    """Largest Lambertian ``k_d`` (RGB) under the backscattering up to 70 degrees, per channel."""
    th = np.linspace(0.0, np.radians(70.0), 29)
    o = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], axis=-1)
    rgb_back = np.asarray(brdf.eval(o, o), dtype=np.float64)
    return np.pi * np.min(np.where(np.isfinite(rgb_back), np.maximum(rgb_back, 0.0), 0.0), axis=0)


@dataclass(frozen=True)
class _TableProblem:
    """What one tabulated fit solves, read once: the data, its backscattering ``f_back`` at
    ``theta`` (x ``phi``), the model (``gaf``, the inverted backscattering ``model``,
    ``shadowing``), the power iterations' ``tol``/``max_iter``, the Fresnel ``samples``,
    the energy constraint's ``views`` (None: off), the albedo weight and ``kd_max`` (None:
    no Lambertian base)."""
    brdf: object
    theta: np.ndarray
    phi: np.ndarray | None
    f_back: np.ndarray
    gaf: str
    model: str
    shadowing: bool
    tol: float
    max_iter: int
    samples: tuple
    views: np.ndarray | None
    albedo_weight: float
    kd_max: np.ndarray | None


def _solve_table(problem: _TableProblem, base: float) -> tuple:
    """NDF from the backscattering minus ``base / pi`` (luminance), then the Fresnel table
    (and ``k_d``) against it: ``(dist, f0, its, (cos_d, rgb, k_d, residual))``."""
    pr = problem
    dist, f0, its = _fit_ndf(np.maximum(pr.f_back - base / np.pi, 0.0), pr.theta, pr.phi, pr.gaf, pr.model,
                             pr.tol, pr.max_iter)
    ideal = MicrofacetBRDF(dist, gaf=pr.gaf, shadowing=pr.shadowing)
    n = len(pr.theta)
    energy = None if pr.views is None else extract.albedo_rows(pr.brdf, ideal, n, pr.views, n_u=20)
    diffuse = pr.kd_max is not None
    solved = extract.solve_fresnel(pr.samples, ideal, diffuse=diffuse, albedo=energy, kd_max=pr.kd_max,
                                   albedo_weight=pr.albedo_weight, energy_margin=ENERGY_MARGIN)
    return dist, f0, its, solved


def _fit_with_base(problem: _TableProblem, iterations: int) -> tuple:
    """:func:`_solve_table` at the base luminance that minimizes the whole model's misfit (a
    bounded scalar search of at most ``iterations`` steps, kept only if better than no base)."""
    from scipy.optimize import minimize_scalar
    top = float(min(extract.luminance(problem.kd_max), np.pi * np.max(problem.f_back)))
    cache = {}

    def misfit(base):
        if base not in cache:
            try:
                cache[base] = _solve_table(problem, base)
            except MicrofacetError:          # nothing left for the lobe
                return np.inf
        return cache[base][3][3]

    best = 0.0
    if top > 0:
        found = minimize_scalar(misfit, bounds=(0.0, top), method="bounded",
                                options=dict(xatol=1e-3 * top, maxiter=max(int(iterations), 1))).x
        best = found if misfit(found) < misfit(0.0) else 0.0
    return cache[best] if best in cache else _solve_table(problem, best)


# ------------------------------------------------------------------------- files
_KEYS = ("format", "version", "kind", "gaf", "shadowing", "ndf", "fresnel_cos", "fresnel_rgb", "f0",
         "iterations", "alpha_x", "alpha_y", "rho", "mean_slope")


def load(path: str | os.PathLike, model: str | None = None):
    """Read a fit written by :meth:`FittedBRDF.save` or ``microfacet fit`` (any of
    :data:`READABLE_VERSIONS`): the tabulated :class:`FittedBRDF` (``model`` None or
    ``"tabulated"``), or the fit named ``model`` among those the file keeps
    (:func:`fit_names`; ``"best"``: the one ``microfacet fit`` chose by image error) as a
    BRDF (:func:`microfacet.fit.spec.from_spec`). Raises :class:`MicrofacetError` naming
    the file when it is not a valid fit file of a supported version, or naming the fits it
    has when ``model`` is not one of them, and saying what it is when it is another
    microfacet ``.npz`` (a glint microsurface of ``microfacet glints``).

    Parameters
    ----------
    path : str or os.PathLike
        A fit file written by :meth:`FittedBRDF.save` or ``microfacet fit``.
    model : str, optional
        ``None`` or ``"tabulated"`` for the tabulated fit, ``"best"`` for the file's best, or
        the name of an analytic fit (:func:`fit_names`).

    Returns
    -------
    FittedBRDF or BRDF
        The tabulated fit, or the analytic BRDF tree of ``model``.

    Example
    -------
    >>> best = load("nickel.npz", model="best")          # doctest: +SKIP
    >>> best.eval(wi, wo)                                 # doctest: +SKIP
    """
    path = Path(path)
    data = load_npz(path, "a microfacet fit file")
    if "format" not in data and "magic" in data:
        from ..glints.microsurface import MAGIC as GLINTS_MAGIC
        if str(data["magic"]) == GLINTS_MAGIC:
            raise MicrofacetError(f"{path}: a glint microsurface written by 'microfacet glints' "
                                  "(read it with microfacet.glints.Microsurface.load), not a microfacet fit file "
                                  "(written by 'microfacet fit' or FittedBRDF.save)")
    try:
        if model is None or model == "tabulated" or (model == "best" and "fits" not in data):
            return _from_arrays(data)
        fits, best = _fits_of(data)
        name = best if model == "best" else model
        if name == "tabulated":
            return _from_arrays(data)
        if name not in fits:
            raise MicrofacetError(f"{path}: no fit named {model!r}; the file has: "
                                  f"{', '.join(['best', 'tabulated', *fits])}")
        from .spec import from_spec
        return from_spec(fits[name])
    except (KeyError, ValueError, TypeError, IndexError) as e:
        raise MicrofacetError(f"{path}: invalid microfacet fit file: {e}") from None


def _fits_of(data: dict) -> tuple[dict, str]:
    if "fits" not in data:
        return {}, "tabulated"
    fits = json.loads(str(data["fits"]))
    if not isinstance(fits, dict):
        raise ValueError("fits is not a JSON object")
    return fits, str(data["best"]) if "best" in data else "tabulated"


def fit_names(path: str | os.PathLike) -> tuple[list[str], str]:
    """``(names, best)``: the fits a fit file keeps (``"tabulated"`` first) and the name of
    the best one (``"tabulated"`` in files that keep only it).

    Parameters
    ----------
    path : str or os.PathLike
        A fit file (``.npz``).

    Returns
    -------
    names : list of str
        The fits it keeps, ``"tabulated"`` first.
    best : str
        The name of its best fit.

    Examples
    --------
    >>> import microfacet as mf
    >>> path = fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), resolution=8).save("ggx.npz")
    >>> fit_names(path)
    (['tabulated'], 'tabulated')
    """
    path = Path(path)
    data = load_npz(path, "a microfacet fit file")
    try:
        fits, best = _fits_of(data)
    except (ValueError, TypeError) as e:
        raise MicrofacetError(f"{path}: invalid microfacet fit file: {e}") from None
    return ["tabulated", *fits], best


def _from_arrays(data: dict) -> FittedBRDF:
    missing = [k for k in _KEYS if k not in data]
    if missing:
        raise KeyError(f"missing fields {missing}")
    if str(data["format"]) != FORMAT:
        raise ValueError(f"format is {str(data['format'])!r}, expected {FORMAT!r}")
    version = int(data["version"])
    if version not in READABLE_VERSIONS:
        raise ValueError(f"unsupported version {version} (this library reads versions {READABLE_VERSIONS})")
    kind, gaf = str(data["kind"]), str(data["gaf"])
    if gaf not in GAFS:
        raise ValueError(f"gaf is {gaf!r}")
    ndf = np.asarray(data["ndf"], dtype=np.float64)
    params = dict(alpha_x=data["alpha_x"], alpha_y=data["alpha_y"], rho=data["rho"], mean_slope=data["mean_slope"])
    if kind == "isotropic":
        if ndf.ndim != 1:
            raise ValueError(f"isotropic ndf must be 1D, got shape {ndf.shape}")
        dist = TabulatedIsotropic(ndf, **params)
    elif kind == "anisotropic":
        if ndf.ndim != 2:
            raise ValueError(f"anisotropic ndf must be 2D, got shape {ndf.shape}")
        area = np.asarray(data["projected_area"], dtype=np.float64) if "projected_area" in data else None
        if area is not None and (area.shape[1:] != ndf.shape[1:] or area.shape[0] < 2
                                 or not np.all(np.isfinite(area)) or np.any(area < 0)):
            raise ValueError(f"projected_area of shape {area.shape} does not match ndf {ndf.shape}")
        dist = TabulatedAnisotropic(ndf, n_lambda=None if area is None else area.shape[0],
                                    projected_area=area, **params)
    else:
        raise ValueError(f"kind is {kind!r}")
    fresnel = _fresnel.Tabulated(data["fresnel_cos"], data["fresnel_rgb"])
    # version 1 files: Eq. 4.3 backscattering, no diffuse base
    model = str(data["backscatter_gaf"]) if "backscatter_gaf" in data else "masking"
    diffuse = np.asarray(data["diffuse"], dtype=np.float64) if "diffuse" in data else np.zeros(3)
    if diffuse.shape != (3,):
        raise ValueError(f"diffuse must have 3 values, got shape {diffuse.shape}")
    return FittedBRDF(dist, fresnel, gaf=gaf, shadowing=bool(data["shadowing"]), f0=float(data["f0"]),
                      iterations=int(data["iterations"]), backscatter_gaf=model, diffuse=diffuse)
