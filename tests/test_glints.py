"""Glints microsurface: lobe mixture of a normal map, footprint weights, P-NDF and its
acceleration hierarchy (Chermain, Claux and Mérillou 2019, Sec. 3, 4.1, 4.2.2, 5)."""

import numpy as np
import pytest

from conftest import DATA

import microfacet as mf
from microfacet import leadr
from microfacet.cli import main
from microfacet.errors import MicrofacetError
from microfacet.geometry import spherical_to_cartesian
from microfacet.glints import FORMAT_VERSION, Microsurface, interpolate_slopes, load_slopes
from microfacet.glints.microsurface import (FWHM_PER_SIGMA, _central_float32, _floor_moments, _raw_from_central,
                                            _floor_moments_compiled, _lobe_moments, _quadrature,
                                            lobe_moments, lobe_moments_reference)
from microfacet.glints.reference import compare_histogram
from microfacet.io import write_exr
from microfacet.io.png import write_png_data
from microfacet.validation import integrate_hemisphere

MAPS = DATA / "maps"


def real_map(name):
    path = MAPS / name
    if not path.exists():
        pytest.skip(f"test data {path} absent ($MICROFACET_DATA or ../shared/data: not part of a user's clone)")
    return path


def random_slopes(shape=(24, 32), alpha=0.3, correlation=3.0, seed=1):
    height = leadr.gaussian_heightfield(shape, alpha, correlation=correlation, seed=seed)
    return leadr.height_to_slopes(height)


def hemisphere_grid(n=400):
    """Normals and solid-angle weights of a midpoint (theta, phi) grid over the hemisphere."""
    th = (np.arange(n) + 0.5) * (np.pi / 2) / n
    ph = (np.arange(2 * n) + 0.5) * np.pi / n
    T, P = np.meshgrid(th, ph, indexing="ij")
    h = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1)
    return h, np.sin(T) * (np.pi / 2 / n) * (np.pi / n)


@pytest.fixture(scope="module")
def ms():
    return Microsurface.from_normal_map(leadr.encode_normal_map(random_slopes(), np.uint16))


# --------------------------------------------------------------------------- normal maps
def test_load_slopes_encodings_round_trip(tmp_path):
    s = random_slopes((16, 20))
    for dtype, tol in ((np.uint8, 0.03), (np.uint16, 2e-4)):
        path = tmp_path / f"n{np.dtype(dtype).itemsize}.png"
        write_png_data(path, leadr.encode_normal_map(s, dtype))
        assert np.abs(load_slopes(path) - s).max() < tol
    n = leadr.slopes_to_normals(s)
    write_exr(tmp_path / "signed.exr", n)
    write_exr(tmp_path / "offset.exr", 0.5 * n + 0.5)
    for name in ("signed.exr", "offset.exr"):
        assert np.abs(load_slopes(tmp_path / name) - s).max() < 1e-5, name
    assert np.abs(load_slopes(0.5 * n + 0.5, encoding="offset") - s).max() < 1e-12
    two = np.rint((0.5 * n[..., :2] + 0.5) * 65535).astype(np.uint16)       # 2-channel map
    assert np.abs(load_slopes(two) - s).max() < 2e-4
    flat_blue = leadr.encode_normal_map(s, np.uint16)
    flat_blue[..., 2] = 65535                                                 # z to reconstruct
    assert np.abs(load_slopes(flat_blue) - s).max() < 2e-4
    scaled = n * np.linspace(0.5, 1.4, n.shape[1])[None, :, None]            # stored, non-unit
    assert np.abs(load_slopes(scaled, z="stored") - s).max() < 1e-12
    assert np.abs(load_slopes(scaled) - s).max() < 1e-12                     # auto: stored z


