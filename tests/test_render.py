"""microfacet.render: sphere frames, directional and environment shading, QMC, lobes."""
import numpy as np
import pytest

import microfacet as mf
from microfacet.geometry import dot, normalize
from microfacet.io import write_exr
from microfacet.render import (DirectionalLight, Environment, Sphere, procedural_sky, save_lobe_figure,
                               shade_directional, shade_environment, shifted_sobol, sobol_02,
                               tangent_frame)
from microfacet.render.lights import latlong_directions
from microfacet.render.lobes import lobe_curve
from microfacet.render.sphere import VIEW


def render_directional(brdf, sphere, light):
    return sphere.image(shade_directional(brdf, sphere.wo, sphere.to_local(light.w), light.rgb))


class Constant:
    """Environment of constant radiance."""

    def __init__(self, value):
        self.value = np.asarray(value, dtype=np.float64)

    def radiance(self, w):
        return np.broadcast_to(self.value, np.shape(w)[:-1] + (3,))


class Linear:
    """Environment ``L(w) = 1 + a.w``: a Lambertian reflects ``rho (1 + 2/3 a.n)``."""

    a = np.array([0.3, -0.4, 0.2])

    def radiance(self, w):
        return (1.0 + w @ self.a)[..., None] * np.ones(3)


# ---------------------------------------------------------------------- frames
def test_tangent_frame_is_orthonormal_right_handed_and_follows_x():
    rng = np.random.default_rng(0)
    n = normalize(rng.normal(size=(1000, 3)))
    n[0] = (1.0, 0.0, 0.0)          # degenerate: normal along the tangent direction
    n[1] = (-1.0, 0.0, 0.0)
    s, t = tangent_frame(n)
    for a, b in ((s, s), (t, t), (n, n)):
        np.testing.assert_allclose(dot(a, b), 1.0, atol=1e-12)
    for a, b in ((s, t), (s, n), (t, n)):
        np.testing.assert_allclose(dot(a, b), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(s, t), n, atol=1e-12)
    # s lies in the plane of x and n, on the side of x
    x = np.array([1.0, 0.0, 0.0])
    regular = np.abs(n[:, 0]) < 0.999
    np.testing.assert_allclose(dot(np.cross(x, n), s)[regular], 0.0, atol=1e-12)
    assert np.all(dot(s, x)[regular] > 0)


def test_sphere_geometry():
    sp = Sphere(33)
    assert sp.mask.sum() == sp.n.shape[0] == sp.wo.shape[0]
    np.testing.assert_allclose(dot(sp.n, sp.n), 1.0, atol=1e-12)
    np.testing.assert_allclose(sp.wo[:, 2], sp.n[:, 2], atol=1e-12)          # cos theta_o = n.view
    np.testing.assert_allclose(sp.to_world(sp.wo), np.broadcast_to(VIEW, sp.n.shape), atol=1e-12)
    # the centre pixel sees the pole, with local x = world x and y = world y
    mid = np.argmax(sp.n[:, 2])
    np.testing.assert_allclose(sp.n[mid], VIEW, atol=1e-12)
    np.testing.assert_allclose(sp.s[mid], (1, 0, 0), atol=1e-12)
    np.testing.assert_allclose(sp.t[mid], (0, 1, 0), atol=1e-12)
    # coverage: 1 inside, fractional at the silhouette, corners empty
    assert sp.coverage.max() == 1.0 and 0.0 < sp.coverage.min() < 1.0
    assert not sp.mask[0, 0] and sp.mask[16, 16]
    # area of the disk in pixels
    assert abs(sp.coverage.sum() - np.pi * 33**2 / 4) < 0.01 * np.pi * 33**2 / 4
    # image orientation: top rows have n_y > 0, right columns n_x > 0
    ny = sp.image(sp.n[:, 1:2])[..., 0]
    nx = sp.image(sp.n[:, 0:1])[..., 0]
    assert ny[2, 16] > 0.5 and ny[-3, 16] < -0.5 and nx[16, -3] > 0.5 and nx[16, 2] < -0.5


