"""Cross-check of the microfacet terms against Mitsuba 3 (``scalar_rgb`` variant).

Where the two models coincide (rho = 0, zero mean slope; Beckmann alpha has the same
meaning in both, slope standard deviation alpha/sqrt(2)) we compare, for Beckmann and
GGX, isotropic and anisotropic, alpha from 0.05 to 1 and views down to 1e-4 of the
horizon:

* the NDF ``D(h)`` against ``MicrofacetDistribution.eval(m)``;
* Smith ``G1(k)`` against ``smith_g1(v, m)``;
* the visible-normal density ``D_k(h) = <k,h> D(h) G1(k) / z_k`` (Eq. 2.17) against
  ``pdf(wi, m) = D(m) smith_g1(wi, m) |wi.m| / cos theta_i`` (``sample_visible=True``);
* the Fresnel term against ``mi.fresnel_conductor``;
* the full ``roughconductor`` BSDF (``eval`` and ``pdf``) against our terms.

Tolerances
----------
Inputs are rounded to float32 before both sides see them (directions and alphas), so
the differences come only from Mitsuba's float32 arithmetic, and we compare to our
float64 values. With the float32 unit roundoff ``U = 2**-24`` (about 6e-8), each of
Mitsuba's expressions is a few tens of roundings, so we allow ``RTOL_F32 = 32 U``
(about 1.9e-6) for the well-conditioned rational and square-root forms (GGX D and G1).
Beckmann ``D = exp(-X) / (...)`` with ``X = (x^2/ax^2 + y^2/ay^2) / z^2`` turns a
relative error of a few U in X into an error of a few ``U X`` in D, so there we allow
``RTOL_F32 (1 + X)``; Mitsuba flushes D to 0 where ``D cos theta_h <= 1e-20``, which
bounds X by about 50 where values are compared (so the bound stays below 1e-4).

Mitsuba's Beckmann G1 is not the exact Smith function (Table 2.III,
``G1 = 2 / (1 + erf(a) + exp(-a^2) / (a sqrt(pi)))``, ``a = 1 / (alpha_k tan theta)``)
but the rational approximation
``(3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)`` (1 for ``a >= 1.6``), documented in
its source as "< 0.35 % rel. error". Our own dense sweep of ``a`` finds
a largest error of 0.3127 % (at ``a ~ 1.34``), so the raw comparison uses
``BECKMANN_G1_APPROX = 3.2e-3`` (plus the float32 term), and the Beckmann quantities
that contain G1 (the visible-normal pdf, the BSDF) inherit that bound (twice, for the
separable G1 G1 of ``roughconductor``). We also check, at float32 precision, that
Mitsuba's Beckmann G1 *is* that rational function of the same ``a`` (so that the
anisotropic projected roughness is the same in both) and that, once the approximation
is divided out, everything agrees to float32 precision again.

Run ``python tests/test_mitsuba.py`` to print the largest relative errors measured.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.special import erf

import microfacet as mf

mi = pytest.importorskip(
    "mitsuba", reason="Mitsuba 3 cross-checks need the optional `mitsuba` package "
                      "(pip install 'microfacet[mitsuba]')")
dr = pytest.importorskip("drjit", reason="Mitsuba 3 cross-checks need drjit (installed with mitsuba)")

U = 2.0**-24                  # float32 unit roundoff
RTOL_F32 = 32 * U             # ~1.9e-6: a few tens of float32 roundings
BECKMANN_G1_APPROX = 3.2e-3   # measured max error of Mitsuba's rational Beckmann G1: 3.127e-3
MI_D_CUTOFF = 1e-20           # Mitsuba returns D = 0 where D cos theta_h <= 1e-20

# (alpha_u, alpha_v): isotropic smooth/medium/rough, anisotropic both ways, extreme ratio
ALPHAS = [(0.05, 0.05), (0.3, 0.3), (1.0, 1.0), (0.1, 0.6), (0.8, 0.2), (0.05, 1.0)]
KINDS = {"beckmann": mf.Beckmann, "ggx": mf.GGX}
GRAZING_COS = (1e-4, 1e-3, 1e-2, 0.05, 0.1)
CASES = [(kind, au, av) for kind in KINDS for au, av in ALPHAS]
IDS = [f"{kind}-{au}-{av}" for kind, au, av in CASES]

#: largest relative error, and largest error / tolerance, per (quantity, distribution)
MAX_REL_ERR: dict[tuple[str, str], float] = {}
MAX_ERR_OVER_TOL: dict[tuple[str, str], float] = {}


# --------------------------------------------------------------------------- helpers
@pytest.fixture(scope="module", autouse=True)
def scalar_rgb():
    """Select Mitsuba's ``scalar_rgb`` variant for this module, restoring the previous one."""
    previous = mi.variant()
    if "scalar_rgb" not in mi.variants():
        pytest.skip("this Mitsuba build has no scalar_rgb variant")
    mi.set_variant("scalar_rgb")
    yield
    if previous is not None:
        mi.set_variant(previous)


