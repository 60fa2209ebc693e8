"""The albedo match of the perceptual fits (microfacet.fit.albedo): the directional albedo
reaches the data's, the lobes keep their shape, the tables stay smooth."""
import numpy as np

import microfacet as mf
from microfacet.fit import albedo as A
from microfacet.fit.perceptual import fit_models
from microfacet.metrics import AlbedoRatios, LogError


def _dielectric(f0_fresnel, kd=0.3):
    return mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.15), f0_fresnel), mf.Lambertian(kd))


def _worst(ratios, ref, floor=0.03):
    r = np.asarray(ratios, float)
    return float(np.nanmax(np.where(ref > floor, np.abs(r - 1.0), 0.0)))


def test_match_reaches_the_albedo_and_keeps_the_lobe_shape():
    data = _dielectric(mf.fresnel.Dielectric(1.5))
    fit = _dielectric(mf.fresnel.Schlick(0.02, 0.3))          # too little grazing reflection
    judge = AlbedoRatios(data)
    assert _worst(judge(fit), judge.ref) > 0.1
    matched = A.match_albedo(data, fit)
    assert _worst(judge(matched), judge.ref) < 0.02
    lobe, base = matched.brdfs
    assert isinstance(lobe.fresnel, mf.fresnel.Tabulated) and base is fit.brdfs[1]
    assert lobe.distribution is fit.brdfs[0].distribution
    values = lobe.fresnel.values
    tv = np.abs(np.diff(values, axis=0)).sum(axis=0)
    assert np.all(tv <= 2.0 * np.ptp(values, axis=0) + 1e-9)       # no rings
    assert np.all((values >= 0) & (values <= 1))


def test_a_lambertian_fit_is_returned_as_is():
    fit = mf.Lambertian(0.4)
    assert A.match_albedo(mf.Lambertian(0.5), fit) is fit


def test_corpus_plastic_reaches_the_albedo_band_without_losing_its_log_error(corpus):
    data = mf.measured.load(corpus("merl/specular-orange-phenolic"))
    fit = fit_models(data, ("dielectric_mixture",))["dielectric_mixture"]
    judge, log = AlbedoRatios(data), LogError(data)
    matched = A.match_albedo(data, fit)
    before, after = _worst(judge(fit), judge.ref), _worst(judge(matched), judge.ref)
    assert after <= 0.05 < before
    assert log(matched) <= 1.05 * log(fit)
