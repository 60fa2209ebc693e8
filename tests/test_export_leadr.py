"""LEADR pyramids for engines (microfacet.export.leadr_textures): the covariance <-> (alpha1, alpha2,
phi) <-> glTF texture round trip, the PNG chains and the .glb (Khronos gltf-validator), the CLI's
one-line errors, and three.js: a plane receding to the horizon where the LEADR MIPs are closer to a
supersampled reference than naive MIPs."""
from __future__ import annotations

import concurrent.futures
import importlib
import os

import numpy as np
import pytest

import microfacet as mf
from microfacet.cli import main
from microfacet.export import export
from microfacet.export.gltf import roughness_anisotropy

lt = importlib.import_module("microfacet.export.leadr_textures")   # the package re-exports a function of that name
CI = os.environ.get("CI", "").lower() in ("1", "true", "yes")


def _skip_or_fail(reason):
    if CI:
        pytest.fail(f"{reason} [CI=true: make setup installs three.js/gltf-validator (setup-npm) and chromium]")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def pyramid():
    """An anisotropic, correlated Gaussian bump map (64^2) with a base roughness 0.05."""
    h = mf.leadr.gaussian_heightfield((64, 64), 0.4, 0.15, 0.6, seed=1)
    return mf.leadr.bake(h, roughness=0.05)


def _ellipses(n=2000, seed=0):
    rng = np.random.default_rng(seed)
    a1 = rng.uniform(0.02, 0.95, n)
    a2 = a1 * rng.uniform(0.05, 1.0, n)
    phi = rng.uniform(-np.pi / 2, np.pi / 2, n)
    return a1, a2, phi


def test_covariance_ellipse_round_trip_is_exact():
    """alpha^2 = 2 sigma^2 (Beckmann): covariance -> (alpha1, alpha2, phi) -> covariance to 1e-12."""
    a1, a2, phi = _ellipses()
    vx, vy, c = lt.covariance_of_ellipse(a1, a2, phi)
    b1, b2, bphi = lt.ellipse_of_covariance(vx, vy, c)
    back = lt.covariance_of_ellipse(b1, b2, bphi)
    for x, y in zip((vx, vy, c), back):
        assert np.abs(x - y).max() < 1e-12
    assert np.abs(b1 - a1).max() < 1e-9 and np.abs(b2 - a2).max() < 1e-9
    assert np.all(b1 >= b2) and np.all((bphi > -np.pi / 2) & (bphi <= np.pi / 2))
    # the library's own Beckmann conversion (from_moments) has the same convention
    E = mf.leadr.to_moments(0.3, 0.1, 0.5)
    d = mf.leadr.from_moments(E)
    vx, vy, c = mf.leadr.covariance(E)
    assert np.isclose(2 * vx, float(d.alpha_x) ** 2) and np.isclose(2 * vy, float(d.alpha_y) ** 2)


def test_gltf_parameters_match_the_sphere_export_and_khr_formula():
    a1, a2, _ = _ellipses(200)
    r, s, clipped = lt.gltf_parameters(a1, a2)
    for i in range(0, 200, 17):
        rr, ss, _ = roughness_anisotropy(a1[i], a2[i])
        assert abs(r[i] - rr) < 1e-12 and abs(s[i] - ss) < 1e-12
    at, ab = r**2 + s**2 * (1 - r**2), r**2                      # KHR_materials_anisotropy / three.js
    assert np.abs(at - a1).max() < 1e-12 and np.abs(ab - a2).max() < 1e-12
    assert not clipped.any()
    r, s, clipped = lt.gltf_parameters(np.array([1.4]), np.array([0.2]))
    assert clipped[0] and abs(r[0] ** 2 + s[0] ** 2 * (1 - r[0] ** 2) - 1.0) < 1e-12


