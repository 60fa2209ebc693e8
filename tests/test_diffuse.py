"""The diffuse body seen through its surface (microfacet.diffuse.TransmittedLambertian)."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.export.analysis import equivalent_lambertian
from microfacet.fit.spec import from_spec, to_spec
from microfacet.metrics import directional_albedo
from microfacet.validation import chi2_test


def _view(deg):
    t = np.radians(deg)
    return np.array([np.sin(t), 0.0, np.cos(t)])


def test_value_is_the_transmitted_lambertian():
    b = mf.TransmittedLambertian([0.6, 0.3, 0.1], eta=1.5)
    f0 = ((1.5 - 1) / 2.5) ** 2
    n = np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(b.eval(n, n), np.array([0.6, 0.3, 0.1]) / np.pi, rtol=1e-12)
    fd = mf.fresnel.Dielectric(1.5)(np.cos(np.radians(70.0)))[0]              # one side at 70 deg
    np.testing.assert_allclose(b.eval(_view(70), n), np.array([0.6, 0.3, 0.1]) / np.pi * (1 - fd) / (1 - f0),
                               rtol=1e-12)
    assert np.all(b.eval(_view(70) * [1, 1, -1], n) == 0)                     # below the horizon


def test_albedo_is_at_most_the_reflectance_and_falls_at_grazing():
    a = directional_albedo(mf.TransmittedLambertian(1.0), (0, 30, 60, 75, 85))[:, 0]
    assert np.all(a <= 0.95) and np.all(np.diff(a) < 0) and a[-1] < 0.5 * a[0]


@pytest.mark.parametrize("deg", [0, 40, 70, 85])
def test_sampling_matches_its_pdf_and_weight(deg):
    b = mf.TransmittedLambertian([0.5, 0.4, 0.3], eta=1.4)
    p, *_ = chi2_test(b, _view(deg), n=100_000, seed=deg)
    assert p > 1e-3
    u = np.random.default_rng(deg).random((4096, 2))
    wo = np.broadcast_to(_view(deg), (4096, 3))
    wi, weight, pdf = b.sample(u, wo)
    ok = pdf > 0
    np.testing.assert_allclose(weight[ok], b.eval_cos(wi[ok], wo[ok]) / pdf[ok, None], rtol=1e-12)
    np.testing.assert_allclose(pdf, b.pdf(wi, wo), rtol=1e-12)


def test_spec_round_trip_and_export_equivalent():
    b = mf.TransmittedLambertian([0.5, 0.2, 0.1], eta=1.7)
    back = from_spec(to_spec(b))
    assert isinstance(back, mf.TransmittedLambertian) and back.eta == 1.7
    np.testing.assert_array_equal(back.reflectance, b.reflectance)
    mu = (np.arange(64) + 0.5) / 64                       # cosine-weighted mean albedo over views
    mean = 2 * np.mean(mu[:, None] * directional_albedo(b, tuple(np.degrees(np.arccos(mu)))), axis=0)
    np.testing.assert_allclose(equivalent_lambertian(b), mean, rtol=1e-3)


@pytest.mark.parametrize("bad", [dict(reflectance=1.2), dict(eta=1.0), dict(eta=float("nan"))])
def test_bad_parameters_name_themselves(bad):
    with pytest.raises(ValueError, match="reflectance|eta"):
        mf.TransmittedLambertian(**bad)
