"""Cold start: BRDF methods run the NumPy reference while their kernels compile on a background
thread (``MICROFACET_COMPILE=background``, the library's default; the suite itself runs with
``wait``, tests/conftest.py), then switch to the compiled kernels; the README quick start runs in a
few seconds with an empty Numba cache; ``python -m microfacet.kernels --precompile`` fills the
cache that a later process loads from."""
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import microfacet as mf
from microfacet import kernels

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (or MICROFACET_NUMBA=0)")

README = Path(__file__).resolve().parents[1] / "README.md"


@pytest.fixture
def background(monkeypatch):
    """``COMPILE == "background"`` with no kernel ready, queued or failed in this process (fresh
    registries: the kernels that other tests compiled are loaded again, from Numba's cache)."""
    monkeypatch.setattr(kernels, "COMPILE", "background")
    monkeypatch.setattr(kernels, "_READY", {})
    monkeypatch.setattr(kernels, "_QUEUED", set())
    monkeypatch.setattr(kernels, "_FAILED", set())
    yield
    assert kernels.ready(wait=600), "the background thread did not finish"


def _dirs(rng, n):
    w = mf.geometry.normalize(rng.normal(size=(n, 3)))
    w[:, 2] = np.abs(w[:, 2])
    return w


def _eval_key(brdf):
    """The dispatcher of ``brdf``'s float64 eval kernel (Numba imported)."""
    return kernels._dispatcher(("eval_kernel", brdf.params.kind, np.dtype(np.float64)))


def test_kind_constants_match_the_kernels():
    """microfacet.params spells the kernels' kind constants so that choosing a kernel does not import Numba."""
    from microfacet import params
    k = kernels._kernels()
    assert (params.BECKMANN, params.GGX) == (k.BECKMANN, k.GGX)
    assert (params.IDEAL, params.SCHLICK, params.DIELECTRIC, params.CONDUCTOR, params.TABULATED) == \
        (k.IDEAL, k.SCHLICK, k.DIELECTRIC, k.CONDUCTOR, k.TABULATED)


