#!/usr/bin/env python3
"""Load time and evaluation throughput of the measured-BRDF readers (``mf.measured``).

For every MERL ``.binary(.gz)`` and RGL ``.bsdf`` file in ``--data`` (default
``../shared/data`` from the project root; UTIA ``.bin`` files too if any) and for a
synthetic UTIA file written to a temporary folder (no real one ships with the data),
this times ``mf.measured.load(path)`` and ``eval(wi, wo)`` / ``sample(u, wo)`` on
``--n`` fixed-seed direction pairs uniform over the upper hemisphere (float64, NumPy,
one thread). Each figure is the best and the median of ``--repeats`` runs after one
warm-up run (``time.perf_counter``); loads are cold only for the first run (the OS file
cache keeps the bytes afterwards).

Usage::

    python benchmarks/bench_measured.py [--n 1000000] [--repeats 3] [--json out.json]
"""
from __future__ import annotations

import argparse
import json
import platform
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

import microfacet as mf
from microfacet.geometry import spherical_to_cartesian
from microfacet.io import write_text

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DATA = ROOT / ".." / "shared" / "data"
PATTERNS = ("merl/*.binary*", "rgl/*.bsdf", "utia/*.bin")


def timed(fn, repeats: int) -> tuple[float, float]:
    """Best and median wall time of ``fn()`` over ``repeats`` runs after a warm-up run."""
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times), statistics.median(times)


def uniform_dirs(rng, n: int) -> np.ndarray:
    u = rng.random((n, 2))
    return spherical_to_cartesian(np.arccos(u[:, 0]), 2 * np.pi * u[:, 1])


def synthetic_utia(folder: Path) -> Path:
    """A smooth synthetic UTIA file (the data folder has no real one)."""
    rng = np.random.default_rng(0)
    path = folder / "synthetic_utia.bin"
    path.write_bytes(rng.uniform(0, 140, (3, 6, 48, 6, 48)).astype("<f8").tobytes())
    return path


def bench_file(path: Path, wi, wo, u, repeats: int) -> dict:
    load = timed(lambda: mf.measured.load(path), repeats)
    m = mf.measured.load(path)
    ev = timed(lambda: m.eval(wi, wo), repeats)
    sa = timed(lambda: m.sample(u, wo), repeats)
    n = len(wi)
    return {"file": path.name, "format": m.format, "bytes": path.stat().st_size,
            "load_best_s": load[0], "load_median_s": load[1],
            "eval_best_s": ev[0], "eval_median_s": ev[1], "eval_meval_per_s": n / ev[0] / 1e6,
            "sample_best_s": sa[0], "sample_median_s": sa[1], "sample_meval_per_s": n / sa[0] / 1e6}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA, help="folder with merl/, rgl/, utia/")
    ap.add_argument("--n", type=int, default=1_000_000, help="direction pairs per eval/sample")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", type=Path, help="also write the raw results here")
    args = ap.parse_args(argv)

    rng = np.random.default_rng(1)
    wi, wo, u = uniform_dirs(rng, args.n), uniform_dirs(rng, args.n), rng.random((args.n, 2))
    files = sorted(p for pattern in PATTERNS for p in args.data.glob(pattern)) if args.data.exists() else []
    if not files:
        print(f"no measured files under {args.data}; benchmarking the synthetic UTIA file only")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for path in files + [synthetic_utia(Path(tmp))]:
            rows.append(bench_file(path, wi, wo, u, args.repeats))
            r = rows[-1]
            print(f"{r['file']:34s} {r['format']:5s} {r['bytes'] / 2**20:7.1f} MiB  "
                  f"load {1e3 * r['load_best_s']:7.1f} ms (median {1e3 * r['load_median_s']:7.1f})  "
                  f"eval {r['eval_best_s']:6.3f} s = {r['eval_meval_per_s']:5.2f} M/s  "
                  f"sample {r['sample_best_s']:6.3f} s = {r['sample_meval_per_s']:5.2f} M/s", flush=True)
    if args.json:
        env = {"python": platform.python_version(), "numpy": np.__version__,
               "machine": platform.machine(), "processor": platform.processor(), "n": args.n,
               "repeats": args.repeats}
        write_text(args.json, json.dumps({"environment": env, "results": rows}, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
