"""Issue 25, items 4-10: first-run faults and faults under concurrency, kill -9, a full
disk and unreachable Dask schedulers.

* 4: ``bake`` of a height map at an implausible ``--scale`` warns in one line with the
  scale to use, which gives a plausible roughness.
* 5: ``-o dir/`` is a folder; ``-o ''`` and ``-o .exr`` are one-line errors, every command.
* 6: the demo page fits a 1,400 px window (headless Chromium), lobe-plot tick labels do
  not overlap, ``make setup`` says what it installs with apt and why, and the Mitsuba
  example of docs/mitsuba.md runs as written.
* 7: two batches into one output folder both succeed (the second waits), and temporaries
  of live writers are never removed.
* 8: ``kill -9`` of a ``--jobs 2`` batch leaves no process holding the caller's pipes;
  ``kill -9`` of a single-file bake leaves a temporary that the rerun removes.
* 9: a full disk (a 1 MiB tmpfs, where root may mount one) is one line naming the file;
  a failed demo leaves nothing.
* 10: Dask scheduler addresses: a silent listener on 127.0.0.1, a refused port and bad
  schemes fail in one line within the timeout, before any output.

Inputs are generated (small smooth height and normal maps, an analytic GGX conductor on the
MERL grid); processes run the CLI as users do (``python -m microfacet``).
"""
from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from test_batch import height, write_height, write_normals
from test_fit_cli import merl_file_bytes

import microfacet as mf
from microfacet.cli import main
from microfacet.io import write_exr
from microfacet.io.atomic import (LOCK_NAME, STAGING_NAME, FolderBusy, atomic_path, folder_lock, remove_stale,
                                  staging_folder, temporary_owner)

ROOT = Path(__file__).resolve().parents[1]


