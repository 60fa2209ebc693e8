"""The compiled Smith kernel against the NumPy reference it replaces."""
import os

import numpy as np
import pytest

import microfacet as mf
from microfacet import kernels

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (or MICROFACET_NUMBA=0)")


def _same_support(a, b):
    """``a > 0`` where ``b > 0`` and conversely, except at subnormal values (< 1e-300), which
    round to 0 on one side and not the other near the underflow threshold."""
    return not np.any(((a > 0) != (b > 0)) & (np.maximum(a, b) >= 1e-300))


def _dirs(rng, n):
    w = mf.geometry.normalize(rng.normal(size=(n, 3)))
    w[: n // 2, 2] = np.abs(w[: n // 2, 2])           # half upper, half anywhere
    return w


@pytest.mark.parametrize("D", [mf.Beckmann, mf.GGX], ids=lambda D: D.__name__)
@pytest.mark.parametrize("kw", [dict(alpha=0.3), dict(alpha=1e-4), dict(alpha=2.0),
                                dict(alpha_x=0.05, alpha_y=0.7, rho=-0.8, mean_slope=(0.9, -0.4))])
@pytest.mark.parametrize("shadowing", [True, False])
def test_kernel_matches_numpy(D, kw, shadowing):
    rng = np.random.default_rng(12)
    brdf = mf.MicrofacetBRDF(D(**kw), shadowing=shadowing)
    wi, wo = _dirs(rng, 20000), _dirs(rng, 20000)
    wi[:100] = mf.geometry.reflect(wo[:100], [0, 0, 1.0])        # mirror configurations
    wo[100:110] = [1.0, 0, 0]                                    # grazing
    for divide in (False, True):
        oh_fast, s_fast = kernels.smith_projected(brdf.distribution, shadowing, wi, wo, divide)
        oh_ref, s_ref = brdf._projected_numpy(wi, wo, divide)
        assert np.all(np.isfinite(s_fast))
        np.testing.assert_allclose(oh_fast, oh_ref, rtol=1e-14, atol=1e-15)
        np.testing.assert_allclose(s_fast, s_ref, rtol=1e-12, atol=1e-300)   # subnormals keep fewer digits
        assert _same_support(s_fast, s_ref)


def test_kernel_shapes_and_fallbacks():
    d = mf.GGX(alpha=0.3)
    wi = np.broadcast_to(mf.geometry.normalize([0.3, 0.1, 0.95]), (4, 5, 3))
    wo = np.array([0.0, 0.0, 1.0])
    oh, s = kernels.smith_projected(d, True, wi, wo, False)
    assert oh.shape == s.shape == (4, 5)
    assert kernels.smith_projected(mf.GGX(alpha=np.full(5, 0.3)), True, wi, wo, False) is None
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=np.array([0.1, 0.3, 0.9])))    # per-texel parameters
    np.testing.assert_allclose(brdf.eval(wi[0, :3], wo), brdf._projected_numpy(wi[0, :3], wo, True)[1][:, None]
                               * np.ones(3), rtol=1e-14)


def test_compiled_conductor_fresnel_matches_numpy():
    from microfacet.fresnel import conductor_reflectance
    c = np.concatenate([np.linspace(0, 1, 1001), [0.0, 1.0]])
    f = mf.fresnel.Conductor.metal("Au")
    ref = np.stack([conductor_reflectance(c, e, k) for e, k in zip(f.eta, f.k)], axis=-1)   # NumPy
    np.testing.assert_allclose(f(c), ref, rtol=1e-14, atol=1e-16)


FRESNELS = [mf.fresnel.Ideal(), mf.fresnel.Schlick((0.04, 0.5, 1.0)), mf.fresnel.Dielectric(1.5),
            mf.fresnel.Dielectric(0.7),                                   # total internal reflection
            mf.fresnel.Conductor.metal("Cu"),
            mf.fresnel.Tabulated([0.0, 0.2, 0.5, 0.9, 1.0], [[0.9, 0.1, 0.5], [0.5, 0.2, 0.4], [0.3, 0.3, 0.3],
                                                          [0.1, 0.4, 0.2], [0.05, 0.5, 0.1]])]


