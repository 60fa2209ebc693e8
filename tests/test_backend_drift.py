"""Backends that drift from the NumPy reference fail here.

The Smith microfacet BRDF exists as the NumPy reference (:mod:`microfacet.distributions`,
:class:`microfacet.MicrofacetBRDF` with the compiled backend off, :func:`microfacet.backend.choose`),
the compiled Numba kernels (:mod:`microfacet.kernels`) and the GLSL shaders
(:mod:`microfacet.glsl`). For GGX and Beckmann, isotropic, anisotropic (correlated) and sheared
(mean slope):

* Numba vs NumPy: ``eval`` and ``pdf`` at random pairs to 1e-10 relative (float64; the kernels
  agree to ~1e-12), and ``sample``'s directions, weights and densities;
* GLSL vs NumPy: the terms ``D``, ``G1`` (and ``Lambda``) and the Fresnel terms at a few hundred
  pairs to float32 accuracy (1e-4 relative where the reference exceeds 1e-3 of its maximum, as
  ``tests/test_glsl.py``), on a real GL (moderngl on EGL: Mesa llvmpipe). The composite
  ``mf_eval_cos`` against ``MicrofacetBRDF.eval_cos`` for every Fresnel kind is
  ``tests/test_glsl.py::test_microfacet_brdf`` (not repeated here).
"""

import numpy as np
import pytest

import microfacet as mf
from conftest import rel_error
from microfacet import backend, kernels
from microfacet import fresnel as fr

CASES = {"isotropic": dict(alpha=0.3), "anisotropic": dict(alpha_x=0.2, alpha_y=0.5, rho=0.3),
         "sheared": dict(alpha_x=0.25, alpha_y=0.4, rho=-0.2, mean_slope=(0.15, -0.1))}
DISTRIBUTIONS = {"ggx": mf.GGX, "beckmann": mf.Beckmann}


