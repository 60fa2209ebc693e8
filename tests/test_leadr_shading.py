"""LEADR shading (supplemental Sec. 1.4-3.7), the Ch. 5 downsampling operator, Smith
masking on ray-cast Gaussian heightfields (5b) and LEADR vs. naive MIP (5c)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

import microfacet as mf
from microfacet.geometry import spherical_to_cartesian
from microfacet.leadr import downsample as ds
from microfacet.leadr import figures, shading
from microfacet.leadr.heightfield import gaussian_heightfield
from microfacet.leadr.maps import bake, slopes_to_moments
from microfacet.leadr.mip import mip_pyramid
from microfacet.leadr.moments import from_moments, to_moments
from microfacet.render.lights import latlong_directions, procedural_sky

ROOT = Path(__file__).resolve().parents[1]


def _validation():
    """The experiment module (ray caster of 5b, scenes of 5c)."""
    spec = importlib.util.spec_from_file_location("leadr_validation", ROOT / "experiments" / "leadr_validation.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _upper(rng, n):
    v = rng.normal(size=(n, 3))
    v[:, 2] = np.abs(v[:, 2])
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _random_moments(rng, n):
    return to_moments(rng.uniform(0.05, 0.9, n), rng.uniform(0.05, 0.9, n), rng.uniform(-0.9, 0.9, n),
                      rng.uniform(-0.5, 0.5, (n, 2)))


# ------------------------------------------------------------------ point light
@pytest.mark.parametrize("shadowing", [True, False])
def test_point_light_is_microfacet_brdf_of_the_moments(shadowing):
    rng = np.random.default_rng(0)
    E = _random_moments(rng, 4000)
    wi, wo = _upper(rng, 4000), _upper(rng, 4000)
    f = mf.fresnel.Conductor.metal("Au")
    ours = shading.point_light(E, wi, wo, irradiance=2.0, fresnel=f, shadowing=shadowing)
    brdf = mf.MicrofacetBRDF(mf.Beckmann.from_moments(*E.T), f, shadowing=shadowing)
    ref = 2.0 * brdf.eval_cos(wi, wo)
    assert np.count_nonzero(ref) > 1000
    np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-300)


def test_point_light_formula_terms():
    """I = E F D / (4 c_o (1 + Lambda_o + Lambda_i)) with c_o the mesonormal's projected area."""
    E = to_moments(0.3, 0.5, 0.4, (0.2, -0.1))
    d = mf.Beckmann(alpha_x=0.3, alpha_y=0.5, rho=0.4, mean_slope=(0.2, -0.1))
    wi, wo = spherical_to_cartesian(0.7, 0.3), spherical_to_cartesian(0.4, 2.5)
    h = (wi + wo) / np.linalg.norm(wi + wo)
    c_o = wo @ np.array([-0.2, 0.1, 1.0])
    expect = d.ndf(h) / (4 * c_o * (1 + d.lambda_(wo) + d.lambda_(wi)))
    assert shading.point_light(E, wi, wo)[0] == pytest.approx(expect, rel=1e-12)
    np.testing.assert_allclose(shading.lambda_(E, np.stack([wi, wo])), d.lambda_(np.stack([wi, wo])), rtol=1e-12)
    assert shading.lambda_(E, np.array([0.0, 0.0, 1.0])) == 0.0
    k = np.stack([wi, wo, spherical_to_cartesian(1.4, 0.1)])
    np.testing.assert_allclose(shading.projected_area(E, k), d.projected_area(k), rtol=1e-12)


def test_point_light_zero_below_horizon_and_behind_mesonormal():
    E = to_moments(0.2, 0.2, 0.0, (2.0, 0.0))            # mesonormal tilted far toward -x
    wo = spherical_to_cartesian(1.2, 0.0)                  # c_o = cos - sin * 2 < 0
    wi = spherical_to_cartesian(0.3, np.pi)
    assert np.all(shading.point_light(E, wi, wo) == 0)
    assert np.all(shading.point_light(E, -wi, spherical_to_cartesian(0.3, 0)) == 0)