def test_image_blends_background_by_coverage():
    sp = Sphere(16)
    img = sp.image(np.ones((sp.n.shape[0], 3)), background=0.25)
    assert img.shape == (16, 16, 3)
    assert np.all(img[~sp.mask] == 0.25)
    np.testing.assert_allclose(img[sp.mask][:, 0], sp.coverage + (1 - sp.coverage) * 0.25)


# ---------------------------------------------------------------- directional
def test_white_lambertian_under_directional_light_is_cos_over_pi_times_e():
    sp = Sphere(64)
    light = DirectionalLight(direction=(-0.3, 0.6, 0.8), irradiance=2.5)
    img = render_directional(mf.Lambertian(1.0), sp, light)
    full = sp.coverage == 1.0
    expected = 2.5 * np.maximum(0.0, sp.n @ light.w) / np.pi
    got = img[sp.mask][full]
    np.testing.assert_allclose(got, np.repeat(expected[full, None], 3, 1), rtol=1e-13, atol=1e-15)
    assert np.all(img[~sp.mask] == 0.0)
    assert np.any(expected[full] == 0.0)         # the terminator is on the sphere


def test_glossy_highlight_sits_at_the_half_vector():
    sp = Sphere(96)
    light = DirectionalLight(direction=(-0.5, 0.5, 1.0))
    radiance = shade_directional(mf.MicrofacetBRDF(mf.GGX(alpha=0.05)), sp.wo, sp.to_local(light.w), light.rgb)
    h = normalize(light.w + VIEW)
    assert dot(sp.n[np.argmax(radiance[:, 0])], h) > np.cos(np.radians(2.0))


def _highlight_covariance(dist):
    """Image-plane covariance of the core (> 1/4 of the peak) of the highlight of ``dist``
    lit from the view direction (the long tails bend along the sphere)."""
    sp = Sphere(96)
    f = shade_directional(mf.MicrofacetBRDF(dist), sp.wo, sp.wo, 1.0)[:, 0]
    core = f > 0.25 * f.max()
    xy, f = sp.n[core, :2], f[core]
    w = f / f.sum()
    mean = w @ xy
    d = xy - mean
    return (d * w[:, None]).T @ d, mean


@pytest.mark.parametrize("ax, ay", [(0.3, 0.05), (0.05, 0.3)])
def test_anisotropic_highlight_stretches_along_the_rougher_axis(ax, ay):
    cov, mean = _highlight_covariance(mf.GGX(alpha_x=ax, alpha_y=ay))
    np.testing.assert_allclose(mean, 0.0, atol=1e-9)
    wide, narrow = (cov[0, 0], cov[1, 1]) if ax > ay else (cov[1, 1], cov[0, 0])
    assert wide > 4.0 * narrow


@pytest.mark.parametrize("phi, sign", [(np.pi / 4, 1.0), (3 * np.pi / 4, -1.0)])
def test_anisotropy_orientation_turns_the_highlight(phi, sign):
    cov, _ = _highlight_covariance(mf.GGX.from_ellipse(0.3, 0.05, phi))
    evals, evecs = np.linalg.eigh(cov)
    major = evecs[:, 1] * np.sign(evecs[0, 1])
    assert evals[1] > 4.0 * evals[0]
    np.testing.assert_allclose(major, [np.sqrt(0.5), sign * np.sqrt(0.5)], atol=0.05)


# ---------------------------------------------------------------- environment
def test_lambertian_under_constant_environment_is_reflectance_times_l():
    sp = Sphere(24)
    est = shade_environment(mf.Lambertian((0.2, 0.5, 0.9)), sp.wo, sp.frame, Constant((1.0, 2.0, 3.0)),
                            8, np.random.default_rng(1))
    np.testing.assert_allclose(est, np.broadcast_to([0.2, 1.0, 2.7], est.shape), rtol=1e-12)


