"""The colour balance of the perceptual fits (microfacet.fit.colour): the spheres' colour moves
to the data's under lights the balance did not see, the albedo stays in its band, the tables
stay smooth; and the image error's scenes of other lights it rests on (microfacet.metrics)."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.fit import colour as C
from microfacet.fit.albedo import BAND_VIEWS_DEG, albedo_target, match_albedo
from microfacet.fit.extract import table_variation
from microfacet.metrics import AlbedoRatios, ImageError


def test_image_error_under_other_lights_and_a_turned_environment():
    ref = mf.Lambertian((0.6, 0.4, 0.2))
    default = ImageError(ref, size=24)
    assert default.ref.shape[0] == 4 and default.used == [0, 1, 2, 3]
    lights = [(20.0, 30.0), (50.0, 200.0)]
    dark = ImageError(ref, size=24, lights_deg=lights, environment_deg=None)
    assert dark.ref.shape[0] == 3 and dark.used == [0, 1] and not np.any(dark.ref[2])
    turned = ImageError(ref, size=24, lights_deg=lights, environment_deg=180.0)
    np.testing.assert_array_equal(turned.ref[:2], dark.ref[:2])
    straight = ImageError(ref, size=24, lights_deg=lights)
    assert np.abs(turned.ref[2] - straight.ref[2]).sum() > 0.05 * straight.ref[2].sum()   # another sky
    np.testing.assert_array_equal(straight.ref[2], default.ref[3])                           # the image error's
    assert turned.chromaticity(ref) == 0.0 and turned(ref) == 0.0
    with pytest.raises(ValueError, match="lights_deg"):
        ImageError(ref, size=24, lights_deg=[(95.0, 0.0)])


def _tinted():
    """Data: a white highlight over an orange body. Fit: the same lobe with an orange tint and a
    paler body, its albedo matched to the data's: the spheres show an orange cast."""
    data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.08), mf.fresnel.Schlick(0.3)),
                          mf.Lambertian((0.5, 0.3, 0.1)))
    fit = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.08), mf.fresnel.Schlick((0.7, 0.3, 0.1))),
                         mf.Lambertian((0.4, 0.32, 0.13)))
    target = albedo_target(data)
    return data, match_albedo(None, fit, target), target


def test_display_jacobian_matches_finite_differences():
    data, fit, target = _tinted()
    judge = C.colour_target(data)
    parts = list(fit.brdfs)
    columns = C._columns(judge, target, fit, parts)
    display = C._Display(judge, columns)
    g = 1.0 + 0.3 * np.random.default_rng(1).uniform(-1.0, 1.0, (len(columns.terms), 3))
    s, jac = display(g)
    assert np.allclose(s, judge.displayed_rgb(columns.render(g)), rtol=1e-12)   # the images as rendered
    h = 1e-6
    for f, c in [(0, 0), (3, 1), (len(g) - 1, 2)]:
        up, down = g.copy(), g.copy()
        up[f, c] += h
        down[f, c] -= h
        numeric = (display(up)[0] - display(down)[0]) / (2 * h)
        assert np.allclose(jac[:, f, c], numeric, rtol=1e-5, atol=1e-8 * np.abs(s).max())


def test_balance_removes_a_cast_seen_under_lights_it_did_not_see():
    data, fit, target = _tinted()
    judge, held_out = C.colour_target(data), ImageError(data, size=48)    # the image error's own lights
    assert judge.chromaticity(fit) > C.CAST_TRIGGER and held_out.chromaticity(fit) > 0.02
    balanced = C.balance_colour(judge, target, fit)
    assert balanced is not fit
    assert judge.chromaticity(balanced) < 0.5 * judge.chromaticity(fit)
    assert held_out.chromaticity(balanced) < 0.5 * held_out.chromaticity(fit)
    assert held_out(balanced) < held_out(fit)
    # the same tree; the albedo held in its band; no table rings; the log error within tolerance
    assert [type(p) for p in balanced.brdfs] == [type(p) for p in fit.brdfs]
    assert balanced.brdfs[0].distribution is fit.brdfs[0].distribution
    ratios = AlbedoRatios(data, BAND_VIEWS_DEG)
    assert np.max(np.abs(ratios(balanced) - 1.0)) <= 0.05
    assert np.max(table_variation(balanced.brdfs[0].fresnel.values)) <= 2.0 + 1e-9
    assert target.log(balanced) <= (1.0 + C.LOG_TOLERANCE) * target.log(fit)


def test_a_fit_without_a_cast_is_kept_as_is():
    data = mf.fit.SumBRDF(mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick(0.04)), mf.Lambertian(0.3))
    target = albedo_target(data)
    fit = match_albedo(None, data, target)
    assert C.balance_colour(C.colour_target(data), target, fit) is fit
    golden = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), mf.fresnel.Schlick((0.9, 0.6, 0.2)))   # no table to scale
    assert C.balance_colour(C.colour_target(data), target, golden) is golden


def test_corpus_metal_mixture_loses_its_cast(corpus):
    """chrome's mixture (16 GGX lobes) renders with a cast of about 0.018 under the image
    error's lights; balanced under the others, far less, at the same log error."""
    from microfacet.fit.perceptual import fit_models
    data = mf.measured.load(corpus("merl/chrome"))
    target = albedo_target(data)
    fit = match_albedo(None, fit_models(data, ("mixture",))["mixture"], target)
    held_out = ImageError(data, size=32)
    balanced = C.balance_colour(C.colour_target(data), target, fit)
    assert held_out.chromaticity(fit) > 0.01
    assert held_out.chromaticity(balanced) < 0.5 * held_out.chromaticity(fit)
    assert target.log(balanced) <= 1.02 * target.log(fit)
    assert max(np.max(table_variation(p.fresnel.values)) for p in balanced.brdfs if hasattr(p, "fresnel")) <= 2.0 + 1e-9
