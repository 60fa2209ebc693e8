"""Least-squares fits of analytic microfacet BRDFs to data (issue 10), and the sum BRDF
that carries an optional coat lobe and Lambertian base.

:func:`fit_analytic` fits ``f = F D G / (4 cos theta_i cos theta_o) + k_d / pi``
(Eq. 2.1 plus Eq. 1.9; with ``coat=True`` plus a second lobe whose Fresnel term is a
7-node table or Schlick's with free ``f0, f90``, linear in its coefficients like ``k_d``)
to a reference BRDF by minimizing
``e_grid^2 + e_uniform^2 + lambda^2 mean((a_fit / a_data - 1)^2)``: the squared relative RMS
errors of ``f_r cos theta_i`` (RGB) of :func:`microfacet.metrics.fit_error` (a
MERL-coordinate grid dense at the specular peak) and :func:`microfacet.metrics.uniform_error`
(pairs uniform in solid angle), grazing and unmeasured pairs excluded as there, plus the
directional-albedo ratios of :func:`microfacet.metrics.albedo_ratios` (views 0/30/60/75 deg,
RGB) weighted by ``lambda = albedo_weight``. The grid alone leaves everything off the peak
free; the uniform pairs pin the diffuse base; the albedo term makes the fit carry the
data's energy, not only its shape.

Variable projection, in node space. For given shape parameters ``q`` (``log alpha_x``,
``log alpha_y``, ``rho``; then ``log alpha_c`` of a coat) the model is
``s(q) F(cos theta_d) [+ s_c(q) F_c(cos theta_d)] + k_d cos theta_i / pi`` with
``s = D G / (4 cos theta_o)`` and ``F_c = sum_b c_b B_b`` (:func:`_coat_basis`); ``F`` and
``F_c`` enter only through their values ``v`` and ``B c`` at the 91 :data:`FRESNEL_NODES`
(1 deg apart in ``theta_d``; piecewise linear in ``cos theta_d``: exact for the tables,
whose 7 nodes are among them, within 1e-3 for Schlick and conductors; the fitted coat is
tabulated there). So the objective is, per channel, a quadratic form in
``x = (v, c, k_d)`` whose matrix and vector are sums over pairs accumulated into
the nodes once per lobe and per ``q`` (the pairs are sorted by Fresnel node, each sum one
``np.add.reduceat``; the blocks of ``F`` and ``F_c`` are tridiagonal): one evaluation of
``s`` (and ``s_c``) on the pairs and the albedo nodes per lobe, and the cross sums of
``s s_c`` per ``q``, nothing else per pair. The linear coefficients
(Schlick ``F0``, table values, the coat's ``c``, ``k_d``, each in ``[0, 1]``) are then
solved exactly on that small system (a box QP, :func:`.extract.box_qp`, where a bound is
active) under the energy constraint: at every view of :data:`ENERGY_VIEWS_DEG` and per
channel, the fit's directional albedo (Eq. 1.8), ``sum_k v_k a_k(theta_o) + sum_b c_b a_cb +
k_d`` (``a_k``: the albedo of the lobe with ``F`` the hat of node ``k``,
:func:`.extract.albedo_rows`; the coat's likewise; the base's is ``k_d``), is at most 1
(less :data:`ENERGY_MARGIN`, the rows' sampling error; :func:`.extract._energy_constrained` when the box solution violates it; no fit reflects
more than it receives); a conductor's ``eta, k`` (per channel, bounded) by a small nonlinear solve on
it. ``q`` is found by a scan of the roughness and a golden-section search
(isotropic; no SciPy optimizer imported), then ``L-BFGS-B`` over ``(log alpha_x,
log alpha_y, rho)`` (anisotropic), started from the moment conversion of the tabulated
fit (thesis App. C); a coat's roughness by a scan at that shape, then ``L-BFGS-B`` over
all from the :data:`COAT_STARTS` best, each on the box-only objective, then the best on
``E`` (:func:`_coat_search`); a conductor is fitted at the table fit's shape and
both refined together.

Examples
--------
>>> sorted(MODELS), FRESNELS, ALPHA_BOUNDS
(['beckmann', 'ggx'], ('conductor', 'schlick', 'table'), (0.001, 2.0))
>>> TABLE_NODES.round(3), len(FRESNEL_NODES)         # cos theta_d, every 15 and every 1 degree
(array([0.   , 0.259, 0.5  , 0.707, 0.866, 0.966, 1.   ]), 91)
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._colour import LUMINANCE
from .. import fresnel as _fresnel
from ..brdf import BRDF, Lambertian, MicrofacetBRDF
from ..protocol import into, into_sample
from ..distributions import GGX, Beckmann
from ..geometry import dot, half_vector
from .extract import albedo_rows, box_qp, distribution_key, energy_constrained, golden_section, kept
from ..metrics import (ALBEDO_VIEWS_DEG, GRAZING_COS, albedo_directions, compared_pairs, measured_mask,
                       measurement_directions, uniform_directions)

__all__ = ["SumBRDF", "fit_analytic", "MODELS", "FRESNELS", "ALPHA_BOUNDS", "TABLE_NODES", "FRESNEL_NODES"]

MODELS = {"ggx": GGX, "beckmann": Beckmann}
FRESNELS = ("conductor", "schlick", "table")
#: Fresnel terms of a coat (:func:`_coat_basis`).
COAT_FRESNELS = ("table", "schlick")
#: Bounds of the fitted roughness ``alpha_x, alpha_y``.
ALPHA_BOUNDS = (1e-3, 2.0)
#: Bounds of the fitted conductor indices ``eta`` and ``k``.
ETA_BOUNDS, K_BOUNDS = (0.02, 10.0), (0.0, 20.0)
_RHO_BOUND = 0.95
#: Nodes of the fitted Fresnel table, uniform in ``theta_d`` (as ``cos theta_d``, increasing).
TABLE_NODES = np.cos(np.radians(np.arange(90, -1, -15)))
#: Nodes through which every Fresnel model enters the objective (module docstring): 1 deg
#: apart in ``theta_d``, as ``cos theta_d``, increasing; :data:`TABLE_NODES` are among them.
FRESNEL_NODES = np.cos(np.radians(np.arange(90, -1, -1)))
#: Starts ``(eta, k)`` of the conductor solve: dielectrics and metals of normal reflectance
#: 0.01-0.95.
_CONDUCTOR_STARTS = np.array([(eta, k) for eta in np.geomspace(0.2, 5.0, 8) for k in (0.0, 0.5, 1.0, 2.0, 4.0, 8.0)])
#: Default weight of the albedo term of :func:`fit_analytic`.
ALBEDO_WEIGHT = 4.0
#: Starts of the joint search of the lobe and coat roughness (the best of the coat scan).
COAT_STARTS = 3
#: ``ftol`` of L-BFGS-B (absolute for objectives below 1): every search's, and the looser
#: one of the coat's searches that only lead a start to its basin (:func:`_coat_search`).
FTOL, BASIN_FTOL = 1e-12, 1e-8
#: Views ``theta_o`` (deg) at which a fit's directional albedo is bounded by 1 (energy
#: constraint of :func:`fit_analytic`; azimuths 0, 45 and 90 deg for an anisotropic fit).
ENERGY_VIEWS_DEG = (0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 84.0, 87.0, 89.0, 89.5)
#: Stratified samples per dimension and strategy of the albedo rows of the energy constraint.
ENERGY_SAMPLES = 48
#: The energy constraint bounds the albedo by ``1 - ENERGY_MARGIN``: the rows' sampling error
#: near 89.5 deg (~2e-3 against 1024^2 samples for GGX of alpha 0.05-1).
ENERGY_MARGIN = 2e-3
#: Roughness values of the initial scan.
_SCAN = np.geomspace(0.004, 1.5, 12)


class SumBRDF(BRDF):
    """The sum of BRDFs, ``f = sum_j f_j`` (e.g. a specular lobe over a Lambertian base).

    ``sample`` is mixture sampling: lobe ``j`` is chosen with probability ``w_j`` (the
    first uniform, rescaled, drives the chosen lobe), so ``pdf = sum_j w_j pdf_j`` and
    the weight is the exact ``eval_cos / pdf`` of the sum (multi-sample MIS, balance
    heuristic). ``weights`` default to equal; they change the variance, never the mean.

    Parameters
    ----------
    *brdfs : BRDF
        The terms (any objects of the BRDF protocol).
    weights : sequence of float, optional
        Probabilities of sampling each term (normalized; default equal).

    Examples
    --------
    >>> import numpy as np, microfacet as mf
    >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.5))
    >>> n = np.array([0.0, 0.0, 1.0])
    >>> brdf.eval(n, n).round(4)           # 0.0354 (the lobe) + 0.5 / pi
    array([0.1945, 0.1945, 0.1945])
    >>> wi, weight, pdf = brdf.sample(np.array([0.3, 0.6]), n)
    >>> bool(np.allclose(weight * pdf, brdf.eval_cos(wi, n)))     # weight = f cos / pdf
    True
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

    def eval_cos(self, wi, wo, out=None) -> np.ndarray:
        """``sum_j f_j cos theta_i``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Output array.

        Returns
        -------
        (..., 3) ndarray
            The sum of the terms' ``f_r cos theta_i``.
        """
        return into(out, self._sum(wi, wo, True), (wi, wo))

    def eval(self, wi, wo, out=None) -> np.ndarray:
        """``sum_j f_j``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Output array.

        Returns
        -------
        (..., 3) ndarray
            The sum of the terms' ``f_r``.
        """
        return into(out, self._sum(wi, wo, False), (wi, wo))

    def _sum(self, wi, wo, cos: bool) -> np.ndarray:
        """The terms' ``eval_cos`` (``cos``) or ``eval``, summed (a subclass may evaluate them together)."""
        return sum(b.eval_cos(wi, wo) if cos else b.eval(wi, wo) for b in self.brdfs)

    def terms_cos(self, wi, wo) -> list:
        """Each term's ``f_j cos theta_i``, in the order of ``brdfs`` (a subclass may
        evaluate them together).

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.

        Returns
        -------
        list of (..., 3) ndarray
            The terms' ``eval_cos``; their sum is :meth:`eval_cos`.

        Examples
        --------
        >>> import numpy as np, microfacet as mf
        >>> brdf = SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.3)), mf.Lambertian(0.5))
        >>> n = np.array([0.0, 0.0, 1.0])
        >>> [v.round(4) for v in brdf.terms_cos(n, n)]
        [array([0.8842, 0.8842, 0.8842]), array([0.1592, 0.1592, 0.1592])]
        """
        return [b.eval_cos(wi, wo) for b in self.brdfs]

    def pdf(self, wi, wo, out=None) -> np.ndarray:
        """Mixture density ``sum_j w_j pdf_j``.

        Parameters
        ----------
        wi, wo : (..., 3) array_like
            Unit light and view directions in the local frame.
        out : ndarray, optional
            Output array.

        Returns
        -------
        (...) ndarray
            The mixture density ``sum_j w_j pdf_j``.
        """
        return into(out, sum(w * b.pdf(wi, wo) for w, b in zip(self.weights, self.brdfs, strict=True) if w > 0),
                     (wi, wo))

    def sample(self, u, wo, out=None):
        """Choose lobe ``j`` with probability ``w_j`` by ``u[..., 0]``, sample it with the
        rescaled uniform; return ``(wi, eval_cos / pdf, pdf)`` of the mixture.

        Parameters
        ----------
        u : (..., 2) array_like
            Uniform numbers in ``[0, 1]`` (the first picks the term, then is rescaled).
        wo : (..., 3) array_like
            Unit view directions in the local frame.
        out : tuple of ndarray, optional
            Output arrays ``(wi, weight, pdf)``.

        Returns
        -------
        wi : (..., 3) ndarray
            Sampled light directions.
        weight : (..., 3) ndarray
            ``eval_cos / pdf`` of the sum.
        pdf : (...) ndarray
            The mixture density.
        """
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
        return into_sample(out, (wi, weight, np.where(ok, pdf, 0.0)), (u, wo))


