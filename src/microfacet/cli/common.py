"""What every ``microfacet`` command shares: one-line usage errors, argument types and the
output naming rule.

Output naming rule (every command; docs/cli.md): ``-o OUT`` names the main output file.
``OUT`` ending with the command's suffix (``.npz``, ``.exr``, ``.png``, ``.md``) is used as
it is; ``OUT`` without a suffix gets it appended; an existing folder, or ``OUT`` ending with
a path separator (``-o new/``, created), receives ``<input name><suffix>``. Any other
suffix is an error, and so are an empty ``OUT`` and a name that is only a suffix
(``-o .exr``), and an output (or a side output such as ``OUT.png``) that is the input
itself. Outputs are checked (their folder created, and writable), before the work; stale
temporaries that a killed earlier run left for the same outputs are removed. A folder input
(``bake``, ``glints``, ``fit``) is a batch: ``-o`` is the output folder, whose tree mirrors
the input's (:mod:`microfacet.batch`), under the same rule for empty and suffix-only names.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from ..io.atomic import check_writable, remove_stale
from ..io.names import input_name
from ..errors import MicrofacetError

PROG = "microfacet"
EXIT_ERROR, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130


class Parser(argparse.ArgumentParser):
    """ArgumentParser whose usage errors are one line: ``microfacet: error: ...``."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{PROG}: error: {message} (see '{self.prog} --help')\n")


