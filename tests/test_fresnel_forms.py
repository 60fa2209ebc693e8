"""Schlick's term with a grazing value and the F82-tint metal term: against their
written-out formulas, in a microfacet BRDF (compiled kernels and NumPy path), and their
Dr.Jit twins of :mod:`microfacet.mitsuba.fresnel`."""
import numpy as np
import pytest

import microfacet as mf
from microfacet import kernels
from microfacet.fresnel import F82_COS, F82Tint, Schlick

C = np.linspace(0.0, 1.0, 1001)
F0 = np.array([0.95, 0.64, 0.54])
F82 = np.array([0.7, 0.85, 1.0])


def _schlick(c, f0, f90=1.0):
    return np.asarray(f0) + (np.asarray(f90) - np.asarray(f0)) * (1.0 - np.asarray(c))[..., None] ** 5


def _f82(c, f0, f82):
    """Kutz et al. 2021 / OpenPBR: F_S(c) - c (1 - c)^6 (F_S(mu) - f82 F_S(mu)) / (mu (1 - mu)^6)."""
    mu = 1.0 / 7.0
    fs_mu = _schlick(mu, f0)
    c = np.asarray(c)[..., None]
    return np.clip(_schlick(c[..., 0], f0) - c * (1 - c) ** 6 * (fs_mu - f82 * fs_mu) / (mu * (1 - mu) ** 6), 0, 1)


def test_schlick_f90_formula_and_old_calls_unchanged():
    np.testing.assert_allclose(Schlick(F0, 0.7)(C), _schlick(C, F0, 0.7), rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(Schlick(F0, [0.5, 0.6, 0.9])(0.0), [0.5, 0.6, 0.9])
    np.testing.assert_allclose(Schlick(0.04)(C), 0.04 + 0.96 * (1 - C[:, None]) ** 5 * np.ones(3), rtol=1e-14)
    assert np.all(Schlick(0.04).f90 == 1.0)
    assert np.all(np.diff(Schlick(0.9, 0.2)(C)[:, 0]) >= 0)     # monotone in c, between f90 and f0


def test_f82_tint_formula_and_its_defining_points():
    f = F82Tint(F0, F82)
    np.testing.assert_allclose(f(C), _f82(C, F0, F82), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(f(1.0), F0, rtol=1e-14)
    np.testing.assert_allclose(f(0.0), 1.0)
    np.testing.assert_allclose(f(F82_COS), F82 * Schlick(F0)(F82_COS), rtol=1e-13)
    np.testing.assert_allclose(F82Tint(F0, 1.0)(C), Schlick(F0)(C), rtol=1e-14)        # f82 = 1: Schlick
    assert F82Tint(0.0, 0.0)(C).min() == 0.0 and F82Tint(0.0, 0.0)(C).max() <= 1.0     # clamped


@pytest.mark.parametrize("metal", sorted(mf.fresnel.Conductor.METALS))
def test_f82_tint_through_a_conductor_beats_schlick(metal):
    cond = mf.fresnel.Conductor.metal(metal)
    f = F82Tint.from_conductor(cond.eta, cond.k)
    np.testing.assert_allclose(f(1.0), cond(1.0), rtol=1e-13)
    err = np.abs(f(C) - cond(C)).max()
    assert err < 0.035
    assert err <= np.abs(Schlick(f.f0)(C) - cond(C)).max() + 1e-12


@pytest.mark.parametrize("make, match", [
    (lambda: Schlick(0.5, 1.2), "f90"), (lambda: Schlick(0.5, np.nan), "f90"),
    (lambda: F82Tint(1.5, 0.5), "f0"), (lambda: F82Tint(0.5, -0.1), "f82"),
    (lambda: F82Tint(0.5, [0.1, 0.2, np.inf]), "f82")])
def test_invalid_parameters(make, match):
    with pytest.raises(ValueError, match=match):
        make()


FRESNELS = {"schlick_f90": Schlick(F0, [0.8, 0.9, 0.6]), "schlick": Schlick(F0), "f82": F82Tint(F0, F82)}


@pytest.mark.parametrize("numba", [True, False], ids=["kernels", "numpy"])
@pytest.mark.parametrize("name", sorted(FRESNELS))
@pytest.mark.parametrize("dist", [mf.GGX, mf.Beckmann], ids=["ggx", "beckmann"])
def test_microfacet_brdf_with_these_fresnels(name, dist, numba, monkeypatch):
    """eval = F(o.h) D G2 / (4 z_i z_o) written out, with the compiled kernels and without;
    sample weights = eval_cos / pdf."""
    if numba and not kernels.AVAILABLE:
        pytest.skip("numba is not installed (or MICROFACET_NUMBA=0)")
    if not numba:
        monkeypatch.setattr(kernels, "AVAILABLE", False)
    fresnel = FRESNELS[name]
    brdf = mf.MicrofacetBRDF(dist(alpha=0.3), fresnel=fresnel)
    rng = np.random.default_rng(3)
    z = rng.uniform(0.05, 1.0, (2, 400))
    phi = rng.uniform(0.0, 2 * np.pi, (2, 400))
    r = np.sqrt(1 - z * z)
    wi, wo = (np.stack([r[j] * np.cos(phi[j]), r[j] * np.sin(phi[j]), z[j]], axis=-1) for j in range(2))
    h = wi + wo
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    oh = np.sum(wo * h, axis=-1)
    d = brdf.distribution
    g2 = 1.0 / (1.0 + d.lambda_(wi) + d.lambda_(wo))              # height-correlated Smith (Eq. 2.13)
    expected = fresnel(oh) * (d.ndf(h) * g2 / (4 * wi[:, 2] * wo[:, 2]))[:, None]
    np.testing.assert_allclose(brdf.eval(wi, wo), expected, rtol=1e-10)
    u = rng.random((400, 2))
    wi_s, weight, pdf = brdf.sample(u, wo)
    ok = pdf > 0
    np.testing.assert_allclose(weight[ok], brdf.eval_cos(wi_s[ok], wo[ok]) / pdf[ok, None], rtol=1e-9)


def test_mitsuba_fresnel_twins_match_numpy():
    """:mod:`microfacet.mitsuba.fresnel` (Dr.Jit, float32) against the NumPy terms."""
    pytest.importorskip("mitsuba", reason="the Dr.Jit twins need the optional `mitsuba` package")
    pytest.importorskip("drjit", reason="the Dr.Jit twins need drjit (installed with mitsuba)")
    from microfacet.mitsuba import fresnel as mfr
    try:
        from drjit.llvm import Float
        Float([1.0]) + 1.0
    except Exception as e:                         # noqa: BLE001 - no libLLVM: the scalar type
        if "LLVM" not in str(e) and "llvm" not in str(e):
            raise
        pytest.skip(f"drjit's LLVM backend is unavailable here ({e})")
    c = np.linspace(0.0, 1.0, 257)
    cf = Float(c.astype(np.float32))
    for ch in range(3):
        ours = Schlick(F0, [0.8, 0.9, 0.6])(c)[:, ch]
        theirs = np.array(mfr.schlick(cf, float(F0[ch]), float([0.8, 0.9, 0.6][ch])))
        np.testing.assert_allclose(theirs, ours, atol=2e-6)
        ours = Schlick(F0)(c)[:, ch]
        np.testing.assert_allclose(np.array(mfr.schlick(cf, float(F0[ch]))), ours, atol=2e-6)
        ours = F82Tint(F0, F82)(c)[:, ch]
        theirs = np.array(mfr.f82_tint(cf, float(F0[ch]), float(F82[ch])))
        np.testing.assert_allclose(theirs, ours, atol=2e-6)
