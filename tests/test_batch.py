"""Batches (``mf.batch.run``, ``microfacet bake|glints DIR``): a Dask LocalCluster gives the
serial run's bytes, a killed worker loses nothing, an interrupted ``--jobs 2`` run resumes,
a corrupt file is reported in its row; and the memory and file rules underneath.

Inputs are generated: smooth 32^2 height and normal maps (PNG) and analytic GGX
conductors written on the MERL grid (the format of ``../shared/data/merl``).
"""
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import default_sigint
from test_fit_cli import merl_file_bytes

import microfacet as mf
from microfacet.batch import memory
from microfacet.batch.files import plan
from microfacet.batch.tasks import Task, image_pixels
from microfacet.cli import main
from microfacet.io.png import write_png_data

N_MAPS, SIZE = 8, 32
ALPHAS = (0.1, 0.2, 0.4)                                # GGX conductors (Au, Cu, Au) on the MERL grid
CORRUPT = b"\x89PNG\r\n\x1a\n" + b"\0" * 20            # a PNG signature and nothing readable
FIT_OPTIONS = {"resolution": 16, "method": "moments"}   # the least-squares fits: tests/test_fit_cli.py


def height(n: int, k: int) -> np.ndarray:
    """A smooth periodic height field in [0.1, 0.9], different for each ``k``."""
    x = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return 0.5 + 0.4 * np.sin((1 + k % 3) * x[None, :] + k) * np.cos((1 + k % 4) * x[:, None])


def write_height(path: Path, n: int, k: int) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_png_data(path, np.round(height(n, k) * 65535).astype(np.uint16))


