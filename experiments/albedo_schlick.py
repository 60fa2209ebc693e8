"""The albedo match as Schlick parameters vs as a Fresnel table, on the fit corpus.

:func:`microfacet.fit.albedo.match_albedo` matches a perceptual fit's directional albedo to
the data's by a smooth table ``s(theta_d)`` on every lobe's Fresnel term (``"table"``), which
the exports (glTF, MaterialX, USD, Blender) cannot hold and refit as a least-squares Schlick.
The alternative measured here (``albedo_schlick_match.match``, this study's own code) solves
the lobes' Schlick ``f0``/``f90`` (and the base colours) directly (``"schlick"``,
``"schlick_base"``, ``"shared"``, ``"shared_base"``), which the exports hold exactly.

Phase ``corpus``: for every material of the fit corpus whose best fit
(``experiments/results/fit_corpus.csv``) is a perceptual model, that model is fitted again
(:func:`microfacet.fit.perceptual.fit_models`) and matched by each method; per method the
albedo band (worst ``|a_fit / a_data - 1|`` at 0/30/60/75 deg over channels with data albedo
> 0.03, :class:`microfacet.metrics.AlbedoRatios`), the log error
(:class:`~microfacet.metrics.LogError`, 2^15 pairs), the image error
(:class:`~microfacet.metrics.ImageError`, 32 px, as the CLI chooses) and the chromaticity
difference are recorded (resumable: one JSON line per material in ``--cache``). Materials
whose best fit is not a perceptual model (tabulated, least squares) are not matched: their
band status is read from the corpus CSV and counted alike for every method.

Phase ``export``: for a few materials, the best model matched by the table and by the
default method is exported to MaterialX and glTF through :func:`microfacet.export.export`,
and the report's expected error (image error of the exported material against the fit) is
quoted.

Phase ``report`` writes ``experiments/results/albedo_schlick.md``.

    nice python experiments/albedo_schlick.py --phase corpus export report
"""
from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from albedo_schlick_match import band_error, match  # noqa: E402  (this study's Schlick match)

ROOT = HERE.parent
RESULTS = ROOT / "experiments" / "results"
CACHE = Path.home() / ".cache" / "microfacet" / "corpus"
METHODS = ("table", "schlick", "schlick_base", "shared", "shared_base")
#: Fallback variants ``"S|table"``: the Schlick match ``S`` where its band error is within
#: :data:`BAND` and its log error within ``1 + LOG_SLACK`` times the table's, else the table.
FALLBACKS = ("schlick", "shared", "schlick_base", "shared_base")
LOG_SLACK = 0.05
EXPORT_MATERIALS = ("merl/ss440", "merl/specular-orange-phenolic", "merl/nickel")
EXPORT_METHODS = ("table", "schlick", "shared_base", "fallback")
BAND = 0.05


def corpus_rows() -> list[dict]:
    with open(RESULTS / "fit_corpus.csv") as f:
        return list(csv.DictReader(f))


def material(group: str, name: str):
    import microfacet as mf
    return mf.measured.load(CACHE / f"{group}__{name}.binary")


def measure(data, fit, band_ratios, le, ie) -> dict:
    a = np.asarray(band_ratios(fit), float)
    band = float(np.nanmax(np.where(band_ratios.ref > 0.03, np.abs(a - 1.0), 0.0)))
    return {"band": band, "log": float(le(fit)), "image": float(ie(fit)), "chroma": float(ie.chromaticity(fit))}


def run_material(group: str, name: str, model: str) -> dict:
    from microfacet.fit import albedo as A
    from microfacet.fit.perceptual import fit_models
    from microfacet.metrics import AlbedoRatios, ImageError, LogError
    data = material(group, name)
    t0 = time.perf_counter()
    fit = fit_models(data, (model,))[model]
    out = {"group": group, "name": name, "model": model, "fit_s": time.perf_counter() - t0}
    le, ie, band = LogError(data, n=2**15), ImageError(data, size=32), AlbedoRatios(data)
    target = A.albedo_target(data, le)
    out["fit"] = measure(data, fit, band, le, ie)
    matched = {}
    for method in METHODS:
        t0 = time.perf_counter()
        matched[method] = match(None, fit, target, method=method)
        dt = time.perf_counter() - t0
        out[method] = {**measure(data, matched[method], band, le, ie), "s": dt}
    return out


