"""Least-squares fits of analytic microfacet BRDFs to data (issue 10), and the sum BRDF
that carries an optional Lambertian base.

:func:`fit_analytic` fits ``f = F D G / (4 cos theta_i cos theta_o) + k_d / pi``
(Eq. 2.1 plus Eq. 1.9) to a reference BRDF by minimizing ``e_grid^2 + e_uniform^2``, the
squared relative RMS errors of ``f_r cos theta_i`` (RGB) of
:func:`microfacet.metrics.fit_error` (a MERL-coordinate grid dense at the specular peak)
and :func:`microfacet.metrics.uniform_error` (pairs uniform in solid angle), grazing and
unmeasured pairs excluded as there. The grid alone leaves everything off the peak
free (a fit of gold metallic paint to it alone has 2.5x the data's albedo); the uniform
pairs pin the albedo and the diffuse base. The problem is solved by variable projection: for given nonlinear parameters
``q`` (``log alpha_x``, ``log alpha_y``, ``rho``; for a conductor Fresnel also ``eta``,
``k`` per channel) the model is linear in the remaining ones ``c`` (Schlick ``F0``, the
nodes of a Fresnel table, ``k_d``), which are solved exactly per channel with bounds
``[0, 1]``; ``q`` is found by ``scipy.optimize.least_squares`` with bounds (trust-region
reflective), started from the best of the moment conversion of the tabulated fit
(thesis App. C) and a coarse scan of the roughness.
"""
from __future__ import annotations

import numpy as np

from .. import fresnel as _fresnel
from ..brdf import BRDF, Lambertian, MicrofacetBRDF
from ..distributions import GGX, Beckmann
from ..geometry import dot, half_vector
from ..metrics import compared_pairs, measurement_directions, uniform_directions

__all__ = ["SumBRDF", "fit_analytic", "MODELS", "FRESNELS", "ALPHA_BOUNDS", "TABLE_NODES"]

MODELS = {"ggx": GGX, "beckmann": Beckmann}
FRESNELS = ("conductor", "schlick", "table")
#: Bounds of the fitted roughness ``alpha_x, alpha_y``.
ALPHA_BOUNDS = (1e-3, 2.0)
#: Bounds of the fitted conductor indices ``eta`` and ``k``.
ETA_BOUNDS, K_BOUNDS = (0.02, 10.0), (0.0, 20.0)
_RHO_BOUND = 0.95
#: Nodes of the fitted Fresnel table, uniform in ``theta_d`` (as ``cos theta_d``, increasing).
TABLE_NODES = np.cos(np.linspace(np.pi / 2, 0.0, 7))
#: Roughness values of the initial scan.
_SCAN = np.geomspace(0.004, 1.5, 20)


