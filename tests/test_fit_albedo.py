"""The albedo match of the perceptual fits (microfacet.fit.albedo): the directional albedo
reaches the data's, the lobes keep their shape, the tables stay smooth."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.fit import albedo as A
from microfacet.fit.perceptual import fit_models
from microfacet.metrics import AlbedoRatios, LogError, directional_albedo


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


@pytest.mark.parametrize("name, model, log_growth", [
    ("merl/specular-orange-phenolic", "dielectric_mixture", 1.05),
    # nylon's mixture reflects ~10 % less than the data at some view: the albedo-first match
    # brings it to the data's albedo at 1.3 times its log error, the log-first table holds it
    # within the band (LOG_WEIGHT_IN_BAND, BAND_TARGET) at less than 1.2 times
    ("merl/nylon", "mixture", 1.2)])
def test_corpus_fit_reaches_the_albedo_band_at_little_more_log_error(corpus, name, model, log_growth):
    data = mf.measured.load(corpus(name))
    fit = fit_models(data, (model,))[model]
    judge, log = AlbedoRatios(data), LogError(data)
    matched = A.match_albedo(data, fit)
    before, after = _worst(judge(fit), judge.ref), _worst(judge(matched), judge.ref)
    assert after <= 0.05 < before
    assert log(matched) <= log_growth * log(fit)


def test_corpus_plastic_whose_red_rises_at_grazing_reaches_the_band(corpus):
    """pink-plastic's red albedo rises from 0.43 at 70 deg to 0.58 at 80 deg: the lobes reach
    the band at 75 deg only at a little more log error over their shared table than a match
    that merely comes closer to the band may cost (LOG_TOLERANCE); one that reaches it may
    (LOG_TOLERANCE_IN_BAND)."""
    data = mf.measured.load(corpus("merl/pink-plastic"))
    fit = fit_models(data, ("lobe", "two_lobes"))["two_lobes"]
    judge, log = AlbedoRatios(data), LogError(data)
    matched = A.match_albedo(data, fit)
    assert _worst(judge(fit), judge.ref) > 0.05
    assert _worst(judge(matched), judge.ref) <= 0.05
    assert log(matched) <= (1.0 + A.LOG_TOLERANCE_IN_BAND) * log(fit)


def _flat_lobe(f0):
    return mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(f0, f0))


def test_a_base_dominated_fit_reaches_the_band_through_its_base():
    """A red body 0.4 where the data's is 0.6: a lobe of f0 0.02 cannot carry the missing
    albedo (the table alone stays ~0.2 below the data); its base's red reflectance can."""
    from microfacet.diffuse import TransmittedLambertian
    for base in (mf.Lambertian, TransmittedLambertian):
        data = mf.fit.SumBRDF(_flat_lobe(0.02), base([0.6, 0.4, 0.2]))
        fit = mf.fit.SumBRDF(_flat_lobe(0.02), base([0.4, 0.4, 0.2]))
        judge, log = AlbedoRatios(data), LogError(data)
        assert _worst(judge(fit), judge.ref) > 0.3
        matched = A.match_albedo(data, fit)
        assert _worst(judge(matched), judge.ref) < 0.02, base.__name__
        assert log(matched) < 0.5 * log(fit)
        lobe, body = matched.brdfs
        assert type(body) is base and isinstance(lobe.fresnel, mf.fresnel.Tabulated)
        assert np.allclose(body.reflectance, [0.6, 0.4, 0.2], atol=0.01)
        if base is TransmittedLambertian:
            assert body.eta == fit.brdfs[1].eta


def test_the_bases_move_only_where_the_lobes_cannot_reach_the_band():
    data = _dielectric(mf.fresnel.Dielectric(1.5))
    fit = _dielectric(mf.fresnel.Schlick(0.02, 0.3))
    factors = A.albedo_factors(A.albedo_target(data), fit)
    assert np.all(factors.bases == 1.0) and factors.s.shape == (len(A.NODES_DEG), 3)


def test_scaled_bases_keep_reflectance_and_energy_bounds():
    """A bright body far below the data's: the base's factor is held to reflectance <= 1 and
    to a total albedo below 1 up to 89 deg."""
    data = mf.fit.SumBRDF(_flat_lobe(0.02), mf.Lambertian([0.97, 0.5, 0.5]))
    fit = mf.fit.SumBRDF(_flat_lobe(0.02), mf.Lambertian([0.6, 0.5, 0.5]))
    matched = A.match_albedo(data, fit)
    body = matched.brdfs[1]
    assert np.all(body.reflectance <= 1.0) and body.reflectance[0] > 0.8
    assert mf.metrics.directional_albedo(matched, (0.0, 60.0, 85.0, 89.0)).max() <= 1.0