# ------------------------------------------------------------------ sample grid
@pytest.mark.parametrize("n", [1, 3, 5, 8, 32])
def test_sample_grid_weights_sum_to_one(n):
    p, w = shading.sample_grid(n)
    assert w.sum() == pytest.approx(1.0, abs=1e-15)
    assert p.shape == w.shape == (n,)
    np.testing.assert_allclose(p, -p[::-1], atol=1e-15)
    assert np.all(np.abs(p) <= 3.0 + 1e-12)
    x, y, W = shading.grid_slopes(to_moments(0.3, 0.6, 0.5, (0.1, 0.2)), n)
    np.testing.assert_allclose(W.sum(axis=-1), 1.0, atol=1e-14)


def test_sample_grid_matches_supplemental_5x5():
    p, w = shading.sample_grid(5)
    np.testing.assert_allclose(p, [-1.8, -0.9, 0.0, 0.9, 1.8], atol=1e-15)
    np.testing.assert_allclose(w, [0.0725, 0.2443, 0.3663, 0.2443, 0.0725], atol=1e-4)
    assert shading.lod_bias(5) == 0.5 and shading.lod_bias(32) == -0.5 and shading.lod_bias(128) == -1.48


def test_grid_slopes_reproduce_moments():
    """The grid is a quadrature of the Gaussian: weighted means are exact, covariances
    are those of the standard normal truncated to the grid (within 3% at +-3 sigma)."""
    E = to_moments(0.4, 0.2, -0.6, (0.3, -0.1))
    for n in (5, 64):
        x, y, W = shading.grid_slopes(E, n)
        np.testing.assert_allclose([np.sum(W * x), np.sum(W * y)], E[:2], atol=1e-15)
        p, w = shading.sample_grid(n)
        shrink = np.sum(w * p * p)                      # variance of the 1-D grid
        cov = [np.sum(W * (x - E[0]) ** 2), np.sum(W * (y - E[1]) ** 2), np.sum(W * (x - E[0]) * (y - E[1]))]
        np.testing.assert_allclose(cov, shrink * np.array([0.08, 0.02, -0.6 * 0.4 * 0.2 / 2]), rtol=1e-12)
        assert 0.97 < shrink <= 1.0 or n == 5


# ------------------------------------------------------------------ environment
def test_env_constant_environment_gives_albedo():
    rng = np.random.default_rng(1)
    E = _random_moments(rng, 300)
    wo = _upper(rng, 300)
    env = shading.MipEnvironment(np.full((32, 64, 3), 1.7))
    np.testing.assert_allclose(shading.env_specular(E, wo, env), 1.7, rtol=1e-13)
    f = mf.fresnel.Schlick(0.3)
    got = shading.env_specular(E, wo, env, fresnel=f)
    # the albedo of the grid: weighted mean of F(<n_k, o>) over the visible grid normals
    normals, w, vn, zn = shading._grid_normals(E, wo, 5, True)
    a = w * vn / zn
    albedo = (a[..., None] * f(vn)).sum(-2) / a.sum(-1)[..., None]
    np.testing.assert_allclose(got, 1.7 * albedo, rtol=1e-12)
    assert np.all((got > 1.7 * 0.3) & (got < 1.7))


def test_env_mip_levels_preserve_integral_and_trilinear_lookup():
    env = shading.MipEnvironment(procedural_sky(32, 64))
    assert [lv.map.shape[:2] for lv in env.levels] == [(32, 64), (16, 32), (8, 16), (4, 8), (2, 4), (1, 2)]

    def integral(m):
        h, w = m.shape[:2]
        edges = np.cos(np.arange(h + 1) / h * np.pi)
        return np.einsum("ijc,i->c", m, edges[:-1] - edges[1:]) * 2 * np.pi / w
    for lv in env.levels:
        np.testing.assert_allclose(integral(lv.map), integral(env.map), rtol=1e-12)
    w = latlong_directions(8, 16).reshape(-1, 3)
    np.testing.assert_allclose(env.radiance_lod(w, 0.0), env.radiance(w), rtol=1e-14)
    lo, hi = env.levels[1].radiance(w), env.levels[2].radiance(w)
    np.testing.assert_allclose(env.radiance_lod(w, 1.25), 0.75 * lo + 0.25 * hi, rtol=1e-13)
    np.testing.assert_allclose(env.radiance_lod(w, 99.0), env.levels[-1].radiance(w), rtol=1e-13)