class SumBRDF(BRDF):
    """The sum of BRDFs, ``f = sum_j f_j`` (e.g. a specular lobe over a Lambertian base).

    ``sample`` is mixture sampling: lobe ``j`` is chosen with probability ``w_j`` (the
    first uniform, rescaled, drives the chosen lobe), so ``pdf = sum_j w_j pdf_j`` and
    the weight is the exact ``eval_cos / pdf`` of the sum (multi-sample MIS, balance
    heuristic). ``weights`` default to equal; they change the variance, never the mean.
    """

    def __init__(self, *brdfs: BRDF, weights=None):
        if not brdfs or not all(isinstance(b, BRDF) for b in brdfs):
            raise ValueError("SumBRDF needs one or more BRDF objects")
        w = np.ones(len(brdfs)) if weights is None else np.asarray(weights, dtype=np.float64).ravel()
        if w.shape != (len(brdfs),) or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ValueError(f"weights must be {len(brdfs)} finite values >= 0 with a positive sum, "
                             f"got {weights!r}")
        self.brdfs = tuple(brdfs)
        self.weights = w / w.sum()

    def __repr__(self) -> str:
        return "SumBRDF(" + ", ".join(map(repr, self.brdfs)) + f", weights={self.weights.round(4).tolist()})"

    def eval_cos(self, wi, wo) -> np.ndarray:
        """``sum_j f_j cos theta_i``."""
        return sum(b.eval_cos(wi, wo) for b in self.brdfs)

    def eval(self, wi, wo) -> np.ndarray:
        """``sum_j f_j``."""
        return sum(b.eval(wi, wo) for b in self.brdfs)

    def pdf(self, wi, wo) -> np.ndarray:
        """Mixture density ``sum_j w_j pdf_j``."""
        return sum(w * b.pdf(wi, wo) for w, b in zip(self.weights, self.brdfs, strict=True) if w > 0)

    def sample(self, u, wo):
        """Choose lobe ``j`` with probability ``w_j`` by ``u[..., 0]``, sample it with the
        rescaled uniform; return ``(wi, eval_cos / pdf, pdf)`` of the mixture."""
        wo = np.asarray(wo, dtype=np.float64)
        u = np.asarray(u, dtype=np.float64)
        shape = np.broadcast_shapes(u.shape[:-1], wo.shape[:-1])
        u = np.broadcast_to(u, shape + (2,))
        edges = np.concatenate([[0.0], np.cumsum(self.weights)])
        edges[-1] = 1.0
        j = np.clip(np.searchsorted(edges, u[..., 0], side="right") - 1, 0, len(self.brdfs) - 1)
        lo, width = edges[j], self.weights[j]
        v = np.stack([np.clip((u[..., 0] - lo) / np.where(width > 0, width, 1.0), 0.0, 1.0 - 1e-16),
                      u[..., 1]], axis=-1)
        wi = np.zeros(shape + (3,))
        for index, brdf in enumerate(self.brdfs):
            chosen = j == index
            if np.any(chosen):
                wo_j = np.broadcast_to(wo, shape + (3,))[chosen]
                wi[chosen] = brdf.sample(v[chosen], wo_j)[0]
        pdf = self.pdf(wi, wo)
        fc = self.eval_cos(wi, wo)
        ok = (pdf > 0) & np.all(np.isfinite(fc), axis=-1)
        weight = np.where(ok[..., None], fc / np.where(ok, pdf, 1.0)[..., None], 0.0)
        return wi, weight, np.where(ok, pdf, 0.0)


# ------------------------------------------------------------------ least squares
class _Data:
    """The compared pairs of a reference (the grid of :func:`~microfacet.metrics.fit_error`
    and, optionally, uniformly distributed pairs), their weights and the model-independent
    terms on them."""

    def __init__(self, reference, n: int, n_uniform: int):
        blocks = [measurement_directions(n)] + ([uniform_directions(n_uniform, seed=1)] if n_uniform else [])
        wis, wos, refs, scales = [], [], [], []
        for directions in blocks:
            pairs = compared_pairs(reference, directions)
            wi, wo = pairs[:2]
            w = pairs[2] if len(pairs) == 3 else np.ones(len(wi))
            ref = np.asarray(reference.eval_cos(wi, wo), dtype=np.float64)
            finite = np.all(np.isfinite(ref), axis=-1)
            wi, wo, ref, w = wi[finite], wo[finite], ref[finite], w[finite]
            norm = float(np.sqrt(np.sum(w[:, None] * ref**2)))
            if not norm > 0:
                raise ValueError("fit_analytic: the reference BRDF is zero on the compared directions")
            wis.append(wi), wos.append(wo), refs.append(ref), scales.append(np.sqrt(w) / norm)
        self.wi, self.wo, self.ref = np.concatenate(wis), np.concatenate(wos), np.concatenate(refs)
        self.scale = np.concatenate(scales)[:, None]        # each block: its relative RMS
        self.cos_d = dot(self.wo, half_vector(self.wi, self.wo))
        self.m5 = (1.0 - np.clip(self.cos_d, 0.0, 1.0)) ** 5                # Schlick (Table 2.I)
        self.lambert = np.clip(self.wi[:, 2], 0.0, None) / np.pi          # k_d cos theta_i / pi
        self.hats = np.stack([np.interp(self.cos_d, TABLE_NODES, e) for e in np.eye(len(TABLE_NODES))],
                             axis=-1)