def upper(rng, n):
    """Unit directions uniform over the upper hemisphere, a tenth of them beyond 80 degrees."""
    z = np.concatenate([rng.uniform(0, 1, n - n // 10), rng.uniform(0, np.cos(np.radians(80)), n // 10)])
    p = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(1 - z * z)
    return np.stack([s * np.cos(p), s * np.sin(p), z], -1)


def reference(brdf, method, *args):
    """``brdf.method(*args)`` by the NumPy reference: the backend seam chooses NumPy while the
    compiled backend is off."""
    saved, kernels.AVAILABLE = kernels.AVAILABLE, False
    try:
        assert not backend.smith(brdf)
        return getattr(brdf, method)(*args)
    finally:
        kernels.AVAILABLE = saved


@pytest.mark.skipif(not kernels.AVAILABLE, reason="numba is not installed (or MICROFACET_NUMBA=0)")
@pytest.mark.parametrize("fresnel", ["conductor", "schlick_f90"])
@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_numba_backend_matches_the_numpy_reference(dist, case, fresnel):
    rng = np.random.default_rng(7)
    n = 2000
    wi, wo, u = upper(rng, n), upper(rng, n), rng.random((n, 2))
    term = fr.Conductor.metal("Cu") if fresnel == "conductor" else fr.Schlick((0.9, 0.6, 0.3), f90=(0.5, 0.7, 0.2))
    b = mf.MicrofacetBRDF(DISTRIBUTIONS[dist](**CASES[case]), fresnel=term)
    assert backend.smith(b)
    f, checks = kernels.smith_eval(b, wi, wo, True)              # the compiled kernels, compiled first
    p, _ = kernels.smith_pdf(b, wi, wo)
    (si, sw, sp), _ = kernels.smith_sample(b, u, wo)
    assert checks["wi"] <= 1e-12 and checks["wo"] <= 1e-12
    ref_f, ref_p = reference(b, "eval", wi, wo), reference(b, "pdf", wi, wo)
    assert (ref_f > 0).mean() > 0.5 and (ref_p > 0).mean() > 0.5       # the comparison is not of zeros
    np.testing.assert_allclose(f, ref_f, rtol=1e-10, atol=1e-300)
    np.testing.assert_allclose(p, ref_p, rtol=1e-10, atol=1e-300)
    ri, rw, rp = reference(b, "sample", u, wo)
    np.testing.assert_allclose(si, ri, rtol=0, atol=1e-10)
    np.testing.assert_allclose(sw, rw, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(sp, rp, rtol=1e-9, atol=1e-300)


# ------------------------------------------------------------------------------ GLSL
TOL = 1e-4
SURFACE = "uniform int s_dist; uniform vec2 s_alpha; uniform float s_rho; uniform vec2 s_mean;"
FRESNEL = "uniform int f_kind; uniform vec3 f_a; uniform vec3 f_b;"





@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("dist", DISTRIBUTIONS)
def test_glsl_terms_match_the_numpy_reference(gl, dist, case):
    """``mf_ndf``, ``mf_lambda`` and ``mf_g1`` of the GLSL surface against the distribution's
    ``ndf``, ``lambda_`` and ``g1`` at 400 directions ``k`` and 400 normals ``h`` drawn from the
    distribution's visible normals (where ``D`` is not negligible; float32-exact inputs)."""
    rng = np.random.default_rng(3)
    k = upper(rng, 400).astype(np.float32).astype(np.float64)
    d = DISTRIBUTIONS[dist](**CASES[case])
    h = d.sample_visible(rng.random((400, 2)), upper(rng, 400))
    h = (h / np.linalg.norm(h, axis=-1, keepdims=True)).astype(np.float32).astype(np.float64)
    u = dict(s_dist=0 if dist == "beckmann" else 1, s_alpha=(float(d.alpha_x), float(d.alpha_y)),
             s_rho=float(d.rho), s_mean=tuple(map(float, d.mean_slope)))
    got = gl.evaluate("microfacet", """
        MfSurface s = MfSurface(s_dist, s_alpha, s_rho, s_mean);
        result = vec4(mf_ndf(s, h.xyz), 1.0 / (1.0 + mf_lambda(s, k.xyz)), mf_g1(s, k.xyz), 0.0);""",
                      {"k": k, "h": h}, uniforms=u, declarations=SURFACE)
    assert rel_error(got[:, 0], d.ndf(h)) <= TOL
    assert rel_error(got[:, 1], 1.0 / (1.0 + d.lambda_(k))) <= TOL
    assert rel_error(got[:, 2], d.g1(k)) <= TOL


@pytest.mark.parametrize("fresnel, kind, a, b", [
    (fr.Schlick((0.9, 0.6, 0.3)), 1, (0.9, 0.6, 0.3), (1.0,) * 3),
    (fr.Schlick((0.9, 0.6, 0.3), f90=(0.5, 0.7, 0.2)), 1, (0.9, 0.6, 0.3), (0.5, 0.7, 0.2)),
    (fr.Dielectric(1.5), 2, (1.5,) * 3, (0.0,) * 3),
    (fr.Conductor.metal("Au"), 3, *fr.Conductor.METALS["Au"])], ids=["schlick", "schlick_f90", "dielectric", "conductor"])
def test_glsl_fresnel_matches_the_numpy_reference(gl, fresnel, kind, a, b):
    """``mf_fresnel`` against the :mod:`microfacet.fresnel` term at 300 ``cos theta_d`` in ``[0, 1]``."""
    c = np.linspace(0.0, 1.0, 300).astype(np.float32).astype(np.float64)
    got = gl.evaluate("microfacet", "result = vec4(mf_fresnel(MfFresnel(f_kind, f_a, f_b), c.x), 0.0);",
                      {"c": c[:, None]}, uniforms=dict(f_kind=kind, f_a=np.broadcast_to(a, 3), f_b=np.broadcast_to(b, 3)),
                      declarations=FRESNEL)
    assert rel_error(got[:, :3], fresnel(c)) <= TOL
