"""The one normal-map decoder (microfacet.io.normalmap) and its use by ``bake`` and ``glints``:
encodings by content or given, z stored or rebuilt, per-texel repair, warnings."""
import warnings

import numpy as np
import pytest
from conftest import DATA

from microfacet import leadr
from microfacet.cli import main
from microfacet.errors import MicrofacetError, NormalMapWarning
from microfacet.glints import Microsurface, load_slopes
from microfacet.io import write_exr, write_png_data
from microfacet.io.normalmap import MAX_THETA_DEG, decode_normals, normals_to_slopes, read_normals, read_slopes

MAPS = DATA / "maps"
SHIPPED = ["glitterman_scratches.png", "glitterman_isotropic_large.png",
           "sms_normalmap_gaussian.exr", "sms_normalmap_waves.exr"]
COS_MAX = np.cos(np.radians(MAX_THETA_DEG))


def real_map(name):
    path = MAPS / name
    if not path.exists():
        pytest.skip(f"test data {path} absent (../shared/data or $MICROFACET_DATA; not part of a user's clone)")
    return path


def random_slopes(shape=(12, 10), seed=4):
    return np.random.default_rng(seed).uniform(-1.5, 1.5, shape + (2,))


def quiet(*args, **kwargs):
    """:func:`decode_normals` that fails the test on any warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return decode_normals(*args, **kwargs)


# ------------------------------------------------------------------------- encodings
def test_auto_detection_by_content():
    s = random_slopes()
    n = leadr.slopes_to_normals(s)
    cases = {"uint8": (leadr.encode_normal_map(s, np.uint8), "biased"),
             "uint16": (leadr.encode_normal_map(s, np.uint16), "biased"),
             "float biased": (0.5 * n + 0.5, "biased"),
             "float signed": (n, "signed"),
             "flat signed (no negatives)": (np.tile([0.0, 0.0, 1.0], (4, 4, 1)), "signed"),
             "flat biased": (np.tile([0.5, 0.5, 1.0], (4, 4, 1)), "biased"),
             "tilted signed (no negatives)": (np.tile(leadr.slopes_to_normals([-0.5, -0.5]), (4, 4, 1)), "signed"),
             "tilted biased": (np.tile(0.5 * leadr.slopes_to_normals([2.0, 1.0]) + 0.5, (4, 4, 1)), "biased")}
    for name, (image, encoding) in cases.items():
        normals, report = quiet(image)
        assert report.encoding == encoding and report.detected, name
        assert report.z == "stored" and report.repaired == 0, name
        np.testing.assert_allclose(np.linalg.norm(normals, axis=-1), 1.0, atol=1e-12)
    for name, (image, encoding) in {"2-channel signed": (n[..., :2], "signed"),           # z rebuilt:
                                    "2-channel biased": (0.5 * n[..., :2] + 0.5, "biased"),  # mean rule
                                    "2-channel flat signed": (np.zeros((3, 3, 2)), "signed")}.items():
        normals, report = quiet(image)
        assert report.encoding == encoding and report.z == "reconstruct", name


def test_explicit_encoding_overrides_and_offset_alias():
    n = leadr.slopes_to_normals(random_slopes())
    biased = 0.5 * n + 0.5
    for encoding in ("biased", "offset"):
        normals, report = quiet(biased, encoding)
        assert report.encoding == "biased" and not report.detected
        np.testing.assert_allclose(normals, n, atol=1e-12)
    with pytest.warns(NormalMapWarning, match="far from unit length"):
        _, report = decode_normals(biased, "signed")        # forced: read as n itself
    assert report.encoding == "signed"
    with pytest.raises(MicrofacetError, match="'signed' needs float data"):
        decode_normals(leadr.encode_normal_map(random_slopes(), np.uint8), "signed")
    with pytest.raises(ValueError, match="encoding"):
        decode_normals(biased, "srgb")
    with pytest.raises(ValueError, match="z must be"):
        decode_normals(biased, z="blue")


@pytest.mark.parametrize("dtype, tol", [(np.uint8, 0.35), (np.uint16, 2e-3), (np.float32, 1e-4)])
def test_round_trips_of_every_layout(dtype, tol):
    """Encode slopes up to 1.5 per axis, decode: 3 channels (z stored), 2 channels and a
    placeholder blue channel (z rebuilt), RGBA (alpha ignored). The 8-bit tolerance is
    the quantization step 2/255 of n times |d(x/z)/dn| <= 1/z^3 ~ 20 at slope 2.1."""
    s = random_slopes()
    nmap = leadr.encode_normal_map(s, dtype)
    layouts = {"rgb": (nmap, "stored"), "rg": (nmap[..., :2], "reconstruct"),
               "rgba": (np.concatenate([nmap, nmap[..., :1]], axis=-1), "stored")}
    blue = nmap.copy()
    blue[..., 2] = blue[..., 2].max()
    layouts["placeholder blue"] = (blue, "reconstruct")
    for name, (image, z) in layouts.items():
        normals, report = quiet(image)
        assert report.z == z, name
        assert np.abs(normals_to_slopes(normals) - s).max() < tol, name


def test_non_unit_vectors_keep_their_direction():
    s = random_slopes()
    n = leadr.slopes_to_normals(s) * np.linspace(0.5, 1.45, s.shape[1])[None, :, None]
    normals, report = quiet(n)
    assert report.z == "stored" and report.repaired == 0
    assert report.mean_length == pytest.approx(np.linalg.norm(n, axis=-1).mean())
    np.testing.assert_allclose(normals_to_slopes(normals), s, atol=1e-12)


def test_uniform_signed_map_with_long_tangent_is_not_rebuilt():
    """Regression: this map gave slopes (-8000, -7000) (n_z rebuilt from x^2 + y^2 > 1, floored
    at 1e-4); its normal (0.8, 0.7, 0.2) has slopes (-4, -3.5)."""
    got = load_slopes(np.tile([[[0.8, 0.7, 0.2]]], (2, 2, 1)), encoding="signed")
    np.testing.assert_allclose(got, np.tile([-4.0, -3.5], (2, 2, 1)), rtol=1e-12)


# ------------------------------------------------------------------------- per-texel repair
def test_two_texels_facing_away_leave_the_others_unchanged(tmp_path):
    """Regression: 2 texels with n_z <= 0 switched the whole map to n_z rebuilt from x and y,
    which changes every non-unit texel (and gives slopes of 1e4 where x^2 + y^2 > 1)."""
    s = random_slopes((16, 16))
    n = leadr.slopes_to_normals(s) * np.linspace(0.6, 1.4, 16)[:, None, None]    # non-unit, as in 8-bit maps
    n[3, 4] = (0.6, -0.3, -0.2)
    n[9, 1] = (0.0, 0.0, -1.0)                 # straight down: no azimuth
    write_exr(tmp_path / "two_bad.exr", n)
    with pytest.warns(NormalMapWarning, match=r"two_bad\.exr: 2 of 256 texels \(0\.781 %\) repaired"):
        normals, report = read_normals(tmp_path / "two_bad.exr", "signed")
    assert report.repaired == 2 and report.facing_away == 2
    keep = np.ones((16, 16), bool)
    keep[3, 4] = keep[9, 1] = False
    np.testing.assert_allclose(normals_to_slopes(normals)[keep], s[keep], rtol=1e-5, atol=1e-6)  # float32 file
    assert normals[3, 4, 2] == pytest.approx(COS_MAX)            # clamped to 89 deg ...
    np.testing.assert_allclose(normals[3, 4, :2] / np.hypot(*normals[3, 4, :2]), np.array([0.6, -0.3]) / np.hypot(0.6, 0.3))
    np.testing.assert_array_equal(normals[9, 1], [0.0, 0.0, 1.0])  # ... or flat without azimuth
    slopes = normals_to_slopes(normals)
    assert np.hypot(*slopes[3, 4]) == pytest.approx(np.tan(np.radians(MAX_THETA_DEG)))


def test_rebuilt_z_repairs_only_texels_outside_the_unit_disk():
    s = random_slopes((8, 8), seed=5)
    two = 0.5 * leadr.slopes_to_normals(s)[..., :2] + 0.5
    two[2, 2] = (1.0, 1.0)                      # x^2 + y^2 = 2
    two[5, 7] = (0.5, 0.0)                      # x = 0, y = -1: the horizon
    with pytest.warns(NormalMapWarning, match="2 of 64 texels"):
        normals, report = decode_normals(two)
    assert report.z == "reconstruct" and report.repaired == 2 and report.facing_away == 1
    keep = np.ones((8, 8), bool)
    keep[2, 2] = keep[5, 7] = False
    np.testing.assert_allclose(normals_to_slopes(normals)[keep], s[keep], atol=1e-12)
    np.testing.assert_allclose(normals[2, 2], [np.sqrt(0.5) * np.sin(np.radians(89))] * 2 + [COS_MAX])


def test_8_bit_png_with_zero_blue_texels(tmp_path):
    nmap = leadr.encode_normal_map(random_slopes((10, 10)) * 0.5, np.uint8)
    nmap[0, 0, 2] = nmap[4, 6, 2] = 0            # n_z = -1
    write_png_data(tmp_path / "n.png", nmap)
    with pytest.warns(NormalMapWarning, match="n.png: 2 of 100 texels"):
        slopes, report = read_slopes(tmp_path / "n.png")
    assert report.encoding == "biased" and report.z == "stored" and report.repaired == 2
    assert np.abs(slopes).max() <= np.tan(np.radians(MAX_THETA_DEG)) * (1 + 1e-12)


def test_most_normals_facing_away_warns():
    n = leadr.slopes_to_normals(random_slopes())
    n[..., 2] *= -1                               # a map whose blue channel is inverted
    with pytest.warns(NormalMapWarning) as record:
        _, report = decode_normals(n, "signed", source="flipped.exr")
    messages = [str(w.message) for w in record]
    assert any(m.startswith("flipped.exr: most normals (100 %) face away") for m in messages)
    assert all("\n" not in m for m in messages)
    assert report.repaired == report.texels


def test_bad_input_raises_naming_the_file(tmp_path):
    with pytest.raises(MicrofacetError, match="m.exr: a normal map must be finite"):
        decode_normals(np.full((2, 2, 3), np.nan), source="m.exr")
    with pytest.raises(MicrofacetError, match="2 to 4 channels"):
        decode_normals(np.zeros((4, 4)))
    with pytest.raises(MicrofacetError, match="uint8, uint16 or float"):
        decode_normals(np.zeros((4, 4, 3), np.int32))
    with pytest.raises(MicrofacetError, match="third channel"):
        decode_normals(np.zeros((4, 4, 2)), z="stored")
    (tmp_path / "junk.png").write_bytes(b"junk")
    with pytest.raises(MicrofacetError, match="junk.png: not a PNG or OpenEXR"):
        read_normals(tmp_path / "junk.png")


# ------------------------------------------------------------------------- shipped maps, CLI
def independent_slopes(name):
    """Slopes of a shipped map, decoded here from its documented encoding (data/README)."""
    from microfacet.io.image import read_image
    a = read_image(real_map(name)).astype(np.float64)
    a = a / 255.0 if name.endswith(".png") else a
    n = 2.0 * a - 1.0
    if name == "glitterman_isotropic_large.png":          # x and y only
        n[..., 2] = np.sqrt(1.0 - n[..., 0] ** 2 - n[..., 1] ** 2)
    return -n[..., :2] / n[..., 2:3]


@pytest.mark.parametrize("name", SHIPPED)
def test_bake_reads_the_shipped_maps_as_glints_does(name, tmp_path, capsys):
    """Regression: bake read the sms EXRs as n (waves: mean slope (-0.73, -0.73) and a black
    preview; gaussian: alpha 220) and floored rebuilt n_z of glitterman_scratches.png at 1e-4
    (alpha 1644). Now its level 0 holds the slopes glints reads, and the top level is the
    mean of the independently decoded slopes' moments."""
    path = real_map(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                 # the shipped maps decode without warnings
        assert main(["bake", str(path), "--normal-map", "-o", str(tmp_path / "b.exr")]) == 0
        glint_slopes = load_slopes(path)
    pyramid = leadr.read_pyramid(tmp_path / "b.exr")
    np.testing.assert_array_equal(pyramid[0][..., :2], glint_slopes.astype(np.float32))
    s = independent_slopes(name)
    np.testing.assert_allclose(glint_slopes, s, rtol=1e-9, atol=1e-12)
    top = leadr.from_moments(pyramid[-1][0, 0])
    alpha = np.sqrt(2.0 * s.reshape(-1, 2).var(axis=0))
    np.testing.assert_allclose([top.alpha_x, top.alpha_y], alpha, rtol=1e-3)
    assert np.all(alpha < 1.0) and np.all(np.abs([top.xn, top.yn]) < 0.01)
    from PIL import Image
    with Image.open(tmp_path / "b.png") as im:
        assert np.asarray(im).mean() > 10            # the waves preview was black (mean 3.6)
    assert "top level: alpha_x" in capsys.readouterr().out


@pytest.mark.parametrize("encoding", ["auto", "biased", "offset", "signed"])
def test_bake_and_glints_commands_give_the_same_slopes(encoding, tmp_path):
    """Generated maps (8-bit PNG with 2 texels facing away, biased and signed float EXR)
    through both commands with the same --encoding give the same level-0 slopes."""
    s = random_slopes((16, 16), seed=7)
    n = leadr.slopes_to_normals(s)
    png = leadr.encode_normal_map(s, np.uint8)
    png[1, 1, 2] = png[7, 3, 2] = 0
    maps = {"signed": [("signed.exr", n)],
            "biased": [("biased.exr", 0.5 * n + 0.5), ("biased8.png", png)]}
    maps["auto"] = maps["signed"] + maps["biased"]
    maps["offset"] = maps["biased"]
    for name, image in maps[encoding]:
        path = tmp_path / name
        write_png_data(path, image) if name.endswith(".png") else write_exr(path, image)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", NormalMapWarning)
            assert main(["bake", str(path), "--normal-map", "--encoding", encoding, "-o", str(tmp_path / "out")]) == 0
            assert main(["glints", str(path), "--encoding", encoding, "-o", str(tmp_path / "out")]) == 0
        baked = leadr.read_pyramid(tmp_path / "out.exr")[0][..., :2]
        np.testing.assert_array_equal(baked, Microsurface.load(tmp_path / "out.npz").slopes)
        keep = np.ones((16, 16), bool)
        if name.endswith(".png"):                # 8 bits; the 2 repaired texels differ
            keep[1, 1] = keep[7, 3] = False
        assert np.abs(baked[keep] - s[keep]).max() < (0.2 if name.endswith(".png") else 1e-5), name


def test_cli_prints_the_repair_warning_on_one_line(tmp_path, capsys):
    nmap = leadr.encode_normal_map(random_slopes((8, 8)) * 0.3, np.uint16)
    nmap[2, 2, 2] = 0
    write_png_data(tmp_path / "m.png", nmap)
    assert main(["bake", str(tmp_path / "m.png"), "--normal-map", "-o", str(tmp_path / "o.exr")]) == 0
    err = capsys.readouterr().err
    assert err == (f"microfacet: warning: {tmp_path / 'm.png'}: 1 of 64 texels (1.56 %) repaired: facing away "
                   f"or beyond 89 deg from the normal, clamped to 89 deg\n")
