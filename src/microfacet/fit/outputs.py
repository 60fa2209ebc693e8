"""What ``microfacet fit`` writes: a fit's files and the summary table of a folder of fits.

For a material fitted by :func:`microfacet.fit.fit` (power iterations, thesis Ch. 4) and
:func:`microfacet.fit.fit_analytic` (least squares, started from the moment conversion):

* ``NAME.npz`` — the tabulated fit (``fit.save``), loadable by :func:`microfacet.fit.load`;
* ``NAME.json`` — ``"ggx"`` and ``"beckmann"``: the analytic fits of the chosen method
  (``least_squares`` by default: :func:`microfacet.fit.fit_analytic`, with a diffuse
  base unless it fits to less than :data:`NEGLIGIBLE_BASE` for ``diffuse="auto"``, with
  a coat for ``coat=True``; ``moments``: ``fit.to_ggx(reference=data)``,
  ``fit.to_beckmann(reference=data)``: Fresnel tables solved against the data), each
  ``{"alpha_x", "alpha_y", "rho", "fresnel", "coat", "diffuse"}`` (``coat``: ``{"alpha",
  "fresnel"}`` or null; ``diffuse``: the Lambertian reflectance, RGB, or null);
  ``"moments"`` and ``"least_squares"``: every fit of each method by name; ``"fresnel"`` (the tabulated fit's), ``"seconds"`` (fit
  times), ``"errors"`` (per fit name: the grid error of
  :func:`microfacet.metrics.fit_error`; ``"uniform"``: :func:`~microfacet.metrics.uniform_error`;
  ``"albedo_ratio"``: :func:`~microfacet.metrics.albedo_ratios`, views x RGB;
  ``"white_furnace"``: :func:`~microfacet.metrics.white_furnace`), the options, and for a
  MERL table ``"data": {"fold_seam"}`` (:meth:`microfacet.measured.MERLBRDF.fold_seam`: above
  :data:`microfacet.measured.merl.SEAM_LIMIT` the data are not reciprocal, and the printed
  table says so);
* ``NAME.png`` — the spheres of the data, the best fit and the tabulated fit (or the best
  analytic fit where the tabulated fit is the best), with their errors
  (:func:`microfacet.render.fit_spheres_png`; with ``curves``, the comparison picture of
  :func:`microfacet.render.fit_comparison_png`, their curves too).

:func:`analytic_from_json` rebuilds an analytic fit from its JSON entry. A folder of
materials is a batch (:mod:`microfacet.batch`, task ``fit``): one such triple per
material and ``summary.csv`` / ``summary.md`` with the figures of :func:`summary_row`.
Every file is written atomically.

Examples
--------
>>> METHODS, DIFFUSE, SUMMARY_COLUMNS[:5]
(('least_squares', 'moments'), ('auto', 'on', 'off'), ('material', 'file', 'format', 'status', 'seconds'))
"""
from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from threadpoolctl import threadpool_limits

from .._background import Handoff, can_fork, in_background, in_process_items
from ..errors import MicrofacetError
from ..io.names import material_name
from ..metrics import (ALBEDO_VIEWS_DEG, AlbedoRatios, RelativeRMS, describe_albedo, describe_fit_error,
                       describe_uniform_error, measurement_directions, uniform_directions, white_furnace)
from .albedo import albedo_target, match_albedo
from .colour import CAST_TRIGGER, IMAGE_TOLERANCE, balance_colour, colour_target

__all__ = ["material_name", "fit_material", "distribution_params",
           "fresnel_json", "analytic_json", "analytic_from_json", "summary_row",
           "format_summary_markdown", "objective", "SUMMARY_COLUMNS", "METHODS",
           "DIFFUSE"]

#: Conversion methods of the analytic fits.
METHODS = ("least_squares", "moments")
#: Diffuse-base choices of the least-squares fits: with, dropped where negligible; with; without.
DIFFUSE = ("auto", "on", "off")
#: ``diffuse="auto"`` drops a fitted base whose reflectance is below this in every channel.
NEGLIGIBLE_BASE = 2e-3
_KINDS = ("tabulated", "ggx", "beckmann")
#: Columns of ``summary.csv`` (``summary.md`` shows the same, formatted).
SUMMARY_COLUMNS = ("material", "file", "format", "status", "seconds", "best", "log_best", "image_best",
                   "image_tabulated", "method",
                   *(f"error_{k}" for k in _KINDS), *(f"uniform_{k}" for k in _KINDS),
                   *(f"albedo_{k}" for k in _KINDS), "error_ggx_moments",
                   "ggx_alpha_x", "ggx_alpha_y", "ggx_rho", "ggx_diffuse",
                   "beckmann_alpha_x", "beckmann_alpha_y", "beckmann_rho", "beckmann_diffuse")


def distribution_params(brdf) -> dict[str, float]:
    """``{"alpha_x", "alpha_y", "rho"}`` of a :class:`microfacet.MicrofacetBRDF`.

    Parameters
    ----------
    brdf : MicrofacetBRDF
        A lobe over an analytic distribution.

    Returns
    -------
    dict
        ``{"alpha_x", "alpha_y", "rho"}`` as floats (``rho`` 0 below 1e-12).

    Examples
    --------
    >>> import microfacet as mf
    >>> distribution_params(mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4, rho=0.1)))
    {'alpha_x': 0.2, 'alpha_y': 0.4, 'rho': 0.1}
    """
    d = brdf.distribution
    rho = float(d.rho)
    return {"alpha_x": float(d.alpha_x), "alpha_y": float(d.alpha_y),
            "rho": 0.0 if abs(rho) < 1e-12 else rho}      # isotropic fits: rounding noise


