#!/usr/bin/env python3
"""Where the single-file ``microfacet fit FILE -o OUT --no-picture`` spends its time, and what
its threads overlap (issue 10).

* ``stages`` (default): each stage of the command alone, one after the other, in
  ``--runs`` fresh processes: thread CPU seconds (``time.thread_time``), min and median.
  The command runs "read + gunzip" beside the "measured + fit" imports, the tabulated
  fit beside the data's side of the metrics, and the two least-squares fits beside the
  metrics of the tabulated and moment fits (:func:`microfacet.fit.outputs.fit_material`);
  the critical path printed is that schedule on 2 cores with free overlap.
* ``threads``: those pairs of stages one after the other and on two threads, alternated
  ``--runs`` times in one process, beside a control (two GIL-free NumPy loops on two
  threads): process CPU / wall near 2 for the control and near 1 for a pair means the GIL
  serializes the pair; near 1 for the control means the machine has no second core free.

Usage::

    python benchmarks/bench_fit_command.py [stages|threads] [--file FILE] [--runs 5]
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

FILE = os.path.join(os.environ.get("MICROFACET_DATA", "../shared/data"), "merl", "nickel.binary.gz")
STAGES = ("imports NumPy + CLI", "read + gunzip", "measured + fit imports", "MERL parse + table", "tabulated fit",
          "moment conversions", "metrics: data side", "least squares GGX", "least squares Beckmann",
          "metrics: tabulated + moments", "metrics: least squares")


def one_process(path: str) -> list[float]:
    """Thread CPU of each of :data:`STAGES`, run one after the other in this (fresh) process."""
    times, clock = [], [time.thread_time()]

    def mark():
        clock.append(time.thread_time())
        times.append(clock[-1] - clock[-2])
    import microfacet.cli  # noqa: F401  (NumPy, as before the command runs)
    from microfacet.batch.tasks import _file_data
    mark()
    data = _file_data(path)
    mark()
    from microfacet.fit import outputs
    from microfacet.measured import load_bytes
    mark()
    brdf = load_bytes(data, path)
    mark()
    from microfacet.cli.fit import numpy_kernels
    with numpy_kernels():
        fit = outputs._run_fit(brdf, 90, False, "smith", False, 4.0)
        mark()
        first = {"tabulated": fit, "ggx_moments": fit.to_ggx(), "beckmann_moments": fit.to_beckmann()}
        mark()
        metrics = outputs._metrics(brdf)
        mark()
        least = []
        for model in ("ggx", "beckmann"):
            least.append(outputs._least_squares_fit(brdf, fit, model, False, "auto", "table", 4.0))
            mark()
        outputs._scores(metrics, first)
        mark()
        outputs._scores(metrics, {f"{name}_least_squares": b for name, b, _ in least})
        mark()
    return times


def stages(path: str, runs: int) -> None:
    rows = [[float(v) for v in subprocess.run([sys.executable, __file__, "_one", "--file", path], check=True,
                                              capture_output=True, text=True).stdout.split()] for _ in range(runs)]
    best = [min(col) for col in zip(*rows, strict=True)]
    for name, col, b in zip(STAGES, zip(*rows, strict=True), best, strict=True):
        print(f"{name:30s} min {b:.3f}  median {statistics.median(col):.3f}")
    s = dict(zip(STAGES, best, strict=True))
    path2 = (s["imports NumPy + CLI"] + max(s["read + gunzip"], s["measured + fit imports"]) + s["MERL parse + table"]
             + max(s["tabulated fit"] + s["moment conversions"], s["metrics: data side"])
             + max(s["least squares GGX"], s["least squares Beckmann"],
                   (s["least squares GGX"] + s["least squares Beckmann"] + s["metrics: tabulated + moments"]) / 2)
             + s["metrics: least squares"])
    print(f"total {sum(best):.3f} s thread CPU; critical path on 2 cores, free overlap: {path2:.3f} s")


def threads(path: str, runs: int) -> None:
    from concurrent.futures import ThreadPoolExecutor

    import numpy as np

    from microfacet.cli.fit import numpy_kernels
    from microfacet.fit import outputs
    from microfacet.measured import load
    a = np.random.default_rng(0).random(2_000_000)

    def control():
        for _ in range(3):
            np.sqrt(np.exp(a) * a + 1.0)
    with numpy_kernels():
        brdf = load(path)
        fit = outputs._run_fit(brdf, 90, False, "smith", False, 4.0)
        metrics = outputs._metrics(brdf)
        first = {"tabulated": fit, "ggx_moments": fit.to_ggx(), "beckmann_moments": fit.to_beckmann()}

        def least(model):
            return outputs._least_squares_fit(brdf, fit, model, False, "auto", "table", 4.0)
        pairs = {"tabulated fit | metrics data side": (lambda: outputs._run_fit(brdf, 90, False, "smith", False, 4.0),
                                                       lambda: outputs._metrics(brdf)),
                 "least squares GGX | Beckmann": (lambda: least("ggx"), lambda: least("beckmann")),
                 "least squares GGX | metrics first": (lambda: least("ggx"), lambda: outputs._scores(metrics, first))}
        with ThreadPoolExecutor(2) as pool:
            for name, (f, g) in pairs.items():
                got = {"serial": [], "threads": [], "control": []}
                for _ in range(runs):
                    for mode, out in got.items():
                        t, c = time.perf_counter(), time.process_time()
                        if mode == "serial":
                            f(), g()
                        else:
                            [job.result() for job in ((pool.submit(f), pool.submit(g)) if mode == "threads"
                                                      else (pool.submit(control), pool.submit(control)))]
                        out.append((time.perf_counter() - t, time.process_time() - c))
                (ws, _), (wt, ct), (wc, cc) = ([statistics.median(v) for v in zip(*got[m], strict=True)] for m in got)
                print(f"{name:36s} serial wall {ws:.3f}  threads wall {wt:.3f} ({wt / ws:.2f}x), "
                      f"threads CPU/wall {ct / wt:.2f}; control CPU/wall {cc / wc:.2f}")


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", nargs="?", default="stages", choices=("stages", "threads", "_one"))
    p.add_argument("--file", default=FILE)
    p.add_argument("--runs", type=int, default=5)
    args = p.parse_args()
    print(f"load average {os.getloadavg()[0]:.2f}", file=sys.stderr)
    if args.mode == "_one":
        print(" ".join(f"{v:.4f}" for v in one_process(args.file)))
    else:
        (stages if args.mode == "stages" else threads)(args.file, args.runs)
    print(f"load average {os.getloadavg()[0]:.2f}", file=sys.stderr)


if __name__ == "__main__":
    main()
