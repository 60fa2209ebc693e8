#!/usr/bin/env python3
"""Reading a 16-bit RGB normal-map PNG: the library's reader (``imagecodecs``, libpng)
against ``pypng`` (pure Python), the two maintained candidates for exact 16-bit PNGs,
and decoding it into slopes with the library's normal-map decoder.

Writes a ``--size`` x ``--size`` (default 4096) 16-bit RGB normal map of a Gaussian
heightfield with :func:`microfacet.io.write_png_data` (zlib level 6), then times reading
it back as a ``uint16 (H, W, 3)`` array with each library (best of ``--repeats`` runs,
``time.perf_counter``) and checks that both return the written samples exactly. pypng
is optional (``pip install pypng``); without it only the library's reader is timed.
Then it times :func:`microfacet.io.normalmap.read_slopes` on the samples (best of
``--repeats``) and reports its peak memory above the input (``tracemalloc``).

Usage::

    python benchmarks/bench_png.py [--size 4096] [--repeats 2]
"""
from __future__ import annotations

import argparse
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

from microfacet import leadr
from microfacet.io import read_png_data, write_png_data
from microfacet.io.normalmap import read_slopes


def read_pypng(path: Path) -> np.ndarray:
    """The samples of a PNG through pypng (rows as Python arrays, stacked)."""
    import png
    width, height, rows, info = png.Reader(filename=str(path)).asDirect()
    return np.vstack([np.asarray(row, np.uint16) for row in rows]).reshape(height, width, info["planes"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=4096)
    parser.add_argument("--repeats", type=int, default=2)
    args = parser.parse_args()
    slopes = leadr.height_to_slopes(leadr.gaussian_heightfield((args.size, args.size), 0.3, correlation=3.0, seed=1))
    nmap = leadr.encode_normal_map(slopes, np.uint16)
    readers = {"imagecodecs (microfacet.io.read_png_data)": read_png_data}
    try:
        import png  # noqa: F401
        readers["pypng"] = read_pypng
    except ImportError:
        print("pypng not installed: timing imagecodecs only")
    with tempfile.TemporaryDirectory() as folder:
        path = write_png_data(Path(folder) / "nmap16.png", nmap)
        print(f"{args.size} x {args.size} 16-bit RGB PNG, {path.stat().st_size / 2**20:.1f} MiB")
        for name, read in readers.items():
            times = []
            for _ in range(args.repeats):
                t = time.perf_counter()
                back = read(path)
                times.append(time.perf_counter() - t)
            exact = back.dtype == np.uint16 and np.array_equal(back, nmap)
            print(f"{name}: best {min(times):.2f} s of {args.repeats}, exact: {exact}")
    times = []
    for _ in range(args.repeats):
        tracemalloc.start()
        t = time.perf_counter()
        read_slopes(nmap)
        times.append(time.perf_counter() - t)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    print(f"decoding to slopes (read_slopes): best {min(times):.2f} s of {args.repeats}, "
          f"peak {peak / 2**20:.0f} MiB above the input")


if __name__ == "__main__":
    main()