def fresnel_json(fresnel) -> dict:
    """A JSON-able description of a Fresnel term: its type and parameters or samples.

    Parameters
    ----------
    fresnel : microfacet.fresnel.Fresnel
        Any Fresnel term.

    Returns
    -------
    dict
        ``{"type", ...}``: its parameters, or ``cos_theta_d`` and ``rgb`` samples for a table.

    Examples
    --------
    >>> import microfacet as mf
    >>> fresnel_json(mf.fresnel.Schlick(0.04))
    {'type': 'schlick', 'f0': [0.04, 0.04, 0.04], 'f90': [1.0, 1.0, 1.0]}
    >>> fresnel_json(mf.fresnel.Conductor(eta=0.2, k=3.0))
    {'type': 'conductor', 'eta': [0.2, 0.2, 0.2], 'k': [3.0, 3.0, 3.0]}
    """
    kind = type(fresnel).__name__.lower()
    if hasattr(fresnel, "cos_theta_d") and hasattr(fresnel, "values"):
        return {"type": kind, "cos_theta_d": np.asarray(fresnel.cos_theta_d, float).round(6).tolist(),
                "rgb": np.asarray(fresnel.values, float).round(6).tolist()}
    params = {k: np.asarray(v).tolist() for k, v in vars(fresnel).items()
              if not k.startswith("_") and isinstance(v, (int, float, np.ndarray, tuple, list))}
    return {"type": kind, **params}


def _fit_fresnel(fit):
    """The fitted Fresnel term: ``fit.fresnel``, else the GGX fit's."""
    f = getattr(fit, "fresnel", None)
    return f if f is not None else fit.to_ggx().fresnel


def _parts(brdf):
    """``(microfacet lobe, coat lobe or None, Lambertian base or None)`` of an analytic fit."""
    from ..brdf import Lambertian
    parts = list(getattr(brdf, "brdfs", [brdf]))
    base = parts.pop() if isinstance(parts[-1], Lambertian) else None
    return parts[0], (parts[1] if len(parts) > 1 else None), base


def analytic_json(brdf) -> dict:
    """``{"model", "alpha_x", "alpha_y", "rho", "mean_slope", "gaf", "fresnel", "coat", "diffuse"}``
    of an analytic fit (a MicrofacetBRDF, or a SumBRDF of one, an optional coat lobe and an
    optional Lambertian base); ``"coat"``: ``{"alpha", "fresnel"}`` or null.

    Parameters
    ----------
    brdf : MicrofacetBRDF or SumBRDF
        An analytic fit: a lobe, optionally with a coat lobe and a Lambertian base.

    Returns
    -------
    dict
        The JSON-able entry.

    Examples
    --------
    >>> import microfacet as mf
    >>> entry = analytic_json(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2), mf.fresnel.Schlick(0.9)))
    >>> entry["model"], entry["alpha_x"], entry["gaf"], entry["coat"], entry["diffuse"]
    ('beckmann', 0.2, 'smith', None, None)
    """
    lobe, coat, base = _parts(brdf)
    return {"model": type(lobe.distribution).__name__.lower(), **distribution_params(lobe),
            "mean_slope": np.asarray(lobe.distribution.mean_slope, float).tolist(), "gaf": lobe.gaf_model,
            "fresnel": fresnel_json(lobe.fresnel),
            "coat": None if coat is None else {"alpha": float(coat.distribution.alpha_x),
                                                "fresnel": fresnel_json(coat.fresnel)},
            "diffuse": None if base is None else np.asarray(base.reflectance, float).round(6).tolist()}


def analytic_from_json(entry: dict):
    """The BRDF of an :func:`analytic_json` entry (inverse up to the rounding of tables).

    Parameters
    ----------
    entry : dict
        An :func:`analytic_json` entry.

    Returns
    -------
    MicrofacetBRDF or SumBRDF
        The lobe, with its coat lobe and Lambertian base when the entry has them.

    Examples
    --------
    >>> import microfacet as mf
    >>> brdf = analytic_from_json(analytic_json(mf.MicrofacetBRDF(mf.GGX(alpha=0.3))))
    >>> brdf
    MicrofacetBRDF(GGX(alpha_x=0.3, alpha_y=0.3, rho=0.0, mean_slope=[0.0, 0.0]), fresnel=Ideal(), gaf='smith', shadowing=True)
    """
    from .. import fresnel as fr
    from ..brdf import Lambertian, MicrofacetBRDF
    from .analytic import MODELS, SumBRDF
    kinds = {"schlick": lambda f: fr.Schlick(f["f0"]), "conductor": lambda f: fr.Conductor(f["eta"], f["k"]),
             "tabulated": lambda f: fr.Tabulated(f["cos_theta_d"], f["rgb"]), "ideal": lambda f: fr.Ideal()}
    coat = entry.get("coat")
    fresnels = [entry["fresnel"]] + ([coat["fresnel"]] if coat else [])
    if entry.get("model") not in MODELS or any(f.get("type") not in kinds for f in fresnels):
        raise ValueError(f"not an analytic fit entry: model {entry.get('model')!r}, "
                         f"fresnel {[f.get('type') for f in fresnels]!r}")
    family, gaf = MODELS[entry["model"]], entry.get("gaf", "smith")
    dist = family(alpha_x=entry["alpha_x"], alpha_y=entry["alpha_y"], rho=entry["rho"],
                  mean_slope=entry.get("mean_slope", (0.0, 0.0)))
    parts = [MicrofacetBRDF(dist, fresnel=kinds[fresnels[0]["type"]](fresnels[0]), gaf=gaf)]
    if coat:
        parts.append(MicrofacetBRDF(family(alpha=coat["alpha"]), fresnel=kinds[fresnels[1]["type"]](fresnels[1]),
                                    gaf=gaf))
    if entry.get("diffuse") is not None:
        parts.append(Lambertian(entry["diffuse"]))
    return parts[0] if len(parts) == 1 else SumBRDF(*parts)