def test_lambertian_under_linear_environment_matches_closed_form():
    sp = Sphere(32)
    rho, spp = 0.7, 64
    est = shade_environment(mf.Lambertian(rho), sp.wo, sp.frame, Linear(), spp, np.random.default_rng(3))
    exact = rho * (1.0 + 2.0 / 3.0 * sp.n @ Linear.a)
    err = est[:, 0] - exact
    sigma = rho * np.linalg.norm(Linear.a)          # bounds the std of one sample
    n = err.size
    assert abs(err.mean()) < 4.0 * sigma / np.sqrt(n * spp)
    assert np.sqrt(np.mean(err**2)) < sigma / np.sqrt(spp)


@pytest.mark.parametrize("brdf", [
    mf.MicrofacetBRDF(mf.GGX(alpha=0.3), fresnel=mf.fresnel.Schlick(0.5)),
    mf.MicrofacetBRDF(mf.Beckmann(alpha_x=0.2, alpha_y=0.6), gaf="vgroove"),
], ids=["ggx", "beckmann-vgroove"])
def test_environment_estimate_matches_quadrature_of_eval_cos(brdf):
    """Constant environment: L_o = L int f_r cos dwi, checked against a midpoint rule in
    (cos theta, phi) that never calls ``sample``."""
    theta_o = np.radians([0.0, 40.0, 70.0])
    wo = np.stack([np.sin(theta_o), np.zeros(3), np.cos(theta_o)], -1)
    frame = (np.tile([1.0, 0, 0], (3, 1)), np.tile([0, 1.0, 0], (3, 1)), np.tile([0, 0, 1.0], (3, 1)))
    est = shade_environment(brdf, wo, frame, Constant(1.0), 4096, np.random.default_rng(5))
    m = 600
    mu = (np.arange(m) + 0.5) / m                      # cos theta_i, uniform: dw = dmu dphi
    phi = (np.arange(2 * m) + 0.5) / (2 * m) * 2 * np.pi
    mu_, phi_ = np.meshgrid(mu, phi, indexing="ij")
    sin_ = np.sqrt(1 - mu_**2)
    wi = np.stack([sin_ * np.cos(phi_), sin_ * np.sin(phi_), mu_], -1).reshape(-1, 3)
    for k in range(3):
        quad = brdf.eval_cos(wi, wo[k]).sum(0) * (1.0 / m) * (2 * np.pi / (2 * m))
        np.testing.assert_allclose(est[k], quad, rtol=0.01)


def test_environment_estimate_is_deterministic_and_finite():
    sp = Sphere(24)
    env = Environment(procedural_sky(16, 32))
    b = mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3), fresnel=mf.fresnel.Conductor.metal("Au"))
    a = shade_environment(b, sp.wo, sp.frame, env, 8, np.random.default_rng(2))
    c = shade_environment(b, sp.wo, sp.frame, env, 8, np.random.default_rng(2))
    np.testing.assert_array_equal(a, c)
    assert np.all(np.isfinite(a)) and np.all(a >= 0)


def test_shade_environment_rejects_bad_spp():
    sp = Sphere(8)
    with pytest.raises(ValueError, match="spp"):
        shade_environment(mf.Lambertian(), sp.wo, sp.frame, Constant(1.0), 0, np.random.default_rng())


# ----------------------------------------------------------------- QMC points
@pytest.mark.parametrize("m", [0, 3, 6])
def test_sobol_points_form_a_0m2_net_also_after_digital_shift(m):
    n = 2**m
    pts = [sobol_02(n) * 2.0**-32, shifted_sobol(np.random.default_rng(4), 3, n)[2]]
    for p in pts:
        assert np.all((p >= 0) & (p < 1))
        for a in range(m + 1):     # every dyadic box of area 2^-m holds exactly one point
            cell = np.floor(p[:, 0] * 2**a) * 2 ** (m - a) + np.floor(p[:, 1] * 2 ** (m - a))
            assert np.unique(cell).size == n


def test_shifted_sobol_is_uniform_per_pixel():
    u = shifted_sobol(np.random.default_rng(0), 20000, 1)[:, 0]
    np.testing.assert_allclose(u.mean(0), 0.5, atol=0.01)
    np.testing.assert_allclose(u.var(0), 1 / 12, atol=0.003)


