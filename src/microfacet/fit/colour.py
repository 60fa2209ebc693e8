"""A fit's colour balanced to the data's as the spheres display it, under lights that do not
judge it.

A fit whose directional albedo matches the data's at every view
(:func:`microfacet.fit.albedo.match_albedo`) can still show another colour: the data's hue
can vary over the sphere (a highlight whiter than the body, a body more saturated where it
is bright) in a way that the fit's terms, each of one colour, share out differently. What
people see is the sphere as displayed: each image exposed to its white, a pixel brighter
than white shown at white's luminance with its hue (:meth:`microfacet.metrics.ImageError.displayed_rgb`,
the colour cast of :func:`microfacet.metrics.chromaticity_difference`).

:func:`balance_colour` scales the fit's terms per RGB channel: each group of microfacet lobes
(the sharp ones and the rough ones, :func:`_groups`) by a factor table ``t(theta_d) = sum_k
g_k h_k(theta_d)`` on the hats of :data:`~microfacet.fit.albedo.NODES_DEG` (times their
Fresnel tables), each diffuse base by one factor ``g``. The factors are the least change

    minimize  |g - 1|^2 + SMOOTHNESS |D2 g|^2 + RHO |rg(S(g)) - rg(S_data)|^2

(``D2`` the second differences of each table, ``S`` the displayed RGB sum of the spheres
under :data:`BALANCE_LIGHTS_DEG` and the environment turned by :data:`BALANCE_TURN_DEG`,
``rg`` its chromaticity ``(r, g) / (r + g + b)``) subject to what the albedo match holds:
the directional albedo within :data:`~microfacet.fit.albedo.BAND_TARGET` of the data's at
:data:`~microfacet.fit.albedo.BAND_VIEWS_DEG` (or no farther than before), at most the
data's + 1 % at every view of :data:`~microfacet.fit.albedo.VIEWS_DEG` (or no more than
before), below ``1 - ENERGY_MARGIN`` up to 89 deg, every table at most 1 and rising and
falling where it did, its total variation at most ``TV_LIMIT`` times its range (no table
rings), every factor within ``[1 / FACTOR_RANGE, FACTOR_RANGE]``. Each term's images and
albedo are computed once and are linear in its factors, the displayed sum nearly so (a
pixel's cap at white bends it), so Gauss-Newton solves it, each step a QP with these linear
constraints (:func:`_gauss_newton`). The longest part of the step (bisected,
:data:`BISECTIONS`) that lowers the cast and costs at most :data:`IMAGE_TOLERANCE` of image
error under these lights and ``LOG_TOLERANCE`` of log error is kept.

The lights are not those of the image error that chooses and reports the fits
(:data:`microfacet.metrics.IMAGE_LIGHTS_DEG` and the environment as it is): the colour is
balanced under lights the image error does not see. A fit is balanced only where its cast
under them exceeds :data:`CAST_TRIGGER` (half the limit of a cast,
:data:`microfacet.fit.outputs.CHROMA_LIMIT`); :func:`microfacet.fit.outputs.fit_material`
keeps a balanced fit where it lowers the cast under the image error's lights too.

Accuracy: on the fit corpus (``experiments/fit_corpus.py``) the balanced fits' casts under
the image error's lights fall with those under these lights on all but a few materials
(which ``fit_material`` leaves unbalanced); a cast that the albedo band forbids closing is
brought as near as it allows.

Examples
--------
>>> import microfacet as mf
>>> from microfacet.fit.albedo import albedo_target, match_albedo
>>> data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.08), mf.fresnel.Schlick(0.3)),
...                       mf.Lambertian((0.5, 0.3, 0.1)))              # a white highlight, an orange body
>>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.08), mf.fresnel.Schlick((0.7, 0.3, 0.1))),
...                      mf.Lambertian((0.4, 0.32, 0.13)))            # an orange highlight, a paler body
>>> target = albedo_target(data)
>>> fit = match_albedo(None, fit, target)                            # the data's albedo, another colour
>>> judge, seen = colour_target(data), mf.metrics.ImageError(data, size=32)
>>> balanced = balance_colour(judge, target, fit)
>>> round(seen.chromaticity(fit), 2), bool(seen.chromaticity(balanced) < 0.005)    # under lights it did not see
(0.03, True)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._colour import LUMINANCE
from ..metrics import ImageError, albedo_directions
from .albedo import ALBEDO_ABOVE, BAND_FLOOR, BAND_TARGET, BAND_VIEWS_DEG, ENERGY_MARGIN, ENERGY_VIEWS_DEG, \
    LOG_TOLERANCE, NODES_DEG, QUADRATURE, TV_LIMIT, VIEWS_DEG, AlbedoTarget, hats, theta_d
from .extract import table_variation

__all__ = ["BALANCE_LIGHTS_DEG", "BALANCE_TURN_DEG", "BALANCE_SIZE", "CAST_TRIGGER", "colour_target", "balance_colour"]

#: Directional lights of the balance, (angle from the view, azimuth) in degrees as
#: :data:`microfacet.metrics.IMAGE_LIGHTS_DEG`, none of them one of those: at the view and
#: from 15 to 80 deg around it.
BALANCE_LIGHTS_DEG = ((0.0, 0.0), (15.0, 300.0), (20.0, 60.0), (30.0, 200.0), (35.0, 330.0), (40.0, 100.0),
                      (50.0, 250.0), (55.0, 20.0), (60.0, 160.0), (65.0, 290.0), (70.0, 60.0), (80.0, 200.0))
#: The turn (deg, about the view axis) of the studio environment of the balance's last image:
#: its sky below the sphere, where the image error's is above.
BALANCE_TURN_DEG = 180.0
#: Sphere size (px) of the balance's images.
BALANCE_SIZE = 32
#: Cast (chromaticity distance of the spheres' displayed colour) above which a fit is balanced.
CAST_TRIGGER = 0.01
#: Weight of the second differences of a group's factors over its nodes.
SMOOTHNESS = 10.0
#: Weight of the squared chromaticity difference against the squared change of the factors: a
#: difference of 0.01 weighs as ten factors moved by 1.
RHO = 1e5
#: Largest number of Gauss-Newton iterations per balance, and the largest change of a factor
#: at which they stop.
GN_ITERATIONS = 30
STEP_TOL = 1e-4
#: Largest factor and the inverse of the smallest.
FACTOR_RANGE = 2.0
#: Largest relative growth of the image error under the balance's lights that a balance may cost.
IMAGE_TOLERANCE = 0.03
#: Halvings of a Gauss-Newton step while the objective does not fall, and bisections of the
#: balance's step for its longest part that costs little enough.
HALVINGS = 4
BISECTIONS = 5


def colour_target(reference) -> ImageError:
    """The data's side of :func:`balance_colour`: ``reference``'s spheres under
    :data:`BALANCE_LIGHTS_DEG` and the environment turned by :data:`BALANCE_TURN_DEG`
    (:class:`~microfacet.metrics.ImageError` of :data:`BALANCE_SIZE` px).

    Parameters
    ----------
    reference : BRDF
        The data.

    Returns
    -------
    microfacet.metrics.ImageError

    Examples
    --------
    >>> import microfacet as mf
    >>> colour_target(mf.Lambertian(0.5)).ref.shape[0]      # 12 lights and the environment
    13
    """
    return ImageError(reference, BALANCE_SIZE, BALANCE_LIGHTS_DEG, environment_deg=BALANCE_TURN_DEG)


def _is_lobe(part) -> bool:
    from ..brdf import MicrofacetBRDF
    from ..fresnel import Tabulated
    return isinstance(part, MicrofacetBRDF) and isinstance(part.fresnel, Tabulated)


def _is_base(part) -> bool:
    from ..brdf import Lambertian
    from ..diffuse import TransmittedLambertian
    return isinstance(part, (Lambertian, TransmittedLambertian))


class _Columns(NamedTuple):
    """The unknowns of the balance: one factor per channel for each ``(terms, node)``: a group
    of lobes (:func:`_groups`) and an index of :data:`~microfacet.fit.albedo.NODES_DEG`, the
    group's factor the table ``t(theta_d) = sum_k g_k h_k(theta_d)``, or a base and None; and
    each one's share of the images ``pixels (F, I, N, 3)``, of the albedo ratios ``ratio (F, V,
    3)`` and of the directional albedo ``energy (F, V', 3)``; ``fixed``: the same of the other
    terms (summed)."""
    terms: list
    pixels: np.ndarray
    ratio: np.ndarray
    energy: np.ndarray
    fixed: tuple

    def render(self, g: np.ndarray) -> np.ndarray:
        """The fit's images (:meth:`ImageError.render`) with the columns' factors ``g`` ``(F, 3)``."""
        return self.fixed[0] + np.einsum("fijc,fc->ijc", self.pixels, g)


def _groups(parts: list) -> list[tuple]:
    """The lobes of ``parts`` (indices) in at most two groups, each sharing one table of factors:
    those rougher than the geometric mean of the roughest and the sharpest, and the others."""
    lobes = [i for i, p in enumerate(parts) if _is_lobe(p)]
    alpha = np.array([np.sqrt(parts[i].distribution.alpha_x * parts[i].distribution.alpha_y) for i in lobes])
    if len(lobes) < 2:
        return [tuple(lobes)] if lobes else []
    rough = alpha > np.sqrt(alpha.min() * alpha.max())
    return [g for g in (tuple(np.asarray(lobes)[~rough]), tuple(np.asarray(lobes)[rough])) if g]


def _summed(brdf, parts: list, members) -> object:
    """The sum of the terms ``members`` (indices into ``parts``) as one BRDF, of ``brdf``'s class
    where it is a sum (a :class:`~microfacet.fit.perceptual.GGXLobes` evaluates its lobes together)."""
    from .analytic import SumBRDF
    if len(members) == 1:
        return parts[members[0]]
    return (type(brdf) if isinstance(brdf, SumBRDF) else SumBRDF)(*(parts[i] for i in members))


def _images(judge: ImageError, term, split: bool) -> np.ndarray:
    """The images of ``term`` (a BRDF) as ``judge`` renders them (:meth:`ImageError.render`),
    ``(I, N, 3)``; with ``split``, their shares by the hats of ``theta_d`` of each pair,
    ``(K, I, N, 3)`` (summing to it)."""
    scene = judge.scene
    out = np.zeros((len(NODES_DEG) if split else 1, len(judge.ref), scene.n_px, 3))

    nodes, n = np.radians(NODES_DEG), scene.n_px

    def add(j, px, wi, wo, weight=None):
        f = np.nan_to_num(np.asarray(term.eval_cos(wi, wo), float))
        f = f if weight is None else f * weight
        if not split:
            for c in range(3):
                out[0, j, :, c] += np.bincount(px, f[:, c], minlength=n)
            return
        theta = np.clip(theta_d(wi, wo), 0.0, nodes[-1])         # two hats are not zero: k and k + 1
        k = np.clip(np.searchsorted(nodes, theta, side="right") - 1, 0, len(nodes) - 2)
        w = (theta - nodes[k]) / (nodes[k + 1] - nodes[k])
        for c in range(3):
            shares = np.bincount(k * n + px, (1.0 - w) * f[:, c], minlength=len(nodes) * n) \
                + np.bincount((k + 1) * n + px, w * f[:, c], minlength=len(nodes) * n)
            out[:, j, :, c] += shares.reshape(len(nodes), n)

    for j, (wi, mask) in enumerate(zip(scene.light_wi, judge.light_masks)):
        px = np.flatnonzero(mask)
        add(j, px, wi[mask], scene.wo[mask])
    for px, wi, wo, lw in judge.env:
        add(-1, px, wi, wo, lw)
    out *= scene.sphere.coverage[None, None, :, None]
    return out if split else out[0]


def _columns(judge: ImageError, target: AlbedoTarget, brdf, parts: list) -> _Columns:
    """:class:`_Columns` of the terms ``parts`` of ``brdf`` (their lobes' groups per node, their bases whole)."""
    k = len(NODES_DEG)
    wi, wo, w, view = target.ratios.nodes
    e_wi, e_wo, e_w, e_view = albedo_directions(VIEWS_DEG + ENERGY_VIEWS_DEG, 0.0, *QUADRATURE)
    n_views, n_energy = target.ratios.n_views, len(VIEWS_DEG + ENERGY_VIEWS_DEG)
    ref = np.maximum(target.ratios.ref, 1e-300)
    ratio_hats, energy_hats = hats(theta_d(wi, wo)), hats(theta_d(e_wi, e_wo))

    def sums(values, weights, index, n):
        return np.stack([np.bincount(index, weights * values[:, c], minlength=n) for c in range(3)], axis=-1)

    def albedo(term):
        """``f cos`` of ``term`` on the ratios' nodes and on the energy's."""
        return (np.nan_to_num(np.asarray(term.eval_cos(wi, wo), float)),
                np.nan_to_num(np.asarray(term.eval_cos(e_wi, e_wo), float)))

    terms, pixels, ratio, energy = [], [], [], []
    for group in _groups(parts):
        term = _summed(brdf, parts, group)
        images = _images(judge, term, split=True)
        f, e = albedo(term)
        for node in range(k):
            terms.append((group, node))
            pixels.append(images[node])
            ratio.append(sums(f, w * ratio_hats[:, node], view, n_views) / ref)
            energy.append(sums(e, e_w * energy_hats[:, node], e_view, n_energy))
    for i in (i for i, p in enumerate(parts) if _is_base(p)):
        f, e = albedo(parts[i])
        terms.append(((i,), None))
        pixels.append(_images(judge, parts[i], split=False))
        ratio.append(sums(f, w, view, n_views) / ref)
        energy.append(sums(e, e_w, e_view, n_energy))
    rest = [i for i, p in enumerate(parts) if not (_is_lobe(p) or _is_base(p))]
    if rest:
        term = _summed(brdf, parts, rest)
        f, e = albedo(term)
        fixed = (_images(judge, term, split=False), sums(f, w, view, n_views) / ref,
                 sums(e, e_w, e_view, n_energy))
    else:
        fixed = (np.zeros_like(judge.ref), np.zeros((n_views, 3)), np.zeros((n_energy, 3)))
    return _Columns(terms, np.stack(pixels), np.stack(ratio), np.stack(energy), fixed)


def _upper(parts: list, terms: list) -> np.ndarray:
    """The largest factor of each column ``(F, 3)``: :data:`FACTOR_RANGE`, and a lobe's table
    at most 1 where the node's hat reaches, a base's reflectance at most 1."""
    out = []
    for members, node in terms:
        if node is None:
            peak = np.broadcast_to(np.asarray(parts[members[0]].reflectance, float), 3)
        else:
            peak = np.zeros(3)
            for i in members:
                fresnel = parts[i].fresnel
                support = _table_hats(fresnel)[:, node] > 0
                if np.any(support):
                    peak = np.maximum(peak, np.max(fresnel.values[support], axis=0))
        with np.errstate(divide="ignore"):
            out.append(np.minimum(FACTOR_RANGE, np.where(peak > 0, 1.0 / peak, FACTOR_RANGE)))
    return np.maximum(np.array(out), 1.0)


def _smoothness(terms: list) -> np.ndarray:
    """The quadratic form ``(F, F)`` of the second differences of each group's factors over its nodes."""
    n = len(terms)
    out = np.zeros((n, n))
    groups = {}
    for j, (members, node) in enumerate(terms):
        if node is not None:
            groups.setdefault(members, []).append(j)
    for cols in groups.values():
        d = np.diff(np.eye(len(cols)), 2, axis=0)
        out[np.ix_(cols, cols)] += d.T @ d
    return out


def _tables(parts: list, terms: list, g: np.ndarray) -> dict:
    """``{term index: table values}`` of each lobe: ``clip(F t, 0, 1)``, ``t`` its group's factors ``g`` over the hats."""
    out = {}
    for members in dict.fromkeys(m for m, node in terms if node is not None):
        rows = [j for j, (m, node) in enumerate(terms) if m == members]
        for i in members:
            fresnel = parts[i].fresnel
            factor = _table_hats(fresnel) @ g[rows]
            out[i] = np.clip(fresnel.values * factor, 0.0, 1.0)
    return out


def _table_hats(fresnel) -> np.ndarray:
    """The hats of :data:`~microfacet.fit.albedo.NODES_DEG` at a tabulated Fresnel term's nodes, ``(T, K)``."""
    return hats(np.arccos(np.clip(fresnel.cos_theta_d, -1.0, 1.0)))


def _rings(values: np.ndarray) -> bool:
    """Whether a table's total variation exceeds :data:`~microfacet.fit.albedo.TV_LIMIT` times its
    range in some channel (:func:`~microfacet.fit.extract.table_variation`)."""
    return bool(np.any(table_variation(values) > TV_LIMIT * (1.0 + 1e-6)))


def _rebuilt(brdf, parts: list, terms: list, g: np.ndarray):
    """``brdf`` with its lobes' tables and bases' reflectances scaled by the columns' factors ``g``."""
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from ..fresnel import Tabulated
    from .analytic import SumBRDF
    new = list(parts)
    for i, values in _tables(parts, terms, g).items():
        p = parts[i]
        new[i] = MicrofacetBRDF(p.distribution, fresnel=Tabulated(p.fresnel.cos_theta_d, values), gaf=p.gaf_model,
                                shadowing=p.shadowing, dtype=p.dtype)
    for j, (members, node) in enumerate(terms):
        if node is None:
            i = members[0]
            p = parts[i]
            reflectance = np.clip(p.reflectance * g[j], 0.0, 1.0)
            new[i] = TransmittedLambertian(reflectance, p.eta) if isinstance(p, TransmittedLambertian) \
                else Lambertian(reflectance)
    if isinstance(brdf, SumBRDF):
        return type(brdf)(*new, weights=brdf.weights)     # a GGXLobes stays one
    return new[0]


class _Display:
    """The displayed RGB sum ``S(g)`` of the balance's images (:meth:`ImageError.displayed_rgb`)
    and its Jacobian, for the columns' renders ``x = fixed + sum_f g_f X_f`` (over each image's white)."""

    def __init__(self, judge: ImageError, columns: _Columns):
        used = judge.used
        white = np.asarray([judge.white[j] for j in used])[:, None, None]
        self.fixed = (columns.fixed[0][used] / white).reshape(-1, 3)                    # (M, 3)
        x = columns.pixels[:, used] / white                                            # (F, U, N, 3)
        self.x = [np.ascontiguousarray(x[..., c].reshape(len(x), -1)) for c in range(3)]  # 3 x (F, M)

    def __call__(self, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(S, dS/dg)``: ``(3,)`` and ``(3, F, 3)``."""
        x = self.fixed + np.stack([g[:, c] @ self.x[c] for c in range(3)], axis=-1)
        y = np.maximum(x @ LUMINANCE, 1e-300)
        capped = y > 1.0
        scale = np.where(capped, 1.0 / y, 1.0)
        q = np.zeros_like(x)                                                          # (M, 3)
        q[capped] = x[capped] / (y[capped] ** 2)[:, None]
        jac = np.zeros((3, len(g), 3))
        for c in range(3):
            jac[:, :, c] = -LUMINANCE[c] * (self.x[c] @ q).T
            jac[c, :, c] += self.x[c] @ scale
        return x.T @ scale, jac


def _chroma(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(rg, d rg / d S)``: the chromaticity ``(r, g) / (r + g + b)`` of ``s`` and its ``(2, 3)`` Jacobian."""
    total = max(float(np.sum(s)), 1e-300)
    return s[:2] / total, (np.eye(3)[:2] * total - s[:2, None]) / total ** 2


def _constraints(target: AlbedoTarget, columns: _Columns, parts: list) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, bound)``: the linear inequalities ``rows @ g >= bound`` on the columns' factors
    (flat; module docstring), each holding at ``g = 1``: the albedo's band and bounds, and the
    tables' shapes (:func:`_table_rows`)."""
    fixed, per = columns.fixed[1], columns.ratio              # (V, 3), (F, V, 3)
    n_free = len(per)
    r0 = fixed + per.sum(axis=0)
    held = np.isin(np.asarray(VIEWS_DEG), BAND_VIEWS_DEG)[:, None] & (target.ratios.ref > BAND_FLOOR)
    upper = np.maximum(1.0 + ALBEDO_ABOVE, r0)
    lower = np.where(held, np.minimum(1.0 - BAND_TARGET, r0), -np.inf)
    e_fixed, e_per = columns.fixed[2], columns.energy
    e_upper = np.maximum(1.0 - ENERGY_MARGIN, e_fixed + e_per.sum(axis=0))

    def rows(per_f):                                          # d value[v, c] / d g[f, c'] as (V*3, F*3)
        m = np.zeros(per_f.shape[1:] + (n_free, 3))
        for c in range(3):
            m[:, c, :, c] = per_f[:, :, c].T
        return m.reshape(-1, n_free * 3)

    a_r, a_e = rows(per), rows(e_per)
    low = np.isfinite(lower).ravel()
    tables = _table_rows(columns.terms, parts)
    a = np.concatenate([-a_r, a_r[low], -a_e, tables])
    b = np.concatenate([(upper - fixed).ravel(), -(lower - fixed).ravel()[low], (e_upper - e_fixed).ravel(),
                        np.zeros(len(tables))])
    return a, -b


def _table_rows(terms: list, parts: list) -> np.ndarray:
    """Rows ``r`` ``(R, 3F)`` of the constraints ``r @ g >= 0`` that keep each lobe's table ``F t``
    rising where ``F`` rises, falling where it falls, and its total variation (those signs
    kept) at most ``TV_LIMIT`` times its value at ``F``'s largest node less that at its least.
    Where ``F`` rises, ``t[m + 1] >= (F[m] / F[m + 1]) t[m]``: one row per node and group of
    lobes on one grid, for its steepest lobe; likewise where it falls."""
    n_free = len(terms)
    grids = {}                               # a group's lobes by the nodes of their tables
    for members in dict.fromkeys(m for m, node in terms if node is not None):
        for i in members:
            grids.setdefault((members, parts[i].fresnel.cos_theta_d.tobytes()), []).append(i)
    blocks = [np.zeros((0, 3 * n_free))]
    for (members, _), lobes in grids.items():
        cols = [j for j, (m, node) in enumerate(terms) if m == members]
        values = np.stack([parts[i].fresnel.values for i in lobes])               # (L, T, 3)
        h = _table_hats(parts[lobes[0]].fresnel)                                  # t = h @ g
        rise, fall = values[:, 1:] > values[:, :-1], values[:, 1:] < values[:, :-1]
        with np.errstate(divide="ignore", invalid="ignore"):
            up = np.max(np.where(rise, values[:, :-1] / values[:, 1:], 0.0), axis=0)    # (T - 1, 3)
            down = np.max(np.where(fall, values[:, 1:] / values[:, :-1], 0.0), axis=0)
        for c in range(3):
            for keep, d in ((np.any(rise[:, :, c], axis=0), h[1:] - up[:, c, None] * h[:-1]),
                            (np.any(fall[:, :, c], axis=0), h[:-1] - down[:, c, None] * h[1:])):
                block = np.zeros((int(keep.sum()), n_free, 3))
                block[:, cols, c] = d[keep]
                blocks.append(block.reshape(-1, 3 * n_free))
            for v in values[:, :, c]:
                sign = np.sign(np.diff(v))
                row = np.zeros((1, n_free, 3))
                row[0, cols, c] = TV_LIMIT * (v[np.argmax(v)] * h[np.argmax(v)] - v[np.argmin(v)] * h[np.argmin(v)]) \
                    - sign @ np.diff(v[:, None] * h, axis=0)
                blocks.append(row.reshape(1, 3 * n_free))
    return np.concatenate(blocks)


def balance_colour(judge: ImageError, target: AlbedoTarget, brdf):
    """``brdf`` with its terms' colours balanced (module docstring): where its cast under
    the ``judge``'s lights exceeds :data:`CAST_TRIGGER`, each lobe's Fresnel table scaled per
    channel by a smooth factor in ``theta_d`` and each base's reflectance per channel, the
    least change toward the data's displayed colour within the albedo band; else ``brdf`` itself.

    Parameters
    ----------
    judge : microfacet.metrics.ImageError
        The data's spheres under the balance's lights (:func:`colour_target`).
    target : microfacet.fit.albedo.AlbedoTarget
        The data's albedo and log error (:func:`microfacet.fit.albedo.albedo_target`).
    brdf : BRDF
        The fit, its albedo matched (:func:`microfacet.fit.albedo.match_albedo`): a
        :class:`~microfacet.fit.SumBRDF` of lobes with tabulated Fresnel terms and diffuse
        bases, or one such term; other terms keep their colour.

    Returns
    -------
    BRDF
        The same tree, terms of the same classes.

    Examples
    --------
    >>> import microfacet as mf
    >>> from microfacet.fit.albedo import albedo_target
    >>> data = mf.Lambertian((0.5, 0.3, 0.1))
    >>> balance_colour(colour_target(data), albedo_target(data), data) is data      # no cast
    True
    """
    parts = list(getattr(brdf, "brdfs", [brdf]))
    if not any(_is_lobe(p) or _is_base(p) for p in parts):
        return brdf
    columns = _columns(judge, target, brdf, parts)
    ones = np.ones((len(columns.terms), 3))
    cast = judge.cast(columns.render(ones))
    if not cast > CAST_TRIGGER or not np.isfinite(cast):
        return brdf
    display, ref = _Display(judge, columns), _chroma(judge.ref_rgb)[0]
    quadratic = np.eye(ones.size) + SMOOTHNESS * np.kron(_smoothness(columns.terms), np.eye(3))
    lower = np.full(ones.size, 1.0 / FACTOR_RANGE)
    rows, bound = _constraints(target, columns, parts)
    rows = np.concatenate([rows, np.eye(ones.size), -np.eye(ones.size)])      # rows @ g >= bound
    bound = np.concatenate([bound, lower, -_upper(parts, columns.terms).ravel()])
    log0, image0 = target.log(brdf), _image_error(judge, columns.render(ones))
    step = _gauss_newton(display, ref, quadratic, rows, bound).reshape(-1, 3) - 1.0
    if not np.all(np.isfinite(step)) or any(_rings(v) for v in _tables(parts, columns.terms, 1.0 + step).values()):
        return brdf

    def kept(t):
        """The fit at ``t`` of the step if it lowers the cast at little enough cost, else None."""
        pixels = columns.render(1.0 + t * step)
        if judge.cast(pixels) >= cast or _image_error(judge, pixels) > (1.0 + IMAGE_TOLERANCE) * image0:
            return None
        out = _rebuilt(brdf, parts, columns.terms, 1.0 + t * step)
        return out if target.log(out) <= (1.0 + LOG_TOLERANCE) * log0 else None

    best, low, high = kept(1.0), 0.0, 1.0
    for _ in range(BISECTIONS if best is None else 0):     # the longest part of the step that is kept
        mid = 0.5 * (low + high)
        out = kept(mid)
        if out is None:
            high = mid
        else:
            best, low = out, mid
    return brdf if best is None else best


def _gauss_newton(display: _Display, ref: np.ndarray, quadratic: np.ndarray, rows: np.ndarray,
                  bound: np.ndarray) -> np.ndarray:
    """The factors ``g`` (flat) of least ``(g - 1)^T Q (g - 1) + RHO |e(g)|^2``, ``e`` the
    chromaticity difference of the displayed spheres from the data's (``Q = quadratic``),
    subject to ``rows @ g >= bound``: Gauss-Newton from ``g = 1`` (``e``
    linearized at each iterate, each step a strictly convex QP solved by Goldfarb & Idnani's
    dual active-set method, ``quadprog``), the step halved while the objective does not fall,
    until it moves no factor by more than :data:`STEP_TOL`."""
    import quadprog

    def residual(g):
        """``(e, de/dg)``: the chromaticity difference and its Jacobian."""
        s, jac = display(g.reshape(-1, 3))
        rg, d_rg = _chroma(s)
        return rg - ref, d_rg @ jac.reshape(3, -1)

    def objective(g, e):
        u = g - 1.0
        return float(u @ quadratic @ u + RHO * e @ e)

    g = np.ones(len(quadratic))
    e, j = residual(g)
    f = objective(g, e)
    for _ in range(GN_ITERATIONS):
        if not np.any(e):
            break
        h = 2.0 * quadratic + 2.0 * RHO * j.T @ j
        lin = 2.0 * quadratic @ np.ones(len(g)) - 2.0 * RHO * j.T @ (e - j @ g)
        try:
            trial = quadprog.solve_qp(h, lin, rows.T, bound)[0]
        except ValueError:                          # quadprog: constraints inconsistent (rounding)
            break
        for _ in range(HALVINGS + 1):
            e_t, j_t = residual(trial)
            f_t = objective(trial, e_t)
            if f_t < f:
                break
            trial = 0.5 * (g + trial)
        else:
            break
        moved = float(np.max(np.abs(trial - g)))
        g, e, j, f = trial, e_t, j_t, f_t
        if moved < STEP_TOL:
            break
    return g


def _image_error(judge: ImageError, pixels: np.ndarray) -> float:
    """:meth:`ImageError.error` of the fit that renders ``pixels``."""
    return float(np.nanmean(judge.per_image(None, pixels)))
