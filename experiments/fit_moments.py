#!/usr/bin/env python3
"""The Fresnel term of the moment conversions on the shared materials (issue 10).

For every MERL ``.binary(.gz)`` in ``DATA/merl`` and RGL ``.bsdf`` in ``DATA/rgl`` and each
albedo weight of ``--weights`` this fits ``fit = mf.fit.fit(m, N, albedo_weight=w)`` and
converts it by moments (App. C) to GGX and Beckmann with

* the fit's own Fresnel table, solved for the tabulated NDF (and tuned for its albedo
  when ``w > 0``): ``fit.to_ggx(resolve_fresnel=False)``, the conversion before issue 10's
  last round;
* a table solved for the converted NDF against the fit's lobe: ``fit.to_ggx()``;
* a table solved for the converted NDF against the data: ``fit.to_ggx(reference=m)`` (what
  ``microfacet fit --method moments`` writes);

and reports each conversion's grid error (:func:`microfacet.metrics.fit_error`), uniform
error (:func:`~microfacet.metrics.uniform_error`) and albedo ratio farthest from 1
(:func:`~microfacet.metrics.albedo_ratios`, views 0/30/60/75 deg, RGB).

Usage::

    python experiments/fit_moments.py [--data ../shared/data] [--resolution 90] [--weights 0,4]
                                      [--out table.md]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import microfacet as mf
from microfacet.fit.outputs import _worst, material_name
from microfacet.io import write_text
from microfacet.metrics import albedo_ratios, fit_error, uniform_error

ROOT = Path(__file__).resolve().parents[1]
#: Conversions by column name: the options of ``to_ggx`` / ``to_beckmann`` (``m``: the data).
CONVERSIONS = {"fit's table": lambda m: dict(resolve_fresnel=False), "own, vs fit": lambda m: {},
               "own, vs data": lambda m: dict(reference=m)}


def convert_one(path: Path, resolution: int, weights) -> list[dict]:
    m = mf.measured.load(path)
    rows = []
    for w in weights:
        fit = mf.fit.fit(m, resolution=resolution, albedo_weight=w)
        fits = {(family, name): (fit.to_ggx if family == "GGX" else fit.to_beckmann)(**options(m))
                for family in ("GGX", "Beckmann") for name, options in CONVERSIONS.items()}
        grid, uniform, albedo = fit_error(m, fits), uniform_error(m, fits), albedo_ratios(m, fits)
        for family in ("GGX", "Beckmann"):
            rows.append({"material": material_name(path), "weight": w, "family": family,
                         "cells": [(grid[(family, n)], uniform[(family, n)], _worst(albedo[(family, n)]))
                                   for n in CONVERSIONS]})
    return rows


def format_table(rows: list[dict], resolution: int) -> str:
    lines = [f"Moment conversions of `fit(m, {resolution}, albedo_weight=w)`: grid error / uniform error / "
             "albedo ratio farthest from 1 (views 0/30/60/75°, RGB) with each Fresnel table.", "",
             "| material | w | family | " + " | ".join(CONVERSIONS) + " |", "|---|---|---|" + "---|" * len(CONVERSIONS)]
    lines += [f"| {r['material']} | {r['weight']:g} | {r['family']} | "
              + " | ".join(f"{g:.4f} / {u:.4f} / {a:.3f}" for g, u, a in r["cells"]) + " |" for r in rows]
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT / ".." / "shared" / "data")
    ap.add_argument("--resolution", type=int, default=90)
    ap.add_argument("--weights", default="0,4", help="albedo weights of the tabulated fit, comma-separated")
    ap.add_argument("--out", type=Path, default=ROOT / "experiments" / "results" / "fit_moments.md")
    args = ap.parse_args(argv)
    paths = sorted((args.data / "merl").glob("*.binary*")) + sorted((args.data / "rgl").glob("*.bsdf"))
    if not paths:
        print(f"fit_moments: no MERL or RGL files under {args.data}", file=sys.stderr)
        return 1
    weights = [float(w) for w in args.weights.split(",") if w]
    rows = [row for p in paths for row in convert_one(p, args.resolution, weights)]
    text = format_table(rows, args.resolution)
    print(text)
    write_text(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
