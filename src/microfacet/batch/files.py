"""Which files a batch reads and writes.

Inputs: a folder's non-hidden regular files that the task takes (with ``recursive``, those
of its subfolders too, except the output folder), or a list of files. Outputs mirror the
input tree: ``IN/a/b/h.png`` -> ``OUT/a/b/h.exr`` (the name rule of every command:
:func:`input_name`); when two inputs of a folder would share a name (``h.png``, ``h.exr``)
the later one, in name order, keeps its suffix (``h.exr.exr``). A file is up to date when
each of its outputs exists and is not older than the input.
"""
from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterable, Sequence
from pathlib import Path

from ..errors import MicrofacetError
from ..io.atomic import remove_stale
from ..io.names import input_name

__all__ = ["input_name", "Item", "plan", "up_to_date", "remove_partials"]


@dataclasses.dataclass(frozen=True)
class Item:
    """One input file: its path, its path relative to the batch's root (the summary's
    ``file``) and its main output."""
    source: Path
    rel: str
    out: Path


def _visible(path: Path, root: Path) -> bool:
    return not any(part.startswith(".") for part in path.relative_to(root).parts)


def _folder_files(task, folder: Path, out_dir: Path, recursive: bool) -> list[Path]:
    found = folder.rglob("*") if recursive else folder.iterdir()
    out_dir = out_dir.resolve()
    inside = folder.resolve() in out_dir.parents          # outputs of an earlier run are no inputs
    return sorted(p for p in found if p.is_file() and _visible(p, folder) and task.accepts(p)
                  and not (inside and out_dir in p.resolve().parents))


def plan(task, inputs: str | os.PathLike | Sequence[str | os.PathLike], out_dir: str | os.PathLike,
         recursive: bool = False) -> list[Item]:
    """The batch's files (module docstring) in order, with their outputs under ``out_dir``.

    ``inputs`` is a folder or a list of files (whose root is their common folder). Raises
    :class:`MicrofacetError` when there is no input, an input is missing, or an output
    would overwrite an input.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise MicrofacetError(f"{out_dir}: exists and is not a folder")
    if isinstance(inputs, (str, os.PathLike)):
        root = Path(inputs)
        if not root.is_dir():
            raise MicrofacetError(f"{root}: not a folder")
        files = _folder_files(task, root, out_dir, recursive)
        if not files:
            raise MicrofacetError(f"{root}: no {task.name} inputs"
                                  f"{' (' + ', '.join(task.inputs) + ')' if task.inputs else ''}"
                                  f"{'' if recursive else ' (subfolders need --recursive)'}")
    else:
        files = [Path(p) for p in inputs]
        if not files:
            raise MicrofacetError("no input files")
        for p in files:
            if not p.is_file():
                raise MicrofacetError(f"{p}: not a file")
        root = Path(os.path.commonpath([p.resolve().parent for p in files]))
        files = [p.resolve() for p in files]
    items, used = [], set()
    for p in files:
        rel = p.relative_to(root)
        name = input_name(p)
        if (rel.parent, name) in used:
            name = p.name
        used.add((rel.parent, name))
        items.append(Item(p, rel.as_posix(), out_dir / rel.parent / f"{name}{task.suffixes[0]}"))
    sources = {p.resolve() for p in files}
    for item in items:
        for out in task.outputs(item.out):
            if out.resolve() in sources:
                raise MicrofacetError(f"{out}: output would overwrite an input; choose another output folder")
    return items


def up_to_date(task, item: Item) -> bool:
    """Whether every output of ``item`` exists and is not older than its input."""
    try:
        t_in = item.source.stat().st_mtime_ns
        return all(out.stat().st_mtime_ns >= t_in for out in task.outputs(item.out))
    except OSError:
        return False


def remove_partials(task, items: Iterable[Item], other_hosts: bool = False) -> int:
    """Remove the temporary files (:func:`microfacet.io.atomic.atomic_path`) that a killed
    writer left beside the outputs of ``items`` (:func:`microfacet.io.atomic.remove_stale`:
    those of dead processes; a live writer's are kept; with ``other_hosts``, other machines'
    too); returns how many."""
    return sum(len(remove_stale(out, other_hosts)) for item in items for out in task.outputs(item.out))