def test_load_slopes_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(MicrofacetError, match="bad.png"):
        load_slopes(bad)
    with pytest.raises(MicrofacetError, match="missing.exr"):
        load_slopes(tmp_path / "missing.exr")
    with pytest.raises(MicrofacetError, match="2 to 4 channels.*shape"):
        load_slopes(np.zeros((4, 4)))
    with pytest.raises(ValueError, match="encoding"):
        load_slopes(np.zeros((4, 4, 3)), encoding="srgb")


def test_interpolation_hits_texel_centres_and_wraps():
    s = random_slopes((8, 6))
    iy, ix = np.mgrid[0:8, 0:6]
    uv = np.stack([(ix + 0.5) / 6, (iy + 0.5) / 8], -1)
    assert np.allclose(interpolate_slopes(s, uv), s)
    assert np.allclose(interpolate_slopes(s, uv + 1.0), s)
    mid = interpolate_slopes(s, np.array([1.0 / 6, 0.5 / 8]))                 # between columns 0, 1
    assert np.allclose(mid, 0.5 * (s[0, 0] + s[0, 1]))


# --------------------------------------------------------------------------- lobes (Eq. 3-6)
def test_compiled_lobe_moments_match_numpy_reference():
    """Both compiled kernels equal the NumPy quadrature: the direct sum, and the shared
    fine-grid one that :func:`lobe_moments` takes when ``h * samples`` is an integer."""
    s = random_slopes((12, 10))
    for nx, ny in ((10, 12), (5, 6)):                                         # h = 1 and h = 2
        o, g = _quadrature((10 / nx) / FWHM_PER_SIGMA, 4)
        assert np.allclose(_lobe_moments(s, nx, ny, o, g), lobe_moments_reference(s, nx, ny), atol=1e-12)
    s = random_slopes((24, 20))
    for nx, ny, samples in ((20, 24, 4), (10, 12, 3), (20, 12, 4), (8, 16, 4), (7, 9, 4), (3, 5, 2)):
        np.testing.assert_allclose(lobe_moments(s, nx, ny, samples), lobe_moments_reference(s, nx, ny, samples),
                                   rtol=0, atol=1e-13)


def test_compiled_floor_matches_numpy_floor():
    """The in-place compiled floor equals :func:`_floor_moments` (correlated, degenerate
    and already-floored lobes) and is idempotent."""
    rng = np.random.default_rng(5)
    m = rng.normal(size=(3000, 2)) * 0.3
    v = np.abs(rng.normal(size=(3000, 2))) * np.array([[0.02, 0.005]]) ** 2 * rng.integers(0, 2, (3000, 1))
    rho = rng.uniform(-1, 1, 3000)
    rho[:300] = 1.0
    E = np.stack([m[:, 0], m[:, 1], v[:, 0] + m[:, 0] ** 2, v[:, 1] + m[:, 1] ** 2,
                  rho * np.sqrt(v[:, 0] * v[:, 1]) + m[:, 0] * m[:, 1]], -1)
    ref = _floor_moments(E, 0.01)
    got = E.copy()
    _floor_moments_compiled(got, 0.01)
    np.testing.assert_allclose(got, ref, rtol=1e-13, atol=1e-17)
    again = got.copy()
    _floor_moments_compiled(again, 0.01)
    assert np.array_equal(again, got)


def test_constant_map_gives_sigma_eps_lobes_at_its_slope():
    s = np.broadcast_to([0.2, -0.1], (8, 8, 2))
    m = Microsurface.from_normal_map(leadr.slopes_to_normals(s), sigma_eps=0.02)
    E = leadr.to_moments(0.02 * np.sqrt(2), 0.02 * np.sqrt(2), 0.0, (0.2, -0.1))
    assert np.allclose(m.lobe_moments, E, atol=1e-12)
    assert m.lobe_uv.shape == (64, 2) and m.resolution == (8, 8)
    assert np.allclose(m.kernel_sigma, 1 / 8 / FWHM_PER_SIGMA)
    # kernel: half maximum midway between seeds
    assert np.isclose(np.exp(-0.5 * (0.5 / 8 / m.kernel_sigma[0]) ** 2), 0.5)