class _Problem:
    """One model on the data: the variable-projection residual (module docstring)."""

    def __init__(self, data: _Data, model, diffuse, anisotropic, fresnel, gaf, shadowing, mean_slope):
        self.data = data
        self.family, self.diffuse, self.anisotropic, self.fresnel = MODELS[model], diffuse, anisotropic, fresnel
        self.gaf, self.shadowing, self.mean_slope = gaf, shadowing, mean_slope

    # --- parameters: q = [log ax, (log ay, rho)] + conductor [eta rgb, k rgb]
    def n_shape(self) -> int:
        return 3 if self.anisotropic else 1

    def distribution(self, q):
        if self.anisotropic:
            return self.family(alpha_x=np.exp(q[0]), alpha_y=np.exp(q[1]), rho=q[2], mean_slope=self.mean_slope)
        return self.family(alpha=np.exp(q[0]), mean_slope=self.mean_slope)

    def bounds(self):
        la = np.log(ALPHA_BOUNDS)
        lo, hi = [la[0]], [la[1]]
        if self.anisotropic:
            lo += [la[0], -_RHO_BOUND]
            hi += [la[1], _RHO_BOUND]
        if self.fresnel == "conductor":
            lo += [ETA_BOUNDS[0]] * 3 + [K_BOUNDS[0]] * 3
            hi += [ETA_BOUNDS[1]] * 3 + [K_BOUNDS[1]] * 3
        return np.array(lo), np.array(hi)

    def specular(self, q) -> np.ndarray:
        """``D G / (4 cos theta_o)`` of the shape parameters, ``(M,)`` (``F = 1``)."""
        brdf = MicrofacetBRDF(self.distribution(q), gaf=self.gaf, shadowing=self.shadowing)
        s = brdf.eval_cos(self.data.wi, self.data.wo)[:, 0]
        return np.where(np.isfinite(s), s, 0.0)

    def conductor(self, q):
        k = self.n_shape()
        return _fresnel.Conductor(eta=q[k:k + 3], k=q[k + 3:k + 6])

    def design(self, q):
        """The model ``a0 + A c`` with linear coefficients ``c`` in ``[0, 1]``: the fixed
        part ``a0 (M, 3)`` and the basis ``A (M, J)`` (the same for every channel)."""
        s = self.specular(q)
        cols = []
        if self.fresnel == "schlick":                   # F = F0 (1 - m^5) + m^5
            a0 = np.repeat((s * self.data.m5)[:, None], 3, axis=1)
            cols.append((s * (1.0 - self.data.m5))[:, None])
        elif self.fresnel == "table":                   # F = sum_k v_k hat_k(cos theta_d)
            a0 = np.zeros((len(s), 3))
            cols.append(s[:, None] * self.data.hats)
        else:                                           # conductor: F(eta, k) fixed here
            a0 = s[:, None] * self.conductor(q)(self.data.cos_d)
        if self.diffuse:
            cols.append(self.data.lambert[:, None])
        return a0, (np.concatenate(cols, axis=1) if cols else np.zeros((len(s), 0)))

    def solve_linear(self, q):
        """Bounded least squares of the linear coefficients per channel, ``(3, J)``:
        ``||A c - b||^2 = ||R c - R^-T A^T b||^2 + const`` with ``A^T A = R^T R``, so the
        bounded solve (BVLS) runs on the small ``J x J`` system."""
        from scipy.optimize import lsq_linear
        a0, A = self.design(q)
        c = np.zeros((3, A.shape[1]))
        if A.shape[1]:
            w2 = self.data.scale**2
            ata = A.T @ (w2 * A)
            ata += (1e-12 * max(float(np.max(np.diag(ata))), 1e-300)) * np.eye(len(ata))
            R = np.linalg.cholesky(ata).T
            rhs = np.linalg.solve(R.T, A.T @ (w2 * (self.data.ref - a0)))
            for ch in range(3):
                c[ch] = lsq_linear(R, rhs[:, ch], bounds=(0.0, 1.0), method="bvls").x
        return a0, A, c

    def residual(self, q) -> np.ndarray:
        """``(model - data) / ||data||`` over pairs and RGB, each block of pairs by its own
        norm (linear coefficients projected out)."""
        a0, A, c = self.solve_linear(q)
        return ((a0 + A @ c.T - self.data.ref) * self.data.scale).ravel()

    def error(self, q) -> float:
        return float(np.sqrt(np.sum(self.residual(q) ** 2)))

    def brdf(self, q):
        """The fitted BRDF of parameters ``q`` (linear coefficients solved)."""
        _, _, c = self.solve_linear(q)
        if self.fresnel == "schlick":
            fresnel = _fresnel.Schlick(c[:, 0])
        elif self.fresnel == "table":
            fresnel = _fresnel.Tabulated(TABLE_NODES, c[:, :len(TABLE_NODES)].T)
        else:
            fresnel = self.conductor(q)
        specular = MicrofacetBRDF(self.distribution(q), fresnel=fresnel, gaf=self.gaf, shadowing=self.shadowing)
        if not self.diffuse:
            return specular
        kd = c[:, -1]
        base = Lambertian(kd)
        lum = np.array([0.2126, 0.7152, 0.0722])
        spec_weight = float(np.mean(fresnel(np.linspace(0.0, 1.0, 9)) @ lum))
        return SumBRDF(specular, base, weights=(max(spec_weight, 1e-3), max(float(kd @ lum), 1e-3)))