def _run_fit(brdf, resolution: int, anisotropic: bool, gaf: str, tabulated_diffuse: bool, albedo_weight: float):
    from .fitted import fit
    return fit(brdf, resolution=resolution, anisotropic=anisotropic, gaf=gaf, diffuse=tabulated_diffuse,
               albedo_weight=None if anisotropic else albedo_weight)       # anisotropic: fit's default 0


def _write_all(files: dict) -> None:
    """Write ``{path: bytes}`` in order, each atomically; if one write fails (or is
    interrupted), the files already written are removed, so a fit never leaves part of
    its outputs (as ``microfacet bake``)."""
    from ..io import write_bytes
    written = []
    try:
        for path, data in files.items():
            write_bytes(path, data)
            written.append(Path(path))
    except BaseException:                          # Ctrl-C, a full disk: all or nothing
        for path in written:
            path.unlink(missing_ok=True)
        raise


def _least_squares_fit(brdf, fit, model: str, anisotropic: bool, diffuse: str, fresnel: str, albedo_weight: float,
                       coat: bool = False) -> tuple[str, object]:
    """``(name, fit)``: the least-squares fit of ``model`` named as ``ggx``,
    ``ggx_diffuse``, ``beckmann_coat_diffuse``, ....
    ``diffuse="auto"``: one fit with a base, the base dropped where it fits to less than
    :data:`NEGLIGIBLE_BASE` (the model without a base is the special case ``k_d = 0`` of
    the one with, so fitting both is redundant)."""
    from .analytic import SumBRDF, fit_analytic
    b = fit_analytic(brdf, model, diffuse=diffuse != "off", anisotropic=anisotropic, fresnel=fresnel, coat=coat,
                     start=fit, albedo_weight=albedo_weight)
    *lobes, base = _parts(b)
    if diffuse == "auto" and base is not None and np.all(base.reflectance < NEGLIGIBLE_BASE):
        b, base = (lobes[0] if lobes[1] is None else SumBRDF(*lobes)), None
    return f"{model}{'_coat' if coat else ''}{'_diffuse' if base is not None else ''}", b


def _metrics(brdf) -> tuple:
    """The data's side of the metrics: the :class:`~microfacet.metrics.RelativeRMS` of the
    grid and of the uniform pairs and the :class:`~microfacet.metrics.AlbedoRatios` of ``brdf``."""
    return RelativeRMS(brdf, measurement_directions()), RelativeRMS(brdf, uniform_directions()), AlbedoRatios(brdf)


def _scores(metrics: tuple, named: dict) -> tuple[dict, dict, dict]:
    """Grid errors, uniform errors and albedo ratios of the fits ``named`` (``metrics``:
    :func:`_metrics` of the data)."""
    grid, uniform, albedo = metrics
    return grid(named), uniform(named), albedo(named)


def objective(grid: float, uniform: float, albedo_ratio, albedo_weight: float) -> float:
    """The objective of :func:`microfacet.fit.fit_analytic` from the metrics:
    ``e_grid^2 + e_uniform^2 + albedo_weight^2 mean((ratio - 1)^2)`` (views x RGB, NaN ratios
    left out); :func:`fit_material` keeps the least-squares fit of least value.

    Parameters
    ----------
    grid, uniform : float
        Relative RMS errors on the measurement grid and on uniform pairs.
    albedo_ratio : (V, 3) array_like
        Albedo ratios fit/data per view and RGB channel.
    albedo_weight : float
        Weight of the albedo term.

    Returns
    -------
    float
        The objective.

    Examples
    --------
    >>> import numpy as np
    >>> round(objective(0.1, 0.2, np.array([[1.1, 1.1, 1.1]]), albedo_weight=1.0), 6)   # 0.01 + 0.04 + 0.01
    0.06
    """
    r = np.asarray(albedo_ratio, dtype=np.float64)
    r = r[np.isfinite(r)]
    return grid**2 + uniform**2 + (albedo_weight**2 * float(np.mean((r - 1.0) ** 2)) if len(r) else 0.0)


