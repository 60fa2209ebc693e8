"""The albedo match as new Schlick parameters: the study code of ``experiments/albedo_schlick.py``.

:func:`microfacet.fit.albedo.match_albedo` matches a fit's directional albedo to the data's by
a smooth table ``s(theta_d)`` on every lobe's Fresnel term. This module is the alternative
measured against it (results: ``experiments/results/albedo_schlick.md``; not adopted). The
albedo is also linear in each Schlick lobe's ``F = f0 + (f90 - f0)(1 - cos theta_d)^5``
(Schlick 1994) parameters and in a Lambertian or transmitted Lambertian base's colour:

    a'(o) = a_fixed(o) + sum_l [f0_l int D G (1 - m^5) ... + f90_l int D G m^5 ...] + k_d a_1(o),

``m = 1 - cos theta_d``, so the table match's least squares (albedo residuals at views up to
:data:`SCHLICK_VIEWS_MAX_DEG`, linearized log error weighed by
:data:`microfacet.fit.albedo.LOG_WEIGHT`, a pull toward the fit's own values relative to
``max(x, PULL_FLOOR)``, the overshoot reweighting at :data:`SCHLICK_CAPPED_DEG`, the views of
the fits' own constraint) is solved for the parameters themselves, each in ``[0, 1]``
(:func:`schlick_parameters`): ``"schlick"`` every lobe's ``f0`` (RGB) and grey ``f90``;
``"shared"`` one factor per channel on every lobe's ``f0`` and one on every ``f90`` (the lobes
keep their relative weights); ``"_base"`` also the base colours. The result has no table and
is held exactly by every export. ``"fallback"`` takes :data:`FALLBACK_SCHLICK` where it
reaches the band (:func:`band_error` within :data:`BAND_TOLERANCE`) at a log error within
:data:`FALLBACK_LOG_SLACK` of the table's, and the table elsewhere.

Only public library names are used; the two small helpers the library keeps private
(``_theta_d``, ``_lobes``) are copied here.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

import microfacet as mf
from microfacet.diffuse import TransmittedLambertian
from microfacet.fit.albedo import (ALBEDO_ABOVE, LOG_WEIGHT, OVERSHOOT_ROUNDS, PULL, VIEWS_DEG, AlbedoTarget,
                                   albedo_target, match_albedo)
from microfacet.fit.extract import box_qp

#: The pull's floor: ``(x - x_fit) / max(x_fit, PULL_FLOOR)``, weighed by ``PULL``.
PULL_FLOOR = 0.02
#: Largest view (deg) of the Schlick match's albedo residuals.
SCHLICK_VIEWS_MAX_DEG = 75.0
#: Views (deg) whose albedo the Schlick match holds below the data's + ALBEDO_ABOVE (those
#: of the fits' own constraint, :data:`microfacet.metrics.ALBEDO_VIEWS_DEG`).
SCHLICK_CAPPED_DEG = (0.0, 30.0, 60.0, 75.0)
#: The ways of :func:`match`: the library's table and the Schlick forms.
METHODS = ("table", "schlick", "schlick_base", "shared", "shared_base", "fallback")
#: Views (deg), albedo floor and tolerance of the albedo band (:func:`band_error`).
BAND_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0)
BAND_FLOOR = 0.03
BAND_TOLERANCE = 0.05
#: ``method="fallback"``: the Schlick match it tries first, and how much larger than the
#: table match's its log error may be.
FALLBACK_SCHLICK = "shared_base"
FALLBACK_LOG_SLACK = 0.05


class Linear(NamedTuple):
    """The fit as ``f = fixed + sum_v x_v basis_v`` on the albedo nodes and the log pairs:
    ``x0`` the fit's own values, ``albedo`` ``(V, n_views, 3)`` each variable's albedo,
    ``log`` ``(V, pairs, 3)`` its ``f cos theta_i`` on the log pairs, and the fixed parts' two."""
    x0: np.ndarray
    albedo: np.ndarray
    log: np.ndarray
    fixed_albedo: np.ndarray
    fixed_log: np.ndarray


