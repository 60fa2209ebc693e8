"""microfacet.io: EXR/PNG round trips, tone map, atomic writes, reader errors."""
import os
import stat

import numpy as np
import OpenEXR
import pytest
from PIL import Image

import microfacet as mf
from microfacet.io.exr import COMPRESSIONS, exr_threads
from microfacet.io import (atomic_path, html_figure, html_grid, html_page, read_exr, read_png_data,
                           srgb_encode, to_srgb8, write_exr, write_png, write_png_data, write_text)


def leftovers(folder):
    """Temporary files an atomic write could have left behind."""
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp") or p.name.startswith(".")]


@pytest.fixture
def rgb():
    rng = np.random.default_rng(7)
    return rng.random((5, 7, 3)) * 10.0


# ------------------------------------------------------------------------- EXR
def test_exr_round_trip_rgb_is_float32_exact(tmp_path, rgb):
    path = write_exr(tmp_path / "a.exr", rgb)
    back = read_exr(path)
    assert back.dtype == np.float64 and back.shape == (5, 7, 3)
    np.testing.assert_array_equal(back, rgb.astype(np.float32))
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("compression", sorted(COMPRESSIONS))
def test_exr_every_compression_is_float32_exact(tmp_path, compression):
    img = np.random.default_rng(5).standard_normal((41, 9, 4)) * 1e3
    path = write_exr(tmp_path / "z.exr", img, compression=compression)
    np.testing.assert_array_equal(read_exr(path), img.astype(np.float32))
    assert OpenEXR.File(str(path)).header()["compression"] == COMPRESSIONS[compression]


def test_exr_threads_uses_the_cores_and_restores_the_count():
    before = OpenEXR.global_thread_count()
    with exr_threads():
        assert OpenEXR.global_thread_count() == len(os.sched_getaffinity(0))
    assert OpenEXR.global_thread_count() == before


def test_exr_threads_overlapping_blocks_in_threads_restore_once_at_the_end():
    """Thread A enters, B enters, A leaves: B still has the cores; the count is restored
    only when B leaves (a save/restore per block restored 0 while B ran, or leaked)."""
    import threading
    cores = len(os.sched_getaffinity(0))
    original = OpenEXR.global_thread_count()
    OpenEXR.set_global_thread_count(0)
    a_in, b_in, a_out, b_checked = (threading.Event() for _ in range(4))
    seen = {}

    def a():
        with exr_threads():
            a_in.set()
            b_in.wait(5)
        a_out.set()

    def b():
        a_in.wait(5)
        with exr_threads():
            b_in.set()
            a_out.wait(5)
            seen["while b runs"] = OpenEXR.global_thread_count()
        b_checked.set()

    try:
        threads = [threading.Thread(target=f) for f in (a, b)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(10)
        assert b_checked.is_set()
        assert seen["while b runs"] == cores
        assert OpenEXR.global_thread_count() == 0
    finally:
        OpenEXR.set_global_thread_count(original)


def test_exr_concurrent_writes_from_threads_round_trip(tmp_path):
    from concurrent.futures import ThreadPoolExecutor
    before = OpenEXR.global_thread_count()
    images = [np.random.default_rng(k).standard_normal((64, 48, 3)) for k in range(16)]
    with ThreadPoolExecutor(8) as pool:
        paths = list(pool.map(lambda k: write_exr(tmp_path / f"t{k}.exr", images[k]), range(16)))
        backs = list(pool.map(read_exr, paths))
    for img, back in zip(images, backs):
        np.testing.assert_array_equal(back, img.astype(np.float32))
    assert OpenEXR.global_thread_count() == before
    assert leftovers(tmp_path) == []


def test_exr_keeps_orientation_and_channels(tmp_path):
    img = np.zeros((4, 6, 3))
    img[0, 0] = (1.0, 2.0, 3.0)          # top-left pixel, distinct channels
    back = read_exr(write_exr(tmp_path / "o.exr", img))
    np.testing.assert_array_equal(back[0, 0], (1.0, 2.0, 3.0))
    assert np.count_nonzero(back) == 3


@pytest.mark.parametrize("shape, channels", [((3, 4), 1), ((3, 4, 1), 1), ((3, 4, 4), 4)])
def test_exr_round_trip_y_and_rgba(tmp_path, shape, channels):
    img = np.arange(np.prod(shape), dtype=np.float64).reshape(shape) / 7.0
    back = read_exr(write_exr(tmp_path / "c.exr", img))
    assert back.shape == (3, 4, channels)
    np.testing.assert_array_equal(back.reshape(shape), img.astype(np.float32))


def test_exr_half(tmp_path, rgb):
    back = read_exr(write_exr(tmp_path / "h.exr", rgb, half=True))
    np.testing.assert_allclose(back, rgb, rtol=1e-3)


@pytest.mark.parametrize("bad", [np.zeros((3, 4, 2)), np.zeros((0, 4, 3)), np.zeros(5), np.array([["a"]])])
def test_exr_writer_rejects_bad_shapes(tmp_path, bad):
    with pytest.raises(ValueError):
        write_exr(tmp_path / "bad.exr", bad)
    assert list(tmp_path.iterdir()) == []


def test_exr_reader_missing_file_names_it(tmp_path):
    path = tmp_path / "nope.exr"
    with pytest.raises(mf.MicrofacetError, match="nope.exr.*no such file"):
        read_exr(path)


def test_exr_reader_rejects_non_exr(tmp_path):
    path = tmp_path / "fake.exr"
    Image.new("RGB", (2, 2)).save(path, format="PNG")
    with pytest.raises(mf.MicrofacetError, match=r"fake\.exr: not an OpenEXR file"):
        read_exr(path)
    empty = tmp_path / "empty.exr"
    empty.write_bytes(b"")
    with pytest.raises(mf.MicrofacetError, match="empty.exr"):
        read_exr(empty)


def test_exr_reader_rejects_truncated_file(tmp_path, rgb):
    path = write_exr(tmp_path / "t.exr", np.random.default_rng(0).random((64, 64, 3)))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(mf.MicrofacetError, match=r"t\.exr: unreadable or corrupt EXR"):
        read_exr(path)


def test_exr_reader_rejects_directory(tmp_path):
    with pytest.raises(mf.MicrofacetError, match="is a directory"):
        read_exr(tmp_path)


def test_exr_reader_needs_colour_channels(tmp_path):
    path = tmp_path / "depth.exr"
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"Z": np.ones((2, 3), np.float32)}).write(str(path))
    with pytest.raises(mf.MicrofacetError, match=r"depth\.exr: needs R, G, B or Y channels, found \['Z'\]"):
        read_exr(path)


