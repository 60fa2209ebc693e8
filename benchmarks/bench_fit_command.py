#!/usr/bin/env python3
"""Where ``microfacet fit FILE -o OUT`` spends its time (issue 24: the whole command in 2 s).

* ``wall``: the command end to end in ``--runs`` fresh processes, wall and CPU (user + system,
  the fitting process included); with ``--baseline SRC`` (the ``src`` folder of another
  checkout, e.g. a ``git worktree`` of an older commit), its runs alternate with that
  checkout's, so the two are compared in one run on a shared machine.
* ``also``: the same end-to-end table for other files (``--also``; by default corpus chrome,
  whose perceptual fits show a colour cast: the command balances their colour,
  :mod:`microfacet.fit.colour`), where it converted (``tests/conftest.py``'s corpus cache).
* ``stages``: each stage of the command alone, one after the other, in one fresh process per
  run, with the evaluations on the NumPy path as the command runs them
  (:func:`microfacet.cli.fit.numpy_kernels`): thread CPU seconds (``time.thread_time``), min
  and median over the runs. Their sum is the command's CPU work; half of it is the least
  wall time that two cores can give it.

Writes ``benchmarks/results/fit_command.md`` (both tables, with the machine's load averages).

Usage::

    python benchmarks/bench_fit_command.py [--file FILE] [--also FILE ...] [--runs 5] [--baseline SRC]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_cold_start import CORPUS, FILES, ROOT, load   # the same file and load line as the cold-start benchmark

RESULTS = ROOT / "benchmarks" / "results" / "fit_command.md"
#: A corpus material whose fits show a colour cast, as ``tests/conftest.py`` converts it.
CAST_FILE = CORPUS / "merl__chrome.binary"
GOAL_S = 2.0


def _usage(before, after) -> tuple[float, float, int]:
    """CPU seconds (user + system), system seconds and minor page faults between two
    ``getrusage(RUSAGE_CHILDREN)``."""
    return ((after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), after.ru_stime - before.ru_stime,
            after.ru_minflt - before.ru_minflt)


def command(src: Path, path: Path, out: Path) -> tuple[float, float, float, int]:
    """Wall seconds, CPU seconds, system CPU seconds and minor page faults of ``microfacet fit
    path -o out`` (its processes together) with ``src`` first on ``PYTHONPATH``."""
    env = dict(os.environ, PYTHONPATH=str(src))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "microfacet", "fit", str(path), "-o", str(out)], env=env,
                       capture_output=True, text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if r.returncode != 0:
        raise SystemExit(f"microfacet fit failed ({src}):\n{r.stderr[-2000:]}")
    return (wall, *_usage(before, after))


def one_process(path: str) -> list[tuple[str, float]]:
    """``(stage, thread CPU seconds)`` of every stage of the command, one after the other, here."""
    out, clock = [], [time.thread_time()]

    def mark(name):
        clock.append(time.thread_time())
        out.append((name, clock[-1] - clock[-2]))
    import microfacet.cli  # noqa: F401
    from microfacet.cli.fit import numpy_kernels
    from microfacet.fit import outputs, perceptual
    from microfacet.fit.albedo import albedo_target
    from microfacet.io.read import MEASURED_BRDF, read_decompressed
    from microfacet.measured import load_bytes
    from microfacet.metrics import white_furnace
    mark("imports")
    brdf = load_bytes(read_decompressed(Path(path), MEASURED_BRDF), path)
    mark("read + parse")
    with numpy_kernels():
        t = perceptual.target(brdf)
        mark("perceptual: data's side")
        fitted = {}
        for name in outputs.PERCEPTUAL_MODELS:
            x, _ = perceptual.fit_model(t, perceptual.MODEL_SPECS[name], fitted)
            nq = len(perceptual.MODEL_SPECS[name].q_bounds[0])
            fitted[name] = (x[:nq], x[nq:])
            mark(f"perceptual fit: {name}")
        metrics, judges = outputs._metrics(brdf), outputs._judges(brdf)
        target = albedo_target(brdf, log=judges[0])
        mark("metrics and judges: data's side")
        fit = outputs._run_fit(brdf, 90, False, "smith", False, 4.0)
        mark("tabulated fit")
        least = {}
        for model in ("ggx", "beckmann"):
            key, b = outputs._least_squares_fit(brdf, fit, model, False, "auto", "table", 4.0)
            least[f"{key}_least_squares"] = b
            mark(f"least squares {model}")
        named = {"tabulated": fit, "ggx_moments": fit.to_ggx(reference=brdf),
                 "beckmann_moments": fit.to_beckmann(reference=brdf), **least}
        mark("moment conversions")
        summaries = outputs._fit_summaries(judges, named, outputs._scores(metrics, named), metrics[2].ref)
        {k: white_furnace(b) for k, b in named.items()}
        mark("metrics of the 5 fits above")
        perceptual_fits = {}
        targets = target, outputs._Once(lambda: outputs.colour_target(brdf))
        for name, (q, y) in fitted.items():
            perceptual_fits[name], summaries[name] = outputs._judged(targets, metrics, judges, name, q, y)
            mark(f"albedo match (+ colour balance) + metrics: {name}")
        from microfacet.render import fit_spheres_png
        mark("picture: imports")
        best = outputs.best_fit({k: v["metrics"] for k, v in summaries.items()})
        shown, notes = outputs._shown_fits({**named, **perceptual_fits}, summaries, best)
        fit_spheres_png({"data": brdf, **shown}, title="bench", notes=notes)
        mark("picture")
    return out


def stages(path: Path, runs: int) -> tuple[list[str], tuple]:
    """The stages table's lines and the stage processes' median ``(CPU, system CPU, page faults)``."""
    rows, usage = [], []
    for _ in range(runs):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        r = subprocess.run([sys.executable, __file__, "_one", "--file", str(path)], check=True, capture_output=True,
                           text=True, env=dict(os.environ, PYTHONPATH=str(ROOT / "src")))
        usage.append(_usage(before, resource.getrusage(resource.RUSAGE_CHILDREN)))
        rows.append([line.rsplit("\t", 1) for line in r.stdout.strip().splitlines()])
    names = [name for name, _ in rows[0]]
    cols = [[float(row[k][1]) for row in rows] for k in range(len(names))]
    total = sum(min(c) for c in cols)
    lines = [f"### Stages, one after the other ({runs} fresh processes, load {load()})", "",
             "| stage | thread CPU min s | median s |", "|---|---:|---:|"]
    lines += [f"| {n} | {min(c):.3f} | {statistics.median(c):.3f} |" for n, c in zip(names, cols, strict=True)]
    lines += [f"| **sum** | **{total:.3f}** | |", "",
              f"The sum is the stages' CPU work one after the other in one process; on 2 cores the command "
              f"would take at least half of it, {total / 2:.2f} s, against the goal of {GOAL_S:g} s."]
    return lines, tuple(statistics.median(u) for u in zip(*usage))


def walls(path: Path, runs: int, baseline: Path | None) -> tuple[list[str], tuple]:
    """The end-to-end table's lines and this checkout's median ``(CPU, system CPU, page faults)``."""
    sources = {"this checkout": ROOT / "src", **({f"baseline ({baseline})": baseline} if baseline else {})}
    got = {k: [] for k in sources}
    with tempfile.TemporaryDirectory(prefix="bench-fit-") as tmp:
        for i in range(runs):
            for label, src in sources.items():
                got[label].append(command(src, path, Path(tmp) / f"fit{i}.npz"))
                print(f"  {label:40s} {got[label][-1][0]:6.2f} s wall {got[label][-1][1]:6.2f} s CPU", flush=True)
    lines = [f"### `microfacet fit {path.name} -o OUT` end to end ({runs} fresh processes each, alternated, "
             f"load {load()})", "",
             "| code | wall min s | wall median s | CPU median s | system CPU median s | page faults median |",
             "|---|---:|---:|---:|---:|---:|"]
    for label, v in got.items():
        w, c, sy, fl = zip(*v)
        lines.append(f"| {label} | {min(w):.2f} | {statistics.median(w):.2f} | {statistics.median(c):.2f} | "
                     f"{statistics.median(sy):.2f} | {statistics.median(fl):,.0f} |")
    return lines, tuple(statistics.median(u) for u in zip(*got["this checkout"]))[1:]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("mode", nargs="?", default="all", choices=("all", "_one"))
    p.add_argument("--file", type=Path, default=next((f for f in FILES if f.exists()), FILES[0]))
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--also", type=Path, nargs="*", default=[CAST_FILE] if CAST_FILE.exists() else [],
                   help="other files timed end to end (default: corpus chrome, whose fits show a cast)")
    p.add_argument("--baseline", type=Path, help="src folder of another checkout, timed alternately")
    args = p.parse_args()
    if args.mode == "_one":
        print("\n".join(f"{name}\t{seconds:.4f}" for name, seconds in one_process(str(args.file))))
        return
    if not args.file.exists():
        raise SystemExit(f"{args.file}: no such file (--file, or the corpus cache of tests/conftest.py)")
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                          text=True).stdout.strip()
    lines = ["# `microfacet fit FILE` (issue 24: <= 2 s end to end)", "",
             f"`python benchmarks/bench_fit_command.py --runs {args.runs}"
             f"{' --baseline ' + str(args.baseline) if args.baseline else ''}`, {time.strftime('%Y-%m-%d %H:%M')}, "
             f"commit {head}, {os.cpu_count()} CPUs shared with other work (load averages 1 / 5 / 15 min). "
             f"File: {args.file.name}.", ""]
    wall_lines, (cpu, system, faults) = walls(args.file, args.runs, args.baseline)
    for other in args.also:
        wall_lines += [""] + walls(other, args.runs, args.baseline)[0]
    stage_lines, (cpu1, system1, faults1) = stages(args.file, args.runs)
    lines += wall_lines + [""] + stage_lines + [
        "", f"Whole processes, medians: the command used {cpu:.2f} s of CPU ({system:.2f} s system, "
            f"{faults:,.0f} page faults) in its three processes; the stages one after the other, imports "
            f"included, {cpu1:.2f} s ({system1:.2f} s system, {faults1:,.0f} page faults) in one."]
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    print(f"wrote {RESULTS}")


if __name__ == "__main__":
    main()
