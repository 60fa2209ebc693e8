"""Measured-BRDF readers (``microfacet.measured``): MERL, RGL and UTIA.

* MERL and UTIA: synthetic files written here from analytic functions round-trip to the
  function at the samples, interpolate exactly what trilinear/quadrilinear interpolation
  reproduces (functions multilinear in the grid coordinates), and stay close for smooth
  ones; gzip and plain files load alike; unmeasured MERL samples are excluded; bad files
  raise ``MicrofacetError`` naming the file and the problem, and are left untouched.
* RGL: a synthetic tensor file (always) and the real files in ``../shared/data`` (when
  present) against Mitsuba 3's ``measured`` plugin, plus sanity checks.

Tolerance of the Mitsuba cross-check
------------------------------------
Directions are rounded to float32 before both sides see them, so the differences come
only from Mitsuba's float32 arithmetic (unit roundoff ``U = 2**-24 ~ 6e-8``) against our
float64. The direction -> unit-coordinate transforms (normalize, asin, atan2, sqrt) cost
about ten roundings (~1e-6 in ``u``); the tables then amplify a coordinate error by their
relative slope: with 32-128 nodes per unit and values changing by up to tens of percent
per node in the sharp lobes (and the VNDF warp's density ``dCDF/du`` up to ~100), a
relative slope of up to ~100 per unit coordinate. Hence ``RTOL = 1e-4`` (~1600 U), plus
``ATOL = 1e-6`` of the largest value for values that cross zero (the interpolated RGB of
out-of-gamut spectra can be slightly negative, Mitsuba keeps it). The measured errors
(``python tests/test_measured.py`` prints them) use at most ~10 % of this tolerance:
largest relative error 1.4e-5 on values above 1 % of the maximum, largest absolute error
9e-7 of the maximum.
"""
from __future__ import annotations

import gzip
import hashlib
import struct
import warnings
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA

import microfacet as mf
from microfacet.geometry import hd_to_io, spherical_to_cartesian
from microfacet.measured import merl, utia
from microfacet.measured.tensor_file import read_tensor_file, write_tensor_file

RTOL, ATOL = 1e-4, 1e-6        # Mitsuba cross-check, see the module docstring


def needs_data(*parts) -> Path:
    path = DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"test data {path} absent ($MICROFACET_DATA or ../shared/data: not part of a user's clone)")
    return path


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def uniform_dirs(rng, n: int) -> np.ndarray:
    """Directions uniform in solid angle over the upper hemisphere."""
    u = rng.random((n, 2))
    return spherical_to_cartesian(np.arccos(u[:, 0]), 2 * np.pi * u[:, 1])


# ============================================================================ MERL
def merl_function(theta_h, theta_d, phi_d) -> np.ndarray:
    """A smooth RGB function of the Rusinkiewicz angles, pi-periodic in phi_d."""
    base = 0.2 + 2.0 * np.cos(theta_h) ** 8 + 0.3 * np.sin(theta_d) ** 2 + 0.1 * np.cos(2 * phi_d)
    return np.stack([base, 0.5 * base + 0.1, 0.25 * base + 0.05], axis=-1)


def merl_linear(u_h, u_d, u_phi=0.0) -> np.ndarray:
    """Bilinear in the bin coordinates: trilinear interpolation reproduces it exactly."""
    v = 1.0 + 0.01 * u_h + 0.02 * u_d + 1e-4 * u_h * u_d + 0 * u_phi
    return np.stack([v, 2 * v, 3 * v], axis=-1)