def test_exr_reader_rejects_nonfinite_unless_allowed(tmp_path, rgb):
    rgb[1, 2, 0] = np.nan
    rgb[0, 0, 1] = np.inf
    path = write_exr(tmp_path / "nan.exr", rgb, allow_nonfinite=True)
    with pytest.raises(mf.MicrofacetError, match=r"nan\.exr: 2 NaN or infinite values"):
        read_exr(path)
    assert np.isnan(read_exr(path, allow_nonfinite=True)[1, 2, 0])


def test_exr_writer_refuses_nonfinite_and_overflow_unless_allowed(tmp_path, rgb):
    big = rgb.copy()
    big[0, 0, 0] = 1e39                              # finite in float64, inf in float32
    for image, half, count in ((big, False, 1), (rgb * 1e4, True, None)):
        with pytest.raises(ValueError, match=r"x\.exr: \d+ NaN or infinite values .*nothing written"):
            write_exr(tmp_path / "x.exr", image, half=half)
        assert leftovers(tmp_path) == [] and not (tmp_path / "x.exr").exists()
    rgb[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match=r"x\.exr: 1 NaN"):
        write_exr(tmp_path / "x.exr", rgb)


# ------------------------------------------------------------------------- PNG
def test_srgb_encode_reference_values():
    v = np.array([0.0, 0.0031308, 0.18, 0.5, 1.0])
    expected = [0.0, 12.92 * 0.0031308, 0.4613561, 0.7353570, 1.0]   # IEC 61966-2-1
    np.testing.assert_allclose(srgb_encode(v), expected, atol=2e-7)


def test_to_srgb8_exposure_clip_and_nan():
    lin = np.array([[[0.25, 0.0, 4.0], [np.nan, -1.0, 0.5]]])
    out = to_srgb8(lin, exposure=1.0)           # x 2: 0.5, 0, 8 -> clip 1
    assert out.dtype == np.uint8
    np.testing.assert_array_equal(out[0, 0], [188, 0, 255])
    np.testing.assert_array_equal(out[0, 1], [0, 0, 255])


def test_png_round_trip(tmp_path):
    lin = np.linspace(0.0, 1.0, 4 * 6 * 3).reshape(4, 6, 3)
    path = write_png(tmp_path / "p.png", lin)
    with Image.open(path) as im:
        assert im.format == "PNG" and im.mode == "RGB" and im.size == (6, 4)
        back = np.asarray(im)
    np.testing.assert_array_equal(back, to_srgb8(lin))
    gray = write_png(tmp_path / "g.png", lin[..., 0])
    with Image.open(gray) as im:
        assert im.mode == "L"
    assert leftovers(tmp_path) == []


def test_png_rejects_bad_shape(tmp_path):
    with pytest.raises(ValueError, match="PNG image"):
        write_png(tmp_path / "x.png", np.zeros((2, 2, 2)))
    assert list(tmp_path.iterdir()) == []


