#!/usr/bin/env python3
"""Fitting time of ``mf.fit.fit`` (thesis Ch. 4, Fig. 4.5; goals from the issue).

* isotropic, ``N = 90`` (Algorithm 3): goal <= 0.1 s;
* anisotropic, ``90 x 90`` (Algorithm 1): goal <= 2 s;
* isotropic with a Lambertian base (``diffuse=True``, a search over the base that builds
  ~17 tables): no goal.

Each time covers everything ``fit`` does: backscattering evaluations of the input, the
kernel, the power iterations, the normalized tables (NDF, Smith Lambda, the visible-slope
sampling tables or the anisotropic projected-area and cell tables) and the Fresnel term
(Algorithm 2). The input is an analytic height-correlated Smith GGX BRDF with a copper
conductor Fresnel term (``mf.MicrofacetBRDF(mf.GGX(...), mf.fresnel.Conductor.metal("Cu"))``;
isotropic ``alpha = 0.3``, anisotropic ``alpha_x = 0.2, alpha_y = 0.4, rho = 0.3``), whose
``eval`` runs the Numba kernel; the base, ``k_d = (0.3, 0.2, 0.1)``, is added to the isotropic
one. Reported: best and median of ``--repeats`` runs after one warm-up run
(``time.perf_counter``, or with ``--clock cpu`` ``time.process_time``, the CPU time of
the process, for a shared machine; what a fit keeps per grid, e.g. the row geometry of the
sampling tables, is then kept), and a per-stage breakdown of one isotropic fit.

Least squares (:func:`microfacet.fit.fit_analytic`, goal <= 1 s per material): the four
fits ``microfacet fit`` makes per material (GGX and Beckmann, with and without a
Lambertian base; Fresnel table, default albedo weight), started from the tabulated fit,
on the analytic copper GGX above and on every shared material (``--data``, default
``../shared/data``; skipped when absent). Reported per material: the first fit (which
also evaluates the data on the fitted pairs, cached for the others), each of the other
three, and the total; best of ``--ls-repeats`` runs (the data cache cleared between
runs), plus the conductor Fresnel fit of GGX with a diffuse base.

Usage::

    python benchmarks/bench_fit.py [--repeats 7] [--aniso-repeats 3] [--ls-repeats 3] [--data DIR]
                                   [--clock wall|cpu]
"""
from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.distributions.tabulated import TabulatedIsotropic, theta_grid
from microfacet.fit import extract

GOALS = {"isotropic N=90": 0.1, "anisotropic 90x90": 2.0}
LS_GOAL = 1.0
#: The least-squares fits of ``microfacet fit`` (model, diffuse).
LS_FITS = (("ggx", False), ("ggx", True), ("beckmann", False), ("beckmann", True))
#: The clocks of ``--clock``: wall time, or the CPU time of the process (all its threads).
CLOCKS = {"wall": time.perf_counter, "cpu": time.process_time}
clock = CLOCKS["wall"]


def _times(fn, repeats: int) -> list[float]:
    fn()                                              # warm-up (imports, JIT, caches)
    out = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        out.append(clock() - t0)
    return out


def _stages(brdf, n: int = 90) -> dict:
    """Per-stage times of one isotropic Smith fit (the steps of ``fit``)."""
    t = {}
    t0 = clock()
    theta = theta_grid(n)
    f_back = extract.backscattering(brdf, theta[:-1])
    t["backscattering f(o,o)"] = clock() - t0
    t0 = clock()
    k, rank_one = extract.smith_kernel_isotropic(f_back, theta, "height_correlated")
    t["kernel K' (Eq. 4.14)"] = clock() - t0
    t0 = clock()
    d, _, its = extract.power_iteration(k, rank_one=rank_one)
    t[f"power iterations ({its})"] = clock() - t0
    t0 = clock()
    dist = TabulatedIsotropic(np.append(d, d[-1]))
    t["tables (D, Lambda, sampling)"] = clock() - t0
    t0 = clock()
    extract.extract_fresnel(brdf, mf.MicrofacetBRDF(dist), n, isotropic=True)
    t["Fresnel (Algorithm 2)"] = clock() - t0
    return t