def cli(*args, **kwargs) -> subprocess.Popen:
    """``python -m microfacet ARGS`` in a child process, pipes for stdout and stderr."""
    env = {**os.environ, "PYTHONPATH": str(Path(mf.__file__).parents[1]), "NUMBA_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, "-m", "microfacet", *map(str, args)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def one_error_line(err: str, *words) -> None:
    assert err.count("\n") == 1 and err.startswith("microfacet: error: "), err
    assert "Traceback" not in err
    for w in words:
        assert w in err, err


# ------------------------------------------------------------ 4: implausible bake scale
def test_bake_warns_of_an_implausible_height_scale_with_the_scale_to_use(tmp_path, capsys):
    source = write_exr(tmp_path / "h.exr", height(64, 2) * 255.0)          # heights in "pixels"
    assert main(["bake", str(source), "-o", str(tmp_path / "a.exr")]) == 0
    captured = capsys.readouterr()
    alpha = float(re.search(r"alpha_x ([0-9.e+-]+)", captured.out).group(1))
    assert alpha > 4                                                        # the fault: implausible
    warning = captured.err.splitlines()
    assert len(warning) == 1 and warning[0].startswith(f"microfacet: warning: {source}: at --scale 1 "), warning
    suggested = re.search(r"--scale ([0-9.e+-]+) gives alpha", warning[0]).group(1)
    assert main(["bake", str(source), "-o", str(tmp_path / "b.exr"), "--scale", suggested]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert 0.1 <= float(re.search(r"alpha_x ([0-9.e+-]+)", captured.out).group(1)) <= 0.4


def test_a_plausible_height_map_bakes_without_warning(tmp_path, capsys):
    source = write_height(tmp_path / "h.png", 32, 1)
    assert main(["bake", str(source), "-o", str(tmp_path / "a.exr")]) == 0
    assert capsys.readouterr().err == ""


# ------------------------------------------------------------ 5: output naming
@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    d = tmp_path_factory.mktemp("inputs25")
    files = {"height": write_height(d / "h.png", 16, 1), "normals": write_normals(d / "n.png", 16, 2)}
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=mf.fresnel.Conductor.metal("Au"))
    (d / "m.binary").write_bytes(merl_file_bytes(brdf))
    files["material"] = d / "m.binary"
    assert main(["glints", str(files["normals"]), "-o", str(d / "ms.npz")]) == 0
    files["microsurface"] = d / "ms.npz"
    write_height(d / "maps" / "a.png", 16, 3)
    files["maps"] = d / "maps"
    return files


FIT = ["--resolution", "16", "--method", "moments", "--no-picture"]
#: command line before -o, its suffix, the input name its outputs take
COMMANDS = {"bake": (["bake", "{height}"], ".exr", "h"),
            "glints": (["glints", "{normals}"], ".npz", "n"),
            "glints render": (["glints", "render", "{microsurface}", "--size", "8"], ".png", "ms"),
            "fit": (["fit", "{material}", *FIT], ".npz", "m")}


def command(name: str, inputs) -> tuple[list[str], str, str]:
    args, suffix, stem = COMMANDS[name]
    return [a.format(**{k: str(v) for k, v in inputs.items()}) for a in args], suffix, stem


@pytest.mark.parametrize("name", list(COMMANDS))
def test_a_trailing_separator_names_a_new_folder(name, inputs, tmp_path, capsys):
    args, suffix, stem = command(name, inputs)
    assert main([*args, "-o", str(tmp_path / "new") + os.sep]) == 0, capsys.readouterr().err
    assert (tmp_path / "new" / f"{stem}{suffix}").is_file()
    assert not (tmp_path / f"new{suffix}").exists()


NAMING_ERRORS = [("", "empty output name"), (".exr", "only a suffix"), (".npz", "only a suffix"),
                 ("sub/.png", "only a suffix")]


@pytest.mark.parametrize("name", [*COMMANDS, "validate", "bake folder"])
@pytest.mark.parametrize("output, words", NAMING_ERRORS)
def test_empty_and_suffix_only_outputs_are_one_line_errors(name, output, words, inputs, tmp_path, capsys,
                                                           monkeypatch):
    monkeypatch.chdir(tmp_path)
    if name == "validate":
        args = ["validate", "--quick"]
    elif name == "bake folder":
        args = ["bake", str(inputs["maps"])]
    else:
        args = command(name, inputs)[0]
    assert main([*args, "-o", output]) == 1
    one_error_line(capsys.readouterr().err, words)
    assert list(tmp_path.iterdir()) == []                   # nothing written, here or hidden


def test_demo_into_an_empty_output_name_is_a_one_line_error(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)                             # the demo's -o is a folder: any other name is one
    assert main(["demo", "-o", "", "--size", "8", "--spp", "1", "--no-viewer", "--no-mitsuba"]) == 1
    one_error_line(capsys.readouterr().err, "empty name")
    assert list(tmp_path.iterdir()) == []


# ------------------------------------------------------------ 6: demo page, ticks, setup, docs
def test_demo_page_fits_a_1400_px_window(tmp_path):
    pytest.importorskip("playwright", reason="needs Playwright (make setup / the view extra)")
    from playwright.sync_api import sync_playwright

    from microfacet.glsl.browser import chromium_path
    from microfacet.io import html_figure, html_grid, html_page, write_png
    try:
        exe = chromium_path()
    except mf.errors.MicrofacetError as e:
        pytest.skip(str(e))
    for k in range(3):                                      # the viewer section: 3 x 640 px renders
        write_png(tmp_path / f"wide{k}.png", np.full((360, 640, 3), 0.2 * k))
    body = (html_grid([("a row label", [(f"wide{k}.png", f"render {k}") for k in range(3)])])
            + html_figure("wide0.png", "a figure", css_class="lobes"))
    (tmp_path / "index.html").write_text(html_page("page", body), encoding="utf-8")
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=exe, headless=True)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 900})
            page.goto((tmp_path / "index.html").as_uri())
            page.wait_for_load_state("load")
            width = page.evaluate("document.documentElement.scrollWidth")
            shown = page.evaluate("Array.from(document.images).map(i => [i.complete, i.naturalWidth, "
                                  "i.getBoundingClientRect().width])")
        finally:
            browser.close()
    assert width <= 1400
    assert all(done and natural == 640 and 100 < shown_w <= 640 for done, natural, shown_w in shown), shown