def merl_raw(fn) -> np.ndarray:
    """Raw planar array ``(3, 90, 90, 180)`` (physical value / channel scale) of ``fn`` on
    the MERL grid, evaluated with the angles of the sample positions."""
    i_h, i_d, i_p = np.meshgrid(np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    th, td, pd = (i_h / 90) ** 2 * np.pi / 2, i_d / 90 * np.pi / 2, i_p / 180 * np.pi
    return np.moveaxis(fn(th, td, pd) / merl.SCALE, -1, 0)


def merl_bytes(raw: np.ndarray, header=(90, 90, 180)) -> bytes:
    return np.array(header, "<i4").tobytes() + np.ascontiguousarray(raw, "<f8").tobytes()


@pytest.fixture(scope="module")
def smooth_raw():
    return merl_raw(merl_function)


@pytest.fixture(scope="module")
def linear_raw():
    return merl_raw(lambda th, td, pd: merl_linear(*merl.grid_coordinates(th, td, pd)))


@pytest.fixture(scope="module")
def smooth_file(tmp_path_factory, smooth_raw):
    path = tmp_path_factory.mktemp("merl") / "smooth.binary"
    path.write_bytes(merl_bytes(smooth_raw))
    return path


def hd_directions(rng, theta_h, theta_d, phi_d):
    """``(wi, wo)`` with the given Rusinkiewicz angles and random phi_h, and the mask of
    pairs above both horizons."""
    h = spherical_to_cartesian(theta_h, rng.uniform(0, 2 * np.pi, np.shape(theta_h)))
    wi, wo = hd_to_io(h, spherical_to_cartesian(theta_d, phi_d))
    return wi, wo, (wi[..., 2] > 1e-3) & (wo[..., 2] > 1e-3)


def test_merl_hd_coordinates_match_geometry():
    rng = np.random.default_rng(11)
    wi, wo = uniform_dirs(rng, 2000), uniform_dirs(rng, 2000)
    h, d = mf.geometry.io_to_hd(wi, wo)
    th, td, pd = merl.hd_coordinates(wi, wo)
    (th_ref, _), (td_ref, pd_ref) = mf.geometry.cartesian_to_spherical(h), mf.geometry.cartesian_to_spherical(d)
    np.testing.assert_allclose(th, th_ref, atol=1e-12)
    np.testing.assert_allclose(td, td_ref, atol=1e-12)
    np.testing.assert_allclose(np.cos(2 * pd), np.cos(2 * pd_ref), atol=1e-12)   # modulo pi
    assert np.all((pd >= 0) & (pd <= np.pi))


def test_merl_samples_round_trip(smooth_file):
    rng = np.random.default_rng(1)
    m = mf.measured.load(smooth_file)
    assert isinstance(m, mf.BRDF) and m.format == "merl"
    # theta_h = 0 or theta_d = 0 leave phi_d undefined: start at the second samples
    i_h, i_d, i_p = rng.integers(1, 90, 4000), rng.integers(1, 90, 4000), rng.integers(0, 180, 4000)
    th, td, pd = m.theta_h[i_h], m.theta_d[i_d], m.phi_d[i_p]
    wi, wo, up = hd_directions(rng, th, td, pd + np.pi * rng.integers(0, 2, 4000))  # phi_d ~ phi_d + pi
    assert up.sum() > 1000
    np.testing.assert_allclose(m.eval(wi, wo)[up], merl_function(th, td, pd)[up], rtol=1e-9)
    np.testing.assert_allclose(m.values[i_h, i_d, i_p], merl_function(th, td, pd), rtol=1e-12)


def test_merl_interpolation(tmp_path, linear_raw, smooth_file):
    rng = np.random.default_rng(2)
    th, td, pd = rng.uniform(0, 1.5, 20000), rng.uniform(0, 1.5, 20000), rng.uniform(-np.pi, np.pi, 20000)
    wi, wo, up = hd_directions(rng, th, td, pd)
    # exact for a function bilinear in the bin coordinates (below the clamped last bins)
    path = tmp_path / "linear.binary"
    path.write_bytes(merl_bytes(linear_raw))
    u = merl.grid_coordinates(th, td, pd)
    np.testing.assert_allclose(mf.measured.load(path).eval(wi, wo)[up], merl_linear(*u)[up], rtol=1e-9)
    # close for a smooth one: the trilinear error is (step^2 / 8) |f''|, below 0.5 % here
    f = mf.measured.load(smooth_file).eval(wi, wo)[up]
    ref = merl_function(th, td, pd)[up]
    assert np.max(np.abs(f / ref - 1)) < 5e-3
    # halfway between two phi_d samples (on theta samples): the mean of both
    m = mf.measured.load(smooth_file)
    th, td = m.theta_h[30], m.theta_d[40]
    wi, wo, up = hd_directions(rng, np.full(50, th), np.full(50, td), np.full(50, 10.5 / 180 * np.pi))
    mid = 0.5 * (merl_function(th, td, m.phi_d[10]) + merl_function(th, td, m.phi_d[11]))
    assert up.all()
    np.testing.assert_allclose(m.eval(wi, wo), np.broadcast_to(mid, (50, 3)), rtol=1e-9)


def test_merl_gzip_and_plain_load_alike(tmp_path, smooth_file):
    gz = tmp_path / "smooth.data"                  # detection is by content, not by name
    gz.write_bytes(gzip.compress(smooth_file.read_bytes(), compresslevel=1))
    a, b = mf.measured.load(smooth_file), mf.measured.load(gz)
    assert isinstance(b, mf.measured.MERLBRDF)
    np.testing.assert_array_equal(a.values, b.values)
    rng = np.random.default_rng(3)
    wi, wo = uniform_dirs(rng, 100), uniform_dirs(rng, 100)
    np.testing.assert_array_equal(a.eval(wi, wo), b.eval(wi, wo))


def test_merl_unmeasured_samples(tmp_path, linear_raw):
    raw = linear_raw.copy()
    raw[:, 40:50] = -1.0                           # theta_h bins 40..49 not measured
    raw[1, 10, 20, 30] = -1.0                      # one channel of one sample
    path = tmp_path / "holes.binary"
    path.write_bytes(merl_bytes(raw))
    m = mf.measured.load(path)
    assert not m.valid[40:50].any() and not m.valid[10, 20, 30] and m.valid.sum() == 80 * 90 * 180 - 1
    rng = np.random.default_rng(4)
    td, pd = rng.uniform(0.1, 1.0, 200), rng.uniform(0, np.pi, 200)
    theta = lambda u_h: (u_h / 90) ** 2 * np.pi / 2      # noqa: E731
    # inside the hole: no data at all
    wi, wo, up = hd_directions(rng, np.full(200, theta(45.0)), td, pd)
    assert np.all(m.eval(wi, wo)[up] == 0) and np.all(m.coverage(wi, wo)[up] == 0)
    # half a bin from its edge: only the measured layer counts, with full weight
    wi, wo, up = hd_directions(rng, np.full(200, theta(39.5)), td, pd)
    np.testing.assert_allclose(m.coverage(wi, wo)[up], 0.5, rtol=1e-9)
    u = merl.grid_coordinates(theta(39.0), td, pd)
    np.testing.assert_allclose(m.eval(wi, wo)[up], merl_linear(*u)[up], rtol=1e-9)
    # measured elsewhere: coverage 1
    wi, wo, up = hd_directions(rng, np.full(200, theta(60.0)), td, pd)
    np.testing.assert_allclose(m.coverage(wi, wo)[up], 1.0)


def test_merl_fold_seam_marks_a_corpus_table_that_is_not_reciprocal(corpus):
    """chm_mint's network, sampled on phi_d in [0, pi), jumps across the fold by a factor
    ~1.4: at normal view every light reads phi_d = 0, so the data's albedo there exceeds its
    albedo half a degree off by over 10 % (no reciprocal fit follows both). A near-reciprocal
    corpus table (blue-metallic-paint) jumps by 1.4 % and its albedo is continuous."""
    from microfacet.metrics import directional_albedo
    for name, seamless in (("merl/blue-metallic-paint", True), ("rgl/chm_mint_rgb", False)):
        data = mf.measured.load(corpus(name))
        albedo = directional_albedo(data, (0.0, 0.5))
        jump = np.max(albedo[0] / albedo[1])
        if seamless:
            assert data.fold_seam() < 0.02 and jump < 1.01, (name, data.fold_seam(), jump)
        else:
            assert data.fold_seam() > merl.SEAM_LIMIT and jump > 1.1, (name, data.fold_seam(), jump)


def test_merl_interpolation_cache(smooth_file, monkeypatch):
    """Data and coverage on the same pairs interpolate once; a cached answer equals the
    computed one, is a fresh array (mutating it changes nothing), and other pairs miss."""
    m = mf.measured.load(smooth_file)
    rng = np.random.default_rng(7)
    wi, wo, _ = hd_directions(rng, rng.uniform(0, 1.4, 500), rng.uniform(0, 1.4, 500), rng.uniform(0, 3, 500))
    expected = m._interpolate_uncached(*np.broadcast_arrays(wi, wo))
    calls = []
    compute = m._interpolate_uncached
    monkeypatch.setattr(m, "_interpolate_uncached", lambda a, b: calls.append(len(a)) or compute(a, b))
    cover = m.coverage(wi, wo)
    f = m._eval_numpy(wi, wo)
    assert calls == [500]
    np.testing.assert_array_equal(cover, expected[1])
    np.testing.assert_array_equal(f, expected[0])
    f[:] = -1.0
    np.testing.assert_array_equal(m._eval_numpy(wi.copy(), wo.copy()), expected[0])   # by content
    assert calls == [500]
    m._eval_numpy(wo, wi)                                   # other pairs
    assert calls == [500, 500]
    for k in range(merl.CACHE_SIZE):                        # evicts the oldest
        m.coverage(wi[k + 1:], wo[k + 1:])
    m.coverage(wi, wo)
    assert len(calls) == 3 + merl.CACHE_SIZE and len(m._cache) == merl.CACHE_SIZE
    monkeypatch.setattr(merl, "CACHE_MAX_PAIRS", 100)       # larger sets are not kept
    m._cache.clear()
    m.coverage(wi, wo), m.coverage(wi, wo)
    assert len(calls) == 5 + merl.CACHE_SIZE and not m._cache


def test_merl_interpolation_in_blocks(smooth_file, monkeypatch):
    """The NumPy path's blocks of pairs (the last one short) give the same values and
    coverage, of the pairs' leading shape, as one block of them all."""
    m = mf.measured.load(smooth_file)
    rng = np.random.default_rng(8)
    wi, wo, _ = hd_directions(rng, rng.uniform(0, 1.4, 500), rng.uniform(0, 1.4, 500), rng.uniform(0, 3, 500))
    wi, wo = wi.reshape(20, 25, 3), wo.reshape(20, 25, 3)
    whole = m._interpolate_uncached(wi, wo)
    monkeypatch.setattr(merl, "BLOCK", 7)
    blocks = m._interpolate_uncached(wi, wo)
    assert blocks[0].shape == (20, 25, 3) and blocks[1].shape == (20, 25)
    np.testing.assert_array_equal(blocks[0], whole[0])
    np.testing.assert_array_equal(blocks[1], whole[1])
    assert np.count_nonzero(whole[1]) > 250                 # not vacuous


def test_merl_bad_files(tmp_path, smooth_raw):
    good = merl_bytes(smooth_raw)
    cases = {
        "header.binary": (merl_bytes(smooth_raw[:, :, :, :90], header=(90, 90, 90)), r"bin counts \(90, 90, 90\)"),
        "truncated.binary": (good[:1_000_000], "truncated"),
        "trailing.binary": (good + b"\0" * 8, "trailing"),
        "empty.binary": (b"", "unknown"),
        "truncated.binary.gz": (gzip.compress(good, compresslevel=1)[:100_000], "gzip"),
    }
    bad = smooth_raw.copy()
    bad[2, 5, 5, 5] = np.nan
    cases["nan.binary"] = (merl_bytes(bad), "NaN")
    bad[2, 5, 5, 5] = np.inf
    cases["inf.binary.gz"] = (gzip.compress(merl_bytes(bad), compresslevel=1), "NaN or infinite")
    for name, (data, what) in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        before = digest(path)
        with pytest.raises(mf.MicrofacetError, match=what) as e:
            mf.measured.load(path)
        assert name in str(e.value)
        assert digest(path) == before              # inputs are never modified
    with pytest.raises(mf.MicrofacetError, match="missing.binary: no such file"):
        mf.measured.load(tmp_path / "missing.binary")
    with pytest.raises(mf.MicrofacetError, match="is a directory, not a measured BRDF"):
        mf.measured.load(tmp_path)


def test_merl_header_mismatch_message(tmp_path):
    path = tmp_path / "dims.binary"
    path.write_bytes(np.array([90, 90, 180], "<i4").tobytes()[:8] + np.array([90], "<i4").tobytes() + b"\0" * 64)
    with pytest.raises(mf.MicrofacetError, match="unknown measured-BRDF format"):
        mf.measured.load(path)
    with pytest.raises(mf.MicrofacetError, match=r"bin counts \(90, 90, 90\)"):
        merl.read_merl(np.array([90, 90, 90], "<i4").tobytes() + b"\0" * 64, path)


def test_protocol_cosine_sampling(smooth_file):
    m = mf.measured.load(smooth_file)
    rng = np.random.default_rng(5)
    wo = uniform_dirs(rng, 500)
    wi, weight, pdf = m.sample(rng.random((500, 2)), wo)
    np.testing.assert_allclose(pdf, wi[:, 2] / np.pi)
    np.testing.assert_allclose(pdf, m.pdf(wi, wo))
    np.testing.assert_allclose(weight, m.eval_cos(wi, wo) / pdf[:, None])
    np.testing.assert_allclose(m.eval_cos(wi, wo), m.eval(wi, wo) * wi[:, 2:3])
    # below the horizon: zeros, never NaN; leading dimensions broadcast
    below = wo * [1, 1, -1]
    assert np.all(m.eval(wi, below) == 0) and np.all(m.pdf(wi, below) == 0)
    assert np.all(m.sample(rng.random((500, 2)), below)[1] == 0)
    assert m.eval(wi[:5, None], wo[None, :4]).shape == (5, 4, 3)


# ============================================================================ UTIA
def utia_function(ti, pi_, tv, pv) -> np.ndarray:
    v = 1.0 + np.cos(ti) * np.cos(tv) + 0.2 * np.cos(pi_ - pv) + 0.05 * np.sin(2 * pi_)
    return np.stack([v, 0.5 * v, 2.0 * v], axis=-1)


def utia_bytes(fn) -> bytes:
    """Raw UTIA file: physical values encoded as ``140 srgb_encode(value / 100)``."""
    t, p = np.radians(np.arange(6) * 15.0), np.radians(np.arange(48) * 7.5)
    value = fn(*np.meshgrid(t, p, t, p, indexing="ij"))
    c = value / 100.0
    enc = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.ascontiguousarray(np.moveaxis(140.0 * enc, -1, 0), "<f8").tobytes()


def test_utia_round_trip_and_interpolation(tmp_path):
    path = tmp_path / "synthetic.bin"
    path.write_bytes(utia_bytes(utia_function))
    m = mf.measured.load(path)
    assert isinstance(m, mf.measured.UTIABRDF)
    rng = np.random.default_rng(6)
    i = rng.integers(0, 6, (2, 500)) * np.radians(15.0)
    p = rng.integers(0, 48, (2, 500)) * np.radians(7.5)
    wi, wo = spherical_to_cartesian(i[0], p[0]), spherical_to_cartesian(i[1], p[1])
    ok = (i[0] > 0) & (i[1] > 0)                   # at the pole phi is not defined
    np.testing.assert_allclose(m.eval(wi, wo)[ok], utia_function(i[0], p[0], i[1], p[1])[ok], rtol=1e-12)
    # periodic in phi: 356.25 deg is halfway between the 352.5 and 0 (= 360) samples
    ti, tv = np.radians(30.0), np.radians(45.0)
    half = m.eval(spherical_to_cartesian(ti, np.radians(356.25)), spherical_to_cartesian(tv, 0.0))
    ends = [m.eval(spherical_to_cartesian(ti, np.radians(a)), spherical_to_cartesian(tv, 0.0)) for a in (352.5, 0.0)]
    np.testing.assert_allclose(half, 0.5 * (ends[0] + ends[1]), rtol=1e-12)
    # elevations beyond 75 degrees are clamped
    np.testing.assert_allclose(m.eval(spherical_to_cartesian(np.radians(85.0), 0.3), wo[:1]),
                               m.eval(spherical_to_cartesian(np.radians(75.0), 0.3), wo[:1]), rtol=1e-12)
    # smooth in between: quadrilinear error well below 5 %
    wi, wo = uniform_dirs(rng, 2000), uniform_dirs(rng, 2000)
    (ti, pi_), (tv, pv) = mf.geometry.cartesian_to_spherical(wi), mf.geometry.cartesian_to_spherical(wo)
    inside = (ti < np.radians(75)) & (tv < np.radians(75))
    ref = utia_function(ti, pi_, tv, pv)[inside]
    assert np.max(np.abs(m.eval(wi, wo)[inside] / ref - 1)) < 0.05


def test_utia_decoding_and_errors(tmp_path):
    raw = np.zeros(utia.SHAPE)
    raw[0, 0, 0, 0, 0], raw[1, 0, 0, 0, 0], raw[2, 0, 0, 0, 0] = 140.0, 140.0 * 0.04, -3.0
    path = tmp_path / "decode.bin"
    path.write_bytes(raw.astype("<f8").tobytes())
    v = mf.measured.load(path).values[0, 0, 0, 0]
    np.testing.assert_allclose(v, [100.0, 100.0 * 0.04 / 12.92, 0.0])   # negative raw clamps to 0
    raw[0, 1, 2, 3, 4] = np.nan
    path.write_bytes(raw.astype("<f8").tobytes())
    with pytest.raises(mf.MicrofacetError, match=r"decode\.bin.*NaN"):
        mf.measured.load(path)
    path.write_bytes(raw.astype("<f8").tobytes()[:-8])
    with pytest.raises(mf.MicrofacetError, match="unknown measured-BRDF format"):
        mf.measured.load(path)
    raw[0, 1, 2, 3, 4] = 1e200                    # finite but decodes to inf (found by fuzzing)
    path.write_bytes(raw.astype("<f8").tobytes())
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(mf.MicrofacetError, match=r"decode\.bin.*decoded to RGB holds 1 NaN or infinite"):
            mf.measured.load(path)


# ============================================================================= RGL
def synthetic_rgl(rng, phi_i=(0.0,), n_theta=4) -> dict:
    """A small, smooth, positive RGL-style tensor file (1 or more phi_i slices)."""
    phi_i = np.asarray(phi_i, np.float32)
    theta_i = np.linspace(0, np.pi / 2 * 0.9, n_theta).astype(np.float32)
    n_phi = len(phi_i)
    u = np.linspace(0, 1, 16)
    bump = lambda s: np.exp(-(u[:, None] ** 2 + u[None, :] ** 2) / s)  # noqa: E731
    tab = lambda *shape: (rng.uniform(0.5, 1.5, shape) * 0.2 + 1.0).astype(np.float32)  # noqa: E731
    return {
        "version": np.array([1, 0], np.uint32),
        "description": np.frombuffer(b"synthetic test material", np.uint8),
        "phi_i": phi_i, "theta_i": theta_i,
        "sigma": np.repeat(np.linspace(1.0, 0.4, 32)[None], 2, 0).astype(np.float32),
        "ndf": np.repeat(np.exp(-np.linspace(0, 1, 32) ** 2 * 6)[None] * 3, 2, 0).astype(np.float32),
        "vndf": (tab(n_phi, n_theta, 16, 16) * bump(0.3)).astype(np.float32),
        "luminance": tab(n_phi, n_theta, 8, 8),
        "rgb": (tab(n_phi, n_theta, 3, 8, 8) - 0.15).astype(np.float32),
        "jacobian": np.array([1], np.uint8),
        "valid": np.ones(8, np.uint8),
    }


@pytest.fixture(scope="module")
def mitsuba():
    mi = pytest.importorskip("mitsuba", reason="the RGL cross-check needs the optional `mitsuba` package")
    if "scalar_rgb" not in mi.variants():
        pytest.skip("this Mitsuba build has no scalar_rgb variant")
    previous = mi.variant()
    mi.set_variant("scalar_rgb")
    yield mi
    if previous is not None:
        mi.set_variant(previous)


def mitsuba_eval(mi, path, rng, n: int):
    """``(wi, wo, f cos theta_i)`` from Mitsuba's ``measured`` plugin (``si.wi = wo``) on
    float32 directions: half the lights sampled by the plugin (in its lobe), half uniform."""
    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    ctx, si = mi.BSDFContext(), mi.SurfaceInteraction3f()
    f32 = lambda a: np.asarray(a, np.float32).astype(np.float64)  # noqa: E731
    wo = f32(uniform_dirs(rng, n // 2))
    sampled = []
    for v, s in zip(wo, rng.random((len(wo), 2))):
        si.wi = mi.Vector3f(*v)
        sampled.append(np.array(bsdf.sample(ctx, si, 0.5, mi.Point2f(*s))[0].wo))
    wi = f32(np.concatenate([np.array(sampled), uniform_dirs(rng, len(wo))]))
    wo = np.concatenate([wo, wo])
    theirs = []
    for light, view in zip(wi, wo):
        si.wi = mi.Vector3f(*view)
        theirs.append(np.array(bsdf.eval(ctx, si, mi.Vector3f(*light))))
    return wi, wo, np.array(theirs)


def check_against_mitsuba(mi, path, rng, n=300):
    wi, wo, theirs = mitsuba_eval(mi, path, rng, n)
    ours = mf.measured.load(path).eval_cos(wi, wo)
    err, scale = np.abs(ours - theirs), np.abs(theirs).max()
    used = err / (RTOL * np.abs(theirs) + ATOL * scale)      # share of the tolerance used
    assert np.all(used <= 1), used.max()
    assert np.count_nonzero(theirs) > n            # the comparison is not vacuous
    big = np.abs(theirs) > 1e-2 * scale
    return err.max() / scale, np.max(err[big] / np.abs(theirs[big])), used.max()


def test_rgl_synthetic_against_mitsuba(tmp_path, mitsuba):
    rng = np.random.default_rng(7)
    iso = tmp_path / "iso.bsdf"
    iso.write_bytes(write_tensor_file(synthetic_rgl(rng)))
    check_against_mitsuba(mitsuba, iso, rng, 200)
    # anisotropic, stored over a half turn of phi_i (Mitsuba's "reduction" 2: mirrored)
    aniso = tmp_path / "aniso.bsdf"
    aniso.write_bytes(write_tensor_file(synthetic_rgl(rng, phi_i=np.linspace(-np.pi, 0, 5))))
    m = mf.measured.load(aniso)
    assert not m.isotropic and m.reduction == 2
    check_against_mitsuba(mitsuba, aniso, rng, 200)


@pytest.mark.parametrize("name", ["cc_ibiza_sunset_rgb.bsdf", "paper_white_rgb.bsdf"])
def test_rgl_real_against_mitsuba(name, mitsuba):
    check_against_mitsuba(mitsuba, needs_data("rgl", name), np.random.default_rng(8), 300)


@pytest.mark.parametrize("name, spread", [("cc_ibiza_sunset_rgb.bsdf", 0.25), ("paper_white_rgb.bsdf", 0.03)])
def test_rgl_sanity(name, spread):
    path = needs_data("rgl", name)
    before = digest(path)
    m = mf.measured.load(path)
    assert digest(path) == before and m.format == "rgl" and m.isotropic
    rng = np.random.default_rng(9)
    wi, wo = uniform_dirs(rng, 20000), uniform_dirs(rng, 20000)
    f, g = m.eval(wi, wo), m.eval(wo, wi)
    lum = f.mean(axis=-1)
    assert np.all(np.isfinite(f)) and np.mean(lum > 0) > 0.99 and lum.min() > -1e-3 * lum.max()
    # reciprocity holds only roughly for measured data (noise; tables parameterized by
    # the view, 8 elevations apart, blur sharp lobes differently): no bias and a
    # material-dependent spread (the paper's 3 % pins the cosine factor to the light
    # direction: with the view's cosine its spread is 70 %)
    big = (lum > 0.05 * np.percentile(lum, 99)) & (wi[:, 2] > 0.2) & (wo[:, 2] > 0.2)
    ratio = g[big] / f[big]
    assert abs(np.median(ratio) - 1) < 0.05 and np.median(np.abs(ratio - 1)) < spread
    # the file's own NDF: D(z) is the first sample, and int D cos = 1 (up to interpolation)
    np.testing.assert_allclose(m.ndf(np.array([0.0, 0.0, 1.0])), m.ndf_table[0, 0], rtol=1e-6)
    t = (np.arange(2000) + 0.5) / 2000 * np.pi / 2
    h = spherical_to_cartesian(t, 0.0)
    assert abs(np.sum(m.ndf(h) * np.cos(t) * np.sin(t)) * (np.pi / 2 / 2000) * 2 * np.pi - 1) < 0.02
    assert m.ndf_table.shape == (2, 128) and "rgb" in m.fields and m.description


def test_tensor_file_round_trip_and_errors(tmp_path):
    rng = np.random.default_rng(10)
    fields = synthetic_rgl(rng)
    data = write_tensor_file(fields)
    back = read_tensor_file(data, "mem")
    for k, v in fields.items():
        np.testing.assert_array_equal(back[k], v)
        assert back[k].dtype == v.dtype
    cases = {
        "version.bsdf": (data[:12] + b"\2\0" + data[14:], "version"),
        "header.bsdf": (data[:30], "truncated or corrupt"),
        "data.bsdf": (data[:-200], "truncated: field"),
    }
    spectral = {k: v for k, v in fields.items() if k != "rgb"}
    spectral["spectra"] = fields["rgb"]
    cases["spectral.bsdf"] = (write_tensor_file(spectral), "lacks the field 'rgb'.*_rgb variant")
    nan = dict(fields, ndf=fields["ndf"].copy())
    nan["ndf"][0, 3] = np.nan
    cases["nan.bsdf"] = (write_tensor_file(nan), "'ndf' holds 1 NaN")
    cases["dtype.bsdf"] = (write_tensor_file(dict(fields, sigma=fields["sigma"].astype(np.float64))), "'sigma' is float64")
    cases["shape.bsdf"] = (write_tensor_file(dict(fields, rgb=fields["rgb"][:, :2])), "tables disagree")
    tiny = write_tensor_file({"a": np.zeros((1, 1), np.float32)})       # its shape is at bytes 32..48
    for dims, what in (((0, 2**62), "impossible shape"), ((2**40, 2**40), "impossible shape"),
                       ((2**33, 2**31), "impossible shape")):              # found by fuzzing: overflow, reshape
        cases[f"shape{dims[1]}.bsdf"] = (tiny[:32] + struct.pack("<2Q", *dims) + tiny[48:], what)
    for name, (blob, what) in cases.items():
        path = tmp_path / name
        path.write_bytes(blob)
        with pytest.raises(mf.MicrofacetError, match=what) as e:
            mf.measured.load(path)
        assert name in str(e.value)


if __name__ == "__main__":                          # print the Mitsuba cross-check errors
    import mitsuba as mi

    mi.set_variant("scalar_rgb")
    for name in ("cc_ibiza_sunset_rgb.bsdf", "paper_white_rgb.bsdf"):
        path = DATA / "rgl" / name
        if path.exists():
            worst_abs, worst_rel, used = check_against_mitsuba(mi, path, np.random.default_rng(8), 300)
            print(f"{name}: max |ours - mitsuba| / max|mitsuba| = {worst_abs:.2e}, max relative "
                  f"error (values > 1 % of max) = {worst_rel:.2e}, share of tolerance used {used:.2f}")


# ================================================= compiled loops against the NumPy reference
#: The compiled loops repeat the reference's operations in its order; they differ only where
#: NumPy's SIMD arcsin / arctan2 differ from libm's (by an ulp, in ~8 % of the inputs).
#: MERL and UTIA interpolate linearly in those angles: relative error ~1e-14. RGL's VNDF
#: warp amplifies a coordinate error by up to ~1e5 at grazing angles, where the values are
#: also cancellations (interpolants crossing zero, D ~ 1e-11): there the tolerance has an
#: absolute part, 1e-13 of the largest value (measured: <= 6e-15 of it; relative error
#: <= 1.1e-11 on values above 1e-6 of the largest, on 1e5 pairs of the real files).
KERNEL_RTOL = 1e-10


def kernel_pairs(rng, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(wi, wo, u)``: ``n`` pairs over the whole sphere (a quarter of each below the
    horizon), a tenth grazing (``|cos theta|`` down to 1e-12), some at the pole, some at
    the azimuth seam (``phi = +-pi`` and just below) and some mirror pairs (``wi = -wo``:
    zero half vector)."""
    def dirs():
        cos = rng.uniform(-1, 1, n)
        graze = rng.random(n) < 0.1
        cos[graze] = np.copysign(10.0 ** rng.uniform(-12, -2, graze.sum()), cos[graze])
        w = spherical_to_cartesian(np.arccos(cos), rng.uniform(-np.pi, np.pi, n))
        w[:20] = [0.0, 0.0, 1.0]
        w[40:60] = [[-0.6, 0.0, 0.8], [-0.6, -0.0, 0.8], [-0.6, -1e-300, 0.8], [-0.6, 1e-17, 0.8]] * 5
        return w
    wi, wo = dirs(), dirs()
    wi[20:40] = -wo[20:40]
    u = rng.random((n, 2))
    u[:10] = [[0.5, 0.5], [0, 0], [1, 1], [0, 1], [1, 0], [0.5, 0], [0, 0.5], [1, 0.5], [0.5, 1], [0.25, 0.75]]
    return wi, wo, u


def assert_kernels_match(m, rng, monkeypatch, n=10_000, atol=0.0):
    """eval, eval_cos and sample of the compiled loops equal the NumPy reference:
    ``KERNEL_RTOL`` relative to each value plus ``atol`` times the largest one, and
    ``KERNEL_RTOL`` relative on values above 1e-6 of the largest."""
    pytest.importorskip("numba")
    from microfacet import kernels
    if not kernels.AVAILABLE:
        pytest.skip("Numba disabled (MICROFACET_NUMBA=0)")
    wi, wo, u = kernel_pairs(rng, n)
    ours = [m.eval(wi, wo), m.eval_cos(wi, wo), *m.sample(u, wo)]
    monkeypatch.setattr(kernels, "AVAILABLE", False)
    assert m._kernel() is None
    ref = [m.eval(wi, wo), m.eval_cos(wi, wo), *m.sample(u, wo)]
    monkeypatch.undo()
    for name, a, b in zip(("eval", "eval_cos", "wi", "weight", "pdf"), ours, ref):
        assert a.shape == b.shape and np.all(np.isfinite(a)), name
        scale = np.abs(b).max()
        np.testing.assert_allclose(a, b, rtol=KERNEL_RTOL, atol=atol * scale, err_msg=name)
        big = np.abs(b) > 1e-6 * scale
        np.testing.assert_allclose(a[big], b[big], rtol=KERNEL_RTOL, atol=0, err_msg=name)
    assert np.count_nonzero(ref[0]) > n // 3          # not vacuous: most upper pairs are nonzero
    # leading axes broadcast: the (5, 4) grid of pairs is the flat batch of the same pairs
    grid = m.eval(wi[:5, None], wo[None, :4])
    flat = m.eval(np.repeat(wi[:5], 4, axis=0), np.tile(wo[:4], (5, 1)))
    np.testing.assert_array_equal(grid.reshape(-1, 3), flat)


def test_kernels_merl(tmp_path, linear_raw, smooth_file, monkeypatch):
    rng = np.random.default_rng(20)
    assert_kernels_match(mf.measured.load(smooth_file), rng, monkeypatch)
    raw = linear_raw.copy()
    raw[:, 40:50] = -1.0                           # unmeasured samples: renormalized weights, zeros
    raw[2, 10, 20:40] = -1.0
    path = tmp_path / "holes.binary"
    path.write_bytes(merl_bytes(raw))
    assert_kernels_match(mf.measured.load(path), rng, monkeypatch)


@pytest.mark.parametrize("name", ["nickel.binary.gz", "violet-acrylic.binary.gz"])
def test_kernels_merl_real(name, monkeypatch):
    assert_kernels_match(mf.measured.load(needs_data("merl", name)), np.random.default_rng(21), monkeypatch)


def test_kernels_utia(tmp_path, monkeypatch):
    path = tmp_path / "synthetic.bin"
    path.write_bytes(utia_bytes(utia_function))
    assert_kernels_match(mf.measured.load(path), np.random.default_rng(22), monkeypatch)


@pytest.mark.parametrize("phi_i, clip", [((0.0,), False), ((0.0, np.pi), True),
                                         (np.linspace(-np.pi, 0, 5), False), (np.linspace(-np.pi / 2, 0, 3), True)])
def test_kernels_rgl_synthetic(tmp_path, phi_i, clip, monkeypatch):
    rng = np.random.default_rng(23)
    fields = synthetic_rgl(rng, phi_i=phi_i)
    path = tmp_path / "synthetic.bsdf"
    path.write_bytes(write_tensor_file(fields))
    m = mf.measured.load(path)
    m.clip_negative = clip
    assert m.reduction == {1: 0, 2: 0, 5: 2, 3: 4}[len(phi_i)]
    assert_kernels_match(m, rng, monkeypatch, atol=1e-13)
    fields["jacobian"] = np.array([0], np.uint8)          # tables without the NDF / sigma factor
    path.write_bytes(write_tensor_file(fields))
    assert_kernels_match(mf.measured.load(path), rng, monkeypatch, atol=1e-13)


@pytest.mark.parametrize("name", ["cc_ibiza_sunset_rgb.bsdf", "paper_white_rgb.bsdf"])
def test_kernels_rgl_real(name, monkeypatch):
    assert_kernels_match(mf.measured.load(needs_data("rgl", name)), np.random.default_rng(24), monkeypatch,
                         atol=1e-13)


def test_kernels_parallel_batches(tmp_path, smooth_file):
    """A batch above ``PARALLEL_MIN`` (Numba's threads, blocks split among them) gives the
    values of the same pairs evaluated in small single-threaded batches."""
    pytest.importorskip("numba")
    from microfacet import kernels
    if not kernels.AVAILABLE:
        pytest.skip("Numba disabled (MICROFACET_NUMBA=0)")
    rng = np.random.default_rng(25)
    path = tmp_path / "synthetic.bsdf"
    path.write_bytes(write_tensor_file(synthetic_rgl(rng)))
    n = kernels.PARALLEL_MIN + 37                          # not a multiple of the block size
    wi, wo, u = kernel_pairs(rng, n)
    for m in (mf.measured.load(path), mf.measured.load(smooth_file)):
        chunks = range(0, n, 4096)
        np.testing.assert_array_equal(m.eval(wi, wo), np.concatenate([m.eval(wi[i:i + 4096], wo[i:i + 4096])
                                                                      for i in chunks]))
        big = m.sample(u, wo)
        for part, whole in zip(zip(*(m.sample(u[i:i + 4096], wo[i:i + 4096]) for i in chunks)), big):
            np.testing.assert_array_equal(np.concatenate(part), whole)
