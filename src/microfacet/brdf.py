"""BRDF protocol, microfacet BRDF (thesis Ch. 2, 3.2) and Lambertian BRDF (Eq. 1.9).

Every BRDF-like object answers ``eval``, ``eval_cos``, ``sample`` and ``pdf`` over
arrays of directions: ``wi`` is the light (emitter) direction, ``wo`` the view
(receiver) direction, both unit ``(..., 3)`` in the local frame (z = macro normal).
Directions that are not unit length (within :data:`UNIT_TOLERANCE`), or hold NaN/inf,
and uniforms outside ``[0, 1]`` raise ``ValueError``: they are never normalized silently.
Each method also writes its result into ``out`` if given (NumPy's ``out=``; ``sample``: a
tuple ``(wi, weight, pdf)``), C-contiguous arrays of the result's shape and dtype that share
no memory with the inputs (``ValueError`` naming ``out`` otherwise), and returns them; for
:class:`MicrofacetBRDF`'s compiled kernels, which write straight into them, that saves the
allocation and first touch of new outputs.
"""
from __future__ import annotations

import numpy as np

from . import fresnel as _fresnel
from . import kernels
from .distributions.base import SlopeDistribution
from .geometry import (cosine_hemisphere_pdf, dot, half_vector, reflect,
                       square_to_cosine_hemisphere)

__all__ = ["BRDF", "MicrofacetBRDF", "Lambertian", "GAFS", "UNIT_TOLERANCE", "unit_directions", "uniforms"]

GAFS = ("smith", "vgroove", "normal_map")


#: Largest accepted ``| |w|^2 - 1 |`` of a direction (``|w|`` within about ``1 +- 5e-6``):
#: unit vectors rounded to float32 pass (their error is ~1e-7); within it ``f_r`` moves by
#: ~1e-5 relative (1 % too long changes it by 2.2 %), so directions are used as given.
UNIT_TOLERANCE = 1e-5


def _as_dirs(w, name: str, float32: bool = False) -> np.ndarray:
    """``w`` as float64 directions ``(..., 3)`` (float32 arrays stay float32 if ``float32``, for
    the compiled kernels, which read either); ``ValueError`` naming ``name`` if the last axis is not 3."""
    w = np.asarray(w)
    if not (float32 and w.dtype == np.float32):
        w = w.astype(np.float64, copy=False)
    if w.shape[-1:] != (3,):
        raise ValueError(f"{name} must have a last axis of size 3, got shape {w.shape}")
    return w


def _check_unit(w, name: str, deviation=None) -> None:
    """``ValueError`` naming ``name`` if a vector of ``w`` is not unit length within
    :data:`UNIT_TOLERANCE` (NaN, inf and zero vectors included). ``deviation``: the largest
    ``| |w|^2 - 1 |`` (or an upper bound of it) if a kernel measured it while reading ``w``, else,
    and where that fails, one compiled pass (:func:`microfacet.kernels.unit_deviation`)."""
    if deviation is None or not deviation <= UNIT_TOLERANCE:
        deviation = kernels.unit_deviation(w)
    if not deviation <= UNIT_TOLERANCE:
        n2 = np.sum(w * w, axis=-1)
        bad = np.argwhere(~(np.abs(n2 - 1.0) <= UNIT_TOLERANCE))[0]
        where = f" at index {tuple(bad.tolist())}" if w.ndim > 1 else ""
        raise ValueError(f"{name} must be unit vectors (| |w|^2 - 1 | <= {UNIT_TOLERANCE:g}; "
                         f"normalize them first), got {w[tuple(bad)].tolist()} of length "
                         f"{np.sqrt(n2[tuple(bad)]):.9g}{where}")


def _dirs(w, name: str, float32: bool = False) -> np.ndarray:
    """``w`` as unit directions ``(..., 3)`` (the convention of every BRDF method): :func:`_as_dirs`
    and :func:`_check_unit`."""
    w = _as_dirs(w, name, float32)
    _check_unit(w, name)
    return w


