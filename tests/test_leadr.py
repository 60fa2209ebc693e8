"""LEAN/LEADR: moments, maps, MIP pyramids, lookups, files and ``microfacet bake``."""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import microfacet as mf
from microfacet import leadr
from microfacet.cli import main
from microfacet.errors import MicrofacetError
from microfacet.io import write_exr
from microfacet.io.exr import COMPRESSIONS
from microfacet.io.png import read_png_data, write_png_data
from microfacet.leadr.files import load_height_map, load_normal_map
from microfacet.leadr.heightfield import slope_spectrum

PARAMS = [(0.3, 0.3, 0.0, (0.0, 0.0)), (0.5, 0.1, 0.0, (0.2, -0.1)),
          (0.2, 0.4, 0.7, (-0.3, 0.5)), (0.05, 0.6, -0.9, (1.0, 0.0))]


def sample_moments(s):
    """Moments (5,) of slope samples (N, 2)."""
    x, y = s[:, 0], s[:, 1]
    return np.array([x.mean(), y.mean(), (x * x).mean(), (y * y).mean(), (x * y).mean()])


# ------------------------------------------------------------------------- moments
@pytest.mark.parametrize("ax, ay, rho, mean", PARAMS)
def test_moments_match_quadrature_of_the_beckmann_pdf(ax, ay, rho, mean):
    d = mf.Beckmann(alpha_x=ax, alpha_y=ay, rho=rho, mean_slope=mean)
    E = leadr.to_moments(ax, ay, rho, mean)
    # independent: integrate P22 on a slope grid covering +-9 standard deviations
    n = 1201
    x = mean[0] + np.linspace(-9, 9, n) * ax / np.sqrt(2)
    y = mean[1] + np.linspace(-9, 9, n) * ay / np.sqrt(2)
    X, Y = np.meshgrid(x, y, indexing="ij")
    w = d.p22(X, Y) * (x[1] - x[0]) * (y[1] - y[0])
    quad = [np.sum(w * f) for f in (X, Y, X * X, Y * Y, X * Y)]
    assert np.sum(w) == pytest.approx(1.0, abs=1e-9)
    np.testing.assert_allclose(E, quad, atol=1e-9)
    np.testing.assert_allclose(E, np.stack(d.moments()), rtol=1e-14, atol=1e-15)


def test_moments_round_trip_arrays():
    rng = np.random.default_rng(1)
    ax, ay = rng.uniform(0.01, 1.5, (2, 50))
    rho, ms = rng.uniform(-0.95, 0.95, 50), rng.normal(0, 0.5, (50, 2))
    b = leadr.from_moments(leadr.to_moments(ax, ay, rho, ms))
    assert isinstance(b, mf.Beckmann)
    np.testing.assert_allclose(b.alpha_x, ax, rtol=1e-10)
    np.testing.assert_allclose(b.alpha_y, ay, rtol=1e-10)
    np.testing.assert_allclose(b.rho, rho, atol=1e-10)
    np.testing.assert_allclose(b.mean_slope, ms, atol=1e-14)


def test_from_moments_clamps_degenerate_texels():
    single = np.array([0.3, -0.2, 0.09, 0.04, -0.06])            # one facet: zero variance
    rounding = np.array([0.3, -0.2, 0.09 - 1e-9, 0.04, -0.06])   # negative by rounding
    correlated = leadr.to_moments(0.2, 0.2, 1.0)                  # |rho| = 1
    b = leadr.from_moments(np.stack([single, rounding, correlated]))
    assert np.all(b.alpha_x >= leadr.moments.MIN_ALPHA) and np.all(b.alpha_y >= leadr.moments.MIN_ALPHA)
    assert np.all(np.abs(b.rho) <= 0.99)
    np.testing.assert_allclose(b.mean_slope[0], [0.3, -0.2])
    assert np.all(np.isfinite(b.ndf(np.array([0.0, 0.0, 1.0]))))
    with pytest.raises(ValueError, match="finite"):
        leadr.from_moments([np.nan, 0, 1, 1, 0])
    with pytest.raises(ValueError, match="size 5"):
        leadr.from_moments(np.zeros(4))


def test_convolution_is_moment_of_sums_of_independent_slopes():
    rng = np.random.default_rng(2)
    a = rng.normal([0.2, -0.1], [0.3, 0.1], (40, 2)) @ np.array([[1, 0.5], [0, 1]])
    b = rng.normal([-0.5, 0.3], [0.05, 0.4], (30, 2))
    sums = (a[:, None, :] + b[None, :, :]).reshape(-1, 2)      # the product measure, exactly
    np.testing.assert_allclose(leadr.convolve(sample_moments(a), sample_moments(b)),
                               sample_moments(sums), rtol=1e-12, atol=1e-14)
    # two Beckmann lobes: covariances and means add
    Ea, Eb = leadr.to_moments(0.3, 0.1, 0.5, (0.1, 0.2)), leadr.to_moments(0.2, 0.4, -0.3, (-0.3, 0.1))
    va, vb, vc = (np.array(leadr.covariance(E)) for E in (Ea, Eb, leadr.convolve(Ea, Eb)))
    np.testing.assert_allclose(vc, va + vb, rtol=1e-12)
    np.testing.assert_allclose(leadr.convolve(Ea, Eb)[:2], Ea[:2] + Eb[:2])