def test_lobe_moments_of_a_linear_ramp():
    """On a slope field linear in u (no wrap seam inside the kernels), E[x~] is the field at
    the seed and Var[x~] = (d x~/du)^2 sigma_k^2 (Eq. 5-6) up to quadrature error."""
    w = 64
    x = np.linspace(-0.6, 0.6, w)
    s = np.stack(np.broadcast_arrays(x[None, :], 0.0 * x[:, None]), -1)
    m = Microsurface.from_normal_map(leadr.slopes_to_normals(s), sigma_eps=1e-4, samples=16)
    E = m.lobe_moments.reshape(w, w, 5)[:, 8:-8]
    assert np.allclose(E[..., 0], x[None, 8:-8], atol=1e-12)
    var = (1.2 / (w - 1)) ** 2 * (1 / FWHM_PER_SIGMA) ** 2                  # texel step^2 sigma^2
    assert np.allclose(E[..., 2] - E[..., 0] ** 2, var, rtol=0.02)


def test_lobes_are_core_beckmann_with_array_parameters(ms):
    idx = np.array([0, 5, 17])
    b = ms.lobes(idx)
    assert isinstance(b, mf.Beckmann) and np.shape(b.alpha_x) == (3,)
    assert np.allclose(np.stack(np.broadcast_arrays(*b.moments()), -1), ms.lobe_moments[idx], rtol=1e-9)
    var = ms.lobe_moments[:, 2:4] - ms.lobe_moments[:, :2] ** 2
    assert var.min() >= ms.sigma_eps**2 * (1 - 1e-9)


# --------------------------------------------------------------------------- weights (Eq. 9)
def test_weights_closed_form_matches_numerical_integral(ms):
    center, cov = np.array([0.41, 0.57]), np.array([[4e-4, 1.5e-4], [1.5e-4, 3e-4]])
    idx, W = ms.weights(center, cov, normalize=False)
    ny, nx = ms.grid
    g = (np.arange(1200) + 0.5) / 1200
    U, V = np.meshgrid(g, g, indexing="xy")
    d = np.stack([U - center[0], V - center[1]], -1)
    kp = np.exp(-0.5 * np.einsum("...i,ij,...j", d, np.linalg.inv(cov), d)) / (2 * np.pi * np.sqrt(np.linalg.det(cov)))
    for k in np.argsort(W)[-5:]:
        du, dv = U - ms.lobe_uv[idx[k], 0], V - ms.lobe_uv[idx[k], 1]
        ki = np.exp(-0.5 * ((du / ms.kernel_sigma[0]) ** 2 + (dv / ms.kernel_sigma[1]) ** 2)) / (nx * ny) \
            / (2 * np.pi * ms.kernel_sigma[0] * ms.kernel_sigma[1])               # integral h^2
        assert np.isclose(W[k], np.sum(ki * kp) / 1200**2, rtol=1e-3)


def test_weights_sum_and_normalization(ms):
    _, W = ms.weights((0.3, 0.7), np.eye(2) * 0.05**2)
    assert np.isclose(W.sum(), 1.0)
    _, raw = ms.weights((0.3, 0.7), np.eye(2) * 0.05**2, normalize=False)
    assert abs(raw.sum() - 1.0) < 0.01                 # 3-sigma truncation, kernel-sum ripple
    # a point footprint sees the ripple of sum_i k_i(u): with FWHM = spacing it runs from
    # 0.889 between seeds to 1.115 on a seed (theta-function sums of the Gaussian)
    _, raw = ms.weights((0.5, 0.5), np.zeros((2, 2)), normalize=False)     # between 4 seeds
    assert 0.87 < raw.sum() < 0.89
    _, raw = ms.weights(((12 + 0.5) / 32, (7 + 0.5) / 24), np.zeros((2, 2)), normalize=False)
    assert 1.10 < raw.sum() < 1.12