def test_texture_round_trip_within_8_bit_quantization():
    """Encode -> decode: exact parameters are recovered to the half step of each 8-bit channel."""
    a1, a2, phi = _ellipses(4096, seed=3)
    vx, vy, c = lt.covariance_of_ellipse(a1, a2, phi)
    slopes = np.random.default_rng(4).normal(0, 0.2, (4096, 2))
    E = np.stack([slopes[:, 0], slopes[:, 1], vx + slopes[:, 0] ** 2, vy + slopes[:, 1] ** 2,
                  c + slopes[:, 0] * slopes[:, 1]], -1).reshape(64, 64, 5)
    p = lt.level_parameters(E)
    assert np.abs(p["alpha1"].ravel() - a1).max() < 1e-9 and np.abs(p["alpha2"].ravel() - a2).max() < 1e-9
    images = lt.encode_level(p)
    d = lt.decode_level(images)
    half = 0.5 / 255
    assert np.abs(d["roughness"] - p["roughness"]).max() <= half + 1e-12
    assert np.abs(d["strength"] - p["strength"]).max() <= half + 1e-12
    dr = 2 * p["roughness"] * half + half**2                     # alpha_b = r^2
    assert np.all(np.abs(d["alpha_b"] - p["alpha2"]) <= dr + 1e-12)
    visible = p["strength"] > 0.1                                # the direction matters where the lobe is elongated
    dphi = np.abs(np.angle(np.exp(2j * (d["phi"] - p["phi"]))) / 2)
    assert dphi[visible].max() < 2.5 / 127.5                      # a step of RG in [-1, 1]
    assert np.abs(d["slopes"] - p["slopes"]).max() < 0.03          # a few 8-bit steps of the normal
    q = lt.quantization_error(p, images)
    assert 0 < q["covariance_mean"] < 0.02 and q["clipped"] == 0.0
    again = lt.encode_level(p)
    assert all(np.array_equal(again[k], images[k]) for k in lt.TEXTURES)


def test_pyramid_textures_follow_the_moments(pyramid):
    levels, params = lt.leadr_textures(pyramid, with_parameters=True)
    assert len(levels) == len(pyramid) == 7
    assert [lv["normal"].shape[:2] for lv in levels] == [E.shape[:2] for E in pyramid]
    assert np.all(levels[0]["anisotropy"][..., 2] == 0)           # single facets + isotropic base
    assert np.allclose(params[0]["alpha1"], 0.05, atol=1e-4)
    assert params[-1]["alpha1"].mean() > 0.4                      # the bumps become roughness
    top = params[-1]
    vx, vy, c = mf.leadr.covariance(np.asarray(pyramid[-1], np.float64))
    assert np.allclose(lt.covariance_of_ellipse(top["alpha1"], top["alpha2"], top["phi"]), (vx, vy, c), atol=1e-7)
    with_base = lt.level_parameters(pyramid[-1], base_roughness=0.2)
    assert np.allclose(with_base["vx"], vx + 0.02, atol=1e-7)    # alpha^2 / 2 added
    naive = lt.naive_textures(levels[0])
    base_r = levels[0]["metallic_roughness"][0, 0, 1]
    assert len(naive) == 7 and np.all(naive[-1]["metallic_roughness"][..., 1] == base_r)


def test_export_writes_chains_glb_and_report(pyramid, tmp_path):
    rep = export(pyramid, "textures", tmp_path / "tex")
    assert [p.name for p in sorted((tmp_path / "tex" / "normal").iterdir())] == [f"level_{k:02d}.png" for k in range(7)]
    back = lt.read_chains(tmp_path / "tex")
    assert np.array_equal(back[3]["anisotropy"], lt.leadr_textures(pyramid)[3]["anisotropy"])
    md = (tmp_path / "tex.export.md").read_text()
    assert "Not carried" in md and "Beckmann" in md and "| 6 | 1x1 |" in md
    rep = export(pyramid, "gltf", tmp_path / "plane")
    assert rep["file"].endswith("plane.glb") and (tmp_path / "plane.mips" / "normal" / "level_06.png").is_file()
    assert any("KTX2" in x for x in rep["lost"])
    with pytest.raises(ValueError, match="textures"):
        export(mf.MicrofacetBRDF(mf.GGX(alpha=0.1)), "textures", tmp_path / "x")


def test_glb_passes_the_khronos_validator(pyramid, tmp_path):
    from microfacet.export.threejs import npm_modules, validate_gltf
    if npm_modules(required=False) is None:
        _skip_or_fail("three.js / gltf-validator absent: make setup-npm")
    rep = export(pyramid, "gltf", tmp_path / "plane.glb", tiles=4)
    issues = validate_gltf(rep["file"])["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"][:5]


