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

Examples
--------
>>> from microfacet.brdf import GAFS, UNIT_TOLERANCE
>>> GAFS, UNIT_TOLERANCE
(('smith', 'vgroove', 'normal_map'), 1e-05)
"""
from __future__ import annotations

import numpy as np

from . import backend
from . import fresnel as _fresnel
from . import kernels
from . import protocol
from .params import SmithParams, smith_params
from .protocol import UNIT_TOLERANCE, directions, into, into_sample
from .distributions.base import SlopeDistribution
from .geometry import (cosine_hemisphere_pdf, dot, half_vector, reflect,
                       square_to_cosine_hemisphere)

__all__ = ["BRDF", "MicrofacetBRDF", "Lambertian", "GAFS", "UNIT_TOLERANCE", "unit_directions", "uniforms"]

GAFS = ("smith", "vgroove", "normal_map")


#: Kept for the fitting modules until they import :mod:`microfacet.protocol` themselves
#: (issue 27: the lead's files); new code imports the public names there.
_into, _into_sample = protocol.into, protocol.into_sample


def unit_directions(w, name: str) -> np.ndarray:
    """``w`` as float64 unit directions ``(..., 3)``, checked as every BRDF method checks its
    ``wi``/``wo`` (one-line ``ValueError`` naming ``name``; :func:`microfacet.protocol.directions`).

    Parameters
    ----------
    w : array_like
        Directions, last axis 3.
    name : str
        Parameter name for the error message.

    Returns
    -------
    (..., 3) ndarray
        The checked unit directions.

    Examples
    --------
    >>> unit_directions([0.0, 0.0, 1.0], "wi")
    array([0., 0., 1.])
    >>> unit_directions([0.0, 0.0, 2.0], "wi")
    Traceback (most recent call last):
        ...
    ValueError: wi must be unit vectors (| |w|^2 - 1 | <= 1e-05; normalize them first), got [0.0, 0.0, 2.0] of length 2
    """
    return directions(w, name)


def uniforms(u) -> np.ndarray:
    """``u`` as float64 uniforms ``(..., 2)`` in ``[0, 1]``, checked as :meth:`BRDF.sample` does
    (:func:`microfacet.protocol.uniforms`).

    Parameters
    ----------
    u : array_like
        Uniform numbers, last axis 2.

    Returns
    -------
    (..., 2) ndarray
        The checked uniforms.

    Examples
    --------
    >>> uniforms([[0.25, 0.5]])
    array([[0.25, 0.5 ]])
    >>> uniforms([1.5, 0.5])
    Traceback (most recent call last):
        ...
    ValueError: u must lie in [0, 1] (uniform random numbers), got 1.5 (1 value(s) outside)
    """
    return protocol.uniforms(u)


def _reference(**arrays):
    """The compiled path's stand-in where :func:`microfacet.backend.smith` chose the NumPy reference:
    no result, so that :func:`_fused` checks the inputs itself."""
    return None


def _fused(kernel, float32: bool, **inputs):
    """``(arrays, result)``: ``inputs`` (directions ``wi``/``wo``, uniforms ``u``; keyword order
    is the order of their checks) converted as by :func:`microfacet.protocol.directions` / :func:`~microfacet.protocol.uniforms`, and the
    result of ``kernel(**arrays)``, a :mod:`microfacet.kernels` function that returns ``(result,
    checks)`` (the inputs' measures, taken while it read them: no pass of their own) or ``None``
    where it does not apply (then ``result`` is ``None`` and the inputs are checked here).
    A bad input raises the ``ValueError`` of :func:`microfacet.protocol.directions` / :func:`~microfacet.protocol.uniforms`, whose messages are
    built from the inputs, after the kernel (its outputs are dropped); a malformed input or shapes
    that do not broadcast raise after the checks of the inputs before them, as :func:`~microfacet.protocol.directions`
    called in turn would."""
    arrays = {}
    checks = {name: protocol.check_uniforms if name == "u" else protocol.check_unit for name in inputs}
    try:
        for name, value in inputs.items():
            arrays[name] = protocol.as_uniforms(value, float32) if name == "u" else \
                protocol.as_directions(value, name, float32)
        fast = kernel(**arrays)
    except ValueError:
        for name, a in arrays.items():
            checks[name](a, name)
        raise
    measures = {} if fast is None else fast[1]
    for name, a in arrays.items():
        checks[name](a, name, measures.get(name))
    return arrays, None if fast is None else fast[0]


class BRDF:
    """The BRDF protocol (Listing 1.2). Subclasses implement ``eval_cos``, ``sample``
    and ``pdf``; ``eval`` divides by ``cos theta_i``.

    References
    ----------
    Dupuy 2015, thesis, Listing 1.2 (the BRDF protocol).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> isinstance(mf.Lambertian(0.5), BRDF), isinstance(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), BRDF)
    (True, True)
    """

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:  # pragma: no cover - interface
        """Projected BRDF ``f_r(wi, wo) cos theta_i``, RGB ``(..., 3)`` (``evalp``).

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up); leading axes broadcast.
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values.
        """
        raise NotImplementedError

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """BRDF value ``f_r(wi, wo)``, RGB ``(..., 3)``; 0 below either horizon.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up); leading axes broadcast.
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        (..., 3) ndarray
            RGB values, per steradian.
        """
        wi = directions(wi, "wi")
        zi = wi[..., 2:3]
        fc = self.eval_cos(wi, wo)
        f = np.divide(fc, zi, out=np.zeros(np.broadcast_shapes(fc.shape, zi.shape)), where=zi > 0)
        return into(out, f, (wi, wo))

    def sample(self, u, wo, out=None):  # pragma: no cover - interface
        """Importance-sample ``f_r cos theta_i``: ``(wi, weight, pdf)`` from uniforms
        ``u`` in ``[0,1]^2`` (``ValueError`` outside), with ``weight = eval_cos / pdf``
        (``evalp_is``).

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
            ``eval_cos / pdf``, RGB (0 for a failed sample).
        pdf : (...) ndarray
            Density per steradian of ``wi``.
        """
        raise NotImplementedError

    def pdf(self, wi, wo, out=None) -> np.ndarray:  # pragma: no cover - interface
        """Solid-angle density of ``sample`` producing ``wi`` from ``wo``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions, local frame (z up); leading axes broadcast.
        out : ndarray, optional
            Array ``(...)`` to write into.

        Returns
        -------
        (...) ndarray
            Density per steradian of ``wi``.
        """
        raise NotImplementedError


class Lambertian(BRDF):
    """Ideal diffuse BRDF ``f_r = k_d / pi`` (Eq. 1.9), sampled by the cosine warp.

    Parameters
    ----------
    reflectance : float or (3,) array_like
        Albedo ``k_d`` per RGB channel, ``[0, 1]``.

    References
    ----------
    Dupuy 2015, thesis, Eq. 1.9.

    Examples
    --------
    >>> import numpy as np
    >>> brdf = Lambertian(reflectance=[0.8, 0.5, 0.2])
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> brdf.eval(n, n).round(4)                 # k_d / pi
    array([0.2546, 0.1592, 0.0637])
    >>> wi, weight, pdf = brdf.sample(np.array([0.5, 0.5]), n)
    >>> weight, round(float(pdf), 4)              # cosine sampling: the weight is k_d
    (array([0.8, 0.5, 0.2]), 0.3183)
    """

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
        wi, wo = directions(wi, "wi"), directions(wo, "wo")
        zi, zo = wi[..., 2], wo[..., 2]
        return into(out, np.where((zi > 0) & (zo > 0), zi / np.pi, 0.0)[..., None] * self.reflectance, (wi, wo))

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        wi, wo = directions(wi, "wi"), directions(wo, "wo")
        return into(out, np.where(wo[..., 2] > 0, cosine_hemisphere_pdf(wi), 0.0), (wi, wo))

    def sample(self, u, wo, out=None):
        wo = directions(wo, "wo")
        u = protocol.uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        wi = square_to_cosine_hemisphere(np.broadcast_to(u, shape + (2,)))
        ok = (wo[..., 2] > 0) & (wi[..., 2] > 0)
        pdf = np.where(ok, cosine_hemisphere_pdf(wi), 0.0)
        return into_sample(out, (wi, np.where(ok[..., None], self.reflectance, 0.0), pdf), (u, wo))


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

    References
    ----------
    Dupuy 2015, thesis, Eq. 2.1 (the BRDF), Table 2.IV (the GAFs), Eq. 2.17 (visible normals).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> wi = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8]])
    >>> wo = np.array([[0.0, 0.0, 1.0], [-0.6, 0.0, 0.8]])
    >>> brdf.eval(wi, wo).round(4)                # normal incidence, then mirror pair at 37 degrees
    array([[0.0354, 0.0354, 0.0354],
           [0.0543, 0.0543, 0.0543]])
    >>> brdf.pdf(wi, wo).round(4)
    array([0.8842, 1.0916])
    >>> wi, weight, pdf = brdf.sample(np.array([0.3, 0.7]), wo[1])
    >>> round(float(np.linalg.norm(wi)), 6), bool(pdf > 0)
    (1.0, True)
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

    #: The attributes :attr:`params` is made of: assigning one makes it again.
    _RECORD_OF = frozenset({"distribution", "fresnel", "gaf_model", "shadowing", "dtype"})

    def __setattr__(self, name, value):
        super().__setattr__(name, value)
        if name in self._RECORD_OF:
            self.__dict__.pop("_params", None)

    @property
    def params(self) -> SmithParams | None:
        """The frozen record of this BRDF for the compiled kernels (:class:`microfacet.params.SmithParams`:
        kind, roughness, correlation, mean slope, shadowing, Fresnel term, as scalars of :attr:`dtype`),
        made once, at first use, and passed whole to them; ``None`` where they do not cover the BRDF
        (another GAF than Smith, array parameters, another distribution or Fresnel class: the NumPy
        path). Made again when an attribute it is made of is assigned; a distribution or Fresnel
        term changed in place is not seen (make a new BRDF)."""
        try:
            return self.__dict__["_params"]
        except KeyError:
            p = None if self.gaf_model != "smith" else smith_params(self.distribution, self.fresnel,
                                                                     self.shadowing, self.dtype)
            self.__dict__["_params"] = p
            return p

    def __getstate__(self) -> dict:
        """The attributes without the :attr:`params` record, made again at first use after
        unpickling: pickle would bring its read-only arrays back writeable, and Numba compiles
        another version of every kernel for writeable arrays (a process pool's workers would
        each compile it instead of loading the cached one)."""
        state = dict(self.__dict__)
        state.pop("_params", None)
        return state

    def __repr__(self) -> str:
        dtype = "" if self.dtype == np.float64 else f", dtype=numpy.{self.dtype}"
        return (f"MicrofacetBRDF({self.distribution!r}, fresnel={self.fresnel!r}, "
                f"gaf={self.gaf_model!r}, shadowing={self.shadowing}{dtype})")

    # ------------------------------------------------------------------- terms
    def ndf(self, h) -> np.ndarray:
        """Microfacet NDF ``D(h)`` (Eq. 2.11, 3.2).

        Parameters
        ----------
        h : (..., 3) array_like
            Unit microfacet normals.

        Returns
        -------
        (...) ndarray
            ``D(h)``, per steradian.
        """
        return self.distribution.ndf(h)

    def g1(self, k) -> np.ndarray:
        """Smith masking ``G1(k)`` (Eq. 2.14, 3.3).

        Parameters
        ----------
        k : (..., 3) array_like
            Unit directions.

        Returns
        -------
        (...) ndarray
            Masking in ``[0, 1]``.
        """
        return self.distribution.g1(k)

    def vndf(self, h, k) -> np.ndarray:
        """Distribution of visible normals ``D_k(h)`` (Eq. 2.17).

        Parameters
        ----------
        h : (..., 3) array_like
            Unit microfacet normals.
        k : (..., 3) array_like
            Unit view directions.

        Returns
        -------
        (...) ndarray
            ``D_k(h)``, per steradian.
        """
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

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions.
        h : (..., 3) array_like, optional
            Microfacet normals; None: the half vectors.

        Returns
        -------
        (...) ndarray
            ``G`` in ``[0, 1]``.
        """
        wi, wo = directions(wi, "wi"), directions(wo, "wo")
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
    def _out(self, out, a, b, last):
        """``out`` checked for a compiled kernel (:func:`microfacet.protocol.output`: the result of
        inputs ``a``, ``b``, shape ``(..., *last)``; ``last=None``: :func:`~microfacet.protocol.sample_outputs`),
        or ``None``: no ``out`` given, or no kernel for this BRDF (the NumPy path checks it)."""
        if out is None or self.params is None:
            return None
        shape = protocol.pair_shape(a, b)
        if last is None:
            return protocol.sample_outputs(out, shape, self.dtype, (a, b))
        return protocol.output(out, shape + last, self.dtype, "out", (a, b))

    def _projected(self, wi, wo, divide_cos_i: bool = False):
        """``(o.h, D G / (4 z_o))`` at the half vector (``/ z_i`` if asked), 0 where invalid.

        Smith BRDFs with scalar parameters use the fused compiled kernel
        (:mod:`microfacet.kernels`); :meth:`_projected_numpy` is the reference.
        """
        return self._projected_unit(directions(wi, "wi"), directions(wo, "wo"), divide_cos_i)

    def _projected_unit(self, wi, wo, divide_cos_i: bool = False):
        """:meth:`_projected` of directions already checked (:func:`microfacet.protocol.directions`)."""
        if self.gaf_model == "smith" and backend.choose() == backend.NUMBA:
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
        def compiled(wi, wo):
            return kernels.smith_eval(self, wi, wo, divide_cos_i, self.dtype, self._out(out, wi, wo, (3,)), True)
        d, fast = _fused(compiled if backend.smith(self) else _reference, self.dtype == np.float32, wi=wi, wo=wo)
        if fast is not None:
            return fast
        wi, wo = d["wi"].astype(np.float64, copy=False), d["wo"].astype(np.float64, copy=False)
        projected = self._projected_numpy if backend.smith(self) else self._projected_unit
        oh, s = projected(wi, wo, divide_cos_i)
        return into(out, (self.fresnel(oh) * s[..., None]).astype(self.dtype, copy=False), d.values())

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_r cos theta_i = F D G / (4 cos theta_o)`` (Listing 2.2).

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
        return self._eval(wi, wo, False, out)

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``f_r = F D G / (4 cos theta_i cos theta_o)`` (Eq. 2.1). ``out`` (see the module): of
        the BRDF's ``dtype``; the kernels write into it as they go, so its contents are
        unspecified after a ``ValueError`` on the inputs.

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
        return self._eval(wi, wo, True, out)

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of ``sample``: the density of the sampled normal over ``4 oh`` (one compiled
        pass for Smith BRDFs with scalar parameters, :func:`microfacet.kernels.smith_pdf`).

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
        def compiled(wi, wo):
            return kernels.smith_pdf(self, wi, wo, self.dtype, self._out(out, wi, wo, ()), True)
        d, fast = _fused(compiled if backend.smith(self) else _reference, self.dtype == np.float32, wi=wi, wo=wo)
        if fast is not None:
            return fast
        return into(out, self._pdf_numpy(d["wi"].astype(np.float64, copy=False),
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
        :mod:`microfacet.fresnel` term run one compiled pass (:func:`microfacet.kernels.smith_sample`).

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
        def compiled(wo, u):
            return kernels.smith_sample(self, u, wo, self.dtype, self._out(out, u, wo, None), True)
        d, fast = _fused(compiled if backend.smith(self) else _reference, self.dtype == np.float32, wo=wo, u=u)
        if fast is not None:
            return fast
        result = self._sample_numpy(d["u"].astype(np.float64, copy=False), d["wo"].astype(np.float64, copy=False))
        return into_sample(out, tuple(a.astype(self.dtype, copy=False) for a in result), d.values())

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
