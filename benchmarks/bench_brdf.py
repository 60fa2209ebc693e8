#!/usr/bin/env python3
"""Throughput of ``MicrofacetBRDF.eval``, ``pdf`` and ``sample`` against Mitsuba 3.

For ``--n`` fixed-seed random direction pairs (uniform in the upper hemisphere) this
times our BRDF (float64, and float32 mode for the non-sheared ones; Smith eval, pdf and
sample by the Numba kernels of :mod:`microfacet.kernels`, on Numba's thread count) for
anisotropic GGX and Beckmann, with and without correlation and mean slope, and isotropic
ones ('iso'), and Mitsuba 3's ``roughconductor`` plugin on the same directions with the
same parameters (rho = 0, zero mean slope: the cases both models share) and the same conductor Fresnel term. Each timing is the best and the
median of ``--repeats`` runs after one warm-up run (time.perf_counter). Op ``io`` is
the memory floor of an eval on each side: read the two directions, write a 3-vector per
pair, no arithmetic (ours: a compiled kernel on the same threads, float64 (n, 3) arrays and
float32 ones; Mitsuba: ``view + light`` on its float32 (3, n) arrays).

Mitsuba runs in ``llvm_ad_rgb`` (vectorized float32 JIT on all cores) when that works,
which needs a system libLLVM >= 16 (e.g. Debian's ``libllvm19``; set
``DRJIT_LIBLLVM_PATH`` if it is not found). The variant is probed in a subprocess, since
an unusable LLVM aborts the process. Otherwise it falls back to ``scalar_rgb``: one
Python call per direction, timed on ``--scalar-n`` directions and extrapolated to
``--n`` (the output says so). The first Mitsuba call, which traces and compiles (or
loads from Dr.Jit's kernel cache) its kernel, is reported separately and is not part of
the figures.

Usage::

    python benchmarks/bench_brdf.py [--n 1000000] [--repeats 5] [--json results.json]
                                    [--scaling 1e4,1e5,1e6,1e7,1e8]

Our outputs are new arrays per call, as the API returns them (and, in the rows marked
``out=``, arrays allocated once and passed as ``out=``). New outputs of 1 MiB and more
come from the library's cache of freed outputs (``microfacet._buffers``, as Dr.Jit caches
its allocations): without it, glibc returns a freed block of more than ~48 MB to the
system and the next call page-faults its outputs in again (GGX sample of 10^6: 12.4 ms
against 4.7 ms with ``out=``). ``MICROFACET_OUTPUT_CACHE_MB=0`` turns the cache off; the
header says which applies. The ``--scaling`` table's memory figures empty the cache before
each traced call, so that they count the outputs.

``--scaling`` adds a table of time per element and peak extra memory per element
(``tracemalloc``: NumPy's allocations made by the call, outputs included, inputs not; and
the rise of the process's peak RSS during the call, Linux) of eval, pdf and sample over
the given batch sizes, with the process's peak RSS. Inputs take 64 bytes per element
(float64 ``wi``, ``wo``, ``u``), built without large temporaries, so ``1e8`` fits in
about 16 GB (6.4 GB of inputs, at most 5.6 GB of outputs: sample's ``wi``, weight, pdf).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from typing import Callable

import numpy as np

import microfacet as mf
from microfacet import _buffers

EVAL_GOAL_S = 0.1  # goal: eval on 1e6 directions in under 0.1 s
ALPHA_X, ALPHA_Y = 0.2, 0.5
ALPHA_ISO = 0.3     # the isotropic configurations ('iso')
RHO, MEAN_SLOPE = 0.3, (0.1, -0.2)
METAL = "Cu"  # conductor Fresnel term used on both sides
#: glibc's settings that keep freed memory in the process (reported in the header).
HEAP_VARIABLES = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_THRESHOLD_")


# ------------------------------------------------------------------------- timing
def _numba_threads() -> int:
    try:
        import numba
        return numba.get_num_threads()
    except ImportError:
        return 0


def time_it(fn: Callable[[], object], repeats: int, warm_up: bool = True) -> dict:
    """Best and median wall time of ``fn()`` over ``repeats`` runs after one warm-up run
    (unless ``warm_up`` is False: ``first_s`` is then None), and the best CPU time of the
    process (all its threads: ``time.process_time``), which a loaded machine inflates less
    than wall time (a thread waiting for a core is not counted), and the minor page faults per
    timed run (``resource.getrusage``: fresh output pages, see the module's docstring)."""
    first = None
    if warm_up:
        t0 = time.perf_counter()
        fn()
        first = time.perf_counter() - t0
    times, cpu = [], []
    faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        times.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    faults = (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults) / repeats
    return {"best_s": min(times), "median_s": statistics.median(times), "first_s": first,
            "times_s": times, "cpu_s": min(cpu), "faults": faults}


# --------------------------------------------------------------------------- inputs
CHUNK = 1 << 20     # elements per step when filling large inputs (keeps temporaries small)


def upper_hemisphere(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` directions uniform in solid angle over the upper hemisphere, ``(n, 3)``:
    ``(r cos phi, r sin phi, z)``, ``r = sqrt(1 - z^2)``, ``z`` and ``phi / 2 pi`` uniform.
    Built in chunks of :data:`CHUNK` into the output: besides it, only the ``n`` draws of
    ``z`` and of ``phi`` are held (16 bytes per direction; the values do not depend on the
    chunking)."""
    z, phi = rng.random(n), rng.random(n)
    w = np.empty((n, 3))
    for s in range(0, n, CHUNK):
        zc, pc = z[s:s + CHUNK], 2.0 * np.pi * phi[s:s + CHUNK]
        r = np.sqrt(1.0 - zc * zc)
        w[s:s + CHUNK, 0] = r * np.cos(pc)
        w[s:s + CHUNK, 1] = r * np.sin(pc)
        w[s:s + CHUNK, 2] = zc
    return w


def make_inputs(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Fixed-seed ``wi``, ``wo`` (:func:`upper_hemisphere`) and uniforms ``u`` ``(n, 2)``,
    float64: 64 bytes per element, 6.4 GB at ``n = 10^8``."""
    rng = np.random.default_rng(seed)
    return {"wi": upper_hemisphere(rng, n), "wo": upper_hemisphere(rng, n), "u": rng.random((n, 2))}


def _rss() -> tuple[int, int] | None:
    """``(current, peak)`` resident set size of this process in bytes (Linux
    ``/proc/self/status``: ``VmRSS``, ``VmHWM``), or ``None`` elsewhere."""
    try:
        with open("/proc/self/status") as f:
            kb = {k: int(v.split()[0]) for k, v in (line.split(":", 1) for line in f) if k in ("VmRSS", "VmHWM")}
        return 1024 * kb["VmRSS"], 1024 * kb["VmHWM"]
    except (OSError, KeyError, ValueError):
        return None


def _reset_peak_rss() -> bool:
    """Reset this process's peak RSS (``VmHWM``) to its current RSS (Linux ``clear_refs``)."""
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def peak_memory(fn: Callable[[], object]) -> dict:
    """One call of ``fn`` (result dropped): the peak of the bytes it allocated through
    ``tracemalloc`` (NumPy's allocations, outputs included, inputs not), the rise of the
    process's peak RSS above its RSS before the call and that peak (``None`` where the
    peak cannot be reset)."""
    mf.kernels.release_outputs()                     # the outputs count as new memory
    rss = _rss() if _reset_peak_rss() else None
    tracemalloc.start()
    try:
        fn()
        traced = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    after = _rss() if rss else None
    return {"traced": traced, "rss": after[1] - rss[0] if after else None, "peak_rss": after[1] if after else None}


# ------------------------------------------------------------------------ our BRDF
F32 = " float32"  # suffix of the configurations in float32 mode


def our_configs() -> dict[str, mf.MicrofacetBRDF]:
    """The benchmarked BRDFs; names ending in :data:`F32` use ``dtype=np.float32`` (and get
    float32 inputs, as a renderer's)."""
    fresnel = mf.fresnel.Conductor.metal(METAL)
    aniso = {"alpha_x": ALPHA_X, "alpha_y": ALPHA_Y}
    sheared = dict(aniso, rho=RHO, mean_slope=MEAN_SLOPE)
    configs = {}
    for kind, D in (("ggx", mf.GGX), ("beckmann", mf.Beckmann)):
        configs |= {kind: mf.MicrofacetBRDF(D(**aniso), fresnel=fresnel),
                    kind + F32: mf.MicrofacetBRDF(D(**aniso), fresnel=fresnel, dtype=np.float32),
                    kind + " iso": mf.MicrofacetBRDF(D(alpha=ALPHA_ISO), fresnel=fresnel),
                    kind + " iso" + F32: mf.MicrofacetBRDF(D(alpha=ALPHA_ISO), fresnel=fresnel, dtype=np.float32),
                    kind + " sheared": mf.MicrofacetBRDF(D(**sheared), fresnel=fresnel)}
    return configs


#: Suffix of the runs that write into outputs allocated once (``out=``), as a renderer reusing
#: its buffers would (Dr.Jit reuses its allocations).
OUT = " out="


def bench_ours(inputs, repeats: int) -> list[dict]:
    """Our rows: each configuration's eval, pdf and sample returning new arrays, and (but the
    sheared ones) writing into outputs allocated once (:data:`OUT`)."""
    f32 = {k: v.astype(np.float32) for k, v in inputs.items()}
    rows = []
    for name, brdf in our_configs().items():
        src = f32 if name.endswith(F32) else inputs
        wi, wo, u = src["wi"], src["wo"], src["u"]
        ops = {"eval": lambda: brdf.eval(wi, wo), "pdf": lambda: brdf.pdf(wi, wo), "sample": lambda: brdf.sample(u, wo)}
        runs = [(name, ops)]
        if "sheared" not in name:
            f, p, s = brdf.eval(wi, wo), brdf.pdf(wi, wo), brdf.sample(u, wo)
            runs.append((name + OUT, {"eval": lambda: brdf.eval(wi, wo, out=f), "pdf": lambda: brdf.pdf(wi, wo, out=p),
                                      "sample": lambda: brdf.sample(u, wo, out=s)}))
        for label, ops in runs:
            for op, fn in ops.items():
                rows.append({"impl": "microfacet", "op": op, "distribution": label, "n": len(wi),
                             "extrapolated": False, **time_it(fn, repeats)})
    return rows


def _add_rows(start, stop, a, b, out):
    """``out = a + b`` over rows ``start:stop`` of ``(n, 3)`` arrays through flat views (as the
    Smith kernels read and write them): the memory traffic of an eval and no arithmetic."""
    x, y, z = a.reshape(-1)[3 * start:3 * stop], b.reshape(-1)[3 * start:3 * stop], out.reshape(-1)[3 * start:3 * stop]
    for j in range(x.shape[0]):           # from 0 on the slices: an offset index keeps LLVM from vectorizing
        z[j] = x[j] + y[j]


def bench_io_floor(inputs, repeats: int) -> list[dict]:
    """The memory floor of ``eval`` (op ``io``): read ``wi`` and ``wo``, write an ``(n, 3)``
    output, by a compiled kernel on the same threads as ours, in float64 and float32."""
    if not mf.kernels.AVAILABLE:
        return []
    import numba
    kernel = numba.njit(nogil=True)(_add_rows)
    rows = []
    for name, dtype in (("", np.float64), (F32, np.float32)):
        wi, wo = inputs["wi"].astype(dtype), inputs["wo"].astype(dtype)
        out = np.empty_like(wi)
        rows.append({"impl": "microfacet", "op": "io", "distribution": "read 2, write 1" + name, "n": len(wi),
                     "extrapolated": False,
                     **time_it(lambda: mf.kernels._launch_ranges(kernel, len(wi), wi, wo, out), repeats)})
    return rows


def scaling(sizes: list[int], repeats: int) -> list[dict]:
    """Best time per element, with new outputs and into outputs passed as ``out=``, peak extra
    bytes per element (:func:`peak_memory`, whose call is also the warm-up) and the process's
    peak RSS so far (the largest peak seen since the peak is reset before each traced call) of
    eval, pdf and sample (GGX and Beckmann, non-sheared) for each batch size; above ``10^6``
    elements best of 3 (the first call of a process into gigabytes of fresh memory took up to 10x
    longer). New outputs larger than the output cache
    (``MICROFACET_OUTPUT_CACHE_MB``) are fresh memory at each call, whose pages the system
    zeroes as the kernels first write them; ``out=`` times the kernels' own work."""
    rows, process_peak = [], None
    configs = our_configs()
    for n in sizes:
        inputs = make_inputs(n, seed=1)
        wi, wo, u = inputs["wi"], inputs["wo"], inputs["u"]
        runs = repeats if n <= 1_000_000 else min(repeats, 3)
        for name in ("ggx", "beckmann"):
            b = configs[name]
            ops = {"eval": lambda out=None: b.eval(wi, wo, out=out), "pdf": lambda out=None: b.pdf(wi, wo, out=out),
                   "sample": lambda out=None: b.sample(u, wo, out=out)}
            for op, fn in ops.items():
                mem = peak_memory(fn)
                best = time_it(fn, runs, warm_up=False)["best_s"]
                out = fn()                           # (its memory faulted in: the out= runs reuse it)
                best_out = time_it(lambda: fn(out), runs, warm_up=False)["best_s"]
                del out
                if mem["peak_rss"] is not None:
                    process_peak = max(process_peak or 0, mem["peak_rss"], _rss()[1])
                rows.append({"op": op, "distribution": name, "n": n, "runs": runs, "ns_per_element": best / n * 1e9,
                             "ns_per_element_out": best_out / n * 1e9,
                             "peak_bytes_per_element": mem["traced"] / n,
                             "peak_rss_bytes_per_element": None if mem["rss"] is None else mem["rss"] / n,
                             "process_peak_rss_bytes": process_peak})
        del inputs, wi, wo, u
    return rows


# ------------------------------------------------------------------------- Mitsuba
LLVM_PROBE = """
import drjit as dr, mitsuba as mi
mi.set_variant('llvm_ad_rgb')
b = mi.load_dict({'type': 'roughconductor', 'distribution': 'ggx', 'alpha_u': 0.2, 'alpha_v': 0.5})
si = dr.zeros(mi.SurfaceInteraction3f, 16)
si.wi = dr.normalize(mi.Vector3f(0.3, 0.1, 0.8))
v = b.eval(mi.BSDFContext(), si, dr.normalize(mi.Vector3f(-0.2, 0.3, 0.7)))
dr.eval(v)
print('.'.join(map(str, dr.detail.llvm_version())) if hasattr(dr.detail, 'llvm_version') else '?')
"""


def pick_variant(requested: str) -> tuple[str | None, str]:
    """The Mitsuba variant to use and a line that says why."""
    try:
        import mitsuba as mi  # noqa: F401
    except ImportError as exc:
        return None, f"mitsuba not importable ({exc}); pip install 'microfacet[mitsuba]'"
    if requested in ("auto", "llvm_ad_rgb"):
        try:
            p = subprocess.run([sys.executable, "-c", LLVM_PROBE], capture_output=True,
                               text=True, timeout=300)
        except subprocess.TimeoutExpired:
            p = None
        if p is not None and p.returncode == 0:
            return "llvm_ad_rgb", f"llvm_ad_rgb works (LLVM {p.stdout.strip() or '?'})"
        lines = [] if p is None else p.stderr.strip().splitlines()
        errors = [ln for ln in lines if "error" in ln.lower()]
        err = "timeout" if p is None else ((errors or lines or ["?"])[0 if errors else -1].strip()[:200])
        why = (f"llvm_ad_rgb unusable ({err}); it needs libLLVM >= 16 "
               "(apt-get install libllvm19, or set DRJIT_LIBLLVM_PATH)")
        if requested == "llvm_ad_rgb":
            return None, why
        return "scalar_rgb", why + "; falling back to scalar_rgb"
    return requested, f"{requested} requested"


#: Mitsuba's configurations: ``(our name, distribution, alpha_u, alpha_v)`` (rho = 0, no mean slope).
MITSUBA_CONFIGS = [(kind + iso, kind, *alphas) for kind in ("ggx", "beckmann")
                   for iso, alphas in (("", (ALPHA_X, ALPHA_Y)), (" iso", (ALPHA_ISO, ALPHA_ISO)))]


def mitsuba_bsdf(mi, kind: str, alpha_u: float, alpha_v: float):
    eta, k = mf.fresnel.Conductor.METALS[METAL]
    return mi.load_dict({
        "type": "roughconductor", "distribution": kind, "alpha_u": alpha_u, "alpha_v": alpha_v,
        "eta": {"type": "rgb", "value": list(eta)}, "k": {"type": "rgb", "value": list(k)}})


def bench_mitsuba_llvm(inputs, repeats: int, threads: int | None) -> list[dict]:
    import drjit as dr
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    if threads:
        dr.set_thread_count(threads)
    n = len(inputs["wi"])
    f32 = lambda a: np.ascontiguousarray(a.T, dtype=np.float32)  # noqa: E731  (3, n) SoA
    # our wo (view) is Mitsuba's si.wi; our wi (light) is the argument of eval/pdf
    view, light = mi.Vector3f(f32(inputs["wo"])), mi.Vector3f(f32(inputs["wi"]))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = view
    s1, s2 = dr.zeros(mi.Float, n), mi.Point2f(f32(inputs["u"]))
    dr.eval(si, light, s1, s2)
    dr.sync_thread()
    ctx = mi.BSDFContext()

    def run(fn):
        def go():
            dr.eval(fn())
            dr.sync_thread()
        return go

    rows = []
    for name, kind, au, av in MITSUBA_CONFIGS:
        bsdf = mitsuba_bsdf(mi, kind, au, av)
        ops = {"eval": lambda b=bsdf: b.eval(ctx, si, light),
               "pdf": lambda b=bsdf: b.pdf(ctx, si, light),
               "sample": lambda b=bsdf: b.sample(ctx, si, s1, s2)}
        for op, fn in ops.items():
            rows.append({"impl": "mitsuba llvm_ad_rgb", "op": op, "distribution": name, "n": n,
                         "extrapolated": False, **time_it(run(fn), repeats)})
    rows.append({"impl": "mitsuba llvm_ad_rgb", "op": "io", "distribution": "read 2, write 1", "n": n,
                 "extrapolated": False, **time_it(run(lambda: view + light), repeats)})
    return rows


def bench_mitsuba_scalar(inputs, repeats: int, n_scalar: int) -> list[dict]:
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    n = len(inputs["wi"])
    m = min(n, n_scalar)
    view = [mi.Vector3f(*map(float, v)) for v in inputs["wo"][:m]]
    light = [mi.Vector3f(*map(float, v)) for v in inputs["wi"][:m]]
    s2 = [mi.Point2f(*map(float, s)) for s in inputs["u"][:m]]
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    rows = []
    for name, kind, au, av in MITSUBA_CONFIGS:
        bsdf = mitsuba_bsdf(mi, kind, au, av)

        def loop(method, args):
            def go():
                for v, a in zip(view, args):
                    si.wi = v
                    method(ctx, si, *a)
            return go

        ops = {"eval": loop(bsdf.eval, [(w,) for w in light]),
               "pdf": loop(bsdf.pdf, [(w,) for w in light]),
               "sample": loop(bsdf.sample, [(0.5, s) for s in s2])}
        for op, fn in ops.items():
            t = time_it(fn, repeats)
            scale = n / m  # per-call cost extrapolated to n directions
            rows.append({"impl": "mitsuba scalar_rgb", "op": op, "distribution": name, "n": n,
                         "extrapolated": m < n, "measured_n": m,
                         **{k: (v * scale if k != "times_s" else [x * scale for x in v])
                            for k, v in t.items()}})
    return rows


# -------------------------------------------------------------------------- report
def print_table(rows: list[dict]) -> None:
    print(f"{'implementation':22s} {'op':7s} {'distribution':26s} {'N':>9s} "
          f"{'best ms':>10s} {'median ms':>10s} {'Mevals/s':>9s} {'faults':>7s}")
    for r in rows:
        note = f"  (extrapolated from N={r['measured_n']})" if r.get("extrapolated") else ""
        print(f"{r['impl']:22s} {r['op']:7s} {r['distribution']:26s} {r['n']:9d} "
              f"{r['best_s'] * 1e3:10.3f} {r['median_s'] * 1e3:10.3f} {r['n'] / r['best_s'] / 1e6:9.2f}"
              f"{r['faults'] if 'faults' in r else float('nan'):7.0f}{note}")


def ratios(rows: list[dict]) -> list[dict]:
    """Our best time / Mitsuba's best time for each (op, distribution) both measured (ours in
    float64 and in float32 mode, new outputs and :data:`OUT`, against the same Mitsuba row)."""
    ours = {(r["op"], r["distribution"]): r for r in rows if r["impl"] == "microfacet"}
    out = []
    for r in rows:
        for name in (r["distribution"] + suffix for suffix in ("", F32, OUT, F32 + OUT)):
            if not (r["impl"].startswith("mitsuba") and (r["op"], name) in ours):
                continue
            o = ours[r["op"], name]
            out.append({"op": r["op"], "distribution": name, "mitsuba": r["impl"],
                        "ours_s": o["best_s"], "mitsuba_s": r["best_s"],
                        "ratio": o["best_s"] / r["best_s"], "cpu_ratio": o["cpu_s"] / r["cpu_s"],
                        "mitsuba_first_call_s": r["first_s"]})
    return out


def write_json(path: str, payload: dict) -> None:
    """Write ``payload`` to ``path`` atomically (temporary file in the same folder + os.replace)."""
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".bench-", suffix=".json", dir=folder)
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(payload, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="directions per call (default 1e6)")
    ap.add_argument("--repeats", type=int, default=5, help="timed runs after a warm-up (default 5)")
    ap.add_argument("--json", metavar="PATH", help="also write the results to this JSON file")
    ap.add_argument("--mitsuba", default="auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb", "none"],
                    help="Mitsuba variant to compare with (default: llvm_ad_rgb if it works)")
    ap.add_argument("--scalar-n", type=int, default=20_000,
                    help="directions actually timed with scalar_rgb, extrapolated to --n")
    ap.add_argument("--mitsuba-threads", type=int, default=None,
                    help="Dr.Jit CPU threads for llvm_ad_rgb (default: all cores; 1 for a per-core ratio)")
    ap.add_argument("--scaling", metavar="N1,N2,...", default=None,
                    help="also time eval/pdf/sample over these batch sizes (e.g. 1e4,1e5,1e6,1e7) and "
                         "report time and peak extra memory per element")
    args = ap.parse_args(argv)
    try:
        sizes = [int(float(v)) for v in args.scaling.split(",")] if args.scaling else []
    except ValueError:
        ap.error(f"--scaling must be comma-separated batch sizes, got {args.scaling!r}")
    if any(n < 1 for n in sizes):
        ap.error("--scaling sizes must be >= 1")
    if args.n < 1 or args.repeats < 1 or args.scalar_n < 1 or (args.mitsuba_threads or 1) < 1:
        ap.error("--n, --repeats, --scalar-n and --mitsuba-threads must be >= 1")

    print(f"microfacet {mf.__version__}, numpy {np.__version__}, Python {platform.python_version()}, "
          f"{platform.machine()}, {os.cpu_count()} CPUs; N = {args.n}, repeats = {args.repeats}")
    print(f"parameters: alpha_x = {ALPHA_X}, alpha_y = {ALPHA_Y}; 'iso': alpha = {ALPHA_ISO}; 'sheared': rho = {RHO}, "
          f"mean slope = {MEAN_SLOPE}; conductor Fresnel ({METAL}) on both sides")
    print("glibc heap: " + (", ".join(f"{k}={os.environ[k]}" for k in HEAP_VARIABLES if k in os.environ)
                            if any(k in os.environ for k in HEAP_VARIABLES) else "default")
          + f"; output cache: {_buffers._cache.limit >> 20} MiB (MICROFACET_OUTPUT_CACHE_MB; freed outputs "
          "kept for reuse, as Dr.Jit keeps its allocations)")
    variant, why = (None, "skipped (--mitsuba none)") if args.mitsuba == "none" else pick_variant(args.mitsuba)
    print(f"mitsuba: {why}")
    if variant is None and args.mitsuba not in ("auto", "none"):
        return 2  # the requested Mitsuba variant does not run here
    inputs = make_inputs(args.n)
    rows = bench_ours(inputs, args.repeats) + bench_io_floor(inputs, args.repeats)
    threads = None
    if variant == "llvm_ad_rgb":
        rows += bench_mitsuba_llvm(inputs, args.repeats, args.mitsuba_threads)
        import drjit as dr
        threads = dr.thread_count()
    elif variant == "scalar_rgb":
        rows += bench_mitsuba_scalar(inputs, args.repeats, args.scalar_n)

    print()
    print_table(rows)
    rat = ratios(rows)
    if rat:
        print(f"\nours / Mitsuba (best times, same N; > 1 means ours is slower). Ours: float64 unless named float32; "
              f"Smith eval, pdf and sample by the fused Numba kernels ({_numba_threads()} threads; "
              f"'{F32.strip()}': dtype=np.float32, float32 inputs, arithmetic and outputs; "
              f"'{OUT.strip()}': outputs allocated once and passed as out=). "
              f"Mitsuba {variant}: float32"
              + (f", {threads} thread{'s' if threads > 1 else ''}" if threads else "") + ".")
        print("  (wall-time ratio, then the ratio of process CPU times, which the machine's load "
              "inflates less; Mitsuba's first call, tracing + kernel compile or cache load, not counted)")
        for r in rat:
            first = f"   (first call {r['mitsuba_first_call_s']:.3f} s)" if variant == "llvm_ad_rgb" else ""
            print(f"  {r['op']:7s} {r['distribution']:26s} {r['ours_s'] * 1e3:9.3f} ms / "
                  f"{r['mitsuba_s'] * 1e3:9.3f} ms = {r['ratio']:7.1f}   CPU {r['cpu_ratio']:7.1f}{first}")
    goal = [(r["distribution"], r["best_s"] * 1e6 / r["n"]) for r in rows
            if r["impl"] == "microfacet" and r["op"] == "eval" and not r["distribution"].endswith(OUT)]
    scaled = "" if args.n == 1_000_000 else f", measured at N = {args.n} and scaled to 1e6"
    print(f"\ngoal: eval of 1e6 directions in < {EVAL_GOAL_S} s (best time{scaled}):")
    for name, t in goal:
        print(f"  {name:26s} {t:7.3f} s  {'met' if t < EVAL_GOAL_S else 'NOT met'}")

    scale_rows = scaling(sizes, args.repeats) if sizes else []
    if scale_rows:
        print("\nscaling (best time per element, new outputs and out=; peak extra memory per element incl. the "
              "outputs: tracemalloc, and the rise of the peak RSS; the process's peak RSS so far):")
        print(f"  {'op':7s} {'distribution':9s} {'N':>10s} {'runs':>4s} {'ns/elem':>9s} {'out= ns':>8s} "
              f"{'bytes/elem':>11s} {'RSS B/elem':>11s} {'peak RSS':>10s}")
        for r in scale_rows:
            rss = "n/a" if r["peak_rss_bytes_per_element"] is None else f"{r['peak_rss_bytes_per_element']:.1f}"
            peak = "n/a" if r["process_peak_rss_bytes"] is None else f"{r['process_peak_rss_bytes'] / 2**30:.2f} GiB"
            print(f"  {r['op']:7s} {r['distribution']:9s} {r['n']:10d} {r['runs']:4d} {r['ns_per_element']:9.1f} "
                  f"{r['ns_per_element_out']:8.1f} {r['peak_bytes_per_element']:11.1f} {rss:>11s} {peak:>10s}")
    load = os.getloadavg() if hasattr(os, "getloadavg") else None
    if load:
        print(f"\nload average at the end: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} CPUs)")

    if args.json:
        write_json(args.json, {
            "n": args.n, "repeats": args.repeats, "mitsuba_variant": variant, "mitsuba_note": why,
            "mitsuba_threads": threads, "numpy": np.__version__, "python": platform.python_version(),
            "machine": platform.machine(), "cpus": os.cpu_count(),
            "parameters": {"alpha_x": ALPHA_X, "alpha_y": ALPHA_Y, "alpha_iso": ALPHA_ISO, "rho": RHO,
                           "mean_slope": MEAN_SLOPE, "fresnel": f"conductor {METAL}"},
            "results": rows, "ratios": rat, "eval_goal_s": EVAL_GOAL_S, "scaling": scale_rows,
            "load_average": load, "numba_threads": _numba_threads()})
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
