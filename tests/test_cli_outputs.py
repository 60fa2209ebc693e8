"""The output naming rule and checks before work, for every command (issue 11, defects 3-6)."""
import os

import numpy as np
import pytest

from microfacet.cli import main
from microfacet.io import write_exr


@pytest.fixture
def height_png(tmp_path):
    from PIL import Image
    rng = np.random.default_rng(1)
    path = tmp_path / "h.png"
    Image.fromarray((rng.random((16, 16)) * 255).astype(np.uint8)).save(path)
    return path


@pytest.fixture
def normal_exr(tmp_path):
    rng = np.random.default_rng(2)
    n = np.dstack([rng.normal(0, 0.1, (16, 16)), rng.normal(0, 0.1, (16, 16)), np.ones((16, 16))])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    return write_exr(tmp_path / "n.exr", (n + 1) / 2)


def one_error_line(capsys, *words):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("microfacet: error: "), err
    for w in words:
        assert w in err, err
    assert "Traceback" not in err


@pytest.mark.parametrize("option", [["--scale", "1e300"], ["--roughness", "1e300"], ["--roughness", "1e30"]])
def test_bake_overflow_fails_before_writing(option, height_png, tmp_path, capsys):
    out = tmp_path / "x.exr"
    assert main(["bake", str(height_png), "-o", str(out), *option]) in (1, 2)
    one_error_line(capsys)
    assert not out.exists() and not out.with_suffix(".png").exists()
    assert not any(p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_glints_huge_sigma_eps_is_one_line(normal_exr, tmp_path, capsys):
    assert main(["glints", str(normal_exr), "-o", str(tmp_path / "g.npz"), "--sigma-eps", "1e300"]) == 2
    one_error_line(capsys, "--sigma-eps")
    assert not (tmp_path / "g.npz").exists()


def test_validate_output_is_checked_before_the_work(tmp_path, capsys):
    image = tmp_path / "h.png"
    image.write_bytes(b"not markdown")
    assert main(["validate", "--quick", "-o", str(image)]) == 1
    one_error_line(capsys, "h.png", ".md")
    assert image.read_bytes() == b"not markdown"
    folder = tmp_path / "adir"
    folder.mkdir()
    (folder / "validate.md").mkdir()                 # a folder where the table would go
    assert main(["validate", "--quick", "-o", str(folder)]) == 1
    one_error_line(capsys, "validate.md", "is a folder")
    assert ".tmp" not in capsys.readouterr().err


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux /proc (a folder nobody can write in)")
@pytest.mark.parametrize("command", ["validate", "bake", "glints"])
def test_unwritable_output_folder_is_refused_before_the_work(command, normal_exr, monkeypatch, capsys):
    import microfacet.batch.tasks
    import microfacet.validation

    def work(*args, **kwargs):
        raise AssertionError("the work started")
    for module, name in [(microfacet.validation, "core_report"), (microfacet.batch.tasks, "bake_file"),
                         (microfacet.batch.tasks, "glints_file")]:
        monkeypatch.setattr(module, name, work)
    source = [] if command == "validate" else [str(normal_exr)]
    extra = ["--normal-map"] if command == "bake" else []
    assert main([command, *source, *extra, "-o", "/proc/microfacet-test-output"]) == 1
    one_error_line(capsys, "/proc/microfacet-test-output", "cannot write here")


@pytest.mark.parametrize("command, suffix", [("bake", ".exr"), ("glints", ".npz")])
def test_output_equal_to_the_input_is_refused(command, suffix, normal_exr, height_png, tmp_path, capsys):
    source = height_png if command == "bake" else normal_exr
    before = source.read_bytes()
    assert main([command, str(source), "-o", str(source)]) == 1
    one_error_line(capsys, f"expected a {suffix} file")
    assert source.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["h.png", "n.exr"])


def test_bake_into_a_folder_takes_the_map_name_and_refuses_other_suffixes(height_png, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    assert main(["bake", str(height_png), "-o", str(out)]) == 0
    assert (out / "h.exr").exists() and (out / "h.png").exists()
    capsys.readouterr()
    assert main(["bake", str(height_png), "-o", str(tmp_path / "o.png")]) == 1
    one_error_line(capsys, "o.png", "expected a .exr file")
    assert not (tmp_path / "o.png.exr").exists() and not (tmp_path / "o.png").exists()


def test_bake_side_output_may_not_be_the_input(height_png, tmp_path, capsys):
    # -o h.exr would write its preview to h.png, the input
    assert main(["bake", str(height_png), "-o", str(tmp_path / "h.exr")]) == 1
    one_error_line(capsys, "would overwrite the input")
    assert not (tmp_path / "h.exr").exists()


def test_bake_interrupted_while_writing_the_preview_leaves_no_output(height_png, tmp_path, monkeypatch, capsys):
    import microfacet.io

    def interrupted(path, *args, **kwargs):
        assert (tmp_path / "x.exr").exists()         # the pyramid was written first
        raise KeyboardInterrupt
    monkeypatch.setattr(microfacet.io, "write_png", interrupted)
    assert main(["bake", str(height_png), "-o", str(tmp_path / "x.exr")]) == 130
    assert capsys.readouterr().err == "microfacet: interrupted\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.png"]