def _as_uniforms(u, float32: bool = False) -> np.ndarray:
    """``u`` as float64 uniforms ``(..., 2)`` (float32 arrays stay float32 if ``float32``);
    ``ValueError`` if the last axis is not 2."""
    u = np.asarray(u)
    if not (float32 and u.dtype == np.float32):
        u = u.astype(np.float64, copy=False)
    if u.shape[-1:] != (2,):
        raise ValueError(f"u must have a last axis of size 2, got shape {u.shape}")
    return u


def _check_uniforms(u, name: str = "u", outside=None) -> None:
    """``ValueError`` if a value of ``u`` lies outside ``[0, 1]`` (NaN too). ``outside``: nonzero
    if a kernel found one while reading ``u``, else two NumPy passes."""
    if outside is None:
        outside = u.size and not (np.min(u) >= 0.0 and np.max(u) <= 1.0)
    if outside:
        bad = ~((u >= 0.0) & (u <= 1.0))
        raise ValueError(f"{name} must lie in [0, 1] (uniform random numbers), got {float(u[bad][0])!r} "
                         f"({int(bad.sum())} value(s) outside)")


def _uniforms(u, float32: bool = False) -> np.ndarray:
    """``u`` as uniforms ``(..., 2)`` in ``[0, 1]``: :func:`_as_uniforms` and :func:`_check_uniforms`."""
    u = _as_uniforms(u, float32)
    _check_uniforms(u)
    return u


def unit_directions(w, name: str) -> np.ndarray:
    """``w`` as float64 unit directions ``(..., 3)``, checked as every BRDF method checks its
    ``wi``/``wo`` (one-line ``ValueError`` naming ``name``); for BRDFs defined elsewhere."""
    return _dirs(w, name)


def uniforms(u) -> np.ndarray:
    """``u`` as float64 uniforms ``(..., 2)`` in ``[0, 1]``, checked as :meth:`BRDF.sample` does."""
    return _uniforms(u)


def _fused(kernel, float32: bool, **inputs):
    """``(arrays, result)``: ``inputs`` (directions ``wi``/``wo``, uniforms ``u``; keyword order
    is the order of their checks) converted as by :func:`_dirs` / :func:`_uniforms`, and the
    result of ``kernel(**arrays)``, a :mod:`microfacet.kernels` function that returns ``(result,
    checks)`` (the inputs' measures, taken while it read them: no pass of their own) or ``None``
    where it does not apply (then ``result`` is ``None`` and the inputs are checked here).
    A bad input raises the ``ValueError`` of :func:`_dirs` / :func:`_uniforms`, whose messages are
    built from the inputs, after the kernel (its outputs are dropped); a malformed input or shapes
    that do not broadcast raise after the checks of the inputs before them, as :func:`_dirs`
    called in turn would."""
    arrays = {}
    checks = {name: _check_uniforms if name == "u" else _check_unit for name in inputs}
    try:
        for name, value in inputs.items():
            arrays[name] = _as_uniforms(value, float32) if name == "u" else _as_dirs(value, name, float32)
        fast = kernel(**arrays)
    except ValueError:
        for name, a in arrays.items():
            checks[name](a, name)
        raise
    measures = {} if fast is None else fast[1]
    for name, a in arrays.items():
        checks[name](a, name, measures.get(name))
    return arrays, None if fast is None else fast[0]


def _into(out, result: np.ndarray, inputs) -> np.ndarray:
    """``result``, or ``out`` with ``result`` copied in (:func:`microfacet.kernels.output`)."""
    if out is None:
        return result
    np.copyto(kernels.output(out, result.shape, result.dtype, "out", tuple(inputs)), result)
    return out


def _into_sample(out, result, inputs):
    """``(wi, weight, pdf)`` ``result``, or ``out``'s three arrays with it copied in
    (:func:`microfacet.kernels.sample_outputs`)."""
    if out is None:
        return result
    out = kernels.sample_outputs(out, result[2].shape, result[2].dtype, tuple(inputs))
    for o, a in zip(out, result):
        np.copyto(o, a)
    return out