def f32(a) -> np.ndarray:
    """Round to float32 (what Mitsuba sees) and back to float64 (what we compute with)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def directions(rng, n: int) -> np.ndarray:
    """Upper-hemisphere test directions, float32-exact: ``n`` uniform in solid angle, the
    normal, both tangent axes at 60 degrees, and grazing ones (cos theta down to 1e-4)."""
    z = np.concatenate([rng.uniform(0.0, 1.0, n), [1.0, 0.5, 0.5], GRAZING_COS * 2])
    phi = rng.uniform(0.0, 2.0 * np.pi, len(z))
    phi[n:n + 3] = (0.0, 0.0, np.pi / 2)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return f32(np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1))


def vec(v) -> "mi.Vector3f":
    return mi.Vector3f(float(v[0]), float(v[1]), float(v[2]))


def mi_distribution(kind: str, au: float, av: float):
    mtype = {"beckmann": mi.MicrofacetType.Beckmann, "ggx": mi.MicrofacetType.GGX}[kind]
    return mi.MicrofacetDistribution(mtype, au, av, True)


def setup(kind: str, au: float, av: float, seed: int):
    """float32-exact alphas, our distribution, Mitsuba's, and a seeded generator."""
    au, av = float(np.float32(au)), float(np.float32(av))
    return (au, av, KINDS[kind](alpha_x=au, alpha_y=av), mi_distribution(kind, au, av),
            np.random.default_rng(seed))


def beckmann_exponent(h, au, av) -> np.ndarray:
    """``X = (x^2/ax^2 + y^2/ay^2) / z^2``: Beckmann ``D ∝ exp(-X)`` (Table 2.II)."""
    return (h[..., 0] ** 2 / au**2 + h[..., 1] ** 2 / av**2) / h[..., 2] ** 2


def cot_alpha(k, au, av) -> np.ndarray:
    """``a = z / sqrt((ax x)^2 + (ay y)^2) = 1 / (alpha_k tan theta_k)`` (Eq. 2.26)."""
    with np.errstate(divide="ignore"):
        return k[..., 2] / np.hypot(au * k[..., 0], av * k[..., 1])


def beckmann_g1_exact(a) -> np.ndarray:
    """Smith G1 of Beckmann surfaces, written independently of the library (Table 2.III)."""
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(divide="ignore", over="ignore", invalid="ignore"):
        g = 2.0 / (1.0 + erf(a) + np.exp(-a * a) / (a * np.sqrt(np.pi)))
    return np.where(np.isinf(a), 1.0, g)


