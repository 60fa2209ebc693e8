"""Fuzzing every file reader, and the CLI, with mutated files (Hypothesis, seeded).

Seeds are small valid files written here with the library's own writers (plus a few
structurally wrong ones: missing channels, NaN payloads, other resolutions); Hypothesis
mutates them (truncation, flipped bytes, random header bytes, huge declared sizes, NaN/inf
payloads, appended junk, random bytes). For every mutated file the reader must either
return a complete object whose values are finite, or raise ``MicrofacetError``,
``ValueError`` or ``OSError`` naming the file; never another exception (a traceback),
a NumPy ``RuntimeWarning``, a hang (deadline 10 s), or a change to the file (content and
modification time are compared).

``MICROFACET_FUZZ_EXAMPLES`` sets the number of mutated files per reader (default 100;
e.g. 2000 for a long run). Examples are derandomized: a run is reproducible.
"""
from __future__ import annotations

import gzip
import os
import struct
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis", reason="fuzzing needs the `hypothesis` test extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import microfacet as mf  # noqa: E402
from microfacet import cli  # noqa: E402
from microfacet.errors import MicrofacetError  # noqa: E402
from microfacet.glints import Microsurface  # noqa: E402
from microfacet.glints.figures import scratched_normal_map  # noqa: E402
from microfacet.io.exr import write_exr  # noqa: E402
from microfacet.io.png import write_png_data  # noqa: E402
from microfacet.leadr import files as leadr_files  # noqa: E402
from microfacet.measured import merl, utia  # noqa: E402
from microfacet.measured.tensor_file import write_tensor_file  # noqa: E402

EXAMPLES = int(os.environ.get("MICROFACET_FUZZ_EXAMPLES", "100"))
DEADLINE_S = 10.0
FUZZ = settings(max_examples=EXAMPLES, deadline=DEADLINE_S * 1000, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))
HUGE = (2**31 - 1, 2**31, 2**32 - 1, 2**63 - 1, 2**64 - 1, 0, 1 << 40)
NONFINITE = (np.nan, np.inf, -np.inf)
RNG_DIRS = np.random.default_rng(5)


def _upper(n: int) -> np.ndarray:
    w = RNG_DIRS.normal(size=(n, 3))
    w /= np.linalg.norm(w, axis=-1, keepdims=True)
    w[:, 2] = np.abs(w[:, 2]) + 1e-3
    return w / np.linalg.norm(w, axis=-1, keepdims=True)


WI, WO = _upper(32), _upper(32)


# ------------------------------------------------------------------------ mutations
class Mutant(bytes):
    """File bytes with a short ``repr`` (how they were made), for Hypothesis' reports."""

    def __new__(cls, data, how: str):
        self = super().__new__(cls, data)
        self.how = how
        return self

    def __repr__(self) -> str:
        return f"<{len(self)} bytes: {self.how}>"


