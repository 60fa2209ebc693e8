"""A fit's directional albedo matched to the data's: a smooth Fresnel table, or new Schlick parameters.

A fit made in a compressed space (:mod:`microfacet.fit.perceptual`) weighs the specular
peak little: its shape can be right while the energy it reflects at grazing views falls
short of the data's (a plastic's or paint's albedo stays flat or rises with the view, the
fit's falls with its body's transmission). :func:`match_albedo` changes the lobes' Fresnel
terms, never their distributions, so that the directional albedo
``a(o) = int f cos theta_i d i`` (Dupuy 2015, Eq. 1.8) equals the data's at views
:data:`VIEWS_DEG`, in one of two forms (``method``, :data:`METHODS`).

**Table** (``"table"``, the default). Every microfacet lobe's Fresnel term is multiplied by
one smooth non-negative factor per channel ``s(theta_d)``,

    f'(i, o) = f(i, o) + (s(theta_d) - 1) f_spec(i, o).

The albedo is linear in ``s``: with ``s`` piecewise linear on :data:`NODES_DEG` (hat
functions ``h_k``),

    a'(o) = a(o) + sum_k (s_k - 1) int h_k(theta_d) f_spec cos theta_i d i,

so ``s`` solves a bounded linear least squares (:func:`~microfacet.fit.extract.box_qp`):
the relative albedo residuals, plus the fit's cosine-weighted log error
(:class:`~microfacet.metrics.LogError`, Löw et al. 2012) linearized in ``s`` and weighed by
:data:`LOG_WEIGHT` relative to its value before the match (so that the lobes' energy moves
where it changes the shape least), a second-difference smoothness penalty
(:data:`SMOOTHNESS`) and a weak pull toward 1 (:data:`PULL`); views where the albedo would
exceed the data's by more than 1 % are weighed up until it does not (energy stays a
constraint, as in the fits themselves). A specular lobe's energy at view ``theta_o`` comes
from ``theta_d`` near ``theta_o`` (the mirror configuration), which is why a table in
``theta_d`` reaches the albedo at each view without changing the lobes' shape. The product
``F s`` becomes each lobe's :class:`~microfacet.fresnel.Tabulated` term (clipped to
``[0, 1]``). No table may ring: where a channel's tables would have a total variation above
twice their range, ``s`` is solved again rising to one peak and falling after it (every
peak node tried), and, if that fails too, as a constant. Specs, fit files and the Mitsuba
plugins hold the table; the exports (glTF, MaterialX, USD, Blender) write it as its
least-squares Schlick pair and report that loss.

**Schlick** (``"schlick"``, ``"shared"``, ``"..._base"``). The albedo is also linear in each
Schlick lobe's ``F = f0 + (f90 - f0)(1 - cos theta_d)^5`` (Schlick 1994) parameters and in
a Lambertian or transmitted Lambertian base's colour:

    a'(o) = a_fixed(o) + sum_l [f0_l int D G (1 - m^5) ... + f90_l int D G m^5 ...] + k_d a_1(o),

``m = 1 - cos theta_d``, so the same least squares (albedo residuals at views up to
:data:`SCHLICK_VIEWS_MAX_DEG`, linearized log error, a pull toward the fit's own values
relative to ``max(x, PULL_FLOOR)``, the overshoot reweighting at :data:`SCHLICK_CAPPED_DEG`,
the views of the fits' own constraint) is solved for the parameters themselves, each in
``[0, 1]`` (:func:`schlick_parameters`): ``"schlick"`` every lobe's ``f0`` (RGB) and grey
``f90``; ``"shared"`` one factor per channel on every lobe's ``f0`` and one on every
``f90`` (the lobes keep their relative weights); ``"_base"`` also the base colours. The
result has no table (so no ring) and is held exactly by every export. ``"fallback"`` takes
:data:`FALLBACK_SCHLICK` where it reaches the band (:func:`band_error` within
:data:`BAND_TOLERANCE`) at a log error within :data:`FALLBACK_LOG_SLACK` of the table's, and
the table elsewhere.

Accuracy: the table reaches the albedo band (within 5 % at 0/30/60/75 deg, channels above
0.03) on 90 of the 98 corpus materials whose best fit is a perceptual model, and lowers
their log and image errors; the Schlick forms cannot bend the albedo's course with the
view as a table in ``theta_d`` can (``(1 - cos theta_d)^5`` moves only the grazing views;
per-lobe parameters reach it by moving energy between lobes of different roughness, which
the images show), and reach it on 18-43 of them at a 14-93 % larger geometric-mean image
error (``experiments/albedo_schlick.py``, results in ``experiments/results/albedo_schlick.md``).
On an analytic fit whose only error is its Schlick parameters, every method matches to 2 %.
A fit without microfacet lobes is returned unchanged.

Examples
--------
>>> import microfacet as mf
>>> data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.08)), mf.Lambertian(0.3))
>>> fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.1), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
>>> matched = match_albedo(data, fit)
>>> ratios = mf.metrics.albedo_ratios(data, matched, views_deg=(0.0, 60.0))
>>> bool(abs(ratios - 1.0).max() < 0.01)
True
>>> schlick = match_albedo(data, fit, method="schlick")
>>> type(schlick.brdfs[0].fresnel).__name__, round(float(schlick.brdfs[0].fresnel.f0[0]), 2)
('Schlick', 0.08)
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..metrics import AlbedoRatios, LogError
from .extract import box_qp

__all__ = ["VIEWS_DEG", "NODES_DEG", "SMOOTHNESS", "LOG_WEIGHT", "AlbedoTarget", "albedo_target", "albedo_scale",
           "match_albedo", "LOG_PAIRS", "METHODS", "METHOD", "schlick_parameters", "band_error", "BAND_TOLERANCE"]

#: Views (deg) at which the albedo is matched.
VIEWS_DEG = (0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0, 80.0)
#: Nodes (deg) of the piecewise-linear factor ``s(theta_d)``.
NODES_DEG = (0.0, 20.0, 35.0, 45.0, 55.0, 62.0, 68.0, 74.0, 80.0, 90.0)
#: Weight of the second differences of ``s`` (per node) against the relative albedo residuals.
SMOOTHNESS = 1e-3
#: Weight of the linearized squared log error over its value before the match: doubling
#: it costs as much as a 17 % albedo residual at one view.
LOG_WEIGHT = 0.03
#: Weight of ``s - 1`` (keeps nodes that no view constrains near 1), and of the Schlick
#: match's ``(x - x_fit) / max(x_fit, PULL_FLOOR)``.
PULL = 1e-3
PULL_FLOOR = 0.02
#: Largest view (deg) of the Schlick match's albedo residuals.
SCHLICK_VIEWS_MAX_DEG = 75.0
#: Views (deg) whose albedo the Schlick match holds below the data's + ALBEDO_ABOVE (those
#: of the fits' own constraint, :data:`microfacet.metrics.ALBEDO_VIEWS_DEG`).
SCHLICK_CAPPED_DEG = (0.0, 30.0, 60.0, 75.0)
#: The ways of :func:`match_albedo`, and its default (module docstring).
METHODS = ("table", "schlick", "schlick_base", "shared", "shared_base", "fallback")
METHOD = "table"
#: Views (deg), albedo floor and tolerance of the albedo band (:func:`band_error`).
BAND_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
BAND_FLOOR = 0.03
BAND_TOLERANCE = 0.05
#: ``method="fallback"``: the Schlick match it tries first, and how much larger than the
#: table match's its log error may be.
FALLBACK_SCHLICK = "shared_base"
FALLBACK_LOG_SLACK = 0.05
#: Largest factor.
S_MAX = 20.0
#: Relative excess of the albedo over the data's beyond which a view is weighed up, and the
#: number of rounds of that (the issue's energy constraint: albedo <= data + 1 %).
ALBEDO_ABOVE = 0.01
OVERSHOOT_ROUNDS = 4
#: Largest total variation of a table over its range (a larger one rings).
TV_LIMIT = 2.0
#: Nodes of the tabulated Fresnel terms, uniform in ``theta_d``.
TABLE_SIZE = 46
#: Quadrature of the albedo (half-vector grid per view, :func:`microfacet.metrics.albedo_directions`).
QUADRATURE = 64
#: Pairs of the log-error term.
LOG_PAIRS = 2**15


class AlbedoTarget(NamedTuple):
    """The data's side of :func:`match_albedo`: its albedo at :data:`VIEWS_DEG` and its log
    error's pairs (made by :func:`albedo_target`).

    Attributes
    ----------
    ratios : microfacet.metrics.AlbedoRatios
        The data's albedo at :data:`VIEWS_DEG`.
    log : microfacet.metrics.LogError
        The data's side of the log error.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = albedo_target(mf.Lambertian(0.5))
    >>> isinstance(t, AlbedoTarget), t.ratios.ref.shape == (len(VIEWS_DEG), 3), t.log.n == LOG_PAIRS
    (True, True, True)
    """
    ratios: AlbedoRatios
    log: LogError


def _theta_d(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(wi * h, axis=-1), -1.0, 1.0))


def _hats(theta_d: np.ndarray) -> np.ndarray:
    """Hat functions of :data:`NODES_DEG` at ``theta_d`` (radians): ``(..., K)``."""
    nodes = np.radians(NODES_DEG)
    eye = np.eye(len(nodes))
    return np.stack([np.interp(theta_d, nodes, eye[k]) for k in range(len(nodes))], axis=-1)


def _lobes(brdf) -> list:
    from ..brdf import MicrofacetBRDF
    return [b for b in getattr(brdf, "brdfs", [brdf]) if isinstance(b, MicrofacetBRDF)]


def albedo_target(reference, log: LogError | None = None) -> AlbedoTarget:
    """The data's side of :func:`match_albedo`: ``reference``'s directional albedo at
    :data:`VIEWS_DEG` on a :data:`QUADRATURE` grid, light directions as the metrics compare
    them (:class:`~microfacet.metrics.AlbedoRatios`), and its log error ``log`` (default
    :class:`~microfacet.metrics.LogError` on :data:`LOG_PAIRS` pairs).

    Parameters
    ----------
    reference : BRDF
        The data.
    log : microfacet.metrics.LogError, optional
        Its log error, if already made (e.g. the fit's judge).

    Returns
    -------
    AlbedoTarget

    Examples
    --------
    >>> import microfacet as mf
    >>> albedo_target(mf.Lambertian(0.5)).ratios.ref.shape
    (12, 3)
    """
    return AlbedoTarget(AlbedoRatios(reference, VIEWS_DEG, n_theta=QUADRATURE, n_phi=QUADRATURE),
                        LogError(reference, n=LOG_PAIRS) if log is None else log)


class _System(NamedTuple):
    """One channel's least squares: relative albedo residuals ``m s - rhs`` (``a'/a_data - 1``
    per view) and the other terms' quadratic ``1/2 s^T h s - g^T s``."""
    m: np.ndarray
    rhs: np.ndarray
    h: np.ndarray
    g: np.ndarray

    def solve(self, t: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, float]:
        """``s = t z`` of least objective over ``0 <= z <= upper``, views whose albedo would
        exceed the data's by more than ``ALBEDO_ABOVE`` weighed up tenfold until none does
        (:data:`OVERSHOOT_ROUNDS`); and its objective with unit weights."""
        w = np.ones(len(self.rhs))
        for _ in range(OVERSHOOT_ROUNDS):
            h = self.m.T @ (w[:, None] * self.m) + self.h
            g = self.m.T @ (w * self.rhs) + self.g
            s = t @ box_qp(t.T @ h @ t, t.T @ g, np.zeros(len(upper)), upper)
            over = self.m @ s - self.rhs > ALBEDO_ABOVE
            if not np.any(over):
                break
            w = np.where(over, 10.0 * w, w)
        h, g = self.m.T @ self.m + self.h, self.m.T @ self.rhs + self.g
        return s, float(0.5 * s @ h @ s - g @ s)