def beckmann_g1_mitsuba(a) -> np.ndarray:
    """Mitsuba 3's rational approximation of Beckmann G1 (``microfacet.h``), in float64."""
    a = np.asarray(a, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        g = (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
    return np.where(a >= 1.6, 1.0, g)


def approx_ratio(kind, k, au, av) -> np.ndarray:
    """Mitsuba G1 / exact G1: what its Beckmann approximation multiplies G1 by (1 for GGX)."""
    if kind != "beckmann":
        return np.ones(k.shape[:-1])
    a = cot_alpha(k, au, av)
    return beckmann_g1_mitsuba(a) / beckmann_g1_exact(a)


def near_switch(k, au, av) -> np.ndarray:
    """Directions whose ``a`` is within float32 noise of the approximation's switch at 1.6."""
    return np.abs(cot_alpha(k, au, av) - 1.6) < 1e-5


def check(quantity: str, kind: str, theirs, ours, rtol, where=None) -> float:
    """Assert ``|theirs - ours| <= rtol |ours|`` (``rtol`` may be an array) and record the
    largest relative error; returns it."""
    theirs, ours = np.broadcast_arrays(np.asarray(theirs, float), np.asarray(ours, float))
    rtol = np.broadcast_to(rtol, ours.shape)
    sel = np.ones(ours.shape, bool) if where is None else np.broadcast_to(where, ours.shape)
    assert np.all(np.isfinite(ours[sel])), f"{quantity}/{kind}: non-finite values of ours"
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(sel, np.abs(theirs - ours) / np.abs(ours), 0.0)
    rel = np.where(sel & (theirs == ours), 0.0, rel)
    worst = float(np.max(rel, initial=0.0))
    key = (quantity, kind)
    MAX_REL_ERR[key] = max(MAX_REL_ERR.get(key, 0.0), worst)
    bad = sel & ~(rel <= rtol)
    i = np.unravel_index(np.argmax(np.where(sel, rel / rtol, 0.0)), rel.shape)
    MAX_ERR_OVER_TOL[key] = max(MAX_ERR_OVER_TOL.get(key, 0.0), float(rel[i] / rtol[i]))
    assert not np.any(bad), (
        f"{quantity}/{kind}: {bad.sum()} of {sel.sum()} values beyond tolerance; "
        f"max rel. error {worst:.3e}; worst at index {i}: mitsuba {theirs[i]!r}, "
        f"ours {ours[i]!r}, rtol {rtol[i]:.3e}")
    return worst


# ---------------------------------------------------------------------- NDF D(h)
@pytest.mark.parametrize("kind,au,av", CASES, ids=IDS)
def test_ndf_matches_mitsuba(kind, au, av):
    au, av, d, md, rng = setup(kind, au, av, seed=1)
    # normals distributed as the NDF (the values that matter), then uniform ones (tails)
    # and a few below the horizon (both must give 0)
    h = np.concatenate([d.sample_p22(rng.random((150, 2))), directions(rng, 100),
                        directions(rng, 5) * np.array([1.0, 1.0, -1.0])])
    h = f32(h)
    theirs = np.array([md.eval(vec(m)) for m in h])
    ours = d.ndf(h)
    assert np.all(ours[h[:, 2] < 0] == 0) and np.all(theirs[h[:, 2] < 0] == 0)
    # where Mitsuba flushes to zero, ours must be under its threshold too
    flushed = (theirs == 0) & (h[:, 2] > 0)
    assert np.all(ours[flushed] * h[flushed, 2] <= MI_D_CUTOFF * (1 + 1e-4)), \
        "Mitsuba flushed a D value that is not below its 1e-20 cutoff"
    assert np.count_nonzero(theirs) >= 150  # the comparison below is not vacuous
    if kind == "beckmann":
        rtol = RTOL_F32 * (1.0 + beckmann_exponent(h, au, av))
    else:
        rtol = RTOL_F32
    check("D", kind, theirs, ours, rtol, where=theirs > 0)


# ------------------------------------------------------------------ Smith G1(k)
@pytest.mark.parametrize("kind,au,av", CASES, ids=IDS)
def test_g1_matches_mitsuba(kind, au, av):
    au, av, d, md, rng = setup(kind, au, av, seed=2)
    k = directions(rng, 200)
    up = vec((0.0, 0.0, 1.0))   # a microfacet normal that k sees (orientation test passes)
    theirs = np.array([md.smith_g1(vec(v), up) for v in k])
    ours = d.g1(k)
    if kind == "ggx":
        check("G1", kind, theirs, ours, RTOL_F32)
        return
    # 1) raw: Mitsuba's rational approximation is within its error bound of ours
    check("G1 (raw)", kind, theirs, ours, BECKMANN_G1_APPROX + RTOL_F32)
    # 2) Mitsuba's G1 is that rational function of the same a = 1/(alpha_k tan theta)
    ok = ~near_switch(k, au, av)
    check("G1 rational vs formula", kind, theirs, beckmann_g1_mitsuba(cot_alpha(k, au, av)),
          RTOL_F32, where=ok)
    # 3) with the approximation divided out, ours agrees to float32 precision
    check("G1 (approx. divided out)", kind, theirs / approx_ratio(kind, k, au, av), ours,
          RTOL_F32, where=ok)


def test_beckmann_g1_approximation_bound():
    """The bound used above is the true error of Mitsuba's approximation (dense sweep)."""
    a = np.geomspace(1e-4, 50.0, 400_001)
    err = np.abs(beckmann_g1_mitsuba(a) / beckmann_g1_exact(a) - 1.0)
    assert 3.0e-3 < err.max() <= BECKMANN_G1_APPROX, err.max()
    # and our G1 is the exact one along the same sweep (k in the xz plane, alpha = 1)
    theta = np.arctan(1.0 / a)
    k = np.stack([np.sin(theta), np.zeros_like(a), np.cos(theta)], axis=-1)
    np.testing.assert_allclose(mf.Beckmann(alpha=1.0).g1(k), beckmann_g1_exact(a), rtol=1e-10)


# --------------------------------------------------------- visible-normal pdf D_k(h)
@pytest.mark.parametrize("kind,au,av", CASES, ids=IDS)
def test_vndf_matches_mitsuba_pdf(kind, au, av):
    au, av, d, md, rng = setup(kind, au, av, seed=3)
    k = directions(rng, 150)
    # normals from Mitsuba's own visible-normal sampler (independent of ours) ...
    u = rng.random((len(k), 2))
    h_vis = np.array([np.array(md.sample(vec(v), mi.Point2f(*map(float, s)))[0]) for v, s in zip(k, u)])
    # ... and arbitrary ones, including back-facing (k.h <= 0: both give 0)
    h_any = directions(rng, len(k) - 13)
    kk, h = np.concatenate([k, k]), f32(np.concatenate([h_vis, h_any]))
    theirs = np.array([md.pdf(vec(v), vec(m)) for v, m in zip(kk, h)])
    ours = d.vndf(h, kk)
    back = np.sum(kk * h, axis=-1) <= 0
    assert back.any() and np.all(ours[back] == 0) and np.all(theirs[back] == 0)
    assert np.count_nonzero(theirs) >= len(k)
    # Mitsuba's pdf is 0 elsewhere only where it flushed D to 0 (see test_ndf)
    zero = (theirs == 0) & ~back
    assert np.all((ours[zero] == 0) | (d.ndf(h[zero]) * h[zero, 2] <= MI_D_CUTOFF * (1 + 1e-4)))
    x = beckmann_exponent(h, au, av) if kind == "beckmann" else 0.0
    rtol = RTOL_F32 * (1.0 + x)
    ok = theirs > 0
    if kind == "ggx":
        check("vndf pdf", kind, theirs, ours, rtol, where=ok)
        return
    # Mitsuba's pdf contains its approximate G1(k): raw bound, then divided out
    check("vndf pdf (raw)", kind, theirs, ours, BECKMANN_G1_APPROX + rtol, where=ok)
    ok &= ~near_switch(kk, au, av)
    check("vndf pdf (approx. divided out)", kind, theirs / approx_ratio(kind, kk, au, av),
          ours, rtol, where=ok)


# ------------------------------------------------------------------- Fresnel term
def test_conductor_fresnel_matches_mitsuba():
    rng = np.random.default_rng(4)
    cos = f32(np.concatenate([rng.random(200), [1.0, 1e-4, 1e-2]]))
    for name, (eta, k) in mf.fresnel.Conductor.METALS.items():
        eta, k = f32(eta), f32(k)
        ours = mf.fresnel.Conductor(eta, k)(cos)
        theirs = np.array([[mi.fresnel_conductor(float(c), dr.scalar.Complex2f(float(e), float(kk)))
                            for e, kk in zip(eta, k)] for c in cos])
        check("Fresnel conductor", name, theirs, ours, RTOL_F32)


# -------------------------------------------------------- full BSDF: roughconductor
METAL = "Cu"


def roughconductor(kind, au, av):
    eta, k = (f32(v) for v in mf.fresnel.Conductor.METALS[METAL])
    bsdf = mi.load_dict({
        "type": "roughconductor", "distribution": kind, "alpha_u": au, "alpha_v": av,
        "eta": {"type": "rgb", "value": eta.tolist()}, "k": {"type": "rgb", "value": k.tolist()},
        "specular_reflectance": 1.0, "sample_visible": True})
    return bsdf, mf.fresnel.Conductor(eta, k)


@pytest.mark.parametrize("kind,au,av", CASES, ids=IDS)
def test_roughconductor_matches_our_terms(kind, au, av):
    """Mitsuba's ``f cos theta`` is ``F D G1(i) G1(o) / (4 cos theta_o)`` (separable Smith).

    We assemble the same from our terms, compare, and compare our height-correlated
    ``MicrofacetBRDF.eval`` after the known factor ``G1(i) G1(o) / G2(i, o)``;
    ``MicrofacetBRDF.pdf`` must equal Mitsuba's pdf (both are ``D_o(h) / (4 o.h)``).
    """
    au, av, d, md, rng = setup(kind, au, av, seed=5)
    bsdf, fresnel = roughconductor(kind, au, av)
    ours_brdf = mf.MicrofacetBRDF(d, fresnel=fresnel, gaf="smith")
    wo = directions(rng, 150)                       # view: Mitsuba's si.wi
    # light directions: Mitsuba's own samples (where the lobe is) and uniform ones
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    wi_s = []
    for v, s in zip(wo, rng.random((len(wo), 2))):
        si.wi = vec(v)
        bs, _ = bsdf.sample(ctx, si, 0.5, mi.Point2f(*map(float, s)))
        wi_s.append(np.array(bs.wo))
    wi = f32(np.concatenate([wi_s, directions(rng, len(wo) - 13)]))
    wo = np.concatenate([wo, wo])
    valid = (wi[:, 2] > 0) & (wo[:, 2] > 0)         # failed samples may point below
    f_cos, pdf = [], []
    for light, view in zip(wi, wo):
        si.wi = vec(view)
        f_cos.append(np.array(bsdf.eval(ctx, si, vec(light))))
        pdf.append(bsdf.pdf(ctx, si, vec(light)))
    f_cos, pdf = np.array(f_cos), np.array(pdf)
    with np.errstate(divide="ignore", invalid="ignore"):
        theirs = np.where(valid[:, None], f_cos / wi[:, 2:3], 0.0)   # f = (f cos theta_i) / cos theta_i
    h = mf.geometry.half_vector(wi, wo)
    with np.errstate(divide="ignore", invalid="ignore"):
        sep = fresnel(mf.geometry.dot(wo, h)) * (
            d.ndf(h) * d.g1(wi) * d.g1(wo) / (4.0 * wi[:, 2] * wo[:, 2]))[:, None]
    sep = np.where(valid[:, None], sep, 0.0)
    ok = theirs > 0
    assert np.all(sep[~valid] == 0) and np.all(theirs[~valid] == 0)
    assert np.count_nonzero(ok[:, 0]) >= 100
    # D is evaluated at the half vector, computed in float32 by Mitsuba: its rounding
    # (a few U) is amplified like the exponent error, hence the same (1 + X) factor
    x = beckmann_exponent(h, au, av)[:, None] if kind == "beckmann" else 0.0
    rtol = 2 * RTOL_F32 * (1.0 + x)
    # Mitsuba's separable G and ours, to divide out its Beckmann approximation
    ratio = (approx_ratio(kind, wi, au, av) * approx_ratio(kind, wo, au, av))[:, None]
    g_sep = (d.g1(wi) * d.g1(wo))[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        g_ratio = g_sep / ours_brdf.gaf(wi, wo)[:, None]
    if kind == "ggx":
        check("BSDF f (our D G1 G1 F)", kind, theirs, sep, rtol, where=ok)
        check("BSDF f (MicrofacetBRDF.eval x G1G1/G2)", kind, theirs,
              ours_brdf.eval(wi, wo) * g_ratio, rtol, where=ok)
    else:
        raw = (1 + BECKMANN_G1_APPROX) ** 2 - 1
        check("BSDF f raw (our D G1 G1 F)", kind, theirs, sep, raw + rtol, where=ok)
        ok &= ~(near_switch(wi, au, av) | near_switch(wo, au, av))[:, None]
        check("BSDF f (approx. divided out)", kind, theirs / ratio, sep, rtol, where=ok)
        check("BSDF f (MicrofacetBRDF.eval x G1G1/G2)", kind, theirs / ratio,
              ours_brdf.eval(wi, wo) * g_ratio, rtol, where=ok)
    # height-correlated G2 >= separable G1 G1: our BRDF is never below Mitsuba's
    # beyond the approximation / rounding error
    slack = 1 + (BECKMANN_G1_APPROX * 2 if kind == "beckmann" else 0) + rtol
    assert np.all((ours_brdf.eval(wi, wo) * slack >= theirs)[ok])
    # pdf: Mitsuba D G1(view) / (4 cos theta_view) == our D_o(h) / (4 o.h)
    ours_pdf = ours_brdf.pdf(wi, wo)
    flushed = d.ndf(h) * h[:, 2] <= MI_D_CUTOFF * (1 + 1e-4)   # Mitsuba's D = 0 there
    assert np.all((ours_pdf[pdf == 0] == 0) | flushed[pdf == 0])
    assert np.all(((sep == 0) | flushed[:, None])[~ok])
    okp = pdf > 0
    rtol_p = rtol[:, 0] if kind == "beckmann" else rtol
    if kind == "ggx":
        check("BSDF pdf (MicrofacetBRDF.pdf)", kind, pdf, ours_pdf, rtol_p, where=okp)
    else:
        check("BSDF pdf raw (MicrofacetBRDF.pdf)", kind, pdf, ours_pdf,
              BECKMANN_G1_APPROX + rtol_p, where=okp)
        okp &= ~near_switch(wo, au, av)
        check("BSDF pdf (approx. divided out)", kind, pdf / approx_ratio(kind, wo, au, av),
              ours_pdf, rtol_p, where=okp)


# --------------------------------------------------------------------------- report
def main() -> None:  # pragma: no cover - manual report
    """Run every check and print the largest relative error per quantity."""
    mi.set_variant("scalar_rgb")
    for kind, au, av in CASES:
        test_ndf_matches_mitsuba(kind, au, av)
        test_g1_matches_mitsuba(kind, au, av)
        test_vndf_matches_mitsuba_pdf(kind, au, av)
        test_roughconductor_matches_our_terms(kind, au, av)
    test_conductor_fresnel_matches_mitsuba()
    print(f"{'quantity':40s} {'distribution':>12s} {'max rel. error':>15s} {'max error/tol':>14s}")
    for (quantity, kind), err in sorted(MAX_REL_ERR.items()):
        print(f"{quantity:40s} {kind:>12s} {err:15.3e} {MAX_ERR_OVER_TOL[quantity, kind]:14.3f}")


if __name__ == "__main__":  # pragma: no cover
    main()
