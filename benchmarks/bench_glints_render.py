"""Glint image time: P-BRDF (Chermain et al. 2019) against naive per-pixel sampling of
the normal-mapped near-mirror surface, at matched error.

Scene: :class:`microfacet.glints.figures.PlaneScene` (a plane seen at 50 degrees under a
point light) with the procedural scratched normal map of
:func:`~microfacet.glints.figures.scratched_normal_map`, one Beckmann lobe per texel.

Method (all errors are relative L2 over the image, ``||x - truth|| / ||truth||``):

1. Two independent naive renders ``A``, ``B`` at ``--ref-spp``; ``R = (A + B) / 2`` is the
   reference. The naive estimator's per-sample variance summed over pixels is
   ``V = N_ref ||A - B||^2 / 2`` (so a naive image at ``N`` spp has expected squared error
   ``V / N``), and ``R`` itself carries ``V / (2 N_ref)``.
2. The P-BRDF image ``I`` is noise free; its bias is
   ``b^2 = ||I - R||^2 - V / (2 N_ref)`` (reference noise removed).
3. Matched error: naive needs ``N* = V / b^2`` spp to reach the P-BRDF's error; its time
   is ``N*`` times the measured naive time per spp (timed at ``--naive-spp``), checked by
   rendering at ``N*`` when that is affordable (``--check``).
4. Speed-up = naive time at ``N*`` / P-BRDF time. Goal: >= 30. Like for like: both
   compiled (Numba, same threads): the naive renderer is ``render_naive``'s one-pass
   kernel (positions, bilinear slopes and the sheared Beckmann's ``D G`` fused), the
   P-BRDF ``eval_cos_footprints``'s pruned kernel. The NumPy naive time per spp is
   printed beside it (what earlier versions of this benchmark compared against).

    .venv/bin/python benchmarks/bench_glints_render.py [--map 512] [--width 64 32 16] [--ref-spp 16384]
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from microfacet.glints import Microsurface
from microfacet.glints.figures import PlaneScene, render_naive, render_pbrdf, scratched_normal_map
from microfacet.glints.pbrdf import eval_cos_footprints


def _best(fn, repeats):
    """``(result, best wall seconds, best CPU seconds)`` over ``repeats`` runs; CPU time
    (``time.process_time``, all threads) is the figure that a loaded machine disturbs least."""
    best, cpu, out = np.inf, np.inf, None
    for _ in range(repeats):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        best, cpu = min(best, time.perf_counter() - t), min(cpu, time.process_time() - c)
    return out, best, cpu


def _pbrdf_image(ms, scene, exact, backend):
    uv, cov, p = scene.pixels()
    wi, e = scene.lighting(p)
    f = eval_cos_footprints(ms, uv, cov, wi, scene.wo, exact=exact, backend=backend)
    return (e[:, None] * f).reshape(scene.height, scene.width, 3)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", type=int, default=512, help="normal map side, texels")
    ap.add_argument("--width", type=int, nargs="+", default=[64, 32], help="image widths (pixels)")
    ap.add_argument("--ref-spp", type=int, default=16384)
    ap.add_argument("--naive-spp", type=int, default=256, help="spp of the timed naive render")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--check", action="store_true", help="render naive at the matched spp too")
    ap.add_argument("--json", help="write the results here")
    args = ap.parse_args(argv)

    t = time.perf_counter()
    ms = Microsurface.from_normal_map(scratched_normal_map(args.map, scratches=int(160 * (args.map / 512) ** 2)))
    print(f"{ms}: built in {time.perf_counter() - t:.2f} s")
    results = []
    for width in args.width:
        scene = PlaneScene(width=width)
        texels = args.map / width
        a = render_naive(ms, scene, args.ref_spp, seed=1)
        b = render_naive(ms, scene, args.ref_spp, seed=2)
        ref = 0.5 * (a + b)
        norm2 = float(np.sum(ref[..., 0] ** 2))
        V = args.ref_spp * float(np.sum((a - b)[..., 0] ** 2)) / 2.0          # per-sample variance
        ref_noise2 = V / (2.0 * args.ref_spp)
        t_per_spp, c_per_spp = {}, {}
        for backend in ("numba", "numpy"):
            spp = args.naive_spp if backend == "numba" else max(1, args.naive_spp // 8)
            _, t_spp, c_spp = _best(lambda: render_naive(ms, scene, spp, seed=3, backend=backend), args.repeats)
            t_per_spp[backend], c_per_spp[backend] = t_spp / spp, c_spp / spp
        row = dict(width=width, height=scene.height, texels_per_pixel=texels,
                   ref_spp=args.ref_spp, ref_noise=float(np.sqrt(ref_noise2 / norm2)),
                   naive_time_per_spp=t_per_spp["numba"], naive_numpy_time_per_spp=t_per_spp["numpy"],
                   naive_cpu_per_spp=c_per_spp["numba"], naive_numpy_cpu_per_spp=c_per_spp["numpy"])
        print(f"\n{width} x {scene.height} pixels, {texels:.1f} texels per pixel; reference 2 x {args.ref_spp} spp "
              f"(its own noise {row['ref_noise']:.4f}); naive per spp per image: compiled "
              f"{1e3 * t_per_spp['numba']:.3f} ms ({1e3 * c_per_spp['numba']:.3f} ms CPU), NumPy "
              f"{1e3 * t_per_spp['numpy']:.3f} ms ({1e3 * c_per_spp['numpy']:.3f} ms CPU)")
        for exact in (True, False):
            for backend in ("numba", "numpy"):
                _pbrdf_image(ms, PlaneScene(width=4), exact, backend)                # compile / warm up
                img, tp, cp = _best(lambda: _pbrdf_image(ms, scene, exact, backend), args.repeats)
                err2 = float(np.sum((img - ref)[..., 0] ** 2))
                bias2 = max(err2 - ref_noise2, 1e-30)
                n_star = V / bias2
                t_naive = n_star * t_per_spp[backend]               # like for like: same backend
                r = dict(exact=exact, backend=backend, time=tp, cpu=cp, error=float(np.sqrt(bias2 / norm2)),
                         error_raw=float(np.sqrt(err2 / norm2)), matched_spp=n_star,
                         naive_time=t_naive, speedup=t_naive / tp,
                         speedup_cpu=n_star * c_per_spp[backend] / cp)
                if args.check and backend == "numba" and n_star <= 4 * args.ref_spp:
                    n = max(1, int(round(n_star)))
                    chk = render_naive(ms, scene, n, seed=4)
                    r["check_error"] = float(np.sqrt(max(np.sum((chk - ref)[..., 0] ** 2) - ref_noise2, 0) / norm2))
                row.setdefault("pbrdf", []).append(r)
                print(f"  P-BRDF {'exact ' if exact else 'approx'} [{backend:5s}] {tp:7.3f} s ({cp:.3f} s CPU), "
                      f"error {r['error']:.4f} (raw {r['error_raw']:.4f}); naive [{backend}] needs {n_star:6.0f} spp "
                      f"= {t_naive:7.2f} s -> {r['speedup']:5.1f}x ({r['speedup_cpu']:5.1f}x in CPU time)"
                      + (f"; naive at that spp: error {r['check_error']:.4f}" if "check_error" in r else ""))
        results.append(row)
    out = dict(map=args.map, results=results)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return out


if __name__ == "__main__":
    main()
