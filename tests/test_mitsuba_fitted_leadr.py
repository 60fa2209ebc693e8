"""The Mitsuba 3 plugins ``mf_fitted`` and ``mf_leadr`` (:mod:`microfacet.mitsuba`) against the
library.

* ``eval`` / ``pdf`` equal the NumPy oracle (float64) on >= 10^4 direction pairs (relative
  1e-4 where the value exceeds 1e-3 of the largest; inputs rounded to float32): fits
  (isotropic, anisotropic, with a diffuse base; tabulated and the GGX / Beckmann
  conversions) against :class:`microfacet.fit.FittedBRDF`, and LEADR texels and
  footprints against ``lookup`` + ``from_moments`` + ``MicrofacetBRDF``.
* ``mitsuba.chi2`` accepts each plugin's sampler at views 0, 60 and 85 degrees.
* White furnace (white Fresnel, constant environment, path tracer): no pixel above
  1 + 3 sigma; each plugin renders the same image in ``scalar_rgb`` and ``llvm_ad_rgb``.
* Bad parameters give a one-line error naming the parameter and file.

The llvm skip rules (and ``CI=true``) are those of ``test_mitsuba_plugins.py``, whose
fixtures and helpers are reused.
"""
from __future__ import annotations

import numpy as np
import pytest

import microfacet as mf

mi = pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional `mitsuba` package "
                                           "(pip install 'microfacet[mitsuba]')")
dr = pytest.importorskip("drjit", reason="the Mitsuba plugins need drjit (installed with mitsuba)")
from test_mitsuba_plugins import (assert_close, f32, hemisphere, llvm, llvm_ok, load_error,  # noqa: E402,F401
                                  REL_TOL, plugin_eval_pdf, render_stats, sphere_scene, use, variant, vec3)

CU = mf.fresnel.Conductor.METALS["Cu"]


# ------------------------------------------------------------------ files
class _Sum:
    """A GGX copper lobe plus a Lambertian base: the input of the diffuse fit."""

    def __init__(self):
        self.lobe = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Conductor(*CU))
        self.base = mf.Lambertian([0.2, 0.1, 0.05])

    def eval(self, wi, wo):
        return self.lobe.eval(wi, wo) + self.base.eval(wi, wo)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Small fits (isotropic Cu GGX, anisotropic correlated Beckmann, GGX + diffuse, and
    an isotropic V-groove fit: slopes of ``P``) and a LEADR pyramid (anisotropic,
    correlated Gaussian heights, 64 x 48), written by the library's own writers."""
    d = tmp_path_factory.mktemp("mitsuba_files")
    fits = {
        "iso": mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Conductor(*CU)), 32),
        "aniso": mf.fit.fit(mf.MicrofacetBRDF(mf.Beckmann(alpha_x=0.2, alpha_y=0.4, rho=0.3),
                                              fresnel=mf.fresnel.Schlick(0.5)), 24, anisotropic=True),
        "diffuse": mf.fit.fit(_Sum(), 32, diffuse=True),
        "vgroove": mf.fit.fit(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.25), gaf="vgroove"), 24, gaf="vgroove"),
    }
    out = {name: str(f.save(d / f"{name}.npz")) for name, f in fits.items()}
    h = mf.leadr.gaussian_heightfield((64, 48), 0.3, 0.15, rho=0.4, correlation=4.0, seed=1)
    out["pyramid"] = str(mf.leadr.write_pyramid(d / "pyramid.exr", mf.leadr.bake(h)))
    return out


FITS = ["iso", "aniso", "diffuse", "vgroove"]


def fit_oracle(path, use_="tabulated"):
    fit = mf.fit.load(path)
    return {"tabulated": fit, "ggx": fit.to_ggx(), "beckmann": fit.to_beckmann()}[use_]


