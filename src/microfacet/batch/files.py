"""Which files a batch reads and writes.

Inputs: a folder's non-hidden regular files that the task takes (with ``recursive``, those
of its subfolders too, symlinked ones included, except the output folder), or a list of files.
A subfolder that cannot be read, or a symlink back to a folder above it (a loop), is an
:class:`Item` with a ``problem``: the batch reports it in its summary row and runs nothing there. Outputs mirror the
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
    ``file``) and its main output.

    Parameters
    ----------
    source : Path
        The input file.
    rel : str
        ``source``'s path relative to the batch's root (the summary's ``file`` column).
    out : Path
        The task's main output for ``source``.
    problem : str, optional
        Why the file cannot be processed; ``""`` (default) when it can.

    Examples
    --------
    >>> from pathlib import Path
    >>> Item(Path("maps/a.png"), "a.png", Path("out/a.exr"))
    Item(source=PosixPath('maps/a.png'), rel='a.png', out=PosixPath('out/a.exr'), problem='')
    """
    source: Path
    rel: str
    out: Path
    #: Why this entry (a subfolder) is not run, the status of its summary row; "" for a file.
    problem: str = ""


def _visible(path: Path, root: Path) -> bool:
    return not any(part.startswith(".") for part in path.relative_to(root).parts)


def _walk(folder: Path, out_dir: Path, recursive: bool) -> tuple[list[Path], list[tuple[Path, str]]]:
    """``(files, problems)`` under ``folder``: its non-hidden regular files (and, with
    ``recursive``, its subfolders', symlinked ones followed, the output folder skipped), and
    ``(subfolder, status)`` for each subfolder that could not be read or that is a symlink
    to a folder above it (a loop)."""
    files: list[Path] = []
    problems: list[tuple[Path, str]] = []

    def visit(d: Path, ancestors: frozenset) -> None:
        try:
            with os.scandir(d) as it:
                entries = sorted(it, key=lambda e: e.name)
        except OSError as e:
            if d == folder:
                raise MicrofacetError(f"{d}: cannot read the folder ({e.strerror or e})") from None
            problems.append((d, f"error: cannot read the folder ({e.strerror or type(e).__name__})"))
            return
        for e in entries:
            if e.name.startswith("."):
                continue
            p = Path(e.path)
            try:
                is_dir = e.is_dir()
                is_file = not is_dir and e.is_file()
            except OSError:
                continue
            if is_file:
                files.append(p)
            elif is_dir and recursive:
                try:
                    st = p.stat()
                except OSError as err:
                    problems.append((p, f"error: cannot read the folder ({err.strerror or type(err).__name__})"))
                    continue
                if (st.st_dev, st.st_ino) in ancestors:
                    problems.append((p, "not run: symlink loop (a link to a folder above it)"))
                elif p.resolve() != out_dir:                  # outputs of an earlier run are no inputs
                    visit(p, ancestors | {(st.st_dev, st.st_ino)})

    st = folder.stat()
    visit(folder, frozenset({(st.st_dev, st.st_ino)}))
    return files, problems


def _folder_files(task, folder: Path, out_dir: Path, recursive: bool) -> tuple[list[Path], list[tuple[Path, str]]]:
    files, problems = _walk(folder, out_dir.resolve(), recursive)
    return sorted(p for p in files if task.accepts(p)), problems