def test_height_scaling_scales_moments_by_beta_and_beta_squared():
    xi = leadr.gaussian_heightfield((32, 48), 0.3, 0.2, 0.4, seed=3)
    base = leadr.bake(xi)
    for beta in (0.0, 0.5, 3.0):
        scaled = leadr.bake(xi, scale=beta)
        for k in (0, 2, len(base) - 1):
            np.testing.assert_allclose(leadr.scale_height(base[k], beta), scaled[k], rtol=2e-6, atol=1e-7)
    np.testing.assert_allclose(leadr.scale_height([1, 2, 3, 4, 5], 2.0), [2, 4, 12, 16, 20])


@pytest.mark.parametrize("J", [[[2.0, 0.0], [0.0, 0.5]],          # stretching
                               [[1.0, 0.7], [0.0, 1.0]],          # shearing
                               [[0.8, -0.6], [0.6, 0.8]]])        # rotation
def test_stretching_and_shearing_against_a_transformed_surface(J):
    J = np.array(J)   # [[du/dx, dv/dx], [du/dy, dv/dy]]

    def xi(u, v):
        return 0.05 * np.sin(2 * np.pi * (3 * u + v)) + 0.03 * np.cos(2 * np.pi * (u - 4 * v)) + 0.1 * u * v

    rng = np.random.default_rng(4)
    x, y = rng.uniform(0, 1, (2, 2000))
    uv_of = lambda x, y: (J[0, 0] * x + J[1, 0] * y, J[0, 1] * x + J[1, 1] * y)  # noqa: E731
    h = 1e-5  # brute force: differentiate the world-space surface xi(u(x, y), v(x, y))
    world = np.stack([(xi(*uv_of(x + h, y)) - xi(*uv_of(x - h, y))) / (2 * h),
                      (xi(*uv_of(x, y + h)) - xi(*uv_of(x, y - h))) / (2 * h)], -1)
    u, v = uv_of(x, y)
    uvs = np.stack([(xi(u + h, v) - xi(u - h, v)) / (2 * h), (xi(u, v + h) - xi(u, v - h)) / (2 * h)], -1)
    np.testing.assert_allclose(leadr.transform(sample_moments(uvs), J), sample_moments(world),
                               rtol=1e-7, atol=1e-9)


def test_clean_maps():
    E = leadr.to_moments(0.5, 0.1, 0.6, (0.2, -0.3))
    iso = leadr.from_moments(leadr.clean_to_moments(leadr.clean_moments(E)))
    # Eq. 3.18: alpha^2 = E3 + E4 - E1^2 - E2^2 = (alpha_x^2 + alpha_y^2) / 2, rho = 0, mean kept
    assert iso.alpha_x == pytest.approx(np.sqrt((0.25 + 0.01) / 2)) and iso.alpha_y == iso.alpha_x
    assert iso.rho == 0 and np.allclose(iso.mean_slope, (0.2, -0.3))
    a1, a2, _ = mf.Beckmann(alpha_x=0.5, alpha_y=0.1, rho=0.6).ellipse
    wide = leadr.from_moments(leadr.clean_to_moments(leadr.clean_moments(E, mode="max")))
    assert wide.alpha_x == pytest.approx(a1, rel=1e-12) and a1 > max(0.5, 0.1)
    iso_E = leadr.to_moments(0.3, 0.3, 0.0, (0.1, 0.1))       # isotropic lobes round-trip exactly
    np.testing.assert_allclose(leadr.clean_to_moments(leadr.clean_moments(iso_E)), iso_E, atol=1e-15)
    with pytest.raises(ValueError, match="mode"):
        leadr.clean_moments(E, mode="min")


def test_clean_vs_lean_on_an_anisotropic_map():
    """5d: CLEAN filters linearly like LEAN (same mean and total variance at every level)
    but loses the anisotropy; the max(alpha1, alpha2) option covers the widest axis."""
    xi = leadr.gaussian_heightfield((128, 128), 0.5, 0.1, 0.0, seed=5)
    lean = leadr.bake(xi)
    clean = leadr.mip_pyramid(leadr.clean_moments(lean[0]))      # filter the CLEAN map itself
    for k in (1, 3, len(lean) - 1):
        np.testing.assert_allclose(clean[k], leadr.clean_moments(lean[k]), rtol=1e-5, atol=1e-7)
    top_lean = leadr.from_moments(lean[-1][0, 0])
    top_clean = leadr.from_moments(leadr.clean_to_moments(clean[-1][0, 0]))
    assert top_lean.alpha_x / top_lean.alpha_y > 3.5              # anisotropic map ...
    assert top_clean.alpha_x == top_clean.alpha_y                  # ... CLEAN is isotropic
    assert top_clean.alpha_x**2 == pytest.approx((top_lean.alpha_x**2 + top_lean.alpha_y**2) / 2, rel=1e-5)
    top_max = leadr.from_moments(leadr.clean_to_moments(leadr.clean_moments(lean[-1][0, 0], mode="max")))
    assert top_max.alpha_x == pytest.approx(float(top_lean.ellipse[0]), rel=1e-5)