@st.composite
def mutated(draw, seeds: list[bytes], word: int = 4, header: int = 256):
    """One of ``seeds``, mutated (or not). ``word``: size of the payload floats (4 or 8) for
    NaN/inf payloads; ``header``: the leading bytes where header fields live."""
    index = draw(st.integers(0, len(seeds) - 1))
    data = bytearray(seeds[index])
    n = len(data)
    kind = draw(st.sampled_from(("none", "truncate", "flip", "header", "huge", "nonfinite",
                                 "append", "random")))
    if kind == "truncate" and n:
        del data[draw(st.integers(0, n - 1)):]
    elif kind == "flip" and n:
        for _ in range(draw(st.integers(1, 8))):
            data[draw(st.integers(0, n - 1))] ^= draw(st.integers(1, 255))
    elif kind == "header" and n:
        i = draw(st.integers(0, min(n, header) - 1))
        junk = draw(st.binary(min_size=1, max_size=16))
        data[i:i + len(junk)] = junk
    elif kind == "huge" and n >= 8:
        i = 4 * draw(st.integers(0, (min(n, header) - 8) // 4))
        fmt = draw(st.sampled_from(("<I", ">I", "<Q")))
        value = draw(st.sampled_from(HUGE)) % (1 << (8 * struct.calcsize(fmt)))
        data[i:i + struct.calcsize(fmt)] = struct.pack(fmt, value)
    elif kind == "nonfinite" and n >= header + word:
        i = word * draw(st.integers(header // word, n // word - 1))
        data[i:i + word] = struct.pack("<f" if word == 4 else "<d", draw(st.sampled_from(NONFINITE)))
    elif kind == "append":
        data += draw(st.binary(min_size=1, max_size=64))
    elif kind == "random":
        data = bytearray(draw(st.binary(max_size=512)))
    return Mutant(data, f"seed {index}, {kind}")


def fuzz_reader(folder: Path, name: str, seeds: list[bytes], load, check, known=(), **mutation) -> int:
    """Run ``load`` on ``EXAMPLES`` mutated files ``folder / name``; ``check(result)`` must
    accept what loads. Returns the number of files tried. Exceptions of the types ``known``
    (bugs reported to the owners of code this branch must not edit) are collected, and
    the test is marked xfail with them at the end, after all examples ran."""
    path = folder / name
    tried, escaped = [], []

    @FUZZ
    @given(mutated(seeds, **mutation))
    def run(data):
        path.write_bytes(data)
        stamp = path.stat().st_mtime_ns
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            try:
                result = load(path)
            except (MicrofacetError, ValueError, OSError) as e:
                assert str(path) in str(e), f"error does not name the file: {e!r}"
            except known as e:
                escaped.append(f"{type(e).__name__}: {e} ({data!r})")
            else:
                check(result)
        assert time.perf_counter() - t0 < DEADLINE_S
        assert path.read_bytes() == data and path.stat().st_mtime_ns == stamp, "input modified"
        tried.append(len(data))

    run()
    if escaped:
        pytest.xfail(f"{len(escaped)} of {len(tried)} files escaped as known bugs, e.g. {escaped[0]}")
    return len(tried)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return tmp_path_factory.mktemp("fuzz")


def _finite_brdf(brdf) -> None:
    assert isinstance(brdf, mf.brdf.BRDF)
    assert np.all(np.isfinite(brdf.eval(WI, WO)))


# ----------------------------------------------------------------- measured BRDFs
def _merl_bytes(dims, raw) -> bytes:
    return np.array(dims, "<i4").tobytes() + np.asarray(raw, "<f8").tobytes()


def test_fuzz_merl(folder):
    """MERL ``.binary`` and ``.binary.gz``: a valid full-size file (35 MB, drawn rarely: its
    mutations cost a full read), headers of other resolutions with matching sizes, and
    gzip streams of both."""
    rng = np.random.default_rng(1)
    full = _merl_bytes(merl.SHAPE, rng.uniform(0, 200, (3,) + merl.SHAPE))
    small = [_merl_bytes(d, rng.uniform(-1, 2, (3,) + d)) for d in ((2, 2, 4), (90, 90, 1), (1, 1, 1))]
    seeds = small * 4 + [gzip.compress(s) for s in small] * 4 + [full, gzip.compress(full, 1)]
    tried = fuzz_reader(folder, "fuzz.binary", seeds, mf.measured.load, _finite_brdf, word=8, header=64)
    assert tried >= EXAMPLES


def _rgl_fields(rng) -> dict:
    n_theta, n_phi = 3, 1
    tab = lambda *shape: rng.uniform(0.5, 1.5, shape).astype(np.float32)  # noqa: E731
    return {"version": np.array([1, 0], np.uint32),
            "description": np.frombuffer(b"fuzz", np.uint8),
            "phi_i": np.zeros(n_phi, np.float32), "theta_i": np.linspace(0, 1.2, n_theta).astype(np.float32),
            "sigma": tab(2, 8), "ndf": tab(2, 8), "vndf": tab(n_phi, n_theta, 4, 4),
            "luminance": tab(n_phi, n_theta, 4, 4), "rgb": tab(n_phi, n_theta, 3, 4, 4),
            "jacobian": np.array([1], np.uint8), "valid": np.ones(2, np.uint8)}


def test_fuzz_rgl(folder):
    """RGL ``.bsdf`` tensor files: a small valid one, an anisotropic one, wrong dtypes/shapes."""
    rng = np.random.default_rng(2)
    f = _rgl_fields(rng)
    aniso = dict(f, phi_i=np.linspace(-np.pi, 0, 3).astype(np.float32), vndf=np.ones((3, 3, 4, 4), np.float32),
                 luminance=np.ones((3, 3, 4, 4), np.float32), rgb=np.ones((3, 3, 3, 4, 4), np.float32))
    seeds = [write_tensor_file(f), write_tensor_file(aniso),
             write_tensor_file(dict(f, sigma=f["sigma"].astype(np.float64))),
             write_tensor_file(dict(f, rgb=f["rgb"][:, :2])),
             write_tensor_file({k: v for k, v in f.items() if k != "ndf"})]
    tried = fuzz_reader(folder, "fuzz.bsdf", seeds, mf.measured.load, _finite_brdf, word=4, header=512)
    assert tried >= EXAMPLES


def test_fuzz_utia(folder):
    """UTIA ``.bin`` (headerless float64, recognised by size)."""
    raw = np.random.default_rng(3).uniform(0, 150, utia.SHAPE)
    seeds = [raw.astype("<f8").tobytes()]
    tried = fuzz_reader(folder, "fuzz.bin", seeds, mf.measured.load, _finite_brdf, word=8, header=64)
    assert tried >= EXAMPLES


# --------------------------------------------------------------------- height maps
def _finite_heights(a) -> None:
    assert a.ndim == 2 and a.dtype == np.float64 and min(a.shape) >= 1 and np.all(np.isfinite(a))


def _exr_bytes(folder: Path, image, half=False, channels=None) -> bytes:
    path = folder / "seed.exr"
    if channels is None:
        write_exr(path, image, half=half, allow_nonfinite=True)    # NaN seeds too
    else:                                   # a channel set the readers do not expect
        import OpenEXR
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        OpenEXR.File(header, {c: np.ascontiguousarray(image, np.float32) for c in channels}).write(str(path))
    return path.read_bytes()


def test_fuzz_exr_height_map(folder):
    rng = np.random.default_rng(4)
    h = rng.random((9, 7))
    seeds = [_exr_bytes(folder, h), _exr_bytes(folder, np.dstack([h] * 3), half=True),
             _exr_bytes(folder, np.where(h > 0.9, np.nan, h)), _exr_bytes(folder, h, channels=("X", "Z")),
             _exr_bytes(folder, h, channels=("R", "G"))]
    tried = fuzz_reader(folder, "fuzz.exr", seeds, leadr_files.load_height_map, _finite_heights, header=400)
    assert tried >= EXAMPLES


def _png_bytes(folder: Path, image) -> bytes:
    return write_png_data(folder / "seed.png", image).read_bytes()


def test_fuzz_png_height_map(folder):
    rng = np.random.default_rng(5)
    seeds = [_png_bytes(folder, rng.integers(0, 255, (9, 7), dtype=np.uint8)),
             _png_bytes(folder, rng.integers(0, 65535, (6, 5), dtype=np.uint16)),
             _png_bytes(folder, rng.integers(0, 65535, (5, 4, 3), dtype=np.uint16)),
             _png_bytes(folder, rng.integers(0, 255, (5, 4, 4), dtype=np.uint8))]
    tried = fuzz_reader(folder, "fuzz.png", seeds, leadr_files.load_height_map, _finite_heights, header=64)
    assert tried >= EXAMPLES


def test_png16_with_a_short_ihdr_chunk_is_a_clear_error(folder):
    """Found by fuzzing (hand-written codec, since replaced): a PNG whose IHDR length field is not 13 is a clear error."""
    data = bytearray(_png_bytes(folder, np.zeros((2, 2, 3), np.uint16)))
    data[8:12] = struct.pack(">I", 12)
    path = folder / "short_ihdr.png"
    path.write_bytes(bytes(data))
    with pytest.raises(MicrofacetError, match="short_ihdr.png"):
        leadr_files.load_height_map(path)


# ------------------------------------------------------------------ .npz and pyramids
def _npz_bytes(folder: Path, arrays: dict, compressed=False) -> bytes:
    path = folder / "seed.npz"
    (np.savez_compressed if compressed else np.savez)(path, **arrays)
    return path.read_bytes()


def test_fuzz_fit_npz(folder):
    fitted = mf.fit.fit(mf.MicrofacetBRDF(mf.GGX(alpha=0.4)), resolution=8)
    valid = fitted.save(folder / "fit.npz").read_bytes()
    with np.load(folder / "fit.npz") as z:
        arrays = {k: z[k] for k in z.files}
    seeds = [valid, _npz_bytes(folder, dict(arrays, ndf=np.full_like(arrays["ndf"], np.nan))),
             _npz_bytes(folder, dict(arrays, version=np.array(7))),
             _npz_bytes(folder, {k: v for k, v in arrays.items() if k != "fresnel_rgb"}),
             _npz_bytes(folder, dict(arrays, ndf=arrays["ndf"][:2])),
             _npz_bytes(folder, dict(arrays, alpha_x=np.array(-1.0)))]
    tried = fuzz_reader(folder, "fuzz.npz", seeds, mf.fit.load, _finite_brdf, header=128)
    assert tried >= EXAMPLES


def _finite_microsurface(ms) -> None:
    assert isinstance(ms, Microsurface)
    assert np.all(np.isfinite(ms.slopes)) and np.all(np.isfinite(ms.lobe_moments))


def test_fuzz_glints_npz(folder):
    ms = Microsurface.from_normal_map(scratched_normal_map(8, scratches=2, seed=1), sigma_eps=0.1)
    valid = ms.save(folder / "ms.npz").read_bytes()
    with np.load(folder / "ms.npz") as z:
        arrays = {k: z[k] for k in z.files}
    seeds = [valid, _npz_bytes(folder, dict(arrays, slopes=np.full_like(arrays["slopes"], np.inf)), True),
             _npz_bytes(folder, dict(arrays, central=arrays["central"][..., :4]), True),
             _npz_bytes(folder, dict(arrays, params=np.array([1.0, -0.1, 3.0, 1.0])))]
    tried = fuzz_reader(folder, "fuzz_ms.npz", seeds, Microsurface.load, _finite_microsurface,
                        header=128)
    assert tried >= EXAMPLES


def _finite_pyramid(levels) -> None:
    assert levels and all(level.ndim == 3 and level.shape[2] == 5 and np.all(np.isfinite(level))
                          for level in levels)


def test_fuzz_pyramid_exr(folder):
    rng = np.random.default_rng(6)
    pyramid = [rng.random((4, 4, 5)), rng.random((2, 2, 5)), rng.random((1, 1, 5))]
    path = folder / "seed_pyr.exr"
    seeds = [leadr_files.write_pyramid(path, pyramid).read_bytes(),
             leadr_files.write_pyramid(path, pyramid, compression="zip").read_bytes(),   # the decompressor too
             leadr_files.write_pyramid(path, pyramid[:1] + [np.full((2, 2, 5), np.nan)],
                                       allow_nonfinite=True).read_bytes(),
             leadr_files.write_pyramid(path, [pyramid[0], pyramid[2]]).read_bytes(),
             _exr_bytes(folder, pyramid[0][..., 0], channels=("E1", "E2", "E3", "E4"))]
    tried = fuzz_reader(folder, "fuzz_pyr.exr", seeds, leadr_files.read_pyramid, _finite_pyramid, header=600)
    assert tried >= EXAMPLES


def test_npz_of_random_bytes_says_not_a_microfacet_file(folder):
    """Item 8: random bytes as ``.npz`` name the file and say what it is not, without
    NumPy's 'pickled data ... allow_pickle' message."""
    path = folder / "random.npz"
    path.write_bytes(np.random.default_rng(7).bytes(300))
    for load, what in ((mf.fit.load, "microfacet fit file"), (Microsurface.load, "microsurface")):
        with pytest.raises(MicrofacetError) as e:
            load(path)
        assert str(path) in str(e.value) and what in str(e.value) and "pickle" not in str(e.value)


# -------------------------------------------------------------------------- the CLI
def _cli(argv, capsys) -> tuple[int, str]:
    status = cli.main([str(a) for a in argv])
    return status, capsys.readouterr().err


def test_fuzz_cli(folder, capsys):
    """``microfacet fit | bake | glints`` on mutated inputs: non-zero exit, one line on
    stderr, no output file left, input unchanged."""
    rng = np.random.default_rng(8)
    merl_small = _merl_bytes((2, 2, 4), rng.uniform(0, 1, (3, 2, 2, 4)))
    png = _png_bytes(folder, rng.integers(0, 255, (9, 7), dtype=np.uint8))
    exr = _exr_bytes(folder, rng.random((8, 8)))
    bad = {"truncated": lambda b: b[: len(b) // 2], "flipped": lambda b: bytes([b[0] ^ 0xFF]) + b[1:],
           "random": lambda b: rng.bytes(len(b)), "empty": lambda b: b"",
           "nan": lambda b: b[:-8] + struct.pack("<d", np.nan)}
    cases = []
    for name, mutate in bad.items():
        cases.append((["fit", "{in}", "-o", "{out}", "--resolution", "8"], "in.binary", mutate(merl_small), "fitdir"))
        if name != "nan":          # the payload of a PNG/EXR is compressed
            cases.append((["bake", "{in}", "-o", "{out}", "--roughness", "0.1"], "in.png", mutate(png), "out.exr"))
            cases.append((["glints", "{in}", "-o", "{out}"], "in.exr", mutate(exr), "out.npz"))
    for argv, src_name, data, out_name in cases:
        src, out = folder / src_name, folder / "cli" / out_name
        out.parent.mkdir(exist_ok=True)
        src.write_bytes(data)
        status, err = _cli([a.format(**{"in": src, "out": out}) for a in argv], capsys)
        assert status != 0, (argv, src_name)
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("microfacet: error:") and "Traceback" not in err, err
        assert not out.exists() or (out.is_dir() and not any(out.iterdir())), f"{out} left behind"
        assert sorted(p.name for p in out.parent.iterdir() if p.name != out.name) == [], "temporary files left"
        assert src.read_bytes() == data


def test_load_npz_names_the_file_and_what_it_is_not(folder):
    """The shared ``.npz`` reader (:func:`microfacet.io.load_npz`)."""
    from microfacet.io import load_npz
    good = folder / "good.npz"
    np.savez(good, a=np.arange(3))
    assert list(load_npz(good, "a test file")) == ["a"]
    cases = {"random.npz": np.random.default_rng(9).bytes(300), "empty.npz": b"",
             "truncated.npz": good.read_bytes()[:100], "object.npz": None}
    for name, data in cases.items():
        path = folder / name
        if data is None:
            np.savez(path, a=np.array([{}], dtype=object))
        else:
            path.write_bytes(data)
        with pytest.raises(MicrofacetError, match="not a test file") as e:
            load_npz(path, "a test file")
        assert str(path) in str(e.value) and "allow_pickle" not in str(e.value)
    with pytest.raises(MicrofacetError, match="no such file"):
        load_npz(folder / "missing.npz", "a test file")


def test_load_npz_stored_members_equal_np_load_and_check_the_crc(folder):
    """Uncompressed members are views of a private memory map (:func:`microfacet.io.npz._read_stored`):
    the same arrays as ``np.load`` (C and Fortran order, 0-d, empty, several dtypes),
    writeable without touching the file, and a flipped data byte (finite floats, no
    other check sees it) is still refused by the member's CRC-32, naming the file."""
    from microfacet.io import load_npz
    arrays = {"c": np.arange(24, dtype=np.float32).reshape(2, 3, 4), "f": np.asfortranarray(np.eye(3)[:, :2] + 0.5),
              "s": np.array(7), "e": np.zeros((0, 5)), "t": np.array("text"), "u": np.arange(5, dtype=np.uint16)}
    path = folder / "stored.npz"
    np.savez(path, **arrays)
    data = path.read_bytes()
    got = load_npz(path, "a test file")
    with np.load(path) as z:
        assert sorted(got) == sorted(z.files)
        for k in z.files:
            assert got[k].dtype == z[k].dtype and got[k].shape == z[k].shape and np.array_equal(got[k], z[k]), k
    assert got["f"].flags.f_contiguous
    got["c"][...] = -1.0
    assert path.read_bytes() == data, "writing into a loaded array changed the file"
    at = data.index(np.arange(24, dtype=np.float32).tobytes()) + 5       # inside float 1.0: 1.0000001
    path.write_bytes(data[:at] + bytes([data[at] ^ 1]) + data[at + 1:])
    with pytest.raises(MicrofacetError, match="not a test file.*CRC") as e:
        load_npz(path, "a test file")
    assert str(path) in str(e.value)


def test_fuzz_load_npz(folder):
    arrays = {"ndf": np.linspace(1, 2, 9), "kind": np.array("isotropic")}
    seeds = [_npz_bytes(folder, arrays), _npz_bytes(folder, arrays, compressed=True)]
    from microfacet.io import load_npz
    tried = fuzz_reader(folder, "fuzz_any.npz", seeds, lambda p: load_npz(p, "a test file"),
                        lambda d: isinstance(d, dict), header=128)
    assert tried >= EXAMPLES