def test_background_path_then_compiled_path_agree(background):
    """While its kernels compile, a BRDF returns exactly its NumPy reference; once they are ready
    (:func:`kernels.ready`), exactly the compiled kernels' results, without compiling at the call;
    the two agree to 1e-12 (as tests/test_kernels.py)."""
    rng = np.random.default_rng(21)
    brdf = mf.MicrofacetBRDF(mf.GGX.from_ellipse(alpha1=0.4, alpha2=0.1, phi=0.7),
                             fresnel=mf.fresnel.Conductor.metal("Au"))
    wi, wo, u = _dirs(rng, 3000), _dirs(rng, 3000), rng.random((3000, 2))
    first = brdf.eval(wi, wo), brdf.pdf(wi, wo), brdf.sample(u, wo)
    assert kernels._QUEUED or kernels._READY                         # compiling or already loaded
    oh, s = brdf._projected_numpy(wi, wo, True)
    with np.errstate(all="ignore"):
        reference = (mf.fresnel.conductor_reflectance(oh[:, None], brdf.fresnel.eta, brdf.fresnel.k) * s[:, None],
                     brdf._pdf_numpy(wi, wo), brdf._sample_numpy(u, wo))
    np.testing.assert_array_equal(first[0], reference[0])
    np.testing.assert_array_equal(first[1], reference[1])
    for a, b in zip(first[2], reference[2]):
        np.testing.assert_array_equal(a, b)
    assert kernels.ready(wait=600)
    dispatcher = _eval_key(brdf)
    versions = len(dispatcher.signatures)
    second = brdf.eval(wi, wo), brdf.pdf(wi, wo), brdf.sample(u, wo)
    assert len(dispatcher.signatures) == versions                    # loaded in the background, not at the call
    compiled = (kernels.smith_eval(brdf, wi, wo, True)[0], kernels.smith_pdf(brdf, wi, wo)[0],
                kernels.smith_sample(brdf, u, wo)[0])
    np.testing.assert_array_equal(second[0], compiled[0])
    np.testing.assert_array_equal(second[1], compiled[1])
    for a, b in zip(second[2], compiled[2]):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(second[0], first[0], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(second[1], first[1], rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(second[2][0], first[2][0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(second[2][1], first[2][1], rtol=1e-12, atol=1e-12)


def test_compiled_function_runs_its_source_until_ready(background):
    """A :func:`kernels.compiled` function (the conductor Fresnel term) runs the NumPy function
    itself until its compiled version is ready, then that one: same values to 1e-14."""
    from microfacet.fresnel import conductor_reflectance
    f = kernels.compiled(conductor_reflectance)
    c = np.linspace(0.0, 1.0, 1001)
    first = f(c, 0.2, 3.1)
    np.testing.assert_array_equal(first, conductor_reflectance(c, 0.2, 3.1))
    assert kernels.ready(wait=600)
    assert len(f.dispatcher.signatures) == 1
    second = f(c, 0.2, 3.1)
    np.testing.assert_array_equal(second, f.dispatcher(c, 0.2, 3.1))
    np.testing.assert_allclose(second, first, rtol=1e-14)


def test_large_batches_wait_for_their_kernel(background, monkeypatch):
    """A batch above BACKGROUND_MAX pairs runs the kernel (compiled or loaded at the call) instead
    of the NumPy path: with BACKGROUND_MAX 100, a batch of 101 pairs leaves its kernel ready."""
    monkeypatch.setattr(kernels, "BACKGROUND_MAX", 100)
    rng = np.random.default_rng(2)
    brdf = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3), fresnel=mf.fresnel.Schlick(0.04))
    wi, wo = _dirs(rng, 101), _dirs(rng, 101)
    f = brdf.eval(wi, wo)
    assert any(key[0][0] == "eval_kernel" for key in kernels._READY)
    np.testing.assert_array_equal(f, kernels.smith_eval(brdf, wi, wo, True)[0])


def test_compile_mode_is_checked():
    r = subprocess.run([sys.executable, "-c", "import microfacet.kernels"], capture_output=True, text=True, timeout=120,
                       env=dict(os.environ, MICROFACET_COMPILE="later"))
    assert r.returncode != 0 and "MICROFACET_COMPILE must be 'background' or 'wait', got 'later'" in r.stderr


def _quick_start() -> str:
    text = README.read_text(encoding="utf-8")
    m = re.search(r"^## Quick start\n.*?^```python\n(.*?)^```", text, re.S | re.M)
    if m is None:
        pytest.skip("README.md has no '## Quick start' python block")
    return m.group(1)


def test_quick_start_with_an_empty_numba_cache(tmp_path):
    """The README quick start, run as a new user would (a new process, an empty Numba cache, the
    default MICROFACET_COMPILE), finishes within 20 s (goal 5 s; it took 12-28 s when every kernel
    compiled at its first call, 2-4 s measured since) and writes its pictures."""
    (tmp_path / "cache").mkdir()
    env = {k: v for k, v in os.environ.items() if k != "MICROFACET_COMPILE"}
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "cache")
    script = tmp_path / "quick_start.py"
    script.write_text(_quick_start(), encoding="utf-8")
    t = time.perf_counter()
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env, capture_output=True, text=True,
                       timeout=300)
    elapsed = time.perf_counter() - t
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "sphere.png").stat().st_size > 0 and (tmp_path / "sphere.exr").stat().st_size > 0
    assert elapsed < 20.0, f"quick start took {elapsed:.1f} s with an empty Numba cache"


@pytest.mark.slow
def test_precompile_fills_the_cache_that_a_later_process_loads(tmp_path):
    """``python -m microfacet.kernels --precompile --dtypes float64`` into the project's cache (as
    ``make setup`` does: filled there, so this run loads; an empty cache costs ~150 s of CPU, too
    long for the suite); then a new process in ``wait`` mode runs eval, pdf and sample (rows and
    a broadcast view) and the projected kernel, loading every kernel from the cache: none is
    compiled (``data saved``)."""
    env = dict(os.environ, NUMBA_DEBUG_CACHE="1", MICROFACET_COMPILE="wait")
    pre = subprocess.run([sys.executable, "-m", "microfacet.kernels", "--precompile", "--dtypes", "float64"],
                         env=env, capture_output=True, text=True, timeout=1800)
    assert pre.returncode == 0, pre.stderr[-2000:]
    assert "kernels compiled or loaded" in pre.stdout
    code = ("import numpy as np, microfacet as mf\n"
            "b = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Conductor.metal('Cu'))\n"
            "w = np.tile([0.0, 0.6, 0.8], (10, 1)); one = np.array([0.0, 0.0, 1.0])\n"
            "b.eval(w, w); b.eval(w, one); b.pdf(one, w); b.sample(np.full((10, 2), 0.5), w)\n"
            "b.sample(np.full((10, 2), 0.5), one); mf.kernels.smith_projected(b.distribution, True, w, w, True)\n"
            "mf.fresnel.Conductor.metal('Au')(np.linspace(0, 1, 9))\n")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    out = r.stdout + r.stderr
    assert out.count("data loaded") >= 7 and out.count("data saved") == 0, out[-3000:]
