#!/usr/bin/env python3
"""First-run times (issue 25, item 3): the README quick start and ``microfacet fit FILE`` with an
empty Numba cache (cold) and a filled one (warm), in ``MICROFACET_COMPILE`` ``background`` (the
default: NumPy while the kernels compile on a background thread) and ``wait`` (every kernel
compiled at its first call, as before), ``python -m microfacet.kernels --precompile`` into an empty
cache and into a filled one, and with ``--demo`` ``microfacet demo --no-viewer --no-mitsuba`` cold,
after ``--precompile`` and warm.

Each figure is the wall time of a fresh process (``NUMBA_CACHE_DIR`` a new empty folder for cold
runs, one filled by a first run for warm ones), min and median of ``--runs``; the machine's load
average is printed beside them, since a shared machine's times vary (compare ratios within one run).
Writes ``benchmarks/results/cold_start.md``.

Usage::

    python benchmarks/bench_cold_start.py [--runs 3] [--demo] [--file MERL_FILE]
"""
from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FILE = Path(os.environ.get("MICROFACET_DATA", ROOT.parent / "shared" / "data")) / "merl" / "nickel.binary.gz"
RESULTS = ROOT / "benchmarks" / "results" / "cold_start.md"
BIN = Path(sys.executable).parent


def quick_start() -> str:
    """The README's quick start code block."""
    m = re.search(r"^## Quick start\n.*?^```python\n(.*?)^```", (ROOT / "README.md").read_text(), re.S | re.M)
    if m is None:
        raise SystemExit("README.md has no '## Quick start' python block")
    return m.group(1)


def timed(cmd, cache: Path, mode: str, cwd: Path) -> tuple[float, float]:
    """Wall and CPU (user + system, its child processes included) seconds of ``cmd`` in a fresh
    process with ``NUMBA_CACHE_DIR=cache`` and ``MICROFACET_COMPILE=mode``."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), MICROFACET_COMPILE=mode)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(map(str, cmd))} failed:\n{r.stderr[-2000:]}")
    return elapsed, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def load() -> str:
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


def series(label, cmd, mode, runs, work, warm_cache=None) -> tuple[str, list[float], str]:
    """``runs`` cold runs (each a new empty cache), or warm runs (``warm_cache`` filled first)."""
    times, cpus, loads = [], [], []
    for i in range(runs):
        if warm_cache is None:
            cache = work / f"cache-{label}-{mode}-{i}".replace(" ", "_")
            cache.mkdir()
        else:
            cache = warm_cache
        loads.append(load())
        wall, cpu = timed(cmd, cache, mode, work)
        times.append(wall)
        cpus.append(cpu)
        print(f"  {label:42s} {mode:10s} {wall:7.2f} s wall {cpu:7.2f} s CPU   load {loads[-1]}", flush=True)
    return label, times, cpus, mode, loads


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--demo", action="store_true", help="also time microfacet demo (minutes)")
    p.add_argument("--file", type=Path, default=FILE, help="MERL file for microfacet fit")
    args = p.parse_args()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-cold-") as tmp:
        work = Path(tmp)
        script = work / "quick_start.py"
        script.write_text(quick_start())
        qs = [sys.executable, str(script)]
        warm = work / "warm"
        warm.mkdir()
        print("quick start", flush=True)
        rows.append(series("quick start, cold", qs, "background", args.runs, work))
        rows.append(series("quick start, cold", qs, "wait", args.runs, work))
        timed([sys.executable, "-m", "microfacet.kernels", "--precompile", "-q"], warm, "wait", work)
        timed(qs, warm, "wait", work)
        rows.append(series("quick start, warm", qs, "background", args.runs, work, warm))
        rows.append(series("quick start, warm", qs, "wait", args.runs, work, warm))
        if args.file.exists():
            fit = [str(BIN / "microfacet"), "fit", str(args.file), "-o", str(work / "nickel.npz")]
            print("fit", flush=True)
            rows.append(series("microfacet fit nickel, cold", fit, "background", args.runs, work))
            rows.append(series("microfacet fit nickel, warm", fit, "background", args.runs, work, warm))
        else:
            print(f"fit: {args.file} is absent: not timed")
        print("precompile", flush=True)
        pre = [sys.executable, "-m", "microfacet.kernels", "--precompile", "-q"]
        rows.append(series("precompile (float64), empty cache", pre, "wait", 1, work))
        rows.append(series("precompile (float64), filled cache", pre, "wait", args.runs, work, warm))
        if args.demo:
            demo = [str(BIN / "microfacet"), "demo", "-o", str(work / "demo"), "--no-viewer", "--no-mitsuba"]
            print("demo", flush=True)
            rows.append(series("demo --no-viewer --no-mitsuba, cold", demo, "background", 1, work))
            after = work / "after-precompile"
            after.mkdir()
            timed(pre, after, "wait", work)
            rows.append(series("demo ..., after --precompile only", demo, "background", 1, work, after))
            rows.append(series("demo ..., warm (second run)", demo, "background", 1, work, after))
        shutil.rmtree(work / "demo", ignore_errors=True)
    lines = ["# Cold start (issue 25, item 3)", "",
             f"`python benchmarks/bench_cold_start.py --runs {args.runs}{' --demo' if args.demo else ''}`, "
             f"{time.strftime('%Y-%m-%d %H:%M')}, {os.cpu_count()} CPUs, load average at the end {load()} "
             "(a shared machine: compare within this table; CPU seconds vary less with the load than wall seconds). Wall and CPU (user + system, child processes included) seconds of fresh processes; cold: "
             "`NUMBA_CACHE_DIR` a new empty folder per run; warm: a folder filled by `--precompile` and a first run.",
             "", "| what | MICROFACET_COMPILE | runs | wall min s | wall median s | CPU median s | load averages |",
             "|---|---|---:|---:|---:|---:|---|"]
    for label, times, cpus, mode, loads in rows:
        lines.append(f"| {label} | {mode} | {len(times)} | {min(times):.2f} | {statistics.median(times):.2f} | "
                     f"{statistics.median(cpus):.2f} | {'; '.join(loads)} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
