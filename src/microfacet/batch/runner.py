"""Run a per-file task over many files: in this process, on local worker processes
(``concurrent.futures.ProcessPoolExecutor``) or on a Dask distributed cluster.

Guarantees, whichever runs the tasks: each output is written atomically by the task
(:mod:`microfacet.io.atomic`); files whose outputs are newer than their inputs are skipped
unless ``force``, so an interrupted batch resumes; a file that fails is reported in its
row and does not stop the others; temporary files left by a killed worker are removed;
``summary.csv`` and ``summary.md`` in the output folder list every file with its status
(``ok``, ``skipped``, ``error: reason``), time, peak memory and figures. Dask schedules,
retries the tasks of workers that die and moves the data; the workers must see the input
and output paths (a shared file system).
"""
from __future__ import annotations

import csv
import io
import os
import signal
import sys
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

from threadpoolctl import threadpool_limits

from ..errors import MicrofacetError
from ..io import write_text
from . import memory
from .files import Item, plan, remove_partials, up_to_date
from .tasks import Task, get_task

__all__ = ["run", "execute", "summary_columns", "format_summary_csv", "format_summary_markdown"]

#: Errors that mean "this file cannot be done", reported in its row.
FILE_ERRORS = (MicrofacetError, ValueError, OSError, ArithmeticError, MemoryError)
#: Between the warnings of one file in its row's ``warnings``.
WARNING_SEPARATOR = " / "


def execute(task: Task, item: Item) -> dict:
    """Run ``task`` on one file (in whichever process or machine): remove what an earlier
    killed attempt left, reset the peak memory, run, and return the row's status
    (``ok`` or ``error: reason``), ``seconds`` (wall clock), ``cpu_seconds`` (this
    process's CPU time: all its threads), ``peak_mb``, ``warnings`` (the task's warning
    messages, e.g. repaired normal-map texels, joined by `` / ``) and figures. A failed
    file leaves none of its outputs."""
    remove_partials(task, [item])
    item.out.parent.mkdir(parents=True, exist_ok=True)
    memory.reset_peak()
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        with threadpool_limits(limits=1, user_api="blas"), \
                warnings.catch_warnings(record=True) as caught:   # the same sums in every mode
            warnings.simplefilter("always")
            figures, status = task(item.source, item.out), "ok"
    except FILE_ERRORS as e:
        reason = " ".join(str(e).split()) or type(e).__name__
        figures, status = {}, f"error: {reason.removeprefix(f'{item.source}: ')}"
        for out in task.outputs(item.out):
            out.unlink(missing_ok=True)
    return {"status": status, "seconds": round(time.perf_counter() - t0, 4),
            "cpu_seconds": round(time.process_time() - cpu0, 4),
            "peak_mb": round(memory.peak_bytes() / 2**20, 1),
            "warnings": WARNING_SEPARATOR.join(" ".join(str(w.message).split()) for w in caught), **figures}