# ---------------------------------------------------------------- environment map
def test_environment_layout_and_bilinear_lookup():
    h, w = 8, 16
    env = Environment(np.arange(h * w * 3, dtype=float).reshape(h, w, 3))
    dirs = latlong_directions(h, w)
    np.testing.assert_allclose(env.radiance(dirs), env.map, atol=1e-9)          # texel centres
    m = env.map
    # toward the viewer (+z): theta = pi/2, phi = 0, the corner of the 4 central texels
    np.testing.assert_allclose(env.radiance(np.array([0.0, 0.0, 1.0])), m[3:5, 7:9].mean((0, 1)))
    # zenith: row 0 (clamped), phi = atan2(0, 0) = 0 between the two central columns
    np.testing.assert_allclose(env.radiance(np.array([0.0, 1.0, 0.0])), m[0, 7:9].mean(0))
    # +x (image right) is a quarter turn from the centre: phi = pi/2 -> column 3/4 of the width
    np.testing.assert_allclose(env.radiance(np.array([1.0, 0.0, 0.0])), m[3:5, 11:13].mean((0, 1)))
    # phi wraps around behind the sphere (-z): between the last and first columns
    np.testing.assert_allclose(env.radiance(np.array([1e-12, 0.0, -1.0])), 0.5 * (m[3:5, 0] + m[3:5, -1]).mean(0))
    const = Environment(np.full((4, 8, 3), 0.5))
    w_rand = normalize(np.random.default_rng(1).normal(size=(100, 3)))
    np.testing.assert_allclose(const.radiance(w_rand), 0.5)


def test_environment_from_exr(tmp_path):
    sky = procedural_sky(8, 16)
    env = Environment.from_exr(write_exr(tmp_path / "sky.exr", sky))
    np.testing.assert_allclose(env.map, sky, rtol=1e-6)
    with pytest.raises(mf.MicrofacetError, match="missing.exr"):
        Environment.from_exr(tmp_path / "missing.exr")
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        Environment(np.zeros((4, 4)))


def test_procedural_sky_is_small_finite_and_has_bright_lights():
    sky = procedural_sky()
    assert sky.shape == (64, 128, 3) and np.all(np.isfinite(sky)) and sky.min() > 0
    assert sky.max() > 2.0 and np.median(sky) < 1.0


# ----------------------------------------------------------------------- lobes
def test_lobe_peaks_near_mirror_direction_and_figure_is_written(tmp_path):
    brdf = mf.MicrofacetBRDF(mf.GGX(alpha=0.1))
    theta_i, f = lobe_curve(brdf, np.radians(30.0))
    assert abs(np.degrees(theta_i[np.argmax(f)]) - 30.0) < 3.0
    assert np.all(f[theta_i < np.radians(-20.0)] < 0.01 * f.max())     # no backscattering lobe
    assert abs(f[0]) < 1e-12 and abs(f[-1]) < 1e-12                      # grazing wi
    path = save_lobe_figure(tmp_path / "lobes.png", [brdf, mf.Lambertian(0.5)], ["a", "b"],
                            planes_deg=(0, 90))
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["lobes.png"]


def test_fit_comparison_picture_is_written(tmp_path):
    from PIL import Image

    from microfacet.render import render_sphere, save_fit_comparison
    from microfacet.render.compare import backscattering_curve
    f = mf.fresnel.Conductor.metal("Cu")
    data = mf.MicrofacetBRDF(mf.GGX(alpha=0.2), fresnel=f)
    theta, back = backscattering_curve(data, n=50)
    assert back[0] == pytest.approx(float(data.eval([0, 0, 1.0], [0, 0, 1.0]) @ [0.2126, 0.7152, 0.0722]))
    assert np.all(np.diff(back[theta < 0.8]) < 0)                       # falls off the normal
    image = render_sphere(data, 24)
    assert image.shape == (24, 24, 3) and np.all(np.isfinite(image)) and image.max() > 0
    path = save_fit_comparison(tmp_path / "cmp.png", {"data": data, "Beckmann": mf.MicrofacetBRDF(
        mf.Beckmann(alpha=0.2), fresnel=f)}, title="t", size=24, planes_deg=(0, 90))
    with Image.open(path) as im:
        assert im.format == "PNG" and im.size[0] >= 900 and im.size[1] > 2 * 24 + 330
    assert [p.name for p in tmp_path.iterdir()] == ["cmp.png"]