def phase_corpus(cache: Path, limit: int | None, only: list[str] | None = None) -> None:
    from microfacet.fit.outputs import PERCEPTUAL_MODELS
    done = set()
    if cache.exists():
        done = {(r["group"], r["name"]) for r in map(json.loads, cache.read_text().splitlines())}
    rows = [r for r in corpus_rows() if r["best"] in PERCEPTUAL_MODELS and (r["group"], r["name"]) not in done
            and (only is None or f"{r['group']}/{r['name']}" in only)]
    for r in rows[:limit]:
        t0 = time.perf_counter()
        try:
            res = run_material(r["group"], r["name"], r["best"])
        except FileNotFoundError as e:
            print(f"{r['group']}/{r['name']}: missing {e}", flush=True)
            continue
        with open(cache, "a") as f:
            f.write(json.dumps(res) + "\n")
        print(f"{r['group']}/{r['name']} {r['best']} " + " ".join(
            f"{k}:{res[k]['band']:.3f}/{res[k]['image']:.4f}" for k in ("fit",) + METHODS)
            + f" ({time.perf_counter() - t0:.1f} s)", flush=True)


def as_exported(brdf):
    """``brdf`` with every lobe's Fresnel term replaced by its least-squares Schlick pair
    (:func:`microfacet.export.schlick_of`), as the exports write a table."""
    import microfacet as mf
    from microfacet.export import schlick_of
    parts = list(getattr(brdf, "brdfs", [brdf]))
    out = []
    for b in parts:
        if isinstance(b, mf.MicrofacetBRDF) and isinstance(b.fresnel, mf.fresnel.Tabulated):
            f0, f90 = schlick_of(b.fresnel)
            b = mf.MicrofacetBRDF(b.distribution, fresnel=mf.fresnel.Schlick(np.clip(f0, 0, 1), np.clip(f90, 0, 1)),
                                  gaf=b.gaf_model, shadowing=b.shadowing)
        out.append(b)
    return mf.fit.SumBRDF(*out, weights=brdf.weights) if hasattr(brdf, "brdfs") else out[0]


def phase_export(out: Path) -> None:
    from microfacet.export import export
    from microfacet.fit import albedo as A
    from microfacet.fit.perceptual import fit_models
    from microfacet.metrics import ImageError
    best = {f"{r['group']}/{r['name']}": r["best"] for r in corpus_rows()}
    res = []
    with tempfile.TemporaryDirectory() as tmp:
        for key in EXPORT_MATERIALS:
            group, name = key.split("/")
            data, model = material(group, name), best[key]
            if model not in ("lobe", "two_lobes", "mixture", "dielectric_mixture"):
                model = "mixture"                   # the export's best analytic fit (export_mtlx.md)
            fit = fit_models(data, (model,))[model]
            target, ie = A.albedo_target(data), ImageError(data, size=32)
            for method in EXPORT_METHODS:
                brdf = match(None, fit, target, method=method)
                row = {"material": key, "model": model, "method": method, "band": band_error(target, brdf),
                       "fit_vs_data": ie(brdf), "as_exported_vs_data": ie(as_exported(brdf))}
                for to in ("mtlx", "gltf"):
                    rep = export(brdf, to, Path(tmp) / f"{name}_{method}_{to}")
                    row[to] = rep["image_error"]["exported_vs_fit"]
                    row[to + "_lost"] = rep["lost"]
                res.append(row)
                print(json.dumps({k: v for k, v in row.items() if not k.endswith("lost")}), flush=True)
    out.write_text(json.dumps(res, indent=1) + "\n")


def _gmean(x) -> float:
    x = np.asarray(x, float)
    return float(np.exp(np.mean(np.log(np.maximum(x, 1e-12)))))


def _variant(rec: dict, variant: str) -> dict:
    """A record's metrics under ``variant`` (a method, or ``S|table``: :data:`FALLBACKS`)."""
    if variant.endswith("|table"):
        s = rec[variant.split("|")[0]]
        held = s["band"] <= BAND and s["log"] <= (1.0 + LOG_SLACK) * rec["table"]["log"]
        return {**(s if held else rec["table"]), "schlick": held}
    return rec[variant]