def theta_d(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """The difference angle (radians) of directions ``wi``, ``wo`` (as the library's table match)."""
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    return np.arccos(np.clip(np.sum(wi * h, axis=-1), -1.0, 1.0))


def parts(brdf) -> list:
    return list(getattr(brdf, "brdfs", [brdf]))


def has_lobes(brdf) -> bool:
    return any(isinstance(b, mf.MicrofacetBRDF) for b in parts(brdf))


def is_schlick(b) -> bool:
    return isinstance(b, mf.MicrofacetBRDF) and type(b.fresnel) is mf.fresnel.Schlick


def is_base(b) -> bool:
    return type(b) in (mf.Lambertian, TransmittedLambertian)


def variables_of(brdf, bases: bool, shared: bool) -> list[list[tuple[int, str, int, float]]]:
    """The Schlick match's variables, each a list of ``(part, kind, channel, coefficient)``:
    the parameter ``kind`` (``"f0"``, ``"f90"``, ``"base"``) of ``part`` in ``channel`` (-1: all
    three, a grey ``f90``) is ``coefficient x``. Per lobe (``shared`` False): each Schlick
    lobe's ``f0`` per channel and its ``f90`` (one grey variable when it is grey). Shared:
    one factor per channel on every lobe's ``f0`` and one on every lobe's ``f90`` (grey ones
    only; the others per lobe), so that the lobes keep their relative weights. With ``bases``
    the reflectance of each Lambertian and transmitted Lambertian term, per channel."""
    ps = parts(brdf)
    lobes = [p for p, b in enumerate(ps) if is_schlick(b)]
    grey = [p for p in lobes if np.ptp(ps[p].fresnel.f90) <= 1e-12]
    out = []
    if shared:
        out += [[(p, "f0", c, float(ps[p].fresnel.f0[c])) for p in lobes] for c in range(3)]
        out.append([(p, "f90", -1, float(ps[p].fresnel.f90[0])) for p in grey])
    else:
        out += [[(p, "f0", c, 1.0)] for p in lobes for c in range(3)]
        out += [[(p, "f90", -1, 1.0)] for p in grey]
    out += [[(p, "f90", c, 1.0)] for p in lobes if p not in grey for c in range(3)]
    if bases:
        out += [[(p, "base", c, 1.0)] for p, b in enumerate(ps) if is_base(b) for c in range(3)]
    return [v for v in out if any(e[3] > 0 for e in v) or not shared]


def unit_parts(brdf, wi: np.ndarray, wo: np.ndarray) -> dict:
    """Per varied part, its ``f cos theta_i`` at ``(wi, wo)`` with unit parameters: for a
    Schlick lobe the pair ``(F=1) (1 - m^5)``, ``(F=1) m^5`` (``m = 1 - cos theta_d``), for a
    base its value with reflectance 1 (one channel, ``(M,)`` each)."""
    out = {}
    m5 = None
    for p, b in enumerate(parts(brdf)):
        if is_schlick(b):
            ideal = mf.MicrofacetBRDF(b.distribution, fresnel=mf.fresnel.Ideal(), gaf=b.gaf_model,
                                      shadowing=b.shadowing, dtype=b.dtype)
            f = np.nan_to_num(np.asarray(ideal.eval_cos(wi, wo), float)[:, 0])
            if m5 is None:
                m5 = (1.0 - np.cos(theta_d(wi, wo))) ** 5
            out[p] = (f * (1.0 - m5), f * m5)
        elif is_base(b):
            unit = mf.Lambertian(1.0) if type(b) is mf.Lambertian else TransmittedLambertian(1.0, b.eta)
            out[p] = (np.nan_to_num(np.asarray(unit.eval_cos(wi, wo), float)[:, 0]),)
    return out


def value(b, kind: str, c: int) -> float:
    if kind == "f0":
        return float(b.fresnel.f0[c])
    if kind == "f90":
        return float(b.fresnel.f90[max(c, 0)])
    return float(b.reflectance[c])


def linear(target: AlbedoTarget, brdf, variables) -> Linear:
    """The fit as linear in ``variables`` (:func:`variables_of`) on the target's nodes and pairs."""
    ratios, log = target
    wi, wo, w, view = ratios.nodes
    ps = parts(brdf)
    n = len(variables)
    albedo, on_log = np.zeros((n, ratios.n_views, 3)), np.zeros((n, len(log.wi), 3))
    units_a, units_l = unit_parts(brdf, wi, wo), unit_parts(brdf, log.wi, log.wo)
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
        x0[v] = value(ps[p], kind, c) / coef
    fixed = [b for p, b in enumerate(ps) if p not in varied]
    fixed_albedo = sum((ratios.albedo(b) for b in fixed), np.zeros((ratios.n_views, 3)))
    fixed_log = sum((np.nan_to_num(np.asarray(b.eval_cos(log.wi, log.wo), float)) for b in fixed),
                    np.zeros((len(log.wi), 3)))
    return Linear(x0, albedo, on_log, fixed_albedo, fixed_log)


def schlick_system(target: AlbedoTarget, lin: Linear) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
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
    """The Schlick match's variables and their values ``(variables, x)`` (:func:`variables_of`),
    ``x`` such that every parameter lies in ``[0, 1]``: the bounded least squares of the module
    docstring, views of :data:`SCHLICK_CAPPED_DEG` whose albedo would exceed the data's by more
    than ``ALBEDO_ABOVE`` weighed up tenfold until none does (``OVERSHOOT_ROUNDS``)."""
    variables = variables_of(brdf, bases, shared)
    if not variables:
        return variables, np.zeros(0)
    lin = linear(target, brdf, variables)
    m, rhs, h0, g0 = schlick_system(target, lin)
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


def rebuilt(brdf, variables, x):
    """``brdf`` with the values ``x`` of ``variables`` (:func:`schlick_parameters`)."""
    ps = parts(brdf)
    values = {}
    for entries, v in zip(variables, x):
        for p, kind, c, coef in entries:
            b = ps[p]
            if p not in values:
                values[p] = ({"f0": b.fresnel.f0.copy(), "f90": b.fresnel.f90.copy()} if is_schlick(b)
                             else {"base": b.reflectance.copy()})
            values[p][kind][slice(None) if c < 0 else c] = np.clip(coef * v, 0.0, 1.0)
    out = []
    for p, b in enumerate(ps):
        if p not in values:
            out.append(b)
        elif is_schlick(b):
            out.append(mf.MicrofacetBRDF(b.distribution, fresnel=mf.fresnel.Schlick(values[p]["f0"], values[p]["f90"]),
                                         gaf=b.gaf_model, shadowing=b.shadowing, dtype=b.dtype))
        elif type(b) is mf.Lambertian:
            out.append(mf.Lambertian(values[p]["base"]))
        else:
            out.append(TransmittedLambertian(values[p]["base"], b.eta))
    if isinstance(brdf, mf.fit.SumBRDF):
        return mf.fit.SumBRDF(*out, weights=brdf.weights)
    return out[0]


def band_error(target: AlbedoTarget, brdf) -> float:
    """The largest ``|a_fit / a_data - 1|`` at :data:`BAND_VIEWS_DEG` over the channels whose
    data albedo exceeds :data:`BAND_FLOOR` on the target's quadrature; 0 where none is above."""
    ratios = target.ratios
    rows = [VIEWS_DEG.index(v) for v in BAND_VIEWS_DEG]
    ref = ratios.ref[rows]
    r = ratios.albedo(brdf)[rows] / np.maximum(ref, 1e-12)
    return float(np.max(np.where(ref > BAND_FLOOR, np.abs(r - 1.0), 0.0), initial=0.0))


def schlick_match(brdf, target: AlbedoTarget, method: str):
    variables, x = schlick_parameters(target, brdf, bases=method.endswith("_base"), shared=method.startswith("shared"))
    return rebuilt(brdf, variables, x) if variables else brdf


def match(reference, brdf, target: AlbedoTarget | None = None, method: str = "table"):
    """``brdf`` with its directional albedo matched to ``reference``'s by ``method``
    (:data:`METHODS`, module docstring); ``"table"`` is the library's
    :func:`~microfacet.fit.albedo.match_albedo`. A BRDF without microfacet lobes is returned as is."""
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if not has_lobes(brdf):
        return brdf
    target = albedo_target(reference) if target is None else target
    if method == "table":
        return match_albedo(None, brdf, target)
    if method != "fallback":
        return schlick_match(brdf, target, method)
    schlick, table = schlick_match(brdf, target, FALLBACK_SCHLICK), match_albedo(None, brdf, target)
    if (band_error(target, schlick) <= BAND_TOLERANCE
            and target.log(schlick) <= (1.0 + FALLBACK_LOG_SLACK) * target.log(table)):
        return schlick
    return table
