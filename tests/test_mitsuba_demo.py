"""The demo's Mitsuba section (:func:`microfacet.mitsuba.demo.demo_section`) at a tiny size:
its HTML names every render with a time, the errors are finite and its images exist.
Skips like the other Mitsuba tests (no ``mitsuba``; ``llvm_ad_rgb`` falls back to
``scalar_rgb`` where libLLVM is missing, so the section runs either way)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

mi = pytest.importorskip("mitsuba", reason="the Mitsuba plugins need the optional `mitsuba` package "
                                           "(pip install 'microfacet[mitsuba]')")
pytest.importorskip("drjit", reason="the Mitsuba plugins need drjit (installed with mitsuba)")

from microfacet.mitsuba.demo import STEPS, demo_section  # noqa: E402

#: The shared data: $MICROFACET_DATA, else ../shared/data beside the repository.
DATA = Path(os.environ.get("MICROFACET_DATA") or Path(__file__).resolve().parents[2] / "shared" / "data")


@pytest.mark.parametrize("variant", [None, "scalar_rgb"])     # None: llvm_ad_rgb where it runs
def test_section_writes_images_and_timed_html(tmp_path, variant, monkeypatch):
    monkeypatch.setenv("MICROFACET_DATA", str(tmp_path / "no_data"))   # the built-in materials
    steps = []
    html = demo_section(tmp_path, size=16, spp=2, reference_spp=8, variant=variant, progress=steps.append)
    assert html.startswith('<section id="mitsuba">') and html.endswith("</section>")
    assert variant is None or f"variant {variant}" in html
    assert sum(steps) == STEPS
    sources = re.findall(r'<img src="([^"]+)"', html)
    assert len(sources) == 2 * 3 + 3 + 1
    for src in sources:
        png = tmp_path / src
        assert png.stat().st_size > 0 and png.with_suffix(".exr").stat().st_size > 0
    captions = re.findall(r"<small>(.*?)</small>", html)
    assert all(re.search(r"\d+\.\d\d s", c) for c in captions)
    errors = [float(e) for c in captions for e in re.findall(r"rel\. error (\d+\.\d+)", c)]
    assert len(errors) == 2 * 3 + 2 and all(0 <= e < 10 for e in errors)


@pytest.mark.skipif(not (DATA / "rgl" / "paper_white_rgb.bsdf").is_file(),
                    reason="no ../shared/data (RGL files) in this checkout")
def test_section_renders_the_shared_rgl_files_beside_measured(tmp_path, monkeypatch):
    """With shared data, the spheres are the RGL files: Mitsuba's measured (the reference)
    beside mf_fitted tabulated and GGX, each with its time and error."""
    (tmp_path / "data" / "rgl").mkdir(parents=True)
    (tmp_path / "data" / "rgl" / "paper_white_rgb.bsdf").symlink_to(DATA / "rgl" / "paper_white_rgb.bsdf")
    monkeypatch.setenv("MICROFACET_DATA", str(tmp_path / "data"))
    steps = []
    html = demo_section(tmp_path, size=16, spp=2, reference_spp=8, progress=steps.append)
    assert sum(steps) == STEPS
    captions = re.findall(r"<small>(.*?)</small>", html)[:3]
    assert [c.split(",")[0] for c in captions] == ["Mitsuba measured (the data)", "mf_fitted tabulated",
                                                   "mf_fitted use=ggx"]
    assert all(re.search(r"\d+\.\d\d s, rel\. error \d+\.\d+", c) for c in captions), captions
    assert (tmp_path / "mitsuba" / "paper_white_rgb_tabulated.png").stat().st_size > 0


def test_section_rejects_bad_sizes(tmp_path):
    with pytest.raises(ValueError, match="spp"):
        demo_section(tmp_path, spp=0)
    with pytest.raises(ValueError, match="leadr_width"):
        demo_section(tmp_path, leadr_width=4)


def test_run_demo_counts_the_section_steps():
    from microfacet.demo import MITSUBA_STEPS
    assert MITSUBA_STEPS == STEPS