def test_footprints_wrap_around_the_map(ms):
    h = spherical_to_cartesian(np.linspace(0.0, 0.5, 7), np.linspace(0, 6, 7))
    cov = np.eye(2) * 0.04**2
    a = ms.pndf(h, (0.01, 0.98), cov)
    b = ms.pndf(h, (1.01, -0.02), cov)
    assert np.allclose(a, b, rtol=1e-10)
    idx, _ = ms.weights((0.01, 0.98), cov)
    assert idx.min() >= 0 and idx.max() < ms.n_lobes


def test_bad_footprints_raise(ms):
    with pytest.raises(ValueError, match="cov"):
        ms.weights((0.5, 0.5), [[1e-3, 0.0], [0.0, -1e-3]])
    with pytest.raises(ValueError, match="center"):
        ms.pndf(np.array([0, 0, 1.0]), (np.nan, 0.5), np.eye(2) * 1e-4)


# --------------------------------------------------------------------------- P-NDF (Eq. 9)
def random_normals(n, spread=0.4, seed=0):
    rng = np.random.default_rng(seed)
    h = np.concatenate([rng.normal(size=(n, 2)) * spread, np.ones((n, 1))], -1)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def test_pndf_is_the_weighted_sum_of_core_beckmann_ndfs(ms):
    h = random_normals(200)
    center, cov = (0.62, 0.35), np.eye(2) * (2.5 / 32) ** 2
    idx, W = ms.weights(center, cov)
    ref = ms.lobes(idx).ndf(h[:, None, :]) @ W
    assert np.allclose(ms.pndf(h, center, cov, method="brute"), ref, rtol=1e-9, atol=1e-12)


def test_hierarchy_matches_brute_force(ms):
    h = random_normals(300, spread=0.5).reshape(10, 30, 3)
    center, cov = (0.2, 0.8), np.array([[0.06**2, 0.001], [0.001, 0.05**2]])
    brute = ms.pndf(h, center, cov, method="brute")
    assert brute.shape == (10, 30)
    exact = Microsurface(ms._grid, ms.slopes, slope_cutoff=40.0)        # no slope pruning
    for method in ("hierarchy", "hierarchy-numpy"):
        assert np.allclose(exact.pndf(h, center, cov, method=method), brute, rtol=1e-12, atol=1e-300)
    fast = ms.pndf(h, center, cov, method="hierarchy")                   # 4-sigma slope boxes
    assert np.allclose(fast, ms.pndf(h, center, cov, method="hierarchy-numpy"), rtol=1e-12, atol=1e-300)
    assert np.all(fast <= brute * (1 + 1e-12))
    assert np.max(np.abs(fast - brute)) < 2e-3 * brute.max()
    assert np.max(np.abs(fast - brute)) > 0                              # pruning happened