def test_cli_exports_and_errors_in_one_line(pyramid, tmp_path, capsys):
    exr = mf.leadr.write_pyramid(tmp_path / "p.exr", pyramid)
    assert main(["export", str(exr), "--to", "textures", "-o", str(tmp_path / "maps")]) == 0
    assert (tmp_path / "maps" / "metallic_roughness" / "level_00.png").is_file()
    assert main(["export", str(exr), "--to", "gltf", "-o", f"{tmp_path}/g/"]) == 0
    assert (tmp_path / "g" / "p.glb").is_file()
    (tmp_path / "fit.npz").write_bytes(b"x")
    (tmp_path / "junk.exr").write_bytes(b"junk")
    cases = [([str(exr), "--to", "mtlx"], "--to textures or --to gltf"),
             ([str(tmp_path / "none.exr"), "--to", "gltf"], "no such file"),
             ([str(exr), "--to", "gltf", "--base-roughness", "-1"], "--base-roughness"),
             ([str(tmp_path / "fit.npz"), "--to", "textures"], "takes a LEADR pyramid"),
             ([str(exr), "--to", "gltf", "--model", "ggx"], "--model"),
             ([str(tmp_path / "junk.exr"), "--to", "gltf"], "junk.exr")]
    capsys.readouterr()
    for argv, text in cases:
        assert main(["export", *argv, "-o", str(tmp_path / "e")]) != 0
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and text in err[0], err


@pytest.fixture(scope="module")
def plane_renderer():
    from microfacet.export.threejs import chromium, npm_modules
    if npm_modules(required=False) is None:
        _skip_or_fail("three.js / gltf-validator absent: make setup-npm")
    try:
        import playwright  # noqa: F401
    except ImportError:
        _skip_or_fail("playwright is not installed (pip install playwright)")
    if chromium(required=False) is None:
        _skip_or_fail("no system Chromium (apt-get install chromium)")
    from microfacet.export.leadr_threejs import PlaneRenderer
    with PlaneRenderer() as r:
        yield r


def test_threejs_plane_leadr_mips_beat_naive_mips(pyramid, plane_renderer, tmp_path):
    """The horizon plane in three.js: LEADR MIPs closer to the supersampled reference than naive MIPs."""
    from microfacet.export.leadr_threejs import PlaneView, compare_plane, relative_l1
    view = PlaneView(width=96, height=72)
    res = compare_plane(pyramid, plane_renderer, tmp_path, view=view, supersample=6)
    e = res["errors"]
    print(f"three.js r{res['revision']}: relL1 naive {e['naive']:.3f}, LEADR {e['leadr']:.3f}")
    assert e["leadr"] < 0.75 * e["naive"], e
    # the .glb's own level-0 textures render as the uploaded ones (orientation, channels, colour space)
    glb_own = plane_renderer.render(res["glb"], view, None, mips=False, supersample=2)
    uploaded = plane_renderer.render(res["glb"], view, lt.leadr_textures(pyramid), mips=False, supersample=2)
    assert relative_l1(glb_own, uploaded) < 1e-6


def test_threejs_anisotropy_frame_patch(pyramid, plane_renderer, tmp_path):
    """With the patched frame, an anisotropy map of strength 0 renders as three.js's isotropic lobe;
    stock three.js (geometric tangent frame) does not: its normal map barely moves the lobe."""
    from microfacet.export.leadr_threejs import PlaneRenderer, PlaneView, relative_l1
    levels = lt.leadr_textures(pyramid)
    glb = lt.write_plane_glb(levels[0], tmp_path / "p.glb", tiles=80)
    on, off = PlaneView(width=64, height=48), PlaneView(width=64, height=48, extra={"anisotropy": 0})
    patched = relative_l1(plane_renderer.render(glb, on, levels, mips=False, supersample=2),
                          plane_renderer.render(glb, off, levels, mips=False, supersample=2))

    def stock_error():                       # one sync Playwright per thread: the stock page in its own
        with PlaneRenderer(mapped_frame=False) as stock:
            return relative_l1(stock.render(glb, on, levels, mips=False, supersample=2),
                               stock.render(glb, off, levels, mips=False, supersample=2))
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        unpatched = pool.submit(stock_error).result()
    print(f"extension on vs off: patched {patched:.2e}, stock three.js {unpatched:.3f}")
    assert patched < 1e-3 and unpatched > 0.1