@pytest.mark.parametrize("notes", [None, {"GGX": "err 0.1\nunif 0.2"}])
def test_fit_comparison_titles_sit_where_automatic_placement_puts_them(monkeypatch, notes):
    """The explicit title height of the comparison picture (it saves measuring the tick
    labels twice) gives the pixels of Matplotlib's automatic title placement."""
    import io

    from PIL import Image

    from microfacet.render import compare
    brdfs = {"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), "GGX": mf.MicrofacetBRDF(mf.GGX(alpha=0.3)),
             "Beckmann": mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3))}

    def pixels():
        return np.asarray(Image.open(io.BytesIO(compare.fit_comparison_png(brdfs, "title", size=24, notes=notes))))
    explicit = pixels()
    monkeypatch.setattr(compare, "_TITLE_Y", None)                      # Matplotlib's automatic placement
    np.testing.assert_array_equal(explicit, pixels())


@pytest.mark.parametrize("kwargs, word", [({"direction": (0, 0, 0)}, "direction"), ({"direction": (0, np.nan, 1)}, "direction"),
                                          ({"direction": (0, 1)}, "direction"), ({"irradiance": np.nan}, "irradiance"),
                                          ({"irradiance": -1.0}, "irradiance"), ({"irradiance": (1, 2)}, "irradiance")])
def test_directional_light_rejects_bad_parameters(kwargs, word):
    with pytest.raises(ValueError, match=word):
        DirectionalLight(**kwargs)