# ------------------------------------------------------------------------- maps
@pytest.mark.parametrize("shape", [(64, 64), (48, 80)])
def test_slopes_of_a_sinusoid_match_its_derivative(shape):
    H, W = shape
    fu, fv, amp, scale = 3, 2, 0.01, 1.7
    u = (np.arange(W) + 0.5) / W
    v_up = 1.0 - (np.arange(H) + 0.5) / H                  # y points to the top row
    U, V = np.meshgrid(u, v_up)
    xi = amp * np.sin(2 * np.pi * fu * U) * np.cos(2 * np.pi * fv * V)
    s = leadr.height_to_slopes(xi, scale)
    # exact for central differences of a sinusoid: derivative times sin(k h) / (k h)
    ku, kv = 2 * np.pi * fu, 2 * np.pi * fv
    dxi_du = scale * amp * ku * np.cos(ku * U) * np.cos(kv * V)
    dxi_dv = -scale * amp * kv * np.sin(ku * U) * np.sin(kv * V)
    np.testing.assert_allclose(s[..., 0], dxi_du * np.sin(ku / W) / (ku / W), atol=1e-12)
    np.testing.assert_allclose(s[..., 1], dxi_dv * np.sin(kv / H) / (kv / H), atol=1e-12)
    # and the derivative itself up to the O((k h)^2 / 6) truncation error
    np.testing.assert_allclose(s[..., 0], dxi_du, atol=np.max(np.abs(dxi_du)) * (ku / W) ** 2 / 6 * 1.01)


def test_slopes_of_a_plane_and_borders():
    H, W, a, b = 10, 16, 0.3, -0.2
    u = (np.arange(W) + 0.5) / W
    v_up = 1.0 - (np.arange(H) + 0.5) / H
    xi = a * u[None, :] + b * v_up[:, None]
    s = leadr.height_to_slopes(xi, border="clamp")
    np.testing.assert_allclose(s[1:-1, 1:-1], np.broadcast_to([a, b], (H - 2, W - 2, 2)), atol=1e-14)
    np.testing.assert_allclose(s[5, [0, -1], 0], [a / 2, a / 2], atol=1e-14)   # one-sided half difference
    np.testing.assert_allclose(s[[0, -1], 5, 1], [b / 2, b / 2], atol=1e-14)
    wrap = leadr.height_to_slopes(xi, border="wrap")
    assert np.allclose(wrap[:, 0, 0], W * (xi[:, 1] - xi[:, -1]) / 2)
    with pytest.raises(ValueError, match="border"):
        leadr.height_to_slopes(xi, border="mirror")
    with pytest.raises(ValueError, match="finite"):
        leadr.bake(np.full((4, 4), np.nan))


def test_compiled_bake_matches_the_numpy_reference():
    rng = np.random.default_rng(6)
    for shape in [(7, 5), (1, 9), (33, 64), (5, 1)]:
        xi = rng.random(shape)
        for border in ("wrap", "clamp"):
            fast = leadr.bake(xi, 2.0, (0.3, 0.1), border=border)
            ref = leadr.bake_reference(xi, 2.0, (0.3, 0.1), border=border)
            assert [f.dtype for f in fast] == [np.float32] * len(ref)
            for f, r in zip(fast, ref):
                np.testing.assert_allclose(f, r, rtol=3e-7, atol=1e-6 * np.abs(r).max())


def test_bake_of_stored_gray_levels_matches_the_heights():
    """``bake(levels, scale / top)`` (``microfacet bake``'s path: no float64 heights) is the bake
    of the heights ``levels / top`` of 8/16-bit gray and RGB images (RGB: the mean of R, G, B)."""
    from microfacet.leadr.files import height_levels
    rng = np.random.default_rng(8)
    for dtype, channels in [(np.uint8, None), (np.uint16, None), (np.uint16, 3), (np.uint8, 4), (np.uint16, 2)]:
        top = np.iinfo(dtype).max
        image = rng.integers(0, top + 1, (17, 12) if channels is None else (17, 12, channels)).astype(dtype)
        levels, divisor = height_levels(image, "x.png")
        heights = (image if channels is None else image[..., :1 if channels < 3 else 3].mean(axis=2)) / top
        np.testing.assert_allclose(levels / divisor, heights, rtol=1e-15, atol=1e-15)
        fast = leadr.bake(levels, 3.0 / divisor, 0.2)
        for f, r in zip(fast, leadr.bake_reference(heights, 3.0, 0.2)):
            np.testing.assert_allclose(f, r, rtol=3e-7, atol=1e-6 * np.abs(r).max())


def test_bake_refuses_moments_that_overflow_float32():
    xi = leadr.gaussian_heightfield((8, 8), 0.3, seed=2)
    for kwargs in ({"scale": 1e30}, {"roughness": 1e25}):
        with pytest.raises(ValueError, match="overflow float32"):
            leadr.bake(xi, **kwargs)


def test_base_roughness_and_material_merge():
    xi = leadr.gaussian_heightfield((32, 32), 0.3, seed=7)
    lobe = mf.Beckmann(alpha_x=0.2, alpha_y=0.1, rho=0.3, mean_slope=(0.05, 0.0))
    merged = leadr.downsample_operator(leadr.bake(xi), mf.MicrofacetBRDF(lobe))
    baked = leadr.bake(xi, roughness=lobe)
    for m, b in zip(merged, baked):
        np.testing.assert_allclose(m, b, rtol=1e-5, atol=1e-7)
    flat = leadr.bake(np.zeros((4, 4)), roughness=0.25)[-1][0, 0]
    assert leadr.from_moments(flat).alpha_x == pytest.approx(0.25, rel=1e-6)
    with pytest.raises(ValueError, match="Beckmann"):
        leadr.bake(xi, roughness=mf.GGX(alpha=0.2))