@threadpool_limits.wrap(limits=1, user_api="blas")     # one BLAS thread per process: its processes use the cores
def fit_material(brdf, out_npz: str | os.PathLike, resolution: int = 90, anisotropic: bool = False,
                 gaf: str = "smith", title: str = "", method: str = "least_squares", diffuse: str = "auto",
                 fresnel: str = "table", tabulated_diffuse: bool = False, picture: bool = True,
                 albedo_weight: float | None = None, coat: bool = False, curves: bool = False) -> dict:
    """Fit ``brdf`` and write ``out_npz`` with its ``.json`` and ``.png`` beside it
    (its folder is created if needed).

    ``method`` (:data:`METHODS`) chooses the ``"ggx"``/``"beckmann"`` fits of the JSON
    and picture; ``diffuse`` (:data:`DIFFUSE`) and ``fresnel`` are those of the
    least-squares fits (:func:`microfacet.fit.fit_analytic`; ``coat``: each with a coat
    lobe), ``albedo_weight`` the weight of their albedo term and of the isotropic
    tabulated fit's (an anisotropic one keeps :func:`microfacet.fit.fit`'s 0; default :data:`microfacet.fit.analytic.ALBEDO_WEIGHT`, equal to
    :data:`microfacet.fit.fitted.ALBEDO_WEIGHT`). ``tabulated_diffuse`` is forwarded to
    :func:`microfacet.fit.fit` as ``diffuse``. The picture is rendered in memory first,
    then the three files are written, each atomically; if a write fails or is interrupted
    the ones already written are removed (no ``.npz`` without its ``.json`` and
    ``.png``). The perceptual fits and, where this process can fork, the tabulated fit and
    the fits made from it run in processes of their own
    (:func:`microfacet._background.in_process_items`; the same bytes as in this process):
    the perceptual fits matched to the data's albedo, colour balanced where their spheres show
    a cast (:func:`_judged`) and judged here as they come, on two threads, the others judged in
    their process (with the data's side of the metrics, made here while they are fitted); with
    ``curves``, the picture's drawing warms up on another thread meanwhile
    (:func:`microfacet.render.compare.warm_up`). Returns the JSON summary (module
    docstring); ``seconds`` holds the time of the tabulated fit and of the least-squares
    fits (wall; not of the errors, picture or files).

    Parameters
    ----------
    brdf : BRDF
        The material to fit (a measured BRDF or any object with ``eval``).
    out_npz : str or PathLike
        The fit file; ``.json`` and ``.png`` are written beside it.
    resolution, anisotropic, gaf
        Of the tabulated fit (:func:`microfacet.fit.fit`).
    title : str
        The picture's title (default: the material's name from ``out_npz``).
    method : {"least_squares", "moments"}
        How the GGX and Beckmann fits of the JSON and picture are made.
    diffuse : {"auto", "on", "off"}
        Lambertian base of the least-squares fits.
    fresnel : {"conductor", "schlick", "table"}
        Fresnel model of the least-squares fits.
    tabulated_diffuse : bool
        A Lambertian base for the tabulated fit.
    picture : bool
        Render and write the ``.png``: the spheres of the data and of the best and tabulated
        fits (:func:`microfacet.render.fit_spheres_png`).
    albedo_weight : float, optional
        Weight of the albedo term of the fits.
    coat : bool
        Fit each least-squares model with a clear coat lobe too.
    curves : bool
        Draw the picture with its backscattering and in-plane curves too
        (:func:`microfacet.render.fit_comparison_png`; Matplotlib, about 0.5 s more).

    Returns
    -------
    dict
        The JSON summary (module docstring).

    Examples
    --------
    >>> import microfacet as mf
    >>> reference = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), mf.fresnel.Schlick(0.04))
    >>> summary = fit_material(reference, "fits/ggx.npz", resolution=8, picture=False, diffuse="off")  # ~2 s  # doctest: +SKIP
    >>> sorted(p.name for p in __import__("pathlib").Path("fits").iterdir())      # doctest: +SKIP
    ['ggx.json', 'ggx.npz']
    >>> summary["best"], summary["ggx"]["model"], round(summary["ggx"]["alpha_x"], 2)  # doctest: +SKIP
    ('lobe', 'ggx', 0.3)
    """
    from .analytic import ALBEDO_WEIGHT
    albedo_weight = ALBEDO_WEIGHT if albedo_weight is None else float(albedo_weight)
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if diffuse not in DIFFUSE:
        raise ValueError(f"diffuse must be one of {DIFFUSE}, got {diffuse!r}")
    out_npz = Path(out_npz)
    if out_npz.is_dir():
        raise MicrofacetError(f"{out_npz}: is a folder")
    out_npz.parent.mkdir(parents=True, exist_ok=True)     # before the work, not after
    settings = {"resolution": int(resolution), "anisotropic": bool(anisotropic), "gaf": gaf, "diffuse": diffuse,
                "fresnel_model": fresnel, "albedo_weight": albedo_weight, "coat": bool(coat),
                "tabulated_diffuse": bool(tabulated_diffuse)}
    # first, forked before any thread starts, on the NumPy path only (the CLI's: Numba's
    # GNU OpenMP kernels abort a forked child); the data's side of the metrics is made here
    # while the children fit, and handed to the legacy fits' child
    from .. import kernels
    from .perceptual import target as perceptual_target
    models = PERCEPTUAL_MODELS + (("coat",) if coat and not anisotropic else ())
    data_side = Handoff()
    legacy_items = (in_process_items if can_fork() and not kernels.AVAILABLE else _run_here)(
        _legacy_item, brdf, method, settings, data_side)
    try:
        perceptual_items = in_process_items(_perceptual, perceptual_target(brdf), models)
        metrics, judges = _metrics(brdf), _judges(brdf)
    except BaseException:
        data_side.put(None)                         # the legacy fits' child stops
        raise
    data_side.put((metrics, judges))
    _import_numba()
    if picture and curves:          # Matplotlib's imports and fonts, on a thread while the fits run
        from ..render.compare import warm_up
        drawing = in_background(warm_up)
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(2) as pool, ThreadPoolExecutor(1) as feeder:
        # each perceptual fit is judged as it comes, while the legacy fits are made and judged
        # (in a process of their own where one can fork)
        targets = albedo_target(brdf, log=judges[0]), _Once(lambda: colour_target(brdf))
        judged = feeder.submit(_judge_perceptual, perceptual_items, targets, metrics, judges, pool)
        (legacy, scores, fits_summary), = legacy_items
        perceptual, t3 = judged.result()
    for name in (m for m in models if m in perceptual):     # in the order of the models
        fits_summary[name] = perceptual[name][1]
    perceptual = {name: b for name, (b, _) in perceptual.items()}
    best = best_fit({k: v["metrics"] for k, v in fits_summary.items()})
    summary = {**_legacy_json(legacy, scores, method), **settings, "best": best, "fits": fits_summary,
               "seconds_perceptual": round(t3 - legacy.times[1], 4)}
    if hasattr(brdf, "fold_seam"):
        summary["data"] = {"fold_seam": round(brdf.fold_seam(), 4)}
    if legacy.moments_failed:
        summary["moments_failed"] = legacy.moments_failed
    specs = {k: v["model"] for k, v in fits_summary.items() if k != "tabulated"}
    files = {out_npz: legacy.fit.to_bytes(fits=specs, best=best),
             out_npz.with_suffix(".json"): (json.dumps(summary, indent=2) + "\n").encode()}
    if picture:                                     # rendered before any file is written
        from .. import render
        shown, notes = _shown_fits({**legacy.named, **perceptual}, fits_summary, best)
        brdfs, title = {"data": brdf, **shown}, title or material_name(out_npz)
        if curves:
            drawing.result()
            png = render.fit_comparison_png(brdfs, title=title, planes_deg=(0, 90) if anisotropic else (0,),
                                            notes=notes)
        else:
            png = render.fit_spheres_png(brdfs, title=title, notes=notes)
        files[out_npz.with_suffix(".png")] = png
    _write_all(files)
    return summary