@pytest.mark.parametrize("D", [mf.Beckmann, mf.GGX], ids=lambda D: D.__name__)
@pytest.mark.parametrize("kw", [dict(alpha=0.3), dict(alpha=2.0),
                                dict(alpha_x=0.05, alpha_y=0.7, rho=-0.8, mean_slope=(0.9, -0.4))],
                         ids=["iso", "rough", "sheared"])
@pytest.mark.parametrize("fresnel", FRESNELS, ids=lambda f: type(f).__name__ + str(np.round(getattr(f, "eta", [0])[0], 1)))
@pytest.mark.parametrize("shadowing", [True, False])
def test_fused_eval_pdf_sample_match_numpy(D, kw, fresnel, shadowing):
    """Every compiled combination (distribution x Smith x Fresnel) equals the NumPy reference
    to 1e-12 (relative; absolute 1e-12 for sample weights, whose grazing wi amplify rounding)."""
    rng = np.random.default_rng(7)
    brdf = mf.MicrofacetBRDF(D(**kw), fresnel=fresnel, shadowing=shadowing)
    wi, wo, u = _dirs(rng, 4000), _dirs(rng, 4000), rng.random((4000, 2))
    wi[:50] = mf.geometry.reflect(wo[:50], [0, 0, 1.0])
    u[:4] = [[0.0, 0.0], [1.0, 1.0], [0.5, 0.5], [0.0, 1.0]]                # corners of the square
    for divide in (False, True):
        oh, s = brdf._projected_numpy(wi, wo, divide)
        fast = kernels.smith_eval(brdf, wi, wo, divide)[0]
        np.testing.assert_allclose(fast, fresnel(oh) * s[:, None], rtol=1e-12, atol=1e-300)   # subnormals keep fewer digits
    np.testing.assert_allclose(kernels.smith_pdf(brdf, wi, wo)[0], brdf._pdf_numpy(wi, wo), rtol=1e-12, atol=1e-300)   # subnormals keep fewer digits
    wi_s, weight, pdf = kernels.smith_sample(brdf, u, wo)[0]
    wi_r, weight_r, pdf_r = brdf._sample_numpy(u, wo)
    np.testing.assert_allclose(wi_s, wi_r, rtol=0, atol=1e-12)
    np.testing.assert_allclose(pdf, pdf_r, rtol=1e-12, atol=1e-300)   # subnormals keep fewer digits
    np.testing.assert_allclose(weight, weight_r, rtol=1e-12, atol=1e-12)
    assert _same_support(pdf, pdf_r) and np.any(pdf > 0)
    assert np.all(np.isfinite(weight)) and np.all(np.isfinite(pdf))


def test_fused_kernels_used_and_fallbacks():
    """The protocol methods take the kernels (same values, broadcast shapes) and fall back
    to NumPy for what they do not cover (another GAF, a custom Fresnel)."""
    rng = np.random.default_rng(3)
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.4), fresnel=mf.fresnel.Schlick(0.1))
    wi = _dirs(rng, 12).reshape(3, 4, 3)
    wo = mf.geometry.normalize([0.2, -0.1, 0.9])                          # broadcast view
    assert brdf.eval(wi, wo).shape == (3, 4, 3) and brdf.pdf(wi, wo).shape == (3, 4)
    np.testing.assert_allclose(brdf.pdf(wi, wo), brdf._pdf_numpy(wi, np.broadcast_to(wo, wi.shape)), rtol=1e-12)
    s = brdf.sample(rng.random((3, 4, 2)), wo)
    assert s[0].shape == s[1].shape == (3, 4, 3) and s[2].shape == (3, 4)

    class Half(mf.fresnel.Fresnel):
        def __call__(self, c):
            return np.full(np.shape(c) + (3,), 0.5)

    assert kernels.smith_eval(mf.MicrofacetBRDF(mf.GGX(alpha=0.4), fresnel=Half()), wi, wo, True) is None
    assert kernels.smith_pdf(mf.MicrofacetBRDF(mf.GGX(alpha=0.4), gaf="vgroove"), wi, wo) is None