def _exact(variant: str, metrics: list) -> int:
    if variant == "table":
        return 0
    if variant.endswith("|table"):
        return sum(bool(x["schlick"]) for x in metrics)
    return len(metrics)


def report(cache: Path, export_json: Path, command: str) -> str:
    recs = [json.loads(x) for x in cache.read_text().splitlines()]
    rows = corpus_rows()
    from microfacet.fit.outputs import PERCEPTUAL_MODELS
    others = [r for r in rows if r["best"] not in PERCEPTUAL_MODELS]
    others_ok = sum(abs(float(r["albedo_best"]) - 1.0) <= BAND for r in others)
    variants = ["fit"] + list(METHODS) + [f"{f}|table" for f in FALLBACKS]
    lines = [f"# Albedo match: Schlick parameters vs Fresnel table", "",
             f"{datetime.date.today().isoformat()}, {platform.machine()}, {os.cpu_count()} CPUs, "
             f"Python {platform.python_version()}, commit {_commit()}; `{command}`.", "",
             "Materials: every fit-corpus material whose best fit (`experiments/results/fit_corpus.csv`) is a "
             f"perceptual model ({len(recs)} of {len(rows)}), that model fitted again "
             "(`perceptual.fit_models`) and matched by each method (table: `microfacet.fit.albedo.match_albedo`; "
             "the Schlick forms: `experiments/albedo_schlick_match.py`). "
             "band: worst |a_fit/a_data - 1| at 0/30/60/75 deg over channels with data albedo > 0.03 "
             "(`metrics.AlbedoRatios`, 128x128); log: `metrics.LogError` (2^15 pairs); image: `metrics.ImageError` "
             "(32 px); chroma: its chromaticity difference. Geometric means over the materials; change vs the "
             f"table match. \"all\": adding the {len(others)} materials whose best fit is not perceptual "
             f"(tabulated / least squares; {others_ok} within the band, read from the corpus CSV, the same for "
             "every method). The model of each material is held fixed (the corpus's choice under the table "
             "match); a different match could change the choice on a few materials.", "",
             "| variant | within 5 % (these) | within 5 % (all) | gmean log | vs table | gmean image | vs table | "
             "worst chroma | chroma > 0.02 | no table (exact export) | median match s |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    base = {k: [_variant(r, "table")[k] for r in recs] for k in ("log", "image")}
    for v in variants:
        m = [_variant(r, v) for r in recs]
        ok = sum(x["band"] <= BAND for x in m)
        gl, gi = _gmean([x["log"] for x in m]), _gmean([x["image"] for x in m])
        ch = [x["chroma"] for x in m]
        s = [x.get("s", np.nan) for x in m]
        lines.append(f"| {v} | {ok}/{len(m)} | {ok + others_ok}/{len(rows)} | {gl:.5f} | "
                     f"{gl / _gmean(base['log']) - 1:+.1%} | {gi:.5f} | {gi / _gmean(base['image']) - 1:+.1%} | "
                     f"{max(ch):.4f} | {sum(c > 0.02 for c in ch)} | {_exact(v, m)}/{len(m)} | "
                     f"{np.nanmedian(s) if v != 'fit' else 0:.2f} |")
    lines += ["", "`fit`: before any match. `S|table`: the Schlick match `S` where its band error is within 5 % and "
              f"its log error within {1 + LOG_SLACK:g} times the table match's, else the table match "
              "(`albedo_schlick_match.match(method=\"fallback\")` is `shared_base|table`, its band judged on the match's own 64x64 quadrature); its seconds are `S`'s only. "
              "`schlick`: every Schlick lobe's f0 (RGB) and grey f90; `shared`: one factor per channel on every "
              "lobe's f0 and one on every f90 (the lobes keep their relative weights); `_base`: also the base "
              "colours.", ""]
    best_schlick = max(METHODS[1:], key=lambda v: sum(_variant(r, v)["band"] <= BAND for r in recs))
    n_table = sum(r["table"]["band"] <= BAND for r in recs)
    n_best = sum(r[best_schlick]["band"] <= BAND for r in recs)
    lines += ["Decision: a Schlick match replaces the table as the default only if it holds (nearly) the table's band "
              f"count and image error. Best Schlick form: `{best_schlick}`, {n_best}/{len(recs)} within the band vs "
              f"the table's {n_table}/{len(recs)}" + (": the table stays the default." if n_best < n_table - 2 else "."),
              ""]
    by_model = {}
    for r in recs:
        by_model.setdefault(r["model"], []).append(r)
    names = " / ".join(METHODS)
    lines += ["## Per model", "", f"| model | n | within 5 %: {names} | gmean image: {names} |", "|---|---|---|---|"]
    for k, rs in sorted(by_model.items()):
        oks = [sum(r[v]["band"] <= BAND for r in rs) for v in METHODS]
        ims = [_gmean([r[v]["image"] for r in rs]) for v in METHODS]
        lines.append(f"| {k} | {len(rs)} | {' / '.join(map(str, oks))} | {' / '.join(f'{x:.4f}' for x in ims)} |")
    miss = [r for r in recs if r["table"]["band"] > BAND or r["schlick_base"]["band"] > BAND]
    lines += ["", "## Materials outside the band under either method", "",
              "| material | model | band: fit | table | schlick | schlick_base | image: table | schlick_base |",
              "|---|---|---|---|---|---|---|---|"]
    for r in sorted(miss, key=lambda r: -r["schlick_base"]["band"]):
        lines.append(f"| {r['group']}/{r['name']} | {r['model']} | {r['fit']['band']:.3f} | {r['table']['band']:.3f} | "
                     f"{r['schlick']['band']:.3f} | {r['schlick_base']['band']:.3f} | {r['table']['image']:.4f} | "
                     f"{r['schlick_base']['image']:.4f} |")
    if export_json.exists():
        ex = json.loads(export_json.read_text())
        lines += ["", "## Export fidelity", "",
                  "The best analytic model of each material matched by each method and exported with "
                  "`microfacet.export.export` (`to=\"mtlx\"`, `\"gltf\"`): the report's expected error, the image "
                  "error (32 px) of the exported material re-read from the file against the library's fit. "
                  "\"fit vs data\": the matched fit's image error against the data; \"as exported vs data\": the "
                  "fit with each Fresnel table written as its least-squares Schlick (`export.schlick_of`, what the "
                  "exports hold) against the data.", "",
                  "| material | model | match | band | fit vs data | as exported vs data | MaterialX pbrlib vs fit | "
                  "MaterialX open_pbr_surface vs fit | glTF vs fit |", "|---|---|---|---|---|---|---|---|---|"]
        for r in ex:
            mt, gl = r["mtlx"], r["gltf"]
            lines.append(f"| {r['material']} | {r['model']} | {r['method']} | {r['band']:.3f} | "
                         f"{r['fit_vs_data']:.4f} | {r['as_exported_vs_data']:.4f} | "
                         f"{mt.get('pbrlib', float('nan')):.4f} | {mt.get('open_pbr_surface', float('nan')):.4f} | "
                         f"{next(iter(gl.values())):.4f} |")
    return "\n".join(lines) + "\n"


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--phase", nargs="+", default=["corpus", "export", "report"],
                   choices=["corpus", "export", "report"])
    p.add_argument("--cache", type=Path, default=RESULTS / "albedo_schlick.jsonl")
    p.add_argument("--export-json", type=Path, default=RESULTS / "albedo_schlick_export.json")
    p.add_argument("--limit", type=int, default=None, help="at most this many new materials")
    p.add_argument("--report", type=Path, default=RESULTS / "albedo_schlick.md", help="the results page to write")
    p.add_argument("--only", nargs="+", default=None, metavar="GROUP/NAME",
                   help="phase corpus: only these materials (e.g. to check that rows reproduce)")
    a = p.parse_args(argv)
    if "corpus" in a.phase:
        phase_corpus(a.cache, a.limit, a.only)
    if "export" in a.phase:
        phase_export(a.export_json)
    if "report" in a.phase:
        text = report(a.cache, a.export_json, "python experiments/albedo_schlick.py " + " ".join(sys.argv[1:]))
        a.report.write_text(text)
        print(text)


if __name__ == "__main__":
    main()