# ---------------------------------------------------------------------- atomic
def test_atomic_write_replaces_and_respects_umask(tmp_path):
    target = tmp_path / "out.txt"
    write_text(target, "old")
    write_text(target, "new ✓")
    assert target.read_text(encoding="utf-8") == "new ✓"
    mask = os.umask(0o022)
    os.umask(mask)
    assert stat.S_IMODE(target.stat().st_mode) == 0o666 & ~mask
    assert leftovers(tmp_path) == []


def test_interrupted_write_keeps_old_file_and_leaves_no_temp(tmp_path):
    target = tmp_path / "keep.txt"
    write_text(target, "complete")
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(target) as tmp:
            tmp.write_text("half")
            raise KeyboardInterrupt
    assert target.read_text() == "complete"
    assert leftovers(tmp_path) == []


def test_failing_exr_writer_leaves_old_file(tmp_path, rgb, monkeypatch):
    target = write_exr(tmp_path / "img.exr", rgb)
    before = target.read_bytes()

    def broken_write(self, path):
        with open(path, "wb") as f:
            f.write(b"\x76\x2f\x31\x01 partial")
        raise RuntimeError("disk full")

    monkeypatch.setattr(OpenEXR.File, "write", broken_write)
    with pytest.raises(OSError, match="disk full"):         # OpenEXR's RuntimeError, as an OSError naming the file
        write_exr(target, rgb * 2)
    assert target.read_bytes() == before
    assert leftovers(tmp_path) == []


def test_writer_into_missing_folder_raises_oserror(tmp_path):
    with pytest.raises(OSError):
        write_text(tmp_path / "missing" / "a.txt", "x")


# ------------------------------------------------------------------------ HTML
def test_html_escapes_text():
    page = html_page("a < b", html_figure("x.png", 'cap "q" & <b>') + html_grid([("row", [("y.png", "α = 1")])]))
    assert page.startswith("<!DOCTYPE html>") and "<title>a &lt; b</title>" in page
    assert "cap &quot;q&quot; &amp; &lt;b&gt;" in page and "<b>" not in page
    assert '<img src="y.png"' in page and "α = 1" in page


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("shape", [(5, 7), (5, 7, 2), (5, 7, 3), (5, 7, 4)])
def test_png_data_round_trips_exactly(tmp_path, shape, dtype):
    """Gray, gray+alpha, RGB, RGBA at 8 and 16 bits, every sample value range covered."""
    a = np.random.default_rng(3).integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
    a.flat[:2] = (0, np.iinfo(dtype).max)
    path = write_png_data(tmp_path / "d.png", a)
    back = read_png_data(path)
    assert back.dtype == dtype and back.shape == shape
    np.testing.assert_array_equal(back, a)
    if len(shape) == 2 or dtype == np.uint8:       # Pillow reads these exactly (not 16-bit colour)
        with Image.open(path) as im:
            np.testing.assert_array_equal(np.asarray(im).astype(dtype), a)
    assert leftovers(tmp_path) == []


def test_png_data_reader_errors_name_the_file(tmp_path):
    good = write_png_data(tmp_path / "g.png", np.zeros((64, 64, 3), np.uint16)).read_bytes()
    (tmp_path / "cut.png").write_bytes(good[: len(good) // 2])
    (tmp_path / "sig.png").write_bytes(b"GIF89a" + good[6:])
    (tmp_path / "junk.png").write_bytes(good[:8] + b"\x00" * 40)
    for name, message in (("cut.png", "corrupt PNG"), ("sig.png", "not a PNG file"),
                          ("junk.png", "corrupt PNG"), ("missing.png", "no such file")):
        with pytest.raises(mf.MicrofacetError, match=rf"{name}: .*{message}|{name}: {message}"):
            read_png_data(tmp_path / name)
    with pytest.raises(ValueError, match="uint8 or uint16"):
        write_png_data(tmp_path / "f.png", np.zeros((2, 2), np.float32))


# ------------------------------------------------------------------------- names
@pytest.mark.parametrize("path, material, stem", [
    ("d/nickel.binary.gz", "nickel", "nickel"), ("a.bsdf", "a", "a"), ("M.BIN", "M", "M"),
    ("h.png", "h.png", "h"), ("x/fit.npz", "fit.npz", "fit"), ("r.exr", "r.exr", "r"),
    (".gz", ".gz", ".gz"), ("a.b.txt", "a.b.txt", "a.b.txt")])
def test_material_and_input_names(path, material, stem):
    from microfacet.batch import input_name as batch_input_name
    from microfacet.fit.outputs import material_name as fit_material_name
    assert mf.io.material_name(path) == material and mf.io.input_name(path) == stem
    assert fit_material_name is mf.io.material_name and batch_input_name is mf.io.input_name