def int_at_least(lo: int, hi: int | None = None):
    """argparse type: an integer in ``[lo, hi]``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            raise argparse.ArgumentTypeError(f"must lie in [{lo}, {hi}], got {value}" if hi is not None
                                             else f"must be >= {lo}, got {value}")
        return value
    return parse


def finite_float(text: str) -> float:
    """argparse type: a finite float."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def float_in(lo: float, hi: float, open_lo: bool = False):
    """argparse type: a float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    def parse(text: str) -> float:
        value = finite_float(text)
        if value < lo or value > hi or (open_lo and value == lo):
            raise argparse.ArgumentTypeError(f"must lie in {'(' if open_lo else '['}{lo:g}, {hi:g}], got {text}")
        return value
    return parse


def add_normal_map_arguments(parser: argparse.ArgumentParser) -> None:
    """``--encoding`` and ``--z`` of the normal-map decoder (:mod:`microfacet.io.normalmap`),
    the same for every command that reads normal maps."""
    from ..io.normalmap import ENCODINGS, Z_SOURCES
    parser.add_argument("--encoding", choices=ENCODINGS, default="auto",
                        help="normal map encoding: (n + 1) / 2 ('biased', alias 'offset'; 8/16-bit PNGs "
                             "always), n itself ('signed', float EXR) or by content (default auto)")
    parser.add_argument("--z", choices=Z_SOURCES, default="auto",
                        help="n_z from the third channel ('stored'), rebuilt as sqrt(1 - x^2 - y^2) "
                             "('reconstruct'), or auto: rebuilt for 2-channel maps and a constant third "
                             "channel (default)")


#: Names that are only a suffix (``-o .exr``): errors, not hidden files.
SUFFIX_ONLY = (".exr", ".png", ".npz", ".json", ".md", ".csv", ".html")


def _separators() -> tuple[str, ...]:
    return tuple(s for s in (os.sep, os.altsep, "/") if s)


def check_output_name(output: str | os.PathLike) -> str:
    """``output`` (the ``-o`` text) as a string, or :class:`MicrofacetError` when it is empty
    or its last component is only a data suffix (``.exr``, ``out/.npz``)."""
    text = os.fspath(output)
    if not text.strip():
        raise MicrofacetError("-o: empty output name; give a file or folder name")
    name = text.rstrip("".join(_separators())).replace("\\", "/").rsplit("/", 1)[-1]
    if name.lower() in SUFFIX_ONLY:
        raise MicrofacetError(f"-o {text}: a name that is only a suffix; give a name before {name!r} "
                              "(e.g. out" + name + ")")
    return text


def output_folder(output: str | os.PathLike) -> Path:
    """The ``-o`` folder of a batch or the demo: ``output`` checked by
    :func:`check_output_name` (a trailing separator is allowed: it is a folder anyway)."""
    return Path(check_output_name(output))


def output_path(output: str | os.PathLike, suffix: str, source: str | os.PathLike | None = None,
                side: tuple[str, ...] = (), default_name: str = "") -> Path:
    """The main output of a command under the output naming rule (module docstring).

    ``side`` lists the suffixes of the files written beside it (``OUT.png``, ...); none of
    them may be ``source``. The output's folder is created, and stale temporaries of the
    outputs (left by a killed run: :func:`microfacet.io.atomic.remove_stale`) are removed.
    Returns the main output path.

    >>> output_path("maps/", ".exr", "h.png")            # a trailing separator: a folder
    PosixPath('maps/h.exr')
    """
    text = check_output_name(output)
    out = Path(text)
    if text.endswith(_separators()):
        if out.exists() and not out.is_dir():
            raise MicrofacetError(f"{text}: exists and is not a folder")
        out.mkdir(parents=True, exist_ok=True)
    if out.is_dir():
        name = input_name(source) if source is not None else default_name
        if not name:
            raise MicrofacetError(f"{out}: is a folder; give a {suffix} file")
        out = out / f"{name}{suffix}"
    elif out.suffix == "":
        out = out.with_name(out.name + suffix)
    elif out.suffix.lower() != suffix:
        raise MicrofacetError(f"{out}: expected a {suffix} file name (or a folder), got {out.suffix!r}")
    for path in (out, *(out.with_suffix(s) for s in side)):
        if path.is_dir():
            raise MicrofacetError(f"{path}: is a folder")
        if source is not None and path.exists() and Path(source).exists() and path.samefile(source):
            raise MicrofacetError(f"{path}: output would overwrite the input {source}; choose another -o")
    if out.parent.exists() and not out.parent.is_dir():
        raise MicrofacetError(f"{out.parent}: is not a folder")
    out.parent.mkdir(parents=True, exist_ok=True)
    check_writable(out)
    for path in (out, *(out.with_suffix(s) for s in side)):
        remove_stale(path)
    return out


def add_batch_options(parser) -> None:
    """The options of a command's batch mode (a folder input): ``--recursive``, ``--jobs``,
    ``--scheduler``, ``--force``."""
    g = parser.add_argument_group(
        "folders", "a folder input runs every file in it (outputs mirror its tree in the -o folder; "
                   "summary.csv and summary.md list each file; exit 1 if one failed)")
    g.add_argument("--recursive", action="store_true", help="also the files of its subfolders")
    g.add_argument("-j", "--jobs", type=int_at_least(1), metavar="N",
                   help="local worker processes (default: as many as fit in the available memory, "
                        "at most the CPU count)")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="run on a Dask cluster, e.g. tcp://10.0.0.1:8786 (needs microfacet[dask] and "
                        "the files on a shared file system)")
    g.add_argument("--scheduler-timeout", type=float_in(0.0, 3600.0, open_lo=True), default=None, metavar="S",
                   help="seconds to reach the --scheduler before giving up with an error (default 10)")
    g.add_argument("--force", action="store_true",
                   help="redo files whose outputs are newer than their inputs (else skipped, so a "
                        "stopped batch resumes; use it after changing options)")


def run_batch(args, task: str, folder: str) -> int:
    """Run ``task`` on ``folder`` into the ``-o`` folder with the options of ``args`` that the
    task takes; print the summary table and the warnings of the files done (one line each);
    exit status 1 if a file failed."""
    import sys

    from ..batch import format_summary_markdown, get_task, run
    from ..batch.runner import WARNING_SEPARATOR
    task = get_task(task)
    task = task.with_options(**{k: getattr(args, k) for k in task.option_names() if hasattr(args, k)})
    if args.jobs is not None and args.scheduler is not None:
        raise MicrofacetError("--jobs and --scheduler exclude each other")
    timeout = {} if args.scheduler_timeout is None else {"connect_timeout": args.scheduler_timeout}
    rows = run(task, folder, output_folder(args.output), jobs=args.jobs, scheduler=args.scheduler,
               force=args.force, recursive=args.recursive, progress=sys.stderr.isatty(), **timeout)
    print(format_summary_markdown(task, rows), end="")
    for r in rows:
        if r["status"] != "skipped" and r.get("warnings"):
            for message in r["warnings"].split(WARNING_SEPARATOR):
                print(f"{PROG}: warning: {message}", file=sys.stderr)
    failed = [r for r in rows if r["status"] != "ok" and r["status"] != "skipped"]
    if failed:
        print(f"{PROG}: error: {len(failed)} of {len(rows)} files failed (see "
              f"{Path(args.output) / 'summary.md'})", file=sys.stderr)
        return EXIT_ERROR
    return 0