def test_pndf_below_horizon_is_zero(ms):
    h = np.array([[0.0, 0.6, -0.8], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    d = ms.pndf(h, (0.5, 0.5), np.eye(2) * 1e-3)
    assert d[0] == 0 and d[1] == 0 and np.all(np.isfinite(d))


@pytest.mark.parametrize("texels", [0.0, 1.0, 6.0])
def test_pndf_projected_area_normalization(texels):
    """int D_P(h) cos(theta_h) dw = sum W_i (= 1 normalized), hemisphere midpoint grid; the
    lobes are widened (sigma_eps = 0.08) so the grid resolves them."""
    m = Microsurface.from_normal_map(leadr.slopes_to_normals(random_slopes((32, 32), alpha=0.4)),
                                     sigma_eps=0.08)
    h, dw = hemisphere_grid(300)
    cov = np.eye(2) * (texels / 32) ** 2
    for normalize in (True, False):
        _, W = m.weights((0.37, 0.61), cov, normalize=normalize)
        total = np.sum(m.pndf(h, (0.37, 0.61), cov, normalize=normalize) * h[..., 2] * dw)
        assert abs(total - W.sum()) < 2e-3, (normalize, total, W.sum())
    # the same with the core's slope-space quadrature around the filtered lobe
    lobe = m.mip_lobe((0.37, 0.61), cov + np.eye(2) * (4 / 32) ** 2)
    lobe = mf.Beckmann(alpha_x=1.5 * lobe.alpha_x, alpha_y=1.5 * lobe.alpha_y, mean_slope=lobe.mean_slope)
    total = integrate_hemisphere(lambda x: m.pndf(x, (0.37, 0.61), cov) * x[..., 2], lobe, n=(400, 400))
    assert abs(total - 1.0) < 2e-3


def test_sampled_slopes_follow_the_pndf(ms):
    center, cov = (0.45, 0.55), np.eye(2) * (3 / 32) ** 2
    u = np.random.default_rng(3).random((200_000, 3))
    s = ms.sample_slopes(u, center, cov)
    idx, W = ms.weights(center, cov)
    E = W @ ms.lobe_moments[idx]
    assert np.allclose(s.mean(0), E[:2], atol=0.01)
    assert np.allclose([np.mean(s[:, 0] ** 2), np.mean(s[:, 1] ** 2), np.mean(s[:, 0] * s[:, 1])],
                       E[2:], rtol=0.03, atol=2e-3)


def test_pndf_matches_histogram_of_a_synthetic_map():
    m = Microsurface.from_normal_map(leadr.slopes_to_normals(random_slopes((64, 64), 0.3, 4.0)))
    for texels, tol in ((2.0, 0.08), (8.0, 0.05)):
        r = compare_histogram(m, (0.4, 0.6), np.eye(2) * (texels / 64) ** 2, n=200_000)
        assert r["tv"] < tol, (texels, r)


@pytest.mark.parametrize("name,limits", [
    ("sms_normalmap_gaussian.exr", {1: 0.12, 4: 0.08, 16: 0.05}),
    ("glitterman_scratches.png", {1: 0.3, 4: 0.12, 16: 0.12}),
])
def test_pndf_matches_histogram_of_real_maps(name, limits):
    """Paper Sec. 5.1.1, Fig. 5: the P-NDF against the binned interpolated normal map (with
    the material's sigma_eps roughness) over Gaussian footprints of 1, 4 and 16 texels."""
    m = Microsurface.from_normal_map(real_map(name))
    w = m.resolution[1]
    for texels, tol in limits.items():
        r = compare_histogram(m, (0.71, 0.22), np.eye(2) * (texels / w) ** 2, n=200_000)
        assert r["tv"] < tol, (name, texels, r)


# --------------------------------------------------------------------------- MIP (Sec. 4.2.2)
def test_mip_levels_average_lobe_moments(ms):
    assert np.allclose(ms.mip[0].reshape(-1, 5), ms.lobe_moments)
    assert ms.mip[-1].shape[:2] == (1, 1)
    assert np.allclose(ms.mip[-1][0, 0], ms.lobe_moments.mean(0))
    center, cov = (0.5, 0.5), np.eye(2) * 0.15**2
    idx, W = ms.weights(center, cov)
    assert ms.mip_level(cov) > 0
    assert np.allclose(ms.mip_moments(center, cov), W @ ms.lobe_moments[idx], atol=0.02)
    assert np.allclose(ms.mip_moments(center, cov, level=0), W @ ms.lobe_moments[idx], atol=1e-12)
    assert isinstance(ms.mip_lobe(center, cov), mf.Beckmann)


# --------------------------------------------------------------------------- files and CLI
def test_save_load_round_trip(ms, tmp_path):
    """Format 2 stores float32 central moments: means, variances and covariances come back
    to float32 precision (float32 raw moments would lose the variance of steep lobes to
    cancellation); format 1 files (float64 raw moments) still load, bit for bit."""
    path = ms.save(tmp_path / "ms.npz")
    back = Microsurface.load(path)
    central = _central_float32(ms._grid).astype(np.float64)
    np.testing.assert_allclose(_central_float32(back._grid), central, rtol=3e-7, atol=1e-12)
    with np.load(path) as z:
        assert int(z["version"]) == FORMAT_VERSION == 2 and z["central"].dtype == np.float32
    assert back.resolution == ms.resolution and back.h == ms.h and back.sigma_eps == ms.sigma_eps
    h = random_normals(20)
    assert np.allclose(back.pndf(h, (0.5, 0.5), np.eye(2) * 1e-3), ms.pndf(h, (0.5, 0.5), np.eye(2) * 1e-3),
                       rtol=1e-4)
    assert [p.name for p in tmp_path.iterdir()] == ["ms.npz"]        # no temporary left
    params = np.array([ms.h, ms.sigma_eps, ms.cutoff, ms.slope_cutoff])
    old = tmp_path / "v1.npz"
    np.savez_compressed(old, magic=np.array("microfacet.glints.Microsurface"), version=np.array(1),
                        moments=ms._grid, slopes=ms.slopes.astype(np.float32), params=params)
    assert np.array_equal(Microsurface.load(old).lobe_moments, ms.lobe_moments)
    future = tmp_path / "v9.npz"
    np.savez(future, magic=np.array("microfacet.glints.Microsurface"), version=np.array(9), params=params)
    with pytest.raises(MicrofacetError, match="v9.npz.*version 9"):
        Microsurface.load(future)


def test_load_errors_name_the_file(tmp_path):
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"PK\x03\x04 nonsense")
    with pytest.raises(MicrofacetError, match="junk.npz"):
        Microsurface.load(junk)
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(3))
    with pytest.raises(MicrofacetError, match="other.npz.*not a microfacet"):
        Microsurface.load(other)
    with pytest.raises(MicrofacetError, match="nothing.npz"):
        Microsurface.load(tmp_path / "nothing.npz")


