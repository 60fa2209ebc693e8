"""Patch BRDF of a normal-mapped microsurface (Chermain, Claux, Mérillou 2019, Sec. 4-5).

A footprint ``P`` (a normalized 2-D Gaussian ``k_P`` over texture space) sees the
mixture of noncentered anisotropic Beckmann lobes ``D_P(h) = sum_i W_i D_i(h)`` (Eq. 9).
Its BRDF (Eq. 7) is

    f_P(o, i) = F(o.h) G2(P, h, o, i) D_P(h) / (4 A_P(o) A_P(i)),

with the patch projected area ``A_P(k) = sum_i W_i <n_i, k>+ / n_i.z`` (Eq. 17, ``n_i``
the mean normal of lobe ``i``: ``<n_i, k> / n_i.z = c_i(k) = z - x E_i[x~] - y E_i[y~]``)
and the patch Smith function (Eq. 11-15)

    1 + Lambda_P(k) = V_P(k) / A_P(k),   V_P(k) = int <k,h>+ D_P(h) dw_h
                                               = sum_i W_i c_i(k) (1 + Lambda_i(k)).

``Lambda_i`` is the analytic Smith Lambda of the sheared anisotropic Beckmann lobe
(thesis Eq. 3.3, LEADR). We evaluate each lobe's projected area ``c_i (1 + Lambda_i)``
as the mean of the positive part of the Gaussian variable ``s = z - x x~ - y y~``,
``E[s+] = c Phi(c / sigma) + sigma phi(c / sigma)``, which equals ``c (1 + Lambda_i)``
wherever ``c > 0`` and extends it to lobes whose mean normal faces away from ``k``
(where Eq. 13 would drop their visible tail). So ``V_P`` is exactly ``int <k,h>+ D_P``
and the normalization of Eq. 11 holds exactly.

Conventions (the BRDF protocol of :mod:`microfacet.brdf`): ``wi`` light, ``wo`` view,
local frame with z the macro normal. The renderer multiplies ``eval_cos`` by the light's
radiance (or irradiance); as for :class:`~microfacet.MicrofacetBRDF` on a sheared lobe
(the LEADR point-light normalization), the projected area of the lit surface is
``A_P(i)``, not ``cos theta_i``:

    eval_cos(wi, wo) = f_P(o, i) A_P(i) = F G2 D_P / (4 A_P(o)),   eval = eval_cos / z_i.

With this, ``int eval_cos dw_i <= 1`` (white furnace), ``f_P`` (:meth:`PatchBRDF.f_p`)
is symmetric, and a single-lobe patch equals ``MicrofacetBRDF`` of that Beckmann lobe.

``G2``: ``"correlated"`` (default, the height-correlated form the library uses
everywhere, ``G2 = 1 / (1 + Lambda_P(o) + Lambda_P(i))``) or ``"separable"``
(Eq. 16 as printed, ``G1(o) G1(i)``). Both are energy conserving
(``G2 <= G1(o)``); the local factors ``chi+(o.h) chi+(i.h)`` of Eq. 10 apply to both.

``exact=False`` is the approximation of Sec. 4.2.2: one merged Beckmann lobe ``m``, the
``W``-weighted average of the five linear slope moments of the MIP level that matches
the footprint (``ms.mip_moments``; :meth:`PatchBRDF.from_lobes` averages the given lobes),
whose Smith ``Lambda_m`` replaces ``Lambda_P``. ``D_P`` stays exact, and so does its
visible projected area ``V_P(k) = int <k,h>+ D_P`` (Eq. 13-15); the patch projected area
is then ``A_P(k) = V_P(k) / (1 + Lambda_m(k)) = V_P c_m+ / V_m`` (Eq. 15 solved for
``A_P``), so that Eq. 11 normalizes ``D_P`` exactly and the approximation conserves
energy like the exact model. Taking ``A_m = c_m+`` itself (the merged lobe's mean-normal
area, as printed) gains energy wherever ``V_m < V_P``: ``int eval_cos = V_P(o) / V_m(o)``
at most, up to 1.0024 at 60 degrees (MIP level 1 of a smooth map: the MIP lobe's mean
normal is not the footprint's) and 1.048 at 89 degrees (a rough map: a mixture of lobes
has heavier tails toward grazing ``k`` than the Gaussian of the same mean and variance),
see ``tests/test_glints_pbrdf.py::test_white_furnace_approximation_conserves_energy``.

Sampling (Sec. 5): a position of the footprint picks lobe ``i`` with probability
``W_i / sum W``; a normal is drawn from its slope distribution ``P_i`` and ``wo`` is
reflected about it. The pdf is ``D_P(h) z_h / (4 o.h)``.
"""
from __future__ import annotations

from functools import cached_property
from typing import NamedTuple

import numpy as np
from scipy.special import erfc

from .. import backend as _backend
from .. import fresnel as _fresnel
from ..brdf import BRDF
from ..protocol import directions, into, into_sample, uniforms
from ..distributions import Beckmann
from ..geometry import dot, half_vector, reflect
from .microsurface import BLOCK, FWHM_PER_SIGMA, LobeMixture

__all__ = ["Microsurface", "PatchBRDF", "lobe_projected_area", "merge_moments", "footprint_lobes",
           "eval_cos_footprints", "G2_MODELS", "Window", "LobeGrid", "Footprints"]

G2_MODELS = ("correlated", "separable")

_SQRT2 = np.sqrt(2.0)
_INV_SQRT_2PI = 1.0 / np.sqrt(2.0 * np.pi)
#: Default slope-box width, in standard deviations, of the image kernel's pruning
#: (:func:`eval_cos_footprints`): ``exp(-8^2 / 2) = 1.3e-14``.
PRUNE_SIGMA = 8.0
#: lobes x directions evaluated per vectorized block (bounds memory to ~100 MB)
_BLOCK = 1 << 21


def _moments(m) -> np.ndarray:
    m = np.asarray(m, dtype=np.float64)
    if m.ndim != 2 or m.shape[1] != 5:
        raise ValueError(f"lobe moments must have shape (N, 5), got {m.shape}")
    if not np.all(np.isfinite(m)):
        raise ValueError("lobe moments must be finite")
    return m


def _covariance(m: np.ndarray):
    """Slope means and covariance entries ``(mx, my, sxx, syy, sxy)`` of moments (Eq. 5)."""
    mx, my = m[..., 0], m[..., 1]
    return mx, my, m[..., 2] - mx * mx, m[..., 3] - my * my, m[..., 4] - mx * my