def test_lobe_plot_tick_labels_do_not_overlap():
    from microfacet.render.lobes import lobe_figure
    brdfs = [mf.MicrofacetBRDF(cls(alpha=a), fresnel=mf.fresnel.Conductor.metal("Ag"))
             for cls in (mf.Beckmann, mf.GGX) for a in (0.05, 0.1, 0.2, 0.4, 0.8)]
    fig = lobe_figure(brdfs, [str(i) for i in range(len(brdfs))], (0, 30, 60), ncols=5)
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    for ax in fig.axes:
        labels = [t for t in (*ax.get_xticklabels(), *ax.get_yticklabels()) if t.get_visible() and t.get_text()]
        boxes = [t.get_window_extent(renderer) for t in labels]
        assert any(t in ax.get_yticklabels() for t in labels), "no radial scale label"
        for i in range(len(boxes)):
            for j in range(i):
                assert not boxes[i].overlaps(boxes[j]), (labels[i].get_text(), labels[j].get_text())


def test_make_setup_says_what_it_installs_with_apt_and_why():
    recipe = (ROOT / "Makefile").read_text()
    installs = re.findall(r"apt-get install -y -qq ([^>;]+)", recipe)
    assert len(installs) == 3                                 # libLLVM, Chromium/Mesa, Blender's X11 libraries
    for packages in installs:
        before = recipe[:recipe.index(f"apt-get install -y -qq {packages}")]
        said = before[before.rindex("elif"):]                 # the same branch, before the install
        echo = re.search(r'echo "setup(?:-blender)?: installing ([^"]+)"', said)
        assert echo, said
        assert all(p in echo.group(1) for p in packages.split()), (packages, echo.group(1))
        assert ":" in echo.group(1).split("(as root)")[-1]   # ...: why


def test_mitsuba_doc_snippet_runs(tmp_path):
    pytest.importorskip("mitsuba", reason="the Mitsuba example needs the optional `mitsuba` package")
    from test_mitsuba_plugins import _LLVM_PROBE
    probe = subprocess.run([sys.executable, "-c", _LLVM_PROBE], capture_output=True, text=True, timeout=120)
    if probe.returncode != 0:
        if os.environ.get("CI") == "true":
            pytest.fail("llvm_ad_rgb unavailable [CI=true: llvm tests must run]")
        pytest.skip("llvm_ad_rgb unavailable: Dr.Jit needs libLLVM >= 16 (make setup installs libllvm19)")
    blocks = re.findall(r"```python\n(.*?)```", (ROOT / "docs" / "mitsuba.md").read_text(encoding="utf-8"), re.S)
    assert len(blocks) == 1
    (tmp_path / "example.py").write_text(blocks[0], encoding="utf-8")
    # its own HOME, so its own Dr.Jit kernel cache (~/.drjit, which follows HOME): once, under
    # CI, loading the envmap failed with "basic_string::_M_create" while other workers' Mitsuba
    # tests were writing kernels to the shared cache; a cold cache costs this script ~1 s
    (tmp_path / "home").mkdir()
    env = {**os.environ, "PYTHONPATH": str(Path(mf.__file__).parents[1]), "HOME": str(tmp_path / "home")}
    done = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    for name in ("microfacet", "fitted", "leadr"):
        image = mf.io.read_exr(tmp_path / f"{name}.exr")
        assert np.all(np.isfinite(image)) and image[..., :3].mean() > 0.01, name