def _conductor_start(f0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(eta, k)`` per channel with normal reflectance ``F0`` (Table 2.I at ``theta_d = 0``:
    ``F0 = ((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)``): a dielectric ``eta = (1 + sqrt F0) /
    (1 - sqrt F0)`` below ``F0 = 0.2``, else ``eta = 0.5`` and ``k^2 = (F0 (eta+1)^2 - (eta-1)^2) / (1 - F0)``."""
    f0 = np.clip(np.asarray(f0, dtype=np.float64), 1e-4, 0.98)
    r = np.sqrt(f0)
    eta = np.where(f0 < 0.2, (1.0 + r) / (1.0 - r), 0.5)
    k = np.where(f0 < 0.2, 0.0, np.sqrt(np.maximum(f0 * 2.25 - 0.25, 0.0) / (1.0 - f0)))
    return np.clip(eta, *ETA_BOUNDS), np.clip(k, *K_BOUNDS)


def _start_alpha(start) -> tuple[float, float, float, np.ndarray]:
    """``(alpha_x, alpha_y, rho, mean_slope)`` of a start: a fitted tabulated BRDF (its
    moment conversion to GGX, App. C) or an analytic :class:`MicrofacetBRDF`."""
    brdf = start.to_ggx() if hasattr(start, "to_ggx") else start
    d = getattr(brdf, "distribution", None)
    if d is None:
        raise ValueError(f"fit_analytic: start must be a fit or a MicrofacetBRDF, got {type(start).__name__}")
    return float(d.alpha_x), float(d.alpha_y), float(d.rho), np.asarray(d.mean_slope, dtype=np.float64)


def fit_analytic(brdf, model: str = "ggx", diffuse: bool = False, anisotropic: bool = False,
                 fresnel: str = "table", *, start=None, gaf: str | None = None, shadowing: bool = True,
                 n: int = 32, n_uniform: int = 2**13, max_nfev: int = 200):
    """Least-squares fit of an analytic microfacet BRDF (and a Lambertian base) to ``brdf``.

    Minimizes ``e_grid^2 + e_uniform^2`` with ``e^2 = sum |f_fit cos theta_i - f_ref cos theta_i|^2
    / sum |f_ref cos theta_i|^2`` over RGB and the pairs of
    :func:`microfacet.metrics.measurement_directions` (``n`` per MERL coordinate) and of
    :func:`microfacet.metrics.uniform_directions` (``n_uniform``, seed 1, not the metric's
    seed 0; ``n_uniform = 0``: the grid alone), grazing and unmeasured pairs excluded as in
    :func:`microfacet.metrics.fit_error`, with ``f_fit = F D G / (4 cos theta_i cos theta_o)``
    (Eq. 2.1) ``[+ k_d / pi]`` (Eq. 1.9), by variable projection (module docstring).

    Parameters
    ----------
    brdf : BRDF
        The data (measured or analytic).
    model : {"ggx", "beckmann"}
        NDF family (Eq. 2.11 family of Table 2.II).
    diffuse : bool
        Add a Lambertian base ``k_d / pi``, ``k_d`` in ``[0, 1]`` per channel.
    anisotropic : bool
        Fit ``alpha_x, alpha_y, rho`` (``|rho| <= 0.95``) instead of one ``alpha``.
    fresnel : {"table", "schlick", "conductor"}
        Default ``"table"``. Schlick ``F0`` per channel in ``[0, 1]``; a conductor ``eta + i k`` per channel
        (``eta`` in ``[0.02, 10]``, ``k`` in ``[0, 20]``; ``k = 0`` is a dielectric); or a
        piecewise-linear table of 7 nodes uniform in ``theta_d`` with values in ``[0, 1]``.
    start : FittedBRDF or MicrofacetBRDF, optional
        Start of the roughness: the moment conversion ``start.to_ggx()`` of a tabulated
        fit (App. C), or an analytic BRDF's own roughness; default :func:`fit` of
        ``brdf`` at resolution 90. A coarse roughness scan competes with it.
    gaf, shadowing
        GAF of the fitted model (default: the start's, else ``"smith"``).
    n, n_uniform, max_nfev
        Grid size and number of uniform pairs fitted; evaluation budget of ``least_squares``.

    Returns
    -------
    MicrofacetBRDF, or SumBRDF(MicrofacetBRDF, Lambertian) when ``diffuse``.
    """
    from scipy.optimize import least_squares
    if model not in MODELS:
        raise ValueError(f"model must be one of {tuple(MODELS)}, got {model!r}")
    if fresnel not in FRESNELS:
        raise ValueError(f"fresnel must be one of {FRESNELS}, got {fresnel!r}")
    if start is None:
        from .fitted import fit
        start = fit(brdf, resolution=90, anisotropic=anisotropic)
    ax, ay, rho, mean_slope = _start_alpha(start)
    gaf = gaf if gaf is not None else getattr(start, "gaf_model", "smith")
    data = _Data(brdf, int(n), int(n_uniform))
    problem = _Problem(data, model, bool(diffuse), bool(anisotropic), fresnel, gaf, shadowing, mean_slope)
    lo, hi = problem.bounds()
    # stage 1: isotropic roughness by scan + refinement, with a linear Fresnel (Schlick or table)
    linear = fresnel if fresnel != "conductor" else "schlick"
    iso = _Problem(data, model, bool(diffuse), False, linear, gaf, shadowing, mean_slope)
    candidates = [np.log(np.clip(np.sqrt(ax * ay), *ALPHA_BOUNDS))] + list(np.log(_SCAN))
    best = min(candidates, key=lambda la: iso.error(np.array([la])))
    la = np.log(ALPHA_BOUNDS)
    q_iso = least_squares(iso.residual, [best], bounds=([la[0]], [la[1]]), x_scale=[0.3],
                          max_nfev=max_nfev).x
    # stage 2: the full parameter set from there
    q0 = list(q_iso)
    if anisotropic:
        q0 += [q_iso[0], 0.0]
        if np.isfinite(np.log(ax)) and ax != ay:        # anisotropic start: keep its aspect and rho
            ratio = 0.5 * np.log(ay / ax)
            q0 = [q_iso[0] - ratio, q_iso[0] + ratio, float(np.clip(rho, -0.9, 0.9))]
    if fresnel == "conductor":
        _, _, c = iso.solve_linear(q_iso)
        eta, k = _conductor_start(c[:, 0])
        q0 += list(eta) + list(k)
    q0 = np.clip(np.array(q0, dtype=np.float64), lo, hi)
    if len(q0) > 1 or fresnel != linear:
        x_scale = np.concatenate([[0.3] * problem.n_shape(), [0.3] * (len(q0) - problem.n_shape())])
        q = least_squares(problem.residual, q0, bounds=(lo, hi), x_scale=x_scale, max_nfev=max_nfev).x
    else:
        q = q0
    return problem.brdf(q)