class BRDF:
    """The BRDF protocol (Listing 1.2). Subclasses implement ``eval_cos``, ``sample``
    and ``pdf``; ``eval`` divides by ``cos theta_i``."""

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:  # pragma: no cover - interface
        """Projected BRDF ``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)`` (``evalp``)."""
        raise NotImplementedError

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """BRDF value ``f_r(wi, wo)``, RGB ``(..., 3)``; 0 below either horizon."""
        wi = _dirs(wi, "wi")
        zi = wi[..., 2:3]
        fc = self.eval_cos(wi, wo)
        f = np.divide(fc, zi, out=np.zeros(np.broadcast_shapes(fc.shape, zi.shape)), where=zi > 0)
        return _into(out, f, (wi, wo))

    def sample(self, u, wo, out=None):  # pragma: no cover - interface
        """Importance-sample ``f_r cos theta_i``: ``(wi, weight, pdf)`` from uniforms
        ``u`` in ``[0,1]^2`` (``ValueError`` outside), with ``weight = eval_cos / pdf``
        (``evalp_is``)."""
        raise NotImplementedError

    def pdf(self, wi, wo, out=None) -> np.ndarray:  # pragma: no cover - interface
        """Solid-angle density of ``sample`` producing ``wi`` from ``wo``."""
        raise NotImplementedError


class Lambertian(BRDF):
    """Ideal diffuse BRDF ``f_r = k_d / pi`` (Eq. 1.9), sampled by the cosine warp."""

    def __init__(self, reflectance=1.0):
        try:
            r = np.broadcast_to(np.asarray(reflectance, dtype=np.float64), (3,)).copy()
        except (ValueError, TypeError):
            raise ValueError(f"reflectance must be a number or 3 RGB numbers, got {reflectance!r}") from None
        if not np.all((r >= 0) & (r <= 1)):      # albedo <= 1: energy conservation
            raise ValueError(f"reflectance must lie in [0, 1] per channel, got {reflectance!r}")
        self.reflectance = r

    def __repr__(self) -> str:
        return f"Lambertian(reflectance={self.reflectance.tolist()})"

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        wi, wo = _dirs(wi, "wi"), _dirs(wo, "wo")
        zi, zo = wi[..., 2], wo[..., 2]
        return _into(out, np.where((zi > 0) & (zo > 0), zi / np.pi, 0.0)[..., None] * self.reflectance, (wi, wo))

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        wi, wo = _dirs(wi, "wi"), _dirs(wo, "wo")
        return _into(out, np.where(wo[..., 2] > 0, cosine_hemisphere_pdf(wi), 0.0), (wi, wo))

    def sample(self, u, wo, out=None):
        wo = _dirs(wo, "wo")
        u = _uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        wi = square_to_cosine_hemisphere(np.broadcast_to(u, shape + (2,)))
        ok = (wo[..., 2] > 0) & (wi[..., 2] > 0)
        pdf = np.where(ok, cosine_hemisphere_pdf(wi), 0.0)
        return _into_sample(out, (wi, np.where(ok[..., None], self.reflectance, 0.0), pdf), (u, wo))