def _systems(target: AlbedoTarget, brdf, lobes) -> list[_System]:
    """The least squares of :func:`albedo_scale` per channel (module docstring)."""
    ratios, log = target
    k = len(NODES_DEG)
    wi, wo, w, view = ratios.nodes
    fitted = ratios.albedo(brdf)
    spec = w[:, None] * sum(np.nan_to_num(np.asarray(b.eval_cos(wi, wo), float)) for b in lobes)
    hats = _hats(_theta_d(wi, wo))
    f = np.maximum(np.nan_to_num(np.asarray(brdf.eval_cos(log.wi, log.wo), float)), 0.0)
    f_spec = sum(np.nan_to_num(np.asarray(b.eval_cos(log.wi, log.wo), float)) for b in lobes)
    log_hats = _hats(_theta_d(log.wi, log.wo))
    d0 = np.log1p(f) - log.ref                                      # log residual before the match
    pair_w = LOG_WEIGHT * log.w / max(float(np.sum(log.w * np.sum(d0 * d0, axis=-1))), 1e-12)
    second = np.diff(np.eye(k), 2, axis=0)
    regular = SMOOTHNESS * second.T @ second + PULL * np.eye(k)
    out = []
    for c in range(3):
        a = np.stack([np.bincount(view, spec[:, c] * hats[:, j], minlength=ratios.n_views) for j in range(k)], axis=-1)
        ref = np.maximum(ratios.ref[:, c], 1e-4)
        m = a / ref[:, None]                                        # a' = fitted + a (s - 1)
        j = (f_spec[:, c] / (1.0 + f[:, c]))[:, None] * log_hats    # d ln(1 + f') / d s
        out.append(_System(m, (ref - fitted[:, c]) / ref + m.sum(axis=1), (j.T * pair_w) @ j + regular,
                           (j.T * pair_w) @ (j.sum(axis=1) - d0[:, c]) + PULL))
    return out