def write_normals(path: Path, n: int, k: int) -> Path:
    """The unit normals of ``height(n, k) / 8``, (n + 1) / 2 encoded in 8-bit RGB."""
    gy, gx = np.gradient(height(n, k) * n / 8.0)
    normal = np.stack([-gx, gy, np.ones_like(gx)], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_png_data(path, np.round((normal + 1.0) * 127.5).astype(np.uint8))


def files_of(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` (but the summaries) by relative path, with its bytes."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and not p.name.startswith("summary.")}


def same_outputs(a: Path, b: Path) -> None:
    """``a`` and ``b`` hold the same files with the same bytes; a fit's ``.json`` may differ
    only in its fit times (``seconds*``)."""
    fa, fb = files_of(a), files_of(b)
    assert fa.keys() == fb.keys()
    for name in fa:
        if name.endswith(".json"):
            ja, jb = json.loads(fa[name]), json.loads(fb[name])
            for j in (ja, jb):                      # fit times: "seconds", "seconds_least_squares"
                for key in [k for k in j if k.startswith("seconds")]:
                    j.pop(key)
            assert ja == jb, name
        else:
            assert fa[name] == fb[name], name


def no_partials(folder: Path) -> None:
    assert not [p for p in folder.rglob("*.tmp")]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    root = tmp_path_factory.mktemp("inputs")
    for k in range(N_MAPS):
        write_height(root / "heights" / ("nested" if k % 4 == 0 else "") / f"h{k:02d}.png", SIZE, k)
        write_normals(root / "normals" / f"n{k:02d}.png", SIZE, k)
    (root / "heights" / "corrupt.png").write_bytes(CORRUPT)
    for k, alpha in enumerate(ALPHAS):
        brdf = mf.MicrofacetBRDF(mf.GGX(alpha=alpha), fresnel=mf.fresnel.Conductor.metal(("Au", "Cu")[k % 2]))
        (root / "materials" / f"ggx-{k}.binary").parent.mkdir(exist_ok=True)
        (root / "materials" / f"ggx-{k}.binary").write_bytes(merl_file_bytes(brdf))
    return root


JOBS = {"bake": ("heights", {}), "glints": ("normals", {}), "fit": ("materials", FIT_OPTIONS)}


@pytest.fixture(scope="module")
def serial(inputs, tmp_path_factory):
    """Every task run in this process: the reference outputs and summary rows."""
    out = tmp_path_factory.mktemp("serial")
    rows = {task: mf.batch.run(task, inputs / folder, out / task, jobs=1, recursive=True, **options)
            for task, (folder, options) in JOBS.items()}
    return out, rows


@pytest.fixture(scope="module")
def client():
    distributed = pytest.importorskip("distributed", reason="needs dask[distributed] (microfacet[dask])")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as c:
        yield c


def without_timing(rows):
    return [{k: v for k, v in r.items() if k not in ("seconds", "cpu_seconds", "peak_mb", "fit_seconds")} for r in rows]


def test_serial_batch_mirrors_the_tree_and_reports_every_file(inputs, serial):
    out, rows = serial
    bake = {r["file"]: r for r in rows["bake"]}
    assert len(bake) == N_MAPS + 1 and (out / "bake" / "nested" / "h04.exr").is_file()
    assert bake["corrupt.png"]["status"].startswith("error: ") and "PNG" in bake["corrupt.png"]["status"]
    assert not (out / "bake" / "corrupt.exr").exists()
    assert all(r["status"] == "ok" for r in rows["glints"] + rows["fit"])
    assert all(r["width"] == SIZE and r["levels"] == 6 for r in rows["bake"] if r["status"] == "ok")
    assert all(r["lobes"] == SIZE * SIZE for r in rows["glints"])
    fits = sorted(rows["fit"], key=lambda r: r["file"])
    assert np.allclose([r["ggx_alpha_x"] for r in fits], ALPHAS, rtol=0.1)
    summary = (out / "bake" / "summary.csv").read_text().splitlines()
    assert summary[0].startswith("file,status,seconds,cpu_seconds,peak_mb,width") and len(summary) == N_MAPS + 2
    assert all(float(r["peak_mb"]) > 10 for r in rows["fit"])


# the fits in fresh workers pay SciPy/Matplotlib imports and Numba loads (~10 s): CI only
@pytest.mark.parametrize("task", ["bake", "glints", pytest.param("fit", marks=pytest.mark.slow)])
def test_cluster_outputs_are_the_serial_bytes(task, inputs, serial, client, tmp_path):
    out, rows = serial
    folder, options = JOBS[task]
    got = mf.batch.run(task, inputs / folder, tmp_path / task, scheduler=client, recursive=True, **options)
    assert without_timing(got) == without_timing(rows[task])
    same_outputs(out / task, tmp_path / task)
    no_partials(tmp_path)


def test_killing_a_worker_mid_batch_loses_nothing(inputs, client, tmp_path):
    folder = tmp_path / "maps"
    for k in range(16):
        write_normals(folder / f"m{k:02d}.png", 64, k)
    reference = tmp_path / "reference"
    mf.batch.run("glints", folder, reference, jobs=1)
    result = {}
    batch = threading.Thread(target=lambda: result.update(
        rows=mf.batch.run("glints", folder, tmp_path / "out", scheduler=client)))
    batch.start()
    pids = client.run(os.getpid)
    deadline = time.monotonic() + 30
    killed = None
    while killed is None and time.monotonic() < deadline and batch.is_alive():
        busy = [w for w, tasks in client.processing().items() if tasks and w in pids]
        if busy and len(list((tmp_path / "out").glob("*.npz"))) >= 2:
            killed = pids[busy[0]]
            os.kill(killed, signal.SIGKILL)
        time.sleep(0.01)
    batch.join(120)
    assert killed is not None, "the batch ended before a worker could be killed"
    assert [r["status"] for r in result["rows"]] == ["ok"] * 16
    same_outputs(reference, tmp_path / "out")
    no_partials(tmp_path / "out")
    assert len((tmp_path / "out" / "summary.csv").read_text().splitlines()) == 17


def cli(*args) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(Path(mf.__file__).parents[1]), "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "microfacet", *map(str, args)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_sigint)


def test_an_interrupted_local_batch_resumes(tmp_path):
    folder, out = tmp_path / "maps", tmp_path / "out"
    for k in range(30):
        write_height(folder / f"h{k:02d}.png", 128, k)
    first = cli("bake", folder, "-o", out, "--jobs", "2")
    deadline = time.monotonic() + 60
    while len(list(out.glob("*.exr"))) < 2 and time.monotonic() < deadline and first.poll() is None:
        time.sleep(0.01)
    first.send_signal(signal.SIGINT)
    _, err = first.communicate(timeout=60)
    assert first.returncode == 130, err
    done = {p.name: p.stat().st_mtime_ns for p in out.glob("*.exr")}
    assert 2 <= len(done) < 30, "the batch was not interrupted part way"
    assert {p.with_suffix(".exr").name for p in out.glob("*.png")} == set(done)    # pairs complete
    no_partials(out)
    interrupted = (out / "summary.csv").read_text()
    assert interrupted.count(",ok,") == len(done) and "not run: interrupted" in interrupted

    second = cli("bake", folder, "-o", out, "--jobs", "2")
    second.communicate(timeout=120)
    assert second.returncode == 0
    assert {name: (out / name).stat().st_mtime_ns for name in done} == done      # not redone
    assert len(list(out.glob("*.exr"))) == len(list(out.glob("*.png"))) == 30
    rows = (out / "summary.csv").read_text()
    assert rows.count(",skipped,") == len(done) and rows.count(",ok,") == 30 - len(done)
    no_partials(out)


def test_a_corrupt_file_is_reported_and_the_others_done(inputs, tmp_path, capsys):
    folder = tmp_path / "maps"
    for k in range(3):
        write_normals(folder / f"n{k}.png", 16, k)
    (folder / "broken.png").write_bytes(CORRUPT[:12])
    assert main(["glints", str(folder), "-o", str(tmp_path / "out"), "--jobs", "1"]) == 1
    captured = capsys.readouterr()
    assert "1 of 4 files failed" in captured.err and "| broken.png | error: " in captured.out
    assert sorted(p.name for p in (tmp_path / "out").glob("*.npz")) == ["n0.npz", "n1.npz", "n2.npz"]
    # a rerun skips the three done files and tries the broken one again
    assert main(["glints", str(folder), "-o", str(tmp_path / "out"), "--jobs", "1"]) == 1
    assert capsys.readouterr().out.count("| skipped |") == 3


def test_warnings_go_to_the_row_and_one_line_each_to_stderr(tmp_path, capsys):
    import csv
    maps, out = tmp_path / "maps", tmp_path / "out"
    write_normals(maps / "n.png", 16, 0)              # a normal map baked as heights: HeightMapWarning
    write_height(maps / "h.png", 16, 1)
    assert main(["bake", str(maps), "-o", str(out), "--jobs", "1"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"microfacet: warning: {maps / 'n.png'}: looks like a tangent-space")
    rows = {r["file"]: r for r in csv.DictReader(open(out / "summary.csv", encoding="utf-8"))}
    assert "looks like a tangent-space normal map" in rows["n.png"]["warnings"] and rows["h.png"]["warnings"] == ""
    assert main(["bake", str(maps), "-o", str(out), "--jobs", "1"]) == 0       # skipped: kept, not printed again
    assert capsys.readouterr().err == ""
    rows = {r["file"]: r for r in csv.DictReader(open(out / "summary.csv", encoding="utf-8"))}
    assert rows["n.png"]["status"] == "skipped" and "looks like" in rows["n.png"]["warnings"]


def test_force_redoes_up_to_date_files(tmp_path):
    folder = tmp_path / "maps"
    write_height(folder / "h.png", 16, 0)
    mf.batch.run("bake", folder, tmp_path / "out", jobs=1)
    before = (tmp_path / "out" / "h.exr").stat().st_mtime_ns
    assert mf.batch.run("bake", folder, tmp_path / "out", jobs=1)[0]["status"] == "skipped"
    time.sleep(0.01)
    assert mf.batch.run("bake", folder, tmp_path / "out", jobs=1, force=True)[0]["status"] == "ok"
    assert (tmp_path / "out" / "h.exr").stat().st_mtime_ns > before
    os.utime(folder / "h.png")                      # a newer input is redone
    assert mf.batch.run("bake", folder, tmp_path / "out", jobs=1)[0]["status"] == "ok"


def test_plan_names_outputs_and_refuses_to_overwrite_inputs(tmp_path):
    task = mf.batch.get_task("bake")
    write_height(tmp_path / "h.png", 8, 0)
    write_height(tmp_path / "sub" / "h.png", 8, 1)
    (tmp_path / "h.exr").write_bytes((tmp_path / "h.png").read_bytes())
    (tmp_path / "notes.txt").write_text("not a map")
    items = plan(task, tmp_path, tmp_path / "out", recursive=True)
    assert [(i.rel, i.out.relative_to(tmp_path / "out").as_posix()) for i in items] == [
        ("h.exr", "h.exr"), ("h.png", "h.png.exr"), ("sub/h.png", "sub/h.exr")]
    mf.batch.run(task, tmp_path, tmp_path / "out", jobs=1, recursive=True)
    assert len(plan(task, tmp_path, tmp_path / "out", recursive=True)) == 3     # outputs are not inputs
    with pytest.raises(mf.MicrofacetError, match="overwrite an input"):
        plan(task, tmp_path / "sub", tmp_path / "sub")      # the preview sub/h.png
    (tmp_path / "texts").mkdir()
    (tmp_path / "texts" / "notes.txt").write_text("not a map")
    with pytest.raises(mf.MicrofacetError, match="no bake inputs"):
        plan(task, tmp_path / "texts", tmp_path / "x")
    with pytest.raises(ValueError, match="unknown option"):
        mf.batch.run("bake", tmp_path, tmp_path / "o", spacing=2)


def allocate(source, out, megabytes: int = 0) -> dict:
    """A task that touches ``megabytes`` of memory and writes nothing."""
    np.ones(megabytes * 2**17).sum()
    return {}


def test_peak_memory_is_each_tasks_own(tmp_path):
    write_height(tmp_path / "h.png", 8, 0)
    big = Task("allocate", allocate, (".none",), (".png",), (), lambda p: 0.0).with_options(megabytes=300)
    rows = [mf.batch.run(t, tmp_path, tmp_path / "out", jobs=1, force=True)[0]
            for t in (big, big.with_options(megabytes=0))]
    if not memory.reset_peak():
        pytest.skip("this system cannot reset the peak resident memory (/proc/self/clear_refs)")
    assert rows[0]["peak_mb"] - rows[1]["peak_mb"] > 250


def test_default_jobs_fit_the_memory_and_the_cpus(tmp_path):
    assert memory.default_jobs(1.6e9, 100, available=7e9, cpus=32) == 4
    assert memory.default_jobs(1.6e9, 100, available=64e9, cpus=8) == 8
    assert memory.default_jobs(1.6e9, 3, available=64e9, cpus=8) == 3
    assert memory.default_jobs(1.6e9, 100, available=1e9, cpus=8) == 1
    write_height(tmp_path / "h.png", 48, 0)
    assert image_pixels(tmp_path / "h.png") == 48 * 48
    peak = mf.batch.get_task("bake").peak
    assert peak(tmp_path / "h.png") < peak(write_height(tmp_path / "big.png", 96, 0))