class MicrofacetBRDF(BRDF):
    """Microfacet BRDF ``f_r = F D G / (4 cos theta_i cos theta_o)`` (Eq. 2.1).

    Parameters
    ----------
    distribution : SlopeDistribution
        ``mf.Beckmann(...)`` or ``mf.GGX(...)`` with any roughness, correlation and shear.
    fresnel : Fresnel
        Microfacet Fresnel term of ``cos theta_d`` (default: ideal mirrors, ``F = 1``).
    gaf : {"smith", "vgroove", "normal_map"}
        Geometric attenuation factor (Table 2.IV).
    shadowing : bool
        If False, the GAF accounts for masking (of ``wo``) only.
    dtype : {numpy.float64, numpy.float32}
        Type of the results of ``eval``, ``eval_cos``, ``pdf`` and ``sample``. With float32,
        the compiled kernels (Smith, scalar parameters) read float32 directions and uniforms
        as they are (no float64 copy), compute in float32 (twice the SIMD width, approximate
        reciprocal square roots refined by a Newton step: GGX 2.5-3x faster than float64,
        Beckmann eval 2.7x, pdf 2.3x, sample 1.3x, on one core) and write float32; Beckmann's
        visible-slope solve and the Tabulated Fresnel interpolation stay float64, and its
        Gaussian factor ``exp(-|slope|^2)`` is flushed to 0 below 2^-120, near float32's
        smallest normal 2^-126, as a renderer's flush-to-zero mode would (subnormal arithmetic
        is slow). Against float64 on the same inputs, where ``f`` is
        well-conditioned (``z_i, z_o > 0.05`` and ``f cos`` above 1e-6 of its largest value):
        ``f cos`` and pdf within 1e-5 relative for 99.9 % of pairs (2e-4 worst), sampled directions
        within 3e-5 (tested in ``tests/test_kernels.py``). Smaller values, in the Gaussian tails,
        keep less relative precision (Beckmann, alpha 0.2 / 0.5, uniform pairs: 12.7 % of the
        pairs beyond 1e-5, all below 1e-6 of the largest value, down to the flush). The NumPy path
        computes in float64 and rounds.
    """

    def __init__(self, distribution: SlopeDistribution, fresnel: _fresnel.Fresnel | None = None,
                 gaf: str = "smith", shadowing: bool = True, dtype=np.float64):
        if not isinstance(distribution, SlopeDistribution):
            raise ValueError(f"distribution must be a SlopeDistribution, got {type(distribution).__name__}")
        if gaf not in GAFS:
            raise ValueError(f"gaf must be one of {GAFS}, got {gaf!r}")
        if gaf == "vgroove" and np.any(np.abs(distribution.mean_slope) > 1e-6):
            # Table 2.IV's V-grooves stand on the macro normal: with a mean slope their albedo
            # reaches 1.78 (Beckmann 0.3, mean slope (0.5, -1)); the sheared model is Smith's.
            raise ValueError("gaf='vgroove' needs a zero mean slope (V-grooves stand on the macro "
                             "normal); use gaf='smith' for noncentral surfaces")
        if np.dtype(dtype) not in (np.float32, np.float64):
            raise ValueError(f"dtype must be numpy.float32 or numpy.float64, got {dtype!r}")
        self.dtype = np.dtype(dtype)
        distribution.check_dtype(self.dtype)
        self.distribution = distribution
        self.fresnel = _fresnel.Ideal() if fresnel is None else fresnel
        self.gaf_model = gaf
        self.shadowing = bool(shadowing)

    def __repr__(self) -> str:
        dtype = "" if self.dtype == np.float64 else f", dtype=numpy.{self.dtype}"
        return (f"MicrofacetBRDF({self.distribution!r}, fresnel={self.fresnel!r}, "
                f"gaf={self.gaf_model!r}, shadowing={self.shadowing}{dtype})")

    # ------------------------------------------------------------------- terms
    def ndf(self, h) -> np.ndarray:
        """Microfacet NDF ``D(h)`` (Eq. 2.11, 3.2)."""
        return self.distribution.ndf(h)

    def g1(self, k) -> np.ndarray:
        """Smith masking ``G1(k)`` (Eq. 2.14, 3.3)."""
        return self.distribution.g1(k)

    def vndf(self, h, k) -> np.ndarray:
        """Distribution of visible normals ``D_k(h)`` (Eq. 2.17)."""
        return self.distribution.vndf(h, k)

    def gaf(self, wi, wo, h=None) -> np.ndarray:
        """Geometric attenuation ``G(i, o)`` (Table 2.IV; ``h`` defaults to the half vector).

        Smith: height-correlated, ``G = (z_o / c_o) / (1 + Lambda(i) + Lambda(o))`` with
        ``c_k = z_k - x_k x~n - y_k y~n`` and ``Lambda(k) = A(k) / c_k - 1`` (Eq. 3.3). With a
        zero mean slope this is Eq. 2.13. For sheared surfaces it is the projected-area
        normalization of the LEADR supplemental (Sec. 1.5 and its point-light formula,
        Sec. 3.3: ``f cos theta_i = F D / (4 c_o (1 + Lambda_i + Lambda_o))``), which keeps
        a tilted mirror's albedo at exactly 1; the macro-frame BRDF is then reciprocal in
        the form ``f(i, o) z_i c_o = f(o, i) z_o c_i``. Without shadowing: ``G1(o)``.
        V-groove: ``min(1, 2 z_i z_h / ih, 2 z_o z_h / oh)``. Normal map: ``z_o z_h / oh``.
        Without shadowing only the ``o`` factors remain.
        """
        wi, wo = _dirs(wi, "wi"), _dirs(wo, "wo")
        h = half_vector(wi, wo) if h is None else np.asarray(h, dtype=np.float64)
        return self._gaf(wi, wo, h, dot(wi, h), dot(wo, h))

    def _gaf(self, wi, wo, h, ih, oh) -> np.ndarray:
        zi, zo, zh = wi[..., 2], wo[..., 2], h[..., 2]
        ok = (zi > 0) & (zo > 0) & (ih > 0) & (oh > 0) & (zh > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            if self.gaf_model == "smith":
                d = self.distribution
                lam_o, co = d._lambda_c(wo)
                ok &= co > 0
                lam_i = d._lambda_c(wi)[0] if self.shadowing else 0.0
                g = zo / (co * (1.0 + lam_i + lam_o))
            else:
                go = zo * zh / oh
                if self.gaf_model == "vgroove":
                    go = 2.0 * go
                    g = np.minimum(1.0, go if not self.shadowing else np.minimum(go, 2.0 * zi * zh / ih))
                else:
                    g = go
        return np.where(ok, g, 0.0)

    # ---------------------------------------------------------------- protocol
    def _projected(self, wi, wo, divide_cos_i: bool = False):
        """``(o.h, D G / (4 z_o))`` at the half vector (``/ z_i`` if asked), 0 where invalid.

        Smith BRDFs with scalar parameters use the fused compiled kernel
        (:mod:`microfacet.kernels`); :meth:`_projected_numpy` is the reference.
        """
        return self._projected_unit(_dirs(wi, "wi"), _dirs(wo, "wo"), divide_cos_i)

    def _projected_unit(self, wi, wo, divide_cos_i: bool = False):
        """:meth:`_projected` of directions already checked by ``_dirs``."""
        if self.gaf_model == "smith":
            fast = kernels.smith_projected(self.distribution, self.shadowing, wi, wo, divide_cos_i, background=True)
            if fast is not None:
                return fast
        return self._projected_numpy(wi, wo, divide_cos_i)

    def _projected_numpy(self, wi, wo, divide_cos_i: bool = False):
        h = half_vector(wi, wo)
        oh = dot(wo, h)
        g = self._gaf(wi, wo, h, oh, oh)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(g > 0, self.ndf(h) * g / (4.0 * wo[..., 2]), 0.0)
            if divide_cos_i:
                s = np.where(s > 0, s / wi[..., 2], 0.0)
        return oh, s

    def _eval(self, wi, wo, divide_cos_i: bool, out=None) -> np.ndarray:
        """``F D G / (4 z_o) [/ z_i]``: one compiled pass for Smith BRDFs with scalar
        parameters and a :mod:`microfacet.fresnel` term (:func:`microfacet.kernels.smith_eval`),
        :meth:`_projected` times the Fresnel term otherwise (the reference; while the eval kernel
        compiles in the background, :meth:`_projected_numpy`: see :mod:`microfacet.kernels`)."""
        d, fast = _fused(lambda wi, wo: kernels.smith_eval(self, wi, wo, divide_cos_i, self.dtype, out, background=True),
                         self.dtype == np.float32, wi=wi, wo=wo)
        if fast is not None:
            return fast
        wi, wo = d["wi"].astype(np.float64, copy=False), d["wo"].astype(np.float64, copy=False)
        projected = self._projected_numpy if kernels.covers(self) else self._projected_unit
        oh, s = projected(wi, wo, divide_cos_i)
        return _into(out, (self.fresnel(oh) * s[..., None]).astype(self.dtype, copy=False), d.values())

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_r cos theta_i = F D G / (4 cos theta_o)`` (Listing 2.2)."""
        return self._eval(wi, wo, False, out)

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f_r = F D G / (4 cos theta_i cos theta_o)`` (Eq. 2.1). ``out`` (see the module): of
        the BRDF's ``dtype``; the kernels write into it as they go, so its contents are
        unspecified after a ``ValueError`` on the inputs."""
        return self._eval(wi, wo, True, out)

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of ``sample``: the density of the sampled normal over ``4 oh`` (one compiled
        pass for Smith BRDFs with scalar parameters, :func:`microfacet.kernels.smith_pdf`)."""
        d, fast = _fused(lambda wi, wo: kernels.smith_pdf(self, wi, wo, self.dtype, out, background=True),
                         self.dtype == np.float32,
                         wi=wi, wo=wo)
        if fast is not None:
            return fast
        return _into(out, self._pdf_numpy(d["wi"].astype(np.float64, copy=False),
                                          d["wo"].astype(np.float64, copy=False)).astype(self.dtype, copy=False),
                     d.values())

    def _pdf_numpy(self, wi, wo) -> np.ndarray:
        """NumPy reference of :meth:`pdf` (unit ``wi``, ``wo``)."""
        h = half_vector(wi, wo)
        oh = dot(wo, h)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (oh > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(ok, self._normal_pdf(h, wo) / (4.0 * oh), 0.0)

    @property
    def _samples_visible(self) -> bool:
        return self.gaf_model == "smith" and self.distribution.supports_visible_sampling

    def _normal_pdf(self, h, wo) -> np.ndarray:
        """Density of the sampled normals: ``D_o(h)`` for visible normals (Smith, Eq. 2.17),
        ``D(h) z_h`` for slopes drawn from ``P``."""
        if self._samples_visible:
            return self.distribution.vndf(h, wo)
        return self.distribution.ndf(h) * h[..., 2]

    def sample(self, u, wo, out=None):
        """Reflect ``wo`` about a sampled normal: visible normals for Smith (Sec. 2.2, 3.2)
        when the distribution supports it, slopes of ``P`` otherwise. Returns
        ``(wi, weight, pdf)``; the Smith weight is ``F G / G1(o)`` (Eq. 2.23). Failed
        samples have weight 0 and pdf 0. Smith BRDFs with scalar parameters and a
        :mod:`microfacet.fresnel` term run one compiled pass (:func:`microfacet.kernels.smith_sample`)."""
        d, fast = _fused(lambda wo, u: kernels.smith_sample(self, u, wo, self.dtype, out, background=True),
                         self.dtype == np.float32,
                         wo=wo, u=u)
        if fast is not None:
            return fast
        result = self._sample_numpy(d["u"].astype(np.float64, copy=False), d["wo"].astype(np.float64, copy=False))
        return _into_sample(out, tuple(a.astype(self.dtype, copy=False) for a in result), d.values())

    def _sample_numpy(self, u, wo):
        """NumPy reference of :meth:`sample` (unit ``wo``, uniforms ``u``)."""
        if self._samples_visible:
            h = self.distribution.sample_visible(u, wo)
        else:
            h = self.distribution.sample_p22(u)
        wi = reflect(wo, h)
        zi, zo, zh, oh = wi[..., 2], wo[..., 2], h[..., 2], dot(wo, h)
        ok = (zi > 0) & (zo > 0) & (oh > 0)
        g = self._gaf(wi, wo, h, oh, oh)
        with np.errstate(divide="ignore", invalid="ignore"):
            pdf = np.where(ok, self._normal_pdf(h, wo) / (4.0 * oh), 0.0)
            if self._samples_visible:
                ratio = g / self.distribution.g1(wo)             # G / G1(o), Eq. 2.23
            else:
                ratio = g * oh / (zo * zh)                       # F D G / (4 z_o) / (D z_h / (4 oh))
            ok &= pdf > 0
            weight = np.where(ok, ratio, 0.0)[..., None] * self.fresnel(oh)
        return wi, weight, np.where(ok, pdf, 0.0)
