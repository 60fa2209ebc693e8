"""GLSL shaders on a real GL (moderngl, headless EGL: Mesa llvmpipe) against the NumPy
library: relative error <= 1e-4 where the reference exceeds 1e-3 of its maximum (float32
shaders vs float64 references at the same float32-rounded inputs).

Skips with a one-line reason where moderngl or an EGL driver is missing; fails under CI=true.
"""

import numpy as np
import pytest

import microfacet as mf
from conftest import rel_error
from microfacet import fresnel as fr
from microfacet.errors import MicrofacetError
from microfacet.glsl import SHADERS, export_textures, source
from microfacet.leadr import shading

TOL = 1e-4
#: Texture filtering by the GL (exact in llvmpipe; quantized weights on GPUs: :func:`filter_quantum`) or in float32 (MF_MANUAL_BILINEAR)
FILTERS = {"hardware": None, "manual": {"MF_MANUAL_BILINEAR": None}}





def directions(rng, n, max_theta=np.radians(89.5)):
    """Unit directions (float32-exact) over the hemisphere, half of them beyond 70 degrees."""
    t = np.concatenate([rng.uniform(0, max_theta, n // 2), rng.uniform(min(np.radians(70), 0.8 * max_theta), max_theta, n - n // 2)])
    p = rng.uniform(0, 2 * np.pi, n)
    w = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).astype(np.float32)
    return w.astype(np.float64)


def surface_uniforms(d, dist: int):
    return dict(s_dist=dist, s_alpha=(float(d.alpha_x), float(d.alpha_y)), s_rho=float(d.rho),
                s_mean=tuple(map(float, d.mean_slope)))


SURFACE = """
uniform int s_dist; uniform vec2 s_alpha; uniform float s_rho; uniform vec2 s_mean;
uniform int f_kind; uniform vec3 f_a; uniform vec3 f_b; uniform bool shadowing;
"""
FRESNELS = [(fr.Ideal(), 0, 0, 0), (fr.Schlick((0.9, 0.6, 0.3)), 1, (0.9, 0.6, 0.3), 1),
            (fr.Schlick((0.9, 0.6, 0.3), f90=0.5), 1, (0.9, 0.6, 0.3), 0.5),
            (fr.Dielectric(1.5), 2, (1.5,) * 3, 0), (fr.Conductor.metal("Au"), 3, *fr.Conductor.METALS["Au"])]


@pytest.mark.parametrize("dist", [mf.Beckmann, mf.GGX])
@pytest.mark.parametrize("params", [dict(alpha=0.3), dict(alpha_x=0.2, alpha_y=0.6, rho=0.5),
                                    dict(alpha_x=0.4, alpha_y=0.25, rho=-0.3, mean_slope=(0.3, -0.2)),
                                    dict(alpha=0.05, mean_slope=(-0.1, 0.05))],
                         ids=["isotropic", "correlated", "sheared", "sharp"])
def test_microfacet_brdf(gl, dist, params):
    rng = np.random.default_rng(1)
    wi, wo = directions(rng, 4000), directions(rng, 4000)
    d = dist(**params)
    for i, (fresnel, kind, a, b) in enumerate(FRESNELS):
        shadowing = i % 2 == 0
        ref = mf.MicrofacetBRDF(d, fresnel, shadowing=shadowing).eval_cos(wi, wo)
        u = dict(surface_uniforms(d, 0 if dist is mf.Beckmann else 1), f_kind=kind,
                 f_a=np.broadcast_to(a, 3), f_b=np.broadcast_to(b, 3), shadowing=shadowing)
        got = gl.evaluate("microfacet", """
            MfSurface s = MfSurface(s_dist, s_alpha, s_rho, s_mean);
            result = vec4(mf_eval_cos(s, MfFresnel(f_kind, f_a, f_b), shadowing, wi.xyz, wo.xyz), 0.0);""",
                          {"wi": wi, "wo": wo}, uniforms=u, declarations=SURFACE)
        assert rel_error(got[:, :3], ref) <= TOL, (fresnel, shadowing)


def test_microfacet_terms_at_grazing(gl):
    """D, Lambda and G1 near the horizon (theta up to 89.9 degrees), sheared Beckmann."""
    rng = np.random.default_rng(2)
    k = directions(rng, 2000, np.radians(89.9))
    d = mf.Beckmann(alpha_x=0.3, alpha_y=0.5, rho=0.4, mean_slope=(0.2, 0.1))
    got = gl.evaluate("microfacet", """
        MfSurface s = MfSurface(s_dist, s_alpha, s_rho, s_mean);
        result = vec4(mf_ndf(s, k.xyz), 1.0 / (1.0 + mf_lambda(s, k.xyz)), mf_g1(s, k.xyz), 0.0);""",
                      {"k": k}, uniforms=surface_uniforms(d, 0), declarations=SURFACE)
    assert rel_error(got[:, 0], d.ndf(k)) <= TOL
    assert rel_error(got[:, 1], 1.0 / (1.0 + d.lambda_(k))) <= TOL
    assert rel_error(got[:, 2], d.g1(k)) <= TOL


def random_moments(rng, n):
    """Valid moments: mean slopes up to 0.4, alpha 0.05-0.6, correlation up to 0.8."""
    mean = rng.uniform(-0.4, 0.4, (n, 2))
    alpha = rng.uniform(0.05, 0.6, (n, 2))
    rho = rng.uniform(-0.8, 0.8, n)
    var = 0.5 * alpha**2
    cxy = rho * np.sqrt(var[:, 0] * var[:, 1])
    e = np.column_stack([mean, var + mean**2, cxy + mean[:, 0] * mean[:, 1]])
    return e.astype(np.float32).astype(np.float64)


MOMENTS = "MfMoments e = MfMoments(e1234, e5.x);"


def moment_inputs(e):
    return {"e1234": e[:, :4], "e5": e[:, 4:]}


@pytest.mark.parametrize("shadowing", [True, False])
def test_leadr_point_light(gl, shadowing):
    rng = np.random.default_rng(3)
    e = random_moments(rng, 4000)
    wi, wo = directions(rng, 4000), directions(rng, 4000)
    ag = fr.Conductor.metal("Ag")
    ref = shading.point_light(e, wi, wo, 2.0, ag, shadowing=shadowing)
    got = gl.evaluate("leadr", MOMENTS + """
        result = vec4(mf_point_light(e, wi.xyz, wo.xyz, vec3(2.0), MfFresnel(3, f_a, f_b), shadowing), 0.0);""",
                      dict(moment_inputs(e), wi=wi, wo=wo), declarations=SURFACE,
                      uniforms=dict(f_a=ag.eta, f_b=ag.k, shadowing=shadowing))
    assert rel_error(got[:, :3], ref) <= TOL


def test_leadr_convolve_micronormal_area(gl):
    """Listing 5.1 (base merge), the artificial micronormal (Sec. 3.7) and A(k) (Eq. 4, 9)."""
    rng = np.random.default_rng(8)
    e, b = random_moments(rng, 2000), random_moments(rng, 2000)
    wo = directions(rng, 2000)
    got = gl.evaluate("leadr", MOMENTS + """
        MfMoments c = mf_convolve(e, MfMoments(b1234, b5.x));
        result = c.e1234;""", dict(moment_inputs(e), b1234=b[:, :4], b5=b[:, 4:]))
    got5 = gl.evaluate("leadr", MOMENTS + "result = vec4(mf_convolve(e, MfMoments(b1234, b5.x)).e5);",
                       dict(moment_inputs(e), b1234=b[:, :4], b5=b[:, 4:]))
    ref = mf.leadr.convolve(e, b)
    np.testing.assert_allclose(np.column_stack([got, got5[:, 0]]), ref, rtol=1e-5, atol=1e-7)
    got = gl.evaluate("leadr", MOMENTS + """
        result = vec4(mf_artificial_micronormal(e, wo.xyz), mf_leadr_projected_area(e, wo.xyz));""",
                      dict(moment_inputs(e), wo=wo))
    np.testing.assert_allclose(got[:, :3], shading.artificial_micronormal(e, wo), atol=1e-5)   # unit vectors
    assert rel_error(got[:, 3], shading.projected_area(e, wo)) <= TOL


def random_frames(rng, n):
    nn = directions(rng, n, np.radians(60))[:, [0, 2, 1]]          # world y up
    s, t = mf.geometry.orthonormal_basis(nn)
    return s, t, nn


FRAME = "mat3 frame = mat3(fs.xyz, ft.xyz, fn.xyz);"
ENV = "uniform highp sampler2D env; uniform int env_top; uniform float env_T; uniform int grid;"


#: ``u`` of a 2-texel row at which the bilinear weight of texel 1 is ``k / 4096`` exactly (float32).
PROBE_U = 0.25 + 0.5 * np.arange(4097) / 4096


def filter_weights(gl, u, defines=None):
    """The weight a bilinear lookup (``mf_sample_level``) gives texel 1 of a 2-texel row (values 0
    and 1) at ``u``: the GL's filter, or with ``MF_MANUAL_BILINEAR`` the shader's."""
    row = np.zeros((1, 2, 4), np.float32)
    row[0, 1] = 1.0
    return gl.evaluate("leadr", "result = mf_sample_level(probe, vec2(u.x, 0.5), 0, bvec2(false));",
                       {"u": u[:, None]}, declarations="uniform highp sampler2D probe;",
                       textures={"probe": ([row], (False, False))}, defines=defines)[:, 0].astype(float)


@pytest.fixture(scope="module")
def filter_quantum(gl):
    """``None`` where the GL filters with float weights (llvmpipe), else the step ``2^-b`` of its
    bilinear weights, read off :func:`filter_weights` (GPUs: NVIDIA H200, ``b = 8``)."""
    levels = np.unique(filter_weights(gl, PROBE_U)).size
    return None if levels == PROBE_U.size else 2.0 ** -round(np.log2(levels - 1))


def test_filter_weights(gl, filter_quantum):
    """The manual filter's weights are exact; the GL's are exact, or within a step of them, in order."""
    exact = np.arange(PROBE_U.size) / 4096
    assert np.array_equal(filter_weights(gl, PROBE_U, {"MF_MANUAL_BILINEAR": None}), exact)
    w = filter_weights(gl, PROBE_U)
    if filter_quantum is None:
        assert np.array_equal(w, exact)
    else:
        assert np.all(np.diff(w) >= 0) and np.max(np.abs(w - exact)) <= filter_quantum


@pytest.mark.parametrize("n,filtering", [(5, "hardware"), (8, "manual")])
def test_leadr_env_grid(gl, filter_quantum, n, filtering):
    """``mf_env_specular`` vs the library; the hardware path, where the GL quantizes its weights by
    ``q``, within the bound that gives: each bilinear tap within ``2 q max(env)`` (a step per axis
    over the taps' range), the grid's weights summing to the shading of a white environment."""
    rng = np.random.default_rng(4)
    m = 3000
    e = random_moments(rng, m)
    wo = directions(rng, m, np.radians(85))
    s, t, nn = random_frames(rng, m)
    env = shading.MipEnvironment(mf.render.lights.procedural_sky(32, 64).astype(np.float32))
    ag = fr.Conductor.metal("Ag")
    ref = shading.env_specular(e, wo, env, (s, t, nn), n=n, fresnel=ag)
    got = gl.evaluate("leadr", MOMENTS + FRAME + """
        result = vec4(mf_env_specular(e, wo.xyz, frame, env, env_top, env_T, grid, MfFresnel(3, f_a, f_b),
                                      mf_lod_bias(grid), true), 0.0);""",
                      dict(moment_inputs(e), wo=wo, fs=s, ft=t, fn=nn), declarations=SURFACE + ENV,
                      textures={"env": ([lv.map for lv in env.levels], (True, False))}, defines=FILTERS[filtering],
                      uniforms=dict(f_a=ag.eta, f_b=ag.k, env_top=len(env.levels) - 1,
                                    env_T=env.texture_size, grid=n))[:, :3]
    if filtering == "hardware" and filter_quantum is not None:
        white = shading.env_specular(e, wo, shading.MipEnvironment(np.ones((32, 64, 3), np.float32)),
                                     (s, t, nn), n=n, fresnel=ag)
        bound = 2 * filter_quantum * max(lv.map.max() for lv in env.levels) * white + TOL * np.abs(ref)
        assert np.all(np.abs(got - ref) <= bound)
    else:
        assert rel_error(got, ref) <= TOL


def test_leadr_sh_diffuse(gl):
    rng = np.random.default_rng(5)
    m = 3000
    e = random_moments(rng, m)
    wo = directions(rng, m, np.radians(85))
    s, t, nn = random_frames(rng, m)
    coeffs = shading.sh_add_directional(shading.sh_project(mf.render.lights.procedural_sky(32, 64)),
                                        (0.3, 1.0, 0.2), 2.0)
    albedo = (0.8, 0.5, 0.3)
    ref = shading.diffuse_sh(e, wo, coeffs, (s, t, nn), albedo=albedo)
    got = gl.evaluate("leadr", MOMENTS + FRAME + """
        result = vec4(mf_diffuse_sh(e, wo.xyz, frame, sh, albedo, 5, true), 0.0);""",
                      dict(moment_inputs(e), wo=wo, fs=s, ft=t, fn=nn),
                      declarations="uniform vec3 sh[9]; uniform vec3 albedo;",
                      uniforms=dict(sh=coeffs, albedo=albedo))
    assert rel_error(got[:, :3], ref) <= TOL


@pytest.mark.parametrize("filtering", ["hardware", "manual"])
def test_leadr_lookup(gl, filter_quantum, filtering):
    """The GLSL footprint lookup (anisotropic trilinear probes) vs mf.leadr.lookup; the hardware
    path, where the GL quantizes its weights by ``q``, within ``2 q`` times the texels' range (a
    step per axis; probes and levels are convex combinations of taps)."""
    rng = np.random.default_rng(6)
    h = mf.leadr.gaussian_heightfield((64, 48), 0.3, correlation=4.0, seed=1)
    pyramid = mf.leadr.bake(h, 1.0, 0.1)
    m = 2000
    uv = rng.uniform(-0.5, 1.5, (m, 2))
    a = rng.normal(0, 1, (m, 2)) * np.exp(rng.uniform(-7, 0, (m, 1)))
    b = rng.normal(0, 1, (m, 2)) * np.exp(rng.uniform(-7, 0, (m, 1)))
    uv, a, b = (v.astype(np.float32).astype(np.float64) for v in (uv, a, b))
    ref = mf.leadr.lookup(pyramid, uv, np.stack([a, b], -2))
    tex = export_textures_of(pyramid)
    got = gl.evaluate("leadr", """
        MfMoments e = mf_lookup(e1234_map, e5_map, top, uv.xy, a.xy, b.xy, 16);
        result = vec4(e.e1234.xy, e.e1234.z, e.e5);""",
                      {"uv": uv, "a": a, "b": b}, defines=FILTERS[filtering],
                      declarations="uniform highp sampler2D e1234_map; uniform highp sampler2D e5_map; uniform int top;",
                      textures={"e1234_map": (tex["e1234"], (True, True)), "e5_map": (tex["e5"], (True, True))},
                      uniforms=dict(top=len(pyramid) - 1))
    ref = ref[:, [0, 1, 2, 4]]
    atol = 1e-5 * np.abs(ref).max()
    if filtering == "hardware" and filter_quantum is not None:
        span = [np.ptp(np.concatenate([lv[..., c].ravel() for lv in tex["e1234"]])) for c in range(3)]
        span.append(np.ptp(np.concatenate([lv.ravel() for lv in tex["e5"]])))
        assert np.all(np.abs(got - ref) <= 1e-4 * np.abs(ref) + atol + 2 * filter_quantum * np.array(span))
    else:
        np.testing.assert_allclose(got, ref, rtol=1e-4, atol=atol)


def export_textures_of(pyramid):
    from microfacet.glsl.textures import pyramid_textures
    return pyramid_textures(pyramid)


FIT = """
uniform highp sampler2D dummy; uniform vec2 s_alpha; uniform float s_rho; uniform vec2 s_mean;
uniform vec3 diffuse; uniform bool shadowing;
"""


def fitted(params, diffuse=(0.0, 0.0, 0.0), shadowing=True):
    """An isotropic fitted BRDF whose table is a Beckmann-like lobe with a bump, with a
    tabulated Fresnel term, roughness map and mean slope."""
    from microfacet.distributions.tabulated import TabulatedIsotropic, theta_grid
    th = theta_grid(48)
    ndf = np.exp(-np.tan(th) ** 2 / 0.3**2) + 0.05 * np.exp(-((th - 0.8) / 0.1) ** 2)
    c = np.linspace(0.0, 1.0, 37) ** 0.7
    f = fr.Tabulated(c, fr.Conductor.metal("Cu")(c))
    return mf.fit.FittedBRDF(TabulatedIsotropic(ndf, **params), f, shadowing=shadowing, diffuse=diffuse)


@pytest.mark.parametrize("params,diffuse,shadowing", [
    (dict(), (0, 0, 0), True),
    (dict(alpha_x=0.7, alpha_y=1.3, rho=0.3, mean_slope=(0.05, -0.08)), (0.1, 0.2, 0.3), True),
    (dict(alpha=0.5), (0.05, 0.05, 0.05), False)], ids=["plain", "sheared+diffuse", "masking"])
def test_fitted_brdf(gl, params, diffuse, shadowing, tmp_path):
    brdf = fitted(params, diffuse, shadowing)
    assert shader_fit_error(gl, brdf, tmp_path) <= TOL


def shader_fit_error(gl, brdf, tmp_path, n=4000):
    """:func:`rel_error` of ``mf_fit_eval_cos`` (textures exported through the .npz file, as an
    engine would) against ``brdf.eval_cos`` at ``n`` pairs, half of them beyond 70 degrees."""
    tex = export_textures(brdf.save(tmp_path / "fit.npz"))
    rng = np.random.default_rng(7)
    wi, wo = directions(rng, n), directions(rng, n)
    got = gl.evaluate("tabulated", """
        MfSurface s = MfSurface(MF_TABULATED_DISTRIBUTION, s_alpha, s_rho, s_mean);
        result = vec4(mf_fit_eval_cos(s, shadowing, diffuse, wi.xyz, wo.xyz), 0.0);""",
                      {"wi": wi, "wo": wo}, declarations=FIT,
                      textures={"mf_fit_table": ([tex["fit_table"]], (False, False), True)},
                      uniforms=dict(mf_fit_sizes=tuple(int(v) for v in tex["fit_sizes"]),
                                    mf_fit_azimuths=tuple(int(v) for v in tex["fit_azimuths"]), s_alpha=tex["alpha"],
                                    s_rho=float(tex["rho"]), s_mean=tex["mean_slope"], diffuse=tex["diffuse"],
                                    shadowing=tex["shadowing"]))
    return rel_error(got[:, :3], brdf.eval_cos(wi, wo))


class _LobeOverBase:
    """A correlated anisotropic GGX copper lobe over a Lambertian base (input of a diffuse fit)."""

    def __init__(self, lobe):
        self.lobe, self.base = lobe, mf.Lambertian([0.2, 0.1, 0.05])

    def eval(self, wi, wo):
        return self.lobe.eval(wi, wo) + self.base.eval(wi, wo)


@pytest.mark.parametrize("diffuse", [False, True], ids=["lobe", "diffuse"])
def test_fitted_brdf_anisotropic(gl, diffuse, tmp_path):
    """Anisotropic fits (refined log-bilinear D, projected-area Lambda, Fresnel table, base)."""
    lobe = mf.MicrofacetBRDF(mf.GGX(alpha_x=0.2, alpha_y=0.4, rho=0.3), fresnel=fr.Conductor.metal("Cu"))
    brdf = mf.fit.fit(_LobeOverBase(lobe) if diffuse else lobe, 32, anisotropic=True, diffuse=diffuse)
    assert brdf.anisotropic and brdf.has_diffuse == diffuse
    assert shader_fit_error(gl, brdf, tmp_path) <= TOL


@pytest.mark.parametrize("version", ["330", "es300"])
def test_every_shader_compiles(gl, version):
    """Each library file runs, and the viewer's program links, in both versions."""
    for name in SHADERS:
        if not name.startswith("viewer"):
            assert np.all(gl.evaluate(name, "result = vec4(1.0);", {"x": np.zeros((4, 1))}, version=version) == 1.0)
    prog = gl.context().program(vertex_shader=source("viewer.vert", version),
                                fragment_shader=source("viewer.frag", version))
    assert "u_method" in prog and "mf_fit_table" in prog
    prog.release()


def test_source_preprocessor():
    es, core = source("leadr", "es300"), source("leadr", "330")
    assert es.startswith("#version 300 es\nprecision highp float;") and core.startswith("#version 330 core\n")
    assert es.split("\n", 5)[5] == core.split("\n", 2)[2]          # one source, two headers
    assert es.count("// ---- common.glsl") == 1 and "#include" not in es   # included once
    assert "#define MF_MANUAL_BILINEAR\n" in source("leadr", defines={"MF_MANUAL_BILINEAR": None})
    with pytest.raises(ValueError, match="version"):
        source("leadr", "450")
    with pytest.raises(ValueError, match="unknown shader"):
        source("../x")


def test_export_textures_errors(tmp_path):
    bad = tmp_path / "x.exr"
    bad.write_bytes(b"hello world")
    with pytest.raises(MicrofacetError, match="neither"):
        export_textures(bad)
    with pytest.raises(MicrofacetError, match="no such file"):
        export_textures(tmp_path / "missing.exr")
    vgroove = mf.fit.FittedBRDF(mf.distributions.tabulated.TabulatedAnisotropic(np.ones((8, 8))), fr.Ideal(),
                                gaf="vgroove")
    with pytest.raises(MicrofacetError, match="Smith"):
        export_textures(vgroove.save(tmp_path / "a.npz"))