def test_erfinv_matches_scipy():
    from scipy.special import erfinv
    y = np.concatenate([np.linspace(-0.999, 0.999, 2001), 1.0 - np.geomspace(2.0**-52, 0.5, 200),
                        -1.0 + np.geomspace(2.0**-52, 0.5, 200), [0.0, 1e-300]])
    k = kernels._kernels()
    got = np.array([k._erfinv(v) for v in y])
    np.testing.assert_allclose(got, erfinv(y), rtol=1e-13, atol=0)


def test_beckmann_quantile_matches_numpy_at_the_extremes():
    """The compiled Q2 (tabulated guess, safeguarded Halley) equals the NumPy reference's
    Newton-bisection to 1e-13 (absolute, relative above 1) for ``u`` from 0 to 1 (clamped to
    ``[2^-53, 1 - 2^-53]``) and views from normal to 1e-12 from grazing."""
    from microfacet.distributions.beckmann import visible_slope_quantile
    q = kernels._kernels()._visible_slope_quantile
    u = np.concatenate([[0.0, 2.0**-53], np.geomspace(1e-15, 0.5, 40), 1.0 - np.geomspace(1e-15, 0.5, 40),
                        [1.0 - 2.0**-53, 1.0], np.linspace(0.01, 0.99, 41)])
    for c in [1e-12, 1e-8, 1e-4, 0.01, 0.3, 0.7, 0.99, 1.0 - 1e-9, 1.0]:
        got = np.array([q(ui, c) for ui in u])
        ref = visible_slope_quantile(u, c)
        np.testing.assert_array_less(np.abs(got - ref), 1e-13 * np.maximum(1.0, np.abs(ref)), err_msg=f"cos theta {c}")


def test_gather_free_erfc_is_relatively_accurate():
    """:func:`_erfc_near` (``exp(-v^2) erfcx(v)``, a polynomial in ``4 / (4 + v)``) keeps 2.5e-15
    relative to SciPy on ``[0, 4]`` (1.8e-15 measured, SciPy's ``erfcx`` itself is 8e-16 off),
    which the Gaussian tails of the vectorized solve need, and 1e-15 absolute up to 30
    (Beckmann's Lambda; 7.8e-16 measured)."""
    import numba
    from scipy.special import erfc
    k = kernels._kernels()

    @numba.njit
    def near(v):
        out = np.empty(v.size)
        for j in range(v.size):
            out[j] = k._erfc_near(np.float64, v[j], np.exp(-v[j] * v[j]))
        return out

    v = np.concatenate([np.linspace(0.0, 4.0, 40001), np.geomspace(1e-300, 4.0, 2000)])
    np.testing.assert_allclose(near(v), erfc(v), rtol=2.5e-15, atol=0)
    v = np.linspace(0.0, 30.0, 30001)
    np.testing.assert_allclose(near(v), erfc(v), rtol=0, atol=1e-15)


def _elementwise(f, F):
    """A compiled loop applying a kernel helper ``f(F, x)`` to each element of a 1-D array."""
    import numba

    @numba.njit
    def run(x):
        out = np.empty_like(x)
        for j in range(x.size):
            out[j] = f(F, x[j])
        return out
    return run