@pytest.mark.parametrize("dtype, tol", [(np.uint8, 2e-2), (np.uint16, 1e-4), (np.float32, 1e-6)])
def test_normal_map_round_trips(dtype, tol):
    """Quantization of n to 1/255 (1/65535) in [0, 1], i.e. 1/255 in n after rounding's half
    step doubled; |d(n/z)/dn| <= 1/z^3 <= 5.2 for slopes up to 1 per axis: 8-bit errors
    stay below 5.2/255/2 ~ 0.01 per axis, 16-bit ones below 4e-5."""
    rng = np.random.default_rng(8)
    slopes = rng.uniform(-1, 1, (20, 30, 2))
    nmap = leadr.encode_normal_map(slopes, dtype)
    assert nmap.dtype == dtype and nmap.shape == (20, 30, 3)
    assert np.max(np.abs(leadr.decode_normal_map(nmap) - slopes)) < tol
    E = leadr.normal_map_to_moments(nmap, roughness=0.1)
    assert E.dtype == np.float32 and E.shape == (20, 30, 5)
    np.testing.assert_allclose(leadr.covariance(E)[0], 0.005, atol=1e-6)   # alpha^2 / 2 of the base
    np.testing.assert_allclose(leadr.normal_map_to_moments(nmap, scale=2.0),
                               leadr.scale_height(leadr.normal_map_to_moments(nmap), 2.0), rtol=1e-6, atol=1e-7)


def test_normal_maps_through_files(tmp_path):
    rng = np.random.default_rng(9)
    slopes = rng.uniform(-0.8, 0.8, (12, 9, 2))
    for name, dtype, tol in (("n8.png", np.uint8, 2e-2), ("n16.png", np.uint16, 1e-4)):
        leadr.write_normal_map(tmp_path / name, leadr.encode_normal_map(slopes, dtype))
        back = load_normal_map(tmp_path / name)
        assert back.dtype == dtype
        assert np.max(np.abs(leadr.decode_normal_map(back) - slopes)) < tol
    leadr.write_normal_map(tmp_path / "n.exr", leadr.encode_normal_map(slopes, np.float32))
    assert np.max(np.abs(leadr.decode_normal_map(load_normal_map(tmp_path / "n.exr")) - slopes)) < 1e-6


def test_height_maps_from_png_and_exr(tmp_path):
    rng = np.random.default_rng(11)
    h16 = rng.integers(0, 65536, (6, 5)).astype(np.uint16)
    write_png_data(tmp_path / "g16.png", h16)
    np.testing.assert_allclose(load_height_map(tmp_path / "g16.png"), h16 / 65535.0)
    h8 = rng.integers(0, 256, (6, 5)).astype(np.uint8)
    write_png_data(tmp_path / "rgb8.png", np.repeat(h8[..., None], 3, axis=2))
    np.testing.assert_allclose(load_height_map(tmp_path / "rgb8.png"), h8 / 255.0)
    write_png_data(tmp_path / "rgb16.png", np.repeat(h16[..., None], 3, axis=2))
    np.testing.assert_allclose(load_height_map(tmp_path / "rgb16.png"), h16 / 65535.0)
    hf = rng.random((6, 5))
    write_exr(tmp_path / "h.exr", hf)
    np.testing.assert_allclose(load_height_map(tmp_path / "h.exr"), hf.astype(np.float32))
    (tmp_path / "junk.png").write_bytes(b"not an image")
    with pytest.raises(MicrofacetError, match="junk.png: not a PNG or OpenEXR"):
        load_height_map(tmp_path / "junk.png")


def test_a_normal_map_read_as_heights_warns_and_height_maps_do_not(tmp_path, capsys):
    import warnings
    from microfacet.errors import HeightMapWarning
    rng = np.random.default_rng(12)
    slopes = rng.normal(0.0, 0.3, (40, 30, 2))
    leadr.write_normal_map(tmp_path / "n.png", leadr.encode_normal_map(slopes, np.uint8))
    leadr.write_normal_map(tmp_path / "n.exr", (leadr.encode_normal_map(slopes, np.float32) + 1) / 2)
    for name in ("n.png", "n.exr"):
        with pytest.warns(HeightMapWarning, match=f"{name}: looks like a tangent-space normal map.*--normal-map"):
            load_height_map(tmp_path / name)
    colour = rng.integers(0, 256, (40, 30, 3)).astype(np.uint8)          # a photo: no unit normals
    write_png_data(tmp_path / "c.png", colour)
    write_png_data(tmp_path / "g.png", np.repeat(colour[..., :1], 3, axis=2))   # gray stored as RGB
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name in ("c.png", "g.png"):
            load_height_map(tmp_path / name)
    assert main(["bake", str(tmp_path / "n.png"), "-o", str(tmp_path / "x.exr")]) == 0
    err = capsys.readouterr().err
    assert err.startswith("microfacet: warning: ") and "n.png: looks like" in err and err.count("\n") == 1


