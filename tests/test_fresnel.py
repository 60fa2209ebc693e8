"""Fresnel terms (Table 2.I) against independent forms."""
import numpy as np
import pytest

import microfacet as mf

C = np.linspace(0.0, 1.0, 1001)


def _complex_fresnel(c, n):
    """Textbook complex-amplitude Fresnel reflectance, unpolarized."""
    c = c[:, None]
    t = np.sqrt(1 - (1 - c * c) / (n * n) + 0j)
    rs, rp = (c - n * t) / (c + n * t), (n * c - t) / (n * c + t)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


@pytest.mark.parametrize("eta", [1.0001, 1.33, 1.5, 2.4, 0.67])
def test_dielectric_table_2_i_matches_complex_amplitudes(eta):
    np.testing.assert_allclose(mf.fresnel.Dielectric(eta)(C), _complex_fresnel(C, np.full(3, eta + 0j)), atol=1e-14)


def test_dielectric_limits_and_schlick():
    f = mf.fresnel.Dielectric([1.5, 1.33, 2.0])
    f0 = ((f.eta - 1) / (f.eta + 1)) ** 2
    np.testing.assert_allclose(f(1.0), f0, rtol=1e-14)
    np.testing.assert_allclose(f(0.0), 1.0)
    np.testing.assert_allclose(mf.fresnel.Schlick.from_eta(f.eta)(1.0), f0, rtol=1e-14)
    np.testing.assert_allclose(mf.fresnel.Schlick(0.04)(0.0), 1.0)
    tir = mf.fresnel.Dielectric(1 / 1.5)(np.array([0.1, 0.5]))   # inside glass, past the critical angle
    np.testing.assert_allclose(tir, 1.0)


@pytest.mark.parametrize("metal", sorted(mf.fresnel.Conductor.METALS))
def test_conductor_real_form_matches_complex_amplitudes(metal):
    f = mf.fresnel.Conductor.metal(metal)
    np.testing.assert_allclose(f(C), _complex_fresnel(C, f.eta + 1j * f.k), atol=1e-14)
    normal = ((f.eta - 1) ** 2 + f.k**2) / ((f.eta + 1) ** 2 + f.k**2)
    np.testing.assert_allclose(f(1.0), normal, rtol=1e-13)
    np.testing.assert_allclose(mf.fresnel.Conductor(1.7, 0.0)(C), mf.fresnel.Dielectric(1.7)(C), atol=1e-14)


def test_ideal_and_tabulated():
    assert np.all(mf.fresnel.Ideal()(C) == 1) and mf.fresnel.Ideal()(C).shape == (1001, 3)
    t = mf.fresnel.Tabulated([0.0, 0.5, 1.0], [[1, 1, 1], [0.5, 0.4, 0.3], [0.1, 0.2, 0.3]])
    np.testing.assert_allclose(t(np.array([0.25, 0.75, 2.0, -1.0])),
                               [[0.75, 0.7, 0.65], [0.3, 0.3, 0.3], [0.1, 0.2, 0.3], [1, 1, 1]])
    grey = mf.fresnel.Tabulated([0, 1], [0.2, 0.9])
    np.testing.assert_allclose(grey(0.5), [0.55] * 3)


@pytest.mark.parametrize("make, match", [
    (lambda: mf.fresnel.Dielectric(-1), "eta"), (lambda: mf.fresnel.Dielectric(np.nan), "eta"),
    (lambda: mf.fresnel.Schlick(1.5), "f0"), (lambda: mf.fresnel.Conductor(1.0, -2), "k"),
    (lambda: mf.fresnel.Conductor.metal("Xx"), "unknown metal"),
    (lambda: mf.fresnel.Tabulated([1, 0], [0, 1]), "increasing"),
    (lambda: mf.fresnel.Tabulated([0, 1], [[0, 1, 2, 3]]), "Tabulated"),
])
def test_invalid_parameters(make, match):
    with pytest.raises(ValueError, match=match):
        make()