def plan(task, inputs: str | os.PathLike | Sequence[str | os.PathLike], out_dir: str | os.PathLike,
         recursive: bool = False) -> list[Item]:
    """The batch's files (module docstring) in order, with their outputs under ``out_dir``.

    ``inputs`` is a folder or a list of files (whose root is their common folder). Raises
    :class:`MicrofacetError` when there is no input, an input is missing, or an output
    would overwrite an input.

    Parameters
    ----------
    task : Task
        The batch's task (:func:`microfacet.batch.tasks.get_task`): which files it accepts
        and the name of its outputs.
    inputs : str, path-like or sequence of them
        A folder, or a list of files.
    out_dir : str or path-like
        Folder of the outputs; the inputs' relative paths are kept under it.
    recursive : bool, optional
        Also take the files of the sub-folders of a folder ``inputs`` (default ``False``).

    Returns
    -------
    list of Item
        One per input file, in order.

    Examples
    --------
    >>> import os
    >>> from pathlib import Path
    >>> from microfacet.batch import get_task
    >>> os.makedirs("maps/rocks", exist_ok=True)
    >>> for name in ("a.png", "rocks/b.png", "notes.txt"):
    ...     _ = Path("maps", name).write_bytes(b"")
    >>> [(i.rel, i.out.as_posix()) for i in plan(get_task("bake"), "maps", "out", recursive=True)]
    [('a.png', 'out/a.exr'), ('rocks/b.png', 'out/rocks/b.exr')]
    >>> plan(get_task("bake"), "no-such-folder", "out")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: no-such-folder: not a folder
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise MicrofacetError(f"{out_dir}: exists and is not a folder")
    if isinstance(inputs, (str, os.PathLike)):
        root = Path(inputs)
        if not root.is_dir():
            raise MicrofacetError(f"{root}: not a folder")
        files, problems = _folder_files(task, root, out_dir, recursive)
        if not files and not problems:
            raise MicrofacetError(f"{root}: no {task.name} inputs"
                                  f"{' (' + ', '.join(task.inputs) + ')' if task.inputs else ''}"
                                  f"{'' if recursive else ' (subfolders need --recursive)'}")
    else:
        problems = []
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
    for d, status in problems:
        rel = d.relative_to(root)
        items.append(Item(d, f"{rel.as_posix()}/", out_dir / rel, status))
    sources = {p.resolve() for p in files}
    for item in items:
        for out in (() if item.problem else task.outputs(item.out)):
            if out.resolve() in sources:
                raise MicrofacetError(f"{out}: output would overwrite an input; choose another output folder")
    return items


def up_to_date(task, item: Item) -> bool:
    """Whether every output of ``item`` exists and is not older than its input.

    Parameters
    ----------
    task : Task
        The batch's task, which names the outputs of ``item``.
    item : Item
        One file of the batch.

    Returns
    -------
    bool
        ``True`` when every output exists and none is older than the input.

    Examples
    --------
    >>> from pathlib import Path
    >>> from microfacet.batch import get_task
    >>> _ = Path("a.png").write_bytes(b"")
    >>> task = get_task("bake")
    >>> item = plan(task, ["a.png"], "out")[0]
    >>> up_to_date(task, item)                 # no output yet
    False
    """
    try:
        t_in = item.source.stat().st_mtime_ns
        return all(out.stat().st_mtime_ns >= t_in for out in task.outputs(item.out))
    except OSError:
        return False


def remove_partials(task, items: Iterable[Item], other_hosts: bool = False) -> int:
    """Remove the temporary files (:func:`microfacet.io.atomic.atomic_path`) that a killed
    writer left beside the outputs of ``items`` (:func:`microfacet.io.atomic.remove_stale`:
    those of dead processes; a live writer's are kept; with ``other_hosts``, other machines'
    too); returns how many.

    Parameters
    ----------
    task : Task
        The batch's task, which names each item's outputs.
    items : iterable of Item
        The batch's files (:func:`plan`); those with a ``problem`` are skipped.
    other_hosts : bool, optional
        Also remove the temporary files written by other machines (default ``False``: only
        those of dead processes of this machine).

    Returns
    -------
    int
        The number of temporary files removed.

    Examples
    --------
    >>> from pathlib import Path
    >>> from microfacet.batch import get_task
    >>> _ = Path("a.png").write_bytes(b"")
    >>> task = get_task("bake")
    >>> remove_partials(task, plan(task, ["a.png"], "out"))     # nothing left by a killed writer
    0
    """
    return sum(len(remove_stale(out, other_hosts)) for item in items if not item.problem
               for out in task.outputs(item.out))
