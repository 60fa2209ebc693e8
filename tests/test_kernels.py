"""The compiled Smith kernel against the NumPy reference it replaces."""
import numpy as np
import pytest

import microfacet as mf
from microfacet import kernels

pytestmark = pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (or MICROFACET_NUMBA=0)")


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
        np.testing.assert_allclose(s_fast, s_ref, rtol=1e-12, atol=0)
        assert np.array_equal(s_fast > 0, s_ref > 0)


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
