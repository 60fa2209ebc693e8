#!/usr/bin/env python3
"""First-run times (issue 25, item 3), as a new user meets them: from a fresh clone of this
repository's ``HEAD`` (its ``src`` on ``PYTHONPATH``, this interpreter's dependencies) and, with
``--wheel``, from the wheel built from that clone and installed into a clean virtual environment.

Measured, each in a fresh process with ``NUMBA_CACHE_DIR`` a new empty folder (cold) or a folder
filled by the precompile steps of ``make setup`` (after setup):

* the README quick start (goal <= 5 s cold), in ``MICROFACET_COMPILE`` ``background`` (the
  default: NumPy while the kernels compile on a background thread) and ``wait``;
* ``microfacet fit FILE`` of a corpus MERL file (goal <= 3 s cold);
* ``make setup``'s compile steps (``python -m microfacet.kernels --precompile`` and
  ``python -m microfacet.kernels_extra --precompile``) into the empty cache, and again (loads);
* with ``--demo``: ``microfacet demo -o DIR`` as ``make demo`` runs it, after those steps (goal
  <= 90 s), and with ``--demo-cold`` also with an empty cache (minutes).

Python writes its bytecode as it does by default (``PYTHONDONTWRITEBYTECODE`` is removed): a fresh
clone's first runs compile the modules they import (the wheel's are compiled at install).
Wall and CPU (user + system, child processes included) seconds, min, median and max of ``--runs``; the
machine's load average is printed beside each (a shared machine: compare within one table).
Writes ``benchmarks/results/cold_start.md``.

Usage::

    python benchmarks/bench_cold_start.py [--runs 2] [--wheel] [--demo] [--demo-cold] [--file MERL_FILE]
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
DATA = Path(os.environ.get("MICROFACET_DATA") or ROOT.parent / "shared" / "data")
CORPUS = Path(os.environ.get("MICROFACET_CORPUS_CACHE")
              or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "microfacet" / "corpus")
FILES = (CORPUS / "merl__nickel.binary", DATA / "merl" / "nickel.binary.gz")
RESULTS = ROOT / "benchmarks" / "results" / "cold_start.md"


def quick_start(readme: Path) -> str:
    """The README's quick start code block."""
    m = re.search(r"^## Quick start\n.*?^```python\n(.*?)^```", readme.read_text(), re.S | re.M)
    if m is None:
        raise SystemExit(f"{readme} has no '## Quick start' python block")
    return m.group(1)


def load() -> str:
    return " / ".join(f"{x:.1f}" for x in os.getloadavg())


