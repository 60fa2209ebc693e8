#!/usr/bin/env python3
"""Power-iteration fits (thesis Ch. 4) of the measured materials of ``../shared/data``:
fit errors and times, and for RGL files the fitted NDF against the file's own ``ndf``.

For every MERL ``.binary(.gz)`` in ``DATA/merl`` and RGL ``.bsdf`` in ``DATA/rgl`` this
runs ``mf.fit.fit(m, resolution=N)`` (isotropic; with ``--anisotropic`` also an
anisotropic fit of the RGL files) and reports

* the fit time (``time.perf_counter`` around ``mf.fit.fit`` alone; one run, cold);
* the relative RMS error of ``f_r cos theta_i`` of the tabulated fit, its moment
  conversions ``fit.to_ggx(reference=m)`` and ``fit.to_beckmann(reference=m)`` (Fresnel
  tables solved against the data, as ``microfacet fit --method moments`` writes them) and
  the issue's baseline, the moment GGX of the constraint-only fit (``albedo_weight=0``)
  with that fit's own Fresnel table (``resolve_fresnel=False``), against the data
  (:func:`microfacet.metrics.fit_error`: a 32^3 grid of MERL coordinates, **grazing
  pairs with cos theta_i or cos theta_o < 0.1 excluded**, and for MERL the pairs
  touching unmeasured samples);
* the least-squares fits of :func:`microfacet.fit.fit_analytic` (GGX and Beckmann, with
  and without a Lambertian base, and with a coat lobe and a base, GGX also with the
  ``normal_map`` GAF; Fresnel table, the default albedo weight; started from the
  tabulated fit) and their fit time;
* the tabulated fit with and without a Lambertian base (``diffuse=True``), at albedo weight
  0 and the default: its grid and uniform errors and albedo ratio, and the grid error of each
  base fit over the constraint-only fit without a base;
* the trade-off of the albedo weight: for each weight of ``--weights``, the least-squares
  fit of least objective (:func:`microfacet.fit.outputs.objective`) among the six, its
  grid error (and its ratio to the baseline), uniform error and albedo ratio;
* for every fit the error over uniformly distributed pairs
  (:func:`microfacet.metrics.uniform_error`) and the directional-albedo ratio fit/data at
  0/30/60/75 deg (:func:`microfacet.metrics.albedo_ratios`: the ratio farthest from 1 over
  views and RGB), and the white furnace of the fit (:func:`microfacet.metrics.white_furnace`);
* for RGL files, the relative L2 difference of ``D cos theta_h`` over the hemisphere
  between each fit's NDF and the file's ``ndf`` field (both normalized to projected area
  1; :func:`microfacet.metrics.ndf_error`), the file's NDF having been retrieved by its
  authors from retro-reflection measurements by the same power-iteration method.

Usage::

    python experiments/fit_measured.py [--data ../shared/data] [--resolution 90]
                                       [--anisotropic] [--weights 0,1,2,4,8] [--out table.md]
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.fit.analytic import ALBEDO_WEIGHT
from microfacet.fit.outputs import material_name, objective
from microfacet.io import write_text
from microfacet.render.lobes import LUMINANCE
from microfacet.metrics import (albedo_ratios, describe_albedo, describe_fit_error, describe_uniform_error,
                                fit_error, ndf_error, uniform_error, white_furnace)

ROOT = Path(__file__).resolve().parents[1]


def _ndf(brdf):
    """The NDF callable of a fit (``brdf.ndf`` or ``brdf.distribution.ndf``)."""
    ndf = getattr(brdf, "ndf", None)
    return ndf if ndf is not None else brdf.distribution.ndf


def _alpha(brdf) -> str:
    d = brdf.distribution
    ax, ay, rho = float(d.alpha_x), float(d.alpha_y), float(d.rho)
    return f"{ax:.4f}" if abs(ax - ay) < 1e-4 * ax and abs(rho) < 1e-6 else f"{ax:.4f}, {ay:.4f}, ρ {rho:+.3f}"


#: Least-squares fits by column name: (model, diffuse, coat, GAF).
LEAST_SQUARES = {"LS GGX": ("ggx", False, False, "smith"), "LS GGX+d": ("ggx", True, False, "smith"),
                 "LS Beck": ("beckmann", False, False, "smith"), "LS Beck+d": ("beckmann", True, False, "smith"),
                 "LS GGX+c+d": ("ggx", True, True, "smith"), "LS Beck+c+d": ("beckmann", True, True, "smith"),
                 "LS GGX+c+d nm": ("ggx", True, True, "normal_map")}
#: The fits of the albedo-weight sweep (the Smith ones).
SWEPT = [name for name, (*_, gaf) in LEAST_SQUARES.items() if gaf == "smith"]


def _worst(ratios) -> float:
    r = np.asarray(ratios).ravel()
    return float(r[np.argmax(np.abs(r - 1.0))])


def _lobe(brdf):
    return brdf.brdfs[0] if hasattr(brdf, "brdfs") else brdf


def _describe(brdf) -> str:
    """Roughness of the lobe, then the coat's roughness and the base's luminance if any."""
    parts = getattr(brdf, "brdfs", (brdf,))
    text = _alpha(parts[0])
    for p in parts[1:]:
        if isinstance(p, mf.Lambertian):
            text += f", kd {float(p.reflectance @ LUMINANCE):.3f}"
        else:
            text += f", coat {float(p.distribution.alpha_x):.4f}"
    return text


def fit_one(path: Path, resolution: int, anisotropic: bool, weights=()) -> dict:
    m = mf.measured.load(path)
    t0 = time.perf_counter()
    fit = mf.fit.fit(m, resolution=resolution, anisotropic=anisotropic)
    seconds = time.perf_counter() - t0
    constraint_only = fit if anisotropic else mf.fit.fit(m, resolution=resolution, albedo_weight=0.0)
    fits = {"tabulated": fit, "ggx": fit.to_ggx(reference=m), "beckmann": fit.to_beckmann(reference=m),
            "baseline": constraint_only.to_ggx(resolve_fresnel=False)}
    tabulated = {f"{'weight 0' if w == 0 else 'default'}{' +d' if d else ''}":
                 mf.fit.fit(m, resolution=resolution, anisotropic=anisotropic, diffuse=d, albedo_weight=w)
                 for w in (0.0, None) for d in (False, True)}
    ls_seconds = {}
    for name, (model, diffuse, coat, gaf) in LEAST_SQUARES.items():
        t0 = time.perf_counter()
        fits[name] = mf.fit.fit_analytic(m, model, diffuse=diffuse, anisotropic=anisotropic, coat=coat, start=fit,
                                         gaf=gaf)
        ls_seconds[name] = time.perf_counter() - t0
    swept = {(w, name): mf.fit.fit_analytic(m, LEAST_SQUARES[name][0], diffuse=LEAST_SQUARES[name][1],
                                            anisotropic=anisotropic, coat=LEAST_SQUARES[name][2], start=fit,
                                            albedo_weight=w)
             for w in weights if w != ALBEDO_WEIGHT for name in SWEPT}
    swept.update({(ALBEDO_WEIGHT, name): fits[name] for name in SWEPT if ALBEDO_WEIGHT in weights})
    keys = {f"w{w:g} {name}": b for (w, name), b in swept.items()}
    all_fits = {**fits, **keys, **{f"tabulated {k}": b for k, b in tabulated.items()}}
    errors, uniform, albedo = fit_error(m, all_fits), uniform_error(m, all_fits), albedo_ratios(m, all_fits)
    best = min(LEAST_SQUARES, key=lambda k: objective(errors[k], uniform[k], albedo[k], ALBEDO_WEIGHT))
    tradeoff = {}
    for w in weights:
        k = min((f"w{w:g} {name}" for name in SWEPT), key=lambda k: objective(errors[k], uniform[k], albedo[k], w))
        tradeoff[w] = (k.split(" ", 1)[1], errors[k], errors[k] / errors["baseline"], uniform[k], _worst(albedo[k]))
    row = {"material": material_name(path), "format": m.format,
           "mode": "aniso" if anisotropic else "iso", "seconds": seconds, "ls_seconds": ls_seconds,
           "errors": errors, "uniform": uniform, "best": best, "tradeoff": tradeoff,
           "albedo": {k: _worst(albedo[k]) for k in fits},
           "furnace": {k: white_furnace(b) for k, b in fits.items()},
           "alpha": {k: _describe(b) for k, b in fits.items() if k != "tabulated"},
           "tabulated": {k: (errors[f"tabulated {k}"], uniform[f"tabulated {k}"], _worst(albedo[f"tabulated {k}"]))
                         for k in tabulated}}
    if hasattr(m, "ndf_table"):
        row["ndf"] = {k: ndf_error(m.ndf, _ndf(_lobe(b)))["l2"] for k, b in fits.items()}
    return row


def format_tables(rows: list[dict], resolution: int) -> str:
    names = ["tabulated", "baseline", "ggx", "beckmann", *LEAST_SQUARES]
    heads = ["tabulated", "baseline", "GGX (moments)", "Beckmann (moments)", *LEAST_SQUARES]
    lines = [f"Fits at resolution {resolution} ({platform.processor() or platform.machine()}, "
             f"Python {platform.python_version()}, NumPy {np.__version__}); least-squares fits "
             f"(LS) by `mf.fit.fit_analytic(m, model, diffuse=..., coat=..., start=fit)` (Fresnel table, albedo "
             f"weight {ALBEDO_WEIGHT:g}), `+d`: with a Lambertian base, `+c`: with a coat lobe (7-node Fresnel table), "
             "`nm`: the normal_map GAF. Moments: `fit.to_ggx(reference=m)`, `fit.to_beckmann(reference=m)` "
             "(Fresnel tables solved against the data). Baseline: the issue's, "
             "`fit(m, albedo_weight=0).to_ggx(resolve_fresnel=False)`. Best: the LS fit of least objective "
             "(grid² + uniform² + weight² · mean (albedo ratio − 1)²).", "",
             "Grid error (`fit_error`) / uniform-pairs error (`uniform_error`):", "",
             "| material | format | fit | " + " | ".join(heads) + " | best LS / baseline, / GGX moments |",
             "|---|---|---|" + "---|" * (len(heads) + 1)]
    for r in rows:
        e, u = r["errors"], r["uniform"]
        lines.append(f"| {r['material']} | {r['format']} | {r['mode']} | "
                     + " | ".join(f"{e[k]:.4f} / {u[k]:.4f}" for k in names)
                     + f" | {r['best']}: {e[r['best']] / e['baseline']:.2f}, {e[r['best']] / e['ggx']:.2f} |")
    lines += ["", "Albedo ratio fit/data farthest from 1 (views 0/30/60/75°, RGB) and white furnace "
              "(max albedo of the microfacet lobe with F = 1, views 0–89°):", "",
              "| material | fit | " + " | ".join(heads) + " |", "|---|---|" + "---|" * len(heads)]
    lines += [f"| {r['material']} | {r['mode']} | "
              + " | ".join(f"{r['albedo'][k]:.3f} / {r['furnace'][k]:.3f}" for k in names) + " |" for r in rows]
    lines += ["", "Fitted roughness (α, or αx, αy, ρ), coat roughness, diffuse luminance kd, fit times (s; tabulated "
              "fit, then each LS fit; `time.perf_counter`, one run):", "",
              "| material | fit | baseline | GGX mom | Beck mom | " + " | ".join(LEAST_SQUARES) + " | times |",
              "|---|---|---|---|---|" + "---|" * (len(LEAST_SQUARES) + 1)]
    for r in rows:
        cells = [r["alpha"][k] for k in names[1:]]
        times = f"{r['seconds']:.2f}; " + ", ".join(f"{t:.2f}" for t in r["ls_seconds"].values())
        lines.append(f"| {r['material']} | {r['mode']} | " + " | ".join(cells) + f" | {times} |")
    lines += ["", "Tabulated fits with and without a Lambertian base (`fit(m, diffuse=..., albedo_weight=...)`; "
              f"default weight: {ALBEDO_WEIGHT:g} isotropic, 0 anisotropic): grid / uniform error / albedo ratio "
              "farthest from 1, and the grid error of each base fit over the constraint-only fit without a base "
              "(weight 0, the fit of issue 10's time):", "",
              "| material | fit | " + " | ".join(rows[0]["tabulated"]) + " | grid error +d / weight 0: weight 0, "
              "default |", "|---|---|" + "---|" * (len(rows[0]["tabulated"]) + 1)]
    for r in rows:
        t = r["tabulated"]
        w0 = t["weight 0"][0]
        lines.append(f"| {r['material']} | {r['mode']} | "
                     + " | ".join(f"{g:.4f} / {u:.4f} / {a:.3f}" for g, u, a in t.values())
                     + f" | {t['weight 0 +d'][0] / w0:.2f}, {t['default +d'][0] / w0:.2f} |")
    sweep = [r for r in rows if r["tradeoff"]]
    if sweep:
        weights = list(sweep[0]["tradeoff"])
        lines += ["", "Albedo weight trade-off: for each weight, the LS fit of least objective at that weight "
                  "(its name), grid error (× the baseline's), uniform error and albedo ratio "
                  "farthest from 1:", "",
                  "| material | fit | " + " | ".join(f"weight {w:g}" for w in weights) + " |",
                  "|---|---|" + "---|" * len(weights)]
        lines += [f"| {r['material']} | {r['mode']} | " + " | ".join(
            f"{t[0]}: {t[1]:.4f} ({t[2]:.2f}×) / {t[3]:.4f} / {t[4]:.3f}" for t in r["tradeoff"].values()) + " |"
            for r in sweep]
    lines += ["", f"Grid error: {describe_fit_error()}.", f"Uniform error: {describe_uniform_error()}.",
              f"Albedo: {describe_albedo()}.", ""]
    ndf_rows = [r for r in rows if "ndf" in r]
    if ndf_rows:
        lines += ["NDF of the fits against the RGL file's own `ndf` field: relative L2 difference of "
                  "D cos θh over the hemisphere (both normalized to projected area 1; 128 × 128 "
                  "midpoint quadrature, θ quadratic in u).", "",
                  "| material | fit | " + " | ".join(heads) + " |", "|---|---|" + "---|" * len(heads)]
        lines += [f"| {r['material']} | {r['mode']} | " + " | ".join(f"{r['ndf'][k]:.4f}" for k in names) + " |"
                  for r in ndf_rows]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT / ".." / "shared" / "data")
    ap.add_argument("--resolution", type=int, default=90)
    ap.add_argument("--anisotropic", action="store_true", help="also fit the RGL files anisotropically")
    ap.add_argument("--weights", default="0,1,2,4,8",
                    help="albedo weights of the trade-off table, comma-separated ('' for none)")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "fit_measured.md",
                    help="write the Markdown tables here (atomically; default experiments/results/"
                         "fit_measured.md)")
    args = ap.parse_args(argv)
    merl = sorted((args.data / "merl").glob("*.binary*"))
    rgl = sorted((args.data / "rgl").glob("*.bsdf"))
    if not merl and not rgl:
        print(f"fit_measured: no MERL or RGL files under {args.data}", file=sys.stderr)
        return 1
    jobs = [(p, False) for p in merl + rgl] + ([(p, True) for p in rgl] if args.anisotropic else [])
    rows = []
    for path, aniso in jobs:
        print(f"fitting {path.name} ({'anisotropic' if aniso else 'isotropic'}) ...", file=sys.stderr, flush=True)
        rows.append(fit_one(path, args.resolution, aniso, [float(w) for w in args.weights.split(",") if w]))
    text = format_tables(rows, args.resolution)
    print(text)
    if args.out:
        write_text(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
