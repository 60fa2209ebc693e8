"""Validation of MicrofacetBRDF and Lambertian (thesis Ch. 2, 3.2; DESIGN.md's standard)."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.geometry import dot, normalize, reflect, spherical_to_cartesian
from microfacet.validation import SURFACES, albedo, chi2_test

DISTS = (mf.Beckmann, mf.GGX)
VIEWS_DEG = (0, 60, 85)
P_MIN = 1e-3      # per-case significance; ~50 cases, so a family-wise false alarm ~5 %


def _centred(kw, gaf):
    """``kw`` without its mean slope for V-grooves (which need a zero mean slope)."""
    return {k: v for k, v in kw.items() if k != "mean_slope"} if gaf == "vgroove" else kw


def _random_dirs(rng, n):
    return normalize(rng.normal(size=(n, 3)) * [1, 1, 0.7] + [0, 0, 0.5]) * [1, 1, 1]


def _upper(rng, n):
    w = normalize(rng.normal(size=(n, 3)))
    w[..., 2] = np.abs(w[..., 2])
    return w


@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
@pytest.mark.parametrize("surface", SURFACES)
@pytest.mark.parametrize("theta_o", VIEWS_DEG)
def test_chi2_smith_sampling(D, surface, theta_o):
    brdf = mf.MicrofacetBRDF(D(**SURFACES[surface]))
    wo = spherical_to_cartesian(np.radians(theta_o), 0.7)
    p, stat, dof, total = chi2_test(brdf, wo, seed=theta_o)
    assert p > P_MIN, f"chi2={stat:.1f} dof={dof} p={p:.2g} (pdf mass {total:.5f})"


@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
@pytest.mark.parametrize("gaf", ["vgroove", "normal_map"])
@pytest.mark.parametrize("surface", ["aniso", "all"])
def test_chi2_slope_sampling(D, gaf, surface):
    brdf = mf.MicrofacetBRDF(D(**_centred(SURFACES[surface], gaf)), gaf=gaf)
    for theta_o in (30, 80):
        wo = spherical_to_cartesian(np.radians(theta_o), -2.0)
        p, stat, dof, total = chi2_test(brdf, wo, n=200_000, seed=theta_o)
        assert p > P_MIN, f"theta_o={theta_o}: chi2={stat:.1f} dof={dof} p={p:.2g}"


def test_chi2_lambertian():
    p, stat, dof, total = chi2_test(mf.Lambertian(0.5), mf.geometry.normalize([0.3, 0.0, 0.954]), n=200_000)
    assert p > P_MIN and abs(total - 1) < 1e-6


@pytest.mark.parametrize("gaf", mf.brdf.GAFS)
@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
def test_weight_is_eval_cos_over_pdf(D, gaf):
    """The sampling weight (Eq. 2.23 for Smith) equals eval_cos / pdf at the sample."""
    rng = np.random.default_rng(4)
    brdf = mf.MicrofacetBRDF(D(**_centred(SURFACES["all"], gaf)), fresnel=mf.fresnel.Conductor.metal("Cu"), gaf=gaf)
    wo = _upper(rng, 20000)
    wi, weight, pdf = brdf.sample(rng.random((20000, 2)), wo)
    ok = pdf > 0
    assert ok.mean() > 0.5
    np.testing.assert_allclose(weight[ok], brdf.eval_cos(wi[ok], wo[ok]) / pdf[ok, None], rtol=1e-10)
    np.testing.assert_allclose(pdf[ok], brdf.pdf(wi[ok], wo[ok]), rtol=1e-11)
    assert np.all(weight[~ok] == 0)


@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
@pytest.mark.parametrize("gaf", ["smith", "vgroove"])
def test_reciprocity(D, gaf):
    """f(i, o) = f(o, i) without shear; sheared (Smith): f(i, o) z_i c_o = f(o, i) z_o c_i,
    reciprocity of the BRDF measured on the mesosurface."""
    rng = np.random.default_rng(5)
    for surface in SURFACES.values():
        d = D(**_centred(surface, gaf))
        brdf = mf.MicrofacetBRDF(d, fresnel=mf.fresnel.Dielectric(1.6), gaf=gaf)
        wi, wo = _upper(rng, 5000), _upper(rng, 5000)
        if gaf == "smith" and np.any(d.mean_slope):
            ci, co = d._warp(wi)[2], d._warp(wo)[2]
            a = brdf.eval(wi, wo) * (wi[:, 2] * co)[:, None]
            b = brdf.eval(wo, wi) * (wo[:, 2] * ci)[:, None]
        else:
            a, b = brdf.eval(wi, wo), brdf.eval(wo, wi)
        assert np.any(a > 0)
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
def test_smith_gaf_is_eq_2_13_without_shear_and_leadr_with(D):
    """Zero mean slope: G = G1 G1 / (G1 + G1 - G1 G1) (Eq. 2.13). Sheared: the BRDF is the
    LEADR supplemental's point-light radiance (Sec. 3.3), written from its own terms:
    ``f cos theta_i = F D / (4 (-x~n, -y~n, 1).o (1 + Lambda(o) + Lambda(i)))`` with
    ``Lambda(k) = int <k,h>+ D / ((-x~n, -y~n, 1).k) - 1`` (Eq. 9)."""
    rng = np.random.default_rng(6)
    wi, wo = _upper(rng, 4000), _upper(rng, 4000)
    d = D(alpha_x=0.3, alpha_y=0.6, rho=0.4)
    brdf = mf.MicrofacetBRDF(d)
    gi, go = d.g1(wi), d.g1(wo)
    np.testing.assert_allclose(brdf.gaf(wi, wo), gi * go / (gi + go - gi * go), rtol=1e-12)
    np.testing.assert_allclose(mf.MicrofacetBRDF(d, shadowing=False).gaf(wi, wo), go, rtol=1e-14)
    s = D(alpha_x=0.3, alpha_y=0.6, rho=0.4, mean_slope=(0.2, -0.4))
    mesonormal = np.array([-0.2, 0.4, 1.0])
    ci, co = wi @ mesonormal, wo @ mesonormal
    ok = (ci > 0) & (co > 0)
    lam_i = s.projected_area(wi) / np.where(ok, ci, 1) - 1
    lam_o = s.projected_area(wo) / np.where(ok, co, 1) - 1
    fresnel = mf.fresnel.Schlick(0.1)
    h = normalize(wi + wo)
    leadr = (fresnel(dot(wo, h))[:, 0] * s.ndf(h) / (4 * co * (1 + lam_o + lam_i)))
    ours = mf.MicrofacetBRDF(s, fresnel=fresnel).eval_cos(wi, wo)[:, 0]
    assert ok.sum() > 1000
    np.testing.assert_allclose(ours[ok], leadr[ok], rtol=1e-12)
    assert np.all(ours[~ok] == 0)


def test_vgroove_and_normal_map_match_table_2_iv():
    rng = np.random.default_rng(7)
    wi, wo = _upper(rng, 1000), _upper(rng, 1000)
    h = normalize(wi + wo)
    d = mf.GGX(alpha=0.3)
    ih, oh = dot(wi, h), dot(wo, h)
    vg = np.minimum(1, np.minimum(2 * wi[:, 2] * h[:, 2] / ih, 2 * wo[:, 2] * h[:, 2] / oh))
    np.testing.assert_allclose(mf.MicrofacetBRDF(d, gaf="vgroove").gaf(wi, wo), vg, rtol=1e-14)
    nm = wo[:, 2] * h[:, 2] / oh
    np.testing.assert_allclose(mf.MicrofacetBRDF(d, gaf="normal_map").gaf(wi, wo), nm, rtol=1e-14)


@pytest.mark.parametrize("D", DISTS, ids=lambda D: D.__name__)
def test_white_furnace(D):
    """With F = 1, the albedo is <= 1 (Smith: single scattering loses energy at high
    roughness; almost none is lost for smooth surfaces, sheared or not) and the sampling
    weights average to the same integral."""
    rng = np.random.default_rng(8)
    for kw in [dict(alpha=0.01), dict(alpha=0.3), dict(alpha_x=0.1, alpha_y=1.0, rho=0.5), dict(alpha=2.0),
               dict(alpha=0.01, mean_slope=(0.3, 0.0)), dict(alpha=0.3, mean_slope=(0.8, -0.5))]:
        brdf = mf.MicrofacetBRDF(D(**kw))
        for theta in (0.0, 1.0, 1.45):
            wo = spherical_to_cartesian(theta, 0.4 + np.pi * (theta > 1.2))
            if brdf.distribution._warp(wo)[2] <= 0:
                continue
            a = albedo(brdf, wo)
            assert 0 < a <= 1 + 1e-9, f"{kw} theta={theta}: albedo {a}"
            if kw == dict(alpha=0.01):
                assert a > 0.99 if theta < 1.2 else a > 0.9
            _, w, _ = brdf.sample(rng.random((100_000, 2)), wo)
            mc, sd = w[:, 0].mean(), w[:, 0].std() / np.sqrt(len(w))
            assert abs(mc - a) < 5 * sd + 1e-9, f"{kw} theta={theta}: MC {mc}±{sd} vs {a}"


def test_finite_at_tiny_alpha_and_grazing():
    rng = np.random.default_rng(9)
    for D in DISTS:
        for kw in [dict(alpha=1e-4), dict(alpha_x=1e-4, alpha_y=1.0, rho=0.9, mean_slope=(0.5, -1.0))]:
            for gaf in mf.brdf.GAFS:
                brdf = mf.MicrofacetBRDF(D(**_centred(kw, gaf)), fresnel=mf.fresnel.Schlick(0.04), gaf=gaf)
                wo = np.concatenate([_upper(rng, 500), [[0, 0, 1.0], [1, 0, 0], [1, 0, 1e-12], [0.6, 0.8, 1e-300]]])
                wo = normalize(wo)
                wi = np.concatenate([_upper(rng, 500), wo[-4:]])
                wi[:10] = reflect(wo[:10], [0, 0, 1.0])                 # exact mirror directions
                for v in (brdf.eval(wi, wo), brdf.eval_cos(wi, wo), brdf.pdf(wi, wo)):
                    assert np.all(np.isfinite(v)) and np.all(v >= 0)
                u = rng.random((len(wo), 2))
                u[:3] = [[0, 0], [1 - 2**-53, 0.5], [0.5, 1 - 2**-53]]
                for v in brdf.sample(u, wo):
                    assert np.all(np.isfinite(v))


def test_below_horizon_is_zero():
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.5))
    up, down = np.array([0.0, 0.6, 0.8]), np.array([0.0, 0.6, -0.8])
    assert np.all(brdf.eval(up, down) == 0) and np.all(brdf.eval(down, up) == 0)
    assert brdf.pdf(down, up) == 0 and brdf.pdf(up, down) == 0
    wi, w, p = brdf.sample(np.array([0.3, 0.3]), down)
    assert p == 0 and np.all(w == 0)


def test_lambertian():
    rng = np.random.default_rng(10)
    lam = mf.Lambertian([0.2, 0.5, 0.8])
    wi, wo = _upper(rng, 100), _upper(rng, 100)
    np.testing.assert_allclose(lam.eval(wi, wo), np.broadcast_to([0.2, 0.5, 0.8], (100, 3)) / np.pi)
    _, w, p = lam.sample(rng.random((100, 2)), wo)
    np.testing.assert_allclose(w, np.broadcast_to([0.2, 0.5, 0.8], (100, 3)))
    with pytest.raises(ValueError, match="reflectance"):
        mf.Lambertian(-1)


def test_invalid_arguments_raise():
    with pytest.raises(ValueError, match="gaf"):
        mf.MicrofacetBRDF(mf.GGX(alpha=0.1), gaf="smiht")
    with pytest.raises(ValueError, match="distribution"):
        mf.MicrofacetBRDF(0.1)
    with pytest.raises(ValueError, match="wi"):
        mf.MicrofacetBRDF(mf.GGX(alpha=0.1)).eval(np.zeros((4, 2)), np.zeros((4, 3)))


def test_vgroove_with_a_mean_slope_is_refused():
    """Table 2.IV's V-grooves stand on the macro normal; with a mean slope their albedo
    reached 1.78 (issue 11 sweeps), so the combination is an error, not a wrong result."""
    with pytest.raises(ValueError, match="vgroove.*zero mean slope"):
        mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3, mean_slope=(0.5, -1.0)), gaf="vgroove")
    mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3, mean_slope=(0.5, -1.0)), gaf="normal_map")


@pytest.mark.parametrize("dtype", [np.float64, np.float32], ids=["float64", "float32"])
@pytest.mark.parametrize("gaf", ["smith", "vgroove"])     # the compiled kernels and the NumPy path
def test_out_receives_the_same_results(gaf, dtype):
    """``eval``, ``eval_cos``, ``pdf`` and ``sample`` with ``out=`` write into and return the given
    arrays the values they return without it, over a batch the kernels split into tasks and with
    broadcast inputs."""
    rng = np.random.default_rng(3)
    n = mf.kernels.PARALLEL_MIN + 17
    wi, wo, u = _upper(rng, n), _upper(rng, n), rng.random((n, 2))
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.5), fresnel=mf.fresnel.Conductor.metal("Cu"),
                             gaf=gaf, dtype=dtype)
    for method, args in (("eval", (wi, wo)), ("eval_cos", (wi, wo[0])), ("pdf", (wi, wo))):
        want = getattr(brdf, method)(*args)
        out = np.full(want.shape, np.nan, dtype)
        assert getattr(brdf, method)(*args, out=out) is out
        np.testing.assert_array_equal(out, want)
    want = brdf.sample(u, wo)
    out = tuple(np.full(a.shape, np.nan, dtype) for a in want)
    got = brdf.sample(u, wo, out=out)
    assert all(g is o for g, o in zip(got, out))
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


def test_bad_out_raises_naming_it():
    """A wrong ``out`` (shape, dtype, layout, read-only, overlapping an input, not a 3-tuple for
    ``sample``) raises ``ValueError`` naming it; a bad input is reported before it."""
    rng = np.random.default_rng(4)
    wi, wo, u = _upper(rng, 50), _upper(rng, 50), rng.random((50, 2))
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.3))
    frozen = np.empty((50, 3))
    frozen.flags.writeable = False
    for out, what in ((np.empty((49, 3)), "shape"), (np.empty((50, 3), np.float32), "float32"),
                      (np.empty((3, 50)).T, "non-contiguous"), (frozen, "read-only"), ([[0.0] * 3] * 50, "list")):
        with pytest.raises(ValueError, match=f"out must be a writeable C-contiguous float64 array .*{what}"):
            brdf.eval(wi, wo, out=out)
    with pytest.raises(ValueError, match="out must not share memory"):
        brdf.eval(wi, wo, out=wi)
    with pytest.raises(ValueError, match="out must be a tuple of three"):
        brdf.sample(u, wo, out=np.empty((50, 3)))
    with pytest.raises(ValueError, match=r"out\[2\] must be .* of shape \(50,\)"):
        brdf.sample(u, wo, out=(np.empty((50, 3)), np.empty((50, 3)), np.empty((50, 3))))
    shared = np.empty((50, 3))
    with pytest.raises(ValueError, match="three arrays must not share"):
        brdf.sample(u, wo, out=(shared, shared, np.empty(50)))
    with pytest.raises(ValueError, match="wo must be unit vectors"):
        brdf.pdf(wi, 2.0 * wo, out=np.empty(49))


def test_every_brdf_takes_out(tmp_path):
    """The protocol's ``out=`` on every BRDF class (the NumPy paths, the measured kernels, the
    mixtures): the arrays given are returned, holding the values returned without them."""
    from microfacet.distributions.tabulated import TabulatedIsotropic, theta_grid
    from microfacet.fit import FittedBRDF
    from microfacet.fit.analytic import SumBRDF
    from microfacet.glints import Microsurface
    from microfacet.measured import merl
    rng = np.random.default_rng(9)
    n = 200
    wi, wo, u = _upper(rng, n), _upper(rng, n), rng.random((n, 2))
    ggx = mf.GGX(alpha_x=0.2, alpha_y=0.5)
    th = theta_grid(48)
    table = TabulatedIsotropic(np.exp(-np.tan(th) ** 2 / 0.3**2), alpha_x=0.8, alpha_y=1.2)
    i_h, i_d, i_p = np.meshgrid(np.arange(90), np.arange(90), np.arange(180), indexing="ij")
    raw = np.stack([0.2 + np.cos(i_h / 60.0) ** 8, 0.3 + 0.0 * i_d, 0.1 + 0.001 * i_p]) / merl.SCALE[:, None, None, None]
    path = tmp_path / "m.binary"
    path.write_bytes(np.array([90, 90, 180], "<i4").tobytes() + raw.astype("<f8").tobytes())
    slopes = rng.normal(scale=0.2, size=(16, 16, 2))
    ms = Microsurface.from_normal_map(mf.leadr.slopes_to_normals(slopes))
    brdfs = [mf.Lambertian(0.5), mf.MicrofacetBRDF(ggx, gaf="vgroove"),
             FittedBRDF(table, mf.fresnel.Schlick(0.04), diffuse=0.2), FittedBRDF(table, mf.fresnel.Schlick(0.04)),
             SumBRDF(mf.MicrofacetBRDF(ggx), mf.Lambertian(0.3)), ms.pbrdf((0.5, 0.5), np.eye(2) * 0.01),
             mf.measured.load(path)]
    for brdf in brdfs:
        for method, args in (("eval", (wi, wo)), ("eval_cos", (wi, wo)), ("pdf", (wi, wo)), ("sample", (u, wo))):
            want = getattr(brdf, method)(*args)
            if method == "sample":
                out = tuple(np.full(a.shape, np.nan) for a in want)
                got = brdf.sample(*args, out=out)
                assert all(g is o for g, o in zip(got, out)), type(brdf).__name__
            else:
                out = np.full(want.shape, np.nan)
                got = getattr(brdf, method)(*args, out=out)
                assert got is out, (type(brdf).__name__, method)
                got, want = (got,), (want,)
            for g, w in zip(got, want):
                np.testing.assert_array_equal(g, w, err_msg=f"{type(brdf).__name__}.{method}")
        with pytest.raises(ValueError, match="out must be"):
            brdf.pdf(wi, wo, out=np.empty(n + 1))