def test_corpus_base_dominated_plastic_reaches_the_band(corpus):
    """specular-white-phenolic: the lobes alone leave the red albedo at 75 deg ~7 % low
    (best fit out of the band before the bases were scaled)."""
    data = mf.measured.load(corpus("merl/specular-white-phenolic"))
    fit = fit_models(data, ("dielectric_mixture",))["dielectric_mixture"]
    judge, log = AlbedoRatios(data), LogError(data)
    matched = A.match_albedo(data, fit)
    assert _worst(judge(matched), judge.ref) <= 0.05
    assert log(matched) <= 1.15 * log(fit)
    assert [type(b) for b in matched.brdfs] == [type(b) for b in fit.brdfs]


@pytest.mark.parametrize("name, model", [("rgl/satin_white_rgb", "lobe"), ("rgl/satin_white_rgb", "two_lobes"),
                                         ("rgl/paper_yellow_rgb", "mixture")])
def test_corpus_bright_materials_stay_within_energy(corpus, name, model):
    """Bright RGL materials whose data albedo reaches ~1.02 near grazing (a measurement above
    1): the table matched there overshot beyond it (satin_white: 1.17 at 89 deg before the
    energy bound); the matched fit now reflects at most 1 at every view and its tables do not
    ring (total variation at most twice the range), though scaling the grazing nodes alone
    made satin_white's two_lobes ring and a ceiling alone paper_yellow's mixture (a valley)."""
    data = mf.measured.load(corpus(name))
    fit = fit_models(data, (model,))[model]
    matched = A.match_albedo(data, fit)
    assert np.max(directional_albedo(matched, (0, 30, 60, 75, 80, 85, 89))) <= 1.0
    for lobe in matched.brdfs:
        if isinstance(lobe, mf.MicrofacetBRDF):
            v = lobe.fresnel.values
            assert np.all(np.abs(np.diff(v, axis=0)).sum(axis=0) <= 2.0 * np.ptp(v, axis=0) + 1e-9)


def test_corpus_bright_satin_stays_in_the_band(corpus):
    """satin_white's one lobe, held within energy, still reaches the data's albedo at 0-75 deg."""
    data = mf.measured.load(corpus("rgl/satin_white_rgb"))
    matched = A.match_albedo(data, fit_models(data, ("lobe",))["lobe"])
    judge = AlbedoRatios(data)
    assert _worst(judge(matched), judge.ref) <= 0.05


def test_corpus_glossy_vinyl_albedo_is_integrated_as_the_metrics_do(corpus):
    """A glossy vinyl's albedo needs fine nodes in ``theta`` (its blue albedo at normal view
    came out 9 % low on a 64 x 64 grid, so the match aimed below the data): the match integrates
    it as the reported metric's 128 x 128 grid does, within 1 %."""
    data = mf.measured.load(corpus("rgl/vch_silk_blue_rgb"))
    match = A.albedo_target(data).ratios
    metric = AlbedoRatios(data, A.VIEWS_DEG)
    assert np.allclose(match.ref, metric.ref, rtol=0.01)


def _sharp_and_rough(f_sharp, f_rough):
    return mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.05), f_sharp), mf.MicrofacetBRDF(mf.GGX(alpha=0.6), f_rough))


def test_each_lobe_gets_its_own_table_where_one_shared_table_misses_the_band():
    """The data's sharp lobe rises steeply toward grazing (Schlick 0.02 to 1), its rough lobe
    does not; the fit's sharp lobe is flat. One table shared by both lobes cannot add the
    grazing energy to the sharp lobe alone (10 % off the band); each lobe's own table can,
    without rings, and the log error falls."""
    data = _sharp_and_rough(mf.fresnel.Schlick(0.02, 1.0), mf.fresnel.Schlick(0.3, 0.3))
    fit = _sharp_and_rough(mf.fresnel.Schlick(0.02, 0.02), mf.fresnel.Schlick(0.3, 0.3))
    target = A.albedo_target(data)
    factors = A.albedo_factors(target, fit)
    cos_d = np.cos(np.linspace(np.pi / 2, 0.0, A.TABLE_SIZE))
    factor = np.stack([np.interp(np.arccos(cos_d), np.radians(A.NODES_DEG), factors.s[:, c]) for c in range(3)], -1)
    shared = mf.fit.SumBRDF(*(mf.MicrofacetBRDF(lobe.distribution, mf.fresnel.Tabulated(
        cos_d, np.clip(np.asarray(lobe.fresnel(cos_d)) * factor, 0.0, 1.0))) for lobe in fit.brdfs))   # s alone
    matched = A.match_albedo(data, fit)
    judge, log = AlbedoRatios(data), LogError(data)
    assert _worst(judge(shared), judge.ref) > 0.08
    assert _worst(judge(matched), judge.ref) < 0.02
    assert factors.each.shape == (2, len(A.NODES_DEG), 3) and factors.each[0].max() > 1.5
    assert log(matched) < log(shared)
    for lobe in matched.brdfs:
        values = lobe.fresnel.values
        assert np.all(np.abs(np.diff(values, axis=0)).sum(axis=0) <= 2.0 * np.ptp(values, axis=0) + 1e-9)