# ------------------------------------------------------------------------- MIP maps
def _box_matrix(n_in, n_out):
    """Dense averaging matrix from uv-interval overlaps, computed with fractions."""
    from fractions import Fraction
    A = np.zeros((n_out, n_in))
    for o in range(n_out):
        lo, hi = Fraction(o, n_out), Fraction(o + 1, n_out)
        for i in range(n_in):
            a, b = max(lo, Fraction(i, n_in)), min(hi, Fraction(i + 1, n_in))
            A[o, i] = float(max(b - a, 0) * n_out)
    return A


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (5, 7), (9, 1), (13, 31), (64, 48), (3, 3)])
def test_mip_is_exact_averaging_for_any_size(shape):
    rng = np.random.default_rng(12)
    E = rng.normal(size=shape + (5,))
    pyr = leadr.mip_pyramid(E)
    sizes = leadr.mip_sizes(*shape)
    assert [p.shape[:2] for p in pyr] == sizes and sizes[-1] == (1, 1)
    np.testing.assert_allclose(pyr[-1][0, 0], E.mean(axis=(0, 1)), rtol=0, atol=1e-14)
    for k in range(1, len(pyr)):                          # every level keeps the global mean
        np.testing.assert_allclose(pyr[k].mean(axis=(0, 1)), E.mean(axis=(0, 1)), atol=1e-14)
        (h0, w0), (h1, w1) = sizes[k - 1], sizes[k]
        ref = np.einsum("ab,bcz,dc->adz", _box_matrix(h0, h1), pyr[k - 1], _box_matrix(w0, w1))
        np.testing.assert_allclose(pyr[k], ref, atol=1e-13)
    i, w = leadr.downsample_weights(5, 2)
    np.testing.assert_allclose(np.bincount(i.ravel(), w.ravel(), 5), [0.4, 0.4, 0.4, 0.4, 0.4])
    np.testing.assert_allclose(w[0, :3], [0.4, 0.4, 0.2])


def test_mip_of_float32_keeps_the_mean_to_float_precision():
    E = np.random.default_rng(13).random((257, 129, 5)).astype(np.float32)
    top = leadr.mip_pyramid(E)[-1][0, 0]
    assert top.dtype == np.float32
    np.testing.assert_allclose(top, E.astype(np.float64).mean(axis=(0, 1)), rtol=2e-7)


@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (64, 48), (1, 9)])
def test_mip_keeps_the_layout_and_the_values_of_either_layout(shape):
    """A channels-first view (bake's levels, stored plane by plane as the EXR writer needs)
    gives the same levels bit for bit as the same map channels last, each in its layout."""
    E = np.random.default_rng(14).normal(size=shape + (5,)).astype(np.float32)
    planar = np.ascontiguousarray(np.moveaxis(E, -1, 0)).transpose(1, 2, 0)
    last, first = leadr.mip_pyramid(E), leadr.mip_pyramid(planar)
    assert first[0] is planar
    for a, b in zip(last, first):
        np.testing.assert_array_equal(a, b)
        assert a.flags.c_contiguous and np.moveaxis(b, -1, 0).flags.c_contiguous
    assert all(np.moveaxis(level, -1, 0).flags.c_contiguous for level in leadr.bake(E[..., 0]))


def test_mip_linearity_and_block_moments():
    """5d: MIP levels are linear in the map, and a level of a baked map holds the moments
    of all level-0 slopes in its texel's uv cell (Eq. 3.10-3.14)."""
    rng = np.random.default_rng(14)
    A, B = rng.normal(size=(2, 24, 40, 5))
    for pa, pb, pc in zip(leadr.mip_pyramid(A), leadr.mip_pyramid(B), leadr.mip_pyramid(2 * A - 3 * B)):
        np.testing.assert_allclose(pc, 2 * pa - 3 * pb, atol=1e-12)
    xi = leadr.gaussian_heightfield((64, 64), 0.4, 0.2, 0.3, seed=15)
    pyr, s = leadr.bake(xi), leadr.height_to_slopes(xi)
    block = s.reshape(8, 8, 8, 8, 2).transpose(0, 2, 1, 3, 4).reshape(8, 8, 64, 2)   # level 3: 8x8 blocks
    direct = np.stack([[sample_moments(block[j, i]) for i in range(8)] for j in range(8)])
    np.testing.assert_allclose(pyr[3], direct, rtol=1e-5, atol=1e-7)


# ------------------------------------------------------------------------- lookup
def test_lookup_trilinear_and_limits():
    rng = np.random.default_rng(16)
    E = rng.random((16, 8, 5))
    pyr = leadr.mip_pyramid(E)
    j, i = np.meshgrid(np.arange(16), np.arange(8), indexing="ij")
    centres = np.stack([(i + 0.5) / 8, (j + 0.5) / 16], -1)
    np.testing.assert_allclose(leadr.lookup(pyr, centres, 0.0), E, atol=1e-14)       # texel centres
    np.testing.assert_allclose(leadr.lookup(pyr, [[0.3, 0.7]], 10.0)[0], E.mean((0, 1)), atol=1e-14)
    # a footprint 2^1.5 level-0 texels wide on both axes: lod 1.5 blends levels 1 and 2 halfway
    got = leadr.lookup(pyr, np.array([0.5, 0.5]), np.array([2**1.5 / 8, 2**1.5 / 16]))
    want = 0.5 * leadr.lookup(pyr[1:], np.array([0.5, 0.5])) + 0.5 * leadr.lookup(pyr[2:], np.array([0.5, 0.5]))
    assert got.shape == (5,)
    np.testing.assert_allclose(got, want, atol=1e-12)
    const = leadr.mip_pyramid(np.broadcast_to(leadr.to_moments(0.2, 0.3, 0.1), (9, 13, 5)).copy())
    q = rng.random((50, 2)) * 3 - 1
    np.testing.assert_allclose(leadr.lookup(const, q, rng.random(50) * 0.5), np.broadcast_to(const[0][0, 0], (50, 5)), atol=1e-14)
    with pytest.raises(ValueError, match="footprint"):
        leadr.lookup(pyr, np.zeros((4, 2)), np.zeros((3, 3)))