@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=lambda t: np.dtype(t).name)
def test_beckmann_lambda_against_mpmath(dtype):
    """The kernels' ``Lambda(v)`` (:func:`_beckmann_lambda`: ``exp`` and ``erfcx`` polynomials in
    float64, a rational approximation of ``v (1 + Lambda)`` in float32) against mpmath at 30 digits, as
    only ``1 + Lambda`` is used: ``|error| / (1 + Lambda)`` below 1e-15 in float64 (5.5e-16 measured)
    and 4e-7 in float32 (3.3e-7 measured, 2.8 float32 ulps, near ``v = 3``), ``v`` from 1e-6 (grazing)
    to 30, densely where float32's ``1 + Lambda`` is near 1 and around the cuts at 3.5 and 6, 0 at
    ``inf``; and ``erfc = exp(-v^2) erfcx``
    (:func:`_erfc_near` given mpmath's ``exp(-v^2)``) to 1e-15 relative on ``[0, 4]`` in float64."""
    import mpmath
    import numba
    k = kernels._kernels()
    lam = _elementwise(k._beckmann_lambda, np.dtype(dtype).type)

    v = np.concatenate([np.geomspace(1e-6, 30.0, 2000), np.linspace(0.0, 8.0, 801)[1:],
                        np.linspace(1.0, 3.7, 2701), np.linspace(5.8, 6.2, 401)]).astype(dtype)
    with mpmath.workdps(30):
        x = [mpmath.mpf(float(t)) for t in v]
        ref = np.array([float((mpmath.exp(-t * t) / (t * mpmath.sqrt(mpmath.pi)) - mpmath.erfc(t)) / 2) for t in x])
        got = lam(v)
        assert got.dtype == dtype and lam(np.array([np.inf], dtype))[0] == 0.0
        assert np.max(np.abs(got - ref) / (1.0 + ref)) < (1e-15 if dtype == np.float64 else 4e-7)
        if dtype == np.float64:
            w = np.linspace(0.0, 4.0, 801)
            e = np.array([float(mpmath.exp(-mpmath.mpf(t) ** 2)) for t in w])
            ref_erfc = np.array([float(mpmath.erfc(t)) for t in w])

            @numba.njit
            def near(v, e):
                out = np.empty(v.size)
                for j in range(v.size):
                    out[j] = k._erfc_near(np.float64, v[j], e[j])
                return out
            np.testing.assert_allclose(near(w, e), ref_erfc, rtol=1e-15, atol=0)


def test_beckmann_visible_block_matches_numpy():
    """The vectorized visible-normal solve (fixed Halley steps from the guesses, the scalar
    solvers on the lanes that fail their tests) gives the NumPy reference's slopes ``x~ =
    Q2(u1)``, ``y~ = erfinv(2 u2 - 1)`` to 1e-14 and 2e-15 (absolute, relative above 1; 5e-15
    and 9e-16 measured), Gaussian tails, the upper tail and views from grazing to normal included."""
    import numba
    from microfacet.distributions.beckmann import visible_slope_quantile
    from scipy.special import erfinv
    k = kernels._kernels()

    @numba.njit
    def slopes(u, c):
        out, bk, xy = np.empty((3, k.BLOCK)), np.empty((4, k.BLOCK)), np.empty((2, c.size))
        for j0 in range(0, c.size, k.BLOCK):
            m = min(k.BLOCK, c.size - j0)
            k._beckmann_visible_block(u, 2 * j0, c[j0:j0 + m], (out[0], out[1], out[2]), (bk[0], bk[1], bk[2], bk[3]), m)
            xy[0, j0:j0 + m], xy[1, j0:j0 + m] = -out[0, :m] / out[2, :m], -out[1, :m] / out[2, :m]
        return xy

    rng = np.random.default_rng(11)
    n = 200_000
    tails = np.concatenate([[0.0, 2.0**-53, 1.0 - 2.0**-53, 1.0], np.geomspace(1e-16, 0.1, 2000),
                            1.0 - np.geomspace(1e-16, 0.1, 2000)])
    u = rng.random((n, 2))
    u[:tails.size, 0], u[-tails.size:, 1] = tails, tails
    c = np.concatenate([[0.0, 1e-12, 1e-8, 1e-4, 1.0 - 1e-9, 1.0], rng.random(n - 6)])
    rng.shuffle(c)
    x, y = slopes(u.ravel(), c)
    x_ref = visible_slope_quantile(u[:, 0], c)
    y_ref = erfinv(2.0 * np.clip(u[:, 1], 2.0**-53, 1.0 - 2.0**-53) - 1.0)
    np.testing.assert_array_less(np.abs(x - x_ref), 1e-14 * np.maximum(1.0, np.abs(x_ref)))
    np.testing.assert_array_less(np.abs(y - y_ref), 2e-15 * np.maximum(1.0, np.abs(y_ref)))