# ------------------------------------------------------------ 7: concurrent batches
def test_two_batches_into_one_folder_both_succeed(tmp_path):
    """Both start at once on 512^2 maps, so that (before the lock) each removed the other's
    temporaries and, failing, its finished outputs; now one waits, then skips what the
    other did."""
    maps, out = tmp_path / "maps", tmp_path / "out"
    n = 8
    for k in range(n):
        write_height(maps / f"h{k}.png", 512, k)
    first = cli("bake", maps, "-o", out, "--jobs", "1", "--scale", "0.05")
    second = cli("bake", maps, "-o", out, "--jobs", "1", "--scale", "0.05")
    results = [r.communicate(timeout=120) for r in (first, second)]
    assert [first.returncode, second.returncode] == [0, 0], results
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"h{k}{s}" for k in range(n) for s in (".exr", ".png")] + ["summary.csv", "summary.md"])
    summary = (out / "summary.csv").read_text()
    assert summary.count(",ok,") + summary.count(",skipped,") == n
    for k in range(n):
        assert len(mf.leadr.read_pyramid(out / f"h{k}.exr")) == 10


def test_a_second_batch_waits_for_the_folder_lock_or_refuses(tmp_path):
    write_height(tmp_path / "maps" / "h.png", 16, 0)
    out = tmp_path / "out"
    out.mkdir()
    with folder_lock(out):
        assert (out / LOCK_NAME).read_text().split() == [str(os.getpid())]
        with pytest.raises(FolderBusy, match=f"process {os.getpid()}"):
            mf.batch.run("bake", tmp_path / "maps", out, jobs=1, wait=False)
        done = []
        thread = threading.Thread(target=lambda: done.append(mf.batch.run("bake", tmp_path / "maps", out, jobs=1)))
        with pytest.warns(RuntimeWarning, match="waiting for it to finish") as record:
            thread.start()
            deadline = time.monotonic() + 60
            while not record and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(0.5)
        assert not done and not (out / "h.exr").exists()      # waiting
    thread.join(60)
    assert done and done[0][0]["status"] == "ok"
    assert not (out / LOCK_NAME).exists()


def test_temporaries_of_live_writers_are_kept_and_stale_ones_removed(tmp_path):
    out = tmp_path / "h.exr"
    with atomic_path(out) as live:                           # this process: alive
        live.write_bytes(b"x")
        dead = subprocess.Popen([sys.executable, "-c", "pass"])
        dead.wait()
        host = temporary_owner(live, out)[1]
        stale = tmp_path / f".h.exr.{dead.pid}@{host}.abcd1234.tmp"
        legacy = tmp_path / ".h.exr.abcd1234.tmp"                # written before owners were recorded
        other_output = tmp_path / ".h.exr.x.exr.abcd1234.tmp"    # a temporary of h.exr.x.exr
        elsewhere = tmp_path / ".h.exr.1@another-host.abcd1234.tmp"
        for p in (stale, legacy, other_output, elsewhere):
            p.write_bytes(b"x")
        assert sorted(remove_stale(out)) == sorted([stale, legacy])
        assert live.exists() and other_output.exists() and elsewhere.exists()
        assert remove_stale(out, other_hosts=True) == [elsewhere]
    assert out.read_bytes() == b"x" and live.exists() is False


def test_a_staging_folder_is_all_or_nothing_and_stale_ones_are_removed(tmp_path):
    (tmp_path / "index.html").write_text("old")
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    with atomic_path(tmp_path / "probe") as probe:
        host = temporary_owner(probe, tmp_path / "probe")[1]
    (tmp_path / "probe").unlink()
    left = tmp_path / f".{STAGING_NAME}.{dead.pid}@{host}.abcd1234.tmp"      # a kill -9'd demo's
    (left / "fig").mkdir(parents=True)
    (left / "fig" / "a.png").write_bytes(b"x")
    with pytest.raises(OSError, match="disk full"), staging_folder(tmp_path, last="index.html") as stage:
        (stage / "fig").mkdir()
        (stage / "fig" / "b.png").write_bytes(b"b")
        raise OSError(28, "disk full")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["index.html"]       # as it was, stale one gone
    with staging_folder(tmp_path, last="index.html") as stage:
        (stage / "fig").mkdir()
        (stage / "fig" / "b.png").write_bytes(b"b")
        (stage / "index.html").write_text("new")
    assert (tmp_path / "index.html").read_text() == "new" and (tmp_path / "fig" / "b.png").read_bytes() == b"b"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fig", "index.html"]