class _Legacy(NamedTuple):
    """The tabulated fit, its moment conversions and the least-squares fits (``named``, by
    name) and the times ``(t0, t1, t2)``: start, tabulated fit done, least-squares fits done."""
    fit: object
    moments: dict
    moments_failed: dict
    least: dict
    named: dict
    times: tuple


def _run_here(fn, *args):
    """``fn(*args)``: the generator of :func:`in_process_items`, run in this process as it is read."""
    return fn(*args)


def _legacy_item(brdf, method: str, settings: dict, data_side: Handoff):
    """``(legacy, scores, summaries)``: :func:`_legacy_fits`, their :func:`_scores` and white
    furnaces, and :func:`_fit_summaries` (``data_side``: the :class:`~microfacet._background.Handoff`
    of :func:`_metrics` and :func:`_judges` of the data, made while the fits are), as the one
    item of a generator (for :func:`in_process_items`); none if no data's side comes."""
    legacy = _legacy_fits(brdf, method, settings)
    data = data_side.get()
    if data is None:
        return
    metrics, judges = data
    scores = _scores(metrics, legacy.named)
    furnace = {k: white_furnace(b) for k, b in legacy.named.items()}
    yield legacy, (*scores, furnace), _fit_summaries(judges, legacy.named, scores, metrics[2].ref)


def _legacy_fits(brdf, method: str, settings: dict) -> _Legacy:
    """The tabulated fit and the fits made from it, one after the other."""
    t0 = time.perf_counter()
    fit = _run_fit(brdf, settings["resolution"], settings["anisotropic"], settings["gaf"],
                   settings["tabulated_diffuse"], settings["albedo_weight"])
    t1 = time.perf_counter()
    least = dict(_least_squares_fit(brdf, fit, model, settings["anisotropic"], settings["diffuse"],
                                    settings["fresnel_model"], settings["albedo_weight"], settings["coat"])
                 for model in (("ggx", "beckmann") if method == "least_squares" else ()))
    t2 = time.perf_counter()
    moments, moments_failed = _moment_fits(fit, brdf, required=method == "moments")
    named = {"tabulated": fit, **{f"{k}_moments": b for k, b in moments.items()},
             **{f"{k}_least_squares": b for k, b in least.items()}}
    return _Legacy(fit, moments, moments_failed, least, named, (t0, t1, t2))


def _legacy_json(legacy: _Legacy, scores: tuple, method: str) -> dict:
    """The summary's entries of the tabulated, moment and least-squares fits: the headline
    ``"ggx"``/``"beckmann"`` fits of ``method``, every fit's parameters, errors (``scores``:
    :func:`_scores` of ``legacy.named`` and their white furnaces) and times."""
    grid, uniform, albedo, furnace = scores
    least, named = legacy.least, legacy.named
    chosen = legacy.moments if method == "moments" else {
        family: next(b for k, b in least.items() if k.startswith(family)) for family in ("ggx", "beckmann")}
    fits = {"tabulated": legacy.fit, **chosen}
    names = {"tabulated": "tabulated", **{k: _key(named, b) for k, b in chosen.items()}}
    errors = {k: grid[names[k]] for k in fits}
    errors.update({k: grid[k] for k in named})
    t0, t1, t2 = legacy.times
    return {
        **{k: analytic_json(b) for k, b in chosen.items()},
        "method": method, "selected": {k: names[k] for k in chosen},
        "moments": {k: analytic_json(b) for k, b in legacy.moments.items()},
        "least_squares": {k: analytic_json(b) for k, b in least.items()},
        "fresnel": fresnel_json(_fit_fresnel(legacy.fit)),
        "seconds": round(t1 - t0, 4), "seconds_least_squares": round(t2 - t1, 4),
        "errors": {**errors, "n_pairs": grid["n_pairs"], "metric": describe_fit_error(),
                   "uniform": {**{k: uniform[names[k]] for k in fits}, **{k: uniform[k] for k in named},
                               "n_pairs": uniform["n_pairs"], "metric": describe_uniform_error()},
                   "albedo_ratio": {**{k: albedo[names[k]].round(4).tolist() for k in fits},
                                    **{k: v.round(4).tolist() for k, v in albedo.items()},
                                    "views_deg": list(ALBEDO_VIEWS_DEG), "metric": describe_albedo()},
                   "white_furnace": {k: round(furnace[k], 4) for k in named}},
    }


def _shown_fits(every: dict, fits_summary: dict, best: str) -> tuple[dict, dict]:
    """``({label: BRDF}, {label: note})`` of the picture: the best fit and the tabulated fit,
    or, where the tabulated fit is the best, the best analytic fit (:func:`best_fit`)."""
    second = "tabulated" if best != "tabulated" else best_fit(
        {k: v["metrics"] for k, v in fits_summary.items() if k != "tabulated"})
    labels = {best: f"best: {best}", second: "tabulated fit" if second == "tabulated" else f"best analytic: {second}"}
    return ({labels[k]: every[k] for k in (best, second)},
            {labels[k]: _fit_note(fits_summary[k]["metrics"]) for k in (best, second)})


def _moment_fits(fit, brdf, required: bool) -> tuple[dict, dict]:
    """``({family: BRDF}, {family: why it failed})``: the GGX and Beckmann fits of the tabulated
    fit's moments. A conversion whose Fresnel solve fails on data of implausible values is
    left out of the candidates (and said so in the summary) unless ``required`` (``--method
    moments``, whose headline fits they are)."""
    out, failed = {}, {}
    for family in ("ggx", "beckmann"):
        try:
            out[family] = getattr(fit, f"to_{family}")(reference=brdf)
        except MicrofacetError as e:
            if required:
                raise
            failed[family] = str(e)
    return out, failed