def test_env_grid_matches_monte_carlo_reference():
    """Masking-only BRDF under a smooth environment: the 16 x 16 grid with unfiltered
    lookups against Monte Carlo importance sampling of the same BRDF (views near the
    normal and moderate roughness, so reflections below the horizon are negligible)."""
    w = latlong_directions(64, 128)
    bump = np.exp(-8 * np.sum((w - [0.3, 0.2, 0.93]) ** 2, -1))[..., None]
    sky = 1.0 + 0.8 * w[..., 2:3] + 0.5 * w[..., 0:1] * w[..., 1:2] + bump
    env = shading.MipEnvironment(sky * [1.0, 0.8, 0.6])
    E = to_moments(np.array([0.1, 0.2]), np.array([0.15, 0.1]), np.array([0.3, -0.2]),
                   np.array([[0.05, 0.0], [0.0, -0.05]]))
    wo = np.array([spherical_to_cartesian(0.2, 0.5), spherical_to_cartesian(0.3, 2.0)])
    grid = shading.env_specular(E, wo, env, n=16, lod_offset=-40.0)
    brdf = mf.MicrofacetBRDF(from_moments(E[:, None]), shadowing=False)
    frame = (np.tile([1.0, 0, 0], (2, 1)), np.tile([0, 1.0, 0], (2, 1)), np.tile([0, 0, 1.0], (2, 1)))
    mc = mf.render.shade_environment(brdf, wo, frame, env, 4096, np.random.default_rng(3))
    np.testing.assert_allclose(grid, mc, rtol=0.01)


def test_artificial_micronormal_keeps_results_defined():
    env = shading.MipEnvironment(procedural_sky(16, 32))
    E = to_moments(0.1, 0.1, 0.0, (3.0, 0.0))             # mesonormal faces away from wo
    wo = spherical_to_cartesian(1.2, 0.0)
    assert np.all(shading.env_specular(E, wo, env, fallback=False) == 0)     # undefined: S = 0
    got = shading.env_specular(E, wo, env)
    assert np.all(np.isfinite(got)) and np.all(got > 0)
    m = shading.mesonormal(E)
    n = shading.artificial_micronormal(E, wo)
    assert m @ wo < 0 < n @ wo
    # where the grid is visible, the artificial normal's weight 1e-5 is negligible
    rng = np.random.default_rng(2)
    Er, wr = _random_moments(rng, 200), _upper(rng, 200)
    wr[:, 2] += 0.5
    wr /= np.linalg.norm(wr, axis=1, keepdims=True)
    a, b = shading.env_specular(Er, wr, env), shading.env_specular(Er, wr, env, fallback=False)
    np.testing.assert_allclose(a, b, rtol=1e-3)
    d = shading.diffuse_directional(E, wo, spherical_to_cartesian(0.2, np.pi))
    assert np.all(np.isfinite(d))


# ------------------------------------------------------------------ SH irradiance
def test_sh_irradiance_of_constant_and_linear_environments():
    rng = np.random.default_rng(4)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    c = shading.sh_project(np.full((16, 32, 3), 1.5))
    np.testing.assert_allclose(shading.sh_irradiance(c, n), 1.5 * np.pi, rtol=1e-12)
    a, b = np.array([1.0, 2.0, 3.0]), np.array([[0.3, -0.2, 0.5], [0.1, 0.4, -0.2], [0.2, 0.1, 0.3]])
    w = latlong_directions(128, 256)
    c = shading.sh_project(a + np.einsum("ijk,kc->ijc", w, b))
    # E(n) = pi a + 2 pi / 3 b.n (the texel-constant map is exact up to O(1/H^2))
    np.testing.assert_allclose(shading.sh_irradiance(c, n), np.pi * a + 2 * np.pi / 3 * (n @ b), rtol=2e-5)


def test_sh_directional_light_is_its_order_2_irradiance():
    d = np.array([0.3, 0.8, -0.2])
    c = shading.sh_add_directional(np.zeros((9, 3)), d, (1.0, 2.0, 3.0))
    d = d / np.linalg.norm(d)
    # a Dirac projects to Y_lm(d) L; its irradiance is sum_lm A_l Y_lm(n) Y_lm(d) L
    y = shading.sh_basis(d)
    A = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)
    np.testing.assert_allclose(shading.sh_irradiance(c, d), (A * y * y).sum() * np.array([1.0, 2.0, 3.0]), rtol=1e-12)