def _least_squares_times(brdf, repeats: int) -> dict:
    """Seconds of each fit of :data:`LS_FITS`, of a conductor GGX + diffuse fit and of a
    GGX + coat + diffuse fit (best of ``repeats``; the per-material data cache cleared
    before each run)."""
    from microfacet.fit import analytic
    start = mf.fit.fit(brdf, 90)
    best = {}
    for _ in range(repeats):
        analytic._DATA_CACHE.clear()
        times = {}
        for model, diffuse in LS_FITS + (("ggx conductor", True), ("ggx coat", True)):
            t0 = clock()
            mf.fit.fit_analytic(brdf, model.split()[0], diffuse=diffuse, start=start, coat="coat" in model,
                                fresnel="conductor" if "conductor" in model else "table")
            times[f"{model}{' + diffuse' if diffuse else ''}"] = clock() - t0
        best = {k: min(v, best.get(k, np.inf)) for k, v in times.items()}
    return best


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--aniso-repeats", type=int, default=3)
    p.add_argument("--ls-repeats", type=int, default=3)
    p.add_argument("--data", type=Path, default=Path(__file__).resolve().parents[1] / ".." / "shared" / "data")
    p.add_argument("--clock", choices=CLOCKS, default="wall",
                   help="wall time (default) or the process's CPU time (a shared machine; set NUMBA_NUM_THREADS=1)")
    args = p.parse_args(argv)
    global clock
    clock = CLOCKS[args.clock]
    cu = mf.fresnel.Conductor.metal("Cu")
    iso = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=cu)
    aniso = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4, rho=0.3), fresnel=cu)
    with_base = mf.fit.SumBRDF(iso, mf.Lambertian((0.3, 0.2, 0.1)))
    print(f"# bench_fit ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, NumPy {np.__version__}; {args.clock} time)")
    results = {
        "isotropic N=90": _times(lambda: mf.fit.fit(iso, 90), args.repeats),
        "anisotropic 90x90": _times(lambda: mf.fit.fit(aniso, 90, anisotropic=True), args.aniso_repeats),
        "isotropic N=90 + diffuse": _times(lambda: mf.fit.fit(with_base, 90, diffuse=True), args.aniso_repeats),
    }
    print("\n| fit | best (s) | median (s) | goal (s) | met |\n|---|---|---|---|---|")
    for name, ts in results.items():
        best, goal = min(ts), GOALS.get(name)
        met = "-" if goal is None else "yes" if best <= goal else "NO"
        print(f"| {name} | {best:.4f} | {statistics.median(ts):.4f} | {goal or '-'} | {met} |")
    print("\nOne isotropic N=90 fit by stage:\n\n| stage | time (s) |\n|---|---|")
    for stage, s in _stages(iso).items():
        print(f"| {stage} | {s:.4f} |")
    materials = {"analytic GGX 0.3, Cu": iso}
    for path in sorted((args.data / "merl").glob("*.binary*")) + sorted((args.data / "rgl").glob("*.bsdf")):
        materials[path.name.split(".")[0]] = mf.measured.load(path)
    print(f"\nLeast-squares fits (s, best of {args.ls_repeats}; goal <= {LS_GOAL} s per fit; the first "
          "fit of a material also evaluates its data):\n")
    rows = {name: _least_squares_times(brdf, args.ls_repeats) for name, brdf in materials.items()}
    names = list(next(iter(rows.values())))
    print("| material | " + " | ".join(names) + " | total of the 4 table fits |\n|---|" + "---|" * (len(names) + 1))
    for material, t in rows.items():
        total = sum(v for k, v in t.items() if "conductor" not in k and "coat" not in k)
        print(f"| {material} | " + " | ".join(f"{t[k]:.3f}" for k in names) + f" | {total:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
