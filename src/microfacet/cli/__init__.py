"""The ``microfacet`` command line: one module per command.

``microfacet demo -o DIR`` renders the demo report; ``microfacet validate`` checks the
core models numerically; ``microfacet fit INPUT -o OUT`` fits measured BRDFs;
``microfacet bake MAP -o OUT.exr`` prefilters a height or normal map into a LEAN/LEADR
moment pyramid; ``microfacet glints NORMAL_MAP -o OUT.npz`` builds a glint microsurface and
``microfacet glints render OUT.npz -o IMG.png`` renders one; ``microfacet view PYRAMID.exr``
serves the WebGL2 viewer on 127.0.0.1; ``microfacet export FIT.npz --to gltf|mtlx|usd -o OUT``
writes a fit as a glTF, MaterialX or USD material. Outputs follow one naming
rule (:mod:`microfacet.cli.common`). Bad input prints one line on stderr and exits with a
non-zero status, without a traceback; long work shows a progress bar only on a terminal.
"""
from __future__ import annotations

import os

# Before NumPy loads: the commands' parallel work is their own (Numba kernels, threads,
# processes); OpenBLAS's pool only spins on the second core after each small BLAS call
# (a caller's own setting wins).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import warnings  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from .. import __version__  # noqa: E402
from ..errors import MicrofacetError  # noqa: E402
from . import bake, demo, export, fit, glints, validate, view  # noqa: E402
from .common import EXIT_ERROR, EXIT_INTERRUPTED, EXIT_USAGE, PROG, Parser  # noqa: E402

__all__ = ["main", "build_parser"]

COMMANDS = (demo, validate, fit, bake, glints, view, export)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``microfacet`` command (one subcommand per module of
    :mod:`microfacet.cli`; ``glints render`` has its own parser, which :func:`main` picks).

    Returns
    -------
    argparse.ArgumentParser
        The parser; each subcommand's namespace carries its ``run`` function.

    Examples
    --------
    >>> args = build_parser().parse_args(["demo", "-o", "demo-output", "--size", "48"])
    >>> args.command, args.output, args.size
    ('demo', 'demo-output', 48)
    """
    parser = Parser(prog=PROG, description="Multiscale microfacet rendering: BRDFs in slope space, "
                                           "fitting, LEAN/LEADR prefiltering and glints.")
    parser.add_argument("--version", action="version", version=f"{PROG} {__version__}")
    sub = parser.add_subparsers(title="commands", dest="command", metavar="COMMAND", required=True)
    for command in COMMANDS:
        command.add(sub)
    return parser


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    print(f"{PROG}: warning: {message}", file=sys.stderr)


def _one_line(e: Exception) -> str:
    """``path: reason`` for OS errors, the message otherwise, on one line."""
    if isinstance(e, OSError) and e.strerror and e.filename:
        text = f"{e.filename}: {e.strerror}"
    else:
        text = str(e) or type(e).__name__
    return " ".join(text.split())


def _keep_freed_memory() -> None:
    """glibc's ``malloc`` told to serve large blocks from its heap and never to trim it
    (``mallopt``: ``M_MMAP_THRESHOLD`` 1 GiB, ``M_TRIM_THRESHOLD`` 2 GiB), as
    ``MALLOC_MMAP_THRESHOLD_`` and ``MALLOC_TRIM_THRESHOLD_`` would: NumPy's large
    temporaries then reuse memory already mapped rather than fault in fresh pages at each
    allocation, in this process and the ones it forks (``benchmarks/bench_fit_command.py``).
    Freed memory stays with the process until it exits. Nothing elsewhere than Linux, or
    where the C library has no ``mallopt``."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt(-3, 1 << 30)                # M_MMAP_THRESHOLD
    mallopt(-1, (1 << 31) - 1)          # M_TRIM_THRESHOLD


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line with ``argv``; bad input prints one line on stderr, without a
    traceback. Run as the program (``argv`` None: ``sys.argv``), it first sets the
    process's allocator to keep freed memory for reuse (:func:`_keep_freed_memory`).

    Parameters
    ----------
    argv : sequence of str, optional
        The arguments, without the program name; default ``sys.argv[1:]``.

    Returns
    -------
    int
        The exit status: 0 on success, else that of a usage error, a failed command or an
        interruption (:mod:`microfacet.cli.common`).

    Examples
    --------
    >>> main(["--version"])
    microfacet ...
    0
    >>> main(["demo", "-o", "demo-output", "--size", "48"])     # doctest: +SKIP
    0
    """
    if argv is None:
        _keep_freed_memory()
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        if argv[:2] == ["glints", "render"]:        # second form of 'glints'
            args = glints.render_parser().parse_args(argv[1:])
        else:
            args = build_parser().parse_args(argv)
    except SystemExit as e:          # --help, --version, usage errors (already printed)
        return e.code if isinstance(e.code, int) else EXIT_USAGE
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _show_warning
            return args.run(args)
    except (MicrofacetError, ValueError, OSError) as e:
        print(f"{PROG}: error: {_one_line(e)}", file=sys.stderr)
        return EXIT_ERROR
    except ArithmeticError as e:     # overflow in a computation: the inputs are out of range
        print(f"{PROG}: error: numbers out of range ({_one_line(e)}); check the parameters", file=sys.stderr)
        return EXIT_ERROR
    except MemoryError:
        print(f"{PROG}: error: out of memory (try a smaller size or resolution)", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print(f"{PROG}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