def fresnel_tolerance(brdf) -> float:
    """``REL_TOL``, or more for a steep Fresnel table: the plugin's float32 ``o.h`` (errors
    up to ~5e-6 measured) moves ``F`` by ``|dF/d cos| / F`` times that (the table a moment conversion
    solves for a cross-family NDF, e.g. GGX 0.3 -> Beckmann 1.29, has ``|dF/d cos|`` ~ 24
    where ``F`` ~ 0.1)."""
    fresnel = getattr(brdf, "fresnel", None)
    if not hasattr(fresnel, "cos_theta_d"):
        return REL_TOL
    x, v = fresnel.cos_theta_d, fresnel.values
    mid = 0.5 * (v[1:] + v[:-1])
    log_slope = np.abs(np.diff(v, axis=0)) / np.diff(x)[:, None] / np.maximum(mid, 1e-3)
    return max(REL_TOL, 5e-6 * float(log_slope.max()))


def direction_pairs(brdf, rng, n):
    """Views ``wo`` (grazing ones included); lights half from the oracle's sampler, half uniform."""
    wo = hemisphere(rng, n // 2)
    wi = np.concatenate([brdf.sample(rng.random((len(wo), 2)), wo)[0], hemisphere(rng, len(wo), grazing=False)])
    wi, wo = f32(wi), np.concatenate([wo, wo])
    keep = np.linalg.norm(wi, axis=-1) > 0.5
    return wi[keep], wo[keep]


# ------------------------------------------------------------- mf_fitted
@pytest.mark.parametrize("use_", ["tabulated", "ggx", "beckmann"])
@pytest.mark.parametrize("name", FITS)
def test_fitted_eval_pdf_match_numpy(llvm, files, name, use_):
    """The tabulated fit (D, Lambda, Fresnel tables, diffuse base) and its analytic
    conversions: eval and pdf equal the library's on >= 10^4 pairs."""
    brdf = fit_oracle(files[name], use_)
    wi, wo = direction_pairs(brdf, np.random.default_rng(FITS.index(name)), 12000)
    bsdf = mi.load_dict({"type": "mf_fitted", "filename": files[name], "use": use_})
    f, pdf = plugin_eval_pdf(bsdf, "llvm_ad_rgb", wi, wo)
    assert_close("eval", f, brdf.eval_cos(wi, wo), rel_tol=fresnel_tolerance(brdf))
    assert_close("pdf", pdf, brdf.pdf(wi, wo))


@pytest.mark.parametrize("name", ["iso", "diffuse"])
def test_fitted_scalar_variant_matches_numpy(files, name):
    """``scalar_rgb`` (double-precision Python floats, tables indexed by NumPy): same values."""
    use("scalar_rgb")
    brdf = fit_oracle(files[name])
    wi, wo = direction_pairs(brdf, np.random.default_rng(5), 2400)
    f, pdf = plugin_eval_pdf(mi.load_dict({"type": "mf_fitted", "filename": files[name]}), "scalar_rgb", wi, wo)
    assert_close("eval", f, brdf.eval_cos(wi, wo))
    assert_close("pdf", pdf, brdf.pdf(wi, wo))


def _search_tables(rng):
    """Sorted float32 tables as the plugins search them: a CDF with runs of tiny-mass and
    empty intervals at both ends (as tabulated fits have), ``cos theta`` at uniform
    ``theta`` (the Fresnel nodes, dense near 1), and random sorted values with ties."""
    mass = np.concatenate([np.full(40, 1e-9), rng.random(60), np.zeros(5), np.full(50, 1e-8), [0.0] * 3])
    cdf = np.concatenate([[0.0], np.cumsum(mass) / mass.sum()])
    return {"cdf": (cdf, 1.0 - 2.0**-24), "cos": (np.cos(np.linspace(np.pi / 2, 0, 90)), np.inf),
            "ties": (np.sort(np.round(rng.normal(size=300), 1)) + 0.25, np.inf)}   # no 0: its neighbours are denormal


@pytest.mark.parametrize("kind", ["cdf", "cos", "ties"])
def test_sorted_search_is_searchsorted(llvm, kind):
    """The guided search returns ``searchsorted(x, v, "right") - 1`` clipped into the
    intervals, for every node value, its float32 neighbours, the ends and random values."""
    from microfacet.mitsuba.tabulated import SortedSearch
    rng = np.random.default_rng(3)
    x, v_max = _search_tables(rng)[kind]
    x = x.astype(np.float32)
    v = np.concatenate([x, np.nextafter(x, -np.inf), np.nextafter(x, np.inf),
                        rng.uniform(x[0] - 0.1, x[-1] + 0.1, 20000).astype(np.float32), [x[0], x[-1]]])
    v = np.minimum(v, np.float32(v_max)).astype(np.float32)
    search = SortedSearch(x, v_max)
    assert search.width < len(x) // 4                    # the guide narrows the bisection
    ours = np.array(search(mi.Float(v)))
    expected = np.clip(np.searchsorted(x, v, side="right") - 1, 0, len(x) - 2)
    np.testing.assert_array_equal(ours, expected)
    use("scalar_rgb")
    scalar = SortedSearch(x, v_max)
    assert [scalar(float(t)) for t in v[::97]] == list(expected[::97])


def test_next_row_window_brackets_the_next_row(files):
    """For every row ``k`` and ``v``, row ``k + 1``'s answer lies in the window that row
    ``k``'s answer names (the fit's conditional CDFs of ``|y~|``)."""
    from microfacet.mitsuba.tabulated import next_row_window
    d = mf.fit.load(files["iso"]).distribution
    cdf = np.asarray(d.y_cdf, dtype=np.float32).reshape(d.eta_nodes.shape)
    v_max = np.float32(1.0 - 2.0**-24)
    start, width = next_row_window(cdf, v_max)
    assert width < cdf.shape[1] // 8
    rng = np.random.default_rng(4)
    v = np.concatenate([rng.random(4000, dtype=np.float32), cdf.ravel()[::7], [0.0, v_max]]).astype(np.float32)
    v = v[v <= v_max]
    n = cdf.shape[1]
    for k in range(cdf.shape[0] - 1):
        j0, j1 = (np.clip(np.searchsorted(cdf[r], v, side="right") - 1, 0, n - 2) for r in (k, k + 1))
        lo = start[k, j0]
        assert np.all((lo <= j1) & (j1 < lo + width)), k


def _sample(bsdf, wo, u1, u):
    si = dr.zeros(mi.SurfaceInteraction3f, len(wo))
    si.wi = vec3(wo)
    bs, weight = bsdf.sample(mi.BSDFContext(), si, mi.Float(u1.astype(np.float32)),
                             mi.Point2f(*(np.ascontiguousarray(u[:, j], np.float32) for j in range(2))))
    return np.array(bs.wo).T.reshape(-1, 3), np.array(weight).T.reshape(-1, 3), np.array(bs.pdf).ravel()


@pytest.mark.parametrize("name", ["iso", "aniso", "vgroove"])
def test_fitted_sample_matches_numpy(llvm, files, name):
    """Without a base, ``sample`` maps uniforms to the library's directions (visible-slope
    tables for the isotropic Smith fit, cell + Newton + azimuth quantile for slopes of
    ``P``), with its pdf and weight."""
    brdf = fit_oracle(files[name])
    rng = np.random.default_rng(13)
    wo = hemisphere(rng, 20000, grazing=False)
    u = f32(rng.uniform(0.01, 0.99, (len(wo), 2)))
    wi_ref, weight_ref, pdf_ref = brdf.sample(u, wo)
    wi, weight, pdf = _sample(mi.load_dict({"type": "mf_fitted", "filename": files[name]}), wo,
                              np.zeros(len(wo)), u)
    ok = pdf_ref > 0
    assert ok.sum() > 0.5 * len(wo)
    err = np.abs(wi - wi_ref).max(axis=-1)
    assert np.quantile(err[ok], 0.999) < 2e-3, np.quantile(err[ok], 0.999)
    good = ok & (wi_ref[:, 2] > 0.05) & (err < 1e-4)
    assert good.sum() > 0.5 * ok.sum()
    np.testing.assert_allclose(pdf[good], pdf_ref[good], rtol=2e-2)
    np.testing.assert_allclose(weight[good], weight_ref[good], rtol=2e-2, atol=1e-4)


def test_fitted_diffuse_sample_weight_is_eval_over_pdf(llvm, files):
    """With a base: the mixture's weight ``eval / pdf``, both lobes chosen as often as ``p``."""
    fit = fit_oracle(files["diffuse"])
    rng = np.random.default_rng(17)
    wo = hemisphere(rng, 20000, grazing=False)
    u1 = rng.random(len(wo))
    wi, weight, pdf = _sample(mi.load_dict({"type": "mf_fitted", "filename": files["diffuse"]}), wo, u1,
                              rng.random((len(wo), 2)))
    ok = pdf > 0
    assert ok.mean() > 0.9
    np.testing.assert_allclose(weight[ok], fit.eval_cos(wi[ok], wo[ok]) / fit.pdf(wi[ok], wo[ok])[:, None],
                               rtol=1e-3, atol=1e-6)


# -------------------------------------------------------------- mf_leadr
LEADR_BASES = [("alpha", 0.1), ("fit", "iso")]


def leadr_dict(files, key, value, **extra):
    return {"type": "mf_leadr", "filename": files["pyramid"],
            key: files[value] if key == "fit" else value, **extra}


@pytest.mark.parametrize("width", [0.0, 0.01, 0.05, 0.3])
@pytest.mark.parametrize("key,value", LEADR_BASES, ids=["alpha", "fit"])
def test_leadr_eval_pdf_match_library(llvm, files, key, value, width):
    """Random uv (wrapping) and random footprint axes ``si.duv_dx``, ``si.duv_dy`` of
    scale ``width`` (isotropic to strongly anisotropic: 1 to 16 probes, every MIP level):
    eval and pdf equal ``MicrofacetBRDF(from_moments(lookup(levels, uv, J)))`` with the
    base merged by ``downsample_operator``."""
    rng = np.random.default_rng(int(width * 100))
    base = mf.fit.load(files[value]) if key == "fit" else value
    surface = mf.leadr.FilteredSurface(mf.leadr.read_pyramid(files["pyramid"]), base)
    n = 12000
    uv = f32(rng.uniform(-1.0, 2.0, (n, 2)))
    J = f32(rng.normal(0.0, width, (n, 2, 2)))
    brdf = surface.brdf(uv, J)
    wo = hemisphere(rng, n, grazing=False)
    wi = brdf.sample(rng.random((n, 2)), wo)[0]
    wi = f32(np.where((np.linalg.norm(wi, axis=-1) > 0.5)[:, None] & (rng.random((n, 1)) < 0.5), wi,
                      hemisphere(rng, n, grazing=False)))
    bsdf = mi.load_dict(leadr_dict(files, key, value))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = vec3(wo)
    v2 = lambda a: mi.Vector2f(*(np.ascontiguousarray(a[:, j], np.float32) for j in range(2)))  # noqa: E731
    si.uv, si.duv_dx, si.duv_dy = v2(uv), v2(J[:, 0]), v2(J[:, 1])
    value_, pdf = bsdf.eval_pdf(mi.BSDFContext(), si, vec3(wi))
    assert_close("eval", np.array(value_).T.reshape(-1, 3), brdf.eval_cos(wi, wo), rel_tol=fresnel_tolerance(brdf))
    assert_close("pdf", np.array(pdf).ravel(), brdf.pdf(wi, wo))


def test_leadr_footprint_parameter_is_the_fallback(llvm, files):
    """Without differentials (``duv = 0``) the ``footprint`` width (times ``uv_scale``
    for the differentials only) is used: equal to the library's isotropic lookup."""
    rng = np.random.default_rng(23)
    surface = mf.leadr.FilteredSurface(mf.leadr.read_pyramid(files["pyramid"]), 0.05)
    n = 10000
    uv = f32(rng.uniform(0.0, 1.0, (n, 2)))
    brdf = surface.brdf(2.0 * uv, 0.08)
    wo = hemisphere(rng, n, grazing=False)
    wi = f32(brdf.sample(rng.random((n, 2)), wo)[0])
    bsdf = mi.load_dict({"type": "mf_leadr", "filename": files["pyramid"], "alpha": 0.05,
                         "footprint": 0.08, "uv_scale": 2.0})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = vec3(wo)
    si.uv = mi.Vector2f(*(np.ascontiguousarray(uv[:, j], np.float32) for j in range(2)))
    value_ = bsdf.eval(mi.BSDFContext(), si, vec3(wi))
    assert_close("eval", np.array(value_).T.reshape(-1, 3), brdf.eval_cos(wi, wo))


# ------------------------------------------------------------- chi-square
def _chi2(plugin, d, tmp_path, monkeypatch, label, uv=(0.5, 0.5), ires=8):
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain
    monkeypatch.chdir(tmp_path)
    for deg in (0, 60, 85):
        theta = np.radians(deg)
        sample, pdf = BSDFAdapter(plugin, d, wi=[float(np.sin(theta)), 0.0, float(np.cos(theta))], uv=list(uv))
        chi2 = ChiSquareTest(domain=SphericalDomain(), sample_func=sample, pdf_func=pdf,
                             sample_dim=3, sample_count=200_000, res=100, ires=ires)
        assert chi2.run(0.01, test_count=3, quiet=True), f"{label} view {deg} deg: {chi2.messages}"
        print(f"chi2 {label} view={deg}: p = {chi2.p_value:.3f}")


@pytest.mark.parametrize("name", FITS)
def test_fitted_chi2(llvm, files, name, tmp_path, monkeypatch):
    """Mitsuba's chi-square test of ``sample`` against ``pdf`` (settings of
    ``test_mitsuba_plugins.test_chi2_sampling_matches_pdf``)."""
    _chi2("mf_fitted", {"type": "mf_fitted", "filename": files[name]}, tmp_path, monkeypatch, f"mf_fitted {name}")


@pytest.mark.parametrize("uv", [(0.3, 0.6), (0.71, 0.12)])
def test_leadr_chi2(llvm, files, uv, tmp_path, monkeypatch):
    """At two points of the finest level (bilinear blends of sheared, correlated lobes;
    ``footprint`` 0). Base alpha 0.2: with 0.1 these lobes (alpha ~0.1, mean slope ~0.06)
    fail at 85 degrees in ``mf_microfacet`` itself (p = 0, same statistic), where
    ``roughconductor`` alpha 0.1 passes with p = 0.005: a limit of the shared lobe code
    at sharp grazing lobes, not of the lookup."""
    _chi2("mf_leadr", leadr_dict(files, "alpha", 0.2), tmp_path, monkeypatch, f"mf_leadr uv={uv}", uv)


# -------------------------------------------------------------- rendering
def white_fit(path, tmp_path):
    """The fit with its Fresnel table set to 1 (and no base): the white-furnace material."""
    fit = mf.fit.load(path)
    c = fit.fresnel.cos_theta_d
    white = mf.fit.FittedBRDF(fit.distribution, mf.fresnel.Tabulated(c, np.ones((len(c), 3))),
                              gaf=fit.gaf_model, shadowing=fit.shadowing, f0=fit.f0)
    return str(white.save(tmp_path / "white.npz"))


@pytest.mark.parametrize("plugin", ["mf_fitted iso", "mf_fitted aniso", "mf_leadr"])
def test_white_furnace(llvm, files, plugin, tmp_path):
    """A sphere of each plugin with a white Fresnel in a constant unit environment (path
    tracer): no pixel above 1 + 3 sigma (sigma from 16 independent renders)."""
    if plugin == "mf_leadr":
        bsdf = leadr_dict(files, "alpha", 0.1, footprint=0.02)
    else:
        bsdf = {"type": "mf_fitted", "filename": white_fit(files[plugin.split()[1]], tmp_path)}
    mean, se = render_stats(sphere_scene(bsdf, {"type": "constant", "radiance": 1.0}), spp=64, renders=16)
    mean, se = mean[..., 0], se[..., 0]
    excess = (mean - 1.0) / np.where(se > 0, se, np.inf)
    print(f"white furnace {plugin}: max pixel {mean.max():.4f}, max (value - 1)/sigma "
          f"{excess[se > 0].max():.2f}, min pixel {mean.min():.3f}")
    assert np.all(mean[se == 0] <= 1.0 + 1e-5)
    assert np.all(mean[se > 0] <= 1.0 + 3.0 * se[se > 0])
    assert np.median(mean) > 0.7                    # the sphere reflects (the test is not vacuous)


def _env():
    v, u = np.meshgrid(np.linspace(0, 1, 8), np.linspace(0, 1, 16), indexing="ij")
    sky = np.stack([0.2 + 0.6 * v, 0.3 + 0.5 * v, 0.6 + 0.3 * (1 - v)], axis=-1)
    sun = 4.0 * np.exp(-((u - 0.3) ** 2 + (v - 0.35) ** 2) / 0.01)[..., None]
    return {"type": "envmap", "bitmap": mi.Bitmap((sky + sun).astype(np.float32))}


@pytest.mark.parametrize("plugin", ["mf_fitted diffuse", "mf_fitted aniso", "mf_leadr"])
def test_scalar_and_llvm_render_alike(llvm_ok, files, plugin):
    """The same scene in ``scalar_rgb`` and ``llvm_ad_rgb``: per-pixel difference within
    noise (mean |diff| / sigma < 3; sigma from 4 renders per variant)."""
    if plugin == "mf_leadr":
        bsdf = leadr_dict(files, "alpha", 0.1, footprint=0.01)
    else:
        bsdf = {"type": "mf_fitted", "filename": files[plugin.split()[1]]}
    assert_scalar_and_llvm_alike(bsdf, 12, plugin)


def assert_scalar_and_llvm_alike(bsdf, size, label):
    """A ``size``² sphere with ``bsdf`` under the environment renders alike in
    ``scalar_rgb`` and ``llvm_ad_rgb``: mean |diff| / sigma < 3 over the noisy pixels."""
    stats = {}
    for v in ("scalar_rgb", "llvm_ad_rgb"):
        use(v)
        scene = sphere_scene(bsdf, _env())
        scene["sensor"]["film"]["width"] = scene["sensor"]["film"]["height"] = size
        stats[v] = _render_small(scene)
    (m0, s0), (m1, s1) = stats.values()
    sigma = np.sqrt(s0**2 + s1**2)
    noisy = sigma > 0
    assert noisy.mean() > 0.3
    z = np.abs(m0 - m1)[noisy] / sigma[noisy]
    print(f"scalar vs llvm {label}: mean |diff|/sigma = {z.mean():.3f}")
    assert z.mean() < 3.0


def _render_small(scene, renders=4, spp=16):
    s = mi.load_dict(scene)
    images = np.stack([np.array(mi.render(s, spp=spp, seed=seed)) for seed in range(renders)])
    return images.mean(0), images.std(0, ddof=1) / np.sqrt(renders)


# ----------------------------------------------------------------- errors
@pytest.mark.parametrize("plugin", ["mf_fitted", "mf_leadr"])
def test_missing_file_names_parameter_and_file(plugin, tmp_path):
    missing = str(tmp_path / "nope.bin")
    last = load_error({"type": plugin, "filename": missing})
    assert f"{plugin}: parameter 'filename'" in last and "nope.bin" in last, last
    last = load_error({"type": plugin})
    assert f"{plugin}: parameter 'filename' is required" in last, last


def test_corrupt_files_name_parameter_and_file(files, tmp_path):
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(b"PK\x03\x04 this is not a zip")
    last = load_error({"type": "mf_fitted", "filename": str(bad)})
    assert "mf_fitted: parameter 'filename'" in last and "corrupt.npz" in last and "not a microfacet fit" in last, last
    exr = tmp_path / "corrupt.exr"
    exr.write_bytes(open(files["pyramid"], "rb").read()[:200])
    last = load_error({"type": "mf_leadr", "filename": str(exr)})
    assert "mf_leadr: parameter 'filename'" in last and "corrupt.exr" in last, last


def test_wrong_kind_of_file_is_named(files, tmp_path):
    """A glint (or fit) .npz given to mf_leadr, a pyramid EXR given to mf_fitted, a glint
    .npz given to mf_fitted."""
    glint = tmp_path / "glints.npz"
    np.savez(glint, format=np.array("microfacet.glints"), normals=np.zeros((4, 4, 3)))
    last = load_error({"type": "mf_leadr", "filename": str(glint)})
    assert "mf_leadr: parameter 'filename'" in last and "glints.npz" in last and ".npz archive" in last, last
    last = load_error({"type": "mf_fitted", "filename": files["pyramid"]})
    assert "mf_fitted: parameter 'filename'" in last and "OpenEXR" in last and "mf_leadr" in last, last
    last = load_error({"type": "mf_fitted", "filename": str(glint)})
    assert "mf_fitted: parameter 'filename'" in last and "glints.npz" in last and "microfacet fit file" in last, last
    last = load_error({"type": "mf_leadr", "filename": files["pyramid"], "fit": files["pyramid"]})
    assert "mf_leadr: parameter 'fit'" in last and "OpenEXR" in last, last


@pytest.mark.parametrize("extra,name", [
    ({"use": "phong"}, "use"), ({"specular_reflectance": "red"}, "specular_reflectance")])
def test_fitted_bad_parameters(files, extra, name):
    last = load_error({"type": "mf_fitted", "filename": files["iso"], **extra})
    assert f"mf_fitted: parameter '{name}'" in last, last


@pytest.mark.parametrize("extra,name", [
    ({"alpha": -0.1}, "alpha"), ({"alpha": 0.1, "fit": "x.npz"}, "alpha"), ({"uv_scale": 0.0}, "uv_scale"),
    ({"footprint": -1.0}, "footprint"), ({"shadowing": "often"}, "shadowing"),
    ({"material": "Unobtainium"}, "material")])
def test_leadr_bad_parameters(files, extra, name):
    last = load_error({"type": "mf_leadr", "filename": files["pyramid"], **extra})
    assert f"mf_leadr: parameter '{name}'" in last, last


# ----------------------------------------------------------------- variants
def grey_fit(path, tmp_path):
    """The fit with a grey Fresnel table (0.5) and a grey base (0.2)."""
    fit = mf.fit.load(path)
    c = fit.fresnel.cos_theta_d
    grey = mf.fit.FittedBRDF(fit.distribution, mf.fresnel.Tabulated(c, np.full((len(c), 3), 0.5)),
                             gaf=fit.gaf_model, shadowing=fit.shadowing, f0=fit.f0, diffuse=[0.2, 0.2, 0.2])
    return str(grey.save(tmp_path / "grey.npz"))


def _eval_channels(variant_, bsdf: dict, wi, wo):
    """``eval`` in ``variant_`` at 550 nm where spectral: ``(channels, n)``."""
    use(variant_)
    si = dr.zeros(mi.SurfaceInteraction3f, len(wi))
    si.wi = vec3(wo)
    si.uv = mi.Point2f(0.3, 0.6)
    if mi.is_spectral:
        si.wavelengths = dr.full(mi.Spectrum, 550.0, len(wi))
    return np.array(mi.load_dict(bsdf).eval(mi.BSDFContext(), si, vec3(wi))).reshape(-1, len(wi))


@pytest.mark.parametrize("variant_", ["llvm_ad_spectral", "llvm_ad_mono"])
def test_spectral_and_mono_variants_match_rgb(llvm_ok, files, tmp_path, variant_):
    """The table-based plugins (a fit's Fresnel table and base, LEADR over a fit, glints)
    in a spectral and a monochrome variant: on grey tables each channel equals the RGB
    variant's value; a coloured (copper) table gives finite, positive spectra."""
    grey = grey_fit(files["diffuse"], tmp_path)
    slopes = 0.3 * np.random.default_rng(2).normal(size=(8, 8, 2))
    glints = str(mf.glints.Microsurface.from_slopes(slopes, sigma_eps=0.1).save(tmp_path / "g.npz"))
    bsdfs = [{"type": "mf_fitted", "filename": grey}, {"type": "mf_fitted", "filename": grey, "use": "ggx"},
             {"type": "mf_leadr", "filename": files["pyramid"], "fit": grey, "footprint": 0.05},
             {"type": "mf_glints", "filename": glints, "schlick_f0": 0.5}]
    rng = np.random.default_rng(6)
    wo, wi = hemisphere(rng, 4000, grazing=False), hemisphere(rng, 4000, grazing=False)
    for bsdf in bsdfs:
        rgb = _eval_channels("llvm_ad_rgb", bsdf, wi, wo)
        assert np.abs(rgb[0]).max() > 0 and np.allclose(rgb[0], rgb[1]) and np.allclose(rgb[0], rgb[2])
        other = _eval_channels(variant_, bsdf, wi, wo)
        for channel in other:
            np.testing.assert_allclose(channel, rgb[0], rtol=1e-4, atol=1e-6 * np.abs(rgb[0]).max(),
                                       err_msg=f"{bsdf['type']} in {variant_}")
    copper = _eval_channels(variant_, {"type": "mf_fitted", "filename": files["iso"]}, wi, wo)
    assert np.all(np.isfinite(copper)) and copper.max() > 0 and copper.min() >= 0
    use("llvm_ad_rgb")