def test_fit_spheres_picture_has_the_comparison_pictures_spheres_without_matplotlib(tmp_path):
    """The spheres picture (microfacet fit's): the same sphere pixels as the comparison
    picture's, every label and note inside its column, bad notes refused, and no Matplotlib
    imported to draw it."""
    import io
    import subprocess
    import sys

    from PIL import Image, ImageDraw

    from microfacet.render import compare
    brdfs = {"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), **{f"a long fit name {k}": mf.MicrofacetBRDF(
        mf.GGX(alpha=0.1 + 0.1 * k)) for k in range(4)}}
    notes = {name: "log 0.123 · image 0.456\nalbedo ratio 0.91–1.08 θ" for name in list(brdfs)[1:]}
    size = 64

    def spheres(png, min_width):
        part = compare._spheres(brdfs, "title", size, notes, min_width, 100)
        top, (h, w) = part.title_h + part.label_h, part.canvas.shape[:2]
        with Image.open(io.BytesIO(png)) as im:
            return np.asarray(im.convert("RGB"))[top:top + h, part.xs[0]:part.xs[0] + w], part
    ours, part = spheres(compare.fit_spheres_png(brdfs, "title", size=size, notes=notes), 600)
    theirs, _ = spheres(compare.fit_comparison_png(brdfs, "title", size=size, notes=notes), 900)
    np.testing.assert_array_equal(ours, theirs)
    assert np.count_nonzero(ours.min(axis=-1) < 255) > 5 * size * size     # the spheres, not a blank
    draw = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    for k, label in enumerate(part.labels):
        cell = (part.left + k * part.cell, part.left + (k + 1) * part.cell)
        boxes = [draw.textbbox((part.label_x(k), 0), label, font=compare._font(13), anchor="ms")]
        if label in notes:
            boxes.append(draw.multiline_textbbox((part.note_x(k), 0), notes[label], font=compare._font(10),
                                                 anchor="ma", align="center", spacing=3))
        assert all(cell[0] <= b[0] and b[2] <= cell[1] for b in boxes), label
    with pytest.raises(ValueError, match="not in brdfs"):
        compare.fit_spheres_png(brdfs, notes={"nobody": "x"})
    code = ("import sys, microfacet as mf; from microfacet.render import fit_spheres_png; "
            "png = fit_spheres_png({'data': mf.Lambertian(0.5)}, size=16); "
            "print(png[:4] == b'\\x89PNG', 'matplotlib' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "False"]


def test_fit_comparison_shows_five_brdfs_on_large_spheres_with_every_label_inside():
    """3-5 BRDFs: spheres of the requested size pixel for pixel, every text inside the figure
    and no two texts (titles, tick labels, legends, notes) overlapping."""
    import io

    from PIL import Image

    from microfacet.render import compare
    brdfs = {"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), **{f"a long fit name {k}": mf.MicrofacetBRDF(
        mf.GGX(alpha=0.1 + 0.1 * k)) for k in range(4)}}
    notes = {name: "log 0.123 · image 0.456\nalbedo ratio 0.91–1.08" for name in list(brdfs)[1:]}
    png = compare.fit_comparison_png(brdfs, "title", size=192, notes=notes)
    with Image.open(io.BytesIO(png)) as im:
        width, height = im.size
    assert width >= 5 * 192 and height >= 2 * 192 + 330
    fig = compare._comparison_figure(brdfs, "title", (0, 30, 60), (0,), 192, 100, notes)
    renderer = fig.canvas.get_renderer()
    fig.draw(renderer)
    def in_view(axis, lim):
        lo, hi = sorted(lim)
        return [t.label1 for t in axis.get_major_ticks() if lo * (1 - 1e-9) <= t.get_loc() <= hi * (1 + 1e-9)]
    texts = list(fig.texts) + [t for leg in fig.legends for t in leg.get_texts()]
    for ax in fig.axes:
        texts += [ax.title, ax.xaxis.label, ax.yaxis.label]
        texts += in_view(ax.xaxis, ax.get_xlim()) + in_view(ax.yaxis, ax.get_ylim()) + list(ax.texts)
        if ax.get_legend() is not None:
            texts += list(ax.get_legend().get_texts()) + [ax.get_legend().get_title()]
    boxes = [t.get_window_extent(renderer) for t in texts if t.get_visible() and t.get_text().strip()]
    assert len(boxes) > 20
    for b in boxes:
        assert b.x0 >= 0 and b.y0 >= 0 and b.x1 <= width and b.y1 <= height
    for i, a in enumerate(boxes):
        for b in boxes[i + 1:]:
            assert not a.overlaps(b) or a.width == 0 or b.width == 0, (a, b)


def _comparison_brdfs():
    return {"data": mf.MicrofacetBRDF(mf.GGX(alpha=0.2)), "GGX": mf.MicrofacetBRDF(mf.GGX(alpha=0.3)),
            "Beckmann": mf.MicrofacetBRDF(mf.Beckmann(alpha=0.3), fresnel=mf.fresnel.Conductor.metal("Cu"))}