def test_diffuse_constant_environment_and_flat_surface():
    rng = np.random.default_rng(5)
    E = _random_moments(rng, 100)
    wo = _upper(rng, 100)
    c = shading.sh_project(np.full((8, 16, 3), 2.0))
    np.testing.assert_allclose(shading.diffuse_sh(E, wo, c, albedo=0.4), 0.8, rtol=1e-12)
    # a nearly flat surface under one light is Lambertian
    flat = to_moments(1e-4, 1e-4)
    wi = spherical_to_cartesian(0.6, 1.0)
    got = shading.diffuse_directional(flat, wo, wi, irradiance=3.0, albedo=0.5)
    np.testing.assert_allclose(got, 3.0 * 0.5 / np.pi * wi[2], rtol=1e-3)
    # the same through SH: the light's order-2 irradiance at the flat normal
    c1 = shading.sh_add_directional(np.zeros((9, 3)), wi, 3.0)
    got = shading.diffuse_sh(flat, wo, c1, albedo=0.5)
    expect = 0.5 / np.pi * shading.sh_irradiance(c1, np.array([0, 0, 1.0]))
    np.testing.assert_allclose(got, np.broadcast_to(expect, got.shape), rtol=1e-3)


# ------------------------------------------------------------------ downsampling
def test_downsampling_adds_moments_exactly():
    a = dict(alpha_x=0.3, alpha_y=0.2, rho=0.4, mean_slope=(0.1, -0.2))
    b = dict(alpha_x=0.1, alpha_y=0.25, rho=-0.3, mean_slope=(0.05, 0.3))
    Ea, Eb = to_moments(**a), to_moments(**b)
    merged = ds.downsample_operator([Ea[None, None]], mf.Beckmann(**b))[0][0, 0]
    # covariances and means add (independent slopes: convolution of the PDFs)
    cov = lambda p: np.array([[p["alpha_x"] ** 2, p["rho"] * p["alpha_x"] * p["alpha_y"]],  # noqa: E731
                              [p["rho"] * p["alpha_x"] * p["alpha_y"], p["alpha_y"] ** 2]]) / 2
    c = cov(a) + cov(b)
    m = np.add(a["mean_slope"], b["mean_slope"])
    expect = [m[0], m[1], c[0, 0] + m[0] ** 2, c[1, 1] + m[1] ** 2, c[0, 1] + m[0] * m[1]]
    np.testing.assert_allclose(merged, expect, rtol=1e-14)
    # and sample moments of sums of independent samples converge to it
    rng = np.random.default_rng(6)
    sa = rng.multivariate_normal(a["mean_slope"], cov(a), 400_000)
    sb = rng.multivariate_normal(b["mean_slope"], cov(b), 400_000)
    s = sa + sb
    got = [s[:, 0].mean(), s[:, 1].mean(), (s[:, 0] ** 2).mean(), (s[:, 1] ** 2).mean(), (s[:, 0] * s[:, 1]).mean()]
    np.testing.assert_allclose(got, expect, atol=3e-3)