# ------------------------------------------------------------ 8: kill -9
def session_processes(sid: int) -> list[str]:
    """Live (not zombie) processes of session ``sid``: ``pid state cmdline``."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmd = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()[:100]
        except (OSError, IndexError):
            continue
        if int(fields[3]) == sid and fields[0] != "Z":
            found.append(f"{stat.parent.name} {fields[0]} {cmd}")
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs Linux /proc to find the processes")
def test_kill_9_of_a_jobs_2_batch_leaves_no_process(tmp_path):
    maps = tmp_path / "maps"
    for k in range(24):
        write_height(maps / f"h{k:02d}.png", 256, k)
    run = cli("bake", maps, "-o", tmp_path / "out", "--jobs", "2", start_new_session=True)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and run.poll() is None:
        if len(list((tmp_path / "out").glob("*.exr"))) >= 1 and len(session_processes(run.pid)) >= 5:
            break                        # the batch, resource tracker, fork server and two workers
        time.sleep(0.05)
    assert run.poll() is None, "the batch ended before it could be killed"
    assert len(session_processes(run.pid)) >= 5, session_processes(run.pid)
    os.kill(run.pid, signal.SIGKILL)
    try:
        run.communicate(timeout=20)      # returns once no process holds its stdout and stderr
    except subprocess.TimeoutExpired:
        left = session_processes(run.pid)
        for line in left:                # clean up what the fault left, then fail
            os.kill(int(line.split()[0]), signal.SIGKILL)
        pytest.fail(f"processes kept the batch's pipes open after kill -9: {left}")
    deadline = time.monotonic() + 10
    while session_processes(run.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert session_processes(run.pid) == []


def test_kill_9_of_a_bake_leaves_a_temporary_that_the_rerun_removes(tmp_path):
    source = write_height(tmp_path / "big.png", 1024, 1)
    out = tmp_path / "out" / "h.exr"
    out.parent.mkdir()
    run = cli("bake", source, "-o", out)
    deadline, killed = time.monotonic() + 60, []
    while time.monotonic() < deadline and run.poll() is None and not killed:
        tmps = [p for p in out.parent.glob(".h.exr.*.tmp") if p.stat().st_size > 10**6]   # the preallocated pyramid
        if tmps:
            os.kill(run.pid, signal.SIGKILL)
            killed = tmps
        time.sleep(0.002)
    run.communicate(timeout=30)
    assert killed and run.returncode == -signal.SIGKILL, "the bake ended before it could be killed"
    assert all(p.exists() for p in killed) and not out.exists()  # what kill -9 leaves
    rerun = cli("bake", source, "-o", out)
    _, err = rerun.communicate(timeout=120)
    assert rerun.returncode == 0, err
    assert out.exists() and list(out.parent.glob(".*.tmp")) == []


# ------------------------------------------------------------ 9: a full disk
@pytest.fixture
def full_disk(tmp_path):
    """A 1 MiB tmpfs at ``tmp_path/disk`` (root only), unmounted after the test."""
    disk = tmp_path / "disk"
    disk.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1M", "tmpfs", str(disk)], capture_output=True,
                              text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as e:
        pytest.skip(f"cannot mount a tmpfs to fill: {e}")
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs to fill (needs root): {done.stderr.strip()}")
    try:
        yield disk
    finally:
        if subprocess.run(["umount", str(disk)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(disk)], capture_output=True)


@pytest.mark.parametrize("compression", ["none", "zip"])      # the preallocated file; OpenEXR's writer
def test_a_full_disk_while_baking_is_one_line_naming_the_file(compression, full_disk, tmp_path, capsys):
    source = write_height(tmp_path / "h.png", 512, 1)
    out = full_disk / "h.exr"
    assert main(["bake", str(source), "-o", str(out), "--compression", compression]) == 1
    one_error_line(capsys.readouterr().err, f"{out}: No space left on device")
    assert list(full_disk.iterdir()) == []


def test_write_exr_on_a_full_disk_raises_an_os_error_naming_the_file(full_disk):
    with pytest.raises(OSError, match="No space left on device") as e:
        write_exr(full_disk / "big.exr", np.random.default_rng(0).random((512, 512, 3)))
    assert e.value.filename == str(full_disk / "big.exr")
    assert list(full_disk.iterdir()) == []


def test_a_demo_that_fills_the_disk_leaves_nothing(full_disk):
    out = full_disk / "demo"
    run = cli("demo", "-o", out, "--size", "16", "--spp", "2", "--no-viewer", "--no-mitsuba", "-j", "1")
    _, err = run.communicate(timeout=300)
    assert run.returncode == 1
    one_error_line(err, "No space left on device", str(out))
    assert list(out.rglob("*")) == []


# ------------------------------------------------------------ 10: Dask scheduler addresses
@pytest.fixture
def silent_listener():
    """A TCP listener on 127.0.0.1 that accepts connections and never answers; closed (with
    what it accepted) after the test, and by itself after 120 s at the latest."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.2)
    accepted, stop = [], threading.Event()

    def serve():
        deadline = time.monotonic() + 120
        while not stop.is_set() and time.monotonic() < deadline:
            try:
                accepted.append(server.accept()[0])
            except OSError:
                pass
        for c in accepted:
            c.close()
        server.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield f"tcp://127.0.0.1:{server.getsockname()[1]}", accepted
    stop.set()
    thread.join(5)