def test_fit_comparison_shows_the_spheres_pixel_for_pixel():
    """The PNG holds every sphere of render_sphere, in sRGB at its row's exposure (the first
    BRDF's), pixel for pixel where it is written, except under the silhouette circle."""
    import io

    from PIL import Image

    from microfacet.io import to_srgb8
    from microfacet.render import compare
    brdfs, size = _comparison_brdfs(), 40
    png = compare.fit_comparison_png(brdfs, "title", size=size)
    with Image.open(io.BytesIO(png)) as im:
        assert im.format == "PNG" and im.mode == "RGB"
        picture = np.asarray(im)
    with compare._drawing():
        fig = compare._comparison_figure(brdfs, "title", (0, 30, 60), (0,), size, 100, None)
    pixels, = [a for a in fig.artists if hasattr(a, "rgba")]
    canvas = pixels.rgba[::-1, :, :3]                              # stored bottom row first
    top = picture.shape[0] - pixels.y - canvas.shape[0]
    np.testing.assert_array_equal(picture[top:top + canvas.shape[0], pixels.x:pixels.x + canvas.shape[1]], canvas)
    ring, _ = compare._silhouette(size, compare._SILHOUETTE_PT * 100 / 72.0)
    off_ring = np.ones((size, size), bool)
    off_ring[ring] = False
    assert 0.05 * size * size < (~off_ring).sum() < 0.3 * size * size
    columns = sorted({int(c) for c in np.nonzero(np.all(canvas[size // 2] != 255, axis=-1))[0][::size]})
    assert len(columns) == len(brdfs)
    row_step = canvas.shape[0] - size
    for r, light in enumerate((compare.COMPARE_LIGHT, compare.GRAZING_LIGHT)):
        images = [compare.render_sphere(b, size, light) for b in brdfs.values()]
        exposure = compare._exposure(images[0])
        for x, image in zip(columns, images):
            shown = canvas[r * row_step:r * row_step + size, x:x + size]
            np.testing.assert_array_equal(shown[off_ring], to_srgb8(image, exposure)[off_ring])
            assert shown[ring].min() > 0                           # the grey circle over the black


def test_fit_comparison_ticks_sit_where_matplotlib_puts_them():
    """The comparison's hand-made ticks (marker lines, texts, the x label placed from their
    extents) give the pixels of Matplotlib's own Axis ticks at the same places and labels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import NullFormatter

    from microfacet.render import compare
    with compare._drawing():
        fig = compare._comparison_figure(_comparison_brdfs(), "title", (0, 30, 60), (0,), 24, 100, None)
        fig.canvas.draw()
        ours = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
        ref = Figure(figsize=fig.get_size_inches(), dpi=fig.dpi)
        FigureCanvasAgg(ref)
        for ax in fig.axes:
            rax = ref.add_axes(ax.get_position().bounds)
            rax.set_yscale(ax.get_yscale())
            rax.set_xlim(ax.get_xlim())
            rax.set_ylim(ax.get_ylim())
            xs = [t for t in ax.texts if t.get_va() == "top"]
            ys = [t for t in ax.texts if t.get_ha() == "right"]
            assert len(xs) >= 9 and len(ys) >= 3
            rax.set_xticks([t.get_position()[0] for t in xs], [t.get_text() for t in xs])
            rax.set_yticks([t.get_position()[1] for t in ys], [t.get_text() for t in ys])
            minor = [line for line in ax.get_children() if getattr(line, "get_markersize", lambda: 0)() == 2.0]
            rax.set_yticks(np.concatenate([line.get_ydata() for line in minor]) if minor else [], minor=True)
            rax.yaxis.set_minor_formatter(NullFormatter())
            rax.tick_params(labelsize=7)
            rax.set_xlabel(ax.get_xlabel(), fontsize=8)
        ref.canvas.draw()
        theirs = np.asarray(ref.canvas.buffer_rgba())[..., :3]
    height = ours.shape[0]
    for ax in fig.axes:
        b = ax.get_window_extent()
        below = slice(int(height - b.y0) + 2, int(height - b.y0) + 45), slice(int(b.x0) - 30, int(b.x1) + 10)
        beside = slice(int(height - b.y1) - 5, int(height - b.y0) + 2), slice(int(b.x0) - 45, int(b.x0) - 1)
        for region in (below, beside):
            assert (theirs[region] < 128).sum() > 100              # ticks and labels there
            np.testing.assert_array_equal(ours[region], theirs[region])


def test_fit_comparison_of_a_black_brdf_still_has_log_axes():
    """Nothing positive to plot (a black BRDF): positive log axes with labelled decades
    (10^-3..1 where Matplotlib's own limits are not positive), not an error."""
    from microfacet.render import compare
    with compare._drawing():
        fig = compare._comparison_figure({"black": mf.Lambertian(0.0)}, "", (0, 30), (0,), 8, 100, None)
    limits = [ax.get_ylim() for ax in fig.axes]
    assert all(0 < lo < hi < np.inf for lo, hi in limits) and (1e-3, 1.0) in limits
    for ax in fig.axes:
        assert [t.get_text() for t in ax.texts if t.get_ha() == "right"][-1] in ("10⁰", "10¹")
    assert compare.fit_comparison_png({"black": mf.Lambertian(0.0)}, size=8)[:8] == b"\x89PNG\r\n\x1a\n"