class Install:
    """How to run the package: ``python`` and the environment of one installation."""

    def __init__(self, label: str, python: str, env: dict, readme: Path):
        self.label, self.python, self.env, self.readme = label, python, env, readme

    def timed(self, args, cache: Path, cwd: Path, mode: str = "background") -> tuple[float, float]:
        """Wall and CPU seconds of ``python args`` in a fresh process (``NUMBA_CACHE_DIR=cache``)."""
        env = dict(self.env, NUMBA_CACHE_DIR=str(cache), MICROFACET_COMPILE=mode)
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t = time.perf_counter()
        r = subprocess.run([self.python, *map(str, args)], cwd=cwd, env=env, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
        elapsed = time.perf_counter() - t
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if r.returncode != 0:
            raise SystemExit(f"{self.label}: {' '.join(map(str, args))} failed:\n{r.stdout[-1000:]}\n{r.stderr[-3000:]}")
        return elapsed, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def _user_environment() -> dict:
    """This environment as a user's shell has it: Python writes its bytecode (``__pycache__``),
    so a clone's first commands compile the modules they import and later ones load them."""
    return {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def clone_install(work: Path) -> Install:
    """A fresh ``git clone`` of ``HEAD``: its ``src`` first on ``PYTHONPATH``, with this interpreter."""
    dest = work / "clone"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(dest)], check=True)
    env = dict(_user_environment(), PYTHONPATH=str(dest / "src"))
    head = subprocess.run(["git", "-C", str(dest), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    return Install(f"fresh clone ({head})", sys.executable, env, dest / "README.md")


def wheel_install(work: Path, clone: Path) -> tuple[Install, float]:
    """The wheel built from ``clone``, installed into a clean venv; and the install's seconds."""
    dist = work / "dist"
    subprocess.run([sys.executable, "-m", "build", "--wheel", "--outdir", str(dist), str(clone)], check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wheel = next(dist.glob("microfacet-*.whl"))
    venv = work / "venv"
    t = time.perf_counter()
    subprocess.run(["python3", "-m", "venv", str(venv)], check=True)
    subprocess.run([str(venv / "bin" / "python"), "-m", "pip", "install", "--quiet", str(wheel)], check=True,
                   stderr=subprocess.DEVNULL)
    env = {k: v for k, v in _user_environment().items() if k not in ("PYTHONPATH", "MICROFACET_DATA")}
    return Install(f"wheel ({wheel.name}, clean venv)", str(venv / "bin" / "python"), env, clone / "README.md"), \
        time.perf_counter() - t


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--wheel", action="store_true", help="also from a wheel in a clean venv")
    p.add_argument("--demo", action="store_true", help="also time microfacet demo after the precompile steps")
    p.add_argument("--demo-cold", action="store_true", help="also time microfacet demo with an empty cache (minutes)")
    p.add_argument("--file", type=Path, default=next((f for f in FILES if f.exists()), FILES[0]),
                   help="MERL file for microfacet fit (default: the corpus's nickel)")
    args = p.parse_args()
    rows = []

    def series(inst, label, cmd, runs, work, cache=None, mode="background"):
        """``runs`` runs, each with a new empty cache (``cache`` None) or with ``cache``."""
        times, cpus, loads = [], [], []
        for i in range(runs):
            c = cache
            if c is None:
                c = Path(tempfile.mkdtemp(prefix="cache-", dir=work))
            loads.append(load())
            wall, cpu = inst.timed(cmd, c, work, mode)
            times.append(wall)
            cpus.append(cpu)
            print(f"  {inst.label[:14]:14s} {label:44s} {mode:10s} {wall:7.2f} s wall {cpu:7.2f} s CPU   load {loads[-1]}",
                  flush=True)
        rows.append((inst.label, label, mode, times, cpus, loads))

    with tempfile.TemporaryDirectory(prefix="bench-cold-") as tmp:
        work = Path(tmp)
        installs = [clone_install(work)]
        if args.wheel:
            inst, seconds = wheel_install(work, work / "clone")
            print(f"wheel installed in {seconds:.1f} s", flush=True)
            installs.append(inst)
        for inst in installs:
            run = work / re.sub(r"\W+", "-", inst.label)[:20]
            run.mkdir()
            script = run / "quick_start.py"
            script.write_text(quick_start(inst.readme))
            qs = [script]
            fit = ["-m", "microfacet", "fit", args.file, "-o", run / "fit.npz"]
            pre = ["-m", "microfacet.kernels", "--precompile", "-q"]
            extra = ["-m", "microfacet.kernels_extra", "--precompile", "-q"]
            print(inst.label, flush=True)
            series(inst, "quick start, empty cache", qs, args.runs, run)
            if inst is installs[0]:                 # every kernel compiled at its first call, as before
                series(inst, "quick start, empty cache", qs, 1, run, mode="wait")
            if args.file.exists():
                series(inst, f"microfacet fit {args.file.name}, empty cache", fit, args.runs, run)
            else:
                print(f"fit: {args.file} is absent: not timed")
            filled = run / "filled"
            filled.mkdir()
            series(inst, "precompile BRDF kernels, empty cache", pre, 1, filled.parent, filled, "wait")
            series(inst, "precompile measured/LEADR/glints, empty cache", extra, 1, filled.parent, filled, "wait")
            series(inst, "precompile BRDF kernels, filled cache", pre, 1, run, filled, "wait")
            series(inst, "precompile measured/LEADR/glints, filled cache", extra, 1, run, filled, "wait")
            series(inst, "quick start, after precompile", qs, args.runs, run, filled)
            if args.file.exists():
                series(inst, f"microfacet fit {args.file.name}, after precompile", fit, args.runs, run, filled)
            if args.demo and inst is installs[0]:       # make demo: from the repository
                demo = ["-m", "microfacet", "demo", "-o", run / "demo"]
                series(inst, "microfacet demo, after precompile", demo, 1, run, filled)
                shutil.rmtree(run / "demo", ignore_errors=True)
            if args.demo_cold and inst is installs[0]:
                demo = ["-m", "microfacet", "demo", "-o", run / "demo-cold"]
                series(inst, "microfacet demo, empty cache", demo, 1, run)
                shutil.rmtree(run / "demo-cold", ignore_errors=True)
    lines = ["# Cold start (issue 25, item 3)", "",
             f"`python benchmarks/bench_cold_start.py --runs {args.runs}{' --wheel' if args.wheel else ''}"
             f"{' --demo' if args.demo else ''}{' --demo-cold' if args.demo_cold else ''}`, "
             f"{time.strftime('%Y-%m-%d %H:%M')}, niceness {os.nice(0)}, {os.cpu_count()} CPUs shared with other work (load averages "
             "1 / 5 / 15 min at the start of each run beside it; at the end "
             f"{load()}). Wall and CPU (user + system, child processes included) seconds of fresh processes. "
             "Python writes its bytecode as by default: the clone's first runs compile the modules they import "
             "(the max column of its first series). "
             "Empty cache: `NUMBA_CACHE_DIR` a new empty folder per run; after precompile: the folder that "
             "`python -m microfacet.kernels --precompile` and `python -m microfacet.kernels_extra --precompile` "
             "(`make setup`'s compile steps) filled. Goals: quick start <= 5 s and `microfacet fit` <= 3 s "
             "with an empty cache, `make demo` <= 90 s after `make setup`.",
             "", "| install | what | MICROFACET_COMPILE | runs | wall min s | wall median s | wall max s | CPU median s "
             "| load averages |",
             "|---|---|---|---:|---:|---:|---:|---:|---|"]
    for inst, label, mode, times, cpus, loads in rows:
        lines.append(f"| {inst} | {label} | {mode} | {len(times)} | {min(times):.2f} | "
                     f"{statistics.median(times):.2f} | {max(times):.2f} | {statistics.median(cpus):.2f} | {'; '.join(loads)} |")
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(lines) + "\n")
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