@pytest.mark.parametrize("D", [mf.Beckmann, mf.GGX], ids=lambda D: D.__name__)
def test_float32_mode_of_the_numpy_path_is_float64_rounded(D):
    """``dtype=np.float32`` on the NumPy path (here V-groove): float32 results equal to the
    float64 ones on the same inputs to float32 rounding (relative 1e-6; absolute 1e-6 of the
    largest value), from float32 or float64 inputs."""
    rng = np.random.default_rng(5)
    cu = mf.fresnel.Conductor.metal("Cu")
    b64 = mf.MicrofacetBRDF(D(alpha_x=0.2, alpha_y=0.5), fresnel=cu, gaf="vgroove")
    b32 = mf.MicrofacetBRDF(D(alpha_x=0.2, alpha_y=0.5), fresnel=cu, gaf="vgroove", dtype=np.float32)
    wi, wo = _dirs(rng, 3000).astype(np.float32), _dirs(rng, 3000).astype(np.float32)
    u = rng.random((3000, 2)).astype(np.float32)

    def close(a32, a64):
        assert a32.dtype == np.float32 and a32.shape == a64.shape
        np.testing.assert_allclose(a32, a64, rtol=1e-6, atol=1e-6 * np.max(np.abs(a64)))

    for op in ("eval", "eval_cos", "pdf"):
        ref = getattr(b64, op)(wi, wo)
        close(getattr(b32, op)(wi, wo), ref)
        close(getattr(b32, op)(wi.astype(np.float64), wo.astype(np.float64)), ref)
    for a32, a64 in zip(b32.sample(u, wo), b64.sample(u, wo)):
        close(a32, a64)
    with pytest.raises(ValueError, match="dtype"):
        mf.MicrofacetBRDF(D(alpha=0.3), dtype=np.int32)


@pytest.mark.parametrize("D", [mf.Beckmann, mf.GGX], ids=lambda D: D.__name__)
@pytest.mark.parametrize("kw", [dict(alpha=0.05), dict(alpha=1.0),
                                dict(alpha_x=0.2, alpha_y=0.5, rho=0.3, mean_slope=(0.1, -0.2))],
                         ids=["smooth", "rough", "sheared"])
def test_float32_arithmetic_tolerance(D, kw):
    """The Smith kernels in float32 arithmetic (``dtype=np.float32``) against float64 on the same
    float32 inputs, where ``f`` is well-conditioned (``z_i, z_o > 0.05``, ``f cos`` and pdf above
    1e-6 of their largest value): ``f cos`` and pdf to 1e-5 relative for 99.9 % of the pairs and
    2e-4 for all (measured: 5e-6 and 1.2e-4); sampled ``wi`` to 3e-5 (99.9 %; measured 1.6e-5:
    ``z = sqrt(1 - x^2 - y^2)`` of GGX's disk map near its rim) and 2e-4 (all), their pdf to
    2e-3 and weight to 1e-4 relative (99.9 %; a grazing ``wi`` moved by 1e-5 changes ``G``), the
    same failed samples. Beckmann's Lambda and exp are float32 polynomials (:func:`_exp_neg`,
    :func:`_erfc_near`); its visible-slope solve stays float64."""
    rng = np.random.default_rng(5)
    cu = mf.fresnel.Conductor.metal("Cu")
    b64, b32 = mf.MicrofacetBRDF(D(**kw), fresnel=cu), mf.MicrofacetBRDF(D(**kw), fresnel=cu, dtype=np.float32)
    n = 20000
    wi, wo = _dirs(rng, n).astype(np.float32), _dirs(rng, n).astype(np.float32)
    u = rng.random((n, 2)).astype(np.float32)

    def rel(a32, a64, where):
        assert a32.dtype == np.float32 and a32.shape == a64.shape
        return (np.abs(a32 - a64) / np.where(a64 != 0, np.abs(a64), 1.0))[np.broadcast_to(where, a64.shape)]

    lit = (wi[:, 2] > 0.05) & (wo[:, 2] > 0.05)
    f64, p64 = b64.eval_cos(wi, wo), b64.pdf(wi, wo)
    f32 = b32.eval_cos(wi, wo)
    assert np.any(f32 != f64.astype(np.float32))                  # float32 arithmetic, not float64 rounded
    f_ok = lit[:, None] & (f64 > 1e-6 * f64.max())
    for r in (rel(f32, f64, f_ok), rel(b32.eval_cos(wi.astype(np.float64), wo.astype(np.float64)), f64, f_ok),
              rel(b32.pdf(wi, wo), p64, lit & (p64 > 1e-6 * p64.max()))):
        assert r.size > 100 and np.quantile(r, 0.999) < 1e-5 and r.max() < 2e-4
    (wi32, w32, pdf32), (wi64, w64, pdf64) = b32.sample(u, wo), b64.sample(u, wo)
    assert np.array_equal(pdf32 > 0, pdf64 > 0) and np.mean(pdf64 > 0) > 0.3
    ok = (pdf64 > 0) & (wo[:, 2] > 0.05)
    dw = np.max(np.abs(wi32 - wi64), axis=-1)[ok]
    assert np.quantile(dw, 0.999) < 3e-5 and dw.max() < 2e-4
    assert np.quantile(rel(pdf32, pdf64, ok), 0.999) < 2e-3
    assert np.quantile(rel(w32, w64, (ok & (wi64[:, 2] > 0.05))[:, None]), 0.999) < 1e-4


