"""``microfacet view`` in a real browser (headless Chromium driven by Playwright, WebGL2 on
SwiftShader) against the library's NumPy renders, and its bad-input handling.

The page's validation view renders the patch of ``microfacet.leadr.figures`` (one pixel per
texel of a MIP level, PatchScene's camera and light) by naive MIP, LEADR and the
supersampled reference; each is compared with ``figures.render_level``. Skips with a
one-line reason where Playwright or Chromium is missing; fails under CI=true.
"""
import os
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import default_sigint

from microfacet.leadr import bake, figures, read_pyramid, write_pyramid
from microfacet.leadr.downsample import base_lobe, downsample_operator, naive_pyramid

SRC = str(Path(__file__).resolve().parents[1] / "src")
CHROMIUM = ("/usr/lib/chromium/chromium", "/usr/bin/chromium", "/usr/bin/chromium-browser")
SIZE, BASE = 64, 0.1
LEVELS = (2, 4)
METHODS = {"naive": 0, "leadr": 1, "reference": 2}


def _env():
    return dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""), NUMBA_NUM_THREADS="1")


@pytest.fixture
def view(capsys, monkeypatch):
    """``microfacet view ARGS`` in this process, expecting it to fail before serving:
    returns (exit status, stderr); a server that starts fails the test instead of hanging."""
    import socketserver

    from microfacet.cli import main

    def serve_forever(self, *args):
        raise AssertionError("the server started")
    monkeypatch.setattr(socketserver.BaseServer, "serve_forever", serve_forever)

    def run(*args):
        code = main(["view", *map(str, args)])
        return code, capsys.readouterr().err
    return run


def _skip_or_fail(reason):
    if os.environ.get("CI", "").lower() in ("true", "1"):
        pytest.fail(f"{reason} [CI=true: browser tests must run; make setup installs chromium and playwright]")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def pyramid_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("view") / "map.exr"
    write_pyramid(path, bake(figures.default_heightfield(SIZE, 3), 1.0))
    return path


@pytest.fixture(scope="module")
def page(pyramid_file):
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _skip_or_fail("playwright is not installed (pip install playwright)")
    exe = next((c for c in CHROMIUM if Path(c).exists()), shutil.which("chromium"))
    if exe is None:
        _skip_or_fail("no system Chromium (apt-get install chromium)")
    proc = subprocess.Popen([sys.executable, "-m", "microfacet", "view", str(pyramid_file), "--roughness", str(BASE)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())
    try:
        url = proc.stdout.readline().strip()
        assert url.startswith("http://127.0.0.1:"), (url, proc.stderr.read() if proc.poll() is not None else "")
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=exe, headless=True)
            pg = browser.new_page(viewport={"width": 480, "height": 320})
            pg.messages = []
            pg.on("console", lambda m: pg.messages.append(f"{m.type}: {m.text}") if m.type == "error" else None)
            pg.on("pageerror", lambda e: pg.messages.append(f"pageerror: {e}"))
            pg.goto(url)
            pg.wait_for_function("window.mfViewer && window.mfViewer.frames > 0", timeout=60000)
            yield pg
            browser.close()
    finally:
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="module")
def renders(page, pyramid_file):
    """{(kind, level): {method: (browser image, NumPy image)}}."""
    levels = read_pyramid(pyramid_file)
    b = base_lobe(BASE)
    leadr, naive = downsample_operator(levels, b), naive_pyramid(levels[0].astype(np.float64), b)
    scene = figures.PatchScene()
    env = scene.environment()
    out = {}
    for light, kind in enumerate(("point", "env")):
        for level in LEVELS:
            n = SIZE >> level
            out[kind, level] = {}
            for method, m in METHODS.items():
                got = np.array(page.evaluate(f"mfViewer.renderPatch({{method: {m}, level: {level}, light: {light}}})"))
                ref = figures.render_level(method, level, leadr[0], naive, leadr, scene, kind, env)
                out[kind, level][method] = (got.reshape(n, n, 4)[..., :3], ref)
    return out


def mean_relative_error(image, reference) -> float:
    return float(np.mean(np.abs(image - reference)) / np.mean(np.abs(reference)))


def test_browser_matches_numpy(renders):
    errors = {key: {m: mean_relative_error(*pair) for m, pair in d.items()} for key, d in renders.items()}
    assert all(e <= 0.02 for d in errors.values() for e in d.values()), errors


def test_leadr_closer_to_reference_than_naive(renders):
    """As in the Python validation (figures.compare_levels), measured on the browser's images."""
    for key, d in renders.items():
        ref = d["reference"][0]
        rms = {m: figures.relative_rms(d[m][0], ref) for m in ("naive", "leadr")}
        assert rms["leadr"] < rms["naive"], (key, rms)


def test_no_console_errors(page, renders):
    assert page.evaluate("mfViewer.frameMs") > 0
    assert page.messages == []


# ------------------------------------------------------------------ bad input
def test_missing_and_corrupt_pyramid(tmp_path, view):
    code, err = view(tmp_path / "missing.exr")
    assert code != 0 and err.count("\n") == 1 and "missing.exr: no such file" in err
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"v/1\x01" + b"\0" * 64)                    # EXR magic, garbage header
    code, err = view(bad)
    assert code != 0 and err.count("\n") == 1 and "bad.exr" in err and "Traceback" not in err


def test_glint_npz_refused(tmp_path, pyramid_file, view):
    from microfacet.glints import Microsurface
    glint = Microsurface.from_normal_map(np.dstack([np.zeros((8, 8, 2)), np.ones((8, 8))])).save(tmp_path / "g.npz")
    for args in ([glint], [pyramid_file, "--material", glint]):
        code, err = view(*args)
        assert code != 0 and err.count("\n") == 1 and "g.npz" in err, err


def test_port_in_use(pyramid_file, view):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        code, err = view(pyramid_file, "--port", s.getsockname()[1])
    assert code != 0 and err.count("\n") == 1 and "cannot listen on 127.0.0.1" in err


def test_server_binds_localhost_only(pyramid_file):
    from microfacet.glsl.server import load_viewer_data, make_server
    server = make_server(load_viewer_data(pyramid_file))
    try:
        assert server.server_address[0] == "127.0.0.1" and server.server_address[1] > 0
    finally:
        server.server_close()


def test_ctrl_c_stops_the_server(pyramid_file):
    import signal
    proc = subprocess.Popen([sys.executable, "-m", "microfacet", "view", str(pyramid_file)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=_env(), preexec_fn=default_sigint)
    url = proc.stdout.readline().strip()
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert url.startswith("http://127.0.0.1:") and proc.returncode == 0 and err.strip().endswith("stopped")