def _import_numba() -> None:
    """Import Numba, where the kernels will use it (:data:`microfacet.kernels.AVAILABLE`; the
    command's single-file fit runs the NumPy references and never imports it), on this
    thread before any other starts (the kernels' background compiles): two threads whose
    first use of a kernel imports Numba at once can deadlock in its package imports
    (``_DeadlockError`` on ``numba.core.compiler_lock``)."""
    from .. import kernels
    if kernels.AVAILABLE:
        import numba  # noqa: F401


#: The models of :mod:`microfacet.fit.perceptual` that every fit tries (``coat=True`` adds ``"coat"``).
PERCEPTUAL_MODELS = ("lobe", "two_lobes", "mixture", "dielectric_mixture")
#: Sphere size (px) of the image error that chooses the best fit (:class:`microfacet.metrics.ImageError`).
IMAGE_SIZE = 32
#: Pairs of the log error reported per fit (:class:`microfacet.metrics.LogError`).
LOG_PAIRS = 2**15
#: Views (deg) of the energy check ``max_albedo``: the largest directional albedo of a fit.
ENERGY_VIEWS_DEG = (0.0, 30.0, 60.0, 75.0, 85.0, 89.0)


def _judge_perceptual(items, targets: tuple, metrics: tuple, judges: tuple, pool) -> tuple[dict, float]:
    """``({name: (BRDF, summary)}, end time)`` of the perceptual fits ``items`` (of
    :func:`_perceptual`, the last one's end time), each made by :func:`_judged` on the thread
    pool ``pool`` as it comes."""
    t3, futures = time.perf_counter(), {}
    for name, (q, y), t3 in items:
        futures[name] = pool.submit(_judged, targets, metrics, judges, name, q, y)
    return {name: f.result() for name, f in futures.items()}, t3


def _judged(targets: tuple, metrics: tuple, judges: tuple, name: str, q, y) -> tuple:
    """``(BRDF, summary)`` of the perceptual fit ``name`` of parameters ``(q, y)``: its albedo
    matched (:func:`_perceptual_brdf`) and, where its spheres show a cast above
    :data:`~microfacet.fit.colour.CAST_TRIGGER`, its colour balanced
    (:func:`~microfacet.fit.colour.balance_colour`) if :func:`_balance_kept` (the summary's
    ``"balanced_from"``: the chromaticity, image and log errors before); judged by the data's
    ``metrics`` and ``judges`` (:func:`_metrics`, :func:`_judges`). ``targets``: the data's
    albedo target and its colour target made at the first call."""
    target, colour = targets

    def summary(b):
        one = {name: b}
        return _fit_summaries(judges, one, _scores(metrics, one), metrics[2].ref)[name]

    b = _perceptual_brdf(target, name, q, y)
    out = summary(b)
    if out["metrics"]["chromaticity"] > CAST_TRIGGER:
        balanced = balance_colour(colour(), target, b)
        if balanced is not b and _balance_kept(out["metrics"], (other := summary(balanced))["metrics"]):
            other["balanced_from"] = {k: out["metrics"][k] for k in ("chromaticity", "image", "log")}
            return balanced, other
    return b, out


def _perceptual(t, models):
    """``(name, (q, y), end time)`` of :func:`microfacet.fit.perceptual.iter_parameters` on the
    target ``t``, each as fitted (run in a process of its own: many small solves, mostly
    Python, that threads would serialize)."""
    from .perceptual import iter_parameters
    for name, parameters in iter_parameters(None, models, t):
        yield name, parameters, time.perf_counter()


def _perceptual_brdf(target, name: str, q, y):
    """The BRDF of the perceptual fit ``name`` of parameters ``(q, y)``, its albedo matched
    to the data's (:func:`microfacet.fit.albedo.match_albedo`; ``target``: the data's
    :func:`~microfacet.fit.albedo.albedo_target`)."""
    from .perceptual import MODEL_SPECS
    return match_albedo(None, MODEL_SPECS[name].brdf(q, y), target)


class _Once:
    """A value made by ``make()`` at the first call, once, whichever thread calls first."""

    def __init__(self, make):
        self.make, self.lock, self.value = make, threading.Lock(), None

    def __call__(self):
        with self.lock:
            if self.value is None:
                self.value = self.make()
            return self.value


def _balance_kept(before: dict, after: dict) -> bool:
    """Whether a fit's colour balance (metrics ``after``) is kept over the fit (``before``):
    less colour cast under the image error's lights, the image error at most
    :data:`~microfacet.fit.colour.IMAGE_TOLERANCE` above, the albedo no farther from the band."""
    return (after["chromaticity"] < before["chromaticity"]
            and after["image"] <= (1.0 + IMAGE_TOLERANCE) * before["image"]
            and after["albedo_error"] <= max(ALBEDO_TOLERANCE, before["albedo_error"]))


def _judges(brdf) -> tuple:
    """The data's side of the log and image errors."""
    from ..metrics import ImageError, LogError
    return LogError(brdf, n=LOG_PAIRS), ImageError(brdf, size=IMAGE_SIZE)


def _energy(brdf) -> float:
    """The largest directional albedo of ``brdf`` (RGB, views :data:`ENERGY_VIEWS_DEG`): <= 1 conserves energy."""
    from ..metrics import directional_albedo
    return float(np.max(directional_albedo(brdf, ENERGY_VIEWS_DEG)))