def lobe_projected_area(moments, k) -> tuple[np.ndarray, np.ndarray]:
    """Projected areas of Beckmann lobes toward ``k``: ``(c_k, A(k))``.

    ``A(k) = int <k,h>+ D(h) dw_h = E[s+]`` for ``s = z_k - x_k x~ - y_k y~`` with Gaussian
    slopes ``(x~, y~)`` of the lobe's moments: ``s ~ N(c_k, sigma^2)``,
    ``A = c Phi(c/sigma) + sigma phi(c/sigma)`` (``= c_k (1 + Lambda(k))`` of Eq. 3.3
    where ``c_k > 0``, Chermain et al. Eq. 13). ``moments`` ``(..., 5)`` broadcast against
    ``k`` ``(..., 3)``; ``c_k = <n_mean, k> / n_mean.z`` is returned unclamped.

    Parameters
    ----------
    moments : (..., 5) array_like
        Raw slope moments ``E1..E5`` of Beckmann lobes.
    k : (..., 3) array_like
        Unit directions.

    Returns
    -------
    c : ndarray
        ``<n_mean, k> / n_mean.z``.
    area : ndarray
        The projected area ``int <k, h>+ D(h) dw_h``.

    Examples
    --------
    A centred lobe seen from the normal projects to 1; from 74 degrees, to ``cos theta (1 +
    Lambda)``, a little more than ``cos theta``:

    >>> E = np.array([0.0, 0.0, 0.02, 0.02, 0.0])             # Beckmann alpha = 0.2
    >>> c, area = lobe_projected_area(E, [[0.0, 0.0, 1.0], [0.96, 0.0, 0.28]])
    >>> c.tolist(), area.round(4).tolist()
    ([1.0, 0.28], [1.0, 0.281])
    """
    m = np.asarray(moments, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    mx, my, sxx, syy, sxy = _covariance(m)
    x, y, z = k[..., 0], k[..., 1], k[..., 2]
    c = z - x * mx - y * my
    var = np.maximum(x * x * sxx + 2.0 * x * y * sxy + y * y * syy, 0.0)
    sigma = np.sqrt(var)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = np.where(sigma > 0, c / sigma, np.where(c > 0, np.inf, -np.inf))
        gauss = np.where(np.isfinite(t), np.exp(-0.5 * np.where(np.isfinite(t), t, 0.0) ** 2), 0.0)
        area = c * 0.5 * erfc(-t / _SQRT2) + sigma * _INV_SQRT_2PI * gauss
    return c, np.where(sigma > 0, area, np.maximum(c, 0.0))


def merge_moments(moments, weights) -> np.ndarray:
    """``W``-weighted average of linear slope moments (LEADR): the single Beckmann lobe
    with the mixture's mean and covariance (Sec. 4.2.2, what MIP levels store).

    Parameters
    ----------
    moments : (N, 5) array_like
        Raw moments of the lobes.
    weights : (N,) array_like
        Their weights ``W_i`` (any positive scale).

    Returns
    -------
    (5,) ndarray
        The merged raw moments.

    Examples
    --------
    Two narrow lobes of mean slopes +-0.1 merge into one centred lobe of variance 0.01 more:

    >>> merge_moments([[0.1, 0.0, 0.02, 0.01, 0.0], [-0.1, 0.0, 0.02, 0.01, 0.0]], [1.0, 1.0]).round(6).tolist()
    [0.0, 0.0, 0.02, 0.01, 0.0]
    """
    m = _moments(moments)
    w = np.asarray(weights, dtype=np.float64)
    return (w[:, None] * m).sum(0) / w.sum()


def _merged_area(v, merged, k) -> tuple[np.ndarray, np.ndarray]:
    """``(A_P, V_P)`` of the approximation (Sec. 4.2.2, module notes): ``Lambda_P`` is the
    merged lobe's Smith ``Lambda_m = V_m / c_m - 1`` and ``A_P = V_P / (1 + Lambda_m) =
    V_P c_m+ / V_m`` (Eq. 15), with ``V_P`` the mixture's visible projected area ``v``
    (Eq. 13) and ``c_m``, ``V_m`` the merged lobe's (:func:`lobe_projected_area`)."""
    c, vm = lobe_projected_area(merged, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = np.where((vm > 0) & (c > 0), v * np.maximum(c, 0.0) / np.where(vm > 0, vm, 1.0), 0.0)
    return a, v


def _g2_over_ao(g2: str, ai, vi, ao, vo) -> np.ndarray:
    """``G2 / A_P(o)`` from the patch areas ``A_P``, ``V_P`` of ``i`` and ``o`` (Eq. 7, 11-16),
    written without dividing by ``A_P`` (finite where it vanishes):
    separable ``G1(o) G1(i) / A_o = A_i / (V_o V_i)``; height-correlated
    ``1 / (A_o (1 + Lambda_o + Lambda_i)) = A_i / (V_o A_i + A_o V_i - A_o A_i)``."""
    with np.errstate(divide="ignore", invalid="ignore"):
        den = vo * vi if g2 == "separable" else vo * ai + ao * (vi - ai)
        return np.where((den > 0) & (ai > 0), ai / np.where(den > 0, den, 1.0), 0.0)


def _local_ok(wi, wo, h, oh, ih):
    """Both directions above the macro horizon and ``chi+(o.h) chi+(i.h)`` (Eq. 10)."""
    return (wi[..., 2] > 0) & (wo[..., 2] > 0) & (oh > 0) & (ih > 0) & (h[..., 2] > 0)


class PatchBRDF(BRDF):
    """P-BRDF of a footprint (Chermain et al. 2019, Eq. 7) with the BRDF protocol.

    Parameters
    ----------
    ms : Microsurface
        Mixture of Beckmann lobes (``ms.weights``, ``ms.lobe_moments``).
    center : (2,) array
        Footprint centre in texture space (the units of ``ms.lobe_uv``).
    cov : (2, 2) array
        Footprint covariance (``k_P`` is the normalized Gaussian of that covariance).
    fresnel : Fresnel, optional
        Microfacet Fresnel term (default: ideal mirrors).
    exact : bool
        Exact patch masking and projected area (Eq. 10-17) or the merged-lobe
        approximation of Sec. 4.2.2 (module notes).
    g2 : {"correlated", "separable"}
        Masking-shadowing form (see the module notes).
    backend : {"auto", "numpy", "numba"}
        ``eval``/``eval_cos``/``pdf``/``sample``: the NumPy sums over lobes (the reference)
        or one compiled pass over the lobes per direction pair (:func:`_lobe_sums`, the
        same sums; ``"auto"``: compiled when available).

    Attributes
    ----------
    indices, weights : (N,) arrays
        Lobes of the footprint and their ``W_i`` (Eq. 9, ``ms.weights``), normalized to
        sum to 1 (Sec. 4.1); ``weight_sum`` is the sum given. ``eval`` does not depend on
        it (Eq. 7 is homogeneous of degree 0 in ``W``).
    moments : (N, 5)
        Their slope moments; ``merged`` ``(5,)`` the approximation's single lobe.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((4, 4, 2)))
    >>> f = PatchBRDF(ms, center=[0.5, 0.5], cov=np.eye(2) * 1e-3, backend="numpy")
    >>> len(f.indices), round(float(f.weights.sum()), 6)
    (4, 1.0)
    >>> wi, wo = np.array([0.3, 0.0, 0.954]), np.array([-0.3, 0.0, 0.954])
    >>> f.eval_cos(wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)).shape
    (3,)
    """

    def __init__(self, ms, center, cov, fresnel: _fresnel.Fresnel | None = None,
                 exact: bool = True, g2: str = "correlated", backend: str = "auto"):
        indices, weights = ms.weights(np.asarray(center, float), np.asarray(cov, float))
        indices = np.asarray(indices)
        moments = np.asarray(ms.lobe_moments, dtype=np.float64)[indices]
        # Sec. 4.2.2: the filtered lobe of the MIP level matching the footprint
        merged = None if exact else ms.mip_moments(center, cov)
        self._setup(moments, weights, fresnel, exact, g2, merged, backend)
        self.microsurface, self.indices = ms, indices
        self.center, self.cov = np.asarray(center, float), np.asarray(cov, float)

    @classmethod
    def from_lobes(cls, moments, weights, fresnel: _fresnel.Fresnel | None = None,
                   exact: bool = True, g2: str = "correlated", merged=None,
                   backend: str = "auto") -> "PatchBRDF":
        """P-BRDF of explicit lobes: slope moments ``(N, 5)`` and weights ``W`` ``(N,)``.

        Parameters
        ----------
        moments : array-like, shape (N, 5)
            Raw slope moments of the lobes.
        weights : array-like, shape (N,)
            Their weights ``W_i`` (normalized here).
        fresnel : Fresnel, optional
            Microfacet Fresnel term (default: ideal mirrors).
        exact : bool, optional
            Exact patch masking (default) or the merged-lobe approximation.
        g2 : {"correlated", "separable"}, optional
            Masking-shadowing form.
        merged : array-like, shape (5,), optional
            The approximation's single lobe (default: the weighted merge of the lobes).
        backend : {"auto", "numpy", "numba"}, optional
            Evaluation backend.

        Returns
        -------
        PatchBRDF
            The P-BRDF, without a microsurface.
        """
        self = cls.__new__(cls)
        self._setup(moments, weights, fresnel, exact, g2, merged, backend)
        self.microsurface, self.indices = None, np.arange(len(self.weights))
        self.center = self.cov = None
        return self

    def _setup(self, moments, weights, fresnel, exact, g2, merged, backend) -> None:
        if g2 not in G2_MODELS:
            raise ValueError(f"g2 must be one of {G2_MODELS}, got {g2!r}")
        self._compiled = _backend.choose(backend, _lobe_sums is not None) == _backend.NUMBA
        m = _moments(moments)
        w = np.asarray(weights, dtype=np.float64).reshape(-1)
        if w.shape != (m.shape[0],) or np.any(~np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"weights must be {m.shape[0]} finite values >= 0")
        keep = w > 0
        self.weight_sum = float(w[keep].sum())
        self.moments = np.ascontiguousarray(m[keep])
        self.weights = w[keep] / self.weight_sum if self.weight_sum > 0 else w[keep]
        self.fresnel = _fresnel.Ideal() if fresnel is None else fresnel
        self.exact, self.g2 = bool(exact), g2
        if self.weight_sum > 0:
            self._cdf = np.cumsum(self.weights)
            self.merged = (merge_moments(self.moments, self.weights) if merged is None
                           else np.asarray(merged, dtype=np.float64).reshape(5))
        else:
            self._cdf, self.merged = np.zeros(0), None

    @cached_property
    def lobes(self) -> Beckmann | None:
        """The lobes as one :class:`~microfacet.Beckmann` with array parameters (built on
        first use: the compiled sums read the moments); ``None`` without lobes."""
        return Beckmann.from_moments(*self.moments.T) if self.weight_sum > 0 else None

    def __repr__(self) -> str:
        return (f"PatchBRDF({len(self.weights)} lobes, sum W = {self.weight_sum:.6g}, "
                f"exact={self.exact}, g2={self.g2!r}, fresnel={self.fresnel!r})")

    # ---------------------------------------------------------------- mixture sums
    def _lobe_sum(self, fn, *dirs) -> tuple[np.ndarray, ...]:
        """``sum_i W_i fn(lobe_i, *dirs)`` for each output of ``fn``, in memory-bounded blocks."""
        shape = np.broadcast_shapes(*(d.shape for d in dirs))[:-1]
        flat = [np.broadcast_to(d, shape + (3,)).reshape(-1, 3) for d in dirs]
        n, nl = flat[0].shape[0], len(self.weights)
        step = max(1, _BLOCK // max(nl, 1))
        out = None
        for s in range(0, n, step):
            parts = fn(*(f[s:s + step, None, :] for f in flat))
            parts = parts if isinstance(parts, tuple) else (parts,)
            if out is None:
                out = [np.empty(n) for _ in parts]
            for o, p in zip(out, parts):
                o[s:s + step] = p @ self.weights
        if out is None:
            out = [np.empty(0)]
        return tuple(o.reshape(shape) for o in out)

    def pndf(self, h) -> np.ndarray:
        """P-NDF ``D_P(h) = sum_i W_i D_i(h)`` (Eq. 9), weights normalized to ``sum W = 1``.

        Parameters
        ----------
        h : array-like, shape (..., 3)
            Unit normals in the local frame.

        Returns
        -------
        numpy.ndarray, shape (...)
            ``D_P(h)`` in 1/sr.
        """
        h = directions(h, "h")
        if self.weight_sum <= 0:
            return np.zeros(h.shape[:-1])
        if self._compiled:         # the compiled sums (their area columns unused)
            flat = np.ascontiguousarray(h.reshape(-1, 3))
            return _lobe_sums((self.moments.reshape(-1), self.weights), (flat, flat, flat))[:, 0].reshape(h.shape[:-1])
        return self._lobe_sum(self.lobes.ndf, h)[0]

    def areas(self, k) -> tuple[np.ndarray, np.ndarray]:
        """``(A_P(k), V_P(k))``: patch projected area (Eq. 17) and the visible projected
        area of the microfacets ``int <k,h>+ D_P = A_P (1 + Lambda_P)`` (Eq. 13-15);
        with ``exact=False`` ``A_P = V_P / (1 + Lambda_m)`` of the merged lobe (Sec.
        4.2.2, :func:`_merged_area`).

        Parameters
        ----------
        k : array-like, shape (..., 3)
            Unit directions in the local frame.

        Returns
        -------
        A_P, V_P : numpy.ndarray, shape (...)
            Patch projected area and visible projected area of the microfacets.
        """
        k = directions(k, "k")
        if self.lobes is None:
            z = np.zeros(k.shape[:-1])
            return z, z

        if self._compiled:         # the compiled sums (toward k; their P-NDF column unused)
            flat = np.ascontiguousarray(k.reshape(-1, 3))
            sums = _lobe_sums((self.moments.reshape(-1), self.weights), (flat, flat, flat))
            a, v = sums[:, 1].reshape(k.shape[:-1]), sums[:, 2].reshape(k.shape[:-1])
        else:
            def fn(kk):
                c, area = lobe_projected_area(self.moments, kk)
                return np.maximum(c, 0.0), area
            a, v = self._lobe_sum(fn, k)
        return (a, v) if self.exact else _merged_area(v, self.merged, k)

    def lambda_p(self, k) -> np.ndarray:
        """Patch Smith ``Lambda_P(k) = V_P / A_P - 1`` (Eq. 15); ``inf`` where ``A_P = 0``.

        Parameters
        ----------
        k : array-like, shape (..., 3)
            Unit directions in the local frame.

        Returns
        -------
        numpy.ndarray, shape (...)
            ``Lambda_P(k)``.
        """
        a, v = self.areas(k)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(a > 0, v / np.where(a > 0, a, 1.0) - 1.0, np.inf)

    def g1(self, k) -> np.ndarray:
        """Distant patch masking ``G1_dist(P, k) = A_P / V_P = 1 / (1 + Lambda_P)`` (Eq. 11, 14).

        Parameters
        ----------
        k : array-like, shape (..., 3)
            Unit directions in the local frame.

        Returns
        -------
        numpy.ndarray, shape (...)
            ``G1_dist`` in ``[0, 1]`` (0 where ``V_P = 0``).
        """
        a, v = self.areas(k)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(v > 0, a / np.where(v > 0, v, 1.0), 0.0)

    def _g2_over_ao(self, ai, vi, ao, vo) -> np.ndarray:
        return _g2_over_ao(self.g2, ai, vi, ao, vo)

    # -------------------------------------------------------------------- protocol
    def _sums(self, h, wi, wo):
        """``(D_P(h), A_P(i), V_P(i), A_P(o), V_P(o))`` (Eq. 9, 13-17), compiled or NumPy."""
        if not self._compiled or self.lobes is None:
            return (self.pndf(h),) + self.areas(wi) + self.areas(wo)
        shape = np.broadcast_shapes(h.shape, wi.shape, wo.shape)
        flat = [np.ascontiguousarray(np.broadcast_to(d, shape).reshape(-1, 3)) for d in (h, wi, wo)]
        for f in flat:      # read-only, copied or not: one compiled version of the loop, not one per flag
            f.flags.writeable = False
        out = [v.reshape(shape[:-1]) for v in _lobe_sums((self.moments.reshape(-1), self.weights), tuple(flat)).T]
        if not self.exact:
            out[1:3] = _merged_area(out[2], self.merged, wi)
            out[3:5] = _merged_area(out[4], self.merged, wo)
        return tuple(out)

    def _projected(self, wi, wo):
        """``(o.h, D_P G2 / (4 A_P(o)), valid)``."""
        wi, wo = directions(wi, "wi"), directions(wo, "wo")
        h = half_vector(wi, wo)
        oh, ih = dot(wo, h), dot(wi, h)
        ok = _local_ok(wi, wo, h, oh, ih)
        d, ai, vi, ao, vo = self._sums(h, wi, wo)
        s = np.where(ok, d * self._g2_over_ao(ai, vi, ao, vo) / 4.0, 0.0)
        return oh, s

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``f_P(o, i) A_P(i) = F G2 D_P / (4 A_P(o))`` (Eq. 7), RGB ``(..., 3)``.

        Parameters
        ----------
        wi, wo : array-like, shape (..., 3)
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Array ``(..., 3)`` to write into.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            ``f_P A_P(i)`` (``out`` when given).
        """
        oh, s = self._projected(wi, wo)
        return into(out, self.fresnel(oh) * s[..., None], (wi, wo))

    def f_p(self, wi, wo) -> np.ndarray:
        """The symmetric P-BRDF of Eq. 7, ``F G2 D_P / (4 A_P(o) A_P(i))``, RGB.

        Parameters
        ----------
        wi, wo : array-like, shape (..., 3)
            Unit light and view directions in the local frame.

        Returns
        -------
        numpy.ndarray, shape (..., 3)
            The symmetric P-BRDF.
        """
        oh, s = self._projected(wi, wo)
        ai, ao = self.areas(directions(wi, "wi"))[0], self.areas(directions(wo, "wo"))[0]
        with np.errstate(divide="ignore", invalid="ignore"):      # Eq. 7 needs A_P > 0 on both sides
            s = np.where((ai > 0) & (ao > 0), s / np.where(ai > 0, ai, 1.0), 0.0)
        return self.fresnel(oh) * s[..., None]

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Density of :meth:`sample`: ``D_P(h) z_h / (4 o.h)`` (Sec. 5).

        Parameters
        ----------
        wi, wo : array-like, shape (..., 3)
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Array ``(...)`` to write into.

        Returns
        -------
        numpy.ndarray, shape (...)
            Density per solid angle of ``wi`` (``out`` when given).
        """
        wi, wo = directions(wi, "wi"), directions(wo, "wo")
        h = half_vector(wi, wo)
        oh = dot(wo, h)
        ok = (wi[..., 2] > 0) & (wo[..., 2] > 0) & (oh > 0) & (self.weight_sum > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            p = self.pndf(h) * h[..., 2] / (4.0 * np.where(ok, oh, 1.0))
        return into(out, np.where(ok, p, 0.0), (wi, wo))

    def sample(self, u, wo, out=None):
        """Footprint position, then normal (Sec. 5): lobe ``i`` with probability
        ``W_i / sum W`` from ``u[..., 0]`` (rescaled and reused), a normal of slope density
        ``P_i`` (``mf.Beckmann.sample_p22``), ``wi`` the reflection of ``wo``.
        Returns ``(wi, weight, pdf)`` with ``weight = eval_cos / pdf`` (0 where pdf is 0).

        Parameters
        ----------
        u : array-like, shape (..., 2)
            Uniform random numbers in ``[0, 1)``.
        wo : array-like, shape (..., 3)
            Unit view directions in the local frame.
        out : tuple of 3 ndarray, optional
            ``(wi, weight, pdf)`` arrays to write into.

        Returns
        -------
        wi : numpy.ndarray, shape (..., 3)
            Sampled light directions.
        weight : numpy.ndarray, shape (..., 3)
            ``eval_cos / pdf`` (0 where ``pdf`` is 0).
        pdf : numpy.ndarray, shape (...)
            Density per solid angle of ``wi``.
        """
        wo = directions(wo, "wo")
        u = uniforms(u)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        u = np.broadcast_to(u, shape + (2,)).reshape(-1, 2)
        wof = np.broadcast_to(wo, shape + (3,)).reshape(-1, 3)
        if self.lobes is None:
            z = np.zeros(shape)
            return into_sample(out, (np.broadcast_to(wo, shape + (3,)) * [-1, -1, 1], np.zeros(shape + (3,)), z),
                                (u, wo))
        j = np.minimum(np.searchsorted(self._cdf, u[:, 0], side="right"), len(self._cdf) - 1)
        lo = np.where(j > 0, self._cdf[np.maximum(j - 1, 0)], 0.0)
        u0 = np.clip((u[:, 0] - lo) / np.maximum(self._cdf[j] - lo, 1e-300), 0.0, 1.0 - 1e-16)
        lobe = Beckmann.from_moments(*self.moments[j].T)
        h = lobe.sample_p22(np.stack([u0, u[:, 1]], -1))
        wi = reflect(wof, h)
        pdf = self.pdf(wi, wof)
        f = self.eval_cos(wi, wof)
        with np.errstate(divide="ignore", invalid="ignore"):
            weight = np.where((pdf > 0)[:, None], f / np.where(pdf > 0, pdf, 1.0)[:, None], 0.0)
        return into_sample(out, (wi.reshape(shape + (3,)), weight.reshape(shape + (3,)), pdf.reshape(shape)), (u, wo))

    # ---------------------------------------------------------------- diagnostics
    def albedo(self, wo, order: int = 24) -> float:
        """White furnace ``int eval_cos(wi, wo) dw_i`` (first channel).

        With ``dw_i = 4 (o.h) dw_h``, ``dw_h = z_h^3 ds`` and ``D_i = P_i / z_h^4`` (slopes
        ``s``) the integral is ``sum_i W_i E_{P_i}[F G2 (o.h) / (A_P(o) z_h)]`` (0 where
        ``wi`` falls below the horizon), computed by ``order x order`` Gauss-Hermite
        quadrature of each lobe's Gaussian slopes. Independent of :meth:`sample`;
        ``<= 1`` for both models (``G2 <= G1(o)`` and Eq. 11). Cost ``~ N^2 order^2``.

        Parameters
        ----------
        wo : array-like, shape (3,)
            Unit view direction in the local frame.
        order : int, optional
            Gauss-Hermite points per slope axis (default 24).

        Returns
        -------
        float
            The directional albedo (0 when the footprint has no lobe).
        """
        wo = np.asarray(wo, dtype=np.float64).reshape(3)
        if self.lobes is None:
            return 0.0
        t, w = np.polynomial.hermite.hermgauss(order)
        tx, ty = np.meshgrid(t, t, indexing="ij")
        wq = (w[:, None] * w[None, :]).ravel() / np.pi
        mx, my, sxx, syy, sxy = _covariance(self.moments)
        lxx = np.sqrt(sxx)                                        # Cholesky of each covariance
        lyx = sxy / lxx
        lyy = np.sqrt(np.maximum(syy - lyx * lyx, 0.0))
        gx, gy = _SQRT2 * tx.ravel(), _SQRT2 * ty.ravel()
        sx = mx[:, None] + lxx[:, None] * gx
        sy = my[:, None] + lyx[:, None] * gx + lyy[:, None] * gy  # (N, Q) slopes
        inv = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
        h = np.stack([-sx * inv, -sy * inv, inv], -1)
        wi = reflect(np.broadcast_to(wo, h.shape), h)
        oh = dot(wo, h)
        ok = (wi[..., 2] > 0) & (oh > 0)
        ai, vi = self.areas(wi)
        ao, vo = self.areas(wo)
        g = self._g2_over_ao(ai, vi, ao, vo)
        q = np.where(ok, self.fresnel(oh)[..., 0] * g * oh / h[..., 2], 0.0)
        return float(self.weights @ (q @ wq))


# ------------------------------------------------------------------ the microsurface
class Microsurface(LobeMixture):
    """A normal map's lobe mixture (:class:`~microfacet.glints.microsurface.LobeMixture`:
    Sec. 3-5, P-NDF, files) with its patch BRDF (Eq. 7): the public class. It lives here
    so that imports flow one way (``microsurface`` <- ``pbrdf`` <- ``figures``).

    Build it with :meth:`from_normal_map` or :meth:`from_slopes` (parameters of
    :class:`~microfacet.glints.microsurface.LobeMixture`).

    Parameters
    ----------
    moments : array-like, shape (ny, nx, 5)
        Raw lobe moments.
    slopes : array-like, shape (H, W, 2)
        The texel slopes they came from.
    h : float, optional
        Seed spacing in texels (default 1; :data:`SPACING_RANGE`).
    sigma_eps : float, optional
        Floor of the lobes' principal slope deviations (default 0.01).
    cutoff, slope_cutoff : float, optional
        Truncations of the footprint weights and of the hierarchy's slope boxes, in
        standard deviations (defaults 3 and 4).
    copy : bool, optional
        Floor a copy of ``moments`` (default ``True``; ``False``: in place).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((4, 4, 2)))
    >>> ms
    Microsurface(4 x 4 lobes from a 4 x 4 map, h=1, sigma_eps=0.01)
    >>> wi = wo = np.array([0.0, 0.0, 1.0])
    >>> float(ms.pbrdf([0.5, 0.5], np.eye(2) * 1e-3, backend="numpy").eval_cos(wi, wo)[0]) > 0
    True
    """

    def pbrdf(self, center, cov, fresnel=None, exact: bool = True, **kwargs) -> PatchBRDF:
        """The patch BRDF (Eq. 7) of a footprint; see :class:`PatchBRDF`.

        Parameters
        ----------
        center : array-like, shape (2,)
            Footprint centre in uv.
        cov : array-like, shape (2, 2)
            Footprint covariance in uv^2.
        fresnel : Fresnel, optional
            Microfacet Fresnel term (default: ideal mirrors).
        exact : bool, optional
            Exact patch masking (default) or the merged-lobe approximation.
        **kwargs
            ``g2`` and ``backend`` of :class:`PatchBRDF`.

        Returns
        -------
        PatchBRDF
            The footprint's P-BRDF.
        """
        return PatchBRDF(self, center, cov, fresnel, exact, **kwargs)


# ------------------------------------------------------------------ many footprints at once
def footprint_lobes(grid_shape, centers, covs, cutoff: float = 3.0):
    """Lobes and weights ``W_i`` (Eq. 9, normalized) of many Gaussian footprints at once.

    The seeds are the ``ny x nx`` grid of :class:`~microfacet.glints.Microsurface` (cell
    centres of the wrapped unit uv square, kernels of FWHM one cell), and the lobe set is
    its ``ms.weights``': the rectangle within ``cutoff`` standard deviations of
    ``Sigma_P + sigma_k^2 I`` per axis. ``centers`` ``(P, 2)``, ``covs`` ``(P, 2, 2)`` or
    ``(2, 2)``. Returns flat lobe indices ``(P, K)`` and weights ``(P, K)`` (0 outside each
    footprint's rectangle; ``K`` the largest rectangle of the batch).

    Parameters
    ----------
    grid_shape : (int, int)
        ``(ny, nx)`` of the lobe grid (``ms.grid``).
    centers : (P, 2) array_like
        Footprint centres in uv.
    covs : (P, 2, 2) or (2, 2) array_like
        Footprint covariances in uv^2.
    cutoff : float
        Half-width of the window, in standard deviations.

    Returns
    -------
    indices : (P, K) int ndarray
        Flat lobe indices (``iy * nx + ix``, wrapped).
    weights : (P, K) ndarray
        ``W_i``, summing to 1 per footprint.

    Examples
    --------
    >>> idx, W = footprint_lobes((4, 4), [[0.5, 0.5], [0.0, 0.0]], np.eye(2) * 1e-3)
    >>> idx.shape, W.sum(-1).round(6).tolist()
    ((2, 4), [1.0, 1.0])
    >>> idx[0].tolist()                       # the 2 x 2 lobes around the centre
    [5, 6, 9, 10]
    """
    ny, nx = grid_shape
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    cov = np.broadcast_to(np.asarray(covs, dtype=np.float64), (c.shape[0], 2, 2))
    ks2 = (np.array([1.0 / nx, 1.0 / ny]) / FWHM_PER_SIGMA) ** 2
    sxx, syy, sxy = cov[:, 0, 0] + ks2[0], cov[:, 1, 1] + ks2[1], cov[:, 0, 1]
    det = sxx * syy - sxy * sxy
    r = cutoff * np.sqrt(np.stack([sxx, syy], -1))                          # (P, 2)
    n = np.array([nx, ny])
    i0 = np.ceil((c - r) * n - 0.5).astype(np.int64)
    i1 = np.floor((c + r) * n - 0.5).astype(np.int64)
    kx, ky = (int(v) for v in np.maximum((i1 - i0).max(0) + 1, 1))
    ix = i0[:, 0, None] + np.arange(kx)                                      # (P, kx)
    iy = i0[:, 1, None] + np.arange(ky)                                      # (P, ky)
    du = ((ix + 0.5) / nx - c[:, 0, None])[:, None, :]
    dv = ((iy + 0.5) / ny - c[:, 1, None])[:, :, None]
    q = (syy[:, None, None] * du * du + sxx[:, None, None] * dv * dv
         - 2.0 * sxy[:, None, None] * du * dv) / det[:, None, None]
    inside = (ix <= i1[:, 0, None])[:, None, :] & (iy <= i1[:, 1, None])[:, :, None]
    W = np.where(inside, np.exp(-0.5 * q), 0.0).reshape(c.shape[0], -1)
    total = W.sum(-1, keepdims=True)
    W = np.where(total > 0, W / np.where(total > 0, total, 1.0), 0.0)
    idx = ((iy % ny)[:, :, None] * nx + (ix % nx)[:, None, :]).reshape(c.shape[0], -1)
    return idx, W


def eval_cos_footprints(ms, centers, covs, wi, wo, *, fresnel: _fresnel.Fresnel | None = None,
                        exact: bool = True, g2: str = "correlated", block: int = 4096,
                        backend: str = "auto", prune: float = PRUNE_SIGMA) -> np.ndarray:
    """``eval_cos`` of the P-BRDF of footprint ``p`` at ``(wi[p], wo[p])`` for many
    footprints (a rendered image's pixels): the same math as :class:`PatchBRDF`, batched
    over footprints (lobes gathered by :func:`footprint_lobes`; with ``exact=False`` the
    merged lobe is the ``W``-weighted average over the MIP level of ``ms.mip_level``).
    ``centers`` ``(P, 2)``, ``covs`` ``(P, 2, 2)`` or ``(2, 2)``, ``wi``, ``wo``
    ``(P, 3)`` or ``(3,)``. Returns RGB ``(P, 3)``.

    ``backend``: ``"numpy"`` (the reference: lobes gathered into padded ``(P, K)``
    arrays), ``"numba"`` (a compiled loop over each footprint's window, the same sums;
    tested against the reference) or ``"auto"`` (numba when available).

    ``prune`` (compiled backend): lobes are skipped by blocks whose slope box, ``prune``
    standard deviations wide, misses the half vector's slope and whose projected areas
    are linear in their mean slopes (:func:`_footprint_sums`): each pixel's ``D_P`` then
    drops at most ``exp(-prune^2 / 2) / (2 pi sigma_eps^2 z_h^4)`` (``1.3e-14`` of the
    largest lobe density at the default 8) and the areas are unchanged; ``np.inf``
    visits every lobe. The NumPy backend sums every lobe.

    Parameters
    ----------
    ms : Microsurface
        The lobe mixture.
    centers, covs : array_like
        Footprints (``(P, 2)``; ``(P, 2, 2)`` or ``(2, 2)``).
    wi, wo : array_like
        Light and view directions, ``(P, 3)`` or ``(3,)``.
    fresnel : Fresnel, optional
        Microfacet Fresnel term (default ideal mirrors).
    exact : bool
        Exact patch masking or the MIP approximation (Sec. 4.2.2).
    g2 : str
        One of :data:`G2_MODELS`.
    block : int
        Footprints per NumPy batch.
    backend : str
        ``"auto"``, ``"numpy"`` or ``"numba"``.
    prune : float
        The compiled backend's pruning width (standard deviations).

    Returns
    -------
    (P, 3) ndarray
        ``eval_cos`` per footprint.

    Raises
    ------
    ValueError
        ``prune <= 0`` or ``g2`` not in :data:`G2_MODELS`.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((4, 4, 2)))
    >>> wi, wo = np.array([0.3, 0.0, 0.954]), np.array([-0.3, 0.0, 0.954])
    >>> wi, wo = wi / np.linalg.norm(wi), wo / np.linalg.norm(wo)
    >>> cov = np.eye(2) * 1e-3
    >>> batch = eval_cos_footprints(ms, [[0.5, 0.5]], cov, wi, wo, backend="numpy")
    >>> G2_MODELS, bool(np.allclose(batch[0], ms.pbrdf([0.5, 0.5], cov, backend="numpy").eval_cos(wi, wo)))
    (('correlated', 'separable'), True)
    """
    if not prune > 0:
        raise ValueError(f"prune must be > 0 (standard deviations), got {prune!r}")
    if g2 not in G2_MODELS:
        raise ValueError(f"g2 must be one of {G2_MODELS}, got {g2!r}")
    if _backend.choose(backend, _footprint_sums is not None) == _backend.NUMBA:
        return _eval_cos_footprints_numba(ms, (centers, covs, wi, wo), fresnel, exact, g2, float(prune))
    fresnel = _fresnel.Ideal() if fresnel is None else fresnel
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    P = c.shape[0]
    cov = np.broadcast_to(np.asarray(covs, dtype=np.float64), (P, 2, 2))
    wi = np.broadcast_to(directions(wi, "wi"), (P, 3))
    wo = np.broadcast_to(directions(wo, "wo"), (P, 3))
    out = np.zeros((P, 3))
    E_all = np.asarray(ms.lobe_moments, dtype=np.float64)
    for s in range(0, P, block):
        sl = slice(s, min(P, s + block))
        h = half_vector(wi[sl], wo[sl])
        oh, ih = dot(wo[sl], h), dot(wi[sl], h)
        ok = _local_ok(wi[sl], wo[sl], h, oh, ih)
        idx, W = footprint_lobes(ms.grid, c[sl], cov[sl], ms.cutoff)
        E = E_all[idx]                                                       # (B, K, 5)
        D = np.einsum("bk,bk->b", W, Beckmann.from_moments(*np.moveaxis(E, -1, 0)).ndf(h[:, None, :]))
        merged = None if exact else _merged_footprints(ms, c[sl], cov[sl])

        def areas(k):
            cc, v = lobe_projected_area(E, k[:, None, :])
            v = np.einsum("bk,bk->b", W, v)
            return (np.einsum("bk,bk->b", W, np.maximum(cc, 0.0)), v) if exact else _merged_area(v, merged, k)
        ai, vi = areas(wi[sl])
        ao, vo = areas(wo[sl])
        val = np.where(ok, D * _g2_over_ao(g2, ai, vi, ao, vo) / 4.0, 0.0)
        out[sl] = fresnel(oh) * val[:, None]
    return out


# ------------------------------------------------------------- compiled footprint kernel
class Window(NamedTuple):
    """How a footprint selects and weights the lobes of a grid of ``nx`` x ``ny`` lobes
    (:func:`footprint_lobes`): the reconstruction kernel's variances ``ks2x``, ``ks2y``
    (added to the footprint's covariance; ``(1 / n / FWHM_PER_SIGMA)^2`` per axis) and the
    window's half-width ``cutoff`` in standard deviations. Built once per grid
    (:meth:`of`) and passed whole to the compiled footprint kernels.

    Attributes
    ----------
    nx, ny : int
        Lobes along u and v.
    ks2x, ks2y : float
        Variances of the reconstruction kernel along u and v, in uv^2.
    cutoff : float
        The window's half-width in standard deviations.

    Examples
    --------
    >>> w = Window.of((64, 32), 3.0)
    >>> w.nx, w.ny, w.cutoff, bool(np.isclose(w.ks2x, (1 / 32 / FWHM_PER_SIGMA) ** 2))
    (32, 64, 3.0, True)
    """

    nx: int
    ny: int
    ks2x: float
    ks2y: float
    cutoff: float

    @classmethod
    def of(cls, grid_shape, cutoff) -> "Window":
        """The window of a lobe grid of shape ``(ny, nx)`` and ``cutoff`` deviations.

        Parameters
        ----------
        grid_shape : (int, int)
            ``(ny, nx)`` of the lobe grid.
        cutoff : float
            The window's half-width in standard deviations.

        Returns
        -------
        Window
            The window.
        """
        ny, nx = (int(n) for n in grid_shape[:2])
        ks2 = (np.array([1.0 / nx, 1.0 / ny]) / FWHM_PER_SIGMA) ** 2
        return cls(nx, ny, float(ks2[0]), float(ks2[1]), float(cutoff))


class LobeGrid(NamedTuple):
    """A microsurface's lobes as the compiled image kernel reads them: ``E`` the flat raw
    moments ``(ny * nx * 5,)`` (Eq. 5), ``bounds`` the per-block bounds ``(nby, nbx, 7)`` of
    ``B x B`` blocks (:meth:`~microfacet.glints.microsurface.LobeMixture._block_bounds`, the
    pruning grid) and the footprint :class:`Window` of the grid.

    Attributes
    ----------
    E : numpy.ndarray, shape (ny * nx * 5,)
        Flat raw lobe moments (float64).
    bounds : numpy.ndarray, shape (nby, nbx, 7)
        Per-block bounds of the pruning grid.
    B : int
        Block side in lobes.
    window : Window
        The footprint window of the grid.

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> ms = mf.glints.Microsurface.from_slopes(0.1 * np.random.default_rng(0).standard_normal((4, 4, 2)))
    >>> g = LobeGrid.of(ms)
    >>> g.E.shape, g.window.nx
    ((80,), 4)
    """

    E: np.ndarray
    bounds: np.ndarray
    B: int
    window: Window

    @classmethod
    def of(cls, ms) -> "LobeGrid":
        """The record of a :class:`Microsurface` ``ms`` (level 0, its cutoff).

        Parameters
        ----------
        ms : Microsurface
            The microsurface.

        Returns
        -------
        LobeGrid
            Its level-0 lobes, block bounds and footprint window.
        """
        return cls(np.ascontiguousarray(ms.lobe_moments, dtype=np.float64).reshape(-1), ms._block_bounds, BLOCK,
                   Window.of(ms.grid, ms.cutoff))


class Footprints(NamedTuple):
    """The queries of the compiled image kernel: per footprint ``p``, ``fp[p] = (u, v, cuu, cvv,
    cuv)`` (centre and covariance), the half vector ``h[p]`` and the directions ``wi[p]``,
    ``wo[p]`` (C-contiguous float64 rows); ``exo`` the lobes' tabulated area excess toward a
    shared ``wo`` (:func:`_area_excess`) or empty, ``prune`` the pruning width in standard
    deviations (:func:`eval_cos_footprints`).

    Attributes
    ----------
    fp : numpy.ndarray, shape (P, 5)
        Per footprint ``(u, v, cuu, cvv, cuv)``: centre in uv and covariance in uv^2.
    h : numpy.ndarray, shape (P, 3)
        Unit half vectors.
    wi, wo : numpy.ndarray, shape (P, 3)
        Unit light and view directions.
    exo : numpy.ndarray
        The lobes' tabulated area excess toward a shared ``wo``, or empty.
    prune : float
        Pruning width in standard deviations.

    Examples
    --------
    >>> Footprints._fields
    ('fp', 'h', 'wi', 'wo', 'exo', 'prune')
    """

    fp: np.ndarray
    h: np.ndarray
    wi: np.ndarray
    wo: np.ndarray
    exo: np.ndarray
    prune: float


from .. import kernels as _kernels  # noqa: E402

if _kernels.AVAILABLE:
    import math

    import numba

    from .._numba_kernels import erfc_near as _erfc_near
    from .._numba_kernels import exp_neg as _exp_neg
    from .._numba_kernels import inline as _inline
    from .._numba_kernels import jit_contract as _kernel

    #: The per-footprint loop (:func:`_footprint_loops`): ``contract``, as :data:`_kernel`, and no
    #: reference counts (Numba's ``_nrt=False``; its scratch comes from :func:`_footprint_range`):
    #: the views of each run of lobes cost two atomic reference counts each, 28 % of a glint
    #: image's profile samples.
    _loops = numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)

    #: ``t = c / sigma`` beyond which a lobe's projected area ``E[s+]`` is ``c`` to
    #: rounding: ``0 <= E[s+] - c = sigma (phi(t) - t Q(t)) <= sigma phi(t) / (1 + t^2)``
    #: (Mills ratio), so the relative error is below ``phi(t) / (t (1 + t^2)) < 1e-17``
    #: (less than half an ulp) for ``t >= 8``: the area is ``c`` there (:func:`_linear`; the
    #: branch-free loops compute the erfc and exp of every lobe and select).
    _AREA_T = 8.0
    _AREA_T2 = _AREA_T * _AREA_T
    #: Mahalanobis distance^2 of a half vector's slope beyond which a lobe's slope density
    #: (Eq. 4) is 0 (:func:`_p22`): ``exp(-q / 2) < 1e-304``.
    _Q_MAX = 1400.0
    _INV_2PI = 1.0 / (2.0 * math.pi)
    _INV_SQRT2 = 1.0 / _SQRT2
    _F = np.float64        # arithmetic type of the shared exp / erfc kernels
    # The per-lobe helpers (``_inline``, the Smith kernels' decorator: inlined in Numba's IR,
    # ``error_model="numpy"``) are branch-free (selects, and the Smith kernels' polynomial
    # ``_exp_neg`` / ``_erfc_near`` instead of library calls), so that the loops over a row of
    # lobes vectorize; the kernels that run them (``_kernel``) fuse multiply-adds (``contract``,
    # which the inlined helpers take: 10-12 % faster, images within 4e-14 of the kernel without).

    @_inline
    def _area(c, var):  # pragma: no cover - compiled
        """``(c+, E[s+])`` of ``s ~ N(c, var)`` (Eq. 13, 17; :func:`lobe_projected_area`):
        ``E[s+] = c Phi(t) + sigma phi(t)``, ``t = c / sigma``, with ``2 Phi(t) = erfc(v)``
        for ``t < 0`` and ``2 - erfc(v)`` for ``t >= 0``, ``v = |t| / sqrt 2``, and
        ``erfc(v) = e erfcx(v)``: ``e = exp(-t^2 / 2)`` is shared with ``phi``. ``c`` itself
        where ``c >= _AREA_T sigma`` (tested without sqrt), ``c+`` where ``sigma = 0``."""
        sg = math.sqrt(max(var, 0.0))
        t = c / (sg if sg > 0.0 else 1.0)
        e = _exp_neg(_F, -0.5 * t * t)
        half = 0.5 * _erfc_near(_F, abs(t) * _INV_SQRT2, e)
        area = c * (1.0 - half if t >= 0.0 else half) + sg * _INV_SQRT_2PI * e
        cp = max(c, 0.0)
        linear = (c > 0.0) & (c * c >= _AREA_T2 * var)
        return cp, (c if linear else (area if sg > 0.0 else cp))

    @_inline
    def _p22(xh, yh, lobe, qmax):  # pragma: no cover - compiled
        """Gaussian slope density ``P_i`` (Eq. 4) of one lobe (``lobe = (mx, my, sxx, syy, sxy)``,
        :func:`_lobe`) at slope ``(xh, yh)``; 0 where the Mahalanobis distance^2 ``q`` is at least
        ``qmax`` (or ``det <= 0``)."""
        mx, my, sxx, syy, sxy = lobe
        det = sxx * syy - sxy * sxy
        gx, gy = xh - mx, yh - my
        qdet = syy * gx * gx + sxx * gy * gy - 2.0 * sxy * gx * gy      # q det
        inside = qdet < qmax * det
        # sqrt of an operand known >= 0: LLVM's intrinsic (vectorizes), not the libm call
        return _exp_neg(_F, -0.5 * qdet / det if inside else -np.inf) * _INV_2PI / math.sqrt(max(det if inside else 1.0, 0.0))

    @_inline
    def _lobe(E, k):  # pragma: no cover - compiled
        """``(mx, my, sxx, syy, sxy)``: slope means and covariance (Eq. 5) of lobe ``k`` of the
        flat raw moments ``E`` (``5 k .. 5 k + 4``: constant strides, so that loops vectorize)."""
        mx, my = E[5 * k], E[5 * k + 1]
        return mx, my, E[5 * k + 2] - mx * mx, E[5 * k + 3] - my * my, E[5 * k + 4] - mx * my

    @_inline
    def _toward(kx, ky, kz, lobe):  # pragma: no cover - compiled
        """``(c, var)`` of ``s = z - x x~ - y y~`` toward ``k`` (:func:`_area`) for the lobe
        ``lobe = (mx, my, sxx, syy, sxy)`` (:func:`_lobe`)."""
        mx, my, sxx, syy, sxy = lobe
        return kz - kx * mx - ky * my, kx * kx * sxx + 2.0 * kx * ky * sxy + ky * ky * syy

    @_inline
    def _linear(c, var):  # pragma: no cover - compiled
        """Whether :func:`_area` is ``(c, c)``: ``c >= _AREA_T sigma``."""
        return (c > 0.0) & (c * c >= _AREA_T2 * var)

    @_kernel
    def _area_excess_range(start, stop, E, k, out):  # pragma: no cover - compiled
        """``out[n] = V_n(k) - A_n(k) = E[s+] - c+ >= 0`` (:func:`_area`) of lobes
        ``start:stop`` of the flat raw moments ``E`` toward one direction ``k``."""
        kx, ky, kz = k[0], k[1], k[2]
        Er, outr = E[5 * start:5 * stop], out[start:stop]         # indexed from 0: vectorizes
        for n in range(stop - start):
            c, var = _toward(kx, ky, kz, _lobe(Er, n))
            a, v = _area(c, var)
            outr[n] = v - a

    def _area_excess(E, k):
        """The per-lobe part of the patch areas toward one direction ``k`` that is not
        linear in the mean slopes (:func:`_area_excess_range`), tabulated once when every
        pixel shares ``k``."""
        out = np.empty(E.size // 5)
        _kernels.launch_ranges(_area_excess_range, out.size, E, np.ascontiguousarray(k, dtype=np.float64), out)
        return out

    @numba.njit(cache=True, inline="always")
    def _half_slope(h):  # pragma: no cover - compiled
        """``(z_h, x~, y~, 1 / z_h^4)`` of a half vector: its slope and the Jacobian of
        ``D(h) = P22(h~) / cos^4`` (Eq. 4, 9); zeros below the horizon."""
        hz = h[2]
        if hz > 0:
            return hz, -h[0] / hz, -h[1] / hz, 1.0 / (hz * hz * hz * hz)
        return hz, 0.0, 0.0, 0.0

    @numba.njit(cache=True, nogil=True)
    def _window(f, win):  # pragma: no cover - compiled
        """Centre, covariance (footprint + kernel), its determinant and the inclusive seed
        index window ``x0..x1, y0..y1`` of footprint row ``f = (u, v, cuu, cvv, cuv)``
        (the window of :func:`footprint_lobes`; ``win`` the grid's :class:`Window`)."""
        nx, ny, ks2x, ks2y, cutoff = win
        cu, cv = f[0], f[1]
        sxx, syy, sxy = f[2] + ks2x, f[3] + ks2y, f[4]
        rx, ry = cutoff * math.sqrt(sxx), cutoff * math.sqrt(syy)
        x0, x1 = int(math.ceil((cu - rx) * nx - 0.5)), int(math.floor((cu + rx) * nx - 0.5))
        y0, y1 = int(math.ceil((cv - ry) * ny - 0.5)), int(math.floor((cv + ry) * ny - 0.5))
        return cu, cv, sxx, syy, sxy, sxx * syy - sxy * sxy, x0, x1, y0, y1

    @numba.njit(cache=True, nogil=True)
    def _widest(start, stop, fp, win):  # pragma: no cover - compiled
        """``(L, K)``: the most columns and the most lobes (at least 1) of the windows of the
        footprints ``start:stop`` of ``fp`` (:func:`_window`), which size the range kernels' scratch."""
        L, K = 1, 1
        for p in range(start, stop):
            x0, x1, y0, y1 = _window(fp[p], win)[6:10]
            L, K = max(L, x1 - x0 + 1), max(K, (x1 - x0 + 1) * (y1 - y0 + 1))
        return L, K

    @numba.njit(cache=True, inline="always")
    def _block_linear(b, kx, ky, kz):  # pragma: no cover - compiled
        """Whether every lobe of a block with bounds ``b`` (see
        :func:`~microfacet.glints.microsurface._block_bounds_compiled`) has projected areas
        ``(c, c)`` toward ``k`` (:func:`_linear`, :func:`_area`): the smallest ``c`` over the block's mean
        slopes is positive and at least ``_AREA_T`` times the largest ``sigma``."""
        c = kz - max(kx * b[0], kx * b[1]) - max(ky * b[2], ky * b[3])
        var = kx * kx * b[4] * b[4] + ky * ky * b[5] * b[5] + 2.0 * abs(kx * ky) * b[6]
        return c > 0.0 and c * c >= _AREA_T2 * var

    @numba.njit(cache=True, inline="always")
    def _block_dark(b, hz, xh, yh, prune):  # pragma: no cover - compiled
        """Whether the half vector's slope lies outside the block's slope box (mean bounds
        +- ``prune`` times the largest per-axis deviation): then every lobe of the block has
        Mahalanobis distance ``> prune`` (at least the per-axis one) and ``P_i(h~) <=
        exp(-prune^2 / 2) / (2 pi sqrt(det))``."""
        return hz <= 0.0 or (xh < b[0] - prune * b[4] or xh > b[1] + prune * b[4]
                             or yh < b[2] - prune * b[5] or yh > b[3] + prune * b[5])

    @numba.njit(cache=True, inline="always")
    def _segment(s, e, n, B):  # pragma: no cover - compiled
        """The run of unwrapped seed indices from ``s`` (at most ``e``) that falls in one
        ``B``-block of the wrapped grid of ``n`` seeds: ``(last index, wrapped s, block)``."""
        w = s % n
        blk = w // B
        return min(e, s + min(blk * B + B, n) - 1 - w), w, blk

    @_inline
    def _add_run(lobes, run, cols, q, tab, curved, m):  # pragma: no cover - compiled
        """Adds ``w (1, P_i, A_i(i), V_i(i), A_i(o), V_i(o))`` (Eq. 9, 13, 17: the slope density
        :func:`_p22` and the projected areas :func:`_area`) of the ``n`` consecutive lobes ``k0 ..``
        (``run = (k0, j0, n)``; ``lobes = (E, exo)``: the flat raw moments and the tabulated area
        excess) with weights ``wr[j0 ..]`` to the columns ``j0 ..`` of ``acc`` (``cols = (wr, acc)``;
        ``6 j + term``: one array, so that LLVM sees the stores apart and vectorizes the loop), at the
        query ``q = (x~h, y~h, qmax, i, o)`` (:func:`_query`). The view direction's areas from
        the lobes' tabulated ``V_i(o) - A_i(o)`` (``exo``, :func:`_area_excess`) where ``tab``, else
        :func:`_area`; ``tab`` is a constant at each call (:func:`_footprint_range`), so that the
        choice leaves the loop.

        With ``tab``, ``V_i(i)`` is added as ``c`` (as if every lobe's were linear, :func:`_linear`),
        and the lobes where it is not are appended from ``m`` on to ``curved = (c, var, w, row)``
        (``row``: the run's ``var``, -1 where linear; returns the new ``m``) by a branch-free loop,
        their :func:`_excess_sum` added by the caller once per footprint: the erfc and exp of
        :func:`_area` only for those (9.4 % of the window lobes in the glint benchmark's scenes), in a
        loop long enough to vectorize (per run, its few lobes took the scalar remainder). One core,
        the benchmark's 16-texel image: 13.8 -> 13.0 ms."""
        E, exo = lobes
        k0, j0, n = run
        wr, acc = cols
        xh, yh, qmax, ix, iy, iz, ox, oy, oz = q
        # views from the run's start, indexed from 0: LLVM vectorizes the loop (not with
        # the indices k0 + j: unknown sign, wraparound)
        Er, wrr, accr, exr = E[5 * k0:5 * (k0 + n)], wr[j0:j0 + n], acc[6 * j0:6 * (j0 + n)], exo[k0:k0 + n]
        cc, vv, ww, row = curved
        fr = row[0:n]
        for j in range(n):
            lobe = _lobe(Er, j)
            ci, vari = _toward(ix, iy, iz, lobe)
            co, varo = _toward(ox, oy, oz, lobe)
            if tab:         # the tabulated V_i(o) - A_i(o) (_area_excess); V_i(i) = c, see above
                ai, vi = max(ci, 0.0), ci
                ao = max(co, 0.0)
                vo = ao + exr[j]
                fr[j] = -1.0 if _linear(ci, vari) else vari
            else:
                ai, vi = _area(ci, vari)
                ao, vo = _area(co, varo)
            w = wrr[j]
            accr[6 * j] += w
            accr[6 * j + 1] += w * _p22(xh, yh, lobe, qmax)
            accr[6 * j + 2] += w * ai
            accr[6 * j + 3] += w * vi
            accr[6 * j + 4] += w * ao
            accr[6 * j + 5] += w * vo
        if tab:
            m = max(m, 0)                            # (known >= 0: no wraparound of the indices)
            for j in range(n):                       # branch-free gathering
                var = fr[j]
                cc[m] = _toward(ix, iy, iz, (Er[5 * j], Er[5 * j + 1], 0.0, 0.0, 0.0))[0]
                vv[m], ww[m] = var, wrr[j]
                m += 1 if var >= 0.0 else 0
        return m

    @_inline
    def _excess_sum(curved, m):  # pragma: no cover - compiled
        """``sum_t w_t (E[s+] - c)_t`` (:func:`_area`) of the lobes ``t < m`` of :func:`_add_run`'s
        ``curved``: the part of ``V_P(i)`` that is not linear (overwrites ``c``)."""
        cc, vv, ww = curved[:3]
        for t in range(m):
            cc[t] = ww[t] * (_area(cc[t], vv[t])[1] - cc[t])
        total = 0.0
        for t in range(m):
            total += cc[t]
        return total

    @_inline
    def _add_linear(E, run, cols, q):  # pragma: no cover - compiled
        """:func:`_add_run` for the lobes of a pruned block: ``w (1, 0, c(i), c(i), c(o), c(o))``."""
        k0, j0, n = run
        wr, acc = cols
        ix, iy, iz, ox, oy, oz = q[3:9]
        Er, wrr, accr = E[5 * k0:5 * (k0 + n)], wr[j0:j0 + n], acc[6 * j0:6 * (j0 + n)]
        for j in range(n):
            w = wrr[j]
            ci, co = w * (iz - ix * Er[5 * j] - iy * Er[5 * j + 1]), w * (oz - ox * Er[5 * j] - oy * Er[5 * j + 1])
            accr[6 * j] += w
            accr[6 * j + 2] += ci
            accr[6 * j + 3] += ci
            accr[6 * j + 4] += co
            accr[6 * j + 5] += co

    @_inline
    def _column_sums(acc, L):  # pragma: no cover - compiled
        """The six sums ``sum_j acc[6 j + term]`` of the column accumulators of :func:`_add_run`."""
        return (acc[0:6 * L:6].sum(), acc[1:6 * L:6].sum(), acc[2:6 * L:6].sum(), acc[3:6 * L:6].sum(),
                acc[4:6 * L:6].sum(), acc[5:6 * L:6].sum())

    @_inline
    def _column_weights(ex, wnd, nx):  # pragma: no cover - compiled
        """The footprint weights ``exp(-q / 2)`` (:func:`footprint_lobes`) of a window's columns:
        ``ex[jx] = exp(ax du^2)`` for the ``L`` columns from ``x0`` of the window ``wnd``
        (:func:`_window`, of a grid ``nx`` lobes wide); returns ``(ax, ay, axy)`` of
        ``-q / 2 = ax du^2 + ay dv^2 + axy du dv`` (covariance ``sxx, syy, sxy``, determinant ``det``)."""
        cu, _, sxx, syy, sxy, det, x0, x1 = wnd[:8]
        L = x1 - x0 + 1
        ax, ay, axy = -0.5 * syy / det, -0.5 * sxx / det, sxy / det
        for jx in range(L):
            du = (x0 + jx + 0.5) / nx - cu
            ex[jx] = math.exp(ax * du * du)
        return ax, ay, axy

    @_inline
    def _row_weights(wr, ex, wnd, nx, quad, dv):  # pragma: no cover - compiled
        """``wr[:L]``: the footprint weights of the row at ``dv`` of the window ``wnd`` (``quad = (ax, ay,
        axy)`` and ``ex`` from :func:`_column_weights`): ``ex[jx] exp(ay dv^2)`` when uncorrelated (one exp
        per column and per row instead of one per lobe), else ``exp(-q / 2)`` in one exp (the factors may
        over/underflow for thin footprints)."""
        ax, ay, axy = quad
        cu, x0, L = wnd[0], wnd[6], wnd[7] - wnd[6] + 1
        cross = axy * dv
        if cross == 0.0:
            ey = math.exp(ay * dv * dv)
            for jx in range(L):
                wr[jx] = ex[jx] * ey
        else:
            for jx in range(L):
                du = (x0 + jx + 0.5) / nx - cu
                wr[jx] = math.exp(ax * du * du + ay * dv * dv + cross * du)

    @_inline
    def _query(h, wi, wo, qmax):  # pragma: no cover - compiled
        """``(z_h, 1 / z_h^4, q)`` of a footprint's half vector ``h`` and directions ``wi``, ``wo``:
        the query ``q = (x~h, y~h, qmax, ix, iy, iz, ox, oy, oz)`` of :func:`_add_run` (``qmax`` 0
        below the horizon: no density there; :func:`_half_slope`)."""
        hz, xh, yh, inv4 = _half_slope(h)
        return hz, inv4, (xh, yh, qmax if hz > 0.0 else 0.0, wi[0], wi[1], wi[2], wo[0], wo[1], wo[2])

    @_inline
    def _block_runs(grid, wnd, ys, q, hp, runs):  # pragma: no cover - compiled
        """The runs of blocks of the block row of seed row ``ys`` (``B``-blocks of ``grid``, a
        :class:`LobeGrid`) across the window ``wnd`` (:func:`_window`) for the query ``q``
        (:func:`_query`; ``hp = (z_h, prune)``): consecutive blocks of the same
        kind (pruned or not, :func:`_block_dark`, :func:`_block_linear`) that are consecutive in memory,
        into ``runs = (r0, r1, rw, rfull)`` (first and last unwrapped column, first wrapped column,
        kind). Returns ``(ye, wys, n_runs)``: the block row's last seed row, its wrapped first one and
        how many runs it has."""
        r0, r1, rw, rfull = runs
        nx, ny = grid.window.nx, grid.window.ny
        x0, x1, y1 = wnd[6], wnd[7], wnd[9]
        xh, yh = q[0], q[1]
        hz, prune = hp
        ye, wys, by = _segment(ys, y1, ny, grid.B)
        n_runs = 0
        xs = x0
        while xs <= x1:
            xe, wxs, bx = _segment(xs, x1, nx, grid.B)
            b = grid.bounds[by, bx]
            full = not (_block_dark(b, hz, xh, yh, prune) and _block_linear(b, q[3], q[4], q[5])
                        and _block_linear(b, q[6], q[7], q[8]))
            if n_runs > 0 and rfull[n_runs - 1] == full and wxs == rw[n_runs - 1] + xs - r0[n_runs - 1]:
                r1[n_runs - 1] = xe
            else:
                r0[n_runs], r1[n_runs], rw[n_runs], rfull[n_runs] = xs, xe, wxs, full
                n_runs += 1
            xs = xe + 1
        return ye, wys, n_runs

    @_loops
    def _footprint_loops(start, stop, out, grid, query, scratch):  # pragma: no cover - compiled
        """Per footprint ``p`` of ``start:stop``, into ``out[p]``: ``(D_P(h), A_P(i), V_P(i),
        A_P(o), V_P(o))`` of the lobes of :func:`footprint_lobes` (same window, same
        weights), looping over the window instead of padding it; ``grid`` the
        :class:`LobeGrid` (``E`` the flat raw lobe moments ``(ny * nx * 5,)``: each lobe's Gaussian
        is set up from them where it is used, no per-lobe table), ``query`` the
        :class:`Footprints`, ``scratch = (ex, wr, acc, runs, curved)`` (:func:`_footprint_range`).

        Pruning by ``B x B`` blocks of lobes (``bounds``, :func:`_block_runs`): a block whose slope
        box (``prune`` deviations) misses the
        half vector's slope and whose lobes all have projected areas ``(c, c)`` toward
        ``i`` and ``o`` adds only its weights and ``W c`` (Eq. 13, 17); its slope
        densities, each below ``exp(-prune^2 / 2) / (2 pi sigma_eps^2)``, are dropped, and
        so is, in the other blocks, every lobe density whose Mahalanobis distance is at
        least ``prune``. So ``D_P`` is at most
        ``exp(-prune^2 / 2) / (2 pi sigma_eps^2 z_h^4)`` below the unpruned sum and the
        areas are unchanged; ``prune = inf`` visits every lobe. ``exo``: the lobes'
        :func:`_area_excess` toward ``wo`` when every footprint has the same ``wo`` (an
        orthographic view: one erfc per lobe instead of one per lobe and pixel), else
        empty; ``curved``, the scratch where :func:`_add_run` gathers the lobes whose area toward
        ``i`` is not linear.

        Each row of the window is added in runs of consecutive lobes of the same kind
        (pruned or not), column by column into ``6 L`` accumulators (:func:`_add_run`,
        :func:`_add_linear`: branch-free loops that vectorize), summed once per footprint:
        the same sums as the NumPy reference up to rounding (the order of the additions
        differs). The footprint weight ``exp(-q/2)`` of an uncorrelated footprint is
        factored into per-column and per-row exponentials (one exp per lobe otherwise),
        the lobe's slope density is cut where its exponent is below ``-700``
        (``_Q_MAX``), and the projected areas are ``c`` where ``c / sigma >= 8``
        (``_AREA_T``)."""
        E, win = grid.E, grid.window
        nx, ny = win.nx, win.ny
        ex, wr, acc, runs, curved = scratch
        r0, r1, rw, rfull = runs
        lobes, cols = (E, query.exo), (wr, acc)
        qmax = min(query.prune * query.prune, _Q_MAX)
        tab = query.exo.size > 0
        for p in range(start, stop):
            wnd = _window(query.fp[p], win)
            cu, cv, sxx, syy, sxy, det, x0, x1, y0, y1 = wnd
            if x1 < x0 or y1 < y0:
                continue
            L = x1 - x0 + 1
            quad = _column_weights(ex, wnd, nx)
            hz, inv4, q = _query(query.h[p], query.wi[p], query.wo[p], qmax)
            acc[:6 * L] = 0.0
            m, excess = 0, 0.0                       # the gathered lobes of _add_run, their sum
            ys = y0
            while ys <= y1:
                # runs of blocks along this block row: same kind, consecutive in memory
                ye, wys, n_runs = _block_runs(grid, wnd, ys, q, (hz, query.prune), runs)
                for iy in range(ys, ye + 1):
                    _row_weights(wr, ex, wnd, nx, quad, (iy + 0.5) / ny - cv)
                    row = (wys + iy - ys) * nx
                    for r in range(n_runs):
                        run = (row + rw[r], r0[r] - x0, r1[r] - r0[r] + 1)
                        if rfull[r] and tab:        # constant tab: a loop without the choice
                            if m + run[2] > curved[0].size:      # full: sum what it holds
                                excess, m = excess + _excess_sum(curved, m), 0
                            m = _add_run(lobes, run, cols, q, True, curved, m)
                        elif rfull[r]:
                            _add_run(lobes, run, cols, q, False, curved, 0)
                        else:
                            _add_linear(E, run, cols, q)
                ys = ye + 1
            wsum, s0, s1, s2, s3, s4 = _column_sums(acc, L)
            s2 += excess + _excess_sum(curved, m)
            if wsum > 0:
                out[p, 0], out[p, 1], out[p, 2] = s0 * inv4 / wsum, s1 / wsum, s2 / wsum
                out[p, 3], out[p, 4] = s3 / wsum, s4 / wsum

    #: Most lobes :func:`_footprint_range` gathers (:func:`_add_run`'s ``curved``, 3 x 512 KB) before
    #: it sums them, so that a footprint over a large part of a map takes bounded scratch.
    _GATHER = 1 << 16

    @_kernel
    def _footprint_range(start, stop, out, grid, query):  # pragma: no cover - compiled
        """:func:`_footprint_loops` over the footprints ``start:stop`` of ``query`` (:class:`Footprints`)
        on ``grid`` (:class:`LobeGrid`), with scratch for the widest of their windows (``L`` lobes:
        ``6 L`` accumulators, ``L // B + 2`` runs per block row) and :func:`_add_run`'s ``curved`` where
        ``exo`` is tabulated: room for the largest window's lobes, at most :data:`_GATHER` but at least a
        row's (the loops sum the list when it is full)."""
        L, K = _widest(start, stop, query.fp, grid.window)
        nr = L // grid.B + 2
        K = max(L, min(K, _GATHER)) if query.exo.size > 0 else 0     # (only with the tabulated view)
        runs = (np.empty(nr, np.int64), np.empty(nr, np.int64), np.empty(nr, np.int64), np.empty(nr, np.bool_))
        _footprint_loops(start, stop, out, grid, query,
                         (np.empty(L), np.empty(L), np.empty(6 * L), runs,
                          (np.empty(K), np.empty(K), np.empty(K), np.empty(L))))

    def _footprint_sums(grid, query):
        """``(P, 5)`` sums of :func:`_footprint_range` over all footprints of ``query``
        (:class:`Footprints`) on ``grid`` (:class:`LobeGrid`), as tasks on the kernels' thread pool
        (:func:`microfacet.kernels.launch_ranges`: a thread takes the next task when done, so that
        footprints of different cost balance)."""
        out = np.zeros((query.fp.shape[0], 5))
        _kernels.launch_ranges(_footprint_range, query.fp.shape[0], out, grid, query,
                                cost=_task_cost(query.fp, grid.window))
        return out

    @_kernel
    def _lobe_range(start, stop, out, lobes, query):  # pragma: no cover - compiled
        """Per query ``q`` of ``start:stop``, into ``out[q]``: ``(D_P(h), A_P(i), V_P(i),
        A_P(o), V_P(o))`` of explicit lobes ``lobes = (E, W)`` (flat raw moments ``E (5 N,)``,
        weights ``W`` summing to 1) at ``query = (h, wi, wo)``: the sums of :meth:`PatchBRDF.pndf`
        and :meth:`PatchBRDF.areas` (Eq. 9, 13, 17) in one pass, the lobes as one run of :func:`_add_run`."""
        E, W = lobes
        h, wi, wo = query
        acc, none = np.empty(6 * W.size), np.empty(0)
        for q in range(start, stop):
            hz, inv4, qq = _query(h[q], wi[q], wo[q], _Q_MAX)
            acc[:] = 0.0
            _add_run((E, none), (0, 0, W.size), (W, acc), qq, False, (none, none, none, none), 0)
            _, d, ai, vi, ao, vo = _column_sums(acc, W.size)
            out[q, 0], out[q, 1], out[q, 2], out[q, 3], out[q, 4] = d * inv4, ai, vi, ao, vo

    def _lobe_sums(lobes, query):
        """``(Q, 5)`` sums of :func:`_lobe_range` over all queries ``query = (h, wi, wo)`` of the lobes
        ``lobes = (E, W)``, as tasks on the kernels' thread pool (:func:`microfacet.kernels.launch_ranges`)."""
        out = np.zeros((query[0].shape[0], 5))
        _kernels.launch_ranges(_lobe_range, out.shape[0], out, lobes, query, cost=lobes[1].size)
        return out

    @_kernel
    def _merge_range(start, stop, out, grid, win, fp):  # pragma: no cover - compiled
        """Per footprint ``p`` of ``start:stop``, into ``out[p]``: the ``W``-weighted average of the flat
        moments ``grid`` ``(ny * nx * 5,)`` over its window (``win``, a :class:`Window`; the weights of
        :func:`footprint_lobes`: :func:`_column_weights`, :func:`_row_weights`, as in :func:`_footprint_loops`)."""
        nx, ny = win.nx, win.ny
        L = _widest(start, stop, fp, win)[0]
        ex, wr, xw = np.empty(L), np.empty(L), np.empty(L, np.int64)
        for p in range(start, stop):
            wnd = _window(fp[p], win)
            cu, cv, sxx, syy, sxy, det, x0, x1, y0, y1 = wnd
            n = x1 - x0 + 1
            quad = _column_weights(ex, wnd, nx)
            for jx in range(n):
                xw[jx] = 5 * ((x0 + jx) % nx)
            wsum, m0, m1, m2, m3, m4 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            for iy in range(y0, y1 + 1):
                _row_weights(wr, ex, wnd, nx, quad, (iy + 0.5) / ny - cv)
                row = 5 * nx * (iy % ny)
                for jx in range(n):
                    w = wr[jx]
                    k = row + xw[jx]
                    wsum += w
                    m0, m1, m2 = m0 + w * grid[k], m1 + w * grid[k + 1], m2 + w * grid[k + 2]
                    m3, m4 = m3 + w * grid[k + 3], m4 + w * grid[k + 4]
            if wsum > 0:
                out[p, 0], out[p, 1], out[p, 2] = m0 / wsum, m1 / wsum, m2 / wsum
                out[p, 3], out[p, 4] = m3 / wsum, m4 / wsum

    def _footprint_merge(grid, win, fp):
        """``(P, 5)`` averages of :func:`_merge_range` over all footprints ``fp`` of the moments ``grid``
        ``(ny * nx, 5)`` (``win``, its :class:`Window`), as tasks on the kernels' thread pool
        (:func:`microfacet.kernels.launch_ranges`)."""
        out = np.zeros((fp.shape[0], 5))
        _kernels.launch_ranges(_merge_range, fp.shape[0], out, grid.reshape(-1), win, fp,
                                cost=_task_cost(fp, win))
        return out
else:  # pragma: no cover - without numba
    _footprint_sums = _footprint_merge = _lobe_sums = _area_excess = None


def _window_pairs(fp, win) -> float:
    """About how many (footprint, lobe) pairs the windows of footprints ``fp`` hold (:class:`Window` ``win``)."""
    return float(np.sum((2 * win.cutoff * np.sqrt(fp[:, 2] + win.ks2x) * win.nx + 1)
                        * (2 * win.cutoff * np.sqrt(fp[:, 3] + win.ks2y) * win.ny + 1)))


def _task_cost(fp, win) -> int:
    """Lobes per footprint of ``fp``'s windows (:func:`_window_pairs`), the ``cost`` of a footprint
    for :func:`microfacet.kernels.launch_ranges`."""
    return int(_window_pairs(fp, win) / max(fp.shape[0], 1)) + 1


def _merged_footprints(ms, c, cov, fast: bool = False) -> np.ndarray:
    """Merged-lobe moments ``(P, 5)`` of Sec. 4.2.2 for each footprint (MIP level of
    ``ms.mip_level``, weights of that level's grid)."""
    flat = np.asarray(cov).reshape(-1, 4)
    if flat.shape[0] and np.all(flat == flat[:1]):                 # one footprint shape (a broadcast)
        levels = np.full(flat.shape[0], ms.mip_level(flat[0].reshape(2, 2)))
    else:                                                          # images often share footprints
        uniq, inverse = np.unique(flat, axis=0, return_inverse=True)
        levels = np.array([ms.mip_level(u.reshape(2, 2)) for u in uniq])[inverse.reshape(-1)]
    merged = np.empty((c.shape[0], 5))
    for lev in np.unique(levels):
        sel = np.flatnonzero(levels == lev)
        grid = ms.mip[lev]
        if fast and _footprint_merge is not None:
            fp = np.ascontiguousarray(np.stack([c[sel, 0], c[sel, 1], cov[sel, 0, 0], cov[sel, 1, 1],
                                                cov[sel, 0, 1]], -1))
            merged[sel] = _footprint_merge(np.ascontiguousarray(grid.reshape(-1, 5)),
                                           Window.of(grid.shape, ms.cutoff), fp)
            continue
        for s in range(0, sel.size, 4096):
            part = sel[s:s + 4096]
            li, lw = footprint_lobes(grid.shape[:2], c[part], cov[part], ms.cutoff)
            merged[part] = np.einsum("bk,bkm->bm", lw, grid.reshape(-1, 5)[li])
    return merged


def _eval_cos_footprints_numba(ms, pixels, fresnel, exact, g2, prune) -> np.ndarray:
    """:func:`eval_cos_footprints` by the compiled image kernel (:func:`_footprint_sums`), ``pixels =
    (centers, covs, wi, wo)``."""
    centers, covs, wi, wo = pixels
    fresnel = _fresnel.Ideal() if fresnel is None else fresnel
    c = np.asarray(centers, dtype=np.float64).reshape(-1, 2)
    P = c.shape[0]
    cov = np.broadcast_to(np.asarray(covs, dtype=np.float64), (P, 2, 2))
    wi = np.ascontiguousarray(np.broadcast_to(directions(wi, "wi"), (P, 3)))
    wo1 = directions(wo, "wo")
    wo = np.ascontiguousarray(np.broadcast_to(wo1, (P, 3)))
    fp = np.ascontiguousarray(np.stack([c[:, 0], c[:, 1], cov[:, 0, 0], cov[:, 1, 1], cov[:, 0, 1]], -1))
    h = half_vector(wi, wo)
    oh, ih = dot(wo, h), dot(wi, h)
    ok = _local_ok(wi, wo, h, oh, ih)
    grid = LobeGrid.of(ms)
    # one view direction for all pixels: tabulate the lobes' area excess toward it once,
    # when the image visits more (pixel, lobe) pairs than there are lobes
    pairs = _window_pairs(fp, grid.window)
    exo = _area_excess(grid.E, wo1) if wo1.ndim == 1 and pairs > 2 * ms.n_lobes else np.zeros(0)
    D, ai, vi, ao, vo = _footprint_sums(grid, Footprints(fp, np.ascontiguousarray(h), wi, wo, exo, prune)).T
    if not exact:
        merged = _merged_footprints(ms, c, cov, fast=True)
        ai, vi = _merged_area(vi, merged, wi)
        ao, vo = _merged_area(vo, merged, wo)
    val = np.where(ok, D * _g2_over_ao(g2, ai, vi, ao, vo) / 4.0, 0.0)
    return fresnel(oh) * val[:, None]