def test_vectorizable_exp_matches_numpy():
    """The kernels' ``exp`` (x <= 0; :func:`_exp_neg`), polynomials and bit operations only: float64
    to 2.2e-16 relative (1 ulp) down to -708, float32 to 1.2e-7 relative against float64 (1 ulp) down
    to -87, exactly 1 at 0; 0 below those bounds, where the value leaves the normal range (flushed:
    no subnormal result), and for NaN and -inf."""
    k = kernels._kernels()

    def exp(x):
        return _elementwise(k._exp_neg, x.dtype.type)(x)

    for F, lo, rtol, span in ((np.float64, -708.0, 2.3e-16, 746.0), (np.float32, -87.0, 1.2e-7, 105.0)):
        x = -np.concatenate([np.linspace(0.0, 60.0, 20001), np.geomspace(1e-30, span, 2000),
                             np.linspace(span - 40.0, span, 4001), [np.inf, np.nan]]).astype(F)
        got, e = exp(x), np.exp(x.astype(np.float64))
        assert got.dtype == F and got[0] == 1.0 and got[-1] == 0.0 and got[-2] == 0.0
        kept = x[:-2] > lo
        np.testing.assert_allclose(got[:-2][kept], e[:-2][kept], rtol=rtol, atol=0)
        assert np.all(got[:-2][~kept] == 0.0) and np.all(got[got > 0] >= np.finfo(F).tiny)


def test_vectorizable_log_matches_mpmath():
    """:func:`_log_pos` (the guesses' ``log``: bits and an ``atanh`` series) to 5e-16 relative
    against mpmath (4.4e-16 measured), from the smallest normal float to 1e300 and around 1
    (exactly 0 at 1)."""
    import mpmath
    import numba
    k = kernels._kernels()

    @numba.njit
    def log(x):
        out = np.empty_like(x)
        for j in range(x.size):
            out[j] = k._log_pos(x[j])
        return out

    x = np.concatenate([np.geomspace(2.3e-308, 1e300, 1001), np.linspace(0.5, 2.0, 1001),
                        1.0 + np.geomspace(2.3e-16, 1e-3, 200), 1.0 - np.geomspace(1.2e-16, 1e-3, 200)])
    with mpmath.workdps(30):
        ref = np.array([float(mpmath.log(mpmath.mpf(float(t)))) for t in x])
    np.testing.assert_allclose(log(x), ref, rtol=5e-16, atol=0)
    assert log(np.array([1.0]))[0] == 0.0