def test_anisotropic_footprint_filters_along_its_major_axis_only():
    """Stripes along u (period 2 texels) plus a wave along v (period 8 texels): a footprint
    16 texels long in u and one texel in v must average the stripes exactly and keep the
    wave sharp; an isotropic footprint of the same length blurs both."""
    H = W = 64
    i, j = np.meshgrid(np.arange(W), np.arange(H))
    value = np.where(i % 2 == 0, 1.0, -1.0) + 0.3 * np.cos(2 * np.pi * j / 8)
    E = np.repeat(value[..., None], 5, axis=2)
    pyr = leadr.mip_pyramid(E)
    uv = np.stack([np.full(20, 0.5), (np.arange(20) + 20.5) / H], -1)
    axes = np.broadcast_to(np.array([[16 / W, 0.0], [0.0, 1 / H]]), (20, 2, 2))
    aniso = leadr.lookup(pyr, uv, axes)[:, 0]
    exact = 0.3 * np.cos(2 * np.pi * (np.arange(20) + 20) / 8)
    np.testing.assert_allclose(aniso, exact, atol=1e-12)
    iso = leadr.lookup(pyr, uv, 16 / W)[:, 0]
    assert np.max(np.abs(iso - exact)) > 0.1


# ------------------------------------------------------------------------- 5a
CASES_5A = [(0.3, 0.3, 0.0), (0.5, 0.2, 0.6), (0.15, 0.4, -0.8)]


@pytest.mark.parametrize("ax, ay, rho", CASES_5A)
def test_gaussian_field_covariance_is_recovered_at_the_top_level(ax, ay, rho):
    """5a. The top MIP texel holds the sample moments of all N slopes. For an FFT field
    with random Gaussian coefficients, each sample second moment is a sum over frequency
    pairs of independent exponential variables: ``sum_k S_k g_k |W_k|^2 / N`` with
    expectation ``sum_k S_k g_k`` (= the prescribed covariance, by construction) and
    variance ``2 sum_k (S_k g_k)^2`` (``g = |dx|^2, |dy|^2, Re dx dy*``). We require each
    moment within 5 of those standard deviations (two-sided p ~ 6e-7 per check)."""
    shape = (256, 256)
    S, dx, dy = slope_spectrum(shape, ax, ay, rho)
    g = [np.abs(dx) ** 2, np.abs(dy) ** 2, (dx * np.conj(dy)).real]
    expect = np.array([np.sum(S * gi) for gi in g])
    sigma = np.array([np.sqrt(2 * np.sum((S * gi) ** 2)) for gi in g])
    target = np.array([ax * ax / 2, ay * ay / 2, rho * ax * ay / 2])
    np.testing.assert_allclose(expect, target, atol=1e-12)
    top = leadr.bake(leadr.gaussian_heightfield(shape, ax, ay, rho, seed=17))[-1][0, 0].astype(np.float64)
    assert abs(top[0]) < 1e-6 and abs(top[1]) < 1e-6               # periodic: zero mean slope
    got = np.array(leadr.covariance(top))
    assert np.all(np.abs(got - target) <= 5 * sigma + 1e-6), (got, target, sigma)
    b = leadr.from_moments(top)
    assert b.alpha_x == pytest.approx(ax, rel=0.1) and b.alpha_y == pytest.approx(ay, rel=0.1)


def test_gaussian_field_mean_slope_is_recovered_at_the_top_level():
    """5a with a mean slope: a plane ``m . (u, v)`` on the periodic field, baked with clamped
    borders. The plane's central differences are exactly ``m`` inside and ``m / 2`` on the
    two outer columns (rows), so ``E[x~] = m_x (1 - 1/W)``; the periodic part adds the
    boundary term ``sum_j (xi(j, W-1) + xi(j, W-2) - xi(j, 1) - xi(j, 0)) / 2H``, a linear
    functional ``c . xi`` of the Gaussian field with variance ``sum_k S_k |c_hat_k|^2``."""
    shape, (ax, ay, rho), m = (256, 256), (0.3, 0.2, 0.4), np.array([0.25, -0.15])
    H, W = shape
    S, _, _ = slope_spectrum(shape, ax, ay, rho)
    cx = np.zeros(shape)
    cx[:, [W - 1, W - 2]], cx[:, [0, 1]] = 0.5 / H, -0.5 / H
    cy = np.zeros(shape)
    cy[[0, 1], :], cy[[H - 1, H - 2], :] = 0.5 / W, -0.5 / W
    sd = [np.sqrt(np.sum(S * np.abs(np.fft.fft2(c)) ** 2)) for c in (cx, cy)]
    xi = leadr.gaussian_heightfield(shape, ax, ay, rho, mean_slope=m, seed=18)
    top = leadr.bake(xi, border="clamp")[-1][0, 0].astype(np.float64)
    expect = m * (1 - 1 / np.array([W, H]))
    assert np.all(np.abs(top[:2] - expect) <= 5 * np.array(sd) + 1e-6), (top[:2], expect, sd)
    b = leadr.from_moments(top)
    assert b.alpha_x == pytest.approx(ax, rel=0.1) and b.alpha_y == pytest.approx(ay, rel=0.1)