def test_cli_builds_and_saves_a_microsurface(tmp_path, capsys):
    src = tmp_path / "map.png"
    write_png_data(src, leadr.encode_normal_map(random_slopes((16, 16)), np.uint8))
    assert main(["glints", str(src), "-o", str(tmp_path / "out"), "--spacing", "2"]) == 0
    m = Microsurface.load(tmp_path / "out.npz")
    assert m.grid == (8, 8) and m.resolution == (16, 16)
    assert "64 lobes" in capsys.readouterr().out
    assert main(["glints", str(tmp_path / "missing.png"), "-o", str(tmp_path / "x.npz")]) == 1
    err = capsys.readouterr().err
    assert "missing.png" in err and err.count("\n") == 1 and "Traceback" not in err


def test_central_moment_conversions_invert_each_other():
    E = lobe_moments(random_slopes((9, 7)), 7, 9)
    C = _central_float32(E)
    assert C.dtype == np.float32
    np.testing.assert_allclose(C[..., 2], E[..., 2] - E[..., 0] ** 2, rtol=1e-6)
    np.testing.assert_allclose(C[..., 4], E[..., 4] - E[..., 0] * E[..., 1], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(_raw_from_central(C), E, rtol=1e-6, atol=1e-9)
    assert np.array_equal(_raw_from_central(C.astype(np.float64))[..., :2], C[..., :2])


def test_load_floors_in_the_conversion_pass_bit_for_bit(ms, tmp_path):
    """``_raw_from_central(C, sigma_eps)`` floors each lobe as ``_floor_moments_compiled``
    does afterwards (same numbers, steep and thin lobes included), and a loaded format-2
    file holds exactly the lobes of the constructor on its raw moments; bad parameters,
    an empty lobe grid and float64 central moments still load or fail as before."""
    rng = np.random.default_rng(5)
    C = _central_float32(lobe_moments(random_slopes((12, 10)) * 3.0, 10, 12))
    C[0, :, 2:4] = 1e-7                     # thinner than sigma_eps: changed by the floor
    C[1, :, 4] = np.sqrt(C[1, :, 2] * C[1, :, 3])            # |rho| = 1: clamped
    C[2, :, :2] = rng.normal(0, 50, (10, 2))                 # steep means
    for eps in (0.01, 0.3):
        sep = _raw_from_central(C)
        _floor_moments_compiled(sep.reshape(-1, 5), eps)
        fused = _raw_from_central(C, eps)
        assert np.array_equal(fused, sep) and not np.array_equal(fused, _raw_from_central(C))
    path = ms.save(tmp_path / "ms.npz")
    back = Microsurface.load(path)
    with np.load(path) as z:
        ref = Microsurface(_raw_from_central(z["central"]), z["slopes"], ms.h, ms.sigma_eps, ms.cutoff,
                           ms.slope_cutoff)
    assert np.array_equal(back.lobe_moments, ref.lobe_moments) and back._grid.flags.c_contiguous
    assert (back.grid, back.resolution, back.cutoff, back.slope_cutoff) == (ref.grid, ref.resolution, ms.cutoff,
                                                                            ms.slope_cutoff)
    assert np.array_equal(back.kernel_sigma, ref.kernel_sigma) and back.slopes.dtype == np.float32
    arrays = dict(np.load(path))
    for name, change, why in [("eps", {"params": np.array([1.0, 0.0, 3.0, 4.0])}, "sigma_eps must be > 0"),
                              ("cut", {"params": np.array([1.0, 0.01, -3.0, 4.0])}, "cutoff and slope_cutoff"),
                              ("empty", {"central": np.zeros((0, 4, 5), np.float32)}, "bad array shapes")]:
        np.savez(tmp_path / f"{name}.npz", **dict(arrays, **change))
        with pytest.raises(MicrofacetError, match=f"{name}.npz: corrupt microsurface file.*{why}"):
            Microsurface.load(tmp_path / f"{name}.npz")
    np.savez(tmp_path / "f64.npz", **dict(arrays, central=arrays["central"].astype(np.float64)))
    assert np.array_equal(Microsurface.load(tmp_path / "f64.npz").lobe_moments, back.lobe_moments)


def test_alpha_summary_is_the_median_and_max_of_both_axes():
    """``alpha_summary`` (float32, partitioned in place) gives ``np.median`` and the
    largest of the per-axis roughness ``sqrt(2 var)`` of the lobes, even and odd counts."""
    from microfacet.glints.figures import scratched_normal_map
    for size in (16, 9):
        ms = Microsurface.from_normal_map(scratched_normal_map(16, scratches=3, seed=2)[:size, :9])
        E = ms.lobe_moments
        alpha = np.sqrt(2.0 * (E[:, 2:4] - E[:, :2] ** 2))
        med, top = ms.alpha_summary()
        assert med == pytest.approx(float(np.median(alpha)), rel=1e-6)
        assert top == pytest.approx(float(alpha.max()), rel=1e-6)
        assert alpha.min() < med < top


def test_load_rejects_arrays_of_other_types(tmp_path):
    """A microsurface file whose arrays are not float32/float64 (here float16 moments, which
    the compiled checks cannot read) is a clear error naming the file, not a traceback."""
    ms = Microsurface.from_normal_map(np.dstack([np.zeros((8, 8, 2)), np.ones((8, 8))]))
    ms.save(tmp_path / "ok.npz")
    arrays = dict(np.load(tmp_path / "ok.npz"))
    arrays["central"] = arrays["central"].astype(np.float16)
    np.savez(tmp_path / "half.npz", **arrays)
    with pytest.raises(MicrofacetError, match="half.npz.*types"):
        Microsurface.load(tmp_path / "half.npz")
    assert Microsurface.load(tmp_path / "ok.npz").n_lobes == 64