@pytest.fixture
def maps_folder(tmp_path):
    for k in range(2):
        write_height(tmp_path / "maps" / f"h{k}.png", 16, k)
    return tmp_path / "maps"


def test_a_silent_scheduler_fails_within_the_timeout(silent_listener, maps_folder, tmp_path):
    pytest.importorskip("distributed", reason="needs dask[distributed] (microfacet[dask])")
    address, accepted = silent_listener
    t0 = time.monotonic()
    run = cli("bake", maps_folder, "-o", tmp_path / "out", "--scheduler", address, "--scheduler-timeout", "2")
    try:
        out, err = run.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        run.kill()
        run.communicate()
        pytest.fail("the batch hung on a scheduler that never answers")
    assert run.returncode == 1 and out == ""
    one_error_line(err, address, "did not answer within 2 s")
    assert time.monotonic() - t0 < 30 and accepted
    assert not (tmp_path / "out").exists()               # no summary of files "not run: interrupted"


def test_a_refused_scheduler_port_fails_at_once(maps_folder, tmp_path, capsys):
    pytest.importorskip("distributed", reason="needs dask[distributed] (microfacet[dask])")
    with socket.socket() as s:                           # a port that was free: now refused
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    assert main(["bake", str(maps_folder), "-o", str(tmp_path / "out"), "--scheduler",
                 f"tcp://127.0.0.1:{port}"]) == 1
    assert time.monotonic() - t0 < 5
    one_error_line(capsys.readouterr().err, f"tcp://127.0.0.1:{port}", "connection refused")
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("address, words", [("ucx://127.0.0.1:1", "scheme 'ucx' is not supported"),
                                            ("inproc://x", "inproc:// address works only inside"),
                                            ("nonsense://127.0.0.1:1", "scheme 'nonsense' is not supported"),
                                            ("tcp://127.0.0.1:notaport", "expected tcp://HOST:PORT")])
def test_bad_scheduler_addresses_are_one_line_errors(address, words, maps_folder, tmp_path, capsys):
    pytest.importorskip("distributed", reason="needs dask[distributed] (microfacet[dask])")
    assert main(["bake", str(maps_folder), "-o", str(tmp_path / "out"), "--scheduler", address]) == 1
    one_error_line(capsys.readouterr().err, address, words)
    assert not (tmp_path / "out").exists()


def test_connect_timeout_must_be_positive(maps_folder, tmp_path):
    pytest.importorskip("distributed", reason="needs dask[distributed] (microfacet[dask])")
    with pytest.raises(ValueError, match="connect_timeout must be a positive number of seconds"):
        mf.batch.run("bake", maps_folder, tmp_path / "out", scheduler="tcp://127.0.0.1:1", connect_timeout=0)
