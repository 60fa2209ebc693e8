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

Concurrency and faults: a batch holds its output folder's lock
(:func:`microfacet.io.atomic.folder_lock`) while it runs, so a second batch into the same
folder waits for the first (saying so in a warning) and then skips what the first did;
temporary files are removed only when their writer is dead (another command writing the
same output keeps its own); local worker processes exit when the batch's process dies,
``kill -9`` included (:mod:`microfacet.batch.workers`); a Dask scheduler is reached within
``connect_timeout`` seconds or the batch stops with one line saying what failed, before
any file is touched.

Examples
--------
>>> SCHEDULER_SCHEMES, CONNECT_TIMEOUT
(('tcp', 'tls'), 10.0)
"""
from __future__ import annotations

import csv
import io
import os
import signal
import socket
import sys
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

from threadpoolctl import threadpool_limits

from ..errors import MicrofacetError
from ..io import write_text
from ..io.atomic import folder_lock
from . import memory
from .files import Item, plan, remove_partials, up_to_date
from .tasks import Task, get_task
from .workers import exit_with

__all__ = ["run", "execute", "summary_columns", "format_summary_csv", "format_summary_markdown",
           "connect_scheduler", "SCHEDULER_SCHEMES", "CONNECT_TIMEOUT"]

#: Seconds to reach a Dask scheduler (TCP connection and its first answer) by default.
CONNECT_TIMEOUT = 10.0
#: Dask scheduler address schemes a batch connects to (``host:port`` alone means ``tcp``).
SCHEDULER_SCHEMES = ("tcp", "tls")
#: Port of a Dask scheduler address without one (Dask's default).
DEFAULT_SCHEDULER_PORT = 8786

#: Errors that mean "this file cannot be done", reported in its row.
FILE_ERRORS = (MicrofacetError, ValueError, OSError, ArithmeticError, MemoryError)
#: Between the warnings of one file in its row's ``warnings``.
WARNING_SEPARATOR = " / "


def execute(task: Task, item: Item, other_hosts: bool = False) -> dict:
    """Run ``task`` on one file (in whichever process or machine): remove what an earlier
    killed attempt left (temporaries of dead processes; with ``other_hosts``, those of other
    machines too: a Dask rerun), reset the peak memory, run, and return the row's status
    (``ok`` or ``error: reason``), ``seconds`` (wall clock), ``cpu_seconds`` (this
    process's CPU time: all its threads), ``peak_mb``, ``warnings`` (the task's warning
    messages, e.g. repaired normal-map texels, joined by `` / ``) and figures. A failed
    file leaves none of its outputs.

    Parameters
    ----------
    task : Task
        The task, with its options.
    item : Item
        The file to process (:func:`microfacet.batch.files.plan`).
    other_hosts : bool, optional
        Also remove the temporaries that other machines left (default ``False``).

    Returns
    -------
    dict
        The summary row: ``status``, ``seconds``, ``cpu_seconds``, ``peak_mb``,
        ``warnings`` and the task's figures.

    Examples
    --------
    >>> import numpy as np
    >>> from pathlib import Path
    >>> from microfacet.batch import get_task
    >>> from microfacet.batch.files import plan
    >>> _ = Path("in.png").write_bytes(b"not a PNG")
    >>> task = get_task("bake")
    >>> row = execute(task, plan(task, ["in.png"], "out")[0])
    >>> row["status"], sorted(row)[:4]
    ('error: not a PNG or OpenEXR image', ['cpu_seconds', 'peak_mb', 'seconds', 'status'])
    """
    remove_partials(task, [item], other_hosts)
    item.out.parent.mkdir(parents=True, exist_ok=True)
    memory.reset_peak()
    t0, cpu0 = time.perf_counter(), time.process_time()
    try:
        with threadpool_limits(limits=1, user_api="blas"), \
                warnings.catch_warnings(record=True) as caught:   # the same sums in every mode
            warnings.simplefilter("always")
            figures, status = task(item.source, item.out), "ok"
    except FILE_ERRORS as e:
        text = f"{e.filename}: {e.strerror}" if isinstance(e, OSError) and e.filename and e.strerror else str(e)
        reason = " ".join(text.split()) or type(e).__name__
        figures, status = {}, f"error: {reason.removeprefix(f'{item.source}: ')}"
        for out in task.outputs(item.out):
            out.unlink(missing_ok=True)
    return {"status": status, "seconds": round(time.perf_counter() - t0, 4),
            "cpu_seconds": round(time.process_time() - cpu0, 4),
            "peak_mb": round(memory.peak_bytes() / 2**20, 1),
            "warnings": WARNING_SEPARATOR.join(" ".join(str(w.message).split()) for w in caught), **figures}


def _init_worker(threads: int, parent: int | None = None) -> None:
    """A local worker leaves Ctrl-C to the parent (which stops the batch between files),
    exits when the batch's process ``parent`` ends (:func:`~microfacet.batch.workers.exit_with`)
    and runs compiled kernels on its share of the CPUs."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if parent is not None:
        exit_with(parent)
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
                               initargs=(memory.cpu_count() // jobs, os.getpid()))
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


def _scheduler_error(address: str, what: str) -> MicrofacetError:
    return MicrofacetError(f"Dask scheduler {address}: {what}")


def _probe(address: str, scheme: str, host: str, port: int, timeout: float) -> None:
    """Open a TCP connection to the scheduler and, for ``tcp``, wait for its first bytes (a
    Dask scheduler sends its handshake as soon as it accepts), within ``timeout`` seconds;
    raise :class:`MicrofacetError` saying what failed."""
    deadline = time.monotonic() + timeout
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        raise _scheduler_error(address, "connection refused (nothing listens on that port)") from None
    except socket.gaierror as e:
        raise _scheduler_error(address, f"unknown host {host!r} ({e.strerror})") from None
    except TimeoutError:
        raise _scheduler_error(address, f"no TCP connection within {timeout:g} s") from None
    except OSError as e:
        raise _scheduler_error(address, f"cannot connect ({e.strerror or e})") from None
    with sock:
        if scheme != "tcp":                 # TLS: the client speaks first
            return
        try:
            sock.settimeout(max(deadline - time.monotonic(), 0.01))
            first = sock.recv(1)
        except TimeoutError:
            raise _scheduler_error(address, f"accepted the connection but did not answer within {timeout:g} s "
                                            "(not a Dask scheduler, or a hung one?)") from None
        except OSError as e:
            raise _scheduler_error(address, f"connection failed ({e.strerror or e})") from None
        if not first:
            raise _scheduler_error(address, "closed the connection without answering (not a Dask scheduler?)")


def connect_scheduler(address: str, timeout: float = CONNECT_TIMEOUT):
    """A ``distributed.Client`` of the Dask scheduler at ``address`` (``tcp://host:port``,
    ``tls://host:port`` or ``host:port``; port 8786 if none), reached within ``timeout``
    seconds, else :class:`MicrofacetError` in one line saying what failed: a scheme the batch
    does not use (``inproc://`` exists only in the process that made the cluster: pass its
    client), an unknown host, a refused connection, no TCP connection, a listener that never
    answers, a client that does not start.

    Parameters
    ----------
    address : str
        The scheduler's address: ``tcp://host:port``, ``tls://host:port`` or ``host:port``.
    timeout : float, optional
        Seconds allowed to connect (default 10).

    Returns
    -------
    distributed.Client
        A client connected to the scheduler.

    Examples
    --------
    >>> client = connect_scheduler("tcp://127.0.0.1:8786", timeout=10)  # needs a Dask scheduler  # doctest: +SKIP
    >>> connect_scheduler("inproc://cluster")
    Traceback (most recent call last):
        ...
    microfacet.errors.MicrofacetError: Dask scheduler inproc://cluster: an inproc:// address works only inside the process that made the cluster; pass its distributed.Client instead, or use tcp://HOST:PORT
    """
    try:
        from distributed import Client
        from distributed.comm.addressing import parse_address, parse_host_port
    except ImportError:
        raise MicrofacetError("--scheduler needs Dask: pip install 'microfacet[dask]'") from None
    if not (isinstance(timeout, (int, float)) and 0 < timeout < float("inf")):
        raise ValueError(f"connect_timeout must be a positive number of seconds, got {timeout!r}")
    address = str(address).strip()
    try:
        scheme, location = parse_address(address) if "://" in address else ("tcp", address)
    except ValueError as e:
        raise _scheduler_error(address, str(e)) from None
    if scheme == "inproc":
        raise _scheduler_error(address, "an inproc:// address works only inside the process that made the "
                                        "cluster; pass its distributed.Client instead, or use tcp://HOST:PORT")
    if scheme not in SCHEDULER_SCHEMES:
        raise _scheduler_error(address, f"scheme {scheme!r} is not supported; give "
                                        f"{' or '.join(s + '://HOST:PORT' for s in SCHEDULER_SCHEMES)}")
    try:
        host, port = parse_host_port(location, default_port=DEFAULT_SCHEDULER_PORT)
    except (ValueError, TypeError) as e:
        raise _scheduler_error(address, f"expected {scheme}://HOST:PORT ({e})") from None
    _probe(address, scheme, host, int(port), timeout)
    result: dict = {}

    def start() -> None:                    # in a thread: a client that hangs cannot hang the batch
        try:
            result["client"] = Client(f"{scheme}://{location}", timeout=timeout)
        except BaseException as e:          # noqa: BLE001 (reported below, in one line)
            result["error"] = e

    thread = threading.Thread(target=start, name="microfacet-dask-connect", daemon=True)
    thread.start()
    thread.join(timeout + 5.0)
    if thread.is_alive():
        raise _scheduler_error(address, f"the Dask client did not start within {timeout + 5.0:g} s")
    if "error" in result:
        e = result["error"]
        raise _scheduler_error(address, f"{type(e).__name__}: {' '.join(str(e).split())}") from None
    return result["client"]


def _run_dask(task, items, client, report, progress: bool) -> None:
    """The tasks on a Dask cluster through ``client`` (a ``distributed.Client``).
    Dask reruns the tasks of a worker that dies; a task that fails for another reason
    (e.g. it killed its workers repeatedly) is reported as an error row."""
    from distributed import as_completed
    futures = client.map(execute, [task] * len(items), items, other_hosts=True, pure=False,
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


def summary_columns(task: Task) -> tuple[str, ...]:
    """Columns of a batch summary: ``file``, ``status``, ``seconds``, ``cpu_seconds``,
    ``peak_mb``, the task's figures and ``warnings``.

    Parameters
    ----------
    task : Task
        The batch's task.

    Returns
    -------
    tuple of str
        The column names in order.

    Examples
    --------
    >>> from microfacet.batch import get_task
    >>> summary_columns(get_task("glints"))
    ('file', 'status', 'seconds', 'cpu_seconds', 'peak_mb', 'width', 'height', 'lobes', 'levels', 'alpha_median', 'alpha_max', 'warnings')
    """
    return ("file", "status", "seconds", "cpu_seconds", "peak_mb", *task.columns, "warnings")


def format_summary_csv(task: Task, rows: Sequence[dict]) -> str:
    """The rows as CSV (header :func:`summary_columns`, full precision).

    Parameters
    ----------
    task : Task
        The batch's task, which names the figure columns.
    rows : sequence of dict
        The summary rows (:func:`run`).

    Returns
    -------
    str
        The CSV text, header first.

    Examples
    --------
    >>> from microfacet.batch import get_task
    >>> rows = [{"file": "a.png", "status": "ok", "seconds": 0.5, "lobes": 256}]
    >>> print(format_summary_csv(get_task("glints"), rows))
    file,status,seconds,cpu_seconds,peak_mb,width,height,lobes,levels,alpha_median,alpha_max,warnings
    a.png,ok,0.5,,,,,256,,,,
    """
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=summary_columns(task), lineterminator="\n", extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _cell(value) -> str:
    return f"{value:.4g}" if isinstance(value, float) else str(value).replace("|", "\\|")


def format_summary_markdown(task: Task, rows: Sequence[dict]) -> str:
    """The rows as a Markdown table and a count of each status.

    Parameters
    ----------
    task : Task
        The batch's task, which names the figure columns.
    rows : sequence of dict
        The summary rows (:func:`run`).

    Returns
    -------
    str
        The Markdown table followed by the status counts.

    Examples
    --------
    >>> from microfacet.batch import get_task
    >>> rows = [{"file": "a.png", "status": "ok", "seconds": 0.5, "lobes": 256},
    ...         {"file": "b.png", "status": "error: not a PNG", "seconds": 0.1}]
    >>> print(format_summary_markdown(get_task("glints"), rows))
    | file | status | seconds | cpu_seconds | peak_mb | width | height | lobes | levels | alpha_median | alpha_max | warnings |
    |---|---|---|---|---|---|---|---|---|---|---|---|
    | a.png | ok | 0.5 |  |  |  |  | 256 |  |  |  |  |
    | b.png | error: not a PNG | 0.1 |  |  |  |  |  |  |  |  |  |
    <BLANKLINE>
    1 ok, 1 error of 2 files.
    """
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
        progress: bool | None = None, connect_timeout: float = CONNECT_TIMEOUT, wait: bool = True,
        **options) -> list[dict]:
    """Run ``task`` (``"bake"``, ``"glints"``, ``"fit"`` or a :class:`Task`, with
    ``options``) on ``inputs`` (a folder or a list of files), writing into ``out_dir``
    (module docstring for the guarantees).

    Parameters
    ----------
    task : str or Task
        ``"bake"``, ``"glints"``, ``"fit"`` (:data:`microfacet.batch.tasks.TASKS`) or a
        :class:`Task`.
    inputs : str, path-like or sequence of them
        A folder of input files, or a list of files (their root: their common folder).
    out_dir : str or path-like
        Folder of the outputs and of ``summary.csv``/``summary.md``; created if absent.
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
    connect_timeout : float
        Seconds to reach the ``scheduler`` address (:func:`connect_scheduler`).
    wait : bool
        When another batch writes into ``out_dir``: wait for it (default; a
        ``RuntimeWarning`` says so), else raise :class:`microfacet.io.atomic.FolderBusy`.
    **options
        Keyword arguments of the task's function (e.g. ``scale`` of ``bake``), given to
        every file.

    Returns
    -------
    list of dict
        The summary rows in input order (also written as ``summary.csv`` and ``summary.md``).

    Raises
    ------
    MicrofacetError
        For no inputs, a bad output folder or a scheduler that cannot be reached (then
        nothing is written).
    KeyboardInterrupt
        After writing the summary of what was done.

    Examples
    --------
    >>> import os, numpy as np
    >>> from microfacet.io import write_png_data
    >>> from microfacet.leadr import gaussian_heightfield
    >>> os.makedirs("heights", exist_ok=True)
    >>> for seed in (0, 1):                  # two 16 x 16 height maps
    ...     h = gaussian_heightfield((16, 16), 0.3, seed=seed)
    ...     _ = write_png_data(f"heights/h{seed}.png", np.round((h - h.min()) / np.ptp(h) * 65535).astype(np.uint16))
    >>> rows = run("bake", "heights", "pyramids", jobs=1, progress=False, scale=0.05)
    >>> [(r["file"], r["status"], r["levels"]) for r in rows]
    [('h0.png', 'ok', 5), ('h1.png', 'ok', 5)]
    >>> sorted(os.listdir("pyramids"))
    ['h0.exr', 'h0.png', 'h1.exr', 'h1.png', 'summary.csv', 'summary.md']
    >>> [r["status"] for r in run("bake", "heights", "pyramids", jobs=1, progress=False, scale=0.05)]
    ['skipped', 'skipped']
    """
    task = get_task(task, **options)
    if jobs is not None and scheduler is not None:
        raise ValueError("give either jobs (local processes) or scheduler (a Dask cluster), not both")
    if jobs is not None and jobs < 1:
        raise ValueError(f"jobs must be >= 1, got {jobs}")
    out_dir = Path(out_dir)
    items = plan(task, inputs, out_dir, recursive)
    own = isinstance(scheduler, (str, os.PathLike))
    client = connect_scheduler(os.fspath(scheduler), connect_timeout) if own else scheduler
    try:
        out_dir.mkdir(parents=True, exist_ok=True)

        def waiting(pid: int) -> None:
            warnings.warn(f"{out_dir}: another batch ({f'process {pid}' if pid else 'another process'}) is "
                          "writing into this folder; waiting for it to finish", RuntimeWarning, stacklevel=4)

        with folder_lock(out_dir, wait=wait, on_wait=waiting):
            return _run_locked(task, items, out_dir, jobs, client, force, progress)
    finally:
        if own:
            client.close()


def _run_locked(task: Task, items: list[Item], out_dir: Path, jobs, client, force: bool, progress) -> list[dict]:
    """:func:`run` once it holds the output folder's lock (and a client, for Dask)."""
    previous = _previous_rows(out_dir)
    rows: dict[str, dict] = {}
    todo = []
    for item in items:
        if item.problem:                    # a subfolder not run (files.plan): its row says why
            rows[item.rel] = {"status": item.problem, "seconds": "", "cpu_seconds": "", "peak_mb": ""}
        elif not force and up_to_date(task, item):
            old = previous.get(item.rel, {})
            rows[item.rel] = {**{k: old.get(k, "") for k in (*task.columns, "warnings")}, "status": "skipped",
                              "seconds": "", "cpu_seconds": "", "peak_mb": ""}
        else:
            todo.append(item)
    progress = sys.stderr.isatty() if progress is None else progress
    bar = None
    if progress and client is None:
        from tqdm import tqdm
        bar = tqdm(total=len(todo), unit="file", desc=f"microfacet {task.name}", leave=False)

    def report(item: Item, result: dict) -> None:
        rows[item.rel] = result
        if bar is not None:
            bar.update()

    try:
        if client is not None:
            _run_dask(task, todo, client, report, progress)
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
        remove_partials(task, items, other_hosts=client is not None)
        ordered = [{"file": i.rel, **rows.get(i.rel, {"status": "not run: interrupted"})} for i in items]
        write_text(out_dir / "summary.csv", format_summary_csv(task, ordered))
        write_text(out_dir / "summary.md", format_summary_markdown(task, ordered))
    return ordered
