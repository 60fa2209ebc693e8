#!/usr/bin/env python3
"""Power-iteration fits (thesis Ch. 4) of the measured materials of ``../shared/data``:
fit errors and times, and for RGL files the fitted NDF against the file's own ``ndf``.

For every MERL ``.binary(.gz)`` in ``DATA/merl`` and RGL ``.bsdf`` in ``DATA/rgl`` this
runs ``mf.fit.fit(m, resolution=N)`` (isotropic; with ``--anisotropic`` also an
anisotropic fit of the RGL files) and reports

* the fit time (``time.perf_counter`` around ``mf.fit.fit`` alone; one run, cold);
* the relative RMS error of ``f_r cos theta_i`` of the tabulated fit, ``fit.to_ggx()``
  and ``fit.to_beckmann()`` against the data (:func:`microfacet.metrics.fit_error`: a
  32^3 grid of MERL coordinates, **grazing pairs with cos theta_i or cos theta_o < 0.1
  excluded**, and for MERL the pairs touching unmeasured samples);
* for RGL files, the relative L2 difference of ``D cos theta_h`` over the hemisphere
  between each fit's NDF and the file's ``ndf`` field (both normalized to projected area
  1; :func:`microfacet.metrics.ndf_error`), the file's NDF having been retrieved by its
  authors from retro-reflection measurements by the same power-iteration method.

Usage::

    python experiments/fit_measured.py [--data ../shared/data] [--resolution 90]
                                       [--anisotropic] [--out table.md]
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.fit.outputs import material_name
from microfacet.io import write_text
from microfacet.metrics import describe_fit_error, fit_error, ndf_error

ROOT = Path(__file__).resolve().parents[1]


def _ndf(brdf):
    """The NDF callable of a fit (``brdf.ndf`` or ``brdf.distribution.ndf``)."""
    ndf = getattr(brdf, "ndf", None)
    return ndf if ndf is not None else brdf.distribution.ndf


def _alpha(brdf) -> str:
    d = brdf.distribution
    ax, ay, rho = float(d.alpha_x), float(d.alpha_y), float(d.rho)
    return f"{ax:.4f}" if abs(ax - ay) < 1e-4 * ax and abs(rho) < 1e-6 else f"{ax:.4f}, {ay:.4f}, ρ {rho:+.3f}"


def fit_one(path: Path, resolution: int, anisotropic: bool) -> dict:
    m = mf.measured.load(path)
    t0 = time.perf_counter()
    fit = mf.fit.fit(m, resolution=resolution, anisotropic=anisotropic)
    seconds = time.perf_counter() - t0
    fits = {"tabulated": fit, "ggx": fit.to_ggx(), "beckmann": fit.to_beckmann()}
    row = {"material": material_name(path), "format": m.format,
           "mode": "aniso" if anisotropic else "iso", "seconds": seconds,
           "errors": fit_error(m, fits), "ggx": _alpha(fits["ggx"]), "beckmann": _alpha(fits["beckmann"])}
    if hasattr(m, "ndf_table"):
        row["ndf"] = {k: ndf_error(m.ndf, _ndf(b))["l2"] for k, b in fits.items()}
    return row


def format_tables(rows: list[dict], resolution: int) -> str:
    lines = [f"Fits at resolution {resolution} ({platform.processor() or platform.machine()}, "
             f"Python {platform.python_version()}, NumPy {np.__version__}).", "",
             "| material | format | fit | fit time (s) | err tabulated | err GGX | err Beckmann "
             "| GGX α | Beckmann α | pairs |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        e = r["errors"]
        lines.append(f"| {r['material']} | {r['format']} | {r['mode']} | {r['seconds']:.2f} "
                     f"| {e['tabulated']:.4f} | {e['ggx']:.4f} | {e['beckmann']:.4f} "
                     f"| {r['ggx']} | {r['beckmann']} | {e['n_pairs']} |")
    lines += ["", f"Errors: {describe_fit_error()}.", ""]
    ndf_rows = [r for r in rows if "ndf" in r]
    if ndf_rows:
        lines += ["NDF of the fits against the RGL file's own `ndf` field: relative L2 difference of "
                  "D cos θh over the hemisphere (both normalized to projected area 1; 128 × 128 "
                  "midpoint quadrature, θ quadratic in u).", "",
                  "| material | fit | tabulated | GGX | Beckmann |", "|---|---|---|---|---|"]
        lines += [f"| {r['material']} | {r['mode']} | {r['ndf']['tabulated']:.4f} | {r['ndf']['ggx']:.4f} "
                  f"| {r['ndf']['beckmann']:.4f} |" for r in ndf_rows]
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=ROOT / ".." / "shared" / "data")
    ap.add_argument("--resolution", type=int, default=90)
    ap.add_argument("--anisotropic", action="store_true", help="also fit the RGL files anisotropically")
    ap.add_argument("--out", type=Path, help="write the Markdown tables here (atomically)")
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
        rows.append(fit_one(path, args.resolution, aniso))
    text = format_tables(rows, args.resolution)
    print(text)
    if args.out:
        write_text(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