# ------------------------------------------------------------------------- files
def test_pyramid_exr_round_trip(tmp_path):
    pyr = leadr.bake(leadr.gaussian_heightfield((37, 20), 0.3, seed=19), roughness=0.05)
    path = leadr.write_pyramid(tmp_path / "p.exr", pyr)
    back = leadr.read_pyramid(path)
    assert len(back) == len(pyr) and all(b.dtype == np.float32 for b in back)
    for a, b in zip(pyr, back):
        np.testing.assert_array_equal(a, b)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.exr"]          # no temporary left
    import OpenEXR
    parts = OpenEXR.File(str(path), separate_channels=True).parts
    assert [p.name() for p in parts] == [f"mip{k}" for k in range(len(pyr))]
    assert sorted(parts[1].channels) == ["E1", "E2", "E3", "E4", "E5"]


@pytest.mark.parametrize("shape", [(37, 20), (1, 9), (64, 64), (5, 1), (1, 1)])
def test_pyramid_file_is_openexrs_file_byte_for_byte(tmp_path, shape):
    """A bake into ``pyramid_file`` writes the bytes OpenEXR writes for the same pyramid."""
    xi = leadr.gaussian_heightfield(shape, 0.3, seed=5) if min(shape) > 1 else np.linspace(0, 1, np.prod(shape)).reshape(shape)
    pyr = leadr.bake(xi, 2.0, roughness=0.05)
    with leadr.pyramid_file(tmp_path / "mapped.exr", *shape) as levels:
        assert [lv.shape for lv in levels] == [p.shape for p in pyr]
        baked = leadr.bake(xi, 2.0, roughness=0.05, out=levels)
        assert baked is levels and not (tmp_path / "mapped.exr").exists()
    leadr.write_pyramid(tmp_path / "openexr.exr", pyr)
    assert (tmp_path / "mapped.exr").read_bytes() == (tmp_path / "openexr.exr").read_bytes()
    for a, b in zip(pyr, leadr.read_pyramid(tmp_path / "mapped.exr"), strict=True):
        np.testing.assert_array_equal(a, b)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mapped.exr", "openexr.exr"]


def test_pyramid_file_leaves_nothing_on_an_error(tmp_path):
    (tmp_path / "p.exr").write_bytes(b"old")
    with pytest.raises(ValueError, match="overflow"):
        with leadr.pyramid_file(tmp_path / "p.exr", 8, 8) as levels:
            leadr.bake(leadr.gaussian_heightfield((8, 8), 0.3, seed=2), 1e30, out=levels)
    assert [p.name for p in tmp_path.iterdir()] == ["p.exr"] and (tmp_path / "p.exr").read_bytes() == b"old"
    with pytest.raises(ValueError, match="out must be the float32 levels of a 8 x 9"):
        leadr.bake(np.zeros((8, 9)), out=levels)


@pytest.mark.parametrize("compression", sorted(COMPRESSIONS))
def test_pyramid_every_lossless_compression_is_exact(tmp_path, compression):
    pyr = leadr.bake(leadr.gaussian_heightfield((70, 45), 0.3, seed=3), roughness=0.05)   # > 1 PIZ block
    path = leadr.write_pyramid(tmp_path / "p.exr", pyr, compression=compression)
    for a, b in zip(pyr, leadr.read_pyramid(path), strict=True):
        np.testing.assert_array_equal(a, b)
    import OpenEXR
    assert {p.header["compression"] for p in OpenEXR.File(str(path)).parts} == {COMPRESSIONS[compression]}


def test_pyramid_default_is_uncompressed_and_lossy_compressions_refused(tmp_path):
    pyr = leadr.bake(leadr.gaussian_heightfield((8, 8), 0.3, seed=3))
    path = leadr.write_pyramid(tmp_path / "p.exr", pyr)
    import OpenEXR
    assert OpenEXR.File(str(path)).parts[0].header["compression"] == OpenEXR.NO_COMPRESSION
    with pytest.raises(ValueError, match="EXR compression must be one of .*got 'dwaa'"):
        leadr.write_pyramid(tmp_path / "q.exr", pyr, compression="dwaa")
    assert not (tmp_path / "q.exr").exists()


def test_bad_pyramid_files(tmp_path):
    (tmp_path / "t.exr").write_bytes(b"v/1\x01garbage")
    with pytest.raises(MicrofacetError, match="t.exr: unreadable or corrupt"):
        leadr.read_pyramid(tmp_path / "t.exr")
    write_exr(tmp_path / "rgb.exr", np.ones((4, 4, 3)))
    with pytest.raises(MicrofacetError, match="rgb.exr: not a moment pyramid"):
        leadr.read_pyramid(tmp_path / "rgb.exr")
    with pytest.raises(MicrofacetError, match="no such file"):
        leadr.read_pyramid(tmp_path / "missing.exr")
    np.savez(tmp_path / "g.npz", x=np.zeros(2))              # e.g. a glints microsurface
    with pytest.raises(MicrofacetError, match=r"g.npz: not a moment pyramid EXR \(from 'microfacet bake'\)"):
        leadr.read_pyramid(tmp_path / "g.npz")
    pyr = leadr.bake(np.zeros((8, 8)))
    leadr.write_pyramid(tmp_path / "short.exr", pyr[:2])
    with pytest.raises(MicrofacetError, match="sizes"):
        leadr.read_pyramid(tmp_path / "short.exr")


# ------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def height_png(tmp_path_factory):
    path = tmp_path_factory.mktemp("maps") / "h.png"
    xi = leadr.gaussian_heightfield((96, 80), 0.4, 0.2, 0.5, seed=20)
    xi = (xi - xi.min()) / (xi.max() - xi.min())
    write_png_data(path, np.rint(xi * 65535).astype(np.uint16))
    return path