def _fit_summaries(judges, named: dict, legacy: tuple, data_albedo: np.ndarray) -> dict:
    """``{name: {"model": spec, "metrics": {...}}}`` for every fit of ``named`` (the tabulated
    fit's model is ``"tabulated"``): the legacy metrics ``legacy = (grid, uniform, albedo)``
    where computed, the log and image errors, chromaticity difference, largest albedo and
    ``albedo_error``, the largest ``|ratio - 1|`` over the channels whose ``data_albedo``
    (views x RGB) exceeds :data:`microfacet.fit.perceptual.ALBEDO_FLOOR`."""
    from .perceptual import ALBEDO_FLOOR
    from .spec import to_spec
    log_error, image_error = judges
    grid, uniform, albedo = legacy
    out = {}
    for name, b in named.items():
        details = image_error.details(b)
        metrics = {"log": round(log_error(b), 6), "image": round(details["image"], 6),
                   "chromaticity": round(details["chromaticity"], 6), "grid": grid.get(name),
                   "uniform": uniform.get(name), "albedo_ratio": np.asarray(albedo[name]).round(4).tolist(),
                   "albedo_ratio_worst": round(_worst(albedo[name]), 4), "max_albedo": round(_energy(b), 4),
                   "albedo_error": round(_albedo_error(albedo[name], data_albedo > ALBEDO_FLOOR), 4)}
        out[name] = {"model": "tabulated" if name == "tabulated" else _spec_or_none(to_spec, b), "metrics": metrics}
    return out


#: Largest chromaticity difference (CIE 1931 xy of the rendered spheres' mean colour) of a
#: fit without a colour cast.
CHROMA_LIMIT = 0.02


#: Albedo band of a fit that reflects the data's energy: ``albedo_error`` at most this.
ALBEDO_TOLERANCE = 0.05
#: A fit whose albedo is off by more than this at some view (half or 1.5 times the data's)
#: fails as a colour cast does: e.g. a near-black sphere, whose chromaticity means little.
ALBEDO_GROSS = 0.5
#: A fit within the albedo band is chosen over the best one when its score is at most this
#: many times the best's.
ALBEDO_PREFERENCE = 2.0


def best_fit(metrics: dict) -> str:
    """The best of fits ``{name: metrics}`` (each with ``"image"``, ``"log"``,
    ``"chromaticity"`` and, optionally, ``"albedo_error"``): of the fits without a colour cast
    (chromaticity difference at most :data:`CHROMA_LIMIT`), the one of least
    :func:`best_score`, unless a fit whose albedo is within the band
    (``albedo_error <= ALBEDO_TOLERANCE``) scores within :data:`ALBEDO_PREFERENCE` times it:
    then the least of those. Fits whose albedo is grossly off (``albedo_error >
    ALBEDO_GROSS``) are left out first; when every fit has a cast, the same among all. A cast is a
    visible failure that neither error weighs much (an iridescent gem's sphere can score best
    with a hue the data does not have); a fit that reflects less or more energy than the
    data at some view is one that the images, lit from a few directions, can miss.

    >>> best_fit({"a": {"image": 0.1, "log": 0.01, "chromaticity": 0.05},
    ...           "b": {"image": 0.2, "log": 0.01, "chromaticity": 0.01}})
    'b'
    >>> best_fit({"a": {"image": 0.1, "log": 0.01, "chromaticity": 0.0, "albedo_error": 0.2},
    ...           "b": {"image": 0.14, "log": 0.01, "chromaticity": 0.0, "albedo_error": 0.01}})
    'b'
    """
    from .perceptual import select
    sound = {k: m for k, m in metrics.items() if float(m.get("albedo_error", 0.0)) <= ALBEDO_GROSS} or metrics
    clean = {k: m for k, m in sound.items() if float(m.get("chromaticity", np.inf)) <= CHROMA_LIMIT} or sound
    scores = {k: best_score(m) for k, m in clean.items()}
    best = select(scores)
    held = {k: v for k, v in scores.items() if float(clean[k].get("albedo_error", np.inf)) <= ALBEDO_TOLERANCE}
    if held and min(held.values()) <= ALBEDO_PREFERENCE * scores[best]:
        return select(held)
    return best


def best_score(metrics: dict) -> float:
    """The score that chooses the best fit: image error times log error (the square of their
    geometric mean). The image error says whether spheres look like the data's under a few
    lights (Bieron & Peers 2020); the log error whether the whole BRDF, on pairs uniform in
    solid angle, holds (Löw et al. 2012). Either alone chooses fits that fail the other: a
    tabulated fit can render a metal's highlight best yet miss its halo by twice the log
    error of an analytic one."""
    return float(metrics["image"]) * float(metrics["log"])


def _spec_or_none(to_spec, brdf):
    try:
        return to_spec(brdf)
    except ValueError:                       # e.g. a moment conversion's tabulated distribution
        return None


def _fit_note(metrics: dict) -> str:
    """Two lines of figures under a sphere of the picture."""
    return (f"image {metrics['image']:.3f} · log {metrics['log']:.4f}\n"
            f"albedo ratio {metrics['albedo_ratio_worst']:.2f}")