@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=lambda t: np.dtype(t).name)
def test_kernels_read_any_layout(dtype):
    """Strided, Fortran-ordered and broadcast inputs (copied block by block into a contiguous
    scratch) give the results of C-contiguous ones (read in place), bit for bit in float64; in
    float32 to 2e-6 relative: the two are compiled apart, and the float32 kernels' fast-math
    (contracted multiply-adds, approximate reciprocals) may round them differently (1.3e-6
    measured; against float64 both are as accurate, 1.2e-6 and 1.4e-6 worst on 10^5 pairs)."""
    rng = np.random.default_rng(9)
    cu = mf.fresnel.Conductor.metal("Cu")
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.5), fresnel=cu, dtype=dtype)
    n = 3 * kernels._kernels().BLOCK + 17                         # a partial last block
    wi = _dirs(rng, 2 * n).astype(dtype)[::2]                     # strided rows
    wo = np.asfortranarray(_dirs(rng, n).astype(dtype))
    u = rng.random((n, 2)).astype(dtype)
    one = wo[:1]
    rtol = 0.0 if dtype == np.float64 else 2e-6
    for fast, ref in ((brdf.eval(wi, wo), brdf.eval(np.ascontiguousarray(wi), np.ascontiguousarray(wo))),
                      (brdf.pdf(wi, one), brdf.pdf(np.ascontiguousarray(wi), np.repeat(one, n, axis=0)))):
        np.testing.assert_allclose(fast, ref, rtol=rtol, atol=0)
    for fast, ref in zip(brdf.sample(u, wo), brdf.sample(u, np.ascontiguousarray(wo))):
        np.testing.assert_allclose(fast, ref, rtol=rtol, atol=0)