def test_cli_bake_writes_pyramid_and_preview(height_png, tmp_path, capsys):
    out = tmp_path / "out.exr"
    assert main(["bake", str(height_png), "-o", str(out), "--scale", "0.02", "--roughness", "0.1"]) == 0
    printed = capsys.readouterr().out
    assert "MIP levels" in printed and str(tmp_path / "out.png") in printed
    pyr = leadr.read_pyramid(out)
    ref = leadr.bake(load_height_map(height_png), 0.02, 0.1)
    for a, b in zip(pyr, ref):
        np.testing.assert_array_equal(a, b)
    png = read_png_data(tmp_path / "out.png")
    assert png.dtype == np.uint8 and png.ndim == 3 and png.shape[1] > png.shape[0] and png.std() > 0


def test_cli_bake_compression(height_png, tmp_path, capsys):
    import OpenEXR
    out = tmp_path / "z.exr"
    assert main(["bake", str(height_png), "-o", str(out), "--compression", "zip"]) == 0
    assert OpenEXR.File(str(out)).parts[0].header["compression"] == OpenEXR.ZIP_COMPRESSION
    for a, b in zip(leadr.read_pyramid(out), leadr.bake(load_height_map(height_png)), strict=True):
        np.testing.assert_array_equal(a, b)
    assert main(["bake", str(height_png), "-o", str(out), "--compression", "dwaa"]) == 2
    assert "invalid choice: 'dwaa'" in capsys.readouterr().err


def test_cli_bake_normal_map_and_material(tmp_path, capsys):
    slopes = np.random.default_rng(21).uniform(-0.5, 0.5, (24, 24, 2))
    write_png_data(tmp_path / "nmap.png", leadr.encode_normal_map(slopes, np.uint16))
    fit = mf.fit.fit(mf.MicrofacetBRDF(mf.Beckmann(alpha=0.2)), 32, shadowing=False)
    fit.save(tmp_path / "fit.npz")
    assert main(["bake", str(tmp_path / "nmap.png"), "--normal-map", "-o", str(tmp_path / "n"),
                 "--material", str(tmp_path / "fit.npz")]) == 0
    pyr = leadr.read_pyramid(tmp_path / "n.exr")
    base = fit.to_beckmann().distribution
    want = leadr.convolve(leadr.slopes_to_moments(leadr.decode_normal_map(
        load_normal_map(tmp_path / "nmap.png"))).mean((0, 1)), np.stack(base.moments()))
    np.testing.assert_allclose(pyr[-1][0, 0], want, rtol=1e-5)
    assert (tmp_path / "n.png").exists()


@pytest.mark.parametrize("argv, message", [
    (["bake", "{d}/missing.png", "-o", "{d}/o.exr"], "missing.png: no such file"),
    (["bake", "{d}/junk.png", "-o", "{d}/o.exr"], "junk.png: not a PNG or OpenEXR image"),
    (["bake", "{h}", "-o", "{d}/o.exr", "--normal-map"], "a normal map needs 2 to 4 channels"),
    (["bake", "{h}", "-o", "{d}/junk.png/o.exr"], "junk.png"),        # a file where a folder should be
    (["bake", "{d}/o.png", "-o", "{d}/o.exr"], "would overwrite the input"),
])
def test_cli_bake_bad_input_is_one_line_and_exit_1(argv, message, height_png, tmp_path, capsys):
    (tmp_path / "junk.png").write_bytes(b"\x00" * 64)
    (tmp_path / "o.png").write_bytes(height_png.read_bytes())
    argv = [a.format(d=tmp_path, h=height_png) for a in argv]
    assert main(argv) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("microfacet: error: ") and message in err
    assert not (tmp_path / "o.exr").exists()


def test_cli_bake_usage_errors(height_png, capsys):
    assert main(["bake", str(height_png), "-o", "x.exr", "--roughness", "0.1", "--material", "f.npz"]) == 2
    assert "not allowed with" in capsys.readouterr().err


def test_cli_bake_console_has_no_traceback(tmp_path):
    r = subprocess.run([sys.executable, "-m", "microfacet", "bake", str(tmp_path / "none.png"),
                        "-o", str(tmp_path / "o.exr")], capture_output=True, text=True)
    assert r.returncode == 1 and "Traceback" not in r.stderr and r.stderr.count("\n") == 1


def test_lookup_rejects_nonfinite_uv_and_footprints():
    pyramid = leadr.bake(np.zeros((8, 8)))
    for uv, footprint, word in (([[np.nan, 0.5]], 0.01, "uv"), ([[0.5, np.inf]], 0.01, "uv"),
                                ([[0.5, 0.5]], np.nan, "footprint"), ([[0.5, 0.5]], [[[np.inf, 0], [0, 0.1]]], "footprint")):
        with pytest.raises(ValueError, match=f"{word} must be finite"):
            leadr.lookup(pyramid, np.array(uv), footprint)


def test_lookup_wrap_and_clamp_borders():
    E = np.arange(4 * 4 * 5, dtype=np.float64).reshape(4, 4, 5)
    pyr = leadr.mip_pyramid(E)
    left_of_map = np.array([[-0.125, 0.375]])               # half a texel left of column 0, row 1
    np.testing.assert_allclose(leadr.lookup(pyr, left_of_map, wrap=False)[0], E[1, 0])
    np.testing.assert_allclose(leadr.lookup(pyr, left_of_map, wrap=True)[0], E[1, 3])
    np.testing.assert_allclose(leadr.lookup(pyr, left_of_map + [1.0, 0.0])[0], E[1, 3])
