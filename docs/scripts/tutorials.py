"""The executed tutorials: run each script of ``examples/`` and make its docs page.

Each tutorial is a plain script (``examples/NN_name.py``) that a reader can copy: its
docstring's first line is the page title, the rest of the docstring the introduction; it
writes its pictures (PNG) into the current folder and prints a few figures. This module
runs each in its own process (cwd ``build/tutorials/NN_name/``, matplotlib's Agg backend,
a time limit), keeps what it wrote there with a stamp (``stamp.json``: the script's hash,
the command, the exit status, the time, the pictures), and turns the result into a
Markdown page: introduction, the command, the code, its output and its pictures.

A script runs again only when its text or its arguments change (or with ``--force``), so
``make docs`` stays fast when nothing changed. Inputs a script takes from the project's
data folder (``MICROFACET_DATA``, default ``../shared/data`` beside the repository), when
present, are linked into its folder and passed by name (:data:`INPUTS`); without them the
script uses its built-in stand-in.

    python docs/scripts/tutorials.py            # run the stale tutorials, print their times
    python docs/scripts/tutorials.py --force 02_fit_measured

Why not mkdocs-gallery: its last release (0.10.4) dates from September 2024, it executes
the examples inside the MkDocs process (Numba, Mitsuba and matplotlib state shared across
examples, no time limit per script) and would add a dependency to the ``docs`` extra; this
executor is ~150 lines, runs every script in a fresh process and caches by script hash.
"""
from __future__ import annotations

import argparse
import ast
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
CACHE = ROOT / "build" / "tutorials"
DATA = Path(os.environ.get("MICROFACET_DATA", ROOT.parent / "shared" / "data"))
TIMEOUT_S = 600
#: tutorial -> files of the data folder it takes as arguments when they are present
INPUTS = {"02_fit_measured": ("merl/nickel.binary.gz",)}
IMAGE_SUFFIXES = (".png", ".jpg", ".svg")


@dataclass(frozen=True)
class Result:
    """What one tutorial run left: its folder, command, exit status, seconds, output and
    pictures (file names in ``folder``)."""

    name: str
    folder: Path
    command: str
    returncode: int
    seconds: float
    output: str
    images: tuple[str, ...]


def scripts() -> list[Path]:
    """The tutorial scripts, in name order."""
    return sorted(EXAMPLES.glob("[0-9][0-9]_*.py"))


def inputs(script: Path) -> list[Path]:
    """The data files ``script`` takes (:data:`INPUTS`) that are present."""
    return [DATA / p for p in INPUTS.get(script.stem, ()) if (DATA / p).is_file()]


def key(script: Path) -> str:
    """The cache key: hash of the script's text and the names of its inputs."""
    h = hashlib.sha256(script.read_bytes())
    for p in inputs(script):
        h.update(p.name.encode())
    return h.hexdigest()


def run(script: Path, force: bool = False, folder: Path | None = None) -> Result:
    """Run ``script`` (unless its stamp in ``folder``, default ``build/tutorials/<stem>``,
    has the same :func:`key` and ``force`` is false) and return its :class:`Result`.
    Raises ``RuntimeError`` with the script's output when it fails or times out."""
    folder = CACHE / script.stem if folder is None else Path(folder)
    stamp = folder / "stamp.json"
    k = key(script)
    if not force and stamp.is_file():
        s = json.loads(stamp.read_text(encoding="utf-8"))
        if s.get("key") == k and s["returncode"] == 0 and all((folder / i).is_file() for i in s["images"]):
            return Result(script.stem, folder, s["command"], 0, s["seconds"], s["output"], tuple(s["images"]))
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    args = []
    for p in inputs(script):
        (folder / p.name).symlink_to(p)
        args.append(p.name)
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONUNBUFFERED="1")
    command = " ".join(["python", script.name, *args])
    t = time.perf_counter()
    try:
        r = subprocess.run([sys.executable, str(script), *args], cwd=folder, env=env, capture_output=True,
                           text=True, timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired as e:
        raise RuntimeError(f"tutorial {script.name} ran over {TIMEOUT_S} s:\n{e.stdout or ''}{e.stderr or ''}") from None
    seconds = time.perf_counter() - t
    if r.returncode != 0:
        raise RuntimeError(f"tutorial {script.name} failed (exit {r.returncode}):\n{r.stdout}{r.stderr[-4000:]}")
    images = tuple(sorted(p.name for p in folder.iterdir() if p.suffix in IMAGE_SUFFIXES))
    stamp.write_text(json.dumps({"key": k, "command": command, "returncode": 0, "seconds": round(seconds, 2),
                                 "output": r.stdout, "images": images}, indent=1), encoding="utf-8")
    return Result(script.stem, folder, command, 0, seconds, r.stdout, images)


def split_docstring(script: Path) -> tuple[str, str, str]:
    """``(title, introduction, code)`` of a tutorial: its docstring's first line, the rest
    of the docstring, and the source after the docstring."""
    text = script.read_text(encoding="utf-8")
    tree = ast.parse(text)
    doc = ast.get_docstring(tree)
    if not doc:
        raise ValueError(f"{script}: a tutorial starts with a docstring (title line, introduction)")
    title, _, intro = doc.partition("\n")
    end = tree.body[0].end_lineno
    code = "\n".join(text.splitlines()[end:]).strip("\n")
    return title.strip(), intro.strip(), code


def page(script: Path, result: Result, image_prefix: str) -> str:
    """The Markdown page of a tutorial: introduction, command, code, output, pictures."""
    title, intro, code = split_docstring(script)
    lines = [f"# {title}", "", intro, "",
             f"`examples/{script.name}`, run as `{result.command}` in an empty folder "
             f"({result.seconds:.1f} s when the docs were built):", "",
             "```python", code, "```", ""]
    if result.output.strip():
        lines += ["Output:", "", "```text", result.output.rstrip(), "```", ""]
    if result.images:
        for name in result.images:
            lines += [f"![{name}]({image_prefix}{name})", "", f"*{name}*", ""]
    else:
        lines += ["!!! warning \"No picture\"",
                  "    The script wrote no picture where the docs were built (its output above says why).", ""]
    return "\n".join(lines)


def index(entries: list[tuple[str, str, str]]) -> str:
    """The tutorials' index page from ``[(page file, title, first sentence)]``."""
    lines = ["# Tutorials", "",
             "Short scripts, each making one of the demo's pictures from code you can copy. They live in "
             "`examples/` and run when the docs are built (`make tutorials`, which `make docs` runs; a script "
             "runs again only when it changed): every page shows the code, what it printed and the pictures "
             "it wrote.", "", "| tutorial | what it shows |", "|---|---|"]
    for target, title, summary in entries:
        lines.append(f"| [{title}]({target}) | {summary} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Run the tutorials of examples/ (cached by script hash).")
    parser.add_argument("names", nargs="*", help="tutorial stems (default: all)")
    parser.add_argument("--force", action="store_true", help="run even when the cached output is current")
    args = parser.parse_args(argv)
    chosen = [s for s in scripts() if not args.names or s.stem in args.names]
    unknown = set(args.names) - {s.stem for s in chosen}
    if unknown:
        parser.error(f"unknown tutorials: {', '.join(sorted(unknown))}")
    for script in chosen:
        t = time.perf_counter()
        r = run(script, force=args.force)
        fresh = time.perf_counter() - t > 0.5
        print(f"{script.name}: {'ran in' if fresh else 'cached,'} {r.seconds:.1f} s, "
              f"{len(r.images)} picture(s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