def _shapes(k: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(T, upper)``: ``s = T z`` over ``0 <= z <= upper``: free (``T = I``), then rising to
    a peak at node ``p`` and falling after it, for every ``p``."""
    out = [(np.eye(k), np.full(k, S_MAX))]
    for p in range(k):
        t = np.zeros((k, k))
        for j in range(k):
            t[j, :min(j, p) + 1] = 1.0
            t[j, p + 1:j + 1] = -1.0
        out.append((t, np.full(k, np.inf)))
    return out


def _tables(brdf, s: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """The cosines of the tables and each lobe's ``clip(F s, 0, 1)`` for factors ``s`` ``(K, 3)``."""
    theta = np.linspace(np.pi / 2, 0.0, TABLE_SIZE)
    cos_d, factor = np.cos(theta), _hats(theta) @ s
    return cos_d, [np.clip(np.asarray(b.fresnel(cos_d), float) * factor, 0.0, 1.0) for b in _lobes(brdf)]


def _rings(values: np.ndarray) -> np.ndarray:
    """Per channel: whether a table's total variation exceeds :data:`TV_LIMIT` times its range."""
    tv = np.sum(np.abs(np.diff(values, axis=0)), axis=0)
    return tv > TV_LIMIT * np.ptp(values, axis=0) + 1e-9


def albedo_scale(target: AlbedoTarget, brdf) -> np.ndarray:
    """The factor ``s`` of :func:`match_albedo` on :data:`NODES_DEG`, ``(K, 3)``, for the
    data's :func:`albedo_target` and the fit ``brdf``; ones where it has no microfacet lobe.
    Per channel, the least of the module's quadratic among the shapes whose tables do not
    ring (free, one peak, constant: module docstring).

    Parameters
    ----------
    target : AlbedoTarget
        The data's side (:func:`albedo_target`).
    brdf : MicrofacetBRDF or SumBRDF
        The fit.

    Returns
    -------
    (K, 3) ndarray
        ``s`` per node of :data:`NODES_DEG` and RGB channel.

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25))
    >>> s = albedo_scale(albedo_target(data), fit)
    >>> s.shape == (len(NODES_DEG), 3), bool(s[0, 0] > 1.5)      # SMOOTHNESS, LOG_WEIGHT: module docstring
    (True, True)
    """
    lobes = _lobes(brdf)
    k = len(NODES_DEG)
    s = np.ones((k, 3))
    if not lobes:
        return s
    systems = _systems(target, brdf, lobes)
    solved = [[system.solve(t, upper) for system in systems] for t, upper in _shapes(k)]
    for c, system in enumerate(systems):
        best = np.inf
        for shape in solved:
            s_c, objective = shape[c]
            trial = s.copy()
            trial[:, c] = s_c
            if objective < best and not any(_rings(v)[c] for v in _tables(brdf, trial)[1]):
                s[:, c], best = s_c, objective
        if not np.isfinite(best):                     # a constant factor keeps each table's shape
            s[:, c] = system.solve(np.ones((k, 1)), np.full(1, S_MAX))[0]
    return s


# --- the Schlick match: new Schlick parameters and base colours, no table -------------------

class _Linear(NamedTuple):
    """The fit as ``f = fixed + sum_v x_v basis_v`` on the albedo nodes and the log pairs:
    ``x0`` the fit's own values, ``albedo`` ``(V, n_views, 3)`` each variable's albedo,
    ``log`` ``(V, pairs, 3)`` its ``f cos theta_i`` on the log pairs, and the fixed parts' two."""
    x0: np.ndarray
    albedo: np.ndarray
    log: np.ndarray
    fixed_albedo: np.ndarray
    fixed_log: np.ndarray


def _is_schlick(b) -> bool:
    from .. import fresnel as fr
    from ..brdf import MicrofacetBRDF
    return isinstance(b, MicrofacetBRDF) and type(b.fresnel) is fr.Schlick


def _is_base(b) -> bool:
    from ..brdf import Lambertian
    from ..diffuse import TransmittedLambertian
    return type(b) in (Lambertian, TransmittedLambertian)


def _parts(brdf) -> list:
    return list(getattr(brdf, "brdfs", [brdf]))


def _variables(brdf, bases: bool, shared: bool) -> list[list[tuple[int, str, int, float]]]:
    """The Schlick match's variables, each a list of ``(part, kind, channel, coefficient)``:
    the parameter ``kind`` (``"f0"``, ``"f90"``, ``"base"``) of ``part`` in ``channel`` (-1: all
    three, a grey ``f90``) is ``coefficient x``. Per lobe (``shared`` False): each Schlick
    lobe's ``f0`` per channel and its ``f90`` (one grey variable when it is grey). Shared:
    one factor per channel on every lobe's ``f0`` and one on every lobe's ``f90`` (grey ones
    only; the others per lobe), so that the lobes keep their relative weights. With ``bases``
    the reflectance of each Lambertian and transmitted Lambertian term, per channel."""
    parts = _parts(brdf)
    lobes = [p for p, b in enumerate(parts) if _is_schlick(b)]
    grey = [p for p in lobes if np.ptp(parts[p].fresnel.f90) <= 1e-12]
    out = []
    if shared:
        out += [[(p, "f0", c, float(parts[p].fresnel.f0[c])) for p in lobes] for c in range(3)]
        out.append([(p, "f90", -1, float(parts[p].fresnel.f90[0])) for p in grey])
    else:
        out += [[(p, "f0", c, 1.0)] for p in lobes for c in range(3)]
        out += [[(p, "f90", -1, 1.0)] for p in grey]
    out += [[(p, "f90", c, 1.0)] for p in lobes if p not in grey for c in range(3)]
    if bases:
        out += [[(p, "base", c, 1.0)] for p, b in enumerate(parts) if _is_base(b) for c in range(3)]
    return [v for v in out if any(e[3] > 0 for e in v) or not shared]


def _unit_parts(brdf, wi: np.ndarray, wo: np.ndarray) -> dict:
    """Per varied part, its ``f cos theta_i`` at ``(wi, wo)`` with unit parameters: for a
    Schlick lobe the pair ``(F=1) (1 - m^5)``, ``(F=1) m^5`` (``m = 1 - cos theta_d``), for a
    base its value with reflectance 1 (one channel, ``(M,)`` each)."""
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    out = {}
    m5 = None
    for p, b in enumerate(_parts(brdf)):
        if _is_schlick(b):
            ideal = MicrofacetBRDF(b.distribution, fresnel=fr.Ideal(), gaf=b.gaf_model, shadowing=b.shadowing,
                                   dtype=b.dtype)
            f = np.nan_to_num(np.asarray(ideal.eval_cos(wi, wo), float)[:, 0])
            if m5 is None:
                m5 = (1.0 - np.cos(_theta_d(wi, wo))) ** 5
            out[p] = (f * (1.0 - m5), f * m5)
        elif _is_base(b):
            unit = Lambertian(1.0) if type(b) is Lambertian else TransmittedLambertian(1.0, b.eta)
            out[p] = (np.nan_to_num(np.asarray(unit.eval_cos(wi, wo), float)[:, 0]),)
    return out


def _value(b, kind: str, c: int) -> float:
    if kind == "f0":
        return float(b.fresnel.f0[c])
    if kind == "f90":
        return float(b.fresnel.f90[max(c, 0)])
    return float(b.reflectance[c])


def _linear(target: AlbedoTarget, brdf, variables) -> _Linear:
    """The fit as linear in ``variables`` (:func:`_variables`) on the target's nodes and pairs."""
    ratios, log = target
    wi, wo, w, view = ratios.nodes
    parts = _parts(brdf)
    n = len(variables)
    albedo, on_log = np.zeros((n, ratios.n_views, 3)), np.zeros((n, len(log.wi), 3))
    units_a, units_l = _unit_parts(brdf, wi, wo), _unit_parts(brdf, log.wi, log.wo)
    varied = {e[0] for v in variables for e in v}
    x0 = np.zeros(n)
    for v, entries in enumerate(variables):
        for p, kind, c, coef in entries:
            j = 1 if kind == "f90" else 0
            a = coef * np.bincount(view, w * units_a[p][j], minlength=ratios.n_views)
            for ch in (range(3) if c < 0 else (c,)):
                albedo[v, :, ch] += a
                on_log[v, :, ch] += coef * units_l[p][j]
        p, kind, c, coef = max(entries, key=lambda e: e[3])
        x0[v] = _value(parts[p], kind, c) / coef
    fixed = [b for p, b in enumerate(parts) if p not in varied]
    fixed_albedo = sum((ratios.albedo(b) for b in fixed), np.zeros((ratios.n_views, 3)))
    fixed_log = sum((np.nan_to_num(np.asarray(b.eval_cos(log.wi, log.wo), float)) for b in fixed),
                    np.zeros((len(log.wi), 3)))
    return _Linear(x0, albedo, on_log, fixed_albedo, fixed_log)


def _schlick_system(target: AlbedoTarget, lin: _Linear) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(m, rhs, h, g)``: relative albedo residuals ``m x - rhs`` (rows: views x channels)
    and the log and pull terms' quadratic ``1/2 x^T h x - g^T x`` (module docstring)."""
    ratios, log = target
    ref = np.maximum(ratios.ref, 1e-4)                                  # (n_views, 3)
    rows = np.asarray(VIEWS_DEG) <= SCHLICK_VIEWS_MAX_DEG
    m = (lin.albedo[:, rows] / ref[None, rows]).reshape(len(lin.x0), -1).T     # (views * 3, V)
    rhs = ((ref[rows] - lin.fixed_albedo[rows]) / ref[rows]).ravel()
    f = np.maximum(lin.fixed_log + np.tensordot(lin.x0, lin.log, axes=1), 0.0)     # the fit on the pairs
    d0 = np.log1p(f) - log.ref
    pair_w = LOG_WEIGHT * log.w / max(float(np.sum(log.w * np.sum(d0 * d0, axis=-1))), 1e-12)
    n = len(lin.x0)
    h, g = np.zeros((n, n)), np.zeros(n)
    for c in range(3):
        j = (lin.log[:, :, c] / (1.0 + f[:, c])).T                      # d ln(1 + f) / d x, (pairs, V)
        jw = j * pair_w[:, None]
        h += jw.T @ j
        g += jw.T @ (j @ lin.x0 - d0[:, c])
    scale = 1.0 / np.maximum(lin.x0, PULL_FLOOR) ** 2                   # relative pull toward the fit's values
    h += np.diag(PULL * scale)
    g += PULL * scale * lin.x0
    return m, rhs, h, g


def schlick_parameters(target: AlbedoTarget, brdf, bases: bool = True, shared: bool = False) -> tuple[list, np.ndarray]:
    """The Schlick match's variables and their values: ``(variables, x)``, each variable a
    list of ``(part, kind, channel, coefficient)`` (:func:`match_albedo`'s module docstring:
    parameter ``kind`` (``"f0"``, ``"f90"``, ``"base"``) of part ``part`` of ``brdf`` in
    ``channel`` (-1: all three) equals ``coefficient x``), ``x`` such that every parameter lies
    in ``[0, 1]``: the bounded least squares of the module docstring, views of
    :data:`SCHLICK_CAPPED_DEG` whose albedo would exceed the data's by more than
    :data:`ALBEDO_ABOVE` weighed up tenfold until none does (:data:`OVERSHOOT_ROUNDS`).

    Parameters
    ----------
    target : AlbedoTarget
        The data's side (:func:`albedo_target`).
    brdf : MicrofacetBRDF or SumBRDF
        The fit.
    bases : bool
        Also solve for the colours of its Lambertian and transmitted Lambertian terms.
    shared : bool
        One factor per channel on every lobe's ``f0`` and one on every grey ``f90``, instead of
        each lobe's own parameters.

    Returns
    -------
    variables : list of list of (int, str, int, float)
        Each variable's parameters (part of ``brdf``, its index in a SumBRDF; kind; channel;
        coefficient).
    x : ndarray
        Their values.

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25))
    >>> variables, x = schlick_parameters(albedo_target(data), fit)
    >>> variables[:2], bool(abs(x[0] - 0.5) < 0.02)
    ([[(0, 'f0', 0, 1.0)], [(0, 'f0', 1, 1.0)]], True)
    """
    variables = _variables(brdf, bases, shared)
    if not variables:
        return variables, np.zeros(0)
    lin = _linear(target, brdf, variables)
    m, rhs, h0, g0 = _schlick_system(target, lin)
    n = len(variables)
    upper = np.array([min(1.0 / e[3] for e in v if e[3] > 0) for v in variables])   # every parameter <= 1
    w = np.ones(len(rhs))
    x = lin.x0
    views = np.asarray(VIEWS_DEG)[np.asarray(VIEWS_DEG) <= SCHLICK_VIEWS_MAX_DEG]
    capped = np.repeat(np.isin(views, SCHLICK_CAPPED_DEG), 3)        # rows are (view, channel)
    for _ in range(OVERSHOOT_ROUNDS):
        h = m.T @ (w[:, None] * m) + h0
        g = m.T @ (w * rhs) + g0
        x = box_qp(h, g, np.zeros(n), upper, x0=np.minimum(x, upper))
        over = (m @ x - rhs > ALBEDO_ABOVE) & capped
        if not np.any(over):
            break
        w = np.where(over, 10.0 * w, w)
    return variables, np.clip(x, 0.0, upper)


def _rebuilt(brdf, variables, x):
    """``brdf`` with the values ``x`` of ``variables`` (:func:`schlick_parameters`)."""
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from ..diffuse import TransmittedLambertian
    from .analytic import SumBRDF
    parts = _parts(brdf)
    values = {}
    for entries, v in zip(variables, x):
        for p, kind, c, coef in entries:
            b = parts[p]
            if p not in values:
                values[p] = ({"f0": b.fresnel.f0.copy(), "f90": b.fresnel.f90.copy()} if _is_schlick(b)
                             else {"base": b.reflectance.copy()})
            values[p][kind][slice(None) if c < 0 else c] = np.clip(coef * v, 0.0, 1.0)
    out = []
    for p, b in enumerate(parts):
        if p not in values:
            out.append(b)
        elif _is_schlick(b):
            out.append(MicrofacetBRDF(b.distribution, fresnel=fr.Schlick(values[p]["f0"], values[p]["f90"]),
                                      gaf=b.gaf_model, shadowing=b.shadowing, dtype=b.dtype))
        elif type(b) is Lambertian:
            out.append(Lambertian(values[p]["base"]))
        else:
            out.append(TransmittedLambertian(values[p]["base"], b.eta))
    if isinstance(brdf, SumBRDF):
        return SumBRDF(*out, weights=brdf.weights)
    return out[0]


def band_error(target: AlbedoTarget, brdf) -> float:
    """The largest ``|a_fit / a_data - 1|`` at :data:`BAND_VIEWS_DEG` over the channels whose
    data albedo exceeds :data:`BAND_FLOOR` (the issue's albedo band: within 0.05).

    Parameters
    ----------
    target : AlbedoTarget
        The data's side (:func:`albedo_target`).
    brdf : BRDF
        The fit.

    Returns
    -------
    float
        0 where no channel is above the floor.

    Examples
    --------
    >>> import microfacet as mf
    >>> t = albedo_target(mf.Lambertian(0.5))
    >>> round(band_error(t, mf.Lambertian(0.55)), 3), band_error(t, mf.Lambertian(0.51)) <= BAND_TOLERANCE
    (0.1, True)
    """
    ratios = target.ratios
    rows = [VIEWS_DEG.index(v) for v in BAND_VIEWS_DEG]
    ref = ratios.ref[rows]
    r = ratios.albedo(brdf)[rows] / np.maximum(ref, 1e-12)
    return float(np.max(np.where(ref > BAND_FLOOR, np.abs(r - 1.0), 0.0), initial=0.0))


def _table_match(brdf, target: AlbedoTarget):
    """``brdf`` with each microfacet lobe's Fresnel term ``F`` replaced by the table ``clip(F s, 0, 1)``."""
    from .. import fresnel as fr
    from ..brdf import MicrofacetBRDF
    from .analytic import SumBRDF
    cos_d, tables = _tables(brdf, albedo_scale(target, brdf))
    tables = iter(tables)

    def scaled(b):
        if not isinstance(b, MicrofacetBRDF):
            return b
        return MicrofacetBRDF(b.distribution, fresnel=fr.Tabulated(cos_d, next(tables)), gaf=b.gaf_model,
                              shadowing=b.shadowing, dtype=b.dtype)

    if isinstance(brdf, SumBRDF):
        return SumBRDF(*map(scaled, brdf.brdfs), weights=brdf.weights)
    return scaled(brdf)


def _schlick_match(brdf, target: AlbedoTarget, method: str):
    variables, x = schlick_parameters(target, brdf, bases=method.endswith("_base"), shared=method.startswith("shared"))
    return _rebuilt(brdf, variables, x) if variables else brdf


def match_albedo(reference, brdf, target: AlbedoTarget | None = None, method: str = METHOD):
    """``brdf`` with its directional albedo matched to ``reference``'s at :data:`VIEWS_DEG`
    (module docstring). ``method`` (:data:`METHODS`): ``"table"`` (default) replaces each
    microfacet lobe's Fresnel term ``F`` by the table ``clip(F s, 0, 1)``
    (:func:`albedo_scale`); ``"schlick"`` solves each Schlick lobe's ``f0`` (RGB) and ``f90``,
    ``"shared"`` one factor per channel on every lobe's ``f0`` and one on every ``f90``
    (:func:`schlick_parameters`), ``"..._base"`` with the base colours; ``"fallback"`` is
    :data:`FALLBACK_SCHLICK` where its :func:`band_error` is within :data:`BAND_TOLERANCE` and
    its log error within ``1 + FALLBACK_LOG_SLACK`` times the table match's, else the table
    match. ``target``: the reference's :func:`albedo_target`, to share among fits. A BRDF
    without microfacet lobes is returned as is.

    Parameters
    ----------
    reference : BRDF
        The data (measured or any BRDF).
    brdf : MicrofacetBRDF or SumBRDF
        The fit: a lobe, or a sum of lobes and diffuse terms.
    target : AlbedoTarget, optional
        :func:`albedo_target` of ``reference`` (which is then not read).
    method : str
        One of :data:`METHODS`.

    Returns
    -------
    BRDF
        The same tree with tabulated Fresnel terms (``"table"``: ``TABLE_SIZE`` nodes uniform in
        ``theta_d``), or with Schlick lobes and bases of new values (the Schlick methods).

    Examples
    --------
    >>> import microfacet as mf
    >>> data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.5))
    >>> fit = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.25))
    >>> table = match_albedo(data, fit)
    >>> type(table.fresnel).__name__, bool(abs(table.fresnel(1.0)[0] - 0.5) < 0.02)
    ('Tabulated', True)
    >>> schlick = match_albedo(data, fit, method="schlick")
    >>> type(schlick.fresnel).__name__, bool(abs(schlick.fresnel.f0[0] - 0.5) < 0.02)
    ('Schlick', True)
    >>> METHOD, METHODS[:3]
    ('table', ('table', 'schlick', 'schlick_base'))
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not _lobes(brdf):
        return brdf
    target = albedo_target(reference) if target is None else target
    if method == "table":
        return _table_match(brdf, target)
    if method != "fallback":
        return _schlick_match(brdf, target, method)
    schlick, table = _schlick_match(brdf, target, FALLBACK_SCHLICK), _table_match(brdf, target)
    if (band_error(target, schlick) <= BAND_TOLERANCE
            and target.log(schlick) <= (1.0 + FALLBACK_LOG_SLACK) * target.log(table)):
        return schlick
    return table