def _init_worker(threads: int) -> None:
    """A local worker leaves Ctrl-C to the parent (which stops the batch between files) and
    runs compiled kernels on its share of the CPUs."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    import numba
    numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))


def _run_serial(task, items, report) -> None:
    for item in items:
        report(item, execute(task, item))


def _run_local(task, items, jobs: int, report) -> None:
    """``jobs`` worker processes. On Ctrl-C the files not started are cancelled, the
    running ones finish (their outputs are complete) and are reported, and the
    interrupt propagates."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool
    methods = multiprocessing.get_all_start_methods()
    context = multiprocessing.get_context("forkserver" if "forkserver" in methods else None)
    if "forkserver" in methods:
        context.set_forkserver_preload([__name__])
    pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=_init_worker,
                               initargs=(memory.cpu_count() // jobs,))
    futures = {pool.submit(execute, task, item): item for item in items}
    pending = set(futures)
    try:
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for f in done:
                try:
                    result = f.result()
                except BrokenProcessPool:
                    result = {"status": "error: its worker process died (killed, or out of memory)"}
                report(futures[f], result)
    except KeyboardInterrupt:
        pool.shutdown(wait=True, cancel_futures=True)
        for f in pending:
            if f.done() and not f.cancelled() and f.exception() is None:
                report(futures[f], f.result())
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(task, items, scheduler, report, progress: bool) -> None:
    """The tasks on a Dask cluster: ``scheduler`` is its address or a ``distributed.Client``.
    Dask reruns the tasks of a worker that dies; a task that fails for another reason
    (e.g. it killed its workers repeatedly) is reported as an error row."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise MicrofacetError("--scheduler needs Dask: pip install 'microfacet[dask]'") from None
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        futures = client.map(execute, [task] * len(items), items, pure=False,
                             key=[f"microfacet-{task.name}-{i}-{time.time_ns()}" for i in range(len(items))])
        index = {f.key: item for f, item in zip(futures, items)}
        try:
            if progress:
                from distributed import progress as dask_progress
                dask_progress(futures)
            for f in as_completed(futures):
                try:
                    result = f.result()
                except Exception as e:          # the cluster gave up on this task
                    result = {"status": f"error: {type(e).__name__}: {' '.join(str(e).split())}"}
                report(index[f.key], result)
        except KeyboardInterrupt:
            client.cancel(futures)
            raise
    finally:
        if own:
            client.close()


def summary_columns(task: Task) -> tuple[str, ...]:
    """Columns of a batch summary: ``file``, ``status``, ``seconds``, ``cpu_seconds``,
    ``peak_mb``, the task's figures and ``warnings``."""
    return ("file", "status", "seconds", "cpu_seconds", "peak_mb", *task.columns, "warnings")


def format_summary_csv(task: Task, rows: Sequence[dict]) -> str:
    """The rows as CSV (header :func:`summary_columns`, full precision)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=summary_columns(task), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value).replace("|", "\\|")


def format_summary_markdown(task: Task, rows: Sequence[dict]) -> str:
    """The rows as a Markdown table and a count of each status."""
    columns = summary_columns(task)
    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(_cell(r.get(k, "")) for k in columns) + " |" for r in rows]
    counts = {}
    for r in rows:
        key = "error" if r["status"].startswith("error") else r["status"]
        counts[key] = counts.get(key, 0) + 1
    return "\n".join(lines) + "\n\n" + ", ".join(f"{n} {k}" for k, n in counts.items()) + f" of {len(rows)} files.\n"


def _number(text: str):
    """A CSV cell as it was written: int, float or text."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _previous_rows(out_dir: Path) -> dict[str, dict]:
    """Rows of an earlier ``summary.csv`` by file, to keep the figures of skipped files."""
    try:
        with open(out_dir / "summary.csv", newline="", encoding="utf-8") as f:
            return {r["file"]: {k: _number(v) for k, v in r.items()} for r in csv.DictReader(f)
                    if r.get("status") in ("ok", "skipped")}
    except (OSError, KeyError, csv.Error):
        return {}


def run(task: str | Task, inputs: str | os.PathLike | Sequence[str | os.PathLike], out_dir: str | os.PathLike,
        jobs: int | None = None, scheduler=None, force: bool = False, recursive: bool = False,
        progress: bool | None = None, **options) -> list[dict]:
    """Run ``task`` (``"bake"``, ``"glints"``, ``"fit"`` or a :class:`Task`, with
    ``options``) on ``inputs`` (a folder or a list of files), writing into ``out_dir``
    (module docstring for the guarantees).

    Parameters
    ----------
    jobs : int, optional
        Local worker processes; default: as many as fit in the available memory at the
        task's estimated peak (:func:`microfacet.batch.memory.default_jobs`), at most the
        CPU count. 1 runs in this process.
    scheduler : str or distributed.Client, optional
        A Dask scheduler address (``tcp://host:8786``) or client: run the tasks there.
    force : bool
        Redo files whose outputs are up to date.
    recursive : bool
        Take a folder's subfolders too; outputs mirror the tree.
    progress : bool, optional
        Show a progress bar (default: when stderr is a terminal).

    Returns the summary rows in input order (also written as ``summary.csv`` and
    ``summary.md``). Raises :class:`MicrofacetError` for no inputs or a bad output folder;
    ``KeyboardInterrupt`` after writing the summary of what was done.
    """
    task = get_task(task, **options)
    if jobs is not None and scheduler is not None:
        raise ValueError("give either jobs (local processes) or scheduler (a Dask cluster), not both")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    out_dir = Path(out_dir)
    items = plan(task, inputs, out_dir, recursive)
    out_dir.mkdir(parents=True, exist_ok=True)
    previous = _previous_rows(out_dir)
    rows: dict[str, dict] = {}
    todo = []
    for item in items:
        if not force and up_to_date(task, item):
            old = previous.get(item.rel, {})
            rows[item.rel] = {**{k: old.get(k, "") for k in (*task.columns, "warnings")}, "status": "skipped",
                              "seconds": "", "cpu_seconds": "", "peak_mb": ""}
        else:
            todo.append(item)
    progress = sys.stderr.isatty() if progress is None else progress
    bar = None
    if progress and scheduler is None:
        from tqdm import tqdm
        bar = tqdm(total=len(todo), unit="file", desc=f"microfacet {task.name}", leave=False)

    def report(item: Item, result: dict) -> None:
        rows[item.rel] = result
        if bar is not None:
            bar.update()

    try:
        if scheduler is not None:
            _run_dask(task, todo, scheduler, report, progress)
        else:
            if jobs is None:
                jobs = memory.default_jobs(max((task.peak(i.source) for i in todo), default=0), len(todo))
            if jobs == 1 or len(todo) <= 1:
                _run_serial(task, todo, report)
            else:
                _run_local(task, todo, min(jobs, len(todo)), report)
    finally:
        if bar is not None:
            bar.close()
        remove_partials(task, items)
        ordered = [{"file": i.rel, **rows.get(i.rel, {"status": "not run: interrupted"})} for i in items]
        write_text(out_dir / "summary.csv", format_summary_csv(task, ordered))
        write_text(out_dir / "summary.md", format_summary_markdown(task, ordered))
    return ordered