def test_downsampling_commutes_with_mip_and_accepts_materials():
    h = gaussian_heightfield((32, 32), 0.4, 0.2, 0.3, correlation=3.0, seed=1)
    base = mf.MicrofacetBRDF(mf.Beckmann(alpha_x=0.1, alpha_y=0.2, rho=0.5), mf.fresnel.Schlick(0.9))
    merged = ds.downsample_operator(bake(h), base)
    direct = bake(h, roughness=base)
    for a, b in zip(merged, direct, strict=True):
        np.testing.assert_allclose(a, b, rtol=2e-6, atol=2e-7)
    level0 = slopes_to_moments(np.random.default_rng(2).normal(size=(16, 16, 2)))
    merged_first = mip_pyramid(ds.downsample_operator([level0], 0.3)[0])
    for a, b in zip(merged_first, ds.downsample_operator(mip_pyramid(level0), 0.3), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(ds.base_lobe(0.3), to_moments(0.3, 0.3))
    np.testing.assert_allclose(ds.base_lobe(None), 0.0)

    class Fit:                                              # anything with to_beckmann()
        def to_beckmann(self):
            return base
    np.testing.assert_allclose(ds.base_lobe(Fit()), to_moments(0.1, 0.2, 0.5))
    surface = ds.FilteredSurface(bake(h), Fit())
    assert surface.fresnel is base.fresnel
    brdf = surface.brdf(np.array([[0.25, 0.5], [0.7, 0.1]]), 1 / 8)
    assert brdf.distribution.alpha_x.shape == (2,) and np.all(brdf.distribution.alpha_x >= 0.1)
    with pytest.raises(ValueError):
        ds.box_average(np.zeros((6, 6)), 4)


def test_naive_mip_averages_normals():
    s = np.array([[[0.5, 0.0], [-0.5, 0.0]], [[0.0, 0.5], [0.0, -0.5]]])
    got = ds.naive_slopes(slopes_to_moments(s), 2)
    np.testing.assert_allclose(got, 0.0, atol=1e-15)
    pyr = ds.naive_pyramid(slopes_to_moments(s), base=0.1)
    assert len(pyr) == 2
    np.testing.assert_allclose(pyr[1][0, 0], to_moments(0.1, 0.1), atol=1e-15)   # the spread is lost


# ------------------------------------------------------------------ 5b, 5c (small)
def test_smith_masking_of_raycast_gaussian_heightfield():
    """5b: G1 predicted from the surface's moments against the ray-cast visible fraction."""
    V = _validation()
    Z = V.masking_field(256, 0.7, 0.4, 0.4, 4.0, seed=11)
    rng = np.random.default_rng(12)
    for mean_slope in ((0.0, 0.0), (0.25, -0.15)):
        E = V.bilinear_moments(Z, mean_slope)
        for theta, phi in ((60, 30), (70, 200)):
            k = spherical_to_cartesian(np.radians(theta), np.radians(phi))
            g, se = V.visible_fraction(Z, k, 20_000, rng, mean_slope)
            pred = V.predicted_masking(E, k)
            assert 0 < se < 0.01
            assert abs(pred - g) < 4 * se + 2e-3, (mean_slope, theta, phi, g, pred, se)
    # and the fraction visibly drops toward grazing as Smith predicts
    k = spherical_to_cartesian(np.radians(85), 0.0)
    g, se = V.visible_fraction(Z, k, 20_000, rng)
    assert g < 0.7 and abs(V.predicted_masking(V.bilinear_moments(Z), k) - g) < 0.03


def test_bilinear_moments_of_a_plane_and_a_ramp():
    V = _validation()
    Z = np.zeros((8, 8))
    np.testing.assert_allclose(V.bilinear_moments(Z, (0.3, -0.1)), to_moments(0, 0, 0, (0.3, -0.1)), atol=1e-15)
    Z = np.tile(np.array([0.0, 1.0] * 4), (8, 1))          # zig-zag along x: slopes +-1
    np.testing.assert_allclose(V.bilinear_moments(Z), [0, 0, 1, 0, 0], atol=1e-15)


def test_leadr_beats_naive_mip_against_supersampling():
    """5c: at coarse MIP levels LEADR is much closer to the supersampled reference."""
    V = _validation()
    h = gaussian_heightfield((64, 64), 0.5, 0.3, 0.3, correlation=3.0, seed=7)
    for cfg, kinds in (((30, 180, 34, 0), ("point",)), (V.ENV_CONFIG, ("env",))):
        images, errors = figures.compare_levels(h, 0.1, levels=(2, 4), scene=V.orthographic_scene(*cfg), kinds=kinds)
        for key, e in errors.items():
            assert e["leadr"] < 0.6 * e["naive"], (key, e)
            ref = images[key]["reference"]
            assert abs(images[key]["leadr"].mean() / ref.mean() - 1) < 0.3


def test_leadr_demo_section_writes_images_and_errors(tmp_path):
    html = figures.leadr_section(tmp_path, size=32, levels=(1, 2), display=32)
    for kind in ("point", "env"):
        for method in figures.METHODS:
            for level in (1, 2):
                assert (tmp_path / "leadr" / f"{kind}_{method}_level{level}.png").is_file()
                assert (tmp_path / "leadr" / f"{kind}_{method}_level{level}.exr").is_file()
    assert html.startswith('<section id="leadr">') and html.count("error") >= 8