@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=lambda t: np.dtype(t).name)
def test_input_checks_fused_into_the_kernels(dtype, monkeypatch):
    """eval, eval_cos, pdf and sample check their inputs in the kernels' pass (no pass of their
    own, ``kernels.unit_deviation`` is not called, but for a float32 measure within its slack of
    the tolerance: an upper bound, measured again exactly) and raise the errors of ``_dirs`` /
    ``_uniforms``, message for message, for one bad value at the start, in the middle or at the
    end of a batch run as several tasks, or in a broadcast input; values within the tolerance pass."""
    from microfacet._numba_kernels import _SLACK32
    from microfacet.protocol import UNIT_TOLERANCE, directions as dirs, uniforms
    from microfacet.geometry import unit_deviation
    f32 = dtype == np.float32
    monkeypatch.setattr(kernels, "threads", lambda: 2)            # tasks on 2 threads, also where Numba has 1
    passes = []
    monkeypatch.setattr(kernels, "unit_deviation", lambda w: passes.append(w.shape) or unit_deviation(w))
    rng = np.random.default_rng(11)
    n = 3 * kernels.PARALLEL_MIN + 5
    assert min(8, n // kernels.TASK_MIN) == 6
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.5), fresnel=mf.fresnel.Conductor.metal("Cu"), dtype=dtype)
    wi, wo, u = _dirs(rng, n).astype(dtype), _dirs(rng, n).astype(dtype), rng.random((n, 2)).astype(dtype)
    u[:2] = [[0.0, 1.0], [1.0, 0.0]]                              # both ends are accepted
    for scale2 in (1 + 0.9 * UNIT_TOLERANCE, 1 - 0.9 * UNIT_TOLERANCE):
        w = wi.copy()
        w[n // 2] = (w[n // 2] * np.sqrt(scale2)).astype(dtype)
        assert np.all(np.isfinite(brdf.eval(w, wo))) and np.all(np.isfinite(brdf.pdf(wo, w)))
    assert np.all(np.isfinite(brdf.sample(u, wo)[1]))
    assert f32 or passes == []                                    # float32: 0.9 tolerance + slack: remeasured
    passes.clear()
    assert np.all(np.isfinite(brdf.eval(wi, wo))) and np.all(np.isfinite(brdf.pdf(wi, wo)))
    assert np.all(np.isfinite(brdf.sample(u, wo)[1])) and passes == []
    measured = {"wi": unit_deviation(wi), "wo": unit_deviation(wo)}               # the NumPy values, exactly
    got = kernels.smith_eval(brdf, wi, wo, True, dtype)[1]
    sampled = kernels.smith_sample(brdf, u, wo, dtype)[1]
    assert sampled["u"] == 0 and sampled["wo"] == got["wo"]
    if f32:                                                       # float32 arithmetic: an upper bound
        assert all(measured[k] <= got[k] <= measured[k] + 2 * _SLACK32 for k in measured)
    else:
        assert got == measured

    def reference(f, *args):
        with pytest.raises(ValueError) as e:
            f(*args)
        return str(e.value)

    monkeypatch.setattr(kernels, "unit_deviation", unit_deviation)                # for the references
    bad_dirs = ([0.0, 0.0, 1.0 + 1.1 * UNIT_TOLERANCE / 2], [0.0, np.nan, 1.0], [np.inf, 0.0, 0.0], [0.0, 0.0, 0.0])
    for k in (0, n // 2 + 7, n - 1):
        for bad in bad_dirs:
            w = wi.copy()
            w[k] = bad
            ref = reference(dirs, w, "wi", f32)
            for method in (brdf.eval, brdf.eval_cos, brdf.pdf):
                assert reference(method, w, wo) == ref
                assert reference(method, wo, w) == ref.replace("wi ", "wo ", 1)
            assert reference(brdf.sample, u, w) == ref.replace("wi ", "wo ", 1)
        for bad in (1.5, -0.1, np.nan):
            v = u.copy()
            v[k, 1] = bad
            assert reference(brdf.sample, v, wo) == reference(uniforms, v, f32)
    # broadcast inputs, copied block by block: (m, 1, 3) against (1, l, 3), one direction against all
    w = wi[:600, None].copy()
    w[400, 0] = [0.0, 0.6, 0.9]
    assert reference(brdf.eval, w, wo[None, :300]) == reference(dirs, w, "wi", f32)
    assert reference(brdf.pdf, wo[None, :300], w) == reference(dirs, w, "wo", f32)
    one = np.array([0.0, 0.0, 1.01], dtype)
    assert reference(brdf.eval, wi, one) == reference(brdf.sample, u, one) == reference(dirs, one, "wo", f32)
    v = np.array([0.5, 1.01], dtype)
    assert reference(brdf.sample, v, wo) == reference(uniforms, v, f32)


def test_concurrent_calls_from_threads_match_serial():
    """Calls from several Python threads at once (each splitting its batch into tasks that it and
    the shared pool take from its own counter) give the results of the same calls made one by one,
    ``out=`` included."""
    from concurrent.futures import ThreadPoolExecutor
    rng = np.random.default_rng(8)
    n = 3 * kernels.PARALLEL_MIN + 5
    wi, wo, u = _dirs(rng, n), _dirs(rng, n), rng.random((n, 2))
    cu = mf.fresnel.Conductor.metal("Cu")
    brdfs = [mf.MicrofacetBRDF(D(alpha_x=ax, alpha_y=0.4), fresnel=cu) for D in (mf.GGX, mf.Beckmann) for ax in (0.1, 0.3)]
    calls = [(b, op) for b in brdfs for op in ("eval", "pdf", "sample")]

    def run(call, out=None):
        b, op = call
        if op == "sample":
            return b.sample(u, wo, out=out)
        return getattr(b, op)(wi, wo, out=out)
    serial = [run(c) for c in calls]
    outs = [tuple(np.empty_like(a) for a in s) if isinstance(s, tuple) else np.empty_like(s) for s in serial]
    with ThreadPoolExecutor(4) as pool:
        parallel = list(pool.map(run, calls * 2, outs + [None] * len(calls)))
    for s, p in zip(serial * 2, parallel):
        for a, b in zip(s if isinstance(s, tuple) else (s,), p if isinstance(p, tuple) else (p,)):
            np.testing.assert_array_equal(a, b)


def test_a_second_process_loads_the_kernels_from_numbas_cache(tmp_path):
    """The eval, pdf, sample and projected kernels are saved to Numba's cache once and loaded
    from it by the next process: none is compiled again (the eval kernel once held its loops in
    a closure, which Numba's cache keys by a pickle that differs per process: 0.2-0.5 s per
    kernel in every process, and a cache that grew)."""
    import subprocess
    import sys
    code = ("import numpy as np, microfacet as mf\n"
            "b = mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Conductor.metal('Cu'))\n"
            "w = np.tile([0.0, 0.6, 0.8], (10, 1))\n"
            "b.eval(w, w); b.pdf(w, w); b.sample(np.full((10, 2), 0.5), w)\n"
            "mf.kernels.smith_projected(b.distribution, True, w, w, True)\n")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path), NUMBA_DEBUG_CACHE="1")
    runs = [subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
            for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[-1].stderr[-2000:]
    saved = [(r.stdout + r.stderr).count("data saved") for r in runs]
    assert saved[0] >= 4 and saved[1] == 0, saved
