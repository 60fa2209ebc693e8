"""``python -m microfacet.kernels_extra --precompile`` (run by ``make setup``): the measured-BRDF,
LEADR and glints kernels compiled ahead of time, so that the demo's sections and later processes
load them from Numba's cache instead of compiling them at first use."""
import os
import subprocess
import sys

import pytest

from microfacet import kernels, kernels_extra

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (or MICROFACET_NUMBA=0)")


def test_unknown_groups_are_refused_in_one_line():
    with pytest.raises(ValueError, match="groups must be among measured, leadr, glints, got nope"):
        kernels_extra.group_calls(["leadr", "nope"])
    r = subprocess.run([sys.executable, "-m", "microfacet.kernels_extra", "--precompile", "--groups", "nope"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "--groups: groups must be among measured, leadr, glints, got nope" in r.stderr


def _saved_and_loaded(code: str) -> tuple[int, int, str]:
    """``(data saved, data loaded, output)`` of Numba's cache log for ``code`` in a new process."""
    env = dict(os.environ, NUMBA_DEBUG_CACHE="1", MICROFACET_COMPILE="wait")
    r = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stderr[-3000:]
    out = r.stdout + r.stderr
    return out.count("data saved"), out.count("data loaded"), out


def test_precompiled_leadr_kernels_load_at_other_sizes(tmp_path):
    """After the ``leadr`` group (16^2 map; compiled here if the cache is empty, ~10 s), the LEADR
    section on a 64^2 map loads every kernel it runs from the cache: the kernels' argument types do
    not depend on the sizes, so ``make setup`` covers the demo's 256^2 map."""
    saved, _, out = _saved_and_loaded("from microfacet import kernels_extra; kernels_extra.precompile(('leadr',))")
    saved, loaded, out = _saved_and_loaded(
        f"from microfacet.leadr.figures import leadr_section; leadr_section({str(tmp_path)!r}, size=64, "
        "levels=(1, 2, 3), display=64)")
    assert loaded >= 2 and saved == 0, out[-3000:]


@pytest.mark.slow
def test_precompiled_groups_cover_the_demo_sections_and_measured_files(tmp_path):
    """After every group (``make setup`` fills the cache, so this loads: an empty cache costs
    ~2-3 min of CPU), a new process that runs the glints section at other sizes and evaluates
    and samples MERL and RGL data compiles nothing (``data saved`` 0)."""
    saved, loaded, out = _saved_and_loaded("from microfacet import kernels_extra; kernels_extra.precompile()")
    code = ("import numpy as np\n"
            "from microfacet.glints.figures import glints_section\n"
            "from microfacet.kernels_extra import synthetic_rgl\n"
            "from microfacet.measured.merl import MERLBRDF, SHAPE\n"
            "from microfacet.measured.rgl import RGLBRDF\n"
            f"glints_section({str(tmp_path)!r}, map_size=64, width=16, reference_spp=4, naive_spp=2, seed=1)\n"
            "rng = np.random.default_rng(3)\n"
            "w = rng.normal(size=(1000, 3)); w[:, 2] = abs(w[:, 2]); w /= np.linalg.norm(w, axis=1)[:, None]\n"
            "for b in (MERLBRDF(np.full(SHAPE + (3,), 0.2), np.ones(SHAPE, bool)),\n"
            "          RGLBRDF(synthetic_rgl(rng, phi_i=(0.0, np.pi / 2, np.pi), n_theta=5))):\n"
            "    b.eval(w, w[::-1]); b.eval_cos(w, w[0]); b.sample(rng.random((1000, 2)), w)\n")
    saved, loaded, out = _saved_and_loaded(code)
    assert loaded >= 10 and saved == 0, out[-3000:]


def test_fortran_ordered_rows_run_the_c_rows_kernels():
    """Rows in Fortran order (Dr.Jit arrays seen through NumPy, the Mitsuba plugins' path) are read
    as C rows: the same values, and no compiled version of their own (the demo's Mitsuba section
    compiled one per kernel at its first use, outside what ``make setup`` precompiles)."""
    code = ("import numpy as np, microfacet as mf\n"
            "b = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.04))\n"
            "rng = np.random.default_rng(1)\n"
            "w = rng.normal(size=(2, 500, 3)); w[..., 2] = abs(w[..., 2]); w /= np.linalg.norm(w, axis=-1)[..., None]\n"
            "wi, wo = w\n"
            "c = b.eval(wi, wo), b.eval_cos(wi, wo)\n"
            "print('MARKER', flush=True)\n"
            "f = b.eval(wi, np.asfortranarray(wo)), b.eval_cos(np.asfortranarray(wi), wo)\n"
            "assert np.asfortranarray(wo).flags.f_contiguous and not np.asfortranarray(wo).flags.c_contiguous\n"
            "assert all(np.array_equal(x, y) for x, y in zip(c, f))\n")
    saved, loaded, out = _saved_and_loaded(code)
    after = out[out.index("MARKER"):]
    assert after.count("data saved") == 0, after[-3000:]