def format_fits_table(summary: dict) -> str:
    """A short table of every fit of a ``microfacet fit`` summary, one row per fit, the
    best marked ``*``, for a terminal."""
    rows = [("fit", "log err", "image err", "grid err", "albedo", "max albedo")]
    for name, entry in summary["fits"].items():
        m = entry["metrics"]
        rows.append((("* " if name == summary["best"] else "  ") + name, f"{m['log']:.4f}", f"{m['image']:.3f}",
                     "" if m["grid"] is None else f"{m['grid']:.3f}", f"{m['albedo_ratio_worst']:.2f}",
                     f"{m['max_albedo']:.3f}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths))) for r in rows]
    return "\n".join(lines) + ("\n* best: least image error x log error of the fits without a colour cast, or one within "
                                f"5 % of the data's albedo scoring within {ALBEDO_PREFERENCE:g} times it (images: spheres "
                                f"under 3 lights and an environment, {IMAGE_SIZE} px); log: cosine-weighted log error; "
                                "albedo: worst ratio fit/data\n") + _seam_note(summary)


def _seam_note(summary: dict) -> str:
    """A line on data that are not reciprocal (:meth:`microfacet.measured.MERLBRDF.fold_seam`), else ``""``."""
    from ..measured.merl import SEAM_LIMIT
    seam = summary.get("data", {}).get("fold_seam")
    if seam is None or not seam > SEAM_LIMIT:
        return ""
    return (f"note: the data are not reciprocal: their table jumps by a factor {np.exp(seam):.2f} across phi_d = "
            "0/180 deg (fold_seam), which no fit, being reciprocal, can follow on both sides\n")


def _key(named: dict, brdf) -> str:
    return next(k for k, b in named.items() if b is brdf)


def _label(name: str) -> str:
    """Short picture label of a fit name: ``ggx_diffuse_least_squares`` -> ``least squares + diffuse``."""
    method = "moments" if name.endswith("_moments") else "least squares"
    return method + (" + coat" if "_coat" in name else "") + (" + diffuse" if "_diffuse" in name else "")


def _note(grid: float, uniform: float, albedo: np.ndarray) -> str:
    """Two lines of errors under a sphere of the picture."""
    return (f"grid {grid:.3f} · uniform {uniform:.3f}\n"
            f"albedo ratio {np.nanmin(albedo):.2f}–{np.nanmax(albedo):.2f}")


def _albedo_error(ratios, bright) -> float:
    """The largest ``|ratio - 1|`` over the ``bright`` entries (views x RGB); 0 where none is."""
    r = np.abs(np.asarray(ratios, dtype=np.float64) - 1.0)
    r = r[np.asarray(bright, bool) & np.isfinite(r)]
    return float(np.max(r)) if len(r) else 0.0


def _worst(ratios) -> float:
    """The albedo ratio farthest from 1 (views x RGB)."""
    r = np.asarray(ratios, dtype=np.float64).ravel()
    r = r[np.isfinite(r)]
    return float(r[np.argmax(np.abs(r - 1.0))]) if len(r) else float("nan")


def summary_row(name: str, path, fmt: str, summary: dict | None, status: str = "ok") -> dict:
    """A row of the folder summary (:data:`SUMMARY_COLUMNS`) from a JSON summary.

    Parameters
    ----------
    name : str
        The material's name.
    path : str or os.PathLike
        Its input file.
    fmt : str
        The input's format.
    summary : dict or None
        The JSON summary of :func:`fit_material` (None when the fit failed).
    status : str
        ``"ok"`` or what went wrong.

    Returns
    -------
    dict
        The row, keys :data:`SUMMARY_COLUMNS`.

    Examples
    --------
    >>> row = summary_row("gold", "gold.binary", "merl", None, status="error: unreadable")
    >>> row["material"], row["status"], len(row) == len(SUMMARY_COLUMNS)
    ('gold', 'error: unreadable', True)
    """
    row = dict.fromkeys(SUMMARY_COLUMNS, "")
    row.update(material=name, file=Path(path).name, format=fmt, status=status)
    if summary is not None:
        errors = summary["errors"]
        row["seconds"] = round(summary["seconds"] + summary.get("seconds_least_squares", 0.0), 4)
        row["method"] = summary["method"]
        if "fits" in summary:
            best = summary["fits"][summary["best"]]["metrics"]
            row.update(best=summary["best"], log_best=best["log"], image_best=best["image"],
                       image_tabulated=summary["fits"]["tabulated"]["metrics"]["image"])
        for kind in _KINDS:
            row[f"error_{kind}"] = errors[kind]
            row[f"uniform_{kind}"] = errors["uniform"][kind]
            row[f"albedo_{kind}"] = _worst(errors["albedo_ratio"][kind])
        row["error_ggx_moments"] = errors["ggx_moments"]
        for kind in ("ggx", "beckmann"):
            for key in ("alpha_x", "alpha_y", "rho"):
                row[f"{kind}_{key}"] = summary[kind][key]
            d = summary[kind]["diffuse"]
            row[f"{kind}_diffuse"] = "" if d is None else " ".join(f"{v:.3f}" for v in d)
    return row


def _cell(value, digits: int = 4) -> str:
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return str(value).replace("|", "\\|")


def format_summary_markdown(rows: Sequence[dict]) -> str:
    """The rows as a Markdown table, plus notes on the metrics.

    Parameters
    ----------
    rows : sequence of dict
        Rows of :func:`summary_row`.

    Returns
    -------
    str
        The Markdown table and its notes.

    Examples
    --------
    >>> rows = [summary_row("gold", "gold.binary", "merl", None, status="error: unreadable")]
    >>> print(format_summary_markdown(rows).splitlines()[0][:60])
    | material | format | fit s | method | err tab | err GGX | e
    """
    head = ("material", "format", "fit s", "method", "err tab", "err GGX", "err Beck", "err GGX mom",
            "unif tab", "unif GGX", "unif Beck", "albedo tab", "albedo GGX", "albedo Beck",
            "GGX αx", "GGX αy", "GGX ρ", "GGX kd", "Beck αx", "Beck αy", "Beck ρ", "Beck kd", "status")
    keys = ("material", "format", "seconds", "method", "error_tabulated", "error_ggx", "error_beckmann",
            "error_ggx_moments", "uniform_tabulated", "uniform_ggx", "uniform_beckmann",
            "albedo_tabulated", "albedo_ggx", "albedo_beckmann",
            "ggx_alpha_x", "ggx_alpha_y", "ggx_rho", "ggx_diffuse",
            "beckmann_alpha_x", "beckmann_alpha_y", "beckmann_rho", "beckmann_diffuse", "status")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(_cell(r[k], 3 if k == "seconds" else 4) if not k.endswith("_rho") or r[k] == ""
                                else f"{r[k]:+.4f}" for k in keys) + " |" for r in rows]
    return "\n".join(lines) + (f"\n\nerr: {describe_fit_error()}.\nunif: {describe_uniform_error()}."
                               f"\nalbedo: the ratio farthest from 1 of the {describe_albedo()}."
                               "\nkd: diffuse (Lambertian) reflectance of the fit, RGB.\n")


