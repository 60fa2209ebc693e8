"""Ahead-of-time compilation of the Numba kernels, one entry point (:func:`main`):
``python -m microfacet.kernels --precompile`` (run by ``make setup``; the same as ``python -m
microfacet.precompile --precompile``) compiles the kernels that the library's BRDFs use into
Numba's on-disk cache, or loads those already there (``docs/performance.md``); ``--groups
brdf,measured,leadr,glints`` adds those of :mod:`microfacet.kernels_extra`, whose own ``python -m
microfacet.kernels_extra --precompile`` is this command line for its groups. Here, not in :mod:`microfacet.kernels`, since it builds BRDFs
(:mod:`microfacet.brdf`, :mod:`microfacet.fresnel`), which import the kernels' module.

Example: ``microfacet.precompile.precompile(dtypes=("float64",))``.

Examples
--------
>>> PRECOMPILE_DTYPES, PRECOMPILE_DEFAULT, GROUPS
(('float64', 'float32'), ('float64',), ('brdf', 'measured', 'leadr', 'glints'))
"""
from __future__ import annotations

import functools

import numpy as np

from . import fresnel as fr
from . import kernels, kernels_extra
from .brdf import MicrofacetBRDF
from .distributions import GGX, Beckmann

__all__ = ["PRECOMPILE_DTYPES", "PRECOMPILE_DEFAULT", "GROUPS", "precompile", "main"]

#: The arithmetic types :func:`precompile` can compile for (``MicrofacetBRDF(dtype=...)``), and
#: those it compiles by default (float32 BRDFs are opt-in: ``--dtypes float64,float32``).
PRECOMPILE_DTYPES = ("float64", "float32")
PRECOMPILE_DEFAULT = ("float64",)
#: The groups of kernels the command line compiles: the BRDF kernels (this module) and those of
#: :data:`microfacet.kernels_extra.GROUPS` (measured-BRDF readers, LEADR, glints).
GROUPS = ("brdf",) + kernels_extra.GROUPS


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
    instead of compiling them at first use (5-20 s each), one kernel at a time in this process
    (:func:`microfacet.kernels.precompile_calls`). ``progress(name, seconds)`` is called after each.
    Returns how many kernels were compiled or loaded; 0 without Numba. Run by ``make setup`` as
    ``python -m microfacet.kernels --precompile`` (``docs/performance.md``).

    Example: ``microfacet.precompile.precompile(dtypes=("float64",))``.

    Parameters
    ----------
    dtypes : sequence of str
        Arithmetic types to compile for (``"float64"``, ``"float32"``).
    progress : callable, optional
        ``progress(name, seconds)``.

    Returns
    -------
    int
        Kernels compiled or loaded.

    Examples
    --------
    >>> precompile(dtypes=())        # no arithmetic type: nothing to compile
    0
    >>> precompile(dtypes=("float64",))   # compiles for minutes when cold  # doctest: +SKIP
    """
    return kernels.precompile_calls([c for dtype in dtypes for c in _precompile_calls(dtype)], progress)


def _calls(groups, dtypes) -> list:
    """``[(name, call)]`` of :data:`GROUPS` ``groups``: the BRDF kernels of ``dtypes`` for ``"brdf"``,
    :func:`microfacet.kernels_extra.group_calls` for the others."""
    calls = [c for dtype in dtypes for c in _precompile_calls(dtype)] if "brdf" in groups else []
    return calls + kernels_extra.group_calls([g for g in groups if g != "brdf"])


def main(argv=None, prog: str = "python -m microfacet.kernels", groups=("brdf",)) -> int:
    """The one precompile command line: ``python -m microfacet.kernels --precompile [--dtypes
    float64,float32] [--groups LIST] [-q]`` (default group ``brdf``) and ``python -m
    microfacet.kernels_extra --precompile [--groups LIST] [-q]`` (``prog``; ``groups``: the groups it
    accepts, all of them by default): compiles the kernels of the groups (:data:`GROUPS`) in this
    process, printing each one's time (:func:`microfacet.kernels.precompile_calls`).

    Parameters
    ----------
    argv : list of str, optional
        Arguments; None: ``sys.argv[1:]``.
    prog : str
        Program name for the usage line.
    groups : sequence of str
        Groups the command accepts.

    Returns
    -------
    int
        Exit status (0).

    Examples
    --------
    >>> main(["--precompile", "--groups", "brdf,measured", "--quiet"])  # compiles for minutes  # doctest: +SKIP
    """
    import argparse
    import time
    allowed = tuple(groups) if prog.endswith("kernels_extra") else GROUPS
    default = tuple(groups)
    p = argparse.ArgumentParser(prog=prog, description="Compile microfacet's Numba kernels into Numba's on-disk "
                                                       "cache ahead of time (or check that they load from it).")
    p.add_argument("--precompile", action="store_true", required=True, help="compile the kernels now")
    p.add_argument("--dtypes", default=",".join(PRECOMPILE_DEFAULT), metavar="LIST",
                   help=f"arithmetic types of the brdf group, among {','.join(PRECOMPILE_DTYPES)} "
                        f"(default {','.join(PRECOMPILE_DEFAULT)})")
    p.add_argument("--groups", default=",".join(default), metavar="LIST",
                   help=f"comma-separated groups among {','.join(allowed)} (default: {','.join(default)})")
    p.add_argument("-q", "--quiet", action="store_true", help="print only the total")
    args = p.parse_args(argv)
    dtypes = [d.strip() for d in args.dtypes.split(",") if d.strip()]
    if not dtypes or any(d not in PRECOMPILE_DTYPES for d in dtypes):
        p.error(f"--dtypes must list some of {', '.join(PRECOMPILE_DTYPES)}, got {args.dtypes!r}")
    chosen = [g.strip() for g in args.groups.split(",") if g.strip()]
    bad = [g for g in chosen if g not in allowed]
    if bad:
        p.error(f"--groups: groups must be among {', '.join(allowed)}, got {', '.join(bad)}")
    if not chosen:
        p.error(f"--groups must list some of {', '.join(allowed)}, got {args.groups!r}")
    name = prog.split()[-1]
    if not kernels.AVAILABLE:
        print(f"{name}: Numba is not installed (or MICROFACET_NUMBA=0): nothing to compile")
        return 0
    start = time.perf_counter()
    n = kernels.precompile_calls(_calls(chosen, dtypes),
                                 None if args.quiet else lambda what, t: print(f"  {t:6.2f} s  {what}", flush=True))
    print(f"{name}: {n} precompile calls ({', '.join(chosen)}): kernels compiled or loaded from Numba's cache in "
          f"{time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