# ------------------------------------------------------------------ least squares
def _node_weights(cos_d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Left node ``j`` and weight ``t`` of ``cos_d`` in :data:`FRESNEL_NODES`: the hat
    functions of nodes ``j`` and ``j + 1`` are ``1 - t`` and ``t`` there."""
    nodes = FRESNEL_NODES
    j = np.clip(np.searchsorted(nodes, cos_d, side="right") - 1, 0, len(nodes) - 2)
    t = np.clip((cos_d - nodes[j]) / (nodes[j + 1] - nodes[j]), 0.0, 1.0)
    return j, t


class _Data:
    """The reference on the compared pairs (the grid of :func:`~microfacet.metrics.fit_error`
    and uniformly distributed pairs, each block weighted by its own norm) and on the nodes
    of a coarse :func:`~microfacet.metrics.directional_albedo` quadrature, with every
    model-independent sum of the objective (module docstring)."""

    def __init__(self, reference, n: int, n_uniform: int, albedo_grid: tuple[int, int]):
        blocks = [measurement_directions(n)] + ([uniform_directions(n_uniform, seed=1)] if n_uniform else [])
        wis, wos, refs, weights = [], [], [], []
        for directions in blocks:
            pairs = compared_pairs(reference, directions)
            wi, wo = pairs[:2]
            w = pairs[2] if len(pairs) == 3 else np.ones(len(wi))
            ref = np.asarray(reference.eval_cos(wi, wo), dtype=np.float64)
            finite = np.all(np.isfinite(ref), axis=-1)
            wi, wo, ref, w = wi[finite], wo[finite], ref[finite], w[finite]
            norm2 = float(np.sum(w[:, None] * ref**2))
            if not norm2 > 0:
                raise ValueError("fit_analytic: the reference BRDF is zero on the compared directions")
            wis.append(wi), wos.append(wo), refs.append(ref), weights.append(w / norm2)
        self.m = sum(len(w) for w in weights)
        self.w = np.concatenate(weights)                        # each block: its relative MS
        ref = np.concatenate(refs)
        # albedo quadrature (views x nodes), restricted as albedo_ratios restricts it
        wi_a, wo_a, w_a, view = albedo_directions(ALBEDO_VIEWS_DEG, GRAZING_COS, *albedo_grid)
        keep = measured_mask(reference, wi_a, wo_a)
        wi_a, wo_a, w_a, view = wi_a[keep], wo_a[keep], w_a[keep], view[keep]
        f = np.asarray(reference.eval_cos(wi_a, wo_a), dtype=np.float64)
        f = w_a[:, None] * np.where(np.isfinite(f), f, 0.0)
        n_views = len(ALBEDO_VIEWS_DEG)
        self.albedo = np.stack([np.bincount(view, f[:, c], minlength=n_views) for c in range(3)], axis=-1)
        # every direction s(q) is evaluated on, and its Fresnel nodes
        self.wi = np.concatenate(wis + [wi_a])
        self.wo = np.concatenate(wos + [wo_a])
        oh = dot(self.wo, half_vector(self.wi, self.wo))
        j, t = _node_weights(oh)
        m, n_nodes = self.m, len(FRESNEL_NODES)
        # pairs sorted by left node j (albedo pairs by view, then j): every sum of the
        # quadratic form is then a sum over runs of rows (_Groups)
        key_p, key_a = j[:m], view * n_nodes + j[m:]
        order_p, order_a = np.argsort(key_p, kind="stable"), np.argsort(key_a, kind="stable")
        order = np.concatenate([order_p, m + order_a])
        self.wi, self.wo, oh, t = self.wi[order], self.wo[order], oh[order], t[order]
        self.w, ref, view, w_a = self.w[order_p], ref[order_p], view[order_a], w_a[order_a]
        self.pairs = _Groups(key_p[order_p], n_nodes)
        self.albedo_nodes = _Groups(key_a[order_a], n_views * n_nodes)
        hats = np.stack([1.0 - t, t], axis=-1)                      # hats of nodes j, j + 1
        self.w_hat = self.w[:, None] * hats[:m]                               # w hat
        self.w_hat2 = self.w[:, None] * np.stack([hats[:m, 0]**2, hats[:m, 1]**2, hats[:m, 0] * hats[:m, 1]], -1)
        self.w_hat_ref = (self.w_hat[:, :, None] * ref[:, None, :]).reshape(m, 6)     # w hat f_ref
        self.w_albedo_hat = w_a[:, None] * hats[m:]
        self.view, self.w_albedo = view, w_a
        self.lambert = np.clip(self.wi[:, 2], 0.0, None) / np.pi            # k_d cos theta_i / pi
        self.wref = self.w[:, None] * ref                                    # w f_ref
        self.ref2 = np.sum(self.wref * ref, axis=0)         # sum w f_ref^2 per channel


class _Groups:
    """Row sums by a sorted integer key in ``[0, size)`` (``np.bincount`` of many columns
    at once): one ``np.add.reduceat`` over the runs of equal keys."""

    def __init__(self, sorted_key: np.ndarray, size: int):
        self.keys, self.starts = np.unique(sorted_key, return_index=True)
        self.size = int(size)

    def sum(self, values: np.ndarray) -> np.ndarray:
        """``(size, ...)``: the sums of ``values`` (rows as the keys) per key."""
        out = np.zeros((self.size,) + values.shape[1:])
        if len(self.keys):
            out[self.keys] = np.add.reduceat(values, self.starts, axis=0)
        return out


class _LobeSums(NamedTuple):
    """A lobe's terms of :meth:`_Problem.quadratic`: ``s = D G / (4 cos theta_o)`` on the
    pairs ``(m,)`` (0 where invalid); per left node ``j`` the sums ``sum w s^2`` of the hat
    products ``hat_j^2, hat_{j+1}^2, hat_j hat_{j+1}`` ``(n, 3)``; ``sum w s hat_k f_ref``
    ``(3, n)``; the albedo rows ``sum w_a s hat_k`` per view ``(V, n)``; with a base,
    ``sum w s hat_k L`` ``(n,)`` (else None)."""
    s: np.ndarray
    s2: np.ndarray
    g: np.ndarray
    rows: np.ndarray
    lambert: np.ndarray | None


def _tridiagonal(s2: np.ndarray) -> np.ndarray:
    """``(n, n)``: ``sum w s s' hat_j hat_k`` from its sums per left node ``(n, 3)``
    (:class:`_LobeSums`): each pair touches nodes ``j, j + 1`` only."""
    return np.diag(_spread(s2[:, :2])) + np.diag(s2[:-1, 2], 1) + np.diag(s2[:-1, 2], -1)


def _spread(sums: np.ndarray) -> np.ndarray:
    """Node values from sums per left node ``(size, 2, ...)`` of the two hats: the left
    hat's at ``j``, the right hat's at ``j + 1`` (never past a view's last node)."""
    out = sums[:, 0].copy()
    out[1:] += sums[:-1, 1]
    return out


def _table_map() -> np.ndarray:
    """``(91, 7)``: Fresnel-node values of the piecewise-linear table of :data:`TABLE_NODES`."""
    return _coat_basis("table", FRESNEL_NODES)


def _coat_basis(kind: str, cos_d) -> np.ndarray:
    """``(P, b)``: the basis of a coat's Fresnel term at ``cos theta_d``, ``F_c = basis @ c``
    with ``c`` in ``[0, 1]``: the hats of the piecewise-linear table of :data:`TABLE_NODES`
    (``"table"``, ``c`` its values) or Schlick's ``1 - m^5, m^5``, ``m = 1 - cos theta_d``
    (``"schlick"``, ``c = (f0, f90)``). Both are partitions of unity: ``F_c <= max c``."""
    if kind == "table":
        return np.stack([np.interp(cos_d, TABLE_NODES, e) for e in np.eye(len(TABLE_NODES))], axis=-1)
    m5 = (1.0 - np.asarray(cos_d, dtype=np.float64)) ** 5
    return np.stack([1.0 - m5, m5], axis=-1)


#: A fitted Fresnel table's total variation may be at most this times its range (max - min).
TABLE_TV_LIMIT = 2.0


def _smooth_table(values: np.ndarray) -> bool:
    """Whether a table's total variation is at most :data:`TABLE_TV_LIMIT` times its range."""
    tv = float(np.sum(np.abs(np.diff(values))))
    return tv <= TABLE_TV_LIMIT * float(np.ptp(values)) + 1e-12


class _Problem:
    """One model on the data: the projected objective ``E(q)`` (module docstring). ``q`` is
    ``log alpha`` (or ``log alpha_x, log alpha_y, rho``), then ``log alpha_c`` of the coat."""

    def __init__(self, data: _Data, model, diffuse, anisotropic, fresnel, gaf, shadowing, mean_slope,
                 albedo_weight: float, coat: bool = False, coat_fresnel: str = "table"):
        self.data = data
        self.family, self.diffuse, self.anisotropic, self.fresnel = MODELS[model], diffuse, anisotropic, fresnel
        self.gaf, self.shadowing, self.mean_slope = gaf, shadowing, mean_slope
        self.albedo_weight = float(albedo_weight)
        self.coat = bool(coat)
        self.coat_fresnel = coat_fresnel
        self._last = (None, None)
        self._quadratics, self._lobes, self._lobe_rows = {}, {}, {}
        self._coat_nodes = _coat_basis(coat_fresnel, FRESNEL_NODES) if self.coat else None
        self._base = self._base_sums() if self.diffuse else None

    def distribution(self, q):
        if self.anisotropic:
            return self.family(alpha_x=np.exp(q[0]), alpha_y=np.exp(q[1]), rho=q[2], mean_slope=self.mean_slope)
        return self.family(alpha=np.exp(q[0]), mean_slope=self.mean_slope)

    def coat_distribution(self, q):
        """The coat's isotropic NDF, ``alpha_c = exp(q[-1])``, same family."""
        return self.family(alpha=np.exp(q[-1]))

    def bounds(self):
        la = np.log(ALPHA_BOUNDS)
        lo, hi = ([la[0], la[0], -_RHO_BOUND], [la[1], la[1], _RHO_BOUND]) if self.anisotropic else ([la[0]], [la[1]])
        if self.coat:
            lo, hi = lo + [la[0]], hi + [la[1]]
        return np.array(lo), np.array(hi)

    def _lobe(self, distribution) -> _LobeSums:
        """A lobe's terms of :meth:`quadratic` (:class:`_LobeSums`), kept per lobe
        (:func:`.extract._kept`, 16 of each kind: at least the scan's; a coat fit's finite
        differences move one lobe at a time)."""
        def make():
            d, n = self.data, len(FRESNEL_NODES)
            # unit directions by construction (metrics' direction sets): no check per lobe
            s = MicrofacetBRDF(distribution, gaf=self.gaf, shadowing=self.shadowing)._projected_unit(d.wi, d.wo)[1]
            s = np.where(np.isfinite(s), s, 0.0)
            sp, sa = s[:d.m], s[d.m:]
            return _LobeSums(sp, d.pairs.sum(sp[:, None] ** 2 * d.w_hat2),
                             _spread(d.pairs.sum(sp[:, None] * d.w_hat_ref).reshape(n, 2, 3)).T,
                             _spread(d.albedo_nodes.sum(sa[:, None] * d.w_albedo_hat)).reshape(-1, n),
                             _spread(d.pairs.sum((sp * d.lambert[:d.m])[:, None] * d.w_hat)) if self.diffuse else None)
        return kept(self._lobes, distribution_key(distribution), make)

    def quadratic(self, q):
        """``H (3, X, X)``, ``g (3, X)``, ``k (3,)`` with ``E_c(x) = x^T H_c x - 2 g_c^T x + k_c``,
        ``x = (v, c, k_d)`` (``v``: Fresnel values at :data:`FRESNEL_NODES`; the coat's
        coefficients ``c`` only with a coat, ``k_d`` only with a diffuse base): the pairs'
        ``sum w (s F + s_c F_c + k_d L - f_ref)^2`` plus the albedo term
        ``lambda^2 / (3 V) sum_{views} (a_fit / a_data - 1)^2``. The coat enters as the lobe,
        through its values at the nodes, ``F_c = B c`` (``B``: :func:`_coat_basis` at
        :data:`FRESNEL_NODES`; exact for the table, whose nodes are among them): its blocks
        are those of a second lobe mapped by ``B``, the cross block
        ``sum w s s_c hat_j hat_k`` is tridiagonal like the lobe's own."""
        d = self.data
        lobe = self._lobe(self.distribution(q))
        G, g, albedo_rows = _tridiagonal(lobe.s2), lobe.g, lobe.rows
        k = d.ref2.copy()
        base = [lobe.lambert]
        if self.coat:
            coat, B = self._lobe(self.coat_distribution(q)), self._coat_nodes
            cross = _tridiagonal(d.pairs.sum((lobe.s * coat.s)[:, None] * d.w_hat2)) @ B
            G = np.block([[G, cross], [cross.T, B.T @ _tridiagonal(coat.s2) @ B]])
            g = np.concatenate([g, coat.g @ B], axis=1)
            albedo_rows = np.concatenate([albedo_rows, coat.rows @ B], axis=1)
            base.append(coat.lambert @ B if self.diffuse else None)
        if self.diffuse:
            LL, gL, rows_L = self._base
            GL = np.concatenate(base)[:, None]
            G = np.block([[G, GL], [GL.T, LL]])
            g = np.concatenate([g, gL], axis=1)
            albedo_rows = np.concatenate([albedo_rows, rows_L], axis=1)
        H = np.repeat(G[None], 3, axis=0)
        if self.albedo_weight > 0:
            c2 = self.albedo_weight**2 / (3 * len(ALBEDO_VIEWS_DEG))
            with np.errstate(divide="ignore"):
                inv = np.where(d.albedo > 0, 1.0 / d.albedo, 0.0).T                    # (3, V)
            scaled = albedo_rows[None] * inv[:, :, None]                               # (3, V, X)
            H = H + c2 * np.einsum("cvx,cvy->cxy", scaled, scaled)
            g = g + c2 * np.einsum("cvx,cv->cx", scaled, (inv > 0).astype(float))
            k = k + c2 * np.sum(inv > 0, axis=1)
        return H, g, k

    def _base_sums(self):
        """The base's terms of :meth:`quadratic`, which depend on no parameter: ``sum w L^2``
        ``(1, 1)``, ``sum w L f_ref`` ``(3, 1)`` and its albedo rows ``(V, 1)``
        (``L = cos theta_i / pi``)."""
        d = self.data
        L = d.lambert[:d.m, None]
        # einsum, not BLAS: a threaded GEMM over the pairs costs more than it saves here
        return (np.einsum("me,mf->ef", L, d.w[:, None] * L), np.einsum("me,mc->ce", L, d.wref),
                np.bincount(d.view, d.w_albedo * d.lambert[d.m:], minlength=len(ALBEDO_VIEWS_DEG))[:, None])

    @property
    def n_coat(self) -> int:
        """Number of the coat's Fresnel coefficients (:func:`_coat_basis`; 0 without a coat)."""
        return self._coat_nodes.shape[1] if self.coat else 0

    @property
    def n_extra(self) -> int:
        """Number of linear coefficients after the Fresnel term (the coat's; ``k_d``)."""
        return self.n_coat + int(self.diffuse)

    def _linear_map(self):
        """``(Q, x0)``: ``x = Q y + x0`` for the linear Fresnel models, ``y`` in ``[0, 1]``."""
        n = len(FRESNEL_NODES)
        if self.fresnel == "table":
            Q, x0 = _table_map(), np.zeros(n)
        else:                                          # Schlick: F = F0 (1 - m^5) + m^5
            m5 = (1.0 - FRESNEL_NODES) ** 5
            Q, x0 = (1.0 - m5)[:, None], m5
        e = self.n_extra
        Q = np.block([[Q, np.zeros((n, e))], [np.zeros((e, Q.shape[1])), np.eye(e)]])
        return Q, np.append(x0, np.zeros(e))

    def solve(self, q):
        """``(E, coefficients)``: the objective at ``q`` with the linear (or conductor)
        parameters solved per channel under the energy constraint (module docstring);
        coefficients ``(3, J)``."""
        if self._last[0] is not None and np.array_equal(self._last[0], q):
            return self._last[1]
        H, g, k = self._quadratic_kept(q)
        rows = _Lazy(lambda: self.energy_rows(q))
        out = (self._solve_conductor(H, g, k, rows) if self.fresnel == "conductor"
               else self._solve_linear(H, g, k, rows))
        self._last = (np.array(q, dtype=np.float64), out)
        return out

    def _quadratic_kept(self, q):
        """:meth:`quadratic`, kept per ``q`` (:func:`.extract._kept`; a :meth:`lower_bound` is
        followed by the :meth:`solve` of the same ``q``)."""
        return kept(self._quadratics, np.asarray(q, dtype=np.float64).tobytes(), lambda: self.quadratic(q))

    def lower_bound(self, q) -> float:
        """A lower bound of :meth:`error` (linear Fresnel models): ``E(q)`` with the
        coefficients in their box but without the energy constraint, whose solution is
        feasible for the box alone (no energy rows built). Equal to ``E(q)`` where the
        constraint is inactive. A conductor has none (``-inf``)."""
        if self.fresnel == "conductor":
            return -np.inf
        q = np.atleast_1d(np.asarray(q, dtype=np.float64))
        return self._solve_linear(*self._quadratic_kept(q), None)[0]

    def energy_rows(self, q) -> np.ndarray:
        """``(V, X)``: the fit's directional albedo (Eq. 1.8) per unit linear unknown
        ``x = (v, c, k_d)`` at the views of :data:`ENERGY_VIEWS_DEG`: the lobe's
        albedo with ``F`` the hat of each Fresnel node (:func:`.extract.albedo_rows`, whose
        nodes are :data:`FRESNEL_NODES` reversed), the coat's with ``F`` each function of
        :func:`_coat_basis`, and 1 for ``k_d`` (a Lambertian's albedo is
        ``k_d``). The fit's albedo at view ``v`` is ``rows[v] @ x``. Each lobe's rows are
        kept per lobe (:func:`.extract._kept`; a coat fit moves one lobe at a time)."""
        t = np.radians(ENERGY_VIEWS_DEG)
        phis = np.radians([0.0, 45.0, 90.0]) if self.anisotropic else np.zeros(1)
        views = np.concatenate([np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1)
                                for p in phis])
        n = len(FRESNEL_NODES)

        def lobe(distribution):
            ideal = MicrofacetBRDF(distribution, gaf=self.gaf, shadowing=self.shadowing)
            return kept(self._lobe_rows, distribution_key(distribution),
                         lambda: albedo_rows(None, ideal, n, views, ENERGY_SAMPLES)[0][:, n - 1::-1])
        cols = [lobe(self.distribution(q))]
        if self.coat:
            cols.append(lobe(self.coat_distribution(q)) @ self._coat_nodes)
        if self.diffuse:
            cols.append(np.ones((len(views), 1)))
        return np.concatenate(cols, axis=1)

    def _solve_linear(self, H, g, k, rows):
        """Per channel, ``y`` in ``[0, 1]`` (``x = Q y + x0``, :meth:`_linear_map`) minimizing
        ``E_c`` under ``rows x <= 1 - ENERGY_MARGIN`` (:meth:`energy_rows`; computed only when
        :meth:`_may_gain`; ``rows=None``: the box alone). A Fresnel table whose total
        variation exceeds :data:`TABLE_TV_LIMIT` times its range is solved again with a
        second-difference penalty ``lam |D2 t|^2``, ``lam`` growing tenfold until it is not
        (a straight table, the limit, has the variation of its range)."""
        Q, x0 = self._linear_map()
        total, coef = 0.0, np.zeros((3, Q.shape[1]))
        tables = self._table_blocks()
        for c in range(3):
            Hy = Q.T @ H[c] @ Q
            Hy += (1e-12 * max(float(np.max(np.diag(Hy))), 1e-300)) * np.eye(len(Hy))
            hx0 = H[c] @ x0
            gy = Q.T @ (g[c] - hx0)
            ky = k[c] - 2.0 * g[c] @ x0 + x0 @ hx0
            y = self._solve_channel(Hy, gy, Q, x0, rows, c)
            scale = float(np.mean(np.diag(Hy)))
            for lam in 10.0 ** np.arange(-6, 7):
                if all(_smooth_table(y[b]) for b in tables):
                    break
                penalty = np.zeros_like(Hy)
                for b in tables:
                    d2 = np.diff(np.eye(b.stop - b.start), 2, axis=0)
                    penalty[b, b] = lam * scale * d2.T @ d2
                y = self._solve_channel(Hy + penalty, gy, Q, x0, rows, c)
            total += float(y @ Hy @ y - 2.0 * gy @ y + ky)
            coef[c] = y
        return max(total, 0.0), coef

    def _table_blocks(self) -> list:
        """Slices of ``y`` holding Fresnel tables (the lobe's, the coat's)."""
        n = len(TABLE_NODES)
        blocks = [slice(0, n)] if self.fresnel == "table" else []
        if self.coat and self.coat_fresnel == "table":
            start = n if self.fresnel == "table" else 1
            blocks.append(slice(start, start + n))
        return blocks

    def _solve_channel(self, Hy, gy, Q, x0, rows, c):
        """``y`` of one channel: the box QP, then the energy constraint where it may bind."""
        lo, hi = np.zeros(len(gy)), np.ones(len(gy))
        y = np.linalg.solve(Hy, gy)
        if np.any(y < 0.0) or np.any(y > 1.0):
            y = box_qp(Hy, gy, lo, hi)
        if rows is not None and self._may_gain(Q @ y + x0):
            r = rows() @ Q
            limit = 1.0 - ENERGY_MARGIN - rows() @ x0
            y = energy_constrained(Hy, gy, y, (lo, hi), (r, np.repeat(limit[:, None], 3, 1)), c, True)
        return y

    def _may_gain(self, x) -> bool:
        """False when ``x = (v, c, k_d)`` surely reflects at most ``1 - ENERGY_MARGIN``
        (``max v + max c + k_d`` does): each lobe's
        albedo is at most its largest Fresnel value (a lobe with ``F = 1`` loses energy,
        :func:`~microfacet.metrics.white_furnace`)."""
        n = len(FRESNEL_NODES)
        coat = np.max(x[n:n + self.n_coat]) if self.coat else 0.0
        bound = np.max(x[:n]) + coat + (x[-1] if self.diffuse else 0.0)
        return bool(bound > 1.0 - ENERGY_MARGIN)

    def _solve_conductor(self, H, g, k, rows):
        """Per channel, ``eta, k`` (and the coat's ``c``, ``k_d``) minimizing ``E_c`` through
        the conductor's values at the nodes (Table 2.I): the best of
        :data:`_CONDUCTOR_STARTS` (the other coefficients solved for each, clipped to
        ``[0, 1]``), refined by bounded least squares; then, if the energy constraint
        ``rows x <= 1`` (:meth:`energy_rows`) is violated, the other coefficients are
        solved again under it at that ``eta, k``."""
        from scipy.optimize import least_squares
        e = self.n_extra
        lo, hi = np.array([ETA_BOUNDS[0], K_BOUNDS[0]] + [0.0] * e), np.array([ETA_BOUNDS[1], K_BOUNDS[1]] + [1.0] * e)
        n = len(FRESNEL_NODES)
        v = _fresnel.conductor_reflectance(FRESNEL_NODES[None, :], _CONDUCTOR_STARTS[:, :1], _CONDUCTOR_STARTS[:, 1:])
        total, params = 0.0, np.zeros((3, len(lo)))
        for c in range(3):
            x = np.concatenate([v, np.zeros((len(v), e))], axis=1)
            if e:                                       # the best other coefficients of each start
                Hee, Hev, ge = H[c][n:, n:], H[c][n:, :n], g[c][n:]
                Hee = Hee + 1e-12 * max(float(np.max(np.diag(Hee))), 1e-300) * np.eye(e)
                x[:, n:] = np.clip(np.linalg.solve(Hee, ge[:, None] - Hev @ v.T).T, 0.0, 1.0)
            best = int(np.argmin(np.einsum("sx,xy,sy->s", x, H[c], x) - 2.0 * x @ g[c]))
            Hc = H[c] + (1e-12 * max(float(np.max(np.diag(H[c]))), 1e-300)) * np.eye(len(H[c]))
            R = np.linalg.cholesky(Hc).T
            z = np.linalg.solve(R.T, g[c])

            def residual(p, R=R, z=z):
                return R @ np.append(_fresnel.conductor_reflectance(FRESNEL_NODES, p[0], p[1]), p[2:]) - z
            p0 = np.clip(np.append(_CONDUCTOR_STARTS[best], x[best, n:]), lo, hi)
            p = least_squares(residual, p0, bounds=(lo, hi), x_scale=[0.3, 0.3] + [0.1] * e,
                              xtol=1e-8, ftol=1e-10, max_nfev=40).x
            x = np.append(_fresnel.conductor_reflectance(FRESNEL_NODES, p[0], p[1]), p[2:])
            if e and self._may_gain(x):
                Hee = Hc[n:, n:]
                ge = g[c][n:] - Hc[n:, :n] @ x[:n]
                limit = 1.0 - ENERGY_MARGIN - rows()[:, :n] @ x[:n]
                p[2:] = energy_constrained(Hee, ge, p[2:], (lo[2:], hi[2:]),
                                            (rows()[:, n:], np.repeat(limit[:, None], 3, 1)), c, True)
                x[n:] = p[2:]
            total += float(x @ Hc @ x - 2.0 * g[c] @ x + k[c])
            params[c] = p
        return max(total, 0.0), params

    def error(self, q) -> float:
        """The objective ``E(q)`` (module docstring)."""
        return self.solve(np.atleast_1d(np.asarray(q, dtype=np.float64)))[0]

    def brdf(self, q):
        """The fitted BRDF of parameters ``q`` (linear coefficients solved)."""
        _, c = self.solve(np.asarray(q, dtype=np.float64))
        if self.fresnel == "schlick":
            fresnel = _fresnel.Schlick(np.clip(c[:, 0], 0.0, 1.0))
        elif self.fresnel == "table":
            fresnel = _fresnel.Tabulated(TABLE_NODES, np.clip(c[:, :len(TABLE_NODES)].T, 0.0, 1.0))
        else:
            fresnel = _fresnel.Conductor(eta=c[:, 0], k=c[:, 1])
        lobes = [MicrofacetBRDF(self.distribution(q), fresnel=fresnel, gaf=self.gaf, shadowing=self.shadowing)]
        if self.coat:
            i = c.shape[1] - self.n_extra                          # coefficients: (F..., coat...[, k_d])
            values = self._coat_nodes @ np.clip(c[:, i:i + self.n_coat].T, 0.0, 1.0)
            lobes.append(MicrofacetBRDF(self.coat_distribution(q), fresnel=_fresnel.Tabulated(FRESNEL_NODES, values),
                                        gaf=self.gaf, shadowing=self.shadowing))
        if self.diffuse:
            lobes.append(Lambertian(np.clip(c[:, -1], 0.0, 1.0)))
        if len(lobes) == 1:
            return lobes[0]
        return SumBRDF(*lobes, weights=[max(_albedo_estimate(b), 1e-3) for b in lobes])


class _Lazy:
    """A value computed on first call, then kept."""

    def __init__(self, make):
        self.make, self.value = make, None

    def __call__(self):
        if self.value is None:
            self.value = self.make()
        return self.value


def coat_fresnel(f0, f90) -> _fresnel.Tabulated:
    """The coat's Fresnel term, Schlick's approximation with a free grazing value,
    ``F = f0 (1 - (1 - cos theta_d)^5) + f90 (1 - cos theta_d)^5`` (RGB ``f0``, ``f90`` in
    ``[0, 1]``; ``f90 = 1``: Schlick, Eq. 2.6), tabulated at :data:`FRESNEL_NODES`
    (piecewise linear: within 1e-3 of the formula the fit uses)."""
    basis = _coat_basis("schlick", FRESNEL_NODES)[..., None]
    return _fresnel.Tabulated(FRESNEL_NODES, f0 * basis[:, 0] + f90 * basis[:, 1])


def _albedo_estimate(brdf) -> float:
    """Luminance of a lobe's mean Fresnel term over ``cos theta_d`` (a microfacet lobe) or
    of ``k_d`` (a Lambertian): the mixture weights of the sum BRDF's sampling."""
    if isinstance(brdf, Lambertian):
        return float(brdf.reflectance @ LUMINANCE)
    return float(np.mean(brdf.fresnel(np.linspace(0.0, 1.0, 9)) @ LUMINANCE))


def _start_alpha(start) -> tuple[float, float, float, np.ndarray]:
    """``(alpha_x, alpha_y, rho, mean_slope)`` of a start: a fitted tabulated BRDF (its
    moment conversion to GGX, App. C) or an analytic :class:`MicrofacetBRDF`."""
    brdf = start.to_ggx(resolve_fresnel=False) if hasattr(start, "to_ggx") else start
    d = getattr(brdf, "distribution", None)
    if d is None:
        raise ValueError(f"fit_analytic: start must be a fit or a MicrofacetBRDF, got {type(start).__name__}")
    return float(d.alpha_x), float(d.alpha_y), float(d.rho), np.asarray(d.mean_slope, dtype=np.float64)


_DATA_CACHE: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _data(brdf, n: int, n_uniform: int, albedo_grid: tuple[int, int]) -> _Data:
    """The :class:`_Data` of ``brdf``, kept (weakly, by object) so that fits of several
    models to one material evaluate the data once."""
    key = (n, n_uniform, albedo_grid)
    try:
        per_brdf = _DATA_CACHE.setdefault(brdf, {})
    except TypeError:                                   # not weak-referenceable: no cache
        return _Data(brdf, n, n_uniform, albedo_grid)
    if key not in per_brdf:
        per_brdf[key] = _Data(brdf, n, n_uniform, albedo_grid)
    return per_brdf[key]


def _least(problem: _Problem, candidates, k: int) -> tuple[np.ndarray, np.ndarray]:
    """``(order, errors)``: the indices of the ``k`` candidates of least ``problem.error``,
    least first (ties in the given order, as ``sorted``), and the errors, evaluated in the
    order of the candidates' :meth:`_Problem.lower_bound` until it exceeds the ``k``-th
    least error found: the others (``inf``) cannot be among them, and their energy rows
    are never built."""
    bounds = [problem.lower_bound(c) for c in candidates]
    errors = np.full(len(candidates), np.inf)
    for i in np.argsort(bounds, kind="stable"):
        if bounds[i] > np.sort(errors)[k - 1]:
            break
        errors[i] = problem.error(candidates[i])
    return np.argsort(errors, kind="stable")[:k], errors


def _minimize_log_alpha(problem: _Problem, candidates, lo: float, hi: float) -> float:
    """``log alpha`` minimizing the isotropic ``problem``: the best of ``candidates``
    (:func:`_least`), then a golden-section search between its neighbours, which also
    evaluates the error only where the lower bound does not decide."""
    grid = np.unique(np.clip(np.asarray(candidates, dtype=np.float64), lo, hi))
    (b,), errors = _least(problem, grid, 1)
    left, right = grid[max(b - 1, 0)], grid[min(b + 1, len(grid) - 1)]
    if right - left <= 0:
        return float(grid[b])
    x, fx = golden_section(problem.error, left, right, xatol=2e-3, lower=problem.lower_bound)
    return float(x) if fx <= errors[b] else float(grid[b])


def _minimize(problem: _Problem, q0, max_nfev: int, relaxed: bool = False) -> np.ndarray:
    """``q`` minimizing ``problem`` from ``q0``: Brent around ``q0`` (one parameter) or
    bounded L-BFGS-B (``ftol`` :data:`FTOL`). ``relaxed``: L-BFGS-B on the box-only
    objective :meth:`_Problem.lower_bound` (no energy rows) to :data:`BASIN_FTOL`."""
    from scipy.optimize import minimize
    from threadpoolctl import threadpool_limits
    lo, hi = problem.bounds()
    q0 = np.clip(np.asarray(q0, dtype=np.float64), lo, hi)
    if len(q0) == 1:
        return np.array([_minimize_log_alpha(problem, q0[0] + np.linspace(-0.3, 0.3, 5), lo[0], hi[0])])
    f = problem.lower_bound if relaxed else problem.error
    # one BLAS thread: on 2-4 parameters SciPy's L-BFGS-B woke OpenBLAS's threads, which
    # then spun (a coat fit's CPU time doubled)
    with threadpool_limits(limits=1, user_api="blas"):
        r = minimize(f, q0, method="L-BFGS-B", bounds=list(zip(lo, hi, strict=True)),
                     options={"maxfun": max_nfev, "ftol": BASIN_FTOL if relaxed else FTOL, "gtol": 1e-9})
    return r.x if r.fun <= f(q0) else q0


def _coat_search(problem: _Problem, scan, max_nfev: int) -> np.ndarray:
    """``q`` (shape, then ``log alpha_c``) minimizing the coat ``problem``, whose objective has
    several minima: the :data:`COAT_STARTS` best of the ``scan`` (:func:`_least`) are each led
    to their basin on the box-only objective, a lower bound of ``E`` equal to it wherever
    the energy constraint is inactive (:func:`_minimize`, ``relaxed``: no energy rows, a
    loose tolerance), and the one of least ``E`` is refined on ``E``."""
    basins = (_minimize(problem, scan[i], max_nfev, relaxed=True) for i in _least(problem, scan, COAT_STARTS)[0])
    return _minimize(problem, min(basins, key=problem.error), max_nfev)


def fit_analytic(brdf, model: str = "ggx", diffuse: bool = False, anisotropic: bool = False,
                 fresnel: str = "table", *, coat: bool = False, coat_fresnel: str = "table", start=None,
                 gaf: str | None = None,
                 shadowing: bool = True, albedo_weight: float = ALBEDO_WEIGHT, n: int = 32, n_uniform: int = 2**13,
                 albedo_grid: tuple[int, int] = (64, 32), max_nfev: int = 200):
    """Least-squares fit of an analytic microfacet BRDF (with an optional clear coat and
    Lambertian base) to ``brdf``.

    Minimizes ``e_grid^2 + e_uniform^2 + albedo_weight^2 mean_{views, RGB}(a_fit / a_data - 1)^2``
    with ``e^2 = sum |f_fit cos theta_i - f_ref cos theta_i|^2 / sum |f_ref cos theta_i|^2`` over RGB and the pairs of
    :func:`microfacet.metrics.measurement_directions` (``n`` per MERL coordinate) and of
    :func:`microfacet.metrics.uniform_directions` (``n_uniform``, seed 1, not the metric's
    seed 0; ``n_uniform = 0``: the grid alone), grazing and unmeasured pairs excluded as in
    :func:`microfacet.metrics.fit_error`, with ``f_fit = F D G / (4 cos theta_i cos theta_o)``
    (Eq. 2.1) ``[+ F_c D_c G_c / (4 cos theta_i cos theta_o)] [+ k_d / pi]`` (a coat lobe,
    Eq. 2.1 with its own Fresnel term ``F_c``, and Eq. 1.9), by variable
    projection (module docstring).

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
    coat : bool
        Add a coat: a second isotropic lobe of the same family, roughness ``alpha_c``
        (any, sharper or wider than the first), with its own Fresnel term
        (``coat_fresnel``), summed with the others (as a production clear coat,
        without attenuating the base).
    coat_fresnel : {"table", "schlick"}
        The coat's Fresnel term, per channel in ``[0, 1]``: a 7-node table as ``fresnel="table"``
        (the default: a coloured base under a coat needs more than Schlick's two values;
        see the fitting-methods guide), or Schlick's with free normal and grazing
        values ``f0, f90`` (:func:`coat_fresnel`; a dielectric clear coat).
    fresnel : {"table", "schlick", "conductor"}
        Default ``"table"``. Schlick ``F0`` per channel in ``[0, 1]``; a conductor ``eta + i k`` per channel
        (``eta`` in ``[0.02, 10]``, ``k`` in ``[0, 20]``; ``k = 0`` is a dielectric); or a
        piecewise-linear table of 7 nodes uniform in ``theta_d`` with values in ``[0, 1]``.
    start : FittedBRDF or MicrofacetBRDF, optional
        Start of the roughness: the moment conversion ``start.to_ggx()`` of a tabulated
        fit (App. C), or an analytic BRDF's own roughness (and mean slope, GAF). A
        coarse roughness scan competes with it; without a start, the scan alone
        (isotropic start, zero mean slope).
    gaf, shadowing
        GAF of the fitted model (default: the start's, else ``"smith"``).
    albedo_weight : float
        Weight ``lambda`` of the directional-albedo ratios ``a_fit / a_data`` at
        :data:`~microfacet.metrics.ALBEDO_VIEWS_DEG` (RGB; light directions as
        :func:`~microfacet.metrics.albedo_ratios` takes them) in the objective; 0: shape only.
    n, n_uniform, albedo_grid, max_nfev
        Grid size and number of uniform pairs fitted; ``(n_theta, n_phi)`` of the albedo
        quadrature (:func:`~microfacet.metrics.hemisphere_grid`, per view); evaluation
        budget of the anisotropic search.

    Returns
    -------
    MicrofacetBRDF, or SumBRDF(MicrofacetBRDF[, coat MicrofacetBRDF][, Lambertian]) with a
    coat or a diffuse base.

    References
    ----------
    Dupuy 2015, thesis, Eq. 1.9, 2.1, 2.11, Table 2.II, App. C; Walter et al. 2007 (GGX); Beckmann & Spizzichino 1963.

    Examples
    --------
    >>> import microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.25), mf.fresnel.Schlick(0.9))
    >>> ggx = fit_analytic(reference, "ggx", fresnel="schlick", n=8, n_uniform=512)
    >>> type(ggx.distribution).__name__, round(float(ggx.distribution.alpha_x), 2)
    ('GGX', 0.23)
    """
    if model not in MODELS:
        raise ValueError(f"model must be one of {tuple(MODELS)}, got {model!r}")
    if fresnel not in FRESNELS:
        raise ValueError(f"fresnel must be one of {FRESNELS}, got {fresnel!r}")
    if coat_fresnel not in COAT_FRESNELS:
        raise ValueError(f"coat_fresnel must be one of {COAT_FRESNELS}, got {coat_fresnel!r}")
    if not (np.isfinite(albedo_weight) and albedo_weight >= 0):
        raise ValueError(f"albedo_weight must be a finite number >= 0, got {albedo_weight!r}")
    ax, ay, rho, mean_slope = _start_alpha(start) if start is not None else (_SCAN[6], _SCAN[6], 0.0, np.zeros(2))
    gaf = gaf if gaf is not None else getattr(start, "gaf_model", "smith")
    data = _data(brdf, int(n), int(n_uniform), tuple(int(v) for v in albedo_grid))
    options = dict(gaf=gaf, shadowing=shadowing, mean_slope=mean_slope, albedo_weight=albedo_weight,
                   coat_fresnel=coat_fresnel)
    shape = _Shape(data, model, bool(diffuse), bool(anisotropic), bool(coat), options)
    linear = "schlick" if fresnel == "conductor" else fresnel   # stages 1-3: a Fresnel linear in its values
    q, problem = _isotropic_roughness(shape, linear, np.sqrt(ax * ay))
    if anisotropic:
        q, problem = _anisotropy(shape, linear, q, (ax, ay, rho), max_nfev)
    if coat:
        q, problem = _coat_roughness(shape, linear, q, max_nfev)
    if fresnel == "conductor":                                  # stage 4: refined from that shape
        problem = _Problem(data, model, shape.diffuse, shape.anisotropic, "conductor", coat=coat, **options)
        q = _minimize(problem, q, max_nfev)
    return problem.brdf(q)


@dataclass(frozen=True)
class _Shape:
    """What every stage of :func:`fit_analytic` fits: the data's side, the model family,
    whether it has a base, anisotropy and a coat, and the options of its problems."""
    data: object
    model: str
    diffuse: bool
    anisotropic: bool
    coat: bool
    options: dict


def _isotropic_roughness(shape: _Shape, linear: str, alpha0: float) -> tuple:
    """Stage 1: ``(q, problem)``, the isotropic log roughness by a scan and Brent's method."""
    problem = _Problem(shape.data, shape.model, shape.diffuse, False, linear, **shape.options)
    la = np.log(ALPHA_BOUNDS)
    starts = [np.log(np.clip(alpha0, *ALPHA_BOUNDS))] + list(np.log(_SCAN))
    return np.array([_minimize_log_alpha(problem, starts, *la)]), problem


def _anisotropy(shape: _Shape, linear: str, q, start: tuple, max_nfev: int) -> tuple:
    """Stage 2: ``(q, problem)``, log roughnesses and ``rho`` from the isotropic one (with the
    ``start``'s aspect and ``rho`` if it has them)."""
    ax, ay, rho = start
    problem = _Problem(shape.data, shape.model, shape.diffuse, True, linear, **shape.options)
    q0 = [q[0], q[0], 0.0]
    if ax != ay:
        ratio = 0.5 * np.log(ay / ax)
        q0 = [q[0] - ratio, q[0] + ratio, float(np.clip(rho, -0.9, 0.9))]
    return _minimize(problem, q0, max_nfev), problem


def _coat_roughness(shape: _Shape, linear: str, q, max_nfev: int) -> tuple:
    """Stage 3: ``(q, problem)`` with the coat's log roughness, from a scan at the lobe's
    shape, then refined with it; of the two interchangeable lobes the coat is the sharper."""
    problem = _Problem(shape.data, shape.model, shape.diffuse, shape.anisotropic, linear, coat=True, **shape.options)
    q = _coat_search(problem, [np.append(q, lc) for lc in np.log(_SCAN)], max_nfev)
    if not shape.anisotropic and linear == shape.options["coat_fresnel"] and q[0] < q[1]:
        q = q[::-1].copy()       # mirror minima
    return q, problem
