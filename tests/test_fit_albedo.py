"""The albedo match of the perceptual fits (microfacet.fit.albedo): the directional albedo
reaches the data's, the lobes keep their shape, the tables stay smooth, the Schlick match
keeps Schlick lobes."""
import numpy as np
import pytest

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
    assert A.match_albedo(mf.Lambertian(0.5), fit, method="schlick_base") is fit


def test_schlick_match_recovers_the_parameters_without_tables():
    # the data a Schlick lobe can reach: the fit errs only in its Schlick parameters
    data = _dielectric(mf.fresnel.Schlick([0.06, 0.05, 0.04], 1.0))
    fit = _dielectric(mf.fresnel.Schlick(0.02, 0.3))
    judge, target = AlbedoRatios(data), A.albedo_target(data)
    assert _worst(judge(fit), judge.ref) > 0.1
    for method in ("schlick", "schlick_base", "shared", "shared_base"):
        matched = A.match_albedo(None, fit, target, method=method)
        assert _worst(judge(matched), judge.ref) < 0.02, method
        assert A.band_error(target, matched) < 0.02, method
        lobe, base = matched.brdfs
        assert type(lobe.fresnel) is mf.fresnel.Schlick, method             # no table
        assert lobe.distribution is fit.brdfs[0].distribution
        f = np.concatenate([lobe.fresnel.f0, lobe.fresnel.f90, base.reflectance])
        assert np.all((f >= 0) & (f <= 1)), method
    assert A.band_error(target, A.match_albedo(None, fit, target, method="fallback")) <= A.BAND_TOLERANCE
    lobe = A.match_albedo(None, fit, target, method="schlick").brdfs[0]
    assert np.allclose(lobe.fresnel.f0, [0.06, 0.05, 0.04], atol=0.01) and lobe.fresnel.f90[0] > 0.7


def test_shared_schlick_keeps_the_lobes_relative_weights():
    lobes = [mf.MicrofacetBRDF(mf.GGX(alpha=a), mf.fresnel.Schlick(f0, 0.5)) for a, f0 in ((0.05, 0.3), (0.3, 0.1))]
    data = mf.fit.SumBRDF(*[mf.MicrofacetBRDF(b.distribution, mf.fresnel.Schlick(2 * b.fresnel.f0, 0.5))
                            for b in lobes])
    matched = A.match_albedo(data, mf.fit.SumBRDF(*lobes), method="shared")
    f0 = [b.fresnel.f0[0] for b in matched.brdfs]
    assert abs(f0[0] / f0[1] - 3.0) < 1e-9 and abs(f0[0] - 0.6) < 0.03


def test_unknown_method_is_one_line():
    with pytest.raises(ValueError, match="method must be one of"):
        A.match_albedo(mf.Lambertian(0.5), _dielectric(mf.fresnel.Schlick(0.04)), method="spline")


def test_corpus_plastic_reaches_the_albedo_band_without_losing_its_log_error(corpus):
    data = mf.measured.load(corpus("merl/specular-orange-phenolic"))
    fit = fit_models(data, ("dielectric_mixture",))["dielectric_mixture"]
    judge, log = AlbedoRatios(data), LogError(data)
    matched = A.match_albedo(data, fit)
    before, after = _worst(judge(fit), judge.ref), _worst(judge(matched), judge.ref)
    assert after <= 0.05 < before
    assert log(matched) <= 1.05 * log(fit)
    fallback = A.match_albedo(data, fit, method="fallback")         # the Schlick match misses the band here
    assert _worst(judge(fallback), judge.ref) <= 0.05
