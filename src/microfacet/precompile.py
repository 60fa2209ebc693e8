"""Ahead-of-time compilation of the Smith kernels: ``python -m microfacet.kernels --precompile``
(run by ``make setup``; the same as ``python -m microfacet.precompile --precompile``) compiles the kernels that
the library's BRDFs use into Numba's on-disk cache, or loads those already there
(``docs/performance.md``). Here, not in :mod:`microfacet.kernels`, since it builds BRDFs
(:mod:`microfacet.brdf`, :mod:`microfacet.fresnel`), which import the kernels' module.

Example: ``microfacet.precompile.precompile(dtypes=("float64",))``.
"""
from __future__ import annotations

import functools

import numpy as np

from . import fresnel as fr
from . import kernels
from .brdf import MicrofacetBRDF
from .distributions import GGX, Beckmann

__all__ = ["PRECOMPILE_DTYPES", "PRECOMPILE_DEFAULT", "precompile", "main"]

#: The arithmetic types :func:`precompile` can compile for (``MicrofacetBRDF(dtype=...)``), and
#: those it compiles by default (float32 BRDFs are opt-in: ``--dtypes float64,float32``).
PRECOMPILE_DTYPES = ("float64", "float32")
PRECOMPILE_DEFAULT = ("float64",)


def _precompile_calls(dtype):
    """``[(name, call)]``: calls that compile (or load) the kernels of one arithmetic type ``dtype``: the
    eval and pdf kernels of both distributions for the input layouts that the library's callers make
    (both inputs C-contiguous rows, or either one a single direction broadcast), sample (``u`` rows
    with ``wo`` rows or one ``wo``), in float64 the projected kernel (glints, fits: rows or one ``wo``)
    and the conductor Fresnel term, and the unit-length check."""
    F = np.dtype(dtype)
    rows = np.array([[0.0, 0.6, 0.8], [0.6, 0.0, 0.8], [0.0, 0.0, 1.0], [0.28, 0.96, 0.0]], F)
    one, u = rows[0].copy(), np.full((4, 2), 0.5, F)
    calls = []
    for D in (Beckmann, GGX):
        b = MicrofacetBRDF(D(alpha_x=0.3, alpha_y=0.2), fresnel=fr.Conductor.metal("Cu"), dtype=F)
        name = f"{D.__name__} {F.name}"
        for wi, wo, layout in ((rows, rows, "rows, rows"), (rows, one, "rows, one"), (one, rows, "one, rows")):
            calls.append((f"{name} eval ({layout})", functools.partial(kernels.smith_eval, b, wi, wo, True, F)))
            calls.append((f"{name} pdf ({layout})", functools.partial(kernels.smith_pdf, b, wi, wo, F)))
            if F == np.float64 and layout != "one, rows":
                calls.append((f"{name} projected ({layout})",
                              functools.partial(kernels.smith_projected, b.distribution, True, wi, wo, True)))
        for wo, layout in ((rows, "rows"), (one, "one")):
            calls.append((f"{name} sample (u rows, wo {layout})", functools.partial(kernels.smith_sample, b, u, wo, F)))
    calls.append((f"unit deviation {F.name}", functools.partial(kernels.unit_deviation, rows, False)))
    if F == np.float64:
        def conductor():
            saved, kernels.COMPILE = kernels.COMPILE, "wait"
            try:
                fr.Conductor.metal("Cu")(np.linspace(0.0, 1.0, 5))
            finally:
                kernels.COMPILE = saved
        calls.append(("conductor Fresnel float64", conductor))
    return calls


def precompile(dtypes=PRECOMPILE_DEFAULT, progress=None) -> int:
    """Compiles the kernels that the library's BRDFs use (:func:`_precompile_calls`) into Numba's
    on-disk cache, or loads those already there, so that later processes load them in milliseconds
    instead of compiling them at first use (5-20 s each). One kernel at a time, in this process:
    Numba's cache is not safe for processes that compile versions of one function at once
    (:func:`_compile`). ``progress(name, seconds)`` is called after each. Returns how many kernels
    were compiled or loaded; 0 without Numba. Run by ``make setup`` as ``python -m microfacet.kernels
    --precompile`` (``docs/performance.md``).

    Example: ``microfacet.precompile.precompile(dtypes=("float64",))``."""
    import time
    if not kernels.AVAILABLE:
        return 0
    calls = [c for dtype in dtypes for c in _precompile_calls(dtype)]
    for name, call in calls:
        t = time.perf_counter()
        call()
        if progress is not None:
            progress(name, time.perf_counter() - t)
    return len(calls)


def main(argv=None) -> int:
    """``python -m microfacet.kernels --precompile [--dtypes float64,float32] [-q]``: :func:`precompile`,
    printing each kernel's time."""
    import argparse
    import time
    p = argparse.ArgumentParser(prog="python -m microfacet.kernels",
                                description="Compile the microfacet BRDF kernels into Numba's on-disk cache ahead of "
                                            "time (or check that they load from it).")
    p.add_argument("--precompile", action="store_true", required=True, help="compile the kernels now")
    p.add_argument("--dtypes", default=",".join(PRECOMPILE_DEFAULT), metavar="LIST",
                   help=f"comma-separated arithmetic types among {','.join(PRECOMPILE_DTYPES)} "
                        f"(default {','.join(PRECOMPILE_DEFAULT)})")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the total")
    args = p.parse_args(argv)
    dtypes = [d.strip() for d in args.dtypes.split(",") if d.strip()]
    bad = [d for d in dtypes if d not in PRECOMPILE_DTYPES]
    if bad or not dtypes:
        p.error(f"--dtypes must list some of {', '.join(PRECOMPILE_DTYPES)}, got {args.dtypes!r}")
    if not kernels.AVAILABLE:
        print("microfacet.kernels: Numba is not installed (or MICROFACET_NUMBA=0): nothing to compile")
        return 0
    start = time.perf_counter()
    n = precompile(dtypes, None if args.quiet else lambda name, t: print(f"  {t:6.2f} s  {name}", flush=True))
    print(f"microfacet.kernels: {n} kernels compiled or loaded from Numba's cache in "
          f"{time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
